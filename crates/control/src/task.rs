//! Task-space torques with null-space joint impedance (seed 001 eq. 15):
//!
//! τ = (J M⁻¹)^# (p̈_des − J̇q̇ + J M⁻¹ h − J M⁻¹ Jᵀ f) + N τ₀,  N = I − (J M⁻¹)^# (J M⁻¹),
//!
//! with f the wrench the contact exerts on the hand. The generalised inverse is the dynamically
//! consistent one, (J M⁻¹)^# = Jᵀ Λ with the task-space inertia Λ = (J M⁻¹ Jᵀ)⁻¹: among all torques that
//! produce p̈_des it is the one of least kinetic-energy weight (τᵀ M⁻¹ τ), and N τ₀ then produces no
//! task acceleration at all, so the posture impedance cannot disturb the force. Near a singularity Λ⁻¹
//! loses rank and Λ explodes; there the inversion is damped (Λ = V diag(σ / (σ² + λ²)) Vᵀ, λ growing as
//! the smallest eigenvalue σ falls below a threshold), trading task accuracy for bounded torques.

use nalgebra::{DMatrix, DVector, Matrix6, SymmetricEigen, Vector6};
use softcontact_dynamics::ControlTerms;

/// Singularity handling of the task-inertia inversion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    /// Eigenvalue of J M⁻¹ Jᵀ below which damping starts.
    pub threshold: f64,
    /// λ² at a full singularity.
    pub max: f64,
}

impl Default for Damping {
    fn default() -> Self {
        Self { threshold: 1e-4, max: 1e-4 }
    }
}

/// The torques of one control tick and what went into them.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskTorque {
    pub tau: DVector<f64>,
    /// The task-space part (without the null-space torque).
    pub task: DVector<f64>,
    /// The null-space projector N.
    pub projector: DMatrix<f64>,
    /// Whether the inversion was damped (near a singularity).
    pub damped: bool,
}

/// Eq. 15 for the control terms of one tick.
pub fn task_space_torque(
    terms: &ControlTerms<'_>,
    acceleration: &Vector6<f64>,
    contact_wrench: &Vector6<f64>,
    tau0: &DVector<f64>,
    damping: &Damping,
) -> TaskTorque {
    let j = terms.jacobian;
    let n = j.ncols();
    let a = j * terms.mass_matrix_inverse; // J M⁻¹, 6×n
    let inverse_inertia: Matrix6<f64> = {
        let m = &a * j.transpose();
        Matrix6::from_fn(|r, c| 0.5 * (m[(r, c)] + m[(c, r)]))
    };
    let eigen = SymmetricEigen::new(inverse_inertia);
    let smallest = eigen.eigenvalues.min();
    let lambda2 = if smallest >= damping.threshold {
        0.0
    } else {
        let s = (smallest / damping.threshold).max(0.0);
        (1.0 - s * s) * damping.max
    };
    let scaled = eigen.eigenvalues.map(|s| if lambda2 == 0.0 { 1.0 / s } else { s / (s * s + lambda2) });
    let inertia = eigen.eigenvectors * Matrix6::from_diagonal(&scaled) * eigen.eigenvectors.transpose(); // Λ
    let jt_lambda = j.transpose() * inertia; // (J M⁻¹)^#, n×6
    let b =
        acceleration - terms.bias_acceleration + &a * terms.nonlinear_effects - &a * (j.transpose() * contact_wrench);
    let task = &jt_lambda * b;
    let projector = DMatrix::identity(n, n) - &jt_lambda * &a;
    let tau = &task + &projector * tau0;
    TaskTorque { tau, task, projector, damped: lambda2 > 0.0 }
}
