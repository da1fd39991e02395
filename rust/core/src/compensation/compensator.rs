//! The feedforward compensator of a cascade (u -> G -> x -> B -> y) or a sandwich
//! (u -> G -> x -> B -> y -> H -> w): the input u(t) that makes the model's output follow
//! the reference, through the inverse of each block in turn.
//!
//! With d_G, d_H the blocks' relative degrees (`LinearInverse`), the preview delay is
//! D = d_G (+ d_H): u(t) first acts on the output at t + D. `step` takes r(t + D) and
//! returns u(t): for the sandwich y_d(t + d_G) = H^-1(r) (the inverse filter of H), then
//! x_d(t + d_G) = B^-1(y_d) (`BacklashInverse`), u(t) = G^-1(x_d); for the cascade
//! x_d = B^-1(r), u = G^-1(x_d). The start: the model is run D samples from its state (the
//! inputs u(1..) do not reach x(1..d_G), y(1..d_G) or w(1..D)), and the inverses' pasts
//! and the backlash memory are those of the plant, so that with the same model the output
//! equals the reference from sample D + 1 on.

use crate::compensation::linear_inverse::{Filter, LinearInverse};
use crate::error::{Error, Result};
use crate::guard;
use crate::model::{
    BacklashInverse, CascadeModel, CascadeState, GeneralBacklash, LinearState, SandwichModel,
    SandwichState,
};

/// A model to compensate (or to run as the plant of a closed loop).
#[derive(Debug, Clone, PartialEq)]
pub enum Chain {
    Cascade(CascadeModel),
    Sandwich(SandwichModel),
}

/// A `Chain`'s state.
#[derive(Debug, Clone, PartialEq)]
pub enum ChainState {
    Cascade(CascadeState),
    Sandwich(SandwichState),
}

impl Chain {
    pub fn backlash(&self) -> &GeneralBacklash {
        match self {
            Chain::Cascade(m) => &m.backlash,
            Chain::Sandwich(m) => &m.backlash,
        }
    }

    pub fn rest_state(&self) -> ChainState {
        match self {
            Chain::Cascade(m) => ChainState::Cascade(m.rest_state()),
            Chain::Sandwich(m) => ChainState::Sandwich(m.rest_state()),
        }
    }
}

/// The compensator's memory: the inverse filters' pasts and the backlash inverse.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensatorState {
    /// G^-1's pasts: [x_d(t+d_G-1), ..] and [u(t-1), ..].
    pub input: (Vec<f64>, Vec<f64>),
    /// H^-1's pasts (empty for a cascade): [w_d(t+D-1), ..] and [y_d(t+d_G-1), ..].
    pub output: (Vec<f64>, Vec<f64>),
    pub backlash: BacklashInverse,
    /// References stepped so far.
    pub samples: u64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Compensator {
    backlash: GeneralBacklash,
    input: LinearInverse,
    output: Option<LinearInverse>,
    inverse: BacklashInverse,
    delay: usize,
    samples: u64,
    /// Added to `samples` in messages: `compensate` steps reference[t + D] at step t.
    pub(crate) index_offset: u64,
}

/// The newest `n` values of a record `recent` (oldest first) followed by `before` (newest
/// first): [recent[last], .., recent[0], before[0], ..].
fn newest_first(recent: &[f64], before: &[f64], n: usize) -> Vec<f64> {
    recent.iter().rev().chain(before).copied().take(n).collect()
}

/// The first `k` samples of x and y (and the first `d` of w) of the model run from `state`
/// with zero input: the part of the record the state alone determines.
fn preview(model: &Chain, state: &ChainState, d: usize) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    if d == 0 {
        return Ok((Vec::new(), Vec::new(), Vec::new()));
    }
    let zeros = vec![0.0; d];
    match (model, state) {
        (Chain::Cascade(m), ChainState::Cascade(s)) => {
            let sim = m.simulate_internals(&zeros, s)?;
            Ok((sim.x, sim.y, Vec::new()))
        }
        (Chain::Sandwich(m), ChainState::Sandwich(s)) => {
            let sim = m.simulate_internals(&zeros, s)?;
            Ok((sim.x, sim.y, sim.w))
        }
        _ => Err(mismatch()),
    }
}

