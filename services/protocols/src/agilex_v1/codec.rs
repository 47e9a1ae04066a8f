//! SCOUT MINI wire codec: every frame of the manual, both directions.
//!
//! CAN 2.0B, 500 kbit/s, standard 11-bit ids, Motorola (big-endian) byte order. Every frame, in
//! both directions, is 8 bytes: a 6-byte payload, then **b6** a rolling count (0-255, +1 per frame
//! sent) and **b7** a checksum, `(id_hi + id_lo + dlc + b0 + … + b6) & 0xFF` with `dlc` = 8 (the
//! DLC counts the checksum byte; the count byte is summed, the checksum byte is not). See
//! [`checksum`].
//!
//! [`decode`] checks the checksum before it looks at a single payload byte: a frame with a wrong
//! checksum is [`DecodeError::BadChecksum`] (the chassis drops such frames too, and so must the
//! driver, counting them). The count byte is handed back beside the frame in [`Decoded`], and
//! [`Frame::encode`] takes the count to send.
//!
//! | id | dir | payload (b0-b5) |
//! | --- | --- | --- |
//! | 0x130 | → | mode, fault-clear code, `s8` linear %, `s8` angular %, reserved ×2 |
//! | 0x140 | → | light control enable, front mode, front brightness %, reserved ×3 |
//! | 0x151 | ← | body status, mode, `u16` battery 0.1 V, `u16` fault word |
//! | 0x131 | ← | `s16` linear 0.001 m/s, `s16` angular 0.001 rad/s, reserved ×2 |
//! | 0x200-0x203 | ← | motor 1-4: `u16` current 0.1 A, `s16` shaft rpm, `s8` driver °C, `s8` motor °C |
//! | 0x141 | ← | light control enabled, front mode, front brightness % |
//!
//! The motion command's speeds are signed percentages of full scales the manual contradicts
//! itself about (⚠ angular: 0.5235 rad/s by the table, 0.7853 by the example); the
//! [`V1Profile`] holds both full scales. Percent commands have 1 % resolution: use
//! [`quantise_percent`] (or [`super::kinematics::twist_to_command`]) to learn the command the
//! wire actually carries. Frame structs hold SI values in ISO 8855 axes (left turn positive).

use serde::{Deserialize, Serialize};
use zerocopy::byteorder::big_endian::{I16, U16};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use crate::Direction;
use crate::agilex_v1::V1Profile;
use crate::can::CanFrame;
use crate::error::{DecodeError, EncodeError, check_u8, to_i8, to_i16, to_u16, to_wire};
use crate::wire_layout::{index_in, invalid, read_bool, read_prefix, si, wire_bytes};

/// Frame identifiers.
pub mod id {
    /// → motion command: mode, fault clear, speeds (heartbeat, 20 ms, timeout 500 ms).
    pub const MOTION_COMMAND: u16 = 0x130;
    /// → light command (25 ms when used).
    pub const LIGHT_COMMAND: u16 = 0x140;
    /// ← body status, mode, battery voltage, fault bits (20 ms).
    pub const SYSTEM_STATUS: u16 = 0x151;
    /// ← linear and angular speed (20 ms).
    pub const MOTION_FEEDBACK: u16 = 0x131;
    /// ← motor 1 current, speed, temperatures; motors 2-4 follow (0x201-0x203, 20 ms).
    pub const MOTOR_1: u16 = 0x200;
    /// ← light state (20 ms).
    pub const LIGHT_STATE: u16 = 0x141;

    /// Every id the SCOUT MINI manual defines.
    pub const ALL: [u16; 9] = [
        MOTION_COMMAND,
        LIGHT_COMMAND,
        SYSTEM_STATUS,
        MOTION_FEEDBACK,
        MOTOR_1,
        MOTOR_1 + 1,
        MOTOR_1 + 2,
        MOTOR_1 + 3,
        LIGHT_STATE,
    ];
}

/// Data length of every SCOUT MINI frame (payload, count, checksum).
pub const DLC: usize = 8;

/// `MotionCommand::mode` and `SystemStatus::mode` values (0x130 b0, 0x151 b1).
pub mod mode {
    /// An RC transmitter controls the chassis.
    pub const RC: u8 = 0x00;
    /// CAN command mode: every 0x130 must carry this to be obeyed.
    pub const CAN_COMMAND: u8 = 0x01;
    /// Serial command mode (commands on the serial port; CAN commands ignored).
    pub const SERIAL: u8 = 0x02;

