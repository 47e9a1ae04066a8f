//! `ChassisState` and `MuxStatus` → ROS 2 messages, as pure functions.
//!
//! Frames follow REP-103 and REP-105: `base_link` is x forward, y left, z up; `odom` is the frame
//! the robot started in. Stamps: every state sample carries `CLOCK_MONOTONIC` nanoseconds
//! (`stamp_ns`, the receive time of the frame that produced it). The bridge measures the offset
//! between the system clock and `CLOCK_MONOTONIC` once at start ([`RosClock::measure`]) and adds
//! it to every stamp, so messages carry ROS time (Unix time) and keep the monotonic clock's
//! spacing; a later step of the system clock (NTP) does not move them until the bridge restarts.

use chassis_client::{
    ChassisState, ClampFlags, FaultFlags, Group, LinkFlags, MuxStatus, RobotKind, WireProtocol,
    ZeroReason,
};

use chassis_protocols::profile::XbotProfile;

use crate::msg::{
    BatteryState, DiagnosticArray, DiagnosticStatus, Header, Imu, JointState, KeyValue, NavSatFix,
    NavSatStatus, Odometry, Point, Pose, PoseWithCovariance, Quaternion, Range, TfMessage, Time,
    Transform, TransformStamped, Twist, TwistWithCovariance, Vector3,
};

/// Frame names (`--frame-prefix` is prepended, e.g. `robot1/`).
#[derive(Debug, Clone)]
pub struct Frames {
    pub odom: String,
    pub base_link: String,
    pub gps: String,
    pub imu: String,
    prefix: String,
}

impl Frames {
    pub fn new(prefix: &str) -> Self {
        Self {
            odom: format!("{prefix}odom"),
            base_link: format!("{prefix}base_link"),
            gps: format!("{prefix}gps_link"),
            imu: format!("{prefix}imu_link"),
            prefix: prefix.to_string(),
        }
    }

    /// A sensor's frame: `<prefix><name>_link`.
    pub fn sensor(&self, name: &str) -> String {
        format!("{}{name}_link", self.prefix)
    }
}

/// `CLOCK_MONOTONIC` → ROS time (the system clock), with the offset measured once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosClock {
    offset_ns: i128,
}

impl RosClock {
    /// Reads both clocks once.
    // The bridge's one reading of the system clock, at start.
    #[allow(clippy::disallowed_methods)]
    pub fn measure() -> Self {
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        Self::with_offset(wall - i128::from(chassis_client::now_ns()))
    }

    /// A clock `offset_ns` ahead of `CLOCK_MONOTONIC`.
    pub fn with_offset(offset_ns: i128) -> Self {
        Self { offset_ns }
    }

    /// The ROS time of the monotonic instant `monotonic_ns`.
    pub fn ros_time(self, monotonic_ns: u64) -> Time {
        let ns = i128::from(monotonic_ns) + self.offset_ns;
        Time::from_nanos(i64::try_from(ns).unwrap_or(i64::MAX))
    }

    /// The monotonic instant of the ROS time `time`.
    pub fn monotonic_ns(self, time: Time) -> u64 {
        u64::try_from(i128::from(time.nanos()) - self.offset_ns).unwrap_or(0)
    }
}

/// Variance stated for what the wheels measure well (x, y, vx, vy; a robot that cannot move
/// sideways reports vy = 0 by construction). The pose's variances do not grow with distance here: the driver's
/// dead reckoning has no error model, and a localiser fusing `odom` (robot_localization) weighs
/// it by the twist, whose variance is stated.
pub const MEASURED_VARIANCE: f64 = 1e-3;
/// Variance stated for the yaw and yaw rate integrated from wheel speeds (skid steer slips).
pub const YAW_VARIANCE: f64 = 1e-2;
/// Variance for what a ground robot does not measure at all (z, roll, pitch and their rates):
/// large, as REP-105 odometry publishers state it.
pub const UNMEASURED_VARIANCE: f64 = 1e6;

/// The diagonal of a 6×6 covariance.
fn diagonal(values: [f64; 6]) -> [f64; 36] {
    let mut m = [0.0; 36];
    for (i, v) in values.into_iter().enumerate() {
        m[i * 7] = v;
    }
    m
}

