//! Dead time: the linear block sees u(t - d), d extra samples (rest before the record).
//!
//! Stage: Drive (a transport delay of the command, before the input block).

use super::{arity, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "dead_time";

/// Extra input delay of `delay` samples.
#[derive(Debug, Clone, PartialEq)]
pub struct DeadTime {
    /// d, in samples.
    pub delay: usize,
}

/// From [d] (a whole number >= 0).
pub fn from_parameters(p: &[f64]) -> Result<DeadTime> {
    arity(NAME, p, "d", 1)?;
    let d = p[0];
    if !(d.is_finite() && d >= 0.0 && d.fract() == 0.0) {
        return Err(Error::Model(format!(
            "dead time d = {d}: give a whole number of samples >= 0"
        )));
    }
    Ok(DeadTime { delay: d as usize })
}

impl Effect for DeadTime {
    // the source of the drive input: first
    place!(Drive, 0);
    fn check(&self) -> Result<()> {
        Ok(())
    }
    #[inline]
    fn drive(&mut self, _v: f64, s: &Sample) -> f64 {
        if s.t >= self.delay {
            s.u[s.t - self.delay]
        } else {
            0.0
        }
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.delay as f64]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["d".into()]
    }
    /// d is a whole number of samples: searched outside the refit.
    fn differentiable(&self, _k: usize) -> bool {
        false
    }
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (0.0, f64::INFINITY)
    }
    #[inline]
    fn drive_tangent(
        &mut self,
        v: f64,
        dv: &mut [f64],
        s: &Sample,
        _d: &Tangent,
        _cols: &Columns,
    ) -> f64 {
        // the source of the drive: the measured input, no parameter in it
        dv.fill(0.0);
        self.drive(v, s)
    }
}
