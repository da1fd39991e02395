//! Throughput of `tracking::Tracker::update` on Example 1 (p = 11), both update rules, with
//! forgetting and with the Kalman random walk, recording the trajectory (theta and standard
//! errors) after every sample or every 1000th, next to `CascadeModel::simulate` of the same
//! record (the floor: one model step per sample).
//!
//! `cargo bench -p backlashid-core --bench tracking` runs the criterion groups, then prints
//! million samples per second (best of 7 timed runs, subjects taking turns). Issue 20's
//! target: >= 5 million samples per second on one core.

use std::hint::black_box;
use std::time::{Duration, Instant};

use backlashid_core::tracking::{DetectorOptions, Method, Options, Orders, Sink, Tracker};
use backlashid_core::CascadeModel;
use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const N: usize = 1_000_000;
const TABLE_RUNS: usize = 7;

#[path = "../rust/core/src/test_params.rs"]
mod test_params;
use test_params::example1_model as example1;

/// Example 1's physical theta: a1 a2 b1 b2 c_L m_L2 m_L3 m_R1 c_R m_R2 m_R3.
const THETA: [f64; 11] = [0.7, 0.5, -0.2, 0.35, 0.6, -0.3, 0.3, 1.5, 0.5, 0.4, 0.2];

/// u uniform in (-1, 1) and Example 1's output plus uniform noise near SNR 25.
fn record(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(2024);
    let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let m: CascadeModel = example1();
    let y: Vec<f64> = m
        .simulate(&u, &m.rest_state())
        .unwrap()
        .iter()
        .map(|v| v + rng.random_range(-0.05..0.05))
        .collect();
    (u, y)
}

/// (name, method, forgetting, drift on every parameter, recording every).
const SUBJECTS: [(&str, Method, f64, f64, u64); 6] = [
    (
        "rpem/forget/every 1",
        Method::PredictionError,
        0.9999,
        0.0,
        1,
    ),
    (
        "rpem/forget/every 1000",
        Method::PredictionError,
        0.9999,
        0.0,
        1000,
    ),
    (
        "rpem/drift/every 1000",
        Method::PredictionError,
        1.0,
        1e-5,
        1000,
    ),
    (
        "regression/forget/every 1",
        Method::Regression,
        0.9999,
        0.0,
        1,
    ),
    (
        "regression/forget/every 1000",
        Method::Regression,
        0.9999,
        0.0,
        1000,
    ),
    (
        "regression/drift/every 1000",
        Method::Regression,
        1.0,
        1e-5,
        1000,
    ),
];

fn tracker(method: Method, forgetting: f64, drift: f64) -> Tracker {
    let cov: Vec<f64> = (0..121)
        .map(|k| if k % 12 == 0 { 1e-4 } else { 0.0 })
        .collect();
    let options = Options {
        method,
        forgetting,
        drift: if drift > 0.0 { vec![drift; 11] } else { vec![] },
        noise_memory: 1e4,
        innovation_bound: 20.0, // the Python default
    };
    let det = DetectorOptions::for_forgetting(0.9999);
    Tracker::new(
        Orders::cascade(2, 2, 3),
        &THETA,
        &cov,
        1e-3,
        100.0,
        &options,
        Some(det),
        None,
    )
    .unwrap()
}

/// Track the record from the start; the trajectory buffers are allocated outside the timing.
struct Run {
    theta: Vec<f64>,
    se: Vec<f64>,
}

impl Run {
    fn new(n: usize) -> Self {
        Run {
            theta: vec![0.0; n * 11],
            se: vec![0.0; n * 11],
        }
    }

    fn track(&mut self, subject: usize, u: &[f64], y: &[f64]) -> f64 {
        let (_, method, forgetting, drift, every) = SUBJECTS[subject];
        let mut t = tracker(method, forgetting, drift);
        let (mut alarms, mut windows) = (Vec::new(), Vec::new());
        let mut sink = Sink {
            theta: &mut self.theta,
            se: &mut self.se,
            every,
            alarms: &mut alarms,
            windows: &mut windows,
        };
        t.update(u, y, &mut sink).unwrap();
        assert!(alarms.is_empty(), "{alarms:?}");
        t.estimate().0[8]
    }
}

fn main() {
    let (u, y) = record(N);
    let m = example1();
    let mut run = Run::new(N);
    let mut c = Criterion::default().configure_from_args();
    for (k, (name, ..)) in SUBJECTS.iter().enumerate() {
        let mut group = c.benchmark_group(format!("tracking/{name}"));
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(2))
            .throughput(Throughput::Elements(N as u64));
        group.bench_with_input(BenchmarkId::from_parameter(N), &k, |b, &k| {
            b.iter(|| run.track(k, black_box(&u), black_box(&y)))
        });
        group.finish();
    }
    c.final_summary();
    if !std::env::args().any(|a| a == "--bench") {
        return; // `cargo test --benches`: no timed table
    }
    let mut best = [f64::INFINITY; SUBJECTS.len() + 1];
    for _ in 0..TABLE_RUNS {
        for (k, best) in best.iter_mut().enumerate() {
            let start = Instant::now();
            if k < SUBJECTS.len() {
                black_box(run.track(k, &u, &y));
            } else {
                black_box(m.simulate(&u, &m.rest_state()).unwrap());
            }
            *best = best.min(start.elapsed().as_secs_f64());
        }
    }
    println!("\ntracking, Example 1 (p = 11), N = {N}: million samples per second (best of {TABLE_RUNS})");
    for (k, (name, ..)) in SUBJECTS.iter().enumerate() {
        println!("{name:>32} {:>8.2}", N as f64 / best[k] / 1e6);
    }
    println!(
        "{:>32} {:>8.2}",
        "simulate (floor)",
        N as f64 / best[SUBJECTS.len()] / 1e6
    );
}
