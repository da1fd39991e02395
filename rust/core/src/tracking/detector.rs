//! Wear detection on the tracked dead-band width w = c_L + c_R: a two-sided CUSUM on the
//! standardised deviations of the width from a reference, read every `spacing` samples.
//!
//! Why not a CUSUM on every sample: the tracked estimate is an exponentially weighted
//! average over about 1 / (1 - lambda) samples, so consecutive estimates are almost equal and
//! a CUSUM of them is far from i.i.d. (its false-alarm rate would depend on the forgetting
//! window, not on the threshold). Estimates `spacing` >= 3 / (1 - lambda) samples apart
//! share at most exp(-3) = 5 % of their weight: read there, the standardised deviations
//!     z_k = (w_k - w_ref) / sqrt(var(w_k) + var(w_ref))
//! are close to i.i.d. N(0, 1) for a constant system, and the classical CUSUM
//!     S+_k = max(0, S+_{k-1} + z_k - slack),   S-_k = max(0, S-_{k-1} - z_k - slack),
//! alarms when S+ or S- exceeds `threshold`. The reference w_ref is the mean of the first
//! `reference` readings after (re)arming (its variance the mean variance / `reference`);
//! after an alarm the detector waits `holdoff` readings (the tracker settles on the new
//! width) and arms again. Its average run length under no change is a property of (slack,
//! threshold) for N(0, 1) readings (Siegmund's approximation, two-sided: about 170 readings
//! for slack 0.5, threshold 4; about 1e9 for the defaults slack 1, threshold 10). The tracked
//! readings are close to N(0, 1) but not exactly (Example 1: about twice the alarms of N(0, 1)
//! readings at slack 0.5, threshold 4), hence the defaults' wide margin; `benches/tracking.py`
//! counts the false alarms on 1e8 samples of Example 1 (1 in 33333 readings).

use crate::error::{Error, Result};

/// The detector's settings (`Detector` documents them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorOptions {
    /// Samples between two readings of the tracked width (>= 1).
    pub spacing: u64,
    /// Readings averaged into the reference width after (re)arming (>= 1).
    pub reference: u32,
    /// CUSUM slack (allowance) in standard deviations, >= 0.
    pub slack: f64,
    /// CUSUM threshold in standard deviations, > 0.
    pub threshold: f64,
    /// Readings skipped after an alarm before the reference is collected again.
    pub holdoff: u32,
}

impl DetectorOptions {
    /// The defaults for a tracker forgetting with `lambda` (spacing 3 / (1 - lambda), or
    /// 30000 samples without forgetting), reference 8, slack 1, threshold 10, holdoff 2.
    pub fn for_forgetting(lambda: f64) -> Self {
        let spacing = if lambda < 1.0 {
            (3.0 / (1.0 - lambda)).ceil().max(1.0) as u64
        } else {
            30_000
        };
        Self {
            spacing,
            reference: 8,
            slack: 1.0,
            threshold: 10.0,
            holdoff: 2,
        }
    }

    pub fn check(&self) -> Result<()> {
        if self.spacing == 0 || self.reference == 0 {
            return Err(Error::Data(
                "the detector's spacing and reference must be whole numbers >= 1".into(),
            ));
        }
        if !(self.slack.is_finite() && self.slack >= 0.0) {
            return Err(Error::Data(format!(
                "detector slack = {}: give a finite number >= 0",
                self.slack
            )));
        }
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err(Error::Data(format!(
                "detector threshold = {}: give a finite number > 0",
                self.threshold
            )));
        }
        Ok(())
    }
}

/// One alarm: the sample it fired at (counted from the tracker's first sample), +1 for a
/// widening dead band, -1 for a narrowing one, the width read then, the reference and the
/// CUSUM statistic that crossed the threshold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alarm {
    pub sample: u64,
    pub direction: i8,
    pub width: f64,
    pub reference: f64,
    pub statistic: f64,
}

/// The two-sided CUSUM of the module header; its state is a handful of numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Detector {
    pub options: DetectorOptions,
    /// Readings still skipped before collecting the reference.
    wait: u32,
    /// Readings in the reference so far, their sum and their variances' sum.
    collected: u32,
    sum: f64,
    var_sum: f64,
    /// The reference width and its variance (valid once `collected` == options.reference).
    reference: f64,
    reference_var: f64,
    pos: f64,
    neg: f64,
}

/// Numbers in `Detector::save` (the options are not saved).
pub(crate) const DETECTOR_SAVED: usize = 8;

impl Detector {
    pub fn new(options: DetectorOptions) -> Result<Self> {
        options.check()?;
        Ok(Self {
            options,
            wait: 0,
            collected: 0,
            sum: 0.0,
            var_sum: 0.0,
            reference: f64::NAN,
            reference_var: f64::NAN,
            pos: 0.0,
            neg: 0.0,
        })
    }

    /// True when a reference is set and the CUSUM runs.
    pub fn armed(&self) -> bool {
        self.collected == self.options.reference
    }

    /// The CUSUM statistics (S+, S-).
    pub fn statistics(&self) -> (f64, f64) {
        (self.pos, self.neg)
    }

