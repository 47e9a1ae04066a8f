//! A robot in Foxglove's well-known messages (feature `foxglove`): state samples in, `/tf`,
//! `/pose`, `/gps` and `/log` out, the same for the live view (`chassis-foxglove`) and a
//! recording (`chassis record`), so a recording replayed in Foxglove looks like the live view.
//!
//! Pure: every function takes the sample and the time to stamp it with; the caller owns the
//! clocks and the channels.
//!
//! Frames (REP 103: x forward, y left, z up; yaw left positive):
//!
//! | frame | parent | from |
//! | --- | --- | --- |
//! | `odom` | — | the fixed frame: where the service's odometry started |
//! | `base_link` | `odom` | `odometry.x_m`, `y_m`, `yaw_rad` |
//! | `imu`, `gps` | `base_link` | the centre of the body (their mounting is not in the manuals) |
//! | each of the body's range sensors (`ultrasonic_front_left`, `ir_rear_centre`, …) | `base_link` | the description's sensors ([`Body`]) |

use ::foxglove::messages::{
    FrameTransform, FrameTransforms, LocationFix, Log, Pose, PoseInFrame, Quaternion, Timestamp,
    Vector3, location_fix, log,
};
use chassis_interfaces::{ChassisState, Group, RobotDescription, SensorKind};

use crate::watch::Severity;

/// The fixed frame.
pub const ODOM: &str = "odom";
/// The robot's body frame.
pub const BASE_LINK: &str = "base_link";

/// A Foxglove timestamp from Unix-epoch nanoseconds.
pub fn stamp(wall_ns: u64) -> Timestamp {
    let sec = u32::try_from(wall_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (wall_ns % 1_000_000_000) as u32)
}

/// A rotation about z by `yaw_rad`.
pub fn yaw_quaternion(yaw_rad: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (yaw_rad / 2.0).sin(),
        w: (yaw_rad / 2.0).cos(),
    }
}

/// A pose at (x, y, z), m, turned by `orientation`.
pub fn pose(x: f64, y: f64, z: f64, orientation: Quaternion) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(orientation),
    }
}

/// Which kind of range sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RangeKind {
    /// `RangesState::ultrasonic_m`.
    Ultrasonic,
    /// `RangesState::ir_m`.
    Ir,
}

/// A range sensor mounted on the body.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMount {
    /// Its frame's name, the sensor's name in the description (`ultrasonic_front_left`, …).
    pub frame: String,
    pub kind: RangeKind,
    /// Index into `RangesState::ultrasonic_m` or `ir_m`.
    pub index: usize,
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// Full opening angle of the sensor's cone, rad.
    pub cone_rad: f64,
}

/// The body drawn for a robot: its outline and its range sensors, from its description.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub sensors: Vec<SensorMount>,
}

impl Body {
    /// The described robot's outline and its range sensors with their cones.
    pub fn of(description: &RobotDescription) -> Self {
        let g = &description.geometry;
        let sensors = description
            .sensors()
            .iter()
            .filter_map(|s| {
                let kind = match s.kind {
                    SensorKind::ULTRASONIC => RangeKind::Ultrasonic,
                    SensorKind::INFRARED => RangeKind::Ir,
                    _ => return None,
                };
                Some(SensorMount {
                    frame: s.name().to_string(),
                    kind,
                    index: usize::from(s.index).min(2),
                    x_m: s.x_m,
                    y_m: s.y_m,
                    yaw_rad: s.yaw_rad,
                    cone_rad: s.field_of_view_rad,
                })
            })
            .collect();
        Body {
            length_m: g.length_m,
            width_m: g.width_m,
            height_m: g.height_m,
            sensors,
        }
    }
}

/// The body of the robot behind a `ChassisState::robot` value as the registry describes it with
/// the manuals' profile (a recording made without the service's description); `None` for an
/// unknown robot. A running service's own description is better: [`Body::of`].
pub fn body_of(kind: u8) -> Option<Body> {
    let kind = chassis_protocols::RobotKind::from_id(kind)?;
    let description = chassis_protocols::description::describe(&kind.entry().defaults());
    Some(Body::of(&description))
}

/// The JSON Schema (Foxglove's `jsonschema` encoding) of a JSON value's shape: every field
/// with its type, arrays with their length. The fixed-layout samples serialize every field, so a
/// default sample shows them all: `schema_of(&serde_json::to_value(ChassisState::default())?)`.
/// The live view and `chassis record` describe their JSON channels with it.
pub fn schema_of(value: &serde_json::Value) -> serde_json::Value {
    use serde_json::{Value, json};
    match value {
        Value::Null => json!({}),
        Value::Bool(_) => json!({"type": "boolean"}),
        Value::Number(n) if n.is_f64() => json!({"type": "number"}),
        Value::Number(_) => json!({"type": "integer"}),
        Value::String(_) => json!({"type": "string"}),
        Value::Array(items) => json!({
            "type": "array",
            "items": items.first().map_or(json!({}), schema_of),
            "minItems": items.len(),
            "maxItems": items.len(),
        }),
        Value::Object(map) => {
            let properties: serde_json::Map<String, Value> =
                map.iter().map(|(k, v)| (k.clone(), schema_of(v))).collect();
            json!({"type": "object", "properties": properties})
        }
    }
}

