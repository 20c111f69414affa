//! ROS 2 wiring shared by the node binaries: one DDS participant per process on `ROS_DOMAIN_ID`, QoS
//! per docs/architecture.md (sensor streams best-effort keep-last, commands and models reliable, static frames
//! latched), topics by their ROS 2 names and types.

use softcontact_msgs::topics::{self, Topic};
use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use ros2_client::qos::{Durability, History, WhenFull};
pub use ros2_client::ros2::LogLevel;
use ros2_client::{
    Context, ContextOptions, Name, Node, NodeEvent, NodeName, NodeOptions, ParameterValue, QosProfile, RosoutRaw,
    ServiceMapping, ServiceTypeName,
};
use serde::Serialize;
use serde::de::DeserializeOwned;
use softcontact_msgs::RosType;
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};

use crate::runtime::params::Declared;
use crate::runtime::security;

/// Sends the `log` records of the middleware (RustDDS, ros2-client) and of our crates to stderr, each
/// line prefixed with `node`: warnings and errors by default (RustDDS's errors only: its warnings are
/// routine discovery chatter), `RUST_LOG` (e.g. `info`, `rustdds=debug`) overrides. Without it a middleware failure is silent. Call it first in `main`; a second call is a no-op.
pub fn init_logging(node: &str) {
    use std::io::Write;
    let node = node.to_owned();
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn,rustdds=error"))
        .format(move |f, r| writeln!(f, "{node}: [{} {}] {}", r.level(), r.target(), r.args()))
        .try_init();
}

fn domain_id() -> anyhow::Result<u16> {
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) if v.trim().is_empty() => Ok(0),
        Ok(v) => v.trim().parse::<u16>().map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID `{v}` is not a domain number")),
        Err(_) => Ok(0),
    }
}

/// A node on the domain of `ROS_DOMAIN_ID` (0 if unset), logging to /rosout, without parameters.
pub fn node(name: &str) -> anyhow::Result<Node> {
    node_with_parameters(name, Declared::default())
}

/// A tool's node whose topics and services are those of a graph started in `namespace` (`-r __ns:=/NS`),
/// in `enclave` on a secure graph (`None`: ROS 2's default, `/`).
pub fn tool_node(name: &str, namespace: &str, enclave: Option<&str>) -> anyhow::Result<Node> {
    let remapping =
        crate::runtime::names::Remapping::parse(name, &[format!("__ns:={namespace}")]).map_err(anyhow::Error::msg)?;
    node_with_parameters(name, Declared { remapping, enclave: enclave.map(str::to_owned), ..Default::default() })
}

/// Whether this process joined the graph under DDS-Security.
static SECURE: AtomicBool = AtomicBool::new(false);
/// The remote participants DDS-Security refused in this process (no credentials, another authority's, a
/// failed handshake), each once whichever of the process's nodes heard of it.
static REFUSED: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());

/// For a process's exit report: how many participants DDS-Security refused, on a secure graph; else
/// nothing.
pub fn security_report() -> String {
    if !SECURE.load(Ordering::Relaxed) {
        return String::new();
    }
    let refused = REFUSED.lock().unwrap_or_else(|e| e.into_inner()).len();
    format!("; {refused} participants refused by DDS-Security")
}

/// Counts and logs each participant DDS-Security refuses, as `node`'s spinner hears of it.
fn watch_refusals(node: &Node, name: &str) -> anyhow::Result<()> {
    let Some(events) = node.status_receiver() else { return Ok(()) };
    let name = name.to_owned();
    std::thread::Builder::new().name(format!("{name}-refusals")).spawn(move || {
        futures::executor::block_on(async {
            while let Ok(event) = events.recv().await {
                let NodeEvent::ParticipantRefused(participant) = event else { continue };
                if REFUSED.lock().unwrap_or_else(|e| e.into_inner()).insert(participant.clone()) {
                    eprintln!(
                        "{name}: security: refused participant {participant} (no credentials, another \
                         authority's, or a failed handshake)"
                    );
                }
            }
        })
    })?;
    Ok(())
}

