//! What each robot can do, as far as following a path is concerned.
//!
//! The values are the defaults of `chassisd`'s robot profiles (the manuals'), repeated here
//! because a client depends on `chassis-client` only. A robot whose `chassisd` config changes
//! them is driven with `--min-turn-radius` / `--max-angular` / `--speed`.
//!
//! | robot | drive | turns on the spot | top speed | turning limit |
//! | --- | --- | --- | --- | --- |
//! | TITAN | dual Ackermann (front and rear axles steer opposite) | no | 3.0 m/s, 1.5 m/s while \|steer\| > 0.087 rad | radius ≥ 1.53 m |
//! | SCOUT MINI | skid steer | yes | 5.0 m/s (commands in 1 % = 0.05 m/s steps) | 0.5235 rad/s (the manual's full scale) |
//! | XBot | differential | yes | 1.5 m/s (below 0.01 m/s it does not move) | π rad/s |
//! | SCOUT 2.0 (V2) | skid steer | yes | 1.5 m/s | 0.5235 rad/s |
//! | HUNTER 2.0 | front Ackermann | no | 1.5 m/s | radius ≥ 1.30 m (inner angle 0.576 rad) |
//! | HUNTER SE | front Ackermann | no | 1.5 m/s | radius ≥ 1.83 m (inner angle 0.4 rad) |
//! | TRACER | differential | yes | 1.8 m/s | 1.0 rad/s |
//! | BUNKER | tracked | yes | 1.5 m/s | 0.7853 rad/s |
//! | RANGER MINI | four-wheel steering, followed in dual Ackermann | (spins, not used here) | 1.5 m/s | radius ≥ 0.6 m (0.476 m reachable) |

use chassis_client::RobotKind;

/// The robots the planner knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum RobotModel {
    Titan,
    ScoutMini,
    Xbot,
    Scout,
    Hunter,
    HunterSe,
    Tracer,
    Bunker,
    RangerMini,
}

impl RobotModel {
    /// The model of a `ChassisState::robot` value.
    pub fn from_kind(kind: u8) -> Option<Self> {
        match kind {
            RobotKind::TITAN => Some(Self::Titan),
            RobotKind::SCOUT_MINI => Some(Self::ScoutMini),
            RobotKind::XBOT => Some(Self::Xbot),
            RobotKind::SCOUT => Some(Self::Scout),
            RobotKind::HUNTER => Some(Self::Hunter),
            RobotKind::HUNTER_SE => Some(Self::HunterSe),
            RobotKind::TRACER => Some(Self::Tracer),
            RobotKind::BUNKER => Some(Self::Bunker),
            RobotKind::RANGER_MINI => Some(Self::RangerMini),
            _ => None,
        }
    }

    /// The `ChassisState::robot` value of this model.
    pub fn kind(self) -> u8 {
        match self {
            Self::Titan => RobotKind::TITAN,
            Self::ScoutMini => RobotKind::SCOUT_MINI,
            Self::Xbot => RobotKind::XBOT,
            Self::Scout => RobotKind::SCOUT,
            Self::Hunter => RobotKind::HUNTER,
            Self::HunterSe => RobotKind::HUNTER_SE,
            Self::Tracer => RobotKind::TRACER,
            Self::Bunker => RobotKind::BUNKER,
            Self::RangerMini => RobotKind::RANGER_MINI,
        }
    }

    pub fn name(self) -> &'static str {
        RobotKind::name(self.kind())
    }
}

/// How a robot turns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Steering {
    /// Skid or differential drive: any yaw rate up to the limit, also standing still.
    Differential { max_angular_radps: f64 },
    /// Steered wheels: a curvature of at most 1 / `min_turn_radius_m`, and only while moving.
    Ackermann {
        min_turn_radius_m: f64,
        /// Top speed while the path curves more than `turning_above_curvature` (1/m).
        max_linear_turning_mps: f64,
        turning_above_curvature: f64,
    },
}

/// A robot's limits and habits as the path follower sees them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    pub model: RobotModel,
    pub steering: Steering,
    /// Top speed, m/s.
    pub max_linear_mps: f64,
    /// Slowest speed worth commanding, m/s: below it the robot does not move (XBot), or the
    /// command rounds to zero (SCOUT MINI's 1 % steps).
    pub min_linear_mps: f64,
    /// Slowest yaw rate worth commanding for a turn on the spot, rad/s.
    pub min_angular_radps: f64,
    /// Cruise speed when `--speed` is not given, m/s.
    pub default_speed_mps: f64,
    /// Time constant of the robot's speed response, s: how far it coasts after a stop
    /// (speed × lag). The simulated chassis: 0.3 s (TITAN, SCOUT MINI), 0.2 s (XBot).
    pub response_lag_s: f64,
}

