//! The robot as chassisd describes it (`chassis/<name>/robot`), for `chassis status` and
//! `chassis top`: what it is, its protocol in use, its effective limits, battery levels, sensors,
//! joints and the mux's configured sources — as text lines and as JSON — and the profile its
//! frames are named with (the registry's codec of the described robot).

use chassis_client::{
    BusKind, ChassisState, DescriptionFlags, Group, JointSource, Kinematics, MotionLimits,
    RobotDescription, SensorKind, SourceFlags, WireProtocol,
};
use chassis_protocols::{Profile, RobotKind};
use serde_json::{Value, json};

/// A finite number with `places` decimals, or `—`.
fn number(value: f64, places: usize) -> String {
    if value.is_finite() {
        format!("{value:.places$}")
    } else {
        "—".into()
    }
}

/// A finite number, or null (JSON has no NaN).
fn finite(value: f64) -> Value {
    if value.is_finite() {
        json!(value)
    } else {
        Value::Null
    }
}

/// `AgileX TITAN (titan)`, or the kind's number when the description names nothing.
pub fn title(d: &RobotDescription) -> String {
    match (d.display_name(), d.kind_name()) {
        ("", "") => format!("robot kind {}", d.kind),
        ("", kind) => kind.to_string(),
        (display, kind) => format!("{display} ({kind})"),
    }
}

/// `model titan-x · dual_ackermann · can · protocol v2 · simulated · brake, lights`.
pub fn model_line(d: &RobotDescription) -> String {
    let mut words = vec![
        d.model().to_string(),
        Kinematics::name(d.kinematics).to_string(),
        format!("{} bus", BusKind::name(d.bus)),
        format!("protocol {}", WireProtocol::name(d.protocol)),
    ];
    if d.flags & DescriptionFlags::SIMULATED != 0 {
        words.push("simulated".into());
    }
    let has: Vec<&str> = [
        (DescriptionFlags::BRAKE, "brake"),
        (DescriptionFlags::LIGHTS, "lights"),
        (DescriptionFlags::LATERAL, "moves sideways"),
    ]
    .into_iter()
    .filter_map(|(flag, word)| (d.flags & flag != 0).then_some(word))
    .collect();
    if !has.is_empty() {
        words.push(has.join(", "));
    }
    words.join(" · ")
}

/// The speeds of `limits`: `forward 1.50 · reverse 1.50 m/s · yaw 0.52 rad/s · steer 33.0°`.
fn speeds_text(limits: &MotionLimits) -> Vec<String> {
    let mut words = Vec::new();
    if limits.forward_mps.is_finite() || limits.reverse_mps.is_finite() {
        words.push(format!(
            "forward {} · reverse {} m/s",
            number(limits.forward_mps, 2),
            number(limits.reverse_mps, 2)
        ));
    }
    if limits.lateral_mps.is_finite() && limits.lateral_mps > 0.0 {
        words.push(format!("sideways {:.2} m/s", limits.lateral_mps));
    }
    if limits.angular_radps.is_finite() {
        words.push(format!("yaw {:.2} rad/s", limits.angular_radps));
    }
    if limits.steer_rad.is_finite() {
        words.push(format!("steer {:.1}°", limits.steer_rad.to_degrees()));
    }
    if limits.linear_accel_mps2.is_finite() {
        words.push(format!("accel {:.2} m/s²", limits.linear_accel_mps2));
    }
    if limits.angular_accel_radps2.is_finite() {
        words.push(format!(
            "yaw accel {:.2} rad/s²",
            limits.angular_accel_radps2
        ));
    }
    if limits.braking_mps2.is_finite() {
        words.push(format!("braking {:.2} m/s²", limits.braking_mps2));
    }
    words
}

/// The effective limits, and how the robot turns.
pub fn limits_line(d: &RobotDescription) -> String {
    let mut words = speeds_text(&d.effective_limits());
    let radius = d.geometry.min_turn_radius_m;
    if Kinematics::steers(d.kinematics) && radius.is_finite() {
        words.push(format!("turns ≥ {radius:.2} m"));
    } else if d.kinematics == Kinematics::FOUR_WHEEL_STEER && radius > 0.0 {
        words.push(format!("turns ≥ {radius:.2} m, spins below"));
    } else {
        words.push("turns on the spot".into());
    }
    words.join(" · ")
}

