//! Pairing each force reading with the tool pose and twist of the reading's own time.
//!
//! Readings, poses and twists are paired by their stamps, not by when they arrive: a middleware under
//! load delivers each stream in bursts, and a burst of wrenches paired with the newest pose of the
//! poses' burst puts every reading but the last at the wrong deformation. The last [`HISTORY`] poses and
//! twists are kept; a reading between two poses takes the pose interpolated at its stamp, a reading
//! newer than every pose the newest one (at most `stale_after` older than the reading).

use std::collections::VecDeque;

use nalgebra::{UnitQuaternion, Vector3};

use crate::geometry::ContactGeometry;

/// Poses and twists kept: half a second of 1 kHz streams.
pub const HISTORY: usize = 512;

/// The largest force a reading may carry \[N\]: a thousand times beyond the product's 10 kN. A reading
/// past it, or not finite, is a corrupted datagram or a wrong unit, not a measurement; it is left out and
/// counted, as a table refuses such a cell.
pub const MAX_READABLE_FORCE: f64 = 1e7;

/// One force reading made into what the estimator takes (docs/conventions.md): the sensor's force
/// rotated into the world through the tool pose at the reading's stamp, its normal component
/// f = −F·n ≥ 0, and the tool's position and velocity. The node and `softcontact identify` pair readings
/// the same way.
#[derive(Debug, Clone)]
pub struct ForcePairing {
    /// The normal and the sensor's mounting (its `tool_to_sensor` from /tf_static, or the URDF).
    pub geometry: ContactGeometry,
    stale_after: f64,
    /// Tool position and rotation by stamp \[s\], oldest first, stamps increasing.
    poses: VecDeque<(f64, Pose)>,
    /// Tool velocity by stamp, oldest first; without twists the velocity is the poses' difference.
    twists: VecDeque<(f64, Vector3<f64>)>,
}

/// Why a reading got no tool state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unpaired {
    /// No pose within `stale_after` of the reading's stamp.
    NoFreshPose,
    /// A stamp or force that is not finite, or a force beyond [`MAX_READABLE_FORCE`].
    Unreadable,
}

/// The tool's position and rotation in the world.
type Pose = (Vector3<f64>, UnitQuaternion<f64>);

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

/// Appends `entry` stamped `t` to a stamp-ordered history: a stamp that goes back (a restarted
/// publisher, a replay started again) starts the history anew; a repeated stamp replaces its entry.
fn push<T>(history: &mut VecDeque<(f64, T)>, t: f64, entry: T) {
    if !t.is_finite() {
        return;
    }
    match history.back() {
        Some((last, _)) if t < *last => history.clear(),
        Some((last, _)) if t == *last => {
            history.pop_back();
        }
        _ => {}
    }
    if history.len() == HISTORY {
        history.pop_front();
    }
    history.push_back((t, entry));
}

/// The index of the last entry stamped at or before `t` (`None`: every entry is newer).
fn at_or_before<T>(history: &VecDeque<(f64, T)>, t: f64) -> Option<usize> {
    history.partition_point(|(s, _)| *s <= t).checked_sub(1)
}

impl ForcePairing {
    /// `None` for a zero or non-finite normal.
    pub fn new(tool_to_sensor: UnitQuaternion<f64>, normal: Vector3<f64>, stale_after: f64) -> Option<Self> {
        Some(Self {
            geometry: ContactGeometry::new(normal, tool_to_sensor)?,
            stale_after,
            poses: VecDeque::with_capacity(HISTORY),
            twists: VecDeque::with_capacity(HISTORY),
        })
    }

    /// The tool's pose stamped `t` \[s\].
    pub fn pose(&mut self, t: f64, position: Vector3<f64>, rotation: UnitQuaternion<f64>) {
        push(&mut self.poses, t, (position, rotation));
    }

    /// The tool's linear velocity stamped `t` \[s\].
    pub fn twist(&mut self, t: f64, linear: Vector3<f64>) {
        push(&mut self.twists, t, linear);
    }

