//! The KRC side of FRI: the OFF/MON/CMD state machine driven through the KRL exchange variables, the
//! timing grade (quality) of the remote's answers, and the joint-impedance law the KRC runs, with its
//! own gravity compensation, as the real controller does (docs/protocols/fri-lwr4.md sections 9–11).
//!
//! The KRL side runs one of two programs ([`KrlProgram`]): the one this repository ships
//! (`krl/softcontact.src`) or the common `ros_control.src` of the LWR's ROS 1 stack. Both read
//! `$FRI_FRM_INT[1]` as the strategy the remote asks for (10 joint position, 20 Cartesian impedance, 30
//! joint impedance) and `$FRI_FRM_INT[2]` as 1 start / 0 stop, and acknowledge in `$FRI_TO_INT[2]` (10
//! program just started, 1 started, 0 stopped). Both begin in position control (strategy 10). They
//! differ in two things: `ros_control.src` keeps position control on its first start after the program
//! began (the remote must stop and start again to change it) and does not report the strategy;
//! `softcontact.src` takes the asked strategy on every start and reports it in `$FRI_TO_INT[1]`.
//! `robot.control` reports the strategy the KRL side selected, in every state.

use std::collections::VecDeque;

use rand::Rng;
use rand_distr::{Distribution, Normal};
use softcontact_dynamics::{Axes, Data, FrameId, Model};
use softcontact_wire::fri::{self, ControlMode, InterfaceState, Quality, flags};

/// The grade the KRC gives the remote's answers over a sliding window of cycles. KUKA does not publish
/// the real thresholds; these defaults are configurable: PERFECT needs every cycle answered (the KRL
/// program starts command mode only then), OK ≥ 98 %, BAD ≥ 80 % (still commanding, as FRI allows
/// from BAD up: a link losing 5 % of its datagrams each way answers ≈ 90 % of cycles), UNACCEPTABLE
/// below, which ends command mode, as do more than `max_consecutive_misses` misses in a row.
#[derive(Debug, Clone, PartialEq)]
pub struct QualityPolicy {
    pub window: usize,
    /// Answer rate for OK and for BAD; PERFECT needs every cycle answered.
    pub ok_rate: f64,
    pub bad_rate: f64,
}

impl Default for QualityPolicy {
    fn default() -> Self {
        Self { window: 100, ok_rate: 0.98, bad_rate: 0.8 }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct KrcConfig {
    pub quality: QualityPolicy,
    /// Consecutive unanswered cycles in command mode before the KRC falls back to monitor mode.
    pub max_consecutive_misses: usize,
    /// Largest |jntPos − current| accepted on entering command mode \[rad\].
    pub mirror_tolerance: f64,
    /// Noise of the joint torque sensors [N·m].
    pub torque_noise: f64,
    pub cycle: f64,
    pub program: KrlProgram,
}

impl Default for KrcConfig {
    fn default() -> Self {
        Self {
            quality: QualityPolicy::default(),
            max_consecutive_misses: 5,
            mirror_tolerance: 1e-3,
            torque_noise: 0.05,
            cycle: 1e-3,
            program: KrlProgram::default(),
        }
    }
}

/// The KRL program running on the KRC (see the module's docs for how they differ).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KrlProgram {
    #[default]
    Softcontact,
    RosControl,
    /// A program of the cell's own that always starts this strategy, whatever the remote asks, and
    /// reports none.
    Fixed(i32),
}

/// What changed in the KRC.
#[derive(Debug, Clone, PartialEq)]
pub enum KrcEvent {
    EnteredCommand,
    /// Back to monitor mode, brakes on, with the reason.
    FellBack(String),
    /// A start was refused because the command did not mirror the current position.
    InterpolationError,
    /// A start the KRL program or the KRC refused, and why (as the pendant's message line says it).
    Refused(String),
}

/// The KRL strategies (`$stiffness.strategy`).
pub const STRATEGY_POSITION: i32 = 10;
pub const STRATEGY_CARTESIAN_IMPEDANCE: i32 = 20;
pub const STRATEGY_JOINT_IMPEDANCE: i32 = 30;
/// `$FRI_TO_INT[2]` once the KRL program has begun, before its first start.
pub const KRL_INIT: i32 = 10;
/// `robot.power` with all seven drives on.
pub const ALL_DRIVES: u16 = 0x7F;

/// The control mode `robot.control` reports for a KRL strategy.
pub fn control_mode(strategy: i32) -> ControlMode {
    match strategy {
        STRATEGY_POSITION => ControlMode::Position,
        STRATEGY_CARTESIAN_IMPEDANCE => ControlMode::CartesianImpedance,
        STRATEGY_JOINT_IMPEDANCE => ControlMode::JointImpedance,
        _ => ControlMode::Other,
    }
}

/// The command fields a strategy needs (FRI: position control reads jntPos, joint impedance jntPos and
/// optionally stiffness, damping and torque, Cartesian impedance cartPos).
fn needed_flags(strategy: i32) -> u32 {
    match strategy {
        STRATEGY_CARTESIAN_IMPEDANCE => flags::CART_POS,
        _ => flags::JNT_POS,
    }
}

/// How the KRC drives the motors this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// Monitor mode, drives off or a fault: the brakes hold the arm.
    Brakes,
    /// Position control (also how the simulator holds an arm in Cartesian impedance, whose KRL-set
    /// stiffness it does not model): the joints follow these positions, as stiff as the arm's own
    /// position controller.
    Position([f64; 7]),
    /// Joint impedance: these motor torques.
    Torque([f64; 7]),
}

