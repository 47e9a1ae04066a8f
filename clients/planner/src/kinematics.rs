//! What the robot can do, as far as following a path is concerned — read from the
//! `RobotDescription` chassisd publishes (`chassis/<name>/robot`), never from a table of robots:
//!
//! * **how it turns**, from its kinematics: differential, skid-steered, tracked and omni robots
//!   turn on the spot; Ackermann, dual-Ackermann and four-wheel-steered robots are followed
//!   with steered wheels (a four-wheel-steered robot spins on the spot only below its smallest
//!   dual-Ackermann radius, a change of mode the follower keeps clear of);
//! * **its smallest turning radius** (robots that steer): the larger of the description's
//!   `geometry.min_turn_radius_m` and the radius its effective steering limit reaches with its
//!   wheelbase and track (R = L / tan δ + W/2 with the front axle steering, (L/2) / tan δ + W/2
//!   with both), so a tighter `[mux.limits]` steering limit widens it, and kept
//!   [`TURN_RADIUS_MARGIN`] clear of the boundary, where a driver clamps the angle or (four-wheel
//!   steering) spins instead;
//! * **its speed limits**: the description's effective limits (the robot's after every
//!   `[profile]` override, tightened by chassisd's `[mux.limits]`): forward, reverse, yaw rate
//!   where there is one (the mux clamps a steered robot's yaw rate too, which would change the
//!   curvature driven), and the sideways speed of a robot that can move sideways.
//!
//! What no description states is the planner's own tuning, the same for every robot: the
//! slowest speed and yaw rate worth commanding ([`MIN_LINEAR_MPS`]: the coarsest command
//! resolution among the robots, 1 % of 5 m/s; [`MIN_ANGULAR_RADPS`]), how long the robot coasts
//! after a stop ([`RESPONSE_LAG_S`]: the simulated chassis' response, 0.2-0.3 s), and the cruise
//! speed when `--speed` is not given ([`DEFAULT_SPEED_MPS`], within the robot's limit).

use chassis_client::{DescriptionFlags, Kinematics as KinematicsKind, RobotDescription};
use thiserror::Error;

/// Slowest speed worth commanding, m/s: below it a robot may not move (the XBot below
/// 0.01 m/s) or the command rounds to zero (the SCOUT MINI's 1 % steps of 5 m/s).
pub const MIN_LINEAR_MPS: f64 = 0.05;
/// Slowest yaw rate worth commanding for a turn on the spot, rad/s.
pub const MIN_ANGULAR_RADPS: f64 = 0.06;
/// How long the robot takes to answer a change of speed, s: it coasts speed × this after a stop.
pub const RESPONSE_LAG_S: f64 = 0.25;
/// Cruise speed when `--speed` is not given, m/s (or the robot's limit, if lower).
pub const DEFAULT_SPEED_MPS: f64 = 0.8;
/// A steered robot is asked for radii at least this × its smallest: at the boundary itself a
/// driver clamps its steering angle, or (four-wheel steering) spins on the spot instead.
pub const TURN_RADIUS_MARGIN: f64 = 1.02;

/// How a robot turns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Steering {
    /// Skid, tracked, differential or omni drive: any yaw rate up to the limit, also standing
    /// still.
    Differential,
    /// Steered wheels: a curvature of at most 1 / `min_turn_radius_m`, and only while moving.
    Ackermann { min_turn_radius_m: f64 },
}

/// A robot's limits as the path follower sees them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub steering: Steering,
    /// Top forward speed, m/s.
    pub max_linear_mps: f64,
    /// Top reverse speed (a positive number), m/s.
    pub max_reverse_mps: f64,
    /// Largest |yaw rate|, rad/s (infinite where nothing limits it but the curvature).
    pub max_angular_radps: f64,
    /// Largest |sideways speed|, m/s (0: the robot cannot move sideways).
    pub lateral_mps: f64,
    /// Slowest speed worth commanding, m/s.
    pub min_linear_mps: f64,
    /// Slowest yaw rate worth commanding for a turn on the spot, rad/s.
    pub min_angular_radps: f64,
    /// Cruise speed when `--speed` is not given, m/s.
    pub default_speed_mps: f64,
    /// Time constant of the robot's speed response, s: how far it coasts after a stop
    /// (speed × lag).
    pub response_lag_s: f64,
}

