//! The inverse of the general backlash (eq 1): for a desired output y_d(t), the internal
//! signal x(t) that makes the backlash produce it (Tao & Kokotovic's backlash inverse,
//! generalised to the polynomial branches of eq 4-5).
//!
//! Algorithm (a port must reproduce it to 1e-12). State: y_prev (the backlash memory, what
//! the plant's backlash holds), x_prev, direction in {-1, 0, +1} (0: none yet) and the
//! extremum of the targets reached in that direction; start: direction 0, extremum y(0).
//! Per sample with target y_d (finite):
//!
//! 1. Smoothing gate, threshold >= 0. against = extremum - y_d if direction = +1,
//!    y_d - extremum if -1, else 0. If 0 < against <= threshold the target becomes y_prev
//!    (hold). Then: if against > threshold, reverse (direction := -direction, extremum :=
//!    y_d); else if direction = 0 and y_d != y_prev, direction := sign(y_d - y_prev),
//!    extremum := y_d; else if against < 0 (y_d beyond the extremum), extremum := y_d.
//!    With threshold 0 the target is never replaced: the exact inverse.
//! 2. target > y_prev: x = R^{-1}(target); target < y_prev: x = L^{-1}(target);
//!    target == y_prev: x = x_prev clamped to [L^{-1}(y_prev), R^{-1}(y_prev)] (the dead band
//!    at that level: the input moves only if it must).
//! 3. The memory: with (y, case) = eq 1's step from y_prev (`GeneralBacklash::step`, case
//!    f1 for L, f2 for R), y_prev := target if the step took the branch chosen in 2 (R for
//!    a rising target, L for a falling one), y_prev := y if it took another case (branches
//!    that cross: the plant's backlash goes there); a hold leaves y_prev. x_prev := x.
//!    (Not y_prev := y always: B(B^{-1}(level)) is the level only to a few ulps, and a
//!    constant target would then read those ulps as reversals and jump across the band.)
//!
//! Root of a branch B(x) = p(xi) = sum_{i>=1} m_i xi^i = level (xi = x + shift, shift = c_L
//! for L and -c_R for R; B and B' evaluated by Horner's rule in xi, `Branch::value` and
//! `Branch::slope`), searched from s = x_prev (the x_prev of the sample, also for both roots
//! of a hold); ulp(v) is the gap from abs(v) to the next float up (the least normal for 0):
//!
//! - degree 1 (one coefficient): xi = level / m_1 (unreachable if not finite), x = xi - shift.
//! - else f(x) = B(x) - level. f(s) not finite: unreachable; f(s) = 0: x = s. Direction
//!   d = +1 if f(s) < 0 else -1; h = 1e-3 (1 + abs(s)). Bracket: a = s; repeat b = a + d h;
//!   unreachable (Error::Data) if f(b) is not finite or abs(b + shift) > 1e12 (1 + abs(s));
//!   f(b) = 0: x = b; stop if (f(b) < 0) != (f(a) < 0); else a = b, h = 2 h.
//! - Newton safeguarded by bisection (rtsafe) on [lo, hi] = the bracket oriented so that
//!   f(lo) < 0 < f(hi) (lo > hi is allowed), from x = the end of smaller abs(f) (a on a
//!   tie), with both previous step sizes set to abs(b - a). Per iteration (at most 2200,
//!   then x): if abs(hi - lo) <= 4 ulp(max(abs(lo), abs(hi))), x = (lo + hi) / 2, done;
//!   f(x) = 0: done; f(x) < 0 sets lo = x, else hi = x; the Newton point n = x - f(x) / B'(x)
//!   is the next x if finite, strictly between lo and hi and abs(n - x) <= half the step
//!   size before the last, else (lo + hi) / 2 is; if that step's size abs(next - x) <=
//!   ulp(next), x = next, done.
//! - The hold's clamp: x = max(L^{-1}(y_prev), min(x_prev, R^{-1}(y_prev))).
//!
//! Continuity (the bracket grows from x_prev) picks the root on the increasing part that the
//! motion is on, where identified branches turn outside the data's range.

use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::{check_memory, Branch, GeneralBacklash, Step};
use crate::model::signal::check_signal;

/// The per-sample backlash inverse: `step` returns x(t) for the target y_d(t).
#[derive(Debug, Clone, PartialEq)]
pub struct BacklashInverse {
    /// The backlash memory y(t-1): the last target reached (eq 1's value where it left the intended branch).
    pub y_prev: f64,
    /// x(t-1), the last x returned (x(0) before the first sample).
    pub x_prev: f64,
    /// -1 (falling), +1 (rising) or 0 (not moved yet): the direction of the smoothing gate.
    pub direction: i8,
    /// The extremum of the targets reached in `direction`.
    pub extremum: f64,
    /// Smoothing threshold >= 0 (0: the exact inverse).
    pub threshold: f64,
    /// Samples stepped so far (for the error messages).
    pub samples: u64,
}

