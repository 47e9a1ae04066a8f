//! The monitor's configuration: TOML → [`RawConfig`] (every key defaulted, unknown keys
//! rejected) → one validated [`Config`] with times in ns. `chassis-safety --print-config` prints
//! the effective configuration in the file's format.
//!
//! Every rule has `enabled`, its thresholds, an `action` (`slow`, `stop` or `latch`), and a
//! release condition: a margin past the threshold the measurement must cross back over
//! (hysteresis), and `release_ms`, how long it must stay there. `trigger_ms` is how long a
//! condition must hold before the rule acts (0: at once).
//!
//! Nothing here knows a robot. The levels of the speed and battery rules come from the robot's
//! description, as chassisd publishes it for the robot it drives (its profile and its configured
//! limits after every override; see [`crate::levels`]); a plain number in the file
//! (`min_voltage_v = 23.0`, `max_linear_mps = 2.0`) overrides the description's on the robot the
//! monitor runs for.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use chassis_client::{FaultFlags, SafetyRule, valid_robot_name};

pub use crate::plausibility::{
    DirectionRule, FollowingRule, Plausibility, PlausibilityThresholds, RunawayRule,
};
use serde::{Deserialize, Deserializer, Serialize};
use thiserror::Error;

/// What a rule does while it is in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Action {
    /// Publish a speed envelope: the `[slow]` speeds (range rules: only towards the obstacle, and
    /// nothing at all towards it inside the stop zone).
    Slow,
    /// Publish a zero request at the safety source's priority while the rule is in force.
    Stop,
    /// Stop and engage the `estop` lock: released only by the operator
    /// (`chassis control estop-release`).
    Latch,
}

impl Action {
    pub fn name(self) -> &'static str {
        match self {
            Action::Slow => "slow",
            Action::Stop => "stop",
            Action::Latch => "latch",
        }
    }
}

/// `[monitor]`: the loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MonitorConfig {
    /// The request (heartbeat, envelope or stop) is re-sent at least this often, ms; a changed
    /// decision is sent at once. Must stay well inside the `safety` source's timeout (200 ms).
    pub publish_period_ms: u64,
    /// Rules are evaluated at least this often, ms, and on every new state sample.
    pub evaluate_period_ms: u64,
    /// `SafetyStatus` is published on every change and at least this often, ms.
    pub status_period_ms: u64,
    /// The mux lock a `latch` engages.
    pub lock: String,
    /// The stop category (IEC 60204-1: 0 cuts the drive at once, 1 brakes and then cuts it, 2
    /// brakes and holds) a latching rule engages the lock with, by rule name (`runaway = 0`,
    /// `operator = 1`); a rule not named stops with the lock's configured category.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub categories: BTreeMap<String, u8>,
}

impl Default for MonitorConfig {
    fn default() -> Self {
        Self {
            publish_period_ms: 50,
            evaluate_period_ms: 20,
            status_period_ms: 100,
            lock: "estop".into(),
            categories: BTreeMap::new(),
        }
    }
}

/// `[slow]`: the envelope of the `slow` action and of the range rules' slow zones.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SlowConfig {
    /// Largest forward and reverse speed, m/s.
    pub linear_mps: f64,
    /// Largest |lateral speed|, m/s (omni robots).
    pub lateral_mps: f64,
    /// Largest |yaw rate|, rad/s.
    pub angular_radps: f64,
}

impl Default for SlowConfig {
    fn default() -> Self {
        Self {
            linear_mps: 0.15,
            lateral_mps: 0.15,
            angular_radps: 0.5,
        }
    }
}

/// `[rules.fault]`: chassis fault flags.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FaultRule {
    pub enabled: bool,
    pub action: Action,
    /// The `FaultFlags` names that trigger the rule. Default: every flag that is not a warning,
    /// except `bumper` (its own rule).
    pub flags: Vec<String>,
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for FaultRule {
    fn default() -> Self {
        let mask = !FaultFlags::WARNINGS & !FaultFlags::BUMPER;
        Self {
            enabled: true,
            action: Action::Stop,
            flags: FaultFlags::names(mask)
                .into_iter()
                .map(str::to_string)
                .collect(),
            trigger_ms: 0,
            release_ms: 500,
        }
    }
}

/// A level the file may set as a plain number, overriding the robot's description. Anything
/// else — the per-robot tables of earlier versions (`[rules.battery.min_voltage_v]` with
/// `titan = …`) among them — is refused with a word on what replaced them.
pub(crate) fn plain_number<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> Result<Option<f64>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Written {
        Number(f64),
        Other(serde::de::IgnoredAny),
    }
    match Written::deserialize(deserializer)? {
        Written::Number(v) => Ok(Some(v)),
        Written::Other(_) => Err(serde::de::Error::custom(
            "must be a plain number; per-robot tables are no longer read: the level comes from \
             the description of the robot chassisd drives (its [profile] after every \
             override), and a number here overrides it for the robot this monitor runs for",
        )),
    }
}

