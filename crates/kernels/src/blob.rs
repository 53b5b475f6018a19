//! The model blob a microcontroller runs: a mat's compiled chain in `f32`, versioned and
//! checksummed, read in place (from flash: nothing is copied to RAM).
//!
//! All fields are little-endian 4-byte words (`u32` or `f32`), so every array is 4-byte
//! aligned when the blob is. Layout, version [`VERSION`]:
//!
//! | offset | field |
//! |---:|---|
//! | 0 | magic `TXSNMCU\0` (8 bytes) |
//! | 8 | format version (`u32`) |
//! | 12 | total length in bytes, checksum included (`u32`) |
//! | 16 | number of elements N (`u32`) |
//! | 20 | number of stages (`u32`) |
//! | 24 | reserved, 0 (2 x `u32`) |
//! | 32 | the stages in order: kind (`u32`), payload length in words (`u32`), payload |
//! | length - 4 | CRC-32 (IEEE, as zlib's `crc32`) of every byte before it |
//!
//! Payloads (`[N]`: one per element; a *curve* is `points P`, `1 / bucket width`, `x[P]`,
//! `y[P]`, `slope[P - 1]`, `bucket_start[4P + 1]` (u32): [`crate::convert::Curve`]; a
//! *graph* is `nnz`, `indptr[N + 1]`, `indices[nnz]` (u32): [`crate::graph::Graph`]):
//!
//! | kind | stage | payload |
//! |---:|---|---|
//! | 1 | detect | `stuck_frames`, flags (1: baseline, 2: max), `min_pf`, `low_share`, `high_share`, `stuck_pf`, `neighbour_change_pf`, `stuck_floor_pf`, `jump[N]`, [`baseline[N]`], [`max[N]`], graph |
//! | 2 | convert / linear | flags (1: curve), `offset[N]`, `gain[N]`, [curve] |
//! | 3 | first-loading curve | curve |
//! | 4 | hysteresis | `K`, capacity, `u_min`, `u_max`, output offset, output sign, Everett table `[K x K]` |
//! | 5 | drift | terms `J`, flags (1: on the elastic response, a curve follows: QLV, right after a hysteresis stage), γ, `rest_rate`, `rest_window`, `gamma_time`, level power, `weights[J]`, `taus[J]`, [curve] |
//! | 6 | repair | method (0 zero, 1 last value, 2 neighbour mean (eq. 6.14), 3 weighted), [graph], [`weights[nnz]`] (3) |
//!
//! [`Model::parse`] checks everything a stage's kernel relies on (and the checksum), so a
//! blob that passes runs without a bounds failure; [`Model::parse_trusted`] re-reads a blob
//! that passed, without the checks that cost a pass over the arrays.

use crate::convert::{buckets, Curve};
use crate::detect::{self, Params};
use crate::drift::Settings;
use crate::error::KernelError;
use crate::everett::Everett;
use crate::graph::Graph;
use crate::preisach::Output;
use crate::repair::Method;

/// The first 8 bytes.
pub const MAGIC: [u8; 8] = *b"TXSNMCU\0";
/// The format version this build reads and writes.
pub const VERSION: u32 = 1;
/// Bytes of the header.
pub const HEADER_BYTES: usize = 32;
/// The most stages a blob may hold.
pub const MAX_STAGES: usize = 16;

/// Stage kinds.
pub mod kind {
    /// Failure detection.
    pub const DETECT: u32 = 1;
    /// Conversion (eq. 2.1, or linear).
    pub const CONVERT: u32 = 2;
    /// The first-loading curve.
    pub const LOADING: u32 = 3;
    /// Preisach hysteresis.
    pub const HYSTERESIS: u32 = 4;
    /// Drift.
    pub const DRIFT: u32 = 5;
    /// Local repair.
    pub const REPAIR: u32 = 6;
}

/// Repair methods in a blob.
pub mod repair_method {
    /// Zero.
    pub const ZERO: u32 = 0;
    /// Last value.
    pub const LAST_VALUE: u32 = 1;
    /// Neighbour mean (eq. 6.14).
    pub const NEIGHBOUR_MEAN: u32 = 2;
    /// Weighted mean.
    pub const WEIGHTED: u32 = 3;
}

