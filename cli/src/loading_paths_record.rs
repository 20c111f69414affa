//! The loading-path experiments as ROS 2 recordings, one per family, as the product's own cell would record
//! them: /lwr/ee_pose (the stage's tool, in the world) and /ft_sensor/wrench (the sensor's reading in its
//! frame) at 1 kHz, and /tf_static (the sensor frame in the tool frame: nominally aligned, so identity —
//! the misalignment is a mounting error the recording does not know).
//!
//! Geometry: the specimen's true surface at z = 0 of the world, the tool pushing down (normal (0, 0, −1))
//! and sideways along +x. Before each experiment the tool comes down from 0.1 mm above the surface to the
//! zero the bench found; after it, it lifts back. Each experiment's found zero lies `zero_error` below the
//! surface, and the surface itself creeps during the experiment: neither is written anywhere but in the
//! forces.

use softcontact_msgs::topics;
use std::path::{Path, PathBuf};

use softcontact_bag::BagWriter;
use softcontact_contact::{Family, LoadingPath};
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::geometry_msgs::{Point, Pose, PoseStamped, Quaternion, Vector3, Wrench, WrenchStamped};
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::messages::transform;
use softcontact_sim::BenchRun;

/// Time between samples \[ns\] (1 kHz).
const PERIOD_NS: u64 = 1_000_000;
/// Free-space samples before and after each experiment.
const FREE_SAMPLES: usize = 20;
/// Height above the surface the tool starts and ends each experiment at \[m\].
const LIFT: f64 = 1e-4;
/// Stamps start here (2026-01-01, ns since the epoch), as a recording made on a bench would.
const START_NS: u64 = 1_767_225_600_000_000_000;

/// The recordings written, one per family: normal.mcap, linear.mcap, two_segment.mcap.
pub fn write(out: &Path, paths: &[LoadingPath], runs: &[BenchRun]) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (name, family) in [
        ("normal", &(|f: Family| f == Family::Normal) as &dyn Fn(Family) -> bool),
        ("linear", &|f| f == Family::Linear),
        ("two_segment", &|f| matches!(f, Family::TwoSegment(_))),
    ] {
        let file = out.join(format!("{name}.mcap"));
        let _ = std::fs::remove_file(&file);
        let experiments = paths.iter().zip(runs).filter(|(p, _)| family(p.family)).map(|(_, r)| r);
        write_family(&file, experiments)?;
        written.push(file);
    }
    Ok(written)
}

fn stamp(ns: u64) -> Time {
    Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
}

fn write_family<'a>(file: &Path, runs: impl Iterator<Item = &'a BenchRun>) -> anyhow::Result<()> {
    let mut w = BagWriter::create(file)?;
    let tf_static = w.add(&topics::TF_STATIC)?;
    let pose_channel = w.add(&topics::EE_POSE)?;
    let wrench_channel = w.add(&topics::WRENCH)?;
    let aligned = nalgebra::Isometry3::identity();
    let tf =
        TFMessage { transforms: vec![transform(lwr4::TOOL_FRAME, lwr4::FT_SENSOR_FRAME, &aligned, stamp(START_NS))] };
    w.write(tf_static, START_NS, &tf)?;
    let mut ns = START_NS;
    // One sample: the tool at (x, z) in the world, the sensor reading (normal, tangential) in its frame —
    // the force on the hand: the specimen pushes it up (+z) and back against its sideways motion (−x).
    let mut sample = |w: &mut BagWriter, x: f64, z: f64, normal: f64, tangential: f64| -> anyhow::Result<()> {
        ns += PERIOD_NS;
        let pose = PoseStamped {
            header: Header { stamp: stamp(ns), frame_id: "world".into() },
            pose: Pose { position: Point { x, y: 0.0, z }, orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 } },
        };
        let wrench = WrenchStamped {
            header: Header { stamp: stamp(ns), frame_id: lwr4::FT_SENSOR_FRAME.into() },
            wrench: Wrench { force: Vector3 { x: -tangential, y: 0.0, z: normal }, torque: Vector3::default() },
        };
        w.write(pose_channel, ns, &pose)?;
        w.write(wrench_channel, ns, &wrench)?;
        Ok(())
    };
    for run in runs {
        let zero = -run.zero_error;
        for k in 0..FREE_SAMPLES {
            let z = LIFT + (zero - LIFT) * k as f64 / FREE_SAMPLES as f64;
            sample(&mut w, 0.0, z, 0.0, 0.0)?;
        }
        for s in &run.samples {
            sample(
                &mut w,
                s.tangential_displacement,
                zero - s.normal_displacement,
                s.normal_force,
                s.tangential_force,
            )?;
        }
        for _ in 0..FREE_SAMPLES {
            sample(&mut w, 0.0, LIFT, 0.0, 0.0)?;
        }
    }
    w.finish()?;
    Ok(())
}