/// The participant's options: the domain of `ROS_DOMAIN_ID`, and DDS-Security where `ROS_SECURITY_*`
/// asks for it ([`security::decide`]); refused under `Enforce` without a usable enclave, or in a build
/// without the `security` feature.
fn context_options(enclave: Option<&str>) -> anyhow::Result<ContextOptions> {
    let options = ContextOptions::new().domain_id(domain_id()?);
    let environment = security::Environment::from_process();
    for warning in environment.warnings() {
        eprintln!("warning: {warning}");
    }
    match security::decide(&environment, enclave).map_err(anyhow::Error::msg)? {
        security::Decision::Off => Ok(options),
        security::Decision::Unsecured { why } => {
            eprintln!("warning: {why}: joining the graph without DDS-Security (ROS_SECURITY_STRATEGY is not Enforce)");
            Ok(options)
        }
        #[cfg(feature = "security")]
        security::Decision::Secure { dir, .. } => {
            SECURE.store(true, Ordering::Relaxed);
            Ok(options.enable_security(dir, String::new()))
        }
        #[cfg(not(feature = "security"))]
        security::Decision::Secure { name, .. } => match environment.strategy() {
            security::Strategy::Enforce => anyhow::bail!(
                "ROS_SECURITY_ENABLE with ROS_SECURITY_STRATEGY=Enforce, and this build has no DDS-Security \
                 (enclave {name}): not starting (build with `--features security`)"
            ),
            security::Strategy::Permissive => {
                eprintln!(
                    "warning: this build has no DDS-Security: enclave {name} unused, joining the graph without it"
                );
                Ok(options)
            }
        },
    }
}

/// A node on the domain of `ROS_DOMAIN_ID` that declares `parameters` and serves them through the
/// standard parameter services (list, get, get_types, describe; set answers that a node reads its
/// parameters at start-up). The services run on a spinner thread of their own, never in a 1 kHz path.
pub fn node_with_parameters(name: &str, declared: Declared) -> anyhow::Result<Node> {
    let Declared { values: parameters, specs, remapping, enclave } = declared;
    let context = Context::with_options(context_options(enclave.as_deref())?)?;
    let serve = !parameters.is_empty();
    // Declaring sets each value once through the validator: those are the only values it accepts.
    let start_values = parameters.clone();
    // The parameter services speak the peers' request mapping: the node's `service_mapping` parameter
    // where it has one, else Cyclone DDS's (the default peers').
    let mapping = parameters
        .iter()
        .find_map(|(n, v)| match (n.as_str(), v) {
            ("service_mapping", ParameterValue::String(m)) => Some(m.as_str()),
            _ => None,
        })
        .unwrap_or("cyclone");
    let mut options = NodeOptions::new()
        .enable_rosout(true)
        .start_parameter_services(serve)
        .parameter_service_mapping(service_mapping(mapping)?)
        .parameter_validator(Box::new(move |name, value| {
            if start_values.iter().any(|(n, v)| n == name && v == value) {
                Ok(())
            } else {
                Err(format!("`{name}` is read at start-up: change the parameter file and restart"))
            }
        }));
    for (n, v) in parameters {
        // A nested parameter (`a.b`) is described by its top-level declaration.
        if let Some(spec) = specs.iter().find(|s| s.covers(&n)) {
            let descriptor = ros2_client::parameters::ParameterDescriptor { name: n.clone(), ..spec.descriptor() };
            options = options.describe_parameter(descriptor);
        }
        options = options.declare_parameter(&n, v);
    }
    let node_name = NodeName::new(remapping.namespace(), remapping.node_name(name))?;
    let mut node = context.new_node(node_name, options)?;
    REMAPPINGS.lock().unwrap_or_else(|e| e.into_inner()).push((node.fully_qualified_name(), remapping));
    if serve {
        spin(&mut node, name)?;
    }
    Ok(node)
}

/// Runs `node`'s spinner on a thread of its own: it serves the node's parameters, and keeps the node's
/// view of the graph (which subscriptions match its publishers: `Publisher::get_subscription_count`).
/// Once a node.
pub fn spin(node: &mut Node, name: &str) -> anyhow::Result<()> {
    let spinner = node.spinner()?;
    std::thread::Builder::new().name(format!("{name}-spinner")).spawn(move || {
        if let Err(e) = futures::executor::block_on(spinner.spin()) {
            eprintln!("the node's spinner stopped: {e:?}");
        }
    })?;
    if SECURE.load(Ordering::Relaxed) {
        watch_refusals(node, name)?;
    }
    Ok(())
}

