//! Using an identified model to cancel its backlash: the inverse of the linear blocks
//! (`linear_inverse`), the feedforward compensator of the cascade and the sandwich
//! (`compensator`, with the backlash inverse of `model::inverse`) and a closed-loop PID
//! simulation around a plant model (`closed_loop`).

pub mod closed_loop;
pub mod compensator;
pub mod linear_inverse;

pub use closed_loop::{closed_loop, ClosedLoop, Pid};
pub use compensator::{compensate, Chain, ChainState, Compensator, CompensatorState};
pub use linear_inverse::{Filter, LinearInverse};
