//! The deformation controller's node policy, one copy for every host: its own process, the composed
//! 1 kHz process (`lwr_control`), and the in-process cell of the demo and the tests. The host hands in
//! what arrived (joint states, force readings, models, force commands) with its own monotonic clock's
//! reading `now` [s]; the node decides what is ticked, with which force, and what the driver is told.
//!
//! - Only a joint state newer than the newest one ticked is ticked (a replayed recording, or a backlog
//!   after a stall, never drives the arm); the controller runs on the joint states' stamps. A stamp
//!   from the far future (a stranger's) silences the node until it is passed: the driver's watchdog
//!   holds the arm meanwhile and reports the silence.
//! - A force reading counts while it is at most `stale_after` old by `now`; without one no command is
//!   sent (the driver's watchdog holds). A reading that is not finite, or not newer by its stamp, is
//!   dropped.
//! - A new KRC session, a KRC that does not command, or joint states interrupted longer than
//!   `restart_after` by their stamps restart the controller: the contact is forgotten and the hand
//!   approaches again.
//! - A tick that fails asks the driver to hold at once, never for an older torque.
//! - Models: adopted at the next force command (seed 001), or on arrival with the standing command
//!   re-planned (`model_update: continuous`). An implausible one is refused and the present one kept.
//! - Retreat and re-tare (a drifting sensor's zero is only known with the hand free): the hand lifts
//!   [`RETARE_LIFT`] off the surface and settles, the host has the F/T node tare, and the controller
//!   restarts — it approaches again and finds the onset with the fresh zero. Commands are refused
//!   meanwhile.

use nalgebra::Vector3;
use softcontact_contact::ContactModel;
use softcontact_dynamics::{Data, FrameId, Model, lwr4};

use super::{ControlError, ControllerState, DeformationController, ModelUpdate, Params};
use crate::geometry::ContactGeometry;
use crate::ros::LogLevel;

/// A joint state as the driver measured it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSample {
    /// When it was measured, on the driver's clock [s].
    pub stamp: f64,
    /// The KRC session it belongs to, and whether the KRC commands (`None`: not said).
    pub session: Option<u32>,
    pub commanding: bool,
    pub q: [f64; 7],
    pub dq: [f64; 7],
}

/// What the driver is told for one joint state.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// Total joint torques (gravity included) answering this joint state.
    Torque([f64; 7]),
    /// The tick failed: hold at once (the error says why).
    Hold(ControlError),
    /// Nothing: the driver answers with what it has, and its watchdog holds when that ages.
    Nothing(Silence),
}

/// Why a joint state got no command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Silence {
    /// Not newer than the newest joint state ticked.
    NotNewer,
    /// The KRC does not command (monitor mode).
    NotCommanding,
    /// No force reading at most `stale_after` old.
    NoFreshForce,
}

/// One joint state handled.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub reply: Reply,
    /// The controller's report (the normal force alone when it did not tick).
    pub state: ControllerState,
    /// The contact force on the hand in the world [N] (zero without a fresh reading).
    pub force_world: Vector3<f64>,
    /// The controller restarted before this joint state (new session, monitor mode or a gap).
    pub restarted: bool,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeCounters {
    /// Commands sent.
    pub ticks: u64,
    /// Joint states without a fresh force reading.
    pub no_fresh_force: u64,
    /// Ticks that failed (the driver was asked to hold).
    pub failed: u64,
    pub models_adopted: u64,
    pub models_refused: u64,
    pub restarts: u64,
    /// Joint states not newer than the newest one ticked.
    pub not_newer: u64,
    /// Force readings dropped (not finite, or not newer).
    pub readings_dropped: u64,
}

/// The policy's own settings (the rest of [`Params`] configures the law).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Policy {
    stale_after: f64,
    restart_after: f64,
    model_update: ModelUpdate,
    retarget_duration: f64,
}

