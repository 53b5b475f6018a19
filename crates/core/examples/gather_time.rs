//! What a gather of eight f64 costs on this processor against eight loads (issue 34,
//! eighteenth round): `cargo run --release -p texsense-core --example gather_time`.
//!
//! Four registers of eight values from random places of an 80 KB table (the Everett table
//! of a 100-point grid) per step, the places independent of the values read:
//! - by four gathers (`vgatherqpd`, every lane on);
//! - by eight loads of 32 bytes (each lane's four values side by side, as the table by
//!   cell) and a transpose (`texsense_core::simd::loads::rows_of_four`, the lookup the
//!   AVX-512 kernels use on AMD processors);
//!
//! and one gather after another, each place from the value the last one read (the
//! gather's latency, plus a conversion and a mask). Best of five, on the CPU clock.

mod common;
use common::cpu;

#[cfg(target_arch = "x86_64")]
fn main() {
    use std::arch::is_x86_feature_detected as has;
    if !(has!("avx512f") && has!("avx2")) {
        println!("this processor has no AVX-512: nothing to time");
        return;
    }
    // SAFETY: AVX-512 F and AVX2 detected above
    unsafe { time_all() };
}

#[cfg(not(target_arch = "x86_64"))]
fn main() {
    println!("x86-64 only: nothing to time");
}

/// Steps per timing.
#[cfg(target_arch = "x86_64")]
const STEPS: usize = 10_000_000;

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
unsafe fn time_all() {
    use std::arch::x86_64::*;
    use texsense_core::simd::loads::rows_of_four;
    let table: Vec<f64> = (0..10_000).map(|i| (i % 977) as f64).collect();
    // random places, each with room for four values after it
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let places: Vec<i64> = (0..4096)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % (table.len() as u64 - 4)) as i64
        })
        .collect();
    let t = table.as_ptr();
    let best = |f: &mut dyn FnMut() -> f64| {
        let mut best = f64::INFINITY;
        let mut sum = 0.0;
        for _ in 0..5 {
            let s = cpu();
            sum += f();
            best = best.min(cpu() - s);
        }
        (best / STEPS as f64 * 1e9, sum)
    };
    let (gathers, s1) = best(&mut || {
        let mut acc = _mm512_setzero_pd();
        for i in 0..STEPS {
            let at = _mm512_loadu_si512(places[(8 * i) % 4088..].as_ptr().cast());
            for k in 0..4 {
                let q = _mm512_add_epi64(at, _mm512_set1_epi64(k));
                acc = _mm512_add_pd(acc, _mm512_i64gather_pd::<8>(q, t));
            }
        }
        _mm512_reduce_add_pd(acc)
    });
    let (loads, s2) = best(&mut || {
        let mut acc = _mm512_setzero_pd();
        for i in 0..STEPS {
            let at = _mm512_loadu_si512(places[(8 * i) % 4088..].as_ptr().cast());
            // SAFETY: AVX-512 (this function's features); every place has four values
            // after it in the table
            for v in unsafe { rows_of_four(t, at) } {
                acc = _mm512_add_pd(acc, v);
            }
        }
        _mm512_reduce_add_pd(acc)
    });
    assert_eq!(s1, s2, "both ways read the same values");
    let (chain, _) = best(&mut || {
        let mut at = _mm512_loadu_si512(places.as_ptr().cast());
        let mut last = _mm512_setzero_pd();
        for _ in 0..STEPS {
            last = _mm512_i64gather_pd::<8>(at, t);
            at = _mm512_and_si512(_mm512_cvttpd_epi64(last), _mm512_set1_epi64(8191));
        }
        _mm512_reduce_add_pd(last)
    });
    println!("| four registers of eight f64 from random places | ns per step |");
    println!("|---|---:|");
    println!("| four gathers | {gathers:.2} |");
    println!("| eight loads of 32 bytes and a transpose | {loads:.2} |");
    println!("| gathers / loads | {:.2} x |", gathers / loads);
    println!(
        "| one gather after another (latency + conversion + mask), ns per gather | {chain:.2} |"
    );
}
