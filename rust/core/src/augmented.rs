//! The nominal cascade (eq 16 -> eq 1) with effects of the diagnosis catalogue, simulated
//! sample by sample in one fused pass. Every effect ([`crate::effects`], one module each) is an
//! optional term that gives exactly the nominal model at zero size, so a refit of the effect's
//! parameters starts from the nominal fit. Per sample, in this order:
//!
//! - drive stage (dead time, saturation, friction): the linear block's input u_eff(t);
//! - widths stage (width drift): the dead-band widths of that time;
//! - the backlash (eq 1) on x(t);
//! - output stage (compliance, extra plays, output offset, quantiser).
//!
//! Time t is 0-based within the record; `t0` places the record in a longer continuous one
//! (the validation record follows the estimation record), tau = (t0 + t) / time_scale.

use crate::effects::{AnyEffect, Sample, Stage};
use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::{check_memory, GeneralBacklash};
use crate::model::cascade::{CascadeModel, CascadeState};
use crate::model::linear::{LinearBlock, LinearState};
use crate::model::signal::check_signal;

/// Default samples per time unit of the drifts.
pub const TIME_SCALE: f64 = 1000.0;

/// Horner's rule for sum_{i>=1} m_i xi^i (eq 4-5).
#[inline(always)]
pub(crate) fn branch(m: &[f64], xi: f64) -> f64 {
    let mut acc = 0.0;
    for c in m.iter().rev() {
        acc = acc * xi + c;
    }
    acc * xi
}

/// Eq (1) with its case order: L first, then R, else hold.
#[inline(always)]
fn select(l: f64, r: f64, y_prev: f64) -> f64 {
    if l <= y_prev {
        l
    } else if r >= y_prev {
        r
    } else {
        y_prev
    }
}

/// The augmented cascade's output for the input `u`, from `state` (the linear block's past of
/// the effective input and of x, and the backlash memory), with `effects` (any order; each
/// applies at its place in the pass, see the module docs). `t0` is the time of u[0] in the
/// continuous record and `time_scale` the samples per time unit (drifts only).
pub fn simulate_augmented(
    model: &CascadeModel,
    effects: &[AnyEffect],
    u: &[f64],
    t0: f64,
    time_scale: f64,
    state: &CascadeState,
) -> Result<Vec<f64>> {
    check_signal("u", u)?;
    model.linear.check_state(&state.linear, "state.linear")?;
    check_memory(state.y_prev)?;
    for e in effects {
        e.check()?;
    }
    if !(time_scale.is_finite() && time_scale > 0.0) {
        return Err(Error::Data(format!(
            "time_scale = {time_scale}: give a positive number of samples per time unit"
        )));
    }
    if !t0.is_finite() {
        return Err(Error::Data(format!(
            "t0 = {t0}: give the record's start time in samples"
        )));
    }
    let lin = &model.linear;
    let bl: &GeneralBacklash = &model.backlash;
    let (m_l, m_r) = (bl.left().coefficients(), bl.right().coefficients());
    let (c_l, c_r) = (bl.c_left(), bl.c_right());
    let x0 = state.linear.x_past.first().copied().unwrap_or(0.0);
    // fresh copies with their memories at rest on x(0), y(0), in the order of the pass
    let mut running: Vec<AnyEffect> = effects.iter().map(|e| e.start(x0, state.y_prev)).collect();
    running.sort_by_key(|e| e.order());
    let mut drive: Vec<AnyEffect> = Vec::new();
    let mut widths: Vec<AnyEffect> = Vec::new();
    let mut output: Vec<AnyEffect> = Vec::new();
    for e in running {
        match e.stage() {
            Stage::Drive => drive.push(e),
            Stage::Widths => widths.push(e),
            Stage::Output => output.push(e),
        }
    }
    let n = u.len();
    let mut u_eff = guard::filled(n, 0.0, "u_eff")?;
    let mut x = guard::filled(n, 0.0, "x")?;
    let mut y = guard::filled(n, 0.0, "y")?;
    let mut y_prev = state.y_prev;
    let mut x_prev = x0;
    let free = drive.iter().any(|e| e.needs_free());
    let gain = free_gain(lin);
    for t in 0..n {
        let xt = lin.output_at(&u_eff, &x, t, &state.linear);
        x[t] = xt;
        let mut s = Sample {
            t,
            u,
            x: xt,
            x_prev,
            f: 0.0,
            tau: (t0 + t as f64) / time_scale,
            x_free: if free {
                free_response(lin, &u_eff, &x, t, &state.linear)
            } else {
                0.0
            },
            gain,
        };
        // the drive input of the linear block at t
        let mut v = u[t];
        for e in drive.iter_mut() {
            v = e.drive(v, &s);
        }
        u_eff[t] = v;
        x_prev = xt;
        let mut c = None;
        for e in &widths {
            if let Some(w) = e.widths(c_l, c_r, &s) {
                c = Some(w);
            }
        }
        let f = match c {
            Some((cl, cr)) => select(branch(m_l, xt + cl), branch(m_r, xt - cr), y_prev),
            None => bl.step(xt, y_prev),
        };
        y_prev = f;
        s.f = f;
        let mut out = f;
        for e in output.iter_mut() {
            out = e.output(out, &s);
        }
        if !(out.is_finite() && xt.is_finite()) {
            return Err(diverged(t, xt, out));
        }
        y[t] = out;
    }
    Ok(y)
}

