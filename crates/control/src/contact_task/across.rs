//! Across the surface and in orientation: the hand's hold at its start pose, moved by
//! [`DeformationController::command_across`] within [`MAX_LATERAL`] and [`MAX_TILT`] (from the start and
//! from the very first start) on a rest-to-rest quintic whose velocity and acceleration feed forward.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::{ControlError, DeformationController};
use crate::Quintic;

/// Farthest [`DeformationController::command_across`] moves the hand across the surface from its start
/// \[m\]. A lateral offset is a test excitation (a tangential load on the surface: it sticks, then slips;
/// the sensor's crosstalk), not a motion planner: a few centimetres are enough for that, keep the hand
/// on the sample and the arm near its start posture, where the null-space impedance holds the elbow.
pub const MAX_LATERAL: f64 = 0.03;
/// Largest tilt of the hand from its start orientation \[rad\] (20°): enough to change the sensor's
/// orientation to gravity measurably — along the pushing axis the tool's weight changes by 1 − cos 20° ≈
/// 6 % (a tool mass error of 0.6 kg shows 0.36 N there), across it by 34 % — small enough that the wrist
/// stays far from its limits. (Tilt in free space: in contact the hand's edge would dig into the surface.)
pub const MAX_TILT: f64 = 0.35;
/// Fastest tilt [rad/s] (the quintic's peak, 15/8 · angle / duration): the orientation PD and the
/// torque-rate limit follow it without a jolt, and the sensor's gravity reading changes slowly against
/// the contact dynamics. (The lateral speed is bounded by the limits' `max_deformation_rate`.)
pub const MAX_TILT_RATE: f64 = 0.5;
/// A lateral offset's component along n [m] beyond which it is refused: it must be across the surface
/// (the normal is commanded by deformation and force commands only); below it is rounding and is removed.
pub(super) const ACROSS_NORMAL_TOLERANCE: f64 = 1e-6;
/// Peak speed of a rest-to-rest quintic per unit distance and second: ṡ(T/2) = 15/(8T).
pub(super) const QUINTIC_PEAK: f64 = 15.0 / 8.0;

/// A move of the hold across the surface and in orientation: the lateral offset and the tilt (a rotation
/// vector in the world) go on straight lines from `from` to `to` with `progress`, a rest-to-rest quintic
/// 0 → 1 that began at controller time `since`. With `from == to` it is a hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct AcrossMove {
    pub(super) from: (Vector3<f64>, Vector3<f64>),
    pub(super) to: (Vector3<f64>, Vector3<f64>),
    pub(super) progress: Quintic,
    pub(super) since: f64,
}

/// The reference across the surface and in orientation at one instant: lateral offset from the start
/// position \[m\], its velocity and acceleration; tilt (rotation vector, R_ref = exp(tilt) · R_start), the
/// world angular velocity and acceleration of R_ref.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcrossReference {
    pub lateral: Vector3<f64>,
    pub velocity: Vector3<f64>,
    pub acceleration: Vector3<f64>,
    pub tilt: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
    pub angular_acceleration: Vector3<f64>,
}

impl AcrossReference {
    pub const HOLD_START: Self = Self {
        lateral: Vector3::new(0.0, 0.0, 0.0),
        velocity: Vector3::new(0.0, 0.0, 0.0),
        acceleration: Vector3::new(0.0, 0.0, 0.0),
        tilt: Vector3::new(0.0, 0.0, 0.0),
        angular_velocity: Vector3::new(0.0, 0.0, 0.0),
        angular_acceleration: Vector3::new(0.0, 0.0, 0.0),
    };
}

impl AcrossMove {
    pub(super) fn at(&self, t: f64) -> AcrossReference {
        let s = self.progress.at(t - self.since);
        let (lateral, tilt) = (self.to.0 - self.from.0, self.to.1 - self.from.1);
        let theta = self.from.1 + s.position * tilt;
        // The world angular velocity of exp(θ(t)) is J_l(θ)·θ̇. Its acceleration J_l·θ̈ + J̇_l·θ̇ drops
        // the second term: with θ on a straight line it is, to leading order, (1/6)·ṡ²·Δ×(θ×Δ): zero
        // when θ ∥ Δ (every move from the start), below 1 % of the first's peak within the tilt limits.
        let jacobian = left_jacobian(&theta);
        AcrossReference {
            lateral: self.from.0 + s.position * lateral,
            velocity: s.velocity * lateral,
            acceleration: s.acceleration * lateral,
            tilt: theta,
            angular_velocity: s.velocity * (jacobian * tilt),
            angular_acceleration: s.acceleration * (jacobian * tilt),
        }
    }
}

