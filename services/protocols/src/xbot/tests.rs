//! XBot codec and stream tests: every example frame of the manual, hand-built frames, the stream
//! parser's resynchronisation rules, and property tests.

use std::f64::consts::{FRAC_PI_2, PI};

use proptest::prelude::*;

use super::*;
use crate::frame_json::frame_name;
use crate::xbot::XbotProfile;
use crate::xbot::test_support::{hex, p};
use crate::{DecodeError, Direction, EncodeError};

/// Decodes a whole frame (header, length and checksum checked) with `profile`.
fn decode_frame(bytes: &[u8], profile: &XbotProfile) -> Result<Frame, DecodeError> {
    assert_eq!(&bytes[..2], &HEADER);
    let len = bytes[2];
    assert_eq!(usize::from(len) + FRAME_OVERHEAD, bytes.len());
    let payload = &bytes[3..bytes.len() - 1];
    let got = bytes[bytes.len() - 1];
    let expected = checksum(len, payload);
    if got != expected {
        return Err(DecodeError::BadChecksum { expected, got });
    }
    decode_payload(payload, profile)
}

/// Decodes a manual example and checks it encodes back byte for byte.
fn round_trip_with(text: &str, profile: &XbotProfile) -> Frame {
    let bytes = hex(text);
    let frame = decode_frame(&bytes, profile).unwrap();
    assert_eq!(frame.encode(profile).unwrap(), bytes, "re-encoding {text}");
    frame
}

fn round_trip(text: &str) -> Frame {
    round_trip_with(text, &p())
}

/// The velocity command of a manual example, round-tripped.
fn velocity_with(text: &str, profile: &XbotProfile) -> VelocityCommand {
    let Frame::Velocity(v) = round_trip_with(text, profile) else {
        panic!("{text}: not a velocity command")
    };
    v
}

fn velocity(text: &str) -> VelocityCommand {
    velocity_with(text, &p())
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-12
}

const SENSOR_EXAMPLE: &str = concat!(
    "AA 55 47 10 01 62 26 03 02 00 01 00 00 00 05 0A 00 06 00 00 00 00 00 06 00 ",
    "03 00 00 00 00 00 00 05 00 00 00 00 00 00 00 00 E8 03 01 00 00 00 00 00 00 ",
    "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 02 DC 2F",
);

/// A valid sensor payload (command id first) with every field zero.
fn zero_sensor_payload() -> Vec<u8> {
    let mut payload = vec![0u8; 71];
    payload[0] = id::SENSOR;
    for (offset, value, _) in SENSOR_MARKERS {
        payload[offset] = value;
    }
    payload
}

fn put_u16(payload: &mut [u8], offset: usize, value: u16) {
    payload[offset..offset + 2].copy_from_slice(&value.to_le_bytes());
}

// ---------------------------------------------------------------------------------------------
// The manual's examples.

#[test]
fn manual_power_examples_decode_and_encode_byte_for_byte() {
    assert_eq!(
        round_trip("AA 55 02 01 01 02"),
        Frame::Power(PowerCommand { enable: true })
    );
    assert_eq!(
        round_trip("AA 55 02 01 00 03"),
        Frame::Power(PowerCommand { enable: false })
    );
}

#[test]
fn manual_forward_and_backward_examples_carry_the_f32_nearest_to_0_2() {
    let v = velocity("AA 55 0D 03 CD CC 4C 3E 00 00 00 00 00 00 00 00 7D");
    // 0x3E4CCCCD is the f32 nearest 0.2; it widens to f64 exactly, without re-rounding.
    assert_eq!(v.linear_x_mps, f64::from(0.2f32));
    assert!((v.linear_x_mps - 0.2).abs() < 1e-8);
    assert_eq!((v.linear_y_mps, v.angular_z_radps), (0.0, 0.0));
    let v = velocity("AA 55 0D 03 CD CC 4C BE 00 00 00 00 00 00 00 00 FD");
    assert_eq!(v.linear_x_mps, -f64::from(0.2f32));
}

#[test]
fn a_velocity_of_exactly_0_2_encodes_to_the_manual_bytes() {
    let cmd = Frame::Velocity(VelocityCommand {
        linear_x_mps: 0.2,
        ..VelocityCommand::default()
    });
    assert_eq!(
        cmd.encode(&p()).unwrap(),
        hex("AA 55 0D 03 CD CC 4C 3E 00 00 00 00 00 00 00 00 7D")
    );
}

