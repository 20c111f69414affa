//! The deformation control law of the force-control paper (eq. 11, and eq. 19 for a plain model): a force
//! command becomes a deformation command through the inverted contact model, and the deformation follows its
//! reference with a PD law on the acceleration.

use softcontact_contact::{ContactError, ContactModel};

use crate::quintic::Reference;

/// Gains of z̈_des = z̈_cmd + k_z (z_cmd − z) + k_ż (ż_cmd − ż).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeformationGains {
    /// k_z [1/s²].
    pub stiffness: f64,
    /// k_ż [1/s].
    pub damping: f64,
}

impl DeformationGains {
    /// Critically damped gains for a natural frequency ω [rad/s]: k_z = ω², k_ż = 2ω.
    pub fn critically_damped(omega: f64) -> Self {
        Self { stiffness: omega * omega, damping: 2.0 * omega }
    }
}

/// The desired deformation acceleration for the reference and the measured deformation and rate.
pub fn deformation_acceleration(gains: &DeformationGains, reference: &Reference, z: f64, zdot: f64) -> f64 {
    reference.acceleration + gains.stiffness * (reference.position - z) + gains.damping * (reference.velocity - zdot)
}

/// The deformation that holds force f at rest under the current model (the force-control paper's eq. 19).
pub fn force_to_deformation(model: &ContactModel, force: f64) -> Result<f64, ContactError> {
    model.deformation_for_force(force)
}
