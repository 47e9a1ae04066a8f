//! Robot profiles: every physical constant of each chassis and every choice where its manual
//! contradicts itself (the ⚠ entries of `PROTOCOLS.md`), with the manuals' values as defaults.
//!
//! Profiles deserialize from the `[profile]` table of the service's TOML config, so a user with a
//! real robot can flip a doubtful parameter without a rebuild. Unknown keys are rejected.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::agilex_v2::V2Profile;
use crate::registry::RobotKind;

/// Which AgileX wire protocol: V1 (count and checksum in every frame) or V2 (the TITAN's family).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    V1,
    V2,
}

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::V1 => "v1",
            Protocol::V2 => "v2",
        }
    }
}

/// A protocol name that is neither `v1` nor `v2`, or one the robot does not speak.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ProtocolError {
    #[error("unknown protocol '{name}' (expected v1 or v2)")]
    Unknown { name: String },
    #[error("{robot} does not speak protocol {protocol} here")]
    NotSpoken {
        robot: RobotKind,
        protocol: &'static str,
    },
}

impl std::str::FromStr for Protocol {
    type Err = ProtocolError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "v1" => Ok(Protocol::V1),
            "v2" => Ok(Protocol::V2),
            _ => Err(ProtocolError::Unknown { name: s.into() }),
        }
    }
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

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
    /// The robot of this model, as the registry knows it.
    pub fn robot(self) -> RobotKind {
        RobotKind::of_v1(self).unwrap_or(RobotKind::ScoutMini)
    }
}

/// The AgileX protocol-V1 profile (SCOUT MINI, SCOUT 2.0, BUNKER).
pub type V1Profile = ScoutMiniProfile;

/// AgileX protocol V1 — SCOUT MINI by default, SCOUT 2.0 and BUNKER by `model`: skid steer or
/// tracks, CAN 500 kbit/s, count + checksum in every frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScoutMiniProfile {
    /// Which V1 robot (its defaults come from [`ScoutMiniProfile::for_model`]).
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

