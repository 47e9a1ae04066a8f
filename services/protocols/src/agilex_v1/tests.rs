//! SCOUT MINI codec tests: the manual's examples, hand-built frames for every id (checksums
//! summed by hand in the comments), the count byte, round trips and checksum properties.

// 0.5235 and 0.7853 are the manual's full scales as printed, not approximations of π/6 and π/4.
#![allow(clippy::approx_constant)]

use proptest::prelude::*;

use super::*;
use crate::agilex_v1::V1Profile;
use crate::frame_json::frame_name;
use crate::{CanFrame, DecodeError, Direction, EncodeError};

fn p() -> V1Profile {
    V1Profile::default()
}

fn frame(text: &str) -> CanFrame {
    CanFrame::from_candump(text).unwrap()
}

/// Decodes `text`, checks that re-encoding with the decoded count gives the same bytes.
fn round_trip(text: &str) -> Decoded {
    let f = frame(text);
    let decoded = decode(&f, &p()).unwrap();
    assert_eq!(
        decoded.frame.encode(decoded.count, &p()).unwrap(),
        f,
        "re-encoding {text}"
    );
    decoded
}

/// The manual's checksum, written independently of the codec: widen, add, keep the low byte.
fn reference_checksum(id: u16, data7: &[u8; 7]) -> u8 {
    let total: u32 = u32::from(id >> 8)
        + u32::from(id & 0xFF)
        + 8
        + data7.iter().map(|&b| u32::from(b)).sum::<u32>();
    total.to_le_bytes()[0]
}

/// A standard frame of `id` with `data7` and its correct checksum.
fn with_checksum(id: u16, data7: [u8; 7]) -> CanFrame {
    let mut data = [0u8; 8];
    data[..7].copy_from_slice(&data7);
    data[7] = reference_checksum(id, &data7);
    CanFrame::new(id.into(), &data).unwrap()
}

fn assert_close(actual: f64, expected: f64) {
    assert!(
        (actual - expected).abs() < 1e-12,
        "{actual} is not {expected}"
    );
}

// ---------------------------------------------------------------------------------------------
// The manual's examples (0x130, count 0).

#[test]
fn manual_example_forward_half_a_metre_per_second_round_trips() {
    // 01+30+08+01+0A = 0x44.
    let d = round_trip("130#01000A0000000044");
    assert_eq!(d.count, 0);
    assert_eq!(
        d.frame,
        Frame::MotionCommand(MotionCommand {
            mode: mode::CAN_COMMAND,
            fault_clear: clear_code::NONE,
            linear_mps: 0.5,
            angular_radps: 0.0,
        })
    );
    assert_eq!(
        Frame::MotionCommand(MotionCommand::drive(0.5, 0.0))
            .encode(0, &p())
            .unwrap(),
        frame("130#01000A0000000044")
    );
}

#[test]
fn manual_example_rotate_ten_percent_of_full_scale_round_trips() {
    // 01+30+08+01+0A = 0x44.
    let d = round_trip("130#0100000A00000044");
    let Frame::MotionCommand(m) = d.frame else {
        panic!("{d:?}")
    };
    assert_eq!((m.mode, m.fault_clear, m.linear_mps), (1, 0, 0.0));
    // ⚠ 10 % of the table's 0.5235 rad/s (the default profile).
    assert_close(m.angular_radps, 0.05235);
    // The example's own reading: 10 % = 0.07853 rad/s, a full scale of 0.7853 rad/s.
    let example_reading = V1Profile {
        angular_full_scale_rad_s: 0.7853,
        ..p()
    };
    let f = frame("130#0100000A00000044");
    let Frame::MotionCommand(m) = decode(&f, &example_reading).unwrap().frame else {
        panic!()
    };
    assert_close(m.angular_radps, 0.07853);
    assert_eq!(
        Frame::MotionCommand(m).encode(0, &example_reading).unwrap(),
        f
    );
}

#[test]
fn manual_example_command_mode_standing_round_trips() {
    // 01+30+08+01 = 0x3A.
    let d = round_trip("130#010000000000003A");
    assert_eq!(
        d,
        Decoded {
            frame: Frame::MotionCommand(MotionCommand::drive(0.0, 0.0)),
            count: 0
        }
    );
}

