//! The model classes of `backlashid._core`: thin frozen wrappers of the core's linear
//! block, general backlash, cascade and sandwich. A model's state crosses as the lists the
//! Python layer keeps (u_past, x_past, ... newest first).

use backlashid_core as core;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{signal, vec_bool, vec_f64, FlagOut, SignalIn, SignalOut};
use crate::errors::{run, CoreError};

#[pyclass(frozen, module = "backlashid._core", name = "LinearBlock")]
pub(crate) struct PyLinearBlock(core::LinearBlock);

#[pymethods]
impl PyLinearBlock {
    /// `a0`: the feedthrough a_0 of u(t), None for eq (16) as the paper has it.
    #[new]
    #[pyo3(signature = (a, b, a0=None))]
    fn new(a: Vec<f64>, b: Vec<f64>, a0: Option<f64>) -> PyResult<Self> {
        let block = match a0 {
            None => core::LinearBlock::new(a, b),
            Some(a0) => core::LinearBlock::with_feedthrough(a0, a, b),
        };
        Ok(Self(block.map_err(CoreError)?))
    }

    /// Poles as (re, im) pairs.
    fn poles(&self) -> Vec<(f64, f64)> {
        self.0.poles()
    }

    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: SignalIn<'py>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let state = core::LinearState { u_past, x_past };
        Ok(vec_f64(py, run(py, || self.0.simulate(&u, &state))?))
    }
}

#[pyclass(frozen, module = "backlashid._core", name = "GeneralBacklash")]
pub(crate) struct PyGeneralBacklash(core::GeneralBacklash);

/// A branch's values at every x.
fn branch_values<'py>(
    py: Python<'py>,
    branch: &core::Branch,
    x: SignalIn<'py>,
) -> PyResult<SignalOut<'py>> {
    let x = signal("x", &x)?;
    Ok(vec_f64(py, x.iter().map(|&v| branch.value(v)).collect()))
}

#[pymethods]
impl PyGeneralBacklash {
    #[new]
    fn new(c_left: f64, c_right: f64, m_left: Vec<f64>, m_right: Vec<f64>) -> PyResult<Self> {
        let backlash = core::GeneralBacklash::new(c_left, c_right, m_left, m_right);
        Ok(Self(backlash.map_err(CoreError)?))
    }

    fn left<'py>(&self, py: Python<'py>, x: SignalIn<'py>) -> PyResult<SignalOut<'py>> {
        branch_values(py, self.0.left(), x)
    }

    fn right<'py>(&self, py: Python<'py>, x: SignalIn<'py>) -> PyResult<SignalOut<'py>> {
        branch_values(py, self.0.right(), x)
    }

