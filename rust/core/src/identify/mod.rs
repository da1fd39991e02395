//! The identification numerics, one call per iteration (the Python layer drives the
//! iterations): the quasi-linear regressions of the paper's algorithms (cascade eq 18-28,
//! sandwich eq 33-36) streamed into a triangular factor, the ARX start, and for the
//! output-error refinement the exact sensitivities, their factored Gauss-Newton problem and
//! the gradient.

pub mod augmented_problem;
mod augmented_sensitivity;
pub mod gradient;
pub mod initial;
pub mod problem;
pub mod regressor;
mod rows;
pub mod sensitivity;
pub mod wiener_hammerstein;

pub use augmented_problem::{AugmentedProblem, RecordStart};
pub use gradient::{cascade_oe_gradient, sandwich_oe_gradient, OeGradient};
pub use initial::InitialState;
pub use problem::{Iteration, Problem, Structure};
pub use regressor::{
    solve_factor, ArxRegression, CascadeRegression, Regression, RowRegression, SandwichRegression,
};
pub use sensitivity::{
    cascade_oe_factor, cascade_sensitivity, sandwich_oe_factor, sandwich_sensitivity, Sensitivity,
};
pub use wiener_hammerstein::{WhStructure, WienerHammersteinProblem};
