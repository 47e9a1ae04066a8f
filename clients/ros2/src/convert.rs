//! `ChassisState` and `MuxStatus` → ROS 2 messages, as pure functions. What the robot is —
//! its range sensors and their limits, its joints, its wheel geometry, the variances odometry
//! states — comes from the description chassisd publishes (`RobotDescription`), never from a
//! table of robots here.
//!
//! Frames follow REP-103 and REP-105: `base_link` is x forward, y left, z up; `odom` is the frame
//! the robot started in. Stamps: every state sample carries `CLOCK_MONOTONIC` nanoseconds
//! (`stamp_ns`, the receive time of the frame that produced it). [`RosClock`] is the client
//! library's [`WallClock`] (the offset between the system clock and `CLOCK_MONOTONIC`, measured
//! once at start): messages carry ROS time (Unix time) and keep the monotonic clock's spacing; a
//! later step of the system clock (NTP) does not move them until the bridge restarts.

use chassis_client::{
    ChassisState, ClampFlags, ControllerState, FaultFlags, Group, JointSource, LinkFlags,
    MuxStatus, OdometryVariance, RobotDescription, SafetyAction, SafetyRule, SafetyStatus,
    SensorKind, Stop, Unfollowed, WallClock, WireProtocol, ZeroReason,
};

use crate::msg::{
    BatteryState, DiagnosticArray, DiagnosticStatus, Header, Imu, JointState, KeyValue, NavSatFix,
    NavSatStatus, Odometry, Point, Pose, PoseWithCovariance, Quaternion, Range, StdString,
    TfMessage, Time, Transform, TransformStamped, Twist, TwistWithCovariance, Vector3,
};
use chassis_client::urdf::{self, UrdfError};
use chassis_protocols::RobotKind;

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

    /// A sensor's frame: `<prefix><name>_link` (the URDF's link of the sensor).
    pub fn sensor(&self, name: &str) -> String {
        chassis_client::urdf::link_of_sensor(&self.prefix, name)
    }
}

/// `CLOCK_MONOTONIC` → ROS time (the system clock): the client library's [`WallClock`] in ROS'
/// `Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosClock(WallClock);

impl RosClock {
    /// Reads both clocks once ([`WallClock::measure`]); with `monotonic_stamps` the stamps are
    /// `CLOCK_MONOTONIC` itself.
    pub fn new(monotonic_stamps: bool) -> Self {
        if monotonic_stamps {
            Self::with_offset(0)
        } else {
            Self(WallClock::measure())
        }
    }

    /// A clock `offset_ns` ahead of `CLOCK_MONOTONIC` (0: stamps are monotonic time).
    pub const fn with_offset(offset_ns: i128) -> Self {
        Self(WallClock::with_offset(offset_ns))
    }

    /// The ROS time of the monotonic instant `monotonic_ns`.
    pub fn ros_time(self, monotonic_ns: u64) -> Time {
        Time::from_nanos(i64::try_from(self.0.wall_ns(monotonic_ns)).unwrap_or(i64::MAX))
    }

    /// The monotonic instant of the ROS time `time`.
    pub fn monotonic_ns(self, time: Time) -> u64 {
        self.0
            .monotonic_ns(u64::try_from(time.nanos()).unwrap_or(0))
    }
}

/// Variance for what a ground robot does not measure at all (z, roll, pitch and their rates):
/// large, as REP-105 odometry publishers state it. What it does measure (x, y, yaw and their
/// rates) has the variances of the robot's description (`RobotDescription::odometry_variance`);
/// they do not grow with distance: the driver's dead reckoning has no error model, and a
/// localiser fusing `odom` (robot_localization) weighs it by the twist.
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

/// A variance as stated, or the unmeasured one where the description has none (NaN).
fn variance(v: f64) -> f64 {
    if v.is_finite() && v >= 0.0 {
        v
    } else {
        UNMEASURED_VARIANCE
    }
}

