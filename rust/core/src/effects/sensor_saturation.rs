//! Sensor saturation: the measured output clipped to [lo, hi] (a sensor's or its amplifier's
//! range). (-inf, +inf) is none.
//!
//! Stage: Output (the sensor's side: after a sandwich's output block and the output offset,
//! before the quantiser).

use super::{Columns, Effect, Sample, Stage, Tangent, arity, check_clip, clip, clip_tangent};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "sensor_saturation";

/// Bounds (lo, hi) of the measured output; (-inf, +inf) is none.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSaturation {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

/// From [lo, hi].
pub fn from_parameters(p: &[f64]) -> Result<SensorSaturation> {
    arity(NAME, p, "lo, hi", 2)?;
    Ok(SensorSaturation { lo: p[0], hi: p[1] })
}

impl Effect for SensorSaturation {
    place!(Output, 9);
    fn check(&self) -> Result<()> {
        check_clip(NAME, self.lo, self.hi)
    }
    #[inline]
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        clip(out, self.lo, self.hi)
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.lo, self.hi]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["lo".into(), "hi".into()]
    }
    /// Clipped: the bound's column; at an edge the value is the output's, so is the
    /// derivative.
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        _s: &Sample,
        _d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        clip_tangent(out, dout, self.lo, self.hi, cols)
    }
}
