//! FRI codec against bytes laid out by hand from docs/protocols/fri-lwr4.md (offsets written out here, not
//! taken from the codec), round trips, and refusal of anything malformed.

use proptest::prelude::*;
use softcontact_wire::WireError;
use softcontact_wire::fri::{self, Command, ControlMode, InterfaceState, Measurement, Quality, flags};

fn put_u16(b: &mut [u8], off: usize, v: u16) {
    b[off..off + 2].copy_from_slice(&v.to_le_bytes());
}
fn put_u32(b: &mut [u8], off: usize, v: u32) {
    b[off..off + 4].copy_from_slice(&v.to_le_bytes());
}
fn put_f32(b: &mut [u8], off: usize, v: f32) {
    put_u32(b, off, v.to_bits());
}

fn golden_measurement() -> Vec<u8> {
    let mut b = vec![0u8; 916];
    put_u16(&mut b, 0, 0xFFFF); // sendSeqCount
    put_u16(&mut b, 2, 41); // reflSeqCount
    put_u16(&mut b, 4, 916);
    put_u16(&mut b, 6, 0x2006);
    put_f32(&mut b, 8, 1.5); // $FRI_TO_REA[1]
    put_u32(&mut b, 72 + 15 * 4, (-20i32) as u32); // $FRI_TO_INT[16]
    put_u16(&mut b, 136, 0b101); // $FRI_TO_BOOL[1], [3]
    put_f32(&mut b, 140, 12.25); // timestamp
    put_u16(&mut b, 144, 2); // state CMD
    put_u16(&mut b, 146, 3); // quality PERFECT
    put_f32(&mut b, 148, 0.001);
    put_f32(&mut b, 152, 0.001);
    put_f32(&mut b, 160, 0.99); // answerRate
    put_u32(&mut b, 176, 7); // missCounter
    put_u16(&mut b, 180, 0x7F); // power
    put_u16(&mut b, 182, 3); // JNT_IMP
    put_f32(&mut b, 188 + 6 * 4, 41.0); // temperature A6
    put_f32(&mut b, 216 + 2 * 4, -0.75); // msrJntPos E1
    put_f32(&mut b, 244 + 3 * 4, 0.5); // msrCartPos px
    put_f32(&mut b, 244 + 11 * 4, 0.9); // msrCartPos pz
    put_f32(&mut b, 292, 0.125); // cmdJntPos A1
    put_f32(&mut b, 320 + 6 * 4, 0.01); // cmdJntPosFriOffset A6
    put_f32(&mut b, 444 + 6 * 4, 2.5); // msrJntTrq A6
    put_f32(&mut b, 472, -3.0); // estExtJntTrq A1
    put_f32(&mut b, 500 + 2 * 4, -12.0); // estExtTcpFT Fz
    put_f32(&mut b, 500 + 3 * 4, 0.3); // estExtTcpFT Tz
    put_f32(&mut b, 524 + 41 * 4, 0.2); // jacobian[5][6]
    put_f32(&mut b, 692 + 48 * 4, 0.0008); // massMatrix[6][6]
    put_f32(&mut b, 888 + 4, -48.9); // gravity A2 (index 1)
    b
}

#[test]
fn measurement_fields_sit_at_the_documented_offsets() {
    let bytes = golden_measurement();
    let m = Measurement::decode(&bytes).unwrap();
    assert_eq!(
        (m.header.send_seq, m.header.refl_seq, m.header.packet_size, m.header.datagram_id),
        (0xFFFF, 41, 916, 0x2006)
    );
    assert_eq!(m.krl.real[0], 1.5);
    assert_eq!(m.krl.int[15], -20);
    assert_eq!(m.krl.bools, 0b101);
    assert_eq!(m.intf.timestamp, 12.25);
    assert_eq!(m.intf.state, InterfaceState::Command);
    assert_eq!(m.intf.quality, Quality::Perfect);
    assert_eq!(m.intf.desired_msr_sample_time, 0.001);
    assert_eq!(m.intf.stat.answer_rate, 0.99);
    assert_eq!(m.intf.stat.miss_counter, 7);
    assert_eq!((m.robot.power, m.robot.control), (0x7F, ControlMode::JointImpedance));
    assert_eq!(m.robot.temperature[6], 41.0);
    assert_eq!(m.data.msr_jnt_pos[2], -0.75);
    assert_eq!((m.data.msr_cart_pos[3], m.data.msr_cart_pos[11]), (0.5, 0.9));
    assert_eq!(m.data.cmd_jnt_pos[0], 0.125);
    assert_eq!(m.data.cmd_jnt_pos_fri_offset[6], 0.01);
    assert_eq!(m.data.msr_jnt_trq[6], 2.5);
    assert_eq!(m.data.est_ext_jnt_trq[0], -3.0);
    assert_eq!((m.data.est_ext_tcp_ft[2], m.data.est_ext_tcp_ft[3]), (-12.0, 0.3));
    assert_eq!(m.data.jacobian[41], 0.2);
    assert_eq!(m.data.mass_matrix[48], 0.0008);
    assert_eq!(m.data.gravity[1], -48.9);
    assert_eq!(m.encode().to_vec(), bytes, "encoding the decoded measurement gives the same bytes");
}

