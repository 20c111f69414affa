//! The force guard and the plausibility of a contact model: what the controller refuses and when it backs
//! off. Backing off past `force_limit` or the standing command's bound, the hold of an augmented model
//! within its margins, and a sensor correction taken only as far as the arm's joint torques confirm it.

use softcontact_contact::{ContactModel, Effect};

use super::{ControlError, ControllerConfig, DeformationController};

/// The largest correction of a reading by a named sensor bias or drift, as a share of `max_force`: a
/// tare zeroes the offset, so what is left is small, and a model claiming more is refused (a bias) or
/// cut to it (a drift, which grows with the time since the tare).
pub const MAX_SENSOR_CORRECTION: f64 = 0.05;
/// How far above a force command the hold of an augmented model lets the measured force stand (a share
/// of the command, and at least \[N\]) before it backs off, whatever the model says of the surface.
pub const MODEL_FORCE_EXCESS: f64 = 0.05;
pub const MODEL_FORCE_EXCESS_MIN: f64 = 2.0;
/// The least force \[N\] a contact model must give at `max_deformation` for the controller to take it.
pub const MIN_MODEL_FORCE: f64 = 1.0;

/// How far above a force command the measured force may go, whatever the model and its plan, before
/// the controller backs off as it does from `force_limit` (a share of the command, and at least \[N\]).
/// While the command's move runs, the bound is taken from the larger of the command and the force
/// measured when it was given, so a step down is not a trip. A model that misplaces or softens the
/// surface (a stranger's, or one identified on another material) would otherwise press on to the force
/// limit. Above the transients of a fitting model's moves; the augmented model's hold keeps its own,
/// tighter bound ([`MODEL_FORCE_EXCESS`]).
pub const OVER_COMMAND: f64 = 0.25;
pub const OVER_COMMAND_MIN: f64 = 5.0;

/// The time constant over which the arm's normal force is smoothed before it confirms a sensor
/// correction \[s\].
pub const ARM_FORCE_SMOOTHING: f64 = 0.05;

/// How far above the command the surface's measured force may be before the hold of an augmented model
/// stops going deeper (a share of the command; above the sensor's noise at the forces commanded).
pub const HOLD_FORCE_MARGIN: f64 = 0.02;

/// How far the hold of an augmented model may lead the measured deformation \[m\].
pub const HOLD_LEAD: f64 = 1e-3;

/// How fast the controller backs off after passing the force limit [s].
pub(super) const BACK_OFF_DURATION: f64 = 0.2;
/// How far ahead the force guard looks [s]: the hand needs a few ticks to turn around.
pub(super) const FORCE_LOOKAHEAD: f64 = 0.02;
/// Smallest step of a back-off [m]: it always lifts the hand.
pub(super) const BACK_OFF_MIN_STEP: f64 = 0.5e-3;
/// Most periods of one series of identification pushes.
pub(super) const MAX_PUSH_PERIODS: u32 = 10_000;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ForceHold {
    pub(super) since: f64,
    /// The deformation held now; `None` until the move has ended.
    pub(super) z: Option<f64>,
}

/// The standing force command's bound ([`OVER_COMMAND`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CommandBound {
    /// The command [N], and the larger of it and the force measured when it was given.
    pub(super) force: f64,
    pub(super) during_move: f64,
    /// When the command's move ends [s, controller time].
    pub(super) move_end: f64,
}

impl CommandBound {
    pub(super) fn at(&self, time: f64) -> f64 {
        let force = if time < self.move_end { self.during_move } else { self.force };
        force * (1.0 + OVER_COMMAND) + OVER_COMMAND_MIN
    }
}

/// Why the guard backed off: it backs off again if the force is still `above` when the back-off ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Trip {
    pub(super) above: f64,
    /// The force the back-off aims for, if the surface's force grew linearly with the deformation.
    pub(super) towards: f64,
    pub(super) over_command: bool,
}

/// What the controller takes as a contact model under `config`: a plausible one
/// ([`ContactModel::plausible`], which holds the exponents to [`super::EXPONENT_RANGE`]) with a named sensor bias within
/// [`MAX_SENSOR_CORRECTION`] of `max_force`.
pub(super) fn plausible_for(model: &ContactModel, config: &ControllerConfig) -> Result<(), ControlError> {
    let implausible = |why: String| Err(ControlError::ImplausibleModel(why));
    if let Err(e) = model.plausible() {
        return implausible(e.to_string());
    }
    // A surface the law cannot press measurably within max_deformation: its inverse asks for depths
    // the limits refuse, or for a deformation the hand cannot hold against the sensor's noise.
    let deepest = model.force(config.limits.max_deformation, 0.0).unwrap_or(f64::NAN);
    if !(deepest >= MIN_MODEL_FORCE) {
        return implausible(format!(
            "{deepest} N at max_deformation ({} m): softer than a surface pressed with {MIN_MODEL_FORCE} N",
            config.limits.max_deformation
        ));
    }
    let bias: f64 =
        model.effects.iter().map(|e| if let Effect::SensorBias { offset } = *e { offset } else { 0.0 }).sum();
    let most = MAX_SENSOR_CORRECTION * config.limits.max_force;
    if bias.abs() > most {
        return implausible(format!(
            "a sensor bias of {bias} N, beyond {most} N ({MAX_SENSOR_CORRECTION} of max_force)"
        ));
    }
    Ok(())
}

