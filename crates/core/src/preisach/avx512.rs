//! The Preisach step (eq. 4.16-4.22) across eight elements at once, in the lanes of
//! AVX-512 registers: `super::avx2`'s lane program (the scalar kernel's operations in the
//! same order, without fused multiply-adds, so every output and state is the scalar
//! kernel's, bit for bit) on a group of eight heads, with the lane conditions in mask
//! registers (masked adds, blends and gathers instead of all-ones vectors). The Everett
//! corners come by the processor's faster lookup ([`crate::simd::lookup`]): four gathers
//! from the table (on the Intel Xeon of the eighth round 1.14 x against loads per lane), or
//! one 32-byte load per lane from the table by cell and a transpose ([`cell_corners`]; on an
//! AMD Zen 5, where four gathers take four times as long as the loads and the transpose,
//! 1.07-1.33 x against the gathers on `preisach_inputs.py`'s moving inputs: issue 34,
//! eighteenth round).
//!
//! Whole groups step here, two side by side ([`pair_n`]; a group with a stack on the heap
//! gives each lane's stack from its own offset, and a stack on the heap that is shallow again
//! goes back in place afterwards), one at a time where a turning point of the other group
//! lands on a stack at its room; a stack at its room steps here too unless its input turns.
//! A turning point onto a full stack and the last group of a block go through
//! `super::avx2::row` for those elements, which grows the stack on the heap or forgets a
//! loop.

use std::arch::x86_64::*;

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::Output;

use super::{avx2, Element, Heads, GROUP, INLINE_EXTREMA};

mod memory;
use memory::{cell_corners, few_lanes, store_pairs};

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
    let consts = Consts::new(e, cells, output);
    let room = _mm512_set1_epi64(INLINE_EXTREMA.min(capacity) as i64);
    let step = (std::mem::size_of::<Element>() / 8) as i64;
    let off = _mm512_mullo_epi64(
        _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0),
        _mm512_set1_epi64(step),
    );
    let mut i = 0;
    while i < n {
        let g = i / GROUP;
        let stacks = (off, room, capacity);
        // RUNS whole groups side by side ([`pair_n`]); where a turning point lands on a
        // stack at its room, the groups go alone below
        // SAFETY: AVX-512 (this function's features); the slices hold n elements
        if i + RUNS * WIDE <= n
            && unsafe { run_of_groups::<RUNS>(&consts, elements, heads, stacks, i, u, ok, out) }
        {
            i += RUNS * WIDE;
            continue;
        }
        // SAFETY: as above
        let stepped = i + WIDE <= n
            && unsafe { run_of_groups::<1>(&consts, elements, heads, stacks, i, u, ok, out) };
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

/// [`pair_n`] of the `R` groups from element `i` (stacks in place at `off` with `room`
/// extrema; a group with a stack on the heap gives its lanes' own offsets and rooms, and its
/// stacks that are shallow again go back in place after the step: issue 34, seventeenth
/// round, 1.04 x the Preisach row on the walk against stepping such a group alone); false
/// when they did not step (a turning point onto a stack at its room: nothing touched).
///
/// # Safety
/// The processor must have AVX2 and AVX-512 F, DQ and VL; `i + R * WIDE` elements are
/// in `elements`, `u`, `ok` and `out`, and their groups in `heads`.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn run_of_groups<const R: usize>(
    consts: &Consts,
    elements: &mut [Element],
    heads: &mut [Heads],
    (off, room, capacity): (__m512i, __m512i, usize),
    i: usize,
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) -> bool {
    let g = i / GROUP;
    // SAFETY: AVX-512 (this function's features)
    let spilled: [__mmask8; R] = std::array::from_fn(|k| unsafe { on_heap(&heads[g + k]) });
    debug_assert!((0..R).all(|k| (0..WIDE)
        .all(|l| (spilled[k] >> l & 1 != 0) == elements[i + k * WIDE + l].spill.is_some())));
    let mut stacks = [(off, room); R];
    for (k, s) in stacks.iter_mut().enumerate() {
        if spilled[k] != 0 {
            let els = &mut elements[i + k * WIDE..i + (k + 1) * WIDE];
            let base = els[0].inline.as_mut_ptr().cast::<f64>();
            *s = heap_stacks(els, spilled[k], *s, base, capacity);
        }
    }
    let p = elements[i..i + R * WIDE].as_mut_ptr();
    // SAFETY: group k's elements start at p + 8 k (inside the slice)
    let bases: [*mut f64; R] = std::array::from_fn(|k| unsafe {
        std::ptr::addr_of_mut!((*p.add(k * WIDE)).inline).cast::<f64>()
    });
    let hd: &mut [Heads; R] = (&mut heads[g..g + R]).try_into().expect("R groups");
    let at = i..i + R * WIDE;
    // SAFETY: AVX-512 (this function's features); group k's lane l's stack `stacks[k].0[l]`
    // f64 from `bases[k]` with `stacks[k].1[l]` extrema plus the spare slot
    let done = unsafe {
        pair_n::<R>(
            consts,
            hd,
            bases,
            stacks.map(|s| s.0),
            stacks.map(|s| s.1),
            &u[at.clone()],
            &ok[at.clone()],
            &mut out[at],
        )
    };
    if let Some(moved) = done {
        for k in (0..R).filter(|&k| spilled[k] & moved[k] != 0) {
            let els = &mut elements[i + k * WIDE..i + (k + 1) * WIDE];
            back_in_place(els, &mut heads[g + k], spilled[k] & moved[k]);
        }
    }
    done.is_some()
}

