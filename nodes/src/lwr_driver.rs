//! The joint-torque interface of the LWR IV: answers every FRI measurement with a command, turning the
//! total desired joint torque (gravity included, as /lwr/joint_torque_command carries it) into what the
//! KRC expects — joint impedance with zero stiffness, the measured position mirrored, and the KRC's own
//! gravity removed because the KRC adds it back.
//!
//! Torque reaches the arm only in torque mode: the KRC's interface in command state, `robot.control`
//! joint impedance, the KRL program's handshake saying it started (`$FRI_TO_INT[2]` = 1, and
//! `$FRI_TO_INT[1]` = 30 where the program reports its strategy), all seven drives powered, no drive
//! error, a link graded OK or better and no fault latched. In any other state the answer is that mode's
//! safe command, with no added torque: the measured position (and pose) in position control, Cartesian
//! impedance or any other strategy, what the KRC commands itself in monitor mode, and in joint impedance
//! the hold below. Joint states then say "monitor": the controller integrates and plans nothing, and
//! approaches afresh when torque mode begins again — each beginning is a new KRC session. A KRC that
//! commands in another strategy is asked to stop, so that the KRL program starts again in joint impedance.
//!
//! Safety, in this order: a joint moving faster than `velocity_margin` of its limit, or heading into the
//! last `limit_margin` before its position limit, is a fault, found as the measurement is read, before
//! any controller sees it: the driver holds where the arm is, with no torque of any command, and asks
//! for no start, until the operator restarts the KRL program (the KRC seen in monitor mode with
//! `$FRI_TO_INT[2]` = 10 for [`OPERATOR_RESTART_CYCLES`] measurements) — never on a silence, a new
//! port or a new session. A command older than
//! `watchdog_cycles` (or none yet) makes the driver hold the current position with a stiff joint
//! impedance instead. A torque beyond its joint's limit is
//! no command a sound controller sends: it is refused (hold), never clipped into one. The driver never
//! waits for the controller — it answers with the newest command it has and counts stale cycles.
//!
//! A stale command's torque is handed over to the hold's spring: in contact the last torque is what
//! balances the surface, and dropping it would let the surface throw the hand back against the spring
//! (a 10 ms hiccup of the controller became a 0.17 m/s kick; a 1.5 s stall at 200 N threw the hand
//! back 30 mm). The hold's set point is offset from the held position by that torque over the joint's
//! stiffness, at most `hold_max_preload` rad — the farthest the hold would move a joint if the surface
//! vanished — and only what the offset cannot carry fades, over `hold_release_cycles`. Overspeed drops
//! the torque and the offset at once: then the command itself is suspect.
//!
//! Who and when (the safety contract, docs/safety.md):
//! - One KRC: the first sender (or the configured `krc_address`) is pinned by IP address; datagrams
//!   from any other address, or from port 0, are refused and counted as strangers, unanswered. A new
//!   source port of the pinned address once the old one has been silent for `new_session_after` (while
//!   the KRC talks, another port is a stranger), or measurements resuming after that silence, start a
//!   new KRC session: the command, the hold and the velocity history are forgotten (a latched
//!   fault is not), and only a command answering a joint state of the new session is applied.
//! - The watchdog counts answered measurements (each one sample time), whatever their sequence
//!   numbers say: an out-of-order counter is counted, never a way to keep an old command alive.
//! - A measurement that is not physically plausible (sample time outside 0.5–100 ms, a joint beyond its
//!   limit by more than [`POSITION_MARGIN`], a KRC gravity torque beyond twice the joint's limit, or, in
//!   command mode, one that stepped faster than [`GRAVITY_RATE`] allows since the last measurement) is
//!   refused unanswered: the KRC's own fallback takes over. The driver sends the total torque less the
//!   KRC's gravity, so a gravity that jumps would step the torque at the arm past any rate limit.
//! - Outside torque mode every answer is a stiff spring (the hold's stiffness): mirroring the KRC's own
//!   command in monitor mode, and held where the arm was when the driver began to hold in any other
//!   strategy, so that no answer, applied when it should not be, lets the arm float or follow its own
//!   drift.
//! - A command that is not 7 finite torques within the joints' limits makes the driver hold at once (the
//!   controller sends an empty command when its tick failed); a command from another session, or older
//!   than the watchdog by its stamp, is refused and the previous one ages out.
//! - Commands over the network come from one writer: the first heard while it is the only one on the
//!   topic, pinned for the KRC session ([`crate::runtime::writer_pin`]); any other writer's are refused and
//!   counted, and the arm never answers to them.

pub mod commander;
pub mod component;
mod counters;
mod held;
mod params;
pub use counters::{DriverCounters, Refusals};
pub use params::Params;

use std::net::SocketAddr;

use softcontact_dynamics::{Data, FrameId, FrameMotion, Model, lwr4};
use softcontact_wire::WireError;
use softcontact_wire::fri::{self, ControlMode, InterfaceState, Quality, flags};

