//! Any byte stream into the NMEA line reader and sentence parser: no panic; whatever parses
//! updates a fix and prints back to a sentence that parses to the same value.
#![no_main]

use chassis_interfaces::GpsFix;
use chassis_protocols::nmea;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut reader = nmea::LineReader::new();
    let mut fix = GpsFix::default();
    for piece in data.chunks(7) {
        reader.push(piece);
        while let Some(line) = reader.next_line() {
            if let Ok(sentence) = nmea::parse_sentence(&line) {
                nmea::apply(&sentence, &mut fix);
                let again = nmea::parse_sentence(&sentence.to_sentence())
                    .expect("a printed sentence parses");
                assert_eq!(again.kind(), sentence.kind());
            }
        }
    }
});
