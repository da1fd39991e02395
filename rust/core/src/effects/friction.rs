//! Friction: u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1), sign(0) = 0
//! (x(t) depends on u_eff up to t-1 only, so this is causal).
//!
//! Stage: Drive (the friction force opposes the motor's drive, fed back from x).

use super::{Columns, Effect, Sample, Stage, Tangent, add_at, arity, finite, sign};
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
    fn parameters(&self) -> Vec<f64> {
        vec![self.coulomb, self.viscous]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["F_c".into(), "F_v".into()]
    }
    /// Friction dissipates: F_c, F_v >= 0.
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (0.0, f64::INFINITY)
    }
    /// d u_eff = dv - sign(v) dF_c - v dF_v - F_v (dx(t) - dx(t-1)); sign is flat (its
    /// derivative 0, also at v = 0 where it is 0). At F_c = F_v = 0 the derivatives in F_c
    /// and F_v are those of the limit.
    #[inline]
    fn drive_tangent(
        &mut self,
        v: f64,
        dv: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let vel = s.x - s.x_prev;
        if self.viscous != 0.0 {
            for ((o, a), b) in dv.iter_mut().zip(d.dx).zip(d.dx_prev) {
                *o -= self.viscous * (a - b);
            }
        }
        add_at(dv, cols[0], -sign(vel));
        add_at(dv, cols[1], -vel);
        self.drive(v, s)
    }
}
