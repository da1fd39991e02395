//! Throughput of `CascadeModel::simulate` (Example 1) and `SandwichModel::simulate`
//! (Example 2), next to a bare hand-written loop for Example 1: the reference of what a
//! plain Rust loop with the coefficients inlined can do.
//!
//! `cargo bench -p backlashid-core` runs the criterion groups, then prints a plain table of
//! ns/sample (best of 5 timed runs per N) with the ratio cascade / bare loop.

use std::hint::black_box;
use std::time::{Duration, Instant};

use backlashid_core::{CascadeModel, SandwichModel};
use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const SIZES: [usize; 4] = [10_000, 100_000, 1_000_000, 10_000_000];
const TABLE_RUNS: usize = 7;

#[path = "../rust/core/src/test_params.rs"]
mod test_params;
use test_params::{example1_model as example1, example2_model as example2};

/// The input: uniform in (-1, 1), from a seeded rng (the same record every run).
fn input(n: usize) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(2024);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// Example 1 written out by hand, from rest: x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1)
/// - 0.35 x(t-2), the cubic branches by Horner's rule, and the case order of eq (1).
fn bare_loop(u: &[f64]) -> Vec<f64> {
    let mut y = Vec::with_capacity(u.len());
    let (mut u1, mut u2, mut x1, mut x2, mut y_prev) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &ut in u {
        let x = 0.7 * u1 + 0.5 * u2 + 0.2 * x1 - 0.35 * x2;
        let (xl, xr) = (x + 0.6, x - 0.5);
        let l = ((0.3 * xl - 0.3) * xl + 1.0) * xl;
        let r = ((0.2 * xr + 0.4) * xr + 1.5) * xr;
        y_prev = if l <= y_prev {
            l
        } else if r >= y_prev {
            r
        } else {
            y_prev
        };
        y.push(y_prev);
        (u2, u1, x2, x1) = (u1, ut, x1, x);
    }
    y
}

/// The measured functions, by the name used in both the criterion groups and the table.
struct Subjects {
    cascade: CascadeModel,
    sandwich: SandwichModel,
}

impl Subjects {
    fn run(&self, name: &str, u: &[f64]) -> Vec<f64> {
        match name {
            "cascade" => self
                .cascade
                .simulate(u, &self.cascade.rest_state())
                .unwrap(),
            "sandwich" => self
                .sandwich
                .simulate(u, &self.sandwich.rest_state())
                .unwrap(),
            "bare loop" => bare_loop(u),
            _ => unreachable!("unknown subject {name}"),
        }
    }
}

const NAMES: [&str; 3] = ["cascade", "sandwich", "bare loop"];

fn criterion_groups(c: &mut Criterion, subjects: &Subjects, u: &[f64]) {
    for name in NAMES {
        let mut group = c.benchmark_group(format!("simulate/{name}"));
        // One iteration at N = 1e7 takes ~0.1 s: few, flat samples keep the run short.
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(2));
        for n in SIZES {
            group.throughput(Throughput::Elements(n as u64));
            group.bench_with_input(BenchmarkId::from_parameter(n), &u[..n], |b, u| {
                b.iter(|| subjects.run(name, black_box(u)))
            });
        }
        group.finish();
    }
}

/// ns per sample of each subject on `u`: the best of `TABLE_RUNS` timed runs, the subjects
/// taking turns so that a noisy machine slows them alike.
fn best_ns_per_sample<const K: usize>(
    subjects: &Subjects,
    names: [&str; K],
    u: &[f64],
) -> [f64; K] {
    let mut best = [f64::INFINITY; K];
    for _ in 0..TABLE_RUNS {
        for (name, best) in names.iter().zip(&mut best) {
            let start = Instant::now();
            black_box(subjects.run(name, black_box(u)));
            *best = best.min(start.elapsed().as_secs_f64() * 1e9 / u.len() as f64);
        }
    }
    best
}

fn print_table(subjects: &Subjects, u: &[f64]) {
    println!("\nsimulate ns/sample (best of {TABLE_RUNS} runs)");
    println!(
        "{:>10} {:>10} {:>10} {:>10} {:>14}",
        "N", "cascade", "sandwich", "bare loop", "cascade/bare"
    );
    for n in SIZES {
        let [cascade, sandwich, bare] = best_ns_per_sample(subjects, NAMES, &u[..n]);
        println!(
            "{n:>10} {cascade:>10.2} {sandwich:>10.2} {bare:>10.2} {:>14.2}",
            cascade / bare
        );
    }
}

fn main() {
    let subjects = Subjects {
        cascade: example1(),
        sandwich: example2(),
    };
    let u = input(*SIZES.last().unwrap());
    // The bare loop must compute what the cascade computes, or the comparison means nothing.
    assert_eq!(
        subjects.run("cascade", &u[..SIZES[0]]),
        subjects.run("bare loop", &u[..SIZES[0]]),
        "the bare loop disagrees with CascadeModel::simulate"
    );

    let mut c = Criterion::default().configure_from_args();
    criterion_groups(&mut c, &subjects, &u);
    c.final_summary();

    // `cargo test --benches` runs this binary without `--bench`: skip the timed table there.
    if std::env::args().any(|a| a == "--bench") {
        print_table(&subjects, &u);
    }
}
