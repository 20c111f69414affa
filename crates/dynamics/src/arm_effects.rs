//! The arm's own effects beyond its description — joint friction and a payload the URDF does not know
//! (the discrepancy workflow's `joint_friction` and `payload_mass`): one description for the simulator
//! that hides them, the workflow that names them, the file that carries them and the controller that
//! compensates them.
//!
//! Friction at joint i takes τ_f = bᵢ q̇ᵢ + cᵢ tanh(q̇ᵢ / v_s) from the motor's torque (viscous and
//! Coulomb, the sign smoothed over v_s = [`COULOMB_VELOCITY_SCALE`]). The payload is a point mass m at c
//! in the `lwr_flange` frame ([`crate::lwr4::FLANGE_FRAME`]), carried by [`Model::with_payload`].

use serde::{Deserialize, Serialize};

use crate::{BodyInertia, Error, Model, lwr4};

/// The velocity over which Coulomb friction's sign is smoothed [rad/s].
pub const COULOMB_VELOCITY_SCALE: f64 = 0.01;
/// The largest viscous friction a file may give a joint, as a share of the joint's effort limit per
/// rad/s: compensating more friction than the joint has is negative damping, and the light wrist joints
/// (38 N m) cannot take what the shoulder's (176 N m) can. The LWR's own lie well below.
pub const MAX_VISCOUS_SHARE: f64 = 0.01;
/// The largest Coulomb friction a file may give a joint, as a share of its effort limit (0.53 N m at
/// A1–A2, 0.3 N m at A3–A5, 0.11 N m at the wrist): fed forward on an arm without it, it pushes each
/// joint along its motion; at these the arm stays below a quarter of its velocity limits.
pub const MAX_COULOMB_SHARE: f64 = 0.003;
/// The heaviest payload a file may give \[kg\]: a load the description does not know (an adapter, cables),
/// not a tool — a tool belongs in the URDF. Compensated on an arm that does not carry it, a file's payload
/// pushes the hand with its full weight (14 kg at 0.5 m swung a wrist joint past its velocity limit;
/// 1.5 kg at 5 cm moves the hand about 1 cm across and takes 15 N off a press).
pub const MAX_PAYLOAD_MASS: f64 = 1.5;
/// The farthest a payload's centre may lie from the flange \[m\].
pub const MAX_PAYLOAD_REACH: f64 = 0.3;
/// The largest first moment m·|c| of a payload about the flange [kg m]: the torque it puts on the wrist.
pub const MAX_PAYLOAD_MOMENT: f64 = 0.075;

/// Viscous and Coulomb friction per joint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointFriction {
    /// bᵢ [N m s/rad].
    pub viscous: [f64; 7],
    /// cᵢ [N m].
    pub coulomb: [f64; 7],
}

impl JointFriction {
    /// The torque friction takes from joint `i` moving at `dq` [rad/s]: b q̇ + c tanh(q̇ / v_s).
    #[inline]
    pub fn torque(&self, i: usize, dq: f64) -> f64 {
        self.viscous[i] * dq + self.coulomb_part(i, dq, COULOMB_VELOCITY_SCALE)
    }

    /// The Coulomb part alone with its sign smoothed over `velocity_scale` [rad/s]: c tanh(q̇ / v).
    #[inline]
    pub fn coulomb_part(&self, i: usize, dq: f64, velocity_scale: f64) -> f64 {
        self.coulomb[i] * (dq / velocity_scale).tanh()
    }

    /// The largest coefficients a file may give the LWR IV's joints: viscous [N m s/rad] and Coulomb [N m].
    pub fn bounds() -> ([f64; 7], [f64; 7]) {
        let model = lwr4::model();
        let effort: [f64; 7] = std::array::from_fn(|i| model.joints[i].limits.effort);
        (effort.map(|e| MAX_VISCOUS_SHARE * e), effort.map(|e| MAX_COULOMB_SHARE * e))
    }

