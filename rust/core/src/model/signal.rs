//! Checks on measured or simulated signals before any numerics touch them.

use crate::error::{Error, Result};

/// A signal must be non-empty and finite everywhere.
pub fn check_signal(name: &str, values: &[f64]) -> Result<()> {
    if values.is_empty() {
        return Err(Error::Data(format!(
            "{name} is empty: pass at least one sample"
        )));
    }
    check_finite(name, values)
}

/// Every value finite; the message names the first bad sample.
pub fn check_finite(name: &str, values: &[f64]) -> Result<()> {
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::Data(format!(
            "{name}[{i}] is {}: remove or interpolate non-finite samples before calling",
            values[i]
        )));
    }
    Ok(())
}

/// A coefficient list: non-empty (if required) and finite.
pub fn check_coefficients(name: &str, values: &[f64], allow_empty: bool) -> Result<()> {
    if values.is_empty() && !allow_empty {
        return Err(Error::Model(format!(
            "{name} is empty: give at least one coefficient"
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::Model(format!(
            "{name}[{i}] is {}: every coefficient must be a finite number",
            values[i]
        )));
    }
    Ok(())
}

/// Input and output of one record must have the same length.
pub(crate) fn check_same_length(u: &[f64], y: &[f64], y_name: &str) -> Result<()> {
    if u.len() != y.len() {
        return Err(Error::Data(format!(
            "u has {} samples but {y_name} has {}: give input and output of the same record",
            u.len(),
            y.len()
        )));
    }
    Ok(())
}
