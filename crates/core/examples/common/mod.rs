//! What the timing examples share: the process's CPU clock and the SIMD path named by their
//! first argument.

use texsense_core::simd::{Lookup, Path};

extern "C" {
    fn clock_gettime(clock: i32, ts: *mut [i64; 2]) -> i32;
}

/// This process's CPU time in s (the machine is shared).
pub fn cpu() -> f64 {
    let mut ts = [0i64; 2];
    // SAFETY: CLOCK_PROCESS_CPUTIME_ID (2) into a timespec (two 64-bit fields on x86-64 Linux)
    unsafe { clock_gettime(2, &mut ts) };
    ts[0] as f64 + ts[1] as f64 * 1e-9
}

/// Limit the kernels to the path an example's first argument names (`avx2`, anything ending
/// in `scalar`, else AVX-512), and the AVX-512 kernels' table lookup to the environment's
/// `LOOKUP` (`gather` or `loads`; else the processor's); returns the argument (default
/// `avx512`).
#[allow(dead_code)] // not every example takes a path (`gather_time`)
pub fn use_path(args: &[String]) -> &str {
    texsense_core::simd::set_lookup(match std::env::var("LOOKUP").as_deref() {
        Ok("") | Err(_) => None,
        Ok(name) => Some(Lookup::from_name(name).unwrap_or_else(|| {
            eprintln!("LOOKUP={name:?}: one of gather, loads (or unset: the processor's)");
            std::process::exit(2);
        })),
    });
    let path = args.get(1).map_or("avx512", |s| s.as_str());
    texsense_core::simd::set_limit(match path {
        "avx2" => Path::Avx2,
        p if p.ends_with("scalar") => Path::Scalar,
        _ => Path::Avx512,
    });
    path
}
