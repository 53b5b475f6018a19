//! The Preisach step (eq. 4.16-4.22) across eight elements at once, in the lanes of
//! AVX-512 registers: `super::avx2`'s lane program (the scalar kernel's operations in the
//! same order, without fused multiply-adds, so every output and state is the scalar
//! kernel's, bit for bit) on a group of eight heads, with the lane conditions in mask
//! registers (masked adds, blends and gathers instead of all-ones vectors). The Everett
//! corners are gathered from the table (four gathers; on AVX-512 faster than a load per lane
//! from the table by cell and its transpose, 1.14 x on the timing binary).
//!
//! Two whole groups step here, their stacks in place or on the heap (each lane's stack
//! from its own offset; a stack on the heap that is shallow again goes back in place
//! afterwards), a stack at its room too unless its input turns. A turning point onto a full
//! stack and the last group of a block go through `super::avx2::row` for those elements,
//! which grows the stack on the heap or forgets a loop.

use std::arch::x86_64::*;

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::Output;

use super::{avx2, Element, Heads, GROUP, INLINE_EXTREMA};

/// Elements per step: a group of heads.
const WIDE: usize = GROUP;

/// One frame of a block (the arguments and results of `super::avx2::row`).
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F, DQ and VL. `u`, `ok` and `out` hold
/// `elements.len()` values, `heads` one group per eight elements.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
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
    let consts = Consts::new(e, output);
    let room = _mm512_set1_epi64(INLINE_EXTREMA.min(capacity) as i64);
    let step = (std::mem::size_of::<Element>() / 8) as i64;
    let off = _mm512_mullo_epi64(
        _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0),
        _mm512_set1_epi64(step),
    );
    let mut i = 0;
    while i < n {
        let g = i / GROUP;
        let stepped = i + WIDE <= n && {
            let els = &mut elements[i..i + WIDE];
            let base = els[0].inline.as_mut_ptr().cast::<f64>();
            // the heads' bit per stack on the heap (`element::HEAP`: the counters' sign bits)
            let counts = _mm512_load_si512(heads[g].clamped.as_ptr().cast());
            let spilled = _mm512_movepi64_mask(counts) != 0;
            debug_assert_eq!(spilled, els.iter().any(|el| el.spill.is_some()));
            let (offs, rooms) = if spilled {
                heap_stacks(els, base, capacity)
            } else {
                (off, room)
            };
            // SAFETY: AVX-512 (this function's features); eight elements, lane `l`'s stack
            // `offs[l]` f64 from `base` with `rooms[l]` extrema plus the spare slot
            let moved = unsafe {
                pair(
                    &consts,
                    &mut heads[g],
                    base,
                    offs,
                    rooms,
                    &u[i..i + WIDE],
                    &ok[i..i + WIDE],
                    &mut out[i..i + WIDE],
                )
            };
            if let (Some(moved), true) = (moved, spilled) {
                back_in_place(els, &mut heads[g], moved);
            }
            moved.is_some()
        };
        let m = WIDE.min(n - i);
        if !stepped {
            // SAFETY: AVX2 (this function's features); one group (or the block's last
            // elements) with its heads
            unsafe {
                avx2::row(
                    e,
                    cells,
                    capacity,
                    output,
                    &mut elements[i..i + m],
                    &mut heads[g..g + 1],
                    &u[i..i + m],
                    &ok[i..i + m],
                    &mut out[i..i + m],
                )
            };
        }
        i += m;
    }
}

/// Each stack of a group with a stack on the heap: its offset from lane 0's place in f64
/// (the distance of two f64 arrays) and its room.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn heap_stacks(els: &mut [Element], base: *mut f64, capacity: usize) -> (__m512i, __m512i) {
    let (mut o, mut r) = ([0i64; WIDE], [0i64; WIDE]);
    for (l, el) in els.iter_mut().enumerate() {
        r[l] = el.room(capacity) as i64;
        o[l] = (el.stack_mut().as_mut_ptr() as isize - base as isize) as i64 >> 3;
    }
    let load = |v: &[i64; WIDE]| _mm512_loadu_si512(v.as_ptr().cast());
    (load(&o), load(&r))
}