fn finite(v: f32) -> f64 {
    if v.is_finite() { f64::from(v) } else { 0.0 }
}

/// `odom`: the driver's integrated pose and the reported body twist, odom → base_link.
pub fn odometry(state: &ChassisState, clock: RosClock, frames: &Frames) -> Odometry {
    let o = &state.odometry;
    let m = &state.motion;
    Odometry {
        header: Header::new(clock.ros_time(state.stamp_ns), &frames.odom),
        child_frame_id: frames.base_link.clone(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point {
                    x: o.x_m,
                    y: o.y_m,
                    z: 0.0,
                },
                orientation: Quaternion::from_yaw(o.yaw_rad),
            },
            covariance: diagonal([
                MEASURED_VARIANCE,
                MEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                YAW_VARIANCE,
            ]),
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3 {
                    x: finite(m.linear_mps),
                    y: finite(m.lateral_mps),
                    z: 0.0,
                },
                angular: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: finite(m.angular_radps),
                },
            },
            covariance: diagonal([
                MEASURED_VARIANCE,
                MEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                YAW_VARIANCE,
            ]),
        },
    }
}

/// `tf`: odom → base_link, the same pose as [`odometry`].
pub fn transform(state: &ChassisState, clock: RosClock, frames: &Frames) -> TfMessage {
    let o = &state.odometry;
    TfMessage {
        transforms: vec![TransformStamped {
            header: Header::new(clock.ros_time(state.stamp_ns), &frames.odom),
            child_frame_id: frames.base_link.clone(),
            transform: Transform {
                translation: Vector3 {
                    x: o.x_m,
                    y: o.y_m,
                    z: 0.0,
                },
                rotation: Quaternion::from_yaw(o.yaw_rad),
            },
        }],
    }
}

/// The wheel geometry joint states need: radius and travel per encoder count, m. Only the XBot's
/// manual gives them (its profile's defaults); the AgileX manuals give no wheel radius, so their
/// wheel joints are not published.
pub fn wheel_geometry(robot: u8) -> Option<WheelGeometry> {
    (robot == RobotKind::XBOT).then(|| {
        let xbot = XbotProfile::default();
        WheelGeometry {
            radius_m: xbot.wheel_diameter_m / 2.0,
            metres_per_count: xbot.metres_per_count(),
        }
    })
}

/// See [`wheel_geometry`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WheelGeometry {
    pub radius_m: f64,
    pub metres_per_count: f64,
}

/// The wheels in `ChassisState::motion.wheel_mps` order.
pub const WHEELS: [&str; 4] = ["front_left", "front_right", "rear_left", "rear_right"];

/// `joint_states`: the steering joints where the robot reports their angles (TITAN, HUNTER,
/// RANGER MINI: `front_steer_joint`, `rear_steer_joint`), and the wheel joints (angle and rate)
/// where the robot reports per-wheel speeds and its wheel radius is known (XBot). `None` when the
/// robot reports neither.
pub fn joint_states(
    state: &ChassisState,
    clock: RosClock,
    wheels: Option<WheelGeometry>,
) -> Option<JointState> {
    let mut joints = JointState {
        header: Header::new(clock.ros_time(state.stamp_ns), ""),
        ..JointState::default()
    };
    let steering = state.is_valid(Group::Steering);
    if steering {
        for (name, angle) in [
            ("front_steer_joint", state.motion.front_steer_rad),
            ("rear_steer_joint", state.motion.rear_steer_rad),
        ] {
            joints.name.push(name.to_string());
            joints.position.push(finite(angle));
            joints.velocity.push(f64::NAN);
        }
    }
    if let Some(w) = wheels.filter(|_| state.is_valid(Group::WheelSpeed)) {
        for (i, wheel) in WHEELS.iter().enumerate() {
            joints.name.push(format!("{wheel}_wheel_joint"));
            let travel_m = state.motors[i].position_counts as f64 * w.metres_per_count;
            joints.position.push(travel_m / w.radius_m);
            joints
                .velocity
                .push(finite(state.motion.wheel_mps[i]) / w.radius_m);
        }
    }
    (!joints.name.is_empty()).then_some(joints)
}

