//! The cascade of Section 3 (Fig. 2): the linear block (16) followed by a general backlash (1).

use crate::backlash::{check_memory, GeneralBacklash};
use crate::error::Result;
use crate::linear::{check_no_overflow, LinearBlock, LinearState};
use crate::signal::check_signal;
use crate::switching::switching;

#[derive(Debug, Clone, PartialEq)]
pub struct CascadeModel {
    pub linear: LinearBlock,
    pub backlash: GeneralBacklash,
}

/// Where a cascade record starts: the linear block's past and the backlash memory y(0).
#[derive(Debug, Clone, PartialEq)]
pub struct CascadeState {
    pub linear: LinearState,
    pub y_prev: f64,
}

/// A cascade simulation with its internal signals.
#[derive(Debug, Clone, PartialEq)]
pub struct CascadeSimulation {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub f1: Vec<bool>,
    pub f2: Vec<bool>,
    pub final_state: CascadeState,
}

impl CascadeModel {
    pub fn new(linear: LinearBlock, backlash: GeneralBacklash) -> Self {
        CascadeModel { linear, backlash }
    }

    /// At rest: the paper's convention (all past signals and y(0) zero).
    pub fn rest_state(&self) -> CascadeState {
        CascadeState {
            linear: self.linear.rest_state(),
            y_prev: 0.0,
        }
    }

    /// x (eq 16) and y (eq 1), sample by sample in one pass.
    fn run(&self, u: &[f64], state: &CascadeState) -> Result<(Vec<f64>, Vec<f64>)> {
        check_signal("u", u)?;
        self.linear.check_state(&state.linear, "state.linear")?;
        check_memory(state.y_prev)?;
        let n = u.len();
        let mut x = vec![0.0; n];
        let mut y = vec![0.0; n];
        let mut y_prev = state.y_prev;
        for t in 0..n {
            let xt = self.linear.output_at(u, &x, t, &state.linear);
            x[t] = xt;
            y_prev = self.backlash.step(xt, y_prev);
            y[t] = y_prev;
        }
        check_no_overflow(&self.linear, &x, "x")?;
        Ok((x, y))
    }

    /// The cascade output y for the input u.
    pub fn simulate(&self, u: &[f64], state: &CascadeState) -> Result<Vec<f64>> {
        Ok(self.run(u, state)?.1)
    }

    /// The output with x, f1, f2 and the state to continue from.
    pub fn simulate_internals(&self, u: &[f64], state: &CascadeState) -> Result<CascadeSimulation> {
        let (x, y) = self.run(u, state)?;
        let (f1, f2) = switching_flags(&self.backlash, &x, &y, state.y_prev);
        let final_state = CascadeState {
            linear: self.linear.state_after(&state.linear, u, &x),
            y_prev: *y.last().unwrap_or(&state.y_prev),
        };
        Ok(CascadeSimulation {
            x,
            y,
            f1,
            f2,
            final_state,
        })
    }
}

/// f1(t), f2(t) of eq (12)-(13) (case order of eq 1) along a simulated record.
pub(crate) fn switching_flags(
    backlash: &GeneralBacklash,
    x: &[f64],
    y: &[f64],
    y0: f64,
) -> (Vec<bool>, Vec<bool>) {
    let mut y_prev = y0;
    x.iter()
        .zip(y)
        .map(|(&xt, &yt)| {
            let f = switching(backlash, xt, y_prev);
            y_prev = yt;
            f
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn example1() -> CascadeModel {
        CascadeModel::new(
            LinearBlock::new(vec![0.7, 0.5], vec![-0.2, 0.35]).unwrap(),
            GeneralBacklash::new(0.6, 0.5, vec![1.0, -0.3, 0.3], vec![1.5, 0.4, 0.2]).unwrap(),
        )
    }

    #[test]
    fn equals_the_blocks_run_one_after_the_other() {
        let m = example1();
        let u: Vec<f64> = (0..500).map(|k| ((k as f64) * 0.7).sin()).collect();
        let x = m.linear.simulate(&u, &m.linear.rest_state()).unwrap();
        let y = m.backlash.simulate(&x, 0.0).unwrap();
        assert_eq!(m.simulate(&u, &m.rest_state()).unwrap(), y);
    }

    #[test]
    fn continuing_from_the_final_state_equals_one_long_run() {
        let m = example1();
        let u: Vec<f64> = (0..400).map(|k| ((k as f64) * 0.31).sin() * 1.3).collect();
        let whole = m.simulate(&u, &m.rest_state()).unwrap();
        let first = m.simulate_internals(&u[..123], &m.rest_state()).unwrap();
        let rest = m.simulate(&u[123..], &first.final_state).unwrap();
        assert_eq!(&whole[123..], &rest[..]);
        assert_eq!(&whole[..123], &first.y[..]);
    }
}
