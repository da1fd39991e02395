//! Binding of the core's augmented chain (`backlashid_core::augmented`): the nominal cascade,
//! or the sandwich with its output block (r, s), with effects of the diagnosis catalogue, each
//! given as (name, parameters) and built by the core's effect registry
//! (`backlashid_core::effects`), from any start. Converts arguments, releases the GIL.

use backlashid_core as core;
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;

use crate::identify::estimate_fn;
use crate::{run, signal, vec_f64, SignalOut};

/// A past of `n` values named `name` (most recent first; `default` where not given): the
/// right length and finite, else a DataError naming it.
pub(crate) fn past(
    name: &str,
    given: Option<Vec<f64>>,
    n: usize,
    default: impl FnOnce() -> Vec<f64>,
) -> core::Result<Vec<f64>> {
    let Some(v) = given else {
        return Ok(default());
    };
    if v.len() != n {
        return Err(core::Error::Data(format!(
            "{name} has {} values but the block needs {n} (its order): give the most recent \
             value first",
            v.len()
        )));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(core::Error::Data(format!(
            "{name} holds {x}: give finite past values"
        )));
    }
    Ok(v)
}

/// The sandwich's output block's past inputs at rest but for the newest, the backlash
/// memory y(0) (`nr` values).
pub(crate) fn rest_y_past(nr: usize, y_prev: f64) -> Vec<f64> {
    let mut v = vec![0.0; nr];
    if let Some(first) = v.first_mut() {
        *first = y_prev;
    }
    v
}

estimate_fn! {
    /// Output of the augmented chain (an estimate: no branch-shape checks) for `u`, with
    /// `effects` a sequence of (name, parameters) in the catalogue's parameter order: the
    /// cascade, or with `r`, `s` the sandwich whose output block (eq 29) follows the load. From
    /// the state u_past of the effective input, x_past, y_prev and for the sandwich y_past
    /// (the output block's past inputs, y_past[0] = y_prev; default [y_prev, 0, ..]) and
    /// w_past; pasts not given are at rest.
    #[pyfunction]
    #[pyo3(signature = (
        a, b, c_left, c_right, m_left, m_right, u, *, r = None, s = None, effects = vec![],
        t0 = 0.0, time_scale = core::augmented::TIME_SCALE, y_prev = 0.0, u_past = None,
        x_past = None, y_past = None, w_past = None
    ))]
    pub(crate) fn simulate_augmented<'py>(
        est,
        py: Python<'py>,
        u: PyReadonlyArrayDyn<'py, f64>,
        r: Option<Vec<f64>>,
        s: Option<Vec<f64>>,
        effects: Vec<(String, Vec<f64>)>,
        t0: f64,
        time_scale: f64,
        y_prev: f64,
        u_past: Option<Vec<f64>>,
        x_past: Option<Vec<f64>>,
        y_past: Option<Vec<f64>>,
        w_past: Option<Vec<f64>>,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let out = run(py, || {
            let effects = effects
                .iter()
                .map(|(name, p)| core::effects::from_parameters(name, p))
                .collect::<core::Result<Vec<_>>>()?;
            let (na, nb) = (est.linear.0.len(), est.linear.1.len());
            let (lin, bl) = est.blocks()?;
            let linear = core::LinearState {
                u_past: past("u_past", u_past, na, || vec![0.0; na])?,
                x_past: past("x_past", x_past, nb, || vec![0.0; nb])?,
            };
            let (output, output_state) = match r {
                Some(r) => {
                    if r.is_empty() {
                        return Err(core::Error::Data(
                            "r is empty: give the output block's r_1..r_nr (r_1 = 1 as the \
                             paper normalises it)"
                                .into(),
                        ));
                    }
                    let s = s.unwrap_or_default();
                    let (nr, ns) = (r.len(), s.len());
                    let state = core::LinearState {
                        u_past: past("y_past", y_past, nr, || rest_y_past(nr, y_prev))?,
                        x_past: past("w_past", w_past, ns, || vec![0.0; ns])?,
                    };
                    (Some(core::LinearBlock::new(r, s)?), Some(state))
                }
                None => {
                    if s.is_some() || y_past.is_some() || w_past.is_some() {
                        return Err(core::Error::Data(
                            "s, y_past and w_past are the sandwich's output block's: give r \
                             too (none for a cascade)"
                                .into(),
                        ));
                    }
                    (None, None)
                }
            };
            let chain = core::AugmentedChain {
                cascade: core::CascadeModel::new(lin, bl),
                output,
            };
            let state = core::AugmentedState {
                cascade: core::CascadeState { linear, y_prev },
                output: output_state,
            };
            core::simulate_augmented_chain(&chain, &effects, &u, t0, time_scale, &state)
        })?;
        Ok(vec_f64(py, out))
    }
}
