//! XBot wire codec: every frame of the manual, both directions.
//!
//! RS232, little-endian (LSB first). A frame is `AA 55 | len | payload | checksum`: `len` counts
//! the payload bytes, `payload[0]` is the command id, and the checksum is the XOR of `len` and
//! every payload byte (not of the two header bytes).
//!
//! | id | dir | payload after the id | frame struct (SI, ISO 8855) |
//! | --- | --- | --- | --- |
//! | 0x01 | → | `u8` 0/1 | [`PowerCommand`] |
//! | 0x03 | → | `f32le` vx m/s, vy m/s, yaw rate **°/s** | [`VelocityCommand`] (m/s, rad/s; ⚠ signs) |
//! | 0x04 | → | `u8` enable 0/1, `u8` position 0-100 | [`LiftCommand`] |
//! | 0x05 | → | `u8` pan 0-180, `u8` tilt 0-180 (°, 90 = ahead) | [`ServoCommand`] (rad) |
//! | 0x10 | ← | 70 bytes, see [`SensorReport`] | [`SensorReport`] |
//!
//! Velocity floats are carried through `f64` without re-rounding: a decoded `f32` widens
//! exactly, and re-encoding narrows it back to the same bits, so `encode(decode(bytes)) == bytes`.
//! Where the manual contradicts itself the [`XbotProfile`] decides: the yaw-rate and
//! lateral-speed signs (⚠) and whether currents and ultrasonic ranges are BCD (⚠).

use serde::{Deserialize, Serialize};
use zerocopy::byteorder::little_endian::{F32, I16, U16};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

use crate::Direction;
use crate::error::{DecodeError, EncodeError, to_i16, to_wire};
use crate::wire_layout::{first_byte, invalid, read_bool, read_prefix, si, try_map};
use crate::xbot::XbotProfile;

/// The two bytes that start every frame.
pub const HEADER: [u8; 2] = [0xAA, 0x55];
/// Bytes of a frame around its payload: the header, the length byte and the checksum.
pub const FRAME_OVERHEAD: usize = 4;
/// The longest frame the format can carry (a 255-byte payload).
pub const MAX_FRAME_LEN: usize = FRAME_OVERHEAD + u8::MAX as usize;

/// Command ids (`payload[0]`).
pub mod id {
    /// → power enable.
    pub const POWER: u8 = 0x01;
    /// → velocity; also the heartbeat (more than 5 Hz, less than 10 Hz; timeout 500 ms).
    pub const VELOCITY: u8 = 0x03;
    /// → lift platform.
    pub const LIFT: u8 = 0x04;
    /// → pan ("cloud") and camera tilt servos.
    pub const SERVOS: u8 = 0x05;
    /// ← sensor report.
    pub const SENSOR: u8 = 0x10;
}

/// Scales of the sensor report (manual notes 6-8).
pub mod scale {
    /// Accelerometer, g per LSB (±2 g).
    pub const ACCEL_G_PER_LSB: f64 = 0.000_060_86;
    /// Standard gravity, m/s² per g.
    pub const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;
    /// Gyroscope, °/s per LSB (±500 °/s).
    pub const GYRO_DEG_S_PER_LSB: f64 = 0.015_213_984_694_731_4;
    /// Magnetometer, gauss per LSB.
    pub const MAG_GAUSS_PER_LSB: f64 = 0.000_429_687_5;
}

const ACCEL_MPS2_PER_LSB: f64 = scale::ACCEL_G_PER_LSB * scale::STANDARD_GRAVITY_MPS2;
const GYRO_RADPS_PER_LSB: f64 = scale::GYRO_DEG_S_PER_LSB * std::f64::consts::PI / 180.0;

/// The fixed marker bytes of the sensor report: (payload offset, value, field name).
pub const SENSOR_MARKERS: [(usize, u8, &str); 6] = [
    (1, 0x01, "marker at payload offset 1"),
    (4, 0x03, "marker at payload offset 4"),
    (11, 0x05, "marker at payload offset 11"),
    (22, 0x03, "marker at payload offset 22"),
    (29, 0x05, "marker at payload offset 29"),
    (40, 0x01, "marker at payload offset 40"),
];

