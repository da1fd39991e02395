//! Simulated output and its exact derivatives with respect to every parameter, for the
//! output-error (simulation error) refinement. Sensitivity recursions run beside the model:
//!   dx(t)/da_i = u(t-i) - sum_j b_j dx(t-j)/da_i,   dx(t)/db_j = -x(t-j) - sum_k b_k dx(t-k)/db_j,
//!   on L: dy = L'(xi1) dx + [dL/dc_L = L'(xi1), dL/dm_Li = xi1^i],
//!   on R: dy = R'(xi2) dx + [dR/dc_R = -R'(xi2), dR/dm_Ri = xi2^i],
//!   holding: dy(t) = dy(t-1);
//!   sandwich: dw(t) = sum_i r_i dy(t-i) - sum_j s_j dw(t-j) + [dw/dr_i = y(t-i), dw/ds_j = -w(t-j)].
//! Column order: a_1..a_na, b_1..b_nb, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn, then for the
//! sandwich r_2..r_nr, s_1..s_ns (m_L1 = 1 and r_1 = 1 are fixed).

use crate::backlash::GeneralBacklash;
use crate::error::{Error, Result};
use crate::linear::LinearBlock;
use crate::signal::check_signal;

/// Output and row-major Jacobian (rows = samples, cols = parameters).
#[derive(Debug, Clone, PartialEq)]
pub struct Sensitivity {
    pub output: Vec<f64>,
    pub jacobian: Vec<f64>,
    pub cols: usize,
}

/// Column layout of the backlash and linear parameters.
struct Layout {
    na: usize,
    nb: usize,
    n: usize,
}

impl Layout {
    fn linear(&self) -> usize {
        self.na + self.nb
    }
    fn c_l(&self) -> usize {
        self.linear()
    }
    fn m_l(&self, i: usize) -> usize {
        self.c_l() + i - 1 // i = 2..n
    }
    fn m_r1(&self) -> usize {
        self.linear() + self.n
    }
    fn c_r(&self) -> usize {
        self.m_r1() + 1
    }
    fn m_r(&self, i: usize) -> usize {
        self.c_r() + i - 1 // i = 2..n
    }
    fn cols(&self) -> usize {
        self.linear() + 2 * self.n + 1
    }
}

/// x and y of the cascade with dx/dtheta (linear columns) and dy/dtheta (all backlash-model
/// columns, `cols` wide) in row-major order.
fn backlash_chain(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
    cols: usize,
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>, Layout)> {
    let n = backlash.left().coefficients().len();
    if backlash.right().coefficients().len() != n {
        return Err(Error::Model("both branches need the same degree n".into()));
    }
    let lay = Layout {
        na: linear.na(),
        nb: linear.nb(),
        n,
    };
    let b = linear.b();
    let nl = lay.linear();
    let len = u.len();
    let x = linear.simulate(u, &linear.rest_state())?;
    let mut dx = vec![0.0; len * nl];
    let mut y = vec![0.0; len];
    let mut dy = vec![0.0; len * cols];
    let mut y_prev = 0.0;
    for t in 0..len {
        // dx(t)
        for k in 0..nl {
            let mut acc = if k < lay.na {
                let i = k + 1;
                if i <= t {
                    u[t - i]
                } else {
                    0.0
                }
            } else {
                let j = k - lay.na + 1;
                if j <= t {
                    -x[t - j]
                } else {
                    0.0
                }
            };
            for (jj, bj) in b.iter().enumerate() {
                let lagj = jj + 1;
                if lagj <= t {
                    acc -= bj * dx[(t - lagj) * nl + k];
                }
            }
            dx[t * nl + k] = acc;
        }
        let yt = backlash.step(x[t], y_prev);
        let l = backlash.left().value(x[t]);
        let row = t * cols;
        if l <= y_prev {
            let xi1 = x[t] + backlash.c_left();
            let slope = backlash.left().slope(x[t]);
            for k in 0..nl {
                dy[row + k] = slope * dx[t * nl + k];
            }
            dy[row + lay.c_l()] = slope;
            let mut p = xi1;
            for i in 2..=n {
                p *= xi1;
                dy[row + lay.m_l(i)] = p;
            }
        } else if backlash.right().value(x[t]) >= y_prev {
            let xi2 = x[t] - backlash.c_right();
            let slope = backlash.right().slope(x[t]);
            for k in 0..nl {
                dy[row + k] = slope * dx[t * nl + k];
            }
            dy[row + lay.c_r()] = -slope;
            dy[row + lay.m_r1()] = xi2;
            let mut p = xi2;
            for i in 2..=n {
                p *= xi2;
                dy[row + lay.m_r(i)] = p;
            }
        } else if t > 0 {
            let (prev, this) = dy.split_at_mut(row);
            this[..cols].copy_from_slice(&prev[row - cols..row]);
        }
        y[t] = yt;
        y_prev = yt;
    }
    Ok((x, y, dy, lay))
}

