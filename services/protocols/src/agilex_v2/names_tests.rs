//! What a protocol-V2 chassis says, by name, for every V2 robot: 0x211's vehicle state, control
//! mode and fault bits (`PROTOCOLS-V2` §2.3.1, §2.3.2, ⚠ D-2, D-3, D-20), the driver status bits
//! (§2.3.5, ⚠ D-7), the BMS alarms (§2.3.6, ⚠ D-6) — in `chassis decode`'s describer and in the
//! driver's `ChassisState`.
//!
//! The expected tables are written out again from §2.3.2, not taken from the code's tables.

use chassis_interfaces::{ControlMode, DriverStatus, FaultFlags as F, SystemState};
use serde_json::{Value, json};

use super::*;
use crate::can::CanFrame;
use crate::driver::{Driver, DriverConfig, Rx};
use crate::family::Profile;
use crate::frame_json::FrameJson;
use crate::kind::RobotKind;
use crate::time::Timestamp;

const T0: Timestamp = Timestamp::from_millis(1_000);

/// One row of §2.3.2: the bit in the `u16be` word b4-5, its name, the normalized flag.
type Row = (u16, &'static str, u64);

/// SDK generic masks, with b5 bit7 read as the E-stop (⚠ D-20's default).
const SDK: &[Row] = &[
    (0x0100, "motor_driver_error", F::MOTOR_DRIVER_ERROR),
    (0x0200, "host_communication_lost", F::HEARTBEAT_LOST),
    (0x0001, "battery_failure", F::BATTERY_UNDER_VOLTAGE),
    (0x0002, "battery_warning", F::BATTERY_UNDER_VOLTAGE_WARNING),
    (0x0004, "rc_signal_lost", F::RC_LINK_LOST),
    (0x0008, "motor_1_communication_lost", F::MOTOR_1_COMM_LOST),
    (0x0010, "motor_2_communication_lost", F::MOTOR_2_COMM_LOST),
    (0x0020, "motor_3_communication_lost", F::MOTOR_3_COMM_LOST),
    (0x0040, "motor_4_communication_lost", F::MOTOR_4_COMM_LOST),
    (0x0080, "estop", F::EMERGENCY_STOP),
];

/// SCOUT v1.3.0 / TRACER v1.2 (b4 only).
const SCOUT_V13: &[Row] = &[
    (
        0x0100,
        "battery_under_voltage_failure",
        F::BATTERY_UNDER_VOLTAGE,
    ),
    (
        0x0200,
        "battery_under_voltage_warning",
        F::BATTERY_UNDER_VOLTAGE_WARNING,
    ),
    (0x0400, "rc_link_lost", F::RC_LINK_LOST),
];

/// TRACER MINI (TMM p18), which the TRACER follows too.
const TRACER_MINI: &[Row] = &[
    (0x0200, "accessory_12v_over_current", F::OVER_CURRENT),
    (0x8000, "anti_collision_strip", F::BUMPER),
    (
        0x0001,
        "battery_under_voltage_failure",
        F::BATTERY_UNDER_VOLTAGE,
    ),
    (
        0x0002,
        "battery_under_voltage_warning",
        F::BATTERY_UNDER_VOLTAGE_WARNING,
    ),
    (0x0004, "rc_link_lost", F::RC_LINK_LOST),
];

const HUNTER_2: &[Row] = &[
    (
        0x0200,
        "front_steering_encoder_offline",
        F::FRONT_STEERING_ENCODER,
    ),
    (0x0400, "rc_link_lost", F::RC_LINK_LOST),
    (0x1000, "host_communication_lost", F::HEARTBEAT_LOST),
    (0x4000, "driver_state_error", F::MOTOR_DRIVER_ERROR),
    (0x0001, "battery_under_voltage", F::BATTERY_UNDER_VOLTAGE),
    (
        0x0008,
        "steering_driver_communication_lost",
        F::MOTOR_1_COMM_LOST,
    ),
    (
        0x0010,
        "rear_right_driver_communication_lost",
        F::MOTOR_2_COMM_LOST,
    ),
    (
        0x0020,
        "rear_left_driver_communication_lost",
        F::MOTOR_3_COMM_LOST,
    ),
    (0x0040, "driver_over_temperature", F::OVER_TEMPERATURE),
    (0x0080, "motor_over_current", F::OVER_CURRENT),
];

const HUNTER_SE: &[Row] = &[
    (0x0100, "motor_over_temperature", F::OVER_TEMPERATURE),
    (0x0200, "driver_over_current", F::OVER_CURRENT),
    (0x0400, "driver_status_error", F::MOTOR_DRIVER_ERROR),
    (0x0001, "battery_under_voltage", F::BATTERY_UNDER_VOLTAGE),
    (
        0x0002,
        "steering_zero_setting_error",
        F::FRONT_STEERING_ENCODER,
    ),
    (0x0004, "rc_link_lost", F::RC_LINK_LOST),
    (
        0x0008,
        "steering_driver_communication_lost",
        F::MOTOR_1_COMM_LOST,
    ),
    (
        0x0010,
        "rear_right_driver_communication_lost",
        F::MOTOR_2_COMM_LOST,
    ),
    (
        0x0020,
        "rear_left_driver_communication_lost",
        F::MOTOR_3_COMM_LOST,
    ),
    (0x0080, "estop", F::EMERGENCY_STOP),
];

/// Every robot that speaks V2, with its V2 profile.
fn v2_robots() -> Vec<(RobotKind, V2Profile)> {
    let robots: Vec<_> = RobotKind::ALL
        .iter()
        .filter_map(|r| {
            let profile = r.entry().default_profile(Some(crate::Protocol::V2)).ok()?;
            Some((*r, profile.get::<V2Profile>()?.clone()))
        })
        .collect();
    assert_eq!(
        robots.len(),
        8,
        "HUNTER 2.0, HUNTER SE, TRACER, TRACER MINI, BUNKER, RANGER MINI, SCOUT 2.0, SCOUT MINI V2"
    );
    robots
}

/// The column of §2.3.2 each robot follows (⚠ D-3, the reading's defaults).
fn table_of(robot: RobotKind) -> &'static [Row] {
    match robot {
        RobotKind::Scout | RobotKind::ScoutMini | RobotKind::Bunker | RobotKind::RangerMini => SDK,
        RobotKind::Hunter => HUNTER_2,
        RobotKind::HunterSe => HUNTER_SE,
        RobotKind::Tracer | RobotKind::TracerMini => TRACER_MINI,
        other => panic!("{other:?} does not speak V2"),
    }
}

