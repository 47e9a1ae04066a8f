//! The cited test vectors of AgileX protocol V2 (docs/PROTOCOLS.md, "AgileX protocol V2",
//! TV1-TV17) through the command-line tools: `chassis decode --robot R` reads each one, and
//! `chassis encode` prints exactly the vector's bytes for the commands it can express. The V1
//! SCOUT MINI example still decodes as V1 (count and checksum) without `--protocol`.

use chassis_protocols::RobotKind;
use chassis_tests::Env;

/// Each AgileX protocol (`v1`, `v2`) each robot of the registry speaks, by the robot's name.
fn registry_protocols() -> Vec<(&'static str, &'static str)> {
    RobotKind::ALL
        .into_iter()
        .flat_map(|kind| {
            kind.entry()
                .profiles()
                .filter_map(move |p| Some((kind.name(), p.protocol()?.name())))
        })
        .collect()
}

/// One vector: robot (and protocol flag), frame, fields `chassis decode` must report, and the
/// `chassis encode` arguments that print the same frame (empty: a report, or no such command).
struct Vector {
    name: &'static str,
    robot: &'static [&'static str],
    frame: &'static str,
    decoded: &'static [&'static str],
    encode: &'static [&'static str],
}

const VECTORS: &[Vector] = &[
    Vector {
        name: "TV1",
        robot: &["hunter"],
        frame: "111#0096000000000000",
        decoded: &[r#""frame":"motion_command""#, r#""linear_mps":0.15,"#],
        encode: &["velocity", "--vx", "0.15"],
    },
    Vector {
        name: "TV2",
        robot: &["hunter"],
        frame: "111#00000000000000C8",
        decoded: &[r#""linear_mps":0.0"#, r#""steer_rad":0.2"#],
        encode: &["velocity", "--steer", "0.2"],
    },
    Vector {
        name: "TV3",
        robot: &["scout"],
        frame: "111#0000003200000000",
        decoded: &[r#""angular_radps":0.05,"#],
        encode: &["velocity", "--wz", "0.05"],
    },
    Vector {
        name: "TV4",
        robot: &["bunker"],
        frame: "111#000000C800000000",
        decoded: &[r#""angular_radps":0.2,"#],
        encode: &["velocity", "--wz", "0.2"],
    },
    Vector {
        name: "TV5",
        robot: &["bunker"],
        frame: "111#00FA000000000000",
        decoded: &[r#""linear_mps":0.25,"#, r#""lateral_mps":0.0"#],
        encode: &["velocity", "--vx", "0.25"],
    },
    Vector {
        name: "TV6",
        robot: &["bunker"],
        frame: "421#0100000000000000",
        decoded: &[r#""frame":"mode""#, r#""can":true"#],
        encode: &["mode", "command"],
    },
    Vector {
        name: "TV7",
        robot: &["bunker"],
        frame: "421#0000000000000000",
        decoded: &[r#""can":false"#],
        encode: &["mode", "standby"],
    },
    Vector {
        name: "TV8",
        robot: &["bunker"],
        frame: "211#0100010000800000",
        decoded: &[
            r#""vehicle_state":1"#,
            r#""vehicle":"estop""#,
            r#""control":"standby""#,
            r#""battery_voltage_v":25.6"#,
            r#""fault_word":128"#,
            r#""fault_bits":["estop"]"#,
            r#""faults":["emergency_stop"]"#,
        ],
        encode: &[],
    },
    Vector {
        name: "TV9",
        robot: &["bunker"],
        frame: "221#0000000000000000",
        decoded: &[r#""frame":"motion_feedback""#, r#""linear_mps":0.0"#],
        encode: &[],
    },
    Vector {
        name: "TV10",
        robot: &["bunker"],
        frame: "241#AA00000000000061",
        decoded: &[
            r#""switch_a":2"#,
            r#""switch_b":2"#,
            r#""switch_c":2"#,
            r#""switch_d":2"#,
            r#""counter":97"#,
        ],
        encode: &[],
    },
    Vector {
        name: "TV11",
        robot: &["bunker"],
        frame: "311#0000000000000000",
        decoded: &[
            r#""frame":"odometer""#,
            r#""left_m":0.0"#,
            r#""right_m":0.0"#,
        ],
        encode: &[],
    },
    Vector {
        name: "TV12",
        robot: &["bunker"],
        frame: "211#010100FE00800000",
        decoded: &[
            r#""vehicle":"estop""#,
            r#""control":"can""#,
            r#""battery_voltage_v":25.4"#,
            r#""fault_bits":["estop"]"#,
        ],
        encode: &[],
    },
    Vector {
        name: "TV13",
        robot: &["tracer"],
        frame: "121#0100000000000000",
        decoded: &[
            r#""frame":"light_command""#,
            r#""enabled":true"#,
            r#""front_mode":0"#,
        ],
        encode: &["lights", "off"],
    },
    Vector {
        name: "TV14",
        robot: &["scout-mini", "--protocol", "v2"],
        frame: "4A1#01",
        decoded: &[r#""frame":"sdk_version_request""#],
        encode: &[],
    },
    Vector {
        name: "TV15",
        robot: &["scout"],
        frame: "411#01",
        decoded: &[r#""frame":"version_request""#],
        encode: &[],
    },
    Vector {
        name: "TV16",
        robot: &["hunter"],
        frame: "431#AA",
        decoded: &[r#""frame":"steering_zero""#],
        encode: &["steering-zero"],
    },
    Vector {
        name: "TV16 reply",
        robot: &["hunter"],
        frame: "43A#EE",
        decoded: &[r#""frame":"steering_zero_ack""#, r#""done":true"#],
        encode: &[],
    },
    Vector {
        name: "TV17",
        robot: &["hunter-se"],
        frame: "433#AA",
        decoded: &[r#""frame":"steering_zero_query""#],
        encode: &[],
    },
];

#[test]
fn every_cited_v2_vector_decodes_and_the_commands_encode_to_its_bytes() {
    let env = Env::new("protocol-v2");
    for v in VECTORS {
        let mut args = vec!["decode", "--robot"];
        args.extend_from_slice(v.robot);
        args.push(v.frame);
        let json = env.chassis_ok(&args).trim().to_string();
        assert!(json.contains(r#""protocol":"v2""#), "{}: {json}", v.name);
        for field in v.decoded {
            assert!(json.contains(field), "{}: {field} not in {json}", v.name);
        }
        if !v.encode.is_empty() {
            let mut args = vec!["encode", "--robot"];
            args.extend_from_slice(v.robot);
            args.extend_from_slice(v.encode);
            let lines = env.chassis_ok(&args).trim().to_string();
            assert_eq!(lines.lines().last(), Some(v.frame), "{}: {args:?}", v.name);
        }
    }
}

#[test]
fn the_v1_example_stays_v1_and_v2_is_only_on_request() {
    let env = Env::new("protocol-v1");
    // 0x130 with a valid V1 checksum in b7: the SCOUT MINI's default protocol.
    let json = env
        .chassis_ok(&["decode", "--robot", "scout-mini", "130#01000a0000000044"])
        .trim()
        .to_string();
    assert!(json.contains(r#""count":0"#), "{json}");
    assert!(!json.contains(r#""protocol":"v2""#), "{json}");
    // The same robot with --protocol v2 speaks V2.
    let v2 = env
        .chassis_ok(&[
            "encode",
            "--robot",
            "scout-mini",
            "--protocol",
            "v2",
            "velocity",
            "--vx",
            "0.03",
        ])
        .trim()
        .to_string();
    assert_eq!(v2, "111#001E000000000000");
    // A robot without V1 firmware support refuses --protocol v1.
    let out = env.chassis(&["decode", "--robot", "hunter", "--protocol", "v1", "111#00"]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("hunter does not speak protocol v1"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn chassis_detect_classifies_the_v1_example_as_v1_and_the_v2_capture_as_v2() {
    let env = Env::new("protocol-detect");
    let v1 = "130#01000A0000000044";
    assert_eq!(env.chassis_ok(&["detect", v1, v1, v1]).trim(), "v1");
    let capture = [
        "detect",
        "211#0100010000800000",
        "221#0000000000000000",
        "241#AA00000000000061",
        "311#0000000000000000",
    ];
    assert_eq!(env.chassis_ok(&capture).trim(), "v2");
    // A frame both protocols use proves nothing: no decision, exit 1, the ids heard named.
    let out = env.chassis(&["detect", "211#0100010000800000"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("heard 0x211×1"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Every V2 robot's `chassis decode` names an E-stop vehicle state (0x211 b0 = 0x01, fault word
/// 0) and the bit of its own fault table that says "RC link lost" (`PROTOCOLS-V2` §2.3.2).
#[test]
fn every_v2_robot_names_the_estop_and_its_own_fault_bits() {
    let env = Env::new("protocol-v2-names");
    let cases: [(&str, &str, &str); 8] = [
        ("scout", "211#0001010000040000", "rc_signal_lost"),
        ("scout-mini", "211#0001010000040000", "rc_signal_lost"),
        ("bunker", "211#0001010000040000", "rc_signal_lost"),
        ("ranger-mini", "211#0001010000040000", "rc_signal_lost"),
        ("tracer", "211#0001010000040000", "rc_link_lost"),
        ("tracer-mini", "211#0001010000040000", "rc_link_lost"),
        ("hunter-se", "211#0001010000040000", "rc_link_lost"),
        ("hunter", "211#0001010004000000", "rc_link_lost"),
    ];
    // Every robot of the registry that speaks V2 has its case: a new one is not left out.
    for (robot, protocol) in registry_protocols() {
        assert!(
            protocol != "v2" || cases.iter().any(|(r, _, _)| *r == robot),
            "{robot} speaks V2 and has no case"
        );
    }
    for (robot, rc_lost, name) in cases {
        let decode = |frame: &str| {
            env.chassis_ok(&["decode", "--robot", robot, "--protocol", "v2", frame])
                .trim()
                .to_string()
        };
        let json = decode("211#0100010000000000");
        for field in [
            r#""vehicle":"estop""#,
            r#""fault_bits":[]"#,
            r#""faults":["emergency_stop"]"#,
        ] {
            assert!(json.contains(field), "{robot}: {field} not in {json}");
        }
        let json = decode(rc_lost);
        for field in [
            r#""vehicle":"normal""#,
            &format!(r#""fault_bits":["{name}"]"#),
            r#""faults":[]"#,
            r#""warnings":["rc_link_lost"]"#,
        ] {
            assert!(json.contains(field), "{robot}: {field} not in {json}");
        }
    }
}

/// Every AgileX robot in each protocol it speaks: `chassis encode` prints the frames of a
/// velocity command, and `chassis decode` reads each back as that robot's, in that protocol,
/// with the speed asked for.
#[test]
fn every_agilex_robot_encodes_and_decodes_in_each_of_its_protocols() {
    let env = Env::new("protocol-each");
    let cases: [(&str, &str, &[&str], &str); 13] = [
        ("scout-mini", "v1", &["--vx", "0.5"], r#""linear_mps":0.5"#),
        (
            "scout-mini",
            "v2",
            &["--vx", "0.5", "--wz", "0.2"],
            r#""angular_radps":0.2"#,
        ),
        ("scout", "v1", &["--vx", "0.3"], r#""linear_mps":0.3"#),
        (
            "scout",
            "v2",
            &["--vx", "0.3", "--wz", "0.2"],
            r#""angular_radps":0.2"#,
        ),
        ("bunker", "v1", &["--vx", "0.3"], r#""linear_mps":0.3"#),
        (
            "bunker",
            "v2",
            &["--vx", "0.3", "--wz", "0.2"],
            r#""angular_radps":0.2"#,
        ),
        (
            "hunter",
            "v2",
            &["--vx", "0.5", "--steer", "0.2"],
            r#""steer_rad":0.2"#,
        ),
        (
            "hunter-se",
            "v2",
            &["--vx", "0.5", "--steer", "0.2"],
            r#""steer_rad":0.2"#,
        ),
        (
            "tracer",
            "v2",
            &["--vx", "0.5", "--wz", "0.2"],
            r#""angular_radps":0.2"#,
        ),
        (
            "tracer-mini",
            "v2",
            &["--vx", "0.5", "--wz", "0.2"],
            r#""angular_radps":0.2"#,
        ),
        ("ranger-mini", "v2", &["--vx", "0.5"], r#""linear_mps":0.5"#),
        ("ranger-mini", "v2", &["--vy", "0.3"], r#""linear_mps":0.3"#),
        (
            "ranger-mini",
            "v2",
            &["--wz", "0.5"],
            r#""angular_radps":0.5"#,
        ),
    ];
    // Every protocol of every AgileX robot of the registry has its case.
    for (robot, protocol) in registry_protocols() {
        assert!(
            cases
                .iter()
                .any(|(r, p, _, _)| (*r, *p) == (robot, protocol)),
            "{robot} speaks {protocol} and has no case"
        );
    }
    for (robot, protocol, velocity, expected) in cases {
        let mut args = vec![
            "encode",
            "--robot",
            robot,
            "--protocol",
            protocol,
            "velocity",
        ];
        args.extend_from_slice(velocity);
        let lines = env.chassis_ok(&args).trim().to_string();
        assert!(!lines.is_empty(), "{robot} {protocol}: nothing encoded");
        let mut motion = None;
        for line in lines.lines() {
            let json = env
                .chassis_ok(&["decode", "--robot", robot, "--protocol", protocol, line])
                .trim()
                .to_string();
            assert!(
                json.contains(&format!(r#""robot":"{robot}""#)),
                "{robot}: {json}"
            );
            // V2 frames say so; V1 frames carry their count byte instead.
            match protocol {
                "v2" => assert!(json.contains(r#""protocol":"v2""#), "{json}"),
                _ => assert!(json.contains(r#""count":0"#), "{json}"),
            }
            if json.contains(r#""frame":"motion_command""#) {
                motion = Some(json);
            }
        }
        let motion = motion.unwrap_or_else(|| panic!("{robot} {protocol}: no motion in {lines}"));
        assert!(
            motion.contains(expected),
            "{robot} {protocol} {velocity:?}: {motion}"
        );
    }
}
