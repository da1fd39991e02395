//! The shared test parameters (the paper's examples, test signals) of the integration tests:
//! the same file the unit tests use as `crate::test_params`.
#[path = "../../src/test_params.rs"]
mod test_params;
#[allow(unused_imports)]
pub use test_params::*;
