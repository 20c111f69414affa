//! The simulated cell behind real sockets: the KRC's side of FRI (a measurement to the remote every
//! cycle, its answer applied), the Net F/T's side of RDT (records streamed on request, one a datagram or
//! the box's buffer size a datagram, biased on the reading of the moment) and the box's settings page over
//! HTTP (`netftapi2.xml`: its calibration, units and ranges), paced in real time against deadlines.
//! Optional loss in both directions for robustness tests.

use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::ContactModel;
use softcontact_sim::Simulator;
use softcontact_wire::netft_xml::{self, BoxSettings};
use softcontact_wire::{fri, rdt};

#[derive(Debug, Clone)]
pub struct SimArmConfig {
    pub fri_bind: SocketAddr,
    /// Where the driver listens (the KRC's `FRIHOST`/`FRISOCK`).
    pub fri_remote: SocketAddr,
    pub rdt_bind: SocketAddr,
    /// Where the box serves its settings page (`netftapi2.xml`); None: no web server.
    pub http_bind: Option<SocketAddr>,
    /// The box's transducer and configuration as its settings page gives them (its calibration is the
    /// one the records are counted in; its buffer size is what buffered mode packs a datagram with).
    pub box_settings: BoxSettings,
    /// Fractions of measurements (KRC → remote) and of commands (remote → KRC) lost, once the KRC is in
    /// command mode (a KRC will not enter command mode over a lossy link).
    pub measurement_loss: f64,
    pub command_loss: f64,
    /// RDT records per second while streaming (the box's `comrdtrate`, 1–7000 Hz).
    pub rdt_rate: f64,
    pub pacing: Pacing,
    pub seed: u64,
}

/// How cycles follow each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// One cycle per FRI period of wall time, as the KRC does. The KRC waits 0.9 of a cycle for the
    /// remote's answer; `answer_wait`, if longer, is how long the simulated one waits instead, so that a
    /// remote on a host without real-time scheduling pauses the simulated arm rather than ending command
    /// mode (answers later than 0.9 of a cycle are counted as `late_answers`).
    RealTime { answer_wait: Duration },
    /// The next cycle as soon as the remote has answered (or after `timeout`): faster than real time,
    /// with simulated time published on /clock by the caller.
    Lockstep { timeout: Duration },
}

/// What the cell counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimArmStats {
    pub cycles: u64,
    pub measurements_dropped: u64,
    pub commands_dropped: u64,
    pub malformed: u64,
    pub overruns: u64,
    /// Answers later than 0.9 of a cycle after their measurement (missed cycles on a real KRC), taken
    /// because `answer_wait` allowed them.
    pub late_answers: u64,
    pub records_sent: u64,
}

pub struct SimArmServer {
    sim: Simulator,
    fri: UdpSocket,
    rdt: UdpSocket,
    http: Option<Arc<tiny_http::Server>>,
    config: SimArmConfig,
    stream_to: Option<SocketAddr>,
    remaining: Option<u32>,
    /// Buffered mode: the records of the datagram being filled.
    buffered: Option<Vec<rdt::Record>>,
    rng: SmallRng,
    records_due: f64,
    pub stats: SimArmStats,
}

impl SimArmServer {
    pub fn bind(sim: Simulator, config: SimArmConfig) -> std::io::Result<Self> {
        let invalid = |what: &str| std::io::Error::new(std::io::ErrorKind::InvalidInput, what.to_string());
        if !(1.0..=7000.0).contains(&config.rdt_rate) {
            return Err(invalid("RDT rate must lie in 1..=7000 Hz"));
        }
        if !config.box_settings.rdt_buffer.is_some_and(|n| (1..=40).contains(&n)) {
            return Err(invalid("the box's RDT buffer size must lie in 1..=40 records"));
        }
        let page = config.box_settings.calibration().map_err(|e| invalid(&e.to_string()))?;
        if page != *sim.sensor.calibration() {
            return Err(invalid("the box's settings page must give the calibration its records are counted in"));
        }
        let fri = UdpSocket::bind(config.fri_bind)?;
        fri.set_nonblocking(true)?;
        let rdt = UdpSocket::bind(config.rdt_bind)?;
        rdt.set_nonblocking(true)?;
        let http = match config.http_bind {
            Some(addr) => Some(Arc::new(tiny_http::Server::http(addr).map_err(std::io::Error::other)?)),
            None => None,
        };
        if let Some(server) = &http {
            serve_settings_page(server.clone(), config.box_settings.to_xml());
        }
        let rng = SmallRng::seed_from_u64(config.seed ^ 0x5eed);
        Ok(Self {
            sim,
            fri,
            rdt,
            http,
            config,
            stream_to: None,
            remaining: None,
            buffered: None,
            rng,
            records_due: 0.0,
            stats: SimArmStats::default(),
        })
    }

