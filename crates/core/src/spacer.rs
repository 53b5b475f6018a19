//! Mechanics of a compressible spacer: the ground truth of the virtual sensor.
//!
//! This model is deliberately *not* a Preisach model and not a logarithmic step-response
//! superposition (the two models the compensation uses): a compensation tested against it
//! cannot grade itself. It is a physical law of another family, chosen to reproduce what the
//! thesis measured (chapters 2, 4 and 5):
//!
//! - **Backbone** (elastic, plateau, densification of a foam or a knitted pile):
//!   `σ_e(e) = A (e / (e_d - e))^m + E_lin e`, with `e` the compression as a fraction of the
//!   thickness and `e_d` the densification limit.
//! - **Friction between piles / cell walls** (rate-independent hysteresis): K spring-slider
//!   elements with deflection `z_i` limited to `±r_i`, whose stress is proportional to the
//!   backbone stress (Coulomb friction grows with the contact force):
//!   `σ_f = σ_e(e) Σ w_i z_i / r_i`. Because the friction is modulated by the current
//!   compression, minor loops between the same extrema are *not* congruent.
//! - **Creep of stuck contacts** (drift under constant compression): a slider that is at rest
//!   or being unloaded creeps back with a thermally activated rate
//!   `d|z|/dt = -(a r / t_c) exp((|z| - r) / (a r))`, integrated exactly over any step
//!   (`exp(-y)` grows linearly with time). Contacts creep only at rest: the creep clock runs
//!   at `1 / (1 + (|de/dt| / rest_rate)²)` of real time, so an element held still relaxes like
//!   `r (1 - a ln(1 + t / t_c))` while any ramp (0.1 mm/min is 2800 x rest_rate) leaves it
//!   alone: ramps are nearly rate independent (thesis §4.1) and holds relax logarithmically
//!   (§5.1).
//! - **Clutched relaxation of the structure** (drift after any step, up or down): one branch
//!   stores the increases `w Δσ` of the elastic and friction stress, another the decreases;
//!   each is idle while it grows and relaxes like a stuck contact at rest
//!   (`|s| → S (1 - a ln(1 + t_eff / t_c))`, `S` all it has stored, `t_eff` the age that
//!   explains what has relaxed). Being idle during monotone motion it keeps ramps rate
//!   independent, while the change after a step is proportional to the step, rising or
//!   falling (thesis eq. 5.1, fig. 5.2/5.3). At every reversal the two branches' common
//!   content cancels (the net stored stress is unchanged) and an increment joins a branch
//!   without making its relaxed content young again: repeated loading and unloading (sitting bouts) creeps the spacer
//!   like a step to the mean load (thesis §5.1.2.2), not bout after bout without bound.
//! - **Air flow and fast viscoelasticity** (0.1-10 s): quasi-linear viscoelastic branches
//!   `q_j` driven by the backbone stress, integrated exactly for a stress that is linear within
//!   the step.
//! - **Cyclic softening** (a Mullins-like effect of foams and piles): stress reductions `R_j`
//!   that follow `ρ_j σ_e` along the *path* of the compression, `dR_j = κ_j (ρ_j σ_e - R_j)
//!   |de|`, with κ_j spread over decades, and recover in time (hours) when the load drops.
//!   Driven by path length, not time, they do not make ramps rate dependent, leave held
//!   compressions alone, and shift loops towards higher compression over many cycles (thesis
//!   fig. 5.4/5.5).
//! - **Structural creep and slow recovery** (10² - 10⁴ s): Kelvin elements adding a creep
//!   strain `c` that grows under load and recovers (slower) when unloaded; the backbone and
//!   the friction see `(e - c) / (1 - c / e_d)`. This leaves the permanent set of a foam that recovers over
//!   hours.
//!
//! Every update is an exact solution or an exponential integrator over the step, so the model
//! cannot blow up at any step size. Pressure-controlled drive solves for the compression by
//! bisection (the stress is monotone in the compression for a given state).