/// `battery_state`: the BMS pack where the robot has one, else the chassis' own battery reading.
/// Unmeasured fields are NaN, as `sensor_msgs/BatteryState` asks.
pub fn battery(state: &ChassisState, clock: RosClock, frames: &Frames) -> Option<BatteryState> {
    let mut b = BatteryState {
        header: Header::new(clock.ros_time(state.stamp_ns), &frames.base_link),
        voltage: f32::NAN,
        temperature: f32::NAN,
        current: f32::NAN,
        charge: f32::NAN,
        capacity: f32::NAN,
        design_capacity: f32::NAN,
        percentage: f32::NAN,
        power_supply_status: BatteryState::POWER_SUPPLY_STATUS_UNKNOWN,
        power_supply_health: BatteryState::POWER_SUPPLY_HEALTH_UNKNOWN,
        power_supply_technology: BatteryState::POWER_SUPPLY_TECHNOLOGY_UNKNOWN,
        present: true,
        ..BatteryState::default()
    };
    if state.is_valid(Group::BmsPack) {
        let pack = &state.bms[0];
        b.voltage = pack.voltage_v;
        b.current = -pack.current_a; // ROS: negative while discharging.
        b.temperature = pack.temperature_c;
        b.percentage = pack.soc_pct / 100.0;
        b.power_supply_status = if pack.current_a > 0.0 {
            BatteryState::POWER_SUPPLY_STATUS_DISCHARGING
        } else if pack.current_a < 0.0 {
            BatteryState::POWER_SUPPLY_STATUS_CHARGING
        } else {
            BatteryState::POWER_SUPPLY_STATUS_UNKNOWN
        };
        b.power_supply_health = if state.system.fault_flags & FaultFlags::OVER_TEMPERATURE != 0 {
            BatteryState::POWER_SUPPLY_HEALTH_OVERHEAT
        } else {
            BatteryState::POWER_SUPPLY_HEALTH_GOOD
        };
    } else if state.is_valid(Group::System) {
        let s = &state.system;
        b.voltage = s.battery_voltage_v;
        if s.battery_soc_pct > 0.0 {
            b.percentage = s.battery_soc_pct / 100.0;
        }
        if s.battery_current_a != 0.0 {
            b.current = -s.battery_current_a;
        }
    } else {
        return None;
    }
    Some(b)
}

/// `imu/data` (XBot): orientation from the board's roll, pitch and yaw, its rates and
/// accelerations. No covariance is known: each matrix's first element is 0 ("unknown"), as the
/// message's comment allows.
pub fn imu(state: &ChassisState, clock: RosClock, frames: &Frames) -> Option<Imu> {
    if !state.is_valid(Group::Imu) {
        return None;
    }
    let i = &state.imu;
    let v = |a: [f32; 3]| Vector3 {
        x: finite(a[0]),
        y: finite(a[1]),
        z: finite(a[2]),
    };
    Some(Imu {
        header: Header::new(
            clock.ros_time(state.group_stamp_ns[Group::Imu.index()]),
            &frames.imu,
        ),
        orientation: Quaternion::from_rpy(
            finite(i.roll_rad),
            finite(i.pitch_rad),
            finite(i.yaw_rad),
        ),
        orientation_covariance: [0.0; 9],
        angular_velocity: v(i.gyro_radps),
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: v(i.accel_mps2),
        linear_acceleration_covariance: [0.0; 9],
    })
}

/// One range sensor of the XBot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeSensor {
    /// Topic suffix and frame stem: `range/<name>`, `<name>_link`.
    pub name: &'static str,
    pub radiation_type: u8,
    /// Index into `RangesState::ir_m` or `ultrasonic_m`.
    pub index: usize,
}

/// The XBot's three rear IR cliff sensors and three front ultrasonic sensors (PROTOCOLS.md).
pub const XBOT_RANGES: [RangeSensor; 6] = [
    RangeSensor {
        name: "ir_rear_left",
        radiation_type: Range::INFRARED,
        index: 0,
    },
    RangeSensor {
        name: "ir_rear_centre",
        radiation_type: Range::INFRARED,
        index: 1,
    },
    RangeSensor {
        name: "ir_rear_right",
        radiation_type: Range::INFRARED,
        index: 2,
    },
    RangeSensor {
        name: "ultrasonic_front_left",
        radiation_type: Range::ULTRASOUND,
        index: 0,
    },
    RangeSensor {
        name: "ultrasonic_front_centre",
        radiation_type: Range::ULTRASOUND,
        index: 1,
    },
    RangeSensor {
        name: "ultrasonic_front_right",
        radiation_type: Range::ULTRASOUND,
        index: 2,
    },
];

