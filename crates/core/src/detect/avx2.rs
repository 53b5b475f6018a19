//! The codes (pass 2) of four neighbouring elements at once in AVX2 lanes, for the common
//! case in which none of the four readings holds still (then `kernel::code` reads no
//! neighbour movement and clears the stillness counters, so no stuck code can arise). The
//! comparisons are the kernel's, on the same products, so the same codes; a group with a
//! reading that holds still goes to the scalar kernel.

use std::arch::x86_64::*;

use texsense_kernels::detect::{codes, Element};

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

/// The per-element limits of a block's elements (as [`Limits4`], one value per element).
pub(super) struct RowLimits<'a> {
    pub(super) jump: &'a [f64],
    pub(super) baseline: Option<&'a [f64]>,
    pub(super) max: Option<&'a [f64]>,
}

/// Lane `l`'s bit of `m` (0..=15) at bit 0 of byte `l` (the four bits land on distinct
/// bits of the product, so no carry mixes them).
#[inline(always)]
fn spread(m: u32) -> u32 {
    m.wrapping_mul(0x0020_4081) & 0x0101_0101
}

/// The codes of a block's row (whole groups of four; readings `c`, their changes `d` and
/// validity `valid`, the elements' states `els`) into `out`, every group in lanes in which
/// no reading holds still (as [`moving`], without a call per group: the validity of four
/// readings read as one word, the four codes written as one). Returns the groups left to
/// the scalar kernel (bit `g`: elements `4 g .. 4 g + 4`; nothing of them written).
///
/// # Safety
/// The processor must have AVX2.
///
/// # Panics
/// When the slices differ in length, are not whole groups, or hold more than 32 groups.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn codes_row(
    p: &DetectorParams,
    lim: &RowLimits<'_>,
    c: &[f64],
    d: &[f64],
    valid: &[bool],
    els: &mut [Element<f64>],
    out: &mut [u8],
) -> u32 {
    let w = c.len();
    assert!(w.is_multiple_of(LANES) && w <= 32 * LANES);
    assert!(d.len() == w && valid.len() == w && els.len() == w && out.len() == w);
    assert!(lim.jump.len() == w);
    assert!(lim.baseline.is_none_or(|b| b.len() == w) && lim.max.is_none_or(|m| m.len() == w));
    let (stuck, floor) = (_mm256_set1_pd(p.stuck_pf), _mm256_set1_pd(p.stuck_floor_pf));
    let (high_share, low_share) = (_mm256_set1_pd(p.high_share), _mm256_set1_pd(p.low_share));
    let min_pf = _mm256_set1_pd(p.min_pf);
    let mut left = 0u32;
    for g in 0..w / LANES {
        let i = g * LANES;
        // SAFETY: i + LANES <= w, the length of every slice (checked above)
        let load = |s: &[f64]| unsafe { _mm256_loadu_pd(s.as_ptr().add(i)) };
        let (cv, dv) = (load(c), load(d));
        let still = _mm256_and_pd(
            _mm256_cmp_pd::<_CMP_LE_OQ>(dv, stuck),
            _mm256_cmp_pd::<_CMP_GT_OQ>(cv, floor),
        );
        if _mm256_movemask_pd(still) != 0 {
            left |= 1 << g;
            continue;
        }
        let jump = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(dv, load(lim.jump))) as u32;
        let mut high = 0;
        if let Some(m) = lim.max {
            let top = _mm256_mul_pd(high_share, load(m));
            high = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(cv, top)) as u32;
        }
        let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(cv, cv), _mm256_setzero_pd());
        let at_min = _mm256_cmp_pd::<_CMP_LE_OQ>(cv, min_pf);
        let mut low =
            (!_mm256_movemask_pd(finite) as u32 & 0xf) | _mm256_movemask_pd(at_min) as u32;
        if let Some(b) = lim.baseline {
            let floor = _mm256_mul_pd(low_share, load(b));
            low |= _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(cv, floor)) as u32;
        }
        // the four validity bytes (0 or 1) as lane bits: each byte's bit lands on a
        // distinct bit of the product's top byte, without carries
        let bytes =
            u32::from_le_bytes([valid[i], valid[i + 1], valid[i + 2], valid[i + 3]].map(u8::from));
        let ok = (bytes.wrapping_mul(0x0102_0408) >> 24) & 0xf;
        // the later rule wins, as in kernel::code: short/break, then out of range, then jump
        let high = (high | !ok & 0xf) & !low;
        let jump = jump & !low & !high;
        let word = (spread(low) * u32::from(codes::SHORT_OR_BREAK))
            | (spread(high) * u32::from(codes::OUT_OF_RANGE))
            | (spread(jump) * u32::from(codes::JUMP));
        out[i..i + LANES].copy_from_slice(&word.to_le_bytes());
        for el in &mut els[i..i + LANES] {
            // kernel::code for a reading that does not hold still
            el.still = 0;
            el.moved = 0.0;
        }
    }
    left
}

/// The change of each reading since the element's last finite one (`kernel::change`: NaN
/// after no finite reading; the last reading kept where finite), four elements at a time.
///
/// # Safety
/// The processor must have AVX2.
///
/// # Panics
/// When the slices differ in length.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn changes_row(els: &mut [Element<f64>], c: &[f64], d: &mut [f64]) {
    let w = c.len();
    assert!(els.len() == w && d.len() == w);
    let whole = w / LANES * LANES;
    let abs = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
    for i in (0..whole).step_by(LANES) {
        let e = &mut els[i..i + LANES];
        // SAFETY: i + LANES <= whole <= w
        let cv = unsafe { _mm256_loadu_pd(c.as_ptr().add(i)) };
        let last = _mm256_set_pd(e[3].last, e[2].last, e[1].last, e[0].last);
        // |c - last| as the kernel's `abs` (the sign bit cleared)
        let dv = _mm256_and_pd(_mm256_sub_pd(cv, last), abs);
        // SAFETY: as the load
        unsafe { _mm256_storeu_pd(d.as_mut_ptr().add(i), dv) };
        let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(cv, cv), _mm256_setzero_pd());
        let mut kept = [0.0; LANES];
        _mm256_storeu_pd(kept.as_mut_ptr(), _mm256_blendv_pd(last, cv, finite));
        for (el, k) in e.iter_mut().zip(kept) {
            el.last = k;
        }
    }
    for i in whole..w {
        d[i] = texsense_kernels::detect::change(&mut els[i], c[i]);
    }
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
