//! Simulated output and its exact derivatives with respect to every parameter, for the
//! output-error (simulation error) refinement. Sensitivity recursions run beside the model:
//!   dx(t)/da_i = u(t-i) - sum_j b_j dx(t-j)/da_i,   dx(t)/db_j = -x(t-j) - sum_k b_k dx(t-k)/db_j,
//!   on L: dy = L'(xi1) dx + [dL/dc_L = L'(xi1), dL/dm_Li = xi1^i],
//!   on R: dy = R'(xi2) dx + [dR/dc_R = -R'(xi2), dR/dm_Ri = xi2^i],
//!   holding: dy(t) = dy(t-1);
//!   sandwich: dw(t) = sum_i r_i dy(t-i) - sum_j s_j dw(t-j) + [dw/dr_i = y(t-i), dw/ds_j = -w(t-j)].
//! Column order: theta's layout (`problem::Layout`, its one home): a_1..a_na, b_1..b_nb, c_L,
//! m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn, then for the sandwich r_2..r_nr, s_1..s_ns (m_L1 = 1
//! and r_1 = 1 are fixed); with an initial state (`initial::Start`) x0_1..x0_n, y_prev,
//! w0_1..w0_m follow: dx(t)/dx0_k = g(t-k) (g the impulse response of 1/B), dy/dy_prev = 1
//! until the first move, dw(t)/dw0_k = [t = k] + the recursion.

use crate::error::{Error, Result};
use crate::guard;
use crate::identify::gradient::Motion;
use crate::identify::initial::{simulate_from, start_cols, Start};
use crate::identify::problem::Layout;
use crate::linalg::streaming::{
    default_threads, fold_stream, fold_stream_parts, RowSink, StreamedParts, TriangularFactor,
};
use crate::model::backlash::{GeneralBacklash, PaddedSlope, PaddedStep};
use crate::model::linear::LinearBlock;
use crate::model::signal::{check_same_length, check_signal};

/// Samples from which the default output-error factors fold on a second thread. The
/// sequential sensitivity recursion is the larger part of the work, so the hand-over only
/// pays on long records: cascade at p = 11 (2026-11-22, this 2-core machine), 1 thread / 2
/// threads 0.78 / 0.81 ms at N = 2e4, 1.95 / 1.81 ms at 5e4, 7.8 / 7.0 ms at 2e5.
const OE_SECOND_THREAD_FROM: usize = 50_000;

/// Threads of the default output-error factors for `rows` samples: the recursion, plus one
/// folding thread on long records when the machine has a second core (the same bits either
/// way), or from `TIME_SPLIT_FROM` samples the cascade's two halves (the same to rounding).
pub(crate) fn oe_threads(rows: usize) -> usize {
    if rows < OE_SECOND_THREAD_FROM {
        1
    } else {
        default_threads().min(2)
    }
}

/// Output and row-major Jacobian (rows = samples, cols = parameters).
#[derive(Debug, Clone, PartialEq)]
pub struct Sensitivity {
    pub output: Vec<f64>,
    pub jacobian: Vec<f64>,
    pub cols: usize,
}

/// Jacobian columns of the cascade: a, b, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn.
pub(crate) fn cascade_cols(linear: &LinearBlock, backlash: &GeneralBacklash) -> usize {
    linear.na() + linear.nb() + 2 * backlash.left().coefficients().len() + 1
}

/// Jacobian columns of the sandwich: the cascade's, then r_2..r_nr, s_1..s_ns.
pub(crate) fn sandwich_cols(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
) -> usize {
    cascade_cols(input_linear, backlash) + output_linear.na().saturating_sub(1) + output_linear.nb()
}

/// The cascade output y and d y / d theta (dense: N x p; the fits use `cascade_oe_factor`).
pub fn cascade_sensitivity(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
) -> Result<Sensitivity> {
    check_signal("u", u)?;
    let cols = cascade_cols(linear, backlash);
    let mut out = Sensitivity {
        output: guard::buffer(u.len(), "the simulated output")?,
        jacobian: guard::buffer(u.len().saturating_mul(cols), "the Jacobian")?,
        cols,
    };
    walk_cascade(linear, backlash, None, u, |_, yt, _, row| {
        out.output.push(yt);
        out.jacobian.extend_from_slice(row);
        Ok(())
    })?;
    Ok(out)
}

/// The sandwich output w and d w / d theta (dense: N x p; the fits use `sandwich_oe_factor`).
pub fn sandwich_sensitivity(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
) -> Result<Sensitivity> {
    check_signal("u", u)?;
    let cols = sandwich_cols(input_linear, backlash, output_linear);
    let mut out = Sensitivity {
        output: guard::buffer(u.len(), "the simulated output")?,
        jacobian: guard::buffer(u.len().saturating_mul(cols), "the Jacobian")?,
        cols,
    };
    walk_sandwich(
        input_linear,
        backlash,
        output_linear,
        None,
        u,
        |_, wt, row| {
            out.output.push(wt);
            out.jacobian.extend_from_slice(row);
            Ok(())
        },
    )?;
    Ok(out)
}

// ---- streaming: the output-error factor of [J | r] without the N x p Jacobian ----------------

/// Which case of eq (1) a sample took.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Move {
    Left,
    Right,
    Hold,
}