/// `range/<sensor>` for one XBot sensor. The manual states neither field of view nor limits:
/// the message says so with `field_of_view` 0 and `min_range` 0 / `max_range` +∞.
pub fn range(
    state: &ChassisState,
    sensor: RangeSensor,
    clock: RosClock,
    frames: &Frames,
) -> Option<Range> {
    if !state.is_valid(Group::Ranges) {
        return None;
    }
    let r = &state.ranges;
    let value = if sensor.radiation_type == Range::INFRARED {
        r.ir_m[sensor.index]
    } else {
        r.ultrasonic_m[sensor.index]
    };
    Some(Range {
        header: Header::new(
            clock.ros_time(state.group_stamp_ns[Group::Ranges.index()]),
            &frames.sensor(sensor.name),
        ),
        radiation_type: sensor.radiation_type,
        field_of_view: 0.0,
        min_range: 0.0,
        max_range: f32::INFINITY,
        range: value,
        variance: 0.0,
    })
}

/// Horizontal error of a GPS receiver at HDOP 1, m (a common figure for a single-frequency
/// receiver): the covariance stated is `(hdop × this)²` horizontally, twice that vertically.
pub const GPS_UERE_M: f64 = 3.0;

/// `fix` (XBot GPS). Before the receiver has a fix: `STATUS_NO_FIX` with zeros.
pub fn nav_sat_fix(state: &ChassisState, clock: RosClock, frames: &Frames) -> Option<NavSatFix> {
    if !state.is_valid(Group::Gps) {
        return None;
    }
    let g = &state.gps;
    let stamp = clock.ros_time(state.group_stamp_ns[Group::Gps.index()]);
    let mut fix = NavSatFix {
        header: Header::new(stamp, &frames.gps),
        status: NavSatStatus {
            status: NavSatStatus::STATUS_NO_FIX,
            service: NavSatStatus::SERVICE_GPS,
        },
        ..NavSatFix::default()
    };
    if g.fix_quality == 0 {
        return Some(fix);
    }
    fix.status.status = match g.fix_quality {
        2 => NavSatStatus::STATUS_SBAS_FIX,
        4 | 5 => NavSatStatus::STATUS_GBAS_FIX,
        _ => NavSatStatus::STATUS_FIX,
    };
    fix.latitude = g.latitude_deg;
    fix.longitude = g.longitude_deg;
    fix.altitude = f64::from(g.altitude_m);
    if g.hdop > 0.0 && g.hdop.is_finite() {
        let h = (f64::from(g.hdop) * GPS_UERE_M).powi(2);
        fix.position_covariance = [h, 0.0, 0.0, 0.0, h, 0.0, 0.0, 0.0, 4.0 * h];
        fix.position_covariance_type = NavSatFix::COVARIANCE_TYPE_APPROXIMATED;
    }
    Some(fix)
}

/// `diagnostics`: the chassis' faults and warnings by name, the bus link, the mux decision with
/// its clamp reasons. `hardware_id` is the robot's name.
pub fn diagnostics(
    name: &str,
    state: Option<&ChassisState>,
    mux: Option<&MuxStatus>,
    stamp: Time,
) -> DiagnosticArray {
    let mut status = Vec::new();
    let prefix = "chassis";
    match state {
        Some(state) => {
            status.push(faults_status(name, prefix, state));
            status.push(link_status(name, prefix, state));
        }
        None => status.push(DiagnosticStatus {
            level: DiagnosticStatus::STALE,
            name: format!("{prefix}: link"),
            message: "no state from chassisd yet".into(),
            hardware_id: name.into(),
            values: Vec::new(),
        }),
    }
    if let Some(mux) = mux {
        status.push(mux_status(name, prefix, mux, state));
    }
    DiagnosticArray {
        header: Header::new(stamp, ""),
        status,
    }
}

