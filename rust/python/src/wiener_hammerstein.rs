//! `_core.WienerHammersteinProblem`: the Wiener-Hammerstein problem compiled once (structure,
//! scale k and record checked on construction); its methods take only theta, the protocol
//! of the one Levenberg-Marquardt (`backlashid.identify.levenberg_marquardt`).

use backlashid_core as core;
use pyo3::prelude::*;

use crate::convert::{factor_out, kept_signal, vec_f64, FactorOut, SignalIn, SignalOut};
use crate::errors::run;
use crate::problem::{warmup_of, whole};

/// u -> G1 -> x -> f(x) = sum c_i (T_i(x / k) - T_i(0)) -> G2 -> + offset -> y, with the
/// record (u, y, warm-up). Rust owns the layout of theta and its names; `fixed` (name,
/// value) pairs are held at their values and left out of theta.
#[pyclass(frozen, name = "WienerHammersteinProblem", module = "backlashid._core")]
pub(crate) struct PyWienerHammersteinProblem {
    inner: core::WienerHammersteinProblem,
}

#[pymethods]
impl PyWienerHammersteinProblem {
    #[new]
    #[pyo3(signature = (u, y, nb, ns, degree, k=1.0, feedthrough=false, output_feedthrough=false, offset=true, warmup=None, fixed=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        u: SignalIn<'_>,
        y: SignalIn<'_>,
        nb: &Bound<'_, PyAny>,
        ns: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        k: f64,
        feedthrough: bool,
        output_feedthrough: bool,
        offset: bool,
        warmup: Option<&Bound<'_, PyAny>>,
        fixed: Option<Vec<(String, f64)>>,
    ) -> PyResult<Self> {
        let s = core::WhStructure::new(
            whole(nb, "nb", 1)?,
            whole(ns, "ns", 1)?,
            whole(degree, "degree", 1)?,
            feedthrough,
            output_feedthrough,
            offset,
        )
        .map_err(|e| PyErr::from(crate::errors::CoreError(e)))?;
        let (u, y) = (kept_signal("u", &u)?, kept_signal("y", &y)?);
        let warmup = match warmup {
            Some(w) => warmup_of(w, u.len())?,
            None => 0,
        };
        let fixed = fixed.unwrap_or_default();
        let inner = run(py, || {
            core::WienerHammersteinProblem::new(s, k, u, y, warmup)?.with_fixed(&fixed)
        })?;
        Ok(Self { inner })
    }

    /// The parameter names, in the order of theta.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names()
    }

    /// The number of samples of the record.
    #[getter]
    fn samples(&self) -> usize {
        self.inner.samples()
    }

    /// The samples at the start left out of every criterion.
    #[getter]
    fn warmup(&self) -> usize {
        self.inner.warmup()
    }

    /// The scale of x the Chebyshev basis is centred on.
    #[getter]
    fn k(&self) -> f64 {
        self.inner.k()
    }

    /// Free-run output of theta from rest.
    fn simulate<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<SignalOut<'py>> {
        let out = run(py, || self.inner.simulate(&theta))?;
        Ok(vec_f64(py, out))
    }

    /// The internal signal x = G1 u from rest.
    fn internal<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<SignalOut<'py>> {
        let out = run(py, || self.inner.internal(&theta))?;
        Ok(vec_f64(py, out))
    }

    /// sum (y - y_sim)^2 over t >= warmup.
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

    /// The stability guard: every pole of G1 and G2 of modulus below 0.9999.
    fn feasible(&self, theta: Vec<f64>) -> PyResult<bool> {
        self.inner
            .feasible(&theta)
            .map_err(|e| crate::errors::CoreError(e).into())
    }

    /// (lower, upper) bounds of theta: every parameter free (+-inf).
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.inner.bounds()
    }
}
