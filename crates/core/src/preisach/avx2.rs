//! The Preisach step (eq. 4.16-4.22) across four elements at once, in the lanes of AVX2
//! registers: the same operations as the scalar kernel (`texsense_kernels::preisach`
//! `prepare` + `finish`, `Everett::value_of_numbers`) in the same order, without fused
//! multiply-adds, so every output and every state is the scalar kernel's, bit for bit.
//!
//! What differs is how the data-dependent outcomes are taken: rising or falling, turning
//! or not, wiping out a loop or not, which Everett cell — all are lane masks and blends, so
//! a random walk costs no mispredicted branch per element. The four heads are half a group
//! ([`Heads`], field after field), with copies of each stack's top extremum and of the
//! input below it, so a step that wipes out no loop reads and writes the heads with plain
//! vector loads and stores, and touches the stacks only to push the turning point; the
//! lanes that wipe out loops (or return to saturation) gather the new top from their own
//! stacks. The Everett table entries are gathered. The rare outcomes the lanes cannot share
//! run the scalar step for the whole group: a stack at its room (it grows on the heap or
//! forgets a loop).

use std::arch::x86_64::*;

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::Output;

use super::{Element, Heads, GROUP, INLINE_EXTREMA, LANES};

/// One frame of a block: inputs `u`, validity `ok` -> outputs `out` (NaN where invalid or
/// not finite), the elements' states stepped; identical to the scalar step per element.
///
/// # Safety
/// The processor must have AVX2. `u`, `ok` and `out` hold `elements.len()` values, `heads`
/// one group per eight elements.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn row(
    e: &EverettView<'_, f64>,
    cells: &[f64],
    capacity: usize,
    output: Output<f64>,
    elements: &mut [Element],
    heads: &mut [Heads],
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let n = elements.len();
    assert!(u.len() == n && ok.len() == n && out.len() == n);
    assert!(heads.len() == n.div_ceil(GROUP));
    let consts = Consts::new(e, cells, output);
    // the room of a stack in place (`Element::room`)
    let room = _mm256_set1_epi64x(INLINE_EXTREMA.min(capacity) as i64);
    let step = (std::mem::size_of::<Element>() / 8) as i64;
    let in_place = _mm256_set_epi64x(3 * step, 2 * step, step, 0);
    for q in 0..n.div_ceil(LANES) {
        // lanes `h .. h + 4` of a group of heads
        let (hd, h) = (&mut heads[q / 2], q % 2 * LANES);
        let i = q * LANES;
        if i + LANES > n {
            for j in i..n {
                out[j] = scalar(
                    &mut elements[j],
                    hd,
                    h + j - i,
                    e,
                    capacity,
                    output,
                    u[j],
                    ok[j],
                );
            }
            break;
        }
        let els = &mut elements[i..i + LANES];
        let mut stacks = [std::ptr::null_mut::<f64>(); LANES];
        // the heads' bit per stack on the heap (`element::HEAP`: the counters' sign bits)
        let counts = _mm256_load_pd(hd.clamped[h..].as_ptr().cast());
        let spilled = _mm256_movemask_pd(counts) != 0;
        debug_assert_eq!(spilled, els.iter().any(|el| el.spill.is_some()));
        let (at_room, off) = if spilled {
            let mut at_room = false;
            for (l, el) in els.iter_mut().enumerate() {
                at_room |= hd.len[h + l] as usize == el.room(capacity);
                stacks[l] = el.stack_mut().as_mut_ptr().cast::<f64>();
            }
            // each stack from lane 0's, in f64 (the distance of two f64 arrays)
            let rel = |l: usize| (stacks[l] as isize - stacks[0] as isize) as i64 >> 3;
            (at_room, _mm256_set_epi64x(rel(3), rel(2), rel(1), 0))
        } else {
            // every stack in place, with the same room, one element apart
            for (l, el) in els.iter_mut().enumerate() {
                stacks[l] = el.inline.as_mut_ptr().cast::<f64>();
            }
            let len = _mm256_load_si256(hd.len[h..].as_ptr().cast());
            let full = _mm256_movemask_pd(_mm256_castsi256_pd(_mm256_cmpeq_epi64(len, room)));
            (full != 0, in_place)
        };
        if at_room {
            for l in 0..LANES {
                let (x, v) = (u[i + l], ok[i + l]);
                out[i + l] = scalar(&mut els[l], hd, h + l, e, capacity, output, x, v);
            }
            continue;
        }
        // SAFETY: AVX2 (this function's feature); four elements, inputs and outputs; every
        // stack has room for a turning point
        let moved = unsafe {
            group(
                &consts,
                hd,
                h,
                &stacks,
                off,
                &u[i..i + LANES],
                &ok[i..i + LANES],
                &mut out[i..i + LANES],
            )
        };
        if spilled {
            for (l, el) in els.iter_mut().enumerate() {
                let len = hd.len[h + l] as usize;
                if moved >> l & 1 != 0 && len <= INLINE_EXTREMA / 2 && el.spill.is_some() {
                    el.unspill(len);
                    hd.mark(h + l, false);
                }
            }
        }
    }
}

