//! A path: a polyline parametrised by arc length, with the queries pure pursuit needs
//! (point and heading at an arc length, windowed projection) and the edits the planner makes
//! (moving it to the start pose, repeating a closed loop, rounding corners to a turning radius).
//!
//! Past its end a path continues straight along its last segment (and before its start along
//! its first), so a lookahead point or a projection just beyond the goal stays well defined.

use thiserror::Error;

use crate::geometry::{Point, Pose, wrap_angle};

/// Points closer than this to their predecessor are dropped, m.
const SAME_POINT_M: f64 = 1e-6;
/// A later pass of the path is taken for the robot's position only when it is nearer than the
/// earliest pass by more than this, m ([`Path::project`]).
pub const PASS_SLACK_M: f64 = 0.1;

/// Why points do not make a path.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PathError {
    #[error("a path needs at least two distinct points (got {distinct})")]
    TooFewPoints { distinct: usize },
    #[error("point {index} is not finite")]
    NotFinite { index: usize },
    #[error(
        "the path turns back on itself at point {index} ({angle_deg:.0}°): a robot that cannot \
         turn on the spot cannot follow it"
    )]
    TurnsBack { index: usize, angle_deg: f64 },
    #[error(
        "the leg from point {from} to point {to} is {length_m:.2} m long, but rounding its corners \
         to a {radius_m:.2} m turning radius needs {needed_m:.2} m"
    )]
    TooTight {
        from: usize,
        to: usize,
        length_m: f64,
        needed_m: f64,
        radius_m: f64,
    },
    #[error("{what} needs a closed path (its end within {tolerance_m} m of its start)")]
    NotClosed {
        what: &'static str,
        tolerance_m: f64,
    },
}

/// The point of a path nearest to a position, within a window of arc lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arc length of the foot point, m (beyond the window's end when the window is open there).
    pub s: f64,
    /// The foot point.
    pub point: Point,
    /// Signed distance from the path, m: positive when the position is left of it.
    pub lateral_m: f64,
}

/// A polyline with its cumulative arc lengths.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    points: Vec<Point>,
    /// `s[i]`: arc length at `points[i]`; `s[0] == 0`.
    s: Vec<f64>,
}

impl Path {
    /// A path through `points`; repeated points are dropped.
    pub fn new(points: Vec<Point>) -> Result<Self, PathError> {
        if let Some(index) = points.iter().position(|p| !p.is_finite()) {
            return Err(PathError::NotFinite { index });
        }
        let mut kept: Vec<Point> = Vec::with_capacity(points.len());
        for p in points {
            if kept
                .last()
                .is_none_or(|last| last.distance(p) > SAME_POINT_M)
            {
                kept.push(p);
            }
        }
        if kept.len() < 2 {
            return Err(PathError::TooFewPoints {
                distinct: kept.len(),
            });
        }
        let mut s = Vec::with_capacity(kept.len());
        let mut total = 0.0;
        s.push(0.0);
        for pair in kept.windows(2) {
            total += pair[0].distance(pair[1]);
            s.push(total);
        }
        Ok(Self { points: kept, s })
    }

    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// Arc length at each point.
    pub fn arc_lengths(&self) -> &[f64] {
        &self.s
    }

    /// Total length, m.
    pub fn length_m(&self) -> f64 {
        self.s.last().copied().unwrap_or(0.0)
    }

    pub fn start(&self) -> Point {
        self.points[0]
    }

    pub fn end(&self) -> Point {
        self.points[self.points.len() - 1]
    }

    /// True when the end is within `tolerance_m` of the start.
    pub fn is_closed(&self, tolerance_m: f64) -> bool {
        self.start().distance(self.end()) <= tolerance_m
    }

    fn segments(&self) -> usize {
        self.points.len() - 1
    }

    /// Index of the segment that holds arc length `s`, preferring the later segment at a vertex.
    fn segment_after(&self, s: f64) -> usize {
        let i = self.s.partition_point(|&x| x <= s);
        i.saturating_sub(1).min(self.segments() - 1)
    }

    /// Index of the segment that holds arc length `s`, preferring the earlier one at a vertex.
    fn segment_before(&self, s: f64) -> usize {
        let i = self.s.partition_point(|&x| x < s);
        i.saturating_sub(1).min(self.segments() - 1)
    }

    fn segment_heading(&self, i: usize) -> f64 {
        self.points[i].bearing(self.points[i + 1])
    }

    /// Heading of the path just after arc length `s`.
    pub fn heading_after(&self, s: f64) -> f64 {
        self.segment_heading(self.segment_after(s))
    }

    /// Heading of the path just before arc length `s`.
    pub fn heading_before(&self, s: f64) -> f64 {
        self.segment_heading(self.segment_before(s))
    }

