//! Time per sample of the cascade's output-error gradient pass (forward simulation plus the
//! reverse recursion) beside the forward simulation alone and the streamed factor. Run:
//! cargo run --release -p backlashid-core --example gradient_speed [N...]
use backlashid_core::identify::gradient::cascade_oe_gradient_threads;
use backlashid_core::identify::sensitivity::cascade_oe_factor_threads;
use backlashid_core::CascadeModel;

#[path = "../src/test_params.rs"]
mod test_params;
#[path = "common/timing.rs"]
mod timing;
use test_params::{example1, input};
use timing::{best, sizes};

fn main() {
    let sizes = sizes(&[1_000_000]);
    let (lin, bl) = example1();
    println!("ns per sample (best of 9); cascade p = 11 (Example 1)");
    for &n in &sizes {
        let u = input(n);
        let m = CascadeModel::new(lin.clone(), bl.clone());
        let y = m.simulate(&u, &m.rest_state()).unwrap();
        if std::env::var_os("GRADIENT_ONLY").is_some() {
            let threads: usize = std::env::var("GRADIENT_ONLY").unwrap().parse().unwrap_or(1);
            let grad = best(60, n, || {
                cascade_oe_gradient_threads(&lin, &bl, &u, &y, 0, threads).unwrap()
            });
            println!("N = {n}: gradient {grad:.1} ({threads} threads)");
            continue;
        }
        let sim = best(9, n, || m.simulate(&u, &m.rest_state()).unwrap());
        let grad = best(9, n, || {
            cascade_oe_gradient_threads(&lin, &bl, &u, &y, 0, 1).unwrap()
        });
        let grad2 = best(9, n, || {
            cascade_oe_gradient_threads(&lin, &bl, &u, &y, 0, 2).unwrap()
        });
        let f1 = best(9, n, || {
            cascade_oe_factor_threads(&lin, &bl, &u, &y, 0, 1).unwrap()
        });
        let f2 = best(9, n, || {
            cascade_oe_factor_threads(&lin, &bl, &u, &y, 0, 2).unwrap()
        });
        println!("N = {n}: simulate {sim:.1}, gradient 1 thread {grad:.1}, 2 threads {grad2:.1}, factor 1 thread {f1:.1}, 2 threads {f2:.1}");
    }
}