/// Why a blob is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlobError {
    /// Not a model blob (the magic is wrong, or it is shorter than a header).
    Magic,
    /// A blob of another format version.
    Version(u32),
    /// The blob is not as long as its header says (cut short or padded).
    Length,
    /// The checksum does not match: the blob is damaged.
    Checksum,
    /// A stage's content is inconsistent (what, why).
    Format(KernelError),
    /// Not 4-byte aligned in memory.
    Alignment,
}

/// A stage as the blob holds it.
#[derive(Debug, Clone, Copy)]
pub enum StageView<'a> {
    /// Failure detection.
    Detect {
        /// The thresholds.
        params: Params<f32>,
        /// Per element: jump limit.
        jump: &'a [f32],
        /// Per element: unloaded reading.
        baseline: Option<&'a [f32]>,
        /// Per element: largest expected reading.
        max: Option<&'a [f32]>,
        /// Neighbours.
        graph: Graph<'a>,
    },
    /// Conversion.
    Convert {
        /// Per element offset.
        offset: &'a [f32],
        /// Per element gain.
        gain: &'a [f32],
        /// The material curve (None: linear).
        curve: Option<Curve<'a, f32>>,
    },
    /// The first-loading curve.
    Loading(Curve<'a, f32>),
    /// Preisach hysteresis.
    Hysteresis {
        /// The Everett function.
        everett: Everett<'a, f32>,
        /// Turning points kept per element.
        capacity: usize,
        /// Offset and sign of the output.
        output: Output<f32>,
    },
    /// Drift (with `level`: on the elastic response of the hysteresis stage's input).
    Drift {
        /// Kernel and options.
        settings: Settings<'a, f32>,
        /// The elastic response (QLV).
        level: Option<Curve<'a, f32>>,
    },
    /// A local repair.
    Repair(Method<'a, f32>),
}

impl StageView<'_> {
    /// True for the stages that work element by element (no neighbour of the same frame).
    pub fn is_elementwise(&self) -> bool {
        !matches!(self, StageView::Detect { .. } | StageView::Repair(_))
    }
}

/// A parsed blob.
#[derive(Debug, Clone, Copy)]
pub struct Model<'a> {
    n: usize,
    n_stages: usize,
    body: &'a [u32],
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in data {
        c = CRC_TABLE[((c ^ u32::from(b)) & 0xff) as usize] ^ (c >> 8);
    }
    !c
}

const CRC_TABLE: [u32; 256] = crc_table();

const fn crc_table() -> [u32; 256] {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
}

/// The words of a 4-byte aligned byte slice.
fn words(bytes: &[u8]) -> Result<&[u32], BlobError> {
    // SAFETY: every bit pattern is a valid u32; align_to only hands out aligned words
    let (head, w, tail) = unsafe { bytes.align_to::<u32>() };
    if !head.is_empty() || !tail.is_empty() {
        return Err(BlobError::Alignment);
    }
    Ok(w)
}

fn as_f32(w: &[u32]) -> &[f32] {
    // SAFETY: u32 and f32 have the same size and alignment, and every bit pattern is an f32
    unsafe { core::slice::from_raw_parts(w.as_ptr().cast::<f32>(), w.len()) }
}

/// A cursor over a stage's payload words.
struct Reader<'a> {
    w: &'a [u32],
    what: &'static str,
}

impl<'a> Reader<'a> {
    fn fail(&self, why: &'static str) -> BlobError {
        BlobError::Format(KernelError {
            what: self.what,
            why,
        })
    }

    fn u32s(&mut self, n: usize) -> Result<&'a [u32], BlobError> {
        if n > self.w.len() {
            return Err(self.fail("the payload is shorter than its arrays"));
        }
        let (a, b) = self.w.split_at(n);
        self.w = b;
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32, BlobError> {
        Ok(self.u32s(1)?[0])
    }

