//! Every example frame of the manuals (docs/PROTOCOLS.md) through the command-line tools:
//! `chassis encode` prints exactly the manual's bytes for the command the example describes, and
//! `chassis decode` turns the manual's bytes back into that command.

use chassis_tests::Env;

/// One manual example: the robot, the `chassis encode` arguments, the manual's frame as
/// `chassis encode` prints it, and fields `chassis decode` must report for it.
struct Example {
    robot: &'static str,
    encode: &'static [&'static str],
    frame: &'static str,
    decoded: &'static [&'static str],
}

const EXAMPLES: &[Example] = &[
    // TITAN 0x111: 150 mm/s forward, steering 0.
    Example {
        robot: "titan",
        encode: &["velocity", "--vx", "0.15"],
        frame: "111#0096000000000000",
        decoded: &[
            r#""frame":"motion_command""#,
            r#""linear_mps":0.15"#,
            r#""steer_rad":0.0"#,
        ],
    },
    // SCOUT MINI 0x130, count 0, checksums as printed.
    Example {
        robot: "scout-mini",
        encode: &["velocity", "--vx", "0.5"],
        frame: "130#01000A0000000044",
        decoded: &[r#""count":0"#, r#""mode":1"#, r#""linear_mps":0.5"#],
    },
    Example {
        robot: "scout-mini",
        encode: &["velocity", "--wz", "0.05235"],
        frame: "130#0100000A00000044",
        decoded: &[r#""linear_mps":0.0"#, r#""angular_radps":0.05235"#],
    },
    Example {
        robot: "scout-mini",
        encode: &["mode", "command"],
        frame: "130#010000000000003A",
        decoded: &[
            r#""mode":1"#,
            r#""linear_mps":0.0"#,
            r#""angular_radps":0.0"#,
        ],
    },
    // XBot, serial frames as hex.
    Example {
        robot: "xbot",
        encode: &["power", "on"],
        frame: "AA 55 02 01 01 02",
        decoded: &[r#""frame":"power""#, r#""enable":true"#],
    },
    Example {
        robot: "xbot",
        encode: &["power", "off"],
        frame: "AA 55 02 01 00 03",
        decoded: &[r#""frame":"power""#, r#""enable":false"#],
    },
    Example {
        robot: "xbot",
        encode: &["velocity", "--vx", "0.2"],
        frame: "AA 55 0D 03 CD CC 4C 3E 00 00 00 00 00 00 00 00 7D",
        decoded: &[r#""frame":"velocity""#, r#""linear_x_mps":0.2000000029"#],
    },
    Example {
        robot: "xbot",
        encode: &["velocity", "--vx=-0.2"],
        frame: "AA 55 0D 03 CD CC 4C BE 00 00 00 00 00 00 00 00 FD",
        decoded: &[r#""linear_x_mps":-0.2000000029"#],
    },
    Example {
        robot: "xbot",
        encode: &["lift", "--position", "0"],
        frame: "AA 55 03 04 01 00 06",
        decoded: &[r#""frame":"lift""#, r#""position_pct":0.0"#],
    },
    Example {
        robot: "xbot",
        encode: &["lift", "--position", "100"],
        frame: "AA 55 03 04 01 64 62",
        decoded: &[r#""position_pct":100.0"#],
    },
    Example {
        robot: "xbot",
        encode: &["lift", "--position", "10"],
        frame: "AA 55 03 04 01 0A 0C",
        decoded: &[r#""position_pct":10.0"#],
    },
    // The manual's servo angles are 0-180 with 90 straight ahead; ours are left/up positive.
    Example {
        robot: "xbot",
        encode: &["servos", "--pan", "90", "--tilt", "0"],
        frame: "AA 55 03 05 00 5A 5C",
        decoded: &[
            r#""frame":"servos""#,
            r#""pan_rad":1.5707963"#,
            r#""tilt_rad":0.0"#,
        ],
    },
    Example {
        robot: "xbot",
        encode: &["servos", "--pan", "0", "--tilt=-90"],
        frame: "AA 55 03 05 5A 00 5C",
        decoded: &[r#""pan_rad":0.0"#, r#""tilt_rad":-1.5707963"#],
    },
    Example {
        robot: "xbot",
        encode: &["servos", "--pan=-90", "--tilt", "90"],
        frame: "AA 55 03 05 B4 B4 06",
        decoded: &[r#""pan_rad":-1.5707963"#, r#""tilt_rad":1.5707963"#],
    },
];

/// The manual's XBot sensor frame (a report, so decoded only).
const XBOT_SENSOR: &str = concat!(
    "AA 55 47 10 01 62 26 03 02 00 01 00 00 00 05 0A 00 06 00 00 00 00 00 06 00 ",
    "03 00 00 00 00 00 00 05 00 00 00 00 00 00 00 00 E8 03 01 00 00 00 00 00 00 ",
    "00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 02 DC 2F",
);

#[test]
fn chassis_encode_prints_every_manual_example_and_chassis_decode_reads_it_back() {
    let env = Env::new("manual");
    for example in EXAMPLES {
        let mut args = vec!["encode", "--robot", example.robot];
        args.extend_from_slice(example.encode);
        assert_eq!(
            env.chassis_ok(&args).trim(),
            example.frame,
            "chassis {args:?}"
        );

        let json = env
            .chassis_ok(&["decode", "--robot", example.robot, example.frame])
            .trim()
            .to_string();
        for field in example.decoded {
            assert!(
                json.contains(field),
                "{} {}: {field} not in {json}",
                example.robot,
                example.frame
            );
        }
    }
}

#[test]
fn chassis_decode_reads_the_manuals_xbot_sensor_frame() {
    let env = Env::new("manual-sensor");
    let json = env
        .chassis_ok(&["decode", "--robot", "xbot", XBOT_SENSOR])
        .trim()
        .to_string();
    for field in [
        r#""frame":"sensor""#,
        r#""battery_voltage_v":26.62"#,
        r#""ir_m":[0.002,0.001,0.0]"#,
        r#""motor_current_a":[1.0,0.6,0.0,0.0]"#,
        r#""lift_current_a":0.6"#,
        r#""lift_encoder_counts":1000"#,
    ] {
        assert!(json.contains(field), "{field} not in {json}");
    }
}