/// The scalar step of the element in lane `l` of `hd` (the kernel's, through
/// `Element::step`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scalar(
    el: &mut Element,
    hd: &mut Heads,
    l: usize,
    e: &EverettView<'_, f64>,
    capacity: usize,
    output: Output<f64>,
    u: f64,
    ok: bool,
) -> f64 {
    if ok && u.is_finite() {
        output.of(el.step(hd, l, e, capacity, u))
    } else {
        f64::NAN
    }
}

/// The bank's constants in registers.
struct Consts {
    u_min: __m256d,
    u_max: __m256d,
    inv_step: __m256d,
    last: __m256d,
    top: __m128i,
    k: __m256i,
    offset: __m256d,
    sign: __m256d,
    /// The table, and the table by cell (null: gathered from the table).
    table: *const f64,
    cells: *const f64,
}

impl Consts {
    #[target_feature(enable = "avx2")]
    unsafe fn new(e: &EverettView<'_, f64>, cells: &[f64], output: Output<f64>) -> Self {
        let k = e.size();
        debug_assert!(cells.is_empty() || cells.len() == 2 * k * (k - 1));
        Self {
            u_min: _mm256_set1_pd(e.u_min()),
            u_max: _mm256_set1_pd(e.u_max()),
            inv_step: _mm256_set1_pd(e.inv_step()),
            last: _mm256_set1_pd((k - 1) as f64),
            top: _mm_set1_epi32((k - 2) as i32),
            k: _mm256_set1_epi64x(k as i64),
            offset: _mm256_set1_pd(output.offset),
            sign: _mm256_set1_pd(output.sign),
            table: e.table().as_ptr(),
            cells: if cells.is_empty() {
                std::ptr::null()
            } else {
                cells.as_ptr()
            },
        }
    }
}

/// `f64::clamp(x, lo, hi)` per lane, with its exact semantics (a signed zero kept).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn clamp(x: __m256d, lo: __m256d, hi: __m256d) -> __m256d {
    let x = _mm256_blendv_pd(x, lo, _mm256_cmp_pd::<_CMP_LT_OQ>(x, lo));
    _mm256_blendv_pd(x, hi, _mm256_cmp_pd::<_CMP_GT_OQ>(x, hi))
}

/// An input in grid steps, at most `K - 1`: `(v - u_min) / step` of a number
/// `v >= u_min` (an input clamped into the range, an extremum on a stack, or the lower
/// saturation). That is `+0`, `-0` (`v = -0`, `u_min = +0`) or above and never NaN, so
/// the scalar kernel's clamp into `[0, K - 1]` only ever takes the upper bound, which
/// `min` gives bit for bit.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn grid(c: &Consts, v: __m256d) -> __m256d {
    _mm256_min_pd(_mm256_mul_pd(_mm256_sub_pd(v, c.u_min), c.inv_step), c.last)
}

