//! ROS 2 wiring shared by the node binaries: one DDS participant per process on `ROS_DOMAIN_ID`, QoS
//! per design.md (sensor streams best-effort keep-last, commands and models reliable, static frames
//! latched), topics by their ROS 2 names and types.

use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{Context, ContextOptions, Name, Node, NodeName, NodeOptions, QosProfile, ServiceMapping};
use serde::Serialize;
use serde::de::DeserializeOwned;
use softcontact_msgs::RosType;

/// A node on the domain of `ROS_DOMAIN_ID` (0 if unset).
pub fn node(name: &str) -> anyhow::Result<Node> {
    let domain = match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) => v.trim().parse::<u16>().map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID `{v}` is not a domain number"))?,
        Err(_) => 0,
    };
    let context = Context::with_options(ContextOptions::new().domain_id(domain))?;
    Ok(context.new_node(NodeName::new("/", name)?, NodeOptions::new().enable_rosout(true))?)
}

/// Sensor streams: best effort, newest only.
pub fn sensor_qos() -> QosProfile {
    QosProfile::subscription_default().reliability_best_effort().history(History::KeepLast { depth: 1 })
}

/// Commands, models, diagnostics: reliable.
pub fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// Latched (/tf_static): late joiners get the last sample.
pub fn latched_qos() -> QosProfile {
    reliable_qos().durability(Durability::TransientLocal).history(History::KeepLast { depth: 1 })
}

fn topic<T: RosType>(
    node: &mut Node,
    path: &str,
    qos: &QosProfile,
) -> anyhow::Result<ros2_client::dds::rustdds::Topic> {
    let (ns, base) = path.rsplit_once('/').ok_or_else(|| anyhow::anyhow!("topic `{path}` needs a /"))?;
    let ns = if ns.is_empty() { "/" } else { ns };
    Ok(node.create_topic(&Name::new(ns, base)?, T::type_name(), qos)?)
}

pub fn publisher<T: RosType + Serialize>(
    node: &mut Node,
    path: &str,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Publisher<T>> {
    let t = topic::<T>(node, path, &qos)?;
    Ok(node.create_publisher(&t, Some(qos))?)
}

pub fn subscription<T: RosType + DeserializeOwned + 'static>(
    node: &mut Node,
    path: &str,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Subscription<T>> {
    let t = topic::<T>(node, path, &qos)?;
    Ok(node.create_subscription(&t, Some(qos))?)
}

/// The service mapping of the peers' middleware: `cyclone` (rmw_cyclonedds), `enhanced` (Fast DDS,
/// Connext) or `basic`.
pub fn service_mapping(name: &str) -> anyhow::Result<ServiceMapping> {
    Ok(match name {
        "cyclone" => ServiceMapping::Cyclone,
        "enhanced" | "fastdds" => ServiceMapping::Enhanced,
        "basic" => ServiceMapping::Basic,
        other => anyhow::bail!("unknown service mapping `{other}` (cyclone, enhanced or basic)"),
    })
}

/// The time a node stamps its messages with: the system clock, or with `use_sim_time` the newest
/// /clock sample (the simulator's time when it runs faster than real time).
pub struct Clock {
    sim: Option<(
        ros2_client::Subscription<softcontact_msgs::rosgraph_msgs::Clock>,
        softcontact_msgs::builtin_interfaces::Time,
    )>,
}

impl Clock {
    pub fn new(node: &mut Node, use_sim_time: bool) -> anyhow::Result<Self> {
        let sim = if use_sim_time {
            Some((subscription(node, "/clock", reliable_qos())?, softcontact_msgs::builtin_interfaces::Time::default()))
        } else {
            None
        };
        Ok(Self { sim })
    }

    pub fn now(&mut self) -> softcontact_msgs::builtin_interfaces::Time {
        match &mut self.sim {
            None => softcontact_msgs::builtin_interfaces::Time::now(),
            Some((sub, latest)) => {
                while let Ok(Some((c, _))) = sub.take() {
                    *latest = c.clock;
                }
                *latest
            }
        }
    }
}

/// One /diagnostics message with a single status and its counters.
pub fn diagnostics(
    stamp: softcontact_msgs::builtin_interfaces::Time,
    name: &str,
    hardware_id: &str,
    level: u8,
    message: String,
    counters: &[(&str, u64)],
) -> softcontact_msgs::diagnostic_msgs::DiagnosticArray {
    use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
    DiagnosticArray {
        header: softcontact_msgs::std_msgs::Header { stamp, frame_id: String::new() },
        status: vec![DiagnosticStatus {
            level,
            name: name.into(),
            message,
            hardware_id: hardware_id.into(),
            values: counters.iter().map(|(k, v)| KeyValue { key: (*k).into(), value: v.to_string() }).collect(),
        }],
    }
}
