//! `ChassisState`: one snapshot holding everything any of the three robots reports.
//!
//! A signal the robot has never reported reads as zero *and* has its group bit clear in
//! [`ChassisState::valid_mask`]; a signal that stopped arriving keeps its last value and an old
//! [`ChassisState::group_stamp_ns`] entry. Readers decide staleness against their own clock
//! (`CLOCK_MONOTONIC`), so a zero is never mistaken for a reading.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

/// Signal groups: the index into [`ChassisState::group_stamp_ns`] and the bit in
/// [`ChassisState::valid_mask`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Group {
    /// Linear, angular and lateral speed and the body steering angle.
    Motion = 0,
    /// Front and rear steering angles.
    Steering = 1,
    /// Axle and wheel speeds.
    WheelSpeed = 2,
    /// Odometer distances reported by the chassis (or counted from its encoders).
    Odometry = 3,
    /// The pose integrated by the driver.
    Pose = 4,
    /// Body status, control mode, faults, battery voltage.
    System = 5,
    /// Motor speed, current and encoder position.
    MotorDrive = 6,
    /// Motor driver voltage, temperatures and status bits.
    MotorDriver = 7,
    /// BMS group 0: the pack as a whole.
    BmsPack = 8,
    /// BMS group 1: battery 1.
    Bms1 = 9,
    /// BMS group 2: battery 2.
    Bms2 = 10,
    /// RC transmitter.
    Rc = 11,
    /// Light state.
    Lights = 12,
    /// Parking brake and off-road mode (as commanded; TITAN reports neither).
    Body = 13,
    /// IR and ultrasonic ranges.
    Ranges = 14,
    /// Inertial measurement unit.
    Imu = 15,
    /// Lift platform.
    Lift = 16,
    /// Pan and tilt servos (as commanded; the XBot reports neither).
    PanTilt = 17,
    /// GPS fix from the NMEA stream.
    Gps = 18,
    /// The motion command actually sent on the wire.
    Command = 19,
}

impl Group {
    /// Number of groups in use; [`ChassisState::group_stamp_ns`] has room for [`GROUP_SLOTS`].
    pub const COUNT: usize = 20;
    /// Every group, in index order.
    pub const ALL: [Group; Self::COUNT] = [
        Group::Motion,
        Group::Steering,
        Group::WheelSpeed,
        Group::Odometry,
        Group::Pose,
        Group::System,
        Group::MotorDrive,
        Group::MotorDriver,
        Group::BmsPack,
        Group::Bms1,
        Group::Bms2,
        Group::Rc,
        Group::Lights,
        Group::Body,
        Group::Ranges,
        Group::Imu,
        Group::Lift,
        Group::PanTilt,
        Group::Gps,
        Group::Command,
    ];

    /// The bit of this group in [`ChassisState::valid_mask`].
    pub const fn bit(self) -> u32 {
        1 << self as u32
    }

    /// Index into [`ChassisState::group_stamp_ns`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Lower-case name used in logs and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Group::Motion => "motion",
            Group::Steering => "steering",
            Group::WheelSpeed => "wheel_speed",
            Group::Odometry => "odometry",
            Group::Pose => "pose",
            Group::System => "system",
            Group::MotorDrive => "motor_drive",
            Group::MotorDriver => "motor_driver",
            Group::BmsPack => "bms_pack",
            Group::Bms1 => "bms_1",
            Group::Bms2 => "bms_2",
            Group::Rc => "rc",
            Group::Lights => "lights",
            Group::Body => "body",
            Group::Ranges => "ranges",
            Group::Imu => "imu",
            Group::Lift => "lift",
            Group::PanTilt => "pan_tilt",
            Group::Gps => "gps",
            Group::Command => "command",
        }
    }
}

/// Slots reserved for group stamps (room to add groups without a layout change).
pub const GROUP_SLOTS: usize = 24;
const _: () = assert!(Group::COUNT <= GROUP_SLOTS);