use crate::error::{check_len, CoreError};
use step_factors::StepFactors;

mod step_factors;

/// Largest share of the elastic and friction stress the clutched relaxation can cancel.
const CLUTCH_FLOOR: f64 = 0.8;

/// Parameters of one spacer material (shared by all elements of a bank).
#[derive(Debug, Clone, PartialEq)]
pub struct SpacerParams {
    /// Backbone amplitude `A` (N/cm²).
    pub backbone_a: f64,
    /// Backbone exponent `m`.
    pub backbone_m: f64,
    /// Densification limit `e_d` (fraction of thickness, in (0, 1)).
    pub densification: f64,
    /// Linear backbone stiffness `E_lin` (N/cm² per unit compression).
    pub linear: f64,
    /// Friction elements: weight `w_i` (share of the backbone stress) and slip deflection
    /// `r_i` (fraction of thickness).
    pub friction: Vec<(f64, f64)>,
    /// Creep amplitude `a` of stuck contacts (dimensionless).
    pub creep_a: f64,
    /// Creep time scale `t_c` (s).
    pub creep_tc: f64,
    /// Compression rate (fraction of thickness per s) below which contacts count as at rest:
    /// creep runs at the rate `1 / (1 + (|de/dt| / rest_rate)²)` of its full speed.
    pub rest_rate: f64,
    /// Clutched relaxation branch: stored share `w` of the backbone stress changes and its
    /// creep amplitude `a` (same time scale `t_c`).
    pub clutch: (f64, f64),
    /// Fast viscoelastic branches: weight (share of the backbone stress step) and time
    /// constant (s).
    pub viscous: Vec<(f64, f64)>,
    /// Kelvin creep elements: maximal creep strain (fraction of thickness) and time constant
    /// (s) under load.
    pub kelvin: Vec<(f64, f64)>,
    /// How much slower creep strain recovers than it grows (>= 1).
    pub recovery_factor: f64,
    /// Reference stress of the creep drive (N/cm²): the creep target is
    /// `c_max h / (1 + h)` with `h = σ_e / p_ref`.
    pub creep_p_ref: f64,
    /// Cyclic softening elements: share `ρ_j` of the backbone stress and path rate `κ_j`
    /// (per unit compression travelled).
    pub softening: Vec<(f64, f64)>,
    /// Time constant (s) with which softening recovers when the load drops.
    pub softening_recovery_s: f64,
}

impl SpacerParams {
    /// Check every parameter's domain (NaN fails every check).
    pub fn validate(&self) -> Result<(), CoreError> {
        let bad = |what: &'static str, why: String| Err(CoreError::Parameter { what, why });
        let pos = |x: f64| x > 0.0;
        let nonneg = |x: f64| x >= 0.0;
        if !pos(self.backbone_a) {
            return bad(
                "backbone_a",
                format!("must be > 0, got {}", self.backbone_a),
            );
        }
        if !pos(self.backbone_m) {
            return bad(
                "backbone_m",
                format!("must be > 0, got {}", self.backbone_m),
            );
        }
        if !(pos(self.densification) && self.densification < 1.0) {
            return bad(
                "densification",
                format!("must be in (0, 1), got {}", self.densification),
            );
        }
        if !nonneg(self.linear) {
            return bad("linear", format!("must be >= 0, got {}", self.linear));
        }
        let share: f64 = self.friction.iter().map(|f| f.0).sum();
        if share >= 1.0 || self.friction.iter().any(|&(w, r)| !nonneg(w) || !pos(r)) {
            return bad(
                "friction",
                "weights must be >= 0 and sum below 1, slip deflections > 0".into(),
            );
        }
        if !(nonneg(self.creep_a) && self.creep_a < 0.5 && pos(self.creep_tc)) {
            return bad("creep", "need 0 <= creep_a < 0.5 and creep_tc > 0".into());
        }
        if !pos(self.rest_rate) {
            return bad("rest_rate", format!("must be > 0, got {}", self.rest_rate));
        }
        if !(nonneg(self.clutch.0) && nonneg(self.clutch.1) && self.clutch.1 < 0.5) {
            return bad("clutch", "need weight >= 0 and 0 <= amplitude < 0.5".into());
        }
        if self.viscous.iter().any(|&(w, t)| !nonneg(w) || !pos(t)) {
            return bad(
                "viscous",
                "weights must be >= 0 and time constants > 0".into(),
            );
        }
        if self.kelvin.iter().any(|&(c, t)| !nonneg(c) || !pos(t)) {
            return bad(
                "kelvin",
                "strains must be >= 0 and time constants > 0".into(),
            );
        }
        if !(self.recovery_factor >= 1.0 && pos(self.creep_p_ref)) {
            return bad(
                "kelvin",
                "recovery_factor must be >= 1 and creep_p_ref > 0".into(),
            );
        }
        let rho: f64 = self.softening.iter().map(|f| f.0).sum();
        if rho >= 1.0 || self.softening.iter().any(|&(r, k)| !nonneg(r) || !pos(k)) {
            return bad(
                "softening",
                "shares must be >= 0 and sum below 1, path rates > 0".into(),
            );
        }
        if !pos(self.softening_recovery_s) {
            return bad("softening_recovery_s", "must be > 0".into());
        }
        if [share, rho].iter().any(|v| v.is_nan()) {
            return bad("friction", "NaN in the parameters".into());
        }
        Ok(())
    }