/// How far the hand lifts off the surface to re-tare [m], over how long [s], and how long it then
/// settles before the tare [s] (the surface's fast relaxation and the arm's motion die out).
pub const RETARE_LIFT: f64 = 0.01;
const RETARE_LIFT_TIME: f64 = 1.0;
const RETARE_SETTLE: f64 = 0.5;

/// Where a retreat to re-tare is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Retare {
    /// Lifting and settling until the controller's time `until` [s].
    Lifting { until: f64 },
    /// Free and still: the F/T node is to tare now.
    Taring,
}

pub struct ControllerNode {
    /// The control law.
    pub law: DeformationController,
    policy: Policy,
    geometry: ContactGeometry,
    kinematics: (Model, Data, FrameId),
    /// The newest force reading in the sensor frame and when it arrived (`now`).
    force: Option<(Vector3<f64>, f64)>,
    newest_force_stamp: f64,
    newest_joint_state_stamp: f64,
    /// The session of the newest joint state.
    last_session: Option<u32>,
    ticks_in_session: u64,
    pending_model: Option<(ContactModel, Vector3<f64>)>,
    retare: Option<Retare>,
    pub counters: NodeCounters,
}

impl ControllerNode {
    /// The node with its parameters (checked by `Params::validate` when loaded) around `law`.
    pub fn new(params: &Params, law: DeformationController) -> Result<Self, ControlError> {
        let geometry = ContactGeometry::lwr4(Vector3::from(params.normal)).ok_or(ControlError::ZeroNormal)?;
        let model = lwr4::model();
        let tool = model.frame_id(lwr4::TOOL_FRAME)?;
        let data = model.data();
        Ok(Self {
            law,
            policy: Policy {
                stale_after: params.stale_after,
                restart_after: params.restart_after,
                model_update: params.model_update,
                retarget_duration: params.retarget_duration,
            },
            geometry,
            kinematics: (model, data, tool),
            force: None,
            newest_force_stamp: f64::NEG_INFINITY,
            newest_joint_state_stamp: f64::NEG_INFINITY,
            last_session: None,
            ticks_in_session: 0,
            pending_model: None,
            retare: None,
            counters: NodeCounters::default(),
        })
    }

    /// The node as the parameters describe it, with their initial model.
    pub fn from_params(params: &Params) -> Result<Self, ControlError> {
        let law = DeformationController::new(params.controller_config(), params.initial_model.clone())?;
        Self::new(params, law)
    }

    pub fn geometry(&self) -> &ContactGeometry {
        &self.geometry
    }

    /// A force reading of the sensor in its own frame (/ft_sensor/wrench: tared, the hand's weight
    /// removed), stamped `stamp` by the sensor node, arrived at `now`.
    pub fn on_force(&mut self, stamp: f64, force_in_sensor: Vector3<f64>, now: f64) {
        if force_in_sensor.iter().all(|v| v.is_finite()) && stamp.is_finite() && stamp > self.newest_force_stamp {
            self.newest_force_stamp = stamp;
            self.force = Some((force_in_sensor, now));
        } else if stamp != self.newest_force_stamp {
            // (The same reading again, as a host that polls its newest one may hand it over, is no news.)
            self.counters.readings_dropped += 1;
        }
    }

    /// Forgets the force reading: until the next one arrives no command is sent (the sensor node stopped
    /// publishing, e.g. an invalid sample).
    pub fn force_withheld(&mut self) {
        self.force = None;
    }

    /// A model from the estimator with its placement of the undeformed surface in the world. Returns
    /// whether it was adopted now (`continuous`) rather than kept for the next command; an implausible
    /// model is refused.
    pub fn on_model(&mut self, model: ContactModel, surface: Vector3<f64>) -> Result<bool, ControlError> {
        match self.policy.model_update {
            ModelUpdate::Continuous => {
                let adopted = self.law.adopt_estimate(model, &surface, Some(self.policy.retarget_duration));
                self.count_adoption(adopted.is_ok());
                adopted.map(|()| true)
            }
            ModelUpdate::OnCommand => {
                self.pending_model = Some((model, surface));
                Ok(false)
            }
        }
    }

