//! The F/T sensor node's core: RDT records to SI wrenches in the sensing frame, a software tare, tool
//! gravity compensation from the sensor's orientation, an optional Butterworth low-pass, and counts of
//! lost, repeated and saturated records.
//!
//! What it refuses to pass on as fresh data: records that repeat or precede the last one of the stream
//! (by RDT sequence, wrap-aware; a restarted sequence after a silence or a start request is a new
//! stream), and records with the saturation or an error bit, or with any axis at or beyond the
//! calibrated range. What it refuses to do: a tare (/ft_sensor/bias) while the hand is in contact,
//! the reading is unsteady or the tool moves ([`TarePolicy`]).
//!
//! Model (sensor frame S, world W, tool mass m with centre c in S, gravity g_W, rotation R_WS):
//! measured = external + (R_WSᵀ m g_W, c × R_WSᵀ m g_W) + bias. `wrench_raw` removes the bias,
//! `wrench` also the tool's weight.

pub mod calibration;
pub mod component;
mod params;

pub use params::Params;

use std::collections::VecDeque;

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use softcontact_dynamics::BodyInertia;
use softcontact_wire::WireError;
use softcontact_wire::rdt::{Calibration, Record, Status};

#[derive(Debug, Clone, PartialEq)]
pub struct FtConfig {
    pub calibration: Calibration,
    /// The tool beyond the sensing frame (mass, centre of mass in the sensing frame).
    pub tool: BodyInertia,
    pub gravity: Vector3<f64>,
    /// Low-pass cut-off \[Hz\] at `sample_rate`; `None` for no filter.
    pub low_pass: Option<f64>,
    pub sample_rate: f64,
}

impl FtConfig {
    /// The LWR IV's hand on the sensor (the URDF's load), gravity along −z, 1 kHz records, no filter.
    pub fn lwr4(calibration: Calibration) -> Self {
        Self {
            calibration,
            tool: softcontact_dynamics::lwr4::tool_load(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            low_pass: None,
            sample_rate: 1000.0,
        }
    }
}

/// A second-order Butterworth low-pass (bilinear transform with pre-warping), one per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
    x: [f64; 2],
    y: [f64; 2],
    primed: bool,
}

impl Biquad {
    pub fn low_pass(cutoff: f64, sample_rate: f64) -> Result<Self, String> {
        if !(cutoff > 0.0 && sample_rate > 0.0 && cutoff < 0.5 * sample_rate) {
            return Err(format!("low-pass cut-off {cutoff} Hz must lie in (0, {}) Hz", 0.5 * sample_rate));
        }
        let k = (std::f64::consts::PI * cutoff / sample_rate).tan();
        let norm = 1.0 / (1.0 + std::f64::consts::SQRT_2 * k + k * k);
        let b0 = k * k * norm;
        Ok(Self {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - std::f64::consts::SQRT_2 * k + k * k) * norm],
            x: [0.0; 2],
            y: [0.0; 2],
            primed: false,
        })
    }

    /// Filters one sample; the first sample initialises the state at rest (no start-up transient).
    pub fn filter(&mut self, x: f64) -> f64 {
        if !self.primed {
            self.x = [x; 2];
            self.y = [x; 2];
            self.primed = true;
        }
        let y = self.b[0] * x + self.b[1] * self.x[0] + self.b[2] * self.x[1]
            - self.a[0] * self.y[0]
            - self.a[1] * self.y[1];
        self.x = [x, self.x[0]];
        self.y = [y, self.y[0]];
        y
    }
}

/// What one record gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FtOutput {
    /// Bias removed, sensing frame [N, N·m] (filtered if configured).
    pub raw: [f64; 6],
    /// Bias and tool weight removed; `None` until the sensor's orientation is known.
    pub compensated: Option<[f64; 6]>,
    pub status: Status,
    /// The sample must not be used for control: saturation, a value at or beyond the calibrated range,
    /// a device error, or not fresh.
    pub invalid: bool,
    /// Some axis reads at or beyond the calibrated range, or the box flags saturation.
    pub saturated: bool,
    /// The record is the next of its stream (not a duplicate or an older record). A record that is not
    /// fresh changes nothing in the node (filter, tare window, sequence), and its `raw` is unfiltered.
    pub fresh: bool,
    pub rdt_sequence: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FtCounters {
    /// Well-formed records received (fresh or not).
    pub records: u64,
    /// Records missing between fresh ones (forward gaps of the RDT sequence).
    pub lost: u64,
    /// Records older than the last fresh one of the stream: skipped.
    pub out_of_order: u64,
    /// Records repeating the last fresh one's sequence number: skipped.
    pub duplicate: u64,
    /// New streams: a restarted sequence accepted after a silence or a start request, or a coherent
    /// run of records behind the old sequence (the box restarted it without a pause).
    pub restarts: u64,
    pub malformed: u64,
    /// Fresh records with the saturation bit, or an axis at or beyond the calibrated range.
    pub saturated: u64,
    /// Fresh records with a device error bit.
    pub errors: u64,
    /// Fresh records whose transducer sample counter (`ft_sequence`) did not advance from the last
    /// record's: a stalled or restarted transducer behind a box still streaming. Not used for control.
    pub device_stalled: u64,
    /// Socket errors (ICMP port or host unreachable: the box is not up, or rebooting; no route yet).
    pub network_errors: u64,
    /// Datagrams from another address than the sensor's: skipped.
    pub foreign: u64,
    /// Tares refused by the [`TarePolicy`].
    pub tares_refused: u64,
}

