//! geometry_msgs ↔ nalgebra and the fixed frames below the tool from /tf_static. The contact's geometry
//! itself (eqs. 8–10 of the force-control paper) is the control crate's [`ContactGeometry`].

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
pub use softcontact_control::contact_task::{ContactGeometry, lwr4_tool_to_sensor};
use softcontact_msgs::geometry_msgs::{Pose, Vector3 as Vector3Msg};
use softcontact_msgs::tf2_msgs::TFMessage;

pub fn vector_of(v: &Vector3Msg) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// Position and rotation of a pose (the quaternion is normalised).
pub fn pose_of(p: &Pose) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let o = p.orientation;
    (
        Vector3::new(p.position.x, p.position.y, p.position.z),
        UnitQuaternion::from_quaternion(Quaternion::new(o.w, o.x, o.y, o.z)),
    )
}

/// The pose of frame `child` in frame `ancestor` through the chain of static transforms, if the
/// transforms connect them.
pub fn static_transform(transforms: &[&TFMessage], ancestor: &str, child: &str) -> Option<Isometry3<f64>> {
    let parent_of = |frame: &str| {
        transforms.iter().flat_map(|m| &m.transforms).find(|t| t.child_frame_id == frame).map(|t| {
            let (r, p) = (t.transform.rotation, t.transform.translation);
            let rotation = UnitQuaternion::from_quaternion(Quaternion::new(r.w, r.x, r.y, r.z));
            (t.header.frame_id.as_str(), Isometry3::from_parts(Translation3::new(p.x, p.y, p.z), rotation))
        })
    };
    let mut pose = Isometry3::identity();
    let mut frame = child;
    for _ in 0..32 {
        if frame == ancestor {
            return Some(pose);
        }
        let (parent, t) = parent_of(frame)?;
        pose = t * pose;
        frame = parent;
    }
    None
}

/// The rotation of frame `child` in frame `ancestor` ([`static_transform`]'s).
pub fn static_rotation(transforms: &[&TFMessage], ancestor: &str, child: &str) -> Option<UnitQuaternion<f64>> {
    static_transform(transforms, ancestor, child).map(|t| t.rotation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_msgs::geometry_msgs::{Quaternion as Q, Transform, TransformStamped};
    use softcontact_msgs::std_msgs::Header;

    fn tf(parent: &str, child: &str, r: UnitQuaternion<f64>) -> TransformStamped {
        TransformStamped {
            header: Header { frame_id: parent.into(), ..Default::default() },
            child_frame_id: child.into(),
            transform: Transform { rotation: Q { x: r.i, y: r.j, z: r.k, w: r.w }, ..Default::default() },
        }
    }

    #[test]
    fn chains_compose_parent_first() {
        let a = UnitQuaternion::from_euler_angles(0.3, 0.0, 0.0);
        let b = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
        let m1 = TFMessage { transforms: vec![tf("tool", "hand", a)] };
        let m2 = TFMessage { transforms: vec![tf("hand", "sensor", b)] };
        let r = static_rotation(&[&m1, &m2], "tool", "sensor").unwrap();
        assert!((r.angle_to(&(a * b))) < 1e-12);
        let v = Vector3::new(0.1, 0.2, 0.3);
        assert!((r * v - a * (b * v)).norm() < 1e-12);
        assert_eq!(static_rotation(&[&m1], "tool", "sensor"), None);
        assert_eq!(static_rotation(&[&m1, &m2], "sensor", "sensor"), Some(UnitQuaternion::identity()));
    }

    #[test]
    fn transforms_compose_translations_in_the_parent_frame() {
        use softcontact_msgs::geometry_msgs::Vector3 as V;
        let quarter = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let mut hand = tf("tool", "hand", quarter);
        hand.transform.translation = V { x: 0.1, y: 0.0, z: 0.0 };
        let mut sensor = tf("hand", "sensor", UnitQuaternion::identity());
        sensor.transform.translation = V { x: 0.0, y: 0.0, z: 0.2 };
        let m = TFMessage { transforms: vec![hand, sensor] };
        let t = static_transform(&[&m], "tool", "sensor").unwrap();
        // The sensor's origin: 0.1 along the tool's x, then 0.2 along the hand's z (the tool's z too).
        assert!((t.translation.vector - Vector3::new(0.1, 0.0, 0.2)).norm() < 1e-12);
        // A point 1 m along the sensor's x lies along the tool's y (the quarter turn about z).
        assert!((t * nalgebra::Point3::new(1.0, 0.0, 0.0) - nalgebra::Point3::new(0.1, 1.0, 0.2)).norm() < 1e-12);
    }
}
