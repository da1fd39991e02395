//! Feedback hysteresis: a hysteretic restoring force fed back around the linear dynamics
//! (Bouc-Wen family, with a static cubic stiffness as its non-hysteretic limit: a Duffing
//! oscillator). On the drive:
//!
//!   u_eff(t) = u(t) - z(t) - k_3 x(t)^3,
//!   z(t) = z(t-1) + alpha v - beta |v| z(t-1) - gamma v |z(t-1)|,   v = x(t) - x(t-1),
//!
//! the Bouc-Wen law dz = alpha dx - beta |dx| |z|^(nu-1) z - gamma dx |z|^nu with nu = 1 (as
//! in the Bouc-Wen benchmark) stepped once a sample with the velocity of x, z at rest (0) at
//! the start. x(t) depends on u_eff up to t-1 only, so this is causal. Under a steady slide z
//! tends to alpha / (beta + gamma sign(v z)); the explicit step stays bounded while
//! (beta + |gamma|) |v| <= 1, and a parameter set whose z runs away makes x non-finite, which
//! the pass refuses (ModelError). At alpha = 0 and k_3 = 0 (z stays 0) it is the nominal model.

use super::{Columns, Effect, Sample, Stage, Tangent, add_at, arity, finite, sign};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "feedback_hysteresis";

/// Bouc-Wen feedback (alpha, beta, gamma) with a cubic stiffness k_3, and the state z.
#[derive(Debug, Clone, PartialEq)]
pub struct FeedbackHysteresis {
    /// The hysteretic stiffness alpha.
    pub alpha: f64,
    /// The Bouc-Wen shape beta.
    pub beta: f64,
    /// The Bouc-Wen shape gamma.
    pub gamma: f64,
    /// The cubic stiffness k_3.
    pub cubic: f64,
    z: f64,
    /// d z / d theta (tangent simulations only).
    dz: Vec<f64>,
}

/// From [alpha, beta, gamma, k_3].
pub fn from_parameters(p: &[f64]) -> Result<FeedbackHysteresis> {
    arity(NAME, p, "alpha, beta, gamma, k_3", 4)?;
    Ok(FeedbackHysteresis {
        alpha: p[0],
        beta: p[1],
        gamma: p[2],
        cubic: p[3],
        z: 0.0,
        dz: Vec::new(),
    })
}

impl FeedbackHysteresis {
    fn active(&self) -> bool {
        self.alpha != 0.0 || self.cubic != 0.0
    }

    /// z(t) from z(t-1) and the velocity v.
    #[inline(always)]
    fn next(&self, v: f64) -> f64 {
        let z1 = self.z;
        z1 + self.alpha * v - self.beta * v.abs() * z1 - self.gamma * v * z1.abs()
    }
}

impl Effect for FeedbackHysteresis {
    // on the drive after the friction: the restoring force in the same force balance
    place!(Drive, 4);
    fn check(&self) -> Result<()> {
        finite("alpha", self.alpha, "give a finite hysteretic stiffness")?;
        finite("beta", self.beta, "give a finite Bouc-Wen beta")?;
        finite("gamma", self.gamma, "give a finite Bouc-Wen gamma")?;
        finite("k_3", self.cubic, "give a finite cubic stiffness")
    }
    fn start(&self, _x0: f64, _y0: f64) -> Self {
        FeedbackHysteresis {
            z: 0.0,
            dz: Vec::new(),
            ..self.clone()
        }
    }
    #[inline]
    fn drive(&mut self, v: f64, s: &Sample) -> f64 {
        if !self.active() {
            return v;
        }
        self.z = self.next(s.x - s.x_prev);
        v - self.z - self.cubic * s.x * s.x * s.x
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.alpha, self.beta, self.gamma, self.cubic]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["alpha".into(), "beta".into(), "gamma".into(), "k_3".into()]
    }
    /// alpha >= 0 (a restoring force), beta >= 0; gamma and k_3 free (softening or
    /// stiffening).
    fn bounds(&self, k: usize) -> (f64, f64) {
        match k {
            0 | 1 => (0.0, f64::INFINITY),
            _ => (f64::NEG_INFINITY, f64::INFINITY),
        }
    }
    /// Where the refit may take it: |gamma| <= 2 beta. Bouc-Wen's condition for a z bounded
    /// under any motion is |gamma| <= beta (|z| <= alpha / (beta - |gamma|)); the Bouc-Wen
    /// benchmark's own hysteresis has gamma = -1.375 beta (beta 800, gamma -1100: z grows on
    /// loading, bounded over its stroke), which |gamma| <= beta cut off (multisine error
    /// 4.7e-5 m at the bound). A set whose z runs away on a record ends the pass in a
    /// ModelError, which the refit and the diagnosis treat as unusable.
    fn feasible(&self) -> bool {
        self.check().is_ok() && self.gamma.abs() <= 2.0 * self.beta
    }
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        e.dz = vec![0.0; dx0.len()];
        e
    }
    /// dz = (1 - beta |v|) dz1 - gamma v d|z1| + (alpha - beta sign(v) z1 - gamma |z1|) dv +
    /// v dalpha - |v| z1 dbeta - v |z1| dgamma, dv = dx(t) - dx(t-1), with the one-sided
    /// derivatives of |.| at 0: d|v| = sign(v) dv with sign(0) = 0 (v = 0 is a standstill, not
    /// a crossing), and d|z1| = |dz1| at z1 = 0 (the derivative as theta_j grows: at alpha = 0,
    /// the edge of its domain, z = alpha zeta(t) for alpha >= 0, and that is zeta);
    /// d u_eff = dv_in - dz - 3 k_3 x^2 dx - x^3 dk_3. The state runs at zero size too.
    #[inline]
    fn drive_tangent(
        &mut self,
        v: f64,
        dv: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let (vel, x, z1) = (s.x - s.x_prev, s.x, self.z);
        let c_z = 1.0 - self.beta * vel.abs();
        let c_v = self.alpha - self.beta * sign(vel) * z1 - self.gamma * z1.abs();
        let g = self.gamma * vel;
        for ((o, a), b) in self.dz.iter_mut().zip(d.dx).zip(d.dx_prev) {
            // d|z1| = sign(z1) dz1; at z1 = 0 the derivative into theta_j > 0, |dz1_j|
            let dabs = if z1 == 0.0 { o.abs() } else { sign(z1) * *o };
            *o = c_z * *o - g * dabs + c_v * (a - b);
        }
        add_at(&mut self.dz, cols[0], vel);
        add_at(&mut self.dz, cols[1], -vel.abs() * z1);
        add_at(&mut self.dz, cols[2], -vel * z1.abs());
        let k = 3.0 * self.cubic * x * x;
        for ((o, dz), dx) in dv.iter_mut().zip(&self.dz).zip(d.dx) {
            *o -= dz + k * dx;
        }
        add_at(dv, cols[3], -x * x * x);
        // z stays 0 at alpha = 0 from rest
        self.z = self.next(vel);
        if self.active() {
            v - self.z - self.cubic * x * x * x
        } else {
            v
        }
    }
}
