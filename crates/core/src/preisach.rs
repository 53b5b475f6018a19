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

use crate::error::{check_len, CoreError};
use crate::par::{block_size, for_blocks, parallel, FrameBlock};

/// An Everett function on a uniform grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Everett {
    k: usize,
    u_min: f64,
    u_max: f64,
    inv_step: f64,
    table: Vec<f64>,
}

impl Everett {
    /// Build from a row-major `k x k` table (row α, column β; entries above the diagonal are
    /// ignored and the diagonal must be 0) over `[u_min, u_max]`.
    pub fn new(k: usize, u_min: f64, u_max: f64, table: Vec<f64>) -> Result<Self, CoreError> {
        if !(2..=1 << 20).contains(&k) {
            return Err(CoreError::Parameter {
                what: "everett",
                why: format!("the grid needs 2 ..= 2^20 points, got {k}"),
            });
        }
        check_len("everett table", table.len(), k * k)?;
        if !(u_min.is_finite() && u_max.is_finite() && u_max > u_min) {
            return Err(CoreError::Parameter {
                what: "input range",
                why: format!("need finite u_min < u_max, got {u_min} .. {u_max}"),
            });
        }
        let mut table = table;
        for i in 0..k {
            for j in 0..k {
                let v = table[i * k + j];
                if j > i || i == j {
                    table[i * k + j] = 0.0;
                } else if !v.is_finite() {
                    return Err(CoreError::Parameter {
                        what: "everett table",
                        why: format!("entry ({i}, {j}) is not finite"),
                    });
                }
            }
        }
        Ok(Self {
            k,
            u_min,
            u_max,
            inv_step: (k - 1) as f64 / (u_max - u_min),
            table,
        })
    }

    /// Grid size K.
    pub fn size(&self) -> usize {
        self.k
    }

    /// Lower end of the input range (the saturation input `m_0`).
    pub fn u_min(&self) -> f64 {
        self.u_min
    }

    /// Upper end of the input range.
    pub fn u_max(&self) -> f64 {
        self.u_max
    }

    /// `F(α, β)` for `u_min <= β <= α <= u_max` (interpolated).
    ///
    /// Branch-free: both the bilinear and the diagonal-cell formula are computed and the
    /// right one selected, since on a real input which cell is hit is unpredictable (a
    /// mispredicted branch costs more than the few extra multiplications).
    #[inline]
    pub fn value(&self, alpha: f64, beta: f64) -> f64 {
        if alpha.is_nan() || beta.is_nan() {
            return f64::NAN;
        }
        self.value_of_numbers(alpha, beta)
    }

    /// [`Everett::value`] for inputs that are numbers (not NaN; infinities are clamped).
    #[inline(always)]
    fn value_of_numbers(&self, alpha: f64, beta: f64) -> f64 {
        let last = (self.k - 1) as f64;
        let a = ((alpha - self.u_min) * self.inv_step).clamp(0.0, last);
        let b = ((beta - self.u_min) * self.inv_step).clamp(0.0, last);
        // SAFETY: a and b are in [0, k - 1] (clamped, not NaN), so the truncation is a floor
        // that fits in u32 (k is at most the table's side)
        let (ia, ib) = unsafe { (a.to_int_unchecked::<u32>(), b.to_int_unchecked::<u32>()) };
        let top = (self.k - 2) as u32;
        let (i0, j0) = (ia.min(top) as usize, ib.min(top) as usize);
        let wa = a - i0 as f64;
        let wb = b - j0 as f64;
        let q = i0 * self.k + j0;
        // SAFETY: i0, j0 <= k - 2, so q + 1 and q + k + 1 are below k * k = table.len()
        let (f00, f01, f10, f11) = unsafe {
            let t = self.table.as_ptr().add(q);
            (*t, *t.add(1), *t.add(self.k), *t.add(self.k + 1))
        };
        let bilinear =
            (1.0 - wa) * ((1.0 - wb) * f00 + wb * f01) + wa * ((1.0 - wb) * f10 + wb * f11);
        // diagonal cell: linear on the lower triangle, F = 0 on the diagonal
        let diagonal = (wa - wb) * f10;
        let v = if i0 == j0 { diagonal } else { bilinear };
        if b >= a {
            0.0
        } else {
            v
        }
    }
}

