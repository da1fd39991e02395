//! The identification functions of `backlashid._core` that need no record compiled into a
//! `Problem` (`problem.rs` has the iterations, the output-error factor and gradient and the
//! free run of an estimate): least squares, the ARX start, the spectral radius, and the
//! `estimate_fn!` macro by which the effect binding takes an estimate as the paper's
//! parameters (a, b, c_left, c_right, m_left, m_right).

use backlashid_core as core;
use pyo3::prelude::*;

use crate::convert::{ls_out, matrix, signal, LsOut, SignalIn};
use crate::errors::run;

/// An estimate during the iterations: the linear block's (a, b) and the backlash's
/// (c_left, c_right, m_left, m_right), as `estimate_fn!` receives them.
pub(crate) struct Estimate {
    pub(crate) linear: (Vec<f64>, Vec<f64>),
    pub(crate) backlash: (f64, f64, Vec<f64>, Vec<f64>),
}

impl Estimate {
    /// The blocks: finite numbers, no branch-shape checks (`GeneralBacklash::from_estimate`).
    pub(crate) fn blocks(self) -> core::Result<(core::LinearBlock, core::GeneralBacklash)> {
        let ((a, b), (c_left, c_right, m_left, m_right)) = (self.linear, self.backlash);
        Ok((
            core::LinearBlock::new(a, b)?,
            core::GeneralBacklash::from_estimate(c_left, c_right, m_left, m_right)?,
        ))
    }
}

/// A function whose first arguments are an estimate's parameters a, b, c_left, c_right,
/// m_left, m_right (the order every `_core` function takes them in), handed to the body as
/// one `Estimate` named by the first identifier; the other arguments follow. The attributes
/// (`#[pyfunction]`, `#[pyo3(signature = ...)]`, docs) apply to the function.
macro_rules! estimate_fn {
    (
        $(#[$attr:meta])*
        $vis:vis fn $name:ident $(<$lt:lifetime>)? ($est:ident $(, $arg:ident: $ty:ty)* $(,)?)
            -> $ret:ty $body:block
    ) => {
        $(#[$attr])*
        #[allow(clippy::too_many_arguments)]
        $vis fn $name $(<$lt>)? (
            a: Vec<f64>, b: Vec<f64>, c_left: f64, c_right: f64, m_left: Vec<f64>, m_right: Vec<f64>,
            $($arg: $ty),*
        ) -> $ret {
            let $est = $crate::identify::Estimate {
                linear: (a, b),
                backlash: (c_left, c_right, m_left, m_right),
            };
            $body
        }
    };
}
pub(crate) use estimate_fn; // the effect binding's simulate_augmented takes an estimate too

/// min ||A theta - b|| by faer QR: (theta, rss, (A^T A)^-1, rcond).
#[pyfunction]
fn lstsq<'py>(
    py: Python<'py>,
    a: SignalIn<'py>,
    b: SignalIn<'py>,
    names: Vec<String>,
) -> PyResult<LsOut<'py>> {
    let (a, rows, cols) = matrix("A", &a)?; // row-major (logical order)
    let b = signal("b", &b)?;
    let ls = run(py, || {
        core::linalg::lstsq::solve(&a, rows, cols, &b, &names)
    })?;
    ls_out(py, ls)
}

/// ARX least squares y(t) = sum a_i u(t-delay+1-i) - sum b_j y(t-j): (theta, rss, cov, rcond).
#[pyfunction]
fn arx<'py>(
    py: Python<'py>,
    u: SignalIn<'py>,
    y: SignalIn<'py>,
    na: usize,
    nb: usize,
    delay: usize,
    warmup: usize,
) -> PyResult<LsOut<'py>> {
    let (u, y) = (signal("u", &u)?, signal("y", &y)?);
    let names: Vec<String> = (1..=na)
        .map(|i| format!("a{i}"))
        .chain((1..=nb).map(|j| format!("b{j}")))
        .collect();
    let ls = run(py, || {
        core::ArxRegression::new(&u, &y, na, nb, delay)?
            .factor(warmup)
            .solve(&names)
    })?;
    ls_out(py, ls)
}

/// ARX least squares over several records (u[i], y[i]), their rows stacked in one problem,
/// each record's lags starting from zero at its own start: (theta, rss, cov, rcond).
#[pyfunction]
fn arx_records<'py>(
    py: Python<'py>,
    u: Vec<SignalIn<'py>>,
    y: Vec<SignalIn<'py>>,
    na: usize,
    nb: usize,
    delay: usize,
    warmup: usize,
) -> PyResult<LsOut<'py>> {
    if u.len() != y.len() || u.is_empty() {
        return Err(crate::errors::DataError::new_err(format!(
            "u has {} records but y has {}: give one output per input record (at least one)",
            u.len(),
            y.len()
        )));
    }
    let mut signals = Vec::with_capacity(u.len());
    for (i, (ui, yi)) in u.iter().zip(&y).enumerate() {
        signals.push((
            signal(&format!("u[{i}]"), ui)?,
            signal(&format!("y[{i}]"), yi)?,
        ));
    }
    let names: Vec<String> = (1..=na)
        .map(|i| format!("a{i}"))
        .chain((1..=nb).map(|j| format!("b{j}")))
        .collect();
    let ls = run(py, || {
        let mut joint = core::TriangularFactor::new(na + nb);
        for (ui, yi) in &signals {
            joint.merge(&core::ArxRegression::new(ui, yi, na, nb, delay)?.factor(warmup))?;
        }
        joint.solve(&names)
    })?;
    ls_out(py, ls)
}

/// Largest root modulus of z^n + den[0] z^(n-1) + ... (0 for none, inf if not finite).
#[pyfunction]
fn spectral_radius(den: Vec<f64>) -> f64 {
    core::spectral_radius(&den)
}

/// Adds the identification functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(lstsq, m)?)?;
    m.add_function(wrap_pyfunction!(arx_records, m)?)?;
    m.add_function(wrap_pyfunction!(arx, m)?)?;
    m.add_function(wrap_pyfunction!(spectral_radius, m)?)?;
    Ok(())
}
