//! Every robot of the registry, walked whole: a robot missing anywhere fails here.

use std::time::Duration;

use chassis_interfaces::{Kinematics, MAX_JOINTS, MAX_SENSORS, Velocity, WireProtocol};

use super::*;
use crate::CanFrame;
use crate::description::describe;
use crate::family::Family;
use crate::profile::ProfileError;

/// The robot's default profile in each protocol it speaks, its default one first.
fn every_profile(entry: &RobotEntry) -> Vec<Profile> {
    entry.profiles().collect()
}

#[test]
fn every_kind_has_an_entry_that_names_it_back() {
    let mut names = std::collections::HashSet::new();
    for kind in RobotKind::ALL {
        let entry = kind.entry();
        assert_eq!(entry.kind, kind);
        assert_eq!(RobotKind::from_id(kind.id()), Some(kind));
        assert_eq!(kind.name().parse::<RobotKind>(), Ok(kind));
        assert!(names.insert(kind.name()), "{kind} named twice");
        assert!(!entry.profiles.is_empty(), "{kind} has no profile");
        assert!(!entry.display_name.is_empty(), "{kind}");
        assert!(entry.sensors.len() <= MAX_SENSORS, "{kind}");
        assert!(entry.joints.len() <= MAX_JOINTS, "{kind}");
        assert!(
            entry.outline.length_m > 0.0 && entry.outline.width_m > 0.0,
            "{kind}"
        );
    }
    assert_eq!(RobotKind::from_id(0), None);
    assert!("husky".parse::<RobotKind>().is_err());
}

/// Every protocol-V1 and V2 model is some robot's: a model added to its family without a
/// registry entry fails here (the match below stops compiling when a model is added, a reminder
/// to add it to `V2Model::ALL`).
#[test]
fn every_protocol_model_belongs_to_one_robot() {
    use crate::agilex_v2::V2Model;
    fn listed(model: V2Model) -> V2Model {
        match model {
            V2Model::Scout
            | V2Model::ScoutMini
            | V2Model::ScoutMiniOmni
            | V2Model::Hunter
            | V2Model::HunterSe
            | V2Model::Tracer
            | V2Model::Bunker
            | V2Model::RangerMini
            | V2Model::RangerMiniV1
            | V2Model::TracerMini => model,
        }
    }
    for model in V2Model::ALL.map(listed) {
        let robot = model.robot();
        let mut table = toml::Table::new();
        table.insert("model".into(), crate::family::kebab(&model).into());
        let profile = robot
            .entry()
            .profile_from_table(Some(Protocol::V2), &table)
            .unwrap_or_else(|e| panic!("{model:?}: {e}"));
        assert_eq!(profile.get::<V2Profile>().map(|p| p.model), Some(model));
    }
    for model in [V1Model::ScoutMini, V1Model::Scout, V1Model::Bunker] {
        let profile = model
            .robot()
            .entry()
            .default_profile(Some(Protocol::V1))
            .unwrap_or_else(|e| panic!("{model:?}: {e}"));
        assert_eq!(profile.get::<V1Profile>().map(|p| p.model), Some(model));
    }
}

#[test]
fn every_robot_defaults_to_a_valid_profile_of_its_own_kind_in_each_of_its_protocols() {
    for kind in RobotKind::ALL {
        let entry = kind.entry();
        let defaults = entry.defaults();
        assert_eq!(defaults.robot(), kind);
        assert_eq!(defaults.validate(), Ok(()), "{kind}");
        let protocols: Vec<Protocol> = entry.profiles().filter_map(|p| p.protocol()).collect();
        assert_eq!(entry.detects_protocol(), protocols.len() == 2, "{kind}");
        for &protocol in &protocols {
            let profile = entry.default_profile(Some(protocol)).unwrap();
            assert_eq!(
                (profile.robot(), profile.protocol()),
                (kind, Some(protocol))
            );
            assert_eq!(profile.validate(), Ok(()), "{kind} {protocol}");
        }
        for protocol in [Protocol::V1, Protocol::V2] {
            if !protocols.contains(&protocol) {
                assert!(
                    entry.default_profile(Some(protocol)).is_err(),
                    "{kind} {protocol}"
                );
            }
        }
    }
}