/// A stack on the heap that is shallow again after a step that `moved` it goes back in
/// place (`Element::step`).
#[inline]
fn back_in_place(els: &mut [Element], hd: &mut Heads, moved: __mmask8) {
    for (l, el) in els.iter_mut().enumerate() {
        let len = hd.len[l] as usize;
        if moved >> l & 1 != 0 && len <= INLINE_EXTREMA / 2 && el.spill.is_some() {
            el.unspill(len);
            hd.mark(l, false);
        }
    }
}

/// The bank's constants in registers.
struct Consts {
    u_min: __m512d,
    u_max: __m512d,
    inv_step: __m512d,
    last: __m512d,
    top: __m256i,
    k: __m512i,
    offset: __m512d,
    sign: __m512d,
    /// The table (row-major).
    table: *const f64,
}

impl Consts {
    #[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
    unsafe fn new(e: &EverettView<'_, f64>, output: Output<f64>) -> Self {
        let k = e.size();
        Self {
            u_min: _mm512_set1_pd(e.u_min()),
            u_max: _mm512_set1_pd(e.u_max()),
            inv_step: _mm512_set1_pd(e.inv_step()),
            last: _mm512_set1_pd((k - 1) as f64),
            top: _mm256_set1_epi32((k - 2) as i32),
            k: _mm512_set1_epi64(k as i64),
            offset: _mm512_set1_pd(output.offset),
            sign: _mm512_set1_pd(output.sign),
            table: e.table().as_ptr(),
        }
    }
}

/// `f64::clamp(x, lo, hi)` per lane (as `super::avx2`'s).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn clamp(x: __m512d, lo: __m512d, hi: __m512d) -> __m512d {
    let x = _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_LT_OQ>(x, lo), x, lo);
    _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_GT_OQ>(x, hi), x, hi)
}

/// An input in grid steps (`super::avx2::grid`).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn grid(c: &Consts, v: __m512d) -> __m512d {
    _mm512_min_pd(_mm512_mul_pd(_mm512_sub_pd(v, c.u_min), c.inv_step), c.last)
}

/// `Everett::value_of_numbers` per lane for `u_min <= alpha, beta` (`super::avx2::everett`).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn everett(c: &Consts, alpha: __m512d, beta: __m512d) -> __m512d {
    let zero = _mm512_setzero_pd();
    let one = _mm512_set1_pd(1.0);
    let (a, b) = (grid(c, alpha), grid(c, beta));
    let zero_i = _mm256_setzero_si256();
    let i0 = _mm256_max_epi32(_mm256_min_epi32(_mm512_cvttpd_epi32(a), c.top), zero_i);
    let j0 = _mm256_max_epi32(_mm256_min_epi32(_mm512_cvttpd_epi32(b), c.top), zero_i);
    let wa = _mm512_sub_pd(a, _mm512_cvtepi32_pd(i0));
    let wb = _mm512_sub_pd(b, _mm512_cvtepi32_pd(j0));
    let (i64a, i64b) = (_mm512_cvtepi32_epi64(i0), _mm512_cvtepi32_epi64(j0));
    // four gathers from the table (on this path they beat a load per lane from the table
    // by cell and its transpose: fewer instructions, and no lane's index through a
    // general register)
    let q = _mm512_add_epi64(_mm512_mul_epi32(i64a, c.k), i64b);
    let one_i = _mm512_set1_epi64(1);
    let qk = _mm512_add_epi64(q, c.k);
    let (f00, f01, f10, f11) = (
        _mm512_i64gather_pd::<8>(q, c.table),
        _mm512_i64gather_pd::<8>(_mm512_add_epi64(q, one_i), c.table),
        _mm512_i64gather_pd::<8>(qk, c.table),
        _mm512_i64gather_pd::<8>(_mm512_add_epi64(qk, one_i), c.table),
    );
    let (owa, owb) = (_mm512_sub_pd(one, wa), _mm512_sub_pd(one, wb));
    let low = _mm512_add_pd(_mm512_mul_pd(owb, f00), _mm512_mul_pd(wb, f01));
    let high = _mm512_add_pd(_mm512_mul_pd(owb, f10), _mm512_mul_pd(wb, f11));
    let bilinear = _mm512_add_pd(_mm512_mul_pd(owa, low), _mm512_mul_pd(wa, high));
    let diagonal = _mm512_mul_pd(_mm512_sub_pd(wa, wb), f10);
    let on_diagonal = _mm512_cmpeq_epi64_mask(i64a, i64b);
    let v = _mm512_mask_blend_pd(on_diagonal, bilinear, diagonal);
    _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_GE_OQ>(b, a), v, zero)
}

