//! The model-mismatch monitor (issue 33): does the tracked structure explain the data? Over
//! consecutive windows of `window` samples it tests the tracker's own innovations e(t) (the
//! prediction error of each update) against what the right structure leaves: an innovation
//! uncorrelated with its own past (whiteness; prediction-error rule only: the regression's
//! equation error of a sandwich is coloured by its output block even for the right model),
//! with the past input u(t-k) and with the model's past internal signal x(t-k), k = 1..K.
//! It takes the samples that update the estimate (a held sample of the cascade's regression
//! has no innovation: it is skipped, and the lags are those of the updating samples).
//!
//! The statistic is the score (Lagrange-multiplier) test of the window's regression
//!     e(t) = sum_k g_k e(t-k) + z(t)^T h + noise,   z(t) = [u(t-1..K), x(t-1..K)] (centred),
//! in two parts (Ljung, System Identification, 16.6):
//!     Q = n sum_k r_ee(k)^2  +  n R^2,     r_ee(k) = sum e(t) e(t-k) / sum e^2,
//! with R^2 = c^T C^+ c / sum (e - e_bar)^2 the share of the innovation that z explains (c =
//! sum e z, C = sum z z^T, both centred): the quadratic form n r^T R^-1 r of the cross
//! correlations with the lags' own correlation matrix, not the sum of their squares. A slow
//! input barely changes from one lag to the next, so its K lags (and x = a_1 u(t-1) of an
//! input backlash) are nearly one regressor: the sum of squares counts it 2K times, the
//! quadratic form once. C^+ keeps the directions of z whose variance is above `TOL` of the
//! variables' own mean square (pivoted elimination), and Q is about chi-square
//! with K + rank degrees of freedom (rank alone without the whiteness part) when the
//! structure is right. A window whose Q exceeds the caller's chi-square quantile for its
//! degrees fails; `confirm` consecutive failing windows set the "mismatch" verdict (one
//! failing window is also a start that has not settled yet), and it holds until `clear`
//! consecutive windows pass. While it holds the wear detector takes no readings: a wandering
//! estimate of a wrong structure is not wear.
//!
//! A wrong structure leaves a deterministic error, a function of the past input through the
//! plant's dynamics: coloured (so not white) and correlated with the past input or the
//! model's x, unless the tracker absorbs it within its forgetting window.

use super::shift_in;
use crate::error::{Error, Result};

/// The largest number of lags K a monitor takes.
pub const MAX_MONITOR_LAGS: usize = 16;
/// The largest degrees of freedom of Q: K whiteness lags and 2K cross-correlation lags.
pub const MAX_MONITOR_DEGREES: usize = 3 * MAX_MONITOR_LAGS;
/// Regressors z: u and x at lags 1..K.
const MAX_Z: usize = 2 * MAX_MONITOR_LAGS;
/// Entries of z z^T's upper triangle.
const MAX_ZZ: usize = MAX_Z * (MAX_Z + 1) / 2;
/// A direction of z whose variance, after the directions kept before it, is below this share
/// of its own (on the correlation scale) is a combination of them: not a degree of freedom.
const TOL: f64 = 1e-8;

/// The monitor's settings (module header).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorOptions {
    /// Samples per window (>= 10 K).
    pub window: u64,
    /// Lags K (1..=16).
    pub lags: usize,
    /// `thresholds[d - 1]`: the Q above which a window of d degrees of freedom says
    /// "mismatch" (> 0 for d = 1..=degrees()).
    pub thresholds: [f64; MAX_MONITOR_DEGREES],
    /// Consecutive failing windows that set the verdict (>= 1).
    pub confirm: u32,
    /// Consecutive passing windows that clear the verdict (>= 1).
    pub clear: u32,
    /// Test the innovation's whiteness too (the prediction-error rule).
    pub whiteness: bool,
}

