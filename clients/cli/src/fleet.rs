//! `chassis fleet`: one row per robot served on this computer — by its chassisd, or mirrored
//! from another computer by `chassis-zenoh --mirror-all` — and `chassis control --all estop`.
//!
//! Robots are found by listing this computer's iceoryx2 services under the IPC prefix
//! (`chassis/<name>/state`, [`chassis_ipc::robots`]), again every second, so robots mirrored
//! later appear. Each robot is read by a thread of its own that blocks on the robot's state
//! events ([`Robot`] ports stay on the thread that made them): a latency is the sample's
//! `published_ns` (its publisher's clock: chassisd's, on the robot) → this process woken by it,
//! measured only for samples that woke the thread, never for a backlog. The link age is how long
//! ago this process last received a new sample (a higher `seq`), on its own clock.
//!
//! Across two computers `published_ns` is the robot's `CLOCK_MONOTONIC` and means nothing here:
//! a latency outside 0..60 s is shown as `clock?`, not as a number.
//!
//! A mirrored robot's e-stop may be `pending`: the operator asked for it, the robot did not
//! answer, and the mirror keeps it asked until the robot's chassisd has it ([`estop_pending`]).

mod estop;
mod view;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{
    ChassisState, ControlMode, FaultFlags, Group, LinkFlags, LockStatus, MuxStatus, Robot,
    RobotDescription, WireProtocol, install_signal_handlers, now_ns, termination_requested,
};
use clap::Args;
use serde::Serialize;

pub use estop::{EstopArgs, estop_all};

/// How often the robots' services are listed again.
const RESCAN_NS: u64 = 1_000_000_000;
/// How often each robot's thread reports.
const REPORT_NS: u64 = 100_000_000;
/// Longest a robot's thread waits for a state sample.
const MAX_WAIT: Duration = Duration::from_millis(50);
/// A robot heard from longer ago than this is shown as silent.
const SILENT_NS: u64 = 1_000_000_000;
/// Latencies kept per robot (the newest).
const LATENCY_WINDOW: usize = 4096;
/// A latency beyond this is another computer's clock, not a delay.
const PLAUSIBLE_NS: u64 = 60_000_000_000;

#[derive(Debug, Args)]
pub struct FleetArgs {
    /// Print one snapshot after collecting for --collect seconds, instead of the live table.
    #[arg(long)]
    pub once: bool,
    /// JSON: with --once one document, else one line per refresh.
    #[arg(long)]
    pub json: bool,
    /// With --once: seconds to collect before printing.
    #[arg(long, default_value_t = 1.5)]
    pub collect: f64,
    /// Refresh period, ms.
    #[arg(long, default_value_t = 500)]
    pub interval_ms: u64,
    /// With the live table: how long the e-stop key waits for each robot's answer, ms.
    #[arg(long, default_value_t = 2000)]
    pub estop_timeout_ms: u64,
}

/// Latency figures of one robot over the samples measured so far, ms.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LatencyStats {
    pub count: usize,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

impl LatencyStats {
    pub fn of(samples: &[u64]) -> Option<Self> {
        if samples.is_empty() {
            return None;
        }
        let mut sorted = samples.to_vec();
        sorted.sort_unstable();
        let at = |q: f64| {
            let i = ((sorted.len() as f64 - 1.0) * q).round() as usize;
            sorted[i.min(sorted.len() - 1)] as f64 / 1e6
        };
        Some(Self {
            count: sorted.len(),
            p50_ms: at(0.5),
            p99_ms: at(0.99),
            max_ms: at(1.0),
        })
    }
}

/// What one robot's thread has seen.
#[derive(Debug, Clone, Default)]
struct Seen {
    state: Option<ChassisState>,
    mux: Option<MuxStatus>,
    description: Option<RobotDescription>,
    /// This process' clock when the newest new sample woke it.
    heard_ns: Option<u64>,
    latencies: Vec<u64>,
    /// Latencies beyond [`PLAUSIBLE_NS`] (or negative): another computer's clock.
    implausible: u64,
    /// The robot's service lost its publisher (chassisd or the mirror is gone).
    gone: bool,
}

