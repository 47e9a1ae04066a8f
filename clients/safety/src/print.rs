//! `chassis-safety --print-config`: the effective configuration in the file's format, every
//! value with where it comes from — `default`, `config (FILE)`, or `description (ROBOT: …)`.
//!
//! The levels the speed and battery rules take from the robot's description are printed
//! commented out: a file made from this output keeps following the robot (another robot, a
//! `[profile]` override in chassisd's config), and uncommenting one overrides it. Where no
//! description was read the levels say they are unknown, and why.

use crate::config::Config;
use crate::config::Origin;
use crate::levels::{Level, Levels, number};

/// The configuration `config` with the levels `levels`, annotated; `about` are comment lines
/// saying which robot the levels are for.
pub fn print_config(
    config: &Config,
    levels: &Levels,
    about: &[String],
) -> Result<String, toml::ser::Error> {
    let text = config.to_toml()?;
    let mut out = String::new();
    for line in [
        "chassis-safety: the effective configuration, in the file's format (--config FILE).",
        "Beside each value, where it comes from: `default`, `config (FILE)`, or `description",
        "(ROBOT: …)` — the robot's description as its chassisd publishes it (its [profile] and",
        "[mux.limits] after every override). Levels from the description are commented out: a",
        "file made from this keeps following the robot; uncomment one to override it there.",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain(about.iter().cloned())
    {
        push_comment(&mut out, &line);
    }
    out.push('\n');
    let mut table = String::new();
    for line in text.lines() {
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            table = name.to_string();
            out.push_str(line);
            out.push('\n');
            described_levels(&mut out, &table, levels);
            continue;
        }
        match line.split_once(" = ") {
            Some((key, _)) => {
                let dotted = format!("{table}.{key}");
                let origin = match override_of(&dotted, levels) {
                    Some(level) => overridden(level),
                    None => config.origin_of(&dotted).to_string(),
                };
                out.push_str(&format!("{line}  # {origin}\n"));
            }
            None => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    Ok(out)
}

fn push_comment(out: &mut String, line: &str) {
    if line.is_empty() {
        out.push_str("#\n");
    } else {
        out.push_str(&format!("# {line}\n"));
    }
}

/// The level a key of the file overrides, if it is one.
fn override_of<'a>(key: &str, levels: &'a Levels) -> Option<&'a Level> {
    match key {
        "rules.speed.max_linear_mps" => Some(&levels.speed_forward_mps),
        "rules.battery.min_soc_pct" => Some(&levels.battery_soc_pct),
        "rules.battery.min_voltage_v" => Some(&levels.battery_voltage_v),
        _ => None,
    }
}

/// An override's origin, with what the description would give.
fn overridden(level: &Level) -> String {
    match &level.described {
        Some((value, origin)) => {
            format!("{}; without it {} — {origin}", level.origin, number(*value))
        }
        None => level.origin.to_string(),
    }
}

/// The levels of `table` that come from the description (or nowhere), commented out.
fn described_levels(out: &mut String, table: &str, levels: &Levels) {
    let from_description = |l: &Level| !matches!(l.origin, Origin::Config(_));
    let line = |out: &mut String, key: &str, l: &Level| match l.value {
        Some(v) => out.push_str(&format!("# {key} = {}  # {}\n", number(v), l.origin)),
        None => out.push_str(&format!("# {key}: {}\n", l.origin)),
    };
    match table {
        "rules.speed" => {
            let (f, r) = (&levels.speed_forward_mps, &levels.speed_reverse_mps);
            if from_description(f) {
                line(out, "max_linear_mps", f);
                if r.value != f.value {
                    match r.value {
                        Some(v) => out.push_str(&format!(
                            "#   in reverse: {}  # {}\n",
                            number(v),
                            r.origin
                        )),
                        None => out.push_str(&format!("#   in reverse: {}\n", r.origin)),
                    }
                }
            }
        }
        "rules.battery" => {
            for (key, l) in [
                ("min_soc_pct", &levels.battery_soc_pct),
                ("min_voltage_v", &levels.battery_voltage_v),
            ] {
                if from_description(l) {
                    line(out, key, l);
                }
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RawConfig;
    use chassis_protocols::RobotKind;
    use chassis_protocols::description::describe;

    fn hunter() -> chassis_client::RobotDescription {
        describe(&RobotKind::Hunter.entry().defaults())
    }

    #[test]
    fn every_value_says_where_it_comes_from_and_the_descriptions_levels_are_commented_out() {
        let config = Config::defaults().unwrap();
        let levels = Levels::resolve(&config, Some(&hunter()), "chassis/h1");
        let text = print_config(&config, &levels, &["Robot: a test.".into()]).unwrap();
        assert!(
            text.contains("\n# min_voltage_v = 24.5  # description (chassis/h1: battery.low_v)\n"),
            "{text}"
        );
        assert!(
            text.contains(
                "\n# max_linear_mps = 1.7  # description (chassis/h1: forward limit 1.5 m/s \
                 (the driver's limit) × limit_factor 1.1 + limit_margin_mps 0.05)\n"
            ),
            "{text}"
        );
        assert!(
            text.contains("\n# min_soc_pct: unknown: no battery.low_soc_pct"),
            "{text}"
        );
        assert!(text.contains("\ntrigger_ms = 200  # default\n"), "{text}");
        // Every line that is not a comment says where its value comes from.
        for line in text
            .lines()
            .filter(|l| l.contains(" = ") && !l.starts_with('#'))
        {
            assert!(line.ends_with("  # default"), "{line}");
        }
        // It reads back to the same configuration, still following the robot.
        let again = RawConfig::parse(&text).unwrap().validate().unwrap();
        assert_eq!(again, config);
    }

    #[test]
    fn a_value_of_the_file_names_the_file_and_what_the_description_would_give() {
        let (config, path) = crate::config::loaded(
            "print",
            "[rules.battery]\nmin_voltage_v = 23.0\n[rules.speed]\ntrigger_ms = 100\n",
        );
        let levels = Levels::resolve(&config, Some(&hunter()), "chassis/h1");
        let text = print_config(&config, &levels, &[]).unwrap();
        let file = path.display();
        assert!(
            text.contains(&format!(
                "\nmin_voltage_v = 23.0  # config ({file}); without it 24.5 — description \
                 (chassis/h1: battery.low_v)\n"
            )),
            "{text}"
        );
        assert!(
            text.contains(&format!("\ntrigger_ms = 100  # config ({file})\n")),
            "{text}"
        );
        assert!(!text.contains("# min_voltage_v ="), "{text}");
    }

    #[test]
    fn without_a_description_the_levels_say_they_are_unknown_until_it_is_read() {
        let config = Config::defaults().unwrap();
        let levels = Levels::resolve(&config, None, "chassis/h1");
        let text = print_config(&config, &levels, &[]).unwrap();
        assert!(
            text.contains("\n# max_linear_mps: unknown: until chassis/h1's description is read\n"),
            "{text}"
        );
        assert!(
            text.contains("\n# min_voltage_v: unknown: until chassis/h1's description is read\n"),
            "{text}"
        );
    }
}
