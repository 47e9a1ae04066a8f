//! The results: a table on stdout, JSON for machines, CDF plots as SVG.

use std::path::Path;

use plotters::prelude::*;
use serde::Serialize;

use crate::paths::Cost;
use crate::stats::{Latencies, Summary};

/// One measured distribution.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// `baseline`, `command`, `state`, `preemption`, `fan-out`.
    pub path: String,
    /// What ran: the transport of a baseline, or robot and bus of a service path.
    pub what: String,
    /// Service loop mode (`event`, `spin`, `hybrid`), or `-` for baselines.
    pub mode: String,
    /// Where the two ends ran.
    pub placement: String,
    pub summary: Summary,
    /// Requests that produced no frame within the wait (0 expected).
    pub missed: u64,
    /// The baseline this row is compared with, p50 / baseline p50 and p99 / baseline p99.
    pub baseline: Option<String>,
    pub ratio_p50: Option<f64>,
    pub ratio_p99: Option<f64>,
    #[serde(skip)]
    pub latencies: Latencies,
}

/// Everything one run measured.
#[derive(Debug, Default, Serialize)]
pub struct Report {
    pub machine: Machine,
    pub rows: Vec<Row>,
    pub cost: Vec<Cost>,
    pub throughput: Option<Throughput>,
    pub notes: Vec<String>,
}

/// Replay of a recorded bus through decode + publish as fast as the service drains it.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Throughput {
    pub frames: u64,
    pub seconds: f64,
    pub frames_per_s: f64,
    /// CPU use of the service while replaying, % of one core.
    pub service_cpu_pct: f64,
}

#[derive(Debug, Default, Serialize)]
pub struct Machine {
    pub cpus: usize,
    pub kernel: String,
    pub cpu_model: String,
}

impl Machine {
    pub fn probe() -> Self {
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .unwrap_or_default()
            .trim()
            .to_string();
        let cpu_model = std::fs::read_to_string("/proc/cpuinfo")
            .unwrap_or_default()
            .lines()
            .find_map(|l| l.strip_prefix("model name"))
            .and_then(|l| l.split(':').nth(1))
            .unwrap_or("")
            .trim()
            .to_string();
        Self {
            cpus: crate::placement::cpu_count(),
            kernel,
            cpu_model,
        }
    }
}

/// How a paced baseline is labelled: one ping per command period, the hop after the pause only.
pub const PACED: &str = "paced";

impl Report {
    /// Fills in each service row's ratios to the paced raw iceoryx2 baseline of the same
    /// placement (a service path's request also comes after a pause): event-driven and hybrid
    /// loops against iceoryx2 event, spin against iceoryx2 busy-poll.
    pub fn compute_ratios(&mut self) {
        let baselines: Vec<(String, String, f64, f64)> = self
            .rows
            .iter()
            .filter(|r| r.path == "baseline")
            .map(|r| {
                (
                    r.what.clone(),
                    r.placement.clone(),
                    r.summary.p50_us,
                    r.summary.p99_us,
                )
            })
            .collect();
        for row in self.rows.iter_mut().filter(|r| r.path != "baseline") {
            let transport = if row.mode == "spin" {
                "iceoryx2 busy-poll"
            } else {
                "iceoryx2 event"
            };
            let wanted = format!("{transport} {PACED}");
            if let Some((what, placement, p50, p99)) = baselines
                .iter()
                .find(|(w, p, _, _)| *w == wanted && *p == row.placement)
            {
                row.baseline = Some(format!("{what}, {placement}"));
                row.ratio_p50 = (*p50 > 0.0).then(|| row.summary.p50_us / p50);
                row.ratio_p99 = (*p99 > 0.0).then(|| row.summary.p99_us / p99);
            }
        }
    }