/// Payload length (command id included) of each command, `None` for an id the manual does not
/// define.
pub fn payload_len(command: u8) -> Option<usize> {
    match command {
        id::POWER => Some(size_of::<PowerWire>()),
        id::VELOCITY => Some(size_of::<VelocityWire>()),
        id::LIFT => Some(size_of::<LiftWire>()),
        id::SERVOS => Some(size_of::<ServoWire>()),
        id::SENSOR => Some(size_of::<SensorWire>()),
        _ => None,
    }
}

/// The frame checksum: XOR of the length byte and every payload byte.
pub fn checksum(len: u8, payload: &[u8]) -> u8 {
    payload.iter().fold(len, |acc, b| acc ^ b)
}

/// Wraps a payload (command id first) into a whole frame: header, length, payload, checksum.
/// `None` when the payload is empty or longer than 255 bytes. For tests and fault injection;
/// [`Frame::encode`] is the normal way to build a frame.
pub fn wrap_payload(payload: &[u8]) -> Option<Vec<u8>> {
    let len = u8::try_from(payload.len()).ok().filter(|&l| l > 0)?;
    Some(frame_bytes(len, payload))
}

/// Header, `len`, payload, checksum.
fn frame_bytes(len: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + FRAME_OVERHEAD);
    out.extend_from_slice(&HEADER);
    out.push(len);
    out.extend_from_slice(payload);
    out.push(checksum(len, payload));
    out
}

// ---------------------------------------------------------------------------------------------
// Wire layouts (little-endian), each starting with the command id: the layout is the payload.

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct PowerWire {
    id: u8,
    enable: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct VelocityWire {
    id: u8,
    vx_mps: F32,
    vy_mps: F32,
    yaw_rate_deg_s: F32,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct LiftWire {
    id: u8,
    enable: u8,
    position_pct: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct ServoWire {
    id: u8,
    pan_deg: u8,
    tilt_deg: u8,
}

#[repr(C)]
#[derive(FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
struct SensorWire {
    id: u8,
    marker_1: u8,
    /// BCD, 0.01 V.
    battery_bcd: U16,
    marker_4: u8,
    /// Rear-left, rear-centre, rear-right, 0.1 cm.
    ir: [U16; 3],
    marker_11: u8,
    /// Front-left, front-right, rear-left, rear-right, 0.1 A (⚠ BCD per profile).
    motor_current: [U16; 4],
    lift_current: U16,
    marker_22: u8,
    /// Front-left, front-centre, front-right, 0.1 cm (⚠ BCD per profile).
    ultrasonic: [U16; 3],
    marker_29: u8,
    /// Front-left, front-right, BACK-RIGHT, BACK-LEFT (this order on the wire).
    encoder: [U16; 4],
    lift_encoder: U16,
    marker_40: u8,
    accel: [I16; 3],
    gyro: [I16; 3],
    mag: [I16; 3],
    temperature_c: F32,
    /// 0.1°.
    yaw: I16,
    pitch: I16,
    roll: I16,
    stamp_us: U16,
}

// Sizes pinned to the manual (payload lengths, command id included).
const _: () = assert!(size_of::<PowerWire>() == 2);
const _: () = assert!(size_of::<VelocityWire>() == 13);
const _: () = assert!(size_of::<LiftWire>() == 3);
const _: () = assert!(size_of::<ServoWire>() == 3);
const _: () = assert!(size_of::<SensorWire>() == 71);

// ---------------------------------------------------------------------------------------------
// Frames.

/// 0x01: power the drive on or off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct PowerCommand {
    pub enable: bool,
}

/// 0x03: body velocity; doubles as the heartbeat.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct VelocityCommand {
    /// Forward speed, m/s (wire: `f32` m/s).
    pub linear_x_mps: f64,
    /// Lateral speed, m/s, left positive (wire: `f32` m/s, ⚠ sign per
    /// `XbotProfile::lateral_left_positive`; ignored by two-wheel robots).
    pub linear_y_mps: f64,
    /// Yaw rate, rad/s, left turn positive (wire: `f32` **°/s**, ⚠ sign per
    /// `XbotProfile::yaw_rate_left_positive`).
    pub angular_z_radps: f64,
}

/// 0x04: lift platform.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LiftCommand {
    pub enable: bool,
    /// Target position, % of travel: 0 bottom, 100 top (wire: whole percent).
    pub position_pct: f64,
}