/// Extrema an element holds in place. A deeper stack (ever-shrinking nested oscillations;
/// the deepest seen on real and simulated records is 13) moves to the heap, up to the bank's
/// capacity, and back in place once it is shallow again.
pub const INLINE_EXTREMA: usize = 12;

/// The state of one element: its extremum stack (input and output at each extremum) and the
/// last input and output.
#[derive(Debug, Clone)]
struct Element {
    len: u32,
    last_u: f64,
    last_h: f64,
    clamped: u64,
    forgotten: u64,
    inline: [[f64; 2]; INLINE_EXTREMA + 1],
    spill: Option<Box<[[f64; 2]]>>,
}

impl Element {
    fn new(u_min: f64) -> Self {
        let mut inline = [[0.0; 2]; INLINE_EXTREMA + 1];
        inline[0] = [u_min, 0.0];
        Self {
            len: 1,
            last_u: u_min,
            last_h: 0.0,
            clamped: 0,
            forgotten: 0,
            inline,
            spill: None,
        }
    }

    #[inline]
    fn stack(&self) -> &[[f64; 2]] {
        match &self.spill {
            Some(s) => s,
            None => &self.inline,
        }
    }

    #[inline]
    fn stack_mut(&mut self) -> &mut [[f64; 2]] {
        match &mut self.spill {
            Some(s) => s,
            None => &mut self.inline,
        }
    }

    /// Give the stack room for `room` extrema on the heap (plus the spare slot).
    #[cold]
    fn grow_to(&mut self, room: usize) {
        let len = self.len as usize;
        let mut s = vec![[0.0; 2]; room + 1].into_boxed_slice();
        s[..len].copy_from_slice(&self.stack()[..len]);
        self.spill = Some(s);
    }

    /// Back in place (the stack is shallow again).
    #[cold]
    fn unspill(&mut self) {
        if let Some(s) = self.spill.take() {
            let len = self.len as usize;
            self.inline[..len].copy_from_slice(&s[..len]);
        }
    }

    /// One valid input (eq. 4.16-4.22). Written so that the outcomes that are unpredictable
    /// on a real input (rising or falling, turning or not) select values instead of branching.
    #[inline]
    fn step(&mut self, e: &Everett, capacity: usize, u_in: f64) -> f64 {
        let u = u_in.clamp(e.u_min, e.u_max);
        self.clamped += u64::from(u != u_in);
        let prev = self.last_u;
        if u == prev {
            return self.last_h;
        }
        let mut len = self.len as usize;
        let rising = u > prev;
        // the top is a minimum when len is odd (stack = m0, M1, m1, ...); a turn at `prev`
        // pushes it as a new extremum
        let turned = rising != (len % 2 == 1);
        if len == self.room(capacity) {
            // rare; `turned` is tested inside, out of line, so that the compiler cannot
            // test it first (it is as unpredictable as a coin on a real input)
            self.make_room(capacity, turned, &mut len);
        }
        let Element {
            inline,
            spill,
            last_h,
            last_u,
            len: stored_len,
            ..
        } = self;
        let s: &mut [[f64; 2]] = match spill {
            Some(b) => b,
            None => inline,
        };
        s[len] = [prev, *last_h]; // written always, kept only on a turn
        len += usize::from(turned);
        // wiping-out: the new input passes the extremum before the top
        let dir = if rising { 1.0 } else { -1.0 };
        // the first level without a branch (whether a step wipes out one loop is as
        // unpredictable as a coin on a real input); deeper levels are rare
        let wipes = (len >= 3) & ((u - s[len.max(2) - 2][0]) * dir >= 0.0);
        len = std::hint::select_unpredictable(wipes, len.wrapping_sub(2), len);
        while wipes && len >= 3 && (u - s[len - 2][0]) * dir >= 0.0 {
            len -= 2;
        }
        if len == 2 && u <= s[0][0] {
            len = 1; // back at lower saturation (only a falling input gets here)
        }
        let [top, x] = s[len - 1];
        // rising after a minimum: x + 2 F(u, m); falling after a maximum: x - 2 F(M, u)
        let odd = len % 2 == 1;
        let (alpha, beta) = if odd { (u, top) } else { (top, u) };
        let sign = if odd { 2.0 } else { -2.0 };
        let h = x + sign * e.value_of_numbers(alpha, beta);
        *stored_len = len as u32;
        *last_u = u;
        *last_h = h;
        if len <= INLINE_EXTREMA / 2 && spill.is_some() {
            self.unspill();
        }
        h
    }