/// Logs to stderr and to /rosout.
pub fn log(node: &Node, level: LogLevel, message: &str) {
    eprintln!("{}: {message}", RosoutRaw::base_name(node));
    node.rosout_raw(
        ros2_client::builtin_interfaces::Time::now(),
        level,
        RosoutRaw::base_name(node),
        message,
        file!(),
        "",
        line!(),
    );
}

/// Set by SIGINT or SIGTERM: nodes finish their cycle, report and exit 0.
pub fn shutdown_flag() -> anyhow::Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&flag))?;
    }
    Ok(flag)
}

/// Whether a shutdown was asked for.
pub fn stopping(flag: &AtomicBool) -> bool {
    flag.load(Ordering::Relaxed)
}

/// Peak resident memory of this process \[MB\] (Linux `VmHWM`), for the exit report.
pub fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
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

/// /tf as tf2's listeners read it: reliable, keep-last 100 (what rclcpp's tf2 broadcaster offers).
pub fn tf_qos() -> QosProfile {
    reliable_qos().history(History::KeepLast { depth: 100 })
}

/// The most /tf messages a second: a tf2 buffer, rviz2 or a bag needs no more, and a reliable writer
/// at the loop's 1 kHz would load every reader's history.
pub const TF_RATE: f64 = 100.0;

/// /clock as ROS 2's ClockQoS reads it: best effort, keep-last 1 (a reliable writer — a simulator —
/// and a best-effort one — `ros2 bag play --clock` — both match).
pub fn clock_qos() -> QosProfile {
    sensor_qos()
}

/// Latched (/tf_static): late joiners get the last sample.
pub fn latched_qos() -> QosProfile {
    reliable_qos().durability(Durability::TransientLocal).history(History::KeepLast { depth: 1 })
}

/// Each node's names as its command line set them (`-r`), by the node's fully qualified name.
static REMAPPINGS: std::sync::Mutex<Vec<(String, crate::runtime::names::Remapping)>> =
    std::sync::Mutex::new(Vec::new());

/// The graph name of the topic or service declared as `declared` (absolute, as in
/// `softcontact_msgs::topics`) for `node`: its namespace and remapping rules applied (crate::runtime::names).
pub fn resolve(node: &Node, declared: &str) -> anyhow::Result<Name> {
    let fqn = node.fully_qualified_name();
    let remappings = REMAPPINGS.lock().unwrap_or_else(|e| e.into_inner());
    let resolved = match remappings.iter().rev().find(|(n, _)| *n == fqn) {
        Some((_, remapping)) => remapping.resolve(RosoutRaw::base_name(node), declared),
        None => declared.to_owned(),
    };
    let (ns, base) = resolved.rsplit_once('/').ok_or_else(|| anyhow::anyhow!("name `{resolved}` needs a /"))?;
    Ok(Name::new(if ns.is_empty() { "/" } else { ns }, base)?)
}

fn topic<T: RosType>(
    node: &mut Node,
    path: &str,
    qos: &QosProfile,
) -> anyhow::Result<ros2_client::dds::rustdds::Topic> {
    let name = resolve(node, path)?;
    Ok(node.create_topic(&name, T::type_name(), qos)?)
}

