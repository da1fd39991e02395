//! Exact forward sensitivities of the augmented chain ([`crate::augmented`]): the one-pass
//! simulation run again with d/dtheta carried beside every value, theta = the nominal
//! chain's parameters (`problem::Layout`'s columns, then the sandwich's r_2..r_nr,
//! s_1..s_ns) followed by the refitted effects' continuous parameters. Per sample t:
//!
//! - linear block (eq 16) with its input u_eff depending on theta (saturation's levels,
//!   friction's feedback): dx(t) = sum_i a_i du_eff(t-i) - sum_j b_j dx(t-j) +
//!   [dx/da_i = u_eff(t-i), dx/db_j = -x(t-j)], the past before the record carried as
//!   given (zero at rest or from an explicit start, a constant; the held start's
//!   equilibrium x = sum a / (1 + sum b) u(0) has its own);
//! - state stage: each effect's `state_tangent` (dx(t) itself, before the recursion keeps it);
//! - drive stage: each effect's `drive_tangent` (d u_eff);
//! - widths stage: each effect's `widths_tangent` (d c_L(t), d c_R(t); e_{c_L}, e_{c_R}
//!   without one);
//! - the backlash's switching derivatives, those of `sensitivity`'s recursions with the
//!   widths' tangents in place of e_{c_L}, e_{c_R}: on L dy = L'(xi1) (dx + dc_L) +
//!   [dL/dm_Li = xi1^i], on R dy = R'(xi2) (dx - dc_R) + [dR/dm_Ri = xi2^i], holding dy(t) =
//!   dy(t-1);
//! - load stage: each effect's `output_tangent` on df;
//! - the sandwich's output block (eq 29): dw(t) = sum_i r_i dy_L(t-i) - sum_j s_j dw(t-j) +
//!   [dw/dr_i = y_L(t-i) for i >= 2 (r_1 = 1 fixed), dw/ds_j = -w(t-j)], the pasts before
//!   the record as given (dy_L zero; dw zero but for the held start's equilibrium);
//! - output stage: each effect's `output_tangent`.
//!
//! `sensitivity`'s cascade recursion filters lags of u and x by 1/B once for all columns; that
//! needs an input free of theta, which a drive effect breaks, so the linear block's tangent
//! here is the plain recursion on dx (p (na + nb) multiply-adds a sample).

use crate::augmented::{
    branch, diverged, free_gain, free_response, AugmentedChain, AugmentedState, Stages,
};
use crate::effects::{AnyEffect, Sample, Tangent};
use crate::error::{Error, Result};
use crate::guard;
use crate::identify::gradient::OeGradient;
use crate::identify::problem::Layout;
use crate::identify::sensitivity::{branch_degree, finish, overflowed, Move, Sensitivity};
use crate::linalg::streaming::{fold_stream_parts, TriangularFactor};

/// d branch / d xi by Horner's rule (as `Branch::slope`).
#[inline(always)]
fn slope(m: &[f64], xi: f64) -> f64 {
    let mut acc = 0.0;
    for (k, c) in m.iter().enumerate().rev() {
        acc = acc * xi + (k + 1) as f64 * c;
    }
    acc
}

/// The last `rows` tangents (p each), most recent first: `lag(k)` is the one k samples back.
struct Ring {
    rows: usize,
    p: usize,
    head: usize,
    data: Vec<f64>,
}

impl Ring {
    /// Holding `past` (row k-1 is lag k), zero rows beyond it.
    fn new(rows: usize, p: usize, past: &[f64]) -> Self {
        let mut data = vec![0.0; rows * p];
        let m = past.len().min(data.len());
        data[..m].copy_from_slice(&past[..m]);
        Self {
            rows,
            p,
            head: 0,
            data,
        }
    }

    /// Lag k >= 1 (k <= rows).
    #[inline(always)]
    fn lag(&self, k: usize) -> &[f64] {
        let mut at = self.head + k - 1;
        if at >= self.rows {
            at -= self.rows;
        }
        &self.data[at * self.p..(at + 1) * self.p]
    }

