//! Binding of the core's augmented cascade (`backlashid_core::augmented`): the nominal
//! cascade with the diagnosis catalogue's effects. Converts arguments, releases the GIL.

use backlashid_core as core;
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;

use crate::{estimate, run, signal, vec_f64, SignalOut};

/// Output of the augmented cascade (an estimate: no branch-shape checks) for `u`, from the
/// state (u_past of the effective input, x_past, y_prev; empty pasts mean rest).
#[pyfunction]
#[pyo3(signature = (
    a, b, c_left, c_right, m_left, m_right, u, *, t0 = 0.0, time_scale = 1000.0, delay = 0,
    sat_lo = f64::NEG_INFINITY, sat_hi = f64::INFINITY, f_c = 0.0, f_v = 0.0, drift_left = 0.0,
    drift_right = 0.0, compliance = 0.0, omega = 0.5, zeta = 0.1, play_r = vec![],
    play_w = vec![], offset = 0.0, offset_rate = 0.0, quantum = 0.0, u_past = None,
    x_past = None, y_prev = 0.0
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate_augmented<'py>(
    py: Python<'py>,
    a: Vec<f64>,
    b: Vec<f64>,
    c_left: f64,
    c_right: f64,
    m_left: Vec<f64>,
    m_right: Vec<f64>,
    u: PyReadonlyArrayDyn<'py, f64>,
    t0: f64,
    time_scale: f64,
    delay: usize,
    sat_lo: f64,
    sat_hi: f64,
    f_c: f64,
    f_v: f64,
    drift_left: f64,
    drift_right: f64,
    compliance: f64,
    omega: f64,
    zeta: f64,
    play_r: Vec<f64>,
    play_w: Vec<f64>,
    offset: f64,
    offset_rate: f64,
    quantum: f64,
    u_past: Option<Vec<f64>>,
    x_past: Option<Vec<f64>>,
    y_prev: f64,
) -> PyResult<SignalOut<'py>> {
    let u = signal(py, "u", &u)?;
    let out = run(py, || {
        if play_r.len() != play_w.len() {
            return Err(core::Error::Model(format!(
                "{} play half-widths but {} weights: give one weight per play",
                play_r.len(),
                play_w.len()
            )));
        }
        let (na, nb) = (a.len(), b.len());
        let (lin, bl) = estimate(a, b, c_left, c_right, m_left, m_right)?;
        let model = core::CascadeModel::new(lin, bl);
        let state = core::CascadeState {
            linear: core::LinearState {
                u_past: u_past.unwrap_or_else(|| vec![0.0; na]),
                x_past: x_past.unwrap_or_else(|| vec![0.0; nb]),
            },
            y_prev,
        };
        let effects = core::Effects {
            delay,
            saturation: (sat_lo, sat_hi),
            friction: (f_c, f_v),
            width_drift: (drift_left, drift_right),
            compliance: (compliance, omega, zeta),
            plays: play_r.into_iter().zip(play_w).collect(),
            offset: (offset, offset_rate),
            quantum,
            time_scale,
        };
        core::simulate_augmented(&model, &effects, &u, t0, &state)
    })?;
    Ok(vec_f64(py, out))
}