/// 0x05: pan ("cloud") and camera tilt servos.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ServoCommand {
    /// Pan, rad: 0 ahead, left positive, ±π/2 (wire: 0° = left, 90° = ahead, 180° = right,
    /// whole degrees).
    pub pan_rad: f64,
    /// Camera tilt, rad: 0 ahead, up positive, ±π/2 (wire: 0° = floor, 90° = ahead,
    /// 180° = up, whole degrees).
    pub tilt_rad: f64,
}

/// 0x10: the sensor report.
///
/// Arrays of four wheels are in the project's order front-left, front-right, rear-left,
/// rear-right; the codec re-orders the encoders, which the wire sends as front-left, front-right,
/// **back-right, back-left**. Two-wheel robots report 0 for the rear wheels. IMU values are in the
/// sensor's own axes, as sent.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SensorReport {
    /// V (wire: BCD, 0x2596 = 25.96 V).
    pub battery_voltage_v: f64,
    /// IR ranges rear-left, rear-centre, rear-right, m (wire: 0.1 cm).
    pub ir_m: [f64; 3],
    /// Ultrasonic ranges front-left, front-centre, front-right, m (wire: 0.1 cm; ⚠ BCD per
    /// profile).
    pub ultrasonic_m: [f64; 3],
    /// Drive motor currents front-left, front-right, rear-left, rear-right, A (wire: 0.1 A;
    /// ⚠ BCD per profile).
    pub motor_current_a: [f64; 4],
    /// Lift motor current, A (wire: 0.1 A; ⚠ BCD per profile).
    pub lift_current_a: f64,
    /// Wheel encoders front-left, front-right, rear-left, rear-right (re-ordered from the wire),
    /// counts, wrapping at 65536.
    pub encoder_counts: [u16; 4],
    /// Lift encoder, counts, wrapping at 65536.
    pub lift_encoder_counts: u16,
    /// Accelerometer x, y, z, m/s² (wire: 0.00006086 g).
    pub accel_mps2: [f64; 3],
    /// Gyroscope x, y, z, rad/s (wire: 0.0152139846947314 °/s).
    pub gyro_radps: [f64; 3],
    /// Magnetometer x, y, z, gauss (wire: 0.0004296875 gauss).
    pub mag_gauss: [f64; 3],
    /// IMU temperature, °C (wire: `f32`, passed through as sent, even NaN).
    pub temperature_c: f64,
    /// rad (wire: 0.1°).
    pub roll_rad: f64,
    /// rad (wire: 0.1°).
    pub pitch_rad: f64,
    /// rad (wire: 0.1°).
    pub yaw_rad: f64,
    /// The board's timestamp, µs, wrapping at 65536.
    pub sensor_stamp_us: u16,
}

/// Every XBot frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "frame", rename_all = "snake_case")]
pub enum Frame {
    Power(PowerCommand),
    Velocity(VelocityCommand),
    Lift(LiftCommand),
    Servos(ServoCommand),
    Sensor(SensorReport),
}

// ---------------------------------------------------------------------------------------------
// Decoding.

/// ⚠ Applies a profile sign choice: negates `value` unless `left_positive`. Zero keeps its sign
/// bit, so an ISO `0.0` goes on the wire as `0.0` (not `-0.0`), as in the manual's examples, and
/// every wire value round-trips bit for bit.
fn signed(left_positive: bool, value: f64) -> f64 {
    if left_positive || value == 0.0 {
        value
    } else {
        -value
    }
}

/// A velocity float: finite, widened exactly.
fn finite_f32(id: u32, field: &'static str, raw: F32) -> Result<f64, DecodeError> {
    let value = raw.get();
    if value.is_finite() {
        Ok(value.into())
    } else {
        Err(invalid(id, field, value.to_bits()))
    }
}

/// Four BCD digits → 0..=9999.
fn from_bcd(id: u32, field: &'static str, raw: u16) -> Result<u16, DecodeError> {
    let mut value = 0u16;
    for shift in [12, 8, 4, 0] {
        let digit = (raw >> shift) & 0xF;
        if digit > 9 {
            return Err(invalid(id, field, raw));
        }
        value = value * 10 + digit;
    }
    Ok(value)
}