fn mismatch() -> Error {
    Error::Data("the state is not of the model's kind (cascade or sandwich)".into())
}

impl Compensator {
    /// The compensator of `model` started from the model's `state`, with the backlash
    /// inverse's smoothing `threshold` (0: exact).
    pub fn new(model: &Chain, state: &ChainState, threshold: f64) -> Result<Self> {
        let (g, g_state): (_, &LinearState) = match (model, state) {
            (Chain::Cascade(m), ChainState::Cascade(s)) => (&m.linear, &s.linear),
            (Chain::Sandwich(m), ChainState::Sandwich(s)) => (&m.input_linear, &s.input),
            _ => return Err(mismatch()),
        };
        // the delays first (rest pasts), then the pasts from the model's run
        let d_g = LinearInverse::new(g, &g_state.x_past, &g_state.u_past, "input")?.delay;
        let d_h = match model {
            Chain::Sandwich(m) => {
                let h = &m.output_linear;
                let rest = h.rest_state();
                LinearInverse::new(h, &rest.x_past, &rest.u_past, "output")?.delay
            }
            Chain::Cascade(_) => 0,
        };
        let delay = d_g + d_h;
        let (x, y, w) = preview(model, state, delay)?;
        let (x, y) = (&x[..d_g.min(x.len())], &y[..d_g.min(y.len())]);
        let input = LinearInverse::new(
            g,
            &newest_first(x, &g_state.x_past, g.nb()),
            &g_state.u_past,
            "input",
        )?;
        let (output, y0) = match (model, state) {
            (Chain::Sandwich(m), ChainState::Sandwich(s)) => {
                let h = &m.output_linear;
                let y_past = newest_first(y, &s.output.u_past, h.na() + 1);
                let inv = LinearInverse::new(
                    h,
                    &newest_first(&w, &s.output.x_past, h.nb()),
                    &y_past,
                    "output",
                )?;
                (Some(inv), y_past[0])
            }
            (Chain::Cascade(_), ChainState::Cascade(s)) => {
                (None, y.last().copied().unwrap_or(s.y_prev))
            }
            _ => return Err(mismatch()),
        };
        let x0 = x.last().or(g_state.x_past.first()).copied().unwrap_or(0.0);
        Ok(Compensator {
            backlash: model.backlash().clone(),
            input,
            output,
            inverse: BacklashInverse::new(y0, x0, threshold)?,
            delay,
            samples: 0,
            index_offset: 0,
        })
    }

    /// D: `step` takes the reference D samples ahead of the input it returns.
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// Whether a linear block's inverse is the stable approximation (non-minimum phase).
    pub fn approximate(&self) -> bool {
        self.input.approximate || self.output.as_ref().is_some_and(|h| h.approximate)
    }

    /// u(t) for the reference r(t + D).
    pub fn step(&mut self, reference: f64) -> Result<f64> {
        let t = self.samples + self.index_offset;
        if !reference.is_finite() {
            return Err(Error::Data(format!(
                "reference[{t}] is {reference}: give a finite reference"
            )));
        }
        let y_d = match &mut self.output {
            Some(h) => h.filter.next(reference),
            None => reference,
        };
        let x_d = self
            .inverse
            .step(&self.backlash, y_d)
            .map_err(|e| match e {
                Error::Data(msg) => Error::Data(format!(
                    "reference[{t}] is not reachable: the backlash inverse says {msg}"
                )),
                other => other,
            })?;
        let u = self.input.filter.next(x_d);
        if !u.is_finite() {
            return Err(Error::Model(format!(
                "the compensator's input u diverged at reference[{t}]: the model's inverse \
                 overflows there; use a smaller or smoother reference"
            )));
        }
        self.samples += 1;
        Ok(u)
    }