    /// The point at arc length `s`; before the start and past the end the path continues
    /// straight.
    pub fn point_at(&self, s: f64) -> Point {
        if s <= 0.0 {
            return self.start().toward(self.segment_heading(0), s);
        }
        let length = self.length_m();
        if s >= length {
            let last = self.segments() - 1;
            return self.end().toward(self.segment_heading(last), s - length);
        }
        let i = self.segment_after(s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let span = self.s[i + 1] - self.s[i];
        let t = if span > 0.0 {
            (s - self.s[i]) / span
        } else {
            0.0
        };
        Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t)
    }

    /// The point at arc length `s`, where the path past `stop` is replaced by the straight
    /// continuation of its segment ending at `stop`.
    pub fn point_at_until(&self, s: f64, stop: f64) -> Point {
        if s <= stop {
            self.point_at(s)
        } else {
            self.point_at(stop)
                .toward(self.heading_before(stop), s - stop)
        }
    }

    /// Signed turning angle at each point, rad (left positive; 0 at both ends).
    pub fn turn_angles(&self) -> Vec<f64> {
        let mut angles = vec![0.0; self.points.len()];
        for (i, angle) in angles
            .iter_mut()
            .enumerate()
            .take(self.points.len() - 1)
            .skip(1)
        {
            *angle = wrap_angle(self.segment_heading(i) - self.segment_heading(i - 1));
        }
        angles
    }

    /// The nearest point to `p` with an arc length in `[from, to]`. With `open_end` the segment
    /// holding `to` continues straight past it, so a position beyond `to` projects beyond it.
    ///
    /// Where the path passes `p` more than once in the window (it crosses or touches itself: a
    /// figure-eight's middle is also its end), the earliest pass within [`PASS_SLACK_M`] of the
    /// nearest is taken, so a robot on the first pass is not moved on to the second.
    pub fn project(&self, p: Point, from: f64, to: f64, open_end: bool) -> Projection {
        let to = to.max(from);
        let first = self.segment_after(from.max(0.0));
        let last = self.segment_before(to.min(self.length_m()));
        let last = last.max(first);
        // The nearest point of each segment, in order.
        let mut nearest: Vec<(f64, Projection)> = Vec::with_capacity(last + 1 - first);
        for i in first..=last {
            let (a, b) = (self.points[i], self.points[i + 1]);
            let span = self.s[i + 1] - self.s[i];
            let (ux, uy) = ((b.x - a.x) / span, (b.y - a.y) / span);
            let along = (p.x - a.x) * ux + (p.y - a.y) * uy;
            let low = (from - self.s[i]).max(0.0);
            let high = if i == last && open_end {
                f64::INFINITY
            } else {
                (to - self.s[i]).min(span)
            };
            let t = along.clamp(low.min(high), high);
            let foot = Point::new(a.x + ux * t, a.y + uy * t);
            let distance = p.distance(foot);
            let lateral = ux * (p.y - foot.y) - uy * (p.x - foot.x);
            nearest.push((
                distance,
                Projection {
                    s: self.s[i] + t,
                    point: foot,
                    lateral_m: lateral,
                },
            ));
        }
        let closest = nearest
            .iter()
            .map(|(d, _)| *d)
            .fold(f64::INFINITY, f64::min);
        // A pass is a local minimum of the distance along the path; the closest one is one.
        let pass = |k: usize| {
            let d = nearest[k].0;
            (k == 0 || d <= nearest[k - 1].0 + 1e-12)
                && nearest.get(k + 1).is_none_or(|next| d <= next.0 + 1e-12)
        };
        (0..nearest.len())
            .find(|&k| pass(k) && nearest[k].0 <= closest + PASS_SLACK_M)
            .map_or(
                Projection {
                    s: from,
                    point: self.point_at(from),
                    lateral_m: 0.0,
                },
                |k| nearest[k].1,
            )
    }

    /// The path given in `pose`'s frame, in the outer frame.
    pub fn transformed(&self, pose: Pose) -> Path {
        Path {
            points: self.points.iter().map(|&p| pose.to_world(p)).collect(),
            s: self.s.clone(),
        }
    }

    /// A closed path driven `loops` times in a row.
    pub fn repeated(&self, loops: usize, tolerance_m: f64) -> Result<Path, PathError> {
        if loops <= 1 {
            return Ok(self.clone());
        }
        if !self.is_closed(tolerance_m) {
            return Err(PathError::NotClosed {
                what: "driving it more than once",
                tolerance_m,
            });
        }
        let mut points = self.points.clone();
        for _ in 1..loops {
            points.extend_from_slice(&self.points[1..]);
        }
        Path::new(points)
    }