#[test]
fn every_robot_has_a_description_with_limits_geometry_and_a_battery_level() {
    for kind in RobotKind::ALL {
        let entry = kind.entry();
        for profile in every_profile(entry) {
            let d = describe(&profile);
            let what = format!("{kind} {:?}", profile.protocol());
            assert_eq!(d.kind, kind.id(), "{what}");
            assert_eq!(d.kind_name(), kind.name(), "{what}");
            assert_eq!(d.display_name(), entry.display_name, "{what}");
            assert!(!d.model().is_empty(), "{what}");
            assert_ne!(Kinematics::name(d.kinematics), "unknown", "{what}");
            assert_ne!(d.protocol, WireProtocol::DETECTING, "{what}");
            let limits = d.robot_limits;
            assert!(
                limits.forward_mps > 0.0 && limits.reverse_mps > 0.0,
                "{what}"
            );
            assert!(limits.lateral_mps >= 0.0, "{what}");
            assert!(
                limits.angular_radps > 0.0 || limits.steer_rad > 0.0,
                "{what}: neither a yaw-rate nor a steering limit"
            );
            assert!(
                d.geometry.length_m > 0.0 && d.geometry.width_m > 0.0,
                "{what}"
            );
            // The safety monitor's battery rule needs a level on every robot.
            let b = d.battery;
            assert!(
                b.low_v > 0.0 || b.low_soc_pct > 0.0,
                "{what}: no battery level: {b:?}"
            );
            assert!(
                d.command_timeout_ms > 0 && d.heartbeat_period_ms > 0,
                "{what}"
            );
            assert!(
                d.heartbeat_period_ms < d.command_timeout_ms,
                "{what}: heartbeat {} ms, chassis timeout {} ms",
                d.heartbeat_period_ms,
                d.command_timeout_ms
            );
            assert_eq!(d.sensors().len(), entry.sensors.len(), "{what}");
        }
    }
}

/// The turning radius a robot that steers is described with is the one its driver turns at full
/// lock: a twist a little wider is driven as asked, a little tighter is clamped (or, four-wheel
/// steering, spun) and flagged — what the planner keeps its paths to.
#[test]
fn every_steered_robot_is_described_with_the_radius_its_driver_turns() {
    use chassis_interfaces::ClampFlags;
    let mut steered = 0;
    for kind in RobotKind::ALL {
        let entry = kind.entry();
        let profile = entry.defaults();
        let d = describe(&profile);
        let radius = d.geometry.min_turn_radius_m;
        if !d.robot_limits.steer_rad.is_finite() {
            assert_eq!(radius, 0.0, "{kind} turns on the spot");
            continue;
        }
        steered += 1;
        assert!(radius > 0.0, "{kind}: {radius}");
        let flags_at = |r: f64| {
            let mut pair = entry.simulated_pair(&profile, Timestamp::from_millis(1_000));
            pair.run_for(Duration::from_secs(2));
            let twist = Velocity::twist(0.3, (0.3 / r) as f32).unwrap();
            let now = pair.now();
            pair.driver.set_command(now, &twist);
            pair.run_for(Duration::from_millis(200));
            pair.driver.state().command.clamp_flags
        };
        let wider = flags_at(radius * 1.01);
        assert_eq!(
            wider & ClampFlags::TURN_RADIUS_LIMIT,
            0,
            "{kind}: {radius} m"
        );
        let tighter = flags_at(radius * 0.99);
        assert_ne!(
            tighter & ClampFlags::TURN_RADIUS_LIMIT,
            0,
            "{kind}: {radius} m"
        );
    }
    assert!(steered >= 4, "TITAN, HUNTER, HUNTER SE, RANGER MINI");
}

#[test]
fn an_override_of_a_limit_reaches_the_description() {
    let table: toml::Table = toml::from_str("max_linear_mps = 0.4").unwrap();
    let profile = RobotKind::Hunter
        .entry()
        .profile_from_table(None, &table)
        .unwrap();
    assert_eq!(describe(&profile).robot_limits.forward_mps, 0.4);
    let table: toml::Table = toml::from_str("model = \"scout-mini-omni\"").unwrap();
    let omni = RobotKind::ScoutMini
        .entry()
        .profile_from_table(Some(Protocol::V2), &table)
        .unwrap();
    let d = describe(&omni);
    assert_eq!(d.model(), "scout-mini-omni");
    assert_eq!(d.kinematics, Kinematics::OMNI);
    assert!(d.robot_limits.lateral_mps > 0.0);
}