named_constants! {
    /// Link and authority flags (`ChassisState::link_flags`).
    pub flags LinkFlags: u32 {
        /// No feedback frame from the chassis for longer than the configured silence limit.
        CHASSIS_SILENT = 1 << 0 => "chassis_silent",
        /// The bus itself is gone (interface down, serial port unplugged); the service retries.
        BUS_DOWN = 1 << 1 => "bus_down",
        /// The chassis reports it obeys our motion commands.
        COMMAND_MODE = 1 << 2 => "command_mode",
        /// An RC transmitter holds authority; our commands are not obeyed (reported, not fought).
        RC_AUTHORITY = 1 << 3 => "rc_authority",
        /// A steering-zero calibration was sent and its acknowledgement has not arrived yet.
        STEERING_ZERO_PENDING = 1 << 4 => "steering_zero_pending",
        /// The GPS receiver's stream is gone.
        GPS_DOWN = 1 << 5 => "gps_down",
        /// The chassis was told to stop transmitting (CAN-upgrade silent mode).
        SILENT_MODE = 1 << 6 => "silent_mode",
        /// The CAN controller is error-passive: an error counter passed 127 (SocketCAN error
        /// frames; `LinkStats::can_state`). It still sends and receives, but the bus is unhealthy.
        CAN_ERROR_PASSIVE = 1 << 7 => "can_error_passive",
        /// The CAN controller is bus-off: it takes no part in the bus until it is restarted
        /// (`restart-ms`, or the interface taken down and up); nothing reaches the chassis.
        CAN_BUS_OFF = 1 << 8 => "can_bus_off",
        /// Set by a mirror on another computer (`chassis-zenoh --mirror`), never by chassisd:
        /// nothing has arrived from the robot over the network for longer than the mirror's loss
        /// limit (or its liveliness token is gone). The sample is the last one received, published
        /// again; the robot's own remote sources time out on the robot.
        REMOTE_LOST = 1 << 9 => "remote_lost",
    }
}

named_constants! {
    /// The CAN controller's error state (`LinkStats::can_state`), as ISO 11898-1 defines it from
    /// the controller's transmit and receive error counters and SocketCAN reports it.
    pub enum ControllerState: u8 {
        /// Not known: not a CAN bus, or the controller reported nothing (a vcan has no controller).
        UNKNOWN = 0 => "unknown",
        /// Both error counters below 96: all is well.
        ERROR_ACTIVE = 1 => "error-active",
        /// An error counter reached 96.
        ERROR_WARNING = 2 => "error-warning",
        /// An error counter passed 127: the controller no longer signals the errors it sees.
        ERROR_PASSIVE = 3 => "error-passive",
        /// The transmit error counter passed 255: the controller is off the bus.
        BUS_OFF = 4 => "bus-off",
    }
}

named_constants! {
    /// Normalized control mode (`SystemState::control_mode`), the same for every robot.
    pub enum ControlMode: u8 {
        UNKNOWN = 0 => "unknown",
        /// Powered up, reacting only to the mode frame (TITAN).
        STANDBY = 1 => "standby",
        /// Obeying commands from this computer (CAN or serial command mode).
        COMMAND = 2 => "command",
        /// An RC transmitter is in control.
        REMOTE = 3 => "remote",
        /// Serial command mode (commands on another port; CAN commands ignored): SCOUT MINI V1,
        /// and protocol V2's "UART" / "APP" mode (0x211 b1 = 0x02 where the profile's mode codes
        /// say so).
        SERIAL = 4 => "serial",
    }
}

named_constants! {
    /// Which AgileX wire protocol the driver speaks (`SystemState::wire_protocol`).
    pub enum WireProtocol: u8 {
        /// The robot has one protocol of its own (TITAN, XBot).
        OWN = 0 => "own",
        /// AgileX V1 (count and checksum in every frame).
        V1 = 1 => "v1",
        /// AgileX V2 (the TITAN's layout family).
        V2 = 2 => "v2",
        /// Listening to find out (SCOUT MINI on a real bus): nothing is sent yet.
        DETECTING = 3 => "detecting",
    }
}

