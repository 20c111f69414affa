//! FRI 1.x of the KUKA LWR IV / KRC2lr (datagram ids 0x2006 / 0x1005): the KRC sends a 916-byte
//! measurement every cycle, the remote answers each with a 376-byte command. Little-endian, offsets
//! per `friComm.h`; see docs/protocols/fri-lwr4.md for every field.

use crate::WireError;
use crate::bytes::{Reader, Writer};

pub const MEASUREMENT_SIZE: usize = 916;
pub const COMMAND_SIZE: usize = 376;
pub const MEASUREMENT_ID: u16 = 0x2006;
pub const COMMAND_ID: u16 = 0x1005;
/// The conventional UDP port of the remote (the PC side).
pub const DEFAULT_PORT: u16 = 49938;

/// `tFriHeader`, both directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Header {
    /// The sender's own counter, +1 per datagram, wrapping.
    pub send_seq: u16,
    /// The peer's `send_seq` of the last datagram received.
    pub refl_seq: u16,
    pub packet_size: u16,
    pub datagram_id: u16,
}

/// `tFriKrlData`: the KRL exchange variables (`$FRI_TO_*` in measurements, `$FRI_FRM_*` in commands).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KrlData {
    pub real: [f32; 16],
    pub int: [i32; 16],
    /// Bit i is `$FRI_…_BOOL[i+1]`.
    pub bools: u16,
    pub fill: u16,
}

/// `intf.state` (FRI_STATE).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InterfaceState {
    Off,
    Monitor,
    Command,
    /// −1 on the controller, 0xFFFF on the wire, or any value the protocol does not define.
    Invalid(u16),
}

impl InterfaceState {
    pub fn from_wire(v: u16) -> Self {
        match v {
            0 => Self::Off,
            1 => Self::Monitor,
            2 => Self::Command,
            other => Self::Invalid(other),
        }
    }
    pub fn to_wire(self) -> u16 {
        match self {
            Self::Off => 0,
            Self::Monitor => 1,
            Self::Command => 2,
            Self::Invalid(v) => v,
        }
    }
}

/// `intf.quality` (FRI_QUALITY): commanding is allowed from `Bad` up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Quality {
    Invalid(u16),
    Unacceptable,
    Bad,
    Ok,
    Perfect,
}

impl Quality {
    pub fn from_wire(v: u16) -> Self {
        match v {
            0 => Self::Unacceptable,
            1 => Self::Bad,
            2 => Self::Ok,
            3 => Self::Perfect,
            other => Self::Invalid(other),
        }
    }
    pub fn to_wire(self) -> u16 {
        match self {
            Self::Unacceptable => 0,
            Self::Bad => 1,
            Self::Ok => 2,
            Self::Perfect => 3,
            Self::Invalid(v) => v,
        }
    }
}

/// `robot.control` (FRI_CTRL): the control law the KRC is running.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlMode {
    Other,
    Position,
    CartesianImpedance,
    JointImpedance,
    Unknown(u16),
}

impl ControlMode {
    pub fn from_wire(v: u16) -> Self {
        match v {
            0 => Self::Other,
            1 => Self::Position,
            2 => Self::CartesianImpedance,
            3 => Self::JointImpedance,
            other => Self::Unknown(other),
        }
    }
    pub fn to_wire(self) -> u16 {
        match self {
            Self::Other => 0,
            Self::Position => 1,
            Self::CartesianImpedance => 2,
            Self::JointImpedance => 3,
            Self::Unknown(v) => v,
        }
    }
}

/// `intf.stat`: the KRC's view of the remote's timing over the last 100 packets.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Statistics {
    pub answer_rate: f32,
    pub latency: f32,
    pub jitter: f32,
    pub miss_rate: f32,
    pub miss_counter: u32,
}

/// `intf`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interface {
    pub timestamp: f32,
    pub state: InterfaceState,
    pub quality: Quality,
    pub desired_msr_sample_time: f32,
    pub desired_cmd_sample_time: f32,
    pub safety_limits: f32,
    pub stat: Statistics,
}