/// 0..=9999 → four BCD digits (callers check the range).
fn to_bcd(value: u16) -> u16 {
    let mut out = 0u16;
    let mut rest = value;
    for shift in [0, 4, 8, 12] {
        out |= (rest % 10) << shift;
        rest /= 10;
    }
    out
}

fn servo_from_wire(id: u32, field: &'static str, deg: u8) -> Result<f64, DecodeError> {
    if deg > 180 {
        return Err(invalid(id, field, deg));
    }
    Ok(f64::from(deg))
}

/// Decodes one payload (command id and data; without header, length byte and checksum).
pub fn decode_payload(payload: &[u8], profile: &XbotProfile) -> Result<Frame, DecodeError> {
    let command = first_byte(0, payload)?;
    let cid = u32::from(command);
    let expected = payload_len(command).ok_or(DecodeError::UnknownId { id: cid })?;
    if payload.len() != expected {
        return Err(DecodeError::BadLength {
            command,
            len: payload.len(),
            expected,
        });
    }
    let frame = match command {
        id::POWER => {
            let w: PowerWire = read_prefix(cid, payload)?;
            Frame::Power(PowerCommand {
                enable: read_bool(cid, "power enable", w.enable)?,
            })
        }
        id::VELOCITY => {
            let w: VelocityWire = read_prefix(cid, payload)?;
            let yaw_deg_s = finite_f32(cid, "yaw rate", w.yaw_rate_deg_s)?;
            Frame::Velocity(VelocityCommand {
                linear_x_mps: finite_f32(cid, "vx", w.vx_mps)?,
                linear_y_mps: signed(
                    profile.lateral_left_positive,
                    finite_f32(cid, "vy", w.vy_mps)?,
                ),
                angular_z_radps: signed(profile.yaw_rate_left_positive, yaw_deg_s.to_radians()),
            })
        }
        id::LIFT => {
            let w: LiftWire = read_prefix(cid, payload)?;
            if w.position_pct > 100 {
                return Err(invalid(cid, "lift position", w.position_pct));
            }
            Frame::Lift(LiftCommand {
                enable: read_bool(cid, "lift enable", w.enable)?,
                position_pct: w.position_pct.into(),
            })
        }
        id::SERVOS => {
            let w: ServoWire = read_prefix(cid, payload)?;
            let pan = servo_from_wire(cid, "pan", w.pan_deg)?;
            let tilt = servo_from_wire(cid, "tilt", w.tilt_deg)?;
            Frame::Servos(ServoCommand {
                pan_rad: (90.0 - pan).to_radians(),
                tilt_rad: (tilt - 90.0).to_radians(),
            })
        }
        id::SENSOR => Frame::Sensor(decode_sensor(payload, profile)?),
        _ => return Err(DecodeError::UnknownId { id: cid }),
    };
    Ok(frame)
}

/// The first wrong fixed marker among the sensor-report bytes present in `payload` (which may be
/// a prefix of the payload: the stream parser rejects a false start early with it).
pub(crate) fn check_sensor_markers(payload: &[u8]) -> Result<(), DecodeError> {
    for (offset, value, field) in SENSOR_MARKERS {
        match payload.get(offset) {
            Some(&got) if got != value => return Err(invalid(id::SENSOR.into(), field, got)),
            _ => {}
        }
    }
    Ok(())
}

