//! The linear dynamic block of eq (16):
//!     x(t) = sum_{i=1}^{na} a_i u(t-i) - sum_{j=1}^{nb} b_j x(t-j),
//! optionally with a direct feedthrough a_0 u(t) (lag 0) added (not in the paper; real
//! sampled systems often have one). The sandwich's output block (eq 29, coefficients r and s,
//! feedthrough r_0) is the same block.

use crate::error::{Error, Result};
use crate::guard;
use crate::model::polynomial::{monic_roots, Root};
use crate::model::signal::check_coefficients;

#[derive(Debug, Clone, PartialEq)]
pub struct LinearBlock {
    a: Vec<f64>,
    b: Vec<f64>,
    /// The feedthrough a_0 of u(t); None for eq (16) as the paper has it.
    a0: Option<f64>,
}

/// The past of a linear block, most recent first: `u_past = [u(0), u(-1), ..]` (na values)
/// and `x_past = [x(0), x(-1), ..]` (nb values), where t = 1 is the first sample simulated.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearState {
    pub u_past: Vec<f64>,
    pub x_past: Vec<f64>,
}

/// The largest order of a block's denominator (nb), and of every order and the degree of an
/// identification's `Structure`. The poles, which `poles()` and every stability check
/// compute, are the eigenvalues of the nb x nb companion matrix: O(nb^3) time, 0.03 s at
/// nb = 200 but about 30 s at 2000 (2026-11-24), and with it an identification's p x p
/// algebra; orders that high are far beyond what a record identifies.
pub const MAX_ORDER: usize = 200;

impl LinearBlock {
    /// `a` (at least one coefficient) and `b` (possibly none: an FIR block, at most
    /// `MAX_ORDER`), all finite.
    pub fn new(a: Vec<f64>, b: Vec<f64>) -> Result<Self> {
        check_coefficients("a", &a, false)?;
        check_coefficients("b", &b, true)?;
        if b.len() > MAX_ORDER {
            return Err(Error::Model(format!(
                "b has {} coefficients: the denominator's order nb is at most {MAX_ORDER} (its \
                 poles, which poles() and every stability check compute, are the eigenvalues \
                 of an nb x nb companion matrix: O(nb^3) time, 0.03 s at nb = 200, about 30 s \
                 at 2000)",
                b.len()
            )));
        }
        Ok(LinearBlock { a, b, a0: None })
    }

    /// Eq (16) plus a direct feedthrough: x(t) = a_0 u(t) + sum_{i>=1} a_i u(t-i) - ...;
    /// `a` (lags 1..na) still needs at least one coefficient (give 0.0 for none).
    pub fn with_feedthrough(a0: f64, a: Vec<f64>, b: Vec<f64>) -> Result<Self> {
        check_coefficients("a_0", &[a0], false)?;
        let mut block = Self::new(a, b)?;
        block.a0 = Some(a0);
        Ok(block)
    }

    /// The feedthrough a_0 (None: no lag-0 term).
    pub fn feedthrough(&self) -> Option<f64> {
        self.a0
    }

    /// a_0 as a number (0 without feedthrough).
    #[inline(always)]
    pub fn a0(&self) -> f64 {
        self.a0.unwrap_or(0.0)
    }

    pub fn a(&self) -> &[f64] {
        &self.a
    }

    pub fn b(&self) -> &[f64] {
        &self.b
    }

    pub fn na(&self) -> usize {
        self.a.len()
    }

    pub fn nb(&self) -> usize {
        self.b.len()
    }

    /// Roots of z^nb + b_1 z^(nb-1) + ... + b_nb, the poles of eq (16).
    pub fn poles(&self) -> Vec<Root> {
        monic_roots(&self.b)
    }

    /// Largest pole modulus (0 for an FIR block).
    pub fn spectral_radius(&self) -> f64 {
        crate::model::polynomial::spectral_radius(&self.b)
    }

    /// All poles strictly inside the unit circle.
    pub fn is_stable(&self) -> bool {
        self.spectral_radius() < 1.0
    }

    /// Rest: every past input and output zero (the paper's assumption).
    pub fn rest_state(&self) -> LinearState {
        LinearState {
            u_past: vec![0.0; self.na()],
            x_past: vec![0.0; self.nb()],
        }
    }

    /// A state must give exactly na past inputs and nb past outputs, all finite.
    pub fn check_state(&self, state: &LinearState, name: &str) -> Result<()> {
        for (what, values, n) in [
            ("u_past", &state.u_past, self.na()),
            ("x_past", &state.x_past, self.nb()),
        ] {
            if values.len() != n {
                return Err(Error::Data(format!(
                    "{name}.{what} has {} values but the block needs {n} (its order): \
                     give the most recent value first",
                    values.len()
                )));
            }
            if values.iter().any(|v| !v.is_finite()) {
                return Err(Error::Data(format!(
                    "{name}.{what} holds a non-finite value: give finite past values"
                )));
            }
        }
        Ok(())
    }