#[test]
fn checksum_function_reproduces_the_manual_examples() {
    assert_eq!(checksum(0x130, &[0x01, 0x00, 0x0A, 0, 0, 0, 0]), 0x44);
    assert_eq!(checksum(0x130, &[0x01, 0x00, 0x00, 0x0A, 0, 0, 0]), 0x44);
    assert_eq!(checksum(0x130, &[0x01, 0, 0, 0, 0, 0, 0]), 0x3A);
    // The manual's id split: 0x540 → 0x05 + 0x40 (+ dlc 8).
    assert_eq!(checksum(0x540, &[0; 7]), 0x4D);
}

// ---------------------------------------------------------------------------------------------
// Checksum and count.

#[test]
fn a_wrong_checksum_reads_expected_and_got() {
    let err = decode(&frame("130#01000A0000000045"), &p()).unwrap_err();
    assert_eq!(
        err,
        DecodeError::BadChecksum {
            expected: 0x44,
            got: 0x45
        }
    );
    assert_eq!(err.to_string(), "bad checksum, expected 0x44, got 0x45");
}

#[test]
fn the_checksum_is_checked_before_any_value() {
    // Mode 0x07 is undefined, but the checksum (01+30+08+07 = 0x40) is wrong first.
    assert_eq!(
        decode(&frame("130#0700000000000000"), &p()),
        Err(DecodeError::BadChecksum {
            expected: 0x40,
            got: 0x00
        })
    );
}

#[test]
fn the_id_takes_part_in_the_checksum() {
    // The first manual example's bytes under 0x131: 01+31+08+01+0A = 0x45.
    assert_eq!(
        decode(&frame("131#01000A0000000044"), &p()),
        Err(DecodeError::BadChecksum {
            expected: 0x45,
            got: 0x44
        })
    );
}

#[test]
fn the_count_byte_round_trips_and_is_summed() {
    let f = Frame::MotionCommand(MotionCommand::drive(0.5, 0.0))
        .encode(200, &p())
        .unwrap();
    // 01+30+08+01+0A+C8 = 0x10C → 0x0C.
    assert_eq!(f, frame("130#01000A000000C80C"));
    let d = decode(&f, &p()).unwrap();
    assert_eq!(d.count, 200);
    // Count 255 wraps the sum too: 01+30+08+02+FF = 0x13A → 0x3A.
    let d = round_trip("130#020000000000FF3A");
    assert_eq!(d.count, 255);
    let Frame::MotionCommand(m) = d.frame else {
        panic!()
    };
    assert_eq!(m.mode, mode::SERIAL);
}

// ---------------------------------------------------------------------------------------------
// Hand-built frames for every id.

#[test]
fn motion_command_carries_negative_speeds_and_a_fault_clear() {
    // CAN command, clear motor over-current, -20 % (0xEC), -100 % (0x9C), count 3.
    // 01+30+08+01+08+EC+9C+03 = 0x1CD → 0xCD.
    let d = round_trip("130#0108EC9C000003CD");
    assert_eq!(d.count, 3);
    assert_eq!(
        d.frame,
        Frame::MotionCommand(MotionCommand {
            mode: mode::CAN_COMMAND,
            fault_clear: clear_code::MOTOR_OVER_CURRENT,
            linear_mps: -1.0,
            angular_radps: -0.5235,
        })
    );
}

#[test]
fn system_status_decodes_body_mode_voltage_and_fault_word() {
    // Emergency stop, CAN command, 24.6 V (0x00F6), b4 0x11 (checksum error + RC disconnected),
    // b5 0x84 (motor 1 comm + over-current protection), count 5.
    // 01+51+08+01+01+F6+11+84+05 = 0x1EC → 0xEC.
    let d = round_trip("151#010100F6118405EC");
    assert_eq!(d.count, 5);
    let Frame::SystemStatus(s) = d.frame else {
        panic!("{d:?}")
    };
    assert_eq!(s.body_status, body::EMERGENCY_STOP);
    assert_eq!(s.mode, mode::CAN_COMMAND);
    assert_eq!(s.battery_voltage_v, 24.6);
    assert_eq!(s.vendor_fault_word, 0x1184);
    assert_eq!(
        s.vendor_fault_word,
        fault::COMMAND_CHECKSUM
            | fault::RC_DISCONNECTED
            | fault::MOTOR_1_COMM
            | fault::MOTOR_OVER_CURRENT_PROTECTION
    );
    assert_eq!(
        fault::names(s.vendor_fault_word),
        [
            "command_checksum",
            "rc_disconnected",
            "motor_1_comm",
            "motor_over_current_protection"
        ]
    );
}

