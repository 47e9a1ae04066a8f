//! Where one robot's channels, services and frames live on a bridge that serves several: its
//! topics and services under `/<name>` (`/scout1/tf`, `/scout1/estop`), its frames under
//! `<name>/` (`scout1/odom`, `scout1/base_link`: the `tf_prefix` convention), so that each robot
//! keeps its own odometry origin in one Foxglove scene. A bridge serving one robot uses no
//! prefix, as it always has.

use foxglove::messages::{FrameTransforms, LocationFix, PoseInFrame, SceneUpdate};

/// One robot's place on the bridge.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Naming {
    /// chassisd's robot name.
    pub robot: String,
    /// Put before every topic and service name: `/<name>`, or nothing.
    pub topics: String,
    /// Put before every frame id: `<name>/`, or nothing.
    pub frames: String,
}

impl Naming {
    /// The naming of robot `name`; `prefixed` when the bridge serves several.
    pub fn of(name: &str, prefixed: bool) -> Self {
        if prefixed {
            Self {
                robot: name.to_string(),
                topics: format!("/{name}"),
                frames: format!("{name}/"),
            }
        } else {
            Self {
                robot: name.to_string(),
                ..Self::default()
            }
        }
    }

    /// `topic` (`/tf`, `/estop`) as this robot's.
    pub fn topic(&self, topic: &str) -> String {
        format!("{}{topic}", self.topics)
    }

    /// Whether a client's `topic` addresses this robot: under its prefix, or any topic when the
    /// bridge serves this robot alone.
    pub fn owns(&self, topic: &str) -> bool {
        self.topics.is_empty()
            || topic
                .strip_prefix(&self.topics)
                .is_some_and(|rest| rest.starts_with('/'))
    }

    fn frame(&self, frame: &mut String) {
        if !self.frames.is_empty() && !frame.is_empty() {
            frame.insert_str(0, &self.frames);
        }
    }

    pub fn transforms(&self, mut m: FrameTransforms) -> FrameTransforms {
        for t in &mut m.transforms {
            self.frame(&mut t.parent_frame_id);
            self.frame(&mut t.child_frame_id);
        }
        m
    }

    pub fn pose(&self, mut m: PoseInFrame) -> PoseInFrame {
        self.frame(&mut m.frame_id);
        m
    }

    pub fn scene(&self, mut m: SceneUpdate) -> SceneUpdate {
        for e in &mut m.entities {
            self.frame(&mut e.frame_id);
        }
        m
    }

    pub fn fix(&self, mut m: LocationFix) -> LocationFix {
        self.frame(&mut m.frame_id);
        m
    }
}

/// Checks the robots a bridge is asked to serve: at least one, each named once, and names that
/// can head a topic (no `/`, no spaces).
pub fn check_names(names: &[String]) -> Result<(), String> {
    if names.is_empty() {
        return Err("name at least one robot (--name NAME)".into());
    }
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() || name.contains(['/', ' ']) {
            return Err(format!(
                "'{name}' cannot name a robot's topics (empty, or with '/' or a space)"
            ));
        }
        if names[..i].contains(name) {
            return Err(format!("robot '{name}' is named twice"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::messages::{FrameTransform, SceneEntity};

    #[test]
    fn one_robot_keeps_the_plain_names() {
        let n = Naming::of("titan", false);
        assert_eq!(n.topic("/tf"), "/tf");
        assert!(n.owns("/cmd_vel"));
        assert_eq!(
            n.pose(PoseInFrame {
                frame_id: "odom".into(),
                ..Default::default()
            })
            .frame_id,
            "odom"
        );
    }

    #[test]
    fn several_robots_each_get_their_prefix() {
        let n = Naming::of("scout1", true);
        assert_eq!(n.topic("/tf"), "/scout1/tf");
        assert_eq!(n.topic("/estop"), "/scout1/estop");
        assert!(n.owns("/scout1/cmd_vel"));
        assert!(!n.owns("/scout10/cmd_vel"));
        assert!(!n.owns("/cmd_vel"));
        let tf = n.transforms(FrameTransforms {
            transforms: vec![FrameTransform {
                parent_frame_id: "odom".into(),
                child_frame_id: "base_link".into(),
                ..Default::default()
            }],
        });
        assert_eq!(tf.transforms[0].parent_frame_id, "scout1/odom");
        assert_eq!(tf.transforms[0].child_frame_id, "scout1/base_link");
        let scene = n.scene(SceneUpdate {
            entities: vec![SceneEntity {
                frame_id: "base_link".into(),
                ..Default::default()
            }],
            ..Default::default()
        });
        assert_eq!(scene.entities[0].frame_id, "scout1/base_link");
    }

    #[test]
    fn names_that_cannot_head_a_topic_are_refused() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(check_names(&names(&["a", "b"])).is_ok());
        assert!(check_names(&names(&[])).is_err());
        assert!(check_names(&names(&["a", "a"])).is_err());
        assert!(check_names(&names(&["a/b"])).is_err());
        assert!(check_names(&names(&[""])).is_err());
    }
}
