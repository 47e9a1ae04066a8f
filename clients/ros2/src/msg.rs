//! The ROS 2 messages the bridge speaks, as plain serde structs in the field order of their
//! `.msg` definitions (ROS 2 Jazzy), so that RustDDS' CDR serializer writes exactly what a ROS 2
//! node writes. [`ros2_client`] turns the package and type names into the DDS names ROS 2 uses
//! (`geometry_msgs/msg/Twist` → `geometry_msgs::msg::dds_::Twist_`).
//!
//! They are declared here rather than taken from a generated message crate: the crates that
//! generate them are built against older `ros2-client` releases, and this bridge needs only the
//! twenty-odd types below.

use ros2_client::{Message, MessageTypeName};
use serde::{Deserialize, Serialize};
use serde_big_array::BigArray;

/// A message type with its ROS 2 package and name.
pub trait Typed: Message {
    const PACKAGE: &'static str;
    const NAME: &'static str;

    fn type_name() -> MessageTypeName {
        MessageTypeName::new(Self::PACKAGE, Self::NAME)
    }
}

macro_rules! typed {
    ($ty:ident, $package:literal, $name:literal) => {
        impl Message for $ty {}
        impl Typed for $ty {
            const PACKAGE: &'static str = $package;
            const NAME: &'static str = $name;
        }
    };
}

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the Unix epoch (ROS time).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch (clamped to what `sec: i32` holds).
    pub fn from_nanos(ns: i64) -> Self {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000);
        Self {
            sec: i32::try_from(sec).unwrap_or(if sec < 0 { i32::MIN } else { i32::MAX }),
            nanosec: u32::try_from(nanosec).unwrap_or(0),
        }
    }

    /// Nanoseconds since the epoch.
    pub fn nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    pub fn new(stamp: Time, frame_id: &str) -> Self {
        Self {
            stamp,
            frame_id: frame_id.to_string(),
        }
    }
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quaternion {
    pub const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// The rotation by `yaw` about z.
    pub fn from_yaw(yaw: f64) -> Self {
        Self::from_rpy(0.0, 0.0, yaw)
    }

    /// The rotation by roll about x, then pitch about y, then yaw about z (fixed axes).
    pub fn from_rpy(roll: f64, pitch: f64, yaw: f64) -> Self {
        let (sr, cr) = (roll / 2.0).sin_cos();
        let (sp, cp) = (pitch / 2.0).sin_cos();
        let (sy, cy) = (yaw / 2.0).sin_cos();
        Self {
            x: sr * cp * cy - cr * sp * sy,
            y: cr * sp * cy + sr * cp * sy,
            z: cr * cp * sy - sr * sp * cy,
            w: cr * cp * cy + sr * sp * sy,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseWithCovariance`: row-major 6×6 over (x, y, z, roll, pitch, yaw).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
typed!(Twist, "geometry_msgs", "Twist");

/// `geometry_msgs/msg/TwistStamped` (what Jazzy's controllers take on `cmd_vel`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    pub header: Header,
    pub twist: Twist,
}
typed!(TwistStamped, "geometry_msgs", "TwistStamped");

/// `geometry_msgs/msg/TwistWithCovariance`: row-major 6×6 over (vx, vy, vz, wx, wy, wz).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    #[serde(with = "BigArray")]
    pub covariance: [f64; 36],
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}
typed!(Odometry, "nav_msgs", "Odometry");

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}
typed!(TfMessage, "tf2_msgs", "TFMessage");

/// `sensor_msgs/msg/JointState`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}
typed!(JointState, "sensor_msgs", "JointState");

/// `sensor_msgs/msg/BatteryState`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BatteryState {
    pub header: Header,
    pub voltage: f32,
    pub temperature: f32,
    pub current: f32,
    pub charge: f32,
    pub capacity: f32,
    pub design_capacity: f32,
    pub percentage: f32,
    pub power_supply_status: u8,
    pub power_supply_health: u8,
    pub power_supply_technology: u8,
    pub present: bool,
    pub cell_voltage: Vec<f32>,
    pub cell_temperature: Vec<f32>,
    pub location: String,
    pub serial_number: String,
}
typed!(BatteryState, "sensor_msgs", "BatteryState");

impl BatteryState {
    pub const POWER_SUPPLY_STATUS_UNKNOWN: u8 = 0;
    pub const POWER_SUPPLY_STATUS_CHARGING: u8 = 1;
    pub const POWER_SUPPLY_STATUS_DISCHARGING: u8 = 2;
    pub const POWER_SUPPLY_HEALTH_UNKNOWN: u8 = 0;
    pub const POWER_SUPPLY_HEALTH_GOOD: u8 = 1;
    pub const POWER_SUPPLY_HEALTH_OVERHEAT: u8 = 2;
    pub const POWER_SUPPLY_TECHNOLOGY_UNKNOWN: u8 = 0;
}

/// `sensor_msgs/msg/Imu`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}
typed!(Imu, "sensor_msgs", "Imu");

/// `sensor_msgs/msg/Range` as of ROS 2 Jazzy (with `variance`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Range {
    pub header: Header,
    pub radiation_type: u8,
    pub field_of_view: f32,
    pub min_range: f32,
    pub max_range: f32,
    pub range: f32,
    pub variance: f32,
}
typed!(Range, "sensor_msgs", "Range");

impl Range {
    pub const ULTRASOUND: u8 = 0;
    pub const INFRARED: u8 = 1;
}

/// `sensor_msgs/msg/NavSatStatus`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NavSatStatus {
    pub status: i8,
    pub service: u16,
}

impl NavSatStatus {
    pub const STATUS_NO_FIX: i8 = -1;
    pub const STATUS_FIX: i8 = 0;
    pub const STATUS_SBAS_FIX: i8 = 1;
    pub const STATUS_GBAS_FIX: i8 = 2;
    pub const SERVICE_GPS: u16 = 1;
}

/// `sensor_msgs/msg/NavSatFix`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NavSatFix {
    pub header: Header,
    pub status: NavSatStatus,
    pub latitude: f64,
    pub longitude: f64,
    pub altitude: f64,
    pub position_covariance: [f64; 9],
    pub position_covariance_type: u8,
}
typed!(NavSatFix, "sensor_msgs", "NavSatFix");

impl NavSatFix {
    pub const COVARIANCE_TYPE_UNKNOWN: u8 = 0;
    pub const COVARIANCE_TYPE_APPROXIMATED: u8 = 1;
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}

impl KeyValue {
    pub fn new(key: &str, value: impl ToString) -> Self {
        Self {
            key: key.to_string(),
            value: value.to_string(),
        }
    }
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
    pub const STALE: u8 = 3;
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}
typed!(DiagnosticArray, "diagnostic_msgs", "DiagnosticArray");

/// `std_msgs/msg/Bool`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Bool {
    pub data: bool,
}
typed!(Bool, "std_msgs", "Bool");

/// `nav2_msgs/msg/SpeedLimit`: Nav2's speed filter's limit, absolute m/s or percent of the
/// robot's maximum; 0 is no limit.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SpeedLimit {
    pub header: Header,
    pub percentage: bool,
    pub speed_limit: f64,
}
typed!(SpeedLimit, "nav2_msgs", "SpeedLimit");

/// `std_msgs/msg/String` (`robot_description` carries the URDF in one).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StdString {
    pub data: String,
}
typed!(StdString, "std_msgs", "String");

/// `std_srvs/srv/Trigger` request. ROS 2 gives a message without fields one byte,
/// `structure_needs_at_least_one_member`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerRequest {
    pub structure_needs_at_least_one_member: u8,
}
impl Message for TriggerRequest {}

/// `std_srvs/srv/Trigger` response.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub success: bool,
    pub message: String,
}
impl Message for TriggerResponse {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_splits_nanoseconds_and_keeps_negative_times_ordered() {
        let t = Time::from_nanos(1_700_000_000_123_456_789);
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_789));
        assert_eq!(t.nanos(), 1_700_000_000_123_456_789);
        let before = Time::from_nanos(-1);
        assert_eq!((before.sec, before.nanosec), (-1, 999_999_999));
        assert!(before < Time::default());
    }

    #[test]
    fn quaternion_from_yaw_turns_about_z() {
        let q = Quaternion::from_yaw(std::f64::consts::FRAC_PI_2);
        let half = std::f64::consts::FRAC_PI_4;
        assert!((q.z - half.sin()).abs() < 1e-12);
        assert!((q.w - half.cos()).abs() < 1e-12);
        assert_eq!((q.x, q.y), (0.0, 0.0));
        assert_eq!(Quaternion::from_yaw(0.0), Quaternion::IDENTITY);
    }

    #[test]
    fn type_names_are_ros_2_dds_names() {
        assert_eq!(
            Twist::type_name().dds_msg_type(),
            "geometry_msgs::msg::dds_::Twist_"
        );
        assert_eq!(
            TfMessage::type_name().dds_msg_type(),
            "tf2_msgs::msg::dds_::TFMessage_"
        );
    }
}