/// The KRC's FRI state.
#[derive(Debug, Clone)]
pub struct Krc {
    config: KrcConfig,
    state: InterfaceState,
    /// The position the KRC holds in monitor mode (and reports as cmdJntPos).
    hold: [f64; 7],
    /// The command in force and its flags.
    command: Option<fri::Command>,
    send_seq: u16,
    /// `send_seq` of the last received command.
    last_remote_seq: u16,
    answered: bool,
    history: VecDeque<bool>,
    consecutive_misses: usize,
    pub late_answers: u64,
    pub missed_cycles: u64,
    ack: i32,
    /// The KRL program's `$stiffness.strategy`.
    strategy: i32,
    /// `robot.power`, `robot.error` and `robot.warning` (tests set them as a real cell's drives would).
    pub power: u16,
    pub error: u16,
    pub warning: u16,
    fault: Option<String>,
    jacobian: nalgebra::Matrix6xX<f64>,
}

impl Krc {
    pub fn new(config: KrcConfig, q: [f64; 7]) -> Self {
        Self {
            config,
            state: InterfaceState::Monitor,
            hold: q,
            command: None,
            send_seq: 0,
            last_remote_seq: 0,
            answered: false,
            history: VecDeque::new(),
            consecutive_misses: 0,
            late_answers: 0,
            missed_cycles: 0,
            ack: KRL_INIT,
            strategy: STRATEGY_POSITION,
            power: ALL_DRIVES,
            error: 0,
            warning: 0,
            fault: None,
            jacobian: nalgebra::Matrix6xX::zeros(7),
        }
    }

    /// The newest command datagram received from the remote.
    pub fn last_command(&self) -> Option<&fri::Command> {
        self.command.as_ref()
    }

    pub fn state(&self) -> InterfaceState {
        self.state
    }

