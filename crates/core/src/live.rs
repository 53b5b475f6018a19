//! The per-frame arithmetic a live mat runs around its compiled chain, each in one pass over
//! the elements, with the same operations in the same order as the numpy code it stands in for
//! (that code stays the reference: the results are the same to the bit, tested from Python):
//!
//! - [`frame_bounds`]: every value's bound of one frame
//!   (`texsense.compensation.intervals.bounds`: `σ = a(v) + |v| (d + R·repaired) + excess`,
//!   the half-width `m σ` with the multiplier of the value's band);
//! - [`Motion`]: the in-use drift estimator's test of an empty mat and of movement between two
//!   frames (`InUseDrift.step` and `_moved`: the load change summed over blocks of elements);
//! - [`exposure_advance`]: the exposure tracker's step of every element
//!   (`ExposureTracker.step` and `_advance`: time above the threshold grows while loaded, a
//!   relief of the offload time resets it; thesis §1.1);
//! - [`first_off_scale`]: the first of a frame's element times that no clock has
//!   (`texsense.data.times.off_scale`, the door of every live frame).
//!
//! Sums of many values are numpy's pairwise sums ([`pairwise_sum`]), so that a comparison of a
//! sum with a threshold comes out as numpy's does.

/// The index of the first time in `t` that is not a number or lies beyond `limit` in size
/// (`!(|t| <= limit)`, the test of `texsense.data.times.off_scale`), or None.
pub fn first_off_scale(t: &[f64], limit: f64) -> Option<usize> {
    // whole chunks tested without an early exit (the loop vectorises), then the chunk found
    const CHUNK: usize = 64;
    let off = |v: f64| v.is_nan() || v.abs() > limit;
    let mut start = 0;
    for chunk in t.chunks(CHUNK) {
        let found = chunk.iter().fold(false, |any, &v| any | off(v));
        if found {
            return chunk.iter().position(|&v| off(v)).map(|i| start + i);
        }
        start += chunk.len();
    }
    None
}

/// `numpy.add.reduce` of a contiguous float64 array: pairwise summation in blocks of at most
/// 128 values, each summed in eight interleaved partial sums.
pub fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        return a.iter().fold(0.0, |s, &v| s + v);
    }
    if n <= 128 {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let whole = n - n % 8;
        let mut i = 8;
        while i < whole {
            for (j, rj) in r.iter_mut().enumerate() {
                *rj += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for &v in &a[whole..] {
            res += v;
        }
        return res;
    }
    let mut half = n / 2;
    half -= half % 8;
    pairwise_sum(&a[..half]) + pairwise_sum(&a[half..])
}

/// `numpy.searchsorted(edges, v, side="right") - 1`, at least 0: the band of a magnitude
/// (NaN sorts after every edge: the last band).
fn band(edges: &[f64], v: f64) -> usize {
    let k = if v.is_nan() {
        edges.len()
    } else {
        edges.partition_point(|&e| e <= v)
    };
    k.saturating_sub(1)
}

/// What [`frame_bounds`] reads besides the frame: the held-out scale per band (`edges`,
/// `scale`), the conformal multiplier per band (`mult_edges`, `mult`) or one for every value
/// (`multiplier`), the relative uncertainty of a repaired value and the calibration's range.
#[derive(Debug, Clone, Copy)]
pub struct BoundsOf<'a> {
    pub edges: &'a [f64],
    pub scale: &'a [f64],
    pub mult_edges: &'a [f64],
    pub mult: &'a [f64],
    pub multiplier: Option<f64>,
    pub r_repaired: f64,
    pub range_max: Option<f64>,
}