    /// Eq (16) at sample index `t` (0-based; paper time t+1), given the inputs `u[..t]` and
    /// the outputs `x[..t]` computed so far, falling back on `state` before the record.
    #[inline(always)]
    pub fn output_at(&self, u: &[f64], x: &[f64], t: usize, state: &LinearState) -> f64 {
        let (na, nb) = (self.a.len(), self.b.len());
        let mut acc = self.a0() * u[t];
        if t >= na && t >= nb {
            for (ai, ui) in self.a.iter().zip(u[t - na..t].iter().rev()) {
                acc += ai * ui;
            }
            for (bj, xj) in self.b.iter().zip(x[t - nb..t].iter().rev()) {
                acc -= bj * xj;
            }
        } else {
            // Lag k reaches sample t-k, which lies before the record when k > t.
            let past = |k: usize, now: &[f64], before: &[f64]| {
                if k <= t {
                    now[t - k]
                } else {
                    before[k - t - 1]
                }
            };
            for (i, ai) in self.a.iter().enumerate() {
                acc += ai * past(i + 1, u, &state.u_past);
            }
            for (j, bj) in self.b.iter().enumerate() {
                acc -= bj * past(j + 1, x, &state.x_past);
            }
        }
        acc
    }

    /// Simulate eq (16) from `state`; fails on non-finite input or if the output overflows.
    pub fn simulate(&self, u: &[f64], state: &LinearState) -> Result<Vec<f64>> {
        crate::model::signal::check_signal("u", u)?;
        self.check_state(state, "state")?;
        let x = self.with_recursion(state, Outputs(u))?;
        check_no_overflow(self, &x, "x")?;
        Ok(x)
    }

    /// Run `f` on this block's recursion started from `state`. The usual low orders get a
    /// recursion with its orders fixed at compile time, so that its past lives in registers;
    /// every order gives the same numbers (the same sums in the same order).
    #[inline]
    pub(crate) fn with_recursion<F: RecursionUser>(&self, state: &LinearState, f: F) -> F::Output {
        macro_rules! try_fixed {
            ($(($na:literal, $nb:literal)),*) => {$(
                if let Some(rec) = Fixed::<$na, $nb>::new(self, state) {
                    return f.run(rec);
                }
            )*};
        }
        try_fixed!((1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2));
        f.run(Dynamic::new(self, state))
    }

    /// The state after the record `u` -> `x` that started from `before`.
    pub fn state_after(&self, before: &LinearState, u: &[f64], x: &[f64]) -> LinearState {
        LinearState {
            u_past: shift_in(&before.u_past, u),
            x_past: shift_in(&before.x_past, x),
        }
    }
}

/// Eq (16) run forward sample by sample, the past held by the recursion itself.
pub(crate) trait Recursion: 'static {
    /// x(t) from the past inputs and outputs; then `u_now` = u(t) and x(t) join the past.
    fn next(&mut self, u_now: f64) -> f64;
}

/// Something to do with a recursion of any order: `LinearBlock::with_recursion` calls it.
pub(crate) trait RecursionUser {
    type Output;
    fn run<R: Recursion>(self, rec: R) -> Self::Output;
}

/// A recursion behind `dyn`, run a block of samples per (virtual) call.
pub(crate) trait BlockRecursion {
    /// x for the inputs `u`, into `x` (as many as both have).
    fn run_block(&mut self, u: &[f64], x: &mut [f64]);
}

impl<R: Recursion> BlockRecursion for R {
    fn run_block(&mut self, u: &[f64], x: &mut [f64]) {
        for (xt, &ut) in x.iter_mut().zip(u) {
            *xt = self.next(ut);
        }
    }
}

/// The recursion, boxed: `LinearBlock::with_recursion(state, Boxed)`.
pub(crate) struct Boxed;

impl RecursionUser for Boxed {
    type Output = Box<dyn BlockRecursion>;
    fn run<R: Recursion>(self, rec: R) -> Self::Output {
        Box::new(rec)
    }
}

/// x for the input `u`, sample by sample.
pub(crate) struct Outputs<'a>(pub(crate) &'a [f64]);

impl RecursionUser for Outputs<'_> {
    type Output = Result<Vec<f64>>;
    fn run<R: Recursion>(self, mut rec: R) -> Result<Vec<f64>> {
        let mut x = guard::buffer(self.0.len(), "x")?;
        for chunk in self.0.chunks(guard::CHUNK) {
            guard::check()?;
            x.extend(chunk.iter().map(|&ut| rec.next(ut)));
        }
        Ok(x)
    }
}