#[test]
fn the_xbot_describes_its_range_sensors_and_its_wheels() {
    let d = describe(&RobotKind::Xbot.entry().defaults());
    let names: Vec<&str> = d.sensors().iter().map(|s| s.name()).collect();
    assert!(names.contains(&"ultrasonic_front_centre"), "{names:?}");
    assert!(names.contains(&"ir_rear_left"), "{names:?}");
    let joints: Vec<&str> = d.joints().iter().map(|j| j.name()).collect();
    assert_eq!(
        joints,
        ["front_left_wheel_joint", "front_right_wheel_joint"]
    );
    assert!((d.geometry.wheel_radius_m - 0.1).abs() < 1e-12);
    let titan = describe(&RobotKind::Titan.entry().defaults());
    let joints: Vec<&str> = titan.joints().iter().map(|j| j.name()).collect();
    assert_eq!(joints, ["front_steer_joint", "rear_steer_joint"]);
}

#[test]
fn the_frame_describer_follows_the_protocol_the_state_reports() {
    let tv8 = CanFrame::from_candump("211#0100010000800000").unwrap();
    // SCOUT MINI and BUNKER speak V1 or V2: a state saying V2 gets the V2 describer, names and all.
    for robot in [RobotKind::ScoutMini, RobotKind::Scout, RobotKind::Bunker] {
        let json = robot
            .entry()
            .profile_for_wire(WireProtocol::V2)
            .codec()
            .decode_can(&tv8)
            .unwrap();
        assert_eq!(json["protocol"], "v2", "{robot:?}");
        assert_eq!(json["vehicle"], "estop", "{robot:?}");
        assert_eq!(
            json["faults"],
            serde_json::json!(["emergency_stop"]),
            "{robot:?}"
        );
        let v1 = robot.entry().profile_for_wire(WireProtocol::V1).codec();
        assert_eq!(v1.robot(), robot);
        assert!(
            v1.decode_can(&tv8).is_err(),
            "{robot:?}: 0x211 is no V1 frame"
        );
    }
    // Still detecting: the robot's default protocol (SCOUT MINI: V1).
    let detecting = RobotKind::ScoutMini
        .entry()
        .profile_for_wire(WireProtocol::DETECTING)
        .codec();
    assert!(detecting.decode_can(&tv8).is_err());
    // A robot with one protocol of its own keeps it.
    let titan = RobotKind::Titan
        .entry()
        .profile_for_wire(WireProtocol::V2)
        .codec();
    assert_eq!(titan.robot(), RobotKind::Titan);
}

// The profiles: the manuals' choices, a `[profile]` table over them, and what is refused.
#[test]
#[allow(clippy::approx_constant)] // 0.5235 is the manual's value
fn defaults_are_the_manuals_choices() {
    let t = TitanProfile::default();
    assert!(!t.steering_feedback_left_positive);
    assert_eq!((t.max_linear_mps, t.max_steer_rad), (3.0, 0.367));
    let s = V1Profile::default();
    assert_eq!(s.angular_full_scale_rad_s, 0.5235);
    assert_eq!(s.linear_full_scale_mps, 5.0);
    let x = XbotProfile::default();
    assert!(x.yaw_rate_left_positive && !x.lateral_left_positive);
    assert!(!x.bcd_currents_and_ranges);
    assert_eq!(x.encoder_counts_per_rev, 8000.0);
    assert_eq!(x.wheel_separation_m, None);
    assert!(x.heartbeat_hz > 5.0 && x.heartbeat_hz < 10.0);
}

