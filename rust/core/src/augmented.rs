//! The nominal cascade (eq 16 -> eq 1) with the effects of the diagnosis catalogue, simulated
//! sample by sample. Every effect is an optional term that gives exactly the nominal model at
//! zero size, so a refit of the effect's parameters starts from the nominal fit:
//!
//! - dead time: the linear block sees u(t - d) (d extra samples; before the record: rest);
//! - saturation: u clipped to [lo, hi] before the linear block;
//! - friction: u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1), sign(0) = 0
//!   (x(t) depends on u_eff up to t-1 only, so this is causal);
//! - width drift: c_L(t) = c_L + dc_L tau, c_R(t) = c_R + dc_R tau, tau = (t0 + t) / time_scale;
//! - compliance: y = (1 - k) f + k H(q) f, H a unit-DC-gain 2nd-order resonance with natural
//!   frequency omega (rad/sample) and damping zeta (k = 1: the pure resonance);
//! - extra plays on x: y += sum_k w_k play_{r_k}(x);
//! - output offset and drift: y += o_0 + o_1 tau;
//! - quantiser: y := q round(y / q) (q = 0: none).
//!
//! Time t is 0-based within the record; `t0` places the record in a longer continuous one
//! (the validation record follows the estimation record).

use crate::error::{Error, Result};
use crate::model::backlash::{check_memory, GeneralBacklash};
use crate::model::cascade::{CascadeModel, CascadeState};
use crate::model::signal::check_signal;

/// The effects' parameters; `Effects::default()` is the nominal model.
#[derive(Debug, Clone, PartialEq)]
pub struct Effects {
    /// Extra input delay d in samples.
    pub delay: usize,
    /// Saturation bounds (lo, hi) of the drive input; (-inf, +inf) is none.
    pub saturation: (f64, f64),
    /// Coulomb and viscous friction (F_c, F_v).
    pub friction: (f64, f64),
    /// Drift rates (dc_L, dc_R) of the dead-band widths per time unit.
    pub width_drift: (f64, f64),
    /// Compliance (k, omega, zeta): share of the resonant path, natural frequency in rad per
    /// sample, damping ratio. k = 0 is none.
    pub compliance: (f64, f64, f64),
    /// Extra plays (r_k, w_k) on x.
    pub plays: Vec<(f64, f64)>,
    /// Output offset o_0 and its drift rate o_1 per time unit.
    pub offset: (f64, f64),
    /// Quantiser step q (0: none).
    pub quantum: f64,
    /// Samples per time unit of the drifts (> 0).
    pub time_scale: f64,
}

impl Default for Effects {
    fn default() -> Self {
        Effects {
            delay: 0,
            saturation: (f64::NEG_INFINITY, f64::INFINITY),
            friction: (0.0, 0.0),
            width_drift: (0.0, 0.0),
            compliance: (0.0, 0.5, 0.1),
            plays: Vec::new(),
            offset: (0.0, 0.0),
            quantum: 0.0,
            time_scale: 1000.0,
        }
    }
}

fn finite(name: &str, v: f64, what: &str) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::Model(format!("{name} = {v}: {what}")))
    }
}

impl Effects {
    /// Every parameter in its domain; the message says which one to fix.
    pub fn check(&self) -> Result<()> {
        let (lo, hi) = self.saturation;
        if lo.is_nan() || hi.is_nan() || lo >= hi {
            return Err(Error::Model(format!(
                "saturation bounds lo = {lo}, hi = {hi}: give lo < hi (+-inf for no bound)"
            )));
        }
        finite("F_c", self.friction.0, "give a finite Coulomb friction")?;
        finite("F_v", self.friction.1, "give a finite viscous friction")?;
        finite("dc_L", self.width_drift.0, "give a finite drift rate")?;
        finite("dc_R", self.width_drift.1, "give a finite drift rate")?;
        let (k, omega, zeta) = self.compliance;
        finite("compliance share k", k, "give a finite share (0 for none)")?;
        if k != 0.0 && !(omega > 0.0 && omega < std::f64::consts::PI && zeta > 0.0 && zeta < 1.0) {
            return Err(Error::Model(format!(
                "compliance omega = {omega}, zeta = {zeta}: give 0 < omega < pi (rad/sample) \
                 and 0 < zeta < 1 (a lightly damped mode)"
            )));
        }
        for &(r, w) in &self.plays {
            if !(r.is_finite() && r >= 0.0 && w.is_finite()) {
                return Err(Error::Model(format!(
                    "play (r = {r}, w = {w}): give a finite half-width r >= 0 and a finite weight"
                )));
            }
        }
        finite("o_0", self.offset.0, "give a finite offset")?;
        finite("o_1", self.offset.1, "give a finite offset drift")?;
        if !(self.quantum.is_finite() && self.quantum >= 0.0) {
            return Err(Error::Model(format!(
                "quantiser step q = {}: give q >= 0 (0 for no quantiser)",
                self.quantum
            )));
        }
        if !(self.time_scale.is_finite() && self.time_scale > 0.0) {
            return Err(Error::Data(format!(
                "time_scale = {}: give a positive number of samples per time unit",
                self.time_scale
            )));
        }
        Ok(())
    }
}

