//! The monitor's loop: connect, read the newest state and mux status, run the rule engine,
//! publish the decision on the `safety` source and the `SafetyStatus`, and reconnect when the
//! service goes away.
//!
//! * Rules are evaluated on every new state sample and at least every `evaluate_period_ms`
//!   (20 ms): the wait for state has that deadline, so a service that stops publishing is noticed
//!   on the monitor's own clock.
//! * The request is sent at once when the decision changes and re-sent every
//!   `publish_period_ms` (50 ms), well inside the source's 200 ms timeout.
//! * `SafetyStatus` is published on every change and every `status_period_ms` (100 ms).
//! * The robot's description (`chassis/<name>/robot`) is read on every connection and watched
//!   for a newer one (chassisd's protocol detection deciding, a restarted chassisd with another
//!   configuration): the speed and battery rules take their levels from it, and the log says
//!   which, from where, and loudly what is missing.
//! * SIGUSR1 latches the operator e-stop; SIGINT / SIGTERM send a last stop and end the loop
//!   (exit code 0). Nothing else ends it: a lost service is logged (ERROR) and reconnected with
//!   backoff (100 ms doubling to 2 s).
//!
//! Time comes from `chassis_client::now_ns`, waits from `Robot::wait_state` and
//! `chassis_client::Ticker`: this module neither sleeps nor reads `Instant`.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use chassis_client::{
    ClientError, Envelope, Publication, Robot, RobotDescription, SafetyAction, SafetyEvent,
    SafetyRule, SafetyStatus, Source, Ticker, WireProtocol, install_signal_handlers, now_ns,
    termination_requested,
};
use thiserror::Error;
use tracing::{debug, error, info, info_span, warn};

use crate::config::Config;
use crate::engine::{Command, Decision, Engine};

