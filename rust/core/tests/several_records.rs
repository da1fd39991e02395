//! `Problem::several`: one record is the plain problem bit for bit; on several records the
//! factor's Gram matrix R^T R, the cost and the gradient are the sums of the records' own
//! (each record's initial-state columns in its own block), the paper's iteration solves the
//! records' stacked rows, and bad records are refused naming the record.

mod common;

use backlashid_core::identify::{Problem, Structure};
use backlashid_core::{Error, TriangularFactor};
use common::{example1_model, example2_model, input, noisy, perturbed, EXAMPLE2_THETA};

const EXAMPLE1_THETA: [f64; 11] = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.5, 0.4, 0.2];

/// R^T R of a factor (p+1 square, the target's column included).
fn gram(f: &TriangularFactor) -> Vec<f64> {
    let n = f.cols() + 1;
    let r = f.r_aug();
    let mut g = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            g[i * n + j] = (0..n).map(|k| r[k * n + i] * r[k * n + j]).sum();
        }
    }
    g
}

fn close(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() <= tol * scale, "{x} vs {y}");
    }
}

/// Three records of a system (cascade: Example 1; sandwich: Example 2), of unequal lengths.
fn records(sandwich: bool) -> Vec<(Vec<f64>, Vec<f64>, usize)> {
    [900, 1300, 700]
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            let u: Vec<f64> = input(n + 50 * i)[50 * i..].to_vec();
            let y = match sandwich {
                false => example1_model().simulate(&u, &example1_model().rest_state()),
                true => example2_model().simulate(&u, &example2_model().rest_state()),
            };
            (u, noisy(&y.unwrap(), 3 + i as u64), 4)
        })
        .collect()
}

fn structure(sandwich: bool, initial_state: bool) -> Structure {
    let s = match sandwich {
        false => Structure::new(2, 2, 3, 0, 0, false, false),
        true => Structure::new(2, 2, 3, 2, 2, false, false),
    };
    s.unwrap().with_initial_state(initial_state)
}

fn model_theta(sandwich: bool) -> Vec<f64> {
    match sandwich {
        false => perturbed(EXAMPLE1_THETA).to_vec(),
        true => perturbed(EXAMPLE2_THETA).to_vec(),
    }
}

#[test]
fn one_record_is_the_plain_problem_bit_for_bit() {
    for sandwich in [false, true] {
        for state in [false, true] {
            let s = structure(sandwich, state);
            let (u, y, w) = records(sandwich).swap_remove(1);
            let plain = Problem::new(s, u.clone(), y.clone(), w).unwrap();
            let one = Problem::several(s, vec![(u, y, w)]).unwrap();
            let mut theta = model_theta(sandwich);
            theta.extend((0..s.initial_size()).map(|k| 0.05 * k as f64));
            assert_eq!(one.names(), plain.names());
            assert_eq!(one.size(), s.size());
            assert_eq!(
                one.simulate(&theta).unwrap(),
                plain.simulate(&theta).unwrap()
            );
            assert_eq!(one.cost(&theta).unwrap(), plain.cost(&theta).unwrap());
            assert_eq!(
                one.oe_factor(&theta).unwrap(),
                plain.oe_factor(&theta).unwrap()
            );
            let (g1, g0) = (
                one.gradient(&theta).unwrap(),
                plain.gradient(&theta).unwrap(),
            );
            assert_eq!((g1.gradient, g1.cost), (g0.gradient, g0.cost));
            let (i1, i0) = (
                one.iteration(&theta, sandwich).unwrap(),
                plain.iteration(&theta, sandwich).unwrap(),
            );
            assert_eq!(i1.ls.theta, i0.ls.theta);
            assert_eq!((i1.moving_fraction, i1.rmse), (i0.moving_fraction, i0.rmse));
            assert_eq!(one.bounds(), plain.bounds());
        }
    }
}

#[test]
fn several_records_sum_the_records_factors_costs_and_gradients() {
    for sandwich in [false, true] {
        for state in [false, true] {
            let s = structure(sandwich, state);
            let recs = records(sandwich);
            let joint = Problem::several(s, recs.clone()).unwrap();
            let (p0, k) = (s.model_size(), s.initial_size());
            assert_eq!(joint.size(), p0 + 3 * k);
            let mut theta = model_theta(sandwich);
            let blocks: Vec<Vec<f64>> = (0..3)
                .map(|i| {
                    (0..k)
                        .map(|j| 0.02 * (i + 1) as f64 * (j as f64 - 0.5))
                        .collect()
                })
                .collect();
            theta.extend(blocks.iter().flatten());
            let (jf, jc) = joint.oe_factor(&theta).unwrap();
            let jg = joint.gradient(&theta).unwrap();
            let p = joint.size();
            let mut want = vec![0.0; (p + 1) * (p + 1)];
            let mut want_g = vec![0.0; p];
            let (mut cost, mut rows, mut sim) = (0.0, 0, Vec::new());
            for (i, (u, y, w)) in recs.iter().enumerate() {
                let own = Problem::new(s, u.clone(), y.clone(), *w).unwrap();
                let own_theta: Vec<f64> = theta[..p0].iter().chain(&blocks[i]).copied().collect();
                let (f, c) = own.oe_factor(&own_theta).unwrap();
                let g = gram(&f);
                // record i's columns: the model's, then its block; the target last
                let cols: Vec<usize> = (0..p0)
                    .chain(p0 + i * k..p0 + (i + 1) * k)
                    .chain([p])
                    .collect();
                for (a, &ca) in cols.iter().enumerate() {
                    for (b, &cb) in cols.iter().enumerate() {
                        want[ca * (p + 1) + cb] += g[a * (p0 + k + 1) + b];
                    }
                }
                let og = own.gradient(&own_theta).unwrap();
                for (a, &ca) in cols[..p0 + k].iter().enumerate() {
                    want_g[ca] += og.gradient[a];
                }
                cost += c;
                rows += f.rows();
                sim.extend(own.simulate(&own_theta).unwrap());
            }
            close(&gram(&jf), &want, 1e-11);
            close(&jg.gradient, &want_g, 1e-11);
            close(
                &[jc, jg.cost, joint.cost(&theta).unwrap()],
                &[cost, cost, cost],
                1e-12,
            );
            assert_eq!(jf.rows(), rows);
            assert_eq!(joint.simulate(&theta).unwrap(), sim);
            if state {
                assert_eq!(joint.names()[p0], "x0_1@1");
                assert_eq!(joint.names()[p0 + k], "x0_1@2");
            } else {
                assert_eq!(joint.names(), s.names());
            }
        }
    }
}