/// The cascade chain run one sample at a time: x(t), y(t), and dy(t) (`cols` wide; the
/// columns after the backlash model's stay zero): the recursions of the module header, used
/// by the dense Jacobian and the streamed factors. dx/da_i and dx/db_j are lags of u and x
/// filtered by 1/B(q) (w_u(t) = u(t) - sum_k b_k w_u(t-k), likewise w_x): dx(t)/da_i =
/// w_u(t-i), dx(t)/db_j = -w_x(t-j), the same operations as the recursions on dx themselves.
struct ChainStepper<'a> {
    backlash: &'a GeneralBacklash,
    /// The branches with a fixed number of Horner steps (the same values), where the degree
    /// allows: the walk's L(x) and R(x).
    padded: Option<PaddedStep>,
    /// Their slopes likewise (the same values as `Branch::slope`).
    slopes: Option<(PaddedSlope, PaddedSlope)>,
    b: &'a [f64],
    u: &'a [f64],
    /// x(t) of the linear block, a chunk at a time: memory bounded on any record length.
    x: XChunks<'a>,
    lay: Layout,
    /// w_u(t-1), w_u(t-2), .. and w_x(t-1), .. (max(na, nb) lags; 0 before the record).
    wu: Vec<f64>,
    wx: Vec<f64>,
    /// dy(t) after `step(t)` (dy(t-1) before it).
    dy: Vec<f64>,
    /// x(t) after `step(t)`.
    xt: f64,
    y_prev: f64,
    /// With an initial state: the column of x0_1 and g(t-1), g(t-2), .. (n lags), g the
    /// impulse response of 1/B, dx(t)/dx0_k = g(t-k) (0-based t, k = 0..n).
    init_col: Option<usize>,
    g: Vec<f64>,
}

impl<'a> ChainStepper<'a> {
    fn new(
        linear: &'a LinearBlock,
        backlash: &'a GeneralBacklash,
        start: Option<&Start<'a>>,
        u: &'a [f64],
        cols: usize,
    ) -> Result<Self> {
        let x = XChunks::new(linear, u, start.map(|st| &st.state.x0[..]))?;
        let mut chain = Self::with_x(linear, backlash, start, u, cols, x)?;
        if let Some(st) = start {
            chain.dy[st.y_prev_col()] = 1.0; // dy(-1)/dy_prev: y(0) is the memory itself
            chain.y_prev = st.state.y_prev;
        }
        Ok(chain)
    }

    /// A walk of the samples from `from` on started from a guess (every past and lag zero, the
    /// memory y 0), to be checked against the exact walk where the two meet (`snapshot`): the
    /// linear recursions forget their start as the poles' powers, the backlash at its first
    /// move across the band. None where the guessed walk's x overflows.
    fn guessed(
        linear: &'a LinearBlock,
        backlash: &'a GeneralBacklash,
        start: Option<&Start<'a>>,
        u: &'a [f64],
        cols: usize,
        from: usize,
    ) -> Result<Option<Self>> {
        match XChunks::from_rest_at(linear, u, from) {
            Some(x) => Self::with_x(linear, backlash, start, u, cols, x).map(Some),
            None => Ok(None),
        }
    }

    /// The walk over x, every lag zero, the memory y 0 (the initial state's columns, if any,
    /// after the model's).
    fn with_x(
        linear: &'a LinearBlock,
        backlash: &'a GeneralBacklash,
        start: Option<&Start<'a>>,
        u: &'a [f64],
        cols: usize,
        x: XChunks<'a>,
    ) -> Result<Self> {
        let n = branch_degree(backlash)?;
        let lay = Layout {
            na: linear.na(),
            nb: linear.nb(),
            n,
        };
        let lags = lay.na.max(lay.nb);
        Ok(Self {
            backlash,
            padded: backlash.padded_step(),
            slopes: backlash.padded_slopes(),
            b: linear.b(),
            u,
            x,
            wu: vec![0.0; lags],
            wx: vec![0.0; lags],
            dy: vec![0.0; cols],
            xt: 0.0,
            lay,
            y_prev: 0.0,
            init_col: start.map(|st| st.col),
            g: vec![0.0; start.map_or(0, Start::nx)],
        })
    }

    /// The walk's state after sample t: the last x values, y(t), the lags and dy(t).
    fn snapshot(&self, t: usize, on_right: bool) -> Option<WalkState> {
        let lags = self.lay.na.max(self.lay.nb);
        Some(WalkState {
            x: self.x.recent(t, lags)?.to_vec(),
            y: self.y_prev,
            lags: [&self.wu[..], &self.wx[..], &self.g[..]].concat(),
            dy: self.dy.clone(),
            on_right,
        })
    }

