//! The quasi-linear regressions of the identification algorithms: the cascade's data vector
//! phi(t) of eq (18) with target eq (21), the sandwich's Phi(t) of eq (33) with target eq (34),
//! and a plain ARX regression for the first linear estimate.
//!
//! Column order (eq 19 / 31): a_1..a_na, b_1..b_nb, c_1, m_L2..m_Ln, m_R1, c_2, m_R2..m_Rn,
//! then for the sandwich r_2..r_nr, s_1..s_ns; with m_L1 = 1, r_1 = 1, c_L = c_1,
//! c_R = c_2 / m_R1 (eq 20, 32).

use crate::backlash::GeneralBacklash;
use crate::error::{Error, Result};
use crate::linear::LinearBlock;
use crate::lstsq::{solve, LeastSquares};
use crate::signal::check_signal;
use crate::switching::switching;

/// Row-major regressor, target, and the internal signals the rows were built from.
#[derive(Debug, Clone, PartialEq)]
pub struct Regression {
    pub rows: usize,
    pub cols: usize,
    pub phi: Vec<f64>,
    pub target: Vec<f64>,
    /// Internal x of eq (22) for every sample.
    pub x: Vec<f64>,
    /// Switching functions eq (25)-(26) (case order of eq 1) for every sample.
    pub f1: Vec<bool>,
    pub f2: Vec<bool>,
}

impl Regression {
    /// Fraction of samples from `skip` on where the estimate's backlash moves (f1 or f2).
    pub fn moving_fraction(&self, skip: usize) -> f64 {
        let n = self.f1.len().saturating_sub(skip);
        if n == 0 {
            return 0.0;
        }
        let moving = self.f1[skip..]
            .iter()
            .zip(&self.f2[skip..])
            .filter(|(a, b)| **a || **b)
            .count();
        moving as f64 / n as f64
    }

    /// The least-squares solution; when the data do not determine it, the error also says on
    /// how many samples the current estimate moves the backlash.
    pub fn solve(&self, names: &[String], skip: usize) -> Result<LeastSquares> {
        solve(&self.phi, self.rows, self.cols, &self.target, names).map_err(|e| match e {
            Error::NotIdentifiable(msg) => Error::NotIdentifiable(format!(
                "{msg} (at the current estimate {:.1} % of samples move the backlash \
                 output: f1 or f2)",
                100.0 * self.moving_fraction(skip)
            )),
            other => other,
        })
    }
}

fn check_same_length(u: &[f64], y: &[f64], y_name: &str) -> Result<()> {
    if u.len() != y.len() {
        return Err(Error::Data(format!(
            "u has {} samples but {y_name} has {}: give input and output of the same record",
            u.len(),
            y.len()
        )));
    }
    Ok(())
}

/// Degree n of an estimate (both branches have n coefficients in the regressions).
fn degree(backlash: &GeneralBacklash) -> Result<usize> {
    let (nl, nr) = (
        backlash.left().coefficients().len(),
        backlash.right().coefficients().len(),
    );
    if nl != nr {
        return Err(Error::Model(format!(
            "the estimate's branches have degrees {nl} and {nr}: identification uses one degree n"
        )));
    }
    Ok(nl)
}

/// The backlash part of eq (18) at sample `tau` (the whole phi(tau) of the cascade), pushed
/// onto `row`: [u(tau-i) f1, -x(tau-j) f1, f1, xi1^i f1 (i>=2), x f2, -f2, xi2^i f2 (i>=2)].
#[allow(clippy::too_many_arguments)]
fn push_backlash_part(
    row: &mut Vec<f64>,
    na: usize,
    nb: usize,
    n: usize,
    backlash: &GeneralBacklash,
    u: &[f64],
    x: &[f64],
    tau: usize,
    f1: bool,
    f2: bool,
) {
    let lag = |s: &[f64], k: usize| if k <= tau { s[tau - k] } else { 0.0 };
    let (g1, g2) = (f1 as u8 as f64, f2 as u8 as f64);
    let xi1 = x[tau] + backlash.c_left(); // eq (23)
    let xi2 = x[tau] - backlash.c_right(); // eq (24)
    row.extend((1..=na).map(|i| lag(u, i) * g1));
    row.extend((1..=nb).map(|j| -lag(x, j) * g1));
    row.push(g1);
    row.extend((2..=n).map(|i| xi1.powi(i as i32) * g1));
    row.push(x[tau] * g2);
    row.push(-g2);
    row.extend((2..=n).map(|i| xi2.powi(i as i32) * g2));
}