    /// Extrema the stack may hold; one more slot always exists (the unconditional write of
    /// a possible turning point).
    #[inline]
    fn room(&self, capacity: usize) -> usize {
        (self.stack().len() - 1).min(capacity)
    }

    /// The stack is full: if the input turned, grow it on the heap (doubling) while below
    /// `capacity`, else forget the most recent completed minor loop (the two entries below
    /// the top).
    #[cold]
    #[inline(never)]
    fn make_room(&mut self, capacity: usize, turned: bool, len: &mut usize) {
        if !turned {
            return;
        }
        let room = self.stack().len() - 1;
        if room < capacity {
            self.grow_to((2 * room).min(capacity));
        } else {
            let s = self.stack_mut();
            s[*len - 3] = s[*len - 1];
            *len -= 2;
            self.forgotten += 1;
        }
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
    output: Output,
}

/// `sign (h + offset)`: the model's output from the Preisach sum `h`.
#[derive(Debug, Clone, Copy)]
struct Output {
    offset: f64,
    sign: f64,
}

impl Output {
    #[inline]
    fn of(self, h: f64) -> f64 {
        self.sign * (h + self.offset)
    }

    /// The Preisach sum that gives the output `y` (the sign is +1 or -1).
    #[inline]
    fn sum_for(self, y: f64) -> f64 {
        self.sign * y - self.offset
    }
}

/// The elements `start .. start + len` of a bank, for a parallel batch.
pub struct PreisachBlock<'a> {
    everett: &'a Everett,
    capacity: usize,
    elements: &'a mut [Element],
    output: Output,
}

