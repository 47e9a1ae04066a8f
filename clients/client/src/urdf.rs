//! The robot as a URDF, from its [`RobotDescription`] alone: one generator for every robot the
//! registry knows (and any robot chassisd describes), for RViz's RobotModel display,
//! `robot_state_publisher` and anything else that reads `robot_description`.
//!
//! What it holds, all in `base_link` (REP-103 axes: x forward, y left, z up):
//!
//! * `base_link`, the root, with the body: a box of the described size, standing on the ground;
//!   `base_footprint` (REP-105) under it, on the ground, by a fixed joint. `base_link` is the
//!   root, not `base_footprint`: the bridges publish `odom → base_link`, and a frame has one
//!   parent. `base_link` sits at the wheels' axle height where the wheel radius is described,
//!   on the ground otherwise;
//! * a link per wheel joint the description lists (continuous, about y), at ±wheelbase/2 and
//!   ±track/2, a cylinder of the wheel radius; front-left, front-right, rear-left, rear-right as
//!   `MotionState::wheel_mps` orders them;
//! * a link per steering joint (revolute about z, ±the robot's largest steering angle), the
//!   steered axle at +wheelbase/2 (front) or −wheelbase/2 (rear), drawn as a bar across the
//!   track;
//! * for a tracked robot, its two tracks (fixed links: a track turns with no joint to publish);
//! * a link per sensor at its mounting (fixed joint), `<name>_link` as the bridges name its frame.
//!
//! The moving joints are named exactly as the description names them, which is what the
//! bridges' `joint_states` carries; the fixed joints `base_footprint_joint`, `<sensor>_joint`,
//! `left_track_joint` and `right_track_joint`. Links (TF frames) take the optional `prefix`
//! (the bridge's `--frame-prefix`, `robot1/`); joints do not, as `joint_states` names them
//! without it (several robots are told apart by their topics' namespace).
//!
//! What the description leaves unknown (NaN) is not invented: a body of unknown size is not
//! drawn, wheels of unknown radius are not drawn; where a wheel's or a track's position is not
//! described it is placed by the body's outline, as the comments in the file say.
//!
//! ```
//! use chassis_client::{JointSource, RobotDescription};
//!
//! let mut d = RobotDescription::default();
//! d.set_name("r1");
//! d.geometry.track_m = 0.5;
//! d.geometry.wheel_radius_m = 0.1;
//! d.push_joint("front_left_wheel_joint", JointSource::WHEEL, 0).unwrap();
//! let urdf = chassis_client::urdf::urdf(&d, "r1/").unwrap();
//! assert!(urdf.contains(r#"<joint name="front_left_wheel_joint" type="continuous">"#));
//! assert!(urdf.contains(r#"<link name="r1/front_left_wheel_link">"#));
//! ```

use std::collections::BTreeSet;
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write as _;

use chassis_interfaces::{JointSource, Kinematics, RobotDescription, SensorKind};

/// The body's frame, the URDF's root.
pub const BASE_LINK: &str = "base_link";
/// The frame on the ground under `base_link` (REP-105).
pub const BASE_FOOTPRINT: &str = "base_footprint";

/// Why a description cannot be written as a URDF.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UrdfError {
    /// A name is empty or holds a character XML cannot carry.
    #[error("{what} name {name:?} cannot be a URDF name: {why}")]
    BadName {
        what: &'static str,
        name: String,
        why: &'static str,
    },
    /// Two links or two joints would have the same name.
    #[error("two {what}s would be named {name:?}")]
    Duplicate { what: &'static str, name: String },
}

/// A fixed joint of the URDF as a static transform: `child` in `parent`, translated by `xyz`, m,
/// then turned by `rpy` (roll, pitch, yaw about the fixed x, y, z axes), rad. What the bridges
/// publish on `/tf_static`.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedFrame {
    pub parent: String,
    pub child: String,
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
}

