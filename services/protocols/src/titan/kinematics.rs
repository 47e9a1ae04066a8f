//! TITAN's dual-Ackermann kinematics: twist ↔ inner steering angle, and the speed limits.
//!
//! Front and rear axles steer opposite by the same angle, so the centre of rotation lies on the
//! lateral line through the body centre. With half-wheelbase a = L/2 and half-track b = W/2, a
//! body turning radius R = v/ω gives the inner wheel angle δᵢ = atan(a / (|R| − b)), signed like
//! the curvature ω/v (left turn positive). Backwards: R = a / tan|δ| + b, ω = v / R · sign(δ).

use chassis_interfaces::ClampFlags;

use crate::titan::TitanProfile;

/// A speed and steering angle ready for 0x111, with what was clamped on the way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteerCommand {
    pub linear_mps: f64,
    pub steer_rad: f64,
    /// `chassis_interfaces::ClampFlags`.
    pub clamp_flags: u32,
}

/// Smallest body turning radius the steering allows, m.
pub fn min_turn_radius_m(profile: &TitanProfile) -> f64 {
    let (a, b) = half_sizes(profile);
    a / profile.max_steer_rad.tan() + b
}

fn half_sizes(profile: &TitanProfile) -> (f64, f64) {
    (profile.wheelbase_m / 2.0, profile.track_m / 2.0)
}

/// The yaw rate, rad/s, of driving at `linear_mps` with inner steering angle `steer_rad`.
pub fn yaw_rate(linear_mps: f64, steer_rad: f64, profile: &TitanProfile) -> f64 {
    if steer_rad == 0.0 || !steer_rad.is_finite() {
        return 0.0;
    }
    let (a, b) = half_sizes(profile);
    let radius = a / steer_rad.abs().tan() + b;
    steer_rad.signum() * linear_mps / radius
}

/// Converts a twist (v, ω) to a speed and inner steering angle within the profile's limits.
/// A turn on the spot (ω with v = 0) is unachievable: it is answered with the tightest steering
/// in the asked direction and no speed, flagged [`ClampFlags::TURN_IN_PLACE_UNACHIEVABLE`].
pub fn twist_to_command(
    linear_mps: f64,
    angular_radps: f64,
    profile: &TitanProfile,
) -> SteerCommand {
    let mut flags = 0;
    let steer = if angular_radps == 0.0 {
        0.0
    } else if linear_mps == 0.0 {
        flags |= ClampFlags::TURN_IN_PLACE_UNACHIEVABLE;
        angular_radps.signum() * profile.max_steer_rad
    } else {
        let (a, b) = half_sizes(profile);
        let curvature_sign = (angular_radps / linear_mps).signum();
        let radius = (linear_mps / angular_radps).abs();
        if radius <= b {
            flags |= ClampFlags::TURN_RADIUS_LIMIT;
            curvature_sign * profile.max_steer_rad
        } else {
            curvature_sign * (a / (radius - b)).atan()
        }
    };
    let mut command = steer_command(linear_mps, steer, profile);
    // A radius the steering cannot reach is a turn-radius limit, not a plain steering limit.
    if command.clamp_flags & ClampFlags::STEER_LIMIT != 0 && angular_radps != 0.0 {
        command.clamp_flags =
            (command.clamp_flags & !ClampFlags::STEER_LIMIT) | ClampFlags::TURN_RADIUS_LIMIT;
    }
    command.clamp_flags |= flags;
    command
}

