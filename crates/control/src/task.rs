//! Task-space torques with null-space joint impedance (the force-control paper's eq. 15):
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

/// Preallocated buffers of eq. 15 for an n-joint arm: after `new`, a tick allocates nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskTorque {
    pub tau: DVector<f64>,
    /// The task-space part (without the null-space torque).
    pub task: DVector<f64>,
    /// The null-space projector N.
    pub projector: DMatrix<f64>,
    /// Whether the last inversion was damped (near a singularity).
    pub damped: bool,
    /// J M⁻¹ (6×n) and (J M⁻¹)^# = Jᵀ Λ (n×6).
    a: DMatrix<f64>,
    inverse: DMatrix<f64>,
    jt_f: DVector<f64>,
}

impl TaskTorque {
    pub fn new(n: usize) -> Self {
        Self {
            tau: DVector::zeros(n),
            task: DVector::zeros(n),
            projector: DMatrix::zeros(n, n),
            damped: false,
            a: DMatrix::zeros(6, n),
            inverse: DMatrix::zeros(n, 6),
            jt_f: DVector::zeros(n),
        }
    }

    /// Eq. 15 for the control terms of one tick, into these buffers (no allocation).
    pub fn compute(
        &mut self,
        terms: &ControlTerms<'_>,
        acceleration: &Vector6<f64>,
        contact_wrench: &Vector6<f64>,
        tau0: &DVector<f64>,
        damping: &Damping,
    ) {
        let j = terms.jacobian;
        let minv = terms.mass_matrix_inverse;
        let n = j.ncols();
        for r in 0..6 {
            for c in 0..n {
                self.a[(r, c)] = (0..n).map(|k| j[(r, k)] * minv[(k, c)]).sum();
            }
        }
        let inverse_inertia = Matrix6::from_fn(|r, s| (0..n).map(|c| self.a[(r, c)] * j[(s, c)]).sum::<f64>());
        let symmetric = 0.5 * (inverse_inertia + inverse_inertia.transpose());
        let eigen = SymmetricEigen::new(symmetric);
        let smallest = eigen.eigenvalues.min();
        let lambda2 = if smallest >= damping.threshold {
            0.0
        } else {
            let s = (smallest / damping.threshold).max(0.0);
            (1.0 - s * s) * damping.max
        };
        let scaled = eigen.eigenvalues.map(|s| if lambda2 == 0.0 { 1.0 / s } else { s / (s * s + lambda2) });
        let inertia = eigen.eigenvectors * Matrix6::from_diagonal(&scaled) * eigen.eigenvectors.transpose(); // Λ
        for c in 0..n {
            for r in 0..6 {
                self.inverse[(c, r)] = (0..6).map(|s| j[(s, c)] * inertia[(s, r)]).sum();
            }
            self.jt_f[c] = (0..6).map(|r| j[(r, c)] * contact_wrench[r]).sum();
        }
        let h = terms.nonlinear_effects;
        let b = Vector6::from_fn(|r, _| {
            acceleration[r] - terms.bias_acceleration[r]
                + (0..n).map(|c| self.a[(r, c)] * (h[c] - self.jt_f[c])).sum::<f64>()
        });
        for c in 0..n {
            self.task[c] = (0..6).map(|r| self.inverse[(c, r)] * b[r]).sum();
            for d in 0..n {
                let identity = if c == d { 1.0 } else { 0.0 };
                self.projector[(c, d)] = identity - (0..6).map(|r| self.inverse[(c, r)] * self.a[(r, d)]).sum::<f64>();
            }
        }
        for c in 0..n {
            self.tau[c] = self.task[c] + (0..n).map(|d| self.projector[(c, d)] * tau0[d]).sum::<f64>();
        }
        self.damped = lambda2 > 0.0;
    }
}

/// Eq. 15 for the control terms of one tick (allocates its buffers; a controller keeps a
/// [`TaskTorque`] and calls [`TaskTorque::compute`]).
pub fn task_space_torque(
    terms: &ControlTerms<'_>,
    acceleration: &Vector6<f64>,
    contact_wrench: &Vector6<f64>,
    tau0: &DVector<f64>,
    damping: &Damping,
) -> TaskTorque {
    let mut out = TaskTorque::new(terms.jacobian.ncols());
    out.compute(terms, acceleration, contact_wrench, tau0, damping);
    out
}