/// Where the effective limits come from, when chassisd's `[mux.limits]` sets any.
pub fn limits_origin_line(d: &RobotDescription) -> Option<String> {
    let configured = speeds_text(&d.configured_limits);
    if configured.is_empty() {
        return None;
    }
    Some(format!(
        "robot {} · [mux.limits] {}",
        speeds_text(&d.robot_limits).join(" · "),
        configured.join(" · ")
    ))
}

/// The battery levels the description gives, `None` where it gives none.
pub fn levels_text(d: &RobotDescription) -> Option<String> {
    let b = &d.battery;
    let mut words = Vec::new();
    let both = |v: f64, pct: f64| match (v.is_finite(), pct.is_finite()) {
        (true, true) => Some(format!("{v:.1} V / {pct:.0} %")),
        (true, false) => Some(format!("{v:.1} V")),
        (false, true) => Some(format!("{pct:.0} %")),
        (false, false) => None,
    };
    if let Some(low) = both(b.low_v, b.low_soc_pct) {
        words.push(format!("low {low}"));
    }
    if let Some(cut) = both(b.critical_v, b.critical_soc_pct) {
        words.push(format!("cut-off {cut}"));
    }
    if b.full_v.is_finite() {
        words.push(format!("full {:.1} V", b.full_v));
    }
    (!words.is_empty()).then(|| words.join(", "))
}

/// The battery as the state reports it, with the description's levels.
pub fn battery_line(state: Option<&ChassisState>, d: Option<&RobotDescription>) -> String {
    let mut text = match state {
        Some(s) if s.is_valid(Group::BmsPack) => format!(
            "{:.1} V  {:.0} %  {:+.1} A",
            s.system.battery_voltage_v, s.system.battery_soc_pct, s.system.battery_current_a
        ),
        Some(s) => format!("{:.1} V", s.system.battery_voltage_v),
        None => "—".into(),
    };
    if let Some(levels) = d.and_then(levels_text) {
        text.push_str(&format!("   (levels: {levels})"));
    }
    text
}

/// `ultrasonic 3 · infrared 3 · imu`; `None` for a robot without sensors.
pub fn sensors_line(d: &RobotDescription) -> Option<String> {
    let mut kinds: Vec<(u8, usize)> = Vec::new();
    for s in d.sensors() {
        match kinds.iter_mut().find(|(k, _)| *k == s.kind) {
            Some((_, n)) => *n += 1,
            None => kinds.push((s.kind, 1)),
        }
    }
    let words: Vec<String> = kinds
        .iter()
        .map(|&(k, n)| match n {
            1 => SensorKind::name(k).to_string(),
            n => format!("{} {n}", SensorKind::name(k)),
        })
        .collect();
    (!words.is_empty()).then(|| words.join(" · "))
}

/// The joints' names, `None` for a robot without joints.
pub fn joints_line(d: &RobotDescription) -> Option<String> {
    let joints: Vec<&str> = d.joints().iter().map(|j| j.name()).collect();
    (!joints.is_empty()).then(|| joints.join(", "))
}

/// The mux's sources as configured: `safety 255 150 ms required · teleop 100 300 ms remote`.
pub fn sources_line(d: &RobotDescription) -> String {
    let sources: Vec<String> = d
        .sources()
        .iter()
        .map(|s| {
            let mut words = vec![format!("{} {} {} ms", s.name(), s.priority, s.timeout_ms)];
            if s.flags & SourceFlags::REQUIRED != 0 {
                words.push("required".into());
            }
            if s.flags & SourceFlags::REMOTE != 0 {
                words.push("remote".into());
            }
            words.join(" ")
        })
        .collect();
    let mut text = sources.join(" · ");
    if d.flags & DescriptionFlags::SAFETY_REQUIRED == 0 {
        text.push_str("   (--no-safety-monitor: no source required)");
    }
    text
}

