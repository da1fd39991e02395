//! The models of the paper and their simulation: the linear block (eq 16), the general
//! backlash (eq 1-15) with its switching form (eq 9-15), the cascade linear -> backlash
//! (eq 16-17) and the sandwich linear -> backlash -> linear (eq 29), plus the checks every
//! signal and coefficient list passes before the numerics touch it.

pub mod backlash;
pub mod cascade;
pub mod inverse;
pub mod linear;
pub mod polynomial;
pub mod sandwich;
pub mod signal;
pub mod sink;
pub mod state_space;
pub mod switching;

pub use backlash::{Branch, BranchCheck, GeneralBacklash};
pub use cascade::{CascadeModel, CascadeSimulation, CascadeState};
pub use inverse::BacklashInverse;
pub use linear::{LinearBlock, LinearState};
pub use polynomial::spectral_radius;
pub use sandwich::{SandwichModel, SandwichSimulation, SandwichState};
pub use switching::{switching, switching_form, SwitchingSignals};