    /// True for a mode the manual defines.
    pub fn is_defined(mode: u8) -> bool {
        mode <= SERIAL
    }
}

/// `MotionCommand::fault_clear` values (0x130 b1).
pub mod clear_code {
    /// No fault-clear command.
    pub const NONE: u8 = 0x00;
    pub const BATTERY_UNDER_VOLTAGE: u8 = 0x01;
    pub const BATTERY_OVER_VOLTAGE: u8 = 0x02;
    /// Motor 1 communication failure; motors 2-4 are 0x04-0x06.
    pub const MOTOR_1_COMM: u8 = 0x03;
    pub const MOTOR_2_COMM: u8 = 0x04;
    pub const MOTOR_3_COMM: u8 = 0x05;
    pub const MOTOR_4_COMM: u8 = 0x06;
    /// Drive over-temperature protection ([`super::fault::DRIVE_OVER_TEMP_PROTECTION`]).
    pub const DRIVE_OVER_TEMPERATURE: u8 = 0x07;
    /// Motor over-current protection ([`super::fault::MOTOR_OVER_CURRENT_PROTECTION`]).
    pub const MOTOR_OVER_CURRENT: u8 = 0x08;

    /// True for a code the manual defines.
    pub fn is_defined(code: u8) -> bool {
        code <= MOTOR_OVER_CURRENT
    }
}

/// Bits of `SystemStatus::vendor_fault_word`.
///
/// The word is 0x151 b4-5 read big-endian, `u16::from_be_bytes([b4, b5])` (the manual labels b4
/// "failure information higher 8 bits"): b4 bit n is `1 << (8 + n)`, b5 bit n is `1 << n`.
/// Alarms (b4) clear themselves; protections (b5 bits 6-7) hold until a fault-clear command.
pub mod fault {
    /// b4 bit0: the chassis received a command frame with a wrong checksum.
    pub const COMMAND_CHECKSUM: u16 = 1 << 8;
    /// b4 bit1: drive over-temperature alarm (55 °C; clears itself).
    pub const DRIVE_OVER_TEMP_ALARM: u16 = 1 << 9;
    /// b4 bit2: motor over-current alarm (15 A rms; clears itself).
    pub const MOTOR_OVER_CURRENT_ALARM: u16 = 1 << 10;
    /// b4 bit3: battery under-voltage alarm (22.5 V; clears itself).
    pub const BATTERY_UNDER_VOLTAGE_ALARM: u16 = 1 << 11;
    /// b4 bit4: RC transmitter disconnected.
    pub const RC_DISCONNECTED: u16 = 1 << 12;
    /// b5 bit0: battery under-voltage failure (22 V).
    pub const BATTERY_UNDER_VOLTAGE: u16 = 1 << 0;
    /// b5 bit1: battery over-voltage failure.
    pub const BATTERY_OVER_VOLTAGE: u16 = 1 << 1;
    /// b5 bit2: motor 1 communication failure; motors 2-4 are the next three bits.
    pub const MOTOR_1_COMM: u16 = 1 << 2;
    pub const MOTOR_2_COMM: u16 = 1 << 3;
    pub const MOTOR_3_COMM: u16 = 1 << 4;
    pub const MOTOR_4_COMM: u16 = 1 << 5;
    /// b5 bit6: drive over-temperature protection (65 °C; output limited until cleared).
    pub const DRIVE_OVER_TEMP_PROTECTION: u16 = 1 << 6;
    /// b5 bit7: motor over-current protection (20 A rms; until cleared).
    pub const MOTOR_OVER_CURRENT_PROTECTION: u16 = 1 << 7;

    /// Every bit with its name, b4 first.
    pub const ALL: [(u16, &str); 13] = [
        (COMMAND_CHECKSUM, "command_checksum"),
        (DRIVE_OVER_TEMP_ALARM, "drive_over_temp_alarm"),
        (MOTOR_OVER_CURRENT_ALARM, "motor_over_current_alarm"),
        (BATTERY_UNDER_VOLTAGE_ALARM, "battery_under_voltage_alarm"),
        (RC_DISCONNECTED, "rc_disconnected"),
        (BATTERY_UNDER_VOLTAGE, "battery_under_voltage"),
        (BATTERY_OVER_VOLTAGE, "battery_over_voltage"),
        (MOTOR_1_COMM, "motor_1_comm"),
        (MOTOR_2_COMM, "motor_2_comm"),
        (MOTOR_3_COMM, "motor_3_comm"),
        (MOTOR_4_COMM, "motor_4_comm"),
        (DRIVE_OVER_TEMP_PROTECTION, "drive_over_temp_protection"),
        (
            MOTOR_OVER_CURRENT_PROTECTION,
            "motor_over_current_protection",
        ),
    ];

