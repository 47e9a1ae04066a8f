//! `chassis detect`: which AgileX protocol (V1 or V2) a recording of a chassis' frames speaks,
//! by the rule `chassisd` applies before it sends anything to a SCOUT MINI, SCOUT or BUNKER.

use std::io::BufRead;
use std::time::Duration;

use chassis_protocols::CandumpLine;
use chassis_protocols::agilex_v2::detect::{Detection, Detector};
use chassis_protocols::time::Timestamp;

/// The verdict on `args` (or, when there are none, every line of `input`): the detection and
/// the lines that are not CAN frames.
pub fn run(
    args: &[String],
    input: impl BufRead,
    min_frames: u32,
) -> std::io::Result<(Detection, Vec<String>)> {
    let mut detector = Detector::new(Timestamp::ZERO, Duration::ZERO, min_frames);
    let mut bad = Vec::new();
    let mut feed = |text: &str| {
        let text = text.trim();
        if text.is_empty() || text.starts_with('#') {
            return;
        }
        match CandumpLine::parse(text) {
            Ok(line) => detector.handle_rx(&line.frame),
            Err(e) => bad.push(format!("{text}: {e}")),
        }
    };
    if args.is_empty() {
        for line in input.lines() {
            feed(&line?);
        }
    } else {
        for arg in args {
            feed(arg);
        }
    }
    // Everything has been heard: the deadline is now.
    Ok((detector.poll(Timestamp::ZERO), bad))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::Protocol;

    fn detect(frames: &[&str]) -> Detection {
        let args: Vec<String> = frames.iter().map(|s| s.to_string()).collect();
        run(&args, "".as_bytes(), 3).unwrap().0
    }

    #[test]
    fn the_manuals_v1_frames_are_v1_and_the_bunker_capture_is_v2() {
        // PROTOCOLS.md §2: 0x130 01 00 0A … 44 carries a valid V1 checksum.
        let v1 = ["130#01000A0000000044"; 3];
        assert_eq!(detect(&v1), Detection::Decided(Protocol::V1));
        let v2 = [
            "211#0100010000800000",
            "221#0000000000000000",
            "241#AA00000000000061",
            "311#0000000000000000",
        ];
        assert_eq!(detect(&v2), Detection::Decided(Protocol::V2));
        assert!(matches!(
            detect(&["211#0100010000800000"]),
            Detection::Silent { .. }
        ));
    }
}
