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

use crate::aligned::Row;
use rayon::prelude::*;

/// Most elements per block. 512 elements' states (about 260 KB for the benchmark's chain, 510
/// bytes per element) stay in a core's second-level cache; against blocks of 128 elements
/// (whose states fit the first-level cache), a block's rows are read and written in runs four
/// times as long and each row's fixed costs are spread over four times the elements (issue
/// 34, seventeenth round: docs/pipeline.md has the measurements).
pub const MAX_BLOCK: usize = 512;

/// Fewest elements per block.
pub const MIN_BLOCK: usize = 16;

/// Batches smaller than this many element-samples run on the calling thread.
pub const PARALLEL_MIN: usize = 1 << 15;

/// Elements per block for a bank of `n`: at most [`MAX_BLOCK`], and small enough that every
/// thread of the pool gets a block (a 96-element seat runs on both cores); a multiple of 8
/// (the drift states' and the Preisach heads' groups of eight, `drift::GROUP` and
/// `preisach::GROUP`, never straddle two blocks). The outputs do not
/// depend on it: every element is computed by the same code in any block.
#[inline]
pub fn block_size(n: usize) -> usize {
    n.div_ceil(rayon::current_num_threads().max(1))
        .next_multiple_of(8)
        .clamp(MIN_BLOCK, MAX_BLOCK)
}

/// True when a batch of `t` frames of `n` elements is worth handing to the thread pool.
#[inline]
pub fn parallel(t: usize, n: usize) -> bool {
    t.saturating_mul(n) >= PARALLEL_MIN && n > block_size(n)
}

