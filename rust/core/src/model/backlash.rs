//! The general backlash of eq (1)-(8): branches
//!     L(x) = sum_{i=1}^n m_Li (x + c_L)^i   (eq 4),   R(x) = sum_{i=1}^n m_Ri (x - c_R)^i   (eq 5),
//! and the output moves along L or R, or holds y(t-1) inside the dead band (eq 1).

use crate::error::{Error, Result};
use crate::guard;
use crate::model::signal::{check_coefficients, check_signal};

/// One branch: value(x) = sum_{i>=1} m_i (x + shift)^i, so shift = c_L for L and -c_R for R.
#[derive(Debug, Clone, PartialEq)]
pub struct Branch {
    shift: f64,
    m: Vec<f64>,
}

impl Branch {
    pub fn coefficients(&self) -> &[f64] {
        &self.m
    }

    /// The branch at x, by Horner's rule in xi = x + shift (eq 4-5, or eq 9-10 for xi).
    #[inline(always)]
    pub fn value(&self, x: f64) -> f64 {
        let xi = x + self.shift;
        let mut acc = 0.0;
        for m in self.m.iter().rev() {
            acc = acc * xi + m;
        }
        acc * xi
    }

    /// d value / dx.
    pub fn slope(&self, x: f64) -> f64 {
        let xi = x + self.shift;
        let mut acc = 0.0;
        for (k, m) in self.m.iter().enumerate().rev() {
            acc = acc * xi + (k + 1) as f64 * m;
        }
        acc
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct GeneralBacklash {
    c_left: f64,
    c_right: f64,
    left: Branch,
    right: Branch,
}

/// What `GeneralBacklash::check_branches` found on an x-range: the paper assumes both branches
/// increase and do not cross "in the region of practical interest" (Section 2).
#[derive(Debug, Clone, PartialEq)]
pub struct BranchCheck {
    pub x_min: f64,
    pub x_max: f64,
    /// Intervals where dL/dx <= 0.
    pub left_not_increasing: Vec<(f64, f64)>,
    /// Intervals where dR/dx <= 0.
    pub right_not_increasing: Vec<(f64, f64)>,
    /// Intervals where L(x) <= R(x): the branches cross at their ends.
    pub crossed: Vec<(f64, f64)>,
}

impl BranchCheck {
    pub fn is_valid(&self) -> bool {
        self.left_not_increasing.is_empty()
            && self.right_not_increasing.is_empty()
            && self.crossed.is_empty()
    }
}

impl GeneralBacklash {
    /// Widths c_L, c_R >= 0 and branch coefficients m_L = [m_L1..m_Ln], m_R = [m_R1..m_Rn].
    /// Both branches must increase from their x-axis crossings across the dead band [-c_L, c_R].
    pub fn new(c_left: f64, c_right: f64, m_left: Vec<f64>, m_right: Vec<f64>) -> Result<Self> {
        for (name, c) in [("c_L", c_left), ("c_R", c_right)] {
            if !(c.is_finite() && c >= 0.0) {
                return Err(Error::Model(format!(
                    "{name} = {c}: dead-band widths must be finite and >= 0 \
                     (the branches cross the x-axis at -c_L and +c_R)"
                )));
            }
        }
        let bl = Self::from_estimate(c_left, c_right, m_left, m_right)?;
        let check = bl.check_branches(-c_left, c_right);
        for (name, branch, bad) in [
            ("L", &bl.left, &check.left_not_increasing),
            ("R", &bl.right, &check.right_not_increasing),
        ] {
            if branch.m[0] <= 0.0 || !bad.is_empty() {
                return Err(Error::Model(format!(
                    "branch {name} does not increase across the dead band [-c_L, c_R] = \
                     [{:.6}, {:.6}] (m_{name}1 = {}): a backlash needs increasing branches; \
                     make m_{name}1 > 0 and check the higher coefficients",
                    -c_left, c_right, branch.m[0]
                )));
            }
        }
        Ok(bl)
    }

    /// An estimate during identification: finite numbers only, no shape checks (the
    /// iterations may pass through branches that turn or cross; eq 1's case order copes).
    pub fn from_estimate(
        c_left: f64,
        c_right: f64,
        m_left: Vec<f64>,
        m_right: Vec<f64>,
    ) -> Result<Self> {
        for (name, c) in [("c_L", c_left), ("c_R", c_right)] {
            if !c.is_finite() {
                return Err(Error::Model(format!("{name} = {c}: the estimate diverged")));
            }
        }
        check_coefficients("m_L", &m_left, false)?;
        check_coefficients("m_R", &m_right, false)?;
        Ok(GeneralBacklash {
            c_left,
            c_right,
            left: Branch {
                shift: c_left,
                m: m_left,
            },
            right: Branch {
                shift: -c_right,
                m: m_right,
            },
        })
    }

    pub fn c_left(&self) -> f64 {
        self.c_left
    }

    pub fn c_right(&self) -> f64 {
        self.c_right
    }

    pub fn left(&self) -> &Branch {
        &self.left
    }

    pub fn right(&self) -> &Branch {
        &self.right
    }

    /// One step of eq (1) with its case order (L first, then R, else hold). For increasing
    /// branches x <= z_L is L(x) <= y(t-1) by eq (2), and x >= z_R is R(x) >= y(t-1) by eq (3).
    #[inline(always)]
    pub fn step(&self, x: f64, y_prev: f64) -> f64 {
        select(self.left.value(x), self.right.value(x), y_prev)
    }

    /// The step with both branches copied into fixed-size arrays, for the hot loops; None
    /// for a branch of degree above `PADDED`.
    pub(crate) fn padded_step(&self) -> Option<PaddedStep> {
        Some(PaddedStep {
            left: PaddedBranch::new(&self.left)?,
            right: PaddedBranch::new(&self.right)?,
        })
    }

    /// The backlash output for the internal signal `x`, from memory y(0) = `y0`.
    pub fn simulate(&self, x: &[f64], y0: f64) -> Result<Vec<f64>> {
        check_signal("x", x)?;
        check_memory(y0)?;
        let y = match self.padded_step() {
            Some(padded) => run_steps(x, y0, padded)?,
            None => run_steps(x, y0, self)?,
        };
        check_output_overflow(x, &y)?;
        Ok(y)
    }

    /// z_L, z_R of eq (2)-(3): where L and R reach `y_prev`, searched on [x_lo, x_hi], where
    /// the branches are taken to increase. Outside the range: -inf / +inf as appropriate.
    pub fn breakpoints(&self, y_prev: f64, x_lo: f64, x_hi: f64) -> (f64, f64) {
        (
            inverse_on(&self.left, y_prev, x_lo, x_hi),
            inverse_on(&self.right, y_prev, x_lo, x_hi),
        )
    }

    /// Eq (1) read literally, through the breakpoints of eq (2)-(3). A reference form (slow:
    /// a root search per sample) to check `simulate` and the switching form against.
    pub fn simulate_by_breakpoints(&self, x: &[f64], y0: f64) -> Result<Vec<f64>> {
        check_signal("x", x)?;
        check_memory(y0)?;
        let x_lo = x.iter().cloned().fold(f64::INFINITY, f64::min);
        let x_hi = x.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let mut y = guard::buffer(x.len(), "y")?;
        let mut y_prev = y0;
        for (t, &xt) in x.iter().enumerate() {
            // a root search per sample: checked more often than the fast loops
            if t % (guard::CHUNK >> 8) == 0 {
                guard::check()?;
            }
            let (z_l, z_r) = self.breakpoints(y_prev, x_lo, x_hi);
            y_prev = if xt <= z_l {
                self.left.value(xt)
            } else if xt >= z_r {
                self.right.value(xt)
            } else {
                y_prev
            };
            y.push(y_prev);
        }
        Ok(y)
    }

    /// Where, on [x_min, x_max], a branch fails to increase or L falls to or below R.
    /// Sampled on a fine grid (4096 cells) with interval ends refined by bisection.
    pub fn check_branches(&self, x_min: f64, x_max: f64) -> BranchCheck {
        let (lo, hi) = (x_min.min(x_max), x_min.max(x_max));
        BranchCheck {
            x_min: lo,
            x_max: hi,
            left_not_increasing: intervals_where_nonpositive(|x| self.left.slope(x), lo, hi),
            right_not_increasing: intervals_where_nonpositive(|x| self.right.slope(x), lo, hi),
            crossed: intervals_where_nonpositive(
                |x| self.left.value(x) - self.right.value(x),
                lo,
                hi,
            ),
        }
    }
}

/// y(t) = step(x(t), y(t-1)) along x from y(0) = `y0`.
fn run_steps(x: &[f64], y0: f64, step: impl Step) -> Result<Vec<f64>> {
    let mut y_prev = y0;
    let mut y = guard::buffer(x.len(), "y")?;
    for chunk in x.chunks(guard::CHUNK) {
        guard::check()?;
        y.extend(chunk.iter().map(|&xt| {
            y_prev = step.step(xt, y_prev);
            y_prev
        }));
    }
    Ok(y)
}

/// Eq (1)'s case order given L(x) and R(x), written as two selects (no branch to mispredict).
#[inline(always)]
fn select(l: f64, r: f64, y_prev: f64) -> f64 {
    let not_left = if r >= y_prev { r } else { y_prev };
    if l <= y_prev {
        l
    } else {
        not_left
    }
}

/// One step of eq (1) in a hot loop: the model itself, or its `PaddedStep`.
pub(crate) trait Step: Copy {
    fn step(&self, x: f64, y_prev: f64) -> f64;
    /// f1(t) or f2(t) of eq (12)-(13): the step takes a branch (`switching::switching`).
    fn moves(&self, x: f64, y_prev: f64) -> bool;
    /// The step and its case, f1 + 2 f2 (`switching::switching`'s flags, the same bits).
    fn step_case(&self, x: f64, y_prev: f64) -> (f64, u8);
}

/// f1 + 2 f2 of eq (12)-(13) (case order of eq 1) from L(x) and R(x), as
/// `switching::switching` computes them.
#[inline(always)]
fn case_of(l: f64, r: f64, y_prev: f64) -> (f64, u8) {
    let f1 = l - y_prev <= 0.0;
    let f2 = y_prev - r <= 0.0 && !f1;
    (select(l, r, y_prev), u8::from(f1) | (u8::from(f2) << 1))
}

impl Step for &GeneralBacklash {
    #[inline(always)]
    fn step_case(&self, x: f64, y_prev: f64) -> (f64, u8) {
        case_of(self.left.value(x), self.right.value(x), y_prev)
    }

    #[inline(always)]
    fn step(&self, x: f64, y_prev: f64) -> f64 {
        GeneralBacklash::step(self, x, y_prev)
    }

    #[inline(always)]
    fn moves(&self, x: f64, y_prev: f64) -> bool {
        let (f1, f2) = crate::model::switching::switching(self, x, y_prev);
        f1 | f2
    }
}

/// Branch degree up to which `GeneralBacklash::padded_step` applies.
const PADDED: usize = 3;

/// A branch as [m_n, .., m_1] behind leading zeros, so that Horner's rule runs a fixed
/// number of steps. The zeros change nothing: `Branch::value` starts from acc = 0 anyway,
/// 0 * xi + 0 = +0 for every finite xi, and a non-finite xi gives NaN either way.
#[derive(Debug, Clone, Copy)]
struct PaddedBranch {
    shift: f64,
    m: [f64; PADDED],
}

impl PaddedBranch {
    fn new(branch: &Branch) -> Option<Self> {
        let mut m = [0.0; PADDED];
        let tail = PADDED.checked_sub(branch.m.len())?;
        for (slot, mi) in m[tail..].iter_mut().zip(branch.m.iter().rev()) {
            *slot = *mi;
        }
        Some(PaddedBranch {
            shift: branch.shift,
            m,
        })
    }

    #[inline(always)]
    fn value(&self, x: f64) -> f64 {
        let xi = x + self.shift;
        self.m.iter().fold(0.0, |acc, m| acc * xi + m) * xi
    }
}

/// A branch's derivative as [n m_n, .., 1 m_1] behind leading zeros (`Branch::slope` with a
/// fixed number of Horner steps: the same products k m_k, and 0 * xi + 0 = +0 before them,
/// so the same bits).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PaddedSlope {
    shift: f64,
    d: [f64; PADDED],
}

impl PaddedSlope {
    fn new(branch: &Branch) -> Option<Self> {
        let mut d = [0.0; PADDED];
        let tail = PADDED.checked_sub(branch.m.len())?;
        for (k, (slot, mi)) in d[tail..].iter_mut().zip(branch.m.iter().rev()).enumerate() {
            *slot = (branch.m.len() - k) as f64 * mi;
        }
        Some(PaddedSlope {
            shift: branch.shift,
            d,
        })
    }

