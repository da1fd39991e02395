//! Cost of identification on Example 1 (cascade, p = 11 least-squares parameters), from
//! noisy data (uniform u in (-1, 1), output noise at SNR 25, seeded):
//!
//! - "iteration": one iteration of the cascade algorithm at a perturbed estimate:
//!   `CascadeRegression::factor` (y_switch = the measured y, no warm-up) + `solve_factor`;
//! - "fit": the paper's whole algorithm driven from here: ARX start, m_R1 = 1,
//!   c_L = c_R = 0.001, higher terms 0, then `ITERATIONS` iterations; the estimate must end
//!   within `MAX_ERROR` of the truth, so the bench cannot silently time a diverged fit;
//! - "oe_factor": one `identify::cascade_oe_factor` at the true parameters (the cost of
//!   one Levenberg-Marquardt Jacobian, folded).
//!
//! `cargo bench -p backlashid-core --bench identify` runs the criterion groups (N = 1e4 to
//! 1e6), then prints a plain table of ns/sample and peak resident memory for N = 1e4 up to
//! `BACKLASHID_BENCH_MAX_N` (default 1e8; e.g. `BACKLASHID_BENCH_MAX_N=1e7` for a quick
//! run). Peak memory is Linux's VmHWM, reset before each measurement through
//! /proc/self/clear_refs; "n/a" where that is not available.

use std::hint::black_box;
use std::time::{Duration, Instant};

use backlashid_core::identify::cascade_oe_factor;
use backlashid_core::identify::{solve_factor, ArxRegression, CascadeRegression};
use backlashid_core::linalg::default_threads;
use backlashid_core::LeastSquares;
use backlashid_core::{CascadeModel, GeneralBacklash, LinearBlock, TriangularFactor};
use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "../rust/core/src/test_params.rs"]
mod test_params;

const CRITERION_SIZES: [usize; 3] = [10_000, 100_000, 1_000_000];
const TABLE_SIZES: [usize; 5] = [10_000, 100_000, 1_000_000, 10_000_000, 100_000_000];
const DEFAULT_MAX_N: usize = 100_000_000;
const MAX_N_VAR: &str = "BACKLASHID_BENCH_MAX_N";
/// Output signal-to-noise ratio: noise std = std(clean output) / SNR.
const SNR: f64 = 25.0;
/// Cascade iterations of the full fit (after the ARX start).
const ITERATIONS: usize = 20;
/// The largest |estimate - truth| a fit may end with (any parameter, physical form).
const MAX_ERROR: f64 = 0.05;
/// A fit whose projected time (from the single iteration at the same N) exceeds this is
/// not run in the table.
const FIT_BUDGET: Duration = Duration::from_secs(600);
/// Below this N the table keeps the best of `SMALL_RUNS` runs; from it on, one run.
const ONE_RUN_FROM: usize = 10_000_000;
const SMALL_RUNS: usize = 5;

// -- the system and its data ---------------------------------------------------------------

/// Polynomial degree n of both branches; with na = nb = 2 the regression has 2 + 2 + 2n + 1
/// columns.
const DEGREE: usize = 3;

/// A cascade estimate in physical form (m_L1 = 1 fixed).
#[derive(Debug, Clone)]
struct Estimate {
    linear: LinearBlock,
    backlash: GeneralBacklash,
}

impl Estimate {
    /// a_1 a_2 b_1 b_2 c_L m_L2 m_L3 m_R1 c_R m_R2 m_R3: the parameters the fit is judged on.
    fn physical(&self) -> Vec<f64> {
        let (bl, lin) = (&self.backlash, &self.linear);
        let mut v = [lin.a(), lin.b()].concat();
        v.push(bl.c_left());
        v.extend_from_slice(&bl.left().coefficients()[1..]);
        v.push(bl.right().coefficients()[0]);
        v.push(bl.c_right());
        v.extend_from_slice(&bl.right().coefficients()[1..]);
        v
    }

