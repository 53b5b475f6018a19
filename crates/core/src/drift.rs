//! Drift as a superposition of step responses, in a recursive form that needs no history
//! (thesis §5.2, eq. 5.4/5.8).
//!
//! Eq. 5.8 adds to the Preisach output `h(t)` the drift of every past change of it,
//! `d(t) = γ Σ_i Δh_i k(t - t_i)` with the kernel `k(t) = ln(1 + t)` (eq. 5.2). Written with a
//! kernel that is a sum of exponentials, `k(t) ≈ Σ_j c_j (1 - exp(-t / τ_j))`, the sum over
//! the history collapses into one state per time constant:
//!
//! `d(t) = γ Σ_j c_j (H(t) - z_j(t))`, `H(t) = Σ_i Δh_i`, `z_j(t) = Σ_i Δh_i exp(-(t - t_i)/τ_j)`,
//!
//! and `z_j` is updated exactly per sample: `z_j ← z_j exp(-Δt / τ_j) + Δh`. Each element
//! keeps K states and each sample costs O(K) — independent of how long the history is. The
//! same machinery runs any non-negative Prony series (a fitted kernel where the logarithm does
//! not hold).

use std::borrow::Cow;

use texsense_kernels::drift::{self as kernel, Element, Settings};

use crate::aligned::Lines;
use crate::error::{check_len, CoreError};
use crate::par::{block_size, run_frames, FrameBlock};
use crate::snapshot::{Reader, Writer};

/// A kernel `k(t) = Σ_j c_j (1 - exp(-t / τ_j))` (c_j >= 0, τ_j > 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Kernel {
    weights: Vec<f64>,
    taus: Vec<f64>,
}

impl Kernel {
    /// Build and check a kernel.
    pub fn new(weights: Vec<f64>, taus: Vec<f64>) -> Result<Self, CoreError> {
        check_len("taus", taus.len(), weights.len())?;
        if weights.is_empty() {
            return Err(CoreError::Parameter {
                what: "kernel",
                why: "needs at least one term".into(),
            });
        }
        if weights.iter().any(|w| w.is_nan() || *w < 0.0)
            || taus.iter().any(|t| t.is_nan() || *t <= 0.0)
        {
            return Err(CoreError::Parameter {
                what: "kernel",
                why: "weights must be >= 0 and time constants > 0".into(),
            });
        }
        Ok(Self { weights, taus })
    }

    /// The kernel at time `t >= 0`.
    pub fn value(&self, t: f64) -> f64 {
        self.weights
            .iter()
            .zip(&self.taus)
            .map(|(c, tau)| c * (1.0 - (-t / tau).exp()))
            .sum()
    }

    /// The weights c_j.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The time constants τ_j (s).
    pub fn taus(&self) -> &[f64] {
        &self.taus
    }

    /// Number of terms K.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// True without terms (never, by construction).
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }
}

/// The clock and kernel settings shared by all elements of a bank.
#[derive(Debug, Clone)]
struct DriftSettings {
    kernel: Kernel,
    gamma: f64,
    rest_rate: f64,
    rest_window: f64,
    gamma_time: f64,
    /// Power `q` of the level the kernel superposes (1: the thesis's linear superposition).
    exponent: f64,
}

impl DriftSettings {
    /// The kernels' view (checked when the bank was built).
    fn view(&self) -> Settings<'_, f64> {
        Settings::new(&self.kernel.weights, &self.kernel.taus, self.gamma)
            .and_then(|s| s.with_rest_rate(self.rest_rate, self.rest_window))
            .and_then(|s| s.with_time_component(self.gamma_time))
            .and_then(|s| s.with_exponent(self.exponent))
            .expect("drift settings checked when set")
    }
}

/// Elements per group of the states' layout: the K states of a group of [`GROUP`]
/// neighbouring elements are stored term-major (`[group][term][element]`), so that the
/// AVX-512 path reads one term of eight elements as one vector, and the AVX2 path one term
/// of four (half a group; the last group is padded). Block boundaries fall on group
/// boundaries ([`crate::par::block_size`] is a multiple).
pub const GROUP: usize = 8;

