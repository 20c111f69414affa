//! Publishers and subscriptions of any message type the project knows, chosen by type name at run
//! time (record and replay handle topics of many types).

use ros2_client::{Node, Publisher, Subscription};
use softcontact_bag::{AnyMessage, Qos};
use softcontact_msgs::RosType;
use softcontact_msgs::topics;
use softcontact_nodes::runtime::ros;

/// The graph's recorded topics (`softcontact_msgs::topics::recorded`): name, type and the QoS their
/// publishers offer.
pub fn graph_topics() -> Vec<(&'static str, String, Qos)> {
    topics::recorded().into_iter().map(|t| (t.name, t.type_path, Qos::of(t.delivery))).collect()
}

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
                    return Ok(Self::$variant(ros::subscription_by_name::<$ty>(node, topic, profile(qos))?));
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
                    return Ok(Self::$variant(ros::publisher_by_name::<$ty>(node, topic, profile(qos))?));
                })+
                anyhow::bail!("{topic}: type {type_name} is not one the project knows")
            }

            /// How many subscriptions match this publisher, as `node` (its creator, spinning: `ros::spin`)
            /// sees the graph.
            pub fn subscription_count(&self, node: &Node) -> usize {
                match self {
                    $(Self::$variant(p) => p.get_subscription_count(node)),+
                }
            }

            /// Waits until the matched reliable subscriptions acknowledged all that was published, at
            /// most `max_wait`; whether they all did.
            pub fn wait_for_acknowledgments(&self, max_wait: std::time::Duration) -> bool {
                match self {
                    $(Self::$variant(p) => p.wait_for_acknowledgments(max_wait).unwrap_or(false)),+
                }
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
