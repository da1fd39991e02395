//! `_core.Problem`: an identification problem compiled once (the structure and the record,
//! checked on construction), whose methods take only a parameter vector theta. The
//! identification's iterations and output-error refinement call it once per step or trial
//! instead of passing the record again (pydantic-core's compile-once `SchemaValidator` is
//! the pattern).

use backlashid_core as core;
use pyo3::prelude::*;
use pyo3::types::PyBool;

use crate::convert::{
    factor_out, kept_signal, ls_out, vec_f64, FactorOut, LsOut, SignalIn, SignalOut,
};
use crate::errors::{run, DataError};

/// A whole number >= `least` (an order, a degree, a warm-up), else a DataError with the
/// message of `_validation.check_whole`.
pub(crate) fn whole(value: &Bound<'_, PyAny>, name: &str, least: usize) -> PyResult<usize> {
    let bad = || {
        let text = value
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_else(|_| "?".into());
        DataError::new_err(format!("{name} = {text}: give a whole number >= {least}"))
    };
    if value.is_instance_of::<PyBool>() {
        return Err(bad());
    }
    match value.extract::<i64>() {
        Ok(v) if v >= least as i64 => Ok(v as usize),
        _ => Err(bad()),
    }
}

/// The warm-up: a whole number >= 0, with `_validation.check_warmup`'s message (the core
/// checks warmup < n after the signals).
pub(crate) fn warmup_of(value: &Bound<'_, PyAny>, n: usize) -> PyResult<usize> {
    let ok = !value.is_instance_of::<PyBool>();
    match value.extract::<i64>() {
        Ok(v) if ok && v >= 0 => Ok(v as usize),
        _ => {
            let text = value
                .repr()
                .map(|r| r.to_string())
                .unwrap_or_else(|_| "?".into());
            Err(DataError::new_err(format!(
                "warmup = {text}: give a whole number of samples, 0 <= warmup < {n} (the record \
                 length)"
            )))
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn structure(
    na: &Bound<'_, PyAny>,
    nb: &Bound<'_, PyAny>,
    degree: &Bound<'_, PyAny>,
    nr: &Bound<'_, PyAny>,
    ns: &Bound<'_, PyAny>,
    feedthrough: bool,
    output_feedthrough: bool,
) -> PyResult<core::Structure> {
    let s = core::Structure::new(
        whole(na, "na", 1)?,
        whole(nb, "nb", 0)?,
        whole(degree, "degree", 1)?,
        whole(nr, "nr", 0)?,
        whole(ns, "ns", 0)?,
        feedthrough,
        output_feedthrough,
    );
    s.map_err(|e| crate::errors::CoreError(e).into())
}

/// An identification problem: the structure (orders, degree, feedthroughs) and the record
/// (u, y, warm-up), checked once. Rust owns the layout of theta and its names; with
/// `initial_state`, theta ends with the record's initial state x0_1..x0_n, y_prev (and the
/// sandwich's w0_1..w0_m), see the core's `identify::initial`.
#[pyclass(frozen, name = "Problem", module = "backlashid._core")]
pub(crate) struct PyProblem {
    inner: core::Problem,
}

#[pymethods]
impl PyProblem {
    #[new]
    #[pyo3(signature = (u, y, na, nb, degree, nr, ns, feedthrough=false, output_feedthrough=false, warmup=None, initial_state=false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        u: SignalIn<'_>,
        y: SignalIn<'_>,
        na: &Bound<'_, PyAny>,
        nb: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        nr: &Bound<'_, PyAny>,
        ns: &Bound<'_, PyAny>,
        feedthrough: bool,
        output_feedthrough: bool,
        warmup: Option<&Bound<'_, PyAny>>,
        initial_state: bool,
    ) -> PyResult<Self> {
        let s = structure(na, nb, degree, nr, ns, feedthrough, output_feedthrough)?
            .with_initial_state(initial_state);
        let (u, y) = (kept_signal("u", &u)?, kept_signal("y", &y)?);
        let warmup = match warmup {
            Some(w) => warmup_of(w, u.len())?,
            None => 0,
        };
        let inner = run(py, || core::Problem::new(s, u, y, warmup))?;
        Ok(Self { inner })
    }

    /// Several records of one system: `u` and `y` lists of 1-D signals (record i is
    /// (u[i], y[i])), the warm-up applied to each. Theta is the model's parameters, then
    /// with `initial_state` one initial-state block per record (names suffixed @1, @2, ...);
    /// the criteria sum over the records and `simulate` concatenates their outputs. One
    /// record is the plain problem, bit for bit.
    #[staticmethod]
    #[pyo3(signature = (u, y, na, nb, degree, nr, ns, feedthrough=false, output_feedthrough=false, warmup=None, initial_state=false))]
    #[allow(clippy::too_many_arguments)]
    fn from_records(
        py: Python<'_>,
        u: Vec<SignalIn<'_>>,
        y: Vec<SignalIn<'_>>,
        na: &Bound<'_, PyAny>,
        nb: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        nr: &Bound<'_, PyAny>,
        ns: &Bound<'_, PyAny>,
        feedthrough: bool,
        output_feedthrough: bool,
        warmup: Option<&Bound<'_, PyAny>>,
        initial_state: bool,
    ) -> PyResult<Self> {
        let s = structure(na, nb, degree, nr, ns, feedthrough, output_feedthrough)?
            .with_initial_state(initial_state);
        if u.len() != y.len() {
            return Err(DataError::new_err(format!(
                "u has {} records but y has {}: give one output per input record",
                u.len(),
                y.len()
            )));
        }
        let shortest = u.iter().map(|a| a.len().unwrap_or(0)).min().unwrap_or(0);
        let warmup = match warmup {
            Some(w) => warmup_of(w, shortest)?,
            None => 0,
        };
        let mut records = Vec::with_capacity(u.len());
        for (i, (ui, yi)) in u.iter().zip(&y).enumerate() {
            let ui = kept_signal(&format!("u[{i}]"), ui)?;
            let yi = kept_signal(&format!("y[{i}]"), yi)?;
            records.push((ui, yi, warmup));
        }
        let inner = run(py, || core::Problem::several(s, records))?;
        Ok(Self { inner })
    }

    /// The parameter names of a structure, in the order of theta (no record needed); with
    /// `least_squares`, those of the least-squares vector of eq (19) / (31) (which has no
    /// initial state); with `initial_state`, theta's trailing x0_k, y_prev, w0_k.
    #[staticmethod]
    #[pyo3(signature = (na, nb, degree, nr, ns, feedthrough=false, output_feedthrough=false, least_squares=false, initial_state=false))]
    #[allow(clippy::too_many_arguments)]
    fn layout(
        na: &Bound<'_, PyAny>,
        nb: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        nr: &Bound<'_, PyAny>,
        ns: &Bound<'_, PyAny>,
        feedthrough: bool,
        output_feedthrough: bool,
        least_squares: bool,
        initial_state: bool,
    ) -> PyResult<Vec<String>> {
        let s = structure(na, nb, degree, nr, ns, feedthrough, output_feedthrough)?
            .with_initial_state(initial_state);
        Ok(if least_squares {
            s.ls_names()
        } else {
            s.names()
        })
    }

    /// Where each block of parameters sits in theta: name -> (start, stop), in theta's order
    /// (a, b, c_L, m_L, m_R1, c_R, m_R, r, s, x0, y_prev, w0; a block the structure lacks is
    /// empty), so that the Python layer reads the layout instead of rebuilding it.
    #[staticmethod]
    #[pyo3(signature = (na, nb, degree, nr, ns, feedthrough=false, output_feedthrough=false, initial_state=false))]
    #[allow(clippy::too_many_arguments)]
    fn blocks(
        na: &Bound<'_, PyAny>,
        nb: &Bound<'_, PyAny>,
        degree: &Bound<'_, PyAny>,
        nr: &Bound<'_, PyAny>,
        ns: &Bound<'_, PyAny>,
        feedthrough: bool,
        output_feedthrough: bool,
        initial_state: bool,
    ) -> PyResult<Vec<(&'static str, (usize, usize))>> {
        let s = structure(na, nb, degree, nr, ns, feedthrough, output_feedthrough)?
            .with_initial_state(initial_state);
        Ok(s.blocks()
            .into_iter()
            .map(|(name, r)| (name, (r.start, r.end)))
            .collect())
    }

    /// The parameter names, in the order of theta.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.inner.names()
    }

    /// Whether theta ends with the record's initial state (False: from rest).
    #[getter]
    fn initial_state(&self) -> bool {
        self.inner.structure().initial_state
    }

    /// The names of the least-squares vector of eq (19) / (31) (c_1, c_2 for c_L, c_R).
    #[getter]
    fn ls_names(&self) -> Vec<String> {
        self.inner.structure().ls_names()
    }

    /// The number of samples of the record (of all records).
    #[getter]
    fn samples(&self) -> usize {
        self.inner.samples()
    }

    /// The samples at the start left out of every criterion (several records: the
    /// records' warm-ups summed, so that samples - warmup counts the residuals).
    #[getter]
    fn warmup(&self) -> usize {
        self.inner.total_warmup()
    }

    /// The number of records (1 for the plain constructor).
    #[getter]
    fn records(&self) -> usize {
        self.inner.records().len()
    }

    /// The samples of each record, in order (how `simulate`'s output splits).
    #[getter]
    fn lengths(&self) -> Vec<usize> {
        self.inner.records().iter().map(|r| r.u.len()).collect()
    }

    /// Free-run output of the estimate theta, from rest or from theta's initial state
    /// (several records: their outputs concatenated, split by `lengths`).
    fn simulate<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<SignalOut<'py>> {
        let out = run(py, || self.inner.simulate(&theta))?;
        Ok(vec_f64(py, out))
    }

    /// The output-error cost at theta: sum (y - y_sim)^2 over t >= warmup (ModelError where the
    /// simulation diverges).
    fn cost(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<f64> {
        run(py, || self.inner.cost(&theta))
    }

    /// The stability guard: every linear block of theta stable (poles inside the unit circle).
    fn feasible(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<bool> {
        run(py, || self.inner.feasible(&theta))
    }

    /// The box of theta as (lower, upper): c_L, c_R >= 0, every other parameter free.
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.inner.bounds()
    }

    /// One iteration of the paper's algorithm at theta (cascade eq 18-28, sandwich eq
    /// 33-36): ((theta_ls, rss, cov, rcond), moving_fraction, rmse), rmse the estimate's own
    /// simulation RMSE (cascade) or None (sandwich). From rest: theta's initial state, if
    /// any, is ignored (theta may also be given without it).
    #[pyo3(signature = (theta, simulated_switching=false))]
    fn iteration<'py>(
        &self,
        py: Python<'py>,
        theta: Vec<f64>,
        simulated_switching: bool,
    ) -> PyResult<(LsOut<'py>, f64, Option<f64>)> {
        let it = run(py, || self.inner.iteration(&theta, simulated_switching))?;
        Ok((ls_out(py, it.ls)?, it.moving_fraction, it.rmse))
    }

    /// The output-error problem at theta, streamed: (R_aug, cost) with R_aug^T R_aug =
    /// [J | r]^T [J | r] over t >= warmup, r = y - y_sim.
    fn oe_factor<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<FactorOut<'py>> {
        let out = run(py, || self.inner.oe_factor(&theta))?;
        factor_out(py, out)
    }

    /// The record's motion at theta over t >= warmup, on the simulation of `simulate`:
    /// (samples that move the backlash, min x, max x), x the input linear block's output.
    /// Taken from the last gradient pass (two-thread cascade passes) or motion call when it
    /// ran at this very theta, else one simulation. One record only (DataError otherwise).
    fn motion(&self, py: Python<'_>, theta: Vec<f64>) -> PyResult<(usize, f64, f64)> {
        let m = run(py, || self.inner.motion(&theta))?;
        Ok((m.moving, m.x_min, m.x_max))
    }

    /// The output-error gradient at theta: (J^T r, cost = sum r^2) over t >= warmup.
    fn gradient<'py>(&self, py: Python<'py>, theta: Vec<f64>) -> PyResult<(SignalOut<'py>, f64)> {
        let g = run(py, || self.inner.gradient(&theta))?;
        Ok((vec_f64(py, g.gradient), g.cost))
    }
}
