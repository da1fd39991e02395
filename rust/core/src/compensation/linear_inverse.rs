//! The inverse of a linear block (eq 16) as a filter of the previewed target.
//!
//! With the lag coefficients c_0 = a_0 (the feedthrough, 0 without), c_i = a_i, the relative
//! degree d is the index of the first nonzero c. The block
//!     x(t) = sum_i c_i u(t-i) - sum_j b_j x(t-j)
//! solved for u(t) is
//!     u(t) = (v(t) + sum_j b_j v(t-j) - sum_{k>=1} c_{d+k} u(t-k)) / c_d,   v(t) = x(t+d):
//! an IIR filter whose poles are the block's zeros (the roots of c_d z^m + .. + c_{d+m},
//! m = na - d). Where a zero lies on or outside the unit circle (a non-minimum-phase block)
//! the exact inverse diverges; the stable approximation reflects each such zero z to
//! 1/conj(z) and rescales the numerator so that the static gain sum(c) is kept. A zero on
//! the circle (within 1e-9) cannot be reflected away: a ModelError.

use crate::error::{Error, Result};
use crate::model::polynomial::monic_roots;
use crate::model::{LinearBlock, LinearState};

/// y(t) = f u(t) + sum_i a_i u(t-i) - sum_j b_j y(t-j), its pasts held newest first.
#[derive(Debug, Clone, PartialEq)]
pub struct Filter {
    pub feedthrough: f64,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    /// [u(t-1), u(t-2), ..], a.len() values.
    pub in_past: Vec<f64>,
    /// [y(t-1), y(t-2), ..], b.len() values.
    pub out_past: Vec<f64>,
}

/// Newest value first: [v, past[0], ..] without the oldest.
fn push_front(past: &mut [f64], v: f64) {
    if let Some(last) = past.len().checked_sub(1) {
        past.copy_within(0..last, 1);
        past[0] = v;
    }
}

impl Filter {
    /// The block itself (eq 16) from `state`, run forward.
    pub fn forward(block: &LinearBlock, state: &LinearState) -> Self {
        Filter {
            feedthrough: block.a0(),
            a: block.a().to_vec(),
            b: block.b().to_vec(),
            in_past: state.u_past.clone(),
            out_past: state.x_past.clone(),
        }
    }

    /// The output for the input `u_now`; both join the pasts.
    #[inline]
    pub fn next(&mut self, u_now: f64) -> f64 {
        let mut acc = self.feedthrough * u_now;
        for (ai, ui) in self.a.iter().zip(&self.in_past) {
            acc += ai * ui;
        }
        for (bj, yj) in self.b.iter().zip(&self.out_past) {
            acc -= bj * yj;
        }
        push_front(&mut self.in_past, u_now);
        push_front(&mut self.out_past, acc);
        acc
    }
}

/// A block's inverse: the filter from v(t) = x(t+d) to u(t), its delay d and whether it is
/// the stable approximation (zeros reflected).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearInverse {
    pub filter: Filter,
    pub delay: usize,
    /// True when zeros on or outside the unit circle were reflected (an approximate inverse).
    pub approximate: bool,
}

/// Product of (z - r) over `roots` as the monic coefficients [p_1..p_m] of z^m + p_1 z^(m-1) ..
fn monic_from_roots(roots: &[(f64, f64)]) -> Vec<f64> {
    let mut re = vec![1.0];
    let mut im = vec![0.0];
    for &(rr, ri) in roots {
        let mut nre = vec![0.0; re.len() + 1];
        let mut nim = vec![0.0; im.len() + 1];
        for k in 0..re.len() {
            nre[k] += re[k];
            nim[k] += im[k];
            // - r * coef[k] into k + 1
            nre[k + 1] -= rr * re[k] - ri * im[k];
            nim[k + 1] -= rr * im[k] + ri * re[k];
        }
        re = nre;
        im = nim;
    }
    re[1..].to_vec()
}