impl Default for ScoutMiniProfile {
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

impl ScoutMiniProfile {
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
        let base = ScoutMiniProfile::default();
        match model {
            V1Model::ScoutMini => base,
            V1Model::Scout => ScoutMiniProfile {
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
            V1Model::Bunker => ScoutMiniProfile {
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

/// `profile` with the keys of `overrides` (the `[profile]` table of the service's config) set
/// over it. Unknown keys and wrong types are errors.
pub(crate) fn with_overrides<P>(profile: &P, overrides: &toml::Table) -> Result<P, toml::de::Error>
where
    P: Serialize + serde::de::DeserializeOwned,
{
    let mut table = toml::Table::try_from(profile)
        .map_err(|e| <toml::de::Error as serde::de::Error>::custom(format!("profile: {e}")))?;
    for (key, value) in overrides {
        table.insert(key.clone(), value.clone());
    }
    toml::Value::Table(table).try_into()
}

/// XBot: differential (optionally omni) drive, RS232, little-endian.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XbotProfile {
    /// Baud rate of the control link (not in the manual), 8N1.
    pub baud: u32,
    /// Baud rate of the GPS receiver's NMEA stream, 8N1.
    pub gps_baud: u32,
    /// Drive wheel diameter, m.
    pub wheel_diameter_m: f64,
    /// ⚠ Encoder counts per wheel turn: the protocol note says 8000; the spec sheet's 1000-line
    /// encoder behind 1:16 and "0.019 mm per count" disagree.
    pub encoder_counts_per_rev: f64,
    /// Distance between the drive wheels, m. Not in the manual: odometry from the encoders is
    /// only published once this is set.
    pub wheel_separation_m: Option<f64>,
    /// Top speed, m/s.
    pub max_linear_mps: f64,
    /// Smallest speed the board executes, m/s (smaller requests are sent as 0).
    pub min_linear_mps: f64,
    /// Largest yaw rate the driver will command, rad/s.
    pub max_angular_rad_s: f64,
    /// True for omni variants that accept a lateral speed.
    pub omni: bool,
    /// ⚠ Yaw-rate sign on the wire. Note 1 says positive is a left turn (default); the examples
    /// label +20 °/s "turn right".
    pub yaw_rate_left_positive: bool,
    /// ⚠ Lateral-speed sign on the wire. The examples label +vy "move right" (default false).
    pub lateral_left_positive: bool,
    /// ⚠ Decode motor currents and ultrasonic ranges as BCD (the vendor's 2017 driver) instead
    /// of plain binary (the manual, default).
    pub bcd_currents_and_ranges: bool,
    /// Heartbeat (0x03) rate, Hz: the manual wants more than 5 and less than 10.
    pub heartbeat_hz: f64,
    /// The board's command timeout, ms.
    pub command_timeout_ms: u64,
    /// Battery voltage when fully charged, V (the manual's charging voltage, 24.9 V).
    pub battery_full_v: f64,
    /// Battery voltage below which the robot should be charged, V. Not in the manual: 15 % of
    /// the 23.0-26.0 V range the simulated chassis models; set your pack's level.
    pub battery_low_v: f64,
}

impl Default for XbotProfile {
    fn default() -> Self {
        Self {
            baud: 115_200,
            gps_baud: 4800,
            wheel_diameter_m: 0.2,
            encoder_counts_per_rev: 8000.0,
            wheel_separation_m: None,
            max_linear_mps: 1.5,
            min_linear_mps: 0.01,
            max_angular_rad_s: std::f64::consts::PI,
            omni: false,
            yaw_rate_left_positive: true,
            lateral_left_positive: false,
            bcd_currents_and_ranges: false,
            heartbeat_hz: 8.0,
            command_timeout_ms: 500,
            battery_full_v: 24.9,
            battery_low_v: 23.45,
        }
    }
}

impl XbotProfile {
    /// Wheel travel per encoder count, m.
    pub fn metres_per_count(&self) -> f64 {
        std::f64::consts::PI * self.wheel_diameter_m / self.encoder_counts_per_rev
    }
}

/// Why a profile does not make a drivable robot.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileError {
    /// A length, speed, scale or rate that must be finite and above zero.
    #[error("{name} must be above zero (is {value})")]
    NotPositive { name: &'static str, value: f64 },
    /// The heartbeat does not fit inside the chassis' command timeout.
    #[error(
        "heartbeat_period_ms ({heartbeat_ms}) must be above 0 and below command_timeout_ms \
         ({timeout_ms})"
    )]
    Heartbeat { heartbeat_ms: u64, timeout_ms: u64 },
    /// A steering limit at or beyond a right angle (TITAN).
    #[error("max_steer_rad must be below π/2")]
    SteerBeyondRightAngle,
    /// A negative (or NaN) steering angle above which speed is limited (TITAN).
    #[error("steer_speed_limit_above_rad must not be negative")]
    NegativeSteerSpeedLimit,
    /// A serial line at 0 baud (XBot).
    #[error("baud rates must be above zero")]
    ZeroBaud,
    /// A dead band below zero or reaching the top speed (XBot).
    #[error("min_linear_mps must be at least 0 and below max_linear_mps")]
    MinLinear,
    /// A heartbeat rate outside the manual's bounds (XBot).
    #[error("heartbeat_hz must be above 5 and below 10 Hz (the manual's bounds), is {hz}")]
    HeartbeatRate { hz: f64 },
    /// No command timeout (XBot).
    #[error("command_timeout_ms must be above zero")]
    ZeroCommandTimeout,
}

/// Checks `value` is finite and above zero.
fn positive(name: &'static str, value: f64) -> Result<(), ProfileError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ProfileError::NotPositive { name, value })
    }
}

/// Checks the protocol detection listens for a while and needs at least one frame (⚠ D-16).
pub(crate) fn detection(timeout_ms: u64, min_frames: u32) -> Result<(), ProfileError> {
    if timeout_ms == 0 {
        return Err(ProfileError::NotPositive {
            name: "detect_timeout_ms",
            value: 0.0,
        });
    }
    if min_frames == 0 {
        return Err(ProfileError::NotPositive {
            name: "detect_min_frames",
            value: 0.0,
        });
    }
    Ok(())
}

fn timeouts(heartbeat_ms: u64, timeout_ms: u64) -> Result<(), ProfileError> {
    if heartbeat_ms == 0 || heartbeat_ms >= timeout_ms {
        return Err(ProfileError::Heartbeat {
            heartbeat_ms,
            timeout_ms,
        });
    }
    Ok(())
}

impl TitanProfile {
    /// Checks the values make a drivable robot.
    pub fn validate(&self) -> Result<(), ProfileError> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_linear_steering_mps", self.max_linear_steering_mps)?;
        positive("max_steer_rad", self.max_steer_rad)?;
        if self.max_steer_rad >= std::f64::consts::FRAC_PI_2 {
            return Err(ProfileError::SteerBeyondRightAngle);
        }
        if self.steer_speed_limit_above_rad.is_nan() || self.steer_speed_limit_above_rad < 0.0 {
            return Err(ProfileError::NegativeSteerSpeedLimit);
        }
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)
    }
}

