//! The AgileX protocol-V1 profile: the SCOUT MINI's, SCOUT 2.0's and BUNKER's constants and
//! the ⚠ choices of their manuals.

use serde::{Deserialize, Serialize};

use crate::kind::RobotKind;

/// Which robot speaks the AgileX protocol V1 (0x130 / 0x131 / 0x151 / 0x200-0x203, count and
/// checksum in every frame). The three share the frame set and differ in the percent full
/// scales of 0x130, their geometry and their limits.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum V1Model {
    /// SCOUT MINI (its 2019 manual, `PROTOCOLS.md` §2).
    #[default]
    ScoutMini,
    /// SCOUT 2.0 with V1 firmware.
    Scout,
    /// BUNKER with V1 firmware.
    Bunker,
}

impl V1Model {
    /// The robot of this model.
    pub fn robot(self) -> RobotKind {
        match self {
            V1Model::ScoutMini => RobotKind::ScoutMini,
            V1Model::Scout => RobotKind::Scout,
            V1Model::Bunker => RobotKind::Bunker,
        }
    }
}

/// AgileX protocol V1 — SCOUT MINI by default, SCOUT 2.0 and BUNKER by `model`: skid steer or
/// tracks, CAN 500 kbit/s, count + checksum in every frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct V1Profile {
    /// Which V1 robot (its defaults come from [`V1Profile::for_model`]).
    pub model: V1Model,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Track, m.
    pub track_m: f64,
    /// Linear speed at 100 % in 0x130, m/s (table: 5.0; AgileX's SDK: 3.0).
    pub linear_full_scale_mps: f64,
    /// ⚠ Angular speed at 100 % in 0x130, rad/s. The table says 0.5235; the manual's example
    /// (10 % = 0.07853 rad/s) implies 0.7853; AgileX's SDK uses 2.5235. Default: the table.
    pub angular_full_scale_rad_s: f64,
    /// Top speed the driver will command, m/s (the robot's top speed is 20 km/h ≈ 5.56 m/s; the
    /// command's full scale caps it).
    pub max_linear_mps: f64,
    /// Largest yaw rate the driver will command, rad/s.
    pub max_angular_rad_s: f64,
    /// The chassis' command timeout, ms.
    pub command_timeout_ms: u64,
    /// Heartbeat (0x130) period, ms.
    pub heartbeat_period_ms: u64,
    /// Battery under-voltage alarm level, V.
    pub under_voltage_alarm_v: f64,
    /// Battery under-voltage failure level, V.
    pub under_voltage_failure_v: f64,
    /// Pack voltage when fully charged, V (NaN: not in the manuals at hand).
    pub battery_full_v: f64,
    /// ⚠ D-16 (`PROTOCOLS-V2.md` §4.3): on a real CAN bus without a protocol asked for, listen
    /// this long for V1/V2 evidence before reporting silence and listening again, ms.
    pub detect_timeout_ms: u64,
    /// ⚠ D-16: consistent frames of one protocol needed to decide.
    pub detect_min_frames: u32,
}

impl Default for V1Profile {
    // 0.5235 is the manual's table value as printed, not an approximation of π/6.
    #[allow(clippy::approx_constant)]
    fn default() -> Self {
        Self {
            model: V1Model::ScoutMini,
            wheelbase_m: 0.452,
            track_m: 0.450,
            linear_full_scale_mps: 5.0,
            angular_full_scale_rad_s: 0.5235,
            max_linear_mps: 5.0,
            max_angular_rad_s: 0.5235,
            command_timeout_ms: 500,
            heartbeat_period_ms: 20,
            under_voltage_alarm_v: 22.5,
            under_voltage_failure_v: 22.0,
            // "the voltage of fully-recharged battery is about 29.2 V" (SCOUT MINI manual §4.1).
            battery_full_v: 29.2,
            detect_timeout_ms: 5000,
            detect_min_frames: 3,
        }
    }
}

impl V1Profile {
    /// The defaults of a V1 `model`.
    ///
    /// SCOUT 2.0 (`PROTOCOLS-V2.md` §3.1): 0x130 full scales 1.5 m/s and 0.5235 rad/s (AgileX's
    /// SDK, `ScoutV2Limits`, which its V1 parser scales the percentages by), the same values as
    /// limits; wheelbase 0.498 m, track 0.583 m (AgileX's SCOUT 2.0 model); battery warning
    /// 23.5 V and failure 22 V (SCOUT manual v1.3.0).
    ///
    /// BUNKER (§3.7): full scales 3.0 m/s and 2.5235 rad/s (the SDK's `BunkerLimits`); limits
    /// 1.5 m/s and 0.7853 rad/s and the 0.5 × 0.5 m track geometry, as the V2 BUNKER profile
    /// (no V1 BUNKER manual was found); the SCOUT MINI's battery levels (a BUNKER MINI's 24 V
    /// pack).
    #[allow(clippy::approx_constant)] // 0.5235 and 0.7853 are the sources' values as printed
    pub fn for_model(model: V1Model) -> Self {
        let base = V1Profile::default();
        match model {
            V1Model::ScoutMini => base,
            V1Model::Scout => V1Profile {
                model,
                wheelbase_m: 0.498,
                track_m: 0.583,
                linear_full_scale_mps: 1.5,
                angular_full_scale_rad_s: 0.5235,
                max_linear_mps: 1.5,
                max_angular_rad_s: 0.5235,
                under_voltage_alarm_v: 23.5,
                under_voltage_failure_v: 22.0,
                battery_full_v: f64::NAN,
                ..base
            },
            V1Model::Bunker => V1Profile {
                model,
                wheelbase_m: 0.5,
                track_m: 0.5,
                linear_full_scale_mps: 3.0,
                angular_full_scale_rad_s: 2.5235,
                max_linear_mps: 1.5,
                max_angular_rad_s: 0.7853,
                battery_full_v: f64::NAN,
                ..base
            },
        }
    }
}
