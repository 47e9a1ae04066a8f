//! The built-in paths, in the frame of the robot's start pose (x ahead, y left), starting at the
//! robot:
//!
//! * `line`: straight ahead for `size` metres;
//! * `square`: `size` ahead, then three left turns back to the start (counter-clockwise);
//! * `figure-eight`: two tangent circles of diameter `size / 2`, the left one first, crossing at
//!   the start with the start heading — `size` across, `size / 2` wide.
//!
//! A robot that turns on the spot drives the square's corners exactly (it stops and turns). A
//! robot with a minimum turning radius (TITAN: 1.53 m by its description, 1.56 m as the planner
//! asks for it) cannot: its square gets corners rounded to [`CORNER_RADIUS_MARGIN`] × its
//! minimum radius, which needs `size ≥ 2 ×` that radius (3.59 m for TITAN); its figure-eight
//! needs circles of that radius (`size ≥ 4 ×`, 7.17 m).
//! The margin leaves the path follower room to correct on an arc. A size too small for the robot
//! is refused with the smallest that works, and the default size is the smallest multiple of
//! 0.5 m from 2 m up that fits.

use std::f64::consts::{FRAC_PI_2, TAU};

use thiserror::Error;

use crate::geometry::Point;
use crate::kinematics::Kinematics;
use crate::path::{Path, PathError};

/// Spacing of the samples of a curve, m.
pub const SAMPLE_STEP_M: f64 = 0.05;
/// A robot with a minimum turning radius R is given corners and circles of this × R.
pub const CORNER_RADIUS_MARGIN: f64 = 1.15;
/// Size when `--size` is not given (if the robot's turning radius allows it), m.
pub const DEFAULT_SIZE_M: f64 = 2.0;

/// A built-in path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Shape {
    Line,
    Square,
    FigureEight,
}

impl Shape {
    pub fn name(self) -> &'static str {
        match self {
            Shape::Line => "line",
            Shape::Square => "square",
            Shape::FigureEight => "figure-eight",
        }
    }

    /// True when the shape ends where it starts (so it can be driven more than once).
    pub fn is_closed(self) -> bool {
        !matches!(self, Shape::Line)
    }

    /// Smallest size, m, whose corners or circles have at least `radius_m`.
    pub fn min_size_m(self, radius_m: f64) -> f64 {
        match self {
            Shape::Line => 0.0,
            Shape::Square => 2.0 * radius_m,
            Shape::FigureEight => 4.0 * radius_m,
        }
    }

    /// `--size` when none is given: 2 m, or the smallest multiple of 0.5 m the robot can turn.
    pub fn default_size_m(self, kinematics: &Kinematics) -> f64 {
        let min = self.min_size_m(corner_radius_m(kinematics));
        DEFAULT_SIZE_M.max((min * 2.0).ceil() / 2.0)
    }
}

/// Radius of the corners built for a robot: 0 when it turns on the spot.
pub fn corner_radius_m(kinematics: &Kinematics) -> f64 {
    kinematics.min_turn_radius_m() * CORNER_RADIUS_MARGIN
}

