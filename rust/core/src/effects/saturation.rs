//! Saturation: the drive input clipped to [lo, hi] before the linear block.
//!
//! Stage: Drive (the actuator's input limit; `state_saturation` limits x(t) itself and
//! `sensor_saturation` the measured output).

use super::{add_at, arity, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "saturation";

/// Bounds (lo, hi) of the drive input; (-inf, +inf) is none.
#[derive(Debug, Clone, PartialEq)]
pub struct Saturation {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

/// From [lo, hi].
pub fn from_parameters(p: &[f64]) -> Result<Saturation> {
    arity(NAME, p, "lo, hi", 2)?;
    Ok(Saturation { lo: p[0], hi: p[1] })
}

impl Effect for Saturation {
    place!(Drive, 1);
    fn check(&self) -> Result<()> {
        let (lo, hi) = (self.lo, self.hi);
        if lo.is_nan() || hi.is_nan() || lo >= hi {
            return Err(Error::Model(format!(
                "saturation bounds lo = {lo}, hi = {hi}: give lo < hi (+-inf for no bound)"
            )));
        }
        Ok(())
    }
    #[inline]
    fn drive(&mut self, v: f64, _s: &Sample) -> f64 {
        if v < self.lo {
            self.lo
        } else if v > self.hi {
            self.hi
        } else {
            v
        }
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.lo, self.hi]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["lo".into(), "hi".into()]
    }
    /// Clipped: the bound's column; at an edge (v = lo or hi) the value is v's, so is the
    /// derivative.
    #[inline]
    fn drive_tangent(
        &mut self,
        v: f64,
        dv: &mut [f64],
        _s: &Sample,
        _d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        if v < self.lo {
            dv.fill(0.0);
            add_at(dv, cols[0], 1.0);
            self.lo
        } else if v > self.hi {
            dv.fill(0.0);
            add_at(dv, cols[1], 1.0);
            self.hi
        } else {
            v
        }
    }
}
