//! One robot's codec behind a uniform face: frames in, JSON objects out, the fields as
//! `chassis decode` prints them (and the Foxglove bridge shows them).

use crate::agilex_v2::{self, V2Model, V2Profile};
use crate::profile::{ScoutMiniProfile, TitanProfile, V1Model, XbotProfile};
use crate::{CanFrame, DecodeError, Profile, RobotKind, scout_mini, titan, xbot};
use chassis_interfaces::{DriverStatus, FaultFlags, LightMode, RobotDescription, WireProtocol};
use serde::Serialize;
use serde_json::{Map, Value};

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
    Rejected(xbot::StreamError),
}

/// The codec of one robot, with its profile.
#[derive(Debug)]
pub enum RobotCodec {
    Titan(TitanProfile),
    ScoutMini(ScoutMiniProfile),
    Xbot {
        profile: XbotProfile,
        parser: xbot::StreamParser,
    },
    /// An AgileX protocol-V2 robot.
    V2 {
        profile: V2Profile,
        robot: RobotKind,
    },
}

impl RobotCodec {
    pub fn new(profile: Profile) -> Self {
        match profile {
            Profile::Titan(p) => RobotCodec::Titan(p),
            Profile::ScoutMini(p) => RobotCodec::ScoutMini(p),
            Profile::Xbot(p) => RobotCodec::Xbot {
                profile: p,
                parser: xbot::StreamParser::new(),
            },
            Profile::V2(p) => RobotCodec::V2 {
                robot: Profile::V2(p.clone()).robot(),
                profile: p,
            },
        }
    }

    /// The codec of the robot `description` describes (as chassisd publishes it), in the
    /// protocol it says is in use, with the manuals' profile of its model: how a client that
    /// knows the robot only from its description (the Foxglove view's `/frames`) reads its bus.
    /// Its own protocol, or still detecting: the kind's default profile. `None` for a kind the
    /// registry does not know.
    pub fn for_description(description: &RobotDescription) -> Option<Self> {
        let entry = RobotKind::from_id(description.kind)?.entry();
        let model = || Value::String(description.model().to_string());
        let profile = match description.protocol {
            WireProtocol::V2 => serde_json::from_value::<V2Model>(model())
                .ok()
                .filter(|m| entry.v2_models.contains(m))
                .map(|m| Profile::V2(V2Profile::for_model(m))),
            WireProtocol::V1 => serde_json::from_value::<V1Model>(model())
                .ok()
                .filter(|m| entry.v1_model == Some(*m))
                .map(|m| Profile::ScoutMini(ScoutMiniProfile::for_model(m))),
            _ => None,
        };
        Some(profile.map_or_else(
            || entry.codec_for_wire(description.protocol),
            RobotCodec::new,
        ))
    }

    pub fn robot(&self) -> RobotKind {
        match self {
            RobotCodec::Titan(_) => RobotKind::Titan,
            RobotCodec::ScoutMini(p) => p.model.robot(),
            RobotCodec::Xbot { .. } => RobotKind::Xbot,
            RobotCodec::V2 { robot, .. } => *robot,
        }
    }

