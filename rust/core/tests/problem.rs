//! The compiled `Problem` against the functions it unpacks theta for: its factor, gradient,
//! iteration and simulation equal those of the blocks built by hand, on Example 1 (cascade),
//! Example 2 (sandwich) and a sandwich with both feedthroughs; its names are the paper's
//! order; the record is checked once, on construction.

mod common;

use backlashid_core::identify::{
    cascade_oe_factor, cascade_oe_gradient, sandwich_oe_factor, sandwich_oe_gradient, solve_factor,
    CascadeRegression, Problem, SandwichRegression, Structure,
};
use backlashid_core::{
    CascadeModel, Error, GeneralBacklash, LinearBlock, SandwichModel, TriangularFactor,
};
use common::{
    example1_model, example2_model, input, noisy, perturbed, sandwich_from, EXAMPLE2_THETA,
};

/// Example 1 in the physical order a1 a2 b1 b2 c_L m_L2 m_L3 m_R1 c_R m_R2 m_R3.
const EXAMPLE1_THETA: [f64; 11] = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.5, 0.4, 0.2];

fn close(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() <= 1e-12 * scale, "{x} vs {y}");
    }
}

fn same_factor(a: &(TriangularFactor, f64), b: &(TriangularFactor, f64)) {
    close(a.0.r_aug(), b.0.r_aug());
    close(&[a.1], &[b.1]);
}

fn cascade_blocks(t: &[f64]) -> (LinearBlock, GeneralBacklash) {
    let lin = LinearBlock::new(t[0..2].to_vec(), t[2..4].to_vec()).unwrap();
    let bl =
        GeneralBacklash::from_estimate(t[4], t[8], vec![1.0, t[5], t[6]], vec![t[7], t[9], t[10]])
            .unwrap();
    (lin, bl)
}

/// sum (y - y_sim)^2 over t >= warmup, in time order.
fn squared_error(y: &[f64], y_sim: &[f64], warmup: usize) -> f64 {
    y[warmup..]
        .iter()
        .zip(&y_sim[warmup..])
        .map(|(a, b)| (a - b) * (a - b))
        .sum()
}

fn names(s: &[&str]) -> Vec<String> {
    s.iter().map(|k| k.to_string()).collect()
}

#[test]
fn the_cascade_problem_equals_the_functions_on_example1() {
    let s = Structure::new(2, 2, 3, 0, 0, false, false).unwrap();
    assert_eq!(
        s.names(),
        names(&["a1", "a2", "b1", "b2", "c_L", "m_L2", "m_L3", "m_R1", "c_R", "m_R2", "m_R3"])
    );
    let u = input(3000);
    let y = noisy(
        &example1_model()
            .simulate(&u, &example1_model().rest_state())
            .unwrap(),
        7,
    );
    let theta = perturbed(EXAMPLE1_THETA);
    let (lin, bl) = cascade_blocks(&theta);
    for warmup in [0, 100] {
        let p = Problem::new(s, u.clone(), y.clone(), warmup).unwrap();
        same_factor(
            &p.oe_factor(&theta).unwrap(),
            &cascade_oe_factor(&lin, &bl, &u, &y, warmup).unwrap(),
        );
        let (g, want) = (
            p.gradient(&theta).unwrap(),
            cascade_oe_gradient(&lin, &bl, &u, &y, warmup).unwrap(),
        );
        close(&g.gradient, &want.gradient);
        close(&[g.cost], &[want.cost]);
        let model = CascadeModel::new(lin.clone(), bl.clone());
        let y_sim = model.simulate(&u, &model.rest_state()).unwrap();
        close(&p.simulate(&theta).unwrap(), &y_sim);
        // the cost folded as the simulation runs: the sum over the kept output, bit for bit
        assert_eq!(p.cost(&theta).unwrap(), squared_error(&y, &y_sim, warmup));
        for (simulated, y_switch) in [(false, &y), (true, &y_sim)] {
            let it = p.iteration(&theta, simulated).unwrap();
            let reg = CascadeRegression::new(&lin, &bl, &u, &y, y_switch).unwrap();
            let (factor, moving, rmse) = reg.iteration(warmup);
            let ls = solve_factor(&factor, &s.ls_names(), moving).unwrap();
            close(&it.ls.theta, &ls.theta);
            close(&it.ls.unscaled_covariance, &ls.unscaled_covariance);
            close(&[it.ls.rss, it.moving_fraction], &[ls.rss, moving]);
            close(&[it.rmse.unwrap()], &[rmse]);
        }
    }
}

