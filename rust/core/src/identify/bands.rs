//! Prediction bands: the first-order variance of the simulated output under a parameter
//! covariance, var(y_hat(t)) = J_t Sigma J_t^T with J_t = d y_hat(t) / d theta the output
//! sensitivity row at the model's parameters (the recursions of `sensitivity`, theta's
//! layout `problem::Layout`), one quadratic form per sample, no N x p matrix.
//!
//! From a given physical state (the linear blocks' pasts and the backlash memory) the walk
//! runs from the state's observer-canonical parameters x0 (and w0) (`initial::free_terms`),
//! which depend on the model's coefficients: x0_k = sum_{i>=k} a_i u_past[i-k] -
//! sum_{j>=k} b_j x_past[j-k], likewise w0 with r, s and the output block's pasts. The
//! state itself is taken as known; its part of the row is the chain rule
//! dy/dtheta += sum_k dy/dx0_k dx0_k/dtheta (and w0), the backlash memory contributing
//! nothing (fixed).

use crate::error::{Error, Result};
use crate::guard;
use crate::identify::initial::{free_terms, InitialState, Start};
use crate::identify::sensitivity::{
    branch_degree, cascade_cols, sandwich_cols, walk_cascade, walk_sandwich, Move,
};
use crate::model::backlash::GeneralBacklash;
use crate::model::linear::{LinearBlock, LinearState};
use crate::model::signal::check_signal;
use crate::model::{CascadeState, SandwichState};

/// The simulated output and its first-order variance, sample by sample.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputVariance {
    pub output: Vec<f64>,
    pub variance: Vec<f64>,
}

/// `cov` must be a finite p x p matrix (row-major).
fn check_cov(cov: &[f64], p: usize) -> Result<()> {
    if cov.len() != p * p {
        return Err(Error::Data(format!(
            "covariance has {} values but the model has {p} parameters: give a {p} x {p} \
             matrix in theta's layout",
            cov.len()
        )));
    }
    if cov.iter().any(|v| !v.is_finite()) {
        return Err(Error::Data(
            "covariance holds a non-finite value: give the fit's finite covariance".into(),
        ));
    }
    Ok(())
}

/// r^T S r for a p x p row-major S.
#[inline]
fn quadratic(row: &[f64], cov: &[f64]) -> f64 {
    let p = row.len();
    let mut acc = 0.0;
    for (i, ri) in row.iter().enumerate() {
        if *ri == 0.0 {
            continue;
        }
        let s = &cov[i * p..(i + 1) * p];
        let mut inner = 0.0;
        for (sij, rj) in s.iter().zip(row) {
            inner += sij * rj;
        }
        acc += ri * inner;
    }
    acc
}

/// d x0_k / d (a, b) of `free_terms` as rows (k = 1..n) over theta's `p` columns, the block's
/// a at `a_col`, its b at `b_col`; `skip_first_a` leaves out a_1 (the sandwich's r_1 = 1 is
/// fixed, theta holds r_2..).
fn free_term_rows(
    block: &LinearBlock,
    state: &LinearState,
    a_col: usize,
    b_col: usize,
    skip_first_a: bool,
    p: usize,
) -> Vec<Vec<f64>> {
    let (na, nb) = (block.na(), block.nb());
    let n = na.max(nb);
    (1..=n)
        .map(|k| {
            let mut row = vec![0.0; p];
            for i in k..=na {
                if skip_first_a && i == 1 {
                    continue;
                }
                let col = if skip_first_a {
                    a_col + i - 2
                } else {
                    a_col + i - 1
                };
                row[col] += state.u_past[i - k];
            }
            for j in k..=nb {
                row[b_col + j - 1] -= state.x_past[j - k];
            }
            row
        })
        .collect()
}

/// The model's part of a walk's row plus the chain rule through the state's parameters:
/// `chain` pairs a state column with its d (state value) / d theta row.
fn full_row(row: &[f64], chain: &[(usize, Vec<f64>)], out: &mut [f64]) {
    out.copy_from_slice(&row[..out.len()]);
    for (col, d) in chain {
        let g = row[*col];
        if g != 0.0 {
            for (o, v) in out.iter_mut().zip(d) {
                *o += g * v;
            }
        }
    }
}

