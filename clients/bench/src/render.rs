//! The performance document: its words are `clients/bench/performance.md`, whose `{{name}}`s this
//! fills from a run's samples (a [`Report`]) and its verdict, nothing typed by hand. A
//! `{{name}}` alone on its line stands for a block of lines, none when the block is empty.

use crate::baseline::HYBRID_SPIN;
use crate::parts::Whose;
use crate::paths::{
    BENCH_CONFIG, COMMAND_INTERVAL, REALTIME_PRIORITY, STATE_REQUEST_INTERVAL,
    XBOT_COMMAND_INTERVAL, off_grid, period_text,
};
use crate::report::{
    DEFAULT_CONFIG_ROW, LoopRun, MIN_FOR_P99, MIN_FOR_P999, Report, SUM_TOLERANCE, TOGETHER_CODE,
    TOGETHER_OUTSIDE, percentile, whose_text,
};
use crate::stats::Summary;

const TEMPLATE: &str = include_str!("../performance.md");

/// The performance document of `report`.
pub fn document(report: &Report) -> anyhow::Result<String> {
    let p = &report.provenance;
    let m = &report.machine;
    let values = [
        ("date", p.date.clone()),
        ("commit", p.commit_text()),
        ("cpu_model", m.cpu_model.clone()),
        ("cpus", m.cpus.to_string()),
        ("kernel", m.kernel.clone()),
        ("steal", p.steal_text()),
        ("command", p.command.clone()),
        ("bench_config", BENCH_CONFIG.trim_end().to_string()),
        ("priority", REALTIME_PRIORITY.to_string()),
        ("scheduling", report.scheduling_text()),
        ("default_config_row", DEFAULT_CONFIG_ROW.to_string()),
        ("table", table(report)),
        ("inconsistent", inconsistent(report)),
        ("conditions", conditions(report)),
        ("stalls", report.stalls_text()),
        ("targets", targets(report)?),
        ("parts", parts(report)),
        ("loops", loops(report)),
        ("cost", cost(report)),
        ("throughput", throughput_and_notes(report)),
        (
            "payload_bytes",
            size_of::<chassis_client::ChassisState>().to_string(),
        ),
        ("hybrid_spin_us", HYBRID_SPIN.as_micros().to_string()),
        ("command_period", period_text(off_grid(COMMAND_INTERVAL))),
        (
            "xbot_command_period",
            period_text(off_grid(XBOT_COMMAND_INTERVAL)),
        ),
        (
            "command_interval_ms",
            COMMAND_INTERVAL.as_millis().to_string(),
        ),
        (
            "state_request_interval_ms",
            STATE_REQUEST_INTERVAL.as_millis().to_string(),
        ),
        ("sum_tolerance_pct", format!("{}", SUM_TOLERANCE * 100.0)),
        ("min_for_p99", MIN_FOR_P99.to_string()),
        ("min_for_p999", MIN_FOR_P999.to_string()),
    ];
    fill(TEMPLATE, &values)
}

/// `template` with each `{{name}}` replaced by its value in `values`: a name with no value is
/// an error, and so is a value the template never names.
pub(crate) fn fill(template: &str, values: &[(&str, String)]) -> anyhow::Result<String> {
    let value = |name: &str| {
        values
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| v.as_str())
            .ok_or_else(|| anyhow::anyhow!("the document names {{{{{name}}}}}, which has no value"))
    };
    let mut out = String::new();
    for line in template.lines() {
        if let Some(name) = line.strip_prefix("{{").and_then(|l| l.strip_suffix("}}"))
            && !name.contains("{{")
        {
            let block = value(name)?;
            if !block.is_empty() {
                out.push_str(block);
                out.push('\n');
            }
            continue;
        }
        let mut rest = line;
        while let Some(start) = rest.find("{{") {
            let end = rest[start..]
                .find("}}")
                .ok_or_else(|| anyhow::anyhow!("an unclosed {{{{ in the document: {line}"))?;
            out.push_str(&rest[..start]);
            out.push_str(value(&rest[start + 2..start + end])?);
            rest = &rest[start + end + 2..];
        }
        out.push_str(rest);
        out.push('\n');
    }
    if let Some((name, _)) = values
        .iter()
        .find(|(name, _)| !template.contains(&format!("{{{{{name}}}}}")))
    {
        anyhow::bail!("the document never names {{{{{name}}}}}");
    }
    Ok(out)
}

