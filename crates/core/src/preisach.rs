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
use texsense_kernels::preisach::{self as kernel, Head, Output, Prepared, CLAMPED};

use crate::error::{check_len, frames_of, CoreError};
pub use crate::everett::{everett_terms, Everett, EverettTerms};
use crate::par::{block_size, for_blocks, parallel, FrameBlock};
use crate::snapshot::{Reader, Writer};

#[cfg(target_arch = "x86_64")]
mod avx2;

/// Extrema an element holds in place. A deeper stack (ever-shrinking nested oscillations;
/// the deepest seen on real and simulated records is 13) moves to the heap, up to the bank's
/// capacity, and back in place once it is shallow again.
pub const INLINE_EXTREMA: usize = 12;

/// The state of one element: the kernel's head (depth, last input and output), its
/// extremum stack (input and output at each extremum) and its counters.
#[derive(Debug, Clone)]
struct Element {
    head: Head<f64>,
    clamped: u64,
    forgotten: u64,
    inline: [[f64; 2]; INLINE_EXTREMA + 1],
    spill: Option<Box<[[f64; 2]]>>,
}

impl Element {
    fn new(u_min: f64) -> Self {
        let mut el = Self {
            head: Head::new(u_min),
            clamped: 0,
            forgotten: 0,
            inline: [[0.0; 2]; INLINE_EXTREMA + 1],
            spill: None,
        };
        kernel::start(&mut el.head, &mut el.inline, u_min);
        el
    }

    #[inline]
    fn stack(&self) -> &[[f64; 2]] {
        match &self.spill {
            Some(s) => s,
            None => &self.inline,
        }
    }

    /// Give the stack room for `room` extrema on the heap (plus the spare slot).
    #[cold]
    fn grow_to(&mut self, room: usize) {
        let len = self.head.len as usize;
        let mut s = vec![[0.0; 2]; room + 1].into_boxed_slice();
        s[..len].copy_from_slice(&self.stack()[..len]);
        self.spill = Some(s);
    }

    /// Back in place (the stack is shallow again).
    #[cold]
    fn unspill(&mut self) {
        if let Some(s) = self.spill.take() {
            let len = self.head.len as usize;
            self.inline[..len].copy_from_slice(&s[..len]);
        }
    }

    /// One valid input (eq. 4.16-4.22): the kernel's step (`prepare`, then `finish`) on
    /// this element's stack, which grows on the heap up to the capacity.
    #[inline]
    fn step(&mut self, e: &EverettView<'_, f64>, capacity: usize, u_in: f64) -> f64 {
        let (prepared, flags) = kernel::prepare(&self.head, e, u_in);
        self.clamped += u64::from(flags & CLAMPED != 0);
        let (u, rising, turned) = match prepared {
            Prepared::Same(h) => return h,
            Prepared::Moves { u, rising, turned } => (u, rising, turned),
        };
        if self.head.len as usize == (self.stack().len() - 1).min(capacity) {
            // rare; `turned` is tested inside, out of line, so that the compiler cannot
            // test it first (it is as unpredictable as a coin on a real input)
            self.make_room(capacity, turned);
        }
        let Element {
            head,
            inline,
            spill,
            ..
        } = self;
        let s: &mut [[f64; 2]] = match spill {
            Some(b) => b,
            None => inline,
        };
        let h = kernel::finish(head, s, e, u, rising, turned);
        if head.len as usize <= INLINE_EXTREMA / 2 && spill.is_some() {
            self.unspill();
        }
        h
    }

    /// The stack is full: if the input turned, grow it on the heap (doubling) while below
    /// the capacity, else forget the innermost loop (the kernel's `forget`).
    #[cold]
    #[inline(never)]
    fn make_room(&mut self, capacity: usize, turned: bool) {
        if !turned {
            return;
        }
        let room = self.stack().len() - 1;
        if room < capacity {
            self.grow_to((2 * room).min(capacity));
            return;
        }
        let Element {
            head,
            inline,
            spill,
            forgotten,
            ..
        } = self;
        let s: &mut [[f64; 2]] = match spill {
            Some(b) => b,
            None => inline,
        };
        kernel::forget(head, s);
        *forgotten += 1;
    }

    /// The element's state in a snapshot: head, counters, the extrema on the stack.
    fn save(&self, w: &mut Writer) {
        let len = self.head.len as usize;
        w.u32(self.head.len);
        w.f64(self.head.last_u);
        w.f64(self.head.last_h);
        w.u64(self.clamped);
        w.u64(self.forgotten);
        for &[u, h] in &self.stack()[..len] {
            w.f64(u);
            w.f64(h);
        }
    }

