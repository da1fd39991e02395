//! Compliance: y = (1 - k) f + k H(q) f, H a unit-DC-gain 2nd-order resonance with natural
//! frequency omega (rad/sample) and damping zeta (k = 1: the pure resonance).
//!
//! Stage: Load. The resonance is the elastic transmission between the backlash's output and
//! the load it moves, so in a sandwich it filters f(t) before the output block (eq 29).

use super::{add_at, arity, finite, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "compliance";

/// Compliance (k, omega, zeta) and the resonance's memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Compliance {
    /// Share k of the resonant path (0: none).
    pub share: f64,
    /// Natural frequency omega in rad per sample.
    pub omega: f64,
    /// Damping ratio zeta.
    pub zeta: f64,
    d1: f64,
    d2: f64,
    g: f64,
    h1: f64,
    h2: f64,
    /// d(d1, d2) / d(omega, zeta) as [[dd1/domega, dd1/dzeta], [dd2/domega, dd2/dzeta]].
    partials: [[f64; 2]; 2],
    /// d h(t-1) / d theta and d h(t-2) / d theta (tangent simulations only).
    dh1: Vec<f64>,
    dh2: Vec<f64>,
}

/// The resonance's denominator (d1, d2) for (omega, zeta), and its partials (see
/// `Compliance::partials`): rho = exp(-zeta omega), omega_d = omega sqrt(1 - zeta^2),
/// d1 = -2 rho cos(omega_d), d2 = rho^2.
fn resonance(omega: f64, zeta: f64) -> ((f64, f64), [[f64; 2]; 2]) {
    let rho = (-zeta * omega).exp();
    let root = (1.0 - zeta * zeta).sqrt();
    let wd = omega * root;
    let (d1, d2) = (-2.0 * rho * wd.cos(), rho * rho);
    // d rho = -rho (zeta domega + omega dzeta); d wd = root domega - omega zeta / root dzeta
    let drho = [-zeta * rho, -omega * rho];
    let dwd = [root, -omega * zeta / root];
    let dd1 = |k: usize| -2.0 * (drho[k] * wd.cos() - rho * wd.sin() * dwd[k]);
    let dd2 = |k: usize| 2.0 * rho * drho[k];
    ((d1, d2), [[dd1(0), dd1(1)], [dd2(0), dd2(1)]])
}

/// 0 < omega < pi and 0 < zeta < 1.
fn in_domain(omega: f64, zeta: f64) -> bool {
    omega > 0.0 && omega < std::f64::consts::PI && zeta > 0.0 && zeta < 1.0
}

/// From [k, omega, zeta].
pub fn from_parameters(p: &[f64]) -> Result<Compliance> {
    arity(NAME, p, "k, omega, zeta", 3)?;
    let (k, omega, zeta) = (p[0], p[1], p[2]);
    // H(q) = g / (1 + d1 q^-1 + d2 q^-2), poles exp(omega (-zeta +- j sqrt(1 - zeta^2))).
    let (d1, d2) = if k != 0.0 {
        resonance(omega, zeta).0
    } else {
        (0.0, 0.0)
    };
    Ok(Compliance {
        share: k,
        omega,
        zeta,
        d1,
        d2,
        g: 1.0 + d1 + d2,
        h1: 0.0,
        h2: 0.0,
        partials: [[0.0; 2]; 2],
        dh1: Vec::new(),
        dh2: Vec::new(),
    })
}

impl Effect for Compliance {
    // on the backlash output f itself: first of the load stage
    place!(Load, 4);
    fn check(&self) -> Result<()> {
        let (k, omega, zeta) = (self.share, self.omega, self.zeta);
        finite("compliance share k", k, "give a finite share (0 for none)")?;
        if k != 0.0 && !in_domain(omega, zeta) {
            return Err(Error::Model(format!(
                "compliance omega = {omega}, zeta = {zeta}: give 0 < omega < pi (rad/sample) \
                 and 0 < zeta < 1 (a lightly damped mode)"
            )));
        }
        Ok(())
    }
    fn start(&self, _x0: f64, y0: f64) -> Self {
        // the resonance at rest on y(0)
        Compliance {
            h1: y0,
            h2: y0,
            ..self.clone()
        }
    }
    #[inline]
    fn output(&mut self, out: f64, s: &Sample) -> f64 {
        if self.share == 0.0 {
            return out;
        }
        let f = s.f;
        let h = self.g * f - self.d1 * self.h1 - self.d2 * self.h2;
        self.h2 = self.h1;
        self.h1 = h;
        (1.0 - self.share) * f + self.share * h
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.share, self.omega, self.zeta]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["k".into(), "omega".into(), "zeta".into()]
    }
    /// k >= 0, 0 <= omega <= pi, 0 <= zeta <= 1 (`feasible`: the open intervals).
    fn bounds(&self, k: usize) -> (f64, f64) {
        match k {
            0 => (0.0, f64::INFINITY),
            1 => (0.0, std::f64::consts::PI),
            _ => (0.0, 1.0),
        }
    }
    fn feasible(&self) -> bool {
        self.check().is_ok() && in_domain(self.omega, self.zeta)
    }
    /// The resonance runs at k = 0 too (its output is the derivative in k there: H f - f).
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        if in_domain(self.omega, self.zeta) {
            let ((d1, d2), partials) = resonance(self.omega, self.zeta);
            (e.d1, e.d2, e.g, e.partials) = (d1, d2, 1.0 + d1 + d2, partials);
        }
        e.dh1 = vec![0.0; dx0.len()];
        e.dh2 = vec![0.0; dx0.len()];
        e
    }
    /// h = g f - d1 h1 - d2 h2 (g = 1 + d1 + d2) differentiated in f, h1, h2 and through
    /// d1, d2 in (omega, zeta); d out = (1 - k) df + k dh + (h - f) dk.
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let (f, k) = (s.f, self.share);
        let (g, d1, d2, h1, h2) = (self.g, self.d1, self.d2, self.h1, self.h2);
        let h = g * f - d1 * h1 - d2 * h2;
        // the new dh in dh2's buffer, then the two swap
        for ((n, o1), df) in self.dh2.iter_mut().zip(&self.dh1).zip(d.df) {
            *n = g * df - d1 * o1 - d2 * *n;
        }
        let [[d1_w, d1_z], [d2_w, d2_z]] = self.partials;
        add_at(&mut self.dh2, cols[1], f * (d1_w + d2_w) - h1 * d1_w - h2 * d2_w);
        add_at(&mut self.dh2, cols[2], f * (d1_z + d2_z) - h1 * d1_z - h2 * d2_z);
        std::mem::swap(&mut self.dh1, &mut self.dh2);
        self.h2 = h1;
        self.h1 = h;
        for ((o, df), dh) in dout.iter_mut().zip(d.df).zip(&self.dh1) {
            *o = (1.0 - k) * df + k * dh;
        }
        add_at(dout, cols[0], h - f);
        if k == 0.0 {
            out
        } else {
            (1.0 - k) * f + k * h
        }
    }
}