impl LinearInverse {
    /// The inverse of `block`, its pasts taken from the block's: `v_past` = [x(d), x(d-1),
    /// ..] (nb values) and `u_past` = [u(0), u(-1), ..] (at least na - d values). `name`
    /// names the block in messages.
    pub fn new(block: &LinearBlock, v_past: &[f64], u_past: &[f64], name: &str) -> Result<Self> {
        let mut c = vec![block.a0()];
        c.extend_from_slice(block.a());
        let Some(delay) = c.iter().position(|&v| v != 0.0) else {
            return Err(Error::Model(format!(
                "the {name} block's numerator is zero: it has no inverse"
            )));
        };
        let c_d = c[delay];
        let mut tail: Vec<f64> = c[delay + 1..].iter().map(|v| v / c_d).collect();
        let mut gain = c_d;
        let zeros = monic_roots(&tail);
        let radius = |z: &(f64, f64)| z.0.hypot(z.1);
        if zeros.iter().any(|z| (radius(z) - 1.0).abs() <= 1e-9) {
            return Err(Error::Model(format!(
                "the {name} block has a zero on the unit circle: no stable inverse keeps its \
                 static gain; compensate a model without it"
            )));
        }
        let approximate = zeros.iter().any(|z| radius(z) > 1.0);
        if approximate {
            let reflected: Vec<(f64, f64)> = zeros
                .iter()
                .map(|&(re, im)| {
                    if re.hypot(im) > 1.0 {
                        let r2 = re * re + im * im;
                        (re / r2, im / r2)
                    } else {
                        (re, im)
                    }
                })
                .collect();
            let new_tail = monic_from_roots(&reflected);
            let static_old = c_d * (1.0 + tail.iter().sum::<f64>());
            let static_new = 1.0 + new_tail.iter().sum::<f64>();
            gain = static_old / static_new;
            tail = new_tail;
        }
        if !(gain.is_finite() && gain != 0.0) {
            return Err(Error::Model(format!(
                "the {name} block's inverse has no finite gain"
            )));
        }
        let m = tail.len();
        if v_past.len() != block.nb() || u_past.len() < m {
            return Err(Error::Data(format!(
                "the {name} block's inverse needs {} past outputs and {m} past inputs",
                block.nb()
            )));
        }
        Ok(LinearInverse {
            filter: Filter {
                feedthrough: 1.0 / gain,
                a: block.b().iter().map(|bj| bj / gain).collect(),
                b: tail,
                in_past: v_past.to_vec(),
                out_past: u_past[..m].to_vec(),
            },
            delay,
            approximate,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_params::{example1_linear, input};

    #[test]
    fn the_inverse_undoes_the_block_with_its_delay() {
        let blocks = [
            example1_linear(),
            LinearBlock::with_feedthrough(0.4, vec![0.3, 0.1], vec![-0.5, 0.2]).unwrap(),
            LinearBlock::new(vec![0.0, 0.0, 0.8, 0.3], vec![0.4]).unwrap(),
        ];
        for g in blocks {
            let x_d = input(400);
            let rest = g.rest_state();
            let inv = LinearInverse::new(&g, &rest.x_past, &rest.u_past, "input").unwrap();
            assert!(!inv.approximate);
            let mut f = inv.filter.clone();
            // u(t) targets x(t + d): v = x_d shifted by d, the last d held
            let n = x_d.len();
            let u: Vec<f64> = (0..n)
                .map(|t| f.next(x_d[(t + inv.delay).min(n - 1)]))
                .collect();
            let x = g.simulate(&u, &rest).unwrap();
            for t in inv.delay..n {
                assert!(
                    (x[t] - x_d[t]).abs() < 1e-10,
                    "{t} {} {} {g:?}",
                    x[t],
                    x_d[t]
                );
            }
        }
    }

    #[test]
    fn non_minimum_phase_zeros_are_reflected_keeping_the_static_gain() {
        // numerator 0.3 z + 0.9: zero at -3
        let g = LinearBlock::new(vec![0.3, 0.9], vec![-0.5]).unwrap();
        let rest = g.rest_state();
        let inv = LinearInverse::new(&g, &rest.x_past, &rest.u_past, "input").unwrap();
        assert!(inv.approximate);
        // reflected zero -1/3: pole of the inverse inside the circle
        assert!((inv.filter.b[0] - 1.0 / 3.0).abs() < 1e-12);
        // static gain of block times inverse is 1: a constant target is reached
        let mut f = inv.filter.clone();
        let u: Vec<f64> = (0..200).map(|_| f.next(1.0)).collect();
        let x = g.simulate(&u, &rest).unwrap();
        assert!((x[199] - 1.0).abs() < 1e-10);
        assert!(u.iter().all(|v| v.abs() < 10.0));
        let on_circle = LinearBlock::new(vec![1.0, 1.0], vec![]).unwrap();
        let r = on_circle.rest_state();
        assert!(matches!(
            LinearInverse::new(&on_circle, &r.x_past, &r.u_past, "input"),
            Err(Error::Model(_))
        ));
    }
}