/// Why a description cannot be driven.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum KinematicsError {
    #[error(
        "the description of {robot} gives no forward speed limit (robot and configured limits \
         are both unset)"
    )]
    NoSpeedLimit { robot: String },
    #[error(
        "{robot} steers its wheels, but its description gives neither a turning radius nor a \
         steering limit with its wheelbase and track"
    )]
    NoTurnRadius { robot: String },
    #[error("{robot} has kinematics {kinematics} ({name}), which the planner does not know")]
    UnknownKinematics {
        robot: String,
        kinematics: u8,
        name: &'static str,
    },
}

/// `kind_name` and `model` of a description, for messages (`hunter`, `scout-mini (scout-mini-omni)`).
pub fn robot_label(d: &RobotDescription) -> String {
    match (d.kind_name(), d.model()) {
        ("", _) => format!("robot kind {}", d.kind),
        (kind, model) if model.is_empty() || model == kind => kind.to_string(),
        (kind, model) => format!("{kind} ({model})"),
    }
}

fn positive(value: f64) -> Option<f64> {
    (value.is_finite() && value > 0.0).then_some(value)
}

/// The radius of `base_link`'s path at inner steering angle `steer_rad`: the turn centre lies on
/// the rear axle's line (front steering) or half way between the axles (both steering).
fn radius_at_steer(kinematics: u8, d: &RobotDescription, steer_rad: f64) -> Option<f64> {
    let wheelbase = positive(d.geometry.wheelbase_m)?;
    let half_track = positive(d.geometry.track_m).map_or(0.0, |w| w / 2.0);
    let tan = positive(steer_rad.abs().tan())?;
    let along = match kinematics {
        KinematicsKind::ACKERMANN => wheelbase,
        _ => wheelbase / 2.0,
    };
    Some(along / tan + half_track)
}

impl Kinematics {
    /// The robot a description describes, within its effective limits.
    pub fn from_description(d: &RobotDescription) -> Result<Self, KinematicsError> {
        let robot = robot_label(d);
        let limits = d.effective_limits();
        let max_linear_mps =
            positive(limits.forward_mps).ok_or_else(|| KinematicsError::NoSpeedLimit {
                robot: robot.clone(),
            })?;
        let max_reverse_mps = positive(limits.reverse_mps).unwrap_or(max_linear_mps);
        let max_angular_radps = positive(limits.angular_radps).unwrap_or(f64::INFINITY);
        let lateral_mps = if d.flags & DescriptionFlags::LATERAL != 0 {
            positive(limits.lateral_mps).unwrap_or(0.0)
        } else {
            0.0
        };
        let steering = match d.kinematics {
            KinematicsKind::DIFFERENTIAL
            | KinematicsKind::SKID_STEER
            | KinematicsKind::TRACKED
            | KinematicsKind::OMNI => Steering::Differential,
            k @ (KinematicsKind::ACKERMANN
            | KinematicsKind::DUAL_ACKERMANN
            | KinematicsKind::FOUR_WHEEL_STEER) => {
                let described = positive(d.geometry.min_turn_radius_m);
                let reached = radius_at_steer(k, d, limits.steer_rad);
                let radius = match (described, reached) {
                    (Some(a), Some(b)) => a.max(b),
                    (Some(r), None) | (None, Some(r)) => r,
                    (None, None) => return Err(KinematicsError::NoTurnRadius { robot }),
                };
                Steering::Ackermann {
                    min_turn_radius_m: radius * TURN_RADIUS_MARGIN,
                }
            }
            other => {
                return Err(KinematicsError::UnknownKinematics {
                    robot,
                    kinematics: other,
                    name: KinematicsKind::name(other),
                });
            }
        };
        Ok(Self {
            steering,
            max_linear_mps,
            max_reverse_mps,
            max_angular_radps,
            lateral_mps,
            min_linear_mps: MIN_LINEAR_MPS.min(max_linear_mps),
            min_angular_radps: MIN_ANGULAR_RADPS.min(max_angular_radps),
            default_speed_mps: DEFAULT_SPEED_MPS.min(max_linear_mps),
            response_lag_s: RESPONSE_LAG_S,
        })
    }

