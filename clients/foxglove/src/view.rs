//! What the robot looks like in Foxglove: state samples in, Foxglove's well-known messages out.
//!
//! Pure: every function takes the sample and the time to stamp it with; the live bridge and
//! `chassis record` own the clocks and the channels.
//!
//! Frames (REP 103: x forward, y left, z up; yaw left positive):
//!
//! | frame | parent | from |
//! | --- | --- | --- |
//! | `odom` | — | the fixed frame: where the service's odometry started |
//! | `base_link` | `odom` | `odometry.x_m`, `y_m`, `yaw_rad` |
//! | `imu`, `gps` | `base_link` | the centre of the body (their mounting is not in the manuals) |
//! | `us_left`, `us_centre`, `us_right` | `base_link` | XBot ultrasonic rangers, front edge, looking 30° left, ahead, 30° right |
//! | `ir_left`, `ir_centre`, `ir_right` | `base_link` | XBot IR cliff sensors, rear edge, looking back |

use chassis_client::{
    ChassisState, FaultFlags, Group, LinkFlags, MuxStatus, RobotDescription, SensorKind, ZeroReason,
};
use foxglove::messages::{
    Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms, LinePrimitive,
    LocationFix, Log, Point3, Pose, PoseInFrame, Quaternion, SceneEntity, SceneUpdate, Timestamp,
    Vector3, line_primitive, location_fix, log,
};

/// The fixed frame.
pub const ODOM: &str = "odom";
/// The robot's body frame.
pub const BASE_LINK: &str = "base_link";
/// Points kept in the trail of the path just driven.
pub const TRAIL_POINTS: usize = 2000;
/// A new trail point once the robot moved this far from the last one, m.
const TRAIL_STEP_M: f64 = 0.02;
/// Name under which the live bridge's log messages appear.
pub const LOG_NAME: &str = "chassis-foxglove";

/// A Foxglove timestamp from Unix-epoch nanoseconds.
pub fn stamp(wall_ns: u64) -> Timestamp {
    let sec = u32::try_from(wall_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (wall_ns % 1_000_000_000) as u32)
}

fn yaw_quaternion(yaw_rad: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (yaw_rad / 2.0).sin(),
        w: (yaw_rad / 2.0).cos(),
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

fn pose(x: f64, y: f64, z: f64, orientation: Quaternion) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(orientation),
    }
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// Which of the XBot's range sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RangeKind {
    Ultrasonic,
    Ir,
}

/// A range sensor mounted on the body.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMount {
    pub frame: String,
    pub kind: RangeKind,
    /// Index into `RangesState::ultrasonic_m` or `ir_m`.
    pub index: usize,
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// Full opening angle of the cone drawn, rad.
    pub cone_rad: f64,
}

/// The body drawn in the scene, from the robot's description.
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

/// `/tf`: odom → base_link from the odometry, base_link → each sensor frame.
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

/// `/scene`: the body in base_link, the XBot's range cones with their readings, the trail in
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

/// A `/log` message from the process `name`.
pub fn log_message(name: &str, level: log::Level, message: String, ns: u64) -> Log {
    Log {
        timestamp: Some(stamp(ns)),
        level: level as i32,
        message,
        name: name.into(),
        ..Log::default()
    }
}

/// What changed worth a log line between two samples: faults appearing and clearing, link
/// flags (bus down, RC authority, …) raised and lowered.
#[derive(Debug, Default)]
pub struct Watch {
    faults: Option<u64>,
    link: Option<u32>,
    mux: Option<(u8, u8, u8)>,
}

impl Watch {
    /// Log lines for the changes `state` brings.
    pub fn state(&mut self, state: &ChassisState) -> Vec<(log::Level, String)> {
        let mut out = Vec::new();
        let faults = state.system.fault_flags;
        let before = self.faults.replace(faults).unwrap_or(0);
        let raised = faults & !before;
        let cleared = before & !faults;
        if raised != 0 {
            out.push((
                log::Level::Error,
                format!("fault: {}", FaultFlags::names(raised).join(", ")),
            ));
        }
        if cleared != 0 {
            out.push((
                log::Level::Info,
                format!("fault cleared: {}", FaultFlags::names(cleared).join(", ")),
            ));
        }
        let link = state.link_flags;
        let before = self.link.replace(link).unwrap_or(0);
        let raised = link & !before;
        let lowered = before & !link;
        if raised != 0 {
            out.push((
                log::Level::Warning,
                format!("link: {}", LinkFlags::names(raised).join(", ")),
            ));
        }
        if lowered != 0 {
            out.push((
                log::Level::Info,
                format!("link: {} no more", LinkFlags::names(lowered).join(", ")),
            ));
        }
        out
    }

