//! `RobotDescription`: what the robot `chassisd` drives *is* — its kind, model and protocol, the
//! effective profile after every override (limits, geometry, battery levels), its sensors with
//! their mounting, its joints and the mux's source table — published on `chassis/<name>/robot`
//! with history 1, so a client that starts an hour later reads it at once.
//!
//! Clients (safety monitor, planner, views, bridges, Python) read robot facts from here, never
//! from a table of their own. Unknown values are NaN (a length the manuals do not give); counts
//! say how many entries of each fixed array are used.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;
use crate::text::{serialize_fixed_str, write_fixed_str};
use crate::{MAX_SOURCES, NAME_LEN};

/// Most sensors a description lists.
pub const MAX_SENSORS: usize = 12;
/// Most joints a description lists.
pub const MAX_JOINTS: usize = 12;
/// Length of a sensor's or joint's name (also its frame id), NUL-padded UTF-8.
pub const LABEL_LEN: usize = 32;

named_constants! {
    /// How the robot's wheels turn a twist into motion (`RobotDescription::kinematics`).
    pub enum Kinematics: u8 {
        /// Two driven wheels (or sides): (v, ω).
        DIFFERENTIAL = 1 => "differential",
        /// Four wheels, skid-steered: (v, ω), turning by slipping.
        SKID_STEER = 2 => "skid_steer",
        /// Tracks: (v, ω), turning by slipping.
        TRACKED = 3 => "tracked",
        /// Mecanum or omni wheels: (v, v_y, ω).
        OMNI = 4 => "omni",
        /// Front-wheel Ackermann: (v, δ); no turn on the spot.
        ACKERMANN = 5 => "ackermann",
        /// Front and rear axles steering opposite (TITAN): (v, δ).
        DUAL_ACKERMANN = 6 => "dual_ackermann",
        /// Four independently steered wheels (dual Ackermann, crab, spin).
        FOUR_WHEEL_STEER = 7 => "four_wheel_steer",
    }
}

impl Kinematics {
    /// True where the robot steers its wheels and cannot turn on the spot by (v = 0, ω).
    pub fn steers(kinematics: u8) -> bool {
        matches!(kinematics, Self::ACKERMANN | Self::DUAL_ACKERMANN)
    }
}

named_constants! {
    /// Which bus the robot is on (`RobotDescription::bus`).
    pub enum BusKind: u8 {
        /// CAN (SocketCAN, slcan).
        CAN = 1 => "can",
        /// RS232 byte stream.
        RS232 = 2 => "rs232",
    }
}

named_constants! {
    /// Bits of [`RobotDescription::flags`].
    pub flags DescriptionFlags: u8 {
        /// The bus is the simulated chassis (embedded or `chassisd sim`), not a robot.
        SIMULATED = 1 << 0 => "simulated",
        /// The robot has a parking brake chassisd can lock and release.
        BRAKE = 1 << 1 => "brake",
        /// The robot has lights chassisd can switch.
        LIGHTS = 1 << 2 => "lights",
        /// The robot can move sideways (`linear_y`).
        LATERAL = 1 << 3 => "lateral",
        /// The mux requires its safety source (`--no-safety-monitor` not given).
        SAFETY_REQUIRED = 1 << 4 => "safety_required",
    }
}

named_constants! {
    /// What a sensor measures (`SensorDescription::kind`).
    pub enum SensorKind: u8 {
        /// An ultrasonic range sensor: its reading is `RangesState::ultrasonic_m[index]`.
        ULTRASONIC = 1 => "ultrasonic",
        /// An infrared range sensor: `RangesState::ir_m[index]`.
        INFRARED = 2 => "infrared",
        /// An inertial unit: `ChassisState::imu`.
        IMU = 3 => "imu",
        /// A GNSS receiver: `ChassisState::gps`.
        GPS = 4 => "gps",
        /// Bumpers: `FaultFlags::BUMPER`.
        BUMPER = 5 => "bumper",
    }
}

