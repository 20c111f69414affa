//! `deformation_controller`: seed 001's deformation control as a ROS 2 node. Ticks once per
//! /lwr/joint_states (1 kHz), with the newest /ft_sensor/wrench turned into the world by the arm's own
//! kinematics; takes force commands on /deformation_controller/force_command and models from
//! /contact_estimator/model (adopted per `model_update`); publishes /lwr/joint_torque_command, stamped
//! with the joint state it answers (the driver measures the command's age from it), and
//! /deformation_controller/state. With a stale force reading it sends nothing, and the driver holds.
//! Joint states silent for `dead_after` after they flowed (a dead driver or middleware): it exits with an
//! error naming the stream, and the launch script stops the graph.

use std::time::{Duration, Instant};

use clap::Parser;
use mio::{Events, Interest, Poll, Token};
use nalgebra::Vector3;
use softcontact_dynamics::lwr4;
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ControllerState as StateMsg, ForceCommand};
use softcontact_nodes::contact_estimator::{ModelMsg, model_from_msg};
use softcontact_nodes::deformation_controller::{DeformationController, ModelUpdate, Params};
use softcontact_nodes::liveness::StreamWatch;
use softcontact_nodes::messages::{self, DriverSession};
use softcontact_nodes::params::{self, ParamArgs};
use softcontact_nodes::ros::{self, LogLevel};

#[derive(Parser)]
#[command(
    version,
    about = "Deformation control of a soft contact, as a ROS 2 node (parameters: config/deformation_controller.yaml)"
)]
struct Args {
    #[command(flatten)]
    params: ParamArgs,
}

