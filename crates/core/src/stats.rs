//! One frame's pressure statistics on a grid layout, in one pass: what a station computes for
//! every frame of every mat (`texsense.apps.stats.one_frame_stats` and the monitor's centre
//! of force in grid cells, the same numbers up to the order of the additions).
//!
//! - load: sum of pressure x element area (N, from N/cm² and cm², eq. 2.1 of a map);
//! - contact area: the area of the elements above a threshold;
//! - peak: the highest element;
//! - peak pressure index (PPI): the highest mean over every k x k window of the grid's cells,
//!   empty cells left out of the mean (the window shrinks on grids smaller than k);
//! - centre of force: the mean of the elements' positions (cm) weighted by pressure x area
//!   (negative pressure counts 0), and in grid cells (row, column) weighted by pressure.
//!
//! The statistics are of the values rounded to `f32` first, as a recording stores them; the
//! centre in cells is of the values as given. A frame with an infinite value (or one that
//! overflows `f32`) is not taken ([`GridStats::frame`] gives `None`): the caller's general
//! path says what it makes of it.

/// A grid layout's elements, kept for the statistics of its frames.
#[derive(Debug, Clone)]
pub struct GridStats {
    area: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    cell: Vec<usize>,
    rows: usize,
    cols: usize,
    window: usize,
    full: bool,
}

/// One frame's statistics (NaN where there is none: no load, no cell occupied).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameStats {
    pub load: f64,
    pub contact_area: f64,
    pub peak: f64,
    pub ppi: f64,
    /// Centre of force (x, y) in cm, weighted by pressure x area.
    pub cof_cm: [f64; 2],
    /// Centre of force (row, column) in grid cells, weighted by pressure.
    pub cof_cell: [f64; 2],
}

impl GridStats {
    /// `cell[i]`: the cell (row x `cols` + column) of element `i`; each cell holds at most one
    /// element. `None` when the arrays do not fit each other or the grid.
    pub fn new(
        area: &[f64],
        xy: &[f64],
        cell: &[i64],
        rows: usize,
        cols: usize,
        window: usize,
    ) -> Option<Self> {
        let n = area.len();
        if n == 0 || xy.len() != 2 * n || cell.len() != n || window == 0 {
            return None;
        }
        let cells = rows.checked_mul(cols)?;
        let mut seen = vec![false; cells];
        let mut cell_u = Vec::with_capacity(n);
        for &c in cell {
            let c = usize::try_from(c).ok().filter(|&c| c < cells)?;
            if std::mem::replace(&mut seen[c], true) {
                return None;
            }
            cell_u.push(c);
        }
        Some(Self {
            area: area.to_vec(),
            x: xy.iter().step_by(2).copied().collect(),
            y: xy.iter().skip(1).step_by(2).copied().collect(),
            cell: cell_u,
            rows,
            cols,
            window,
            full: n == cells,
        })
    }

    /// The number of elements.
    pub fn len(&self) -> usize {
        self.area.len()
    }

    /// True when the layout has no element (never: [`GridStats::new`] refuses it).
    pub fn is_empty(&self) -> bool {
        self.area.is_empty()
    }

    /// The statistics of one frame of pressure (N/cm², NaN read as 0) above `threshold`;
    /// `map` is scratch space (kept by the caller between frames). `None` for a frame of
    /// another length or with a value that is infinite as `f32`.
    pub fn frame(&self, p: &[f64], threshold: f64, map: &mut Vec<f64>) -> Option<FrameStats> {
        if p.len() != self.len() {
            return None;
        }
        map.clear();
        map.resize(self.rows * self.cols, f64::NAN);
        let (mut load, mut contact, mut peak) = (0.0, 0.0, f64::NEG_INFINITY);
        let (mut wsum, mut wx, mut wy) = (0.0, 0.0, 0.0);
        let (mut csum, mut cr, mut cc) = (0.0, 0.0, 0.0);
        for (i, &raw) in p.iter().enumerate() {
            let given = if raw.is_nan() { 0.0 } else { raw };
            let v = f64::from(given as f32);
            if !v.is_finite() {
                return None;
            }
            let a = self.area[i];
            load += v * a;
            if v > threshold {
                contact += a;
            }
            peak = peak.max(v);
            let w = (v * a).max(0.0);
            wsum += w;
            wx += w * self.x[i];
            wy += w * self.y[i];
            let c = self.cell[i];
            let g = given.max(0.0);
            csum += g;
            cr += g * (c / self.cols) as f64;
            cc += g * (c % self.cols) as f64;
            map[c] = v;
        }
        let centre = |total: f64, a: f64, b: f64| {
            if total > 0.0 {
                [a / total, b / total]
            } else {
                [f64::NAN; 2]
            }
        };
        Some(FrameStats {
            load,
            contact_area: contact,
            peak,
            ppi: self.ppi(map),
            cof_cm: centre(wsum, wx, wy),
            cof_cell: centre(csum, cr, cc),
        })
    }

