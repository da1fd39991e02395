//! The model-mismatch monitor (issue 33): does the tracked structure explain the data? Over
//! consecutive windows of `window` samples it tests the tracker's own innovations e(t) (the
//! prediction error of each update) against what the right structure leaves: an innovation
//! uncorrelated with its own past (whiteness; prediction-error rule only: the regression's
//! equation error of a sandwich is coloured by its output block even for the right model),
//! with the past input u(t-k) and with the model's past internal signal x(t-k), k = 1..K,
//! once a parameter error is allowed for. It takes the samples that update the estimate (a
//! held sample of the cascade's regression has no innovation: it is skipped, and the lags are
//! those of the updating samples).
//!
//! The statistic is the score (Lagrange-multiplier) test of the window's regression
//!     e(t) = psi(t)^T d + sum_k g_k e(t-k) + z(t)^T h + noise,   z(t) = [u(t-1..K), x(t-1..K)],
//! (centred), psi(t) the update's row (the prediction error's d y_hat(t) / d theta, the
//! regression's row of eq 18 / 33). An estimate off the plant by d leaves psi^T d in e to
//! first order: coloured and correlated with the past input however right the structure (a
//! start fitted on a head that does not determine the model; an estimate whose forgetting
//! window holds one leg of a ramp). So the lags are tested on what psi leaves (Ljung, System
//! Identification, 16.6; Breusch-Godfrey):
//!     Q = n R^2(lags | psi) = n (explained by psi and the lags - explained by psi) / (sum e^2
//!         - explained by psi),
//! about chi-square with rank(lags | psi) degrees of freedom when the structure is right,
//! whatever d. Its partner, Q_psi = n R^2 of e on psi alone (chi-square with rank(psi)
//! when the estimate is right too), tells whether the estimate has settled: failing windows
//! with a passing Q say "the parameters are off", not "the structure is wrong". Each share is
//! the quadratic form c^T C^+ c of the cross products with the regressors' own correlation
//! matrix, by pivoted elimination (psi's columns first): a slow input barely changes from one
//! lag to the next, so its K lags (and x = a_1 u(t-1) of an input backlash) are nearly one
//! regressor, counted once. C^+ keeps the directions whose variance is above `TOL` of the
//! variables' own mean square.
//!
//! A window whose Q exceeds the caller's chi-square quantile for its degrees fails; `confirm`
//! consecutive failing windows set the "mismatch" verdict (one failing window is also a start
//! that has not settled yet), and it holds until `clear` consecutive windows pass; Q_psi sets
//! and clears the "unsettled" verdict the same way. While mismatch holds the wear detector
//! takes no readings: a wandering estimate of a wrong structure is not wear.
//!
//! A wrong structure leaves a deterministic error, a function of the past input through the
//! plant's dynamics that no parameter change of the tracked structure reproduces: coloured
//! and correlated with the past input or the model's x beyond psi, unless the tracker absorbs
//! it within its forgetting window.

use super::shift_in;
use crate::error::{Error, Result};

/// The largest number of lags K a monitor takes.
pub const MAX_MONITOR_LAGS: usize = 16;
/// The largest degrees of freedom of a test: the lags' 3K (<= 48) or psi's p (<= 64).
pub const MAX_MONITOR_DEGREES: usize = 64;
/// A direction whose variance, after the directions kept before it, is below this share of
/// its own (on the correlation scale) is a combination of them: not a degree of freedom.
const TOL: f64 = 1e-8;

/// The monitor's settings (module header).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorOptions {
    /// Samples per window (>= 10 K).
    pub window: u64,
    /// Lags K (1..=16).
    pub lags: usize,
    /// `thresholds[d - 1]`: the Q (or Q_psi) above which a window of d degrees of freedom
    /// fails (> 0 for d = 1..=max(degrees(), p)).
    pub thresholds: [f64; MAX_MONITOR_DEGREES],
    /// Consecutive failing windows that set a verdict (>= 1).
    pub confirm: u32,
    /// Consecutive passing windows that clear it (>= 1).
    pub clear: u32,
    /// Test the innovation's whiteness too (the prediction-error rule).
    pub whiteness: bool,
}

