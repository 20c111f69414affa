//! The `ft_sensor` node's process loop, hosted by its own binary or by `lwr_control` (see the binary
//! for what it publishes and serves).

use softcontact_msgs::topics;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::diagnostic_msgs::DiagnosticArray;
use softcontact_msgs::diagnostic_msgs::DiagnosticStatus;
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};

use super::{FtConfig, FtSensorNode, Params, StartupTare, calibration};
use crate::geometry;
use crate::messages;
use crate::runtime::handover::{ForceReading, Latest, ToolPose};
use crate::runtime::liveness::{DeadStream, StreamWatch};
use crate::runtime::ros::{self, LogLevel};
use crate::runtime::udp::RdtClient;

/// What the node shares with the components of its process, when composed (`lwr_control`): the tool
/// pose comes from the driver in memory instead of /lwr/ee_pose, and the compensated force goes to the
/// controller in memory as well as on /ft_sensor/wrench.
#[derive(Default)]
pub struct Links {
    pub poses: Option<Arc<Latest<ToolPose>>>,
    pub forces: Option<Arc<Latest<ForceReading>>>,
}

/// The node until `stop` is set (or it exits after a silence): the binary's `main`, and a thread of
/// `lwr_control`.
pub fn run(
    p: Params,
    declared: crate::runtime::params::Declared,
    links: Links,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let (config, calibration_source) = config(&p, &stop)?;
    let ft = FtSensorNode::new(config).map_err(anyhow::Error::msg)?.with_tare_policy(p.tare_policy());
    let mut client = RdtClient::connect(p.sensor, ft)?;
    client.new_stream_after = Duration::from_secs_f64(p.stale_after);
    if p.exit_after_silence > 0.0 {
        // A node that gives up after a silence asks the box at least four times before it does: a box
        // that came up just after the first request must not find the node gone a moment after the retry.
        client.restart_after = client.restart_after.min(Duration::from_secs_f64(p.exit_after_silence / 4.0));
    }
    let mut node = ros::node_with_parameters("ft_sensor", declared)?;
    let raw_pub = ros::publisher(&mut node, &topics::WRENCH_RAW, ros::sensor_qos())?;
    let wrench_pub = ros::publisher(&mut node, &topics::WRENCH, ros::sensor_qos())?;
    // Every tare taken (its bias, stamped when taken): a recording then shows where the sensor's drifted
    // offset was zeroed, which the discrepancy workflow needs to tell a drift from a moving surface.
    let tare_pub = ros::publisher(&mut node, &topics::TARE, ros::reliable_qos())?;
    let diag = ros::publisher(&mut node, &topics::DIAGNOSTICS, ros::reliable_qos())?;
    // Composed, the driver hands the pose over in memory.
    let poses = match links.poses {
        None => Some(ros::subscription(&mut node, &topics::EE_POSE, ros::sensor_qos())?),
        Some(_) => None,
    };
    let mut clock = ros::Clock::new(&mut node, p.use_sim_time)?;
    let bias_name = ros::resolve(&node, topics::FT_BIAS_SERVICE)?;
    let server = ros::trigger_server(&mut node, ros::service_mapping(&p.service_mapping)?, &bias_name)?;
    let mut tares = Tares { startup: StartupTare::new(p.tare_after), publisher: tare_pub, server };

    if let Err(e) = client.start() {
        ros::log(&node, LogLevel::Warn, &format!("start request to {} failed ({e}): retrying", p.sensor));
    }
    ros::log(&node, LogLevel::Info, &calibration_source);
    ros::log(&node, LogLevel::Info, &format!("ready: streaming from {}, domain {}", p.sensor, node.domain_id()));
    let mut last_status = 0u32;
    let mut last_saturated = false;
    let mut next_diagnostics = Instant::now();
    let mut logged_network_errors = 0;
    let start = Instant::now();
    let mut hand = Hand::new(p.dead_after);
    while !ros::stopping(&stop) {
        hand.take(poses.as_ref(), links.poses.as_deref(), &mut client.node, start);
        if hand.watch_poses(&node, start.elapsed().as_secs_f64())
            && let Some(forces) = &links.forces
        {
            forces.withdraw();
        }
        let orientation = hand.orientation;
        if let Some(out) = client.receive(Duration::from_millis(2), orientation.as_ref())? {
            last_status = out.status.0;
            last_saturated = out.saturated;
            let compensated = out.compensated.filter(|_| tares.startup.tared() && !out.invalid);
            // The composed controller first: it answers the next FRI measurement with this reading.
            if let Some(forces) = &links.forces {
                hand_over(forces, compensated, &mut clock);
            }
            if !out.invalid {
                let stamp = clock.now();
                raw_pub.publish(messages::wrench(&out.raw, stamp))?;
                if let Some(c) = compensated {
                    wrench_pub.publish(messages::wrench(&c, stamp))?;
                }
            }
        }
        tares.take(&node, &mut client.node, orientation.as_ref(), start.elapsed().as_secs_f64(), &mut clock)?;
        // The client repeats the start request while no fresh record comes (box booting, rebooting).
        let silent = client.silence().as_secs_f64();
        let network_errors = client.node.counters.network_errors;
        if network_errors > logged_network_errors && silent > 1.0 {
            ros::log(
                &node,
                LogLevel::Warn,
                &format!("no record from {} for {silent:.1} s, {network_errors} network errors: retrying", p.sensor),
            );
            logged_network_errors = network_errors + 10;
        }
        if p.exit_after_silence > 0.0 && silent > p.exit_after_silence {
            ros::log(&node, LogLevel::Info, &format!("no record for {} s, exiting", p.exit_after_silence));
            break;
        }
        if Instant::now() >= next_diagnostics {
            let seen = Seen { status: softcontact_wire::rdt::Status(last_status), saturated: last_saturated, silent };
            let c = client.node.counters;
            let (level, message) = seen.status(&p, &c, hand.poses_dead.as_ref(), orientation.is_some(), &tares.startup);
            diag.publish(diagnostics(&p, &c, level, message, clock.now()))?;
            next_diagnostics += Duration::from_secs(1);
        }
    }
    let _ = client.stop();
    eprintln!(
        "ft_sensor: exit: {:?}; peak RSS {:.1} MB{}",
        client.node.counters,
        ros::peak_rss_mb().unwrap_or(f64::NAN),
        ros::security_report()
    );
    Ok(())
}