    /// Names of the set bits (undefined bits are left out).
    pub fn names(word: u16) -> Vec<&'static str> {
        ALL.iter()
            .filter(|(bit, _)| word & bit != 0)
            .map(|(_, name)| *name)
            .collect()
    }
}

/// `SystemStatus::body_status` values (0x151 b0).
pub mod body {
    pub const NORMAL: u8 = 0x00;
    pub const EMERGENCY_STOP: u8 = 0x01;
    pub const EXCEPTION: u8 = 0x02;
}

/// `Lights::front_mode` values (0x140 b1, 0x141 b1).
pub mod light_mode {
    /// Normally closed (NC): off while standing, on while driving.
    pub const NORMALLY_CLOSED: u8 = 0x00;
    /// Normally open (NO): always on.
    pub const NORMALLY_OPEN: u8 = 0x01;
    /// Breathing light (BL).
    pub const BREATHING: u8 = 0x02;
    /// Custom brightness (`Lights::front_brightness_pct`).
    pub const CUSTOM_BRIGHTNESS: u8 = 0x03;

    /// Largest custom brightness, %.
    pub const MAX_BRIGHTNESS_PCT: u8 = 100;

    /// True for a mode the manual defines.
    pub fn is_defined(mode: u8) -> bool {
        mode <= CUSTOM_BRIGHTNESS
    }
}

/// The checksum of a frame whose bytes before the checksum are `data7` (b0-b6 for every
/// SCOUT MINI frame): `(id_hi + id_lo + dlc + Σ data7) & 0xFF`, where `dlc = data7.len() + 1`
/// counts the checksum byte itself, as the manual's `Agilex_CANMsgChecksum` does.
pub fn checksum(id: u16, data7: &[u8]) -> u8 {
    let [id_hi, id_lo] = id.to_be_bytes();
    // Reduced mod 256 first, so the cast is exact (the sum is mod 256 anyway).
    let dlc = (data7.len().wrapping_add(1) % 256) as u8;
    data7
        .iter()
        .fold(id_hi.wrapping_add(id_lo).wrapping_add(dlc), |sum, b| {
            sum.wrapping_add(*b)
        })
}

/// The speed a motion-command percentage means: `percent × full_scale / 100`. [`decode`] uses
/// exactly this, so a driver reporting it reports what the chassis was told.
pub fn percent_to_si(percent: i8, full_scale: f64) -> f64 {
    f64::from(percent) / 100.0 * full_scale
}

/// Rounds a speed to the nearest whole percent of `full_scale`, saturating at ±100 %, and returns
/// the percentage and the speed it means ([`percent_to_si`]): the command the wire actually
/// carries. NaN, and any value with a full scale that is not finite and positive, give `(0, 0.0)`.
/// [`Frame::encode`] sends the returned speed as the returned percentage.
pub fn quantise_percent(value: f64, full_scale: f64) -> (i8, f64) {
    if value.is_nan() || !full_scale.is_finite() || full_scale <= 0.0 {
        return (0, 0.0);
    }
    let percent = (value * (100.0 / full_scale)).round().clamp(-100.0, 100.0);
    // Integral and within ±100: the cast is exact.
    let percent = percent as i8;
    (percent, percent_to_si(percent, full_scale))
}

/// Scales a speed to its wire percentage, rounding to nearest; outside ±100 % (after rounding)
/// it cannot be sent.
fn to_percent(field: &'static str, value: f64, full_scale: f64) -> Result<i8, EncodeError> {
    // In -100..=100 after the check: the cast is exact.
    to_wire(field, value, 100.0 / full_scale, -100, 100).map(|p| p as i8)
}

// ---------------------------------------------------------------------------------------------
// Wire layouts (big-endian). Every frame is a 6-byte payload + count + checksum.

/// Payload length, b0-b5.
const PAYLOAD_LEN: usize = 6;

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct FrameWire {
    payload: [u8; PAYLOAD_LEN],
    count: u8,
    checksum: u8,
}

