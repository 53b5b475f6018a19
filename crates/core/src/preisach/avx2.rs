//! The Preisach step (eq. 4.16-4.22) across four elements at once, in the lanes of AVX2
//! registers: the same operations as the scalar kernel (`texsense_kernels::preisach`
//! `prepare` + `finish`, `Everett::value_of_numbers`) in the same order, without fused
//! multiply-adds, so every output and every state is the scalar kernel's, bit for bit.
//!
//! What differs is how the data-dependent outcomes are taken: rising or falling, turning
//! or not, wiping out a loop or not, which Everett cell — all are lane masks and blends, so
//! a random walk costs no mispredicted branch per element. The stacks stay where they are
//! (each element's own, in place or on the heap); the four lanes' extrema and the Everett
//! table entries are gathered. The rare outcomes the lanes cannot share run the scalar
//! step for the whole group: a stack at its room (it grows on the heap or forgets a loop).
//! Deeper wiping-out (two loops or more in one step) loops while any lane still wipes.

use std::arch::x86_64::*;

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::Output;

use super::{Element, INLINE_EXTREMA};

/// Lanes of a register.
const LANES: usize = 4;

/// One frame of a block: inputs `u`, validity `ok` -> outputs `out` (NaN where invalid or
/// not finite), the elements' states stepped; identical to the scalar step per element.
///
/// # Safety
/// The processor must have AVX2. `u`, `ok` and `out` hold `elements.len()` values.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn row(
    e: &EverettView<'_, f64>,
    capacity: usize,
    output: Output<f64>,
    elements: &mut [Element],
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let n = elements.len();
    assert!(u.len() == n && ok.len() == n && out.len() == n);
    let consts = Consts::new(e, output);
    let mut i = 0;
    while i + LANES <= n {
        let els = &mut elements[i..i + LANES];
        let at_room = els
            .iter()
            .any(|el| el.head.len as usize == (el.stack().len() - 1).min(capacity));
        if at_room {
            for l in 0..LANES {
                out[i + l] = scalar(&mut els[l], e, capacity, output, u[i + l], ok[i + l]);
            }
        } else {
            // SAFETY: AVX2 (this function's feature); four elements, inputs and outputs
            unsafe {
                group(
                    &consts,
                    e,
                    els,
                    &u[i..i + LANES],
                    &ok[i..i + LANES],
                    &mut out[i..i + LANES],
                )
            };
        }
        i += LANES;
    }
    for j in i..n {
        out[j] = scalar(&mut elements[j], e, capacity, output, u[j], ok[j]);
    }
}

