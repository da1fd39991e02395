//! Small polynomial helpers: roots by the companion matrix (nalgebra's Schur form).

use nalgebra::DMatrix;

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
    m.complex_eigenvalues()
        .iter()
        .map(|z| (z.re, z.im))
        .collect()
}

/// |z| of a root.
pub fn modulus(z: Root) -> f64 {
    z.0.hypot(z.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_a_known_quadratic() {
        // (z - 0.5)(z + 0.25) = z^2 - 0.25 z - 0.125
        let mut r = monic_roots(&[-0.25, -0.125]);
        r.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
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
}
