//! `chassis top`: a live dashboard of state, mux decisions, bus statistics and latency.

use clap::Args;

#[derive(Debug, Args)]
pub struct TopArgs {
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    pub name: String,
}

pub fn run(_args: &TopArgs) -> anyhow::Result<()> {
    anyhow::bail!("chassis top is being written")
}