    pub fn fri_addr(&self) -> std::io::Result<SocketAddr> {
        self.fri.local_addr()
    }

    pub fn rdt_addr(&self) -> std::io::Result<SocketAddr> {
        self.rdt.local_addr()
    }

    /// Where the box's settings page is served, if it is.
    pub fn http_addr(&self) -> Option<SocketAddr> {
        self.http.as_ref().and_then(|h| h.server_addr().to_ip())
    }

    pub fn simulator(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    fn serve_rdt_requests(&mut self) {
        let mut buf = [0u8; 64];
        while let Ok((n, from)) = self.rdt.recv_from(&mut buf) {
            match rdt::Request::decode(&buf[..n]) {
                Ok(req) => match req.command {
                    rdt::RdtCommand::StartRealTime | rdt::RdtCommand::StartBuffered => {
                        // A newer start steals the stream.
                        self.stream_to = Some(from);
                        self.remaining = (req.sample_count > 0).then_some(req.sample_count);
                        self.buffered = (req.command == rdt::RdtCommand::StartBuffered).then(Vec::new);
                        self.sim.sensor.start_stream();
                    }
                    rdt::RdtCommand::Stop => self.stream_to = None,
                    rdt::RdtCommand::SetBias => self.sim.ft_set_bias(),
                    _ => {}
                },
                Err(_) => self.stats.malformed += 1,
            }
        }
    }

    /// Runs cycles paced in real time until `observe` returns false. `observe` sees the simulator after
    /// every cycle (the truth a test compares against).
    pub fn run(&mut self, mut observe: impl FnMut(&mut Simulator) -> bool) -> std::io::Result<SimArmStats> {
        let cycle = Duration::from_secs_f64(self.sim.krc_cycle());
        let mut next = Instant::now();
        let mut box_clock: Option<Instant> = None;
        let mut buf = [0u8; 2048];
        loop {
            let m = self.sim.measurement();
            let lossy = m.intf.state == fri::InterfaceState::Command;
            if lossy && self.rng.random::<f64>() < self.config.measurement_loss {
                self.stats.measurements_dropped += 1;
            } else {
                self.fri.send_to(&m.encode(), self.config.fri_remote)?;
            }
            self.take_answer(&m, lossy, cycle, &mut buf)?;
            self.serve_rdt_requests();
            self.sim.step_cycle().map_err(std::io::Error::other)?;
            // The box streams on its own clock: in real time by the wall clock (a late cycle costs no
            // records), in lockstep by the simulated time.
            let elapsed = match self.config.pacing {
                Pacing::RealTime { .. } => {
                    let now = Instant::now();
                    let dt = now.duration_since(*box_clock.get_or_insert(now)).as_secs_f64();
                    box_clock = Some(now);
                    dt
                }
                Pacing::Lockstep { .. } => self.sim.krc_cycle(),
            };
            self.stream_records(elapsed)?;
            self.stats.cycles += 1;
            if !observe(&mut self.sim) {
                return Ok(self.stats);
            }
            if matches!(self.config.pacing, Pacing::Lockstep { .. }) {
                continue;
            }
            next += cycle;
            let now = Instant::now();
            if now < next {
                std::thread::sleep(next - now);
            } else {
                self.stats.overruns += 1;
                if now - next > cycle * 10 {
                    next = now; // fell far behind (debugger, overload): resynchronise instead of bursting
                }
            }
        }
    }

    /// Takes the remote's answers until the one for `m` arrives or the pacing's deadline passes (0.9 of
    /// a cycle from the send in real time): each is applied as the KRC applies it, a late one counted.
    fn take_answer(
        &mut self,
        m: &fri::Measurement,
        lossy: bool,
        cycle: Duration,
        buf: &mut [u8; 2048],
    ) -> std::io::Result<()> {
        // Take answers until one for this measurement arrives or 0.9 of a cycle has passed since it
        // was sent (measured from the send, so that one late cycle does not also cost the next).
        let sent = Instant::now();
        let on_time = sent + cycle.mul_f64(0.9);
        let deadline = match self.config.pacing {
            Pacing::RealTime { answer_wait } => on_time.max(sent + answer_wait),
            Pacing::Lockstep { timeout } => sent + timeout,
        };
        // Past the deadline, what already arrived is still read (a few datagrams at most): when this
        // process, not the remote, was late, the answer is in the socket and counts as on time.
        let mut read_after_deadline = 0;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                read_after_deadline += 1;
                if read_after_deadline > READ_AFTER_DEADLINE_AT_MOST {
                    break;
                }
            }
            if !softcontact_nodes::runtime::udp::wait_readable(&self.fri, left)? {
                break;
            }
            match self.fri.recv_from(&mut buf[..]) {
                Ok((n, _)) => match fri::Command::decode(&buf[..n]) {
                    Ok(cmd) => {
                        if lossy && self.rng.random::<f64>() < self.config.command_loss {
                            self.stats.commands_dropped += 1;
                            continue;
                        }
                        let answered = cmd.header.refl_seq == m.header.send_seq;
                        self.sim.command(&cmd);
                        if answered {
                            let late =
                                matches!(self.config.pacing, Pacing::RealTime { .. }) && Instant::now() > on_time;
                            self.stats.late_answers += u64::from(late);
                            break;
                        }
                    }
                    Err(_) => self.stats.malformed += 1,
                },
                Err(e) if softcontact_nodes::runtime::udp::no_datagram(&e) => continue,
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// The box's records due after `elapsed` seconds, sent to the streaming client (one a datagram, or
    /// buffered as the box is set).
    fn stream_records(&mut self, elapsed: f64) -> std::io::Result<()> {
        self.records_due = (self.records_due + self.config.rdt_rate * elapsed).min(RECORDS_DUE_AT_MOST);
        while self.records_due >= 1.0 {
            self.records_due -= 1.0;
            let Some(to) = self.stream_to else { continue };
            let record = self.sim.ft_record();
            let last = self.remaining.as_mut().is_some_and(|left| {
                *left -= 1;
                *left == 0
            });
            let per_datagram = self.config.box_settings.rdt_buffer.unwrap_or(1) as usize;
            match self.buffered.as_mut() {
                None => {
                    self.rdt.send_to(&record.encode(), to)?;
                    self.stats.records_sent += 1;
                }
                Some(pending) => {
                    pending.push(record);
                    if pending.len() == per_datagram || last {
                        self.rdt.send_to(&rdt::Record::encode_buffered(pending), to)?;
                        self.stats.records_sent += pending.len() as u64;
                        pending.clear();
                    }
                }
            }
            if last {
                self.stream_to = None;
            }
        }
        Ok(())
    }
}

/// Datagrams read after a cycle's answer deadline that were already waiting in the socket.
const READ_AFTER_DEADLINE_AT_MOST: usize = 8;
/// Records the box sends at once after the cell stalled (a debugger, an overloaded machine): a stall's
/// backlog beyond this is dropped, as a box's socket buffer would.
const RECORDS_DUE_AT_MOST: f64 = 50.0;

/// Serves the box's settings page on its own thread for the server's life: `GET /netftapi2.xml` answers
/// the page, anything else 404.
fn serve_settings_page(server: Arc<tiny_http::Server>, page: String) {
    std::thread::Builder::new()
        .name("netft_http".into())
        .spawn(move || {
            for request in server.incoming_requests() {
                let path = request.url().split('?').next().unwrap_or_default();
                let response = if *request.method() == tiny_http::Method::Get && path == netft_xml::PATH {
                    let xml = "Content-Type: text/xml".parse::<tiny_http::Header>().expect("a valid header");
                    tiny_http::Response::from_string(page.clone()).with_header(xml)
                } else {
                    tiny_http::Response::from_string("not found").with_status_code(404)
                };
                let _ = request.respond(response);
            }
        })
        .expect("a thread for the settings page");
}

impl Drop for SimArmServer {
    fn drop(&mut self) {
        if let Some(server) = &self.http {
            server.unblock();
        }
    }
}

/// The simulated surface under the hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceKind {
    /// The force-control paper's surfaces as pure laws (Azad-Featherstone, Kelvin-Voigt).
    Sponge,
    Dice,
    /// The same with the effects no model kind has, and a drifting sensor (`softcontact demo`).
    LabSponge,
    LabDice,
    None,
}

/// The transducer of the simulated Net F/T box, and the settings page it serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transducer {
    /// Gamma SI-130-10 in N and N·m (the cell's sensor).
    Gamma,
    /// Nano17 SI-25-0.25 in N and N·mm.
    Nano17,
    /// Mini45 US-60-80 in lbf and lbf-in.
    Mini45,
}