/// Applies the profile's limits to a speed and inner steering angle: steering to
/// ±`max_steer_rad`, speed to ±`max_linear_mps`, or ±`max_linear_steering_mps` while
/// |steer| > `steer_speed_limit_above_rad`.
pub fn steer_command(linear_mps: f64, steer_rad: f64, profile: &TitanProfile) -> SteerCommand {
    let mut flags = 0;
    let steer = if steer_rad.abs() > profile.max_steer_rad {
        flags |= ClampFlags::STEER_LIMIT;
        steer_rad.signum() * profile.max_steer_rad
    } else {
        steer_rad
    };
    let (limit, flag) = if steer.abs() > profile.steer_speed_limit_above_rad {
        (
            profile.max_linear_steering_mps,
            ClampFlags::LINEAR_LIMIT_STEERING,
        )
    } else {
        (profile.max_linear_mps, ClampFlags::LINEAR_LIMIT)
    };
    let linear = if linear_mps.abs() > limit {
        flags |= flag;
        linear_mps.signum() * limit
    } else {
        linear_mps
    };
    SteerCommand {
        linear_mps: linear,
        steer_rad: steer,
        clamp_flags: flags,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> TitanProfile {
        TitanProfile::default()
    }

    #[test]
    fn straight_driving_needs_no_steering() {
        let c = twist_to_command(1.0, 0.0, &p());
        assert_eq!((c.linear_mps, c.steer_rad, c.clamp_flags), (1.0, 0.0, 0));
    }

    #[test]
    fn twist_to_steer_and_back_agree() {
        for (v, w) in [
            (1.0, 0.3),
            (1.0, -0.3),
            (-0.8, 0.2),
            (0.5, 0.1),
            (-1.2, -0.4),
        ] {
            let c = twist_to_command(v, w, &p());
            assert_eq!(c.clamp_flags, 0, "v={v} w={w}");
            let back = yaw_rate(c.linear_mps, c.steer_rad, &p());
            assert!((back - w).abs() < 1e-9, "v={v} w={w} back={back}");
        }
    }

    #[test]
    fn left_turn_forward_steers_left_and_reversing_mirrors_it() {
        assert!(twist_to_command(1.0, 0.2, &p()).steer_rad > 0.0);
        // Reversing while yawing left means the wheels point right.
        assert!(twist_to_command(-1.0, 0.2, &p()).steer_rad < 0.0);
    }

    #[test]
    fn formula_matches_the_manual_geometry() {
        // R = 2 m: δ = atan(0.4225 / (2 − 0.43)).
        let c = twist_to_command(1.0, 0.5, &p());
        assert!((c.steer_rad - (0.4225f64 / 1.57).atan()).abs() < 1e-12);
    }

    #[test]
    fn turn_on_the_spot_is_clamped_and_flagged_not_dropped() {
        let c = twist_to_command(0.0, 0.5, &p());
        assert_eq!(c.linear_mps, 0.0);
        assert_eq!(c.steer_rad, 0.367);
        assert_ne!(c.clamp_flags & ClampFlags::TURN_IN_PLACE_UNACHIEVABLE, 0);
    }

    #[test]
    fn too_tight_a_turn_is_limited_to_the_minimum_radius() {
        let c = twist_to_command(1.0, 2.0, &p());
        assert_eq!(c.steer_rad, 0.367);
        assert_ne!(c.clamp_flags & ClampFlags::TURN_RADIUS_LIMIT, 0);
        assert!(min_turn_radius_m(&p()) > 1.5 && min_turn_radius_m(&p()) < 1.6);
    }

    #[test]
    fn speed_is_limited_more_while_steering() {
        let c = steer_command(3.5, 0.0, &p());
        assert_eq!(c.linear_mps, 3.0);
        assert_ne!(c.clamp_flags & ClampFlags::LINEAR_LIMIT, 0);
        let c = steer_command(2.0, 0.1, &p());
        assert_eq!(c.linear_mps, 1.5);
        assert_ne!(c.clamp_flags & ClampFlags::LINEAR_LIMIT_STEERING, 0);
        let c = steer_command(-2.0, -0.5, &p());
        assert_eq!((c.linear_mps, c.steer_rad), (-1.5, -0.367));
        assert_ne!(c.clamp_flags & ClampFlags::STEER_LIMIT, 0);
        assert_eq!(steer_command(1.4, 0.3, &p()).clamp_flags, 0);
    }
}
