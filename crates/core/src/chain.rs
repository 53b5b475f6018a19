//! The whole capacitance-to-pressure chain of a mat in one compiled pass over a `T x N` block:
//! failure detection -> capacitance to compression -> Preisach + drift (or the first-loading
//! curve) -> local repair of failed readings.
//!
//! - **detect**: [`crate::detect::FailureDetector`]; without it a reading fails when the
//!   converter flagged it or it is not a number;
//! - **convert** (eq. 2.1 per element): `C_ref = (C - a_i) / b_i`, then the compression from
//!   the material curve `C_ref(e)`, linearly interpolated and held at its ends;
//! - **respond**: [`Compensation`] (eq. 4.15-4.22 and 5.8), or without hysteresis the
//!   first-loading curve `p(e)`; failed readings are NaN and leave the states untouched;
//! - **repair** (thesis §6.5.2.5), local methods: `zero`, `last-value`, eq. 6.14
//!   `neighbour-mean`, and `weighted` (any fixed neighbour weights, e.g. inverse squared
//!   distance over the 8-neighbourhood). Only measured readings of the same frame enter a
//!   mean; where none is available the element's last value (real or repaired) is held, NaN
//!   before it has one.
//!
//! Every stage keeps its state per element, so a batch runs each pass over blocks of elements
//! in parallel (the repair pass reads the neighbours' measured values, which no pass writes
//! any more). `step` is the same code with T = 1.

use crate::compensation::{Compensation, CompensationBlock};
use crate::detect::{code, Changes, FailureDetector};
use crate::error::{check_len, CoreError};
use crate::par::{block_size, each_block, each_chunk, parallel, Columns};
use crate::topology::Neighbours;

/// Element-samples per tile of frames in a batch (a float64 array of a tile is 1 MiB).
const TILE_SAMPLES: usize = 1 << 17;

/// A piecewise-linear curve `y(x)` over increasing `x`, held at its ends (`np.interp`).
///
/// The segment of an input is found without a search: a table of uniform buckets over `x`
/// holds, per bucket, the last point at or below the bucket's start, and a step or two
/// forward from there reaches the segment (exactly the one a binary search finds).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    x: Vec<f64>,
    y: Vec<f64>,
    slope: Vec<f64>,
    bucket_start: Vec<u32>,
    inv_width: f64,
}

impl Curve {
    /// Build from points with strictly increasing `x` (at least 2).
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Result<Self, CoreError> {
        check_len("curve y", y.len(), x.len())?;
        if x.len() < 2
            || x.len() > u32::MAX as usize
            || x.windows(2)
                .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
            || x.iter().chain(&y).any(|v| !v.is_finite())
        {
            return Err(CoreError::Parameter {
                what: "curve",
                why: "needs >= 2 finite points with strictly increasing x".into(),
            });
        }
        let last = x.len() - 1;
        let buckets = 4 * x.len();
        let width = (x[last] - x[0]) / buckets as f64;
        let bucket_start = (0..=buckets)
            .map(|b| {
                let lo = x[0] + b as f64 * width;
                (x.partition_point(|&xi| xi <= lo).max(1) - 1).min(last - 1) as u32
            })
            .collect();
        // per segment, as np.interp computes it (so the same bits)
        let slope = (0..last)
            .map(|j| (y[j + 1] - y[j]) / (x[j + 1] - x[j]))
            .collect();
        Ok(Self {
            bucket_start,
            inv_width: 1.0 / width,
            slope,
            x,
            y,
        })
    }

    /// `y` at `v` (NaN for NaN).
    #[inline]
    pub fn at(&self, v: f64) -> f64 {
        let (x, y) = (&self.x, &self.y);
        let last = x.len() - 1;
        if v.is_nan() {
            return f64::NAN;
        }
        if v >= x[last] {
            return y[last];
        }
        if v <= x[0] {
            return y[0];
        }
        let top = (self.bucket_start.len() - 1) as f64;
        let pos = ((v - x[0]) * self.inv_width).min(top);
        // SAFETY: x[0] < v and v is a number, so 0 <= pos <= top < 2^32 (a plain `as` cast
        // spends a dozen instructions on saturation that cannot happen here)
        let b = unsafe { pos.to_int_unchecked::<u32>() } as usize;
        let mut j = self.bucket_start[b] as usize;
        // the bucket's start may round either way at its edge: settle on x[j] <= v < x[j + 1]
        while j > 0 && x[j] > v {
            j -= 1;
        }
        while j + 1 < last && x[j + 1] <= v {
            j += 1;
        }
        if x[j] == v {
            return y[j];
        }
        self.slope[j] * (v - x[j]) + y[j]
    }
}

/// Capacitance -> compression per element (eq. 2.1): `C_ref = (C - offset_i) / gain_i`,
/// then the material curve from `C_ref` to the compression (or, without a curve, the
/// reading scaled per element: a linear calibration).
#[derive(Debug, Clone)]
pub struct Converter {
    offset: Vec<f64>,
    gain: Vec<f64>,
    curve: Option<Curve>,
}

