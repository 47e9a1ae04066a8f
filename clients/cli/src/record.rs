//! `chassis record` and `chassis replay`.

use std::path::PathBuf;

use clap::Args;

#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Output file: MCAP (frames, state, mux decisions), or a can-utils log with --candump.
    pub file: PathBuf,
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    pub name: String,
    /// Write the CAN frames as a `candump -l` log instead of MCAP.
    #[arg(long)]
    pub candump: bool,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    pub duration: Option<f64>,
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A recording: MCAP or a candump log.
    pub file: PathBuf,
}

pub fn record(_args: &RecordArgs) -> anyhow::Result<()> {
    anyhow::bail!("chassis record is being written")
}

pub fn replay(_args: &ReplayArgs) -> anyhow::Result<()> {
    anyhow::bail!("chassis replay is being written")
}
