//! The ATI Gamma on the flange: the wrench the hand puts on the sensing frame (contact force and the
//! hand's weight), plus bias, drift, white and coloured noise, quantised to RDT counts.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use softcontact_dynamics::BodyInertia;
use softcontact_wire::rdt::{self, Calibration, Record, Status};

/// Sensor imperfections.
#[derive(Debug, Clone)]
pub struct FtSensorConfig {
    pub calibration: Calibration,
    /// Standard deviation of white noise per axis (Fx Fy Fz \[N\], Tx Ty Tz [N·m]).
    pub noise: [f64; 6],
    /// Constant offset per axis.
    pub bias: [f64; 6],
    /// Offset growth per axis per second (temperature drift).
    pub drift: [f64; 6],
    /// Coloured noise per axis: the standard deviation of an Ornstein–Uhlenbeck process (first-order
    /// low-passed white noise) added to the reading; 0 for none.
    pub coloured_noise: [f64; 6],
    /// Its correlation time \[s\]: tens of ms is a filtered electronics' noise, tens of seconds a slow
    /// wander of the offset that no tare schedule follows.
    pub coloured_time_constant: f64,
    /// The sensor as mounted, turned from the frame the URDF gives it by this rotation (the snake paper's
    /// misalignment of the sensor's axes with the pushing axes: a mounting error no tool knows of).
    pub mounting: UnitQuaternion<f64>,
    /// A warm-up of the electronics: per axis, an offset that settles exponentially to this value,
    /// w(t) = warm_up·(1 − e^{−t/τ}) with τ = [`Self::warm_up_time_constant`]; zeros for none.
    pub warm_up: [f64; 6],
    pub warm_up_time_constant: f64,
    /// The converter's lag \[s\]: each reading is the wrench of this long ago, linearly interpolated
    /// between the simulator's steps (any value, not a whole number of them); 0 for none.
    pub delay: f64,
}

impl FtSensorConfig {
    /// A Gamma SI-130-10 as it behaves on a bench: noise near its resolution, a small bias.
    pub fn gamma() -> Self {
        Self {
            calibration: Calibration::gamma_si_130_10(),
            noise: [0.03, 0.03, 0.05, 0.0015, 0.0015, 0.0012],
            bias: [0.4, -0.3, 0.8, 0.01, -0.02, 0.005],
            drift: [0.0; 6],
            coloured_noise: [0.0; 6],
            coloured_time_constant: 0.0,
            mounting: UnitQuaternion::identity(),
            warm_up: [0.0; 6],
            warm_up_time_constant: 0.0,
            delay: 0.0,
        }
    }

    /// A Gamma in a lab session: as [`Self::gamma`], with its offsets drifting as it warms up (a few
    /// tenths of a newton over minutes: what a tare at the start of each experiment is for).
    pub fn gamma_drifting() -> Self {
        Self { drift: [0.003, -0.002, 0.004, 1e-4, -1e-4, 5e-5], ..Self::gamma() }
    }

    /// No noise, bias or drift: for tests that compare against exact physics.
    pub fn ideal() -> Self {
        Self { noise: [0.0; 6], bias: [0.0; 6], ..Self::gamma() }
    }

    /// A Nano17 (SI-25-0.25) as the snake paper read its half-ball: 1/1280 N resolution (counts per newton),
    /// noise a few resolution steps, no bias. Its ranges are widened (forces 70 N, torques 5 N·m): on the
    /// product's flange the hand weighs on it and the contact lies 10 cm from its origin, where the snake paper's
    /// plate sat on the sensor itself.
    pub fn nano17() -> Self {
        Self {
            calibration: Calibration {
                counts_per_force: 1280.0,
                counts_per_torque: 256_000.0,
                force_unit: 1.0,
                torque_unit: 1.0,
                range: [70.0, 70.0, 70.0, 5.0, 5.0, 5.0],
            },
            noise: [0.005, 0.005, 0.005, 1e-5, 1e-5, 1e-5],
            bias: [0.0; 6],
            drift: [0.0; 6],
            coloured_noise: [0.0; 6],
            coloured_time_constant: 0.0,
            mounting: UnitQuaternion::identity(),
            warm_up: [0.0; 6],
            warm_up_time_constant: 0.0,
            delay: 0.0,
        }
    }
}