    fn max_error(&self, truth: &Estimate) -> f64 {
        self.physical()
            .iter()
            .zip(truth.physical())
            .map(|(e, t)| (e - t).abs())
            .fold(0.0, f64::max)
    }
}

/// Example 1 of the paper.
fn truth() -> Estimate {
    let (linear, backlash) = test_params::example1();
    Estimate { linear, backlash }
}

/// Example 1 a little off: where an iteration of a fit in progress would be.
fn perturbed() -> Estimate {
    Estimate {
        linear: LinearBlock::new(vec![0.68, 0.52], vec![-0.18, 0.33]).unwrap(),
        backlash: GeneralBacklash::from_estimate(
            0.58,
            0.52,
            vec![1.0, -0.28, 0.31],
            vec![1.47, 0.42, 0.19],
        )
        .unwrap(),
    }
}

/// A record of Example 1: u uniform in (-1, 1), y the output plus white Gaussian noise of
/// std = std(clean y) / SNR (the convention of python/backlashid/examples.py), seeded.
struct Data {
    u: Vec<f64>,
    y: Vec<f64>,
}

fn example_data(n: usize) -> Data {
    let mut rng = StdRng::seed_from_u64(2024);
    let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let t = truth();
    let model = CascadeModel::new(t.linear, t.backlash);
    let mut y = model.simulate(&u, &model.rest_state()).unwrap();
    let mean = y.iter().sum::<f64>() / n as f64;
    let std = (y.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let noise_std = std / SNR;
    for v in &mut y {
        // Box-Muller: u1 in (0, 1] keeps the log finite
        let (u1, u2): (f64, f64) = (1.0 - rng.random::<f64>(), rng.random());
        *v += noise_std * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
    }
    Data { u, y }
}

// -- the algorithm ---------------------------------------------------------------------------

/// Column names of the cascade regression (order of regressor.rs: a, b, c_1, m_L2.., m_R1,
/// c_2, m_R2..), used in the errors of an unidentifiable iteration.
fn ls_names() -> Vec<String> {
    let mut names: Vec<String> = ["a_1", "a_2", "b_1", "b_2", "c_1"].map(String::from).into();
    names.extend((2..=DEGREE).map(|i| format!("m_L{i}")));
    names.extend(["m_R1".to_string(), "c_2".to_string()]);
    names.extend((2..=DEGREE).map(|i| format!("m_R{i}")));
    names
}

/// One iteration: the regression of eq (18)-(21) at `est`, folded into a triangular factor
/// on the default threads, and its least-squares solution.
fn iteration(est: &Estimate, data: &Data, names: &[String]) -> LeastSquares {
    let (factor, moving): (TriangularFactor, f64) =
        CascadeRegression::new(&est.linear, &est.backlash, &data.u, &data.y, &data.y)
            .expect("cascade regression")
            .factor(0);
    solve_factor(&factor, names, moving).expect("an iteration's least squares")
}

/// theta_LS (a, b, c_1, m_L2..m_Ln, m_R1, c_2, m_R2..m_Rn) to the physical estimate:
/// c_L = c_1, m_L1 = 1, c_R = c_2 / m_R1 (eq 20; structure.py `physical_from_ls`).
fn from_ls(theta: &[f64]) -> Estimate {
    let (na, nb, n) = (2, 2, DEGREE);
    let k = na + nb; // c_1
    let m_r1 = theta[k + n];
    let m_left = [&[1.0], &theta[k + 1..k + n]].concat();
    let m_right = [&[m_r1], &theta[k + n + 2..k + 2 * n + 1]].concat();
    Estimate {
        linear: LinearBlock::new(theta[..na].to_vec(), theta[na..k].to_vec())
            .expect("finite linear estimate"),
        backlash: GeneralBacklash::from_estimate(
            theta[k],
            theta[k + n + 1] / m_r1,
            m_left,
            m_right,
        )
        .expect("finite backlash estimate"),
    }
}

/// The paper's first iteration: an ARX fit (delay 1) with the measured y standing in for x,
/// and the backlash m_R1 = 1, c_L = c_R = 0.001, higher coefficients 0.
fn start(data: &Data) -> Estimate {
    let (na, nb) = (2, 2);
    let names = ["a_1", "a_2", "b_1", "b_2"].map(String::from);
    let arx = ArxRegression::new(&data.u, &data.y, na, nb, 1)
        .and_then(|r| r.factor(0).solve(&names))
        .expect("ARX fit");
    let zeros = vec![0.0; DEGREE - 1];
    Estimate {
        linear: LinearBlock::new(arx.theta[..na].to_vec(), arx.theta[na..].to_vec())
            .expect("finite ARX estimate"),
        backlash: GeneralBacklash::from_estimate(
            0.001,
            0.001,
            [&[1.0][..], &zeros].concat(),
            [&[1.0][..], &zeros].concat(),
        )
        .unwrap(),
    }
}

/// The paper's plain algorithm: the ARX start, then `ITERATIONS` full steps to the
/// least-squares solution at the current estimate.
fn fit(data: &Data, names: &[String]) -> Estimate {
    let mut est = start(data);
    for _ in 0..ITERATIONS {
        est = from_ls(&iteration(&est, data, names).theta);
    }
    est
}

fn oe_factor(data: &Data, truth: &Estimate) -> (TriangularFactor, f64) {
    cascade_oe_factor(&truth.linear, &truth.backlash, &data.u, &data.y, 0).expect("oe factor")
}

/// A fit that does not end near the truth means the bench measures garbage: stop.
fn check_fit(est: &Estimate, truth: &Estimate, n: usize) -> f64 {
    let err = est.max_error(truth);
    assert!(
        err < MAX_ERROR,
        "fit at N = {n} ended {err:.3} from the truth (limit {MAX_ERROR}): {:?}",
        est.physical()
    );
    err
}

// -- criterion -------------------------------------------------------------------------------

const MEASUREMENTS: [&str; 3] = ["iteration", "fit", "oe_factor"];

fn criterion_groups(c: &mut Criterion) {
    let (truth, est, names) = (truth(), perturbed(), ls_names());
    let data: Vec<Data> = CRITERION_SIZES.iter().map(|&n| example_data(n)).collect();
    for (d, &n) in data.iter().zip(&CRITERION_SIZES) {
        check_fit(&fit(d, &names), &truth, n);
    }
    for name in MEASUREMENTS {
        let mut group = c.benchmark_group(format!("identify/{name}"));
        // A fit at N = 1e6 takes seconds: few, flat samples keep the run short.
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(2));
        for (d, &n) in data.iter().zip(&CRITERION_SIZES) {
            group.throughput(Throughput::Elements(n as u64));
            group.bench_with_input(BenchmarkId::from_parameter(n), d, |b, d| match name {
                "iteration" => b.iter(|| iteration(black_box(&est), black_box(d), &names)),
                "fit" => b.iter(|| fit(black_box(d), &names)),
                "oe_factor" => b.iter(|| oe_factor(black_box(d), &truth)),
                _ => unreachable!("unknown measurement {name}"),
            });
        }
        group.finish();
    }
}