/// TITAN's geometry (`TitanProfile` defaults): wheelbase, track, largest inner steering angle.
pub const TITAN_WHEELBASE_M: f64 = 0.845;
pub const TITAN_TRACK_M: f64 = 0.860;
pub const TITAN_MAX_STEER_RAD: f64 = 0.367;
/// SCOUT MINI's yaw rate at 100 % of its motion command (`ScoutMiniProfile` default: the
/// manual's table as printed — not an approximation of π/6).
#[allow(clippy::approx_constant)]
pub const SCOUT_MINI_ANGULAR_FULL_SCALE_RADPS: f64 = 0.5235;
/// Above this inner steering angle TITAN's top speed is 1.5 m/s.
pub const TITAN_FAST_STEER_LIMIT_RAD: f64 = 0.087;

/// Body turning radius of dual-Ackermann steering at inner wheel angle `steer_rad`: the centre
/// of rotation lies on the lateral line through the body centre, R = (L/2) / tan δ + W/2.
pub fn titan_turn_radius_m(steer_rad: f64) -> f64 {
    (TITAN_WHEELBASE_M / 2.0) / steer_rad.abs().tan() + TITAN_TRACK_M / 2.0
}

/// Smallest turning radius of front-wheel Ackermann steering (HUNTER): R = L / tan δ + W/2.
fn front_ackermann_radius_m(wheelbase_m: f64, track_m: f64, max_inner_rad: f64) -> f64 {
    wheelbase_m / max_inner_rad.tan() + track_m / 2.0
}

impl Kinematics {
    /// An AgileX protocol-V2 robot (`V2Profile` defaults).
    fn v2(model: RobotModel, steering: Steering, max_linear_mps: f64) -> Self {
        Self {
            model,
            steering,
            max_linear_mps,
            min_linear_mps: 0.01,
            min_angular_radps: 0.02,
            default_speed_mps: 0.6,
            response_lag_s: 0.2,
        }
    }

    fn ackermann(min_turn_radius_m: f64, max_linear_mps: f64) -> Steering {
        Steering::Ackermann {
            min_turn_radius_m,
            max_linear_turning_mps: max_linear_mps,
            turning_above_curvature: f64::INFINITY,
        }
    }

    /// The defaults of `model`.
    #[allow(clippy::approx_constant)] // 0.5235 and 0.7853 are the SDK's limits as printed
    pub fn of(model: RobotModel) -> Self {
        let differential = |max_angular_radps| Steering::Differential { max_angular_radps };
        match model {
            RobotModel::Scout => Self::v2(model, differential(0.5235), 1.5),
            RobotModel::Tracer => Self::v2(model, differential(1.0), 1.8),
            RobotModel::Bunker => Self::v2(model, differential(0.7853), 1.5),
            RobotModel::Hunter => Self::v2(
                model,
                Self::ackermann(front_ackermann_radius_m(0.650, 0.605, 0.576), 1.5),
                1.5,
            ),
            RobotModel::HunterSe => Self::v2(
                model,
                Self::ackermann(front_ackermann_radius_m(0.657, 0.550, 0.400), 1.5),
                1.5,
            ),
            // Dual Ackermann reaches R = (L/2) / tan δ + W/2 = 0.476 m (L 0.494, W 0.364,
            // δ 0.6981 rad); a tighter request makes the driver spin instead. Paths keep a
            // margin so the follower's corrections stay in dual Ackermann.
            RobotModel::RangerMini => Self::v2(model, Self::ackermann(0.6, 1.5), 1.5),
            RobotModel::Titan => Self {
                model,
                steering: Steering::Ackermann {
                    min_turn_radius_m: titan_turn_radius_m(TITAN_MAX_STEER_RAD),
                    max_linear_turning_mps: 1.5,
                    turning_above_curvature: 1.0 / titan_turn_radius_m(TITAN_FAST_STEER_LIMIT_RAD),
                },
                max_linear_mps: 3.0,
                min_linear_mps: 0.05,
                min_angular_radps: 0.0,
                default_speed_mps: 1.0,
                response_lag_s: 0.3,
            },
            RobotModel::ScoutMini => Self {
                model,
                steering: Steering::Differential {
                    max_angular_radps: SCOUT_MINI_ANGULAR_FULL_SCALE_RADPS,
                },
                max_linear_mps: 5.0,
                min_linear_mps: 0.05,
                min_angular_radps: 0.06,
                default_speed_mps: 0.8,
                response_lag_s: 0.3,
            },
            RobotModel::Xbot => Self {
                model,
                steering: Steering::Differential {
                    max_angular_radps: std::f64::consts::PI,
                },
                max_linear_mps: 1.5,
                min_linear_mps: 0.03,
                min_angular_radps: 0.06,
                default_speed_mps: 0.8,
                response_lag_s: 0.2,
            },
        }
    }

