//! The hardware boundary as bytes: codecs of the KUKA LWR IV's FRI ([`fri`]) and the ATI Net F/T's RDT
//! ([`rdt`]), and the Net F/T's settings page ([`netft_xml`]). No sockets: the driver nodes and the simulator share these codecs, so nothing else in
//! the product knows the wire formats. Every decoder checks length, size fields and ids before it
//! trusts a field, refuses NaN or ±∞ in control data, and never panics on any input.

mod bytes;
pub mod fri;
pub mod netft_xml;
pub mod rdt;

/// Why a datagram was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("{what}: {got} bytes, expected {expected}")]
    Length { what: &'static str, expected: usize, got: usize },
    #[error("{what}: packet size field says {got}, expected {expected}")]
    SizeField { what: &'static str, expected: u16, got: u16 },
    #[error("{what}: id {got:#06x}, expected {expected:#06x}")]
    DatagramId { what: &'static str, expected: u16, got: u16 },
    #[error("{what}: {field}[{index}] is not a finite number")]
    NonFinite { what: &'static str, field: &'static str, index: usize },
    #[error("RDT request: unknown command {code:#06x}")]
    UnknownCommand { code: u16 },
    #[error("unsupported unit or calibration: {0}")]
    Unit(String),
    #[error("the box's netftapi2.xml: {0}")]
    Settings(String),
}