/// The scalar step of one element (the kernel's, through `Element::step`).
#[inline(always)]
fn scalar(
    el: &mut Element,
    e: &EverettView<'_, f64>,
    capacity: usize,
    output: Output<f64>,
    u: f64,
    ok: bool,
) -> f64 {
    if ok && u.is_finite() {
        output.of(el.step(e, capacity, u))
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
}

impl Consts {
    #[target_feature(enable = "avx2")]
    unsafe fn new(e: &EverettView<'_, f64>, output: Output<f64>) -> Self {
        let k = e.size();
        Self {
            u_min: _mm256_set1_pd(e.u_min()),
            u_max: _mm256_set1_pd(e.u_max()),
            inv_step: _mm256_set1_pd(e.inv_step()),
            last: _mm256_set1_pd((k - 1) as f64),
            top: _mm_set1_epi32((k - 2) as i32),
            k: _mm256_set1_epi64x(k as i64),
            offset: _mm256_set1_pd(output.offset),
            sign: _mm256_set1_pd(output.sign),
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

/// An input in grid steps, clamped into `[0, K - 1]` (0 for a lane that is not a number).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn grid(c: &Consts, v: __m256d) -> __m256d {
    let zero = _mm256_setzero_pd();
    let x = clamp(
        _mm256_mul_pd(_mm256_sub_pd(v, c.u_min), c.inv_step),
        zero,
        c.last,
    );
    _mm256_blendv_pd(x, zero, _mm256_cmp_pd::<_CMP_UNORD_Q>(x, x))
}

/// `Everett::value_of_numbers` per lane (the same arithmetic; lanes that are not numbers
/// read the table's first cell instead of out of bounds, and are discarded by the caller).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn everett(c: &Consts, table: *const f64, alpha: __m256d, beta: __m256d) -> __m256d {
    let zero = _mm256_setzero_pd();
    let one = _mm256_set1_pd(1.0);
    let (a, b) = (grid(c, alpha), grid(c, beta));
    // a, b in [0, K - 1]: truncation is the floor; then at most K - 2
    let i0 = _mm_min_epi32(_mm256_cvttpd_epi32(a), c.top);
    let j0 = _mm_min_epi32(_mm256_cvttpd_epi32(b), c.top);
    let wa = _mm256_sub_pd(a, _mm256_cvtepi32_pd(i0));
    let wb = _mm256_sub_pd(b, _mm256_cvtepi32_pd(j0));
    let (i64a, i64b) = (_mm256_cvtepi32_epi64(i0), _mm256_cvtepi32_epi64(j0));
    let q = _mm256_add_epi64(_mm256_mul_epi32(i64a, c.k), i64b);
    let one_i = _mm256_set1_epi64x(1);
    let f00 = _mm256_i64gather_pd::<8>(table, q);
    let f01 = _mm256_i64gather_pd::<8>(table, _mm256_add_epi64(q, one_i));
    let qk = _mm256_add_epi64(q, c.k);
    let f10 = _mm256_i64gather_pd::<8>(table, qk);
    let f11 = _mm256_i64gather_pd::<8>(table, _mm256_add_epi64(qk, one_i));
    let (owa, owb) = (_mm256_sub_pd(one, wa), _mm256_sub_pd(one, wb));
    let low = _mm256_add_pd(_mm256_mul_pd(owb, f00), _mm256_mul_pd(wb, f01));
    let high = _mm256_add_pd(_mm256_mul_pd(owb, f10), _mm256_mul_pd(wb, f11));
    let bilinear = _mm256_add_pd(_mm256_mul_pd(owa, low), _mm256_mul_pd(wa, high));
    let diagonal = _mm256_mul_pd(_mm256_sub_pd(wa, wb), f10);
    let on_diagonal = _mm256_castsi256_pd(_mm256_cmpeq_epi64(i64a, i64b));
    let v = _mm256_blendv_pd(bilinear, diagonal, on_diagonal);
    _mm256_blendv_pd(v, zero, _mm256_cmp_pd::<_CMP_GE_OQ>(b, a))
}

/// The four lanes of a group at the start of a step (prepare: clamped input, moving,
/// rising, turning).
struct Lanes {
    /// Each lane's stack (in place or on the heap).
    stacks: [*mut f64; LANES],
    /// Lane 0's stack: the gathers' base.
    base: *const f64,
    /// Each lane's stack from `base`, in f64 steps.
    off: __m256i,
    len0: __m256i,
    last_u: __m256d,
    last_h: __m256d,
    /// The input clamped into the range (`u_min` where not live).
    uc: __m256d,
    /// Valid and finite.
    live: __m256d,
    /// Live, and not the last input again.
    moving: __m256d,
    rising: __m256d,
    turned: __m256i,
    was_clamped: __m256d,
}

/// Read four elements' heads and inputs into lanes (the kernel's `prepare`).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn load(c: &Consts, els: &mut [Element], u: &[f64], ok: &[bool]) -> Lanes {
    let one_i = _mm256_set1_epi64x(1);
    let mut stacks = [std::ptr::null_mut::<f64>(); LANES];
    for (p, el) in stacks.iter_mut().zip(els.iter_mut()) {
        *p = match &mut el.spill {
            Some(b) => b.as_mut_ptr().cast::<f64>(),
            None => el.inline.as_mut_ptr().cast::<f64>(),
        };
    }
    let base = stacks[0] as *const f64;
    let rel = |l: usize| (stacks[l] as isize - base as isize) as i64 / 8;
    let h = |l: usize| &els[l].head;
    let len0 = _mm256_set_epi64x(
        h(3).len as i64,
        h(2).len as i64,
        h(1).len as i64,
        h(0).len as i64,
    );
    let last_u = _mm256_set_pd(h(3).last_u, h(2).last_u, h(1).last_u, h(0).last_u);
    let last_h = _mm256_set_pd(h(3).last_h, h(2).last_h, h(1).last_h, h(0).last_h);
    let u_in = _mm256_loadu_pd(u.as_ptr());
    let m = |b: bool| -i64::from(b);
    let ok_m = _mm256_castsi256_pd(_mm256_set_epi64x(m(ok[3]), m(ok[2]), m(ok[1]), m(ok[0])));
    // valid and finite (x - x is 0 for a finite x, NaN otherwise)
    let finite = _mm256_cmp_pd::<_CMP_EQ_OQ>(_mm256_sub_pd(u_in, u_in), _mm256_setzero_pd());
    let live = _mm256_and_pd(ok_m, finite);
    let clamped = clamp(u_in, c.u_min, c.u_max);
    let uc = _mm256_blendv_pd(c.u_min, clamped, live);
    let rising = _mm256_cmp_pd::<_CMP_GT_OQ>(uc, last_u);
    let odd0 = _mm256_cmpeq_epi64(_mm256_and_si256(len0, one_i), one_i);
    Lanes {
        stacks,
        base,
        off: _mm256_set_epi64x(rel(3), rel(2), rel(1), rel(0)),
        len0,
        last_u,
        last_h,
        uc,
        live,
        moving: _mm256_andnot_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(uc, last_u), live),
        rising,
        turned: _mm256_xor_si256(_mm256_castpd_si256(rising), odd0),
        was_clamped: _mm256_and_pd(_mm256_cmp_pd::<_CMP_NEQ_UQ>(clamped, u_in), live),
    }
}