    /// A log line when the mux's winner (or its reason for zero) changes.
    pub fn mux(&mut self, mux: &MuxStatus) -> Option<(log::Level, String)> {
        let key = (mux.active_source, mux.zero_reason, mux.lock_count);
        let locks = held_locks(mux);
        let key = (key.0, key.1, u8::try_from(locks.len()).unwrap_or(u8::MAX));
        if self.mux.replace(key) == Some(key) {
            return None;
        }
        let mut text = match mux.active() {
            Some(source) => format!(
                "mux: {} drives (priority {})",
                source.name(),
                mux.active_priority
            ),
            None => format!("mux: zero ({})", ZeroReason::name(mux.zero_reason)),
        };
        if !locks.is_empty() {
            text.push_str(&format!("; locks held: {}", locks.join(", ")));
        }
        let level = if mux.active().is_some() {
            log::Level::Info
        } else {
            log::Level::Warning
        };
        Some((level, text))
    }
}

/// Names of the locks held.
pub fn held_locks(mux: &MuxStatus) -> Vec<String> {
    mux.locks()
        .iter()
        .filter(|l| l.held != 0)
        .map(|l| l.name().to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;

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
        let body = Body::of(&describe(&RobotKind::Xbot.entry().defaults()));
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
    fn timestamps_split_unix_nanoseconds() {
        let t = stamp(1_700_000_000_123_456_789);
        assert_eq!((t.sec(), t.nsec()), (1_700_000_000, 123_456_789));
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
        let body = Body::of(&describe(&RobotKind::Xbot.entry().defaults()));
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
            &Body::of(&describe(&RobotKind::Titan.entry().defaults())),
            &Trail::default(),
            0,
        );
        assert_eq!(titan.entities.len(), 2);
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

    /// The state the robot's own driver (default profile) makes of `frames`.
    fn driver_state(robot: RobotKind, frames: &[&str]) -> ChassisState {
        use chassis_protocols::{CanFrame, DriverConfig, Rx, Timestamp};
        let entry = robot.entry();
        let now = Timestamp::from_millis(1_000);
        let mut driver = entry.driver(&entry.defaults(), false, &DriverConfig::default(), now);
        for frame in frames {
            driver.handle_rx(now, Rx::Can(&CanFrame::from_candump(frame).unwrap()));
        }
        *driver.state()
    }

    #[test]
    fn a_v2_robots_estop_is_logged_by_name_and_so_is_its_release() {
        let mut watch = Watch::default();
        // TV8: BUNKER MINI 2.0, E-stop pressed (0x211 b0 = 0x01, fault word 0x0080).
        let pressed = driver_state(RobotKind::Bunker, &["211#0100010000800000"]);
        let lines = watch.state(&pressed);
        assert_eq!(
            lines,
            vec![(log::Level::Error, "fault: emergency_stop".to_string())]
        );
        let released = driver_state(RobotKind::Bunker, &["211#0000010000000000"]);
        let lines = watch.state(&released);
        assert_eq!(
            lines,
            vec![(
                log::Level::Info,
                "fault cleared: emergency_stop".to_string()
            )]
        );
    }

    #[test]
    fn faults_log_when_they_appear_and_when_they_clear() {
        let mut watch = Watch::default();
        let mut s = driven(0.0, 0.0, 0.0);
        assert!(watch.state(&s).is_empty());
        s.system.fault_flags = FaultFlags::from_name("battery_over_voltage").unwrap();
        let lines = watch.state(&s);
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].0, log::Level::Error);
        assert!(lines[0].1.contains("battery_over_voltage"), "{lines:?}");
        assert!(watch.state(&s).is_empty(), "unchanged: no line");
        s.system.fault_flags = 0;
        let lines = watch.state(&s);
        assert!(lines[0].1.starts_with("fault cleared"), "{lines:?}");
    }
}
