//! The laws of the effects with memory, step by step: a Maxwell branch's update and an adhesion's share
//! of its pull-off force ([`crate::Effect::ViscoelasticRelaxation`], [`crate::Effect::QuasiLinearRelaxation`],
//! [`crate::Effect::Adhesion`]); [`crate::ContactModel::step_surface`] and the discrepancy workflow's
//! columns both call them, so that a fit and a simulation step alike. And the medium's drag on a reading
//! ([`crate::Effect::MediumDrag`], [`crate::Effect::SqueezeFilm`]), which the model's reading, its sensor
//! offset and the estimator's window refit all take from one place.

use crate::Effect;

impl Effect {
    /// What a drag of the medium adds to a reading at the deformation's rate `zdot` \[m/s\] and `gap` \[m\]
    /// from the surface: damping·(ż − tare_speed) for [`Effect::MediumDrag`], damping·reach/(gap + reach)·ż
    /// for [`Effect::SqueezeFilm`], 0 for any other effect.
    #[inline]
    pub fn drag(&self, zdot: f64, gap: f64) -> f64 {
        match *self {
            Effect::MediumDrag { damping, tare_speed } => damping * (zdot - tare_speed),
            Effect::SqueezeFilm { damping, reach } => damping * reach / (gap + reach) * zdot,
            _ => 0.0,
        }
    }

    /// The damping \[N·s/m\] with which a drag of the medium acts in contact (a squeeze film's whole
    /// damping there), 0 for any other effect: [`Effect::drag`]'s slope in ż at gap 0.
    #[inline]
    pub fn drag_in_contact(&self) -> f64 {
        match *self {
            Effect::MediumDrag { damping, .. } | Effect::SqueezeFilm { damping, .. } => damping,
            _ => 0.0,
        }
    }
}

/// The share of an [`crate::Effect::Adhesion`]'s pull-off force at deformation z \[m\] after the contact's deepest
/// deformation `peak`: min(1, (peak − z)/(peak + range)), 0 while pressing deeper.
#[inline]
pub fn adhesion_share(peak: f64, z: f64, range: f64) -> f64 {
    ((peak - z) / (peak + range)).clamp(0.0, 1.0)
}

/// The contact's deepest deformation after a step to z: deeper in contact, kept until z is `reach` \[m\]
/// beyond the surface (the farthest an adhesion holds on), then forgotten.
#[inline]
pub fn next_adhesion_peak(peak: Option<f64>, z: f64, reach: f64) -> Option<f64> {
    if z > 0.0 {
        Some(peak.map_or(z, |p| p.max(z)))
    } else if z < -reach {
        None
    } else {
        peak
    }
}

/// One step of a Maxwell branch, ṡ = k_m ż − s/τ, over dt: the branch force s after a step in which the
/// spring's force would change by `spring_change` = k_m·Δz, exact when the deformation changes linearly
/// over the step. The measured change of the deformation, not its rate held over the step, drives it: the
/// update is then second-order in the step (recordings at 100 Hz drive a 0.15 s branch), and the noise of
/// a measured deformation telescopes instead of accumulating. dt = 0 is a step of the deformation alone.
#[inline]
pub fn maxwell_step(s: f64, spring_change: f64, dt: f64, time_constant: f64) -> f64 {
    if dt <= 0.0 {
        return s + spring_change;
    }
    maxwell_step_with_decay(s, spring_change, dt, time_constant, (-dt / time_constant).exp())
}

/// [`maxwell_step`] with exp(−dt/τ) given (computed once for a series of equal steps); dt > 0.
#[inline]
pub fn maxwell_step_with_decay(s: f64, spring_change: f64, dt: f64, time_constant: f64, decay: f64) -> f64 {
    s * decay + spring_change * time_constant * (1.0 - decay) / dt
}