/// `robot`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Robot {
    /// Drive power bits; non-zero means drives on.
    pub power: u16,
    pub control: ControlMode,
    pub error: u16,
    pub warning: u16,
    pub temperature: [f32; 7],
}

/// `data`: measured and commanded state and the KRC's own model terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredData {
    pub msr_jnt_pos: [f32; 7],
    /// 3×4 row-major frame; indices 3, 7, 11 are the translation.
    pub msr_cart_pos: [f32; 12],
    pub cmd_jnt_pos: [f32; 7],
    pub cmd_jnt_pos_fri_offset: [f32; 7],
    pub cmd_cart_pos: [f32; 12],
    pub cmd_cart_pos_fri_offset: [f32; 12],
    pub msr_jnt_trq: [f32; 7],
    pub est_ext_jnt_trq: [f32; 7],
    /// Fx Fy Fz Tz Ty Tx.
    pub est_ext_tcp_ft: [f32; 6],
    /// 6×7 row-major, rows X Y Z RZ RY RX.
    pub jacobian: [f32; 42],
    pub mass_matrix: [f32; 49],
    pub gravity: [f32; 7],
}

/// `tFriMsrData`, KRC → remote.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    pub header: Header,
    pub krl: KrlData,
    pub intf: Interface,
    pub robot: Robot,
    pub data: MeasuredData,
}

/// `cmd.cmdFlags` bits.
pub mod flags {
    pub const JNT_POS: u32 = 0x0001;
    pub const JNT_TRQ: u32 = 0x0004;
    pub const JNT_STIFF: u32 = 0x0010;
    pub const JNT_DAMP: u32 = 0x0020;
    pub const CART_POS: u32 = 0x0100;
    pub const TCP_FT: u32 = 0x0400;
    pub const CART_STIFF: u32 = 0x1000;
    pub const CART_DAMP: u32 = 0x2000;
    /// Joint impedance with additional torque: what joint-torque control on the LWR IV is.
    pub const JOINT_IMPEDANCE: u32 = JNT_POS | JNT_TRQ | JNT_STIFF | JNT_DAMP;
}

/// `tFriCmdData`, remote → KRC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    pub header: Header,
    pub krl: KrlData,
    pub flags: u32,
    pub jnt_pos: [f32; 7],
    pub cart_pos: [f32; 12],
    pub add_jnt_trq: [f32; 7],
    /// Fx Fy Fz Tz Ty Tx.
    pub add_tcp_ft: [f32; 6],
    pub jnt_stiffness: [f32; 7],
    pub jnt_damping: [f32; 7],
    pub cart_stiffness: [f32; 6],
    pub cart_damping: [f32; 6],
}

impl Default for Command {
    fn default() -> Self {
        Self {
            header: Header { packet_size: COMMAND_SIZE as u16, datagram_id: COMMAND_ID, ..Default::default() },
            krl: KrlData::default(),
            flags: 0,
            jnt_pos: [0.0; 7],
            cart_pos: [0.0; 12],
            add_jnt_trq: [0.0; 7],
            add_tcp_ft: [0.0; 6],
            jnt_stiffness: [0.0; 7],
            jnt_damping: [0.0; 7],
            cart_stiffness: [0.0; 6],
            cart_damping: [0.0; 6],
        }
    }
}

fn read_header(r: &mut Reader) -> Header {
    Header { send_seq: r.u16(), refl_seq: r.u16(), packet_size: r.u16(), datagram_id: r.u16() }
}

fn write_header(w: &mut Writer, h: &Header) {
    w.u16(h.send_seq);
    w.u16(h.refl_seq);
    w.u16(h.packet_size);
    w.u16(h.datagram_id);
}

fn read_krl(r: &mut Reader) -> KrlData {
    KrlData { real: r.f32s(), int: r.i32s(), bools: r.u16(), fill: r.u16() }
}

