//! The factors of a step that depend on its length `dt` alone: the same for every element
//! and for every trial of a pressure-control step (about 45 trials per element while the
//! bisection looks for the compression), so they are computed once per `dt` instead of in
//! every trial. Each is the very expression the trial used, so the results are the same to
//! the bit.

use super::SpacerParams;

#[derive(Debug, Clone, Default)]
pub(super) struct StepFactors {
    /// The bits of the `dt` the factors below belong to (None: not computed yet).
    dt_bits: Option<u64>,
    /// `exp(-dt/τ)` of each Kelvin creep branch while it creeps towards more set.
    pub kelvin_loading: Vec<f64>,
    /// `exp(-dt/(τ·recovery_factor))` of each Kelvin branch while it recovers.
    pub kelvin_recovering: Vec<f64>,
    /// `exp(-dt/τ)` of each fast viscoelastic branch.
    pub viscous_decay: Vec<f64>,
    /// The gain of a stress linear within the step: `τ/dt·(1 - exp(-dt/τ))` (1 when dt = 0).
    pub viscous_gain: Vec<f64>,
    /// `exp(-dt/softening_recovery_s)`: how much of the softening recovers in the step.
    pub softening_recovery: f64,
}

impl StepFactors {
    /// Make the factors those of `dt` (nothing to do when they already are).
    pub fn update(&mut self, p: &SpacerParams, dt: f64) {
        if self.dt_bits == Some(dt.to_bits()) {
            return;
        }
        self.kelvin_loading.clear();
        self.kelvin_recovering.clear();
        for &(_, tau) in &p.kelvin {
            self.kelvin_loading.push((-dt / tau).exp());
            self.kelvin_recovering
                .push((-dt / (tau * p.recovery_factor)).exp());
        }
        self.viscous_decay.clear();
        self.viscous_gain.clear();
        for &(_, tau) in &p.viscous {
            let decay = (-dt / tau).exp();
            self.viscous_decay.push(decay);
            self.viscous_gain.push(if dt > 0.0 {
                tau / dt * (1.0 - decay)
            } else {
                1.0
            });
        }
        self.softening_recovery = (-dt / p.softening_recovery_s).exp();
        self.dt_bits = Some(dt.to_bits());
    }
}
