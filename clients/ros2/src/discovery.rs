//! How far the bridge's DDS participant reaches, from ROS 2's own switches.
//!
//! | switch | chassis-ros2 |
//! | --- | --- |
//! | `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, or unset, or `SYSTEM_DEFAULT` | **this computer only** (the default): the participant joins multicast and advertises locators on the loopback interface alone, so a peer on the robot's network neither discovers it nor is discovered |
//! | `ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET` | every interface, as ROS 2's DDS layers do by default: anyone on the robot's network can drive it |
//! | `ROS_AUTOMATIC_DISCOVERY_RANGE=OFF` | no automatic discovery: RustDDS has no list of static peers, so nothing is reachable; refused |
//! | `ROS_STATIC_PEERS=a;b` | RustDDS has no unicast initial-peers list: with `LOCALHOST` the peers are not reached (said loudly); with `SUBNET` they are if multicast reaches them |
//! | `ROS_LOCALHOST_ONLY=1` (deprecated since Iron) | as `LOCALHOST`; `=0` with no range set: as `SUBNET`, as before Iron |
//!
//! Unlike ROS 2, whose default range is `SUBNET`, the bridge's default is this computer: the
//! participant carries `cmd_vel` and the e-stop services, and a robot's network is not a place
//! where anyone who joins should drive it. Remote driving with authentication is chassis-zenoh's
//! (mTLS). The outputs (odom, tf, …) share the participant, so they are local by default too:
//! one participant keeps discovery simple, and `SUBNET` opens both.
//!
//! "This computer only" is a discovery setting, not a firewall: RustDDS still binds its unicast
//! sockets to every address, so a peer that already knows the bridge's ports and GUID could
//! address it directly. Where the robot's network is hostile, keep DDS off it (nftables) and
//! drive remotely through chassis-zenoh.

use std::net::{IpAddr, Ipv4Addr};

use thiserror::Error;

/// How far automatic discovery reaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// This computer only (the loopback interface).
    Localhost,
    /// Every interface.
    Subnet,
}

/// What the participant reaches and why, from the environment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reach {
    pub range: Range,
    /// `ROS_STATIC_PEERS`, which RustDDS cannot reach by unicast.
    pub static_peers: Vec<String>,
    /// Which switch decided, for the log.
    pub why: String,
}

/// A setting the bridge cannot follow.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ReachError {
    #[error(
        "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF: RustDDS has no list of static peers, so nothing could \
         reach the bridge; use LOCALHOST (the default) or SUBNET"
    )]
    Off,
    #[error(
        "ROS_AUTOMATIC_DISCOVERY_RANGE={0:?} is not one of SYSTEM_DEFAULT, LOCALHOST, SUBNET, OFF"
    )]
    Unknown(String),
}

impl Reach {
    /// From the values of `ROS_AUTOMATIC_DISCOVERY_RANGE`, `ROS_STATIC_PEERS` and
    /// `ROS_LOCALHOST_ONLY` (`None`: unset).
    pub fn from_switches(
        range: Option<&str>,
        static_peers: Option<&str>,
        localhost_only: Option<&str>,
    ) -> Result<Self, ReachError> {
        let static_peers: Vec<String> = static_peers
            .unwrap_or("")
            .split(';')
            .map(str::trim)
            .filter(|p| !p.is_empty())
            .map(String::from)
            .collect();
        let range_set = range.map(str::trim).filter(|r| !r.is_empty());
        let (range, why) = match range_set.map(str::to_ascii_uppercase).as_deref() {
            Some("LOCALHOST") => (
                Range::Localhost,
                "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST".to_string(),
            ),
            Some("SUBNET") => (
                Range::Subnet,
                "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET".to_string(),
            ),
            Some("OFF") => return Err(ReachError::Off),
            Some("SYSTEM_DEFAULT") | None => match localhost_only.map(str::trim) {
                Some("1") => (
                    Range::Localhost,
                    "ROS_LOCALHOST_ONLY=1 (deprecated: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)"
                        .to_string(),
                ),
                Some("0") if range_set.is_none() => (
                    Range::Subnet,
                    "ROS_LOCALHOST_ONLY=0 and no ROS_AUTOMATIC_DISCOVERY_RANGE".to_string(),
                ),
                _ => (
                    Range::Localhost,
                    "chassis-ros2's default: ROS_AUTOMATIC_DISCOVERY_RANGE unset or SYSTEM_DEFAULT"
                        .to_string(),
                ),
            },
            Some(_) => {
                return Err(ReachError::Unknown(
                    range_set.unwrap_or_default().to_string(),
                ));
            }
        };
        Ok(Self {
            range,
            static_peers,
            why,
        })
    }

