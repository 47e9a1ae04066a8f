//! The Zenoh configuration of either side: explicit endpoints only (no multicast scouting, no
//! gossip), plain TCP only on loopback unless asked, TLS with mutual authentication, and on the
//! robot side an access list naming what the operator's certificate may do.

use std::net::IpAddr;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use serde_json::json;
use zenoh::Config;

/// The files `chassis-zenoh gen-certs DIR` writes, and each side reads.
pub const CA_CERT: &str = "ca.pem";
pub const ROBOT_CERT: &str = "robot.pem";
pub const ROBOT_KEY: &str = "robot-key.pem";
pub const OPERATOR_CERT: &str = "operator.pem";
pub const OPERATOR_KEY: &str = "operator-key.pem";
/// Common name of the operator's certificate: the subject of the robot side's access list.
pub const OPERATOR_CN: &str = "chassis-operator";
/// Common name of the robot's certificate.
pub const ROBOT_CN: &str = "chassis-robot";

/// Which side this process is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Robot,
    Operator,
}

/// What the command line says about the network.
#[derive(Debug, Clone)]
pub struct Net {
    pub role: Role,
    /// `tcp/ADDR:PORT` or `tls/ADDR:PORT`.
    pub endpoints: Vec<String>,
    /// The directory `gen-certs` wrote (needed for `tls/` endpoints).
    pub certs: Option<PathBuf>,
    /// Plain TCP beyond loopback.
    pub insecure: bool,
    /// Link lease, ms: how long a silent link lives before the session drops it.
    pub lease_ms: u64,
}

