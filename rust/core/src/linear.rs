//! The linear dynamic block of eq (16):
//!     x(t) = sum_{i=1}^{na} a_i u(t-i) - sum_{j=1}^{nb} b_j x(t-j).
//! The sandwich's output block (eq 29, coefficients r and s) is the same block.

use crate::error::{Error, Result};
use crate::polynomial::{modulus, monic_roots, Root};
use crate::signal::check_coefficients;

#[derive(Debug, Clone, PartialEq)]
pub struct LinearBlock {
    a: Vec<f64>,
    b: Vec<f64>,
}

/// The past of a linear block, most recent first: `u_past = [u(0), u(-1), ..]` (na values)
/// and `x_past = [x(0), x(-1), ..]` (nb values), where t = 1 is the first sample simulated.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearState {
    pub u_past: Vec<f64>,
    pub x_past: Vec<f64>,
}

impl LinearBlock {
    /// `a` (at least one coefficient) and `b` (possibly none: an FIR block), all finite.
    pub fn new(a: Vec<f64>, b: Vec<f64>) -> Result<Self> {
        check_coefficients("a", &a, false)?;
        check_coefficients("b", &b, true)?;
        Ok(LinearBlock { a, b })
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
        self.poles().into_iter().map(modulus).fold(0.0, f64::max)
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
        let mut acc = 0.0;
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
        crate::signal::check_signal("u", u)?;
        self.check_state(state, "state")?;
        let mut x = vec![0.0; u.len()];
        for t in 0..u.len() {
            x[t] = self.output_at(u, &x, t, state);
        }
        check_no_overflow(self, &x, "x")?;
        Ok(x)
    }

    /// The state after the record `u` -> `x` that started from `before`.
    pub fn state_after(&self, before: &LinearState, u: &[f64], x: &[f64]) -> LinearState {
        LinearState {
            u_past: shift_in(&before.u_past, u),
            x_past: shift_in(&before.x_past, x),
        }
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

/// An unstable block drives its output to inf/NaN: say so instead of returning garbage.
pub(crate) fn check_no_overflow(block: &LinearBlock, out: &[f64], name: &str) -> Result<()> {
    if let Some(i) = out.iter().position(|v| !v.is_finite()) {
        return Err(Error::Model(format!(
            "simulation diverged: {name}[{i}] overflowed; the linear block has spectral \
             radius {:.4} (stable needs < 1); use a stable block or a shorter record",
            block.spectral_radius()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example1() -> LinearBlock {
        LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap()
    }

    #[test]
    fn impulse_response_follows_eq16() {
        let g = example1();
        let mut u = vec![0.0; 5];
        u[0] = 1.0;
        let x = g.simulate(&u, &g.rest_state()).unwrap();
        // x1 = 0, x2 = 0.7, x3 = 0.5 + 0.2*0.7 = 0.64, x4 = 0.2*0.64 - 0.35*0.7
        assert_eq!(x[0], 0.0);
        assert!((x[1] - 0.7).abs() < 1e-15);
        assert!((x[2] - 0.64).abs() < 1e-15);
        assert!((x[3] - (0.2 * 0.64 - 0.35 * 0.7)).abs() < 1e-15);
    }

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
}
