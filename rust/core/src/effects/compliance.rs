//! Compliance: y = (1 - k) f + k H(q) f, H a unit-DC-gain 2nd-order resonance with natural
//! frequency omega (rad/sample) and damping zeta (k = 1: the pure resonance).

use super::{arity, finite, Effect, Sample, Stage};
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
}

/// From [k, omega, zeta].
pub fn from_parameters(p: &[f64]) -> Result<Compliance> {
    arity(NAME, p, "k, omega, zeta", 3)?;
    let (k, omega, zeta) = (p[0], p[1], p[2]);
    // H(q) = g / (1 + d1 q^-1 + d2 q^-2), poles exp(omega (-zeta +- j sqrt(1 - zeta^2))).
    let (d1, d2) = if k != 0.0 {
        let rho = (-zeta * omega).exp();
        (
            -2.0 * rho * (omega * (1.0 - zeta * zeta).sqrt()).cos(),
            rho * rho,
        )
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
    })
}

impl Effect for Compliance {
    // on the backlash output f itself: first of the output stage
    place!(Output, 4);
    fn check(&self) -> Result<()> {
        let (k, omega, zeta) = (self.share, self.omega, self.zeta);
        finite("compliance share k", k, "give a finite share (0 for none)")?;
        if k != 0.0 && !(omega > 0.0 && omega < std::f64::consts::PI && zeta > 0.0 && zeta < 1.0)
        {
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
}
