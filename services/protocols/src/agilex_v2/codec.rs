//! AgileX protocol-V2 codec: every frame of the V2 reading, both directions, for the whole
//! family (SCOUT 2.0, SCOUT MINI V2, HUNTER 2.0 / SE, TRACER, BUNKER, RANGER MINI).
//!
//! CAN 2.0B, 500 kbit/s, standard ids, big-endian, no checksum. The layouts the TITAN shares
//! (0x241 RC, 0x25x / 0x26x actuators, 0x361 / 0x362 BMS) use the TITAN's frame types. Where the
//! family disagrees with itself the [`V2Profile`] decides (mode codes, brake polarity, steering
//! unit, lateral sign, BMS voltage unit, stick order, DLC of one-byte commands).
//!
//! Encoding rounds to the nearest wire unit (the SDK truncates toward zero: 0.1999 m/s is 200
//! here, 199 there); every cited test vector is an exact wire value, so both agree on them.

use chassis_interfaces::RcState;
use serde::{Deserialize, Serialize};
use zerocopy::byteorder::big_endian::{I16, I32, U16};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use super::profile::{BmsAlarmLayout, RcStickOrder, V2Profile};
use crate::Direction;
use crate::can::CanFrame;
use crate::error::{DecodeError, EncodeError, check_u8, to_i16, to_i32, to_u16};
use crate::titan::{BmsAlarm, BmsData, MotorFast, MotorSlow, rc_from_wire, rc_wire};
use crate::wire_layout::{first_byte, index_in, invalid, read_bool, read_prefix, si, wire_bytes};

/// Frame identifiers.
pub mod id {
    /// → motion command (heartbeat, 20 ms, chassis timeout 500 ms).
    pub const MOTION_COMMAND: u16 = 0x111;
    /// → light command.
    pub const LIGHT_COMMAND: u16 = 0x121;
    /// → parking brake (HUNTER 2.0).
    pub const PARKING_BRAKE: u16 = 0x131;
    /// → motion mode (RANGER family).
    pub const MOTION_MODE: u16 = 0x141;
    /// → version request (manual); answer 0x41A.
    pub const VERSION_REQUEST: u16 = 0x411;
    /// → control mode.
    pub const MODE: u16 = 0x421;
    /// → take the present steering position as zero (HUNTER 2.0).
    pub const STEERING_ZERO: u16 = 0x431;
    /// → set the steering zero offset (HUNTER SE).
    pub const STEERING_ZERO_OFFSET: u16 = 0x432;
    /// → query the steering zero offset (HUNTER SE).
    pub const STEERING_ZERO_QUERY: u16 = 0x433;
    /// → clear faults.
    pub const CLEAR_FAULT: u16 = 0x441;
    /// ↔ SDK version request (DLC 1, →) and its ASCII answer (8 characters per frame, ←).
    pub const SDK_VERSION: u16 = 0x4A1;
    /// ← system state.
    pub const SYSTEM_STATUS: u16 = 0x211;
    /// ← motion feedback.
    pub const MOTION_FEEDBACK: u16 = 0x221;
    /// ← light state.
    pub const LIGHT_STATE: u16 = 0x231;
    /// ← RC transmitter.
    pub const RC: u16 = 0x241;
    /// ← actuator 1 high-speed feedback; 2-8 follow.
    pub const MOTOR_FAST_1: u16 = 0x251;
    /// ← actuator 1 low-speed feedback; 2-8 follow.
    pub const MOTOR_SLOW_1: u16 = 0x261;
    /// ← four steering angles (RANGER).
    pub const STEERING_ANGLES: u16 = 0x271;
    /// ← four wheel speeds (RANGER).
    pub const WHEEL_SPEEDS: u16 = 0x281;
    /// ← motion mode state (RANGER).
    pub const MOTION_MODE_STATE: u16 = 0x291;
    /// ← odometers.
    pub const ODOMETER: u16 = 0x311;
    /// ← IMU accelerations; 0x322 gyro, 0x323 Euler angles.
    pub const IMU_ACCEL: u16 = 0x321;
    /// ← bumper.
    pub const BUMPER: u16 = 0x331;
    /// ← ultrasonic sensors 1-8 (0x341-0x348).
    pub const ULTRASONIC_1: u16 = 0x341;
    /// ← UWB modules 1-4 (0x351-0x354).
    pub const UWB_1: u16 = 0x351;
    /// ← BMS data.
    pub const BMS_DATA: u16 = 0x361;
    /// ← BMS alarms.
    pub const BMS_ALARM: u16 = 0x362;
    /// ← version answer to 0x411.
    pub const VERSION: u16 = 0x41A;
    /// ← steering zero acknowledged.
    pub const STEERING_ZERO_ACK: u16 = 0x43A;
    /// ← steering zero offset (answer to 0x433).
    pub const STEERING_ZERO_OFFSET_REPLY: u16 = 0x43B;
}

