//! One element of a Preisach bank: its stack of extrema (in place, or on the heap when
//! deep) and the heads of eight neighbouring elements kept field after field for the SIMD
//! path (eq. 4.16-4.22 by the kernel's `prepare` and `finish`).

use texsense_kernels::everett::Everett as EverettView;
use texsense_kernels::preisach::{self as kernel, Head, Prepared, CLAMPED};

use super::{GROUP, INLINE_EXTREMA};
use crate::error::CoreError;
use crate::snapshot::{Reader, Writer};

/// The heads of eight neighbouring elements, field after field (structure of arrays): the
/// kernel's head (depth, last input and output), copies of the stack's top extremum (input
/// and output) and of the input of the extremum below it, and the clamping counter. The
/// copies make the common step (no loop wiped out) a step of plain vector loads and stores
/// on the SIMD path; every step, on either path, keeps them equal to the stack
/// ([`Heads::set`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Heads {
    /// Extrema on the stack (>= 1).
    pub(super) len: [i64; GROUP],
    pub(super) last_u: [f64; GROUP],
    pub(super) last_h: [f64; GROUP],
    /// `stack[len - 1]`: the top extremum's input and output.
    pub(super) top_u: [f64; GROUP],
    pub(super) top_h: [f64; GROUP],
    /// `stack[max(len, 2) - 2]`'s input: the extremum below the top (the lower saturation
    /// at depth 1).
    pub(super) below_u: [f64; GROUP],
    /// The clamping counter, and in its top bit ([`HEAP`]) whether the lane's stack is on the
    /// heap (kept with `Element::spill` by every path, so that the SIMD rows find a group's
    /// stacks in place without reading its elements, at no extra byte of state).
    pub(super) clamped: [u64; GROUP],
}

/// The bit of a lane's `Heads::clamped` word that says its stack is on the heap (a counter
/// of samples never reaches it).
pub(super) const HEAP: u64 = 1 << 63;

impl Heads {
    /// Eight elements at lower saturation.
    pub(super) fn new(u_min: f64) -> Self {
        Self {
            len: [1; GROUP],
            last_u: [u_min; GROUP],
            last_h: [0.0; GROUP],
            top_u: [u_min; GROUP],
            top_h: [0.0; GROUP],
            below_u: [u_min; GROUP],
            clamped: [0; GROUP],
        }
    }

    /// Lane `l`'s stack is on the heap (`on`) or in place.
    #[inline(always)]
    pub(super) fn mark(&mut self, l: usize, on: bool) {
        self.clamped[l] = self.clamped[l] & !HEAP | if on { HEAP } else { 0 };
    }

    /// Lane `l`'s clamping counter.
    #[inline(always)]
    pub(super) fn count(&self, l: usize) -> u64 {
        self.clamped[l] & !HEAP
    }

    /// Lane `l`'s kernel head.
    #[inline(always)]
    pub(super) fn head(&self, l: usize) -> Head<f64> {
        Head {
            len: self.len[l] as u32,
            last_u: self.last_u[l],
            last_h: self.last_h[l],
        }
    }

    /// Lane `l` takes the kernel head `h` over the stack `s` (its copies of the top and
    /// the extremum below from the stack).
    #[inline(always)]
    pub(super) fn set(&mut self, l: usize, h: &Head<f64>, s: &[[f64; 2]]) {
        let len = h.len as usize;
        self.len[l] = len as i64;
        self.last_u[l] = h.last_u;
        self.last_h[l] = h.last_h;
        [self.top_u[l], self.top_h[l]] = s[len - 1];
        self.below_u[l] = s[len.max(2) - 2][0];
    }
}

/// The stack and the rare counter of one element (its head is in the group's [`Heads`]).
#[derive(Debug, Clone)]
pub(super) struct Element {
    pub(super) forgotten: u64,
    pub(super) inline: [[f64; 2]; INLINE_EXTREMA + 1],
    pub(super) spill: Option<Box<[[f64; 2]]>>,
}

impl Element {
    /// At lower saturation, with its head.
    pub(super) fn new(u_min: f64) -> (Self, Head<f64>) {
        let mut el = Self {
            forgotten: 0,
            inline: [[0.0; 2]; INLINE_EXTREMA + 1],
            spill: None,
        };
        let mut head = Head::new(u_min);
        kernel::start(&mut head, &mut el.inline, u_min);
        (el, head)
    }

    #[inline]
    pub(super) fn stack(&self) -> &[[f64; 2]] {
        match &self.spill {
            Some(s) => s,
            None => &self.inline,
        }
    }

