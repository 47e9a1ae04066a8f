//! The levels of the speed and battery rules, and where each comes from.
//!
//! The monitor knows no robot. It reads the description chassisd publishes for the robot it
//! drives (`chassis/<name>/robot`: the profile and the configured limits after every override,
//! the protocol once detected) and takes its levels from there:
//!
//! * **speed**: the rule acts above the description's effective limit (the tighter of the
//!   driver's `robot_limits` and chassisd's `[mux.limits]`), forward and reverse each,
//!   × `[rules.speed] limit_factor` + `limit_margin_mps` (1.1 and 0.05 m/s by default);
//! * **battery**: below the description's state-of-charge level where the robot reports a state
//!   of charge and the description gives one (`battery.low_soc_pct`, the chassis' own
//!   low-battery warning), else below its voltage level (`battery.low_v`, the under-voltage
//!   alarm); where a robot states only the level at which it cuts power (`critical_*`), that
//!   one.
//!
//! A plain number in the monitor's file (`[rules.battery] min_voltage_v = 23.0`,
//! `[rules.speed] max_linear_mps = 2.0`) wins over the description. A level nothing gives is
//! [`Origin::Unknown`], and [`Levels::warnings`] says so, naming the rule and the robot: a rule
//! is never silently absent.

use std::path::PathBuf;

use chassis_client::{BatteryLevels, MotionLimits, RobotDescription};

use crate::config::{Config, Origin};

/// A level a rule triggers at.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// The level in force; `None` when nothing gives one.
    pub value: Option<f64>,
    pub origin: Origin,
    /// What the description gives, where the file overrides it.
    pub described: Option<(f64, Origin)>,
}

impl Level {
    fn unknown(why: String) -> Self {
        Self {
            value: None,
            origin: Origin::Unknown(why),
            described: None,
        }
    }

    /// The file's value where it sets one, else the description's.
    fn overridden_by(self, value: Option<f64>, config: &Config, key: &str) -> Self {
        let Some(value) = value else {
            return self;
        };
        let origin = match &config.file {
            Some(file) => Origin::Config(file.path.clone()),
            None => Origin::Config(PathBuf::from(key)),
        };
        Self {
            value: Some(value),
            origin,
            described: self.value.map(|v| (v, self.origin)),
        }
    }
}

/// A number as a person writes it: at most three decimals, no trailing zeros (`0.6`, `24.5`,
/// `15.0`).
pub fn number(v: f64) -> String {
    let text = format!("{v:.3}");
    let trimmed = text.trim_end_matches('0');
    if trimmed.ends_with('.') {
        format!("{trimmed}0")
    } else {
        trimmed.to_string()
    }
}

/// The robot the levels were resolved for.
#[derive(Debug, Clone, PartialEq)]
pub struct DescribedRobot {
    /// How the origins name it: `chassis/h1`, or `hunter defaults`.
    pub label: String,
    /// `AgileX HUNTER 2.0`.
    pub display_name: String,
    /// `hunter`.
    pub kind_name: String,
    /// The description's `seq`.
    pub seq: u64,
}

/// The levels of the speed and battery rules.
#[derive(Debug, Clone, PartialEq)]
pub struct Levels {
    /// The robot whose description they come from; `None` before one was read.
    pub robot: Option<DescribedRobot>,
    /// The speed rule acts above this forward speed, m/s…
    pub speed_forward_mps: Level,
    /// …and above this reverse speed (a positive number), m/s.
    pub speed_reverse_mps: Level,
    /// The battery rule's state-of-charge level, %.
    pub battery_soc_pct: Level,
    /// The battery rule's voltage level, V.
    pub battery_voltage_v: Level,
}

/// Which reading the battery rule judges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BatteryBasis {
    /// The state of charge (the robot reports one and there is a level for it).
    Soc,
    /// The voltage.
    Voltage,
}