    /// True when the robot can turn on the spot.
    pub fn turns_on_the_spot(&self) -> bool {
        matches!(self.steering, Steering::Differential)
    }

    /// Smallest turning radius the follower asks for, m (0 for a robot that turns on the spot).
    pub fn min_turn_radius_m(&self) -> f64 {
        match self.steering {
            Steering::Differential => 0.0,
            Steering::Ackermann { min_turn_radius_m } => min_turn_radius_m,
        }
    }

    /// Largest curvature the robot can drive, 1/m (infinite for one that turns on the spot).
    pub fn max_curvature(&self) -> f64 {
        match self.steering {
            Steering::Differential => f64::INFINITY,
            Steering::Ackermann { min_turn_radius_m } => 1.0 / min_turn_radius_m,
        }
    }

    /// Largest yaw rate, rad/s (infinite when only the curvature limits it).
    pub fn max_angular_radps(&self) -> f64 {
        self.max_angular_radps
    }

    /// Widens the smallest turning radius (robots that steer) — `--min-turn-radius`.
    pub fn with_min_turn_radius(mut self, radius_m: f64) -> Self {
        if let Steering::Ackermann { min_turn_radius_m } = &mut self.steering {
            *min_turn_radius_m = radius_m;
        }
        self
    }

    /// Lowers the largest yaw rate — `--max-angular`.
    pub fn with_max_angular(mut self, radps: f64) -> Self {
        self.max_angular_radps = radps;
        self.min_angular_radps = self.min_angular_radps.min(radps);
        self
    }

    /// Top speed on a path of curvature `curvature` (1/m): the speed limit, and the yaw-rate
    /// limit on a curve.
    pub fn max_speed_at(&self, curvature: f64) -> f64 {
        let k = curvature.abs();
        if k > 0.0 {
            self.max_linear_mps.min(self.max_angular_radps / k)
        } else {
            self.max_linear_mps
        }
    }

