//! Thin pyo3 binding of backlashid-core: converts arrays (`convert`), releases the GIL around
//! the loops and maps `backlashid_core::Error` onto `backlashid.errors` (`errors`), and
//! exposes the model classes (`models`) and the identification functions (`identify`). No
//! numerics live here.

mod augmented;
mod augmented_problem;
mod bands;
mod compensation;
mod convert;
mod errors;
mod export;
mod identify;
mod models;
mod problem;
mod tracking;
mod wiener_hammerstein;

// The helpers the effect binding (`augmented`) shares.
use convert::{signal, vec_f64, SignalOut};
use errors::run;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::remember_main_thread(m.py())?;
    m.add_class::<models::PyLinearBlock>()?;
    m.add_class::<models::PyGeneralBacklash>()?;
    m.add_class::<models::PyCascadeModel>()?;
    m.add_class::<models::PySandwichModel>()?;
    m.add_class::<problem::PyProblem>()?;
    m.add_class::<augmented_problem::PyAugmentedProblem>()?;
    m.add_class::<wiener_hammerstein::PyWienerHammersteinProblem>()?;
    identify::register(m)?;
    bands::register(m)?;
    m.add_function(wrap_pyfunction!(augmented::simulate_augmented, m)?)?;
    m.add_class::<compensation::PyCompensator>()?;
    m.add_function(wrap_pyfunction!(compensation::compensate, m)?)?;
    m.add_function(wrap_pyfunction!(compensation::closed_loop, m)?)?;
    m.add_function(wrap_pyfunction!(export::linear_inverse, m)?)?;
    m.add_class::<tracking::PyTracker>()?;
    Ok(())
}
