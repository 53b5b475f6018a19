//! The Preisach step (eq. 4.16-4.22) in float32, eight elements in the lanes of one AVX2
//! register (issue 34, seventh round): an **experimental bank** that measures what float32
//! lanes give before the pipeline's state is laid out for them. It is not on any path of
//! the pipeline; `examples/preisach_time.rs` times it beside the float64 bank.
//!
//! Its numbers are those of the scalar kernel in float32
//! (`texsense_kernels::preisach::step::<f32>`, the microcontroller's arithmetic) bit for bit:
//! the same operations in the same order, without fused multiply-adds (property test in
//! `preisach/tests_f32x8.rs`). Against the float64 kernel they differ by the rounding of
//! float32: inputs and table rounded to 24 bits, and every Everett value of the sum rounded
//! (the bound the test holds is stated there).
//!
//! Layout: every element has a stack of [`ROOM`]` + 1` slots in place (no heap); the heads
//! of eight neighbouring elements are one group, field after field, as in the float64
//! bank (depth, last input and output, copies of the top extremum and of the input below
//! it, the clamping counter). A group with a stack at its room runs the scalar kernel,
//! which forgets the innermost loop. An input counts as a number when its float32 rounding
//! is finite (a reading beyond ±3.4e38 is not a number here; the float64 bank clamps it).

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::{self as kernel, Head, Output, CLAMPED};

use super::Everett;
use crate::error::{check_len, frames_of, CoreError};
use crate::everett::CELL_GRID_MAX;

/// Elements per group: the f32 lanes of an AVX2 register.
pub const WIDTH: usize = 8;
/// Turning points an element keeps (its stack in place holds one slot more).
pub const ROOM: usize = 28;
/// f32 values per stack: `ROOM + 1` slots of input and output.
const STACK: usize = 2 * (ROOM + 1);

/// The heads of eight neighbouring elements, field after field.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
struct Heads8 {
    len: [i32; WIDTH],
    last_u: [f32; WIDTH],
    last_h: [f32; WIDTH],
    top_u: [f32; WIDTH],
    top_h: [f32; WIDTH],
    below_u: [f32; WIDTH],
    clamped: [u32; WIDTH],
}

impl Heads8 {
    fn new(u_min: f32) -> Self {
        Self {
            len: [1; WIDTH],
            last_u: [u_min; WIDTH],
            last_h: [0.0; WIDTH],
            top_u: [u_min; WIDTH],
            top_h: [0.0; WIDTH],
            below_u: [u_min; WIDTH],
            clamped: [0; WIDTH],
        }
    }

    fn head(&self, l: usize) -> Head<f32> {
        Head {
            len: self.len[l] as u32,
            last_u: self.last_u[l],
            last_h: self.last_h[l],
        }
    }

    fn set(&mut self, l: usize, h: &Head<f32>, s: &[[f32; 2]]) {
        let len = h.len as usize;
        self.len[l] = len as i32;
        self.last_u[l] = h.last_u;
        self.last_h[l] = h.last_h;
        [self.top_u[l], self.top_h[l]] = s[len - 1];
        self.below_u[l] = s[len.max(2) - 2][0];
    }
}

/// N elements of one Everett function in float32 (see the module's text).
#[derive(Debug, Clone)]
pub struct Bank32 {
    k: usize,
    u_min: f32,
    u_max: f32,
    table: Vec<f32>,
    /// The table by cell, as [`Everett`]'s, in float32 (16 bytes a cell).
    cells: Vec<f32>,
    output: Output<f32>,
    n: usize,
    heads: Vec<Heads8>,
    stacks: Vec<[[f32; 2]; ROOM + 1]>,
}

