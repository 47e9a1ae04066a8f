//! Where a run's figures come from: the commit (a tree with uncommitted changes is refused for
//! figures written to files, unless allowed, and then marked DIRTY), the date, the command line,
//! and the host's steal time over the run, read from `/proc/stat` at its start and end.

use anyhow::bail;
use chassis_provenance::GitState;
pub use chassis_provenance::{CpuTimes, Steal};
use serde::{Deserialize, Serialize};

/// Commit, date, command and steal time of one run.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
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

impl Provenance {
    /// Notes the commit and `/proc/stat` now. With `strict`, a checkout with uncommitted changes
    /// (or none at all) is an error unless `allow_dirty`.
    pub fn begin(strict: bool, allow_dirty: bool) -> anyhow::Result<Self> {
        let git = GitState::read();
        let dirty = git.as_ref().is_none_or(|g| !g.changed.is_empty());
        match &git {
            _ if !strict || !dirty || allow_dirty => {}
            None => bail!(
                "not in a git checkout: figures written to files must name their commit \
                 (run from the workspace, or pass --allow-dirty)"
            ),
            Some(g) => bail!(
                "the git tree has uncommitted changes ({}): figures written to files must come \
                 from a commit. Commit them, or pass --allow-dirty for a local run (the files \
                 then say DIRTY)",
                g.changed.join(", ")
            ),
        }
        Ok(Self {
            commit: git.map_or_else(|| "unknown".into(), |g| g.commit),
            dirty,
            date: chassis_provenance::utc_date(),
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
        let steal = self.start.steal_until(&CpuTimes::read()?);
        self.steal_s = steal.steal_s;
        self.cpu_time_s = steal.cpu_time_s;
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
        Steal {
            steal_s: self.steal_s,
            cpu_time_s: self.cpu_time_s,
        }
        .text()
    }
}