/// True when the endpoint's host is on this machine only.
pub fn is_loopback(address: &str) -> bool {
    // The host part: `tcp/10.0.0.1:7447` → `10.0.0.1`, `tcp/[::1]:7447` → `::1`.
    let address = address.split(['?', '#']).next().unwrap_or(address);
    let host = address.rsplit_once(':').map_or(address, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost" || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Checks one endpoint against the security rules; returns whether it is TLS.
fn check_endpoint(endpoint: &str, net: &Net) -> anyhow::Result<bool> {
    let Some((proto, address)) = endpoint.split_once('/') else {
        bail!("endpoint '{endpoint}' is not PROTOCOL/ADDRESS:PORT (tcp/… or tls/…)");
    };
    if !address.contains(':') {
        bail!("endpoint '{endpoint}' has no port");
    }
    match proto {
        "tls" => {
            if net.certs.is_none() {
                bail!(
                    "endpoint '{endpoint}' is TLS: give --certs DIR (made by `chassis-zenoh gen-certs DIR`)"
                );
            }
            Ok(true)
        }
        "tcp" => {
            if !is_loopback(address) && !net.insecure {
                bail!(
                    "refusing plain TCP on '{endpoint}': anyone on that network could drive the \
                     robot. Use tls/{address} with --certs DIR, or --insecure on a network you trust"
                );
            }
            Ok(false)
        }
        other => bail!("endpoint '{endpoint}': protocol '{other}' is not tcp or tls"),
    }
}

fn path_json(dir: &Path, file: &str) -> anyhow::Result<String> {
    let path = dir.join(file);
    if !path.is_file() {
        bail!(
            "{} is missing (make it with `chassis-zenoh gen-certs {}`)",
            path.display(),
            dir.display()
        );
    }
    Ok(serde_json::to_string(&path.to_string_lossy())?)
}

fn set(config: &mut Config, key: &str, value: &str) -> anyhow::Result<()> {
    config
        .insert_json5(key, value)
        .map_err(|e| anyhow::anyhow!("zenoh config {key} = {value}: {e}"))
}

/// The Zenoh configuration of this side. `robot` and `remote_sources` feed the robot side's
/// access list (under TLS).
pub fn config(net: &Net, robot: &str, remote_sources: &[String]) -> anyhow::Result<Config> {
    if net.endpoints.is_empty() {
        bail!("no endpoint");
    }
    let mut tls = false;
    for endpoint in &net.endpoints {
        tls |= check_endpoint(endpoint, net)?;
    }
    let mut config = Config::default();
    set(&mut config, "mode", "\"peer\"")?;
    // No discovery on any interface: the peers are the endpoints given, nothing else.
    set(&mut config, "scouting/multicast/enabled", "false")?;
    // Nor does a peer learn other peers from the ones it knows: robots of one operator never
    // try to connect to each other.
    set(&mut config, "scouting/gossip/enabled", "false")?;
    set(
        &mut config,
        "transport/link/tx/lease",
        &net.lease_ms.to_string(),
    )?;
    let endpoints = serde_json::to_string(&net.endpoints)?;
    match net.role {
        Role::Robot => {
            set(&mut config, "listen/endpoints", &endpoints)?;
            set(&mut config, "connect/endpoints", "[]")?;
        }
        Role::Operator => {
            set(&mut config, "listen/endpoints", "[]")?;
            set(&mut config, "connect/endpoints", &endpoints)?;
            // Start even while the robot is unreachable, and keep trying in the background
            // (a peer's connect endpoints with an endless timeout and no exit on failure).
            set(&mut config, "connect/timeout_ms", "-1")?;
            set(&mut config, "connect/exit_on_failure", "false")?;
            set(
                &mut config,
                "connect/retry",
                r#"{"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}"#,
            )?;
        }
    }
    if let Some(dir) = net.certs.as_deref().filter(|_| tls) {
        let base = "transport/link/tls";
        set(
            &mut config,
            &format!("{base}/root_ca_certificate"),
            &path_json(dir, CA_CERT)?,
        )?;
        set(&mut config, &format!("{base}/enable_mtls"), "true")?;
        let (cert, key, side) = match net.role {
            Role::Robot => (ROBOT_CERT, ROBOT_KEY, "listen"),
            Role::Operator => (OPERATOR_CERT, OPERATOR_KEY, "connect"),
        };
        set(
            &mut config,
            &format!("{base}/{side}_certificate"),
            &path_json(dir, cert)?,
        )?;
        set(
            &mut config,
            &format!("{base}/{side}_private_key"),
            &path_json(dir, key)?,
        )?;
        if net.role == Role::Robot {
            set(
                &mut config,
                "access_control",
                &access_list(robot, remote_sources).to_string(),
            )?;
        }
    }
    Ok(config)
}

/// The robot side's access list: everything is denied but what a holder of the operator's
/// certificate needs — reading the robot's publications, asking its control and description
/// queryables, answering the robot side's clock queries, publishing on its remote sources — and
/// what the robot side itself sends.
fn access_list(robot: &str, remote_sources: &[String]) -> serde_json::Value {
    let all = format!("chassis/{robot}/**");
    let cmds: Vec<String> = remote_sources
        .iter()
        .map(|s| format!("chassis/{robot}/cmd/{s}"))
        .collect();
    let mut rules = vec![
        json!({
            "id": "operator-reads",
            "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [all],
        }),
        // A fleet's operator asks which robots are alive with one wildcard (`chassis/*/alive`):
        // this robot answers with its own token only.
        json!({
            "id": "operator-finds-robots",
            "messages": ["declare_liveliness_subscriber", "liveliness_query"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": ["chassis/*/alive"],
        }),
        json!({
            "id": "operator-controls",
            "messages": ["query"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [
                format!("chassis/{robot}/control"),
                format!("chassis/{robot}/robot"),
            ],
        }),
        json!({
            "id": "operator-clock",
            "messages": ["declare_queryable", "reply"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [format!("chassis/{robot}/clock")],
        }),
        json!({
            "id": "robot-asks-the-clock",
            "messages": ["query"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": [format!("chassis/{robot}/clock")],
        }),
        json!({
            "id": "robot-publishes",
            "messages": ["put", "reply", "declare_queryable", "declare_subscriber", "liveliness_token"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": [all],
        }),
    ];
    if !cmds.is_empty() {
        rules.push(json!({
            "id": "operator-drives",
            "messages": ["put"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": cmds,
        }));
    }
    let ids: Vec<serde_json::Value> = rules.iter().map(|r| r["id"].clone()).collect();
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": [{"id": "operator", "cert_common_names": [OPERATOR_CN]}],
        "policies": [{"rules": ids, "subjects": ["operator"]}],
    })
}

/// Reads a hint for the error of a failed session open.
pub fn open(config: Config) -> anyhow::Result<zenoh::Session> {
    use zenoh::Wait as _;
    zenoh::open(config)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("opening the Zenoh session")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn net(role: Role, endpoint: &str) -> Net {
        Net {
            role,
            endpoints: vec![endpoint.into()],
            certs: None,
            insecure: false,
            lease_ms: 3000,
        }
    }

    #[test]
    fn plain_tcp_is_refused_beyond_loopback_unless_insecure() {
        assert!(config(&net(Role::Robot, "tcp/127.0.0.1:7447"), "titan", &[]).is_ok());
        assert!(config(&net(Role::Operator, "tcp/[::1]:7447"), "titan", &[]).is_ok());
        assert!(config(&net(Role::Robot, "tcp/localhost:7447"), "titan", &[]).is_ok());
        let err = config(&net(Role::Robot, "tcp/10.77.0.1:7447"), "titan", &[]).unwrap_err();
        assert!(err.to_string().contains("refusing plain TCP"), "{err}");
        let err = config(&net(Role::Operator, "tcp/0.0.0.0:7447"), "titan", &[]).unwrap_err();
        assert!(err.to_string().contains("--insecure"), "{err}");
        let insecure = Net {
            insecure: true,
            ..net(Role::Robot, "tcp/10.77.0.1:7447")
        };
        assert!(config(&insecure, "titan", &[]).is_ok());
        let err = config(&net(Role::Robot, "tls/10.77.0.1:7447"), "titan", &[]).unwrap_err();
        assert!(err.to_string().contains("--certs"), "{err}");
        assert!(config(&net(Role::Robot, "udp/127.0.0.1:7447"), "titan", &[]).is_err());
        assert!(config(&net(Role::Robot, "tcp/127.0.0.1"), "titan", &[]).is_err());
    }

    #[test]
    fn the_access_list_lets_the_operator_drive_only_the_remote_sources() {
        let acl = access_list("titan", &["remote".into()]);
        assert_eq!(acl["default_permission"], "deny");
        let drives = acl["rules"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == "operator-drives")
            .unwrap();
        assert_eq!(drives["key_exprs"], json!(["chassis/titan/cmd/remote"]));
        assert_eq!(acl["subjects"][0]["cert_common_names"][0], OPERATOR_CN);
        // The operator answers the robot side's clock queries, and nothing else there.
        let clock = acl["rules"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == "operator-clock")
            .unwrap();
        assert_eq!(clock["key_exprs"], json!(["chassis/titan/clock"]));
        assert_eq!(clock["flows"], json!(["ingress"]));
        let none = access_list("titan", &[]);
        assert!(
            none["rules"]
                .as_array()
                .unwrap()
                .iter()
                .all(|r| r["id"] != "operator-drives")
        );
    }
}