impl FrameWire {
    /// b0-b6, the bytes the checksum covers.
    fn data7(&self) -> [u8; 7] {
        let [b0, b1, b2, b3, b4, b5] = self.payload;
        [b0, b1, b2, b3, b4, b5, self.count]
    }
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotionCommandWire {
    mode: u8,
    fault_clear: u8,
    linear_pct: i8,
    angular_pct: i8,
    reserved: [u8; 2],
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct LightsWire {
    control_enable: u8,
    front_mode: u8,
    front_brightness_pct: u8,
    reserved: [u8; 3],
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct SystemStatusWire {
    body_status: u8,
    mode: u8,
    battery_dv: U16,
    fault_word: U16,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotionFeedbackWire {
    linear_mm_s: I16,
    angular_mrad_s: I16,
    reserved: [u8; 2],
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotorWire {
    current_da: U16,
    rpm: I16,
    driver_temp_c: i8,
    motor_temp_c: i8,
}

#[cfg(test)]
pub(super) const WIRE_SIZES: [(&str, usize); 6] = [
    ("frame", size_of::<FrameWire>()),
    ("motion command", size_of::<MotionCommandWire>()),
    ("lights", size_of::<LightsWire>()),
    ("system status", size_of::<SystemStatusWire>()),
    ("motion feedback", size_of::<MotionFeedbackWire>()),
    ("motor", size_of::<MotorWire>()),
];

// ---------------------------------------------------------------------------------------------
// Frames.

/// 0x130: control mode, fault clear and speeds. Also the heartbeat.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MotionCommand {
    /// [`mode`] value; the chassis obeys the speeds only with [`mode::CAN_COMMAND`].
    pub mode: u8,
    /// [`clear_code`] value ([`clear_code::NONE`] normally).
    pub fault_clear: u8,
    /// m/s (wire: `s8` percent of `linear_full_scale_mps`, ±100).
    pub linear_mps: f64,
    /// rad/s, left turn positive (wire: `s8` percent of ⚠ `angular_full_scale_rad_s`, ±100).
    pub angular_radps: f64,
}

impl MotionCommand {
    /// A speed command in CAN command mode, clearing nothing.
    pub fn drive(linear_mps: f64, angular_radps: f64) -> Self {
        Self {
            mode: mode::CAN_COMMAND,
            fault_clear: clear_code::NONE,
            linear_mps,
            angular_radps,
        }
    }
}

/// 0x140 (command) and 0x141 (state): front light control.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Lights {
    /// Command: obey this frame (false: the chassis ignores it). State: light control by
    /// command is enabled.
    pub control_enabled: bool,
    /// [`light_mode`] value (0x141: as sent, undefined values kept).
    pub front_mode: u8,
    /// Custom brightness, 0-100 % (used in [`light_mode::CUSTOM_BRIGHTNESS`]; 0x141: as sent).
    pub front_brightness_pct: u8,
}

/// 0x151: body status, mode, battery voltage and fault bits.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SystemStatus {
    /// [`body`] value as sent (0x00 normal, 0x01 emergency stop, 0x02 exception).
    pub body_status: u8,
    /// [`mode`] value as sent (0x00 RC, 0x01 CAN command, 0x02 serial).
    pub mode: u8,
    /// V (wire: 0.1 V).
    pub battery_voltage_v: f64,
    /// [`fault`] bits: `u16::from_be_bytes([b4, b5])`.
    pub vendor_fault_word: u16,
}

/// 0x131: linear and angular speed of the body.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotionFeedback {
    /// m/s (wire: 0.001 m/s).
    pub linear_mps: f64,
    /// rad/s, left turn positive (wire: 0.001 rad/s).
    pub angular_radps: f64,
}

/// 0x200-0x203: one motor's current, shaft speed and temperatures.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct MotorFeedback {
    /// 1-4, as the vendor numbers them.
    pub motor: u8,
    /// A (wire: `u16` 0.1 A).
    pub current_a: f64,
    /// Shaft speed, rpm.
    pub rpm: f64,
    /// °C (wire: `s8`).
    pub driver_temp_c: f64,
    /// °C (wire: `s8`).
    pub motor_temp_c: f64,
}

/// Every SCOUT MINI frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "frame", rename_all = "snake_case")]
pub enum Frame {
    MotionCommand(MotionCommand),
    LightCommand(Lights),
    SystemStatus(SystemStatus),
    MotionFeedback(MotionFeedback),
    Motor(MotorFeedback),
    LightState(Lights),
}

/// A decoded frame and its rolling count (b6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    pub frame: Frame,
    pub count: u8,
}

