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
//! - Models: adopted at the next force command (the force-control paper), or on arrival with the standing command
//!   re-planned (`model_update: continuous`). An implausible one is refused and the present one kept.
//! - The F/T sensor is checked against the arm's joint torque sensors ([`ForceCheck`]): when they
//!   disagree on the contact force, every tick holds until the KRC starts a new session.
//! - Retreat and re-tare (a drifting sensor's zero is only known with the hand free): the hand lifts
//!   [`RETARE_LIFT`] off the surface and settles, the host has the F/T node tare, and the controller
//!   restarts — it approaches again and finds the onset with the fresh zero. Commands are refused
//!   meanwhile.

use nalgebra::{Matrix3, Matrix6xX, Vector3};
use softcontact_contact::ContactModel;

use super::{
    ControlError, ControllerState, DeformationController, ModelUpdate, OVER_COMMAND, OVER_COMMAND_MIN, Params,
};
use crate::geometry::ContactGeometry;
use crate::runtime::ros::LogLevel;

/// A joint state as the driver measured it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSample {
    /// When it was measured, on the driver's clock \[s\].
    pub stamp: f64,
    /// The KRC session it belongs to, and whether the KRC commands (`None`: not said).
    pub session: Option<u32>,
    pub commanding: bool,
    pub q: [f64; 7],
    pub dq: [f64; 7],
}

/// The F/T sensor checked against the arm's own joint torque sensors. The KRC estimates the external
/// joint torques τ_ext (FRI estExtJntTrq: measured less its model's); the contact force at the tool point
/// they imply is f̂ = argmin ‖J_vᵀ f − τ_ext‖ = (J_v J_vᵀ)⁻¹ J_v τ_ext, with J_v the tool's linear
/// Jacobian in world axes (7 torques, 3 unknowns). The joint torques, not the KRC's own estExtTcpFT,
/// whose task frame and axis order depend on the KRL program's settings.
///
/// Sensor and arm agree within `tolerance + relative · min(|f|, |f̂|)`. The disagreement beyond that,
/// summed over the joint states' clock (and drained while they agree), trips the check at `impulse`
/// N·s — 10 ms at 50 N beyond, 100 ms at 5 N: a sensor that reads too much drives the law's force
/// feed-forward into a runaway that doubles the force every 20 ms, and that cannot wait for a fixed
/// persistence. The check catches a mis-scaled or frozen sensor, a wrong sensor
/// frame, a tare taken under load or a wrong tool load on the KRC — the controller no longer knows the
/// force it applies, and pressing on would be blind. Tripped, the node holds the arm until the KRC
/// starts a new session (the operator restarts the FRI program).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceCheck {
    /// [N]
    pub tolerance: f64,
    pub relative: f64,
    /// [N·s]
    pub impulse: f64,
    /// The disagreement beyond the allowance, summed over time (and drained while they agree), and the
    /// joint-state stamp it was last updated at.
    excess: f64,
    last: Option<f64>,
    /// The forces (sensor, arm) that tripped the check.
    tripped: Option<([f64; 3], [f64; 3])>,
}

impl ForceCheck {
    pub fn new(tolerance: f64, relative: f64, impulse: f64) -> Self {
        Self { tolerance, relative, impulse, excess: 0.0, last: None, tripped: None }
    }

    /// The arm's view of the contact force (world axes) from the tool's Jacobian (6 × 7, world axes,
    /// linear rows first) and the external joint torques; `None` near a singularity, where the torques
    /// do not determine a force (nor any non-finite input).
    pub fn arm_force(jacobian: &Matrix6xX<f64>, external: &[f64; 7]) -> Option<Vector3<f64>> {
        // J_v J_vᵀ and J_v τ column by column (fixed sizes: nothing is allocated on the FRI thread).
        let (mut normal, mut projected) = (Matrix3::zeros(), Vector3::zeros());
        for (j, tau) in external.iter().enumerate() {
            let column = jacobian.fixed_view::<3, 1>(0, j);
            normal += column * column.transpose();
            projected += column * *tau;
        }
        // The arm's least singular direction: below 1 mm of tool motion per 0.1 rad of joints the
        // torques say little of a force along it.
        let f = normal.cholesky().filter(|_| normal.symmetric_eigenvalues().min() > 1e-4)?.solve(&projected);
        f.iter().all(|v| v.is_finite()).then_some(f)
    }

