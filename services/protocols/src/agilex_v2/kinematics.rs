//! Velocity ↔ 0x111 / 0x221 per kinematic kind (`PROTOCOLS-V2` §2.4, §3.3, §3.6, §3.8).
//!
//! * Differential / skid / tracked: (v, ω); v_y is unachievable.
//! * Omni (mecanum SCOUT MINI): (v, ω, v_y).
//! * Ackermann (HUNTER): v and the front inner-wheel angle δᵢ = atan(L / (R − W/2)), signed like
//!   the curvature ω/v; a turn radius below the steering's reach takes the largest angle. Turning
//!   on the spot is impossible. Back: R = L / tan|δᵢ| + W/2, ω = v / R.
//! * Four-wheel steering (RANGER MINI): v_y ≠ 0 → crab (all wheels at atan(v_y / v_x)); a turn
//!   tighter than `min_turn_radius_m` (or ω with v = 0) → spin; otherwise dual Ackermann with
//!   δᵢ = atan((L/2) / (R − W/2)). Back: R = (L/2) / tan|δᵢ| + W/2, ω = v / R (the exact
//!   inverse; AgileX's ROS driver uses ω = 2·v·sin δc / L, which differs by tan vs sin).

use chassis_interfaces::ClampFlags;
use serde::{Deserialize, Serialize};

use super::codec::Motion;
use super::profile::{Kinematics, SpinField, V2Profile};
use crate::command::Turn;

/// RANGER motion modes (their wire numbers are the profile's ⚠ D-12 codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum RangerMode {
    DualAckermann,
    Crab,
    Spin,
    Park,
}

impl RangerMode {
    /// The 0x141 value under `profile` (`None`: this variant has no such mode).
    pub fn code(self, profile: &V2Profile) -> Option<u8> {
        let codes = &profile.ranger_mode_codes;
        match self {
            RangerMode::DualAckermann => Some(codes.dual_ackermann),
            RangerMode::Crab => Some(codes.crab),
            RangerMode::Spin => Some(codes.spin),
            RangerMode::Park => codes.park,
        }
    }

    /// The mode of a 0x291 value.
    pub fn from_code(code: u8, profile: &V2Profile) -> Option<Self> {
        let codes = &profile.ranger_mode_codes;
        if code == codes.dual_ackermann {
            Some(RangerMode::DualAckermann)
        } else if code == codes.crab || Some(code) == codes.side_slip {
            Some(RangerMode::Crab)
        } else if code == codes.spin {
            Some(RangerMode::Spin)
        } else if Some(code) == codes.park {
            Some(RangerMode::Park)
        } else {
            None
        }
    }
}

/// A twist mapped onto 0x111, with the RANGER mode it needs and what was clamped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Planned {
    pub motion: Motion,
    /// Four-wheel steering only; `None` when standing still (the mode is kept).
    pub mode: Option<RangerMode>,
    /// `chassis_interfaces::ClampFlags`.
    pub clamp_flags: u32,
}

fn clamp(value: f64, max: f64, flag: u32, flags: &mut u32) -> f64 {
    if value.abs() > max {
        *flags |= flag;
        value.signum() * max
    } else {
        value
    }
}

/// HUNTER inner angle for turn radius `radius` (> 0), m.
fn ackermann_inner(radius: f64, profile: &V2Profile) -> Option<f64> {
    let denominator = radius - profile.track_m / 2.0;
    (denominator > 0.0).then(|| (profile.wheelbase_m / denominator).atan())
}

/// RANGER dual-Ackermann inner angle for turn radius `radius` (> 0), m.
fn dual_ackermann_inner(radius: f64, profile: &V2Profile) -> Option<f64> {
    let denominator = radius - profile.track_m / 2.0;
    (denominator > 0.0).then(|| (profile.wheelbase_m / 2.0 / denominator).atan())
}

