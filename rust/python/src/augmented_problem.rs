//! `_core.AugmentedProblem`: the diagnosis's refit of the nominal cascade with effects of the
//! catalogue, compiled once (structure, effects, the names of the effect parameters the refit
//! frees, and the record, checked on construction; `backlashid_core::AugmentedProblem`). Its
//! methods take only theta (the cascade's parameters, then the free effect parameters) and
//! follow the protocol of the one Levenberg-Marquardt: names, samples, warmup, simulate,
//! cost, oe_factor, gradient, feasible, bounds.

use backlashid_core as core;
use pyo3::prelude::*;

use crate::convert::{
    factor_out, owned_signal, vec_f64, FactorOut, MatrixOut, SignalIn, SignalOut,
};
use crate::errors::run;
use crate::problem::{warmup_of, whole};
use numpy::{IntoPyArray, PyArrayMethods};

/// The nominal cascade (orders na, nb, branch degree) with `effects`, their parameters
/// `free` in theta after the cascade's, on the record (u, y) from rest or held at u[0].
#[pyclass(frozen, name = "AugmentedProblem", module = "backlashid._core")]
pub(crate) struct PyAugmentedProblem {
    inner: core::AugmentedProblem,
}

#[pymethods]
impl PyAugmentedProblem {
    #[new]
    #[pyo3(signature = (
        u, y, na, nb, degree, effects = vec![], free = vec![], *, warmup = None, t0 = 0.0,
        time_scale = core::augmented::TIME_SCALE, held = false, y_prev = 0.0
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        u: SignalIn<'_>,
        y: SignalIn<'_>,
        na: &Bound<'_, PyAny>,
        nb: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        effects: Vec<(String, Vec<f64>)>,
        free: Vec<String>,
        warmup: Option<&Bound<'_, PyAny>>,
        t0: f64,
        time_scale: f64,
        held: bool,
        y_prev: f64,
    ) -> PyResult<Self> {
        let (na, nb, degree) = (
            whole(na, "na", 1)?,
            whole(nb, "nb", 0)?,
            whole(degree, "degree", 1)?,
        );
        let (u, y) = (owned_signal("u", &u)?, owned_signal("y", &y)?);
        let warmup = match warmup {
            Some(w) => warmup_of(w, u.len())?,
            None => 0,
        };
        let start = core::RecordStart {
            held,
            y_prev,
            t0,
            time_scale,
        };
        let inner = run(py, || {
            let s = core::Structure::new(na, nb, degree, 0, 0, false, false)?;
            core::AugmentedProblem::new(s, &effects, &free, u, y, warmup, start)
        })?;
        Ok(Self { inner })
    }

    /// The parameter names: the cascade's, then the free effect parameters'.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names().to_vec()
    }

    /// The number of samples of the record.
    #[getter]
    fn samples(&self) -> usize {
        self.inner.u().len()
    }

    /// The samples at the start left out of every criterion.
    #[getter]
    fn warmup(&self) -> usize {
        self.inner.warmup()
    }

    /// Free-run output at theta (`simulate_augmented` with the problem's start).
    fn simulate<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<SignalOut<'py>> {
        let out = run(py, || self.inner.simulate(&theta))?;
        Ok(vec_f64(py, out))
    }

    /// Sum of squared output errors over t >= warmup.
    fn cost(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<f64> {
        run(py, || self.inner.cost(&theta))
    }

    /// (R_aug, cost) with R_aug^T R_aug = [J | r]^T [J | r] over t >= warmup, streamed.
    fn oe_factor<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<FactorOut<'py>> {
        let out = run(py, || self.inner.oe_factor(&theta))?;
        factor_out(py, out)
    }

    /// (J^T r, cost) over t >= warmup, one pass without the factor.
    fn gradient<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<(SignalOut<'py>, f64)> {
        let g = run(py, || self.inner.gradient(&theta))?;
        Ok((vec_f64(py, g.gradient), g.cost))
    }

    /// (y_sim, J) over the whole record, J = d y_sim / d theta dense (N x p).
    fn sensitivity<'py>(
        &self,
        py: Python<'py>,
        theta: Vec<f64>,
    ) -> PyResult<(SignalOut<'py>, MatrixOut<'py>)> {
        let s = run(py, || self.inner.sensitivity(&theta))?;
        let rows = s.output.len();
        let jac = s.jacobian.into_pyarray(py).reshape([rows, s.cols])?;
        Ok((vec_f64(py, s.output), jac))
    }

    /// The stability guard: the linear block stable, every effect with a free parameter
    /// inside its domain.
    fn feasible(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<bool> {
        run(py, || self.inner.feasible(&theta))
    }

    /// (lower, upper): the cascade's as Problem.bounds (c_L, c_R >= 0), the effects' domains
    /// for theirs.
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.inner.bounds()
    }
}
