//! The output-error gradient g = J^T r (J = d y_sim / d theta, r = y - y_sim) and the cost
//! sum r^2 at an estimate, without the Jacobian or its factor. LM uses it to test the end of
//! a short step against the factor of the Jacobian folded where the step began (`refine.py`).
//!
//! The cascade's gradient runs in reverse (the adjoint of the recursions in `sensitivity`):
//!   lambda(t) = r(t) + [t+1 holds] lambda(t+1): the residuals that see dy(t), since a held
//!     sample repeats the row dy of the last move;
//!   on L at t: mu(t) = lambda(t) L'(xi1), g[c_L] += mu(t), g[m_Li] += lambda(t) xi1^i;
//!   on R at t: mu(t) = lambda(t) R'(xi2), g[c_R] -= mu(t), g[m_Ri] += lambda(t) xi2^i;
//!   nu = mu filtered backwards by 1/B (nu(t) = mu(t) - sum_k b_k nu(t+k)), the transpose of
//!     the causal 1/B that makes dx(t)/da_i = w_u(t-i), dx(t)/db_j = -w_x(t-j);
//!   g[a_i] = sum_t nu(t) u(t-i),   g[b_j] = -sum_t nu(t) x(t-j).
//! With an initial state (`initial`): g[x0_k] = nu(k) (x0_k enters x as u enters through a_i)
//! and g[y_prev] = lambda(1) if the first sample holds, else 0 (paper time).
//! The forward pass is the model's own simulation; one backward pass does the rest, with
//! the case flags f1, f2 recomputed as the simulation's, in straight-line code (both
//! branches' terms, weighted by f1 and f2). The sandwich's output
//! filter mixes the rows of every lag, so its gradient sums the forward rows of
//! `sensitivity::walk_sandwich` instead.

use crate::error::Result;
use crate::guard;
use crate::identify::initial::{simulate_from, start_cols, Start};
use crate::identify::sensitivity::{
    branch_degree, cascade_cols, check_pair, overflowed, sandwich_cols, walk_sandwich,
};
use crate::linalg::streaming::default_threads;
use crate::model::backlash::GeneralBacklash;
use crate::model::backlash::Step;
use crate::model::linear::LinearBlock;
use crate::model::linear::{BlockRecursion, Boxed};
use crate::model::switching::switching;

/// g = J^T r over the samples t >= warmup and the cost sum r^2.
#[derive(Debug, Clone, PartialEq)]
pub struct OeGradient {
    pub gradient: Vec<f64>,
    pub cost: f64,
}

impl OeGradient {
    fn new(cols: usize) -> Self {
        Self {
            gradient: vec![0.0; cols],
            cost: 0.0,
        }
    }

    /// Refused when the gradient or the cost overflowed (as the output-error factors).
    fn finished(self) -> Result<Self> {
        if !self.cost.is_finite() || self.gradient.iter().any(|v| !v.is_finite()) {
            return Err(overflowed());
        }
        Ok(self)
    }
}

/// What a simulation at theta says of the record's motion over t >= warmup: how many
/// samples move the backlash (f1 or f2 of eq 12-13) and the range of x (the first linear
/// block's output) they visit. The fit's checks need both at its end (`Problem::motion`);
/// the cascade's two-thread gradient pass has them from its forward pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    pub moving: usize,
    pub x_min: f64,
    pub x_max: f64,
}

impl Motion {
    /// No sample yet.
    pub(crate) fn empty() -> Self {
        Self {
            moving: 0,
            x_min: f64::INFINITY,
            x_max: f64::NEG_INFINITY,
        }
    }

    /// The motion of two sets of samples.
    pub(crate) fn join(&self, other: &Motion) -> Motion {
        Motion {
            moving: self.moving + other.moving,
            x_min: self.x_min.min(other.x_min),
            x_max: self.x_max.max(other.x_max),
        }
    }

    /// Add samples: their x and case (f1 + 2 f2, 0 when holding).
    #[inline]
    pub(crate) fn add(&mut self, x: &[f64], case: &[u8]) {
        for (&xt, &ct) in x.iter().zip(case) {
            self.moving += usize::from(ct != 0);
            self.x_min = self.x_min.min(xt);
            self.x_max = self.x_max.max(xt);
        }
    }
}

/// `OeGradient` of the cascade, by the reverse recursion of the module header.
pub fn cascade_oe_gradient(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    check_pair(u, y, "y")?;
    cascade_oe_gradient_from(linear, backlash, None, u, y, warmup)
}

/// `cascade_oe_gradient` of a record checked before (`Problem`) from an initial state (its columns after the model's), or
/// from rest (None).
pub(crate) fn cascade_oe_gradient_from(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    cascade_oe_gradient_motion_from(linear, backlash, start, u, y, warmup).map(|(g, _)| g)
}

