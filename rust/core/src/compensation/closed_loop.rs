//! A discrete PID loop around a plant model (cascade or sandwich):
//!     e(t) = r(t-1) - y(t-1),
//!     u(t) = u_ff(t) + kp e(t) + ki sum_{s<=t} e(s) + kd (e(t) - e(t-1)),
//! the controller seeing the output one sample late (the computation delay of a digital
//! controller) and comparing it with the reference of that same sample, so that a
//! feedforward that makes y follow r leaves e = 0 (against r(t), e would be r(t) - r(t-1) on
//! every ramp, and the PI would push the plant off the reference). y(0) is the plant's output
//! before the record (the cascade's memory y(0), the sandwich's w(0), 0 without one), r(0)
//! is taken as y(0) (no error before the record) and e(0) - e(-1) as 0 (no derivative kick). With a
//! saturation [lo, hi] the input is clamped, and the integral does not grow while the input
//! is clamped in the direction of the error (conditional integration, against windup).

use crate::compensation::compensator::{Chain, ChainState};
use crate::compensation::linear_inverse::Filter;
use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::check_memory;
use crate::model::signal::{check_finite, check_signal};

/// The gains of the PID.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    pub kp: f64,
    pub ki: f64,
    pub kd: f64,
}

/// The closed loop's input and output.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoop {
    pub u: Vec<f64>,
    pub y: Vec<f64>,
}

/// The plant run one sample at a time.
struct Plant {
    input: Filter,
    backlash: crate::model::GeneralBacklash,
    y_prev: f64,
    output: Option<Filter>,
}

impl Plant {
    fn new(model: &Chain, state: &ChainState) -> Result<(Self, f64)> {
        match (model, state) {
            (Chain::Cascade(m), ChainState::Cascade(s)) => {
                m.linear.check_state(&s.linear, "state.linear")?;
                check_memory(s.y_prev)?;
                let plant = Plant {
                    input: Filter::forward(&m.linear, &s.linear),
                    backlash: m.backlash.clone(),
                    y_prev: s.y_prev,
                    output: None,
                };
                Ok((plant, s.y_prev))
            }
            (Chain::Sandwich(m), ChainState::Sandwich(s)) => {
                m.input_linear.check_state(&s.input, "state.input")?;
                m.output_linear.check_state(&s.output, "state.output")?;
                let plant = Plant {
                    input: Filter::forward(&m.input_linear, &s.input),
                    backlash: m.backlash.clone(),
                    y_prev: s.output.u_past.first().copied().unwrap_or(0.0),
                    output: Some(Filter::forward(&m.output_linear, &s.output)),
                };
                Ok((plant, s.output.x_past.first().copied().unwrap_or(0.0)))
            }
            _ => Err(Error::Data(
                "the state is not of the plant's kind (cascade or sandwich)".into(),
            )),
        }
    }

    fn next(&mut self, u: f64) -> f64 {
        let x = self.input.next(u);
        self.y_prev = self.backlash.step(x, self.y_prev);
        match &mut self.output {
            Some(h) => h.next(self.y_prev),
            None => self.y_prev,
        }
    }
}