use crate::runtime::writer_pin::{WriterId, WriterPin, WriterRefused};
use held::{Command, Hold};

/// How far beyond its limit a measured joint position is still believed \[rad\] (the KRC's software
/// limits lie inside the URDF's; more is a corrupt or forged datagram).
pub const POSITION_MARGIN: f64 = 0.1;
/// The hold's joint stiffness per joint [N·m/rad], lowest and highest: below, the hold does not hold
/// (1 N·m/rad let a stalled controller's hand fly 290 mm); above, the 1 ms loop of the simulated
/// KRC chatters at 500 Hz (5000 on joints 1–4 did, at every start).
pub const HOLD_STIFFNESS: [(f64, f64); 7] =
    [(500.0, 3000.0), (500.0, 3000.0), (200.0, 1500.0), (200.0, 1500.0), (50.0, 500.0), (20.0, 300.0), (20.0, 300.0)];
/// How far ahead the position-limit guard looks at the present joint velocity \[s\]: the hold's spring
/// stops a joint within about this long (ω ≈ 30–80 rad/s at the hold's stiffness), so a joint moving
/// into its last `limit_margin` is stopped before its limit, not after.
pub const LIMIT_LOOKAHEAD: f64 = 0.05;
/// Sample times the KRC can be configured to (FRI: 1 to 100 ms), with a margin below.
const SAMPLE_TIME: std::ops::RangeInclusive<f64> = 0.0005..=0.1;
/// The slowest FRI cycle torque is applied at: the loop is shown to hold a press from 1 to 10 ms
/// (`nodes/tests/closed_loop.rs`); a slower cycle gets the safe command of its mode and no torque.
pub const TORQUE_CYCLE_AT_MOST: f64 = 0.010;

/// KRL exchange (krl/softcontact.src, as ros_control.src of the LWR's ROS 1 stack): `$FRI_FRM_INT[1]`
/// the strategy the remote asks for, `$FRI_FRM_INT[2]` 1 start / 0 stop; `$FRI_TO_INT[2]` 1 started,
/// 0 stopped, 10 the program just began; `$FRI_TO_INT[1]` the strategy started (softcontact.src only).
pub const STRATEGY_JOINT_IMPEDANCE: i32 = 30;
pub const KRL_STARTED: i32 = 1;
pub const KRL_INIT: i32 = 10;
/// Measurements in a row in monitor mode with `$FRI_TO_INT[2]` = 10 that show the operator restarted
/// the KRL program.
pub const OPERATOR_RESTART_CYCLES: u32 = 100;
/// `robot.power`: one bit a drive.
pub const ALL_DRIVES: u16 = 0x7F;
/// More lost measurements in a row than this is no longer a gap but a broken counter.
const MAX_LOST_IN_A_ROW: i32 = 100;
/// The fastest the KRC's gravity torque may change in command mode \[N·m/s\], and the least step it
/// is allowed per measurement \[N·m\]. Gravity follows the joint positions: at the joints' velocity
/// limits the LWR IV's changes by at most about 130 N·m/s (∂g/∂q below 70 N·m/rad, 1.9 rad/s), so a
/// faster change is no KRC's gravity. Steps are counted over at most 10 lost measurements.
pub const GRAVITY_RATE: f64 = 500.0;
pub const GRAVITY_STEP_AT_LEAST: f64 = 1.0;

/// Why a command or datagram was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriverError {
    #[error(transparent)]
    Wire(#[from] WireError),
    #[error("torque command has {0} joints, the arm has 7")]
    CommandLength(usize),
    #[error("torque command holds a non-finite value for joint {0}")]
    NonFiniteCommand(usize),
    #[error("torque command of {1} N·m for joint {0} is beyond its limit of {2} N·m")]
    BeyondLimit(usize, f64, f64),
    #[error("torque command refused: {0}")]
    Writer(#[from] WriterRefused),
    #[error("torque command answers KRC session {0:?}, the present one is {1}")]
    OtherSession(Option<u32>, u32),
    #[error("torque command is {0:.4} s old, beyond max_command_age {1:.4} s (or stamped in the future)")]
    TooOld(f64, f64),
    #[error("implausible measurement: {0}")]
    Implausible(String),
}

/// Why the driver holds until the KRC starts a new session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// Joint (from 1) at this velocity [rad/s], beyond `velocity_margin` of its limit.
    Overspeed { joint: usize, velocity: f64 },
    /// Joint (from 1) at this position \[rad\] heading into its last `limit_margin`.
    PositionLimit { joint: usize, position: f64 },
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fault::Overspeed { joint, velocity } => write!(f, "joint {joint} overspeed at {velocity:.3} rad/s"),
            Fault::PositionLimit { joint, position } => {
                write!(f, "joint {joint} at {position:.4} rad, heading into its position limit")
            }
        }?;
        write!(f, ": holding until the operator restarts the KRL program")
    }
}