#[test]
fn system_status_keeps_undefined_body_and_mode_bytes() {
    // Body 0x07 (undefined), serial mode, 26.0 V (0x0104). 01+51+08+07+02+01+04 = 0x68.
    let Frame::SystemStatus(s) = round_trip("151#0702010400000068").frame else {
        panic!()
    };
    assert_eq!((s.body_status, s.mode), (0x07, mode::SERIAL));
    assert_eq!(s.battery_voltage_v, 26.0);
    assert_eq!(s.vendor_fault_word, 0);
}

#[test]
fn every_fault_bit_sits_where_the_manual_puts_it() {
    // (byte in the frame, bit in that byte, constant)
    let table = [
        (4, 0, fault::COMMAND_CHECKSUM),
        (4, 1, fault::DRIVE_OVER_TEMP_ALARM),
        (4, 2, fault::MOTOR_OVER_CURRENT_ALARM),
        (4, 3, fault::BATTERY_UNDER_VOLTAGE_ALARM),
        (4, 4, fault::RC_DISCONNECTED),
        (5, 0, fault::BATTERY_UNDER_VOLTAGE),
        (5, 1, fault::BATTERY_OVER_VOLTAGE),
        (5, 2, fault::MOTOR_1_COMM),
        (5, 3, fault::MOTOR_2_COMM),
        (5, 4, fault::MOTOR_3_COMM),
        (5, 5, fault::MOTOR_4_COMM),
        (5, 6, fault::DRIVE_OVER_TEMP_PROTECTION),
        (5, 7, fault::MOTOR_OVER_CURRENT_PROTECTION),
    ];
    assert_eq!(table.len(), fault::ALL.len());
    for (byte, bit, constant) in table {
        let mut data7 = [0u8; 7];
        data7[byte] = 1 << bit;
        let Frame::SystemStatus(s) = decode(&with_checksum(0x151, data7), &p()).unwrap().frame
        else {
            panic!()
        };
        assert_eq!(s.vendor_fault_word, constant, "byte {byte} bit {bit}");
    }
}

#[test]
fn motion_feedback_decodes_signed_speeds() {
    // -0.500 m/s (0xFE0C), +0.300 rad/s (0x012C), count 0x10.
    // 01+31+08+FE+0C+01+2C+10 = 0x181 → 0x81.
    let d = round_trip("131#FE0C012C00001081");
    assert_eq!(
        d,
        Decoded {
            frame: Frame::MotionFeedback(MotionFeedback {
                linear_mps: -0.5,
                angular_radps: 0.3
            }),
            count: 0x10
        }
    );
}

#[test]
fn motor_frames_map_ids_0x200_to_0x203_to_motors_1_to_4() {
    // 2.5 A (0x0019), -1500 rpm (0xFA24), driver 35 °C (0x23), motor -5 °C (0xFB), count 7.
    // 0x200: 02+00+08+19+FA+24+23+FB+07 = 0x266 → 0x66; each next id adds one.
    for (motor, text) in [
        (1, "200#0019FA2423FB0766"),
        (2, "201#0019FA2423FB0767"),
        (3, "202#0019FA2423FB0768"),
        (4, "203#0019FA2423FB0769"),
    ] {
        let d = round_trip(text);
        assert_eq!(
            d.frame,
            Frame::Motor(MotorFeedback {
                motor,
                current_a: 2.5,
                rpm: -1500.0,
                driver_temp_c: 35.0,
                motor_temp_c: -5.0,
            }),
            "{text}"
        );
        assert_eq!(d.count, 7);
        assert_eq!(u32::from(d.frame.id()), frame(text).id());
    }
}

#[test]
fn light_state_decodes_and_keeps_undefined_mode_and_brightness() {
    // Enabled, custom brightness, 80 % (0x50), count 0x2A. 01+41+08+01+03+50+2A = 0xC8.
    let d = round_trip("141#0103500000002AC8");
    assert_eq!(
        d,
        Decoded {
            frame: Frame::LightState(Lights {
                control_enabled: true,
                front_mode: light_mode::CUSTOM_BRIGHTNESS,
                front_brightness_pct: 80
            }),
            count: 0x2A
        }
    );
    // Disabled, mode 0x07, brightness 200: as sent. 01+41+08+07+C8 = 0x119 → 0x19.
    let d = round_trip("141#0007C80000000019");
    assert_eq!(
        d.frame,
        Frame::LightState(Lights {
            control_enabled: false,
            front_mode: 0x07,
            front_brightness_pct: 200
        })
    );
}