/// The loop of the module doc over `reference`, with the feedforward `feedforward` (same
/// length), the gains `pid` and the input limits `saturation` (lo <= hi).
pub fn closed_loop(
    plant: &Chain,
    state: &ChainState,
    reference: &[f64],
    feedforward: &[f64],
    pid: Pid,
    saturation: Option<(f64, f64)>,
) -> Result<ClosedLoop> {
    check_signal("reference", reference)?;
    check_finite("feedforward", feedforward)?;
    if feedforward.len() != reference.len() {
        return Err(Error::Data(format!(
            "feedforward has {} samples but reference has {}: give one input per reference sample",
            feedforward.len(),
            reference.len()
        )));
    }
    for (name, v) in [("kp", pid.kp), ("ki", pid.ki), ("kd", pid.kd)] {
        if !v.is_finite() {
            return Err(Error::Data(format!("{name} = {v}: give a finite gain")));
        }
    }
    if let Some((lo, hi)) = saturation {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return Err(Error::Data(format!(
                "saturation = ({lo}, {hi}): give limits lo <= hi"
            )));
        }
    }
    let (mut model, mut y_last) = Plant::new(plant, state)?;
    let n = reference.len();
    let (mut u, mut y) = (guard::buffer(n, "u")?, guard::buffer(n, "y")?);
    let (mut integral, mut e_prev, mut r_last) = (0.0, None::<f64>, y_last);
    for (i, (chunk_r, chunk_ff)) in reference
        .chunks(guard::CHUNK)
        .zip(feedforward.chunks(guard::CHUNK))
        .enumerate()
    {
        guard::check()?;
        for (k, (&r, &ff)) in chunk_r.iter().zip(chunk_ff).enumerate() {
            let e = r_last - y_last;
            r_last = r;
            let derivative = e - e_prev.unwrap_or(e);
            let trial = integral + e;
            let mut ut = ff + pid.kp * e + pid.ki * trial + pid.kd * derivative;
            let mut clamped = false;
            if let Some((lo, hi)) = saturation {
                if ut > hi {
                    clamped = e > 0.0;
                    ut = hi;
                } else if ut < lo {
                    clamped = e < 0.0;
                    ut = lo;
                }
            }
            if !clamped {
                integral = trial;
            }
            e_prev = Some(e);
            y_last = model.next(ut);
            if !(ut.is_finite() && y_last.is_finite()) {
                let t = i * guard::CHUNK + k;
                return Err(Error::Model(format!(
                    "the closed loop diverged at sample {t}: lower the gains (the loop is \
                     unstable) or add a saturation"
                )));
            }
            u.push(ut);
            y.push(y_last);
        }
    }
    Ok(ClosedLoop { u, y })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensation::compensate;
    use crate::test_params::{example1_model, example2_model};

    fn rmse(a: &[f64], b: &[f64]) -> f64 {
        (a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum::<f64>() / a.len() as f64).sqrt()
    }

    #[test]
    fn without_feedback_the_loop_is_the_plant() {
        for plant in [
            Chain::Cascade(example1_model()),
            Chain::Sandwich(example2_model()),
        ] {
            let u: Vec<f64> = (0..300).map(|k| ((k as f64) * 0.05).sin() * 1.5).collect();
            let zero = Pid {
                kp: 0.0,
                ki: 0.0,
                kd: 0.0,
            };
            let state = plant.rest_state();
            let out = closed_loop(&plant, &state, &u, &u, zero, None).unwrap();
            let y = match &plant {
                Chain::Cascade(m) => m.simulate(&u, &m.rest_state()).unwrap(),
                Chain::Sandwich(m) => m.simulate(&u, &m.rest_state()).unwrap(),
            };
            for (p, q) in out.y.iter().zip(&y) {
                assert!((p - q).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn the_compensator_helps_a_pi_loop() {
        let plant = Chain::Cascade(example1_model());
        let state = plant.rest_state();
        let r: Vec<f64> = (0..1500)
            .map(|k| 0.8 * ((k as f64) * 0.02).sin() + 0.2 * ((k as f64) * 0.045).sin())
            .collect();
        let pi = Pid {
            kp: 0.3,
            ki: 0.1,
            kd: 0.0,
        };
        let zero = vec![0.0; r.len()];
        let fb = closed_loop(&plant, &state, &r, &zero, pi, None).unwrap();
        let ff = compensate(&plant, &r, &state, 0.0).unwrap();
        let both = closed_loop(&plant, &state, &r, &ff, pi, None).unwrap();
        assert!(rmse(&both.y, &r) < 0.5 * rmse(&fb.y, &r));
        let sat = closed_loop(&plant, &state, &r, &zero, pi, Some((-0.5, 0.5))).unwrap();
        assert!(sat.u.iter().all(|v| v.abs() <= 0.5));
        assert!(closed_loop(&plant, &state, &r, &zero[1..], pi, None).is_err());
        assert!(closed_loop(&plant, &state, &r, &zero, pi, Some((1.0, -1.0))).is_err());
    }
}