#[test]
fn the_sandwich_problem_equals_the_functions_on_example2() {
    let s = Structure::new(2, 2, 3, 2, 2, false, false).unwrap();
    assert_eq!(s.size(), 14);
    assert_eq!(&s.names()[11..], &names(&["r2", "s1", "s2"])[..]);
    assert_eq!(s.ls_names()[4], "c_1");
    let u = input(3000);
    let m = example2_model();
    let w = noisy(&m.simulate(&u, &m.rest_state()).unwrap(), 8);
    let theta = perturbed(EXAMPLE2_THETA);
    let (lin, bl, out) = sandwich_from(&theta);
    for warmup in [0, 100] {
        let p = Problem::new(s, u.clone(), w.clone(), warmup).unwrap();
        same_factor(
            &p.oe_factor(&theta).unwrap(),
            &sandwich_oe_factor(&lin, &bl, &out, &u, &w, warmup).unwrap(),
        );
        let (g, want) = (
            p.gradient(&theta).unwrap(),
            sandwich_oe_gradient(&lin, &bl, &out, &u, &w, warmup).unwrap(),
        );
        close(&g.gradient, &want.gradient);
        close(&[g.cost], &[want.cost]);
        let model = SandwichModel::new(lin.clone(), bl.clone(), out.clone());
        let w_sim = model.simulate(&u, &model.rest_state()).unwrap();
        close(&p.simulate(&theta).unwrap(), &w_sim);
        assert_eq!(p.cost(&theta).unwrap(), squared_error(&w, &w_sim, warmup));
        let it = p.iteration(&theta, false).unwrap();
        let (factor, moving) = SandwichRegression::new(&lin, &bl, &out, &u, &w)
            .unwrap()
            .factor(warmup);
        let ls = solve_factor(&factor, &s.ls_names(), moving).unwrap();
        close(&it.ls.theta, &ls.theta);
        close(&[it.ls.rss, it.moving_fraction], &[ls.rss, moving]);
        assert!(it.rmse.is_none());
    }
}

#[test]
fn a_feedthrough_structure_unpacks_a0_and_r1_into_the_shifted_blocks() {
    let s = Structure::new(2, 1, 2, 2, 1, true, true).unwrap();
    let want = [
        "a0", "a1", "a2", "b1", "c_L", "m_L2", "m_R1", "c_R", "m_R2", "r1", "r2", "s1",
    ];
    assert_eq!(s.names(), names(&want));
    let theta = [
        0.3, 0.6, 0.2, -0.3, 0.4, 0.1, 0.9, 0.5, 0.05, 0.4, 0.1, -0.2,
    ];
    let lin = LinearBlock::new(theta[0..3].to_vec(), vec![theta[3]]).unwrap();
    let bl = GeneralBacklash::from_estimate(
        theta[4],
        theta[7],
        vec![1.0, theta[5]],
        vec![theta[6], theta[8]],
    )
    .unwrap();
    let out = LinearBlock::new(vec![1.0, theta[9], theta[10]], vec![theta[11]]).unwrap();
    let u = input(2000);
    let model = SandwichModel::new(lin.clone(), bl.clone(), out.clone());
    let w = noisy(&model.simulate(&u, &model.rest_state()).unwrap(), 9);
    let p = Problem::new(s, u.clone(), w.clone(), 10).unwrap();
    close(
        &p.simulate(&theta).unwrap(),
        &model.simulate(&u, &model.rest_state()).unwrap(),
    );
    same_factor(
        &p.oe_factor(&theta).unwrap(),
        &sandwich_oe_factor(&lin, &bl, &out, &u, &w, 10).unwrap(),
    );
    let g = p.gradient(&theta).unwrap();
    close(
        &g.gradient,
        &sandwich_oe_gradient(&lin, &bl, &out, &u, &w, 10)
            .unwrap()
            .gradient,
    );
    // an input feedthrough alone: a cascade with a0..a2
    let c = Structure::new(2, 2, 1, 0, 0, true, false).unwrap();
    assert_eq!(
        c.names(),
        names(&["a0", "a1", "a2", "b1", "b2", "c_L", "m_R1", "c_R"])
    );
}

