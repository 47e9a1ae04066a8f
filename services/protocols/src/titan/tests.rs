//! TITAN codec tests: the manual's example, hand-built frames for every id, round trips.

use proptest::prelude::*;

use super::*;
use crate::titan::TitanProfile;
use crate::{CanFrame, DecodeError, Direction};

fn p() -> TitanProfile {
    TitanProfile::default()
}

fn frame(text: &str) -> CanFrame {
    CanFrame::from_candump(text).unwrap()
}

fn round_trip(text: &str) -> Frame {
    let f = frame(text);
    let decoded = decode(&f, &p()).unwrap();
    assert_eq!(decoded.encode(&p()).unwrap(), f, "re-encoding {text}");
    decoded
}

#[test]
fn manual_example_motion_command_150_mm_s_forward() {
    assert_eq!(
        round_trip("111#0096000000000000"),
        Frame::MotionCommand(MotionCommand {
            linear_mps: 0.15,
            steer_rad: 0.0
        })
    );
}

#[test]
fn motion_command_carries_a_left_positive_steering_angle() {
    // -1.2 m/s, +0.300 rad (left).
    assert_eq!(
        round_trip("111#FB5000000000012C"),
        Frame::MotionCommand(MotionCommand {
            linear_mps: -1.2,
            steer_rad: 0.3
        })
    );
}

#[test]
fn one_byte_commands_decode_and_encode() {
    let can_command = ModeCommand {
        mode: mode::CAN_COMMAND,
    };
    let standby = ModeCommand {
        mode: mode::STANDBY,
    };
    for (text, frame) in [
        ("421#01", Frame::Mode(can_command)),
        ("421#00", Frame::Mode(standby)),
        (
            "131#01",
            Frame::ParkingBrake(ParkingBrake { engage: false }),
        ),
        ("131#00", Frame::ParkingBrake(ParkingBrake { engage: true })),
        ("422#01", Frame::SilentMode(Switch { enter: true })),
        ("423#00", Frame::OffRoad(Switch { enter: false })),
        ("431#AA", Frame::SteeringZero),
        ("43A#EE", Frame::SteeringZeroAck),
    ] {
        assert_eq!(round_trip(text), frame, "{text}");
    }
    for code in [
        0x00, 0x01, 0x02, 0x03, 0x04, 0x09, 0x0A, 0x0B, 0x0C, 0x0F, 0x10,
    ] {
        let text = format!("441#{code:02X}");
        assert_eq!(round_trip(&text), Frame::ClearFault(ClearFault { code }));
    }
}

#[test]
fn undefined_command_values_are_typed_errors() {
    for (text, field) in [
        ("421#02", "mode"),
        ("131#02", "parking brake"),
        ("431#AB", "steering zero"),
        ("43A#00", "steering zero acknowledgement"),
        ("441#05", "fault clear code"),
        ("423#FF", "off-road mode"),
    ] {
        match decode(&frame(text), &p()) {
            Err(DecodeError::InvalidValue { field: f, .. }) => assert_eq!(f, field, "{text}"),
            other => panic!("{text}: {other:?}"),
        }
    }
}

#[test]
fn system_status_decodes_voltage_mode_and_fault_bits() {
    // normal, CAN command, 48.0 V, heartbeat lost (b6 bit1) + bumper (b5 bit5) + motor 2 comm
    // (b7 bit4).
    let decoded = round_trip("211#000101E000200210");
    let Frame::SystemStatus(s) = decoded else {
        panic!("{decoded:?}")
    };
    assert_eq!(s.body_status, body::NORMAL);
    assert_eq!(s.mode, mode::CAN_COMMAND);
    assert_eq!(s.battery_voltage_v, 48.0);
    assert_eq!(
        s.vendor_fault_word,
        fault::HEARTBEAT_LOST | fault::BUMPER | fault::MOTOR_2_COMM_LOST
    );
}

