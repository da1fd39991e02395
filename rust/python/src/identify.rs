//! The identification functions of `backlashid._core`: one call per iteration (the Python
//! layer drives the iterations), least squares, the ARX start, the output-error factor and
//! gradient, and the free run of an estimate. An estimate crosses as the paper's parameters
//! (a, b, c_left, c_right, m_left, m_right), plus (r, s) for the sandwich's output block.

use backlashid_core as core;
use pyo3::prelude::*;

use crate::convert::{
    factor_out, ls_out, matrix, signal, vec_f64, FactorOut, LsOut, SignalIn, SignalOut,
};
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

    /// The estimate as a cascade model.
    fn cascade(self) -> core::Result<core::CascadeModel> {
        let (linear, backlash) = self.blocks()?;
        Ok(core::CascadeModel::new(linear, backlash))
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

/// The output block (r, s) of a sandwich estimate; None (a cascade) when r is empty.
fn output_block(r: Vec<f64>, s: Vec<f64>) -> core::Result<Option<core::LinearBlock>> {
    if r.is_empty() {
        Ok(None)
    } else {
        core::LinearBlock::new(r, s).map(Some)
    }
}

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

estimate_fn! {
    /// One iteration of the cascade algorithm (eq 18-28): internal variables at the current
    /// estimate, the regressor rows folded into a streaming QR factor (no N x p matrix),
    /// solve. Returns ((theta, rss, cov, rcond), moving_fraction, simulation RMSE of the
    /// estimate itself from rest over t >= warmup).
    #[pyfunction]
    fn cascade_iteration<'py>(
        est,
        py: Python<'py>,
        u: SignalIn<'py>,
        y: SignalIn<'py>,
        y_switch: SignalIn<'py>,
        warmup: usize,
        names: Vec<String>,
    ) -> PyResult<(LsOut<'py>, f64, f64)> {
        let (u, y, ys) = (signal("u", &u)?, signal("y", &y)?, signal("y_switch", &y_switch)?);
        let (ls, moving, rmse) = run(py, || {
            let (lin, bl) = est.blocks()?;
            let regression = core::CascadeRegression::new(&lin, &bl, &u, &y, &ys)?;
            let (factor, moving, rmse) = regression.iteration(warmup);
            Ok((core::solve_factor(&factor, &names, moving)?, moving, rmse))
        })?;
        Ok((ls_out(py, ls)?, moving, rmse))
    }
}

estimate_fn! {
    /// One iteration of the sandwich algorithm (eq 33-36), streamed like
    /// `cascade_iteration`. Returns ((theta, rss, cov, rcond), moving_fraction).
    #[pyfunction]
    fn sandwich_iteration<'py>(
        est,
        py: Python<'py>,
        r: Vec<f64>,
        s: Vec<f64>,
        u: SignalIn<'py>,
        w: SignalIn<'py>,
        warmup: usize,
        names: Vec<String>,
    ) -> PyResult<(LsOut<'py>, f64)> {
        let (u, w) = (signal("u", &u)?, signal("w", &w)?);
        let (ls, moving) = run(py, || {
            let (lin, bl) = est.blocks()?;
            let out = core::LinearBlock::new(r, s)?;
            let regression = core::SandwichRegression::new(&lin, &bl, &out, &u, &w)?;
            let (factor, moving) = regression.factor(warmup);
            Ok((core::solve_factor(&factor, &names, moving)?, moving))
        })?;
        Ok((ls_out(py, ls)?, moving))
    }
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

estimate_fn! {
    /// The cascade's output-error problem in factored form, streamed (no N x p Jacobian):
    /// (R_aug, cost) with R_aug^T R_aug = [J | r]^T [J | r] over t >= warmup,
    /// J = dy_sim/dtheta, r = y - y_sim, cost = sum r^2.
    #[pyfunction]
    fn cascade_oe_factor<'py>(
        est,
        py: Python<'py>,
        u: SignalIn<'py>,
        y: SignalIn<'py>,
        warmup: usize,
    ) -> PyResult<FactorOut<'py>> {
        let (u, y) = (signal("u", &u)?, signal("y", &y)?);
        let out = run(py, || {
            let (lin, bl) = est.blocks()?;
            core::cascade_oe_factor(&lin, &bl, &u, &y, warmup)
        })?;
        factor_out(py, out)
    }
}

