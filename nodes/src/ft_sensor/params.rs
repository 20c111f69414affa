//! The `ft_sensor` node's parameters, each declared once.

use softcontact_wire::rdt::Calibration;

use super::{DEFAULT_HTTP_PORT, LOWEST_LOW_PASS, TarePolicy};

/// The `ft_sensor` node's parameters (config/ft_sensor.yaml). What each means and the values it takes are
/// declared once, in `declare` (`NodeParams`), which checks them at start-up and describes them over ROS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub sensor: std::net::SocketAddr,
    pub http_port: i64,
    pub http_timeout: f64,
    pub counts_per_force: f64,
    pub counts_per_torque: f64,
    pub force_unit: String,
    pub torque_unit: String,
    pub ranges: Vec<f64>,
    pub calibration_override: bool,
    pub low_pass: f64,
    pub rate: f64,
    pub stale_after: f64,
    pub tare_after: f64,
    pub bias_window: f64,
    pub bias_max_force: f64,
    pub bias_max_offset: f64,
    pub bias_max_spread: f64,
    pub bias_max_motion: f64,
    pub bias_max_rotation: f64,
    pub service_mapping: String,
    pub exit_after_silence: f64,
    pub dead_after: f64,
    pub use_sim_time: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            sensor: ([127, 0, 0, 1], 49152).into(),
            http_port: DEFAULT_HTTP_PORT as i64,
            http_timeout: 10.0,
            counts_per_force: 0.0,
            counts_per_torque: 0.0,
            force_unit: String::new(),
            torque_unit: String::new(),
            ranges: Vec::new(),
            calibration_override: false,
            low_pass: 0.0,
            rate: 1000.0,
            stale_after: 0.1,
            tare_after: 0.5,
            bias_window: 0.1,
            bias_max_force: 5.0,
            bias_max_offset: 10.0,
            bias_max_spread: 0.25,
            bias_max_motion: 5e-4,
            bias_max_rotation: 5e-3,
            service_mapping: "cyclone".into(),
            exit_after_silence: 0.0,
            dead_after: 2.0,
            use_sim_time: false,
        }
    }
}

impl Params {
    /// Where the box serves its settings page; None when it is not read (`http_port` 0).
    pub fn settings_page(&self) -> Option<std::net::SocketAddr> {
        (self.http_port != 0).then(|| std::net::SocketAddr::new(self.sensor.ip(), self.http_port as u16))
    }

    /// The tare checks of these parameters.
    pub fn tare_policy(&self) -> TarePolicy {
        TarePolicy {
            window: (self.bias_window * self.rate).round() as usize,
            max_offset: self.bias_max_offset,
            max_force: self.bias_max_force,
            max_spread: self.bias_max_spread,
            max_motion: self.bias_max_motion,
            max_rotation: self.bias_max_rotation,
        }
    }
}

impl crate::runtime::params::NodeParams for Params {
    fn declare(&self, d: &mut crate::runtime::params::Declarations) {
        self.declare_box(d);
        self.declare_stream(d);
        self.declare_tare(d);
        self.declare_node(d);
        d.use_sim_time();
    }
}

impl Params {
    /// The box: where it is, and its calibration where its settings page is not read or is overridden.
    fn declare_box(&self, d: &mut crate::runtime::params::Declarations) {
        d.any("sensor", "the Net F/T box's RDT address");
        d.integer(
            "http_port",
            self.http_port,
            (0, 65535),
            "the box's web server port, where the node reads its calibration, units, ranges and RDT rate (netftapi2.xml) at start-up; 0: not read, the calibration parameters below are then all needed",
        );
        d.within(
            "http_timeout",
            self.http_timeout,
            (0.1, 600.0),
            "how long start-up keeps asking the box for its settings page before the node refuses to start [s]",
        );
        // The box's counts per unit: 1 to 10⁹ covers every ATI calibration; 0 takes the box's.
        let counts = |v: f64| {
            if v == 0.0 || (1.0..=1e9).contains(&v) {
                Ok(())
            } else {
                Err(format!("must be 0 or lie in [1, 1e9], not {v}"))
            }
        };
        d.rule(
            "counts_per_force",
            counts(self.counts_per_force),
            "0 (the box's), or 1 to 1e9",
            "counts per force unit (the box's cfgcpf)",
        );
        d.rule(
            "counts_per_torque",
            counts(self.counts_per_torque),
            "0 (the box's), or 1 to 1e9",
            "counts per torque unit (cfgcpt)",
        );
        let unit = |force: &str, torque: &str| {
            Calibration::from_settings(1.0, 1.0, force, torque, [0.0; 6]).map(|_| ()).map_err(|e| e.to_string())
        };
        let force_unit = if self.force_unit.is_empty() { Ok(()) } else { unit(&self.force_unit, "Nm") };
        let torque_unit = if self.torque_unit.is_empty() { Ok(()) } else { unit("N", &self.torque_unit) };
        d.rule(
            "force_unit",
            force_unit,
            "\"\" (the box's), or N, lbf, klbf, kN, kgf, gf",
            "the force unit of the counts (scfgfu)",
        );
        d.rule(
            "torque_unit",
            torque_unit,
            "\"\" (the box's), or Nm, N-m, Nmm, N-mm, lbf-in, lbf-ft, kgf-cm, kN-m",
            "the torque unit of the counts (scfgtu)",
        );
        let ranges = if self.ranges.is_empty()
            || (self.ranges.len() == 6 && self.ranges.iter().all(|r| r.is_finite() && *r > 0.0 && *r <= 1e6))
        {
            Ok(())
        } else {
            Err(format!("must be empty or six positive ranges, not {:?}", self.ranges))
        };
        d.rule(
            "ranges",
            ranges,
            "[] (the box's), or six values in (0, 1e6]",
            "the calibrated range of Fx Fy Fz Tx Ty Tz in the configured units (cfgmr): a reading at or beyond it is not used",
        );
        d.any(
            "calibration_override",
            "true: calibration parameters that are set win over the box's page where they differ (the node otherwise refuses to start)",
        );
    }

