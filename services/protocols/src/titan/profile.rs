//! The TITAN's profile: its physical constants and the ⚠ choices of its manual.

use serde::{Deserialize, Serialize};

/// AgileX TITAN: front/rear dual Ackermann, CAN 500 kbit/s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TitanProfile {
    /// Wheelbase L, m.
    pub wheelbase_m: f64,
    /// Track W, m.
    pub track_m: f64,
    /// Top speed, m/s (0x111 valid ±3000 mm/s).
    pub max_linear_mps: f64,
    /// Top speed while |steer| exceeds `steer_speed_limit_above_rad`, m/s.
    pub max_linear_steering_mps: f64,
    /// Steering angle above which the lower speed limit applies, rad.
    pub steer_speed_limit_above_rad: f64,
    /// Largest inner steering angle, rad (0x111 valid ±367 mrad).
    pub max_steer_rad: f64,
    /// ⚠ 0x221/0x271 steering sign. The 0x111 table says left turn is positive; the text of
    /// 0x221 says a left turn reports negative. `false` (default) trusts the text and negates
    /// the reported angles.
    pub steering_feedback_left_positive: bool,
    /// The chassis' command timeout, ms: without 0x111 for this long it faults to standby.
    pub command_timeout_ms: u64,
    /// Heartbeat (0x111) period, ms.
    pub heartbeat_period_ms: u64,
    /// State of charge below which the tail lights warn, %.
    pub low_battery_warning_soc_pct: f64,
    /// State of charge below which the chassis cuts drive power, %.
    pub low_battery_cutoff_soc_pct: f64,
}

impl Default for TitanProfile {
    fn default() -> Self {
        Self {
            wheelbase_m: 0.845,
            track_m: 0.860,
            max_linear_mps: 3.0,
            max_linear_steering_mps: 1.5,
            steer_speed_limit_above_rad: 0.087,
            max_steer_rad: 0.367,
            steering_feedback_left_positive: false,
            command_timeout_ms: 500,
            heartbeat_period_ms: 20,
            low_battery_warning_soc_pct: 15.0,
            low_battery_cutoff_soc_pct: 10.0,
        }
    }
}