    /// The backbone stress `σ_e(e)` in N/cm² (0 for e <= 0).
    #[inline]
    pub fn backbone(&self, e: f64) -> f64 {
        if e <= 0.0 {
            return 0.0;
        }
        let e = e.min(self.densification * (1.0 - 1e-9));
        self.backbone_a * (e / (self.densification - e)).powf(self.backbone_m) + self.linear * e
    }
}

/// The state of N spacer elements of one material, stepped together.
#[derive(Debug, Clone)]
pub struct SpacerBank {
    p: SpacerParams,
    n: usize,
    scale: Vec<f64>,
    e: Vec<f64>,
    z: Vec<f64>,
    q: Vec<f64>,
    c: Vec<f64>,
    soft: Vec<f64>,
    clutch: Vec<f64>,
    clutch_ref: Vec<f64>,
    last_change_sign: Vec<f64>,
    ef_prev: Vec<f64>,
    stress_prev: Vec<f64>,
    backbone_prev: Vec<f64>,
    /// The step's factors that depend on `dt` alone (computed once per `dt`).
    factors: StepFactors,
}

/// What one trial step produces for one element, without committing it.
#[derive(Debug, Clone, Copy)]
pub struct Trial {
    /// Stress at the end of the step (N/cm²).
    pub stress: f64,
    /// Compression at which the spacer's own surface sits (its permanent set).
    pub creep: f64,
}

fn check_dt(dt: f64) -> Result<(), CoreError> {
    if dt >= 0.0 && dt.is_finite() {
        Ok(())
    } else {
        Err(CoreError::Parameter {
            what: "dt",
            why: format!("time steps must be finite and >= 0, got {dt}"),
        })
    }
}

/// A spacer law: N elements of one material whose state a trial step advances. The
/// test-machine drivers (displacement control, pressure control, a ramp until a pressure) are
/// shared by every law.
pub trait SpacerLaw {
    /// Number of elements.
    fn len(&self) -> usize;
    /// True without elements.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Densification limit (fraction of the thickness; compressions stay below it).
    fn limit(&self) -> f64;
    /// Current platen compression of element `i` (fraction of thickness).
    fn current(&self, i: usize) -> f64;
    /// End-of-step stress of element `i` for platen compression `e_new` after `dt` seconds;
    /// when `commit`, store the new state.
    fn trial(&mut self, i: usize, dt: f64, e_new: f64, commit: bool) -> Trial;
    /// The elastic backbone stress (N/cm²) at compression `e` (no friction, no creep).
    fn backbone(&self, e: f64) -> f64;
    /// Current permanent set of every element (fraction of thickness).
    fn creep_strain(&self) -> Vec<f64>;