impl Levels {
    /// The levels for `description` (named `label` in every origin), or the file's alone when
    /// there is none yet (`label` then names the robot it waits for).
    pub fn resolve(config: &Config, description: Option<&RobotDescription>, label: &str) -> Self {
        let raw = config.raw();
        let speed = &raw.rules.speed;
        let battery = &raw.rules.battery;
        let waiting = || format!("until {label}'s description is read");
        let from_description = |value: f64, from: String| Level {
            value: Some(value),
            origin: Origin::Description {
                robot: label.to_string(),
                from,
            },
            described: None,
        };

        let speed_level = |pick: fn(&MotionLimits) -> f64, way: &str| match description {
            None => Level::unknown(waiting()),
            Some(d) => {
                let limit = pick(&d.effective_limits());
                if limit.is_finite() && limit > 0.0 {
                    let whose = if pick(&d.configured_limits) == limit {
                        "chassisd's [mux.limits]"
                    } else {
                        "the driver's limit"
                    };
                    from_description(
                        limit * speed.limit_factor + speed.limit_margin_mps,
                        format!(
                            "{way} limit {} m/s ({whose}) × limit_factor {} + \
                             limit_margin_mps {}",
                            number(limit),
                            number(speed.limit_factor),
                            number(speed.limit_margin_mps)
                        ),
                    )
                } else {
                    Level::unknown(format!("no {way} limit in {label}'s description"))
                }
            }
        };
        let (max, key) = (speed.max_linear_mps, "rules.speed.max_linear_mps");
        let speed_forward_mps =
            speed_level(|l| l.forward_mps, "forward").overridden_by(max, config, key);
        let speed_reverse_mps =
            speed_level(|l| l.reverse_mps, "reverse").overridden_by(max, config, key);

        // The chassis' warning level first; where a robot states only the level at which it
        // cuts power, that one.
        let battery_level = |pick: fn(&BatteryLevels) -> (f64, f64),
                             [low_name, critical_name]: [&str; 2]| {
            let (low, critical) = description.map_or((f64::NAN, f64::NAN), |d| pick(&d.battery));
            let usable = |v: f64| v.is_finite() && v > 0.0;
            match description {
                None => Level::unknown(waiting()),
                Some(_) if usable(low) => from_description(low, format!("battery.{low_name}")),
                Some(_) if usable(critical) => from_description(
                    critical,
                    format!("battery.{critical_name}, as it gives no {low_name}"),
                ),
                Some(_) => Level::unknown(format!(
                    "no battery.{low_name} or battery.{critical_name} in {label}'s description"
                )),
            }
        };
        let battery_soc_pct = battery_level(
            |b| (b.low_soc_pct, b.critical_soc_pct),
            ["low_soc_pct", "critical_soc_pct"],
        )
        .overridden_by(battery.min_soc_pct, config, "rules.battery.min_soc_pct");
        let battery_voltage_v = battery_level(|b| (b.low_v, b.critical_v), ["low_v", "critical_v"])
            .overridden_by(battery.min_voltage_v, config, "rules.battery.min_voltage_v");

        Self {
            robot: description.map(|d| DescribedRobot {
                label: label.to_string(),
                display_name: d.display_name().to_string(),
                kind_name: d.kind_name().to_string(),
                seq: d.seq,
            }),
            speed_forward_mps,
            speed_reverse_mps,
            battery_soc_pct,
            battery_voltage_v,
        }
    }

    /// What the robot is called in a message: `chassis/h1 (AgileX HUNTER 2.0)`.
    fn robot_text(&self, label: &str) -> String {
        match &self.robot {
            Some(r) => format!("{} ({})", r.label, r.display_name),
            None => label.to_string(),
        }
    }