/// Why the driver applies no torque on a measurement: what it waits for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Waiting {
    /// The KRC's interface is not in command state.
    Monitor(InterfaceState),
    /// In command state, but the KRC runs another control strategy.
    Strategy(ControlMode),
    /// The same, after the KRL program was asked to start joint impedance and started this again.
    StrategyKept(ControlMode),
    /// The KRL program has not said that it started joint impedance (`$FRI_TO_INT[2]`,
    /// `$FRI_TO_INT[1]`).
    Handshake {
        started: i32,
        strategy: i32,
    },
    /// `robot.power`: not all seven drives on.
    DrivesOff(u16),
    /// `robot.error`: a drive error.
    DriveError(u16),
    /// The link graded below OK.
    Quality(Quality),
    /// The KRL program opened FRI at a cycle \[s\] slower than torque control is run at.
    SlowCycle(f64),
    Fault(Fault),
}

impl std::fmt::Display for Waiting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Waiting::Monitor(state) => {
                write!(f, "KRC in {state:?} state: waiting for the KRL program to start joint impedance")
            }
            Waiting::Strategy(mode) => write!(
                f,
                "KRC commands in {mode:?} control: no torque applied; asking the KRL program to stop and start again in joint impedance (strategy {STRATEGY_JOINT_IMPEDANCE})"
            ),
            Waiting::StrategyKept(mode) => write!(
                f,
                "KRC commands in {mode:?} control: no torque applied; asked for joint impedance, the KRL program started {mode:?} again: it does not take $FRI_FRM_INT[1] (run krl/softcontact.src)"
            ),
            Waiting::Handshake { started, strategy } => write!(
                f,
                "KRL handshake: $FRI_TO_INT[2] = {started}, $FRI_TO_INT[1] = {strategy}; waiting for {KRL_STARTED} and {STRATEGY_JOINT_IMPEDANCE}"
            ),
            Waiting::DrivesOff(power) => write!(f, "drives off (robot.power {power:#04x}): waiting for all seven"),
            Waiting::DriveError(error) => write!(f, "drive error {error:#06x}: waiting for the KRC to clear it"),
            Waiting::Quality(q) => write!(f, "FRI link quality {q:?}: waiting for OK or better"),
            Waiting::SlowCycle(t) => write!(
                f,
                "FRI cycle {:.0} ms: torque control runs at 1 to {:.0} ms; no torque applied (friOpen in the KRL program)",
                t * 1e3,
                TORQUE_CYCLE_AT_MOST * 1e3
            ),
            Waiting::Fault(fault) => write!(f, "{fault}"),
        }
    }
}

/// The state the driver publishes for one measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct DriverOutput {
    pub q: [f64; 7],
    /// Joint velocities by differencing positions over the KRC's own cycle count.
    pub dq: [f64; 7],
    /// Measured joint torques [N·m].
    pub effort: [f64; 7],
    /// The KRC's estimate of the external joint torques (FRI estExtJntTrq: measured less its model's)
    /// [N·m]: the arm's own, independent view of the contact force.
    pub external_torque: [f64; 7],
    pub state: InterfaceState,
    pub quality: Quality,
    /// The driver is holding position instead of applying the command.
    pub holding: bool,
    /// Why no torque is applied on this measurement; `None`: torque mode.
    pub waiting: Option<Waiting>,
    /// The KRC's cycle counter of this measurement.
    pub sequence: u16,
    /// The KRC session this measurement belongs to (published with the joint state).
    pub session: u32,
    /// The KRC's own clock (FRI `intf.timestamp`) \[s\], to the sample time: the simulated KRC keeps the
    /// simulated time on it, the loop's clock in lockstep (`use_sim_time`), where /clock can lag the
    /// datagram. FRI sends it as f32: whole cycles stay exact for about 2 hours (2^13 s at 1 ms).
    pub krc_time: f64,
}

impl DriverOutput {
    /// The driver applies the controller's torque on this measurement (if one is fresh).
    pub fn torque_mode(&self) -> bool {
        self.waiting.is_none()
    }
}

/// A measurement read by [`LwrDriver::measure`], waiting for [`LwrDriver::answer`].
#[derive(Debug, Clone)]
pub struct Measured {
    m: fri::Measurement,
    /// What the measurement says (`holding` is decided by the answer).
    pub output: DriverOutput,
}