/// 0x211 b0.
pub mod vehicle {
    pub const NORMAL: u8 = 0x00;
    pub const ESTOP: u8 = 0x01;
    pub const EXCEPTION: u8 = 0x02;

    /// The name of a 0x211 b0 value: `normal`, `estop`, `exception` or `unknown`.
    pub fn name(state: u8) -> &'static str {
        match state {
            NORMAL => "normal",
            ESTOP => "estop",
            EXCEPTION => "exception",
            _ => "unknown",
        }
    }
}

/// 0x43A b0.
pub const STEERING_ZERO_DONE: u8 = 0xEE;
/// 0x43A b0 (SDK header): failure.
pub const STEERING_ZERO_FAILED: u8 = 0xFF;

// ---------------------------------------------------------------------------------------------
// Wire layouts (big-endian).

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct MotionWire {
    linear_mm_s: I16,
    angular_mrad_s: I16,
    lateral_mm_s: I16,
    steer: I16,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct LightWire {
    enabled: u8,
    front_mode: u8,
    front_brightness_pct: u8,
    rear_mode: u8,
    rear_brightness_pct: u8,
    reserved: [u8; 2],
    count: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct SystemStatusWire {
    vehicle_state: u8,
    mode: u8,
    battery_dv: U16,
    fault_word: U16,
    b6: u8,
    count: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct FourI16Wire {
    values: [I16; 4],
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct OdometerWire {
    left: I32,
    right: I32,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct ImuWire {
    values: [I16; 3],
    reserved: u8,
    count: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct UwbWire {
    distance: I16,
    angle: I16,
    valid: u8,
    channels: [i8; 3],
}

// ---------------------------------------------------------------------------------------------
// Frames.

/// 0x111 (→) and 0x221 (←): the four motion fields. Fields a robot does not use are 0.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Motion {
    /// m/s (wire: mm/s).
    pub linear_mps: f64,
    /// rad/s, left positive (wire: 0.001 rad/s).
    pub angular_radps: f64,
    /// m/s, left positive (wire: mm/s; ⚠ D-17 sign).
    pub lateral_mps: f64,
    /// rad, left positive (wire: 0.001 rad, or 0.01° inverted on RANGER MINI 1.0).
    pub steer_rad: f64,
}

/// 0x121 (→) and 0x231 (←): lights.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Lights {
    /// b0: the computer commands the lights (false: handed back to the chassis).
    pub enabled: bool,
    /// 0 off, 1 on, 2 breathing, 3 custom brightness.
    pub front_mode: u8,
    pub front_brightness_pct: u8,
    pub rear_mode: u8,
    pub rear_brightness_pct: u8,
    pub count: u8,
}

/// 0x131: parking brake.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ParkingBrake {
    pub engage: bool,
}

/// 0x141 (→) and 0x291 (←): RANGER motion mode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MotionMode {
    /// Wire value (⚠ D-12: its meaning is the profile's `ranger_mode_codes`).
    pub mode: u8,
    /// 0x291 b1: a mode change is in progress (always false on 0x141).
    pub changing: bool,
}

/// 0x421: control mode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ModeCommand {
    /// true: CAN command mode (0x01); false: standby (0x00).
    pub can: bool,
}

/// 0x441: clear faults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClearFault {
    pub code: u8,
}

/// 0x432 (→) and 0x43B (←): HUNTER SE steering zero offset.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SteeringZeroOffset {
    /// Encoder pulses (reference 22000 ± 10000).
    pub pulses: i16,
}

/// 0x211: system state.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SystemStatus {
    /// 0x00 normal, 0x01 E-stop, 0x02 exception.
    pub vehicle_state: u8,
    /// Its name: normal, estop, exception or unknown ([`vehicle::name`]).
    pub vehicle: &'static str,
    /// b1 as sent (⚠ D-2: meaning per profile, see [`SystemStatus::control`]).
    pub mode: u8,
    /// The mode's meaning under the profile: standby, can, uart, rc or unknown.
    pub control: &'static str,
    /// V (wire: 0.1 V).
    pub battery_voltage_v: f64,
    /// b4-5 as `u16be` (⚠ D-3: meaning per profile).
    pub fault_word: u16,
    /// b6: HUNTER 2.0 parking-brake state (1 locked), reserved elsewhere.
    pub b6: u8,
    pub count: u8,
}

