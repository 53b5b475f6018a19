//! Failure detection on raw capacitance (thesis §6.5.2.5), frame by frame for many elements.
//!
//! Per reading, in this order of precedence (the later wins):
//! - `stuck` (3): no change larger than `stuck_pf` for `stuck_frames` frames while the median
//!   change of the element's neighbours added up to more than `neighbour_change_pf` (readings
//!   at or below `stuck_floor_pf` are never stuck);
//! - `jump` (4): a change larger than the element's jump limit between two readings;
//! - `out of range` (2): flagged invalid by the converter, or beyond `high_share` times the
//!   largest capacitance the calibration expects;
//! - `short/break` (1): not a number, at or below `min_pf`, or below `low_share` of the
//!   element's unloaded capacitance.
//!
//! 0 means healthy. A batch runs in two passes over blocks of elements: the change of every
//! reading first (each element on its own), then the codes (which read the neighbours'
//! changes of the same frame). A single frame on AVX-512 (a live step) runs in one pass,
//! the codes that read the neighbours' changes after it. Same results as frame after frame
//! and on every path (tested).

use texsense_kernels::detect::{self as kernel, Element, Limits};

use crate::aligned::Lines;
use crate::error::{check_len, CoreError};
use crate::par::{block_size, for_blocks, parallel};
use crate::snapshot::{Reader, Writer};
use crate::topology::Neighbours;

/// Failure codes.
pub use texsense_kernels::detect::codes as code;

/// Thresholds of the detector (see the module documentation).
pub type DetectorParams = kernel::Params<f64>;

/// Where pass 2 finds a reading's validity.
#[derive(Clone, Copy)]
enum Validity<'a> {
    /// In an array.
    Given(&'a [bool]),
    /// Code 0 in the codes it writes (which it merges: codes other than 0 and the `unset`
    /// one stay).
    InCodes(u8),
}

/// Streaming failure detector of N elements.
#[derive(Debug, Clone)]
pub struct FailureDetector {
    params: DetectorParams,
    neighbours: Neighbours,
    /// The limits and states per element on cache lines ([`Lines`]): the rows read eight
    /// elements' at a time.
    jump: Lines<f64>,
    baseline: Option<Lines<f64>>,
    max: Option<Lines<f64>>,
    elements: Lines<Element<f64>>,
}

/// Scratch of one batch: the change of every reading since the element's last finite one
/// (NaN for an element's first reading, or a reading that is not a number).
#[derive(Debug, Clone, Default)]
pub struct Changes {
    delta: Vec<f64>,
}

