//! Where a run's figures come from, for `chassis-bench` (docs/PERFORMANCE.md) and the
//! reliability report (docs/RELIABILITY.md): the commit checked out and the files changed since,
//! the date, the machine, and the host's CPU time and steal time over the run, read from
//! `/proc/stat` at its start and end.

use std::process::Command;

use serde::{Deserialize, Serialize};

/// What went wrong reading the host.
#[derive(Debug, thiserror::Error)]
pub enum ProvenanceError {
    #[error("reading /proc/stat: {0}")]
    ProcStat(#[from] std::io::Error),
    #[error("/proc/stat: {0}")]
    Malformed(&'static str),
}

/// The first line of `/proc/stat`: CPU time of every CPU together, clock ticks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CpuTimes {
    pub total: u64,
    pub steal: u64,
    /// idle + iowait.
    #[serde(default)]
    pub idle: u64,
}

impl CpuTimes {
    /// The host's CPU times now.
    pub fn read() -> Result<Self, ProvenanceError> {
        Self::parse(&std::fs::read_to_string("/proc/stat")?)
    }

    /// The CPU times of `/proc/stat`'s text.
    pub fn parse(stat: &str) -> Result<Self, ProvenanceError> {
        let line = stat
            .lines()
            .find(|l| l.starts_with("cpu "))
            .ok_or(ProvenanceError::Malformed("no cpu line"))?;
        let fields: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| ProvenanceError::Malformed("a field of the cpu line is not a number"))?;
        // user nice system idle iowait irq softirq steal guest guest_nice; guest time is
        // already counted in user and nice.
        let steal = *fields
            .get(7)
            .ok_or(ProvenanceError::Malformed("no steal column"))?;
        Ok(Self {
            total: fields.iter().take(8).sum(),
            steal,
            idle: fields.get(3).copied().unwrap_or(0) + fields.get(4).copied().unwrap_or(0),
        })
    }

    /// Ticks every CPU was busy (not idle, not waiting for I/O) and ticks in all, since `self`
    /// up to `later`.
    pub fn busy_since(&self, later: &CpuTimes) -> (u64, u64) {
        let total = later.total.saturating_sub(self.total);
        let idle = later.idle.saturating_sub(self.idle);
        (total.saturating_sub(idle), total)
    }

    /// The steal time from `self` up to `later`.
    pub fn steal_until(&self, later: &CpuTimes) -> Steal {
        let hz = ticks_per_second();
        Steal {
            steal_s: later.steal.saturating_sub(self.steal) as f64 / hz,
            cpu_time_s: later.total.saturating_sub(self.total) as f64 / hz,
        }
    }
}

/// Steal time over a run: time the host ran something else while this machine's CPUs wanted
/// to run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Steal {
    pub steal_s: f64,
    /// CPU time of all CPUs over the run, s.
    pub cpu_time_s: f64,
}

impl Steal {
    /// `0.05 s of 308 s of CPU time (0.02 %)`.
    pub fn text(&self) -> String {
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

/// Clock ticks a second (`CLK_TCK`), 100 when the system does not say.
pub fn ticks_per_second() -> f64 {
    nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)
        .ok()
        .flatten()
        .map_or(100.0, |t| t as f64)
}

/// What `program args…` printed, trimmed; empty when it failed or is missing.
pub fn output(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

/// The commit checked out (short hash) and the tracked files changed since.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GitState {
    pub commit: String,
    pub changed: Vec<String>,
}

impl GitState {
    /// The working directory's; `None` outside a git checkout (or without git).
    pub fn read() -> Option<Self> {
        let commit = output("git", &["rev-parse", "--short", "HEAD"]);
        if commit.is_empty() {
            return None;
        }
        let changed = output("git", &["status", "--porcelain", "--untracked-files=no"])
            .lines()
            .map(|l| l.trim().to_string())
            .collect();
        Some(Self { commit, changed })
    }

    /// Uncommitted changes to tracked files.
    pub fn dirty(&self) -> bool {
        !self.changed.is_empty()
    }
}

/// `2026-11-26 09:05 UTC`, now.
pub fn utc_date() -> String {
    output("date", &["-u", "+%Y-%m-%d %H:%M UTC"])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cpu_line_gives_total_steal_and_idle() {
        let stat = "cpu  100 5 50 1000 20 3 2 7 40 0\ncpu0 1 2 3 4 5 6 7 8 9 10\n";
        let t = CpuTimes::parse(stat).unwrap();
        assert_eq!(
            t,
            CpuTimes {
                total: 1187,
                steal: 7,
                idle: 1020
            }
        );
        let later = CpuTimes {
            total: 1387,
            steal: 17,
            idle: 1120,
        };
        assert_eq!(t.busy_since(&later), (100, 200));
        assert!(CpuTimes::parse("cpu  1 2 3\n").is_err());
        assert!(CpuTimes::parse("intr 5\n").is_err());
    }
}