/// `[rules.battery]`: the state of charge where the robot reports one and there is a level
/// for it, else the voltage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BatteryRule {
    pub enabled: bool,
    pub action: Action,
    /// Triggers below this state of charge, %. Absent: the description's
    /// `battery.low_soc_pct` (the chassis' low-battery warning), else its `critical_soc_pct`.
    #[serde(deserialize_with = "plain_number")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_soc_pct: Option<f64>,
    /// Releases at or above the state-of-charge level + this, %.
    pub release_margin_pct: f64,
    /// Triggers below this voltage where the state of charge is not judged, V. Absent: the
    /// description's `battery.low_v` (the chassis' under-voltage alarm), else its `critical_v`.
    #[serde(deserialize_with = "plain_number")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_voltage_v: Option<f64>,
    /// Releases at or above the voltage level + this, V.
    pub release_margin_v: f64,
    /// A voltage sags while accelerating: it must read low this long.
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for BatteryRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Stop,
            min_soc_pct: None,
            release_margin_pct: 5.0,
            min_voltage_v: None,
            release_margin_v: 0.3,
            trigger_ms: 1000,
            release_ms: 1000,
        }
    }
}

/// `[rules.stale]`: the monitor's own watchdog over the state it relies on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StaleRule {
    pub enabled: bool,
    pub action: Action,
    /// Triggers when no new `ChassisState` arrived for this long, ms (the service publishes at
    /// least every 100 ms).
    pub service_timeout_ms: u64,
    /// Triggers when the newest state is older than this (no frame from the chassis), ms; also
    /// whenever the state says `chassis_silent` or `bus_down`.
    pub chassis_timeout_ms: u64,
    pub trigger_ms: u64,
    /// The state must be fresh this long before motion is allowed again.
    pub release_ms: u64,
}

impl Default for StaleRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Stop,
            service_timeout_ms: 200,
            chassis_timeout_ms: 300,
            trigger_ms: 0,
            release_ms: 500,
        }
    }
}

/// `[rules.bumper]`: the bumper (`FaultFlags::BUMPER`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BumperRule {
    pub enabled: bool,
    pub action: Action,
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for BumperRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Latch,
            trigger_ms: 0,
            release_ms: 500,
        }
    }
}

/// A range rule (`[rules.ultrasonic]` in front, `[rules.ir]` behind), in force only where the
/// robot reports ranges (the XBot). The nearest of the three sensors counts. `slow` (default):
/// inside the slow zone, motion towards the obstacle is limited to the `[slow]` speed; inside the
/// stop zone it is blocked — the other direction stays free. `stop` / `latch`: inside the stop
/// zone the robot stops (latches); the slow zone still slows.
macro_rules! range_rule {
    ($name:ident, $doc:literal, $stop:expr, $slow:expr, $hysteresis:expr) => {
        #[doc = $doc]
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct $name {
            pub enabled: bool,
            pub action: Action,
            /// Motion towards an obstacle nearer than this is blocked, m.
            pub stop_m: f64,
            /// Motion towards an obstacle nearer than this is slowed, m.
            pub slow_m: f64,
            /// A zone is left only beyond its edge + this, m.
            pub hysteresis_m: f64,
            /// Ranges older than this count as an obstacle at 0 m (a blind sensor), ms.
            pub max_age_ms: u64,
            pub trigger_ms: u64,
            pub release_ms: u64,
        }

        impl Default for $name {
            fn default() -> Self {
                Self {
                    enabled: true,
                    action: Action::Slow,
                    stop_m: $stop,
                    slow_m: $slow,
                    hysteresis_m: $hysteresis,
                    max_age_ms: 300,
                    trigger_ms: 0,
                    release_ms: 300,
                }
            }
        }

        impl $name {
            fn to_zones(&self, key: &'static str) -> Result<Option<RangeZones>, ConfigError> {
                check_timing(key, self.trigger_ms, self.release_ms)?;
                if !(self.stop_m.is_finite() && self.slow_m.is_finite() && self.stop_m >= 0.0) {
                    return Err(bad(
                        key,
                        "stop_m and slow_m must be finite and not negative",
                    ));
                }
                if self.slow_m < self.stop_m {
                    return Err(bad(key, "slow_m must be at least stop_m"));
                }
                if !(self.hysteresis_m.is_finite() && self.hysteresis_m >= 0.0) {
                    return Err(bad(key, "hysteresis_m must be finite and not negative"));
                }
                if self.max_age_ms == 0 {
                    return Err(bad(key, "max_age_ms must be above 0"));
                }
                Ok(self.enabled.then(|| RangeZones {
                    timing: Timing::new(self.action, self.trigger_ms, self.release_ms),
                    stop_m: self.stop_m,
                    slow_m: self.slow_m,
                    hysteresis_m: self.hysteresis_m,
                    max_age_ns: ms_to_ns(self.max_age_ms),
                }))
            }
        }
    };
}

