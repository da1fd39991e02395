//! The initial state as parameters (`identify::initial`): the compiled `Problem` with
//! `initial_state` simulates from theta's state exactly as a longer record whose prefix
//! drove the system into it, and its factor and gradient carry the exact sensitivities
//! (against central finite differences of the simulation) at random non-zero states, for
//! cascades and sandwiches of several orders, with feedthroughs, FIR blocks and warm-ups.

mod common;

use backlashid_core::identify::initial::{free_terms, order};
use backlashid_core::identify::{Problem, Structure};
use backlashid_core::{CascadeModel, Error, SandwichModel};
use common::{example1_model, example2_model, lcg_unit, noisy, smooth_input, EXAMPLE2_THETA};

/// Example 1 in the physical order a1 a2 b1 b2 c_L m_L2 m_L3 m_R1 c_R m_R2 m_R3.
const EXAMPLE1_THETA: [f64; 11] = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.5, 0.4, 0.2];

fn close(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol * scale, "[{i}] {x} vs {y}");
    }
}

/// A plausible parameter vector for a structure, read off its names (stable blocks, branches
/// that increase on the input's range), the initial state random and non-zero.
fn theta_for(names: &[String], seed: u64) -> Vec<f64> {
    let mut g = seed;
    names
        .iter()
        .map(|k| {
            let tail: usize = k
                .trim_start_matches(|c: char| !c.is_ascii_digit())
                .parse()
                .unwrap_or(0);
            let decay = 0.5f64.powi(tail as i32);
            match k.as_str() {
                "c_L" => 0.3,
                "c_R" => 0.4,
                "m_R1" => 1.2,
                "y_prev" => 0.2,
                // x(1) = x0_1 near 0: L(x) > y_prev > R(x), the record starts holding
                "x0_1" => 0.1 * (lcg_unit(&mut g) - 0.5),
                _ if k.starts_with("m_") => 0.1 * decay,
                _ if k.starts_with('a') => 0.6 * decay + 0.1,
                _ if k.starts_with('b') || k.starts_with('s') => -0.4 * decay,
                _ if k.starts_with('r') => 0.5 * decay,
                _ => lcg_unit(&mut g) - 0.5, // x0_k, w0_k
            }
        })
        .collect()
}

/// d simulate / d theta by central differences, column by column.
fn fd_jacobian(p: &Problem, theta: &[f64]) -> Vec<Vec<f64>> {
    (0..theta.len())
        .map(|k| {
            let h = 1e-6 * theta[k].abs().max(1.0);
            let (mut up, mut down) = (theta.to_vec(), theta.to_vec());
            up[k] += h;
            down[k] -= h;
            let (a, b) = (p.simulate(&up).unwrap(), p.simulate(&down).unwrap());
            a.iter().zip(&b).map(|(x, y)| (x - y) / (2.0 * h)).collect()
        })
        .collect()
}

/// The factor's R_aug^T R_aug, the gradient and the cost against [J | r] with J by finite
/// differences; returns J for further checks.
fn check_sensitivities(p: &Problem, theta: &[f64]) -> Vec<Vec<f64>> {
    let jac = fd_jacobian(p, theta);
    let sim = p.simulate(theta).unwrap();
    let ts = p.warmup()..sim.len();
    let r: Vec<f64> = ts.clone().map(|t| p.y()[t] - sim[t]).collect();
    let n = theta.len();
    let col = |j: usize| -> Vec<f64> {
        match j < n {
            true => jac[j][p.warmup()..].to_vec(),
            false => r.clone(),
        }
    };
    let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
    let (factor, cost) = p.oe_factor(theta).unwrap();
    close(&[cost], &[dot(&r, &r)], 1e-12);
    let ra = factor.r_aug();
    let m = n + 1;
    let size = (0..m).map(|j| dot(&col(j), &col(j))).fold(0.0, f64::max);
    for i in 0..m {
        for j in 0..m {
            let rtr: f64 = (0..m).map(|k| ra[k * m + i] * ra[k * m + j]).sum();
            let gram = dot(&col(i), &col(j));
            assert!(
                (rtr - gram).abs() <= 1e-7 * size,
                "{} x {}: factor {rtr}, finite differences {gram}",
                p.names()[i.min(n - 1)],
                p.names()[j.min(n - 1)]
            );
        }
    }
    let g = p.gradient(theta).unwrap();
    close(&[g.cost], &[cost], 1e-12);
    let want: Vec<f64> = (0..n).map(|j| dot(&col(j), &r)).collect();
    let scale = (0..n)
        .map(|j| dot(&col(j), &col(j)).sqrt() * dot(&r, &r).sqrt())
        .fold(0.0, f64::max);
    for (j, (a, b)) in g.gradient.iter().zip(&want).enumerate() {
        assert!(
            (a - b).abs() <= 1e-7 * scale,
            "gradient {}: {a} against {b}",
            p.names()[j]
        );
    }
    jac
}