/// The lower and upper bounds of one frame `v` (`ok`: measured, else repaired) with the drift
/// share `drift` (`intervals.drift_share`); `None` when the lengths or tables do not fit.
pub fn frame_bounds(
    v: &[f64],
    ok: &[bool],
    drift: f64,
    of: &BoundsOf<'_>,
    lower: &mut [f64],
    upper: &mut [f64],
) -> Option<()> {
    let n = v.len();
    let fits = ok.len() == n && lower.len() == n && upper.len() == n;
    let tables = of.edges.len() == of.scale.len() && !of.edges.is_empty();
    let mults = of.multiplier.is_some() || (of.mult_edges.len() == of.mult.len());
    if !(fits && tables && mults && (of.multiplier.is_some() || !of.mult.is_empty())) {
        return None;
    }
    for i in 0..n {
        let x = v[i];
        let a = x.abs();
        let mut sigma = of.scale[band(of.edges, a)] + a * drift;
        let rep = if ok[i] { 0.0 } else { 1.0 };
        sigma += of.r_repaired * a * rep;
        if let Some(top) = of.range_max {
            let beyond = x - top;
            // np.maximum: NaN propagates
            sigma += if beyond.is_nan() {
                beyond
            } else {
                beyond.max(0.0)
            };
        }
        let m = match of.multiplier {
            Some(m) => m,
            None => of.mult[band(of.mult_edges, a)],
        };
        let hw = m * sigma;
        lower[i] = x - hw;
        upper[i] = x + hw;
    }
    Some(())
}

/// What the in-use estimator's test of a frame found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// At most the empty count of measured elements above the empty threshold.
    Empty,
    /// The load moved by more than the motion share (or there is no frame before it).
    Moved,
    /// Still since the frame before.
    Still,
}

/// The in-use estimator's movement test, with the last frame it saw (`InUseDrift._moved`).
#[derive(Debug, Clone)]
pub struct Motion {
    block: Vec<usize>,
    area: Vec<f64>,
    sums: Vec<f64>,
    prev: Option<(Vec<f64>, Vec<f64>)>,
    scratch: Vec<f64>,
}

/// The thresholds of [`Motion::step`]: the empty threshold and count, the smallest load a
/// movement is judged against (N) and the motion share.
#[derive(Debug, Clone, Copy)]
pub struct MotionLimits {
    pub empty: f64,
    pub empty_count: usize,
    pub floor: f64,
    pub motion: f64,
}

impl Motion {
    /// `block[i]`: the block of element `i` (blocks numbered from 0); `area` per element (cm²).
    /// `None` when the lengths differ.
    pub fn new(block: &[usize], area: &[f64]) -> Option<Self> {
        if block.len() != area.len() {
            return None;
        }
        let n_blocks = block.iter().map(|&b| b + 1).max().unwrap_or(0);
        Some(Self {
            block: block.to_vec(),
            area: area.to_vec(),
            sums: vec![0.0; n_blocks],
            prev: None,
            scratch: vec![0.0; n_blocks],
        })
    }

    /// The number of elements.
    pub fn len(&self) -> usize {
        self.area.len()
    }

    /// True for a layout without elements.
    pub fn is_empty(&self) -> bool {
        self.area.is_empty()
    }

    /// Forget the last frame (an empty mat, a new stream).
    pub fn forget(&mut self) {
        self.prev = None;
    }

    /// One frame `x` (finite) with its `gain` and measured mask: `c = x · gain` into `c`, then
    /// whether the mat is empty, else whether the load moved since the last frame (which is
    /// then this one: a value not measured keeps the last one's). `None` when lengths differ.
    pub fn step(
        &mut self,
        x: &[f64],
        gain: &[f64],
        ok: &[bool],
        limits: MotionLimits,
        c: &mut [f64],
    ) -> Option<Verdict> {
        let n = self.len();
        if x.len() != n || gain.len() != n || ok.len() != n || c.len() != n {
            return None;
        }
        let mut loaded = 0usize;
        for i in 0..n {
            c[i] = x[i] * gain[i];
            loaded += usize::from(c[i] > limits.empty && ok[i]);
        }
        if loaded <= limits.empty_count {
            return Some(Verdict::Empty);
        }
        self.sums.iter_mut().for_each(|s| *s = 0.0);
        let (mut last, last_sums) = match self.prev.take() {
            Some((v, s)) => (v, Some(s)),
            None => (vec![0.0; n], None),
        };
        let had = last_sums.is_some();
        for i in 0..n {
            let v = if had && !ok[i] { last[i] } else { c[i] };
            last[i] = v;
            self.sums[self.block[i]] += self.area[i] * v;
        }
        let moved = match last_sums {
            None => true,
            Some(before) => {
                self.scratch
                    .iter_mut()
                    .zip(&self.sums)
                    .for_each(|(d, s)| *d = s.abs());
                let total = pairwise_sum(&self.scratch);
                let scale = if limits.floor > total {
                    limits.floor
                } else {
                    total
                };
                for ((d, s), b) in self.scratch.iter_mut().zip(&self.sums).zip(&before) {
                    *d = (s - b).abs();
                }
                pairwise_sum(&self.scratch) > limits.motion * scale
            }
        };
        self.prev = Some((last, self.sums.clone()));
        Some(if moved {
            Verdict::Moved
        } else {
            Verdict::Still
        })
    }
}

