//! The `lwr_driver` node's process loop, hosted by its own binary or as the FRI thread of `lwr_control`
//! with the controller answering in process (see the binary for what it publishes and takes).

use softcontact_msgs::topics;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nalgebra::Isometry3;
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped};
use softcontact_msgs::sensor_msgs::JointState;

use super::commander::{Answered, Commander};
use super::{DriverCounters, DriverOutput, Params, Refusals, Waiting};
use crate::messages;
use crate::runtime::handover::{Latest, ToolPose};
use crate::runtime::liveness::{DeadStream, StreamWatch};
use crate::runtime::realtime;
use crate::runtime::ros::{self, LogLevel};
use crate::runtime::stats::Histogram;
use crate::runtime::udp::FriClient;

/// The driver's status: a fault, then a dead controller, then datagrams all refused, then any refused or
/// commands from strangers, then holding.
fn diagnostics(
    client: &FriClient,
    command_age: &Histogram,
    last: Option<&DriverOutput>,
    dead: Option<&DeadStream>,
    refusals: &Refusals,
    stranger_commands: u64,
    stamp: Time,
) -> DiagnosticArray {
    let c = client.driver.counters;
    let us = |s: f64| (s * 1e6).round() as u64;
    let (level, message) = match (dead, last) {
        _ if client.driver.fault().is_some() => {
            (DiagnosticStatus::ERROR, client.driver.fault().map(|f| f.to_string()).unwrap_or_default())
        }
        (Some(d), _) => (DiagnosticStatus::ERROR, format!("{d}; holding position")),
        _ if refusals.all_refused() => {
            (DiagnosticStatus::ERROR, format!("{refusals} in the last second: the KRC is not answered"))
        }
        _ if refusals.refused() > 0 => (DiagnosticStatus::WARN, format!("{refusals} in the last second")),
        _ if stranger_commands > 0 => (
            DiagnosticStatus::WARN,
            format!(
                "{stranger_commands} torque commands from a writer other than the pinned one refused in the last second"
            ),
        ),
        (None, None) => (DiagnosticStatus::STALE, "no FRI measurement yet".to_string()),
        (None, Some(o)) if o.waiting.is_some() => (
            DiagnosticStatus::WARN,
            format!(
                "no torque applied: {} ({:?}, quality {:?})",
                o.waiting.map(|w| w.to_string()).unwrap_or_default(),
                o.state,
                o.quality
            ),
        ),
        (None, Some(o)) if o.holding => {
            (DiagnosticStatus::WARN, format!("holding position ({:?}, quality {:?})", o.state, o.quality))
        }
        (None, Some(o)) => (DiagnosticStatus::OK, format!("{:?}, quality {:?}", o.state, o.quality)),
    };
    ros::diagnostics(
        stamp,
        "lwr_driver: FRI",
        "kuka_lwr4",
        level,
        message,
        &[
            ("sample_time_us", us(client.driver.sample_time())),
            ("measurements", c.measurements),
            ("lost", c.lost),
            ("out_of_order", c.out_of_order),
            ("malformed", c.malformed),
            ("implausible", c.implausible),
            ("strangers", c.strangers),
            ("sessions", c.sessions),
            ("network_errors", c.network_errors),
            ("commands_too_old", c.commands_too_old),
            ("stale_cycles", c.stale_cycles),
            ("overspeed_cycles", c.overspeed_cycles),
            ("limit_cycles", c.limit_cycles),
            ("commands_from_strangers", c.commands_from_strangers),
            ("commands_refused", c.commands_refused),
            ("waiting_cycles", c.waiting_cycles),
            ("faults_cleared", c.faults_cleared),
            ("reply_latency_p99_us", us(client.reply_latency.quantile(0.99))),
            ("reply_latency_max_us", us(client.reply_latency.max())),
            ("command_age_p99_us", us(command_age.quantile(0.99))),
            ("command_age_max_us", us(command_age.max())),
        ],
    )
}

