//! The types generated from msg/*.msg encode in CDR exactly as the .msg field list says, which is what
//! rclcpp/rclpy peers decode.

use ros2_client::dds::rustdds::cdr_encoding::{from_bytes, to_vec};
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::softcontact_msgs::{ContactModel, ContactState, ControllerState, ForceCommand};
use softcontact_msgs::std_msgs::Header;

type Le = byteorder::LittleEndian;

#[test]
fn contact_state_lays_out_in_msg_field_order() {
    let msg = ContactState {
        header: Header { stamp: Time { sec: 7, nanosec: 9 }, frame_id: "world".into() },
        deformation: 0.02,
        deformation_rate: -0.1,
        normal_force: 140.0,
        in_contact: true,
    };
    // By hand: Time (i32, u32), string (u32 length incl. NUL, bytes), pad to 8, three f64, bool.
    let mut want = Vec::new();
    want.extend_from_slice(&7i32.to_le_bytes());
    want.extend_from_slice(&9u32.to_le_bytes());
    want.extend_from_slice(&6u32.to_le_bytes());
    want.extend_from_slice(b"world\0");
    while want.len() % 8 != 0 {
        want.push(0);
    }
    for v in [0.02f64, -0.1, 140.0] {
        want.extend_from_slice(&v.to_le_bytes());
    }
    want.push(1);
    assert_eq!(to_vec::<_, Le>(&msg).unwrap(), want);
}

#[test]
fn every_project_message_round_trips_through_cdr() {
    let model = ContactModel {
        kind: "azad_featherstone".into(),
        stiffness: 25_044.0,
        damping: 1100.0,
        exponent_a: 1.5,
        exponent_b: 0.5,
        exponent_c: 1.0,
        candidate_kinds: vec!["kelvin_voigt".into(), "hunt_crossley".into(), "azad_featherstone".into()],
        candidate_fitness_mean: vec![0.965, 0.981, 0.986],
        candidate_fitness_std: vec![0.001; 3],
        window_fill: 1.0,
        stiffness_excited: true,
        damping_excited: false,
        effects: vec![
            softcontact_msgs::softcontact_msgs::ContactEffect {
                id: "viscoelastic_relaxation".into(),
                parameters: vec![2500.0, 0.15],
            },
            softcontact_msgs::softcontact_msgs::ContactEffect { id: "sensor_drift".into(), parameters: vec![-0.004] },
        ],
        ..Default::default()
    };
    let bytes = to_vec::<_, Le>(&model).unwrap();
    assert_eq!(from_bytes::<ContactModel, Le>(&bytes).unwrap().0, model);
    let cmd = ForceCommand { force: 140.0, duration: 2.0 };
    assert_eq!(to_vec::<_, Le>(&cmd).unwrap().len(), 16);
    let state = ControllerState { f_cmd: 140.0, z: 0.03, contact_lost: true, ..Default::default() };
    assert_eq!(from_bytes::<ControllerState, Le>(&to_vec::<_, Le>(&state).unwrap()).unwrap().0, state);
}

#[test]
fn definitions_append_dependencies_depth_first_as_rosbag2_does() {
    use softcontact_msgs::RosType;
    use softcontact_msgs::geometry_msgs::WrenchStamped;
    let sep = "=".repeat(80);
    let want = format!(
        "std_msgs/Header header\nWrench wrench\n{sep}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
         {sep}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n{sep}\nMSG: geometry_msgs/Wrench\n\
         Vector3  force\nVector3  torque\n{sep}\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
    );
    assert_eq!(WrenchStamped::definition(), want);
    assert_eq!(WrenchStamped::type_path(), "geometry_msgs/msg/WrenchStamped");
    assert_eq!(softcontact_msgs::definition("geometry_msgs/WrenchStamped"), Some(want.as_str()));
    assert_eq!(softcontact_msgs::definition("geometry_msgs/msg/Nonexistent"), None);
}

#[test]
fn every_message_type_has_a_definition_naming_each_dependency_once() {
    use ::softcontact_msgs::*;
    fn check<T: RosType>() {
        let text = T::definition();
        let blocks: Vec<&str> = text.lines().filter(|l| l.starts_with("MSG: ")).collect();
        let mut unique = blocks.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(blocks.len(), unique.len(), "{}", T::type_path());
    }
    check::<builtin_interfaces::Time>();
    check::<std_msgs::Header>();
    check::<geometry_msgs::PoseStamped>();
    check::<geometry_msgs::TwistStamped>();
    check::<geometry_msgs::WrenchStamped>();
    check::<sensor_msgs::JointState>();
    check::<tf2_msgs::TFMessage>();
    check::<diagnostic_msgs::DiagnosticArray>();
    check::<rosgraph_msgs::Clock>();
    check::<::softcontact_msgs::softcontact_msgs::ContactModel>();
    check::<::softcontact_msgs::softcontact_msgs::ContactEffect>();
    check::<::softcontact_msgs::softcontact_msgs::ContactState>();
    check::<::softcontact_msgs::softcontact_msgs::ControllerState>();
    check::<::softcontact_msgs::softcontact_msgs::ForceCommand>();
    // TFMessage → TransformStamped → Header → Time, Transform → Vector3, Quaternion: Header once.
    assert_eq!(tf2_msgs::TFMessage::definition().matches("MSG: ").count(), 6);
}