impl DeformationController {
    pub(super) fn check_plausible(&self, model: &ContactModel, offset: f64) -> Result<(), ControlError> {
        let implausible = |why: String| Err(ControlError::ImplausibleModel(why));
        plausible_for(model, &self.config)?;
        if !(offset.is_finite() && offset.abs() <= self.config.max_surface_offset) {
            return implausible(format!(
                "surface {offset} m from the onset, beyond {} m",
                self.config.max_surface_offset
            ));
        }
        Ok(())
    }

    /// The measured force's rate [N/s], smoothed over ~10 ms so that sensor noise does not trip it.
    pub(super) fn force_rate(&mut self, force: f64, dt: f64) -> f64 {
        let alpha = (dt / 0.01).min(1.0);
        let (previous, rate) = self.force_trend.unwrap_or((force, 0.0));
        let rate = rate + alpha * ((force - previous) / dt - rate);
        self.force_trend = Some((force, rate));
        rate
    }

    /// How much of a model's correction of the reading (its named sensor bias and drift, at most
    /// [`MAX_SENSOR_CORRECTION`] of `max_force`) is taken: as much as the arm's torques confirm it. In
    /// full where the corrected force agrees with the arm's (smoothed over [`ARM_FORCE_SMOOTHING`]),
    /// nothing where it is half the correction or more away from it, linearly in between. Unconfirmed,
    /// a correction is a push of its own: fed forward, a wrong bias of −12 N in a model turned a 60 N
    /// command into 103 N, and even 3 N of it pressed 10 N more into the sponge.
    pub(super) fn sensor_correction(&mut self, reading: f64, correction: f64, dt: f64) -> f64 {
        let most = MAX_SENSOR_CORRECTION * self.config.limits.max_force;
        let correction = correction.clamp(-most, most);
        let alpha = (dt / ARM_FORCE_SMOOTHING).min(1.0);
        self.arm_smoothed = self.arm_force.map(|arm| match self.arm_smoothed {
            Some(previous) => previous + alpha * (arm - previous),
            None => arm,
        });
        let Some(arm) = self.arm_smoothed else { return 0.0 };
        if correction == 0.0 {
            return 0.0;
        }
        let disagreement = ((reading - correction) - arm).abs() / (0.5 * correction.abs());
        correction * (1.0 - disagreement).clamp(0.0, 1.0)
    }

    /// After the standing force command's move: the deformation that keeps its force through the
    /// augmented model now, at most `max_deformation_rate` from the last one and within the limits
    /// (else the last one is kept). It goes no deeper while the surface's measured force is above the
    /// command by [`HOLD_FORCE_MARGIN`], or while it leads the measured deformation by [`HOLD_LEAD`]: a
    /// model whose surface relaxes or sinks where the real one does not can neither walk the force up
    /// nor wind the reference up ahead of the hand. Allocates nothing.
    pub(super) fn update_force_hold(&mut self, dt: f64, measured: f64, z_measured: f64) {
        let (Some(inverse), Some(hold)) = (self.inverse.as_ref(), self.force_hold) else { return };
        if self.f_cmd <= 0.0 || self.time < hold.since {
            return;
        }
        let last = hold.z.unwrap_or_else(|| self.reference().position);
        let limits = &self.config.limits;
        let step = limits.max_deformation_rate * dt;
        let pressed = measured > self.f_cmd * (1.0 + HOLD_FORCE_MARGIN) || last - z_measured > HOLD_LEAD;
        let deeper = if pressed { 0.0 } else { step };
        // Above the command by more than MODEL_FORCE_EXCESS (MODEL_FORCE_EXCESS_MIN at least), whatever
        // the model says of the surface (a drift it names that is not there): back off, faster the more
        // it is over, at most max_deformation_rate.
        let allowed = (MODEL_FORCE_EXCESS * self.f_cmd).max(MODEL_FORCE_EXCESS_MIN);
        let over = measured - self.f_cmd - allowed;
        let shallower = (over > 0.0).then(|| last - step * (over / allowed).min(1.0));
        let z = match inverse.hold(self.f_cmd, last, dt) {
            Ok(z) => z.clamp(last - step, last + deeper).min(shallower.unwrap_or(f64::INFINITY)),
            Err(_) => shallower.unwrap_or(last),
        };
        let z = limits.check_deformation(z).unwrap_or(last);
        self.force_hold = Some(ForceHold { z: Some(z), ..hold });
    }

    /// Whether the force `guarded` (rising at `rate` [N/s]) trips the guard now: past `force_limit`
    /// (looking `FORCE_LOOKAHEAD` ahead), past the standing command's bound, or — when a back-off has
    /// ended — still past what tripped it. Nothing while a back-off runs.
    pub(super) fn over_force(&self, guarded: f64, rate: f64) -> Option<Trip> {
        let ahead = guarded + rate.max(0.0) * FORCE_LOOKAHEAD;
        if self.force_limited {
            let backing_off = self.back_off_since.is_some_and(|t| self.time - t < BACK_OFF_DURATION);
            return self.trip.filter(|t| !backing_off && if t.over_command { guarded } else { ahead } > t.above);
        }
        let max_force = self.config.limits.max_force;
        if ahead > self.config.limits.force_limit {
            return Some(Trip { above: max_force, towards: max_force, over_command: false });
        }
        let bound = self.command_bound?.at(self.time);
        (guarded > bound).then_some(Trip { above: bound, towards: self.f_cmd, over_command: true })
    }
}