range_rule!(
    UltrasonicRule,
    "`[rules.ultrasonic]`: the XBot's three ultrasonic rangers in front.",
    0.35,
    0.8,
    0.05
);
range_rule!(
    IrRule,
    "`[rules.ir]`: the XBot's three IR rangers behind. The manual calls them cliff sensors and \
     its example frame reads 0.2 / 0.1 / 0 cm: if a real XBot reads like that, this rule blocks \
     reversing — check the readings (`chassis echo state --json`) before relying on it, or \
     disable it.",
    0.15,
    0.3,
    0.03
);

/// `[rules.speed]`: a measured linear speed beyond what the robot may do — a runaway (downhill,
/// a failing speed loop, bad feedback), never a request: the mux and the driver keep every
/// request inside the robot's effective limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpeedRule {
    pub enabled: bool,
    pub action: Action,
    /// Triggers above this measured |linear speed|, m/s, either way. Absent: the description's
    /// effective limits (the tighter of the driver's and chassisd's `[mux.limits]`), forward and
    /// reverse, × `limit_factor` + `limit_margin_mps`.
    #[serde(deserialize_with = "plain_number")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_linear_mps: Option<f64>,
    /// How far past the description's limit a measured speed may go, as a factor (≥ 1)…
    pub limit_factor: f64,
    /// …plus a margin, m/s (speed measurement noise, overshoot at low limits).
    pub limit_margin_mps: f64,
    /// Releases below the trigger level − this (at most half of it), m/s.
    pub release_margin_mps: f64,
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for SpeedRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Stop,
            max_linear_mps: None,
            limit_factor: 1.1,
            limit_margin_mps: 0.05,
            release_margin_mps: 0.2,
            trigger_ms: 200,
            release_ms: 500,
        }
    }
}

/// `[rules.limit]`: safely limited speed — the measured |linear speed| above the mux's standing
/// speed limit (`MuxStatus::speed_limit_mps`, set by any client, raised only by the operator) +
/// `margin_mps`, for longer than `trigger_ms` (the time the robot may take to brake down to a
/// newly lowered limit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LimitRule {
    pub enabled: bool,
    pub action: Action,
    /// How far past the limit a measured speed may go, m/s (measurement noise, overshoot).
    pub margin_mps: f64,
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for LimitRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Stop,
            margin_mps: 0.1,
            trigger_ms: 1000,
            release_ms: 500,
        }
    }
}

/// `[rules.operator]`: SIGUSR1 to the monitor latches the e-stop (`kill -USR1 <pid>`; the
/// operator's other e-stop, `chassis control estop`, engages the lock in the service directly).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OperatorRule {
    pub enabled: bool,
}

impl Default for OperatorRule {
    fn default() -> Self {
        Self { enabled: true }
    }
}

/// `[rules]`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RulesConfig {
    pub fault: FaultRule,
    pub battery: BatteryRule,
    pub stale: StaleRule,
    pub bumper: BumperRule,
    pub ultrasonic: UltrasonicRule,
    pub ir: IrRule,
    pub speed: SpeedRule,
    pub operator: OperatorRule,
    pub runaway: RunawayRule,
    pub direction: DirectionRule,
    pub following: FollowingRule,
    pub plausibility: PlausibilityThresholds,
    pub limit: LimitRule,
}

/// The file as written.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawConfig {
    pub monitor: MonitorConfig,
    pub slow: SlowConfig,
    pub rules: RulesConfig,
}

/// Why a configuration is not usable.
#[derive(Debug, Error)]
pub enum ConfigError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: String,
        source: toml::de::Error,
    },
    #[error("{key}: {reason}")]
    Bad { key: String, reason: String },
}

/// When a rule acts and releases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timing {
    pub action: Action,
    pub trigger_ns: u64,
    pub release_ns: u64,
}

impl Timing {
    pub(crate) fn new(action: Action, trigger_ms: u64, release_ms: u64) -> Self {
        Self {
            action,
            trigger_ns: ms_to_ns(trigger_ms),
            release_ns: ms_to_ns(release_ms),
        }
    }
}

/// The validated fault rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Faults {
    pub timing: Timing,
    pub mask: u64,
}

