//! A family's frame describer behind one face ([`Codec`]): frames in, JSON objects out, the
//! fields as `chassis decode` prints them (and the Foxglove bridge shows them); each family's
//! `family.rs` implements it, with the helpers here for what the families' frames share.

use chassis_interfaces::{FaultFlags, RcState};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::can::CanFrame;
use crate::error::DecodeError;
use crate::kind::RobotKind;
use crate::titan::BmsAlarm;
use crate::xbot::StreamError;

/// A decoded frame as one JSON object: `robot`, `id`, `frame`, `direction`, then the frame's
/// fields in SI units under the names the interfaces use.
pub type FrameJson = Map<String, Value>;

/// Why serial bytes did not decode into a frame.
#[derive(Debug, thiserror::Error)]
pub enum SerialError {
    /// The robot is on a CAN bus: its frames are given as `ID#HEX`.
    #[error("{robot} speaks CAN: give frames as ID#HEX")]
    NotSerial { robot: RobotKind },
    /// The XBot stream parser rejected a candidate frame (its bytes are in the message).
    #[error("{0}")]
    Rejected(StreamError),
}

/// A family's frame describer, boxed ([`crate::family::Family::codec`]).
pub type BoxedCodec = Box<dyn Codec>;

/// A family's frame describer: frames in, JSON objects out.
pub trait Codec: std::fmt::Debug + Send {
    /// The robot whose frames it reads.
    fn robot(&self) -> RobotKind;

    /// Decodes one CAN frame (the CAN families).
    fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        Err(DecodeError::UnknownId { id: frame.id() })
    }

    /// Feeds serial bytes (the serial families) and returns every frame or error they complete,
    /// in order. Errors carry the bytes of the rejected candidate frame when there is one.
    fn push_serial(&mut self, _bytes: &[u8]) -> Vec<Result<FrameJson, SerialError>> {
        vec![Err(SerialError::NotSerial {
            robot: self.robot(),
        })]
    }

    /// Bytes the stream parser has thrown away so far while resynchronising.
    fn serial_bytes_discarded(&self) -> u64 {
        0
    }
}

/// 0x362's alarm and warning bits by name.
pub(crate) fn insert_bms_alarms(json: &mut FrameJson, b: &BmsAlarm) {
    json.insert("alarms".into(), b.alarm_names().into());
    json.insert("warnings".into(), b.warning_names().into());
}

/// 0x241's lever positions by name (`PROTOCOLS-V2` §2.3.3): SWA and SWD have two positions,
/// SWB and SWC three; 0b00 reads `none` (no RC data).
pub(crate) fn insert_switches(json: &mut FrameJson, r: &RcState) {
    let position = |value: u8, three: bool| match value {
        2 => "up",
        1 if three => "middle",
        3 => "down",
        0 => "none",
        _ => "unknown",
    };
    let mut levers = Map::new();
    for (name, value, three) in [
        ("swa", r.switch_a, false),
        ("swb", r.switch_b, true),
        ("swc", r.switch_c, true),
        ("swd", r.switch_d, false),
    ] {
        levers.insert(name.into(), position(value, three).into());
    }
    json.insert("switches".into(), Value::Object(levers));
}

/// The normalized fault flags by name, as `chassis status` prints them: `faults` (the chassis
/// stops or limits) and `warnings` (it still drives), beside the raw word.
pub(crate) fn insert_faults(json: &mut FrameJson, flags: u64) {
    json.insert(
        "faults".into(),
        FaultFlags::names(flags & !FaultFlags::WARNINGS).into(),
    );
    json.insert(
        "warnings".into(),
        FaultFlags::names(flags & FaultFlags::WARNINGS).into(),
    );
}

/// The set bits of a motor driver status byte (`chassis_interfaces::DriverStatus`), by their
/// names in the IPC contract; a set bit the contract does not name reads `bit7`.
pub fn driver_status_names(bits: u8) -> Vec<String> {
    let constants = chassis_interfaces::layout::constants();
    let named: Vec<_> = constants
        .iter()
        .filter(|group| group.name == "DriverStatus")
        .flat_map(|group| group.values.iter())
        .collect();
    (0..8)
        .map(|n| 1u64 << n)
        .filter(|bit| u64::from(bits) & bit != 0)
        .map(|bit| {
            named.iter().find(|c| c.value == bit).map_or_else(
                || format!("bit{}", bit.trailing_zeros()),
                |c| c.name.to_lowercase(),
            )
        })
        .collect()
}

/// A frame's name, as its JSON `frame` tag spells it (`motion_command`).
pub fn frame_name(frame: &impl Serialize) -> String {
    match serde_json::to_value(frame) {
        Ok(Value::Object(fields)) => fields
            .get("frame")
            .and_then(Value::as_str)
            .unwrap_or_default()
            .to_owned(),
        _ => String::new(),
    }
}

/// A decoded frame as JSON: the robot, its id (`0x111` for a CAN identifier, `0x03` for a
/// serial command id, as `id_digits` says), the count where the protocol has one, the frame's
/// name, its direction and its fields.
pub(crate) fn frame_json(
    robot: RobotKind,
    (id, id_digits): (u32, usize),
    direction: crate::Direction,
    count: Option<u8>,
    frame: &impl Serialize,
) -> FrameJson {
    let mut out = Map::new();
    out.insert("robot".into(), robot.name().into());
    out.insert("id".into(), format!("0x{id:0id_digits$X}").into());
    if let Some(count) = count {
        out.insert("count".into(), count.into());
    }
    match serde_json::to_value(frame) {
        Ok(Value::Object(fields)) => {
            // `frame` (the tag) first, then the direction, then the fields.
            if let Some(name) = fields.get("frame") {
                out.insert("frame".into(), name.clone());
            }
            out.insert(
                "direction".into(),
                serde_json::to_value(direction).unwrap_or(Value::Null),
            );
            for (key, value) in fields {
                if key != "frame" {
                    out.insert(key, value);
                }
            }
        }
        Ok(other) => {
            out.insert("frame".into(), other);
        }
        Err(err) => {
            out.insert("error".into(), err.to_string().into());
        }
    }
    out
}