impl MonitorOptions {
    /// Checks the options for a tracker of p parameters (psi's columns).
    pub fn check(&self, p: usize) -> Result<()> {
        if !(1..=MAX_MONITOR_LAGS).contains(&self.lags) {
            return Err(Error::Data(format!(
                "monitor lags = {}: give 1..{MAX_MONITOR_LAGS}",
                self.lags
            )));
        }
        if self.window < 10 * self.lags as u64 {
            return Err(Error::Data(format!(
                "monitor window = {}: give at least 10 samples per lag ({})",
                self.window,
                10 * self.lags
            )));
        }
        let most = self.degrees().max(p);
        if most > MAX_MONITOR_DEGREES {
            return Err(Error::Data(format!(
                "a monitor of {p} parameters: give at most {MAX_MONITOR_DEGREES}"
            )));
        }
        let bad = self.thresholds[..most]
            .iter()
            .find(|t| !(t.is_finite() && **t > 0.0));
        if let Some(t) = bad {
            return Err(Error::Data(format!(
                "monitor threshold = {t}: give finite thresholds > 0 for 1..{most} degrees of \
                 freedom"
            )));
        }
        if self.clear == 0 || self.confirm == 0 {
            return Err(Error::Data(format!(
                "monitor confirm = {}, clear = {}: give confirm, clear >= 1",
                self.confirm, self.clear
            )));
        }
        Ok(())
    }

    /// The largest degrees of freedom of Q (every lag independent of the others and of psi).
    pub fn degrees(&self) -> usize {
        self.lags * if self.whiteness { 3 } else { 2 }
    }
}

/// One window's verdicts: its last sample, Q and its degrees of freedom, whether the mismatch
/// verdict holds after it, and the same of Q_psi and the "unsettled" verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub sample: u64,
    pub statistic: f64,
    pub degrees: usize,
    pub mismatch: bool,
    pub parameter_statistic: f64,
    pub parameter_degrees: usize,
    pub unsettled: bool,
}

/// A verdict set by `confirm` consecutive failing windows and cleared by `clear` passing ones.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Verdict {
    failed: u32,
    passed: u32,
    holds: bool,
}

