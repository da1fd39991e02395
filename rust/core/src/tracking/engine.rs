#![allow(clippy::needless_range_loop)] // p x p algebra on fixed arrays reads as the formulas: P[i][j]
//! The recursive estimator with fixed-size state: `Engine<W>` holds theta, P and the lags in
//! arrays of W values (W >= p; the padding stays zero and changes nothing), so an update
//! allocates nothing and the compiler unrolls the p x p loops for the common orders.

use super::detector::{Alarm, Detector, DETECTOR_SAVED};
use super::monitor::{monitor_saved, Monitor, Window};
use super::{shift_in, Method, Options, Orders};
use crate::error::{Error, Result};

/// theta's positions (`identify::problem::Layout`, without feedthroughs): a, b, c_L,
/// m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn, then for the sandwich r_2..r_nr, s_1..s_ns (r_1 = 1).
impl Orders {
    pub(crate) fn p(&self) -> usize {
        self.r() + self.nr.saturating_sub(1) + self.ns
    }
    pub(crate) fn sandwich(&self) -> bool {
        self.nr > 0
    }
    fn c_l(&self) -> usize {
        self.na + self.nb
    }
    fn m_r1(&self) -> usize {
        self.na + self.nb + self.degree
    }
    fn c_r(&self) -> usize {
        self.m_r1() + 1
    }
    /// r_2's position (after m_Rn).
    fn r(&self) -> usize {
        self.c_r() + self.degree
    }
    /// s_1's position.
    fn s(&self) -> usize {
        self.r() + self.nr.saturating_sub(1)
    }
}

/// Lags of the sandwich's output block a tracker keeps: nr, ns <= `MAX_OUTPUT_ORDER` (one
/// more y lag for the held target of eq 34).
pub const MAX_OUTPUT_ORDER: usize = 7;
const OUT_LAGS: usize = MAX_OUTPUT_ORDER + 1;

/// Where a sample's output goes: the trajectory (theta and standard errors of recorded
/// samples, p values each) and the alarms.
pub struct Sink<'a> {
    pub theta: &'a mut [f64],
    pub se: &'a mut [f64],
    /// Record every `every`-th sample (sample t recorded when (t + 1) % every == 0, counted
    /// over the tracker's life).
    pub every: u64,
    pub alarms: &'a mut Vec<Alarm>,
    /// The mismatch monitor's windows.
    pub windows: &'a mut Vec<Window>,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Engine<const W: usize> {
    dims: Orders,
    method: Method,
    lambda: f64,
    /// 1 / lambda and its square root.
    inv_lambda: f64,
    sqrt_inv_lambda: f64,
    /// Whether Q has a nonzero drift.
    has_drift: bool,
    /// Per-sample drift variances in the working parametrisation (Kalman random walk).
    q: [f64; W],
    noise_memory: f64,
    /// The working parameters: the physical layout for `PredictionError`; eq (19)'s
    /// regression parameters for `Regression` (c_R's slot holds c_2 = m_R1 c_R, eq 20).
    theta: [f64; W],
    /// A square root S of P, P = S S' normalised by the noise variance: Cov(theta) =
    /// sigma2 * P (times `s2 / s1` with forgetting). Potter's square-root update keeps P
    /// positive semi-definite by construction; the plain update P - g g' / s lost it after
    /// about 3e4 samples of Example 1 with lambda = 0.999 (a negative variance, then
    /// divergence), in both methods.
    sm: [[f64; W]; W],
    /// Samples of drift (Q) not yet added to P: Q is added every `DRIFT_BATCH` samples as
    /// h Q (P + h Q re-factored), the random walk's variance over those h samples.
    q_wait: f64,
    /// trace(P) after the last update or fold (`TRACE_CAP`).
    trace: f64,
    sigma2: f64,
    noise_count: f64,
    /// sum lambda^k and sum lambda^2k over the updates (forgetting's covariance factor).
    s1: f64,
    s2: f64,
    /// u(t-1), u(t-2), ..; x(t-1), ..; 1/B-filtered u and x lags (prediction error).
    u_lag: [f64; W],
    x_lag: [f64; W],
    wu: [f64; W],
    wx: [f64; W],
    /// d y_hat / d theta carried over holds (prediction error).
    psi: [f64; W],
    /// The last update's row (psi or the regression's): the monitor's parameter directions.
    row: [f64; W],
    /// y_hat(t-1): the simulated backlash memory of the current estimate.
    y_hat: f64,
    /// The sandwich's output block (eq 29, r_1 = 1): y_hat(t-1), y_hat(t-2), .. the
    /// backlash's simulated output; w(t-1), .. (the simulated output for the prediction
    /// error, the measured one in the regression's row of eq 33); for the prediction error
    /// their sensitivities d y_hat / d theta, d w_hat / d theta at those lags.
    y_out: [f64; OUT_LAGS],
    w_out: [f64; OUT_LAGS],
    psi_y: [[f64; W]; OUT_LAGS],
    psi_w: [[f64; W]; OUT_LAGS],
    /// The regression: the input block's and backlash's part of eq (33)'s row at t - 1 (the
    /// cascade row of eq 18 one sample back) and whether the backlash moved then.
    phi_prev: [f64; W],
    moved_prev: bool,
    /// Held samples not yet folded into P (regression: their rows are zero).
    pending: f64,
    t: u64,
    rejected: u64,
    /// The innovation bound's square, in units of the noise variance, times the start's
    /// noise variance: e(t)^2 > bound2 (1 + psi' P psi) refuses the update and sends the
    /// estimate back to its checkpoint (`update`); infinite: off.
    bound2: f64,
    /// The estimate after the last `CHECKPOINT` consecutive accepted updates.
    checkpoint: Checkpoint<W>,
    /// Accepted updates since the checkpoint or the last refusal.
    since_ck: u64,
    /// Updates the innovation bound refused.
    refused: u64,
    detector: Option<Detector>,
    monitor: Option<Monitor>,
}

