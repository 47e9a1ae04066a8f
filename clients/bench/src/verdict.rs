//! The verdict: the targets of `clients/bench/targets.toml` held against a run's rows, found by
//! their typed identity (path, leg, loop), by one comparator with a typed [`Outcome`]. A target
//! missed says where the time of its worst row goes and what bounds it on this machine.

use serde::Deserialize;

use crate::parts::{Part, Split, Whose};
use crate::report::{Leg, LoopRun, MIN_FOR_P99, PathKind, Report, Row, median_replay};
use crate::stats::Summary;

/// The committed targets, in the document's order.
const TARGETS: &str = include_str!("../targets.toml");

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

/// Rows by their typed identity: a path, a leg, and the loop modes (any when none is given).
#[derive(Debug, Clone, Deserialize)]
struct Select {
    path: PathKind,
    leg: Leg,
    #[serde(default)]
    modes: Vec<String>,
}

/// A split by the rows it divides.
#[derive(Debug, Clone, Copy, Deserialize)]
struct SplitOf {
    path: PathKind,
    leg: Leg,
}

/// Which parts of a split lie within a row.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Within {
    #[default]
    All,
    /// From the request read on ([`crate::parts::in_service_command`]).
    InService,
}

#[derive(Debug, Deserialize)]
#[serde(tag = "check", rename_all = "kebab-case")]
enum Check {
    Latency {
        rows: Select,
        p50_us: f64,
        p99_us: f64,
        split: Option<SplitOf>,
        #[serde(default)]
        within: Within,
    },
    Ratio {
        rows: Select,
        p99_times: f64,
        against: Option<SplitOf>,
    },
    LoopMisses,
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
    /// and what bounds it on this machine ([`Limit`]); empty when the run has no split to say.
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

/// One target judged.
#[derive(Debug, Clone)]
pub struct Verdict {
    pub text: String,
    /// The run's figures the target was judged on, in words.
    pub measured: String,
    pub outcome: Outcome,
}

/// Every target of `targets.toml` judged against `report`.
pub fn judge(report: &Report) -> anyhow::Result<Vec<Verdict>> {
    let targets: Targets =
        toml::from_str(TARGETS).map_err(|e| anyhow::anyhow!("clients/bench/targets.toml: {e}"))?;
    Ok(targets
        .target
        .into_iter()
        .map(|t| {
            let (measured, outcome) = t.check.judge(report);
            Verdict {
                text: t.text,
                measured,
                outcome,
            }
        })
        .collect())
}

impl Select {
    fn rows<'r>(&self, report: &'r Report) -> Vec<&'r Row> {
        report
            .rows
            .iter()
            .filter(|r| r.path == self.path && r.leg == self.leg)
            .filter(|r| self.modes.is_empty() || self.modes.contains(&r.mode))
            .collect()
    }
}

/// "not measured", or the figures of each judged thing joined.
fn figures(items: impl Iterator<Item = String>) -> String {
    let all: Vec<String> = items.collect();
    if all.is_empty() {
        "not measured".into()
    } else {
        all.join("; ")
    }
}

