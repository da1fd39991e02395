//! Arrays in and out: 1-D float64 signals borrowed from NumPy, vectors and matrices handed
//! back as NumPy arrays, and the result tuples of the solvers.

use std::borrow::Cow;

use backlashid_core as core;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{CoreError, DataError};

/// A signal argument: any float64 array (checked to be 1-D by `signal`).
pub(crate) type SignalIn<'py> = PyReadonlyArrayDyn<'py, f64>;
pub(crate) type SignalOut<'py> = Bound<'py, PyArray1<f64>>;
pub(crate) type FlagOut<'py> = Bound<'py, PyArray1<bool>>;
pub(crate) type MatrixOut<'py> = Bound<'py, PyArray2<f64>>;
/// (theta, rss, (A^T A)^-1, rcond) of a least-squares solve.
pub(crate) type LsOut<'py> = (SignalOut<'py>, f64, MatrixOut<'py>, f64);
/// (R_aug, cost) of an output-error factor.
pub(crate) type FactorOut<'py> = (MatrixOut<'py>, f64);

/// A 1-D float64 signal, borrowed when contiguous (the Python layer converted the dtype).
pub(crate) fn signal<'a>(name: &str, arr: &'a SignalIn<'_>) -> PyResult<Cow<'a, [f64]>> {
    if arr.ndim() != 1 {
        return Err(DataError::new_err(format!(
            "{name} has {} dimensions, expected a 1-D signal: pass one channel, e.g. \
             {name}.ravel() for a column",
            arr.ndim()
        )));
    }
    Ok(match arr.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => {
            let mut v = core::guard::buffer(arr.len(), name).map_err(CoreError)?;
            v.extend(arr.as_array().iter().copied());
            Cow::Owned(v)
        }
    })
}

/// A signal the core keeps (a compiled problem's record): a contiguous array read in place
/// for as long as the problem lives, else `signal`'s copy (MemoryError where it cannot be
/// allocated). In place, a 1e8-sample record costs the problem no memory of its own.
pub(crate) fn kept_signal(name: &str, arr: &SignalIn<'_>) -> PyResult<core::identify::Samples> {
    Ok(match signal(name, arr)? {
        Cow::Borrowed(s) if !s.is_empty() => core::identify::Samples::shared(NumpySamples {
            ptr: s.as_ptr(),
            len: s.len(),
            _array: arr.as_any().clone().unbind(),
        }),
        Cow::Borrowed(s) => core::identify::Samples::from(s.to_vec()),
        Cow::Owned(v) => core::identify::Samples::from(v),
    })
}

/// The values of a C-contiguous float64 NumPy array, read in place. The array is referenced
/// (`_array`), so it stays alive and NumPy refuses to resize it; the package compiles a
/// problem on arrays it does not write while the problem lives (as any NumPy function that
/// releases the GIL, a caller writing them from another thread meanwhile races the read).
struct NumpySamples {
    ptr: *const f64,
    len: usize,
    _array: Py<PyAny>,
}

// SAFETY: the pointer is into an array kept alive by `_array` and only read; `Py` is Send
// and Sync.
unsafe impl Send for NumpySamples {}
unsafe impl Sync for NumpySamples {}

impl AsRef<[f64]> for NumpySamples {
    fn as_ref(&self) -> &[f64] {
        // SAFETY: `ptr` is non-null and aligned (a non-empty slice's), `len` values long,
        // valid while `_array` is held (see the struct).
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }
}

/// A row-major matrix: its values in logical order and its shape (rows, cols).
pub(crate) fn matrix(name: &str, arr: &SignalIn<'_>) -> PyResult<(Vec<f64>, usize, usize)> {
    match *arr.shape() {
        [rows, cols] => Ok((arr.as_array().iter().copied().collect(), rows, cols)),
        _ => Err(DataError::new_err(format!("{name} must be a 2-D matrix"))),
    }
}

/// The vector as a NumPy array that wraps its buffer (rust-numpy's `into_pyarray`: only a
/// small owner object and the array header are allocated, nothing proportional to the
/// record, which the core allocated fallibly, `core::guard`).
pub(crate) fn vec_f64(py: Python<'_>, v: Vec<f64>) -> SignalOut<'_> {
    v.into_pyarray(py)
}

pub(crate) fn vec_bool(py: Python<'_>, v: Vec<bool>) -> FlagOut<'_> {
    v.into_pyarray(py)
}

/// A row-major n x n matrix.
fn square(py: Python<'_>, values: Vec<f64>, n: usize) -> PyResult<MatrixOut<'_>> {
    values.into_pyarray(py).reshape([n, n])
}

pub(crate) fn ls_out(py: Python<'_>, ls: core::LeastSquares) -> PyResult<LsOut<'_>> {
    let p = ls.theta.len();
    let cov = square(py, ls.unscaled_covariance, p)?;
    Ok((vec_f64(py, ls.theta), ls.rss, cov, ls.rcond))
}

pub(crate) fn factor_out(
    py: Python<'_>,
    (factor, cost): (core::TriangularFactor, f64),
) -> PyResult<FactorOut<'_>> {
    let n = factor.cols() + 1;
    Ok((square(py, factor.r_aug().to_vec(), n)?, cost))
}