    /// A level an enabled rule needs and nothing gives, one line per rule, naming the rule and
    /// the robot (logged at WARN when a description is read). `label` names the robot when no
    /// description was read.
    pub fn warnings(&self, config: &Config, label: &str) -> Vec<String> {
        let robot = self.robot_text(label);
        let mut out = Vec::new();
        if config.speed.is_some() {
            let missing: Vec<&str> = [
                ("forward", &self.speed_forward_mps),
                ("reverse", &self.speed_reverse_mps),
            ]
            .into_iter()
            .filter(|(_, l)| l.value.is_none())
            .map(|(way, _)| way)
            .collect();
            if !missing.is_empty() {
                let why = match &self.speed_forward_mps.origin {
                    Origin::Unknown(why) if self.speed_forward_mps.value.is_none() => why.clone(),
                    _ => match &self.speed_reverse_mps.origin {
                        Origin::Unknown(why) => why.clone(),
                        other => other.to_string(),
                    },
                };
                out.push(format!(
                    "speed rule: no {} limit for {robot} ({why}): a runaway that way goes \
                     unnoticed; set [rules.speed] max_linear_mps in the monitor's file",
                    missing.join(" or ")
                ));
            }
        }
        if config.battery.is_some()
            && self.battery_soc_pct.value.is_none()
            && self.battery_voltage_v.value.is_none()
        {
            let why = match &self.battery_voltage_v.origin {
                Origin::Unknown(why) => why.clone(),
                other => other.to_string(),
            };
            out.push(format!(
                "battery rule: no level for {robot} ({why}): a flat battery goes unnoticed; set \
                 [rules.battery] min_voltage_v or min_soc_pct in the monitor's file"
            ));
        }
        out
    }

    /// The levels in words, one line per rule (logged at INFO).
    pub fn summary(&self, config: &Config) -> Vec<String> {
        let mut out = Vec::new();
        let level = |l: &Level, unit: &str| match l.value {
            Some(v) => format!("{} {unit} — {}", number(v), l.origin),
            None => format!("none — {}", l.origin),
        };
        if config.speed.is_some() {
            let (f, r) = (&self.speed_forward_mps, &self.speed_reverse_mps);
            if f.value == r.value {
                out.push(match f.value {
                    Some(v) => format!(
                        "speed rule: acts above {} m/s either way — {}",
                        number(v),
                        f.origin
                    ),
                    None => format!("speed rule: no limit — {}", f.origin),
                });
            } else {
                out.push(format!(
                    "speed rule: acts above {} forward, above {} reverse",
                    level(f, "m/s"),
                    level(r, "m/s")
                ));
            }
        }
        if config.battery.is_some() {
            let (soc, volt) = (&self.battery_soc_pct, &self.battery_voltage_v);
            out.push(match (soc.value, volt.value) {
                (Some(_), Some(_)) => format!(
                    "battery rule: where the robot reports a state of charge, below {}; else \
                     voltage below {}",
                    level(soc, "%"),
                    level(volt, "V")
                ),
                (Some(_), None) => format!(
                    "battery rule: state of charge below {}; no voltage level ({})",
                    level(soc, "%"),
                    volt.origin
                ),
                (None, Some(_)) => format!(
                    "battery rule: voltage below {} (no state-of-charge level: the voltage is \
                     judged even where the robot reports a state of charge)",
                    level(volt, "V")
                ),
                (None, None) => format!("battery rule: no level ({})", volt.origin),
            });
        }
        out
    }

    /// The speed above which the rule acts in the direction of `linear_mps` (NaN: forward).
    pub fn speed_limit(&self, linear_mps: f64) -> Option<f64> {
        if linear_mps < 0.0 {
            self.speed_reverse_mps.value
        } else {
            self.speed_forward_mps.value
        }
    }

    /// What the battery rule judges, given what the robot reports: the state of charge where
    /// it reports one and there is a level for it, else the voltage where there is a level.
    pub fn battery_basis(&self, reports_soc: bool, reports_voltage: bool) -> Option<BatteryBasis> {
        if reports_soc && self.battery_soc_pct.value.is_some() {
            Some(BatteryBasis::Soc)
        } else if reports_voltage && self.battery_voltage_v.value.is_some() {
            Some(BatteryBasis::Voltage)
        } else {
            None
        }
    }
}
