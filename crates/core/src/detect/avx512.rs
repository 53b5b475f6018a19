//! The detector's two passes in eight AVX-512 lanes (issue 34, ninth round): `avx2.rs`'s
//! lane program on two groups of four at once, the conditions in mask registers. The
//! elements' states (`Element<f64>`, `repr(C)`: `last`, `still` and its padding, `moved`,
//! three words each) of eight elements are three 512-bit registers: the eight `last` words
//! come out of them by two permutes and go back by three masked stores, and a group's
//! stillness is cleared by masked stores of zeros — instead of a load or store per element.
//! The comparisons and products are the scalar kernel's, so the same changes, codes and
//! states (`detect/tests.rs` compares the paths).

use std::arch::x86_64::*;

use texsense_kernels::detect::{codes, Element};

use super::avx2::{self, RowLimits};
use super::DetectorParams;

/// Lanes of a register.
const LANES: usize = 8;

/// Words (8 bytes) of an element's state.
const WORDS: usize = 3;

const _: () = assert!(std::mem::size_of::<Element<f64>>() == WORDS * 8);

/// Lane bit `l` of `m` (four lanes) at bit 0 of byte `l` (distinct bits: no carries).
#[inline(always)]
fn spread4(m: u32) -> u32 {
    m.wrapping_mul(0x0020_4081) & 0x0101_0101
}

/// Lane bit `l` of `m` (eight lanes) at bit 0 of byte `l`.
#[inline(always)]
fn spread8(m: u8) -> u64 {
    u64::from(spread4(u32::from(m & 0xf))) | u64::from(spread4(u32::from(m >> 4))) << 32
}

/// The 24 words of eight elements' states as three 8-bit masks: `bits` (bit `l` for
/// element `l`) on the word `at` of each element (0 `last`, 1 `still`, 2 `moved`).
#[inline(always)]
fn word_masks(bits: u8, at: usize) -> [u8; 3] {
    let m = WORD_MASKS[at][usize::from(bits)];
    [m as u8, (m >> 8) as u8, (m >> 16) as u8]
}

/// [`word_masks`] of every 8-bit mask for each word of an element, made when compiling (a
/// load per group instead of a loop over the lanes; issue 34, eleventh round).
const WORD_MASKS: [[u32; 256]; WORDS] = {
    let mut table = [[0u32; 256]; WORDS];
    let mut at = 0;
    while at < WORDS {
        let mut bits = 0usize;
        while bits < 256 {
            let (mut m, mut l) = (0u32, 0);
            while l < LANES {
                m |= (((bits >> l) & 1) as u32) << (l * WORDS + at);
                l += 1;
            }
            table[at][bits] = m;
            bits += 1;
        }
        at += 1;
    }
    table
};

/// The change of each reading since the element's last finite one (as `avx2::changes_row`),
/// eight elements at a time; the rest through the AVX2 row.
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL and AVX2.
///
/// # Panics
/// When the slices differ in length.
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
pub(super) unsafe fn changes_row(els: &mut [Element<f64>], c: &[f64], d: &mut [f64]) {
    let w = c.len();
    assert!(els.len() == w && d.len() == w);
    let whole = w / LANES * LANES;
    for i in (0..whole).step_by(LANES) {
        // SAFETY: i + 8 <= whole <= w: the eight elements (24 words) and values are inside
        // the slices
        unsafe {
            let cv = _mm512_loadu_pd(c.as_ptr().add(i));
            let dv = change8(els.as_mut_ptr().add(i), cv);
            _mm512_storeu_pd(d.as_mut_ptr().add(i), dv);
        }
    }
    // SAFETY: the caller's processor has AVX2
    unsafe { avx2::changes_row(&mut els[whole..], &c[whole..], &mut d[whole..]) };
}

/// The changes `|c - last|` of eight readings `cv` (`kernel::change`), and the eight
/// elements' `last` set to their readings that are finite.
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL; `els` points to eight elements.
#[inline]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
unsafe fn change8(els: *mut Element<f64>, cv: __m512d) -> __m512d {
    let abs = _mm512_castsi512_pd(_mm512_set1_epi64(i64::MAX));
    // word 3 j of the three registers to lane j, and back
    let pick_ab = _mm512_setr_epi64(0, 3, 6, 9, 12, 15, 0, 0);
    let pick_c = _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 10, 13);
    let to_a = _mm512_setr_epi64(0, 0, 0, 1, 0, 0, 2, 0);
    let to_b = _mm512_setr_epi64(0, 3, 0, 0, 4, 0, 0, 5);
    let to_c = _mm512_setr_epi64(0, 0, 6, 0, 0, 7, 0, 0);
    // SAFETY: the eight elements' 24 words (`Element<f64>` is repr(C), three words with
    // `last` first)
    unsafe {
        let e = els.cast::<f64>();
        let (a, b, cc) = (
            _mm512_loadu_pd(e),
            _mm512_loadu_pd(e.add(8)),
            _mm512_loadu_pd(e.add(16)),
        );
        let last = _mm512_permutex2var_pd(_mm512_permutex2var_pd(a, pick_ab, b), pick_c, cc);
        // |c - last| as the kernel's `abs` (the sign bit cleared)
        let dv = _mm512_and_pd(_mm512_sub_pd(cv, last), abs);
        let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(cv, cv), _mm512_setzero_pd());
        let [ma, mb, mc] = word_masks(finite, 0);
        _mm512_mask_storeu_pd(e, ma, _mm512_permutexvar_pd(to_a, cv));
        _mm512_mask_storeu_pd(e.add(8), mb, _mm512_permutexvar_pd(to_b, cv));
        _mm512_mask_storeu_pd(e.add(16), mc, _mm512_permutexvar_pd(to_c, cv));
        dv
    }
}

