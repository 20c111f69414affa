//! The contact task of the force-control paper (contact normal-force control of a KUKA LWR IV on compliant
//! surfaces with identified contact models): one `tick` per joint-state measurement turns the measured
//! force and joint state into joint torques. Pure: no ROS, no clock, no allocation in a tick.
//!
//! Before contact the hand descends along the contact direction n at a slow, constant speed; the onset
//! detector fixes the contact position d. In contact a force command becomes a deformation command
//! through the inverse of the current contact model, a quintic joins the present deformation to it, the
//! deformation law turns the reference into z̈_des along n, the hand's position across the surface and its
//! orientation are held by PD laws (at the start pose, or where [`DeformationController::command_across`]
//! moved their reference), and eq. 15 turns the task acceleration into joint torques with a
//! null-space joint impedance holding the initial posture. Every output passes the torque limiter.
//!
//! | the paper | what | where |
//! |---|---|---|
//! | eq. 8 | normal force f = −F·n (the force on the hand, in the world) | [`ContactGeometry::normal_force`] |
//! | eq. 9 | deformation z = (r − d)·n from the contact position d | [`ContactGeometry::deformation`] |
//! | eq. 10 | deformation rate ż = ṙ·n | [`ContactGeometry::rate`] |
//! | eq. 11 | z̈_des = z̈_cmd + k_z (z_cmd − z) + k_ż (ż_cmd − ż) | [`crate::law::deformation_acceleration`] |
//! | eq. 12 | r̈_des = z̈_des n, plus the PD laws across the surface and in orientation | `tick.rs` (`task_acceleration`) |
//! | eq. 15 | τ = (J M⁻¹)^# (p̈_des − J̇q̇ + J M⁻¹ h − J M⁻¹ Jᵀ f) + N τ₀ | [`crate::task::TaskTorque`], `tick.rs` (`torques`) |
//! | eq. 19 | force command → deformation command through the inverted model | [`DeformationController::command_force`], [`crate::augmented`] |
//!
//! A contact model with named effects (one the discrepancy workflow augmented) is inverted with its
//! effects' states ([`AugmentedInverse`]): a force command's move ends where the model gives the force
//! with its relaxation branches as the move leaves them, and the hold is re-solved every tick as they
//! fade (at most `max_deformation_rate` from the last, within `max_deformation`); the sensor's named bias
//! and drift come out of the reading (at most [`MAX_SENSOR_CORRECTION`] of `max_force`), and the force
//! guard watches the larger of the reading and the corrected force (`guard.rs`).
//!
//! What it refuses (the safety contract, docs/safety.md): a command whose force, deformation, lift or
//! move duration lies outside the configured limits; a move across the surface or a tilt beyond
//! [`MAX_LATERAL`], [`MAX_TILT`] or their speed limits (`across.rs`); a contact model that is not
//! plausible (exponents outside [`EXPONENT_RANGE`], a sensor bias beyond [`MAX_SENSOR_CORRECTION`] or a
//! surface drift beyond the contact crate's `MAX_SURFACE_DRIFT`, a surface placed further than
//! `max_surface_offset` from the measured onset); a tick whose measurements are not finite numbers. A
//! tick that cannot produce finite torques returns an error and re-plans a hold where the hand is: the
//! node then sends the driver a hold request, never an older torque. After the joint states were
//! interrupted (a new KRC session) the controller forgets the contact and approaches again.

use nalgebra::{DVector, Isometry3, Matrix6xX, UnitQuaternion, Vector3};
use softcontact_contact::{ContactModel, OnsetConfig, OnsetDetector};
use softcontact_dynamics::{ArmEffects, Axes, Data, FrameId, FrameMotion, Model, lwr4};

use crate::{
    AugmentedInverse, DeformationGains, LimitError, Limits, Oscillation, Quintic, Reference, Segment, TaskTorque,
    TorqueLimiter, Trajectory,
};

mod across;
mod geometry;
mod guard;
#[cfg(test)]
mod tests;
mod tick;