/// The description as `chassis status --json` prints it: every field, names beside numbers,
/// unknown values null, the lists as long as they are.
pub fn json(d: &RobotDescription) -> Value {
    let effective = d.effective_limits();
    json!({
        "seq": d.seq,
        "stamp_ns": d.stamp_ns,
        "name": d.name(),
        "kind": d.kind,
        "kind_name": d.kind_name(),
        "display_name": d.display_name(),
        "model": d.model(),
        "protocol": d.protocol,
        "protocol_name": WireProtocol::name(d.protocol),
        "kinematics": d.kinematics,
        "kinematics_name": Kinematics::name(d.kinematics),
        "bus": d.bus,
        "bus_name": BusKind::name(d.bus),
        "flags": d.flags,
        "simulated": d.flags & DescriptionFlags::SIMULATED != 0,
        "safety_required": d.flags & DescriptionFlags::SAFETY_REQUIRED != 0,
        "robot_limits": limits_json(&d.robot_limits),
        "configured_limits": limits_json(&d.configured_limits),
        "effective_limits": limits_json(&effective),
        "geometry": {
            "wheelbase_m": finite(d.geometry.wheelbase_m),
            "track_m": finite(d.geometry.track_m),
            "wheel_radius_m": finite(d.geometry.wheel_radius_m),
            "travel_per_count_m": finite(d.geometry.travel_per_count_m),
            "length_m": finite(d.geometry.length_m),
            "width_m": finite(d.geometry.width_m),
            "height_m": finite(d.geometry.height_m),
            "min_turn_radius_m": finite(d.geometry.min_turn_radius_m),
        },
        "battery": {
            "full_v": finite(d.battery.full_v),
            "low_v": finite(d.battery.low_v),
            "critical_v": finite(d.battery.critical_v),
            "low_soc_pct": finite(d.battery.low_soc_pct),
            "critical_soc_pct": finite(d.battery.critical_soc_pct),
        },
        "command_timeout_ms": d.command_timeout_ms,
        "heartbeat_period_ms": d.heartbeat_period_ms,
        "sensors": d.sensors().iter().map(|s| json!({
            "name": s.name(),
            "kind": SensorKind::name(s.kind),
            "index": s.index,
            "x_m": finite(s.x_m),
            "y_m": finite(s.y_m),
            "z_m": finite(s.z_m),
            "yaw_rad": finite(s.yaw_rad),
            "field_of_view_rad": finite(s.field_of_view_rad),
            "min_range_m": finite(s.min_range_m),
            "max_range_m": finite(s.max_range_m),
        })).collect::<Vec<_>>(),
        "joints": d.joints().iter().map(|j| json!({
            "name": j.name(),
            "source": JointSource::name(j.source),
            "index": j.index,
        })).collect::<Vec<_>>(),
        "sources": d.sources().iter().map(|s| json!({
            "name": s.name(),
            "priority": s.priority,
            "timeout_ms": s.timeout_ms,
            "required": s.flags & SourceFlags::REQUIRED != 0,
            "remote": s.flags & SourceFlags::REMOTE != 0,
        })).collect::<Vec<_>>(),
    })
}

fn limits_json(l: &MotionLimits) -> Value {
    json!({
        "forward_mps": finite(l.forward_mps),
        "reverse_mps": finite(l.reverse_mps),
        "lateral_mps": finite(l.lateral_mps),
        "angular_radps": finite(l.angular_radps),
        "steer_rad": finite(l.steer_rad),
        "linear_accel_mps2": finite(l.linear_accel_mps2),
        "angular_accel_radps2": finite(l.angular_accel_radps2),
        "braking_mps2": finite(l.braking_mps2),
    })
}

