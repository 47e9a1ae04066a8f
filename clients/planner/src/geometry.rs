//! Points, poses and angles in the plane (metres, radians, left turn positive).

pub use chassis_client::wrap_angle;

/// A point in the plane, m.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    pub x: f64,
    pub y: f64,
}

impl Point {
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    pub fn distance(self, other: Point) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }

    /// The point `distance` along `heading` from here.
    pub fn toward(self, heading: f64, distance: f64) -> Point {
        let (sin, cos) = heading.sin_cos();
        Point::new(self.x + distance * cos, self.y + distance * sin)
    }

    /// Direction from here to `other`, rad.
    pub fn bearing(self, other: Point) -> f64 {
        (other.y - self.y).atan2(other.x - self.x)
    }
}

/// A position and heading, m and rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
}

impl Pose {
    pub const fn new(x: f64, y: f64, yaw: f64) -> Self {
        Self { x, y, yaw }
    }

    pub fn position(self) -> Point {
        Point::new(self.x, self.y)
    }

    /// A point given in this pose's frame (x ahead, y left), in the outer frame.
    pub fn to_world(self, p: Point) -> Point {
        let (sin, cos) = self.yaw.sin_cos();
        Point::new(
            self.x + p.x * cos - p.y * sin,
            self.y + p.x * sin + p.y * cos,
        )
    }

    /// A point of the outer frame in this pose's frame (x ahead, y left).
    pub fn to_local(self, p: Point) -> Point {
        let (sin, cos) = self.yaw.sin_cos();
        let (dx, dy) = (p.x - self.x, p.y - self.y);
        Point::new(dx * cos + dy * sin, -dx * sin + dy * cos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn to_world_and_to_local_are_inverse() {
        let pose = Pose::new(1.0, -2.0, 0.7);
        let p = Point::new(0.3, 1.9);
        let back = pose.to_local(pose.to_world(p));
        assert!(back.distance(p) < 1e-12);
        // Ahead of a robot facing +y is +y.
        let ahead = Pose::new(0.0, 0.0, std::f64::consts::FRAC_PI_2).to_world(Point::new(1.0, 0.0));
        assert!(ahead.distance(Point::new(0.0, 1.0)) < 1e-12);
    }
}
