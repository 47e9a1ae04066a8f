//! The performance document: its words are `clients/bench/performance.md`, whose `{{name}}`s this
//! fills from a run's samples (a [`Report`]) and its verdict, nothing typed by hand. A
//! `{{name}}` alone on its line stands for a block of lines, none when the block is empty. The
//! terminal's table is the document's tables and lists.

use crate::parts::Whose;
use crate::paths::HYBRID_SPIN;
use crate::paths::{
    BENCH_CONFIG, COMMAND_INTERVAL, REALTIME_PRIORITY, STATE_REQUEST_INTERVAL,
    XBOT_COMMAND_INTERVAL, off_grid, period_text,
};
use crate::provenance::Provenance;
use crate::report::{
    DEFAULT_CONFIG_ROW, LoopRun, MIN_FOR_P99, MIN_FOR_P999, Machine, Report, SUM_TOLERANCE,
    StallRates, UNRECORDED_ROW,
};
use crate::stats::Summary;

const TEMPLATE: &str = include_str!("../performance.md");

/// The microseconds table's rows of each sample's parts of the code, and outside it, summed.
pub(crate) const TOGETHER_CODE: &str = "*together*: the code's parts, each sample's sum";
pub(crate) const TOGETHER_OUTSIDE: &str =
    "*together*: the parts outside the code, each sample's sum";

/// The performance document of `report`.
pub fn document(report: &Report) -> anyhow::Result<String> {
    let period = |interval| period_text(off_grid(interval));
    let ms = |interval: std::time::Duration| interval.as_millis().to_string();
    let payload_bytes = size_of::<chassis_client::ChassisState>();
    let mut values = provenance_values(&report.provenance, &report.machine);
    values.extend([
        ("steal", report.provenance.steal_text()),
        ("bench_config", BENCH_CONFIG.trim_end().to_string()),
        ("priority", REALTIME_PRIORITY.to_string()),
        ("scheduling", report.scheduling_text()),
        ("default_config_row", DEFAULT_CONFIG_ROW.to_string()),
        ("unrecorded_row", UNRECORDED_ROW.to_string()),
        ("table", table(report)),
        ("inconsistent", inconsistent(report)),
        ("conditions", conditions(report)),
        ("stalls", report.stalls_text()),
        ("targets", targets(report)?),
        ("parts", parts(report)),
        ("loops", loops(report)),
        ("cost", cost(report)),
        ("throughput", throughput_and_notes(report)),
        ("payload_bytes", payload_bytes.to_string()),
        ("hybrid_spin_us", HYBRID_SPIN.as_micros().to_string()),
        ("command_period", period(COMMAND_INTERVAL)),
        ("xbot_command_period", period(XBOT_COMMAND_INTERVAL)),
        ("command_interval_ms", ms(COMMAND_INTERVAL)),
        ("state_request_interval_ms", ms(STATE_REQUEST_INTERVAL)),
        ("sum_tolerance_pct", format!("{}", SUM_TOLERANCE * 100.0)),
        ("min_for_p99", MIN_FOR_P99.to_string()),
        ("min_for_p999", MIN_FOR_P999.to_string()),
    ]);
    fill(TEMPLATE, &values)
}

/// Where a document's figures come from: its run's date and commit, the command, the machine.
pub(crate) fn provenance_values(p: &Provenance, m: &Machine) -> Vec<(&'static str, String)> {
    vec![
        ("date", p.date.clone()),
        ("commit", p.commit_text()),
        ("command", p.command.clone()),
        ("cpu_model", m.cpu_model.clone()),
        ("cpus", m.cpus.to_string()),
        ("kernel", m.kernel.clone()),
    ]
}