impl Converter {
    /// Per-element offsets and gains (> 0) and the curve from reference capacitance to
    /// compression (None: the scaled reading itself).
    pub fn new(offset: Vec<f64>, gain: Vec<f64>, curve: Option<Curve>) -> Result<Self, CoreError> {
        check_len("gain", gain.len(), offset.len())?;
        if gain.iter().any(|g| g.is_nan() || *g <= 0.0) || offset.iter().any(|o| !o.is_finite()) {
            return Err(CoreError::Parameter {
                what: "converter",
                why: "offsets must be finite and gains > 0".into(),
            });
        }
        Ok(Self {
            offset,
            gain,
            curve,
        })
    }
}

/// The compression -> pressure stage.
#[derive(Debug, Clone)]
pub enum Response {
    /// Preisach (and drift): the compensated output.
    Compensation(Compensation),
    /// The first-loading curve (what an uncompensated system does).
    Loading(Curve),
    /// The converted value itself (a linear calibration: no spacer model).
    Direct,
}

/// The local repair methods.
#[derive(Debug, Clone)]
pub enum LocalRepair {
    /// Leave failed readings NaN.
    None,
    /// Failed readings read 0.
    Zero,
    /// Hold the last value (real or repaired).
    LastValue,
    /// Eq. 6.14: the mean of the measured 4-neighbours.
    NeighbourMean(Neighbours),
    /// A weighted mean of the measured neighbours (`weights` parallel to the neighbours'
    /// indices).
    Weighted(Neighbours, Vec<f64>),
}

/// Per-element state of the chain outside the detector and the response.
#[derive(Debug, Clone, Copy)]
struct ChainElement {
    last: f64,
}

impl Default for ChainElement {
    fn default() -> Self {
        Self { last: f64::NAN }
    }
}

/// The chain of one mat.
#[derive(Debug, Clone)]
pub struct Chain {
    detector: Option<FailureDetector>,
    converter: Converter,
    response: Response,
    repair: LocalRepair,
    elements: Vec<ChainElement>,
    changes: Changes,
}

