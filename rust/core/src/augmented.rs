//! The nominal chain, the cascade (eq 16 -> eq 1) or the sandwich (eq 16 -> eq 1 -> eq 29;
//! the input backlash is the sandwich with input block 1), with effects of the diagnosis
//! catalogue, simulated sample by sample in one fused pass. Every effect
//! ([`crate::effects`], one module each) is an optional term that gives exactly the nominal
//! model at zero size, so a refit of the effect's parameters starts from the nominal fit.
//! Per sample, in this order:
//!
//! - the linear block (eq 16): x(t) from the drive's and x's past;
//! - state stage (state saturation): x(t) itself, as the recursion stores it;
//! - drive stage (dead time, saturation, friction): the linear block's input u_eff(t);
//! - widths stage (width drift): the dead-band widths of that time;
//! - the backlash (eq 1) on x(t): f(t);
//! - load stage (compliance, extra plays): on f(t), the load the backlash drives;
//! - the sandwich's output block (eq 29): w(t) = sum r_i y_L(t-i) - sum s_j w(t-j) of the
//!   load's output y_L (none for a cascade);
//! - output stage (output offset, sensor saturation, quantiser): the measured output.
//!
//! Time t is 0-based within the record; `t0` places the record in a longer continuous one
//! (the validation record follows the estimation record), tau = (t0 + t) / time_scale.

use crate::effects::{AnyEffect, Sample, Stage};
use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::{check_memory, GeneralBacklash};
use crate::model::cascade::{CascadeModel, CascadeState};
use crate::model::linear::{LinearBlock, LinearState};
use crate::model::sandwich::{SandwichModel, SandwichState};
use crate::model::signal::check_signal;

/// Default samples per time unit of the drifts.
pub const TIME_SCALE: f64 = 1000.0;

/// The nominal chain the effects augment: the cascade (input block, backlash) and, for the
/// sandwich, its output block (r = a, s = b of eq 29; no feedthrough).
#[derive(Debug, Clone, PartialEq)]
pub struct AugmentedChain {
    pub cascade: CascadeModel,
    pub output: Option<LinearBlock>,
}

/// Where a record of an [`AugmentedChain`] starts: the input block's past and the backlash
/// memory y(0) (`cascade`), and for the sandwich the output block's (`output.u_past` =
/// [y(0), y(-1), ..] its past inputs, whose newest is the backlash memory, as in
/// [`SandwichState`]; `output.x_past` its past outputs w). The effects start at rest on it.
#[derive(Debug, Clone, PartialEq)]
pub struct AugmentedState {
    pub cascade: CascadeState,
    pub output: Option<LinearState>,
}

impl From<CascadeModel> for AugmentedChain {
    fn from(cascade: CascadeModel) -> Self {
        Self {
            cascade,
            output: None,
        }
    }
}

impl From<SandwichModel> for AugmentedChain {
    fn from(m: SandwichModel) -> Self {
        Self {
            cascade: CascadeModel::new(m.input_linear, m.backlash),
            output: Some(m.output_linear),
        }
    }
}

impl From<CascadeState> for AugmentedState {
    fn from(cascade: CascadeState) -> Self {
        Self {
            cascade,
            output: None,
        }
    }
}

impl From<SandwichState> for AugmentedState {
    fn from(s: SandwichState) -> Self {
        Self {
            cascade: CascadeState {
                linear: s.input,
                y_prev: s.output.u_past.first().copied().unwrap_or(0.0),
            },
            output: Some(s.output),
        }
    }
}

impl AugmentedChain {
    /// At rest: every past and the backlash memory zero.
    pub fn rest_state(&self) -> AugmentedState {
        AugmentedState {
            cascade: self.cascade.rest_state(),
            output: self.output.as_ref().map(LinearBlock::rest_state),
        }
    }

