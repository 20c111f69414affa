//! Publishers and subscriptions of any message type the project knows, chosen by type name at run
//! time (record and replay handle topics of many types).

use ros2_client::{Node, Publisher, Subscription};
use softcontact_bag::{AnyMessage, Qos};
use softcontact_msgs::RosType;
use softcontact_nodes::ros;

/// The topics of docs/architecture.md, "The ROS 2 graph", their types and the QoS their publishers offer.
pub const GRAPH_TOPICS: [(&str, &str, Qos); 14] = [
    ("/lwr/joint_states", "sensor_msgs/msg/JointState", Qos::SENSOR),
    ("/lwr/joint_torque_command", "sensor_msgs/msg/JointState", Qos::RELIABLE),
    ("/lwr/ee_pose", "geometry_msgs/msg/PoseStamped", Qos::SENSOR),
    ("/lwr/ee_twist", "geometry_msgs/msg/TwistStamped", Qos::SENSOR),
    ("/tf", "tf2_msgs/msg/TFMessage", Qos::SENSOR),
    ("/tf_static", "tf2_msgs/msg/TFMessage", Qos::LATCHED),
    ("/ft_sensor/wrench_raw", "geometry_msgs/msg/WrenchStamped", Qos::SENSOR),
    ("/ft_sensor/wrench", "geometry_msgs/msg/WrenchStamped", Qos::SENSOR),
    ("/ft_sensor/tare", "geometry_msgs/msg/WrenchStamped", Qos::RELIABLE),
    ("/contact_estimator/model", "softcontact_msgs/msg/ContactModel", Qos::RELIABLE),
    ("/contact_estimator/state", "softcontact_msgs/msg/ContactState", Qos::SENSOR),
    ("/deformation_controller/force_command", "softcontact_msgs/msg/ForceCommand", Qos::RELIABLE),
    ("/deformation_controller/state", "softcontact_msgs/msg/ControllerState", Qos::SENSOR),
    ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", Qos::RELIABLE),
];

fn profile(qos: Qos) -> ros2_client::QosProfile {
    ros::qos(qos.reliable, qos.transient_local, if qos.transient_local { qos.depth as usize } else { 1000 })
}

macro_rules! any_topic {
    ($($variant:ident: $ty:ty),+ $(,)?) => {
        pub enum AnySubscription {
            $($variant(Subscription<$ty>)),+
        }

        impl AnySubscription {
            pub fn new(node: &mut Node, topic: &str, type_name: &str, qos: Qos) -> anyhow::Result<Self> {
                let path = softcontact_bag::type_path(type_name);
                $(if path == <$ty>::type_path() {
                    return Ok(Self::$variant(ros::subscription::<$ty>(node, topic, profile(qos))?));
                })+
                anyhow::bail!("{topic}: type {type_name} is not one the project knows")
            }

            /// Wakes `poll` when messages arrive (edge-triggered: drain with [`Self::take`]).
            pub fn register(&mut self, registry: &mio::Registry, token: mio::Token) -> std::io::Result<()> {
                match self {
                    $(Self::$variant(s) => registry.register(s, token, mio::Interest::READABLE)),+
                }
            }

            /// The next message received, if any.
            pub fn take(&self) -> Option<AnyMessage> {
                match self {
                    $(Self::$variant(s) => s.take().ok().flatten().map(|(m, _)| AnyMessage::$variant(m))),+
                }
            }
        }

        pub enum AnyPublisher {
            $($variant(Publisher<$ty>)),+
        }

        impl AnyPublisher {
            pub fn new(node: &mut Node, topic: &str, type_name: &str, qos: Qos) -> anyhow::Result<Self> {
                let path = softcontact_bag::type_path(type_name);
                $(if path == <$ty>::type_path() {
                    return Ok(Self::$variant(ros::publisher::<$ty>(node, topic, profile(qos))?));
                })+
                anyhow::bail!("{topic}: type {type_name} is not one the project knows")
            }

            /// Publishes `msg`; a message of another type than the publisher's is an error.
            pub fn publish(&self, msg: AnyMessage) -> anyhow::Result<()> {
                match (self, msg) {
                    $((Self::$variant(p), AnyMessage::$variant(m)) => Ok(p.publish(m)?),)+
                    (_, m) => anyhow::bail!("a {} on a publisher of another type", m.type_path()),
                }
            }
        }
    };
}

softcontact_msgs::with_message_types!(any_topic);