#[test]
fn manual_lateral_examples_are_0_2_m_s_and_wire_positive_means_right_by_default() {
    // The manual labels these "right/left 0.3 m/s" but prints the bytes of 0.2 m/s.
    let right = "AA 55 0D 03 00 00 00 00 CD CC 4C 3E 00 00 00 00 7D";
    let left = "AA 55 0D 03 00 00 00 00 CD CC 4C BE 00 00 00 00 FD";
    let v = velocity(right);
    assert_eq!(v.linear_y_mps, -f64::from(0.2f32), "ISO: right is negative");
    let v = velocity(left);
    assert_eq!(v.linear_y_mps, f64::from(0.2f32));
    let flipped = XbotProfile {
        lateral_left_positive: true,
        ..p()
    };
    let v = velocity_with(right, &flipped);
    assert_eq!(v.linear_y_mps, f64::from(0.2f32));
}

#[test]
fn manual_yaw_examples_follow_note_1_by_default_and_the_labels_when_flipped() {
    // +20 °/s, labelled "turn right" by the examples; note 1 says positive is left.
    let plus_20 = "AA 55 0D 03 00 00 00 00 00 00 00 00 00 00 A0 41 EF";
    let minus_20 = "AA 55 0D 03 00 00 00 00 00 00 00 00 00 00 A0 C1 6F";
    let v = velocity(plus_20);
    assert!(close(v.angular_z_radps, 20f64.to_radians()));
    let v = velocity(minus_20);
    assert!(close(v.angular_z_radps, -20f64.to_radians()));
    let labels = XbotProfile {
        yaw_rate_left_positive: false,
        ..p()
    };
    let v = velocity_with(plus_20, &labels);
    assert!(close(v.angular_z_radps, -20f64.to_radians()));
}

#[test]
fn manual_lift_examples_decode_and_encode_byte_for_byte() {
    for (text, position_pct) in [
        ("AA 55 03 04 01 00 06", 0.0),
        ("AA 55 03 04 01 64 62", 100.0),
        ("AA 55 03 04 01 0A 0C", 10.0),
    ] {
        assert_eq!(
            round_trip(text),
            Frame::Lift(LiftCommand {
                enable: true,
                position_pct
            }),
            "{text}"
        );
    }
}

#[test]
fn manual_servo_examples_map_to_iso_angles() {
    // pan 0 = left = +π/2, tilt 90 = ahead = 0.
    let Frame::Servos(s) = round_trip("AA 55 03 05 00 5A 5C") else {
        panic!()
    };
    assert!(
        close(s.pan_rad, FRAC_PI_2) && close(s.tilt_rad, 0.0),
        "{s:?}"
    );
    // pan 90 = ahead, tilt 0 = floor = -π/2.
    let Frame::Servos(s) = round_trip("AA 55 03 05 5A 00 5C") else {
        panic!()
    };
    assert!(
        close(s.pan_rad, 0.0) && close(s.tilt_rad, -FRAC_PI_2),
        "{s:?}"
    );
    // pan 180 = right = -π/2, tilt 180 = up = +π/2.
    let Frame::Servos(s) = round_trip("AA 55 03 05 B4 B4 06") else {
        panic!()
    };
    assert!(
        close(s.pan_rad, -FRAC_PI_2) && close(s.tilt_rad, FRAC_PI_2),
        "{s:?}"
    );
}

#[test]
fn manual_sensor_example_decodes_to_the_documented_values() {
    let Frame::Sensor(s) = round_trip(SENSOR_EXAMPLE) else {
        panic!()
    };
    assert_eq!(
        s,
        SensorReport {
            battery_voltage_v: 26.62,
            // 0.2 cm, 0.1 cm, 0.
            ir_m: [0.002, 0.001, 0.0],
            ultrasonic_m: [0.0; 3],
            motor_current_a: [1.0, 0.6, 0.0, 0.0],
            lift_current_a: 0.6,
            encoder_counts: [0; 4],
            lift_encoder_counts: 1000,
            accel_mps2: [0.0; 3],
            gyro_radps: [0.0; 3],
            mag_gauss: [0.0; 3],
            temperature_c: 0.0,
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: 0.0,
            sensor_stamp_us: 56322,
        }
    );
}

#[test]
fn manual_sensor_example_is_not_valid_bcd_so_the_bcd_profile_rejects_it() {
    let bcd = XbotProfile {
        bcd_currents_and_ranges: true,
        ..p()
    };
    // Front-left current `0A 00`: nibble A is not a decimal digit.
    assert_eq!(
        decode_frame(&hex(SENSOR_EXAMPLE), &bcd),
        Err(DecodeError::InvalidValue {
            id: 0x10,
            field: "motor current",
            value: 0x000A
        })
    );
}