/// Groups side by side in [`pair_n`].
const RUNS: usize = 2;

/// The lanes of a group whose stacks are on the heap (`element::HEAP`: the counters' sign
/// bits).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn on_heap(hd: &Heads) -> __mmask8 {
    _mm512_movepi64_mask(_mm512_load_si512(hd.clamped.as_ptr().cast()))
}

/// `Everett::value_of_numbers` per lane for `u_min <= alpha, beta` (`super::avx2::everett`)
/// of `N` groups side by side, stage by stage: the four gathers of the corners of every
/// group one after the other, so that the groups' lookups overlap (on AVX-512 the gathers
/// beat a load per lane from the table by cell and its transpose: fewer instructions, and no
/// lane's index through a general register).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn everett_n<const N: usize>(
    c: &Consts,
    alpha: [__m512d; N],
    beta: [__m512d; N],
) -> [__m512d; N] {
    use std::array::from_fn;
    let zero = _mm512_setzero_pd();
    let one = _mm512_set1_pd(1.0);
    let zero_i = _mm256_setzero_si256();
    // SAFETY: AVX-512 (this function's features)
    let a: [__m512d; N] = from_fn(|k| unsafe { grid(c, alpha[k]) });
    // SAFETY: as above
    let b: [__m512d; N] = from_fn(|k| unsafe { grid(c, beta[k]) });
    let cell =
        |v: __m512d| _mm256_max_epi32(_mm256_min_epi32(_mm512_cvttpd_epi32(v), c.top), zero_i);
    let i0: [__m256i; N] = from_fn(|k| cell(a[k]));
    let j0: [__m256i; N] = from_fn(|k| cell(b[k]));
    let i64a: [__m512i; N] = from_fn(|k| _mm512_cvtepi32_epi64(i0[k]));
    let i64b: [__m512i; N] = from_fn(|k| _mm512_cvtepi32_epi64(j0[k]));
    // the corners F(i, j), F(i, j + 1), F(i + 1, j), F(i + 1, j + 1) of every group
    let f: [[__m512d; 4]; N] = if c.cells.is_null() {
        let one_i = _mm512_set1_epi64(1);
        let q: [__m512i; N] =
            from_fn(|k| _mm512_add_epi64(_mm512_mul_epi32(i64a[k], c.k), i64b[k]));
        let qk: [__m512i; N] = from_fn(|k| _mm512_add_epi64(q[k], c.k));
        let (t, k1) = (c.table, one_i);
        let f00: [__m512d; N] = from_fn(|k| _mm512_i64gather_pd::<8>(q[k], t));
        let f01: [__m512d; N] =
            from_fn(|k| _mm512_i64gather_pd::<8>(_mm512_add_epi64(q[k], k1), t));
        let f10: [__m512d; N] = from_fn(|k| _mm512_i64gather_pd::<8>(qk[k], t));
        let f11: [__m512d; N] =
            from_fn(|k| _mm512_i64gather_pd::<8>(_mm512_add_epi64(qk[k], k1), t));
        from_fn(|k| [f00[k], f01[k], f10[k], f11[k]])
    } else {
        // SAFETY: AVX-512 (this function's features); i0, j0 <= K - 2, and the table by
        // cell exists (K <= CELL_GRID_MAX)
        from_fn(|k| unsafe { cell_corners(c.cells, i0[k], j0[k]) })
    };
    from_fn(|k| {
        let wa = _mm512_sub_pd(a[k], _mm512_cvtepi32_pd(i0[k]));
        let wb = _mm512_sub_pd(b[k], _mm512_cvtepi32_pd(j0[k]));
        let (owa, owb) = (_mm512_sub_pd(one, wa), _mm512_sub_pd(one, wb));
        let [f00, f01, f10, f11] = f[k];
        let low = _mm512_add_pd(_mm512_mul_pd(owb, f00), _mm512_mul_pd(wb, f01));
        let high = _mm512_add_pd(_mm512_mul_pd(owb, f10), _mm512_mul_pd(wb, f11));
        let bilinear = _mm512_add_pd(_mm512_mul_pd(owa, low), _mm512_mul_pd(wa, high));
        let diagonal = _mm512_mul_pd(_mm512_sub_pd(wa, wb), f10);
        let on_diagonal = _mm512_cmpeq_epi64_mask(i64a[k], i64b[k]);
        let v = _mm512_mask_blend_pd(on_diagonal, bilinear, diagonal);
        _mm512_mask_blend_pd(_mm512_cmp_pd_mask::<_CMP_GE_OQ>(b[k], a[k]), v, zero)
    })
}

