//! Any text as a candump frame or log line: no panic; a frame that parses prints back to text
//! that parses to the same frame.
#![no_main]

use chassis_protocols::{CanFrame, CandumpLine};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(line) = CandumpLine::parse(text) {
        let again = CanFrame::from_candump(&line.frame.to_candump()).expect("printed frames parse");
        assert_eq!(again, line.frame);
    }
});