#[test]
fn the_record_is_checked_once_on_construction() {
    let s = Structure::new(2, 2, 3, 0, 0, false, false).unwrap();
    let data = |e: Result<Problem, Error>| match e {
        Err(Error::Data(msg)) => msg,
        other => panic!("expected a data error, got {other:?}"),
    };
    let u = input(100);
    let msg = data(Problem::new(s, u.clone(), u[..99].to_vec(), 0));
    assert!(msg.contains("u has 100 samples but y has 99"), "{msg}");
    let mut bad = u.clone();
    bad[3] = f64::NAN;
    assert!(data(Problem::new(s, u.clone(), bad, 0)).starts_with("y[3]"));
    let msg = data(Problem::new(s, u.clone(), u.clone(), 100));
    assert!(
        msg.contains("warmup = 100") && msg.contains("0 <= warmup < 100"),
        "{msg}"
    );
    assert!(data(Problem::new(s, vec![], vec![], 0)).starts_with("u is empty"));
    let p = Problem::new(s, u.clone(), u.clone(), 0).unwrap();
    assert!(matches!(p.simulate(&[0.0; 3]), Err(Error::Data(_))));
    assert!(matches!(
        Structure::new(2, 2, 3, 0, 0, false, true),
        Err(Error::Data(_))
    ));
}

/// (moving count, min x, max x) over t >= warmup from the models themselves.
fn motion_by_hand(x: &[f64], moving: usize, warmup: usize) -> (usize, f64, f64) {
    let x = &x[warmup..];
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (moving, lo, hi)
}

#[test]
fn motion_is_the_models_moving_count_and_x_range_with_or_without_a_gradient_pass() {
    // 2e5 samples: the gradient pass runs on two threads (where the machine has two) and
    // leaves its motion for `motion` at the same theta; elsewhere `motion` simulates
    let s = Structure::new(2, 2, 3, 0, 0, false, false).unwrap();
    let u = input(200_000);
    let y = noisy(
        &example1_model()
            .simulate(&u, &example1_model().rest_state())
            .unwrap(),
        3,
    );
    for warmup in [0, 17, 150_000] {
        let p = Problem::new(s, u.clone(), y.clone(), warmup).unwrap();
        for theta in [EXAMPLE1_THETA.to_vec(), perturbed(EXAMPLE1_THETA).to_vec()] {
            let (lin, bl) = cascade_blocks(&theta);
            let m = CascadeModel::new(lin.clone(), bl);
            let x = lin.simulate(&u, &lin.rest_state()).unwrap();
            let count = m.moving_count(&u, &m.rest_state(), warmup).unwrap();
            let want = motion_by_hand(&x, count, warmup);
            let fresh = p.motion(&theta).unwrap();
            assert_eq!((fresh.moving, fresh.x_min, fresh.x_max), want);
            p.gradient(&theta).unwrap();
            let after = p.motion(&theta).unwrap();
            assert_eq!((after.moving, after.x_min, after.x_max), want);
            p.oe_factor(&theta).unwrap(); // the factor's walk leaves its motion too
            let folded = p.motion(&theta).unwrap();
            assert_eq!((folded.moving, folded.x_min, folded.x_max), want);
        }
    }
    // the sandwich: the input block's x and the backlash, as SandwichModel counts them
    let s2 = Structure::new(2, 2, 3, 2, 2, false, false).unwrap();
    let u2 = input(3000);
    let m2 = example2_model();
    let w = noisy(&m2.simulate(&u2, &m2.rest_state()).unwrap(), 5);
    let p2 = Problem::new(s2, u2.clone(), w, 10).unwrap();
    let theta2 = perturbed(EXAMPLE2_THETA).to_vec();
    let (lin2, bl2, out2) = sandwich_from(&theta2);
    let x2 = lin2.simulate(&u2, &lin2.rest_state()).unwrap();
    let m2 = SandwichModel::new(lin2, bl2, out2);
    let count2 = m2.moving_count(&u2, &m2.rest_state(), 10).unwrap();
    let got = p2.motion(&theta2).unwrap();
    assert_eq!(
        (got.moving, got.x_min, got.x_max),
        motion_by_hand(&x2, count2, 10)
    );
    // several records: per record only
    let several = Problem::several(s, vec![(u.clone(), y.clone(), 0), (u, y, 0)]).unwrap();
    assert!(matches!(
        several.motion(&EXAMPLE1_THETA),
        Err(Error::Data(_))
    ));
}