#[test]
fn every_manual_example_frame_has_a_correct_checksum_and_length() {
    for text in [
        "AA 55 02 01 01 02",
        "AA 55 02 01 00 03",
        "AA 55 0D 03 CD CC 4C 3E 00 00 00 00 00 00 00 00 7D",
        "AA 55 0D 03 CD CC 4C BE 00 00 00 00 00 00 00 00 FD",
        "AA 55 0D 03 00 00 00 00 CD CC 4C 3E 00 00 00 00 7D",
        "AA 55 0D 03 00 00 00 00 CD CC 4C BE 00 00 00 00 FD",
        "AA 55 0D 03 00 00 00 00 00 00 00 00 00 00 A0 41 EF",
        "AA 55 0D 03 00 00 00 00 00 00 00 00 00 00 A0 C1 6F",
        "AA 55 03 04 01 00 06",
        "AA 55 03 04 01 64 62",
        "AA 55 03 04 01 0A 0C",
        "AA 55 03 05 00 5A 5C",
        "AA 55 03 05 5A 00 5C",
        "AA 55 03 05 B4 B4 06",
        SENSOR_EXAMPLE,
    ] {
        let bytes = hex(text);
        let payload = &bytes[3..bytes.len() - 1];
        assert_eq!(payload_len(payload[0]), Some(payload.len()), "{text}");
        assert_eq!(wrap_payload(payload).unwrap(), bytes, "{text}");
    }
}

// ---------------------------------------------------------------------------------------------
// Hand-built frames.

#[test]
fn battery_voltage_is_bcd_as_in_the_manual_notes() {
    for (raw, volts) in [
        (0x2596u16, 25.96),
        (0x2712, 27.12),
        (0x0000, 0.0),
        (0x9999, 99.99),
    ] {
        let mut payload = zero_sensor_payload();
        put_u16(&mut payload, 2, raw);
        let Frame::Sensor(s) = decode_payload(&payload, &p()).unwrap() else {
            panic!()
        };
        assert_eq!(s.battery_voltage_v, volts, "{raw:04X}");
        assert_eq!(
            Frame::Sensor(s).encode(&p()).unwrap(),
            wrap_payload(&payload).unwrap()
        );
    }
    let mut payload = zero_sensor_payload();
    put_u16(&mut payload, 2, 0x25A6);
    assert_eq!(
        decode_payload(&payload, &p()),
        Err(DecodeError::InvalidValue {
            id: 0x10,
            field: "battery voltage",
            value: 0x25A6
        })
    );
}

#[test]
fn every_wrong_fixed_marker_is_an_invalid_value() {
    for (offset, value, field) in SENSOR_MARKERS {
        let mut payload = zero_sensor_payload();
        payload[offset] = value ^ 0x40;
        assert_eq!(
            decode_payload(&payload, &p()),
            Err(DecodeError::InvalidValue {
                id: 0x10,
                field,
                value: (value ^ 0x40).into()
            }),
            "offset {offset}"
        );
    }
}

#[test]
fn encoders_are_reordered_from_the_wire_order_fl_fr_br_bl_to_fl_fr_rl_rr() {
    let mut payload = zero_sensor_payload();
    for (i, value) in [11u16, 22, 33, 44, 55].into_iter().enumerate() {
        put_u16(&mut payload, 30 + 2 * i, value);
    }
    let Frame::Sensor(s) = decode_payload(&payload, &p()).unwrap() else {
        panic!()
    };
    // Wire: FL 11, FR 22, back-right 33, back-left 44; lift 55.
    assert_eq!(s.encoder_counts, [11, 22, 44, 33]);
    assert_eq!(s.lift_encoder_counts, 55);
    assert_eq!(
        Frame::Sensor(s).encode(&p()).unwrap(),
        wrap_payload(&payload).unwrap()
    );
}

#[test]
fn ranges_and_currents_sit_at_their_offsets_in_project_order() {
    let mut payload = zero_sensor_payload();
    for (i, value) in [1u16, 2, 3].into_iter().enumerate() {
        put_u16(&mut payload, 5 + 2 * i, value * 100); // IR: 10, 20, 30 cm
        put_u16(&mut payload, 23 + 2 * i, value * 1000); // ultrasonic: 1, 2, 3 m
    }
    for (i, value) in [15u16, 25, 35, 45, 55].into_iter().enumerate() {
        put_u16(&mut payload, 12 + 2 * i, value);
    }
    let Frame::Sensor(s) = decode_payload(&payload, &p()).unwrap() else {
        panic!()
    };
    assert_eq!(s.ir_m, [0.1, 0.2, 0.3]);
    assert_eq!(s.ultrasonic_m, [1.0, 2.0, 3.0]);
    assert_eq!(s.motor_current_a, [1.5, 2.5, 3.5, 4.5]);
    assert_eq!(s.lift_current_a, 5.5);
}

