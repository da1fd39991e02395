//! One step of a model for state-space use (python-control's `NonlinearIOSystem`, the exported
//! C of `backlashid.export`): the model's state as one flat vector, and
//! `step(state, u(t)) -> (output(t), next state)`.
//!
//! The state vector, most recent values first within each block:
//!
//! - cascade: `[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)]` (na + nb + 1 values): the
//!   linear block's past inputs and outputs (`CascadeState::linear`), then the backlash
//!   memory y(t-1) (`CascadeState::y_prev`);
//! - sandwich: `[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)..y(t-nr), w(t-1)..w(t-ns)]`
//!   (na + nb + nr + ns values): the input block's past (`SandwichState::input`), then the
//!   output block's past inputs, the backlash outputs (their first, y(t-1), is the backlash
//!   memory), and its past outputs (`SandwichState::output`).
//!
//! Before the first sample (t = 1) the vector holds the model state's `u_past`, `x_past`, ...
//! in that order. A step computes what `simulate` computes for one sample, the same sums in
//! the same order (the linear recursion: a_0 u(t), then + a_i u(t-i) for i = 1..na, then
//! - b_j x(t-j) for j = 1..nb; the backlash: `GeneralBacklash::step`, Horner's rule in
//!   xi = x + shift and eq (1)'s case order), so stepping through a record reproduces
//!   `simulate` bit for bit.

use crate::error::{Error, Result};
use crate::model::backlash::GeneralBacklash;
use crate::model::cascade::{CascadeModel, CascadeState};
use crate::model::linear::{LinearBlock, LinearState};
use crate::model::sandwich::{SandwichModel, SandwichState};

/// Eq (16) for one sample from the block's past (newest first): the sums of the recursion
/// that `LinearBlock::simulate` runs, in its order.
#[inline]
fn linear_output(block: &LinearBlock, u_now: f64, u_past: &[f64], x_past: &[f64]) -> f64 {
    let mut acc = block.a0() * u_now;
    for (ai, ui) in block.a().iter().zip(u_past) {
        acc += ai * ui;
    }
    for (bj, xj) in block.b().iter().zip(x_past) {
        acc -= bj * xj;
    }
    acc
}

/// `v` becomes the newest value of `past`; the oldest drops out.
#[inline]
fn push_front(past: &mut [f64], v: f64) {
    if let Some(last) = past.len().checked_sub(1) {
        past.copy_within(0..last, 1);
        past[0] = v;
    }
}

/// The checks of a step's arguments: the state's length and finite values, a finite input.
fn check_step(state: &[f64], size: usize, u: f64) -> Result<()> {
    if state.len() != size {
        return Err(Error::Data(format!(
            "the state vector has {} values but the model needs {size} (its state_size): \
             build it with state_vector",
            state.len()
        )));
    }
    if let Some(i) = state.iter().position(|v| !v.is_finite()) {
        return Err(Error::Data(format!(
            "state[{i}] = {}: give finite state values",
            state[i]
        )));
    }
    if !u.is_finite() {
        return Err(Error::Data(format!("u = {u}: give a finite input")));
    }
    Ok(())
}

/// A step's output overflowed (an unstable block, or branches beyond the float range).
fn check_output(value: f64, what: &str) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::Model(format!(
            "the step diverged: {what} = {value}; check the model's stability and the \
             signals' scale"
        )))
    }
}

/// The backlash step of eq (1) with `simulate`'s arithmetic.
#[inline]
fn backlash_output(backlash: &GeneralBacklash, x: f64, y_prev: f64) -> f64 {
    backlash.step(x, y_prev)
}

impl CascadeModel {
    /// The length of the state vector: na + nb + 1.
    pub fn state_size(&self) -> usize {
        self.linear.na() + self.linear.nb() + 1
    }

    /// The state as the flat vector `[u_past.., x_past.., y_prev]` (module doc).
    pub fn state_vector(&self, state: &CascadeState) -> Result<Vec<f64>> {
        self.linear.check_state(&state.linear, "state.linear")?;
        let mut v = Vec::with_capacity(self.state_size());
        v.extend_from_slice(&state.linear.u_past);
        v.extend_from_slice(&state.linear.x_past);
        v.push(state.y_prev);
        check_step(&v, self.state_size(), 0.0)?;
        Ok(v)
    }

    /// The state of a flat vector (the inverse of `state_vector`).
    pub fn state_from_vector(&self, v: &[f64]) -> Result<CascadeState> {
        check_step(v, self.state_size(), 0.0)?;
        let (na, nb) = (self.linear.na(), self.linear.nb());
        Ok(CascadeState {
            linear: LinearState {
                u_past: v[..na].to_vec(),
                x_past: v[na..na + nb].to_vec(),
            },
            y_prev: v[na + nb],
        })
    }

