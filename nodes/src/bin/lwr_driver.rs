//! `lwr_driver`: the LWR IV joint-torque interface as a ROS 2 node. Answers the KRC over FRI every
//! cycle (the reply goes out before anything is published), publishes /lwr/joint_states, /lwr/ee_pose,
//! /lwr/ee_twist, /tf and /tf_static, takes /lwr/joint_torque_command (effort = total torque, gravity
//! included), and reports its counters on /diagnostics once a second. Torque commands that flowed and
//! stopped for `dead_after` while the KRC commands (a dead controller or middleware): the watchdog holds
//! the arm, and the driver logs an error once and reports ERROR on /diagnostics; it never exits for it.

use std::time::{Duration, Instant};

use clap::Parser;
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus};
use softcontact_msgs::geometry_msgs::{PoseStamped, TwistStamped};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::liveness::{DeadStream, StreamWatch};
use softcontact_nodes::lwr_driver::{DriverCounters, DriverOutput, LwrDriver, Params, Refusals};
use softcontact_nodes::messages::{self, DriverSession};
use softcontact_nodes::params::{self, ParamArgs};
use softcontact_nodes::ros::{self, LogLevel};
use softcontact_nodes::stats::Histogram;
use softcontact_nodes::udp::FriClient;
use softcontact_wire::fri::InterfaceState;

#[derive(Parser)]
#[command(
    version,
    about = "KUKA LWR IV joint-torque interface over FRI, as a ROS 2 node (parameters: config/lwr_driver.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

