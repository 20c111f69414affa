//! The deformation controller's ROS side, one copy for every process that hosts it (its own, and the
//! composed `lwr_control`): what it takes — models, force commands on a topic, and the force action
//! `/deformation_controller/press` (softcontact_msgs/action/PressForce: goal force and move duration;
//! feedback force, deformation and phase; result the force reached and its error) — and what it
//! publishes after each answer: /lwr/joint_torque_command, /deformation_controller/state and its log.
//! The node policy stays in [`ControllerNode`] and [`Press`]; this only wires them to the middleware.
//!
//! The service /deformation_controller/retare (std_srvs/Trigger) retreats and re-tares: the node lifts
//! the hand, the F/T node's /ft_sensor/bias is called once the hand is free and still (retried while it
//! refuses, up to [`TARE_ATTEMPTS`]), and the controller approaches the surface again; the answer comes
//! when the tare is taken (or given up).
//!
//! One press at a time: a new goal or force command supersedes the one under way (the move goes on
//! from the present reference, as a new command mid-move does), which is aborted. A cancel request is
//! rejected — stopping a move midway is a new goal, so that the hand never stops with a jolt.

use softcontact_msgs::topics;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ros2_client::action::{
    ActionServer, ActionServerQosPolicies, CancelGoalResponse, GetResultResponse, GoalId, GoalInfo, GoalStatusEnum,
    SendGoalResponse,
};
use ros2_client::action_msgs::{CancelGoalResponseEnum, GoalStatus, GoalStatusArray};
use ros2_client::service::{Client, Server};
use ros2_client::{ActionTypeName, Node, Publisher, RmwRequestId, Subscription};
use softcontact_dynamics::lwr4;
use softcontact_msgs::sensor_msgs::JointState;
use softcontact_msgs::softcontact_msgs::{
    ControllerState as StateMsg, ForceCommand, PressForceFeedback, PressForceGoal, PressForceResult,
};
use softcontact_msgs::std_msgs::Header;
use softcontact_msgs::std_srvs::{TriggerRequest, TriggerResponse};

use super::{ControlError, ControllerNode, Notices, Params, Press, PressProgress, Reply, Retare, Silence, Step};
use crate::contact_estimator::{ModelMsg, model_from_msg};
use crate::messages;
use crate::runtime::ros::{self, LogLevel};
use crate::runtime::writer_pin::WriterPin;

/// The action's name.
pub use softcontact_msgs::topics::PRESS_ACTION;
/// Results kept for late result requests, and result requests kept waiting (the oldest go first).
const KEPT_RESULTS: usize = 16;
const WAITING_REQUESTS: usize = 16;

/// Calls of /ft_sensor/bias before a re-tare is given up, their spacing and how long one may take.
pub const TARE_ATTEMPTS: u32 = 5;
const TARE_RETRY: Duration = Duration::from_millis(200);
const TARE_TIMEOUT: Duration = Duration::from_secs(2);

type PressServer = ActionServer<PressForceGoal, PressForceResult, PressForceFeedback>;

/// The action's server and types, with the QoS of ROS 2 actions (services reliable, status latched).
pub fn press_server(node: &mut Node, mapping: &str) -> anyhow::Result<PressServer> {
    let name = ros::resolve(node, PRESS_ACTION)?;
    let [goal_service, result_service, cancel_service, feedback_publisher, status_publisher] = ros::press_action_qos();
    let qos =
        ActionServerQosPolicies { goal_service, result_service, cancel_service, feedback_publisher, status_publisher };
    Ok(node.create_action_server(
        ros::service_mapping(mapping)?,
        &name,
        &ActionTypeName::new("softcontact_msgs", "PressForce"),
        qos,
    )?)
}

/// The press under way.
struct Goal {
    info: GoalInfo,
    press: Press,
}

/// A retreat to re-tare under way: the user's request, and the call of /ft_sensor/bias in flight.
struct RetareCall {
    request: RmwRequestId,
    call: Option<(RmwRequestId, Instant)>,
    attempts: u32,
    next_try: Instant,
    refusal: String,
}