/// Orders fixed at compile time: the loops unroll and the past stays in registers.
struct Fixed<const NA: usize, const NB: usize> {
    a0: f64,
    a: [f64; NA],
    b: [f64; NB],
    /// [u(t-1), u(t-2), ..] and [x(t-1), x(t-2), ..]
    u_past: [f64; NA],
    x_past: [f64; NB],
}

impl<const NA: usize, const NB: usize> Fixed<NA, NB> {
    /// None unless the block has exactly these orders (and the state fits them).
    fn new(block: &LinearBlock, state: &LinearState) -> Option<Self> {
        Some(Fixed {
            a0: block.a0(),
            a: block.a.as_slice().try_into().ok()?,
            b: block.b.as_slice().try_into().ok()?,
            u_past: state.u_past.as_slice().try_into().ok()?,
            x_past: state.x_past.as_slice().try_into().ok()?,
        })
    }
}

/// Newest value first: [v, past[0], past[1], ..] without the oldest.
#[inline(always)]
fn push_front<const N: usize>(past: &mut [f64; N], v: f64) {
    if N > 0 {
        past.copy_within(0..N - 1, 1);
        past[0] = v;
    }
}

impl<const NA: usize, const NB: usize> Recursion for Fixed<NA, NB> {
    #[inline(always)]
    fn next(&mut self, u_now: f64) -> f64 {
        let mut acc = self.a0 * u_now; // +-0 without feedthrough: the sums below are unchanged
        for i in 0..NA {
            acc += self.a[i] * self.u_past[i];
        }
        for j in 0..NB {
            acc -= self.b[j] * self.x_past[j];
        }
        push_front(&mut self.u_past, u_now);
        push_front(&mut self.x_past, acc);
        acc
    }
}

/// Any orders: the same sums over the coefficient vectors.
struct Dynamic {
    a0: f64,
    a: Vec<f64>,
    b: Vec<f64>,
    u_past: Vec<f64>,
    x_past: Vec<f64>,
}

impl Dynamic {
    fn new(block: &LinearBlock, state: &LinearState) -> Self {
        Dynamic {
            a0: block.a0(),
            a: block.a.clone(),
            b: block.b.clone(),
            u_past: state.u_past.clone(),
            x_past: state.x_past.clone(),
        }
    }
}

/// Newest value first, as `push_front`; a no-op on an empty past.
fn push_front_slice(past: &mut [f64], v: f64) {
    if let Some(last) = past.len().checked_sub(1) {
        past.copy_within(0..last, 1);
        past[0] = v;
    }
}

impl Recursion for Dynamic {
    fn next(&mut self, u_now: f64) -> f64 {
        let mut acc = self.a0 * u_now;
        for (ai, ui) in self.a.iter().zip(&self.u_past) {
            acc += ai * ui;
        }
        for (bj, xj) in self.b.iter().zip(&self.x_past) {
            acc -= bj * xj;
        }
        push_front_slice(&mut self.u_past, u_now);
        push_front_slice(&mut self.x_past, acc);
        acc
    }
}

/// The newest `past.len()` values of `past` followed by `signal`, most recent first.
fn shift_in(past: &[f64], signal: &[f64]) -> Vec<f64> {
    (0..past.len())
        .map(|k| {
            if k < signal.len() {
                signal[signal.len() - 1 - k]
            } else {
                past[k - signal.len()]
            }
        })
        .collect()
}

/// A backlash overflow error, with the stability of the block that fed it: an unstable block
/// makes x grow until the branch polynomials overflow.
pub(crate) fn blame_feeding_block(err: Error, block: &LinearBlock, name: &str) -> Error {
    match err {
        Error::Model(msg) => Error::Model(format!(
            "{msg}; the {name} linear block has spectral radius {:.4} (stable needs < 1)",
            block.spectral_radius()
        )),
        other => other,
    }
}

/// An unstable block drives its output to inf/NaN: say so instead of returning garbage.
pub(crate) fn check_no_overflow(block: &LinearBlock, out: &[f64], name: &str) -> Result<()> {
    if let Some(i) = out.iter().position(|v| !v.is_finite()) {
        return Err(overflow(block, name, i));
    }
    Ok(())
}

