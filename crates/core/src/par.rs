//! Parallel batches over blocks of elements.
//!
//! Every stage keeps its state per element, and a frame is a row of a row-major `T x N` block,
//! so a batch splits into blocks of neighbouring elements ([`block_size`]) that run on their own for
//! all `T` frames (rayon, one task per block): each task reads the block's columns of every
//! row and writes the same columns of the output. The state of a block stays in the core's
//! cache for the whole batch, and the rows are read in runs of contiguous values.
//!
//! Small batches (fewer than [`PARALLEL_MIN`] element-samples, e.g. one live frame) run the
//! same blocks one after the other on the calling thread: identical arithmetic, no hand-off.

use rayon::prelude::*;

/// Most elements per block (128 elements' states fit in a core's first-level cache).
pub const MAX_BLOCK: usize = 128;

/// Fewest elements per block.
pub const MIN_BLOCK: usize = 16;

/// Batches smaller than this many element-samples run on the calling thread.
pub const PARALLEL_MIN: usize = 1 << 15;

/// Elements per block for a bank of `n`: at most [`MAX_BLOCK`], and small enough that every
/// thread of the pool gets a block (a 96-element seat runs on both cores). The outputs do not
/// depend on it: every element is computed by the same code in any block.
#[inline]
pub fn block_size(n: usize) -> usize {
    n.div_ceil(rayon::current_num_threads().max(1))
        .clamp(MIN_BLOCK, MAX_BLOCK)
}

/// True when a batch of `t` frames of `n` elements is worth handing to the thread pool.
#[inline]
pub fn parallel(t: usize, n: usize) -> bool {
    t.saturating_mul(n) >= PARALLEL_MIN && n > block_size(n)
}

/// A `T x N` row-major output that blocks of columns fill from several threads at once.
///
/// Each block writes only its own columns, so no element is written by two threads; that is
/// the invariant every user of [`Columns::write`] keeps.
#[derive(Clone, Copy)]
pub struct Columns<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Columns` is a raw view of a slice that outlives the parallel section (it is built
// from `&mut [T]` and used only inside a scope that holds that borrow); threads write disjoint
// indices (one block of columns each), so sharing the pointer is sound for `T: Send`.
unsafe impl<T: Send> Send for Columns<T> {}
// SAFETY: see above; `&Columns` only allows writes to disjoint indices per thread.
unsafe impl<T: Send> Sync for Columns<T> {}

impl<T: Copy> Columns<T> {
    /// View `out` for writing from several threads.
    pub fn new(out: &mut [T]) -> Self {
        Self {
            ptr: out.as_mut_ptr(),
            len: out.len(),
        }
    }

    /// Write `v` at `idx`.
    ///
    /// # Safety
    /// No other thread may read or write `idx` during the parallel section (each block owns
    /// its columns), and the slice this view was made from must still be borrowed.
    #[inline]
    pub unsafe fn write(&self, idx: usize, v: T) {
        debug_assert!(idx < self.len);
        // SAFETY: idx < len (checked in debug builds; callers index rows of length N inside
        // a slice checked to be T x N) and the caller guarantees exclusive access to idx.
        unsafe { self.ptr.add(idx).write(v) }
    }

    /// Read the value at `idx`.
    ///
    /// # Safety
    /// No thread may write `idx` during the parallel section.
    #[inline]
    pub unsafe fn read(&self, idx: usize) -> T {
        debug_assert!(idx < self.len);
        // SAFETY: as for `write`; nobody writes idx concurrently.
        unsafe { self.ptr.add(idx).read() }
    }
}

/// `work((b, chunk))` for every chunk of `size` items (chunk `b` starts at item `b * size`),
/// on the thread pool when `par`, else one after the other on this thread.
pub fn each_chunk<T, F>(items: &mut [T], size: usize, par: bool, work: F)
where
    T: Send,
    F: Fn((usize, &mut [T])) + Sync + Send,
{
    if par {
        items.par_chunks_mut(size).enumerate().for_each(work);
    } else {
        items.chunks_mut(size).enumerate().for_each(work);
    }
}

/// `work((b, block))` for every block (e.g. the per-block views of a bank), on the thread
/// pool when `par`, else one after the other on this thread.
pub fn each_block<B, F>(blocks: Vec<B>, par: bool, work: F)
where
    B: Send,
    F: Fn((usize, B)) + Sync + Send,
{
    if par {
        blocks.into_par_iter().enumerate().for_each(work);
    } else {
        blocks.into_iter().enumerate().for_each(work);
    }
}
