//! Where a run's figures come from: the commit (a tree with uncommitted changes is refused for
//! figures written to files, unless allowed, and then marked DIRTY), the date, the command line,
//! and the host's steal time over the run, read from `/proc/stat` at its start and end.

use std::process::Command;

use anyhow::{Context, bail};
use serde::Serialize;

/// The first line of `/proc/stat`: CPU time of every CPU together, clock ticks.
#[derive(Debug, Clone, Copy, Default)]
pub struct CpuTimes {
    total: u64,
    steal: u64,
    /// idle + iowait.
    idle: u64,
}

impl CpuTimes {
    pub fn read() -> anyhow::Result<Self> {
        let stat = std::fs::read_to_string("/proc/stat").context("reading /proc/stat")?;
        let line = stat
            .lines()
            .find(|l| l.starts_with("cpu "))
            .context("/proc/stat has no cpu line")?;
        let fields: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .map(|v| v.parse().context("a field of /proc/stat's cpu line"))
            .collect::<anyhow::Result<_>>()?;
        // user nice system idle iowait irq softirq steal (guest time is inside user and nice).
        let steal = *fields.get(7).context("/proc/stat has no steal column")?;
        Ok(Self {
            total: fields.iter().take(8).sum(),
            steal,
            idle: fields.get(3).copied().unwrap_or(0) + fields.get(4).copied().unwrap_or(0),
        })
    }
}

impl CpuTimes {
    /// Ticks every CPU was busy (not idle, not waiting for I/O) and ticks in all, since `self`
    /// up to `later`.
    pub fn busy_since(&self, later: &CpuTimes) -> (u64, u64) {
        let total = later.total.saturating_sub(self.total);
        let idle = later.idle.saturating_sub(self.idle);
        (total.saturating_sub(idle), total)
    }
}

/// Commit, date, command and steal time of one run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Provenance {
    pub commit: String,
    /// The tree had uncommitted changes (allowed with `--allow-dirty`).
    pub dirty: bool,
    pub date: String,
    pub command: String,
    /// Time the host ran something else while this machine's CPUs wanted to run, s.
    pub steal_s: f64,
    /// CPU time of all CPUs over the run, s.
    pub cpu_time_s: f64,
    #[serde(skip)]
    start: CpuTimes,
}

fn output(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

impl Provenance {
    /// Notes the commit and `/proc/stat` now. With `strict`, a checkout with uncommitted changes
    /// (or none at all) is an error unless `allow_dirty`.
    pub fn begin(strict: bool, allow_dirty: bool) -> anyhow::Result<Self> {
        let commit = output("git", &["rev-parse", "--short", "HEAD"]);
        let changed: Vec<String> =
            output("git", &["status", "--porcelain", "--untracked-files=no"])
                .lines()
                .map(|l| l.trim().to_string())
                .collect();
        let dirty = commit.is_empty() || !changed.is_empty();
        if strict && dirty && !allow_dirty {
            if commit.is_empty() {
                bail!(
                    "not in a git checkout: figures written to files must name their commit \
                     (run from the workspace, or pass --allow-dirty)"
                );
            }
            bail!(
                "the git tree has uncommitted changes ({}): figures written to files must come \
                 from a commit. Commit them, or pass --allow-dirty for a local run (the files \
                 then say DIRTY)",
                changed.join(", ")
            );
        }
        Ok(Self {
            commit: if commit.is_empty() {
                "unknown".into()
            } else {
                commit
            },
            dirty,
            date: output("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
            command: std::env::args()
                .map(|a| a.rsplit('/').next().unwrap_or_default().to_string())
                .take(1)
                .chain(std::env::args().skip(1))
                .collect::<Vec<_>>()
                .join(" "),
            steal_s: 0.0,
            cpu_time_s: 0.0,
            start: CpuTimes::read()?,
        })
    }

    /// Adds the steal time since [`Provenance::begin`].
    pub fn end(&mut self) -> anyhow::Result<()> {
        let end = CpuTimes::read()?;
        let hz = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
            .ok()
            .flatten()
            .map_or(100.0, |t| t as f64);
        self.steal_s = end.steal.saturating_sub(self.start.steal) as f64 / hz;
        self.cpu_time_s = end.total.saturating_sub(self.start.total) as f64 / hz;
        Ok(())
    }

    /// `commit 1a2b3c4` or `commit 1a2b3c4 — DIRTY: uncommitted changes`.
    pub fn commit_text(&self) -> String {
        if self.dirty {
            format!("commit `{}` — DIRTY: uncommitted changes", self.commit)
        } else {
            format!("commit `{}`", self.commit)
        }
    }

    pub fn steal_text(&self) -> String {
        let share = if self.cpu_time_s > 0.0 {
            100.0 * self.steal_s / self.cpu_time_s
        } else {
            0.0
        };
        format!(
            "{:.2} s of {:.0} s of CPU time ({share:.2} %)",
            self.steal_s, self.cpu_time_s
        )
    }
}