pub struct ControllerInterface {
    pub node: Node,
    retare_server: Server<TriggerRequest, TriggerResponse>,
    bias_client: Client<TriggerRequest, TriggerResponse>,
    retare: Option<RetareCall>,
    commands: Subscription<ForceCommand>,
    models: Subscription<ModelMsg>,
    /// Models come from one estimator: the first writer heard while it is the only one
    /// ([`crate::runtime::writer_pin`]); a stranger's models are refused (force commands and goals come from any
    /// client: they are the user's).
    model_writer: WriterPin,
    server: PressServer,
    goal: Option<Goal>,
    ended: VecDeque<(GoalId, GoalStatusEnum, PressForceResult)>,
    /// The goals refused when they came (the latest [`KEPT_RESULTS`]): a repeat is answered as they were.
    refused_goals: VecDeque<GoalId>,
    waiting: VecDeque<(RmwRequestId, GoalId)>,
    torque_pub: Publisher<JointState>,
    state_pub: Publisher<StateMsg>,
    names: Vec<String>,
    state_every: u64,
    notices: Notices,
    next_stale_log: Instant,
    /// A hold that lasts (a tripped force check) is logged once a second, not each tick.
    next_hold_log: Instant,
}

impl ControllerInterface {
    /// The node "deformation_controller", serving its `declared` parameters, with its topics and action.
    pub fn new(p: &Params, declared: crate::runtime::params::Declared) -> anyhow::Result<Self> {
        let mut node = ros::node_with_parameters("deformation_controller", declared)?;
        let commands = ros::subscription(&mut node, &topics::FORCE_COMMAND, ros::reliable_qos())?;
        let models = ros::subscription(&mut node, &topics::CONTACT_MODEL, ros::reliable_qos())?;
        let server = press_server(&mut node, &p.service_mapping)?;
        let mapping = ros::service_mapping(&p.service_mapping)?;
        let retare_name = ros::resolve(&node, topics::RETARE_SERVICE)?;
        let retare_server = ros::trigger_server(&mut node, mapping, &retare_name)?;
        let bias_name = ros::resolve(&node, topics::FT_BIAS_SERVICE)?;
        let bias_client = ros::trigger_client(&mut node, mapping, &bias_name)?;
        let torque_pub = ros::publisher(&mut node, &topics::JOINT_TORQUE_COMMAND, ros::reliable_qos())?;
        let state_pub = ros::publisher(&mut node, &topics::CONTROLLER_STATE, ros::sensor_qos())?;
        Ok(Self {
            node,
            retare_server,
            bias_client,
            retare: None,
            commands,
            models,
            model_writer: WriterPin::default(),
            server,
            goal: None,
            ended: VecDeque::new(),
            refused_goals: VecDeque::new(),
            waiting: VecDeque::new(),
            torque_pub,
            state_pub,
            names: lwr4::model().joints.iter().map(|j| j.name.clone()).collect(),
            state_every: ((1000.0 / p.state_rate).round() as u64).max(1),
            notices: Notices::default(),
            next_stale_log: Instant::now(),
            next_hold_log: Instant::now(),
        })
    }

    pub fn log(&self, level: LogLevel, line: &str) {
        ros::log(&self.node, level, line);
    }

