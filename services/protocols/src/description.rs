//! The robot's part of the `RobotDescription` chassisd publishes: its registry entry and its
//! effective profile (the manuals' values with every override) turned into limits, geometry,
//! battery levels, sensors and joints. chassisd adds what only it knows (the robot's name, the
//! protocol once detected, its configured limits and the mux's sources).

use chassis_interfaces::{
    DescriptionFlags, Geometry, JointSource, RobotDescription, SensorDescription,
};

use crate::family::Profile;

/// The description of `profile`'s robot: kind, model, protocol, the driver's limits, geometry,
/// battery levels, sensors, joints, odometry variances, the chassis' timeouts.
pub fn describe(profile: &Profile) -> RobotDescription {
    let kind = profile.robot();
    let entry = kind.entry();
    let mut d = RobotDescription {
        kind: kind.id(),
        kinematics: entry.kinematics,
        bus: entry.bus.kind(),
        odometry_variance: entry.odometry_variance,
        heartbeat_period_ms: u32::try_from(profile.heartbeat_period().as_millis()).unwrap_or(0),
        ..RobotDescription::default()
    };
    d.set_kind_name(kind.name());
    d.set_name(kind.name());
    d.set_display_name(entry.display_name);
    d.geometry = Geometry {
        length_m: entry.outline.length_m,
        width_m: entry.outline.width_m,
        height_m: entry.outline.height_m,
        ..d.geometry
    };
    profile.describe(&mut d);
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
    // Wheel joints need the wheel radius, which only some families know.
    let wheels = profile.wheel_joints();
    for j in entry
        .joints
        .iter()
        .filter(|j| j.source != JointSource::WHEEL || j.index < wheels)
    {
        let _ = d.push_joint(j.name, j.source, j.index);
    }
    d
}
