//! Safety limits the controller never bypasses: commands outside the surface's force or deformation
//! range are refused (not silently clipped), torques are clipped to the joint limits and their change
//! per second is bounded, losing contact while pushing stops the push, and a measured force beyond
//! `force_limit` makes the controller back off whatever it was doing. Every number that reaches the
//! law is checked against a physical range first; a non-finite torque is an error (the driver then
//! holds), never replaced by an older one.

/// Limits of one robot on one surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// |τ_i| [N·m] (the URDF's effort limits).
    pub joint_torque: Vec<f64>,
    /// |dτ_i/dt| [N·m/s]: no torque step above this rate.
    pub torque_rate: f64,
    /// Largest force command \[N\].
    pub max_force: f64,
    /// Largest deformation command \[m\].
    pub max_deformation: f64,
    /// Largest lift above the surface a deformation command may ask for \[m\] (a negative deformation).
    pub max_lift: f64,
    /// Shortest and longest move \[s\]: a quicker move is a jolt, a longer one a forgotten command (and
    /// beyond ~1e150 s a quintic's coefficients are no longer numbers).
    pub move_duration: (f64, f64),
    /// Fastest a move may compress or lift [m/s] (a quick plunge overshoots any force guard).
    pub max_deformation_rate: f64,
    /// Below this normal force while a force is commanded, contact counts as lost \[N\].
    pub contact_lost_below: f64,
    /// Above this measured normal force the controller backs off \[N\] (above `max_force`: a model that
    /// is too soft, or a surface that stiffened, must not crush anything).
    pub force_limit: f64,
}

/// Why a command was refused (numbers as Rust's shortest round trip: 1e300 stays short).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitError {
    #[error("force command {0:?} N is outside [0, {1:?}] N")]
    Force(f64, f64),
    #[error("the force command needs a deformation of {0:?} m, beyond the surface's limit of {1:?} m")]
    Deformation(f64, f64),
    #[error("a lift of {0:?} m is beyond the limit of {1:?} m")]
    Lift(f64, f64),
    #[error("move duration {0:?} s is outside [{1:?}, {2:?}] s")]
    Duration(f64, f64, f64),
    #[error("a move at {0:?} m/s is faster than {1:?} m/s: give it more time")]
    Rate(f64, f64),
    #[error("{0} is not a finite number")]
    NonFinite(&'static str),
    #[error("torque for joint {0} is not a finite number: the driver holds")]
    NonFiniteTorque(usize),
}

impl Limits {
    pub fn check_force(&self, force: f64) -> Result<f64, LimitError> {
        if !force.is_finite() {
            return Err(LimitError::NonFinite("the force command"));
        }
        if !(0.0..=self.max_force).contains(&force) {
            return Err(LimitError::Force(force, self.max_force));
        }
        Ok(force)
    }

    pub fn check_deformation(&self, z: f64) -> Result<f64, LimitError> {
        if !z.is_finite() {
            return Err(LimitError::NonFinite("the deformation command"));
        }
        if z > self.max_deformation {
            return Err(LimitError::Deformation(z, self.max_deformation));
        }
        if z < -self.max_lift {
            return Err(LimitError::Lift(-z, self.max_lift));
        }
        Ok(z)
    }

    pub fn check_rate(&self, speed: f64) -> Result<f64, LimitError> {
        if !speed.is_finite() {
            return Err(LimitError::NonFinite("the move's speed"));
        }
        if speed.abs() > self.max_deformation_rate {
            return Err(LimitError::Rate(speed.abs(), self.max_deformation_rate));
        }
        Ok(speed)
    }

    pub fn check_duration(&self, duration: f64) -> Result<f64, LimitError> {
        let (shortest, longest) = self.move_duration;
        if !duration.is_finite() {
            return Err(LimitError::NonFinite("the move duration"));
        }
        if !(shortest..=longest).contains(&duration) {
            return Err(LimitError::Duration(duration, shortest, longest));
        }
        Ok(duration)
    }
}

/// Clips torques to the joint limits and to the rate limit relative to the previous tick's output.
#[derive(Debug, Clone, PartialEq)]
pub struct TorqueLimiter {
    last: Option<Vec<f64>>,
    /// Ticks in which something was clipped.
    pub clipped: u64,
}

impl TorqueLimiter {
    pub fn new() -> Self {
        Self { last: None, clipped: 0 }
    }

    /// Limits `tau` in place for a tick of `dt` seconds. A non-finite torque is refused whole: the
    /// caller sends no torque (the driver holds), and the rate limit starts afresh afterwards.
    pub fn apply(&mut self, limits: &Limits, tau: &mut [f64], dt: f64) -> Result<(), LimitError> {
        if let Some(i) = tau.iter().position(|t| !t.is_finite()) {
            self.last = None;
            return Err(LimitError::NonFiniteTorque(i));
        }
        let mut clipped = false;
        for (i, t) in tau.iter_mut().enumerate() {
            let previous = self.last.as_ref().map(|l| l[i]);
            let limit = limits.joint_torque[i];
            let mut v = t.clamp(-limit, limit);
            if let Some(p) = previous {
                let step = limits.torque_rate * dt;
                v = v.clamp(p - step, p + step);
            }
            clipped |= v != *t;
            *t = v;
        }
        self.clipped += u64::from(clipped);
        match self.last.as_mut() {
            Some(last) if last.len() == tau.len() => last.copy_from_slice(tau),
            _ => self.last = Some(tau.to_vec()),
        }
        Ok(())
    }

    /// Forget the previous output (e.g. after the driver held position).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

impl Default for TorqueLimiter {
    fn default() -> Self {
        Self::new()
    }
}