    /// `newer`'s limits with this one's steering, if a path built for this one still fits
    /// `newer`: the same way of turning, and no wider a turning radius (a newer description —
    /// protocol detection deciding, a restarted chassisd — changes the limits under a path).
    pub fn updated_by(&self, newer: &Kinematics) -> Option<Kinematics> {
        let fits = match (self.steering, newer.steering) {
            (Steering::Differential, Steering::Differential) => true,
            (
                Steering::Ackermann {
                    min_turn_radius_m: built,
                },
                Steering::Ackermann {
                    min_turn_radius_m: now,
                },
            ) => now <= built + 1e-9,
            _ => false,
        };
        fits.then_some(Kinematics {
            steering: self.steering,
            ..*newer
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::{JointSource, MotionLimits};

    /// A description as chassisd would publish it, without chassis-protocols.
    fn described(kinematics: u8) -> RobotDescription {
        let mut d = RobotDescription {
            kind: 1,
            kinematics,
            ..RobotDescription::default()
        };
        d.set_kind_name("test-robot");
        d.robot_limits = MotionLimits {
            forward_mps: 1.5,
            reverse_mps: 1.0,
            lateral_mps: 0.0,
            angular_radps: 0.8,
            steer_rad: 0.5,
            ..MotionLimits::NONE
        };
        d.geometry.wheelbase_m = 0.6;
        d.geometry.track_m = 0.5;
        let _ = d.push_joint("front_steer_joint", JointSource::FRONT_STEER, 0);
        d
    }

    #[test]
    fn a_robot_that_turns_on_the_spot_keeps_its_yaw_rate_and_speeds() {
        let k = Kinematics::from_description(&described(KinematicsKind::SKID_STEER)).unwrap();
        assert!(k.turns_on_the_spot());
        assert_eq!(k.max_curvature(), f64::INFINITY);
        assert_eq!((k.max_linear_mps, k.max_reverse_mps), (1.5, 1.0));
        assert_eq!(k.max_angular_radps(), 0.8);
        assert!((k.max_speed_at(2.0) - 0.4).abs() < 1e-12);
        assert_eq!(k.lateral_mps, 0.0);
        assert_eq!(k.default_speed_mps, DEFAULT_SPEED_MPS);
    }

    #[test]
    fn a_steered_robot_turns_no_tighter_than_its_steering_reaches() {
        let mut d = described(KinematicsKind::ACKERMANN);
        // Front steering: R = L / tan δ + W/2.
        let reach = 0.6 / 0.5f64.tan() + 0.25;
        let k = Kinematics::from_description(&d).unwrap();
        assert!(!k.turns_on_the_spot());
        assert!((k.min_turn_radius_m() - reach * TURN_RADIUS_MARGIN).abs() < 1e-9);
        // A larger described radius wins.
        d.geometry.min_turn_radius_m = 3.0;
        let k = Kinematics::from_description(&d).unwrap();
        assert!((k.min_turn_radius_m() - 3.0 * TURN_RADIUS_MARGIN).abs() < 1e-9);
        // A tighter configured steering limit widens it.
        d.geometry.min_turn_radius_m = 0.0;
        d.configured_limits.steer_rad = 0.2;
        let k = Kinematics::from_description(&d).unwrap();
        let reach = 0.6 / 0.2f64.tan() + 0.25;
        assert!((k.min_turn_radius_m() - reach * TURN_RADIUS_MARGIN).abs() < 1e-9);
        // Both axles steering: half the wheelbase.
        d.configured_limits.steer_rad = f64::NAN;
        d.kinematics = KinematicsKind::DUAL_ACKERMANN;
        let k = Kinematics::from_description(&d).unwrap();
        let reach = 0.3 / 0.5f64.tan() + 0.25;
        assert!((k.min_turn_radius_m() - reach * TURN_RADIUS_MARGIN).abs() < 1e-9);
    }

    #[test]
    fn configured_limits_tighten_the_robots_own() {
        let mut d = described(KinematicsKind::DIFFERENTIAL);
        d.configured_limits.forward_mps = 0.4;
        d.configured_limits.angular_radps = 0.3;
        let k = Kinematics::from_description(&d).unwrap();
        assert_eq!(k.max_linear_mps, 0.4);
        assert_eq!(k.max_angular_radps(), 0.3);
        assert_eq!(
            k.default_speed_mps, 0.4,
            "the cruise speed stays within the limit"
        );
    }

    #[test]
    fn a_robot_that_moves_sideways_says_so_and_nan_means_no_limit() {
        let mut d = described(KinematicsKind::OMNI);
        d.robot_limits.lateral_mps = 0.7;
        d.flags |= DescriptionFlags::LATERAL;
        d.robot_limits.angular_radps = f64::NAN;
        let k = Kinematics::from_description(&d).unwrap();
        assert_eq!(k.lateral_mps, 0.7);
        assert_eq!(k.max_angular_radps(), f64::INFINITY);
    }

    #[test]
    fn a_description_without_what_the_planner_needs_is_refused() {
        let mut d = described(KinematicsKind::ACKERMANN);
        d.robot_limits.forward_mps = f64::NAN;
        assert!(matches!(
            Kinematics::from_description(&d),
            Err(KinematicsError::NoSpeedLimit { .. })
        ));
        let mut d = described(KinematicsKind::ACKERMANN);
        d.robot_limits.steer_rad = f64::NAN;
        d.geometry.min_turn_radius_m = f64::NAN;
        let err = Kinematics::from_description(&d).unwrap_err();
        assert!(err.to_string().contains("test-robot steers"), "{err}");
        let d = described(0);
        assert!(matches!(
            Kinematics::from_description(&d),
            Err(KinematicsError::UnknownKinematics { .. })
        ));
    }
}
