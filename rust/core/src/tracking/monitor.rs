//! The model-mismatch monitor (issue 33): does the tracked structure explain the data? Over
//! consecutive windows of `window` samples it tests the tracker's own innovations e(t) (the
//! prediction error of each update) against what the right structure leaves: an innovation
//! uncorrelated with its own past (whiteness; prediction-error rule only: the regression's
//! equation error of a sandwich is coloured by its output block even for the right model),
//! with the past input u(t-k) and with the model's past internal signal x(t-k), k = 1..K.
//! It takes the samples that update the estimate (a held sample of the cascade's regression
//! has no innovation: it is skipped, and the lags are those of the updating samples).
//!
//! With the sample correlations over the window (means of u and x removed)
//!     r_ee(k) = sum e(t) e(t-k) / sum e^2,
//!     r_eu(k) = sum e(t) (u(t-k) - u_bar) / sqrt(sum e^2 sum (u - u_bar)^2),  r_ex(k) alike,
//! the portmanteau statistic Q = n sum_k (r_ee(k)^2 + r_eu(k)^2 + r_ex(k)^2) is about
//! chi-square with 3K degrees of freedom (2K without whiteness) when the structure is right
//! (Box-Pierce; Ljung, System Identification, 16.6). A window whose Q exceeds `threshold`
//! (the caller's chi-square quantile) fails; `confirm` consecutive failing windows set the
//! "mismatch" verdict (one failing window is also a start that has not settled yet), and it
//! holds until `clear` consecutive windows pass. While it holds the wear detector takes no readings: a wandering
//! estimate of a wrong structure is not wear.
//!
//! A wrong structure leaves a deterministic error, a function of the past input through the
//! plant's dynamics: coloured (so not white) and correlated with the past input or the
//! model's x, unless the tracker absorbs it within its forgetting window.

use super::shift_in;
use crate::error::{Error, Result};

/// The largest number of lags K a monitor takes.
pub const MAX_MONITOR_LAGS: usize = 16;

/// The monitor's settings (module header).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorOptions {
    /// Samples per window (>= 10 K).
    pub window: u64,
    /// Lags K (1..=16).
    pub lags: usize,
    /// Q above which a window says "mismatch" (> 0).
    pub threshold: f64,
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
        if !(self.threshold.is_finite() && self.threshold > 0.0)
            || self.clear == 0
            || self.confirm == 0
        {
            return Err(Error::Data(format!(
                "monitor threshold = {}, confirm = {}, clear = {}: give a finite threshold > 0 \
                 and confirm, clear >= 1",
                self.threshold, self.confirm, self.clear
            )));
        }
        Ok(())
    }

    /// Degrees of freedom of Q under the right structure.
    pub fn degrees(&self) -> usize {
        self.lags * if self.whiteness { 3 } else { 2 }
    }
}

/// One window's verdict: its last sample, Q, and whether the mismatch verdict holds after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub sample: u64,
    pub statistic: f64,
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
    /// The window's sums: n, sum e^2, sum e, sum u, sum u^2, sum x, sum x^2 (lag 1's), and per
    /// lag sum e e_k, sum e u_k, sum e x_k.
    n: f64,
    see: f64,
    se: f64,
    su: f64,
    suu: f64,
    sx: f64,
    sxx: f64,
    cee: [f64; MAX_MONITOR_LAGS],
    ceu: [f64; MAX_MONITOR_LAGS],
    cex: [f64; MAX_MONITOR_LAGS],
    /// Consecutive failing windows; consecutive passing windows while the verdict holds.
    failed: u32,
    passed: u32,
    mismatch: bool,
}

