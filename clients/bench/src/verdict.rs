//! The verdict: the targets of `clients/bench/targets.toml` held against a run's rows, found by
//! their typed identity (path, leg, loop), by one comparator with a typed [`Outcome`]. A target
//! missed says where the time of its worst row goes and what bounds it on this machine.

use serde::Deserialize;

use crate::parts::{IN_SERVICE_COMMAND_PARTS, Part, Split, Whose};
use crate::report::{Leg, LoopRun, MIN_FOR_P99, PathKind, Report, Row};
use crate::stats::Summary;

#[derive(Debug, Deserialize)]
struct Targets {
    target: Vec<Target>,
}

#[derive(Debug, Deserialize)]
struct Target {
    /// The target in the document's words.
    text: String,
    #[serde(flatten)]
    check: Check,
}

/// Rows by their typed identity: a path, a leg, and the loop modes (any when none is given). As
/// a split or the rows a ratio is taken against, its modes are the judged row's.
#[derive(Debug, Clone, Deserialize)]
struct Select {
    path: PathKind,
    leg: Leg,
    #[serde(default)]
    modes: Vec<String>,
}

/// Which parts of a split lie within a row: all, or from the request read on
/// ([`crate::parts::IN_SERVICE_COMMAND_PARTS`]).
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Within {
    #[default]
    All,
    InService,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "check", rename_all = "kebab-case")]
enum Check {
    Latency {
        rows: Select,
        p50_us: f64,
        p99_us: f64,
        split: Option<Select>,
        #[serde(default)]
        within: Within,
    },
    Ratio {
        rows: Select,
        p99_times: f64,
        against: Option<Select>,
    },
    LoopMisses {
        chance: f64,
    },
    FramesPerCpuSecond {
        min: f64,
    },
    BusCpu {
        bitrate: u32,
        max_percent: f64,
    },
    ResidentMemory {
        max_mib: f64,
    },
}

/// How a run stands against one target.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Met,
    /// Missed: where the time of the worst row goes (the largest part of its split at the p99)
    /// and what bounds it on this machine ([`Bound`]); empty when the run has no split to say.
    Missed {
        worst: String,
        bound: String,
    },
    /// No row, loop or cost run of the target's kind in this run.
    NotMeasured,
    /// Every figure within the bound, but these rows' path and baseline were not measured under
    /// the same conditions.
    Inconsistent {
        rows: Vec<String>,
    },
}

impl Outcome {
    /// Missed, with no split to say where the time goes.
    fn unexplained() -> Self {
        let (worst, bound) = (String::new(), String::new());
        Outcome::Missed { worst, bound }
    }
}

impl std::fmt::Display for Outcome {
    /// The document's three cells: met?, where the worst row's time goes, what bounds it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Outcome::Met => f.write_str("met |  | "),
            Outcome::Missed { worst, bound } => write!(f, "**not met** | {worst} | {bound}"),
            Outcome::NotMeasured => f.write_str("not measured |  | "),
            Outcome::Inconsistent { rows } => write!(
                f,
                "**inconsistent** | flagged: {} | the measurement, not the time: a flagged \
                 row's path and baseline were not measured under the same conditions \
                 (*Inconsistent measurements*, above)",
                rows.join("; ")
            ),
        }
    }
}

/// One target judged: its words, the run's figures it was judged on, its outcome.
#[derive(Debug, Clone)]
pub struct Verdict {
    pub text: String,
    pub measured: String,
    pub outcome: Outcome,
}

/// Every target of `targets.toml` judged against `report`.
pub fn judge(report: &Report) -> anyhow::Result<Vec<Verdict>> {
    let targets: Targets = toml::from_str(include_str!("../targets.toml"))
        .map_err(|e| anyhow::anyhow!("clients/bench/targets.toml: {e}"))?;
    let verdicts = targets.target.into_iter().map(|t| {
        let (measured, outcome) = t.check.judge(report);
        Verdict {
            text: t.text,
            measured,
            outcome,
        }
    });
    Ok(verdicts.collect())
}

