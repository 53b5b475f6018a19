//! A single frame (a live step) on AVX-512 in one pass over the detector's elements instead
//! of two (issue 34, fifteenth round).

use super::{avx512, kernel, FailureDetector, Validity, KERNEL_ROW};

impl FailureDetector {
    /// One frame (a live step) in one pass on AVX-512 instead of two (issue 34, fifteenth
    /// round): each group of eight gets its changes and then its codes
    /// (`avx512::changes_codes_row`); the groups with a reading that holds still, which
    /// reads its neighbours' changes, and the row's last elements short of eight get
    /// theirs afterwards by the scalar kernel, when every change of the frame is made. The
    /// same codes and states as the two passes (`detect/tests.rs`).
    pub(super) fn frame_in_one_pass(
        &mut self,
        readings: &[f64],
        valid: &[bool],
        delta: &mut [f64],
        codes: &mut [u8],
    ) {
        let n = self.len();
        let size = KERNEL_ROW;
        let mut elements = std::mem::take(&mut self.elements);
        // per part of the row (one call of the lane kernel each), its groups of four left to
        // the scalar kernel
        let mut left = Vec::with_capacity(n.div_ceil(size));
        for start in (0..n).step_by(size) {
            let end = (start + size).min(n);
            let whole = (end - start) / 8 * 8;
            let (c, els) = (&readings[start..end], &mut elements[start..end]);
            let d = &mut delta[start..end];
            let at = start..start + whole;
            let lim = self.row_limits(start, whole);
            // SAFETY: `crate::simd::avx512` found AVX-512 F/DQ/VL and AVX2 (the caller's
            // `simd_wide`)
            let mut groups = unsafe {
                avx512::changes_codes_row(
                    &self.params,
                    &lim,
                    &c[..whole],
                    &mut d[..whole],
                    &valid[at.clone()],
                    &mut els[..whole],
                    &mut codes[at],
                )
            };
            for (li, el) in els.iter_mut().enumerate().skip(whole) {
                d[li] = kernel::change(el, c[li]);
            }
            // the groups of four short of a group of eight
            groups |= ((1u64 << (end - start).div_ceil(4)) - (1u64 << (whole / 4))) as u32;
            left.push(groups);
        }
        let mut scratch = (Vec::new(), [0.0; 8]);
        for (b, mut groups) in left.into_iter().enumerate() {
            let start = b * size;
            let end = (start + size).min(n);
            // the set bits only (most parts have none)
            while groups != 0 {
                let g = groups.trailing_zeros() as usize;
                groups &= groups - 1;
                let (a, z) = (start + 4 * g, (start + 4 * g + 4).min(end));
                self.codes_scalar(
                    readings,
                    delta,
                    Validity::Given(valid),
                    (a, 0),
                    &mut elements[a..z],
                    &mut codes[a..z],
                    &mut scratch,
                );
            }
        }
        self.elements = elements;
    }
}