    /// form: "eq1" (value comparisons, fast) or "breakpoints" (eq 1 through z_L, z_R of eq 2-3).
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        x: SignalIn<'py>,
        y0: f64,
        form: &str,
    ) -> PyResult<SignalOut<'py>> {
        let x = signal("x", &x)?;
        let y = match form {
            "eq1" => run(py, || self.0.simulate(&x, y0))?,
            "breakpoints" => run(py, || self.0.simulate_by_breakpoints(&x, y0))?,
            other => {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "unknown form {other:?}: use 'eq1' or 'breakpoints'"
                )))
            }
        };
        Ok(vec_f64(py, y))
    }

    /// Eq (9)-(15): (xi1, xi2, f1, f2, y).
    #[allow(clippy::type_complexity)]
    fn switching<'py>(
        &self,
        py: Python<'py>,
        x: SignalIn<'py>,
        y0: f64,
    ) -> PyResult<(
        SignalOut<'py>,
        SignalOut<'py>,
        FlagOut<'py>,
        FlagOut<'py>,
        SignalOut<'py>,
    )> {
        let x = signal("x", &x)?;
        let s = run(py, || core::switching_form(&self.0, &x, y0))?;
        Ok((
            vec_f64(py, s.xi1),
            vec_f64(py, s.xi2),
            vec_bool(py, s.f1),
            vec_bool(py, s.f2),
            vec_f64(py, s.y),
        ))
    }

    /// x such that the backlash, from memory y0, outputs y (the inverse of eq 1, from x(0) =
    /// x0, smoothing `threshold`).
    fn inverse<'py>(
        &self,
        py: Python<'py>,
        y: SignalIn<'py>,
        y0: f64,
        x0: f64,
        threshold: f64,
    ) -> PyResult<SignalOut<'py>> {
        let y = signal("y_desired", &y)?;
        let x = run(py, || self.0.inverse(&y, y0, x0, threshold))?;
        Ok(vec_f64(py, x))
    }

    fn breakpoints(&self, y_prev: f64, x_lo: f64, x_hi: f64) -> (f64, f64) {
        self.0.breakpoints(y_prev, x_lo, x_hi)
    }

    fn check_branches<'py>(
        &self,
        py: Python<'py>,
        x_min: f64,
        x_max: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let c = py.detach(|| self.0.check_branches(x_min, x_max));
        let d = PyDict::new(py);
        d.set_item("x_min", c.x_min)?;
        d.set_item("x_max", c.x_max)?;
        d.set_item("left_not_increasing", c.left_not_increasing)?;
        d.set_item("right_not_increasing", c.right_not_increasing)?;
        d.set_item("crossed", c.crossed)?;
        Ok(d)
    }
}

#[pyclass(frozen, module = "backlashid._core", name = "CascadeModel")]
pub(crate) struct PyCascadeModel(pub(crate) core::CascadeModel);

/// The cascade's state as the Python layer passes it.
fn cascade_state(u_past: Vec<f64>, x_past: Vec<f64>, y_prev: f64) -> core::CascadeState {
    core::CascadeState {
        linear: core::LinearState { u_past, x_past },
        y_prev,
    }
}

#[pymethods]
impl PyCascadeModel {
    #[new]
    fn new(linear: &PyLinearBlock, backlash: &PyGeneralBacklash) -> Self {
        Self(core::CascadeModel::new(
            linear.0.clone(),
            backlash.0.clone(),
        ))
    }

    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: SignalIn<'py>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_prev: f64,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let state = cascade_state(u_past, x_past, y_prev);
        Ok(vec_f64(py, run(py, || self.0.simulate(&u, &state))?))
    }

    /// (x, y, f1, f2, (u_past, x_past, y_prev)) of the record.
    #[allow(clippy::type_complexity)]
    fn simulate_internals<'py>(
        &self,
        py: Python<'py>,
        u: SignalIn<'py>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_prev: f64,
    ) -> PyResult<(
        SignalOut<'py>,
        SignalOut<'py>,
        FlagOut<'py>,
        FlagOut<'py>,
        (Vec<f64>, Vec<f64>, f64),
    )> {
        let u = signal("u", &u)?;
        let state = cascade_state(u_past, x_past, y_prev);
        let s = run(py, || self.0.simulate_internals(&u, &state))?;
        let fs = s.final_state;
        Ok((
            vec_f64(py, s.x),
            vec_f64(py, s.y),
            vec_bool(py, s.f1),
            vec_bool(py, s.f2),
            (fs.linear.u_past, fs.linear.x_past, fs.y_prev),
        ))
    }

    /// Samples t >= warmup on which the backlash moves (f1 or f2), counted without the flags.
    fn moving_count(
        &self,
        py: Python<'_>,
        u: SignalIn<'_>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_prev: f64,
        warmup: usize,
    ) -> PyResult<usize> {
        let u = signal("u", &u)?;
        let state = cascade_state(u_past, x_past, y_prev);
        run(py, || self.0.moving_count(&u, &state, warmup))
    }

    /// The length of the state vector [u_past.., x_past.., y_prev] of `step`.
    #[getter]
    fn state_size(&self) -> usize {
        self.0.state_size()
    }

    /// One sample (rust/core/src/model/state_space.rs): (y(t), the next state vector).
    fn step<'py>(
        &self,
        py: Python<'py>,
        state: SignalIn<'py>,
        u: f64,
    ) -> PyResult<(f64, SignalOut<'py>)> {
        let state = signal("state", &state)?;
        let (y, next) = self.0.step(&state, u).map_err(CoreError)?;
        Ok((y, vec_f64(py, next)))
    }
}