    /// The sensor's and the arm's contact force at `time` [s]: `Err` once the check has tripped.
    pub fn compare(&mut self, time: f64, sensor: &Vector3<f64>, arm: &Vector3<f64>) -> Result<(), ControlError> {
        if self.tripped.is_none() {
            let dt = self.last.map_or(0.0, |last| (time - last).clamp(0.0, 0.1));
            self.last = Some(time);
            // The smaller force scales the allowance: a sensor that reads too much must not widen its own.
            let allowed = self.tolerance + self.relative * sensor.norm().min(arm.norm());
            let beyond = (sensor - arm).norm() - allowed;
            // (A non-finite force trips at once.)
            self.excess = if beyond.is_finite() { (self.excess + beyond * dt).max(0.0) } else { f64::INFINITY };
            if !(self.excess <= self.impulse) {
                self.tripped = Some(((*sensor).into(), (*arm).into()));
            }
        }
        self.error().map_or(Ok(()), Err)
    }

    /// Why the check holds the arm (`None`: it does not).
    pub fn error(&self) -> Option<ControlError> {
        self.tripped.map(|(sensor, arm)| ControlError::ForceDisagreement { sensor, arm })
    }

    /// A new KRC session: the operator has seen the hold.
    pub fn reset(&mut self) {
        *self = Self::new(self.tolerance, self.relative, self.impulse);
    }
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
    /// No external torque estimate of the KRC within `stale_after` of the joint state: the force
    /// cannot be checked.
    NoArmForce,
}

/// One joint state handled.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub reply: Reply,
    /// The controller's report (the normal force alone when it did not tick).
    pub state: ControllerState,
    /// The contact force on the hand in the world \[N\] (zero without a fresh reading).
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
    /// Joint states without the KRC's external torque estimate.
    pub no_arm_force: u64,
    /// Times the force check tripped.
    pub force_check_trips: u64,
}

/// The policy's own settings (the rest of [`Params`] configures the law).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Policy {
    stale_after: f64,
    restart_after: f64,
    model_update: ModelUpdate,
    retarget_duration: f64,
}

/// How far the hand lifts off the surface to re-tare \[m\], over how long \[s\], and how long it then
/// settles before the tare \[s\] (the surface's fast relaxation and the arm's motion die out).
pub const RETARE_LIFT: f64 = 0.01;
const RETARE_LIFT_TIME: f64 = 1.0;
const RETARE_SETTLE: f64 = 0.5;

/// Where a retreat to re-tare is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Retare {
    /// Lifting and settling until the controller's time `until` \[s\].
    Lifting { until: f64 },
    /// Free and still: the F/T node is to tare now.
    Taring,
}

pub struct ControllerNode {
    /// The control law.
    pub law: DeformationController,
    policy: Policy,
    /// The newest force reading in the sensor frame and when it arrived (`now`).
    force: Option<(Vector3<f64>, f64)>,
    newest_force_stamp: f64,
    newest_joint_state_stamp: f64,
    /// The KRC's newest external torque estimate and its stamp.
    external_torque: Option<(f64, [f64; 7])>,
    force_check: ForceCheck,
    jacobian: Matrix6xX<f64>,
    /// The session of the newest joint state.
    last_session: Option<u32>,
    /// Whether the newest joint state said the driver applies torques (the KRC commanding in joint
    /// impedance).
    torque_mode: bool,
    ticks_in_session: u64,
    pending_model: Option<(ContactModel, Vector3<f64>)>,
    retare: Option<Retare>,
    pub counters: NodeCounters,
    /// The driver's latched fault, as it said it.
    driver_fault: Option<String>,
}

