//! The monitor's configuration: TOML → [`RawConfig`] (every key defaulted, unknown keys
//! rejected) → one validated [`Config`] with times in ns. `chassis-safety --print-config` prints
//! the effective configuration in the file's format.
//!
//! Every rule has `enabled`, its thresholds, an `action` (`slow`, `stop` or `latch`), and a
//! release condition: a margin past the threshold the measurement must cross back over
//! (hysteresis), and `release_ms`, how long it must stay there. `trigger_ms` is how long a
//! condition must hold before the rule acts (0: at once).

use std::path::Path;

use chassis_client::{FaultFlags, RobotKind, valid_robot_name};
use serde::{Deserialize, Serialize};
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
}

impl Default for MonitorConfig {
    fn default() -> Self {
        Self {
            publish_period_ms: 50,
            evaluate_period_ms: 20,
            status_period_ms: 100,
            lock: "estop".into(),
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

/// Battery voltages per robot, V (0: no voltage rule for that robot).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BatteryVoltages {
    pub titan: f64,
    #[serde(rename = "scout-mini")]
    pub scout_mini: f64,
    pub xbot: f64,
}

impl Default for BatteryVoltages {
    /// 15 % of each pack's open-circuit range as the simulated chassis models it from the
    /// manuals: TITAN 44.0-52.0 V, SCOUT MINI 21.0-29.2 V, XBot 23.0-26.0 V.
    fn default() -> Self {
        Self {
            titan: 45.2,
            scout_mini: 22.2,
            xbot: 23.45,
        }
    }
}

impl BatteryVoltages {
    fn of(&self, robot: u8) -> f64 {
        match robot {
            RobotKind::TITAN => self.titan,
            RobotKind::SCOUT_MINI => self.scout_mini,
            RobotKind::XBOT => self.xbot,
            _ => 0.0,
        }
    }
}

/// `[rules.battery]`: state of charge from the BMS, or the voltage where there is none.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BatteryRule {
    pub enabled: bool,
    pub action: Action,
    /// Triggers below this state of charge, % (robots with a BMS: TITAN).
    pub min_soc_pct: f64,
    /// Releases at or above `min_soc_pct` + this, %.
    pub release_margin_pct: f64,
    /// Triggers below this voltage where the robot reports no state of charge.
    pub min_voltage_v: BatteryVoltages,
    /// Releases at or above `min_voltage_v` + this, V.
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
            min_soc_pct: 15.0,
            release_margin_pct: 5.0,
            min_voltage_v: BatteryVoltages::default(),
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
                let bad = |reason: &str| ConfigError::Bad {
                    key: key.into(),
                    reason: reason.into(),
                };
                if !(self.stop_m.is_finite() && self.slow_m.is_finite() && self.stop_m >= 0.0) {
                    return Err(bad("stop_m and slow_m must be finite and not negative"));
                }
                if self.slow_m < self.stop_m {
                    return Err(bad("slow_m must be at least stop_m"));
                }
                if !(self.hysteresis_m.is_finite() && self.hysteresis_m >= 0.0) {
                    return Err(bad("hysteresis_m must be finite and not negative"));
                }
                if self.max_age_ms == 0 {
                    return Err(bad("max_age_ms must be above 0"));
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

/// Speed limits per robot, m/s (0: no speed rule for that robot).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpeedLimits {
    pub titan: f64,
    #[serde(rename = "scout-mini")]
    pub scout_mini: f64,
    pub xbot: f64,
}

impl Default for SpeedLimits {
    /// Each robot's top speed from its manual + 10 %: faster means a runaway (downhill, a
    /// failing speed loop, bad feedback), never a request.
    fn default() -> Self {
        Self {
            titan: 3.3,
            scout_mini: 6.1,
            xbot: 1.65,
        }
    }
}

impl SpeedLimits {
    fn of(&self, robot: u8) -> f64 {
        match robot {
            RobotKind::TITAN => self.titan,
            RobotKind::SCOUT_MINI => self.scout_mini,
            RobotKind::XBOT => self.xbot,
            _ => 0.0,
        }
    }
}

/// `[rules.speed]`: measured |linear speed| above a limit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SpeedRule {
    pub enabled: bool,
    pub action: Action,
    pub max_linear_mps: SpeedLimits,
    /// Releases below the limit − this, m/s.
    pub release_margin_mps: f64,
    pub trigger_ms: u64,
    pub release_ms: u64,
}

impl Default for SpeedRule {
    fn default() -> Self {
        Self {
            enabled: true,
            action: Action::Stop,
            max_linear_mps: SpeedLimits::default(),
            release_margin_mps: 0.2,
            trigger_ms: 200,
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
    fn new(action: Action, trigger_ms: u64, release_ms: u64) -> Self {
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

/// The validated battery rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    pub timing: Timing,
    pub min_soc_pct: f64,
    pub release_margin_pct: f64,
    pub min_voltage_v: BatteryVoltages,
    pub release_margin_v: f64,
}

impl Battery {
    /// The voltage threshold for a robot kind (0: none).
    pub fn min_voltage_v(&self, robot: u8) -> f64 {
        self.min_voltage_v.of(robot)
    }
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

/// The validated speed rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Speed {
    pub timing: Timing,
    pub max_linear_mps: SpeedLimits,
    pub release_margin_mps: f64,
}

impl Speed {
    /// The limit for a robot kind (0: none).
    pub fn max_linear_mps(&self, robot: u8) -> f64 {
        self.max_linear_mps.of(robot)
    }
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
    pub slow: SlowSpeeds,
    pub fault: Option<Faults>,
    pub battery: Option<Battery>,
    pub stale: Option<Stale>,
    pub bumper: Option<Timing>,
    pub ultrasonic: Option<RangeZones>,
    pub ir: Option<RangeZones>,
    pub speed: Option<Speed>,
    pub operator: bool,
    raw: RawConfig,
}

pub(crate) fn ms_to_ns(ms: u64) -> u64 {
    ms.saturating_mul(1_000_000)
}

/// Longest `trigger_ms` / `release_ms`.
const MAX_DELAY_MS: u64 = 60_000;

fn bad(key: &str, reason: impl Into<String>) -> ConfigError {
    ConfigError::Bad {
        key: key.into(),
        reason: reason.into(),
    }
}

fn check_timing(key: &str, trigger_ms: u64, release_ms: u64) -> Result<(), ConfigError> {
    if trigger_ms > MAX_DELAY_MS || release_ms > MAX_DELAY_MS {
        return Err(bad(
            key,
            format!("trigger_ms and release_ms must be at most {MAX_DELAY_MS}"),
        ));
    }
    Ok(())
}

fn check_non_negative(key: &str, values: &[(&str, f64)]) -> Result<(), ConfigError> {
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
    /// Reads a TOML file in the `--print-config` format.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text).map_err(|source| ConfigError::Parse {
            path: path.display().to_string(),
            source,
        })
    }

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
                ("min_soc_pct", b.min_soc_pct),
                ("release_margin_pct", b.release_margin_pct),
                ("release_margin_v", b.release_margin_v),
                ("min_voltage_v.titan", b.min_voltage_v.titan),
                ("min_voltage_v.scout-mini", b.min_voltage_v.scout_mini),
                ("min_voltage_v.xbot", b.min_voltage_v.xbot),
            ],
        )?;
        if b.min_soc_pct > 100.0 {
            return Err(bad("rules.battery.min_soc_pct", "must be at most 100 %"));
        }
        let battery = b.enabled.then(|| Battery {
            timing: Timing::new(b.action, b.trigger_ms, b.release_ms),
            min_soc_pct: b.min_soc_pct,
            release_margin_pct: b.release_margin_pct,
            min_voltage_v: b.min_voltage_v.clone(),
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

        check_timing(
            "rules.ultrasonic",
            r.ultrasonic.trigger_ms,
            r.ultrasonic.release_ms,
        )?;
        let ultrasonic = r.ultrasonic.to_zones("rules.ultrasonic")?;
        check_timing("rules.ir", r.ir.trigger_ms, r.ir.release_ms)?;
        let ir = r.ir.to_zones("rules.ir")?;

        let sp = &r.speed;
        check_timing("rules.speed", sp.trigger_ms, sp.release_ms)?;
        check_non_negative(
            "rules.speed",
            &[
                ("release_margin_mps", sp.release_margin_mps),
                ("max_linear_mps.titan", sp.max_linear_mps.titan),
                ("max_linear_mps.scout-mini", sp.max_linear_mps.scout_mini),
                ("max_linear_mps.xbot", sp.max_linear_mps.xbot),
            ],
        )?;
        let speed = sp.enabled.then(|| Speed {
            timing: Timing::new(sp.action, sp.trigger_ms, sp.release_ms),
            max_linear_mps: sp.max_linear_mps.clone(),
            release_margin_mps: sp.release_margin_mps,
        });

        Ok(Config {
            publish_period_ns: ms_to_ns(m.publish_period_ms),
            evaluate_period_ns: ms_to_ns(m.evaluate_period_ms),
            status_period_ns: ms_to_ns(m.status_period_ms),
            lock: m.lock.clone(),
            slow,
            fault,
            battery,
            stale,
            bumper,
            ultrasonic,
            ir,
            speed,
            operator: r.operator.enabled,
            raw: self,
        })
    }
}