    /// From this process' environment.
    pub fn from_env() -> Result<Self, ReachError> {
        let var = |name| std::env::var(name).ok();
        Self::from_switches(
            var("ROS_AUTOMATIC_DISCOVERY_RANGE").as_deref(),
            var("ROS_STATIC_PEERS").as_deref(),
            var("ROS_LOCALHOST_ONLY").as_deref(),
        )
    }

    /// The interface addresses the participant is kept to (`None`: all of them).
    pub fn only_networks(&self) -> Option<Vec<IpAddr>> {
        match self.range {
            Range::Localhost => Some(vec![IpAddr::V4(Ipv4Addr::LOCALHOST)]),
            Range::Subnet => None,
        }
    }

    /// One line for the log: what can reach the bridge's command inputs, and why.
    pub fn describe(&self) -> String {
        let mut line = match self.range {
            Range::Localhost => format!(
                "DDS reach: THIS COMPUTER ONLY ({}): cmd_vel, e_stop and the services take \
                 nothing from the network; set ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET to let the \
                 robot's network drive it",
                self.why
            ),
            Range::Subnet => format!(
                "DDS reach: THE WHOLE NETWORK ({}): anyone on a network this computer is on can \
                 publish cmd_vel and DRIVE the robot",
                self.why
            ),
        };
        if !self.static_peers.is_empty() {
            line.push_str(&format!(
                "; ROS_STATIC_PEERS ({}) NOT reached: RustDDS has no unicast peer list{}",
                self.static_peers.join(", "),
                match self.range {
                    Range::Localhost => "",
                    Range::Subnet => " (only where multicast reaches them)",
                }
            ));
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reach(range: Option<&str>, peers: Option<&str>, only: Option<&str>) -> Reach {
        Reach::from_switches(range, peers, only).unwrap()
    }

    #[test]
    fn this_computer_only_is_the_default() {
        assert_eq!(reach(None, None, None).range, Range::Localhost);
        assert_eq!(
            reach(Some("SYSTEM_DEFAULT"), None, None).range,
            Range::Localhost
        );
        assert_eq!(reach(Some(""), None, None).range, Range::Localhost);
        let r = reach(None, None, None);
        assert_eq!(
            r.only_networks(),
            Some(vec![IpAddr::V4(Ipv4Addr::LOCALHOST)])
        );
        assert!(
            r.describe().contains("THIS COMPUTER ONLY"),
            "{}",
            r.describe()
        );
    }

    #[test]
    fn the_range_opens_the_network_and_says_so() {
        let r = reach(Some("SUBNET"), None, None);
        assert_eq!((r.range, r.only_networks()), (Range::Subnet, None));
        assert!(r.describe().contains("DRIVE the robot"));
        assert_eq!(reach(Some("subnet"), None, None).range, Range::Subnet);
        assert_eq!(
            reach(Some("LOCALHOST"), None, Some("0")).range,
            Range::Localhost
        );
    }

    #[test]
    fn the_deprecated_switch_is_followed_where_the_range_is_not_set() {
        assert_eq!(reach(None, None, Some("1")).range, Range::Localhost);
        assert!(
            reach(None, None, Some("1"))
                .why
                .contains("ROS_LOCALHOST_ONLY=1")
        );
        assert_eq!(reach(None, None, Some("0")).range, Range::Subnet);
        // A range set wins over it.
        assert_eq!(reach(Some("SUBNET"), None, Some("1")).range, Range::Subnet);
    }

    #[test]
    fn off_and_unknown_ranges_are_refused_and_static_peers_are_said_unreachable() {
        assert_eq!(
            Reach::from_switches(Some("OFF"), None, None),
            Err(ReachError::Off)
        );
        assert!(matches!(
            Reach::from_switches(Some("LAN"), None, None),
            Err(ReachError::Unknown(_))
        ));
        let r = reach(None, Some("10.0.0.2; robot2;"), None);
        assert_eq!(r.static_peers, ["10.0.0.2", "robot2"]);
        assert!(r.describe().contains("NOT reached"), "{}", r.describe());
    }
}
