//! One control tick, read → update → write for the law: check the measurements, advance the clock, the
//! kinematics once, the onset, the acceleration along n (approach, or the deformation law and the force
//! guard in contact), across the surface and in orientation (eq. 12), and the torques of eq. 15 through
//! the limiter.

use nalgebra::{UnitQuaternion, Vector3, Vector6};
use softcontact_contact::OnsetEvent;

use super::guard::{BACK_OFF_DURATION, BACK_OFF_MIN_STEP};
use super::{ControlError, ControllerState, DeformationController};
use crate::{Damping, Quintic, Reference, Segment, deformation_acceleration};

/// The joints whose Coulomb friction is fed forward: A1–A5 (efforts of 100 N m and more), not the
/// light wrist.
pub const FRICTION_COMPENSATED_JOINTS: usize = 5;

/// The share of the named Coulomb friction fed forward: an estimate a little high would otherwise push
/// the joint along its motion (the light wrist first), one a little low is taken up by the feedback.
pub const FRICTION_COMPENSATED: f64 = 0.8;

/// The velocity over which the compensation's Coulomb torque changes sign [rad/s]: wider than the
/// friction's own (0.01 rad/s), whose slope c/v_s about rest would be a large negative damping wherever
/// the file overestimates c.
pub const FRICTION_COMPENSATION_SCALE: f64 = 0.1;

/// The hand this tick, from one pass of the kinematics: the tool's position and orientation in the world,
/// its linear and angular velocity.
struct Hand {
    r: Vector3<f64>,
    rotation: UnitQuaternion<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
}

/// Where the hand started: position, orientation and the posture the null space holds.
type Start = (Vector3<f64>, UnitQuaternion<f64>, [f64; 7]);

impl DeformationController {
    /// One control tick: total joint torques (gravity included) for the joint state measured at `time`
    /// (its stamp, on any clock that advances with the arm: the driver's, or the simulation's), the
    /// measured normal force f and the contact force on the hand in the world. Plans run on that clock;
    /// a time that does not advance is refused (a replayed or reordered joint state), and a step longer
    /// than `restart_after` counts as that long (the node restarts the controller after such a gap).
    pub fn tick(
        &mut self,
        time: f64,
        q: &[f64; 7],
        dq: &[f64; 7],
        normal_force: f64,
        contact_force: &Vector3<f64>,
    ) -> Result<([f64; 7], ControllerState), ControlError> {
        finite_measurements(time, q, dq, normal_force, contact_force)?;
        let dt = self.advance_clock(time)?;
        let force_rate = self.force_rate(normal_force, dt);
        let surface_force = self.surface_force(normal_force, dt);
        let (hand, start) = self.hand(q, dq);
        self.find_contact(&hand, normal_force)?;
        let forces = Forces { reading: normal_force, surface: surface_force, rate: force_rate, world: *contact_force };
        let mut state = ControllerState { f: normal_force, f_cmd: self.f_cmd, ..Default::default() };
        let z_accel = match self.contact_level {
            None => self.approach(&hand, &start),
            Some(level) => self.in_contact(level, &hand, &forces, dt, &mut state)?,
        };
        state.f_cmd = self.f_cmd;
        state.contact_lost = self.contact_lost;
        state.force_limited = self.force_limited;
        state.over_command = self.force_limited && self.trip.is_some_and(|t| t.over_command);
        let acceleration = self.task_acceleration(z_accel, &hand, &start);
        self.posture_torque(q, dq, &start);
        let tau = self.torques(q, dq, &acceleration, &forces, &state, dt)?;
        Ok((tau, state))
    }

    /// The step since the last tick [s]: the nominal period at a (re)start, at most `restart_after`.
    fn advance_clock(&mut self, time: f64) -> Result<f64, ControlError> {
        let dt = match self.last_tick {
            None => self.config.period,
            Some(last) if time > last => (time - last).min(self.config.restart_after),
            Some(last) => return Err(ControlError::TimeNotAdvancing { time, last }),
        };
        self.last_tick = Some(time);
        self.time += dt;
        Ok(dt)
    }

    /// The surface's force as the reading says it: without the sensor's named bias and drift. Only
    /// while a force command stands on the surface: holding or in free space the correction would be
    /// fed forward as a push of its own (a wrong bias of −12 N pressed a holding hand to 20 N).
    fn surface_force(&mut self, normal_force: f64, dt: f64) -> f64 {
        let correction = match &self.inverse {
            Some(i) if self.f_cmd > 0.0 && self.contact_level.is_some() => {
                normal_force - i.surface_reading(normal_force)
            }
            _ => 0.0,
        };
        normal_force - self.sensor_correction(normal_force, correction, dt)
    }

    /// The hand's pose and velocity (the kinematics, once) and its start, taken at the first tick.
    fn hand(&mut self, q: &[f64; 7], dq: &[f64; 7]) -> (Hand, Start) {
        let motion = self.tool_motion(q, dq);
        let r = motion.pose.translation.vector;
        let start = *self.start.get_or_insert((r, motion.pose.rotation, *q));
        self.origin.get_or_insert((start.0, start.1));
        (Hand { r, rotation: motion.pose.rotation, v: motion.linear(), w: motion.angular() }, start)
    }