/// Position of element `i`'s term `j` (of `k`) in the grouped layout.
#[inline(always)]
fn at(k: usize, i: usize, j: usize) -> usize {
    (i / GROUP) * k * GROUP + j * GROUP + i % GROUP
}

/// Drift states of N elements.
#[derive(Debug, Clone)]
pub struct DriftBank {
    settings: DriftSettings,
    /// On cache lines ([`Lines`]), as `z`: the SIMD rows read four elements to a register.
    elements: Lines<Element<f64>>,
    /// K states per element, in groups of [`GROUP`] elements, term-major ([`at`]), on cache
    /// lines (a group's term is one register, one line).
    z: Lines<f64>,
    /// The time clock's K states per element when two clocks run (else empty), laid out
    /// as `z`.
    z_time: Lines<f64>,
    /// The decay factors of the kernel's terms for a time step (`kernel::frame`), the
    /// blocks' start ([`DriftBank::prepare`]): a block whose frame has this step computes
    /// none (a stream of one frame per call would compute them anew in every block).
    memo: (f64, Vec<f64>),
}

/// The elements of one block of a bank, for a parallel batch (the block starts on a
/// group boundary).
pub struct DriftBlock<'a> {
    settings: Settings<'a, f64>,
    elements: &'a mut [Element<f64>],
    z: &'a mut [f64],
    z_time: &'a mut [f64],
    /// The bank's memo of the first step while the block steps with it (no copy per block
    /// and step: a live step makes its blocks every frame), the block's own after a change.
    decay: Cow<'a, [f64]>,
    /// The time step of `decay` (NaN: none yet).
    decay_dt: f64,
}

impl DriftBlock<'_> {
    /// Start a frame `dt` seconds after the previous one (once per frame, before `step`).
    #[inline]
    pub fn frame(&mut self, dt: f64) {
        if dt.to_bits() != self.decay_dt.to_bits() {
            kernel::frame(self.decay.to_mut(), self.settings.taus(), dt);
            self.decay_dt = dt;
        }
    }

    /// Element `i` of the block, in the frame started by [`DriftBlock::frame`] with `dt`:
    /// hysteresis output `h` in, drift-corrected output out (eq. 5.8); NaN or invalid inputs
    /// keep the state (time still passes for it) and give NaN.
    #[inline(always)]
    pub fn step(&mut self, i: usize, dt: f64, h: f64, valid: bool) -> f64 {
        let (z, z_time) = states(self.z, self.z_time, self.settings.terms(), i);
        kernel::step_strided(
            &self.settings,
            &mut self.elements[i],
            z,
            z_time,
            GROUP,
            &self.decay,
            dt,
            h,
            valid,
        )
    }

    /// One frame of the block: element `i` reads `h[i]` (`ok[i]` false: skipped) into
    /// `out[i]`; on AVX2 with the time clock and the linear level (eq. 5.8 as printed),
    /// four elements at a time (eight on AVX-512: `avx512`, the same bits), one vector per
    /// kernel term (`avx2`: the scalar kernel's
    /// operations in the same order, so the same bits); the rest clock (an `exp` per
    /// element and term) and a level power (a `powf`) run the scalar kernel.
    ///
    /// # Panics
    /// When a slice does not hold one value per element.
    pub fn row(&mut self, dt: f64, h: &[f64], ok: &[bool], out: &mut [f64]) {
        let n = self.elements.len();
        assert!(
            h.len() == n && ok.len() == n && out.len() == n,
            "one per element"
        );
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2() && self.settings.rest().0 == 0.0 && self.settings.exponent() == 1.0 {
            let (mut wide, k) = (0, self.settings.terms());
            if crate::simd::avx512() {
                wide = n / avx512::LANES * avx512::LANES;
                // SAFETY: the processor has AVX2 and AVX-512 F/DQ/VL (detected by
                // `simd::avx512`); `wide` elements are whole groups, the slices hold n >= wide
                unsafe {
                    avx512::groups(
                        &self.settings,
                        self.elements,
                        self.z,
                        &self.decay,
                        &h[..wide],
                        &ok[..wide],
                        &mut out[..wide],
                    )
                };
            }
            let whole = n / avx2::LANES * avx2::LANES;
            // SAFETY: the processor has AVX2 (detected by `simd::avx2`); `wide` is whole
            // groups of the block's layout, `whole` elements are whole halves of groups, the
            // slices hold n >= whole values
            unsafe {
                avx2::groups(
                    &self.settings,
                    &mut self.elements[wide..],
                    &mut self.z[wide * k..],
                    &self.decay,
                    &h[wide..whole],
                    &ok[wide..whole],
                    &mut out[wide..whole],
                )
            };
            for i in whole..n {
                out[i] = self.step(i, dt, h[i], ok[i]);
            }
            return;
        }
        for (i, slot) in out.iter_mut().enumerate() {
            *slot = self.step(i, dt, h[i], ok[i]);
        }
    }

    /// The drift of the elastic response `level(u)` of the hysteresis stage's input `u`,
    /// added to its output `h` (QLV; `ok`: the validity after the hysteresis stage).
    #[inline]
    pub fn step_on_level(
        &mut self,
        i: usize,
        dt: f64,
        level: &texsense_kernels::convert::Curve<'_, f64>,
        u: f64,
        h: f64,
        ok: bool,
    ) -> (f64, bool) {
        let (z, z_time) = states(self.z, self.z_time, self.settings.terms(), i);
        texsense_kernels::stage::drift_on_level_strided(
            &self.settings,
            &mut self.elements[i],
            z,
            z_time,
            GROUP,
            &self.decay,
            dt,
            level,
            u,
            h,
            ok,
        )
    }
}