    /// A force command [N] reached over `duration` [s]. The newest model waiting is adopted first (seed
    /// 001: once per command cycle); if it is refused the command goes on with the present model, and
    /// the refusal is returned beside the command's own result.
    pub fn on_force_command(&mut self, force: f64, duration: f64) -> (Option<ControlError>, Result<(), ControlError>) {
        if self.retare.is_some() {
            return (None, Err(ControlError::Retaring));
        }
        let refused = self.pending_model.take().and_then(|(m, surface)| {
            let adopted = self.law.adopt_estimate(m, &surface, None);
            self.count_adoption(adopted.is_ok());
            adopted.err()
        });
        (refused, self.law.command_force(force, duration))
    }

    /// Retreat and re-tare: lifts the hand off the surface it holds. Needs contact (the hand still on
    /// the way down is moving, and a tare refuses motion).
    pub fn request_retare(&mut self) -> Result<(), ControlError> {
        if self.retare.is_some() {
            return Err(ControlError::Retaring);
        }
        let lift = -RETARE_LIFT.min(self.law.config().limits.max_lift);
        self.law.command_deformation(lift, RETARE_LIFT_TIME)?;
        self.retare = Some(Retare::Lifting { until: self.law.time() + RETARE_LIFT_TIME + RETARE_SETTLE });
        Ok(())
    }

    /// Where a retreat to re-tare is (`None`: none under way).
    pub fn retare(&self) -> Option<Retare> {
        self.retare
    }

    /// The F/T node tared (or refused, `tared` false): the controller restarts, to find the surface
    /// again with the sensor's zero as it now is.
    pub fn on_tared(&mut self, _tared: bool) {
        if self.retare.take().is_some() {
            self.law.restart();
        }
    }

    fn count_adoption(&mut self, adopted: bool) {
        if adopted {
            self.counters.models_adopted += 1;
        } else {
            self.counters.models_refused += 1;
        }
    }

    /// One joint state, arrived at `now`: what the driver is told.
    pub fn on_joint_state(&mut self, js: &JointSample, now: f64) -> Step {
        let nothing =
            |why, state| Step { reply: Reply::Nothing(why), state, force_world: Vector3::zeros(), restarted: false };
        // A stamp that is no number (or infinite) would end the order for good: it is not newer.
        if !(js.stamp.is_finite() && js.stamp > self.newest_joint_state_stamp) {
            self.counters.not_newer += 1;
            return nothing(Silence::NotNewer, ControllerState::default());
        }
        // Interruptions by the joint states' own clock, the loop's: in lockstep the simulated time, where
        // a host starved for a while is no interruption of the arm (restarting while pressing hard on
        // every such stall threw the hand about).
        let previous = std::mem::replace(&mut self.newest_joint_state_stamp, js.stamp);
        let silence = if previous.is_finite() { js.stamp - previous } else { 0.0 };
        let restarted = self.ticks_in_session > 0
            && (!(silence <= self.policy.restart_after) || js.session != self.last_session || !js.commanding);
        if restarted {
            self.counters.restarts += 1;
            self.ticks_in_session = 0;
            // The contact is forgotten: a retreat under way has nothing left to do.
            self.retare = None;
        }
        self.last_session = js.session;
        if !self.law.follow_session(js.session, js.commanding, silence) {
            return Step { restarted, ..nothing(Silence::NotCommanding, ControllerState::default()) };
        }
        let fresh = self.force.filter(|(_, arrived)| now - arrived <= self.policy.stale_after);
        let Some((force_in_sensor, _)) = fresh else {
            self.counters.no_fresh_force += 1;
            return Step { restarted, ..nothing(Silence::NoFreshForce, ControllerState::default()) };
        };
        // The contact force on the hand in the world, through the arm's own kinematics.
        let (model, data, tool) = &mut self.kinematics;
        let force_world = if js.q.iter().all(|v| v.is_finite()) {
            model.forward_kinematics(data, &js.q);
            self.geometry.world_force(&model.frame_pose(data, *tool).rotation, &force_in_sensor)
        } else {
            Vector3::repeat(f64::NAN)
        };
        let f = self.geometry.normal_force(&force_world);
        let (reply, state) = match self.law.tick(js.stamp, &js.q, &js.dq, f, &force_world) {
            Ok((tau, state)) => {
                self.counters.ticks += 1;
                self.ticks_in_session += 1;
                if let Some(Retare::Lifting { until }) = self.retare
                    && self.law.time() >= until
                {
                    self.retare = Some(Retare::Taring);
                }
                (Reply::Torque(tau), state)
            }
            Err(e) => {
                self.counters.failed += 1;
                (Reply::Hold(e), ControllerState { f, ..Default::default() })
            }
        };
        Step { reply, state, force_world, restarted }
    }
}

