//! The output-error gradient g = J^T r (J = d y_sim / d theta, r = y - y_sim) and the cost
//! sum r^2 at an estimate, without the Jacobian or its factor. LM uses it to test the end of
//! a short step against the factor of the Jacobian folded where the step began (`refine.py`).
//!
//! The cascade's gradient runs in reverse (the adjoint of the recursions in `sensitivity`):
//!   lambda(t) = r(t) + [t+1 holds] lambda(t+1): the residuals that see dy(t), since a held
//!     sample repeats the row dy of the last move;
//!   on L at t: mu(t) = lambda(t) L'(xi1), g[c_L] += mu(t), g[m_Li] += lambda(t) xi1^i;
//!   on R at t: mu(t) = lambda(t) R'(xi2), g[c_R] -= mu(t), g[m_Ri] += lambda(t) xi2^i;
//!   nu = mu filtered backwards by 1/B (nu(t) = mu(t) - sum_k b_k nu(t+k)), the transpose of
//!     the causal 1/B that makes dx(t)/da_i = w_u(t-i), dx(t)/db_j = -w_x(t-j);
//!   g[a_i] = sum_t nu(t) u(t-i),   g[b_j] = -sum_t nu(t) x(t-j).
//! With an initial state (`initial`): g[x0_k] = nu(k) (x0_k enters x as u enters through a_i)
//! and g[y_prev] = lambda(1) if the first sample holds, else 0 (paper time).
//! The forward pass is the model's own simulation; one backward pass does the rest, with
//! the case flags f1, f2 recomputed as the simulation's, in straight-line code (both
//! branches' terms, weighted by f1 and f2). The sandwich's output
//! filter mixes the rows of every lag, so its gradient sums the forward rows of
//! `sensitivity::walk_sandwich` instead.

use crate::error::Result;
use crate::identify::initial::{simulate_from, start_cols, Start};
use crate::identify::sensitivity::{
    branch_degree, cascade_cols, check_pair, overflowed, sandwich_cols, walk_sandwich,
};
use crate::model::backlash::GeneralBacklash;
use crate::model::linear::LinearBlock;
use crate::model::switching::switching;

/// g = J^T r over the samples t >= warmup and the cost sum r^2.
#[derive(Debug, Clone, PartialEq)]
pub struct OeGradient {
    pub gradient: Vec<f64>,
    pub cost: f64,
}

impl OeGradient {
    fn new(cols: usize) -> Self {
        Self {
            gradient: vec![0.0; cols],
            cost: 0.0,
        }
    }

    /// Refused when the gradient or the cost overflowed (as the output-error factors).
    fn finished(self) -> Result<Self> {
        if !self.cost.is_finite() || self.gradient.iter().any(|v| !v.is_finite()) {
            return Err(overflowed());
        }
        Ok(self)
    }
}

/// `OeGradient` of the cascade, by the reverse recursion of the module header.
pub fn cascade_oe_gradient(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    check_pair(u, y, "y")?;
    cascade_oe_gradient_from(linear, backlash, None, u, y, warmup)
}

/// `cascade_oe_gradient` of a record checked before (`Problem`) from an initial state (its columns after the model's), or
/// from rest (None).
pub(crate) fn cascade_oe_gradient_from(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    start: Option<&Start>,
    u: &[f64],
    y: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    branch_degree(backlash)?;
    // forward: the model's own simulation; backward: its case flags f1 (on L), f2 (on R)
    // recomputed sample by sample as `CascadeModel::simulate_internals` has them
    let x = match start {
        None => linear.simulate(u, &linear.rest_state())?,
        Some(st) => simulate_from(linear, u, &st.state.x0)?,
    };
    let y0 = start.map_or(0.0, |st| st.state.y_prev);
    let y_sim = backlash.simulate(&x, y0)?;
    let reverse = Reverse {
        linear,
        backlash,
        u,
        y,
        x: &x,
        y_sim: &y_sim,
        warmup,
        start,
    };
    let out = match backlash.padded_step() {
        Some(padded) => reverse.run(|xt, yp| padded.switching(xt, yp)),
        None => reverse.run(|xt, yp| switching(backlash, xt, yp)),
    };
    out.finished()
}

/// The backward pass of `cascade_oe_gradient` over a simulated record.
struct Reverse<'a> {
    linear: &'a LinearBlock,
    backlash: &'a GeneralBacklash,
    u: &'a [f64],
    y: &'a [f64],
    x: &'a [f64],
    y_sim: &'a [f64],
    warmup: usize,
    start: Option<&'a Start<'a>>,
}