/// The node until `stop` is set (or it exits after a silence): the binary's `main` with
/// [`TopicCommands`](super::commander::TopicCommands), and the FRI thread of `lwr_control` with the
/// controller composed. Each cycle: read the measurement, the commander's answer, write it; then the
/// commander's and the driver's messages. `commander` is made with the driver's node; `poses` takes the
/// newest tool pose for the F/T node, when composed.
pub fn run<C: Commander>(
    p: Params,
    declared: crate::runtime::params::Declared,
    commander: impl FnOnce(&mut ros2_client::Node) -> anyhow::Result<C>,
    poses: Option<Arc<Latest<ToolPose>>>,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let mut client = FriClient::bind(p.fri_bind, super::LwrDriver::new(p.clone()))?;
    let mut node = ros::node_with_parameters("lwr_driver", declared)?;
    let streams = FastStreams::new(&mut node)?;
    let mut commander = commander(&mut node)?;
    let names: Vec<String> = lwr4::model().joints.iter().map(|j| j.name.clone()).collect();
    let slow = SlowStreams::new(&mut node, &p, &names)?;
    let tf_static = ros::publisher(&mut node, &topics::TF_STATIC, ros::latched_qos())?;
    let robot_description = ros::publisher(&mut node, &topics::ROBOT_DESCRIPTION, ros::latched_qos())?;
    let diag = ros::publisher(&mut node, &topics::DIAGNOSTICS, ros::reliable_qos())?;
    let mut clock = ros::Clock::new(&mut node, p.use_sim_time)?;

    // The fixed frames below the tool, from the URDF: the sensor as seen from the tool.
    if p.publish_tf {
        tf_static.publish(messages::tool_to_sensor_static(clock.now()))?;
    }
    robot_description.publish(softcontact_msgs::std_msgs::String { data: lwr4::URDF.to_owned() })?;
    // This thread answers the KRC: it asks to run as soon as a measurement arrives.
    let scheduling = realtime::request_short_slice(realtime::FRI_SLICE).unwrap_or_else(|e| format!("unchanged ({e})"));
    let ready = format!("ready: FRI on {}, domain {}; {scheduling}", client.local_addr()?, node.domain_id());
    ros::log(&node, LogLevel::Info, &ready);

    let mut commands = CommandStats::default();
    let mut last: Option<DriverOutput> = None;
    let mut last_seen = Instant::now();
    let mut publish_errors = 0u64;
    // /tf from its own thread at TF_RATE: a reliable write never runs on the 1 kHz loop.
    let arm_state = Latest::<ArmState>::shared();
    let tf_done = Arc::new(AtomicBool::new(false));
    let tf_thread = spawn_slow_streams(slow, arm_state.clone(), tf_done.clone())?;
    let start = Instant::now();
    let mut command_watch = CommandWatch::new(p.dead_after);
    let mut status = Status::default();
    let mut cycle_log = CycleLog::default();
    while !ros::stopping(&stop) {
        commander.take_inputs();
        // The measurement's stamp: the controller answers it, and the joint state carries it.
        let mut measured_at = None;
        let mut answered = Answered::default();
        let output = client.cycle_with(Duration::from_millis(5), |driver, out| {
            // In lockstep the KRC's own clock is the loop's: /clock may not have caught up with the
            // datagram, and a repeated stamp would leave the measurement unanswered.
            let stamp = if p.use_sim_time { Time::from_secs_f64(out.krc_time) } else { clock.now() };
            measured_at = Some(stamp);
            answered = commander.answer(&node, driver, out, stamp);
        })?;
        if answered.sign_of_life {
            command_watch.watch.seen(start.elapsed().as_secs_f64());
        }
        cycle_log.note(&node, output.as_ref(), client.driver.fault(), answered.refused.as_ref());
        if let Some(out) = output {
            last_seen = Instant::now();
            let stamp = measured_at.unwrap_or_else(|| clock.now());
            // The KRC is answered: the tool's motion for the messages, from the cycle's one kinematics pass.
            let tool =
                commander.tool_motion(&out.q, &out.dq).unwrap_or_else(|| client.driver.tool_motion(&out.q, &out.dq));
            if let Some(poses) = &poses {
                poses.put(ToolPose { pose: tool.pose, measured: last_seen });
            }
            commands.answered(&out, stamp.as_secs_f64(), answered.command_stamp, client.driver.counters.stale_cycles);
            let m = out.messages(&names, &tool, stamp);
            // The KRC is answered already; a middleware error is counted, never the end of the driver.
            // The commander's first: a controller of its own pairs the external torque with the joint
            // state by stamp.
            publish_errors += commander.publish(stamp, m.external_torque);
            publish_errors += streams.publish(m.joint_state, m.ee_pose, m.ee_twist);
            arm_state.put(ArmState { stamp, tool_pose: tool.pose, q: out.q });
            last = Some(out);
        } else if p.exit_after_silence > 0.0 && last_seen.elapsed().as_secs_f64() > p.exit_after_silence {
            ros::log(&node, LogLevel::Info, &format!("no measurement for {} s, exiting", p.exit_after_silence));
            break;
        }
        // Commands are due while the KRC commands; silence beyond dead_after is reported, never an exit.
        let krc_commands =
            last.as_ref().is_some_and(|o| o.torque_mode()) && last_seen.elapsed().as_secs_f64() <= p.new_session_after;
        let due = krc_commands && !commander.in_process();
        command_watch.judge(&node, start.elapsed().as_secs_f64(), due, answered.sign_of_life);
        if Instant::now() >= status.next {
            let report = status.report(&node, &client, &commands.age, last.as_ref(), command_watch.dead.as_ref());
            publish_errors += u64::from(diag.publish(report(clock.now())).is_err());
        }
    }
    tf_done.store(true, Ordering::Relaxed);
    publish_errors += tf_thread.join().unwrap_or(1);
    let report = status.report(&node, &client, &commands.age, last.as_ref(), command_watch.dead.as_ref());
    diag.publish(report(clock.now()))?;
    exit_report(&client, &commands, &commander, publish_errors);
    Ok(())
}