impl SensorKind {
    /// True for the range sensors (a cone in a view, a `sensor_msgs/Range` in ROS 2).
    pub fn is_range(kind: u8) -> bool {
        matches!(kind, Self::ULTRASONIC | Self::INFRARED)
    }
}

named_constants! {
    /// Which reading of the state a joint's position comes from (`JointDescription::source`).
    pub enum JointSource: u8 {
        /// `MotionState::front_steer_rad` (a revolute steering joint).
        FRONT_STEER = 1 => "front_steer",
        /// `MotionState::rear_steer_rad`.
        REAR_STEER = 2 => "rear_steer",
        /// A wheel: `MotionState::wheel_mps[index]` and `MotorState::position_counts` of motor
        /// `index` (continuous; needs the geometry's wheel radius and travel per count).
        WHEEL = 3 => "wheel",
    }
}

ipc_type! {
    /// Speed and acceleration limits; NaN where there is none.
    #[derive(Default, Serialize)]
    #[type_name("chassis::MotionLimits.v2")]
    pub struct MotionLimits {
        /// Largest forward speed, m/s.
        pub forward_mps: f64,
        /// Largest reverse speed (a positive number), m/s.
        pub reverse_mps: f64,
        /// Largest |lateral speed|, m/s (0: the robot cannot move sideways).
        pub lateral_mps: f64,
        /// Largest |yaw rate|, rad/s.
        pub angular_radps: f64,
        /// Largest |steering angle| (inner wheel), rad; NaN where the robot does not steer.
        pub steer_rad: f64,
        /// Largest |linear acceleration|, m/s²; NaN: not limited.
        pub linear_accel_mps2: f64,
        /// Largest |yaw acceleration|, rad/s²; NaN: not limited.
        pub angular_accel_radps2: f64,
        /// The deceleration of a controlled stop, m/s² (a held lock's stop of category 1 or 2
        /// ramps the command down at it), for a planner sizing its protective field
        /// (`v ≤ √(2·a·d)`); NaN: unknown (zero is commanded at once and the chassis brakes at
        /// its own rate).
        pub braking_mps2: f64,
    }
}

impl MotionLimits {
    /// No limit at all.
    pub const NONE: MotionLimits = MotionLimits {
        forward_mps: f64::NAN,
        reverse_mps: f64::NAN,
        lateral_mps: f64::NAN,
        angular_radps: f64::NAN,
        steer_rad: f64::NAN,
        linear_accel_mps2: f64::NAN,
        angular_accel_radps2: f64::NAN,
        braking_mps2: f64::NAN,
    };

    /// The tighter of two limits, field by field (NaN: no limit on that side).
    pub fn tighter(&self, other: &MotionLimits) -> MotionLimits {
        let min = |a: f64, b: f64| match (a.is_nan(), b.is_nan()) {
            (true, _) => b,
            (_, true) => a,
            _ => a.min(b),
        };
        MotionLimits {
            forward_mps: min(self.forward_mps, other.forward_mps),
            reverse_mps: min(self.reverse_mps, other.reverse_mps),
            lateral_mps: min(self.lateral_mps, other.lateral_mps),
            angular_radps: min(self.angular_radps, other.angular_radps),
            steer_rad: min(self.steer_rad, other.steer_rad),
            linear_accel_mps2: min(self.linear_accel_mps2, other.linear_accel_mps2),
            angular_accel_radps2: min(self.angular_accel_radps2, other.angular_accel_radps2),
            braking_mps2: min(self.braking_mps2, other.braking_mps2),
        }
    }
}

ipc_type! {
    /// The robot's geometry, m; NaN where the manuals do not give it.
    #[derive(Default, Serialize)]
    #[type_name("chassis::Geometry.v1")]
    pub struct Geometry {
        /// Distance between the axles, m.
        pub wheelbase_m: f64,
        /// Distance between the left and right wheels (or tracks), m.
        pub track_m: f64,
        /// Drive wheel radius, m.
        pub wheel_radius_m: f64,
        /// Wheel travel per encoder count, m.
        pub travel_per_count_m: f64,
        /// The body's outline, centred on `base_link`: length (x), width (y), height (z), m.
        pub length_m: f64,
        pub width_m: f64,
        pub height_m: f64,
        /// Smallest radius of `base_link`'s path while driving (robots that steer: the inner
        /// wheels at full lock), m; 0 where it turns on the spot. A four-wheel-steered robot
        /// (RANGER MINI) drives dual Ackermann down to this radius and spins on the spot below it.
        pub min_turn_radius_m: f64,
    }
}