/// One row of the table (and of `--json`).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub name: String,
    pub kind: String,
    pub model: String,
    pub protocol: String,
    pub mode: String,
    pub battery_v: Option<f32>,
    pub battery_pct: Option<f32>,
    pub faults: Vec<&'static str>,
    pub warnings: Vec<&'static str>,
    /// The mux's winner, or `none (reason)`.
    pub winner: String,
    /// The mux's output, m/s.
    pub output_mps: Option<f32>,
    /// The measured speed, m/s.
    pub speed_mps: Option<f32>,
    /// `ok`, `lost` (the mirror lost the robot: `LinkFlags::REMOTE_LOST`), `silent` (nothing
    /// new for a second here), `gone` (nobody serves it any more), `waiting` (no state yet).
    pub link: &'static str,
    pub link_age_ms: Option<f64>,
    pub latency: Option<LatencyStats>,
    /// Latency samples that were another computer's clock.
    pub latency_clock_mismatch: u64,
    /// `held`, `free`, `unknown`; last known when the link is lost. `pending` while a mirror
    /// keeps the operator's e-stop asked of a robot that has not received it yet.
    pub estop: &'static str,
    pub estop_holder: Option<String>,
}

/// The lock the fleet e-stop engages.
const ESTOP: &str = "estop";

/// Whether the mux, as a mirror (`chassis-zenoh`) publishes it, says the operator's e-stop is
/// pending: forwarded, not answered by the robot yet, kept asked by the mirror
/// ([`LockStatus::is_pending`]).
pub(crate) fn estop_pending(m: &MuxStatus) -> bool {
    m.locks()
        .iter()
        .find(|l| l.name() == ESTOP)
        .is_some_and(LockStatus::is_pending)
}

fn estop_of(mux: Option<&MuxStatus>) -> (&'static str, Option<String>) {
    let Some(m) = mux else {
        return ("unknown", None);
    };
    match m.locks().iter().find(|l| l.name() == ESTOP) {
        Some(l) if l.held != 0 => ("held", Some(crate::live::lock_holder(m, l))),
        Some(_) if estop_pending(m) => ("pending", None),
        Some(_) => ("free", None),
        None => ("unknown", None),
    }
}

fn row(name: &str, seen: &Seen, now_ns: u64) -> Row {
    let s = seen.state.as_ref();
    let d = seen.description.as_ref();
    let kind = d.map_or_else(
        || {
            s.and_then(|s| chassis_protocols::RobotKind::from_id(s.robot))
                .map_or("?", chassis_protocols::RobotKind::name)
                .to_string()
        },
        |d| d.kind_name().to_string(),
    );
    let protocol = match (s, d) {
        (Some(s), _) => WireProtocol::name(s.system.wire_protocol),
        (None, Some(d)) => WireProtocol::name(d.protocol),
        (None, None) => "?",
    };
    let link_age_ns = seen.heard_ns.map(|t| now_ns.saturating_sub(t));
    let link = if seen.gone {
        "gone"
    } else if s.is_some_and(|s| s.link_flags & LinkFlags::REMOTE_LOST != 0) {
        "lost"
    } else if s.is_none() {
        "waiting"
    } else if link_age_ns.is_none_or(|age| age > SILENT_NS) {
        "silent"
    } else {
        "ok"
    };
    let (estop, estop_holder) = estop_of(seen.mux.as_ref());
    let winner = seen.mux.as_ref().map_or("?".to_string(), |m| {
        m.active()
            .map_or_else(|| format!("none ({})", m.why()), |a| a.name().to_string())
    });
    Row {
        name: name.to_string(),
        kind,
        model: d.map_or(String::new(), |d| d.model().to_string()),
        protocol: protocol.to_string(),
        mode: s
            .map_or("?", |s| ControlMode::name(s.system.control_mode))
            .to_string(),
        battery_v: s.map(|s| s.system.battery_voltage_v),
        battery_pct: s
            .filter(|s| s.is_valid(Group::BmsPack))
            .map(|s| s.system.battery_soc_pct),
        faults: s.map_or(Vec::new(), |s| {
            FaultFlags::names(s.system.fault_flags & !FaultFlags::WARNINGS)
        }),
        warnings: s.map_or(Vec::new(), |s| {
            FaultFlags::names(s.system.fault_flags & FaultFlags::WARNINGS)
        }),
        winner,
        output_mps: seen.mux.as_ref().map(|m| m.output.linear_x_mps),
        speed_mps: s.map(|s| s.motion.linear_mps),
        link,
        link_age_ms: link_age_ns.map(|ns| ns as f64 / 1e6),
        latency: LatencyStats::of(&seen.latencies),
        latency_clock_mismatch: seen.implausible,
        estop,
        estop_holder,
    }
}

