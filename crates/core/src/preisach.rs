//! The numerical Preisach model of thesis §4.4.1 (eq. 4.15-4.22), for many elements at once.
//!
//! The model is given by its Everett function `F(α, β)` on a uniform `K x K` grid over the
//! identified input range `[u_min, u_max]` (row = α, column = β, defined for β <= α, eq. 4.12:
//! `F(α, β) = (h_α - h_αβ) / 2`). Each element keeps a stack of alternating input extrema,
//! starting with the lower saturation `m_0 = u_min`, together with the output at each extremum.
//! With `x` the output at the last extremum (eq. 4.18-4.22):
//!
//! - rising input after the minimum `m`: `h = x + 2 F(u, m)`  (eq. 4.16),
//! - falling input after the maximum `M`: `h = x - 2 F(M, u)` (eq. 4.17).
//!
//! When the input passes the extremum before the last one, both are wiped out (the wiping-out
//! property) and `x` becomes the output stored with the extremum now on top (eq. 4.20/4.21).
//! A step therefore costs O(1) amortised. Between grid points `F` is interpolated bilinearly;
//! in the cells on the diagonal, whose upper half lies outside the Preisach triangle, it is
//! interpolated linearly on the lower triangle, so that `F(u, u) = 0` holds exactly. With an
//! Everett table that is non-decreasing in α and non-increasing in β the output is monotone
//! between extrema.
//!
//! Inputs outside `[u_min, u_max]` are clamped (and counted). An element whose input is NaN
//! or flagged invalid keeps its state untouched and outputs NaN.
//!
//! **Stack capacity.** Each element stores at most `capacity` extrema. When a new turning
//! point would overflow the stack, the most recent completed minor loop (the two extrema just
//! below the top) is forgotten first — the smallest loop in the memory, whose loss changes the
//! output least. With wiping-out, the stack only grows for ever-shrinking nested oscillations.

use std::sync::Arc;

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::{self as kernel, Head, Output};

use crate::error::{check_len, frames_of, CoreError};
pub use crate::everett::{everett_terms, Everett, EverettTerms};
use crate::par::{block_size, for_blocks, parallel, FrameBlock};
use crate::snapshot::{Reader, Writer};

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
mod element;
pub mod f32x8;

use element::Element;
pub(crate) use element::Heads;

/// Extrema an element holds in place. A deeper stack (ever-shrinking nested oscillations;
/// the deepest seen on real and simulated records is 13) moves to the heap, up to the bank's
/// capacity, and back in place once it is shallow again.
pub const INLINE_EXTREMA: usize = 12;

/// Element-samples per tile of frames in a batch of the [`Schedule::Blocks`] and
/// [`Schedule::Parallel`] schedules (64 frames of 4096 elements).
const TILE_SAMPLES: usize = 1 << 18;

/// Elements per AVX2 register of f64 (`avx2`'s lanes).
pub(crate) const LANES: usize = 4;

/// Elements per group of heads ([`Heads`]): the lanes of an AVX-512 register of f64 (two
/// AVX2 registers).
pub(crate) const GROUP: usize = 8;

/// How a batch walks through the frames and elements (all give identical outputs; the
/// benchmark shows what each step gains).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Schedule {
    /// Frame after frame over all elements, on the calling thread.
    FrameOrder,
    /// Block of elements after block, each through all frames, on the calling thread.
    Blocks,
    /// Blocks in parallel on the thread pool (the default for large batches).
    Parallel,
}

/// Stacks of N elements, and the output's offset and sign: the model gives
/// `sign (h + offset)` with `h` the Preisach sum (an identified model's output may start above
/// zero at lower saturation, or fall with the input).
#[derive(Debug, Clone)]
pub struct PreisachBank {
    everett: Arc<Everett>,
    capacity: usize,
    elements: Vec<Element>,
    /// The heads of elements `4 g .. 4 g + 4` in `heads[g]` (the last group's lanes beyond
    /// the bank stay at lower saturation).
    heads: Vec<Heads>,
    output: Output<f64>,
}