/// A record longer than `BUFFERED_GRADIENT_SAMPLES` (three chunks of x): the gradient comes
/// from the output-error factor (walked in two halves) and the motion from that walk; both
/// agree with the buffered reverse pass and the model's own count over the whole record, as
/// does the motion of x simulated a chunk at a time (another theta, no walk before it).
#[test]
fn a_long_record_has_the_gradient_and_motion_of_the_buffered_passes() {
    use backlashid_core::identify::problem::BUFFERED_GRADIENT_SAMPLES;
    let s = Structure::new(2, 2, 3, 0, 0, false, false).unwrap();
    let u = input(BUFFERED_GRADIENT_SAMPLES + 12_345);
    let y = noisy(
        &example1_model()
            .simulate(&u, &example1_model().rest_state())
            .unwrap(),
        4,
    );
    let warmup = 1000;
    let p = Problem::new(s, u.clone(), y.clone(), warmup).unwrap();
    let theta = perturbed(EXAMPLE1_THETA);
    let (lin, bl) = cascade_blocks(&theta);
    let (got, want) = (
        p.gradient(&theta).unwrap(),
        cascade_oe_gradient(&lin, &bl, &u, &y, warmup).unwrap(),
    );
    let scale = want.gradient.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    for (g, w) in got.gradient.iter().zip(&want.gradient) {
        assert!((g - w).abs() <= 1e-9 * scale, "{g} vs {w}");
    }
    assert!((got.cost - want.cost).abs() <= 1e-10 * want.cost);
    let m = CascadeModel::new(lin.clone(), bl);
    let x = lin.simulate(&u, &lin.rest_state()).unwrap();
    let count = m.moving_count(&u, &m.rest_state(), warmup).unwrap();
    let motion = p.motion(&theta).unwrap();
    assert_eq!(
        (motion.moving, motion.x_min, motion.x_max),
        motion_by_hand(&x, count, warmup)
    );
    let (lin, bl) = cascade_blocks(&EXAMPLE1_THETA);
    let m = CascadeModel::new(lin.clone(), bl);
    let x = lin.simulate(&u, &lin.rest_state()).unwrap();
    let count = m.moving_count(&u, &m.rest_state(), warmup).unwrap();
    let motion = p.motion(&EXAMPLE1_THETA).unwrap();
    assert_eq!(
        (motion.moving, motion.x_min, motion.x_max),
        motion_by_hand(&x, count, warmup)
    );
}

/// From 2^21 samples the cascade's factor walks two halves on two threads, the second from a
/// guessed state that must meet the exact walk: the factor equals the one-thread walk's to
/// rounding; where the record stands still around the meeting point (the guessed backlash
/// memory never meets the exact one) it falls back on the one-pass walk, bit for bit.
#[test]
fn the_factor_walked_in_two_halves_equals_the_one_pass_walk() {
    use backlashid_core::identify::sensitivity::cascade_oe_factor_threads;
    let n = (1 << 21) + 1000;
    let mut u = input(n);
    let y = noisy(
        &example1_model()
            .simulate(&u, &example1_model().rest_state())
            .unwrap(),
        6,
    );
    let theta = perturbed(EXAMPLE1_THETA);
    let (lin, bl) = cascade_blocks(&theta);
    let one = cascade_oe_factor_threads(&lin, &bl, &u, &y, 50, 1).unwrap();
    let two = cascade_oe_factor_threads(&lin, &bl, &u, &y, 50, 2).unwrap();
    let scale = one.0.r_aug().iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    for (a, b) in two.0.r_aug().iter().zip(one.0.r_aug()) {
        assert!((a.abs() - b.abs()).abs() <= 1e-9 * scale, "{a} vs {b}");
    }
    assert!((two.1 - one.1).abs() <= 1e-11 * one.1);
    assert_eq!(two.0.rows(), one.0.rows());
    assert!(
        two != one,
        "the halves ran (their merge differs from one pass by rounding)"
    );
    for v in &mut u[n / 2 - 6000..n / 2 + 6000] {
        *v = 0.0;
    }
    let one = cascade_oe_factor_threads(&lin, &bl, &u, &y, 50, 1).unwrap();
    let two = cascade_oe_factor_threads(&lin, &bl, &u, &y, 50, 2).unwrap();
    assert_eq!(two, one);
}

/// The blocks' positions and the names agree for every kind of structure: each name sits in
/// the block its prefix says, the blocks tile theta in order.
#[test]
fn the_blocks_are_where_the_names_are() {
    for (na, nb, degree, nr, ns, ft, oft) in [
        (2, 2, 3, 0, 0, false, false),
        (1, 0, 1, 0, 0, true, false),
        (2, 2, 3, 2, 2, false, false),
        (1, 3, 2, 3, 1, true, true),
        (3, 1, 4, 1, 2, false, true),
    ] {
        for initial in [false, true] {
            let s = Structure::new(na, nb, degree, nr, ns, ft, oft)
                .unwrap()
                .with_initial_state(initial);
            let names = s.names();
            let blocks = s.blocks();
            assert_eq!(blocks.last().unwrap().1.end, names.len());
            let mut at = 0;
            for (block, range) in &blocks {
                assert_eq!(range.start, at, "{block} follows the block before it");
                at = range.end;
                for name in &names[range.clone()] {
                    assert!(name.starts_with(block), "{name} in block {block}");
                }
            }
        }
    }
}
