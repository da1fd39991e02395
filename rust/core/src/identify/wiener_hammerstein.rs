//! The Wiener-Hammerstein problem compiled once: u -> G1 -> x -> f -> G2 -> + offset -> y,
//! the record (u, y, warm-up) checked on construction, and theta's layout owned here:
//!
//!   x(t) = sum_{i=d1}^{nb} a_i u(t-i) - sum_{j=1}^{nb} b_j x(t-j)          G1, eq (16)
//!   f(t) = sum_{i=1}^{n} c_i (T_i(x(t) / k) - T_i(0))                      f, Chebyshev T_i
//!   w(t) = sum_{i=d2}^{ns} r_i f(t-i) - sum_{j=1}^{ns} s_j w(t-j)          G2, eq (29)
//!   y(t) = w(t) + offset                                                    (when fitted)
//!
//! theta = [a_d1..a_nb, b_1..b_nb, c_1..c_n, r_d2..r_ns, s_1..s_ns, offset], d1 = 0 with
//! an input feedthrough (else 1), d2 likewise for G2. f(0) = 0, so the model is a sandwich
//! with a zero-width backlash and tied branches plus the output offset; k is fixed (the
//! scale of x the basis is centred on, |x| <= k keeps T_i bounded by 1).
//!
//! Exact derivatives run beside the simulation (forward sensitivities, as in `sensitivity`):
//!   dx/da_i = w_u(t-i), dx/db_j = -w_x(t-j)   (u and x filtered by 1/B),
//!   df = f'(x) dx on G1's columns, df/dc_i = T_i(x/k) - T_i(0),
//!   dw = G2 applied to df on G1's and f's columns, dw/dr_i = w_f(t-i), dw/ds_j = -w_w(t-j)
//!   (f and w filtered by 1/S), dy/d offset = 1.
//! Each row is streamed into the triangular factor (no N x p Jacobian).

use crate::error::{Error, Result};
use crate::guard;
use crate::identify::gradient::OeGradient;
use crate::identify::output_error_cost;
use crate::identify::samples::Samples;
use crate::identify::sensitivity::{oe_threads, overflowed};
use crate::linalg::streaming::default_threads;
use crate::linalg::streaming::{fold_stream_shared, TriangularFactor};

/// The factor's batches the producing thread folds itself (one in OWN_EVERY), beside the
/// folding thread (`fold_stream_shared`): its rows cost about a quarter of their fold at the
/// benchmark's p = 41.
const OWN_EVERY: usize = 3;

/// Samples from which the factor's rows are made on one thread while the other folds them
/// (below `oe_threads`' threshold, where the producer folds none itself: the same bits as one
/// thread, the rows' time hidden behind the fold).
const PIPELINE_FROM: usize = 8192;
use crate::model::polynomial::spectral_radius;
use crate::model::signal::{check_same_length, check_signal};

/// A step that puts a pole of G1 or G2 at or beyond this modulus is infeasible.
pub const STABILITY_MARGIN: f64 = 0.9999;

/// The structure of a Wiener-Hammerstein model: the orders of G1 (nb) and G2 (ns), the
/// degree n of f, the feedthroughs (a lag-0 term in G1 / G2) and whether an output offset is
/// a parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WhStructure {
    pub nb: usize,
    pub ns: usize,
    pub degree: usize,
    pub feedthrough: bool,
    pub output_feedthrough: bool,
    pub offset: bool,
}

/// The blocks of theta, borrowed.
struct Parts<'a> {
    a: &'a [f64],
    b: &'a [f64],
    c: &'a [f64],
    r: &'a [f64],
    s: &'a [f64],
    offset: f64,
}

impl WhStructure {
    /// A structure; orders and degree >= 1.
    pub fn new(
        nb: usize,
        ns: usize,
        degree: usize,
        feedthrough: bool,
        output_feedthrough: bool,
        offset: bool,
    ) -> Result<Self> {
        for (name, v) in [("nb", nb), ("ns", ns), ("degree", degree)] {
            if v < 1 {
                return Err(Error::Data(format!(
                    "{name} = {v}: give a whole number >= 1"
                )));
            }
        }
        Ok(Self {
            nb,
            ns,
            degree,
            feedthrough,
            output_feedthrough,
            offset,
        })
    }