impl ScoutMiniProfile {
    /// Checks the values make a drivable robot (a zero full scale would make every command
    /// unencodable).
    pub fn validate(&self) -> Result<(), ProfileError> {
        positive("wheelbase_m", self.wheelbase_m)?;
        positive("track_m", self.track_m)?;
        positive("linear_full_scale_mps", self.linear_full_scale_mps)?;
        positive("angular_full_scale_rad_s", self.angular_full_scale_rad_s)?;
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_angular_rad_s", self.max_angular_rad_s)?;
        detection(self.detect_timeout_ms, self.detect_min_frames)?;
        timeouts(self.heartbeat_period_ms, self.command_timeout_ms)
    }
}

impl XbotProfile {
    /// Checks the values make a drivable robot, and the heartbeat rate the manual asks for.
    pub fn validate(&self) -> Result<(), ProfileError> {
        if self.baud == 0 || self.gps_baud == 0 {
            return Err(ProfileError::ZeroBaud);
        }
        positive("wheel_diameter_m", self.wheel_diameter_m)?;
        positive("encoder_counts_per_rev", self.encoder_counts_per_rev)?;
        if let Some(separation) = self.wheel_separation_m {
            positive("wheel_separation_m", separation)?;
        }
        positive("max_linear_mps", self.max_linear_mps)?;
        positive("max_angular_rad_s", self.max_angular_rad_s)?;
        if self.min_linear_mps.is_nan()
            || self.min_linear_mps < 0.0
            || self.min_linear_mps >= self.max_linear_mps
        {
            return Err(ProfileError::MinLinear);
        }
        if self.heartbeat_hz.is_nan() || self.heartbeat_hz <= 5.0 || self.heartbeat_hz >= 10.0 {
            return Err(ProfileError::HeartbeatRate {
                hz: self.heartbeat_hz,
            });
        }
        if self.command_timeout_ms == 0 {
            return Err(ProfileError::ZeroCommandTimeout);
        }
        Ok(())
    }
}

/// Why a `[profile]` table does not make a profile.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ProfileTableError {
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    /// An unknown key or a wrong type.
    #[error(transparent)]
    Toml(#[from] toml::de::Error),
    /// A protocol-V1 or V2 `model` of another robot: `owner` is the robot the model belongs to.
    #[error("profile.model: a {owner} model is not a {robot}")]
    WrongModel { owner: RobotKind, robot: RobotKind },
}

/// One robot's profile.
#[derive(Debug, Clone, PartialEq)]
pub enum Profile {
    Titan(TitanProfile),
    ScoutMini(ScoutMiniProfile),
    Xbot(XbotProfile),
    /// An AgileX protocol-V2 robot (SCOUT MINI with V2 firmware included).
    V2(V2Profile),
}

impl Profile {
    /// The defaults for `robot` speaking `protocol`, with the keys of `table` (the `[profile]`
    /// table of the service's config) set over them. A protocol-V2 table may name a variant with
    /// `model` (e.g. `scout-mini-omni`): its keys are then set over that variant's defaults.
    pub fn from_table(
        robot: RobotKind,
        protocol: Option<Protocol>,
        table: &toml::Table,
    ) -> Result<Self, ProfileTableError> {
        let value = toml::Value::Table(table.clone());
        let model = table.get("model").cloned();
        let profile = match robot.entry().default_profile(protocol)? {
            Profile::Titan(_) => Profile::Titan(value.try_into()?),
            Profile::Xbot(_) => Profile::Xbot(value.try_into()?),
            Profile::ScoutMini(default) => {
                let base = match model {
                    Some(model) => ScoutMiniProfile::for_model(model.try_into()?),
                    None => default,
                };
                Profile::ScoutMini(with_overrides(&base, table)?)
            }
            Profile::V2(default) => {
                let base = match model {
                    Some(model) => V2Profile::for_model(model.try_into()?),
                    None => default,
                };
                Profile::V2(with_overrides(&base, table)?)
            }
        };
        if profile.robot() != robot {
            return Err(ProfileTableError::WrongModel {
                owner: profile.robot(),
                robot,
            });
        }
        Ok(profile)
    }

