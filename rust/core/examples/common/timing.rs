//! What the speed examples share: the sizes from the command line and a best-of timing.
use std::time::Instant;

/// The record lengths N given on the command line (`1e6` style accepted), else `default`.
pub fn sizes(default: &[usize]) -> Vec<usize> {
    let given: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse::<f64>().expect("N") as usize)
        .collect();
    if given.is_empty() {
        default.to_vec()
    } else {
        given
    }
}

/// Nanoseconds per sample of the fastest of `reps` runs of `f` over `n` samples.
pub fn best<T>(reps: usize, n: usize, mut f: impl FnMut() -> T) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        let t = Instant::now();
        std::hint::black_box(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    best / n as f64 * 1e9
}
