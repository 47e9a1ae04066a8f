//! The held locks on disk: what the engine asks to keep ([`crate::engine::Engine::poll_held_locks`])
//! survives a crash, a `kill -9` and a reboot, so a latched stop is cleared only by a release.
//!
//! One JSON file per robot, `<state-dir>/<name>.locks.json`:
//!
//! ```json
//! {"robot":"r1","locks":[{"name":"estop","holder":"operator","since_unix_ns":1764000000000000000}]}
//! ```
//!
//! It is written atomically: a temporary file beside it is written and `fsync`ed, renamed over
//! it, and the directory is `fsync`ed, so a crash at any moment leaves either the old set or the
//! new one. `since_unix_ns` is wall-clock time (the monotonic clock restarts with the machine);
//! it converts back to `CLOCK_MONOTONIC` on load. A missing file means nothing was held; a file
//! that cannot be read or understood is set aside as `<name>.locks.json.corrupt` and reported, and
//! the service starts with the e-stop held ([`crate::engine::Engine::restore_failed`]).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use chassis_protocols::Timestamp;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::engine::HeldLock;

/// Why the held locks could not be loaded or kept.
#[derive(Debug, Error)]
pub enum LockFileError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path} is not a held-lock file: {source}")]
    Parse {
        path: String,
        source: serde_json::Error,
    },
    #[error("{path} was written for robot '{robot}'")]
    OtherRobot { path: String, robot: String },
    #[error("writing {path}: {source}")]
    Write {
        path: String,
        source: std::io::Error,
    },
}

#[derive(Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct FileLock {
    name: String,
    holder: String,
    since_unix_ns: u64,
}

#[derive(Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct FileBody {
    robot: String,
    locks: Vec<FileLock>,
}

/// The two clocks read at the same instant: converts a lock's start between them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clocks {
    /// `CLOCK_MONOTONIC`.
    pub monotonic: Timestamp,
    /// `CLOCK_REALTIME`, ns since the Unix epoch.
    pub unix_ns: u64,
}

impl Clocks {
    fn to_unix(self, since: Timestamp) -> u64 {
        let age = self.monotonic.as_nanos().saturating_sub(since.as_nanos());
        self.unix_ns.saturating_sub(age)
    }

    /// A start before this boot reads as the boot itself (1 ns: a held lock's `since_ns` is
    /// never the 0 of a free one).
    fn to_monotonic(self, since_unix_ns: u64) -> Timestamp {
        let age = self.unix_ns.saturating_sub(since_unix_ns);
        Timestamp::from_nanos(self.monotonic.as_nanos().saturating_sub(age).max(1))
    }
}

/// The held-lock file of one robot.
#[derive(Debug, Clone)]
pub struct LockFile {
    robot: String,
    dir: PathBuf,
    path: PathBuf,
}