/// The exit report: tests and `launch-scripts/sim.sh` read these lines.
fn exit_report(client: &FriClient, commands: &CommandStats, commander: &impl Commander, publish_errors: u64) {
    eprintln!("lwr_driver: exit: {:?}, publish errors {publish_errors}", client.driver.counters);
    eprintln!(
        "lwr_driver: reply latency {}; within 200 us: {:.4} %",
        client.reply_latency.summary(1e6, "us"),
        client.reply_latency.fraction_within(200e-6) * 100.0
    );
    eprintln!("lwr_driver: send call {}", client.send_duration.summary(1e6, "us"));
    commands.exit_report(client.driver.counters.stale_cycles);
    commander.exit_report();
    eprintln!("lwr_driver: peak RSS {:.1} MB{}", ros::peak_rss_mb().unwrap_or(f64::NAN), ros::security_report());
}

/// The applied commands: how old the joint state behind each was when applied (the controller stamps
/// its command with the stamp of the joint state it answered; older ones are stale cycles), how many
/// measurements behind, and the stale cycles once the controller first commanded.
struct CommandStats {
    age: Histogram,
    /// The stamp of the joint state the command in force answers.
    stamp: Option<f64>,
    lag: CommandLag,
    stale_at_first_command: Option<u64>,
}

impl Default for CommandStats {
    fn default() -> Self {
        Self {
            age: Histogram::new(1e-5, 100_000),
            stamp: None,
            lag: CommandLag::default(),
            stale_at_first_command: None,
        }
    }
}