    pub fn validate(&self) -> Result<(), Error> {
        let (viscous, coulomb) = Self::bounds();
        let bad = |what: &str, v: &[f64; 7], max: &[f64; 7]| {
            (!v.iter().zip(max).all(|(x, m)| x.is_finite() && (0.0..=*m).contains(x))).then(|| {
                Error::ArmEffects(format!("joint friction: each {what} must be in [0, {max:.2?}] (got {v:?})"))
            })
        };
        match bad("viscous coefficient [N m s/rad]", &self.viscous, &viscous)
            .or_else(|| bad("Coulomb torque [N m]", &self.coulomb, &coulomb))
        {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// A point mass on the flange the description does not know.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Payload {
    /// \[kg\].
    pub mass: f64,
    /// Its centre in the `lwr_flange` frame \[m\].
    pub com: [f64; 3],
}

impl Payload {
    pub fn validate(&self) -> Result<(), Error> {
        let reach = self.com.iter().map(|c| c * c).sum::<f64>().sqrt();
        if !(self.mass.is_finite() && (0.0..=MAX_PAYLOAD_MASS).contains(&self.mass)) {
            return Err(Error::ArmEffects(format!("payload: mass {} kg outside [0, {MAX_PAYLOAD_MASS}]", self.mass)));
        }
        if !(reach.is_finite() && reach <= MAX_PAYLOAD_REACH && self.mass * reach <= MAX_PAYLOAD_MOMENT * (1.0 + 1e-12))
        {
            return Err(Error::ArmEffects(format!(
                "payload: centre {:?} m, farther than {MAX_PAYLOAD_REACH} m from the flange or a moment m·|c| beyond {MAX_PAYLOAD_MOMENT} kg m",
                self.com
            )));
        }
        Ok(())
    }

    /// `model` carrying the payload on its flange (the LWR IV's `lwr_flange`).
    pub fn carried_by(&self, model: &Model) -> Result<Model, Error> {
        self.validate()?;
        let load = BodyInertia::from_com(self.mass, self.com.into(), nalgebra::Matrix3::zeros());
        model.with_payload(model.frame_id(lwr4::FLANGE_FRAME)?, &load)
    }
}

/// The file `softcontact discrepancy --arm --out` writes and the deformation controller's
/// `arm_effects` parameter reads: what to compensate beyond the URDF.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmEffects {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_friction: Option<JointFriction>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload: Option<Payload>,
}

impl ArmEffects {
    pub fn validate(&self) -> Result<(), Error> {
        self.joint_friction.as_ref().map_or(Ok(()), JointFriction::validate)?;
        self.payload.as_ref().map_or(Ok(()), Payload::validate)
    }

    /// Reads and checks a file's text.
    pub fn from_yaml(text: &str) -> Result<Self, Error> {
        let effects: ArmEffects = serde_yaml_ng::from_str(text).map_err(|e| Error::ArmEffects(e.to_string()))?;
        effects.validate()?;
        Ok(effects)
    }

    pub fn to_yaml(&self) -> String {
        serde_yaml_ng::to_string(self).expect("arm effects always serialise")
    }

    /// The robot as it is: `model` with the payload, if any.
    pub fn model(&self, model: &Model) -> Result<Model, Error> {
        match &self.payload {
            Some(p) => p.carried_by(model),
            None => Ok(model.clone()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_round_trips_and_bad_ones_are_refused() {
        let effects = ArmEffects {
            joint_friction: Some(JointFriction { viscous: [0.3; 7], coulomb: [0.1; 7] }),
            payload: Some(Payload { mass: 1.2, com: [0.01, -0.02, 0.03] }),
        };
        assert_eq!(ArmEffects::from_yaml(&effects.to_yaml()).unwrap(), effects);
        assert_eq!(ArmEffects::from_yaml("{}").unwrap(), ArmEffects::default());
        for bad in [
            "joint_friction: {viscous: [.nan, 0, 0, 0, 0, 0, 0], coulomb: [0, 0, 0, 0, 0, 0, 0]}",
            "joint_friction: {viscous: [1e300, 0, 0, 0, 0, 0, 0], coulomb: [0, 0, 0, 0, 0, 0, 0]}",
            "joint_friction: {viscous: [0, 0, 0, 0, 0, 0, 0], coulomb: [-1, 0, 0, 0, 0, 0, 0]}",
            "joint_friction: {viscous: [0, 0, 0, 0, 0, 0, 0.5], coulomb: [0, 0, 0, 0, 0, 0, 0]}",
            "joint_friction: {viscous: [0, 0, 0], coulomb: [0, 0, 0]}",
            "payload: {mass: .inf, com: [0, 0, 0]}",
            "payload: {mass: -1, com: [0, 0, 0]}",
            "payload: {mass: 1, com: [0, 0, 1e300]}",
            "payload: {mass: 1, com: [0, 0, 0], extra: 1}",
            "payload: {mass: 100, com: [0, 0, 0]}",
            "payload: {mass: 14, com: [0.5, 0, 0]}",
            "payload: {mass: 2, com: [0.2, 0, 0]}",
            "payload: {mass: 3, com: [0, 0, 0]}",
        ] {
            assert!(ArmEffects::from_yaml(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn friction_opposes_motion_and_its_coulomb_part_saturates() {
        let f = JointFriction { viscous: [2.0; 7], coulomb: [0.5; 7] };
        assert_eq!(f.torque(0, 0.0), 0.0);
        assert!((f.torque(3, 1.0) - (2.0 + 0.5)).abs() < 1e-12);
        assert!((f.torque(3, -1.0) + (2.0 + 0.5)).abs() < 1e-12);
        assert!((f.torque(6, COULOMB_VELOCITY_SCALE) - (2.0 * 0.01 + 0.5 * 1f64.tanh())).abs() < 1e-12);
    }
}