/// Eq (18)-(21) at the current estimate: x by eq (22), f1, f2 by eq (25)-(26) with
/// `y_switch(t-1)` (the measured output as the paper reads, or the model's simulated output),
/// target y(t) - y(t-1)[1 - f1][1 - f2] with the measured y. Rows t < `skip` are left out.
pub fn cascade_regression(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    y: &[f64],
    y_switch: &[f64],
    skip: usize,
) -> Result<Regression> {
    check_signal("u", u)?;
    check_signal("y", y)?;
    check_same_length(u, y, "y")?;
    check_same_length(u, y_switch, "y_switch")?;
    let n = degree(backlash)?;
    let (na, nb) = (linear.na(), linear.nb());
    let cols = na + nb + 2 * n + 1;
    let x = linear.simulate(u, &linear.rest_state())?; // eq (22)
    let mut f1s = Vec::with_capacity(u.len());
    let mut f2s = Vec::with_capacity(u.len());
    let mut phi = Vec::with_capacity(u.len().saturating_sub(skip) * cols);
    let mut target = Vec::with_capacity(u.len().saturating_sub(skip));
    for t in 0..u.len() {
        let (ys_prev, y_prev) = if t > 0 {
            (y_switch[t - 1], y[t - 1])
        } else {
            (0.0, 0.0)
        };
        let (f1, f2) = switching(backlash, x[t], ys_prev); // eq (25)-(26)
        f1s.push(f1);
        f2s.push(f2);
        if t < skip {
            continue;
        }
        push_backlash_part(&mut phi, na, nb, n, backlash, u, &x, t, f1, f2);
        let hold = if f1 || f2 { 0.0 } else { y_prev };
        target.push(y[t] - hold); // eq (21)
    }
    Ok(Regression {
        rows: target.len(),
        cols,
        phi,
        target,
        x,
        f1: f1s,
        f2: f2s,
    })
}

/// Eq (33)-(34) at the current estimate: x by eq (22), the backlash output y by eq (35)
/// (the model's own, as y is not measured), f1, f2 from it; rows
/// [backlash part at t-1, y(t-2)..y(t-nr), -w(t-1)..-w(t-ns)] with the measured w, target
/// w(t) - y(t-2)[1 - f1(t-1)][1 - f2(t-1)]. Rows t < max(skip, 1) are left out.
pub fn sandwich_regression(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
    w: &[f64],
    skip: usize,
) -> Result<Regression> {
    check_signal("u", u)?;
    check_signal("w", w)?;
    check_same_length(u, w, "w")?;
    let n = degree(backlash)?;
    let (na, nb) = (input_linear.na(), input_linear.nb());
    let (nr, ns) = (output_linear.na(), output_linear.nb());
    let cols = na + nb + 2 * n + 1 + (nr - 1) + ns;
    let x = input_linear.simulate(u, &input_linear.rest_state())?; // eq (22)
    let y = backlash.simulate(&x, 0.0)?; // eq (35)
    let (f1s, f2s) = crate::cascade::switching_flags(backlash, &x, &y, 0.0);
    let lag = |s: &[f64], t: usize, k: usize| if k <= t { s[t - k] } else { 0.0 };
    let mut phi = Vec::with_capacity(u.len() * cols);
    let mut target = Vec::with_capacity(u.len());
    for t in skip.max(1)..u.len() {
        let tau = t - 1;
        push_backlash_part(
            &mut phi, na, nb, n, backlash, u, &x, tau, f1s[tau], f2s[tau],
        );
        phi.extend((2..=nr).map(|i| lag(&y, t, i)));
        phi.extend((1..=ns).map(|j| -lag(w, t, j)));
        let hold = if f1s[tau] || f2s[tau] {
            0.0
        } else {
            lag(&y, t, 2)
        };
        target.push(w[t] - hold); // eq (34)
    }
    Ok(Regression {
        rows: target.len(),
        cols,
        phi,
        target,
        x,
        f1: f1s,
        f2: f2s,
    })
}

