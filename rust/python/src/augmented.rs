//! Binding of the core's augmented cascade (`backlashid_core::augmented`): the nominal
//! cascade with effects of the diagnosis catalogue, each given as (name, parameters) and built
//! by the core's effect registry (`backlashid_core::effects`). Converts arguments, releases
//! the GIL.

use backlashid_core as core;
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;

use crate::identify::estimate_fn;
use crate::{run, signal, vec_f64, SignalOut};

estimate_fn! {
    /// Output of the augmented cascade (an estimate: no branch-shape checks) for `u`, with
    /// `effects` a sequence of (name, parameters) in the catalogue's parameter order, from the
    /// state (u_past of the effective input, x_past, y_prev; empty pasts mean rest).
    #[pyfunction]
    #[pyo3(signature = (
        a, b, c_left, c_right, m_left, m_right, u, *, effects = vec![], t0 = 0.0,
        time_scale = core::augmented::TIME_SCALE, u_past = None, x_past = None, y_prev = 0.0
    ))]
    pub(crate) fn simulate_augmented<'py>(
        est,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
        effects: Vec<(String, Vec<f64>)>,
        t0: f64,
        time_scale: f64,
        u_past: Option<Vec<f64>>,
        x_past: Option<Vec<f64>>,
        y_prev: f64,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let out = run(py, || {
            let effects = effects
                .iter()
                .map(|(name, p)| core::effects::from_parameters(name, p))
                .collect::<core::Result<Vec<_>>>()?;
            let (na, nb) = (est.linear.0.len(), est.linear.1.len());
            let (lin, bl) = est.blocks()?;
            let model = core::CascadeModel::new(lin, bl);
            let state = core::CascadeState {
                linear: core::LinearState {
                    u_past: u_past.unwrap_or_else(|| vec![0.0; na]),
                    x_past: x_past.unwrap_or_else(|| vec![0.0; nb]),
                },
                y_prev,
            };
            core::simulate_augmented(&model, &effects, &u, t0, time_scale, &state)
        })?;
        Ok(vec_f64(py, out))
    }
}