/// `Everett::value_of_numbers` per lane for `u_min <= alpha, beta` (the same arithmetic;
/// see [`grid`]). The cell indices are kept in `[0, K - 2]` whatever the inputs, so that
/// no lane reads outside the table.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn everett(c: &Consts, alpha: __m256d, beta: __m256d) -> __m256d {
    let table = c.table;
    let zero = _mm256_setzero_pd();
    let one = _mm256_set1_pd(1.0);
    let (a, b) = (grid(c, alpha), grid(c, beta));
    // a, b in [0, K - 1]: truncation is the floor; then at most K - 2 (and at least 0:
    // a NaN, which the caller never passes, would truncate to i32::MIN)
    let zero_i = _mm_setzero_si128();
    let i0 = _mm_max_epi32(_mm_min_epi32(_mm256_cvttpd_epi32(a), c.top), zero_i);
    let j0 = _mm_max_epi32(_mm_min_epi32(_mm256_cvttpd_epi32(b), c.top), zero_i);
    let wa = _mm256_sub_pd(a, _mm256_cvtepi32_pd(i0));
    let wb = _mm256_sub_pd(b, _mm256_cvtepi32_pd(j0));
    let (i64a, i64b) = (_mm256_cvtepi32_epi64(i0), _mm256_cvtepi32_epi64(j0));
    let (f00, f01, f10, f11) = if c.cells.is_null() {
        let q = _mm256_add_epi64(_mm256_mul_epi32(i64a, c.k), i64b);
        let one_i = _mm256_set1_epi64x(1);
        let qk = _mm256_add_epi64(q, c.k);
        (
            _mm256_i64gather_pd::<8>(table, q),
            _mm256_i64gather_pd::<8>(table, _mm256_add_epi64(q, one_i)),
            _mm256_i64gather_pd::<8>(table, qk),
            _mm256_i64gather_pd::<8>(table, _mm256_add_epi64(qk, one_i)),
        )
    } else {
        cell_corners(c.cells, i0, j0)
    };
    let (owa, owb) = (_mm256_sub_pd(one, wa), _mm256_sub_pd(one, wb));
    let low = _mm256_add_pd(_mm256_mul_pd(owb, f00), _mm256_mul_pd(wb, f01));
    let high = _mm256_add_pd(_mm256_mul_pd(owb, f10), _mm256_mul_pd(wb, f11));
    let bilinear = _mm256_add_pd(_mm256_mul_pd(owa, low), _mm256_mul_pd(wa, high));
    let diagonal = _mm256_mul_pd(_mm256_sub_pd(wa, wb), f10);
    let on_diagonal = _mm256_castsi256_pd(_mm256_cmpeq_epi64(i64a, i64b));
    let v = _mm256_blendv_pd(bilinear, diagonal, on_diagonal);
    _mm256_blendv_pd(v, zero, _mm256_cmp_pd::<_CMP_GE_OQ>(b, a))
}

/// The four corners of each lane's Everett cell `(i0, j0)` (`i0, j0 <= K - 2`) from the
/// table by cell: one 32-byte load per lane, transposed into `F(i, j), F(i, j + 1),
/// F(i + 1, j), F(i + 1, j + 1)` across the lanes. A lane with `j0 > i0` (whose value the
/// caller discards: `β >= α`) reads a cell of the next row, still inside the table.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn cell_corners(
    cells: *const f64,
    i0: __m128i,
    j0: __m128i,
) -> (__m256d, __m256d, __m256d, __m256d) {
    // cell index i (i + 1) / 2 + j, in 32-bit lanes (K <= CELL_GRID_MAX)
    let tri = _mm_srli_epi32::<1>(_mm_mullo_epi32(i0, _mm_add_epi32(i0, _mm_set1_epi32(1))));
    let q = _mm_slli_epi32::<2>(_mm_add_epi32(tri, j0));
    let at = |l: usize| -> __m256d {
        let q = match l {
            0 => _mm_cvtsi128_si32(q),
            1 => _mm_extract_epi32::<1>(q),
            2 => _mm_extract_epi32::<2>(q),
            _ => _mm_extract_epi32::<3>(q),
        };
        // SAFETY: i0, j0 <= K - 2, so the cell index is below (K - 1) K / 2
        unsafe { _mm256_loadu_pd(cells.add(q as usize)) }
    };
    let (r0, r1, r2, r3) = (at(0), at(1), at(2), at(3));
    let (lo01, hi01) = (_mm256_unpacklo_pd(r0, r1), _mm256_unpackhi_pd(r0, r1));
    let (lo23, hi23) = (_mm256_unpacklo_pd(r2, r3), _mm256_unpackhi_pd(r2, r3));
    (
        _mm256_permute2f128_pd::<0x20>(lo01, lo23),
        _mm256_permute2f128_pd::<0x20>(hi01, hi23),
        _mm256_permute2f128_pd::<0x31>(lo01, lo23),
        _mm256_permute2f128_pd::<0x31>(hi01, hi23),
    )
}