    /// The reading stamped `t` of the force on the sensor in its frame, or why it has no tool state.
    pub fn force(&self, t: f64, force_in_sensor: Vector3<f64>) -> Result<Paired, Unpaired> {
        if !t.is_finite() || !force_in_sensor.iter().all(|v| v.is_finite() && v.abs() <= MAX_READABLE_FORCE) {
            return Err(Unpaired::Unreadable);
        }
        let (position, rotation) = self.pose_at(t).ok_or(Unpaired::NoFreshPose)?;
        let velocity = self.velocity_at(t);
        let geometry = &self.geometry;
        let sensor_rotation = geometry.sensor_rotation(&rotation);
        let force = geometry.world_force(&rotation, &force_in_sensor);
        let normal_reading = geometry.normal_reading(&force);
        Ok(Paired { position, velocity, normal_force: normal_reading.max(0.0), normal_reading, force, sensor_rotation })
    }

    /// The pose at `t`: interpolated between the two poses around it, else the nearest one if it is
    /// at most `stale_after` away.
    fn pose_at(&self, t: f64) -> Option<Pose> {
        let poses = &self.poses;
        let near = |(s, pose): &(f64, Pose)| ((t - s).abs() <= self.stale_after).then_some(*pose);
        let Some(i) = at_or_before(poses, t) else {
            return near(poses.front()?);
        };
        let Some(next) = poses.get(i + 1) else {
            return near(&poses[i]);
        };
        let (t0, (p0, r0)) = &poses[i];
        let (t1, (p1, r1)) = next;
        if t1 - t0 > 2.0 * self.stale_after {
            // A gap in the poses: no pose of the reading's time.
            return near(&poses[i]).or_else(|| near(next));
        }
        let a = (t - t0) / (t1 - t0);
        Some((p0.lerp(p1, a), r0.try_slerp(r1, a, 1e-9).unwrap_or(if a < 0.5 { *r0 } else { *r1 })))
    }

