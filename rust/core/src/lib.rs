//! backlashid-core: the numerics of backlashid, without Python.
//!
//! Models of Vörös, "Modeling and identification of nonlinear cascade and sandwich systems
//! with general backlash": the general backlash (eq 1-15), the cascade linear block ->
//! backlash (eq 16-17) and the sandwich linear -> backlash -> linear (eq 29).
//!
//! Layout, following the data path u -> x -> f1/f2 -> regressor -> QR -> parameters:
//! - `model`: the blocks and their simulation (linear block, general backlash and its
//!   switching form, cascade, sandwich) and the checks on signals and coefficients;
//! - `identify`: the paper's regressions at an estimate (`CascadeRegression`,
//!   `SandwichRegression`, the ARX start), the output-error sensitivities, factor and
//!   gradient;
//! - `linalg`: least squares by QR and the streaming triangular factor;
//! - `effects`: the diagnosis catalogue's effects, one module each over the `Effect` trait;
//! - `augmented`: the cascade or sandwich with those effects, simulated in one fused pass;
//! - `guard`: fallible allocation of record-sized buffers and the interruption check.
//!
//! The items below are the API the Python binding and the benches use.

pub mod augmented;
pub mod compensation;
pub mod effects;
pub mod error;
pub mod guard;
pub mod identify;
pub mod linalg;
pub mod model;
#[cfg(test)]
pub(crate) mod test_params;
pub mod tracking;
// `test_params` names this crate as the integration tests do.
#[cfg(test)]
extern crate self as backlashid_core;

pub use augmented::{simulate_augmented, simulate_augmented_chain, AugmentedChain, AugmentedState};
pub use compensation::{compensate, Chain, ChainState, Compensator};
pub use effects::{AnyEffect, Effect};
pub use error::{Error, Result};
pub use identify::{
    cascade_oe_factor, cascade_oe_gradient, sandwich_oe_factor, sandwich_oe_gradient, solve_factor,
    ArxRegression, AugmentedProblem, CascadeRegression, Iteration, OeGradient, Past, Problem,
    RecordStart, SandwichRegression, Structure, WhStructure, WienerHammersteinProblem,
};
pub use linalg::{fold_parallel, LeastSquares, TriangularFactor};
pub use model::{
    spectral_radius, switching, switching_form, BacklashInverse, Branch, BranchCheck, CascadeModel,
    CascadeSimulation, CascadeState, GeneralBacklash, LinearBlock, LinearState, SandwichModel,
    SandwichSimulation, SandwichState, SwitchingSignals,
};
