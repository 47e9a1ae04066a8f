//! What each robot's body looks like from outside: a box around its wheels and where its range
//! sensors sit. Drawn by every view of a robot (the live Foxglove view, `chassis record`'s
//! `/tf`), so a robot added to [`Robot`] gets a body here or nowhere.
//!
//! Axes as REP 103: x forward, y left, z up, yaw left positive; the origin is `base_link`, the
//! centre of the footprint on the ground.

use crate::Robot;
use crate::profile::{Profile, ScoutMiniProfile, TitanProfile};

/// Which kind of range sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RangeKind {
    /// `RangesState::ultrasonic_m`.
    Ultrasonic,
    /// `RangesState::ir_m`.
    Ir,
}

/// A range sensor mounted on the body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorMount {
    /// Its frame's name (`us_left`, `ir_centre`, …).
    pub frame: &'static str,
    pub kind: RangeKind,
    /// Index into `RangesState::ultrasonic_m` or `ir_m`.
    pub index: usize,
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// Full opening angle of the sensor's cone, rad.
    pub cone_rad: f64,
}

/// The body of a robot: the box drawn for it and its range sensors.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub sensors: Vec<SensorMount>,
}

impl Body {
    /// The footprint: the wheelbase × track rectangle of the profile's defaults with the wheels'
    /// size around it (TITAN, SCOUT MINI, the protocol-V2 robots); the XBot's body (its profile
    /// has no wheelbase) with its six range sensors: ultrasonic rangers on the front edge looking
    /// 30° left, ahead and 30° right, IR cliff sensors on the rear edge looking back (their
    /// mounting is not in the manual: evenly spread over the width).
    pub fn of(robot: Robot) -> Self {
        match robot {
            Robot::Titan => {
                let p = TitanProfile::default();
                Body {
                    length_m: p.wheelbase_m + 0.35,
                    width_m: p.track_m + 0.25,
                    height_m: 0.45,
                    sensors: Vec::new(),
                }
            }
            Robot::ScoutMini => {
                let p = ScoutMiniProfile::default();
                Body {
                    length_m: p.wheelbase_m + 0.2,
                    width_m: p.track_m + 0.12,
                    height_m: 0.25,
                    sensors: Vec::new(),
                }
            }
            Robot::Scout
            | Robot::Hunter
            | Robot::HunterSe
            | Robot::Tracer
            | Robot::Bunker
            | Robot::RangerMini => match Profile::default_for(robot) {
                Profile::V2(p) => Body {
                    length_m: p.wheelbase_m + 0.2,
                    width_m: p.track_m + 0.15,
                    height_m: 0.3,
                    sensors: Vec::new(),
                },
                // Every protocol-V2 robot's default profile is a V2 one; anything else is drawn
                // as a SCOUT MINI.
                _ => Body::of(Robot::ScoutMini),
            },
            Robot::Xbot => {
                let (length_m, width_m) = (0.5, 0.4);
                let side = std::f64::consts::FRAC_PI_6;
                let mount = |frame, kind, index, x_m, y_m, yaw_rad, cone_deg: f64| SensorMount {
                    frame,
                    kind,
                    index,
                    x_m,
                    y_m,
                    yaw_rad,
                    cone_rad: cone_deg.to_radians(),
                };
                let (front, rear, w) = (length_m / 2.0, -length_m / 2.0, width_m / 2.0 - 0.05);
                let back = std::f64::consts::PI;
                Body {
                    length_m,
                    width_m,
                    height_m: 0.3,
                    sensors: vec![
                        mount("us_left", RangeKind::Ultrasonic, 0, front, w, side, 30.0),
                        mount("us_centre", RangeKind::Ultrasonic, 1, front, 0.0, 0.0, 30.0),
                        mount("us_right", RangeKind::Ultrasonic, 2, front, -w, -side, 30.0),
                        mount("ir_left", RangeKind::Ir, 0, rear, w, back, 10.0),
                        mount("ir_centre", RangeKind::Ir, 1, rear, 0.0, back, 10.0),
                        mount("ir_right", RangeKind::Ir, 2, rear, -w, back, 10.0),
                    ],
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_robot_has_a_body_around_its_wheels() {
        for robot in Robot::ALL {
            let body = Body::of(robot);
            assert!(
                body.length_m > 0.2 && body.width_m > 0.2 && body.height_m > 0.1,
                "{robot:?}: {body:?}"
            );
        }
    }

    #[test]
    fn only_the_xbot_carries_range_sensors_each_on_its_own_reading() {
        let xbot = Body::of(Robot::Xbot);
        assert_eq!(xbot.sensors.len(), 6);
        for kind in [RangeKind::Ultrasonic, RangeKind::Ir] {
            let mut indices: Vec<usize> = xbot
                .sensors
                .iter()
                .filter(|s| s.kind == kind)
                .map(|s| s.index)
                .collect();
            indices.sort_unstable();
            assert_eq!(indices, [0, 1, 2], "{kind:?}");
        }
        assert!(
            Robot::ALL
                .into_iter()
                .filter(|r| *r != Robot::Xbot)
                .all(|r| Body::of(r).sensors.is_empty())
        );
    }
}
