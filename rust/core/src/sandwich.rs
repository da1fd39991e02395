//! The sandwich of Section 4 (Fig. 3): the input block (16), a general backlash (1) and the
//! output block (29): w(t) = sum_{i=1}^{nr} r_i y(t-i) - sum_{j=1}^{ns} s_j w(t-j).

use crate::backlash::GeneralBacklash;
use crate::cascade::switching_flags;
use crate::error::{Error, Result};
use crate::linear::{check_no_overflow, LinearBlock, LinearState};
use crate::signal::check_signal;

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

    /// x (eq 16), y (eq 1) and w (eq 29), sample by sample in one pass.
    fn run(&self, u: &[f64], state: &SandwichState) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        check_signal("u", u)?;
        self.check_state(state)?;
        let n = u.len();
        let (mut x, mut y, mut w) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut y_prev = state.output.u_past[0];
        for t in 0..n {
            // w(t) needs y up to t-1 only
            w[t] = self.output_linear.output_at(&y, &w, t, &state.output);
            let xt = self.input_linear.output_at(u, &x, t, &state.input);
            x[t] = xt;
            y_prev = self.backlash.step(xt, y_prev);
            y[t] = y_prev;
        }
        check_no_overflow(&self.input_linear, &x, "x")?;
        check_no_overflow(&self.output_linear, &w, "w")?;
        Ok((x, y, w))
    }

    /// The sandwich output w for the input u.
    pub fn simulate(&self, u: &[f64], state: &SandwichState) -> Result<Vec<f64>> {
        Ok(self.run(u, state)?.2)
    }

    /// The output with x, y, f1, f2 and the state to continue from.
    pub fn simulate_internals(
        &self,
        u: &[f64],
        state: &SandwichState,
    ) -> Result<SandwichSimulation> {
        let (x, y, w) = self.run(u, state)?;
        let (f1, f2) = switching_flags(&self.backlash, &x, &y, state.output.u_past[0]);
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example2() -> SandwichModel {
        SandwichModel::new(
            LinearBlock::new(vec![0.8, 0.2], vec![0.2, -0.2]).unwrap(),
            GeneralBacklash::new(0.4, 0.5, vec![1.0, 0.1, 0.3], vec![0.75, 0.2, 0.6]).unwrap(),
            LinearBlock::new(vec![1.0, 0.15], vec![-0.2, 0.35]).unwrap(),
        )
    }

    #[test]
    fn equals_the_three_blocks_run_one_after_the_other() {
        let m = example2();
        let u: Vec<f64> = (0..700).map(|k| ((k as f64) * 0.9).sin() * 0.95).collect();
        let x = m
            .input_linear
            .simulate(&u, &m.input_linear.rest_state())
            .unwrap();
        let y = m.backlash.simulate(&x, 0.0).unwrap();
        let w = m
            .output_linear
            .simulate(&y, &m.output_linear.rest_state())
            .unwrap();
        assert_eq!(m.simulate(&u, &m.rest_state()).unwrap(), w);
    }

    #[test]
    fn continuing_from_the_final_state_equals_one_long_run() {
        let m = example2();
        let u: Vec<f64> = (0..300).map(|k| ((k as f64) * 0.23).cos()).collect();
        let whole = m.simulate(&u, &m.rest_state()).unwrap();
        let first = m.simulate_internals(&u[..77], &m.rest_state()).unwrap();
        let rest = m.simulate(&u[77..], &first.final_state).unwrap();
        assert_eq!(&whole[77..], &rest[..]);
    }
}