#[test]
fn the_bcd_profile_reads_currents_and_ultrasonic_ranges_as_bcd() {
    let bcd = XbotProfile {
        bcd_currents_and_ranges: true,
        ..p()
    };
    let mut payload = zero_sensor_payload();
    put_u16(&mut payload, 12, 0x0123); // FL 12.3 A
    put_u16(&mut payload, 20, 0x0045); // lift 4.5 A
    put_u16(&mut payload, 25, 0x1500); // front-centre 1.5 m
    put_u16(&mut payload, 5, 0x0100); // IR is never BCD: 0x100 = 256 → 0.256 m
    let Frame::Sensor(s) = decode_payload(&payload, &bcd).unwrap() else {
        panic!()
    };
    assert_eq!(s.motor_current_a, [12.3, 0.0, 0.0, 0.0]);
    assert_eq!(s.lift_current_a, 4.5);
    assert_eq!(s.ultrasonic_m, [0.0, 1.5, 0.0]);
    assert_eq!(s.ir_m[0], 0.256);
    assert_eq!(
        Frame::Sensor(s).encode(&bcd).unwrap(),
        wrap_payload(&payload).unwrap()
    );
    // The same report sent as binary: 12.3 A is 123 = 0x007B.
    let binary = Frame::Sensor(s).encode(&p()).unwrap();
    assert_eq!(&binary[3 + 12..3 + 14], &[0x7B, 0x00]);
}

#[test]
fn imu_fields_use_the_manual_scales() {
    let mut payload = zero_sensor_payload();
    put_u16(&mut payload, 41, 16431); // ≈ 1 g
    put_u16(&mut payload, 47 + 4, (-1000i16) as u16); // gyro z
    put_u16(&mut payload, 53, 2048u16.wrapping_neg()); // mag x = -2048
    payload[59..63].copy_from_slice(&36.5f32.to_le_bytes());
    put_u16(&mut payload, 63, 900); // yaw 90.0°
    put_u16(&mut payload, 65, (-50i16) as u16); // pitch -5.0°
    put_u16(&mut payload, 67, 1800); // roll 180.0°
    let Frame::Sensor(s) = decode_payload(&payload, &p()).unwrap() else {
        panic!()
    };
    assert!(
        (s.accel_mps2[0] - 9.80665).abs() < 1e-3,
        "{:?}",
        s.accel_mps2
    );
    assert!(close(s.accel_mps2[0], 16431.0 * 0.00006086 * 9.80665));
    assert!(close(
        s.gyro_radps[2],
        (-1000.0 * 0.0152139846947314f64).to_radians()
    ));
    assert!(close(s.mag_gauss[0], -0.88));
    assert_eq!(s.temperature_c, 36.5);
    assert!(close(s.yaw_rad, FRAC_PI_2));
    assert!(close(s.pitch_rad, -5f64.to_radians()));
    assert!(close(s.roll_rad, PI));
    assert_eq!(
        Frame::Sensor(s).encode(&p()).unwrap(),
        wrap_payload(&payload).unwrap()
    );
}

#[test]
fn undefined_values_and_wrong_lengths_are_typed_errors() {
    assert_eq!(
        decode_payload(&[], &p()),
        Err(DecodeError::TooShort {
            id: 0,
            len: 0,
            need: 1
        })
    );
    assert_eq!(
        decode_payload(&[0x02, 0x00], &p()),
        Err(DecodeError::UnknownId { id: 0x02 })
    );
    assert_eq!(
        decode_payload(&[0x01, 0x01, 0x00], &p()),
        Err(DecodeError::BadLength {
            command: 0x01,
            len: 3,
            expected: 2
        })
    );
    assert_eq!(
        decode_payload(&zero_sensor_payload()[..70], &p()),
        Err(DecodeError::BadLength {
            command: 0x10,
            len: 70,
            expected: 71
        })
    );
    for (payload, field, value) in [
        (vec![0x01, 0x02], "power enable", 2),
        (vec![0x04, 0x02, 0x00], "lift enable", 2),
        (vec![0x04, 0x01, 101], "lift position", 101),
        (vec![0x05, 181, 90], "pan", 181),
        (vec![0x05, 90, 0xFF], "tilt", 0xFF),
    ] {
        assert_eq!(
            decode_payload(&payload, &p()),
            Err(DecodeError::InvalidValue {
                id: u32::from(payload[0]),
                field,
                value
            }),
            "{payload:02X?}"
        );
    }
    let mut nan = vec![0x03];
    nan.extend(0f32.to_le_bytes());
    nan.extend(f32::NAN.to_le_bytes());
    nan.extend(0f32.to_le_bytes());
    assert!(matches!(
        decode_payload(&nan, &p()),
        Err(DecodeError::InvalidValue { field: "vy", .. })
    ));
}

