//! The exceptions of `backlashid.errors` (imported once; pyo3 caches the classes) and the
//! conversion of the core's one error type to them, so that binding code uses `?`.

use std::panic::{catch_unwind, AssertUnwindSafe};

use backlashid_core as core;
use pyo3::prelude::*;

pyo3::import_exception!(backlashid.errors, BacklashIdError);
pyo3::import_exception!(backlashid.errors, DataError);
pyo3::import_exception!(backlashid.errors, ModelError);
pyo3::import_exception!(backlashid.errors, NotIdentifiableError);

/// A core error on its way to Python. A newtype because neither `core::Error` nor `PyErr`
/// belongs to this crate (polars' `PyPolarsErr` does the same).
#[derive(Debug)]
pub(crate) struct CoreError(pub core::Error);

impl From<core::Error> for CoreError {
    fn from(err: core::Error) -> Self {
        Self(err)
    }
}

impl From<CoreError> for PyErr {
    /// Each variant of `core::Error` raises its class of `backlashid.errors`.
    fn from(CoreError(err): CoreError) -> Self {
        match err {
            core::Error::Data(msg) => DataError::new_err(msg),
            core::Error::Model(msg) => ModelError::new_err(msg),
            core::Error::NotIdentifiable(msg) => NotIdentifiableError::new_err(msg),
        }
    }
}

/// Run core work without the GIL; a core error becomes its Python class, a panic
/// `BacklashIdError` (a bug to report).
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> core::Result<T> + Send,
) -> PyResult<T> {
    match py.detach(|| catch_unwind(AssertUnwindSafe(work))) {
        Ok(result) => result.map_err(|e| CoreError(e).into()),
        Err(_) => Err(BacklashIdError::new_err(
            "internal error in the Rust core (a bug): please report it with the input that \
             caused it",
        )),
    }
}
