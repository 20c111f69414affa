#![no_main]
//! Any bytes: the RDT decoders return, never panic; what they accept re-encodes to itself.
use libfuzzer_sys::fuzz_target;
use softcontact_wire::rdt::{Record, Request};

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = Request::decode(data) {
        assert_eq!(&r.encode()[..], data);
    }
    if let Ok(r) = Record::decode(data) {
        assert_eq!(&r.encode()[..], data);
    }
    if let Ok(records) = Record::decode_buffered(data) {
        let records: Vec<Record> = records.collect();
        assert_eq!(Record::encode_buffered(&records), data);
    }
});