    /// d value / dx at x, as `Branch::slope`.
    #[inline(always)]
    pub(crate) fn slope(&self, x: f64) -> f64 {
        let xi = x + self.shift;
        self.d.iter().fold(0.0, |acc, d| acc * xi + d)
    }
}

impl GeneralBacklash {
    /// The slopes of (L, R) with a fixed number of Horner steps; None for a branch of degree
    /// above `PADDED`.
    pub(crate) fn padded_slopes(&self) -> Option<(PaddedSlope, PaddedSlope)> {
        Some((
            PaddedSlope::new(&self.left)?,
            PaddedSlope::new(&self.right)?,
        ))
    }
}

#[derive(Debug, Clone, Copy)]
pub(crate) struct PaddedStep {
    left: PaddedBranch,
    right: PaddedBranch,
}

impl PaddedStep {
    /// L(x): `Branch::value` of the left branch, the same bits.
    #[inline(always)]
    pub(crate) fn left_value(&self, x: f64) -> f64 {
        self.left.value(x)
    }

    /// R(x): `Branch::value` of the right branch, the same bits.
    #[inline(always)]
    pub(crate) fn right_value(&self, x: f64) -> f64 {
        self.right.value(x)
    }

    /// `switching::switching` (eq 12-13, case order of eq 1) with the padded branches: the
    /// same bits, a fixed number of Horner steps.
    #[inline(always)]
    pub(crate) fn switching(&self, x: f64, y_prev: f64) -> (bool, bool) {
        let f1 = self.left.value(x) - y_prev <= 0.0;
        let f2 = y_prev - self.right.value(x) <= 0.0;
        (f1, f2 && !f1)
    }
}

impl Step for PaddedStep {
    #[inline(always)]
    fn step_case(&self, x: f64, y_prev: f64) -> (f64, u8) {
        case_of(self.left.value(x), self.right.value(x), y_prev)
    }