/// The URDF of `description`, its links' names under `prefix` (`""` or `robot1/`).
pub fn urdf(description: &RobotDescription, prefix: &str) -> Result<String, UrdfError> {
    Ok(Model::of(description, prefix)?.to_xml())
}

/// The URDF's fixed joints, parent to child, in its order: `base_link → base_footprint`, each
/// sensor, the tracks.
pub fn fixed_frames(
    description: &RobotDescription,
    prefix: &str,
) -> Result<Vec<FixedFrame>, UrdfError> {
    let model = Model::of(description, prefix)?;
    Ok(model
        .joints
        .into_iter()
        .filter(|j| j.kind == JointKind::Fixed)
        .map(|j| FixedFrame {
            parent: j.parent,
            child: j.child,
            xyz: j.origin.xyz,
            rpy: j.origin.rpy,
        })
        .collect())
}

/// The link a described joint moves: `front_steer_joint` → `front_steer_link`.
pub fn link_of_joint(prefix: &str, joint: &str) -> String {
    let stem = joint.strip_suffix("_joint").unwrap_or(joint);
    format!("{prefix}{stem}_link")
}

/// A sensor's link (its frame, as the bridges name it): `imu` → `imu_link`.
pub fn link_of_sensor(prefix: &str, sensor: &str) -> String {
    format!("{prefix}{sensor}_link")
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Origin {
    xyz: [f64; 3],
    rpy: [f64; 3],
}

impl Origin {
    fn at(x: f64, y: f64, z: f64) -> Self {
        Self {
            xyz: [x, y, z],
            rpy: [0.0; 3],
        }
    }

    fn turned(mut self, roll: f64, yaw: f64) -> Self {
        self.rpy = [roll, 0.0, yaw];
        self
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Shape {
    Box([f64; 3]),
    Cylinder { radius: f64, length: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Visual {
    origin: Origin,
    shape: Shape,
    material: &'static str,
    /// Also a collision element (the body and the wheels).
    collides: bool,
}

#[derive(Debug, Clone, PartialEq)]
struct Link {
    name: String,
    visual: Option<Visual>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum JointKind {
    Fixed,
    Continuous,
    Revolute { lower: f64, upper: f64 },
}

#[derive(Debug, Clone, PartialEq)]
struct Joint {
    name: String,
    kind: JointKind,
    parent: String,
    child: String,
    origin: Origin,
    axis: [f64; 3],
    /// Why it sits where it does, where the description does not say.
    notes: Vec<&'static str>,
}

/// The materials, by name and colour.
const MATERIALS: &[(&str, &str)] = &[
    ("chassis_body", "0.55 0.57 0.6 1"),
    ("chassis_wheel", "0.1 0.1 0.1 1"),
    ("chassis_steer", "0.9 0.55 0.1 1"),
    ("chassis_sensor", "0.15 0.4 0.85 1"),
];

/// A length the description gives: finite and positive.
fn given(v: f64) -> Option<f64> {
    (v.is_finite() && v > 0.0).then_some(v)
}

/// A coordinate, 0 where the description gives none.
fn coordinate(v: f64) -> f64 {
    if v.is_finite() { v } else { 0.0 }
}

/// The robot as links and joints.
#[derive(Debug, Clone, PartialEq)]
struct Model {
    name: String,
    links: Vec<Link>,
    joints: Vec<Joint>,
}

impl Model {
    fn of(d: &RobotDescription, prefix: &str) -> Result<Self, UrdfError> {
        let g = &d.geometry;
        let radius = given(g.wheel_radius_m);
        let (length, width, height) = (given(g.length_m), given(g.width_m), given(g.height_m));
        // base_link at the axles' height where the wheels are described, else on the ground.
        let base_z = radius.unwrap_or(0.0);
        let base = format!("{prefix}{BASE_LINK}");
        let name = [d.name(), d.kind_name()]
            .into_iter()
            .find(|n| !n.is_empty())
            .unwrap_or("robot")
            .to_string();
        let mut m = Model {
            name,
            links: Vec::new(),
            joints: Vec::new(),
        };
        let body = match (length, width, height) {
            (Some(l), Some(w), Some(h)) => Some(Visual {
                origin: Origin::at(0.0, 0.0, h / 2.0 - base_z),
                shape: Shape::Box([l, w, h]),
                material: "chassis_body",
                collides: true,
            }),
            _ => None,
        };
        m.links.push(Link {
            name: base.clone(),
            visual: body,
        });
        m.fixed(
            &base,
            "base_footprint_joint",
            format!("{prefix}{BASE_FOOTPRINT}"),
            Origin::at(0.0, 0.0, -base_z),
            None,
        );

        // Wheels: where the wheels are, and how wide one is.
        let wheel_width = radius.map_or(0.05, |r| (r * 0.5).clamp(0.02, 0.15));
        let wheels: Vec<_> = d
            .joints()
            .iter()
            .filter(|j| j.source == JointSource::WHEEL)
            .collect();
        let has_rear = wheels.iter().any(|j| j.index >= 2);
        let (wheel_x, x_note) = match (given(g.wheelbase_m), has_rear, length, radius) {
            (Some(wb), _, _, _) => (wb / 2.0, None),
            (None, false, _, _) => (0.0, Some("wheelbase not described: on the centre line")),
            (None, true, Some(l), Some(r)) if l / 2.0 > r => (
                l / 2.0 - r,
                Some("wheelbase not described: a radius inside the body's ends"),
            ),
            (None, true, _, _) => (0.0, Some("wheelbase not described")),
        };
        let (wheel_y, y_note) = match (given(g.track_m), width) {
            (Some(t), _) => (t / 2.0, None),
            (None, Some(w)) => (
                (w / 2.0 - wheel_width / 2.0).max(wheel_width),
                Some("track not described: at the body's sides"),
            ),
            (None, None) => (
                wheel_width,
                Some("track not described, nor the body's width"),
            ),
        };
        for j in wheels {
            let (sx, sy) = match j.index {
                0 => (1.0, 1.0),
                1 => (1.0, -1.0),
                2 => (-1.0, 1.0),
                _ => (-1.0, -1.0),
            };
            let link = link_of_joint(prefix, j.name());
            m.links.push(Link {
                name: link.clone(),
                visual: radius.map(|r| Visual {
                    origin: Origin::at(0.0, 0.0, 0.0).turned(FRAC_PI_2, 0.0),
                    shape: Shape::Cylinder {
                        radius: r,
                        length: wheel_width,
                    },
                    material: "chassis_wheel",
                    collides: true,
                }),
            });
            m.joints.push(Joint {
                name: j.name().to_string(),
                kind: JointKind::Continuous,
                parent: base.clone(),
                child: link,
                origin: Origin::at(sx * wheel_x, sy * wheel_y, 0.0),
                axis: [0.0, 1.0, 0.0],
                notes: [x_note, y_note].into_iter().flatten().collect(),
            });
        }

        // Steering: the steered axle turns about z; the limits are the robot's.
        let steer = given(d.robot_limits.steer_rad);
        let axle = given(g.track_m).or(width.map(|w| w * 0.8)).unwrap_or(0.3);
        let half_wheelbase = given(g.wheelbase_m)
            .map(|wb| wb / 2.0)
            .or(length.map(|l| l / 4.0));
        for j in d.joints() {
            let x = match j.source {
                JointSource::FRONT_STEER => half_wheelbase.unwrap_or(0.0),
                JointSource::REAR_STEER => -half_wheelbase.unwrap_or(0.0),
                _ => continue,
            };
            let link = link_of_joint(prefix, j.name());
            m.links.push(Link {
                name: link.clone(),
                visual: Some(Visual {
                    origin: Origin::at(0.0, 0.0, 0.0),
                    shape: Shape::Box([0.04, axle, 0.04]),
                    material: "chassis_steer",
                    collides: false,
                }),
            });
            let limit = steer.unwrap_or(FRAC_PI_2).min(PI);
            m.joints.push(Joint {
                name: j.name().to_string(),
                kind: JointKind::Revolute {
                    lower: -limit,
                    upper: limit,
                },
                parent: base.clone(),
                child: link,
                origin: Origin::at(x, 0.0, 0.0),
                axis: [0.0, 0.0, 1.0],
                notes: [
                    match (given(g.wheelbase_m), length) {
                        (Some(_), _) => None,
                        (None, Some(_)) => {
                            Some("wheelbase not described: a quarter of the body's length out")
                        }
                        (None, None) => Some("wheelbase not described: at the centre"),
                    },
                    steer
                        .is_none()
                        .then_some("largest steering angle not described: ±90°"),
                ]
                .into_iter()
                .flatten()
                .collect(),
            });
        }

        // Tracks: two bands along the sides, as long as the wheelbase, as tall as the wheels.
        if d.kinematics == Kinematics::TRACKED {
            let band = match (width, given(g.track_m)) {
                (Some(w), Some(t)) if w > t => (w - t).clamp(0.05, 0.3),
                _ => 0.1,
            };
            let long = given(g.wheelbase_m)
                .or(length.map(|l| l * 0.9))
                .unwrap_or(0.5);
            let tall = radius
                .map(|r| 2.0 * r)
                .or(height.map(|h| h * 0.4))
                .unwrap_or(0.1);
            let y = given(g.track_m)
                .map(|t| t / 2.0)
                .or(width.map(|w| (w - band) / 2.0))
                .unwrap_or(band);
            for (side, sy) in [("left", 1.0), ("right", -1.0)] {
                let link = format!("{prefix}{side}_track_link");
                m.links.push(Link {
                    name: link.clone(),
                    visual: Some(Visual {
                        origin: Origin::at(0.0, 0.0, 0.0),
                        shape: Shape::Box([long, band, tall]),
                        material: "chassis_wheel",
                        collides: true,
                    }),
                });
                m.fixed(
                    &base,
                    &format!("{side}_track_joint"),
                    link,
                    Origin::at(0.0, sy * y, tall / 2.0 - base_z),
                    Some("a track: its height the wheels' diameter, or 40 % of the body's"),
                );
            }
        }

        // Sensors at their mountings.
        for s in d.sensors() {
            let link = link_of_sensor(prefix, s.name());
            let shape = match s.kind {
                SensorKind::GPS => Shape::Cylinder {
                    radius: 0.04,
                    length: 0.02,
                },
                SensorKind::ULTRASONIC | SensorKind::INFRARED => Shape::Box([0.02, 0.04, 0.02]),
                _ => Shape::Box([0.03, 0.03, 0.02]),
            };
            m.links.push(Link {
                name: link.clone(),
                visual: Some(Visual {
                    origin: Origin::at(0.0, 0.0, 0.0),
                    shape,
                    material: "chassis_sensor",
                    collides: false,
                }),
            });
            m.fixed(
                &base,
                &format!("{}_joint", s.name()),
                link,
                Origin::at(coordinate(s.x_m), coordinate(s.y_m), coordinate(s.z_m))
                    .turned(0.0, coordinate(s.yaw_rad)),
                None,
            );
        }
        m.check()?;
        Ok(m)
    }

    /// A fixed joint from `parent` to `child` (its link pushed bare unless it is there).
    fn fixed(
        &mut self,
        parent: &str,
        name: &str,
        child: String,
        origin: Origin,
        note: Option<&'static str>,
    ) {
        if !self.links.iter().any(|l| l.name == child) {
            self.links.push(Link {
                name: child.clone(),
                visual: None,
            });
        }
        self.joints.push(Joint {
            name: name.to_string(),
            kind: JointKind::Fixed,
            parent: parent.to_string(),
            child,
            origin,
            axis: [0.0; 3],
            notes: note.into_iter().collect(),
        });
    }

    /// Every name is non-empty, writable in XML and unique among its links or joints.
    fn check(&self) -> Result<(), UrdfError> {
        check_name("robot", &self.name)?;
        let links = self.links.iter().map(|l| ("link", &l.name));
        let joints = self.joints.iter().map(|j| ("joint", &j.name));
        let mut seen = BTreeSet::new();
        for (what, name) in links.chain(joints) {
            check_name(what, name)?;
            if !seen.insert((what, name.as_str())) {
                return Err(UrdfError::Duplicate {
                    what,
                    name: name.clone(),
                });
            }
        }
        Ok(())
    }

    fn to_xml(&self) -> String {
        let mut x = String::new();
        x.push_str("<?xml version=\"1.0\"?>\n");
        x.push_str(
            "<!-- Generated by chassis from the robot's description (RobotDescription): \
             lengths in metres, angles in radians, REP-103 axes. -->\n",
        );
        let _ = writeln!(x, "<robot name=\"{}\">", escape(&self.name));
        for (name, rgba) in MATERIALS {
            let _ = writeln!(
                x,
                "  <material name=\"{name}\"><color rgba=\"{rgba}\"/></material>"
            );
        }
        for link in &self.links {
            let name = escape(&link.name);
            let Some(v) = link.visual else {
                let _ = writeln!(x, "  <link name=\"{name}\"/>");
                continue;
            };
            let _ = writeln!(x, "  <link name=\"{name}\">");
            let geometry = match v.shape {
                Shape::Box([a, b, c]) => {
                    format!("<box size=\"{} {} {}\"/>", num(a), num(b), num(c))
                }
                Shape::Cylinder { radius, length } => format!(
                    "<cylinder radius=\"{}\" length=\"{}\"/>",
                    num(radius),
                    num(length)
                ),
            };
            let origin = origin_xml(&v.origin);
            let _ = writeln!(
                x,
                "    <visual>\n      {origin}\n      <geometry>{geometry}</geometry>\n      \
                 <material name=\"{}\"/>\n    </visual>",
                v.material
            );
            if v.collides {
                let _ = writeln!(
                    x,
                    "    <collision>\n      {origin}\n      <geometry>{geometry}</geometry>\n    \
                     </collision>"
                );
            }
            x.push_str("  </link>\n");
        }
        for j in &self.joints {
            let kind = match j.kind {
                JointKind::Fixed => "fixed",
                JointKind::Continuous => "continuous",
                JointKind::Revolute { .. } => "revolute",
            };
            for note in &j.notes {
                let _ = writeln!(x, "  <!-- {note} -->");
            }
            let _ = writeln!(
                x,
                "  <joint name=\"{}\" type=\"{kind}\">\n    <parent link=\"{}\"/>\n    \
                 <child link=\"{}\"/>\n    {}",
                escape(&j.name),
                escape(&j.parent),
                escape(&j.child),
                origin_xml(&j.origin)
            );
            if j.kind != JointKind::Fixed {
                let [a, b, c] = j.axis;
                let _ = writeln!(x, "    <axis xyz=\"{} {} {}\"/>", num(a), num(b), num(c));
            }
            if let JointKind::Revolute { lower, upper } = j.kind {
                let _ = writeln!(
                    x,
                    "    <limit lower=\"{}\" upper=\"{}\" effort=\"0\" velocity=\"0\"/>",
                    num(lower),
                    num(upper)
                );
            }
            x.push_str("  </joint>\n");
        }
        x.push_str("</robot>\n");
        x
    }
}

fn origin_xml(o: &Origin) -> String {
    let [x, y, z] = o.xyz;
    let [r, p, w] = o.rpy;
    format!(
        "<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>",
        num(x),
        num(y),
        num(z),
        num(r),
        num(p),
        num(w)
    )
}

/// A number as XML carries it: rounded to the nanometre (nanoradian), trailing zeros dropped,
/// never an exponent; 0 for NaN or an infinity (never written: the model replaces them first),
/// no `-0`.
fn num(v: f64) -> String {
    if !v.is_finite() {
        return "0".into();
    }
    let text = format!("{v:.9}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    match text {
        "-0" | "" => "0".into(),
        t => t.to_string(),
    }
}

/// Non-empty, with no character XML 1.0 cannot carry (controls other than tab, newline and
/// carriage return; U+FFFE, U+FFFF).
fn check_name(what: &'static str, name: &str) -> Result<(), UrdfError> {
    let bad = |why| UrdfError::BadName {
        what,
        name: name.to_string(),
        why,
    };
    if name.is_empty() {
        return Err(bad("empty"));
    }
    if name.chars().any(|c| {
        (c.is_control() && !matches!(c, '\t' | '\n' | '\r')) || matches!(c, '\u{FFFE}' | '\u{FFFF}')
    }) {
        return Err(bad("a control character"));
    }
    Ok(())
}

/// `text` as an XML attribute value between double quotes.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Whitespace other than a space is normalised away in an attribute: keep it.
            '\t' => out.push_str("&#9;"),
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_interfaces::SensorDescription;

    /// A TITAN-like description: dual Ackermann, two steering joints, no wheel radius.
    fn steered() -> RobotDescription {
        let mut d = RobotDescription {
            kind: 1,
            kinematics: Kinematics::DUAL_ACKERMANN,
            ..RobotDescription::default()
        };
        d.set_name("titan");
        d.geometry.wheelbase_m = 1.0;
        d.geometry.track_m = 0.8;
        d.geometry.length_m = 1.4;
        d.geometry.width_m = 1.0;
        d.geometry.height_m = 0.6;
        d.robot_limits.steer_rad = 0.5;
        d.push_joint("front_steer_joint", JointSource::FRONT_STEER, 0)
            .unwrap();
        d.push_joint("rear_steer_joint", JointSource::REAR_STEER, 0)
            .unwrap();
        d
    }

    /// An XBot-like description: four described wheels with a radius, sensors.
    fn wheeled() -> RobotDescription {
        let mut d = RobotDescription {
            kind: 3,
            kinematics: Kinematics::OMNI,
            ..RobotDescription::default()
        };
        d.set_name("xbot");
        d.geometry.wheelbase_m = 0.3;
        d.geometry.track_m = 0.4;
        d.geometry.wheel_radius_m = 0.05;
        d.geometry.length_m = 0.47;
        d.geometry.width_m = 0.494;
        d.geometry.height_m = 0.21;
        for (i, n) in [
            "front_left_wheel_joint",
            "front_right_wheel_joint",
            "rear_left_wheel_joint",
            "rear_right_wheel_joint",
        ]
        .into_iter()
        .enumerate()
        {
            d.push_joint(n, JointSource::WHEEL, i as u8).unwrap();
        }
        d.push_sensor(
            "ultrasonic_front_left",
            SensorDescription {
                kind: SensorKind::ULTRASONIC,
                x_m: 0.235,
                y_m: 0.197,
                z_m: 0.15,
                yaw_rad: 0.5,
                ..SensorDescription::default()
            },
        )
        .unwrap();
        d.push_sensor(
            "imu",
            SensorDescription {
                kind: SensorKind::IMU,
                ..SensorDescription::default()
            },
        )
        .unwrap();
        d
    }

    /// The `<joint name=…>` element of `urdf`, up to its end.
    fn joint<'a>(urdf: &'a str, name: &str) -> &'a str {
        let start = urdf
            .find(&format!("<joint name=\"{name}\""))
            .unwrap_or_else(|| panic!("no joint {name} in\n{urdf}"));
        let end = urdf[start..].find("</joint>").unwrap() + start;
        &urdf[start..end]
    }

    #[test]
    fn steering_joints_are_revolute_at_the_axles_with_the_robots_limits() {
        let u = urdf(&steered(), "").unwrap();
        let front = joint(&u, "front_steer_joint");
        assert!(front.contains("type=\"revolute\""), "{front}");
        assert!(front.contains("<child link=\"front_steer_link\"/>"));
        assert!(front.contains("<origin xyz=\"0.5 0 0\""), "{front}");
        assert!(front.contains("<axis xyz=\"0 0 1\"/>"));
        assert!(front.contains("lower=\"-0.5\" upper=\"0.5\""), "{front}");
        let rear = joint(&u, "rear_steer_joint");
        assert!(rear.contains("<origin xyz=\"-0.5 0 0\""), "{rear}");
        // No wheel radius: no wheel is drawn, base_link stands on the ground, the body on it.
        assert!(!u.contains("cylinder"), "{u}");
        assert!(u.contains("<box size=\"1.4 1 0.6\"/>"), "{u}");
        assert!(u.contains("<origin xyz=\"0 0 0.3\" rpy=\"0 0 0\"/>"), "{u}");
        assert!(
            joint(&u, "base_footprint_joint").contains("<child link=\"base_footprint\"/>"),
            "{u}"
        );
    }

    #[test]
    fn wheels_are_continuous_at_the_corners_with_the_radius() {
        let u = urdf(&wheeled(), "").unwrap();
        for (name, x, y) in [
            ("front_left_wheel_joint", "0.15", "0.2"),
            ("front_right_wheel_joint", "0.15", "-0.2"),
            ("rear_left_wheel_joint", "-0.15", "0.2"),
            ("rear_right_wheel_joint", "-0.15", "-0.2"),
        ] {
            let j = joint(&u, name);
            assert!(j.contains("type=\"continuous\""), "{j}");
            assert!(j.contains(&format!("<origin xyz=\"{x} {y} 0\"")), "{j}");
            assert!(j.contains("<axis xyz=\"0 1 0\"/>"), "{j}");
        }
        assert_eq!(u.matches("<cylinder radius=\"0.05\"").count(), 8, "{u}");
        // base_link at the axles: the footprint a radius below, the body standing on the ground.
        assert!(joint(&u, "base_footprint_joint").contains("<origin xyz=\"0 0 -0.05\""));
        assert!(
            u.contains("<origin xyz=\"0 0 0.055\" rpy=\"0 0 0\"/>"),
            "{u}"
        );
    }

    #[test]
    fn sensors_are_fixed_links_at_their_mountings_and_static_frames() {
        let d = wheeled();
        let u = urdf(&d, "r1/").unwrap();
        let j = joint(&u, "ultrasonic_front_left_joint");
        assert!(j.contains("type=\"fixed\""));
        assert!(j.contains("<parent link=\"r1/base_link\"/>"));
        assert!(j.contains("<child link=\"r1/ultrasonic_front_left_link\"/>"));
        assert!(
            j.contains("<origin xyz=\"0.235 0.197 0.15\" rpy=\"0 0 0.5\"/>"),
            "{j}"
        );
        let frames = fixed_frames(&d, "r1/").unwrap();
        let children: Vec<&str> = frames.iter().map(|f| f.child.as_str()).collect();
        assert_eq!(
            children,
            [
                "r1/base_footprint",
                "r1/ultrasonic_front_left_link",
                "r1/imu_link"
            ]
        );
        assert!(frames.iter().all(|f| f.parent == "r1/base_link"));
        assert_eq!(frames[1].xyz, [0.235, 0.197, 0.15]);
        assert_eq!(frames[1].rpy, [0.0, 0.0, 0.5]);
    }

    #[test]
    fn links_take_the_prefix_and_joints_keep_the_described_names() {
        let u = urdf(&steered(), "robot1/").unwrap();
        assert!(u.contains("<link name=\"robot1/base_link\">"));
        assert!(u.contains("<link name=\"robot1/base_footprint\"/>"));
        assert!(u.contains("<joint name=\"front_steer_joint\" type=\"revolute\">"));
        assert!(!u.contains("<joint name=\"robot1/"));
        // Every link is named once and every joint's links exist.
        let links: Vec<&str> = u
            .match_indices("<link name=\"")
            .map(|(i, _)| {
                let rest = &u[i + 12..];
                &rest[..rest.find('"').unwrap()]
            })
            .collect();
        assert_eq!(links.len(), BTreeSet::from_iter(&links).len());
        for (i, _) in u.match_indices(" link=\"") {
            let rest = &u[i + 7..];
            let name = &rest[..rest.find('"').unwrap()];
            assert!(links.contains(&name), "{name} is no link");
        }
    }

    #[test]
    fn a_tracked_robot_gets_two_tracks() {
        let mut d = RobotDescription {
            kinematics: Kinematics::TRACKED,
            ..RobotDescription::default()
        };
        d.set_name("bunker");
        d.geometry.wheelbase_m = 0.5;
        d.geometry.track_m = 0.5;
        d.geometry.length_m = 0.7;
        d.geometry.width_m = 0.65;
        d.geometry.height_m = 0.3;
        let u = urdf(&d, "").unwrap();
        let left = joint(&u, "left_track_joint");
        assert!(left.contains("<origin xyz=\"0 0.25 0.06\""), "{left}");
        assert!(joint(&u, "right_track_joint").contains("<origin xyz=\"0 -0.25 0.06\""));
        assert!(u.contains("<box size=\"0.5 0.15"), "{u}");
        let frames = fixed_frames(&d, "").unwrap();
        assert_eq!(frames.len(), 3, "{frames:?}");
    }

    #[test]
    fn what_is_not_described_is_not_invented() {
        let mut d = RobotDescription::default();
        d.set_name("bare");
        d.push_joint("front_left_wheel_joint", JointSource::WHEEL, 0)
            .unwrap();
        d.push_joint("front_steer_joint", JointSource::FRONT_STEER, 0)
            .unwrap();
        let u = urdf(&d, "").unwrap();
        assert!(!u.contains("NaN") && !u.contains("inf"), "{u}");
        assert!(u.contains("<link name=\"base_link\"/>"), "no body: {u}");
        assert!(u.contains("<link name=\"front_left_wheel_link\"/>"), "{u}");
        assert!(u.contains("<!-- wheelbase not described: on the centre line -->"));
        assert!(u.contains("<!-- track not described, nor the body's width -->"));
        assert!(u.contains("<!-- wheelbase not described: at the centre -->"));
        assert!(u.contains("<!-- largest steering angle not described: ±90° -->"));
        // Revolute joints need limits: ±90° where none is described.
        assert!(joint(&u, "front_steer_joint").contains("upper=\"1.570796327\""));
    }

    #[test]
    fn names_are_escaped_and_unwritable_or_repeated_ones_refused() {
        let mut d = steered();
        d.set_name("a<b>&\"c'");
        let u = urdf(&d, "").unwrap();
        assert!(
            u.contains("<robot name=\"a&lt;b&gt;&amp;&quot;c&apos;\">"),
            "{u}"
        );
        let mut bad = steered();
        bad.push_sensor("bell\u{7}", SensorDescription::default())
            .unwrap();
        assert!(matches!(
            urdf(&bad, ""),
            Err(UrdfError::BadName { what: "link", .. })
        ));
        let mut twice = steered();
        twice
            .push_joint("front_steer_joint", JointSource::FRONT_STEER, 0)
            .unwrap();
        assert_eq!(
            urdf(&twice, ""),
            Err(UrdfError::Duplicate {
                what: "link",
                name: "front_steer_link".into()
            })
        );
    }
}