/// Maps a twist onto 0x111 for the profile's kinematics, within its limits. The numbers are a
/// `Velocity`'s: finite.
pub fn plan(linear_x_mps: f64, linear_y_mps: f64, turn: Turn, profile: &V2Profile) -> Planned {
    let mut flags = 0;
    let v = clamp(
        linear_x_mps,
        profile.max_linear_mps,
        ClampFlags::LINEAR_LIMIT,
        &mut flags,
    );
    // A steering angle asked of a robot that turns by yaw rate: the bicycle model's yaw rate.
    let yaw = |v: f64| match turn {
        Turn::YawRate(w) => w,
        Turn::Steer(s) => v * s.tan() / profile.wheelbase_m,
    };
    let mut motion = Motion::default();
    let mut mode = None;
    match profile.kinematics {
        Kinematics::Differential | Kinematics::Omni => {
            motion.linear_mps = v;
            motion.angular_radps = clamp(
                yaw(v),
                profile.max_angular_radps,
                ClampFlags::ANGULAR_LIMIT,
                &mut flags,
            );
            if profile.kinematics == Kinematics::Omni {
                motion.lateral_mps = clamp(
                    linear_y_mps,
                    profile.max_lateral_mps,
                    ClampFlags::LINEAR_LIMIT,
                    &mut flags,
                );
            } else if linear_y_mps != 0.0 {
                flags |= ClampFlags::LATERAL_UNSUPPORTED;
            }
        }
        Kinematics::Ackermann => {
            if linear_y_mps != 0.0 {
                flags |= ClampFlags::LATERAL_UNSUPPORTED;
            }
            motion.linear_mps = v;
            let steer = match turn {
                Turn::Steer(s) => s,
                Turn::YawRate(0.0) => 0.0,
                Turn::YawRate(w) if v == 0.0 => {
                    flags |= ClampFlags::TURN_IN_PLACE_UNACHIEVABLE;
                    w.signum() * profile.max_steer_rad
                }
                Turn::YawRate(w) => {
                    let sign = (w / v).signum();
                    match ackermann_inner((v / w).abs(), profile) {
                        Some(angle) => sign * angle,
                        None => {
                            flags |= ClampFlags::TURN_RADIUS_LIMIT;
                            sign * profile.max_steer_rad
                        }
                    }
                }
            };
            let limit_flag = match turn {
                Turn::Steer(_) => ClampFlags::STEER_LIMIT,
                Turn::YawRate(_) => ClampFlags::TURN_RADIUS_LIMIT,
            };
            motion.steer_rad = clamp(steer, profile.max_steer_rad, limit_flag, &mut flags);
        }
        Kinematics::FourWheelSteer => {
            let w = yaw(v);
            if linear_y_mps != 0.0 {
                if w != 0.0 {
                    flags |= ClampFlags::ANGULAR_LIMIT;
                }
                let vy = clamp(
                    linear_y_mps,
                    profile.max_linear_mps,
                    ClampFlags::LINEAR_LIMIT,
                    &mut flags,
                );
                let (speed, angle) = if v == 0.0 {
                    (vy, std::f64::consts::FRAC_PI_2)
                } else {
                    (v.signum() * v.hypot(vy), (vy / v).atan())
                };
                motion.linear_mps = clamp(
                    speed,
                    profile.max_linear_mps,
                    ClampFlags::LINEAR_LIMIT,
                    &mut flags,
                );
                motion.steer_rad = clamp(
                    angle,
                    profile.max_crab_rad,
                    ClampFlags::STEER_LIMIT,
                    &mut flags,
                );
                mode = Some(RangerMode::Crab);
            } else if w != 0.0 && (v == 0.0 || (v / w).abs() < profile.min_turn_radius_m) {
                let w = clamp(
                    w,
                    profile.max_angular_radps,
                    ClampFlags::ANGULAR_LIMIT,
                    &mut flags,
                );
                if v != 0.0 {
                    flags |= ClampFlags::TURN_RADIUS_LIMIT;
                }
                match profile.spin_speed_field {
                    SpinField::AngularB2 => motion.angular_radps = w,
                    SpinField::WheelSpeedB4 => motion.lateral_mps = w * profile.spin_radius_m,
                }
                mode = Some(RangerMode::Spin);
            } else if v != 0.0 {
                motion.linear_mps = v;
                let steer = if w == 0.0 {
                    0.0
                } else {
                    let sign = (w / v).signum();
                    match dual_ackermann_inner((v / w).abs(), profile) {
                        Some(angle) => sign * angle,
                        None => sign * profile.max_steer_rad,
                    }
                };
                motion.steer_rad = clamp(
                    steer,
                    profile.max_steer_rad,
                    ClampFlags::TURN_RADIUS_LIMIT,
                    &mut flags,
                );
                mode = Some(RangerMode::DualAckermann);
            }
        }
    }
    Planned {
        motion,
        mode,
        clamp_flags: flags,
    }
}