fn faults_status(name: &str, prefix: &str, state: &ChassisState) -> DiagnosticStatus {
    let flags = state.system.fault_flags;
    let errors = flags & !FaultFlags::WARNINGS;
    let warnings = flags & FaultFlags::WARNINGS;
    let (level, message) = if errors != 0 {
        (
            DiagnosticStatus::ERROR,
            FaultFlags::names(errors).join(", "),
        )
    } else if warnings != 0 {
        (
            DiagnosticStatus::WARN,
            FaultFlags::names(warnings).join(", "),
        )
    } else {
        (DiagnosticStatus::OK, "no faults".to_string())
    };
    let mut values = vec![KeyValue::new(
        "vendor_fault_word",
        format!("0x{:08x}", state.system.vendor_fault_word),
    )];
    for (bit, fault) in FaultFlags::ALL {
        if flags & bit != 0 {
            let kind = if bit & FaultFlags::WARNINGS != 0 {
                "warning"
            } else {
                "fault"
            };
            values.push(KeyValue::new(fault, kind));
        }
    }
    DiagnosticStatus {
        level,
        name: format!("{prefix}: faults"),
        message,
        hardware_id: name.into(),
        values,
    }
}

fn link_status(name: &str, prefix: &str, state: &ChassisState) -> DiagnosticStatus {
    let l = &state.link;
    let down = state.link_flags & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT);
    let (level, message) = if down != 0 {
        (DiagnosticStatus::ERROR, LinkFlags::names(down).join(", "))
    } else if state.has_link_flag(LinkFlags::RC_AUTHORITY) {
        (
            DiagnosticStatus::WARN,
            "the RC transmitter has authority".into(),
        )
    } else {
        (
            DiagnosticStatus::OK,
            "bus up, chassis answering".to_string(),
        )
    };
    DiagnosticStatus {
        level,
        name: format!("{prefix}: link"),
        message,
        hardware_id: name.into(),
        values: vec![
            KeyValue::new("robot", RobotKind::name(state.robot)),
            KeyValue::new("protocol", WireProtocol::name(state.system.wire_protocol)),
            KeyValue::new("flags", LinkFlags::names(state.link_flags).join(", ")),
            KeyValue::new("rx_frames", l.rx_frames),
            KeyValue::new("tx_frames", l.tx_frames),
            KeyValue::new("rx_bad_checksum", l.rx_bad_checksum),
            KeyValue::new("rx_decode_errors", l.rx_decode_errors),
            KeyValue::new("rx_unknown_id", l.rx_unknown_id),
            KeyValue::new("tx_errors", l.tx_errors),
            KeyValue::new("bus_reconnects", l.bus_reconnects),
            KeyValue::new(
                "battery_voltage_v",
                format!("{:.2}", state.system.battery_voltage_v),
            ),
        ],
    }
}

fn mux_status(
    name: &str,
    prefix: &str,
    mux: &MuxStatus,
    state: Option<&ChassisState>,
) -> DiagnosticStatus {
    let active = mux.active().map_or("none", |s| s.name());
    let locks: Vec<&str> = mux
        .locks()
        .iter()
        .filter(|l| l.holder != chassis_client::LockStatus::HOLDER_NONE)
        .map(|l| l.name())
        .collect();
    let clamps = state.map_or(0, |s| s.command.clamp_flags);
    let (level, message) = if !locks.is_empty() {
        (
            DiagnosticStatus::WARN,
            format!("locked: {}", locks.join(", ")),
        )
    } else if mux.zero_reason == ZeroReason::REQUIRED_SOURCE_STALE {
        (
            DiagnosticStatus::WARN,
            "the required source is stale: holding zero".into(),
        )
    } else {
        (DiagnosticStatus::OK, format!("active source: {active}"))
    };
    DiagnosticStatus {
        level,
        name: format!("{prefix}: mux"),
        message,
        hardware_id: name.into(),
        values: vec![
            KeyValue::new("active", active),
            KeyValue::new("zero_reason", ZeroReason::name(mux.zero_reason)),
            KeyValue::new("locks_held", locks.join(", ")),
            KeyValue::new("clamps", ClampFlags::names(clamps).join(", ")),
        ],
    }
}

/// What [`diagnostics`] reports, without the counters: a change of it publishes at once.
pub fn diagnostics_key(array: &DiagnosticArray) -> Vec<(u8, String)> {
    array
        .status
        .iter()
        .map(|s| (s.level, s.message.clone()))
        .collect()
}
