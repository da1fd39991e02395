//! The quasi-linear regressions of the identification algorithms: the cascade's data vector
//! phi(t) of eq (18) with target eq (21), the sandwich's Phi(t) of eq (33) with target eq (34),
//! and a plain ARX regression for the first linear estimate.
//!
//! Column order (eq 19 / 31): theta's layout (`problem::Layout`) with c_1 = c_L and
//! c_2 = m_R1 c_R at the positions of c_L and c_R (eq 20, 32; `Structure::ls_names`).

use super::rows::{dense, simulation_rmse, CascadeRows, RowSource, SandwichRows};
use crate::error::{Error, Result};
use crate::linalg::lstsq::{solve, LeastSquares};
use crate::linalg::streaming::{fold_parallel, threads_for, TriangularFactor};
use crate::model::signal::{check_same_length, check_signal};

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
    /// Fraction of samples from `warmup` on where the estimate's backlash moves (f1 or f2).
    pub fn moving_fraction(&self, warmup: usize) -> f64 {
        moving_fraction(&self.f1, &self.f2, warmup)
    }

    /// The least-squares solution; when the data do not determine it, the error also says on
    /// how many samples the current estimate moves the backlash.
    pub fn solve(&self, names: &[String], warmup: usize) -> Result<LeastSquares> {
        solve(&self.phi, self.rows, self.cols, &self.target, names)
            .map_err(|e| with_moving_fraction(e, self.moving_fraction(warmup)))
    }
}

/// Fraction of samples from `warmup` on where the backlash moves (f1 or f2); 0 for none.
pub fn moving_fraction(f1: &[bool], f2: &[bool], warmup: usize) -> f64 {
    let n = f1.len().min(f2.len()).saturating_sub(warmup);
    if n == 0 {
        return 0.0;
    }
    let moving = f1[warmup..]
        .iter()
        .zip(&f2[warmup..])
        .filter(|(a, b)| **a || **b)
        .count();
    moving as f64 / n as f64
}

/// A `NotIdentifiable` error completed with the share of samples on which the current
/// estimate moves the backlash (the usual cause: too few samples off the dead band).
pub fn with_moving_fraction(err: Error, moving_fraction: f64) -> Error {
    match err {
        Error::NotIdentifiable(msg) => Error::NotIdentifiable(format!(
            "{msg} (at the current estimate {:.1} % of samples move the backlash \
             output: f1 or f2)",
            100.0 * moving_fraction
        )),
        other => other,
    }
}

/// `TriangularFactor::solve` with the moving fraction in a `NotIdentifiable` error, as
/// `Regression::solve` reports it.
pub fn solve_factor(
    factor: &TriangularFactor,
    names: &[String],
    moving_fraction: f64,
) -> Result<LeastSquares> {
    factor
        .solve(names)
        .map_err(|e| with_moving_fraction(e, moving_fraction))
}

/// A regression at an estimate whose rows are built on demand from the estimate's internal
/// signals: `CascadeRegression` (eq 18-21) or `SandwichRegression` (eq 33-34). The record is
/// checked and simulated on construction; rows t < `warmup` are left out (the sandwich's
/// also t = 0: eq 33 starts from the backlash at t - 1).
pub struct RowRegression<R>(pub(super) R);

/// The cascade's regression at an estimate, eq (18)-(21): x by eq (22), f1, f2 by
/// eq (25)-(26) with `y_switch(t-1)` (the measured output as the paper reads, or the model's
/// simulated output), target y(t) - y(t-1)[1 - f1][1 - f2] with the measured y.
pub type CascadeRegression<'a> = RowRegression<CascadeRows<'a>>;

/// The sandwich's regression at an estimate, eq (33)-(34): x by eq (22), the backlash
/// output y by eq (35) (the model's own, as y is not measured), f1, f2 from it; rows
/// [backlash part at t-1, y(t-2)..y(t-nr), -w(t-1)..-w(t-ns)] with the measured w, target
/// w(t) - y(t-2)[1 - f1(t-1)][1 - f2(t-1)].
pub type SandwichRegression<'a> = RowRegression<SandwichRows<'a>>;

impl<'a, R: RowSource<'a>> RowRegression<R> {
    /// All rows from `warmup` on as a dense row-major matrix, with x, f1 and f2.
    pub fn dense(self, warmup: usize) -> Regression {
        dense(self.0.with_flags(), warmup)
    }

    /// The rows folded into a triangular factor on the default number of threads, without
    /// the N x p matrix; with the moving fraction from `warmup` on.
    pub fn factor(&self, warmup: usize) -> (TriangularFactor, f64) {
        self.factor_threads(warmup, threads_for(self.0.len()))
    }