/// 0x271: four steering angles; 0x281: four wheel speeds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Four {
    pub values: [f64; 4],
}

/// 0x311: odometers.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Odometer {
    /// m (wire: mm, ⚠ D-24). TITAN: front.
    pub left_m: f64,
    /// m. TITAN: rear.
    pub right_m: f64,
}

/// 0x321-0x323: IMU (units undocumented: raw values).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Imu {
    /// 0 accelerations, 1 gyro, 2 Euler angles.
    pub kind: u8,
    pub raw: [i16; 3],
    pub count: u8,
}

/// 0x341-0x348: ultrasonic distances (unit undocumented: raw bytes).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Ultrasonic {
    /// 1-8.
    pub sensor: u8,
    pub raw: [u8; 8],
}

/// 0x351-0x354: UWB.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Uwb {
    /// 1-4.
    pub module: u8,
    pub distance_raw: i16,
    pub angle_raw: i16,
    pub valid: bool,
    pub channels: [i8; 3],
}

/// 0x41A: versions, each (major, minor).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Version {
    pub controller_hw: [u8; 2],
    pub driver_hw: [u8; 2],
    pub controller_sw: [u8; 2],
    pub driver_sw: [u8; 2],
}

/// 0x4A1 (←): eight characters of the SDK's version text.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct VersionText {
    /// As received; non-printable bytes are shown as spaces by [`VersionText::text`].
    pub bytes: [u8; 8],
}

impl VersionText {
    /// The printable text, non-printable bytes as spaces (as the SDK does).
    pub fn text(&self) -> String {
        self.bytes
            .iter()
            .map(|&b| {
                if b.is_ascii_graphic() || b == b' ' {
                    char::from(b)
                } else {
                    ' '
                }
            })
            .collect()
    }
}

/// 0x362 in the older layout (⚠ D-6): protection codes and cell temperatures.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BmsProtection {
    pub codes: [u8; 4],
    pub max_cell_temp_c: i8,
    pub min_cell_temp_c: i8,
    pub count: u8,
}

impl BmsProtection {
    /// The bits of protection codes 1-4 (b0-b3) by name, with `true` for a protection (a fault)
    /// and `false` for a state bit (current flowing, a MOS switch on) — the masks the SDK keeps
    /// in `agilex_message.h` (`BMS_PROT1..4_*`).
    pub const NAMES: [&'static [(u8, &'static str, bool)]; 4] = [
        &[
            (0x01, "charging_current", false),
            (0x02, "charging_over_current", true),
            (0x10, "discharging_current", false),
            (0x20, "discharging_over_current", true),
            (0x40, "discharging_short_circuit", true),
        ],
        &[
            (0x01, "cell_open_circuit", true),
            (0x02, "temperature_sensor_open_circuit", true),
            (0x10, "cell_over_voltage", true),
            (0x20, "cell_under_voltage", true),
            (0x40, "total_over_voltage", true),
            (0x80, "total_under_voltage", true),
        ],
        &[
            (0x04, "charging_over_temperature", true),
            (0x08, "discharging_over_temperature", true),
            (0x10, "charging_under_temperature", true),
            (0x20, "discharging_under_temperature", true),
            (0x40, "charging_temperature_difference", true),
            (0x80, "discharging_temperature_difference", true),
        ],
        &[
            (0x01, "charging_mos_on", false),
            (0x02, "discharging_mos_on", false),
            (0x04, "charging_mos_failure", true),
            (0x08, "discharging_mos_failure", true),
            (0x10, "weak_signal_switch_open", true),
        ],
    ];

    /// The set bits that are protections (`true`) or states (`false`), by name.
    pub fn names(&self, protections: bool) -> Vec<&'static str> {
        self.codes
            .iter()
            .zip(Self::NAMES)
            .flat_map(|(code, names)| {
                names
                    .iter()
                    .filter(move |(bit, _, p)| code & bit != 0 && *p == protections)
                    .map(|(_, name, _)| *name)
            })
            .collect()
    }
}

