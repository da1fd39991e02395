//! Creep: slow relaxation of the output after the input stops changing (piezo actuators).
//! The output so far, f(t) (the backlash's, after compliance, friction and plays), passes
//! through slow first-order modes k = 1..K:
//!
//!   y(t) = f(t) + sum_k g_k (c_k(t) - f(t)),   c_k(t) = p_k c_k(t-1) + (1 - p_k) f(t),
//!   p_k = exp(-1 / T_k),   T_k = exp(l_k) samples,
//!
//! so after a step of f the output jumps to (1 - sum g_k) of it and creeps to it with the
//! time constants T_k (c_k is f seen through a unit-DC-gain low-pass; the creep has unit
//! gain). Parameters in pairs (g_k, l_k): the share g_k (zero size 0) and the log time
//! constant l_k in samples (LM sees a scale-free parameter; the domain is T_k in
//! [10, 1e5] samples). The modes start at rest on y(0).

use super::{add_at, Columns, Effect, Sample, Stage, Tangent};
use crate::error::{Error, Result};

/// Name in the catalogue.
pub const NAME: &str = "creep";

/// The least and greatest time constants, in samples.
pub const T_MIN: f64 = 10.0;
/// See [`T_MIN`].
pub const T_MAX: f64 = 1e5;

/// Creep modes (g_k, l_k) and their memories c_k.
#[derive(Debug, Clone, PartialEq)]
pub struct Creep {
    /// (share g_k, log time constant l_k) of each mode.
    pub modes: Vec<(f64, f64)>,
    c: Vec<f64>,
    /// d c_k / d theta, one row of p per mode, and a copy of d f (tangent simulations only).
    dc: Vec<f64>,
    df: Vec<f64>,
}

/// From [g_1, l_1, g_2, l_2, ...] (any number of modes).
pub fn from_parameters(p: &[f64]) -> Result<Creep> {
    if p.len() % 2 != 0 {
        return Err(Error::Model(format!(
            "{} creep parameters: give pairs (g_k, l_k), a share and a log time constant per mode",
            p.len()
        )));
    }
    let modes: Vec<(f64, f64)> = p.chunks_exact(2).map(|c| (c[0], c[1])).collect();
    Ok(Creep {
        c: vec![0.0; modes.len()],
        modes,
        dc: Vec::new(),
        df: Vec::new(),
    })
}

impl Effect for Creep {
    // on the mechanical output, before the offset and the quantiser
    place!(Output, 7);
    fn check(&self) -> Result<()> {
        for &(g, l) in &self.modes {
            if !g.is_finite() {
                return Err(Error::Model(format!(
                    "creep share g = {g}: give a finite share (0 for none)"
                )));
            }
            if !(l >= T_MIN.ln() && l <= T_MAX.ln()) {
                return Err(Error::Model(format!(
                    "creep log time constant l = {l}: give ln(T) for T in [{T_MIN}, {T_MAX}] \
                     samples ({:.4} <= l <= {:.4})",
                    T_MIN.ln(),
                    T_MAX.ln()
                )));
            }
        }
        Ok(())
    }
    fn start(&self, _x0: f64, y0: f64) -> Self {
        // each mode at rest on y(0)
        Creep {
            modes: self.modes.clone(),
            c: vec![y0; self.modes.len()],
            dc: Vec::new(),
            df: Vec::new(),
        }
    }
    #[inline]
    fn output(&mut self, out: f64, _s: &Sample) -> f64 {
        let mut y = out;
        for (c, &(g, l)) in self.c.iter_mut().zip(&self.modes) {
            if g == 0.0 {
                continue;
            }
            let p = (-(-l).exp()).exp();
            *c = p * *c + (1.0 - p) * out;
            y += g * (*c - out);
        }
        y
    }
    fn parameters(&self) -> Vec<f64> {
        self.modes.iter().flat_map(|&(g, l)| [g, l]).collect()
    }
    fn parameter_names(&self) -> Vec<String> {
        (1..=self.modes.len())
            .flat_map(|k| [format!("g_{k}"), format!("l_{k}")])
            .collect()
    }
    /// g_k free (creep or its overshooting counterpart), l_k in [ln 10, ln 1e5].
    fn bounds(&self, k: usize) -> (f64, f64) {
        if k % 2 == 0 {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            (T_MIN.ln(), T_MAX.ln())
        }
    }
    /// The modes run at g_k = 0 too (c_k - f is the derivative in g_k there).
    fn start_tangent(&self, x0: f64, y0: f64, dx0: &[f64], _cols: &Columns) -> Self {
        let mut e = self.start(x0, y0);
        e.dc = vec![0.0; dx0.len() * self.modes.len()];
        e.df = vec![0.0; dx0.len()];
        e
    }
    /// With df = d out so far: d c_k = p_k dc_k(t-1) + (1 - p_k) df + (c_k(t-1) - f) dp_k,
    /// dp_k = p_k e^(-l_k) dl_k; d y = df + sum_k g_k (dc_k - df) + (c_k - f) dg_k.
    #[inline]
    fn output_tangent(
        &mut self,
        out: f64,
        dout: &mut [f64],
        _s: &Sample,
        _d: &Tangent,
        cols: &Columns,
    ) -> f64 {
        let n = dout.len();
        self.df.copy_from_slice(dout);
        let df = &self.df;
        let mut y = out;
        for (k, (c, &(g, l))) in self.c.iter_mut().zip(&self.modes).enumerate() {
            let dc = &mut self.dc[k * n..(k + 1) * n];
            let rate = (-l).exp();
            let p = (-rate).exp();
            for (o, f) in dc.iter_mut().zip(df) {
                *o = p * *o + (1.0 - p) * f;
            }
            add_at(dc, cols[2 * k + 1], (*c - out) * p * rate);
            *c = p * *c + (1.0 - p) * out;
            for ((o, v), f) in dout.iter_mut().zip(dc.iter()).zip(df) {
                *o += g * (v - f);
            }
            add_at(dout, cols[2 * k], *c - out);
            if g != 0.0 {
                y += g * (*c - out);
            }
        }
        y
    }
}