    fn f32s(&mut self, n: usize) -> Result<&'a [f32], BlobError> {
        Ok(as_f32(self.u32s(n)?))
    }

    fn f32(&mut self) -> Result<f32, BlobError> {
        Ok(f32::from_bits(self.u32()?))
    }

    fn curve(&mut self, full: bool) -> Result<Curve<'a, f32>, BlobError> {
        let p = self.u32()? as usize;
        if !(2..=1 << 24).contains(&p) {
            return Err(self.fail("a curve needs 2 ..= 2^24 points"));
        }
        let inv_width = self.f32()?;
        let (x, y) = (self.f32s(p)?, self.f32s(p)?);
        let slope = self.f32s(p - 1)?;
        let b = self.u32s(buckets(p) + 1)?;
        let what = self.what;
        if full
            && !(x.windows(2).all(|w| w[1] > w[0])
                && x.iter().chain(y).chain(slope).all(|v| v.is_finite()))
        {
            return Err(self.fail("a curve needs finite points with increasing x"));
        }
        let c = if full {
            Curve::new(x, y, slope, b, inv_width)
        } else {
            Curve::new_trusted(x, y, slope, b, inv_width)
        };
        c.map_err(|e| BlobError::Format(KernelError { what, ..e }))
    }

    fn graph(&mut self, n: usize, full: bool) -> Result<Graph<'a>, BlobError> {
        let nnz = self.u32()? as usize;
        let indptr = self.u32s(n + 1)?;
        let indices = self.u32s(nnz)?;
        if full {
            Graph::new(indptr, indices).map_err(BlobError::Format)
        } else if indptr.first() == Some(&0) && indptr[n] as usize == nnz {
            // trusted: only what keeps the views in bounds is re-checked by the kernels'
            // slices (a blob that passed the full check)
            Ok(Graph::new_trusted(indptr, indices))
        } else {
            Err(self.fail("the neighbour graph is inconsistent"))
        }
    }
}

impl<'a> Model<'a> {
    /// Parse and check a blob (4-byte aligned): header, version, length, checksum, and every
    /// stage's content. `Err` names what is wrong.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, BlobError> {
        let m = Self::header(bytes)?;
        let len = bytes.len();
        let stored = u32::from_le_bytes([
            bytes[len - 4],
            bytes[len - 3],
            bytes[len - 2],
            bytes[len - 1],
        ]);
        if crc32(&bytes[..len - 4]) != stored {
            return Err(BlobError::Checksum);
        }
        let mut count = 0;
        let mut prev_hysteresis = false;
        for s in m.walk(true) {
            let s = s?;
            if let StageView::Drift { level: Some(_), .. } = s {
                if !prev_hysteresis {
                    return Err(BlobError::Format(KernelError {
                        what: "drift",
                        why: "a drift on the elastic response must follow a hysteresis stage",
                    }));
                }
            }
            prev_hysteresis = matches!(s, StageView::Hysteresis { .. });
            count += 1;
        }
        debug_assert_eq!(count, m.n_stages);
        Ok(m)
    }

    /// Parse a blob that [`Model::parse`] accepted before (no checksum, no pass over the
    /// arrays; still no read outside the blob).
    pub fn parse_trusted(bytes: &'a [u8]) -> Result<Self, BlobError> {
        Self::header(bytes)
    }

    fn header(bytes: &'a [u8]) -> Result<Self, BlobError> {
        if bytes.len() < HEADER_BYTES + 4 || bytes[..8] != MAGIC {
            return Err(BlobError::Magic);
        }
        let w = words(bytes)?;
        if w[2] != VERSION {
            return Err(BlobError::Version(w[2]));
        }
        if w[3] as usize != bytes.len() {
            return Err(BlobError::Length);
        }
        let (n, n_stages) = (w[4] as usize, w[5] as usize);
        if n == 0 || n > 1 << 24 || n_stages == 0 || n_stages > MAX_STAGES {
            return Err(BlobError::Format(KernelError {
                what: "header",
                why: "needs 1 ..= 2^24 elements and 1 ..= 16 stages",
            }));
        }
        Ok(Self {
            n,
            n_stages,
            body: &w[HEADER_BYTES / 4..w.len() - 1],
        })
    }

    /// Number of elements.
    pub fn n_elements(&self) -> usize {
        self.n
    }

    /// Number of stages.
    pub fn n_stages(&self) -> usize {
        self.n_stages
    }

    /// The stages in order (each `Err` if inconsistent; a parsed blob has none).
    pub fn stages(&self) -> impl Iterator<Item = Result<StageView<'a>, BlobError>> {
        self.walk(false)
    }

    fn walk(&self, full: bool) -> impl Iterator<Item = Result<StageView<'a>, BlobError>> {
        let (n, mut rest, mut left) = (self.n, self.body, self.n_stages);
        core::iter::from_fn(move || {
            if left == 0 {
                return if rest.is_empty() {
                    None
                } else {
                    left = usize::MAX; // stop after this error
                    Some(Err(BlobError::Length))
                };
            }
            if left == usize::MAX {
                return None;
            }
            left -= 1;
            let r = (|| {
                if rest.len() < 2 || rest[1] as usize > rest.len() - 2 {
                    return Err(BlobError::Length);
                }
                let (k, words) = (rest[0], rest[1] as usize);
                let payload = &rest[2..2 + words];
                rest = &rest[2 + words..];
                stage(k, payload, n, full)
            })();
            if r.is_err() {
                left = usize::MAX;
            }
            Some(r)
        })
    }
}

