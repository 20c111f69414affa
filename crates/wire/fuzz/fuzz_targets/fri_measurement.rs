#![no_main]
//! Any bytes: the FRI measurement decoder returns, never panics; what it accepts re-encodes to itself.
use libfuzzer_sys::fuzz_target;
use softcontact_wire::fri::Measurement;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = Measurement::decode(data) {
        assert_eq!(&m.encode()[..], data);
    }
});