fn decode_sensor(payload: &[u8], profile: &XbotProfile) -> Result<SensorReport, DecodeError> {
    let cid = u32::from(id::SENSOR);
    check_sensor_markers(payload)?;
    let w: SensorWire = read_prefix(cid, payload)?;
    let bcd = profile.bcd_currents_and_ranges;
    let maybe_bcd = |field: &'static str, raw: U16| {
        if bcd {
            from_bcd(cid, field, raw.get())
        } else {
            Ok(raw.get())
        }
    };
    let amps = |raw: U16| maybe_bcd("motor current", raw).map(|v| si(v, 10.0));
    let sonar = |raw: U16| maybe_bcd("ultrasonic range", raw).map(|v| si(v, 1000.0));
    let [fl, fr, br, bl] = w.encoder.map(|e| e.get());
    let angle = |raw: I16| (f64::from(raw.get()) / 10.0).to_radians();
    Ok(SensorReport {
        battery_voltage_v: si(
            from_bcd(cid, "battery voltage", w.battery_bcd.get())?,
            100.0,
        ),
        ir_m: w.ir.map(|r| si(r.get(), 1000.0)),
        ultrasonic_m: try_map(w.ultrasonic, sonar)?,
        motor_current_a: try_map(w.motor_current, amps)?,
        lift_current_a: maybe_bcd("lift current", w.lift_current).map(|v| si(v, 10.0))?,
        encoder_counts: [fl, fr, bl, br],
        lift_encoder_counts: w.lift_encoder.get(),
        accel_mps2: w.accel.map(|a| f64::from(a.get()) * ACCEL_MPS2_PER_LSB),
        gyro_radps: w.gyro.map(|g| f64::from(g.get()) * GYRO_RADPS_PER_LSB),
        mag_gauss: w.mag.map(|m| f64::from(m.get()) * scale::MAG_GAUSS_PER_LSB),
        temperature_c: w.temperature_c.get().into(),
        roll_rad: angle(w.roll),
        pitch_rad: angle(w.pitch),
        yaw_rad: angle(w.yaw),
        sensor_stamp_us: w.stamp_us.get(),
    })
}

// ---------------------------------------------------------------------------------------------
// Encoding.

/// `value` (SI, for the error message) sent as the `f32` `wire`: must be finite after narrowing.
fn to_f32(field: &'static str, value: f64, wire: f64) -> Result<F32, EncodeError> {
    // Narrowing rounds to nearest; a value beyond f32's range becomes ±inf and is refused.
    let narrowed = wire as f32;
    if narrowed.is_finite() {
        Ok(F32::new(narrowed))
    } else {
        Err(EncodeError::OutOfRange {
            field,
            value,
            min: f32::MIN.into(),
            max: f32::MAX.into(),
        })
    }
}

/// A servo angle to whole wire degrees 0..=180.
fn servo_to_wire(field: &'static str, rad: f64, wire_deg: f64) -> Result<u8, EncodeError> {
    let deg = wire_deg.round();
    if deg.is_finite() && (0.0..=180.0).contains(&deg) {
        // In 0..=180 and integral: the cast is exact.
        Ok(deg as u8)
    } else {
        Err(EncodeError::OutOfRange {
            field,
            value: rad,
            min: -std::f64::consts::FRAC_PI_2,
            max: std::f64::consts::FRAC_PI_2,
        })
    }
}

/// A `u16` field, BCD when `bcd` (then 0..=9999 wire units).
fn to_u16_maybe_bcd(
    field: &'static str,
    value: f64,
    scale: f64,
    bcd: bool,
) -> Result<U16, EncodeError> {
    let max = if bcd { 9999 } else { u16::MAX.into() };
    // Range-checked against u16 (or 9999): the cast is exact.
    let raw = to_wire(field, value, scale, 0, max)? as u16;
    Ok(U16::new(if bcd { to_bcd(raw) } else { raw }))
}