/// Met or missed (without a split to say why), or not measured.
fn plain(met: Option<bool>) -> Outcome {
    match met {
        None => Outcome::NotMeasured,
        Some(true) => Outcome::Met,
        Some(false) => Outcome::Missed {
            worst: String::new(),
            bound: String::new(),
        },
    }
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
                let rows = rows.rows(report);
                let measured = figures(rows.iter().map(|r| {
                    format!(
                        "{} {} {}: {:.1} / {:.1} µs",
                        r.what, r.mode, r.placement, r.summary.p50_us, r.summary.p99_us
                    )
                }));
                let within: fn(&Part) -> bool = match within {
                    Within::All => |_| true,
                    Within::InService => crate::parts::in_service_command,
                };
                let limit = Limit::Absolute {
                    p50_us: *p50_us,
                    p99_us: *p99_us,
                };
                let split = split
                    .map(|s| (s.path, s.leg))
                    .or_else(|| rows.first().map(|r| (r.path, r.leg)));
                let over = |r: &&Row| r.summary.p50_us > *p50_us || r.summary.p99_us > *p99_us;
                let outcome = if rows.is_empty() {
                    Outcome::NotMeasured
                } else if rows.iter().any(over) {
                    missed(report, &rows, split, within, limit)
                } else {
                    Outcome::Met
                };
                (measured, outcome)
            }
            Check::Ratio {
                rows,
                p99_times,
                against,
            } => ratio(report, rows, *p99_times, *against),
            Check::LoopMisses => {
                let loops = &report.loops;
                let measured = figures(loops.iter().map(|l| {
                    format!(
                        "{} {}: {} vs {} of a million",
                        l.rate,
                        l.mode,
                        LoopRun::per_million(l.misses, l.periods).round(),
                        LoopRun::per_million(l.raw_misses, l.raw_periods).round()
                    )
                }));
                let met = (!loops.is_empty()).then(|| {
                    loops.iter().all(|l| {
                        LoopRun::per_million(l.misses, l.periods)
                            <= LoopRun::per_million(l.raw_misses, l.raw_periods)
                    })
                });
                (measured, plain(met))
            }
            Check::FramesPerCpuSecond { min } => {
                let median = median_replay(&report.throughput);
                let measured = median.map_or("not measured".into(), |m| {
                    format!(
                        "{:.0} frames per second of the service's CPU, the median of {} \
                         replays ({})",
                        m.frames_per_cpu_s,
                        report.throughput.len(),
                        report
                            .throughput
                            .iter()
                            .map(|t| format!("{:.0}", t.frames_per_cpu_s))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                });
                (measured, plain(median.map(|m| m.frames_per_cpu_s >= *min)))
            }
            Check::BusCpu {
                bitrate,
                max_percent,
            } => {
                let worst = report
                    .cost
                    .iter()
                    .filter(|c| c.bitrate == *bitrate)
                    .max_by(|a, b| a.cpu_pct.total_cmp(&b.cpu_pct));
                let measured = worst.map_or("not measured".into(), |c| {
                    format!(
                        "{:.2} % at {:.0} frames/s ({})",
                        c.cpu_pct, c.frames_per_s, c.bus
                    )
                });
                (measured, plain(worst.map(|c| c.cpu_pct < *max_percent)))
            }
            Check::ResidentMemory { max_mib } => {
                let rss = report.cost.iter().map(|c| c.rss_mib).reduce(f64::max);
                let measured = rss.map_or("not measured".into(), |r| format!("{r:.1} MiB"));
                (measured, plain(rss.map(|r| r < *max_mib)))
            }
        }
    }
}