/// A force command followed to the end of its move: what the force action (PressForce) reports. The
/// move ends `duration` after the command on the controller's own clock; the force reached is the mean
/// measured normal force of the move's last 10 ticks (seed 001 reads the force at the end of the move).
/// The press is aborted when the controller restarts, loses contact, passes its force limit or fails a
/// tick: the arm then does what the controller's rules say, and the user is told why.
#[derive(Debug, Clone, PartialEq)]
pub struct Press {
    pub force: f64,
    pub duration: f64,
    /// The controller's time when the command was taken [s].
    started: f64,
    /// The normal forces of the last ticks, newest at `next - 1`.
    last_forces: [f64; PRESS_AVERAGE],
    ticked: usize,
}

/// Ticks averaged for the force reached (10 ms at 1 kHz).
const PRESS_AVERAGE: usize = 10;

/// Where a press is.
#[derive(Debug, Clone, PartialEq)]
pub enum PressProgress {
    /// Taken, not ticked since (no fresh force: the driver holds meanwhile).
    Waiting,
    /// The move goes on: the measured normal force [N] and deformation [m].
    Moving { force: f64, deformation: f64 },
    /// The move ended: the force reached [N] (its error is `force − Press::force`).
    Done { force: f64 },
    /// It cannot end as commanded.
    Aborted(String),
}

impl PressProgress {
    /// The feedback's phase.
    pub fn phase(&self) -> &'static str {
        match self {
            Self::Waiting => "waiting",
            Self::Moving { .. } => "moving",
            Self::Done { .. } => "done",
            Self::Aborted(_) => "aborted",
        }
    }
}

impl Press {
    /// A press the node took at the controller's time `law_time` (after `on_force_command` succeeded).
    pub fn new(force: f64, duration: f64, law_time: f64) -> Self {
        Self { force, duration, started: law_time, last_forces: [0.0; PRESS_AVERAGE], ticked: 0 }
    }

    /// The press after `step`, the controller's time being `law_time` after it. Allocates nothing unless
    /// aborted.
    pub fn follow(&mut self, step: &Step, law_time: f64) -> PressProgress {
        if step.restarted {
            return PressProgress::Aborted("the controller restarted (new KRC session, monitor mode or a gap)".into());
        }
        match &step.reply {
            Reply::Hold(e) => return PressProgress::Aborted(format!("a tick failed and the driver held: {e}")),
            Reply::Nothing(Silence::NotCommanding) => {
                return PressProgress::Aborted("the KRC stopped commanding".into());
            }
            Reply::Nothing(_) if self.ticked == 0 => return PressProgress::Waiting,
            Reply::Nothing(_) => {}
            Reply::Torque(_) => {
                if step.state.contact_lost {
                    return PressProgress::Aborted("contact lost during the move".into());
                }
                if step.state.force_limited {
                    return PressProgress::Aborted("the force limit was passed: the controller backed off".into());
                }
                self.last_forces[self.ticked % PRESS_AVERAGE] = step.state.f;
                self.ticked += 1;
            }
        }
        // The end by the controller's clock (a restart would have aborted first: it only moves on).
        if law_time >= self.started + self.duration - 1e-9 {
            let n = self.ticked.min(PRESS_AVERAGE);
            return PressProgress::Done { force: self.last_forces[..n].iter().sum::<f64>() / n as f64 };
        }
        PressProgress::Moving { force: step.state.f, deformation: step.state.z }
    }
}