#[test]
fn light_command_decodes_and_encodes() {
    // Enable, breathing, count 1. 01+40+08+01+02+01 = 0x4D.
    let d = round_trip("140#010200000000014D");
    assert_eq!(
        d,
        Decoded {
            frame: Frame::LightCommand(Lights {
                control_enabled: true,
                front_mode: light_mode::BREATHING,
                front_brightness_pct: 0
            }),
            count: 1
        }
    );
    // Enable, custom, 100 %. 01+40+08+01+03+64 = 0xB1.
    let d = round_trip("140#01036400000000B1");
    assert_eq!(
        d.frame,
        Frame::LightCommand(Lights {
            control_enabled: true,
            front_mode: light_mode::CUSTOM_BRIGHTNESS,
            front_brightness_pct: 100
        })
    );
}

#[test]
fn undefined_command_values_are_typed_errors() {
    let cases: [(u16, [u8; 7], &str, u32); 9] = [
        (0x130, [0x03, 0, 0, 0, 0, 0, 0], "mode", 0x03),
        (0x130, [0x01, 0x09, 0, 0, 0, 0, 0], "fault clear code", 0x09),
        (
            0x130,
            [0x01, 0, 0x65, 0, 0, 0, 0],
            "linear speed percent",
            0x65,
        ),
        (
            0x130,
            [0x01, 0, 0x9B, 0, 0, 0, 0],
            "linear speed percent",
            0x9B,
        ),
        (
            0x130,
            [0x01, 0, 0, 0x80, 0, 0, 0],
            "angular speed percent",
            0x80,
        ),
        (
            0x140,
            [0x02, 0, 0, 0, 0, 0, 0],
            "light control enable",
            0x02,
        ),
        (0x140, [0x01, 0x04, 0, 0, 0, 0, 0], "front light mode", 0x04),
        (
            0x140,
            [0x01, 0x03, 0x65, 0, 0, 0, 0],
            "front light brightness",
            0x65,
        ),
        (
            0x141,
            [0xFF, 0, 0, 0, 0, 0, 0],
            "light control enabled",
            0xFF,
        ),
    ];
    for (id, data7, field, value) in cases {
        assert_eq!(
            decode(&with_checksum(id, data7), &p()),
            Err(DecodeError::InvalidValue {
                id: id.into(),
                field,
                value
            }),
            "{id:03X} {data7:02X?}"
        );
    }
    // ±100 % are the limits, not beyond: 0x64 and 0x9C decode.
    assert!(decode(&with_checksum(0x130, [1, 0, 0x64, 0x9C, 0, 0, 0]), &p()).is_ok());
}

#[test]
fn short_frames_unknown_ids_and_extended_ids_are_typed_errors() {
    assert_eq!(
        decode(&frame("130#01000A"), &p()),
        Err(DecodeError::TooShort {
            id: 0x130,
            len: 3,
            need: 8
        })
    );
    assert_eq!(
        decode(&frame("151#"), &p()),
        Err(DecodeError::TooShort {
            id: 0x151,
            len: 0,
            need: 8
        })
    );
    // A 7-byte frame whose last byte would be the right checksum is still short.
    assert_eq!(
        decode(&frame("130#01000A00000044"), &p()),
        Err(DecodeError::TooShort {
            id: 0x130,
            len: 7,
            need: 8
        })
    );
    for unknown in [0x111, 0x204, 0x1FF, 0x150, 0x000] {
        assert_eq!(
            decode(&CanFrame::new(unknown, &[0; 8]).unwrap(), &p()),
            Err(DecodeError::UnknownId { id: unknown })
        );
    }
    assert_eq!(
        decode(&frame("00000130#01000A0000000044"), &p()),
        Err(DecodeError::ExtendedId { id: 0x130 })
    );
}

// ---------------------------------------------------------------------------------------------
// Encoding.