/// a_1, the weight of u_eff(t) in x(t+1) (0 for a block with feedthrough, whose x(t+1) also
/// takes u(t+1): the stick rule is then off).
pub(crate) fn free_gain(lin: &LinearBlock) -> f64 {
    if lin.feedthrough().is_some() {
        0.0
    } else {
        lin.a().first().copied().unwrap_or(0.0)
    }
}

/// x(t+1) without the term a_1 u_eff(t): sum_{i >= 2} a_i u_eff(t+1-i) - sum_j b_j x(t+1-j),
/// with x(0..=t) and u_eff(0..t) of the record and the state's past before it.
pub(crate) fn free_response(
    lin: &LinearBlock,
    u_eff: &[f64],
    x: &[f64],
    t: usize,
    state: &LinearState,
) -> f64 {
    let past = |k: usize, now: &[f64], before: &[f64]| {
        if k <= t {
            now[t - k]
        } else {
            before[k - t - 1]
        }
    };
    let mut acc = 0.0;
    for (i, ai) in lin.a().iter().enumerate().skip(1) {
        // u_eff(t + 1 - (i + 1)) = lag i from t
        acc += ai * past(i, u_eff, &state.u_past);
    }
    for (j, bj) in lin.b().iter().enumerate() {
        // x(t + 1 - (j + 1)) = lag j from t (lag 0: x(t))
        acc -= bj
            * if j == 0 {
                x[t]
            } else {
                past(j, x, &state.x_past)
            };
    }
    acc
}