impl std::fmt::Display for NodeCounters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} commands sent, {} joint states without a fresh force, {} failed, {} models adopted, {} models refused, \
             {} restarts, {} joint states not newer than the last, {} force readings dropped",
            self.ticks,
            self.no_fresh_force,
            self.failed,
            self.models_adopted,
            self.models_refused,
            self.restarts,
            self.not_newer,
            self.readings_dropped
        )
    }
}

/// What is worth a log line, once per change: contact made or lost, an approach that found no surface.
#[derive(Debug, Clone, Copy, Default)]
pub struct Notices {
    in_contact: bool,
    approach_exhausted: bool,
}

impl Notices {
    /// The log lines for what changed with `step` (none most ticks; nothing is allocated then).
    pub fn changes(&mut self, node: &ControllerNode, step: &Step) -> Vec<(LogLevel, String)> {
        let mut lines = Vec::new();
        if !matches!(step.reply, Reply::Torque(_)) {
            return lines;
        }
        let exhausted = node.law.approach_exhausted();
        if exhausted && !self.approach_exhausted {
            let why = format!("no surface within max_approach {} m: holding there", node.law.config().max_approach);
            lines.push((LogLevel::Error, why));
        }
        self.approach_exhausted = exhausted;
        if step.state.in_contact != self.in_contact {
            self.in_contact = step.state.in_contact;
            let what = if self.in_contact { "contact: holding, ready for force commands" } else { "contact lost" };
            lines.push((LogLevel::Info, what.to_string()));
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_sim::DEFAULT_Q;

    fn node() -> ControllerNode {
        ControllerNode::from_params(&Params::default()).unwrap()
    }

    fn sample(stamp: f64, session: u32) -> JointSample {
        JointSample { stamp, session: Some(session), commanding: true, q: DEFAULT_Q, dq: [0.0; 7] }
    }

    /// Every torque the node sends is finite and within the URDF's effort limits.
    fn assert_safe(node: &ControllerNode, step: &Step) {
        if let Reply::Torque(tau) = step.reply {
            let limits = &node.law.config().limits.joint_torque;
            for (i, t) in tau.iter().enumerate() {
                assert!(t.is_finite() && t.abs() <= limits[i], "joint {i}: {t} N·m (limit {})", limits[i]);
            }
        }
    }

    /// Free space for 0.2 s: the node ticks, answering every joint state with a torque.
    fn run_free(node: &mut ControllerNode, from: f64, session: u32) -> f64 {
        let mut t = from;
        for _ in 0..200 {
            t += 1e-3;
            node.on_force(t, Vector3::zeros(), t);
            let step = node.on_joint_state(&sample(t, session), t);
            assert!(matches!(step.reply, Reply::Torque(_)), "{:?}", step.reply);
            assert_safe(node, &step);
        }
        t
    }

    #[test]
    fn force_readings_that_are_no_numbers_are_dropped_and_send_nothing() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        for (i, bad) in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY].into_iter().enumerate() {
            // The last good reading is 0.2 s old by now: beyond stale_after, so nothing is fresh.
            let later = t + 0.2 + i as f64 * 1e-3;
            node.on_force(later, Vector3::new(0.0, 0.0, bad), later);
            let step = node.on_joint_state(&sample(later, 1), later);
            assert_eq!(step.reply, Reply::Nothing(Silence::NoFreshForce), "a force of {bad}");
        }
        assert_eq!(node.counters.readings_dropped, 3);
        // A force stamped with no number is dropped too, and does not end the readings' order.
        node.on_force(f64::NAN, Vector3::zeros(), t + 0.21);
        node.on_force(f64::INFINITY, Vector3::zeros(), t + 0.21);
        node.on_force(t + 0.21, Vector3::zeros(), t + 0.21);
        let step = node.on_joint_state(&sample(t + 0.21, 1), t + 0.21);
        assert!(matches!(step.reply, Reply::Torque(_)), "{:?}", step.reply);
    }

