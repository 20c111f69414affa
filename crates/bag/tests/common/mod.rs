//! Messages of every type the project publishes, with values that exercise each field.
#![allow(dead_code)]

use softcontact_bag::AnyMessage;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use softcontact_msgs::geometry_msgs::*;
use softcontact_msgs::rosgraph_msgs::Clock;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ContactEffect, ContactModel, ContactState, ControllerState, ForceCommand};
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::tf2_msgs::TFMessage;

pub const T0: u64 = 1_700_000_000_000_000_000;

pub fn header(i: u32, frame: &str) -> Header {
    Header { stamp: Time { sec: 1_700_000_000 + i as i32, nanosec: 1000 * i + 7 }, frame_id: frame.into() }
}

/// The i-th message of every type, on its topic in docs/architecture.md.
pub fn samples(i: u32) -> Vec<(&'static str, AnyMessage)> {
    let x = i as f64;
    let v = |a: f64, b: f64, c: f64| Vector3 { x: a, y: b, z: c };
    let q = Quaternion { x: 1.0, y: 0.0, z: -0.0, w: 1e-17 };
    vec![
        (
            "/lwr/joint_states",
            AnyMessage::JointState(JointState {
                header: header(i, ""),
                name: (1..=7).map(|j| format!("lwr_joint_{j}")).collect(),
                position: (0..7).map(|j| 0.1 * j as f64 + x * 1e-3).collect(),
                velocity: (0..7).map(|j| -0.01 * j as f64).collect(),
                effort: vec![f64::MAX, f64::MIN_POSITIVE, -0.0, 1e300, -1.5, 2.25, x],
            }),
        ),
        (
            "/lwr/joint_torque_command",
            AnyMessage::JointState(JointState {
                header: header(i, ""),
                effort: vec![0.5 * x; 7],
                ..Default::default()
            }),
        ),
        (
            "/lwr/ee_pose",
            AnyMessage::PoseStamped(PoseStamped {
                header: header(i, "world"),
                pose: Pose { position: Point { x: 0.5, y: -0.1, z: 0.3 - x * 1e-4 }, orientation: q },
            }),
        ),
        (
            "/lwr/ee_twist",
            AnyMessage::TwistStamped(TwistStamped {
                header: header(i, "world"),
                twist: Twist { linear: v(0.0, 1e-9, -0.01 * x), angular: v(0.0, 1e-3, 0.0) },
            }),
        ),
        (
            "/tf_static",
            AnyMessage::TFMessage(TFMessage {
                transforms: vec![TransformStamped {
                    header: header(i, "lwr_tool"),
                    child_frame_id: "ft_sensor".into(),
                    transform: Transform { translation: v(0.0, 0.0, 0.1), rotation: q },
                }],
            }),
        ),
        ("/tf", AnyMessage::TFMessage(TFMessage::default())),
        (
            "/ft_sensor/wrench",
            AnyMessage::WrenchStamped(WrenchStamped {
                header: header(i, "ft_sensor"),
                wrench: Wrench { force: v(0.1 * x, -2.5, -140.0 - x / 3.0), torque: v(1e-3, -x * 1e-4, 0.25) },
            }),
        ),
        (
            "/diagnostics",
            AnyMessage::DiagnosticArray(DiagnosticArray {
                header: header(i, ""),
                status: vec![DiagnosticStatus {
                    level: DiagnosticStatus::WARN,
                    name: "lwr_driver: FRI".into(),
                    message: "späte Antworten: 3 ✓".into(),
                    hardware_id: "krc".into(),
                    values: vec![KeyValue { key: "late".into(), value: i.to_string() }],
                }],
            }),
        ),
        ("/clock", AnyMessage::Clock(Clock { clock: header(i, "").stamp })),
        (
            "/contact_estimator/model",
            AnyMessage::ContactModel(ContactModel {
                header: header(i, "world"),
                kind: "azad_featherstone".into(),
                stiffness: 25_044.0 + x,
                damping: 1100.0,
                exponent_a: 1.5,
                exponent_b: 0.5,
                exponent_c: 1.0,
                contact_position: Point { x: 0.5, y: 0.0, z: 0.2 },
                candidate_kinds: vec!["kelvin_voigt".into(), "hunt_crossley".into(), "azad_featherstone".into()],
                candidate_fitness_mean: vec![0.93, 0.996, 0.997],
                candidate_fitness_std: vec![0.01, 0.001, 0.0005],
                window_fill: 1.0,
                stiffness_excited: true,
                damping_excited: i.is_multiple_of(2),
                effects: vec![
                    ContactEffect { id: "viscoelastic_relaxation".into(), parameters: vec![2500.0 + x, 0.15] },
                    ContactEffect { id: "sensor_drift".into(), parameters: vec![-0.004] },
                ],
            }),
        ),
        (
            "/contact_estimator/state",
            AnyMessage::ContactState(ContactState {
                header: header(i, "world"),
                deformation: 0.02,
                deformation_rate: -0.1,
                normal_force: 140.0 + x,
                in_contact: true,
            }),
        ),
        (
            "/deformation_controller/state",
            AnyMessage::ControllerState(ControllerState {
                header: header(i, "world"),
                f_cmd: 140.0,
                z_cmd: 0.031,
                zdot_cmd: 0.0,
                z: 0.0309,
                zdot: -1e-5,
                f: 139.9,
                f_predicted: 140.01,
                in_contact: true,
                contact_lost: false,
                force_limited: true,
            }),
        ),
        (
            "/deformation_controller/force_command",
            AnyMessage::ForceCommand(ForceCommand { force: 140.0, duration: 2.0 }),
        ),
    ]
}

pub fn qos_of(topic: &str) -> softcontact_bag::Qos {
    match topic {
        "/tf_static" => softcontact_bag::Qos::LATCHED,
        "/contact_estimator/model" | "/deformation_controller/force_command" | "/diagnostics" => {
            softcontact_bag::Qos::RELIABLE
        }
        _ => softcontact_bag::Qos::SENSOR,
    }
}

/// Writes `n` rounds of every sample, 1 ms apart; returns what was written, in order.
pub fn write_samples(path: &std::path::Path, n: u32) -> Vec<(String, u64, AnyMessage)> {
    let mut writer = softcontact_bag::BagWriter::create(path).unwrap();
    let mut written = Vec::new();
    for i in 0..n {
        let t = T0 + i as u64 * 1_000_000;
        for (topic, msg) in samples(i) {
            msg.write(&mut writer, topic, qos_of(topic), t).unwrap();
            written.push((topic.to_string(), t, msg));
        }
    }
    writer.finish().unwrap();
    written
}