#[test]
fn the_joint_iteration_solves_the_records_stacked_rows() {
    for sandwich in [false, true] {
        let s = structure(sandwich, false);
        let recs = records(sandwich);
        let joint = Problem::several(s, recs.clone()).unwrap();
        let theta = model_theta(sandwich);
        let it = joint.iteration(&theta, sandwich).unwrap();
        // the normal equations of the stacked rows: the sum of the records' Gram matrices
        let p = s.model_size();
        let mut g = vec![0.0; (p + 1) * (p + 1)];
        let (mut moved, mut n) = (0.0, 0.0);
        for (u, y, w) in &recs {
            let own = Problem::new(s, u.clone(), y.clone(), *w).unwrap();
            let one = own.iteration(&theta, sandwich).unwrap();
            // rebuild the record's Gram matrix from its solution: (A^T A)^-1 and A^T b
            let cov = &one.ls.unscaled_covariance;
            let ata = invert(cov, p);
            let atb: Vec<f64> = (0..p)
                .map(|i| (0..p).map(|j| ata[i * p + j] * one.ls.theta[j]).sum())
                .collect();
            for i in 0..p {
                for j in 0..p {
                    g[i * (p + 1) + j] += ata[i * p + j];
                }
                g[i * (p + 1) + p] += atb[i];
            }
            let rows = (u.len() - w) as f64;
            moved += one.moving_fraction * rows;
            n += rows;
        }
        let ata: Vec<f64> = (0..p * p).map(|k| g[(k / p) * (p + 1) + k % p]).collect();
        let atb: Vec<f64> = (0..p).map(|i| g[i * (p + 1) + p]).collect();
        let inv = invert(&ata, p);
        let want: Vec<f64> = (0..p)
            .map(|i| (0..p).map(|j| inv[i * p + j] * atb[j]).sum())
            .collect();
        close(&it.ls.theta, &want, 1e-7);
        close(&[it.moving_fraction], &[moved / n], 1e-12);
        assert_eq!(it.rmse.is_some(), !sandwich);
    }
}

/// Gauss-Jordan inverse of a p x p matrix (small, well conditioned in these tests).
fn invert(m: &[f64], p: usize) -> Vec<f64> {
    let mut a = m.to_vec();
    let mut inv: Vec<f64> = (0..p * p)
        .map(|k| f64::from(u8::from(k / p == k % p)))
        .collect();
    for c in 0..p {
        let piv = (c..p)
            .max_by(|&i, &j| a[i * p + c].abs().total_cmp(&a[j * p + c].abs()))
            .unwrap();
        for k in 0..p {
            a.swap(c * p + k, piv * p + k);
            inv.swap(c * p + k, piv * p + k);
        }
        let d = a[c * p + c];
        for k in 0..p {
            a[c * p + k] /= d;
            inv[c * p + k] /= d;
        }
        for r in 0..p {
            if r != c {
                let f = a[r * p + c];
                for k in 0..p {
                    a[r * p + k] -= f * a[c * p + k];
                    inv[r * p + k] -= f * inv[c * p + k];
                }
            }
        }
    }
    inv
}

#[test]
fn bad_records_are_refused_naming_the_record() {
    let s = structure(false, false);
    let data = |r: Result<Problem, Error>| match r {
        Err(Error::Data(m)) => m,
        other => panic!("{other:?}"),
    };
    let mut recs = records(false);
    recs[1].1.pop();
    let msg = data(Problem::several(s, recs));
    assert!(msg.contains("record 1"), "{msg}");
    let mut recs = records(false);
    recs[2].2 = 700;
    let msg = data(Problem::several(s, recs));
    assert!(msg.contains("of record 2"), "{msg}");
    let mut recs = records(false);
    recs[0].0[5] = f64::NAN;
    assert!(data(Problem::several(s, recs)).starts_with("u[0][5]"));
    assert!(data(Problem::several::<Vec<f64>, Vec<f64>>(s, vec![])).contains("no records"));
    let joint = Problem::several(s, records(false)).unwrap();
    assert!(matches!(joint.cost(&[0.0; 3]), Err(Error::Data(_))));
}