#[test]
fn encoding_rounds_servos_and_lift_to_whole_units_and_refuses_what_the_wire_cannot_carry() {
    let servos = Frame::Servos(ServoCommand {
        pan_rad: 0.5,   // 28.6° left → wire 61.35 → 61
        tilt_rad: -0.1, // 5.7° down → wire 84.27 → 84
    });
    assert_eq!(
        servos.encode(&p()).unwrap(),
        wrap_payload(&[5, 61, 84]).unwrap()
    );
    let lift = Frame::Lift(LiftCommand {
        enable: false,
        position_pct: 10.4,
    });
    assert_eq!(
        lift.encode(&p()).unwrap(),
        wrap_payload(&[4, 0, 10]).unwrap()
    );

    let too_far = Frame::Servos(ServoCommand {
        pan_rad: 1.6,
        tilt_rad: 0.0,
    });
    assert!(matches!(
        too_far.encode(&p()),
        Err(EncodeError::OutOfRange {
            field: "pan_rad",
            ..
        })
    ));
    for position_pct in [100.6, -1.0, f64::NAN] {
        let lift = Frame::Lift(LiftCommand {
            enable: true,
            position_pct,
        });
        assert!(lift.encode(&p()).is_err(), "{position_pct}");
    }
    for bad in [f64::NAN, f64::INFINITY, 1e39] {
        let v = Frame::Velocity(VelocityCommand {
            linear_x_mps: bad,
            ..VelocityCommand::default()
        });
        assert!(v.encode(&p()).is_err(), "{bad}");
    }
    let flat_battery = Frame::Sensor(SensorReport {
        battery_voltage_v: 100.0,
        ..SensorReport::default()
    });
    assert!(flat_battery.encode(&p()).is_err());
    let bcd = XbotProfile {
        bcd_currents_and_ranges: true,
        ..p()
    };
    let big_current = Frame::Sensor(SensorReport {
        lift_current_a: 1000.0,
        ..SensorReport::default()
    });
    assert!(big_current.encode(&p()).is_ok());
    assert!(big_current.encode(&bcd).is_err());
}

#[test]
fn frames_know_their_id_name_and_direction_and_serialize_with_a_tag() {
    let frames = [
        (Frame::Power(PowerCommand::default()), 0x01, "power"),
        (
            Frame::Velocity(VelocityCommand::default()),
            0x03,
            "velocity",
        ),
        (Frame::Lift(LiftCommand::default()), 0x04, "lift"),
        (Frame::Servos(ServoCommand::default()), 0x05, "servos"),
        (Frame::Sensor(SensorReport::default()), 0x10, "sensor"),
    ];
    for (frame, id, name) in frames {
        assert_eq!((frame.command_id(), frame_name(&frame)), (id, name.into()));
        let expected = if id == 0x10 {
            Direction::FromChassis
        } else {
            Direction::ToChassis
        };
        assert_eq!(frame.direction(), expected);
        let json = serde_json::to_value(frame).unwrap();
        assert_eq!(json["frame"], name);
        // Every default frame is representable.
        let bytes = frame.encode(&p()).unwrap();
        assert_eq!(bytes[3], id);
    }
    let json = serde_json::to_value(Frame::Power(PowerCommand { enable: true })).unwrap();
    assert_eq!(json, serde_json::json!({"frame": "power", "enable": true}));
}

// ---------------------------------------------------------------------------------------------
// The stream parser.

/// Pushes `bytes` in chunks of `chunk` and collects everything the parser yields.
fn parse_chunked(
    parser: &mut StreamParser,
    bytes: &[u8],
    chunk: usize,
) -> Vec<Result<Frame, StreamError>> {
    let mut out = Vec::new();
    for piece in bytes.chunks(chunk.max(1)) {
        parser.push(piece);
        while let Some(item) = parser.next_frame(&p()) {
            out.push(item);
        }
    }
    out
}

fn parse_all(bytes: &[u8]) -> Vec<Result<Frame, StreamError>> {
    parse_chunked(&mut StreamParser::new(), bytes, bytes.len())
}

fn ok_frames(items: &[Result<Frame, StreamError>]) -> Vec<Frame> {
    items
        .iter()
        .filter_map(|i| i.as_ref().ok().copied())
        .collect()
}

fn errors(items: &[Result<Frame, StreamError>]) -> Vec<DecodeError> {
    items
        .iter()
        .filter_map(|i| i.as_ref().err().map(|e| e.error.clone()))
        .collect()
}

fn power(enable: bool) -> Frame {
    Frame::Power(PowerCommand { enable })
}

const POWER_ON: &str = "AA 55 02 01 01 02";
const POWER_OFF: &str = "AA 55 02 01 00 03";
const FORWARD: &str = "AA 55 0D 03 CD CC 4C 3E 00 00 00 00 00 00 00 00 7D";

#[test]
fn garbage_before_between_and_after_frames_is_skipped_and_counted() {
    let mut stream = hex("00 13 55 FF");
    stream.extend(hex(POWER_ON));
    stream.extend(hex("01 02 03 55 55"));
    stream.extend(hex(SENSOR_EXAMPLE));
    stream.extend(hex("AA AA 00"));
    stream.extend(hex(POWER_OFF));
    stream.extend(hex("77"));
    let mut parser = StreamParser::new();
    let items = parse_chunked(&mut parser, &stream, stream.len());
    let frames = ok_frames(&items);
    assert_eq!(frames.len(), 3);
    assert_eq!(frames[0], power(true));
    assert!(matches!(frames[1], Frame::Sensor(_)));
    assert_eq!(frames[2], power(false));
    assert!(errors(&items).is_empty(), "{items:?}");
    assert_eq!(parser.bytes_discarded(), 4 + 5 + 3 + 1);
    assert_eq!(
        (parser.frames(), parser.errors(), parser.pending()),
        (3, 0, 0)
    );
}

