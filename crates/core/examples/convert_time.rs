//! Timing of the conversion row (eq. 2.1) with a material curve of 200 unevenly spaced
//! points, for profiling: `cargo run --release -p texsense-core --example convert_time --
//! [avx512|avx2|scalar] [T] [N]`, frame after frame on one thread (`REPS`: best of).

mod common;
use common::{cpu, use_path};

use texsense_core::{Converter, Curve};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = use_path(&args);
    let t: usize = args.get(2).map_or(4000, |s| s.parse().unwrap());
    let n: usize = args.get(3).map_or(1024, |s| s.parse().unwrap());
    // points dense at low capacitance, 25 times wider at the top (as the seat's curve)
    let x: Vec<f64> = (0..200)
        .map(|k| 2.5 + 6.7 * (k as f64 / 199.0).powf(1.8))
        .collect();
    let y: Vec<f64> = x.iter().map(|c| (c - 2.5).sqrt()).collect();
    let curve = Curve::new(x, y).unwrap();
    let offset: Vec<f64> = (0..n).map(|i| 0.01 * (i % 7) as f64).collect();
    let gain: Vec<f64> = (0..n).map(|i| 1.0 + 0.001 * (i % 11) as f64).collect();
    let conv = Converter::new(offset, gain, Some(curve)).unwrap();
    let h: Vec<f64> = (0..t * n)
        .map(|q| 5.5 + 3.5 * ((q / n) as f64 / 30.0 + (q % n) as f64 / 50.0).sin())
        .collect();
    let ok = vec![true; n];
    let mut out = vec![0.0; t * n];
    let reps: usize = std::env::var("REPS").ok().map_or(5, |s| s.parse().unwrap());
    let mut best = f64::INFINITY;
    let view = conv.view();
    for _ in 0..reps {
        let s = cpu();
        for (f, o) in h.chunks_exact(n).zip(out.chunks_exact_mut(n)) {
            view.row(0, f, &ok, o);
        }
        best = best.min(cpu() - s);
    }
    let sum: f64 = out.iter().sum();
    println!(
        "{path}: {:.1} M element-steps/s (best of {reps}), checksum {sum:.6e}",
        (t * n) as f64 / best / 1e6
    );
}
