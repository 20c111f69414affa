//! RDT codec against bytes laid out by hand from docs/protocols/netft-rdt.md, units, status words, round trips.

use proptest::prelude::*;
use softcontact_wire::WireError;
use softcontact_wire::rdt::{self, Calibration, RdtCommand, Record, Request, Status};

#[test]
fn requests_are_big_endian_with_the_0x1234_header() {
    let start = Request { command: RdtCommand::StartRealTime, sample_count: 0 };
    assert_eq!(start.encode(), [0x12, 0x34, 0x00, 0x02, 0, 0, 0, 0]);
    // A count of 1 is a proper big-endian u32 (one public driver sent 0x00010001).
    let one = Request { command: RdtCommand::StartRealTime, sample_count: 1 };
    assert_eq!(one.encode(), [0x12, 0x34, 0x00, 0x02, 0, 0, 0, 1]);
    assert_eq!(Request { command: RdtCommand::SetBias, sample_count: 0 }.encode()[2..4], [0x00, 0x42]);
    assert_eq!(Request::decode(&[0x12, 0x34, 0, 0, 0, 0, 0, 0]).unwrap().command, RdtCommand::Stop);
    assert!(matches!(Request::decode(&[0x12, 0x35, 0, 2, 0, 0, 0, 0]), Err(WireError::DatagramId { .. })));
    assert!(matches!(Request::decode(&[0x12, 0x34, 0, 7, 0, 0, 0, 0]), Err(WireError::UnknownCommand { code: 7 })));
    assert!(matches!(Request::decode(&[0x12, 0x34, 0, 2]), Err(WireError::Length { .. })));
}

fn golden_record() -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&7u32.to_be_bytes());
    b.extend_from_slice(&123_456u32.to_be_bytes());
    b.extend_from_slice(&0u32.to_be_bytes());
    for c in [1_000_000i32, -2_500_000, -12_000_000, 50_000, -60_000, 7] {
        b.extend_from_slice(&c.to_be_bytes());
    }
    b
}

#[test]
fn records_decode_to_si_with_the_calibration() {
    let r = Record::decode(&golden_record()).unwrap();
    assert_eq!((r.rdt_sequence, r.ft_sequence, r.status), (7, 123_456, Status(0)));
    let si = Calibration::gamma_si_130_10().to_si(&r.counts);
    assert_eq!(si, [1.0, -2.5, -12.0, 0.05, -0.06, 7e-6]);
    assert_eq!(r.encode().to_vec(), golden_record());
    assert!(matches!(Record::decode(&golden_record()[..35]), Err(WireError::Length { .. })));
}

#[test]
fn units_other_than_si_are_converted() {
    // A box set to lbf and N-mm: 1000 counts per N·mm is 1 N·mm = 0.001 N·m, not 1 N·m.
    let cal = Calibration::from_settings(1_000.0, 1_000.0, "lbf", "N-mm", [130.0; 6]).unwrap();
    let si = cal.to_si(&[1000, 0, 0, 1000, 0, 0]);
    assert!((si[0] - 4.448_221_615_260_5).abs() < 1e-12 && (si[3] - 0.001).abs() < 1e-15);
    assert!(matches!(Calibration::from_settings(1.0, 1.0, "furlong", "Nm", [1.0; 6]), Err(WireError::Unit(_))));
    assert!(Calibration::from_settings(0.0, 1.0, "N", "Nm", [1.0; 6]).is_err());
}

#[test]
fn counts_saturate_at_the_range() {
    let cal = Calibration::gamma_si_130_10();
    let (counts, saturated) = cal.to_counts(&[10.0, 0.0, -450.0, 0.0, 0.0, 0.0]);
    assert!(saturated);
    assert_eq!(counts[2], -400_000_000);
    let (counts, saturated) = cal.to_counts(&[10.0000004, 0.0, -45.0, 0.0, 0.0, 0.0]);
    assert!(!saturated && counts[0] == 10_000_000 && counts[2] == -45_000_000);
}

#[test]
fn buffered_datagrams_carry_whole_records() {
    let records: Vec<Record> = (0..4).map(|i| Record { rdt_sequence: i, ..Default::default() }).collect();
    let bytes = Record::encode_buffered(&records);
    assert_eq!(bytes.len(), 4 * 36);
    assert_eq!(Record::decode_buffered(&bytes).unwrap().collect::<Vec<_>>(), records);
    assert!(Record::decode_buffered(&bytes[..40]).is_err());
    assert!(Record::decode_buffered(&[]).is_err());
}

#[test]
fn status_words_are_classified_and_named() {
    assert!(Status(0).is_ok());
    assert!(Status(0x8001_0000).is_warning() && !Status(0x8001_0000).is_error());
    let sat = Status(0x8002_0000);
    assert!(sat.is_error() && sat.is_saturated());
    assert_eq!(sat.describe(), vec!["error summary", "transducer saturation or A/D error"]);
}

#[test]
fn sequence_gaps_wrap() {
    assert_eq!(rdt::sequence_gap(u32::MAX, 0), 0);
    assert_eq!(rdt::sequence_gap(5, 9), 3);
    assert_eq!(rdt::sequence_gap(9, 9), -1);
}

proptest! {
    #[test]
    fn records_round_trip(rdt_sequence: u32, ft_sequence: u32, status: u32, counts: [i32; 6]) {
        let r = Record { rdt_sequence, ft_sequence, status: Status(status), counts };
        prop_assert_eq!(Record::decode(&r.encode()).unwrap(), r);
    }

    #[test]
    fn requests_round_trip(i in 0usize..6, sample_count: u32) {
        let command = [RdtCommand::Stop, RdtCommand::StartRealTime, RdtCommand::StartBuffered,
            RdtCommand::StartMultiUnit, RdtCommand::ResetLatch, RdtCommand::SetBias][i];
        let r = Request { command, sample_count };
        prop_assert_eq!(Request::decode(&r.encode()).unwrap(), r);
    }

    #[test]
    fn decoding_any_bytes_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = Request::decode(&bytes);
        let _ = Record::decode(&bytes);
        if let Ok(records) = Record::decode_buffered(&bytes) {
            prop_assert_eq!(records.count(), bytes.len() / 36);
        }
    }
}