/// The cascade output y and d y / d theta.
pub fn cascade_sensitivity(
    linear: &LinearBlock,
    backlash: &GeneralBacklash,
    u: &[f64],
) -> Result<Sensitivity> {
    check_signal("u", u)?;
    let cols = linear.na() + linear.nb() + 2 * backlash.left().coefficients().len() + 1;
    let (_, y, dy, lay) = backlash_chain(linear, backlash, u, cols)?;
    debug_assert_eq!(lay.cols(), cols);
    Ok(Sensitivity {
        output: y,
        jacobian: dy,
        cols,
    })
}

/// The sandwich output w and d w / d theta.
pub fn sandwich_sensitivity(
    input_linear: &LinearBlock,
    backlash: &GeneralBacklash,
    output_linear: &LinearBlock,
    u: &[f64],
) -> Result<Sensitivity> {
    check_signal("u", u)?;
    let (r, s) = (output_linear.a(), output_linear.b());
    let (nr, ns) = (r.len(), s.len());
    let inner =
        input_linear.na() + input_linear.nb() + 2 * backlash.left().coefficients().len() + 1;
    let cols = inner + (nr - 1) + ns;
    let (_, y, dy, _) = backlash_chain(input_linear, backlash, u, cols)?;
    let len = u.len();
    let mut w = vec![0.0; len];
    let mut dw = vec![0.0; len * cols];
    for t in 0..len {
        let row = t * cols;
        let mut wt = 0.0;
        for (ii, ri) in r.iter().enumerate() {
            let i = ii + 1;
            if i <= t {
                wt += ri * y[t - i];
                for k in 0..cols {
                    dw[row + k] += ri * dy[(t - i) * cols + k];
                }
                if i >= 2 {
                    dw[row + inner + i - 2] += y[t - i];
                }
            }
        }
        for (jj, sj) in s.iter().enumerate() {
            let j = jj + 1;
            if j <= t {
                wt -= sj * w[t - j];
                for k in 0..cols {
                    dw[row + k] -= sj * dw[(t - j) * cols + k];
                }
                dw[row + inner + nr - 1 + jj] -= w[t - j];
            }
        }
        w[t] = wt;
    }
    crate::linear::check_no_overflow(output_linear, &w, "w")?;
    Ok(Sensitivity {
        output: w,
        jacobian: dw,
        cols,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| ((k as f64) * 0.61).sin() * 0.9 + ((k as f64) * 0.17).cos() * 0.3)
            .collect()
    }

    /// Parameter vector in the column order, and a model from it.
    fn sandwich_from(theta: &[f64]) -> (LinearBlock, GeneralBacklash, LinearBlock) {
        let lin = LinearBlock::new(theta[0..2].to_vec(), theta[2..4].to_vec()).unwrap();
        let bl = GeneralBacklash::from_estimate(
            theta[4],
            theta[8],
            vec![1.0, theta[5], theta[6]],
            vec![theta[7], theta[9], theta[10]],
        )
        .unwrap();
        let out = LinearBlock::new(vec![1.0, theta[11]], theta[12..14].to_vec()).unwrap();
        (lin, bl, out)
    }

    #[test]
    fn sandwich_jacobian_matches_central_differences() {
        // Example 2's parameters: a1 a2 b1 b2 cL mL2 mL3 mR1 cR mR2 mR3 r2 s1 s2
        let theta = [
            0.8, 0.2, 0.2, -0.2, 0.4, 0.1, 0.3, 0.75, 0.5, 0.2, 0.6, 0.15, -0.2, 0.35,
        ];
        let u = input(400);
        let (lin, bl, out) = sandwich_from(&theta);
        let sens = sandwich_sensitivity(&lin, &bl, &out, &u).unwrap();
        assert_eq!(sens.cols, theta.len());
        let h = 1e-7;
        for k in 0..theta.len() {
            let (mut up, mut dn) = (theta, theta);
            up[k] += h;
            dn[k] -= h;
            let (l1, b1, o1) = sandwich_from(&up);
            let (l2, b2, o2) = sandwich_from(&dn);
            let w1 = sandwich_sensitivity(&l1, &b1, &o1, &u).unwrap().output;
            let w2 = sandwich_sensitivity(&l2, &b2, &o2, &u).unwrap().output;
            // Samples where a switch moves between +h and -h differ; most must agree closely.
            let mut close = 0;
            for t in 0..u.len() {
                let fd = (w1[t] - w2[t]) / (2.0 * h);
                if (fd - sens.jacobian[t * sens.cols + k]).abs() < 1e-5 {
                    close += 1;
                }
            }
            assert!(
                close >= u.len() * 97 / 100,
                "parameter {k}: {close} of {}",
                u.len()
            );
        }
    }

    #[test]
    fn cascade_output_equals_the_model_simulation() {
        let lin = LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap();
        let bl = GeneralBacklash::new(0.6, 0.5, vec![1.0, -0.3, 0.3], vec![1.5, 0.4, 0.2]).unwrap();
        let u = input(500);
        let m = crate::CascadeModel::new(lin.clone(), bl.clone());
        let sens = cascade_sensitivity(&lin, &bl, &u).unwrap();
        assert_eq!(sens.output, m.simulate(&u, &m.rest_state()).unwrap());
        assert_eq!(sens.cols, 11);
    }
}
