//! What the driver holds between cycles: the command it applies, with its age, and the hold it answers
//! with when there is none.

use super::Params;

/// A command and its age: taken at cycle `at`, when its stamp was `age` seconds old; `stamp`: the stamp
/// of the joint state a command from the network answers (`None`: the in-process controller's, which
/// answers the very measurement).
#[derive(Debug, Clone, Copy)]
pub(super) struct Command {
    pub effort: [f64; 7],
    pub at: u64,
    pub age: f64,
    pub stamp: Option<f64>,
}

impl Command {
    /// Whether the command may still answer the measurement of `cycle`: at most `watchdog_cycles` after
    /// it was taken, and its stamp then at most `max_command_age` old.
    pub fn fresh(&self, cycle: u64, sample_time: f64, config: &Params) -> bool {
        let cycles = cycle.saturating_sub(self.at);
        cycles <= config.watchdog_cycles && self.age + cycles as f64 * sample_time <= config.max_command_age
    }
}

/// Where a hold holds, since which cycle, and how the torque it took over is split: a set-point offset
/// of the spring (kept) and the rest (fading).
#[derive(Debug, Clone, Copy)]
pub(super) struct Hold {
    pub q: [f64; 7],
    pub since: u64,
    pub preload: [f64; 7],
    pub rest: [f64; 7],
}

impl Hold {
    pub fn new(q: [f64; 7], since: u64, torque: &[f32; 7], config: &Params) -> Self {
        let limit = config.hold_max_preload;
        let preload = std::array::from_fn(|i| (torque[i] as f64 / config.hold_stiffness[i]).clamp(-limit, limit));
        let rest = std::array::from_fn(|i| torque[i] as f64 - config.hold_stiffness[i] * preload[i]);
        Self { q, since, preload, rest }
    }
}