impl CommandStats {
    /// The measurement stamped `stamp` was answered with `out`; `command_stamp`: a command set for it.
    fn answered(&mut self, out: &DriverOutput, stamp: f64, command_stamp: Option<f64>, stale_cycles: u64) {
        if command_stamp.is_some() {
            self.stamp = command_stamp;
        }
        let commanded = out.torque_mode() && !out.holding;
        if commanded {
            self.stale_at_first_command.get_or_insert(stale_cycles);
        }
        self.lag.measured(stamp);
        if let Some(t) = self.stamp.filter(|_| commanded) {
            // By the stamp of the measurement it answered, as `max_command_age` is checked (the
            // reply's own delay is the reply latency's).
            self.age.record(stamp - t);
            self.lag.applied(t);
        }
    }

    fn exit_report(&self, stale: u64) {
        let after_start = self.stale_at_first_command.map_or(0, |s| stale - s);
        eprintln!(
            "lwr_driver: command age {}; stale cycles {stale}, {after_start} after the first command",
            self.age.summary(1e3, "ms")
        );
        eprintln!("lwr_driver: {}", self.lag);
    }
}

/// /lwr/joint_torque_command watched while commands are due (the KRC commands and no controller answers
/// in process): silence beyond `dead_after` is logged and reported, never an exit.
struct CommandWatch {
    watch: StreamWatch,
    dead: Option<DeadStream>,
}

impl CommandWatch {
    fn new(dead_after: f64) -> Self {
        Self { watch: StreamWatch::new(topics::JOINT_TORQUE_COMMAND.name, 1000.0, dead_after), dead: None }
    }

    fn judge(&mut self, node: &ros2_client::Node, now: f64, due: bool, sign_of_life: bool) {
        if !due {
            self.watch.not_due(now);
        }
        match (self.watch.dead(now), &self.dead) {
            (Some(d), None) => {
                ros::log(node, LogLevel::Error, &format!("{d}; holding the arm while the KRC commands"));
                self.dead = Some(d);
            }
            (Some(d), Some(_)) => self.dead = Some(d),
            // Only commands end the report: a KRC that pauses commanding (a new session after the
            // stall) does not bring the controller back, and its next silence is the same outage.
            (None, Some(_)) if sign_of_life => {
                ros::log(node, LogLevel::Info, "torque commands flow again");
                self.dead = None;
            }
            (None, _) => {}
        }
    }
}

/// /diagnostics once a second, with what was refused since the last.
struct Status {
    next: Instant,
    /// The counters at the last report.
    counted: DriverCounters,
    all_refused_logged: bool,
}

impl Default for Status {
    fn default() -> Self {
        Self { next: Instant::now(), counted: DriverCounters::default(), all_refused_logged: false }
    }
}

impl Status {
    /// The report (to be stamped), logging once when everything is refused.
    fn report<'a>(
        &mut self,
        node: &ros2_client::Node,
        client: &'a FriClient,
        command_age: &'a Histogram,
        last: Option<&'a DriverOutput>,
        dead: Option<&'a DeadStream>,
    ) -> impl FnOnce(Time) -> DiagnosticArray + 'a {
        let refusals = client.driver.counters.refusals_since(&self.counted);
        if refusals.all_refused() && !self.all_refused_logged {
            ros::log(node, LogLevel::Error, &format!("{refusals} in the last second: the KRC is not answered"));
        }
        self.all_refused_logged = refusals.all_refused();
        let strangers = client.driver.counters.commands_from_strangers - self.counted.commands_from_strangers;
        self.counted = client.driver.counters;
        self.next += Duration::from_secs(1);
        move |stamp| diagnostics(client, command_age, last, dead, &refusals, strangers, stamp)
    }
}

/// How far behind the KRC the applied commands are, in measurements: 0 when the command answers this very
/// measurement (composed), 1 when it answers the one before (the best a controller of its own can do,
/// over DDS), more when its answer came late. Also the KRC's period as the driver sees it (between
/// measurement stamps): with a controller of its own, the command age includes it.
struct CommandLag {
    /// The stamps of the last measurements, the newest at `count % RECENT`.
    recent: [f64; RECENT],
    count: usize,
    /// Applied commands 0, 1, 2 and ≥ 3 measurements behind.
    behind: [u64; 4],
    period: Histogram,
}