#[test]
fn every_fault_bit_sits_where_the_manual_puts_it() {
    // (byte in the frame, bit in that byte, constant)
    let table = [
        (5, 0, fault::FRONT_STEERING_ENCODER),
        (5, 1, fault::REAR_STEERING_ENCODER),
        (5, 5, fault::BUMPER),
        (6, 0, fault::MOTOR_DRIVER_ERROR),
        (6, 1, fault::HEARTBEAT_LOST),
        (6, 6, fault::OVER_TEMPERATURE),
        (6, 7, fault::OVER_CURRENT),
        (7, 0, fault::BATTERY_UNDER_VOLTAGE),
        (7, 2, fault::RC_LINK_LOST),
        (7, 3, fault::MOTOR_1_COMM_LOST),
        (7, 4, fault::MOTOR_2_COMM_LOST),
        (7, 5, fault::MOTOR_3_COMM_LOST),
        (7, 6, fault::MOTOR_4_COMM_LOST),
    ];
    for (byte, bit, constant) in table {
        let mut data = [0u8; 8];
        data[byte] = 1 << bit;
        let Frame::SystemStatus(s) = decode(&CanFrame::new(0x211, &data).unwrap(), &p()).unwrap()
        else {
            panic!()
        };
        assert_eq!(s.vendor_fault_word, constant, "byte {byte} bit {bit}");
    }
}

#[test]
fn motion_feedback_steering_sign_follows_the_profile() {
    // Wire: +0.100 rad. Default profile trusts the text (left turn reports negative).
    let f = frame("221#01F4000000000064");
    let Frame::MotionFeedback(m) = decode(&f, &p()).unwrap() else {
        panic!()
    };
    assert_eq!((m.linear_mps, m.steer_rad), (0.5, -0.1));
    let flipped = TitanProfile {
        steering_feedback_left_positive: true,
        ..p()
    };
    let Frame::MotionFeedback(m) = decode(&f, &flipped).unwrap() else {
        panic!()
    };
    assert_eq!(m.steer_rad, 0.1);
    assert_eq!(Frame::MotionFeedback(m).encode(&flipped).unwrap(), f);
}

#[test]
fn steering_feedback_reports_both_axles() {
    let Frame::SteeringFeedback(s) = round_trip("271#00C8FF3800000000") else {
        panic!()
    };
    // Wire +0.200 / -0.200 rad, negated by the default profile.
    assert_eq!((s.front_steer_rad, s.rear_steer_rad), (-0.2, 0.2));
}

#[test]
fn motor_frames_map_ids_to_motor_numbers() {
    // motor 3: 1500 rpm, -2.5 A, position -100000.
    let Frame::MotorFast(m) = round_trip("253#05DCFFE7FFFE7960") else {
        panic!()
    };
    assert_eq!(
        m,
        MotorFast {
            motor: 3,
            rpm: 1500.0,
            current_a: -2.5,
            position_counts: -100_000
        }
    );
    // motor 4: 48.2 V, 35 °C driver, -5 °C motor, status enabled + sensor fault.
    let Frame::MotorSlow(m) = round_trip("264#01E20023FB500000") else {
        panic!()
    };
    assert_eq!(
        m,
        MotorSlow {
            motor: 4,
            driver_voltage_v: 48.2,
            driver_temp_c: 35.0,
            motor_temp_c: -5.0,
            driver_status: 0x50
        }
    );
}

#[test]
fn axle_speed_and_odometer_decode() {
    let Frame::AxleSpeed(a) = round_trip("281#03E8FC1800000000") else {
        panic!()
    };
    assert_eq!((a.front_axle_mps, a.rear_axle_mps), (1.0, -1.0));
    let Frame::Odometer(o) = round_trip("311#00012345FFFFFC18") else {
        panic!()
    };
    assert_eq!((o.front_distance_m, o.rear_distance_m), (74.565, -1.0));
}

#[test]
fn rc_frame_unpacks_switches_and_signed_sticks() {
    // switches: A=2 (up), B=1 (middle), C=3 (down), D=3 → 0b11_11_01_10 = 0xF6.
    let Frame::Rc(r) = round_trip("241#F6649C000A320007") else {
        panic!()
    };
    assert_eq!(
        (r.switch_a, r.switch_b, r.switch_c, r.switch_d),
        (2, 1, 3, 3)
    );
    assert_eq!((r.right_x_pct, r.right_y_pct, r.left_y_pct), (100, -100, 0));
    assert_eq!((r.left_x_pct, r.knob_a_pct, r.counter), (10, 50, 7));
}