named_constants! {
    /// Normalized fault flags (`SystemState::fault_flags`); the vendor's own word is kept beside
    /// it in `SystemState::vendor_fault_word`.
    pub flags FaultFlags: u64 {
        /// The chassis lost our heartbeat (TITAN "upper-computer communication lost").
        HEARTBEAT_LOST = 1 << 0 => "heartbeat_lost",
        /// Battery under-voltage failure: drive power cut.
        BATTERY_UNDER_VOLTAGE = 1 << 1 => "battery_under_voltage",
        /// Battery under-voltage alarm (warning level).
        BATTERY_UNDER_VOLTAGE_WARNING = 1 << 2 => "battery_under_voltage_warning",
        /// Battery over-voltage failure.
        BATTERY_OVER_VOLTAGE = 1 << 3 => "battery_over_voltage",
        /// A motor driver reports an error.
        MOTOR_DRIVER_ERROR = 1 << 4 => "motor_driver_error",
        /// Motor 1 driver communication lost (motor 2-4: the next three bits).
        MOTOR_1_COMM_LOST = 1 << 5 => "motor_1_comm_lost",
        MOTOR_2_COMM_LOST = 1 << 6 => "motor_2_comm_lost",
        MOTOR_3_COMM_LOST = 1 << 7 => "motor_3_comm_lost",
        MOTOR_4_COMM_LOST = 1 << 8 => "motor_4_comm_lost",
        /// Over-temperature protection (drive limited until cleared).
        OVER_TEMPERATURE = 1 << 9 => "over_temperature",
        /// Over-temperature alarm (clears itself).
        OVER_TEMPERATURE_WARNING = 1 << 10 => "over_temperature_warning",
        /// Over-current protection (until cleared).
        OVER_CURRENT = 1 << 11 => "over_current",
        /// Over-current alarm (clears itself).
        OVER_CURRENT_WARNING = 1 << 12 => "over_current_warning",
        FRONT_STEERING_ENCODER = 1 << 13 => "front_steering_encoder",
        REAR_STEERING_ENCODER = 1 << 14 => "rear_steering_encoder",
        /// The bumper (touch edge) stopped the robot.
        BUMPER = 1 << 15 => "bumper",
        /// The RC transmitter link is lost / the transmitter is off.
        RC_LINK_LOST = 1 << 16 => "rc_link_lost",
        /// The chassis received a command frame with a wrong checksum (SCOUT MINI).
        COMMAND_CHECKSUM = 1 << 17 => "command_checksum",
        /// The chassis reports an emergency stop.
        EMERGENCY_STOP = 1 << 18 => "emergency_stop",
        /// The chassis reports an exception body state.
        BODY_EXCEPTION = 1 << 19 => "body_exception",
        /// State of charge below the low-battery warning level.
        BATTERY_LOW = 1 << 20 => "battery_low",
        /// Any BMS alarm bit is set.
        BMS_ALARM = 1 << 21 => "bms_alarm",
    }
}

impl FaultFlags {
    /// The faults after which a chassis does not drive: its E-stop aside, those that stop the
    /// drive (a motor driver in error or unreachable, over-current, over-temperature, a body
    /// exception, the battery cut). While one is reported the service commands zero, and when
    /// it clears motion starts again only from a zero.
    pub const STOPS_DRIVE: u64 = Self::MOTOR_DRIVER_ERROR
        | Self::MOTOR_1_COMM_LOST
        | Self::MOTOR_2_COMM_LOST
        | Self::MOTOR_3_COMM_LOST
        | Self::MOTOR_4_COMM_LOST
        | Self::OVER_CURRENT
        | Self::OVER_TEMPERATURE
        | Self::BODY_EXCEPTION
        | Self::BATTERY_UNDER_VOLTAGE;
}