    /// The wire protocol of this profile, for the robots that have a choice of two.
    pub fn protocol(&self) -> Option<Protocol> {
        match self {
            Profile::ScoutMini(_) => Some(Protocol::V1),
            Profile::V2(_) => Some(Protocol::V2),
            Profile::Titan(_) | Profile::Xbot(_) => None,
        }
    }

    /// Checks the values make a drivable robot.
    pub fn validate(&self) -> Result<(), ProfileError> {
        match self {
            Profile::Titan(p) => p.validate(),
            Profile::ScoutMini(p) => p.validate(),
            Profile::Xbot(p) => p.validate(),
            Profile::V2(p) => p.validate(),
        }
    }

    /// The robot the profile is of, as the registry knows its models. (Every V1 and V2 model
    /// belongs to a registry entry: `registry::tests` checks it; the fallbacks are unreachable.)
    pub fn robot(&self) -> RobotKind {
        match self {
            Profile::Titan(_) => RobotKind::Titan,
            Profile::ScoutMini(p) => p.model.robot(),
            Profile::Xbot(_) => RobotKind::Xbot,
            Profile::V2(p) => RobotKind::of_v2(p.model).unwrap_or(RobotKind::Scout),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::approx_constant)] // 0.5235 is the manual's value
    fn defaults_are_the_manuals_choices() {
        let t = TitanProfile::default();
        assert!(!t.steering_feedback_left_positive);
        assert_eq!((t.max_linear_mps, t.max_steer_rad), (3.0, 0.367));
        let s = ScoutMiniProfile::default();
        assert_eq!(s.angular_full_scale_rad_s, 0.5235);
        assert_eq!(s.linear_full_scale_mps, 5.0);
        let x = XbotProfile::default();
        assert!(x.yaw_rate_left_positive && !x.lateral_left_positive);
        assert!(!x.bcd_currents_and_ranges);
        assert_eq!(x.encoder_counts_per_rev, 8000.0);
        assert_eq!(x.wheel_separation_m, None);
        assert!(x.heartbeat_hz > 5.0 && x.heartbeat_hz < 10.0);
    }

    #[test]
    #[allow(clippy::approx_constant)] // 0.5235 is the sources' value
    fn scout_and_bunker_speak_v1_with_their_own_scales_and_hunter_does_not() {
        for (robot, scales) in [
            (RobotKind::ScoutMini, (5.0, 0.5235)),
            (RobotKind::Scout, (1.5, 0.5235)),
            (RobotKind::Bunker, (3.0, 2.5235)),
        ] {
            assert!(robot.protocols().contains(&Protocol::V1), "{robot}");
            let profile = robot.entry().default_profile(Some(Protocol::V1)).unwrap();
            assert_eq!(profile.robot(), robot);
            assert_eq!(profile.protocol(), Some(Protocol::V1));
            let Profile::ScoutMini(p) = &profile else {
                panic!("{robot}: {profile:?}");
            };
            assert_eq!(
                (p.linear_full_scale_mps, p.angular_full_scale_rad_s),
                scales
            );
            assert_eq!(profile.validate(), Ok(()), "{robot}");
        }
        // Their default protocol stays what it was: SCOUT MINI V1, SCOUT and BUNKER V2.
        assert_eq!(
            RobotKind::Scout.entry().defaults().protocol(),
            Some(Protocol::V2)
        );
        assert_eq!(
            RobotKind::Hunter
                .entry()
                .default_profile(Some(Protocol::V1)),
            Err(ProtocolError::NotSpoken {
                robot: RobotKind::Hunter,
                protocol: "v1"
            })
        );
        // A `[profile]` table of a V1 BUNKER starts from the BUNKER's values.
        let table: toml::Table = toml::from_str("max_linear_mps = 1.0").unwrap();
        let Profile::ScoutMini(p) =
            Profile::from_table(RobotKind::Bunker, Some(Protocol::V1), &table).unwrap()
        else {
            panic!("not V1");
        };
        assert_eq!((p.model, p.max_linear_mps), (V1Model::Bunker, 1.0));
        assert_eq!(p.linear_full_scale_mps, 3.0);
        let scout: toml::Table = toml::from_str("model = \"scout\"").unwrap();
        assert_eq!(
            Profile::from_table(RobotKind::Bunker, Some(Protocol::V1), &scout),
            Err(ProfileTableError::WrongModel {
                owner: RobotKind::Scout,
                robot: RobotKind::Bunker
            })
        );
    }