/// `template` with each `{{name}}` replaced by its value in `values`: a name with no value is
/// an error, and so is a value the template never names.
pub(crate) fn fill(template: &str, values: &[(&str, String)]) -> anyhow::Result<String> {
    let value = |name: &str| {
        let found = values
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| v.as_str());
        found
            .ok_or_else(|| anyhow::anyhow!("the document names {{{{{name}}}}}, which has no value"))
    };
    let mut out = String::new();
    for line in template.lines() {
        let block = line.strip_prefix("{{").and_then(|l| l.strip_suffix("}}"));
        if let Some(name) = block.filter(|name| !name.contains("{{")) {
            let block = value(name)?;
            if !block.is_empty() {
                out.push_str(&format!("{block}\n"));
            }
            continue;
        }
        let mut rest = line;
        while let Some(start) = rest.find("{{") {
            let unclosed = || anyhow::anyhow!("an unclosed {{{{ in the document: {line}");
            let end = start + rest[start..].find("}}").ok_or_else(unclosed)?;
            out.push_str(&rest[..start]);
            out.push_str(value(&rest[start + 2..end])?);
            rest = &rest[end + 2..];
        }
        out.push_str(&format!("{rest}\n"));
    }
    let unnamed = values
        .iter()
        .find(|(n, _)| !template.contains(&format!("{{{{{n}}}}}")));
    if let Some((name, _)) = unnamed {
        anyhow::bail!("the document never names {{{{{name}}}}}");
    }
    Ok(out)
}

/// `items` one a line.
pub(crate) fn lines<T>(
    items: impl IntoIterator<Item = T>,
    line: impl FnMut(T) -> String,
) -> String {
    items.into_iter().map(line).collect::<Vec<_>>().join("\n")
}

/// A percentile for a table: `—` when the row has too few samples to tell it from the maximum.
pub(crate) fn percentile(value: f64, count: u64, fewest: u64) -> String {
    let shown = (count >= fewest).then(|| format!("{value:.1}"));
    shown.unwrap_or_else(|| "—".into())
}

/// The table's rows: each row's count with what it lost beside it, its percentiles (a dash
/// where its count cannot give one), its ratios to its baseline.
fn table(report: &Report) -> String {
    lines(&report.rows, |r| {
        let s = &r.summary;
        let ratio = match (r.ratio_p50, r.ratio_p99) {
            (Some(x), Some(y)) => format!("{x:.2}, {y:.2}"),
            (Some(x), None) => format!("{x:.2}, —"),
            _ => String::new(),
        };
        let flag = r.inconsistent.as_ref().map_or("", |_| " **inconsistent**");
        let (path, what, mode, placement) = (r.path, &r.what, &r.mode, &r.placement);
        let (n, p50, p90, max) = (r.count_text(), s.p50_us, s.p90_us, s.max_us);
        let p99 = percentile(s.p99_us, s.count, MIN_FOR_P99);
        let p999 = percentile(s.p999_us, s.count, MIN_FOR_P999);
        let baseline = r.baseline.as_deref().unwrap_or("");
        format!(
            "| {path} | {what} | {mode} | {placement} | {n} | {p50:.1} | {p90:.1} | {p99} | {p999} \
             | {max:.1} | {ratio}{flag} | {baseline} |"
        )
    })
}

/// The rows flagged inconsistent, with why, or nothing.
fn inconsistent(report: &Report) -> String {
    let flagged = report.rows.iter().filter_map(|r| {
        let why = r.inconsistent.as_deref()?;
        let (path, what, mode, placement) = (r.path, &r.what, &r.mode, &r.placement);
        Some(format!("* {path} {what} ({mode} loop, {placement}): {why}"))
    });
    let flagged = lines(flagged, |f| f);
    match flagged.is_empty() {
        true => flagged,
        false => {
            format!("**Inconsistent measurements** (flagged by the benchmark):\n\n{flagged}\n")
        }
    }
}

/// Each baseline's conditions.
fn conditions(report: &Report) -> String {
    let baselines = report.rows.iter().filter_map(|r| {
        let (what, placement, c) = (&r.what, &r.placement, r.conditions.as_ref()?);
        Some(format!("* {what}, {placement}: {c}"))
    });
    lines(baselines, |l| l)
}

/// The targets' rows: each target, what this run measured, and its outcome.
fn targets(report: &Report) -> anyhow::Result<String> {
    let verdicts = crate::verdict::judge(report)?;
    Ok(lines(verdicts, |v| {
        format!("| {} | {} | {} |", v.text, v.measured, v.outcome)
    }))
}