#[test]
fn a_corrupted_frame_immediately_followed_by_a_good_one_loses_only_the_bad_one() {
    let mut stream = hex("AA 55 02 01 01 07"); // bad checksum
    stream.extend(hex(POWER_OFF));
    let items = parse_all(&stream);
    assert_eq!(
        errors(&items),
        [DecodeError::BadChecksum {
            expected: 0x02,
            got: 0x07
        }]
    );
    assert_eq!(ok_frames(&items), [power(false)]);
    let Err(e) = &items[0] else { panic!() };
    assert_eq!(e.raw, hex("AA 55 02 01 01 07"));
    assert_eq!(
        e.to_string(),
        "bad checksum, expected 0x02, got 0x07 in AA 55 02 01 01 07"
    );
}

#[test]
fn a_good_frame_inside_a_bad_candidate_is_found() {
    // A header claiming a velocity frame (17 bytes) whose "payload" holds a whole power frame.
    let mut stream = hex("AA 55 0D 03 00");
    stream.extend(hex(POWER_ON));
    stream.extend(hex("00 00 00 00 00 00"));
    stream.extend(hex(POWER_OFF));
    let items = parse_all(&stream);
    assert_eq!(ok_frames(&items), [power(true), power(false)]);
    assert_eq!(errors(&items).len(), 1);
    assert!(matches!(errors(&items)[0], DecodeError::BadChecksum { .. }));
}

#[test]
fn a_fake_header_inside_a_good_frame_is_not_a_frame() {
    // vx bytes AA 55 0D 03 look like a header; the frame itself is valid.
    let mut payload = vec![0x03, 0xAA, 0x55, 0x02, 0x01];
    payload.extend([0u8; 8]);
    let frame = wrap_payload(&payload).unwrap();
    let mut stream = hex("12 34");
    stream.extend(&frame);
    stream.extend(hex(POWER_ON));
    let items = parse_all(&stream);
    assert!(errors(&items).is_empty(), "{items:?}");
    let frames = ok_frames(&items);
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[0], decode_payload(&payload, &p()).unwrap());
    assert_eq!(frames[1], power(true));
}

#[test]
fn an_absurd_length_is_rejected_at_once_without_waiting_for_255_bytes() {
    let mut stream = hex("AA 55 FF 01");
    stream.extend(hex(POWER_ON));
    let items = parse_all(&stream);
    assert_eq!(
        errors(&items),
        [DecodeError::BadLength {
            command: 0x01,
            len: 255,
            expected: 2
        }]
    );
    assert_eq!(ok_frames(&items), [power(true)]);
}

#[test]
fn zero_lengths_and_unknown_ids_are_rejected_at_once() {
    let mut stream = hex("AA 55 00");
    stream.extend(hex("AA 55 03 07"));
    stream.extend(hex(POWER_ON));
    let items = parse_all(&stream);
    assert_eq!(
        errors(&items),
        [
            DecodeError::TooShort {
                id: 0,
                len: 0,
                need: 1
            },
            DecodeError::UnknownId { id: 0x07 }
        ]
    );
    assert_eq!(ok_frames(&items), [power(true)]);
}

#[test]
fn a_truncated_sensor_report_followed_by_a_whole_one_yields_the_whole_one() {
    let good = hex(SENSOR_EXAMPLE);
    let mut stream = good[..30].to_vec();
    stream.extend(&good);
    let mut parser = StreamParser::new();
    let items = parse_chunked(&mut parser, &stream, stream.len());
    // The fixed markers reject the truncated report as soon as the next one's bytes arrive.
    assert_eq!(ok_frames(&items).len(), 1);
    assert_eq!(errors(&items).len(), 1);
    assert!(matches!(
        errors(&items)[0],
        DecodeError::InvalidValue { id: 0x10, .. }
    ));
    assert_eq!(parser.pending(), 0);
}

#[test]
fn a_truncated_command_followed_by_good_frames_loses_none_of_them() {
    let mut stream = hex("AA 55 0D 03 CD CC 4C"); // 7 of 17 bytes
    stream.extend(hex(POWER_ON));
    stream.extend(hex(FORWARD));
    stream.extend(hex(POWER_OFF));
    let items = parse_all(&stream);
    let forward = decode_frame(&hex(FORWARD), &p()).unwrap();
    assert_eq!(ok_frames(&items), [power(true), forward, power(false)]);
    assert_eq!(errors(&items).len(), 1);
}