    #[test]
    fn a_profile_flips_one_parameter_from_toml() {
        let t: TitanProfile = toml::from_str("steering_feedback_left_positive = true").unwrap();
        assert!(t.steering_feedback_left_positive);
        assert_eq!(t.max_linear_mps, 3.0);
        let err = toml::from_str::<TitanProfile>("max_speed = 4").unwrap_err();
        assert!(err.to_string().contains("unknown field"), "{err}");
    }

    #[test]
    fn the_defaults_validate_and_nonsense_does_not() {
        for r in RobotKind::ALL {
            assert_eq!(r.entry().defaults().validate(), Ok(()), "{r}");
        }
        let zero = ScoutMiniProfile {
            angular_full_scale_rad_s: 0.0,
            ..ScoutMiniProfile::default()
        };
        assert_eq!(
            zero.validate(),
            Err(ProfileError::NotPositive {
                name: "angular_full_scale_rad_s",
                value: 0.0
            })
        );
        assert_eq!(
            zero.validate().unwrap_err().to_string(),
            "angular_full_scale_rad_s must be above zero (is 0)"
        );
        // Nonsense is refused, and the refusal names the parameter.
        for (nonsense, name) in [
            (
                Profile::Xbot(XbotProfile {
                    heartbeat_hz: 12.0,
                    ..XbotProfile::default()
                }),
                "heartbeat_hz",
            ),
            (
                Profile::Titan(TitanProfile {
                    track_m: f64::NAN,
                    ..TitanProfile::default()
                }),
                "track_m",
            ),
            (
                Profile::Titan(TitanProfile {
                    heartbeat_period_ms: 600,
                    ..TitanProfile::default()
                }),
                "heartbeat_period_ms",
            ),
        ] {
            let refusal = nonsense.validate().unwrap_err().to_string();
            assert!(refusal.contains(name), "{refusal}");
        }
    }

    #[test]
    fn every_id_is_one_robot_and_back() {
        for id in 0..=u8::MAX {
            if let Some(kind) = RobotKind::from_id(id) {
                assert_eq!(kind.id(), id);
            }
        }
        assert_eq!(RobotKind::from_id(0), None);
        assert_eq!(RobotKind::from_id(5), Some(RobotKind::Hunter));
    }

    #[test]
    fn robot_names_parse() {
        for r in RobotKind::ALL {
            assert_eq!(r.name().parse::<RobotKind>(), Ok(r));
            assert_eq!(r.entry().defaults().robot(), r);
            assert_eq!(RobotKind::from_id(r.id()), Some(r));
        }
        let v2 = RobotKind::ScoutMini
            .entry()
            .default_profile(Some(Protocol::V2))
            .unwrap();
        assert_eq!(
            (v2.robot(), v2.protocol()),
            (RobotKind::ScoutMini, Some(Protocol::V2))
        );
        let err = RobotKind::Hunter
            .entry()
            .default_profile(Some(Protocol::V1))
            .unwrap_err();
        assert_eq!(err.to_string(), "hunter does not speak protocol v1 here");
        assert!("v3".parse::<Protocol>().is_err());
        let omni: toml::Table = toml::from_str("model = \"scout-mini-omni\"").unwrap();
        let Profile::V2(p) =
            Profile::from_table(RobotKind::ScoutMini, Some(Protocol::V2), &omni).unwrap()
        else {
            panic!("not V2")
        };
        assert_eq!(p.max_lateral_mps, 2.0);
        let err = Profile::from_table(RobotKind::Hunter, None, &omni).unwrap_err();
        assert_eq!(
            err.to_string(),
            "profile.model: a scout-mini model is not a hunter"
        );
        assert!("husky".parse::<RobotKind>().is_err());
    }

    #[test]
    fn xbot_travel_per_count_follows_the_profile() {
        let x = XbotProfile::default();
        assert!((x.metres_per_count() - std::f64::consts::PI * 0.2 / 8000.0).abs() < 1e-12);
    }
}