    /// True when the robot can turn on the spot.
    pub fn turns_on_the_spot(&self) -> bool {
        matches!(self.steering, Steering::Differential { .. })
    }

    /// Smallest turning radius, m (0 for a robot that turns on the spot).
    pub fn min_turn_radius_m(&self) -> f64 {
        match self.steering {
            Steering::Differential { .. } => 0.0,
            Steering::Ackermann {
                min_turn_radius_m, ..
            } => min_turn_radius_m,
        }
    }

    /// Largest curvature the robot can drive, 1/m (infinite for one that turns on the spot).
    pub fn max_curvature(&self) -> f64 {
        match self.steering {
            Steering::Differential { .. } => f64::INFINITY,
            Steering::Ackermann {
                min_turn_radius_m, ..
            } => 1.0 / min_turn_radius_m,
        }
    }

    /// Largest yaw rate, rad/s (infinite when only the curvature limits it).
    pub fn max_angular_radps(&self) -> f64 {
        match self.steering {
            Steering::Differential { max_angular_radps } => max_angular_radps,
            Steering::Ackermann { .. } => f64::INFINITY,
        }
    }

    /// Sets the smallest turning radius (Ackermann) — a `chassisd` config with another geometry.
    pub fn with_min_turn_radius(mut self, radius_m: f64) -> Self {
        if let Steering::Ackermann {
            min_turn_radius_m, ..
        } = &mut self.steering
        {
            *min_turn_radius_m = radius_m;
        }
        self
    }

    /// Sets the largest yaw rate (differential) — e.g. SCOUT MINI with another full scale.
    pub fn with_max_angular(mut self, radps: f64) -> Self {
        if let Steering::Differential { max_angular_radps } = &mut self.steering {
            *max_angular_radps = radps;
        }
        self
    }

    /// Top speed on a path of curvature `curvature` (1/m) from the robot's own limits: TITAN's
    /// lower limit while steering, a differential robot's yaw-rate limit.
    pub fn max_speed_at(&self, curvature: f64) -> f64 {
        let k = curvature.abs();
        match self.steering {
            Steering::Differential { max_angular_radps } => {
                if k > 0.0 {
                    self.max_linear_mps.min(max_angular_radps / k)
                } else {
                    self.max_linear_mps
                }
            }
            Steering::Ackermann {
                max_linear_turning_mps,
                turning_above_curvature,
                ..
            } => {
                if k > turning_above_curvature {
                    self.max_linear_mps.min(max_linear_turning_mps)
                } else {
                    self.max_linear_mps
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn titan_cannot_turn_tighter_than_about_one_and_a_half_metres() {
        let k = Kinematics::of(RobotModel::Titan);
        let r = k.min_turn_radius_m();
        assert!(r > 1.52 && r < 1.54, "{r}");
        assert!(!k.turns_on_the_spot());
        // 1.5 m/s once the steering exceeds 0.087 rad, i.e. below a radius of about 5.3 m.
        assert_eq!(k.max_speed_at(1.0 / 5.0), 1.5);
        assert_eq!(k.max_speed_at(1.0 / 6.0), 3.0);
    }

    #[test]
    fn skid_and_differential_robots_turn_on_the_spot_within_their_yaw_rate() {
        let scout = Kinematics::of(RobotModel::ScoutMini);
        assert!(scout.turns_on_the_spot());
        assert_eq!(scout.max_curvature(), f64::INFINITY);
        assert!(
            (scout.max_speed_at(2.0) - SCOUT_MINI_ANGULAR_FULL_SCALE_RADPS / 2.0).abs() < 1e-12
        );
        let xbot = Kinematics::of(RobotModel::Xbot).with_max_angular(1.0);
        assert_eq!(xbot.max_angular_radps(), 1.0);
        for m in [
            RobotModel::Titan,
            RobotModel::ScoutMini,
            RobotModel::Xbot,
            RobotModel::Scout,
            RobotModel::Hunter,
            RobotModel::HunterSe,
            RobotModel::Tracer,
            RobotModel::Bunker,
            RobotModel::RangerMini,
        ] {
            assert_eq!(RobotModel::from_kind(m.kind()), Some(m));
        }
        assert_eq!(RobotModel::ScoutMini.name(), "scout-mini");
    }
}
