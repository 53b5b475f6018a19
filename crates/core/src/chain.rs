//! A mat's chain of stages compiled: the stages' own kernels run one after the other, as
//! the chain file holds them, over a `T x N` block of frames (or one frame: `step` is the
//! same code with T = 1).
//!
//! A [`Stage`] is one of the kernels the Python stages run: [`FailureDetector`] (`detect`),
//! [`Converter`] (`convert` / `linear`), [`Compensation`] (`hysteresis`, or `hysteresis` and
//! the `drift` right after it, QLV included), [`DriftBank`] (a `drift` on its own), the
//! first-loading [`Curve`] (in place of `hysteresis`: an uncompensated system) and
//! [`LocalRepair`] (`repair`). Any order runs, with the rules of the stage contract
//! (`texsense.stage`): every reading carries a value and a validity; a stage that fails a
//! reading makes it invalid (it stays so: a repaired reading is filled but still invalid);
//! an invalid reading leaves the element's state untouched.
//!
//! The per-reading failure code (`codes`, 0 = valid) is the code of the first detect stage
//! that failed it; a reading that was invalid or not a number on input, or that a stage
//! made invalid, and that no detect stage coded is [`code::OUT_OF_RANGE`]. A value that is
//! not a number is never valid.
//!
//! Stages that work element by element (convert, compensation, drift, loading curve) run
//! as one pass per block of elements in parallel (no intermediate array); a detect or repair
//! stage, which reads the neighbours' readings of the same frame, is a pass of its own.

use crate::compensation::Compensation;
use crate::convert::{Converter, Curve};
use crate::detect::{code, Changes, FailureDetector};
use crate::drift::{check_time_steps, DriftBank};
use crate::error::{check_len, CoreError};
use crate::repair::LocalRepair;
use crate::snapshot::{Reader, Writer};
use texsense_kernels::blob::kind;

/// Element-samples per tile of frames in a batch (a float64 array of a tile is 1 MiB).
const TILE_SAMPLES: usize = 1 << 17;

/// A batch's arguments checked: its time steps, and its readings, validity, values and codes
/// (their lengths, in that order) each of `dt.len()` frames of `n` elements.
fn check_batch(dt: &[f64], n: usize, lens: [usize; 4]) -> Result<(), CoreError> {
    check_time_steps(dt)?;
    for (name, len) in ["readings", "valid", "out", "codes"].into_iter().zip(lens) {
        check_len(name, len, dt.len() * n)?;
    }
    Ok(())
}

/// A reading invalid on input that no detect stage has coded yet.
const UNSET: u8 = u8::MAX;

/// The first 8 bytes of a snapshot.
pub const SNAPSHOT_MAGIC: [u8; 8] = *b"TXSNSNAP";
/// The snapshot format this build writes and reads.
pub const SNAPSHOT_VERSION: u32 = 1;

/// One stage of a compiled chain.
#[derive(Debug, Clone)]
pub enum Stage {
    /// `detect`: failure codes; failed readings become invalid.
    Detect(FailureDetector),
    /// `convert` or `linear` (eq. 2.1).
    Convert(Converter),
    /// `hysteresis` (eq. 4.15-4.22), with the `drift` that follows it (eq. 5.8, QLV
    /// included) if any.
    Compensation(Compensation),
    /// A `drift` stage on its own (eq. 5.8).
    Drift(DriftBank),
    /// The first-loading curve in place of `hysteresis`.
    Loading(Curve),
    /// `repair` (eq. 6.14 and the other local methods).
    Repair(LocalRepair),
}

impl Stage {
    /// The stage's name, as the Python stages name theirs.
    pub fn name(&self) -> &'static str {
        match self {
            Stage::Detect(_) => "detect",
            Stage::Convert(_) => "convert",
            Stage::Compensation(_) => "hysteresis",
            Stage::Drift(_) => "drift",
            Stage::Loading(_) => "loading curve",
            Stage::Repair(_) => "repair",
        }
    }

    fn kind(&self) -> u32 {
        match self {
            Stage::Detect(_) => kind::DETECT,
            Stage::Convert(_) => kind::CONVERT,
            Stage::Compensation(_) => kind::HYSTERESIS,
            Stage::Drift(_) => kind::DRIFT,
            Stage::Loading(_) => kind::LOADING,
            Stage::Repair(_) => kind::REPAIR,
        }
    }

    /// Number of elements (None: a curve, the same for every element).
    fn len(&self) -> Option<usize> {
        match self {
            Stage::Detect(d) => Some(d.len()),
            Stage::Convert(c) => Some(c.len()),
            Stage::Compensation(c) => Some(c.len()),
            Stage::Drift(d) => Some(d.len()),
            Stage::Loading(_) => None,
            Stage::Repair(r) => Some(r.len()),
        }
    }

    fn elementwise(&self) -> bool {
        !matches!(self, Stage::Detect(_) | Stage::Repair(_))
    }

    fn reset(&mut self) {
        match self {
            Stage::Detect(d) => d.reset(),
            Stage::Compensation(c) => c.reset(),
            Stage::Drift(d) => d.reset(),
            Stage::Repair(r) => r.reset(),
            Stage::Convert(_) | Stage::Loading(_) => {}
        }
    }

    fn state_bytes_per_element(&self) -> usize {
        let f64s = std::mem::size_of::<f64>();
        match self {
            Stage::Detect(d) => d.state_bytes_per_element() + 3 * f64s,
            Stage::Convert(_) => 2 * f64s,
            Stage::Compensation(c) => c.state_bytes_per_element(),
            Stage::Drift(d) => d.state_bytes_per_element(),
            Stage::Loading(_) => 0,
            Stage::Repair(r) => r.state_bytes_per_element(),
        }
    }
}