/// theta, S and trace(P) of a moment: the estimate the innovation bound returns to.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Checkpoint<const W: usize> {
    theta: [f64; W],
    sm: [[f64; W]; W],
    trace: f64,
}

/// Consecutive accepted updates after which the estimate becomes the checkpoint the
/// innovation bound returns to.
const CHECKPOINT: u64 = 1000;
/// The guard's numbers `save` appends after the monitor's: since_ck, refused, ck_trace, then
/// ck_theta (p) and ck_sm (p x p).
const GUARD_SAVED: usize = 3;

/// Horner: sum_{i>=1} m_i xi^i with m_1 = `m1` and m_2.. = `rest`.
#[inline(always)]
fn branch(m1: f64, rest: &[f64], xi: f64) -> f64 {
    let mut acc = 0.0;
    for m in rest.iter().rev() {
        acc = acc * xi + m;
    }
    (acc * xi + m1) * xi
}

/// d/dxi of `branch`.
#[inline(always)]
fn slope(m1: f64, rest: &[f64], xi: f64) -> f64 {
    let mut acc = 0.0;
    for (k, m) in rest.iter().enumerate().rev() {
        acc = acc * xi + (k + 2) as f64 * m;
    }
    acc * xi + m1
}

/// Whether 1 + b_1 z^-1 + .. + b_nb z^-nb has every root strictly inside the unit circle
/// (Schur-Cohn step-down: every reflection coefficient below 1 in magnitude).
#[inline]
pub(crate) fn stable<const W: usize>(b: &[f64]) -> bool {
    let nb = b.len();
    match nb {
        0 => true,
        1 => b[0].abs() < 1.0,
        2 => b[1].abs() < 1.0 && b[0].abs() < 1.0 + b[1],
        _ => {
            let mut a = [0.0; W];
            a[..nb].copy_from_slice(b);
            for m in (1..=nb).rev() {
                let k = a[m - 1];
                if k.abs() >= 1.0 || k.is_nan() {
                    return false;
                }
                let d = 1.0 - k * k;
                let mut next = [0.0; W];
                for i in 0..m - 1 {
                    next[i] = (a[i] - k * a[m - 2 - i]) / d;
                }
                a = next;
            }
            true
        }
    }
}

/// Samples between two additions of the drift's covariance (`Engine::sm`).
const DRIFT_BATCH: f64 = 16.0;

/// Anti-windup: forgetting inflates P by 1 / lambda per sample whatever the data say, so
/// without excitation (u = 0, or a long hold in the regression) P grows until it overflows.
/// Forgetting is suspended while trace(P) (normalised by the noise variance) would exceed
/// this.
const TRACE_CAP: f64 = 1e8;

/// Samples between two sums of trace(P) from S (a power of 2); in between the cap reads
/// the last sum (P grows at most lambda^-64 meanwhile: finite for lambda >= 1e-4, the
/// least allowed).
const TRACE_EVERY: u64 = 64;

