//! Thin pyo3 binding of backlashid-core: converts arrays, releases the GIL around the loops,
//! and maps `backlashid_core::Error` onto `backlashid.errors`. No numerics live here.

use std::panic::{catch_unwind, AssertUnwindSafe};

mod augmented;

use backlashid_core as core;
use std::borrow::Cow;

use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Raise the `backlashid.errors` class that matches a core error.
fn to_py_err(py: Python<'_>, err: core::Error) -> PyErr {
    let (class, msg) = match err {
        core::Error::Data(m) => ("DataError", m),
        core::Error::Model(m) => ("ModelError", m),
        core::Error::NotIdentifiable(m) => ("NotIdentifiableError", m),
    };
    raise(py, class, msg)
}

fn raise(py: Python<'_>, class: &str, msg: String) -> PyErr {
    let made = py
        .import("backlashid.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1((msg,)));
    match made {
        Ok(instance) => PyErr::from_value(instance),
        Err(e) => e,
    }
}

/// Run core work without the GIL; a panic becomes `BacklashIdError` (a bug to report).
fn run<T: Send>(py: Python<'_>, work: impl FnOnce() -> core::Result<T> + Send) -> PyResult<T> {
    match py.detach(|| catch_unwind(AssertUnwindSafe(work))) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py_err(py, e)),
        Err(_) => Err(raise(
            py,
            "BacklashIdError",
            "internal error in the Rust core (a bug): please report it with the input that \
             caused it"
                .into(),
        )),
    }
}

/// A 1-D float64 signal, borrowed when contiguous (the Python layer converted the dtype).
fn signal<'a>(
    py: Python<'_>,
    name: &str,
    arr: &'a PyReadonlyArrayDyn<'_, f64>,
) -> PyResult<Cow<'a, [f64]>> {
    if arr.ndim() != 1 {
        return Err(to_py_err(
            py,
            core::Error::Data(format!(
                "{name} has {} dimensions, expected a 1-D signal: pass one channel, e.g. \
                 {name}.ravel() for a column",
                arr.ndim()
            )),
        ));
    }
    Ok(match arr.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(arr.as_array().iter().copied().collect()),
    })
}

fn vec_f64<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyArray1<f64>> {
    v.into_pyarray(py)
}

fn vec_bool<'py>(py: Python<'py>, v: Vec<bool>) -> Bound<'py, PyArray1<bool>> {
    v.into_pyarray(py)
}

#[pyclass(frozen, module = "backlashid._core", name = "LinearBlock")]
struct PyLinearBlock(core::LinearBlock);

#[pymethods]
impl PyLinearBlock {
    /// `a0`: the feedthrough a_0 of u(t), None for eq (16) as the paper has it.
    #[new]
    #[pyo3(signature = (a, b, a0=None))]
    fn new(py: Python<'_>, a: Vec<f64>, b: Vec<f64>, a0: Option<f64>) -> PyResult<Self> {
        match a0 {
            None => core::LinearBlock::new(a, b),
            Some(a0) => core::LinearBlock::with_feedthrough(a0, a, b),
        }
        .map(Self)
        .map_err(|e| to_py_err(py, e))
    }

    /// Poles as (re, im) pairs.
    fn poles(&self) -> Vec<(f64, f64)> {
        self.0.poles()
    }

    fn simulate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let u = signal(py, "u", &u)?;
        let state = core::LinearState { u_past, x_past };
        let x = run(py, || self.0.simulate(&u, &state))?;
        Ok(vec_f64(py, x))
    }
}

#[pyclass(frozen, module = "backlashid._core", name = "GeneralBacklash")]
struct PyGeneralBacklash(core::GeneralBacklash);

#[pymethods]
impl PyGeneralBacklash {
    #[new]
    fn new(
        py: Python<'_>,
        c_left: f64,
        c_right: f64,
        m_left: Vec<f64>,
        m_right: Vec<f64>,
    ) -> PyResult<Self> {
        core::GeneralBacklash::new(c_left, c_right, m_left, m_right)
            .map(Self)
            .map_err(|e| to_py_err(py, e))
    }