const RECENT: usize = 8;

impl Default for CommandLag {
    fn default() -> Self {
        CommandLag { recent: [f64::NAN; RECENT], count: 0, behind: [0; 4], period: Histogram::new(1e-5, 100_000) }
    }
}

impl CommandLag {
    fn measured(&mut self, stamp: f64) {
        if self.count > 0 {
            self.period.record(stamp - self.recent[(self.count - 1) % RECENT]);
        }
        self.recent[self.count % RECENT] = stamp;
        self.count += 1;
    }

    /// A command that answers the measurement stamped `answers` was applied to the newest measurement.
    fn applied(&mut self, answers: f64) {
        let back = (0..RECENT.min(self.count)).find(|k| self.recent[(self.count - 1 - k) % RECENT] == answers);
        self.behind[back.unwrap_or(3).min(3)] += 1;
    }
}

impl std::fmt::Display for CommandLag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.behind.iter().sum::<u64>().max(1) as f64;
        let [b0, b1, b2, b3] = self.behind.map(|b| 100.0 * b as f64 / n);
        write!(
            f,
            "commands applied 0 / 1 / 2 / ≥3 measurements behind: {b0:.2} / {b1:.2} / {b2:.2} / {b3:.2} %; KRC period {}",
            self.period.summary(1e3, "ms")
        )
    }
}

/// What the reliable streams of the slow thread are made of: the newest measurement's stamp, tool pose
/// and joint positions.
#[derive(Clone, Copy)]
struct ArmState {
    stamp: Time,
    tool_pose: Isometry3<f64>,
    q: [f64; 7],
}

/// The reliable streams for ROS 2's tools, written at TF_RATE: /tf (unless robot_state_publisher
/// publishes the tree), and /joint_states with its joint names.
struct SlowStreams {
    tf: Option<ros2_client::Publisher<softcontact_msgs::tf2_msgs::TFMessage>>,
    joint_states: Option<(ros2_client::Publisher<JointState>, Vec<String>)>,
}

impl SlowStreams {
    fn new(node: &mut ros2_client::Node, p: &Params, names: &[String]) -> anyhow::Result<Self> {
        let tf = ros::publisher(node, &topics::TF, ros::tf_qos())?;
        let joint_states = match p.publish_joint_states {
            true => Some((ros::publisher(node, &topics::ROBOT_JOINT_STATES, ros::reliable_qos())?, names.to_vec())),
            false => None,
        };
        Ok(Self { tf: p.publish_tf.then_some(tf), joint_states })
    }
}

/// The streams written each cycle, after the answer: /lwr/joint_states, /lwr/ee_pose, /lwr/ee_twist.
struct FastStreams {
    joint_states: ros2_client::Publisher<JointState>,
    ee_pose: ros2_client::Publisher<PoseStamped>,
    ee_twist: ros2_client::Publisher<TwistStamped>,
}

impl FastStreams {
    fn new(node: &mut ros2_client::Node) -> anyhow::Result<Self> {
        Ok(Self {
            joint_states: ros::publisher(node, &topics::JOINT_STATES, ros::sensor_qos())?,
            ee_pose: ros::publisher(node, &topics::EE_POSE, ros::sensor_qos())?,
            ee_twist: ros::publisher(node, &topics::EE_TWIST, ros::sensor_qos())?,
        })
    }

    /// Returns the publish errors: the KRC is answered already, a middleware error is counted, never the
    /// end of the driver.
    fn publish(&self, joint_state: JointState, ee_pose: PoseStamped, ee_twist: TwistStamped) -> u64 {
        let sent = [
            self.joint_states.publish(joint_state).is_ok(),
            self.ee_pose.publish(ee_pose).is_ok(),
            self.ee_twist.publish(ee_twist).is_ok(),
        ];
        sent.iter().filter(|ok| !**ok).count() as u64
    }
}

