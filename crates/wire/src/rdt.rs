//! ATI Net F/T Raw Data Transfer over UDP: 8-byte requests to the sensor, 36-byte records back (one per
//! datagram in real-time mode, several in buffered mode). Big-endian; see docs/protocols/netft-rdt.md.

use crate::WireError;
use crate::bytes::{Reader, Writer};

/// The sensor's RDT port.
pub const PORT: u16 = 49152;
pub const REQUEST_SIZE: usize = 8;
pub const RECORD_SIZE: usize = 36;
pub const REQUEST_HEADER: u16 = 0x1234;

/// RDT request commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RdtCommand {
    Stop,
    /// One record per datagram.
    StartRealTime,
    /// Several records per datagram.
    StartBuffered,
    StartMultiUnit,
    /// Clears the latched monitor condition.
    ResetLatch,
    /// Software bias (tare) in the box.
    SetBias,
}

impl RdtCommand {
    pub fn code(self) -> u16 {
        match self {
            Self::Stop => 0x0000,
            Self::StartRealTime => 0x0002,
            Self::StartBuffered => 0x0003,
            Self::StartMultiUnit => 0x0004,
            Self::ResetLatch => 0x0041,
            Self::SetBias => 0x0042,
        }
    }

    pub fn from_code(code: u16) -> Option<Self> {
        Some(match code {
            0x0000 => Self::Stop,
            0x0002 => Self::StartRealTime,
            0x0003 => Self::StartBuffered,
            0x0004 => Self::StartMultiUnit,
            0x0041 => Self::ResetLatch,
            0x0042 => Self::SetBias,
            _ => return None,
        })
    }
}

/// A request: the command and how many records to send (0 = until stopped).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Request {
    pub command: RdtCommand,
    pub sample_count: u32,
}

impl Request {
    pub fn encode(&self) -> [u8; REQUEST_SIZE] {
        let mut out = [0u8; REQUEST_SIZE];
        let mut w = Writer::be(&mut out);
        w.u16(REQUEST_HEADER);
        w.u16(self.command.code());
        w.u32(self.sample_count);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<Self, WireError> {
        const WHAT: &str = "RDT request";
        if bytes.len() != REQUEST_SIZE {
            return Err(WireError::Length { what: WHAT, expected: REQUEST_SIZE, got: bytes.len() });
        }
        let mut r = Reader::be(bytes);
        let header = r.u16();
        if header != REQUEST_HEADER {
            return Err(WireError::DatagramId { what: WHAT, expected: REQUEST_HEADER, got: header });
        }
        let code = r.u16();
        let command = RdtCommand::from_code(code).ok_or(WireError::UnknownCommand { code })?;
        Ok(Self { command, sample_count: r.u32() })
    }
}

/// One F/T record in counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Record {
    /// Position in the current stream (restarts with each start request).
    pub rdt_sequence: u32,
    /// The device's internal sample counter since power-up.
    pub ft_sequence: u32,
    pub status: Status,
    /// Fx Fy Fz Tx Ty Tz in counts.
    pub counts: [i32; 6],
}

impl Record {
    pub fn encode(&self) -> [u8; RECORD_SIZE] {
        let mut out = [0u8; RECORD_SIZE];
        self.encode_into(&mut out);
        out
    }

    fn encode_into(&self, out: &mut [u8]) {
        let mut w = Writer::be(out);
        w.u32(self.rdt_sequence);
        w.u32(self.ft_sequence);
        w.u32(self.status.0);
        w.i32s(&self.counts);
    }

    fn decode_exact(bytes: &[u8]) -> Self {
        let mut r = Reader::be(bytes);
        Self { rdt_sequence: r.u32(), ft_sequence: r.u32(), status: Status(r.u32()), counts: r.i32s() }
    }

    /// A real-time datagram: exactly one record.
    pub fn decode(bytes: &[u8]) -> Result<Self, WireError> {
        if bytes.len() != RECORD_SIZE {
            return Err(WireError::Length { what: "RDT record", expected: RECORD_SIZE, got: bytes.len() });
        }
        Ok(Self::decode_exact(bytes))
    }

    /// A buffered datagram: one or more whole records.
    pub fn decode_buffered(bytes: &[u8]) -> Result<impl Iterator<Item = Record> + '_, WireError> {
        if bytes.is_empty() || !bytes.len().is_multiple_of(RECORD_SIZE) {
            return Err(WireError::Length { what: "buffered RDT datagram", expected: RECORD_SIZE, got: bytes.len() });
        }
        Ok(bytes.chunks_exact(RECORD_SIZE).map(Self::decode_exact))
    }

    /// Several records into one buffered datagram.
    pub fn encode_buffered(records: &[Record]) -> Vec<u8> {
        let mut out = vec![0u8; records.len() * RECORD_SIZE];
        for (chunk, r) in out.chunks_exact_mut(RECORD_SIZE).zip(records) {
            r.encode_into(chunk);
        }
        out
    }
}

/// The status word: 0 is healthy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Status(pub u32);

impl Status {
    pub const ERROR_SUMMARY: u32 = 0x8000_0000;
    pub const SATURATION: u32 = 0x0002_0000;
    pub const MONITOR_LATCHED: u32 = 0x0001_0000;