/// The microseconds table's rows: each part's p50 and p99 over the same samples and its share
/// of the sum of the p50s, then each sample's parts of the code summed, and those outside it.
pub fn parts(report: &Report) -> String {
    lines(&report.parts, |p| {
        let total: f64 = p.split.parts.iter().map(|part| part.summary.p50_us).sum();
        let (path, what, mode, placement) = (&p.path, &p.what, &p.mode, &p.placement);
        // A part, or a sum of parts (no share of the p50s).
        let row = |name: &str, whose: Whose, s: &Summary, part: bool| {
            let whose = match whose {
                Whose::Code => "the code",
                Whose::Outside => "outside",
            };
            let (n, p50, p99) = (
                s.count,
                s.p50_us,
                percentile(s.p99_us, s.count, MIN_FOR_P99),
            );
            let share = (part && total > 0.0).then(|| format!("{:.0} %", 100.0 * p50 / total));
            let share = share.unwrap_or_default();
            format!(
                "| {path} | {what} | {mode} | {placement} | {name} | {whose} | {n} | {p50:.1} | \
                 {p99} | {share} |"
            )
        };
        let parts = p.split.parts.iter();
        let parts = parts.map(|part| row(&part.name, part.whose, &part.summary, true));
        let code = row(TOGETHER_CODE, Whose::Code, &p.split.code, false);
        let outside = row(TOGETHER_OUTSIDE, Whose::Outside, &p.split.outside, false);
        lines(parts.chain([code, outside]), |l| l)
    })
}

/// The control loops' rows: each loop's periods and misses beside the raw loop's.
pub fn loops(report: &Report) -> String {
    if report.loops.is_empty() {
        return "| not measured in this run | | | | | | |".into();
    }
    lines(&report.loops, |l| {
        let own = LoopRun::per_million(l.misses, l.periods);
        let raw = LoopRun::per_million(l.raw_misses, l.raw_periods);
        let (run, rate, mode, placement) = (&l.run, &l.rate, &l.mode, &l.placement);
        let (periods, misses, raw_misses) = (l.periods, l.misses, l.raw_misses);
        let (raw_periods, superseded) = (l.raw_periods, l.superseded);
        format!(
            "| {run}, {rate} | {mode} | {placement} | {periods} | {misses} ({own:.0}) | \
             {raw_misses} of {raw_periods} ({raw:.0}) | {superseded} |"
        )
    })
}

/// The cost under a full bus of each bus and bit rate, and the memory real-time mode locks.
fn cost(report: &Report) -> String {
    let buses = report.cost.iter().map(|c| {
        let (bus, kbit, rate) = (&c.bus, c.bitrate / 1000, c.frames_per_s);
        let (cpu, rss) = (c.cpu_pct, c.rss_mib);
        let recorder = match (c.recorder_cpu_pct, c.recorder_mb_per_min) {
            (Some(pct), Some(mb)) => {
                format!("its black box writer {pct:.2} % ({mb:.1} MB a minute)")
            }
            _ => "the black box off".into(),
        };
        format!(
            "* {bus} bus, {kbit} kbit/s (the simulated chassis flooding it): {rate:.0} frames/s \
             received; the service's loop thread used {cpu:.2} % of one core, {recorder}; \
             resident memory {rss:.1} MiB"
        )
    });
    let realtime = report.realtime_rss_mib.map(|rss| {
        format!(
            "* in real-time mode (`--realtime`, the latency runs) chassisd locks every page it \
             maps, its whole executable and every iceoryx2 segment it serves included: resident \
             memory {rss:.1} MiB at most over those runs (the target below is read on the runs \
             with normal scheduling above)"
        )
    });
    lines(buses.chain(realtime), |l| l)
}

/// The replays of a recorded bus, and the run's notes.
fn throughput_and_notes(report: &Report) -> String {
    let replays = [true, false].map(|recorder| {
        let of = report.throughput.iter().filter(|t| t.recorder == recorder);
        let runs = lines(of.clone(), |t| {
            format!(
                "{} frames in {:.2} s, {:.0} frames/s, the service's loop busy {:.0} % of the \
                 time: {:.0} frames per second of its CPU",
                t.frames, t.seconds, t.frames_per_s, t.service_cpu_pct, t.frames_per_cpu_s
            )
        });
        let (n, runs) = (of.count(), runs.replace('\n', "; "));
        let black_box = if recorder { "recording" } else { "off" };
        (n > 0).then(|| {
            format!(
                "* a recorded TITAN bus replayed at full speed through the service, read, \
                 decoded and published, {n} times with the black box {black_box}, each into a \
                 fresh service: {runs}. The replay's writer (a thread on the other CPU, one \
                 write per frame) does not always keep the service busy: the target counts the \
                 frames per second of the service's own CPU time, the median replay's with the \
                 black box recording"
            )
        })
    });
    let notes = report.notes.iter().chain(&report.problems);
    let notes = notes.map(|n| format!("* note: {n}"));
    lines(replays.into_iter().flatten().chain(notes), |l| l)
}

