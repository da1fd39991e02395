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

/// A signal the core keeps (a compiled problem's record): `signal`, copied into memory the
/// core owns (MemoryError where it cannot be allocated).
pub(crate) fn owned_signal(name: &str, arr: &SignalIn<'_>) -> PyResult<Vec<f64>> {
    Ok(match signal(name, arr)? {
        Cow::Borrowed(s) => core::guard::copied(s, name).map_err(CoreError)?,
        Cow::Owned(v) => v,
    })
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