/// The driver: one instance per FRI connection.
pub struct LwrDriver {
    config: Params,
    model: Model,
    data: Data,
    tool: FrameId,
    effort_limits: [f64; 7],
    velocity_limits: [f64; 7],
    position_limits: [(f64, f64); 7],
    send_seq: u16,
    last_msr: Option<(u16, [f64; 7])>,
    /// Measurements answered; the watchdog's clock.
    cycle: u64,
    /// The sample time of the newest measurement [s].
    sample_time: f64,
    peer: Option<SocketAddr>,
    session: u32,
    command: Option<Command>,
    /// The writer of the network's commands, pinned for the session.
    commander: WriterPin,
    hold: Option<Hold>,
    fault: Option<Fault>,
    /// The newest measurement was in torque mode; torque mode has begun in this session.
    torque_mode: bool,
    session_used: bool,
    /// Times in a row the KRC entered command mode in another strategy than joint impedance, and the
    /// state of the newest measurement.
    wrong_starts: u32,
    last_state: InterfaceState,
    /// Measurements in a row that say the KRL program just began, in monitor mode.
    restart_seen: u32,
    /// The torque beyond the KRC's gravity of the last commanded cycle [N·m].
    last_torque: [f32; 7],
    /// The KRC's gravity torque in the last measurement taken (the step check's reference).
    krc_gravity: Option<[f32; 7]>,
    pub counters: DriverCounters,
}

impl LwrDriver {
    pub fn new(config: Params) -> Self {
        let model = lwr4::model();
        let effort_limits = std::array::from_fn(|i| model.joints[i].limits.effort);
        let velocity_limits = std::array::from_fn(|i| model.joints[i].limits.velocity);
        let position_limits = std::array::from_fn(|i| (model.joints[i].limits.lower, model.joints[i].limits.upper));
        Self {
            data: model.data(),
            tool: model.frame_id(lwr4::TOOL_FRAME).expect("the LWR model has lwr_tool"),
            effort_limits,
            velocity_limits,
            position_limits,
            config,
            model,
            send_seq: 0,
            last_msr: None,
            cycle: 0,
            sample_time: 1e-3,
            peer: None,
            session: 0,
            command: None,
            commander: WriterPin::default(),
            hold: None,
            fault: None,
            torque_mode: false,
            session_used: false,
            wrong_starts: 0,
            last_state: InterfaceState::Off,
            restart_seen: 0,
            last_torque: [0.0; 7],
            krc_gravity: None,
            counters: DriverCounters::default(),
        }
    }

    /// The tool's pose and twist at (q, q̇) by the driver's own kinematics: for a process whose
    /// controller computes none (an in-process one hands over its own, [`Commander::tool_motion`]).
    ///
    /// [`Commander::tool_motion`]: commander::Commander::tool_motion
    pub fn tool_motion(&mut self, q: &[f64; 7], dq: &[f64; 7]) -> FrameMotion {
        self.model.frame_motion(&mut self.data, q, dq, self.tool)
    }

    /// The KRC session of the newest measurement.
    pub fn session(&self) -> u32 {
        self.session
    }

    /// Who sent a datagram, `silence` seconds after the pinned KRC's last one: the pinned KRC
    /// (`Some(new_session)`), or a stranger (`None`, counted, not to be answered). A datagram from the
    /// pinned address on a new port begins a new session, but only once the old port has been silent
    /// for `new_session_after`: while the KRC is talking, another port is a stranger.
    pub fn accept_sender(&mut self, from: SocketAddr, silence: f64) -> Option<bool> {
        let pinned_ip = self.config.krc_address.or(self.peer.map(|p| p.ip()));
        let talking = self.peer.is_some() && silence <= self.config.new_session_after;
        let new_session = self.peer != Some(from);
        if from.port() == 0 || pinned_ip.is_some_and(|ip| ip != from.ip()) || (new_session && talking) {
            self.counters.strangers += 1;
            return None;
        }
        if new_session {
            self.peer = Some(from);
            self.begin_session();
        }
        Some(new_session)
    }

    /// Measurements resume after `silence` seconds without one: a long silence is a new session.
    pub fn resumed_after(&mut self, silence: f64) {
        if !(silence <= self.config.new_session_after) {
            self.begin_session();
        }
    }

    /// The KRC's cycle, from the newest measurement \[s\].
    pub fn sample_time(&self) -> f64 {
        self.sample_time
    }

    /// The fault the driver holds for, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    /// A new KRC session: forget the command, its writer, the hold and the velocity history. A latched
    /// fault stays: only the operator clears it (see [`LwrDriver::measure`]).
    pub fn begin_session(&mut self) {
        self.session = self.session.wrapping_add(1);
        self.counters.sessions += 1;
        self.last_msr = None;
        self.command = None;
        self.commander.release();
        self.hold = None;
        self.torque_mode = false;
        self.session_used = false;
        self.last_torque = [0.0; 7];
        self.krc_gravity = None;
    }

