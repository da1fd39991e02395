//! The cascade of Section 3 (Fig. 2): the linear block (16) followed by a general backlash (1).

use crate::error::{Error, Result};
use crate::guard;
use crate::model::backlash::{check_memory, GeneralBacklash, Step};
use crate::model::linear::{
    blame_feeding_block, LinearBlock, LinearState, Recursion, RecursionUser,
};
use crate::model::signal::check_signal;
use crate::model::sink::OutputSink;
use crate::model::switching::switching;

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

    /// y (eq 1) of x (eq 16) in one pass, x not kept.
    ///
    /// The checks of u and x ride along in the loop instead of taking passes of their own:
    /// a_1 u(t-1) is a term of x(t), so a non-finite u[i] makes x[i+1] non-finite; finite
    /// x all through and a finite last u thus mean a finite u. On any failure the linear
    /// block is rerun alone, which names the first culprit exactly as separate checks would.
    pub fn simulate(&self, u: &[f64], state: &CascadeState) -> Result<Vec<f64>> {
        let mut y = guard::buffer(u.len(), "y")?;
        self.simulate_into(u, state, &mut y)?;
        Ok(y)
    }

    /// `simulate`, its output handed to `sink` chunk by chunk instead of kept (the output
    /// error of a long record in constant memory: `ErrorSum`).
    pub fn simulate_into(
        &self,
        u: &[f64],
        state: &CascadeState,
        sink: &mut impl OutputSink,
    ) -> Result<()> {
        self.check_start(u, state)?;
        let run = CascadeRun {
            backlash: &self.backlash,
            u,
            y0: state.y_prev,
            sink,
        };
        match self.linear.with_recursion(&state.linear, run)? {
            true if u.last().is_some_and(|v| v.is_finite()) => Ok(()),
            _ => {
                let x = self.linear.simulate(u, &state.linear)?;
                self.backlash
                    .simulate(&x, state.y_prev)
                    .map_err(|e| blame_feeding_block(e, &self.linear, "input"))?;
                unreachable_error()
            }
        }
    }

    /// The output with x, f1, f2 and the state to continue from.
    pub fn simulate_internals(&self, u: &[f64], state: &CascadeState) -> Result<CascadeSimulation> {
        check_signal("u", u)?;
        self.linear.check_state(&state.linear, "state.linear")?;
        check_memory(state.y_prev)?;
        let x = self.linear.simulate(u, &state.linear)?;
        let y = self
            .backlash
            .simulate(&x, state.y_prev)
            .map_err(|e| blame_feeding_block(e, &self.linear, "input"))?;
        let (f1, f2) = switching_flags(&self.backlash, &x, &y, state.y_prev)?;
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

    /// The checks before the loops of `simulate` and `moving_count`: the state, and u only
    /// if empty or the state is bad (the loops check u as they run).
    fn check_start(&self, u: &[f64], state: &CascadeState) -> Result<()> {
        let ready = self
            .linear
            .check_state(&state.linear, "state.linear")
            .and_then(|()| check_memory(state.y_prev));
        if u.is_empty() || ready.is_err() {
            check_signal("u", u)?;
            ready?;
        }
        Ok(())
    }

    /// How many samples t >= `warmup` move the backlash (f1 or f2 of eq 12-13) on the run
    /// from `state`: the flags of `simulate_internals`, counted in the loop of `simulate`.
    pub fn moving_count(&self, u: &[f64], state: &CascadeState, warmup: usize) -> Result<usize> {
        self.check_start(u, state)?;
        let count = CascadeCount {
            backlash: &self.backlash,
            u,
            y0: state.y_prev,
            warmup,
        };
        match self.linear.with_recursion(&state.linear, count)? {
            (moving, true) if u.last().is_some_and(|v| v.is_finite()) => Ok(moving),
            // the simulation names what failed
            _ => self.simulate(u, state).and_then(|_| unreachable_error()),
        }
    }
}

/// The loop of `CascadeModel::moving_count`: the count, and whether every x and y was finite.
struct CascadeCount<'a> {
    backlash: &'a GeneralBacklash,
    u: &'a [f64],
    y0: f64,
    warmup: usize,
}

impl RecursionUser for CascadeCount<'_> {
    type Output = Result<(usize, bool)>;

    fn run<R: Recursion>(self, linear: R) -> Self::Output {
        match self.backlash.padded_step() {
            Some(step) => self.count_with(linear, step),
            None => self.count_with(linear, self.backlash),
        }
    }
}

impl CascadeCount<'_> {
    fn count_with<R: Recursion, S: Step>(
        &self,
        mut linear: R,
        backlash: S,
    ) -> Result<(usize, bool)> {
        let (mut finite, mut y_prev, mut moving) = (true, self.y0, 0);
        let (head, counted) = self.u.split_at(self.warmup.min(self.u.len()));
        for chunk in head.chunks(guard::CHUNK) {
            guard::check()?;
            for &ut in chunk {
                let xt = linear.next(ut);
                y_prev = backlash.step(xt, y_prev);
                finite &= xt.is_finite() & y_prev.is_finite();
            }
        }
        for chunk in counted.chunks(guard::CHUNK) {
            guard::check()?;
            for &ut in chunk {
                let xt = linear.next(ut);
                moving += backlash.moves(xt, y_prev) as usize;
                y_prev = backlash.step(xt, y_prev);
                finite &= xt.is_finite() & y_prev.is_finite();
            }
        }
        Ok((moving, finite))
    }
}