    #[inline(always)]
    fn step(&self, x: f64, y_prev: f64) -> f64 {
        select(self.left.value(x), self.right.value(x), y_prev)
    }

    #[inline(always)]
    fn moves(&self, x: f64, y_prev: f64) -> bool {
        let (f1, f2) = self.switching(x, y_prev);
        f1 | f2
    }
}

/// Branches of degree n grow like |x|^n: a large but finite x can overflow y.
pub(crate) fn check_output_overflow(x: &[f64], y: &[f64]) -> Result<()> {
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(output_overflow(i, x[i]));
    }
    Ok(())
}

/// The error of `check_output_overflow` for sample `i` with input `x`.
pub(crate) fn output_overflow(i: usize, x: f64) -> Error {
    Error::Model(format!(
        "simulation diverged: the backlash output y[{i}] overflowed at x[{i}] = {x:e}, \
         where the branch polynomials exceed the float range; scale the signals down"
    ))
}

pub(crate) fn check_memory(y0: f64) -> Result<()> {
    if !y0.is_finite() {
        return Err(Error::Data(format!(
            "initial backlash memory y0 = {y0}: give a finite value (0 starts inside the dead band)"
        )));
    }
    Ok(())
}

/// The x in [lo, hi] where an increasing `branch` equals `level` (bisection to adjacent
/// floats); -inf if the branch is above `level` on all of it, +inf if below.
fn inverse_on(branch: &Branch, level: f64, lo: f64, hi: f64) -> f64 {
    if branch.value(lo) > level {
        return f64::NEG_INFINITY;
    }
    if branch.value(hi) < level {
        return f64::INFINITY;
    }
    let (mut a, mut b) = (lo, hi);
    for _ in 0..2100 {
        let mid = 0.5 * (a + b);
        if mid <= a || mid >= b {
            break;
        }
        if branch.value(mid) <= level {
            a = mid;
        } else {
            b = mid;
        }
    }
    // The largest x with value <= level: x <= z_L then holds exactly when L(x) <= level.
    a
}