/// The error of `check_no_overflow` for sample `i` of the output `name`.
pub(crate) fn overflow(block: &LinearBlock, name: &str, i: usize) -> Error {
    Error::Model(format!(
        "simulation diverged: {name}[{i}] overflowed; the linear block has spectral \
         radius {:.4} (stable needs < 1); use a stable block or a shorter record",
        block.spectral_radius()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_params::example1_linear as example1;

    #[test]
    fn continuing_from_the_final_state_equals_one_long_run() {
        let g = example1();
        let u: Vec<f64> = (0..50)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) / 5.0)
            .collect();
        let whole = g.simulate(&u, &g.rest_state()).unwrap();
        for cut in [0usize, 1, 2, 3, 49] {
            let first = g.simulate(&u[..cut.max(1)], &g.rest_state()).unwrap();
            let cut = cut.max(1);
            let s = g.state_after(&g.rest_state(), &u[..cut], &first);
            let rest = g.simulate(&u[cut..], &s).unwrap();
            for (k, v) in rest.iter().enumerate() {
                assert!((v - whole[cut + k]).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn denominator_orders_above_the_cap_are_refused() {
        assert!(LinearBlock::new(vec![1.0], vec![1e-3; MAX_ORDER]).is_ok());
        let err = LinearBlock::new(vec![1.0], vec![1e-3; 2000]).unwrap_err();
        assert!(matches!(err, Error::Model(ref m) if m.contains("at most 200")));
        // a long numerator has no poles to compute
        assert!(LinearBlock::new(vec![1e-3; 2000], vec![0.5]).is_ok());
        let s = crate::identify::Structure::new(1_000_000_000, 2, 3, 0, 0, false, false);
        assert!(matches!(s, Err(Error::Model(ref m)) if m.starts_with("na = 1000000000")));
    }

    #[test]
    fn poles_and_stability() {
        let g = example1();
        // z^2 - 0.2 z + 0.35: |p|^2 = 0.35
        assert!((g.spectral_radius() - 0.35f64.sqrt()).abs() < 1e-12);
        assert!(g.is_stable());
        let unstable = LinearBlock::new(vec![1.0], vec![-1.5]).unwrap();
        assert!(!unstable.is_stable());
        let u = vec![1.0; 3000];
        let err = unstable.simulate(&u, &unstable.rest_state()).unwrap_err();
        assert!(matches!(err, Error::Model(_)));
    }

    #[test]
    fn bad_parameters_and_states_are_refused() {
        assert!(matches!(
            LinearBlock::new(vec![], vec![]),
            Err(Error::Model(_))
        ));
        assert!(matches!(
            LinearBlock::new(vec![f64::NAN], vec![]),
            Err(Error::Model(_))
        ));
        let g = example1();
        let bad = LinearState {
            u_past: vec![0.0],
            x_past: vec![0.0, 0.0],
        };
        assert!(matches!(g.simulate(&[1.0], &bad), Err(Error::Data(_))));
        assert!(matches!(
            g.simulate(&[], &g.rest_state()),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            g.simulate(&[f64::INFINITY], &g.rest_state()),
            Err(Error::Data(_))
        ));
    }
    #[test]
    fn feedthrough_adds_a0_u_now_in_every_recursion() {
        let u: Vec<f64> = (0..40)
            .map(|k| ((k * 37 % 11) as f64 - 5.0) / 5.0)
            .collect();
        // orders with a fixed recursion (2, 2) and the dynamic one (3, 3)
        for (a, b) in [
            (vec![0.7, 0.5], vec![-0.2, 0.35]),
            (vec![0.3, 0.2, 0.1], vec![-0.5, 0.2, 0.05]),
        ] {
            let g = LinearBlock::with_feedthrough(0.4, a.clone(), b.clone()).unwrap();
            assert_eq!(g.feedthrough(), Some(0.4));
            let state = LinearState {
                u_past: vec![0.3; a.len()],
                x_past: vec![-0.2; b.len()],
            };
            let x = g.simulate(&u, &state).unwrap();
            // hand loop of x(t) = a0 u(t) + sum a_i u(t-i) - sum b_j x(t-j)
            let mut want = Vec::new();
            for t in 0..u.len() {
                let past = |s: &Vec<f64>, k: usize, before: &Vec<f64>| {
                    if k <= t {
                        s[t - k]
                    } else {
                        before[k - t - 1]
                    }
                };
                let mut v = 0.4 * u[t];
                for (i, ai) in a.iter().enumerate() {
                    v += ai * past(&u, i + 1, &state.u_past);
                }
                for (j, bj) in b.iter().enumerate() {
                    v -= bj * past(&want, j + 1, &state.x_past);
                }
                want.push(v);
                assert!((g.output_at(&u, &want, t, &state) - v).abs() < 1e-14);
            }
            for (p, q) in x.iter().zip(&want) {
                assert!((p - q).abs() < 1e-13, "{p} vs {q}");
            }
        }
        assert!(LinearBlock::with_feedthrough(f64::NAN, vec![1.0], vec![]).is_err());
        assert!(LinearBlock::with_feedthrough(1.0, vec![], vec![]).is_err());
        assert_eq!(example1().feedthrough(), None);
    }
}
