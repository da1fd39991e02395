//! Output offset and drift: y += o_0 + o_1 tau.
//!
//! Stage: Output. A sensor's offset and its drift: on the measured output, after a
//! sandwich's output block.

use super::{add_at, arity, finite, Columns, Effect, Sample, Stage, Tangent};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "output_offset";

/// Offset o_0 and its drift rate o_1 per time unit.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputOffset {
    /// o_0.
    pub offset: f64,
    /// o_1.
    pub rate: f64,
}

/// From [o_0, o_1].
pub fn from_parameters(p: &[f64]) -> Result<OutputOffset> {
    arity(NAME, p, "o_0, o_1", 2)?;
    Ok(OutputOffset {
        offset: p[0],
        rate: p[1],
    })
}

impl Effect for OutputOffset {
    place!(Output, 8);
    fn check(&self) -> Result<()> {
        finite("o_0", self.offset, "give a finite offset")?;
        finite("o_1", self.rate, "give a finite offset drift")
    }
    #[inline]
    fn output(&mut self, out: f64, s: &Sample) -> f64 {
        out + (self.offset + self.rate * s.tau)
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.offset, self.rate]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["o_0".into(), "o_1".into()]
    }
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        s: &Sample,
        _d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        add_at(dout, cols[0], 1.0);
        add_at(dout, cols[1], s.tau);
        self.output(out, s)
    }
}