    /// u for a block of references, continuing the state.
    pub fn run(&mut self, reference: &[f64]) -> Result<Vec<f64>> {
        let mut u = guard::buffer(reference.len(), "u")?;
        for chunk in reference.chunks(guard::CHUNK) {
            guard::check()?;
            for &r in chunk {
                u.push(self.step(r)?);
            }
        }
        Ok(u)
    }

    /// The memory, to save and restore (`set_state`).
    pub fn state(&self) -> CompensatorState {
        let f = &self.input.filter;
        let output = match &self.output {
            Some(h) => (h.filter.in_past.clone(), h.filter.out_past.clone()),
            None => (Vec::new(), Vec::new()),
        };
        CompensatorState {
            input: (f.in_past.clone(), f.out_past.clone()),
            output,
            backlash: self.inverse.clone(),
            samples: self.samples,
        }
    }

    /// Continue from a memory `state` of a compensator of the same model.
    pub fn set_state(&mut self, state: CompensatorState) -> Result<()> {
        fn fits(filter: &Filter, past: &(Vec<f64>, Vec<f64>)) -> bool {
            filter.in_past.len() == past.0.len() && filter.out_past.len() == past.1.len()
        }
        let out_ok = match &self.output {
            Some(h) => fits(&h.filter, &state.output),
            None => state.output.0.is_empty() && state.output.1.is_empty(),
        };
        let finite = state
            .input
            .0
            .iter()
            .chain(&state.input.1)
            .chain(&state.output.0)
            .chain(&state.output.1)
            .chain([
                &state.backlash.y_prev,
                &state.backlash.x_prev,
                &state.backlash.extremum,
            ])
            .all(|v| v.is_finite());
        if !(fits(&self.input.filter, &state.input) && out_ok && finite) {
            return Err(Error::Data(
                "the compensator state does not fit this model (orders) or is not finite".into(),
            ));
        }
        self.input.filter.in_past = state.input.0;
        self.input.filter.out_past = state.input.1;
        if let Some(h) = &mut self.output {
            h.filter.in_past = state.output.0;
            h.filter.out_past = state.output.1;
        }
        let threshold = self.inverse.threshold;
        self.inverse = state.backlash;
        self.inverse.threshold = threshold;
        self.samples = state.samples;
        Ok(())
    }
}