/// A `T x N` row-major output that blocks of columns fill from several threads at once.
///
/// Private to this module: the only way to write through it is a [`BlockOut`] handed out by
/// [`for_blocks`], which gives each block its own columns, so no element is written by two
/// threads.
#[derive(Clone, Copy)]
struct Columns<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Columns` is a raw view of a slice that outlives the parallel section (it is built
// from `&mut [T]` inside `for_blocks`, which holds that borrow until every block is done);
// threads write disjoint indices (one block of columns each), so sharing the pointer is sound
// for `T: Send`.
unsafe impl<T: Send> Send for Columns<T> {}
// SAFETY: see above; `&Columns` only allows writes to disjoint indices per thread.
unsafe impl<T: Send> Sync for Columns<T> {}

/// What one block of the parallel loop may write: its own columns
/// `start .. start + width` of every frame of the `T x N` output.
pub struct BlockOut<'a, T> {
    cols: &'a Columns<T>,
    n: usize,
    start: usize,
    width: usize,
    frames: usize,
}

impl<T: Copy> BlockOut<'_, T> {
    /// The first element (column) of the block.
    #[inline]
    pub fn start(&self) -> usize {
        self.start
    }

    /// Number of elements in the block.
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Number of frames (rows) of the output.
    #[inline]
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The block's columns of frame `r` (`width` values, element `start + li` at `li`).
    ///
    /// # Panics
    /// When `r` is not a frame of the output.
    #[inline]
    pub fn row(&mut self, r: usize) -> &mut [T] {
        assert!(r < self.frames, "frame {r} of {}", self.frames);
        // SAFETY: r < frames puts the `width` values from r * n + start inside the output
        // (start + width <= n), and they are this block's columns, which no other block
        // reads or writes (for_blocks gives each block its own columns); the slice borrows
        // `self`, so a block holds one row at a time; the output stays borrowed by
        // for_blocks until every block is done.
        unsafe {
            std::slice::from_raw_parts_mut(self.cols.ptr.add(r * self.n + self.start), self.width)
        }
    }
}

/// The one parallel block loop of the crate: `work(block, out)` for every block of elements
/// of a bank of `n` (block `b` covers elements `b * size .. (b + 1) * size`, `size =`
/// [`block_size`]`(n)`), each through all frames on its own, on the thread pool when `par`.
/// A block writes its elements' values of every frame through `out` (its own columns of the
/// row-major `T x N` output); the per-block states (`blocks`, one per block, e.g. the
/// [`Vec`] of a bank's block views or element chunks) go to the block that owns them.
///
/// # Panics
/// When `out` is not `T x n` or `blocks` does not hold one entry per block.
pub fn for_blocks<B, T, F>(
    out: &mut [T],
    n: usize,
    blocks: impl IntoIterator<Item = B>,
    par: bool,
    work: F,
) where
    B: Send,
    T: Copy + Send,
    F: Fn(B, &mut BlockOut<'_, T>) + Sync + Send,
{
    if n == 0 {
        return;
    }
    assert!(out.len().is_multiple_of(n), "output is not T x {n}");
    let size = block_size(n);
    let frames = out.len() / n;
    let cols = Columns {
        ptr: out.as_mut_ptr(),
        len: out.len(),
    };
    debug_assert_eq!(cols.len, frames * n);
    let cols = &cols;
    let blocks = each_block(blocks, par, |(b, block)| {
        assert!(b * size < n, "one state per block of {size}");
        let start = b * size;
        let mut o = BlockOut {
            cols,
            n,
            start,
            width: size.min(n - start),
            frames,
        };
        work(block, &mut o);
    });
    assert_eq!(blocks, n.div_ceil(size), "one state per block of {size}");
}

/// A block of a bank whose elements step frame after frame: a frame starts `dt` seconds
/// after the previous one, then each element reads its input (NaN out when it is invalid).
pub trait FrameBlock: Send {
    /// Start a frame `dt` seconds after the previous one (before any `step` of it).
    fn frame(&mut self, _dt: f64) {}

    /// Element `i` of the block reads `x` (`valid` false: skipped, NaN out, state kept).
    fn step(&mut self, i: usize, dt: f64, x: f64, valid: bool) -> f64;

    /// The whole frame of the block: element `i` reads `x[i]` (`ok[i]` false: skipped, its
    /// `x[i]` NaN) into `out[i]`; the stages fused per block override it to run each stage
    /// over the frame's row (on SIMD where the processor has it, [`crate::simd`]).
    fn row(&mut self, dt: f64, x: &[f64], ok: &[bool], out: &mut [f64]) {
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = self.step(i, dt, x[i], ok[i]);
        }
    }
}

/// The frames `dt` (T,) of a batch through blocks of a bank ([`for_blocks`]): element `i`
/// of frame `r` reads `input(r * n + i, i)` (None: an invalid reading) and its output goes to
/// `out[r * n + i]`.
pub fn run_frames<B, F>(
    out: &mut [f64],
    n: usize,
    blocks: impl IntoIterator<Item = B>,
    dt: &[f64],
    input: F,
) where
    B: FrameBlock,
    F: Fn(usize, usize) -> Option<f64> + Sync,
{
    let par = parallel(dt.len(), n);
    for_blocks(out, n, blocks, par, |mut block, o| {
        let (start, width) = (o.start(), o.width());
        // the inputs on a cache line ([`crate::aligned`])
        let (mut x, mut ok) = (Row([0.0; MAX_BLOCK]), [false; MAX_BLOCK]);
        let (x, ok) = (&mut x.0[..width], &mut ok[..width]);
        for (r, &d) in dt.iter().enumerate() {
            block.frame(d);
            let row = r * n + start;
            for li in 0..width {
                (x[li], ok[li]) = match input(row + li, start + li) {
                    Some(v) => (v, true),
                    None => (f64::NAN, false),
                };
            }
            block.row(d, x, ok, o.row(r));
        }
    });
}

/// [`run_frames`] for readings whose validity is a code (`codes[idx] == ok_code`: valid):
/// element `i` of frame `r` reads `src[r * n + i]`, the same inputs as `run_frames` with
/// `input = |idx, _| (codes[idx] == ok_code).then(|| src[idx])`, gathered a row at a time
/// without a call per reading.
///
/// # Panics
/// When `src` or `codes` is not `T x n`.
pub fn run_frames_coded<B>(
    out: &mut [f64],
    n: usize,
    blocks: impl IntoIterator<Item = B>,
    dt: &[f64],
    src: &[f64],
    codes: &[u8],
    ok_code: u8,
) where
    B: FrameBlock,
{
    assert!(
        src.len() == dt.len() * n && codes.len() == src.len(),
        "T x {n}"
    );
    let par = parallel(dt.len(), n);
    for_blocks(out, n, blocks, par, |mut block, o| {
        let (start, width) = (o.start(), o.width());
        let (mut x, mut ok) = ([0.0; MAX_BLOCK], [false; MAX_BLOCK]);
        let (x, ok) = (&mut x[..width], &mut ok[..width]);
        for (r, &d) in dt.iter().enumerate() {
            block.frame(d);
            let at = r * n + start;
            let (s, c) = (&src[at..at + width], &codes[at..at + width]);
            crate::lanes::coded_inputs(s, c, ok_code, x, ok);
            block.row(d, x, ok, o.row(r));
        }
    });
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
/// pool when `par`, else one after the other on this thread as the blocks come (a live
/// frame makes no list of them: issue 34, sixteenth round); how many blocks there were.
pub fn each_block<B, F>(blocks: impl IntoIterator<Item = B>, par: bool, work: F) -> usize
where
    B: Send,
    F: Fn((usize, B)) + Sync + Send,
{
    if par {
        let blocks: Vec<B> = blocks.into_iter().collect();
        let count = blocks.len();
        blocks.into_par_iter().enumerate().for_each(work);
        count
    } else {
        let mut count = 0;
        for (b, block) in blocks.into_iter().enumerate() {
            work((b, block));
            count = b + 1;
        }
        count
    }
}