/// The node's configuration: the box's calibration (its settings page, asked for patiently, and the
/// parameters) before anything else — without it no count means a force — and the hand's tool load.
/// Also says where the calibration came from.
fn config(p: &Params, stop: &AtomicBool) -> anyhow::Result<(FtConfig, String)> {
    let page = match p.settings_page() {
        Some(http) => Some(
            calibration::fetch_settings_patiently(http, Duration::from_secs_f64(p.http_timeout), || {
                !ros::stopping(stop)
            })
            .map_err(|e| match e {
                calibration::FetchError::NoPage(_) => anyhow::anyhow!(
                    "{e} within {} s; set http_port:=0 and every calibration parameter to start without it",
                    p.http_timeout
                ),
                calibration::FetchError::Refused(_) => anyhow::anyhow!("{e}"),
            })?,
        ),
        None => None,
    };
    let (calibration, source) = calibration::resolve(p, page.as_ref()).map_err(anyhow::Error::msg)?;
    let config = FtConfig {
        calibration,
        tool: lwr4::tool_load(),
        gravity: Vector3::new(0.0, 0.0, -9.81),
        low_pass: (p.low_pass > 0.0).then_some(p.low_pass),
        sample_rate: p.rate,
    };
    Ok((config, source))
}

/// What the node last saw of the stream: the box's status word, a reading at or beyond the range, and
/// how long no fresh record came \[s\].
struct Seen {
    status: softcontact_wire::rdt::Status,
    saturated: bool,
    silent: f64,
}