/// The codes of a block's row as `avx2::codes_row` (the same contract: whole groups of four,
/// at most 32; returns the groups left to the scalar kernel, bit `g` for elements
/// `4 g .. 4 g + 4`), two groups at a time; a last lone group through the AVX2 row.
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL and AVX2.
///
/// # Panics
/// When the slices differ in length, are not whole groups, or hold more than 32 groups.
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
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
    assert!(w.is_multiple_of(4) && w <= 32 * 4);
    assert!(d.len() == w && valid.len() == w && els.len() == w && out.len() == w);
    let whole = w / LANES * LANES;
    // SAFETY: AVX-512 (this function's features); `d` is read only (CHANGES false)
    let mut left = unsafe { groups::<false>(p, lim, c, d.as_ptr().cast_mut(), valid, els, out) };
    if whole < w {
        // SAFETY: the caller's processor has AVX2
        left |= unsafe { codes_tail(p, lim, c, d, valid, els, out, whole) } << (whole / 4);
    }
    left
}

/// The changes and the codes of a frame's row of whole groups of eight in one pass (issue
/// 34, fifteenth round): [`changes_row`]'s changes into `d`, then [`codes_row`]'s codes
/// with them, group by group. Returns the groups of four left to the scalar kernel (a
/// reading that holds still reads its neighbours' changes, which may come later in the
/// row): bit `g` for elements `4 g .. 4 g + 4`.
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL and AVX2.
///
/// # Panics
/// When the slices differ in length, are not whole groups of eight, or hold more than 32
/// groups of four.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
pub(super) unsafe fn changes_codes_row(
    p: &DetectorParams,
    lim: &RowLimits<'_>,
    c: &[f64],
    d: &mut [f64],
    valid: &[bool],
    els: &mut [Element<f64>],
    out: &mut [u8],
) -> u32 {
    let w = c.len();
    assert!(w.is_multiple_of(LANES) && w <= 32 * 4);
    assert!(d.len() == w && valid.len() == w && els.len() == w && out.len() == w);
    // SAFETY: AVX-512 (this function's features); `d` is `w` values of its own
    unsafe { groups::<true>(p, lim, c, d.as_mut_ptr(), valid, els, out) }
}