fn main() -> anyhow::Result<()> {
    ros::init_logging("deformation_controller");
    let (p, declared) = params::load::<Params>("deformation_controller", &Args::parse().params)?;
    let stop = ros::shutdown_flag()?;
    let mut controller = DeformationController::new(p.controller_config(), p.initial_model.clone())?;
    let normal = Vector3::from(p.normal).normalize();
    let mut node = ros::node_with_parameters("deformation_controller", declared)?;
    let mut joint_states = ros::subscription::<JointState>(&mut node, "/lwr/joint_states", ros::sensor_qos())?;
    let wrenches = ros::subscription::<WrenchStamped>(&mut node, "/ft_sensor/wrench", ros::sensor_qos())?;
    let models = ros::subscription::<ModelMsg>(&mut node, "/contact_estimator/model", ros::reliable_qos())?;
    let commands =
        ros::subscription::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())?;
    let torque_pub = ros::publisher::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos())?;
    let state_pub = ros::publisher::<StateMsg>(&mut node, "/deformation_controller/state", ros::sensor_qos())?;
    let mut poll = Poll::new()?;
    poll.registry().register(&mut joint_states, Token(0), Interest::READABLE)?;
    let mut events = Events::with_capacity(8);

    let model = lwr4::model();
    let mut data = model.data();
    let sensor = model.frame_id(lwr4::FT_SENSOR_FRAME)?;
    let names: Vec<String> = model.joints.iter().map(|j| j.name.clone()).collect();
    ros::log(&node, LogLevel::Info, &format!("ready: model update {:?}, domain {}", p.model_update, node.domain_id()));

    let mut wrench: Option<(Vector3<f64>, Instant)> = None;
    let (mut newest_wrench_stamp, mut newest_joint_state_stamp, mut not_newer) = (f64::MIN, f64::MIN, 0u64);
    let mut pending_model = None;
    let state_every = ((1000.0 / p.state_rate).round() as u64).max(1);
    let (mut ticks, mut stale, mut failed, mut adopted) = (0u64, 0u64, 0u64, 0u64);
    let mut next_stale_log = Instant::now();
    let mut was_in_contact = false;
    let mut approach_exhausted_logged = false;
    let (mut last_joint_state, mut last_session, mut ticks_in_session, mut restarts) = (None, None, 0u64, 0u64);
    let start = Instant::now();
    let mut joint_states_watch = StreamWatch::new("/lwr/joint_states", 1000.0, p.dead_after);
    let mut dead = None;
    while !ros::stopping(&stop) {
        ros::wait(&mut poll, &mut events, Duration::from_millis(50))?;
        while let Ok(Some((m, _))) = models.take() {
            match model_from_msg(&m) {
                Ok(estimate) if p.model_update == ModelUpdate::Continuous => {
                    if let Err(e) = controller.adopt_estimate(estimate.0, &estimate.1, Some(p.retarget_duration)) {
                        ros::log(&node, LogLevel::Warn, &format!("re-planning with the new model refused: {e}"));
                    }
                    adopted += 1;
                }
                Ok(estimate) => pending_model = Some(estimate),
                Err(e) => ros::log(&node, LogLevel::Warn, &format!("model refused: {e}")),
            }
        }
        while let Ok(Some((c, _))) = commands.take() {
            if let Some((m, surface)) = pending_model.take() {
                // Seed 001: the newest model is adopted at the start of a command cycle.
                if let Err(e) = controller.adopt_estimate(m, &surface, None) {
                    ros::log(&node, LogLevel::Warn, &format!("model refused: {e}"));
                }
                adopted += 1;
            }
            match controller.command_force(c.force, c.duration) {
                Ok(()) => ros::log(
                    &node,
                    LogLevel::Info,
                    &format!(
                        "force command {:.2} N over {:.2} s ({:?} k {:.0} λ {:.1})",
                        c.force,
                        c.duration,
                        controller.contact_model().kind,
                        controller.contact_model().stiffness,
                        controller.contact_model().damping
                    ),
                ),
                Err(e) => ros::log(&node, LogLevel::Error, &format!("force command {} N refused: {e}", c.force)),
            }
        }
        // Only measurements newer than the newest one seen count: a replayed recording (its stamps are
        // as recorded) or a backlog after a stall never drives the arm. Of a backlog, the newest joint
        // state is the one answered.
        while let Ok(Some((w, _))) = wrenches.take() {
            let f = Vector3::new(w.wrench.force.x, w.wrench.force.y, w.wrench.force.z);
            let stamp = w.header.stamp.as_secs_f64();
            if f.iter().all(|v| v.is_finite()) && stamp > newest_wrench_stamp {
                newest_wrench_stamp = stamp;
                wrench = Some((f, Instant::now()));
            }
        }
        let mut newest_joint_state = None;
        while let Ok(Some((js, _))) = joint_states.take() {
            let stamp = js.header.stamp.as_secs_f64();
            if stamp > newest_joint_state_stamp {
                newest_joint_state_stamp = stamp;
                newest_joint_state = Some(js);
            } else {
                not_newer += 1;
            }
        }
        while let Some(js) = newest_joint_state.take() {
            let (Ok(q), Ok(dq)) = (<[f64; 7]>::try_from(&js.position[..]), <[f64; 7]>::try_from(&js.velocity[..]))
            else {
                failed += 1;
                continue;
            };
            // A new KRC session, a KRC that stopped commanding, or joint states that stopped for a
            // while: the arm may have moved, so the controller forgets the contact and approaches again.
            let session = DriverSession::from_frame_id(&js.header.frame_id);
            let arrived = Instant::now();
            joint_states_watch.seen((arrived - start).as_secs_f64());
            let silence = last_joint_state.map_or(0.0, |t: Instant| (arrived - t).as_secs_f64());
            last_joint_state = Some(arrived);
            let commanding = session.is_some_and(|s| s.commanding);
            let restarted = ticks_in_session > 0
                && (silence > p.restart_after || session.map(|s| s.session) != last_session || !commanding);
            if restarted {
                ros::log(
                    &node,
                    LogLevel::Warn,
                    "new KRC session, KRC not commanding, or joint states interrupted: approaching again",
                );
                restarts += 1;
                ticks_in_session = 0;
            }
            last_session = session.map(|s| s.session);
            if !controller.follow_session(last_session, commanding, silence) {
                continue;
            }
            let Some((f_sensor, _)) = wrench.filter(|(_, seen)| seen.elapsed().as_secs_f64() <= p.stale_after) else {
                stale += 1;
                if Instant::now() >= next_stale_log {
                    ros::log(
                        &node,
                        LogLevel::Warn,
                        "no fresh /ft_sensor/wrench: sending no command (the driver holds)",
                    );
                    next_stale_log = Instant::now() + Duration::from_secs(1);
                }
                continue;
            };
            // The contact force on the hand in the world; f = −F·n.
            model.forward_kinematics(&mut data, &q);
            let force = model.frame_pose(&data, sensor).rotation * f_sensor;
            let f = (-force.dot(&normal)).max(0.0);
            let (tau, s) = match controller.tick(&q, &dq, f, &force) {
                Ok(r) => r,
                Err(e) => {
                    // An empty command: the driver holds at once, rather than repeat an older torque.
                    failed += 1;
                    ros::log(&node, LogLevel::Error, &format!("tick failed, the driver is asked to hold: {e}"));
                    torque_pub.publish(messages::hold_request(&names, &js.header))?;
                    continue;
                }
            };
            torque_pub.publish(messages::torque_command(&names, &tau, &js.header))?;
            ticks += 1;
            ticks_in_session += 1;
            if controller.approach_exhausted() && !approach_exhausted_logged {
                let why = format!("no surface within max_approach {} m: holding there", p.max_approach);
                ros::log(&node, LogLevel::Error, &why);
            }
            approach_exhausted_logged = controller.approach_exhausted();
            if s.in_contact != was_in_contact {
                was_in_contact = s.in_contact;
                ros::log(
                    &node,
                    LogLevel::Info,
                    if s.in_contact { "contact: holding, ready for force commands" } else { "contact lost" },
                );
            }
            if ticks % state_every == 0 {
                state_pub.publish(s.to_msg(js.header.stamp))?;
            }
        }
        // Judged after everything that arrived was read.
        if let Some(d) = joint_states_watch.dead(start.elapsed().as_secs_f64()) {
            ros::log(&node, LogLevel::Error, &format!("{d}: exiting"));
            dead = Some(d);
            break;
        }
    }
    eprintln!(
        "deformation_controller: exit: {ticks} commands sent, {stale} joint states without a fresh force, {failed} failed, {adopted} models adopted, {restarts} restarts, {not_newer} joint states not newer than the last; peak RSS {:.1} MB",
        ros::peak_rss_mb().unwrap_or(f64::NAN)
    );
    dead.map_or(Ok(()), |d| Err(d.into()))
}