/// The lower Cholesky factor of the p x p block of a symmetric positive semi-definite
/// matrix; a pivot <= 0 (a direction without variance) leaves its column zero.
fn cholesky<const W: usize>(a: &[[f64; W]; W], p: usize) -> [[f64; W]; W] {
    let mut l = [[0.0; W]; W];
    for j in 0..p {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if d.is_nan() || d <= 1e-300 {
            continue;
        }
        let d = d.sqrt();
        l[j][j] = d;
        for i in j + 1..p {
            let mut v = a[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v / d;
        }
    }
    l
}

/// P = S S'.
fn product<const W: usize>(s: &[[f64; W]; W], p: usize) -> [[f64; W]; W] {
    let mut a = [[0.0; W]; W];
    for i in 0..p {
        for j in 0..=i {
            let mut v = 0.0;
            for k in 0..W {
                v += s[i][k] * s[j][k];
            }
            a[i][j] = v;
            a[j][i] = v;
        }
    }
    a
}

impl<const W: usize> Engine<W> {
    /// From a physical theta0 and its absolute covariance `cov0` (p x p row-major), the noise
    /// variance `sigma2` (> 0) standing for `noise_count` samples.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        dims: Orders,
        options: &Options,
        theta0: &[f64],
        cov0: &[f64],
        sigma2: f64,
        noise_count: f64,
        detector: Option<Detector>,
        monitor: Option<Monitor>,
    ) -> Result<Self> {
        let p = dims.p();
        debug_assert!(p <= W);
        let mut theta = [0.0; W];
        theta[..p].copy_from_slice(theta0);
        // the working parametrisation's Jacobian (regression: c_2 = m_R1 c_R)
        let mut jac = [[0.0; W]; W];
        for (i, row) in jac.iter_mut().enumerate().take(p) {
            row[i] = 1.0;
        }
        let (m_r1, c_r) = (dims.m_r1(), dims.c_r());
        if options.method == Method::Regression {
            let (m, c) = (theta0[m_r1], theta0[c_r]);
            theta[c_r] = m * c;
            jac[c_r][c_r] = m;
            jac[c_r][m_r1] = c;
        }
        let mut pm = [[0.0; W]; W];
        for i in 0..p {
            for j in 0..p {
                let mut v = 0.0;
                for k in 0..p {
                    for l in 0..p {
                        v += jac[i][k] * cov0[k * p + l] * jac[j][l];
                    }
                }
                pm[i][j] = v / sigma2;
            }
        }
        let sm = cholesky(&pm, p);
        let trace = (0..p).map(|i| pm[i][i]).sum();
        let mut q = [0.0; W];
        for (i, d) in options.drift.iter().enumerate() {
            q[i] = d * d;
        }
        if options.method == Method::Regression && !options.drift.is_empty() {
            let (m, c) = (theta0[m_r1], theta0[c_r]);
            q[c_r] = m * m * q[c_r] + c * c * q[m_r1];
        }
        let noise_memory = if options.forgetting < 1.0 {
            options.noise_memory.min(1.0 / (1.0 - options.forgetting))
        } else {
            options.noise_memory
        };
        Ok(Self {
            dims,
            method: options.method,
            lambda: options.forgetting,
            inv_lambda: 1.0 / options.forgetting,
            sqrt_inv_lambda: (1.0 / options.forgetting).sqrt(),
            has_drift: q.iter().any(|v| *v > 0.0),
            q,
            noise_memory,
            theta,
            sm,
            q_wait: 0.0,
            trace,
            sigma2,
            noise_count,
            s1: 0.0,
            s2: 0.0,
            u_lag: [0.0; W],
            x_lag: [0.0; W],
            wu: [0.0; W],
            wx: [0.0; W],
            psi: [0.0; W],
            row: [0.0; W],
            y_hat: 0.0,
            y_out: [0.0; OUT_LAGS],
            w_out: [0.0; OUT_LAGS],
            psi_y: [[0.0; W]; OUT_LAGS],
            psi_w: [[0.0; W]; OUT_LAGS],
            phi_prev: [0.0; W],
            moved_prev: false,
            pending: 0.0,
            t: 0,
            rejected: 0,
            bound2: options.innovation_bound * options.innovation_bound * sigma2,
            checkpoint: Checkpoint { theta, sm, trace },
            since_ck: 0,
            refused: 0,
            detector,
            monitor,
        })
    }

    pub(crate) fn samples(&self) -> u64 {
        self.t
    }

    pub(crate) fn rejected(&self) -> u64 {
        self.rejected
    }

    pub(crate) fn refused(&self) -> u64 {
        self.refused
    }

    /// The estimate now, as a checkpoint.
    fn now(&self) -> Checkpoint<W> {
        Checkpoint {
            theta: self.theta,
            sm: self.sm,
            trace: self.trace,
        }
    }

    pub(crate) fn noise_variance(&self) -> f64 {
        self.sigma2
    }

    pub(crate) fn detector(&self) -> Option<&Detector> {
        self.detector.as_ref()
    }

    pub(crate) fn monitor(&self) -> Option<&Monitor> {
        self.monitor.as_ref()
    }

    /// The covariance factor of forgetting: with weights lambda^k the estimate's covariance
    /// is sigma2 (sum l^k phi phi')^-1 (sum l^2k phi phi') (sum l^k phi phi')^-1, about
    /// sigma2 P * s2 / s1 (1 / (1 + lambda) in the steady state, 1 without forgetting).
    #[inline(always)]
    fn scale(&self) -> f64 {
        if self.s1 > 0.0 && self.lambda < 1.0 {
            self.sigma2 * self.s2 / self.s1
        } else {
            self.sigma2
        }
    }

    /// The physical theta and its covariance (p x p row-major).
    pub(crate) fn estimate(&self) -> (Vec<f64>, Vec<f64>) {
        let p = self.dims.p();
        let scale = self.scale();
        let mut theta = self.theta[..p].to_vec();
        let pm = product(&self.sm, p);
        let mut cov: Vec<f64> = (0..p * p).map(|k| scale * pm[k / p][k % p]).collect();
        if self.method == Method::Regression {
            // c_R = c_2 / m_R1: its row and column by the delta method
            let (m_r1, c_r) = (self.dims.m_r1(), self.dims.c_r());
            let (m, c2) = (self.theta[m_r1], self.theta[c_r]);
            theta[c_r] = c2 / m;
            let (gc, gm) = (1.0 / m, -c2 / (m * m));
            let col: Vec<f64> = (0..p)
                .map(|k| gc * cov[k * p + c_r] + gm * cov[k * p + m_r1])
                .collect();
            let var = gc * col[c_r] + gm * col[m_r1];
            for k in 0..p {
                cov[k * p + c_r] = col[k];
                cov[c_r * p + k] = col[k];
            }
            cov[c_r * p + c_r] = var;
        }
        (theta, cov)
    }

    /// The dead-band width the detector watches and its variance: c_L + c_R for a cascade
    /// (the backlash's output is the record's, slope m_L1 = 1: a width in its units); for a
    /// sandwich referred to the input, (c_L + c_R) (1 + sum b) / sum a, the input block's
    /// static gain dividing (for the input backlash, na = 1, nb = 0: the play in the input's
    /// units, (c_L + c_R) / a_1). The sandwich's normalisation (m_L1 = r_1 = 1) leaves x's
    /// scale to the input block against the output block's gain, a direction a slow input
    /// hardly determines: along it a, c_L and c_R move together by 10 % on a constant plant
    /// while the width referred to the input stays within 1 % (docs/tracking.md). None of it
    /// changes for a cascade.
    #[inline]
    fn width(&self) -> (f64, f64) {
        let (c_l, m_r1, c_r) = (self.dims.c_l(), self.dims.m_r1(), self.dims.c_r());
        let mut g = [0.0; W];
        let w = match self.method {
            Method::PredictionError => {
                g[c_l] = 1.0;
                g[c_r] = 1.0;
                self.theta[c_l] + self.theta[c_r]
            }
            Method::Regression => {
                let (m, c2) = (self.theta[m_r1], self.theta[c_r]);
                g[c_l] = 1.0;
                g[c_r] = 1.0 / m;
                g[m_r1] = -c2 / (m * m);
                self.theta[c_l] + c2 / m
            }
        };
        let w = if self.dims.sandwich() {
            // w h with h = (1 + sum b) / sum a; d h / d a_i = -h / sum a, d h / d b_j = 1 / sum a
            let Orders { na, nb, .. } = self.dims;
            let sa: f64 = self.theta[..na].iter().sum();
            let den = 1.0 + self.theta[na..na + nb].iter().sum::<f64>();
            let h = den / sa;
            for v in &mut g {
                *v *= h;
            }
            for v in &mut g[..na] {
                *v = -w * h / sa;
            }
            for v in &mut g[na..na + nb] {
                *v = w / sa;
            }
            w * h
        } else {
            w
        };
        // g' S S' g = |S' g|^2
        let mut var = 0.0;
        for k in 0..W {
            let mut f = 0.0;
            for (i, gi) in g.iter().enumerate() {
                f += gi * self.sm[i][k];
            }
            var += f * f;
        }
        (w, self.scale() * var)
    }

    /// Write the physical estimate's theta and standard errors into `theta`, `se` (p each).
    #[inline]
    fn record(&self, theta: &mut [f64], se: &mut [f64]) {
        let p = self.dims.p();
        let scale = self.scale();
        for i in 0..p {
            theta[i] = self.theta[i];
            let mut v = 0.0;
            for k in 0..W {
                v += self.sm[i][k] * self.sm[i][k];
            }
            se[i] = (scale * v).sqrt();
        }
        if self.method == Method::Regression {
            let (m_r1, c_r) = (self.dims.m_r1(), self.dims.c_r());
            let (m, c2) = (self.theta[m_r1], self.theta[c_r]);
            let (gc, gm) = (1.0 / m, -c2 / (m * m));
            let mut var = 0.0;
            for k in 0..W {
                let f = gc * self.sm[c_r][k] + gm * self.sm[m_r1][k];
                var += f * f;
            }
            theta[c_r] = c2 / m;
            se[c_r] = (scale * var).sqrt();
        }
    }

    /// Track the samples (u[t], y[t]) in order; see `Sink`.
    pub(crate) fn run(&mut self, u: &[f64], y: &[f64], sink: &mut Sink) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above
            return unsafe { self.run_avx2(u, y, sink) };
        }
        self.run_plain(u, y, sink)
    }

    /// `run_plain` compiled with AVX2's wider vectors: the same operations in the same
    /// order (no fused multiply-add: Rust does not contract a * b + c), so the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2(&mut self, u: &[f64], y: &[f64], sink: &mut Sink) -> Result<()> {
        self.run_plain(u, y, sink)
    }

    #[inline(always)]
    fn run_plain(&mut self, u: &[f64], y: &[f64], sink: &mut Sink) -> Result<()> {
        let p = self.dims.p();
        let mut k = 0;
        // samples until the next recorded row and the next reading (countdowns: no division
        // per sample)
        let mut to_record = sink.every - self.t % sink.every;
        let spacing = self
            .detector
            .as_ref()
            .map_or(u64::MAX, |d| d.options.spacing);
        let mut to_reading = spacing - self.t % spacing;
        for (&ut, &yt) in u.iter().zip(y) {
            let innovation = match (self.method, self.dims.sandwich()) {
                (Method::PredictionError, false) => self.step_pe(ut, yt)?,
                (Method::Regression, false) => self.step_regression(ut, yt)?,
                (Method::PredictionError, true) => self.step_pe_sandwich(ut, yt)?,
                (Method::Regression, true) => self.step_regression_sandwich(ut, yt)?,
            };
            self.t += 1;
            to_record -= 1;
            if to_record == 0 {
                to_record = sink.every;
                self.record(
                    &mut sink.theta[k * p..(k + 1) * p],
                    &mut sink.se[k * p..(k + 1) * p],
                );
                k += 1;
            }
            if let (Some(m), Some((e, xt))) = (self.monitor.as_mut(), innovation) {
                if let Some(w) = m.observe(self.t - 1, e, ut, xt, &self.row[..p]) {
                    sink.windows.push(w);
                }
            }
            to_reading -= 1;
            if to_reading == 0 {
                to_reading = spacing;
                // no reading while the monitor says the structure is wrong: a wandering
                // estimate of a wrong structure is not wear
                if !self.monitor.as_ref().is_some_and(Monitor::mismatch) {
                    let (w, var) = self.width();
                    let sample = self.t - 1;
                    if let Some(alarm) = self
                        .detector
                        .as_mut()
                        .and_then(|d| d.observe(sample, w, var))
                    {
                        sink.alarms.push(alarm);
                    }
                }
            }
        }
        Ok(())
    }

    /// x(t) of eq (16) at the current a, b from the lags.
    #[inline(always)]
    fn internal(&self) -> f64 {
        let Orders { na, nb, .. } = self.dims;
        let mut x = 0.0;
        for i in 0..na {
            x += self.theta[i] * self.u_lag[i];
        }
        for j in 0..nb {
            x -= self.theta[na + j] * self.x_lag[j];
        }
        x
    }

    /// The branches' parameters: (c_L, m_L2..), (m_R1, c_R, m_R2..) as slices of theta.
    #[inline(always)]
    fn c_right(&self) -> f64 {
        let (m_r1, c_r) = (self.dims.m_r1(), self.dims.c_r());
        match self.method {
            Method::PredictionError => self.theta[c_r],
            Method::Regression => self.theta[c_r] / self.theta[m_r1],
        }
    }

    #[inline(always)]
    fn push_lags(&mut self, ut: f64, xt: f64) {
        let Orders { na, nb, .. } = self.dims;
        shift_in(&mut self.u_lag[..na], ut);
        if nb > 0 {
            shift_in(&mut self.x_lag[..nb], xt);
        }
    }

    /// One sample of the recursive prediction-error method: y_hat(t) of the current estimate
    /// and psi(t) = d y_hat(t) / d theta by the recursions of `identify::sensitivity`, then
    /// the update with e(t) = y(t) - y_hat(t). Every step returns the update's (e(t), x(t)),
    /// None for a held sample without one (the monitor's input).
    #[inline(always)]
    fn step_pe(&mut self, ut: f64, yt: f64) -> Result<Option<(f64, f64)>> {
        let xt = self.inner_pe(ut)?;
        let psi = self.psi;
        self.update_pe(&psi, yt - self.y_hat, xt)
    }

    /// The prediction-error rule's update (`update`, row `phi`), then the simulated backlash
    /// memory y_hat(t) carried over to the updated estimate to first order: y_hat += psi(t)'
    /// (theta(t) - theta(t-1)), psi the cascade part's d y_hat / d theta. A moving sample
    /// recomputes y_hat from the branch anyway; a held one keeps the value of its last
    /// contact, and without this the memory stays that of the estimate at the contact while psi (held too) says how it moves
    /// with theta: the updates then push along psi for a change the prediction never shows,
    /// and the estimate runs away along a direction the data barely determine (an input
    /// backlash under a slow input: a_1 and the widths to 0, r_2 up, within 30 samples of a
    /// hold; docs/tracking.md).
    #[inline(always)]
    fn update_pe(&mut self, phi: &[f64; W], e: f64, xt: f64) -> Result<Option<(f64, f64)>> {
        let (before, refused) = (self.theta, self.refused);
        let out = self.update(phi, e, xt)?;
        if self.refused != refused {
            // sent back to the checkpoint: too far for the first-order carry; the memory
            // meets the checkpoint's branches at the next contact
            return Ok(out);
        }
        let mut change = 0.0;
        for k in 0..W {
            change += self.psi[k] * (self.theta[k] - before[k]);
        }
        self.y_hat += change;
        Ok(out)
    }

    /// The sandwich's prediction-error sample: the cascade part's y_hat(t), psi_y(t)
    /// (`inner_pe`), then w_hat(t) = y_hat(t-1) + sum_i>=2 r_i y_hat(t-i) - sum_j s_j
    /// w_hat(t-j) (eq 29, r_1 = 1) and its sensitivities by the same recursion: d w_hat / d
    /// theta = sum_i r_i psi_y(t-i) - sum_j s_j psi_w(t-j), plus y_hat(t-i) in r_i's column
    /// and -w_hat(t-j) in s_j's; the update with e(t) = w(t) - w_hat(t).
    #[inline(always)]
    fn step_pe_sandwich(&mut self, ut: f64, wt: f64) -> Result<Option<(f64, f64)>> {
        let xt = self.inner_pe(ut)?;
        let Orders { nr, ns, .. } = self.dims;
        let (r0, s0) = (self.dims.r(), self.dims.s());
        let mut w = self.y_out[0];
        let mut psi = self.psi_y[0];
        for i in 1..nr {
            let (ri, yl) = (self.theta[r0 + i - 1], self.y_out[i]);
            w += ri * yl;
            for k in 0..W {
                psi[k] += ri * self.psi_y[i][k];
            }
            psi[r0 + i - 1] += yl;
        }
        for j in 0..ns {
            let (sj, wl) = (self.theta[s0 + j], self.w_out[j]);
            w -= sj * wl;
            for k in 0..W {
                psi[k] -= sj * self.psi_w[j][k];
            }
            psi[s0 + j] -= wl;
        }
        if !w.is_finite() {
            return Err(diverged(self.t));
        }
        shift_in(&mut self.y_out, self.y_hat);
        shift_in(&mut self.psi_y, self.psi);
        shift_in(&mut self.w_out, w);
        shift_in(&mut self.psi_w, psi);
        self.update_pe(&psi, wt - w, xt)
    }

    /// The cascade part of a prediction-error sample: x(t), y_hat(t) and psi(t) = d y_hat(t)
    /// / d theta (the input block's and backlash's columns; psi held while the backlash
    /// holds) with the current estimate, the lags moved on; returns x(t).
    #[inline(always)]
    fn inner_pe(&mut self, ut: f64) -> Result<f64> {
        let d = self.dims;
        let (na, nb, n) = (d.na, d.nb, d.degree);
        let (c_l, m_r1, c_r) = (d.c_l(), d.m_r1(), d.c_r());
        let xt = self.internal();
        let th = self.theta;
        let m_l = &th[c_l + 1..c_l + n];
        let m_r = &th[c_r + 1..c_r + n];
        let xi1 = xt + th[c_l];
        let xi2 = xt - th[c_r];
        let lv = branch(1.0, m_l, xi1);
        let yp = self.y_hat;
        let mv = if lv <= yp {
            1
        } else if branch(th[m_r1], m_r, xi2) >= yp {
            2
        } else {
            0
        };
        if mv != 0 {
            let psi = &mut self.psi;
            let (s, xi) = if mv == 1 {
                (slope(1.0, m_l, xi1), xi1)
            } else {
                (slope(th[m_r1], m_r, xi2), xi2)
            };
            for k in 0..na {
                psi[k] = s * self.wu[k];
            }
            for k in 0..nb {
                psi[na + k] = -s * self.wx[k];
            }
            for v in &mut psi[c_l..c_l + 2 * n + 1] {
                *v = 0.0;
            }
            let mut pw = xi;
            if mv == 1 {
                psi[c_l] = s;
                for i in 2..=n {
                    pw *= xi;
                    psi[c_l + i - 1] = pw;
                }
                self.y_hat = lv;
            } else {
                psi[c_r] = -s;
                psi[m_r1] = xi;
                for i in 2..=n {
                    pw *= xi;
                    psi[c_r + i - 1] = pw;
                }
                self.y_hat = branch(th[m_r1], m_r, xi2);
            }
        }
        if !(self.y_hat.is_finite() && xt.is_finite()) {
            return Err(diverged(self.t));
        }
        // the 1/B-filtered lags for sample t + 1
        let lags = na.max(nb);
        let (mut fu, mut fx) = (ut, xt);
        for k in 0..nb {
            fu -= th[na + k] * self.wu[k];
            fx -= th[na + k] * self.wx[k];
        }
        shift_in(&mut self.wu[..lags], fu);
        shift_in(&mut self.wx[..lags], fx);
        self.push_lags(ut, xt);
        Ok(xt)
    }

    /// One sample of the paper's quasi-linear form: x(t) and the switching of eq (25)-(26)
    /// from the current estimate (its simulated memory y_hat(t-1)), the row phi(t) of eq (18)
    /// and its target y(t) (eq 21 on a moving sample); a held sample's row is zero, so only
    /// forgetting and drift act on P (folded in at the next moving sample).
    #[inline(always)]
    fn step_regression(&mut self, ut: f64, yt: f64) -> Result<Option<(f64, f64)>> {
        let (moving, phi, xt) = self.inner_regression(ut)?;
        if moving {
            self.fold_pending();
            self.update(&phi, yt - self.y_hat, xt)
        } else {
            self.hold();
            Ok(None)
        }
    }

    /// The sandwich's regression sample (eq 33-34): the row Phi(t) is the cascade part's row
    /// at t - 1 (zero if the backlash held then), y_hat(t-2..t-nr) in r's columns and
    /// -w(t-1..t-ns) (measured) in s's; the target w(t) - y_hat(t-2) [1 - f_1(t-1)] [1 -
    /// f_2(t-1)]; the error against the current estimate, e = target - Phi' theta. A zero row
    /// (nr = 1, ns = 0 and a hold) is a held sample as in the cascade.
    #[inline(always)]
    fn step_regression_sandwich(&mut self, ut: f64, wt: f64) -> Result<Option<(f64, f64)>> {
        let (moving, phi_now, xt) = self.inner_regression(ut)?;
        let Orders { nr, ns, .. } = self.dims;
        let (r0, s0) = (self.dims.r(), self.dims.s());
        let (mut phi, target) = if self.moved_prev {
            (self.phi_prev, wt)
        } else {
            ([0.0; W], wt - self.y_out[1])
        };
        for i in 1..nr {
            phi[r0 + i - 1] = self.y_out[i];
        }
        for j in 0..ns {
            phi[s0 + j] = -self.w_out[j];
        }
        let mut e = target;
        for k in 0..W {
            e -= phi[k] * self.theta[k];
        }
        shift_in(&mut self.y_out, self.y_hat);
        shift_in(&mut self.w_out, wt);
        self.phi_prev = phi_now;
        self.moved_prev = moving;
        if phi.iter().any(|v| *v != 0.0) {
            self.fold_pending();
            self.update(&phi, e, xt)
        } else {
            self.hold();
            Ok(None)
        }
    }

    /// A held sample's row is zero: only forgetting and drift act (folded into P at the next
    /// update, `fold_pending`).
    #[inline(always)]
    fn hold(&mut self) {
        self.pending += 1.0;
        self.s1 *= self.lambda;
        self.s2 *= self.lambda * self.lambda;
    }

    /// The cascade part of a regression sample: x(t) and the switching of eq (25)-(26) from
    /// the current estimate, y_hat(t) and the row phi(t) of eq (18) (zero while the backlash
    /// holds), the lags moved on; returns (moving, phi(t), x(t)).
    #[inline(always)]
    fn inner_regression(&mut self, ut: f64) -> Result<(bool, [f64; W], f64)> {
        let d = self.dims;
        let (na, nb, n) = (d.na, d.nb, d.degree);
        let (c_l, m_r1, c_r) = (d.c_l(), d.m_r1(), d.c_r());
        let xt = self.internal();
        let th = self.theta;
        let m_l = &th[c_l + 1..c_l + n];
        let m_r = &th[c_r + 1..c_r + n];
        let xi1 = xt + th[c_l];
        let xi2 = xt - self.c_right();
        let lv = branch(1.0, m_l, xi1);
        let yp = self.y_hat;
        let mut phi = [0.0; W];
        let moving = if lv <= yp {
            self.y_hat = lv;
            phi[..na].copy_from_slice(&self.u_lag[..na]);
            for j in 0..nb {
                phi[na + j] = -self.x_lag[j];
            }
            phi[c_l] = 1.0;
            let mut pw = xi1;
            for i in 2..=n {
                pw *= xi1;
                phi[c_l + i - 1] = pw;
            }
            true
        } else {
            let rv = branch(th[m_r1], m_r, xi2);
            if rv >= yp {
                self.y_hat = rv;
                phi[m_r1] = xt;
                phi[c_r] = -1.0;
                let mut pw = xi2;
                for i in 2..=n {
                    pw *= xi2;
                    phi[c_r + i - 1] = pw;
                }
                true
            } else {
                false
            }
        };
        if !(self.y_hat.is_finite() && xt.is_finite()) {
            return Err(diverged(self.t));
        }
        self.push_lags(ut, xt);
        Ok((moving, phi, xt))
    }

    /// P of the held samples: P lambda^-h (S lambda^(-h/2)); their drift joins `q_wait`.
    #[inline(always)]
    fn fold_pending(&mut self) {
        if self.pending == 0.0 {
            return;
        }
        let h = self.pending;
        let mut grow2 = self.inv_lambda.powf(h);
        if self.trace * grow2 > TRACE_CAP {
            grow2 = (TRACE_CAP / self.trace).max(1.0);
        }
        self.trace *= grow2;
        let grow = grow2.sqrt();
        if grow != 1.0 {
            for row in self.sm.iter_mut() {
                for v in row.iter_mut() {
                    *v *= grow;
                }
            }
        }
        if self.has_drift {
            self.q_wait += h;
        }
        self.pending = 0.0;
    }

    /// P + h Q for the h samples of drift waiting, S re-factored.
    #[cold]
    fn add_drift(&mut self) {
        let p = self.dims.p();
        let mut pm = product(&self.sm, p);
        let scale = self.q_wait / self.sigma2;
        for i in 0..p {
            pm[i][i] += scale * self.q[i];
        }
        self.sm = cholesky(&pm, p);
        self.trace = (0..p).map(|i| pm[i][i]).sum();
        self.q_wait = 0.0;
    }

    /// The measurement update with row `phi` and error `e` at internal signal `xt`, then
    /// P / lambda (drift added in batches, `add_drift`); a step that leaves the linear block
    /// unstable, m_R1 <= 0 or a branch decreasing at `xt` is rejected (theta kept), a
    /// negative width projected to 0 (the batch LM's `feasible` and `bounds`). Returns (e,
    /// xt) for the monitor.
    #[inline(always)]
    fn update(&mut self, phi: &[f64; W], e: f64, xt: f64) -> Result<Option<(f64, f64)>> {
        let p = self.dims.p();
        self.row = *phi;
        if self.q_wait >= DRIFT_BATCH {
            self.add_drift();
        }
        // Potter: f = S' phi, beta = 1 + f'f, g = S f = P phi, S <- S (I - gamma f f')
        let mut f = [0.0; W];
        for i in 0..W {
            let (row, ph) = (&self.sm[i], phi[i]);
            for j in 0..W {
                f[j] += row[j] * ph;
            }
        }
        let mut beta = 1.0;
        for v in &f {
            beta += v * v;
        }
        let mut g = [0.0; W];
        for i in 0..W {
            let mut acc = 0.0;
            for j in 0..W {
                acc += self.sm[i][j] * f[j];
            }
            g[i] = acc;
        }
        if !beta.is_finite() {
            return Err(sensitivities_overflowed(self.t));
        }
        if e * e > self.bound2 * beta {
            // an innovation no estimate near this one explains (a runaway or an outlier):
            // the update is refused and the estimate goes back to its checkpoint
            Checkpoint {
                theta: self.theta,
                sm: self.sm,
                trace: self.trace,
            } = self.checkpoint;
            self.since_ck = 0;
            self.refused += 1;
            return Ok(Some((e, xt)));
        }
        let inv_s = 1.0 / beta;
        let gamma = 1.0 / (beta + beta.sqrt());
        let mut cand = self.theta;
        let ke = e * inv_s;
        for i in 0..W {
            cand[i] += g[i] * ke;
        }
        let (c_l, m_r1, c_r, na, nb) = (
            self.dims.c_l(),
            self.dims.m_r1(),
            self.dims.c_r(),
            self.dims.na,
            self.dims.nb,
        );
        cand[c_l] = cand[c_l].max(0.0);
        cand[c_r] = cand[c_r].max(0.0);
        // both branches still increase at this sample's x (m_L1 = 1)
        let n = self.dims.degree;
        let c_right = match self.method {
            Method::PredictionError => cand[c_r],
            Method::Regression => cand[c_r] / cand[m_r1],
        };
        let rising = slope(1.0, &cand[c_l + 1..c_l + n], xt + cand[c_l]) > 0.0
            && slope(cand[m_r1], &cand[c_r + 1..c_r + n], xt - c_right) > 0.0;
        let (s0, ns) = (self.dims.s(), self.dims.ns);
        if cand[m_r1] > 0.0
            && rising
            && stable::<W>(&cand[na..na + nb])
            && stable::<W>(&cand[s0..s0 + ns])
            && cand[..p].iter().all(|v| v.is_finite())
        {
            self.theta = cand;
        } else {
            self.rejected += 1;
        }
        let c = if self.trace * self.inv_lambda > TRACE_CAP {
            1.0
        } else {
            self.sqrt_inv_lambda
        };
        for i in 0..W {
            let gi = g[i] * gamma;
            for j in 0..W {
                self.sm[i][j] = (self.sm[i][j] - gi * f[j]) * c;
            }
        }
        if self.t & (TRACE_EVERY - 1) == 0 {
            // summed from S itself: a running recursion trace <- (trace - |g|^2 / beta) /
            // lambda would amplify its rounding by 1 / lambda per sample
            self.trace = self.sm.iter().flatten().map(|v| v * v).sum();
        }
        if self.has_drift {
            self.q_wait += 1.0;
        }
        self.s1 = self.lambda * self.s1 + 1.0;
        self.s2 = self.lambda * self.lambda * self.s2 + 1.0;
        self.noise_count += 1.0;
        let gamma = 1.0 / self.noise_count.min(self.noise_memory);
        let v = e * e * inv_s;
        if v.is_finite() {
            self.sigma2 += gamma * (v - self.sigma2);
        }
        self.sigma2 = self.sigma2.max(f64::MIN_POSITIVE);
        self.since_ck += 1;
        if self.since_ck == CHECKPOINT {
            self.checkpoint = self.now();
            self.since_ck = 0;
        }
        Ok(Some((e, xt)))
    }

    /// Every number that changes while tracking, in a fixed order (`load` reads it back).
    pub(crate) fn save(&self) -> Vec<f64> {
        let p = self.dims.p();
        let mut out = Vec::with_capacity(p * p + 10 * p + 16);
        out.extend_from_slice(&self.q[..p]);
        out.extend_from_slice(&self.theta[..p]);
        for row in self.sm.iter().take(p) {
            out.extend_from_slice(&row[..p]);
        }
        for lags in [&self.u_lag, &self.x_lag, &self.wu, &self.wx, &self.psi] {
            out.extend_from_slice(&lags[..p]);
        }
        out.extend([
            self.sigma2,
            self.noise_count,
            self.s1,
            self.s2,
            self.y_hat,
            self.pending,
            self.q_wait,
            self.trace,
            self.t as f64,
            self.rejected as f64,
        ]);
        if self.dims.sandwich() {
            out.extend_from_slice(&self.y_out);
            out.extend_from_slice(&self.w_out);
            for row in self.psi_y.iter().chain(&self.psi_w) {
                out.extend_from_slice(&row[..p]);
            }
            out.extend_from_slice(&self.phi_prev[..p]);
            out.push(f64::from(u8::from(self.moved_prev)));
        }
        if let Some(d) = &self.detector {
            d.save(&mut out);
        }
        if let Some(m) = &self.monitor {
            m.save(&mut out);
        }
        let ck = &self.checkpoint;
        out.extend([self.since_ck as f64, self.refused as f64, ck.trace]);
        out.extend_from_slice(&ck.theta[..p]);
        for row in ck.sm.iter().take(p) {
            out.extend_from_slice(&row[..p]);
        }
        out
    }

    pub(crate) fn saved_len(&self) -> usize {
        let p = self.dims.p();
        self.saved_len_before_guard() + GUARD_SAVED + p + p * p
    }

    /// The length of a state saved before the innovation bound (2026-11-29): `load` takes
    /// it, the checkpoint its estimate, nothing refused yet.
    fn saved_len_before_guard(&self) -> usize {
        let p = self.dims.p();
        let sandwich = match self.dims.sandwich() {
            true => 2 * OUT_LAGS * (1 + p) + p + 1,
            false => 0,
        };
        p * p
            + 7 * p
            + 10
            + sandwich
            + self.detector.as_ref().map_or(0, |_| DETECTOR_SAVED)
            + self
                .monitor
                .as_ref()
                .map_or(0, |m| monitor_saved(m.options.lags, m.options.whiteness, p))
    }

    pub(crate) fn load(&mut self, s: &[f64]) -> Result<()> {
        let guarded = s.len() == self.saved_len();
        if !guarded && s.len() != self.saved_len_before_guard() {
            return Err(Error::Data(format!(
                "a saved tracker state of {} numbers, this tracker's has {}: restore it \
                 into a tracker of the same structure and options",
                s.len(),
                self.saved_len()
            )));
        }
        let p = self.dims.p();
        let mut it = s.iter().copied();
        let mut take = |dst: &mut [f64]| dst.iter_mut().for_each(|v| *v = it.next().unwrap());
        take(&mut self.q[..p]);
        take(&mut self.theta[..p]);
        for row in self.sm.iter_mut().take(p) {
            take(&mut row[..p]);
        }
        take(&mut self.u_lag[..p]);
        take(&mut self.x_lag[..p]);
        take(&mut self.wu[..p]);
        take(&mut self.wx[..p]);
        take(&mut self.psi[..p]);
        let mut rest = [0.0; 10];
        take(&mut rest);
        [
            self.sigma2,
            self.noise_count,
            self.s1,
            self.s2,
            self.y_hat,
            self.pending,
            self.q_wait,
        ] = [
            rest[0], rest[1], rest[2], rest[3], rest[4], rest[5], rest[6],
        ];
        self.trace = rest[7];
        self.t = rest[8] as u64;
        self.rejected = rest[9] as u64;
        if self.dims.sandwich() {
            take(&mut self.y_out);
            take(&mut self.w_out);
            for row in self.psi_y.iter_mut().chain(self.psi_w.iter_mut()) {
                take(&mut row[..p]);
            }
            take(&mut self.phi_prev[..p]);
            let mut moved = [0.0];
            take(&mut moved);
            self.moved_prev = moved[0] != 0.0;
        }
        if let Some(d) = &mut self.detector {
            let mut ds = [0.0; DETECTOR_SAVED];
            take(&mut ds);
            d.load(&ds);
        }
        if let Some(m) = &mut self.monitor {
            let mut ms = vec![0.0; monitor_saved(m.options.lags, m.options.whiteness, p)];
            take(&mut ms);
            m.load(&ms);
        }
        if guarded {
            let mut g = [0.0; GUARD_SAVED];
            take(&mut g);
            (self.since_ck, self.refused, self.checkpoint.trace) = (g[0] as u64, g[1] as u64, g[2]);
            take(&mut self.checkpoint.theta[..p]);
            for row in self.checkpoint.sm.iter_mut().take(p) {
                take(&mut row[..p]);
            }
        } else {
            (self.since_ck, self.refused) = (0, 0);
            self.checkpoint = self.now();
        }
        Ok(())
    }
}

