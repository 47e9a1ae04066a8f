//! The loopback profile: the robot it stands in for, its limits and its timing.

use serde::{Deserialize, Serialize};

use crate::kind::RobotKind;

/// The loopback protocol's values; every one may be set from a `[profile]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoopbackProfile {
    /// The registered robot the test protocol stands in for (it has none of its own).
    pub robot: RobotKind,
    /// Top forward and reverse speed, m/s.
    pub max_linear_mps: f64,
    /// Top yaw rate, rad/s.
    pub max_angular_radps: f64,
    /// Heartbeat (0x010) period, ms.
    pub heartbeat_period_ms: u64,
    /// The chassis' command timeout, ms: without 0x010 for this long it stops.
    pub command_timeout_ms: u64,
}

/// Not the real families' 20 ms and 500 ms: the conformance suite takes its timing from the
/// profile, never from a number of its own.
impl Default for LoopbackProfile {
    fn default() -> Self {
        Self {
            // A differential CAN robot, as the loopback chassis is.
            robot: RobotKind::Tracer,
            max_linear_mps: 1.0,
            max_angular_radps: 1.0,
            heartbeat_period_ms: 50,
            command_timeout_ms: 300,
        }
    }
}