impl Bank32 {
    /// N elements at lower saturation; the table and range rounded to float32 (grids of
    /// at most [`CELL_GRID_MAX`] points).
    pub fn new(everett: &Everett, n: usize) -> Result<Self, CoreError> {
        let k = everett.k;
        if k > CELL_GRID_MAX {
            return Err(CoreError::Parameter {
                what: "everett",
                why: format!("the float32 bank needs a grid of <= {CELL_GRID_MAX} points"),
            });
        }
        let table: Vec<f32> = everett.table.iter().map(|&v| v as f32).collect();
        let mut cells = Vec::with_capacity(2 * k * (k - 1));
        for i in 0..k - 1 {
            for j in 0..=i {
                let q = i * k + j;
                cells.extend_from_slice(&[table[q], table[q + 1], table[q + k], table[q + k + 1]]);
            }
        }
        let (u_min, u_max) = (everett.u_min as f32, everett.u_max as f32);
        let mut bank = Self {
            k,
            u_min,
            u_max,
            table,
            cells,
            output: Output::identity(),
            n,
            heads: Vec::new(),
            stacks: Vec::new(),
        };
        bank.view()?;
        bank.reset();
        Ok(bank)
    }

    /// The output `sign (h + offset)` (offset rounded to float32; sign +1 or -1).
    pub fn with_output(mut self, offset: f64, sign: f64) -> Result<Self, CoreError> {
        if !(offset as f32).is_finite() || (sign != 1.0 && sign != -1.0) {
            return Err(CoreError::Parameter {
                what: "output",
                why: format!("offset must be finite and sign +1 or -1, got {offset}, {sign}"),
            });
        }
        self.output = Output {
            offset: offset as f32,
            sign: sign as f32,
        };
        Ok(self)
    }

    /// Back to lower saturation.
    pub fn reset(&mut self) {
        let groups = self.n.div_ceil(WIDTH);
        self.heads = vec![Heads8::new(self.u_min); groups];
        let mut s = [[0.0f32; 2]; ROOM + 1];
        s[0] = [self.u_min, 0.0];
        self.stacks = vec![s; groups * WIDTH];
    }