    /// `factor` on `threads` threads (the result depends on it only through rounding).
    pub fn factor_threads(&self, warmup: usize, threads: usize) -> (TriangularFactor, f64) {
        self.0.factor(warmup, threads)
    }
}

impl CascadeRegression<'_> {
    /// One iteration of the cascade algorithm in one pass over the record: the factor and
    /// moving fraction of `factor`, and the free-run simulation RMSE of the estimate itself
    /// (from rest, samples t >= `warmup`; +inf if the simulation overflows), which the
    /// iterations report for every iterate and which needs only the backlash run on the
    /// same x.
    pub fn iteration(&self, warmup: usize) -> (TriangularFactor, f64, f64) {
        let (rows, backlash) = (&self.0, self.0.part.backlash);
        let rmse = match backlash.padded_step() {
            Some(padded) => simulation_rmse(&rows.part.x, rows.y, warmup, padded),
            None => simulation_rmse(&rows.part.x, rows.y, warmup, backlash),
        };
        let (factor, moving) = self.factor(warmup);
        (factor, moving, rmse)
    }
}

/// ARX regression y(t) = sum a_i u(t-delay+1-i) - sum b_j y(t-j): rows
/// [u(t-delay)..u(t-delay-na+1), -y(t-1..t-nb)] for t >= warmup, zero before the record,
/// target y(t). Columns a_1..a_na, b_1..b_nb. The cascade has delay 1; the sandwich's two
/// blocks delay 2.
pub struct ArxRegression<'a> {
    u: &'a [f64],
    y: &'a [f64],
    na: usize,
    nb: usize,
    delay: usize,
    cols: usize,
}

impl<'a> ArxRegression<'a> {
    pub fn new(u: &'a [f64], y: &'a [f64], na: usize, nb: usize, delay: usize) -> Result<Self> {
        check_signal("u", u)?;
        check_signal("y", y)?;
        check_same_length(u, y, "y")?;
        Ok(Self {
            u,
            y,
            na,
            nb,
            delay,
            cols: na + nb,
        })
    }

    /// The rows from `warmup` on as a dense row-major matrix, and the targets.
    pub fn dense(&self, warmup: usize) -> (Vec<f64>, Vec<f64>) {
        let (start, cols) = (warmup.min(self.u.len()), self.cols);
        let mut phi = vec![0.0; (self.u.len() - start) * cols];
        let target = (start..self.u.len())
            .map(|t| self.fill(t, &mut phi[(t - start) * cols..(t - start + 1) * cols]))
            .collect();
        (phi, target)
    }

    /// The rows from `warmup` on folded into a triangular factor (no N x (na + nb) matrix).
    pub fn factor(&self, warmup: usize) -> TriangularFactor {
        let start = warmup.min(self.u.len());
        fold_parallel(
            self.u.len() - start,
            self.cols,
            threads_for(self.u.len()),
            |i, row| self.fill(start + i, row),
        )
    }