impl MonitorOptions {
    pub fn check(&self) -> Result<()> {
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
        let bad = self.thresholds[..self.degrees()]
            .iter()
            .find(|t| !(t.is_finite() && **t > 0.0));
        if let Some(t) = bad {
            return Err(Error::Data(format!(
                "monitor threshold = {t}: give finite thresholds > 0 for 1..{} degrees of \
                 freedom",
                self.degrees()
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

    /// The largest degrees of freedom of Q (every regressor independent).
    pub fn degrees(&self) -> usize {
        self.lags * if self.whiteness { 3 } else { 2 }
    }
}

/// One window's verdict: its last sample, Q, its degrees of freedom, and whether the mismatch
/// verdict holds after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub sample: u64,
    pub statistic: f64,
    pub degrees: usize,
    pub mismatch: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Monitor {
    pub options: MonitorOptions,
    /// e, u, x at lags 1..K (index 0 = lag 1).
    e_lag: [f64; MAX_MONITOR_LAGS],
    u_lag: [f64; MAX_MONITOR_LAGS],
    x_lag: [f64; MAX_MONITOR_LAGS],
    /// Lagged samples seen (up to K): a window's first products wait for the lags.
    filled: usize,
    /// The window's sums: n, sum e^2, sum e, per lag sum e e_k, and of z = [u lags, x lags]:
    /// sum z, sum e z, sum z z^T (upper triangle, row by row).
    n: f64,
    see: f64,
    se: f64,
    cee: [f64; MAX_MONITOR_LAGS],
    sz: [f64; MAX_Z],
    cez: [f64; MAX_Z],
    szz: [f64; MAX_ZZ],
    /// Consecutive failing windows; consecutive passing windows while the verdict holds.
    failed: u32,
    passed: u32,
    mismatch: bool,
}

/// Numbers `save` writes.
pub(crate) const fn monitor_saved(lags: usize) -> usize {
    let d = 2 * lags;
    4 * lags + 2 * d + d * (d + 1) / 2 + 8
}

impl Monitor {
    pub fn new(options: MonitorOptions) -> Result<Self> {
        options.check()?;
        Ok(Self {
            options,
            e_lag: [0.0; MAX_MONITOR_LAGS],
            u_lag: [0.0; MAX_MONITOR_LAGS],
            x_lag: [0.0; MAX_MONITOR_LAGS],
            filled: 0,
            n: 0.0,
            see: 0.0,
            se: 0.0,
            cee: [0.0; MAX_MONITOR_LAGS],
            sz: [0.0; MAX_Z],
            cez: [0.0; MAX_Z],
            szz: [0.0; MAX_ZZ],
            failed: 0,
            passed: 0,
            mismatch: false,
        })
    }

    /// Whether the mismatch verdict holds.
    pub fn mismatch(&self) -> bool {
        self.mismatch
    }

    /// Take sample `sample`'s innovation e(t), input u(t) and the model's x(t); at a window's
    /// end, its verdict. The lags roll on every sample.
    #[inline(always)]
    pub(crate) fn observe(&mut self, sample: u64, e: f64, u: f64, x: f64) -> Option<Window> {
        let k = self.options.lags;
        let mut out = None;
        if self.filled == k {
            let d = 2 * k;
            let mut z = [0.0; MAX_Z];
            z[..k].copy_from_slice(&self.u_lag[..k]);
            z[k..d].copy_from_slice(&self.x_lag[..k]);
            self.n += 1.0;
            self.see += e * e;
            self.se += e;
            for j in 0..k {
                self.cee[j] += e * self.e_lag[j];
            }
            let mut at = 0;
            for i in 0..d {
                self.sz[i] += z[i];
                self.cez[i] += e * z[i];
                let zi = z[i];
                for (s, zj) in self.szz[at..at + d - i].iter_mut().zip(&z[i..d]) {
                    *s += zi * zj;
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

    /// n R^2 of the innovation regressed on z (module header) and the rank of z's centred
    /// correlation matrix, by pivoted elimination: each step takes the direction with the most
    /// variance left, adds its share of the innovation and removes it from the others.
    #[allow(clippy::needless_range_loop)] // the symmetric matrix reads best by its indices
    fn cross(&self) -> (f64, usize) {
        let d = 2 * self.options.lags;
        let n = self.n;
        let vee = self.see - self.se * self.se / n;
        let mut c = [[0.0; MAX_Z]; MAX_Z];
        let mut g = [0.0; MAX_Z];
        let mut at = 0;
        for i in 0..d {
            for j in i..d {
                let v = self.szz[at] - self.sz[i] * self.sz[j] / n;
                c[i][j] = v;
                c[j][i] = v;
                at += 1;
            }
            g[i] = self.cez[i] - self.sz[i] * self.se / n;
        }
        // on the scale of each regressor's raw second moment (the precision of its centred
        // sums): a direction is judged by the share of it left, so a constant regressor (at
        // rest) or a combination of the others has none
        let mut scale = [0.0; MAX_Z];
        let mut left = [false; MAX_Z];
        at = 0;
        for i in 0..d {
            let raw = self.szz[at];
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
        let (mut explained, mut rank) = (0.0, 0);
        loop {
            let pivot = (0..d)
                .filter(|&i| left[i])
                .max_by(|&a, &b| c[a][a].total_cmp(&c[b][b]));
            let Some(p) = pivot else { break };
            let cpp = c[p][p];
            if cpp <= TOL || cpp.is_nan() {
                break;
            }
            left[p] = false;
            rank += 1;
            explained += g[p] * g[p] / cpp;
            for i in (0..d).filter(|&i| left[i]) {
                let f = c[i][p] / cpp;
                g[i] -= f * g[p];
                for j in (0..d).filter(|&j| left[j]) {
                    c[i][j] -= f * c[p][j];
                }
            }
        }
        if vee > 0.0 {
            (n * explained / vee, rank)
        } else {
            (0.0, rank)
        }
    }

    /// Q of the window (module header) and the verdict; the sums start again.
    fn close(&mut self, sample: u64) -> Window {
        let k = self.options.lags;
        let n = self.n;
        let (mut q, mut degrees) = self.cross();
        if self.options.whiteness {
            degrees += k;
            if self.see > 0.0 {
                q += n * self.cee[..k]
                    .iter()
                    .map(|c| (c / self.see).powi(2))
                    .sum::<f64>();
            }
        }
        let fails = match degrees {
            0 => false,
            d => q > self.options.thresholds[d - 1] || !q.is_finite(),
        };
        if fails {
            self.failed += 1;
            self.passed = 0;
            if self.failed >= self.options.confirm {
                self.mismatch = true;
            }
        } else {
            self.failed = 0;
            if self.mismatch {
                self.passed += 1;
                if self.passed >= self.options.clear {
                    self.mismatch = false;
                    self.passed = 0;
                }
            }
        }
        self.n = 0.0;
        self.see = 0.0;
        self.se = 0.0;
        self.cee = [0.0; MAX_MONITOR_LAGS];
        self.sz = [0.0; MAX_Z];
        self.cez = [0.0; MAX_Z];
        self.szz = [0.0; MAX_ZZ];
        Window {
            sample,
            statistic: q,
            degrees,
            mismatch: self.mismatch,
        }
    }

    pub(crate) fn save(&self, out: &mut Vec<f64>) {
        let k = self.options.lags;
        let d = 2 * k;
        for a in [&self.e_lag, &self.u_lag, &self.x_lag, &self.cee] {
            out.extend_from_slice(&a[..k]);
        }
        out.extend_from_slice(&self.sz[..d]);
        out.extend_from_slice(&self.cez[..d]);
        out.extend_from_slice(&self.szz[..d * (d + 1) / 2]);
        out.extend([
            self.filled as f64,
            self.n,
            self.see,
            self.se,
            f64::from(self.failed),
            f64::from(self.passed),
            f64::from(u8::from(self.mismatch)),
            0.0,
        ]);
    }

    pub(crate) fn load(&mut self, s: &[f64]) {
        let k = self.options.lags;
        let d = 2 * k;
        let mut it = s.iter().copied();
        let mut take = |dst: &mut [f64]| dst.iter_mut().for_each(|v| *v = it.next().unwrap_or(0.0));
        take(&mut self.e_lag[..k]);
        take(&mut self.u_lag[..k]);
        take(&mut self.x_lag[..k]);
        take(&mut self.cee[..k]);
        take(&mut self.sz[..d]);
        take(&mut self.cez[..d]);
        take(&mut self.szz[..d * (d + 1) / 2]);
        let mut rest = [0.0; 8];
        take(&mut rest);
        self.filled = rest[0] as usize;
        self.n = rest[1];
        self.see = rest[2];
        self.se = rest[3];
        self.failed = rest[4] as u32;
        self.passed = rest[5] as u32;
        self.mismatch = rest[6] != 0.0;
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

    /// Q of every window over white innovations independent of u and x.
    fn statistics(slow: bool, seed: u64) -> Vec<(f64, usize)> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut m = Monitor::new(options()).unwrap();
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
            if let Some(w) = m.observe(t, gauss(&mut rng), u, x) {
                out.push((w.statistic, w.degrees));
            }
            prev_u = u;
        }
        out
    }

    /// Under the right structure Q is chi-square with K + rank(z) degrees of freedom: its mean
    /// is the degrees, its variance twice the degrees, for a white input and for a slow one
    /// whose lags are nearly one regressor (there the sum of the 15 squared correlations, the
    /// form before 2026-11-29, has a mean of 13.5 and a variance of 155, five times chi-square's).
    #[test]
    fn white_innovations_give_chi_square_with_the_rank_s_degrees() {
        // x's lags span u(t-1..K+1) in both (x = 0.5 u + 0.3 u(t-1); x = a_1 u(t-1)): rank 6
        // of the 10 columns, 11 degrees
        for (slow, degrees) in [(false, 11), (true, 11)] {
            let qs = statistics(slow, 1);
            let other: Vec<_> = qs.iter().filter(|q| q.1 != degrees).take(3).collect();
            assert!(other.is_empty(), "slow {slow}: {other:?}");
            let n = qs.len() as f64;
            let mean = qs.iter().map(|q| q.0).sum::<f64>() / n;
            let var = qs.iter().map(|q| (q.0 - mean).powi(2)).sum::<f64>() / (n - 1.0);
            let k = degrees as f64;
            assert!(
                (mean / k - 1.0).abs() < 0.1 && (var / (2.0 * k) - 1.0).abs() < 0.3,
                "slow {slow}: mean {mean}, variance {var}, degrees {k}"
            );
        }
    }

    /// Innovations that carry a past input fail at once and the verdict clears after `clear`
    /// passing windows; a window at rest (no variance in u or x) tests the whiteness alone.
    #[test]
    fn a_leftover_of_the_input_fails_and_clears() {
        let mut rng = StdRng::seed_from_u64(2);
        let mut m = Monitor::new(options()).unwrap();
        let (mut verdicts, mut prev_u) = (vec![], 0.0);
        for t in 0..10_000u64 {
            let u = rng.random_range(-1.0..1.0);
            let leftover = if t < 4000 { 0.2 * prev_u } else { 0.0 };
            if let Some(w) = m.observe(t, gauss(&mut rng) * 0.1 + leftover, u, u) {
                verdicts.push(w.mismatch);
                assert_eq!(w.degrees, 10, "{w:?}");
            }
            prev_u = u;
        }
        assert_eq!(verdicts, [true, true, true, false]);
        let mut m = Monitor::new(options()).unwrap();
        let w = (0..2005u64)
            .find_map(|t| m.observe(t, gauss(&mut rng), 0.3, 0.3))
            .unwrap();
        assert_eq!(w.degrees, 5, "{w:?}");
        assert!(w.statistic < 50.0 && !w.mismatch, "{w:?}");
    }

    /// A saved monitor restored mid-window closes that window as the original does.
    #[test]
    fn a_saved_monitor_continues_where_it_stopped() {
        let mut rng = StdRng::seed_from_u64(3);
        let mut a = Monitor::new(options()).unwrap();
        let data: Vec<[f64; 3]> = (0..4000)
            .map(|_| [gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)])
            .collect();
        for (t, s) in data[..1234].iter().enumerate() {
            a.observe(t as u64, s[0], s[1], s[2]);
        }
        let mut saved = vec![];
        a.save(&mut saved);
        assert_eq!(saved.len(), monitor_saved(5));
        let mut b = Monitor::new(options()).unwrap();
        b.load(&saved);
        assert_eq!(a, b);
        for (t, s) in data.iter().enumerate().skip(1234) {
            let t = t as u64;
            assert_eq!(
                a.observe(t, s[0], s[1], s[2]),
                b.observe(t, s[0], s[1], s[2])
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
            assert!(Monitor::new(bad).is_err(), "{bad:?}");
        }
    }
}