#[test]
fn encoding_rounds_speeds_to_the_nearest_percent() {
    let encode = |v: f64, w: f64| {
        Frame::MotionCommand(MotionCommand::drive(v, w))
            .encode(0, &p())
            .unwrap()
    };
    // 0.52 m/s = 10.4 % → 10; 0.53 m/s = 10.6 % → 11; -0.0262 rad/s = -5.005 % → -5.
    assert_eq!(encode(0.52, 0.0).data()[2], 10);
    assert_eq!(encode(0.53, 0.0).data()[2], 11);
    assert_eq!(encode(0.0, -0.0262).data()[3], (-5i8).cast_unsigned());
    // 100.4 % still rounds to 100.
    assert_eq!(encode(5.02, 0.0).data()[2], 100);
}

#[test]
fn encoding_refuses_values_the_wire_cannot_carry() {
    let motion = |m: MotionCommand| Frame::MotionCommand(m).encode(0, &p());
    // 5.1 m/s is 102 %: the range is reported in m/s.
    assert_eq!(
        motion(MotionCommand::drive(5.1, 0.0)),
        Err(EncodeError::OutOfRange {
            field: "linear_mps",
            value: 5.1,
            min: -5.0,
            max: 5.0
        })
    );
    assert!(motion(MotionCommand::drive(0.0, -0.6)).is_err());
    assert!(motion(MotionCommand::drive(f64::NAN, 0.0)).is_err());
    assert!(motion(MotionCommand::drive(0.0, f64::INFINITY)).is_err());
    assert!(
        motion(MotionCommand {
            mode: 3,
            ..MotionCommand::default()
        })
        .is_err()
    );
    assert!(
        motion(MotionCommand {
            fault_clear: 9,
            ..MotionCommand::default()
        })
        .is_err()
    );
    let zero_scale = V1Profile {
        linear_full_scale_mps: 0.0,
        ..p()
    };
    assert!(
        Frame::MotionCommand(MotionCommand::drive(0.1, 0.0))
            .encode(0, &zero_scale)
            .is_err()
    );

    let light = |mode: u8, pct: u8| {
        Frame::LightCommand(Lights {
            control_enabled: true,
            front_mode: mode,
            front_brightness_pct: pct,
        })
        .encode(0, &p())
    };
    assert!(light(light_mode::CUSTOM_BRIGHTNESS, 100).is_ok());
    assert!(light(light_mode::CUSTOM_BRIGHTNESS, 101).is_err());
    assert!(light(4, 0).is_err());

    let motor = |m: MotorFeedback| Frame::Motor(m).encode(0, &p());
    let ok = MotorFeedback {
        motor: 1,
        ..MotorFeedback::default()
    };
    assert!(motor(ok).is_ok());
    for bad in [
        MotorFeedback { motor: 0, ..ok },
        MotorFeedback { motor: 5, ..ok },
        MotorFeedback {
            current_a: -0.1,
            ..ok
        },
        MotorFeedback {
            driver_temp_c: 128.0,
            ..ok
        },
        MotorFeedback {
            rpm: 40_000.0,
            ..ok
        },
    ] {
        assert!(motor(bad).is_err(), "{bad:?}");
    }
    assert!(
        Frame::MotionFeedback(MotionFeedback {
            linear_mps: 33.0,
            angular_radps: 0.0
        })
        .encode(0, &p())
        .is_err()
    );
}

#[test]
fn quantise_percent_reports_the_command_actually_sent() {
    assert_eq!(quantise_percent(0.5, 5.0), (10, 0.5));
    assert_eq!(quantise_percent(0.52, 5.0), (10, 0.5));
    assert_eq!(quantise_percent(-0.53, 5.0), (-11, -0.55));
    assert_eq!(quantise_percent(9.0, 5.0), (100, 5.0));
    assert_eq!(quantise_percent(f64::NEG_INFINITY, 5.0), (-100, -5.0));
    assert_eq!(quantise_percent(f64::NAN, 5.0), (0, 0.0));
    assert_eq!(quantise_percent(1.0, 0.0), (0, 0.0));
    let (pct, sent) = quantise_percent(0.06, 0.5235);
    assert_eq!(pct, 11);
    assert_eq!(sent, percent_to_si(11, 0.5235));
    // What quantise_percent says is sent is what the chassis decodes.
    let f = Frame::MotionCommand(MotionCommand::drive(0.52, 0.06))
        .encode(0, &p())
        .unwrap();
    let Frame::MotionCommand(m) = decode(&f, &p()).unwrap().frame else {
        panic!()
    };
    assert_eq!(
        (m.linear_mps, m.angular_radps),
        (quantise_percent(0.52, 5.0).1, sent)
    );
}