impl Report {
    /// What the system granted: real-time mode in every run that asked for it, or the runs
    /// where it was refused (their loops ran with normal scheduling, and so did their
    /// baselines' receivers).
    pub fn scheduling_text(&self) -> String {
        use crate::report::Scheduling;
        let runs = self.scheduling.iter();
        let asked = runs
            .clone()
            .filter(|(_, s)| *s != Scheduling::Normal)
            .count();
        let refused = runs.filter(|(_, s)| *s == Scheduling::Refused);
        let refused: Vec<&str> = refused.map(|(run, _)| run.as_str()).collect();
        let (n, runs) = (refused.len(), refused.join("; "));
        if refused.is_empty() {
            return format!(
                "Real-time mode was granted in each of the {asked} runs that asked for it."
            );
        }
        format!(
            "**Real-time mode was refused** (no CAP_SYS_NICE or RLIMIT_RTPRIO) in {n} of the \
             {asked} runs that asked for it, which ran with normal scheduling: {runs}."
        )
    }

    /// What the stall rows say of every p99 on this machine, or nothing without them.
    pub(crate) fn stalls_text(&self) -> String {
        if self.stalls.is_empty() {
            return String::new();
        }
        // "LOW to HIGH" over the CPUs, one figure when they print alike.
        let span = |f: &dyn Fn(&StallRates) -> f64, decimals: usize| {
            let low = self.stalls.iter().map(f).fold(f64::INFINITY, f64::min);
            let high = self.stalls.iter().map(f).fold(0.0, f64::max);
            let (low, high) = (format!("{low:.decimals$}"), format!("{high:.decimals$}"));
            match low == high {
                true => low,
                false => format!("{low} to {high}"),
            }
        };
        // The chance that a window of 100 µs holds the start of a stall over 20 µs, %.
        let chance = |s: &StallRates| 100.0 * s.over_20_us * 100e-6;
        let least = self.stalls.iter().map(chance).fold(f64::INFINITY, f64::min);
        let (over_20, over_100) = (span(&|s| s.over_20_us, 0), span(&|s| s.over_100_us, 2));
        let chances = span(&chance, 1);
        let end = match least >= 1.0 {
            true => ": more than 1 %, so that its p99 carries one, whatever the code does.",
            false => ".",
        };
        format!(
            " On this machine a thread that never blocks lost more than 20 µs {over_20} times a \
             second and more than 100 µs {over_100} times a second, by CPU (the stall rows of \
             the table): a path of 100 µs meets a stall of more than 20 µs in about {chances} % \
             of its samples on each CPU it runs on{end}"
        )
    }

    /// The run on a terminal: the document's tables and lists, without its words.
    pub fn table(&self) -> String {
        let (p, m) = (&self.provenance, &self.machine);
        let (date, commit, steal) = (&p.date, p.commit_text().replace('`', ""), p.steal_text());
        let (model, cpus, kernel) = (&m.cpu_model, m.cpus, &m.kernel);
        let blocks = [
            format!(
                "{date}, {commit}; machine: {model}, {cpus} cores, kernel {kernel}; host steal \
                 time over the run: {steal}"
            ),
            with_head("table", table(self)),
            inconsistent(self),
            conditions(self),
            with_head("parts", parts(self)),
            with_head("loops", loops(self)),
            cost(self),
            throughput_and_notes(self),
        ];
        let blocks = blocks.iter().filter(|b| !b.is_empty());
        lines(blocks, |b| format!("{}\n", b.trim_end()))
    }
}

/// `block` under the table head the template puts above `{{name}}` (nothing when empty).
fn with_head(name: &str, block: String) -> String {
    let above = TEMPLATE.split(&format!("\n{{{{{name}}}}}\n")).next();
    let mut lines = above.unwrap_or_default().rsplitn(3, '\n');
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