/// The body twist (v, v_y, ω) of a 0x221 report, given the RANGER mode in force.
pub fn body_twist(m: &Motion, mode: Option<RangerMode>, profile: &V2Profile) -> (f64, f64, f64) {
    match profile.kinematics {
        Kinematics::Differential => (m.linear_mps, 0.0, m.angular_radps),
        Kinematics::Omni => (m.linear_mps, m.lateral_mps, m.angular_radps),
        Kinematics::Ackermann => {
            if m.steer_rad == 0.0 {
                return (m.linear_mps, 0.0, 0.0);
            }
            let radius = profile.wheelbase_m / m.steer_rad.abs().tan() + profile.track_m / 2.0;
            (
                m.linear_mps,
                0.0,
                m.steer_rad.signum() * m.linear_mps / radius,
            )
        }
        Kinematics::FourWheelSteer => match mode {
            Some(RangerMode::Crab) => (
                m.linear_mps * m.steer_rad.cos(),
                m.linear_mps * m.steer_rad.sin(),
                0.0,
            ),
            Some(RangerMode::Spin) => match profile.spin_speed_field {
                SpinField::AngularB2 => (0.0, 0.0, m.angular_radps),
                SpinField::WheelSpeedB4 => (0.0, 0.0, -m.linear_mps / profile.spin_radius_m),
            },
            Some(RangerMode::Park) => (0.0, 0.0, 0.0),
            _ => {
                if m.steer_rad == 0.0 {
                    return (m.linear_mps, 0.0, 0.0);
                }
                let radius =
                    profile.wheelbase_m / 2.0 / m.steer_rad.abs().tan() + profile.track_m / 2.0;
                (
                    m.linear_mps,
                    0.0,
                    m.steer_rad.signum() * m.linear_mps / radius,
                )
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agilex_v2::V2Model;

    fn p(model: V2Model) -> V2Profile {
        V2Profile::for_model(model)
    }

    #[test]
    fn differential_drops_and_flags_lateral_and_clamps() {
        let t = p(V2Model::Bunker);
        let out = plan(3.0, 0.2, Turn::YawRate(0.2), &t);
        assert_eq!(out.motion.linear_mps, 1.5);
        assert_eq!(out.motion.angular_radps, 0.2);
        assert_eq!(out.motion.lateral_mps, 0.0);
        assert_ne!(out.clamp_flags & ClampFlags::LINEAR_LIMIT, 0);
        assert_ne!(out.clamp_flags & ClampFlags::LATERAL_UNSUPPORTED, 0);
    }

    #[test]
    fn omni_sends_lateral() {
        let out = plan(0.0, 0.3, Turn::YawRate(0.0), &p(V2Model::ScoutMiniOmni));
        assert_eq!(out.motion.lateral_mps, 0.3);
        assert_eq!(out.clamp_flags, 0);
    }

    #[test]
    fn hunter_steers_and_its_feedback_gives_the_yaw_rate_back() {
        let h = p(V2Model::Hunter);
        for (v, w) in [(1.0, 0.5), (-1.0, 0.5), (0.5, -0.3)] {
            let out = plan(v, 0.0, Turn::YawRate(w), &h);
            assert_eq!(out.clamp_flags, 0, "{v} {w}");
            let (_, _, back) = body_twist(&out.motion, None, &h);
            assert!((back - w).abs() < 1e-9, "{v} {w}: {back}");
        }
        let spot = plan(0.0, 0.0, Turn::YawRate(0.5), &h);
        assert_ne!(spot.clamp_flags & ClampFlags::TURN_IN_PLACE_UNACHIEVABLE, 0);
        assert_eq!(spot.motion.linear_mps, 0.0);
    }

    #[test]
    fn ranger_chooses_its_mode_from_the_twist() {
        let r = p(V2Model::RangerMini);
        let crab = plan(0.5, 0.5, Turn::YawRate(0.0), &r);
        assert_eq!(crab.mode, Some(RangerMode::Crab));
        assert!((crab.motion.steer_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-9);
        let (vx, vy, _) = body_twist(&crab.motion, crab.mode, &r);
        assert!((vx - 0.5).abs() < 1e-9 && (vy - 0.5).abs() < 1e-9);
        let spin = plan(0.0, 0.0, Turn::YawRate(1.0), &r);
        assert_eq!(spin.mode, Some(RangerMode::Spin));
        assert_eq!(spin.motion.angular_radps, 1.0);
        let arc = plan(1.0, 0.0, Turn::YawRate(0.5), &r);
        assert_eq!(arc.mode, Some(RangerMode::DualAckermann));
        let (_, _, w) = body_twist(&arc.motion, arc.mode, &r);
        assert!((w - 0.5).abs() < 1e-9, "{w}");
        assert_eq!(plan(0.0, 0.0, Turn::YawRate(0.0), &r).mode, None);
        // RANGER MINI 1.0: the spin speed goes into b4-5 as a wheel speed.
        let v1 = p(V2Model::RangerMiniV1);
        let spin = plan(0.0, 0.0, Turn::YawRate(0.2), &v1);
        assert!((spin.motion.lateral_mps - 0.2 * 0.254558).abs() < 1e-9);
        assert_eq!(spin.motion.angular_radps, 0.0);
    }
}