impl Chain {
    /// Assemble a chain; every stage must have the same number of elements.
    pub fn new(
        detector: Option<FailureDetector>,
        converter: Converter,
        response: Response,
        repair: LocalRepair,
    ) -> Result<Self, CoreError> {
        let n = converter.offset.len();
        if let Some(d) = &detector {
            check_len("detector elements", d.len(), n)?;
        }
        if let Response::Compensation(c) = &response {
            check_len("compensation elements", c.len(), n)?;
        }
        match &repair {
            LocalRepair::NeighbourMean(nb) => check_len("repair neighbours", nb.len(), n)?,
            LocalRepair::Weighted(nb, w) => {
                check_len("repair neighbours", nb.len(), n)?;
                check_len("repair weights", w.len(), nb.nnz())?;
            }
            _ => {}
        }
        Ok(Self {
            detector,
            converter,
            response,
            repair,
            elements: vec![ChainElement::default(); n],
            changes: Changes::default(),
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

    /// Every stage back to its initial state.
    pub fn reset(&mut self) {
        if let Some(d) = &mut self.detector {
            d.reset();
        }
        if let Response::Compensation(c) = &mut self.response {
            c.reset();
        }
        self.elements.fill(ChainElement::default());
    }

    /// Bytes of state per element, all stages together (parameters per element included).
    pub fn state_bytes_per_element(&self) -> usize {
        let response = match &self.response {
            Response::Compensation(c) => c.state_bytes_per_element(),
            Response::Loading(_) | Response::Direct => 0,
        };
        std::mem::size_of::<ChainElement>()
            + 2 * std::mem::size_of::<f64>() // offset, gain
            + self
                .detector
                .as_ref()
                .map_or(0, |d| d.state_bytes_per_element() + 3 * std::mem::size_of::<f64>())
            + response
    }

    /// A batch: time steps `dt` (T,), readings (pF) and the converter's validity (T x N) ->
    /// pressure (T x N) and failure codes (T x N; 0 = measured).
    pub fn run(
        &mut self,
        dt: &[f64],
        readings: &[f64],
        valid: &[bool],
        out: &mut [f64],
        codes: &mut [u8],
    ) -> Result<(), CoreError> {
        let n = self.len();
        let t = dt.len();
        crate::drift::check_time_steps(dt)?;
        check_len("readings", readings.len(), t * n)?;
        check_len("valid", valid.len(), t * n)?;
        check_len("out", out.len(), t * n)?;
        check_len("codes", codes.len(), t * n)?;
        if n == 0 {
            return Ok(());
        }
        // tiles of frames small enough that a tile's arrays stay in cache from one pass to
        // the next (each pass streams through the whole tile)
        let tile = (TILE_SAMPLES / n).max(1);
        for a in (0..t).step_by(tile) {
            let b = (a + tile).min(t);
            let rows = a * n..b * n;
            self.run_tile(
                &dt[a..b],
                &readings[rows.clone()],
                &valid[rows.clone()],
                &mut out[rows.clone()],
                &mut codes[rows],
            )?;
        }
        Ok(())
    }

    /// The passes over one tile of frames: detect, convert and respond, repair.
    fn run_tile(
        &mut self,
        dt: &[f64],
        readings: &[f64],
        valid: &[bool],
        out: &mut [f64],
        codes: &mut [u8],
    ) -> Result<(), CoreError> {
        let t = dt.len();
        let par = parallel(t, self.len());
        match &mut self.detector {
            Some(d) => d.run(readings, valid, codes, &mut self.changes)?,
            None => {
                for ((c, &r), &v) in codes.iter_mut().zip(readings).zip(valid) {
                    *c = if v && r.is_finite() {
                        code::OK
                    } else {
                        code::OUT_OF_RANGE
                    };
                }
            }
        }
        self.respond(dt, readings, codes, out, par);
        self.repair(t, codes, out, par);
        Ok(())
    }

    fn respond(&mut self, dt: &[f64], readings: &[f64], codes: &[u8], out: &mut [f64], par: bool) {
        let n = self.len();
        let conv = &self.converter;
        let cols = Columns::new(out);
        let compression = |i: usize, c: f64| {
            let scaled = (c - conv.offset[i]) / conv.gain[i];
            match &conv.curve {
                Some(curve) => curve.at(scaled),
                None => scaled,
            }
        };
        let size = block_size(n);
        match &mut self.response {
            Response::Compensation(comp) => {
                let work = |(b, mut block): (usize, CompensationBlock<'_>)| {
                    let start = b * size;
                    let width = block.len();
                    for (r, &d) in dt.iter().enumerate() {
                        block.frame(d);
                        let row = r * n + start;
                        for li in 0..width {
                            let v = if codes[row + li] == code::OK {
                                let e = compression(start + li, readings[row + li]);
                                block.step(li, d, e, true)
                            } else {
                                block.step(li, d, f64::NAN, false)
                            };
                            // SAFETY: this block owns columns start .. start + width
                            unsafe { cols.write(row + li, v) };
                        }
                    }
                };
                each_block(comp.blocks(), par, work);
            }
            response @ (Response::Loading(_) | Response::Direct) => {
                let curve = match &*response {
                    Response::Loading(c) => Some(c),
                    _ => None,
                };
                let work = |(_, start): (usize, usize)| {
                    let end = (start + size).min(n);
                    for r in 0..dt.len() {
                        for i in start..end {
                            let idx = r * n + i;
                            let v = if codes[idx] == code::OK {
                                let e = compression(i, readings[idx]);
                                curve.map_or(e, |c| c.at(e))
                            } else {
                                f64::NAN
                            };
                            // SAFETY: this block owns columns start .. end
                            unsafe { cols.write(idx, v) };
                        }
                    }
                };
                each_block((0..n).step_by(size).collect(), par, work);
            }
        }
    }

    fn repair(&mut self, t: usize, codes: &[u8], out: &mut [f64], par: bool) {
        let n = self.len();
        let repair = &self.repair;
        let cols = Columns::new(out);
        let size = block_size(n);
        let work = |(b, state): (usize, &mut [ChainElement])| {
            let start = b * size;
            for r in 0..t {
                let row = r * n;
                for (li, el) in state.iter_mut().enumerate() {
                    let i = start + li;
                    if codes[row + i] == code::OK {
                        // SAFETY: a measured reading is read by everyone and written by nobody
                        el.last = unsafe { cols.read(row + i) };
                        continue;
                    }
                    // SAFETY: measured readings of the frame are never written in this pass
                    let measured = |j: u32| {
                        let j = j as usize;
                        (codes[row + j] == code::OK).then(|| unsafe { cols.read(row + j) })
                    };
                    let fill = match repair {
                        LocalRepair::None => f64::NAN,
                        LocalRepair::Zero => 0.0,
                        LocalRepair::LastValue => el.last,
                        LocalRepair::NeighbourMean(nb) => {
                            let (mut sum, mut count) = (0.0, 0u32);
                            for v in nb.of(i).iter().filter_map(|&j| measured(j)) {
                                sum += v;
                                count += 1;
                            }
                            if count > 0 {
                                sum / f64::from(count)
                            } else {
                                el.last
                            }
                        }
                        LocalRepair::Weighted(nb, w) => {
                            let (mut num, mut den) = (0.0, 0.0);
                            let lo = nb.start(i);
                            for (q, &j) in nb.of(i).iter().enumerate() {
                                if let Some(v) = measured(j) {
                                    num += w[lo + q] * v;
                                    den += w[lo + q];
                                }
                            }
                            if den > 0.0 {
                                num / den
                            } else {
                                el.last
                            }
                        }
                    };
                    if !matches!(repair, LocalRepair::None) && fill.is_finite() {
                        el.last = fill;
                    }
                    // SAFETY: a failed reading of this block's element: nobody else reads
                    // or writes it in this pass
                    unsafe { cols.write(row + i, fill) };
                }
            }
        };
        each_chunk(&mut self.elements, size, par, work);
    }
}