impl Config {
    /// The configuration with everything filled in, in the file's format.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(&self.raw)
    }
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
            "[rules.ir]\nstop_m = 0.1\n[rules.battery.min_voltage_v]\nxbot = 23.0\n\
             [rules.bumper]\naction = \"stop\"\n",
        )
        .unwrap()
        .validate()
        .unwrap();
        let ir = c.ir.unwrap();
        assert_eq!((ir.stop_m, ir.slow_m, ir.hysteresis_m), (0.1, 0.3, 0.03));
        let b = c.battery.unwrap();
        assert_eq!(b.min_voltage_v(RobotKind::XBOT), 23.0);
        assert_eq!(b.min_voltage_v(RobotKind::TITAN), 45.2);
        assert_eq!(c.bumper.unwrap().action, Action::Stop);
    }

    #[test]
    fn unknown_keys_are_rejected() {
        for text in [
            "[rules.ultrasonic]\nstop_distance = 0.3\n",
            "[monitor]\nrate_hz = 50\n",
            "[rules.teleport]\nenabled = true\n",
            "[rules.speed.max_linear_mps]\nscout_mini = 2.0\n",
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
    }

    #[test]
    fn the_printed_configuration_reads_back_to_the_same() {
        let c = defaults();
        let text = c.to_toml().unwrap();
        assert!(text.contains("[rules.ultrasonic]"), "{text}");
        assert!(text.contains("scout-mini = "), "{text}");
        let again = RawConfig::parse(&text).unwrap().validate().unwrap();
        assert_eq!(again, c);
        assert_eq!(again.to_toml().unwrap(), text);
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
