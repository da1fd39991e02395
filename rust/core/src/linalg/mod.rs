//! Least squares: the dense QR solve with column scaling and rank check (`lstsq`), and the
//! streaming triangular factor that folds regressor rows block by block on several threads
//! without forming the N x p matrix (`streaming`).

pub mod lstsq;
pub mod streaming;

pub use lstsq::LeastSquares;
pub use streaming::{default_threads, fold_parallel, TriangularFactor};