/// `cascade_oe_gradient_from` and, where its pass had them (the two-thread pass), the
/// `Motion` of the record over t >= warmup at no extra pass.
pub(crate) fn cascade_oe_gradient_motion_from(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<(OeGradient, Option<Motion>)> {
    gradient_from_threads(
        linear,
        backlash,
        start,
        u,
        y,
        warmup,
        gradient_threads(u.len()),
    )
}

/// Samples from which the cascade's gradient pass runs on two threads (`split_gradient`):
/// where the second thread's start and its homogeneous responses (about 1000 samples each on
/// Example 1) are small against the pass (about 5 ms at 2e5); below it the pass is the
/// one-thread one, bit for bit. A split pass at 1e6 costs slightly less CPU than the
/// one-thread pass (60 passes: 1.52 against 1.65-1.71 s user time, 2026-11-24); wall times on
/// the shared 2-core machine were too noisy to place the threshold finer.
const GRADIENT_SECOND_THREAD_FROM: usize = 200_000;

/// Threads of the cascade's gradient pass for `rows` samples (`cascade_oe_gradient_threads`).
pub(crate) fn gradient_threads(rows: usize) -> usize {
    if rows < GRADIENT_SECOND_THREAD_FROM {
        1
    } else {
        default_threads().min(2)
    }
}

/// `cascade_oe_gradient` on `threads` threads (two when >= 2: `split_gradient`; the same
/// numbers to rounding).
pub fn cascade_oe_gradient_threads(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<OeGradient> {
    check_pair(u, y, "y")?;
    gradient_from_threads(linear, backlash, None, u, y, warmup, threads).map(|(g, _)| g)
}

/// `cascade_oe_gradient_from` on `threads` threads (two when >= 2 and the record starts
/// from rest: `split_gradient`, which also returns the `Motion`).
fn gradient_from_threads(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    threads: usize,
) -> Result<(OeGradient, Option<Motion>)> {
    branch_degree(backlash)?;
    if threads >= 2 && start.is_none() {
        let split = match backlash.padded_step() {
            Some(padded) => split_gradient(linear, backlash, u, y, warmup, padded),
            None => split_gradient(linear, backlash, u, y, warmup, backlash),
        };
        if let Some((out, motion)) = split {
            return Ok((out.finished()?, Some(motion)));
        }
        guard::check()?;
        // not split (orders beyond the kernel's, slow poles) or the simulation overflowed:
        // the one-thread pass (which reports the overflow)
    }
    // forward: the model's own simulation; backward: its case flags f1 (on L), f2 (on R)
    // recomputed sample by sample as `CascadeModel::simulate_internals` has them
    let x = match start {
        None => linear.simulate(u, &linear.rest_state())?,
        Some(st) => simulate_from(linear, u, &st.state.x0)?,
    };
    let y0 = start.map_or(0.0, |st| st.state.y_prev);
    let y_sim = backlash.simulate(&x, y0)?;
    let reverse = Reverse {
        linear,
        backlash,
        u,
        y,
        x: &x,
        y_sim: &y_sim,
        warmup,
        start,
    };
    let out = match backlash.padded_step() {
        Some(padded) => reverse.run(|xt, yp| padded.switching(xt, yp)),
        None => reverse.run(|xt, yp| switching(backlash, xt, yp)),
    };
    Ok((out.finished()?, None))
}

/// The share of the record whose reverse pass the second thread takes: the first thread
/// simulates the whole record and runs the reverse pass of the rest (the simulation is
/// about 0.4 of a one-thread pass).
const SPLIT_SHARE: f64 = 0.62;

/// Chunk of the homogeneous responses between two tests of their decay.
const DECAY_CHUNK: usize = 512;

/// A homogeneous response below this is dropped: its contribution to g, against those of the
/// state at the split, is below this too (far below rounding).
const DECAYED: f64 = 1e-200;

/// The cascade's gradient pass on two threads, from rest. The reverse recursion is linear in
/// its state (lambda, nu(t + 1), .., nu(t + nb)): with M the split, the first thread
/// simulates the record and runs the reverse pass over t >= M; the second, as soon as the
/// simulation has passed M, runs it over t < M from a zero state (a particular solution)
/// and from each unit state (1 + nb homogeneous responses, followed until they decay:
/// lambda dies at the first move, nu as the poles of 1/B). g is the sum of the two parts and
/// of the homogeneous responses weighted by the first thread's state at M. None if the
/// orders are beyond the fixed-size kernel's, the poles are too slow for the responses to
/// decay early, or the simulation overflowed. With g, the `Motion` over t >= warmup, from
/// the forward pass's x and cases (each block's while in cache).
fn split_gradient(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
    step: impl Step + Send + Sync,
) -> Option<(OeGradient, Motion)> {
    let (len, nb) = (u.len(), linear.nb());
    let n = backlash.left().coefficients().len();
    if linear.na() > FIXED || nb > FIXED || !(1..=FIXED).contains(&n) || len < 4 * FIXED {
        return None;
    }
    let m = ((len as f64 * SPLIT_SHARE) as usize).clamp(2 * FIXED, len - FIXED);
    // the responses of nu decay as rho^t: followed over at most a tenth of the head
    let rho = linear.spectral_radius();
    if rho.is_nan() || rho >= 1.0 || (rho > 0.0 && DECAYED.ln() / rho.ln() > m as f64 / 10.0) {
        return None;
    }
    // the forward pass in blocks: x, then y and the case of each sample (f1 + 2 f2) from
    // the step itself, so that the reverse pass reads the case instead of recomputing it
    let mut rec = linear.with_recursion(&linear.rest_state(), Boxed);
    // `offset`: the record's index of u[0], for the motion's samples t >= warmup
    let forward = |rec: &mut Box<dyn BlockRecursion>,
                   u: &[f64],
                   x: &mut [f64],
                   y: &mut [f64],
                   case: &mut [u8],
                   y0: f64,
                   offset: usize,
                   motion: &mut Motion| {
        let mut finite = true;
        let mut y_prev = y0;
        for (k, uk) in u.chunks(FORWARD_BLOCK).enumerate() {
            // interrupted: give up (the caller checks again and returns the interruption)
            if k % (guard::CHUNK / FORWARD_BLOCK) == 0 && guard::interrupted() {
                return false;
            }
            let at = k * FORWARD_BLOCK;
            let xs = &mut x[at..at + uk.len()];
            rec.run_block(uk, xs);
            let cs = &mut case[at..at + uk.len()];
            for ((xt, yt), ct) in xs.iter().zip(&mut y[at..at + uk.len()]).zip(cs.iter_mut()) {
                let (v, c) = step.step_case(*xt, y_prev);
                (*yt, *ct, y_prev) = (v, c, v);
                finite &= xt.is_finite() & v.is_finite();
            }
            let from = warmup.saturating_sub(offset + at).min(uk.len());
            motion.add(&xs[from..], &cs[from..]);
        }
        finite
    };
    let mut motion = Motion::empty();
    // not allocated: the one-thread pass (which reports the memory it cannot have)
    let (mut x_head, mut y_head, mut case_head) = (
        scratch(&SPARE_F64, m, 0.0, "x").ok()?,
        scratch(&SPARE_F64, m, 0.0, "y").ok()?,
        scratch(&SPARE_U8, m, 0u8, "the cases").ok()?,
    );
    if !forward(
        &mut rec,
        &u[..m],
        &mut x_head,
        &mut y_head,
        &mut case_head,
        0.0,
        0,
        &mut motion,
    ) {
        return None;
    }
    let cols = cascade_cols(linear, backlash);
    let head = Reverse {
        linear,
        backlash,
        u: &u[..m],
        y: &y[..m],
        x: &x_head,
        y_sim: &y_head,
        warmup,
        start: None,
    };
    let rest = len - m + FIXED;
    let (mut x_tail, mut y_tail, mut case_tail) = (
        scratch(&SPARE_F64, rest, 0.0, "x").ok()?,
        scratch(&SPARE_F64, rest, 0.0, "y").ok()?,
        scratch(&SPARE_U8, rest, 0u8, "the cases").ok()?,
    );
    let flags_head = |t: usize| decode(case_head[t]);
    let out = std::thread::scope(|scope| {
        let second = scope.spawn(|| {
            let flags = flags_head;
            let horner = |xt: f64, yp: f64| decode(step.step_case(xt, yp).1);
            // the particular solution over t < M, then the homogeneous ones
            let mut g = vec![0.0; cols];
            let mut state = ReverseState::zero();
            head.kernel_any(flags, FIXED, m, &mut g, &mut state, true);
            head.general(horner, FIXED, &mut g, &mut state, true);
            let units: Vec<Vec<f64>> = (0..=nb)
                .map(|k| {
                    let mut unit = ReverseState::zero();
                    if k == 0 {
                        (unit.lambda, unit.next_holds) = (1.0, 1.0);
                    } else {
                        unit.nu_lags[k - 1] = 1.0;
                    }
                    head.homogeneous(flags, horner, m, unit, cols)
                })
                .collect();
            (g, state.cost, units)
        });
        // the first thread: the rest of the simulation, then the reverse pass over t >= M on
        // the record from M - FIXED (the kernel's lags)
        x_tail[..FIXED].copy_from_slice(&x_head[m - FIXED..]);
        y_tail[..FIXED].copy_from_slice(&y_head[m - FIXED..]);
        case_tail[..FIXED].copy_from_slice(&case_head[m - FIXED..]);
        let finite = forward(
            &mut rec,
            &u[m..],
            &mut x_tail[FIXED..],
            &mut y_tail[FIXED..],
            &mut case_tail[FIXED..],
            y_head[m - 1],
            m,
            &mut motion,
        );
        let tail_out = finite.then(|| {
            let tail = Reverse {
                linear,
                backlash,
                u: &u[m - FIXED..],
                y: &y[m - FIXED..],
                x: &x_tail,
                y_sim: &y_tail,
                warmup: warmup.saturating_sub(m - FIXED),
                start: None,
            };
            let mut g = vec![0.0; cols];
            let mut state = ReverseState::zero();
            tail.kernel_any(
                |t: usize| decode(case_tail[t]),
                FIXED,
                rest,
                &mut g,
                &mut state,
                true,
            );
            (g, state)
        });
        let (g_head, cost_head, units) = second.join().expect("the gradient's second thread");
        let (g_tail, at_m) = tail_out?;
        // the state at M: lambda(M) times "M holds", then nu(M), .., nu(M + nb - 1)
        let weights: Vec<f64> = std::iter::once(at_m.next_holds * at_m.lambda)
            .chain(at_m.nu_lags[..nb].iter().copied())
            .collect();
        let mut out = OeGradient::new(cols);
        for j in 0..cols {
            let mut v = g_tail[j] + g_head[j];
            for (w, unit) in weights.iter().zip(&units) {
                v += w * unit[j];
            }
            out.gradient[j] = v;
        }
        out.cost = at_m.cost + cost_head;
        Some((out, motion))
    });
    for v in [x_head, y_head, x_tail, y_tail] {
        keep_scratch(&SPARE_F64, v);
    }
    for v in [case_head, case_tail] {
        keep_scratch(&SPARE_U8, v);
    }
    out
}

/// Samples up to which `split_gradient` keeps its forward pass's buffers for the next call on
/// this thread (at most `SPARE_SCRATCH` of each kind: a head and a tail of x and y, of the
/// cases): fresh ones come from the OS page by page. Example 1 at N = 1e6 (2026-11-24, this
/// 2-core machine, quiet): one gradient pass 27-33 ms with fresh pages, 19-23 ms reused.
const SCRATCH_SAMPLES: usize = 1 << 21;
const SPARE_SCRATCH: usize = 4;

type Spares<T> = std::thread::LocalKey<std::cell::RefCell<Vec<Vec<T>>>>;

thread_local! {
    static SPARE_F64: std::cell::RefCell<Vec<Vec<f64>>> = const { std::cell::RefCell::new(Vec::new()) };
    static SPARE_U8: std::cell::RefCell<Vec<Vec<u8>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// `guard::filled(n, value, what)`, in the smallest kept buffer that holds n values if any
/// (its values left as they were, `value` beyond them: the forward pass writes every one).
fn scratch<T: Copy>(spares: &'static Spares<T>, n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let kept = spares.with(|s| {
        let mut s = s.borrow_mut();
        let best = (0..s.len())
            .filter(|&i| s[i].capacity() >= n)
            .min_by_key(|&i| s[i].capacity())?;
        Some(s.swap_remove(best))
    });
    match kept {
        Some(mut v) => {
            v.truncate(n);
            v.resize(n, value);
            Ok(v)
        }
        None => guard::filled(n, value, what),
    }
}

/// Keep a forward-pass buffer for the next `scratch` on this thread.
fn keep_scratch<T>(spares: &'static Spares<T>, v: Vec<T>) {
    if v.capacity() <= SCRATCH_SAMPLES {
        spares.with(|s| {
            let mut s = s.borrow_mut();
            if s.len() < SPARE_SCRATCH {
                s.push(v);
            }
        });
    }
}

/// Samples of x made per block before their backlash steps (`split_gradient`).
const FORWARD_BLOCK: usize = 4096;

/// (f1, f2) from f1 + 2 f2.
#[inline(always)]
fn decode(case: u8) -> (bool, bool) {
    (case & 1 != 0, case & 2 != 0)
}

/// The backward pass of `cascade_oe_gradient` over a simulated record.
struct Reverse<'a> {
    linear: &'a LinearBlock,
    backlash: &'a GeneralBacklash,
    u: &'a [f64],
    y: &'a [f64],
    x: &'a [f64],
    y_sim: &'a [f64],
    warmup: usize,
    start: Option<&'a Start<'a>>,
}