    /// The tool's velocity at `t`: the last twist at or before it (the first one before any), else the
    /// difference of the poses around `t`.
    fn velocity_at(&self, t: f64) -> Vector3<f64> {
        if let Some(first) = self.twists.front() {
            return at_or_before(&self.twists, t).map_or(first.1, |i| self.twists[i].1);
        }
        let poses = &self.poses;
        let n = poses.len();
        if n < 2 {
            return Vector3::zeros();
        }
        let i = poses.partition_point(|(s, _)| *s <= t).clamp(1, n - 1);
        let ((t0, (p0, _)), (t1, (p1, _))) = (&poses[i - 1], &poses[i]);
        (p1 - p0) / (t1 - t0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairing() -> ForcePairing {
        ForcePairing::new(UnitQuaternion::identity(), Vector3::z(), 0.05).unwrap()
    }

    /// The tool moving down at 0.1 m/s: its height at `t`.
    fn height(t: f64) -> f64 {
        0.3 - 0.1 * t
    }

    #[test]
    fn a_burst_of_readings_after_a_burst_of_poses_pairs_each_reading_with_the_pose_of_its_stamp() {
        let mut p = pairing();
        // 50 ms of poses arrive before the 50 readings of the same 50 ms.
        for k in 0..50 {
            let t = k as f64 * 1e-3;
            p.pose(t, Vector3::new(0.0, 0.0, height(t)), UnitQuaternion::identity());
        }
        for k in 0..50 {
            let t = k as f64 * 1e-3;
            let paired = p.force(t, Vector3::new(0.0, 0.0, 10.0)).unwrap();
            assert!((paired.position.z - height(t)).abs() < 1e-12, "reading {k}: {}", paired.position.z);
            assert!((paired.velocity.z + 0.1).abs() < 1e-9, "velocity from the poses: {}", paired.velocity.z);
        }
    }

    #[test]
    fn a_reading_between_two_poses_takes_the_pose_interpolated_at_its_stamp() {
        let mut p = pairing();
        let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2);
        p.pose(1.0, Vector3::new(0.0, 0.0, height(1.0)), UnitQuaternion::identity());
        p.pose(1.004, Vector3::new(0.0, 0.0, height(1.004)), turned);
        let paired = p.force(1.001, Vector3::new(1.0, 0.0, 0.0)).unwrap();
        assert!((paired.position.z - height(1.001)).abs() < 1e-12);
        // A quarter of the way round: the sensor's x axis turned by 0.05 rad.
        assert!((paired.force.y.atan2(paired.force.x) - 0.05).abs() < 1e-9, "{}", paired.force);
    }

    #[test]
    fn a_reading_newer_than_every_pose_takes_the_newest_until_it_is_stale() {
        let mut p = pairing();
        p.pose(2.0, Vector3::new(0.0, 0.0, 0.25), UnitQuaternion::identity());
        assert_eq!(p.force(2.04, Vector3::zeros()).unwrap().position.z, 0.25);
        assert_eq!(p.force(2.06, Vector3::zeros()).unwrap_err(), Unpaired::NoFreshPose, "no pose within 50 ms");
        assert_eq!(p.force(1.94, Vector3::zeros()).unwrap_err(), Unpaired::NoFreshPose, "older by more than 50 ms");
    }

    #[test]
    fn a_gap_in_the_poses_is_not_bridged() {
        let mut p = pairing();
        p.pose(1.0, Vector3::new(0.0, 0.0, 0.3), UnitQuaternion::identity());
        p.pose(2.0, Vector3::new(0.0, 0.0, 0.2), UnitQuaternion::identity());
        assert_eq!(
            p.force(1.5, Vector3::zeros()).unwrap_err(),
            Unpaired::NoFreshPose,
            "half a second from either pose"
        );
        assert_eq!(p.force(1.03, Vector3::zeros()).unwrap().position.z, 0.3);
    }

    #[test]
    fn twists_are_taken_at_the_readings_stamp() {
        let mut p = pairing();
        p.pose(0.0, Vector3::zeros(), UnitQuaternion::identity());
        for k in 0..10 {
            p.twist(k as f64 * 1e-3, Vector3::new(0.0, 0.0, -(k as f64)));
        }
        assert_eq!(p.force(0.0035, Vector3::zeros()).unwrap().velocity.z, -3.0);
        assert_eq!(p.force(-0.001, Vector3::zeros()).unwrap().velocity.z, 0.0, "before every twist: the first");
    }

    #[test]
    fn stamps_that_go_back_start_the_history_anew_and_non_finite_ones_are_ignored() {
        let mut p = pairing();
        p.pose(5.0, Vector3::new(0.0, 0.0, 0.5), UnitQuaternion::identity());
        p.pose(f64::NAN, Vector3::new(0.0, 0.0, 9.0), UnitQuaternion::identity());
        p.pose(0.0, Vector3::new(0.0, 0.0, 0.1), UnitQuaternion::identity());
        assert_eq!(p.poses.len(), 1, "the replay started again");
        assert_eq!(p.force(0.01, Vector3::zeros()).unwrap().position.z, 0.1);
        assert_eq!(p.force(f64::INFINITY, Vector3::zeros()).unwrap_err(), Unpaired::Unreadable);
        assert_eq!(p.force(0.0, Vector3::new(f64::NAN, 0.0, 0.0)).unwrap_err(), Unpaired::Unreadable);
    }

    #[test]
    fn a_force_beyond_ten_meganewtons_is_unreadable_and_ten_kilonewtons_is_a_reading() {
        let mut p = pairing();
        p.pose(0.0, Vector3::zeros(), UnitQuaternion::identity());
        for bad in [1e9, -1e300, 1.0001e7, f64::NEG_INFINITY] {
            assert_eq!(p.force(0.0, Vector3::new(0.0, bad, 0.0)).unwrap_err(), Unpaired::Unreadable, "{bad}");
        }
        assert_eq!(p.force(0.0, Vector3::new(0.0, 0.0, -1e4)).unwrap().normal_reading, 1e4);
    }

    #[test]
    fn the_history_stays_bounded() {
        let mut p = pairing();
        for k in 0..10 * HISTORY {
            let t = k as f64 * 1e-3;
            p.pose(t, Vector3::zeros(), UnitQuaternion::identity());
            p.twist(t, Vector3::zeros());
        }
        assert_eq!((p.poses.len(), p.twists.len()), (HISTORY, HISTORY));
    }
}