impl Seen {
    /// The node's status: dead poses, then a stale stream, then the box's errors, then no pose yet or
    /// no tare yet.
    fn status(
        &self,
        p: &Params,
        c: &super::FtCounters,
        poses_dead: Option<&DeadStream>,
        posed: bool,
        startup_tare: &StartupTare,
    ) -> (u8, String) {
        let (status, silent) = (self.status, self.silent);
        if let Some(d) = poses_dead {
            (DiagnosticStatus::ERROR, format!("{d}: tool gravity unknown, /ft_sensor/wrench withheld"))
        } else if silent > p.stale_after {
            let why = if c.network_errors > 0 {
                format!(" ({} network errors: box not up or unreachable?)", c.network_errors)
            } else {
                String::new()
            };
            (DiagnosticStatus::STALE, format!("no fresh record for {silent:.3} s{why}"))
        } else if status.is_error() || self.saturated {
            let mut what = status.describe();
            if self.saturated && !status.is_saturated() {
                what.push("reading at or beyond the calibrated range");
            }
            (DiagnosticStatus::ERROR, what.join(", "))
        } else if !posed {
            (DiagnosticStatus::WARN, "no /lwr/ee_pose yet: tool gravity not compensated".into())
        } else if !startup_tare.tared() {
            let why = startup_tare.refusal.as_deref().unwrap_or("waiting for tare_after");
            (DiagnosticStatus::WARN, format!("not tared yet ({why}): /ft_sensor/wrench waits"))
        } else {
            (DiagnosticStatus::OK, "streaming".into())
        }
    }
}

/// The hand's pose as the node knows it: from /lwr/ee_pose, or from the driver in memory when composed;
/// the sensor's orientation from it, unknown while the poses are dead.
struct Hand {
    orientation: Option<UnitQuaternion<f64>>,
    tool_to_sensor: UnitQuaternion<f64>,
    watch: StreamWatch,
    poses_dead: Option<DeadStream>,
    newest_shared: Option<Instant>,
}

impl Hand {
    fn new(dead_after: f64) -> Self {
        Self {
            orientation: None,
            tool_to_sensor: crate::geometry::lwr4_tool_to_sensor().rotation,
            watch: StreamWatch::new(topics::EE_POSE.name, 1000.0, dead_after),
            poses_dead: None,
            newest_shared: None,
        }
    }

    /// The poses that arrived, handed to the F/T node (its tare checks for motion).
    fn take(
        &mut self,
        topic: Option<&ros2_client::Subscription<softcontact_msgs::geometry_msgs::PoseStamped>>,
        shared: Option<&Latest<ToolPose>>,
        ft: &mut FtSensorNode,
        start: Instant,
    ) {
        while let Some(Ok(Some((pose, _)))) = topic.map(|s| s.take()) {
            self.watch.seen(start.elapsed().as_secs_f64());
            let (position, rotation) = geometry::pose_of(&pose.pose);
            ft.observe_tool_pose(&Isometry3::from_parts(position.into(), rotation));
            self.orientation = Some(rotation * self.tool_to_sensor);
        }
        if let Some(pose) = shared.and_then(|s| s.get()).filter(|p| Some(p.measured) != self.newest_shared) {
            self.newest_shared = Some(pose.measured);
            self.watch.seen(pose.measured.duration_since(start).as_secs_f64());
            ft.observe_tool_pose(&pose.pose);
            self.orientation = Some(pose.pose.rotation * self.tool_to_sensor);
        }
    }