impl FailureDetector {
    /// A detector with per-element jump limits (pF) and optional unloaded and largest
    /// expected capacitance per element.
    pub fn new(
        params: DetectorParams,
        neighbours: Neighbours,
        jump: Vec<f64>,
        baseline: Option<Vec<f64>>,
        max: Option<Vec<f64>>,
    ) -> Result<Self, CoreError> {
        let n = neighbours.len();
        check_len("jump", jump.len(), n)?;
        if let Some(b) = &baseline {
            check_len("baseline", b.len(), n)?;
        }
        if let Some(m) = &max {
            check_len("max", m.len(), n)?;
        }
        params.check()?;
        Ok(Self {
            params,
            neighbours,
            jump: Lines::from_slice(&jump),
            baseline: baseline.as_deref().map(Lines::from_slice),
            max: max.as_deref().map(Lines::from_slice),
            elements: Lines::new(Element::default(), n),
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// Forget the history.
    pub fn reset(&mut self) {
        self.elements.fill(Element::default());
    }

    /// The thresholds, the neighbours and the per-element limits (jump, unloaded, largest
    /// expected reading).
    #[allow(clippy::type_complexity)]
    pub fn parts(
        &self,
    ) -> (
        &DetectorParams,
        &Neighbours,
        &[f64],
        Option<&[f64]>,
        Option<&[f64]>,
    ) {
        (
            &self.params,
            &self.neighbours,
            &self.jump,
            self.baseline.as_deref(),
            self.max.as_deref(),
        )
    }

    /// Every element's state into a snapshot.
    pub(crate) fn save(&self, w: &mut Writer) {
        w.u32(self.len() as u32);
        for e in &self.elements {
            w.f64(e.last);
            w.u32(e.still);
            w.f64(e.moved);
        }
    }

    /// Every element's state from a snapshot of a detector of the same size.
    pub(crate) fn load(&mut self, r: &mut Reader<'_>) -> Result<(), CoreError> {
        r.expect("detector elements", self.len())?;
        for e in &mut self.elements {
            *e = Element {
                last: r.f64()?,
                still: r.u32()?,
                moved: r.f64()?,
            };
        }
        Ok(())
    }

    /// Bytes of state per element.
    pub fn state_bytes_per_element(&self) -> usize {
        std::mem::size_of::<Element<f64>>()
    }

    /// Codes (T x N) of a batch of readings (T x N) with the converter's validity.
    pub fn run(
        &mut self,
        readings: &[f64],
        valid: &[bool],
        codes: &mut [u8],
        scratch: &mut Changes,
    ) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        let t = readings.len() / n;
        check_len("readings", readings.len(), t * n)?;
        check_len("valid", valid.len(), t * n)?;
        check_len("codes", codes.len(), t * n)?;
        scratch.delta.resize(t * n, 0.0);
        #[cfg(target_arch = "x86_64")]
        if t == 1 && simd_wide() {
            self.frame_in_one_pass(readings, valid, &mut scratch.delta, codes);
            return Ok(());
        }
        let par = parallel(t, n);
        self.changes(readings, &mut scratch.delta, par);
        self.codes(readings, Validity::Given(valid), &scratch.delta, codes, par);
        Ok(())
    }

    /// [`FailureDetector::run`] in a chain: a reading is valid when its code is 0 (`codes`
    /// in), and the detector's code replaces the codes 0 and `unset` (a reading invalid on
    /// input that no detect stage has coded yet); other codes stay (`codes` out).
    pub fn run_on_codes(
        &mut self,
        readings: &[f64],
        codes: &mut [u8],
        unset: u8,
        scratch: &mut Changes,
    ) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        let t = readings.len() / n;
        check_len("readings", readings.len(), t * n)?;
        check_len("codes", codes.len(), t * n)?;
        scratch.delta.resize(t * n, 0.0);
        let par = parallel(t, n);
        self.changes(readings, &mut scratch.delta, par);
        self.codes(
            readings,
            Validity::InCodes(unset),
            &scratch.delta,
            codes,
            par,
        );
        Ok(())
    }

    /// Pass 1: the change of every reading since the element's last finite one (NaN for an
    /// element's first reading or one that is not a number).
    fn changes(&mut self, readings: &[f64], delta: &mut [f64], par: bool) {
        let n = self.len();
        let t = readings.len() / n;
        let chunks: Vec<_> = self.elements.chunks_mut(block_size(n)).collect();
        let (lanes, wide) = (simd_lanes(), simd_wide());
        for_blocks(delta, n, chunks, par, |block, o| {
            let start = o.start();
            for r in 0..t {
                let row = r * n + start;
                let out = o.row(r);
                let c = &readings[row..row + out.len()];
                #[cfg(target_arch = "x86_64")]
                if wide {
                    // SAFETY: `crate::simd::avx512` found AVX-512 F/DQ/VL and AVX2
                    unsafe { avx512::changes_row(block, c, out) };
                    continue;
                }
                #[cfg(target_arch = "x86_64")]
                if lanes {
                    // SAFETY: `simd_lanes` found AVX2
                    unsafe { avx2::changes_row(block, c, out) };
                    continue;
                }
                for (li, el) in block.iter_mut().enumerate() {
                    out[li] = kernel::change(el, c[li]);
                }
            }
        });
    }

    /// Pass 2: the codes, with the neighbours' median change of the same frame.
    fn codes(
        &mut self,
        readings: &[f64],
        valid: Validity<'_>,
        delta: &[f64],
        codes: &mut [u8],
        par: bool,
    ) {
        let n = self.len();
        let t = readings.len() / n;
        // the elements' states leave `self` for the pass, which reads the rest of it
        let mut elements = std::mem::take(&mut self.elements);
        let this = &*self;
        let chunks: Vec<_> = elements.chunks_mut(block_size(n)).collect();
        let lanes = simd_lanes();
        for_blocks(codes, n, chunks, par, |block, o| {
            let start = o.start();
            let mut scratch = (Vec::new(), [0.0; 8]);
            for r in 0..t {
                let row = r * n;
                let out = o.row(r);
                let w = out.len();
                // the whole groups of the row in lanes, except those with a reading that
                // holds still (`in_lanes`: bit g for the group at 4 g done)
                let in_lanes = match valid {
                    Validity::Given(v) if lanes => {
                        let whole = w / GROUP * GROUP;
                        let left =
                            this.codes_row(readings, delta, v, row + start, block, out, whole);
                        !left & low_bits(whole / GROUP)
                    }
                    _ => 0,
                };
                // the other groups one by one, in order (issue 34, eighteenth round: a
                // test of every group's bit was about 3 % of a pipeline batch at 4096
                // elements)
                let mut todo = !in_lanes & low_bits(w.div_ceil(GROUP));
                while todo != 0 {
                    let li = todo.trailing_zeros() as usize * GROUP;
                    todo &= todo - 1;
                    let end = (li + GROUP).min(w);
                    if lanes
                        && matches!(valid, Validity::InCodes(_))
                        && end - li == GROUP
                        && this.moving(
                            readings,
                            delta,
                            valid,
                            row,
                            start + li,
                            &mut block[li..end],
                            &mut out[li..end],
                        )
                    {
                        continue;
                    }
                    let ends = (start + li, row);
                    this.codes_scalar(
                        readings,
                        delta,
                        valid,
                        ends,
                        &mut block[li..end],
                        &mut out[li..end],
                        &mut scratch,
                    );
                }
            }
        });
        self.elements = elements;
    }
}

impl FailureDetector {
    /// The codes of a few elements from element `first` in frame `row` by the scalar kernel
    /// (`block` and `out`: their states and codes).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn codes_scalar(
        &self,
        readings: &[f64],
        delta: &[f64],
        valid: Validity<'_>,
        (first, row): (usize, usize),
        block: &mut [Element<f64>],
        out: &mut [u8],
        scratch: &mut (Vec<f64>, [f64; 8]),
    ) {
        for (lj, (el, code)) in block.iter_mut().zip(out.iter_mut()).enumerate() {
            let i = first + lj;
            let was = *code;
            let ok = match valid {
                Validity::Given(v) => v[row + i],
                Validity::InCodes(_) => was == 0,
            };
            let k = self.code_of(el, i, readings[row + i], delta, row, ok, scratch);
            if match valid {
                Validity::Given(_) => true,
                Validity::InCodes(unset) => was == 0 || was == unset,
            } {
                *code = k;
            }
        }
    }