#[test]
fn ids_directions_and_names_cover_every_frame() {
    let frames = [
        (
            Frame::MotionCommand(MotionCommand::default()),
            0x130,
            "motion_command",
            Direction::ToChassis,
        ),
        (
            Frame::LightCommand(Lights::default()),
            0x140,
            "light_command",
            Direction::ToChassis,
        ),
        (
            Frame::SystemStatus(SystemStatus::default()),
            0x151,
            "system_status",
            Direction::FromChassis,
        ),
        (
            Frame::MotionFeedback(MotionFeedback::default()),
            0x131,
            "motion_feedback",
            Direction::FromChassis,
        ),
        (
            Frame::Motor(MotorFeedback {
                motor: 4,
                ..MotorFeedback::default()
            }),
            0x203,
            "motor",
            Direction::FromChassis,
        ),
        (
            Frame::LightState(Lights::default()),
            0x141,
            "light_state",
            Direction::FromChassis,
        ),
    ];
    for (f, id, name, direction) in frames {
        assert_eq!(
            (f.id(), frame_name(&f), f.direction()),
            (id, name.into(), direction)
        );
        assert!(id::ALL.contains(&f.id()));
        let json = serde_json::to_value(f).unwrap();
        assert_eq!(json["frame"], name);
    }
}

#[test]
fn frames_serialise_with_their_name_and_si_fields() {
    let json = serde_json::to_value(Frame::Motor(MotorFeedback {
        motor: 2,
        current_a: 2.5,
        rpm: -1500.0,
        driver_temp_c: 35.0,
        motor_temp_c: -5.0,
    }))
    .unwrap();
    assert_eq!(
        json,
        serde_json::json!({
            "frame": "motor", "motor": 2, "current_a": 2.5, "rpm": -1500.0,
            "driver_temp_c": 35.0, "motor_temp_c": -5.0
        })
    );
}

#[test]
fn wire_layouts_have_their_documented_sizes() {
    for (name, size) in WIRE_SIZES {
        let expected = if name == "frame" { DLC } else { 6 };
        assert_eq!(size, expected, "{name}");
    }
}

// ---------------------------------------------------------------------------------------------
// Properties.

/// The three readings of each full scale (PROTOCOLS.md §2).
fn arb_profile() -> impl Strategy<Value = V1Profile> {
    (
        prop::sample::select(vec![5.0, 3.0]),
        prop::sample::select(vec![0.5235, 0.7853, 2.5235]),
    )
        .prop_map(|(linear, angular)| V1Profile {
            linear_full_scale_mps: linear,
            angular_full_scale_rad_s: angular,
            ..V1Profile::default()
        })
}

/// Any frame the wire can carry, with values on the wire's grid.
fn arb_frame(profile: V1Profile) -> impl Strategy<Value = Frame> {
    let lights = (any::<bool>(), 0u8..=3, 0u8..=100).prop_map(|(e, m, b)| Lights {
        control_enabled: e,
        front_mode: m,
        front_brightness_pct: b,
    });
    prop_oneof![
        (0u8..=2, 0u8..=8, -100i8..=100, -100i8..=100).prop_map(move |(m, c, v, w)| {
            Frame::MotionCommand(MotionCommand {
                mode: m,
                fault_clear: c,
                linear_mps: percent_to_si(v, profile.linear_full_scale_mps),
                angular_radps: percent_to_si(w, profile.angular_full_scale_rad_s),
            })
        }),
        lights.clone().prop_map(Frame::LightCommand),
        (any::<u8>(), any::<u8>(), any::<u16>(), any::<u16>()).prop_map(|(b, m, dv, f)| {
            Frame::SystemStatus(SystemStatus {
                body_status: b,
                mode: m,
                battery_voltage_v: f64::from(dv) / 10.0,
                vendor_fault_word: f,
            })
        }),
        (any::<i16>(), any::<i16>()).prop_map(|(v, w)| Frame::MotionFeedback(MotionFeedback {
            linear_mps: f64::from(v) / 1000.0,
            angular_radps: f64::from(w) / 1000.0,
        })),
        (
            1u8..=4,
            any::<u16>(),
            any::<i16>(),
            any::<i8>(),
            any::<i8>()
        )
            .prop_map(|(motor, da, rpm, dt, mt)| Frame::Motor(MotorFeedback {
                motor,
                current_a: f64::from(da) / 10.0,
                rpm: rpm.into(),
                driver_temp_c: dt.into(),
                motor_temp_c: mt.into(),
            })),
        (any::<bool>(), any::<u8>(), any::<u8>()).prop_map(|(e, m, b)| Frame::LightState(Lights {
            control_enabled: e,
            front_mode: m,
            front_brightness_pct: b,
        })),
    ]
}

