//! The codes (pass 2) of four neighbouring elements at once in AVX2 lanes, for the common
//! case in which none of the four readings holds still (then `kernel::code` reads no
//! neighbour movement and clears the stillness counters, so no stuck code can arise). The
//! comparisons are the kernel's, on the same products, so the same codes; a group with a
//! reading that holds still goes to the scalar kernel.

use std::arch::x86_64::*;

use texsense_kernels::detect::codes;

use super::DetectorParams;

/// Lanes of a register.
pub(super) const LANES: usize = 4;

/// The per-element limits of the four elements: jump limit, unloaded and largest expected
/// reading (if the detector has them).
pub(super) struct Limits4<'a> {
    pub(super) jump: &'a [f64],
    pub(super) baseline: Option<&'a [f64]>,
    pub(super) max: Option<&'a [f64]>,
}

/// The codes of readings `c` with their changes `d` and validity `valid` (four each), or
/// None when one of them holds still (`kernel::holds_still`; nothing computed). The caller
/// clears the four elements' stillness (`still = 0`, `moved = 0`) when it takes the codes.
///
/// # Safety
/// The processor must have AVX2.
///
/// # Panics
/// When a slice holds fewer than four values.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn moving(
    p: &DetectorParams,
    lim: &Limits4<'_>,
    c: &[f64],
    d: &[f64],
    valid: [bool; LANES],
) -> Option<[u8; LANES]> {
    let load = |s: &[f64]| _mm256_loadu_pd(s[..LANES].as_ptr());
    let (cv, dv) = (load(c), load(d));
    // holds still: a change that is a number at or below stuck_pf, above the floor
    let still = _mm256_and_pd(
        _mm256_cmp_pd::<_CMP_LE_OQ>(dv, _mm256_set1_pd(p.stuck_pf)),
        _mm256_cmp_pd::<_CMP_GT_OQ>(cv, _mm256_set1_pd(p.stuck_floor_pf)),
    );
    if _mm256_movemask_pd(still) != 0 {
        return None;
    }
    // a jump: a change beyond the limit (a first reading's change is NaN: never)
    let jump = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(dv, load(lim.jump)));
    let mut high = 0;
    if let Some(m) = lim.max {
        let top = _mm256_mul_pd(_mm256_set1_pd(p.high_share), load(m));
        high = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(cv, top));
    }
    let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(cv, cv), _mm256_setzero_pd());
    let at_min = _mm256_cmp_pd::<_CMP_LE_OQ>(cv, _mm256_set1_pd(p.min_pf));
    let mut low = (!_mm256_movemask_pd(finite) & 0xf) | _mm256_movemask_pd(at_min);
    if let Some(b) = lim.baseline {
        let floor = _mm256_mul_pd(_mm256_set1_pd(p.low_share), load(b));
        low |= _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(cv, floor));
    }
    let mut k = [codes::OK; LANES];
    for (lane, slot) in k.iter_mut().enumerate() {
        let bit = |m: i32| m >> lane & 1 != 0;
        // the later rule wins, as in kernel::code
        *slot = if bit(low) {
            codes::SHORT_OR_BREAK
        } else if !valid[lane] || bit(high) {
            codes::OUT_OF_RANGE
        } else if bit(jump) {
            codes::JUMP
        } else {
            codes::OK
        };
    }
    Some(k)
}