impl LockFile {
    /// The file of robot `name` in `dir`.
    pub fn new(dir: &Path, name: &str) -> Self {
        Self {
            robot: name.to_string(),
            dir: dir.to_path_buf(),
            path: dir.join(format!("{name}.locks.json")),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The locks held when the file was last written (none when there is no file).
    pub fn load(&self, clocks: Clocks) -> Result<Vec<HeldLock>, LockFileError> {
        let path = self.path.display().to_string();
        let text = match std::fs::read_to_string(&self.path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(source) => return Err(LockFileError::Read { path, source }),
        };
        let body: FileBody =
            serde_json::from_str(&text).map_err(|source| LockFileError::Parse {
                path: path.clone(),
                source,
            })?;
        if body.robot != self.robot {
            return Err(LockFileError::OtherRobot {
                path,
                robot: body.robot,
            });
        }
        Ok(body
            .locks
            .into_iter()
            .map(|l| HeldLock {
                name: l.name,
                holder: l.holder,
                since: clocks.to_monotonic(l.since_unix_ns),
            })
            .collect())
    }

    /// Moves an unusable file out of the way (kept for a post-mortem); returns where.
    pub fn set_aside(&self) -> Option<PathBuf> {
        let aside = self.dir.join(format!("{}.locks.json.corrupt", self.robot));
        std::fs::rename(&self.path, &aside).ok().map(|()| aside)
    }

    /// Writes `locks` atomically: temporary file, `fsync`, rename, `fsync` of the directory.
    pub fn store(&self, locks: &[HeldLock], clocks: Clocks) -> Result<(), LockFileError> {
        let body = FileBody {
            robot: self.robot.clone(),
            locks: locks
                .iter()
                .map(|l| FileLock {
                    name: l.name.clone(),
                    holder: l.holder.clone(),
                    since_unix_ns: clocks.to_unix(l.since),
                })
                .collect(),
        };
        let write = |path: &Path, source| LockFileError::Write {
            path: path.display().to_string(),
            source,
        };
        let mut text = serde_json::to_string(&body).map_err(|e| write(&self.path, e.into()))?;
        text.push('\n');
        std::fs::create_dir_all(&self.dir).map_err(|e| write(&self.dir, e))?;
        let temporary = self.dir.join(format!(".{}.locks.json.new", self.robot));
        let mut file = File::create(&temporary).map_err(|e| write(&temporary, e))?;
        file.write_all(text.as_bytes())
            .and_then(|()| file.sync_all())
            .map_err(|e| write(&temporary, e))?;
        drop(file);
        std::fs::rename(&temporary, &self.path).map_err(|e| write(&self.path, e))?;
        File::open(&self.dir)
            .and_then(|dir| dir.sync_all())
            .map_err(|e| write(&self.dir, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(test: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("chassisd-lockfile-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    const CLOCKS: Clocks = Clocks {
        monotonic: Timestamp::from_millis(50_000),
        unix_ns: 1_764_000_000_000_000_000,
    };

    #[test]
    fn the_held_set_reads_back_with_its_age_across_a_restart() {
        let dir = scratch("roundtrip");
        let file = LockFile::new(&dir, "r1");
        assert_eq!(file.load(CLOCKS).unwrap(), vec![], "no file: nothing held");
        let held = vec![HeldLock {
            name: "estop".into(),
            holder: "safety".into(),
            since: Timestamp::from_millis(20_000),
        }];
        file.store(&held, CLOCKS).unwrap();
        // Restarted 100 s later on a machine whose monotonic clock restarted (a reboot).
        let later = Clocks {
            monotonic: Timestamp::from_millis(200_000),
            unix_ns: CLOCKS.unix_ns + 100_000_000_000,
        };
        let back = file.load(later).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(
            (back[0].name.as_str(), back[0].holder.as_str()),
            ("estop", "safety")
        );
        assert_eq!(back[0].since, Timestamp::from_millis(200_000 - 130_000));
        // Held since before this boot: the boot.
        let rebooted = Clocks {
            monotonic: Timestamp::from_millis(5_000),
            unix_ns: later.unix_ns,
        };
        assert_eq!(
            file.load(rebooted).unwrap()[0].since,
            Timestamp::from_nanos(1)
        );
        file.store(&[], CLOCKS).unwrap();
        assert_eq!(file.load(CLOCKS).unwrap(), vec![], "a release clears it");
        assert!(!dir.join(".r1.locks.json.new").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_corrupt_or_foreign_file_is_an_error_and_can_be_set_aside() {
        let dir = scratch("corrupt");
        std::fs::create_dir_all(&dir).unwrap();
        let file = LockFile::new(&dir, "r1");
        std::fs::write(file.path(), "{\"robot\":\"r1\",\"locks\":[{\"na").unwrap();
        assert!(matches!(
            file.load(CLOCKS),
            Err(LockFileError::Parse { .. })
        ));
        std::fs::write(file.path(), "{\"robot\":\"r2\",\"locks\":[]}").unwrap();
        assert!(matches!(
            file.load(CLOCKS),
            Err(LockFileError::OtherRobot { .. })
        ));
        let aside = file.set_aside().unwrap();
        assert!(aside.exists() && !file.path().exists());
        std::fs::create_dir_all(file.path()).unwrap();
        assert!(matches!(file.load(CLOCKS), Err(LockFileError::Read { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