fn check_linear_block(block: &LinearBlock, name: &str) -> Result<()> {
    if block.feedthrough().is_some() {
        return Err(Error::Model(format!(
            "the {name} has a feedthrough: the sensitivities take the block shifted by one \
             sample (the identification's form, `Structure.unpack`)"
        )));
    }
    Ok(())
}

/// The cascade's simulated output y_hat and var(y_hat(t)) = J_t Sigma J_t^T (`cov` = Sigma,
/// p x p row-major in theta's layout a, b, c_L, m_L2.., m_R1, c_R, m_R2..), from `state`
/// (None: rest), in one pass of the sensitivity recursions.
pub fn cascade_output_variance(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    state: Option<&CascadeState>,
    u: &[f64],
    cov: &[f64],
) -> Result<OutputVariance> {
    check_signal("u", u)?;
    check_linear_block(linear, "linear block")?;
    branch_degree(backlash)?;
    let p = cascade_cols(linear, backlash);
    check_cov(cov, p)?;
    let (initial, chain) = match state {
        Some(st) => {
            linear.check_state(&st.linear, "initial_state")?;
            let x0 = free_terms(linear, &st.linear)?;
            let d = free_term_rows(linear, &st.linear, 0, linear.na(), false, p);
            let init = InitialState {
                x0,
                y_prev: st.y_prev,
                w0: vec![],
            };
            (Some(init), d)
        }
        None => (None, vec![]),
    };
    let start = initial.as_ref().map(|st| Start { state: st, col: p });
    let chain: Vec<(usize, Vec<f64>)> = chain
        .into_iter()
        .enumerate()
        .map(|(k, d)| (p + k, d))
        .collect();
    let mut out = OutputVariance {
        output: guard::buffer(u.len(), "the simulated output")?,
        variance: guard::buffer(u.len(), "the output variance")?,
    };
    let mut row = vec![0.0; p];
    let mut last = f64::NAN;
    walk_cascade(linear, backlash, start.as_ref(), u, |t, yt, mv, dy| {
        if t % guard::CHUNK == 0 {
            guard::check()?;
        }
        // a hold repeats the last row (dy(t) = dy(t-1)), so its variance too
        if mv != Move::Hold || t == 0 {
            full_row(dy, &chain, &mut row);
            last = quadratic(&row, cov);
        }
        out.output.push(yt);
        out.variance.push(last);
        Ok(())
    })?;
    finite(out)
}

/// The sandwich's simulated output w_hat and var(w_hat(t)) = J_t Sigma J_t^T (`cov` =
/// Sigma, p x p row-major in theta's layout: the cascade's, then r_2..r_nr, s_1..s_ns), from
/// `state` (None: rest), in one pass of the sensitivity recursions.
pub fn sandwich_output_variance(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    state: Option<&SandwichState>,
    u: &[f64],
    cov: &[f64],
) -> Result<OutputVariance> {
    check_signal("u", u)?;
    check_linear_block(input_linear, "input block")?;
    check_linear_block(output_linear, "output block")?;
    branch_degree(backlash)?;
    if output_linear.na() == 0 {
        return Err(Error::Model(
            "the output block needs r_1 (the normalised first coefficient)".into(),
        ));
    }
    let p = sandwich_cols(input_linear, backlash, output_linear);
    check_cov(cov, p)?;
    let inner = cascade_cols(input_linear, backlash);
    let (initial, chain) = match state {
        Some(st) => {
            input_linear.check_state(&st.input, "initial_state")?;
            output_linear.check_state(&st.output, "initial_state")?;
            let x0 = free_terms(input_linear, &st.input)?;
            let w0 = free_terms(output_linear, &st.output)?;
            let nx = x0.len();
            let nr = output_linear.na();
            let mut chain: Vec<(usize, Vec<f64>)> =
                free_term_rows(input_linear, &st.input, 0, input_linear.na(), false, p)
                    .into_iter()
                    .enumerate()
                    .map(|(k, d)| (p + k, d))
                    .collect();
            // w0 after x0 and y_prev
            chain.extend(
                free_term_rows(output_linear, &st.output, inner, inner + nr - 1, true, p)
                    .into_iter()
                    .enumerate()
                    .map(|(k, d)| (p + nx + 1 + k, d)),
            );
            let init = InitialState {
                x0,
                y_prev: st.output.u_past[0],
                w0,
            };
            (Some(init), chain)
        }
        None => (None, vec![]),
    };
    let start = initial.as_ref().map(|st| Start { state: st, col: p });
    let mut out = OutputVariance {
        output: guard::buffer(u.len(), "the simulated output")?,
        variance: guard::buffer(u.len(), "the output variance")?,
    };
    let mut row = vec![0.0; p];
    walk_sandwich(
        input_linear,
        backlash,
        output_linear,
        start.as_ref(),
        u,
        |t, wt, dw| {
            if t % guard::CHUNK == 0 {
                guard::check()?;
            }
            full_row(dw, &chain, &mut row);
            out.output.push(wt);
            out.variance.push(quadratic(&row, cov));
            Ok(())
        },
    )?;
    finite(out)
}