fn arb_profile_and_frame() -> impl Strategy<Value = (V1Profile, Frame)> {
    arb_profile().prop_flat_map(|profile| (Just(profile.clone()), arb_frame(profile)))
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic_and_decoded_frames_re_encode(
        id_index in 0..id::ALL.len(),
        data in proptest::collection::vec(any::<u8>(), 0..=8),
        profile in arb_profile(),
    ) {
        let f = CanFrame::new(id::ALL[id_index].into(), &data).unwrap();
        if let Ok(decoded) = decode(&f, &profile) {
            let encoded = decoded.frame.encode(decoded.count, &profile).unwrap();
            prop_assert_eq!(decode(&encoded, &profile).unwrap(), decoded);
            prop_assert_eq!(encoded.id(), f.id());
            prop_assert_eq!(encoded.len(), DLC);
        }
    }

    #[test]
    fn arbitrary_ids_and_bytes_never_panic(
        id in 0u32..=0x7FF,
        extended in any::<bool>(),
        data in proptest::collection::vec(any::<u8>(), 0..=8),
    ) {
        let f = if extended {
            CanFrame::new_extended(id, &data).unwrap()
        } else {
            CanFrame::new(id, &data).unwrap()
        };
        let _ = decode(&f, &p());
    }

    #[test]
    fn any_payload_with_a_correct_checksum_decodes_or_is_an_invalid_value(
        id_index in 0..id::ALL.len(),
        data7 in any::<[u8; 7]>(),
    ) {
        let id = id::ALL[id_index];
        match decode(&with_checksum(id, data7), &p()) {
            Ok(decoded) => prop_assert_eq!(decoded.count, data7[6]),
            Err(DecodeError::InvalidValue { id: err_id, .. }) => {
                prop_assert_eq!(err_id, u32::from(id));
                // Only commands and the light state's enable byte are checked.
                prop_assert!(matches!(id, 0x130 | 0x140 | 0x141), "{:03X}", id);
            }
            Err(other) => prop_assert!(false, "{:03X}: {:?}", id, other),
        }
    }

    #[test]
    fn the_checksum_function_agrees_with_the_manuals_formula(
        id in 0u16..=0x7FF,
        data7 in any::<[u8; 7]>(),
    ) {
        prop_assert_eq!(checksum(id, &data7), reference_checksum(id, &data7));
    }

    #[test]
    fn valid_frames_round_trip_exactly_with_their_count(
        (profile, f) in arb_profile_and_frame(),
        count in any::<u8>(),
    ) {
        let encoded = f.encode(count, &profile).unwrap();
        prop_assert_eq!(encoded.id(), u32::from(f.id()));
        let data: [u8; 8] = encoded.data().try_into().unwrap();
        prop_assert_eq!(data[6], count);
        prop_assert_eq!(data[7], reference_checksum(f.id(), &data[..7].try_into().unwrap()));
        prop_assert_eq!(decode(&encoded, &profile).unwrap(), Decoded { frame: f, count });
    }

    #[test]
    fn flipping_any_single_bit_is_a_bad_checksum(
        (profile, f) in arb_profile_and_frame(),
        count in any::<u8>(),
        byte in 0usize..8,
        bit in 0u8..8,
    ) {
        let encoded = f.encode(count, &profile).unwrap();
        let mut data: [u8; 8] = encoded.data().try_into().unwrap();
        data[byte] ^= 1 << bit;
        let flipped = CanFrame::new(encoded.id(), &data).unwrap();
        // A single bit changes the byte sum by ±2^bit, never a multiple of 256.
        let result = decode(&flipped, &profile);
        prop_assert!(
            matches!(result, Err(DecodeError::BadChecksum { .. })),
            "byte {} bit {}: {:?}", byte, bit, result
        );
        if byte == 7 {
            prop_assert_eq!(
                result,
                Err(DecodeError::BadChecksum { expected: encoded.data()[7], got: data[7] })
            );
        }
    }
}
