//! Width drift: c_L(t) = c_L + dc_L tau, c_R(t) = c_R + dc_R tau, tau = (t0 + t) / time_scale.
//!
//! Stage: Widths (wear of the backlash itself).

use super::{add_at, arity, finite, Columns, Effect, Sample, Stage};
use crate::error::Result;

/// Name in the catalogue.
pub const NAME: &str = "width_drift";

/// Drift rates (dc_L, dc_R) of the dead-band widths per time unit.
#[derive(Debug, Clone, PartialEq)]
pub struct WidthDrift {
    /// dc_L.
    pub left: f64,
    /// dc_R.
    pub right: f64,
}

/// From [dc_L, dc_R].
pub fn from_parameters(p: &[f64]) -> Result<WidthDrift> {
    arity(NAME, p, "dc_L, dc_R", 2)?;
    Ok(WidthDrift {
        left: p[0],
        right: p[1],
    })
}

impl Effect for WidthDrift {
    place!(Widths, 3);
    fn check(&self) -> Result<()> {
        finite("dc_L", self.left, "give a finite drift rate")?;
        finite("dc_R", self.right, "give a finite drift rate")
    }
    #[inline]
    fn widths(&self, c_left: f64, c_right: f64, s: &Sample) -> Option<(f64, f64)> {
        if self.left != 0.0 || self.right != 0.0 {
            Some((c_left + self.left * s.tau, c_right + self.right * s.tau))
        } else {
            None
        }
    }
    fn parameters(&self) -> Vec<f64> {
        vec![self.left, self.right]
    }
    fn parameter_names(&self) -> Vec<String> {
        vec!["dc_L".into(), "dc_R".into()]
    }
    /// d c_L(t) += tau d dc_L, d c_R(t) += tau d dc_R (at zero rates too).
    #[inline]
    fn widths_tangent(
        &self,
        c: (f64, f64),
        dc: (&mut [f64], &mut [f64]),
        s: &Sample,
        cols: &Columns,
    ) -> (f64, f64) {
        add_at(dc.0, cols[0], s.tau);
        add_at(dc.1, cols[1], s.tau);
        self.widths(c.0, c.1, s).unwrap_or(c)
    }
}