/// Which branch a root is asked of (for messages).
#[derive(Clone, Copy)]
enum Side {
    Left,
    Right,
}

impl Side {
    fn name(self) -> &'static str {
        match self {
            Side::Left => "L",
            Side::Right => "R",
        }
    }
}

impl BacklashInverse {
    /// Start from the backlash memory y(0) = `y0` and x(0) = `x0`; `threshold` >= 0.
    pub fn new(y0: f64, x0: f64, threshold: f64) -> Result<Self> {
        check_memory(y0)?;
        if !x0.is_finite() {
            return Err(Error::Data(format!(
                "initial x0 = {x0}: give a finite value (e.g. 0 for a backlash at rest)"
            )));
        }
        if !(threshold.is_finite() && threshold >= 0.0) {
            return Err(Error::Data(format!(
                "threshold = {threshold}: give a finite value >= 0 (0: the exact inverse)"
            )));
        }
        Ok(BacklashInverse {
            y_prev: y0,
            x_prev: x0,
            direction: 0,
            extremum: y0,
            threshold,
            samples: 0,
        })
    }

    /// x(t) for the target y_d(t) (the module's algorithm), and the state moved on by it.
    pub fn step(&mut self, backlash: &GeneralBacklash, y_d: f64) -> Result<f64> {
        let t = self.samples;
        if !y_d.is_finite() {
            return Err(Error::Data(format!(
                "y_desired[{t}] is {y_d}: give a finite target"
            )));
        }
        let target = self.gate(y_d);
        // the case of eq 1 the root is for: f2 (R) rising, f1 (L) falling, none on a hold
        let (x, intended) = if target > self.y_prev {
            (self.root(backlash, Side::Right, target)?, 2)
        } else if target < self.y_prev {
            (self.root(backlash, Side::Left, target)?, 1)
        } else {
            let lo = self.root(backlash, Side::Left, self.y_prev)?;
            let hi = self.root(backlash, Side::Right, self.y_prev)?;
            // lo <= hi for branches that do not cross; otherwise the clamp keeps lo
            (self.x_prev.min(hi).max(lo), 0)
        };
        if intended != 0 {
            let (y, case) = backlash.step_case(x, self.y_prev);
            self.y_prev = if case == intended { target } else { y };
        }
        self.x_prev = x;
        self.samples += 1;
        Ok(x)
    }

    /// Step 1 of the algorithm: the target after the smoothing gate, with the direction and
    /// extremum moved on.
    fn gate(&mut self, y_d: f64) -> f64 {
        let against = match self.direction {
            1 => self.extremum - y_d,
            -1 => y_d - self.extremum,
            _ => 0.0,
        };
        let target = if against > 0.0 && against <= self.threshold {
            self.y_prev
        } else {
            y_d
        };
        if against > self.threshold {
            self.direction = -self.direction;
            self.extremum = y_d;
        } else if self.direction == 0 && y_d != self.y_prev {
            self.direction = if y_d > self.y_prev { 1 } else { -1 };
            self.extremum = y_d;
        } else if against < 0.0 {
            self.extremum = y_d;
        }
        target
    }

    fn root(&self, backlash: &GeneralBacklash, side: Side, level: f64) -> Result<f64> {
        let (branch, shift) = match side {
            Side::Left => (backlash.left(), backlash.c_left()),
            Side::Right => (backlash.right(), -backlash.c_right()),
        };
        branch_root(branch, shift, level, self.x_prev).ok_or_else(|| {
            Error::Data(format!(
                "y_desired[{}]: the branch {} cannot reach the level {level:e} from x = {:e} \
                 (it turns or overflows before); keep the reference inside the range the \
                 model's branches increase on",
                self.samples,
                side.name(),
                self.x_prev
            ))
        })
    }
}

impl GeneralBacklash {
    /// x such that this backlash, from memory `y0`, outputs `y_desired` (the inverse of
    /// eq 1, `BacklashInverse`), starting from x(0) = `x0`, with the smoothing `threshold`.
    pub fn inverse(&self, y_desired: &[f64], y0: f64, x0: f64, threshold: f64) -> Result<Vec<f64>> {
        check_signal("y_desired", y_desired)?;
        let mut inv = BacklashInverse::new(y0, x0, threshold)?;
        let mut x = guard::buffer(y_desired.len(), "x")?;
        for chunk in y_desired.chunks(guard::CHUNK) {
            guard::check()?;
            for &y_d in chunk {
                x.push(inv.step(self, y_d)?);
            }
        }
        Ok(x)
    }
}

