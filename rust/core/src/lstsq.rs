//! Linear least squares by Householder QR (faer), with the statistics the fits report.
//!
//! Columns are scaled to unit norm before the factorisation, so the rank test and the
//! conditioning do not depend on the units of the regressors (powers of xi up to degree 25).

use faer::linalg::solvers::SolveLstsq;
use faer::{Mat, MatRef};

use crate::error::{Error, Result};

/// The solution of min ||A theta - b|| and what is needed for standard errors.
#[derive(Debug, Clone, PartialEq)]
pub struct LeastSquares {
    pub theta: Vec<f64>,
    /// Residual sum of squares ||A theta - b||^2.
    pub rss: f64,
    /// (A^T A)^{-1}, row-major p x p: the covariance of theta is sigma^2 times this.
    pub unscaled_covariance: Vec<f64>,
    /// Reciprocal condition estimate of the column-scaled A (min |R_ii| / max |R_ii|).
    pub rcond: f64,
}

/// Relative size of a pivot below which a column counts as dependent on the others.
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Solve min ||A theta - b||, A given row-major as `rows` x `cols`. `names` label the columns
/// in the error raised when a column carries no information (e.g. no sample on a branch).
pub fn solve(
    a: &[f64],
    rows: usize,
    cols: usize,
    b: &[f64],
    names: &[String],
) -> Result<LeastSquares> {
    if a.len() != rows * cols || b.len() != rows {
        return Err(Error::Data(format!(
            "least squares: A has {} values for {rows} x {cols} and b has {} (internal shape mismatch)",
            a.len(),
            b.len()
        )));
    }
    if rows < cols {
        return Err(Error::NotIdentifiable(format!(
            "only {rows} usable samples for {cols} parameters: give a longer record"
        )));
    }
    let label = |j: usize| {
        names
            .get(j)
            .cloned()
            .unwrap_or_else(|| format!("column {j}"))
    };
    let mut scale = vec![0.0; cols];
    for r in 0..rows {
        for (j, s) in scale.iter_mut().enumerate() {
            *s += a[r * cols + j] * a[r * cols + j];
        }
    }
    for (j, s) in scale.iter_mut().enumerate() {
        *s = s.sqrt();
        if !(*s > 0.0) || !s.is_finite() {
            return Err(Error::NotIdentifiable(format!(
                "the regressor of {} is {} in every sample: the data never excite it \
                 (check the input amplitude and the initial values)",
                label(j),
                if s.is_finite() { "zero" } else { "non-finite" }
            )));
        }
    }
    let scaled = Mat::<f64>::from_fn(rows, cols, |r, j| a[r * cols + j] / scale[j]);
    let rhs = Mat::<f64>::from_fn(rows, 1, |r, _| b[r]);
    let qr = scaled.qr();
    let r_factor = qr.thin_R();
    let diag: Vec<f64> = (0..cols).map(|j| r_factor[(j, j)].abs()).collect();
    let max_diag = diag.iter().cloned().fold(0.0, f64::max);
    let min_diag = diag.iter().cloned().fold(f64::INFINITY, f64::min);
    if let Some(j) = diag.iter().position(|&d| !(d > RANK_TOLERANCE * max_diag)) {
        return Err(Error::NotIdentifiable(format!(
            "the regressor is rank deficient: {} is (nearly) a combination of the other \
             columns; lower the branch degree or linear orders, or excite the system more",
            label(j)
        )));
    }
    let sol = qr.solve_lstsq(rhs.as_ref());
    let theta: Vec<f64> = (0..cols).map(|j| sol[(j, 0)] / scale[j]).collect();
    let mut rss = 0.0;
    for r in 0..rows {
        let fit: f64 = (0..cols).map(|j| a[r * cols + j] * theta[j]).sum();
        rss += (b[r] - fit).powi(2);
    }
    let unscaled_covariance = inverse_gram(r_factor, &scale);
    Ok(LeastSquares {
        theta,
        rss,
        unscaled_covariance,
        rcond: min_diag / max_diag,
    })
}

/// (A^T A)^{-1} = D^{-1} R^{-1} R^{-T} D^{-1} from the R factor of A D^{-1}.
fn inverse_gram(r: MatRef<'_, f64>, scale: &[f64]) -> Vec<f64> {
    let p = scale.len();
    // R^{-1} by back substitution, column by column.
    let mut rinv = vec![0.0; p * p];
    for col in 0..p {
        for i in (0..=col).rev() {
            let mut acc = if i == col { 1.0 } else { 0.0 };
            for k in i + 1..=col {
                acc -= r[(i, k)] * rinv[k * p + col];
            }
            rinv[i * p + col] = acc / r[(i, i)];
        }
    }
    let mut out = vec![0.0; p * p];
    for i in 0..p {
        for j in 0..p {
            let s: f64 = (i.max(j)..p)
                .map(|k| rinv[i * p + k] * rinv[j * p + k])
                .sum();
            out[i * p + j] = s / (scale[i] * scale[j]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(p: usize) -> Vec<String> {
        (0..p).map(|j| format!("p{j}")).collect()
    }

    #[test]
    fn recovers_an_exact_solution_and_its_gram_inverse() {
        // rows [1, t, t^2] for t = 0..9, theta = [1, -2, 0.5]
        let rows = 10;
        let a: Vec<f64> = (0..rows)
            .flat_map(|t| {
                let t = t as f64;
                [1.0, t, t * t]
            })
            .collect();
        let b: Vec<f64> = (0..rows)
            .map(|t| 1.0 - 2.0 * t as f64 + 0.5 * (t * t) as f64)
            .collect();
        let ls = solve(&a, rows, 3, &b, &names(3)).unwrap();
        for (got, want) in ls.theta.iter().zip([1.0, -2.0, 0.5]) {
            assert!((got - want).abs() < 1e-10);
        }
        assert!(ls.rss < 1e-20);
        // (A^T A) (A^T A)^{-1} = I
        for i in 0..3 {
            for j in 0..3 {
                let g: f64 = (0..3)
                    .map(|k| {
                        let ata: f64 = (0..rows).map(|r| a[r * 3 + i] * a[r * 3 + k]).sum();
                        ata * ls.unscaled_covariance[k * 3 + j]
                    })
                    .sum();
                assert!(
                    (g - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9,
                    "{i} {j} {g}"
                );
            }
        }
    }

    #[test]
    fn a_dead_or_dependent_column_is_reported_by_name() {
        let a = vec![1.0, 0.0, 2.0, 0.0, 3.0, 0.0];
        match solve(&a, 3, 2, &[1.0, 2.0, 3.0], &names(2)) {
            Err(Error::NotIdentifiable(m)) => assert!(m.contains("p1"), "{m}"),
            other => panic!("{other:?}"),
        }
        let a = vec![1.0, 2.0, 2.0, 4.0, 3.0, 6.0];
        assert!(matches!(
            solve(&a, 3, 2, &[1.0, 2.0, 3.0], &names(2)),
            Err(Error::NotIdentifiable(_))
        ));
        assert!(matches!(
            solve(&a, 1, 2, &[1.0], &names(2)),
            Err(Error::Data(_))
        ));
    }
}