/// Intervals of [lo, hi] where f <= 0, found on a grid and refined by bisection.
fn intervals_where_nonpositive(f: impl Fn(f64) -> f64, lo: f64, hi: f64) -> Vec<(f64, f64)> {
    const CELLS: usize = 4096;
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    let at = |k: usize| lo + (hi - lo) * (k as f64) / (CELLS as f64);
    let refine = |mut good: f64, mut bad: f64| {
        // f(good) > 0 >= f(bad): move both towards the sign change.
        for _ in 0..200 {
            let mid = 0.5 * (good + bad);
            if mid == good || mid == bad {
                break;
            }
            if f(mid) > 0.0 {
                good = mid;
            } else {
                bad = mid;
            }
        }
        bad
    };
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    let mut prev_x = lo;
    for k in 0..=CELLS {
        let x = at(k);
        // not f > 0, a NaN included
        let bad = f(x).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater);
        match (start, bad) {
            (None, true) => start = Some(if k == 0 { x } else { refine(prev_x, x) }),
            (Some(s), false) => {
                out.push((s, refine(x, prev_x)));
                start = None;
            }
            _ => {}
        }
        prev_x = x;
    }
    if let Some(s) = start {
        out.push((s, hi));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_params::{example1_backlash as example1, quintic_backlash};

    #[test]
    fn padded_branches_and_slopes_are_the_branches_bit_for_bit() {
        let cubic = example1();
        let linear = GeneralBacklash::new(0.3, 0.2, vec![1.1], vec![0.9]).unwrap();
        let quadratic = GeneralBacklash::new(0.3, 0.2, vec![1.0, -0.4], vec![1.2, 0.3]).unwrap();
        for bl in [cubic, linear, quadratic] {
            let step = bl.padded_step().unwrap();
            let (ls, rs) = bl.padded_slopes().unwrap();
            for k in -400..=400 {
                let x = f64::from(k) * 0.0123 + 1e-3;
                assert_eq!(step.left_value(x).to_bits(), bl.left().value(x).to_bits());
                assert_eq!(step.right_value(x).to_bits(), bl.right().value(x).to_bits());
                assert_eq!(ls.slope(x).to_bits(), bl.left().slope(x).to_bits());
                assert_eq!(rs.slope(x).to_bits(), bl.right().slope(x).to_bits());
            }
        }
        let quintic = quintic_backlash();
        assert!(quintic.padded_slopes().is_none());
    }

    #[test]
    fn branches_cross_the_axis_at_minus_c_left_and_c_right() {
        let bl = example1();
        assert_eq!(bl.left().value(-0.6), 0.0);
        assert_eq!(bl.right().value(0.5), 0.0);
        // L(0) = 0.6 - 0.3*0.36 + 0.3*0.216
        assert!((bl.left().value(0.0) - (0.6 - 0.108 + 0.0648)).abs() < 1e-15);
    }

    #[test]
    fn holds_in_the_dead_band_and_follows_the_branches_outside() {
        let bl = example1();
        let y = bl.simulate(&[0.0, 0.3, -0.3, 2.0, 1.9, -2.0], 0.0).unwrap();
        assert_eq!(&y[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(y[3], bl.right().value(2.0));
        assert_eq!(y[4], y[3]); // a small reversal stays in the dead band
        assert_eq!(y[5], bl.left().value(-2.0));
    }

    #[test]
    fn breakpoint_form_equals_value_form() {
        let bl = example1();
        let x: Vec<f64> = (0..2000)
            .map(|k| 1.5 * ((k as f64) * 0.37).sin() + 0.3 * ((k as f64) * 1.3).cos())
            .collect();
        let a = bl.simulate(&x, 0.0).unwrap();
        let b = bl.simulate_by_breakpoints(&x, 0.0).unwrap();
        for (p, q) in a.iter().zip(&b) {
            assert!((p - q).abs() < 1e-12);
        }
    }

    #[test]
    fn invalid_parameters_are_refused() {
        let bad = [
            GeneralBacklash::new(-0.1, 0.5, vec![1.0], vec![1.0]),
            GeneralBacklash::new(0.1, f64::NAN, vec![1.0], vec![1.0]),
            GeneralBacklash::new(0.1, 0.5, vec![], vec![1.0]),
            GeneralBacklash::new(0.1, 0.5, vec![-1.0], vec![1.0]),
            // R'(x) = 1 + 6 (x - 0.5) < 0 for x < 1/3: R falls across the dead band
            GeneralBacklash::new(0.5, 0.5, vec![1.0], vec![1.0, 3.0]),
        ];
        for b in bad {
            assert!(matches!(b, Err(Error::Model(_))), "{b:?}");
        }
    }

    #[test]
    fn check_reports_where_branches_cross_and_turn() {
        // L(x) = (x+0.1) - (x+0.1)^2 turns at x = 0.4; R(x) = 2(x-0.1) overtakes L at x = 0.3
        let bl = GeneralBacklash::new(0.1, 0.1, vec![1.0, -1.0], vec![2.0]).unwrap();
        let c = bl.check_branches(-1.0, 1.0);
        assert!(!c.is_valid());
        assert_eq!(c.left_not_increasing.len(), 1);
        assert!((c.left_not_increasing[0].0 - 0.4).abs() < 1e-9);
        assert!(c.right_not_increasing.is_empty());
        // L - R = -x^2 - 1.2x + 0.29 <= 0 for x >= (-1.2 + sqrt(2.6)) / 2 on [-1, 1]
        let root = (-1.2 + 2.6f64.sqrt()) / 2.0;
        assert_eq!(c.crossed.len(), 1);
        assert!((c.crossed[0].0 - root).abs() < 1e-9, "{:?}", c.crossed);
        assert_eq!(c.crossed[0].1, 1.0);
        assert!(example1().check_branches(-3.0, 3.0).is_valid());
    }
}
