//! Prediction bands: the simulated output of an estimate and its first-order variance under
//! a parameter covariance (`backlashid_core::identify::bands`), from rest or a given state.

use backlashid_core as core;
use pyo3::prelude::*;

use crate::convert::{matrix, signal, vec_f64, SignalIn, SignalOut};
use crate::errors::run;
use crate::identify::estimate_fn;

/// The covariance as a p x p row-major matrix (shape checked by the core against p).
fn covariance(cov: &SignalIn<'_>) -> PyResult<Vec<f64>> {
    let (values, rows, cols) = matrix("covariance", cov)?;
    if rows != cols {
        return Err(crate::errors::DataError::new_err(format!(
            "covariance is {rows} x {cols}: give a square matrix in theta's layout"
        )));
    }
    Ok(values)
}

/// A sandwich state as the Python layer passes it: (u_past, x_past, y_past, w_past).
type SandwichPasts = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

estimate_fn! {
    /// (y_hat, var(y_hat)) of the cascade estimate (no branch-shape checks) for `u`, the
    /// variance J_t Sigma J_t^T with Sigma = `covariance` in theta's layout, from `state` =
    /// (u_past, x_past, y_prev) or rest (None).
    #[pyfunction]
    #[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, u, covariance, state = None))]
    pub(crate) fn cascade_output_variance<'py>(
        est,
        py: Python<'py>,
        u: SignalIn<'py>,
        covariance: SignalIn<'py>,
        state: Option<(Vec<f64>, Vec<f64>, f64)>,
    ) -> PyResult<(SignalOut<'py>, SignalOut<'py>)> {
        let u = signal("u", &u)?;
        let cov = self::covariance(&covariance)?;
        let state = state.map(|(u_past, x_past, y_prev)| core::CascadeState {
            linear: core::LinearState { u_past, x_past },
            y_prev,
        });
        let out = run(py, || {
            let (lin, bl) = est.blocks()?;
            core::identify::cascade_output_variance(&lin, &bl, state.as_ref(), &u, &cov)
        })?;
        Ok((vec_f64(py, out.output), vec_f64(py, out.variance)))
    }
}

estimate_fn! {
    /// (w_hat, var(w_hat)) of the sandwich estimate (no branch-shape checks; output block
    /// r, s with r_1 included) for `u`, as `cascade_output_variance`, from `state` =
    /// (u_past, x_past, y_past, w_past) or rest (None).
    #[pyfunction]
    #[pyo3(signature = (a, b, c_left, c_right, m_left, m_right, r, s, u, covariance, state = None))]
    pub(crate) fn sandwich_output_variance<'py>(
        est,
        py: Python<'py>,
        r: Vec<f64>,
        s: Vec<f64>,
        u: SignalIn<'py>,
        covariance: SignalIn<'py>,
        state: Option<SandwichPasts>,
    ) -> PyResult<(SignalOut<'py>, SignalOut<'py>)> {
        let u = signal("u", &u)?;
        let cov = self::covariance(&covariance)?;
        let state = state.map(|(u_past, x_past, y_past, w_past)| core::SandwichState {
            input: core::LinearState { u_past, x_past },
            output: core::LinearState {
                u_past: y_past,
                x_past: w_past,
            },
        });
        let out = run(py, || {
            let (lin, bl) = est.blocks()?;
            let output = core::LinearBlock::new(r, s)?;
            core::identify::sandwich_output_variance(&lin, &bl, &output, state.as_ref(), &u, &cov)
        })?;
        Ok((vec_f64(py, out.output), vec_f64(py, out.variance)))
    }
}

/// Adds the prediction-band functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(cascade_output_variance, m)?)?;
    m.add_function(wrap_pyfunction!(sandwich_output_variance, m)?)?;
    Ok(())
}
