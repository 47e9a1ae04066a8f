//! The test vectors of the V2 reading (§6, TV1-TV17), each decoded and encoded back.

use super::*;
use crate::DecodeError;
use crate::Direction;
use crate::can::CanFrame;
use chassis_interfaces::RcState;

fn frame(text: &str) -> CanFrame {
    CanFrame::from_candump(text).unwrap()
}

fn decoded(text: &str, profile: &V2Profile) -> Frame {
    decode(&frame(text), profile).unwrap()
}

/// Decodes `text`, checks the result, and encodes it back to the same bytes.
fn vector(text: &str, profile: &V2Profile, expected: Frame) {
    let got = decoded(text, profile);
    assert_eq!(got, expected, "{text}");
    assert_eq!(got.encode(profile).unwrap(), frame(text), "{text}");
}

fn motion(linear_mps: f64, angular_radps: f64, steer_rad: f64) -> Frame {
    Frame::MotionCommand(Motion {
        linear_mps,
        angular_radps,
        lateral_mps: 0.0,
        steer_rad,
    })
}

fn hunter() -> V2Profile {
    V2Profile::for_model(V2Model::Hunter)
}

fn bunker() -> V2Profile {
    V2Profile::for_model(V2Model::Bunker)
}

#[test]
fn tv1_to_tv5_motion_commands() {
    vector("111#0096000000000000", &hunter(), motion(0.150, 0.0, 0.0));
    vector("111#00000000000000C8", &hunter(), motion(0.0, 0.0, 0.200));
    let scout = V2Profile::for_model(V2Model::Scout);
    vector("111#0000003200000000", &scout, motion(0.0, 0.050, 0.0));
    vector("111#000000C800000000", &bunker(), motion(0.0, 0.200, 0.0));
    vector("111#00FA000000000000", &bunker(), motion(0.25, 0.0, 0.0));
    assert_eq!(
        decoded("111#0096000000000000", &hunter()).direction(),
        Direction::ToChassis
    );
}

#[test]
fn tv6_tv7_control_mode_at_dlc_8() {
    vector(
        "421#0100000000000000",
        &bunker(),
        Frame::Mode(ModeCommand { can: true }),
    );
    vector(
        "421#0000000000000000",
        &bunker(),
        Frame::Mode(ModeCommand { can: false }),
    );
    // ⚠ D-9: the manual's DLC 1 form decodes too, and is sent when the profile says so.
    let short = V2Profile {
        short_commands_dlc: 1,
        ..bunker()
    };
    vector("421#01", &short, Frame::Mode(ModeCommand { can: true }));
}

#[test]
fn tv8_tv12_system_state_of_a_bunker_mini_with_its_estop_pressed() {
    vector(
        "211#0100010000800000",
        &bunker(),
        Frame::SystemStatus(SystemStatus {
            vehicle_state: vehicle::ESTOP,
            vehicle: "estop",
            mode: 0,
            control: "standby",
            battery_voltage_v: 25.6,
            fault_word: 0x0080,
            b6: 0,
            count: 0,
        }),
    );
    vector(
        "211#010100FE00800000",
        &bunker(),
        Frame::SystemStatus(SystemStatus {
            vehicle_state: vehicle::ESTOP,
            vehicle: "estop",
            mode: 1,
            control: "can",
            battery_voltage_v: 25.4,
            fault_word: 0x0080,
            b6: 0,
            count: 0,
        }),
    );
}

#[test]
fn tv9_tv10_tv11_idle_feedback() {
    vector(
        "221#0000000000000000",
        &bunker(),
        Frame::MotionFeedback(Motion::default()),
    );
    vector(
        "241#AA00000000000061",
        &bunker(),
        Frame::Rc(RcState {
            switch_a: 2,
            switch_b: 2,
            switch_c: 2,
            switch_d: 2,
            counter: 0x61,
            ..RcState::default()
        }),
    );
    vector(
        "311#0000000000000000",
        &bunker(),
        Frame::Odometer(Odometer::default()),
    );
}

#[test]
fn tv13_front_light_off() {
    vector(
        "121#0100000000000000",
        &V2Profile::for_model(V2Model::Tracer),
        Frame::LightCommand(Lights {
            enabled: true,
            ..Lights::default()
        }),
    );
}