    /// Advance to sample t (called for t = 0, 1, ... in order): returns y(t) and its case,
    /// leaves dy(t).
    #[inline]
    fn step(&mut self, t: usize) -> Result<(f64, Move)> {
        let (na, n) = (self.lay.na, self.lay.n);
        let nl = self.lay.linear();
        // g(t) = [t = 0] - sum_k b_k g(t-k), with an initial state only
        let gt = match self.init_col {
            Some(_) => filtered(f64::from(u8::from(t == 0)), self.b, &self.g),
            None => 0.0,
        };
        let bl = self.backlash;
        let xt = self.x.at(t)?;
        self.xt = xt;
        let yp = self.y_prev;
        // eq (1) in its case order, each branch evaluated once (`GeneralBacklash::step`)
        let lv = match &self.padded {
            Some(p) => p.left_value(xt),
            None => bl.left().value(xt),
        };
        let (yt, mv) = if lv <= yp {
            (lv, Move::Left)
        } else {
            let rv = match &self.padded {
                Some(p) => p.right_value(xt),
                None => bl.right().value(xt),
            };
            if rv >= yp {
                (rv, Move::Right)
            } else {
                (yp, Move::Hold)
            }
        };
        if !yt.is_finite() {
            return Err(crate::model::backlash::output_overflow(t, xt));
        }
        if mv != Move::Hold {
            let dy = &mut self.dy;
            // zero the other branch's columns (the linear ones and this branch's are written
            // below; columns after the backlash model's are never written)
            let other = match mv {
                Move::Left => self.lay.m_r1()..self.lay.m_r1() + n + 1,
                _ => self.lay.c_l()..self.lay.m_r1(),
            };
            for v in &mut dy[other] {
                *v = 0.0;
            }
            let (branch, xi) = match mv {
                Move::Left => (bl.left(), xt + bl.c_left()),
                _ => (bl.right(), xt - bl.c_right()),
            };
            let slope = match (&self.slopes, mv) {
                (Some((left, _)), Move::Left) => left.slope(xt),
                (Some((_, right)), _) => right.slope(xt),
                (None, _) => branch.slope(xt),
            };
            for (k, w) in self.wu[..na].iter().enumerate() {
                dy[k] = slope * w;
            }
            for (k, w) in self.wx[..nl - na].iter().enumerate() {
                dy[na + k] = slope * -w;
            }
            if let Some(col) = self.init_col {
                // dx(t)/dx0_k = g(t-k): g(t), then the lags; y_prev no longer matters
                let nx = self.g.len();
                dy[col] = slope * gt;
                for (k, w) in self.g[..nx.saturating_sub(1)].iter().enumerate() {
                    dy[col + 1 + k] = slope * w;
                }
                dy[col + nx] = 0.0;
            }
            let mut p = xi;
            if mv == Move::Left {
                dy[self.lay.c_l()] = slope;
                for i in 2..=n {
                    p *= xi;
                    dy[self.lay.m_l(i)] = p;
                }
            } else {
                dy[self.lay.c_r()] = -slope;
                dy[self.lay.m_r1()] = xi;
                for i in 2..=n {
                    p *= xi;
                    dy[self.lay.m_r(i)] = p;
                }
            }
        }
        // else holding: dy(t) = dy(t-1), already in place (zero before the record)

        // w_u(t), w_x(t) join the lags for sample t + 1
        let (wu, wx) = (
            filtered(self.u[t], self.b, &self.wu),
            filtered(xt, self.b, &self.wx),
        );
        push_lag(&mut self.wu, wu);
        push_lag(&mut self.wx, wx);
        if self.init_col.is_some() {
            push_lag(&mut self.g, gt);
        }
        self.y_prev = yt;
        Ok((yt, mv))
    }
}

/// Samples of x held at a time (8 MB).
const X_CHUNK: usize = guard::CHUNK;

/// x of a linear block over a record, from rest or from an initial state x0, simulated
/// `X_CHUNK` samples at a time: each chunk continues the recursion from the state the
/// previous one ended in, the same numbers as one simulation of the whole record.
pub(crate) struct XChunks<'a> {
    linear: &'a LinearBlock,
    u: &'a [f64],
    /// The initial state's parameters x0 (added at the record's first samples), if any.
    x0: Option<&'a [f64]>,
    /// x(t) for t in `from..from + x.len()`.
    x: Vec<f64>,
    from: usize,
}

impl<'a> XChunks<'a> {
    /// The first chunk simulated; errors as one simulation of the whole record reports them.
    pub(crate) fn new(
        linear: &'a LinearBlock,
        u: &'a [f64],
        x0: Option<&'a [f64]>,
    ) -> Result<Self> {
        let x = first_x(linear, &u[..u.len().min(X_CHUNK)], x0)
            .or_else(|e| whole_x_error(linear, u, x0, e))?;
        Ok(Self {
            linear,
            u,
            x0,
            x,
            from: 0,
        })
    }

    /// x(t), for t = 0, 1, ... in order.
    #[inline(always)]
    pub(crate) fn at(&mut self, t: usize) -> Result<f64> {
        if t >= self.from + self.x.len() {
            self.advance()?;
        }
        Ok(self.x[t - self.from])
    }

    /// x from sample `from` on, the linear block started there at rest (a guess: see
    /// `ChainStepper::guessed`); None where it overflows.
    fn from_rest_at(linear: &'a LinearBlock, u: &'a [f64], from: usize) -> Option<Self> {
        let to = (from + X_CHUNK).min(u.len());
        let x = linear.simulate(&u[from..to], &linear.rest_state()).ok()?;
        Some(Self {
            linear,
            u,
            x0: None,
            x,
            from,
        })
    }

    /// x(t - k + 1..=t), if the chunk held has them.
    fn recent(&self, t: usize, k: usize) -> Option<&[f64]> {
        let end = (t + 1).checked_sub(self.from)?;
        self.x.get(end.checked_sub(k)?..end)
    }

