//! The simulated cell behind real UDP sockets: the KRC's side of FRI (a measurement to the remote every
//! cycle, its answer applied) and the Net F/T's side of RDT (records streamed on request), paced in
//! real time. Optional loss in both directions for robustness tests.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::ContactModel;
use softcontact_sim::Simulator;
use softcontact_wire::{fri, rdt};

#[derive(Debug, Clone)]
pub struct SimArmConfig {
    pub fri_bind: SocketAddr,
    /// Where the driver listens (the KRC's `FRIHOST`/`FRISOCK`).
    pub fri_remote: SocketAddr,
    pub rdt_bind: SocketAddr,
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
    /// One cycle per FRI period of wall time, as the KRC does.
    RealTime,
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
    pub records_sent: u64,
}

pub struct SimArmServer {
    sim: Simulator,
    fri: UdpSocket,
    rdt: UdpSocket,
    config: SimArmConfig,
    stream_to: Option<SocketAddr>,
    remaining: Option<u32>,
    rng: SmallRng,
    records_due: f64,
    pub stats: SimArmStats,
}

impl SimArmServer {
    pub fn bind(sim: Simulator, config: SimArmConfig) -> std::io::Result<Self> {
        let fri = UdpSocket::bind(config.fri_bind)?;
        let rdt = UdpSocket::bind(config.rdt_bind)?;
        rdt.set_nonblocking(true)?;
        let rng = SmallRng::seed_from_u64(config.seed ^ 0x5eed);
        if !(1.0..=7000.0).contains(&config.rdt_rate) {
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "RDT rate must lie in 1..=7000 Hz"));
        }
        Ok(Self {
            sim,
            fri,
            rdt,
            config,
            stream_to: None,
            remaining: None,
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
                        self.sim.sensor.start_stream();
                    }
                    rdt::RdtCommand::Stop => self.stream_to = None,
                    rdt::RdtCommand::SetBias => self.sim.sensor.set_bias(),
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
        let mut buf = [0u8; 2048];
        loop {
            let m = self.sim.measurement();
            let lossy = m.intf.state == fri::InterfaceState::Command;
            if lossy && self.rng.random::<f64>() < self.config.measurement_loss {
                self.stats.measurements_dropped += 1;
            } else {
                self.fri.send_to(&m.encode(), self.config.fri_remote)?;
            }
            // Take answers until one for this measurement arrives or 0.9 of a cycle has passed since it
            // was sent (measured from the send, so that one late cycle does not also cost the next).
            let wait = match self.config.pacing {
                Pacing::RealTime => cycle.mul_f64(0.9),
                Pacing::Lockstep { timeout } => timeout,
            };
            let deadline = Instant::now() + wait;
            loop {
                let now = Instant::now();
                if now >= deadline {
                    break;
                }
                self.fri.set_read_timeout(Some(deadline - now))?;
                match self.fri.recv_from(&mut buf) {
                    Ok((n, _)) => match fri::Command::decode(&buf[..n]) {
                        Ok(cmd) => {
                            if lossy && self.rng.random::<f64>() < self.config.command_loss {
                                self.stats.commands_dropped += 1;
                                continue;
                            }
                            let answered = cmd.header.refl_seq == m.header.send_seq;
                            self.sim.command(&cmd);
                            if answered {
                                break;
                            }
                        }
                        Err(_) => self.stats.malformed += 1,
                    },
                    Err(e) if crate::udp::no_datagram(&e) => break,
                    Err(e) => return Err(e),
                }
            }
            self.serve_rdt_requests();
            self.sim.step_cycle().map_err(std::io::Error::other)?;
            self.records_due += self.config.rdt_rate * self.sim.krc_cycle();
            while self.records_due >= 1.0 {
                self.records_due -= 1.0;
                let Some(to) = self.stream_to else { continue };
                let record = self.sim.ft_record();
                self.rdt.send_to(&record.encode(), to)?;
                self.stats.records_sent += 1;
                if let Some(left) = self.remaining.as_mut() {
                    *left -= 1;
                    if *left == 0 {
                        self.stream_to = None;
                    }
                }
            }
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
    pub surface: SurfaceKind,
    pub surface_model: String,
    pub seconds: f64,
    pub drop_rate: f64,
    pub rdt_rate: f64,
    pub lockstep: bool,
    pub seed: u64,
    pub krl_program: KrlProgramKind,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            fri_remote: ([127, 0, 0, 1], 49938).into(),
            fri_bind: ([127, 0, 0, 1], 0).into(),
            rdt_bind: ([127, 0, 0, 1], 49152).into(),
            surface: SurfaceKind::Sponge,
            surface_model: String::new(),
            seconds: 0.0,
            drop_rate: 0.0,
            rdt_rate: 1000.0,
            lockstep: false,
            seed: 1,
            krl_program: KrlProgramKind::Softcontact,
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
        let text = crate::params::read_small(std::path::Path::new(&self.surface_model))
            .map_err(|e| format!("{}: {e}", self.surface_model))?;
        let model = ContactModel::from_yaml(&text).map_err(|e| format!("{}: {e}", self.surface_model))?;
        model.plausible().map_err(|e| format!("{}: {e}", self.surface_model))?;
        Ok(Some(model))
    }
}

impl crate::params::NodeParams for Params {
    fn declare(&self, d: &mut crate::params::Declarations) {
        d.any("fri_remote", "where the FRI driver listens (the KRC's FRIHOST:FRISOCK)");
        d.any("fri_bind", "the simulated KRC's own FRI address");
        d.any("rdt_bind", "the simulated Net F/T box's RDT address");
        d.any("surface", "the simulated surface: its preset law, place and sensor (none: free space)");
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
            "stop after this many simulated seconds (0: run until stopped)",
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
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::NodeParams;

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
