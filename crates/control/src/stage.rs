//! The arm as a stiff displacement stage (the snake paper's loading paths): the tool follows a position
//! reference at a fixed orientation, by computed torque with integral action.
//!
//! A Cartesian impedance of a few N/mm would give way more than the whole indentation of a specimen whose
//! tangent stiffness reaches ≈ 18 N/mm, so the stage is made stiff in three ways:
//!
//! - the reference is turned into joint positions and velocities by damped least squares, from the
//!   previous cycle's solution (two Newton steps: the reference moves micrometres per cycle);
//! - τ = M(q) (K_p e + K_d ė + K_i ∫e) + h(q, q̇) − Jᵀ f: with the model exact, every joint's error obeys
//!   ë + K_d ė + K_p e + K_i ∫e = 0 at the chosen bandwidth ω (K_p = 3ω², K_d = 3ω, K_i = ω³: a triple
//!   pole at −ω);
//! - the contact force f measured by the F/T sensor is fed forward (the −Jᵀ f of the inverse dynamics),
//!   and the integral takes up what the model and the sensor get wrong.
//!
//! δ is measured from the tool's actual pose, never from the reference. Pure: no clock — `dt` is passed in.

use nalgebra::{Dyn, Matrix6, Matrix6xX, OMatrix, U6, UnitQuaternion, Vector3, Vector6};
use softcontact_dynamics::{Axes, Data, ExternalWrench, FrameId, FrameMotion, Model};

/// Why the stage refused a cycle (the caller holds the arm).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageError {
    #[error("stage input {0} is not a finite number")]
    NonFinite(&'static str),
    #[error("the reference is out of the arm's reach: {0:.2e} m left after the inverse kinematics")]
    Unreachable(f64),
}

/// The stage: its model and workspace, the held orientation, and the joint reference and integral.
pub struct PositionStage {
    model: Model,
    data: Data,
    tool: FrameId,
    jacobian: Matrix6xX<f64>,
    orientation: UnitQuaternion<f64>,
    q_ref: [f64; 7],
    integral: [f64; 7],
    gains: [f64; 3],
}

/// The most the integral of one joint's error may hold [rad·s] (it never needs more than the model's
/// error over a second; a bound keeps a blocked joint from winding it up).
const INTEGRAL_LIMIT: f64 = 0.01;
/// Damping of the least-squares inverse kinematics [m].
const IK_DAMPING: f64 = 1e-4;

impl PositionStage {
    /// Holds the tool where it is at `q`, with bandwidth `omega` [rad/s] (ω·dt ≪ 1 at the cycle used).
    pub fn new(model: Model, tool: FrameId, q: &[f64; 7], omega: f64) -> Self {
        let mut data = model.data();
        model.forward_kinematics(&mut data, q);
        let orientation = model.frame_pose(&data, tool).rotation;
        let jacobian = Matrix6xX::zeros(model.dof());
        Self {
            model,
            data,
            tool,
            jacobian,
            orientation,
            q_ref: *q,
            integral: [0.0; 7],
            gains: [3.0 * omega * omega, 3.0 * omega, omega.powi(3)],
        }
    }

    /// The tool's position at `q` [m, world].
    pub fn tool_position(&mut self, q: &[f64; 7]) -> Vector3<f64> {
        self.model.forward_kinematics(&mut self.data, q);
        self.model.frame_pose(&self.data, self.tool).translation.vector
    }

    /// The tool's pose and twist at the measurement (q, q̇), on the stage's model: the kinematics its
    /// update reuses at the same q.
    pub fn tool_motion(&mut self, q: &[f64; 7], dq: &[f64; 7]) -> FrameMotion {
        self.model.frame_motion(&mut self.data, q, dq, self.tool)
    }

    /// The joint reference of the last cycle.
    pub fn joint_reference(&self) -> &[f64; 7] {
        &self.q_ref
    }

    /// Joint torques (total, gravity included) for the measurement (q, q̇) that drive the tool to
    /// `position` moving at `velocity` (world) with the held orientation, the contact force on the hand
    /// `force` (world, measured) fed forward; `dt` the time since the last cycle \[s\].
    pub fn update(
        &mut self,
        q: &[f64; 7],
        dq: &[f64; 7],
        position: &Vector3<f64>,
        velocity: &Vector3<f64>,
        force: &Vector3<f64>,
        dt: f64,
    ) -> Result<[f64; 7], StageError> {
        let finite =
            |name, v: &[f64]| if v.iter().all(|x| x.is_finite()) { Ok(()) } else { Err(StageError::NonFinite(name)) };
        finite("q", q)?;
        finite("q̇", dq)?;
        finite("position", position.as_slice())?;
        finite("velocity", velocity.as_slice())?;
        finite("force", force.as_slice())?;
        if !(dt.is_finite() && dt > 0.0 && dt < 1.0) {
            return Err(StageError::NonFinite("dt"));
        }
        // Inverse kinematics from the last reference: position and orientation error, damped least squares.
        let mut residual = f64::INFINITY;
        for _ in 0..2 {
            let error = self.pose_error(position);
            residual = error.fixed_rows::<3>(0).norm();
            let step = self.damped_pseudo_inverse() * error;
            for (q, s) in self.q_ref.iter_mut().zip(step.iter()) {
                *q += s;
            }
        }
        if residual > 1e-3 {
            return Err(StageError::Unreachable(residual));
        }
        let twist = Vector6::new(velocity.x, velocity.y, velocity.z, 0.0, 0.0, 0.0);
        let dq_ref = self.damped_pseudo_inverse() * twist;
        let [kp, kd, ki] = self.gains;
        let mut ddq = [0.0; 7];
        for i in 0..7 {
            let e = self.q_ref[i] - q[i];
            self.integral[i] = (self.integral[i] + e * dt).clamp(-INTEGRAL_LIMIT, INTEGRAL_LIMIT);
            ddq[i] = kp * e + kd * (dq_ref[i] - dq[i]) + ki * self.integral[i];
        }
        let contact = ExternalWrench { frame: self.tool, force: *force, torque: Vector3::zeros() };
        let tau = self.model.rnea(&mut self.data, q, dq, &ddq, Some(&contact));
        let mut out = [0.0; 7];
        out.copy_from_slice(tau.as_slice());
        finite("torque", &out)?;
        Ok(out)
    }

