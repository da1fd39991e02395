//! State saturation: x(t) := clip(x(t), lo, hi) inside the linear block's recursion (eq 16),
//! so the clipped value is what x(t+1) remembers: a tank that overflows, a motor against its
//! travel stop. (-inf, +inf) is none.
//!
//! Stage: State (on x(t) itself, before the recursion stores it and the backlash sees it).
//! Unlike `saturation` (the drive input u's limit) the limit here holds the state, so the
//! block leaves the stop as soon as its drive turns, without first unwinding what a linear
//! block would have integrated past it.

use super::{Columns, Effect, Sample, Stage, arity, check_clip, clip, clip_tangent};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "state_saturation";

/// Bounds (lo, hi) of x(t); (-inf, +inf) is none.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSaturation {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

/// From [lo, hi].
pub fn from_parameters(p: &[f64]) -> Result<StateSaturation> {
    arity(NAME, p, "lo, hi", 2)?;
    Ok(StateSaturation { lo: p[0], hi: p[1] })
}

impl Effect for StateSaturation {
    place!(State, 0);
    fn check(&self) -> Result<()> {
        check_clip(NAME, self.lo, self.hi)
    }
    #[inline]
    fn state(&mut self, x: f64, _s: &Sample) -> f64 {
        clip(x, self.lo, self.hi)
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.lo, self.hi]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["lo".into(), "hi".into()]
    }
    /// Clipped: x(t) is the bound, its derivative the bound's column (and nothing of the
    /// past: the stop cuts the recursion's memory); at an edge the value is x's, so is the
    /// derivative.
    #[inline]
    fn state_tangent(&mut self, x: f64, dx: &mut [f64], _s: &Sample, cols: &Columns) -> f64 {
        clip_tangent(x, dx, self.lo, self.hi, cols)
    }
}
