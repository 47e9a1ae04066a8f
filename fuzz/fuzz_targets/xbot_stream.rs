//! Any byte stream, in chunks chosen by the input, into the XBot stream parser: no panic,
//! bounded memory, and every byte accounted for.
#![no_main]

use chassis_protocols::xbot::XbotProfile;
use chassis_protocols::xbot;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&chunking, stream)) = data.split_first() else {
        return;
    };
    let profile = XbotProfile {
        bcd_currents_and_ranges: chunking & 0x80 != 0,
        ..XbotProfile::default()
    };
    let chunk = usize::from(chunking & 0x3F).max(1);
    let mut parser = xbot::StreamParser::new();
    for piece in stream.chunks(chunk) {
        parser.push(piece);
        while let Some(item) = parser.next_frame(&profile) {
            if let Ok(frame) = item {
                let bytes = frame.encode(&profile).expect("a decoded frame encodes");
                assert!(bytes.len() <= xbot::MAX_FRAME_LEN);
            }
        }
        assert!(parser.pending() <= xbot::STREAM_CAPACITY);
    }
});
