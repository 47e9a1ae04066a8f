//! The description chassisd publishes on `chassis/<name>/robot`: the registry's and the
//! effective profile's facts (`chassis_protocols::description::describe`) plus what only the
//! service knows — the robot's name, the protocol in use (updated once detection decides), its
//! configured limits, the mux's sources, whether the bus is simulated and whether the safety
//! source is required.

use chassis_bus::BusSpec;
use chassis_interfaces::{
    DescriptionFlags, MotionLimits, RobotDescription, SensorDescription, SensorKind, SourceFlags,
    WireProtocol,
};
use chassis_protocols::description::describe;
use chassis_protocols::{Profile, Protocol};
use chassisd_config::Config;

/// The description of the robot `config` drives, speaking `wire_protocol` (the driver's
/// `SystemState::wire_protocol`: `DETECTING` while it listens).
pub fn for_config(config: &Config, wire_protocol: u8) -> RobotDescription {
    let entry = config.robot.entry();
    // After detection the driver speaks the protocol it heard: the configured profile if that is
    // the configured one's protocol, else the other protocol's defaults (as the driver does).
    let detected = match wire_protocol {
        WireProtocol::V1 => Some(Protocol::V1),
        WireProtocol::V2 => Some(Protocol::V2),
        _ => None,
    };
    let profile: Profile = match detected {
        Some(p) if config.profile.protocol() != Some(p) => entry
            .default_profile(Some(p))
            .unwrap_or_else(|_| config.profile.clone()),
        _ => config.profile.clone(),
    };
    let mut d = describe(&profile);
    d.protocol = wire_protocol;
    d.set_name(&config.name);
    let limits = &config.mux.limits;
    let limit = |v: f64| if v > 0.0 { v } else { f64::NAN };
    d.configured_limits = MotionLimits {
        forward_mps: limit(limits.max_linear_mps),
        reverse_mps: limit(limits.max_linear_mps),
        lateral_mps: limit(limits.max_lateral_mps),
        angular_radps: limit(limits.max_angular_radps),
        steer_rad: f64::NAN,
        linear_accel_mps2: limit(limits.linear_accel_mps2),
        angular_accel_radps2: limit(limits.angular_accel_radps2),
        braking_mps2: limit(limits.braking_mps2),
    };
    for source in &config.mux.sources {
        let mut flags = 0;
        if source.required {
            flags |= SourceFlags::REQUIRED;
            d.flags |= DescriptionFlags::SAFETY_REQUIRED;
        }
        if source.remote {
            flags |= SourceFlags::REMOTE;
        }
        let timeout_ms = u32::try_from(source.timeout_ms).unwrap_or(u32::MAX);
        // The mux admits at most as many sources as the description holds.
        let _ = d.push_source(&source.name, source.priority, timeout_ms, flags);
    }
    if config.gps.is_some() {
        let gps = SensorDescription {
            kind: SensorKind::GPS,
            field_of_view_rad: f64::NAN,
            min_range_m: f64::NAN,
            max_range_m: f64::NAN,
            ..SensorDescription::default()
        };
        let _ = d.push_sensor("gps", gps);
    }
    if config.bus == BusSpec::Sim {
        d.flags |= DescriptionFlags::SIMULATED;
    }
    d
}