/// The elements `start .. start + len` of a bank, for a parallel batch (`start` a multiple
/// of [`GROUP`]: their heads are `heads`).
pub struct PreisachBlock<'a> {
    everett: EverettView<'a, f64>,
    /// The Everett table by cell (empty: gathered from the table).
    cells: &'a [f64],
    capacity: usize,
    elements: &'a mut [Element],
    heads: &'a mut [Heads],
    output: Output<f64>,
}

impl PreisachBlock<'_> {
    /// Element `i` of the block reads `u`: the model's output (skipped, NaN out, when
    /// invalid or not finite).
    #[inline(always)]
    pub fn step(&mut self, i: usize, u: f64, valid: bool) -> f64 {
        if valid && u.is_finite() {
            let heads = &mut self.heads[i / GROUP];
            let h = self.elements[i].step(heads, i % GROUP, &self.everett, self.capacity, u);
            self.output.of(h)
        } else {
            f64::NAN
        }
    }

    /// One frame of the block: inputs `u` and their validity `ok` (one per element) ->
    /// outputs `out` (NaN where skipped); on AVX2 four elements at a time, on AVX-512
    /// eight (`avx512`; [`crate::simd`]), with the scalar kernel's results bit for bit.
    ///
    /// # Panics
    /// When a slice does not hold one value per element.
    pub fn row(&mut self, u: &[f64], ok: &[bool], out: &mut [f64]) {
        let n = self.elements.len();
        assert!(
            u.len() == n && ok.len() == n && out.len() == n,
            "one per element"
        );
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx512() {
            // SAFETY: the processor has AVX2 and AVX-512 F/DQ/VL (detected by
            // `simd::avx512`); lengths checked
            unsafe {
                avx512::row(
                    &self.everett,
                    self.cells,
                    self.capacity,
                    self.output,
                    self.elements,
                    self.heads,
                    u,
                    ok,
                    out,
                )
            };
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() {
            // SAFETY: the processor has AVX2 (detected by `simd::avx2`); lengths checked
            unsafe {
                avx2::row(
                    &self.everett,
                    self.cells,
                    self.capacity,
                    self.output,
                    self.elements,
                    self.heads,
                    u,
                    ok,
                    out,
                )
            };
            return;
        }
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = self.step(i, u[i], ok[i]);
        }
    }

    /// Number of elements in the block.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }
}

impl FrameBlock for PreisachBlock<'_> {
    #[inline]
    fn step(&mut self, i: usize, _dt: f64, u: f64, valid: bool) -> f64 {
        PreisachBlock::step(self, i, u, valid)
    }

    fn row(&mut self, _dt: f64, u: &[f64], ok: &[bool], out: &mut [f64]) {
        PreisachBlock::row(self, u, ok, out);
    }
}

impl PreisachBank {
    /// N elements at lower saturation (input `u_min`, output 0), each with a stack of at most
    /// `capacity` extrema (>= 4); the first [`INLINE_EXTREMA`] are held in place.
    pub fn new(everett: Everett, n: usize, capacity: usize) -> Result<Self, CoreError> {
        if capacity < 4 {
            return Err(CoreError::Parameter {
                what: "capacity",
                why: format!("must be >= 4, got {capacity}"),
            });
        }
        let (element, _) = Element::new(everett.u_min);
        Ok(Self {
            elements: vec![element; n],
            heads: vec![Heads::new(everett.u_min); n.div_ceil(GROUP)],
            capacity,
            everett: Arc::new(everett),
            output: Output::identity(),
        })
    }