    /// `visit(from, x)` for every chunk in order (`from` the index of its first sample).
    pub(crate) fn each(mut self, mut visit: impl FnMut(usize, &[f64]) -> Result<()>) -> Result<()> {
        loop {
            visit(self.from, &self.x)?;
            if self.from + self.x.len() >= self.u.len() {
                return Ok(());
            }
            self.advance()?;
        }
    }

    #[cold]
    fn advance(&mut self) -> Result<()> {
        let from = self.from + self.x.len();
        let u_held = &self.u[self.from..from];
        let state = self
            .linear
            .state_after(&self.linear.rest_state(), u_held, &self.x);
        let to = (from + X_CHUNK).min(self.u.len());
        self.x = self
            .linear
            .simulate(&self.u[from..to], &state)
            .or_else(|e| whole_x_error(self.linear, self.u, self.x0, e))?;
        self.from = from;
        Ok(())
    }
}

/// x over the first samples of a record, from rest or from the initial state x0.
fn first_x(linear: &LinearBlock, u: &[f64], x0: Option<&[f64]>) -> Result<Vec<f64>> {
    match x0 {
        None => linear.simulate(u, &linear.rest_state()),
        Some(x0) => simulate_from(linear, u, x0),
    }
}

/// The error of simulating x over the whole record `u` (which names the sample of the
/// record, not of a chunk), for a chunk's simulation that failed with `chunk_error`.
#[cold]
fn whole_x_error(
    linear: &LinearBlock,
    u: &[f64],
    x0: Option<&[f64]>,
    chunk_error: Error,
) -> Result<Vec<f64>> {
    first_x(linear, u, x0).and(Err(chunk_error))
}

/// s(t) - sum_k b_k w(t-k), with `lags` = [w(t-1), w(t-2), ..].
#[inline(always)]
fn filtered(s: f64, b: &[f64], lags: &[f64]) -> f64 {
    let mut acc = s;
    for (bk, w) in b.iter().zip(lags) {
        acc -= bk * w;
    }
    acc
}

/// Shift the lags by one sample, `newest` first (a plain loop: a few values, where
/// `copy_within` would call memmove).
#[inline(always)]
fn push_lag(lags: &mut [f64], newest: f64) {
    for i in (1..lags.len()).rev() {
        lags[i] = lags[i - 1];
    }
    if let Some(first) = lags.first_mut() {
        *first = newest;
    }
}

/// The factor and cost of `fold_stream`, refused when the Jacobian or residual overflowed.
pub(crate) fn finish(folded: Result<(TriangularFactor, f64)>) -> Result<(TriangularFactor, f64)> {
    let (factor, cost) = folded?;
    if !cost.is_finite() || factor.r_aug().iter().any(|v| !v.is_finite()) {
        return Err(overflowed());
    }
    Ok((factor, cost))
}

pub(crate) fn overflowed() -> Error {
    Error::Model(
        "output-error Jacobian overflowed: the sensitivities of the simulated output are not \
         finite (an unstable or badly scaled estimate); scale the signals down or start from \
         a stable estimate"
            .into(),
    )
}

/// The degree n of both branches: the Jacobian columns assume L and R have the same.
pub(crate) fn branch_degree(backlash: &GeneralBacklash) -> Result<usize> {
    let n = backlash.left().coefficients().len();
    if backlash.right().coefficients().len() != n {
        return Err(Error::Model("both branches need the same degree n".into()));
    }
    Ok(n)
}

pub(crate) fn check_pair(u: &[f64], y: &[f64], y_name: &str) -> Result<()> {
    check_signal("u", u)?;
    check_signal(y_name, y)?;
    check_same_length(u, y, y_name)
}