    /// The code of element `i`'s reading `c` (`ok`: valid before) by the scalar kernel,
    /// with the neighbours' median change of frame `row` when the reading holds still.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn code_of(
        &self,
        el: &mut Element<f64>,
        i: usize,
        c: f64,
        delta: &[f64],
        row: usize,
        ok: bool,
        (wide, few): &mut (Vec<f64>, [f64; 8]),
    ) -> u8 {
        let p = &self.params;
        let nbs = self.neighbours.of(i);
        let d = delta[row + i];
        // the neighbours' movement counts only for a reading that holds still (`code` reads
        // it then alone)
        let nb_move = if !kernel::holds_still(p, c, d) {
            0.0
        } else if nbs.len() <= few.len() {
            kernel::neighbour_move(nbs, delta, row, few)
        } else {
            wide.resize(nbs.len(), 0.0);
            kernel::neighbour_move(nbs, delta, row, wide)
        };
        let lim = Limits {
            jump: self.jump[i],
            baseline: self.baseline.as_ref().map(|b| b[i]),
            max: self.max.as_ref().map(|m| m[i]),
        };
        kernel::code(p, el, lim, c, ok, d, nb_move, !nbs.is_empty())
    }

    /// The codes of the first `whole` elements (whole groups) of a block's row starting
    /// at reading `at` (element `at % n`) in SIMD lanes, [`KERNEL_ROW`] elements per call of
    /// the lane kernel; returns the groups left to the scalar kernel (bit g: the group at
    /// 4 g); all of them without AVX2.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn codes_row(
        &self,
        readings: &[f64],
        delta: &[f64],
        valid: &[bool],
        at: usize,
        els: &mut [Element<f64>],
        out: &mut [u8],
        whole: usize,
    ) -> u128 {
        let mut left = 0;
        for a in (0..whole).step_by(KERNEL_ROW) {
            let b = (a + KERNEL_ROW).min(whole);
            let part = self.codes_part(
                readings,
                delta,
                valid,
                at + a,
                &mut els[a..b],
                &mut out[a..b],
            );
            left |= u128::from(part) << (a / GROUP);
        }
        left
    }

    /// [`FailureDetector::codes_row`] of at most [`KERNEL_ROW`] elements (`els.len()`, whole
    /// groups) by one call of the lane kernel (`detect::avx2::codes_row`).
    #[inline]
    fn codes_part(
        &self,
        readings: &[f64],
        delta: &[f64],
        valid: &[bool],
        at: usize,
        els: &mut [Element<f64>],
        out: &mut [u8],
    ) -> u32 {
        let whole = els.len();
        #[cfg(target_arch = "x86_64")]
        {
            let n = self.jump.len(); // the states are out of `self` during the pass
            let lim = self.row_limits(at % n, whole);
            let at = at..at + whole;
            if simd_wide() {
                // SAFETY: `crate::simd::avx512` found AVX-512 F/DQ/VL and AVX2
                return unsafe {
                    avx512::codes_row(
                        &self.params,
                        &lim,
                        &readings[at.clone()],
                        &delta[at.clone()],
                        &valid[at],
                        els,
                        out,
                    )
                };
            }
            // SAFETY: `simd_lanes` found AVX2 before the caller came here
            unsafe {
                avx2::codes_row(
                    &self.params,
                    &lim,
                    &readings[at.clone()],
                    &delta[at.clone()],
                    &valid[at],
                    els,
                    out,
                )
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (readings, delta, valid, at, els, out, whole);
            u32::MAX
        }
    }

    /// The limits of elements `i .. i + w`.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    fn row_limits(&self, i: usize, w: usize) -> avx2::RowLimits<'_> {
        avx2::RowLimits {
            jump: &self.jump[i..i + w],
            baseline: self.baseline.as_deref().map(|b| &b[i..i + w]),
            max: self.max.as_deref().map(|m| &m[i..i + w]),
        }
    }

    /// The codes of the four elements `i .. i + 4` of frame `row` in SIMD lanes when none
    /// of their readings holds still (`detect::avx2`); false (nothing written, no state
    /// touched) when one does, or without AVX2.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn moving(
        &self,
        readings: &[f64],
        delta: &[f64],
        valid: Validity<'_>,
        row: usize,
        i: usize,
        els: &mut [Element<f64>],
        out: &mut [u8],
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            let at = row + i..row + i + GROUP;
            let ok: [bool; GROUP] = std::array::from_fn(|l| match valid {
                Validity::Given(v) => v[row + i + l],
                Validity::InCodes(_) => out[l] == 0,
            });
            let lim = avx2::Limits4 {
                jump: &self.jump[i..i + GROUP],
                baseline: self.baseline.as_deref().map(|b| &b[i..i + GROUP]),
                max: self.max.as_deref().map(|m| &m[i..i + GROUP]),
            };
            // SAFETY: `simd_lanes` found AVX2 before the caller came here
            let Some(k) = (unsafe {
                avx2::moving(&self.params, &lim, &readings[at.clone()], &delta[at], ok)
            }) else {
                return false;
            };
            for (l, (el, slot)) in els.iter_mut().zip(out.iter_mut()).enumerate() {
                // kernel::code for a reading that does not hold still
                el.still = 0;
                el.moved = 0.0;
                let write = match valid {
                    Validity::Given(_) => true,
                    Validity::InCodes(unset) => *slot == 0 || *slot == unset,
                };
                if write {
                    *slot = k[l];
                }
            }
            true
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (readings, delta, valid, row, i, els, out);
            false
        }
    }
}

/// Elements per group of the SIMD path.
const GROUP: usize = 4;

/// Elements per call of the lane kernels that report the groups they leave to the scalar
/// kernel as the bits of a `u32` (32 groups of [`GROUP`]); a block's row of up to
/// [`crate::par::MAX_BLOCK`] elements takes several calls.
const KERNEL_ROW: usize = 32 * GROUP;

/// The lowest `k` bits set (`k <= 128`).
#[inline]
fn low_bits(k: usize) -> u128 {
    u128::MAX.checked_shr((128 - k) as u32).unwrap_or(0)
}

/// Whether the codes run four elements at a time in AVX2 lanes ([`crate::simd`]).
fn simd_lanes() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        crate::simd::avx2()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the passes run eight elements at a time in AVX-512 lanes ([`crate::simd`]).
fn simd_wide() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        crate::simd::avx512()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
#[cfg(target_arch = "x86_64")]
mod one_pass;

#[cfg(test)]
mod tests;