/// The sensor's state: stream counters and the box's own tare.
#[derive(Debug, Clone)]
pub struct FtSensor {
    config: FtSensorConfig,
    /// The hand beyond the sensing frame, in the sensing frame.
    load: BodyInertia,
    rdt_sequence: u32,
    ft_sequence: u32,
    tare: [i32; 6],
    /// The coloured noise's state and the time it was last advanced to.
    coloured: [f64; 6],
    coloured_at: Option<f64>,
    /// The exact wrenches of the last [`FtSensorConfig::delay`] (time, wrench), oldest first.
    history: std::collections::VecDeque<(f64, [f64; 6])>,
}

impl FtSensor {
    pub fn new(config: FtSensorConfig, load: BodyInertia) -> Self {
        Self {
            config,
            load,
            rdt_sequence: 0,
            ft_sequence: 0,
            tare: [0; 6],
            coloured: [0.0; 6],
            coloured_at: None,
            history: Default::default(),
        }
    }

    /// A new stream starts (RDT start request): the stream counter restarts.
    pub fn start_stream(&mut self) {
        self.rdt_sequence = 0;
    }

    /// The exact wrench on the sensing frame, in it: contact force at the tool plus the hand's weight.
    pub fn true_wrench(
        &self,
        sensor: &Isometry3<f64>,
        tool: &Isometry3<f64>,
        contact_force: &Vector3<f64>,
        gravity: Vector3<f64>,
    ) -> [f64; 6] {
        let r = (sensor.rotation * self.config.mounting).to_rotation_matrix();
        let weight = r.inverse() * (self.load.mass * gravity);
        let contact = r.inverse() * contact_force;
        let lever = r.inverse() * (tool.translation.vector - sensor.translation.vector);
        let force = contact + weight;
        let torque = lever.cross(&contact) + self.load.com().cross(&weight);
        [force.x, force.y, force.z, torque.x, torque.y, torque.z]
    }

    /// The Ornstein–Uhlenbeck noise advanced exactly to `time` (stationary from its first sample).
    fn advance_coloured(&mut self, time: f64, rng: &mut impl Rng) {
        let c = &self.config;
        if c.coloured_time_constant <= 0.0 || c.coloured_noise.iter().all(|&s| s <= 0.0) {
            return;
        }
        let keep = match self.coloured_at {
            Some(at) => (-(time - at).max(0.0) / c.coloured_time_constant).exp(),
            None => 0.0,
        };
        let fresh = (1.0 - keep * keep).sqrt();
        for i in 0..6 {
            let sigma = c.coloured_noise[i];
            let z: f64 = if sigma > 0.0 { Normal::new(0.0, sigma).expect("finite σ").sample(rng) } else { 0.0 };
            self.coloured[i] = keep * self.coloured[i] + fresh * z;
        }
        self.coloured_at = Some(time);
    }

    /// The next record of the stream.
    pub fn record(
        &mut self,
        sensor: &Isometry3<f64>,
        tool: &Isometry3<f64>,
        contact_force: &Vector3<f64>,
        gravity: Vector3<f64>,
        time: f64,
        rng: &mut impl Rng,
    ) -> Record {
        let (raw, saturated) = self.sample(sensor, tool, contact_force, gravity, time, rng);
        let record = Record {
            rdt_sequence: self.rdt_sequence,
            ft_sequence: self.ft_sequence,
            status: Status(if saturated { Status::ERROR_SUMMARY | Status::SATURATION } else { 0 }),
            counts: std::array::from_fn(|i| raw[i].wrapping_sub(self.tare[i])),
        };
        self.rdt_sequence = self.rdt_sequence.wrapping_add(1);
        record
    }

