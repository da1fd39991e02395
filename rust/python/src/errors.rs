//! The exceptions of `backlashid.errors` (imported once; pyo3 caches the classes) and the
//! conversion of the core's one error type to them, so that binding code uses `?`.

use std::cell::RefCell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;

use backlashid_core as core;
use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError};
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
            core::Error::OutOfMemory(msg) => PyMemoryError::new_err(msg),
            // what the signal handler raised (`interrupt_hook`), else the default's error
            core::Error::Interrupted => PENDING
                .with(|p| p.borrow_mut().take())
                .unwrap_or_else(|| PyKeyboardInterrupt::new_err(())),
        }
    }
}

/// The identifier of the interpreter's main thread (`threading.main_thread().ident`), the
/// only thread on which Python runs signal handlers; set when the module is imported.
static MAIN_THREAD: OnceLock<u64> = OnceLock::new();

pub(crate) fn remember_main_thread(py: Python<'_>) -> PyResult<()> {
    let ident: u64 = py
        .import("threading")?
        .call_method0("main_thread")?
        .getattr("ident")?
        .extract()?;
    let _ = MAIN_THREAD.set(ident);
    Ok(())
}

extern "C" {
    /// The C API's identifier of the calling thread (what `threading.get_ident()` returns);
    /// pyo3-ffi does not declare it.
    fn PyThread_get_thread_ident() -> std::os::raw::c_ulong;
}

thread_local! {
    /// The exception a signal handler raised during core work, until `run` returns it.
    static PENDING: RefCell<Option<PyErr>> = const { RefCell::new(None) };
}

/// The core's interruption hook (`core::guard`): takes the GIL and runs Python's pending
/// signal handlers (Ctrl-C's raises KeyboardInterrupt); true, the exception kept, if one
/// raised.
fn interrupt_hook() -> bool {
    Python::attach(|py| match py.check_signals() {
        Ok(()) => false,
        Err(err) => {
            PENDING.with(|p| *p.borrow_mut() = Some(err));
            true
        }
    })
}

/// Run core work without the GIL; a core error becomes its Python class, a panic
/// `BacklashIdError` (a bug to report). On the main thread the work's long loops check for
/// signals (`core::guard::check`, at most every 50 ms): Ctrl-C ends it with KeyboardInterrupt.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> core::Result<T> + Send,
) -> PyResult<T> {
    // SAFETY: a C API function without arguments or preconditions (the GIL is held)
    let this = unsafe { PyThread_get_thread_ident() } as u64;
    let main = MAIN_THREAD.get() == Some(&this);
    let outcome = py.detach(|| {
        catch_unwind(AssertUnwindSafe(|| {
            if main {
                core::guard::interruptible(interrupt_hook, work)
            } else {
                (work(), false)
            }
        }))
    });
    match outcome {
        // a fold stopped early returns a partial result: discarded
        Ok((_, true)) => Err(CoreError(core::Error::Interrupted).into()),
        Ok((result, false)) => result.map_err(|e| CoreError(e).into()),
        Err(_) => Err(BacklashIdError::new_err(
            "internal error in the Rust core (a bug): please report it with the input that \
             caused it",
        )),
    }
}