impl Select {
    fn rows(&self, report: &Report) -> Vec<Row> {
        let mode = |r: &Row| self.modes.is_empty() || self.modes.contains(&r.mode);
        let rows = report
            .rows
            .iter()
            .filter(|r| (r.path, r.leg) == (self.path, self.leg));
        rows.filter(|r| mode(r)).cloned().collect()
    }
}

/// The figures of each judged thing joined ("not measured" without one), and whether each is
/// within the target (none: nothing measured).
fn tally(items: impl Iterator<Item = (String, bool)>) -> (String, Option<bool>) {
    let (figures, within): (Vec<String>, Vec<bool>) = items.unzip();
    if figures.is_empty() {
        return ("not measured".into(), None);
    }
    (figures.join("; "), Some(within.iter().all(|w| *w)))
}

/// The chance that a loop which misses a period as often as its raw loop misses at least as
/// many of the misses the two made together as it did: each miss falls in either loop in
/// proportion to its periods (a binomial tail). Small: the loop misses more than the raw loop,
/// beyond the noise of the counts.
fn as_many_by_chance(l: &LoopRun) -> f64 {
    use statrs::distribution::{Binomial, DiscreteCDF};
    let (both, periods) = (l.misses + l.raw_misses, l.periods + l.raw_periods);
    let share = l.periods as f64 / periods.max(1) as f64;
    match (l.misses.checked_sub(1), Binomial::new(share, both)) {
        (Some(fewer), Ok(binomial)) => binomial.sf(fewer),
        _ => 1.0,
    }
}

/// Met or missed (without a split to say why), or not measured: `items` [`tally`]ed.
fn plain(items: impl Iterator<Item = (String, bool)>) -> (String, Outcome) {
    let (measured, met) = tally(items);
    let outcome = match met {
        None => Outcome::NotMeasured,
        Some(true) => Outcome::Met,
        Some(false) => Outcome::unexplained(),
    };
    (measured, outcome)
}

impl Check {
    fn judge(&self, report: &Report) -> (String, Outcome) {
        match self {
            Check::Latency {
                rows,
                p50_us,
                p99_us,
                split,
                within,
            } => {
                let bound = Bound::Absolute {
                    p50_us: *p50_us,
                    p99_us: *p99_us,
                };
                let rows = rows.rows(report);
                let figures = |r: &Row| {
                    let s = &r.summary;
                    let at = format!("{} {} {}", r.what, r.mode, r.placement);
                    format!("{at}: {:.1} / {:.1} µs", s.p50_us, s.p99_us)
                };
                let split = split.as_ref().map(|s| (s.path, s.leg));
                compare(report, &rows, figures, |_| Some(bound), split, *within)
            }
            Check::Ratio {
                rows,
                p99_times,
                against,
            } => ratio(report, rows, *p99_times, against.as_ref()),
            Check::LoopMisses { chance } => plain(report.loops.iter().map(|l| {
                let own = LoopRun::per_million(l.misses, l.periods);
                let raw = LoopRun::per_million(l.raw_misses, l.raw_periods);
                let (rate, mode, own_n, raw_n) = (&l.rate, &l.mode, own.round(), raw.round());
                let mut text = format!("{rate} {mode}: {own_n} vs {raw_n} of a million");
                let by_chance = as_many_by_chance(l);
                if own > raw {
                    let (m, r) = (l.misses, l.raw_misses);
                    let percent = match 100.0 * by_chance {
                        p if p < 0.05 => "< 0.1".to_string(),
                        p => format!("{p:.1}"),
                    };
                    text += &format!(" ({m} vs {r} misses, as many by chance: {percent} %)");
                }
                (text, own <= raw || by_chance >= *chance)
            })),
            Check::FramesPerCpuSecond { min } => {
                // The replay whose frames per CPU second are the median, of those with the
                // black box recording (the robot as it is shipped).
                let mut runs: Vec<f64> = (report.throughput.iter())
                    .filter(|t| t.recorder)
                    .map(|t| t.frames_per_cpu_s)
                    .collect();
                let each: Vec<String> = runs.iter().map(|f| format!("{f:.0}")).collect();
                runs.sort_by(f64::total_cmp);
                let (n, each) = (runs.len(), each.join(", "));
                plain(runs.get(n / 2).into_iter().map(|&median| {
                    let text = format!(
                        "{median:.0} frames per second of the service's CPU, the median of {n} \
                         replays with the black box recording ({each})"
                    );
                    (text, median >= *min)
                }))
            }
            Check::BusCpu {
                bitrate,
                max_percent,
            } => {
                let at = report.cost.iter().filter(|c| c.bitrate == *bitrate);
                let worst = at.max_by(|a, b| a.service_cpu_pct().total_cmp(&b.service_cpu_pct()));
                plain(worst.into_iter().map(|c| {
                    let (pct, rate, bus) = (c.service_cpu_pct(), c.frames_per_s, &c.bus);
                    let text = format!("{pct:.2} % at {rate:.0} frames/s ({bus})");
                    (text, pct < *max_percent)
                }))
            }
            Check::ResidentMemory { max_mib } => {
                let rss = report.cost.iter().map(|c| c.rss_mib).reduce(f64::max);
                plain(
                    rss.into_iter()
                        .map(|r| (format!("{r:.1} MiB"), r < *max_mib)),
                )
            }
        }
    }
}