impl Reverse<'_> {
    fn run(&self, flags: impl Fn(f64, f64) -> (bool, bool)) -> OeGradient {
        let (u, y, x, y_sim) = (self.u, self.y, self.x, self.y_sim);
        let (a_len, b) = (self.linear.na(), self.linear.b());
        let bl = self.backlash;
        let (m_left, m_right) = (bl.left().coefficients(), bl.right().coefficients());
        let n = m_left.len();
        // columns: a, b, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn
        let (c_l, m_r1) = (a_len + b.len(), a_len + b.len() + n);
        let (c_left, c_right) = (bl.c_left(), bl.c_right());
        let model = cascade_cols(self.linear, bl);
        let mut out = OeGradient::new(model + start_cols(self.start));
        let (nx, y0) = self.start.map_or((0, 0.0), |st| (st.nx(), st.state.y_prev));
        let g = &mut out.gradient;
        let mut cost = 0.0;
        let mut lambda = 0.0; // lambda(t + 1)
        let mut next_holds = 0.0; // 1 when t + 1 holds (0 past the record's end)
        let mut nu_lags = vec![0.0; b.len()]; // nu(t + 1), nu(t + 2), ..
        for t in (0..u.len()).rev() {
            let y_prev = if t > 0 { y_sim[t - 1] } else { y0 };
            let (f1, f2) = flags(x[t], y_prev);
            let r = if t >= self.warmup {
                y[t] - y_sim[t]
            } else {
                0.0
            };
            // both branches' terms, weighted by 0 or 1: straight-line code, no case to mispredict
            let (wl, wr) = (f64::from(u8::from(f1)), f64::from(u8::from(f2)));
            lambda = r + next_holds * lambda;
            let (lam_l, lam_r) = (wl * lambda, wr * lambda);
            let (xi_l, xi_r) = (x[t] + c_left, x[t] - c_right);
            // L'(xi) = sum_i i m_i xi^(i-1) beside the powers xi^i (p_l, p_r)
            let (mut p_l, mut p_r, mut slope_l, mut slope_r) = (1.0, 1.0, 0.0, 0.0);
            for i in 1..=n {
                let k = i as f64;
                slope_l += k * m_left[i - 1] * p_l;
                slope_r += k * m_right[i - 1] * p_r;
                p_l *= xi_l;
                p_r *= xi_r;
                if i >= 2 {
                    g[c_l + i - 1] += lam_l * p_l;
                    g[m_r1 + i] += lam_r * p_r;
                }
            }
            let (mu_l, mu_r) = (lam_l * slope_l, lam_r * slope_r);
            g[c_l] += mu_l;
            g[m_r1] += lam_r * xi_r;
            g[m_r1 + 1] -= mu_r;
            next_holds = 1.0 - wl - wr;
            // nu(t) = mu(t) - sum_k b_k nu(t + k): the transpose of the causal 1/B
            let mut nu = mu_l + mu_r;
            for (bk, v) in b.iter().zip(&nu_lags) {
                nu -= bk * v;
            }
            if !nu_lags.is_empty() {
                nu_lags.rotate_right(1);
                nu_lags[0] = nu;
            }
            for i in 1..=a_len.min(t) {
                g[i - 1] += nu * u[t - i];
            }
            if t < nx {
                g[model + t] += nu; // x0 enters x(t) as a_i u(t - i) does
            }
            for j in 1..=b.len().min(t) {
                g[a_len + j - 1] -= nu * x[t - j];
            }
            cost += r * r; // r = 0 before the warm-up ends
        }
        if nx > 0 {
            // dy/dy_prev is 1 over the first run of holds: the residuals lambda(0) collects
            g[model + nx] = next_holds * lambda;
        }
        out.cost = cost;
        out
    }
}

/// `OeGradient` of the sandwich: the forward rows dw(t) times the residuals.
pub fn sandwich_oe_gradient(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
    w: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    check_pair(u, w, "w")?;
    sandwich_oe_gradient_from(input_linear, backlash, output_linear, None, u, w, warmup)
}