impl Transducer {
    /// The box's settings page at this RDT rate and buffer size.
    pub fn settings(self, rdt_rate: f64, rdt_buffer: u32) -> BoxSettings {
        let page = match self {
            Self::Gamma => BoxSettings::gamma_si_130_10(),
            Self::Nano17 => BoxSettings::nano17_si_25_025(),
            Self::Mini45 => BoxSettings::mini45_us_60_80(),
        };
        BoxSettings { rdt_rate: Some(rdt_rate.round() as u32), rdt_buffer: Some(rdt_buffer), ..page }
    }
}

/// The KRL program the simulated KRC runs (`krl/README.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KrlProgramKind {
    /// The shipped `krl/softcontact.src`.
    Softcontact,
    /// The LWR ROS 1 stack's `ros_control.src`: position control on its first start.
    RosControl,
    /// A program of the cell's own that only ever starts position control.
    PositionOnly,
}

impl KrlProgramKind {
    pub fn program(self) -> softcontact_sim::KrlProgram {
        match self {
            Self::Softcontact => softcontact_sim::KrlProgram::Softcontact,
            Self::RosControl => softcontact_sim::KrlProgram::RosControl,
            Self::PositionOnly => softcontact_sim::KrlProgram::Fixed(softcontact_sim::STRATEGY_POSITION),
        }
    }
}