    /// Decodes one CAN frame (TITAN, SCOUT MINI).
    pub fn decode_can(&self, frame: &CanFrame) -> Result<FrameJson, DecodeError> {
        match self {
            RobotCodec::Titan(profile) => {
                let decoded = titan::decode(frame, profile)?;
                let mut json = frame_json(
                    RobotKind::Titan,
                    decoded.id().into(),
                    decoded.direction(),
                    None,
                    &decoded,
                );
                match &decoded {
                    titan::Frame::SystemStatus(s) => {
                        let body = if s.body_status == titan::body::EXCEPTION {
                            FaultFlags::BODY_EXCEPTION
                        } else {
                            0
                        };
                        insert_faults(
                            &mut json,
                            titan::normalize_faults(s.vendor_fault_word) | body,
                        );
                    }
                    titan::Frame::MotorSlow(m) => {
                        json.insert(
                            "driver_status_flags".into(),
                            driver_status_names(m.driver_status).into(),
                        );
                    }
                    titan::Frame::BmsAlarm(b) => insert_bms_alarms(&mut json, b),
                    titan::Frame::Rc(r) => insert_switches(&mut json, r),
                    _ => {}
                }
                Ok(json)
            }
            RobotCodec::ScoutMini(profile) => {
                let decoded = scout_mini::decode(frame, profile)?;
                let mut json = frame_json(
                    profile.model.robot(),
                    decoded.frame.id().into(),
                    decoded.frame.direction(),
                    Some(decoded.count),
                    &decoded.frame,
                );
                if let scout_mini::Frame::SystemStatus(s) = &decoded.frame {
                    insert_faults(
                        &mut json,
                        scout_mini::normalize_faults(s.vendor_fault_word)
                            | scout_mini::body_flags(s.body_status),
                    );
                }
                Ok(json)
            }
            RobotCodec::V2 { profile, robot } => {
                let decoded = agilex_v2::decode(frame, profile)?;
                let mut json = frame_json(
                    *robot,
                    decoded.id().into(),
                    decoded.direction(),
                    None,
                    &decoded,
                );
                json.insert("protocol".into(), "v2".into());
                name_v2_fields(&mut json, &decoded, profile);
                Ok(json)
            }
            RobotCodec::Xbot { .. } => Err(DecodeError::UnknownId { id: frame.id() }),
        }
    }

    /// Feeds serial bytes (XBot) and returns every frame or error they complete, in order.
    /// Errors carry the bytes of the rejected candidate frame when there is one.
    pub fn push_serial(&mut self, bytes: &[u8]) -> Vec<Result<FrameJson, SerialError>> {
        let RobotCodec::Xbot { profile, parser } = self else {
            return vec![Err(SerialError::NotSerial {
                robot: self.robot(),
            })];
        };
        parser.push(bytes);
        let mut out = Vec::new();
        while let Some(item) = parser.next_frame(profile) {
            out.push(match item {
                Ok(frame) => Ok(frame_json(
                    RobotKind::Xbot,
                    frame.command_id().into(),
                    frame.direction(),
                    None,
                    &frame,
                )),
                Err(err) => Err(SerialError::Rejected(err)),
            });
        }
        out
    }

    /// Bytes the XBot stream parser has thrown away so far while resynchronising.
    pub fn serial_bytes_discarded(&self) -> u64 {
        match self {
            RobotCodec::Xbot { parser, .. } => parser.bytes_discarded(),
            _ => 0,
        }
    }
}