    /// The RDT stream: its rate, filter and staleness.
    fn declare_stream(&self, d: &mut crate::runtime::params::Declarations) {
        // The Net F/T streams RDT at up to 7 kHz; below 100 Hz a force loop has nothing to run on.
        d.within("rate", self.rate, (100.0, 7000.0), "the box's RDT output rate [Hz]");
        let low_pass =
            if self.low_pass == 0.0 || (self.low_pass >= LOWEST_LOW_PASS && self.low_pass <= 0.45 * self.rate) {
                Ok(())
            } else {
                Err(format!("must be 0 or lie in [{LOWEST_LOW_PASS}, {}] Hz, not {}", 0.45 * self.rate, self.low_pass))
            };
        let range = format!("0 (none), or from {LOWEST_LOW_PASS} Hz to 0.45 × rate");
        d.rule(
            "low_pass",
            low_pass,
            &range,
            "low-pass cut-off [Hz] (a lower cut-off delays the force the controller feeds forward)",
        );
        d.within(
            "stale_after",
            self.stale_after,
            (2.0 / self.rate, 1.0),
            "data older than this is stale [s] (at least two records)",
        );
    }

    /// The tare: when, and the checks that refuse one taken in contact or in motion.
    fn declare_tare(&self, d: &mut crate::runtime::params::Declarations) {
        let tare_after = if !self.tare_after.is_finite() || self.tare_after > 60.0 {
            Err(format!("must be finite and at most 60 s, not {}", self.tare_after))
        } else {
            Ok(())
        };
        d.rule("tare_after", tare_after, "at most 60 s; negative: never", "tare once, this long after the stream and the hand's orientation are both there [s]; negative: never (then call /ft_sensor/bias); /ft_sensor/wrench is published only once tared, and a refused start-up tare is retried");
        d.within(
            "bias_window",
            self.bias_window,
            ((10.0 / self.rate).max(0.01), 2.0),
            "the tare's checks look back this long [s] (at least 10 records)",
        );
        d.within("bias_max_force", self.bias_max_force, (0.1, 20.0), "a tare is refused when the force beyond the hand's weight, with the present tare, exceeds this: the hand is in contact or loaded [N]");
        d.within("bias_max_offset", self.bias_max_offset, (self.bias_max_force, 50.0), "the same for the node's first tare, when the sensor's own offset is unknown: set it above the box's unloaded reading [N] (at least bias_max_force)");
        d.within("bias_max_spread", self.bias_max_spread, (0.01, 2.0), "a tare is refused when a force axis' standard deviation over the window exceeds this (a contact coming or going, vibration) [N]");
        d.within(
            "bias_max_motion",
            self.bias_max_motion,
            (1e-5, 0.01),
            "a tare is refused when the tool travelled more than this over the window [m]",
        );
        d.within("bias_max_rotation", self.bias_max_rotation, (1e-4, 0.1), "... or turned more than this [rad]");
    }

    /// The node: its service mapping and liveness.
    fn declare_node(&self, d: &mut crate::runtime::params::Declarations) {
        d.service_mapping(&self.service_mapping, "service mapping of the peers' middleware for /ft_sensor/bias");
        d.within(
            "exit_after_silence",
            self.exit_after_silence,
            (0.0, 86_400.0),
            "stop after this long without a record (0: wait forever) [s]",
        );
        crate::runtime::liveness::declare_dead_after(
            d,
            self.dead_after,
            0.0,
            "/lwr/ee_pose silent this long after it flowed: the hand's orientation is unknown, /ft_sensor/wrench is withheld and /diagnostics says ERROR until poses flow again [s]",
        );
    }
}