// -- the table -------------------------------------------------------------------------------

/// A "kB" field of /proc/self/status in MiB; None off Linux or if it is missing.
fn status_mib(field: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    let kb: f64 = line[field.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

/// Reset the peak resident set size (VmHWM) to the current one; false if not possible.
fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// One measurement: best time per sample over `runs` runs, and the peak resident memory
/// over all of them, total and above the resident memory before (the inputs and whatever
/// the process already held).
struct Measured {
    ns_per_sample: f64,
    seconds: f64,
    peak_mib: Option<f64>,
    beyond_mib: Option<f64>,
}

fn measure<T>(n: usize, runs: usize, mut f: impl FnMut() -> T) -> (Measured, T) {
    let reset = reset_peak();
    let before = status_mib("VmRSS:");
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..runs {
        let t = Instant::now();
        let value = black_box(f());
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(value);
    }
    let peak = status_mib("VmHWM:").filter(|_| reset);
    let measured = Measured {
        ns_per_sample: best * 1e9 / n as f64,
        seconds: best,
        peak_mib: peak,
        beyond_mib: peak.zip(before).map(|(p, b)| p - b),
    };
    (measured, out.expect("at least one run"))
}

fn mib(v: Option<f64>) -> String {
    v.map_or("n/a".to_string(), |v| format!("{v:.1}"))
}

fn print_row(n: usize, what: &str, runs: usize, m: &Measured, note: &str) {
    println!(
        "{n:>10.0e} {what:<20} {runs:>4} {:>10.1} {:>9.3} {:>9} {:>9} {:>9.1}  {note}",
        m.ns_per_sample,
        m.seconds,
        mib(m.peak_mib),
        mib(m.beyond_mib),
        (16 * n) as f64 / (1024.0 * 1024.0),
    );
}

/// The largest N of the table: `BACKLASHID_BENCH_MAX_N` (e.g. "1e7"), default 1e8.
fn max_n() -> usize {
    match std::env::var(MAX_N_VAR) {
        Ok(s) => match s.trim().parse::<f64>() {
            Ok(v) if v >= 1.0 => v as usize,
            _ => {
                eprintln!("{MAX_N_VAR} = {s:?} is not a sample count; using {DEFAULT_MAX_N:e}");
                DEFAULT_MAX_N
            }
        },
        Err(_) => DEFAULT_MAX_N,
    }
}

fn print_table() {
    let (truth, est, names) = (truth(), perturbed(), ls_names());
    let max_n = max_n();
    println!(
        "\nidentification ns/sample and peak memory (Example 1, SNR {SNR}, p = {}, {} \
         thread(s); best of {SMALL_RUNS} runs for N < {ONE_RUN_FROM:.0e}, one run from there)",
        names.len(),
        default_threads(),
    );
    println!(
        "{:>10} {:<20} {:>4} {:>10} {:>9} {:>9} {:>9} {:>9}",
        "N", "measurement", "runs", "ns/sample", "seconds", "peak MiB", "+MiB", "u+y MiB"
    );
    for n in TABLE_SIZES.into_iter().filter(|&n| n <= max_n) {
        let data = example_data(n);
        let runs = if n < ONE_RUN_FROM { SMALL_RUNS } else { 1 };
        let (m, _) = measure(n, runs, || iteration(&est, &data, &names));
        print_row(n, "iteration", runs, &m, "");
        let projected = m.seconds * (ITERATIONS + 1) as f64;
        let fit_label = format!("fit ({ITERATIONS} iterations)");
        if projected > FIT_BUDGET.as_secs_f64() {
            println!(
                "{n:>10.0e} {fit_label:<20}    -  not run: projected {projected:.0} s > \
                 {} s; the iteration row above is the per-iteration cost",
                FIT_BUDGET.as_secs()
            );
        } else {
            let (m, est) = measure(n, runs, || fit(&data, &names));
            let err = check_fit(&est, &truth, n);
            print_row(n, &fit_label, runs, &m, &format!("max |error| {err:.4}"));
        }
        let (m, _) = measure(n, runs, || oe_factor(&data, &truth));
        print_row(n, "oe_factor", runs, &m, "");
    }
    println!(
        "peak MiB: VmHWM over the runs (reset through /proc/self/clear_refs); +MiB: peak minus \
         the resident memory before the runs (u and y already in; memory the allocator kept \
         from earlier frees is reused, so small N can read 0); u+y MiB: the inputs"
    );
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    criterion_groups(&mut c);
    c.final_summary();

    // `cargo test --benches` runs this binary without `--bench`: skip the timed table there.
    if std::env::args().any(|a| a == "--bench") {
        print_table();
    }
}