/// When a tare (/ft_sensor/bias, the start-up tare) is allowed: the hand free, still and steady. The
/// checks look at the last `window` records.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TarePolicy {
    /// Records the checks look back over (`bias_window` × rate).
    pub window: usize,
    /// The first tare of the node, when the sensor's own offset is unknown: |reading − hand's weight|
    /// of the force at most this \[N\] (the sensor's offset plus any contact force).
    pub max_offset: f64,
    /// Any later tare: |force with the present tare, hand's weight removed| at most this \[N\].
    pub max_force: f64,
    /// Standard deviation of each force axis over the window at most this \[N\].
    pub max_spread: f64,
    /// Travel of the tool over the window at most this \[m\] (needs /lwr/ee_pose through the window).
    pub max_motion: f64,
    /// Rotation of the tool over the window at most this \[rad\].
    pub max_rotation: f64,
}

impl Default for TarePolicy {
    fn default() -> Self {
        Self { window: 100, max_offset: 10.0, max_force: 5.0, max_spread: 0.25, max_motion: 5e-4, max_rotation: 5e-3 }
    }
}

/// The box's web server port the node reads its calibration from by default: the simulated box's (a real
/// box serves on 80, which needs privileges to bind; `config/robot.yaml` sets it).
pub const DEFAULT_HTTP_PORT: u16 = 49180;

/// Time between start-up tare attempts while they are refused \[s\].
pub const TARE_RETRY: f64 = 0.1;

/// The start-up tare (the node's `tare_after`, one default for every host): once, `after` seconds after
/// the stream and the hand's orientation are both there, retried every [`TARE_RETRY`] while the checks
/// refuse it (the hand in contact, moving, an unsteady reading). Negative `after`: never; the user tares
/// through /ft_sensor/bias, and /ft_sensor/wrench is published from the start, untared.
#[derive(Debug, Clone, PartialEq)]
pub struct StartupTare {
    after: f64,
    due: Option<f64>,
    tared: bool,
    /// Why the last attempt was refused.
    pub refusal: Option<String>,
}

impl StartupTare {
    pub fn new(after: f64) -> Self {
        Self { after, due: None, tared: after < 0.0, refusal: None }
    }

    /// /ft_sensor/wrench may be published.
    pub fn tared(&self) -> bool {
        self.tared
    }

    /// A tare was taken on request (/ft_sensor/bias).
    pub fn taken(&mut self) {
        self.tared = true;
        self.refusal = None;
    }

    /// With the hand's orientation known at `now` [s, the host's clock]: the start-up tare's outcome when
    /// one was attempted now (its bias, or why it was refused).
    pub fn poll(
        &mut self,
        node: &mut FtSensorNode,
        orientation: &UnitQuaternion<f64>,
        now: f64,
    ) -> Option<Result<[f64; 6], String>> {
        if self.tared || now < *self.due.get_or_insert(now + self.after) {
            return None;
        }
        let outcome = node.checked_tare(Some(orientation));
        match &outcome {
            Ok(_) => self.taken(),
            Err(e) => {
                self.refusal = Some(e.clone());
                self.due = Some(now + TARE_RETRY);
            }
        }
        Some(outcome)
    }
}

/// One fresh record as the tare checks see it.
#[derive(Debug, Clone, Copy)]
struct Sample {
    unbiased: [f64; 6],
    valid: bool,
    /// The tool's pose when the record came, if a pose came within the window before it.
    tool: Option<Isometry3<f64>>,
}

/// A run of records behind the stream's sequence that follow each other: a restarted stream once it is
/// long enough.
#[derive(Debug, Clone, Copy)]
struct BehindRun {
    last: u32,
    length: usize,
}

pub struct FtSensorNode {
    config: FtConfig,
    bias: [f64; 6],
    filters: Option<[Biquad; 6]>,
    last_sequence: Option<u32>,
    /// The last fresh record's transducer sample counter, in this stream.
    last_device_sample: Option<u32>,
    last_unbiased: Option<[f64; 6]>,
    /// The next record may start a new stream (a start request went out, or the stream was silent).
    new_stream: bool,
    behind: Option<BehindRun>,
    /// The newest tool pose and the count of fresh records when it came.
    tool_pose: Option<(Isometry3<f64>, u64)>,
    fresh_records: u64,
    history: VecDeque<Sample>,
    /// A tare has been taken since start-up (the sensor's offset is then known).
    tared_once: bool,
    pub tare_policy: TarePolicy,
    pub counters: FtCounters,
}