    /// Models, force commands, goals, cancel and result requests that arrived (between ticks).
    pub fn take_inputs(&mut self, control: &mut ControllerNode) {
        while let Ok(Some((m, info))) = self.models.take() {
            let writers = || self.models.get_publisher_count(&self.node);
            if let Err(e) = self.model_writer.admit(info.publisher_gid().to_bytes16(), writers) {
                // Counted with the implausible ones: the exit line's "models refused" is every model not
                // adopted.
                control.counters.models_refused += 1;
                if self.model_writer.refused.is_power_of_two() {
                    self.log(LogLevel::Warn, &format!("model refused {} times so far: {e}", self.model_writer.refused));
                }
                continue;
            }
            let outcome = match model_from_msg(&m) {
                Ok((model, surface)) => control.on_model(model, surface),
                Err(e) => {
                    // A message that is no model is refused as an implausible one is.
                    control.counters.models_refused += 1;
                    Err(ControlError::from(e))
                }
            };
            if let Err(e) = outcome {
                // The log backs off as refusals repeat (a stranger may send them at any rate).
                if control.counters.models_refused.is_power_of_two() {
                    let why: String = e.to_string().chars().take(300).collect();
                    let n = control.counters.models_refused;
                    self.log(LogLevel::Warn, &format!("model refused ({n} so far): {why}"));
                }
            }
        }
        while let Ok(Some((c, _))) = self.commands.take() {
            if self.command(control, c.force, c.duration).is_ok() {
                self.end_goal(GoalStatusEnum::Aborted, f64::NAN, "superseded by a force command");
            }
        }
        while let Ok(Some((id, request))) = self.server.receive_goal() {
            // A goal id already seen is never a new press: a client that resends while its reply is late
            // (as the Fast DDS and Cyclone DDS peers do), or a replay, gets the answer the id first got.
            let seen = self.goal.as_ref().filter(|g| g.info.goal_id == request.goal_id).map(|g| (true, g.info.stamp));
            let seen = seen.or_else(|| {
                let refused = self.refused_goals.contains(&request.goal_id);
                let ended = self.ended.iter().any(|(g, _, _)| *g == request.goal_id);
                (refused || ended).then(|| (!refused, ros2_client::builtin_interfaces::Time::now()))
            });
            if let Some((accepted, stamp)) = seen {
                let _ = self.server.send_goal_response(id, SendGoalResponse { accepted, stamp });
                continue;
            }
            let (force, duration) = (request.goal.force, request.goal.duration);
            let commanded = self.command(control, force, duration);
            let accepted = commanded.is_ok();
            let stamp = ros2_client::builtin_interfaces::Time::now();
            if let Err(why) = commanded {
                // The reason waits as the goal's result, for the client that asks.
                let result = PressForceResult { force: f64::NAN, error: f64::NAN, message: why };
                self.remember(request.goal_id, GoalStatusEnum::Aborted, result);
                if self.refused_goals.len() == KEPT_RESULTS {
                    self.refused_goals.pop_front();
                }
                self.refused_goals.push_back(request.goal_id);
            } else {
                self.end_goal(GoalStatusEnum::Aborted, f64::NAN, "superseded by a newer goal");
                let press = Press::new(force, duration, control.law.time());
                self.goal = Some(Goal { info: GoalInfo { goal_id: request.goal_id, stamp }, press });
            }
            let _ = self.server.send_goal_response(id, SendGoalResponse { accepted, stamp });
            self.publish_statuses();
        }
        while let Ok(Some((id, _))) = self.server.receive_cancel_request() {
            let rejected =
                CancelGoalResponse { return_code: CancelGoalResponseEnum::Rejected, goals_canceling: vec![] };
            let _ = self.server.send_cancel_response(id, rejected);
        }
        self.follow_retare(control);
        while let Ok(Some((id, request))) = self.server.receive_result_request() {
            match self.ended.iter().find(|(g, _, _)| *g == request.goal_id) {
                Some((_, status, result)) => {
                    let _ = self.server.send_result(id, GetResultResponse { status: *status, result: result.clone() });
                }
                None if self.goal.as_ref().is_some_and(|g| g.info.goal_id == request.goal_id) => {
                    if self.waiting.len() == WAITING_REQUESTS {
                        self.waiting.pop_front();
                    }
                    self.waiting.push_back((id, request.goal_id));
                }
                None => {
                    let unknown = PressForceResult { force: f64::NAN, error: f64::NAN, message: "unknown goal".into() };
                    let response = GetResultResponse { status: GoalStatusEnum::Unknown, result: unknown };
                    let _ = self.server.send_result(id, response);
                }
            }
        }
    }