/// Numbers `save` writes.
pub(crate) const fn monitor_saved(lags: usize) -> usize {
    6 * lags + 12
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
            su: 0.0,
            suu: 0.0,
            sx: 0.0,
            sxx: 0.0,
            cee: [0.0; MAX_MONITOR_LAGS],
            ceu: [0.0; MAX_MONITOR_LAGS],
            cex: [0.0; MAX_MONITOR_LAGS],
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
            let u1 = self.u_lag[0];
            let x1 = self.x_lag[0];
            self.n += 1.0;
            self.see += e * e;
            self.se += e;
            self.su += u1;
            self.suu += u1 * u1;
            self.sx += x1;
            self.sxx += x1 * x1;
            for j in 0..k {
                self.cee[j] += e * self.e_lag[j];
                self.ceu[j] += e * self.u_lag[j];
                self.cex[j] += e * self.x_lag[j];
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

    /// Q of the window (module header) and the verdict; the sums start again.
    fn close(&mut self, sample: u64) -> Window {
        let k = self.options.lags;
        let n = self.n;
        // centred: sum e (u_k - u_bar) = sum e u_k - u_bar sum e (u_bar of lag 1: the lags'
        // means differ by at most K samples' worth)
        let (ub, xb) = (self.su / n, self.sx / n);
        let vuu = (self.suu - n * ub * ub).max(0.0);
        let vxx = (self.sxx - n * xb * xb).max(0.0);
        let mut q = 0.0;
        if self.see > 0.0 {
            for j in 0..k {
                if self.options.whiteness {
                    let r = self.cee[j] / self.see;
                    q += r * r;
                }
                if vuu > 0.0 {
                    let r = (self.ceu[j] - ub * self.se) / (self.see * vuu).sqrt();
                    q += r * r;
                }
                if vxx > 0.0 {
                    let r = (self.cex[j] - xb * self.se) / (self.see * vxx).sqrt();
                    q += r * r;
                }
            }
        }
        let q = n * q;
        if q > self.options.threshold || !q.is_finite() {
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
        self.su = 0.0;
        self.suu = 0.0;
        self.sx = 0.0;
        self.sxx = 0.0;
        self.cee = [0.0; MAX_MONITOR_LAGS];
        self.ceu = [0.0; MAX_MONITOR_LAGS];
        self.cex = [0.0; MAX_MONITOR_LAGS];
        Window {
            sample,
            statistic: q,
            mismatch: self.mismatch,
        }
    }

    pub(crate) fn save(&self, out: &mut Vec<f64>) {
        let k = self.options.lags;
        for a in [
            &self.e_lag,
            &self.u_lag,
            &self.x_lag,
            &self.cee,
            &self.ceu,
            &self.cex,
        ] {
            out.extend_from_slice(&a[..k]);
        }
        out.extend([
            self.filled as f64,
            self.n,
            self.see,
            self.se,
            self.su,
            self.suu,
            self.sx,
            self.sxx,
            f64::from(self.failed),
            f64::from(self.passed),
            f64::from(u8::from(self.mismatch)),
            0.0,
        ]);
    }

    pub(crate) fn load(&mut self, s: &[f64]) {
        let k = self.options.lags;
        let mut it = s.iter().copied();
        for a in [
            &mut self.e_lag,
            &mut self.u_lag,
            &mut self.x_lag,
            &mut self.cee,
            &mut self.ceu,
            &mut self.cex,
        ] {
            a[..k]
                .iter_mut()
                .for_each(|v| *v = it.next().unwrap_or(0.0));
        }
        let mut next = || it.next().unwrap_or(0.0);
        self.filled = next() as usize;
        self.n = next();
        self.see = next();
        self.se = next();
        self.su = next();
        self.suu = next();
        self.sx = next();
        self.sxx = next();
        self.failed = next() as u32;
        self.passed = next() as u32;
        self.mismatch = next() != 0.0;
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
            threshold: 50.0,
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

    /// White innovations independent of u and x: Q has the chi-square(15) mean (15) and
    /// passes; innovations that carry a past input fail at once and the verdict clears after
    /// `clear` passing windows.
    #[test]
    fn white_innovations_pass_and_a_leftover_of_the_input_fails() {
        let mut rng = StdRng::seed_from_u64(1);
        let mut m = Monitor::new(options()).unwrap();
        let mut qs = vec![];
        let mut prev_u = 0.0;
        for t in 0..400_000u64 {
            let u = rng.random_range(-1.0..1.0);
            let x = 0.5 * u + 0.3 * prev_u;
            if let Some(w) = m.observe(t, gauss(&mut rng), u, x) {
                assert!(!w.mismatch, "{w:?}");
                qs.push(w.statistic);
            }
            prev_u = u;
        }
        let mean = qs.iter().sum::<f64>() / qs.len() as f64;
        assert!((mean / 15.0 - 1.0).abs() < 0.15, "{mean}");
        let mut m = Monitor::new(options()).unwrap();
        let mut verdicts = vec![];
        for t in 0..10_000u64 {
            let u = rng.random_range(-1.0..1.0);
            let leftover = if t < 4000 { 0.2 * prev_u } else { 0.0 };
            if let Some(w) = m.observe(t, gauss(&mut rng) * 0.1 + leftover, u, u) {
                verdicts.push(w.mismatch);
            }
            prev_u = u;
        }
        assert_eq!(verdicts, [true, true, true, false]);
    }

    #[test]
    fn bad_options_are_refused() {
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
                threshold: 0.0,
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
