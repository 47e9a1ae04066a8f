//! The operator side of a fleet (`--mirror-all`, `--robots NAMES`): every robot found through
//! Zenoh's own liveliness, mirrored into this computer's iceoryx2 under its name.
//!
//! One Zenoh session connects to every endpoint given (each robot's, in peer mode; Zenoh keeps
//! retrying the unreachable ones in the background, so a robot switched on later is reached
//! then). A liveliness subscriber on `chassis/<pattern>/alive` — with history, so robots that
//! were there first count — names each robot the moment its robot side declares its token; a
//! mirror ([`crate::mirror::serve`]) starts for each new name on its own threads and the shared
//! session. A robot that leaves keeps its mirror: its last state is published again marked
//! [`LinkFlags::REMOTE_LOST`] (see [`LinkWatch`]), and it resumes by itself when the robot is
//! back. Each robot's TLS certificate and access list apply to its own link, as with one robot.
//!
//! Nothing here is a registry: which robots exist is what Zenoh's liveliness says.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use chassis_client::{ChassisState, LinkFlags, termination_requested, valid_robot_name};
use zenoh::Wait as _;
use zenoh::sample::SampleKind;

use crate::mirror;
use crate::net::{self, Net};

/// A mirrored robot silent for this long is marked lost. chassisd refreshes its state at
/// least every 100 ms and the robot side forwards each refresh: five missed in a row.
pub const LOST_AFTER: Duration = Duration::from_millis(500);
/// While lost, the last state is published again this often (a reader that asks then gets an
/// answer, marked lost, rather than nothing).
const REPUBLISH_NS: u64 = 200_000_000;
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

/// The last state of a robot whose link is lost, marked so, to publish again.
#[derive(Debug, Clone, Copy)]
pub struct Lost {
    pub state: ChassisState,
    /// The first publication of this loss (log it), not a repetition.
    pub first: bool,
    pub why: &'static str,
}

/// Whether a mirrored robot is still heard, judged on local arrival times (the robot's stamps
/// are another clock): lost after [`LOST_AFTER`] of silence or when its liveliness token goes,
/// heard again with its next state. Time is a parameter.
#[derive(Debug, Clone)]
pub struct LinkWatch {
    lost_after_ns: u64,
    last_heard_ns: Option<u64>,
    last_state: Option<ChassisState>,
    lost_since_ns: Option<u64>,
    republished_ns: u64,
    why: &'static str,
}

impl LinkWatch {
    pub fn new(lost_after: Duration) -> Self {
        Self {
            lost_after_ns: u64::try_from(lost_after.as_nanos()).unwrap_or(u64::MAX),
            last_heard_ns: None,
            last_state: None,
            lost_since_ns: None,
            republished_ns: 0,
            why: "",
        }
    }

    /// A state sample arrived at `now`; true if the robot was lost until now.
    pub fn heard(&mut self, now_ns: u64, state: &ChassisState) -> bool {
        self.last_heard_ns = Some(now_ns);
        self.last_state = Some(*state);
        self.lost_since_ns.take().is_some()
    }

    /// The robot's liveliness token appeared (`true`) or went (`false`) at `now`.
    pub fn alive(&mut self, now_ns: u64, alive: bool) -> Option<Lost> {
        if alive || self.lost_since_ns.is_some() {
            return None;
        }
        self.lose(now_ns, "its liveliness token is gone")
    }

    /// At `now`: the state to publish again, marked lost, when the robot has been silent too
    /// long (first at the loss, then every 200 ms).
    pub fn poll(&mut self, now_ns: u64) -> Option<Lost> {
        if self.lost_since_ns.is_some() {
            if now_ns.saturating_sub(self.republished_ns) < REPUBLISH_NS {
                return None;
            }
            self.republished_ns = now_ns;
            return self.marked(false);
        }
        let heard = self.last_heard_ns?;
        if now_ns.saturating_sub(heard) <= self.lost_after_ns {
            return None;
        }
        self.lose(now_ns, "nothing heard for longer than the loss limit")
    }

    /// True while the robot is lost.
    #[cfg(test)]
    pub fn is_lost(&self) -> bool {
        self.lost_since_ns.is_some()
    }

    fn lose(&mut self, now_ns: u64, why: &'static str) -> Option<Lost> {
        self.lost_since_ns = Some(now_ns);
        self.republished_ns = now_ns;
        self.why = why;
        self.marked(true)
    }

    fn marked(&self, first: bool) -> Option<Lost> {
        let mut state = self.last_state?;
        state.link_flags |= LinkFlags::REMOTE_LOST;
        Some(Lost {
            state,
            first,
            why: self.why,
        })
    }
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

    const MS: u64 = 1_000_000;

    fn state(seq: u64) -> ChassisState {
        ChassisState {
            seq,
            ..ChassisState::default()
        }
    }

    #[test]
    fn a_robot_silent_past_the_limit_is_lost_with_its_last_state_and_heard_again_after() {
        let mut link = LinkWatch::new(Duration::from_millis(500));
        assert!(link.poll(0).is_none(), "never heard: nothing to publish");
        assert!(!link.heard(1_000 * MS, &state(7)));
        assert!(link.poll(1_400 * MS).is_none());
        assert!(link.poll(1_500 * MS).is_none(), "at the limit: not yet");
        let lost = link.poll(1_501 * MS).expect("lost past the limit");
        assert!(lost.first && link.is_lost());
        assert_eq!(lost.state.seq, 7);
        assert_ne!(lost.state.link_flags & LinkFlags::REMOTE_LOST, 0);
        // Published again every 200 ms while lost, not on every poll.
        assert!(link.poll(1_600 * MS).is_none());
        let again = link.poll(1_701 * MS).expect("again after 200 ms");
        assert!(!again.first);
        assert!(link.heard(1_800 * MS, &state(8)), "heard again");
        assert!(!link.is_lost());
        assert!(link.poll(2_000 * MS).is_none());
    }

    #[test]
    fn a_robot_whose_token_goes_is_lost_at_once() {
        let mut link = LinkWatch::new(Duration::from_millis(500));
        link.heard(0, &state(1));
        assert!(link.alive(10 * MS, true).is_none());
        let lost = link.alive(20 * MS, false).expect("lost with its token");
        assert!(lost.first);
        assert!(link.alive(30 * MS, false).is_none(), "lost once, not twice");
    }

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