#[pyclass(frozen, module = "backlashid._core", name = "SandwichModel")]
pub(crate) struct PySandwichModel(pub(crate) core::SandwichModel);

/// The sandwich's state as the Python layer passes it: the input block's pasts, then the
/// output block's (its input y, its output w).
fn sandwich_state(
    u_past: Vec<f64>,
    x_past: Vec<f64>,
    y_past: Vec<f64>,
    w_past: Vec<f64>,
) -> core::SandwichState {
    core::SandwichState {
        input: core::LinearState { u_past, x_past },
        output: core::LinearState {
            u_past: y_past,
            x_past: w_past,
        },
    }
}

#[pymethods]
impl PySandwichModel {
    #[new]
    fn new(
        input_linear: &PyLinearBlock,
        backlash: &PyGeneralBacklash,
        output_linear: &PyLinearBlock,
    ) -> Self {
        Self(core::SandwichModel::new(
            input_linear.0.clone(),
            backlash.0.clone(),
            output_linear.0.clone(),
        ))
    }

    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: SignalIn<'py>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_past: Vec<f64>,
        w_past: Vec<f64>,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let state = sandwich_state(u_past, x_past, y_past, w_past);
        Ok(vec_f64(py, run(py, || self.0.simulate(&u, &state))?))
    }

    /// (x, y, w, f1, f2, (u_past, x_past, y_past, w_past)) of the record.
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn simulate_internals<'py>(
        &self,
        py: Python<'py>,
        u: SignalIn<'py>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_past: Vec<f64>,
        w_past: Vec<f64>,
    ) -> PyResult<(
        SignalOut<'py>,
        SignalOut<'py>,
        SignalOut<'py>,
        FlagOut<'py>,
        FlagOut<'py>,
        (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>),
    )> {
        let u = signal("u", &u)?;
        let state = sandwich_state(u_past, x_past, y_past, w_past);
        let s = run(py, || self.0.simulate_internals(&u, &state))?;
        let fs = s.final_state;
        Ok((
            vec_f64(py, s.x),
            vec_f64(py, s.y),
            vec_f64(py, s.w),
            vec_bool(py, s.f1),
            vec_bool(py, s.f2),
            (
                fs.input.u_past,
                fs.input.x_past,
                fs.output.u_past,
                fs.output.x_past,
            ),
        ))
    }

    /// Samples t >= warmup on which the backlash moves (f1 or f2), counted without the flags.
    #[allow(clippy::too_many_arguments)]
    fn moving_count(
        &self,
        py: Python<'_>,
        u: SignalIn<'_>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_past: Vec<f64>,
        w_past: Vec<f64>,
        warmup: usize,
    ) -> PyResult<usize> {
        let u = signal("u", &u)?;
        let state = sandwich_state(u_past, x_past, y_past, w_past);
        run(py, || self.0.moving_count(&u, &state, warmup))
    }

    /// The length of the state vector [u_past.., x_past.., y_past.., w_past..] of `step`.
    #[getter]
    fn state_size(&self) -> usize {
        self.0.state_size()
    }

    /// One sample (rust/core/src/model/state_space.rs): (w(t), the next state vector).
    fn step<'py>(
        &self,
        py: Python<'py>,
        state: SignalIn<'py>,
        u: f64,
    ) -> PyResult<(f64, SignalOut<'py>)> {
        let state = signal("state", &state)?;
        let (w, next) = self.0.step(&state, u).map_err(CoreError)?;
        Ok((w, vec_f64(py, next)))
    }
}