use across::AcrossMove;
pub use across::{AcrossReference, MAX_LATERAL, MAX_TILT, MAX_TILT_RATE};
pub use geometry::{ContactGeometry, lwr4_tool_to_sensor};
pub use guard::{
    ARM_FORCE_SMOOTHING, HOLD_FORCE_MARGIN, HOLD_LEAD, MAX_SENSOR_CORRECTION, MIN_MODEL_FORCE, MODEL_FORCE_EXCESS,
    MODEL_FORCE_EXCESS_MIN, OVER_COMMAND, OVER_COMMAND_MIN,
};
use guard::{CommandBound, ForceHold, MAX_PUSH_PERIODS, Trip, plausible_for};
pub use tick::{FRICTION_COMPENSATED, FRICTION_COMPENSATED_JOINTS, FRICTION_COMPENSATION_SCALE};

#[derive(Debug, Clone, PartialEq)]
pub struct ControllerConfig {
    /// Contact direction n in the world: the way the hand moves to compress the surface.
    pub normal: Vector3<f64>,
    pub gains: DeformationGains,
    /// PD of the hand's position across the surface [1/s², 1/s].
    pub lateral: (f64, f64),
    /// PD of the hand's orientation [1/s², 1/s].
    pub orientation: (f64, f64),
    /// Null-space joint impedance holding the initial posture [N·m/rad, N·m·s/rad].
    pub posture_stiffness: [f64; 7],
    pub posture_damping: [f64; 7],
    /// Descent speed before contact [m/s].
    pub approach_speed: f64,
    /// Farthest the approach goes from where it started \[m\]: with no surface within it (none there,
    /// or a wrong `normal`) the hand stops and holds, instead of travelling to a joint limit.
    pub max_approach: f64,
    pub onset: OnsetConfig,
    pub limits: Limits,
    /// Farthest an estimated surface may lie from the measured onset position \[m\]: a model placing
    /// it further is refused (a surface 5 cm too low turned a 50 N command into 302 N).
    pub max_surface_offset: f64,
    /// Joint states interrupted this long \[s\] mean a new KRC session or a moved arm: approach again.
    pub restart_after: f64,
    /// Nominal control period \[s\]: the step of the first tick after a (re)start; later ticks step by the
    /// time between their joint states.
    pub period: f64,
    /// The arm's own effects beyond the URDF to compensate (`softcontact discrepancy --arm` names them):
    /// the payload is carried in the model whose gravity and inertia eq. 15 compensates, the joint
    /// friction is added to the torque before the limiter.
    pub arm: ArmEffects,
}

/// Exponents a, b, c of a plausible contact law ([`softcontact_contact::PLAUSIBLE_EXPONENTS`]).
pub const EXPONENT_RANGE: std::ops::RangeInclusive<f64> = softcontact_contact::PLAUSIBLE_EXPONENTS;

