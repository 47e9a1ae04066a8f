//! The robot as the live view shows it, as pure functions: the scene (the body and range cones
//! of the robot's description, the cones sized by their readings, the path just driven), `/mux`
//! and `/safety` with their names spelled out, and `/frames` decoded by the described robot's codec. `/tf`,
//! `/pose`, `/gps`, `/log` and the JSON schemas, which a recording carries too, are
//! `chassis_client::foxglove`'s.

use chassis_client::foxglove::{BASE_LINK, Body, ODOM, RangeKind, pose, stamp, yaw_quaternion};
use chassis_client::watch;
use chassis_client::{
    BusFrame, ChassisState, EstopState, FrameDirection, FrameKind, MuxStatus, SafetyAction,
    SafetyRule, SafetyStatus, Stop, Unfollowed, ZeroReason,
};
use chassis_protocols::CanFrame;
use chassis_protocols::frame_json::BoxedCodec;
use foxglove::messages::{
    Color, CubePrimitive, CylinderPrimitive, LinePrimitive, Point3, Quaternion, SceneEntity,
    SceneUpdate, Vector3, line_primitive,
};
use serde_json::{Map, Value, json};

/// Points kept in the trail of the path just driven.
pub const TRAIL_POINTS: usize = 2000;
/// A new trail point once the robot moved this far from the last one, m.
const TRAIL_STEP_M: f64 = 0.02;
/// Name under which the live bridge's log messages appear.
pub const LOG_NAME: &str = "chassis-foxglove";

/// `/mux`: every field of the decision, with the names spelled out.
pub fn mux_json(mux: &MuxStatus) -> serde_json::Result<Value> {
    let mut value = serde_json::to_value(mux)?;
    if let Some(obj) = value.as_object_mut() {
        obj.insert(
            "active_name".into(),
            mux.active().map_or("", |s| s.name()).into(),
        );
        obj.insert(
            "zero_reason_name".into(),
            ZeroReason::name(mux.zero_reason).into(),
        );
        obj.insert("locks_held".into(), watch::held_locks(mux).into());
        obj.insert("stop_name".into(), Stop::name(mux.stop).into());
        obj.insert(
            "awaiting_name".into(),
            mux.awaiting().map_or("", |s| s.name()).into(),
        );
        obj.insert("why".into(), mux.why().to_string().into());
    }
    Ok(value)
}

/// `/safety`: the safety monitor's decision, its rules and the cause of a chassis that does not
/// follow, named, and in words as every view shows it ([`SafetyStatus::why`]).
pub fn safety_json(status: &SafetyStatus) -> serde_json::Result<Value> {
    let mut value = serde_json::to_value(status)?;
    if let Some(obj) = value.as_object_mut() {
        obj.insert(
            "action_name".into(),
            SafetyAction::name(status.action).into(),
        );
        obj.insert(
            "active_names".into(),
            SafetyRule::names(status.active_rules).into(),
        );
        obj.insert(
            "unfollowed_name".into(),
            Unfollowed::name(status.unfollowed).into(),
        );
        obj.insert("estop_name".into(), EstopState::name(status.estop).into());
        obj.insert("why".into(), status.why().into());
    }
    Ok(value)
}

/// The JSON Schema of `/frames`.
pub fn frames_schema() -> Value {
    json!({
        "type": "object",
        "title": "chassis.Frames",
        "description": "Bus frames since the previous batch, each decoded as `chassis decode` prints it",
        "properties": {
            "count": {"type": "integer", "description": "frames in this batch"},
            "left_out": {"type": "integer", "description": "frames seen but not carried (batch full)"},
            "frames": {"type": "array", "items": {"type": "object", "properties": {
                "stamp_ns": {"type": "integer"},
                "seq": {"type": "integer"},
                "direction": {"type": "string"},
                "raw": {"type": "string"},
                "decoded": {"type": "object"},
                "error": {"type": "string"}
            }}}
        }
    })
}