ipc_type! {
    /// Battery levels; NaN where the robot reports no such reading or the manual gives no level.
    #[derive(Default, Serialize)]
    #[type_name("chassis::BatteryLevels.v1")]
    pub struct BatteryLevels {
        /// Pack voltage when full, V.
        pub full_v: f64,
        /// Below this the chassis warns (its under-voltage alarm), V.
        pub low_v: f64,
        /// Below this the chassis cuts drive power (its under-voltage failure), V.
        pub critical_v: f64,
        /// State of charge below which the chassis warns, %.
        pub low_soc_pct: f64,
        /// State of charge below which the chassis cuts drive power, %.
        pub critical_soc_pct: f64,
    }
}

ipc_type! {
    /// Odometry's stated (not measured) variances, for the bridges' covariance matrices.
    #[derive(Default, Serialize)]
    #[type_name("chassis::OdometryVariance.v1")]
    pub struct OdometryVariance {
        /// Of x and y, m².
        pub position_m2: f64,
        /// Of yaw, rad².
        pub yaw_rad2: f64,
        /// Of the linear and lateral speed, (m/s)².
        pub linear_m2ps2: f64,
        /// Of the yaw rate, (rad/s)².
        pub angular_rad2ps2: f64,
    }
}

ipc_type! {
    /// One sensor and where it sits on the body (in `base_link`, REP-103 axes).
    #[derive(Default, Serialize)]
    #[type_name("chassis::SensorDescription.v1")]
    pub struct SensorDescription {
        /// The sensor's name, also its frame id (`ultrasonic_front_left`).
        #[serde(serialize_with = "serialize_fixed_str")]
        pub name: [u8; LABEL_LEN] as text,
        /// [`SensorKind`].
        pub kind: u8,
        /// Index of its reading in the state (e.g. `RangesState::ultrasonic_m[index]`).
        pub index: u8,
        #[serde(skip)]
        pub _reserved: [u8; 6],
        pub x_m: f64,
        pub y_m: f64,
        pub z_m: f64,
        /// Heading of its axis, rad, left of forward positive.
        pub yaw_rad: f64,
        /// Full opening angle of a range sensor's cone, rad (NaN otherwise).
        pub field_of_view_rad: f64,
        /// Nearest and farthest reading a range sensor gives, m (NaN otherwise).
        pub min_range_m: f64,
        pub max_range_m: f64,
    }
}

ipc_type! {
    /// One joint the bridges publish (`sensor_msgs/JointState`).
    #[derive(Default, Serialize)]
    #[type_name("chassis::JointDescription.v1")]
    pub struct JointDescription {
        /// The joint's name (`front_steer_joint`, `front_left_wheel_joint`).
        #[serde(serialize_with = "serialize_fixed_str")]
        pub name: [u8; LABEL_LEN] as text,
        /// [`JointSource`]: which reading of the state is its position.
        pub source: u8,
        /// Which wheel (`MotionState::wheel_mps` order) for a wheel joint.
        pub index: u8,
        #[serde(skip)]
        pub _reserved: [u8; 6],
    }
}

ipc_type! {
    /// One velocity source of the mux, as configured.
    #[derive(Default, Serialize)]
    #[type_name("chassis::SourceDescription.v1")]
    pub struct SourceDescription {
        /// Source name (`teleop`): the service `chassis/<name>/cmd/<source>`.
        #[serde(serialize_with = "serialize_fixed_str")]
        pub name: [u8; NAME_LEN] as text,
        /// Its request ends its motion this long after it was made, ms.
        pub timeout_ms: u32,
        pub priority: u8,
        /// `SourceFlags::REQUIRED` and `SourceFlags::REMOTE` as configured.
        pub flags: u8,
        #[serde(skip)]
        pub _reserved: [u8; 2],
    }
}