#[test]
fn initial_state_names_follow_the_model_and_size_the_free_response() {
    let s = Structure::new(2, 2, 3, 0, 0, false, false)
        .unwrap()
        .with_initial_state(true);
    assert_eq!(&s.names()[11..], ["x0_1", "x0_2", "y_prev"]);
    assert_eq!((s.size(), s.model_size(), s.initial_size()), (14, 11, 3));
    assert_eq!(s.ls_names().len(), 11); // the paper's iteration has no initial state
    let fir = Structure::new(3, 0, 1, 2, 0, true, false)
        .unwrap()
        .with_initial_state(true);
    let n = fir.names();
    assert_eq!(
        &n[n.len() - 7..],
        ["x0_1", "x0_2", "x0_3", "x0_4", "y_prev", "w0_1", "w0_2"]
    );
    assert_eq!(order(1, 3), 3);
    let s = Structure::new(1, 3, 1, 0, 0, false, false).unwrap();
    assert_eq!(s.with_initial_state(true).size(), s.size() + 4);
    assert_eq!(s.with_initial_state(false), s);
}

#[test]
fn sensitivities_of_the_initial_state_match_finite_differences() {
    let u = smooth_input(500);
    for (seed, (na, nb, degree, nr, ns, ft, oft)) in [
        (2, 2, 3, 0, 0, false, false),
        (2, 0, 2, 0, 0, true, false),
        (1, 3, 2, 0, 0, false, false),
        (2, 2, 3, 2, 2, false, false),
        (2, 1, 2, 2, 1, true, true),
        (1, 2, 2, 3, 0, false, false),
        (2, 2, 1, 1, 2, false, false),
    ]
    .into_iter()
    .enumerate()
    {
        let s = Structure::new(na, nb, degree, nr, ns, ft, oft)
            .unwrap()
            .with_initial_state(true);
        let theta = theta_for(&s.names(), 11 + seed as u64);
        let rest = Problem::new(s, u.clone(), u.clone(), 0).unwrap();
        let y = noisy(&rest.simulate(&theta).unwrap(), 3 + seed as u64);
        for warmup in [0, 5] {
            let p = Problem::new(s, u.clone(), y.clone(), warmup).unwrap();
            let jac = check_sensitivities(&p, &theta);
            // y_prev matters: the record starts holding (dy/dy_prev = 1 there; the sandwich's
            // w sees y one sample later)
            let y_prev = s.model_size() + s.n_x0();
            let first = usize::from(s.is_sandwich());
            assert!(jac[y_prev][first] != 0.0, "{s:?}: y_prev does not act");
            // every value acts (an FIR block's x0_k acts on x(k) only, here held)
            let x0_acts = nb > 0;
            let names = s.names();
            for (k, column) in jac.iter().enumerate().skip(s.model_size()) {
                if x0_acts || k >= y_prev {
                    assert!(column.iter().any(|v| *v != 0.0), "{}", names[k]);
                }
            }
        }
    }
}

#[test]
fn the_state_held_in_the_band_is_y_prev_until_the_first_move() {
    let s = Structure::new(2, 2, 3, 0, 0, false, false)
        .unwrap()
        .with_initial_state(true);
    let mut theta = EXAMPLE1_THETA.to_vec();
    theta.extend([0.1, -0.05, 0.2]); // x(1) = 0.1: L(x) = 0.66 > 0.2 > R(x) = -0.55, a hold
    let u = vec![0.0; 40]; // no input: x decays inside the band, y stays at y_prev
    let p = Problem::new(s, u.clone(), u, 0).unwrap();
    let sim = p.simulate(&theta).unwrap();
    assert!(sim.iter().all(|v| *v == 0.2), "{sim:?}");
    let jac = fd_jacobian(&p, &theta);
    close(&jac[13], &[1.0; 40], 1e-8);
}