#[test]
fn command_fields_sit_at_the_documented_offsets() {
    let mut b = vec![0u8; 376];
    put_u16(&mut b, 0, 9);
    put_u16(&mut b, 2, 0xFFFF);
    put_u16(&mut b, 4, 376);
    put_u16(&mut b, 6, 0x1005);
    put_u32(&mut b, 72 + 14 * 4, 30); // $FRI_FRM_INT[15] = joint impedance strategy
    put_u32(&mut b, 140, 0x0035);
    put_f32(&mut b, 144, 0.1); // jntPos A1
    put_f32(&mut b, 172 + 11 * 4, 0.8); // cartPos pz
    put_f32(&mut b, 220 + 6 * 4, -1.25); // addJntTrq A6
    put_f32(&mut b, 248 + 5 * 4, 0.4); // addTcpFT Tx
    put_f32(&mut b, 272, 0.0); // jntStiffness A1
    put_f32(&mut b, 300 + 6 * 4, 0.7); // jntDamping A6
    put_f32(&mut b, 328, 2000.0); // cartStiffness Cx
    put_f32(&mut b, 352 + 5 * 4, 0.7); // cartDamping Cc
    let c = Command::decode(&b).unwrap();
    assert_eq!((c.header.send_seq, c.header.refl_seq), (9, 0xFFFF));
    assert_eq!(c.krl.int[14], 30);
    assert_eq!(c.flags, flags::JOINT_IMPEDANCE);
    assert_eq!((c.jnt_pos[0], c.cart_pos[11], c.add_jnt_trq[6], c.add_tcp_ft[5]), (0.1, 0.8, -1.25, 0.4));
    assert_eq!((c.jnt_damping[6], c.cart_stiffness[0], c.cart_damping[5]), (0.7, 2000.0, 0.7));
    assert_eq!(c.encode().to_vec(), b);
}

#[test]
fn floats_are_little_endian_binary32() {
    // The SDK's self-test: 0x40490FDB is π and travels as DB 0F 49 40.
    let mut c = Command::default();
    c.jnt_pos[0] = f32::from_bits(0x4049_0FDB);
    assert_eq!(&c.encode()[144..148], &[0xDB, 0x0F, 0x49, 0x40]);
    assert!((c.jnt_pos[0] - std::f32::consts::PI).abs() < 1e-6);
}

#[test]
fn malformed_datagrams_are_refused_with_the_reason() {
    let good = golden_measurement();
    assert!(matches!(Measurement::decode(&good[..915]), Err(WireError::Length { expected: 916, got: 915, .. })));
    let mut longer = good.clone();
    longer.push(0);
    assert!(matches!(Measurement::decode(&longer), Err(WireError::Length { .. })));
    let mut wrong_id = good.clone();
    put_u16(&mut wrong_id, 6, 0x1005);
    assert!(matches!(Measurement::decode(&wrong_id), Err(WireError::DatagramId { got: 0x1005, .. })));
    let mut wrong_size = good.clone();
    put_u16(&mut wrong_size, 4, 376);
    assert!(matches!(Measurement::decode(&wrong_size), Err(WireError::SizeField { got: 376, .. })));
    let mut nan = good.clone();
    put_f32(&mut nan, 888 + 3 * 4, f32::NAN);
    let err = Measurement::decode(&nan).unwrap_err();
    assert_eq!(err, WireError::NonFinite { what: "FRI measurement", field: "gravity", index: 3 });
    assert!(err.to_string().contains("gravity[3]"), "{err}");
    let mut cmd = Command::default().encode();
    put_f32(&mut cmd, 220, f32::INFINITY);
    assert!(matches!(Command::decode(&cmd), Err(WireError::NonFinite { field: "addJntTrq", index: 0, .. })));
    assert!(matches!(Command::decode(&good), Err(WireError::Length { .. })), "a measurement is not a command");
}

#[test]
fn sequence_gaps_wrap() {
    assert_eq!(fri::sequence_gap(10, 11), 0);
    assert_eq!(fri::sequence_gap(65535, 0), 0);
    assert_eq!(fri::sequence_gap(65534, 2), 3);
    assert_eq!(fri::sequence_gap(11, 11), -1);
    assert_eq!(fri::sequence_gap(11, 9), -3);
}

proptest! {
    /// Any 916 bytes with a valid header either decode and re-encode to the same bytes, or are refused
    /// for a non-finite control value.
    #[test]
    fn measurement_round_trips_bit_exactly(mut bytes in prop::collection::vec(any::<u8>(), 916)) {
        put_u16(&mut bytes, 4, 916);
        put_u16(&mut bytes, 6, 0x2006);
        match Measurement::decode(&bytes) {
            Ok(m) => prop_assert_eq!(m.encode().to_vec(), bytes),
            Err(e) => prop_assert!(matches!(e, WireError::NonFinite { .. }), "{}", e),
        }
    }

    #[test]
    fn command_round_trips_bit_exactly(mut bytes in prop::collection::vec(any::<u8>(), 376)) {
        put_u16(&mut bytes, 4, 376);
        put_u16(&mut bytes, 6, 0x1005);
        match Command::decode(&bytes) {
            // Bytes, not structs: the KRL exchange block is passed through as is, NaN included.
            Ok(c) => prop_assert_eq!(c.encode().to_vec(), bytes),
            Err(e) => prop_assert!(matches!(e, WireError::NonFinite { .. }), "{}", e),
        }
    }

    #[test]
    fn decoding_any_bytes_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..1200)) {
        let _ = Measurement::decode(&bytes);
        let _ = Command::decode(&bytes);
    }
}
