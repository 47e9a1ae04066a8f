//! Starting the workspace's other programs from the CLI (`chassis demo`, `chassis replay`).

use std::path::PathBuf;
use std::process::{Child, Command};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{Ticker, now_ns};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// The program `name` installed next to this `chassis` executable.
pub fn sibling(name: &str) -> anyhow::Result<PathBuf> {
    let path = std::env::current_exe()
        .context("finding this executable")?
        .with_file_name(name);
    if !path.exists() {
        bail!(
            "{} is missing: it is built with the workspace (`cargo build --release`)",
            path.display()
        );
    }
    Ok(path)
}

/// Makes `command`'s process get SIGTERM when this one dies, however it dies.
pub fn die_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: between fork and exec the closure makes one async-signal-safe system call (prctl).
    unsafe {
        command.pre_exec(|| {
            nix::sys::prctl::set_pdeathsig(Signal::SIGTERM).map_err(std::io::Error::from)
        });
    }
}

/// Child processes, stopped in reverse order of start when dropped: SIGTERM, then SIGKILL
/// after `grace`.
#[derive(Debug, Default)]
pub struct Children {
    children: Vec<(String, Child)>,
}

impl Children {
    pub fn spawn(&mut self, label: &str, mut command: Command) -> anyhow::Result<u32> {
        die_with_parent(&mut command);
        let child = command
            .spawn()
            .with_context(|| format!("starting {label}"))?;
        let pid = child.id();
        self.children.push((label.to_string(), child));
        Ok(pid)
    }

    /// The first child that has exited, with its status.
    pub fn exited(&mut self) -> Option<(String, std::process::ExitStatus)> {
        self.children.iter_mut().find_map(|(label, child)| {
            child
                .try_wait()
                .ok()
                .flatten()
                .map(|status| (label.clone(), status))
        })
    }

    /// Stops every child, last started first.
    pub fn stop_all(&mut self, grace: Duration) {
        while let Some((label, mut child)) = self.children.pop() {
            if let Ok(pid) = i32::try_from(child.id()) {
                let _ = kill(Pid::from_raw(pid), Signal::SIGTERM);
            }
            let deadline = now_ns() + u64::try_from(grace.as_nanos()).unwrap_or(u64::MAX / 2);
            let mut ticker = Ticker::new(Duration::from_millis(20));
            loop {
                if child.try_wait().ok().flatten().is_some() {
                    break;
                }
                if now_ns() > deadline {
                    eprintln!("{label} did not stop within {grace:?}: killing it");
                    let _ = child.kill();
                    let _ = child.wait();
                    break;
                }
                ticker.wait();
            }
        }
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        self.stop_all(Duration::from_secs(3));
    }
}