/// One ulp of `v` (the gap to the next float away from zero).
fn ulp(v: f64) -> f64 {
    let a = v.abs();
    if a == 0.0 {
        f64::MIN_POSITIVE
    } else {
        f64::from_bits(a.to_bits() + 1) - a
    }
}

/// The x with `branch(x) = level` found from `start` (the module's root search); None when
/// the branch cannot reach `level`.
pub(crate) fn branch_root(branch: &Branch, shift: f64, level: f64, start: f64) -> Option<f64> {
    let m = branch.coefficients();
    if m.len() == 1 {
        let xi = level / m[0];
        let x = xi - shift;
        return x.is_finite().then_some(x);
    }
    let f = |x: f64| branch.value(x) - level;
    let limit = 1e12 * (1.0 + start.abs());
    let (mut a, mut fa) = (start, f(start));
    if !fa.is_finite() {
        return None;
    }
    if fa == 0.0 {
        return Some(start);
    }
    let d = if fa < 0.0 { 1.0 } else { -1.0 };
    let mut h = 1e-3 * (1.0 + start.abs());
    let (b, fb) = loop {
        let b = a + d * h;
        let fb = f(b);
        if !fb.is_finite() || (b + shift).abs() > limit {
            return None;
        }
        if fb == 0.0 {
            return Some(b);
        }
        if (fb < 0.0) != (fa < 0.0) {
            break (b, fb);
        }
        a = b;
        fa = fb;
        h *= 2.0;
    };
    let mut x = if fb.abs() < fa.abs() { b } else { a };
    let (mut lo, mut hi) = if fa < 0.0 { (a, b) } else { (b, a) };
    let (mut step_old, mut step) = ((hi - lo).abs(), (hi - lo).abs());
    for _ in 0..2200 {
        if (hi - lo).abs() <= 4.0 * ulp(lo.abs().max(hi.abs())) {
            return Some(0.5 * (lo + hi));
        }
        let fx = f(x);
        if fx == 0.0 {
            return Some(x);
        }
        if fx < 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let newton = x - fx / branch.slope(x);
        let (l, u) = (lo.min(hi), lo.max(hi));
        let next = if newton.is_finite()
            && newton > l
            && newton < u
            && (newton - x).abs() <= 0.5 * step_old
        {
            newton
        } else {
            0.5 * (lo + hi)
        };
        step_old = step;
        step = (next - x).abs();
        x = next;
        if step <= ulp(x) {
            return Some(x);
        }
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_params::{example1_backlash, example2_backlash, lcg_unit, quintic_backlash};

    /// backlash.simulate(inverse(y_d)) against y_d, relative error per sample.
    fn worst_error(bl: &GeneralBacklash, y_d: &[f64], threshold: f64) -> f64 {
        let x = bl.inverse(y_d, 0.0, 0.0, threshold).unwrap();
        let y = bl.simulate(&x, 0.0).unwrap();
        y.iter()
            .zip(y_d)
            .map(|(a, b)| (a - b).abs() / (1.0 + b.abs()))
            .fold(0.0, f64::max)
    }

    fn smooth(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64;
                1.2 * (0.021 * t).sin() + 0.4 * (0.067 * t + 0.3).sin()
            })
            .collect()
    }

    fn rough(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n).map(|_| 3.0 * lcg_unit(&mut s) - 1.5).collect()
    }

    #[test]
    fn a_constant_target_holds_the_input_still() {
        // B(B^{-1}(level)) is the level only to a few ulps: read as reversals, those ulps made
        // x jump across the dead band every sample on a flat reference
        for bl in [example1_backlash(), example2_backlash()] {
            for level in [0.37, -0.81, 1e-3, 2.5] {
                let x = bl.inverse(&[level; 50], -0.01, 0.0, 0.0).unwrap();
                // still up to the ulp the hold's clamp may take (the band is about 1 wide)
                assert!(
                    x[1..].iter().all(|&v| (v - x[0]).abs() <= 1e-12),
                    "{level}: {x:?}"
                );
                let y = bl.simulate(&x, -0.01).unwrap();
                assert!(
                    y.iter().all(|v| (v - level).abs() <= 1e-12),
                    "{level}: {y:?}"
                );
            }
        }
    }

    #[test]
    fn the_backlash_of_the_inverse_is_the_identity() {
        let quintic = quintic_backlash();
        let linear = GeneralBacklash::new(0.3, 0.2, vec![1.1], vec![0.9]).unwrap();
        for bl in [example1_backlash(), example2_backlash(), quintic, linear] {
            for y_d in [smooth(3000), rough(2000, 7), rough(500, 99)] {
                let e = worst_error(&bl, &y_d, 0.0);
                assert!(e < 1e-10, "{bl:?}: {e}");
            }
            // repeated levels: the holds
            let steps: Vec<f64> = (0..300)
                .map(|k| ((k / 10) % 7) as f64 * 0.3 - 0.9)
                .collect();
            assert!(worst_error(&bl, &steps, 0.0) < 1e-10);
        }
    }

    #[test]
    fn hold_keeps_x_inside_the_dead_band() {
        let bl = example1_backlash();
        let mut inv = BacklashInverse::new(0.0, 0.0, 0.0).unwrap();
        let up = inv.step(&bl, 1.0).unwrap();
        assert!((bl.right().value(up) - 1.0).abs() < 1e-12);
        // hold at the level: x stays put (it is on the band's edge)
        assert_eq!(inv.step(&bl, 1.0).unwrap(), up);
        // a start outside the band at the memory's level is pulled to its nearer edge
        for x0 in [-5.0, 5.0, 0.1] {
            let mut inv = BacklashInverse::new(0.3, x0, 0.0).unwrap();
            let x = inv.step(&bl, 0.3).unwrap();
            let lo = branch_root(bl.left(), 0.6, 0.3, 0.0).unwrap();
            let hi = branch_root(bl.right(), -0.5, 0.3, 0.0).unwrap();
            assert!(
                lo - 1e-12 <= x && x <= hi + 1e-12 && lo < hi,
                "{lo} {x} {hi}"
            );
            assert!((x - x0.clamp(lo, hi)).abs() < 1e-12);
            // on the band's edge the branch gives the level back to an ulp
            assert!((inv.y_prev - 0.3).abs() < 1e-15);
        }
    }

    #[test]
    fn a_reversal_crosses_the_dead_band_in_one_sample() {
        let bl = example1_backlash();
        let x = bl.inverse(&[1.0, 1.2, 1.1], 0.0, 0.0, 0.0).unwrap();
        assert!((bl.right().value(x[1]) - 1.2).abs() < 1e-12);
        assert!((bl.left().value(x[2]) - 1.1).abs() < 1e-12);
        // the band at that level: R^{-1}(1.2) - L^{-1}(1.1), about 0.68 on these branches
        assert!(x[1] - x[2] > 0.6, "{x:?}");
        assert_eq!(bl.simulate(&x, 0.0).unwrap()[2], bl.left().value(x[2]));
    }

    #[test]
    fn threshold_suppresses_chatter_on_a_noisy_ramp() {
        let bl = example1_backlash();
        let mut s = 3u64;
        let ramp: Vec<f64> = (0..800)
            .map(|k| 0.1 + 0.002 * k as f64 + 0.02 * (lcg_unit(&mut s) - 0.5))
            .collect();
        // big jumps of x: crossings of the dead band (width about 1.1)
        let crossings = |x: &[f64]| x.windows(2).filter(|w| (w[1] - w[0]).abs() > 0.5).count();
        let exact = bl.inverse(&ramp, 0.0, 0.0, 0.0).unwrap();
        let smooth = bl.inverse(&ramp, 0.0, 0.0, 0.025).unwrap();
        // (the first sample moves x from x(0) = 0 onto the band's edge)
        assert!(crossings(&exact[1..]) > 50, "{}", crossings(&exact));
        assert_eq!(crossings(&smooth[1..]), 0);
        // the smoothed output still follows the ramp within the threshold
        let y = bl.simulate(&smooth, 0.0).unwrap();
        for (a, b) in y.iter().zip(&ramp) {
            assert!((a - b).abs() <= 0.025 + 1e-9);
        }
    }

    #[test]
    fn unreachable_and_bad_targets_are_errors() {
        // R(x) = (x - 0.1) - 0.5 (x - 0.1)^2 + ... peaks: a level above the peak
        let bl =
            GeneralBacklash::from_estimate(0.1, 0.1, vec![1.0, -0.5], vec![1.0, -0.5]).unwrap();
        let err = bl.inverse(&[0.2, 5.0], 0.0, 0.0, 0.0).unwrap_err();
        assert!(
            matches!(err, Error::Data(ref m) if m.starts_with("y_desired[1]") && m.contains("R")),
            "{err:?}"
        );
        let bl = example1_backlash();
        assert!(matches!(
            bl.inverse(&[0.1, f64::NAN], 0.0, 0.0, 0.0),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            bl.inverse(&[], 0.0, 0.0, 0.0),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            bl.inverse(&[0.1], 0.0, 0.0, -1.0),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            bl.inverse(&[0.1], f64::NAN, 0.0, 0.0),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            bl.inverse(&[1e300], 0.0, 0.0, 0.0),
            Err(Error::Data(_))
        ));
    }
}