/// Every protocol-V2 frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "frame", rename_all = "snake_case")]
pub enum Frame {
    MotionCommand(Motion),
    LightCommand(Lights),
    ParkingBrake(ParkingBrake),
    MotionModeCommand(MotionMode),
    VersionRequest,
    SdkVersionRequest,
    Mode(ModeCommand),
    SteeringZero,
    SteeringZeroOffset(SteeringZeroOffset),
    SteeringZeroQuery,
    ClearFault(ClearFault),
    SystemStatus(SystemStatus),
    MotionFeedback(Motion),
    LightState(Lights),
    Rc(RcState),
    MotorFast(MotorFast),
    MotorSlow(MotorSlow),
    SteeringAngles(Four),
    WheelSpeeds(Four),
    MotionModeState(MotionMode),
    Odometer(Odometer),
    Imu(Imu),
    Bumper {
        state: u8,
    },
    Ultrasonic(Ultrasonic),
    Uwb(Uwb),
    BmsData(BmsData),
    BmsAlarm(BmsAlarm),
    BmsProtection(BmsProtection),
    Version(Version),
    VersionText(VersionText),
    /// 0x43A: true = 0xEE (set), false = 0xFF (failed).
    SteeringZeroAck {
        done: bool,
    },
    SteeringZeroOffsetReply(SteeringZeroOffset),
}

/// The name of a 0x141 / 0x291 b0 motion mode under the profile's ⚠ D-12 codes: dual_ackermann,
/// crab, spin, park, side_slip or unknown.
pub fn motion_mode_name(mode: u8, profile: &V2Profile) -> &'static str {
    code_name(mode, &profile.ranger_mode_codes.names())
}

