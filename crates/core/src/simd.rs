//! Runtime choice between the scalar kernels and their SIMD paths (issue 34).
//!
//! The scalar kernels are those of `texsense-kernels` (shared with the microcontroller
//! build, which never sees this module). On x86-64 a processor with AVX2 runs the Preisach
//! kernel across elements (four elements in the lanes of one register:
//! `preisach::avx2`), the drift kernel on the time clock across elements (one kernel
//! term of four elements per register: `drift::avx2`) and the conversion across elements
//! (`convert::avx2`); all give the scalar kernels' results bit for bit (no fused
//! multiply-add, the same operations in the same order; property tests in
//! `preisach/tests.rs`, `drift/tests.rs` and `convert/avx2.rs`). Elsewhere, or after [`set_enabled`]`(false)`, the scalar kernels run.
//!
//! The choice is made per call from a flag and the CPU detection that `std` caches
//! (`is_x86_feature_detected!`), so switching it between two batches is safe.

use std::sync::atomic::{AtomicBool, Ordering};

static ENABLED: AtomicBool = AtomicBool::new(true);

/// The kernel path a batch runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// The scalar kernels of `texsense-kernels`.
    Scalar,
    /// AVX2 (x86-64): four f64 lanes.
    Avx2,
}

impl Path {
    /// `"scalar"` or `"avx2"`.
    pub fn name(self) -> &'static str {
        match self {
            Path::Scalar => "scalar",
            Path::Avx2 => "avx2",
        }
    }
}

/// The best path this processor has (whether enabled or not).
pub fn detected() -> Path {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            return Path::Avx2;
        }
    }
    Path::Scalar
}

/// The path batches run on now: [`detected`] unless disabled by [`set_enabled`].
#[inline]
pub fn path() -> Path {
    if ENABLED.load(Ordering::Relaxed) {
        detected()
    } else {
        Path::Scalar
    }
}

/// Allow (default) or forbid the SIMD paths, process-wide (for benchmarks and tests that
/// compare the two paths on the same input).
pub fn set_enabled(on: bool) {
    ENABLED.store(on, Ordering::Relaxed);
}

/// True when batches run on AVX2 now.
#[inline]
pub fn avx2() -> bool {
    path() == Path::Avx2
}

#[cfg(test)]
pub(crate) mod testing {
    use std::sync::{Mutex, MutexGuard};

    /// Tests that switch the path hold this lock (the flag is process-wide and tests run
    /// on several threads).
    pub(crate) fn lock() -> MutexGuard<'static, ()> {
        static LOCK: Mutex<()> = Mutex::new(());
        LOCK.lock().unwrap_or_else(|e| e.into_inner())
    }
}