    #[test]
    fn an_absurd_force_backs_the_hand_off_within_the_torque_limits() {
        // 1e300 N is finite: it passes the force limit at once, and the law backs off (or holds).
        for absurd in [1e300, -1e300, 1e6] {
            let mut node = node();
            let mut t = run_free(&mut node, 10.0, 1);
            let n = node.geometry().normal();
            let mut backed_off = false;
            for _ in 0..500 {
                t += 1e-3;
                // The sensor reads the surface pushing back along the normal, in its own frame.
                let tool = node_pose_rotation(&mut node);
                let sensor = node.geometry().sensor_rotation(&tool);
                node.on_force(t, sensor.inverse() * (-n * absurd), t);
                let step = node.on_joint_state(&sample(t, 1), t);
                assert_safe(&node, &step);
                backed_off |= step.state.force_limited || matches!(step.reply, Reply::Hold(_));
            }
            if absurd > 0.0 {
                assert!(backed_off, "a force of {absurd} N along the normal: no back-off");
            }
        }
    }

    /// The tool's rotation at the start posture (the sample's q).
    fn node_pose_rotation(node: &mut ControllerNode) -> nalgebra::UnitQuaternion<f64> {
        let (model, data, tool) = &mut node.kinematics;
        model.forward_kinematics(data, &DEFAULT_Q);
        model.frame_pose(data, *tool).rotation
    }