impl ControllerNode {
    /// The node with its parameters (checked by `Params::validate` when loaded) around `law`.
    pub fn new(params: &Params, law: DeformationController) -> Result<Self, ControlError> {
        let jacobian = Matrix6xX::zeros(7);
        Ok(Self {
            law,
            policy: Policy {
                stale_after: params.stale_after,
                restart_after: params.restart_after,
                model_update: params.model_update,
                retarget_duration: params.retarget_duration,
            },
            force: None,
            newest_force_stamp: f64::NEG_INFINITY,
            newest_joint_state_stamp: f64::NEG_INFINITY,
            external_torque: None,
            force_check: ForceCheck::new(
                params.force_check_tolerance,
                params.force_check_relative,
                params.force_check_impulse,
            ),
            jacobian,
            last_session: None,
            torque_mode: false,
            ticks_in_session: 0,
            pending_model: None,
            retare: None,
            counters: NodeCounters::default(),
            driver_fault: None,
        })
    }

    /// The node as the parameters describe it, with their initial model.
    pub fn from_params(params: &Params) -> Result<Self, ControlError> {
        let law = DeformationController::new(params.controller_config(), params.initial_model.clone())?;
        let mut node = Self::new(params, law)?;
        // A known surface places the initial model as an estimate would, at the first command in contact.
        node.pending_model = params.initial_surface.map(|p| (params.initial_model.clone(), Vector3::from(p)));
        Ok(node)
    }

