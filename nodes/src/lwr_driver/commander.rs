//! Who answers the KRC's measurements: the driver's 1 kHz loop ([`super::component::run`]) reads a
//! measurement, hands it to its [`Commander`] for the answer, writes the answer, then lets the commander
//! publish. Two commanders exist: [`TopicCommands`], the driver's own process taking
//! /lwr/joint_torque_command from the network, and the deformation controller composed in `lwr_control`
//! (`deformation_controller::InProcessController`), which answers each measurement itself. The driver
//! knows neither controller nor law.

use ros2_client::{Node, Publisher, Subscription};
use softcontact_dynamics::FrameMotion;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::topics;

use super::{DriverError, DriverOutput, LwrDriver};
use crate::messages::DriverSession;
use crate::runtime::ros;

/// What a commander did with one measurement.
#[derive(Debug, Default)]
pub struct Answered {
    /// A live commander answered the present session in time (a hold request included).
    pub sign_of_life: bool,
    /// The stamp of the joint state the command now set answers, if a command was set.
    pub command_stamp: Option<f64>,
    /// The last command refused this cycle.
    pub refused: Option<DriverError>,
}

/// The answer to each measurement, on the FRI thread, between the driver reading it and replying.
pub trait Commander {
    /// Whether it answers each measurement itself, in this process: then nobody else may command the
    /// arm, its command answers this very measurement, and no command stream is watched for silence.
    fn in_process(&self) -> bool;

    /// What arrived since the last cycle (between cycles, never between a measurement and its answer).
    fn take_inputs(&mut self) {}

    /// Sets the driver's command for the measurement `out`, stamped `stamp` on the driver's clock: a
    /// torque, or a hold. `node` is the driver's.
    fn answer(&mut self, node: &Node, driver: &mut LwrDriver, out: &DriverOutput, stamp: Time) -> Answered;

    /// The tool's pose and twist at (q, q̇) if the commander's own kinematics computed them this cycle
    /// (the driver then computes none: one kinematics pass a cycle); `None`: the driver computes them.
    fn tool_motion(&mut self, _q: &[f64; 7], _dq: &[f64; 7]) -> Option<FrameMotion> {
        None
    }

    /// After the answer went: what the commander publishes, with the measurement's external torque
    /// message first; returns the publish errors.
    fn publish(&mut self, stamp: Time, external_torque: JointState) -> u64;

    /// The lines the commander adds to the driver's exit report.
    fn exit_report(&self) {}
}

/// The driver's own process: torque commands from /lwr/joint_torque_command, the external torque
/// published for the controller to pair with each joint state.
pub struct TopicCommands {
    commands: Subscription<JointState>,
    external_torque: Publisher<JointState>,
}

impl TopicCommands {
    pub fn new(node: &mut Node) -> anyhow::Result<Self> {
        Ok(Self {
            external_torque: ros::publisher(node, &topics::EXTERNAL_TORQUE, ros::sensor_qos())?,
            commands: ros::subscription(node, &topics::JOINT_TORQUE_COMMAND, ros::reliable_qos())?,
        })
    }
}

impl Commander for TopicCommands {
    fn in_process(&self) -> bool {
        false
    }

    /// The newest torque command, taken now, just before the answer — so that the command for the
    /// previous measurement has had the whole cycle to arrive. A bad one is refused and counted, the
    /// previous one stays. A command must answer a joint state of the present KRC session, within
    /// `max_command_age` by that joint state's stamp (the driver's own clock); an empty one asks for a hold.
    /// Only the session's pinned writer commands (crate::runtime::writer_pin).
    fn answer(&mut self, node: &Node, driver: &mut LwrDriver, _: &DriverOutput, stamp: Time) -> Answered {
        let mut answered = Answered::default();
        let now = stamp.as_secs_f64();
        // The command in force ages by the driver's clock: one taken before a gap between measurements
        // answers none after it.
        driver.expire_command(now);
        while let Ok(Some((cmd, info))) = self.commands.take() {
            let session = DriverSession::from_frame_id(&cmd.header.frame_id).map(|s| s.session);
            let answers = cmd.header.stamp.as_secs_f64();
            let writer = info.publisher_gid().to_bytes16();
            let writers = || self.commands.get_publisher_count(node);
            match driver.set_remote_command(&cmd.effort, session, answers, now, writer, writers) {
                Ok(()) => {
                    answered.sign_of_life = true;
                    answered.command_stamp = Some(answers);
                }
                // A backlog delivered after a stall, another session's commands, or a stranger's, are no
                // sign of life.
                Err(e @ (DriverError::TooOld(..) | DriverError::OtherSession(..) | DriverError::Writer(_))) => {
                    answered.refused = Some(e)
                }
                Err(e) => {
                    answered.sign_of_life = true;
                    answered.refused = Some(e);
                }
            }
        }
        answered
    }

    fn publish(&mut self, _: Time, external_torque: JointState) -> u64 {
        u64::from(self.external_torque.publish(external_torque).is_err())
    }
}
