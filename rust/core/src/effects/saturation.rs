//! Saturation: the drive input clipped to [lo, hi] before the linear block.
//!
//! Stage: Drive (the actuator's input limit; `state_saturation` limits x(t) itself and
//! `sensor_saturation` the measured output).

use super::{Columns, Effect, Sample, Stage, Tangent, arity, check_clip, clip, clip_tangent};
use crate::error::Result;

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
        check_clip(NAME, self.lo, self.hi)
    }
    #[inline]
    fn drive(&mut self, v: f64, _s: &Sample) -> f64 {
        clip(v, self.lo, self.hi)
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
        clip_tangent(v, dv, self.lo, self.hi, cols)
    }
}
