//! A test hook, never for a robot: the event loop's thread stalls on request, alone, as a hung
//! loop would, while the process's other threads (the simulated chassis) run on. The watchdog
//! test uses it to show that `WATCHDOG=1` comes from the loop and not from a timer beside it —
//! a `SIGSTOP` freezes every thread and cannot tell the two apart.
//!
//! It exists only when chassisd starts with [`TEST_LOOP_STALL_ENV`] set to a file path (chassisd
//! warns at start that it is armed). After every pass the loop then looks for that file; when it
//! is there, the loop reads the milliseconds written in it (at most [`LoopStall::LONGEST`]),
//! removes it and sleeps that long. Without the variable nothing is looked for.

use std::path::PathBuf;
use std::time::Duration;

use chassis_ipc::TEST_LOOP_STALL_ENV;
use tracing::warn;

/// The armed hook: the file that asks for a stall.
#[derive(Debug)]
pub(super) struct LoopStall {
    file: PathBuf,
}

impl LoopStall {
    /// The longest stall one request asks for.
    pub(super) const LONGEST: Duration = Duration::from_secs(10);

    /// The hook, when [`TEST_LOOP_STALL_ENV`] names a file (warned about at start).
    pub(super) fn from_env() -> Option<Self> {
        let file = PathBuf::from(std::env::var_os(TEST_LOOP_STALL_ENV)?);
        if file.as_os_str().is_empty() {
            return None;
        }
        warn!(
            "{TEST_LOOP_STALL_ENV} is set: a test hook stalls the event loop whenever {} \
             appears; never set it on a robot",
            file.display()
        );
        Some(Self { file })
    }

    /// Stalls the calling thread (the loop's) if the file asks for it; returns how long.
    pub(super) fn check(&self) -> Option<Duration> {
        let text = std::fs::read_to_string(&self.file).ok()?;
        if let Err(err) = std::fs::remove_file(&self.file) {
            warn!("test hook: removing {}: {err}", self.file.display());
        }
        let Ok(ms) = text.trim().parse::<u64>() else {
            warn!(
                "test hook: {} holds {text:?}, not a number of milliseconds",
                self.file.display()
            );
            return None;
        };
        let stall = Duration::from_millis(ms).min(Self::LONGEST);
        warn!("test hook: the event loop stalls for {stall:?}");
        // The loop's own thread, on purpose: that is the hang this hook stands for.
        #[allow(clippy::disallowed_methods)]
        std::thread::sleep(stall);
        Some(stall)
    }
}