/// The `sim_arm` node's parameters (config/sim_arm.yaml). What each means and the values it takes are
/// declared once, in `declare` (`NodeParams`), which checks them at start-up and describes them over ROS.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub fri_remote: SocketAddr,
    pub fri_bind: SocketAddr,
    pub rdt_bind: SocketAddr,
    pub http_bind: SocketAddr,
    pub transducer: Transducer,
    pub rdt_buffer: i64,
    pub surface: SurfaceKind,
    pub surface_model: String,
    pub seconds: f64,
    pub drop_rate: f64,
    pub rdt_rate: f64,
    pub lockstep: bool,
    pub seed: u64,
    pub krl_program: KrlProgramKind,
    pub fri_cycle: f64,
    pub answer_wait: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            fri_remote: ([127, 0, 0, 1], 49938).into(),
            fri_bind: ([127, 0, 0, 1], 0).into(),
            rdt_bind: ([127, 0, 0, 1], 49152).into(),
            http_bind: ([127, 0, 0, 1], softcontact_nodes::ft_sensor::DEFAULT_HTTP_PORT).into(),
            transducer: Transducer::Gamma,
            rdt_buffer: 1,
            surface: SurfaceKind::Sponge,
            surface_model: String::new(),
            seconds: 0.0,
            drop_rate: 0.0,
            rdt_rate: 1000.0,
            lockstep: false,
            seed: 1,
            krl_program: KrlProgramKind::Softcontact,
            fri_cycle: 0.001,
            answer_wait: 0.02,
        }
    }
}

impl Params {
    /// The contact model of `surface_model`, read and checked (None: the preset's); an error names the
    /// file, not the parameter.
    pub fn surface_model(&self) -> Result<Option<ContactModel>, String> {
        if self.surface_model.is_empty() {
            return Ok(None);
        }
        if self.surface == SurfaceKind::None {
            return Err("surface_model given with surface none".into());
        }
        let text = softcontact_nodes::runtime::params::read_small(std::path::Path::new(&self.surface_model))
            .map_err(|e| format!("{}: {e}", self.surface_model))?;
        let model = ContactModel::from_yaml(&text).map_err(|e| format!("{}: {e}", self.surface_model))?;
        model.plausible().map_err(|e| format!("{}: {e}", self.surface_model))?;
        Ok(Some(model))
    }
}

