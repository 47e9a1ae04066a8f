//! TITAN wire codec: every frame of the manual, both directions.
//!
//! CAN 2.0B, 500 kbit/s, standard 11-bit ids, Motorola (big-endian) byte order, no checksum.
//! Frame structs hold SI values in ISO 8855 axes (left turn positive); the codec is the only place
//! that knows the vendor's units and signs. Where the manual contradicts itself the
//! [`TitanProfile`] decides (⚠ steering feedback sign).

use chassis_interfaces::RcState;
use serde::{Deserialize, Serialize};
use zerocopy::byteorder::big_endian::{I16, I32, U16, U32};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use crate::Direction;
use crate::can::CanFrame;
use crate::error::{
    DecodeError, EncodeError, check_range, check_u8, to_i8, to_i16, to_i32, to_u8, to_u16,
};
use crate::titan::TitanProfile;
use crate::wire_layout::{first_byte, index_in, invalid, read_bool, read_prefix, si, wire_bytes};

/// Frame identifiers.
pub mod id {
    /// → motion command: speed and inner steering angle (heartbeat, 20 ms, timeout 500 ms).
    pub const MOTION_COMMAND: u16 = 0x111;
    /// → parking brake.
    pub const PARKING_BRAKE: u16 = 0x131;
    /// → control mode (standby / CAN command).
    pub const MODE: u16 = 0x421;
    /// → CAN-upgrade silent mode.
    pub const SILENT_MODE: u16 = 0x422;
    /// → off-road mode.
    pub const OFF_ROAD: u16 = 0x423;
    /// → set the current steering position as zero.
    pub const STEERING_ZERO: u16 = 0x431;
    /// ← steering zero acknowledged.
    pub const STEERING_ZERO_ACK: u16 = 0x43A;
    /// → clear faults.
    pub const CLEAR_FAULT: u16 = 0x441;
    /// ← body state, mode, battery voltage, fault bits (20 ms).
    pub const SYSTEM_STATUS: u16 = 0x211;
    /// ← speed and steering angle (20 ms).
    pub const MOTION_FEEDBACK: u16 = 0x221;
    /// ← RC transmitter (20 ms).
    pub const RC: u16 = 0x241;
    /// ← motor 1 fast feedback; motors 2-4 follow (0x251-0x254, 20 ms).
    pub const MOTOR_FAST_1: u16 = 0x251;
    /// ← motor 1 slow feedback; motors 2-4 follow (0x261-0x264, 100 ms).
    pub const MOTOR_SLOW_1: u16 = 0x261;
    /// ← front and rear inner steering angles (20 ms).
    pub const STEERING_FEEDBACK: u16 = 0x271;
    /// ← front and rear axle speeds (20 ms).
    pub const AXLE_SPEED: u16 = 0x281;
    /// ← front and rear odometers (20 ms).
    pub const ODOMETER: u16 = 0x311;
    /// ← BMS data of group 0 (pack); groups 1, 2 at 0x363, 0x365 (500 ms).
    pub const BMS_DATA_0: u16 = 0x361;
    /// ← BMS alarms of group 0; groups 1, 2 at 0x364, 0x366 (500 ms).
    pub const BMS_ALARM_0: u16 = 0x362;
}

/// `ModeCommand::mode` and `SystemStatus::mode` values.
pub mod mode {
    pub const STANDBY: u8 = 0x00;
    pub const CAN_COMMAND: u8 = 0x01;
    /// Only reported: an RC transmitter controls the chassis.
    pub const REMOTE: u8 = 0x03;
}

/// `ClearFault::code` values (0x441 b0).
pub mod clear_code {
    /// Every non-severe fault.
    pub const ALL_NON_SEVERE: u8 = 0x00;
    /// Motor driver 1 communication; 2-4 are 0x02-0x04.
    pub const MOTOR_1_COMM: u8 = 0x01;
    pub const MOTOR_4_COMM: u8 = 0x04;
    /// Battery under-voltage (and try to restore power).
    pub const BATTERY_UNDER_VOLTAGE: u8 = 0x09;
    pub const RC_LINK_LOST: u8 = 0x0A;
    pub const FRONT_STEERING_ENCODER: u8 = 0x0B;
    pub const REAR_STEERING_ENCODER: u8 = 0x0C;
    pub const OVER_CURRENT: u8 = 0x0F;
    pub const OVER_TEMPERATURE: u8 = 0x10;