    /// One sample: y(t) for the input u(t), the state advanced in place.
    pub fn step_in_place(&self, state: &mut [f64], u: f64) -> Result<f64> {
        check_step(state, self.state_size(), u)?;
        let (na, nb) = (self.linear.na(), self.linear.nb());
        let (u_past, rest) = state.split_at_mut(na);
        let (x_past, y_prev) = rest.split_at_mut(nb);
        let x = check_output(linear_output(&self.linear, u, u_past, x_past), "x(t)")?;
        let y = check_output(backlash_output(&self.backlash, x, y_prev[0]), "y(t)")?;
        push_front(u_past, u);
        push_front(x_past, x);
        y_prev[0] = y;
        Ok(y)
    }

    /// One sample: (y(t), the next state) for the state vector and the input u(t).
    pub fn step(&self, state: &[f64], u: f64) -> Result<(f64, Vec<f64>)> {
        let mut next = state.to_vec();
        let y = self.step_in_place(&mut next, u)?;
        Ok((y, next))
    }
}

impl SandwichModel {
    /// The length of the state vector: na + nb + nr + ns.
    pub fn state_size(&self) -> usize {
        let (i, o) = (&self.input_linear, &self.output_linear);
        i.na() + i.nb() + o.na() + o.nb()
    }

    /// The state as the flat vector `[u_past.., x_past.., y_past.., w_past..]` (module doc).
    pub fn state_vector(&self, state: &SandwichState) -> Result<Vec<f64>> {
        self.input_linear.check_state(&state.input, "state.input")?;
        self.output_linear
            .check_state(&state.output, "state.output")?;
        let mut v = Vec::with_capacity(self.state_size());
        for part in [
            &state.input.u_past,
            &state.input.x_past,
            &state.output.u_past,
            &state.output.x_past,
        ] {
            v.extend_from_slice(part);
        }
        Ok(v)
    }

    /// The state of a flat vector (the inverse of `state_vector`).
    pub fn state_from_vector(&self, v: &[f64]) -> Result<SandwichState> {
        check_step(v, self.state_size(), 0.0)?;
        let (i, o) = (&self.input_linear, &self.output_linear);
        let cuts = [i.na(), i.na() + i.nb(), i.na() + i.nb() + o.na()];
        Ok(SandwichState {
            input: LinearState {
                u_past: v[..cuts[0]].to_vec(),
                x_past: v[cuts[0]..cuts[1]].to_vec(),
            },
            output: LinearState {
                u_past: v[cuts[1]..cuts[2]].to_vec(),
                x_past: v[cuts[2]..].to_vec(),
            },
        })
    }

    /// One sample: w(t) for the input u(t), the state advanced in place.
    pub fn step_in_place(&self, state: &mut [f64], u: f64) -> Result<f64> {
        check_step(state, self.state_size(), u)?;
        let (i, o) = (&self.input_linear, &self.output_linear);
        let (u_past, rest) = state.split_at_mut(i.na());
        let (x_past, rest) = rest.split_at_mut(i.nb());
        let (y_past, w_past) = rest.split_at_mut(o.na());
        let x = check_output(linear_output(i, u, u_past, x_past), "x(t)")?;
        let y = check_output(backlash_output(&self.backlash, x, y_past[0]), "y(t)")?;
        let w = check_output(linear_output(o, y, y_past, w_past), "w(t)")?;
        push_front(u_past, u);
        push_front(x_past, x);
        push_front(y_past, y);
        push_front(w_past, w);
        Ok(w)
    }

    /// One sample: (w(t), the next state) for the state vector and the input u(t).
    pub fn step(&self, state: &[f64], u: f64) -> Result<(f64, Vec<f64>)> {
        let mut next = state.to_vec();
        let w = self.step_in_place(&mut next, u)?;
        Ok((w, next))
    }
}

#[cfg(test)]
mod tests {
    use crate::model::cascade::{CascadeModel, CascadeState};
    use crate::model::linear::{LinearBlock, LinearState};
    use crate::model::sandwich::{SandwichModel, SandwichState};
    use crate::test_params::{example1_model, example2_model, quintic_backlash};