    fn left<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = signal(py, "x", &x)?;
        Ok(vec_f64(
            py,
            x.iter().map(|&v| self.0.left().value(v)).collect(),
        ))
    }

    fn right<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = signal(py, "x", &x)?;
        Ok(vec_f64(
            py,
            x.iter().map(|&v| self.0.right().value(v)).collect(),
        ))
    }

    /// form: "eq1" (value comparisons, fast) or "breakpoints" (eq 1 through z_L, z_R of eq 2-3).
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArrayDyn<'py, f64>,
        y0: f64,
        form: &str,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = signal(py, "x", &x)?;
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
        x: PyReadonlyArrayDyn<'py, f64>,
        y0: f64,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray1<f64>>,
    )> {
        let x = signal(py, "x", &x)?;
        let s = run(py, || core::switching_form(&self.0, &x, y0))?;
        Ok((
            vec_f64(py, s.xi1),
            vec_f64(py, s.xi2),
            vec_bool(py, s.f1),
            vec_bool(py, s.f2),
            vec_f64(py, s.y),
        ))
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

type SignalOut<'py> = Bound<'py, PyArray1<f64>>;
type FlagOut<'py> = Bound<'py, PyArray1<bool>>;

#[pyclass(frozen, module = "backlashid._core", name = "CascadeModel")]
struct PyCascadeModel(core::CascadeModel);

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
        u: PyReadonlyArrayDyn<'py, f64>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_prev: f64,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal(py, "u", &u)?;
        let state = core::CascadeState {
            linear: core::LinearState { u_past, x_past },
            y_prev,
        };
        Ok(vec_f64(py, run(py, || self.0.simulate(&u, &state))?))
    }

    /// (x, y, f1, f2, (u_past, x_past, y_prev)) of the record.
    #[allow(clippy::type_complexity)]
    fn simulate_internals<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
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
        let u = signal(py, "u", &u)?;
        let state = core::CascadeState {
            linear: core::LinearState { u_past, x_past },
            y_prev,
        };
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

    /// Samples t >= skip on which the backlash moves (f1 or f2), counted without the flags.
    fn moving_count<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_prev: f64,
        skip: usize,
    ) -> PyResult<usize> {
        let u = signal(py, "u", &u)?;
        let state = core::CascadeState {
            linear: core::LinearState { u_past, x_past },
            y_prev,
        };
        run(py, || self.0.moving_count(&u, &state, skip))
    }
}

#[pyclass(frozen, module = "backlashid._core", name = "SandwichModel")]
struct PySandwichModel(core::SandwichModel);

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
        u: PyReadonlyArrayDyn<'py, f64>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_past: Vec<f64>,
        w_past: Vec<f64>,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal(py, "u", &u)?;
        let state = sandwich_state(u_past, x_past, y_past, w_past);
        Ok(vec_f64(py, run(py, || self.0.simulate(&u, &state))?))
    }

    /// (x, y, w, f1, f2, (u_past, x_past, y_past, w_past)) of the record.
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn simulate_internals<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
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
        let u = signal(py, "u", &u)?;
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

    /// Samples t >= skip on which the backlash moves (f1 or f2), counted without the flags.
    #[allow(clippy::too_many_arguments)]
    fn moving_count<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
        u_past: Vec<f64>,
        x_past: Vec<f64>,
        y_past: Vec<f64>,
        w_past: Vec<f64>,
        skip: usize,
    ) -> PyResult<usize> {
        let u = signal(py, "u", &u)?;
        let state = sandwich_state(u_past, x_past, y_past, w_past);
        run(py, || self.0.moving_count(&u, &state, skip))
    }
}

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

// ---- identification: one call per iteration; Python drives the iterations ----------------

/// An estimate during the iterations: finite numbers, no shape checks.
fn estimate(
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
) -> core::Result<(core::LinearBlock, core::GeneralBacklash)> {
    Ok((
        core::LinearBlock::new(a, b)?,
        core::GeneralBacklash::from_estimate(c_left, c_right, m_left, m_right)?,
    ))
}

type LsOut<'py> = (SignalOut<'py>, f64, Bound<'py, PyArray2<f64>>, f64);

fn ls_out<'py>(py: Python<'py>, ls: core::LeastSquares) -> PyResult<LsOut<'py>> {
    let p = ls.theta.len();
    let cov = ls.unscaled_covariance.into_pyarray(py).reshape([p, p])?;
    Ok((vec_f64(py, ls.theta), ls.rss, cov, ls.rcond))
}