/// The validated battery rule; its levels are resolved with the robot's description
/// ([`crate::levels::Levels`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    pub timing: Timing,
    /// The file's state-of-charge level, %, overriding the description's.
    pub min_soc_pct: Option<f64>,
    pub release_margin_pct: f64,
    /// The file's voltage level, V, overriding the description's.
    pub min_voltage_v: Option<f64>,
    pub release_margin_v: f64,
}

/// The validated stale rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Stale {
    pub timing: Timing,
    pub service_timeout_ns: u64,
    pub chassis_timeout_ns: u64,
}

/// A validated range rule.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeZones {
    pub timing: Timing,
    pub stop_m: f64,
    pub slow_m: f64,
    pub hysteresis_m: f64,
    pub max_age_ns: u64,
}

/// The validated speed rule; its levels are resolved with the robot's description
/// ([`crate::levels::Levels`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Speed {
    pub timing: Timing,
    /// The file's trigger level, m/s, overriding the description's.
    pub max_linear_mps: Option<f64>,
    pub limit_factor: f64,
    pub limit_margin_mps: f64,
    pub release_margin_mps: f64,
}

/// The validated safely-limited-speed rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Limit {
    pub timing: Timing,
    pub margin_mps: f64,
}

/// The slow envelope, m/s and rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlowSpeeds {
    pub linear_mps: f32,
    pub lateral_mps: f32,
    pub angular_radps: f32,
}

/// The validated configuration; a disabled rule is `None`.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub publish_period_ns: u64,
    pub evaluate_period_ns: u64,
    pub status_period_ns: u64,
    pub lock: String,
    /// The stop category each latching rule engages the lock with, by [`SafetyRule`] (`None`:
    /// the lock's configured one).
    pub categories: [Option<u8>; SafetyRule::COUNT],
    pub slow: SlowSpeeds,
    pub fault: Option<Faults>,
    pub battery: Option<Battery>,
    pub stale: Option<Stale>,
    pub bumper: Option<Timing>,
    pub ultrasonic: Option<RangeZones>,
    pub ir: Option<RangeZones>,
    pub speed: Option<Speed>,
    pub operator: bool,
    pub plausibility: Plausibility,
    pub limit: Option<Limit>,
    /// The file it was read from (`None`: the defaults).
    pub file: Option<ConfigFile>,
    raw: RawConfig,
}

/// The file a configuration was read from, and the keys it sets (`rules.speed.trigger_ms`):
/// a value is `config` where the file sets it, `default` where it does not.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigFile {
    pub path: PathBuf,
    pub keys: BTreeSet<String>,
}

impl ConfigFile {
    fn of(path: &Path, table: &toml::Table) -> Self {
        fn walk(prefix: &str, table: &toml::Table, keys: &mut BTreeSet<String>) {
            for (key, value) in table {
                let path = if prefix.is_empty() {
                    key.clone()
                } else {
                    format!("{prefix}.{key}")
                };
                match value {
                    toml::Value::Table(inner) => walk(&path, inner, keys),
                    _ => {
                        keys.insert(path);
                    }
                }
            }
        }
        let mut keys = BTreeSet::new();
        walk("", table, &mut keys);
        Self {
            path: path.to_path_buf(),
            keys,
        }
    }

    /// True when the file sets `key` (dotted: `rules.battery.min_voltage_v`).
    pub fn sets(&self, key: &str) -> bool {
        self.keys.contains(key)
    }
}

pub(crate) fn ms_to_ns(ms: u64) -> u64 {
    ms.saturating_mul(1_000_000)
}

/// Longest `trigger_ms` / `release_ms`.
const MAX_DELAY_MS: u64 = 60_000;

pub(crate) fn bad(key: &str, reason: impl Into<String>) -> ConfigError {
    ConfigError::Bad {
        key: key.into(),
        reason: reason.into(),
    }
}

pub(crate) fn check_timing(key: &str, trigger_ms: u64, release_ms: u64) -> Result<(), ConfigError> {
    if trigger_ms > MAX_DELAY_MS || release_ms > MAX_DELAY_MS {
        return Err(bad(
            key,
            format!("trigger_ms and release_ms must be at most {MAX_DELAY_MS}"),
        ));
    }
    Ok(())
}

/// Levels the file may leave out, but if it sets them they must be above 0.
fn check_positive(key: &str, values: &[(&str, Option<f64>)]) -> Result<(), ConfigError> {
    for (name, v) in values {
        if let Some(v) = v
            && !(v.is_finite() && *v > 0.0)
        {
            return Err(bad(
                key,
                format!("{name} must be a finite number above 0 (is {v})"),
            ));
        }
    }
    Ok(())
}