/// Lags, branch degree and linear orders up to which `Reverse` runs its fixed-size kernel
/// (`Reverse::kernel`): accumulators and lags in registers, fully unrolled, where the general
/// loop keeps them in memory.
const FIXED: usize = 4;

/// The state of the reverse recursion at a sample t: lambda(t), whether t holds, nu(t),
/// nu(t + 1), .. (FIXED of them; the first nb used) and the cost of the samples >= t.
#[derive(Debug, Clone, Copy)]
struct ReverseState {
    lambda: f64,
    next_holds: f64,
    nu_lags: [f64; FIXED],
    cost: f64,
}

impl ReverseState {
    fn zero() -> Self {
        Self {
            lambda: 0.0,
            next_holds: 0.0,
            nu_lags: [0.0; FIXED],
            cost: 0.0,
        }
    }
}

impl Reverse<'_> {
    fn run(&self, flags: impl Fn(f64, f64) -> (bool, bool) + Copy) -> OeGradient {
        let mut out =
            OeGradient::new(cascade_cols(self.linear, self.backlash) + start_cols(self.start));
        let mut state = ReverseState::zero();
        // the samples t >= FIXED by the kernel (every lag inside the record, x0 columns
        // behind), then the first FIXED by the general loop: the same operations in the same
        // order as the general loop throughout, the same bits
        let len = self.u.len();
        let (x, y_sim) = (self.x, self.y_sim);
        let at = |t: usize| flags(x[t], y_sim[t - 1]); // t >= FIXED > 0
        let end = if len > FIXED
            && self.kernel_any(at, FIXED, len, &mut out.gradient, &mut state, true)
        {
            FIXED
        } else {
            len
        };
        self.general(flags, end, &mut out.gradient, &mut state, true);
        out.cost = state.cost;
        out
    }

    /// `kernel` for this backlash's degree over lo <= t < hi: false (nothing done) if the
    /// orders are beyond it.
    fn kernel_any(
        &self,
        flags: impl Fn(usize) -> (bool, bool),
        lo: usize,
        hi: usize,
        g: &mut [f64],
        state: &mut ReverseState,
        residuals: bool,
    ) -> bool {
        if self.linear.na() > FIXED || self.linear.nb() > FIXED || lo < FIXED {
            return false;
        }
        match self.backlash.left().coefficients().len() {
            1 => self.kernel::<1, 2>(flags, lo, hi, g, state, residuals),
            2 => self.kernel::<2, 3>(flags, lo, hi, g, state, residuals),
            3 => self.kernel::<3, 4>(flags, lo, hi, g, state, residuals),
            4 => self.kernel::<4, 5>(flags, lo, hi, g, state, residuals),
            _ => return false,
        }
        true
    }

    /// The reverse recursion over t = hi - 1 down to lo >= FIXED from `state` for branch
    /// degree N (NR = N + 1 columns of R), na, nb <= FIXED: the lags padded with zero
    /// coefficients (subtracting a zero product leaves every sum as it was). Adds into `g`
    /// (the model's columns) and leaves the state at lo. Without `residuals`, r = 0 (a
    /// homogeneous response).
    #[allow(clippy::too_many_arguments)]
    fn kernel<const N: usize, const NR: usize>(
        &self,
        flags: impl Fn(usize) -> (bool, bool),
        lo: usize,
        hi: usize,
        g: &mut [f64],
        state: &mut ReverseState,
        residuals: bool,
    ) {
        let (u, y, x, y_sim) = (self.u, self.y, self.x, self.y_sim);
        let (a_len, nb) = (self.linear.na(), self.linear.nb());
        let bl = self.backlash;
        let mut m_l = [0.0; N];
        let mut m_r = [0.0; N];
        m_l.copy_from_slice(bl.left().coefficients());
        m_r.copy_from_slice(bl.right().coefficients());
        let mut b = [0.0; FIXED];
        b[..nb].copy_from_slice(self.linear.b());
        let (c_left, c_right) = (bl.c_left(), bl.c_right());
        let warmup = if residuals { self.warmup } else { usize::MAX };
        // accumulators: a, b, [c_L, m_L2..m_LN], [m_R1, c_R, m_R2..m_RN]
        let (mut ga, mut gb) = ([0.0; FIXED], [0.0; FIXED]);
        let (mut gl, mut gr) = ([0.0; N], [0.0; NR]);
        let ReverseState {
            mut lambda,
            mut next_holds,
            mut nu_lags,
            mut cost,
        } = *state;
        for t in (lo..hi).rev() {
            let (f1, f2) = flags(t);
            let r = if t >= warmup { y[t] - y_sim[t] } else { 0.0 };
            let (wl, wr) = (f64::from(u8::from(f1)), f64::from(u8::from(f2)));
            lambda = r + next_holds * lambda;
            let (lam_l, lam_r) = (wl * lambda, wr * lambda);
            let (xi_l, xi_r) = (x[t] + c_left, x[t] - c_right);
            let (mut p_l, mut p_r, mut slope_l, mut slope_r) = (1.0, 1.0, 0.0, 0.0);
            for i in 1..=N {
                let k = i as f64;
                slope_l += k * m_l[i - 1] * p_l;
                slope_r += k * m_r[i - 1] * p_r;
                p_l *= xi_l;
                p_r *= xi_r;
                if i >= 2 {
                    gl[i - 1] += lam_l * p_l;
                    gr[i] += lam_r * p_r;
                }
            }
            let (mu_l, mu_r) = (lam_l * slope_l, lam_r * slope_r);
            gl[0] += mu_l;
            gr[0] += lam_r * xi_r;
            gr[1] -= mu_r;
            next_holds = 1.0 - wl - wr;
            let mut nu = mu_l + mu_r;
            for k in 0..FIXED {
                nu -= b[k] * nu_lags[k];
            }
            for k in (1..FIXED).rev() {
                nu_lags[k] = nu_lags[k - 1];
            }
            nu_lags[0] = nu;
            let (us, xs) = (&u[t - FIXED..t], &x[t - FIXED..t]);
            for i in 0..FIXED {
                ga[i] += nu * us[FIXED - 1 - i];
                gb[i] -= nu * xs[FIXED - 1 - i];
            }
            cost += r * r;
        }
        let (c_l, m_r1) = (a_len + nb, a_len + nb + N);
        let parts = [
            (0, &ga[..a_len]),
            (a_len, &gb[..nb]),
            (c_l, &gl[..]),
            (m_r1, &gr[..]),
        ];
        for (from, acc) in parts {
            for (gi, v) in g[from..from + acc.len()].iter_mut().zip(acc) {
                *gi += v; // 0 + v = v: the kernel over the whole record leaves g as the loop does
            }
        }
        *state = ReverseState {
            lambda,
            next_holds,
            nu_lags,
            cost,
        };
    }

    /// A homogeneous response (r = 0) of the reverse recursion from `unit` at t = hi over
    /// t < hi, followed in chunks until it decays (lambda 0 and every lag of nu below
    /// DECAYED) or the record starts: its contribution to g (the model's `cols` columns).
    fn homogeneous(
        &self,
        flags: impl Fn(usize) -> (bool, bool) + Copy,
        horner: impl Fn(f64, f64) -> (bool, bool),
        hi: usize,
        unit: ReverseState,
        cols: usize,
    ) -> Vec<f64> {
        let mut g = vec![0.0; cols];
        let mut state = unit;
        let mut t = hi;
        while t > FIXED {
            let lo = t.saturating_sub(DECAY_CHUNK).max(FIXED);
            self.kernel_any(flags, lo, t, &mut g, &mut state, false);
            t = lo;
            if state.lambda == 0.0 && state.nu_lags.iter().all(|v| v.abs() < DECAYED) {
                return g;
            }
        }
        self.general(horner, t, &mut g, &mut state, false);
        g
    }

    /// The reverse recursion over t = end - 1 down to 0 from `state`, any orders (without
    /// `residuals`, r = 0).
    fn general(
        &self,
        flags: impl Fn(f64, f64) -> (bool, bool),
        end: usize,
        g: &mut [f64],
        state: &mut ReverseState,
        residuals: bool,
    ) {
        let (u, y, x, y_sim) = (self.u, self.y, self.x, self.y_sim);
        let (a_len, b) = (self.linear.na(), self.linear.b());
        let bl = self.backlash;
        let (m_left, m_right) = (bl.left().coefficients(), bl.right().coefficients());
        let n = m_left.len();
        // columns: a, b, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn
        let (c_l, m_r1) = (a_len + b.len(), a_len + b.len() + n);
        let (c_left, c_right) = (bl.c_left(), bl.c_right());
        let model = cascade_cols(self.linear, bl);
        let (nx, y0) = self.start.map_or((0, 0.0), |st| (st.nx(), st.state.y_prev));
        let warmup = if residuals { self.warmup } else { usize::MAX };
        let mut cost = state.cost;
        let mut lambda = state.lambda; // lambda(t + 1)
        let mut next_holds = state.next_holds; // 1 when t + 1 holds (0 past the record's end)
                                               // nu(t + 1), nu(t + 2), .. (the kernel's state holds the first FIXED)
        let mut nu_lags: Vec<f64> = (0..b.len())
            .map(|k| state.nu_lags.get(k).copied().unwrap_or(0.0))
            .collect();
        for t in (0..end).rev() {
            let y_prev = if t > 0 { y_sim[t - 1] } else { y0 };
            let (f1, f2) = flags(x[t], y_prev);
            let r = if t >= warmup { y[t] - y_sim[t] } else { 0.0 };
            // both branches' terms, weighted by 0 or 1: straight-line code, no case to mispredict
            let (wl, wr) = (f64::from(u8::from(f1)), f64::from(u8::from(f2)));
            lambda = r + next_holds * lambda;
            let (lam_l, lam_r) = (wl * lambda, wr * lambda);
            let (xi_l, xi_r) = (x[t] + c_left, x[t] - c_right);
            // L'(xi) = sum_i i m_i xi^(i-1) beside the powers xi^i (p_l, p_r)
            let (mut p_l, mut p_r, mut slope_l, mut slope_r) = (1.0, 1.0, 0.0, 0.0);
            for i in 1..=n {
                let k = i as f64;
                slope_l += k * m_left[i - 1] * p_l;
                slope_r += k * m_right[i - 1] * p_r;
                p_l *= xi_l;
                p_r *= xi_r;
                if i >= 2 {
                    g[c_l + i - 1] += lam_l * p_l;
                    g[m_r1 + i] += lam_r * p_r;
                }
            }
            let (mu_l, mu_r) = (lam_l * slope_l, lam_r * slope_r);
            g[c_l] += mu_l;
            g[m_r1] += lam_r * xi_r;
            g[m_r1 + 1] -= mu_r;
            next_holds = 1.0 - wl - wr;
            // nu(t) = mu(t) - sum_k b_k nu(t + k): the transpose of the causal 1/B
            let mut nu = mu_l + mu_r;
            for (bk, v) in b.iter().zip(&nu_lags) {
                nu -= bk * v;
            }
            if !nu_lags.is_empty() {
                nu_lags.rotate_right(1);
                nu_lags[0] = nu;
            }
            for i in 1..=a_len.min(t) {
                g[i - 1] += nu * u[t - i];
            }
            if t < nx {
                g[model + t] += nu; // x0 enters x(t) as a_i u(t - i) does
            }
            for j in 1..=b.len().min(t) {
                g[a_len + j - 1] -= nu * x[t - j];
            }
            cost += r * r; // r = 0 before the warm-up ends
        }
        if nx > 0 {
            // dy/dy_prev is 1 over the first run of holds: the residuals lambda(0) collects
            g[model + nx] = next_holds * lambda;
        }
        *state = ReverseState {
            lambda,
            next_holds,
            nu_lags: state.nu_lags,
            cost,
        };
    }
}