/// The driver's status: a dead controller, then datagrams all refused, then any refused, then holding.
fn diagnostics(
    client: &FriClient,
    command_age: &Histogram,
    last: Option<&DriverOutput>,
    dead: Option<&DeadStream>,
    refusals: &Refusals,
    stamp: Time,
) -> DiagnosticArray {
    let c = client.driver.counters;
    let us = |s: f64| (s * 1e6).round() as u64;
    let (level, message) = match (dead, last) {
        (Some(d), _) => (DiagnosticStatus::ERROR, format!("{d}; holding position")),
        _ if refusals.all_refused() => {
            (DiagnosticStatus::ERROR, format!("{refusals} in the last second: the KRC is not answered"))
        }
        _ if refusals.refused() > 0 => (DiagnosticStatus::WARN, format!("{refusals} in the last second")),
        (None, None) => (DiagnosticStatus::STALE, "no FRI measurement yet".to_string()),
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
            ("clipped_cycles", c.clipped_cycles),
            ("overspeed_cycles", c.overspeed_cycles),
            ("commands_refused", c.commands_refused),
            ("reply_latency_p99_us", us(client.reply_latency.quantile(0.99))),
            ("reply_latency_max_us", us(client.reply_latency.max())),
            ("command_age_p99_us", us(command_age.quantile(0.99))),
            ("command_age_max_us", us(command_age.max())),
        ],
    )
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("lwr_driver");
    let (p, declared) = params::load::<Params>("lwr_driver", &Args::parse().params)?;
    let stop = ros::shutdown_flag()?;
    let mut client = FriClient::bind(p.fri_bind, LwrDriver::new(p.driver_config()))?;
    let mut node = ros::node_with_parameters("lwr_driver", declared)?;
    let joint_states = ros::publisher::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos())?;
    let ee_pose = ros::publisher::<PoseStamped>(&mut node, "/lwr/ee_pose", ros::sensor_qos())?;
    let ee_twist = ros::publisher::<TwistStamped>(&mut node, "/lwr/ee_twist", ros::sensor_qos())?;
    let tf = ros::publisher::<TFMessage>(&mut node, "/tf", ros::sensor_qos())?;
    let tf_static = ros::publisher::<TFMessage>(&mut node, "/tf_static", ros::latched_qos())?;
    let diag = ros::publisher::<DiagnosticArray>(&mut node, "/diagnostics", ros::reliable_qos())?;
    let commands = ros::subscription::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos())?;
    let mut clock = ros::Clock::new(&mut node, p.use_sim_time)?;

    // The fixed frames below the tool, from the URDF: the sensor as seen from the tool.
    let model = lwr4::model();
    tf_static.publish(messages::tool_to_sensor_static(clock.now()))?;
    let names: Vec<String> = model.joints.iter().map(|j| j.name.clone()).collect();
    ros::log(&node, LogLevel::Info, &format!("ready: FRI on {}, domain {}", client.local_addr()?, node.domain_id()));

    // How old the joint state behind the applied command is, each cycle it is applied (the controller
    // stamps its command with the stamp of the joint state it answered; older ones are stale cycles).
    let mut command_age = Histogram::new(1e-5, 100_000);
    let mut command_stamp: Option<f64> = None;
    let mut last: Option<DriverOutput> = None;
    let mut next_diagnostics = Instant::now();
    let mut last_seen = Instant::now();
    let mut next_refusal_log = Instant::now();
    let mut publish_errors = 0u64;
    let start = Instant::now();
    let mut command_watch = StreamWatch::new("/lwr/joint_torque_command", 1000.0, p.dead_after);
    let mut commands_dead: Option<DeadStream> = None;
    // The counters at the last diagnostics, for what was refused since.
    let mut counted = DriverCounters::default();
    let mut all_refused_logged = false;
    while !ros::stopping(&stop) {
        let output = client.cycle(Duration::from_millis(5))?;
        // Newest torque command wins; a bad one is refused and counted, the previous one stays.
        // A command must answer a joint state of the present KRC session, within the watchdog's age
        // by that joint state's stamp (the driver's own clock); an empty one asks for a hold.
        while let Ok(Some((cmd, _))) = commands.take() {
            command_watch.seen(start.elapsed().as_secs_f64());
            let session = DriverSession::from_frame_id(&cmd.header.frame_id).map(|s| s.session);
            let age = clock.now().as_secs_f64() - cmd.header.stamp.as_secs_f64();
            match client.driver.set_remote_command(&cmd.effort, session, age) {
                Ok(()) => command_stamp = Some(cmd.header.stamp.as_secs_f64()),
                Err(e) if Instant::now() >= next_refusal_log => {
                    ros::log(&node, LogLevel::Warn, &format!("torque command refused: {e}"));
                    next_refusal_log = Instant::now() + Duration::from_secs(1);
                }
                Err(_) => {}
            }
        }
        if let Some(out) = output {
            last_seen = Instant::now();
            let stamp = clock.now();
            if let Some(t) = command_stamp.filter(|_| out.state == InterfaceState::Command && !out.holding) {
                command_age.record(stamp.as_secs_f64() - t);
            }
            let m = out.messages(&names, stamp);
            // The KRC is answered already; a middleware error is counted, never the end of the driver.
            let sent = [
                joint_states.publish(m.joint_state).is_ok(),
                ee_pose.publish(m.ee_pose).is_ok(),
                ee_twist.publish(m.ee_twist).is_ok(),
                tf.publish(m.tf).is_ok(),
            ];
            publish_errors += sent.iter().filter(|ok| !**ok).count() as u64;
            last = Some(out);
        } else if p.exit_after_silence > 0.0 && last_seen.elapsed().as_secs_f64() > p.exit_after_silence {
            ros::log(&node, LogLevel::Info, &format!("no measurement for {} s, exiting", p.exit_after_silence));
            break;
        }
        // Commands are due while the KRC commands; silence beyond dead_after is reported, never an exit.
        let now = start.elapsed().as_secs_f64();
        let krc_commands = last.as_ref().is_some_and(|o| o.state == InterfaceState::Command)
            && last_seen.elapsed().as_secs_f64() <= p.new_session_after;
        if !krc_commands {
            command_watch.not_due(now);
        }
        match (command_watch.dead(now), &commands_dead) {
            (Some(d), None) => {
                ros::log(&node, LogLevel::Error, &format!("{d}; holding the arm while the KRC commands"));
                commands_dead = Some(d);
            }
            (Some(d), Some(_)) => commands_dead = Some(d),
            (None, Some(_)) => {
                ros::log(&node, LogLevel::Info, "torque commands flow again (or the KRC stopped commanding)");
                commands_dead = None;
            }
            (None, None) => {}
        }
        if Instant::now() >= next_diagnostics {
            let refusals = client.driver.counters.refusals_since(&counted);
            if refusals.all_refused() && !all_refused_logged {
                ros::log(&node, LogLevel::Error, &format!("{refusals} in the last second: the KRC is not answered"));
            }
            all_refused_logged = refusals.all_refused();
            counted = client.driver.counters;
            let dead = commands_dead.as_ref();
            let status = diagnostics(&client, &command_age, last.as_ref(), dead, &refusals, clock.now());
            publish_errors += u64::from(diag.publish(status).is_err());
            next_diagnostics += Duration::from_secs(1);
        }
    }
    let refusals = client.driver.counters.refusals_since(&counted);
    let dead = commands_dead.as_ref();
    diag.publish(diagnostics(&client, &command_age, last.as_ref(), dead, &refusals, clock.now()))?;
    // The exit report: tests and `launch-scripts/sim.sh` read these lines.
    eprintln!("lwr_driver: exit: {:?}, publish errors {publish_errors}", client.driver.counters);
    eprintln!(
        "lwr_driver: reply latency {}; within 200 us: {:.4} %",
        client.reply_latency.summary(1e6, "us"),
        client.reply_latency.fraction_within(200e-6) * 100.0
    );
    eprintln!("lwr_driver: send call {}", client.send_duration.summary(1e6, "us"));
    eprintln!("lwr_driver: command age {}", command_age.summary(1e3, "ms"));
    eprintln!("lwr_driver: peak RSS {:.1} MB", ros::peak_rss_mb().unwrap_or(f64::NAN));
    Ok(())
}