impl ControllerConfig {
    /// The force-control paper's set-up on the LWR IV: surface below, 1 kHz.
    pub fn lwr4(max_force: f64, max_deformation: f64) -> Self {
        let model = lwr4::model();
        Self {
            normal: Vector3::new(0.0, 0.0, -1.0),
            gains: DeformationGains::critically_damped(20.0),
            lateral: (400.0, 40.0),
            orientation: (400.0, 40.0),
            posture_stiffness: [20.0, 20.0, 10.0, 10.0, 2.0, 1.0, 0.5],
            posture_damping: [2.0, 2.0, 1.0, 1.0, 0.2, 0.05, 0.02],
            approach_speed: 0.01,
            max_approach: 0.1,
            onset: OnsetConfig::default(),
            limits: Limits {
                joint_torque: model.joints.iter().map(|j| j.limits.effort).collect(),
                torque_rate: 2000.0,
                max_force,
                max_deformation,
                max_lift: 0.05,
                move_duration: (0.1, 600.0),
                max_deformation_rate: 0.25,
                contact_lost_below: 0.5,
                force_limit: 1.2 * max_force,
            },
            max_surface_offset: 0.01,
            restart_after: 0.1,
            period: 1e-3,
            arm: ArmEffects::default(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    #[error(transparent)]
    Limit(#[from] LimitError),
    #[error(transparent)]
    Contact(#[from] softcontact_contact::ContactError),
    #[error(transparent)]
    Dynamics(#[from] softcontact_dynamics::Error),
    #[error("no contact yet: force commands wait for the onset")]
    NoContact,
    #[error(
        "the driver applies no torque: the KRC is not commanding in joint impedance (the driver's \
         /diagnostics names the mode it sees and what it waits for)"
    )]
    NoTorqueMode,
    #[error("retreating to re-tare the sensor: commands are refused until the hand is back on the surface")]
    Retaring,
    #[error("the LWR driver holds for a fault: {0}")]
    DriverFault(String),
    #[error("move duration must be positive")]
    Duration,
    #[error("the contact normal must not be zero")]
    ZeroNormal,
    #[error("{0} is not a finite number: no torque this tick")]
    NonFinite(&'static str),
    #[error("joint state at {time} s is not newer than the last one ticked ({last} s): no torque this tick")]
    TimeNotAdvancing { time: f64, last: f64 },
    #[error("implausible contact model refused: {0}")]
    ImplausibleModel(String),
    /// The F/T sensor and the arm's joint torque sensors disagree on the contact force.
    #[error(
        "the F/T sensor reads {sensor:.1?} N on the hand, the arm's joint torques say {arm:.1?} N: holding \
         until the KRC starts a new session (check the sensor's counts per unit and frame, its tare, and the \
         tool load $LOAD of the KRC)"
    )]
    ForceDisagreement { sensor: [f64; 3], arm: [f64; 3] },
    /// A move across the surface or a tilt beyond its limit (see [`MAX_LATERAL`], [`MAX_TILT`]).
    #[error("{what} of {value} is beyond the limit of {limit}")]
    Across { what: &'static str, value: f64, limit: f64 },
}

/// What the controller reports each tick (/deformation_controller/state).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControllerState {
    pub in_contact: bool,
    pub contact_lost: bool,
    /// The measured force passed `force_limit`, or the standing force command's bound
    /// ([`OVER_COMMAND`]): the controller backed off and waits for a command.
    pub force_limited: bool,
    /// The back-off was for the command's bound: the contact model in use asks for more deformation than
    /// this surface takes at the commanded force.
    pub over_command: bool,
    pub f_cmd: f64,
    pub z_cmd: f64,
    pub zdot_cmd: f64,
    pub z: f64,
    pub zdot: f64,
    pub f: f64,
    /// The model's force at the commanded deformation and rate.
    pub f_predicted: f64,
}

#[derive(Clone)]
pub struct DeformationController {
    config: ControllerConfig,
    /// The contact direction of `config` and the LWR IV's sensor mounting (eqs. 8–10).
    geometry: ContactGeometry,
    model: Model,
    data: Data,
    tool: FrameId,
    contact_model: ContactModel,
    onset: OnsetDetector,
    /// d·n and the estimated offset of the true surface from it.
    contact_level: Option<f64>,
    offset: f64,
    start: Option<(Vector3<f64>, UnitQuaternion<f64>, [f64; 7])>,
    /// The hand's pose at this controller's very first tick, kept through restarts: moves across the
    /// surface are bounded from it too, so that restarts cannot walk the hand away step by step.
    origin: Option<(Vector3<f64>, UnitQuaternion<f64>)>,
    /// The hold across the surface and in orientation, relative to `start`; `None` holds the start.
    across: Option<AcrossMove>,
    /// Time since the (re)start on the joint states' clock [s], and that clock's reading at the last tick.
    time: f64,
    last_tick: Option<f64>,
    plan: Option<(Trajectory, f64)>,
    f_cmd: f64,
    contact_lost: bool,
    force_limited: bool,
    /// The force command's bound, while one stands; what the last back-off was for.
    command_bound: Option<CommandBound>,
    trip: Option<Trip>,
    /// When the back-off in progress began [s]: the guard waits for it to end before it looks again.
    /// Any new plan ends that wait (a command right after a back-off once pushed on, unguarded).
    back_off_since: Option<f64>,
    /// The measured force of the previous tick and its smoothed rate [N/s], to back off before the
    /// force limit is passed rather than after.
    force_trend: Option<(f64, f64)>,
    /// The driver's KRC session the contact state belongs to.
    session: Option<u32>,
    limiter: TorqueLimiter,
    /// The contact model with its effects' states, when it has effects (an augmented model): force
    /// commands and their holds go through it, and the sensor's named bias and drift come out of the
    /// reading.
    inverse: Option<AugmentedInverse>,
    /// The standing force command's hold through the augmented model: from `since` (the end of its move)
    /// the deformation held is re-solved every tick, so the force stays while the surface relaxes.
    force_hold: Option<ForceHold>,
    /// The arm's normal contact force this tick, from its joint torques ([`Self::observe_arm_force`]),
    /// and smoothed.
    arm_force: Option<f64>,
    arm_smoothed: Option<f64>,
    /// Buffers of eq. 15 and of the posture torque: the tick allocates nothing.
    torque: TaskTorque,
    tau0: DVector<f64>,
}

impl DeformationController {
    pub fn new(config: ControllerConfig, contact_model: ContactModel) -> Result<Self, ControlError> {
        let model = config.arm.model(&lwr4::model())?;
        let geometry = ContactGeometry::lwr4(config.normal).ok_or(ControlError::ZeroNormal)?;
        plausible_for(&contact_model, &config)?;
        let inverse = AugmentedInverse::needed(&contact_model).then(|| AugmentedInverse::new(contact_model.clone()));
        Ok(Self {
            data: model.data(),
            tool: model.frame_id(lwr4::TOOL_FRAME)?,
            onset: OnsetDetector::new(config.onset)?,
            config: ControllerConfig { normal: geometry.normal(), ..config },
            geometry,
            model,
            contact_model,
            contact_level: None,
            offset: 0.0,
            start: None,
            origin: None,
            across: None,
            time: 0.0,
            last_tick: None,
            plan: None,
            f_cmd: 0.0,
            contact_lost: false,
            force_limited: false,
            command_bound: None,
            trip: None,
            back_off_since: None,
            force_trend: None,
            session: None,
            limiter: TorqueLimiter::new(),
            inverse,
            force_hold: None,
            arm_force: None,
            arm_smoothed: None,
            torque: TaskTorque::new(7),
            tau0: DVector::zeros(7),
        })
    }

    /// Adopts a new contact model and the estimated offset of the surface from the onset position (the
    /// true surface lies at d + offset·n; negative when the onset fired late, as on a soft sponge).
    /// An implausible model or offset is refused and the present one kept.
    pub fn set_contact_model(&mut self, model: ContactModel, offset: f64) -> Result<(), ControlError> {
        self.check_plausible(&model, offset)?;
        match (self.inverse.as_mut(), AugmentedInverse::needed(&model)) {
            (Some(inverse), true) => inverse.adopt(model.clone()),
            (None, true) => self.inverse = Some(AugmentedInverse::new(model.clone())),
            (_, false) => self.inverse = None,
        }
        self.contact_model = model;
        self.offset = offset;
        Ok(())
    }

    /// The F/T sensor was tared: a named sensor drift counts from now.
    pub fn sensor_tared(&mut self) {
        if let Some(inverse) = self.inverse.as_mut() {
            inverse.tared();
        }
    }

    /// Adopts the estimator's model and its placement of the undeformed surface in the world. The
    /// present reference is shifted with the new surface, so the hand's target does not jump; with
    /// `retarget` the standing force command is then re-planned through the new model over that many
    /// seconds (the continuous update policy).
    pub fn adopt_estimate(
        &mut self,
        model: ContactModel,
        surface: &Vector3<f64>,
        retarget: Option<f64>,
    ) -> Result<(), ControlError> {
        let offset = match self.contact_level {
            Some(level) => self.geometry.along(surface) - level,
            None => self.offset,
        };
        self.check_plausible(&model, offset)?;
        if let Some((plan, _)) = self.plan.as_mut() {
            plan.offset -= offset - self.offset;
        }
        self.set_contact_model(model, offset)?;
        match retarget {
            Some(duration) if self.f_cmd > 0.0 && !self.contact_lost => {
                // A re-plan is no new command: the bound stays the standing command's (measured anew
                // at each re-plan, a stream of ever softer models would raise it step by step).
                let standing = self.command_bound;
                self.command_force(self.f_cmd, duration)?;
                self.command_bound = standing.or(self.command_bound);
                Ok(())
            }
            _ => Ok(()),
        }
    }

    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// The contact's geometry: the normal of the configuration, the sensor mounted as on the LWR IV.
    pub fn geometry(&self) -> &ContactGeometry {
        &self.geometry
    }

    /// The tool's pose and twist at (q, q̇), from the law's own model: the one kinematics pass of the
    /// cycle, which the tick (and [`Self::tool_jacobian`]) reuse at the same q whoever asks first.
    pub fn tool_motion(&mut self, q: &[f64; 7], dq: &[f64; 7]) -> FrameMotion {
        self.model.frame_motion(&mut self.data, q, dq, self.tool)
    }

    /// The tool's pose at q, on the same kinematics pass (for whoever needs no twist).
    pub fn tool_pose(&mut self, q: &[f64; 7]) -> Isometry3<f64> {
        self.model.forward_kinematics(&mut self.data, q);
        self.model.frame_pose(&self.data, self.tool)
    }

    /// The tool's Jacobian (world axes) at q into `out` (6 × 7), on the same kinematics pass.
    pub fn tool_jacobian(&mut self, q: &[f64; 7], out: &mut Matrix6xX<f64>) {
        self.model.forward_kinematics(&mut self.data, q);
        self.model.frame_jacobian(&self.data, self.tool, Axes::World, out);
    }

    /// Where the undeformed surface is along n \[m\] (`None`: no contact found since the (re)start).
    pub fn contact_level(&self) -> Option<f64> {
        self.contact_level
    }

    /// The controller's own clock \[s\]: it advances with each tick (by the joint states' stamps) and
    /// starts again at a restart; moves are planned on it.
    pub fn time(&self) -> f64 {
        self.time
    }

    pub fn contact_model(&self) -> &ContactModel {
        &self.contact_model
    }

    /// The force commanded now \[N\] (0: none stands, or it was cancelled by a back-off or a lost contact).
    pub fn force_command(&self) -> f64 {
        self.f_cmd
    }

    /// The hand's position and orientation in the world where it started (`None` before the first tick
    /// after a (re)start): the hold across the surface and in orientation is relative to it.
    pub fn start_pose(&self) -> Option<(Vector3<f64>, UnitQuaternion<f64>)> {
        self.start.map(|(r, q, _)| (r, q))
    }

    /// Follows the driver's KRC session before a tick: whether to tick on this joint state. A new session,
    /// a KRC that does not command (monitor mode), or joint states that came after `silence` seconds
    /// longer than `restart_after` make the controller [`restart`](Self::restart); it ticks only while
    /// the KRC commands.
    pub fn follow_session(&mut self, session: Option<u32>, commanding: bool, silence: f64) -> bool {
        let interrupted = !(silence <= self.config.restart_after);
        if interrupted || session != self.session || !commanding {
            self.restart();
            self.session = session;
        }
        commanding
    }

    /// The approach went `max_approach` without finding a surface: the hand holds there.
    pub fn approach_exhausted(&self) -> bool {
        self.contact_level.is_none() && self.config.approach_speed * self.time >= self.config.max_approach
    }

    /// The arm's own view of the normal contact force this tick (from the KRC's external joint torque
    /// estimate), `None` where it has none: what confirms a model's correction of the sensor.
    pub fn observe_arm_force(&mut self, normal_force: Option<f64>) {
        self.arm_force = normal_force.filter(|f| f.is_finite());
    }

    /// Forgets the contact, the plan, the start pose and the move across the surface: the next tick
    /// approaches again from where the hand is, and holds it there across the surface and in orientation.
    /// For a new KRC session, or joint states that stopped for a while — the arm may have been moved, the
    /// surface too.
    pub fn restart(&mut self) {
        self.arm_smoothed = None;
        if let Ok(onset) = OnsetDetector::new(self.config.onset) {
            self.onset = onset;
        }
        self.contact_level = None;
        self.offset = 0.0;
        self.start = None;
        self.across = None;
        self.time = 0.0;
        self.last_tick = None;
        self.plan = None;
        self.f_cmd = 0.0;
        self.contact_lost = false;
        self.force_limited = false;
        self.command_bound = None;
        self.trip = None;
        self.back_off_since = None;
        self.force_trend = None;
        self.limiter.reset();
        self.force_hold = None;
        if let Some(inverse) = self.inverse.as_mut() {
            inverse.reset();
        }
    }

    fn reference(&self) -> Reference {
        if let Some(ForceHold { z: Some(z), .. }) = self.force_hold {
            return Reference { position: z, ..Default::default() };
        }
        self.plan.as_ref().map(|(q, t0)| q.at(self.time - t0)).unwrap_or_default()
    }

    /// Follows `segments` from now on; the first must start at the present reference.
    fn follow(&mut self, segments: Vec<Segment>) -> Result<(), ControlError> {
        self.plan = Some((Trajectory::new(segments).ok_or(ControlError::Duration)?, self.time));
        self.back_off_since = None;
        self.force_hold = None;
        self.command_bound = None;
        Ok(())
    }

    /// Holds deformation z from now on.
    fn hold(&mut self, z: f64) -> Result<(), ControlError> {
        let hold = Reference { position: z, ..Default::default() };
        self.follow(vec![Segment::Move(Quintic::new(hold, hold, 1.0).ok_or(ControlError::Duration)?)])
    }

    /// A move from the present reference, refused if too quick or too long. (Deformation commands are
    /// position commands: the model in use may be a rough guess, so the force guard, not the model,
    /// bounds their force.)
    fn move_to(&self, to: Reference, duration: f64) -> Result<Segment, ControlError> {
        let limits = &self.config.limits;
        let duration = limits.check_duration(duration)?;
        let quintic = Quintic::new(self.reference(), to, duration).ok_or(ControlError::Duration)?;
        limits.check_rate(quintic.peak_velocity())?;
        Ok(Segment::Move(quintic))
    }

    /// A deformation command (position control along n, the force-control paper's identification ramps): a quintic of
    /// `duration` seconds to rest at deformation z; negative z lifts the hand off the surface. Cancels
    /// any force command.
    pub fn command_deformation(&mut self, z: f64, duration: f64) -> Result<(), ControlError> {
        if self.contact_level.is_none() {
            return Err(ControlError::NoContact);
        }
        let z = self.config.limits.check_deformation(z)?;
        let to = self.move_to(Reference { position: z, ..Default::default() }, duration)?;
        self.follow(vec![to])?;
        self.f_cmd = 0.0;
        Ok(())
    }

    /// The force-control paper's identification pushes: a quintic of one period into the lowest point, then `periods`
    /// sinusoidal periods between deformations `low` and `high` at `frequency`; it ends at `low`.
    pub fn command_pushes(&mut self, low: f64, high: f64, frequency: f64, periods: u32) -> Result<(), ControlError> {
        if self.contact_level.is_none() {
            return Err(ControlError::NoContact);
        }
        let limits = &self.config.limits;
        let (low, high) = (limits.check_deformation(low)?, limits.check_deformation(high)?);
        if !(frequency.is_finite() && frequency > 0.0 && high >= low && (1..=MAX_PUSH_PERIODS).contains(&periods)) {
            return Err(ControlError::Duration);
        }
        limits.check_duration(1.0 / frequency)?;
        // The oscillation's peak speed.
        limits.check_rate(std::f64::consts::PI * frequency * (high - low))?;
        let push = Oscillation { mean: (low + high) / 2.0, amplitude: (high - low) / 2.0, frequency, periods };
        let ramp = self.move_to(push.start(), 1.0 / frequency)?;
        self.follow(vec![ramp, Segment::Oscillate(push)])?;
        self.f_cmd = 0.0;
        Ok(())
    }

    /// A new force command, reached by a quintic of `duration` seconds from the present reference.
    pub fn command_force(&mut self, force: f64, duration: f64) -> Result<(), ControlError> {
        let force = self.config.limits.check_force(force)?;
        self.config.limits.check_duration(duration)?;
        if self.contact_level.is_none() {
            return Err(ControlError::NoContact);
        }
        let z = match &self.inverse {
            Some(inverse) => inverse.end_of_move(&self.reference(), force, duration)?,
            None => self.contact_model.deformation_for_force(force)?,
        };
        let z = self.config.limits.check_deformation(z)?;
        let to = self.move_to(Reference { position: z, ..Default::default() }, duration)?;
        self.follow(vec![to])?;
        if self.inverse.is_some() {
            self.force_hold = Some(ForceHold { since: self.time + duration, z: None });
        }
        let measured = self.force_trend.map_or(0.0, |(f, _)| f);
        self.command_bound =
            Some(CommandBound { force, during_move: force.max(measured), move_end: self.time + duration });
        self.f_cmd = force;
        self.contact_lost = false;
        self.force_limited = false;
        self.trip = None;
        Ok(())
    }
}
