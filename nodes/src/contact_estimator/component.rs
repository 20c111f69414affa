//! The contact estimator's ROS 2 loop: subscribes to /ft_sensor/wrench, /lwr/ee_pose and /lwr/ee_twist
//! (each from one pinned writer), pairs them ([`ForcePairing`]), feeds the estimator and publishes
//! /contact_estimator/state and /contact_estimator/model.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use mio::{Events, Interest, Poll, Token};
use nalgebra::Vector3;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::topics;

use super::{ContactEstimatorNode, ForcePairing, MAX_READABLE_FORCE, Paired, Params, Unpaired};
use crate::geometry;
use crate::runtime::liveness::{StreamWatch, first_dead};
use crate::runtime::params::Declared;
use crate::runtime::ros::{self, LogLevel};
use crate::runtime::writer_pin::WriterPin;

/// Runs the node until `stop` is set or a stream it needs dies (then the error names the stream).
pub fn run(p: Params, declared: Declared, stop: Arc<AtomicBool>) -> anyhow::Result<()> {
    let estimator = p.estimator(f64::NEG_INFINITY)?;
    let normal = Vector3::from(p.normal).normalize();
    let mut node = ros::node_with_parameters("contact_estimator", declared)?;
    let mut wrenches = ros::subscription(&mut node, &topics::WRENCH, ros::sensor_qos())?;
    let poses = ros::subscription(&mut node, &topics::EE_POSE, ros::sensor_qos())?;
    let twists = ros::subscription(&mut node, &topics::EE_TWIST, ros::sensor_qos())?;
    let state_pub = ros::publisher(&mut node, &topics::CONTACT_STATE, ros::sensor_qos())?;
    let model_pub = ros::publisher(&mut node, &topics::CONTACT_MODEL, ros::reliable_qos())?;
    let mut clock = ros::Clock::new(&mut node, p.use_sim_time)?;
    let mut poll = Poll::new()?;
    poll.registry().register(&mut wrenches, Token(0), Interest::READABLE)?;
    let mut events = Events::with_capacity(8);

    let mut pairing = ForcePairing::new(geometry::lwr4_tool_to_sensor().rotation, normal, p.stale_after)
        .ok_or_else(|| anyhow::anyhow!("normal must be a non-zero direction"))?;
    let start = Instant::now();
    ros::log(
        &node,
        LogLevel::Info,
        &format!("ready: window {} × {} s, domain {}", p.window, p.sample_period, node.domain_id()),
    );

    let mut estimation = Estimation {
        estimator,
        onset_threshold: p.onset_threshold,
        free_seen: false,
        joined_pressing: 0,
        state_period: 1.0 / p.state_rate,
        next_state: f64::NEG_INFINITY,
        was_in_contact: false,
        samples: 0,
        unpaired: 0,
        unreadable: 0,
        refits: 0,
        refit_failures: 0,
    };
    let mut wrench_watch = StreamWatch::new(topics::WRENCH.name, 1000.0, p.dead_after);
    let mut pose_watch = StreamWatch::new(topics::EE_POSE.name, 1000.0, p.dead_after);
    let mut dead = None;
    // Poses, twists and wrenches each from one writer, the first heard while it is the only one
    // (crate::runtime::writer_pin): a stranger's zero wrenches once kept the estimator from publishing
    // any model.
    let (mut pin_poses, mut pin_twists, mut pin_wrenches) = <(WriterPin, WriterPin, WriterPin)>::default();
    while !ros::stopping(&stop) {
        ros::wait(&mut poll, &mut events, Duration::from_millis(50))?;
        // Paired by the messages' stamps (bursts of one stream do not shift it against another); the
        // streams' liveness by arrival, on this process's clock.
        while let Ok(Some((m, info))) = poses.take() {
            if pin_poses.admit(info.publisher_gid().to_bytes16(), || poses.get_publisher_count(&node)).is_err() {
                continue;
            }
            pose_watch.seen(start.elapsed().as_secs_f64());
            let (position, rotation) = geometry::pose_of(&m.pose);
            pairing.pose(m.header.stamp.as_secs_f64(), position, rotation);
        }
        while let Ok(Some((m, info))) = twists.take() {
            if pin_twists.admit(info.publisher_gid().to_bytes16(), || twists.get_publisher_count(&node)).is_err() {
                continue;
            }
            pairing.twist(m.header.stamp.as_secs_f64(), geometry::vector_of(&m.twist.linear));
        }
        while let Ok(Some((w, info))) = wrenches.take() {
            if pin_wrenches.admit(info.publisher_gid().to_bytes16(), || wrenches.get_publisher_count(&node)).is_err() {
                continue;
            }
            wrench_watch.seen(start.elapsed().as_secs_f64());
            let paired = match pairing.force(w.header.stamp.as_secs_f64(), geometry::vector_of(&w.wrench.force)) {
                Ok(paired) => paired,
                Err(why) => {
                    estimation.unpaired(why);
                    continue;
                }
            };
            estimation.reading(&node, w.header.stamp, &paired, (&state_pub, &model_pub), &mut clock)?;
        }
        // Judged after everything that arrived was read.
        if let Some(d) = first_dead(&[&wrench_watch, &pose_watch], start.elapsed().as_secs_f64()) {
            ros::log(&node, LogLevel::Error, &format!("{d}: exiting"));
            dead = Some(d);
            break;
        }
    }
    eprintln!(
        "contact_estimator: exit: {} readings, {} without a fresh pose, {} unreadable (not finite or beyond {MAX_READABLE_FORCE:e} N), {} before free space was seen, {} models published, {} refits failed; samples refused from writers other than the pinned ones: {} poses, {} twists, {} wrenches; peak RSS {:.1} MB{}",
        estimation.samples,
        estimation.unpaired,
        estimation.unreadable,
        estimation.joined_pressing,
        estimation.refits,
        estimation.refit_failures,
        pin_poses.refused,
        pin_twists.refused,
        pin_wrenches.refused,
        ros::peak_rss_mb().unwrap_or(f64::NAN),
        ros::security_report()
    );
    dead.map_or(Ok(()), |d| Err(d.into()))
}