/// Publishes the newest tool pose (and joint positions) at most `ros::TF_RATE` times a second, until
/// `done`; returns the publish errors. A new pose only: a stalled loop publishes nothing new.
fn spawn_slow_streams(
    streams: SlowStreams,
    arm: Arc<Latest<ArmState>>,
    done: Arc<AtomicBool>,
) -> std::io::Result<std::thread::JoinHandle<u64>> {
    std::thread::Builder::new().name("lwr_driver_tf".into()).spawn(move || {
        let period = Duration::from_secs_f64(1.0 / ros::TF_RATE);
        let (mut next, mut last, mut errors) = (Instant::now(), None, 0u64);
        while !done.load(Ordering::Relaxed) {
            if let Some(state) = arm.get().filter(|s| Some(s.stamp) != last) {
                last = Some(state.stamp);
                if let Some(tf) = &streams.tf {
                    errors += u64::from(tf.publish(messages::tool_tf(&state.tool_pose, state.stamp)).is_err());
                }
                if let Some((publisher, names)) = &streams.joint_states {
                    let message = messages::robot_joint_state(names, &state.q, state.stamp);
                    errors += u64::from(publisher.publish(message).is_err());
                }
            }
            next += period;
            std::thread::sleep(next.saturating_duration_since(Instant::now()));
        }
        errors
    })
}

/// What each cycle logs, each at most once a second: a flapping link logs no flood. What the driver
/// waits for, on each change (a fault is logged on its own, once it latches; monitor mode is no reason to
/// log); a refused command.
struct CycleLog {
    waiting: Option<Waiting>,
    next_waiting: Instant,
    fault: Option<super::Fault>,
    next_refusal: Instant,
}

impl Default for CycleLog {
    fn default() -> Self {
        Self { waiting: None, next_waiting: Instant::now(), fault: None, next_refusal: Instant::now() }
    }
}

impl CycleLog {
    fn note(
        &mut self,
        node: &ros2_client::Node,
        out: Option<&DriverOutput>,
        fault: Option<super::Fault>,
        refused: Option<&super::DriverError>,
    ) {
        if let Some(waiting) = out.map(|o| o.waiting)
            && waiting != self.waiting
            && Instant::now() >= self.next_waiting
        {
            self.waiting = waiting;
            self.next_waiting = Instant::now() + Duration::from_secs(1);
            if let Some(w) = waiting.filter(|w| !matches!(w, Waiting::Fault(_) | Waiting::Monitor(_))) {
                ros::log(node, LogLevel::Warn, &format!("no torque applied: {w}"));
            }
        }
        if fault != self.fault {
            self.fault = fault;
            if let Some(f) = fault {
                ros::log(node, LogLevel::Error, &f.to_string());
            }
        }
        if let Some(e) = refused
            && Instant::now() >= self.next_refusal
        {
            ros::log(node, LogLevel::Warn, &format!("torque command refused: {e}"));
            self.next_refusal = Instant::now() + Duration::from_secs(1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::CommandLag;

    #[test]
    fn a_command_is_counted_by_the_measurements_it_is_behind() {
        let mut lag = CommandLag::default();
        for k in 0..20 {
            lag.measured(k as f64 * 1e-3);
            match k {
                0..5 => lag.applied(k as f64 * 1e-3),         // this measurement (composed)
                5..15 => lag.applied((k - 1) as f64 * 1e-3),  // the one before
                15..18 => lag.applied((k - 2) as f64 * 1e-3), // late
                _ => lag.applied(-1.0),                       // long gone
            }
        }
        assert_eq!(lag.behind, [5, 10, 3, 2]);
        assert!((lag.period.quantile(0.5) - 1e-3).abs() < 2e-5);
        assert!(lag.to_string().contains("25.00 / 50.00 / 15.00 / 10.00 %"), "{lag}");
    }
}