    /// The onset detector on the hand's position along n: at contact the contact position d is fixed
    /// and the hand holds where it touched until a force is commanded.
    fn find_contact(&mut self, hand: &Hand, normal_force: f64) -> Result<(), ControlError> {
        let along = self.geometry.along(&hand.r);
        if let Some(OnsetEvent::Contact { position }) = self.onset.update(along, normal_force)?
            && self.contact_level.is_none()
        {
            // Contact made already pressing (a restart while pushing): the surface is not where the
            // onset fired but as deep above it as the model needs for the force read now.
            let pressed = normal_force > 4.0 * self.config.onset.threshold;
            let depth = match self.contact_model.deformation_for_force(normal_force) {
                Ok(z) if pressed => z.clamp(0.0, self.config.limits.max_deformation),
                _ => 0.0,
            };
            self.contact_level = Some(position - depth);
            let position = position - depth;
            self.hold(along - position - self.offset)?;
        }
        Ok(())
    }

    /// Before contact: a constant descent along n from where the hand started, `max_approach` at most.
    fn approach(&self, hand: &Hand, start: &Start) -> f64 {
        let travel = self.config.approach_speed * self.time;
        let from = self.geometry.along(&start.0);
        let (target, speed) = if travel < self.config.max_approach {
            (from + travel, self.config.approach_speed)
        } else {
            (from + self.config.max_approach, 0.0)
        };
        let g = &self.config.gains;
        g.stiffness * (target - self.geometry.along(&hand.r)) + g.damping * (speed - self.geometry.rate(&hand.v))
    }

    /// In contact: the deformation and its rate (eqs. 9–10), the lost-contact and force guards, the hold
    /// of an augmented model, and the deformation law (eq. 11) on the reference.
    fn in_contact(
        &mut self,
        level: f64,
        hand: &Hand,
        forces: &Forces,
        dt: f64,
        state: &mut ControllerState,
    ) -> Result<f64, ControlError> {
        let along = self.geometry.along(&hand.r);
        state.in_contact = true;
        state.z = along - level - self.offset;
        state.zdot = self.geometry.rate(&hand.v);
        if let Some(inverse) = self.inverse.as_mut() {
            inverse.observe(state.z, state.zdot, dt)?;
        }
        self.watch_contact(forces.reading, state.z)?;
        // (The reading as it is and without a named sensor bias or drift: whichever is larger.)
        let guarded = forces.reading.max(forces.surface);
        self.guard_force(guarded, forces.rate, along - level, state.z)?;
        self.update_force_hold(dt, guarded, state.z);
        let reference = self.reference();
        state.z_cmd = reference.position;
        state.zdot_cmd = reference.velocity;
        state.f_predicted = self.contact_model.force(reference.position, reference.velocity).unwrap_or(0.0);
        Ok(deformation_acceleration(&self.config.gains, &reference, state.z, state.zdot))
    }

    /// The surface is gone while we push: the model expects a clear force at this deformation (four
    /// times the threshold) and the sensor reads less than the threshold. (At the start of a push from a
    /// light touch the force may legitimately read below the threshold.) Stop pushing, hold here.
    fn watch_contact(&mut self, normal_force: f64, z: f64) -> Result<(), ControlError> {
        let lost_below = self.config.limits.contact_lost_below;
        let expected = self.contact_model.force(z.max(0.0), 0.0).unwrap_or(0.0);
        if self.f_cmd > 0.0 && normal_force < lost_below && expected > 4.0 * lost_below && !self.contact_lost {
            self.contact_lost = true;
            self.hold(z)?;
            self.f_cmd = 0.0;
        }
        Ok(())
    }

    /// Too much force, whatever the plan — past `force_limit`, or past the standing force command's bound:
    /// back off from where the hand is, at once, to the deformation that gives `max_force` (or the
    /// command) if the force grew linearly (less on a stiffening surface), and wait there for a new
    /// command. The deformation is taken from the measured onset (`from_onset`), not the model's
    /// surface: a model that misplaces the surface must not make the back-off too short. If the force is
    /// still above what tripped the guard when the back-off ends, back off again.
    fn guard_force(&mut self, guarded: f64, rate: f64, from_onset: f64, z: f64) -> Result<(), ControlError> {
        if let Some(trip) = self.over_force(guarded, rate) {
            self.force_limited = true;
            self.trip = Some(trip);
            self.f_cmd = 0.0;
            let lift = from_onset.max(0.0) * (1.0 - trip.towards / guarded);
            let from = Reference { position: z, ..Default::default() };
            let to = Reference { position: z - lift.max(BACK_OFF_MIN_STEP), ..Default::default() };
            let back_off = Quintic::new(from, to, BACK_OFF_DURATION).ok_or(ControlError::Duration)?;
            self.follow(vec![Segment::Move(back_off)])?;
            self.back_off_since = Some(self.time);
        }
        Ok(())
    }