    /// The output block fits the sandwich (at least r_1, no feedthrough) and `state` fits
    /// the chain: the pasts' lengths, finite values, the output block's newest past input
    /// the backlash memory.
    pub fn check_state(&self, state: &AugmentedState) -> Result<()> {
        self.cascade
            .linear
            .check_state(&state.cascade.linear, "state.linear")?;
        check_memory(state.cascade.y_prev)?;
        match (&self.output, &state.output) {
            (None, None) => Ok(()),
            (Some(block), Some(past)) => {
                if block.feedthrough().is_some() || block.na() == 0 {
                    return Err(Error::Model(
                        "the sandwich's output block takes r_1.. without feedthrough (the                          diagnosis delays the record instead)"
                            .into(),
                    ));
                }
                block.check_state(past, "state.output")?;
                if past.u_past[0] != state.cascade.y_prev {
                    return Err(Error::Data(format!(
                        "y_past[0] = {} but y_prev = {}: the output block's newest past input                          is the backlash memory y(0); give the same value",
                        past.u_past[0], state.cascade.y_prev
                    )));
                }
                Ok(())
            }
            (Some(_), None) => Err(Error::Data(
                "a sandwich's state needs the output block's past (y_past, w_past)".into(),
            )),
            (None, Some(_)) => Err(Error::Data(
                "y_past and w_past are the sandwich's output block's past: a cascade has none                  (give r and s for a sandwich)"
                    .into(),
            )),
        }
    }
}

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

/// t0 finite, time_scale positive and finite.
pub(crate) fn check_time(t0: f64, time_scale: f64) -> Result<()> {
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
    Ok(())
}

/// The effects, started at rest on x(0), y(0) and sorted into the pass's stages (each in
/// its order): state, drive, widths, load, output.
pub(crate) struct Stages<T> {
    pub(crate) state: Vec<T>,
    pub(crate) drive: Vec<T>,
    pub(crate) widths: Vec<T>,
    pub(crate) load: Vec<T>,
    pub(crate) output: Vec<T>,
}