    /// Why the driver would apply no torque on `m` (the fault as latched now).
    fn waiting_for(&self, m: &fri::Measurement) -> Option<Waiting> {
        let (started, strategy) = (m.krl.int[1], m.krl.int[0]);
        if let Some(f) = self.fault {
            Some(Waiting::Fault(f))
        } else if m.intf.state != InterfaceState::Command {
            Some(Waiting::Monitor(m.intf.state))
        } else if m.robot.control != ControlMode::JointImpedance && self.krl_ignores_strategy() {
            Some(Waiting::StrategyKept(m.robot.control))
        } else if m.robot.control != ControlMode::JointImpedance {
            Some(Waiting::Strategy(m.robot.control))
        } else if started != KRL_STARTED || !(strategy == 0 || strategy == STRATEGY_JOINT_IMPEDANCE) {
            Some(Waiting::Handshake { started, strategy })
        } else if m.robot.power & ALL_DRIVES != ALL_DRIVES {
            Some(Waiting::DrivesOff(m.robot.power))
        } else if m.robot.error != 0 {
            Some(Waiting::DriveError(m.robot.error))
        } else if m.intf.quality < Quality::Ok {
            Some(Waiting::Quality(m.intf.quality))
        } else if m.intf.desired_msr_sample_time as f64 > TORQUE_CYCLE_AT_MOST + 1e-6 {
            Some(Waiting::SlowCycle(m.intf.desired_msr_sample_time as f64))
        } else {
            None
        }
    }

    /// A new total joint torque command (gravity included), answering the newest measurement. If it is
    /// not 7 finite values within the joints' effort limits it is refused and the driver holds from the
    /// next cycle on (an empty command is the controller's way to ask for that hold).
    pub fn set_command(&mut self, effort: &[f64]) -> Result<(), DriverError> {
        self.take_command(effort, None)
    }

    /// Takes a command if it is 7 finite torques within the effort limits: from the network answering
    /// the joint state stamped `stamp`, `age` seconds old by the newest measurement's stamp (`None`: the
    /// in-process controller's, for this very measurement).
    fn take_command(&mut self, effort: &[f64], stamped: Option<(f64, f64)>) -> Result<(), DriverError> {
        let refused = if effort.len() != 7 {
            Some(DriverError::CommandLength(effort.len()))
        } else if let Some(i) = effort.iter().position(|v| !v.is_finite()) {
            Some(DriverError::NonFiniteCommand(i))
        } else {
            let beyond = effort.iter().zip(&self.effort_limits).position(|(v, l)| !(v.abs() <= *l));
            beyond.map(|i| DriverError::BeyondLimit(i, effort[i], self.effort_limits[i]))
        };
        if let Some(e) = refused {
            self.counters.commands_refused += 1;
            self.command = None;
            return Err(e);
        }
        let (stamp, age) = (stamped.map(|(stamp, _)| stamp), stamped.map_or(0.0, |(_, age)| age));
        self.command = Some(Command { effort: std::array::from_fn(|i| effort[i]), at: self.cycle, age, stamp });
        Ok(())
    }

    /// No command from this cycle on: the driver holds (an in-process controller's way to ask for it; not
    /// counted as a refusal).
    pub fn clear_command(&mut self) {
        self.command = None;
    }

    /// A command that arrived over the network from `writer` (`writers_matched`: how many writers the
    /// middleware matched on the topic): it names the session of the joint state it answers and carries
    /// that joint state's `stamp`; `now` is the stamp of the measurement about to be answered (both on
    /// the driver's clock). One from a writer other than the session's pinned one is refused and touches
    /// nothing; one from another session, older than `max_command_age` or stamped in the future (it
    /// answers no joint state yet measured), is refused and the present command ages out as usual. A
    /// command taken keeps ageing: it answers no measurement once its stamp is older than
    /// `max_command_age`, by the watchdog's cycles here and by the driver's clock in
    /// [`LwrDriver::expire_command`].
    pub fn set_remote_command(
        &mut self,
        effort: &[f64],
        session: Option<u32>,
        stamp: f64,
        now: f64,
        writer: WriterId,
        writers_matched: impl FnOnce() -> usize,
    ) -> Result<(), DriverError> {
        if let Err(e) = self.commander.admit(writer, writers_matched) {
            self.counters.commands_from_strangers += 1;
            return Err(e.into());
        }
        if session != Some(self.session) {
            self.counters.commands_refused += 1;
            self.counters.commands_too_old += 1;
            return Err(DriverError::OtherSession(session, self.session));
        }
        let (age, bound) = (now - stamp, self.config.max_command_age);
        if !(age >= 0.0 && age <= bound) {
            self.counters.commands_refused += 1;
            self.counters.commands_too_old += 1;
            return Err(DriverError::TooOld(age, bound));
        }
        self.take_command(effort, Some((stamp, age)))
    }

    /// Drops a command from the network whose stamp is older than `max_command_age` at `now`, the stamp
    /// of the measurement about to be answered (the driver's clock): a command taken before a gap
    /// between measurements answers none after it. The in-process controller's command, which answers
    /// the very measurement, is not aged here.
    pub fn expire_command(&mut self, now: f64) {
        let bound = self.config.max_command_age;
        if self.command.and_then(|c| c.stamp).is_some_and(|stamp| !(now - stamp <= bound)) {
            self.command = None;
        }
    }