/// Eight elements (`super::avx2::group` on a group of eight heads): lane `l`'s stack starts
/// `off[l]` f64 from `base` and holds `room[l]` extrema plus the spare slot. Returns the
/// lanes that moved, or `None` before touching anything when an input turns on a stack at
/// its room (the scalar step grows the stack or forgets a loop).
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn pair(
    c: &Consts,
    hd: &mut Heads,
    base: *mut f64,
    off: __m512i,
    room: __m512i,
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) -> Option<__mmask8> {
    let zero = _mm512_setzero_pd();
    let (one_i, two_i) = (_mm512_set1_epi64(1), _mm512_set1_epi64(2));
    // the kernel's `prepare` (the heads aligned, a field per register)
    let len0 = _mm512_load_si512(hd.len.as_ptr().cast());
    let last_u = _mm512_load_pd(hd.last_u.as_ptr());
    let last_h = _mm512_load_pd(hd.last_h.as_ptr());
    let u_in = _mm512_loadu_pd(u.as_ptr());
    // the eight flags as bytes, then one mask bit per lane (a bool is 0 or 1)
    let flags = u64::from_le_bytes(
        ok[..WIDE]
            .try_into()
            .map_or([0; 8], |b: [bool; WIDE]| b.map(u8::from)),
    );
    let ok_k = _mm512_test_epi64_mask(
        _mm512_cvtepu8_epi64(_mm_cvtsi64_si128(flags as i64)),
        _mm512_set1_epi64(1),
    );
    let finite = _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(u_in, u_in), zero);
    let live = ok_k & finite;
    let clamped = clamp(u_in, c.u_min, c.u_max);
    let uc = _mm512_mask_blend_pd(live, c.u_min, clamped);
    let rising = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(uc, last_u);
    let moving = !_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(uc, last_u) & live;
    let odd0 = _mm512_test_epi64_mask(len0, one_i);
    let turned = rising ^ odd0;
    // a turning point onto a stack at its room: the scalar step (it grows or forgets)
    if _mm512_mask_cmpeq_epi64_mask(turned & moving, len0, room) != 0 {
        return None;
    }
    // the kernel's `finish`: the turning point pushed (in registers; stored at the end)
    let top_u = _mm512_load_pd(hd.top_u.as_ptr());
    let top_h = _mm512_load_pd(hd.top_h.as_ptr());
    let below_u = _mm512_load_pd(hd.below_u.as_ptr());
    let mut len = _mm512_mask_add_epi64(len0, turned, len0, one_i);
    let mut t_u = _mm512_mask_blend_pd(turned, top_u, last_u);
    let mut t_h = _mm512_mask_blend_pd(turned, top_h, last_h);
    let mut b_u = _mm512_mask_blend_pd(turned, below_u, top_u);
    let dir = _mm512_mask_blend_pd(rising, _mm512_set1_pd(-1.0), _mm512_set1_pd(1.0));
    let passes = |s: __m512d| {
        let d = _mm512_mul_pd(_mm512_sub_pd(uc, s), dir);
        _mm512_cmp_pd_mask::<_CMP_GE_OQ>(d, zero)
    };
    let wiped = _mm512_cmpgt_epi64_mask(len, two_i) & passes(b_u) & moving;
    let base = base as *const f64;
    if wiped != 0 {
        let slot = |s: __m512i| _mm512_add_epi64(_mm512_add_epi64(s, s), off);
        // the new top and the extremum below it, gathered at once (their addresses depend
        // on the depth alone, not on each other)
        let tops = |t_u, t_h, b_u, lanes, len: __m512i| {
            let top = slot(_mm512_sub_epi64(len, one_i));
            let below = slot(_mm512_sub_epi64(_mm512_max_epi64(len, two_i), two_i));
            (
                _mm512_mask_i64gather_pd::<8>(t_u, lanes, top, base),
                _mm512_mask_i64gather_pd::<8>(t_h, lanes, _mm512_add_epi64(top, one_i), base),
                _mm512_mask_i64gather_pd::<8>(b_u, lanes, below, base),
            )
        };
        len = _mm512_mask_sub_epi64(len, wiped, len, two_i);
        (t_u, t_h, b_u) = tops(t_u, t_h, b_u, wiped, len);
        // deeper: while a lane passes the extremum below its new top (which is `b_u`
        // while above depth 2), the gathers again for those lanes
        let deep = wiped & _mm512_cmpgt_epi64_mask(len, two_i) & passes(b_u);
        if deep != 0 {
            let mut wipes = deep;
            while wipes != 0 {
                len = _mm512_mask_sub_epi64(len, wipes, len, two_i);
                let can = wipes & _mm512_cmpgt_epi64_mask(len, two_i);
                let at = slot(_mm512_sub_epi64(len, two_i));
                let s = _mm512_mask_i64gather_pd::<8>(zero, can, at, base);
                wipes = can & passes(s);
            }
            (t_u, t_h, b_u) = tops(t_u, t_h, b_u, deep, len);
        }
    }
    // back at lower saturation
    let at_sat =
        _mm512_cmpeq_epi64_mask(len, two_i) & moving & _mm512_cmp_pd_mask::<_CMP_LE_OQ>(uc, b_u);
    if at_sat != 0 {
        len = _mm512_mask_mov_epi64(len, at_sat, one_i);
        t_u = _mm512_mask_blend_pd(at_sat, t_u, b_u);
        t_h = _mm512_mask_i64gather_pd::<8>(t_h, at_sat, _mm512_add_epi64(off, one_i), base);
    }
    let odd = _mm512_test_epi64_mask(len, one_i);
    let alpha = _mm512_mask_blend_pd(odd, t_u, uc);
    let beta = _mm512_mask_blend_pd(odd, uc, t_u);
    let sign = _mm512_mask_blend_pd(odd, _mm512_set1_pd(-2.0), _mm512_set1_pd(2.0));
    let f = everett(c, alpha, beta);
    let h = _mm512_add_pd(t_h, _mm512_mul_pd(sign, f));
    let sum = _mm512_mask_blend_pd(moving, last_h, h);
    let y = _mm512_mul_pd(c.sign, _mm512_add_pd(sum, c.offset));
    let nan = _mm512_set1_pd(f64::NAN);
    _mm512_storeu_pd(out.as_mut_ptr(), _mm512_mask_blend_pd(live, nan, y));
    // the turning point into the slot above the old top of each stack (only where it is
    // kept: a lane that moved and turned; the slot above the top is never read)
    let at = _mm512_add_epi64(_mm512_add_epi64(len0, len0), off);
    let push = turned & moving;
    let base = base.cast_mut();
    _mm512_mask_i64scatter_pd::<8>(base.cast(), push, at, last_u);
    _mm512_mask_i64scatter_pd::<8>(base.cast(), push, _mm512_add_epi64(at, one_i), last_h);
    // the heads of the lanes that moved
    let keep = |old: __m512d, new: __m512d| _mm512_mask_blend_pd(moving, old, new);
    let len = _mm512_mask_blend_epi64(moving, len0, len);
    _mm512_store_si512(hd.len.as_mut_ptr().cast(), len);
    _mm512_store_pd(hd.last_u.as_mut_ptr(), keep(last_u, uc));
    _mm512_store_pd(hd.last_h.as_mut_ptr(), keep(last_h, h));
    _mm512_store_pd(hd.top_u.as_mut_ptr(), keep(top_u, t_u));
    _mm512_store_pd(hd.top_h.as_mut_ptr(), keep(top_h, t_h));
    _mm512_store_pd(hd.below_u.as_mut_ptr(), keep(below_u, b_u));
    let was_clamped = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(clamped, u_in) & live;
    if was_clamped != 0 {
        let counts = _mm512_load_si512(hd.clamped.as_ptr().cast());
        let counts = _mm512_mask_add_epi64(counts, was_clamped, counts, one_i);
        _mm512_store_si512(hd.clamped.as_mut_ptr().cast(), counts);
    }
    Some(moving)
}