ipc_type! {
    /// The robot `chassisd` drives, as it is configured and detected: see the module doc.
    #[type_name("chassis::RobotDescription.v2")]
    pub struct RobotDescription {
        /// Bumped at every publication (a change of protocol once detection decides).
        pub seq: u64,
        /// `CLOCK_MONOTONIC` when it was published, ns.
        pub stamp_ns: u64,
        /// The robot's kind: `chassis_protocols::RobotKind` as a number, as in
        /// `ChassisState::robot`.
        pub kind: u8,
        /// `WireProtocol` in use (`DETECTING` until detection decides).
        pub protocol: u8,
        /// [`Kinematics`].
        pub kinematics: u8,
        /// [`BusKind`].
        pub bus: u8,
        /// [`DescriptionFlags`].
        pub flags: u8,
        pub sensor_count: u8,
        pub joint_count: u8,
        pub source_count: u8,
        /// The robot's name (`--name`): its services are `chassis/<name>/…`.
        pub name: [u8; NAME_LEN] as text,
        /// The kind's `--robot` spelling (`hunter`).
        pub kind_name: [u8; NAME_LEN] as text,
        /// The variant of the kind the profile describes (`scout-mini-omni`, `ranger-mini-v1`, or
        /// the kind's name).
        pub model: [u8; LABEL_LEN] as text,
        /// What people call it (`AgileX HUNTER 2.0`).
        pub display_name: [u8; LABEL_LEN] as text,
        /// The limits the driver itself applies: the robot's profile after overrides.
        pub robot_limits: MotionLimits,
        /// chassisd's configured speed and acceleration limits (`[mux]`), applied to every source.
        pub configured_limits: MotionLimits,
        pub geometry: Geometry,
        pub battery: BatteryLevels,
        pub odometry_variance: OdometryVariance,
        /// The chassis' own command timeout, ms (it stops without a command for this long).
        pub command_timeout_ms: u32,
        /// The heartbeat chassisd sends, ms.
        pub heartbeat_period_ms: u32,
        pub sensors: [SensorDescription; MAX_SENSORS],
        pub joints: [JointDescription; MAX_JOINTS],
        pub sources: [SourceDescription; MAX_SOURCES],
    }
}

impl Default for RobotDescription {
    fn default() -> Self {
        Self {
            robot_limits: MotionLimits::NONE,
            configured_limits: MotionLimits::NONE,
            geometry: Geometry {
                wheelbase_m: f64::NAN,
                track_m: f64::NAN,
                wheel_radius_m: f64::NAN,
                travel_per_count_m: f64::NAN,
                length_m: f64::NAN,
                width_m: f64::NAN,
                height_m: f64::NAN,
                min_turn_radius_m: f64::NAN,
            },
            battery: BatteryLevels {
                full_v: f64::NAN,
                low_v: f64::NAN,
                critical_v: f64::NAN,
                low_soc_pct: f64::NAN,
                critical_soc_pct: f64::NAN,
            },
            // Every other field zero: no name, no sensor, joint or source.
            ..zerocopy::FromZeros::new_zeroed()
        }
    }
}

/// A list of the description is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a robot description holds at most {max} {what}")]
pub struct DescriptionFull {
    pub what: &'static str,
    pub max: usize,
}

impl DescriptionFull {
    const fn of(what: &'static str, max: usize) -> Self {
        Self { what, max }
    }
}

impl RobotDescription {
    pub fn set_name(&mut self, name: &str) {
        write_fixed_str(&mut self.name, name);
    }

    pub fn set_kind_name(&mut self, name: &str) {
        write_fixed_str(&mut self.kind_name, name);
    }

    pub fn set_model(&mut self, model: &str) {
        write_fixed_str(&mut self.model, model);
    }

    pub fn set_display_name(&mut self, name: &str) {
        write_fixed_str(&mut self.display_name, name);
    }

    /// The sensors in use.
    pub fn sensors(&self) -> &[SensorDescription] {
        &self.sensors[..usize::from(self.sensor_count).min(MAX_SENSORS)]
    }