    fn check_plausible(&self, m: &fri::Measurement) -> Result<(), DriverError> {
        let implausible = |why: String| Err(DriverError::Implausible(why));
        let t = m.intf.desired_msr_sample_time as f64;
        if !SAMPLE_TIME.contains(&t) {
            return implausible(format!("sample time {t} s"));
        }
        for i in 0..7 {
            let q = m.data.msr_jnt_pos[i] as f64;
            let (lower, upper) = self.position_limits[i];
            if !(q >= lower - POSITION_MARGIN && q <= upper + POSITION_MARGIN) {
                return implausible(format!("joint {} at {q} rad, limits [{lower}, {upper}]", i + 1));
            }
            let g = m.data.gravity[i] as f64;
            if !(g.abs() <= 2.0 * self.effort_limits[i]) {
                return implausible(format!("KRC gravity {g} N·m on joint {}", i + 1));
            }
        }
        self.check_gravity_step(m)
    }

    /// In command mode, the KRC's gravity changed since the last measurement by no more than
    /// [`GRAVITY_RATE`] allows. Outside command mode no torque is applied, and the reference follows.
    fn check_gravity_step(&self, m: &fri::Measurement) -> Result<(), DriverError> {
        let (Some(previous), Some((prev_seq, _))) = (self.krc_gravity, self.last_msr) else { return Ok(()) };
        if m.intf.state != InterfaceState::Command {
            return Ok(());
        }
        let steps = fri::sequence_gap(prev_seq, m.header.send_seq).clamp(0, 9) as f64 + 1.0;
        let allowed = (GRAVITY_RATE * m.intf.desired_msr_sample_time as f64 * steps).max(GRAVITY_STEP_AT_LEAST);
        for (i, (now, before)) in m.data.gravity.iter().zip(previous).enumerate() {
            let step = (now - before) as f64;
            if !(step.abs() <= allowed) {
                return Err(DriverError::Implausible(format!(
                    "KRC gravity on joint {} stepped by {step:.3} N·m in one measurement (at most {allowed:.3})",
                    i + 1
                )));
            }
        }
        Ok(())
    }

    /// Handles one datagram from the KRC: the reply to send back (with the present command) and the state
    /// to publish. A malformed datagram is counted and refused (no reply: the KRC bridges a missing
    /// answer). [`LwrDriver::measure`] then [`LwrDriver::answer`].
    pub fn handle(&mut self, datagram: &[u8]) -> Result<(fri::Command, DriverOutput), DriverError> {
        let measured = self.measure(datagram)?;
        Ok(self.answer(measured))
    }

    /// Reads one datagram from the KRC: decoded, checked, counted, with the joint velocities (the tool's
    /// pose and twist come after the answer, [`LwrDriver::tool_motion`]). The answer is chosen by [`LwrDriver::answer`]: in between, an in-process
    /// controller can compute the torque for this very measurement and hand it over with
    /// [`LwrDriver::set_command`] (or ask for a hold with [`LwrDriver::clear_command`]).
    pub fn measure(&mut self, datagram: &[u8]) -> Result<Measured, DriverError> {
        let m = match fri::Measurement::decode(datagram) {
            Ok(m) => m,
            Err(e) => {
                self.counters.malformed += 1;
                return Err(e.into());
            }
        };
        if let Err(e) = self.check_plausible(&m) {
            self.counters.implausible += 1;
            return Err(e);
        }
        self.counters.measurements += 1;
        self.krc_gravity = Some(m.data.gravity);
        self.sample_time = m.intf.desired_msr_sample_time as f64;
        let q: [f64; 7] = std::array::from_fn(|i| m.data.msr_jnt_pos[i] as f64);
        let seq = m.header.send_seq;
        let mut dq = [0.0; 7];
        let trusted = self.last_msr.map_or(q, |(_, prev_q)| prev_q);
        if let Some((prev_seq, prev_q)) = self.last_msr {
            // Lost measurements widen the step; a counter that went back (or jumped) is counted and the
            // step taken as one cycle, so the velocity guard sees any jump in position.
            let gap = fri::sequence_gap(prev_seq, seq);
            let steps = if (0..=MAX_LOST_IN_A_ROW).contains(&gap) {
                self.counters.lost += gap as u64;
                gap as f64 + 1.0
            } else {
                self.counters.out_of_order += 1;
                1.0
            };
            dq = std::array::from_fn(|i| (q[i] - prev_q[i]) / (steps * self.sample_time));
        }
        self.last_msr = Some((seq, q));
        self.cycle += 1;
        self.note_operator(&m);
        // A joint too fast or too near its limit latches the fault here, before any controller sees the
        // measurement (a forged or corrupt position jump included).
        if m.intf.state == InterfaceState::Command && self.fault.is_none() {
            self.fault = self.fault_of(&q, &dq);
            // Held where the arm was last seen sound: a jump of the position is no place to hold.
            if let Some(fault) = self.fault {
                let at = if matches!(fault, Fault::Overspeed { .. }) { trusted } else { q };
                self.hold = Some(Hold::new(at, self.cycle, &[0.0; 7], &self.config));
            }
        }
        self.note_start(&m);
        let waiting = self.waiting_for(&m);
        self.note_torque_mode(waiting.is_none());
        let output = DriverOutput {
            q,
            dq,
            effort: std::array::from_fn(|i| m.data.msr_jnt_trq[i] as f64),
            external_torque: std::array::from_fn(|i| m.data.est_ext_jnt_trq[i] as f64),
            state: m.intf.state,
            quality: m.intf.quality,
            holding: false,
            waiting,
            sequence: seq,
            session: self.session,
            krc_time: (m.intf.timestamp as f64 / self.sample_time).round() * self.sample_time,
        };
        Ok(Measured { m, output })
    }

