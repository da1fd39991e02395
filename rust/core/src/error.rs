//! The one error type of the core. The Python binding maps each variant to a class of
//! `backlashid.errors`; every message says what the caller should do.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// Bad data: NaN or inf, wrong dimensionality, empty or too short. (`DataError`)
    Data(String),
    /// Invalid model parameters: negative widths, non-increasing branches, empty coefficient
    /// lists, an unstable block that diverged in simulation. (`ModelError`)
    Model(String),
    /// The data do not determine the parameters: too few samples off the dead band, a
    /// regressor column that is never excited, a rank-deficient regressor.
    /// (`NotIdentifiableError`)
    NotIdentifiable(String),
    /// A buffer proportional to the record could not be allocated (`guard::buffer`).
    /// (`MemoryError`)
    OutOfMemory(String),
    /// The caller asked the work to stop (`guard::check`). (`KeyboardInterrupt`, or what the
    /// caller's signal handler raised)
    Interrupted,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Data(msg)
            | Error::Model(msg)
            | Error::NotIdentifiable(msg)
            | Error::OutOfMemory(msg) => f.write_str(msg),
            Error::Interrupted => f.write_str("interrupted"),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;