/// min ||A theta - b|| by faer QR: (theta, rss, (A^T A)^-1, rcond).
#[pyfunction]
fn lstsq<'py>(
    py: Python<'py>,
    a: PyReadonlyArrayDyn<'py, f64>,
    b: PyReadonlyArrayDyn<'py, f64>,
    names: Vec<String>,
) -> PyResult<LsOut<'py>> {
    let shape = a.shape().to_vec();
    if shape.len() != 2 {
        return Err(to_py_err(
            py,
            core::Error::Data("A must be a 2-D matrix".into()),
        ));
    }
    let a_vec: Vec<f64> = a.as_array().iter().copied().collect(); // row-major (logical order)
    let b = signal(py, "b", &b)?;
    let ls = run(py, || {
        core::linalg::lstsq::solve(&a_vec, shape[0], shape[1], &b, &names)
    })?;
    ls_out(py, ls)
}

/// One iteration of the cascade algorithm (eq 18-28): internal variables at the current
/// estimate, the regressor rows folded into a streaming QR factor (no N x p matrix), solve.
/// Returns ((theta, rss, cov, rcond), moving_fraction, simulation RMSE of the estimate itself
/// from rest over t >= skip).
#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, u, y, y_switch, skip, names))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn cascade_iteration<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    y: PyReadonlyArrayDyn<'py, f64>,
    y_switch: PyReadonlyArrayDyn<'py, f64>,
    skip: usize,
    names: Vec<String>,
) -> PyResult<(LsOut<'py>, f64, f64)> {
    let (u, y, ys) = (
        signal(py, "u", &u)?,
        signal(py, "y", &y)?,
        signal(py, "y_switch", &y_switch)?,
    );
    let (ls, moving, rmse) = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        let (factor, moving, rmse) =
            core::identify::cascade_iteration(&lin, &bl, &u, &y, &ys, skip)?;
        Ok((
            core::identify::solve_factor(&factor, &names, moving)?,
            moving,
            rmse,
        ))
    })?;
    Ok((ls_out(py, ls)?, moving, rmse))
}

/// One iteration of the sandwich algorithm (eq 33-36), streamed like `cascade_iteration`.
/// Returns ((theta, rss, cov, rcond), moving_fraction).
#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, r, s, u, w, skip, names))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn sandwich_iteration<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    r: Vec<f64>,
    s: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    w: PyReadonlyArrayDyn<'py, f64>,
    skip: usize,
    names: Vec<String>,
) -> PyResult<(LsOut<'py>, f64)> {
    let (u, w) = (signal(py, "u", &u)?, signal(py, "w", &w)?);
    let (ls, moving) = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        let out = core::LinearBlock::new(r, s)?;
        let (factor, moving) = core::identify::sandwich_factor(&lin, &bl, &out, &u, &w, skip)?;
        Ok((
            core::identify::solve_factor(&factor, &names, moving)?,
            moving,
        ))
    })?;
    Ok((ls_out(py, ls)?, moving))
}

/// ARX least squares y(t) = sum a_i u(t-delay+1-i) - sum b_j y(t-j): (theta, rss, cov, rcond).
#[pyfunction]
fn arx<'py>(
    py: Python<'py>,
    u: PyReadonlyArrayDyn<'py, f64>,
    y: PyReadonlyArrayDyn<'py, f64>,
    na: usize,
    nb: usize,
    delay: usize,
    skip: usize,
) -> PyResult<LsOut<'py>> {
    let (u, y) = (signal(py, "u", &u)?, signal(py, "y", &y)?);
    let names: Vec<String> = (1..=na)
        .map(|i| format!("a{i}"))
        .chain((1..=nb).map(|j| format!("b{j}")))
        .collect();
    let ls = run(py, || {
        core::identify::arx_factor(&u, &y, na, nb, delay, skip)?.solve(&names)
    })?;
    ls_out(py, ls)
}

type FactorOut<'py> = (Bound<'py, PyArray2<f64>>, f64);

fn factor_out<'py>(
    py: Python<'py>,
    (factor, cost): (core::TriangularFactor, f64),
) -> PyResult<FactorOut<'py>> {
    let n = factor.cols() + 1;
    let r = factor.r_aug().to_vec().into_pyarray(py).reshape([n, n])?;
    Ok((r, cost))
}

