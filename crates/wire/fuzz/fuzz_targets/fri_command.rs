#![no_main]
//! Any bytes: the FRI command decoder returns, never panics; what it accepts re-encodes to itself.
use libfuzzer_sys::fuzz_target;
use softcontact_wire::fri::Command;

fuzz_target!(|data: &[u8]| {
    if let Ok(c) = Command::decode(data) {
        assert_eq!(&c.encode()[..], data);
    }
});