    /// The output `sign (h + offset)` instead of the Preisach sum `h` (sign +1 or -1).
    pub fn with_output(mut self, offset: f64, sign: f64) -> Result<Self, CoreError> {
        if !offset.is_finite() || (sign != 1.0 && sign != -1.0) {
            return Err(CoreError::Parameter {
                what: "output",
                why: format!("offset must be finite and sign +1 or -1, got {offset}, {sign}"),
            });
        }
        self.output = Output { offset, sign };
        Ok(self)
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// The Everett function.
    pub fn everett(&self) -> &Everett {
        &self.everett
    }

    /// Back to lower saturation; counters cleared.
    pub fn reset(&mut self) {
        let (fresh, _) = Element::new(self.everett.u_min);
        self.elements.iter_mut().for_each(|e| *e = fresh.clone());
        self.heads.fill(Heads::new(self.everett.u_min));
    }

    /// Turning points an element keeps at most.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The output's offset and sign.
    pub fn output(&self) -> (f64, f64) {
        (self.output.offset, self.output.sign)
    }

    /// Every element's state into a snapshot.
    pub(crate) fn save(&self, w: &mut Writer) {
        w.u32(self.len() as u32);
        w.u32(self.capacity as u32);
        for (i, e) in self.elements.iter().enumerate() {
            let heads = &self.heads[i / GROUP];
            e.save(&heads.head(i % GROUP), heads.count(i % GROUP), w);
        }
    }

    /// Every element's state from a snapshot of a bank of the same size and capacity.
    pub(crate) fn load(&mut self, r: &mut Reader<'_>) -> Result<(), CoreError> {
        r.expect("Preisach elements", self.len())?;
        r.expect("Preisach capacity", self.capacity)?;
        let u_min = self.everett.u_min;
        let mut heads = vec![Heads::new(u_min); self.heads.len()];
        let mut elements = Vec::with_capacity(self.len());
        for i in 0..self.len() {
            let (el, head, clamped) = Element::load(r, u_min, self.capacity)?;
            let g = &mut heads[i / GROUP];
            g.set(i % GROUP, &head, el.stack());
            g.clamped[i % GROUP] = clamped & !element::HEAP;
            g.mark(i % GROUP, el.spill.is_some());
            elements.push(el);
        }
        self.elements = elements;
        self.heads = heads;
        Ok(())
    }

    /// The head of element `i`.
    fn head(&self, i: usize) -> Head<f64> {
        self.heads[i / GROUP].head(i % GROUP)
    }

    /// Samples clamped into the input range, per element.
    pub fn clamped(&self) -> Vec<u64> {
        (0..self.len())
            .map(|i| self.heads[i / GROUP].count(i % GROUP))
            .collect()
    }

    /// Minor loops forgotten because a stack was full, per element.
    pub fn forgotten(&self) -> Vec<u64> {
        self.elements.iter().map(|e| e.forgotten).collect()
    }

    /// Current depth of every element's stack.
    pub fn depth(&self) -> Vec<usize> {
        (0..self.len()).map(|i| self.head(i).len as usize).collect()
    }

    /// Last output of every element.
    pub fn last_outputs(&self) -> Vec<f64> {
        (0..self.len())
            .map(|i| self.output.of(self.head(i).last_h))
            .collect()
    }

    /// Bytes of state: the elements themselves (stacks in place and heads) and the stacks
    /// moved to the heap.
    pub fn state_bytes(&self) -> usize {
        let heap: usize = self
            .elements
            .iter()
            .filter_map(|e| e.spill.as_ref())
            .map(|s| std::mem::size_of_val(&s[..]))
            .sum();
        self.elements.len() * std::mem::size_of::<Element>()
            + self.heads.len() * std::mem::size_of::<Heads>()
            + heap
    }

    /// Set element `i` to input `u` with the output `target` (§6.4.4: a model started from a
    /// known pressure). Reached by rising from saturation to a maximum `M >= u` and falling
    /// back to `u`: `M = u` gives the rising branch, `M = u_max` the major falling branch, and
    /// `M` is found by bisection for targets between the two (either orientation of the
    /// loop). Targets outside are clamped to the nearer branch; returns the output set.
    /// Targets and the result are the model's output (`sign (h + offset)`).
    pub fn set_state(&mut self, i: usize, u: f64, target: f64) -> f64 {
        let out = self.output;
        out.of(self.set_sum(i, u, out.sum_for(target)))
    }

    /// [`PreisachBank::set_state`] for the Preisach sum `h` itself (the kernel's
    /// `set_sum`).
    fn set_sum(&mut self, i: usize, u: f64, target: f64) -> f64 {
        let e = self.everett.view();
        let el = &mut self.elements[i];
        el.spill = None;
        let heads = &mut self.heads[i / GROUP];
        let mut head = heads.head(i % GROUP);
        let h = kernel::set_sum(&mut head, &mut el.inline, &e, u, target);
        heads.set(i % GROUP, &head, &el.inline);
        heads.mark(i % GROUP, false);
        h
    }

    /// The bank split into blocks of [`block_size`] elements (the last may be shorter; a
    /// block's first element is a multiple of [`GROUP`]).
    pub fn blocks(&mut self) -> impl Iterator<Item = PreisachBlock<'_>> {
        let (everett, capacity, output) = (self.everett.view(), self.capacity, self.output);
        let cells = self.everett.cells();
        let size = block_size(self.len());
        debug_assert!(size.is_multiple_of(GROUP));
        self.elements
            .chunks_mut(size)
            .zip(self.heads.chunks_mut(size / GROUP))
            .map(move |(elements, heads)| PreisachBlock {
                everett,
                cells,
                capacity,
                elements,
                heads,
                output,
            })
    }