/// The name of the first of `names` whose code (where the profile has one) is `mode`, else
/// "unknown": the order settles a code two names share.
fn code_name(mode: u8, names: &[(Option<u8>, &'static str)]) -> &'static str {
    names
        .iter()
        .find(|(code, _)| *code == Some(mode))
        .map_or("unknown", |(_, name)| *name)
}

fn lateral_sign(profile: &V2Profile) -> f64 {
    if profile.lateral_left_positive {
        1.0
    } else {
        -1.0
    }
}

/// 0x432 / 0x43B b0-1.
fn zero_offset(raw_id: u32, data: &[u8]) -> Result<SteeringZeroOffset, DecodeError> {
    let pulses: I16 = read_prefix(raw_id, data)?;
    Ok(SteeringZeroOffset {
        pulses: pulses.get(),
    })
}

fn decode_motion(raw_id: u32, data: &[u8], profile: &V2Profile) -> Result<Motion, DecodeError> {
    let w: MotionWire = read_prefix(raw_id, data)?;
    Ok(Motion {
        linear_mps: si(w.linear_mm_s.get(), 1000.0),
        angular_radps: si(w.angular_mrad_s.get(), 1000.0),
        lateral_mps: lateral_sign(profile) * si(w.lateral_mm_s.get(), 1000.0),
        steer_rad: si(w.steer.get(), profile.steer_unit.scale()),
    })
}

fn encode_motion(m: &Motion, profile: &V2Profile) -> Result<[u8; 8], EncodeError> {
    let scale = profile.steer_unit.scale();
    Ok(wire_bytes::<8, _>(MotionWire {
        linear_mm_s: to_i16("linear_mps", m.linear_mps, 1000.0)?.into(),
        angular_mrad_s: to_i16("angular_radps", m.angular_radps, 1000.0)?.into(),
        lateral_mm_s: to_i16("lateral_mps", lateral_sign(profile) * m.lateral_mps, 1000.0)?.into(),
        steer: to_i16("steer_rad", m.steer_rad * scale.signum(), scale.abs())?.into(),
    }))
}

/// Light modes: 0 off, 1 on, 2 breathing, 3 custom brightness.
const MAX_LIGHT_MODE: u8 = 3;
const MAX_BRIGHTNESS_PCT: u8 = 100;

fn decode_lights(raw_id: u32, data: &[u8]) -> Result<Lights, DecodeError> {
    let w: LightWire = read_prefix(raw_id, data)?;
    for (field, value, max) in [
        ("front light mode", w.front_mode, MAX_LIGHT_MODE),
        (
            "front brightness",
            w.front_brightness_pct,
            MAX_BRIGHTNESS_PCT,
        ),
        ("rear light mode", w.rear_mode, MAX_LIGHT_MODE),
        ("rear brightness", w.rear_brightness_pct, MAX_BRIGHTNESS_PCT),
    ] {
        if value > max {
            return Err(invalid(raw_id, field, value));
        }
    }
    Ok(Lights {
        enabled: read_bool(raw_id, "light control", w.enabled)?,
        front_mode: w.front_mode,
        front_brightness_pct: w.front_brightness_pct,
        rear_mode: w.rear_mode,
        rear_brightness_pct: w.rear_brightness_pct,
        count: w.count,
    })
}

fn decode_four(raw_id: u32, data: &[u8], scale: f64) -> Result<Four, DecodeError> {
    let w: FourI16Wire = read_prefix(raw_id, data)?;
    Ok(Four {
        values: w.values.map(|v| si(v.get(), scale)),
    })
}

fn encode_four(field: &'static str, f: &Four, scale: f64) -> Result<[u8; 8], EncodeError> {
    let mut values = [I16::new(0); 4];
    for (out, value) in values.iter_mut().zip(f.values) {
        *out = to_i16(field, value * scale.signum(), scale.abs())?.into();
    }
    Ok(wire_bytes::<8, _>(FourI16Wire { values }))
}

/// True when 0x241 b1-2 carry the right stick vertical first (⚠ D-11).
fn sticks_swapped(profile: &V2Profile) -> bool {
    matches!(profile.rc_stick_order, RcStickOrder::Pya)
}

/// Decodes one protocol-V2 frame (either direction).
pub fn decode(frame: &CanFrame, profile: &V2Profile) -> Result<Frame, DecodeError> {
    let raw_id = frame.id();
    let id16 = frame.standard_id()?;
    let data = frame.data();
    let decoded = match id16 {
        id::MOTION_COMMAND => Frame::MotionCommand(decode_motion(raw_id, data, profile)?),
        id::MOTION_FEEDBACK => Frame::MotionFeedback(decode_motion(raw_id, data, profile)?),
        id::LIGHT_COMMAND => Frame::LightCommand(decode_lights(raw_id, data)?),
        id::LIGHT_STATE => Frame::LightState(decode_lights(raw_id, data)?),
        id::PARKING_BRAKE => {
            let b = first_byte(raw_id, data)?;
            let lock = profile.brake_lock_value.unwrap_or(0x01);
            let release = if lock == 0x01 { 0x00 } else { 0x01 };
            if b != lock && b != release {
                return Err(invalid(raw_id, "parking brake", b));
            }
            Frame::ParkingBrake(ParkingBrake { engage: b == lock })
        }
        id::MOTION_MODE => Frame::MotionModeCommand(MotionMode {
            mode: first_byte(raw_id, data)?,
            changing: false,
        }),
        id::MOTION_MODE_STATE => Frame::MotionModeState(MotionMode {
            mode: first_byte(raw_id, data)?,
            changing: data.get(1).is_some_and(|&b| b != 0),
        }),
        id::VERSION_REQUEST => match first_byte(raw_id, data)? {
            0x01 => Frame::VersionRequest,
            other => return Err(invalid(raw_id, "version request", other)),
        },
        id::SDK_VERSION => {
            if data.len() == 1 {
                match data[0] {
                    0x01 => Frame::SdkVersionRequest,
                    other => return Err(invalid(raw_id, "version request", other)),
                }
            } else {
                let bytes: [u8; 8] = read_prefix(raw_id, data)?;
                Frame::VersionText(VersionText { bytes })
            }
        }
        id::MODE => match first_byte(raw_id, data)? {
            0x00 => Frame::Mode(ModeCommand { can: false }),
            0x01 => Frame::Mode(ModeCommand { can: true }),
            other => return Err(invalid(raw_id, "mode", other)),
        },
        id::STEERING_ZERO => {
            let b = first_byte(raw_id, data)?;
            if b != profile.steering_zero_request {
                return Err(invalid(raw_id, "steering zero", b));
            }
            Frame::SteeringZero
        }
        id::STEERING_ZERO_OFFSET => Frame::SteeringZeroOffset(zero_offset(raw_id, data)?),
        id::STEERING_ZERO_QUERY => match first_byte(raw_id, data)? {
            0xAA => Frame::SteeringZeroQuery,
            other => return Err(invalid(raw_id, "steering zero query", other)),
        },
        id::STEERING_ZERO_ACK => match first_byte(raw_id, data)? {
            STEERING_ZERO_DONE => Frame::SteeringZeroAck { done: true },
            STEERING_ZERO_FAILED => Frame::SteeringZeroAck { done: false },
            other => return Err(invalid(raw_id, "steering zero acknowledgement", other)),
        },
        id::STEERING_ZERO_OFFSET_REPLY => {
            Frame::SteeringZeroOffsetReply(zero_offset(raw_id, data)?)
        }
        id::CLEAR_FAULT => Frame::ClearFault(ClearFault {
            code: first_byte(raw_id, data)?,
        }),
        id::SYSTEM_STATUS => {
            let w: SystemStatusWire = read_prefix(raw_id, data)?;
            Frame::SystemStatus(SystemStatus {
                vehicle_state: w.vehicle_state,
                vehicle: vehicle::name(w.vehicle_state),
                mode: w.mode,
                control: code_name(w.mode, &profile.mode_codes.names()),
                battery_voltage_v: si(w.battery_dv.get(), 10.0),
                fault_word: w.fault_word.get(),
                b6: w.b6,
                count: w.count,
            })
        }
        id::RC => Frame::Rc(rc_from_wire(raw_id, data, sticks_swapped(profile))?),
        id::STEERING_ANGLES => {
            Frame::SteeringAngles(decode_four(raw_id, data, profile.steer_unit.scale())?)
        }
        id::WHEEL_SPEEDS => Frame::WheelSpeeds(decode_four(raw_id, data, 1000.0)?),
        id::ODOMETER => {
            let w: OdometerWire = read_prefix(raw_id, data)?;
            Frame::Odometer(Odometer {
                left_m: f64::from(w.left.get()) * profile.odometer_lsb_m,
                right_m: f64::from(w.right.get()) * profile.odometer_lsb_m,
            })
        }
        id::BUMPER => Frame::Bumper {
            state: first_byte(raw_id, data)?,
        },
        id::BMS_DATA => Frame::BmsData(BmsData::from_wire(0, raw_id, data, |v| {
            f64::from(v) * profile.bms_voltage_lsb_v
        })?),
        id::BMS_ALARM => match profile.bms_alarm_layout {
            BmsAlarmLayout::AlarmWarning => Frame::BmsAlarm(BmsAlarm::from_wire(0, raw_id, data)?),
            BmsAlarmLayout::ProtectionCodes => {
                let b: [u8; 8] = read_prefix(raw_id, data)?;
                Frame::BmsProtection(BmsProtection {
                    codes: [b[0], b[1], b[2], b[3]],
                    max_cell_temp_c: i8::from_be_bytes([b[4]]),
                    min_cell_temp_c: i8::from_be_bytes([b[5]]),
                    count: b[7],
                })
            }
        },
        id::VERSION => {
            let [controller_hw, driver_hw, controller_sw, driver_sw] = read_prefix(raw_id, data)?;
            Frame::Version(Version {
                controller_hw,
                driver_hw,
                controller_sw,
                driver_sw,
            })
        }
        other => {
            if let Some(n) = index_in(other, id::MOTOR_FAST_1, 8) {
                let mut m = MotorFast::from_wire(n, raw_id, data)?;
                if !profile.motor_position_valid {
                    m.position_counts = 0;
                }
                Frame::MotorFast(m)
            } else if let Some(n) = index_in(other, id::MOTOR_SLOW_1, 8) {
                Frame::MotorSlow(MotorSlow::from_wire(n, raw_id, data)?)
            } else if let Some(n) = index_in(other, id::IMU_ACCEL, 3) {
                let w: ImuWire = read_prefix(raw_id, data)?;
                Frame::Imu(Imu {
                    kind: n - 1,
                    raw: w.values.map(|v| v.get()),
                    count: w.count,
                })
            } else if let Some(n) = index_in(other, id::ULTRASONIC_1, 8) {
                Frame::Ultrasonic(Ultrasonic {
                    sensor: n,
                    raw: read_prefix(raw_id, data)?,
                })
            } else if let Some(n) = index_in(other, id::UWB_1, 4) {
                let w: UwbWire = read_prefix(raw_id, data)?;
                Frame::Uwb(Uwb {
                    module: n,
                    distance_raw: w.distance.get(),
                    angle_raw: w.angle.get(),
                    valid: w.valid != 0,
                    channels: w.channels,
                })
            } else {
                return Err(DecodeError::UnknownId { id: raw_id });
            }
        }
    };
    Ok(decoded)
}

/// A one-byte command at the profile's ⚠ D-9 DLC (1, or 8 zero-padded).
fn short(id: u16, byte: u8, profile: &V2Profile) -> CanFrame {
    if profile.short_commands_dlc == 1 {
        CanFrame::from_parts(id, [byte])
    } else {
        CanFrame::from_parts(id, [byte, 0, 0, 0, 0, 0, 0, 0])
    }
}

impl Frame {
    /// The frame's CAN id.
    pub fn id(&self) -> u16 {
        match self {
            Frame::MotionCommand(_) => id::MOTION_COMMAND,
            Frame::LightCommand(_) => id::LIGHT_COMMAND,
            Frame::ParkingBrake(_) => id::PARKING_BRAKE,
            Frame::MotionModeCommand(_) => id::MOTION_MODE,
            Frame::VersionRequest => id::VERSION_REQUEST,
            Frame::SdkVersionRequest | Frame::VersionText(_) => id::SDK_VERSION,
            Frame::Mode(_) => id::MODE,
            Frame::SteeringZero => id::STEERING_ZERO,
            Frame::SteeringZeroOffset(_) => id::STEERING_ZERO_OFFSET,
            Frame::SteeringZeroQuery => id::STEERING_ZERO_QUERY,
            Frame::ClearFault(_) => id::CLEAR_FAULT,
            Frame::SystemStatus(_) => id::SYSTEM_STATUS,
            Frame::MotionFeedback(_) => id::MOTION_FEEDBACK,
            Frame::LightState(_) => id::LIGHT_STATE,
            Frame::Rc(_) => id::RC,
            Frame::MotorFast(m) => id::MOTOR_FAST_1 + u16::from(m.motor.clamp(1, 8)) - 1,
            Frame::MotorSlow(m) => id::MOTOR_SLOW_1 + u16::from(m.motor.clamp(1, 8)) - 1,
            Frame::SteeringAngles(_) => id::STEERING_ANGLES,
            Frame::WheelSpeeds(_) => id::WHEEL_SPEEDS,
            Frame::MotionModeState(_) => id::MOTION_MODE_STATE,
            Frame::Odometer(_) => id::ODOMETER,
            Frame::Imu(i) => id::IMU_ACCEL + u16::from(i.kind.min(2)),
            Frame::Bumper { .. } => id::BUMPER,
            Frame::Ultrasonic(u) => id::ULTRASONIC_1 + u16::from(u.sensor.clamp(1, 8)) - 1,
            Frame::Uwb(u) => id::UWB_1 + u16::from(u.module.clamp(1, 4)) - 1,
            Frame::BmsData(_) => id::BMS_DATA,
            Frame::BmsAlarm(_) | Frame::BmsProtection(_) => id::BMS_ALARM,
            Frame::Version(_) => id::VERSION,
            Frame::SteeringZeroAck { .. } => id::STEERING_ZERO_ACK,
            Frame::SteeringZeroOffsetReply(_) => id::STEERING_ZERO_OFFSET_REPLY,
        }
    }

    /// Who sends it.
    pub fn direction(&self) -> Direction {
        match self {
            Frame::MotionCommand(_)
            | Frame::LightCommand(_)
            | Frame::ParkingBrake(_)
            | Frame::MotionModeCommand(_)
            | Frame::VersionRequest
            | Frame::SdkVersionRequest
            | Frame::Mode(_)
            | Frame::SteeringZero
            | Frame::SteeringZeroOffset(_)
            | Frame::SteeringZeroQuery
            | Frame::ClearFault(_) => Direction::ToChassis,
            _ => Direction::FromChassis,
        }
    }

    /// Encodes the frame. Values outside what the wire can carry are an error, never silently
    /// saturated.
    pub fn encode(&self, profile: &V2Profile) -> Result<CanFrame, EncodeError> {
        let id = self.id();
        let frame = match self {
            Frame::MotionCommand(m) | Frame::MotionFeedback(m) => {
                CanFrame::from_parts(id, encode_motion(m, profile)?)
            }
            Frame::LightCommand(l) | Frame::LightState(l) => {
                for (field, v, max) in [
                    (
                        "front_brightness_pct",
                        l.front_brightness_pct,
                        MAX_BRIGHTNESS_PCT,
                    ),
                    (
                        "rear_brightness_pct",
                        l.rear_brightness_pct,
                        MAX_BRIGHTNESS_PCT,
                    ),
                    ("front_mode", l.front_mode, MAX_LIGHT_MODE),
                    ("rear_mode", l.rear_mode, MAX_LIGHT_MODE),
                ] {
                    check_u8(field, v, 0, max)?;
                }
                CanFrame::from_parts(
                    id,
                    wire_bytes::<8, _>(LightWire {
                        enabled: u8::from(l.enabled),
                        front_mode: l.front_mode,
                        front_brightness_pct: l.front_brightness_pct,
                        rear_mode: l.rear_mode,
                        rear_brightness_pct: l.rear_brightness_pct,
                        reserved: [0; 2],
                        count: l.count,
                    }),
                )
            }
            Frame::ParkingBrake(b) => {
                let lock = profile.brake_lock_value.unwrap_or(0x01);
                let release = if lock == 0x01 { 0x00 } else { 0x01 };
                short(id, if b.engage { lock } else { release }, profile)
            }
            Frame::MotionModeCommand(m) => short(id, m.mode, profile),
            Frame::MotionModeState(m) => CanFrame::from_parts(id, [m.mode, u8::from(m.changing)]),
            Frame::VersionRequest | Frame::SdkVersionRequest => CanFrame::from_parts(id, [0x01]),
            Frame::VersionText(t) => CanFrame::from_parts(id, t.bytes),
            Frame::Mode(m) => short(id, u8::from(m.can), profile),
            Frame::SteeringZero => CanFrame::from_parts(id, [profile.steering_zero_request]),
            Frame::SteeringZeroOffset(o) | Frame::SteeringZeroOffsetReply(o) => {
                CanFrame::from_parts(id, o.pulses.to_be_bytes())
            }
            Frame::SteeringZeroQuery => CanFrame::from_parts(id, [0xAA]),
            Frame::ClearFault(c) => short(id, c.code, profile),
            Frame::SystemStatus(s) => CanFrame::from_parts(
                id,
                wire_bytes::<8, _>(SystemStatusWire {
                    vehicle_state: s.vehicle_state,
                    mode: s.mode,
                    battery_dv: to_u16("battery_voltage_v", s.battery_voltage_v, 10.0)?.into(),
                    fault_word: s.fault_word.into(),
                    b6: s.b6,
                    count: s.count,
                }),
            ),
            Frame::Rc(r) => CanFrame::from_parts(id, rc_wire(r, sticks_swapped(profile))?),
            Frame::MotorFast(m) => CanFrame::from_parts(id, m.wire(8)?),
            Frame::MotorSlow(m) => CanFrame::from_parts(id, m.wire(8)?),
            Frame::SteeringAngles(f) => {
                CanFrame::from_parts(id, encode_four("steer_rad", f, profile.steer_unit.scale())?)
            }
            Frame::WheelSpeeds(f) => {
                CanFrame::from_parts(id, encode_four("wheel_speed_mps", f, 1000.0)?)
            }
            Frame::Odometer(o) => {
                let lsb = 1.0 / profile.odometer_lsb_m;
                CanFrame::from_parts(
                    id,
                    wire_bytes::<8, _>(OdometerWire {
                        left: to_i32("left_m", o.left_m, lsb)?.into(),
                        right: to_i32("right_m", o.right_m, lsb)?.into(),
                    }),
                )
            }
            Frame::Imu(i) => {
                check_u8("kind", i.kind, 0, 2)?;
                CanFrame::from_parts(
                    id,
                    wire_bytes::<8, _>(ImuWire {
                        values: i.raw.map(I16::new),
                        reserved: 0,
                        count: i.count,
                    }),
                )
            }
            Frame::Bumper { state } => CanFrame::from_parts(id, [*state, 0, 0, 0, 0, 0, 0, 0]),
            Frame::Ultrasonic(u) => {
                check_u8("sensor", u.sensor, 1, 8)?;
                CanFrame::from_parts(id, u.raw)
            }
            Frame::Uwb(u) => {
                check_u8("module", u.module, 1, 4)?;
                CanFrame::from_parts(
                    id,
                    wire_bytes::<8, _>(UwbWire {
                        distance: u.distance_raw.into(),
                        angle: u.angle_raw.into(),
                        valid: u8::from(u.valid),
                        channels: u.channels,
                    }),
                )
            }
            Frame::BmsData(b) => CanFrame::from_parts(id, b.wire(1.0 / profile.bms_voltage_lsb_v)?),
            Frame::BmsAlarm(b) => CanFrame::from_parts(id, b.alarm_flags().to_le_bytes()),
            Frame::BmsProtection(p) => {
                let [c1, c2, c3, c4] = p.codes;
                let [max, min] = [p.max_cell_temp_c, p.min_cell_temp_c].map(|t| t.to_be_bytes()[0]);
                CanFrame::from_parts(id, [c1, c2, c3, c4, max, min, 0, p.count])
            }
            Frame::Version(v) => CanFrame::from_parts(
                id,
                wire_bytes::<8, _>([v.controller_hw, v.driver_hw, v.controller_sw, v.driver_sw]),
            ),
            Frame::SteeringZeroAck { done } => CanFrame::from_parts(
                id,
                [if *done {
                    STEERING_ZERO_DONE
                } else {
                    STEERING_ZERO_FAILED
                }],
            ),
        };
        Ok(frame)
    }
}
