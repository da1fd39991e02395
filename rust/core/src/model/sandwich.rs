//! The sandwich of Section 4 (Fig. 3): the input block (16), a general backlash (1) and the
//! output block (29): w(t) = sum_{i=1}^{nr} r_i y(t-i) - sum_{j=1}^{ns} s_j w(t-j).

use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::{GeneralBacklash, Step};
use crate::model::cascade::{moving_count, switching_flags, unreachable_error};
use crate::model::linear::{
    blame_feeding_block, check_no_overflow, Boxed, LinearBlock, LinearState, Outputs, Recursion,
    RecursionUser,
};
use crate::model::signal::check_signal;
use crate::model::sink::OutputSink;

#[derive(Debug, Clone, PartialEq)]
pub struct SandwichModel {
    pub input_linear: LinearBlock,
    pub backlash: GeneralBacklash,
    /// Coefficients a = r, b = s of eq (29).
    pub output_linear: LinearBlock,
}

/// Where a sandwich record starts. The output block's past inputs are the backlash outputs,
/// `output.u_past = [y(0), y(-1), ..]`, so y(0) is also the backlash memory.
#[derive(Debug, Clone, PartialEq)]
pub struct SandwichState {
    pub input: LinearState,
    pub output: LinearState,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SandwichSimulation {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub w: Vec<f64>,
    pub f1: Vec<bool>,
    pub f2: Vec<bool>,
    pub final_state: SandwichState,
}

impl SandwichModel {
    pub fn new(
        input_linear: LinearBlock,
        backlash: GeneralBacklash,
        output_linear: LinearBlock,
    ) -> Self {
        SandwichModel {
            input_linear,
            backlash,
            output_linear,
        }
    }

    pub fn rest_state(&self) -> SandwichState {
        SandwichState {
            input: self.input_linear.rest_state(),
            output: self.output_linear.rest_state(),
        }
    }

    fn check_state(&self, state: &SandwichState) -> Result<()> {
        self.input_linear.check_state(&state.input, "state.input")?;
        self.output_linear
            .check_state(&state.output, "state.output")?;
        if state.output.u_past.is_empty() {
            return Err(Error::Model(
                "the output block needs at least one r coefficient".into(),
            ));
        }
        Ok(())
    }

    /// x (eq 16), y (eq 1) and w (eq 29), one block after the other.
    fn run(&self, u: &[f64], state: &SandwichState) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        check_signal("u", u)?;
        self.check_state(state)?;
        let x = self.input_linear.simulate(u, &state.input)?;
        let y = self
            .backlash
            .simulate(&x, state.output.u_past[0])
            .map_err(|e| blame_feeding_block(e, &self.input_linear, "input"))?;
        let w = self
            .output_linear
            .with_recursion(&state.output, Outputs(&y))?;
        check_no_overflow(&self.output_linear, &w, "w")?;
        Ok((x, y, w))
    }

    /// The sandwich output w for the input u, block by block: x and y, then w, for `BLOCK`
    /// samples at a time, only w kept. (One loop for all three would let the compiler pack
    /// x(t) and w(t) into one vector, which chains x(t) behind y(t-1): slower. Boxing the
    /// two stages also spares compiling one loop per pair of block orders.) The checks of
    /// u, x and w ride along as in `CascadeModel::simulate`; on a failure `run` names it.
    pub fn simulate(&self, u: &[f64], state: &SandwichState) -> Result<Vec<f64>> {
        let mut w = guard::buffer(u.len(), "w")?;
        self.simulate_into(u, state, &mut w)?;
        Ok(w)
    }

    /// `simulate`, its output handed to `sink` block by block instead of kept (the output
    /// error of a long record in constant memory: `ErrorSum`).
    pub fn simulate_into(
        &self,
        u: &[f64],
        state: &SandwichState,
        sink: &mut impl OutputSink,
    ) -> Result<()> {
        const BLOCK: usize = 256;
        let ready = self.check_state(state);
        if u.is_empty() || ready.is_err() {
            check_signal("u", u)?;
            ready?;
        }
        let first_two = XyBlocks {
            backlash: &self.backlash,
            y0: state.output.u_past[0],
        };
        let mut x_then_y = self.input_linear.with_recursion(&state.input, first_two);
        let mut output = self.output_linear.with_recursion(&state.output, Boxed);
        let (mut x_block, mut y_block, mut w_block) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
        let mut finite = true;
        for (i, u_block) in u.chunks(BLOCK).enumerate() {
            if i % (guard::CHUNK / BLOCK) == 0 {
                guard::check()?;
            }
            let x_block = &mut x_block[..u_block.len()];
            let y_block = &mut y_block[..u_block.len()];
            let w_block = &mut w_block[..u_block.len()];
            x_then_y.run_block(u_block, x_block, y_block);
            output.run_block(y_block, w_block);
            finite &= x_block
                .iter()
                .chain(&*y_block)
                .chain(&*w_block)
                .all(|v| v.is_finite());
            sink.take(w_block.iter().copied());
        }
        if finite && u.last().is_some_and(|v| v.is_finite()) {
            Ok(())
        } else {
            self.run(u, state)?;
            unreachable_error()
        }
    }

