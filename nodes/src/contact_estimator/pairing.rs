//! Pairing each force reading with the newest tool pose and twist.

use nalgebra::{UnitQuaternion, Vector3};

use crate::geometry::ContactGeometry;

/// One force reading made into what the estimator takes (docs/conventions.md): the sensor's force
/// rotated into the world through the newest tool pose, its normal component f = −F·n ≥ 0, and the
/// tool's position and velocity. The node and `softcontact identify` pair readings the same way.
#[derive(Debug, Clone)]
pub struct ForcePairing {
    /// The normal and the sensor's mounting (its `tool_to_sensor` from /tf_static, or the URDF).
    pub geometry: ContactGeometry,
    stale_after: f64,
    /// Tool position, rotation and the time they were taken [s].
    pose: Option<(Vector3<f64>, UnitQuaternion<f64>, f64)>,
    velocity: Vector3<f64>,
    /// Without twists the velocity is the difference of successive poses.
    twists_seen: bool,
}

/// A force reading paired with the tool's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Paired {
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    /// The contact's normal force, f ≥ 0 \[N\].
    pub normal_force: f64,
    /// The sensor's reading along the normal, unclamped \[N\]: in free space its noise and bias.
    pub normal_reading: f64,
    /// The whole force on the hand in the world \[N\] and the sensor's orientation (sensor → world).
    pub force: Vector3<f64>,
    pub sensor_rotation: UnitQuaternion<f64>,
}

impl ForcePairing {
    /// `None` for a zero or non-finite normal.
    pub fn new(tool_to_sensor: UnitQuaternion<f64>, normal: Vector3<f64>, stale_after: f64) -> Option<Self> {
        Some(Self {
            geometry: ContactGeometry::new(normal, tool_to_sensor)?,
            stale_after,
            pose: None,
            velocity: Vector3::zeros(),
            twists_seen: false,
        })
    }

    pub fn pose(&mut self, t: f64, position: Vector3<f64>, rotation: UnitQuaternion<f64>) {
        if !self.twists_seen
            && let Some((previous, _, t0)) = self.pose
            && t > t0
        {
            self.velocity = (position - previous) / (t - t0);
        }
        self.pose = Some((position, rotation, t));
    }

    pub fn twist(&mut self, linear: Vector3<f64>) {
        self.twists_seen = true;
        self.velocity = linear;
    }

    /// The reading at `t` of the force on the sensor in its frame; `None` without a pose at most
    /// `stale_after` old, or for a non-finite force.
    pub fn force(&self, t: f64, force_in_sensor: Vector3<f64>) -> Option<Paired> {
        let (position, rotation, seen) = self.pose?;
        if t - seen > self.stale_after || !force_in_sensor.iter().all(|v| v.is_finite()) {
            return None;
        }
        let geometry = &self.geometry;
        let sensor_rotation = geometry.sensor_rotation(&rotation);
        let force = geometry.world_force(&rotation, &force_in_sensor);
        let normal_reading = geometry.normal_reading(&force);
        Some(Paired {
            position,
            velocity: self.velocity,
            normal_force: normal_reading.max(0.0),
            normal_reading,
            force,
            sensor_rotation,
        })
    }
}
