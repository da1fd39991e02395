//! The paper's examples and the test signals, typed once. Shared by the unit tests
//! (`crate::test_params`), the integration tests (`tests/common`), the benches and the
//! examples (the last three include this file with `#[path]`); it names the crate
//! `backlashid_core` so that it compiles the same in all of them.
#![allow(dead_code)]

use backlashid_core::{CascadeModel, GeneralBacklash, LinearBlock, SandwichModel};

/// Example 1's linear block: x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1) - 0.35 x(t-2).
pub fn example1_linear() -> LinearBlock {
    LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap()
}

/// Example 1's backlash: c_L = 0.6, c_R = 0.5, cubic branches.
pub fn example1_backlash() -> GeneralBacklash {
    GeneralBacklash::new(0.6, 0.5, vec![1.0, -0.3, 0.3], vec![1.5, 0.4, 0.2]).unwrap()
}

/// A backlash of degree 5 on the left (past the fixed-size hot loops' degree 3), cubic on the
/// right: Example 1's widths.
pub fn quintic_backlash() -> GeneralBacklash {
    GeneralBacklash::new(
        0.6,
        0.5,
        vec![1.0, 0.0, 0.2, 0.0, 0.01],
        vec![1.5, 0.1, 0.2],
    )
    .unwrap()
}

/// Example 1 of the paper (cascade, eq 16-17): its linear block and backlash.
pub fn example1() -> (LinearBlock, GeneralBacklash) {
    (example1_linear(), example1_backlash())
}

/// Example 1 as a cascade model.
pub fn example1_model() -> CascadeModel {
    CascadeModel::new(example1_linear(), example1_backlash())
}

/// Example 1's parameters in the regression's column order (eq 19): a1 a2 b1 b2 c1 mL2 mL3
/// mR1 c2 mR2 mR3, with c2 = mR1 cR (eq 20).
pub const EXAMPLE1_REGRESSION: [f64; 11] =
    [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.75, 0.4, 0.2];

/// Example 2's backlash: c_L = 0.4, c_R = 0.5, cubic branches (checked as a model).
pub fn example2_backlash() -> GeneralBacklash {
    let t = EXAMPLE2_THETA;
    GeneralBacklash::new(t[4], t[8], vec![1.0, t[5], t[6]], vec![t[7], t[9], t[10]]).unwrap()
}

/// Example 2 of the paper (sandwich, eq 29): input block, backlash, output block.
pub fn example2() -> (LinearBlock, GeneralBacklash, LinearBlock) {
    let (input, _, output) = sandwich_from(&EXAMPLE2_THETA);
    (input, example2_backlash(), output)
}

/// Example 2 as a sandwich model.
pub fn example2_model() -> SandwichModel {
    let (input, backlash, output) = example2();
    SandwichModel::new(input, backlash, output)
}

/// Example 2's parameters in the sensitivities' column order: a1 a2 b1 b2 cL mL2 mL3 mR1 cR
/// mR2 mR3 r2 s1 s2.
pub const EXAMPLE2_THETA: [f64; 14] = [
    0.8, 0.2, 0.2, -0.2, 0.4, 0.1, 0.3, 0.75, 0.5, 0.2, 0.6, 0.15, -0.2, 0.35,
];

/// Example 2's parameters in the regression's column order (eq 31): as `EXAMPLE2_THETA`
/// but c2 = mR1 cR in place of cR (eq 32).
pub const EXAMPLE2_REGRESSION: [f64; 14] = [
    0.8, 0.2, 0.2, -0.2, 0.4, 0.1, 0.3, 0.75, 0.375, 0.2, 0.6, 0.15, -0.2, 0.35,
];

/// A sandwich with degree-3 branches and Example 2's orders from a parameter vector in the
/// order of `EXAMPLE2_THETA` (the backlash as an estimate: no branch-shape checks).
pub fn sandwich_from(theta: &[f64]) -> (LinearBlock, GeneralBacklash, LinearBlock) {
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

/// `theta` off by -3 %, 0 or +3 % per parameter in turn: an iterate of a fit in progress.
pub fn perturbed<const P: usize>(theta: [f64; P]) -> [f64; P] {
    let mut est = theta;
    for (k, v) in est.iter_mut().enumerate() {
        *v *= 1.0 + 0.03 * ((k % 3) as f64 - 1.0);
    }
    est
}

/// The next value of the 64-bit linear congruential generator of these tests.
pub fn lcg(state: &mut u64) -> u64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    *state
}

/// Uniform in [0, 1) from the top 53 bits of the generator's next value.
pub fn lcg_unit(state: &mut u64) -> f64 {
    (lcg(state) >> 11) as f64 / (1u64 << 53) as f64
}

/// A deterministic, rich input in (-1, 1): the same record in every test.
pub fn input(n: usize) -> Vec<f64> {
    let mut s = 12345u64;
    (0..n).map(|_| lcg_unit(&mut s) * 2.0 - 1.0).collect()
}

/// A smooth two-tone input, 0.9 sin(0.61 k) + 0.3 cos(0.17 k).
pub fn smooth_input(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| ((k as f64) * 0.61).sin() * 0.9 + ((k as f64) * 0.17).cos() * 0.3)
        .collect()
}

/// `v` plus uniform noise in (-0.025, 0.025) from the generator seeded with `seed`.
pub fn noisy(v: &[f64], seed: u64) -> Vec<f64> {
    let mut g = seed;
    v.iter()
        .map(|a| a + 0.05 * (lcg_unit(&mut g) - 0.5))
        .collect()
}

/// `v` plus `level` times a stretch of `input` (uniform in (-level, level)).
pub fn with_noise(v: &[f64], level: f64) -> Vec<f64> {
    let e = input(v.len() + 7);
    v.iter().zip(&e[7..]).map(|(a, b)| a + level * b).collect()
}

/// Parameter names p0, p1, ... for the solvers' messages.
pub fn names(p: usize) -> Vec<String> {
    (0..p).map(|j| format!("p{j}")).collect()
}
