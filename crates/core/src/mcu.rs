//! The model blob of a microcontroller (`texsense_kernels::blob`, where its layout is
//! documented and read): a compiled [`Chain`] written in `f32`, versioned and checksummed.
//! `texsense export mcu` writes it; the C side (`texsense-mcu`) runs it.

use texsense_kernels::blob::{
    crc32, kind, repair_method, HEADER_BYTES, MAGIC, MAX_STAGES, VERSION,
};
use texsense_kernels::convert::{buckets, tables};

use crate::chain::{Chain, Stage};
use crate::convert::Curve;
use crate::detect::FailureDetector;
use crate::drift::DriftBank;
use crate::error::CoreError;
use crate::repair::{LocalRepair, Method};
use crate::topology::Neighbours;

/// Little-endian words of the blob being written.
#[derive(Default)]
struct Words {
    buf: Vec<u8>,
}

impl Words {
    fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn f32(&mut self, v: f64) {
        self.buf.extend_from_slice(&(v as f32).to_le_bytes());
    }

    fn f32s(&mut self, v: &[f64]) {
        v.iter().for_each(|&x| self.f32(x));
    }

    fn u32s(&mut self, v: &[u32]) {
        v.iter().for_each(|&x| self.u32(x));
    }

    /// A stage: its kind, its length in words, its payload.
    fn stage(&mut self, k: u32, payload: Words) {
        self.u32(k);
        self.u32((payload.buf.len() / 4) as u32);
        self.buf.extend_from_slice(&payload.buf);
    }

    fn curve(&mut self, c: &Curve, what: &'static str) -> Result<(), CoreError> {
        let (x, y) = c.points();
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let y32: Vec<f32> = y.iter().map(|&v| v as f32).collect();
        let mut slope = vec![0.0f32; x.len() - 1];
        let mut starts = vec![0u32; buckets(x.len()) + 1];
        let inv_width =
            tables(&x32, &y32, &mut slope, &mut starts).map_err(|e| CoreError::Parameter {
                what,
                why: format!(
                    "in float32: {} (points closer than float32 resolves?)",
                    e.why
                ),
            })?;
        self.u32(x.len() as u32);
        self.buf.extend_from_slice(&inv_width.to_le_bytes());
        for v in x32.iter().chain(&y32).chain(&slope) {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
        self.u32s(&starts);
        Ok(())
    }

    fn graph(&mut self, nb: &Neighbours) {
        self.u32(nb.nnz() as u32);
        self.u32s(nb.indptr());
        self.u32s(nb.indices());
    }
}

fn detect(d: &FailureDetector) -> Words {
    let (p, nb, jump, baseline, max) = d.parts();
    let mut w = Words::default();
    w.u32(p.stuck_frames);
    w.u32(u32::from(baseline.is_some()) | (u32::from(max.is_some()) << 1));
    for v in [
        p.min_pf,
        p.low_share,
        p.high_share,
        p.stuck_pf,
        p.neighbour_change_pf,
        p.stuck_floor_pf,
    ] {
        w.f32(v);
    }
    w.f32s(jump);
    baseline.into_iter().chain(max).for_each(|v| w.f32s(v));
    w.graph(nb);
    w
}

fn drift(d: &DriftBank, level: Option<&Curve>) -> Result<Words, CoreError> {
    let (gamma, rest_rate, rest_window, gamma_time, exponent) = d.options();
    let mut w = Words::default();
    w.u32(d.kernel().len() as u32);
    w.u32(u32::from(level.is_some()));
    for v in [gamma, rest_rate, rest_window, gamma_time, exponent] {
        w.f32(v);
    }
    w.f32s(d.kernel().weights());
    w.f32s(d.kernel().taus());
    if let Some(c) = level {
        w.curve(c, "drift level curve")?;
    }
    Ok(w)
}

fn repair(r: &LocalRepair) -> Words {
    let mut w = Words::default();
    match r.method() {
        Method::Zero => w.u32(repair_method::ZERO),
        Method::LastValue => w.u32(repair_method::LAST_VALUE),
        Method::NeighbourMean(nb) => {
            w.u32(repair_method::NEIGHBOUR_MEAN);
            w.graph(nb);
        }
        Method::Weighted(nb, weights) => {
            w.u32(repair_method::WEIGHTED);
            w.graph(nb);
            w.f32s(weights);
        }
    }
    w
}

impl Chain {
    /// The chain as the model blob of a microcontroller (`texsense_kernels::blob`): every
    /// parameter in `f32`; each element keeps as many Preisach turning points as here.
    pub fn mcu_blob(&self) -> Result<Vec<u8>, CoreError> {
        let mut body = Words::default();
        let mut count = 0;
        for s in self.stages() {
            match s {
                Stage::Detect(d) => body.stage(kind::DETECT, detect(d)),
                Stage::Convert(c) => {
                    let (offset, gain, curve) = c.parts();
                    let mut w = Words::default();
                    w.u32(u32::from(curve.is_some()));
                    w.f32s(offset);
                    w.f32s(gain);
                    if let Some(c) = curve {
                        w.curve(c, "material curve")?;
                    }
                    body.stage(kind::CONVERT, w);
                }
                Stage::Loading(c) => {
                    let mut w = Words::default();
                    w.curve(c, "first-loading curve")?;
                    body.stage(kind::LOADING, w);
                }
                Stage::Compensation(c) => {
                    let p = c.preisach();
                    let capacity = p.capacity();
                    if capacity > 1 << 16 {
                        return Err(CoreError::Parameter {
                            what: "capacity",
                            why: format!("a blob keeps <= 65536 turning points, not {capacity}"),
                        });
                    }
                    let e = p.everett();
                    let (offset, sign) = p.output();
                    let mut w = Words::default();
                    w.u32(e.size() as u32);
                    w.u32(capacity as u32);
                    for v in [e.u_min(), e.u_max(), offset, sign] {
                        w.f32(v);
                    }
                    w.f32s(e.table());
                    body.stage(kind::HYSTERESIS, w);
                    if let (Some(d), level) = c.drift() {
                        body.stage(kind::DRIFT, drift(d, level)?);
                        count += 1;
                    }
                }
                Stage::Drift(d) => body.stage(kind::DRIFT, drift(d, None)?),
                Stage::Repair(r) => body.stage(kind::REPAIR, repair(r)),
            }
            count += 1;
        }
        if count == 0 || count > MAX_STAGES {
            return Err(CoreError::Parameter {
                what: "chain",
                why: format!("a blob holds 1 ..= {MAX_STAGES} stages, the chain {count}"),
            });
        }
        let mut out = Words::default();
        out.buf.extend_from_slice(&MAGIC);
        out.u32(VERSION);
        out.u32((HEADER_BYTES + body.buf.len() + 4) as u32);
        out.u32(self.len() as u32);
        out.u32(count as u32);
        out.u32(0);
        out.u32(0);
        out.buf.extend_from_slice(&body.buf);
        let crc = crc32(&out.buf);
        out.u32(crc);
        Ok(out.buf)
    }
}

#[cfg(test)]
mod tests {
    use texsense_kernels::blob::{BlobError, Model, StageView};