    fn view(&self) -> Result<EverettView<'_, f32>, CoreError> {
        EverettView::new(self.k, self.u_min, self.u_max, &self.table).map_err(|e| {
            CoreError::Parameter {
                what: "everett",
                why: format!("{e:?} in float32"),
            }
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// A batch of frames (T x N, row-major), frame after frame on the calling thread.
    pub fn run(&mut self, u: &[f64], ok: &[bool], out: &mut [f64]) -> Result<(), CoreError> {
        let n = self.n;
        if n == 0 {
            return Ok(());
        }
        frames_of("inputs", u.len(), n)?;
        check_len("valid", ok.len(), u.len())?;
        check_len("out", out.len(), u.len())?;
        for ((f, v), o) in u
            .chunks_exact(n)
            .zip(ok.chunks_exact(n))
            .zip(out.chunks_exact_mut(n))
        {
            self.row(f, v, o);
        }
        Ok(())
    }

    /// Depth of every element's stack.
    pub fn depth(&self) -> Vec<usize> {
        (0..self.n)
            .map(|i| self.heads[i / WIDTH].len[i % WIDTH] as usize)
            .collect()
    }

    /// Samples clamped into the input range, per element.
    pub fn clamped(&self) -> Vec<u64> {
        (0..self.n)
            .map(|i| u64::from(self.heads[i / WIDTH].clamped[i % WIDTH]))
            .collect()
    }

    /// One frame: inputs `u` (rounded to float32) and their validity -> outputs (NaN where
    /// invalid or not a number); on AVX2 eight elements at a time.
    ///
    /// # Panics
    /// When a slice does not hold one value per element.
    pub fn row(&mut self, u: &[f64], ok: &[bool], out: &mut [f64]) {
        let n = self.n;
        assert!(u.len() == n && ok.len() == n && out.len() == n);
        #[cfg(target_arch = "x86_64")]
        let lanes = crate::simd::avx2();
        #[cfg(not(target_arch = "x86_64"))]
        let lanes = false;
        let whole = if lanes { n / WIDTH * WIDTH } else { 0 };
        #[cfg(target_arch = "x86_64")]
        if whole > 0 {
            // SAFETY: AVX2 (detected); the slices hold `whole` values (checked above)
            unsafe { avx2::groups(self, whole, u, ok, out) };
        }
        for i in whole..n {
            out[i] = self.scalar(i, u[i], ok[i]);
        }
    }

    /// Element `i`'s step by the scalar kernel in float32.
    fn scalar(&mut self, i: usize, u: f64, ok: bool) -> f64 {
        let u = u as f32;
        if !(ok && u.is_finite()) {
            return f64::NAN;
        }
        let output = self.output;
        let e = EverettView::new(self.k, self.u_min, self.u_max, &self.table[..]);
        let e = e.expect("checked by new");
        let (hd, l) = (&mut self.heads[i / WIDTH], i % WIDTH);
        let s = &mut self.stacks[i];
        let mut head = hd.head(l);
        let (h, flags) = kernel::step(&mut head, s, ROOM, &e, u);
        hd.set(l, &head, s);
        hd.clamped[l] += u32::from(flags & CLAMPED != 0);
        f64::from(output.of(h))
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use std::arch::x86_64::*;

    use super::{Bank32, Heads8, ROOM, STACK, WIDTH};

    /// The bank's constants in registers.
    struct Consts {
        u_min: __m256,
        u_max: __m256,
        inv_step: __m256,
        last: __m256,
        top: __m256i,
        offset: __m256,
        sign: __m256,
        cells: *const f32,
    }

    /// The first `whole` elements (whole groups) of a frame.
    ///
    /// # Safety
    /// The processor must have AVX2; `u`, `ok`, `out` hold at least `whole` values, a
    /// multiple of [`WIDTH`] not above the bank's length.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn groups(
        b: &mut Bank32,
        whole: usize,
        u: &[f64],
        ok: &[bool],
        out: &mut [f64],
    ) {
        assert!(whole.is_multiple_of(WIDTH) && whole <= b.n);
        assert!(u.len() >= whole && ok.len() >= whole && out.len() >= whole);
        let inv_step = b.view().expect("checked by new").inv_step();
        let c = Consts {
            u_min: _mm256_set1_ps(b.u_min),
            u_max: _mm256_set1_ps(b.u_max),
            inv_step: _mm256_set1_ps(inv_step),
            last: _mm256_set1_ps((b.k - 1) as f32),
            top: _mm256_set1_epi32((b.k - 2) as i32),
            offset: _mm256_set1_ps(b.output.offset),
            sign: _mm256_set1_ps(b.output.sign),
            cells: b.cells.as_ptr(),
        };
        let room = _mm256_set1_epi32(ROOM as i32);
        let s = STACK as i32;
        let off = _mm256_setr_epi32(0, s, 2 * s, 3 * s, 4 * s, 5 * s, 6 * s, 7 * s);
        for g in 0..whole / WIDTH {
            let i = g * WIDTH;
            let len = _mm256_load_si256(b.heads[g].len.as_ptr().cast());
            if _mm256_testz_si256(_mm256_cmpeq_epi32(len, room), _mm256_set1_epi32(-1)) == 0 {
                for l in i..i + WIDTH {
                    out[l] = b.scalar(l, u[l], ok[l]);
                }
                continue;
            }
            let lo = _mm256_cvtpd_ps(_mm256_loadu_pd(u.as_ptr().add(i)));
            let hi = _mm256_cvtpd_ps(_mm256_loadu_pd(u.as_ptr().add(i + 4)));
            let okg: &[bool; WIDTH] = ok[i..i + WIDTH].try_into().expect("a whole group");
            let bytes = u64::from_le_bytes(okg.map(u8::from));
            let ok_m = _mm256_cmpgt_epi32(
                _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bytes as i64)),
                _mm256_setzero_si256(),
            );
            let base = b.stacks.as_mut_ptr().add(i).cast::<f32>();
            let hd = &mut b.heads[g];
            // SAFETY: AVX2; eight stacks of STACK values from `base`, each with room for a
            // turning point (no lane at its room, tested above); eight outputs at `i`
            let y = unsafe { group(&c, hd, base, off, _mm256_set_m128(hi, lo), ok_m) };
            let o = out.as_mut_ptr().add(i);
            _mm256_storeu_pd(o, _mm256_cvtps_pd(_mm256_castps256_ps128(y)));
            _mm256_storeu_pd(o.add(4), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(y)));
        }
    }

    /// `f32::clamp` per lane (a signed zero kept).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn clamp(x: __m256, lo: __m256, hi: __m256) -> __m256 {
        let x = _mm256_blendv_ps(x, lo, _mm256_cmp_ps::<_CMP_LT_OQ>(x, lo));
        _mm256_blendv_ps(x, hi, _mm256_cmp_ps::<_CMP_GT_OQ>(x, hi))
    }

    /// Grid position of `v >= u_min`, at most K - 1 (the kernel's clamp takes only its
    /// upper bound for such inputs, as in the float64 lanes).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn grid(c: &Consts, v: __m256) -> __m256 {
        _mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(v, c.u_min), c.inv_step), c.last)
    }

    /// `Everett::value_of_numbers` in float32 per lane for `u_min <= alpha, beta`: each
    /// lane's cell loaded as 16 bytes, lanes `l` and `l + 4` in one register, transposed.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn everett(c: &Consts, alpha: __m256, beta: __m256) -> __m256 {
        let (a, b) = (grid(c, alpha), grid(c, beta));
        let zero_i = _mm256_setzero_si256();
        let i0 = _mm256_max_epi32(_mm256_min_epi32(_mm256_cvttps_epi32(a), c.top), zero_i);
        let j0 = _mm256_max_epi32(_mm256_min_epi32(_mm256_cvttps_epi32(b), c.top), zero_i);
        let wa = _mm256_sub_ps(a, _mm256_cvtepi32_ps(i0));
        let wb = _mm256_sub_ps(b, _mm256_cvtepi32_ps(j0));
        let one_i = _mm256_set1_epi32(1);
        let tri = _mm256_srli_epi32::<1>(_mm256_mullo_epi32(i0, _mm256_add_epi32(i0, one_i)));
        let q = _mm256_slli_epi32::<2>(_mm256_add_epi32(tri, j0));
        let mut at = [0i32; WIDTH];
        _mm256_storeu_si256(at.as_mut_ptr().cast(), q);
        // SAFETY: i0, j0 <= K - 2: every cell index is below (K - 1) K / 2
        let pair = |l: usize| unsafe {
            _mm256_set_m128(
                _mm_loadu_ps(c.cells.add(at[l + 4] as usize)),
                _mm_loadu_ps(c.cells.add(at[l] as usize)),
            )
        };
        let (r0, r1, r2, r3) = (pair(0), pair(1), pair(2), pair(3));
        let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpacklo_ps(r2, r3));
        let (t2, t3) = (_mm256_unpackhi_ps(r0, r1), _mm256_unpackhi_ps(r2, r3));
        let f00 = _mm256_shuffle_ps::<0x44>(t0, t1);
        let f01 = _mm256_shuffle_ps::<0xEE>(t0, t1);
        let f10 = _mm256_shuffle_ps::<0x44>(t2, t3);
        let f11 = _mm256_shuffle_ps::<0xEE>(t2, t3);
        let one = _mm256_set1_ps(1.0);
        let (owa, owb) = (_mm256_sub_ps(one, wa), _mm256_sub_ps(one, wb));
        let low = _mm256_add_ps(_mm256_mul_ps(owb, f00), _mm256_mul_ps(wb, f01));
        let high = _mm256_add_ps(_mm256_mul_ps(owb, f10), _mm256_mul_ps(wb, f11));
        let bilinear = _mm256_add_ps(_mm256_mul_ps(owa, low), _mm256_mul_ps(wa, high));
        let diagonal = _mm256_mul_ps(_mm256_sub_ps(wa, wb), f10);
        let on_diagonal = _mm256_castsi256_ps(_mm256_cmpeq_epi32(i0, j0));
        let v = _mm256_blendv_ps(bilinear, diagonal, on_diagonal);
        _mm256_blendv_ps(v, _mm256_setzero_ps(), _mm256_cmp_ps::<_CMP_GE_OQ>(b, a))
    }

    /// Eight elements whose stacks all have room for a turning point: the outputs (NaN
    /// where not live), the heads and the pushed turning points stored.
    #[target_feature(enable = "avx2")]
    unsafe fn group(
        c: &Consts,
        hd: &mut Heads8,
        base: *mut f32,
        off: __m256i,
        u_in: __m256,
        ok_m: __m256i,
    ) -> __m256 {
        let zero = _mm256_setzero_ps();
        let (one_i, two_i) = (_mm256_set1_epi32(1), _mm256_set1_epi32(2));
        // the kernel's `prepare`
        let len0 = _mm256_load_si256(hd.len.as_ptr().cast());
        let last_u = _mm256_load_ps(hd.last_u.as_ptr());
        let last_h = _mm256_load_ps(hd.last_h.as_ptr());
        let finite = _mm256_cmp_ps::<_CMP_EQ_OQ>(_mm256_sub_ps(u_in, u_in), zero);
        let live = _mm256_and_ps(_mm256_castsi256_ps(ok_m), finite);
        let clamped = clamp(u_in, c.u_min, c.u_max);
        let uc = _mm256_blendv_ps(c.u_min, clamped, live);
        let rising = _mm256_cmp_ps::<_CMP_GT_OQ>(uc, last_u);
        let moving = _mm256_andnot_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(uc, last_u), live);
        let moving_i = _mm256_castps_si256(moving);
        let odd0 = _mm256_cmpeq_epi32(_mm256_and_si256(len0, one_i), one_i);
        let turned = _mm256_xor_si256(_mm256_castps_si256(rising), odd0);
        let turned_ps = _mm256_castsi256_ps(turned);
        // the kernel's `finish`: the turning point pushed (stored at the end)
        let top_u = _mm256_load_ps(hd.top_u.as_ptr());
        let top_h = _mm256_load_ps(hd.top_h.as_ptr());
        let below_u = _mm256_load_ps(hd.below_u.as_ptr());
        let mut len = _mm256_sub_epi32(len0, turned);
        let mut t_u = _mm256_blendv_ps(top_u, last_u, turned_ps);
        let mut t_h = _mm256_blendv_ps(top_h, last_h, turned_ps);
        let mut b_u = _mm256_blendv_ps(below_u, top_u, turned_ps);
        let dir = _mm256_blendv_ps(_mm256_set1_ps(-1.0), _mm256_set1_ps(1.0), rising);
        let passes = |s: __m256| {
            let d = _mm256_mul_ps(_mm256_sub_ps(uc, s), dir);
            _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GE_OQ>(d, zero))
        };
        let wiped = _mm256_and_si256(
            _mm256_and_si256(_mm256_cmpgt_epi32(len, two_i), passes(b_u)),
            moving_i,
        );
        let b = base as *const f32;
        if _mm256_testz_si256(wiped, wiped) == 0 {
            let slot = |s: __m256i| _mm256_add_epi32(_mm256_add_epi32(s, s), off);
            len = _mm256_add_epi32(len, _mm256_add_epi32(wiped, wiped));
            let mut wipes = wiped;
            loop {
                let can = _mm256_and_si256(wipes, _mm256_cmpgt_epi32(len, two_i));
                if _mm256_testz_si256(can, can) != 0 {
                    break;
                }
                let at = slot(_mm256_sub_epi32(len, two_i));
                let s = _mm256_mask_i32gather_ps::<4>(zero, b, at, _mm256_castsi256_ps(can));
                wipes = _mm256_and_si256(can, passes(s));
                len = _mm256_add_epi32(len, _mm256_add_epi32(wipes, wipes));
            }
            let w = _mm256_castsi256_ps(wiped);
            let top = slot(_mm256_sub_epi32(len, one_i));
            t_u = _mm256_mask_i32gather_ps::<4>(t_u, b, top, w);
            t_h = _mm256_mask_i32gather_ps::<4>(t_h, b, _mm256_add_epi32(top, one_i), w);
            let below = _mm256_max_epi32(len, two_i);
            b_u = _mm256_mask_i32gather_ps::<4>(b_u, b, slot(_mm256_sub_epi32(below, two_i)), w);
        }
        // back at lower saturation
        let at_sat = _mm256_and_si256(
            _mm256_and_si256(_mm256_cmpeq_epi32(len, two_i), moving_i),
            _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(uc, b_u)),
        );
        if _mm256_testz_si256(at_sat, at_sat) == 0 {
            let s = _mm256_castsi256_ps(at_sat);
            len = _mm256_blendv_epi8(len, one_i, at_sat);
            t_u = _mm256_blendv_ps(t_u, b_u, s);
            t_h = _mm256_mask_i32gather_ps::<4>(t_h, b, _mm256_add_epi32(off, one_i), s);
        }
        let odd = _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(len, one_i), one_i));
        let alpha = _mm256_blendv_ps(t_u, uc, odd);
        let beta = _mm256_blendv_ps(uc, t_u, odd);
        let sign = _mm256_blendv_ps(_mm256_set1_ps(-2.0), _mm256_set1_ps(2.0), odd);
        let f = everett(c, alpha, beta);
        let h = _mm256_add_ps(t_h, _mm256_mul_ps(sign, f));
        let sum = _mm256_blendv_ps(last_h, h, moving);
        let y = _mm256_mul_ps(c.sign, _mm256_add_ps(sum, c.offset));
        // the turning point into the slot above the old top (every stack has a slot more
        // than its room, and no lane is at its room)
        for l in 0..WIDTH {
            let at = l * STACK + 2 * hd.len[l] as usize;
            // SAFETY: slot len0 <= ROOM of lane l's stack
            unsafe {
                *base.add(at) = hd.last_u[l];
                *base.add(at + 1) = hd.last_h[l];
            }
        }
        let keep = |old: __m256, new: __m256| _mm256_blendv_ps(old, new, moving);
        _mm256_store_si256(
            hd.len.as_mut_ptr().cast(),
            _mm256_blendv_epi8(len0, len, moving_i),
        );
        _mm256_store_ps(hd.last_u.as_mut_ptr(), keep(last_u, uc));
        _mm256_store_ps(hd.last_h.as_mut_ptr(), keep(last_h, h));
        _mm256_store_ps(hd.top_u.as_mut_ptr(), keep(top_u, t_u));
        _mm256_store_ps(hd.top_h.as_mut_ptr(), keep(top_h, t_h));
        _mm256_store_ps(hd.below_u.as_mut_ptr(), keep(below_u, b_u));
        let was_clamped = _mm256_and_ps(_mm256_cmp_ps::<_CMP_NEQ_UQ>(clamped, u_in), live);
        let counts = _mm256_load_si256(hd.clamped.as_ptr().cast());
        let counts = _mm256_sub_epi32(counts, _mm256_castps_si256(was_clamped));
        _mm256_store_si256(hd.clamped.as_mut_ptr().cast(), counts);
        _mm256_blendv_ps(_mm256_set1_ps(f32::NAN), y, live)
    }
}

#[cfg(test)]
#[path = "tests_f32x8.rs"]
mod tests;