    fn fill(&self, t: usize, row: &mut [f64]) -> f64 {
        let lag = |s: &[f64], k: usize| if k <= t { s[t - k] } else { 0.0 };
        for i in 1..=self.na {
            row[i - 1] = lag(self.u, self.delay + i - 1);
        }
        for j in 1..=self.nb {
            row[self.na + j - 1] = -lag(self.y, j);
        }
        self.y[t]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::lstsq::solve;
    use crate::test_params::{
        example1, example1_linear, example2, input, names, with_noise, EXAMPLE1_REGRESSION,
        EXAMPLE2_REGRESSION,
    };
    use crate::{GeneralBacklash, LinearBlock};

    #[test]
    fn streamed_arx_equals_the_dense_one() {
        let lin = example1_linear();
        let u = input(5000);
        let mut x = lin.simulate(&u, &lin.rest_state()).unwrap();
        for (k, v) in x.iter_mut().enumerate() {
            *v += 0.01 * ((k * 7919 % 101) as f64 - 50.0) / 50.0; // deterministic "noise"
        }
        let (phi, target) = ArxRegression::new(&u, &x, 2, 2, 2).unwrap().dense(3);
        let dense = solve(&phi, target.len(), 4, &target, &names(4)).unwrap();
        let streamed = ArxRegression::new(&u, &x, 2, 2, 2)
            .unwrap()
            .factor(3)
            .solve(&names(4))
            .unwrap();
        for (d, s) in dense.theta.iter().zip(&streamed.theta) {
            assert!((d - s).abs() < 1e-10 * d.abs().max(1.0));
        }
        assert!((dense.rss - streamed.rss).abs() < 1e-9 * dense.rss);
    }

    #[test]
    fn arx_recovers_a_linear_block() {
        let lin = example1_linear();
        let u = input(300);
        let x = lin.simulate(&u, &lin.rest_state()).unwrap();
        let (phi, target) = ArxRegression::new(&u, &x, 2, 2, 1).unwrap().dense(0);
        let ls = solve(&phi, target.len(), 4, &target, &names(4)).unwrap();
        for (g, w) in ls.theta.iter().zip([0.7, 0.5, -0.2, 0.35]) {
            assert!((g - w).abs() < 1e-12);
        }
    }

    fn assert_close(got: &LeastSquares, want: &LeastSquares, tol: f64) {
        for (g, w) in got.theta.iter().zip(&want.theta) {
            assert!((g - w).abs() <= tol * w.abs().max(1e-3), "{g} vs {w}");
        }
        assert!(
            (got.rss - want.rss).abs() <= tol * want.rss.max(1e-20),
            "{} {}",
            got.rss,
            want.rss
        );
        for (g, w) in got
            .unscaled_covariance
            .iter()
            .zip(&want.unscaled_covariance)
        {
            assert!((g - w).abs() <= tol * w.abs().max(1e-6), "{g} vs {w}");
        }
    }

    #[test]
    fn cascade_iteration_is_the_factor_plus_the_estimate_s_own_simulation_rmse() {
        let (lin, bl) = example1();
        let u = input(3000);
        let x = lin.simulate(&u, &lin.rest_state()).unwrap();
        let yn = with_noise(&bl.simulate(&x, 0.0).unwrap(), 0.05);
        let est =
            GeneralBacklash::from_estimate(0.5, 0.4, vec![1.0, -0.2, 0.25], vec![1.4, 0.3, 0.1])
                .unwrap();
        let lin2 = LinearBlock::new(vec![0.6, 0.45], vec![-0.1, 0.3]).unwrap();
        let model = crate::CascadeModel::new(lin2.clone(), est.clone());
        let y_sim = model.simulate(&u, &model.rest_state()).unwrap();
        for warmup in [0, 250] {
            let (f, moving, rmse) = CascadeRegression::new(&lin2, &est, &u, &yn, &yn)
                .unwrap()
                .iteration(warmup);
            let (want_f, want_moving) = CascadeRegression::new(&lin2, &est, &u, &yn, &yn)
                .unwrap()
                .factor(warmup);
            assert_eq!((f, moving), (want_f, want_moving));
            let sse: f64 = (warmup..u.len()).map(|t| (yn[t] - y_sim[t]).powi(2)).sum();
            let want = (sse / (u.len() - warmup) as f64).sqrt();
            assert!((rmse - want).abs() < 1e-12 * want, "{rmse} vs {want}");
        }
        // the degree-4 estimate takes the unpadded path, with the same result
        let wide = GeneralBacklash::from_estimate(
            0.5,
            0.4,
            vec![1.0, -0.2, 0.25, 0.0],
            vec![1.4, 0.3, 0.1, 0.0],
        )
        .unwrap();
        let (_, moving4, rmse4) = CascadeRegression::new(&lin2, &wide, &u, &yn, &yn)
            .unwrap()
            .iteration(0);
        let (_, moving3, rmse3) = CascadeRegression::new(&lin2, &est, &u, &yn, &yn)
            .unwrap()
            .iteration(0);
        assert_eq!(moving4, moving3);
        assert!((rmse4 - rmse3).abs() < 1e-12 * rmse3);
    }

    #[test]
    fn cascade_factor_solves_like_the_dense_regression() {
        let (lin, bl) = example1();
        let u = input(5000);
        let x = lin.simulate(&u, &lin.rest_state()).unwrap();
        let y = bl.simulate(&x, 0.0).unwrap();
        let want = EXAMPLE1_REGRESSION;
        for threads in [1, 2, 3] {
            let (f, moving) = CascadeRegression::new(&lin, &bl, &u, &y, &y)
                .unwrap()
                .factor_threads(0, threads);
            let ls = solve_factor(&f, &names(11), moving).unwrap();
            for (g, w) in ls.theta.iter().zip(want) {
                assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
            }
        }
        // noisy data at a perturbed estimate, with a warm-up: the dense solution to rounding
        let yn = with_noise(&y, 0.05);
        let est =
            GeneralBacklash::from_estimate(0.5, 0.4, vec![1.0, -0.2, 0.25], vec![1.4, 0.3, 0.1])
                .unwrap();
        let lin2 = LinearBlock::new(vec![0.6, 0.45], vec![-0.1, 0.3]).unwrap();
        for warmup in [0, 13] {
            let reg = CascadeRegression::new(&lin2, &est, &u, &yn, &yn)
                .unwrap()
                .dense(warmup);
            let dense = reg.solve(&names(11), warmup).unwrap();
            for threads in [1, 2] {
                let (f, moving) = CascadeRegression::new(&lin2, &est, &u, &yn, &yn)
                    .unwrap()
                    .factor_threads(warmup, threads);
                assert_eq!(f.rows(), reg.rows);
                assert_eq!(moving, reg.moving_fraction(warmup));
                assert_close(
                    &solve_factor(&f, &names(11), moving).unwrap(),
                    &dense,
                    1e-10,
                );
            }
        }
        let (f, m) = CascadeRegression::new(&lin, &bl, &u, &y, &y)
            .unwrap()
            .factor(0);
        assert!(m > 0.0 && m < 1.0);
        assert_eq!(f.cols(), 11);
    }

    #[test]
    fn sandwich_factor_solves_like_the_dense_regression() {
        let (lin, bl, out) = example2();
        let u = input(5000);
        let m = crate::SandwichModel::new(lin.clone(), bl.clone(), out.clone());
        let w = m.simulate(&u, &m.rest_state()).unwrap();
        let want = EXAMPLE2_REGRESSION;
        for threads in [1, 2] {
            let (f, moving) = SandwichRegression::new(&lin, &bl, &out, &u, &w)
                .unwrap()
                .factor_threads(0, threads);
            let ls = solve_factor(&f, &names(14), moving).unwrap();
            for (g, w) in ls.theta.iter().zip(want) {
                assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
            }
        }
        let wn = with_noise(&w, 0.02);
        for warmup in [0, 1, 50] {
            let reg = SandwichRegression::new(&lin, &bl, &out, &u, &wn)
                .unwrap()
                .dense(warmup);
            let dense = reg.solve(&names(14), warmup).unwrap();
            for threads in [1, 2] {
                let (f, moving) = SandwichRegression::new(&lin, &bl, &out, &u, &wn)
                    .unwrap()
                    .factor_threads(warmup, threads);
                assert_eq!(f.rows(), reg.rows);
                assert_eq!(moving, reg.moving_fraction(warmup));
                assert_close(
                    &solve_factor(&f, &names(14), moving).unwrap(),
                    &dense,
                    1e-10,
                );
            }
        }
    }

    #[test]
    fn a_backlash_that_never_moves_is_not_identifiable_with_the_moving_share() {
        let (lin, _) = example1();
        // a dead band far wider than x: f1 = f2 = 0 everywhere, the backlash columns are zero
        let wide = GeneralBacklash::new(50.0, 50.0, vec![1.0, 0.0], vec![1.0, 0.0]).unwrap();
        let u = input(800);
        let y = input(900)[100..].to_vec();
        let (f, moving) = CascadeRegression::new(&lin, &wide, &u, &y, &y)
            .unwrap()
            .factor(0);
        assert_eq!(moving, 0.0);
        let dense = CascadeRegression::new(&lin, &wide, &u, &y, &y)
            .unwrap()
            .dense(0)
            .solve(&names(7), 0);
        for got in [solve_factor(&f, &names(7), moving), dense] {
            match got {
                Err(Error::NotIdentifiable(m)) => {
                    assert!(
                        m.contains("p0") && m.contains("0.0 % of samples move"),
                        "{m}"
                    )
                }
                other => panic!("{other:?}"),
            }
        }
        // bad inputs are errors, not panics
        assert!(matches!(
            CascadeRegression::new(&lin, &wide, &u, &y[..10], &y).map(|r| r.factor(0)),
            Err(Error::Data(_))
        ));
        let mut bad = u.clone();
        bad[3] = f64::NAN;
        assert!(matches!(
            CascadeRegression::new(&lin, &wide, &bad, &y, &y).map(|r| r.factor(0)),
            Err(Error::Data(_))
        ));
        let (f, _) = CascadeRegression::new(&lin, &wide, &u, &y, &y)
            .unwrap()
            .factor(10_000);
        assert_eq!(f.rows(), 0);
        let (l2, b2, o2) = example2();
        let (f, m) = SandwichRegression::new(&l2, &b2, &o2, &u, &y)
            .unwrap()
            .factor(10_000);
        assert_eq!((f.rows(), m), (0, 0.0));
        assert!(matches!(
            solve_factor(&f, &names(14), m),
            Err(Error::NotIdentifiable(_))
        ));
        let uneven = GeneralBacklash::from_estimate(0.1, 0.1, vec![1.0], vec![1.0, 0.2]).unwrap();
        assert!(matches!(
            SandwichRegression::new(&l2, &uneven, &o2, &u, &y).map(|r| r.factor(0)),
            Err(Error::Model(_))
        ));
    }
}