#[test]
fn a_simulation_from_a_state_equals_the_longer_record_that_led_there() {
    let u = smooth_input(1500);
    let cut = 613;
    // cascade (Example 1)
    let m: CascadeModel = example1_model();
    let whole = m.simulate(&u, &m.rest_state()).unwrap();
    let head = m.simulate_internals(&u[..cut], &m.rest_state()).unwrap();
    let st = &head.final_state;
    let mut theta = EXAMPLE1_THETA.to_vec();
    theta.extend(free_terms(&m.linear, &st.linear).unwrap());
    theta.push(st.y_prev);
    let s = Structure::new(2, 2, 3, 0, 0, false, false)
        .unwrap()
        .with_initial_state(true);
    let tail = u[cut..].to_vec();
    let p = Problem::new(s, tail.clone(), whole[cut..].to_vec(), 0).unwrap();
    close(&p.simulate(&theta).unwrap(), &whole[cut..], 1e-12);
    assert!(p.oe_factor(&theta).unwrap().1 < 1e-24);
    // from rest the cut record is off at its start
    let rest = Problem::new(s.with_initial_state(false), tail.clone(), tail.clone(), 0).unwrap();
    let from_rest = rest.simulate(&EXAMPLE1_THETA).unwrap();
    assert!((from_rest[0] - whole[cut]).abs() > 1e-3);

    // sandwich (Example 2): the output block's past input u_past[0] is the memory y(0)
    let m: SandwichModel = example2_model();
    let whole = m.simulate(&u, &m.rest_state()).unwrap();
    let head = m.simulate_internals(&u[..cut], &m.rest_state()).unwrap();
    let st = &head.final_state;
    let mut theta = EXAMPLE2_THETA.to_vec();
    theta.extend(free_terms(&m.input_linear, &st.input).unwrap());
    theta.push(st.output.u_past[0]);
    theta.extend(free_terms(&m.output_linear, &st.output).unwrap());
    let s = Structure::new(2, 2, 3, 2, 2, false, false)
        .unwrap()
        .with_initial_state(true);
    let p = Problem::new(s, tail, whole[cut..].to_vec(), 0).unwrap();
    close(&p.simulate(&theta).unwrap(), &whole[cut..], 1e-12);
    let g = p.gradient(&theta).unwrap();
    assert!(g.cost < 1e-24 && g.gradient.iter().all(|v| v.abs() < 1e-10));
}

#[test]
fn a_bad_initial_state_is_refused_and_the_iteration_ignores_it() {
    let s = Structure::new(2, 2, 3, 0, 0, false, false)
        .unwrap()
        .with_initial_state(true);
    let u = smooth_input(300);
    let y = example1_model()
        .simulate(&u, &example1_model().rest_state())
        .unwrap();
    let p = Problem::new(s, u, y, 0).unwrap();
    let mut theta = EXAMPLE1_THETA.to_vec();
    theta.extend([0.3, f64::NAN, 0.0]);
    match p.simulate(&theta) {
        Err(Error::Model(m)) => assert!(m.contains("x0_2"), "{m}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(p.simulate(&EXAMPLE1_THETA), Err(Error::Data(_))));
    assert!(matches!(p.oe_factor(&EXAMPLE1_THETA), Err(Error::Data(_))));
    theta[12] = -0.2;
    let with_state = p.iteration(&theta, false).unwrap();
    let from_rest = Problem::new(
        s.with_initial_state(false),
        p.u().to_vec(),
        p.y().to_vec(),
        0,
    )
    .unwrap()
    .iteration(&EXAMPLE1_THETA, false)
    .unwrap();
    assert_eq!(with_state.ls.theta, from_rest.ls.theta);
    assert_eq!(with_state.ls.theta.len(), 11);
    let without = p.iteration(&EXAMPLE1_THETA, false).unwrap(); // theta without the state
    assert_eq!(without.ls.theta, from_rest.ls.theta);
}

/// The sensitivity walk simulates x a chunk of 2^20 samples at a time; on a record of three
/// chunks its output equals one whole-record simulation bit for bit (cascade and sandwich).
#[test]
fn the_walk_across_chunks_of_x_equals_one_whole_record_simulation() {
    use backlashid_core::identify::{cascade_sensitivity, sandwich_sensitivity};
    let u = smooth_input((1 << 21) + 12_345);
    let m = example1_model();
    let walked = cascade_sensitivity(&m.linear, &m.backlash, &u).unwrap();
    assert!(walked.output == m.simulate(&u, &m.rest_state()).unwrap());
    let m = example2_model();
    let walked = sandwich_sensitivity(&m.input_linear, &m.backlash, &m.output_linear, &u).unwrap();
    assert!(walked.output == m.simulate(&u, &m.rest_state()).unwrap());
}