    /// The output with x, y, f1, f2 and the state to continue from.
    pub fn simulate_internals(
        &self,
        u: &[f64],
        state: &SandwichState,
    ) -> Result<SandwichSimulation> {
        let (x, y, w) = self.run(u, state)?;
        let (f1, f2) = switching_flags(&self.backlash, &x, &y, state.output.u_past[0])?;
        let final_state = SandwichState {
            input: self.input_linear.state_after(&state.input, u, &x),
            output: self.output_linear.state_after(&state.output, &y, &w),
        };
        Ok(SandwichSimulation {
            x,
            y,
            w,
            f1,
            f2,
            final_state,
        })
    }

    /// How many samples t >= `warmup` move the backlash (f1 or f2 of eq 12-13) on the run
    /// from `state`: the flags of `simulate_internals`, counted without storing them.
    pub fn moving_count(&self, u: &[f64], state: &SandwichState, warmup: usize) -> Result<usize> {
        let (x, y, _w) = self.run(u, state)?;
        Ok(moving_count(
            &self.backlash,
            &x,
            &y,
            state.output.u_past[0],
            warmup,
        ))
    }
}

/// The input block and the backlash of a sandwich, run a block of samples per call.
trait XyBlock {
    /// x and y for the inputs `u`, into `x` and `y` (as many as all three have).
    fn run_block(&mut self, u: &[f64], x: &mut [f64], y: &mut [f64]);
}

struct Xy<R, S> {
    input: R,
    backlash: S,
    y_prev: f64,
}

impl<R: Recursion, S: Step> XyBlock for Xy<R, S> {
    fn run_block(&mut self, u: &[f64], x: &mut [f64], y: &mut [f64]) {
        for ((xt, yt), &ut) in x.iter_mut().zip(y.iter_mut()).zip(u) {
            *xt = self.input.next(ut);
            self.y_prev = self.backlash.step(*xt, self.y_prev);
            *yt = self.y_prev;
        }
    }
}

/// Boxes the input block's recursion with the backlash, from memory y(0) = `y0`.
struct XyBlocks<'a> {
    backlash: &'a GeneralBacklash,
    y0: f64,
}

impl<'a> RecursionUser for XyBlocks<'a> {
    type Output = Box<dyn XyBlock + 'a>;

    fn run<R: Recursion>(self, input: R) -> Self::Output {
        let y_prev = self.y0;
        match self.backlash.padded_step() {
            Some(backlash) => Box::new(Xy {
                input,
                backlash,
                y_prev,
            }),
            None => Box::new(Xy {
                input,
                backlash: self.backlash,
                y_prev,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::test_params::example2_model as example2;

    #[test]
    fn continuing_from_the_final_state_equals_one_long_run() {
        let m = example2();
        let u: Vec<f64> = (0..300).map(|k| ((k as f64) * 0.23).cos()).collect();
        let whole = m.simulate(&u, &m.rest_state()).unwrap();
        let first = m.simulate_internals(&u[..77], &m.rest_state()).unwrap();
        let rest = m.simulate(&u[77..], &first.final_state).unwrap();
        assert_eq!(&whole[77..], &rest[..]);
    }

    #[test]
    fn moving_count_counts_the_flags_after_warmup() {
        let m = example2();
        let u: Vec<f64> = (0..600).map(|k| ((k as f64) * 0.04).sin() * 1.5).collect();
        let s = m.simulate_internals(&u, &m.rest_state()).unwrap();
        let moving: Vec<bool> = s.f1.iter().zip(&s.f2).map(|(a, b)| a | b).collect();
        assert!(moving.iter().any(|&v| v) && moving.iter().any(|&v| !v));
        for warmup in [0, 10, 333, 600] {
            let want = moving.iter().skip(warmup).filter(|&&v| v).count();
            assert_eq!(m.moving_count(&u, &m.rest_state(), warmup).unwrap(), want);
        }
    }
}
