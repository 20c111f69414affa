//! The deformation controller as a component of the driver's process (`lwr_control`): it answers each
//! FRI measurement on the FRI thread, between the driver reading it and answering it, with the F/T
//! node's newest force handed over in memory — no DDS and no allocation on that path. Its topics and
//! action are the node's own ([`ControllerInterface`]); /lwr/joint_torque_command is published for
//! monitoring and recording (the driver does not listen to it here), after the answer has gone.

use std::sync::Arc;
use std::time::Instant;

use softcontact_dynamics::FrameMotion;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::std_msgs::Header;

use super::{ControllerInterface, ControllerNode, JointSample, Params, Reply, Step};
use crate::lwr_driver::commander::{Answered, Commander};
use crate::lwr_driver::{DriverOutput, LwrDriver};
use crate::messages::DriverSession;
use crate::runtime::handover::{ForceReading, Latest};
use crate::runtime::ros::LogLevel;
use ros2_client::Node;
use softcontact_msgs::sensor_msgs::JointState;

pub struct InProcessController {
    pub control: ControllerNode,
    topics: ControllerInterface,
    forces: Arc<Latest<ForceReading>>,
    start: Instant,
    /// The step of the newest measurement and the joint state it answered (stamp, session).
    last: Option<(Step, f64, DriverSession)>,
    /// The driver's fault as last handed to the controller.
    driver_fault: Option<crate::lwr_driver::Fault>,
}

impl InProcessController {
    /// The controller's ROS node ("deformation_controller", serving its parameters) and policy; the F/T
    /// node puts its readings in `forces`.
    pub fn new(
        p: &Params,
        declared: crate::runtime::params::Declared,
        forces: Arc<Latest<ForceReading>>,
    ) -> anyhow::Result<Self> {
        let control = ControllerNode::from_params(p)?;
        let topics = ControllerInterface::new(p, declared)?;
        topics.log(LogLevel::Info, &format!("ready: in process, model update {:?}", p.model_update));
        Ok(Self { control, topics, forces, start: Instant::now(), last: None, driver_fault: None })
    }

    fn seconds(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.start).as_secs_f64()
    }
}

/// Composed, the controller answers each measurement itself: nobody else may command the arm, and the
/// external torque reaches it in memory (no fifth message a cycle on the FRI thread).
impl Commander for InProcessController {
    fn in_process(&self) -> bool {
        true
    }

    /// Models, force commands and goals that arrived (between cycles, never between a measurement and
    /// its answer).
    fn take_inputs(&mut self) {
        self.topics.take_inputs(&mut self.control);
    }

    /// The answer to the measurement `out`, stamped `stamp` on the driver's clock, handed to `driver`:
    /// a torque for this very measurement, or a hold at once (a failed tick, no fresh force). Allocates
    /// nothing.
    fn answer(&mut self, _: &Node, driver: &mut LwrDriver, out: &DriverOutput, stamp: Time) -> Answered {
        let stamp = stamp.as_secs_f64();
        match self.forces.get() {
            Some(r) => self.control.on_force(r.stamp, r.force, self.seconds(r.arrived)),
            None => self.control.force_withheld(),
        }
        let session = DriverSession::of(out);
        // The fault's reason, once at each change (the only allocation here, never per cycle).
        if driver.fault() != self.driver_fault {
            self.driver_fault = driver.fault();
            self.control.on_driver_fault(self.driver_fault.map(|f| f.to_string()));
        }
        let sample =
            JointSample { stamp, session: Some(session.session), commanding: session.commanding, q: out.q, dq: out.dq };
        self.control.on_external_torque(stamp, &out.external_torque);
        let step = self.control.on_joint_state(&sample, self.seconds(Instant::now()));
        match &step.reply {
            // A torque the driver refuses (not 7 finite values) clears its command: it holds.
            Reply::Torque(tau) => driver.set_command(tau).map_or((), |_| ()),
            Reply::Hold(_) | Reply::Nothing(_) => driver.clear_command(),
        }
        self.last = Some((step, stamp, session));
        Answered { command_stamp: Some(stamp), ..Default::default() }
    }

    /// The law's kinematics of this cycle (already computed by its tick).
    fn tool_motion(&mut self, q: &[f64; 7], dq: &[f64; 7]) -> Option<FrameMotion> {
        Some(self.control.law.tool_motion(q, dq))
    }

    /// After the answer went: the torque command and the state on their topics, the press's progress,
    /// and what is worth a log line.
    fn publish(&mut self, stamp: Time, _: JointState) -> u64 {
        let Some((step, _, session)) = self.last.take() else { return 0 };
        let header = Header { stamp, frame_id: session.to_frame_id() };
        self.topics.publish(&self.control, &step, &header, session.commanding)
    }

    fn exit_report(&self) {
        eprintln!("deformation_controller: exit: {}", self.control.counters);
    }
}