/// Why the monitor gave up (it never gives up on a lost service).
#[derive(Debug, Error)]
pub enum MonitorError {
    #[error("{0}")]
    Client(#[from] ClientError),
    #[error("installing the SIGUSR1 handler: {0}")]
    Signal(std::io::Error),
}

/// Why one connection to the service ended (the monitor then reconnects).
#[derive(Debug, Error)]
enum LinkLost {
    /// Waiting for state failed and the service is no longer there.
    #[error("{0}")]
    Waiting(ClientError),
    /// The velocity request could not be published.
    #[error("publishing on the safety source: {0}")]
    Publishing(ClientError),
    /// The state went stale and the service no longer serves it.
    #[error("chassisd no longer publishes its state")]
    NotServed,
}

/// How often the source may be found taken before the monitor gives up: a monitor killed a
/// moment ago may still hold it until iceoryx2 cleans up after it.
const SOURCE_TAKEN_ATTEMPTS: u32 = 5;
/// While the state is stale, how often to check whether the service is still there.
const SERVED_CHECK_NS: u64 = 1_000_000_000;
/// How long a new connection waits for the robot's description (chassisd hands it to a new
/// reader within one tick of its loop).
const DESCRIPTION_WAIT: Duration = Duration::from_secs(2);

/// Connects to the robot `name`, publishes as `source`, and runs until SIGINT or SIGTERM.
pub fn run(config: Config, name: &str, source: &str) -> Result<(), MonitorError> {
    let _span = info_span!("safety", robot = name).entered();
    install_signal_handlers();
    let operator = Arc::new(AtomicBool::new(false));
    signal_hook::flag::register(signal_hook::consts::SIGUSR1, Arc::clone(&operator))
        .map_err(MonitorError::Signal)?;
    let label = format!("chassis/{name}");
    let mut engine = Engine::new(config, source, &label);
    let mut status = SafetyStatus {
        started_ns: now_ns(),
        ..SafetyStatus::default()
    };
    info!(
        "safety monitor for chassis/{name} as source '{source}': rules {}",
        SafetyRule::names(engine.enabled_rules()).join(", ")
    );
    let mut described = Described::default();
    let mut backoff_ms = 100u64;
    let mut failures = 0u32;
    let mut taken = 0u32;
    while !termination_requested() {
        match Link::connect(name, source) {
            Ok(link) => {
                backoff_ms = 100;
                failures = 0;
                taken = 0;
                info!("connected to chassis/{name}: publishing as source '{source}'");
                match serve(&mut engine, link, &operator, &mut status, &mut described) {
                    Ok(()) => return Ok(()),
                    Err(reason) => error!(
                        "lost chassis/{name}: {reason}; the robot stops (its required source \
                         is silent); reconnecting"
                    ),
                }
            }
            Err(e @ ClientError::BadName(_)) => return Err(e.into()),
            Err(e @ ClientError::SourceTaken { .. }) => {
                taken += 1;
                if taken >= SOURCE_TAKEN_ATTEMPTS {
                    return Err(e.into());
                }
                warn!("{e}; retrying");
            }
            Err(e) => {
                // A service that is starting has its state before its sources: give it a few
                // tries before calling a missing source an error.
                let quiet = if matches!(e, ClientError::UnknownSource { .. }) {
                    3
                } else {
                    0
                };
                // Said once, then every minute or so: the robot cannot move meanwhile.
                if failures >= quiet && (failures - quiet).is_multiple_of(30) {
                    error!("cannot serve chassis/{name}: {e}; retrying");
                } else {
                    debug!("cannot serve chassis/{name}: {e}");
                }
                failures = failures.saturating_add(1);
            }
        }
        pause(Duration::from_millis(backoff_ms));
        backoff_ms = (backoff_ms * 2).min(2000);
    }
    info!("terminated");
    Ok(())
}

/// Waits `d` (a signal ends it early).
fn pause(d: Duration) {
    let mut ticker = Ticker::new(d);
    ticker.wait(); // the first tick is due now
    ticker.wait();
}

/// The ports of one connection, and the description read as it was made.
struct Link {
    robot: Robot,
    source: Source,
    status: Option<Publication<SafetyStatus>>,
    description: Result<RobotDescription, ClientError>,
}

impl Link {
    /// Connects, reads the description, then takes the source: its first heartbeat (the
    /// library's, as the process connects) is followed by the loop's at once. Taken before a
    /// wait of up to [`DESCRIPTION_WAIT`], the source would go stale and come back — for the
    /// mux a restarted monitor, after which motion starts only from a zero.
    fn connect(name: &str, source_name: &str) -> Result<Self, ClientError> {
        let mut robot = Robot::connect(name)?;
        let description = robot.description(DESCRIPTION_WAIT);
        let source = robot.source(source_name)?;
        let status = match robot.publisher::<SafetyStatus>(SafetyStatus::SERVICE) {
            Ok(p) => Some(p),
            Err(e) => {
                warn!(
                    "cannot publish chassis/{name}/{}: {e}; `chassis status` will not show \
                     the monitor",
                    SafetyStatus::SERVICE
                );
                None
            }
        };
        Ok(Self {
            robot,
            source,
            status,
            description,
        })
    }
}

/// What was last reported, to log changes only.
#[derive(Debug, Default)]
struct Reported {
    action: Option<u8>,
    envelope: Option<Envelope>,
    active_rules: u32,
}

/// The description in force: which one (`seq`, `stamp_ns`), and the levels last logged.
#[derive(Debug, Default)]
struct Described {
    applied: Option<(u64, u64)>,
    logged: Vec<String>,
}

impl Described {
    /// Takes a description the engine has not seen yet; logs the robot and the levels when
    /// they change, and loudly what a rule lacks.
    fn apply(&mut self, engine: &mut Engine, d: &RobotDescription) {
        if self.applied == Some((d.seq, d.stamp_ns)) {
            return;
        }
        self.applied = Some((d.seq, d.stamp_ns));
        engine.set_description(d);
        let label = format!("chassis/{}", d.name());
        let robot = format!(
            "{label}: {} ({}, model {}, protocol {})",
            d.display_name(),
            d.kind_name(),
            d.model(),
            WireProtocol::name(d.protocol),
        );
        let summary = engine.levels().summary(engine.config());
        let warnings = engine.levels().warnings(engine.config(), &label);
        // Logged when the robot or a level changed, not at every reconnection.
        let said: Vec<String> = std::iter::once(robot.clone())
            .chain(summary.iter().cloned())
            .chain(warnings.iter().cloned())
            .collect();
        if said == self.logged {
            debug!("description seq {}: nothing new", d.seq);
            return;
        }
        info!("{robot}; description seq {}", d.seq);
        for line in &summary {
            info!("{line}");
        }
        for warning in &warnings {
            warn!("{warning}");
        }
        self.logged = said;
    }

