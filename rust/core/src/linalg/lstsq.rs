//! Linear least squares by Householder QR, with the statistics the fits report. The dense
//! `solve` folds its rows into a `streaming::TriangularFactor`; both solve through
//! `solve_triangular`.
//!
//! Columns are scaled to unit norm before the factorisation, so the rank test and the
//! conditioning do not depend on the units of the regressors (powers of xi up to degree 25).

use crate::error::{Error, Result};
use crate::linalg::streaming::TriangularFactor;

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
///
/// The rows are folded into a `TriangularFactor` (blocked Householder QR of [A | b]) and
/// solved from it, so the dense and the streaming paths share every check and statistic.
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
        return Err(too_few_rows(rows, cols));
    }
    let mut factor = TriangularFactor::new(cols);
    factor.fold(a, b)?;
    factor.solve(names)
}

fn too_few_rows(rows: usize, cols: usize) -> Error {
    Error::NotIdentifiable(format!(
        "only {rows} usable samples for {cols} parameters: give a longer record"
    ))
}

/// The solution from R_aug (row-major `n` x `n`, n = p + 1, upper triangular) of [A | b]
/// over `rows` rows: the column norms of A are those of R, the rank test and rcond use the
/// R of the column-scaled A (R D^{-1}), theta by back substitution, rss = R_aug[p][p]^2.
pub(crate) fn solve_triangular(
    r: &[f64],
    n: usize,
    p: usize,
    rows: usize,
    names: &[String],
) -> Result<LeastSquares> {
    if n != p + 1 || r.len() != n * n {
        return Err(Error::Data(format!(
            "least squares: a triangular factor of {} values for {p} columns (internal shape \
             mismatch)",
            r.len()
        )));
    }
    if rows < p {
        return Err(too_few_rows(rows, p));
    }
    let label = |j: usize| {
        names
            .get(j)
            .cloned()
            .unwrap_or_else(|| format!("column {j}"))
    };
    let mut scale = vec![0.0; p];
    for (j, s) in scale.iter_mut().enumerate() {
        *s = (0..=j)
            .map(|i| r[i * n + j] * r[i * n + j])
            .sum::<f64>()
            .sqrt();
        if !s.is_finite() || *s <= 0.0 {
            return Err(Error::NotIdentifiable(format!(
                "the regressor of {} is {} in every sample: the data never excite it \
                 (check the input amplitude and the initial values)",
                label(j),
                if s.is_finite() { "zero" } else { "non-finite" }
            )));
        }
    }
    if !r[n * n - 1].is_finite() {
        return Err(Error::NotIdentifiable(
            "the regression target is non-finite: the data or the current estimate \
             overflowed (scale the signals down)"
                .into(),
        ));
    }
    // R of the column-scaled A.
    let scaled: Vec<f64> = (0..p * p)
        .map(|k| r[(k / p) * n + k % p] / scale[k % p])
        .collect();
    let diag: Vec<f64> = (0..p).map(|j| scaled[j * p + j].abs()).collect();
    let max_diag = diag.iter().cloned().fold(0.0, f64::max);
    let min_diag = diag.iter().cloned().fold(f64::INFINITY, f64::min);
    if let Some(j) = diag
        .iter()
        .position(|&d| d.is_nan() || d <= RANK_TOLERANCE * max_diag)
    {
        return Err(Error::NotIdentifiable(format!(
            "the regressor is rank deficient: {} is (nearly) a combination of the other \
             columns; lower the branch degree or linear orders, or excite the system more",
            label(j)
        )));
    }
    // R_s z = Q^T b, theta = D^{-1} z.
    let mut z = vec![0.0; p];
    for i in (0..p).rev() {
        let mut acc = r[i * n + p];
        for k in i + 1..p {
            acc -= scaled[i * p + k] * z[k];
        }
        z[i] = acc / scaled[i * p + i];
    }
    let theta: Vec<f64> = z.iter().zip(&scale).map(|(zi, s)| zi / s).collect();
    let rss = r[n * n - 1] * r[n * n - 1];
    let unscaled_covariance = inverse_gram(&scaled, &scale);
    Ok(LeastSquares {
        theta,
        rss,
        unscaled_covariance,
        rcond: if p == 0 { 1.0 } else { min_diag / max_diag },
    })
}

/// (A^T A)^{-1} = D^{-1} R^{-1} R^{-T} D^{-1} from the R factor (row-major p x p) of A D^{-1}.
pub(crate) fn inverse_gram(r: &[f64], scale: &[f64]) -> Vec<f64> {
    let p = scale.len();
    // R^{-1} by back substitution, column by column.
    let mut rinv = vec![0.0; p * p];
    for col in 0..p {
        for i in (0..=col).rev() {
            let mut acc = if i == col { 1.0 } else { 0.0 };
            for k in i + 1..=col {
                acc -= r[i * p + k] * rinv[k * p + col];
            }
            rinv[i * p + col] = acc / r[i * p + i];
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