#[test]
#[allow(clippy::approx_constant)] // 0.5235 is the sources' value
fn scout_and_bunker_speak_v1_with_their_own_scales_and_hunter_does_not() {
    for (robot, scales) in [
        (RobotKind::ScoutMini, (5.0, 0.5235)),
        (RobotKind::Scout, (1.5, 0.5235)),
        (RobotKind::Bunker, (3.0, 2.5235)),
    ] {
        assert!(
            robot.entry().default_profile(Some(Protocol::V1)).is_ok(),
            "{robot}"
        );
        let profile = robot.entry().default_profile(Some(Protocol::V1)).unwrap();
        assert_eq!(profile.robot(), robot);
        assert_eq!(profile.protocol(), Some(Protocol::V1));
        let Some(p) = profile.get::<V1Profile>() else {
            panic!("{robot}: {profile:?}");
        };
        assert_eq!(
            (p.linear_full_scale_mps, p.angular_full_scale_rad_s),
            scales
        );
        assert_eq!(profile.validate(), Ok(()), "{robot}");
    }
    // Their default protocol stays what it was: SCOUT MINI V1, SCOUT and BUNKER V2.
    assert_eq!(
        RobotKind::Scout.entry().defaults().protocol(),
        Some(Protocol::V2)
    );
    assert_eq!(
        RobotKind::Hunter
            .entry()
            .default_profile(Some(Protocol::V1)),
        Err(ProtocolError::NotSpoken {
            robot: RobotKind::Hunter,
            protocol: "v1"
        })
    );
    // A `[profile]` table of a V1 BUNKER starts from the BUNKER's values.
    let table: toml::Table = toml::from_str("max_linear_mps = 1.0").unwrap();
    let Some(p) = RobotKind::Bunker
        .entry()
        .profile_from_table(Some(Protocol::V1), &table)
        .unwrap()
        .get::<V1Profile>()
        .cloned()
    else {
        panic!("not V1");
    };
    assert_eq!((p.model, p.max_linear_mps), (V1Model::Bunker, 1.0));
    assert_eq!(p.linear_full_scale_mps, 3.0);
    let scout: toml::Table = toml::from_str("model = \"scout\"").unwrap();
    assert_eq!(
        RobotKind::Bunker
            .entry()
            .profile_from_table(Some(Protocol::V1), &scout),
        Err(ProfileTableError::WrongModel {
            owner: RobotKind::Scout,
            robot: RobotKind::Bunker
        })
    );
}

#[test]
fn a_profile_flips_one_parameter_from_toml() {
    let t: TitanProfile = toml::from_str("steering_feedback_left_positive = true").unwrap();
    assert!(t.steering_feedback_left_positive);
    assert_eq!(t.max_linear_mps, 3.0);
    let err = toml::from_str::<TitanProfile>("max_speed = 4").unwrap_err();
    assert!(err.to_string().contains("unknown field"), "{err}");
}

#[test]
fn the_defaults_validate_and_nonsense_does_not() {
    for r in RobotKind::ALL {
        assert_eq!(r.entry().defaults().validate(), Ok(()), "{r}");
    }
    let zero = V1Profile {
        angular_full_scale_rad_s: 0.0,
        ..V1Profile::default()
    };
    assert_eq!(
        zero.validate(),
        Err(ProfileError::NotPositive {
            name: "angular_full_scale_rad_s",
            value: 0.0
        })
    );
    assert_eq!(
        zero.validate().unwrap_err().to_string(),
        "angular_full_scale_rad_s must be above zero (is 0)"
    );
    // Nonsense is refused, and the refusal names the parameter.
    for (nonsense, name) in [
        (
            Profile::from(XbotProfile {
                heartbeat_hz: 12.0,
                ..XbotProfile::default()
            }),
            "heartbeat_hz",
        ),
        (
            Profile::from(TitanProfile {
                track_m: f64::NAN,
                ..TitanProfile::default()
            }),
            "track_m",
        ),
        (
            Profile::from(TitanProfile {
                heartbeat_period_ms: 600,
                ..TitanProfile::default()
            }),
            "heartbeat_period_ms",
        ),
    ] {
        let refusal = nonsense.validate().unwrap_err().to_string();
        assert!(refusal.contains(name), "{refusal}");
    }
}

#[test]
fn every_id_is_one_robot_and_back() {
    for id in 0..=u8::MAX {
        if let Some(kind) = RobotKind::from_id(id) {
            assert_eq!(kind.id(), id);
        }
    }
    assert_eq!(RobotKind::from_id(0), None);
    assert_eq!(RobotKind::from_id(5), Some(RobotKind::Hunter));
}

