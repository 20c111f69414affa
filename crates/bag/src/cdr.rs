//! CDR as ROS 2 stores it: a 4-byte encapsulation header (`00 01` little endian, `00 00` big endian,
//! then two option bytes), then the message with alignment counted from after the header.

use byteorder::{BigEndian, LittleEndian};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// The encapsulation header the project writes: CDR, little endian.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Encodes `msg` into `out` (cleared first), header included; `out` keeps its capacity between calls.
pub fn encode_into<T: Serialize>(msg: &T, out: &mut Vec<u8>) -> Result<(), String> {
    out.clear();
    out.extend_from_slice(&CDR_LE);
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut *out, msg).map_err(|e| e.to_string())
}

pub fn encode<T: Serialize>(msg: &T) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    encode_into(msg, &mut out)?;
    Ok(out)
}

/// Decodes one message, either byte order; trailing padding is allowed, a short buffer is not.
pub fn decode<T: DeserializeOwned>(data: &[u8]) -> Result<T, String> {
    let Some((header, body)) = data.split_first_chunk::<4>() else {
        return Err(format!("{} bytes: shorter than the CDR encapsulation header", data.len()));
    };
    let decoded = match header[..2] {
        [0x00, 0x01] | [0x00, 0x03] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        [0x00, 0x00] | [0x00, 0x02] => cdr_encoding::from_bytes::<T, BigEndian>(body),
        _ => return Err(format!("unknown CDR encapsulation {:02x} {:02x}", header[0], header[1])),
    };
    decoded.map(|(msg, _)| msg).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use softcontact_msgs::builtin_interfaces::Time;
    use softcontact_msgs::geometry_msgs::{Vector3, Wrench, WrenchStamped};
    use softcontact_msgs::std_msgs::Header;

    fn wrench() -> WrenchStamped {
        WrenchStamped {
            header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "ft_sensor".into() },
            wrench: Wrench {
                force: Vector3 { x: 1.0, y: -2.0, z: -140.5 },
                torque: Vector3 { x: 0.1, y: 0.2, z: 0.3 },
            },
        }
    }

    #[test]
    fn header_then_body_aligned_from_after_the_header() {
        let bytes = encode(&wrench()).unwrap();
        assert_eq!(bytes[..4], CDR_LE);
        // Time (8) + string length (4) + "ft_sensor\0" (10) = 22 → padded to 24, then six f64.
        assert_eq!(bytes.len(), 4 + 24 + 48);
        assert_eq!(f64::from_le_bytes(bytes[4 + 24 + 16..4 + 24 + 24].try_into().unwrap()), -140.5);
        assert_eq!(decode::<WrenchStamped>(&bytes).unwrap(), wrench());
    }

    #[test]
    fn big_endian_input_decodes_too() {
        let mut bytes = vec![0x00, 0x00, 0x00, 0x00];
        bytes.extend(cdr_encoding::to_vec::<_, BigEndian>(&wrench()).unwrap());
        assert_eq!(decode::<WrenchStamped>(&bytes).unwrap(), wrench());
    }

    #[test]
    fn short_or_foreign_data_is_an_error() {
        assert!(decode::<WrenchStamped>(&[0x00, 0x01]).unwrap_err().contains("shorter"));
        assert!(decode::<WrenchStamped>(&[0x07, 0x01, 0, 0, 1, 2]).unwrap_err().contains("encapsulation"));
        let bytes = encode(&wrench()).unwrap();
        assert!(decode::<WrenchStamped>(&bytes[..30]).is_err());
    }
}