impl Verdict {
    fn judge(&mut self, fails: bool, options: &MonitorOptions) {
        if fails {
            self.failed += 1;
            self.passed = 0;
            if self.failed >= options.confirm {
                self.holds = true;
            }
        } else {
            self.failed = 0;
            if self.holds {
                self.passed += 1;
                if self.passed >= options.clear {
                    self.holds = false;
                    self.passed = 0;
                }
            }
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Monitor {
    pub options: MonitorOptions,
    /// psi's columns.
    p: usize,
    /// e, u, x at lags 1..K (index 0 = lag 1).
    e_lag: [f64; MAX_MONITOR_LAGS],
    u_lag: [f64; MAX_MONITOR_LAGS],
    x_lag: [f64; MAX_MONITOR_LAGS],
    /// Lagged samples seen (up to K): a window's first products wait for the lags.
    filled: usize,
    /// The window's sums: n, sum e^2, sum e, and of v = [psi, e lags (with whiteness), u
    /// lags, x lags]: sum v, sum e v, sum v v^T (upper triangle of the dim x dim matrix, row
    /// by row).
    n: f64,
    see: f64,
    se: f64,
    sv: Vec<f64>,
    cev: Vec<f64>,
    svv: Vec<f64>,
    mismatch: Verdict,
    unsettled: Verdict,
}

/// Numbers `save` writes for a monitor of `lags` lags and p parameters.
pub(crate) const fn monitor_saved(lags: usize, whiteness: bool, p: usize) -> usize {
    let d = dim(lags, whiteness, p);
    3 * lags + 2 * d + d * (d + 1) / 2 + 10
}

/// The regressors v per sample: psi's p, then the lags' 3K (2K without whiteness).
const fn dim(lags: usize, whiteness: bool, p: usize) -> usize {
    p + lags * if whiteness { 3 } else { 2 }
}

impl Monitor {
    pub fn new(options: MonitorOptions, p: usize) -> Result<Self> {
        options.check(p)?;
        let d = dim(options.lags, options.whiteness, p);
        Ok(Self {
            options,
            p,
            e_lag: [0.0; MAX_MONITOR_LAGS],
            u_lag: [0.0; MAX_MONITOR_LAGS],
            x_lag: [0.0; MAX_MONITOR_LAGS],
            filled: 0,
            n: 0.0,
            see: 0.0,
            se: 0.0,
            sv: vec![0.0; d],
            cev: vec![0.0; d],
            svv: vec![0.0; d * (d + 1) / 2],
            mismatch: Verdict::default(),
            unsettled: Verdict::default(),
        })
    }

    /// Whether the mismatch verdict holds.
    pub fn mismatch(&self) -> bool {
        self.mismatch.holds
    }

    /// Whether the "unsettled" verdict holds: the innovations say the parameters are off.
    pub fn unsettled(&self) -> bool {
        self.unsettled.holds
    }

    /// Take sample `sample`'s innovation e(t), input u(t), the model's x(t) and the update's
    /// row psi(t) (p values); at a window's end, its verdict. The lags roll on every sample.
    #[inline(always)]
    pub(crate) fn observe(
        &mut self,
        sample: u64,
        e: f64,
        u: f64,
        x: f64,
        psi: &[f64],
    ) -> Option<Window> {
        let k = self.options.lags;
        let mut out = None;
        if self.filled == k {
            let p = self.p;
            let d = self.sv.len();
            let mut v = [0.0; MAX_MONITOR_DEGREES + 3 * MAX_MONITOR_LAGS];
            v[..p].copy_from_slice(&psi[..p]);
            let mut at = p;
            if self.options.whiteness {
                v[at..at + k].copy_from_slice(&self.e_lag[..k]);
                at += k;
            }
            v[at..at + k].copy_from_slice(&self.u_lag[..k]);
            v[at + k..at + 2 * k].copy_from_slice(&self.x_lag[..k]);
            self.n += 1.0;
            self.see += e * e;
            self.se += e;
            let mut at = 0;
            for i in 0..d {
                let vi = v[i];
                self.sv[i] += vi;
                self.cev[i] += e * vi;
                for (s, vj) in self.svv[at..at + d - i].iter_mut().zip(&v[i..d]) {
                    *s += vi * vj;
                }
                at += d - i;
            }
            if self.n as u64 >= self.options.window {
                out = Some(self.close(sample));
            }
        } else {
            self.filled += 1;
        }
        shift_in(&mut self.e_lag[..k], e);
        shift_in(&mut self.u_lag[..k], u);
        shift_in(&mut self.x_lag[..k], x);
        out
    }

    /// The shares of the innovation's centred variance that psi explains and that the lags
    /// explain beyond psi, with their ranks, by pivoted elimination on the regressors'
    /// centred correlation matrix: each step takes the direction with the most variance left
    /// (psi's columns first), adds its share of the innovation and removes it from the others.
    #[allow(clippy::needless_range_loop)] // the symmetric matrix reads best by its indices
    fn shares(&self) -> [(f64, usize); 2] {
        let d = self.sv.len();
        let n = self.n;
        let mut c = vec![vec![0.0; d]; d];
        let mut g = vec![0.0; d];
        let mut at = 0;
        for i in 0..d {
            for j in i..d {
                let v = self.svv[at] - self.sv[i] * self.sv[j] / n;
                c[i][j] = v;
                c[j][i] = v;
                at += 1;
            }
            g[i] = self.cev[i] - self.sv[i] * self.se / n;
        }
        // on the scale of each regressor's raw second moment (the precision of its centred
        // sums): a direction is judged by the share of it left, so a constant regressor (at
        // rest, a held psi) or a combination of the others has none
        let mut scale = vec![0.0; d];
        let mut left = vec![false; d];
        at = 0;
        for i in 0..d {
            let raw = self.svv[at];
            at += d - i;
            if raw > 0.0 && raw.is_finite() {
                scale[i] = 1.0 / raw.sqrt();
                left[i] = true;
            }
        }
        for i in 0..d {
            g[i] *= scale[i];
            for j in 0..d {
                c[i][j] *= scale[i] * scale[j];
            }
        }
        let mut out = [(0.0, 0); 2];
        for (part, columns) in [(0, 0..self.p), (1, self.p..d)] {
            loop {
                let pivot = columns
                    .clone()
                    .filter(|&i| left[i])
                    .max_by(|&a, &b| c[a][a].total_cmp(&c[b][b]));
                let Some(q) = pivot else { break };
                let cqq = c[q][q];
                if cqq <= TOL || cqq.is_nan() {
                    break;
                }
                left[q] = false;
                out[part].1 += 1;
                out[part].0 += g[q] * g[q] / cqq;
                for i in (0..d).filter(|&i| left[i]) {
                    let f = c[i][q] / cqq;
                    g[i] -= f * g[q];
                    for j in (0..d).filter(|&j| left[j]) {
                        c[i][j] -= f * c[q][j];
                    }
                }
            }
            // what a part leaves below TOL is no degree of freedom: not tested with the next
            for i in columns {
                left[i] = false;
            }
        }
        out
    }

    /// Q and Q_psi of the window (module header) and the verdicts; the sums start again.
    fn close(&mut self, sample: u64) -> Window {
        let n = self.n;
        let vee = self.see - self.se * self.se / n;
        let [(by_psi, psi_rank), (by_lags, rank)] = self.shares();
        let ratio = |share: f64, of: f64| if of > 0.0 { n * share / of } else { 0.0 };
        let q = ratio(by_lags, vee - by_psi);
        let q_psi = ratio(by_psi, vee);
        let fails = |q: f64, degrees: usize| match degrees {
            0 => false,
            d => q > self.options.thresholds[d - 1] || !q.is_finite(),
        };
        let (bad, off) = (fails(q, rank), fails(q_psi, psi_rank));
        self.mismatch.judge(bad, &self.options);
        self.unsettled.judge(off, &self.options);
        self.n = 0.0;
        self.see = 0.0;
        self.se = 0.0;
        for s in [&mut self.sv, &mut self.cev, &mut self.svv] {
            s.iter_mut().for_each(|v| *v = 0.0);
        }
        Window {
            sample,
            statistic: q,
            degrees: rank,
            mismatch: self.mismatch.holds,
            parameter_statistic: q_psi,
            parameter_degrees: psi_rank,
            unsettled: self.unsettled.holds,
        }
    }

    pub(crate) fn save(&self, out: &mut Vec<f64>) {
        let k = self.options.lags;
        for a in [&self.e_lag, &self.u_lag, &self.x_lag] {
            out.extend_from_slice(&a[..k]);
        }
        out.extend_from_slice(&self.sv);
        out.extend_from_slice(&self.cev);
        out.extend_from_slice(&self.svv);
        let (m, s) = (self.mismatch, self.unsettled);
        out.extend([
            self.filled as f64,
            self.n,
            self.see,
            self.se,
            f64::from(m.failed),
            f64::from(m.passed),
            f64::from(u8::from(m.holds)),
            f64::from(s.failed),
            f64::from(s.passed),
            f64::from(u8::from(s.holds)),
        ]);
    }

    pub(crate) fn load(&mut self, s: &[f64]) {
        let k = self.options.lags;
        let mut it = s.iter().copied();
        let mut take = |dst: &mut [f64]| dst.iter_mut().for_each(|v| *v = it.next().unwrap_or(0.0));
        take(&mut self.e_lag[..k]);
        take(&mut self.u_lag[..k]);
        take(&mut self.x_lag[..k]);
        take(&mut self.sv);
        take(&mut self.cev);
        take(&mut self.svv);
        let mut rest = [0.0; 10];
        take(&mut rest);
        self.filled = rest[0] as usize;
        self.n = rest[1];
        self.see = rest[2];
        self.se = rest[3];
        let verdict = |r: &[f64]| Verdict {
            failed: r[0] as u32,
            passed: r[1] as u32,
            holds: r[2] != 0.0,
        };
        self.mismatch = verdict(&rest[4..7]);
        self.unsettled = verdict(&rest[7..10]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn options() -> MonitorOptions {
        MonitorOptions {
            window: 2000,
            lags: 5,
            thresholds: [50.0; MAX_MONITOR_DEGREES],
            confirm: 1,
            clear: 2,
            whiteness: true,
        }
    }

    fn gauss(rng: &mut StdRng) -> f64 {
        // Box-Muller
        let (a, b): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }

    /// Q and Q_psi of every window over white innovations independent of u, x and two
    /// parameter directions psi (one of them the input's lag, as a cascade's b_1 column is).
    fn statistics(slow: bool, seed: u64) -> Vec<(f64, usize, f64, usize)> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut m = Monitor::new(options(), 2).unwrap();
        let (mut out, mut u, mut prev_u) = (vec![], 0.0, 0.0);
        for t in 0..1_000_000u64 {
            let x;
            if slow {
                // a drive's slow input (pole 0.995) and an input backlash's x = a_1 u(t-1)
                u = 0.995 * u + 0.1 * gauss(&mut rng);
                x = 0.7 * prev_u;
            } else {
                u = rng.random_range(-1.0..1.0);
                x = 0.5 * u + 0.3 * prev_u;
            }
            let psi = [prev_u, gauss(&mut rng)];
            if let Some(w) = m.observe(t, gauss(&mut rng), u, x, &psi) {
                out.push((
                    w.statistic,
                    w.degrees,
                    w.parameter_statistic,
                    w.parameter_degrees,
                ));
            }
            prev_u = u;
        }
        out
    }

    /// Mean and variance of a sample of statistics.
    fn moments(qs: &[f64]) -> (f64, f64) {
        let n = qs.len() as f64;
        let mean = qs.iter().sum::<f64>() / n;
        (
            mean,
            qs.iter().map(|q| (q - mean).powi(2)).sum::<f64>() / (n - 1.0),
        )
    }

    /// Under the right structure Q is chi-square with K + rank(z | psi) degrees of freedom and
    /// Q_psi with rank(psi): their means are the degrees, their variances twice the degrees,
    /// for a white input and for a slow one whose lags are nearly one regressor (there the
    /// sum of the 15 squared correlations, the form before 2026-11-29, has a mean of 13.5 and
    /// a variance of 155, five times chi-square's).
    #[test]
    fn white_innovations_give_chi_square_with_the_rank_s_degrees() {
        // x's lags span u(t-1..K+1) in both (x = 0.5 u + 0.3 u(t-1); x = a_1 u(t-1)): rank 6
        // of the 10 columns, and psi's first column u(t-1) takes one of them: 5 + 5 degrees
        for (slow, degrees) in [(false, 10), (true, 10)] {
            let qs = statistics(slow, 1);
            let other: Vec<_> = qs
                .iter()
                .filter(|q| q.1 != degrees || q.3 != 2)
                .take(3)
                .collect();
            assert!(other.is_empty(), "slow {slow}: {other:?}");
            for (stat, k) in [(0, degrees as f64), (2, 2.0)] {
                let values: Vec<f64> = qs
                    .iter()
                    .map(|q| if stat == 0 { q.0 } else { q.2 })
                    .collect();
                let (mean, var) = moments(&values);
                assert!(
                    (mean / k - 1.0).abs() < 0.1 && (var / (2.0 * k) - 1.0).abs() < 0.3,
                    "slow {slow}, statistic {stat}: mean {mean}, variance {var}, degrees {k}"
                );
            }
        }
    }

    /// An estimate off by d leaves psi^T d in the innovation, coloured and correlated with the
    /// past input (psi is a filtered input): the lags alone (a monitor without psi, the
    /// statistic before 2026-11-30) call it a wrong structure; with psi allowed for, Q stays
    /// chi-square (mean within 10 % of its 10 degrees) and Q_psi sets the "unsettled" verdict
    /// instead.
    #[test]
    fn a_parameter_error_is_unsettled_not_a_wrong_structure() {
        let mut rng = StdRng::seed_from_u64(4);
        let mut with_psi = Monitor::new(options(), 2).unwrap();
        let mut without = Monitor::new(options(), 0).unwrap();
        let (mut u, mut f, mut qs) = (0.0, 0.0, vec![]);
        for t in 0..200_000u64 {
            // a slow input and a sensitivity that filters it (pole 0.9)
            let prev_u = u;
            u = 0.99 * u + 0.1 * gauss(&mut rng);
            f = 0.9 * f + prev_u;
            let psi = [f, prev_u];
            let e = 0.03 * f - 0.02 * prev_u + 0.1 * gauss(&mut rng);
            if let Some(w) = with_psi.observe(t, e, u, 0.7 * prev_u, &psi) {
                assert!(w.unsettled && !w.mismatch, "{w:?}");
                qs.push(w.statistic);
            }
            if let Some(w) = without.observe(t, e, u, 0.7 * prev_u, &[]) {
                assert!(w.mismatch && w.parameter_degrees == 0, "{w:?}");
            }
        }
        let (mean, _) = moments(&qs);
        assert!((mean / 10.0 - 1.0).abs() < 0.1, "mean Q {mean}");
    }

    /// Innovations that carry a past input fail at once and the verdict clears after `clear`
    /// passing windows; a window at rest (no variance in u or x) tests the whiteness alone.
    #[test]
    fn a_leftover_of_the_input_fails_and_clears() {
        let mut rng = StdRng::seed_from_u64(2);
        let mut m = Monitor::new(options(), 1).unwrap();
        let (mut verdicts, mut prev_u) = (vec![], 0.0);
        for t in 0..10_000u64 {
            let u = rng.random_range(-1.0..1.0);
            let leftover = if t < 4000 { 0.2 * prev_u } else { 0.0 };
            // psi: a parameter direction the leftover is not (the input now)
            if let Some(w) = m.observe(t, gauss(&mut rng) * 0.1 + leftover, u, u, &[u]) {
                verdicts.push(w.mismatch);
                assert_eq!(w.degrees, 10, "{w:?}");
            }
            prev_u = u;
        }
        assert_eq!(verdicts, [true, true, true, false]);
        let mut m = Monitor::new(options(), 1).unwrap();
        let w = (0..2005u64)
            .find_map(|t| m.observe(t, gauss(&mut rng), 0.3, 0.3, &[0.3]))
            .unwrap();
        assert_eq!((w.degrees, w.parameter_degrees), (5, 0), "{w:?}");
        assert!(w.statistic < 50.0 && !w.mismatch, "{w:?}");
    }

    /// A saved monitor restored mid-window closes that window as the original does.
    #[test]
    fn a_saved_monitor_continues_where_it_stopped() {
        let mut rng = StdRng::seed_from_u64(3);
        let mut a = Monitor::new(options(), 2).unwrap();
        let data: Vec<[f64; 5]> = (0..4000)
            .map(|_| std::array::from_fn(|_| gauss(&mut rng)))
            .collect();
        for (t, s) in data[..1234].iter().enumerate() {
            a.observe(t as u64, s[0], s[1], s[2], &s[3..]);
        }
        let mut saved = vec![];
        a.save(&mut saved);
        assert_eq!(saved.len(), monitor_saved(5, true, 2));
        let mut b = Monitor::new(options(), 2).unwrap();
        b.load(&saved);
        assert_eq!(a, b);
        for (t, s) in data.iter().enumerate().skip(1234) {
            let t = t as u64;
            assert_eq!(
                a.observe(t, s[0], s[1], s[2], &s[3..]),
                b.observe(t, s[0], s[1], s[2], &s[3..])
            );
        }
    }

    #[test]
    fn bad_options_are_refused() {
        let mut zero = [50.0; MAX_MONITOR_DEGREES];
        zero[14] = 0.0;
        for bad in [
            MonitorOptions {
                lags: 0,
                ..options()
            },
            MonitorOptions {
                lags: 17,
                ..options()
            },
            MonitorOptions {
                window: 49,
                ..options()
            },
            MonitorOptions {
                thresholds: zero,
                ..options()
            },
            MonitorOptions {
                clear: 0,
                ..options()
            },
            MonitorOptions {
                confirm: 0,
                ..options()
            },
        ] {
            assert!(Monitor::new(bad, 2).is_err(), "{bad:?}");
        }
        // 15 thresholds do not cover psi's test of 16 parameters
        let mut short = [0.0; MAX_MONITOR_DEGREES];
        short[..15].fill(50.0);
        let options = MonitorOptions {
            thresholds: short,
            ..options()
        };
        assert!(Monitor::new(options, 15).is_ok());
        assert!(Monitor::new(options, 16).is_err());
    }
}