/// Slot `s` (an extremum's index) of every lane's stack as an index from `base`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn slot(l: &Lanes, s: __m256i) -> __m256i {
    _mm256_add_epi64(_mm256_add_epi64(s, s), l.off)
}

/// The depth after pushing the turning point and wiping out the loops the input passes
/// (and back at lower saturation), per lane (the kernel's `finish`, up to the top).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn wipe_out(l: &Lanes) -> __m256i {
    let zero = _mm256_setzero_pd();
    let (one_i, two_i) = (_mm256_set1_epi64x(1), _mm256_set1_epi64x(2));
    let mut len = _mm256_sub_epi64(l.len0, l.turned);
    let dir = _mm256_blendv_pd(_mm256_set1_pd(-1.0), _mm256_set1_pd(1.0), l.rising);
    let passes = |s: __m256d| {
        let d = _mm256_mul_pd(_mm256_sub_pd(l.uc, s), dir);
        _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_GE_OQ>(d, zero))
    };
    // the extremum below the top: slot max(len, 2) - 2
    let at_least_3 = _mm256_cmpgt_epi64(len, two_i);
    let below = _mm256_blendv_epi8(len, two_i, _mm256_cmpgt_epi64(two_i, len));
    let s_below = _mm256_i64gather_pd::<8>(l.base, slot(l, _mm256_sub_epi64(below, two_i)));
    let mut wipes = _mm256_and_si256(at_least_3, passes(s_below));
    len = _mm256_add_epi64(len, _mm256_add_epi64(wipes, wipes));
    // deeper levels (rare): while any moving lane still passes the extremum below its top
    wipes = _mm256_and_si256(wipes, _mm256_castpd_si256(l.moving));
    loop {
        let can = _mm256_and_si256(wipes, _mm256_cmpgt_epi64(len, two_i));
        if _mm256_testz_si256(can, can) != 0 {
            break;
        }
        let at = slot(l, _mm256_sub_epi64(len, two_i));
        let s = _mm256_mask_i64gather_pd::<8>(zero, l.base, at, _mm256_castsi256_pd(can));
        wipes = _mm256_and_si256(can, passes(s));
        len = _mm256_add_epi64(len, _mm256_add_epi64(wipes, wipes));
    }
    // back at lower saturation
    let s0 = _mm256_i64gather_pd::<8>(l.base, l.off);
    let at_sat = _mm256_and_si256(
        _mm256_cmpeq_epi64(len, two_i),
        _mm256_castpd_si256(_mm256_cmp_pd::<_CMP_LE_OQ>(l.uc, s0)),
    );
    _mm256_blendv_epi8(len, one_i, at_sat)
}