/// Element `i`'s K states (term `j` at `[j * GROUP]`) and, with two clocks, the time
/// clock's (empty without), in the grouped layout ([`at`]).
#[inline(always)]
fn states<'b>(
    z: &'b mut [f64],
    z_time: &'b mut [f64],
    k: usize,
    i: usize,
) -> (&'b mut [f64], &'b mut [f64]) {
    let first = at(k, i, 0);
    let end = at(k, i, k - 1) + 1;
    let z_time: &mut [f64] = if z_time.is_empty() {
        &mut []
    } else {
        &mut z_time[first..end]
    };
    (&mut z[first..end], z_time)
}

impl FrameBlock for DriftBlock<'_> {
    #[inline]
    fn frame(&mut self, dt: f64) {
        DriftBlock::frame(self, dt);
    }

    #[inline]
    fn step(&mut self, i: usize, dt: f64, h: f64, valid: bool) -> f64 {
        DriftBlock::step(self, i, dt, h, valid)
    }

    fn row(&mut self, dt: f64, x: &[f64], ok: &[bool], out: &mut [f64]) {
        DriftBlock::row(self, dt, x, ok, out);
    }
}

impl DriftBank {
    /// N elements with drift factor `gamma` (thesis: -0.025 for the textile spacer).
    pub fn new(kernel: Kernel, gamma: f64, n: usize) -> Result<Self, CoreError> {
        if !gamma.is_finite() {
            return Err(CoreError::Parameter {
                what: "gamma",
                why: "must be finite".into(),
            });
        }
        let k = kernel.len();
        Ok(Self {
            settings: DriftSettings {
                kernel,
                gamma,
                rest_rate: 0.0,
                rest_window: 0.5,
                gamma_time: 0.0,
                exponent: 1.0,
            },
            elements: Lines::new(Element::default(), n),
            z: Lines::new(0.0, n.div_ceil(GROUP) * GROUP * k),
            z_time: Lines::default(),
            memo: (f64::NAN, vec![1.0; k]),
        })
    }