    /// An element from a snapshot ([`Element::save`]) of a bank with `capacity`.
    fn load(r: &mut Reader<'_>, u_min: f64, capacity: usize) -> Result<Self, CoreError> {
        let mut el = Self::new(u_min);
        let len = r.u32()? as usize;
        if len == 0 || len > capacity {
            return Err(r.error("a Preisach stack is deeper than the capacity"));
        }
        el.head = Head {
            len: len as u32,
            last_u: r.f64()?,
            last_h: r.f64()?,
        };
        el.clamped = r.u64()?;
        el.forgotten = r.u64()?;
        if len > INLINE_EXTREMA {
            el.grow_to(len.next_power_of_two().min(capacity));
        }
        let s: &mut [[f64; 2]] = match &mut el.spill {
            Some(b) => b,
            None => &mut el.inline,
        };
        for slot in &mut s[..len] {
            *slot = [r.f64()?, r.f64()?];
        }
        Ok(el)
    }
}

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
    output: Output<f64>,
}

/// The elements `start .. start + len` of a bank, for a parallel batch.
pub struct PreisachBlock<'a> {
    everett: EverettView<'a, f64>,
    capacity: usize,
    elements: &'a mut [Element],
    output: Output<f64>,
}

impl PreisachBlock<'_> {
    /// Element `i` of the block reads `u`: the model's output (skipped, NaN out, when
    /// invalid or not finite).
    #[inline(always)]
    pub fn step(&mut self, i: usize, u: f64, valid: bool) -> f64 {
        if valid && u.is_finite() {
            self.output
                .of(self.elements[i].step(&self.everett, self.capacity, u))
        } else {
            f64::NAN
        }
    }

    /// One frame of the block: inputs `u` and their validity `ok` (one per element) ->
    /// outputs `out` (NaN where skipped); on AVX2 four elements at a time
    /// ([`crate::simd`]), with the scalar kernel's results bit for bit.
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
        if crate::simd::avx2() {
            // SAFETY: the processor has AVX2 (detected by `simd::avx2`); lengths checked
            unsafe {
                avx2::row(
                    &self.everett,
                    self.capacity,
                    self.output,
                    self.elements,
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
        Ok(Self {
            elements: vec![Element::new(everett.u_min); n],
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
        let fresh = Element::new(self.everett.u_min);
        self.elements.iter_mut().for_each(|e| *e = fresh.clone());
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
        for e in &self.elements {
            e.save(w);
        }
    }

    /// Every element's state from a snapshot of a bank of the same size and capacity.
    pub(crate) fn load(&mut self, r: &mut Reader<'_>) -> Result<(), CoreError> {
        r.expect("Preisach elements", self.len())?;
        r.expect("Preisach capacity", self.capacity)?;
        let u_min = self.everett.u_min;
        let elements = (0..self.len())
            .map(|_| Element::load(r, u_min, self.capacity))
            .collect::<Result<Vec<_>, _>>()?;
        self.elements = elements;
        Ok(())
    }

    /// Samples clamped into the input range, per element.
    pub fn clamped(&self) -> Vec<u64> {
        self.elements.iter().map(|e| e.clamped).collect()
    }

    /// Minor loops forgotten because a stack was full, per element.
    pub fn forgotten(&self) -> Vec<u64> {
        self.elements.iter().map(|e| e.forgotten).collect()
    }

    /// Current depth of every element's stack.
    pub fn depth(&self) -> Vec<usize> {
        self.elements.iter().map(|e| e.head.len as usize).collect()
    }

    /// Last output of every element.
    pub fn last_outputs(&self) -> Vec<f64> {
        self.elements
            .iter()
            .map(|e| self.output.of(e.head.last_h))
            .collect()
    }

    /// Bytes of state: the elements themselves and the stacks moved to the heap.
    pub fn state_bytes(&self) -> usize {
        let heap: usize = self
            .elements
            .iter()
            .filter_map(|e| e.spill.as_ref())
            .map(|s| std::mem::size_of_val(&s[..]))
            .sum();
        self.elements.len() * std::mem::size_of::<Element>() + heap
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
        kernel::set_sum(&mut el.head, &mut el.inline, &e, u, target)
    }

    /// The bank split into blocks of [`block_size`] elements (the last may be shorter).
    pub fn blocks(&mut self) -> Vec<PreisachBlock<'_>> {
        let (everett, capacity, output) = (self.everett.view(), self.capacity, self.output);
        let size = block_size(self.len());
        self.elements
            .chunks_mut(size)
            .map(|elements| PreisachBlock {
                everett,
                capacity,
                elements,
                output,
            })
            .collect()
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
                capacity: self.capacity,
                elements: &mut self.elements,
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
        for_blocks(out, n, self.blocks(), par, |mut block, o| {
            let (start, width) = (o.start(), o.width());
            for r in 0..t {
                let row = r * n + start..r * n + start + width;
                block.row(&inputs[row.clone()], &valid[row], o.row(r));
            }
        });
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests;
