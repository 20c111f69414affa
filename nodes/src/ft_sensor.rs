//! The F/T sensor node's core: RDT records to SI wrenches in the sensing frame, a software tare, tool
//! gravity compensation from the sensor's orientation, an optional Butterworth low-pass, and counts of
//! lost, repeated and saturated records.
//!
//! Model (sensor frame S, world W, tool mass m with centre c in S, gravity g_W, rotation R_WS):
//! measured = external + (R_WSᵀ m g_W, c × R_WSᵀ m g_W) + bias. `wrench_raw` removes the bias,
//! `wrench` also the tool's weight.

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_dynamics::BodyInertia;
use softcontact_wire::WireError;
use softcontact_wire::rdt::{self, Calibration, Record, Status};

#[derive(Debug, Clone, PartialEq)]
pub struct FtConfig {
    pub calibration: Calibration,
    /// The tool beyond the sensing frame (mass, centre of mass in the sensing frame).
    pub tool: BodyInertia,
    pub gravity: Vector3<f64>,
    /// Low-pass cut-off [Hz] at `sample_rate`; `None` for no filter.
    pub low_pass: Option<f64>,
    pub sample_rate: f64,
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
    /// The sample must not be used for control (saturation or a device error).
    pub invalid: bool,
    pub rdt_sequence: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FtCounters {
    pub records: u64,
    pub lost: u64,
    pub out_of_order: u64,
    pub malformed: u64,
    pub saturated: u64,
    pub errors: u64,
}

pub struct FtSensorNode {
    config: FtConfig,
    bias: [f64; 6],
    filters: Option<[Biquad; 6]>,
    last_sequence: Option<u32>,
    last_unbiased: Option<[f64; 6]>,
    pub counters: FtCounters,
}

impl FtSensorNode {
    pub fn new(config: FtConfig) -> Result<Self, String> {
        let filters = match config.low_pass {
            Some(fc) => Some([Biquad::low_pass(fc, config.sample_rate)?; 6]),
            None => None,
        };
        Ok(Self {
            config,
            bias: [0.0; 6],
            filters,
            last_sequence: None,
            last_unbiased: None,
            counters: FtCounters::default(),
        })
    }

    /// The tool's weight as the sensor sees it at orientation R_WS.
    pub fn tool_wrench(&self, orientation: &UnitQuaternion<f64>) -> [f64; 6] {
        let weight = orientation.inverse() * (self.config.tool.mass * self.config.gravity);
        let torque = self.config.tool.com().cross(&weight);
        [weight.x, weight.y, weight.z, torque.x, torque.y, torque.z]
    }

    /// Software tare (the /ft_sensor/bias service): from now on the current reading, less the tool's
    /// weight at the current orientation, is the zero. Needs at least one record.
    pub fn tare(&mut self, orientation: Option<&UnitQuaternion<f64>>) -> Result<[f64; 6], String> {
        let reading = self.last_unbiased.ok_or("no F/T record received yet")?;
        let tool = orientation.map(|o| self.tool_wrench(o)).unwrap_or([0.0; 6]);
        self.bias = std::array::from_fn(|i| reading[i] - tool[i]);
        Ok(self.bias)
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
        if let Some(prev) = self.last_sequence {
            let gap = rdt::sequence_gap(prev, record.rdt_sequence);
            if gap < 0 {
                self.counters.out_of_order += 1;
            } else {
                self.counters.lost += gap as u64;
            }
        }
        self.last_sequence = Some(record.rdt_sequence);
        let invalid = record.status.is_saturated() || record.status.is_error();
        self.counters.saturated += u64::from(record.status.is_saturated());
        self.counters.errors += u64::from(record.status.is_error());
        let si = self.config.calibration.to_si(&record.counts);
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
        Ok(FtOutput { raw, compensated, status: record.status, invalid, rdt_sequence: record.rdt_sequence })
    }
}

/// The `ft_sensor` node's parameters (config/ft_sensor.yaml).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The Net F/T box's RDT address.
    pub sensor: std::net::SocketAddr,
    /// Counts per force unit and per torque unit, and the units, as the box's netftapi2.xml gives them.
    pub counts_per_force: f64,
    pub counts_per_torque: f64,
    pub force_unit: String,
    pub torque_unit: String,
    /// Low-pass cut-off [Hz]; 0 for none.
    pub low_pass: f64,
    /// The box's RDT output rate [Hz].
    pub rate: f64,
    /// Data older than this is stale [s].
    pub stale_after: f64,
    /// Tare once, this long after the stream and the hand's orientation are both there [s]; negative:
    /// never (then call /ft_sensor/bias). /ft_sensor/wrench is published only once tared.
    pub tare_after: f64,
    /// Service mapping of the peers' middleware: cyclone, enhanced or basic.
    pub service_mapping: String,
    /// Stop after this many seconds without a record (0: wait forever).
    pub exit_after_silence: f64,
    /// Stamp messages with the simulated time of /clock.
    pub use_sim_time: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            sensor: ([127, 0, 0, 1], 49152).into(),
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: "N".into(),
            torque_unit: "Nm".into(),
            low_pass: 0.0,
            rate: 1000.0,
            stale_after: 0.1,
            tare_after: 0.5,
            service_mapping: "cyclone".into(),
            exit_after_silence: 0.0,
            use_sim_time: false,
        }
    }
}

impl Params {
    pub fn calibration(&self) -> Result<Calibration, String> {
        Calibration::from_settings(
            self.counts_per_force,
            self.counts_per_torque,
            &self.force_unit,
            &self.torque_unit,
            Calibration::gamma_si_130_10().range,
        )
        .map_err(|e| e.to_string())
    }
}

impl crate::params::NodeParams for Params {
    fn validate(&self) -> Result<(), String> {
        self.calibration()?;
        if !(self.rate.is_finite() && (1.0..=7000.0).contains(&self.rate)) {
            return Err(format!("rate must lie in 1..=7000 Hz (RDT), not {}", self.rate));
        }
        if !(self.low_pass.is_finite() && self.low_pass >= 0.0 && self.low_pass < self.rate / 2.0) {
            return Err(format!("low_pass must lie in [0, rate/2), not {}", self.low_pass));
        }
        if !(self.stale_after.is_finite() && self.stale_after > 0.0) {
            return Err("stale_after must be positive".into());
        }
        if !self.tare_after.is_finite() || !self.exit_after_silence.is_finite() || self.exit_after_silence < 0.0 {
            return Err("tare_after must be finite and exit_after_silence ≥ 0".into());
        }
        crate::ros::service_mapping(&self.service_mapping).map_err(|e| e.to_string())?;
        Ok(())
    }
}
