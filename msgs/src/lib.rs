//! ROS 2 messages as the nodes put them on the wire: serde structs with the fields in `.msg` order, so
//! that CDR (ros2-client / RustDDS) encodes them exactly as rclcpp and rclpy do. Standard types are
//! declared here because ros2-client ships only builtin_interfaces.

use ros2_client::{Message, MessageTypeName};
use serde::{Deserialize, Serialize};

/// The ROS 2 name of a message type (`package/msg/Name`).
pub trait RosType {
    const PACKAGE: &'static str;
    const NAME: &'static str;
    fn type_name() -> MessageTypeName {
        MessageTypeName::new(Self::PACKAGE, Self::NAME)
    }
    /// `pkg/msg/Name`, as recordings name the type.
    fn type_path() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }
    /// The REP-2016 hash of this type (`RIHS01_…`), as ROS 2 Iron and later announce it; `None` for a
    /// type without a .msg in msgs/std or msgs/msg.
    fn type_hash() -> Option<String> {
        type_hash::rihs01(&Self::type_path())
    }
    /// The full definition text (`ros2msg`) recordings carry for this type.
    fn definition() -> &'static str {
        let path = Self::type_path();
        definition(&path).unwrap_or_else(|| panic!("{path} has no .msg in msgs/std or msgs/msg"))
    }
}

pub mod topics;
pub mod type_hash;

include!(concat!(env!("OUT_DIR"), "/definitions.rs"));

/// The full ROS 2 definition of a type named `pkg/msg/Name` (or `pkg/Name`), if the project knows it.
pub fn definition(type_name: &str) -> Option<&'static str> {
    let path = match type_name.split('/').collect::<Vec<_>>()[..] {
        [package, name] => format!("{package}/msg/{name}"),
        _ => type_name.to_string(),
    };
    DEFINITIONS.iter().find(|(t, _)| *t == path).map(|(_, d)| *d)
}

macro_rules! ros_type {
    ($pkg:literal, $($t:ident),+) => {
        $(
            impl Message for $t {}
            impl RosType for $t {
                const PACKAGE: &'static str = $pkg;
                const NAME: &'static str = stringify!($t);
            }
        )+
    };
}

pub mod builtin_interfaces {
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Time {
        pub sec: i32,
        pub nanosec: u32,
    }

    impl Time {
        pub fn from_secs_f64(t: f64) -> Self {
            let sec = t.floor();
            Self { sec: sec as i32, nanosec: ((t - sec) * 1e9).round().min(999_999_999.0) as u32 }
        }

        /// Now, by the system clock.
        pub fn now() -> Self {
            let d = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
            Self { sec: d.as_secs() as i32, nanosec: d.subsec_nanos() }
        }

        pub fn as_secs_f64(&self) -> f64 {
            self.sec as f64 + self.nanosec as f64 * 1e-9
        }
    }
    ros_type!("builtin_interfaces", Time);
}

pub mod std_msgs {
    use super::builtin_interfaces::Time;
    use super::*;

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Header {
        pub stamp: Time,
        pub frame_id: std::string::String,
    }
    ros_type!("std_msgs", Header);

    /// One text (`/robot_description`: the URDF).
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct String {
        pub data: std::string::String,
    }
    ros_type!("std_msgs", String);
}

pub mod geometry_msgs {
    use super::std_msgs::Header;
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Vector3 {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Point {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Quaternion {
        pub x: f64,
        pub y: f64,
        pub z: f64,
        pub w: f64,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Pose {
        pub position: Point,
        pub orientation: Quaternion,
    }

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct PoseStamped {
        pub header: Header,
        pub pose: Pose,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Twist {
        pub linear: Vector3,
        pub angular: Vector3,
    }

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TwistStamped {
        pub header: Header,
        pub twist: Twist,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Wrench {
        pub force: Vector3,
        pub torque: Vector3,
    }

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct WrenchStamped {
        pub header: Header,
        pub wrench: Wrench,
    }

    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Transform {
        pub translation: Vector3,
        pub rotation: Quaternion,
    }

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TransformStamped {
        pub header: Header,
        pub child_frame_id: String,
        pub transform: Transform,
    }

    ros_type!(
        "geometry_msgs",
        Vector3,
        Point,
        Quaternion,
        Pose,
        PoseStamped,
        Twist,
        TwistStamped,
        Wrench,
        WrenchStamped,
        Transform,
        TransformStamped
    );
}

pub mod sensor_msgs {
    use super::std_msgs::Header;
    use super::*;

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct JointState {
        pub header: Header,
        pub name: Vec<String>,
        pub position: Vec<f64>,
        pub velocity: Vec<f64>,
        pub effort: Vec<f64>,
    }
    ros_type!("sensor_msgs", JointState);
}

pub mod tf2_msgs {
    use super::geometry_msgs::TransformStamped;
    use super::*;

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TFMessage {
        pub transforms: Vec<TransformStamped>,
    }
    ros_type!("tf2_msgs", TFMessage);
}

pub mod diagnostic_msgs {
    use super::std_msgs::Header;
    use super::*;

    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct KeyValue {
        pub key: String,
        pub value: String,
    }

    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct DiagnosticStatus {
        /// OK 0, WARN 1, ERROR 2, STALE 3.
        pub level: u8,
        pub name: String,
        pub message: String,
        pub hardware_id: String,
        pub values: Vec<KeyValue>,
    }

    impl DiagnosticStatus {
        pub const OK: u8 = 0;
        pub const WARN: u8 = 1;
        pub const ERROR: u8 = 2;
        pub const STALE: u8 = 3;
    }

    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct DiagnosticArray {
        pub header: Header,
        pub status: Vec<DiagnosticStatus>,
    }
    ros_type!("diagnostic_msgs", KeyValue, DiagnosticStatus, DiagnosticArray);
}

pub mod rosgraph_msgs {
    use super::builtin_interfaces::Time;
    use super::*;

    /// Simulated time on /clock, for nodes running with use_sim_time.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Clock {
        pub clock: Time,
    }
    ros_type!("rosgraph_msgs", Clock);
}

pub mod std_srvs {
    use super::*;

    /// An empty request: IDL structs need a member, so ROS 2 adds this one.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct TriggerRequest {
        pub structure_needs_at_least_one_member: u8,
    }

    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct TriggerResponse {
        pub success: bool,
        pub message: String,
    }

    impl Message for TriggerRequest {}
    impl Message for TriggerResponse {}
}

/// The project's own messages, generated from msg/*.msg by build.rs.
pub mod softcontact_msgs {
    include!(concat!(env!("OUT_DIR"), "/softcontact_msgs.rs"));
}

/// Calls `$callback! { Variant: path::Type, … }` with every message type the nodes publish or take:
/// one list for the code that must handle "any of them" (recording, replay, decoding by type name).
#[macro_export]
macro_rules! with_message_types {
    ($callback:ident) => {
        $callback! {
            JointState: $crate::sensor_msgs::JointState,
            PoseStamped: $crate::geometry_msgs::PoseStamped,
            TwistStamped: $crate::geometry_msgs::TwistStamped,
            WrenchStamped: $crate::geometry_msgs::WrenchStamped,
            TFMessage: $crate::tf2_msgs::TFMessage,
            DiagnosticArray: $crate::diagnostic_msgs::DiagnosticArray,
            Clock: $crate::rosgraph_msgs::Clock,
            ContactModel: $crate::softcontact_msgs::ContactModel,
            ContactState: $crate::softcontact_msgs::ContactState,
            ControllerState: $crate::softcontact_msgs::ControllerState,
            ForceCommand: $crate::softcontact_msgs::ForceCommand,
        }
    };
}