/// `N` groups of eight elements (`super::avx2::group` on each group of eight heads) side by
/// side: group `k`'s lane `l`'s stack starts `off[k][l]` f64 from `bases[k]` and holds
/// `room[k][l]` extrema plus the spare slot. The same lane program per group, stage by stage
/// across the groups, so that their dependent gathers (the wiped tops, the Everett corners)
/// overlap (issue 34, sixteenth round: two groups 0.988 x the step against one at a time, in
/// one process; four 0.993 x). Returns the lanes that moved per group, or `None` before
/// touching anything when an input of any group turns on a stack at its room (the scalar step
/// grows the stack or forgets a loop).
#[allow(clippy::too_many_arguments)]
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn pair_n<const N: usize>(
    c: &Consts,
    hd: &mut [Heads; N],
    bases: [*mut f64; N],
    off: [__m512i; N],
    room: [__m512i; N],
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) -> Option<[__mmask8; N]> {
    use std::array::from_fn;
    assert!(u.len() == N * WIDE && ok.len() == N * WIDE && out.len() == N * WIDE);
    let zero = _mm512_setzero_pd();
    let (one_i, two_i) = (_mm512_set1_epi64(1), _mm512_set1_epi64(2));
    let len0: [__m512i; N] = from_fn(|k| _mm512_load_si512(hd[k].len.as_ptr().cast()));
    let last_u: [__m512d; N] = from_fn(|k| _mm512_load_pd(hd[k].last_u.as_ptr()));
    let last_h: [__m512d; N] = from_fn(|k| _mm512_load_pd(hd[k].last_h.as_ptr()));
    let u_in: [__m512d; N] = from_fn(|k| _mm512_loadu_pd(u[k * WIDE..(k + 1) * WIDE].as_ptr()));
    let live: [__mmask8; N] = from_fn(|k| {
        let flags = u64::from_le_bytes(
            ok[k * WIDE..(k + 1) * WIDE]
                .try_into()
                .map_or([0; 8], |b: [bool; WIDE]| b.map(u8::from)),
        );
        let ok_k = _mm512_test_epi64_mask(
            _mm512_cvtepu8_epi64(_mm_cvtsi64_si128(flags as i64)),
            _mm512_set1_epi64(1),
        );
        let v = u_in[k];
        ok_k & _mm512_cmp_pd_mask::<_CMP_EQ_OQ>(_mm512_sub_pd(v, v), zero)
    });
    // SAFETY: AVX-512 (this function's features)
    let clamped: [__m512d; N] = from_fn(|k| unsafe { clamp(u_in[k], c.u_min, c.u_max) });
    let uc: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(live[k], c.u_min, clamped[k]));
    let rising: [__mmask8; N] = from_fn(|k| _mm512_cmp_pd_mask::<_CMP_GT_OQ>(uc[k], last_u[k]));
    let moving: [__mmask8; N] =
        from_fn(|k| !_mm512_cmp_pd_mask::<_CMP_EQ_OQ>(uc[k], last_u[k]) & live[k]);
    let turned: [__mmask8; N] = from_fn(|k| rising[k] ^ _mm512_test_epi64_mask(len0[k], one_i));
    // a turning point onto a stack at its room: the caller steps the groups one by one
    if (0..N).any(|k| _mm512_mask_cmpeq_epi64_mask(turned[k] & moving[k], len0[k], room[k]) != 0) {
        return None;
    }
    // no lane of any group moves (elements at rest, e.g. unloaded ones held at the range's
    // lower end): the last outputs again and the clampings counted, the heads as they are
    // (issue 34, seventeenth round: a constant input 2.8 x, half a mat at rest 1.3 x)
    if moving.iter().all(|&m| m == 0) {
        let nan = _mm512_set1_pd(f64::NAN);
        for k in 0..N {
            let y = _mm512_mul_pd(c.sign, _mm512_add_pd(last_h[k], c.offset));
            let o = &mut out[k * WIDE..(k + 1) * WIDE];
            _mm512_storeu_pd(o.as_mut_ptr(), _mm512_mask_blend_pd(live[k], nan, y));
            // SAFETY: AVX-512 (this function's features)
            unsafe { count_clamped(&mut hd[k], clamped[k], u_in[k], live[k]) };
        }
        return Some(moving);
    }
    // the kernel's `finish`: the turning point pushed (in registers; stored at the end)
    let top_u: [__m512d; N] = from_fn(|k| _mm512_load_pd(hd[k].top_u.as_ptr()));
    let top_h: [__m512d; N] = from_fn(|k| _mm512_load_pd(hd[k].top_h.as_ptr()));
    let below_u: [__m512d; N] = from_fn(|k| _mm512_load_pd(hd[k].below_u.as_ptr()));
    let mut len: [__m512i; N] =
        from_fn(|k| _mm512_mask_add_epi64(len0[k], turned[k], len0[k], one_i));
    let mut t_u: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(turned[k], top_u[k], last_u[k]));
    let mut t_h: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(turned[k], top_h[k], last_h[k]));
    let mut b_u: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(turned[k], below_u[k], top_u[k]));
    let dir: [__m512d; N] =
        from_fn(|k| _mm512_mask_blend_pd(rising[k], _mm512_set1_pd(-1.0), _mm512_set1_pd(1.0)));
    let passes = |k: usize, s: __m512d| {
        let d = _mm512_mul_pd(_mm512_sub_pd(uc[k], s), dir[k]);
        _mm512_cmp_pd_mask::<_CMP_GE_OQ>(d, zero)
    };
    let base: [*const f64; N] = bases.map(|b| b as *const f64);
    let slot = |k: usize, s: __m512i| _mm512_add_epi64(_mm512_add_epi64(s, s), off[k]);
    let wiped: [__mmask8; N] =
        from_fn(|k| _mm512_cmpgt_epi64_mask(len[k], two_i) & passes(k, b_u[k]) & moving[k]);
    if wiped.iter().any(|&w| w != 0) {
        // the new top and the extremum below it of every group, gathered for the lanes that
        // wiped; a group none of whose lanes wiped gathers nothing (issue 34, seventeenth
        // round: 1.02 x on the walk on an AMD Zen 5 against the masked gathers of every group)
        let tops = |t_u: &mut [__m512d; N],
                    t_h: &mut [__m512d; N],
                    b_u: &mut [__m512d; N],
                    lanes: [__mmask8; N],
                    len: &[__m512i; N]| {
            let top: [__m512i; N] = from_fn(|k| slot(k, _mm512_sub_epi64(len[k], one_i)));
            let below: [__m512i; N] =
                from_fn(|k| slot(k, _mm512_sub_epi64(_mm512_max_epi64(len[k], two_i), two_i)));
            for k in (0..N).filter(|&k| lanes[k] != 0) {
                let (at, lane) = (top[k], lanes[k]);
                t_u[k] = _mm512_mask_i64gather_pd::<8>(t_u[k], lane, at, base[k]);
                let at_h = _mm512_add_epi64(at, one_i);
                t_h[k] = _mm512_mask_i64gather_pd::<8>(t_h[k], lane, at_h, base[k]);
                b_u[k] = _mm512_mask_i64gather_pd::<8>(b_u[k], lane, below[k], base[k]);
            }
        };
        len = from_fn(|k| _mm512_mask_sub_epi64(len[k], wiped[k], len[k], two_i));
        tops(&mut t_u, &mut t_h, &mut b_u, wiped, &len);
        // deeper: while a lane passes the extremum below its new top, the gathers again
        let deep: [__mmask8; N] =
            from_fn(|k| wiped[k] & _mm512_cmpgt_epi64_mask(len[k], two_i) & passes(k, b_u[k]));
        if deep.iter().any(|&d| d != 0) {
            for k in 0..N {
                let mut wipes = deep[k];
                while wipes != 0 {
                    len[k] = _mm512_mask_sub_epi64(len[k], wipes, len[k], two_i);
                    let can = wipes & _mm512_cmpgt_epi64_mask(len[k], two_i);
                    let at = slot(k, _mm512_sub_epi64(len[k], two_i));
                    // SAFETY: AVX-512 (this function's features); each of those lanes' slot
                    // is inside its stack (len > 2)
                    let s = unsafe { few_lanes(c.loads, zero, can, at, base[k]) };
                    wipes = can & passes(k, s);
                }
            }
            tops(&mut t_u, &mut t_h, &mut b_u, deep, &len);
        }
    }
    // back at lower saturation
    for k in 0..N {
        let at_sat = _mm512_cmpeq_epi64_mask(len[k], two_i)
            & moving[k]
            & _mm512_cmp_pd_mask::<_CMP_LE_OQ>(uc[k], b_u[k]);
        if at_sat != 0 {
            len[k] = _mm512_mask_mov_epi64(len[k], at_sat, one_i);
            t_u[k] = _mm512_mask_blend_pd(at_sat, t_u[k], b_u[k]);
            let at = _mm512_add_epi64(off[k], one_i);
            // SAFETY: AVX-512 (this function's features); the first slot of each stack
            t_h[k] = unsafe { few_lanes(c.loads, t_h[k], at_sat, at, base[k]) };
        }
    }
    let odd: [__mmask8; N] = from_fn(|k| _mm512_test_epi64_mask(len[k], one_i));
    let alpha: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(odd[k], t_u[k], uc[k]));
    let beta: [__m512d; N] = from_fn(|k| _mm512_mask_blend_pd(odd[k], uc[k], t_u[k]));
    // SAFETY: AVX-512 (this function's features)
    let f = unsafe { everett_n::<N>(c, alpha, beta) };
    let nan = _mm512_set1_pd(f64::NAN);
    for k in 0..N {
        let sign = _mm512_mask_blend_pd(odd[k], _mm512_set1_pd(-2.0), _mm512_set1_pd(2.0));
        let h = _mm512_add_pd(t_h[k], _mm512_mul_pd(sign, f[k]));
        let sum = _mm512_mask_blend_pd(moving[k], last_h[k], h);
        let y = _mm512_mul_pd(c.sign, _mm512_add_pd(sum, c.offset));
        let o = &mut out[k * WIDE..(k + 1) * WIDE];
        _mm512_storeu_pd(o.as_mut_ptr(), _mm512_mask_blend_pd(live[k], nan, y));
        // the turning point into the slot above the old top of each stack where a lane of
        // the group keeps one (moved and turned): every lane's pair goes to its slot above
        // the top, which is never read unless pushed and exists at the room too (the spare)
        if turned[k] & moving[k] != 0 {
            debug_assert_eq!(_mm512_cmpgt_epi64_mask(len0[k], room[k]), 0);
            let at = _mm512_add_epi64(_mm512_add_epi64(len0[k], len0[k]), off[k]);
            // SAFETY: AVX-512 (this function's features); lane l's slot `at[l]` f64 from
            // `bases[k]` is inside its stack (len0 <= room, and a stack holds room + 1 pairs)
            unsafe { store_pairs(bases[k], at, last_u[k], last_h[k]) };
        }
        // the heads of the lanes that moved
        let m = moving[k];
        let keep = |old: __m512d, new: __m512d| _mm512_mask_blend_pd(m, old, new);
        let h_len = _mm512_mask_blend_epi64(m, len0[k], len[k]);
        let g = &mut hd[k];
        _mm512_store_si512(g.len.as_mut_ptr().cast(), h_len);
        _mm512_store_pd(g.last_u.as_mut_ptr(), keep(last_u[k], uc[k]));
        _mm512_store_pd(g.last_h.as_mut_ptr(), keep(last_h[k], h));
        _mm512_store_pd(g.top_u.as_mut_ptr(), keep(top_u[k], t_u[k]));
        _mm512_store_pd(g.top_h.as_mut_ptr(), keep(top_h[k], t_h[k]));
        _mm512_store_pd(g.below_u.as_mut_ptr(), keep(below_u[k], b_u[k]));
        // SAFETY: AVX-512 (this function's features)
        unsafe { count_clamped(g, clamped[k], u_in[k], live[k]) };
    }
    Some(moving)
}