/// The scratch of a batch (reused from one call to the next).
#[derive(Debug, Clone, Default)]
struct Scratch {
    values: Vec<f64>,
    changes: Changes,
    /// A tile of float32 readings widened, and its values before they are narrowed
    /// ([`Chain::run_f32`]).
    wide: (Vec<f64>, Vec<f64>),
}

/// The chain of one mat.
#[derive(Debug, Clone)]
pub struct Chain {
    n: usize,
    stages: Vec<Stage>,
    scratch: Scratch,
}

/// Where the values of a tile are between passes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum At {
    Readings,
    Out,
    Scratch,
}

impl Chain {
    /// Assemble a chain of `n` elements from its stages in order; every stage must have `n`
    /// elements.
    pub fn new(n: usize, stages: Vec<Stage>) -> Result<Self, CoreError> {
        for s in &stages {
            if let Some(len) = s.len() {
                check_len("stage elements", len, n)?;
            }
        }
        Ok(Self {
            n,
            stages,
            scratch: Scratch::default(),
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

    /// The stages in order.
    pub fn stages(&self) -> &[Stage] {
        &self.stages
    }

    /// Every stage back to its initial state.
    pub fn reset(&mut self) {
        self.stages.iter_mut().for_each(Stage::reset);
    }

    /// Bytes of state per element, all stages together (parameters per element included).
    pub fn state_bytes_per_element(&self) -> usize {
        self.stages.iter().map(Stage::state_bytes_per_element).sum()
    }

    /// A batch: time steps `dt` (T,), readings and their validity (T x N) -> values
    /// (T x N) and failure codes (T x N; 0 = valid).
    pub fn run(
        &mut self,
        dt: &[f64],
        readings: &[f64],
        valid: &[bool],
        out: &mut [f64],
        codes: &mut [u8],
    ) -> Result<(), CoreError> {
        let (n, t) = (self.len(), dt.len());
        check_batch(dt, n, [readings.len(), valid.len(), out.len(), codes.len()])?;
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

    /// [`Chain::run`] for float32 readings and values, as a recording stores them: each tile
    /// of frames is widened to float64 in the chain's scratch (exactly), runs as in `run`,
    /// and its values are rounded to float32 (to nearest, as numpy's `astype(np.float32)`),
    /// so they are `run`'s values rounded, bit for bit, without a float64 copy of the batch
    /// on the way in or out (issue 34, eleventh round).
    pub fn run_f32(
        &mut self,
        dt: &[f64],
        readings: &[f32],
        valid: &[bool],
        out: &mut [f32],
        codes: &mut [u8],
    ) -> Result<(), CoreError> {
        let (n, t) = (self.len(), dt.len());
        check_batch(dt, n, [readings.len(), valid.len(), out.len(), codes.len()])?;
        if n == 0 {
            return Ok(());
        }
        let tile = (TILE_SAMPLES / n).max(1);
        let (mut wide, mut values) = std::mem::take(&mut self.scratch.wide);
        let mut done = Ok(());
        for a in (0..t).step_by(tile) {
            let b = (a + tile).min(t);
            let rows = a * n..b * n;
            wide.clear();
            wide.extend(readings[rows.clone()].iter().map(|&r| f64::from(r)));
            values.resize(rows.len(), 0.0);
            let (v, c) = (&valid[rows.clone()], &mut codes[rows.clone()]);
            done = self.run_tile(&dt[a..b], &wide, v, &mut values, c);
            if done.is_err() {
                break;
            }
            for (o, &x) in out[rows].iter_mut().zip(&values) {
                *o = x as f32;
            }
        }
        self.scratch.wide = (wide, values);
        done
    }

    /// The passes over one tile of frames, stage after stage.
    fn run_tile(
        &mut self,
        dt: &[f64],
        readings: &[f64],
        valid: &[bool],
        out: &mut [f64],
        codes: &mut [u8],
    ) -> Result<(), CoreError> {
        let Self { n, stages, scratch } = self;
        let n = *n;
        scratch.values.resize(readings.len(), 0.0);
        let mut at = At::Readings;
        let mut k = 0;
        // the validity of every reading as codes: 0, or UNSET until a detect stage codes it
        // (a first detect stage codes every reading from the readings and their validity)
        let coded = matches!(stages.first(), Some(Stage::Detect(_)));
        if let Some(Stage::Detect(d)) = stages.first_mut() {
            d.run(readings, valid, codes, &mut scratch.changes)?;
            k = 1;
        } else {
            for ((c, &r), &v) in codes.iter_mut().zip(readings).zip(valid) {
                *c = if v && r.is_finite() { code::OK } else { UNSET };
            }
        }
        while k < stages.len() {
            if stages[k].elementwise() {
                let end = (k..stages.len())
                    .find(|&j| !stages[j].elementwise())
                    .unwrap_or(stages.len());
                let (src, dst, to): (&[f64], &mut [f64], At) = match at {
                    At::Readings => (readings, &mut *out, At::Out),
                    At::Out => (&*out, &mut scratch.values, At::Scratch),
                    At::Scratch => (&scratch.values, &mut *out, At::Out),
                };
                segment(n, &mut stages[k..end], dt, src, codes, dst);
                at = to;
                k = end;
                continue;
            }
            match &mut stages[k] {
                Stage::Detect(d) => {
                    let values = match at {
                        At::Readings => readings,
                        At::Out => &*out,
                        At::Scratch => &scratch.values,
                    };
                    d.run_on_codes(values, codes, UNSET, &mut scratch.changes)?;
                }
                Stage::Repair(r) => {
                    let values: &mut [f64] = match at {
                        At::Readings => {
                            out.copy_from_slice(readings);
                            at = At::Out;
                            &mut *out
                        }
                        At::Out => &mut *out,
                        At::Scratch => &mut scratch.values,
                    };
                    r.run_coded(values, codes, code::OK)?;
                }
                _ => unreachable!("element-wise stages run as a segment"),
            }
            k += 1;
        }
        match at {
            At::Readings => out.copy_from_slice(readings),
            At::Scratch => out.copy_from_slice(&scratch.values),
            At::Out => {}
        }
        if !coded {
            for c in codes.iter_mut() {
                if *c == UNSET {
                    *c = code::OUT_OF_RANGE;
                }
            }
        }
        Ok(())
    }

    /// The state of every stage as bytes (versioned): what [`Chain::restore`] takes, in this
    /// process or another, to continue the stream exactly where it stopped.
    pub fn snapshot(&self) -> Vec<u8> {
        let mut w = Writer::default();
        w.buf.extend_from_slice(&SNAPSHOT_MAGIC);
        w.u32(SNAPSHOT_VERSION);
        w.u32(self.n as u32);
        w.u32(self.stages.len() as u32);
        for s in &self.stages {
            w.u32(s.kind());
            match s {
                Stage::Detect(d) => d.save(&mut w),
                Stage::Compensation(c) => c.save(&mut w),
                Stage::Drift(d) => d.save(&mut w),
                Stage::Repair(r) => r.save(&mut w),
                Stage::Convert(_) | Stage::Loading(_) => {}
            }
        }
        w.buf
    }

    /// Continue from a [`Chain::snapshot`] of a chain of the same stages and sizes (all or
    /// nothing: on an error the state is unchanged).
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), CoreError> {
        if bytes.len() < 12 || bytes[..8] != SNAPSHOT_MAGIC {
            return Err(CoreError::Parameter {
                what: "snapshot",
                why: "not a texsense chain snapshot".into(),
            });
        }
        let mut r = Reader::new(&bytes[8..]);
        let version = r.u32()?;
        if version != SNAPSHOT_VERSION {
            return Err(CoreError::Parameter {
                what: "snapshot",
                why: format!("version {version}; this build reads version {SNAPSHOT_VERSION}"),
            });
        }
        r.expect("elements", self.n)?;
        r.expect("stages", self.stages.len())?;
        let mut stages = self.stages.clone();
        for (i, s) in stages.iter_mut().enumerate() {
            let k = r.u32()?;
            if k != s.kind() {
                return Err(CoreError::Parameter {
                    what: "snapshot",
                    why: format!("stage {}: the snapshot holds another kind of stage", i + 1),
                });
            }
            match s {
                Stage::Detect(d) => d.load(&mut r)?,
                Stage::Compensation(c) => c.load(&mut r)?,
                Stage::Drift(d) => d.load(&mut r)?,
                Stage::Repair(rep) => rep.load(&mut r)?,
                Stage::Convert(_) | Stage::Loading(_) => {}
            }
        }
        if !r.is_empty() {
            return Err(r.error("bytes left over after the last stage"));
        }
        self.stages = stages;
        Ok(())
    }
}

mod segment;
use segment::segment;

#[cfg(test)]
pub(crate) mod tests;