/// The whole groups of eight of a row: with `CHANGES`, each group's changes first
/// ([`change8`], into `d`), else read from `d`; then the codes ([`codes_row`]).
///
/// # Safety
/// The processor must have AVX-512 F/DQ/VL and AVX2; `d` points to `c.len()` values
/// (written only with `CHANGES`); the other slices are `c.len()` long, at most 128.
#[inline]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
unsafe fn groups<const CHANGES: bool>(
    p: &DetectorParams,
    lim: &RowLimits<'_>,
    c: &[f64],
    d: *mut f64,
    valid: &[bool],
    els: &mut [Element<f64>],
    out: &mut [u8],
) -> u32 {
    let w = c.len();
    assert!(valid.len() == w && els.len() == w && out.len() == w && w <= 32 * 4);
    assert!(lim.jump.len() == w);
    assert!(lim.baseline.is_none_or(|b| b.len() == w) && lim.max.is_none_or(|m| m.len() == w));
    let (stuck, floor) = (_mm512_set1_pd(p.stuck_pf), _mm512_set1_pd(p.stuck_floor_pf));
    let (high_share, low_share) = (_mm512_set1_pd(p.high_share), _mm512_set1_pd(p.low_share));
    let min_pf = _mm512_set1_pd(p.min_pf);
    let zero = _mm512_setzero_pd();
    let whole = w / LANES * LANES;
    let mut left = 0u32;
    for i in (0..whole).step_by(LANES) {
        // SAFETY: i + 8 <= whole <= w, the length of every slice (checked above)
        let load = |s: &[f64]| unsafe { _mm512_loadu_pd(s.as_ptr().add(i)) };
        let cv = load(c);
        // SAFETY: i + 8 <= w: `d`'s values and the eight elements
        let dv = unsafe {
            if CHANGES {
                let dv = change8(els.as_mut_ptr().add(i), cv);
                _mm512_storeu_pd(d.add(i), dv);
                dv
            } else {
                _mm512_loadu_pd(d.add(i))
            }
        };
        let still = _mm512_cmp_pd_mask::<_CMP_LE_OQ>(dv, stuck)
            & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(cv, floor);
        // the halves (groups of four) with a reading that holds still go to the scalar kernel
        let lanes: u8 = match (still & 0xf != 0, still >> 4 != 0) {
            (false, false) => 0xff,
            (true, false) => 0xf0,
            (false, true) => 0x0f,
            (true, true) => 0,
        };
        let g = (i / 4) as u32;
        left |= u32::from(lanes & 0xf == 0) << g | u32::from(lanes >> 4 == 0) << (g + 1);
        if lanes == 0 {
            continue;
        }
        let jump = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(dv, load(lim.jump));
        let mut high = 0u8;
        if let Some(m) = lim.max {
            high = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(cv, _mm512_mul_pd(high_share, load(m)));
        }
        let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(cv, cv), zero);
        let mut low = !finite | _mm512_cmp_pd_mask::<_CMP_LE_OQ>(cv, min_pf);
        if let Some(b) = lim.baseline {
            low |= _mm512_cmp_pd_mask::<_CMP_LT_OQ>(cv, _mm512_mul_pd(low_share, load(b)));
        }
        // the eight validity bytes (0 or 1) as lane bits
        // SAFETY: i + 8 <= w
        let bytes = unsafe { _mm_loadl_epi64(valid.as_ptr().add(i).cast()) };
        let ok = _mm512_test_epi64_mask(_mm512_cvtepu8_epi64(bytes), _mm512_set1_epi64(1));
        // the later rule wins, as in kernel::code: short/break, then out of range, then jump
        let high = (high | !ok) & !low;
        let jump = jump & !low & !high;
        let word = (spread8(low) * u64::from(codes::SHORT_OR_BREAK))
            | (spread8(high) * u64::from(codes::OUT_OF_RANGE))
            | (spread8(jump) * u64::from(codes::JUMP));
        // SAFETY: i + 8 <= w, the length of `out` and `els`
        unsafe { write_moving(lanes, word, &mut out[i..i + LANES], &mut els[i..i + LANES]) };
    }
    left
}

/// The codes `word` (byte `l` for lane `l`) of the lanes in `lanes` into `out`, and those
/// lanes' elements cleared of stillness (`kernel::code` for a reading that does not hold
/// still: `still = 0`, `moved = 0`) by three masked stores of zeros.
///
/// # Safety
/// The processor must have AVX-512 F; `out` and `els` hold eight entries.
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2")]
unsafe fn write_moving(lanes: u8, word: u64, out: &mut [u8], els: &mut [Element<f64>]) {
    assert!(out.len() == LANES && els.len() == LANES);
    // the lanes' bytes of `word` over the eight codes, the others kept: one load and store
    // (a byte each, spread8(lanes) * 0xff, instead of a test and a store per lane)
    let keep = spread8(lanes) * 0xff;
    let old = u64::from_le_bytes(out[..LANES].try_into().expect("eight codes"));
    out.copy_from_slice(&((old & !keep) | (word & keep)).to_le_bytes());
    let [ms, mm, mt] = word_masks(lanes, 1);
    let [ns, nm, nt] = word_masks(lanes, 2);
    let zero = _mm512_setzero_pd();
    // SAFETY: the eight elements' 24 words are `els` (checked above); writing the padding
    // after `still` (zeros) is writing plain bytes of the elements
    unsafe {
        let e = els.as_mut_ptr().cast::<f64>();
        _mm512_mask_storeu_pd(e, ms | ns, zero);
        _mm512_mask_storeu_pd(e.add(8), mm | nm, zero);
        _mm512_mask_storeu_pd(e.add(16), mt | nt, zero);
    }
}

/// The codes of a row's last lone group of four (from `whole` on) through the AVX2 row;
/// its groups left (bit 0).
///
/// # Safety
/// The processor must have AVX2.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2")]
unsafe fn codes_tail(
    p: &DetectorParams,
    lim: &RowLimits<'_>,
    c: &[f64],
    d: &[f64],
    valid: &[bool],
    els: &mut [Element<f64>],
    out: &mut [u8],
    whole: usize,
) -> u32 {
    let tail = RowLimits {
        jump: &lim.jump[whole..],
        baseline: lim.baseline.map(|b| &b[whole..]),
        max: lim.max.map(|m| &m[whole..]),
    };
    // SAFETY: the caller's processor has AVX2
    unsafe {
        avx2::codes_row(
            p,
            &tail,
            &c[whole..],
            &d[whole..],
            &valid[whole..],
            &mut els[whole..],
            &mut out[whole..],
        )
    }
}