/// Four elements whose stacks all have room for a turning point.
#[target_feature(enable = "avx2")]
unsafe fn group(
    c: &Consts,
    e: &EverettView<'_, f64>,
    els: &mut [Element],
    u: &[f64],
    ok: &[bool],
    out: &mut [f64],
) {
    let one_i = _mm256_set1_epi64x(1);
    let l = load(c, els, u, ok);
    let len = wipe_out(&l);
    // the top: x + 2 F(u, m) after a minimum, x - 2 F(M, u) after a maximum. The last
    // input and output go into the slot above the old top (kept on a turn) after the last
    // gather (a gather cannot take a value from a store still in flight): a lane whose new
    // top is that slot takes them from the registers.
    let top_slot = slot(&l, _mm256_sub_epi64(len, one_i));
    let pushed = _mm256_castsi256_pd(_mm256_cmpeq_epi64(len, _mm256_add_epi64(l.len0, one_i)));
    let stored = _mm256_andnot_pd(pushed, _mm256_castsi256_pd(_mm256_set1_epi64x(-1)));
    let top = _mm256_mask_i64gather_pd::<8>(l.last_u, l.base, top_slot, stored);
    let x_slot = _mm256_add_epi64(top_slot, one_i);
    let x = _mm256_mask_i64gather_pd::<8>(l.last_h, l.base, x_slot, stored);
    let odd = _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_and_si256(len, one_i), one_i));
    let alpha = _mm256_blendv_pd(top, l.uc, odd);
    let beta = _mm256_blendv_pd(l.uc, top, odd);
    let sign = _mm256_blendv_pd(_mm256_set1_pd(-2.0), _mm256_set1_pd(2.0), odd);
    let f = everett(c, e.table().as_ptr(), alpha, beta);
    let h = _mm256_add_pd(x, _mm256_mul_pd(sign, f));
    let sum = _mm256_blendv_pd(l.last_h, h, l.moving);
    let y = _mm256_mul_pd(c.sign, _mm256_add_pd(sum, c.offset));
    let nan = _mm256_set1_pd(f64::NAN);
    _mm256_storeu_pd(out.as_mut_ptr(), _mm256_blendv_pd(nan, y, l.live));
    store(&l, els, len, h);
}

/// The pushed slots, the moving lanes' heads, the counters, a stack back in place once
/// shallow.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn store(l: &Lanes, els: &mut [Element], len: __m256i, h: __m256d) {
    let mut lens = [0i64; LANES];
    _mm256_storeu_si256(lens.as_mut_ptr().cast(), l.len0);
    let (mut lu, mut lh) = ([0.0; LANES], [0.0; LANES]);
    _mm256_storeu_pd(lu.as_mut_ptr(), l.last_u);
    _mm256_storeu_pd(lh.as_mut_ptr(), l.last_h);
    for k in 0..LANES {
        // SAFETY: a stack has room + 1 >= len + 1 slots (len <= room, the bank's invariant)
        unsafe {
            *l.stacks[k].add(2 * lens[k] as usize) = lu[k];
            *l.stacks[k].add(2 * lens[k] as usize + 1) = lh[k];
        }
    }
    let (mut hs, mut us) = ([0.0; LANES], [0.0; LANES]);
    _mm256_storeu_pd(hs.as_mut_ptr(), h);
    _mm256_storeu_pd(us.as_mut_ptr(), l.uc);
    _mm256_storeu_si256(lens.as_mut_ptr().cast(), len);
    let moved = _mm256_movemask_pd(l.moving);
    let clamps = _mm256_movemask_pd(l.was_clamped);
    for (k, el) in els.iter_mut().enumerate() {
        el.clamped += u64::from(clamps >> k & 1 != 0);
        if moved >> k & 1 != 0 {
            el.head.len = lens[k] as u32;
            el.head.last_u = us[k];
            el.head.last_h = hs[k];
            if lens[k] as usize <= INLINE_EXTREMA / 2 && el.spill.is_some() {
                el.unspill();
            }
        }
    }
}