    /// The first input lag of G1 (0 with feedthrough) and of G2.
    fn d1(&self) -> usize {
        usize::from(!self.feedthrough)
    }
    fn d2(&self) -> usize {
        usize::from(!self.output_feedthrough)
    }
    fn n_a(&self) -> usize {
        self.nb + 1 - self.d1()
    }
    fn n_r(&self) -> usize {
        self.ns + 1 - self.d2()
    }
    /// Columns of G1 and f: a, b, c.
    fn inner(&self) -> usize {
        self.n_a() + self.nb + self.degree
    }

    /// The number of parameters p.
    pub fn size(&self) -> usize {
        self.inner() + self.n_r() + self.ns + usize::from(self.offset)
    }

    /// The parameter names in the order of theta.
    pub fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = (self.d1()..=self.nb).map(|i| format!("a{i}")).collect();
        names.extend((1..=self.nb).map(|j| format!("b{j}")));
        names.extend((1..=self.degree).map(|i| format!("c{i}")));
        names.extend((self.d2()..=self.ns).map(|i| format!("r{i}")));
        names.extend((1..=self.ns).map(|j| format!("s{j}")));
        if self.offset {
            names.push("offset".into());
        }
        names
    }

    fn parts<'a>(&self, theta: &'a [f64]) -> Result<Parts<'a>> {
        if theta.len() != self.size() {
            return Err(Error::Data(format!(
                "theta has {} parameters but the Wiener-Hammerstein structure has {}: give one \
                 value per name",
                theta.len(),
                self.size()
            )));
        }
        let (a, rest) = theta.split_at(self.n_a());
        let (b, rest) = rest.split_at(self.nb);
        let (c, rest) = rest.split_at(self.degree);
        let (r, rest) = rest.split_at(self.n_r());
        let (s, rest) = rest.split_at(self.ns);
        Ok(Parts {
            a,
            b,
            c,
            r,
            s,
            offset: rest.first().copied().unwrap_or(0.0),
        })
    }
}

/// T_i(0), i = 0..=n: 0 for odd i, (-1)^(i/2) for even.
fn chebyshev_at_zero(i: usize) -> f64 {
    match i % 4 {
        0 => 1.0,
        2 => -1.0,
        _ => 0.0,
    }
}

/// T_i(z) - T_i(0) and T_i'(z), i = 1..=n, into `t` and `dt` (length n each).
#[inline]
fn chebyshev_basis(z: f64, t: &mut [f64], dt: &mut [f64]) {
    let (mut t_prev, mut t_cur) = (1.0, z);
    let (mut d_prev, mut d_cur) = (0.0, 1.0);
    for i in 0..t.len() {
        t[i] = t_cur - chebyshev_at_zero(i + 1);
        dt[i] = d_cur;
        let t_next = 2.0 * z * t_cur - t_prev;
        let d_next = 2.0 * t_cur + 2.0 * z * d_cur - d_prev;
        (t_prev, t_cur, d_prev, d_cur) = (t_cur, t_next, d_cur, d_next);
    }
}

/// Linear filter step: sum_{i} num[i] input(t - d - i) - sum_j den[j] out(t - 1 - j), with
/// zeros before the record.
#[inline(always)]
fn filter_step(t: usize, d: usize, num: &[f64], den: &[f64], input: &[f64], out: &[f64]) -> f64 {
    let mut acc = 0.0;
    for (i, v) in num.iter().enumerate() {
        let lag = d + i;
        if lag <= t {
            acc += v * input[t - lag];
        }
    }
    for (j, v) in den.iter().enumerate() {
        let lag = j + 1;
        if lag <= t {
            acc -= v * out[t - lag];
        }
    }
    acc
}

fn diverged(signal: &str, t: usize) -> Error {
    Error::Model(format!(
        "Wiener-Hammerstein simulation overflowed: {signal}[{t}] is not finite (an unstable or \
         badly scaled estimate); start from a stable estimate"
    ))
}