/// The estimator and what it has published and refused.
struct Estimation {
    estimator: ContactEstimatorNode,
    state_period: f64,
    next_state: f64,
    was_in_contact: bool,
    samples: u64,
    unpaired: u64,
    /// Readings not finite or beyond [`MAX_READABLE_FORCE`].
    unreadable: u64,
    refits: u64,
    refit_failures: u64,
    onset_threshold: f64,
    /// A reading at or below the onset threshold has been seen. Until then the hand may have been pressing
    /// since before this node joined (a late match, a restart): its position is deformed, not the onset,
    /// and such readings are not fed to the estimator.
    free_seen: bool,
    joined_pressing: u64,
}

type StatePublisher = ros2_client::Publisher<softcontact_msgs::softcontact_msgs::ContactState>;
type ModelPublisher = ros2_client::Publisher<softcontact_msgs::softcontact_msgs::ContactModel>;

impl Estimation {
    /// Counts a reading left without a tool state, by why.
    fn unpaired(&mut self, why: Unpaired) {
        match why {
            Unpaired::NoFreshPose => self.unpaired += 1,
            Unpaired::Unreadable => self.unreadable += 1,
        }
    }

    /// One paired reading stamped `stamp`: the estimator updated, the state published at `state_rate`
    /// and a model each time a refit is due; contact and release logged.
    fn reading(
        &mut self,
        node: &ros2_client::Node,
        stamp: Time,
        paired: &Paired,
        (state_pub, model_pub): (&StatePublisher, &ModelPublisher),
        clock: &mut ros::Clock,
    ) -> anyhow::Result<()> {
        let t = stamp.as_secs_f64();
        self.free_seen |= paired.normal_force <= self.onset_threshold;
        if !self.free_seen {
            if self.joined_pressing == 0 {
                ros::log(
                    node,
                    LogLevel::Warn,
                    "joined with the hand pressing on the surface: no onset until it leaves the surface and touches it again",
                );
            }
            self.joined_pressing += 1;
            return Ok(());
        }
        let out = match self.estimator.update(t, &paired.position, &paired.velocity, paired.normal_force) {
            Ok(out) => out,
            Err(e) => {
                self.unpaired += 1;
                ros::log(node, LogLevel::Warn, &format!("reading refused: {e}"));
                return Ok(());
            }
        };
        self.samples += 1;
        if out.in_contact != self.was_in_contact {
            self.was_in_contact = out.in_contact;
            let what = if out.in_contact { "contact" } else { "contact released" };
            ros::log(node, LogLevel::Info, &format!("{what} at t = {t:.3} s"));
        }
        if t >= self.next_state {
            self.next_state = t + self.state_period;
            state_pub.publish(out.to_msg(stamp))?;
        }
        match self.estimator.refit_if_due(t) {
            Some(Ok(m)) => {
                self.refits += 1;
                model_pub.publish(m.to_msg(Header { stamp: clock.now(), frame_id: "world".into() }))?;
            }
            Some(Err(e)) => {
                self.refit_failures += 1;
                ros::log(node, LogLevel::Warn, &format!("refit failed: {e}"));
            }
            None => {}
        }
        Ok(())
    }
}