/// The left Jacobian of SO(3) at θ: the world angular velocity of exp(θ(t)) is J_l(θ)·θ̇. Its singular
/// values are 1 (along θ) and |sin(φ/2)/(φ/2)| ≤ 1, so |ω| ≤ |θ̇|.
fn left_jacobian(theta: &Vector3<f64>) -> Matrix3<f64> {
    let phi2 = theta.norm_squared();
    let phi = phi2.sqrt();
    let (a, b) = if phi < 1e-4 {
        (0.5 - phi2 / 24.0, 1.0 / 6.0 - phi2 / 120.0)
    } else {
        ((1.0 - phi.cos()) / phi2, (phi - phi.sin()) / (phi2 * phi))
    };
    let k = theta.cross_matrix();
    Matrix3::identity() + a * k + b * k * k
}

impl DeformationController {
    /// The reference across the surface and in orientation now.
    pub fn across_reference(&self) -> AcrossReference {
        self.across.map_or(AcrossReference::HOLD_START, |m| m.at(self.time))
    }

    /// Moves the hand's hold across the surface and its orientation: a quintic of `duration` seconds from
    /// the present lateral/tilt reference to `lateral` \[m\] (a world vector ⊥ n, from the start position;
    /// its n component is refused if not ~0) and `tilt` \[rad\] (a rotation vector in the world, applied to
    /// the start orientation: R_ref = exp(tilt) · R_start). The normal part (deformation/force command) is
    /// left as it is. Allowed in free space and in contact; a command during a move starts from where the
    /// reference is then (at rest). Refused, and the present move kept, for inputs that are not finite,
    /// offsets beyond [`MAX_LATERAL`] or [`MAX_TILT`], a duration outside the limits, or a peak speed
    /// beyond the limits' `max_deformation_rate` or [`MAX_TILT_RATE`].
    pub fn command_across(
        &mut self,
        lateral: Vector3<f64>,
        tilt: Vector3<f64>,
        duration: f64,
    ) -> Result<(), ControlError> {
        if !lateral.iter().all(|v| v.is_finite()) {
            return Err(ControlError::NonFinite("the lateral offset"));
        }
        if !tilt.iter().all(|v| v.is_finite()) {
            return Err(ControlError::NonFinite("the tilt"));
        }
        if !duration.is_finite() {
            return Err(ControlError::NonFinite("the move duration"));
        }
        let n = self.geometry.normal();
        let along = lateral.dot(&n);
        if along.abs() > ACROSS_NORMAL_TOLERANCE {
            return Err(ControlError::Across {
                what: "the lateral offset's component along the normal [m]",
                value: along,
                limit: ACROSS_NORMAL_TOLERANCE,
            });
        }
        let lateral = lateral - along * n;
        if lateral.norm() > MAX_LATERAL {
            return Err(ControlError::Across {
                what: "the lateral offset [m]",
                value: lateral.norm(),
                limit: MAX_LATERAL,
            });
        }
        if tilt.norm() > MAX_TILT {
            return Err(ControlError::Across { what: "the tilt [rad]", value: tilt.norm(), limit: MAX_TILT });
        }
        // The same bounds from the first start (a restart takes a new start where the hand is).
        if let (Some((r0, q0, _)), Some((origin, q_origin))) = (self.start, self.origin) {
            let away = r0 + lateral - origin;
            let away = (away - away.dot(&n) * n).norm();
            // (1e-9: the rounding of composing the start with the move, not an allowance.)
            if away > MAX_LATERAL + 1e-9 {
                return Err(ControlError::Across {
                    what: "the lateral offset from the first start [m]",
                    value: away,
                    limit: MAX_LATERAL,
                });
            }
            let turned = (UnitQuaternion::from_scaled_axis(tilt) * q0).angle_to(&q_origin);
            if turned > MAX_TILT + 1e-9 {
                return Err(ControlError::Across {
                    what: "the tilt from the first start [rad]",
                    value: turned,
                    limit: MAX_TILT,
                });
            }
        }
        let limits = &self.config.limits;
        let duration = limits.check_duration(duration)?;
        let now = self.across_reference();
        limits.check_rate(QUINTIC_PEAK * (lateral - now.lateral).norm() / duration)?;
        let tilt_rate = QUINTIC_PEAK * (tilt - now.tilt).norm() / duration;
        if !(tilt_rate <= MAX_TILT_RATE) {
            return Err(ControlError::Across {
                what: "the tilt speed [rad/s]",
                value: tilt_rate,
                limit: MAX_TILT_RATE,
            });
        }
        let progress = Quintic::rest_to_rest(0.0, 1.0, duration).ok_or(ControlError::Duration)?;
        self.across =
            Some(AcrossMove { from: (now.lateral, now.tilt), to: (lateral, tilt), progress, since: self.time });
        Ok(())
    }

    /// Stops the move across the surface where its reference is now.
    pub(super) fn hold_across(&mut self) {
        if let Some(m) = self.across.as_mut() {
            let now = m.at(self.time);
            m.from = (now.lateral, now.tilt);
            m.to = m.from;
        }
    }
}