    /// One reading of the width and its variance at `sample`; an alarm if the CUSUM crossed.
    pub fn observe(&mut self, sample: u64, width: f64, var: f64) -> Option<Alarm> {
        if !(width.is_finite() && var.is_finite() && var > 0.0) {
            return None; // no usable reading (an estimate without a covariance yet)
        }
        if self.wait > 0 {
            self.wait -= 1;
            return None;
        }
        if !self.armed() {
            self.collected += 1;
            self.sum += width;
            self.var_sum += var;
            if self.armed() {
                let m = f64::from(self.options.reference);
                self.reference = self.sum / m;
                self.reference_var = self.var_sum / (m * m);
            }
            return None;
        }
        let z = (width - self.reference) / (var + self.reference_var).sqrt();
        self.pos = (self.pos + z - self.options.slack).max(0.0);
        self.neg = (self.neg - z - self.options.slack).max(0.0);
        let (direction, statistic) = if self.pos > self.options.threshold {
            (1, self.pos)
        } else if self.neg > self.options.threshold {
            (-1, self.neg)
        } else {
            return None;
        };
        let alarm = Alarm {
            sample,
            direction,
            width,
            reference: self.reference,
            statistic,
        };
        self.rearm();
        Some(alarm)
    }

    /// Forget the reference and the statistics; wait `holdoff` readings, then collect anew.
    pub fn rearm(&mut self) {
        *self = Self {
            wait: self.options.holdoff,
            ..Self::new(self.options).expect("checked options")
        };
    }

    pub(crate) fn save(&self, out: &mut Vec<f64>) {
        out.extend([
            f64::from(self.wait),
            f64::from(self.collected),
            self.sum,
            self.var_sum,
            self.reference,
            self.reference_var,
            self.pos,
            self.neg,
        ]);
    }

    pub(crate) fn load(&mut self, s: &[f64]) {
        self.wait = s[0] as u32;
        self.collected = s[1] as u32;
        (self.sum, self.var_sum) = (s[2], s[3]);
        (self.reference, self.reference_var) = (s[4], s[5]);
        (self.pos, self.neg) = (s[6], s[7]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn normal(rng: &mut StdRng) -> f64 {
        // Box-Muller
        let (a, b): (f64, f64) = (rng.random_range(1e-300..1.0), rng.random());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }

    fn options(slack: f64, threshold: f64) -> DetectorOptions {
        DetectorOptions {
            spacing: 1,
            reference: 8,
            slack,
            threshold,
            holdoff: 2,
        }
    }

    /// Readings N(1, 0.01^2): the run length of a low threshold is near Siegmund's value,
    /// and the defaults raise nothing in 2e5 readings.
    #[test]
    fn false_alarms_follow_the_threshold() {
        let mut rng = StdRng::seed_from_u64(7);
        let mut low = Detector::new(options(0.5, 3.0)).unwrap();
        let mut high = Detector::new(DetectorOptions {
            spacing: 1,
            ..DetectorOptions::for_forgetting(0.9)
        })
        .unwrap();
        let (mut n_low, mut n_high) = (0, 0);
        let readings = 200_000;
        for k in 0..readings {
            let w = 1.0 + 0.01 * normal(&mut rng);
            n_low += usize::from(low.observe(k, w, 1e-4).is_some());
            n_high += usize::from(high.observe(k, w, 1e-4).is_some());
        }
        assert_eq!(n_high, 0);
        // two-sided ARL of (0.5, 3) for N(0,1) is about 60 readings (each side ~120), plus
        // 10 readings of re-arming: between 1000 and 6000 alarms in 2e5 readings
        assert!((1000..6000).contains(&n_low), "{n_low}");
    }

    #[test]
    fn a_step_fires_with_its_direction() {
        let mut rng = StdRng::seed_from_u64(8);
        let mut d = Detector::new(DetectorOptions {
            spacing: 1,
            ..DetectorOptions::for_forgetting(0.9)
        })
        .unwrap();
        let mut fired = None;
        for k in 0..100u64 {
            let w = if k < 50 { 1.0 } else { 1.2 } + 0.01 * normal(&mut rng);
            if let Some(a) = d.observe(k, w, 1e-4) {
                fired = Some(a);
                break;
            }
        }
        let a = fired.expect("the step is 20 standard deviations");
        assert_eq!((a.sample, a.direction), (50, 1), "{a:?}");
        assert!((a.reference - 1.0).abs() < 0.02 && (a.width - 1.2).abs() < 0.05);
        assert!(!d.armed());
        let mut down = Detector::new(options(1.0, 10.0)).unwrap();
        let fired = (0..40u64).find_map(|k| down.observe(k, if k < 20 { 1.0 } else { 0.8 }, 1e-4));
        assert_eq!(fired.map(|a| (a.sample, a.direction)), Some((20, -1)));
        assert!(down.observe(0, f64::NAN, 1.0).is_none());
        assert!(Detector::new(options(-1.0, 1.0)).is_err());
        assert!(Detector::new(options(1.0, 0.0)).is_err());
    }
}