    /// Retare requests, and the tare of the one under way once the hand is free and still.
    fn follow_retare(&mut self, control: &mut ControllerNode) {
        while let Ok(Some((id, _))) = self.retare_server.receive_request() {
            let refused = match (&self.retare, control.request_retare()) {
                (Some(_), _) => Some("a retreat to re-tare is under way".to_string()),
                (None, Err(e)) => Some(e.to_string()),
                (None, Ok(())) => None,
            };
            match refused {
                Some(why) => {
                    let _ = self.retare_server.send_response(id, TriggerResponse { success: false, message: why });
                }
                None => {
                    self.log(LogLevel::Info, "retreating to re-tare the sensor");
                    self.end_goal(GoalStatusEnum::Aborted, f64::NAN, "a retreat to re-tare began");
                    let now = Instant::now();
                    self.retare = Some(RetareCall {
                        request: id,
                        call: None,
                        attempts: 0,
                        next_try: now,
                        refusal: String::new(),
                    });
                }
            }
        }
        let Some(r) = self.retare.as_mut() else { return };
        let answer = match (control.retare(), r.call) {
            // The controller restarted meanwhile: the retreat has nothing left to do.
            (None, None) => Some((false, "interrupted: the controller restarted".to_string())),
            (Some(Retare::Taring), None) if Instant::now() >= r.next_try => {
                if let Ok(call) = self.bias_client.send_request(TriggerRequest::default()) {
                    r.call = Some((call, Instant::now()));
                    r.attempts += 1;
                }
                None
            }
            (_, Some((call, sent))) => {
                let response = match self.bias_client.receive_response() {
                    Ok(Some((id, response))) if id == call => Some(response),
                    _ if sent.elapsed() > TARE_TIMEOUT => {
                        Some(TriggerResponse { success: false, message: "/ft_sensor/bias did not answer".into() })
                    }
                    _ => None,
                };
                match response {
                    Some(t) if t.success => {
                        control.on_tared(true);
                        Some((true, format!("re-tared ({}): approaching the surface again", t.message)))
                    }
                    Some(t) => {
                        r.call = None;
                        r.refusal = t.message;
                        r.next_try = Instant::now() + TARE_RETRY;
                        (r.attempts >= TARE_ATTEMPTS).then(|| {
                            control.on_tared(false);
                            let why = format!(
                                "the F/T node refused {} times ({}): approaching again with the old zero",
                                r.attempts, r.refusal
                            );
                            (false, why)
                        })
                    }
                    None => None,
                }
            }
            _ => None,
        };
        if let Some((success, message)) = answer {
            let request = r.request;
            self.retare = None;
            self.log(if success { LogLevel::Info } else { LogLevel::Warn }, &message);
            let _ = self.retare_server.send_response(request, TriggerResponse { success, message });
        }
    }

    /// A force command from the topic or a goal; whether the controller took it (logged either way).
    /// A force command or goal: taken, or why not.
    fn command(&mut self, control: &mut ControllerNode, force: f64, duration: f64) -> Result<(), String> {
        let (model_refused, commanded) = control.on_force_command(force, duration);
        if let Some(e) = model_refused {
            self.log(LogLevel::Warn, &format!("model refused: {e}"));
        }
        match commanded {
            Ok(()) => {
                let m = control.law.contact_model();
                let what = format!("{:?} k {:.0} λ {:.1}", m.kind, m.stiffness, m.damping);
                self.log(LogLevel::Info, &format!("force command {force:.2} N over {duration:.2} s ({what})"));
                Ok(())
            }
            Err(e) => {
                self.log(LogLevel::Error, &format!("force command {force:?} N refused: {e}"));
                Err(e.to_string())
            }
        }
    }

    fn remember(&mut self, goal: GoalId, status: GoalStatusEnum, result: PressForceResult) {
        if self.ended.len() == KEPT_RESULTS {
            self.ended.pop_front();
        }
        self.ended.push_back((goal, status, result));
    }

