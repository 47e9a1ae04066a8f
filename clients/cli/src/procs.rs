//! Starting the workspace's other programs from the CLI (`chassis demo`, `chassis replay`).

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{Ticker, now_ns};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// The program `name` installed next to this `chassis` executable; when it is missing, the
/// error says how to build it.
pub fn sibling(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("finding this executable")?;
    let path = exe.with_file_name(name);
    if !path.exists() {
        bail!(
            "{} is missing: build it with `{}`",
            path.display(),
            build_command(&exe, name)
        );
    }
    Ok(path)
}

/// The command that builds the program `name` beside the executable `exe`: a debug build when
/// `exe` is in cargo's `debug` directory, else a release build. Every program the CLI starts is
/// in the package of its own name; the bridges (`chassis-foxglove`, …) are not in the default
/// `cargo build`.
fn build_command(exe: &Path, name: &str) -> String {
    let debug = exe
        .parent()
        .and_then(Path::file_name)
        .is_some_and(|dir| dir == "debug");
    if debug {
        format!("cargo build -p {name}")
    } else {
        format!("cargo build --release -p {name}")
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_program_is_built_in_the_profile_of_the_cli_that_needs_it() {
        assert_eq!(
            build_command(Path::new("/src/target/release/chassis"), "chassis-foxglove"),
            "cargo build --release -p chassis-foxglove"
        );
        assert_eq!(
            build_command(Path::new("/src/target/debug/chassis"), "chassis-foxglove"),
            "cargo build -p chassis-foxglove"
        );
        assert_eq!(
            build_command(Path::new("/usr/bin/chassis"), "chassisd"),
            "cargo build --release -p chassisd"
        );
    }
}