/// The input u of the reference's length with u[t] targeting reference[t + D] (the last D
/// target the last reference value): `model.simulate(u, state)` equals the reference from
/// sample D on (to rounding, for an exact inverse).
pub fn compensate(
    model: &Chain,
    reference: &[f64],
    state: &ChainState,
    threshold: f64,
) -> Result<Vec<f64>> {
    crate::model::signal::check_signal("reference", reference)?;
    let mut comp = Compensator::new(model, state, threshold)?;
    let d = comp.delay().min(reference.len());
    comp.index_offset = d as u64;
    let last = reference[reference.len() - 1];
    let mut u = comp.run(&reference[d..])?;
    for _ in 0..d {
        u.push(comp.step(last)?);
    }
    Ok(u)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{GeneralBacklash, LinearBlock};
    use crate::test_params::{example1_model, example2_model};

    fn reference(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64;
                0.8 * (0.013 * t).sin() + 0.3 * (0.041 * t + 1.0).sin() + 0.1 * (0.029 * t).cos()
            })
            .collect()
    }

    fn check_tracking(model: &Chain, state: &ChainState, r: &[f64]) {
        let u = compensate(model, r, state, 0.0).unwrap();
        let y = match (model, state) {
            (Chain::Cascade(m), ChainState::Cascade(s)) => m.simulate(&u, s).unwrap(),
            (Chain::Sandwich(m), ChainState::Sandwich(s)) => m.simulate(&u, s).unwrap(),
            _ => unreachable!(),
        };
        let d = Compensator::new(model, state, 0.0).unwrap().delay();
        for t in d..r.len() {
            assert!(
                (y[t] - r[t]).abs() < 1e-9 * (1.0 + r[t].abs()),
                "{t}: {} {}",
                y[t],
                r[t]
            );
        }
    }

    #[test]
    fn the_compensated_model_follows_the_reference_from_sample_d_on() {
        let r = reference(1500);
        let c = Chain::Cascade(example1_model());
        check_tracking(&c, &c.rest_state(), &r);
        let s = Chain::Sandwich(example2_model());
        check_tracking(&s, &s.rest_state(), &r);
        // from states off rest
        let m = example1_model();
        let st = CascadeState {
            linear: LinearState {
                u_past: vec![0.3, -0.2],
                x_past: vec![0.5, 0.1],
            },
            y_prev: 0.4,
        };
        check_tracking(&Chain::Cascade(m), &ChainState::Cascade(st), &r);
        let m = example2_model();
        let st = SandwichState {
            input: LinearState {
                u_past: vec![0.3, -0.2],
                x_past: vec![0.5, 0.1],
            },
            output: LinearState {
                u_past: vec![0.2, 0.1],
                x_past: vec![0.3, 0.25],
            },
        };
        check_tracking(&Chain::Sandwich(m), &ChainState::Sandwich(st), &r);
        // feedthrough (d = 0) and a longer delay (d = 2)
        let bl = example1_model().backlash;
        for g in [
            LinearBlock::with_feedthrough(0.5, vec![0.3], vec![-0.4]).unwrap(),
            LinearBlock::new(vec![0.0, 0.6, 0.2], vec![-0.3]).unwrap(),
        ] {
            let c = Chain::Cascade(CascadeModel::new(g, bl.clone()));
            check_tracking(&c, &c.rest_state(), &r);
        }
    }

    #[test]
    fn steps_in_blocks_and_a_restored_state_continue_the_run() {
        let c = Chain::Sandwich(example2_model());
        let r = reference(300);
        let mut whole = Compensator::new(&c, &c.rest_state(), 0.0).unwrap();
        assert_eq!(whole.delay(), 2);
        assert!(!whole.approximate());
        let all = whole.run(&r).unwrap();
        let mut first = Compensator::new(&c, &c.rest_state(), 0.0).unwrap();
        let a = first.run(&r[..100]).unwrap();
        let mut second = Compensator::new(&c, &c.rest_state(), 0.0).unwrap();
        second.set_state(first.state()).unwrap();
        let b = second.run(&r[100..]).unwrap();
        assert_eq!(&all[..100], &a[..]);
        assert_eq!(&all[100..], &b[..]);
        let cascade = Chain::Cascade(example1_model());
        let other = Compensator::new(&cascade, &cascade.rest_state(), 0.0).unwrap();
        assert!(second.set_state(other.state()).is_err());
    }

    #[test]
    fn bad_references_and_mismatched_states_are_errors() {
        let c = Chain::Cascade(example1_model());
        let err = compensate(&c, &[0.1, f64::NAN, 0.2], &c.rest_state(), 0.0).unwrap_err();
        assert!(
            matches!(err, Error::Data(ref m) if m.contains("reference[1]")),
            "{err:?}"
        );
        assert!(compensate(&c, &[], &c.rest_state(), 0.0).is_err());
        let s = Chain::Sandwich(example2_model());
        assert!(compensate(&c, &[0.1], &s.rest_state(), 0.0).is_err());
        let err = compensate(&c, &[0.1, 1e300], &c.rest_state(), 0.0).unwrap_err();
        assert!(
            matches!(err, Error::Data(ref m) if m.contains("not reachable")),
            "{err:?}"
        );
        let _ = GeneralBacklash::new(0.1, 0.1, vec![1.0], vec![1.0]).unwrap();
    }
}
