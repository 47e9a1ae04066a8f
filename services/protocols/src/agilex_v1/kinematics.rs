//! SCOUT MINI's skid-steer kinematics: a twist limited to what the robot and the motion command
//! can carry, quantised to the command's whole-percent steps, and the side speeds of a twist.
//!
//! The chassis takes (v, ω) directly, so no geometry is needed to command it: the work is in the
//! limits and the 1 % resolution (0.05 m/s and 0.005235 rad/s with the default profile). The
//! side speeds use the plain differential model, v_left = v − ω·W/2, v_right = v + ω·W/2 with
//! track W; a skid-steer robot slips while turning, so its effective track is wider than the
//! geometric one and these are an idealisation (good for the simulator, not for odometry).

use chassis_interfaces::ClampFlags;
use serde::{Deserialize, Serialize};

use super::codec::{MotionCommand, quantise_percent};
use crate::agilex_v1::V1Profile;

/// A speed and yaw rate as sent in 0x130, with what was clamped or rounded on the way.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SkidCommand {
    /// The linear speed the wire carries, m/s (a whole percent of the full scale).
    pub linear_mps: f64,
    /// The yaw rate the wire carries, rad/s, left turn positive.
    pub angular_radps: f64,
    /// 0x130 b2.
    pub linear_pct: i8,
    /// 0x130 b3.
    pub angular_pct: i8,
    /// `chassis_interfaces::ClampFlags`.
    pub clamp_flags: u32,
}

impl SkidCommand {
    /// The 0x130 frame in CAN command mode, clearing nothing.
    pub fn motion_command(&self) -> MotionCommand {
        MotionCommand::drive(self.linear_mps, self.angular_radps)
    }
}

/// Limits a twist to the profile's limits, each capped by the (⚠ angular) full scale
/// ([`ClampFlags::LINEAR_LIMIT`], [`ClampFlags::ANGULAR_LIMIT`])
/// and rounds it to whole percents ([`ClampFlags::QUANTISED`] when that changed it at the `f32`
/// resolution a velocity is asked in). The skid steer turns on the spot, so every direction is
/// achievable.
pub fn twist_to_command(linear_mps: f64, angular_radps: f64, profile: &V1Profile) -> SkidCommand {
    let mut flags = 0;
    let mut limit = |value: f64, max: f64, flag: u32| {
        if value.abs() > max {
            flags |= flag;
            value.signum() * max
        } else {
            value
        }
    };
    let linear_max = profile.max_linear_mps.min(profile.linear_full_scale_mps);
    let angular_max = profile
        .max_angular_rad_s
        .min(profile.angular_full_scale_rad_s);
    let linear = limit(linear_mps, linear_max, ClampFlags::LINEAR_LIMIT);
    let angular = limit(angular_radps, angular_max, ClampFlags::ANGULAR_LIMIT);
    let (linear_pct, linear_sent) = quantise_percent(linear, profile.linear_full_scale_mps);
    let (angular_pct, angular_sent) = quantise_percent(angular, profile.angular_full_scale_rad_s);
    let changed = |asked: f64, sent: f64| asked as f32 != sent as f32;
    if changed(linear, linear_sent) || changed(angular, angular_sent) {
        flags |= ClampFlags::QUANTISED;
    }
    SkidCommand {
        linear_mps: linear_sent,
        angular_radps: angular_sent,
        linear_pct,
        angular_pct,
        clamp_flags: flags,
    }
}

/// Left and right side speeds, m/s, of a twist (ISO axes: a left turn speeds up the right side).
pub fn side_speeds(linear_mps: f64, angular_radps: f64, profile: &V1Profile) -> (f64, f64) {
    let half_track = profile.track_m / 2.0;
    (
        linear_mps - angular_radps * half_track,
        linear_mps + angular_radps * half_track,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The twist (v, ω) of left and right side speeds, m/s: the inverse of [`side_speeds`].
    fn twist_from_side_speeds(left_mps: f64, right_mps: f64, profile: &V1Profile) -> (f64, f64) {
        (
            (left_mps + right_mps) / 2.0,
            (right_mps - left_mps) / profile.track_m,
        )
    }

    fn p() -> V1Profile {
        V1Profile::default()
    }

    #[test]
    fn whole_percent_twists_pass_unchanged() {
        let c = twist_to_command(0.5, -0.2094, &p());
        assert_eq!((c.linear_pct, c.angular_pct), (10, -40));
        assert_eq!(c.linear_mps, 0.5);
        assert!((c.angular_radps + 0.2094).abs() < 1e-12);
        assert_eq!(c.clamp_flags, 0);
    }

    #[test]
    fn in_between_values_round_to_the_nearest_percent_and_are_flagged() {
        // 0.52 m/s = 10.4 % → 10 % = 0.5 m/s; 0.53 m/s = 10.6 % → 11 % = 0.55 m/s.
        let c = twist_to_command(0.52, 0.0, &p());
        assert_eq!((c.linear_pct, c.linear_mps), (10, 0.5));
        assert_eq!(c.clamp_flags, ClampFlags::QUANTISED);
        let c = twist_to_command(-0.53, 0.0, &p());
        assert_eq!((c.linear_pct, c.linear_mps), (-11, -0.55));
    }

    #[test]
    fn speeds_beyond_the_limits_are_clamped_and_flagged() {
        let c = twist_to_command(7.0, -1.0, &p());
        assert_eq!((c.linear_pct, c.angular_pct), (100, -100));
        let full_scale = p().angular_full_scale_rad_s;
        assert_eq!((c.linear_mps, c.angular_radps), (5.0, -full_scale));
        assert_eq!(
            c.clamp_flags,
            ClampFlags::LINEAR_LIMIT | ClampFlags::ANGULAR_LIMIT
        );
        // A profile limit below the full scale wins.
        let slow = V1Profile {
            max_linear_mps: 1.0,
            ..p()
        };
        let c = twist_to_command(2.0, 0.0, &slow);
        assert_eq!((c.linear_pct, c.linear_mps), (20, 1.0));
        assert_eq!(c.clamp_flags, ClampFlags::LINEAR_LIMIT);
    }

    #[test]
    fn turning_on_the_spot_is_achievable() {
        let c = twist_to_command(0.0, p().angular_full_scale_rad_s, &p());
        assert_eq!((c.linear_pct, c.angular_pct, c.clamp_flags), (0, 100, 0));
    }

    #[test]
    fn the_command_frame_carries_command_mode() {
        let m = twist_to_command(0.5, 0.0, &p()).motion_command();
        assert_eq!(m.mode, super::super::mode::CAN_COMMAND);
        assert_eq!(m.fault_clear, super::super::clear_code::NONE);
    }

    #[test]
    fn a_left_turn_speeds_up_the_right_side_and_back() {
        let (l, r) = side_speeds(1.0, 0.4, &p());
        assert!((l - 0.91).abs() < 1e-12 && (r - 1.09).abs() < 1e-12);
        let (v, w) = twist_from_side_speeds(l, r, &p());
        assert!((v - 1.0).abs() < 1e-12 && (w - 0.4).abs() < 1e-12);
    }
}