impl FtSensorNode {
    pub fn new(config: FtConfig) -> Result<Self, String> {
        let filters = match config.low_pass {
            Some(fc) => Some([Biquad::low_pass(fc, config.sample_rate)?; 6]),
            None => None,
        };
        let tare_policy = TarePolicy::default();
        Ok(Self {
            config,
            bias: [0.0; 6],
            filters,
            last_sequence: None,
            last_device_sample: None,
            last_unbiased: None,
            new_stream: true,
            behind: None,
            tool_pose: None,
            fresh_records: 0,
            history: VecDeque::with_capacity(tare_policy.window),
            tared_once: false,
            tare_policy,
            counters: FtCounters::default(),
        })
    }

    /// The node with its own tare policy.
    pub fn with_tare_policy(mut self, policy: TarePolicy) -> Self {
        self.tare_policy = policy;
        self.history.reserve(policy.window);
        self
    }

    /// A start request went out, or the stream was silent long enough to have ended: the next record
    /// may restart the RDT sequence, and it is then the first of a new stream, not a replay.
    pub fn new_stream(&mut self) {
        self.new_stream = true;
    }

    /// The tool's pose in the world now (/lwr/ee_pose), for the tare's motion check.
    pub fn observe_tool_pose(&mut self, tool: &Isometry3<f64>) {
        self.tool_pose = Some((*tool, self.fresh_records));
    }

    /// A tare has been taken since start-up.
    pub fn tared(&self) -> bool {
        self.tared_once
    }

    /// The present software bias [N, N·m].
    pub fn bias(&self) -> [f64; 6] {
        self.bias
    }

    /// The tool's weight as the sensor sees it at orientation R_WS.
    pub fn tool_wrench(&self, orientation: &UnitQuaternion<f64>) -> [f64; 6] {
        let weight = orientation.inverse() * (self.config.tool.mass * self.config.gravity);
        let torque = self.config.tool.com().cross(&weight);
        [weight.x, weight.y, weight.z, torque.x, torque.y, torque.z]
    }

    /// Unchecked software tare: from now on the current reading, less the tool's weight at the current
    /// orientation, is the zero. Needs at least one record. The caller vouches that the hand is free and
    /// still (the in-process cell, tests); the /ft_sensor/bias service and the node's start-up tare use
    /// [`Self::checked_tare`].
    pub fn tare(&mut self, orientation: Option<&UnitQuaternion<f64>>) -> Result<[f64; 6], String> {
        let reading = self.last_unbiased.ok_or("no F/T record received yet")?;
        let tool = orientation.map(|o| self.tool_wrench(o)).unwrap_or([0.0; 6]);
        self.bias = std::array::from_fn(|i| reading[i] - tool[i]);
        self.tared_once = true;
        Ok(self.bias)
    }

    /// Why a tare now would be wrong, if it would: the checks of the [`TarePolicy`] over the last
    /// `window` fresh records. On success, the window's mean reading (bias not removed) for the tare.
    pub fn tare_check(&self, orientation: Option<&UnitQuaternion<f64>>) -> Result<[f64; 6], String> {
        let p = &self.tare_policy;
        let Some(orientation) = orientation else {
            return Err("no /lwr/ee_pose yet: the hand's weight cannot be told from a contact".into());
        };
        let n = p.window.max(2);
        if self.history.len() < n {
            return Err(format!("only {} of the {n} records the steadiness check needs", self.history.len()));
        }
        let window = self.history.iter().skip(self.history.len() - n);
        let bad = window.clone().filter(|s| !s.valid).count();
        if bad > 0 {
            return Err(format!("{bad} saturated or faulty records in the last {n}: the reading is not usable"));
        }
        let mut mean = [0.0; 6];
        for s in window.clone() {
            for (m, v) in mean.iter_mut().zip(&s.unbiased) {
                *m += v / n as f64;
            }
        }
        let tool = self.tool_wrench(orientation);
        // Contact: the force beyond the hand's weight, with the present tare (or none before the first).
        let (offset, limit, what) = if self.tared_once {
            (self.bias, p.max_force, "for a re-tare")
        } else {
            ([0.0; 6], p.max_offset, "for the first tare, whose sensor offset is unknown")
        };
        let force = Vector3::from_fn(|i, _| mean[i] - offset[i] - tool[i]).norm();
        if force.is_nan() || force > limit {
            return Err(format!(
                "{force:.1} N on the hand beyond its weight (at most {limit} N {what}): it is in contact or \
                 loaded; free the hand and tare again"
            ));
        }
        let spread = (0..3)
            .map(|i| (window.clone().map(|s| (s.unbiased[i] - mean[i]).powi(2)).sum::<f64>() / n as f64).sqrt())
            .fold(0.0, f64::max);
        if spread.is_nan() || spread > p.max_spread {
            return Err(format!(
                "the force is not steady: σ {spread:.3} N over the last {n} records (at most {} N)",
                p.max_spread
            ));
        }
        let poses: Option<Vec<Isometry3<f64>>> = window.map(|s| s.tool).collect();
        let Some(poses) = poses else {
            return Err(format!("no /lwr/ee_pose through the last {n} records: cannot tell whether the hand moves"));
        };
        let last = poses[poses.len() - 1];
        let travel = poses.iter().map(|q| (q.translation.vector - last.translation.vector).norm()).fold(0.0, f64::max);
        let turn = poses.iter().map(|q| q.rotation.angle_to(&last.rotation)).fold(0.0, f64::max);
        if !(travel <= p.max_motion && turn <= p.max_rotation) {
            return Err(format!(
                "the hand moves: {:.2} mm and {:.4} rad over the last {n} records (at most {} mm, {} rad)",
                travel * 1e3,
                turn,
                p.max_motion * 1e3,
                p.max_rotation
            ));
        }
        Ok(mean)
    }

