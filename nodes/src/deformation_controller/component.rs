//! The deformation controller as a component of the driver's process (`lwr_control`): it answers each
//! FRI measurement on the FRI thread, between the driver reading it and answering it, with the F/T
//! node's newest force handed over in memory — no DDS and no allocation on that path. Its topics are
//! the node's own: it takes /deformation_controller/force_command and /contact_estimator/model, and
//! publishes /lwr/joint_torque_command (for monitoring and recording: the driver does not listen to it
//! here) and /deformation_controller/state, after the answer has gone.

use std::sync::Arc;
use std::time::Instant;

use ros2_client::{Node, ParameterValue, Publisher, Subscription};
use softcontact_dynamics::lwr4;
use softcontact_msgs::builtin_interfaces::Time;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{ControllerState as StateMsg, ForceCommand};
use softcontact_msgs::std_msgs::Header;
use softcontact_wire::fri::InterfaceState;

use super::{ControlError, ControllerNode, JointSample, Notices, Params, Reply, Silence, Step};
use crate::contact_estimator::{ModelMsg, model_from_msg};
use crate::handover::{ForceReading, Latest};
use crate::lwr_driver::{DriverOutput, LwrDriver};
use crate::messages::{self, DriverSession};
use crate::ros::{self, LogLevel};

pub struct InProcessController {
    pub control: ControllerNode,
    node: Node,
    forces: Arc<Latest<ForceReading>>,
    commands: Subscription<ForceCommand>,
    models: Subscription<ModelMsg>,
    torque_pub: Publisher<JointState>,
    state_pub: Publisher<StateMsg>,
    names: Vec<String>,
    state_every: u64,
    start: Instant,
    /// The step of the newest measurement and the joint state it answered (stamp, session).
    last: Option<(Step, f64, DriverSession)>,
    notices: Notices,
    next_stale_log: Instant,
}

impl InProcessController {
    /// The controller's ROS node ("deformation_controller", serving its parameters) and policy; the F/T
    /// node puts its readings in `forces`.
    pub fn new(
        p: &Params,
        declared: Vec<(String, ParameterValue)>,
        forces: Arc<Latest<ForceReading>>,
    ) -> anyhow::Result<Self> {
        let control = ControllerNode::from_params(p)?;
        let mut node = ros::node_with_parameters("deformation_controller", declared)?;
        let commands =
            ros::subscription::<ForceCommand>(&mut node, "/deformation_controller/force_command", ros::reliable_qos())?;
        let models = ros::subscription::<ModelMsg>(&mut node, "/contact_estimator/model", ros::reliable_qos())?;
        let torque_pub = ros::publisher::<JointState>(&mut node, "/lwr/joint_torque_command", ros::reliable_qos())?;
        let state_pub = ros::publisher::<StateMsg>(&mut node, "/deformation_controller/state", ros::sensor_qos())?;
        ros::log(&node, LogLevel::Info, &format!("ready: in process, model update {:?}", p.model_update));
        Ok(Self {
            control,
            node,
            forces,
            commands,
            models,
            torque_pub,
            state_pub,
            names: lwr4::model().joints.iter().map(|j| j.name.clone()).collect(),
            state_every: ((1000.0 / p.state_rate).round() as u64).max(1),
            start: Instant::now(),
            last: None,
            notices: Notices::default(),
            next_stale_log: Instant::now(),
        })
    }

    fn seconds(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.start).as_secs_f64()
    }

    /// Models and force commands that arrived (between cycles, never between a measurement and its
    /// answer).
    pub fn take_inputs(&mut self) {
        while let Ok(Some((m, _))) = self.models.take() {
            let outcome = model_from_msg(&m).map_err(ControlError::from).and_then(|(m, s)| self.control.on_model(m, s));
            if let Err(e) = outcome {
                ros::log(&self.node, LogLevel::Warn, &format!("model refused: {e}"));
            }
        }
        while let Ok(Some((c, _))) = self.commands.take() {
            let (model_refused, commanded) = self.control.on_force_command(c.force, c.duration);
            if let Some(e) = model_refused {
                ros::log(&self.node, LogLevel::Warn, &format!("model refused: {e}"));
            }
            match commanded {
                Ok(()) => {
                    let m = self.control.law.contact_model();
                    let what = format!("{:?} k {:.0} λ {:.1}", m.kind, m.stiffness, m.damping);
                    let line = format!("force command {:.2} N over {:.2} s ({what})", c.force, c.duration);
                    ros::log(&self.node, LogLevel::Info, &line);
                }
                Err(e) => ros::log(&self.node, LogLevel::Error, &format!("force command {} N refused: {e}", c.force)),
            }
        }
    }

    /// The answer to the measurement `out`, stamped `stamp` on the driver's clock, handed to `driver`:
    /// a torque for this very measurement, or a hold at once (a failed tick, no fresh force). Allocates
    /// nothing.
    pub fn respond(&mut self, driver: &mut LwrDriver, out: &DriverOutput, stamp: f64) {
        match self.forces.get() {
            Some(r) => self.control.on_force(r.stamp, r.force, self.seconds(r.arrived)),
            None => self.control.force_withheld(),
        }
        let session = DriverSession { session: out.session, commanding: out.state == InterfaceState::Command };
        let sample =
            JointSample { stamp, session: Some(session.session), commanding: session.commanding, q: out.q, dq: out.dq };
        let step = self.control.on_joint_state(&sample, self.seconds(Instant::now()));
        match &step.reply {
            // A torque the driver refuses (not 7 finite values) clears its command: it holds.
            Reply::Torque(tau) => driver.set_command(tau).map_or((), |_| ()),
            Reply::Hold(_) | Reply::Nothing(_) => driver.clear_command(),
        }
        self.last = Some((step, stamp, session));
    }

    /// After the answer went: the torque command and the state on their topics, and what is worth a
    /// log line.
    pub fn publish(&mut self, stamp: Time) -> u64 {
        let Some((step, _, session)) = self.last.take() else { return 0 };
        let header = Header { stamp, frame_id: session.to_frame_id() };
        let mut errors = 0;
        match &step.reply {
            Reply::Torque(tau) => {
                errors +=
                    u64::from(self.torque_pub.publish(messages::torque_command(&self.names, tau, &header)).is_err());
                if self.control.counters.ticks.is_multiple_of(self.state_every) {
                    errors += u64::from(self.state_pub.publish(step.state.to_msg(stamp)).is_err());
                }
            }
            Reply::Hold(e) => {
                ros::log(&self.node, LogLevel::Error, &format!("tick failed, the driver holds: {e}"));
                errors += u64::from(self.torque_pub.publish(messages::hold_request(&self.names, &header)).is_err());
            }
            Reply::Nothing(Silence::NoFreshForce) if session.commanding && Instant::now() >= self.next_stale_log => {
                ros::log(&self.node, LogLevel::Warn, "no fresh force reading: the driver holds");
                self.next_stale_log = Instant::now() + std::time::Duration::from_secs(1);
            }
            Reply::Nothing(_) => {}
        }
        if step.restarted {
            let why = "new KRC session, KRC not commanding, or measurements interrupted: approaching again";
            ros::log(&self.node, LogLevel::Warn, why);
        }
        for (level, line) in self.notices.changes(&self.control, &step) {
            ros::log(&self.node, level, &line);
        }
        errors
    }
}