impl softcontact_nodes::runtime::params::NodeParams for Params {
    fn declare(&self, d: &mut softcontact_nodes::runtime::params::Declarations) {
        d.any("fri_remote", "where the FRI driver listens (the KRC's FRIHOST:FRISOCK)");
        d.any("fri_bind", "the simulated KRC's own FRI address");
        d.any("rdt_bind", "the simulated Net F/T box's RDT address");
        d.any("http_bind", "where the simulated box serves its settings page, netftapi2.xml (port 0: no web server)");
        d.any("transducer", "the simulated box's transducer and calibration: gamma (SI-130-10, N, N·m), nano17 (SI-25-0.25, N, N·mm) or mini45 (US-60-80, lbf, lbf-in)");
        d.integer("rdt_buffer", self.rdt_buffer, (1, 40), "records a datagram in buffered mode (the box's comrdtbsiz)");
        d.any(
            "surface",
            "the simulated surface, its preset law, place and sensor: sponge, dice, lab_sponge or lab_dice (with relaxation, hysteresis and a drifting sensor), or none (free space)",
        );
        d.any(
            "krl_program",
            "the KRL program the simulated KRC runs: softcontact (shipped), ros_control (position control on its first start) or position_only",
        );
        let model = self.surface_model().map(|_| ());
        d.rule("surface_model", model, "\"\" or a readable contact model file, with a surface", "a contact model file (the model YAML `softcontact discrepancy` and `identify` write) for the surface's law and effects in place of the preset's; \"\" keeps the preset");
        d.within(
            "seconds",
            self.seconds,
            (0.0, f64::MAX),
            "stop after this much simulated time (0: run until stopped) [s]",
        );
        let drop_rate = if (0.0..1.0).contains(&self.drop_rate) {
            Ok(())
        } else {
            Err(format!("must lie in [0, 1), not {}", self.drop_rate))
        };
        d.rule("drop_rate", drop_rate, "[0, 1)", "fraction of FRI datagrams lost once commanding, in each direction");
        d.within(
            "rdt_rate",
            self.rdt_rate,
            (1.0, 7000.0),
            "RDT records per second while streaming (the box's comrdtrate) [Hz]",
        );
        d.any(
            "lockstep",
            "faster than real time: step as soon as the driver has answered, and publish the simulated time on /clock",
        );
        d.any("seed", "seed of the simulated noise and losses");
        let whole_ms = (self.fri_cycle * 1e3 - (self.fri_cycle * 1e3).round()).abs() < 1e-9;
        let cycle = if whole_ms && (0.001..=0.1).contains(&self.fri_cycle) {
            Ok(())
        } else {
            Err(format!("must be 1 to 100 whole milliseconds, not {} s", self.fri_cycle))
        };
        d.rule(
            "fri_cycle",
            cycle,
            "0.001 to 0.1 s in whole ms",
            "the FRI cycle the KRL program opens (friOpen(1): 0.001 s; ros_control.src's friOpen(2): 0.002 s); the driver applies torque at 1 to 10 ms [s]",
        );
        d.within(
            "answer_wait",
            self.answer_wait,
            (0.0, 1.0),
            "how long the simulated KRC waits for the driver's answer to a measurement before counting the cycle missed (a real KRC: 0.9 of its cycle, which any value below that gives); longer lets a host without real-time scheduling run the cell, a late answer pausing the simulated arm, counted as late_answers [s]",
        );
    }
}

/// The simulator's parameter reference (`config/sim_arm.yaml`, its section of `docs/parameters.md`).
pub fn reference() -> softcontact_nodes::runtime::params::reference::NodeReference {
    softcontact_nodes::runtime::params::reference::NodeReference::of::<Params>(
        "sim_arm",
        "the simulated LWR IV, KRC, soft surface and Net F/T behind the same UDP and HTTP protocols",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_nodes::runtime::params::{NodeParams, contract};

    #[test]
    fn every_parameter_is_declared_once_and_no_number_takes_a_non_finite_huge_or_negative_value() {
        contract::assert_declared_once::<Params>("sim_arm");
        // The simulator's run length (seconds) may be as long as one likes.
        contract::assert_non_finite_refused::<Params>("sim_arm", &["seconds"], &[]);
    }

    #[test]
    fn a_surface_model_file_replaces_the_presets_law_and_a_bad_one_is_refused() {
        let dir = std::env::temp_dir().join(format!("sim_arm_model_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("augmented.yaml");
        let mut model = softcontact_sim::lab_sponge();
        model.stiffness = 20_000.0;
        std::fs::write(&good, model.to_yaml()).unwrap();
        let p = Params { surface_model: good.display().to_string(), ..Params::default() };
        assert!(p.validate().is_ok());
        assert_eq!(p.surface_model().unwrap(), Some(model));
        assert_eq!(Params::default().surface_model().unwrap(), None);
        // A missing file, one that is no model, a non-finite or negative law, and a file without a surface.
        let bad = dir.join("bad.yaml");
        for text in ["kind: kelvin_voigt\nstiffness: .nan\n", "kind: kelvin_voigt\nstiffness: -5.0\n", "hello: 1\n"] {
            std::fs::write(&bad, text).unwrap();
            let p = Params { surface_model: bad.display().to_string(), ..Params::default() };
            assert!(p.validate().unwrap_err().contains("surface_model"), "{text}");
        }
        let missing = Params { surface_model: dir.join("none.yaml").display().to_string(), ..Params::default() };
        assert!(missing.validate().is_err());
        let nowhere = Params { surface: SurfaceKind::None, ..p };
        assert!(nowhere.validate().unwrap_err().contains("surface none"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