    #[test]
    fn replayed_and_non_finite_stamps_are_not_ticked() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        let ticks = node.counters.ticks;
        // A replay of the last 0.1 s, stamps that are no numbers, the same stamp again.
        for stamp in [t - 0.1, t - 1e-3, t, f64::NAN, f64::NEG_INFINITY, f64::INFINITY] {
            node.on_force(t + 1e-4, Vector3::zeros(), t + 1e-4);
            let step = node.on_joint_state(&sample(stamp, 1), t + 1e-4);
            assert_eq!(step.reply, Reply::Nothing(Silence::NotNewer), "stamp {stamp}");
        }
        assert_eq!(node.counters.ticks, ticks);
        // The stream goes on where it was (infinity did not end the order).
        run_free(&mut node, t, 1);
    }

    #[test]
    fn a_stamp_from_the_far_future_silences_the_node_and_never_moves_the_arm() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        node.on_force(t + 1e-3, Vector3::zeros(), t + 1e-3);
        let step = node.on_joint_state(&sample(1e300, 1), t + 1e-3);
        assert_safe(&node, &step);
        // The driver's own joint states after it are not newer: no torque, the driver's watchdog holds.
        for i in 2..100 {
            let now = t + i as f64 * 1e-3;
            node.on_force(now, Vector3::zeros(), now);
            assert_eq!(node.on_joint_state(&sample(now, 1), now).reply, Reply::Nothing(Silence::NotNewer));
        }
    }

    /// A node on the simulated sponge, in contact and holding (the cell's own node).
    fn pressing_cell() -> crate::cell::Cell {
        use crate::contact_estimator::{ContactEstimatorNode, EstimatorConfig};
        let config = softcontact_sim::SimConfig::above_surface(softcontact_sim::sponge(), 7);
        let law =
            DeformationController::new(super::super::ControllerConfig::lwr4(250.0, 0.06), softcontact_sim::sponge())
                .unwrap();
        let mut cell =
            crate::cell::Cell::new(config, law, ContactEstimatorNode::new(EstimatorConfig::default()).unwrap())
                .unwrap();
        cell.start(5000).unwrap();
        while !cell.cycle().unwrap().unwrap().controller.in_contact {}
        for _ in 0..500 {
            cell.cycle().unwrap();
        }
        cell
    }

    #[test]
    fn a_press_ends_with_the_move_and_reports_the_force_reached() {
        let mut cell = pressing_cell();
        let (refused, taken) = cell.controller.on_force_command(60.0, 0.5);
        assert!(refused.is_none() && taken.is_ok());
        let mut press = Press::new(60.0, 0.5, cell.controller.law.time());
        let mut moving = 0;
        let (done_at, reached) = loop {
            let tick = cell.cycle().unwrap().unwrap();
            // The cell's step, as the node made it.
            let step = Step {
                reply: tick.torque.map_or(Reply::Nothing(Silence::NoFreshForce), Reply::Torque),
                state: tick.controller,
                force_world: tick.force_world,
                restarted: false,
            };
            match press.follow(&step, cell.controller.law.time()) {
                PressProgress::Moving { force, .. } => {
                    assert_eq!(force, tick.controller.f);
                    moving += 1;
                }
                PressProgress::Done { force } => break (cell.controller.law.time() - press.started, force),
                other => panic!("{other:?}"),
            }
        };
        assert!((done_at - 0.5).abs() < 1.5e-3, "done {done_at} s after the command");
        assert!((moving as f64 - 500.0).abs() <= 2.0, "{moving} ticks moving");
        // The true force of the simulated sponge at the end agrees with the sensor's (tared) reading.
        let truth = cell.sim.contact().normal_force;
        assert!((reached - truth).abs() < 0.05 * 60.0, "reached {reached} N, the surface pushes {truth} N");
    }

    #[test]
    fn a_press_is_aborted_by_a_restart_a_failed_tick_or_a_lost_contact() {
        let base = Step {
            reply: Reply::Torque([0.0; 7]),
            state: ControllerState::default(),
            force_world: Vector3::zeros(),
            restarted: false,
        };
        let fresh = || Press::new(10.0, 1.0, 0.0);
        let cases = [
            Step { restarted: true, ..base.clone() },
            Step { reply: Reply::Hold(ControlError::NonFinite("the measured force")), ..base.clone() },
            Step { reply: Reply::Nothing(Silence::NotCommanding), ..base.clone() },
            Step { state: ControllerState { contact_lost: true, ..Default::default() }, ..base.clone() },
            Step { state: ControllerState { force_limited: true, ..Default::default() }, ..base.clone() },
        ];
        for step in cases {
            assert!(matches!(fresh().follow(&step, 0.5), PressProgress::Aborted(_)), "{step:?}");
        }
        // No fresh force before the first tick: waiting, and the move's end is not reached without ticks.
        let mut press = fresh();
        let silent = Step { reply: Reply::Nothing(Silence::NoFreshForce), ..base.clone() };
        assert_eq!(press.follow(&silent, 0.0), PressProgress::Waiting);
        assert_eq!(press.follow(&silent, 2.0), PressProgress::Waiting);
        let with = |f| Step { state: ControllerState { f, ..Default::default() }, ..base.clone() };
        assert!(matches!(press.follow(&with(4.0), 0.9), PressProgress::Moving { force: 4.0, .. }));
        assert_eq!(press.follow(&with(6.0), 1.0), PressProgress::Done { force: 5.0 });
    }

    #[test]
    fn a_retreat_to_re_tare_lifts_the_hand_free_tares_and_finds_the_surface_again() {
        let mut cell = pressing_cell();
        cell.controller.on_force_command(50.0, 1.0).1.unwrap();
        for _ in 0..1500 {
            cell.cycle().unwrap();
        }
        let contact = cell.controller.law.contact_level().unwrap();
        cell.controller.request_retare().unwrap();
        // Commands wait, and a second request is refused.
        assert_eq!(cell.controller.on_force_command(30.0, 1.0).1, Err(ControlError::Retaring));
        assert_eq!(cell.controller.request_retare(), Err(ControlError::Retaring));
        let mut lifting = 0;
        while cell.controller.retare() != Some(Retare::Taring) {
            cell.cycle().unwrap();
            lifting += 1;
            assert!(lifting < 3000, "still lifting after 3 s");
        }
        // Free (the simulated surface pushes nothing) and still, 1.5 s after the request.
        assert!((lifting as f64 - 1500.0).abs() < 5.0, "{lifting} ticks lifting and settling");
        assert_eq!(cell.sim.contact().normal_force, 0.0, "the hand is off the surface");
        // Still enough for the F/T node's checked tare (which refuses a moving hand).
        assert!(cell.sim.dq().iter().all(|v| v.abs() < 5e-3), "the arm is still: {:?}", cell.sim.dq());
        cell.tare().unwrap();
        cell.controller.on_tared(true);
        assert_eq!(cell.controller.retare(), None);
        let mut approach = 0;
        while !cell.cycle().unwrap().unwrap().controller.in_contact {
            approach += 1;
            assert!(approach < 5000, "no contact again");
        }
        // The surface found again where it was (the onset's threshold deep, at most).
        let again = cell.controller.law.contact_level().unwrap();
        assert!((again - contact).abs() < 2e-3, "surface at {again} m, was at {contact} m");
        for _ in 0..200 {
            cell.cycle().unwrap();
        }
        assert!(cell.controller.on_force_command(30.0, 1.0).1.is_ok());
    }

    #[test]
    fn a_retreat_needs_contact_and_a_restart_ends_it() {
        let mut node = node();
        run_free(&mut node, 10.0, 1);
        assert_eq!(node.request_retare(), Err(ControlError::NoContact));
        let mut cell = pressing_cell();
        cell.controller.request_retare().unwrap();
        // A new session restarts the node: the retreat is over (its host answers "interrupted").
        let t = cell.sim.time();
        cell.controller.on_force(t + 1.0, Vector3::zeros(), t + 1.0);
        let step = cell.controller.on_joint_state(&sample(t + 1.0, 99), t + 1.0);
        assert!(step.restarted);
        assert_eq!(cell.controller.retare(), None);
    }

    #[test]
    fn interruptions_count_on_the_joint_states_clock_not_the_hosts() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        // The host starved for 1 s while the loop's (simulated) clock moved one cycle: no restart.
        let late = t + 1.0;
        node.on_force(t + 1e-3, Vector3::zeros(), late);
        let step = node.on_joint_state(&sample(t + 1e-3, 1), late);
        assert!(!step.restarted && matches!(step.reply, Reply::Torque(_)), "{step:?}");
        // The joint states themselves interrupted beyond restart_after: a restart.
        let gap = t + 1e-3 + Params::default().restart_after + 0.01;
        node.on_force(gap, Vector3::zeros(), late + 1e-3);
        assert!(node.on_joint_state(&sample(gap, 1), late + 1e-3).restarted);
    }

    #[test]
    fn a_new_session_restarts_the_controller_where_the_hand_is() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        node.on_force(t + 1e-3, Vector3::zeros(), t + 1e-3);
        let step = node.on_joint_state(&sample(t + 1e-3, 2), t + 1e-3);
        assert!(step.restarted && matches!(step.reply, Reply::Torque(_)));
        // Monitor mode: a restart, nothing is sent; commanding again starts afresh.
        let monitor = JointSample { commanding: false, ..sample(t + 2e-3, 2) };
        let step = node.on_joint_state(&monitor, t + 2e-3);
        assert!(step.restarted && step.reply == Reply::Nothing(Silence::NotCommanding), "{step:?}");
        node.on_force(t + 3e-3, Vector3::zeros(), t + 3e-3);
        let step = node.on_joint_state(&sample(t + 3e-3, 2), t + 3e-3);
        assert!(!step.restarted && matches!(step.reply, Reply::Torque(_)), "{step:?}");
        assert_eq!(node.counters.restarts, 2);
    }
}
