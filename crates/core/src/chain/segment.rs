//! The element-wise stages of a chain between two neighbour stages (detect, repair), run
//! as one pass per block of elements: conversion then compensation (the usual segment,
//! without a dispatch), or any other run of conversion, loading curve, compensation and
//! drift, stage by stage over each block's row.

use super::{code, Stage};
use crate::compensation::CompensationBlock;
use crate::convert::ConverterView;
use crate::drift::DriftBlock;
use crate::par::{block_size, run_frames_coded, FrameBlock, MAX_BLOCK};
use texsense_kernels::stage as rules;

/// A run of element-wise stages over a tile: `src` (T x N) and the validity in `codes` ->
/// `dst`; a reading the stages made invalid gets [`code::OUT_OF_RANGE`].
pub(super) fn segment(
    n: usize,
    stages: &mut [Stage],
    dt: &[f64],
    src: &[f64],
    codes: &mut [u8],
    dst: &mut [f64],
) {
    let size = block_size(n);
    let n_blocks = n.div_ceil(size);
    if let Some(&first) = dt.first() {
        for s in stages.iter_mut() {
            match s {
                Stage::Compensation(c) => c.prepare(first),
                Stage::Drift(d) => d.prepare(first),
                _ => {}
            }
        }
    }
    if let [Stage::Convert(conv), Stage::Compensation(comp)] = stages {
        // conversion then compensation, the usual segment: one step without a dispatch,
        // its blocks made without a list of parts each (a live step makes them every frame)
        let conv = conv.view();
        let usual = comp.blocks().enumerate().map(|(b, comp)| UsualBlock {
            start: b * size,
            conv,
            comp,
        });
        run_frames_coded(dst, n, usual, dt, src, codes, code::OK);
        crate::lanes::code_not_finite(dst, codes, code::OK, code::OUT_OF_RANGE);
        return;
    }
    let mut blocks: Vec<SegmentBlock<'_>> = (0..n_blocks)
        .map(|b| SegmentBlock {
            start: b * size,
            parts: Vec::with_capacity(stages.len()),
        })
        .collect();
    for s in stages.iter_mut() {
        match s {
            Stage::Convert(c) => {
                let view = c.view();
                blocks
                    .iter_mut()
                    .for_each(|b| b.parts.push(Part::Convert(view)));
            }
            Stage::Loading(curve) => {
                let view = curve.view();
                blocks
                    .iter_mut()
                    .for_each(|b| b.parts.push(Part::Loading(view)));
            }
            Stage::Compensation(c) => {
                for (b, part) in blocks.iter_mut().zip(c.blocks()) {
                    b.parts.push(Part::Compensation(part));
                }
            }
            Stage::Drift(d) => {
                for (b, part) in blocks.iter_mut().zip(d.blocks()) {
                    b.parts.push(Part::Drift(part));
                }
            }
            Stage::Detect(_) | Stage::Repair(_) => unreachable!("not element-wise"),
        }
    }
    run_frames_coded(dst, n, blocks, dt, src, codes, code::OK);
    crate::lanes::code_not_finite(dst, codes, code::OK, code::OUT_OF_RANGE);
}

/// One element-wise stage of a block.
enum Part<'a> {
    Convert(ConverterView<'a>),
    Loading(texsense_kernels::convert::Curve<'a, f64>),
    Compensation(CompensationBlock<'a>),
    Drift(DriftBlock<'a>),
}

/// The element-wise stages of one block of elements, run one after the other per element.
struct SegmentBlock<'a> {
    start: usize,
    parts: Vec<Part<'a>>,
}

/// A block of the usual segment: conversion, then compensation (the same rules as
/// [`SegmentBlock`], without the dispatch).
struct UsualBlock<'a> {
    start: usize,
    conv: ConverterView<'a>,
    comp: CompensationBlock<'a>,
}

impl FrameBlock for UsualBlock<'_> {
    #[inline]
    fn frame(&mut self, dt: f64) {
        self.comp.frame(dt);
    }

    #[inline(always)]
    fn step(&mut self, i: usize, dt: f64, x: f64, valid: bool) -> f64 {
        let (x, ok) = self.conv.stage(self.start + i, x, valid);
        self.comp.stage(i, dt, x, ok).0
    }

    /// The frame's row of the block through conversion, then the compensation's row (its
    /// Preisach step across elements in SIMD lanes where the processor has them).
    fn row(&mut self, dt: f64, x: &[f64], valid: &[bool], out: &mut [f64]) {
        self.conv.row(self.start, x, valid, out);
        // conversion keeps the validity (stage::conversion)
        self.comp.row_in_place(dt, valid, out);
    }
}

impl FrameBlock for SegmentBlock<'_> {
    #[inline]
    fn frame(&mut self, dt: f64) {
        for p in &mut self.parts {
            match p {
                Part::Compensation(c) => c.frame(dt),
                Part::Drift(d) => d.frame(dt),
                Part::Convert(_) | Part::Loading(_) => {}
            }
        }
    }

    #[inline(always)]
    fn step(&mut self, i: usize, dt: f64, x: f64, valid: bool) -> f64 {
        let (mut x, mut ok) = (x, valid);
        for p in &mut self.parts {
            (x, ok) = match p {
                Part::Convert(c) => c.stage(self.start + i, x, ok),
                Part::Loading(curve) => rules::loading(curve, x, ok),
                Part::Compensation(c) => c.stage(i, dt, x, ok),
                Part::Drift(d) => {
                    let y = d.step(i, dt, x, ok);
                    (y, ok && y.is_finite())
                }
            };
        }
        x
    }

    /// The frame's row of the block part after part, each part over the whole row (the
    /// rows of conversion, compensation and drift in SIMD lanes where the processor has
    /// them; the loading curve element by element): the same values as
    /// [`SegmentBlock::step`] per element. After a compensation, drift or loading curve a
    /// reading is valid when its value is a number (each gives NaN for an invalid input,
    /// so `ok && y.is_finite()` is `y.is_finite()`); conversion keeps the validity.
    fn row(&mut self, dt: f64, x: &[f64], valid: &[bool], out: &mut [f64]) {
        let w = out.len();
        let (mut a, mut b, mut ok) = ([0.0; MAX_BLOCK], [0.0; MAX_BLOCK], [false; MAX_BLOCK]);
        let (mut cur, mut next, ok) = (&mut a[..w], &mut b[..w], &mut ok[..w]);
        cur.copy_from_slice(x);
        ok.copy_from_slice(valid);
        for p in &mut self.parts {
            match p {
                Part::Convert(c) => c.row(self.start, cur, ok, next),
                Part::Loading(curve) => {
                    for i in 0..w {
                        (next[i], ok[i]) = rules::loading(curve, cur[i], ok[i]);
                    }
                }
                Part::Compensation(c) => {
                    c.row(dt, cur, ok, next);
                    crate::lanes::finite_flags(next, ok);
                }
                Part::Drift(d) => {
                    d.row(dt, cur, ok, next);
                    crate::lanes::finite_flags(next, ok);
                }
            }
            std::mem::swap(&mut cur, &mut next);
        }
        out.copy_from_slice(cur);
    }
}