    use crate::chain::tests::{usual, Mat};

    /// A blob in memory aligned to 4 bytes, as the C side requires.
    fn aligned(bytes: &[u8]) -> Vec<u32> {
        bytes
            .chunks(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    }

    fn as_bytes(w: &[u32]) -> &[u8] {
        // SAFETY: u32 words viewed as their bytes
        unsafe { std::slice::from_raw_parts(w.as_ptr().cast::<u8>(), w.len() * 4) }
    }

    #[test]
    fn the_blob_reads_back_the_chain_and_refuses_damage() {
        let mat = Mat { rows: 4, cols: 5 };
        let chain = usual(&mat);
        let blob = chain.mcu_blob().unwrap();
        assert_eq!(
            texsense_kernels::blob::crc32(&blob[..blob.len() - 4]).to_le_bytes(),
            blob[blob.len() - 4..]
        );
        let words = aligned(&blob);
        let m = Model::parse(as_bytes(&words)).unwrap();
        assert_eq!(m.n_elements(), 20);
        let kinds: Vec<&str> = m
            .stages()
            .map(|s| match s.unwrap() {
                StageView::Detect { .. } => "detect",
                StageView::Convert { curve, .. } => {
                    assert!(curve.is_some());
                    "convert"
                }
                StageView::Hysteresis { capacity, .. } => {
                    assert_eq!(capacity, 32);
                    "hysteresis"
                }
                StageView::Drift { level, .. } => {
                    assert!(level.is_none());
                    "drift"
                }
                StageView::Repair(_) => "repair",
                StageView::Loading(_) => "loading",
            })
            .collect();
        assert_eq!(
            kinds,
            ["detect", "convert", "hysteresis", "drift", "repair"]
        );
        // one flipped bit anywhere: refused (checksum, or the header's own checks)
        for at in [0, 9, 13, 40, blob.len() / 2, blob.len() - 1] {
            let mut bad = blob.clone();
            bad[at] ^= 0x10;
            let w = aligned(&bad);
            assert!(Model::parse(as_bytes(&w)).is_err(), "a flip at byte {at}");
        }
        let mut v2 = blob.clone();
        v2[8] = 2;
        let w = aligned(&v2);
        assert_eq!(
            Model::parse(as_bytes(&w)).unwrap_err(),
            BlobError::Version(2)
        );
        let cut = aligned(&blob[..blob.len() - 8]);
        assert!(Model::parse(as_bytes(&cut)).is_err());
    }
}
