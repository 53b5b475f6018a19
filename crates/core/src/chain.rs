//! The whole capacitance-to-pressure chain of a mat in one compiled pass over a `T x N` block:
//! failure detection -> conversion -> Preisach + drift (or the first-loading curve) -> local
//! repair of failed readings. Every stage is the kernel the stage uses on its own
//! ([`FailureDetector`], [`Converter`], [`Compensation`], [`LocalRepair`]): the chain only
//! runs them one after the other, so it gives the numbers of the stages run in turn.
//!
//! - **detect**: [`FailureDetector`]; without it a reading fails when the converter flagged
//!   it or it is not a number;
//! - **convert** (eq. 2.1 per element): [`Converter`];
//! - **respond**: [`Compensation`] (eq. 4.15-4.22 and 5.8), or without hysteresis the
//!   first-loading curve `p(e)`, or nothing (a linear calibration); failed readings are NaN
//!   and leave the states untouched;
//! - **repair** (thesis §6.5.2.5): [`LocalRepair`] of the readings that failed (code != 0).
//!
//! Conversion and response run in one pass per block of elements (no intermediate array);
//! `step` is the same code with T = 1.

use crate::compensation::Compensation;
use crate::convert::{Converter, Curve};
use crate::detect::{code, Changes, FailureDetector};
use crate::drift::check_time_steps;
use crate::error::{check_len, CoreError};
use crate::par::{block_size, run_frames, FrameBlock};
use crate::repair::LocalRepair;

/// Element-samples per tile of frames in a batch (a float64 array of a tile is 1 MiB).
const TILE_SAMPLES: usize = 1 << 17;

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

/// The chain of one mat.
#[derive(Debug, Clone)]
pub struct Chain {
    detector: Option<FailureDetector>,
    converter: Converter,
    response: Response,
    repair: Option<LocalRepair>,
    changes: Changes,
}

impl Chain {
    /// Assemble a chain; every stage must have the same number of elements.
    pub fn new(
        detector: Option<FailureDetector>,
        converter: Converter,
        response: Response,
        repair: Option<LocalRepair>,
    ) -> Result<Self, CoreError> {
        let n = converter.len();
        if let Some(d) = &detector {
            check_len("detector elements", d.len(), n)?;
        }
        if let Response::Compensation(c) = &response {
            check_len("compensation elements", c.len(), n)?;
        }
        if let Some(r) = &repair {
            check_len("repair elements", r.len(), n)?;
        }
        Ok(Self {
            detector,
            converter,
            response,
            repair,
            changes: Changes::default(),
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.converter.len()
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.converter.is_empty()
    }

    /// Every stage back to its initial state.
    pub fn reset(&mut self) {
        if let Some(d) = &mut self.detector {
            d.reset();
        }
        if let Response::Compensation(c) = &mut self.response {
            c.reset();
        }
        if let Some(r) = &mut self.repair {
            r.reset();
        }
    }

    /// Bytes of state per element, all stages together (parameters per element included).
    pub fn state_bytes_per_element(&self) -> usize {
        let f64s = std::mem::size_of::<f64>();
        let response = match &self.response {
            Response::Compensation(c) => c.state_bytes_per_element(),
            Response::Loading(_) | Response::Direct => 0,
        };
        2 * f64s // offset, gain
            + self
                .detector
                .as_ref()
                .map_or(0, |d| d.state_bytes_per_element() + 3 * f64s)
            + response
            + self
                .repair
                .as_ref()
                .map_or(0, LocalRepair::state_bytes_per_element)
    }

    /// A batch: time steps `dt` (T,), readings and the converter's validity (T x N) ->
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
        check_time_steps(dt)?;
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
        self.respond(dt, readings, codes, out);
        if let Some(r) = &mut self.repair {
            r.run(out, |idx| codes[idx] == code::OK, None)?;
        }
        Ok(())
    }

    /// Conversion and response of every measured reading, NaN for the failed ones.
    fn respond(&mut self, dt: &[f64], readings: &[f64], codes: &[u8], out: &mut [f64]) {
        let n = self.len();
        let conv = &self.converter;
        let input =
            |idx: usize, i: usize| (codes[idx] == code::OK).then(|| conv.at(i, readings[idx]));
        match &mut self.response {
            Response::Compensation(comp) => run_frames(out, n, comp.blocks(), dt, input),
            Response::Loading(curve) => {
                let blocks = vec![Static(Some(curve)); n.div_ceil(block_size(n))];
                run_frames(out, n, blocks, dt, input);
            }
            Response::Direct => {
                let blocks = vec![Static(None); n.div_ceil(block_size(n))];
                run_frames(out, n, blocks, dt, input);
            }
        }
    }
}

/// A response without state: the first-loading curve, or the value itself.
#[derive(Clone, Copy)]
struct Static<'a>(Option<&'a Curve>);