    /// The operator's action the driver can see: the KRC in monitor mode with the KRL program just begun
    /// (`$FRI_TO_INT[2]` = 10) for [`OPERATOR_RESTART_CYCLES`] measurements in a row (a restarted
    /// program waits that long at least, for the link's grade). It clears a latched fault; a stray
    /// datagram saying so does not.
    fn note_operator(&mut self, m: &fri::Measurement) {
        let restarted = m.intf.state == InterfaceState::Monitor && m.krl.int[1] == KRL_INIT;
        self.restart_seen = if restarted { self.restart_seen.saturating_add(1) } else { 0 };
        if self.fault.is_some() && self.restart_seen >= OPERATOR_RESTART_CYCLES {
            self.fault = None;
            self.counters.faults_cleared += 1;
        }
    }

    /// Torque mode begins again after it ended: a new session, so that no command of before is applied
    /// and the controller approaches afresh. Leaving it forgets the command.
    fn note_torque_mode(&mut self, torque_mode: bool) {
        if torque_mode && !self.torque_mode && self.session_used {
            self.begin_session();
        }
        if !torque_mode {
            self.command = None;
        }
        self.session_used |= torque_mode;
        self.torque_mode = torque_mode;
    }

    /// Counts the KRC entering command mode in another strategy; torque mode resets the count.
    fn note_start(&mut self, m: &fri::Measurement) {
        let entered = m.intf.state == InterfaceState::Command && self.last_state != InterfaceState::Command;
        if entered && m.robot.control != ControlMode::JointImpedance {
            self.wrong_starts += 1;
        }
        if m.intf.state == InterfaceState::Command && m.robot.control == ControlMode::JointImpedance {
            self.wrong_starts = 0;
        }
        self.last_state = m.intf.state;
    }

    /// The KRL program started another strategy again after being asked to stop and start in joint
    /// impedance: it does not take `$FRI_FRM_INT[1]`, and asking again would only toggle FRI.
    pub fn krl_ignores_strategy(&self) -> bool {
        self.wrong_starts >= 2
    }

    /// Whether to ask the KRL program to start (1) or stop (0) command mode: a KRC commanding in another
    /// strategy is asked to stop (the program then starts again in the strategy asked for), once; while a
    /// fault stands no start is asked for; in monitor-only mode the KRC's state is left as it is.
    fn start_request(&self, m: &fri::Measurement) -> bool {
        let in_command = m.intf.state == InterfaceState::Command;
        if self.config.monitor_only || self.krl_ignores_strategy() {
            return in_command;
        }
        if in_command && m.robot.control != ControlMode::JointImpedance {
            return false;
        }
        in_command || (self.fault.is_none() && m.intf.quality == Quality::Perfect)
    }