    /// Replaces every corner by a circular arc of `radius_m` tangent to both legs, sampled every
    /// `step_m`: the path a robot with that turning radius can follow. Fails when a leg is too
    /// short for the arcs at its two ends, or the path turns back on itself.
    pub fn rounded(&self, radius_m: f64, step_m: f64) -> Result<Path, PathError> {
        let angles = self.turn_angles();
        let n = self.points.len();
        let mut tangent = vec![0.0; n];
        for i in 1..n - 1 {
            let angle = angles[i].abs();
            if angle < 1e-9 {
                continue;
            }
            if angle > std::f64::consts::PI - 1e-3 {
                return Err(PathError::TurnsBack {
                    index: i,
                    angle_deg: angle.to_degrees(),
                });
            }
            tangent[i] = radius_m * (angle / 2.0).tan();
        }
        for i in 0..n - 1 {
            let length = self.s[i + 1] - self.s[i];
            let needed = tangent[i] + tangent[i + 1];
            if needed > length + 1e-9 {
                return Err(PathError::TooTight {
                    from: i,
                    to: i + 1,
                    length_m: length,
                    needed_m: needed,
                    radius_m,
                });
            }
        }
        let step = if step_m.is_finite() && step_m > 0.0 {
            step_m
        } else {
            0.05
        };
        let mut out = Vec::with_capacity(n * 4);
        out.push(self.points[0]);
        for i in 1..n - 1 {
            let t = tangent[i];
            if t == 0.0 {
                out.push(self.points[i]);
                continue;
            }
            let h_in = self.segment_heading(i - 1);
            let h_out = self.segment_heading(i);
            let angle = angles[i];
            let t1 = self.points[i].toward(h_in, -t);
            let t2 = self.points[i].toward(h_out, t);
            // The centre lies on the side the path turns to.
            let side = angle.signum() * std::f64::consts::FRAC_PI_2;
            let centre = t1.toward(h_in + side, radius_m);
            let start = centre.bearing(t1);
            // At least a few samples; the float is small, positive and finite.
            let steps = ((radius_m * angle.abs() / step).ceil()).max(2.0) as usize;
            out.push(t1);
            for k in 1..steps {
                let phi = start + angle * k as f64 / steps as f64;
                out.push(centre.toward(phi, radius_m));
            }
            out.push(t2);
        }
        out.push(self.points[n - 1]);
        Path::new(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn square(size: f64) -> Path {
        Path::new(vec![
            Point::new(0.0, 0.0),
            Point::new(size, 0.0),
            Point::new(size, size),
            Point::new(0.0, size),
            Point::new(0.0, 0.0),
        ])
        .unwrap()
    }

    #[test]
    fn repeated_points_are_dropped_and_one_point_is_not_a_path() {
        let p = Path::new(vec![
            Point::new(0.0, 0.0),
            Point::new(0.0, 0.0),
            Point::new(1.0, 0.0),
        ])
        .unwrap();
        assert_eq!(p.points().len(), 2);
        assert_eq!(
            Path::new(vec![Point::new(1.0, 1.0), Point::new(1.0, 1.0)]),
            Err(PathError::TooFewPoints { distinct: 1 })
        );
        assert_eq!(
            Path::new(vec![Point::new(0.0, 0.0), Point::new(f64::NAN, 1.0)]),
            Err(PathError::NotFinite { index: 1 })
        );
    }

    #[test]
    fn points_and_headings_follow_the_arc_length_and_continue_past_the_ends() {
        let p = square(2.0);
        assert!((p.length_m() - 8.0).abs() < 1e-12);
        assert!(p.point_at(3.0).distance(Point::new(2.0, 1.0)) < 1e-12);
        assert!(p.point_at(9.0).distance(Point::new(0.0, -1.0)) < 1e-12);
        assert!(p.point_at(-1.0).distance(Point::new(-1.0, 0.0)) < 1e-12);
        assert!((p.heading_before(2.0) - 0.0).abs() < 1e-12);
        assert!((p.heading_after(2.0) - FRAC_PI_2).abs() < 1e-12);
        // Past a stop at the first corner the path goes straight on.
        assert!(p.point_at_until(2.5, 2.0).distance(Point::new(2.5, 0.0)) < 1e-12);
    }

    #[test]
    fn projection_stays_in_its_window_and_does_not_jump_to_where_a_closed_path_ends() {
        let p = square(2.0);
        // Near the start, which is also the end: the window keeps it at the start.
        let near_start = p.project(Point::new(0.1, 0.05), 0.0, 1.0, false);
        assert!((near_start.s - 0.1).abs() < 1e-12);
        assert!((near_start.lateral_m - 0.05).abs() < 1e-12);
        // Right of the path is negative.
        let right = p.project(Point::new(1.0, -0.2), 0.0, 3.0, false);
        assert!((right.lateral_m + 0.2).abs() < 1e-12);
        // Beyond an open window end, the projection goes past it along the last segment.
        let past = p.project(Point::new(2.3, 0.0), 0.0, 2.0, true);
        assert!((past.s - 2.3).abs() < 1e-12);
        let closed = p.project(Point::new(2.3, 0.0), 0.0, 2.0, false);
        assert!((closed.s - 2.0).abs() < 1e-12);
    }

    #[test]
    fn where_the_path_passes_twice_the_earlier_pass_is_kept_unless_far_worse() {
        // Out along x and back along it `gap_m` to the left: two passes of every point.
        let there_and_back = |gap_m: f64| {
            Path::new(vec![
                Point::new(0.0, 0.0),
                Point::new(1.0, 0.0),
                Point::new(1.0, gap_m),
                Point::new(0.0, gap_m),
            ])
            .unwrap()
        };
        let p = there_and_back(0.02);
        // On the way out, 1.5 cm left of it: the way back is nearer, the way out is kept.
        let out = p.project(Point::new(0.5, 0.015), 0.0, p.length_m(), false);
        assert!((out.s - 0.5).abs() < 1e-12, "{out:?}");
        assert!((out.lateral_m - 0.015).abs() < 1e-12);
        // Far nearer the second pass than the first: the second.
        let p = there_and_back(0.5);
        let back = p.project(Point::new(0.5, 0.45), 0.0, p.length_m(), false);
        assert!((back.s - 2.0).abs() < 1e-12, "{back:?}");
        // Along one pass the nearest point is kept, not an earlier vertex within the slack.
        let line = Path::new(
            (0..=20)
                .map(|i| Point::new(f64::from(i) * 0.05, 0.0))
                .collect(),
        )
        .unwrap();
        let on = line.project(Point::new(0.52, 0.03), 0.0, 1.0, false);
        assert!((on.s - 0.52).abs() < 1e-12, "{on:?}");
    }

    #[test]
    fn transforming_by_the_start_pose_moves_and_turns_the_path() {
        let p = square(1.0).transformed(Pose::new(5.0, 1.0, FRAC_PI_2));
        assert!(p.start().distance(Point::new(5.0, 1.0)) < 1e-12);
        assert!(p.points()[1].distance(Point::new(5.0, 2.0)) < 1e-12);
        assert!((p.length_m() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn rounded_corners_are_arcs_of_the_radius_tangent_to_both_legs() {
        let p = square(4.0).rounded(1.5, 0.05).unwrap();
        assert!(p.is_closed(1e-9));
        // Three quarter circles replace three corners of 2 × 1.5 m of legs each.
        let expected = 16.0 - 3.0 * 3.0 + 3.0 * FRAC_PI_2 * 1.5;
        assert!(
            (p.length_m() - expected).abs() < 0.01,
            "{} vs {expected}",
            p.length_m()
        );
        // Every point of the first arc is 1.5 m from its centre (2.5, 1.5).
        let centre = Point::new(2.5, 1.5);
        for q in p.points().iter().filter(|q| q.x > 2.5 && q.y < 1.5) {
            assert!((q.distance(centre) - 1.5).abs() < 1e-9, "{q:?}");
        }
        // Turning per sample never exceeds what the radius allows.
        let s = p.arc_lengths();
        for (i, angle) in p.turn_angles().iter().enumerate().skip(1) {
            if i + 1 < s.len() {
                let span = 0.5 * (s[i + 1] - s[i - 1]);
                // A chord is a little shorter than its arc: 1 % slack.
                assert!(angle.abs() / span <= 1.01 / 1.5, "vertex {i}");
            }
        }
    }

    #[test]
    fn a_corner_too_tight_for_the_radius_is_refused_and_so_is_a_reversal() {
        let err = square(2.0).rounded(1.5, 0.05).unwrap_err();
        assert!(
            matches!(err, PathError::TooTight { from: 1, to: 2, .. }),
            "{err}"
        );
        let back = Path::new(vec![
            Point::new(0.0, 0.0),
            Point::new(1.0, 0.0),
            Point::new(0.0, 0.0),
        ])
        .unwrap();
        assert!(matches!(
            back.rounded(1.0, 0.05),
            Err(PathError::TurnsBack { index: 1, .. })
        ));
    }

    #[test]
    fn a_closed_path_repeats_and_an_open_one_refuses_to() {
        let twice = square(1.0).repeated(2, 0.01).unwrap();
        assert!((twice.length_m() - 8.0).abs() < 1e-12);
        assert_eq!(twice.points().len(), 9);
        let line = Path::new(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]).unwrap();
        assert!(matches!(
            line.repeated(2, 0.01),
            Err(PathError::NotClosed { .. })
        ));
        assert_eq!(line.turn_angles(), vec![0.0, 0.0]);
        assert!((square(1.0).turn_angles()[1] - FRAC_PI_2).abs() < 1e-12);
    }
}