#[test]
fn byte_at_a_time_feeding_yields_what_the_whole_stream_yields() {
    let mut stream = hex("55 AA 00 AA");
    stream.extend(hex(SENSOR_EXAMPLE));
    stream.extend(hex("AA 55 02 01 01 07"));
    stream.extend(hex(POWER_ON));
    stream.extend(hex(FORWARD));
    stream.extend(hex("AA 55 0D"));
    let whole = parse_all(&stream);
    for chunk in [1, 2, 3, 5, 7, 16] {
        let mut parser = StreamParser::new();
        assert_eq!(
            parse_chunked(&mut parser, &stream, chunk),
            whole,
            "chunk {chunk}"
        );
        // The trailing partial header waits for more bytes.
        assert_eq!(parser.pending(), 3);
    }
    assert_eq!(ok_frames(&whole).len(), 3);
}

#[test]
fn feed_yields_frames_in_order_and_keeps_what_an_early_drop_left() {
    let mut stream = Vec::new();
    for _ in 0..100 {
        stream.extend(hex(SENSOR_EXAMPLE));
        stream.extend(hex(POWER_ON));
    }
    let mut parser = StreamParser::new();
    let profile = p();
    let first: Vec<_> = parser.feed(&stream, &profile).take(3).collect();
    assert_eq!(first.len(), 3);
    // The rest was pushed when the iterator was dropped.
    let mut rest = Vec::new();
    while let Some(item) = parser.next_frame(&profile) {
        rest.push(item.unwrap());
    }
    assert_eq!(rest.len(), 197);
    assert_eq!(parser.frames(), 200);

    let mut parser = StreamParser::new();
    assert_eq!(parser.feed(&stream, &profile).count(), 200);
    assert_eq!(parser.pending(), 0);
}

#[test]
fn memory_stays_bounded_when_nobody_drains_the_parser() {
    let mut parser = StreamParser::new();
    for _ in 0..10 {
        parser.push(&[0xAA; 1000]);
    }
    assert_eq!(parser.pending(), STREAM_CAPACITY);
    assert_eq!(parser.bytes_discarded(), 10_000 - STREAM_CAPACITY as u64);
    assert!(parser.next_frame(&p()).is_none());
    assert_eq!(parser.pending(), 1);
    parser.clear();
    assert_eq!(parser.pending(), 0);
    assert_eq!(parser.bytes_discarded(), 10_000);
}

// ---------------------------------------------------------------------------------------------
// Properties.

/// A finite `f32` from arbitrary bits (non-finite bits become 0).
fn finite_f32() -> impl Strategy<Value = f32> {
    any::<u32>().prop_map(|bits| {
        let f = f32::from_bits(bits);
        if f.is_finite() { f } else { 0.0 }
    })
}

fn bcd(value: u16) -> u16 {
    ((value / 1000) << 12) | ((value / 100 % 10) << 8) | ((value / 10 % 10) << 4) | (value % 10)
}

/// A valid sensor payload for the given BCD setting.
fn sensor_payload(bcd_fields: bool) -> impl Strategy<Value = Vec<u8>> {
    (
        proptest::collection::vec(any::<u8>(), 71),
        0u16..=9999,
        proptest::array::uniform8(0u16..=9999),
        finite_f32(),
    )
        .prop_map(move |(mut payload, volts, bcd_values, temperature)| {
            payload[0] = id::SENSOR;
            for (offset, value, _) in SENSOR_MARKERS {
                payload[offset] = value;
            }
            put_u16(&mut payload, 2, bcd(volts));
            if bcd_fields {
                // Currents at 12..22, ultrasonic ranges at 23..29.
                let offsets = [12, 14, 16, 18, 20, 23, 25, 27];
                for (offset, value) in offsets.into_iter().zip(bcd_values) {
                    put_u16(&mut payload, offset, bcd(value));
                }
            }
            payload[59..63].copy_from_slice(&temperature.to_le_bytes());
            payload
        })
}

/// A valid payload of any command for the given BCD setting.
fn payload(bcd_fields: bool) -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        any::<bool>().prop_map(|on| vec![id::POWER, u8::from(on)]),
        (finite_f32(), finite_f32(), finite_f32()).prop_map(|(x, y, z)| {
            let mut v = vec![id::VELOCITY];
            for f in [x, y, z] {
                v.extend(f.to_le_bytes());
            }
            v
        }),
        (any::<bool>(), 0u8..=100).prop_map(|(on, pos)| vec![id::LIFT, u8::from(on), pos]),
        (0u8..=180, 0u8..=180).prop_map(|(pan, tilt)| vec![id::SERVOS, pan, tilt]),
        sensor_payload(bcd_fields),
    ]
}