    pub fn last_fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }

    /// The strategy the KRL program selected (`$stiffness.strategy`).
    pub fn strategy(&self) -> i32 {
        self.strategy
    }

    /// The operator restarts the KRL program (after acknowledging a fault on the pendant): FRI closed
    /// and opened again in monitor mode, position control, `$FRI_TO_INT[2]` = 10.
    pub fn restart_program(&mut self, q: [f64; 7]) {
        self.state = InterfaceState::Monitor;
        self.hold = q;
        self.command = None;
        self.ack = KRL_INIT;
        self.strategy = STRATEGY_POSITION;
        self.fault = None;
    }

    /// The KRL side changes the strategy while the KRC commands (`$stiffness.strategy`, commit).
    pub fn switch_strategy(&mut self, strategy: i32) {
        self.strategy = strategy;
    }

    /// Drives on, no error: what the KRC's motors need to move the arm.
    fn drives_ready(&self) -> bool {
        self.power == ALL_DRIVES && self.error == 0
    }

    pub(crate) fn hold_at(&mut self, q: [f64; 7]) {
        self.hold = q;
    }

    /// Answer rate over the window.
    pub fn answer_rate(&self) -> f64 {
        if self.history.is_empty() {
            0.0
        } else {
            self.history.iter().filter(|a| **a).count() as f64 / self.history.len() as f64
        }
    }

    pub fn quality(&self) -> Quality {
        let p = &self.config.quality;
        if self.history.len() < p.window {
            return Quality::Unacceptable;
        }
        let rate = self.answer_rate();
        if rate >= 1.0 {
            Quality::Perfect
        } else if rate >= p.ok_rate {
            Quality::Ok
        } else if rate >= p.bad_rate {
            Quality::Bad
        } else {
            Quality::Unacceptable
        }
    }

    pub(crate) fn trip(&mut self, reason: String, q: [f64; 7]) {
        self.state = InterfaceState::Monitor;
        self.hold = q;
        self.ack = 0;
        self.fault = Some(reason);
    }

    fn fall_back(&mut self, reason: String, q: [f64; 7]) -> KrcEvent {
        self.trip(reason.clone(), q);
        KrcEvent::FellBack(reason)
    }

    /// A command datagram from the remote. Only an answer to the newest measurement counts as on time.
    pub fn receive(&mut self, cmd: &fri::Command, q: &[f64; 7]) -> Option<KrcEvent> {
        self.last_remote_seq = cmd.header.send_seq;
        if cmd.header.refl_seq != self.send_seq {
            self.late_answers += 1;
            return None;
        }
        self.answered = true;
        let (strategy, start) = (cmd.krl.int[0], cmd.krl.int[1]);
        match self.state {
            InterfaceState::Command => {
                let previous = self.command.replace(*cmd);
                if previous.is_some_and(|p| p.flags != cmd.flags) {
                    return Some(self.fall_back("cmdFlags changed during cmd mode".into(), *q));
                }
                if start == 0 {
                    self.state = InterfaceState::Monitor;
                    self.hold = *q;
                    self.ack = 0;
                    return Some(KrcEvent::FellBack("stop requested".into()));
                }
                None
            }
            _ => {
                // The KRL program waits for a start request it has not acknowledged yet.
                if start != 1 || self.ack == 1 {
                    return None;
                }
                let strategy = match self.config.program {
                    KrlProgram::Softcontact => strategy,
                    KrlProgram::RosControl if self.ack != KRL_INIT => strategy,
                    KrlProgram::RosControl => self.strategy,
                    KrlProgram::Fixed(fixed) => fixed,
                };
                if control_mode(strategy) == ControlMode::Other {
                    return Some(KrcEvent::Refused(format!("unknown strategy {strategy} in $FRI_FRM_INT[1]")));
                }
                let needed = needed_flags(strategy);
                if cmd.flags & needed != needed {
                    return Some(KrcEvent::Refused(format!(
                        "strategy {strategy} needs cmdFlags {needed:#06x}, the remote sends {:#06x}",
                        cmd.flags
                    )));
                }
                // The KRL program waits for a perfect link, and the drives must be on, before friStart.
                if self.quality() < Quality::Perfect || !self.drives_ready() {
                    return None;
                }
                let mirrored = cmd
                    .jnt_pos
                    .iter()
                    .zip(&self.hold)
                    .all(|(c, h)| (*c as f64 - h).abs() <= self.config.mirror_tolerance);
                if needed == flags::JNT_POS && !mirrored {
                    return Some(KrcEvent::InterpolationError);
                }
                self.strategy = strategy;
                self.state = InterfaceState::Command;
                self.command = Some(*cmd);
                self.consecutive_misses = 0;
                self.ack = 1;
                self.fault = None;
                Some(KrcEvent::EnteredCommand)
            }
        }
    }

    /// Closes a cycle: grades it, and in command mode falls back after too many misses or a poor grade.
    pub fn end_of_cycle(&mut self) -> Option<KrcEvent> {
        let answered = std::mem::take(&mut self.answered);
        self.history.push_back(answered);
        if self.history.len() > self.config.quality.window {
            self.history.pop_front();
        }
        if answered {
            self.consecutive_misses = 0;
        } else {
            self.consecutive_misses += 1;
            self.missed_cycles += 1;
        }
        if self.state == InterfaceState::Command {
            let q = self.hold;
            if self.consecutive_misses > self.config.max_consecutive_misses {
                return Some(
                    self.fall_back(format!("{} consecutive cycles without an answer", self.consecutive_misses), q),
                );
            }
            if self.quality() == Quality::Unacceptable {
                return Some(self.fall_back("communication quality unacceptable".into(), q));
            }
        }
        None
    }

    /// How the motors are driven this step. In joint impedance the law τ = k (q_cmd − q) − D q̇ + g(q) + τ_FRI
    /// with D_j = 2 d_j √(k_j M_jj); in position control the commanded joint positions; brakes in monitor
    /// mode or with the drives off.
    pub fn drive(&mut self, model: &Model, data: &mut Data, q: &[f64; 7], dq: &[f64; 7]) -> Drive {
        if self.state != InterfaceState::Command || !self.drives_ready() {
            self.hold = *q;
            return Drive::Brakes;
        }
        let Some(cmd) = self.command.as_ref() else { return Drive::Brakes };
        match self.strategy {
            STRATEGY_JOINT_IMPEDANCE => {}
            STRATEGY_POSITION => return Drive::Position(cmd.jnt_pos.map(f64::from)),
            _ => return Drive::Position(self.hold),
        }
        let needs_mass = cmd.jnt_stiffness.iter().any(|k| *k != 0.0);
        let diag: [f64; 7] = if needs_mass {
            let m = model.mass_matrix(data, q);
            std::array::from_fn(|i| m[(i, i)])
        } else {
            [0.0; 7]
        };
        let g = model.gravity_torques(data, q);
        Drive::Torque(std::array::from_fn(|i| {
            let k = cmd.jnt_stiffness[i] as f64;
            let d = 2.0 * cmd.jnt_damping[i] as f64 * (k * diag[i]).max(0.0).sqrt();
            k * (cmd.jnt_pos[i] as f64 - q[i]) - d * dq[i] + g[i] + cmd.add_jnt_trq[i] as f64
        }))
    }

    /// The measurement datagram of this cycle.
    #[allow(clippy::too_many_arguments)]
    pub fn measurement(
        &mut self,
        model: &Model,
        data: &mut Data,
        tool: FrameId,
        q: &[f64; 7],
        torque: &[f64; 7],
        contact_force: &nalgebra::Vector3<f64>,
        time: f64,
        rng: &mut impl Rng,
    ) -> fri::Measurement {
        self.send_seq = self.send_seq.wrapping_add(1);
        let noise = Normal::new(0.0, self.config.torque_noise.max(1e-300)).expect("finite σ");
        let mut sample = |v: f64| (v + if self.config.torque_noise > 0.0 { noise.sample(rng) } else { 0.0 }) as f32;
        model.forward_kinematics(data, q);
        let pose = model.frame_pose(data, tool);
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let p = pose.translation.vector;
        let frame: [f32; 12] = std::array::from_fn(|k| {
            let (row, col) = (k / 4, k % 4);
            (if col == 3 { p[row] } else { r[(row, col)] }) as f32
        });
        let jac = &mut self.jacobian;
        model.frame_jacobian(data, tool, Axes::World, jac);
        // FRI row order X Y Z RZ RY RX.
        let rows = [0usize, 1, 2, 5, 4, 3];
        let jacobian: [f32; 42] = std::array::from_fn(|k| jac[(rows[k / 7], k % 7)] as f32);
        // The contact's joint torques, Jᵀ w: what the KRC's external-torque estimate sees.
        let external: [f64; 7] = std::array::from_fn(|j| (0..3).map(|r| jac[(r, j)] * contact_force[r]).sum::<f64>());
        let m = model.mass_matrix(data, q);
        let mass_matrix: [f32; 49] = std::array::from_fn(|k| m[(k / 7, k % 7)] as f32);
        let g = model.gravity_torques(data, q);
        let gravity: [f32; 7] = std::array::from_fn(|i| g[i] as f32);
        let cmd_pos: [f32; 7] = match (&self.state, &self.command) {
            (InterfaceState::Command, Some(c)) => c.jnt_pos,
            _ => std::array::from_fn(|i| self.hold[i] as f32),
        };
        let mut krl = fri::KrlData::default();
        krl.int[1] = self.ack;
        if self.config.program == KrlProgram::Softcontact && self.ack == 1 {
            krl.int[0] = self.strategy;
        }
        let history = self.history.len().max(1) as f32;
        fri::Measurement {
            header: fri::Header {
                send_seq: self.send_seq,
                refl_seq: self.last_remote_seq,
                packet_size: fri::MEASUREMENT_SIZE as u16,
                datagram_id: fri::MEASUREMENT_ID,
            },
            krl,
            intf: fri::Interface {
                timestamp: time as f32,
                state: self.state,
                quality: self.quality(),
                desired_msr_sample_time: self.config.cycle as f32,
                desired_cmd_sample_time: self.config.cycle as f32,
                safety_limits: 1.0,
                stat: fri::Statistics {
                    answer_rate: self.answer_rate() as f32,
                    latency: 0.0,
                    jitter: 0.0,
                    miss_rate: self.history.iter().filter(|a| !**a).count() as f32 / history,
                    miss_counter: self.missed_cycles as u32,
                },
            },
            robot: fri::Robot {
                power: self.power,
                control: control_mode(self.strategy),
                error: self.error,
                warning: self.warning,
                temperature: [35.0; 7],
            },
            data: fri::MeasuredData {
                msr_jnt_pos: std::array::from_fn(|i| q[i] as f32),
                msr_cart_pos: frame,
                cmd_jnt_pos: cmd_pos,
                cmd_jnt_pos_fri_offset: [0.0; 7],
                cmd_cart_pos: frame,
                cmd_cart_pos_fri_offset: [0.0; 12],
                msr_jnt_trq: std::array::from_fn(|i| sample(torque[i])),
                est_ext_jnt_trq: std::array::from_fn(|i| sample(external[i])),
                est_ext_tcp_ft: [0.0; 6],
                jacobian,
                mass_matrix,
                gravity,
            },
        }
    }
}
