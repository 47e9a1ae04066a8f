//! The loopback wire codec: its two frames, both directions.

use serde::{Deserialize, Serialize};
use zerocopy::byteorder::little_endian::{I16, U16};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use crate::Direction;
use crate::can::CanFrame;
use crate::error::{DecodeError, EncodeError, to_i16, to_u16};
use crate::wire_layout::{read_bool, read_prefix, si, wire_bytes};

/// Frame identifiers.
pub mod id {
    /// → the motion command (the heartbeat).
    pub const COMMAND: u16 = 0x010;
    /// ← the speeds, the battery and whether a command is obeyed (20 ms).
    pub const FEEDBACK: u16 = 0x020;
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct CommandWire {
    linear_mm_s: I16,
    angular_mrad_s: I16,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct FeedbackWire {
    linear_mm_s: I16,
    angular_mrad_s: I16,
    battery_cv: U16,
    obeying: u8,
}

/// Forward speed, m/s, and yaw rate, rad/s (ISO: left turn positive).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear_mps: f64,
    pub angular_radps: f64,
}

/// What the chassis reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Feedback {
    pub linear_mps: f64,
    pub angular_radps: f64,
    pub battery_voltage_v: f64,
    /// A command arrived within the timeout and is obeyed.
    pub obeying: bool,
}

/// Every loopback frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "frame", rename_all = "snake_case")]
pub enum Frame {
    Command(Twist),
    Feedback(Feedback),
}

impl Frame {
    pub fn id(&self) -> u16 {
        match self {
            Frame::Command(_) => id::COMMAND,
            Frame::Feedback(_) => id::FEEDBACK,
        }
    }

    pub fn direction(&self) -> Direction {
        match self {
            Frame::Command(_) => Direction::ToChassis,
            Frame::Feedback(_) => Direction::FromChassis,
        }
    }

    pub fn encode(&self) -> Result<CanFrame, EncodeError> {
        Ok(match self {
            Frame::Command(c) => CanFrame::from_parts(
                id::COMMAND,
                wire_bytes::<4, _>(CommandWire {
                    linear_mm_s: to_i16("linear_mps", c.linear_mps, 1000.0)?.into(),
                    angular_mrad_s: to_i16("angular_radps", c.angular_radps, 1000.0)?.into(),
                }),
            ),
            Frame::Feedback(f) => CanFrame::from_parts(
                id::FEEDBACK,
                wire_bytes::<7, _>(FeedbackWire {
                    linear_mm_s: to_i16("linear_mps", f.linear_mps, 1000.0)?.into(),
                    angular_mrad_s: to_i16("angular_radps", f.angular_radps, 1000.0)?.into(),
                    battery_cv: to_u16("battery_voltage_v", f.battery_voltage_v, 100.0)?.into(),
                    obeying: u8::from(f.obeying),
                }),
            ),
        })
    }
}

/// Decodes one CAN frame of the protocol.
pub fn decode(frame: &CanFrame) -> Result<Frame, DecodeError> {
    let raw_id = frame.id();
    match frame.standard_id()? {
        id::COMMAND => {
            let w: CommandWire = read_prefix(raw_id, frame.data())?;
            Ok(Frame::Command(Twist {
                linear_mps: si(w.linear_mm_s.get(), 1000.0),
                angular_radps: si(w.angular_mrad_s.get(), 1000.0),
            }))
        }
        id::FEEDBACK => {
            let w: FeedbackWire = read_prefix(raw_id, frame.data())?;
            Ok(Frame::Feedback(Feedback {
                linear_mps: si(w.linear_mm_s.get(), 1000.0),
                angular_radps: si(w.angular_mrad_s.get(), 1000.0),
                battery_voltage_v: si(w.battery_cv.get(), 100.0),
                obeying: read_bool(raw_id, "obeying", w.obeying)?,
            }))
        }
        _ => Err(DecodeError::UnknownId { id: raw_id }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_frames_round_trip_and_the_layout_is_the_table() {
        let command = Frame::Command(Twist {
            linear_mps: 0.3,
            angular_radps: -0.5,
        });
        let can = command.encode().unwrap();
        assert_eq!(can.to_candump(), "010#2C010CFE");
        assert_eq!(decode(&can), Ok(command));
        let feedback = Frame::Feedback(Feedback {
            linear_mps: -1.0,
            angular_radps: 0.0,
            battery_voltage_v: 24.5,
            obeying: true,
        });
        let can = feedback.encode().unwrap();
        assert_eq!(can.to_candump(), "020#18FC0000920901");
        assert_eq!(decode(&can), Ok(feedback));
        assert!(decode(&CanFrame::from_candump("020#18FC0000920902").unwrap()).is_err());
        assert!(decode(&CanFrame::from_candump("7F0#01").unwrap()).is_err());
    }
}
