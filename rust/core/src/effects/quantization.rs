//! Quantiser: y := q round(y / q) (q = 0: none), after everything else.
//!
//! Stage: Output, last: the sensor's resolution, on the measured output.

use super::{arity, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "quantization";

/// Quantiser step q.
#[derive(Debug, Clone, PartialEq)]
pub struct Quantization {
    /// q (0: none).
    pub quantum: f64,
}

/// From [q].
pub fn from_parameters(p: &[f64]) -> Result<Quantization> {
    arity(NAME, p, "q", 1)?;
    Ok(Quantization { quantum: p[0] })
}

impl Effect for Quantization {
    // last: the sensor's resolution
    place!(Output, 10);
    fn check(&self) -> Result<()> {
        if !(self.quantum.is_finite() && self.quantum >= 0.0) {
            return Err(Error::Model(format!(
                "quantiser step q = {}: give q >= 0 (0 for no quantiser)",
                self.quantum
            )));
        }
        Ok(())
    }
    #[inline]
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        if self.quantum > 0.0 {
            self.quantum * (out / self.quantum).round()
        } else {
            out
        }
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.quantum]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["q".into()]
    }
    /// The output is piecewise constant in q: searched outside the refit.
    fn differentiable(&self, _k: usize) -> bool {
        false
    }
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (0.0, f64::INFINITY)
    }
    /// q > 0: round is piecewise constant, so the output's derivative in every parameter
    /// is 0 (almost everywhere; at a step the value takes one side, so does the derivative).
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        s: &Sample,
        _d: &Tangent,
        _cols: &Columns,
    ) -> f64 {
        if self.quantum > 0.0 {
            dout.fill(0.0);
        }
        self.output(out, s)
    }
}
