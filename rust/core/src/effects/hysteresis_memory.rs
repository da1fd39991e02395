//! Extra plays on x: y += sum_k w_k play_{r_k}(x).

use super::{Effect, Sample, Stage};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "hysteresis_memory";

/// Plays (r_k, w_k) on x and their memories.
#[derive(Debug, Clone, PartialEq)]
pub struct HysteresisMemory {
    /// (half-width r_k, weight w_k) of each play.
    pub plays: Vec<(f64, f64)>,
    state: Vec<f64>,
}

/// From [r_1, w_1, r_2, w_2, ...] (any number of plays).
pub fn from_parameters(p: &[f64]) -> Result<HysteresisMemory> {
    if p.len() % 2 != 0 {
        return Err(Error::Model(format!(
            "{} play parameters: give pairs (r_k, w_k), one weight per play",
            p.len()
        )));
    }
    let plays: Vec<(f64, f64)> = p.chunks_exact(2).map(|c| (c[0], c[1])).collect();
    Ok(HysteresisMemory {
        state: vec![0.0; plays.len()],
        plays,
    })
}

impl Effect for HysteresisMemory {
    place!(Output, 5);
    fn check(&self) -> Result<()> {
        for &(r, w) in &self.plays {
            if !(r.is_finite() && r >= 0.0 && w.is_finite()) {
                return Err(Error::Model(format!(
                    "play (r = {r}, w = {w}): give a finite half-width r >= 0 and a finite weight"
                )));
            }
        }
        Ok(())
    }
    fn start(&self, x0: f64, _y0: f64) -> Self {
        // each play at rest on x(0)
        HysteresisMemory {
            plays: self.plays.clone(),
            state: vec![x0; self.plays.len()],
        }
    }
    #[inline]
    fn output(&mut self, mut out: f64, s: &Sample) -> f64 {
        let xt = s.x;
        for (p, &(r, w)) in self.state.iter_mut().zip(&self.plays) {
            *p = (xt - r).max((xt + r).min(*p));
            out += w * *p;
        }
        out
    }
}