/// The profile the robot's frames are named with: the registry's defaults of the described
/// robot in its protocol in use, of its model where the model is a profile parameter
/// (`scout-mini-omni`, `ranger-mini-v1`). Without a description, the state's robot kind and
/// protocol. `None` for a robot the registry does not know.
pub fn profile_of(d: Option<&RobotDescription>, state: Option<&ChassisState>) -> Option<Profile> {
    let (kind, wire, model) = match (d, state) {
        (Some(d), _) if d.is_known() => (d.kind, d.protocol, d.model()),
        (_, Some(s)) => (s.robot, s.system.wire_protocol, ""),
        _ => return None,
    };
    Some(
        RobotKind::from_id(kind)?
            .entry()
            .profile_for_model(wire, model),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::Protocol;
    use chassis_protocols::agilex_v2::V2Profile;
    use chassis_protocols::description::describe;

    #[test]
    fn every_robot_of_the_registry_is_shown_with_its_limits_and_levels() {
        for kind in RobotKind::ALL {
            let d = describe(&kind.entry().defaults());
            assert!(title(&d).contains(kind.entry().display_name), "{kind}");
            assert!(model_line(&d).contains(d.model()), "{kind}");
            let limits = limits_line(&d);
            assert!(limits.contains("forward"), "{kind}: {limits}");
            assert!(levels_text(&d).is_some(), "{kind}");
            let json = json(&d);
            assert_eq!(json["kind_name"], kind.name());
            assert!(json["effective_limits"]["forward_mps"].as_f64().unwrap() > 0.0);
            let profile = profile_of(Some(&d), None).unwrap();
            assert_eq!(profile.robot(), kind, "{kind}");
            assert_eq!(profile.protocol(), kind.entry().defaults().protocol());
        }
    }

    #[test]
    fn the_effective_limits_are_shown_with_where_they_come_from() {
        let mut d = describe(&RobotKind::Titan.entry().defaults());
        assert_eq!(limits_origin_line(&d), None);
        d.configured_limits.forward_mps = 0.4;
        let line = limits_line(&d);
        assert!(
            line.starts_with("forward 0.40 · reverse 3.00 m/s"),
            "{line}"
        );
        assert!(
            line.contains("steer 21.0°") && line.contains("turns ≥ 1.53 m"),
            "{line}"
        );
        let origin = limits_origin_line(&d).unwrap();
        assert!(origin.contains("[mux.limits] forward 0.40"), "{origin}");
        let json = json(&d);
        assert_eq!(json["effective_limits"]["forward_mps"], 0.4);
        assert_eq!(json["robot_limits"]["forward_mps"], 3.0);
        assert_eq!(json["effective_limits"]["angular_radps"], Value::Null);
    }

    #[test]
    fn sensors_and_joints_are_counted_compactly() {
        let d = describe(&RobotKind::Xbot.entry().defaults());
        assert_eq!(
            sensors_line(&d).as_deref(),
            Some("ultrasonic 3 · infrared 3 · imu")
        );
        assert_eq!(
            joints_line(&d).as_deref(),
            Some("front_left_wheel_joint, front_right_wheel_joint")
        );
        let tracer = describe(&RobotKind::Tracer.entry().defaults());
        assert_eq!((sensors_line(&tracer), joints_line(&tracer)), (None, None));
    }

    #[test]
    fn the_profile_follows_the_described_protocol_and_model() {
        let table: toml::Table = toml::from_str("model = \"ranger-mini-v1\"").unwrap();
        let v1 = RobotKind::RangerMini
            .entry()
            .profile_from_table(None, &table)
            .unwrap();
        let d = describe(&v1);
        let Some(p) = profile_of(Some(&d), None).and_then(|p| p.get::<V2Profile>().cloned()) else {
            panic!("not a V2 profile")
        };
        assert_eq!(p.model, chassis_protocols::agilex_v2::V2Model::RangerMiniV1);
        let scout = RobotKind::ScoutMini.entry();
        let mut d = describe(&scout.default_profile(Some(Protocol::V2)).unwrap());
        assert_eq!(
            profile_of(Some(&d), None).and_then(|p| p.protocol()),
            Some(Protocol::V2)
        );
        d.protocol = WireProtocol::DETECTING;
        assert_eq!(
            profile_of(Some(&d), None).and_then(|p| p.protocol()),
            scout.defaults().protocol()
        );
        // Without a description: the state's kind and protocol.
        let mut state = ChassisState {
            robot: RobotKind::Xbot.id(),
            ..ChassisState::default()
        };
        state.system.wire_protocol = WireProtocol::OWN;
        assert_eq!(
            profile_of(None, Some(&state)).map(|p| p.robot()),
            Some(RobotKind::Xbot)
        );
        state.robot = 0;
        assert!(profile_of(None, Some(&state)).is_none());
    }
}
