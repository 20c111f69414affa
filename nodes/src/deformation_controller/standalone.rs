//! The controller as a process of its own (the `deformation_controller` binary, `launch-scripts/sim.sh
//! --separate`): ticks once per /lwr/joint_states, with the newest /ft_sensor/wrench, and publishes
//! /lwr/joint_torque_command stamped with the joint state it answers. In `lwr_control` the same node runs
//! inside the driver's loop instead ([`super::component`]).
//!
//! Joint states, wrenches and external torques are each taken from one DDS writer, the first heard while
//! it is the only one on its topic ([`crate::runtime::writer_pin`]), so a stranger's joint states or
//! wrenches cannot steer or silence it.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use mio::{Events, Interest, Poll, Token};
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::topics;

use super::{ControllerInterface, ControllerNode, JointSample, Params};
use crate::geometry;
use crate::messages::DriverSession;
use crate::runtime::liveness::StreamWatch;
use crate::runtime::params::Declared;
use crate::runtime::ros::{self, LogLevel};
use crate::runtime::writer_pin::{WriterPin, WriterRefused};

/// Runs the controller as a process of its own until `stop` is set or the joint states die (then the
/// error names the stream).
pub fn run(p: Params, declared: Declared, stop: Arc<AtomicBool>) -> anyhow::Result<()> {
    let mut control = ControllerNode::from_params(&p)?;
    let mut topics = ControllerInterface::new(&p, declared)?;
    let mut joint_states = ros::subscription(&mut topics.node, &topics::JOINT_STATES, ros::sensor_qos())?;
    let wrenches = ros::subscription(&mut topics.node, &topics::WRENCH, ros::sensor_qos())?;
    // The KRC's external torque estimate, to check the force with (published before each joint state).
    let external = ros::subscription(&mut topics.node, &topics::EXTERNAL_TORQUE, ros::sensor_qos())?;
    let mut poll = Poll::new()?;
    poll.registry().register(&mut joint_states, Token(0), Interest::READABLE)?;
    let mut events = Events::with_capacity(8);
    let ready = format!("ready: model update {:?}, domain {}", p.model_update, topics.node.domain_id());
    topics.log(LogLevel::Info, &ready);

    let start = Instant::now();
    let now = || start.elapsed().as_secs_f64();
    let mut joint_states_watch = StreamWatch::new(topics::JOINT_STATES.name, 1000.0, p.dead_after);
    let mut dead = None;
    let (mut pin_joint_states, mut pin_wrenches, mut pin_external) = Default::default();
    let mut strangers_logged = 0;
    let mut next_strangers_log = Instant::now();
    let mut driver_fault = false;
    while !ros::stopping(&stop) {
        ros::wait(&mut poll, &mut events, Duration::from_millis(50))?;
        topics.take_inputs(&mut control);
        let node = &topics.node;
        while let Ok(Some((w, info))) = wrenches.take() {
            let writers = || wrenches.get_publisher_count(node);
            if admit(&mut pin_wrenches, &info, writers).is_err() {
                continue;
            }
            control.on_force(w.header.stamp.as_secs_f64(), geometry::vector_of(&w.wrench.force), now());
        }
        while let Ok(Some((e, info))) = external.take() {
            if admit(&mut pin_external, &info, || external.get_publisher_count(node)).is_err() {
                continue;
            }
            if let Ok(torque) = <[f64; 7]>::try_from(&e.effort[..]) {
                control.on_external_torque(e.header.stamp.as_secs_f64(), &torque);
            }
        }
        // Of a backlog, only the newest joint state is answered (older ones would be stale anyway).
        let mut newest: Option<JointState> = None;
        while let Ok(Some((js, info))) = joint_states.take() {
            if admit(&mut pin_joint_states, &info, || joint_states.get_publisher_count(node)).is_err() {
                continue;
            }
            if newest.as_ref().is_none_or(|n| js.header.stamp.as_secs_f64() > n.header.stamp.as_secs_f64()) {
                newest = Some(js);
            }
        }
        if let Some(js) = newest {
            joint_states_watch.seen(now());
            let (Ok(q), Ok(dq)) = (<[f64; 7]>::try_from(&js.position[..]), <[f64; 7]>::try_from(&js.velocity[..]))
            else {
                topics.log(LogLevel::Warn, "joint state without 7 positions and velocities: ignored");
                continue;
            };
            let session = DriverSession::from_frame_id(&js.header.frame_id);
            let fault = session.is_some_and(|s| s.fault);
            if fault != driver_fault {
                driver_fault = fault;
                let why = "its /diagnostics name it; no torque until the operator restarts the KRL program";
                control.on_driver_fault(fault.then(|| why.to_string()));
            }
            let sample = JointSample {
                stamp: js.header.stamp.as_secs_f64(),
                session: session.map(|s| s.session),
                commanding: session.is_some_and(|s| s.commanding),
                q,
                dq,
            };
            let step = control.on_joint_state(&sample, now());
            topics.publish(&control, &step, &js.header, sample.commanding);
        }
        let strangers = pin_joint_states.refused + pin_wrenches.refused + pin_external.refused;
        if strangers > strangers_logged && Instant::now() >= next_strangers_log {
            let why = strangers_report(&pin_joint_states, &pin_wrenches, &pin_external);
            topics.log(LogLevel::Warn, &why);
            (strangers_logged, next_strangers_log) = (strangers, Instant::now() + Duration::from_secs(1));
        }
        // Judged after everything that arrived was read.
        if let Some(d) = joint_states_watch.dead(now()) {
            topics.log(LogLevel::Error, &format!("{d}: exiting"));
            dead = Some(d);
            break;
        }
    }
    eprintln!(
        "deformation_controller: exit: {}; {}; peak RSS {:.1} MB{}",
        control.counters,
        strangers_report(&pin_joint_states, &pin_wrenches, &pin_external),
        ros::peak_rss_mb().unwrap_or(f64::NAN),
        ros::security_report()
    );
    dead.map_or(Ok(()), |d| Err(d.into()))
}

fn admit(
    pin: &mut WriterPin,
    info: &ros2_client::MessageInfo,
    writers_matched: impl FnOnce() -> usize,
) -> Result<(), WriterRefused> {
    pin.admit(info.publisher_gid().to_bytes16(), writers_matched)
}

fn strangers_report(joint_states: &WriterPin, wrenches: &WriterPin, external: &WriterPin) -> String {
    format!(
        "samples refused from writers other than the pinned ones: {} joint states, {} wrenches, {} external torques",
        joint_states.refused, wrenches.refused, external.refused
    )
}