/// The output-error least-squares problem of the cascade in factored form: R_aug of
/// [J | r] over the samples t >= `warmup`, J = d y_sim / d theta (the columns of
/// `cascade_sensitivity`), r = y - y_sim, and the cost sum r^2. The sensitivity recursions
/// run sample by sample keeping only the rows they need; memory does not grow with N x p.
///
/// Two properties of the rows make the fold cheap. A row on L is zero in R's columns and a
/// row on R in L's, so each branch's rows fold into a factor over the linear columns and
/// that branch's own (`fold_stream_parts`), and `TriangularFactor::embed_sum` adds the two.
/// While the backlash holds, dy(t) = dy(t-1): a run of equal rows folds as one
/// (`RowSink::repeat`). The result is the factor of the full rows to rounding.
pub fn cascade_oe_factor(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<(TriangularFactor, f64)> {
    cascade_oe_factor_threads(linear, backlash, u, y, warmup, oe_threads(u.len()))
}

/// `cascade_oe_factor` with the folding on a second thread when `threads` >= 2 (the same
/// bits either way); from `TIME_SPLIT_FROM` samples the record's two halves walked on two
/// threads instead (the same to rounding, `walk_in_halves`).
pub fn cascade_oe_factor_threads(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64)> {
    check_pair(u, y, "y")?;
    cascade_oe_factor_from(linear, backlash, None, u, y, warmup, threads)
}

/// `cascade_oe_factor_threads` of a record checked before (`Problem`) from an initial state
/// (its columns after the model's), or from rest (None).
pub(crate) fn cascade_oe_factor_from(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64)> {
    cascade_oe_factor_motion_from(linear, backlash, start, u, y, warmup, threads)
        .map(|(factor, cost, _)| (factor, cost))
}

/// `cascade_oe_factor_from` with the record's `Motion` over t >= warmup at theta (the walk's
/// x and cases).
pub(crate) fn cascade_oe_factor_motion_from(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64, Motion)> {
    let model = cascade_cols(linear, backlash);
    let cols = model + start_cols(start);
    let nl = linear.na() + linear.nb();
    // L's rows: a, b, c_L, m_L2..m_Ln; R's rows: a, b, m_R1, c_R, m_R2..m_Rn; the initial
    // state's columns (x0, y_prev) in both
    let split = nl + backlash.left().coefficients().len();
    let left: Vec<usize> = (0..split).chain(model..cols).collect();
    let right: Vec<usize> = (0..nl).chain(split..cols).collect();
    // the rows of sample t (stepped by `Walked::step`) into their branch's part, its x and
    // case into the motion
    let feed = |sink: &mut RowSink, walked: &mut Walked, t: usize, chain: &ChainStepper| {
        let (yt, mv) = (chain.y_prev, walked.mv);
        if t < warmup {
            return Ok(());
        }
        walked
            .motion
            .add(&[chain.xt], &[u8::from(mv != Move::Hold)]);
        let (r, dy) = (y[t] - yt, &chain.dy);
        if mv == Move::Hold && sink.repeat(r) {
            return Ok(());
        }
        match walked.on_right {
            false => sink.push_part(0, &[&dy[..split], &dy[model..]], r),
            true => sink.push_part(1, &[&dy[..nl], &dy[split..]], r),
        }
    };
    let widths = [left.len(), right.len()];
    let halves = match time_split(linear, u.len(), threads) {
        Some((m, lead)) => {
            walk_in_halves(linear, backlash, start, u, cols, &widths, m, lead, &feed)?
        }
        None => None,
    };
    let (streamed, motion) = match halves {
        Some(halves) => halves,
        None => {
            let mut walked = Walked::new();
            let streamed = fold_stream_parts(&widths, threads, |sink| {
                let mut chain = ChainStepper::new(linear, backlash, start, u, cols)?;
                for t in 0..u.len() {
                    walked.step(&mut chain, t)?;
                    feed(sink, &mut walked, t, &chain)?;
                }
                Ok(())
            })?;
            (streamed, walked.motion)
        }
    };
    let factor = TriangularFactor::embed_sum(
        cols,
        &[
            (&streamed.factors[0], &left),
            (&streamed.factors[1], &right),
        ],
        streamed.rows,
        streamed.dispersion,
    );
    finish(factor.map(|f| (f, streamed.sum_squares))).map(|(f, c)| (f, c, motion))
}

/// What a walk that feeds a factor carries from sample to sample: the case of the sample just
/// stepped, the branch of dy and the motion so far.
struct Walked {
    mv: Move,
    on_right: bool,
    motion: Motion,
}

impl Walked {
    fn new() -> Self {
        Self {
            mv: Move::Hold,
            on_right: false,
            motion: Motion::empty(),
        }
    }

    /// The walk to sample t: its case, and the branch of dy after it (before any move: only
    /// y_prev's column, counted with L).
    fn step(&mut self, chain: &mut ChainStepper, t: usize) -> Result<()> {
        self.mv = chain.step(t)?.1;
        match self.mv {
            Move::Left => self.on_right = false,
            Move::Right => self.on_right = true,
            Move::Hold => {}
        }
        Ok(())
    }
}

/// Records from which the cascade's factor walks its two halves on two threads (each walk is
/// about four fifths of a one-thread factor's time).
const TIME_SPLIT_FROM: usize = 1 << 21;

/// (M, lead): the second half's rows start at M, its walk `lead` samples earlier from a
/// guessed state (the poles' powers below 1e-20 over the lead); None for one thread, short
/// records or slow poles.
fn time_split(linear: &LinearBlock, len: usize, threads: usize) -> Option<(usize, usize)> {
    let rho = linear.spectral_radius();
    if threads < 2 || len < TIME_SPLIT_FROM || rho.is_nan() || rho >= 1.0 {
        return None;
    }
    let forget = if rho > 0.0 {
        (1e-20f64.ln() / rho.ln()).ceil()
    } else {
        1.0
    };
    let lead = (4.0 * forget).max(4096.0) as usize;
    (lead <= len / 8).then_some(((len + lead) / 2, lead))
}

/// The walk's state after a sample (`ChainStepper::snapshot`).
struct WalkState {
    x: Vec<f64>,
    y: f64,
    lags: Vec<f64>,
    dy: Vec<f64>,
    on_right: bool,
}

impl WalkState {
    /// Equal to rounding: each vector within 1e-12 of its largest value.
    fn meets(&self, exact: &WalkState) -> bool {
        let close = |a: &[f64], b: &[f64]| {
            let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (p - q).abs() <= 1e-12 * scale)
        };
        self.on_right == exact.on_right
            && close(&[self.y], &[exact.y])
            && close(&self.x, &exact.x)
            && close(&self.lags, &exact.lags)
            && close(&self.dy, &exact.dy)
    }
}