    /// Software tare, refused in contact, in motion or on an unsteady reading (the /ft_sensor/bias
    /// service, the start-up tare): from now on the mean reading of the window, less the tool's weight
    /// at `orientation`, is the zero. The error says why it refused.
    pub fn checked_tare(&mut self, orientation: Option<&UnitQuaternion<f64>>) -> Result<[f64; 6], String> {
        match self.tare_check(orientation) {
            Ok(mean) => {
                let tool = self.tool_wrench(orientation.expect("checked"));
                self.bias = std::array::from_fn(|i| mean[i] - tool[i]);
                self.tared_once = true;
                Ok(self.bias)
            }
            Err(e) => {
                self.counters.tares_refused += 1;
                Err(format!("tare refused: {e}"))
            }
        }
    }

    /// Whether a record with this sequence number is the next of the stream; counts what it is not.
    fn sequence_fresh(&mut self, sequence: u32) -> bool {
        let Some(prev) = self.last_sequence else {
            self.new_stream = false;
            return true;
        };
        // Wrap-aware: the sequence is u32 and may wrap during a long stream.
        let step = sequence.wrapping_sub(prev) as i32;
        if step > 0 {
            self.counters.lost += (step - 1) as u64;
            self.new_stream = false;
            self.behind = None;
            return true;
        }
        if self.new_stream {
            // After a silence or a start request the box restarts the sequence: a new stream.
            self.counters.restarts += 1;
            self.new_stream = false;
            self.behind = None;
            return true;
        }
        // Behind: a duplicate or an older record, unless a run of them follow each other long enough
        // to be a stream the box restarted without a pause.
        let run = match self.behind {
            Some(r) if sequence.wrapping_sub(r.last) == 1 => BehindRun { last: sequence, length: r.length + 1 },
            _ => BehindRun { last: sequence, length: 1 },
        };
        if step < 0 && run.length >= RESTART_RUN {
            self.counters.restarts += 1;
            self.behind = None;
            return true;
        }
        self.behind = Some(run);
        if step == 0 {
            self.counters.duplicate += 1;
        } else {
            self.counters.out_of_order += 1;
        }
        false
    }

    /// Handles one real-time RDT datagram; `orientation` is the sensing frame's rotation in the world.
    pub fn handle(
        &mut self,
        datagram: &[u8],
        orientation: Option<&UnitQuaternion<f64>>,
    ) -> Result<FtOutput, WireError> {
        let record = match Record::decode(datagram) {
            Ok(r) => r,
            Err(e) => {
                self.counters.malformed += 1;
                return Err(e);
            }
        };
        self.counters.records += 1;
        let si = self.config.calibration.to_si(&record.counts);
        let range = &self.config.calibration.range;
        let saturated = record.status.is_saturated() || si.iter().zip(range).any(|(v, r)| v.abs() >= *r);
        let restarts = self.counters.restarts;
        let first = self.last_sequence.is_none();
        if !self.sequence_fresh(record.rdt_sequence) {
            let raw: [f64; 6] = std::array::from_fn(|i| si[i] - self.bias[i]);
            let compensated = orientation.map(|o| {
                let tool = self.tool_wrench(o);
                std::array::from_fn(|i| raw[i] - tool[i])
            });
            return Ok(FtOutput {
                raw,
                compensated,
                status: record.status,
                invalid: true,
                saturated,
                fresh: false,
                rdt_sequence: record.rdt_sequence,
            });
        }
        self.last_sequence = Some(record.rdt_sequence);
        // The box numbers its transducer's samples: a new stream may start anywhere, within one the
        // counter must advance (by more than one when the box streams slower than it samples).
        let new_stream = first || self.counters.restarts != restarts;
        let device_advanced =
            new_stream || self.last_device_sample.is_none_or(|last| record.ft_sequence.wrapping_sub(last) as i32 > 0);
        self.last_device_sample = Some(record.ft_sequence);
        self.counters.device_stalled += u64::from(!device_advanced);
        let invalid = saturated || record.status.is_error() || !device_advanced;
        self.counters.saturated += u64::from(saturated);
        self.counters.errors += u64::from(record.status.is_error());
        self.fresh_records += 1;
        let window = self.tare_policy.window.max(2) as u64;
        let tool = self.tool_pose.filter(|(_, at)| self.fresh_records - at <= window).map(|(pose, _)| pose);
        while self.history.len() >= self.tare_policy.window.max(2) {
            self.history.pop_front();
        }
        self.history.push_back(Sample { unbiased: si, valid: !invalid, tool });
        self.last_unbiased = Some(si);
        let mut raw: [f64; 6] = std::array::from_fn(|i| si[i] - self.bias[i]);
        if let Some(filters) = self.filters.as_mut() {
            for (v, f) in raw.iter_mut().zip(filters.iter_mut()) {
                *v = f.filter(*v);
            }
        }
        let compensated = orientation.map(|o| {
            let tool = self.tool_wrench(o);
            std::array::from_fn(|i| raw[i] - tool[i])
        });
        Ok(FtOutput {
            raw,
            compensated,
            status: record.status,
            invalid,
            saturated,
            fresh: true,
            rdt_sequence: record.rdt_sequence,
        })
    }
}