impl FrameBlock for Static<'_> {
    #[inline]
    fn step(&mut self, _i: usize, _dt: f64, x: f64, valid: bool) -> f64 {
        match (valid, self.0) {
            (false, _) => f64::NAN,
            (true, Some(curve)) => curve.at(x),
            (true, None) => x,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::DetectorParams;
    use crate::drift::{DriftBank, Kernel};
    use crate::preisach::PreisachBank;
    use crate::repair::Method;
    use crate::topology::Neighbours;

    /// A tiny pseudo-random sequence in [0, 1) (tests need no extra crate).
    fn noise(k: usize) -> f64 {
        let x = (k as u64 + 1).wrapping_mul(6_364_136_223_846_793_005);
        ((x >> 11) % 1_000_000) as f64 / 1e6
    }

    struct Mat {
        rows: usize,
        cols: usize,
    }

    impl Mat {
        fn n(&self) -> usize {
            self.rows * self.cols
        }

        fn converter(&self) -> Converter {
            let n = self.n();
            let curve = Curve::new(vec![10.0, 11.0, 12.5, 15.0], vec![0.0, 0.8, 1.6, 2.4]).unwrap();
            let offset = (0..n).map(|i| 0.1 * noise(i)).collect();
            let gain = (0..n).map(|i| 0.9 + 0.2 * noise(i + 99)).collect();
            Converter::new(offset, gain, Some(curve)).unwrap()
        }

        fn detector(&self) -> FailureDetector {
            let n = self.n();
            let params = DetectorParams {
                min_pf: 0.05,
                low_share: 0.5,
                high_share: 1.2,
                stuck_frames: 5,
                stuck_pf: 1e-4,
                neighbour_change_pf: 0.05,
                stuck_floor_pf: f64::NEG_INFINITY,
            };
            let nb = Neighbours::grid4(self.rows, self.cols);
            FailureDetector::new(
                params,
                nb,
                vec![3.0; n],
                Some(vec![10.0; n]),
                Some(vec![15.0; n]),
            )
            .unwrap()
        }

        fn compensation(&self, drift: bool) -> Compensation {
            let e = crate::everett::quadratic(21, 2.4);
            let p = PreisachBank::new(e, self.n(), 32)
                .and_then(|p| p.with_output(0.1, 1.0))
                .unwrap();
            let kernel = Kernel::new(vec![0.5, 0.5], vec![1.0, 100.0]).unwrap();
            let d = drift.then(|| DriftBank::new(kernel, -0.025, self.n()).unwrap());
            Compensation::new(p, d).unwrap()
        }

        fn repair(&self, which: usize) -> Option<LocalRepair> {
            let nb = Neighbours::grid4(self.rows, self.cols);
            let w = vec![1.0; nb.nnz()];
            let method = match which {
                0 => return None,
                1 => Method::Zero,
                2 => Method::LastValue,
                3 => Method::NeighbourMean(nb),
                _ => Method::Weighted(nb, w),
            };
            Some(LocalRepair::new(method, self.n()).unwrap())
        }

        /// Readings (pF) of `t` frames with shorts, saturated and NaN readings.
        fn readings(&self, t: usize) -> (Vec<f64>, Vec<bool>, Vec<f64>) {
            let n = self.n();
            let mut r: Vec<f64> = (0..t * n)
                .map(|k| 10.5 + 3.0 * noise(k) * (1.0 + ((k / n) as f64 / 7.0).sin()) / 2.0)
                .collect();
            let valid: Vec<bool> = (0..t * n).map(|k| noise(k + 7) > 0.03).collect();
            for (k, v) in r.iter_mut().enumerate() {
                if noise(k + 3) < 0.03 {
                    *v = 0.0;
                } else if noise(k + 5) < 0.01 {
                    *v = f64::NAN;
                }
            }
            let dt = (0..t).map(|k| if k == 0 { 0.0 } else { 0.1 }).collect();
            (r, valid, dt)
        }
    }

    fn run(chain: &mut Chain, dt: &[f64], r: &[f64], v: &[bool]) -> (Vec<f64>, Vec<u8>) {
        let mut out = vec![0.0; r.len()];
        let mut codes = vec![0; r.len()];
        chain.run(dt, r, v, &mut out, &mut codes).unwrap();
        (out, codes)
    }

    fn same(a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len());
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            assert_eq!(x.to_bits(), y.to_bits(), "sample {k}: {x} vs {y}");
        }
    }

    #[test]
    fn the_chain_equals_its_stages_run_one_after_the_other() {
        let mat = Mat { rows: 5, cols: 6 };
        let n = mat.n();
        let (r, v, dt) = mat.readings(60);
        let loading = Curve::new(vec![0.0, 1.0, 2.4], vec![0.0, 0.5, 3.0]).unwrap();
        for response in 0..4 {
            for repair in 0..5 {
                let resp = match response {
                    0 => Response::Compensation(mat.compensation(true)),
                    1 => Response::Compensation(mat.compensation(false)),
                    2 => Response::Loading(loading.clone()),
                    _ => Response::Direct,
                };
                let mut chain = Chain::new(
                    Some(mat.detector()),
                    mat.converter(),
                    resp.clone(),
                    mat.repair(repair),
                )
                .unwrap();
                let (got, codes) = run(&mut chain, &dt, &r, &v);
                // the same kernels, one after the other
                let mut expected_codes = vec![0; r.len()];
                mat.detector()
                    .run(&r, &v, &mut expected_codes, &mut Changes::default())
                    .unwrap();
                assert_eq!(codes, expected_codes);
                let ok: Vec<bool> = codes.iter().map(|&c| c == code::OK).collect();
                let mut e = vec![0.0; r.len()];
                mat.converter().run(&r, &ok, &mut e).unwrap();
                let mut p = vec![0.0; r.len()];
                match resp {
                    Response::Compensation(mut c) => c.run(&dt, &e, &ok, &mut p).unwrap(),
                    Response::Loading(c) => {
                        p.iter_mut().zip(&e).for_each(|(p, &e)| *p = c.at(e));
                    }
                    Response::Direct => p.copy_from_slice(&e),
                }
                if let Some(mut rep) = mat.repair(repair) {
                    rep.run(&mut p, |i| ok[i], None).unwrap();
                }
                same(&got, &p);
                assert!(codes.iter().any(|&c| c != 0) && ok.iter().filter(|&&o| o).count() > n);
            }
        }
    }

    #[test]
    fn streaming_equals_batch_also_on_a_large_mat_in_parallel_blocks() {
        for mat in [Mat { rows: 4, cols: 6 }, Mat { rows: 64, cols: 64 }] {
            let n = mat.n();
            let t = 12;
            let (r, v, dt) = mat.readings(t);
            let make = || {
                Chain::new(
                    Some(mat.detector()),
                    mat.converter(),
                    Response::Compensation(mat.compensation(true)),
                    mat.repair(3),
                )
                .unwrap()
            };
            let (batch, codes) = run(&mut make(), &dt, &r, &v);
            let mut stream = make();
            for k in 0..t {
                let rows = k * n..(k + 1) * n;
                let (out, c) = run(&mut stream, &dt[k..=k], &r[rows.clone()], &v[rows.clone()]);
                same(&out, &batch[rows.clone()]);
                assert_eq!(c, &codes[rows]);
            }
        }
    }

    #[test]
    fn a_failed_reading_leaves_the_element_as_if_it_had_not_been_read() {
        let mat = Mat { rows: 3, cols: 4 };
        let n = mat.n();
        let t = 40;
        let r: Vec<f64> = (0..t * n).map(|k| 10.2 + 4.0 * noise(k)).collect();
        let dt: Vec<f64> = (0..t).map(|k| if k == 0 { 0.0 } else { 0.5 }).collect();
        let mut v = vec![true; t * n];
        for k in 10..20 {
            v[k * n + 5] = false;
        }
        let make = || {
            let resp = Response::Compensation(mat.compensation(true));
            Chain::new(None, mat.converter(), resp, None).unwrap()
        };
        let (with_gap, codes) = run(&mut make(), &dt, &r, &v);
        assert!((10..20).all(|k| with_gap[k * n + 5].is_nan() && codes[k * n + 5] != 0));
        // element 5 alone, without the failed frames (their time added to the next step)
        let keep: Vec<usize> = (0..t).filter(|k| !(10..20).contains(k)).collect();
        let r2: Vec<f64> = keep
            .iter()
            .flat_map(|&k| r[k * n..(k + 1) * n].to_vec())
            .collect();
        let mut dt2: Vec<f64> = keep.iter().map(|&k| dt[k]).collect();
        dt2[10] += 10.0 * 0.5;
        let (without, _) = run(&mut make(), &dt2, &r2, &vec![true; r2.len()]);
        for (j, &k) in keep.iter().enumerate() {
            let (a, b) = (with_gap[k * n + 5], without[j * n + 5]);
            assert!(
                (a - b).abs() <= 1e-12 * b.abs().max(1.0),
                "frame {k}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn bad_shapes_and_time_steps_are_errors() {
        let mat = Mat { rows: 2, cols: 3 };
        let small = Mat { rows: 2, cols: 2 };
        let e = Chain::new(
            Some(small.detector()),
            mat.converter(),
            Response::Direct,
            None,
        );
        assert!(matches!(e, Err(CoreError::Shape { .. })));
        let e = Chain::new(None, mat.converter(), Response::Direct, small.repair(3));
        assert!(matches!(e, Err(CoreError::Shape { .. })));
        let mut chain = Chain::new(None, mat.converter(), Response::Direct, None).unwrap();
        let (mut out, mut codes) = (vec![0.0; 12], vec![0; 12]);
        let e = chain.run(&[0.0, -1.0], &[10.0; 12], &[true; 12], &mut out, &mut codes);
        assert!(matches!(e, Err(CoreError::Parameter { what: "dt", .. })));
        let e = chain.run(&[0.0, 1.0], &[10.0; 11], &[true; 12], &mut out, &mut codes);
        assert!(matches!(
            e,
            Err(CoreError::Shape {
                what: "readings",
                ..
            })
        ));
    }

    #[test]
    fn the_curve_interpolates_as_a_binary_search_does() {
        let x: Vec<f64> = (0..50).map(|k| (k as f64).powf(1.3) + noise(k)).collect();
        let y: Vec<f64> = x.iter().map(|v| v.sqrt()).collect();
        let curve = Curve::new(x.clone(), y.clone()).unwrap();
        let reference = |v: f64| {
            if v.is_nan() {
                return f64::NAN;
            }
            if v <= x[0] {
                return y[0];
            }
            if v >= x[49] {
                return y[49];
            }
            let j = x.partition_point(|&xi| xi <= v) - 1;
            if x[j] == v {
                return y[j];
            }
            (y[j + 1] - y[j]) / (x[j + 1] - x[j]) * (v - x[j]) + y[j]
        };
        let probes = (0..2000)
            .map(|k| -5.0 + 180.0 * noise(k))
            .chain(x.iter().copied())
            .chain([f64::NAN, f64::INFINITY, f64::NEG_INFINITY]);
        for v in probes {
            let (a, b) = (curve.at(v), reference(v));
            assert!(a.to_bits() == b.to_bits(), "at {v}: {a} vs {b}");
        }
        assert!(Curve::new(vec![0.0, 0.0], vec![1.0, 2.0]).is_err());
    }
}