/// The simulation's refusal where x(t) or y(t) is not finite.
pub(crate) fn diverged(t: usize, xt: f64, out: f64) -> Error {
    Error::Model(format!(
        "the augmented model diverged at sample {t} (x = {xt}, y = {out}): the linear block \
         or the friction feedback is unstable; reduce F_v or check the poles"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::from_parameters;
    use crate::model::linear::LinearBlock;

    fn model(degree3: bool) -> CascadeModel {
        let (ml, mr) = if degree3 {
            (vec![1.0, -0.3, 0.3], vec![1.5, 0.4, 0.2])
        } else {
            (vec![1.0], vec![1.2])
        };
        CascadeModel::new(
            LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap(),
            GeneralBacklash::new(0.6, 0.5, ml, mr).unwrap(),
        )
    }

    fn input(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| 1.2 * ((k as f64) * 0.13).sin() + 0.4 * ((k as f64) * 0.71).cos())
            .collect()
    }

    fn max_diff(a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    }

    /// The effects of (name, parameters) pairs.
    fn fx(list: &[(&str, &[f64])]) -> Vec<AnyEffect> {
        list.iter()
            .map(|(name, p)| from_parameters(name, p).unwrap())
            .collect()
    }

    fn sim(m: &CascadeModel, e: &[(&str, &[f64])], u: &[f64], t0: f64, ts: f64) -> Vec<f64> {
        simulate_augmented(m, &fx(e), u, t0, ts, &m.rest_state()).unwrap()
    }

    #[test]
    fn zero_size_effects_are_the_nominal_model() {
        let u = input(700);
        let zero: &[(&str, &[f64])] = &[
            ("dead_time", &[0.0]),
            ("saturation", &[f64::NEG_INFINITY, f64::INFINITY]),
            ("friction", &[0.0, 0.0]),
            ("width_drift", &[0.0, 0.0]),
            ("compliance", &[0.0, 0.4, 0.05]),
            ("hysteresis_memory", &[0.3, 0.0, 0.1, 0.0]),
            ("output_offset", &[0.0, 0.0]),
            ("quantization", &[0.0]),
        ];
        for m in [model(true), model(false)] {
            let nominal = m.simulate(&u, &m.rest_state()).unwrap();
            let aug = sim(&m, zero, &u, 123.0, TIME_SCALE);
            assert!(max_diff(&aug, &nominal) < 1e-12);
            // from a non-rest state too
            let s = m.simulate_internals(&u[..300], &m.rest_state()).unwrap();
            let nominal = m.simulate(&u[300..], &s.final_state).unwrap();
            let aug = simulate_augmented(&m, &fx(zero), &u[300..], 0.0, TIME_SCALE, &s.final_state)
                .unwrap();
            assert!(max_diff(&aug, &nominal) < 1e-12);
        }
    }

    #[test]
    fn the_order_of_the_list_does_not_matter() {
        let m = model(true);
        let u = input(500);
        let a = sim(
            &m,
            &[
                ("quantization", &[0.05]),
                ("friction", &[0.05, 0.1]),
                ("dead_time", &[2.0]),
                ("output_offset", &[0.1, 0.2]),
                ("compliance", &[0.5, 0.6, 0.1]),
            ],
            &u,
            0.0,
            TIME_SCALE,
        );
        let b = sim(
            &m,
            &[
                ("dead_time", &[2.0]),
                ("friction", &[0.05, 0.1]),
                ("compliance", &[0.5, 0.6, 0.1]),
                ("output_offset", &[0.1, 0.2]),
                ("quantization", &[0.05]),
            ],
            &u,
            0.0,
            TIME_SCALE,
        );
        assert_eq!(a, b);
    }

    #[test]
    fn dead_time_shifts_the_input() {
        let m = model(true);
        let u = input(400);
        let mut shifted = vec![0.0; 3];
        shifted.extend_from_slice(&u[..397]);
        let want = m.simulate(&shifted, &m.rest_state()).unwrap();
        let got = sim(&m, &[("dead_time", &[3.0])], &u, 0.0, TIME_SCALE);
        assert!(max_diff(&got, &want) < 1e-12);
    }

    #[test]
    fn saturation_clips_the_input() {
        let m = model(true);
        let u = input(400);
        let clipped: Vec<f64> = u.iter().map(|v| v.clamp(-0.8, 0.9)).collect();
        let want = m.simulate(&clipped, &m.rest_state()).unwrap();
        let got = sim(&m, &[("saturation", &[-0.8, 0.9])], &u, 0.0, TIME_SCALE);
        assert!(max_diff(&got, &want) < 1e-12);
    }

    #[test]
    fn friction_by_hand_on_a_first_order_block() {
        // x(t) = 0.5 u_eff(t-1); u = 1 throughout, F_c = 0.1, F_v = 0.2, straight backlash.
        let m = CascadeModel::new(
            LinearBlock::new(vec![0.5], vec![]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        let y = sim(&m, &[("friction", &[0.1, 0.2])], &[1.0; 3], 0.0, TIME_SCALE);
        // t=0: x=0, v=0 -> u_eff = 1; t=1: x=0.5, v=0.5 -> u_eff = 1 - 0.1 - 0.1 = 0.8;
        // t=2: x=0.4, v=-0.1 -> identity backlash y = x.
        assert!(max_diff(&y, &[0.0, 0.5, 0.4]) < 1e-15);
    }

    #[test]
    fn stick_slip_by_hand_on_a_first_order_block() {
        // x(t+1) = 0.5 u_eff(t) + 0.5 x(t), F_c = 0.3, static 0.3 + 0.1, straight backlash.
        let m = CascadeModel::new(
            LinearBlock::new(vec![0.5], vec![-0.5]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        let y = sim(
            &m,
            &[("stick_slip", &[0.3, 0.0, 0.1, 0.05])],
            &[0.35, 1.0, 1.0],
            0.0,
            TIME_SCALE,
        );
        // t=0: x=0, free 0, u_stay = 0, hold 0.35 <= 0.4: stuck, u_eff = 0;
        // t=1: x=0, hold 1 > 0.4: slides, v = 0 so the dip is whole: u_eff = 1 - 0.4 = 0.6;
        // t=2: x = 0.3.
        assert!(max_diff(&y, &[0.0, 0.0, 0.3]) < 1e-15);
    }

    #[test]
    fn width_drift_equals_the_backlash_with_the_widths_of_that_time() {
        let m = model(false);
        let u = input(50);
        let y = sim(&m, &[("width_drift", &[0.2, 0.05])], &u, 1000.0, 100.0);
        // sample 40: tau = 10.4; recompute that step with a backlash of those widths
        let x = m.linear.simulate(&u, &m.linear.rest_state()).unwrap();
        let bl = GeneralBacklash::new(0.6 + 2.08, 0.5 + 0.52, vec![1.0], vec![1.2]).unwrap();
        assert!((bl.step(x[40], y[39]) - y[40]).abs() < 1e-12);
    }

    #[test]
    fn compliance_has_unit_dc_gain_and_rings() {
        let m = CascadeModel::new(
            LinearBlock::new(vec![1.0], vec![]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        let y = sim(
            &m,
            &[("compliance", &[1.0, 0.3, 0.05])],
            &[1.0; 2000],
            0.0,
            TIME_SCALE,
        );
        assert!((y[1999] - 1.0).abs() < 1e-9);
        let peak = y.iter().cloned().fold(f64::MIN, f64::max);
        assert!(
            peak > 1.7,
            "a zeta = 0.05 step response overshoots by ~85 %: {peak}"
        );
    }

    #[test]
    fn plays_offset_and_quantiser_by_hand() {
        let m = CascadeModel::new(
            LinearBlock::new(vec![1.0], vec![]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        // x = u(t-1): 0, 1, 0.5, -1; play r = 0.25: 0, 0.75, 0.75, -0.75
        let u = [1.0, 0.5, -1.0, 0.0];
        let y = sim(
            &m,
            &[("hysteresis_memory", &[0.25, 2.0])],
            &u,
            0.0,
            TIME_SCALE,
        );
        assert!(max_diff(&y, &[0.0, 2.5, 2.0, -2.5]) < 1e-15);
        let y = sim(&m, &[("output_offset", &[0.1, 1.0])], &u, 10.0, 10.0);
        assert!(max_diff(&y, &[1.1, 2.2, 1.8, 0.4]) < 1e-12);
        let y = sim(&m, &[("quantization", &[0.4])], &u, 0.0, TIME_SCALE);
        assert!(max_diff(&y, &[0.0, 1.2, 0.4, -1.2]) < 1e-12);
    }

    #[test]
    fn bad_effects_are_errors_not_panics() {
        let m = model(true);
        let u = input(10);
        let bad: &[(&str, &[f64])] = &[
            ("saturation", &[1.0, -1.0]),
            ("quantization", &[-1.0]),
            ("compliance", &[1.0, 4.0, 0.1]),
            ("hysteresis_memory", &[-0.1, 1.0]),
            ("hysteresis_memory", &[0.1]),
            ("dead_time", &[1.5]),
            ("friction", &[0.1]),
            ("gremlins", &[]),
        ];
        for (name, p) in bad {
            assert!(
                matches!(from_parameters(name, p), Err(Error::Model(_))),
                "{name}"
            );
        }
        assert!(simulate_augmented(&m, &[], &u, 0.0, 0.0, &m.rest_state()).is_err());
        assert!(matches!(
            simulate_augmented(&m, &[], &[f64::NAN], 0.0, TIME_SCALE, &m.rest_state()),
            Err(Error::Data(_))
        ));
        let wild = fx(&[("friction", &[0.0, -50.0])]);
        assert!(matches!(
            simulate_augmented(&m, &wild, &input(2000), 0.0, TIME_SCALE, &m.rest_state()),
            Err(Error::Model(_))
        ));
    }
}
