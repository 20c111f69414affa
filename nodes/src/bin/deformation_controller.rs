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
use softcontact_dynamics::lwr4;
use softcontact_msgs::geometry_msgs::WrenchStamped;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ControllerState as StateMsg, ForceCommand};
use softcontact_nodes::contact_estimator::{ModelMsg, model_from_msg};
use softcontact_nodes::deformation_controller::{
    ControlError, ControllerNode, JointSample, Notices, Params, Reply, Silence,
};
use softcontact_nodes::geometry;
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
    let mut control = ControllerNode::from_params(&p)?;
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

    let names: Vec<String> = lwr4::model().joints.iter().map(|j| j.name.clone()).collect();
    ros::log(&node, LogLevel::Info, &format!("ready: model update {:?}, domain {}", p.model_update, node.domain_id()));

    let state_every = ((1000.0 / p.state_rate).round() as u64).max(1);
    let mut next_stale_log = Instant::now();
    let mut log = Notices::default();
    let start = Instant::now();
    let now = || start.elapsed().as_secs_f64();
    let mut joint_states_watch = StreamWatch::new("/lwr/joint_states", 1000.0, p.dead_after);
    let mut dead = None;
    while !ros::stopping(&stop) {
        ros::wait(&mut poll, &mut events, Duration::from_millis(50))?;
        while let Ok(Some((m, _))) = models.take() {
            match model_from_msg(&m).map_err(ControlError::from).and_then(|(m, s)| control.on_model(m, s)) {
                Ok(_) => {}
                Err(e) => ros::log(&node, LogLevel::Warn, &format!("model refused: {e}")),
            }
        }
        while let Ok(Some((c, _))) = commands.take() {
            let (model_refused, commanded) = control.on_force_command(c.force, c.duration);
            if let Some(e) = model_refused {
                ros::log(&node, LogLevel::Warn, &format!("model refused: {e}"));
            }
            match commanded {
                Ok(()) => {
                    let m = control.law.contact_model();
                    let what = format!("{:?} k {:.0} λ {:.1}", m.kind, m.stiffness, m.damping);
                    ros::log(
                        &node,
                        LogLevel::Info,
                        &format!("force command {:.2} N over {:.2} s ({what})", c.force, c.duration),
                    );
                }
                Err(e) => ros::log(&node, LogLevel::Error, &format!("force command {} N refused: {e}", c.force)),
            }
        }
        while let Ok(Some((w, _))) = wrenches.take() {
            control.on_force(w.header.stamp.as_secs_f64(), geometry::vector_of(&w.wrench.force), now());
        }
        // Of a backlog, only the newest joint state is answered (older ones would be stale anyway).
        let mut newest: Option<JointState> = None;
        while let Ok(Some((js, _))) = joint_states.take() {
            if newest.as_ref().is_none_or(|n| js.header.stamp.as_secs_f64() > n.header.stamp.as_secs_f64()) {
                newest = Some(js);
            }
        }
        if let Some(js) = newest {
            joint_states_watch.seen(now());
            let (Ok(q), Ok(dq)) = (<[f64; 7]>::try_from(&js.position[..]), <[f64; 7]>::try_from(&js.velocity[..]))
            else {
                ros::log(&node, LogLevel::Warn, "joint state without 7 positions and velocities: ignored");
                continue;
            };
            let session = DriverSession::from_frame_id(&js.header.frame_id);
            let sample = JointSample {
                stamp: js.header.stamp.as_secs_f64(),
                session: session.map(|s| s.session),
                commanding: session.is_some_and(|s| s.commanding),
                q,
                dq,
            };
            let step = control.on_joint_state(&sample, now());
            if step.restarted {
                ros::log(
                    &node,
                    LogLevel::Warn,
                    "new KRC session, KRC not commanding, or joint states interrupted: approaching again",
                );
            }
            match &step.reply {
                Reply::Torque(tau) => torque_pub.publish(messages::torque_command(&names, tau, &js.header))?,
                Reply::Hold(e) => {
                    // An empty command: the driver holds at once, rather than repeat an older torque.
                    ros::log(&node, LogLevel::Error, &format!("tick failed, the driver is asked to hold: {e}"));
                    torque_pub.publish(messages::hold_request(&names, &js.header))?;
                }
                Reply::Nothing(Silence::NoFreshForce) if Instant::now() >= next_stale_log => {
                    ros::log(
                        &node,
                        LogLevel::Warn,
                        "no fresh /ft_sensor/wrench: sending no command (the driver holds)",
                    );
                    next_stale_log = Instant::now() + Duration::from_secs(1);
                }
                Reply::Nothing(_) => {}
            }
            for (level, what) in log.changes(&control, &step) {
                ros::log(&node, level, &what);
            }
            if matches!(step.reply, Reply::Torque(_)) && control.counters.ticks.is_multiple_of(state_every) {
                state_pub.publish(step.state.to_msg(js.header.stamp))?;
            }
        }
        // Judged after everything that arrived was read.
        if let Some(d) = joint_states_watch.dead(now()) {
            ros::log(&node, LogLevel::Error, &format!("{d}: exiting"));
            dead = Some(d);
            break;
        }
    }
    eprintln!(
        "deformation_controller: exit: {}; peak RSS {:.1} MB",
        control.counters,
        ros::peak_rss_mb().unwrap_or(f64::NAN)
    );
    dead.map_or(Ok(()), |d| Err(d.into()))
}
