//! The contact's geometry, one description for every node and tool: the force-control paper's eqs. 8–10.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

/// The contact direction n in the world (the way the hand moves to compress the surface) and the sensor's
/// mounting. The sensor reads the force F the surface exerts on the hand in its own frame; in the world
/// that is R_world←tool · R_tool←sensor · F, and the normal force is f = −F·n (eq. 8; ≥ 0 in contact:
/// the surface pushes back against n). Deformation and rate are the hand's position and velocity along n
/// from the contact position d (eqs. 9–10).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactGeometry {
    normal: Vector3<f64>,
    /// The sensor frame's rotation in the tool frame (/tf_static, or the URDF).
    pub tool_to_sensor: UnitQuaternion<f64>,
}

impl ContactGeometry {
    /// `normal` is normalised; `None` for a zero or non-finite direction.
    pub fn new(normal: Vector3<f64>, tool_to_sensor: UnitQuaternion<f64>) -> Option<Self> {
        let normal = normal.try_normalize(1e-9).filter(|n| n.iter().all(|v| v.is_finite()))?;
        Some(Self { normal, tool_to_sensor })
    }

    /// The LWR IV's: the sensor mounted as the URDF says.
    pub fn lwr4(normal: Vector3<f64>) -> Option<Self> {
        Self::new(normal, lwr4_tool_to_sensor().rotation)
    }

    pub fn normal(&self) -> Vector3<f64> {
        self.normal
    }

    /// The sensor's orientation in the world (sensor → world) for the tool's.
    pub fn sensor_rotation(&self, tool_rotation: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        tool_rotation * self.tool_to_sensor
    }

    /// The force on the hand in the world, from the sensor's reading in its frame.
    pub fn world_force(&self, tool_rotation: &UnitQuaternion<f64>, force_in_sensor: &Vector3<f64>) -> Vector3<f64> {
        self.sensor_rotation(tool_rotation) * force_in_sensor
    }

    /// The reading along the normal, −F·n, unclamped (in free space: the sensor's noise and bias).
    pub fn normal_reading(&self, world_force: &Vector3<f64>) -> f64 {
        -world_force.dot(&self.normal)
    }

    /// The contact's normal force f = max(−F·n, 0) (eq. 8).
    pub fn normal_force(&self, world_force: &Vector3<f64>) -> f64 {
        self.normal_reading(world_force).max(0.0)
    }

    /// A position's or velocity's component along n.
    pub fn along(&self, v: &Vector3<f64>) -> f64 {
        v.dot(&self.normal)
    }

    /// The deformation z = (r − d)·n of the hand at `position` r from the contact position d (eq. 9).
    pub fn deformation(&self, position: &Vector3<f64>, contact: &Vector3<f64>) -> f64 {
        self.along(&(position - contact))
    }

    /// The deformation rate ż = ṙ·n (eq. 10).
    pub fn rate(&self, velocity: &Vector3<f64>) -> f64 {
        self.along(velocity)
    }

    /// A vector's part across the surface, v − (v·n) n.
    pub fn across(&self, v: &Vector3<f64>) -> Vector3<f64> {
        v - self.along(v) * self.normal
    }
}

/// The sensor frame's pose in the tool frame of the LWR IV, from the URDF (/tf_static carries the same):
/// the one tool → sensor transform of the product.
pub fn lwr4_tool_to_sensor() -> Isometry3<f64> {
    use softcontact_dynamics::lwr4;
    let model = lwr4::model();
    let mut data = model.data();
    model.forward_kinematics(&mut data, &[0.0; 7]);
    let frame = |name| model.frame_id(name).expect("the LWR IV model has its tool and sensor frames");
    model.frame_pose(&data, frame(lwr4::TOOL_FRAME)).inverse() * model.frame_pose(&data, frame(lwr4::FT_SENSOR_FRAME))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deformation_rate_and_force_follow_the_papers_signs() {
        // The surface below the hand: n points down, the hand 3 mm below the contact position.
        let g = ContactGeometry::new(Vector3::new(0.0, 0.0, -2.0), UnitQuaternion::identity()).unwrap();
        let contact = Vector3::new(0.1, 0.2, 0.5);
        let pressed = contact + Vector3::new(0.004, 0.0, -0.003);
        assert!((g.deformation(&pressed, &contact) - 0.003).abs() < 1e-15);
        assert!((g.rate(&Vector3::new(1.0, 0.0, -0.02)) - 0.02).abs() < 1e-15);
        // The surface pushes the hand up: a positive normal force; a pull reads negative, clamped to 0.
        assert!((g.normal_force(&Vector3::new(0.5, 0.0, 30.0)) - 30.0).abs() < 1e-12);
        assert_eq!(g.normal_force(&Vector3::new(0.0, 0.0, -3.0)), 0.0);
        assert_eq!(g.normal_reading(&Vector3::new(0.0, 0.0, -3.0)), -3.0);
        assert_eq!(g.across(&Vector3::new(0.004, 0.0, -0.003)), Vector3::new(0.004, 0.0, 0.0));
        assert!(ContactGeometry::new(Vector3::zeros(), UnitQuaternion::identity()).is_none());
        assert!(ContactGeometry::new(Vector3::new(f64::NAN, 0.0, 1.0), UnitQuaternion::identity()).is_none());
    }
}