/// The Wiener-Hammerstein structure, the scale k and the record, checked once.
#[derive(Debug, Clone)]
pub struct WienerHammersteinProblem {
    structure: WhStructure,
    k: f64,
    u: Samples,
    y: Samples,
    warmup: usize,
    /// Per parameter of the structure: Some(value) when fixed (left out of theta).
    fixed: Vec<Option<f64>>,
    /// The positions of theta's parameters in the structure's layout.
    free: Vec<usize>,
}

impl WienerHammersteinProblem {
    /// Checks u and y (non-empty, finite, one length), k > 0 finite and warmup < len(u).
    pub fn new(
        structure: WhStructure,
        k: f64,
        u: impl Into<Samples>,
        y: impl Into<Samples>,
        warmup: usize,
    ) -> Result<Self> {
        let (u, y): (Samples, Samples) = (u.into(), y.into());
        check_signal("u", &u)?;
        check_signal("y", &y)?;
        check_same_length(&u, &y, "y")?;
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::Data(format!(
                "k = {k}: give the scale of x as a finite number > 0"
            )));
        }
        if warmup >= u.len() {
            return Err(Error::Data(format!(
                "warmup = {warmup}: give a whole number of samples, 0 <= warmup < {} (the record \
                 length)",
                u.len()
            )));
        }
        let p = structure.size();
        Ok(Self {
            structure,
            k,
            u,
            y,
            warmup,
            fixed: vec![None; p],
            free: (0..p).collect(),
        })
    }

    /// The problem with the named parameters fixed at the given values: theta, the names,
    /// the Jacobian and the bounds then cover the other parameters only (a scale the data
    /// cannot tell, e.g. G2's gain against f's, held without a null direction in J).
    pub fn with_fixed(mut self, fixed: &[(String, f64)]) -> Result<Self> {
        let names = self.structure.names();
        for (name, value) in fixed {
            let Some(j) = names.iter().position(|n| n == name) else {
                return Err(Error::Data(format!(
                    "fixed parameter {name:?} is not one of the structure's: {}",
                    names.join(", ")
                )));
            };
            if !value.is_finite() {
                return Err(Error::Data(format!(
                    "fixed parameter {name} = {value}: give a finite value"
                )));
            }
            self.fixed[j] = Some(*value);
        }
        self.free = (0..names.len())
            .filter(|&j| self.fixed[j].is_none())
            .collect();
        Ok(self)
    }

    /// The structure's full parameter vector of theta (the free parameters).
    fn expand(&self, theta: &[f64]) -> Result<Vec<f64>> {
        if theta.len() != self.free.len() {
            return Err(Error::Data(format!(
                "theta has {} parameters but the Wiener-Hammerstein problem has {}: give one \
                 value per name",
                theta.len(),
                self.free.len()
            )));
        }
        let mut full: Vec<f64> = self.fixed.iter().map(|v| v.unwrap_or(0.0)).collect();
        for (&j, v) in self.free.iter().zip(theta) {
            full[j] = *v;
        }
        Ok(full)
    }

    /// The free entries of a full row.
    #[inline]
    fn gather(&self, row: &[f64], out: &mut [f64]) {
        for (o, &j) in out.iter_mut().zip(&self.free) {
            *o = row[j];
        }
    }

    pub fn structure(&self) -> &WhStructure {
        &self.structure
    }
    pub fn k(&self) -> f64 {
        self.k
    }
    pub fn samples(&self) -> usize {
        self.u.len()
    }
    pub fn warmup(&self) -> usize {
        self.warmup
    }
    /// The names of theta's parameters (the fixed ones left out).
    pub fn names(&self) -> Vec<String> {
        let names = self.structure.names();
        self.free.iter().map(|&j| names[j].clone()).collect()
    }

    /// The bounds of theta: every parameter free.
    pub fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let p = self.free.len();
        (vec![f64::NEG_INFINITY; p], vec![f64::INFINITY; p])
    }

    /// The stability guard: every pole of G1 and G2 inside |z| < `STABILITY_MARGIN`.
    pub fn feasible(&self, theta: &[f64]) -> Result<bool> {
        let full = self.expand(theta)?;
        let p = self.structure.parts(&full)?;
        Ok(spectral_radius(p.b) < STABILITY_MARGIN && spectral_radius(p.s) < STABILITY_MARGIN)
    }

    /// The internal signal x(t) = G1 u from rest.
    pub fn internal(&self, theta: &[f64]) -> Result<Vec<f64>> {
        let full = self.expand(theta)?;
        let p = self.structure.parts(&full)?;
        let d1 = self.structure.d1();
        let mut x = guard::filled(self.u.len(), 0.0, "x")?;
        for t in 0..self.u.len() {
            let v = filter_step(t, d1, p.a, p.b, &self.u, &x);
            if !v.is_finite() {
                return Err(diverged("x", t));
            }
            x[t] = v;
        }
        Ok(x)
    }

    /// Free-run output from rest.
    pub fn simulate(&self, theta: &[f64]) -> Result<Vec<f64>> {
        let full = self.expand(theta)?;
        let p = self.structure.parts(&full)?;
        let x = self.internal(theta)?;
        let d2 = self.structure.d2();
        let n = self.u.len();
        let mut f = guard::filled(n, 0.0, "f")?;
        let (mut tb, mut dtb) = (vec![0.0; p.c.len()], vec![0.0; p.c.len()]);
        for t in 0..n {
            // the same basis and summation order as `walk`, so both give the same bits
            chebyshev_basis(x[t] / self.k, &mut tb, &mut dtb);
            let v: f64 = p.c.iter().zip(&tb).fold(0.0, |acc, (ci, ti)| acc + ci * ti);
            if !v.is_finite() {
                return Err(diverged("f", t));
            }
            f[t] = v;
        }
        let mut w = guard::filled(n, 0.0, "w")?;
        for t in 0..n {
            let v = filter_step(t, d2, p.r, p.s, &f, &w);
            if !v.is_finite() {
                return Err(diverged("y", t));
            }
            w[t] = v;
        }
        for v in &mut w {
            *v += p.offset;
        }
        Ok(w)
    }

    /// The cost sum (y - y_sim)^2 over t >= warmup; a ModelError if the simulation diverges.
    pub fn cost(&self, theta: &[f64]) -> Result<f64> {
        output_error_cost(&self.y, &self.simulate(theta)?, self.warmup)
    }

    /// The output-error problem at theta in factored form: R_aug of [J | y - y_sim] over
    /// t >= warmup and the cost, the rows streamed (no N x p Jacobian).
    pub fn oe_factor(&self, theta: &[f64]) -> Result<(TriangularFactor, f64)> {
        let p = self.free.len();
        let (y, warmup) = (&self.y, self.warmup);
        let len = self.u.len();
        // long records: both threads fold (rounding differs from one thread); shorter ones
        // from PIPELINE_FROM: rows on one thread, folds on the other, the same bits
        let (threads, own_every) = match (oe_threads(len), len >= PIPELINE_FROM) {
            (t, _) if t >= 2 => (t, OWN_EVERY),
            (_, true) => (default_threads().min(2), 0),
            _ => (1, 0),
        };
        let (factor, cost) = fold_stream_shared(p, threads, own_every, |sink| {
            self.walk(theta, |t, yt, row| match t >= warmup {
                true => sink.push(row, y[t] - yt),
                false => Ok(()),
            })
        })?;
        if !cost.is_finite() || factor.r_aug().iter().any(|v| !v.is_finite()) {
            return Err(overflowed());
        }
        Ok((factor, cost))
    }

    /// g = J^T (y - y_sim) over t >= warmup and the cost, one pass without the factor.
    pub fn gradient(&self, theta: &[f64]) -> Result<OeGradient> {
        let mut g = vec![0.0; self.free.len()];
        let mut cost = 0.0;
        self.walk(theta, |t, yt, row| {
            if t >= self.warmup {
                let r = self.y[t] - yt;
                cost += r * r;
                for (gi, v) in g.iter_mut().zip(row) {
                    *gi += v * r;
                }
            }
            Ok(())
        })?;
        if !cost.is_finite() || g.iter().any(|v| !v.is_finite()) {
            return Err(overflowed());
        }
        Ok(OeGradient { gradient: g, cost })
    }

    /// The dense Jacobian d y_sim / d theta (row-major, N x p) and the output; for tests.
    pub fn jacobian(&self, theta: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let mut jac = Vec::with_capacity(self.u.len() * self.free.len());
        let mut out = Vec::with_capacity(self.u.len());
        self.walk(theta, |_, yt, row| {
            out.push(yt);
            jac.extend_from_slice(row);
            Ok(())
        })?;
        Ok((jac, out))
    }

    /// The model run one sample at a time with its sensitivities: `visit(t, y(t), dy(t))`
    /// for t = 0, 1, ... (the one place the recursions of the module header run).
    fn walk(
        &self,
        theta: &[f64],
        mut visit: impl FnMut(usize, f64, &[f64]) -> Result<()>,
    ) -> Result<()> {
        let st = &self.structure;
        let full = self.expand(theta)?;
        let p = st.parts(&full)?;
        let all_free = self.free.len() == st.size();
        let mut reduced = vec![0.0; self.free.len()];
        let (n_a, nb, n, ns) = (st.n_a(), st.nb, st.degree, st.ns);
        let (d1, d2) = (st.d1(), st.d2());
        let inner = st.inner();
        let cols = st.size();
        let len = self.u.len();
        let u = &self.u;
        // full-length signals (a few vectors of N)
        let mut x = guard::filled(len, 0.0, "x")?;
        let mut wu = guard::filled(len, 0.0, "wu")?;
        let mut wx = guard::filled(len, 0.0, "wx")?;
        let mut f = guard::filled(len, 0.0, "f")?;
        let mut w = guard::filled(len, 0.0, "w")?;
        let mut wf = guard::filled(len, 0.0, "wf")?;
        let mut ww = guard::filled(len, 0.0, "ww")?;
        // rings of df and dw rows (G1's and f's columns) over ns + 1 samples
        let ring = ns + 1;
        let mut df_ring = vec![0.0; ring * inner];
        let mut dw_ring = vec![0.0; ring * inner];
        let mut tb = vec![0.0; n];
        let mut dtb = vec![0.0; n];
        let mut row = vec![0.0; cols];
        if st.offset {
            row[cols - 1] = 1.0;
        }
        let k = self.k;
        for t in 0..len {
            // G1 and its filtered signals
            let xt = filter_step(t, d1, p.a, p.b, u, &x);
            if !xt.is_finite() {
                return Err(diverged("x", t));
            }
            x[t] = xt;
            wu[t] = filter_step(t, 0, &[1.0], p.b, u, &wu);
            wx[t] = filter_step(t, 0, &[1.0], p.b, &x, &wx);
            // f, its slope and basis
            let z = xt / k;
            chebyshev_basis(z, &mut tb, &mut dtb);
            let ft: f64 = p.c.iter().zip(&tb).fold(0.0, |acc, (ci, ti)| acc + ci * ti);
            let slope =
                p.c.iter()
                    .zip(&dtb)
                    .fold(0.0, |acc, (ci, di)| acc + ci * di)
                    / k;
            if !(ft.is_finite() && slope.is_finite()) {
                return Err(diverged("f", t));
            }
            f[t] = ft;
            // df(t) into its ring slot
            let slot = t % ring;
            {
                let df = &mut df_ring[slot * inner..(slot + 1) * inner];
                for (i, d) in df[..n_a].iter_mut().enumerate() {
                    let lag = d1 + i;
                    *d = if lag <= t { slope * wu[t - lag] } else { 0.0 };
                }
                for (j, d) in df[n_a..n_a + nb].iter_mut().enumerate() {
                    let lag = j + 1;
                    *d = if lag <= t { -slope * wx[t - lag] } else { 0.0 };
                }
                df[n_a + nb..].copy_from_slice(&tb);
            }
            // G2: w(t) and dw(t) on the inner columns
            let wt = filter_step(t, d2, p.r, p.s, &f, &w);
            if !wt.is_finite() {
                return Err(diverged("y", t));
            }
            w[t] = wt;
            wf[t] = filter_step(t, 0, &[1.0], p.s, &f, &wf);
            ww[t] = filter_step(t, 0, &[1.0], p.s, &w, &ww);
            let acc = &mut row[..inner];
            acc.fill(0.0);
            for (i, ri) in p.r.iter().enumerate() {
                let lag = d2 + i;
                if lag <= t {
                    let k2 = (t - lag) % ring;
                    for (a, v) in acc.iter_mut().zip(&df_ring[k2 * inner..(k2 + 1) * inner]) {
                        *a += ri * v;
                    }
                }
            }
            for (j, sj) in p.s.iter().enumerate() {
                let lag = j + 1;
                if lag <= t {
                    let k2 = (t - lag) % ring;
                    for (a, v) in acc.iter_mut().zip(&dw_ring[k2 * inner..(k2 + 1) * inner]) {
                        *a -= sj * v;
                    }
                }
            }
            dw_ring[slot * inner..(slot + 1) * inner].copy_from_slice(acc);
            // G2's own columns
            let n_r = st.n_r();
            for i in 0..n_r {
                let lag = d2 + i;
                row[inner + i] = if lag <= t { wf[t - lag] } else { 0.0 };
            }
            for j in 0..ns {
                let lag = j + 1;
                row[inner + n_r + j] = if lag <= t { -ww[t - lag] } else { 0.0 };
            }
            if all_free {
                visit(t, wt + p.offset, &row)?;
            } else {
                self.gather(&row, &mut reduced);
                visit(t, wt + p.offset, &reduced)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_params::smooth_input as input;

    /// G1 = 0.4 q^-1 + 0.2 q^-2 over 1 - 1.1 q^-1 + 0.4 q^-2 (gain 2), f a cubic-ish Chebyshev
    /// sum, G2 = 0.5 q^-1 over 1 - 0.6 q^-1 (with feedthrough variants).
    fn truth(s: &WhStructure) -> Vec<f64> {
        let mut th = Vec::new();
        if s.feedthrough {
            th.push(0.1);
        }
        th.extend([0.4, 0.2]);
        th.extend([-1.1, 0.4]);
        let c = [0.9, 0.15, -0.08, 0.03, 0.01];
        th.extend(&c[..s.degree]);
        if s.output_feedthrough {
            th.push(0.3);
        }
        th.extend([0.5, -0.1]);
        th.extend([-0.6, 0.1]);
        if s.offset {
            th.push(0.05);
        }
        th
    }

    fn problem(s: WhStructure, warmup: usize) -> (WienerHammersteinProblem, Vec<f64>) {
        let u = input(600);
        let probe = WienerHammersteinProblem::new(s, 2.0, u.clone(), vec![0.0; 600], 0).unwrap();
        let th = truth(&s);
        let y: Vec<f64> = probe
            .simulate(&th)
            .unwrap()
            .iter()
            .enumerate()
            .map(|(t, v)| v + 0.01 * ((t as f64) * 0.7).sin())
            .collect();
        let perturbed: Vec<f64> = th
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.02 * (1.0 + (i as f64 * 1.3).cos()))
            .collect();
        (
            WienerHammersteinProblem::new(s, 2.0, u, y, warmup).unwrap(),
            perturbed,
        )
    }

    fn structures() -> Vec<WhStructure> {
        let mut out = Vec::new();
        for (ft, oft, off) in [
            (false, false, false),
            (false, false, true),
            (true, true, true),
            (false, true, true),
        ] {
            out.push(WhStructure::new(2, 2, 5, ft, oft, off).unwrap());
        }
        out.push(WhStructure::new(2, 2, 1, false, false, true).unwrap());
        out
    }

    #[test]
    fn names_and_sizes() {
        let s = WhStructure::new(3, 3, 4, false, true, true).unwrap();
        assert_eq!(
            s.names(),
            [
                "a1", "a2", "a3", "b1", "b2", "b3", "c1", "c2", "c3", "c4", "r0", "r1", "r2", "r3",
                "s1", "s2", "s3", "offset"
            ]
        );
        assert_eq!(s.size(), 18);
        assert!(WhStructure::new(0, 1, 1, false, false, false).is_err());
    }

    #[test]
    fn jacobian_is_the_central_difference_of_simulate() {
        for s in structures() {
            let (pr, th) = problem(s, 0);
            let (jac, out) = pr.jacobian(&th).unwrap();
            assert_eq!(out, pr.simulate(&th).unwrap());
            let p = th.len();
            for j in 0..p {
                let h = 1e-6;
                let (mut lo, mut hi) = (th.clone(), th.clone());
                lo[j] -= h;
                hi[j] += h;
                let (ylo, yhi) = (pr.simulate(&lo).unwrap(), pr.simulate(&hi).unwrap());
                let scale = (0..out.len())
                    .map(|t| jac[t * p + j].abs())
                    .fold(1e-3, f64::max);
                for t in 0..out.len() {
                    let fd = (yhi[t] - ylo[t]) / (2.0 * h);
                    assert!(
                        (fd - jac[t * p + j]).abs() < 1e-7 * scale,
                        "{s:?} col {j} t {t}: {fd} {}",
                        jac[t * p + j]
                    );
                }
            }
        }
    }

    #[test]
    fn factor_and_gradient_agree_with_the_jacobian_and_the_cost() {
        for s in structures() {
            for warmup in [0, 37] {
                let (pr, th) = problem(s, warmup);
                let (jac, out) = pr.jacobian(&th).unwrap();
                let p = th.len();
                let y = &pr.y;
                let (factor, cost) = pr.oe_factor(&th).unwrap();
                let want_cost: f64 = (warmup..y.len()).map(|t| (y[t] - out[t]).powi(2)).sum();
                assert!((cost - want_cost).abs() <= 1e-12 * want_cost);
                assert!((pr.cost(&th).unwrap() - want_cost).abs() <= 1e-12 * want_cost);
                // R_aug^T R_aug = [J r]^T [J r]
                let m = p + 1;
                let aug = |t: usize, j: usize| if j < p { jac[t * p + j] } else { y[t] - out[t] };
                let r = factor.r_aug();
                for i in 0..m {
                    for j in 0..m {
                        let rtr: f64 = (0..m).map(|q| r[q * m + i] * r[q * m + j]).sum();
                        let gram: f64 = (warmup..y.len()).map(|t| aug(t, i) * aug(t, j)).sum();
                        let size: f64 = (warmup..y.len())
                            .map(|t| aug(t, i).powi(2) + aug(t, j).powi(2))
                            .sum();
                        assert!((rtr - gram).abs() <= 1e-10 * size, "{i} {j}: {rtr} {gram}");
                    }
                }
                // g = J^T r is -1/2 the central difference of the cost
                let g = pr.gradient(&th).unwrap();
                assert!((g.cost - want_cost).abs() <= 1e-12 * want_cost);
                for j in 0..p {
                    let h = 1e-6;
                    let (mut lo, mut hi) = (th.clone(), th.clone());
                    lo[j] -= h;
                    hi[j] += h;
                    let fd = -(pr.cost(&hi).unwrap() - pr.cost(&lo).unwrap()) / (4.0 * h);
                    let tol = 1e-6 * (g.gradient[j].abs() + 1e-3 * want_cost.sqrt());
                    assert!(
                        (fd - g.gradient[j]).abs() < tol,
                        "{s:?} {j}: {fd} {}",
                        g.gradient[j]
                    );
                }
            }
        }
    }

    #[test]
    fn fixed_parameters_leave_theta_and_the_jacobian() {
        let s = WhStructure::new(2, 2, 5, false, false, true).unwrap();
        let (pr, th) = problem(s, 5);
        let names = pr.names();
        let (jac, out) = pr.jacobian(&th).unwrap();
        let fixed = vec![("a2".to_string(), th[1]), ("r1".to_string(), th[9])];
        let held = pr.clone().with_fixed(&fixed).unwrap();
        let keep: Vec<usize> = (0..th.len()).filter(|&j| j != 1 && j != 9).collect();
        let reduced: Vec<f64> = keep.iter().map(|&j| th[j]).collect();
        let want: Vec<String> = keep.iter().map(|&j| names[j].clone()).collect();
        assert_eq!(held.names(), want);
        assert_eq!(held.bounds().0.len(), keep.len());
        assert_eq!(held.simulate(&reduced).unwrap(), out);
        let (hjac, _) = held.jacobian(&reduced).unwrap();
        let (p, q) = (th.len(), keep.len());
        for t in 0..out.len() {
            for (k, &j) in keep.iter().enumerate() {
                assert_eq!(hjac[t * q + k], jac[t * p + j]);
            }
        }
        let g = held.gradient(&reduced).unwrap();
        let full_g = pr.gradient(&th).unwrap();
        for (k, &j) in keep.iter().enumerate() {
            assert_eq!(g.gradient[k], full_g.gradient[j]);
        }
        assert_eq!(held.oe_factor(&reduced).unwrap().0.cols(), q);
        assert!(matches!(held.simulate(&th), Err(Error::Data(_))));
        let bad = vec![("z9".to_string(), 1.0)];
        assert!(matches!(pr.clone().with_fixed(&bad), Err(Error::Data(_))));
    }

    #[test]
    fn simulate_is_the_block_chain() {
        // f(x) = c_1 T_1(x/k) = x / k * c_1 with G1, G2 first order: a plain linear chain
        let s = WhStructure::new(1, 1, 1, false, false, true).unwrap();
        let u = input(50);
        let pr = WienerHammersteinProblem::new(s, 2.0, u.clone(), vec![0.0; 50], 0).unwrap();
        let th = [0.5, -0.3, 4.0, 0.2, 0.1, 1.5];
        let sim = pr.simulate(&th).unwrap();
        let (mut x, mut w) = (0.0, 0.0);
        let mut f_prev = 0.0;
        for t in 0..50 {
            let u_prev = if t > 0 { u[t - 1] } else { 0.0 };
            x = 0.5 * u_prev + 0.3 * x;
            let f = 2.0 * x;
            w = 0.2 * f_prev - 0.1 * w;
            f_prev = f;
            assert!((sim[t] - (w + 1.5)).abs() < 1e-12);
        }
        // the basis: T_i(cos h) = cos(i h), T_i'(cos h) = i sin(i h) / sin h, minus T_i(0)
        for h in [0.3f64, 1.0, 2.0, 2.9] {
            let (mut t, mut dt) = ([0.0; 6], [0.0; 6]);
            chebyshev_basis(h.cos(), &mut t, &mut dt);
            for i in 1..=6 {
                let fi = i as f64;
                let at0 = (fi * std::f64::consts::FRAC_PI_2).cos();
                assert!((t[i - 1] - ((fi * h).cos() - at0)).abs() < 1e-12);
                assert!((dt[i - 1] - fi * (fi * h).sin() / h.sin()).abs() < 1e-11);
            }
        }
    }

    #[test]
    fn feasibility_bounds_and_bad_input() {
        let s = WhStructure::new(2, 2, 5, false, false, true).unwrap();
        let (pr, th) = problem(s, 0);
        assert!(pr.feasible(&th).unwrap());
        let mut bad = th.clone();
        bad[2] = -2.1; // 1 - 2.1 q^-1 + 0.4 q^-2 ... a root outside
        assert!(!pr.feasible(&bad).unwrap());
        let mut g2 = th.clone();
        g2[11] = -1.0;
        g2[12] = 0.0; // a pole at 1
        assert!(!pr.feasible(&g2).unwrap());
        let (lo, hi) = pr.bounds();
        assert!(
            lo.iter().all(|v| *v == f64::NEG_INFINITY) && hi.iter().all(|v| *v == f64::INFINITY)
        );
        assert!(matches!(pr.simulate(&th[1..]), Err(Error::Data(_))));
        let mut huge = th.clone();
        huge[0] = 1e200;
        assert!(matches!(pr.cost(&huge), Err(Error::Model(_))));
        assert!(matches!(pr.oe_factor(&huge), Err(Error::Model(_))));
        assert!(WienerHammersteinProblem::new(s, 0.0, vec![1.0], vec![1.0], 0).is_err());
        assert!(WienerHammersteinProblem::new(s, 1.0, vec![1.0], vec![1.0], 1).is_err());
        assert!(
            WienerHammersteinProblem::new(s, 1.0, vec![1.0, f64::NAN], vec![1.0, 1.0], 0).is_err()
        );
    }
}