fn stage(k: u32, payload: &[u32], n: usize, full: bool) -> Result<StageView<'_>, BlobError> {
    let what = match k {
        kind::DETECT => "detect",
        kind::CONVERT => "convert",
        kind::LOADING => "loading curve",
        kind::HYSTERESIS => "hysteresis",
        kind::DRIFT => "drift",
        kind::REPAIR => "repair",
        _ => {
            return Err(BlobError::Format(KernelError {
                what: "stage",
                why: "unknown stage kind",
            }))
        }
    };
    let mut r = Reader { w: payload, what };
    let view = match k {
        kind::DETECT => detect_view(&mut r, n, full)?,
        kind::CONVERT => convert_view(&mut r, n, full)?,
        kind::LOADING => StageView::Loading(r.curve(full)?),
        kind::HYSTERESIS => hysteresis_view(&mut r, full)?,
        kind::DRIFT => drift_view(&mut r, full)?,
        _ => repair_view(&mut r, n, full)?,
    };
    if !r.w.is_empty() {
        return Err(r.fail("the payload is longer than its arrays"));
    }
    Ok(view)
}

fn detect_view<'a>(r: &mut Reader<'a>, n: usize, full: bool) -> Result<StageView<'a>, BlobError> {
    let stuck_frames = r.u32()?;
    let flags = r.u32()?;
    let params = Params {
        min_pf: r.f32()?,
        low_share: r.f32()?,
        high_share: r.f32()?,
        stuck_frames,
        stuck_pf: r.f32()?,
        neighbour_change_pf: r.f32()?,
        stuck_floor_pf: r.f32()?,
    };
    params.check().map_err(BlobError::Format)?;
    let jump = r.f32s(n)?;
    let baseline = if flags & 1 != 0 {
        Some(r.f32s(n)?)
    } else {
        None
    };
    let max = if flags & 2 != 0 {
        Some(r.f32s(n)?)
    } else {
        None
    };
    let graph = r.graph(n, full)?;
    Ok(StageView::Detect {
        params,
        jump,
        baseline,
        max,
        graph,
    })
}

fn convert_view<'a>(r: &mut Reader<'a>, n: usize, full: bool) -> Result<StageView<'a>, BlobError> {
    let flags = r.u32()?;
    let (offset, gain) = (r.f32s(n)?, r.f32s(n)?);
    if full
        && !(offset.iter().all(|o| o.is_finite()) && gain.iter().all(|g| g.is_finite() && *g > 0.0))
    {
        return Err(r.fail("offsets must be finite and gains finite and > 0"));
    }
    let curve = if flags & 1 != 0 {
        Some(r.curve(full)?)
    } else {
        None
    };
    Ok(StageView::Convert {
        offset,
        gain,
        curve,
    })
}

