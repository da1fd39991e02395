//! backlashid-core: the numerics of backlashid, without Python.
//!
//! Models of Vörös, "Modeling and identification of nonlinear cascade and sandwich systems
//! with general backlash": the general backlash (eq 1-15), the cascade linear block ->
//! backlash (eq 16-17) and the sandwich linear -> backlash -> linear (eq 29).

pub mod augmented;
pub mod error;
pub mod identify;
pub mod linalg;
pub mod model;
#[cfg(test)]
pub(crate) mod test_params;
// `test_params` names this crate as the integration tests do.
#[cfg(test)]
extern crate self as backlashid_core;

pub use augmented::{simulate_augmented, Effects};
pub use error::{Error, Result};
pub use identify::{
    cascade_oe_factor, cascade_oe_gradient, sandwich_oe_factor, sandwich_oe_gradient, solve_factor,
    ArxRegression, CascadeRegression, OeGradient, SandwichRegression,
};
pub use linalg::{fold_parallel, LeastSquares, TriangularFactor};
pub use model::{
    spectral_radius, switching, switching_form, Branch, BranchCheck, CascadeModel,
    CascadeSimulation, CascadeState, GeneralBacklash, LinearBlock, LinearState, SandwichModel,
    SandwichSimulation, SandwichState, SwitchingSignals,
};