/// Four elements, lanes `h0 .. h0 + 4` of the group of heads `hd`, whose stacks all have
/// room for a turning point (`stacks`: each one's extrema, input and output after each
/// other, `off` lane `l`'s from lane 0's in f64): the outputs into `out`, the heads and the
/// pushed turning points stored; returns the lanes that moved (bit `l` for lane `l`).
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2")]
unsafe fn group(
    c: &Consts,
    hd: &mut Heads,
    h0: usize,
    stacks: &[*mut f64; LANES],
    off: __m256i,
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) -> i32 {
    let zero = _mm256_setzero_pd();
    let (one_i, two_i) = (_mm256_set1_epi64x(1), _mm256_set1_epi64x(2));
    // the kernel's `prepare`
    let len0 = _mm256_load_si256(hd.len[h0..].as_ptr().cast());
    let last_u = _mm256_load_pd(hd.last_u[h0..].as_ptr());
    let last_h = _mm256_load_pd(hd.last_h[h0..].as_ptr());
    let u_in = _mm256_loadu_pd(u.as_ptr());
    let bytes = i32::from_le_bytes([ok[0], ok[1], ok[2], ok[3]].map(u8::from));
    let ok_m = _mm256_cmpgt_epi64(
        _mm256_cvtepu8_epi64(_mm_cvtsi32_si128(bytes)),
        _mm256_setzero_si256(),
    );
    // valid and finite (x - x is 0 for a finite x, NaN otherwise)
    let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(u_in, u_in), zero);
    let live = _mm256_and_pd(_mm256_castsi256_pd(ok_m), finite);
    let clamped = clamp(u_in, c.u_min, c.u_max);
    let uc = _mm256_blendv_pd(c.u_min, clamped, live);
    let rising = _mm256_cmp_pd::<_CMP_GT_OQ>(uc, last_u);
    let moving = _mm256_andnot_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(uc, last_u), live);
    let odd0 = _mm256_cmpeq_epi64(_mm256_and_si256(len0, one_i), one_i);
    let turned = _mm256_xor_si256(_mm256_castpd_si256(rising), odd0);
    let turned_pd = _mm256_castsi256_pd(turned);
    // the kernel's `finish`: the turning point pushed (in registers; stored at the end)
    let top_u = _mm256_load_pd(hd.top_u[h0..].as_ptr());
    let mut len = _mm256_sub_epi64(len0, turned);
    let mut t_u = _mm256_blendv_pd(top_u, last_u, turned_pd);
    let mut t_h = _mm256_blendv_pd(_mm256_load_pd(hd.top_h[h0..].as_ptr()), last_h, turned_pd);
    let mut b_u = _mm256_blendv_pd(_mm256_load_pd(hd.below_u[h0..].as_ptr()), top_u, turned_pd);
    // wiping-out: the input passes the extremum below the top
    let dir = _mm256_blendv_pd(_mm256_set1_pd(-1.0), _mm256_set1_pd(1.0), rising);
    let passes = |s: __m256d| {
        let d = _mm256_mul_pd(_mm256_sub_pd(uc, s), dir);
        _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_GE_OQ>(d, zero))
    };
    let moving_i = _mm256_castpd_si256(moving);
    let wiped = _mm256_and_si256(
        _mm256_and_si256(_mm256_cmpgt_epi64(len, two_i), passes(b_u)),
        moving_i,
    );
    let base = stacks[0] as *const f64;
    if _mm256_testz_si256(wiped, wiped) == 0 {
        // slot `s` (an extremum's index) of every lane's stack as an index from `base`
        let slot = |s: __m256i| _mm256_add_epi64(_mm256_add_epi64(s, s), off);
        len = _mm256_add_epi64(len, _mm256_add_epi64(wiped, wiped));
        // deeper levels: while a lane still passes the extremum below its top
        let mut wipes = wiped;
        loop {
            let can = _mm256_and_si256(wipes, _mm256_cmpgt_epi64(len, two_i));
            if _mm256_testz_si256(can, can) != 0 {
                break;
            }
            let at = slot(_mm256_sub_epi64(len, two_i));
            let s = _mm256_mask_i64gather_pd::<8>(zero, base, at, _mm256_castsi256_pd(can));
            wipes = _mm256_and_si256(can, passes(s));
            len = _mm256_add_epi64(len, _mm256_add_epi64(wipes, wipes));
        }
        // the new top and the extremum below it, from the stacks of the lanes that wiped
        let w = _mm256_castsi256_pd(wiped);
        let top = slot(_mm256_sub_epi64(len, one_i));
        t_u = _mm256_mask_i64gather_pd::<8>(t_u, base, top, w);
        t_h = _mm256_mask_i64gather_pd::<8>(t_h, base, _mm256_add_epi64(top, one_i), w);
        let below = _mm256_blendv_epi8(len, two_i, _mm256_cmpgt_epi64(two_i, len));
        b_u = _mm256_mask_i64gather_pd::<8>(b_u, base, slot(_mm256_sub_epi64(below, two_i)), w);
    }
    // back at lower saturation (the extremum below a top at depth 2 is the saturation)
    let at_sat = _mm256_and_si256(
        _mm256_and_si256(_mm256_cmpeq_epi64(len, two_i), moving_i),
        _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_LE_OQ>(uc, b_u)),
    );
    if _mm256_testz_si256(at_sat, at_sat) == 0 {
        let s = _mm256_castsi256_pd(at_sat);
        len = _mm256_blendv_epi8(len, one_i, at_sat);
        t_u = _mm256_blendv_pd(t_u, b_u, s);
        t_h = _mm256_mask_i64gather_pd::<8>(t_h, base, _mm256_add_epi64(off, one_i), s);
    }
    // the top: x + 2 F(u, m) after a minimum, x - 2 F(M, u) after a maximum
    let odd = _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_and_si256(len, one_i), one_i));
    let alpha = _mm256_blendv_pd(t_u, uc, odd);
    let beta = _mm256_blendv_pd(uc, t_u, odd);
    let sign = _mm256_blendv_pd(_mm256_set1_pd(-2.0), _mm256_set1_pd(2.0), odd);
    let f = everett(c, alpha, beta);
    let h = _mm256_add_pd(t_h, _mm256_mul_pd(sign, f));
    let sum = _mm256_blendv_pd(last_h, h, moving);
    let y = _mm256_mul_pd(c.sign, _mm256_add_pd(sum, c.offset));
    let nan = _mm256_set1_pd(f64::NAN);
    _mm256_storeu_pd(out.as_mut_ptr(), _mm256_blendv_pd(nan, y, live));
    // the turning point into the slot above the old top (kept on a turn; a stack has
    // room + 1 >= len + 1 slots)
    for (l, &p) in stacks.iter().enumerate() {
        let at = 2 * hd.len[h0 + l] as usize;
        // SAFETY: slot len0 of a stack with room for it (see above)
        unsafe {
            *p.add(at) = hd.last_u[h0 + l];
            *p.add(at + 1) = hd.last_h[h0 + l];
        }
    }
    // the heads of the lanes that moved
    let keep = |old: __m256d, new: __m256d| _mm256_blendv_pd(old, new, moving);
    _mm256_store_si256(
        hd.len[h0..].as_mut_ptr().cast(),
        _mm256_blendv_epi8(len0, len, moving_i),
    );
    _mm256_store_pd(hd.last_u[h0..].as_mut_ptr(), keep(last_u, uc));
    _mm256_store_pd(hd.last_h[h0..].as_mut_ptr(), keep(last_h, h));
    _mm256_store_pd(hd.top_u[h0..].as_mut_ptr(), keep(top_u, t_u));
    _mm256_store_pd(
        hd.top_h[h0..].as_mut_ptr(),
        keep(_mm256_load_pd(hd.top_h[h0..].as_ptr()), t_h),
    );
    _mm256_store_pd(
        hd.below_u[h0..].as_mut_ptr(),
        keep(_mm256_load_pd(hd.below_u[h0..].as_ptr()), b_u),
    );
    let was_clamped = _mm256_and_pd(_mm256_cmp_pd::<_CMP_NEQ_UQ>(clamped, u_in), live);
    let counts = _mm256_load_si256(hd.clamped[h0..].as_ptr().cast());
    let counts = _mm256_sub_epi64(counts, _mm256_castpd_si256(was_clamped));
    _mm256_store_si256(hd.clamped[h0..].as_mut_ptr().cast(), counts);
    _mm256_movemask_pd(moving)
}
