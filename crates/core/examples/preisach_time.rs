//! Timing of the Preisach bank on a random walk (the benchmark's input shape), for profiling:
//! `cargo run --release -p texsense-core --example preisach_time -- [avx512|avx2|scalar|f32] [frames|blocks] [T] [N] [K]`
//! (`f32`: the experimental float32 bank, eight lanes, frame order; `f32-scalar`: its
//! scalar kernel; `K`: the Everett grid's points, 100 by default; `SHAPE=walk|alike|ramp`:
//! the input, `shape`).

mod common;
use common::{cpu, use_path};

use texsense_core::preisach::f32x8::Bank32;
use texsense_core::preisach::{Everett, PreisachBank, Schedule};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = use_path(&args);
    let f32 = path.starts_with("f32");
    let schedule = match args.get(2).map_or("frames", |s| s) {
        "blocks" => Schedule::Blocks,
        "parallel" => Schedule::Parallel,
        _ => Schedule::FrameOrder,
    };
    let t: usize = args.get(3).map_or(4000, |s| s.parse().unwrap());
    let n: usize = args.get(4).map_or(4096, |s| s.parse().unwrap());
    let k: usize = args.get(5).map_or(100, |s| s.parse().unwrap());
    let (lo, hi) = (0.0, 2.212);
    let mut table = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..i {
            let d = (i - j) as f64 / (k - 1) as f64;
            table[i * k + j] = 0.5 * d * d + 0.2 * d + 0.01 * (j as f64 / k as f64);
        }
    }
    let e = Everett::new(k, lo, hi, table).unwrap();
    let mut bank32 = Bank32::new(&e, n).unwrap();
    let mut bank = PreisachBank::new(e, n, 64).unwrap();
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut rnd = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let span = hi - lo;
    let mut w = vec![0.0; n];
    let mut inputs = vec![0.0; t * n];
    for f in 0..t {
        for i in 0..n {
            // about N(0, 0.02): a sum of three uniforms
            let s = (rnd() + rnd() + rnd() - 1.5) * 0.04;
            w[i] = (w[i] + s).abs() % (2.0 * span);
            let x = if w[i] > span { 2.0 * span - w[i] } else { w[i] };
            inputs[f * n + i] = lo + x;
        }
    }
    shape(&mut inputs, t, n, lo, hi);
    let valid = vec![true; t * n];
    let mut out = vec![0.0; t * n];
    let reps: usize = std::env::var("REPS").ok().map_or(5, |s| s.parse().unwrap());
    let mut best = f64::INFINITY;
    for _ in 0..reps {
        bank.reset();
        bank32.reset();
        let s = cpu();
        if f32 {
            for ((u, v), o) in inputs
                .chunks_exact(n)
                .zip(valid.chunks_exact(n))
                .zip(out.chunks_exact_mut(n))
            {
                bank32.row(u, v, o);
            }
        } else {
            bank.run_scheduled(&inputs, &valid, &mut out, schedule)
                .unwrap();
        }
        best = best.min(cpu() - s);
    }
    let sum: f64 = out.iter().filter(|v| v.is_finite()).sum();
    println!(
        "{path} {:?}: {:.1} M/s (best of {reps}), checksum {sum:.6e}",
        if f32 { Schedule::FrameOrder } else { schedule },
        (t * n) as f64 / best / 1e6
    );
    let mut copy = vec![1.0; t * n];
    let s = cpu();
    for (o, i) in copy.iter_mut().zip(&inputs) {
        *o = *i * 1.0;
    }
    std::hint::black_box(&copy);
    println!("copy: {:.0} M/s", (t * n) as f64 / (cpu() - s) / 1e6);
}

/// The input's shape by the environment's `SHAPE`: `walk` (each element its own random walk,
/// the default), `alike` (element 0's walk in every element), `ramp` (rising, never turning).
fn shape(inputs: &mut [f64], t: usize, n: usize, lo: f64, hi: f64) {
    match std::env::var("SHAPE").as_deref() {
        Ok("walk") | Ok("") | Err(_) => {}
        Ok("alike") => {
            for row in inputs.chunks_exact_mut(n) {
                let v = row[0];
                row.fill(v);
            }
        }
        Ok("ramp") => {
            for (f, row) in inputs.chunks_exact_mut(n).enumerate() {
                row.fill(lo + (hi - lo) * f as f64 / t as f64);
            }
        }
        Ok(other) => {
            eprintln!("SHAPE={other:?}: one of walk, alike, ramp");
            std::process::exit(2);
        }
    }
}
