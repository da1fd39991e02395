//! `_core.AugmentedProblem`: the diagnosis's refit of the nominal chain (the cascade, or with
//! nr > 0 the sandwich; the input backlash is the sandwich with na = 1, nb = 0) with effects of
//! the catalogue, compiled once (structure, effects, the names of the effect parameters the refit
//! frees, and the record, checked on construction; `backlashid_core::AugmentedProblem`). Its
//! methods take only theta (the chain's parameters, then the free effect parameters) and
//! follow the protocol of the one Levenberg-Marquardt: names, samples, warmup, simulate,
//! cost, oe_factor, gradient, feasible, bounds.

use backlashid_core as core;
use pyo3::prelude::*;

use crate::augmented::{past, rest_y_past};
use crate::convert::{factor_out, kept_signal, vec_f64, FactorOut, MatrixOut, SignalIn, SignalOut};
use crate::errors::run;
use crate::problem::{warmup_of, whole};
use numpy::{IntoPyArray, PyArrayMethods};

/// The nominal chain (orders na, nb, branch degree; nr, ns of a sandwich's output block) with
/// `effects`, their parameters `free` in theta after the chain's, on the record (u, y) from
/// rest, held at u[0], or an explicit state (u_past, x_past, y_past, w_past).
#[pyclass(frozen, name = "AugmentedProblem", module = "backlashid._core")]
pub(crate) struct PyAugmentedProblem {
    inner: core::AugmentedProblem,
}

#[pymethods]
impl PyAugmentedProblem {
    #[new]
    #[pyo3(signature = (
        u, y, na, nb, degree, effects = vec![], free = vec![], *, nr = 0, ns = 0,
        warmup = None, t0 = 0.0, time_scale = core::augmented::TIME_SCALE, held = false,
        y_prev = 0.0, u_past = None, x_past = None, y_past = None, w_past = None
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
        nr: i64,
        ns: i64,
        warmup: Option<&Bound<'_, PyAny>>,
        t0: f64,
        time_scale: f64,
        held: bool,
        y_prev: f64,
        u_past: Option<Vec<f64>>,
        x_past: Option<Vec<f64>>,
        y_past: Option<Vec<f64>>,
        w_past: Option<Vec<f64>>,
    ) -> PyResult<Self> {
        let (na, nb, degree) = (
            whole(na, "na", 1)?,
            whole(nb, "nb", 0)?,
            whole(degree, "degree", 1)?,
        );
        let order = |v: i64, name: &str| {
            usize::try_from(v).map_err(|_| {
                crate::errors::DataError::new_err(format!("{name} = {v}: give a whole number >= 0"))
            })
        };
        let (nr, ns) = (order(nr, "nr")?, order(ns, "ns")?);
        let (u, y) = (kept_signal("u", &u)?, kept_signal("y", &y)?);
        let warmup = match warmup {
            Some(w) => warmup_of(w, u.len())?,
            None => 0,
        };
        let explicit = u_past.is_some() || x_past.is_some() || y_past.is_some() || w_past.is_some();
        let inner = run(py, || {
            if nr == 0 && (ns > 0 || y_past.is_some() || w_past.is_some()) {
                return Err(core::Error::Data(
                    "ns, y_past and w_past are the sandwich's output block's: give nr >= 1 \
                     (nr = 0 is the cascade)"
                        .into(),
                ));
            }
            let s = core::Structure::new(na, nb, degree, nr, ns, false, false)?;
            let past = if explicit {
                Some(core::Past {
                    u_past: past("u_past", u_past, na, || vec![0.0; na])?,
                    x_past: past("x_past", x_past, nb, || vec![0.0; nb])?,
                    y_past: past("y_past", y_past, nr, || rest_y_past(nr, y_prev))?,
                    w_past: past("w_past", w_past, ns, || vec![0.0; ns])?,
                })
            } else {
                None
            };
            let start = core::RecordStart {
                held,
                past,
                y_prev,
                t0,
                time_scale,
            };
            core::AugmentedProblem::new(s, &effects, &free, u, y, warmup, start)
        })?;
        Ok(Self { inner })
    }

    /// The parameter names: the chain's, then the free effect parameters'.
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

    /// The stability guard: the linear blocks stable, every effect with a free parameter
    /// inside its domain.
    fn feasible(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<bool> {
        run(py, || self.inner.feasible(&theta))
    }

    /// (lower, upper): the chain's as Problem.bounds (c_L, c_R >= 0), the effects' domains
    /// for theirs.
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.inner.bounds()
    }
}