/// ARX regression y(t) = sum a_i u(t-delay+1-i) - sum b_j y(t-j): rows
/// [u(t-delay)..u(t-delay-na+1), -y(t-1..t-nb)] for t >= skip, zero before the record.
/// Columns a_1..a_na, b_1..b_nb. The cascade has delay 1; the sandwich's two blocks delay 2.
pub fn arx_regression(
    u: &[f64],
    y: &[f64],
    na: usize,
    nb: usize,
    delay: usize,
    skip: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    check_signal("u", u)?;
    check_signal("y", y)?;
    check_same_length(u, y, "y")?;
    let lag = |s: &[f64], t: usize, k: usize| if k <= t { s[t - k] } else { 0.0 };
    let mut phi = Vec::with_capacity(u.len() * (na + nb));
    let mut target = Vec::with_capacity(u.len());
    for t in skip..u.len() {
        phi.extend((1..=na).map(|i| lag(u, t, delay + i - 1)));
        phi.extend((1..=nb).map(|j| -lag(y, t, j)));
        target.push(y[t]);
    }
    Ok((phi, target))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(p: usize) -> Vec<String> {
        (0..p).map(|j| format!("p{j}")).collect()
    }

    fn input(n: usize) -> Vec<f64> {
        // a deterministic, rich input in (-1, 1)
        let mut s = 12345u64;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn cascade_regression_is_exact_at_the_true_parameters() {
        // Example 1: at the true values eq (21) holds with e = 0, so LS returns theta exactly.
        let lin = LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap();
        let bl = GeneralBacklash::new(0.6, 0.5, vec![1.0, -0.3, 0.3], vec![1.5, 0.4, 0.2]).unwrap();
        let u = input(1500);
        let x = lin.simulate(&u, &lin.rest_state()).unwrap();
        let y = bl.simulate(&x, 0.0).unwrap();
        let reg = cascade_regression(&lin, &bl, &u, &y, &y, 0).unwrap();
        let ls = solve(&reg.phi, reg.rows, reg.cols, &reg.target, &names(reg.cols)).unwrap();
        // theta = a1 a2 b1 b2 c1 mL2 mL3 mR1 c2 mR2 mR3 with c2 = mR1 cR
        let want = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.75, 0.4, 0.2];
        for (g, w) in ls.theta.iter().zip(want) {
            assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
        }
    }

    #[test]
    fn sandwich_regression_is_exact_at_the_true_parameters() {
        let lin = LinearBlock::new(vec![0.8, 0.2], vec![0.2, -0.2]).unwrap();
        let bl = GeneralBacklash::new(0.4, 0.5, vec![1.0, 0.1, 0.3], vec![0.75, 0.2, 0.6]).unwrap();
        let out = LinearBlock::new(vec![1.0, 0.15], vec![-0.2, 0.35]).unwrap();
        let u = input(1500);
        let m = crate::SandwichModel::new(lin.clone(), bl.clone(), out.clone());
        let w = m.simulate(&u, &m.rest_state()).unwrap();
        let reg = sandwich_regression(&lin, &bl, &out, &u, &w, 0).unwrap();
        let ls = solve(&reg.phi, reg.rows, reg.cols, &reg.target, &names(reg.cols)).unwrap();
        // a1 a2 b1 b2 c1 mL2 mL3 mR1 c2 mR2 mR3 r2 s1 s2
        let want = [
            0.8, 0.2, 0.2, -0.2, 0.4, 0.1, 0.3, 0.75, 0.375, 0.2, 0.6, 0.15, -0.2, 0.35,
        ];
        for (g, w) in ls.theta.iter().zip(want) {
            assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
        }
    }

    #[test]
    fn arx_recovers_a_linear_block() {
        let lin = LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap();
        let u = input(300);
        let x = lin.simulate(&u, &lin.rest_state()).unwrap();
        let (phi, target) = arx_regression(&u, &x, 2, 2, 1, 0).unwrap();
        let ls = solve(&phi, target.len(), 4, &target, &names(4)).unwrap();
        for (g, w) in ls.theta.iter().zip([0.7, 0.5, -0.2, 0.35]) {
            assert!((g - w).abs() < 1e-12);
        }
    }
}