fn sensitivities_overflowed(t: u64) -> Error {
    Error::Model(format!(
        "the tracker's regressor overflowed at sample {t} (a huge input or internal signal): \
         scale the signals down"
    ))
}

fn diverged(t: u64) -> Error {
    Error::Model(format!(
        "the tracked model's simulated output overflowed at sample {t}: start from a better \
         model (a batch fit on the first samples) or a smaller initial covariance"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_params::{example1_model, noisy};

    /// The AVX2 build of the loop gives the same bits as the plain one (no contraction into
    /// fused multiply-adds): a tracker pickled on one machine continues alike on another.
    #[test]
    fn wide_vectors_change_no_bit() {
        let u: Vec<f64> = (0..20_000)
            .map(|k| ((k as f64) * 0.7).sin() * 0.8 + ((k as f64) * 0.13).cos() * 0.3)
            .collect();
        let m = example1_model();
        let y = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 21);
        let theta0 = [
            0.68, 0.52, -0.21, 0.33, 0.58, -0.28, 0.31, 1.45, 0.52, 0.42, 0.18,
        ];
        let cov: Vec<f64> = (0..121)
            .map(|k| if k % 12 == 0 { 1e-3 } else { 0.0 })
            .collect();
        let dims = Orders::cascade(2, 2, 3);
        for method in [Method::Regression, Method::PredictionError] {
            let options = Options {
                method,
                forgetting: 0.999,
                drift: vec![1e-5; 11],
                noise_memory: 1e4,
                innovation_bound: f64::INFINITY,
            };
            let det = Detector::new(super::super::DetectorOptions::for_forgetting(0.99)).ok();
            let new =
                || Engine::<12>::new(dims, &options, &theta0, &cov, 1e-3, 10.0, det.clone(), None);
            let (mut a, mut b) = (new().unwrap(), new().unwrap());
            let (mut ta, mut sa, mut aa) = (vec![0.0; 11 * 20_000], vec![0.0; 11 * 20_000], vec![]);
            let (mut tb, mut sb, mut ab) = (ta.clone(), sa.clone(), vec![]);
            let mut sink_a = Sink {
                theta: &mut ta,
                se: &mut sa,
                every: 1,
                alarms: &mut aa,
                windows: &mut vec![],
            };
            a.run(&u, &y, &mut sink_a).unwrap();
            let mut sink_b = Sink {
                theta: &mut tb,
                se: &mut sb,
                every: 1,
                alarms: &mut ab,
                windows: &mut vec![],
            };
            b.run_plain(&u, &y, &mut sink_b).unwrap();
            assert!(
                ta.iter().zip(&tb).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{method:?}"
            );
            assert!(
                sa.iter().zip(&sb).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{method:?}"
            );
            assert_eq!(a.save(), b.save());
        }
    }
}
