//! The paper's Example 2: the sandwich of the linear block
//! x(t) = 0.8 u(t-1) + 0.2 u(t-2) - 0.2 x(t-1) + 0.2 x(t-2), the general backlash
//! c_L = 0.4, c_R = 0.5 with cubic branches, and the output block w(t) = y(t-1) + 0.15 y(t-2) + 0.2 w(t-1) - 0.35 w(t-2) (eq 29).
//! The model's recursions, the switching form (eq 9-15), and the regression (eq 33-34) and
//! sensitivities at the true parameters.

mod common;

use backlashid_core::identify::{sandwich_sensitivity, SandwichRegression};
use backlashid_core::linalg::lstsq::solve;
use backlashid_core::{switching_form, SandwichModel};
use common::{
    example2, example2_backlash, example2_model, input, names, sandwich_from, smooth_input,
    EXAMPLE2_REGRESSION, EXAMPLE2_THETA,
};

#[test]
fn the_sandwich_equals_the_three_blocks_run_one_after_the_other() {
    let m = example2_model();
    let u: Vec<f64> = (0..700).map(|k| ((k as f64) * 0.9).sin() * 0.95).collect();
    let x = m
        .input_linear
        .simulate(&u, &m.input_linear.rest_state())
        .unwrap();
    let y = m.backlash.simulate(&x, 0.0).unwrap();
    let w = m
        .output_linear
        .simulate(&y, &m.output_linear.rest_state())
        .unwrap();
    assert_eq!(m.simulate(&u, &m.rest_state()).unwrap(), w);
}

#[test]
fn eq15_matches_eq1_on_example2_backlash() {
    let bl = example2_backlash();
    let x: Vec<f64> = (0..3000)
        .map(|k| 1.2 * ((k as f64) * 0.11).sin() * ((k as f64) * 0.013).cos())
        .collect();
    let s = switching_form(&bl, &x, 0.0).unwrap();
    let y = bl.simulate(&x, 0.0).unwrap();
    for (ys, yt) in s.y.iter().zip(&y) {
        assert!((ys - yt).abs() < 1e-12);
    }
    assert!(s.f1.iter().zip(&s.f2).all(|(a, b)| !(a & b)));
    assert!(s.f1.iter().any(|&f| f) && s.f2.iter().any(|&f| f));
    assert!(s.f1.iter().zip(&s.f2).any(|(a, b)| !a && !b));
}

#[test]
fn sandwich_regression_is_exact_at_the_true_parameters() {
    let (lin, bl, out) = example2();
    let u = input(1500);
    let m = SandwichModel::new(lin.clone(), bl.clone(), out.clone());
    let w = m.simulate(&u, &m.rest_state()).unwrap();
    let reg = SandwichRegression::new(&lin, &bl, &out, &u, &w)
        .unwrap()
        .dense(0);
    let ls = solve(&reg.phi, reg.rows, reg.cols, &reg.target, &names(reg.cols)).unwrap();
    // a1 a2 b1 b2 c1 mL2 mL3 mR1 c2 mR2 mR3 r2 s1 s2
    let want = EXAMPLE2_REGRESSION;
    for (g, w) in ls.theta.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
    }
}

#[test]
fn sandwich_jacobian_matches_central_differences() {
    // Example 2's parameters: a1 a2 b1 b2 cL mL2 mL3 mR1 cR mR2 mR3 r2 s1 s2
    let theta = EXAMPLE2_THETA;
    let u = smooth_input(400);
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