impl FaultFlags {
    /// Flags that only warn: the chassis still drives.
    pub const WARNINGS: u64 = Self::BATTERY_UNDER_VOLTAGE_WARNING
        | Self::OVER_TEMPERATURE_WARNING
        | Self::OVER_CURRENT_WARNING
        | Self::BATTERY_LOW
        | Self::RC_LINK_LOST
        | Self::BMS_ALARM
        | Self::COMMAND_CHECKSUM;
}

named_constants! {
    /// Motor driver status bits (`MotorState::driver_status`), as TITAN's 0x261-0x264 byte 5.
    pub flags DriverStatus: u8 {
        SUPPLY_UNDER_VOLTAGE = 1 << 0 => "supply_under_voltage",
        MOTOR_OVER_TEMPERATURE = 1 << 1 => "motor_over_temperature",
        DRIVER_OVER_CURRENT = 1 << 2 => "driver_over_current",
        DRIVER_OVER_TEMPERATURE = 1 << 3 => "driver_over_temperature",
        SENSOR_FAULT = 1 << 4 => "sensor_fault",
        DRIVER_ERROR = 1 << 5 => "driver_error",
        ENABLED = 1 << 6 => "enabled",
    }
}

ipc_type! {
    /// Speeds and steering.
    #[derive(Default, Serialize)]
    #[type_name("chassis::MotionState.v1")]
    pub struct MotionState {
        /// Forward speed of the body, m/s.
        pub linear_mps: f32,
        /// Yaw rate, rad/s, left turn positive.
        pub angular_radps: f32,
        /// Lateral speed, m/s, left positive (omni robots).
        pub lateral_mps: f32,
        /// Body steering angle (TITAN: inner wheel angle), rad, left turn positive.
        pub steer_rad: f32,
        /// Front axle inner steering angle, rad, left turn positive.
        pub front_steer_rad: f32,
        /// Rear axle inner steering angle, rad (rear steers opposite the front on TITAN).
        pub rear_steer_rad: f32,
        /// Front axle speed (mean of its wheels), m/s.
        pub front_axle_mps: f32,
        /// Rear axle speed (mean of its wheels), m/s.
        pub rear_axle_mps: f32,
        /// Wheel speeds front-left, front-right, rear-left, rear-right, m/s.
        pub wheel_mps: [f32; 4],
    }
}

ipc_type! {
    /// Distances and the integrated pose.
    #[derive(Default, Serialize)]
    #[type_name("chassis::OdometryState.v1")]
    pub struct OdometryState {
        /// Front axle odometer, m (TITAN 0x311).
        pub front_distance_m: f64,
        /// Rear axle odometer, m.
        pub rear_distance_m: f64,
        /// Left side distance, m (from wheel encoders where the robot has them).
        pub left_distance_m: f64,
        /// Right side distance, m.
        pub right_distance_m: f64,
        /// Pose integrated from the reported speeds, in the frame the robot started in: x, m.
        pub x_m: f64,
        /// y, m.
        pub y_m: f64,
        /// Heading, rad, wrapped to (-π, π].
        pub yaw_rad: f64,
    }
}

/// Wraps an angle to (-π, π] (the range of [`OdometryState::yaw_rad`]); a non-finite angle
/// reads as 0.
pub fn wrap_angle(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if !angle.is_finite() {
        return 0.0;
    }
    let mut a = angle % TAU;
    if a <= -PI {
        a += TAU;
    } else if a > PI {
        a -= TAU;
    }
    a
}

