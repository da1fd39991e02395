//! Friction: u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1), sign(0) = 0
//! (x(t) depends on u_eff up to t-1 only, so this is causal).

use super::{arity, finite, Effect, Sample, Stage};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "friction";

/// Coulomb and viscous friction (F_c, F_v).
#[derive(Debug, Clone, PartialEq)]
pub struct Friction {
    /// Coulomb friction F_c.
    pub coulomb: f64,
    /// Viscous friction F_v.
    pub viscous: f64,
}

/// From [F_c, F_v].
pub fn from_parameters(p: &[f64]) -> Result<Friction> {
    arity(NAME, p, "F_c, F_v", 2)?;
    Ok(Friction {
        coulomb: p[0],
        viscous: p[1],
    })
}

#[inline(always)]
fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl Effect for Friction {
    // on the delayed, clipped input
    place!(Drive, 2);
    fn check(&self) -> Result<()> {
        finite("F_c", self.coulomb, "give a finite Coulomb friction")?;
        finite("F_v", self.viscous, "give a finite viscous friction")
    }
    #[inline]
    fn drive(&mut self, v: f64, s: &Sample) -> f64 {
        if self.coulomb != 0.0 || self.viscous != 0.0 {
            let vel = s.x - s.x_prev;
            v - (self.coulomb * sign(vel) + self.viscous * vel)
        } else {
            v
        }
    }
}
