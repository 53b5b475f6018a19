//! Runtime choice between the scalar kernels and their SIMD paths (issue 34).
//!
//! The scalar kernels are those of `texsense-kernels` (shared with the microcontroller
//! build, which never sees this module). On x86-64 a processor with AVX2 runs the Preisach
//! kernel across elements (four elements in the lanes of one register:
//! `preisach::avx2`), the drift kernel on the time clock across elements (one kernel
//! term of four elements per register: `drift::avx2`) and the conversion across elements
//! (`convert::avx2`); all give the scalar kernels' results bit for bit (no fused
//! multiply-add, the same operations in the same order; property tests in
//! `preisach/tests.rs`, `drift/tests.rs` and `convert/avx2.rs`). A processor with AVX-512
//! F/DQ/VL runs the same three in eight f64 lanes (`preisach::avx512`, `drift::avx512`,
//! `convert::avx512`; the same bits, tested against the scalar kernels and the AVX2 path
//! forced by [`set_limit`]), and the detector's two passes (`detect::avx512`); the chain's
//! glue between kernels ([`crate::lanes`]) has eight- and four-lane paths. Elsewhere, or
//! after [`set_enabled`]`(false)`, the scalar kernels run.
//!
//! The choice is made per call from a flag and the CPU detection that `std` caches
//! (`is_x86_feature_detected!`), so switching it between two batches is safe. Where the
//! AVX-512 kernels read memory at each lane's own place, [`lookup`] chooses between gathers
//! and loads per lane ([`loads`]) by the processor's vendor, as fast as each is there.

use std::sync::atomic::{AtomicU8, Ordering};

#[cfg(target_arch = "x86_64")]
pub mod loads;

/// The best path batches may take ([`Path`] as `u8`; [`set_limit`]).
static LIMIT: AtomicU8 = AtomicU8::new(Path::Avx512 as u8);

/// The kernel path a batch runs on (ordered: each path's processor has the ones before).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Path {
    /// The scalar kernels of `texsense-kernels`.
    Scalar = 0,
    /// AVX2 (x86-64): four f64 lanes.
    Avx2 = 1,
    /// AVX-512 F/DQ/VL (x86-64): eight f64 lanes and mask registers, for the kernels that
    /// have such a build (the Preisach row and the drift row); the others run on AVX2.
    Avx512 = 2,
}

impl Path {
    /// `"scalar"`, `"avx2"` or `"avx512"`.
    pub fn name(self) -> &'static str {
        match self {
            Path::Scalar => "scalar",
            Path::Avx2 => "avx2",
            Path::Avx512 => "avx512",
        }
    }

    fn of(v: u8) -> Path {
        match v {
            0 => Path::Scalar,
            1 => Path::Avx2,
            _ => Path::Avx512,
        }
    }
}

/// The best path this processor has (whether allowed or not).
pub fn detected() -> Path {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx512f") && has!("avx512dq") && has!("avx512vl") && has!("avx2") {
            return Path::Avx512;
        }
        if has!("avx2") {
            return Path::Avx2;
        }
    }
    Path::Scalar
}

/// [`detected`] as `u8`, found once ([`UNKNOWN`] before): the kernels ask for the path
/// per block and row of a frame, where four feature tests each were a measurable share of
/// a live step (issue 34, sixteenth round).
static DETECTED: AtomicU8 = AtomicU8::new(UNKNOWN);

/// [`DETECTED`] not yet found.
const UNKNOWN: u8 = u8::MAX;

/// The path batches run on now: [`detected`], at most the limit of [`set_limit`].
#[inline]
pub fn path() -> Path {
    let mut best = DETECTED.load(Ordering::Relaxed);
    if best == UNKNOWN {
        best = detected() as u8;
        DETECTED.store(best, Ordering::Relaxed);
    }
    Path::of(best.min(LIMIT.load(Ordering::Relaxed)))
}

/// Allow (default) or forbid the SIMD paths, process-wide (for benchmarks and tests that
/// compare the two paths on the same input): `set_limit(Avx512)` or `set_limit(Scalar)`.
pub fn set_enabled(on: bool) {
    set_limit(if on { Path::Avx512 } else { Path::Scalar });
}

