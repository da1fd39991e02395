//! Sensor saturation: the measured output clipped to [lo, hi] (a sensor's or its amplifier's
//! range). (-inf, +inf) is none.
//!
//! Stage: Output (the sensor's side: after a sandwich's output block and the output offset,
//! before the quantiser).

use super::{add_at, arity, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

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
        let (lo, hi) = (self.lo, self.hi);
        if lo.is_nan() || hi.is_nan() || lo >= hi {
            return Err(Error::Model(format!(
                "sensor_saturation bounds lo = {lo}, hi = {hi}: give lo < hi (+-inf for no \
                 bound)"
            )));
        }
        Ok(())
    }
    #[inline]
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        if out < self.lo {
            self.lo
        } else if out > self.hi {
            self.hi
        } else {
            out
        }
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
        if out < self.lo {
            dout.fill(0.0);
            add_at(dout, cols[0], 1.0);
            self.lo
        } else if out > self.hi {
            dout.fill(0.0);
            add_at(dout, cols[1], 1.0);
            self.hi
        } else {
            out
        }
    }
}