    /// A connection that found no description: said loudly when a rule waits for one.
    fn missing(&self, engine: &Engine, name: &str, error: &ClientError) {
        let warnings = engine
            .levels()
            .warnings(engine.config(), &format!("chassis/{name}"));
        if warnings.is_empty() {
            debug!("no description of chassis/{name}: {error}");
        } else {
            warn!(
                "no description of chassis/{name} within {DESCRIPTION_WAIT:?} ({error}); until \
                 one comes:"
            );
            for warning in warnings {
                warn!("{warning}");
            }
        }
    }
}

/// Runs the loop on one connection: `Ok` on SIGINT/SIGTERM, `Err` when the service is gone.
fn serve(
    engine: &mut Engine,
    mut link: Link,
    operator: &AtomicBool,
    status: &mut SafetyStatus,
    described: &mut Described,
) -> Result<(), LinkLost> {
    let evaluate_period = Duration::from_nanos(engine.config().evaluate_period_ns);
    let publish_period_ns = engine.config().publish_period_ns;
    let status_period_ns = engine.config().status_period_ns;
    let lock = engine.config().lock.clone();
    let mut last_command: Option<Command> = None;
    let mut last_sent_ns = 0u64;
    let mut last_status_ns = 0u64;
    let mut last_served_check_ns = now_ns();
    let mut reported = Reported::default();
    let name = link.robot.name().to_string();
    match &link.description {
        Ok(d) => described.apply(engine, d),
        Err(e) => described.missing(engine, &name, e),
    }
    loop {
        if termination_requested() {
            let stopped = link.source.stop();
            info!(
                "SIGINT/SIGTERM: {}; exiting — nothing moves until a safety monitor runs again",
                if stopped.is_ok() {
                    "sent a stop"
                } else {
                    "could not send a stop"
                }
            );
            return Ok(());
        }
        if operator.swap(false, Ordering::Relaxed) {
            if engine.request_operator_estop() {
                warn!("SIGUSR1: operator e-stop");
            } else {
                warn!("SIGUSR1 ignored: [rules.operator] is disabled");
            }
        }
        if let Err(e) = link.robot.wait_state(evaluate_period) {
            // A signal interrupts the wait; anything else is judged by whether the service is
            // still there (the stale rule stops the robot meanwhile).
            if !termination_requested() && !operator.load(Ordering::Relaxed) {
                debug!("waiting for state: {e}");
                if !link.robot.is_served() {
                    let _ = link.source.stop();
                    return Err(LinkLost::Waiting(e));
                }
            }
        }
        let state = match link.robot.latest_state() {
            Ok(s) => s.unwrap_or_default(),
            Err(e) => {
                debug!("reading state: {e}");
                Default::default()
            }
        };
        let mux = link.robot.latest_mux().unwrap_or_else(|e| {
            debug!("reading the mux status: {e}");
            None
        });
        match link.robot.latest_description() {
            Ok(Some(d)) => described.apply(engine, &d),
            Ok(None) => {}
            Err(e) => debug!("reading the robot description: {e}"),
        }
        let now = now_ns();
        let decision = engine.evaluate(now, &state, mux.as_ref());
        report(&decision, &lock, &mut reported);

        if last_command != Some(decision.command)
            || now.saturating_sub(last_sent_ns) >= publish_period_ns
        {
            link.source
                .send(decision.command.request())
                .map_err(LinkLost::Publishing)?;
            last_sent_ns = now;
            last_command = Some(decision.command);
        }

        let changed = !decision.events.is_empty()
            || status.action != decision.action
            || status.active_rules != decision.active_rules
            || status.estop != decision.estop
            || status.limit_forward_mps != decision.envelope.forward_mps
            || status.limit_reverse_mps != decision.envelope.reverse_mps;
        if let Some(publication) = &link.status
            && (changed || now.saturating_sub(last_status_ns) >= status_period_ns)
        {
            engine.fill_status(&decision, status);
            status.seq += 1;
            status.stamp_ns = now;
            status.state_age_ms =
                u32::try_from(now.saturating_sub(state.stamp_ns) / 1_000_000).unwrap_or(u32::MAX);
            if let Err(e) = publication.send(*status) {
                debug!("publishing the safety status: {e}");
            }
            last_status_ns = now;
        }

        // A stale state may mean the service is gone: check now and then.
        if decision.active_rules & SafetyRule::bit(SafetyRule::STALE) != 0
            && now.saturating_sub(last_served_check_ns) >= SERVED_CHECK_NS
        {
            last_served_check_ns = now;
            if !link.robot.is_served() {
                return Err(LinkLost::NotServed);
            }
        }
    }
}

fn limit_text(v: f32, unit: &str) -> String {
    if v >= SafetyStatus::UNLIMITED {
        "free".into()
    } else {
        format!("≤ {v:.2} {unit}")
    }
}

/// The envelope in words.
pub fn envelope_text(e: &Envelope) -> String {
    format!(
        "forward {}, reverse {}, lateral {}, yaw {}",
        limit_text(e.forward_mps, "m/s"),
        limit_text(e.reverse_mps, "m/s"),
        limit_text(e.lateral_mps, "m/s"),
        limit_text(e.angular_radps, "rad/s")
    )
}

/// A measurement for the logs: three decimals are plenty (m, %, V, ms, m/s).
fn rounded(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// Logs the events and any change of action (never once per cycle).
fn report(decision: &Decision, lock: &str, reported: &mut Reported) {
    for notice in &decision.notices {
        warn!("{notice}");
    }
    for line in &decision.infos {
        info!("{line}");
    }
    for e in &decision.events {
        let rule = SafetyRule::name(e.rule);
        match e.kind {
            // "trigger: …", "release: …", with the value that crossed the threshold.
            SafetyEvent::TRIGGER | SafetyEvent::RELEASE => info!(
                rule,
                value = rounded(e.value),
                threshold = rounded(e.threshold),
                "{}: {}",
                SafetyEvent::name(e.kind),
                e.text
            ),
            _ => info!(rule, "{}", e.text),
        }
    }
    let rules = SafetyRule::names(decision.active_rules).join(", ");
    if reported.action != Some(decision.action) {
        match decision.action {
            SafetyAction::STOP => warn!("stopping the robot ({rules})"),
            SafetyAction::LATCH => warn!(
                "latching the '{lock}' lock ({rules}): `chassis control estop-release` \
                 releases it"
            ),
            SafetyAction::SLOW => {
                info!("limiting ({rules}): {}", envelope_text(&decision.envelope))
            }
            _ => {
                if reported.action.is_some() {
                    info!("all clear: heartbeats");
                }
            }
        }
    } else if decision.action == SafetyAction::SLOW
        && (reported.envelope != Some(decision.envelope)
            || reported.active_rules != decision.active_rules)
    {
        info!("limiting ({rules}): {}", envelope_text(&decision.envelope));
    }
    reported.action = Some(decision.action);
    reported.envelope = Some(decision.envelope);
    reported.active_rules = decision.active_rules;
}