/// The clamping counters of a group's live lanes whose input was clamped (`clamped` is not
/// `u`) go up by one.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn count_clamped(g: &mut Heads, clamped: __m512d, u: __m512d, live: __mmask8) {
    let was_clamped = _mm512_cmp_pd_mask::<_CMP_NEQ_UQ>(clamped, u) & live;
    if was_clamped != 0 {
        let counts = _mm512_load_si512(g.clamped.as_ptr().cast());
        let counts = _mm512_mask_add_epi64(counts, was_clamped, counts, _mm512_set1_epi64(1));
        _mm512_store_si512(g.clamped.as_mut_ptr().cast(), counts);
    }
}

/// The stacks of a group with stacks on the heap: the offsets and rooms of stacks in place
/// (`off`, `room`), with each lane of `heap` given its stack's offset from lane 0's place in
/// f64 (the distance of two f64 arrays) and its room. Only those lanes' elements are read: the
/// others' stacks are in place (issue 34, nineteenth round: reading all eight
/// elements' stack fields, eight cache lines a step, made the steps of a group with a stack
/// on the heap cost several times a group's step in place).
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn heap_stacks(
    els: &mut [Element],
    heap: __mmask8,
    (mut off, mut room): (__m512i, __m512i),
    base: *mut f64,
    capacity: usize,
) -> (__m512i, __m512i) {
    let mut lanes = heap;
    while lanes != 0 {
        let l = lanes.trailing_zeros() as usize;
        let one = 1 << l;
        lanes &= lanes - 1;
        let el = &mut els[l];
        let at = (el.stack_mut().as_mut_ptr() as isize - base as isize) as i64 >> 3;
        room = _mm512_mask_set1_epi64(room, one, el.room(capacity) as i64);
        off = _mm512_mask_set1_epi64(off, one, at);
    }
    (off, room)
}