#[test]
fn tv14_tv15_version_requests() {
    let p = V2Profile::default();
    vector("4A1#01", &p, Frame::SdkVersionRequest);
    vector("411#01", &p, Frame::VersionRequest);
    // The answers: 0x41A binary, 0x4A1 eight characters of text.
    let v = decoded("41A#0102030405060708", &p);
    assert_eq!(
        v,
        Frame::Version(Version {
            controller_hw: [1, 2],
            driver_hw: [3, 4],
            controller_sw: [5, 6],
            driver_sw: [7, 8],
        })
    );
    let Frame::VersionText(t) = decoded("4A1#56322E3001020A20", &p) else {
        panic!("not text");
    };
    assert_eq!(t.text(), "V2.0    ");
}

#[test]
fn tv16_hunter_steering_zero_and_its_acknowledgement() {
    vector("431#AA", &hunter(), Frame::SteeringZero);
    vector("43A#EE", &hunter(), Frame::SteeringZeroAck { done: true });
    vector("43A#FF", &hunter(), Frame::SteeringZeroAck { done: false });
}

#[test]
fn tv17_hunter_se_steering_zero_query() {
    let se = V2Profile::for_model(V2Model::HunterSe);
    vector("433#AA", &se, Frame::SteeringZeroQuery);
    vector(
        "43B#55F0",
        &se,
        Frame::SteeringZeroOffsetReply(SteeringZeroOffset { pulses: 22000 }),
    );
}

#[test]
fn brake_polarity_follows_the_profile() {
    let h = hunter();
    vector(
        "131#0100000000000000",
        &h,
        Frame::ParkingBrake(ParkingBrake { engage: true }),
    );
    let titan_like = V2Profile {
        brake_lock_value: Some(0x00),
        ..hunter()
    };
    vector(
        "131#0000000000000000",
        &titan_like,
        Frame::ParkingBrake(ParkingBrake { engage: true }),
    );
}

#[test]
fn mode_codes_follow_the_profile() {
    // 0x02 is RC on HUNTER 2.0, serial elsewhere; 0x00 is RC on TRACER v1.2.
    let Frame::SystemStatus(s) = decoded("211#0002010000000000", &hunter()) else {
        panic!()
    };
    assert_eq!(s.control, "rc");
    let Frame::SystemStatus(s) = decoded("211#0002010000000000", &bunker()) else {
        panic!()
    };
    assert_eq!(s.control, "uart");
    let tracer12 = V2Profile {
        mode_codes: profile::ModeCodes::TRACER_V12,
        ..V2Profile::for_model(V2Model::Tracer)
    };
    let Frame::SystemStatus(s) = decoded("211#0000010000000000", &tracer12) else {
        panic!()
    };
    assert_eq!(s.control, "rc");
}

#[test]
fn omni_lateral_and_ranger_mini_v1_units() {
    let omni = V2Profile::for_model(V2Model::ScoutMiniOmni);
    vector(
        "111#00000000FF380000",
        &omni,
        Frame::MotionCommand(Motion {
            lateral_mps: -0.2,
            ..Motion::default()
        }),
    );
    // RANGER MINI 1.0: 0.01°, inverted: +0.1 rad left = -572.96 → -573 = 0xFDC3.
    let v1 = V2Profile::for_model(V2Model::RangerMiniV1);
    let f = Frame::MotionCommand(Motion {
        steer_rad: 0.1,
        ..Motion::default()
    });
    assert_eq!(f.encode(&v1).unwrap(), frame("111#000000000000FDC3"));
    let Frame::MotionCommand(m) = decoded("111#000000000000FDC3", &v1) else {
        panic!()
    };
    assert!((m.steer_rad - 0.1).abs() < 1e-4, "{}", m.steer_rad);
}