impl<T> Stages<T> {
    /// `running` sorted by `effect(..).order()` into their stages.
    pub(crate) fn sort(mut running: Vec<T>, effect: impl Fn(&T) -> &AnyEffect) -> Self {
        running.sort_by_key(|e| effect(e).order());
        let mut s = Stages {
            state: Vec::new(),
            drive: Vec::new(),
            widths: Vec::new(),
            load: Vec::new(),
            output: Vec::new(),
        };
        for e in running {
            match effect(&e).stage() {
                Stage::State => s.state.push(e),
                Stage::Drive => s.drive.push(e),
                Stage::Widths => s.widths.push(e),
                Stage::Load => s.load.push(e),
                Stage::Output => s.output.push(e),
            }
        }
        s
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
    model.linear.check_state(&state.linear, "state.linear")?;
    check_memory(state.y_prev)?;
    run(model, None, effects, u, t0, time_scale, state)
}

/// [`simulate_augmented`] of any chain: the cascade, or the sandwich with its output block
/// between the load and the output stage, from `state` (checked by
/// [`AugmentedChain::check_state`]).
pub fn simulate_augmented_chain(
    chain: &AugmentedChain,
    effects: &[AnyEffect],
    u: &[f64],
    t0: f64,
    time_scale: f64,
    state: &AugmentedState,
) -> Result<Vec<f64>> {
    chain.check_state(state)?;
    let output = chain.output.as_ref().zip(state.output.as_ref());
    run(
        &chain.cascade,
        output,
        effects,
        u,
        t0,
        time_scale,
        &state.cascade,
    )
}

/// The fused pass of a checked state (`output`: the sandwich's output block and its past).
fn run(
    model: &CascadeModel,
    output: Option<(&LinearBlock, &LinearState)>,
    effects: &[AnyEffect],
    u: &[f64],
    t0: f64,
    time_scale: f64,
    state: &CascadeState,
) -> Result<Vec<f64>> {
    check_signal("u", u)?;
    for e in effects {
        e.check()?;
    }
    check_time(t0, time_scale)?;
    let lin = &model.linear;
    let bl: &GeneralBacklash = &model.backlash;
    let (m_l, m_r) = (bl.left().coefficients(), bl.right().coefficients());
    let (c_l, c_r) = (bl.c_left(), bl.c_right());
    let x0 = state.linear.x_past.first().copied().unwrap_or(0.0);
    let u_before = state.linear.u_past.first().copied().unwrap_or(0.0);
    // fresh copies with their memories at rest on x(0), y(0), in the order of the pass
    let running: Vec<AnyEffect> = effects.iter().map(|e| e.start(x0, state.y_prev)).collect();
    let Stages {
        state: mut on_x,
        mut drive,
        widths,
        mut load,
        output: mut sensor,
    } = Stages::sort(running, |e| e);
    let n = u.len();
    let mut u_eff = guard::filled(n, 0.0, "u_eff")?;
    let mut x = guard::filled(n, 0.0, "x")?;
    let mut y = guard::filled(n, 0.0, "y")?;
    // the output block's input y_L (the load's output) and output w (sandwich only)
    let len_w = if output.is_some() { n } else { 0 };
    let mut y_load = guard::filled(len_w, 0.0, "y_load")?;
    let mut w = guard::filled(len_w, 0.0, "w")?;
    let mut y_prev = state.y_prev;
    let mut x_prev = x0;
    let free = drive.iter().any(|e| e.needs_free());
    let gain = free_gain(lin);
    for t in 0..n {
        let mut s = Sample {
            t,
            u,
            u_prev: if t > 0 { u[t - 1] } else { u_before },
            x: lin.output_at(&u_eff, &x, t, &state.linear),
            x_prev,
            f: 0.0,
            tau: (t0 + t as f64) / time_scale,
            x_free: 0.0,
            gain,
        };
        // x(t) as the recursion stores it
        let mut xt = s.x;
        for e in on_x.iter_mut() {
            xt = e.state(xt, &s);
        }
        x[t] = xt;
        s.x = xt;
        if free {
            s.x_free = free_response(lin, &u_eff, &x, t, &state.linear);
        }
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
        for e in load.iter_mut() {
            out = e.output(out, &s);
        }
        if let Some((block, past)) = output {
            // eq (29): w(t) of y_L up to t-1, then y_L(t) joins its past
            let wt = block.output_at(&y_load, &w, t, past);
            y_load[t] = out;
            w[t] = wt;
            out = wt;
        }
        for e in sensor.iter_mut() {
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

    /// Example 2's sandwich and an input backlash (Hammerstein: input block 1) of it.
    fn sandwiches() -> Vec<(&'static str, AugmentedChain)> {
        let ex2 = crate::test_params::example2_model();
        let hammerstein = SandwichModel::new(
            LinearBlock::new(vec![1.0], vec![]).unwrap(),
            ex2.backlash.clone(),
            ex2.output_linear.clone(),
        );
        vec![
            ("example 2", ex2.into()),
            ("hammerstein", hammerstein.into()),
        ]
    }

    /// The sandwich model of an augmented sandwich chain.
    fn plain(chain: &AugmentedChain) -> SandwichModel {
        SandwichModel::new(
            chain.cascade.linear.clone(),
            chain.cascade.backlash.clone(),
            chain.output.clone().unwrap(),
        )
    }

    /// Without effects the sandwich pass is `SandwichModel::simulate` to the bit, from rest
    /// and from the busy state a first run left (an explicit start); the cascade's likewise.
    #[test]
    fn without_effects_the_chain_is_the_plain_model_from_any_start() {
        let u = input(900);
        for (name, chain) in sandwiches() {
            let m = plain(&chain);
            let rest = m.rest_state();
            let want = m.simulate(&u, &rest).unwrap();
            let got =
                simulate_augmented_chain(&chain, &[], &u, 0.0, TIME_SCALE, &rest.clone().into())
                    .unwrap();
            assert_eq!(got, want, "{name} from rest");
            let busy = m.simulate_internals(&u[..333], &rest).unwrap().final_state;
            assert!(busy.output.x_past.iter().all(|v| *v != 0.0));
            let want = m.simulate(&u[333..], &busy).unwrap();
            let got = simulate_augmented_chain(
                &chain,
                &[],
                &u[333..],
                0.0,
                TIME_SCALE,
                &busy.clone().into(),
            )
            .unwrap();
            assert_eq!(got, want, "{name} from a busy state");
            // zero-size effects of every stage change nothing
            let zero = fx(&[
                ("state_saturation", &[f64::NEG_INFINITY, f64::INFINITY]),
                ("friction", &[0.0, 0.0]),
                ("compliance", &[0.0, 0.4, 0.05]),
                ("hysteresis_memory", &[0.3, 0.0]),
                ("output_offset", &[0.0, 0.0]),
                ("sensor_saturation", &[f64::NEG_INFINITY, f64::INFINITY]),
                ("quantization", &[0.0]),
            ]);
            let got =
                simulate_augmented_chain(&chain, &zero, &u[333..], 0.0, TIME_SCALE, &busy.into())
                    .unwrap();
            assert_eq!(got, want, "{name} with zero-size effects");
        }
        let m = model(true);
        let s = m.simulate_internals(&u[..300], &m.rest_state()).unwrap();
        let want = m.simulate(&u[300..], &s.final_state).unwrap();
        let chain = AugmentedChain::from(m.clone());
        let got = simulate_augmented_chain(
            &chain,
            &[],
            &u[300..],
            0.0,
            TIME_SCALE,
            &s.final_state.clone().into(),
        )
        .unwrap();
        assert_eq!(got, want);
        assert_eq!(
            got,
            simulate_augmented(&m, &[], &u[300..], 0.0, TIME_SCALE, &s.final_state).unwrap()
        );
    }

    /// Load effects act before the output block, output effects after it: a sandwich with
    /// compliance is the cascade with compliance filtered by the output block (eq 29), and
    /// an output offset and a sensor's clip act on w itself.
    #[test]
    fn load_effects_precede_the_output_block_and_sensor_effects_follow_it() {
        let u = input(700);
        for (name, chain) in sandwiches() {
            let block = chain.output.clone().unwrap();
            let cascade = chain.cascade.clone();
            let load = fx(&[
                ("compliance", &[0.6, 0.5, 0.1]),
                ("hysteresis_memory", &[0.2, 0.3]),
            ]);
            let y_load =
                simulate_augmented(&cascade, &load, &u, 0.0, TIME_SCALE, &cascade.rest_state())
                    .unwrap();
            let want = block.simulate(&y_load, &block.rest_state()).unwrap();
            let got =
                simulate_augmented_chain(&chain, &load, &u, 0.0, TIME_SCALE, &chain.rest_state())
                    .unwrap();
            assert!(max_diff(&got, &want) < 1e-12, "{name}");
            let w = plain(&chain)
                .simulate(&u, &plain(&chain).rest_state())
                .unwrap();
            let sensor = fx(&[
                ("output_offset", &[0.1, 0.5]),
                ("sensor_saturation", &[-0.3, 0.4]),
            ]);
            let got =
                simulate_augmented_chain(&chain, &sensor, &u, 50.0, 100.0, &chain.rest_state())
                    .unwrap();
            for (t, (g, v)) in got.iter().zip(&w).enumerate() {
                let want = (v + 0.1 + 0.5 * (50.0 + t as f64) / 100.0).clamp(-0.3, 0.4);
                assert!((g - want).abs() < 1e-12, "{name} {t}");
            }
            assert!(got.contains(&0.4) && got.contains(&-0.3));
        }
    }

    /// x(t) clipped inside the recursion: on a first-order tank x(t+1) = 0.5 u(t) + 0.9 x(t)
    /// the clipped level is what the next step starts from (the physics written out
    /// independently of eq 16's code); a clip of the drive input (`saturation`) is not that.
    #[test]
    fn state_saturation_holds_the_recursions_memory() {
        let m = CascadeModel::new(
            LinearBlock::new(vec![0.5], vec![-0.9]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        let u: Vec<f64> = (0..300)
            .map(|k| if (k / 60) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let (lo, hi) = (-2.0, 3.0);
        let mut want = vec![0.0];
        let mut level: f64 = 0.0;
        for uk in &u[..u.len() - 1] {
            level = (0.5 * uk + 0.9 * level).clamp(lo, hi);
            want.push(level);
        }
        let got = sim(&m, &[("state_saturation", &[lo, hi])], &u, 0.0, TIME_SCALE);
        assert!(max_diff(&got, &want) < 1e-12);
        assert!(got.contains(&hi) && got.contains(&lo));
        let drive = sim(&m, &[("saturation", &[-0.2, 0.3])], &u, 0.0, TIME_SCALE);
        assert!(max_diff(&drive, &got) > 0.1);
        // a sensor's clip leaves the state alone: the unclipped output, clipped
        let free = m.simulate(&u, &m.rest_state()).unwrap();
        let sensor = sim(&m, &[("sensor_saturation", &[lo, hi])], &u, 0.0, TIME_SCALE);
        let clipped: Vec<f64> = free.iter().map(|v| v.clamp(lo, hi)).collect();
        assert_eq!(sensor, clipped);
        assert!(max_diff(&sensor, &got) > 0.1);
    }

    #[test]
    fn bad_chain_states_are_refused() {
        let u = input(20);
        let (_, chain) = sandwiches().remove(0);
        let cascade = AugmentedChain::from(model(true));
        let run = |c: &AugmentedChain, s: &AugmentedState| {
            simulate_augmented_chain(c, &[], &u, 0.0, TIME_SCALE, s)
        };
        // a cascade's state for the sandwich and the other way round
        assert!(matches!(
            run(&chain, &cascade.rest_state()),
            Err(Error::Data(_))
        ));
        assert!(matches!(
            run(&cascade, &chain.rest_state()),
            Err(Error::Data(_))
        ));
        // y_past[0] is the backlash memory
        let mut s = chain.rest_state();
        s.output.as_mut().unwrap().u_past[0] = 0.2;
        assert!(matches!(run(&chain, &s), Err(Error::Data(m)) if m.contains("y_past[0]")));
        s.cascade.y_prev = 0.2;
        assert!(run(&chain, &s).is_ok());
        // lengths and values of the pasts
        let mut s = chain.rest_state();
        s.output.as_mut().unwrap().x_past.push(0.0);
        assert!(matches!(run(&chain, &s), Err(Error::Data(m)) if m.contains("state.output")));
        let mut s = chain.rest_state();
        s.output.as_mut().unwrap().x_past[1] = f64::NAN;
        assert!(matches!(run(&chain, &s), Err(Error::Data(_))));
        let mut s = chain.rest_state();
        s.cascade.linear.u_past.pop();
        assert!(matches!(run(&chain, &s), Err(Error::Data(m)) if m.contains("state.linear")));
        // an output block with a feedthrough
        let mut fed = chain.clone();
        fed.output = Some(LinearBlock::with_feedthrough(1.0, vec![0.2], vec![0.3]).unwrap());
        let s = fed.rest_state();
        assert!(matches!(run(&fed, &s), Err(Error::Model(_))));
        for bad in [
            ("state_saturation", &[1.0, 1.0][..]),
            ("sensor_saturation", &[f64::NAN, 1.0][..]),
            ("state_saturation", &[1.0][..]),
        ] {
            assert!(
                matches!(from_parameters(bad.0, bad.1), Err(Error::Model(_))),
                "{bad:?}"
            );
        }
    }
}