    /// Run the kernel on a *rest clock* instead of time: an element's clock advances by
    /// `dt / (1 + r / rest_rate)`, `r` the rate of change of its own input, so it runs at
    /// full speed while the input holds still and nearly stops while it changes fast. The rate
    /// is the exponential average of the signed velocity `Δh / dt` over `rest_window` (s):
    /// equal to the rate of a steady ramp, through zero only where the input turns, and far
    /// below `rest_rate` for reading noise (whose frame-to-frame differences telescope in the
    /// average, to about `σ √2 / rest_window`).
    /// `rest_rate = 0` (the default) is the thesis's time clock (eq. 5.8 as printed).
    pub fn with_rest_rate(mut self, rest_rate: f64, rest_window: f64) -> Result<Self, CoreError> {
        if !(rest_rate.is_finite() && rest_rate >= 0.0) {
            return Err(CoreError::Parameter {
                what: "rest_rate",
                why: format!("must be finite and >= 0, got {rest_rate}"),
            });
        }
        if !(rest_window.is_finite() && rest_window > 0.0) {
            return Err(CoreError::Parameter {
                what: "rest_window",
                why: format!("must be finite and > 0 s, got {rest_window}"),
            });
        }
        self.settings.rest_rate = rest_rate;
        self.settings.rest_window = rest_window;
        Ok(self)
    }

    /// With the rest clock, add a second superposition on the *time* clock with factor
    /// `gamma_time`: `d = γ Σ Δh k(τ_rest) + γ_time Σ Δh k(t)`. Both factors are identified
    /// together from one record that holds both kinds of load (docs/drift.md), so the data
    /// decide which clock a spacer's drift runs on.
    pub fn with_time_component(mut self, gamma_time: f64) -> Result<Self, CoreError> {
        if !gamma_time.is_finite() {
            return Err(CoreError::Parameter {
                what: "gamma_time",
                why: format!("must be finite, got {gamma_time}"),
            });
        }
        self.settings.gamma_time = gamma_time;
        self.z_time = if gamma_time != 0.0 {
            Lines::new(0.0, self.z.len())
        } else {
            Lines::default()
        };
        Ok(self)
    }

    /// Superpose the steps of `h^exponent` instead of `h` (Schapery's nonlinear
    /// superposition: a step's drift grows as the `exponent`-th power of its level; below
    /// zero the level is 0). `1` (the default) is eq. 5.8; the rest clock then runs on the
    /// rate of change of the powered level.
    pub fn with_exponent(mut self, exponent: f64) -> Result<Self, CoreError> {
        if !(exponent.is_finite() && (0.25..=8.0).contains(&exponent)) {
            return Err(CoreError::Parameter {
                what: "exponent",
                why: format!("must lie in [0.25, 8], got {exponent}"),
            });
        }
        self.settings.exponent = exponent;
        Ok(self)
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.elements.len()
    }

    /// The kernel's weights and time constants.
    pub fn kernel(&self) -> &Kernel {
        &self.settings.kernel
    }

    /// γ, the rest clock's rate and window, the time clock's γ and the level power.
    pub fn options(&self) -> (f64, f64, f64, f64, f64) {
        let s = &self.settings;
        (
            s.gamma,
            s.rest_rate,
            s.rest_window,
            s.gamma_time,
            s.exponent,
        )
    }

    /// Every element's state into a snapshot.
    pub(crate) fn save(&self, w: &mut Writer) {
        w.u32(self.len() as u32);
        w.u32(self.settings.kernel.len() as u32);
        w.u32(u32::from(!self.z_time.is_empty()));
        for e in &self.elements {
            w.f64(e.total);
            w.f64(e.last_h);
            w.f64(e.smooth);
            w.u32(e.started);
        }
        // element-major, as before the grouped layout (the snapshot format is unchanged)
        let k = self.settings.kernel.len();
        for z in [&self.z, &self.z_time] {
            if !z.is_empty() {
                for i in 0..self.len() {
                    (0..k).for_each(|j| w.f64(z[at(k, i, j)]));
                }
            }
        }
    }