ipc_type! {
    /// Body status, mode, faults and battery.
    #[derive(Default, Serialize)]
    #[type_name("chassis::SystemState.v1")]
    pub struct SystemState {
        /// Normalized [`FaultFlags`].
        pub fault_flags: u64,
        /// The vendor's raw fault word (TITAN 0x211 b4-7, SCOUT MINI 0x151 b4-5).
        pub vendor_fault_word: u32,
        /// Battery voltage, V.
        pub battery_voltage_v: f32,
        /// Battery state of charge, %, from the BMS where there is one.
        pub battery_soc_pct: f32,
        /// Battery current, A, from the BMS where there is one (positive = discharge).
        pub battery_current_a: f32,
        /// [`SystemState::BODY_NORMAL`], [`SystemState::BODY_EMERGENCY_STOP`] or
        /// [`SystemState::BODY_EXCEPTION`].
        pub body_status: u8,
        /// [`ControlMode`].
        pub control_mode: u8,
        /// 1 when the parking brake is engaged (TITAN, as last commanded).
        pub parking_brake_engaged: u8,
        /// 1 when off-road mode is on (TITAN, as last commanded and accepted).
        pub off_road: u8,
        /// 1 when the chassis was told to enter CAN-upgrade silent mode.
        pub silent_mode: u8,
        /// 1 when the steering zero position was set and acknowledged since start.
        pub steering_zero_done: u8,
        /// 1 when drive power is enabled (XBot power command; others: always 1 once reported).
        pub power_enabled: u8,
        /// [`WireProtocol`] the driver speaks (was a reserved byte: readers that ignore it see 0).
        pub wire_protocol: u8,
    }
}

impl SystemState {
    pub const BODY_NORMAL: u8 = 0;
    pub const BODY_EMERGENCY_STOP: u8 = 1;
    pub const BODY_EXCEPTION: u8 = 2;
}

ipc_type! {
    /// One drive motor and its driver.
    #[derive(Default, Serialize)]
    #[type_name("chassis::MotorState.v1")]
    pub struct MotorState {
        /// Encoder position, counts (unwrapped where the wire value wraps).
        pub position_counts: i64,
        /// Shaft speed, rpm.
        pub rpm: f32,
        /// Motor current, A.
        pub current_a: f32,
        /// Driver supply voltage, V.
        pub driver_voltage_v: f32,
        /// Driver temperature, °C.
        pub driver_temp_c: f32,
        /// Motor temperature, °C.
        pub motor_temp_c: f32,
        /// [`DriverStatus`] bits.
        pub driver_status: u8,
        #[serde(skip)]
        pub _reserved: [u8; 3],
    }
}

ipc_type! {
    /// One BMS group (0 = pack, 1 = battery 1, 2 = battery 2).
    #[derive(Default, Serialize)]
    #[type_name("chassis::BmsState.v1")]
    pub struct BmsState {
        pub soc_pct: f32,
        pub soh_pct: f32,
        pub voltage_v: f32,
        /// Current, A (positive = discharge).
        pub current_a: f32,
        pub temperature_c: f32,
        /// Raw alarm bytes: alarm 1 (bits 0-7), alarm 2 (8-15), warning 1 (16-23), warning 2
        /// (24-31).
        pub alarm_flags: u32,
    }
}

ipc_type! {
    /// RC transmitter.
    #[derive(Default, Serialize)]
    #[type_name("chassis::RcState.v1")]
    pub struct RcState {
        /// Switch positions as the wire has them: 1 middle, 2 up, 3 down.
        pub switch_a: u8,
        pub switch_b: u8,
        pub switch_c: u8,
        pub switch_d: u8,
        /// Stick positions, % of full deflection, [-100, 100].
        pub right_x_pct: i8,
        pub right_y_pct: i8,
        pub left_y_pct: i8,
        pub left_x_pct: i8,
        /// Knob VRA, %.
        pub knob_a_pct: i8,
        /// Rolling counter of the RC frame.
        pub counter: u8,
        #[serde(skip)]
        pub _reserved: [u8; 2],
    }
}

ipc_type! {
    /// Lights.
    #[derive(Default, Serialize)]
    #[type_name("chassis::LightsState.v1")]
    pub struct LightsState {
        /// 1 when light control by command is enabled.
        pub control_enabled: u8,
        /// [`crate::LightMode`] of the front light.
        pub front_mode: u8,
        /// Custom brightness, % (valid in custom mode).
        pub front_brightness_pct: u8,
        #[serde(skip)]
        pub _reserved: u8,
    }
}