    /// Displacement control: move every element's platen to `compression` (fraction of
    /// thickness, in [0, e_d)) over `dt` seconds. Writes the pressure (N/cm²) and the
    /// spacer's own compression (the platen's, or the creep set when the platen lifted off).
    fn step_displacement(
        &mut self,
        dt: f64,
        compression: &[f64],
        pressure: &mut [f64],
        spacer_compression: &mut [f64],
    ) -> Result<(), CoreError> {
        check_dt(dt)?;
        check_len("compression", compression.len(), self.len())?;
        check_len("pressure", pressure.len(), self.len())?;
        check_len("spacer_compression", spacer_compression.len(), self.len())?;
        let limit = self.limit();
        for i in 0..self.len() {
            let e = compression[i];
            if !(e >= 0.0 && e < limit) {
                return Err(CoreError::Parameter {
                    what: "compression",
                    why: format!(
                        "element {i}: compression {e} is outside [0, {limit}) of the thickness"
                    ),
                });
            }
            let t = self.trial(i, dt, e, true);
            pressure[i] = t.stress;
            spacer_compression[i] = e.max(t.creep);
        }
        Ok(())
    }

    /// Whether, for any state and step, the end-of-step stress never decreases with the
    /// compression `e_new` (then [`SpacerLaw::step_pressure`] may bracket its root locally).
    /// The first law's creep clock runs fastest where the platen rests, so its stress can dip
    /// there: it keeps the default (false).
    fn monotone(&self) -> bool {
        false
    }

    /// For a monotone law: compressions `(below, above)` with the stress at `below` at most
    /// `target` and at `above` more than `target` (`below` = -inf when even 0 carries more,
    /// in which case `above` = 0), searched outwards from the current compression in growing
    /// steps. None when the target lies beyond `hi_limit` (the caller then reports it).
    fn local_bracket(
        &mut self,
        i: usize,
        dt: f64,
        target: f64,
        hi_limit: f64,
    ) -> Option<(f64, f64)> {
        let e0 = self.current(i).clamp(0.0, hi_limit);
        let mut step = 1e-6;
        if self.trial(i, dt, e0, false).stress <= target {
            let mut below = e0;
            loop {
                let e = (e0 + step).min(hi_limit);
                if self.trial(i, dt, e, false).stress > target {
                    return Some((below, e));
                }
                if e >= hi_limit {
                    return None;
                }
                below = e;
                step *= 4.0;
            }
        }
        let mut above = e0;
        loop {
            let e = (e0 - step).max(0.0);
            if self.trial(i, dt, e, false).stress <= target {
                return Some((e, above));
            }
            above = e;
            if e <= 0.0 {
                return Some((f64::NEG_INFINITY, 0.0));
            }
            step *= 4.0;
        }
    }

