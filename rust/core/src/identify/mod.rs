//! The identification numerics, one call per iteration (the Python layer drives the
//! iterations): the quasi-linear regressions of the paper's algorithms (cascade eq 18-28,
//! sandwich eq 33-36) streamed into a triangular factor, the ARX start, and for the
//! output-error refinement the exact sensitivities, their factored Gauss-Newton problem and
//! the gradient.

pub mod augmented_problem;
mod augmented_sensitivity;
pub mod bands;
pub mod gradient;
pub mod initial;
pub mod problem;
pub mod regressor;
mod rows;
pub mod samples;
pub mod sensitivity;
pub mod wiener_hammerstein;

pub use augmented_problem::{AugmentedProblem, Past, RecordStart};
pub use bands::{cascade_output_variance, sandwich_output_variance, OutputVariance};
pub use gradient::{cascade_oe_gradient, sandwich_oe_gradient, Motion, OeGradient};
pub use initial::InitialState;
pub use problem::{Iteration, Problem, Record, Structure};
pub use regressor::{
    solve_factor, ArxRegression, CascadeRegression, Regression, RowRegression, SandwichRegression,
};
pub use samples::Samples;
pub use sensitivity::{
    cascade_oe_factor, cascade_sensitivity, sandwich_oe_factor, sandwich_sensitivity, Sensitivity,
};
pub use wiener_hammerstein::{WhStructure, WienerHammersteinProblem};

/// The output-error cost of every compiled problem: sum (y - y_sim)^2 over t >= `warmup`; a
/// ModelError where the simulation diverged (a non-finite cost).
pub(crate) fn output_error_cost(
    y: &[f64],
    y_sim: &[f64],
    warmup: usize,
) -> crate::error::Result<f64> {
    finite_cost(
        y[warmup..]
            .iter()
            .zip(&y_sim[warmup..])
            .map(|(y, s)| (y - s) * (y - s))
            .sum(),
    )
}

/// The cost, or the ModelError of a diverged simulation (a non-finite cost).
pub(crate) fn finite_cost(cost: f64) -> crate::error::Result<f64> {
    if !cost.is_finite() {
        return Err(crate::error::Error::Model(
            "the simulated output of the estimate diverges (a non-finite output error); start \
             from a stable estimate or scale the signals down"
                .into(),
        ));
    }
    Ok(cost)
}