impl PreisachBlock<'_> {
    /// Element `i` of the block reads `u`: the model's output (skipped, NaN out, when
    /// invalid or not finite).
    #[inline]
    pub fn step(&mut self, i: usize, u: f64, valid: bool) -> f64 {
        if valid && u.is_finite() {
            self.output
                .of(self.elements[i].step(self.everett, self.capacity, u))
        } else {
            f64::NAN
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
            output: Output {
                offset: 0.0,
                sign: 1.0,
            },
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
        self.elements.iter().map(|e| e.len as usize).collect()
    }

    /// Last output of every element.
    pub fn last_outputs(&self) -> Vec<f64> {
        self.elements
            .iter()
            .map(|e| self.output.of(e.last_h))
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

    /// [`PreisachBank::set_state`] for the Preisach sum `h` itself.
    fn set_sum(&mut self, i: usize, u: f64, target: f64) -> f64 {
        let e = &*self.everett;
        let u = u.clamp(e.u_min, e.u_max);
        // output at u after rising to M and falling back: 2 F(M, m0) - 2 F(M, u)
        let after = |m: f64| 2.0 * e.value(m, e.u_min) - 2.0 * e.value(m, u);
        let rising = after(u);
        let major = after(e.u_max);
        let (lo_val, hi_val) = (rising.min(major), rising.max(major));
        let want = if target.is_nan() {
            rising
        } else {
            target.clamp(lo_val, hi_val)
        };
        let m = if (want - rising).abs() <= f64::EPSILON * rising.abs().max(1.0) {
            u
        } else if (want - major).abs() <= f64::EPSILON * major.abs().max(1.0) {
            e.u_max
        } else {
            // after(M) runs monotonically from `rising` (M = u) to `major` (M = u_max)
            let up = major > rising;
            let (mut lo, mut hi) = (u, e.u_max);
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if (after(mid) < want) == up {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        let mut el = Element::new(e.u_min);
        el.clamped = self.elements[i].clamped;
        el.forgotten = self.elements[i].forgotten;
        el.last_u = u;
        let h = if m <= u {
            rising
        } else {
            el.inline[1] = [m, 2.0 * e.value(m, e.u_min)];
            el.len = 2;
            after(m)
        };
        el.last_h = h;
        self.elements[i] = el;
        h
    }

    /// The bank split into blocks of [`block_size`] elements (the last may be shorter).
    pub fn blocks(&mut self) -> Vec<PreisachBlock<'_>> {
        let (everett, capacity, output) = (&*self.everett, self.capacity, self.output);
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
            let (everett, capacity, output) = (&*self.everett, self.capacity, self.output);
            for ((f, v), o) in inputs
                .chunks_exact(n)
                .zip(valid.chunks_exact(n))
                .zip(out.chunks_exact_mut(n))
            {
                for (i, el) in self.elements.iter_mut().enumerate() {
                    o[i] = if v[i] && f[i].is_finite() {
                        output.of(el.step(everett, capacity, f[i]))
                    } else {
                        f64::NAN
                    };
                }
            }
            return Ok(());
        }
        let par = schedule == Schedule::Parallel && parallel(t, n);
        for_blocks(out, n, self.blocks(), par, |mut block, o| {
            let start = o.start();
            for r in 0..t {
                let row = r * n + start;
                for li in 0..o.width() {
                    o.set(r, li, block.step(li, inputs[row + li], valid[row + li]));
                }
            }
        });
        Ok(())
    }
}

/// Frames in a row-major batch of `len` values of `n` elements each.
pub(crate) fn frames_of(what: &'static str, len: usize, n: usize) -> Result<usize, CoreError> {
    if n == 0 || !len.is_multiple_of(n) {
        return Err(CoreError::Shape {
            what,
            expected: format!("a multiple of {n} elements"),
            got: format!("length {len}"),
        });
    }
    Ok(len / n)
}

/// The Everett terms behind the model's output along one input history, for identification.
///
/// The output of the numerical model is linear in the Everett function: with the extremum
/// stack `m_0, M_1, m_1, ...` (which depends on the input alone, eq. 4.18-4.22),
/// `h(t) = h(u_min) + 2 Σ_k [F(M_k, m_{k-1}) - F(M_k, m_k)] ± 2 F(branch now traced)`
/// (eq. 4.15/4.16). Sample `t` owns the terms `indptr[t] .. indptr[t + 1]`, each a point
/// `(alpha, beta)` with `alpha > beta` and a coefficient of ±2; a table on any grid turns
/// them into a design matrix by its interpolation weights. The stack is the evaluator's
/// (same turning and wiping-out rules, no capacity limit); inputs are clamped into
/// `[u_min, u_max]` and must not be NaN.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EverettTerms {
    /// Row pointer: sample `t` owns terms `indptr[t] .. indptr[t + 1]`.
    pub indptr: Vec<usize>,
    /// α of each term.
    pub alpha: Vec<f64>,
    /// β of each term.
    pub beta: Vec<f64>,
    /// Coefficient of each term (±2).
    pub coef: Vec<f64>,
}

impl EverettTerms {
    fn push(&mut self, alpha: f64, beta: f64, coef: f64) {
        if alpha > beta {
            self.alpha.push(alpha);
            self.beta.push(beta);
            self.coef.push(coef);
        }
    }
}