fn write_krl(w: &mut Writer, k: &KrlData) {
    w.f32s(&k.real);
    w.i32s(&k.int);
    w.u16(k.bools);
    w.u16(k.fill);
}

/// Checks length, size field and datagram id before any field is trusted.
fn check_frame(bytes: &[u8], size: usize, id: u16, what: &'static str) -> Result<(), WireError> {
    if bytes.len() != size {
        return Err(WireError::Length { what, expected: size, got: bytes.len() });
    }
    let packet_size = u16::from_le_bytes([bytes[4], bytes[5]]);
    if packet_size as usize != size {
        return Err(WireError::SizeField { what, expected: size as u16, got: packet_size });
    }
    let datagram_id = u16::from_le_bytes([bytes[6], bytes[7]]);
    if datagram_id != id {
        return Err(WireError::DatagramId { what, expected: id, got: datagram_id });
    }
    Ok(())
}

/// Refuses a datagram carrying NaN or ±∞ in a field the control loop would use.
fn check_finite(what: &'static str, field: &'static str, values: &[f32]) -> Result<(), WireError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(WireError::NonFinite { what, field, index }),
        None => Ok(()),
    }
}

impl Measurement {
    pub fn decode(bytes: &[u8]) -> Result<Self, WireError> {
        const WHAT: &str = "FRI measurement";
        check_frame(bytes, MEASUREMENT_SIZE, MEASUREMENT_ID, WHAT)?;
        let mut r = Reader::le(bytes);
        let header = read_header(&mut r);
        let krl = read_krl(&mut r);
        let intf = Interface {
            timestamp: r.f32(),
            state: InterfaceState::from_wire(r.u16()),
            quality: Quality::from_wire(r.u16()),
            desired_msr_sample_time: r.f32(),
            desired_cmd_sample_time: r.f32(),
            safety_limits: r.f32(),
            stat: Statistics {
                answer_rate: r.f32(),
                latency: r.f32(),
                jitter: r.f32(),
                miss_rate: r.f32(),
                miss_counter: r.u32(),
            },
        };
        let robot = Robot {
            power: r.u16(),
            control: ControlMode::from_wire(r.u16()),
            error: r.u16(),
            warning: r.u16(),
            temperature: r.f32s(),
        };
        let data = MeasuredData {
            msr_jnt_pos: r.f32s(),
            msr_cart_pos: r.f32s(),
            cmd_jnt_pos: r.f32s(),
            cmd_jnt_pos_fri_offset: r.f32s(),
            cmd_cart_pos: r.f32s(),
            cmd_cart_pos_fri_offset: r.f32s(),
            msr_jnt_trq: r.f32s(),
            est_ext_jnt_trq: r.f32s(),
            est_ext_tcp_ft: r.f32s(),
            jacobian: r.f32s(),
            mass_matrix: r.f32s(),
            gravity: r.f32s(),
        };
        debug_assert_eq!(r.pos(), MEASUREMENT_SIZE);
        let d = &data;
        for (field, values) in [
            ("msrJntPos", &d.msr_jnt_pos[..]),
            ("msrCartPos", &d.msr_cart_pos[..]),
            ("cmdJntPos", &d.cmd_jnt_pos[..]),
            ("cmdJntPosFriOffset", &d.cmd_jnt_pos_fri_offset[..]),
            ("msrJntTrq", &d.msr_jnt_trq[..]),
            ("estExtJntTrq", &d.est_ext_jnt_trq[..]),
            ("estExtTcpFT", &d.est_ext_tcp_ft[..]),
            ("jacobian", &d.jacobian[..]),
            ("massMatrix", &d.mass_matrix[..]),
            ("gravity", &d.gravity[..]),
        ] {
            check_finite(WHAT, field, values)?;
        }
        Ok(Self { header, krl, intf, robot, data })
    }