/// Names beside the codes of a protocol-V2 frame, read under the robot's profile: 0x211's
/// vehicle state (in the frame already), its fault bits by the names of the robot's ⚠ D-3 table
/// (`fault_bits`) and as normalized flags (`faults`, `warnings`, with the E-stop or exception of
/// b0), HUNTER 2.0's brake in b6; the driver status bits after ⚠ D-7; the BMS alarms (⚠ D-6); the
/// RANGER motion mode (⚠ D-12); light modes; RC lever positions.
fn name_v2_fields(json: &mut FrameJson, frame: &agilex_v2::Frame, profile: &V2Profile) {
    use agilex_v2::Frame;
    match frame {
        Frame::SystemStatus(s) => {
            json.insert(
                "fault_bits".into(),
                profile.fault_names(s.fault_word).into(),
            );
            insert_faults(
                json,
                agilex_v2::normalize_faults(s.fault_word, profile)
                    | agilex_v2::vehicle_state_flags(s.vehicle_state),
            );
            if profile.reports_brake_in_b6() {
                json.insert("parking_brake_engaged".into(), (s.b6 == 0x01).into());
            }
        }
        Frame::MotorSlow(m) => {
            let status = agilex_v2::normalize_driver_status(m.driver_status, profile);
            json.insert(
                "driver_status_flags".into(),
                driver_status_names(status).into(),
            );
            json.insert(
                "driver_enabled".into(),
                (status & DriverStatus::ENABLED != 0).into(),
            );
        }
        Frame::BmsAlarm(b) => insert_bms_alarms(json, b),
        Frame::BmsProtection(p) => {
            json.insert("protections".into(), p.names(true).into());
            json.insert("states".into(), p.names(false).into());
        }
        Frame::MotionModeState(m) | Frame::MotionModeCommand(m) => {
            json.insert(
                "motion_mode".into(),
                agilex_v2::motion_mode_name(m.mode, profile).into(),
            );
        }
        Frame::LightState(l) | Frame::LightCommand(l) => {
            json.insert("front_light".into(), LightMode::name(l.front_mode).into());
            if profile.rear_light {
                json.insert("rear_light".into(), LightMode::name(l.rear_mode).into());
            }
        }
        Frame::Rc(r) => insert_switches(json, r),
        Frame::VersionText(t) => {
            json.insert("text".into(), t.text().into());
        }
        _ => {}
    }
}

/// 0x362's alarm and warning bits by name.
fn insert_bms_alarms(json: &mut FrameJson, b: &titan::BmsAlarm) {
    json.insert("alarms".into(), b.alarm_names().into());
    json.insert("warnings".into(), b.warning_names().into());
}

/// 0x241's lever positions by name (`PROTOCOLS-V2` §2.3.3): SWA and SWD have two positions,
/// SWB and SWC three; 0b00 reads `none` (no RC data).
fn insert_switches(json: &mut FrameJson, r: &titan::RcFeedback) {
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
fn insert_faults(json: &mut FrameJson, flags: u64) {
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

fn frame_json(
    robot: RobotKind,
    id: u32,
    direction: crate::Direction,
    count: Option<u8>,
    frame: &impl Serialize,
) -> FrameJson {
    let mut out = Map::new();
    out.insert("robot".into(), robot.name().into());
    let id_text = if robot.is_can() {
        format!("0x{id:03X}")
    } else {
        format!("0x{id:02X}")
    };
    out.insert("id".into(), id_text.into());
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::description::describe;

    #[test]
    fn a_description_gives_the_codec_of_its_robot_in_the_protocol_in_use() {
        for kind in RobotKind::ALL {
            let d = describe(&kind.entry().defaults());
            let codec = RobotCodec::for_description(&d).expect("a codec");
            assert_eq!(codec.robot(), kind);
        }
        // A SCOUT MINI described in V1, then (detection decided) in V2 with its omni model.
        let v1 = describe(&RobotKind::ScoutMini.entry().defaults());
        assert!(matches!(
            RobotCodec::for_description(&v1),
            Some(RobotCodec::ScoutMini(_))
        ));
        let mut v2 = describe(&Profile::V2(V2Profile::for_model(V2Model::ScoutMiniOmni)));
        v2.protocol = WireProtocol::V2;
        match RobotCodec::for_description(&v2) {
            Some(RobotCodec::V2 { profile, robot }) => {
                assert_eq!(
                    (profile.model, robot),
                    (V2Model::ScoutMiniOmni, RobotKind::ScoutMini)
                );
            }
            other => panic!("{other:?}"),
        }
        // A model of another robot is not taken: the kind's own V2 profile is.
        let mut hunter = describe(&RobotKind::Hunter.entry().defaults());
        hunter.set_model("scout-mini-omni");
        match RobotCodec::for_description(&hunter) {
            Some(RobotCodec::V2 { profile, .. }) => assert_eq!(profile.model, V2Model::Hunter),
            other => panic!("{other:?}"),
        }
        assert!(RobotCodec::for_description(&RobotDescription::default()).is_none());
    }
}