/// The `/frames` entries of one tapped frame: its stamp, direction and raw bytes, and what the
/// described robot's `codec` reads in it (`decoded`, or why not: `error`). A CAN frame is one
/// entry; a serial read may complete several frames (one entry each) or none (one entry with
/// its bytes). Without a codec (no description yet) a CAN frame says so.
pub fn frame_entries(frame: &BusFrame, codec: Option<&mut BoxedCodec>) -> Vec<Value> {
    let mut entry = Map::new();
    entry.insert("stamp_ns".into(), frame.stamp_ns.into());
    entry.insert("seq".into(), frame.seq.into());
    let direction = FrameDirection::name(frame.direction);
    entry.insert("direction".into(), direction.into());
    let hex: String = frame.payload().iter().map(|b| format!("{b:02X}")).collect();
    match frame.kind {
        FrameKind::CAN => {
            entry.insert("raw".into(), format!("{:03X}#{hex}", frame.can_id).into());
            let decoded = CanFrame::try_from(frame)
                .map_err(|e| e.to_string())
                .and_then(|can| match codec {
                    Some(codec) => codec.decode_can(&can).map_err(|e| e.to_string()),
                    None => Err("robot not known yet".to_string()),
                });
            match decoded {
                Ok(fields) => entry.insert("decoded".into(), Value::Object(fields)),
                Err(e) => entry.insert("error".into(), e.into()),
            };
            vec![Value::Object(entry)]
        }
        FrameKind::GPS => {
            entry.insert(
                "raw".into(),
                String::from_utf8_lossy(frame.payload()).trim_end().into(),
            );
            vec![Value::Object(entry)]
        }
        _ => {
            entry.insert("raw".into(), hex.into());
            let decoded = codec
                .map(|codec| codec.push_serial(frame.payload()))
                .unwrap_or_default();
            if decoded.is_empty() {
                return vec![Value::Object(entry)];
            }
            decoded
                .into_iter()
                .map(|item| {
                    let mut e = entry.clone();
                    match item {
                        Ok(fields) => e.insert("decoded".into(), Value::Object(fields)),
                        Err(err) => e.insert("error".into(), err.to_string().into()),
                    };
                    Value::Object(e)
                })
                .collect()
        }
    }
}