    const BITS: [(u32, &'static str); 30] = [
        (0x8000_0000, "error summary"),
        (0x4000_0000, "CPU or RAM error"),
        (0x2000_0000, "digital board error"),
        (0x1000_0000, "analog board error"),
        (0x0800_0000, "serial link communication error"),
        (0x0400_0000, "program memory verification error"),
        (0x0200_0000, "halted due to configuration errors"),
        (0x0100_0000, "settings validation error"),
        (0x0080_0000, "configuration incompatible with calibration"),
        (0x0040_0000, "network communication failure"),
        (0x0020_0000, "CAN communication error"),
        (0x0010_0000, "RDT communication error"),
        (0x0008_0000, "EtherNet/IP protocol failure"),
        (0x0004_0000, "DeviceNet protocol failure"),
        (0x0002_0000, "transducer saturation or A/D error"),
        (0x0001_0000, "monitor condition latched"),
        (0x0000_4000, "watchdog timeout"),
        (0x0000_2000, "stack check error"),
        (0x0000_1000, "serial EEPROM failure"),
        (0x0000_0800, "serial flash failure"),
        (0x0000_0400, "analog board watchdog timeout"),
        (0x0000_0200, "excessive strain-gage excitation current"),
        (0x0000_0100, "insufficient strain-gage excitation current"),
        (0x0000_0080, "artificial analog ground out of range"),
        (0x0000_0040, "analog board supply too high"),
        (0x0000_0020, "analog board supply too low"),
        (0x0000_0010, "serial link data unavailable"),
        (0x0000_0008, "reference voltage or power monitoring error"),
        (0x0000_0004, "internal temperature error"),
        (0x0000_0002, "HTTP protocol failure"),
    ];

    pub fn is_ok(self) -> bool {
        self.0 == 0
    }

    /// Only the monitor latch (with its summary bit): a threshold event, not a fault.
    pub fn is_warning(self) -> bool {
        self.0 == Self::ERROR_SUMMARY | Self::MONITOR_LATCHED
    }

    pub fn is_error(self) -> bool {
        !self.is_ok() && !self.is_warning()
    }

    /// A saturated transducer: the sample must not be used for control.
    pub fn is_saturated(self) -> bool {
        self.0 & Self::SATURATION != 0
    }

    /// Names of the bits that are set.
    pub fn describe(self) -> Vec<&'static str> {
        Self::BITS.iter().filter(|(bit, _)| self.0 & bit != 0).map(|(_, name)| *name).collect()
    }
}

/// Counts → SI: the box's counts per force and torque unit and the units it is configured in
/// (`cfgcpf`, `cfgcpt`, `scfgfu`, `scfgtu` of netftapi2.xml).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    pub counts_per_force: f64,
    pub counts_per_torque: f64,
    /// Newtons per configured force unit.
    pub force_unit: f64,
    /// Newton-metres per configured torque unit.
    pub torque_unit: f64,
    /// Full-scale |value| per axis in SI (Gamma SI-130-10: 130 130 400 N, 10 10 10 N·m).
    pub range: [f64; 6],
}

impl Calibration {
    /// Gamma SI-130-10 in N and N·m with 1 000 000 counts per unit.
    pub fn gamma_si_130_10() -> Self {
        Self {
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: 1.0,
            torque_unit: 1.0,
            range: [130.0, 130.0, 400.0, 10.0, 10.0, 10.0],
        }
    }

    /// From the box's settings; unit names as netftapi2.xml spells them.
    pub fn from_settings(
        cpf: f64,
        cpt: f64,
        force_unit: &str,
        torque_unit: &str,
        range: [f64; 6],
    ) -> Result<Self, WireError> {
        let force = match force_unit {
            "N" => 1.0,
            "lbf" => 4.448_221_615_260_5,
            "klbf" => 4_448.221_615_260_5,
            "kN" => 1000.0,
            "kgf" => 9.806_65,
            "gf" => 9.806_65e-3,
            other => return Err(WireError::Unit(other.to_string())),
        };
        let torque = match torque_unit {
            "Nm" | "N-m" => 1.0,
            "Nmm" | "N-mm" => 1e-3,
            "lbf-in" => 0.112_984_829_027_616_7,
            "lbf-ft" => 1.355_817_948_331_400_4,
            "kgf-cm" | "kg-cm" => 0.098_066_5,
            "kN-m" | "kNm" => 1000.0,
            other => return Err(WireError::Unit(other.to_string())),
        };
        if !(cpf.is_finite() && cpf > 0.0 && cpt.is_finite() && cpt > 0.0) {
            return Err(WireError::Unit(format!("counts per unit must be positive (cpf {cpf}, cpt {cpt})")));
        }
        Ok(Self { counts_per_force: cpf, counts_per_torque: cpt, force_unit: force, torque_unit: torque, range })
    }

    /// Counts → [Fx Fy Fz] N and [Tx Ty Tz] N·m.
    pub fn to_si(&self, counts: &[i32; 6]) -> [f64; 6] {
        std::array::from_fn(|i| {
            if i < 3 {
                counts[i] as f64 / self.counts_per_force * self.force_unit
            } else {
                counts[i] as f64 / self.counts_per_torque * self.torque_unit
            }
        })
    }

    /// SI → counts, rounded (the quantisation of a real box) and clipped to the range; the flag says
    /// whether any axis was beyond it.
    pub fn to_counts(&self, wrench: &[f64; 6]) -> ([i32; 6], bool) {
        let mut saturated = false;
        let counts = std::array::from_fn(|i| {
            let limit = self.range[i];
            let v = if wrench[i].abs() > limit {
                saturated = true;
                limit.copysign(wrench[i])
            } else {
                wrench[i]
            };
            let per =
                if i < 3 { self.counts_per_force / self.force_unit } else { self.counts_per_torque / self.torque_unit };
            (v * per).round().clamp(i32::MIN as f64, i32::MAX as f64) as i32
        });
        (counts, saturated)
    }
}

/// Records missed between two RDT sequence numbers (wrap-aware): 0 when `next` follows `prev`,
/// negative for a duplicate or reordered record.
pub fn sequence_gap(prev: u32, next: u32) -> i64 {
    next.wrapping_sub(prev).wrapping_sub(1) as i32 as i64
}