    /// Poses stopped (the driver or the middleware is dead): the hand may turn unseen, so the
    /// orientation is forgotten and the compensated wrench withheld until they flow again. True when
    /// they have just been found dead.
    fn watch_poses(&mut self, node: &ros2_client::Node, now: f64) -> bool {
        match (self.watch.dead(now), &self.poses_dead) {
            (Some(d), None) => {
                ros::log(node, LogLevel::Error, &format!("{d}; /ft_sensor/wrench withheld"));
                self.orientation = None;
                self.poses_dead = Some(d);
                true
            }
            (Some(d), Some(_)) => {
                self.orientation = None;
                self.poses_dead = Some(d);
                false
            }
            (None, Some(_)) => {
                ros::log(node, LogLevel::Info, "/lwr/ee_pose flows again: /ft_sensor/wrench resumes");
                self.poses_dead = None;
                false
            }
            (None, None) => false,
        }
    }
}

/// /diagnostics: the status and the stream's counters.
fn diagnostics(p: &Params, c: &super::FtCounters, level: u8, message: String, stamp: Time) -> DiagnosticArray {
    ros::diagnostics(
        stamp,
        "ft_sensor: RDT",
        &p.sensor.to_string(),
        level,
        message,
        &[
            ("records", c.records),
            ("lost", c.lost),
            ("out_of_order", c.out_of_order),
            ("duplicate", c.duplicate),
            ("restarts", c.restarts),
            ("malformed", c.malformed),
            ("saturated", c.saturated),
            ("errors", c.errors),
            ("network_errors", c.network_errors),
            ("foreign", c.foreign),
            ("tares_refused", c.tares_refused),
        ],
    )
}

/// The tares: the one at start-up (retried while refused) and those asked for on /ft_sensor/bias, each
/// published on /ft_sensor/tare.
struct Tares {
    startup: StartupTare,
    publisher: ros2_client::Publisher<WrenchStamped>,
    server: ros2_client::service::Server<TriggerRequest, TriggerResponse>,
}

impl Tares {
    /// The start-up tare when due (the sensor's orientation known), then every request waiting.
    fn take(
        &mut self,
        node: &ros2_client::Node,
        ft: &mut FtSensorNode,
        orientation: Option<&UnitQuaternion<f64>>,
        now: f64,
        clock: &mut ros::Clock,
    ) -> anyhow::Result<()> {
        if let Some(o) = orientation {
            let refused_before = self.startup.refusal.clone();
            match self.startup.poll(ft, o, now) {
                Some(Ok(b)) => {
                    self.publisher.publish(messages::wrench(&b, clock.now()))?;
                    ros::log(node, LogLevel::Info, &format!("tared at start-up: bias {b:.3?}"));
                }
                Some(Err(e)) if refused_before.as_ref() != Some(&e) => {
                    ros::log(node, LogLevel::Warn, &format!("start-up {e}; retrying"));
                }
                _ => {}
            }
        }
        while let Ok(Some((id, _))) = self.server.receive_request() {
            let response = match ft.checked_tare(orientation) {
                Ok(b) => {
                    self.startup.taken();
                    self.publisher.publish(messages::wrench(&b, clock.now()))?;
                    ros::log(node, LogLevel::Info, &format!("tared on request: bias {b:.3?}"));
                    TriggerResponse { success: true, message: format!("bias set to {b:?}") }
                }
                Err(e) => {
                    ros::log(node, LogLevel::Warn, &format!("/ft_sensor/bias: {e}"));
                    TriggerResponse { success: false, message: e }
                }
            };
            self.server.send_response(id, response)?;
        }
        Ok(())
    }
}

/// The compensated force to the controller composed in this process, or none (withheld, invalid).
fn hand_over(forces: &Latest<ForceReading>, compensated: Option<[f64; 6]>, clock: &mut ros::Clock) {
    match compensated {
        Some(c) => forces.put(ForceReading {
            stamp: clock.now().as_secs_f64(),
            force: Vector3::new(c[0], c[1], c[2]),
            arrived: Instant::now(),
        }),
        None => forces.withdraw(),
    }
}
