//! Extra plays on x: y += sum_k w_k play_{r_k}(x).
//!
//! Stage: Load. The plays are further hysteresis of the mechanism, in parallel with the
//! backlash on the same x(t), so their sum joins f(t) before a sandwich's output block.

use super::{add_at, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "hysteresis_memory";

/// Plays (r_k, w_k) on x and their memories.
#[derive(Debug, Clone, PartialEq)]
pub struct HysteresisMemory {
    /// (half-width r_k, weight w_k) of each play.
    pub plays: Vec<(f64, f64)>,
    state: Vec<f64>,
    /// d state / d theta, one row of p per play (tangent simulations only).
    dstate: Vec<f64>,
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
        dstate: Vec::new(),
    })
}

impl Effect for HysteresisMemory {
    place!(Load, 5);
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
            dstate: Vec::new(),
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
    fn parameters(&self) -> Vec<f64> {
        self.plays.iter().flat_map(|&(r, w)| [r, w]).collect()
    }
    fn parameter_names(&self) -> Vec<String> {
        (1..=self.plays.len())
            .flat_map(|k| [format!("r_{k}"), format!("w_{k}")])
            .collect()
    }
    /// r_k >= 0 (w_k free).
    fn bounds(&self, k: usize) -> (f64, f64) {
        if k % 2 == 0 {
            (0.0, f64::INFINITY)
        } else {
            (f64::NEG_INFINITY, f64::INFINITY)
        }
    }
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        e.dstate = dx0.repeat(self.plays.len());
        e
    }
    /// Each play p = max(x - r, min(x + r, p(t-1))): on its lower edge d p = dx - dr, on
    /// its upper edge dx + dr, holding d p(t-1) (at a tie the value is the held one, so is
    /// the derivative); d out += w d p + p dw.
    #[inline]
    fn output_tangent(
        &mut self,
        mut out: f64,
        dout: &mut [f64],
        s: &Sample,
        d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let (xt, n) = (s.x, dout.len());
        for (k, (p, &(r, w))) in self.state.iter_mut().zip(&self.plays).enumerate() {
            let dp = &mut self.dstate[k * n..(k + 1) * n];
            let (lo, hi) = (xt - r, xt + r);
            let inner = hi.min(*p);
            let moved = lo.max(inner);
            if lo > inner {
                dp.copy_from_slice(d.dx);
                add_at(dp, cols[2 * k], -1.0);
            } else if hi < *p {
                dp.copy_from_slice(d.dx);
                add_at(dp, cols[2 * k], 1.0);
            }
            *p = moved;
            out += w * *p;
            for (o, v) in dout.iter_mut().zip(dp.iter()) {
                *o += w * v;
            }
            add_at(dout, cols[2 * k + 1], *p);
        }
        out
    }
}