    /// Every element's state from a snapshot of a bank of the same shape.
    pub(crate) fn load(&mut self, r: &mut Reader<'_>) -> Result<(), CoreError> {
        r.expect("drift elements", self.len())?;
        r.expect("drift kernel terms", self.settings.kernel.len())?;
        r.expect("drift clocks", usize::from(!self.z_time.is_empty()))?;
        for e in &mut self.elements {
            *e = Element {
                total: r.f64()?,
                last_h: r.f64()?,
                smooth: r.f64()?,
                started: r.u32()?.min(1),
            };
        }
        let (k, n) = (self.settings.kernel.len(), self.len());
        for z in [&mut self.z, &mut self.z_time] {
            if !z.is_empty() {
                for i in 0..n {
                    for j in 0..k {
                        z[at(k, i, j)] = r.f64()?;
                    }
                }
            }
        }
        Ok(())
    }

    /// True without elements.
    pub fn is_empty(&self) -> bool {
        self.elements.is_empty()
    }

    /// Bytes of state per element.
    pub fn state_bytes_per_element(&self) -> usize {
        let k = self.settings.kernel.len();
        let clocks = if self.z_time.is_empty() { 1 } else { 2 };
        std::mem::size_of::<Element<f64>>() + clocks * k * std::mem::size_of::<f64>()
    }

    /// Forget the history (the next input is the starting level, with no drift).
    pub fn reset(&mut self) {
        self.elements.fill(Element::default());
        self.z.fill(0.0);
        self.z_time.fill(0.0);
    }

    /// The bank split into blocks of [`block_size`] elements (the last may be shorter).
    pub fn blocks(&mut self) -> impl Iterator<Item = DriftBlock<'_>> {
        let k = self.settings.kernel.len();
        let settings = self.settings.view();
        let size = block_size(self.len());
        let (decay_dt, decay) = (self.memo.0, &self.memo.1);
        let mut z_time = self.z_time.chunks_mut(size * k);
        self.elements
            .chunks_mut(size)
            .zip(self.z.chunks_mut(size * k))
            .map(move |(elements, z)| DriftBlock {
                settings,
                elements,
                z,
                z_time: z_time.next().unwrap_or_default(),
                decay: Cow::Borrowed(decay),
                decay_dt,
            })
    }

    /// The decay factors of a time step `dt` computed once for the blocks that
    /// [`DriftBank::blocks`] hands out next (the first step of a batch; the same values as
    /// each block would compute).
    pub fn prepare(&mut self, dt: f64) {
        if dt.to_bits() != self.memo.0.to_bits() {
            kernel::frame(&mut self.memo.1, &self.settings.kernel.taus, dt);
            self.memo.0 = dt;
        }
    }

    /// One sample `dt` seconds after the previous one: the hysteresis outputs `h` (N,) in,
    /// drift-corrected outputs out. NaN or invalid elements keep their state and give NaN.
    /// The first valid sample of an element is its starting level (a step from 0 to it).
    pub fn step(
        &mut self,
        dt: f64,
        h: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        check_len("h", h.len(), self.len())?;
        self.run(&[dt], h, valid, out)
    }

    /// A batch (T x N row-major) with time steps `dt` (T,), identical to T calls of `step`;
    /// large batches run in parallel over blocks of elements.
    pub fn run(
        &mut self,
        dt: &[f64],
        h: &[f64],
        valid: &[bool],
        out: &mut [f64],
    ) -> Result<(), CoreError> {
        let n = self.len();
        check_time_steps(dt)?;
        check_len("h", h.len(), dt.len() * n)?;
        check_len("valid", valid.len(), dt.len() * n)?;
        check_len("out", out.len(), dt.len() * n)?;
        if let Some(&first) = dt.first() {
            self.prepare(first);
        }
        run_frames(out, n, self.blocks(), dt, |idx, _| {
            valid[idx].then_some(h[idx])
        });
        Ok(())
    }
}

/// Time steps must be >= 0 (and not NaN).
pub(crate) fn check_time_steps(dt: &[f64]) -> Result<(), CoreError> {
    match dt.iter().find(|d| d.is_nan() || **d < 0.0) {
        Some(d) => Err(CoreError::Parameter {
            what: "dt",
            why: format!("time steps must be >= 0, got {d}"),
        }),
        None => Ok(()),
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
pub mod f32x8;
#[cfg(test)]
mod tests;
