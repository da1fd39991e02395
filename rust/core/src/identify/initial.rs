//! The initial state as parameters: records that do not start at rest.
//!
//! A linear block of eq (16) with na input and nb output coefficients (as the core sees it:
//! lags 1..; a feedthrough block counts a_0 among them) has a free response of
//! n = max(na, nb) degrees of freedom. Its past before the record (na inputs, nb outputs)
//! is over-parametrised when both orders are non-zero, and past outputs alone miss the free
//! responses of a block with na > nb (an FIR block has none). The parameters chosen here
//! are the n values of the observer-canonical state at the record's start:
//!
//!   x0_k = sum_{i>=k} a_i u(k-i) - sum_{j>=k} b_j x(k-j),   k = 1..n (paper time, the
//!   record starts at t = 1),
//!
//! the part of x(k) that the past contributes to eq (16); x0_1 = x(1) itself. The record
//! then runs the recursion from rest with x0_k added at its k-th sample:
//!
//!   x(t) = sum_{i<t} a_i u(t-i) - sum_{j<t} b_j x(t-j) + x0_t [t <= n].
//!
//! Every state of the block gives one such x0 (the formula) and x0 -> free response is
//! one-to-one (the free response is x0 filtered by 1/B, g(0) = 1), so the n parameters are
//! minimal and identifiable whatever the orders. The sensitivities stay in the existing
//! recursions: dx(t)/dx0_k = g(t-k) with g the impulse response of 1/B (one lagged signal,
//! like dx/da_i = w_u(t-i)), dx/da and dx/db keep their form (the recursion only reads
//! in-record values), and in the gradient's adjoint g[x0_k] = nu(k) (paper time).
//!
//! The backlash memory y(0) is `y_prev`: dy(t)/dy_prev = 1 while the backlash holds from the
//! first sample on and 0 from its first move (eq 1), since a hold repeats the last row.
//! The sandwich's output block gets the same m = max(nr, ns) values w0_1..w0_m (its a-side
//! coefficients counting the fixed first one). They are taken independent of y_prev (the
//! output block's past input): with ns >= 1 this is a reparametrisation of the physical
//! state; with an FIR output block (ns = 0) it is a superset by one value (a physical state
//! has w0_1 - y_prev r_1 fixed by the older past), harmless for the fit (the columns differ:
//! y_prev acts through the backlash, w0 only on w).
//!
//! Theta's layout: the model's parameters, then x0_1..x0_n, y_prev, then (sandwich)
//! w0_1..w0_m. The paper's iteration (eq 17-28, 29-36) stays a from-rest method: it ignores
//! these values (`Problem::iteration`).
//!
//! What the data can tell: y_prev acts only while the record starts holding; when the first
//! sample moves, its column is zero (its value does not matter, and a covariance should leave
//! it out). Likewise x0_k reaches y only through samples that move: an FIR block's x0_k acts
//! on x(k) alone, masked if the backlash holds there. A record that starts holding can also
//! be explained by y_prev alone (a hold at y_prev) or by a first move: a local minimum of the
//! output error from a start of zeros; y_prev = the first measured output is the better start
//! for a cascade. With a feedthrough the caller's record starts `shift` samples early with
//! zeros prepended to the measured output (exact from rest only): with a state those samples
//! belong in the warm-up.

use crate::error::Result;
use crate::guard;
use crate::model::linear::{check_no_overflow, LinearBlock, LinearState};

/// The initial-state values of a parameter vector: the input block's x0 (n values), the
/// backlash memory y(0), the sandwich output block's w0 (m values; empty for a cascade).
#[derive(Debug, Clone, PartialEq)]
pub struct InitialState {
    pub x0: Vec<f64>,
    pub y_prev: f64,
    pub w0: Vec<f64>,
}

/// The number of initial-state values of a block with `na` (lags 1..) and `nb` coefficients.
pub fn order(na: usize, nb: usize) -> usize {
    na.max(nb)
}

/// x0_k = sum_{i>=k} a_i u(k-i) - sum_{j>=k} b_j x(k-j) for k = 1..max(na, nb): the
/// parameters of a block's past `state` (the block without feedthrough, as the core sees it).
pub fn free_terms(block: &LinearBlock, state: &LinearState) -> Result<Vec<f64>> {
    block.check_state(state, "state")?;
    let (a, b) = (block.a(), block.b());
    let n = order(a.len(), b.len());
    Ok((1..=n)
        .map(|k| {
            let mut acc = 0.0;
            for i in k..=a.len() {
                acc += a[i - 1] * state.u_past[i - k];
            }
            for j in k..=b.len() {
                acc -= b[j - 1] * state.x_past[j - k];
            }
            acc
        })
        .collect())
}