/// The factor's rows of samples < M walked on this thread and those >= M on a second one,
/// whose walk starts `lead` samples before M from a guess; their parts merged when the
/// guessed walk has met the exact one at M (else None: the caller walks the record in one
/// pass, which also reports any error of the guessed part). The result differs from the
/// one-pass walk's by rounding.
#[allow(clippy::too_many_arguments)]
fn walk_in_halves<F>(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    cols: usize,
    widths: &[usize],
    m: usize,
    lead: usize,
    feed: &F,
) -> Result<Option<(StreamedParts, Motion)>>
where
    F: Fn(&mut RowSink, &mut Walked, usize, &ChainStepper) -> Result<()> + Sync,
{
    let stop = guard::scope();
    std::thread::scope(|scope| {
        let tail = scope.spawn(
            move || -> Result<Option<(WalkState, StreamedParts, Motion)>> {
                guard::adopt(stop);
                let guessed = ChainStepper::guessed(linear, backlash, start, u, cols, m - lead)?;
                let Some(mut chain) = guessed else {
                    return Ok(None);
                };
                let mut walked = Walked::new();
                for t in m - lead..m {
                    if walked.step(&mut chain, t).is_err() {
                        return Ok(None);
                    }
                }
                let Some(at_m) = chain.snapshot(m - 1, walked.on_right) else {
                    return Ok(None);
                };
                let parts = fold_stream_parts(widths, 1, |sink| {
                    for t in m..u.len() {
                        walked.step(&mut chain, t)?;
                        feed(sink, &mut walked, t, &chain)?;
                    }
                    Ok(())
                });
                Ok(parts.ok().map(|p| (at_m, p, walked.motion)))
            },
        );
        let mut chain = ChainStepper::new(linear, backlash, start, u, cols)?;
        let mut walked = Walked::new();
        let mut head = fold_stream_parts(widths, 1, |sink| {
            for t in 0..m {
                walked.step(&mut chain, t)?;
                feed(sink, &mut walked, t, &chain)?;
            }
            Ok(())
        })?;
        let exact = chain.snapshot(m - 1, walked.on_right);
        let tail = match tail.join() {
            Ok(tail) => tail?,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        let (Some(exact), Some((guessed, tail, tail_motion))) = (exact, tail) else {
            return Ok(None);
        };
        if !guessed.meets(&exact) {
            return Ok(None);
        }
        for (h, t) in head.factors.iter_mut().zip(&tail.factors) {
            h.merge(t)?;
        }
        head.rows += tail.rows;
        head.sum_squares += tail.sum_squares;
        head.dispersion += tail.dispersion;
        Ok(Some((head, walked.motion.join(&tail_motion))))
    })
}

/// The cascade's output y(t), its case and Jacobian row dy(t), handed to `visit(t, y(t),
/// case, dy(t))` for t = 0, 1, ... (the one place the cascade's sensitivity recursions run).
pub(crate) fn walk_cascade(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    mut visit: impl FnMut(usize, f64, Move, &[f64]) -> Result<()>,
) -> Result<()> {
    let cols = cascade_cols(linear, backlash) + start_cols(start);
    let mut chain = ChainStepper::new(linear, backlash, start, u, cols)?;
    for t in 0..u.len() {
        let (yt, mv) = chain.step(t)?;
        visit(t, yt, mv, &chain.dy)?;
    }
    Ok(())
}

/// The output-error least-squares problem of the sandwich in factored form: R_aug of
/// [J | r] over the samples t >= `warmup`, J = d w_sim / d theta (the columns of
/// `sandwich_sensitivity`), r = w - w_sim, and the cost sum r^2, with O(p (nr + ns)) memory
/// for the recursions.
pub fn sandwich_oe_factor(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
    w: &[f64],
    warmup: usize,
) -> Result<(TriangularFactor, f64)> {
    sandwich_oe_factor_threads(
        input_linear,
        backlash,
        output_linear,
        u,
        w,
        warmup,
        oe_threads(u.len()),
    )
}

/// `sandwich_oe_factor` with the folding on a second thread when `threads` >= 2 (the same
/// bits either way).
pub fn sandwich_oe_factor_threads(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
    w: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64)> {
    check_pair(u, w, "w")?;
    sandwich_oe_factor_from(
        input_linear,
        backlash,
        output_linear,
        None,
        u,
        w,
        warmup,
        threads,
    )
}

/// `sandwich_oe_factor_threads` of a record checked before (`Problem`) from an initial state (its columns after the model's), or from
/// rest (None).
#[allow(clippy::too_many_arguments)]
pub(crate) fn sandwich_oe_factor_from(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    start: Option<&Start>,
    u: &[f64],
    w: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(TriangularFactor, f64)> {
    let cols = sandwich_cols(input_linear, backlash, output_linear) + start_cols(start);
    finish(fold_stream(cols, threads, |sink| {
        walk_sandwich(
            input_linear,
            backlash,
            output_linear,
            start,
            u,
            |t, wt, row| match t >= warmup {
                true => sink.push(row, w[t] - wt),
                false => Ok(()),
            },
        )
    }))
}

/// The sandwich's output w(t) and Jacobian row dw(t), handed to `visit(t, w(t), dw(t))` for
/// t = 0, 1, ...; y, dy, w, dw are kept in rings of nr + 1 and ns + 1 samples.
/// From an initial state (its columns after the model's: x0, y_prev, w0; w0_k enters w at
/// the record's k-th sample), or from rest (None).
pub(crate) fn walk_sandwich(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    start: Option<&Start>,
    u: &[f64],
    mut visit: impl FnMut(usize, f64, &[f64]) -> Result<()>,
) -> Result<()> {
    let (r, s) = (output_linear.a(), output_linear.b());
    let (nr, ns) = (r.len(), s.len());
    let inner = cascade_cols(input_linear, backlash);
    let cols = inner + nr.saturating_sub(1) + ns + start_cols(start);
    let mut chain = ChainStepper::new(input_linear, backlash, start, u, cols)?;
    let (w0, w0_col): (&[f64], usize) = match start {
        Some(st) => (&st.state.w0, st.w0_col()),
        None => (&[], 0),
    };
    // rings: y(t), dy(t) over nr + 1 samples, w(t), dw(t) over ns + 1
    let (ry, rw) = (nr + 1, ns + 1);
    let mut y_ring = vec![0.0; ry];
    let mut dy_ring = vec![0.0; ry * cols];
    let mut w_ring = vec![0.0; rw];
    let mut dw_ring = vec![0.0; rw * cols];
    for t in 0..u.len() {
        let (yt, _) = chain.step(t)?;
        let cy = t % ry;
        y_ring[cy] = yt;
        dy_ring[cy * cols..(cy + 1) * cols].copy_from_slice(&chain.dy);
        let cw = t % rw;
        let (before, rest) = dw_ring.split_at_mut(cw * cols);
        let (dw, after) = rest.split_at_mut(cols);
        dw.fill(0.0);
        let mut wt = 0.0;
        for (ii, ri) in r.iter().enumerate() {
            let i = ii + 1;
            if i <= t {
                let k = (t - i) % ry;
                let y_lag = y_ring[k];
                wt += ri * y_lag;
                let dy_lag = &dy_ring[k * cols..(k + 1) * cols];
                for (d, v) in dw.iter_mut().zip(dy_lag) {
                    *d += ri * v;
                }
                if i >= 2 {
                    dw[inner + i - 2] += y_lag;
                }
            }
        }
        for (jj, sj) in s.iter().enumerate() {
            let j = jj + 1;
            if j <= t {
                let k = (t - j) % rw;
                let w_lag = w_ring[k];
                wt -= sj * w_lag;
                let dw_lag = if k < cw {
                    &before[k * cols..(k + 1) * cols]
                } else {
                    &after[(k - cw - 1) * cols..(k - cw) * cols]
                };
                for (d, v) in dw.iter_mut().zip(dw_lag) {
                    *d -= sj * v;
                }
                dw[inner + nr - 1 + jj] -= w_lag;
            }
        }
        if let Some(v) = w0.get(t) {
            wt += v;
            dw[w0_col + t] += 1.0;
        }
        if !wt.is_finite() {
            return Err(crate::model::linear::overflow(output_linear, "w", t));
        }
        w_ring[cw] = wt;
        visit(t, wt, dw)?;
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::test_params::{
        example1, noisy, perturbed, sandwich_from, smooth_input as input, EXAMPLE2_THETA,
    };

    /// The records every output-error pass (factor or gradient) refuses: a cubic estimate
    /// that overflows, an output of the wrong length, a non-finite output, branches of two
    /// degrees. `cascade(linear, backlash, u, y)` and `sandwich(input, backlash, output, u,
    /// w)` run the pass under test.
    pub(crate) fn check_bad_records<T: std::fmt::Debug>(
        cascade: impl Fn(&LinearBlock, &GeneralBacklash, &[f64], &[f64]) -> Result<T>,
        sandwich: impl Fn(&LinearBlock, &GeneralBacklash, &LinearBlock, &[f64], &[f64]) -> Result<T>,
    ) {
        let lin = LinearBlock::new(vec![1.0], vec![]).unwrap();
        let cubic =
            GeneralBacklash::from_estimate(0.1, 0.1, vec![1.0, 0.0, 1.0], vec![1.0, 0.0, 1.0])
                .unwrap();
        let mut u = input(100);
        u[50] = 1e150;
        let y = input(100);
        match cascade(&lin, &cubic, &u, &y) {
            Err(Error::Model(m)) => assert!(m.contains("overflowed"), "{m}"),
            other => panic!("{other:?}"),
        }
        let u = input(100);
        assert!(matches!(
            cascade(&lin, &cubic, &u, &y[..99]),
            Err(Error::Data(_))
        ));
        for nonfinite in [f64::NAN, f64::INFINITY] {
            let mut bad = y.clone();
            bad[7] = nonfinite;
            assert!(matches!(
                cascade(&lin, &cubic, &u, &bad),
                Err(Error::Data(_))
            ));
        }
        let uneven = GeneralBacklash::from_estimate(0.1, 0.1, vec![1.0], vec![1.0, 0.2]).unwrap();
        assert!(matches!(
            cascade(&lin, &uneven, &u, &y),
            Err(Error::Model(_))
        ));
        assert!(matches!(
            sandwich(&lin, &uneven, &lin, &u, &y),
            Err(Error::Model(_))
        ));
    }

    /// R_aug^T R_aug against [J r]^T [J r] of the dense sensitivity, and the cost.
    fn check_factor(
        f: &TriangularFactor,
        cost: f64,
        sens: &Sensitivity,
        measured: &[f64],
        warmup: usize,
    ) {
        let p = sens.cols;
        let n = p + 1;
        let rows = measured.len().saturating_sub(warmup);
        assert_eq!((f.cols(), f.rows()), (p, rows));
        let aug = |t: usize, j: usize| {
            if j < p {
                sens.jacobian[t * p + j]
            } else {
                measured[t] - sens.output[t]
            }
        };
        let r = f.r_aug();
        for i in 0..n {
            for j in 0..n {
                let rtr: f64 = (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum();
                let gram: f64 = (warmup..measured.len())
                    .map(|t| aug(t, i) * aug(t, j))
                    .sum();
                let size = (0..n)
                    .map(|k| {
                        let a: f64 = (warmup..measured.len()).map(|t| aug(t, k).powi(2)).sum();
                        a
                    })
                    .fold(0.0f64, f64::max);
                assert!(
                    (rtr - gram).abs() < 1e-11 * size.max(1e-300),
                    "{i} {j}: {rtr} {gram}"
                );
            }
        }
        let want: f64 = (warmup..measured.len()).map(|t| aug(t, p).powi(2)).sum();
        assert!((cost - want).abs() <= 1e-12 * want, "{cost} {want}");
        // the last column of R_aug carries ||r||^2
        let last: f64 = (0..n).map(|k| r[k * n + p].powi(2)).sum();
        assert!((last - cost).abs() <= 1e-11 * cost, "{last} {cost}");
    }

    #[test]
    fn cascade_oe_factor_is_the_factor_of_the_dense_jacobian() {
        let (lin, bl) = example1();
        let u = input(3000);
        let m = crate::CascadeModel::new(lin.clone(), bl.clone());
        let y = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 3);
        let est_lin = LinearBlock::new(vec![0.65, 0.55], vec![-0.15, 0.3]).unwrap();
        let est = GeneralBacklash::from_estimate(
            0.55,
            0.45,
            vec![1.0, -0.25, 0.28],
            vec![1.45, 0.35, 0.25],
        )
        .unwrap();
        let sens = cascade_sensitivity(&est_lin, &est, &u).unwrap();
        for warmup in [0, 1, 600, 2999, 3000, 5000] {
            let (f, cost) = cascade_oe_factor(&est_lin, &est, &u, &y, warmup).unwrap();
            for threads in [1, 2] {
                let other = cascade_oe_factor_threads(&est_lin, &est, &u, &y, warmup, threads);
                assert_eq!(other.unwrap(), (f.clone(), cost));
            }
            if warmup < u.len() {
                check_factor(&f, cost, &sens, &y, warmup);
            } else {
                assert_eq!((f.rows(), cost), (0, 0.0));
            }
        }
    }

    #[test]
    fn sandwich_oe_factor_is_the_factor_of_the_dense_jacobian() {
        let u = input(3000);
        let (lin, bl, out) = sandwich_from(&EXAMPLE2_THETA);
        let w = noisy(
            &sandwich_sensitivity(&lin, &bl, &out, &u).unwrap().output,
            5,
        );
        let (l2, b2, o2) = sandwich_from(&perturbed(EXAMPLE2_THETA));
        let sens = sandwich_sensitivity(&l2, &b2, &o2, &u).unwrap();
        for warmup in [0, 2, 700] {
            let (f, cost) = sandwich_oe_factor(&l2, &b2, &o2, &u, &w, warmup).unwrap();
            for threads in [1, 2] {
                let other = sandwich_oe_factor_threads(&l2, &b2, &o2, &u, &w, warmup, threads);
                assert_eq!(other.unwrap(), (f.clone(), cost));
            }
            check_factor(&f, cost, &sens, &w, warmup);
        }
        // output orders other than Example 2's: FIR output block, longer denominators
        for (r, s) in [
            (vec![1.0], vec![]),
            (vec![1.0, 0.3, -0.1], vec![0.5, -0.1, 0.05]),
        ] {
            let o3 = LinearBlock::new(r, s).unwrap();
            let sens = sandwich_sensitivity(&l2, &b2, &o3, &u).unwrap();
            let (f, cost) = sandwich_oe_factor(&l2, &b2, &o3, &u, &w, 10).unwrap();
            check_factor(&f, cost, &sens, &w, 10);
        }
    }

    #[test]
    fn oe_factors_report_overflow_and_bad_data() {
        check_bad_records(
            |lin, bl, u, y| cascade_oe_factor(lin, bl, u, y, 0),
            |lin, bl, out, u, w| sandwich_oe_factor(lin, bl, out, u, w, 0),
        );
        let lin = LinearBlock::new(vec![1.0], vec![]).unwrap();
        let cubic =
            GeneralBacklash::from_estimate(0.1, 0.1, vec![1.0, 0.0, 1.0], vec![1.0, 0.0, 1.0])
                .unwrap();
        let unstable = LinearBlock::new(vec![1.0], vec![-3.0]).unwrap();
        let big: Vec<f64> = input(2000).iter().map(|v| v + 1.0).collect();
        let w = vec![0.0; 2000];
        match sandwich_oe_factor(&lin, &cubic, &unstable, &big, &w, 0) {
            Err(Error::Model(m)) => assert!(m.contains("w[") && m.contains("spectral"), "{m}"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            cascade_oe_factor(&lin, &cubic, &[], &[], 0),
            Err(Error::Data(_))
        ));
    }
}