/// The exposure tracker's per-element state: time above the threshold and time below it (s),
/// whether each was loaded at the last step, and with bounds the elements above the threshold
/// with the bounds' confidence and those only possibly above it.
#[derive(Debug)]
pub struct Exposure<'a> {
    pub exposure: &'a mut [f64],
    pub relief: &'a mut [f64],
    pub loaded_last: &'a mut [bool],
    pub confident: &'a mut [bool],
    pub possible: &'a mut [bool],
}

/// The tracker's settings for [`exposure_advance`].
#[derive(Debug, Clone, Copy)]
pub struct ExposureRule {
    pub threshold: f64,
    pub count_possible: bool,
    pub offload_s: f64,
    pub reposition_s: f64,
}

/// What one step left: whether any element is loaded, how many have reached the reposition
/// time, and the largest exposure (s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExposureStep {
    pub any_loaded: bool,
    pub over: usize,
    pub top: f64,
}

/// `_advance` of one element: `dt` in the state `loaded` (selects, not branches: the states of
/// a mat's elements follow no pattern a branch predictor learns).
#[inline(always)]
fn advance(e: &mut f64, r: &mut f64, loaded: bool, dt: f64, offload_s: f64) {
    let grown = *e + dt;
    let rested = *r + dt;
    let e1 = if loaded { grown } else { *e };
    let r1 = if loaded { 0.0 } else { rested };
    *r = r1;
    *e = if r1 >= offload_s { 0.0 } else { e1 };
}