/// `sandwich_oe_gradient` of a record checked before (`Problem`) from an initial state (its columns after the model's),
/// or from rest (None).
pub(crate) fn sandwich_oe_gradient_from(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    start: Option<&Start>,
    u: &[f64],
    w: &[f64],
    warmup: usize,
) -> Result<OeGradient> {
    let cols = sandwich_cols(input_linear, backlash, output_linear) + start_cols(start);
    let mut out = OeGradient::new(cols);
    walk_sandwich(
        input_linear,
        backlash,
        output_linear,
        start,
        u,
        |t, wt, row| {
            if t >= warmup {
                let r = w[t] - wt;
                for (gi, v) in out.gradient.iter_mut().zip(row) {
                    *gi += r * v;
                }
                out.cost += r * r;
            }
            Ok(())
        },
    )?;
    out.finished()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::sensitivity::tests::check_bad_records;
    use crate::identify::sensitivity::{cascade_sensitivity, sandwich_sensitivity, Sensitivity};
    use crate::test_params::{
        example1, noisy, perturbed, sandwich_from, smooth_input as input, EXAMPLE2_THETA,
    };
    use crate::CascadeModel;

    /// J^T r and the cost from the dense sensitivity written out.
    fn check_gradient(g: &OeGradient, sens: &Sensitivity, measured: &[f64], warmup: usize) {
        let p = sens.cols;
        let ts = warmup.min(measured.len())..measured.len();
        let r = |t: usize| measured[t] - sens.output[t];
        assert_eq!(g.gradient.len(), p);
        for j in 0..p {
            let want: f64 = ts.clone().map(|t| sens.jacobian[t * p + j] * r(t)).sum();
            let size: f64 = ts
                .clone()
                .map(|t| (sens.jacobian[t * p + j] * r(t)).abs())
                .sum();
            assert!(
                (g.gradient[j] - want).abs() <= 1e-12 * size.max(1e-300),
                "column {j}: {} against {want}",
                g.gradient[j]
            );
        }
        let cost: f64 = ts.clone().map(|t| r(t).powi(2)).sum();
        assert!((g.cost - cost).abs() <= 1e-12 * cost, "{} {cost}", g.cost);
    }

    fn moves(model: &CascadeModel, u: &[f64]) -> Vec<bool> {
        let sim = model.simulate_internals(u, &model.rest_state()).unwrap();
        sim.f1.iter().zip(&sim.f2).map(|(a, b)| *a || *b).collect()
    }

    #[test]
    fn cascade_gradient_is_the_dense_jacobian_times_the_residual() {
        let (lin, bl) = example1();
        let u = input(3000);
        let m = CascadeModel::new(lin.clone(), bl.clone());
        let y = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 3);
        // orders other than Example 1's too: FIR, longer denominators, degree 1 and 4
        let estimates = [
            (
                vec![0.65, 0.55],
                vec![-0.15, 0.3],
                vec![1.0, -0.25, 0.28],
                vec![1.45, 0.35, 0.25],
            ),
            (vec![0.6], vec![], vec![1.0], vec![1.3]),
            (
                vec![0.5, 0.3, 0.1],
                vec![-0.4, 0.2, 0.05],
                vec![1.0, 0.1, 0.2, 0.05],
                vec![1.2, 0.3, 0.1, 0.02],
            ),
        ];
        for (a, b, ml, mr) in estimates {
            let est_lin = LinearBlock::new(a, b).unwrap();
            let est = GeneralBacklash::from_estimate(0.55, 0.45, ml, mr).unwrap();
            let sens = cascade_sensitivity(&est_lin, &est, &u).unwrap();
            let mv = moves(&CascadeModel::new(est_lin.clone(), est.clone()), &u);
            assert!(
                mv.iter().any(|m| !m) && mv.iter().any(|m| *m),
                "holds and moves both"
            );
            for warmup in [0, 1, 600, 2999, 3000, 5000] {
                let g = cascade_oe_gradient(&est_lin, &est, &u, &y, warmup).unwrap();
                check_gradient(&g, &sens, &y, warmup);
            }
        }
    }

    #[test]
    fn sandwich_gradient_is_the_dense_jacobian_times_the_residual() {
        let u = input(3000);
        let (l2, b2, o2) = sandwich_from(&EXAMPLE2_THETA);
        let w = noisy(&sandwich_sensitivity(&l2, &b2, &o2, &u).unwrap().output, 5);
        let (l3, b3, o3) = sandwich_from(&perturbed(EXAMPLE2_THETA));
        let sens = sandwich_sensitivity(&l3, &b3, &o3, &u).unwrap();
        for warmup in [0, 2, 700] {
            let g = sandwich_oe_gradient(&l3, &b3, &o3, &u, &w, warmup).unwrap();
            check_gradient(&g, &sens, &w, warmup);
        }
    }

    #[test]
    fn gradients_report_overflow_and_bad_data() {
        check_bad_records(
            |lin, bl, u, y| cascade_oe_gradient(lin, bl, u, y, 0),
            |lin, bl, out, u, w| sandwich_oe_gradient(lin, bl, out, u, w, 0),
        );
    }
}