/// The Everett terms of every sample of `inputs` (see [`EverettTerms`]).
pub fn everett_terms(inputs: &[f64], u_min: f64, u_max: f64) -> Result<EverettTerms, CoreError> {
    if !(u_min.is_finite() && u_max.is_finite() && u_max > u_min) {
        return Err(CoreError::Parameter {
            what: "input range",
            why: format!("need finite u_min < u_max, got {u_min} .. {u_max}"),
        });
    }
    if let Some(t) = inputs.iter().position(|u| u.is_nan()) {
        return Err(CoreError::Parameter {
            what: "inputs",
            why: format!("sample {t} is NaN"),
        });
    }
    let mut out = EverettTerms {
        indptr: Vec::with_capacity(inputs.len() + 1),
        ..Default::default()
    };
    out.indptr.push(0);
    let mut stack = vec![u_min];
    let mut prev = u_min;
    for &u_in in inputs {
        let u = u_in.clamp(u_min, u_max);
        if u != prev {
            let rising = u > prev;
            if rising != (stack.len() % 2 == 1) {
                stack.push(prev);
            }
            if rising {
                while stack.len() >= 3 && u >= stack[stack.len() - 2] {
                    stack.truncate(stack.len() - 2);
                }
            } else {
                while stack.len() >= 3 && u <= stack[stack.len() - 2] {
                    stack.truncate(stack.len() - 2);
                }
                if stack.len() == 2 && u <= stack[0] {
                    stack.truncate(1);
                }
            }
            prev = u;
        }
        let len = stack.len();
        for q in (1..len).step_by(2) {
            out.push(stack[q], stack[q - 1], 2.0);
            if q + 1 < len {
                out.push(stack[q], stack[q + 1], -2.0);
            }
        }
        if len % 2 == 1 {
            out.push(u, stack[len - 1], 2.0);
        } else {
            out.push(stack[len - 1], u, -2.0);
        }
        out.indptr.push(out.alpha.len());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The Everett function of a uniform (non-negative) Preisach density: F = (α - β)² / 2.
    fn uniform(k: usize) -> Everett {
        let mut t = vec![0.0; k * k];
        let h = 1.0 / (k - 1) as f64;
        for i in 0..k {
            for j in 0..i {
                let d = (i - j) as f64 * h;
                t[i * k + j] = 0.5 * d * d;
            }
        }
        Everett::new(k, 0.0, 1.0, t).unwrap()
    }

    fn run1(bank: &mut PreisachBank, path: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; path.len()];
        bank.run(path, &vec![true; path.len()], &mut out).unwrap();
        out
    }

    #[test]
    fn major_loop_of_a_uniform_density() {
        let mut bank = PreisachBank::new(uniform(101), 1, 64).unwrap();
        let out = run1(&mut bank, &[0.5, 1.0, 0.5, 0.0]);
        // rising from saturation: 2 F(u, 0) = u²
        assert!((out[0] - 0.25).abs() < 1e-12);
        assert!((out[1] - 1.0).abs() < 1e-12);
        // falling from 1: 1 - 2 F(1, u) = 1 - (1 - u)²
        assert!((out[2] - 0.75).abs() < 1e-12);
        assert!(out[3].abs() < 1e-12);
        assert_eq!(bank.depth()[0], 1);
    }

    #[test]
    fn clamping_nan_and_invalid() {
        let mut bank = PreisachBank::new(uniform(11), 2, 8).unwrap();
        let mut out = [0.0; 2];
        bank.step(&[2.0, 0.5], &[true, true], &mut out).unwrap();
        assert_eq!(bank.clamped(), &[1, 0]);
        assert!((out[0] - 1.0).abs() < 1e-12);
        bank.step(&[f64::NAN, 0.2], &[true, false], &mut out)
            .unwrap();
        assert!(out[0].is_nan() && out[1].is_nan());
        // state untouched: continuing gives the same as if the NaN frame had not happened
        bank.step(&[0.5, 0.5], &[true, true], &mut out).unwrap();
        assert!((out[1] - 0.25).abs() < 1e-12);
    }

    #[test]
    fn set_state_hits_the_target_between_the_branches() {
        let mut bank = PreisachBank::new(uniform(201), 1, 16).unwrap();
        // at u = 0.5 the rising branch gives 0.25 and the falling major branch 0.75
        for target in [0.3, 0.5, 0.74] {
            let got = bank.set_state(0, 0.5, target);
            assert!((got - target).abs() < 1e-9, "{got} vs {target}");
        }
        assert!((bank.set_state(0, 0.5, 0.1) - 0.25).abs() < 1e-12); // below: clamped
        assert!((bank.set_state(0, 0.5, 0.9) - 0.75).abs() < 1e-9); // above: clamped
    }

    #[test]
    fn capacity_policy_forgets_the_innermost_loop() {
        let mut bank = PreisachBank::new(uniform(101), 1, 4).unwrap();
        // ever-shrinking oscillation: 1, 0, 0.9, 0.1, 0.8, 0.2, ...
        let path: Vec<f64> = (0..12)
            .map(|k| {
                let a = 0.05 * (k / 2) as f64;
                if k % 2 == 0 {
                    1.0 - a
                } else {
                    a
                }
            })
            .collect();
        let out = run1(&mut bank, &path);
        assert!(bank.forgotten()[0] > 0);
        assert!(bank.depth()[0] <= 4);
        assert!(out.iter().all(|v| v.is_finite()));
    }

    fn arb_path() -> impl Strategy<Value = Vec<f64>> {
        proptest::collection::vec(0.0f64..1.0, 1..60)
    }

    proptest! {
        #[test]
        fn streaming_equals_batch(path in arb_path()) {
            let mut a = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let batch = run1(&mut a, &path);
            let mut b = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let mut o = [0.0];
            for (k, &u) in path.iter().enumerate() {
                b.step(&[u], &[true], &mut o).unwrap();
                prop_assert_eq!(o[0].to_bits(), batch[k].to_bits());
            }
        }

        #[test]
        fn return_point_memory(path in arb_path(), lo in 0.0f64..0.5, span in 0.05f64..0.5) {
            // after any history, go to an extremum M, make a minor excursion inside
            // [m, M] and come back to M: the output at M is the same as before
            let mut bank = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let mut hist = path.clone();
            let m = lo;
            let big = (lo + span).min(1.0);
            hist.push(0.0); // the extremum before `big`
            hist.push(big);
            let before = run1(&mut bank, &hist);
            let at_m = *before.last().unwrap();
            let after = run1(&mut bank, &[m, (m + big) / 2.0, m + 0.01 * span, big]);
            prop_assert!((after[3] - at_m).abs() < 1e-9);
        }

        #[test]
        fn wiping_out(path in arb_path()) {
            // any history inside [0, 1] is erased by going to 1 and back to a value:
            // the output equals that of a fresh model doing the same
            let mut bank = PreisachBank::new(uniform(51), 1, 256).unwrap();
            run1(&mut bank, &path);
            let a = run1(&mut bank, &[1.0, 0.3]);
            let mut fresh = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let b = run1(&mut fresh, &[1.0, 0.3]);
            prop_assert!((a[1] - b[1]).abs() < 1e-12);
            prop_assert!(bank.depth()[0] == fresh.depth()[0]);
        }

        #[test]
        fn congruent_minor_loops(
            p1 in arb_path(), p2 in arb_path(), lo in 0.2f64..0.5, span in 0.05f64..0.3,
        ) {
            // minor loops between the same extrema, after different histories that stay
            // above lo + span, differ only by a constant
            let hi = lo + span;
            let lift = |p: &Vec<f64>| -> Vec<f64> { p.iter().map(|v| hi + v * (1.0 - hi)).collect() };
            let loop_path: Vec<f64> = (0..=20).map(|k| lo + span * (k as f64 / 20.0))
                .chain((0..=20).map(|k| hi - span * (k as f64 / 20.0))).collect();
            let mut a = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let mut b = PreisachBank::new(uniform(51), 1, 256).unwrap();
            let mut ha = lift(&p1); ha.push(lo);
            let mut hb = lift(&p2); hb.push(lo);
            run1(&mut a, &ha);
            run1(&mut b, &hb);
            let la = run1(&mut a, &loop_path);
            let lb = run1(&mut b, &loop_path);
            let shift = la[0] - lb[0];
            for (x, y) in la.iter().zip(lb.iter()) {
                prop_assert!((x - y - shift).abs() < 1e-9);
            }
        }
    }

    proptest! {
        #[test]
        fn everett_terms_reproduce_the_bank(path in arb_path()) {
            let e = uniform(41);
            let mut bank = PreisachBank::new(e.clone(), 1, 256).unwrap();
            let out = run1(&mut bank, &path);
            let terms = everett_terms(&path, 0.0, 1.0).unwrap();
            prop_assert_eq!(terms.indptr.len(), path.len() + 1);
            for (t, h) in out.iter().enumerate() {
                let r = terms.indptr[t]..terms.indptr[t + 1];
                let sum: f64 = r
                    .map(|q| terms.coef[q] * e.value(terms.alpha[q], terms.beta[q]))
                    .sum();
                prop_assert!((sum - h).abs() < 1e-9, "sample {}: {} vs {}", t, sum, h);
            }
        }
    }

    /// A decaying oscillation nests `2 * turns` extrema: deeper than the in-place stack.
    fn nested(turns: usize, wobble: f64) -> Vec<f64> {
        let mut path = Vec::new();
        for k in 0..turns {
            let a = 0.45 * (1.0 - k as f64 / turns as f64);
            path.push(0.5 + a + wobble * (k % 3) as f64);
            path.push(0.5 - a + 0.5 * wobble * (k % 2) as f64);
        }
        // and unwind them again, wiping out level after level
        path.extend([0.97, 0.02, 0.6, 0.4, 0.55]);
        path
    }

    #[test]
    fn deep_stacks_move_to_the_heap_and_back_without_changing_the_output() {
        let e = uniform(41);
        let path = nested(30, 1e-3);
        let mut bank = PreisachBank::new(e.clone(), 1, 256).unwrap();
        let before = bank.state_bytes();
        let mut deepest = 0;
        let mut out = Vec::new();
        for &u in &path {
            let mut o = [0.0];
            bank.step(&[u], &[true], &mut o).unwrap();
            out.push(o[0]);
            deepest = deepest.max(bank.depth()[0]);
            if bank.depth()[0] > INLINE_EXTREMA {
                assert!(
                    bank.state_bytes() > before,
                    "a deep stack lives on the heap"
                );
            }
        }
        assert!(
            deepest > INLINE_EXTREMA + 20,
            "the path nests {deepest} extrema"
        );
        assert_eq!(bank.state_bytes(), before, "back in place once shallow");
        assert_eq!(bank.forgotten()[0], 0);
        let terms = everett_terms(&path, 0.0, 1.0).unwrap();
        for (t, h) in out.iter().enumerate() {
            let sum: f64 = (terms.indptr[t]..terms.indptr[t + 1])
                .map(|q| terms.coef[q] * e.value(terms.alpha[q], terms.beta[q]))
                .sum();
            assert!((sum - h).abs() < 1e-9, "sample {t}: {sum} vs {h}");
        }
    }

    #[test]
    fn every_schedule_gives_the_same_outputs() {
        let e = uniform(41);
        let (n, t) = (3 * crate::par::MAX_BLOCK + 7, 120);
        let mut inputs = Vec::with_capacity(n * t);
        let mut valid = Vec::with_capacity(n * t);
        for r in 0..t {
            for i in 0..n {
                let x = (r as f64 * 0.37 + i as f64 * 0.11).sin() * (1.0 + (i % 5) as f64 * 0.1);
                inputs.push(0.5 + 0.45 * x * ((r * 7 + i) % 11) as f64 / 10.0);
                valid.push((r * 13 + i * 7) % 17 != 0);
            }
        }
        let mut reference = None;
        for schedule in [Schedule::FrameOrder, Schedule::Blocks, Schedule::Parallel] {
            let mut bank = PreisachBank::new(e.clone(), n, 16).unwrap();
            let mut out = vec![0.0; n * t];
            bank.run_scheduled(&inputs, &valid, &mut out, schedule)
                .unwrap();
            let bits: Vec<u64> = out.iter().map(|v| v.to_bits()).collect();
            match &reference {
                None => reference = Some((bits, bank.depth())),
                Some((r, d)) => {
                    assert!(r == &bits, "{schedule:?} differs");
                    assert_eq!(d, &bank.depth());
                }
            }
        }
    }

    #[test]
    fn everett_terms_reject_nan_and_bad_ranges() {
        assert!(everett_terms(&[0.1, f64::NAN], 0.0, 1.0).is_err());
        assert!(everett_terms(&[0.1], 1.0, 1.0).is_err());
    }
}