    /// The highest mean of the occupied cells of a k x k window (NaN: no window has any).
    fn ppi(&self, map: &[f64]) -> f64 {
        let (kr, kc) = (self.window.min(self.rows), self.window.min(self.cols));
        let mut best = f64::NEG_INFINITY;
        for r in 0..=self.rows - kr {
            for c in 0..=self.cols - kc {
                let (mut sum, mut count) = (0.0, 0usize);
                for i in r..r + kr {
                    for &v in &map[i * self.cols + c..i * self.cols + c + kc] {
                        if self.full || !v.is_nan() {
                            sum += v;
                            count += 1;
                        }
                    }
                }
                if count > 0 {
                    best = best.max(sum / count as f64);
                }
            }
        }
        if best.is_finite() {
            best
        } else {
            f64::NAN
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(rows: usize, cols: usize, skip: &[usize]) -> (GridStats, Vec<(usize, usize)>) {
        let rc: Vec<(usize, usize)> = (0..rows * cols)
            .filter(|c| !skip.contains(c))
            .map(|c| (c / cols, c % cols))
            .collect();
        let area: Vec<f64> = (0..rc.len()).map(|i| 1.0 + 0.1 * i as f64).collect();
        let xy: Vec<f64> = rc
            .iter()
            .flat_map(|&(r, c)| [c as f64 * 2.0, r as f64 * 2.0])
            .collect();
        let cell: Vec<i64> = rc.iter().map(|&(r, c)| (r * cols + c) as i64).collect();
        (
            GridStats::new(&area, &xy, &cell, rows, cols, 3).unwrap(),
            rc,
        )
    }

    #[test]
    fn a_known_map() {
        let (g, _) = grid(4, 4, &[]);
        let mut p = vec![0.0; 16];
        p[5] = 2.0; // row 1, column 1
        p[6] = 4.0; // row 1, column 2
        p[15] = f64::NAN; // read as 0
        let s = g.frame(&p, 1.0, &mut Vec::new()).unwrap();
        assert_eq!(s.peak, 4.0);
        assert!((s.load - (2.0 * 1.5 + 4.0 * 1.6)).abs() < 1e-12);
        assert!((s.contact_area - 3.1).abs() < 1e-12);
        assert!((s.ppi - 6.0 / 9.0).abs() < 1e-12);
        let w = [2.0 * 1.5, 4.0 * 1.6];
        let x = (w[0] * 2.0 + w[1] * 4.0) / (w[0] + w[1]);
        assert!((s.cof_cm[0] - x).abs() < 1e-12 && (s.cof_cm[1] - 2.0).abs() < 1e-12);
        assert!((s.cof_cell[0] - 1.0).abs() < 1e-12);
        assert!((s.cof_cell[1] - (2.0 + 8.0) / 6.0).abs() < 1e-12);
    }

    #[test]
    fn empty_cells_are_left_out_and_an_empty_frame_has_no_centre() {
        let (g, rc) = grid(3, 4, &[0, 1, 4, 5, 8, 9]); // only columns 2 and 3
        let p: Vec<f64> = rc.iter().map(|&(r, _)| r as f64).collect();
        let s = g.frame(&p, 0.0, &mut Vec::new()).unwrap();
        assert!((s.ppi - 1.0).abs() < 1e-12); // a 3 x 3 window holds 6 occupied cells
        let z = g.frame(&vec![0.0; rc.len()], 0.0, &mut Vec::new()).unwrap();
        assert_eq!((z.load, z.peak), (0.0, 0.0));
        assert!(z.cof_cm[0].is_nan() && z.cof_cell[1].is_nan());
    }

    #[test]
    fn values_are_rounded_to_f32_and_infinite_frames_refused() {
        let (g, _) = grid(2, 2, &[]);
        let s = g
            .frame(&[0.1, 0.0, 0.0, 0.0], -1.0, &mut Vec::new())
            .unwrap();
        assert_eq!(s.peak, f64::from(0.1f32));
        assert!(g
            .frame(&[f64::INFINITY, 0.0, 0.0, 0.0], 0.0, &mut Vec::new())
            .is_none());
        assert!(g
            .frame(&[1e300, 0.0, 0.0, 0.0], 0.0, &mut Vec::new())
            .is_none());
        assert!(g.frame(&[0.0; 3], 0.0, &mut Vec::new()).is_none());
    }

    #[test]
    fn layouts_that_do_not_fit_are_refused() {
        assert!(GridStats::new(&[1.0], &[0.0, 0.0], &[4], 2, 2, 3).is_none());
        assert!(GridStats::new(&[1.0, 1.0], &[0.0; 4], &[1, 1], 2, 2, 3).is_none());
        assert!(GridStats::new(&[1.0], &[0.0], &[0], 1, 1, 3).is_none());
    }
}