/// Horner's rule for sum_{i>=1} m_i xi^i (eq 4-5).
#[inline(always)]
fn branch(m: &[f64], xi: f64) -> f64 {
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

#[inline(always)]
fn sign(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The augmented cascade's output for the input `u`, from `state` (the linear block's past of
/// the effective input and of x, and the backlash memory). `t0` is the time of u[0] in the
/// continuous record (drifts only).
pub fn simulate_augmented(
    model: &CascadeModel,
    effects: &Effects,
    u: &[f64],
    t0: f64,
    state: &CascadeState,
) -> Result<Vec<f64>> {
    check_signal("u", u)?;
    model.linear.check_state(&state.linear, "state.linear")?;
    check_memory(state.y_prev)?;
    effects.check()?;
    if !t0.is_finite() {
        return Err(Error::Data(format!(
            "t0 = {t0}: give the record's start time in samples"
        )));
    }
    let lin = &model.linear;
    let bl: &GeneralBacklash = &model.backlash;
    let (m_l, m_r) = (bl.left().coefficients(), bl.right().coefficients());
    let (c_l, c_r) = (bl.c_left(), bl.c_right());
    let e = effects;
    let (lo, hi) = e.saturation;
    let (f_c, f_v) = e.friction;
    let (dc_l, dc_r) = e.width_drift;
    let drifting = dc_l != 0.0 || dc_r != 0.0;
    let friction = f_c != 0.0 || f_v != 0.0;
    let (k, omega, zeta) = e.compliance;
    // H(q) = g / (1 + d1 q^-1 + d2 q^-2), poles exp(omega (-zeta +- j sqrt(1 - zeta^2))).
    let (d1, d2) = if k != 0.0 {
        let rho = (-zeta * omega).exp();
        (
            -2.0 * rho * (omega * (1.0 - zeta * zeta).sqrt()).cos(),
            rho * rho,
        )
    } else {
        (0.0, 0.0)
    };
    let g = 1.0 + d1 + d2;
    let (mut h1, mut h2) = (state.y_prev, state.y_prev); // the resonance at rest on y(0)
    let x0 = state.linear.x_past.first().copied().unwrap_or(0.0);
    let mut plays = vec![x0; e.plays.len()]; // each play at rest on x(0)
    let n = u.len();
    let mut u_eff = vec![0.0; n];
    let mut x = vec![0.0; n];
    let mut y = vec![0.0; n];
    let mut y_prev = state.y_prev;
    let mut x_prev = x0;
    for t in 0..n {
        let xt = lin.output_at(&u_eff, &x, t, &state.linear);
        x[t] = xt;
        // the drive input of the linear block at t
        let mut v = if t >= e.delay { u[t - e.delay] } else { 0.0 };
        v = if v < lo {
            lo
        } else if v > hi {
            hi
        } else {
            v
        };
        if friction {
            let vel = xt - x_prev;
            v -= f_c * sign(vel) + f_v * vel;
        }
        u_eff[t] = v;
        x_prev = xt;
        let tau = (t0 + t as f64) / e.time_scale;
        let f = if drifting {
            let (cl, cr) = (c_l + dc_l * tau, c_r + dc_r * tau);
            select(branch(m_l, xt + cl), branch(m_r, xt - cr), y_prev)
        } else {
            bl.step(xt, y_prev)
        };
        y_prev = f;
        let mut out = f;
        if k != 0.0 {
            let h = g * f - d1 * h1 - d2 * h2;
            h2 = h1;
            h1 = h;
            out = (1.0 - k) * f + k * h;
        }
        for (p, &(r, w)) in plays.iter_mut().zip(&e.plays) {
            *p = (xt - r).max((xt + r).min(*p));
            out += w * *p;
        }
        out += e.offset.0 + e.offset.1 * tau;
        if e.quantum > 0.0 {
            out = e.quantum * (out / e.quantum).round();
        }
        if !(out.is_finite() && xt.is_finite()) {
            return Err(Error::Model(format!(
                "the augmented model diverged at sample {t} (x = {xt}, y = {out}): the linear \
                 block or the friction feedback is unstable; reduce F_v or check the poles"
            )));
        }
        y[t] = out;
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;
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

    #[test]
    fn zero_size_effects_are_the_nominal_model() {
        let u = input(700);
        for m in [model(true), model(false)] {
            let nominal = m.simulate(&u, &m.rest_state()).unwrap();
            let zero = Effects {
                plays: vec![(0.3, 0.0), (0.1, 0.0)],
                compliance: (0.0, 0.4, 0.05),
                ..Effects::default()
            };
            let aug = simulate_augmented(&m, &zero, &u, 123.0, &m.rest_state()).unwrap();
            assert!(max_diff(&aug, &nominal) < 1e-12);
            // from a non-rest state too
            let sim = m.simulate_internals(&u[..300], &m.rest_state()).unwrap();
            let nominal = m.simulate(&u[300..], &sim.final_state).unwrap();
            let aug = simulate_augmented(&m, &zero, &u[300..], 0.0, &sim.final_state).unwrap();
            assert!(max_diff(&aug, &nominal) < 1e-12);
        }
    }

    #[test]
    fn dead_time_shifts_the_input() {
        let m = model(true);
        let u = input(400);
        let mut shifted = vec![0.0; 3];
        shifted.extend_from_slice(&u[..397]);
        let want = m.simulate(&shifted, &m.rest_state()).unwrap();
        let e = Effects {
            delay: 3,
            ..Effects::default()
        };
        let got = simulate_augmented(&m, &e, &u, 0.0, &m.rest_state()).unwrap();
        assert!(max_diff(&got, &want) < 1e-12);
    }

    #[test]
    fn saturation_clips_the_input() {
        let m = model(true);
        let u = input(400);
        let clipped: Vec<f64> = u.iter().map(|v| v.clamp(-0.8, 0.9)).collect();
        let want = m.simulate(&clipped, &m.rest_state()).unwrap();
        let e = Effects {
            saturation: (-0.8, 0.9),
            ..Effects::default()
        };
        let got = simulate_augmented(&m, &e, &u, 0.0, &m.rest_state()).unwrap();
        assert!(max_diff(&got, &want) < 1e-12);
    }

    #[test]
    fn friction_by_hand_on_a_first_order_block() {
        // x(t) = 0.5 u_eff(t-1); u = 1 throughout, F_c = 0.1, F_v = 0.2, straight backlash.
        let m = CascadeModel::new(
            LinearBlock::new(vec![0.5], vec![]).unwrap(),
            GeneralBacklash::new(0.0, 0.0, vec![1.0], vec![1.0]).unwrap(),
        );
        let e = Effects {
            friction: (0.1, 0.2),
            ..Effects::default()
        };
        let y = simulate_augmented(&m, &e, &[1.0; 3], 0.0, &m.rest_state()).unwrap();
        // t=0: x=0, v=0 -> u_eff = 1; t=1: x=0.5, v=0.5 -> u_eff = 1 - 0.1 - 0.1 = 0.8;
        // t=2: x=0.4, v=-0.1 -> identity backlash y = x.
        assert!(max_diff(&y, &[0.0, 0.5, 0.4]) < 1e-15);
    }

    #[test]
    fn width_drift_equals_the_backlash_with_the_widths_of_that_time() {
        let m = model(false);
        let e = Effects {
            width_drift: (0.2, 0.05),
            time_scale: 100.0,
            ..Effects::default()
        };
        let u = input(50);
        let y = simulate_augmented(&m, &e, &u, 1000.0, &m.rest_state()).unwrap();
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
        let e = Effects {
            compliance: (1.0, 0.3, 0.05),
            ..Effects::default()
        };
        let y = simulate_augmented(&m, &e, &[1.0; 2000], 0.0, &m.rest_state()).unwrap();
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
        let e = Effects {
            plays: vec![(0.25, 2.0)],
            ..Effects::default()
        };
        let y = simulate_augmented(&m, &e, &u, 0.0, &m.rest_state()).unwrap();
        assert!(max_diff(&y, &[0.0, 2.5, 2.0, -2.5]) < 1e-15);
        let e = Effects {
            offset: (0.1, 1.0),
            time_scale: 10.0,
            ..Effects::default()
        };
        let y = simulate_augmented(&m, &e, &u, 10.0, &m.rest_state()).unwrap();
        assert!(max_diff(&y, &[1.1, 2.2, 1.8, 0.4]) < 1e-12);
        let e = Effects {
            quantum: 0.4,
            ..Effects::default()
        };
        let y = simulate_augmented(&m, &e, &u, 0.0, &m.rest_state()).unwrap();
        assert!(max_diff(&y, &[0.0, 1.2, 0.4, -1.2]) < 1e-12);
    }

    #[test]
    fn bad_effects_are_errors_not_panics() {
        let m = model(true);
        let u = input(10);
        for e in [
            Effects {
                saturation: (1.0, -1.0),
                ..Effects::default()
            },
            Effects {
                quantum: -1.0,
                ..Effects::default()
            },
            Effects {
                compliance: (1.0, 4.0, 0.1),
                ..Effects::default()
            },
            Effects {
                plays: vec![(-0.1, 1.0)],
                ..Effects::default()
            },
            Effects {
                time_scale: 0.0,
                ..Effects::default()
            },
        ] {
            assert!(simulate_augmented(&m, &e, &u, 0.0, &m.rest_state()).is_err());
        }
        assert!(matches!(
            simulate_augmented(&m, &Effects::default(), &[f64::NAN], 0.0, &m.rest_state()),
            Err(Error::Data(_))
        ));
        let wild = Effects {
            friction: (0.0, -50.0),
            ..Effects::default()
        };
        assert!(matches!(
            simulate_augmented(&m, &wild, &input(2000), 0.0, &m.rest_state()),
            Err(Error::Model(_))
        ));
    }
}
