//! The operator side of a fleet (`--mirror-all`, `--robots NAMES`): every robot found through
//! Zenoh's own liveliness, mirrored into this computer's iceoryx2 under its name.
//!
//! One Zenoh session connects to every endpoint given (each robot's, in peer mode; Zenoh keeps
//! retrying the unreachable ones in the background, so a robot switched on later is reached
//! then). A liveliness subscriber on `chassis/<pattern>/alive` — with history, so robots that
//! were there first count — names each robot the moment its robot side declares its token; a
//! mirror ([`crate::mirror::serve`]) starts for each new name on its own threads and the shared
//! session. A robot that leaves keeps its mirror: its last state is published again marked
//! [`LinkFlags::REMOTE_LOST`](chassis_client::LinkFlags::REMOTE_LOST) (see
//! [`crate::link_watch::LinkWatch`]), and it resumes by itself when the robot is back. Each
//! robot's TLS certificate and access list apply to its own link, as with one robot.
//!
//! Nothing here is a registry: which robots exist is what Zenoh's liveliness says.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use chassis_client::{termination_requested, valid_robot_name};
use zenoh::Wait as _;
use zenoh::sample::SampleKind;

use crate::mirror;
use crate::net::{self, Net};

/// How often the loop looks at the stop flag and at finished mirrors.
const POLL: Duration = Duration::from_millis(100);

/// What the fleet's operator side needs to know.
#[derive(Debug, Clone)]
pub struct Config {
    pub net: Net,
    /// Key-expression chunks naming the robots to mirror: `*` (every robot), a name, or a
    /// pattern such as `scout$*`.
    pub patterns: Vec<String>,
}

/// The key expression of the liveliness tokens of the robots `pattern` names.
pub fn alive_key(pattern: &str) -> String {
    format!("chassis/{pattern}/alive")
}

/// Checks a robot pattern: one key-expression chunk (`*`, a name, `scout$*`), no `/`.
pub fn check_pattern(pattern: &str) -> anyhow::Result<()> {
    let ok = !pattern.is_empty()
        && pattern.len() <= 64
        && !pattern.contains("**")
        && pattern
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || "-_*$".contains(c))
        && zenoh::key_expr::KeyExpr::try_from(alive_key(pattern)).is_ok();
    if !ok {
        anyhow::bail!(
            "'{pattern}' is not a robot name or a key-expression chunk naming robots (`*`, `scout$*`)"
        );
    }
    Ok(())
}

/// The robot a liveliness token's key names (`chassis/<name>/alive`), if it is a valid name.
pub fn robot_of(key: &str) -> Option<&str> {
    key.strip_prefix("chassis/")
        .and_then(|rest| rest.strip_suffix("/alive"))
        .filter(|name| valid_robot_name(name))
}

struct Mirror {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<anyhow::Result<()>>,
}

/// Runs the fleet's operator side until SIGINT/SIGTERM.
pub fn run(config: &Config) -> anyhow::Result<()> {
    if config.patterns.is_empty() {
        anyhow::bail!("no robot pattern");
    }
    let session = net::open(net::config(&config.net, "fleet", &[])?)?;
    eprintln!(
        "chassis-zenoh: mirroring every robot matching {} from {}",
        config.patterns.join(", "),
        config.net.endpoints.join(", ")
    );
    let (tx, rx) = mpsc::channel::<(String, bool)>();
    let mut subscribers = Vec::new();
    for pattern in &config.patterns {
        let key = alive_key(pattern);
        let tx = tx.clone();
        subscribers.push(
            session
                .liveliness()
                .declare_subscriber(key.clone())
                .history(true)
                .callback(move |sample| {
                    let _ = tx.send((
                        sample.key_expr().as_str().to_string(),
                        sample.kind() == SampleKind::Put,
                    ));
                })
                .wait()
                .map_err(|e| anyhow::anyhow!("watching {key}: {e}"))?,
        );
    }
    drop(tx);

    let mut mirrors: HashMap<String, Mirror> = HashMap::new();
    while !termination_requested() {
        match rx.recv_timeout(POLL) {
            Ok((key, alive)) => {
                let Some(name) = robot_of(&key) else {
                    tracing::warn!(key, "a liveliness token that names no robot");
                    continue;
                };
                if !alive {
                    // The robot's own mirror marks it lost; the mirror stays for its return.
                    eprintln!("chassis-zenoh: robot '{name}' left");
                    continue;
                }
                if mirrors.contains_key(name) {
                    eprintln!("chassis-zenoh: robot '{name}' is back");
                    continue;
                }
                eprintln!("chassis-zenoh: found robot '{name}': mirroring it here");
                let stop = Arc::new(AtomicBool::new(false));
                let (thread_name, thread_session, thread_stop) =
                    (name.to_string(), session.clone(), stop.clone());
                let thread = std::thread::Builder::new()
                    .name(format!("mirror/{name}"))
                    .spawn(move || mirror::serve(&thread_name, &thread_session, &thread_stop))?;
                mirrors.insert(name.to_string(), Mirror { stop, thread });
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        // A mirror that failed (its name served here already, a port it could not make) is
        // reported and forgotten: the robot's next liveliness token tries again.
        let ended: Vec<String> = mirrors
            .iter()
            .filter(|(_, m)| m.thread.is_finished())
            .map(|(name, _)| name.clone())
            .collect();
        for name in ended {
            if let Some(m) = mirrors.remove(&name) {
                match m.thread.join() {
                    Ok(Ok(())) => eprintln!("chassis-zenoh: the mirror of '{name}' ended"),
                    Ok(Err(e)) => eprintln!("chassis-zenoh: the mirror of '{name}' failed: {e:#}"),
                    Err(_) => eprintln!("chassis-zenoh: the mirror of '{name}' panicked"),
                }
            }
        }
    }
    for m in mirrors.values() {
        m.stop.store(true, Ordering::Relaxed);
    }
    let mut failures = Vec::new();
    for (name, m) in mirrors {
        match m.thread.join() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => failures.push(format!("{name}: {e:#}")),
            Err(_) => failures.push(format!("{name}: a thread panicked")),
        }
    }
    drop(subscribers);
    let _ = session.close().wait();
    if !failures.is_empty() {
        anyhow::bail!("{}", failures.join("; "));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn only_valid_robot_names_are_taken_from_tokens() {
        assert_eq!(robot_of("chassis/scout1/alive"), Some("scout1"));
        assert_eq!(robot_of("chassis/Bad!/alive"), None);
        assert_eq!(robot_of("chassis/a/b/alive"), None);
        assert_eq!(robot_of("other/a/alive"), None);
        assert_eq!(alive_key("*"), "chassis/*/alive");
        for good in ["*", "titan", "scout$*", "r-1_a"] {
            assert!(check_pattern(good).is_ok(), "{good}");
        }
        for bad in ["", "a/b", "**", "Titan", "$*$*x/"] {
            assert!(check_pattern(bad).is_err(), "{bad}");
        }
    }
}