    /// Ends the press under way (if any) with `status`, answering the requests that wait for it.
    fn end_goal(&mut self, status: GoalStatusEnum, force: f64, message: &str) {
        let Some(goal) = self.goal.take() else { return };
        let result = PressForceResult { force, error: force - goal.press.force, message: message.into() };
        if status != GoalStatusEnum::Succeeded {
            self.log(LogLevel::Warn, &format!("press of {:.2} N aborted: {message}", goal.press.force));
        }
        let id = goal.info.goal_id;
        for (request, _) in self.waiting.iter().filter(|(_, g)| *g == id) {
            let _ = self.server.send_result(*request, GetResultResponse { status, result: result.clone() });
        }
        self.waiting.retain(|(_, g)| *g != id);
        self.remember(id, status, result);
        self.publish_statuses();
    }

    /// The status of the press under way and of those that ended (latched: a late client reads it).
    fn publish_statuses(&self) {
        let mut status_list: Vec<GoalStatus> = self
            .ended
            .iter()
            .map(|(id, status, _)| GoalStatus {
                goal_info: GoalInfo { goal_id: *id, stamp: ros2_client::builtin_interfaces::Time::ZERO },
                status: *status,
            })
            .collect();
        if let Some(g) = &self.goal {
            status_list.push(GoalStatus { goal_info: g.info.clone(), status: GoalStatusEnum::Executing });
        }
        let _ = self.server.send_goal_statuses(GoalStatusArray { status_list });
    }

    /// After the answer to a joint state went: the torque command and the state on their topics, the
    /// press's progress, and what is worth a log line. `header` is the answered joint state's (stamp and
    /// session); `commanding` whether the KRC commands. Returns the publishing errors.
    pub fn publish(&mut self, control: &ControllerNode, step: &Step, header: &Header, commanding: bool) -> u64 {
        let mut errors = 0;
        match &step.reply {
            Reply::Torque(tau) => {
                errors +=
                    u64::from(self.torque_pub.publish(messages::torque_command(&self.names, tau, header)).is_err());
                if control.counters.ticks.is_multiple_of(self.state_every) {
                    errors += u64::from(
                        self.state_pub.publish(messages::controller_state(&step.state, header.stamp)).is_err(),
                    );
                }
            }
            Reply::Hold(e) => {
                // An empty command: the driver holds at once, rather than repeat an older torque.
                if Instant::now() >= self.next_hold_log {
                    self.log(LogLevel::Error, &format!("tick failed, the driver is asked to hold: {e}"));
                    self.next_hold_log = Instant::now() + Duration::from_secs(1);
                }
                errors += u64::from(self.torque_pub.publish(messages::hold_request(&self.names, header)).is_err());
            }
            Reply::Nothing(why @ (Silence::NoFreshForce | Silence::NoArmForce))
                if commanding && Instant::now() >= self.next_stale_log =>
            {
                let what = match why {
                    Silence::NoFreshForce => "no fresh force reading",
                    _ => "no external torque estimate of the KRC (/lwr/external_torque) to check the force with",
                };
                self.log(LogLevel::Warn, &format!("{what}: sending no command (the driver holds)"));
                self.next_stale_log = Instant::now() + Duration::from_secs(1);
            }
            Reply::Nothing(_) => {}
        }
        if step.restarted {
            let why = "new KRC session, KRC not commanding, or joint states interrupted: approaching again";
            self.log(LogLevel::Warn, why);
        }
        for (level, line) in self.notices.changes(control, step) {
            self.log(level, &line);
        }
        if matches!(step.reply, Reply::Nothing(Silence::NotNewer)) {
            return errors;
        }
        if let Some(goal) = self.goal.as_mut() {
            match goal.press.follow(step, control.law.time()) {
                PressProgress::Done { force } => self.end_goal(GoalStatusEnum::Succeeded, force, ""),
                PressProgress::Aborted(why) => self.end_goal(GoalStatusEnum::Aborted, f64::NAN, &why),
                progress if control.counters.ticks.is_multiple_of(self.state_every) => {
                    let (force, deformation) = match progress {
                        PressProgress::Moving { force, deformation } => (force, deformation),
                        _ => (f64::NAN, f64::NAN),
                    };
                    let phase = progress.phase().to_string();
                    let feedback = PressForceFeedback { force, deformation, phase };
                    errors += u64::from(self.server.send_feedback(goal.info.goal_id, feedback).is_err());
                }
                _ => {}
            }
        }
        errors
    }
}