#[test]
fn bms_frames_decode_per_group() {
    // group 1 (0x363): 80 %, 97 %, 51.20 V, -3.5 A (charging), 25.3 °C.
    let Frame::BmsData(b) = round_trip("363#50611400FFDD00FD") else {
        panic!()
    };
    assert_eq!(
        b,
        BmsData {
            group: 1,
            soc_pct: 80.0,
            soh_pct: 97.0,
            voltage_v: 51.2,
            current_a: -3.5,
            temperature_c: 25.3
        }
    );
    let Frame::BmsAlarm(a) = round_trip("366#84010200") else {
        panic!()
    };
    assert_eq!(
        (a.group, a.alarm_1, a.alarm_2, a.warning_1),
        (2, 0x84, 0x01, 0x02)
    );
    assert_eq!(a.alarm_flags(), 0x0002_0184);
    let Frame::BmsData(b) = round_trip("361#6464000000000000") else {
        panic!()
    };
    assert_eq!(b.group, 0);
}

#[test]
fn short_frames_and_unknown_ids_are_typed_errors() {
    assert_eq!(
        decode(&frame("221#0102"), &p()),
        Err(DecodeError::TooShort {
            id: 0x221,
            len: 2,
            need: 8
        })
    );
    assert_eq!(
        decode(&frame("421#"), &p()),
        Err(DecodeError::TooShort {
            id: 0x421,
            len: 0,
            need: 1
        })
    );
    assert_eq!(
        decode(&frame("130#0000000000000000"), &p()),
        Err(DecodeError::UnknownId { id: 0x130 })
    );
    assert_eq!(
        decode(&frame("00000221#0000000000000000"), &p()),
        Err(DecodeError::ExtendedId { id: 0x221 })
    );
}

#[test]
fn encoding_refuses_values_the_wire_cannot_carry() {
    let too_fast = Frame::MotionCommand(MotionCommand {
        linear_mps: 40.0,
        steer_rad: 0.0,
    });
    assert!(too_fast.encode(&p()).is_err());
    let nan = Frame::MotionCommand(MotionCommand {
        linear_mps: f64::NAN,
        steer_rad: 0.0,
    });
    assert!(nan.encode(&p()).is_err());
    let bad_motor = Frame::MotorFast(MotorFast {
        motor: 5,
        ..MotorFast::default()
    });
    assert!(bad_motor.encode(&p()).is_err());
}

#[test]
fn directions_split_commands_from_feedback() {
    assert_eq!(Frame::SteeringZero.direction(), Direction::ToChassis);
    assert_eq!(Frame::SteeringZeroAck.direction(), Direction::FromChassis);
}

/// Every id the TITAN manual defines.
const IDS: [u16; 29] = [
    0x111, 0x131, 0x421, 0x422, 0x423, 0x431, 0x43A, 0x441, 0x211, 0x221, 0x241, 0x251, 0x252,
    0x253, 0x254, 0x261, 0x262, 0x263, 0x264, 0x271, 0x281, 0x311, 0x361, 0x362, 0x363, 0x364,
    0x365, 0x366, 0x221,
];

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic_and_valid_frames_round_trip(
        id_index in 0..IDS.len(),
        data in proptest::collection::vec(any::<u8>(), 0..=8),
        left_positive in any::<bool>(),
    ) {
        let profile = TitanProfile { steering_feedback_left_positive: left_positive, ..p() };
        let f = CanFrame::new(IDS[id_index].into(), &data).unwrap();
        if let Ok(decoded) = decode(&f, &profile) {
            let encoded = decoded.encode(&profile).unwrap();
            prop_assert_eq!(decode(&encoded, &profile).unwrap(), decoded);
            prop_assert_eq!(encoded.id(), f.id());
            // Same bytes except reserved ones (always sent as zero).
            prop_assert!(encoded.len() <= f.len());
        }
    }

    #[test]
    fn arbitrary_ids_and_bytes_never_panic(id in 0u32..=0x7FF, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let f = CanFrame::new(id, &data).unwrap();
        let _ = decode(&f, &p());
    }

    #[test]
    fn motion_commands_round_trip_exactly(mm_s in -3000i16..=3000, mrad in -367i16..=367) {
        let c = Frame::MotionCommand(MotionCommand {
            linear_mps: f64::from(mm_s) / 1000.0,
            steer_rad: f64::from(mrad) / 1000.0,
        });
        let encoded = c.encode(&p()).unwrap();
        prop_assert_eq!(&encoded.data()[..2], &mm_s.to_be_bytes());
        prop_assert_eq!(&encoded.data()[6..], &mrad.to_be_bytes());
        prop_assert_eq!(decode(&encoded, &p()).unwrap(), c);
    }
}