/// Why a shape cannot be built.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ShapeError {
    #[error("--size must be a positive number of metres (got {0})")]
    BadSize(f64),
    #[error(
        "a {shape} of {size_m:.2} m is too small for the robot: it cannot turn tighter than \
         {min_radius_m:.2} m, so its corners get a {radius_m:.2} m radius and the {shape} \
         needs --size {min_size_m:.2} or more"
    )]
    TooSmall {
        shape: &'static str,
        size_m: f64,
        min_size_m: f64,
        radius_m: f64,
        min_radius_m: f64,
    },
    #[error("the {0} does not end where it starts: it can only be driven once")]
    NotClosed(&'static str),
    #[error(transparent)]
    Path(#[from] PathError),
}

/// The shape's polyline, corners sharp.
pub fn outline(shape: Shape, size_m: f64) -> Result<Path, ShapeError> {
    if !(size_m.is_finite() && size_m > 0.0) {
        return Err(ShapeError::BadSize(size_m));
    }
    let s = size_m;
    let points = match shape {
        Shape::Line => vec![Point::new(0.0, 0.0), Point::new(s, 0.0)],
        Shape::Square => vec![
            Point::new(0.0, 0.0),
            Point::new(s, 0.0),
            Point::new(s, s),
            Point::new(0.0, s),
            Point::new(0.0, 0.0),
        ],
        Shape::FigureEight => {
            let r = s / 4.0;
            // At least 16 samples a circle (r is positive and finite: the cast is exact enough).
            let n = ((TAU * r / SAMPLE_STEP_M).ceil() as usize).max(16);
            let mut points = Vec::with_capacity(2 * n + 1);
            // Left circle (centre (0, r)) counter-clockwise from its bottom, then the right one
            // (centre (0, −r)) clockwise from its top: both pass the origin heading +x.
            for k in 0..n {
                let phi = -FRAC_PI_2 + TAU * k as f64 / n as f64;
                points.push(Point::new(r * phi.cos(), r + r * phi.sin()));
            }
            for k in 0..n {
                let phi = FRAC_PI_2 - TAU * k as f64 / n as f64;
                points.push(Point::new(r * phi.cos(), -r + r * phi.sin()));
            }
            points.push(Point::new(0.0, 0.0));
            points
        }
    };
    Ok(Path::new(points)?)
}

/// The shape of `size_m` for `kinematics`, driven `loops` times: corners rounded to the robot's
/// turning radius where it has one.
pub fn build(
    shape: Shape,
    size_m: f64,
    loops: usize,
    kinematics: &Kinematics,
) -> Result<Path, ShapeError> {
    if loops > 1 && !shape.is_closed() {
        return Err(ShapeError::NotClosed(shape.name()));
    }
    let outline = outline(shape, size_m)?;
    let radius = corner_radius_m(kinematics);
    if radius <= 0.0 {
        return Ok(outline.repeated(loops, 1e-9)?);
    }
    let min_size = shape.min_size_m(radius);
    if size_m + 1e-9 < min_size {
        return Err(ShapeError::TooSmall {
            shape: shape.name(),
            size_m,
            min_size_m: min_size,
            radius_m: radius,
            min_radius_m: kinematics.min_turn_radius_m(),
        });
    }
    let repeated = outline.repeated(loops, 1e-9)?;
    match shape {
        // Circles of at least the radius already: nothing to round.
        Shape::FigureEight | Shape::Line => Ok(repeated),
        Shape::Square => Ok(repeated.rounded(radius, SAMPLE_STEP_M)?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;
    use std::f64::consts::PI;

    /// A robot as chassisd describes it with its registry defaults.
    fn kin(kind: RobotKind) -> Kinematics {
        Kinematics::from_description(&describe(&kind.entry().defaults())).unwrap()
    }

    #[test]
    fn every_robot_gets_every_shape_at_its_default_size() {
        for kind in RobotKind::ALL {
            let k = kin(kind);
            for shape in [Shape::Line, Shape::Square, Shape::FigureEight] {
                let size = shape.default_size_m(&k);
                let path = build(shape, size, 1, &k)
                    .unwrap_or_else(|e| panic!("{kind}: {shape:?} of {size} m: {e}"));
                assert!(path.length_m() >= size, "{kind}: {shape:?}");
            }
        }
    }

    #[test]
    fn a_line_is_as_long_as_its_size_and_open() {
        let p = build(Shape::Line, 3.0, 1, &kin(RobotKind::Xbot)).unwrap();
        assert!((p.length_m() - 3.0).abs() < 1e-12);
        assert!(!p.is_closed(0.01));
        assert_eq!(
            build(Shape::Line, 3.0, 2, &kin(RobotKind::Xbot)),
            Err(ShapeError::NotClosed("line"))
        );
    }

    #[test]
    fn a_square_is_four_sides_long_and_closed() {
        for robot in [RobotKind::ScoutMini, RobotKind::Xbot] {
            let p = build(Shape::Square, 2.0, 1, &kin(robot)).unwrap();
            assert!((p.length_m() - 8.0).abs() < 1e-12);
            assert!(p.is_closed(1e-12));
            let twice = build(Shape::Square, 2.0, 2, &kin(robot)).unwrap();
            assert!((twice.length_m() - 16.0).abs() < 1e-12);
        }
    }

    #[test]
    fn a_figure_eight_is_two_closed_circles_long() {
        let p = build(Shape::FigureEight, 2.0, 1, &kin(RobotKind::ScoutMini)).unwrap();
        let expected = 2.0 * 2.0 * PI * 0.5;
        // A sampled circle is a little shorter than the circle.
        assert!(
            (p.length_m() - expected).abs() < 0.005,
            "{} vs {expected}",
            p.length_m()
        );
        assert!(p.is_closed(1e-9));
        // It starts heading ahead, turns left first and is 2 m across, 1 m wide.
        assert!(p.heading_after(0.0).abs() < 0.1);
        assert!(p.turn_angles()[1] > 0.0);
        let ys = p.points().iter().map(|q| q.y);
        let (low, high) = ys.fold((0.0f64, 0.0f64), |(l, h), y| (l.min(y), h.max(y)));
        assert!(
            (low + 1.0).abs() < 1e-2 && (high - 1.0).abs() < 1e-2,
            "{low} {high}"
        );
    }

    #[test]
    fn titan_gets_a_square_with_corners_it_can_turn_and_the_same_closure() {
        let titan = kin(RobotKind::Titan);
        let radius = corner_radius_m(&titan);
        assert!(radius > 1.7 && radius < 1.8, "{radius}");
        let p = build(Shape::Square, 4.0, 1, &titan).unwrap();
        assert!(p.is_closed(1e-9));
        let expected = 16.0 - 3.0 * 2.0 * radius + 3.0 * PI / 2.0 * radius;
        assert!((p.length_m() - expected).abs() < 0.01);
        // Sampled curvature never exceeds 1 / radius.
        let s = p.arc_lengths();
        for (i, angle) in p.turn_angles().iter().enumerate() {
            if i > 0 && i + 1 < s.len() {
                let k = angle.abs() / (0.5 * (s[i + 1] - s[i - 1]));
                // A chord is a little shorter than its arc: 1 % slack.
                assert!(k <= 1.01 / radius, "vertex {i}: {k}");
            }
        }
    }

    #[test]
    fn a_shape_too_small_for_titan_is_refused_with_the_size_that_works() {
        let titan = kin(RobotKind::Titan);
        let err = build(Shape::Square, 2.0, 1, &titan).unwrap_err();
        let ShapeError::TooSmall { min_size_m, .. } = err else {
            panic!("{err}")
        };
        // The figures of the module's docs.
        assert!((titan.min_turn_radius_m() - 1.56).abs() < 0.005);
        assert!((min_size_m - 3.59).abs() < 0.005, "{min_size_m}");
        assert!(err.to_string().contains("--size 3.59"), "{err}");
        let eight = Shape::FigureEight.min_size_m(corner_radius_m(&titan));
        assert!((eight - 7.17).abs() < 0.005, "{eight}");
        assert!(build(Shape::FigureEight, 6.0, 1, &titan).is_err());
        assert_eq!(Shape::Square.default_size_m(&titan), 4.0);
        assert_eq!(Shape::FigureEight.default_size_m(&titan), 7.5);
        assert_eq!(Shape::Line.default_size_m(&titan), 2.0);
        assert_eq!(
            Shape::Square.default_size_m(&kin(RobotKind::ScoutMini)),
            2.0
        );
        assert!(build(Shape::FigureEight, 7.5, 2, &titan).is_ok());
        assert_eq!(
            build(Shape::Square, -1.0, 1, &titan),
            Err(ShapeError::BadSize(-1.0))
        );
    }
}