/// `odom`: the driver's integrated pose and the reported body twist, odom → base_link, with the
/// variances the robot's description states.
pub fn odometry(
    state: &ChassisState,
    variances: &OdometryVariance,
    clock: RosClock,
    frames: &Frames,
) -> Odometry {
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
                variance(variances.position_m2),
                variance(variances.position_m2),
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                variance(variances.yaw_rad2),
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
                variance(variances.linear_m2ps2),
                variance(variances.linear_m2ps2),
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                UNMEASURED_VARIANCE,
                variance(variances.angular_rad2ps2),
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

/// The robot's model, as ROS 2 publishes a robot's model: `robot_description` (its URDF,
/// [`chassis_client::urdf`], links under the frame prefix) and `tf_static` (the URDF's fixed
/// joints: `base_link` → `base_footprint`, → each sensor, → the tracks) stamped `stamp`, all in
/// one message as tf2's static broadcaster sends them.
pub fn robot_model(
    description: &RobotDescription,
    frames: &Frames,
    stamp: Time,
) -> Result<(StdString, TfMessage), UrdfError> {
    let text = urdf::urdf(description, &frames.prefix)?;
    let transforms = urdf::fixed_frames(description, &frames.prefix)?
        .into_iter()
        .map(|f| {
            let [x, y, z] = f.xyz;
            let [roll, pitch, yaw] = f.rpy;
            TransformStamped {
                header: Header::new(stamp, &f.parent),
                child_frame_id: f.child,
                transform: Transform {
                    translation: Vector3 { x, y, z },
                    rotation: Quaternion::from_rpy(roll, pitch, yaw),
                },
            }
        })
        .collect();
    Ok((StdString { data: text }, TfMessage { transforms }))
}

/// Which robot model was sent last: a description whose model differs sends it anew (a newer
/// description of the same robot sends nothing).
#[derive(Debug, Default)]
pub struct ModelSent {
    urdf: Option<String>,
    refused: Option<UrdfError>,
}

impl ModelSent {
    /// The model of `description` when it is not the one sent last ([`robot_model`]); `None`
    /// when it is, or when it cannot be written (logged once per reason).
    pub fn update(
        &mut self,
        description: &RobotDescription,
        frames: &Frames,
        stamp: Time,
    ) -> Option<(StdString, TfMessage)> {
        match robot_model(description, frames, stamp) {
            Ok((text, _)) if self.urdf.as_deref() == Some(text.data.as_str()) => None,
            Ok((text, tf)) => {
                self.urdf = Some(text.data.clone());
                self.refused = None;
                Some((text, tf))
            }
            Err(e) => {
                if self.refused.as_ref() != Some(&e) {
                    tracing::warn!(error = %e, "no robot_description, no tf_static");
                    self.refused = Some(e);
                }
                None
            }
        }
    }
}

/// The wheel geometry wheel joints need: radius and travel per encoder count, m, from the
/// description's geometry; `None` where it does not give both (the AgileX manuals give no wheel
/// radius: their wheel joints are not published). `(radius_m, metres_per_count)`.
pub fn wheel_geometry(description: &RobotDescription) -> Option<(f64, f64)> {
    let g = &description.geometry;
    (g.wheel_radius_m.is_finite()
        && g.wheel_radius_m > 0.0
        && g.travel_per_count_m.is_finite()
        && g.travel_per_count_m > 0.0)
        .then_some((g.wheel_radius_m, g.travel_per_count_m))
}

/// `joint_states`: the description's joints, in its order — steering joints where the robot
/// reports their angles, wheel joints (angle and rate) where it reports per-wheel speeds and its
/// wheel geometry is known. `None` when none of them has a reading.
pub fn joint_states(
    state: &ChassisState,
    description: &RobotDescription,
    clock: RosClock,
) -> Option<JointState> {
    let mut joints = JointState {
        header: Header::new(clock.ros_time(state.stamp_ns), ""),
        ..JointState::default()
    };
    let steering = state.is_valid(Group::Steering);
    let wheels = wheel_geometry(description).filter(|_| state.is_valid(Group::WheelSpeed));
    for joint in description.joints() {
        let (position, velocity) = match joint.source {
            JointSource::FRONT_STEER if steering => {
                (finite(state.motion.front_steer_rad), f64::NAN)
            }
            JointSource::REAR_STEER if steering => (finite(state.motion.rear_steer_rad), f64::NAN),
            JointSource::WHEEL => {
                let i = usize::from(joint.index);
                let (Some((radius_m, metres_per_count)), Some(motor), Some(speed)) =
                    (wheels, state.motors.get(i), state.motion.wheel_mps.get(i))
                else {
                    continue;
                };
                let travel_m = motor.position_counts as f64 * metres_per_count;
                (travel_m / radius_m, finite(*speed) / radius_m)
            }
            _ => continue,
        };
        joints.name.push(joint.name().to_string());
        joints.position.push(position);
        joints.velocity.push(velocity);
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

/// One range sensor of the robot's description.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeSensor {
    /// Topic suffix and frame stem: `range/<name>`, `<name>_link`.
    pub name: String,
    pub radiation_type: u8,
    /// Index into `RangesState::ir_m` or `ultrasonic_m`.
    pub index: usize,
    /// Full opening angle, rad; 0 where the description does not give it.
    pub field_of_view_rad: f32,
    /// Nearest and farthest reading, m; 0 and +∞ where the description does not give them.
    pub min_range_m: f32,
    pub max_range_m: f32,
}

/// The range sensors of `description`, in its order (`range/<name>` each).
pub fn range_sensors(description: &RobotDescription) -> Vec<RangeSensor> {
    let given = |v: f64, otherwise: f32| if v.is_finite() { v as f32 } else { otherwise };
    description
        .sensors()
        .iter()
        .filter(|s| SensorKind::is_range(s.kind))
        .map(|s| RangeSensor {
            name: s.name().to_string(),
            radiation_type: if s.kind == SensorKind::INFRARED {
                Range::INFRARED
            } else {
                Range::ULTRASOUND
            },
            index: usize::from(s.index),
            field_of_view_rad: given(s.field_of_view_rad, 0.0),
            min_range_m: given(s.min_range_m, 0.0),
            max_range_m: given(s.max_range_m, f32::INFINITY),
        })
        .collect()
}

/// `range/<sensor>` for one range sensor, with the limits its description states.
pub fn range(
    state: &ChassisState,
    sensor: &RangeSensor,
    clock: RosClock,
    frames: &Frames,
) -> Option<Range> {
    if !state.is_valid(Group::Ranges) {
        return None;
    }
    let r = &state.ranges;
    let readings: &[f32] = if sensor.radiation_type == Range::INFRARED {
        &r.ir_m
    } else {
        &r.ultrasonic_m
    };
    let value = *readings.get(sensor.index)?;
    Some(Range {
        header: Header::new(
            clock.ros_time(state.group_stamp_ns[Group::Ranges.index()]),
            &frames.sensor(&sensor.name),
        ),
        radiation_type: sensor.radiation_type,
        field_of_view: sensor.field_of_view_rad,
        min_range: sensor.min_range_m,
        max_range: sensor.max_range_m,
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
/// its clamp reasons, the safety monitor's decision with the cause of a chassis that does not
/// follow. `hardware_id` is the robot's name.
pub fn diagnostics(
    name: &str,
    state: Option<&ChassisState>,
    mux: Option<&MuxStatus>,
    safety: Option<&SafetyStatus>,
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
    if let Some(safety) = safety {
        status.push(safety_status(name, prefix, safety));
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
    let down = state.link_flags
        & (LinkFlags::BUS_DOWN | LinkFlags::CHASSIS_SILENT | LinkFlags::CAN_BUS_OFF);
    let (level, message) = if down != 0 {
        (DiagnosticStatus::ERROR, LinkFlags::names(down).join(", "))
    } else if state.has_link_flag(LinkFlags::CAN_ERROR_PASSIVE) {
        (
            DiagnosticStatus::WARN,
            "the CAN controller is error-passive: errors on the bus".into(),
        )
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
            KeyValue::new(
                "robot",
                RobotKind::from_id(state.robot).map_or("unknown", RobotKind::name),
            ),
            KeyValue::new("protocol", WireProtocol::name(state.system.wire_protocol)),
            KeyValue::new("flags", LinkFlags::names(state.link_flags).join(", ")),
            KeyValue::new("rx_frames", l.rx_frames),
            KeyValue::new("tx_frames", l.tx_frames),
            KeyValue::new("rx_bad_checksum", l.rx_bad_checksum),
            KeyValue::new("rx_decode_errors", l.rx_decode_errors),
            KeyValue::new("rx_unknown_id", l.rx_unknown_id),
            KeyValue::new("tx_errors", l.tx_errors),
            KeyValue::new("bus_reconnects", l.bus_reconnects),
            KeyValue::new("can_state", ControllerState::name(l.can_state)),
            KeyValue::new("can_tx_error_count", l.can_tx_error_count),
            KeyValue::new("can_rx_error_count", l.can_rx_error_count),
            KeyValue::new("can_bus_off", l.can_bus_off),
            KeyValue::new("can_restarts", l.can_restarts),
            KeyValue::new("can_error_passive", l.can_error_passive),
            KeyValue::new("can_bus_errors", l.can_bus_errors),
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
        .filter(|l| l.held == 1)
        .map(|l| l.name())
        .collect();
    let clamps = state.map_or(0, |s| s.command.clamp_flags);
    // A stop that is not the robot at rest: a lock, the safety monitor silent, a hold of the
    // bus or the chassis, a source that must ask for zero after one.
    let level = if !locks.is_empty()
        || matches!(
            mux.zero_reason,
            ZeroReason::REQUIRED_SOURCE_STALE | ZeroReason::HELD | ZeroReason::AWAITING_ZERO
        ) {
        DiagnosticStatus::WARN
    } else {
        DiagnosticStatus::OK
    };
    let message = mux.why().to_string();
    DiagnosticStatus {
        level,
        name: format!("{prefix}: mux"),
        message,
        hardware_id: name.into(),
        values: vec![
            KeyValue::new("active", active),
            KeyValue::new("zero_reason", ZeroReason::name(mux.zero_reason)),
            KeyValue::new("stop", Stop::name(mux.stop)),
            KeyValue::new("awaiting", mux.awaiting().map_or("", |s| s.name())),
            KeyValue::new("locks_held", locks.join(", ")),
            KeyValue::new("clamps", ClampFlags::names(clamps).join(", ")),
        ],
    }
}

/// The safety monitor's decision ([`SafetyStatus::why`]): a stop is an error, a slow-down a
/// warning.
fn safety_status(name: &str, prefix: &str, s: &SafetyStatus) -> DiagnosticStatus {
    let level = match s.action {
        SafetyAction::NONE => DiagnosticStatus::OK,
        SafetyAction::SLOW => DiagnosticStatus::WARN,
        _ => DiagnosticStatus::ERROR,
    };
    DiagnosticStatus {
        level,
        name: format!("{prefix}: safety"),
        message: s.why(),
        hardware_id: name.into(),
        values: vec![
            KeyValue::new("action", SafetyAction::name(s.action)),
            KeyValue::new("rules", SafetyRule::names(s.active_rules).join(", ")),
            KeyValue::new("unfollowed", Unfollowed::name(s.unfollowed)),
            KeyValue::new("last", s.last_text()),
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

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::{FaultFlags, Group, LinkFlags};
    use chassis_protocols::description::describe;

    const CLOCK: RosClock = RosClock::with_offset(1_700_000_000_000_000_000);

    fn described(kind: RobotKind) -> RobotDescription {
        describe(&kind.entry().defaults())
    }

    fn titan() -> ChassisState {
        let mut s = ChassisState {
            robot: RobotKind::Titan.id(),
            stamp_ns: 5_000_000_000,
            ..ChassisState::default()
        };
        s.touch(Group::Motion, s.stamp_ns);
        s.touch(Group::Pose, s.stamp_ns);
        s.touch(Group::System, s.stamp_ns);
        s.odometry.x_m = 1.0;
        s.odometry.y_m = 2.0;
        s.odometry.yaw_rad = std::f64::consts::FRAC_PI_2;
        s.motion.linear_mps = 0.5;
        s.motion.angular_radps = 0.25;
        s.system.battery_voltage_v = 52.0;
        s
    }

    #[test]
    fn stamps_are_monotonic_time_plus_the_measured_offset() {
        let t = CLOCK.ros_time(5_000_000_123);
        assert_eq!(t.nanos(), 1_700_000_005_000_000_123);
        assert_eq!(CLOCK.monotonic_ns(t), 5_000_000_123);
    }

    #[test]
    fn odometry_is_odom_to_base_link_with_the_pose_and_the_body_twist() {
        let frames = Frames::new("r1/");
        let d = described(RobotKind::Titan);
        let o = odometry(&titan(), &d.odometry_variance, CLOCK, &frames);
        assert_eq!(o.header.frame_id, "r1/odom");
        assert_eq!(o.child_frame_id, "r1/base_link");
        assert_eq!(o.header.stamp, CLOCK.ros_time(5_000_000_000));
        assert_eq!((o.pose.pose.position.x, o.pose.pose.position.y), (1.0, 2.0));
        let q = o.pose.pose.orientation;
        assert!((q.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert_eq!(o.twist.twist.linear.x, 0.5);
        assert_eq!(o.twist.twist.angular.z, 0.25);
        // The variances are the description's.
        let v = d.odometry_variance;
        assert_eq!(o.pose.covariance[0], v.position_m2);
        assert_eq!(o.pose.covariance[14], UNMEASURED_VARIANCE);
        assert_eq!(o.pose.covariance[35], v.yaw_rad2);
        assert_eq!(o.pose.covariance[1], 0.0);
        assert_eq!(o.twist.covariance[0], v.linear_m2ps2);
        assert_eq!(o.twist.covariance[35], v.angular_rad2ps2);
        let stated = OdometryVariance {
            position_m2: 0.25,
            yaw_rad2: f64::NAN,
            ..v
        };
        let o2 = odometry(&titan(), &stated, CLOCK, &frames);
        assert_eq!(o2.pose.covariance[0], 0.25);
        assert_eq!(
            o2.pose.covariance[35], UNMEASURED_VARIANCE,
            "NaN: not measured"
        );
        let tf = transform(&titan(), CLOCK, &frames);
        assert_eq!(tf.transforms[0].transform.rotation, q);
    }

    #[test]
    fn a_nan_speed_is_published_as_zero_not_nan() {
        let mut s = titan();
        s.motion.linear_mps = f32::NAN;
        let o = odometry(&s, &OdometryVariance::default(), CLOCK, &Frames::new(""));
        assert_eq!(o.twist.twist.linear.x, 0.0);
    }

    #[test]
    fn battery_prefers_the_bms_and_leaves_the_unmeasured_nan() {
        let s = titan();
        let b = battery(&s, CLOCK, &Frames::new("")).expect("system battery");
        assert_eq!(b.voltage, 52.0);
        assert!(b.percentage.is_nan() && b.capacity.is_nan() && b.current.is_nan());
        let mut s = titan();
        s.touch(Group::BmsPack, s.stamp_ns);
        s.bms[0].voltage_v = 48.5;
        s.bms[0].soc_pct = 80.0;
        s.bms[0].current_a = 3.0;
        let b = battery(&s, CLOCK, &Frames::new("")).expect("bms");
        assert_eq!((b.voltage, b.percentage, b.current), (48.5, 0.8, -3.0));
        assert_eq!(
            b.power_supply_status,
            BatteryState::POWER_SUPPLY_STATUS_DISCHARGING
        );
        assert!(battery(&ChassisState::default(), CLOCK, &Frames::new("")).is_none());
    }

    #[test]
    fn sensors_appear_only_where_the_robot_reports_them() {
        let s = titan();
        let f = Frames::new("");
        assert!(imu(&s, CLOCK, &f).is_none());
        let xbot = described(RobotKind::Xbot);
        assert!(range(&s, &range_sensors(&xbot)[0], CLOCK, &f).is_none());
        assert!(nav_sat_fix(&s, CLOCK, &f).is_none());
        assert!(joint_states(&s, &xbot, CLOCK).is_none());
        // A TITAN describes no range sensor: it gets no range topic.
        assert!(range_sensors(&described(RobotKind::Titan)).is_empty());
    }

    #[test]
    fn gps_without_a_fix_says_so_and_with_one_states_its_covariance() {
        let mut s = titan();
        s.touch(Group::Gps, s.stamp_ns);
        let f = Frames::new("");
        let none = nav_sat_fix(&s, CLOCK, &f).expect("gps reported");
        assert_eq!(none.status.status, NavSatStatus::STATUS_NO_FIX);
        s.gps.fix_quality = 1;
        s.gps.latitude_deg = 53.36;
        s.gps.longitude_deg = -6.5;
        s.gps.hdop = 2.0;
        let fix = nav_sat_fix(&s, CLOCK, &f).expect("fix");
        assert_eq!(fix.status.status, NavSatStatus::STATUS_FIX);
        assert_eq!((fix.latitude, fix.longitude), (53.36, -6.5));
        assert_eq!(fix.position_covariance[0], 36.0);
        assert_eq!(fix.position_covariance[8], 144.0);
        assert_eq!(
            fix.position_covariance_type,
            NavSatFix::COVARIANCE_TYPE_APPROXIMATED
        );
    }

    #[test]
    fn xbot_wheels_are_joints_in_radians() {
        let mut s = ChassisState {
            robot: RobotKind::Xbot.id(),
            ..ChassisState::default()
        };
        s.touch(Group::WheelSpeed, 1);
        s.motion.wheel_mps = [0.1, 0.2, 0.3, 0.4];
        s.motors[0].position_counts = 1000;
        let xbot = described(RobotKind::Xbot);
        let (radius_m, metres_per_count) = wheel_geometry(&xbot).expect("xbot geometry");
        let j = joint_states(&s, &xbot, CLOCK).expect("joints");
        let names: Vec<&str> = xbot.joints().iter().map(|j| j.name()).collect();
        assert_eq!(j.name, names, "the description's joints, in its order");
        assert_eq!(j.name[0], "front_left_wheel_joint");
        assert!((j.velocity[0] - 0.1 / radius_m).abs() < 1e-6);
        assert!((j.position[0] - 1000.0 * metres_per_count / radius_m).abs() < 1e-9);
        // Its two-wheel base describes the front pair only.
        assert_eq!(j.position.len(), 2);
        // Without a wheel radius (as the AgileX manuals give none): no wheel joints.
        let mut unknown = xbot;
        unknown.geometry.wheel_radius_m = f64::NAN;
        assert!(joint_states(&s, &unknown, CLOCK).is_none());
    }

    #[test]
    fn a_titan_publishes_its_described_steering_joints() {
        let mut s = titan();
        s.touch(Group::Steering, s.stamp_ns);
        s.motion.front_steer_rad = 0.2;
        s.motion.rear_steer_rad = -0.2;
        let d = described(RobotKind::Titan);
        let j = joint_states(&s, &d, CLOCK).expect("steering joints");
        assert_eq!(j.name, ["front_steer_joint", "rear_steer_joint"]);
        assert_eq!(j.position, [0.2f32 as f64, -0.2f32 as f64]);
    }

    #[test]
    fn range_topics_are_the_described_sensors_with_their_limits() {
        let xbot = described(RobotKind::Xbot);
        let sensors = range_sensors(&xbot);
        let described_ranges: Vec<_> = xbot
            .sensors()
            .iter()
            .filter(|s| SensorKind::is_range(s.kind))
            .collect();
        assert_eq!(sensors.len(), described_ranges.len());
        assert!(sensors.iter().any(|s| s.name == "ir_rear_left"));
        let mut s = ChassisState::default();
        s.touch(Group::Ranges, 7);
        s.ranges.ultrasonic_m = [0.5, 1.25, 2.0];
        let centre = sensors
            .iter()
            .find(|r| r.name == "ultrasonic_front_centre")
            .expect("the centre ultrasonic sensor");
        let d = described_ranges
            .iter()
            .find(|d| d.name() == "ultrasonic_front_centre")
            .unwrap();
        let r = range(&s, centre, CLOCK, &Frames::new("r1/")).expect("a reading");
        assert_eq!(r.range, 1.25);
        assert_eq!(r.header.frame_id, "r1/ultrasonic_front_centre_link");
        assert_eq!(r.radiation_type, Range::ULTRASOUND);
        if d.max_range_m.is_finite() {
            assert_eq!(r.max_range, d.max_range_m as f32);
        } else {
            assert_eq!(r.max_range, f32::INFINITY);
        }
    }

    #[test]
    fn the_model_is_the_urdf_and_its_fixed_frames_under_the_prefix() {
        let xbot = described(RobotKind::Xbot);
        let frames = Frames::new("r1/");
        let stamp = CLOCK.ros_time(7);
        let (urdf, tf) = robot_model(&xbot, &frames, stamp).expect("a model");
        assert!(urdf.data.starts_with("<?xml"), "{}", urdf.data);
        assert!(urdf.data.contains("<link name=\"r1/base_link\">"));
        // base_link → base_footprint, then each sensor at its mounting, as the URDF has them.
        assert_eq!(tf.transforms.len(), 1 + xbot.sensors().len());
        assert!(
            tf.transforms
                .iter()
                .all(|t| t.header.frame_id == frames.base_link)
        );
        assert!(tf.transforms.iter().all(|t| t.header.stamp == stamp));
        assert_eq!(tf.transforms[0].child_frame_id, "r1/base_footprint");
        for (t, s) in tf.transforms[1..].iter().zip(xbot.sensors()) {
            assert_eq!(t.child_frame_id, frames.sensor(s.name()));
            assert_eq!(
                (t.transform.translation.x, t.transform.translation.y),
                (s.x_m, s.y_m)
            );
            let q = t.transform.rotation;
            assert!(
                (2.0 * q.z.atan2(q.w) - s.yaw_rad).abs() < 1e-9,
                "{}",
                s.name()
            );
        }
        // The range topics' and the IMU's frames are links of the model.
        assert!(tf.transforms.iter().any(|t| t.child_frame_id == frames.imu));
        // Sent once; again only when the model changes.
        let mut sent = ModelSent::default();
        assert!(sent.update(&xbot, &frames, stamp).is_some());
        let mut newer = xbot;
        newer.seq += 1;
        assert!(sent.update(&newer, &frames, stamp).is_none());
        newer.geometry.track_m = 0.5;
        assert!(sent.update(&newer, &frames, stamp).is_some());
    }

    #[test]
    fn diagnostics_name_a_v2_robots_estop_and_keep_its_fault_word() {
        use chassis_protocols::{CanFrame, Driver, DriverConfig, Rx, Timestamp};
        // TV8 (BUNKER MINI 2.0, E-stop pressed) through the BUNKER's own driver.
        let entry = RobotKind::Bunker.entry();
        let now = Timestamp::from_millis(1_000);
        let mut driver = entry.driver(&entry.defaults(), false, &DriverConfig::default(), now);
        let tv8 = CanFrame::from_candump("211#0100010000800000").unwrap();
        driver.handle_rx(now, Rx::Can(&tv8));
        let d = diagnostics("bunker", Some(driver.state()), None, None, Time::default());
        let faults = &d.status[0];
        assert_eq!(faults.name, "chassis: faults");
        assert_eq!(faults.level, DiagnosticStatus::ERROR);
        assert_eq!(faults.message, "emergency_stop");
        let values: Vec<_> = faults
            .values
            .iter()
            .map(|kv| (kv.key.as_str(), kv.value.as_str()))
            .collect();
        assert_eq!(
            values,
            vec![
                ("vendor_fault_word", "0x00000080"),
                ("emergency_stop", "fault")
            ]
        );
    }

    #[test]
    fn diagnostics_name_faults_and_rank_errors_above_warnings() {
        let mut s = titan();
        let mux = MuxStatus::default();
        let d = diagnostics("titan", Some(&s), Some(&mux), None, Time::default());
        assert_eq!(d.status[0].level, DiagnosticStatus::OK);
        s.system.fault_flags = FaultFlags::BATTERY_LOW;
        let d = diagnostics("titan", Some(&s), Some(&mux), None, Time::default());
        assert_eq!(d.status[0].level, DiagnosticStatus::WARN);
        s.system.fault_flags |= FaultFlags::MOTOR_DRIVER_ERROR;
        let d = diagnostics("titan", Some(&s), Some(&mux), None, Time::default());
        assert_eq!(d.status[0].level, DiagnosticStatus::ERROR);
        assert!(d.status[0].values.iter().any(|kv| kv.value == "warning"));
        s.link_flags = LinkFlags::BUS_DOWN;
        let d = diagnostics("titan", Some(&s), Some(&mux), None, Time::default());
        assert_eq!(d.status[1].level, DiagnosticStatus::ERROR);
        assert!(d.status[1].message.contains("bus_down"));
        let stale = diagnostics("titan", None, None, None, Time::default());
        assert_eq!(stale.status[0].level, DiagnosticStatus::STALE);
        assert_ne!(diagnostics_key(&d), diagnostics_key(&stale));
    }

    #[test]
    fn diagnostics_carry_the_safety_monitors_decision_and_the_cause_it_names() {
        let s = titan();
        let mut safety = SafetyStatus::default();
        let d = diagnostics("titan", Some(&s), None, Some(&safety), Time::default());
        let status = d.status.last().unwrap();
        assert_eq!(
            (status.level, status.message.as_str()),
            (DiagnosticStatus::OK, "all clear")
        );
        safety.action = SafetyAction::STOP;
        safety.active_rules = SafetyRule::bit(SafetyRule::FOLLOWING);
        safety.unfollowed = Unfollowed::REMOTE_CONTROL;
        let d = diagnostics("titan", Some(&s), None, Some(&safety), Time::default());
        let status = d.status.last().unwrap();
        assert_eq!(status.name, "chassis: safety");
        assert_eq!(status.level, DiagnosticStatus::ERROR);
        assert_eq!(
            status.message,
            "STOP by following: a remote-control transmitter has the chassis"
        );
        assert!(
            status
                .values
                .iter()
                .any(|kv| kv.key == "unfollowed" && kv.value == "remote-control")
        );
    }

    #[test]
    fn diagnostics_report_the_can_controller() {
        let mut s = titan();
        let value = |d: &DiagnosticArray, key: &str| {
            d.status[1]
                .values
                .iter()
                .find(|kv| kv.key == key)
                .map(|kv| kv.value.clone())
                .unwrap()
        };
        s.link.can_state = ControllerState::ERROR_PASSIVE;
        s.link.can_tx_error_count = 130;
        s.link_flags = LinkFlags::CAN_ERROR_PASSIVE;
        let d = diagnostics("titan", Some(&s), None, None, Time::default());
        assert_eq!(d.status[1].level, DiagnosticStatus::WARN);
        assert_eq!(value(&d, "can_state"), "error-passive");
        assert_eq!(value(&d, "can_tx_error_count"), "130");
        s.link.can_state = ControllerState::BUS_OFF;
        s.link.can_bus_off = 1;
        s.link_flags = LinkFlags::CAN_BUS_OFF | LinkFlags::CHASSIS_SILENT;
        let d = diagnostics("titan", Some(&s), None, None, Time::default());
        assert_eq!(d.status[1].level, DiagnosticStatus::ERROR);
        assert!(
            d.status[1].message.contains("can_bus_off"),
            "{}",
            d.status[1].message
        );
        assert_eq!(value(&d, "can_bus_off"), "1");
    }
}