    /// A white-ish and a smooth input.
    fn inputs(n: usize) -> [Vec<f64>; 2] {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let white = (0..n)
            .map(|_| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
            })
            .collect();
        let smooth = (0..n)
            .map(|k| 1.7 * (k as f64 * 0.031).sin() + 0.4 * (k as f64 * 0.17).cos())
            .collect();
        [white, smooth]
    }

    /// The outputs of stepping through `u` from `state`, and the final state vector.
    fn stepped(
        step: impl Fn(&mut [f64], f64) -> f64,
        mut state: Vec<f64>,
        u: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let y = u.iter().map(|&ut| step(&mut state, ut)).collect();
        (y, state)
    }

    fn cascades() -> Vec<CascadeModel> {
        let quintic = quintic_backlash();
        let with_a0 = LinearBlock::with_feedthrough(0.3, vec![0.7, 0.5, 0.1], vec![-0.2]).unwrap();
        let fir = LinearBlock::new(vec![0.5, 0.25], vec![]).unwrap();
        vec![
            example1_model(),
            CascadeModel::new(example1_model().linear, quintic),
            CascadeModel::new(with_a0, example1_model().backlash),
            CascadeModel::new(fir, example1_model().backlash),
        ]
    }

    #[test]
    fn stepping_a_cascade_is_its_simulation_bit_for_bit() {
        for m in cascades() {
            let (na, nb) = (m.linear.na(), m.linear.nb());
            let busy = CascadeState {
                linear: LinearState {
                    u_past: (0..na).map(|k| 0.3 - 0.2 * k as f64).collect(),
                    x_past: (0..nb).map(|k| -0.4 + 0.25 * k as f64).collect(),
                },
                y_prev: 0.35,
            };
            for state in [m.rest_state(), busy] {
                for u in inputs(700) {
                    let want = m.simulate_internals(&u, &state).unwrap();
                    let v = m.state_vector(&state).unwrap();
                    assert_eq!(v.len(), m.state_size());
                    let (y, last) = stepped(|s, ut| m.step_in_place(s, ut).unwrap(), v, &u);
                    for (a, b) in y.iter().zip(&want.y) {
                        assert_eq!(a.to_bits(), b.to_bits(), "{a} vs {b}");
                    }
                    assert_eq!(m.state_from_vector(&last).unwrap(), want.final_state);
                }
            }
        }
    }

    #[test]
    fn stepping_a_sandwich_is_its_simulation_bit_for_bit() {
        let e2 = example2_model();
        let with_r0 = SandwichModel::new(
            e2.input_linear.clone(),
            e2.backlash.clone(),
            LinearBlock::with_feedthrough(0.4, vec![0.15, 0.1], vec![-0.2, 0.35]).unwrap(),
        );
        for m in [e2, with_r0] {
            let (i, o) = (&m.input_linear, &m.output_linear);
            let busy = SandwichState {
                input: LinearState {
                    u_past: (0..i.na()).map(|k| 0.5 - 0.3 * k as f64).collect(),
                    x_past: (0..i.nb()).map(|k| 0.2 + 0.1 * k as f64).collect(),
                },
                output: LinearState {
                    u_past: (0..o.na()).map(|k| -0.3 + 0.2 * k as f64).collect(),
                    x_past: (0..o.nb()).map(|k| 0.1 - 0.15 * k as f64).collect(),
                },
            };
            for state in [m.rest_state(), busy] {
                for u in inputs(700) {
                    let want = m.simulate_internals(&u, &state).unwrap();
                    let v = m.state_vector(&state).unwrap();
                    let (w, last) = stepped(|s, ut| m.step_in_place(s, ut).unwrap(), v, &u);
                    for (a, b) in w.iter().zip(&want.w) {
                        assert_eq!(a.to_bits(), b.to_bits(), "{a} vs {b}");
                    }
                    assert_eq!(m.state_from_vector(&last).unwrap(), want.final_state);
                    assert_eq!(m.simulate(&u, &state).unwrap(), want.w);
                }
            }
        }
    }

    #[test]
    fn step_returns_the_output_and_the_next_state() {
        let m = example1_model();
        let rest = m.state_vector(&m.rest_state()).unwrap();
        let (y, next) = m.step(&rest, 2.0).unwrap();
        assert_eq!(rest, vec![0.0; 5]); // not touched
        assert_eq!(y, 0.0); // x(1) = 0: inside the dead band
        assert_eq!(next, vec![2.0, 0.0, 0.0, 0.0, 0.0]);
        let (y, next) = m.step(&next, 0.0).unwrap();
        assert_eq!(y, m.backlash.right().value(1.4));
        assert_eq!(next, vec![0.0, 2.0, 1.4, 0.0, y]);
    }

    #[test]
    fn bad_states_and_inputs_are_refused() {
        let m = example1_model();
        let s = m.state_vector(&m.rest_state()).unwrap();
        for (state, u) in [
            (vec![0.0; 4], 0.0),
            (vec![0.0, 0.0, f64::NAN, 0.0, 0.0], 0.0),
            (s.clone(), f64::INFINITY),
        ] {
            assert!(
                matches!(m.step(&state, u), Err(crate::Error::Data(_))),
                "{state:?} {u}"
            );
        }
        let sw = example2_model();
        assert!(
            matches!(sw.step(&s, 0.0), Err(crate::Error::Data(ref msg)) if msg.contains("needs 8"))
        );
        let unstable = CascadeModel::new(
            LinearBlock::new(vec![1.0], vec![-2.0]).unwrap(),
            m.backlash.clone(),
        );
        let mut v = unstable.state_vector(&unstable.rest_state()).unwrap();
        let failed = (0..2000)
            .map(|_| unstable.step_in_place(&mut v, 1.0))
            .find_map(|r| r.err());
        assert!(matches!(failed, Some(crate::Error::Model(_))));
    }
}