fn finite(out: OutputVariance) -> Result<OutputVariance> {
    if out.variance.iter().any(|v| !v.is_finite()) {
        return Err(crate::identify::sensitivity::overflowed());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::sensitivity::{cascade_sensitivity, sandwich_sensitivity};
    use crate::test_params::{example1, perturbed, sandwich_from, smooth_input, EXAMPLE2_THETA};
    use crate::{CascadeModel, SandwichModel};

    /// A symmetric positive definite p x p matrix with off-diagonal terms.
    fn spd(p: usize) -> Vec<f64> {
        let mut m = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                let l = |i: usize, j: usize| ((i * 7 + j * 3) % 5) as f64 * 0.1 - 0.2;
                m[i * p + j] = (0..p).map(|k| l(i, k) * l(j, k)).sum::<f64>() * 1e-4;
            }
            m[i * p + i] += 1e-4 * (1.0 + i as f64);
        }
        m
    }

    fn dense_variance(jac: &[f64], p: usize, cov: &[f64]) -> Vec<f64> {
        jac.chunks(p).map(|row| quadratic(row, cov)).collect()
    }

    fn close(a: &[f64], b: &[f64], rel: f64) {
        assert_eq!(a.len(), b.len());
        for (t, (x, y)) in a.iter().zip(b).enumerate() {
            assert!((x - y).abs() <= rel * y.abs().max(1e-300), "{t}: {x} {y}");
        }
    }

    #[test]
    fn cascade_variance_is_the_dense_quadratic_form() {
        let (lin, bl) = example1();
        let u = smooth_input(2000);
        let sens = cascade_sensitivity(&lin, &bl, &u).unwrap();
        let cov = spd(sens.cols);
        let band = cascade_output_variance(&lin, &bl, None, &u, &cov).unwrap();
        assert_eq!(band.output, sens.output);
        close(
            &band.variance,
            &dense_variance(&sens.jacobian, sens.cols, &cov),
            1e-12,
        );
        // the rest state given explicitly is rest
        let rest = CascadeModel::new(lin.clone(), bl.clone()).rest_state();
        let same = cascade_output_variance(&lin, &bl, Some(&rest), &u, &cov).unwrap();
        close(&same.variance, &band.variance, 1e-12);
    }

    #[test]
    fn sandwich_variance_is_the_dense_quadratic_form() {
        let (lin, bl, out) = sandwich_from(&perturbed(EXAMPLE2_THETA));
        let u = smooth_input(2000);
        let sens = sandwich_sensitivity(&lin, &bl, &out, &u).unwrap();
        let cov = spd(sens.cols);
        let band = sandwich_output_variance(&lin, &bl, &out, None, &u, &cov).unwrap();
        assert_eq!(band.output, sens.output);
        close(
            &band.variance,
            &dense_variance(&sens.jacobian, sens.cols, &cov),
            1e-12,
        );
    }

    /// Central differences of the model's simulation from a fixed physical state, theta
    /// perturbed one parameter at a time (`set` builds the model of a theta).
    fn fd_jacobian(
        theta: &[f64],
        u: &[f64],
        simulate: impl Fn(&[f64]) -> Vec<f64>,
    ) -> Vec<Vec<f64>> {
        let h = 1e-6;
        (0..theta.len())
            .map(|j| {
                let (mut up, mut dn) = (theta.to_vec(), theta.to_vec());
                up[j] += h;
                dn[j] -= h;
                let (yu, yd) = (simulate(&up), simulate(&dn));
                (0..u.len()).map(|t| (yu[t] - yd[t]) / (2.0 * h)).collect()
            })
            .collect()
    }

    /// The variance of a unit covariance on parameter j alone is J_tj^2: compare |J_tj| with
    /// finite differences, on the samples away from a switch (most of them).
    fn check_against_fd(var_of: impl Fn(usize) -> Vec<f64>, fd: &[Vec<f64>]) {
        for (j, col) in fd.iter().enumerate() {
            let var = var_of(j);
            let agree = col
                .iter()
                .zip(&var)
                .filter(|(d, v)| (d.abs() - v.sqrt()).abs() <= 1e-5 * (1.0 + d.abs()))
                .count();
            assert!(
                agree * 100 >= 98 * col.len(),
                "param {j}: {agree} of {}",
                col.len()
            );
        }
    }

    fn unit(p: usize, j: usize) -> Vec<f64> {
        let mut c = vec![0.0; p * p];
        c[j * p + j] = 1.0;
        c
    }

    #[test]
    fn cascade_variance_from_a_state_follows_the_state_through_the_coefficients() {
        let (lin, bl) = example1();
        let u = smooth_input(400);
        let state = CascadeState {
            linear: LinearState {
                u_past: vec![0.8, -0.3],
                x_past: vec![1.1, 0.4],
            },
            y_prev: 0.2,
        };
        let theta = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.5, 0.4, 0.2];
        let model_of = |t: &[f64]| {
            CascadeModel::new(
                LinearBlock::new(t[0..2].to_vec(), t[2..4].to_vec()).unwrap(),
                GeneralBacklash::from_estimate(
                    t[4],
                    t[8],
                    vec![1.0, t[5], t[6]],
                    vec![t[7], t[9], t[10]],
                )
                .unwrap(),
            )
        };
        let fd = fd_jacobian(&theta, &u, |t| model_of(t).simulate(&u, &state).unwrap());
        let m = model_of(&theta);
        let y = m.simulate(&u, &state).unwrap();
        check_against_fd(
            |j| {
                let band =
                    cascade_output_variance(&lin, &bl, Some(&state), &u, &unit(11, j)).unwrap();
                close(&band.output, &y, 1e-12);
                band.variance
            },
            &fd,
        );
    }

    #[test]
    fn sandwich_variance_from_a_state_follows_the_state_through_the_coefficients() {
        let theta = EXAMPLE2_THETA;
        let (lin, bl, out) = sandwich_from(&theta);
        let u = smooth_input(400);
        let state = SandwichState {
            input: LinearState {
                u_past: vec![0.8, -0.3],
                x_past: vec![1.1, 0.4],
            },
            output: LinearState {
                u_past: vec![0.3, 0.1],
                x_past: vec![0.5, -0.2],
            },
        };
        let model_of = |t: &[f64]| {
            let (a, b, c) = sandwich_from(t);
            SandwichModel::new(a, b, c)
        };
        let fd = fd_jacobian(&theta, &u, |t| model_of(t).simulate(&u, &state).unwrap());
        let w = model_of(&theta).simulate(&u, &state).unwrap();
        check_against_fd(
            |j| {
                let band =
                    sandwich_output_variance(&lin, &bl, &out, Some(&state), &u, &unit(14, j))
                        .unwrap();
                close(&band.output, &w, 1e-12);
                band.variance
            },
            &fd,
        );
    }

    #[test]
    fn bad_covariances_and_states_are_refused() {
        let (lin, bl) = example1();
        let u = smooth_input(50);
        assert!(matches!(
            cascade_output_variance(&lin, &bl, None, &u, &[1.0; 10]),
            Err(Error::Data(_))
        ));
        let mut cov = spd(11);
        cov[3] = f64::NAN;
        assert!(matches!(
            cascade_output_variance(&lin, &bl, None, &u, &cov),
            Err(Error::Data(_))
        ));
        let short = CascadeState {
            linear: LinearState {
                u_past: vec![0.0],
                x_past: vec![0.0, 0.0],
            },
            y_prev: 0.0,
        };
        assert!(matches!(
            cascade_output_variance(&lin, &bl, Some(&short), &u, &spd(11)),
            Err(Error::Data(_))
        ));
    }
}