/// Eq (16) over `u` from the state of parameters `x0` (k-th value added at the record's k-th
/// sample); fails if the output overflows. The block has no feedthrough (the core's form).
pub fn simulate_from(block: &LinearBlock, u: &[f64], x0: &[f64]) -> Result<Vec<f64>> {
    simulate_named(block, u, x0, "x")
}

/// `simulate_from`, an overflow reported for the output `name`.
pub(crate) fn simulate_named(
    block: &LinearBlock,
    u: &[f64],
    x0: &[f64],
    name: &str,
) -> Result<Vec<f64>> {
    let rest = block.rest_state();
    let mut x = guard::buffer(u.len(), name)?;
    for t in 0..u.len() {
        if t % guard::CHUNK == 0 {
            guard::check()?;
        }
        let v = block.output_at(u, &x, t, &rest) + x0.get(t).copied().unwrap_or(0.0);
        x.push(v);
    }
    check_no_overflow(block, &x, name)?;
    Ok(x)
}

/// Where the initial state's columns sit in theta (and the sensitivities): x0_1 at `col`,
/// then y_prev, then w0; with the values at which the recursions run.
pub(crate) struct Start<'a> {
    pub(crate) state: &'a InitialState,
    pub(crate) col: usize,
}

impl Start<'_> {
    pub(crate) fn nx(&self) -> usize {
        self.state.x0.len()
    }
    pub(crate) fn y_prev_col(&self) -> usize {
        self.col + self.nx()
    }
    pub(crate) fn w0_col(&self) -> usize {
        self.y_prev_col() + 1
    }
    /// The number of columns: x0, y_prev, w0.
    pub(crate) fn cols(&self) -> usize {
        self.nx() + 1 + self.state.w0.len()
    }
}

/// The columns of an optional start (0 without).
pub(crate) fn start_cols(start: Option<&Start>) -> usize {
    start.map_or(0, Start::cols)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_params::{example1_linear, smooth_input as input};

    #[test]
    fn a_simulation_from_the_terms_of_a_state_continues_a_longer_record() {
        let u = input(400);
        for lin in [
            example1_linear(),
            LinearBlock::new(vec![0.4, 0.3, -0.2], vec![0.5]).unwrap(),
            LinearBlock::new(vec![0.4], vec![-0.3, 0.2, 0.1]).unwrap(),
            LinearBlock::new(vec![0.4, 0.3], vec![]).unwrap(),
        ] {
            let whole = lin.simulate(&u, &lin.rest_state()).unwrap();
            let cut = 137;
            let state = lin.state_after(&lin.rest_state(), &u[..cut], &whole[..cut]);
            let x0 = free_terms(&lin, &state).unwrap();
            assert_eq!(x0.len(), order(lin.na(), lin.nb()));
            assert_eq!(x0[0], whole[cut]); // x0_1 = x(1): the past alone makes it
            let rest = simulate_from(&lin, &u[cut..], &x0).unwrap();
            let scale = whole.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (a, b) in rest.iter().zip(&whole[cut..]) {
                assert!((a - b).abs() <= 1e-12 * scale, "{a} {b}");
            }
        }
    }

    #[test]
    fn the_factor_from_a_state_is_the_same_on_two_threads() {
        use crate::identify::sensitivity::{cascade_oe_factor_from, sandwich_oe_factor_from};
        use crate::test_params::{example1, example2, noisy};
        let u = input(3000);
        let y = noisy(&u, 4);
        let (lin, bl) = example1();
        let state = InitialState {
            x0: vec![0.3, -0.1],
            y_prev: 0.2,
            w0: vec![],
        };
        let start = Start {
            state: &state,
            col: 11,
        };
        let one = cascade_oe_factor_from(&lin, &bl, Some(&start), &u, &y, 7, 1).unwrap();
        let two = cascade_oe_factor_from(&lin, &bl, Some(&start), &u, &y, 7, 2).unwrap();
        assert_eq!(one, two);
        assert_eq!(one.0.cols(), 14);
        let (lin, bl, out) = example2();
        let state = InitialState {
            w0: vec![0.1, -0.2],
            ..state
        };
        let start = Start {
            state: &state,
            col: 14,
        };
        let one = sandwich_oe_factor_from(&lin, &bl, &out, Some(&start), &u, &y, 7, 1).unwrap();
        let two = sandwich_oe_factor_from(&lin, &bl, &out, Some(&start), &u, &y, 7, 2).unwrap();
        assert_eq!(one, two);
        assert_eq!(one.0.cols(), 19);
    }
}