/// A rotation about y by `pitch_rad` then about z by `yaw_rad`.
fn yaw_pitch_quaternion(yaw_rad: f64, pitch_rad: f64) -> Quaternion {
    let (sy, cy) = (yaw_rad / 2.0).sin_cos();
    let (sp, cp) = (pitch_rad / 2.0).sin_cos();
    Quaternion {
        x: -sy * sp,
        y: cy * sp,
        z: sy * cp,
        w: cy * cp,
    }
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// The path just driven: odometry positions, one every few centimetres.
#[derive(Debug, Default)]
pub struct Trail {
    points: std::collections::VecDeque<(f64, f64)>,
}

impl Trail {
    /// Adds the robot's position if it moved since the last point; true when it did.
    pub fn see(&mut self, state: &ChassisState) -> bool {
        let (x, y) = (state.odometry.x_m, state.odometry.y_m);
        if !x.is_finite() || !y.is_finite() {
            return false;
        }
        if let Some(&(lx, ly)) = self.points.back()
            && (x - lx).hypot(y - ly) < TRAIL_STEP_M
        {
            return false;
        }
        if self.points.len() == TRAIL_POINTS {
            self.points.pop_front();
        }
        self.points.push_back((x, y));
        true
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.points.len()
    }
}

/// `/scene`: the body in base_link, its range sensors' cones with their readings, the trail in
/// odom.
pub fn scene(state: &ChassisState, body: &Body, trail: &Trail, wall_ns: u64) -> SceneUpdate {
    let timestamp = Some(stamp(wall_ns));
    let entity = |frame: &str, id: &str| SceneEntity {
        timestamp,
        frame_id: frame.into(),
        id: id.into(),
        frame_locked: true,
        ..SceneEntity::default()
    };
    let mut robot = entity(BASE_LINK, "body");
    robot.cubes.push(CubePrimitive {
        pose: Some(pose(0.0, 0.0, body.height_m / 2.0, yaw_quaternion(0.0))),
        size: Some(Vector3 {
            x: body.length_m,
            y: body.width_m,
            z: body.height_m,
        }),
        color: Some(color(0.95, 0.55, 0.1, 0.6)),
    });
    let mut entities = vec![robot];
    if !body.sensors.is_empty() {
        let mut cones = entity(BASE_LINK, "ranges");
        for s in &body.sensors {
            let range = match s.kind {
                RangeKind::Ultrasonic => state.ranges.ultrasonic_m[s.index],
                RangeKind::Ir => state.ranges.ir_m[s.index],
            };
            let range = f64::from(range);
            if !range.is_finite() || range <= 0.0 {
                continue;
            }
            let diameter = 2.0 * range * (s.cone_rad / 2.0).tan();
            let (sy, cy) = s.yaw_rad.sin_cos();
            // The cylinder's axis is z: pitched by 90° it looks along the sensor; its bottom
            // (scale 0) is the apex at the sensor.
            cones.cylinders.push(CylinderPrimitive {
                pose: Some(pose(
                    s.x_m + cy * range / 2.0,
                    s.y_m + sy * range / 2.0,
                    body.height_m / 2.0,
                    yaw_pitch_quaternion(s.yaw_rad, std::f64::consts::FRAC_PI_2),
                )),
                size: Some(Vector3 {
                    x: diameter,
                    y: diameter,
                    z: range,
                }),
                bottom_scale: 0.0,
                top_scale: 1.0,
                color: Some(match s.kind {
                    RangeKind::Ultrasonic => color(0.2, 0.6, 1.0, 0.35),
                    RangeKind::Ir => color(1.0, 0.2, 0.2, 0.35),
                }),
            });
        }
        entities.push(cones);
    }
    let mut path = entity(ODOM, "trail");
    path.lines.push(LinePrimitive {
        r#type: line_primitive::Type::LineStrip as i32,
        pose: Some(pose(0.0, 0.0, 0.01, yaw_quaternion(0.0))),
        thickness: 3.0,
        scale_invariant: true,
        points: trail
            .points
            .iter()
            .map(|&(x, y)| Point3 { x, y, z: 0.0 })
            .collect(),
        color: Some(color(0.3, 0.9, 0.4, 1.0)),
        ..LinePrimitive::default()
    });
    entities.push(path);
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::RobotDescription;
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;

    fn described(kind: RobotKind) -> RobotDescription {
        describe(&kind.entry().defaults())
    }

    fn driven(x: f64, y: f64, yaw: f64) -> ChassisState {
        let mut s = ChassisState {
            robot: RobotKind::Xbot.id(),
            ..ChassisState::default()
        };
        s.odometry.x_m = x;
        s.odometry.y_m = y;
        s.odometry.yaw_rad = yaw;
        s
    }

    #[test]
    fn the_trail_keeps_a_point_every_few_centimetres_and_forgets_the_oldest() {
        let mut trail = Trail::default();
        assert!(trail.see(&driven(0.0, 0.0, 0.0)));
        assert!(!trail.see(&driven(0.01, 0.0, 0.0)), "1 cm is not a step");
        assert!(trail.see(&driven(0.05, 0.0, 0.0)));
        for i in 0..TRAIL_POINTS + 10 {
            trail.see(&driven(i as f64, 0.0, 0.0));
        }
        assert_eq!(trail.len(), TRAIL_POINTS);
    }

    #[test]
    fn range_cones_show_only_the_sensors_with_a_reading() {
        let body = Body::of(&described(RobotKind::Xbot));
        let mut s = driven(0.0, 0.0, 0.0);
        s.ranges.ultrasonic_m = [0.0, 1.25, 0.0];
        let update = scene(&s, &body, &Trail::default(), 0);
        let ranges = update.entities.iter().find(|e| e.id == "ranges").unwrap();
        assert_eq!(ranges.cylinders.len(), 1);
        let cone = &ranges.cylinders[0];
        assert_eq!(cone.size.unwrap().z, 1.25);
        // The centre ultrasonic looks straight ahead from the front edge.
        let p = cone.pose.unwrap().position.unwrap();
        assert!((p.x - (body.length_m / 2.0 + 0.625)).abs() < 1e-9, "{p:?}");
        // A TITAN has no range sensors: only its body and trail.
        let titan = scene(
            &s,
            &Body::of(&described(RobotKind::Titan)),
            &Trail::default(),
            0,
        );
        assert_eq!(titan.entities.len(), 2);
    }

    fn tapped(kind: u8, can_id: u32, bytes: &[u8]) -> BusFrame {
        let mut f = BusFrame {
            kind,
            can_id,
            seq: 7,
            ..BusFrame::default()
        };
        f.set_payload(bytes);
        f
    }

    #[test]
    fn frames_are_decoded_by_the_described_robots_codec() {
        // TITAN's 0x211 (system status) through the codec of its description.
        let mut codec =
            chassis_protocols::registry::profile_for_description(&described(RobotKind::Titan))
                .map(|p| p.codec());
        let frame = tapped(FrameKind::CAN, 0x211, &[0; 8]);
        let entries = frame_entries(&frame, codec.as_mut());
        assert_eq!(entries.len(), 1);
        assert_eq!(entries[0]["raw"], "211#0000000000000000");
        assert_eq!(entries[0]["direction"], "rx");
        assert!(entries[0]["decoded"].is_object(), "{}", entries[0]);
        // No description yet: the frame is carried with the reason it is not decoded.
        let unknown = frame_entries(&frame, None);
        assert_eq!(unknown[0]["error"], "robot not known yet");
        // A CAN id beyond 11 bits without the extended flag is refused, not decoded.
        let bad = frame_entries(&tapped(FrameKind::CAN, 0x800, &[0]), codec.as_mut());
        assert!(
            bad[0]["error"].as_str().unwrap().contains("11 bits"),
            "{}",
            bad[0]
        );
        // A GPS chunk is its sentence.
        let gps = frame_entries(&tapped(FrameKind::GPS, 0, b"$GPGGA,1*00\r\n"), None);
        assert_eq!(gps[0]["raw"], "$GPGGA,1*00");
    }

    #[test]
    fn the_safety_json_says_the_decision_and_the_cause_in_words() {
        let mut status = SafetyStatus {
            action: SafetyAction::STOP,
            active_rules: SafetyRule::bit(SafetyRule::FOLLOWING),
            unfollowed: Unfollowed::STANDBY,
            ..SafetyStatus::default()
        };
        let v = safety_json(&status).unwrap();
        assert_eq!(v["why"], "STOP by following: the chassis is in standby");
        assert_eq!(v["action_name"], "stop");
        assert_eq!(v["active_names"], json!(["following"]));
        assert_eq!(v["unfollowed_name"], "standby");
        status.active_rules = SafetyRule::bit(SafetyRule::LIMIT);
        status.unfollowed = Unfollowed::NONE;
        assert_eq!(safety_json(&status).unwrap()["why"], "STOP by limit");
        let schema = chassis_client::foxglove::schema_of(&v);
        assert_eq!(schema["properties"]["why"]["type"], "string");
    }

    #[test]
    fn the_mux_json_spells_out_the_names() {
        let mux = mux_json(&MuxStatus::default()).unwrap();
        assert_eq!(mux["active_name"], "");
        assert_eq!(mux["zero_reason_name"], ZeroReason::name(0));
        assert!(mux["locks_held"].as_array().unwrap().is_empty());
        let schema = chassis_client::foxglove::schema_of(&mux);
        assert_eq!(schema["properties"]["active_name"]["type"], "string");
    }
}