    /// One frame: inputs (N,), validity (N,) -> outputs (N,) (NaN where skipped).
    pub fn step(
        &mut self,
        inputs: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        let n = self.len();
        check_len("inputs", inputs.len(), n)?;
        check_len("out", out.len(), n)?;
        self.run(inputs, valid, out)
    }

    /// A batch of frames (T x N, row-major), identical to T calls of `step`; large batches
    /// run in parallel over blocks of elements.
    pub fn run(
        &mut self,
        inputs: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        self.run_scheduled(inputs, valid, out, Schedule::Parallel)
    }

    /// [`PreisachBank::run`] with a chosen schedule (identical outputs).
    pub fn run_scheduled(
        &mut self,
        inputs: &[f64],
        valid: &[bool],
        out: &mut [f64],
        schedule: Schedule,
    ) -> Result<(), CoreError> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        let t = frames_of("inputs", inputs.len(), n)?;
        check_len("valid", valid.len(), inputs.len())?;
        check_len("out", out.len(), inputs.len())?;
        if schedule == Schedule::FrameOrder {
            // the whole bank as one block, frame after frame
            let mut all = PreisachBlock {
                everett: self.everett.view(),
                cells: self.everett.cells(),
                capacity: self.capacity,
                elements: &mut self.elements,
                heads: &mut self.heads,
                output: self.output,
            };
            for ((f, v), o) in inputs
                .chunks_exact(n)
                .zip(valid.chunks_exact(n))
                .zip(out.chunks_exact_mut(n))
            {
                all.row(f, v, o);
            }
            return Ok(());
        }
        let par = schedule == Schedule::Parallel && parallel(t, n);
        // tiles of frames: each block runs through a tile, then the next tile (a block that
        // ran through all frames at once read every row from another page of memory, and
        // ran out of the address translation cache on long batches)
        let tile = (TILE_SAMPLES / n).max(1);
        for a in (0..t).step_by(tile) {
            let b = (a + tile).min(t);
            let (inputs, valid) = (&inputs[a * n..b * n], &valid[a * n..b * n]);
            for_blocks(
                &mut out[a * n..b * n],
                n,
                self.blocks(),
                par,
                |mut block, o| {
                    let (start, width) = (o.start(), o.width());
                    for r in 0..b - a {
                        let row = r * n + start..r * n + start + width;
                        block.row(&inputs[row.clone()], &valid[row], o.row(r));
                    }
                },
            );
        }
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests;