    /// Pressure control: find, for every element, the largest compression at which the
    /// pressure does not exceed `pressure[i]` (N/cm², >= 0) after `dt` seconds, and commit it.
    /// Writes the compression (platen = spacer surface, fraction of thickness) and the
    /// pressure reached (equal to the target up to the solver tolerance, except where creep
    /// at a turning point makes the stress jump across it).
    fn step_pressure(
        &mut self,
        dt: f64,
        pressure: &[f64],
        compression: &mut [f64],
        reached: &mut [f64],
    ) -> Result<(), CoreError> {
        check_dt(dt)?;
        check_len("pressure", pressure.len(), self.len())?;
        check_len("compression", compression.len(), self.len())?;
        check_len("reached", reached.len(), self.len())?;
        let hi_limit = self.limit() * (1.0 - 1e-6);
        for i in 0..self.len() {
            let target = pressure[i];
            if !(target >= 0.0 && target.is_finite()) {
                return Err(CoreError::Parameter {
                    what: "pressure",
                    why: format!("element {i}: pressure must be finite and >= 0, got {target}"),
                });
            }
            // the largest compression whose stress does not exceed the target: bisection on
            // [0, hi_limit]; a monotone law first brackets the root near the current
            // compression and decides the midpoints outside that bracket without a trial
            // (the same midpoints, the same decisions: the same result, fewer trials)
            let known = if self.monotone() {
                self.local_bracket(i, dt, target, hi_limit)
            } else {
                None
            };
            let (mut lo, mut hi) = (0.0, hi_limit);
            if known.is_none() && self.trial(i, dt, hi, false).stress <= target {
                return Err(CoreError::Parameter {
                    what: "pressure",
                    why: format!(
                        "element {i}: {target} N/cm² is beyond what the spacer can carry before \
                         densification"
                    ),
                });
            }
            let (below, above) = known.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                let carries = if mid <= below {
                    true
                } else if mid >= above {
                    false
                } else {
                    self.trial(i, dt, mid, false).stress <= target
                };
                if carries {
                    lo = mid;
                } else {
                    hi = mid;
                }
                if hi - lo < 1e-13 {
                    break;
                }
            }
            let t = self.trial(i, dt, lo, true);
            compression[i] = lo.max(t.creep);
            reached[i] = t.stress;
        }
        Ok(())
    }

    /// Test-machine ramp of a single-element bank: move the platen at `rate` (fraction of
    /// thickness per second, sign gives the direction) in steps of `dt` until the pressure
    /// reaches `target` (rising: >= target; falling: <= target or the platen at 0), at most
    /// `max_steps` steps. Appends every step's (compression, pressure, spacer compression).
    #[allow(clippy::too_many_arguments)]
    fn ramp_until(
        &mut self,
        dt: f64,
        rate: f64,
        target: f64,
        max_steps: usize,
        compression: &mut Vec<f64>,
        pressure: &mut Vec<f64>,
        spacer_compression: &mut Vec<f64>,
    ) -> Result<bool, CoreError> {
        if self.len() != 1 {
            return Err(CoreError::Parameter {
                what: "ramp_until",
                why: format!("needs a bank of one element, this one has {}", self.len()),
            });
        }
        check_dt(dt)?;
        if dt <= 0.0 || rate == 0.0 || !rate.is_finite() || target.is_nan() || target < 0.0 {
            return Err(CoreError::Parameter {
                what: "ramp_until",
                why: "need dt > 0, a finite non-zero rate and a target >= 0".into(),
            });
        }
        let limit = self.limit() * (1.0 - 1e-6);
        for _ in 0..max_steps {
            let e = (self.current(0) + rate * dt).clamp(0.0, limit);
            if rate > 0.0 && e >= limit {
                return Err(CoreError::Parameter {
                    what: "ramp_until",
                    why: format!("{target} N/cm² is not reached before densification"),
                });
            }
            let t = self.trial(0, dt, e, true);
            compression.push(e);
            pressure.push(t.stress);
            spacer_compression.push(e.max(t.creep));
            let done = if rate > 0.0 {
                t.stress >= target
            } else {
                t.stress <= target || e <= 0.0
            };
            if done {
                return Ok(true);
            }
        }
        Ok(false)
    }
}