    /// The slot of the newest row, which becomes lag 1 (the oldest's values until written).
    #[inline(always)]
    fn advance(&mut self) -> &mut [f64] {
        self.head = if self.head == 0 {
            self.rows - 1
        } else {
            self.head - 1
        };
        let at = self.head * self.p;
        &mut self.data[at..at + self.p]
    }

    /// The newest row becomes lag 1 (its columns `cols` written; the others keep zero).
    #[inline(always)]
    fn push(&mut self, row: &[f64], cols: &XCols) {
        let slot = self.advance();
        slot[..cols.lead].copy_from_slice(&row[..cols.lead]);
        for &c in &cols.extra {
            slot[c] = row[c];
        }
    }

    /// The newest row becomes lag 1, all its columns written.
    #[inline(always)]
    fn push_all(&mut self, row: &[f64]) {
        self.advance().copy_from_slice(row);
    }
}

/// The columns in which x (and u_eff) can depend on theta: a, b (the first `lead`) and the
/// state and drive effects' free parameters (`extra`, after the cascade's); the others of dx stay 0.
struct XCols {
    lead: usize,
    extra: Vec<usize>,
}

impl XCols {
    fn contains(&self, c: usize) -> bool {
        c < self.lead || self.extra.contains(&c)
    }

    /// d[c] = 0 for c in the columns.
    #[inline(always)]
    fn zero(&self, d: &mut [f64]) {
        d[..self.lead].fill(0.0);
        for &c in &self.extra {
            d[c] = 0.0;
        }
    }

    /// d[c] += k v[c] for c in the columns.
    #[inline(always)]
    fn axpy(&self, d: &mut [f64], k: f64, v: &[f64]) {
        for (o, w) in d[..self.lead].iter_mut().zip(&v[..self.lead]) {
            *o += k * w;
        }
        for &c in &self.extra {
            d[c] += k * v[c];
        }
    }
}

/// The start of a tangent pass: the state before the record, d x_past / d theta (nb rows
/// of p, most recent first; the past inputs u_past are constants) and for the sandwich
/// d w_past / d theta (ns rows of p, or empty for zeros; its past inputs are constants).
pub(crate) struct Start<'a> {
    pub(crate) state: &'a AugmentedState,
    pub(crate) dx_past: &'a [f64],
    pub(crate) dw_past: &'a [f64],
}

