//! Timing of the drift row (eq. 5.8, time clock, 14 kernel terms) on a smooth load, for
//! profiling: `cargo run --release -p texsense-core --example drift_time -- [avx512|avx2|scalar|f32|f32-scalar] [T] [N]`
//! (`f32`: the experimental float32 bank, eight lanes), frame after frame on one thread.

mod common;
use common::{cpu, use_path};

use texsense_core::drift::f32x8::Drift32;
use texsense_core::drift::{DriftBank, Kernel};
use texsense_core::par::block_size;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = use_path(&args);
    let f32 = path.starts_with("f32");
    let t: usize = args.get(2).map_or(1000, |s| s.parse().unwrap());
    let n: usize = args.get(3).map_or(4096, |s| s.parse().unwrap());
    let k = 14;
    let weights: Vec<f64> = (0..k).map(|j| 0.02 + 0.01 * j as f64).collect();
    let taus: Vec<f64> = (0..14).map(|j| 2f64.powi(j)).collect();
    let gamma = -0.0045;
    let mut bank = DriftBank::new(
        Kernel::new(weights.clone(), taus.clone()).unwrap(),
        gamma,
        n,
    )
    .unwrap();
    let mut bank32 = Drift32::new(&weights, &taus, gamma, n).unwrap();
    let dt = 0.1;
    let h: Vec<f64> = (0..t * n)
        .map(|q| 1.2 + 0.8 * ((q / n) as f64 / 30.0 + (q % n) as f64 / 50.0).sin())
        .collect();
    let ok = vec![true; n];
    let mut out = vec![0.0; t * n];
    let reps: usize = std::env::var("REPS").ok().map_or(5, |s| s.parse().unwrap());
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        bank.reset();
        bank32.reset();
        let s = cpu();
        for (f, o) in h.chunks_exact(n).zip(out.chunks_exact_mut(n)) {
            if f32 {
                bank32.row(dt, f, &ok, o);
            } else {
                bank.prepare(dt);
                let (mut start, size) = (0, block_size(n));
                for mut b in bank.blocks() {
                    let m = size.min(n - start);
                    b.frame(dt);
                    b.row(dt, &f[start..start + m], &ok[..m], &mut o[start..start + m]);
                    start += m;
                }
            }
        }
        best = best.min(cpu() - s);
    }
    let sum: f64 = out.iter().sum();
    println!(
        "{path}: {:.1} M element-steps/s (best of {reps}), checksum {sum:.6e}",
        (t * n) as f64 / best / 1e6
    );
}