fn profile_strategy() -> impl Strategy<Value = XbotProfile> {
    (any::<bool>(), any::<bool>(), any::<bool>()).prop_map(|(yaw, lateral, bcd_fields)| {
        XbotProfile {
            yaw_rate_left_positive: yaw,
            lateral_left_positive: lateral,
            bcd_currents_and_ranges: bcd_fields,
            ..XbotProfile::default()
        }
    })
}

fn profile_and_payloads(max: usize) -> impl Strategy<Value = (XbotProfile, Vec<Vec<u8>>)> {
    profile_strategy().prop_flat_map(move |profile| {
        let payloads = proptest::collection::vec(payload(profile.bcd_currents_and_ranges), 0..max);
        (Just(profile), payloads)
    })
}

/// Garbage that cannot start a frame.
fn garbage() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>().prop_filter("no AA", |b| *b != 0xAA), 0..20)
}

proptest! {
    #[test]
    fn every_valid_payload_decodes_and_encodes_back_to_the_same_bytes(
        (profile, payloads) in profile_and_payloads(8),
    ) {
        for payload in payloads {
            let frame = decode_payload(&payload, &profile).unwrap();
            let bytes = frame.encode(&profile).unwrap();
            prop_assert_eq!(&bytes, &wrap_payload(&payload).unwrap());
            prop_assert_eq!(decode_payload(&bytes[3..bytes.len() - 1], &profile).unwrap(), frame);
        }
    }

    #[test]
    fn frames_built_from_wire_values_round_trip(
        pan in 0u8..=180,
        tilt in 0u8..=180,
        position in 0u8..=100,
        enable in any::<bool>(),
        vx in finite_f32(),
        yaw_deg in finite_f32(),
        profile in profile_strategy(),
    ) {
        let frames = [
            Frame::Servos(ServoCommand {
                pan_rad: (90.0 - f64::from(pan)).to_radians(),
                tilt_rad: (f64::from(tilt) - 90.0).to_radians(),
            }),
            Frame::Lift(LiftCommand { enable, position_pct: position.into() }),
            Frame::Power(PowerCommand { enable }),
            Frame::Velocity(VelocityCommand {
                linear_x_mps: vx.into(),
                linear_y_mps: (-vx).into(),
                angular_z_radps: f64::from(yaw_deg).to_radians(),
            }),
        ];
        for frame in frames {
            let bytes = frame.encode(&profile).unwrap();
            prop_assert_eq!(decode_payload(&bytes[3..bytes.len() - 1], &profile).unwrap(), frame);
        }
    }

    #[test]
    fn arbitrary_bytes_in_arbitrary_chunks_never_panic_and_every_byte_is_accounted_for(
        bytes in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(0xAA), Just(0x55), Just(0x47), Just(0x10)], 0..600),
        chunk in 1usize..80,
        profile in profile_strategy(),
    ) {
        let mut parser = StreamParser::new();
        let mut frame_bytes = 0u64;
        for piece in bytes.chunks(chunk) {
            parser.push(piece);
            while let Some(item) = parser.next_frame(&profile) {
                if let Ok(frame) = item {
                    frame_bytes += (payload_len(frame.command_id()).unwrap() + FRAME_OVERHEAD) as u64;
                }
            }
        }
        prop_assert_eq!(
            bytes.len() as u64,
            parser.bytes_discarded() + frame_bytes + parser.pending() as u64
        );
        prop_assert!(parser.pending() < MAX_FRAME_LEN);
        let mut fed = StreamParser::new();
        let _ = fed.feed(&bytes, &profile).count();
        prop_assert_eq!(fed.frames(), parser.frames());
    }

    #[test]
    fn a_valid_stream_with_garbage_between_frames_yields_exactly_its_frames_in_any_chunking(
        (profile, payloads) in profile_and_payloads(12),
        gaps in proptest::collection::vec(garbage(), 13),
        chunks in proptest::collection::vec(1usize..90, 1..20),
    ) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        let mut garbage_len = 0;
        for (payload, gap) in payloads.iter().zip(&gaps) {
            stream.extend(gap);
            garbage_len += gap.len();
            stream.extend(wrap_payload(payload).unwrap());
            expected.push(decode_payload(payload, &profile).unwrap());
        }
        let tail = &gaps[gaps.len() - 1];
        stream.extend(tail);
        garbage_len += tail.len();

        let mut parser = StreamParser::new();
        let mut got = Vec::new();
        let mut rest = stream.as_slice();
        for size in chunks.iter().cycle() {
            if rest.is_empty() {
                break;
            }
            let (piece, more) = rest.split_at((*size).min(rest.len()));
            rest = more;
            parser.push(piece);
            while let Some(item) = parser.next_frame(&profile) {
                got.push(item.unwrap());
            }
        }
        prop_assert_eq!(got, expected);
        prop_assert_eq!(parser.errors(), 0);
        prop_assert_eq!(parser.bytes_discarded(), garbage_len as u64);
        prop_assert_eq!(parser.pending(), 0);
    }
}