    /// True for a code the manual defines.
    pub fn is_defined(code: u8) -> bool {
        matches!(code, 0x00..=0x04 | 0x09..=0x0C | 0x0F | 0x10)
    }
}

/// Bits of `SystemStatus::fault_word` (`u32be` of 0x211 b4-7: b4 is bits 24-31, b7 bits 0-7).
pub mod fault {
    pub const FRONT_STEERING_ENCODER: u32 = 1 << 16;
    pub const REAR_STEERING_ENCODER: u32 = 1 << 17;
    pub const BUMPER: u32 = 1 << 21;
    pub const MOTOR_DRIVER_ERROR: u32 = 1 << 8;
    pub const HEARTBEAT_LOST: u32 = 1 << 9;
    pub const OVER_TEMPERATURE: u32 = 1 << 14;
    pub const OVER_CURRENT: u32 = 1 << 15;
    pub const BATTERY_UNDER_VOLTAGE: u32 = 1 << 0;
    pub const RC_LINK_LOST: u32 = 1 << 2;
    /// Motor driver 1 communication lost; drivers 2-4 are the next three bits.
    pub const MOTOR_1_COMM_LOST: u32 = 1 << 3;
    pub const MOTOR_2_COMM_LOST: u32 = 1 << 4;
    pub const MOTOR_3_COMM_LOST: u32 = 1 << 5;
    pub const MOTOR_4_COMM_LOST: u32 = 1 << 6;
}

/// `SystemStatus::body_status` values.
pub mod body {
    pub const NORMAL: u8 = 0x00;
    pub const EXCEPTION: u8 = 0x02;
}

/// Value of 0x431 b0.
pub const STEERING_ZERO_MAGIC: u8 = 0xAA;
/// Value of 0x43A b0.
pub const STEERING_ZERO_ACK_MAGIC: u8 = 0xEE;

// ---------------------------------------------------------------------------------------------
// Wire layouts (big-endian).

/// 0x111 and 0x221.
#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotionWire {
    linear_mm_s: I16,
    reserved: [u8; 4],
    steer_mrad: I16,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct SystemStatusWire {
    body_status: u8,
    mode: u8,
    battery_dv: U16,
    fault_word: U32,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotorFastWire {
    rpm: I16,
    current_da: I16,
    position_counts: I32,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotorSlowWire {
    driver_voltage_dv: U16,
    driver_temp_c: I16,
    motor_temp_c: i8,
    driver_status: u8,
    reserved: [u8; 2],
}

/// 0x271 (front, rear steering, 0.001 rad) and 0x281 (front, rear axle speed, mm/s).
#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct FrontRearWire {
    milli: [I16; 2],
    reserved: [u8; 4],
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct OdometerWire {
    front_mm: I32,
    rear_mm: I32,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct RcWire {
    switches: u8,
    b1: i8,
    b2: i8,
    left_y: i8,
    left_x: i8,
    knob_a: i8,
    reserved: u8,
    counter: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct BmsDataWire {
    soc_pct: u8,
    soh_pct: u8,
    voltage: U16,
    current_da: I16,
    temperature_dc: I16,
}

// ---------------------------------------------------------------------------------------------
// Frames.

/// 0x111: speed and inner steering angle. Also the heartbeat.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MotionCommand {
    /// m/s (wire: mm/s, valid ±3000).
    pub linear_mps: f64,
    /// Inner wheel angle, rad, left turn positive (wire: 0.001 rad, valid ±367).
    pub steer_rad: f64,
}

/// 0x421: control mode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ModeCommand {
    /// [`mode::STANDBY`] or [`mode::CAN_COMMAND`].
    pub mode: u8,
}

/// 0x441: clear faults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClearFault {
    /// A [`clear_code`] value.
    pub code: u8,
}

/// 0x131: parking brake.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ParkingBrake {
    /// true = engage (lock), false = release.
    pub engage: bool,
}