/// Every row of `rows` with p99 at most `p99_times` × its baseline's, or, with `against`, the
/// p99 of the row of the same run, loop and placement that `against` selects; none flagged
/// inconsistent.
fn ratio(
    report: &Report,
    rows: &Select,
    p99_times: f64,
    against: Option<SplitOf>,
) -> (String, Outcome) {
    // Each row with its ratio: to its baseline, or to the row `against` selects.
    let judged: Vec<Row> = rows
        .rows(report)
        .into_iter()
        .filter_map(|r| match against {
            None => Some(r.clone()),
            Some(a) => {
                let base = report.rows.iter().find(|b| {
                    (b.path, b.leg) == (a.path, a.leg)
                        && (&b.run, &b.mode, &b.placement) == (&r.run, &r.mode, &r.placement)
                })?;
                Some(Row {
                    ratio_p99: Some(r.summary.p99_us / base.summary.p99_us),
                    ..r.clone()
                })
            }
        })
        .collect();
    let rows: Vec<&Row> = judged.iter().collect();
    let measured = figures(rows.iter().map(|r| match (r.ratio_p99, against) {
        (Some(x), Some(_)) => format!(
            "{} {}: {:.1} vs {:.1} µs, {x:.2} ×",
            r.mode,
            r.placement,
            r.summary.p99_us,
            r.summary.p99_us / x
        ),
        (Some(x), None) => format!("{} {}: {x:.2} ×", r.what, r.placement),
        (None, _) => format!("{} {}: no baseline", r.what, r.placement),
    }));
    let within_bound = |r: &&Row| r.ratio_p99.is_some_and(|x| x <= p99_times);
    let outcome = if rows.is_empty() {
        Outcome::NotMeasured
    } else if !rows.iter().all(within_bound) {
        let split = rows.first().map(|r| (r.path, r.leg));
        missed(report, &rows, split, |_| true, Limit::Ratio(p99_times))
    } else {
        let flagged: Vec<String> = rows
            .iter()
            .filter(|r| r.inconsistent.is_some())
            .map(|r| format!("{} {} {}", r.what, r.mode, r.placement))
            .collect();
        if flagged.is_empty() {
            Outcome::Met
        } else {
            Outcome::Inconsistent { rows: flagged }
        }
    };
    (measured, outcome)
}