ipc_type! {
    /// Range sensors (XBot).
    #[derive(Default, Serialize)]
    #[type_name("chassis::RangesState.v1")]
    pub struct RangesState {
        /// IR cliff/range sensors rear-left, rear-centre, rear-right, m.
        pub ir_m: [f32; 3],
        /// Ultrasonic rangers front-left, front-centre, front-right, m.
        pub ultrasonic_m: [f32; 3],
    }
}

ipc_type! {
    /// Inertial measurement unit, in the sensor's axes.
    #[derive(Default, Serialize)]
    #[type_name("chassis::ImuState.v1")]
    pub struct ImuState {
        pub accel_mps2: [f32; 3],
        pub gyro_radps: [f32; 3],
        pub mag_gauss: [f32; 3],
        pub roll_rad: f32,
        pub pitch_rad: f32,
        pub yaw_rad: f32,
        pub temperature_c: f32,
        /// The sensor board's own timestamp, µs (wraps at 65536 on the XBot).
        pub sensor_stamp_us: u32,
    }
}

ipc_type! {
    /// Lift platform (XBot).
    #[derive(Default, Serialize)]
    #[type_name("chassis::LiftState.v1")]
    pub struct LiftState {
        /// Lift encoder, counts (unwrapped).
        pub encoder_counts: i64,
        /// Commanded position, % of travel (0 bottom, 100 top).
        pub target_pct: f32,
        /// Lift motor current, A.
        pub current_a: f32,
        /// 1 when the lift is enabled (as commanded).
        pub enabled: u8,
        #[serde(skip)]
        pub _reserved: [u8; 7],
    }
}

ipc_type! {
    /// Pan and tilt servos (XBot), as commanded.
    #[derive(Default, Serialize)]
    #[type_name("chassis::PanTiltState.v1")]
    pub struct PanTiltState {
        /// Pan, rad: 0 ahead, left positive.
        pub pan_rad: f32,
        /// Tilt, rad: 0 ahead, up positive.
        pub tilt_rad: f32,
    }
}

ipc_type! {
    /// GPS fix from the NMEA 0183 stream.
    #[derive(Default, Serialize)]
    #[type_name("chassis::GpsFix.v1")]
    pub struct GpsFix {
        /// Latitude, degrees, north positive (0 when there is no fix: check `fix_quality`).
        pub latitude_deg: f64,
        /// Longitude, degrees, east positive.
        pub longitude_deg: f64,
        /// UTC time of day of the fix, s.
        pub utc_time_s: f64,
        /// Altitude above mean sea level, m.
        pub altitude_m: f32,
        /// Horizontal dilution of precision.
        pub hdop: f32,
        /// Speed over ground, m/s.
        pub speed_mps: f32,
        /// Course over ground, rad, clockwise from true north (as NMEA gives it).
        pub course_rad: f32,
        /// UTC date as `yyyymmdd`, 0 when unknown.
        pub utc_date: u32,
        /// GGA fix quality: 0 = no fix, 1 = GPS, 2 = DGPS, 4 = RTK fixed, 5 = RTK float, …
        pub fix_quality: u8,
        /// Satellites used in the fix.
        pub satellites: u8,
        /// GSA fix type: 1 = none, 2 = 2D, 3 = 3D, 0 = unknown.
        pub fix_type: u8,
        #[serde(skip)]
        pub _reserved: u8,
    }
}

impl GpsFix {
    /// True when the receiver reports a usable position.
    pub fn has_fix(&self) -> bool {
        self.fix_quality != 0
    }
}

ipc_type! {
    /// The motion command the driver actually put on the wire, after quantisation and clamping.
    #[derive(Default, Serialize)]
    #[type_name("chassis::CommandEcho.v1")]
    pub struct CommandEcho {
        pub linear_mps: f32,
        pub lateral_mps: f32,
        pub angular_radps: f32,
        pub steer_rad: f32,
        /// [`crate::ClampFlags`] applied by the driver (robot limits, unachievable requests).
        pub clamp_flags: u32,
        #[serde(skip)]
        pub _reserved: u32,
    }
}

