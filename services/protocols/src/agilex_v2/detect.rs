//! Telling AgileX protocol V1 from V2 by listening only (`PROTOCOLS-V2` §4.3).
//!
//! A sans-IO classifier: received frames go in with their time, a [`Detection`] comes out. It
//! never asks anything to be sent, so a chassis of either protocol sees nothing of the wrong one.
//!
//! * V1 evidence: id 0x151, 0x131, 0x141 or 0x200-0x203 (and the V1 commands 0x130, 0x140 of
//!   another node), DLC 8, whose b7 is the V1 checksum (`(id_hi + id_lo + dlc + b0 + … + b6) &
//!   0xFF`).
//! * V2 evidence: 0x221 or 0x241 with DLC 8 (what the SDK's detector uses), plus 0x251-0x254,
//!   0x261-0x264 and 0x311. 0x131, 0x141 and 0x211 alone prove nothing (both protocols use them).
//! * Decided after `min_frames` frames of one kind and none of the other; both kinds → unknown
//!   (the SDK's rule); nothing by the deadline → silent, with the ids heard.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::time::Duration;

use crate::agilex_v1::checksum;
use crate::can::CanFrame;
use crate::profile::Protocol;
use crate::time::Timestamp;

/// The detector's answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Detection {
    /// Still listening.
    Listening,
    /// Decided.
    Decided(Protocol),
    /// Both kinds of evidence were heard: a mixed bus or a firmware the rule does not cover.
    Conflicting { v1_frames: u32, v2_frames: u32 },
    /// The deadline passed without enough evidence. `heard` lists the ids seen, with counts.
    Silent { heard: Vec<(u16, u32)> },
}