fn read_percent(id: u32, field: &'static str, percent: i8) -> Result<i8, DecodeError> {
    if (-100..=100).contains(&percent) {
        Ok(percent)
    } else {
        Err(invalid(id, field, percent.cast_unsigned()))
    }
}

/// Decodes one SCOUT MINI frame (either direction) and its count byte.
///
/// Checks, in order: standard id, known id, 8 data bytes, checksum, then the payload's values
/// (commands only: feedback keeps undefined status and mode bytes as sent).
pub fn decode(frame: &CanFrame, profile: &V1Profile) -> Result<Decoded, DecodeError> {
    let raw_id = frame.id();
    let id16 = frame.standard_id()?;
    if !id::ALL.contains(&id16) {
        return Err(DecodeError::UnknownId { id: raw_id });
    }
    let wire: FrameWire = read_prefix(raw_id, frame.data())?;
    let expected = checksum(id16, &wire.data7());
    if wire.checksum != expected {
        return Err(DecodeError::BadChecksum {
            expected,
            got: wire.checksum,
        });
    }
    let payload = &wire.payload;
    let decoded = match id16 {
        id::MOTION_COMMAND => {
            let w: MotionCommandWire = read_prefix(raw_id, payload)?;
            if !mode::is_defined(w.mode) {
                return Err(invalid(raw_id, "mode", w.mode));
            }
            if !clear_code::is_defined(w.fault_clear) {
                return Err(invalid(raw_id, "fault clear code", w.fault_clear));
            }
            let linear = read_percent(raw_id, "linear speed percent", w.linear_pct)?;
            let angular = read_percent(raw_id, "angular speed percent", w.angular_pct)?;
            Frame::MotionCommand(MotionCommand {
                mode: w.mode,
                fault_clear: w.fault_clear,
                linear_mps: percent_to_si(linear, profile.linear_full_scale_mps),
                angular_radps: percent_to_si(angular, profile.angular_full_scale_rad_s),
            })
        }
        id::LIGHT_COMMAND => {
            let w: LightsWire = read_prefix(raw_id, payload)?;
            let control_enabled = read_bool(raw_id, "light control enable", w.control_enable)?;
            if !light_mode::is_defined(w.front_mode) {
                return Err(invalid(raw_id, "front light mode", w.front_mode));
            }
            if w.front_brightness_pct > light_mode::MAX_BRIGHTNESS_PCT {
                return Err(invalid(
                    raw_id,
                    "front light brightness",
                    w.front_brightness_pct,
                ));
            }
            Frame::LightCommand(Lights {
                control_enabled,
                front_mode: w.front_mode,
                front_brightness_pct: w.front_brightness_pct,
            })
        }
        id::LIGHT_STATE => {
            let w: LightsWire = read_prefix(raw_id, payload)?;
            // A bool has no room for an undefined value: that one byte is checked.
            let control_enabled = read_bool(raw_id, "light control enabled", w.control_enable)?;
            Frame::LightState(Lights {
                control_enabled,
                front_mode: w.front_mode,
                front_brightness_pct: w.front_brightness_pct,
            })
        }
        id::SYSTEM_STATUS => {
            let w: SystemStatusWire = read_prefix(raw_id, payload)?;
            Frame::SystemStatus(SystemStatus {
                body_status: w.body_status,
                mode: w.mode,
                battery_voltage_v: si(w.battery_dv.get(), 10.0),
                vendor_fault_word: w.fault_word.get(),
            })
        }
        id::MOTION_FEEDBACK => {
            let w: MotionFeedbackWire = read_prefix(raw_id, payload)?;
            Frame::MotionFeedback(MotionFeedback {
                linear_mps: si(w.linear_mm_s.get(), 1000.0),
                angular_radps: si(w.angular_mrad_s.get(), 1000.0),
            })
        }
        other => {
            let Some(motor) = index_in(other, id::MOTOR_1, 4) else {
                return Err(DecodeError::UnknownId { id: raw_id });
            };
            let w: MotorWire = read_prefix(raw_id, payload)?;
            Frame::Motor(MotorFeedback {
                motor,
                current_a: si(w.current_da.get(), 10.0),
                rpm: w.rpm.get().into(),
                driver_temp_c: w.driver_temp_c.into(),
                motor_temp_c: w.motor_temp_c.into(),
            })
        }
    };
    Ok(Decoded {
        frame: decoded,
        count: wire.count,
    })
}

