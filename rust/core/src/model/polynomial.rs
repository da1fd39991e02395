//! Small polynomial helpers: roots by the companion matrix (nalgebra's Schur form), with a
//! capped Aberth-Ehrlich iteration where the Schur iteration does not converge (it can stall
//! on sparse companion matrices such as that of z^4 + 0.5).

use nalgebra::linalg::Schur;
use nalgebra::{Complex, DMatrix};

/// A complex number as (re, im), so callers need no complex type.
pub type Root = (f64, f64);

/// Roots of the monic polynomial z^n + c[0] z^(n-1) + ... + c[n-1].
pub fn monic_roots(c: &[f64]) -> Vec<Root> {
    let n = c.len();
    if n == 0 {
        return Vec::new();
    }
    // Companion matrix: first row -c, ones on the subdiagonal.
    let mut m = DMatrix::<f64>::zeros(n, n);
    for (j, cj) in c.iter().enumerate() {
        m[(0, j)] = -cj;
    }
    for i in 1..n {
        m[(i, i - 1)] = 1.0;
    }
    match Schur::try_new(m, f64::EPSILON, 100 * n + 100) {
        Some(schur) => schur
            .complex_eigenvalues()
            .iter()
            .map(|z| (z.re, z.im))
            .collect(),
        None => aberth(c),
    }
}

/// p(z) and p'(z) of the monic polynomial by Horner's rule.
fn eval(c: &[f64], z: Complex<f64>) -> (Complex<f64>, Complex<f64>) {
    let mut p = Complex::new(1.0, 0.0);
    let mut dp = Complex::new(0.0, 0.0);
    for &ck in c {
        dp = dp * z + p;
        p = p * z + ck;
    }
    (p, dp)
}

/// Aberth-Ehrlich simultaneous iteration, at most 1000 sweeps.
fn aberth(c: &[f64]) -> Vec<Root> {
    let n = c.len();
    // Start on a circle of the roots' geometric-mean radius, rotated off the real axis.
    let radius = c[n - 1].abs().powf(1.0 / n as f64).max(1e-3);
    let mut z: Vec<Complex<f64>> = (0..n)
        .map(|k| {
            let angle = 2.0 * std::f64::consts::PI * k as f64 / n as f64 + 0.4;
            Complex::from_polar(radius, angle)
        })
        .collect();
    for _ in 0..1000 {
        let mut largest_step: f64 = 0.0;
        for k in 0..n {
            let (p, dp) = eval(c, z[k]);
            if p.norm() == 0.0 {
                continue;
            }
            let ratio = p / dp;
            let repulsion: Complex<f64> = (0..n)
                .filter(|&j| j != k)
                .map(|j| Complex::new(1.0, 0.0) / (z[k] - z[j]))
                .sum();
            let step = ratio / (Complex::new(1.0, 0.0) - ratio * repulsion);
            if step.re.is_finite() && step.im.is_finite() {
                z[k] -= step;
                largest_step = largest_step.max(step.norm() / z[k].norm().max(1e-300));
            }
        }
        if largest_step < 1e-15 {
            break;
        }
    }
    z.iter().map(|v| (v.re, v.im)).collect()
}

/// |z| of a root.
pub fn modulus(z: Root) -> f64 {
    z.0.hypot(z.1)
}

/// Largest root modulus of z^n + c[0] z^(n-1) + ... + c[n-1]: 0 for n = 0, infinite when a
/// coefficient is not finite (no root to speak of; "unstable" to every caller).
pub fn spectral_radius(c: &[f64]) -> f64 {
    if c.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    monic_roots(c).into_iter().map(modulus).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_a_known_quadratic() {
        // (z - 0.5)(z + 0.25) = z^2 - 0.25 z - 0.125
        let mut r = monic_roots(&[-0.25, -0.125]);
        r.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!((r[0].0 + 0.25).abs() < 1e-12 && r[0].1.abs() < 1e-12);
        assert!((r[1].0 - 0.5).abs() < 1e-12 && r[1].1.abs() < 1e-12);
    }

    #[test]
    fn complex_pair() {
        // z^2 + 1 = 0
        let r = monic_roots(&[0.0, 1.0]);
        assert_eq!(r.len(), 2);
        for z in r {
            assert!(z.0.abs() < 1e-12 && (modulus(z) - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn sparse_companion_matrices_return_their_roots() {
        // z^4 + 0.5, z^4 + 1, z^6 + 0.5: every root has modulus |c|^(1/n); Schur stalls here.
        for c in [
            vec![0.0, 0.0, 0.0, 0.5],
            vec![0.0, 0.0, 0.0, 1.0],
            vec![0.0; 5].into_iter().chain([0.5]).collect(),
        ] {
            let n = c.len();
            let r = monic_roots(&c);
            assert_eq!(r.len(), n);
            let want = c[n - 1].powf(1.0 / n as f64);
            for z in &r {
                assert!((modulus(*z) - want).abs() < 1e-9, "{c:?}: {r:?}");
            }
        }
        // and the Aberth fallback on its own agrees with a known factorisation
        let mut r = aberth(&[-0.25, -0.125]);
        r.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!((r[0].0 + 0.25).abs() < 1e-12 && (r[1].0 - 0.5).abs() < 1e-12);
    }
}