ipc_type! {
    /// Counters of the bus link.
    #[derive(Default, Serialize)]
    #[type_name("chassis::LinkStats.v4")]
    pub struct LinkStats {
        /// Frames received and decoded.
        pub rx_frames: u64,
        /// Frames sent.
        pub tx_frames: u64,
        /// Received frames dropped for a bad checksum.
        pub rx_bad_checksum: u64,
        /// Received frames dropped because they could not be decoded (length, values).
        pub rx_decode_errors: u64,
        /// Received frames with an id this robot does not use (ignored).
        pub rx_unknown_id: u64,
        /// Serial bytes discarded while resynchronising.
        pub rx_bytes_discarded: u64,
        /// Frames that could not be written to the bus.
        pub tx_errors: u64,
        /// Times the bus was lost and reopened.
        pub bus_reconnects: u64,
        /// Samples, answers and reader wake-ups chassisd could not publish over iceoryx2.
        pub ipc_failures: u64,
        /// SocketCAN error frames read: the CAN controller's reports on itself and the bus.
        pub can_error_frames: u64,
        /// Times the CAN controller became error-passive.
        pub can_error_passive: u64,
        /// Times the CAN controller went bus-off.
        pub can_bus_off: u64,
        /// Times the CAN controller was restarted after a bus-off (the kernel's `restart-ms`, or
        /// `ip link set IFACE type can restart`).
        pub can_restarts: u64,
        /// Protocol violations the CAN controller reported (bit, stuff, form, CRC errors): noise,
        /// a wrong bit rate, missing termination or CAN H and L swapped.
        pub can_bus_errors: u64,
        /// Reports of a frame sent that no other node acknowledged: the controller is alone on the
        /// bus, or hears it at another bit rate.
        pub can_no_ack: u64,
        /// Passes whose inputs the black box did not record: its writer fell behind (a slow or
        /// full disk). The passes themselves ran.
        pub recorder_dropped: u64,
        /// [`ControllerState`] of the CAN controller now.
        pub can_state: u8,
        /// The controller's transmit and receive error counters, as its last report carrying them.
        pub can_tx_error_count: u8,
        pub can_rx_error_count: u8,
        #[serde(skip)]
        pub _reserved: [u8; 5],
    }
}

ipc_type! {
    /// One snapshot of everything the chassis reports.
    #[derive(Default, Serialize)]
    #[type_name("chassis::ChassisState.v4")]
    pub struct ChassisState {
        /// Incremented for every published sample.
        pub seq: u64,
        /// `CLOCK_MONOTONIC` receive time of the frame that produced this sample, ns.
        pub stamp_ns: u64,
        /// [`Group`] bits that have been reported at least once.
        pub valid_mask: u32,
        /// [`LinkFlags`].
        pub link_flags: u32,
        /// The robot's kind: `chassis_protocols::RobotKind` as a number (its registry's key;
        /// 0: none), as in `RobotDescription::kind`. What the kind *is* — its names, limits,
        /// geometry — comes from the description chassisd publishes (`chassis/<name>/robot`),
        /// never from a table of a client's.
        pub robot: u8,
        #[serde(skip)]
        pub _reserved: [u8; 7],
        /// Last update of each [`Group`], `CLOCK_MONOTONIC` ns, 0 = never.
        pub group_stamp_ns: [u64; GROUP_SLOTS],
        pub motion: MotionState,
        pub odometry: OdometryState,
        pub system: SystemState,
        /// Motors 1-4 (TITAN, SCOUT MINI: as numbered by the vendor; XBot: front-left, front-right,
        /// rear-left, rear-right).
        pub motors: [MotorState; 4],
        /// BMS groups: 0 = pack, 1 = battery 1, 2 = battery 2.
        pub bms: [BmsState; 3],
        pub rc: RcState,
        pub lights: LightsState,
        pub ranges: RangesState,
        pub imu: ImuState,
        pub lift: LiftState,
        pub pan_tilt: PanTiltState,
        pub gps: GpsFix,
        pub command: CommandEcho,
        pub link: LinkStats,
        /// `CLOCK_MONOTONIC` time `chassisd` handed this sample to iceoryx2, ns: with
        /// `stamp_ns`, the service's own part of the state path.
        pub published_ns: u64,
    }
}