    /// The answer to a measurement: the present command when in torque mode with a fresh command, the
    /// hold in joint impedance otherwise, or, in any other mode, that mode's safe command.
    pub fn answer(&mut self, measured: Measured) -> (fri::Command, DriverOutput) {
        let Measured { m, mut output } = measured;
        let (q, seq) = (output.q, output.sequence);
        let fresh = self.command.filter(|c| c.fresh(self.cycle, self.sample_time, &self.config)).map(|c| c.effort);

        let mut reply = fri::Command::default();
        self.send_seq = self.send_seq.wrapping_add(1);
        reply.header.send_seq = self.send_seq;
        reply.header.refl_seq = seq;
        reply.krl.int[0] = STRATEGY_JOINT_IMPEDANCE;
        reply.krl.int[1] = i32::from(self.start_request(&m));
        reply.flags = flags::JOINT_IMPEDANCE;
        // Whatever fields the KRC reads in its present strategy, they say: stay where you are.
        reply.cart_pos = m.data.msr_cart_pos;
        reply.jnt_damping = [self.config.hold_damping as f32; 7];
        let in_command = m.intf.state == InterfaceState::Command;
        let joint_impedance = m.robot.control == ControlMode::JointImpedance;
        let waits = output.waiting.is_some_and(|w| !matches!(w, Waiting::Fault(_)));
        self.counters.waiting_cycles += u64::from(in_command && waits);
        let holding = match (output.waiting, fresh) {
            (None, Some(effort)) => {
                for (i, total) in effort.iter().enumerate() {
                    // The KRC adds its own gravity model: send only the rest.
                    reply.add_jnt_trq[i] = (total - m.data.gravity[i] as f64) as f32;
                }
                reply.jnt_pos = m.data.msr_jnt_pos;
                self.last_torque = reply.add_jnt_trq;
                self.hold = None;
                false
            }
            _ if !in_command => {
                // Mirror what the KRC commands itself, so that entering command mode is seamless, as a
                // stiff spring: applied by a KRC that is commanding after all, it holds the arm.
                reply.jnt_pos = std::array::from_fn(|i| m.data.cmd_jnt_pos[i] + m.data.cmd_jnt_pos_fri_offset[i]);
                reply.jnt_stiffness = self.config.hold_stiffness.map(|v| v as f32);
                self.hold = None;
                self.last_torque = [0.0; 7];
                false
            }
            _ if !joint_impedance => {
                // Position control, Cartesian impedance or anything else: where the arm was when the
                // driver began to hold, never the measured position of the moment (a set point that follows the
                // arm holds nothing), with no torque of any command.
                let config = &self.config;
                let hold = self.hold.get_or_insert_with(|| Hold::new(q, self.cycle, &[0.0; 7], config));
                (hold.preload, hold.rest) = ([0.0; 7], [0.0; 7]);
                reply.jnt_pos = hold.q.map(|v| v as f32);
                reply.jnt_stiffness = self.config.hold_stiffness.map(|v| v as f32);
                self.last_torque = [0.0; 7];
                true
            }
            (waiting, _) => {
                self.hold_answer(&mut reply, &q, waiting, fresh.is_none());
                true
            }
        };
        output.holding = holding;
        (reply, output)
    }

    /// The hold in joint impedance: a stiff spring where the arm is. For a stale command it carries on
    /// the command's torque as a set-point offset and fades the rest; for a fault, or any other reason
    /// not to apply torque, it carries nothing of it.
    fn hold_answer(&mut self, reply: &mut fri::Command, q: &[f64; 7], waiting: Option<Waiting>, stale: bool) {
        self.counters.stale_cycles += u64::from(stale && waiting.is_none());
        match self.fault {
            Some(Fault::Overspeed { .. }) => self.counters.overspeed_cycles += 1,
            Some(Fault::PositionLimit { .. }) => self.counters.limit_cycles += 1,
            None => {}
        }
        let config = &self.config;
        let hold = self.hold.get_or_insert_with(|| Hold::new(*q, self.cycle, &self.last_torque, config));
        if self.fault.is_some() {
            // The command itself is suspect: no torque of it is kept, and the hold stays where the arm
            // is (never beyond a limit).
            hold.preload = [0.0; 7];
            hold.q = std::array::from_fn(|i| hold.q[i].clamp(self.position_limits[i].0, self.position_limits[i].1));
        }
        if waiting.is_some() {
            hold.rest = [0.0; 7];
        }
        self.last_torque = [0.0; 7];
        let elapsed = self.cycle.saturating_sub(hold.since) as f64;
        let keep = (1.0 - elapsed / self.config.hold_release_cycles.max(1) as f64).max(0.0);
        reply.add_jnt_trq = hold.rest.map(|t| (t * keep) as f32);
        reply.jnt_pos = std::array::from_fn(|i| (hold.q[i] + hold.preload[i]) as f32);
        reply.jnt_stiffness = self.config.hold_stiffness.map(|v| v as f32);
    }

    /// A joint beyond `velocity_margin` of its velocity limit, or in or heading into (at its velocity,
    /// [`LIMIT_LOOKAHEAD`] ahead) the last `limit_margin` before a position limit.
    fn fault_of(&self, q: &[f64; 7], dq: &[f64; 7]) -> Option<Fault> {
        let margin = self.config.limit_margin;
        (0..7).find_map(|i| {
            if !(dq[i].abs() <= self.config.velocity_margin * self.velocity_limits[i]) {
                return Some(Fault::Overspeed { joint: i + 1, velocity: dq[i] });
            }
            let (lower, upper) = self.position_limits[i];
            let ahead = q[i] + dq[i] * LIMIT_LOOKAHEAD;
            // A joint already in the band faults too: the KRC jogs it out, not a torque command.
            let inside = |x: f64| x >= lower + margin && x <= upper - margin;
            (!inside(q[i]) || !inside(ahead)).then_some(Fault::PositionLimit { joint: i + 1, position: q[i] })
        })
    }
}
