//! Typed errors of the codecs. No input makes a codec panic; every bad input is one of these.

use thiserror::Error;

/// Why received bytes are not a valid frame.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// The id is not one this robot's protocol defines.
    #[error("unknown frame id 0x{id:03X}")]
    UnknownId { id: u32 },
    /// Fewer data bytes than the frame's layout needs.
    #[error("frame 0x{id:03X} too short: {len} bytes, need {need}")]
    TooShort { id: u32, len: usize, need: usize },
    /// The checksum byte does not match the frame's contents (SCOUT MINI, XBot).
    #[error("bad checksum, expected 0x{expected:02X}, got 0x{got:02X}")]
    BadChecksum { expected: u8, got: u8 },
    /// A field holds a value the protocol does not define.
    #[error("frame 0x{id:03X}: {field} has undefined value 0x{value:02X}")]
    InvalidValue {
        id: u32,
        field: &'static str,
        value: u32,
    },
    /// The robot's protocol uses only standard (11-bit) ids.
    #[error("extended id 0x{id:08X}: this protocol uses standard 11-bit ids only")]
    ExtendedId { id: u32 },
    /// A serial frame's length byte does not fit its command (XBot).
    #[error("command 0x{command:02X}: length byte {len} does not match the expected {expected}")]
    BadLength {
        command: u8,
        len: usize,
        expected: usize,
    },
    /// An NMEA sentence that cannot be used (syntax, checksum, unsupported type).
    #[error("NMEA: {reason}")]
    Nmea { reason: String },
}

/// Why a frame cannot be encoded: a value does not fit the wire field.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EncodeError {
    #[error("{field} = {value} cannot be sent: the wire allows {min} to {max}")]
    OutOfRange {
        field: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// Scales an SI value to an integer wire field: `round(value * scale)`, where `scale` is wire
/// units per SI unit (1000 for mm/s from m/s), checked against the field's range (`min..=max`,
/// in wire units). NaN and ±inf are out of range.
pub(crate) fn to_wire(
    field: &'static str,
    value: f64,
    scale: f64,
    min: i64,
    max: i64,
) -> Result<i64, EncodeError> {
    let scaled = (value * scale).round();
    if scaled.is_finite() && scaled >= min as f64 && scaled <= max as f64 {
        // In range and integral: the cast is exact.
        Ok(scaled as i64)
    } else {
        Err(EncodeError::OutOfRange {
            field,
            value,
            min: min as f64 / scale,
            max: max as f64 / scale,
        })
    }
}

// The narrowing casts below are exact: `to_wire` checked the value against the type's bounds.

/// [`to_wire`] for an `i8` field.
pub(crate) fn to_i8(field: &'static str, value: f64, scale: f64) -> Result<i8, EncodeError> {
    to_wire(field, value, scale, i8::MIN.into(), i8::MAX.into()).map(|v| v as i8)
}

/// [`to_wire`] for a `u8` field.
pub(crate) fn to_u8(field: &'static str, value: f64, scale: f64) -> Result<u8, EncodeError> {
    to_wire(field, value, scale, 0, u8::MAX.into()).map(|v| v as u8)
}

/// [`to_wire`] for an `i16` field.
pub(crate) fn to_i16(field: &'static str, value: f64, scale: f64) -> Result<i16, EncodeError> {
    to_wire(field, value, scale, i16::MIN.into(), i16::MAX.into()).map(|v| v as i16)
}

/// [`to_wire`] for a `u16` field.
pub(crate) fn to_u16(field: &'static str, value: f64, scale: f64) -> Result<u16, EncodeError> {
    to_wire(field, value, scale, 0, u16::MAX.into()).map(|v| v as u16)
}

/// [`to_wire`] for an `i32` field.
pub(crate) fn to_i32(field: &'static str, value: f64, scale: f64) -> Result<i32, EncodeError> {
    to_wire(field, value, scale, i32::MIN.into(), i32::MAX.into()).map(|v| v as i32)
}

/// Checks that a value fits `min..=max` (for fields sent as they are, such as percentages).
/// Checks a byte-sized field against `min..=max`.
pub(crate) fn check_u8(
    field: &'static str,
    value: u8,
    min: u8,
    max: u8,
) -> Result<(), EncodeError> {
    check_range(field, value.into(), min.into(), max.into())
}

pub(crate) fn check_range(
    field: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<(), EncodeError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(())
    } else {
        Err(EncodeError::OutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_scaling_rounds_to_nearest() {
        assert_eq!(to_i16("v", 0.15, 1000.0), Ok(150));
        assert_eq!(to_i16("v", -0.1504, 1000.0), Ok(-150));
        assert_eq!(to_u16("v", 25.96, 10.0), Ok(260));
        assert_eq!(to_i32("d", -2.5, 1000.0), Ok(-2500));
    }

    #[test]
    fn wire_scaling_rejects_out_of_range_and_non_finite() {
        assert!(to_i16("v", 40.0, 1000.0).is_err());
        assert!(to_i16("v", f64::NAN, 1000.0).is_err());
        assert!(to_i16("v", f64::INFINITY, 1000.0).is_err());
        assert!(to_u16("v", -0.1, 10.0).is_err());
        assert!(to_u8("b", 256.0, 1.0).is_err());
        assert!(check_range("pct", 101.0, 0.0, 100.0).is_err());
        assert!(check_range("pct", 100.0, 0.0, 100.0).is_ok());
        let err = to_i8("pct", 200.0, 1.0).unwrap_err();
        assert_eq!(
            err.to_string(),
            "pct = 200 cannot be sent: the wire allows -128 to 127"
        );
    }

    #[test]
    fn decode_errors_read_well() {
        let e = DecodeError::BadChecksum {
            expected: 0x44,
            got: 0x45,
        };
        assert_eq!(e.to_string(), "bad checksum, expected 0x44, got 0x45");
    }
}