fn describe(profile: &V2Profile, text: &str) -> FrameJson {
    Profile::from(profile.clone())
        .codec()
        .decode_can(&CanFrame::from_candump(text).unwrap())
        .unwrap()
}

fn status(vehicle_state: u8, mode: u8, word: u16, b6: u8) -> String {
    format!("211#{vehicle_state:02X}{mode:02X}0100{word:04X}{b6:02X}00")
}

fn names(flags: u64) -> Value {
    json!(F::names(flags))
}

/// `faults` and `warnings` together, as the describer splits them.
fn all_faults(json: &FrameJson) -> Vec<String> {
    ["faults", "warnings"]
        .iter()
        .flat_map(|k| json[*k].as_array().unwrap().clone())
        .map(|v| v.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn tv8_a_bunker_mini_with_its_estop_pressed_decodes_with_the_estop_named() {
    let json = describe(
        &V2Profile::for_model(V2Model::Bunker),
        "211#0100010000800000",
    );
    assert_eq!(json["vehicle_state"], 1);
    assert_eq!(json["vehicle"], "estop");
    assert_eq!(json["control"], "standby");
    assert_eq!(json["fault_word"], 0x0080);
    assert_eq!(json["fault_bits"], json!(["estop"]));
    assert_eq!(json["faults"], json!(["emergency_stop"]));
    assert_eq!(json["warnings"], json!([]));
    // TV12: the same E-stop after 0x421, in CAN mode.
    let json = describe(
        &V2Profile::for_model(V2Model::Bunker),
        "211#010100FE00800000",
    );
    assert_eq!(
        (&json["vehicle"], &json["control"], &json["fault_bits"]),
        (&json!("estop"), &json!("can"), &json!(["estop"]))
    );
}

#[test]
fn every_fault_bit_of_every_v2_robot_decodes_with_the_name_its_table_gives_it() {
    for (robot, profile) in v2_robots() {
        let table = table_of(robot);
        for n in 0..16 {
            let mask = 1u16 << n;
            let json = describe(&profile, &status(0, 0, mask, 0));
            match table.iter().find(|(m, _, _)| *m == mask) {
                Some((_, name, flag)) => {
                    assert_eq!(json["fault_bits"], json!([name]), "{robot:?} {mask:#06x}");
                    assert_eq!(all_faults(&json), F::names(*flag), "{robot:?} {name}");
                }
                None => {
                    let unnamed = if n >= 8 {
                        format!("b4_bit{}", n - 8)
                    } else {
                        format!("b5_bit{n}")
                    };
                    assert_eq!(json["fault_bits"], json!([unnamed]), "{robot:?}");
                    assert!(all_faults(&json).is_empty(), "{robot:?} {mask:#06x}");
                }
            }
        }
        // All of them at once: every name, in the table's order (b4 bit0 … b5 bit7).
        let word = table.iter().fold(0, |w, (m, _, _)| w | m);
        let mut expected: Vec<_> = table.to_vec();
        expected.sort_by_key(|(m, _, _)| (m.trailing_zeros() + 8) % 16);
        let expected: Vec<_> = expected.iter().map(|(_, name, _)| *name).collect();
        let json = describe(&profile, &status(0, 0, word, 0));
        assert_eq!(json["fault_bits"], json!(expected), "{robot:?}");
    }
    // The SCOUT v1.3.0 / TRACER v1.2 table, which no robot's default uses.
    let profile = V2Profile {
        fault_map: profile::FaultMap::ScoutV13,
        ..V2Profile::default()
    };
    for (mask, name, flag) in SCOUT_V13 {
        let json = describe(&profile, &status(0, 0, *mask, 0));
        assert_eq!(json["fault_bits"], json!([name]));
        assert_eq!(all_faults(&json), F::names(*flag));
    }
    let json = describe(&profile, &status(0, 0, 0x0080, 0));
    assert_eq!(json["fault_bits"], json!(["b5_bit7"]));
}

#[test]
fn d20_reads_bit_0080_as_the_steering_encoder_where_the_profile_says_so() {
    for model in [V2Model::Bunker, V2Model::HunterSe] {
        let profile = V2Profile {
            fault_0080_is_estop: false,
            ..V2Profile::for_model(model)
        };
        let json = describe(&profile, &status(0, 0, 0x0080, 0));
        assert_eq!(json["fault_bits"], json!(["steering_encoder"]), "{model:?}");
        assert_eq!(json["faults"], names(F::FRONT_STEERING_ENCODER));
    }
    // HUNTER 2.0's own table names the bit: ⚠ D-20 does not apply.
    let json = describe(
        &V2Profile::for_model(V2Model::Hunter),
        &status(0, 0, 0x0080, 0),
    );
    assert_eq!(json["fault_bits"], json!(["motor_over_current"]));
}

#[test]
fn the_vehicle_state_and_the_control_mode_are_named_per_robot() {
    for (robot, profile) in v2_robots() {
        for (state, name, flags) in [
            (0x00, "normal", 0),
            (0x01, "estop", F::EMERGENCY_STOP),
            (0x02, "exception", F::BODY_EXCEPTION),
            (0x07, "unknown", F::BODY_EXCEPTION),
        ] {
            let json = describe(&profile, &status(state, 1, 0, 0));
            assert_eq!(json["vehicle"], name, "{robot:?}");
            assert_eq!(json["faults"], names(flags), "{robot:?} {name}");
        }
        // ⚠ D-2: HUNTER 2.0 numbers RC 2, the others 3 (and 2 is serial / APP).
        let modes: &[(u8, &str)] = if robot == RobotKind::Hunter {
            &[(0, "standby"), (1, "can"), (2, "rc"), (3, "unknown")]
        } else {
            &[(0, "standby"), (1, "can"), (2, "uart"), (3, "rc")]
        };
        for (code, name) in modes {
            let json = describe(&profile, &status(0, *code, 0, 0));
            assert_eq!(json["control"], *name, "{robot:?} mode {code}");
        }
    }
}

#[test]
fn hunter_2_reports_its_brake_in_b6_and_the_others_do_not() {
    for (robot, profile) in v2_robots() {
        let json = describe(&profile, &status(0, 1, 0, 1));
        if robot == RobotKind::Hunter {
            assert_eq!(json["parking_brake_engaged"], true);
            let json = describe(&profile, &status(0, 1, 0, 0));
            assert_eq!(json["parking_brake_engaged"], false);
        } else {
            assert!(!json.contains_key("parking_brake_engaged"), "{robot:?}");
        }
    }
}

#[test]
fn driver_status_bits_are_named_after_d7() {
    for (robot, profile) in v2_robots() {
        // b5 = 0x40: HUNTER 2.0 reads bit 6 as "disabled" (H2X), the others as "enabled".
        let json = describe(&profile, "261#01E0001E1E400000");
        let enabled = robot != RobotKind::Hunter;
        assert_eq!(json["driver_enabled"], enabled, "{robot:?}");
        let expected: &[&str] = if enabled { &["enabled"] } else { &[] };
        assert_eq!(json["driver_status_flags"], json!(expected), "{robot:?}");
        // b5 = 0xBD: every fault bit, and bit 7 (SDK "driver reset"), unnamed by the contract.
        let json = describe(&profile, "261#01E0001E1EBD0000");
        let mut expected = vec![
            "supply_under_voltage",
            "driver_over_current",
            "driver_over_temperature",
            "sensor_fault",
            "driver_error",
        ];
        if !enabled {
            expected.push("enabled");
        }
        expected.push("bit7");
        assert_eq!(json["driver_status_flags"], json!(expected), "{robot:?}");
    }
}

#[test]
fn bms_alarms_and_the_older_protection_codes_are_named() {
    for (robot, profile) in v2_robots() {
        let json = describe(&profile, "362#04010800");
        assert_eq!(
            json["alarms"],
            json!(["under_voltage", "charge_over_current"]),
            "{robot:?}"
        );
        assert_eq!(json["warnings"], json!(["over_temperature"]), "{robot:?}");
    }
    // ⚠ D-6, the older layout: protection codes 1-4, cell temperatures, count.
    let profile = V2Profile {
        bms_alarm_layout: profile::BmsAlarmLayout::ProtectionCodes,
        ..V2Profile::for_model(V2Model::Bunker)
    };
    let json = describe(&profile, "362#2120040219120005");
    assert_eq!(json["frame"], "bms_protection");
    assert_eq!(
        json["protections"],
        json!([
            "discharging_over_current",
            "cell_under_voltage",
            "charging_over_temperature"
        ])
    );
    assert_eq!(
        json["states"],
        json!(["charging_current", "discharging_mos_on"])
    );
}

#[test]
fn ranger_motion_modes_lights_and_rc_levers_are_named() {
    let ranger = V2Profile::for_model(V2Model::RangerMini);
    for (code, name) in [
        (0, "dual_ackermann"),
        (1, "crab"),
        (2, "spin"),
        (3, "park"),
        (4, "side_slip"),
        (9, "unknown"),
    ] {
        let json = describe(&ranger, &format!("291#{code:02X}00"));
        assert_eq!(json["motion_mode"], name);
        let json = describe(&ranger, &format!("141#{code:02X}00000000000000"));
        assert_eq!(json["motion_mode"], name);
    }
    // ⚠ D-12: on RANGER MINI 1.0, 3 is side-slip.
    let v1 = V2Profile::for_model(V2Model::RangerMiniV1);
    assert_eq!(describe(&v1, "291#0300")["motion_mode"], "side_slip");
    let json = describe(&ranger, "231#0101000200000007");
    assert_eq!(
        (&json["front_light"], &json["rear_light"]),
        (&json!("on"), &json!("breathing"))
    );
    // TRACER has a front light only.
    let tracer = V2Profile::for_model(V2Model::Tracer);
    let json = describe(&tracer, "231#0103320000000000");
    assert_eq!(json["front_light"], "custom");
    assert!(!json.contains_key("rear_light"));
    // TV10: every lever up; then SWB middle, SWC down, SWD without data.
    let bunker = V2Profile::for_model(V2Model::Bunker);
    let json = describe(&bunker, "241#AA00000000000061");
    assert_eq!(
        json["switches"],
        json!({"swa": "up", "swb": "up", "swc": "up", "swd": "up"})
    );
    let json = describe(&bunker, "241#3600000000000000");
    assert_eq!(
        json["switches"],
        json!({"swa": "up", "swb": "middle", "swc": "down", "swd": "none"})
    );
}

fn feed(driver: &mut V2Driver, now: Timestamp, text: &str) {
    driver.handle_rx(now, Rx::Can(&CanFrame::from_candump(text).unwrap()));
}

#[test]
fn every_v2_robots_driver_state_names_the_estop_its_faults_mode_driver_status_and_bms_alarms() {
    for (robot, profile) in v2_robots() {
        let mut d = V2Driver::new(profile.clone(), DriverConfig::default(), T0);
        let mut now = T0;
        let mut rx = |d: &mut V2Driver, text: &str| {
            now += std::time::Duration::from_millis(10);
            feed(d, now, text);
        };
        // TV8's vehicle state on every robot: the E-stop is set, named and in the body status.
        rx(&mut d, &status(0x01, 0, 0, 0));
        let sys = d.state().system;
        assert_ne!(sys.fault_flags & F::EMERGENCY_STOP, 0, "{robot:?}");
        assert!(
            F::names(sys.fault_flags).contains(&"emergency_stop"),
            "{robot:?}"
        );
        assert_eq!(
            sys.body_status,
            SystemState::BODY_EMERGENCY_STOP,
            "{robot:?}"
        );
        rx(&mut d, &status(0x02, 0, 0, 0));
        let sys = d.state().system;
        assert_eq!(sys.fault_flags, F::BODY_EXCEPTION, "{robot:?}");
        assert_eq!(sys.body_status, SystemState::BODY_EXCEPTION, "{robot:?}");
        // Every fault bit of the robot's table, alone: its flag, by name; the vendor's word kept.
        for (mask, name, flag) in table_of(robot) {
            rx(&mut d, &status(0, 0, *mask, 0));
            let sys = d.state().system;
            assert_eq!(
                F::names(sys.fault_flags),
                F::names(*flag),
                "{robot:?} {name}"
            );
            assert_eq!(sys.vendor_fault_word, u32::from(*mask), "{robot:?} {name}");
            assert_eq!(sys.body_status, SystemState::BODY_NORMAL, "{robot:?}");
        }
        // The control mode, normalized (⚠ D-2).
        let modes: &[(u8, u8)] = if robot == RobotKind::Hunter {
            &[
                (0, ControlMode::STANDBY),
                (1, ControlMode::COMMAND),
                (2, ControlMode::REMOTE),
                (3, ControlMode::UNKNOWN),
            ]
        } else {
            &[
                (0, ControlMode::STANDBY),
                (1, ControlMode::COMMAND),
                (2, ControlMode::SERIAL),
                (3, ControlMode::REMOTE),
            ]
        };
        for (code, mode) in modes {
            rx(&mut d, &status(0, *code, 0, 0));
            assert_eq!(
                ControlMode::name(d.state().system.control_mode),
                ControlMode::name(*mode),
                "{robot:?} mode {code}"
            );
        }
        // Driver status: "enabled" per ⚠ D-7, the fault bits as sent.
        rx(&mut d, "261#01E0001E1E410000");
        let status_bits = d.state().motors[0].driver_status;
        let enabled = robot != RobotKind::Hunter;
        assert_eq!(
            status_bits & DriverStatus::ENABLED != 0,
            enabled,
            "{robot:?}"
        );
        assert_ne!(
            status_bits & DriverStatus::SUPPLY_UNDER_VOLTAGE,
            0,
            "{robot:?}"
        );
        // BMS alarms: kept by byte, and named among the faults once 0x211 comes.
        rx(&mut d, "362#04010800");
        rx(&mut d, &status(0, 1, 0, 0));
        let s = d.state();
        assert_eq!(s.bms[0].alarm_flags, 0x0008_0104, "{robot:?}");
        assert_eq!(
            F::names(s.system.fault_flags),
            vec!["bms_alarm"],
            "{robot:?}"
        );
        rx(&mut d, "362#00000000");
        rx(&mut d, &status(0, 1, 0, 0));
        assert_eq!(d.state().system.fault_flags, 0, "{robot:?}");
    }
}

#[test]
fn the_older_bms_layout_raises_the_bms_alarm_on_a_protection_not_on_a_state() {
    let profile = V2Profile {
        bms_alarm_layout: profile::BmsAlarmLayout::ProtectionCodes,
        ..V2Profile::for_model(V2Model::Bunker)
    };
    let mut d = V2Driver::new(profile, DriverConfig::default(), T0);
    let ms = |n| T0 + std::time::Duration::from_millis(n);
    // Current flowing and both MOS switches on: a working battery.
    feed(&mut d, ms(10), "362#1100000319120005");
    feed(&mut d, ms(20), &status(0, 1, 0, 0));
    assert_eq!(d.state().system.fault_flags, 0);
    // Cell under-voltage protection.
    feed(&mut d, ms(30), "362#1120000319120005");
    feed(&mut d, ms(40), &status(0, 1, 0, 0));
    assert_eq!(d.state().system.fault_flags, F::BMS_ALARM);
}