/// 0x422 (silent mode) and 0x423 (off-road mode): enter or leave.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Switch {
    pub enter: bool,
}

/// 0x211: body state, mode, battery voltage and fault bits.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SystemStatus {
    /// [`body`] value as sent (0x00 normal, 0x02 exception).
    pub body_status: u8,
    /// [`mode`] value as sent (0x00 standby, 0x01 CAN command, 0x03 remote control).
    pub mode: u8,
    /// V (wire: 0.1 V).
    pub battery_voltage_v: f64,
    /// [`fault`] bits.
    pub vendor_fault_word: u32,
}

/// 0x221: speed (mean of the four wheels) and steering angle.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotionFeedback {
    pub linear_mps: f64,
    /// rad, left turn positive (after the profile's ⚠ sign choice).
    pub steer_rad: f64,
}

/// 0x251-0x254: motor speed, current and encoder position.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotorFast {
    /// 1-4.
    pub motor: u8,
    pub rpm: f64,
    /// A (wire: 0.1 A).
    pub current_a: f64,
    pub position_counts: i32,
}

/// 0x261-0x264: motor driver voltage, temperatures, status.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotorSlow {
    /// 1-4.
    pub motor: u8,
    /// V (wire: 0.1 V).
    pub driver_voltage_v: f64,
    pub driver_temp_c: f64,
    pub motor_temp_c: f64,
    /// `chassis_interfaces::DriverStatus` bits.
    pub driver_status: u8,
}

/// 0x271: front and rear inner steering angles.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SteeringFeedback {
    /// rad, left turn positive (after the profile's ⚠ sign choice).
    pub front_steer_rad: f64,
    pub rear_steer_rad: f64,
}

/// 0x281: axle speeds (mean of each axle's wheels).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct AxleSpeed {
    pub front_axle_mps: f64,
    pub rear_axle_mps: f64,
}

/// 0x311: odometers.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Odometer {
    /// m (wire: mm).
    pub front_distance_m: f64,
    pub rear_distance_m: f64,
}

/// 0x361, 0x363, 0x365: BMS data.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BmsData {
    /// 0 = pack, 1 = battery 1, 2 = battery 2 (⚠ caption reading, see PROTOCOLS.md).
    pub group: u8,
    pub soc_pct: f64,
    pub soh_pct: f64,
    /// V (wire: 0.01 V).
    pub voltage_v: f64,
    /// A (wire: 0.1 A).
    pub current_a: f64,
    /// °C (wire: 0.1 °C).
    pub temperature_c: f64,
}

/// 0x362, 0x364, 0x366: BMS alarms and warnings.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BmsAlarm {
    pub group: u8,
    /// bit1 over-voltage, bit2 under-voltage, bit3 over-temperature, bit4 under-temperature,
    /// bit7 discharge over-current.
    pub alarm_1: u8,
    /// bit0 charge over-current.
    pub alarm_2: u8,
    pub warning_1: u8,
    pub warning_2: u8,
}

