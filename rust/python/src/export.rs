//! What `backlashid.export` needs of the core beyond the models: the coefficients of the
//! compensator's inverse filters (rust/core/src/compensation/linear_inverse.rs), which the C
//! export writes as literals.

use backlashid_core as core;
use backlashid_core::compensation::LinearInverse;
use pyo3::prelude::*;

use crate::errors::CoreError;

/// (feedthrough, a, b, delay, approximate): an inverse filter as `linear_inverse` returns it.
type InverseFilter = (f64, Vec<f64>, Vec<f64>, usize, bool);

/// (feedthrough, a, b, delay, approximate) of the inverse filter of the block (a, b, a0)
/// (`LinearInverse::new`; its coefficients do not depend on the pasts); `name` names the
/// block in errors.
#[pyfunction]
#[pyo3(signature = (a, b, a0=None, name="input"))]
pub(crate) fn linear_inverse(
    a: Vec<f64>,
    b: Vec<f64>,
    a0: Option<f64>,
    name: &str,
) -> PyResult<InverseFilter> {
    let block = match a0 {
        None => core::LinearBlock::new(a, b),
        Some(a0) => core::LinearBlock::with_feedthrough(a0, a, b),
    }
    .map_err(CoreError)?;
    let rest = block.rest_state();
    let inverse =
        LinearInverse::new(&block, &rest.x_past, &rest.u_past, name).map_err(CoreError)?;
    let f = inverse.filter;
    Ok((f.feedthrough, f.a, f.b, inverse.delay, inverse.approximate))
}