/// A publisher of one of the graph's topics (`softcontact_msgs::topics`).
pub fn publisher<T: RosType + Serialize>(
    node: &mut Node,
    topic: &Topic<T>,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Publisher<T>> {
    publisher_by_name(node, topic.name, qos)
}

/// A subscription to one of the graph's topics (`softcontact_msgs::topics`).
pub fn subscription<T: RosType + DeserializeOwned + 'static>(
    node: &mut Node,
    topic: &Topic<T>,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Subscription<T>> {
    subscription_by_name(node, topic.name, qos)
}

/// A publisher of a topic named at run time (replaying a recording's topics).
pub fn publisher_by_name<T: RosType + Serialize>(
    node: &mut Node,
    path: &str,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Publisher<T>> {
    let t = topic::<T>(node, path, &qos)?;
    Ok(node.create_publisher(&t, Some(announced::<T>(qos)))?)
}

/// An endpoint's QoS with what ROS 2 Jazzy's rmw announces in its USER_DATA: `typehash=RIHS01_…;`, the
/// type's REP-2016 hash, so that `ros2 topic info -v` shows it and a Jazzy peer checks it. The Humble
/// build (feature `humble`) announces nothing, as Humble's rmw does.
fn announced<T: RosType>(qos: QosProfile) -> QosProfile {
    with_type_hash(qos, T::type_hash())
}

fn with_type_hash(qos: QosProfile, hash: Option<String>) -> QosProfile {
    match hash {
        Some(hash) if cfg!(feature = "jazzy") => qos.user_data(format!("typehash={hash};")),
        _ => qos,
    }
}

/// std_srvs/Trigger's type name and its endpoints' QoS (reliable, the type hash announced).
fn trigger_endpoint() -> (ServiceTypeName, QosProfile) {
    (
        ServiceTypeName::new("std_srvs", "Trigger"),
        with_type_hash(reliable_qos(), softcontact_msgs::type_hash::trigger()),
    )
}

/// A std_srvs/Trigger server at `name`.
pub fn trigger_server(
    node: &mut Node,
    mapping: ServiceMapping,
    name: &Name,
) -> anyhow::Result<ros2_client::service::Server<TriggerRequest, TriggerResponse>> {
    let (service, qos) = trigger_endpoint();
    Ok(node.create_server(mapping, name, &service, qos.clone(), qos)?)
}

/// A std_srvs/Trigger client of `name`.
pub fn trigger_client(
    node: &mut Node,
    mapping: ServiceMapping,
    name: &Name,
) -> anyhow::Result<ros2_client::service::Client<TriggerRequest, TriggerResponse>> {
    let (service, qos) = trigger_endpoint();
    Ok(node.create_client(mapping, name, &service, qos.clone(), qos)?)
}

/// The QoS of ROS 2 actions (services reliable, status latched) for the force action's endpoints, each
/// announcing its type hash: `(goal, result, cancel, feedback, status)`. (The cancel service's and
/// the status topic's action_msgs hashes ros2-client adds itself.)
pub fn press_action_qos() -> [QosProfile; 5] {
    let hashes = softcontact_msgs::type_hash::press_force();
    let hash =
        |pick: fn(&softcontact_msgs::type_hash::ActionHashes) -> &String| hashes.as_ref().map(|h| pick(h).clone());
    [
        with_type_hash(reliable_qos(), hash(|h| &h.send_goal)),
        with_type_hash(reliable_qos(), hash(|h| &h.get_result)),
        reliable_qos(),
        with_type_hash(reliable_qos(), hash(|h| &h.feedback_message)),
        latched_qos(),
    ]
}

/// A subscription to a topic named at run time (recording any topic).
pub fn subscription_by_name<T: RosType + DeserializeOwned + 'static>(
    node: &mut Node,
    path: &str,
    qos: QosProfile,
) -> anyhow::Result<ros2_client::Subscription<T>> {
    let t = topic::<T>(node, path, &qos)?;
    Ok(node.create_subscription(&t, Some(announced::<T>(qos)))?)
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
            Some((
                subscription_by_name(node, topics::CLOCK.name, clock_qos())?,
                softcontact_msgs::builtin_interfaces::Time::default(),
            ))
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

/// Waits up to `timeout` for readiness; a signal (the shutdown flag's) only ends the wait early.
pub fn wait(poll: &mut mio::Poll, events: &mut mio::Events, timeout: std::time::Duration) -> std::io::Result<()> {
    match poll.poll(events, Some(timeout)) {
        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(()),
        r => r,
    }
}

/// A recorder's or a replayer's QoS: as offered (reliability, durability), with a deep history so
/// that nothing is dropped between two drains.
pub fn qos(reliable: bool, transient_local: bool, depth: usize) -> QosProfile {
    let base = if reliable { reliable_qos() } else { sensor_qos() };
    base.durability(if transient_local { Durability::TransientLocal } else { Durability::Volatile })
        .history(History::KeepLast { depth })
}