impl BmsAlarm {
    /// Names of the bits of alarm 1 / warning 1 (b0, b2).
    pub const BYTE_1_NAMES: [(u8, &'static str); 5] = [
        (1 << 1, "over_voltage"),
        (1 << 2, "under_voltage"),
        (1 << 3, "over_temperature"),
        (1 << 4, "under_temperature"),
        (1 << 7, "discharge_over_current"),
    ];
    /// Names of the bits of alarm 2 / warning 2 (b1, b3).
    pub const BYTE_2_NAMES: [(u8, &'static str); 1] = [(1 << 0, "charge_over_current")];

    /// The alarms set (b0, b1), by name.
    pub fn alarm_names(&self) -> Vec<&'static str> {
        Self::names(self.alarm_1, self.alarm_2)
    }

    /// The warnings set (b2, b3), by name.
    pub fn warning_names(&self) -> Vec<&'static str> {
        Self::names(self.warning_1, self.warning_2)
    }

    fn names(first: u8, second: u8) -> Vec<&'static str> {
        let set = |byte: u8, names: &[(u8, &'static str)]| {
            names
                .iter()
                .filter(move |(bit, _)| byte & bit != 0)
                .map(|(_, name)| *name)
                .collect::<Vec<_>>()
        };
        let mut out = set(first, &Self::BYTE_1_NAMES);
        out.extend(set(second, &Self::BYTE_2_NAMES));
        out
    }

    /// The bytes `BmsState::alarm_flags` holds, back as a frame of `group`.
    pub fn from_alarm_flags(group: u8, flags: u32) -> Self {
        let [alarm_1, alarm_2, warning_1, warning_2] = flags.to_le_bytes();
        BmsAlarm {
            group,
            alarm_1,
            alarm_2,
            warning_1,
            warning_2,
        }
    }

    /// Decodes the 0x362 layout shared by the TITAN and the protocol-V2 robots: alarm 1, alarm
    /// 2, warning 1, warning 2, the bytes `BmsState::alarm_flags` holds.
    pub(crate) fn from_wire(group: u8, raw_id: u32, data: &[u8]) -> Result<Self, DecodeError> {
        let bytes: [u8; 4] = read_prefix(raw_id, data)?;
        Ok(Self::from_alarm_flags(group, u32::from_le_bytes(bytes)))
    }

    /// The four bytes as `BmsState::alarm_flags` holds them.
    pub fn alarm_flags(&self) -> u32 {
        u32::from_le_bytes([self.alarm_1, self.alarm_2, self.warning_1, self.warning_2])
    }
}

/// Every TITAN frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "frame", rename_all = "snake_case")]
pub enum Frame {
    MotionCommand(MotionCommand),
    ParkingBrake(ParkingBrake),
    Mode(ModeCommand),
    SilentMode(Switch),
    OffRoad(Switch),
    SteeringZero,
    SteeringZeroAck,
    ClearFault(ClearFault),
    SystemStatus(SystemStatus),
    MotionFeedback(MotionFeedback),
    /// 0x241: the RC transmitter, as the state holds it (the SWB lever selects the mode).
    Rc(RcState),
    MotorFast(MotorFast),
    MotorSlow(MotorSlow),
    SteeringFeedback(SteeringFeedback),
    AxleSpeed(AxleSpeed),
    Odometer(Odometer),
    BmsData(BmsData),
    BmsAlarm(BmsAlarm),
}

/// ⚠ The reported steering sign: ISO (left positive) from the wire's value, and back.
fn steer_feedback_sign(profile: &TitanProfile) -> f64 {
    if profile.steering_feedback_left_positive {
        1.0
    } else {
        -1.0
    }
}

/// The two values of a 0x271 / 0x281 layout (wire: ×1000), each multiplied by `sign`.
fn front_rear(raw_id: u32, data: &[u8], sign: f64) -> Result<[f64; 2], DecodeError> {
    let w: FrontRearWire = read_prefix(raw_id, data)?;
    Ok(w.milli.map(|v| sign * si(v.get(), 1000.0)))
}

fn front_rear_wire(fields: [(&'static str, f64); 2], sign: f64) -> Result<[u8; 8], EncodeError> {
    let [(f0, v0), (f1, v1)] = fields;
    Ok(wire_bytes::<8, _>(FrontRearWire {
        milli: [
            to_i16(f0, sign * v0, 1000.0)?.into(),
            to_i16(f1, sign * v1, 1000.0)?.into(),
        ],
        reserved: [0; 4],
    }))
}

fn motion_wire(linear_mps: f64, steer_rad: f64) -> Result<[u8; 8], EncodeError> {
    Ok(wire_bytes::<8, _>(MotionWire {
        linear_mm_s: to_i16("linear_mps", linear_mps, 1000.0)?.into(),
        reserved: [0; 4],
        steer_mrad: to_i16("steer_rad", steer_rad, 1000.0)?.into(),
    }))
}

fn bms_group(id: u16, first: u16) -> Option<u8> {
    [first, first + 2, first + 4]
        .iter()
        .position(|&i| i == id)
        .map(|g| g as u8)
}

/// Decodes one TITAN frame (either direction).
pub fn decode(frame: &CanFrame, profile: &TitanProfile) -> Result<Frame, DecodeError> {
    let raw_id = frame.id();
    let id16 = frame.standard_id()?;
    let data = frame.data();
    let frame = match id16 {
        id::MOTION_COMMAND => {
            let w: MotionWire = read_prefix(raw_id, data)?;
            Frame::MotionCommand(MotionCommand {
                linear_mps: si(w.linear_mm_s.get(), 1000.0),
                steer_rad: si(w.steer_mrad.get(), 1000.0),
            })
        }
        id::PARKING_BRAKE => {
            // 0x00 engage, 0x01 release.
            let release = read_bool(raw_id, "parking brake", first_byte(raw_id, data)?)?;
            Frame::ParkingBrake(ParkingBrake { engage: !release })
        }
        id::MODE => {
            let m = first_byte(raw_id, data)?;
            if m != mode::STANDBY && m != mode::CAN_COMMAND {
                return Err(invalid(raw_id, "mode", m));
            }
            Frame::Mode(ModeCommand { mode: m })
        }
        id::SILENT_MODE => Frame::SilentMode(Switch {
            enter: read_bool(raw_id, "silent mode", first_byte(raw_id, data)?)?,
        }),
        id::OFF_ROAD => Frame::OffRoad(Switch {
            enter: read_bool(raw_id, "off-road mode", first_byte(raw_id, data)?)?,
        }),
        id::STEERING_ZERO => match first_byte(raw_id, data)? {
            STEERING_ZERO_MAGIC => Frame::SteeringZero,
            other => {
                return Err(invalid(raw_id, "steering zero", other));
            }
        },
        id::STEERING_ZERO_ACK => match first_byte(raw_id, data)? {
            STEERING_ZERO_ACK_MAGIC => Frame::SteeringZeroAck,
            other => {
                return Err(invalid(raw_id, "steering zero acknowledgement", other));
            }
        },
        id::CLEAR_FAULT => {
            let code = first_byte(raw_id, data)?;
            if !clear_code::is_defined(code) {
                return Err(invalid(raw_id, "fault clear code", code));
            }
            Frame::ClearFault(ClearFault { code })
        }
        id::SYSTEM_STATUS => {
            let w: SystemStatusWire = read_prefix(raw_id, data)?;
            Frame::SystemStatus(SystemStatus {
                body_status: w.body_status,
                mode: w.mode,
                battery_voltage_v: si(w.battery_dv.get(), 10.0),
                vendor_fault_word: w.fault_word.get(),
            })
        }
        id::MOTION_FEEDBACK => {
            let w: MotionWire = read_prefix(raw_id, data)?;
            Frame::MotionFeedback(MotionFeedback {
                linear_mps: si(w.linear_mm_s.get(), 1000.0),
                steer_rad: steer_feedback_sign(profile) * si(w.steer_mrad.get(), 1000.0),
            })
        }
        id::RC => Frame::Rc(rc_from_wire(raw_id, data, false)?),
        id::STEERING_FEEDBACK => {
            let [front_steer_rad, rear_steer_rad] =
                front_rear(raw_id, data, steer_feedback_sign(profile))?;
            Frame::SteeringFeedback(SteeringFeedback {
                front_steer_rad,
                rear_steer_rad,
            })
        }
        id::AXLE_SPEED => {
            let [front_axle_mps, rear_axle_mps] = front_rear(raw_id, data, 1.0)?;
            Frame::AxleSpeed(AxleSpeed {
                front_axle_mps,
                rear_axle_mps,
            })
        }
        id::ODOMETER => {
            let w: OdometerWire = read_prefix(raw_id, data)?;
            Frame::Odometer(Odometer {
                front_distance_m: si(w.front_mm.get(), 1000.0),
                rear_distance_m: si(w.rear_mm.get(), 1000.0),
            })
        }
        other => {
            if let Some(motor) = index_in(other, id::MOTOR_FAST_1, 4) {
                Frame::MotorFast(MotorFast::from_wire(motor, raw_id, data)?)
            } else if let Some(motor) = index_in(other, id::MOTOR_SLOW_1, 4) {
                Frame::MotorSlow(MotorSlow::from_wire(motor, raw_id, data)?)
            } else if let Some(group) = bms_group(other, id::BMS_DATA_0) {
                Frame::BmsData(BmsData::from_wire(group, raw_id, data, |v| si(v, 100.0))?)
            } else if let Some(group) = bms_group(other, id::BMS_ALARM_0) {
                Frame::BmsAlarm(BmsAlarm::from_wire(group, raw_id, data)?)
            } else {
                return Err(DecodeError::UnknownId { id: raw_id });
            }
        }
    };
    Ok(frame)
}

/// Decodes the 0x241 layout shared by the TITAN and the protocol-V2 robots. `swap_right` reads
/// b1 as the right stick's vertical axis and b2 as its horizontal one, the order some V2
/// firmware uses.
pub(crate) fn rc_from_wire(
    raw_id: u32,
    data: &[u8],
    swap_right: bool,
) -> Result<RcState, DecodeError> {
    let w: RcWire = read_prefix(raw_id, data)?;
    let (right_x_pct, right_y_pct) = if swap_right {
        (w.b2, w.b1)
    } else {
        (w.b1, w.b2)
    };
    Ok(RcState {
        switch_a: w.switches & 0b11,
        switch_b: (w.switches >> 2) & 0b11,
        switch_c: (w.switches >> 4) & 0b11,
        switch_d: (w.switches >> 6) & 0b11,
        right_x_pct,
        right_y_pct,
        left_y_pct: w.left_y,
        left_x_pct: w.left_x,
        knob_a_pct: w.knob_a,
        counter: w.counter,
        ..RcState::default()
    })
}

/// The 8 wire bytes of 0x241, the right stick's axes in the order [`rc_from_wire`] reads them.
pub(crate) fn rc_wire(rc: &RcState, swap_right: bool) -> Result<[u8; 8], EncodeError> {
    for (field, v) in [
        ("switch_a", rc.switch_a),
        ("switch_b", rc.switch_b),
        ("switch_c", rc.switch_c),
        ("switch_d", rc.switch_d),
    ] {
        check_u8(field, v, 0, 3)?;
    }
    let (b1, b2) = if swap_right {
        (rc.right_y_pct, rc.right_x_pct)
    } else {
        (rc.right_x_pct, rc.right_y_pct)
    };
    Ok(wire_bytes::<8, _>(RcWire {
        switches: rc.switch_a | (rc.switch_b << 2) | (rc.switch_c << 4) | (rc.switch_d << 6),
        b1,
        b2,
        left_y: rc.left_y_pct,
        left_x: rc.left_x_pct,
        knob_a: rc.knob_a_pct,
        reserved: 0,
        counter: rc.counter,
    }))
}

impl BmsData {
    /// Decodes the 0x361 layout shared by the TITAN and the protocol-V2 robots. The unit of the
    /// voltage field differs between them, so `volts` reads it.
    pub(crate) fn from_wire(
        group: u8,
        raw_id: u32,
        data: &[u8],
        volts: impl FnOnce(u16) -> f64,
    ) -> Result<Self, DecodeError> {
        let w: BmsDataWire = read_prefix(raw_id, data)?;
        Ok(BmsData {
            group,
            soc_pct: w.soc_pct.into(),
            soh_pct: w.soh_pct.into(),
            voltage_v: volts(w.voltage.get()),
            current_a: si(w.current_da.get(), 10.0),
            temperature_c: si(w.temperature_dc.get(), 10.0),
        })
    }

    /// The 8 wire bytes, the voltage in units of `1 / per_volt` V.
    pub(crate) fn wire(&self, per_volt: f64) -> Result<[u8; 8], EncodeError> {
        Ok(wire_bytes::<8, _>(BmsDataWire {
            soc_pct: to_u8("soc_pct", self.soc_pct, 1.0)?,
            soh_pct: to_u8("soh_pct", self.soh_pct, 1.0)?,
            voltage: to_u16("voltage_v", self.voltage_v, per_volt)?.into(),
            current_da: to_i16("current_a", self.current_a, 10.0)?.into(),
            temperature_dc: to_i16("temperature_c", self.temperature_c, 10.0)?.into(),
        }))
    }
}

impl MotorFast {
    /// Decodes the wire layout shared by the TITAN and the protocol-V2 robots.
    pub(crate) fn from_wire(motor: u8, raw_id: u32, data: &[u8]) -> Result<Self, DecodeError> {
        let w: MotorFastWire = read_prefix(raw_id, data)?;
        Ok(MotorFast {
            motor,
            rpm: w.rpm.get().into(),
            current_a: si(w.current_da.get(), 10.0),
            position_counts: w.position_counts.get(),
        })
    }

    /// The 8 wire bytes; `motors` is how many motors the robot numbers from 1.
    pub(crate) fn wire(&self, motors: u8) -> Result<[u8; 8], EncodeError> {
        check_range("motor", self.motor.into(), 1.0, motors.into())?;
        Ok(wire_bytes::<8, _>(MotorFastWire {
            rpm: to_i16("rpm", self.rpm, 1.0)?.into(),
            current_da: to_i16("current_a", self.current_a, 10.0)?.into(),
            position_counts: self.position_counts.into(),
        }))
    }
}

impl MotorSlow {
    /// Decodes the wire layout shared by the TITAN and the protocol-V2 robots.
    pub(crate) fn from_wire(motor: u8, raw_id: u32, data: &[u8]) -> Result<Self, DecodeError> {
        let w: MotorSlowWire = read_prefix(raw_id, data)?;
        Ok(MotorSlow {
            motor,
            driver_voltage_v: si(w.driver_voltage_dv.get(), 10.0),
            driver_temp_c: w.driver_temp_c.get().into(),
            motor_temp_c: w.motor_temp_c.into(),
            driver_status: w.driver_status,
        })
    }

    /// The 8 wire bytes; `motors` is how many motors the robot numbers from 1.
    pub(crate) fn wire(&self, motors: u8) -> Result<[u8; 8], EncodeError> {
        check_range("motor", self.motor.into(), 1.0, motors.into())?;
        Ok(wire_bytes::<8, _>(MotorSlowWire {
            driver_voltage_dv: to_u16("driver_voltage_v", self.driver_voltage_v, 10.0)?.into(),
            driver_temp_c: to_i16("driver_temp_c", self.driver_temp_c, 1.0)?.into(),
            motor_temp_c: to_i8("motor_temp_c", self.motor_temp_c, 1.0)?,
            driver_status: self.driver_status,
            reserved: [0; 2],
        }))
    }
}

impl Frame {
    /// The frame's CAN id.
    pub fn id(&self) -> u16 {
        match self {
            Frame::MotionCommand(_) => id::MOTION_COMMAND,
            Frame::ParkingBrake(_) => id::PARKING_BRAKE,
            Frame::Mode(_) => id::MODE,
            Frame::SilentMode(_) => id::SILENT_MODE,
            Frame::OffRoad(_) => id::OFF_ROAD,
            Frame::SteeringZero => id::STEERING_ZERO,
            Frame::SteeringZeroAck => id::STEERING_ZERO_ACK,
            Frame::ClearFault(_) => id::CLEAR_FAULT,
            Frame::SystemStatus(_) => id::SYSTEM_STATUS,
            Frame::MotionFeedback(_) => id::MOTION_FEEDBACK,
            Frame::Rc(_) => id::RC,
            Frame::MotorFast(m) => id::MOTOR_FAST_1 + u16::from(m.motor.clamp(1, 4)) - 1,
            Frame::MotorSlow(m) => id::MOTOR_SLOW_1 + u16::from(m.motor.clamp(1, 4)) - 1,
            Frame::SteeringFeedback(_) => id::STEERING_FEEDBACK,
            Frame::AxleSpeed(_) => id::AXLE_SPEED,
            Frame::Odometer(_) => id::ODOMETER,
            Frame::BmsData(b) => id::BMS_DATA_0 + 2 * u16::from(b.group.min(2)),
            Frame::BmsAlarm(b) => id::BMS_ALARM_0 + 2 * u16::from(b.group.min(2)),
        }
    }

    /// Who sends it.
    pub fn direction(&self) -> Direction {
        match self {
            Frame::MotionCommand(_)
            | Frame::ParkingBrake(_)
            | Frame::Mode(_)
            | Frame::SilentMode(_)
            | Frame::OffRoad(_)
            | Frame::SteeringZero
            | Frame::ClearFault(_) => Direction::ToChassis,
            _ => Direction::FromChassis,
        }
    }

    /// Encodes the frame. Values outside what the wire can carry are an error, never
    /// silently saturated.
    pub fn encode(&self, profile: &TitanProfile) -> Result<CanFrame, EncodeError> {
        let id = self.id();
        let frame = match self {
            Frame::MotionCommand(c) => {
                CanFrame::from_parts(id, motion_wire(c.linear_mps, c.steer_rad)?)
            }
            Frame::ParkingBrake(b) => CanFrame::from_parts(id, [u8::from(!b.engage)]),
            Frame::Mode(m) => {
                check_u8("mode", m.mode, mode::STANDBY, mode::CAN_COMMAND)?;
                CanFrame::from_parts(id, [m.mode])
            }
            Frame::SilentMode(s) | Frame::OffRoad(s) => {
                CanFrame::from_parts(id, [u8::from(s.enter)])
            }
            Frame::SteeringZero => CanFrame::from_parts(id, [STEERING_ZERO_MAGIC]),
            Frame::SteeringZeroAck => CanFrame::from_parts(id, [STEERING_ZERO_ACK_MAGIC]),
            Frame::ClearFault(c) => {
                if !clear_code::is_defined(c.code) {
                    return Err(EncodeError::OutOfRange {
                        field: "fault clear code",
                        value: c.code.into(),
                        min: 0.0,
                        max: 16.0,
                    });
                }
                CanFrame::from_parts(id, [c.code])
            }
            Frame::SystemStatus(s) => CanFrame::from_parts(
                id,
                wire_bytes::<8, _>(SystemStatusWire {
                    body_status: s.body_status,
                    mode: s.mode,
                    battery_dv: to_u16("battery_voltage_v", s.battery_voltage_v, 10.0)?.into(),
                    fault_word: s.vendor_fault_word.into(),
                }),
            ),
            Frame::MotionFeedback(m) => CanFrame::from_parts(
                id,
                motion_wire(m.linear_mps, steer_feedback_sign(profile) * m.steer_rad)?,
            ),
            Frame::Rc(r) => CanFrame::from_parts(id, rc_wire(r, false)?),
            Frame::MotorFast(m) => CanFrame::from_parts(id, m.wire(4)?),
            Frame::MotorSlow(m) => CanFrame::from_parts(id, m.wire(4)?),
            Frame::SteeringFeedback(s) => CanFrame::from_parts(
                id,
                front_rear_wire(
                    [
                        ("front_steer_rad", s.front_steer_rad),
                        ("rear_steer_rad", s.rear_steer_rad),
                    ],
                    steer_feedback_sign(profile),
                )?,
            ),
            Frame::AxleSpeed(a) => CanFrame::from_parts(
                id,
                front_rear_wire(
                    [
                        ("front_axle_mps", a.front_axle_mps),
                        ("rear_axle_mps", a.rear_axle_mps),
                    ],
                    1.0,
                )?,
            ),
            Frame::Odometer(o) => CanFrame::from_parts(
                id,
                wire_bytes::<8, _>(OdometerWire {
                    front_mm: to_i32("front_distance_m", o.front_distance_m, 1000.0)?.into(),
                    rear_mm: to_i32("rear_distance_m", o.rear_distance_m, 1000.0)?.into(),
                }),
            ),
            Frame::BmsData(b) => {
                check_u8("group", b.group, 0, 2)?;
                CanFrame::from_parts(id, b.wire(100.0)?)
            }
            Frame::BmsAlarm(b) => {
                check_u8("group", b.group, 0, 2)?;
                CanFrame::from_parts(id, b.alarm_flags().to_le_bytes())
            }
        };
        Ok(frame)
    }
}