    /// The table.
    pub fn table(&self) -> String {
        let mut out = String::new();
        out.push_str(&format!(
            "machine: {} CPUs, {}, kernel {}\n\n",
            self.machine.cpus, self.machine.cpu_model, self.machine.kernel
        ));
        out.push_str(&format!(
            "{:<11} {:<26} {:<7} {:<10} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9}  {}\n",
            "path",
            "what",
            "loop",
            "placement",
            "count",
            "p50 µs",
            "p90 µs",
            "p99 µs",
            "p99.9 µs",
            "max µs",
            "÷ baseline p50, p99"
        ));
        for r in &self.rows {
            let s = &r.summary;
            let ratio = match (r.ratio_p50, r.ratio_p99, &r.baseline) {
                (Some(x), Some(y), Some(b)) => format!("{x:.1}, {y:.1} ({b})"),
                _ => String::new(),
            };
            let missed = if r.missed > 0 {
                format!(" [{} missed]", r.missed)
            } else {
                String::new()
            };
            out.push_str(&format!(
                "{:<11} {:<26} {:<7} {:<10} {:>7} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1}  {}{}\n",
                r.path,
                r.what,
                r.mode,
                r.placement,
                s.count,
                s.p50_us,
                s.p90_us,
                s.p99_us,
                s.p999_us,
                s.max_us,
                ratio,
                missed
            ));
        }
        if !self.cost.is_empty() {
            out.push_str("\nservice cost under a fully loaded bus (simulated chassis flooding):\n");
            for c in &self.cost {
                out.push_str(&format!(
                    "  {:>5} kbit/s: {:>6.0} frames/s received, CPU {:>5.2} % of one core, RSS {:.1} MiB\n",
                    c.bitrate / 1000,
                    c.frames_per_s,
                    c.cpu_pct,
                    c.rss_mib
                ));
            }
        }
        if let Some(t) = &self.throughput {
            out.push_str(&format!(
                "\nreplay at full speed (read + decode + publish in the service): {} frames in {:.2} s = {:.0} frames/s, service CPU {:.0} %\n",
                t.frames, t.seconds, t.frames_per_s, t.service_cpu_pct
            ));
        }
        for note in &self.notes {
            out.push_str(&format!("note: {note}\n"));
        }
        out
    }

    /// Latency CDFs of every row, log latency axis: one panel per kind of path (baselines,
    /// command, state, preemption, fan-out), all on the same axes so panels compare.
    pub fn plot(&self, path: &Path) -> anyhow::Result<()> {
        const PANELS: [(&str, &str); 5] = [
            ("baseline", "raw transports (ping-pong, one way)"),
            ("command", "command: request created → frame written"),
            ("state", "state: frame read → state received"),
            ("preemption", "preemption: safety stop → zero frame written"),
            ("fan-out", "fan-out: state to 1, 4, 16 processes"),
        ];
        let root = SVGBackend::new(path, (1600, 1500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
        let root = root
            .titled(
                "one-way latency, CDF (log latency axis)",
                ("sans-serif", 26),
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let max_us = self
            .rows
            .iter()
            .map(|r| r.summary.max_us)
            .fold(10.0f64, f64::max)
            .min(1e6);
        for (area, (kind, title)) in root.split_evenly((3, 2)).iter().zip(PANELS) {
            let rows: Vec<&Row> = self.rows.iter().filter(|r| r.path == kind).collect();
            if rows.is_empty() {
                continue;
            }
            let mut chart = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(35)
                .y_label_area_size(45)
                .build_cartesian_2d((0.5f64..max_us * 1.2).log_scale(), 0.0f64..1.0)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            chart
                .configure_mesh()
                .x_desc("latency, µs")
                .y_desc("fraction of samples")
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for (i, row) in rows.iter().enumerate() {
                let color = Palette99::pick(i).to_rgba();
                let label = match row.mode.as_str() {
                    "-" => format!("{}, {}", row.what, row.placement),
                    mode => format!("{}, {mode}, {}", row.what, row.placement),
                };
                chart
                    .draw_series(LineSeries::new(row.latencies.cdf(), color.stroke_width(2)))
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .label(label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(())
    }
}