fn hysteresis_view<'a>(r: &mut Reader<'a>, full: bool) -> Result<StageView<'a>, BlobError> {
    let k = r.u32()? as usize;
    let capacity = r.u32()? as usize;
    let (u_min, u_max) = (r.f32()?, r.f32()?);
    let output = Output {
        offset: r.f32()?,
        sign: r.f32()?,
    };
    if !(4..=1 << 16).contains(&capacity)
        || !output.offset.is_finite()
        || (output.sign != 1.0 && output.sign != -1.0)
        || k > 1 << 12
    {
        return Err(r.fail("needs capacity 4 ..= 65536, a finite offset, sign +-1, K <= 4096"));
    }
    let table = r.f32s(k * k)?;
    if full && !table.iter().all(|v| v.is_finite()) {
        return Err(r.fail("an Everett entry is not finite"));
    }
    Ok(StageView::Hysteresis {
        everett: Everett::new(k, u_min, u_max, table).map_err(BlobError::Format)?,
        capacity,
        output,
    })
}

fn drift_view<'a>(r: &mut Reader<'a>, full: bool) -> Result<StageView<'a>, BlobError> {
    let terms = r.u32()? as usize;
    let flags = r.u32()?;
    if !(1..=64).contains(&terms) {
        return Err(r.fail("needs 1 ..= 64 kernel terms"));
    }
    let (gamma, rest_rate, rest_window, gamma_time, exponent) =
        (r.f32()?, r.f32()?, r.f32()?, r.f32()?, r.f32()?);
    let (weights, taus) = (r.f32s(terms)?, r.f32s(terms)?);
    let settings = Settings::new(weights, taus, gamma)
        .and_then(|s| s.with_rest_rate(rest_rate, rest_window))
        .and_then(|s| s.with_time_component(gamma_time))
        .and_then(|s| s.with_exponent(exponent))
        .map_err(BlobError::Format)?;
    let level = if flags & 1 != 0 {
        Some(r.curve(full)?)
    } else {
        None
    };
    Ok(StageView::Drift { settings, level })
}

fn repair_view<'a>(r: &mut Reader<'a>, n: usize, full: bool) -> Result<StageView<'a>, BlobError> {
    let method = match r.u32()? {
        repair_method::ZERO => Method::Zero,
        repair_method::LAST_VALUE => Method::LastValue,
        repair_method::NEIGHBOUR_MEAN => Method::NeighbourMean(r.graph(n, full)?),
        repair_method::WEIGHTED => {
            let g = r.graph(n, full)?;
            Method::Weighted(g, r.f32s(g.nnz())?)
        }
        _ => return Err(r.fail("unknown repair method")),
    };
    if full {
        method.check(n).map_err(BlobError::Format)?;
    }
    Ok(StageView::Repair(method))
}

/// The failure codes a detector stage gives (re-exported for the C side).
pub use detect::codes;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_is_zlibs() {
        // the check value of CRC-32/ISO-HDLC (zlib.crc32(b"123456789"))
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn a_header_alone_is_refused_with_its_reason() {
        let mut b = [0u32; 10];
        let bytes =
            |w: &[u32]| -> std::vec::Vec<u8> { w.iter().flat_map(|x| x.to_le_bytes()).collect() };
        assert_eq!(Model::parse(&bytes(&b)).unwrap_err(), BlobError::Magic);
        b[0] = u32::from_le_bytes(*b"TXSN");
        b[1] = u32::from_le_bytes(*b"MCU\0");
        b[2] = 7;
        let v = bytes(&b);
        let w = words(&v);
        // a Vec<u8> is not necessarily 4-aligned: only check when it is
        if w.is_ok() {
            assert_eq!(Model::parse(&v).unwrap_err(), BlobError::Version(7));
        }
    }
}