pub(crate) fn check_non_negative(key: &str, values: &[(&str, f64)]) -> Result<(), ConfigError> {
    for (name, v) in values {
        if !(v.is_finite() && *v >= 0.0) {
            return Err(bad(
                key,
                format!("{name} must be finite and not negative (is {v})"),
            ));
        }
    }
    Ok(())
}

impl RawConfig {
    pub fn parse(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }

    /// Checks everything once.
    pub fn validate(self) -> Result<Config, ConfigError> {
        let m = &self.monitor;
        if !(10..=100).contains(&m.publish_period_ms) {
            return Err(bad(
                "monitor.publish_period_ms",
                "must be 10 to 100 ms (well inside the safety source's timeout)",
            ));
        }
        if !(5..=100).contains(&m.evaluate_period_ms) {
            return Err(bad("monitor.evaluate_period_ms", "must be 5 to 100 ms"));
        }
        if !(20..=1000).contains(&m.status_period_ms) {
            return Err(bad("monitor.status_period_ms", "must be 20 to 1000 ms"));
        }
        if !valid_robot_name(&m.lock) {
            return Err(bad(
                "monitor.lock",
                format!("'{}' is not a lock name (1-16 of a-z 0-9 - _)", m.lock),
            ));
        }
        let s = &self.slow;
        check_non_negative(
            "slow",
            &[
                ("linear_mps", s.linear_mps),
                ("lateral_mps", s.lateral_mps),
                ("angular_radps", s.angular_radps),
            ],
        )?;
        let slow = SlowSpeeds {
            linear_mps: s.linear_mps as f32,
            lateral_mps: s.lateral_mps as f32,
            angular_radps: s.angular_radps as f32,
        };

        let r = &self.rules;
        check_timing("rules.fault", r.fault.trigger_ms, r.fault.release_ms)?;
        let mut mask = 0u64;
        for name in &r.fault.flags {
            let Some(bit) = FaultFlags::from_name(name) else {
                let known: Vec<&str> = FaultFlags::ALL.iter().map(|(_, n)| *n).collect();
                return Err(bad(
                    "rules.fault.flags",
                    format!("unknown flag '{name}' (known: {})", known.join(", ")),
                ));
            };
            mask |= bit;
        }
        let fault = r.fault.enabled.then(|| Faults {
            timing: Timing::new(r.fault.action, r.fault.trigger_ms, r.fault.release_ms),
            mask,
        });

        let b = &r.battery;
        check_timing("rules.battery", b.trigger_ms, b.release_ms)?;
        check_non_negative(
            "rules.battery",
            &[
                ("release_margin_pct", b.release_margin_pct),
                ("release_margin_v", b.release_margin_v),
            ],
        )?;
        check_positive(
            "rules.battery",
            &[
                ("min_soc_pct", b.min_soc_pct),
                ("min_voltage_v", b.min_voltage_v),
            ],
        )?;
        if b.min_soc_pct.is_some_and(|v| v > 100.0) {
            return Err(bad("rules.battery.min_soc_pct", "must be at most 100 %"));
        }
        let battery = b.enabled.then(|| Battery {
            timing: Timing::new(b.action, b.trigger_ms, b.release_ms),
            min_soc_pct: b.min_soc_pct,
            release_margin_pct: b.release_margin_pct,
            min_voltage_v: b.min_voltage_v,
            release_margin_v: b.release_margin_v,
        });

        let st = &r.stale;
        check_timing("rules.stale", st.trigger_ms, st.release_ms)?;
        for (key, v) in [
            ("rules.stale.service_timeout_ms", st.service_timeout_ms),
            ("rules.stale.chassis_timeout_ms", st.chassis_timeout_ms),
        ] {
            if !(20..=10_000).contains(&v) {
                return Err(bad(key, "must be 20 to 10000 ms"));
            }
        }
        let stale = st.enabled.then(|| Stale {
            timing: Timing::new(st.action, st.trigger_ms, st.release_ms),
            service_timeout_ns: ms_to_ns(st.service_timeout_ms),
            chassis_timeout_ns: ms_to_ns(st.chassis_timeout_ms),
        });

        let bu = &r.bumper;
        check_timing("rules.bumper", bu.trigger_ms, bu.release_ms)?;
        let bumper = bu
            .enabled
            .then(|| Timing::new(bu.action, bu.trigger_ms, bu.release_ms));

        let ultrasonic = r.ultrasonic.to_zones("rules.ultrasonic")?;
        let ir = r.ir.to_zones("rules.ir")?;

        let sp = &r.speed;
        check_timing("rules.speed", sp.trigger_ms, sp.release_ms)?;
        check_non_negative(
            "rules.speed",
            &[
                ("release_margin_mps", sp.release_margin_mps),
                ("limit_margin_mps", sp.limit_margin_mps),
            ],
        )?;
        check_positive("rules.speed", &[("max_linear_mps", sp.max_linear_mps)])?;
        if !(sp.limit_factor.is_finite() && (1.0..=3.0).contains(&sp.limit_factor)) {
            return Err(bad(
                "rules.speed.limit_factor",
                format!(
                    "must be 1 to 3 (is {}): below 1 the rule would stop a robot driving as \
                     fast as it may",
                    sp.limit_factor
                ),
            ));
        }
        let speed = sp.enabled.then(|| Speed {
            timing: Timing::new(sp.action, sp.trigger_ms, sp.release_ms),
            max_linear_mps: sp.max_linear_mps,
            limit_factor: sp.limit_factor,
            limit_margin_mps: sp.limit_margin_mps,
            release_margin_mps: sp.release_margin_mps,
        });

        let li = &r.limit;
        check_timing("rules.limit", li.trigger_ms, li.release_ms)?;
        check_non_negative("rules.limit", &[("margin_mps", li.margin_mps)])?;
        let limit = li.enabled.then(|| Limit {
            timing: Timing::new(li.action, li.trigger_ms, li.release_ms),
            margin_mps: li.margin_mps,
        });

        let mut categories = [None; SafetyRule::COUNT];
        for (name, &category) in &m.categories {
            let rule = SafetyRule::from_name(name).ok_or_else(|| {
                bad(
                    "monitor.categories",
                    format!(
                        "'{name}' is not a rule ({})",
                        SafetyRule::NAMES.map(|(_, n)| n).join(", ")
                    ),
                )
            })?;
            if category > 2 {
                return Err(bad(
                    "monitor.categories",
                    format!("{name} = {category}: a stop category is 0, 1 or 2"),
                ));
            }
            categories[usize::from(rule)] = Some(category);
        }
        let config = Config {
            publish_period_ns: ms_to_ns(m.publish_period_ms),
            evaluate_period_ns: ms_to_ns(m.evaluate_period_ms),
            status_period_ns: ms_to_ns(m.status_period_ms),
            lock: m.lock.clone(),
            categories,
            slow,
            fault,
            battery,
            stale,
            bumper,
            ultrasonic,
            ir,
            speed,
            operator: r.operator.enabled,
            plausibility: Plausibility::validate(
                &r.runaway,
                &r.direction,
                &r.following,
                &r.plausibility,
            )?,
            limit,
            file: None,
            raw: self,
        };
        // A category is what a latch engages the lock with: a rule that does not latch has none.
        if let Some(rule) = (0..SafetyRule::COUNT as u8).find(|&rule| {
            config.categories[usize::from(rule)].is_some()
                && config
                    .timing(rule)
                    .is_none_or(|t| t.action != Action::Latch)
        }) {
            return Err(bad(
                "monitor.categories",
                format!(
                    "{}: only a rule whose action is latch (and that is enabled) engages the lock",
                    SafetyRule::name(rule)
                ),
            ));
        }
        Ok(config)
    }
}