/// The table's rows.
fn table(report: &Report) -> String {
    let rows: Vec<String> = report
        .rows
        .iter()
        .map(|r| {
            let ratio = match (r.ratio_p50, r.ratio_p99) {
                (Some(x), Some(y)) => format!("{x:.2}, {y:.2}"),
                (Some(x), None) => format!("{x:.2}, —"),
                _ => String::new(),
            };
            let flag = if r.inconsistent.is_some() {
                " **inconsistent**"
            } else {
                ""
            };
            format!(
                "| {} | {} | {} | {} | {} | {ratio}{flag} | {} |",
                r.path,
                r.what,
                r.mode,
                r.placement,
                r.figures().join(" | "),
                r.baseline.as_deref().unwrap_or("")
            )
        })
        .collect();
    rows.join("\n")
}

/// The rows flagged inconsistent, with why, or nothing.
fn inconsistent(report: &Report) -> String {
    let flagged: Vec<String> = report
        .rows
        .iter()
        .filter_map(|r| {
            let why = r.inconsistent.as_deref()?;
            Some(format!(
                "* {} {} ({} loop, {}): {why}",
                r.path, r.what, r.mode, r.placement
            ))
        })
        .collect();
    if flagged.is_empty() {
        return String::new();
    }
    format!(
        "**Inconsistent measurements** (flagged by the benchmark):\n\n{}\n",
        flagged.join("\n")
    )
}

/// Each baseline's conditions.
fn conditions(report: &Report) -> String {
    let lines: Vec<String> = report
        .rows
        .iter()
        .filter_map(|r| {
            Some(format!(
                "* {}, {}: {}",
                r.what,
                r.placement,
                r.conditions.as_ref()?
            ))
        })
        .collect();
    lines.join("\n")
}

/// The targets' rows: each target, what this run measured, and its outcome.
fn targets(report: &Report) -> anyhow::Result<String> {
    let rows: Vec<String> = crate::verdict::judge(report)?
        .into_iter()
        .map(|v| format!("| {} | {} | {} |", v.text, v.measured, v.outcome))
        .collect();
    Ok(rows.join("\n"))
}

/// The microseconds table's rows: each part's p50 and p99 over the same samples and its share
/// of the sum of the p50s, then each sample's parts of the code summed, and those outside it.
pub fn parts(report: &Report) -> String {
    let mut rows = Vec::new();
    for p in &report.parts {
        let total: f64 = p.split.parts.iter().map(|part| part.summary.p50_us).sum();
        let row = |name: &str, whose: Whose, s: &Summary, share: String| {
            format!(
                "| {} | {} | {} | {} | {name} | {} | {} | {:.1} | {} | {share} |",
                p.path,
                p.what,
                p.mode,
                p.placement,
                whose_text(whose),
                s.count,
                s.p50_us,
                percentile(s.p99_us, s.count, MIN_FOR_P99)
            )
        };
        for part in &p.split.parts {
            let s = &part.summary;
            let share = if total > 0.0 {
                format!("{:.0} %", 100.0 * s.p50_us / total)
            } else {
                String::new()
            };
            rows.push(row(&part.name, part.whose, s, share));
        }
        rows.push(row(
            TOGETHER_CODE,
            Whose::Code,
            &p.split.code,
            String::new(),
        ));
        rows.push(row(
            TOGETHER_OUTSIDE,
            Whose::Outside,
            &p.split.outside,
            String::new(),
        ));
    }
    rows.join("\n")
}

/// The control loops' rows: each loop's periods and misses beside the raw loop's.
pub fn loops(report: &Report) -> String {
    let rows: Vec<String> = report
        .loops
        .iter()
        .map(|l| {
            format!(
                "| {}, {} | {} | {} | {} | {} ({:.0}) | {} of {} ({:.0}) | {} |",
                l.run,
                l.rate,
                l.mode,
                l.placement,
                l.periods,
                l.misses,
                LoopRun::per_million(l.misses, l.periods),
                l.raw_misses,
                l.raw_periods,
                LoopRun::per_million(l.raw_misses, l.raw_periods),
                l.superseded
            )
        })
        .collect();
    if rows.is_empty() {
        return "| not measured in this run | | | | | | |".into();
    }
    rows.join("\n")
}