    /// The tool's pose error at `q_ref` (linear; angular as a rotation vector), its Jacobian computed.
    fn pose_error(&mut self, position: &Vector3<f64>) -> Vector6<f64> {
        self.model.forward_kinematics(&mut self.data, &self.q_ref);
        let pose = self.model.frame_pose(&self.data, self.tool);
        self.model.frame_jacobian(&self.data, self.tool, Axes::World, &mut self.jacobian);
        let linear = position - pose.translation.vector;
        let angular = (self.orientation * pose.rotation.inverse()).scaled_axis();
        Vector6::new(linear.x, linear.y, linear.z, angular.x, angular.y, angular.z)
    }

    /// Jᵀ (J Jᵀ + λ² I)⁻¹ of the Jacobian last computed.
    fn damped_pseudo_inverse(&self) -> OMatrix<f64, Dyn, U6> {
        let j = &self.jacobian;
        let jjt: Matrix6<f64> = j * j.transpose() + Matrix6::identity() * (IK_DAMPING * IK_DAMPING);
        let inverse = jjt.try_inverse().unwrap_or_else(Matrix6::zeros);
        j.transpose() * inverse
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_dynamics::lwr4;

    /// The hand facing down in front of the robot: A2 30°, A4 −80°, A6 70°.
    const Q: [f64; 7] = {
        let deg = std::f64::consts::PI / 180.0;
        [0.0, 30.0 * deg, 0.0, -80.0 * deg, 0.0, 70.0 * deg, 0.0]
    };

    /// Integrates the arm under the stage's torques and a spring pushing the tool back along z (a contact
    /// of `stiffness` N/m below `surface`), semi-implicit Euler at 0.1 ms with the torque held for 1 ms;
    /// the tool moving down 2 mm at 1 mm/s then sideways. The RMS and largest distance from the reference.
    fn track(stiffness: f64) -> (f64, f64) {
        let model = lwr4::model();
        let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
        let mut stage = PositionStage::new(lwr4::model(), tool, &Q, 150.0);
        let start = stage.tool_position(&Q);
        let mut data = model.data();
        let (mut q, mut dq) = (Q, [0.0; 7]);
        let (mut sum, mut worst, mut n) = (0.0, 0.0f64, 0);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let (down, side) = ((t.min(2.0)) * 1e-3, (t - 2.0).max(0.0) * 1e-3);
            let v = Vector3::new(if t >= 2.0 { 1e-3 } else { 0.0 }, 0.0, if t < 2.0 { -1e-3 } else { 0.0 });
            let reference = start + Vector3::new(side, 0.0, -down);
            let position = stage.tool_position(&q);
            let force = |p: Vector3<f64>| Vector3::new(0.0, 0.0, stiffness * (start.z - p.z).max(0.0));
            let tau = stage.update(&q, &dq, &reference, &v, &force(position), 1e-3).unwrap();
            if k > 100 {
                let e = (position - reference).norm();
                (sum, worst, n) = (sum + e * e, worst.max(e), n + 1);
            }
            for _ in 0..10 {
                model.forward_kinematics(&mut data, &q);
                let p = model.frame_pose(&data, tool).translation.vector;
                let w = ExternalWrench { frame: tool, force: force(p), torque: Vector3::zeros() };
                let ddq = model.forward_dynamics(&mut data, &q, &dq, &tau, Some(&w)).unwrap().clone();
                for i in 0..7 {
                    dq[i] += 1e-4 * ddq[i];
                    q[i] += 1e-4 * dq[i];
                }
            }
        }
        ((sum / n as f64).sqrt(), worst)
    }

    #[test]
    fn the_tool_tracks_a_path_within_a_micrometre_against_a_stiff_contact() {
        // 36 N/mm, twice the half-ball's tangent stiffness at 25 N (72 N at the end).
        let (rms, worst) = track(36e3);
        eprintln!("stage: RMS {:.3} µm, worst {:.3} µm", rms * 1e6, worst * 1e6);
        assert!(rms < 1e-6 && worst < 3e-6, "RMS {rms:e}, worst {worst:e}");
    }

    #[test]
    fn non_finite_inputs_are_refused() {
        let model = lwr4::model();
        let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
        let mut stage = PositionStage::new(lwr4::model(), tool, &Q, 150.0);
        let p = stage.tool_position(&Q);
        let z = Vector3::zeros();
        let mut bad_q = Q;
        bad_q[3] = f64::NAN;
        assert!(stage.update(&bad_q, &[0.0; 7], &p, &z, &z, 1e-3).is_err());
        assert!(stage.update(&Q, &[0.0; 7], &p, &z, &Vector3::new(0.0, f64::INFINITY, 0.0), 1e-3).is_err());
        assert!(stage.update(&Q, &[0.0; 7], &p, &z, &z, f64::NAN).is_err());
        assert!(stage.update(&Q, &[0.0; 7], &(p + Vector3::new(5.0, 0.0, 0.0)), &z, &z, 1e-3).is_err());
    }
}
