//! `[mux]`: the velocity sources, the locks and the limits of the service's priority mux, as
//! configured (the mux itself is `chassisd::mux`).

use chassis_interfaces::{MAX_LOCKS, MAX_SOURCES, valid_robot_name};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// One configured velocity source.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    pub name: String,
    pub priority: u8,
    pub timeout_ms: u64,
    #[serde(default)]
    pub required: bool,
    /// Another computer may publish on it through a bridge (`chassis-zenoh`); never a required
    /// source.
    #[serde(default)]
    pub remote: bool,
}

/// One configured lock.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LockConfig {
    pub name: String,
    /// Sources below this priority are blocked while the lock is held.
    pub priority: u8,
    /// The stop category (IEC 60204-1) of the stop it makes while held and the output is zero:
    /// 0 disables the drive at once, 1 brakes and then disables it, 2 brakes and holds
    /// (`chassis_interfaces::StopCategory`). An engage may ask for another. Unset: 2, except
    /// the lock called `estop`, which stops with category 1 on a robot that can disable its
    /// drive (the service fills it in from the robot's family).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub category: Option<u8>,
}

/// Speed and acceleration limits of the service (on top of the robot's own).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LimitsConfig {
    /// |vx| limit, m/s (0: only the robot's own limit).
    pub max_linear_mps: f64,
    /// |vy| limit, m/s (0: only the robot's own limit).
    pub max_lateral_mps: f64,
    /// |ω| limit, rad/s (0: only the robot's own limit).
    pub max_angular_radps: f64,
    /// Smoothing: largest change of vx and vy per second, m/s² (0: none).
    pub linear_accel_mps2: f64,
    /// Smoothing: largest change of ω per second, rad/s² (0: none).
    pub angular_accel_radps2: f64,
    /// Stops from sources at or above this priority are never smoothed.
    pub safety_priority: u8,
    /// The deceleration a held lock's stop of category 1 or 2 commands, m/s²: the output ramps
    /// down at it (then a category-1 stop cuts the drive), and the robot's description publishes
    /// it for a planner to size its protective field (`v ≤ √(2·a·d)`). 0: zero is commanded at
    /// once and the chassis brakes at its own rate, which no manual gives.
    pub braking_mps2: f64,
}

impl Default for LimitsConfig {
    fn default() -> Self {
        Self {
            max_linear_mps: 0.0,
            max_lateral_mps: 0.0,
            max_angular_radps: 0.0,
            linear_accel_mps2: 2.0,
            angular_accel_radps2: 4.0,
            safety_priority: 255,
            braking_mps2: 0.0,
        }
    }
}

/// The mux's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MuxConfig {
    #[serde(rename = "source")]
    pub sources: Vec<SourceConfig>,
    #[serde(rename = "lock")]
    pub locks: Vec<LockConfig>,
    pub limits: LimitsConfig,
}

impl Default for MuxConfig {
    /// `safety` (255, 200 ms, required), `teleop` (100, 300 ms), `planner` (10, 500 ms),
    /// `foxglove` (100, 300 ms: the Teleop panel of a Foxglove view, teleop's rank), `remote`
    /// (100, 300 ms, remote: a teleop on another computer, through `chassis-zenoh`), `ros2` (50,
    /// 500 ms: a ROS 2 stack's `cmd_vel` through chassis-ros2, below teleop, above the planner);
    /// lock `estop` at 255.
    fn default() -> Self {
        let source = |name: &str, priority, timeout_ms, required| SourceConfig {
            name: name.into(),
            priority,
            timeout_ms,
            required,
            remote: false,
        };
        Self {
            sources: vec![
                source("safety", 255, 200, true),
                source("teleop", 100, 300, false),
                source("planner", 10, 500, false),
                source("foxglove", 100, 300, false),
                SourceConfig {
                    remote: true,
                    ..source("remote", 100, 300, false)
                },
                source("ros2", 50, 500, false),
            ],
            locks: vec![LockConfig {
                name: "estop".into(),
                priority: 255,
                category: None,
            }],
            limits: LimitsConfig::default(),
        }
    }
}