fn encode_sensor(s: &SensorReport, profile: &XbotProfile) -> Result<SensorWire, EncodeError> {
    let bcd = profile.bcd_currents_and_ranges;
    let volts = to_wire("battery_voltage_v", s.battery_voltage_v, 100.0, 0, 9999)?;
    let ir = |v: f64| to_u16_maybe_bcd("ir_m", v, 1000.0, false);
    let sonar = |v: f64| to_u16_maybe_bcd("ultrasonic_m", v, 1000.0, bcd);
    let amps = |v: f64| to_u16_maybe_bcd("motor_current_a", v, 10.0, bcd);
    let i16_of = |field, v: f64, per_lsb: f64| to_i16(field, v, 1.0 / per_lsb).map(I16::new);
    let accel = |v| i16_of("accel_mps2", v, ACCEL_MPS2_PER_LSB);
    let gyro = |v| i16_of("gyro_radps", v, GYRO_RADPS_PER_LSB);
    let mag = |v| i16_of("mag_gauss", v, scale::MAG_GAUSS_PER_LSB);
    let angle = |field, rad: f64| to_i16(field, rad.to_degrees(), 10.0).map(I16::new);
    // Temperature is passed through like the decoder does, NaN included; a finite value must fit.
    let temperature = if s.temperature_c.is_finite() {
        to_f32("temperature_c", s.temperature_c, s.temperature_c)?
    } else {
        F32::new(s.temperature_c as f32)
    };
    let [fl, fr, rl, rr] = s.encoder_counts;
    Ok(SensorWire {
        id: id::SENSOR,
        marker_1: SENSOR_MARKERS[0].1,
        // 0..=9999: the cast is exact.
        battery_bcd: U16::new(to_bcd(volts as u16)),
        marker_4: SENSOR_MARKERS[1].1,
        ir: try_map(s.ir_m, ir)?,
        marker_11: SENSOR_MARKERS[2].1,
        motor_current: try_map(s.motor_current_a, amps)?,
        lift_current: to_u16_maybe_bcd("lift_current_a", s.lift_current_a, 10.0, bcd)?,
        marker_22: SENSOR_MARKERS[3].1,
        ultrasonic: try_map(s.ultrasonic_m, sonar)?,
        marker_29: SENSOR_MARKERS[4].1,
        encoder: [fl, fr, rr, rl].map(U16::new),
        lift_encoder: U16::new(s.lift_encoder_counts),
        marker_40: SENSOR_MARKERS[5].1,
        accel: try_map(s.accel_mps2, accel)?,
        gyro: try_map(s.gyro_radps, gyro)?,
        mag: try_map(s.mag_gauss, mag)?,
        temperature_c: temperature,
        yaw: angle("yaw_rad", s.yaw_rad)?,
        pitch: angle("pitch_rad", s.pitch_rad)?,
        roll: angle("roll_rad", s.roll_rad)?,
        stamp_us: U16::new(s.sensor_stamp_us),
    })
}

impl Frame {
    /// The frame's command id (`payload[0]`).
    pub fn command_id(&self) -> u8 {
        match self {
            Frame::Power(_) => id::POWER,
            Frame::Velocity(_) => id::VELOCITY,
            Frame::Lift(_) => id::LIFT,
            Frame::Servos(_) => id::SERVOS,
            Frame::Sensor(_) => id::SENSOR,
        }
    }

    /// Who sends it.
    pub fn direction(&self) -> Direction {
        match self {
            Frame::Sensor(_) => Direction::FromChassis,
            _ => Direction::ToChassis,
        }
    }

    /// Encodes the whole frame: `AA 55`, length, payload, checksum. Values outside what the wire
    /// can carry are an error, never silently saturated; servo angles and the lift position are
    /// rounded to whole degrees and percent.
    pub fn encode(&self, profile: &XbotProfile) -> Result<Vec<u8>, EncodeError> {
        let payload = match self {
            Frame::Power(p) => PowerWire {
                id: id::POWER,
                enable: p.enable.into(),
            }
            .as_bytes()
            .to_vec(),
            Frame::Velocity(v) => {
                let vy = signed(profile.lateral_left_positive, v.linear_y_mps);
                let yaw = signed(
                    profile.yaw_rate_left_positive,
                    v.angular_z_radps.to_degrees(),
                );
                VelocityWire {
                    id: id::VELOCITY,
                    vx_mps: to_f32("linear_x_mps", v.linear_x_mps, v.linear_x_mps)?,
                    vy_mps: to_f32("linear_y_mps", v.linear_y_mps, vy)?,
                    yaw_rate_deg_s: to_f32("angular_z_radps", v.angular_z_radps, yaw)?,
                }
                .as_bytes()
                .to_vec()
            }
            Frame::Lift(l) => LiftWire {
                id: id::LIFT,
                enable: l.enable.into(),
                // 0..=100: the cast is exact.
                position_pct: to_wire("position_pct", l.position_pct, 1.0, 0, 100)? as u8,
            }
            .as_bytes()
            .to_vec(),
            Frame::Servos(s) => ServoWire {
                id: id::SERVOS,
                pan_deg: servo_to_wire("pan_rad", s.pan_rad, 90.0 - s.pan_rad.to_degrees())?,
                tilt_deg: servo_to_wire("tilt_rad", s.tilt_rad, 90.0 + s.tilt_rad.to_degrees())?,
            }
            .as_bytes()
            .to_vec(),
            Frame::Sensor(s) => encode_sensor(s, profile)?.as_bytes().to_vec(),
        };
        // Every payload is 2..=71 bytes: the cast is exact.
        Ok(frame_bytes(payload.len() as u8, &payload))
    }
}
