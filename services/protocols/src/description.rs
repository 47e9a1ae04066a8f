//! The robot's part of the `RobotDescription` chassisd publishes: its registry entry and its
//! effective profile (the manuals' values with every override) turned into limits, geometry,
//! battery levels, sensors and joints. chassisd adds what only it knows (the robot's name, the
//! protocol once detected, its configured limits and the mux's sources).

use chassis_interfaces::{
    BatteryLevels, DescriptionFlags, Geometry, JointSource, Kinematics, MotionLimits,
    RobotDescription, SensorDescription, WireProtocol,
};

use crate::agilex_v2::{self, V2Model};
use crate::profile::Profile;
use crate::registry::{RobotEntry, heartbeat_period};
use crate::titan;

/// Limits as fast backward as forward; no steering and no acceleration limit.
fn both_ways(linear_mps: f64, lateral_mps: f64, angular_radps: f64) -> MotionLimits {
    MotionLimits {
        forward_mps: linear_mps,
        reverse_mps: linear_mps,
        lateral_mps,
        angular_radps,
        ..MotionLimits::NONE
    }
}

/// The description of `profile`'s robot: kind, model, protocol, the driver's limits, geometry,
/// battery levels, sensors, joints, odometry variances, the chassis' timeouts.
pub fn describe(profile: &Profile) -> RobotDescription {
    let kind = profile.robot();
    let entry = kind.entry();
    let mut d = RobotDescription {
        kind: kind.id(),
        protocol: match profile {
            Profile::ScoutMini(_) => WireProtocol::V1,
            Profile::V2(_) => WireProtocol::V2,
            Profile::Titan(_) | Profile::Xbot(_) => WireProtocol::OWN,
        },
        kinematics: kinematics(entry, profile),
        bus: entry.bus.kind(),
        odometry_variance: entry.odometry_variance,
        heartbeat_period_ms: u32::try_from(heartbeat_period(profile).as_millis()).unwrap_or(0),
        ..RobotDescription::default()
    };
    d.set_kind_name(entry.name);
    d.set_name(entry.name);
    d.set_display_name(entry.display_name);
    d.set_model(&model(profile));
    d.geometry = Geometry {
        length_m: entry.outline.length_m,
        width_m: entry.outline.width_m,
        height_m: entry.outline.height_m,
        ..d.geometry
    };
    let nan = f64::NAN;
    match profile {
        Profile::Titan(p) => {
            d.robot_limits = MotionLimits {
                steer_rad: p.max_steer_rad,
                ..both_ways(p.max_linear_mps, 0.0, nan)
            };
            d.geometry.wheelbase_m = p.wheelbase_m;
            d.geometry.track_m = p.track_m;
            // Both axles steer: the turn centre lies on the line half way between them, and the
            // body's centre runs half a track outside the inner wheels.
            d.geometry.min_turn_radius_m = titan::kinematics::min_turn_radius_m(p);
            d.battery = BatteryLevels {
                // The TITAN manual: charge when the remote shows less than 15 % or the tail
                // display less than 45 V; below 10 % the chassis cuts drive power.
                low_v: 45.0,
                low_soc_pct: p.low_battery_warning_soc_pct,
                critical_soc_pct: p.low_battery_cutoff_soc_pct,
                ..d.battery
            };
            d.command_timeout_ms = millis(p.command_timeout_ms);
            d.flags |= DescriptionFlags::LIGHTS;
        }
        Profile::ScoutMini(p) => {
            d.robot_limits = both_ways(p.max_linear_mps, 0.0, p.max_angular_rad_s);
            d.geometry.wheelbase_m = p.wheelbase_m;
            d.geometry.track_m = p.track_m;
            d.geometry.min_turn_radius_m = 0.0;
            d.battery.low_v = p.under_voltage_alarm_v;
            d.battery.critical_v = p.under_voltage_failure_v;
            d.battery.full_v = p.battery_full_v;
            d.command_timeout_ms = millis(p.command_timeout_ms);
            d.flags |= DescriptionFlags::LIGHTS;
        }
        Profile::Xbot(p) => {
            let lateral_mps = if p.omni { p.max_linear_mps } else { 0.0 };
            d.robot_limits = both_ways(p.max_linear_mps, lateral_mps, p.max_angular_rad_s);
            d.geometry.track_m = p.wheel_separation_m.unwrap_or(nan);
            d.geometry.wheel_radius_m = p.wheel_diameter_m / 2.0;
            d.geometry.travel_per_count_m = p.metres_per_count();
            d.geometry.min_turn_radius_m = 0.0;
            d.battery.full_v = p.battery_full_v;
            d.battery.low_v = p.battery_low_v;
            d.command_timeout_ms = millis(p.command_timeout_ms);
        }
        Profile::V2(p) => {
            let steers = matches!(
                p.kinematics,
                agilex_v2::Kinematics::Ackermann | agilex_v2::Kinematics::FourWheelSteer
            );
            d.robot_limits = MotionLimits {
                steer_rad: if steers { p.max_steer_rad } else { nan },
                ..both_ways(p.max_linear_mps, p.max_lateral_mps, p.max_angular_radps)
            };
            d.geometry.wheelbase_m = p.wheelbase_m;
            d.geometry.track_m = p.track_m;
            d.geometry.min_turn_radius_m = match p.kinematics {
                // The front inner wheel at full lock; the body's centre runs half a track
                // outside it (the driver's R = L / tan δᵢ + W/2).
                agilex_v2::Kinematics::Ackermann => {
                    p.wheelbase_m / p.max_steer_rad.tan() + p.track_m / 2.0
                }
                // Four-wheel steering drives dual Ackermann down to this radius and spins on
                // the spot below it.
                agilex_v2::Kinematics::FourWheelSteer => p.min_turn_radius_m,
                _ => 0.0,
            };
            d.battery.low_v = p.under_voltage_alarm_v;
            d.battery.critical_v = p.under_voltage_failure_v;
            d.command_timeout_ms = millis(p.command_timeout_ms);
            if p.brake_lock_value.is_some() {
                d.flags |= DescriptionFlags::BRAKE;
            }
            if p.front_light || p.rear_light {
                d.flags |= DescriptionFlags::LIGHTS;
            }
        }
    }
    if d.robot_limits.lateral_mps > 0.0 {
        d.flags |= DescriptionFlags::LATERAL;
    }
    for s in entry.sensors {
        let sensor = SensorDescription {
            kind: s.kind,
            index: s.index,
            x_m: s.x_m,
            y_m: s.y_m,
            z_m: s.z_m,
            yaw_rad: s.yaw_rad,
            field_of_view_rad: s.field_of_view_rad,
            min_range_m: s.min_range_m,
            max_range_m: s.max_range_m,
            ..SensorDescription::default()
        };
        // The registry's lists fit (a test checks every entry).
        let _ = d.push_sensor(s.name, sensor);
    }
    for j in entry
        .joints
        .iter()
        .filter(|j| joint_applies(j.source, j.index, profile))
    {
        let _ = d.push_joint(j.name, j.source, j.index);
    }
    d
}