    /// The contact's geometry: the law's.
    pub fn geometry(&self) -> &ContactGeometry {
        self.law.geometry()
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

    /// The KRC's external joint torque estimate (FRI estExtJntTrq) of the joint state stamped `stamp`
    /// (/lwr/external_torque). Not finite, or not newer: dropped.
    pub fn on_external_torque(&mut self, stamp: f64, torque: &[f64; 7]) {
        let newer = self.external_torque.is_none_or(|(newest, _)| stamp > newest);
        if stamp.is_finite() && newer && torque.iter().all(|v| v.is_finite()) {
            self.external_torque = Some((stamp, *torque));
        }
    }

    /// Why the force check holds the arm (`None`: it does not).
    pub fn force_check(&self) -> Option<ControlError> {
        self.force_check.error()
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

    /// A force command \[N\] reached over `duration` \[s\]. The newest model waiting is adopted with it,
    /// once in contact (the force-control paper: once per command cycle); if the model is refused the command goes on
    /// with the present model, and the refusal is returned beside the command's own result. A command
    /// refused changes nothing: the model keeps waiting for the next.
    pub fn on_force_command(&mut self, force: f64, duration: f64) -> (Option<ControlError>, Result<(), ControlError>) {
        if let Some(fault) = &self.driver_fault {
            return (None, Err(ControlError::DriverFault(fault.clone())));
        }
        if self.retare.is_some() {
            return (None, Err(ControlError::Retaring));
        }
        if !self.torque_mode {
            return (None, Err(ControlError::NoTorqueMode));
        }
        // Out of contact a model waits: its surface is placed relative to the onset, not yet found.
        let waiting = if self.law.contact_level().is_some() { self.pending_model.take() } else { None };
        let Some((model, surface)) = waiting else { return (None, self.law.command_force(force, duration)) };
        let before = self.law.clone();
        if let Err(refused) = self.law.adopt_estimate(model.clone(), &surface, None) {
            self.count_adoption(false);
            return (Some(refused), self.law.command_force(force, duration));
        }
        match self.law.command_force(force, duration) {
            Ok(()) => {
                self.count_adoption(true);
                (None, Ok(()))
            }
            Err(e) => {
                // A refused command changes nothing: the law as it was, the model still waiting.
                self.law = before;
                self.pending_model = Some((model, surface));
                (None, Err(e))
            }
        }
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

    /// The driver latched a fault (its reason), or it was cleared (`None`): while it stands force
    /// commands and goals fail with it.
    pub fn on_driver_fault(&mut self, fault: Option<String>) {
        self.driver_fault = fault;
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
        if js.session != self.last_session {
            self.force_check.reset();
        }
        if restarted {
            self.counters.restarts += 1;
            self.ticks_in_session = 0;
            // The contact is forgotten: a retreat under way has nothing left to do.
            self.retare = None;
        }
        self.last_session = js.session;
        self.torque_mode = js.commanding;
        if !self.law.follow_session(js.session, js.commanding, silence) {
            return Step { restarted, ..nothing(Silence::NotCommanding, ControllerState::default()) };
        }
        let fresh = self.force.filter(|(_, arrived)| now - arrived <= self.policy.stale_after);
        let Some((force_in_sensor, _)) = fresh else {
            self.counters.no_fresh_force += 1;
            return Step { restarted, ..nothing(Silence::NoFreshForce, ControllerState::default()) };
        };
        // The contact force on the hand in the world, through the arm's own kinematics (the law's: the
        // one pass of the cycle).
        let force_world = if js.q.iter().all(|v| v.is_finite()) {
            let tool = self.law.tool_pose(&js.q).rotation;
            self.law.geometry().world_force(&tool, &force_in_sensor)
        } else {
            Vector3::repeat(f64::NAN)
        };
        let f = self.law.geometry().normal_force(&force_world);
        // The sensor against the arm's joint torques, on every tick that has both.
        let arm_torque = self.external_torque.filter(|(at, _)| (js.stamp - at).abs() <= self.policy.stale_after);
        let Some((_, arm_torque)) = arm_torque else {
            self.counters.no_arm_force += 1;
            return Step { restarted, ..nothing(Silence::NoArmForce, ControllerState { f, ..Default::default() }) };
        };
        self.law.observe_arm_force(None);
        let checked = if force_world.iter().all(|v| v.is_finite()) {
            self.law.tool_jacobian(&js.q, &mut self.jacobian);
            // Near a singularity the torques say nothing of the force: no comparison, no disagreement.
            let arm = ForceCheck::arm_force(&self.jacobian, &arm_torque);
            self.law.observe_arm_force(arm.map(|a| self.law.geometry().normal_force(&a)));
            match arm {
                Some(arm) => {
                    let tripped_before = self.force_check.error().is_some();
                    let checked = self.force_check.compare(js.stamp, &force_world, &arm);
                    if checked.is_err() && !tripped_before {
                        self.counters.force_check_trips += 1;
                    }
                    checked
                }
                None => self.force_check.error().map_or(Ok(()), Err),
            }
        } else {
            Ok(())
        };
        if let Err(e) = checked {
            self.counters.failed += 1;
            return Step {
                reply: Reply::Hold(e),
                state: ControllerState { f, ..Default::default() },
                force_world,
                restarted,
            };
        }
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
/// measured normal force of the move's last 10 ticks (the force-control paper reads the force at the end of the move).
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
    /// The move goes on: the measured normal force \[N\] and deformation \[m\].
    Moving { force: f64, deformation: f64 },
    /// The move ended: the force reached \[N\] (its error is `force − Press::force`).
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
                if step.state.over_command {
                    return PressProgress::Aborted(format!(
                        "the measured force passed the command's bound ({} % over it, {} N at least): the contact \
                         model in use asks for more deformation than this surface takes; the controller backed off",
                        OVER_COMMAND * 100.0,
                        OVER_COMMAND_MIN
                    ));
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
             {} restarts, {} joint states not newer than the last, {} force readings dropped, {} joint states \
             without the arm's torque estimate, {} force check trips",
            self.ticks,
            self.no_fresh_force,
            self.failed,
            self.models_adopted,
            self.models_refused,
            self.restarts,
            self.not_newer,
            self.readings_dropped,
            self.no_arm_force,
            self.force_check_trips
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
    use softcontact_dynamics::{Axes, lwr4};
    use softcontact_sim::DEFAULT_Q;

    /// A force reading of the sensor at `stamp`, and the external torques the KRC estimates for that
    /// contact force at the start posture (J_vᵀ f): sensor and arm agree.
    fn feed(node: &mut ControllerNode, stamp: f64, force_in_sensor: Vector3<f64>, now: f64) {
        node.on_force(stamp, force_in_sensor, now);
        let tau = arm_torque(node, &force_in_sensor);
        node.on_external_torque(stamp, &tau);
    }

    fn arm_torque(node: &mut ControllerNode, force_in_sensor: &Vector3<f64>) -> [f64; 7] {
        let tool = node_pose_rotation(node);
        let world = node.geometry().world_force(&tool, force_in_sensor);
        let mut jacobian = Matrix6xX::zeros(7);
        node.law.tool_jacobian(&DEFAULT_Q, &mut jacobian);
        let tau = jacobian.fixed_rows::<3>(0).transpose() * world;
        std::array::from_fn(|i| if tau[i].is_finite() { tau[i] } else { 0.0 })
    }

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
            feed(node, t, Vector3::zeros(), t);
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
            feed(&mut node, later, Vector3::new(0.0, 0.0, bad), later);
            let step = node.on_joint_state(&sample(later, 1), later);
            assert_eq!(step.reply, Reply::Nothing(Silence::NoFreshForce), "a force of {bad}");
        }
        assert_eq!(node.counters.readings_dropped, 3);
        // A force stamped with no number is dropped too, and does not end the readings' order.
        feed(&mut node, f64::NAN, Vector3::zeros(), t + 0.21);
        feed(&mut node, f64::INFINITY, Vector3::zeros(), t + 0.21);
        feed(&mut node, t + 0.21, Vector3::zeros(), t + 0.21);
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
                feed(&mut node, t, sensor.inverse() * (-n * absurd), t);
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
        node.law.tool_pose(&DEFAULT_Q).rotation
    }

    #[test]
    fn replayed_and_non_finite_stamps_are_not_ticked() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        let ticks = node.counters.ticks;
        // A replay of the last 0.1 s, stamps that are no numbers, the same stamp again.
        for stamp in [t - 0.1, t - 1e-3, t, f64::NAN, f64::NEG_INFINITY, f64::INFINITY] {
            feed(&mut node, t + 1e-4, Vector3::zeros(), t + 1e-4);
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
        feed(&mut node, t + 1e-3, Vector3::zeros(), t + 1e-3);
        let step = node.on_joint_state(&sample(1e300, 1), t + 1e-3);
        assert_safe(&node, &step);
        // The driver's own joint states after it are not newer: no torque, the driver's watchdog holds.
        for i in 2..100 {
            let now = t + i as f64 * 1e-3;
            feed(&mut node, now, Vector3::zeros(), now);
            assert_eq!(node.on_joint_state(&sample(now, 1), now).reply, Reply::Nothing(Silence::NotNewer));
        }
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
    fn interruptions_count_on_the_joint_states_clock_not_the_hosts() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        // The host starved for 1 s while the loop's (simulated) clock moved one cycle: no restart.
        let late = t + 1.0;
        feed(&mut node, t + 1e-3, Vector3::zeros(), late);
        let step = node.on_joint_state(&sample(t + 1e-3, 1), late);
        assert!(!step.restarted && matches!(step.reply, Reply::Torque(_)), "{step:?}");
        // The joint states themselves interrupted beyond restart_after: a restart.
        let gap = t + 1e-3 + Params::default().restart_after + 0.01;
        feed(&mut node, gap, Vector3::zeros(), late + 1e-3);
        assert!(node.on_joint_state(&sample(gap, 1), late + 1e-3).restarted);
    }

    #[test]
    fn the_arm_force_is_the_force_whose_joint_torques_the_krc_reports() {
        let model = lwr4::model();
        let mut data = model.data();
        let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
        let mut jacobian = Matrix6xX::zeros(7);
        let force = Vector3::new(12.0, -30.0, 150.0);
        for q in [DEFAULT_Q, [0.3, 0.8, -0.4, -1.2, 0.5, 0.9, -0.7]] {
            model.forward_kinematics(&mut data, &q);
            model.frame_jacobian(&data, tool, Axes::World, &mut jacobian);
            let tau = jacobian.fixed_rows::<3>(0).transpose() * force;
            let arm = ForceCheck::arm_force(&jacobian, &std::array::from_fn(|i| tau[i])).unwrap();
            assert!((arm - force).norm() < 1e-6, "{arm} for {force}");
        }
        // Stretched out straight up no joint moves the tool along the arm: no force is determined.
        model.forward_kinematics(&mut data, &[0.0; 7]);
        model.frame_jacobian(&data, tool, Axes::World, &mut jacobian);
        assert_eq!(ForceCheck::arm_force(&jacobian, &[1.0; 7]), None);
        assert_eq!(ForceCheck::arm_force(&jacobian, &[f64::NAN; 7]), None);
    }

    /// The sensor reads `sensor` [N] along the normal (pushing the hand back) while the KRC's joint
    /// torques say `arm` [N], for `ticks` joint states from `t`.
    fn disagree(node: &mut ControllerNode, t: f64, sensor: f64, arm: f64, ticks: usize) -> Vec<Step> {
        let n = node.geometry().normal();
        let tool = node_pose_rotation(node);
        let to_sensor = node.geometry().sensor_rotation(&tool).inverse();
        (1..=ticks)
            .map(|i| {
                let now = t + i as f64 * 1e-3;
                node.on_force(now, to_sensor * (-n * sensor), now);
                let tau = arm_torque(node, &(to_sensor * (-n * arm)));
                node.on_external_torque(now, &tau);
                node.on_joint_state(&sample(now, 1), now)
            })
            .collect()
    }

    #[test]
    fn sensor_and_arm_that_disagree_on_the_force_hold_the_arm_until_a_new_session() {
        let impulse = Params::default().force_check_impulse;
        // (sensor, arm, beyond the allowance of 20 N + 25 % of the smaller) [N]: a sensor that reads
        // nothing, one that reads double (half the counts per unit), and a frozen one; each held once the
        // disagreement beyond the allowance sums to `impulse`.
        for (sensor, arm, beyond) in [(0.0, 35.0, 15.0), (200.0, 100.0, 55.0), (60.0, 0.0, 40.0)] {
            let mut node = node();
            let t = run_free(&mut node, 10.0, 1);
            let steps = disagree(&mut node, t, sensor, arm, 300);
            let first_hold = steps.iter().position(|s| matches!(s.reply, Reply::Hold(_))).expect("held") as f64;
            // (The first comparison has no time step.)
            assert!((first_hold * 1e-3 - impulse / beyond).abs() <= 1.5e-3, "held after {first_hold} ms");
            assert!(
                steps[first_hold as usize..]
                    .iter()
                    .all(|s| matches!(s.reply, Reply::Hold(ControlError::ForceDisagreement { .. })))
            );
            // Agreeing again does not end the hold: the operator restarts the KRC's session.
            let t = t + 0.3;
            let again = disagree(&mut node, t, 10.0, 10.0, 50);
            assert!(again.iter().all(|s| matches!(s.reply, Reply::Hold(_))));
            assert_eq!(node.counters.force_check_trips, 1);
            assert!(node.force_check().is_some());
            let now = t + 0.06;
            feed(&mut node, now, Vector3::zeros(), now);
            let step = node.on_joint_state(&sample(now, 2), now);
            assert!(matches!(step.reply, Reply::Torque(_)), "a new session: {step:?}");
            assert!(node.force_check().is_none());
        }
        // Within the allowance, and brief disagreements drained by agreement between them, never hold.
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        let agreeing = disagree(&mut node, t, 100.0, 140.0, 300);
        agreeing.iter().for_each(|s| assert_safe(&node, s));
        let mut t = t + 0.3;
        for _ in 0..5 {
            // 10 N beyond for 40 ms (0.4 N·s), then 30 ms agreeing (20 N within: 0.6 N·s drained).
            disagree(&mut node, t, 0.0, 30.0, 40).iter().for_each(|s| assert_safe(&node, s));
            t += 0.04;
            disagree(&mut node, t, 0.0, 0.0, 30);
            t += 0.03;
        }
        assert_eq!(node.counters.force_check_trips, 0);
        assert!(node.force_check().is_none());
    }

    #[test]
    fn without_the_krcs_torque_estimate_no_torque_is_sent() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        // The estimate stops (its topic died): once it is stale_after old, nothing is sent.
        let stale = Params::default().stale_after;
        let mut silent = 0;
        for i in 1..200 {
            let now = t + i as f64 * 1e-3;
            node.on_force(now, Vector3::zeros(), now);
            let step = node.on_joint_state(&sample(now, 1), now);
            silent += usize::from(step.reply == Reply::Nothing(Silence::NoArmForce));
        }
        assert!((silent as f64 - (0.199 - stale) * 1e3).abs() <= 2.0, "{silent} joint states silent");
        // A stranger's estimate stamped far in the future is no estimate of these joint states.
        node.on_external_torque(1e300, &[0.0; 7]);
        let now = t + 0.2;
        node.on_force(now, Vector3::zeros(), now);
        assert_eq!(node.on_joint_state(&sample(now, 1), now).reply, Reply::Nothing(Silence::NoArmForce));
    }

    #[test]
    fn a_new_session_restarts_the_controller_where_the_hand_is() {
        let mut node = node();
        let t = run_free(&mut node, 10.0, 1);
        feed(&mut node, t + 1e-3, Vector3::zeros(), t + 1e-3);
        let step = node.on_joint_state(&sample(t + 1e-3, 2), t + 1e-3);
        assert!(step.restarted && matches!(step.reply, Reply::Torque(_)));
        // Monitor mode: a restart, nothing is sent; commanding again starts afresh.
        let monitor = JointSample { commanding: false, ..sample(t + 2e-3, 2) };
        let step = node.on_joint_state(&monitor, t + 2e-3);
        assert!(step.restarted && step.reply == Reply::Nothing(Silence::NotCommanding), "{step:?}");
        feed(&mut node, t + 3e-3, Vector3::zeros(), t + 3e-3);
        let step = node.on_joint_state(&sample(t + 3e-3, 2), t + 3e-3);
        assert!(!step.restarted && matches!(step.reply, Reply::Torque(_)), "{step:?}");
        assert_eq!(node.counters.restarts, 2);
    }

    #[test]
    fn a_force_command_while_the_krc_is_not_in_torque_mode_is_refused_saying_so() {
        let mut node = node();
        let t = run_free(&mut node, 1.0, 1);
        let position_control = JointSample { commanding: false, ..sample(t + 1e-3, 1) };
        node.on_joint_state(&position_control, t + 1e-3);
        assert_eq!(node.on_force_command(20.0, 1.0).1, Err(ControlError::NoTorqueMode));
        feed(&mut node, t + 2e-3, Vector3::zeros(), t + 2e-3);
        node.on_joint_state(&sample(t + 2e-3, 1), t + 2e-3);
        assert_eq!(node.on_force_command(20.0, 1.0).1, Err(ControlError::NoContact));
    }
}