/// A stack on the heap that is shallow again after a step that moved it (the lanes
/// `moved`, each with its stack on the heap) goes back in place (`Element::step`).
#[inline]
fn back_in_place(els: &mut [Element], hd: &mut Heads, moved: __mmask8) {
    let mut lanes = moved;
    while lanes != 0 {
        let l = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        let len = hd.len[l] as usize;
        debug_assert!(els[l].spill.is_some());
        if len <= INLINE_EXTREMA / 2 {
            els[l].unspill(len);
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
    /// The table by cell (`Everett::cells`), or null: the corners gathered from `table`
    /// (a large grid, or [`crate::simd::Lookup::Gather`]).
    cells: *const f64,
    /// [`crate::simd::Lookup::Loads`]: a few lanes' stack slots by loads ([`few_lanes`]).
    loads: bool,
}

impl Consts {
    #[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
    unsafe fn new(e: &EverettView<'_, f64>, cells: &[f64], output: Output<f64>) -> Self {
        let k = e.size();
        debug_assert!(cells.is_empty() || cells.len() == 2 * k * (k - 1));
        let loads = crate::simd::lookup() == crate::simd::Lookup::Loads;
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
            loads,
            cells: if loads && !cells.is_empty() {
                cells.as_ptr()
            } else {
                std::ptr::null()
            },
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