/// The augmented chain's output y(t) and its row dy(t) / d theta (`p` wide), handed to
/// `visit(t, y(t), dy(t), same)` for t = 0, 1, ...; `same` says dy(t) equals dy(t-1) bit for
/// bit (a cascade's held backlash whose output effects left the row alone). `effects` pairs
/// each effect with the columns of its parameters (None: held). The values are those of
/// `simulate_augmented_chain` to the bit.
#[allow(clippy::too_many_arguments)]
pub(crate) fn walk_augmented(
    chain: &AugmentedChain,
    effects: &[(AnyEffect, Vec<Option<usize>>)],
    u: &[f64],
    t0: f64,
    time_scale: f64,
    start: &Start,
    p: usize,
    mut visit: impl FnMut(usize, f64, &[f64], bool) -> Result<()>,
) -> Result<()> {
    let lin = &chain.cascade.linear;
    let bl = &chain.cascade.backlash;
    chain.check_state(start.state)?;
    let state = &start.state.cascade;
    let output = chain.output.as_ref().zip(start.state.output.as_ref());
    let n = branch_degree(bl)?;
    let (a, b) = (lin.a(), lin.b());
    let (na, nb) = (a.len(), b.len());
    let lay = Layout { na, nb, n };
    let (r, s_out): (&[f64], &[f64]) = match output {
        Some((block, _)) => (block.a(), block.b()),
        None => (&[], &[]),
    };
    let (nr, ns) = (r.len(), s_out.len());
    // the columns of r_2..r_nr and s_1..s_ns
    let (col_r, col_s) = (lay.r(), lay.r() + nr.saturating_sub(1));
    let nominal = col_s + ns;
    if p < nominal
        || start.dx_past.len() != nb * p
        || !(start.dw_past.is_empty() || start.dw_past.len() == ns * p)
        || lin.feedthrough().is_some()
    {
        return Err(Error::Data(format!(
            "augmented sensitivities: {p} columns for a chain of {nominal} parameters, {} values \
             of d x_past for {nb} x {p}, {} of d w_past for {ns} x {p} (internal shape mismatch)",
            start.dx_past.len(),
            start.dw_past.len()
        )));
    }
    let (m_l, m_r) = (bl.left().coefficients(), bl.right().coefficients());
    let (c_l, c_r) = (bl.c_left(), bl.c_right());
    let x0 = state.linear.x_past.first().copied().unwrap_or(0.0);
    let u_before = state.linear.u_past.first().copied().unwrap_or(0.0);
    let dx0 = if nb > 0 {
        start.dx_past[..p].to_vec()
    } else {
        vec![0.0; p]
    };
    // fresh copies with their memories at rest on x(0), y(0), in the order of the pass
    let running: Vec<(AnyEffect, &[Option<usize>])> = effects
        .iter()
        .map(|(e, cols)| {
            e.check()?;
            if cols.len() != e.parameters().len() || cols.iter().flatten().any(|&c| c >= p) {
                return Err(Error::Data(format!(
                    "augmented sensitivities: columns {cols:?} for {} (internal shape mismatch)",
                    e.name()
                )));
            }
            Ok((
                e.start_tangent(x0, state.y_prev, &dx0, cols),
                cols.as_slice(),
            ))
        })
        .collect::<Result<_>>()?;
    let Stages {
        state: mut on_x,
        mut drive,
        widths,
        mut load,
        output: mut sensor,
    } = Stages::sort(running, |e| &e.0);
    let driven = !drive.is_empty();
    // the columns x can depend on: a, b and the state and drive effects' free parameters
    // (every other column of dx, du_eff stays 0; the recursions run over these only)
    let mut extra: Vec<usize> = on_x
        .iter()
        .chain(&drive)
        .flat_map(|(_, cols)| cols.iter().flatten().copied())
        .collect();
    extra.sort_unstable();
    extra.dedup();
    let xcols = XCols {
        lead: na + nb,
        extra,
    };
    if xcols.extra.iter().any(|&c| c < xcols.lead) {
        return Err(Error::Data(
            "augmented sensitivities: an effect's column among a, b (internal shape mismatch)"
                .into(),
        ));
    }
    let len = u.len();
    let (mut u_eff, mut x) = (
        guard::filled(len, 0.0, "u_eff")?,
        guard::filled(len, 0.0, "x")?,
    );
    // tangents: of u_eff over na lags, of x over max(nb, 1) lags (x(t-1) for friction)
    let mut du = Ring::new(na, p, &[]);
    let mut dxr = Ring::new(nb.max(1), p, if nb > 0 { start.dx_past } else { &dx0 });
    if start
        .dx_past
        .iter()
        .enumerate()
        .any(|(k, v)| *v != 0.0 && !xcols.contains(k % p))
    {
        return Err(Error::Data(
            "augmented sensitivities: d x_past outside the columns of a, b and the drive effects \
             (internal shape mismatch)"
                .into(),
        ));
    }
    let (mut dxt, mut dv, mut dy, mut dout) =
        (vec![0.0; p], vec![0.0; p], vec![0.0; p], vec![0.0; p]);
    // the free response x_free(t+1) and its tangent, for a drive effect that reads them
    let free = drive.iter().any(|(e, _)| e.needs_free());
    let gain = free_gain(lin);
    let mut dfree = if free { vec![0.0; p] } else { Vec::new() };
    let (mut dcl, mut dcr) = (vec![0.0; p], vec![0.0; p]);
    let mut prev_out = vec![0.0; p];
    let mut y_prev = state.y_prev;
    let mut x_prev = x0;
    // the output block's input y_L and output w with their tangents over nr and ns lags
    let len_w = if output.is_some() { len } else { 0 };
    let (mut y_load, mut w) = (
        guard::filled(len_w, 0.0, "y_load")?,
        guard::filled(len_w, 0.0, "w")?,
    );
    let mut dyl = Ring::new(nr.max(1), p, &[]);
    let mut dwr = Ring::new(ns.max(1), p, start.dw_past);
    let mut dw = vec![0.0; if output.is_some() { p } else { 0 }];
    for t in 0..len {
        let mut xt = lin.output_at(&u_eff, &x, t, &state.linear);
        // dx(t), in the columns of xcols (the others stay 0)
        xcols.zero(&mut dxt);
        if driven {
            for (i, ai) in a.iter().enumerate() {
                xcols.axpy(&mut dxt, *ai, du.lag(i + 1));
            }
        }
        for (j, bj) in b.iter().enumerate() {
            xcols.axpy(&mut dxt, -bj, dxr.lag(j + 1));
        }
        for i in 1..=na {
            dxt[i - 1] += if i <= t {
                u_eff[t - i]
            } else {
                state.linear.u_past[i - t - 1]
            };
        }
        for j in 1..=nb {
            dxt[na + j - 1] -= if j <= t {
                x[t - j]
            } else {
                state.linear.x_past[j - t - 1]
            };
        }
        let mut s = Sample {
            t,
            u,
            u_prev: if t > 0 { u[t - 1] } else { u_before },
            x: xt,
            x_prev,
            f: 0.0,
            tau: (t0 + t as f64) / time_scale,
            x_free: 0.0,
            gain,
        };
        // x(t) as the recursion stores it
        for (e, cols) in on_x.iter_mut() {
            xt = e.state_tangent(xt, &mut dxt, &s, cols);
        }
        x[t] = xt;
        s.x = xt;
        if free {
            // x_free = sum_{i >= 2} a_i u_eff(t+1-i) - sum_j b_j x(t+1-j), and its tangent
            s.x_free = free_response(lin, &u_eff, &x, t, &state.linear);
            xcols.zero(&mut dfree);
            for i in 2..=na {
                // u_eff(t + 1 - i) is lag i - 1 from t
                xcols.axpy(&mut dfree, a[i - 1], du.lag(i - 1));
                dfree[i - 1] += if i - 1 <= t {
                    u_eff[t + 1 - i]
                } else {
                    state.linear.u_past[i - 1 - t - 1]
                };
            }
            for j in 1..=nb {
                // x(t + 1 - j) is lag j - 1 from t (lag 0: x(t))
                if j == 1 {
                    xcols.axpy(&mut dfree, -b[0], &dxt);
                } else {
                    xcols.axpy(&mut dfree, -b[j - 1], dxr.lag(j - 1));
                }
                dfree[na + j - 1] -= if j == 1 {
                    xt
                } else if j - 1 <= t {
                    x[t + 1 - j]
                } else {
                    state.linear.x_past[j - 1 - t - 1]
                };
            }
        }
        // the drive input of the linear block at t
        let mut v = u[t];
        if driven {
            dv.fill(0.0);
            let d = Tangent {
                dx: &dxt,
                dx_prev: dxr.lag(1),
                df: &[],
                dx_free: &dfree,
            };
            for (e, cols) in drive.iter_mut() {
                v = e.drive_tangent(v, &mut dv, &s, &d, cols);
            }
            du.push(&dv, &xcols);
        }
        u_eff[t] = v;
        x_prev = xt;
        // the widths of that time
        let (cl, cr) = if widths.is_empty() {
            (c_l, c_r)
        } else {
            dcl.fill(0.0);
            dcr.fill(0.0);
            dcl[lay.c_l()] = 1.0;
            dcr[lay.c_r()] = 1.0;
            let mut c = (c_l, c_r);
            for (e, cols) in &widths {
                c = e.widths_tangent(c, (&mut dcl, &mut dcr), &s, cols);
            }
            c
        };
        // eq (1) in its case order, and the switching derivatives
        let xi_l = xt + cl;
        let lv = branch(m_l, xi_l);
        let (f, mv, xi) = if lv <= y_prev {
            (lv, Move::Left, xi_l)
        } else {
            let xi_r = xt - cr;
            let rv = branch(m_r, xi_r);
            if rv >= y_prev {
                (rv, Move::Right, xi_r)
            } else {
                (y_prev, Move::Hold, 0.0)
            }
        };
        if mv != Move::Hold {
            let left = mv == Move::Left;
            let sl = slope(if left { m_l } else { m_r }, xi);
            dy.fill(0.0);
            xcols.axpy(&mut dy, sl, &dxt);
            // d c_L(t) on L, -d c_R(t) on R
            let sign = if left { 1.0 } else { -1.0 };
            if widths.is_empty() {
                dy[if left { lay.c_l() } else { lay.c_r() }] += sign * sl;
            } else {
                let dc = if left { &dcl } else { &dcr };
                for (d, v) in dy.iter_mut().zip(dc) {
                    *d += sign * sl * v;
                }
            }
            let mut pw = xi;
            if !left {
                dy[lay.m_r1()] += xi;
            }
            for i in 2..=n {
                pw *= xi;
                dy[if left { lay.m_l(i) } else { lay.m_r(i) }] += pw;
            }
        }
        // else holding: dy(t) = dy(t-1), already in place
        y_prev = f;
        s.f = f;
        let mut out = f;
        if load.is_empty() && output.is_none() && sensor.is_empty() {
            // the row is dy itself
            if !(out.is_finite() && xt.is_finite()) {
                return Err(diverged(t, xt, out));
            }
            visit(t, out, &dy, mv == Move::Hold && t > 0)?;
        } else {
            dout.copy_from_slice(&dy);
            let d = Tangent {
                dx: &dxt,
                dx_prev: dxr.lag(1),
                df: &dy,
                dx_free: &[],
            };
            for (e, cols) in load.iter_mut() {
                out = e.output_tangent(out, &mut dout, &s, &d, cols);
            }
            if let Some((block, past)) = output {
                // eq (29) of y_L up to t-1, then y_L(t) and its tangent join the past
                let wt = block.output_at(&y_load, &w, t, past);
                dw.fill(0.0);
                for (i, ri) in r.iter().enumerate() {
                    for (o, v) in dw.iter_mut().zip(dyl.lag(i + 1)) {
                        *o += ri * v;
                    }
                    if i >= 1 {
                        dw[col_r + i - 1] += if i < t {
                            y_load[t - i - 1]
                        } else {
                            past.u_past[i - t]
                        };
                    }
                }
                for (j, sj) in s_out.iter().enumerate() {
                    for (o, v) in dw.iter_mut().zip(dwr.lag(j + 1)) {
                        *o -= sj * v;
                    }
                    dw[col_s + j] -= if j < t {
                        w[t - j - 1]
                    } else {
                        past.x_past[j - t]
                    };
                }
                y_load[t] = out;
                w[t] = wt;
                dyl.push_all(&dout);
                if ns > 0 {
                    dwr.push_all(&dw);
                }
                out = wt;
                dout.copy_from_slice(&dw);
            }
            for (e, cols) in sensor.iter_mut() {
                out = e.output_tangent(out, &mut dout, &s, &d, cols);
            }
            if !(out.is_finite() && xt.is_finite()) {
                return Err(diverged(t, xt, out));
            }
            let same = output.is_none() && mv == Move::Hold && t > 0 && dout == prev_out;
            visit(t, out, &dout, same)?;
            std::mem::swap(&mut dout, &mut prev_out);
        }
        dxr.push(&dxt, &xcols);
    }
    Ok(())
}