impl Config {
    /// The timing and action of `rule` (a [`SafetyRule`]), `None` while it is disabled.
    pub fn timing(&self, rule: u8) -> Option<Timing> {
        let c = self;
        match rule {
            SafetyRule::FAULT => c.fault.as_ref().map(|r| r.timing),
            SafetyRule::BATTERY => c.battery.as_ref().map(|r| r.timing),
            SafetyRule::STALE => c.stale.as_ref().map(|r| r.timing),
            SafetyRule::BUMPER => c.bumper,
            SafetyRule::ULTRASONIC => c.ultrasonic.as_ref().map(|r| r.timing),
            SafetyRule::IR => c.ir.as_ref().map(|r| r.timing),
            SafetyRule::SPEED => c.speed.as_ref().map(|r| r.timing),
            SafetyRule::OPERATOR => c.operator.then_some(Timing {
                action: Action::Latch,
                trigger_ns: 0,
                release_ns: 0,
            }),
            SafetyRule::RUNAWAY => c.plausibility.runaway,
            SafetyRule::DIRECTION => c.plausibility.direction,
            SafetyRule::FOLLOWING => c.plausibility.following,
            SafetyRule::LIMIT => c.limit.as_ref().map(|r| r.timing),
            _ => None,
        }
    }

    /// Reads, checks and validates a TOML file in the `--print-config` format, remembering
    /// which keys it sets.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        let parse_error = |source| ConfigError::Parse {
            path: path.display().to_string(),
            source,
        };
        let table: toml::Table = toml::from_str(&text).map_err(parse_error)?;
        let raw = RawConfig::parse(&text).map_err(parse_error)?;
        let mut config = raw.validate()?;
        config.file = Some(ConfigFile::of(path, &table));
        Ok(config)
    }

    /// The configuration as written, with every default filled in.
    pub(crate) fn raw(&self) -> &RawConfig {
        &self.raw
    }

    /// The defaults, every rule on.
    pub fn defaults() -> Result<Config, ConfigError> {
        RawConfig::default().validate()
    }

    /// The configuration as the file gives it (levels the file leaves to the description
    /// absent), one key per line: `crate::levels::print_config` annotates it.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(&self.raw)
    }

    /// Where the value of `key` (dotted) comes from when not from the description: the file
    /// that sets it, or the default.
    pub fn origin_of(&self, key: &str) -> Origin {
        match &self.file {
            Some(file) if file.sets(key) => Origin::Config(file.path.clone()),
            _ => Origin::Default,
        }
    }
}