/// The loop of `CascadeModel::simulate`: y, and whether every x and y was finite.
struct CascadeRun<'a, K> {
    backlash: &'a GeneralBacklash,
    u: &'a [f64],
    y0: f64,
    sink: &'a mut K,
}

impl<K: OutputSink> RecursionUser for CascadeRun<'_, K> {
    /// Whether x and y stayed finite.
    type Output = Result<bool>;

    fn run<R: Recursion>(self, linear: R) -> Self::Output {
        let backlash = self.backlash;
        match backlash.padded_step() {
            Some(step) => self.run_with(linear, step),
            None => self.run_with(linear, backlash),
        }
    }
}

impl<K: OutputSink> CascadeRun<'_, K> {
    /// The sink takes each chunk as a slice's `map`: into a vector, `extend` writes it into
    /// one exact allocation without capacity checks (`push` has them, and its rarely taken
    /// call makes the compiler spill the recursion's registers). So no early exit: a
    /// non-finite x only clears the `finite` flag.
    fn run_with<R: Recursion, S: Step>(self, mut linear: R, backlash: S) -> Result<bool> {
        let mut finite = true;
        let mut y_prev = self.y0;
        for chunk in self.u.chunks(guard::CHUNK) {
            guard::check()?;
            self.sink.take(chunk.iter().map(|&ut| {
                let xt = linear.next(ut);
                y_prev = backlash.step(xt, y_prev);
                finite &= xt.is_finite() & y_prev.is_finite();
                y_prev
            }));
        }
        Ok(finite)
    }
}

/// For a failure that a rerun of the linear block alone did not reproduce: cannot happen
/// (the rerun computes the same x), but an error beats a panic.
pub(crate) fn unreachable_error<T>() -> Result<T> {
    Err(Error::Model(
        "internal error: the simulation failed but its rerun did not; please report".into(),
    ))
}

/// f1(t), f2(t) of eq (12)-(13) (case order of eq 1) along a simulated record.
pub(crate) fn switching_flags(
    backlash: &GeneralBacklash,
    x: &[f64],
    y: &[f64],
    y0: f64,
) -> Result<(Vec<bool>, Vec<bool>)> {
    // the padded branches (the same bits, a fixed number of Horner steps) where they apply
    let mut flags = (guard::buffer(x.len(), "f1")?, guard::buffer(x.len(), "f2")?);
    match backlash.padded_step() {
        Some(padded) => flags.extend(flags_along(x, y, y0, move |xt, yp| {
            padded.switching(xt, yp)
        })),
        None => flags.extend(flags_along(x, y, y0, |xt, yp| switching(backlash, xt, yp))),
    }
    Ok(flags)
}

/// The number of t >= warmup with f1(t) or f2(t) along a simulated record (`switching_flags`
/// counted).
pub(crate) fn moving_count(
    backlash: &GeneralBacklash,
    x: &[f64],
    y: &[f64],
    y0: f64,
    warmup: usize,
) -> usize {
    let start = warmup.min(x.len());
    let y0 = if start == 0 { y0 } else { y[start - 1] };
    let (x, y) = (&x[start..], &y[start..]);
    let moves = |(f1, f2): &(bool, bool)| f1 | f2;
    match backlash.padded_step() {
        Some(padded) => flags_along(x, y, y0, move |xt, yp| padded.switching(xt, yp))
            .filter(moves)
            .count(),
        None => flags_along(x, y, y0, |xt, yp| switching(backlash, xt, yp))
            .filter(moves)
            .count(),
    }
}

/// (f1(t), f2(t)) for t = 0, 1, .. from x(t) and y(t-1).
fn flags_along<'a>(
    x: &'a [f64],
    y: &'a [f64],
    y0: f64,
    switching: impl Fn(f64, f64) -> (bool, bool) + 'a,
) -> impl Iterator<Item = (bool, bool)> + 'a {
    let mut y_prev = y0;
    x.iter().zip(y).map(move |(&xt, &yt)| {
        let f = switching(xt, y_prev);
        y_prev = yt;
        f
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_params::example1_model as example1;

    #[test]
    fn moving_count_counts_the_flags_after_warmup() {
        // branches of degree 3 (the padded step) and 5 (the general one)
        let quintic = CascadeModel::new(
            example1().linear,
            GeneralBacklash::new(
                0.6,
                0.5,
                vec![1.0, 0.0, 0.2, 0.0, 0.01],
                vec![1.5, 0.1, 0.2],
            )
            .unwrap(),
        );
        for m in [example1(), quintic] {
            let u: Vec<f64> = (0..700).map(|k| ((k as f64) * 0.05).sin() * 2.0).collect();
            let state = CascadeState {
                y_prev: 0.3,
                ..m.rest_state()
            };
            let s = m.simulate_internals(&u, &state).unwrap();
            let moving: Vec<bool> = s.f1.iter().zip(&s.f2).map(|(a, b)| a | b).collect();
            assert!(moving.iter().any(|&v| v) && moving.iter().any(|&v| !v));
            for warmup in [0, 1, 77, 699, 700, 5000] {
                let want = moving.iter().skip(warmup).filter(|&&v| v).count();
                assert_eq!(
                    m.moving_count(&u, &state, warmup).unwrap(),
                    want,
                    "warmup {warmup}"
                );
            }
            assert!(m.moving_count(&[0.1, f64::NAN], &state, 0).is_err());
            assert!(m.moving_count(&[], &state, 0).is_err());
        }
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