#[test]
fn robot_names_parse() {
    for r in RobotKind::ALL {
        assert_eq!(r.name().parse::<RobotKind>(), Ok(r));
        assert_eq!(r.entry().defaults().robot(), r);
        assert_eq!(RobotKind::from_id(r.id()), Some(r));
    }
    let v2 = RobotKind::ScoutMini
        .entry()
        .default_profile(Some(Protocol::V2))
        .unwrap();
    assert_eq!(
        (v2.robot(), v2.protocol()),
        (RobotKind::ScoutMini, Some(Protocol::V2))
    );
    let err = RobotKind::Hunter
        .entry()
        .default_profile(Some(Protocol::V1))
        .unwrap_err();
    assert_eq!(err.to_string(), "hunter does not speak protocol v1 here");
    assert!("v3".parse::<Protocol>().is_err());
    let omni: toml::Table = toml::from_str("model = \"scout-mini-omni\"").unwrap();
    let Some(p) = RobotKind::ScoutMini
        .entry()
        .profile_from_table(Some(Protocol::V2), &omni)
        .unwrap()
        .get::<V2Profile>()
        .cloned()
    else {
        panic!("not V2")
    };
    assert_eq!(p.max_lateral_mps, 2.0);
    let err = RobotKind::Hunter
        .entry()
        .profile_from_table(None, &omni)
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "profile.model: a scout-mini model is not a hunter"
    );
    assert!("husky".parse::<RobotKind>().is_err());
}

#[test]
fn xbot_travel_per_count_follows_the_profile() {
    let x = XbotProfile::default();
    assert!((x.metres_per_count() - std::f64::consts::PI * 0.2 / 8000.0).abs() < 1e-12);
}

#[test]
fn a_description_gives_the_profile_of_its_robot_in_the_protocol_in_use() {
    for kind in RobotKind::ALL {
        let d = describe(&kind.entry().defaults());
        let profile = profile_for_description(&d).expect("a profile");
        assert_eq!((profile.robot(), profile.codec().robot()), (kind, kind));
    }
    // A SCOUT MINI described in V1, then (detection decided) in V2 with its omni model.
    let v1 = describe(&RobotKind::ScoutMini.entry().defaults());
    let profile = profile_for_description(&v1).expect("a profile");
    assert_eq!(profile.protocol(), Some(Protocol::V1));
    let mut v2 = describe(&Profile::from(V2Profile::for_model(V2Model::ScoutMiniOmni)));
    v2.protocol = WireProtocol::V2;
    let profile = profile_for_description(&v2).expect("a profile");
    assert_eq!(
        (profile.get::<V2Profile>().map(|p| p.model), profile.robot()),
        (Some(V2Model::ScoutMiniOmni), RobotKind::ScoutMini)
    );
    // A model of another robot is not taken: the kind's own V2 profile is.
    let mut hunter = describe(&RobotKind::Hunter.entry().defaults());
    hunter.set_model("scout-mini-omni");
    let profile = profile_for_description(&hunter).expect("a profile");
    assert_eq!(
        profile.get::<V2Profile>().map(|p| p.model),
        Some(V2Model::Hunter)
    );
    assert!(profile_for_description(&RobotDescription::default()).is_none());
}

/// `chassis encode --robot KIND velocity --vx 0.3 --wz 0`: each family's motion frame, as text.
#[test]
fn a_forward_command_becomes_each_familys_motion_frame() {
    let forward = |kind: RobotKind| {
        let command = crate::Command::Velocity(Velocity::twist(0.3, 0.0).unwrap());
        let (lines, clamp_flags) = kind.entry().defaults().command_lines(&command).unwrap();
        assert_eq!(clamp_flags, 0);
        lines
    };
    assert_eq!(forward(RobotKind::Titan), ["111#012C000000000000"]);
    // AgileX V1: the frame counter (b6) starts at 0.
    assert_eq!(forward(RobotKind::ScoutMini), ["130#0100060000000040"]);
    assert_eq!(forward(RobotKind::Hunter), ["111#012C000000000000"]);
    assert_eq!(
        forward(RobotKind::Xbot),
        ["AA 55 0D 03 9A 99 99 3E 00 00 00 00 00 00 00 00 AA"]
    );
}