/// Where a value a rule uses comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Origin {
    /// The monitor's own default.
    Default,
    /// The monitor's configuration file.
    Config(PathBuf),
    /// The robot's description: whose (`chassis/h1`), and which of its values.
    Description { robot: String, from: String },
    /// Nothing gives it, and why.
    Unknown(String),
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Origin::Default => f.write_str("default"),
            Origin::Config(path) => write!(f, "config ({})", path.display()),
            Origin::Description { robot, from } => write!(f, "description ({robot}: {from})"),
            Origin::Unknown(why) => write!(f, "unknown: {why}"),
        }
    }
}

#[cfg(test)]
pub(crate) fn loaded(tag: &str, text: &str) -> (Config, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("chassis-safety-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("safety.toml");
    std::fs::write(&path, text).unwrap();
    let config = Config::load(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    (config, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn defaults() -> Config {
        RawConfig::default().validate().unwrap()
    }

    #[test]
    fn an_empty_file_is_the_default_configuration_with_every_rule_on() {
        let c = RawConfig::parse("").unwrap().validate().unwrap();
        assert_eq!(c, defaults());
        assert_eq!(c.publish_period_ns, 50_000_000);
        assert!(c.fault.is_some() && c.battery.is_some() && c.stale.is_some());
        assert!(c.bumper.is_some() && c.ultrasonic.is_some() && c.ir.is_some());
        assert!(c.speed.is_some() && c.operator);
        assert_eq!(c.bumper.unwrap().action, Action::Latch);
        assert_eq!(c.stale.as_ref().unwrap().service_timeout_ns, 200_000_000);
        let us = c.ultrasonic.unwrap();
        assert_eq!((us.stop_m, us.slow_m), (0.35, 0.8));
        let ir = c.ir.unwrap();
        assert_eq!((ir.stop_m, ir.slow_m), (0.15, 0.3));
        assert_eq!(c.slow.linear_mps, 0.15);
    }

    #[test]
    fn the_default_fault_mask_is_every_non_warning_flag_but_the_bumper() {
        let c = defaults();
        let mask = c.fault.unwrap().mask;
        assert_eq!(mask & FaultFlags::WARNINGS, 0);
        assert_eq!(mask & FaultFlags::BUMPER, 0);
        assert_ne!(mask & FaultFlags::MOTOR_DRIVER_ERROR, 0);
        assert_ne!(mask & FaultFlags::EMERGENCY_STOP, 0);
    }

    #[test]
    fn a_partial_table_keeps_the_defaults_of_the_keys_it_leaves_out() {
        let c = RawConfig::parse(
            "[rules.ir]\nstop_m = 0.1\n[rules.battery]\nmin_voltage_v = 23\n\
             [rules.bumper]\naction = \"stop\"\n",
        )
        .unwrap()
        .validate()
        .unwrap();
        let ir = c.ir.unwrap();
        assert_eq!((ir.stop_m, ir.slow_m, ir.hysteresis_m), (0.1, 0.3, 0.03));
        let b = c.battery.unwrap();
        assert_eq!(
            b.min_voltage_v,
            Some(23.0),
            "a plain number, an integer too"
        );
        assert_eq!(b.min_soc_pct, None, "left to the description");
        assert_eq!(b.release_margin_v, 0.3);
        assert_eq!(c.bumper.unwrap().action, Action::Stop);
    }

    #[test]
    fn the_levels_are_left_to_the_description_unless_the_file_sets_them() {
        let c = defaults();
        assert_eq!(c.battery.unwrap().min_voltage_v, None);
        let s = c.speed.unwrap();
        assert_eq!(s.max_linear_mps, None);
        assert_eq!((s.limit_factor, s.limit_margin_mps), (1.1, 0.05));
        let c = RawConfig::parse("[rules.speed]\nmax_linear_mps = 2.0\nlimit_factor = 1.2\n")
            .unwrap()
            .validate()
            .unwrap();
        let s = c.speed.unwrap();
        assert_eq!((s.max_linear_mps, s.limit_factor), (Some(2.0), 1.2));
    }

    #[test]
    fn a_per_robot_table_of_earlier_versions_is_refused_with_what_replaced_it() {
        for text in [
            "[rules.battery.min_voltage_v]\nxbot = 23.0\n",
            "[rules.speed.max_linear_mps]\ntitan = 3.3\n",
            "[rules.battery]\nmin_soc_pct = \"15\"\n",
        ] {
            let err = RawConfig::parse(text).unwrap_err().to_string();
            assert!(err.contains("plain number"), "{text}: {err}");
            assert!(err.contains("description"), "{text}: {err}");
        }
    }

    #[test]
    fn a_loaded_file_says_which_keys_it_sets() {
        let (c, path) = loaded(
            "keys",
            "[rules.speed]\ntrigger_ms = 100\n[rules.battery]\nmin_voltage_v = 23.0\n",
        );
        let file = c.file.as_ref().unwrap();
        assert_eq!(
            file.keys.iter().map(String::as_str).collect::<Vec<_>>(),
            ["rules.battery.min_voltage_v", "rules.speed.trigger_ms"]
        );
        assert_eq!(
            c.origin_of("rules.speed.trigger_ms"),
            Origin::Config(path.clone())
        );
        assert_eq!(c.origin_of("rules.speed.release_ms"), Origin::Default);
        assert_eq!(c.speed.unwrap().timing.trigger_ns, 100_000_000);
    }

    #[test]
    fn unknown_keys_are_rejected() {
        for text in [
            "[rules.ultrasonic]\nstop_distance = 0.3\n",
            "[monitor]\nrate_hz = 50\n",
            "[rules.teleport]\nenabled = true\n",
            "[rules.speed]\nmax_speed = 2.0\n",
            "[rules.bumper]\naction = \"explode\"\n",
        ] {
            assert!(RawConfig::parse(text).is_err(), "{text} was accepted");
        }
    }

    #[test]
    fn bad_values_are_rejected_with_their_key() {
        let check = |text: &str, key: &str| {
            let err = RawConfig::parse(text).unwrap().validate().unwrap_err();
            assert!(err.to_string().starts_with(key), "{text}: {err}");
        };
        check(
            "[monitor]\npublish_period_ms = 250\n",
            "monitor.publish_period_ms",
        );
        check("[monitor]\nlock = \"E-Stop\"\n", "monitor.lock");
        check("[rules.ultrasonic]\nslow_m = 0.2\n", "rules.ultrasonic");
        check(
            "[rules.fault]\nflags = [\"gremlins\"]\n",
            "rules.fault.flags",
        );
        check("[rules.battery]\nmin_soc_pct = 150.0\n", "rules.battery");
        check("[slow]\nlinear_mps = -1.0\n", "slow");
        check("[rules.stale]\nservice_timeout_ms = 5\n", "rules.stale");
        check("[rules.speed]\nrelease_ms = 3600000\n", "rules.speed");
        check(
            "[rules.speed]\nlimit_factor = 0.9\n",
            "rules.speed.limit_factor",
        );
        check("[rules.speed]\nmax_linear_mps = 0\n", "rules.speed");
        check("[rules.battery]\nmin_voltage_v = -24.0\n", "rules.battery");
    }

    #[test]
    fn the_printed_configuration_reads_back_to_the_same() {
        let c = defaults();
        let text = c.to_toml().unwrap();
        assert!(text.contains("[rules.ultrasonic]"), "{text}");
        assert!(
            !text.contains("min_voltage_v"),
            "left to the description: {text}"
        );
        let again = RawConfig::parse(&text).unwrap().validate().unwrap();
        assert_eq!(again, c);
        assert_eq!(again.to_toml().unwrap(), text);
        let set = RawConfig::parse("[rules.battery]\nmin_voltage_v = 23.0\n")
            .unwrap()
            .validate()
            .unwrap();
        let text = set.to_toml().unwrap();
        assert!(text.contains("min_voltage_v = 23.0"), "{text}");
        assert_eq!(RawConfig::parse(&text).unwrap().validate().unwrap(), set);
    }

    #[test]
    fn a_disabled_rule_is_absent() {
        let c =
            RawConfig::parse("[rules.speed]\nenabled = false\n[rules.operator]\nenabled = false\n")
                .unwrap()
                .validate()
                .unwrap();
        assert!(c.speed.is_none());
        assert!(!c.operator);
    }
}