/// The cascade's output-error problem in factored form, streamed (no N x p Jacobian):
/// (R_aug, cost) with R_aug^T R_aug = [J | r]^T [J | r] over t >= warmup, J = dy_sim/dtheta,
/// r = y - y_sim, cost = sum r^2.
#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, u, y, warmup))]
#[allow(clippy::too_many_arguments)]
fn cascade_oe_factor<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    y: PyReadonlyArrayDyn<'py, f64>,
    warmup: usize,
) -> PyResult<FactorOut<'py>> {
    let (u, y) = (signal(py, "u", &u)?, signal(py, "y", &y)?);
    let out = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        core::identify::cascade_oe_factor(&lin, &bl, &u, &y, warmup)
    })?;
    factor_out(py, out)
}

/// The sandwich's output-error problem in factored form, streamed: (R_aug, cost) over
/// t >= warmup with J = dw_sim/dtheta, r = w - w_sim.
#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, r, s, u, w, warmup))]
#[allow(clippy::too_many_arguments)]
fn sandwich_oe_factor<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    r: Vec<f64>,
    s: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    w: PyReadonlyArrayDyn<'py, f64>,
    warmup: usize,
) -> PyResult<FactorOut<'py>> {
    let (u, w) = (signal(py, "u", &u)?, signal(py, "w", &w)?);
    let out = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        let out = core::LinearBlock::new(r, s)?;
        core::identify::sandwich_oe_factor(&lin, &bl, &out, &u, &w, warmup)
    })?;
    factor_out(py, out)
}

/// The output-error gradient of an estimate (cascade when r is empty, else sandwich), one
/// pass without the factor: (J^T r, cost = sum r^2) over t >= warmup.
#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, r, s, u, y, warmup))]
#[allow(clippy::too_many_arguments)]
fn oe_gradient<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    r: Vec<f64>,
    s: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    y: PyReadonlyArrayDyn<'py, f64>,
    warmup: usize,
) -> PyResult<(Bound<'py, PyArray1<f64>>, f64)> {
    let (u, y) = (signal(py, "u", &u)?, signal(py, "y", &y)?);
    let g = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        if r.is_empty() {
            core::identify::cascade_oe_gradient(&lin, &bl, &u, &y, warmup)
        } else {
            let out = core::LinearBlock::new(r, s)?;
            core::identify::sandwich_oe_gradient(&lin, &bl, &out, &u, &y, warmup)
        }
    })?;
    Ok((vec_f64(py, g.gradient), g.cost))
}

/// Free-run output of an estimate (cascade when r is empty, else sandwich), from rest.
/// Largest root modulus of z^n + den[0] z^(n-1) + ... (0 for none, inf if not finite).
#[pyfunction]
fn spectral_radius(den: Vec<f64>) -> f64 {
    core::spectral_radius(&den)
}

#[pyfunction]
#[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, r, s, u))]
#[allow(clippy::too_many_arguments)]
fn simulate_estimate<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    r: Vec<f64>,
    s: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<SignalOut<'py>> {
    let u = signal(py, "u", &u)?;
    let out = run(py, || {
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        if r.is_empty() {
            let m = core::CascadeModel::new(lin, bl);
            m.simulate(&u, &m.rest_state())
        } else {
            let m = core::SandwichModel::new(lin, bl, core::LinearBlock::new(r, s)?);
            m.simulate(&u, &m.rest_state())
        }
    })?;
    Ok(vec_f64(py, out))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLinearBlock>()?;
    m.add_class::<PyGeneralBacklash>()?;
    m.add_class::<PyCascadeModel>()?;
    m.add_class::<PySandwichModel>()?;
    m.add_function(wrap_pyfunction!(lstsq, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_estimate, m)?)?;
    m.add_function(wrap_pyfunction!(arx, m)?)?;
    m.add_function(wrap_pyfunction!(cascade_iteration, m)?)?;
    m.add_function(wrap_pyfunction!(sandwich_iteration, m)?)?;
    m.add_function(wrap_pyfunction!(cascade_oe_factor, m)?)?;
    m.add_function(wrap_pyfunction!(spectral_radius, m)?)?;
    m.add_function(wrap_pyfunction!(sandwich_oe_factor, m)?)?;
    m.add_function(wrap_pyfunction!(oe_gradient, m)?)?;
    m.add_function(wrap_pyfunction!(augmented::simulate_augmented, m)?)?;
    Ok(())
}