/// The cost under a full bus of each bus and bit rate, and the memory real-time mode locks.
fn cost(report: &Report) -> String {
    let mut lines: Vec<String> = report
        .cost
        .iter()
        .map(|c| {
            format!(
                "* {} bus, {} kbit/s (the simulated chassis flooding it): {:.0} frames/s \
                 received; the service's loop thread used {:.2} % of one core; resident memory \
                 {:.1} MiB",
                c.bus,
                c.bitrate / 1000,
                c.frames_per_s,
                c.cpu_pct,
                c.rss_mib
            )
        })
        .collect();
    if let Some(rss) = report.realtime_rss_mib {
        lines.push(format!(
            "* in real-time mode (`--realtime`, the latency runs) chassisd locks every page it \
             maps, its whole executable and every iceoryx2 segment it serves included: resident \
             memory {rss:.1} MiB at most over those runs (the target below is read on the runs \
             with normal scheduling above)"
        ));
    }
    lines.join("\n")
}

/// The replays of a recorded bus, and the run's notes.
fn throughput_and_notes(report: &Report) -> String {
    let mut lines = Vec::new();
    if !report.throughput.is_empty() {
        let runs: Vec<String> = report
            .throughput
            .iter()
            .map(|t| {
                format!(
                    "{} frames in {:.2} s, {:.0} frames/s, the service's loop busy {:.0} % of \
                     the time: {:.0} frames per second of its CPU",
                    t.frames, t.seconds, t.frames_per_s, t.service_cpu_pct, t.frames_per_cpu_s
                )
            })
            .collect();
        lines.push(format!(
            "* a recorded TITAN bus replayed at full speed through the service, read, decoded \
             and published, {} times, each into a fresh service: {}. The replay's writer (a \
             thread on the other CPU, one write per frame) does not always keep the service \
             busy: the target counts the frames per second of the service's own CPU time, the \
             median replay's",
            report.throughput.len(),
            runs.join("; ")
        ));
    }
    for note in report.notes.iter().chain(&report.problems) {
        lines.push(format!("* note: {note}"));
    }
    lines.join("\n")
}

impl Report {
    /// The run on a terminal: the document's tables and lists, without its words.
    pub fn table(&self) -> String {
        let (p, m) = (&self.provenance, &self.machine);
        let blocks = [
            format!(
                "{}, {}; machine: {}, {} cores, kernel {}; host steal time over the run: {}",
                p.date,
                p.commit_text().replace('`', ""),
                m.cpu_model,
                m.cpus,
                m.kernel,
                p.steal_text()
            ),
            with_head("table", table(self)),
            inconsistent(self),
            conditions(self),
            with_head("parts", parts(self)),
            with_head("loops", loops(self)),
            cost(self),
            throughput_and_notes(self),
        ];
        let blocks: Vec<String> = blocks
            .iter()
            .filter(|b| !b.is_empty())
            .map(|b| format!("{}\n", b.trim_end()))
            .collect();
        blocks.join("\n")
    }
}

/// `block` under the table head the template puts above `{{name}}` (nothing when empty).
fn with_head(name: &str, block: String) -> String {
    let above = TEMPLATE
        .split(&format!("\n{{{{{name}}}}}\n"))
        .next()
        .unwrap_or_default();
    let mut lines = above.rsplitn(3, '\n');
    match (lines.next(), lines.next()) {
        (Some(rule), Some(head)) if !block.is_empty() => format!("{head}\n{rule}\n{block}"),
        _ => block,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_template_is_filled_inline_and_by_blocks_and_every_name_must_match() {
        let values = [
            ("a", "one".to_string()),
            ("rows", "| x |\n| y |".to_string()),
            ("none", String::new()),
        ];
        let text = fill("say {{a}}, {{a}}\n{{rows}}\n{{none}}\nend\n", &values).unwrap();
        assert_eq!(text, "say one, one\n| x |\n| y |\nend\n");
        // A name without a value, and a value the template never names.
        assert!(fill("{{b}}\n{{a}}{{rows}}{{none}}\n", &values).is_err());
        assert!(fill("{{a}}{{rows}}\n", &values).is_err());
        assert!(fill("{{a\n", &values[..1]).is_err());
    }
}
