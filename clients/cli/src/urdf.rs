//! `chassis urdf`: the robot as a URDF ([`chassis_client::urdf`]), from the description a
//! running chassisd publishes (`--name`) or, with no chassisd, from the description chassisd
//! would publish for a registry robot's profile (`--robot`, as `decode` and `encode` take it).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{ClientError, Robot, RobotDescription};
use chassis_protocols::{Protocol, RobotKind};

/// How long a running chassisd has to hand its description over.
const DESCRIPTION_TIMEOUT: Duration = Duration::from_secs(1);

#[derive(Debug, clap::Args)]
pub struct UrdfArgs {
    /// The running robot's name (chassisd --name): its description as chassisd publishes it.
    #[arg(long, conflicts_with = "robot", required_unless_present = "robot")]
    pub name: Option<String>,
    /// A registry robot (titan, scout-mini, xbot, hunter, …) described without chassisd: its
    /// profile's defaults, or --protocol and --profile as for `decode`.
    #[arg(long)]
    pub robot: Option<RobotKind>,
    /// With --robot: AgileX wire protocol, v1 or v2.
    #[arg(long, conflicts_with = "name")]
    pub protocol: Option<Protocol>,
    /// With --robot: a TOML file of profile parameters (the `[profile]` table of chassisd's
    /// config).
    #[arg(long, conflicts_with = "name")]
    pub profile: Option<PathBuf>,
    /// Prefix of every link (frame) name, as chassis-ros2 --frame-prefix (`robot1/`).
    #[arg(long, default_value = "")]
    pub frame_prefix: String,
}

/// The description `args` names.
fn description(args: &UrdfArgs) -> anyhow::Result<RobotDescription> {
    if let Some(robot) = args.robot {
        let profile = crate::ProfileArgs {
            robot,
            protocol: args.protocol,
            profile: args.profile.clone(),
        }
        .load()?;
        return Ok(chassis_protocols::description::describe(&profile));
    }
    let name = args.name.as_deref().context("--name or --robot")?;
    let mut robot = Robot::connect(name)?;
    match robot.description(DESCRIPTION_TIMEOUT) {
        Ok(d) => Ok(d),
        Err(ClientError::NoDescription { .. }) => anyhow::bail!(
            "chassis/{name} published no description within {} s (chassisd older than the \
             description?); `chassis urdf --robot KIND` describes a registry robot",
            DESCRIPTION_TIMEOUT.as_secs()
        ),
        Err(e) => Err(e.into()),
    }
}

/// `chassis urdf`: the URDF on standard output.
pub fn run(args: &UrdfArgs) -> anyhow::Result<()> {
    let d = description(args)?;
    let text = chassis_client::urdf::urdf(&d, &args.frame_prefix)
        .with_context(|| format!("the URDF of {}", crate::described::title(&d)))?;
    print!("{text}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(robot: RobotKind) -> UrdfArgs {
        UrdfArgs {
            name: None,
            robot: Some(robot),
            protocol: None,
            profile: None,
            frame_prefix: String::new(),
        }
    }

    #[test]
    fn a_registry_robot_is_described_as_chassisd_describes_it() {
        for kind in RobotKind::ALL {
            let d = description(&args(kind)).unwrap();
            let expected = chassis_protocols::description::describe(&kind.entry().defaults());
            assert_eq!(d.kind_name(), expected.kind_name());
            let urdf = chassis_client::urdf::urdf(&d, "").unwrap();
            for j in d.joints() {
                assert!(
                    urdf.contains(&format!("<joint name=\"{}\"", j.name())),
                    "{kind}: {} missing",
                    j.name()
                );
            }
        }
    }

    #[test]
    fn name_and_robot_exclude_each_other() {
        use clap::Parser;
        let parse = |args: &[&str]| crate::Cli::try_parse_from(args);
        assert!(parse(&["chassis", "urdf", "--robot", "titan"]).is_ok());
        assert!(parse(&["chassis", "urdf", "--name", "r1", "--frame-prefix", "r1/"]).is_ok());
        assert!(parse(&["chassis", "urdf"]).is_err());
        assert!(parse(&["chassis", "urdf", "--name", "r1", "--robot", "titan"]).is_err());
        assert!(parse(&["chassis", "urdf", "--name", "r1", "--protocol", "v1"]).is_err());
    }
}