estimate_fn! {
    /// The sandwich's output-error problem in factored form, streamed: (R_aug, cost) over
    /// t >= warmup with J = dw_sim/dtheta, r = w - w_sim.
    #[pyfunction]
    fn sandwich_oe_factor<'py>(
        est,
        py: Python<'py>,
        r: Vec<f64>,
        s: Vec<f64>,
        u: SignalIn<'py>,
        w: SignalIn<'py>,
        warmup: usize,
    ) -> PyResult<FactorOut<'py>> {
        let (u, w) = (signal("u", &u)?, signal("w", &w)?);
        let out = run(py, || {
            let (lin, bl) = est.blocks()?;
            let out = core::LinearBlock::new(r, s)?;
            core::sandwich_oe_factor(&lin, &bl, &out, &u, &w, warmup)
        })?;
        factor_out(py, out)
    }
}

estimate_fn! {
    /// The output-error gradient of an estimate (cascade when r is empty, else sandwich),
    /// one pass without the factor: (J^T r, cost = sum r^2) over t >= warmup.
    #[pyfunction]
    fn oe_gradient<'py>(
        est,
        py: Python<'py>,
        r: Vec<f64>,
        s: Vec<f64>,
        u: SignalIn<'py>,
        y: SignalIn<'py>,
        warmup: usize,
    ) -> PyResult<(SignalOut<'py>, f64)> {
        let (u, y) = (signal("u", &u)?, signal("y", &y)?);
        let g = run(py, || {
            let (lin, bl) = est.blocks()?;
            match output_block(r, s)? {
                None => core::cascade_oe_gradient(&lin, &bl, &u, &y, warmup),
                Some(out) => core::sandwich_oe_gradient(&lin, &bl, &out, &u, &y, warmup),
            }
        })?;
        Ok((vec_f64(py, g.gradient), g.cost))
    }
}

/// Largest root modulus of z^n + den[0] z^(n-1) + ... (0 for none, inf if not finite).
#[pyfunction]
fn spectral_radius(den: Vec<f64>) -> f64 {
    core::spectral_radius(&den)
}

estimate_fn! {
    /// Free-run output of an estimate (cascade when r is empty, else sandwich), from rest.
    #[pyfunction]
    fn simulate_estimate<'py>(
        est,
        py: Python<'py>,
        r: Vec<f64>,
        s: Vec<f64>,
        u: SignalIn<'py>,
    ) -> PyResult<SignalOut<'py>> {
        let u = signal("u", &u)?;
        let out = run(py, || match output_block(r, s)? {
            None => {
                let m = est.cascade()?;
                m.simulate(&u, &m.rest_state())
            }
            Some(out) => {
                let (lin, bl) = est.blocks()?;
                let m = core::SandwichModel::new(lin, bl, out);
                m.simulate(&u, &m.rest_state())
            }
        })?;
        Ok(vec_f64(py, out))
    }
}

/// Adds the identification functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(lstsq, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_estimate, m)?)?;
    m.add_function(wrap_pyfunction!(arx, m)?)?;
    m.add_function(wrap_pyfunction!(cascade_iteration, m)?)?;
    m.add_function(wrap_pyfunction!(sandwich_iteration, m)?)?;
    m.add_function(wrap_pyfunction!(cascade_oe_factor, m)?)?;
    m.add_function(wrap_pyfunction!(spectral_radius, m)?)?;
    m.add_function(wrap_pyfunction!(sandwich_oe_factor, m)?)?;
    m.add_function(wrap_pyfunction!(oe_gradient, m)?)?;
    Ok(())
}