/// Records behind the stream's sequence, each following the one before, after which they are taken
/// as a stream the box restarted without a pause (50 ms at 1 kHz; a replay of old datagrams rarely
/// forms such a run, and if the box's stream is lost the periodic start request restarts it anyway).
pub const RESTART_RUN: usize = 50;

/// The lowest low-pass cut-off the node accepts \[Hz\]. The controller feeds the force forward, and a
/// 2nd-order Butterworth delays it by 0.225 / f_c; with more delay the hand slides across the surface
/// under quick presses (nodes/tests/deformation_controller.rs,
/// `the_lowest_low_pass_the_sensor_accepts_keeps_the_hand_in_place`).
pub const LOWEST_LOW_PASS: f64 = 100.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::params::NodeParams;
    use rand::SeedableRng;
    use softcontact_dynamics::lwr4;
    use softcontact_sim::{FtSensor, FtSensorConfig, Surface, SurfaceConfig};

    fn node() -> FtSensorNode {
        FtSensorNode::new(FtConfig {
            calibration: Calibration::gamma_si_130_10(),
            tool: lwr4::tool_load(),
            gravity: Vector3::new(0.0, 0.0, -9.81),
            low_pass: None,
            sample_rate: 1000.0,
        })
        .unwrap()
    }

    /// The hand facing down over a sponge, a simulated Gamma (noise, offset) on the flange, 1 kHz.
    struct Scene {
        sensor: FtSensor,
        surface: Surface,
        rng: rand::rngs::SmallRng,
        /// Height of the hand's sole above the sponge's top [m].
        height: f64,
        t: f64,
        node: FtSensorNode,
    }

    impl Scene {
        fn new() -> Self {
            let surface = Surface::new(SurfaceConfig::new(
                Vector3::zeros(),
                Vector3::new(0.0, 0.0, -1.0),
                softcontact_sim::sponge(),
            ))
            .unwrap();
            Self {
                sensor: FtSensor::new(FtSensorConfig::gamma(), lwr4::tool_load()),
                surface,
                rng: rand::rngs::SmallRng::seed_from_u64(7),
                height: 0.02,
                t: 0.0,
                node: node(),
            }
        }

        fn rotation() -> UnitQuaternion<f64> {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        }

        /// One millisecond with the hand moving at `speed` (down positive) and rotated by `turn` [rad]
        /// about the world z; returns the node's output.
        fn step(&mut self, speed: f64, turn: f64) -> FtOutput {
            let dt = 1e-3;
            self.height -= speed * dt;
            self.t += dt;
            let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * Self::rotation();
            let tool = Isometry3::from_parts(Vector3::new(0.0, 0.0, self.height).into(), rotation);
            let sensor = Isometry3::from_parts(
                (tool.translation.vector - rotation * Vector3::new(0.0, 0.0, 0.1)).into(),
                rotation,
            );
            let contact = self.surface.contact(&tool.translation.vector, &Vector3::new(0.0, 0.0, -speed), dt).unwrap();
            let record = self.sensor.record(
                &sensor,
                &tool,
                &contact.sensed_force,
                Vector3::new(0.0, 0.0, -9.81),
                self.t,
                &mut self.rng,
            );
            self.node.observe_tool_pose(&tool);
            self.node.handle(&record.encode(), Some(&rotation)).unwrap()
        }

        fn hold(&mut self, ms: usize) -> FtOutput {
            (0..ms).map(|_| self.step(0.0, 0.0)).last().unwrap()
        }

        fn world_fz(out: &FtOutput) -> f64 {
            let c = out.compensated.unwrap();
            (Self::rotation() * Vector3::new(c[0], c[1], c[2])).z
        }
    }

    #[test]
    fn a_tare_while_pushing_136_n_is_refused_and_one_in_the_air_is_taken() {
        let mut s = Scene::new();
        s.hold(300);
        let orientation = Scene::rotation();
        s.node.checked_tare(Some(&orientation)).expect("hand free and still: the first tare is taken");
        // Descend into the sponge at 20 mm/s until it pushes back with 136 N, then hold.
        let mut out = s.hold(1);
        let mut refused_moving = None;
        while Scene::world_fz(&out) < 136.0 {
            out = s.step(0.02, 0.0);
            if refused_moving.is_none() && s.height < -0.005 {
                refused_moving = Some(s.node.checked_tare(Some(&orientation)).unwrap_err());
            }
        }
        let moving = refused_moving.unwrap();
        assert!(moving.contains("in contact") || moving.contains("moves"), "{moving}");
        let out = s.hold(300);
        let pushing = Scene::world_fz(&out);
        assert!(pushing > 130.0, "{pushing}");
        let bias_before = s.node.bias();
        let e = s.node.checked_tare(Some(&orientation)).unwrap_err();
        assert!(e.starts_with("tare refused") && e.contains("in contact"), "{e}");
        assert_eq!(s.node.bias(), bias_before, "a refused tare changes nothing");
        assert_eq!(s.node.counters.tares_refused, 2);
        // Lift off and wait: the reading is zero, and a tare is taken again.
        while s.height < 0.02 {
            s.step(-0.05, 0.0);
        }
        let free = Scene::world_fz(&s.hold(300));
        assert!(free.abs() < 0.3, "after unloading the node reads {free} N");
        s.node.checked_tare(Some(&orientation)).unwrap();
        // What the unchecked tare does in contact (the finding): −136 N once the hand is free.
        while Scene::world_fz(&s.step(0.02, 0.0)) < 136.0 {}
        s.hold(300);
        s.node.tare(Some(&orientation)).unwrap();
        while s.height < 0.02 {
            s.step(-0.05, 0.0);
        }
        let thrown = Scene::world_fz(&s.hold(300));
        assert!(thrown < -120.0, "the unchecked tare in contact reads {thrown} N in the air");
    }

    #[test]
    fn a_tare_in_motion_unsteady_unposed_or_saturated_is_refused() {
        let o = Scene::rotation();
        // Too early: fewer records than the window.
        let mut s = Scene::new();
        s.hold(50);
        assert!(s.node.checked_tare(Some(&o)).unwrap_err().contains("only 50 of the 100"));
        // No pose of the hand.
        assert!(s.node.checked_tare(None).unwrap_err().contains("/lwr/ee_pose"));
        // Moving in the air at 10 mm/s (1 mm over the window).
        let mut s = Scene::new();
        s.hold(200);
        (0..100).for_each(|_| {
            s.step(0.01, 0.0);
        });
        let e = s.node.checked_tare(Some(&o)).unwrap_err();
        assert!(e.contains("the hand moves"), "{e}");
        // Turning in place by 0.05 rad over the window.
        let mut s = Scene::new();
        s.hold(200);
        for i in 0..100 {
            s.step(0.0, 5e-4 * i as f64);
        }
        let e = s.node.checked_tare(Some(&o)).unwrap_err();
        assert!(e.contains("the hand moves"), "{e}");
        // The pose stops coming: the node cannot tell motion.
        let mut s = Scene::new();
        s.hold(200);
        let rec = |seq: u32| Record { rdt_sequence: seq, ft_sequence: seq, ..Default::default() }.encode();
        for i in 0..150 {
            s.node.handle(&rec(1000 + i), Some(&o)).unwrap();
        }
        let e = s.node.checked_tare(Some(&o)).unwrap_err();
        assert!(e.contains("no /lwr/ee_pose through"), "{e}");
        // An unsteady reading with a small mean (a light contact coming and going, ±1 N at 20 Hz).
        let mut n = node();
        let counts = |f: [f64; 6]| Calibration::gamma_si_130_10().to_counts(&f).0;
        let tool = Isometry3::from_parts(Vector3::zeros().into(), o);
        let weight = n.tool_wrench(&o);
        for i in 0..200u32 {
            let wobble = (2.0 * std::f64::consts::PI * 20.0 * f64::from(i) * 1e-3).sin();
            let f: [f64; 6] = std::array::from_fn(|k| weight[k] + if k == 2 { wobble } else { 0.0 });
            n.observe_tool_pose(&tool);
            n.handle(
                &Record { rdt_sequence: i, ft_sequence: i, counts: counts(f), ..Default::default() }.encode(),
                Some(&o),
            )
            .unwrap();
        }
        let e = n.checked_tare(Some(&o)).unwrap_err();
        assert!(e.contains("not steady"), "{e}");
        // A saturated record in the window.
        let mut s = Scene::new();
        s.hold(200);
        // (In the stream's sequence: the simulated sensor's own record 200 is then a duplicate.)
        let sat = Record { rdt_sequence: 200, ft_sequence: 200, status: Status(0x8002_0000), ..Default::default() };
        s.node.handle(&sat.encode(), Some(&o)).unwrap();
        s.hold(20);
        assert!(s.node.checked_tare(Some(&o)).unwrap_err().contains("saturated"));
        s.hold(100);
        s.node.checked_tare(Some(&o)).unwrap();
    }

    fn record(seq: u32, fz: f64) -> [u8; softcontact_wire::rdt::RECORD_SIZE] {
        let counts = Calibration::gamma_si_130_10().to_counts(&[0.0, 0.0, fz, 0.0, 0.0, 0.0]).0;
        Record { rdt_sequence: seq, ft_sequence: seq, status: Status(0), counts }.encode()
    }

    #[test]
    fn duplicate_and_older_records_are_skipped_and_counted() {
        let mut n = node();
        for seq in [10, 11, 12] {
            assert!(n.handle(&record(seq, 1.0), None).unwrap().fresh);
        }
        let dup = n.handle(&record(12, 50.0), None).unwrap();
        assert!(!dup.fresh && dup.invalid, "a repeated record is not fresh");
        let old = n.handle(&record(5, 50.0), None).unwrap();
        assert!(!old.fresh && old.invalid, "an older record is not fresh");
        // The stream goes on where it was: nothing counted lost because of the stale ones.
        assert!(n.handle(&record(13, 1.0), None).unwrap().fresh);
        assert!(n.handle(&record(16, 1.0), None).unwrap().fresh);
        let c = n.counters;
        assert_eq!((c.duplicate, c.out_of_order, c.lost, c.records), (1, 1, 2, 7), "{c:?}");
        // A skipped record touches neither the filter nor the tare's reading.
        let mut f = FtSensorNode::new(FtConfig { low_pass: Some(50.0), ..n.config.clone() }).unwrap();
        for seq in 0..200 {
            f.handle(&record(seq, 2.0), None).unwrap();
        }
        f.handle(&record(150, 100.0), None).unwrap();
        let after = f.handle(&record(200, 2.0), None).unwrap();
        assert!((after.raw[2] - 2.0).abs() < 1e-6, "the filter saw the replay: {:?}", after.raw);
        f.tare(None).unwrap();
        assert!((f.bias()[2] - 2.0).abs() < 1e-6);
    }

    #[test]
    fn the_sequence_wraps_and_restarted_streams_are_new_not_replays() {
        let mut n = node();
        for seq in [u32::MAX - 1, u32::MAX, 0, 1] {
            assert!(n.handle(&record(seq, 1.0), None).unwrap().fresh, "{seq} across the wrap");
        }
        assert_eq!((n.counters.lost, n.counters.out_of_order), (0, 0));
        // A start request (or a silence): the box restarts at 0, a new stream.
        for seq in 2..1000 {
            n.handle(&record(seq, 1.0), None).unwrap();
        }
        n.new_stream();
        assert!(n.handle(&record(0, 1.0), None).unwrap().fresh);
        assert!(n.handle(&record(1, 1.0), None).unwrap().fresh);
        assert_eq!((n.counters.restarts, n.counters.out_of_order, n.counters.lost), (1, 0, 0));
        // Without one, a jump back is skipped...
        for seq in 2..1000 {
            n.handle(&record(seq, 1.0), None).unwrap();
        }
        assert!(!n.handle(&record(3, 1.0), None).unwrap().fresh);
        // ...unless a run of records follows on from it: the box restarted without a pause.
        let fresh: Vec<bool> =
            (4..4 + RESTART_RUN as u32).map(|s| n.handle(&record(s, 1.0), None).unwrap().fresh).collect();
        assert!(fresh[..RESTART_RUN - 2].iter().all(|f| !f) && fresh[RESTART_RUN - 1], "{fresh:?}");
        assert_eq!(n.counters.restarts, 2);
        assert!(n.handle(&record(4 + RESTART_RUN as u32, 1.0), None).unwrap().fresh);
    }

    /// The box streams on while its transducer's sample counter stands still or runs backwards (a
    /// stalled or restarted transducer): those records are not used for control, and counted; the
    /// stream is usable again once the counter advances, by one or by more (a box streaming slower than
    /// it samples), and a new stream may start its counter anywhere.
    #[test]
    fn records_whose_transducer_sample_counter_stands_still_or_runs_back_are_not_valid() {
        let mut n = node();
        let rec = |rdt: u32, ft: u32| {
            let counts = Calibration::gamma_si_130_10().to_counts(&[0.0, 0.0, 5.0, 0.0, 0.0, 0.0]).0;
            Record { rdt_sequence: rdt, ft_sequence: ft, status: Status(0), counts }.encode()
        };
        let valid = |n: &mut FtSensorNode, rdt: u32, ft: u32| {
            let out = n.handle(&rec(rdt, ft), None).unwrap();
            assert!(out.fresh, "record {rdt} is the stream's next");
            !out.invalid
        };
        assert!(valid(&mut n, 1, 500));
        assert!(valid(&mut n, 2, 501));
        assert!(valid(&mut n, 3, 505), "advancing by more than one");
        // Frozen for three records, then advancing again.
        assert!(!valid(&mut n, 4, 505) && !valid(&mut n, 5, 505) && !valid(&mut n, 6, 505));
        assert!(valid(&mut n, 7, 506));
        // Backwards (the transducer restarted behind a streaming box): one record refused, then its new
        // count advances.
        assert!(!valid(&mut n, 8, 3));
        assert!(valid(&mut n, 9, 4));
        assert_eq!(n.counters.device_stalled, 4, "{:?}", n.counters);
        // A new stream (a start request): its counter may start anywhere; it wraps forward.
        n.new_stream();
        assert!(valid(&mut n, 0, u32::MAX - 1));
        assert!(valid(&mut n, 1, u32::MAX) && valid(&mut n, 2, 0) && valid(&mut n, 3, 1));
        assert_eq!((n.counters.device_stalled, n.counters.saturated, n.counters.restarts), (4, 0, 1));
    }

    #[test]
    fn readings_at_or_beyond_the_calibrated_range_are_not_valid() {
        let mut n = node();
        let counts = |fz: f64| {
            let mut c = [0i32; 6];
            c[2] = (fz * 1e6) as i32;
            c
        };
        let out = |n: &mut FtSensorNode, seq: u32, fz: f64, status: u32| {
            n.handle(
                &Record { rdt_sequence: seq, ft_sequence: seq, status: Status(status), counts: counts(fz) }.encode(),
                None,
            )
            .unwrap()
        };
        assert!(!out(&mut n, 0, 399.0, 0).invalid);
        let at = out(&mut n, 1, 400.0, 0);
        assert!(at.invalid && at.saturated, "full scale without the status bit");
        assert!(out(&mut n, 2, -1000.0, 0).invalid, "beyond the range without the status bit");
        assert!(out(&mut n, 3, 10.0, 0x8002_0000).invalid, "the box's saturation bit");
        assert!(!out(&mut n, 4, 10.0, 0).invalid);
        assert_eq!(n.counters.saturated, 3);
    }

    #[test]
    fn parameters_out_of_their_physical_range_are_refused() {
        let ok = Params::default();
        ok.validate().unwrap();
        Params { low_pass: 100.0, ..Params::default() }.validate().unwrap();
        let bad = [
            ("rate", Params { rate: 1e300, ..Params::default() }),
            ("rate", Params { rate: 10.0, ..Params::default() }),
            ("rate", Params { rate: f64::NAN, ..Params::default() }),
            ("low_pass", Params { low_pass: 1e-300, ..Params::default() }),
            ("low_pass", Params { low_pass: 499.0, ..Params::default() }),
            ("low_pass", Params { low_pass: -1.0, ..Params::default() }),
            ("stale_after", Params { stale_after: 1e300, ..Params::default() }),
            ("stale_after", Params { stale_after: 1e-6, ..Params::default() }),
            ("tare_after", Params { tare_after: 1e300, ..Params::default() }),
            ("tare_after", Params { tare_after: f64::NEG_INFINITY, ..Params::default() }),
            ("exit_after_silence", Params { exit_after_silence: 1e300, ..Params::default() }),
            ("dead_after", Params { dead_after: f64::NAN, ..Params::default() }),
            ("dead_after", Params { dead_after: 0.0, ..Params::default() }),
            ("counts_per_force", Params { counts_per_force: 1e-300, ..Params::default() }),
            ("counts_per_torque", Params { counts_per_torque: 1e300, ..Params::default() }),
            ("bias_window", Params { bias_window: 0.001, ..Params::default() }),
            ("bias_window", Params { bias_window: 100.0, ..Params::default() }),
            ("bias_max_force", Params { bias_max_force: 1e300, ..Params::default() }),
            ("bias_max_force", Params { bias_max_force: 0.0, ..Params::default() }),
            ("bias_max_offset", Params { bias_max_offset: 1.0, ..Params::default() }),
            ("bias_max_offset", Params { bias_max_offset: f64::INFINITY, ..Params::default() }),
            ("bias_max_spread", Params { bias_max_spread: 100.0, ..Params::default() }),
            ("bias_max_motion", Params { bias_max_motion: 1.0, ..Params::default() }),
            ("bias_max_rotation", Params { bias_max_rotation: 0.0, ..Params::default() }),
        ];
        for (name, p) in bad {
            let e = p.validate().expect_err(name);
            assert!(e.contains(name), "{name}: {e}");
        }
        assert_eq!(Params::default().tare_policy(), TarePolicy::default());
    }
}