/// Every row of `rows` with p99 at most `times` × its baseline's, or, with `against`, the p99
/// of the row of the same run, loop and placement that `against` selects.
fn ratio(
    report: &Report,
    rows: &Select,
    times: f64,
    against: Option<&Select>,
) -> (String, Outcome) {
    // Each row with its ratio: to its baseline, or to the row `against` selects.
    let judged = rows.rows(report).into_iter().filter_map(|r| {
        let Some(a) = against else {
            return Some(r);
        };
        let base = report.rows.iter().find(|b| {
            (b.path, b.leg) == (a.path, a.leg)
                && (&b.run, &b.mode, &b.placement) == (&r.run, &r.mode, &r.placement)
        })?;
        let ratio_p99 = Some(r.summary.p99_us / base.summary.p99_us);
        Some(Row { ratio_p99, ..r })
    });
    let figures = |r: &Row| match (r.ratio_p99, against) {
        (Some(x), Some(_)) => {
            let (p99, at) = (r.summary.p99_us, format!("{} {}", r.mode, r.placement));
            format!("{at}: {p99:.1} vs {:.1} µs, {x:.2} ×", p99 / x)
        }
        (Some(x), None) => format!("{} {}: {x:.2} ×", r.what, r.placement),
        (None, _) => format!("{} {}: no baseline", r.what, r.placement),
    };
    let bound = |row: &Row| {
        let ratio = row.ratio_p99?;
        let base_us = row.summary.p99_us / ratio;
        Some(Bound::Ratio { times, base_us })
    };
    let judged: Vec<Row> = judged.collect();
    compare(report, &judged, figures, bound, None, Within::All)
}

/// The one comparator: each of `rows` with its `figures`, held to its `bound` (none: it cannot
/// be judged, and is not within). All within: met, or inconsistent where a row is flagged; one
/// out: missed, where the time of the worst goes in the split of `split` (the rows' own by
/// default) over its parts `within` the row, and what bounds it.
fn compare(
    report: &Report,
    rows: &[Row],
    figures: impl Fn(&Row) -> String,
    bound: impl Fn(&Row) -> Option<Bound>,
    split: Option<(PathKind, Leg)>,
    within: Within,
) -> (String, Outcome) {
    let holds = |r: &Row| bound(r).is_some_and(|b| b.holds(r));
    let (measured, met) = tally(rows.iter().map(|r| (figures(r), holds(r))));
    let flagged = rows.iter().filter(|r| r.inconsistent.is_some());
    let flagged: Vec<String> = flagged
        .map(|r| format!("{} {} {}", r.what, r.mode, r.placement))
        .collect();
    let outcome = match met {
        None => Outcome::NotMeasured,
        Some(true) if flagged.is_empty() => Outcome::Met,
        Some(true) => Outcome::Inconsistent { rows: flagged },
        Some(false) => missed(report, rows, split, within, bound),
    };
    (measured, outcome)
}