#[test]
fn ranger_frames_and_actuators_up_to_eight() {
    let r = V2Profile::for_model(V2Model::RangerMini);
    vector(
        "141#0200000000000000",
        &r,
        Frame::MotionModeCommand(MotionMode {
            mode: 2,
            changing: false,
        }),
    );
    vector(
        "291#0201",
        &r,
        Frame::MotionModeState(MotionMode {
            mode: 2,
            changing: true,
        }),
    );
    vector(
        "271#03E8FC1800000000",
        &r,
        Frame::SteeringAngles(Four {
            values: [1.0, -1.0, 0.0, 0.0],
        }),
    );
    let Frame::MotorFast(m) = decoded("258#0064FFF600000010", &r) else {
        panic!()
    };
    assert_eq!(
        (m.motor, m.rpm, m.current_a, m.position_counts),
        (8, 100.0, -1.0, 16)
    );
    assert!(decode(&frame("259#0000000000000000"), &r).is_err());
}

#[test]
fn bms_voltage_unit_follows_the_profile() {
    let Frame::BmsData(b) = decoded("361#5A6409C4FFF600FA", &hunter()) else {
        panic!()
    };
    assert!((b.voltage_v - 25.0).abs() < 1e-9);
    let Frame::BmsData(b) = decoded("361#5A6400FAFFF600FA", &bunker()) else {
        panic!()
    };
    assert!((b.voltage_v - 25.0).abs() < 1e-9);
    assert_eq!(
        (b.soc_pct, b.current_a, b.temperature_c),
        (90.0, -1.0, 25.0)
    );
    // ⚠ D-6: both layouts of 0x362, DLC 4 or 8.
    assert!(matches!(
        decoded("362#02000000", &bunker()),
        Frame::BmsAlarm(a) if a.alarm_1 == 2
    ));
    let old = V2Profile {
        bms_alarm_layout: profile::BmsAlarmLayout::ProtectionCodes,
        ..bunker()
    };
    assert!(matches!(
        decoded("362#0100000023FB0007", &old),
        Frame::BmsProtection(p) if p.max_cell_temp_c == 35 && p.min_cell_temp_c == -5
    ));
    let protection = decoded("362#0100000023FB0007", &old);
    assert_eq!(
        protection.encode(&old).unwrap(),
        frame("362#0100000023FB0007")
    );
}

#[test]
fn every_frame_round_trips() {
    let p = V2Profile::for_model(V2Model::RangerMini);
    for text in [
        "111#00960032FF3800C8",
        "121#0103320132000007",
        "231#0100000000000009",
        "4A1#4147582D56322E30",
        "432#55F0",
        "441#0000000000000000",
        "221#FF6A000000000000",
        "251#0064000A00001000",
        "261#00F0001E1C400000",
        "281#03E803E803E803E8",
        "311#000003E8FFFFFC18",
        "321#0001000200030005",
        "331#0100000000000000",
        "341#0102030405060708",
        "351#00640010010102FF",
        "41A#0100010002010203",
    ] {
        let f = frame(text);
        let d = decode(&f, &p).unwrap();
        assert_eq!(d.encode(&p).unwrap(), f, "{text}");
        assert_eq!(u32::from(d.id()), f.id(), "{text}");
    }
}

#[test]
fn nonsense_is_an_error_not_a_panic() {
    let p = V2Profile::default();
    for text in [
        "421#05",
        "211#00",
        "7FF#00",
        "431#00",
        "121#0500000000000000",
    ] {
        assert!(decode(&frame(text), &p).is_err(), "{text}");
    }
    let too_fast = Frame::MotionCommand(Motion {
        linear_mps: 40.0,
        ..Motion::default()
    });
    assert!(too_fast.encode(&p).is_err());
}

/// Found by fuzzing (`agilex_v2_decode`): a light frame whose mode or brightness the wire
/// cannot carry decoded, then could not be encoded back.
#[test]
fn a_light_frame_with_a_mode_or_brightness_beyond_the_manual_is_refused() {
    let p = V2Profile::default();
    for text in [
        "121#0100002100000000",
        "231#0104000000000000",
        "231#0103650000000000",
        "121#0100000065000000",
    ] {
        assert!(
            matches!(
                decode(&frame(text), &p),
                Err(DecodeError::InvalidValue { .. })
            ),
            "{text}"
        );
    }
    // The edges are lights.
    let Frame::LightState(l) = decoded("231#0103640364000009", &p) else {
        panic!()
    };
    assert_eq!(
        (
            l.front_mode,
            l.front_brightness_pct,
            l.rear_mode,
            l.rear_brightness_pct
        ),
        (3, 100, 3, 100)
    );
}