/// The augmented cascade's output and its dense Jacobian (N x p, row-major; the refits use
/// `augmented_oe_factor`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn augmented_sensitivity(
    chain: &AugmentedChain,
    effects: &[(AnyEffect, Vec<Option<usize>>)],
    u: &[f64],
    t0: f64,
    time_scale: f64,
    start: &Start,
    p: usize,
) -> Result<Sensitivity> {
    let mut out = Sensitivity {
        output: guard::buffer(u.len(), "the simulated output")?,
        jacobian: guard::buffer(u.len().saturating_mul(p), "the Jacobian")?,
        cols: p,
    };
    walk_augmented(
        chain,
        effects,
        u,
        t0,
        time_scale,
        start,
        p,
        |_, yt, row, _| {
            out.output.push(yt);
            out.jacobian.extend_from_slice(row);
            Ok(())
        },
    )?;
    Ok(out)
}

/// R_aug of [J | r] over t >= `warmup` (J = d y_sim / d theta, r = y - y_sim) and the cost
/// sum r^2, streamed with `sensitivity::cascade_oe_factor`'s two economies: a row on L is
/// zero in R's own columns (m_R1, c_R, m_R2..) and one on R in L's (c_L, m_L2..) unless an
/// effect mixes them (compliance's resonance filters rows of both), so each row folds into
/// the narrowest of three factors (without R's columns, without L's, all) that holds it,
/// tested on the row itself; and a run of equal rows (a held backlash) folds as one
/// (`RowSink::repeat`). The folding runs on a second thread when `threads` >= 2.
#[allow(clippy::too_many_arguments)]
pub(crate) fn augmented_oe_factor(
    chain: &AugmentedChain,
    effects: &[(AnyEffect, Vec<Option<usize>>)],
    u: &[f64],
    y: &[f64],
    warmup: usize,
    t0: f64,
    time_scale: f64,
    start: &Start,
    p: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64)> {
    let lin = &chain.cascade.linear;
    let lay = Layout {
        na: lin.na(),
        nb: lin.nb(),
        n: branch_degree(&chain.cascade.backlash)?,
    };
    // L's own columns c_l..m_r1, R's m_r1..r
    let (c_l, m_r1, r_end) = (lay.c_l(), lay.m_r1(), lay.r());
    let left: Vec<usize> = (0..m_r1).chain(r_end..p).collect();
    let right: Vec<usize> = (0..c_l).chain(m_r1..p).collect();
    let all: Vec<usize> = (0..p).collect();
    let widths = [left.len(), right.len(), p];
    let streamed = fold_stream_parts(&widths, threads, |sink| {
        walk_augmented(
            chain,
            effects,
            u,
            t0,
            time_scale,
            start,
            p,
            |t, yt, row, same| {
                if t < warmup {
                    return Ok(());
                }
                let r = y[t] - yt;
                if same && sink.repeat(r) {
                    return Ok(());
                }
                if row[m_r1..r_end].iter().all(|v| *v == 0.0) {
                    sink.push_part(0, &[&row[..m_r1], &row[r_end..]], r)
                } else if row[c_l..m_r1].iter().all(|v| *v == 0.0) {
                    sink.push_part(1, &[&row[..c_l], &row[m_r1..]], r)
                } else {
                    sink.push_part(2, &[row], r)
                }
            },
        )
    })?;
    let factor = TriangularFactor::embed_sum(
        p,
        &[
            (&streamed.factors[0], &left),
            (&streamed.factors[1], &right),
            (&streamed.factors[2], &all),
        ],
        streamed.rows,
        streamed.dispersion,
    );
    finish(factor.map(|f| (f, streamed.sum_squares)))
}

/// g = J^T r over t >= `warmup` and the cost, in the forward pass (no factor).
#[allow(clippy::too_many_arguments)]
pub(crate) fn augmented_oe_gradient(
    chain: &AugmentedChain,
    effects: &[(AnyEffect, Vec<Option<usize>>)],
    u: &[f64],
    y: &[f64],
    warmup: usize,
    t0: f64,
    time_scale: f64,
    start: &Start,
    p: usize,
) -> Result<OeGradient> {
    let mut g = OeGradient {
        gradient: vec![0.0; p],
        cost: 0.0,
    };
    walk_augmented(
        chain,
        effects,
        u,
        t0,
        time_scale,
        start,
        p,
        |t, yt, row, _| {
            if t >= warmup {
                let r = y[t] - yt;
                g.cost += r * r;
                for (gk, v) in g.gradient.iter_mut().zip(row) {
                    *gk += r * v;
                }
            }
            Ok(())
        },
    )?;
    if !g.cost.is_finite() || g.gradient.iter().any(|v| !v.is_finite()) {
        return Err(overflowed());
    }
    Ok(g)
}