impl ChassisState {
    /// The part of the sample that changes only when the chassis reports something new: without
    /// its numbering, its stamps and the link's counters.
    pub fn body(&self) -> ChassisState {
        ChassisState {
            seq: 0,
            stamp_ns: 0,
            group_stamp_ns: [0; GROUP_SLOTS],
            link: LinkStats::default(),
            ..*self
        }
    }

    /// Marks `group` as updated at `now_ns`.
    pub fn touch(&mut self, group: Group, now_ns: u64) {
        self.valid_mask |= group.bit();
        self.group_stamp_ns[group.index()] = now_ns;
    }

    /// True when `group` has been reported at least once.
    pub fn is_valid(&self, group: Group) -> bool {
        self.valid_mask & group.bit() != 0
    }

    /// Age of `group` at `now_ns`, ns; `None` when it was never reported.
    pub fn age_ns(&self, group: Group, now_ns: u64) -> Option<u64> {
        self.is_valid(group)
            .then(|| now_ns.saturating_sub(self.group_stamp_ns[group.index()]))
    }

    /// True when the link flag `flag` ([`LinkFlags`]) is set.
    pub fn has_link_flag(&self, flag: u32) -> bool {
        self.link_flags & flag != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_body_leaves_out_the_numbering_the_stamps_and_the_link_counters() {
        let mut a = ChassisState::default();
        a.touch(Group::System, 5);
        a.system.battery_voltage_v = 24.0;
        let mut b = a;
        (b.seq, b.stamp_ns, b.link.rx_frames) = (9, 7, 3);
        b.touch(Group::System, 6);
        assert_eq!(a.body(), b.body());
        b.system.battery_voltage_v = 23.9;
        assert_ne!(a.body(), b.body());
    }

    #[test]
    fn group_bits_and_stamps_tell_never_reported_from_zero() {
        let mut state = ChassisState::default();
        assert!(!state.is_valid(Group::Imu));
        assert_eq!(state.age_ns(Group::Imu, 1_000), None);
        state.touch(Group::Imu, 400);
        assert!(state.is_valid(Group::Imu));
        assert_eq!(state.age_ns(Group::Imu, 1_000), Some(600));
        assert!(!state.is_valid(Group::Gps));
    }

    #[test]
    fn group_list_matches_indices() {
        for (i, group) in Group::ALL.iter().enumerate() {
            assert_eq!(group.index(), i);
        }
    }

    #[test]
    fn fault_flags_have_unique_bits_and_names() {
        let mut seen = 0u64;
        for (bit, name) in FaultFlags::ALL {
            assert_eq!(bit.count_ones(), 1, "{name}");
            assert_eq!(seen & bit, 0, "{name} reuses a bit");
            seen |= bit;
            assert_eq!(FaultFlags::from_name(name), Some(bit));
        }
        assert_eq!(
            FaultFlags::names(FaultFlags::BUMPER | FaultFlags::HEARTBEAT_LOST),
            vec!["heartbeat_lost", "bumper"]
        );
    }

    #[test]
    fn state_serializes_with_unit_names_and_without_padding() {
        let json = serde_json::to_value(ChassisState::default()).unwrap();
        assert!(json["motion"]["linear_mps"].is_number());
        assert!(json["system"]["battery_voltage_v"].is_number());
        assert!(json.get("_reserved").is_none());
    }

    #[test]
    fn angles_wrap_into_the_half_open_interval() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
        assert_eq!(wrap_angle(f64::NAN), 0.0);
    }
}