/// `OeGradient` of the sandwich: the forward rows dw(t) times the residuals.
pub fn sandwich_oe_gradient(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
    w: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    check_pair(u, w, "w")?;
    sandwich_oe_gradient_from(input_linear, backlash, output_linear, None, u, w, warmup)
}

/// `sandwich_oe_gradient` of a record checked before (`Problem`) from an initial state (its columns after the model's),
/// or from rest (None).
pub(crate) fn sandwich_oe_gradient_from(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    start: Option<&Start>,
    u: &[f64],
    w: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    let cols = sandwich_cols(input_linear, backlash, output_linear) + start_cols(start);
    let mut out = OeGradient::new(cols);
    walk_sandwich(
        input_linear,
        backlash,
        output_linear,
        start,
        u,
        |t, wt, row| {
            if t >= warmup {
                let r = w[t] - wt;
                for (gi, v) in out.gradient.iter_mut().zip(row) {
                    *gi += r * v;
                }
                out.cost += r * r;
            }
            Ok(())
        },
    )?;
    out.finished()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::sensitivity::tests::check_bad_records;
    use crate::identify::sensitivity::{cascade_sensitivity, sandwich_sensitivity, Sensitivity};
    use crate::model::backlash::GeneralBacklash;
    use crate::test_params::{
        example1, noisy, perturbed, sandwich_from, smooth_input as input, EXAMPLE2_THETA,
    };
    use crate::CascadeModel;

    /// J^T r and the cost from the dense sensitivity written out.
    fn check_gradient(g: &OeGradient, sens: &Sensitivity, measured: &[f64], warmup: usize) {
        let p = sens.cols;
        let ts = warmup.min(measured.len())..measured.len();
        let r = |t: usize| measured[t] - sens.output[t];
        assert_eq!(g.gradient.len(), p);
        for j in 0..p {
            let want: f64 = ts.clone().map(|t| sens.jacobian[t * p + j] * r(t)).sum();
            let size: f64 = ts
                .clone()
                .map(|t| (sens.jacobian[t * p + j] * r(t)).abs())
                .sum();
            assert!(
                (g.gradient[j] - want).abs() <= 1e-12 * size.max(1e-300),
                "column {j}: {} against {want}",
                g.gradient[j]
            );
        }
        let cost: f64 = ts.clone().map(|t| r(t).powi(2)).sum();
        assert!((g.cost - cost).abs() <= 1e-12 * cost, "{} {cost}", g.cost);
    }

    fn moves(model: &CascadeModel, u: &[f64]) -> Vec<bool> {
        let sim = model.simulate_internals(u, &model.rest_state()).unwrap();
        sim.f1.iter().zip(&sim.f2).map(|(a, b)| *a || *b).collect()
    }

    #[test]
    fn cascade_gradient_is_the_dense_jacobian_times_the_residual() {
        let (lin, bl) = example1();
        let u = input(3000);
        let m = CascadeModel::new(lin.clone(), bl.clone());
        let y = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 3);
        // orders other than Example 1's too: FIR, longer denominators, degree 1 and 4
        let estimates = [
            (
                vec![0.65, 0.55],
                vec![-0.15, 0.3],
                vec![1.0, -0.25, 0.28],
                vec![1.45, 0.35, 0.25],
            ),
            (vec![0.6], vec![], vec![1.0], vec![1.3]),
            (
                vec![0.5, 0.3, 0.1],
                vec![-0.4, 0.2, 0.05],
                vec![1.0, 0.1, 0.2, 0.05],
                vec![1.2, 0.3, 0.1, 0.02],
            ),
        ];
        for (a, b, ml, mr) in estimates {
            let est_lin = LinearBlock::new(a, b).unwrap();
            let est = GeneralBacklash::from_estimate(0.55, 0.45, ml, mr).unwrap();
            let sens = cascade_sensitivity(&est_lin, &est, &u).unwrap();
            let mv = moves(&CascadeModel::new(est_lin.clone(), est.clone()), &u);
            assert!(
                mv.iter().any(|m| !m) && mv.iter().any(|m| *m),
                "holds and moves both"
            );
            for warmup in [0, 1, 600, 2999, 3000, 5000] {
                let g = cascade_oe_gradient(&est_lin, &est, &u, &y, warmup).unwrap();
                check_gradient(&g, &sens, &y, warmup);
            }
        }
    }

    #[test]
    fn two_threads_agree_with_one() {
        // the split pass (particular + homogeneous responses) against the one-thread pass, to
        // rounding: Example 1 and other orders, warm-ups before, at and after the split
        let (lin, bl) = example1();
        let n = 40_000;
        let u = input(n);
        let m = CascadeModel::new(lin.clone(), bl.clone());
        let y = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 3);
        let estimates = [
            (
                vec![0.7, 0.5],
                vec![-0.2, 0.35],
                vec![1.0, -0.3, 0.3],
                vec![1.5, 0.4, 0.2],
            ),
            (
                vec![0.65, 0.55],
                vec![-0.15, 0.3],
                vec![1.0, -0.25, 0.28],
                vec![1.45, 0.35, 0.25],
            ),
            (vec![0.6], vec![], vec![1.0], vec![1.3]),
            (
                vec![0.5, 0.3, 0.1],
                vec![-0.4, 0.2, 0.05],
                vec![1.0, 0.1, 0.2, 0.05],
                vec![1.2, 0.3, 0.1, 0.02],
            ),
            (
                vec![0.5, 0.3, 0.1, 0.1],
                vec![-0.5, 0.1, 0.05, 0.01],
                vec![1.0, 0.1],
                vec![1.2, 0.3],
            ),
        ];
        let mut split = 0;
        for (a, b, ml, mr) in estimates {
            let est_lin = LinearBlock::new(a, b).unwrap();
            let est = GeneralBacklash::from_estimate(0.55, 0.45, ml, mr).unwrap();
            for warmup in [0, 7, 10_000, 24_800, 30_000, n] {
                let one = cascade_oe_gradient_threads(&est_lin, &est, &u, &y, warmup, 1).unwrap();
                let two = cascade_oe_gradient_threads(&est_lin, &est, &u, &y, warmup, 2).unwrap();
                let sens = cascade_sensitivity(&est_lin, &est, &u).unwrap();
                check_gradient(&two, &sens, &y, warmup);
                let p = one.gradient.len();
                for j in 0..p {
                    let size: f64 = (warmup.min(n)..n)
                        .map(|t| (sens.jacobian[t * p + j] * (y[t] - sens.output[t])).abs())
                        .sum();
                    assert!((one.gradient[j] - two.gradient[j]).abs() <= 1e-13 * size.max(1e-300));
                }
                assert!((one.cost - two.cost).abs() <= 1e-13 * one.cost.max(1e-300));
                let fixed = FIXED;
                let plain = est_lin.na() <= fixed && est_lin.nb() <= fixed;
                split += usize::from(plain && one != two);
            }
        }
        assert!(
            split > 0,
            "the split pass ran (differs from the one-thread pass in rounding)"
        );
    }

    #[test]
    fn sandwich_gradient_is_the_dense_jacobian_times_the_residual() {
        let u = input(3000);
        let (l2, b2, o2) = sandwich_from(&EXAMPLE2_THETA);
        let w = noisy(&sandwich_sensitivity(&l2, &b2, &o2, &u).unwrap().output, 5);
        let (l3, b3, o3) = sandwich_from(&perturbed(EXAMPLE2_THETA));
        let sens = sandwich_sensitivity(&l3, &b3, &o3, &u).unwrap();
        for warmup in [0, 2, 700] {
            let g = sandwich_oe_gradient(&l3, &b3, &o3, &u, &w, warmup).unwrap();
            check_gradient(&g, &sens, &w, warmup);
        }
    }

    #[test]
    fn gradients_report_overflow_and_bad_data() {
        check_bad_records(
            |lin, bl, u, y| cascade_oe_gradient(lin, bl, u, y, 0),
            |lin, bl, out, u, w| sandwich_oe_gradient(lin, bl, out, u, w, 0),
        );
    }
}
