//! backlashid-core: the numerics of backlashid, without Python.
//!
//! Models of Vörös, "Modeling and identification of nonlinear cascade and sandwich systems
//! with general backlash": the general backlash (eq 1-15), the cascade linear block ->
//! backlash (eq 16-17) and the sandwich linear -> backlash -> linear (eq 29).

pub mod augmented;
pub mod effects;
pub mod backlash;
pub mod cascade;
pub mod error;
pub mod gradient;
pub mod linear;
pub mod lstsq;
pub mod polynomial;
pub mod regressor;
pub mod sandwich;
pub mod sensitivity;
pub mod signal;
pub mod streaming;
pub mod switching;

pub use augmented::simulate_augmented;
pub use effects::{AnyEffect, Effect};
pub use backlash::{Branch, BranchCheck, GeneralBacklash};
pub use cascade::{CascadeModel, CascadeSimulation, CascadeState};
pub use error::{Error, Result};
pub use linear::{LinearBlock, LinearState};
pub use sandwich::{SandwichModel, SandwichSimulation, SandwichState};
pub use streaming::{fold_parallel, TriangularFactor};
pub use switching::{switching, switching_form, SwitchingSignals};
