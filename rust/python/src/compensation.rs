//! The compensation of `backlashid._core`: the feedforward compensator, `compensate` and the
//! closed-loop PID simulation (rust/core/src/compensation). A model's state crosses as a list
//! of lists: cascade [u_past, x_past, [y_prev]], sandwich [u_past, x_past, y_past, w_past].

use backlashid_core as core;
use backlashid_core::compensation::{Chain, ChainState, CompensatorState, Pid};
use pyo3::prelude::*;

use crate::convert::{signal, vec_f64, SignalIn, SignalOut};
use crate::errors::{run, DataError};
use crate::models::{PyCascadeModel, PySandwichModel};

/// The model and its state from the binding's arguments.
fn chain(model: &Bound<'_, PyAny>, state: Vec<Vec<f64>>) -> PyResult<(Chain, ChainState)> {
    let linear = |u_past: Vec<f64>, x_past: Vec<f64>| core::LinearState { u_past, x_past };
    if let Ok(m) = model.cast::<PyCascadeModel>() {
        let [u_past, x_past, y_prev]: [Vec<f64>; 3] = state
            .try_into()
            .map_err(|_| DataError::new_err("a cascade's state is [u_past, x_past, [y_prev]]"))?;
        let y_prev = *y_prev
            .first()
            .ok_or_else(|| DataError::new_err("a cascade's state needs y_prev"))?;
        let s = core::CascadeState {
            linear: linear(u_past, x_past),
            y_prev,
        };
        return Ok((Chain::Cascade(m.get().0.clone()), ChainState::Cascade(s)));
    }
    if let Ok(m) = model.cast::<PySandwichModel>() {
        let [u_past, x_past, y_past, w_past]: [Vec<f64>; 4] = state.try_into().map_err(|_| {
            DataError::new_err("a sandwich's state is [u_past, x_past, y_past, w_past]")
        })?;
        let s = core::SandwichState {
            input: linear(u_past, x_past),
            output: linear(y_past, w_past),
        };
        return Ok((Chain::Sandwich(m.get().0.clone()), ChainState::Sandwich(s)));
    }
    Err(DataError::new_err(
        "model must be a compiled CascadeModel or SandwichModel",
    ))
}

/// (G^-1 pasts in, out, H^-1 pasts in, out, (y_prev, x_prev, direction, extremum,
/// samples), samples): the compensator's memory.
type SavedState = (
    Vec<f64>,
    Vec<f64>,
    Vec<f64>,
    Vec<f64>,
    (f64, f64, i8, f64, u64),
    u64,
);

#[pyclass(module = "backlashid._core", name = "Compensator")]
pub(crate) struct PyCompensator(core::Compensator);

#[pymethods]
impl PyCompensator {
    #[new]
    fn new(
        py: Python<'_>,
        model: &Bound<'_, PyAny>,
        state: Vec<Vec<f64>>,
        threshold: f64,
    ) -> PyResult<Self> {
        let (m, s) = chain(model, state)?;
        Ok(Self(run(py, || core::Compensator::new(&m, &s, threshold))?))
    }

    /// The preview D.
    #[getter]
    fn delay(&self) -> usize {
        self.0.delay()
    }

    /// Whether a linear block's inverse is the stable approximation.
    #[getter]
    fn approximate(&self) -> bool {
        self.0.approximate()
    }

    fn step(&mut self, reference: f64) -> PyResult<f64> {
        Ok(self.0.step(reference).map_err(crate::errors::CoreError)?)
    }

    fn run<'py>(&mut self, py: Python<'py>, reference: SignalIn<'py>) -> PyResult<SignalOut<'py>> {
        let r = signal("reference", &reference)?;
        let comp = &mut self.0;
        Ok(vec_f64(py, run(py, || comp.run(&r))?))
    }

    fn get_state(&self) -> SavedState {
        let s = self.0.state();
        let b = s.backlash;
        (
            s.input.0,
            s.input.1,
            s.output.0,
            s.output.1,
            (b.y_prev, b.x_prev, b.direction, b.extremum, b.samples),
            s.samples,
        )
    }

    fn set_state(&mut self, state: SavedState) -> PyResult<()> {
        let (g_in, g_out, h_in, h_out, (y_prev, x_prev, direction, extremum, b_samples), samples) =
            state;
        let mut backlash =
            core::BacklashInverse::new(y_prev, x_prev, 0.0).map_err(crate::errors::CoreError)?;
        backlash.direction = direction.signum();
        backlash.extremum = extremum;
        backlash.samples = b_samples;
        let saved = CompensatorState {
            input: (g_in, g_out),
            output: (h_in, h_out),
            backlash,
            samples,
        };
        Ok(self.0.set_state(saved).map_err(crate::errors::CoreError)?)
    }
}

/// u with u[t] targeting reference[t + D] (`core::compensate`).
#[pyfunction]
pub(crate) fn compensate<'py>(
    py: Python<'py>,
    model: &Bound<'py, PyAny>,
    reference: SignalIn<'py>,
    state: Vec<Vec<f64>>,
    threshold: f64,
) -> PyResult<SignalOut<'py>> {
    let (m, s) = chain(model, state)?;
    let r = signal("reference", &reference)?;
    Ok(vec_f64(
        py,
        run(py, || core::compensate(&m, &r, &s, threshold))?,
    ))
}

/// (u, y) of the PID loop around the plant (`core::compensation::closed_loop`).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub(crate) fn closed_loop<'py>(
    py: Python<'py>,
    plant: &Bound<'py, PyAny>,
    state: Vec<Vec<f64>>,
    reference: SignalIn<'py>,
    feedforward: SignalIn<'py>,
    kp: f64,
    ki: f64,
    kd: f64,
    saturation: Option<(f64, f64)>,
) -> PyResult<(SignalOut<'py>, SignalOut<'py>)> {
    let (m, s) = chain(plant, state)?;
    let r = signal("reference", &reference)?;
    let ff = signal("feedforward", &feedforward)?;
    let pid = Pid { kp, ki, kd };
    let out = run(py, || {
        core::compensation::closed_loop(&m, &s, &r, &ff, pid, saturation)
    })?;
    Ok((vec_f64(py, out.u), vec_f64(py, out.y)))
}