/// A target missed on `rows`: where the time of the worst of them goes (its split's largest
/// part at the p99, over the parts `within` the row) and what bounds it ([`Limit`]).
fn missed(
    report: &Report,
    rows: &[&Row],
    split: Option<(PathKind, Leg)>,
    within: impl Fn(&Part) -> bool,
    limit: Limit,
) -> Outcome {
    let nothing = Outcome::Missed {
        worst: String::new(),
        bound: String::new(),
    };
    let worst = rows.iter().max_by(|a, b| {
        a.ratio_p99
            .unwrap_or(a.summary.p99_us)
            .total_cmp(&b.ratio_p99.unwrap_or(b.summary.p99_us))
    });
    let (Some(row), Some(split)) = (worst, split) else {
        return nothing;
    };
    let Some(run) = report.split_of(split, row) else {
        return nothing;
    };
    let split = &run.split;
    let parts: Vec<&Part> = split.parts.iter().filter(|p| within(p)).collect();
    let whole = (parts.len() == split.parts.len()).then_some(split);
    Outcome::Missed {
        worst: largest_part(&parts, row).unwrap_or_default(),
        bound: limit.text(&parts, whole, row),
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
    if part.summary.count < MIN_FOR_P99 {
        return Some(format!(
            "{head}: its run's split holds {} samples (the row {}), too few for a p99",
            part.summary.count, row.summary.count
        ));
    }
    Some(format!(
        "{head}: {}, p99 {:.1} µs (p50 {:.1}), over the {} samples of its run's split (the row \
         {})",
        part.name, part.summary.p99_us, part.summary.p50_us, part.summary.count, row.summary.count
    ))
}

/// What a target holds a row to, to tell what bounds a row that misses it. A sample's time is
/// the sum of its parts, so a row's p50 and p99 are at least those of each part, and at least
/// those of its parts outside the code ([`Whose::Outside`]: a wake-up, a system call, the
/// transport, the peer) summed sample by sample: what the row would take had the code taken no
/// time. Such a part alone, or those parts together, missing the target put it out of reach of
/// anything the code does, on this machine.
#[derive(Debug, Clone, Copy)]
enum Limit {
    /// The row's p99 at most this many times its baseline's.
    Ratio(f64),
    /// The row's p50 and p99 at most these, µs.
    Absolute { p50_us: f64, p99_us: f64 },
}

/// A [`Limit`] held against one row: a ratio's baseline known.
#[derive(Debug, Clone, Copy)]
enum Bound {
    Ratio { bound: f64, base_us: f64 },
    Absolute { p50_us: f64, p99_us: f64 },
}

impl Bound {
    /// Whether `s` (a part, or parts together) misses the bound on its own, with how it
    /// compares: "p99 X µs, N × the baseline's", or "P50 / P99 µs (p50 / p99)".
    fn missed_by(self, s: &Summary) -> (bool, String) {
        match self {
            Bound::Ratio { bound, base_us } => {
                let times = s.p99_us / base_us;
                (
                    times > bound,
                    format!("p99 {:.1} µs, {times:.2} × the baseline's", s.p99_us),
                )
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
            Bound::Ratio { bound, base_us } => {
                write!(f, "{bound} × the baseline's ({base_us:.1} µs)")
            }
            Bound::Absolute { p50_us, p99_us } => write!(f, "{p50_us} / {p99_us} µs"),
        }
    }
}

impl Limit {
    /// The limit against `row`; a ratio of a row without a baseline has none.
    fn against(self, row: &Row) -> Option<Bound> {
        match self {
            Limit::Ratio(bound) => row.ratio_p99.filter(|r| *r > 0.0).map(|r| Bound::Ratio {
                bound,
                base_us: row.summary.p99_us / r,
            }),
            Limit::Absolute { p50_us, p99_us } => Some(Bound::Absolute { p50_us, p99_us }),
        }
    }

    /// What bounds `row`, from the `parts` of its split that lie within it; `whole`: the split,
    /// when every part of it does (its parts' sums are the row's).
    fn text(self, parts: &[&Part], whole: Option<&Split>, row: &Row) -> String {
        let largest = |whose| {
            parts
                .iter()
                .copied()
                .filter(|p| p.whose == whose && p.summary.count >= MIN_FOR_P99)
                .max_by(|a, b| a.summary.p99_us.total_cmp(&b.summary.p99_us))
        };
        let (Some(outside), Some(code)) = (largest(Whose::Outside), largest(Whose::Code)) else {
            return "its run's split is too small for a p99".into();
        };
        let Some(bound) = self.against(row) else {
            return String::new();
        };
        let beyond = format!("beyond {bound} whatever the code does");
        let (alone_missed, alone) = bound.missed_by(&outside.summary);
        if alone_missed {
            return format!(
                "outside the code: {} alone: {alone}, {beyond}",
                outside.name
            );
        }
        let largest_alone = format!("the largest, {}: {alone}", outside.name);
        let (stay, code_together) = match whole.filter(|w| w.outside.count >= MIN_FOR_P99) {
            None => (largest_alone, String::new()),
            Some(w) => {
                let (together_missed, together) = bound.missed_by(&w.outside);
                if together_missed {
                    let count = parts.iter().filter(|p| p.whose == Whose::Outside).count();
                    return format!(
                        "outside the code: its {count} parts outside it together (each \
                         sample's sum): {together}, {beyond}; none alone ({largest_alone})"
                    );
                }
                (
                    format!("together: {together}; {largest_alone}"),
                    code_together_text(w, row),
                )
            }
        };
        format!(
            "the code: the parts outside it stay within the target ({stay}); {code_together}the \
             code's largest, {}, has p99 {:.1} µs (p50 {:.1})",
            code.name, code.summary.p99_us, code.summary.p50_us
        )
    }
}

/// "The code's parts together …; " of a split `w` whose parts are all of `row`'s, with what its
/// slowest samples say when the row's p99 is beyond both sums' p99s added: they were slow in
/// both at once.
fn code_together_text(w: &Split, row: &Row) -> String {
    let mut text = format!(
        "the code's parts together have p99 {:.1} µs (p50 {:.1}); ",
        w.code.p99_us, w.code.p50_us
    );
    let added = w.code.p99_us + w.outside.p99_us;
    if row.summary.count == w.code.count && row.summary.p99_us > added {
        text.push_str(&format!(
            "the row's p99 ({:.1} µs) is beyond the two sums' p99s added ({added:.1} µs): its \
             slowest samples were slow in the code's parts and outside at once; ",
            row.summary.p99_us
        ));
    }
    text
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