impl Detection {
    /// A log line for the outcome.
    pub fn describe(&self) -> String {
        match self {
            Detection::Listening => "listening".into(),
            Detection::Decided(p) => format!("protocol {p} detected"),
            Detection::Conflicting {
                v1_frames,
                v2_frames,
            } => format!(
                "both protocols heard ({v1_frames} V1 frames, {v2_frames} V2 frames): not deciding"
            ),
            Detection::Silent { heard } if heard.is_empty() => {
                "nothing heard on the bus (wiring, bit rate, chassis off?)".into()
            }
            Detection::Silent { heard } => format!(
                "no V1 or V2 evidence; heard {}",
                heard
                    .iter()
                    .map(|(id, n)| format!("0x{id:03X}×{n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// How long to listen and how much evidence decides (⚠ D-16): from the profile the robot is
/// configured with (SCOUT MINI: its V1 profile; SCOUT, BUNKER: their V2 profile).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct DetectSettings {
    /// Listen this long for V1/V2 evidence before reporting silence and listening again, ms.
    pub timeout_ms: u64,
    /// Consistent frames of one protocol needed to decide.
    pub min_frames: u32,
}

impl From<&crate::agilex_v2::V2Profile> for DetectSettings {
    fn from(p: &crate::agilex_v2::V2Profile) -> Self {
        Self {
            timeout_ms: p.detect_timeout_ms,
            min_frames: p.detect_min_frames,
        }
    }
}

impl From<&crate::agilex_v1::V1Profile> for DetectSettings {
    fn from(p: &crate::agilex_v1::V1Profile) -> Self {
        Self {
            timeout_ms: p.detect_timeout_ms,
            min_frames: p.detect_min_frames,
        }
    }
}

/// The passive V1/V2 detector.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Detector {
    deadline: Timestamp,
    min_frames: u32,
    v1: u32,
    v2: u32,
    heard: BTreeMap<u16, u32>,
}

/// Whether `frame` is V1 evidence: a V1 feedback id, DLC 8, and a valid V1 checksum in b7.
pub fn is_v1_evidence(frame: &CanFrame) -> bool {
    if frame.is_extended() {
        return false;
    }
    let id = frame.id();
    let data = frame.data();
    matches!(id, 0x130 | 0x140 | 0x151 | 0x131 | 0x141 | 0x200..=0x203)
        && data.len() == 8
        && u16::try_from(id).is_ok_and(|id| checksum(id, &data[..7]) == data[7])
}

/// Whether `frame` is V2 evidence.
pub fn is_v2_evidence(frame: &CanFrame) -> bool {
    !frame.is_extended()
        && frame.data().len() == 8
        && matches!(frame.id(), 0x221 | 0x241 | 0x251..=0x254 | 0x261..=0x264 | 0x311)
}

impl Detector {
    /// Listening from `now` for at most `timeout`, deciding after `min_frames` frames.
    pub fn new(now: Timestamp, timeout: Duration, min_frames: u32) -> Self {
        Self {
            deadline: now + timeout,
            min_frames: min_frames.max(1),
            v1: 0,
            v2: 0,
            heard: BTreeMap::new(),
        }
    }

    /// When [`Detector::poll`] gives up.
    pub fn deadline(&self) -> Timestamp {
        self.deadline
    }

    /// Counts one received frame.
    pub fn handle_rx(&mut self, frame: &CanFrame) {
        if let Ok(id) = u16::try_from(frame.id()) {
            *self.heard.entry(id).or_default() += 1;
        }
        if is_v1_evidence(frame) {
            self.v1 += 1;
        } else if is_v2_evidence(frame) {
            self.v2 += 1;
        }
    }

    /// The outcome at `now`.
    pub fn poll(&self, now: Timestamp) -> Detection {
        match (self.v1, self.v2) {
            (v1, v2) if v1 > 0 && v2 > 0 => Detection::Conflicting {
                v1_frames: v1,
                v2_frames: v2,
            },
            (v1, 0) if v1 >= self.min_frames => Detection::Decided(Protocol::V1),
            (0, v2) if v2 >= self.min_frames => Detection::Decided(Protocol::V2),
            _ if now >= self.deadline => Detection::Silent {
                heard: self.heard.iter().map(|(id, n)| (*id, *n)).collect(),
            },
            _ => Detection::Listening,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(text: &str) -> CanFrame {
        CanFrame::from_candump(text).unwrap()
    }

    const T0: Timestamp = Timestamp::from_millis(1000);

    fn detect(frames: &[&str]) -> Detection {
        let mut d = Detector::new(T0, Duration::from_secs(5), 3);
        for f in frames {
            d.handle_rx(&frame(f));
        }
        d.poll(T0 + Duration::from_millis(100))
    }

    #[test]
    fn the_bunker_mini_capture_is_v2() {
        // TV8-TV11: 0x211, 0x221, 0x241, 0x311 of a real BUNKER MINI 2.0.
        let capture = [
            "211#0100010000800000",
            "221#0000000000000000",
            "241#AA00000000000061",
            "311#0000000000000000",
            "221#0000000000000000",
        ];
        assert_eq!(detect(&capture), Detection::Decided(Protocol::V2));
        assert_eq!(detect(&capture[..2]), Detection::Listening);
    }

    #[test]
    fn v1_frames_with_their_checksum_are_v1_and_without_it_prove_nothing() {
        // PROTOCOLS.md §2: 0x130 01 00 0a … 44 has a valid V1 checksum; a V1 SCOUT MINI's
        // 0x151 system state and 0x131 motion feedback carry one too.
        assert!(is_v1_evidence(&frame("130#01000A0000000044")));
        assert!(!is_v1_evidence(&frame("130#01000A0000000045")));
        let status = {
            let data7 = [0x00, 0x01, 0x00, 0xF0, 0x00, 0x00, 0x05];
            let mut data = data7.to_vec();
            data.push(checksum(0x151, &data7));
            CanFrame::from_parts(0x151u16, <[u8; 8]>::try_from(data).unwrap())
        };
        assert!(is_v1_evidence(&status));
        let mut d = Detector::new(T0, Duration::from_secs(5), 3);
        for _ in 0..3 {
            d.handle_rx(&status);
        }
        assert_eq!(d.poll(T0), Detection::Decided(Protocol::V1));
        // The same id with a wrong b7 (a V2 0x131 brake command, zero-padded) is no evidence.
        assert!(!is_v1_evidence(&frame("131#0100000000000000")));
        assert!(!is_v1_evidence(&frame("211#0100010000800000")));
    }

    #[test]
    fn both_kinds_conflict_and_silence_names_what_was_heard() {
        let status = {
            let data7 = [0, 1, 0, 0xF0, 0, 0, 0];
            let mut data = data7.to_vec();
            data.push(checksum(0x151, &data7));
            CanFrame::from_parts(0x151u16, <[u8; 8]>::try_from(data).unwrap())
        };
        let mut d = Detector::new(T0, Duration::from_secs(5), 3);
        d.handle_rx(&status);
        d.handle_rx(&frame("221#0000000000000000"));
        assert_eq!(
            d.poll(T0),
            Detection::Conflicting {
                v1_frames: 1,
                v2_frames: 1
            }
        );
        let mut quiet = Detector::new(T0, Duration::from_secs(5), 3);
        quiet.handle_rx(&frame("211#0000010000000000"));
        quiet.handle_rx(&frame("7F0#00"));
        assert_eq!(
            quiet.poll(T0 + Duration::from_secs(1)),
            Detection::Listening
        );
        let silent = quiet.poll(T0 + Duration::from_secs(5));
        assert_eq!(
            silent,
            Detection::Silent {
                heard: vec![(0x211, 1), (0x7F0, 1)]
            }
        );
        assert_eq!(
            silent.describe(),
            "no V1 or V2 evidence; heard 0x211×1, 0x7F0×1"
        );
        let nothing = Detector::new(T0, Duration::from_secs(5), 3);
        assert!(
            nothing
                .poll(T0 + Duration::from_secs(5))
                .describe()
                .contains("nothing heard")
        );
    }
}