impl SpacerBank {
    /// `n` unloaded elements; `scale` multiplies every stress of an element (specimen
    /// variation), one entry per element.
    pub fn new(params: SpacerParams, scale: Vec<f64>) -> Result<Self, CoreError> {
        params.validate()?;
        if scale.iter().any(|&s| s.is_nan() || s <= 0.0) {
            return Err(CoreError::Parameter {
                what: "scale",
                why: "stress scales must be > 0".into(),
            });
        }
        let n = scale.len();
        Ok(Self {
            z: vec![0.0; n * params.friction.len()],
            q: vec![0.0; n * params.viscous.len()],
            c: vec![0.0; n * params.kelvin.len()],
            soft: vec![0.0; n * params.softening.len()],
            clutch: vec![0.0; 2 * n],
            clutch_ref: vec![0.0; 2 * n],
            last_change_sign: vec![0.0; n],
            ef_prev: vec![0.0; n],
            stress_prev: vec![0.0; n],
            e: vec![0.0; n],
            backbone_prev: vec![0.0; n],
            factors: StepFactors::default(),
            p: params,
            n,
            scale,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &SpacerParams {
        &self.p
    }

    /// Current platen compression of every element (fraction of thickness).
    pub fn compression(&self) -> &[f64] {
        &self.e
    }
}

impl SpacerLaw for SpacerBank {
    fn len(&self) -> usize {
        self.n
    }

    fn limit(&self) -> f64 {
        self.p.densification
    }

    fn current(&self, i: usize) -> f64 {
        self.e[i]
    }

    fn backbone(&self, e: f64) -> f64 {
        self.p.backbone(e)
    }

    /// Current creep strain (permanent set) of every element: the compression at which the
    /// spacer's own surface sits when nothing presses on it.
    fn creep_strain(&self) -> Vec<f64> {
        let k = self.p.kelvin.len();
        (0..self.n)
            .map(|i| self.c[i * k..(i + 1) * k].iter().sum())
            .collect()
    }

    /// Compute the end-of-step stress of element `i` for platen compression `e_new`
    /// after `dt` seconds; when `commit`, store the new state.
    fn trial(&mut self, i: usize, dt: f64, e_new: f64, commit: bool) -> Trial {
        self.factors.update(&self.p, dt);
        let p = &self.p;
        let f = &self.factors;
        let (nk, nf, nv) = (p.kelvin.len(), p.friction.len(), p.viscous.len());
        // 1. structural creep strain, driven by the pressure of the previous step (an
        //    unloaded specimen recovers)
        let h = self.stress_prev[i] / p.creep_p_ref;
        let drive = h / (1.0 + h);
        let mut creep_old = 0.0;
        let mut creep_new = 0.0;
        for (j, &(c_max, _)) in p.kelvin.iter().enumerate() {
            let c = self.c[i * nk + j];
            let target = c_max * drive;
            let decay = if target >= c {
                f.kelvin_loading[j]
            } else {
                f.kelvin_recovering[j]
            };
            let c1 = target + (c - target) * decay;
            creep_old += c;
            creep_new += c1;
            if commit {
                self.c[i * nk + j] = c1;
            }
        }
        // the set takes thickness away: [c, e_d] of the platen maps onto [0, e_d] of the
        // material, so a compressed foam still densifies where it did
        let ed = p.densification;
        let eff = |e: f64, c: f64| ((e - c) / (1.0 - c / ed)).max(0.0);
        let eff_old = eff(self.e[i], creep_old);
        let eff_new = eff(e_new, creep_new);
        let backbone = p.backbone(eff_new);
        // 2. friction elements: dragged ones slip at their limit, stuck ones creep
        let delta = eff_new - eff_old;
        // contacts creep at rest; any motion (well below 0.1 mm/min) stops them
        let creep_dt = if dt > 0.0 {
            let r = delta.abs() / dt / p.rest_rate;
            dt / (1.0 + r * r)
        } else {
            0.0
        };
        let mut share = 0.0;
        for (k, &(w, r)) in p.friction.iter().enumerate() {
            let mut z = self.z[i * nf + k] + delta;
            if z > r {
                z = r;
            } else if z < -r {
                z = -r;
            } else if p.creep_a > 0.0 && z != 0.0 && delta * z <= 0.0 {
                // creep only while the contact is not being loaded towards its limit
                let ar = p.creep_a * r;
                let y = (z.abs() - r) / ar; // <= 0
                let grown = (-y).exp() + creep_dt / p.creep_tc;
                let mag = (r - ar * grown.ln()).max(0.0);
                z = mag.copysign(z);
            }
            share += w * z / r;
            if commit {
                self.z[i * nf + k] = z;
            }
        }
        // 3. fast viscoelastic branches, exact for a stress linear within the step
        let step = backbone - self.backbone_prev[i];
        let mut viscous = 0.0;
        for (j, &(w, _)) in p.viscous.iter().enumerate() {
            let (decay, gain) = (f.viscous_decay[j], f.viscous_gain[j]);
            let q = self.q[i * nv + j] * decay + w * step * gain;
            viscous += q;
            if commit {
                self.q[i * nv + j] = q;
            }
        }
        // 4. clutched relaxation: a loading branch stores stress increments, an unloading
        //    branch stores decrements; each is idle while it grows and creeps at rest
        let (cw, ca) = p.clutch;
        let elastic_friction = backbone * (1.0 + share);
        let change = cw * (elastic_friction - self.ef_prev[i]);
        // at a reversal the two stores' common content cancels (the net stored stress, and
        // so the stress now, is unchanged): repeated loading and unloading cannot pile up
        // opposing stores whose different ages would creep the spacer without bound
        let mut stores = [
            (self.clutch[2 * i], self.clutch_ref[2 * i]),
            (self.clutch[2 * i + 1], self.clutch_ref[2 * i + 1]),
        ];
        if change != 0.0 && change.signum() != self.last_change_sign[i] {
            let common = stores[0].0.abs().min(stores[1].0.abs());
            if common > 0.0 {
                for (v, v_ref) in stores.iter_mut() {
                    let kept = (v.abs() - common) / v.abs();
                    *v *= kept;
                    *v_ref *= kept;
                }
            }
        }
        let mut clutch = 0.0;
        for (side, &(mut v, mut v_ref)) in stores.iter().enumerate() {
            let k = 2 * i + side;
            let grows = if side == 0 {
                change > 0.0
            } else {
                change < 0.0
            };
            if grows {
                // what has relaxed stays relaxed: the increment joins the store without
                // making the old content young again
                v += change;
                v_ref += change.abs();
            } else if ca > 0.0 && v_ref > 0.0 && v != 0.0 {
                let ar = ca * v_ref;
                let y = (v.abs() - v_ref) / ar;
                let grown = (-y).exp() + creep_dt / p.creep_tc;
                v = (v_ref - ar * grown.ln()).max(0.0).copysign(v);
            }
            clutch += v;
            if commit {
                self.clutch[k] = v;
                self.clutch_ref[k] = v_ref;
            }
        }
        if commit {
            self.ef_prev[i] = elastic_friction;
            if change != 0.0 {
                self.last_change_sign[i] = change.signum();
            }
        }
        // 5. cyclic softening: follows ρ σ_e along the path, recovers in time when unloading
        let ns = p.softening.len();
        let path = delta.abs();
        let mut softening = 0.0;
        for (j, &(rho, kappa)) in p.softening.iter().enumerate() {
            let r0 = self.soft[i * ns + j];
            let target = rho * backbone;
            let mut r = target + (r0 - target) * (-kappa * path).exp();
            if target < r {
                r = target + (r - target) * f.softening_recovery;
            }
            softening += r;
            if commit {
                self.soft[i * ns + j] = r;
            }
        }
        if commit {
            self.e[i] = e_new;
            self.backbone_prev[i] = backbone;
        }
        // the stored relaxation acts through the structure: it can take at most
        // CLUTCH_FLOOR of the elastic and friction stress away, so an unloaded spacer is not
        // held compressed by its own relaxation (the stress stays > 0 for any compression)
        let clutch = clutch.max(-CLUTCH_FLOOR * elastic_friction);
        let stress = (self.scale[i] * (elastic_friction + viscous + clutch - softening)).max(0.0);
        if commit {
            self.stress_prev[i] = stress;
        }
        Trial {
            stress,
            creep: creep_new,
        }
    }
}

#[cfg(test)]
mod tests;