/// One robot's reader: its own thread, reporting what it has seen every [`REPORT_NS`].
fn watch(name: &str, stop: &AtomicBool, tx: &mpsc::Sender<(String, Seen)>) {
    let Ok(mut robot) = Robot::connect(name) else {
        let gone = Seen {
            gone: true,
            ..Seen::default()
        };
        let _ = tx.send((name.to_string(), gone));
        return;
    };
    let mut seen = Seen::default();
    let mut last_seq = 0u64;
    let mut next_report = now_ns();
    let mut next_check = now_ns() + RESCAN_NS;
    while !stop.load(Ordering::Relaxed) && !termination_requested() {
        // Samples that waited while we were busy: kept, not measured. A sample is new when
        // its `seq` differs from the last one's (a mirror publishing a lost robot's last state
        // again is not news; a restarted chassisd counting from 1 is).
        let mut take = |seen: &mut Seen, state: ChassisState, woke_ns: Option<u64>| {
            let first = seen.state.is_none();
            let new = first || state.seq != last_seq;
            // A mirror's last state of a lost robot, published again, is no news of it.
            let lost = state.link_flags & LinkFlags::REMOTE_LOST != 0;
            if new && !lost {
                if woke_ns.is_some() || !first {
                    seen.heard_ns = Some(now_ns());
                }
                // The first sample a reader gets may be the service's history: not measured.
                if let Some(woke) = woke_ns.filter(|_| !first) {
                    let latency = i128::from(woke) - i128::from(state.published_ns);
                    if (0..i128::from(PLAUSIBLE_NS)).contains(&latency) && state.published_ns != 0 {
                        if seen.latencies.len() >= LATENCY_WINDOW {
                            seen.latencies.remove(0);
                        }
                        seen.latencies.push(latency as u64);
                    } else {
                        seen.implausible += 1;
                    }
                }
            }
            last_seq = state.seq;
            seen.state = Some(state);
        };
        match robot.latest_state() {
            Ok(Some(state)) => take(&mut seen, state, None),
            Ok(None) => {}
            Err(_) => break,
        }
        match robot.wait_state(MAX_WAIT) {
            Ok(Some(state)) => {
                let woke = now_ns();
                take(&mut seen, state, Some(woke));
            }
            Ok(None) => {}
            Err(_) => break,
        }
        if let Ok(Some(m)) = robot.latest_mux() {
            seen.mux = Some(m);
        }
        if let Ok(Some(d)) = robot.latest_description() {
            seen.description = Some(d);
        }
        let now = now_ns();
        if now >= next_check {
            next_check = now + RESCAN_NS;
            seen.gone = !robot.is_served();
        }
        if now >= next_report {
            next_report = now + REPORT_NS;
            if tx.send((name.to_string(), seen.clone())).is_err() {
                return;
            }
        }
    }
}

/// Every robot served here, each read by its own thread.
pub struct Fleet {
    stop: Arc<AtomicBool>,
    tx: mpsc::Sender<(String, Seen)>,
    rx: mpsc::Receiver<(String, Seen)>,
    seen: BTreeMap<String, Seen>,
    threads: Vec<std::thread::JoinHandle<()>>,
    next_scan_ns: u64,
}

impl Fleet {
    pub fn new() -> anyhow::Result<Self> {
        let (tx, rx) = mpsc::channel();
        Ok(Self {
            stop: Arc::new(AtomicBool::new(false)),
            tx,
            rx,
            seen: BTreeMap::new(),
            threads: Vec::new(),
            next_scan_ns: 0,
        })
    }

    /// Lists the robots again when it is time, starting a reader for each new one.
    fn scan(&mut self, now: u64) -> anyhow::Result<()> {
        if now < self.next_scan_ns {
            return Ok(());
        }
        self.next_scan_ns = now + RESCAN_NS;
        let config = chassis_ipc::config(None)?;
        for name in chassis_ipc::robots(&config).context("listing the robots served here")? {
            if self.seen.contains_key(&name) {
                continue;
            }
            self.seen.insert(name.clone(), Seen::default());
            let (stop, tx) = (self.stop.clone(), self.tx.clone());
            self.threads.push(
                std::thread::Builder::new()
                    .name(format!("fleet/{name}"))
                    .spawn(move || watch(&name, &stop, &tx))?,
            );
        }
        Ok(())
    }

    /// Takes in what the readers reported, waiting at most `timeout` for the first report.
    pub fn step(&mut self, timeout: Duration) -> anyhow::Result<()> {
        self.scan(now_ns())?;
        if let Ok((name, seen)) = self.rx.recv_timeout(timeout) {
            self.seen.insert(name, seen);
        }
        while let Ok((name, seen)) = self.rx.try_recv() {
            self.seen.insert(name, seen);
        }
        Ok(())
    }

    pub fn rows(&self) -> Vec<Row> {
        let now = now_ns();
        self.seen
            .iter()
            .map(|(name, seen)| row(name, seen, now))
            .collect()
    }
}

