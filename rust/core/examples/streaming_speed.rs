//! Time per sample of the streaming regressions and output-error factor against the dense
//! path (regressor matrix + QR). Run: cargo run --release -p backlashid-core --example
//! streaming_speed [N...]
use backlashid_core::identify::regressor::{CascadeRegression, SandwichRegression};
use backlashid_core::identify::sensitivity::{
    cascade_oe_factor_threads, cascade_sensitivity, sandwich_oe_factor_threads,
};
use backlashid_core::{CascadeModel, SandwichModel};

#[path = "../src/test_params.rs"]
mod test_params;
#[path = "common/timing.rs"]
mod timing;
use test_params::{example1, example2, input, names};
use timing::{best, sizes};

/// The solve before this change: column-scaled N x p matrix, faer QR, explicit residual.
fn faer_dense(a: &[f64], rows: usize, p: usize, b: &[f64]) -> Vec<f64> {
    use faer::linalg::solvers::SolveLstsq;
    let mut scale = vec![0.0; p];
    for r in 0..rows {
        for j in 0..p {
            scale[j] += a[r * p + j] * a[r * p + j];
        }
    }
    let scale: Vec<f64> = scale.iter().map(|s: &f64| s.sqrt()).collect();
    let m = faer::Mat::<f64>::from_fn(rows, p, |r, j| a[r * p + j] / scale[j]);
    let rhs = faer::Mat::<f64>::from_fn(rows, 1, |r, _| b[r]);
    let sol = m.qr().solve_lstsq(rhs.as_ref());
    (0..p).map(|j| sol[(j, 0)] / scale[j]).collect()
}

fn main() {
    let sizes = sizes(&[1_000_000, 10_000_000]);
    let (lin, bl) = example1();
    let (l2, b2, o2) = example2();
    let names = names(14);
    println!("ns per sample (best of reps); cascade p = 11, sandwich p = 14");
    for &n in &sizes {
        let u = input(n);
        let m = CascadeModel::new(lin.clone(), bl.clone());
        let y = m.simulate(&u, &m.rest_state()).unwrap();
        let sm = SandwichModel::new(l2.clone(), b2.clone(), o2.clone());
        let w = sm.simulate(&u, &sm.rest_state()).unwrap();
        let reps = if n <= 2_000_000 { 3 } else { 1 };
        println!("N = {n:e}");
        if n <= 2_000_000 {
            let t = best(reps, n, || {
                let reg = CascadeRegression::new(&lin, &bl, &u, &y, &y)
                    .unwrap()
                    .dense(0);
                reg.solve(&names[..11], 0).unwrap()
            });
            println!("  cascade dense (regression + lstsq::solve): {t:7.1}");
            let t = best(reps, n, || {
                let reg = SandwichRegression::new(&l2, &b2, &o2, &u, &w)
                    .unwrap()
                    .dense(0);
                reg.solve(&names, 0).unwrap()
            });
            println!("  sandwich dense (regression + lstsq::solve): {t:6.1}");
            let t = best(reps, n, || {
                let reg = CascadeRegression::new(&lin, &bl, &u, &y, &y)
                    .unwrap()
                    .dense(0);
                faer_dense(&reg.phi, reg.rows, reg.cols, &reg.target)
            });
            println!("  cascade dense, faer QR of N x p (before):  {t:7.1}");
            let t = best(reps, n, || cascade_sensitivity(&lin, &bl, &u).unwrap());
            println!("  cascade dense sensitivity (J only, no QR): {t:7.1}");
        }
        for threads in [1, 2] {
            let t = best(reps, n, || {
                let (f, _) = CascadeRegression::new(&lin, &bl, &u, &y, &y)
                    .unwrap()
                    .factor_threads(0, threads);
                f.solve(&names[..11]).unwrap()
            });
            println!("  cascade_factor + solve, {threads} thread(s):    {t:7.1}");
        }
        for threads in [1, 2] {
            let t = best(reps, n, || {
                let (f, _) = SandwichRegression::new(&l2, &b2, &o2, &u, &w)
                    .unwrap()
                    .factor_threads(0, threads);
                f.solve(&names).unwrap()
            });
            println!("  sandwich_factor + solve, {threads} thread(s):   {t:7.1}");
        }
        for threads in [1, 2] {
            let t = best(reps, n, || {
                cascade_oe_factor_threads(&lin, &bl, &u, &y, 0, threads).unwrap()
            });
            println!("  cascade_oe_factor, {threads} thread(s):         {t:7.1}");
        }
        for threads in [1, 2] {
            let t = best(reps, n, || {
                sandwich_oe_factor_threads(&l2, &b2, &o2, &u, &w, 0, threads).unwrap()
            });
            println!("  sandwich_oe_factor, {threads} thread(s):        {t:7.1}");
        }
    }
}