/// The best path batches may take from now on, process-wide (`Avx2` forces the AVX2
/// kernels on an AVX-512 processor, for tests and the benchmark).
pub fn set_limit(best: Path) {
    LIMIT.store(best as u8, Ordering::Relaxed);
}

/// True when batches run on AVX2 (or better) now: the AVX2 kernels serve where no AVX-512
/// build exists.
#[inline]
pub fn avx2() -> bool {
    path() >= Path::Avx2
}

/// True when batches run on AVX-512 now.
#[inline]
pub fn avx512() -> bool {
    path() == Path::Avx512
}

/// How the AVX-512 kernels read memory at eight lanes' own places (the Everett cell of each
/// element and a few lanes' stack slots in the Preisach row, the segment of each input on
/// the conversion's curve): both give the same values, bit for bit; which is faster depends
/// on the processor (issue 34, eighteenth round).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lookup {
    /// A gather instruction per value: the faster on the Intel Xeon of the eighth round
    /// (1.14 x the Preisach kernel against loads per lane).
    Gather,
    /// A load per lane of the lane's entries, stored side by side (the table by cell), and
    /// a transpose across the lanes: the faster on AMD processors (on a Zen 5 four gathers
    /// of eight f64 take four times as long as eight 32-byte loads and the transpose,
    /// `examples/gather_time.rs`; the Preisach kernel 1.07-1.33 x against gathers).
    Loads,
}

impl Lookup {
    /// Both lookups.
    pub const ALL: [Lookup; 2] = [Lookup::Gather, Lookup::Loads];

    /// `"gather"` or `"loads"`.
    pub fn name(self) -> &'static str {
        match self {
            Lookup::Gather => "gather",
            Lookup::Loads => "loads",
        }
    }

    /// The lookup of that [`Lookup::name`], if any.
    pub fn from_name(name: &str) -> Option<Lookup> {
        Self::ALL.into_iter().find(|l| l.name() == name)
    }
}

/// The lookup of [`set_lookup`] ([`Lookup`] as `u8`), or [`UNKNOWN`]: the processor's
/// ([`detected_lookup`]).
static LOOKUP: AtomicU8 = AtomicU8::new(UNKNOWN);

/// The faster lookup of this processor: [`Lookup::Loads`] on an AMD processor (its vendor
/// string), [`Lookup::Gather`] elsewhere.
pub fn detected_lookup() -> Lookup {
    #[cfg(target_arch = "x86_64")]
    {
        // (an unsafe function in older Rust, a safe one in newer)
        #[allow(unused_unsafe)]
        // SAFETY: every x86-64 processor has the `cpuid` instruction and its leaf 0
        let vendor = unsafe { std::arch::x86_64::__cpuid(0) };
        // "AuthenticAMD" in ebx, edx, ecx
        if (vendor.ebx, vendor.edx, vendor.ecx) == (0x6874_7541, 0x6974_6E65, 0x444D_4163) {
            return Lookup::Loads;
        }
    }
    Lookup::Gather
}

/// The lookup the AVX-512 kernels use now: [`set_lookup`]'s, else [`detected_lookup`]
/// (found once: the Preisach row asks per row of a block).
#[inline]
pub fn lookup() -> Lookup {
    let mut chosen = LOOKUP.load(Ordering::Relaxed);
    if chosen == UNKNOWN {
        chosen = DETECTED_LOOKUP.load(Ordering::Relaxed);
        if chosen == UNKNOWN {
            chosen = detected_lookup() as u8;
            DETECTED_LOOKUP.store(chosen, Ordering::Relaxed);
        }
    }
    if chosen == Lookup::Gather as u8 {
        Lookup::Gather
    } else {
        Lookup::Loads
    }
}

/// [`detected_lookup`], found once ([`UNKNOWN`] before).
static DETECTED_LOOKUP: AtomicU8 = AtomicU8::new(UNKNOWN);

/// The lookup the AVX-512 kernels use from now on, process-wide (`None`: the processor's
/// faster one), for tests and the benchmark that compare the two.
pub fn set_lookup(lookup: Option<Lookup>) {
    LOOKUP.store(lookup.map_or(UNKNOWN, |l| l as u8), Ordering::Relaxed);
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