/// A target missed on `rows`: where the time of the worst of them goes (the largest part at the
/// p99 of the split of `split`, the rows' own by default, over its parts `within` the row) and
/// what bounds it against the target's `bound` for that row.
fn missed(
    report: &Report,
    rows: &[Row],
    split: Option<(PathKind, Leg)>,
    within: Within,
    bound: impl Fn(&Row) -> Option<Bound>,
) -> Outcome {
    let p99 = |r: &&Row| r.ratio_p99.unwrap_or(r.summary.p99_us);
    let worst = rows.iter().max_by(|a, b| p99(a).total_cmp(&p99(b)));
    let run = worst.and_then(|row| {
        let split = split.unwrap_or((row.path, row.leg));
        Some((row, &report.split_of(split, row)?.split))
    });
    let Some((row, split)) = run else {
        return Outcome::unexplained();
    };
    let from = match within {
        Within::All => 0,
        Within::InService => (split.parts.len()).saturating_sub(IN_SERVICE_COMMAND_PARTS),
    };
    let parts: Vec<&Part> = split.parts[from..].iter().collect();
    let whole = (parts.len() == split.parts.len()).then_some(split);
    Outcome::Missed {
        worst: largest_part(&parts, row).unwrap_or_default(),
        bound: bound_text(bound(row), &parts, whole, row),
    }
}

/// "ROW: the largest part at the p99, NAME, p99 X µs (p50 Y), over the N samples of its run's
/// split" for `row`, over the `parts` of its split that lie within the row; a split too small
/// for a p99 says so.
fn largest_part(parts: &[&Part], row: &Row) -> Option<String> {
    let part = parts
        .iter()
        .max_by(|a, b| a.summary.p99_us.total_cmp(&b.summary.p99_us))?;
    let head = format!("{} {} {}", row.what, row.mode, row.placement);
    let (name, s, of) = (&part.name, &part.summary, row.summary.count);
    let (n, p99, p50) = (s.count, s.p99_us, s.p50_us);
    Some(match n < MIN_FOR_P99 {
        true => {
            format!("{head}: its run's split holds {n} samples (the row {of}), too few for a p99")
        }
        false => format!(
            "{head}: {name}, p99 {p99:.1} µs (p50 {p50:.1}), over the {n} samples of its run's \
             split (the row {of})"
        ),
    })
}

/// What a target holds one row to: its p99 at most `times` its baseline's, or its p50 and p99 at
/// most these. A sample's time is the sum of its parts, so a row's p50
/// and p99 are at least those of each part, and at least those of its parts outside the code
/// ([`Whose::Outside`]: a wake-up, a system call, the transport, the peer) summed sample by
/// sample: what the row would take had the code taken no time. Such a part alone, or those
/// parts together, missing the target put it out of reach of anything the code does, on this
/// machine.
#[derive(Debug, Clone, Copy)]
enum Bound {
    Ratio { times: f64, base_us: f64 },
    Absolute { p50_us: f64, p99_us: f64 },
}

impl Bound {
    /// Whether `row` is within the bound: its ratio at most `times`, or its p50 and p99 at most
    /// these.
    fn holds(self, row: &Row) -> bool {
        let s = &row.summary;
        match self {
            Bound::Ratio { times, .. } => row.ratio_p99.is_some_and(|x| x <= times),
            Bound::Absolute { p50_us, p99_us } => s.p50_us <= p50_us && s.p99_us <= p99_us,
        }
    }

