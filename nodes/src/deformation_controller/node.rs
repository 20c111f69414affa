//! The deformation controller's node policy, one copy for every host: its own process, the composed
//! 1 kHz process (`lwr_control`), and the in-process cell of the demo and the tests. The host hands in
//! what arrived (joint states, force readings, models, force commands) with its own monotonic clock's
//! reading `now` [s]; the node decides what is ticked, with which force, and what the driver is told.
//!
//! - Only a joint state newer than the newest one ticked is ticked (a replayed recording, or a backlog
//!   after a stall, never drives the arm); the controller runs on the joint states' stamps.
//! - A force reading counts while it is at most `stale_after` old by `now`; without one no command is
//!   sent (the driver's watchdog holds). A reading that is not finite, or not newer by its stamp, is
//!   dropped.
//! - A new KRC session, a KRC that does not command, or joint states interrupted longer than
//!   `restart_after` restart the controller: the contact is forgotten and the hand approaches again.
//! - A tick that fails asks the driver to hold at once, never for an older torque.
//! - Models: adopted at the next force command (seed 001), or on arrival with the standing command
//!   re-planned (`model_update: continuous`). An implausible one is refused and the present one kept.

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
    /// When the last joint state arrived (`now`), and its session.
    last_joint_state: Option<f64>,
    last_session: Option<u32>,
    ticks_in_session: u64,
    pending_model: Option<(ContactModel, Vector3<f64>)>,
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
            last_joint_state: None,
            last_session: None,
            ticks_in_session: 0,
            pending_model: None,
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
        if force_in_sensor.iter().all(|v| v.is_finite()) && stamp > self.newest_force_stamp {
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
        let refused = self.pending_model.take().and_then(|(m, surface)| {
            let adopted = self.law.adopt_estimate(m, &surface, None);
            self.count_adoption(adopted.is_ok());
            adopted.err()
        });
        (refused, self.law.command_force(force, duration))
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
        if !(js.stamp > self.newest_joint_state_stamp) {
            self.counters.not_newer += 1;
            return nothing(Silence::NotNewer, ControllerState::default());
        }
        self.newest_joint_state_stamp = js.stamp;
        let silence = self.last_joint_state.map_or(0.0, |t| now - t);
        self.last_joint_state = Some(now);
        let restarted = self.ticks_in_session > 0
            && (!(silence <= self.policy.restart_after) || js.session != self.last_session || !js.commanding);
        if restarted {
            self.counters.restarts += 1;
            self.ticks_in_session = 0;
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

impl std::fmt::Display for NodeCounters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} commands sent, {} joint states without a fresh force, {} failed, {} models adopted, {} refused, \
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