    /// The task acceleration (eq. 12): z̈_des along n; across the surface and in orientation, PD laws
    /// holding the start, moved by `command_across` (its reference is ⊥ n; velocity and acceleration feed
    /// forward, so a move does not lag).
    fn task_acceleration(&self, z_accel: f64, hand: &Hand, start: &Start) -> Vector6<f64> {
        let n = self.geometry.normal();
        let across = self.across_reference();
        let (kp, kd) = self.config.lateral;
        let target = start.0 + across.lateral;
        let lateral_error = self.geometry.across(&(target - hand.r));
        let lateral_velocity = self.geometry.across(&hand.v);
        let linear = z_accel * n + across.acceleration + kp * lateral_error + kd * (across.velocity - lateral_velocity);
        let (ko, kw) = self.config.orientation;
        let held = UnitQuaternion::from_scaled_axis(across.tilt) * start.1;
        let rotation_error = (held * hand.rotation.inverse()).scaled_axis();
        let angular = across.angular_acceleration + ko * rotation_error + kw * (across.angular_velocity - hand.w);
        Vector6::new(linear.x, linear.y, linear.z, angular.x, angular.y, angular.z)
    }

    /// The posture's null-space impedance: a spring and damper per joint toward the posture at the
    /// start, into `tau0`.
    fn posture_torque(&mut self, q: &[f64; 7], dq: &[f64; 7], start: &Start) {
        for i in 0..7 {
            self.tau0[i] =
                self.config.posture_stiffness[i] * (start.2[i] - q[i]) - self.config.posture_damping[i] * dq[i];
        }
    }

    /// The joint torques of eq. 15 with the posture's null-space torque (`tau0`) and the named friction fed
    /// forward, through the limiter. A limiter that refuses them holds the hand where it is.
    fn torques(
        &mut self,
        q: &[f64; 7],
        dq: &[f64; 7],
        acceleration: &Vector6<f64>,
        forces: &Forces,
        state: &ControllerState,
        dt: f64,
    ) -> Result<[f64; 7], ControlError> {
        let n = self.geometry.normal();
        // The measured contact force is fed forward (eq. 15) — but backing off from the force limit,
        // only up to the model's force at the back-off's reference (at most max_force). A sensor that
        // reads a few per cent high feeds forward more than the surface pushes back, which the soft
        // deformation gains cannot hold: the force would run away to the limit, and with the reading fed
        // forward in full the back-off could not pull the hand out.
        let mut feed_forward = forces.world + (forces.reading - forces.surface) * n;
        let cap = state.f_predicted.clamp(0.0, self.config.limits.max_force);
        if self.force_limited && forces.reading > cap {
            feed_forward += (forces.reading - cap) * n;
        }
        let wrench = Vector6::new(feed_forward.x, feed_forward.y, feed_forward.z, 0.0, 0.0, 0.0);
        let terms = self.model.control_terms(&mut self.data, q, dq, self.tool)?;
        self.torque.compute(&terms, acceleration, &wrench, &self.tau0, &Damping::default());
        // The Coulomb friction named for this arm, fed forward in part at the heavy joints (bounded by the
        // file's checks and the limiter). Its viscous part is left to damp: compensating more of it than a
        // joint has is negative damping. The wrist's is left to the feedback: there the controller's own
        // torque per radian is smaller than a file's error, and an overestimate spun joint 7.
        let friction = self.config.arm.joint_friction;
        let mut tau: [f64; 7] = std::array::from_fn(|i| {
            let compensation = match friction {
                Some(f) if i < FRICTION_COMPENSATED_JOINTS => {
                    FRICTION_COMPENSATED * f.coulomb_part(i, dq[i], FRICTION_COMPENSATION_SCALE)
                }
                _ => 0.0,
            };
            self.torque.tau[i] + compensation
        });
        if let Err(e) = self.limiter.apply(&self.config.limits, &mut tau, dt) {
            // Nothing to send this tick; the next one holds the hand where it is (across the surface:
            // where its reference is now).
            self.hold_across();
            if self.contact_level.is_some() && state.z.is_finite() {
                self.f_cmd = 0.0;
                self.hold(state.z)?;
            }
            return Err(e.into());
        }
        Ok(tau)
    }
}

/// The measured force this tick: along the normal the reading, the surface's force without a named sensor
/// bias or drift, and the reading's smoothed rate \[N/s\]; the whole contact force on the hand in the
/// world \[N\].
struct Forces {
    reading: f64,
    surface: f64,
    rate: f64,
    world: Vector3<f64>,
}

/// A tick's measurements must all be finite numbers: anything else is no torque this tick.
fn finite_measurements(
    time: f64,
    q: &[f64; 7],
    dq: &[f64; 7],
    normal_force: f64,
    contact_force: &Vector3<f64>,
) -> Result<(), ControlError> {
    if !q.iter().chain(dq).all(|v| v.is_finite()) {
        return Err(ControlError::NonFinite("the joint state"));
    }
    if !(normal_force.is_finite() && contact_force.iter().all(|v| v.is_finite())) {
        return Err(ControlError::NonFinite("the measured force"));
    }
    if !time.is_finite() {
        return Err(ControlError::NonFinite("the joint state's time"));
    }
    Ok(())
}