    /// The joints in use.
    pub fn joints(&self) -> &[JointDescription] {
        &self.joints[..usize::from(self.joint_count).min(MAX_JOINTS)]
    }

    /// The configured sources.
    pub fn sources(&self) -> &[SourceDescription] {
        &self.sources[..usize::from(self.source_count).min(MAX_SOURCES)]
    }

    /// Adds a sensor named `name`.
    pub fn push_sensor(
        &mut self,
        name: &str,
        mut sensor: SensorDescription,
    ) -> Result<(), DescriptionFull> {
        let slot = self
            .sensors
            .get_mut(usize::from(self.sensor_count))
            .ok_or(DescriptionFull::of("sensors", MAX_SENSORS))?;
        write_fixed_str(&mut sensor.name, name);
        *slot = sensor;
        self.sensor_count += 1;
        Ok(())
    }

    /// Adds a joint named `name` whose position is `source` (`index`: the wheel).
    pub fn push_joint(&mut self, name: &str, source: u8, index: u8) -> Result<(), DescriptionFull> {
        let slot = self
            .joints
            .get_mut(usize::from(self.joint_count))
            .ok_or(DescriptionFull::of("joints", MAX_JOINTS))?;
        *slot = JointDescription {
            source,
            index,
            ..JointDescription::default()
        };
        write_fixed_str(&mut slot.name, name);
        self.joint_count += 1;
        Ok(())
    }

    /// Adds a source of the mux.
    pub fn push_source(
        &mut self,
        name: &str,
        priority: u8,
        timeout_ms: u32,
        flags: u8,
    ) -> Result<(), DescriptionFull> {
        let slot = self
            .sources
            .get_mut(usize::from(self.source_count))
            .ok_or(DescriptionFull::of("sources", MAX_SOURCES))?;
        *slot = SourceDescription {
            timeout_ms,
            priority,
            flags,
            ..SourceDescription::default()
        };
        write_fixed_str(&mut slot.name, name);
        self.source_count += 1;
        Ok(())
    }

    /// The tighter of the robot's and the configured limits: what the robot will do at most.
    pub fn effective_limits(&self) -> MotionLimits {
        self.robot_limits.tighter(&self.configured_limits)
    }

    /// The source called `name`.
    pub fn source(&self, name: &str) -> Option<&SourceDescription> {
        self.sources().iter().find(|s| s.name() == name)
    }

    /// True when the description was published (a default one has seq 0 and no kind).
    pub fn is_known(&self) -> bool {
        self.kind != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_fill_up_and_refuse_more() {
        let mut d = RobotDescription::default();
        assert!(!d.is_known());
        for i in 0..MAX_SOURCES {
            d.push_source(&format!("s{i}"), i as u8, 100, 0).unwrap();
        }
        assert_eq!(
            d.push_source("one-too-many", 1, 100, 0),
            Err(DescriptionFull {
                what: "sources",
                max: MAX_SOURCES
            })
        );
        assert_eq!(d.sources().len(), MAX_SOURCES);
        assert_eq!(d.source("s3").map(|s| s.priority), Some(3));
        d.push_joint("front_steer_joint", JointSource::FRONT_STEER, 0)
            .unwrap();
        assert_eq!(d.joints()[0].name(), "front_steer_joint");
        d.push_sensor(
            "ultrasonic_front_left",
            SensorDescription {
                kind: SensorKind::ULTRASONIC,
                ..SensorDescription::default()
            },
        )
        .unwrap();
        assert_eq!(d.sensors()[0].name(), "ultrasonic_front_left");
    }

    #[test]
    fn the_effective_limits_are_the_tighter_of_the_two() {
        let mut d = RobotDescription::default();
        d.robot_limits.forward_mps = 1.5;
        d.robot_limits.angular_radps = 2.0;
        d.configured_limits.forward_mps = 0.5;
        let e = d.effective_limits();
        assert_eq!(e.forward_mps, 0.5);
        assert_eq!(e.angular_radps, 2.0);
        assert!(e.lateral_mps.is_nan());
    }
}