    pub fn encode(&self) -> [u8; MEASUREMENT_SIZE] {
        let mut out = [0u8; MEASUREMENT_SIZE];
        let mut w = Writer::le(&mut out);
        write_header(&mut w, &self.header);
        write_krl(&mut w, &self.krl);
        let i = &self.intf;
        w.f32(i.timestamp);
        w.u16(i.state.to_wire());
        w.u16(i.quality.to_wire());
        w.f32(i.desired_msr_sample_time);
        w.f32(i.desired_cmd_sample_time);
        w.f32(i.safety_limits);
        w.f32(i.stat.answer_rate);
        w.f32(i.stat.latency);
        w.f32(i.stat.jitter);
        w.f32(i.stat.miss_rate);
        w.u32(i.stat.miss_counter);
        let r = &self.robot;
        w.u16(r.power);
        w.u16(r.control.to_wire());
        w.u16(r.error);
        w.u16(r.warning);
        w.f32s(&r.temperature);
        let d = &self.data;
        for block in [
            &d.msr_jnt_pos[..],
            &d.msr_cart_pos[..],
            &d.cmd_jnt_pos[..],
            &d.cmd_jnt_pos_fri_offset[..],
            &d.cmd_cart_pos[..],
            &d.cmd_cart_pos_fri_offset[..],
            &d.msr_jnt_trq[..],
            &d.est_ext_jnt_trq[..],
            &d.est_ext_tcp_ft[..],
            &d.jacobian[..],
            &d.mass_matrix[..],
            &d.gravity[..],
        ] {
            w.f32s(block);
        }
        debug_assert_eq!(w.pos(), MEASUREMENT_SIZE);
        out
    }
}

impl Command {
    pub fn decode(bytes: &[u8]) -> Result<Self, WireError> {
        const WHAT: &str = "FRI command";
        check_frame(bytes, COMMAND_SIZE, COMMAND_ID, WHAT)?;
        let mut r = Reader::le(bytes);
        let cmd = Self {
            header: read_header(&mut r),
            krl: read_krl(&mut r),
            flags: r.u32(),
            jnt_pos: r.f32s(),
            cart_pos: r.f32s(),
            add_jnt_trq: r.f32s(),
            add_tcp_ft: r.f32s(),
            jnt_stiffness: r.f32s(),
            jnt_damping: r.f32s(),
            cart_stiffness: r.f32s(),
            cart_damping: r.f32s(),
        };
        debug_assert_eq!(r.pos(), COMMAND_SIZE);
        for (field, values) in [
            ("jntPos", &cmd.jnt_pos[..]),
            ("cartPos", &cmd.cart_pos[..]),
            ("addJntTrq", &cmd.add_jnt_trq[..]),
            ("addTcpFT", &cmd.add_tcp_ft[..]),
            ("jntStiffness", &cmd.jnt_stiffness[..]),
            ("jntDamping", &cmd.jnt_damping[..]),
            ("cartStiffness", &cmd.cart_stiffness[..]),
            ("cartDamping", &cmd.cart_damping[..]),
        ] {
            check_finite(WHAT, field, values)?;
        }
        Ok(cmd)
    }

    pub fn encode(&self) -> [u8; COMMAND_SIZE] {
        let mut out = [0u8; COMMAND_SIZE];
        let mut w = Writer::le(&mut out);
        write_header(&mut w, &self.header);
        write_krl(&mut w, &self.krl);
        w.u32(self.flags);
        for block in [
            &self.jnt_pos[..],
            &self.cart_pos[..],
            &self.add_jnt_trq[..],
            &self.add_tcp_ft[..],
            &self.jnt_stiffness[..],
            &self.jnt_damping[..],
            &self.cart_stiffness[..],
            &self.cart_damping[..],
        ] {
            w.f32s(block);
        }
        debug_assert_eq!(w.pos(), COMMAND_SIZE);
        out
    }
}

/// Datagrams missed between two sequence counters (wrap-aware): 0 when `next` follows `prev`,
/// negative for a repeated or reordered datagram.
pub fn sequence_gap(prev: u16, next: u16) -> i32 {
    next.wrapping_sub(prev).wrapping_sub(1) as i16 as i32
}