/// Whether a joint of the registry is published for this profile: wheel joints need the wheel
/// radius (only the XBot's manual gives it) and, on a two-wheel XBot, are the front pair only.
fn joint_applies(source: u8, index: u8, profile: &Profile) -> bool {
    match (source, profile) {
        (JointSource::WHEEL, Profile::Xbot(p)) => p.omni || index < 2,
        (JointSource::WHEEL, _) => false,
        _ => true,
    }
}

fn millis(ms: u64) -> u32 {
    u32::try_from(ms).unwrap_or(u32::MAX)
}

/// The variant the profile describes: its `model` where it has one, spelled as the config
/// spells it.
fn model(profile: &Profile) -> String {
    fn kebab<T: serde::Serialize>(value: &T) -> String {
        match serde_json::to_value(value) {
            Ok(serde_json::Value::String(s)) => s,
            _ => String::new(),
        }
    }
    match profile {
        Profile::Titan(_) => "titan".into(),
        Profile::Xbot(p) => if p.omni { "xbot-omni" } else { "xbot" }.into(),
        Profile::ScoutMini(p) => kebab(&p.model),
        Profile::V2(p) => kebab(&p.model),
    }
}

/// The kinematics of the robot as its profile configures it.
fn kinematics(entry: &RobotEntry, profile: &Profile) -> u8 {
    match profile {
        Profile::Xbot(p) if p.omni => Kinematics::OMNI,
        Profile::V2(p) if p.model == V2Model::ScoutMiniOmni => Kinematics::OMNI,
        Profile::V2(p) if p.kinematics == agilex_v2::Kinematics::Omni => Kinematics::OMNI,
        _ => entry.kinematics,
    }
}