    /// RDT 0x0042: the box takes a reading now (streaming or not: its converter always runs) and
    /// subtracts it from every record after.
    pub fn set_bias(
        &mut self,
        sensor: &Isometry3<f64>,
        tool: &Isometry3<f64>,
        contact_force: &Vector3<f64>,
        gravity: Vector3<f64>,
        time: f64,
        rng: &mut impl Rng,
    ) {
        self.tare = self.sample(sensor, tool, contact_force, gravity, time, rng).0;
    }

    /// One conversion of the box: the raw counts (before its bias) and whether an axis saturated.
    fn sample(
        &mut self,
        sensor: &Isometry3<f64>,
        tool: &Isometry3<f64>,
        contact_force: &Vector3<f64>,
        gravity: Vector3<f64>,
        time: f64,
        rng: &mut impl Rng,
    ) -> ([i32; 6], bool) {
        let exact = self.true_wrench(sensor, tool, contact_force, gravity);
        let exact = self.delayed(time, exact);
        self.advance_coloured(time, rng);
        let c = &self.config;
        let warmed = if c.warm_up_time_constant > 0.0 { 1.0 - (-time / c.warm_up_time_constant).exp() } else { 0.0 };
        let reading: [f64; 6] = std::array::from_fn(|i| {
            let noise =
                if c.noise[i] > 0.0 { Normal::new(0.0, c.noise[i]).expect("finite σ").sample(rng) } else { 0.0 };
            exact[i] + c.bias[i] + c.drift[i] * time + c.warm_up[i] * warmed + noise + self.coloured[i]
        });
        let (raw, saturated) = c.calibration.to_counts(&reading);
        self.ft_sequence = self.ft_sequence.wrapping_add(1);
        (raw, saturated)
    }

    /// The wrench of [`FtSensorConfig::delay`] before `time`, given this step's `exact` one: linear between
    /// the two steps around it, the oldest kept before the first; the history holds no more than the delay.
    fn delayed(&mut self, time: f64, exact: [f64; 6]) -> [f64; 6] {
        let delay = self.config.delay;
        if delay.is_nan() || delay <= 0.0 {
            return exact;
        }
        if self.history.back().is_some_and(|&(t, _)| t > time) {
            self.history.clear(); // time went back: a new run
        }
        self.history.push_back((time, exact));
        let at = time - delay;
        while self.history.len() > 2 && self.history[1].0 <= at {
            self.history.pop_front();
        }
        let (t0, w0) = self.history[0];
        let Some(&(t1, w1)) = self.history.get(1).filter(|_| at > t0) else { return w0 };
        let s = ((at - t0) / (t1 - t0)).clamp(0.0, 1.0);
        std::array::from_fn(|i| w0[i] + s * (w1[i] - w0[i]))
    }

    pub fn calibration(&self) -> &rdt::Calibration {
        &self.config.calibration
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp read 17.3 ms late at 1 ms steps: the reading is the ramp 17.3 ms earlier, exactly (linear
    /// interpolation is exact on a ramp), and before the first step the first wrench.
    #[test]
    fn a_delay_between_steps_reads_the_ramp_of_that_long_ago() {
        let config = FtSensorConfig { delay: 0.0173, ..FtSensorConfig::ideal() };
        let mut sensor = FtSensor::new(config, BodyInertia::ZERO);
        let ramp = |t: f64| std::array::from_fn(|i| (i as f64 + 1.0) * t);
        for step in 0..200 {
            let t = 1.0 + step as f64 * 1e-3;
            let read = sensor.delayed(t, ramp(t));
            let expected = ramp((t - 0.0173).max(1.0));
            for i in 0..6 {
                assert!((read[i] - expected[i]).abs() < 1e-12, "t {t}: {read:?} against {expected:?}");
            }
            assert!(sensor.history.len() <= 20, "the history holds the delay, not the run");
        }
    }
}