impl Drop for Fleet {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

/// `chassis fleet`.
pub fn run(args: &FleetArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    if !(args.collect.is_finite() && args.collect > 0.0 && args.collect <= 3600.0) {
        anyhow::bail!("--collect must be above 0 and at most 3600 s");
    }
    let mut fleet = Fleet::new()?;
    if args.once {
        let end = now_ns().saturating_add(Duration::from_secs_f64(args.collect).as_nanos() as u64);
        while now_ns() < end && !termination_requested() {
            let left = Duration::from_nanos(end.saturating_sub(now_ns()));
            fleet.step(left.min(Duration::from_millis(100)))?;
        }
        let rows = fleet.rows();
        if args.json {
            println!(
                "{}",
                serde_json::to_string(&serde_json::json!({ "robots": rows }))?
            );
        } else {
            print!("{}", view::text(&rows));
        }
        return Ok(());
    }
    if args.json {
        let interval = Duration::from_millis(args.interval_ms.clamp(20, 60_000));
        let mut next = now_ns();
        while !termination_requested() {
            fleet.step(Duration::from_millis(50))?;
            if now_ns() >= next {
                next = now_ns() + interval.as_nanos() as u64;
                println!(
                    "{}",
                    serde_json::to_string(&serde_json::json!({ "robots": fleet.rows() }))?
                );
            }
        }
        return Ok(());
    }
    view::live(&mut fleet, args)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::LockStatus;

    #[test]
    fn latency_figures_are_the_samples_quantiles() {
        assert_eq!(LatencyStats::of(&[]), None);
        let samples: Vec<u64> = (1..=100).map(|i| i * 1_000_000).collect();
        let stats = LatencyStats::of(&samples).unwrap();
        assert_eq!(stats.count, 100);
        assert!((stats.p50_ms - 50.0).abs() <= 1.0, "{stats:?}");
        assert!((stats.p99_ms - 99.0).abs() <= 1.0, "{stats:?}");
        assert_eq!(stats.max_ms, 100.0);
    }

    #[test]
    fn a_lost_robot_shows_lost_and_its_last_known_estop() {
        let mut state = ChassisState {
            link_flags: LinkFlags::REMOTE_LOST,
            ..ChassisState::default()
        };
        let mut mux = MuxStatus {
            lock_count: 1,
            ..MuxStatus::default()
        };
        mux.locks[0].set_name("estop");
        mux.locks[0].held = 1;
        mux.locks[0].holder = LockStatus::HOLDER_OPERATOR;
        let seen = Seen {
            state: Some(state),
            mux: Some(mux),
            heard_ns: Some(1_000),
            ..Seen::default()
        };
        let r = row("r1", &seen, 2_000_000_000);
        assert_eq!(r.link, "lost");
        assert_eq!(r.estop, "held");
        assert_eq!(r.estop_holder.as_deref(), Some("operator"));
        state.link_flags = 0;
        let fresh = Seen {
            state: Some(state),
            heard_ns: Some(1_999_000_000),
            ..Seen::default()
        };
        assert_eq!(row("r1", &fresh, 2_000_000_000).link, "ok");
        assert_eq!(row("r1", &fresh, 3_500_000_000).link, "silent");
        assert_eq!(row("r1", &Seen::default(), 0).link, "waiting");
        assert_eq!(row("r1", &Seen::default(), 0).estop, "unknown");
    }

    #[test]
    fn a_mirrors_pending_estop_shows_pending_until_the_robot_holds_it() {
        let mut mux = MuxStatus {
            lock_count: 1,
            ..MuxStatus::default()
        };
        mux.locks[0].set_name("estop");
        mux.locks[0].holder = LockStatus::HOLDER_NONE;
        let estop = |mux: MuxStatus| {
            let seen = Seen {
                mux: Some(mux),
                ..Seen::default()
            };
            row("r2", &seen, 0).estop
        };
        assert_eq!(estop(mux), "free");
        assert!(!estop_pending(&mux));
        // The mirror keeps the operator's e-stop asked: not held, the operator its holder.
        mux.locks[0].holder = LockStatus::HOLDER_OPERATOR;
        assert!(estop_pending(&mux));
        assert_eq!(estop(mux), "pending");
        // Delivered: chassisd holds it.
        mux.locks[0].held = 1;
        assert!(!estop_pending(&mux));
        assert_eq!(estop(mux), "held");
        // Another lock's holder says nothing of the e-stop.
        let mut other = mux;
        other.locks[0].set_name("dock");
        other.locks[0].held = 0;
        assert!(!estop_pending(&other));
        assert_eq!(estop(other), "unknown");
    }
}