    /// Whether `s` (a part, or parts together) misses the bound on its own, with how it
    /// compares: "p99 X µs, N × the baseline's", or "P50 / P99 µs (p50 / p99)".
    fn missed_by(self, s: &Summary) -> (bool, String) {
        match self {
            Bound::Ratio { times, base_us } => {
                let of = s.p99_us / base_us;
                let text = format!("p99 {:.1} µs, {of:.2} × the baseline's", s.p99_us);
                (of > times, text)
            }
            Bound::Absolute { p50_us, p99_us } => (
                s.p50_us > p50_us || s.p99_us > p99_us,
                format!("{:.1} / {:.1} µs (p50 / p99)", s.p50_us, s.p99_us),
            ),
        }
    }
}

impl std::fmt::Display for Bound {
    /// The target's own words: "2 × the baseline's (B µs)", "5 / 15 µs".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Bound::Ratio { times, base_us } => {
                write!(f, "{times} × the baseline's ({base_us:.1} µs)")
            }
            Bound::Absolute { p50_us, p99_us } => write!(f, "{p50_us} / {p99_us} µs"),
        }
    }
}

/// What bounds `row` (against `bound`, none: a ratio of a row without a baseline), from the
/// `parts` of its split that lie within it; `whole`: the split, when every part of it does (its
/// parts' sums are the row's).
fn bound_text(bound: Option<Bound>, parts: &[&Part], whole: Option<&Split>, row: &Row) -> String {
    let largest = |whose| {
        let of = parts.iter().filter(|p| p.whose == whose);
        let of = of.filter(|p| p.summary.count >= MIN_FOR_P99);
        of.max_by(|a, b| a.summary.p99_us.total_cmp(&b.summary.p99_us))
    };
    let (Some(outside), Some(code)) = (largest(Whose::Outside), largest(Whose::Code)) else {
        return "its run's split is too small for a p99".into();
    };
    let Some(bound) = bound else {
        return String::new();
    };
    let beyond = format!("beyond {bound} whatever the code does");
    let (alone_missed, alone) = bound.missed_by(&outside.summary);
    let name = &outside.name;
    if alone_missed {
        return format!("outside the code: {name} alone: {alone}, {beyond}");
    }
    let largest_alone = format!("the largest, {name}: {alone}");
    let mut stay = largest_alone.clone();
    let mut code_together = String::new();
    if let Some(w) = whole.filter(|w| w.outside.count >= MIN_FOR_P99) {
        let (together_missed, together) = bound.missed_by(&w.outside);
        if together_missed {
            let count = parts.iter().filter(|p| p.whose == Whose::Outside).count();
            return format!(
                "outside the code: its {count} parts outside it together (each sample's sum): \
                 {together}, {beyond}; none alone ({largest_alone})"
            );
        }
        stay = format!("together: {together}; {largest_alone}");
        let (p99, p50) = (w.code.p99_us, w.code.p50_us);
        code_together = format!("the code's parts together have p99 {p99:.1} µs (p50 {p50:.1}); ");
        // Its slowest samples slow in both at once: the row's p99 beyond both sums' added.
        let (added, row_p99) = (p99 + w.outside.p99_us, row.summary.p99_us);
        if row.summary.count == w.code.count && row_p99 > added {
            code_together.push_str(&format!(
                "the row's p99 ({row_p99:.1} µs) is beyond the two sums' p99s added ({added:.1} \
                 µs): its slowest samples were slow in the code's parts and outside at once; "
            ));
        }
    }
    let (name, p99, p50) = (&code.name, code.summary.p99_us, code.summary.p50_us);
    format!(
        "the code: the parts outside it stay within the target ({stay}); {code_together}the \
         code's largest, {name}, has p99 {p99:.1} µs (p50 {p50:.1})"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_targets_parse_and_each_is_judged() {
        let verdicts = judge(&Report::default()).unwrap();
        assert_eq!(verdicts.len(), 11);
        // An empty run measured nothing: no target is met or missed on it.
        assert!(
            verdicts.iter().all(|v| v.outcome == Outcome::NotMeasured),
            "{verdicts:?}"
        );
    }
}
