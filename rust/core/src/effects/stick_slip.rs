//! Stick-slip friction in the drive's force balance (Karnopp's rule, with a Stribeck dip).
//!
//! The linear block gives x(t+1) = a_1 u_eff(t) + x_free(t+1). The drive force before the
//! friction is w = u(t) - F_v v, v = x(t) - x(t-1). The input that holds the drive at rest,
//! x(t+1) = x(t), is u_stay = (x(t) - x_free) / a_1, and the friction that takes is
//! F_hold = w - u_stay. Stuck while |F_hold| <= F_c + F_s (the static friction): u_eff =
//! u_stay. Else it slides against the slip friction (F_c + F_s exp(-(v / v_s)^2)) sign(F_hold):
//! u_eff = w - that. F_s = 0 is Coulomb plus viscous friction with sticking; F_s > 0 is the
//! Stribeck effect (static friction F_c + F_s, falling to F_c as the drive speeds up). Unlike
//! [`super::friction`], whose sign(v) lags a sample, the drive here stops exactly where the
//! force is too small to move it. At F_c = F_s = F_v = 0 it is the nominal model.
//!
//! Stage: Drive (a force balance on the input block's drive).

use super::{add_at, arity, finite, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "stick_slip";

/// Stick-slip friction (F_c, F_v, F_s, v_s).
#[derive(Debug, Clone, PartialEq)]
pub struct StickSlip {
    /// Coulomb (sliding) friction F_c.
    pub coulomb: f64,
    /// Viscous friction F_v.
    pub viscous: f64,
    /// Stribeck excess F_s: static friction F_c + F_s.
    pub stribeck: f64,
    /// Stribeck velocity v_s (per sample).
    pub velocity: f64,
}

/// From [F_c, F_v, F_s, v_s].
pub fn from_parameters(p: &[f64]) -> Result<StickSlip> {
    arity(NAME, p, "F_c, F_v, F_s, v_s", 4)?;
    Ok(StickSlip {
        coulomb: p[0],
        viscous: p[1],
        stribeck: p[2],
        velocity: p[3],
    })
}

impl StickSlip {
    fn active(&self) -> bool {
        self.coulomb != 0.0 || self.viscous != 0.0 || self.stribeck != 0.0
    }
}

impl Effect for StickSlip {
    // on the delayed, clipped input, where friction acts
    place!(Drive, 3);
    fn check(&self) -> Result<()> {
        finite("F_c", self.coulomb, "give a finite Coulomb friction")?;
        finite("F_v", self.viscous, "give a finite viscous friction")?;
        finite("F_s", self.stribeck, "give a finite Stribeck excess")?;
        if !(self.velocity.is_finite() && self.velocity > 0.0) {
            return Err(Error::Model(format!(
                "v_s = {}: give a positive Stribeck velocity",
                self.velocity
            )));
        }
        Ok(())
    }
    fn needs_free(&self) -> bool {
        true
    }
    #[inline]
    fn drive(&mut self, v: f64, s: &Sample) -> f64 {
        if !self.active() {
            return v;
        }
        let vel = s.x - s.x_prev;
        let w = v - self.viscous * vel;
        if s.gain == 0.0 {
            return w;
        }
        let stay = (s.x - s.x_free) / s.gain;
        let hold = w - stay;
        if hold.abs() <= self.coulomb + self.stribeck {
            stay
        } else {
            let dip = (-(vel / self.velocity).powi(2)).exp();
            w - (self.coulomb + self.stribeck * dip) * hold.signum()
        }
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.coulomb, self.viscous, self.stribeck, self.velocity]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["F_c".into(), "F_v".into(), "F_s".into(), "v_s".into()]
    }
    /// Friction dissipates: F_c, F_v, F_s >= 0; v_s > 0.
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (0.0, f64::INFINITY)
    }
    fn feasible(&self) -> bool {
        self.check().is_ok()
    }
    /// Stuck: d u_eff = (dx(t) - dx_free) / a_1 - (x(t) - x_free) / a_1^2 da_1. Sliding:
    /// d u_eff = dv - F_v (dx(t) - dx(t-1)) - vel dF_v - sign(F_hold) dS, S = F_c + F_s E,
    /// E = exp(-(vel / v_s)^2): dS = dF_c + E dF_s + F_s E (2 vel^2 / v_s^3) dv_s
    /// - F_s E (2 vel / v_s^2) (dx(t) - dx(t-1)). At the switch the branch taken by the value.
    #[inline]
    fn drive_tangent(
        &mut self,
        v: f64,
        dv: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        // at zero size (not active) the value is v, and the derivatives those of the limit:
        // sliding, since no friction holds the drive
        let out = self.drive(v, s);
        let vel = s.x - s.x_prev;
        let w = v - self.viscous * vel;
        if s.gain == 0.0 {
            for ((o, a), b) in dv.iter_mut().zip(d.dx).zip(d.dx_prev) {
                *o -= self.viscous * (a - b);
            }
            add_at(dv, cols[1], -vel);
            return out;
        }
        let stay = (s.x - s.x_free) / s.gain;
        let hold = w - stay;
        if self.active() && hold.abs() <= self.coulomb + self.stribeck {
            for ((o, a), f) in dv.iter_mut().zip(d.dx).zip(d.dx_free) {
                *o = (a - f) / s.gain;
            }
            dv[0] -= stay / s.gain;
        } else {
            let dip = (-(vel / self.velocity).powi(2)).exp();
            let sign = hold.signum();
            // d vel enters through F_v and the Stribeck dip
            let k = self.viscous - sign * self.stribeck * dip * 2.0 * vel / self.velocity.powi(2);
            for ((o, a), b) in dv.iter_mut().zip(d.dx).zip(d.dx_prev) {
                *o -= k * (a - b);
            }
            add_at(dv, cols[0], -sign);
            add_at(dv, cols[1], -vel);
            add_at(dv, cols[2], -sign * dip);
            add_at(
                dv,
                cols[3],
                -sign * self.stribeck * dip * 2.0 * vel * vel / self.velocity.powi(3),
            );
        }
        out
    }
}