/// One step of the tracker over `dt` s with the pressure `p` (NaN: unloaded) and, with bounds,
/// their lower and upper maps; `skipped`: frames since the last step were not read (a station
/// behind, a takeover, frames lost on the way), so the time between the two frames read is not
/// known: it counts as loaded for an element loaded at either of them, never as relief (an
/// alert is never later than reading every frame would raise it, but for the frames not read).
/// `None` when the lengths differ.
pub fn exposure_advance(
    p: &[f64],
    bounds: Option<(&[f64], &[f64])>,
    rule: ExposureRule,
    dt: f64,
    skipped: bool,
    st: Exposure<'_>,
) -> Option<ExposureStep> {
    let n = p.len();
    let lens = [st.exposure.len(), st.relief.len(), st.loaded_last.len()];
    let bl = bounds.is_none_or(|(lo, hi)| lo.len() == n && hi.len() == n);
    let flags = st.confident.len() == n && st.possible.len() == n;
    if lens.iter().any(|&k| k != n) || !bl || !flags {
        return None;
    }
    // (NaN > threshold is false: a missing reading is unloaded, as numpy's NaN -> 0)
    let thr = rule.threshold;
    if let Some((lo, hi)) = bounds {
        for i in 0..n {
            let sure = lo[i] > thr;
            let maybe = (hi[i] > thr) & !sure;
            st.confident[i] = sure;
            st.possible[i] = maybe;
        }
    }
    let (mut any_loaded, mut over, mut top, mut nan) = (false, 0usize, f64::NEG_INFINITY, false);
    for (i, &pi) in p.iter().enumerate() {
        let now = match bounds {
            None => pi > thr,
            Some(_) => st.confident[i] | (st.possible[i] & rule.count_possible),
        };
        let unseen_load = skipped & st.loaded_last[i];
        let (e, r) = (&mut st.exposure[i], &mut st.relief[i]);
        advance(e, r, now | unseen_load, dt, rule.offload_s);
        st.loaded_last[i] = now;
        any_loaded |= now;
        over += usize::from(*e >= rule.reposition_s);
        nan |= e.is_nan();
        top = top.max(*e);
    }
    if nan {
        top = f64::NAN;
    }
    Some(ExposureStep {
        any_loaded,
        over,
        top,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values whose sum depends on the order of the additions: numpy's sums (printed by
    /// `np.sum` of the same arrays) against a plain running sum.
    #[test]
    fn pairwise_sum_is_numpys() {
        let mut a = vec![1e16];
        a.extend([1.0; 20]);
        a.push(-1e16);
        a.extend([3.5; 9]);
        a.extend([1e-3; 100]);
        a.extend([2f64.powi(60), -(2f64.powi(60))]);
        a.extend([0.1; 7]);
        assert_eq!(a.len(), 140);
        assert_eq!(pairwise_sum(&a), 50.4);
        assert_eq!(pairwise_sum(&a[..31]), 50.5);
        assert_eq!(pairwise_sum(&a[..5]), 1e16);
        assert_eq!(a.iter().sum::<f64>(), 0.7);
    }

    #[test]
    fn bands_as_searchsorted() {
        let edges = [0.0, 0.1, 0.25];
        assert_eq!(band(&edges, 0.0), 0);
        assert_eq!(band(&edges, 0.1), 1);
        assert_eq!(band(&edges, 9.0), 2);
        assert_eq!(band(&edges, f64::NAN), 2);
        assert_eq!(band(&[0.5, 1.0], 0.1), 0);
    }

    #[test]
    fn motion_sees_a_move_and_stillness() {
        let mut m = Motion::new(&[0, 0, 1, 1], &[1.0; 4]).unwrap();
        let lim = MotionLimits {
            empty: 0.1,
            empty_count: 0,
            floor: 0.0,
            motion: 0.05,
        };
        let (g, ok, mut c) = ([1.0; 4], [true; 4], [0.0; 4]);
        let step = |m: &mut Motion, x: &[f64], c: &mut [f64]| m.step(x, &g, &ok, lim, c);
        assert_eq!(step(&mut m, &[0.0; 4], &mut c), Some(Verdict::Empty));
        assert_eq!(
            step(&mut m, &[1.0, 1.0, 0.0, 0.0], &mut c),
            Some(Verdict::Moved)
        );
        assert_eq!(
            step(&mut m, &[1.0, 1.01, 0.0, 0.0], &mut c),
            Some(Verdict::Still)
        );
        assert_eq!(
            step(&mut m, &[0.0, 0.0, 1.0, 1.0], &mut c),
            Some(Verdict::Moved)
        );
        assert_eq!(step(&mut m, &[1.0; 3], &mut c), None);
    }

    #[test]
    fn exposure_grows_and_resets() {
        let (mut e, mut r, mut last) = ([0.0; 2], [0.0; 2], [false; 2]);
        let (mut sure, mut maybe) = ([false; 2], [false; 2]);
        let rule = ExposureRule {
            threshold: 0.5,
            count_possible: false,
            offload_s: 60.0,
            reposition_s: 20.0,
        };
        for _ in 0..3 {
            let st = Exposure {
                exposure: &mut e,
                relief: &mut r,
                loaded_last: &mut last,
                confident: &mut sure,
                possible: &mut maybe,
            };
            exposure_advance(&[1.0, f64::NAN], None, rule, 10.0, false, st).unwrap();
        }
        assert_eq!((e, r, last), ([30.0, 0.0], [0.0, 30.0], [true, false]));
        let st = Exposure {
            exposure: &mut e,
            relief: &mut r,
            loaded_last: &mut last,
            confident: &mut sure,
            possible: &mut maybe,
        };
        let got = exposure_advance(&[0.0, 0.0], None, rule, 60.0, false, st).unwrap();
        assert_eq!(e, [0.0, 0.0]);
        assert_eq!((got.any_loaded, got.over, got.top), (false, 0, 0.0));
    }
}