/// Why a mux configuration is not usable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MuxConfigError {
    #[error("no velocity source is configured")]
    NoSources,
    #[error("{count} sources configured; at most {MAX_SOURCES}")]
    TooManySources { count: usize },
    #[error("{count} locks configured; at most {MAX_LOCKS}")]
    TooManyLocks { count: usize },
    #[error("'{0}' is not a valid source or lock name (1-16 of a-z 0-9 - _)")]
    BadName(String),
    #[error("'{0}' is configured twice")]
    Duplicate(String),
    #[error("source '{0}' needs a timeout above 0 ms")]
    ZeroTimeout(String),
    #[error(
        "source '{0}' is both required and remote: the source the robot cannot move without \
         never comes from another computer"
    )]
    RemoteRequired(String),
    #[error("limits.braking_mps2 = {0}: a deceleration is a finite number ≥ 0 (0: none)")]
    BadBraking(f64),
    #[error("lock '{0}': category {1} is not a stop category (0, 1 or 2)")]
    BadCategory(String, u8),
}

impl MuxConfig {
    /// Checks names, counts and timeouts.
    pub fn validate(&self) -> Result<(), MuxConfigError> {
        if self.sources.is_empty() {
            return Err(MuxConfigError::NoSources);
        }
        if self.sources.len() > MAX_SOURCES {
            return Err(MuxConfigError::TooManySources {
                count: self.sources.len(),
            });
        }
        if self.locks.len() > MAX_LOCKS {
            return Err(MuxConfigError::TooManyLocks {
                count: self.locks.len(),
            });
        }
        let mut seen = std::collections::HashSet::new();
        for name in self
            .sources
            .iter()
            .map(|s| &s.name)
            .chain(self.locks.iter().map(|l| &l.name))
        {
            if !valid_robot_name(name) {
                return Err(MuxConfigError::BadName(name.clone()));
            }
            if !seen.insert(name) {
                return Err(MuxConfigError::Duplicate(name.clone()));
            }
        }
        if let Some(s) = self.sources.iter().find(|s| s.timeout_ms == 0) {
            return Err(MuxConfigError::ZeroTimeout(s.name.clone()));
        }
        if let Some(s) = self.sources.iter().find(|s| s.remote && s.required) {
            return Err(MuxConfigError::RemoteRequired(s.name.clone()));
        }
        if let Some(l) = self
            .locks
            .iter()
            .find(|l| l.category.is_some_and(|c| c > 2))
        {
            return Err(MuxConfigError::BadCategory(
                l.name.clone(),
                l.category.unwrap_or_default(),
            ));
        }
        Ok(())
    }

    /// Lifts the "required" rule from every source (`--no-safety-monitor`).
    pub fn without_required_sources(mut self) -> Self {
        for s in &mut self.sources {
            s.required = false;
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_configurations_are_refused_with_a_reason() {
        let mut c = MuxConfig::default();
        c.sources.push(c.sources[0].clone());
        assert_eq!(
            c.validate(),
            Err(MuxConfigError::Duplicate("safety".into()))
        );
        let mut c = MuxConfig::default();
        c.sources[1].name = "Tele Op".into();
        assert!(matches!(c.validate(), Err(MuxConfigError::BadName(_))));
        let mut c = MuxConfig::default();
        c.sources[2].timeout_ms = 0;
        assert!(matches!(c.validate(), Err(MuxConfigError::ZeroTimeout(_))));
        let mut c = MuxConfig::default();
        c.sources[0].remote = true;
        assert_eq!(
            c.validate(),
            Err(MuxConfigError::RemoteRequired("safety".into()))
        );
        let c = MuxConfig {
            sources: vec![],
            ..MuxConfig::default()
        };
        assert_eq!(c.validate(), Err(MuxConfigError::NoSources));
    }
}