/// `/tf`: odom → base_link from the odometry, base_link → imu, gps and each range sensor.
pub fn transforms(state: &ChassisState, body: &Body, wall_ns: u64) -> FrameTransforms {
    let timestamp = Some(stamp(wall_ns));
    let tf = |parent: &str, child: &str, x, y, z, rotation| FrameTransform {
        timestamp,
        parent_frame_id: parent.into(),
        child_frame_id: child.into(),
        translation: Some(Vector3 { x, y, z }),
        rotation: Some(rotation),
    };
    let o = &state.odometry;
    let mut transforms = vec![
        tf(
            ODOM,
            BASE_LINK,
            o.x_m,
            o.y_m,
            0.0,
            yaw_quaternion(o.yaw_rad),
        ),
        tf(
            BASE_LINK,
            "imu",
            0.0,
            0.0,
            body.height_m / 2.0,
            yaw_quaternion(0.0),
        ),
        tf(
            BASE_LINK,
            "gps",
            0.0,
            0.0,
            body.height_m,
            yaw_quaternion(0.0),
        ),
    ];
    for s in &body.sensors {
        transforms.push(tf(
            BASE_LINK,
            &s.frame,
            s.x_m,
            s.y_m,
            body.height_m / 2.0,
            yaw_quaternion(s.yaw_rad),
        ));
    }
    FrameTransforms { transforms }
}

/// `/pose`: the robot in the odom frame.
pub fn pose_in_frame(state: &ChassisState, wall_ns: u64) -> PoseInFrame {
    let o = &state.odometry;
    PoseInFrame {
        timestamp: Some(stamp(wall_ns)),
        frame_id: ODOM.into(),
        pose: Some(pose(o.x_m, o.y_m, 0.0, yaw_quaternion(o.yaw_rad))),
    }
}

/// `/gps`: the fix, when the receiver has one.
pub fn location_fix(state: &ChassisState, wall_ns: u64) -> Option<LocationFix> {
    let g = &state.gps;
    if !state.is_valid(Group::Gps) || !g.has_fix() {
        return None;
    }
    // HDOP × an assumed 5 m user range error, as a diagonal ENU covariance.
    let sigma = f64::from(g.hdop) * 5.0;
    let variance = sigma * sigma;
    Some(LocationFix {
        timestamp: Some(stamp(wall_ns)),
        frame_id: "gps".into(),
        latitude: g.latitude_deg,
        longitude: g.longitude_deg,
        altitude: f64::from(g.altitude_m),
        position_covariance: vec![variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance],
        position_covariance_type: location_fix::PositionCovarianceType::Approximated as i32,
        ..LocationFix::default()
    })
}

/// Foxglove's log level of a [`Severity`].
pub fn level(severity: Severity) -> log::Level {
    match severity {
        Severity::Info => log::Level::Info,
        Severity::Warning => log::Level::Warning,
        Severity::Error => log::Level::Error,
    }
}

/// A `/log` message from the process `name`.
pub fn log_message(name: &str, severity: Severity, message: String, wall_ns: u64) -> Log {
    Log {
        timestamp: Some(stamp(wall_ns)),
        level: level(severity) as i32,
        message,
        name: name.into(),
        ..Log::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::RobotKind;

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
    fn the_base_link_follows_the_odometry() {
        let body = body_of(RobotKind::Xbot.id()).unwrap();
        let tf = transforms(&driven(1.5, -0.5, std::f64::consts::FRAC_PI_2), &body, 0);
        let base = &tf.transforms[0];
        assert_eq!(
            (base.parent_frame_id.as_str(), base.child_frame_id.as_str()),
            (ODOM, BASE_LINK)
        );
        let t = base.translation.unwrap();
        assert_eq!((t.x, t.y), (1.5, -0.5));
        let q = base.rotation.unwrap();
        assert!((q.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert!((q.w - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        // imu, gps and the XBot's six range sensors hang off base_link.
        assert_eq!(tf.transforms.len(), 3 + 6);
        assert!(
            tf.transforms[1..]
                .iter()
                .all(|t| t.parent_frame_id == BASE_LINK)
        );
    }

    #[test]
    fn every_robot_the_service_names_has_a_body_to_draw() {
        for kind in RobotKind::ALL {
            assert!(body_of(kind.id()).is_some(), "{kind}");
        }
        assert!(body_of(0).is_none());
    }

    #[test]
    fn the_state_schema_names_every_field_with_its_type() {
        let schema = schema_of(&serde_json::to_value(ChassisState::default()).unwrap());
        assert_eq!(schema["type"], "object");
        assert_eq!(
            schema["properties"]["motion"]["properties"]["linear_mps"]["type"],
            "number"
        );
        assert_eq!(schema["properties"]["seq"]["type"], "integer");
        let wheels = &schema["properties"]["motion"]["properties"]["wheel_mps"];
        assert_eq!(wheels["type"], "array");
        assert_eq!(wheels["items"]["type"], "number");
        assert_eq!(
            (&wheels["minItems"], &wheels["maxItems"]),
            (&4.into(), &4.into())
        );
    }

    #[test]
    fn timestamps_split_unix_nanoseconds() {
        let t = stamp(1_700_000_000_123_456_789);
        assert_eq!((t.sec(), t.nsec()), (1_700_000_000, 123_456_789));
    }

    #[test]
    fn a_gps_fix_is_published_only_when_there_is_one() {
        let mut s = driven(0.0, 0.0, 0.0);
        assert!(location_fix(&s, 0).is_none());
        s.touch(Group::Gps, 1);
        s.gps.fix_quality = 1;
        s.gps.latitude_deg = 48.1;
        s.gps.hdop = 1.0;
        let fix = location_fix(&s, 0).unwrap();
        assert_eq!(fix.latitude, 48.1);
        assert_eq!(fix.position_covariance[0], 25.0);
    }

    #[test]
    fn log_messages_carry_the_level_of_their_severity() {
        let m = log_message(
            "chassis record",
            Severity::Warning,
            "link: bus_down".into(),
            0,
        );
        assert_eq!(m.level, log::Level::Warning as i32);
        assert_eq!(m.name, "chassis record");
    }
}