impl Frame {
    /// The frame's CAN id.
    pub fn id(&self) -> u16 {
        match self {
            Frame::MotionCommand(_) => id::MOTION_COMMAND,
            Frame::LightCommand(_) => id::LIGHT_COMMAND,
            Frame::SystemStatus(_) => id::SYSTEM_STATUS,
            Frame::MotionFeedback(_) => id::MOTION_FEEDBACK,
            Frame::Motor(m) => id::MOTOR_1 + u16::from(m.motor.clamp(1, 4)) - 1,
            Frame::LightState(_) => id::LIGHT_STATE,
        }
    }

    /// Who sends it.
    pub fn direction(&self) -> Direction {
        match self {
            Frame::MotionCommand(_) | Frame::LightCommand(_) => Direction::ToChassis,
            Frame::SystemStatus(_)
            | Frame::MotionFeedback(_)
            | Frame::Motor(_)
            | Frame::LightState(_) => Direction::FromChassis,
        }
    }

    /// Encodes the frame with rolling count `count` (b6) and its checksum (b7). Reserved bytes
    /// are sent as zero. Values outside what the wire can carry are an error, never silently
    /// saturated; motion-command speeds are rounded to the nearest percent first (see
    /// [`quantise_percent`]).
    pub fn encode(&self, count: u8, profile: &V1Profile) -> Result<CanFrame, EncodeError> {
        let payload: [u8; PAYLOAD_LEN] = match self {
            Frame::MotionCommand(c) => {
                check_u8("mode", c.mode, mode::RC, mode::SERIAL)?;
                check_u8(
                    "fault clear code",
                    c.fault_clear,
                    clear_code::NONE,
                    clear_code::MOTOR_OVER_CURRENT,
                )?;
                wire_bytes(MotionCommandWire {
                    mode: c.mode,
                    fault_clear: c.fault_clear,
                    linear_pct: to_percent(
                        "linear_mps",
                        c.linear_mps,
                        profile.linear_full_scale_mps,
                    )?,
                    angular_pct: to_percent(
                        "angular_radps",
                        c.angular_radps,
                        profile.angular_full_scale_rad_s,
                    )?,
                    reserved: [0; 2],
                })
            }
            Frame::LightCommand(l) => {
                check_u8(
                    "front_mode",
                    l.front_mode,
                    light_mode::NORMALLY_CLOSED,
                    light_mode::CUSTOM_BRIGHTNESS,
                )?;
                check_u8(
                    "front_brightness_pct",
                    l.front_brightness_pct,
                    0,
                    light_mode::MAX_BRIGHTNESS_PCT,
                )?;
                lights_payload(l)
            }
            Frame::LightState(l) => lights_payload(l),
            Frame::SystemStatus(s) => wire_bytes(SystemStatusWire {
                body_status: s.body_status,
                mode: s.mode,
                battery_dv: to_u16("battery_voltage_v", s.battery_voltage_v, 10.0)?.into(),
                fault_word: s.vendor_fault_word.into(),
            }),
            Frame::MotionFeedback(m) => wire_bytes(MotionFeedbackWire {
                linear_mm_s: to_i16("linear_mps", m.linear_mps, 1000.0)?.into(),
                angular_mrad_s: to_i16("angular_radps", m.angular_radps, 1000.0)?.into(),
                reserved: [0; 2],
            }),
            Frame::Motor(m) => {
                check_u8("motor", m.motor, 1, 4)?;
                wire_bytes(MotorWire {
                    current_da: to_u16("current_a", m.current_a, 10.0)?.into(),
                    rpm: to_i16("rpm", m.rpm, 1.0)?.into(),
                    driver_temp_c: to_i8("driver_temp_c", m.driver_temp_c, 1.0)?,
                    motor_temp_c: to_i8("motor_temp_c", m.motor_temp_c, 1.0)?,
                })
            }
        };
        Ok(seal(self.id(), payload, count))
    }
}

fn lights_payload(l: &Lights) -> [u8; PAYLOAD_LEN] {
    wire_bytes(LightsWire {
        control_enable: u8::from(l.control_enabled),
        front_mode: l.front_mode,
        front_brightness_pct: l.front_brightness_pct,
        reserved: [0; 3],
    })
}

/// Appends the count and the checksum to a payload.
fn seal(id: u16, payload: [u8; PAYLOAD_LEN], count: u8) -> CanFrame {
    let mut wire = FrameWire {
        payload,
        count,
        checksum: 0,
    };
    wire.checksum = checksum(id, &wire.data7());
    CanFrame::from_parts(id, wire_bytes::<DLC, _>(wire))
}
