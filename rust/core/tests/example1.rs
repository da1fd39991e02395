//! The paper's Example 1: the cascade of the linear block
//! x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1) - 0.35 x(t-2) and the general backlash
//! c_L = 0.6, c_R = 0.5 with cubic branches.
//! The model's recursions (eq 16-17), and the regression (eq 18-21) and sensitivities that
//! are exact at the true parameters.

mod common;

use backlashid_core::identify::{cascade_sensitivity, CascadeRegression};
use backlashid_core::linalg::lstsq::solve;
use backlashid_core::CascadeModel;
use common::{
    example1, example1_linear, example1_model, input, names, smooth_input, EXAMPLE1_REGRESSION,
};

#[test]
fn impulse_response_follows_eq16() {
    let g = example1_linear();
    let mut u = vec![0.0; 5];
    u[0] = 1.0;
    let x = g.simulate(&u, &g.rest_state()).unwrap();
    // x1 = 0, x2 = 0.7, x3 = 0.5 + 0.2*0.7 = 0.64, x4 = 0.2*0.64 - 0.35*0.7
    assert_eq!(x[0], 0.0);
    assert!((x[1] - 0.7).abs() < 1e-15);
    assert!((x[2] - 0.64).abs() < 1e-15);
    assert!((x[3] - (0.2 * 0.64 - 0.35 * 0.7)).abs() < 1e-15);
}

#[test]
fn the_cascade_equals_the_blocks_run_one_after_the_other() {
    let m = example1_model();
    let u: Vec<f64> = (0..500).map(|k| ((k as f64) * 0.7).sin()).collect();
    let x = m.linear.simulate(&u, &m.linear.rest_state()).unwrap();
    let y = m.backlash.simulate(&x, 0.0).unwrap();
    assert_eq!(m.simulate(&u, &m.rest_state()).unwrap(), y);
}

#[test]
fn cascade_regression_is_exact_at_the_true_parameters() {
    // Example 1: at the true values eq (21) holds with e = 0, so LS returns theta exactly.
    let (lin, bl) = example1();
    let u = input(1500);
    let x = lin.simulate(&u, &lin.rest_state()).unwrap();
    let y = bl.simulate(&x, 0.0).unwrap();
    let reg = CascadeRegression::new(&lin, &bl, &u, &y, &y)
        .unwrap()
        .dense(0);
    let ls = solve(&reg.phi, reg.rows, reg.cols, &reg.target, &names(reg.cols)).unwrap();
    // theta = a1 a2 b1 b2 c1 mL2 mL3 mR1 c2 mR2 mR3 with c2 = mR1 cR
    let want = EXAMPLE1_REGRESSION;
    for (g, w) in ls.theta.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "{:?}", ls.theta);
    }
}

#[test]
fn cascade_output_equals_the_model_simulation() {
    let (lin, bl) = example1();
    let u = smooth_input(500);
    let m = CascadeModel::new(lin.clone(), bl.clone());
    let sens = cascade_sensitivity(&lin, &bl, &u).unwrap();
    assert_eq!(sens.output, m.simulate(&u, &m.rest_state()).unwrap());
    assert_eq!(sens.cols, 11);
}