    #[inline]
    pub(super) fn stack_mut(&mut self) -> &mut [[f64; 2]] {
        match &mut self.spill {
            Some(s) => s,
            None => &mut self.inline,
        }
    }

    /// Extrema the stack has room for now (in place or on the heap, at most the capacity).
    #[inline]
    pub(super) fn room(&self, capacity: usize) -> usize {
        (self.stack().len() - 1).min(capacity)
    }

    /// Give the stack of `len` extrema room for `room` on the heap (plus the spare slot).
    #[cold]
    fn grow_to(&mut self, len: usize, room: usize) {
        let mut s = vec![[0.0; 2]; room + 1].into_boxed_slice();
        s[..len].copy_from_slice(&self.stack()[..len]);
        self.spill = Some(s);
    }

    /// Back in place (the stack of `len` extrema is shallow again).
    #[cold]
    pub(super) fn unspill(&mut self, len: usize) {
        if let Some(s) = self.spill.take() {
            self.inline[..len].copy_from_slice(&s[..len]);
        }
    }

    /// One valid input (eq. 4.16-4.22) of the element in lane `l` of `heads`: the kernel's
    /// step (`prepare`, then `finish`) on this element's stack, which grows on the heap up
    /// to the capacity.
    #[inline]
    pub(super) fn step(
        &mut self,
        heads: &mut Heads,
        l: usize,
        e: &EverettView<'_, f64>,
        capacity: usize,
        u_in: f64,
    ) -> f64 {
        let mut head = heads.head(l);
        let (prepared, flags) = kernel::prepare(&head, e, u_in);
        heads.clamped[l] += u64::from(flags & CLAMPED != 0);
        let (u, rising, turned) = match prepared {
            Prepared::Same(h) => return h,
            Prepared::Moves { u, rising, turned } => (u, rising, turned),
        };
        if head.len as usize == self.room(capacity) {
            // rare; `turned` is tested inside, out of line, so that the compiler cannot
            // test it first (it is as unpredictable as a coin on a real input)
            self.make_room(&mut head, capacity, turned);
        }
        let h = kernel::finish(&mut head, self.stack_mut(), e, u, rising, turned);
        if head.len as usize <= INLINE_EXTREMA / 2 && self.spill.is_some() {
            self.unspill(head.len as usize);
        }
        heads.set(l, &head, self.stack());
        heads.mark(l, self.spill.is_some());
        h
    }

    /// The stack is full: if the input turned, grow it on the heap (doubling) while below
    /// the capacity, else forget the innermost loop (the kernel's `forget`).
    #[cold]
    #[inline(never)]
    fn make_room(&mut self, head: &mut Head<f64>, capacity: usize, turned: bool) {
        if !turned {
            return;
        }
        let room = self.stack().len() - 1;
        if room < capacity {
            self.grow_to(head.len as usize, (2 * room).min(capacity));
            return;
        }
        kernel::forget(head, self.stack_mut());
        self.forgotten += 1;
    }

    /// The element's state in a snapshot: head, counters, the extrema on the stack.
    pub(super) fn save(&self, head: &Head<f64>, clamped: u64, w: &mut Writer) {
        let len = head.len as usize;
        w.u32(head.len);
        w.f64(head.last_u);
        w.f64(head.last_h);
        w.u64(clamped);
        w.u64(self.forgotten);
        for &[u, h] in &self.stack()[..len] {
            w.f64(u);
            w.f64(h);
        }
    }

    /// An element, its head and its clamping counter from a snapshot ([`Element::save`])
    /// of a bank with `capacity`.
    pub(super) fn load(
        r: &mut Reader<'_>,
        u_min: f64,
        capacity: usize,
    ) -> Result<(Self, Head<f64>, u64), CoreError> {
        let (mut el, _) = Self::new(u_min);
        let len = r.u32()? as usize;
        if len == 0 || len > capacity {
            return Err(r.error("a Preisach stack is deeper than the capacity"));
        }
        let head = Head {
            len: len as u32,
            last_u: r.f64()?,
            last_h: r.f64()?,
        };
        let clamped = r.u64()?;
        el.forgotten = r.u64()?;
        if len > INLINE_EXTREMA {
            el.grow_to(0, len.next_power_of_two().min(capacity));
        }
        for slot in &mut el.stack_mut()[..len] {
            *slot = [r.f64()?, r.f64()?];
        }
        Ok((el, head, clamped))
    }
}
