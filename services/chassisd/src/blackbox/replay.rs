//! The replay: the recorded inputs fed through the same engine on the recorded clock, every item
//! written and every publication checked against the recording byte for byte, and the story of
//! the run told from the mux decisions ([`MuxStatus::why`], the one explanation every view shows).

use chassis_interfaces::{ControlRequest, MuxStatus, SourceFlags, VelocityRequest, ZeroReason};
use chassis_protocols::{Timestamp, WireItem};
use chassisd_config::{Config, ConfigError, Overrides, RawConfig};
use serde::Serialize;
use zerocopy::FromBytes;

use super::{Event, Outcome, Published, published, to_bus, wire_item};
use crate::engine::{
    BusItem, Device, Engine, EngineConfig, HeldLock, PassIo, Readers, Ticket, ToPublish, Wake,
    WriteError, Written,
};
use crate::mux::Mux;
use crate::setup::driver_for_config;

/// Why a recording cannot be replayed at all.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("the recording does not begin with its start record")]
    NoStart,
    #[error("the recorded configuration: {0}")]
    Config(#[from] ConfigError),
    #[error("the recorded configuration: {0}")]
    Toml(#[from] toml::de::Error),
    #[error("the recorded configuration: [mux]: {0}")]
    Mux(#[from] chassisd_config::mux::MuxConfigError),
}

/// Where the replay first did something else than the recorded run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Divergence {
    /// The event's index in the recording.
    pub event: usize,
    /// The last instant read before it, ns (`CLOCK_MONOTONIC` of the recorded run).
    pub at_ns: u64,
    pub recorded: String,
    pub replayed: String,
}

/// The replay's verdict and what the engine decided.
#[derive(Debug, Clone, Serialize)]
pub struct Replay {
    pub recorded_version: String,
    /// The recorded run's version is not this program's.
    pub version_differs: bool,
    /// The replay ran on another configuration than the recorded one.
    pub config_differs: bool,
    /// Events replayed and found identical.
    pub checked: usize,
    pub events: usize,
    /// Mux decisions and frames written, replayed.
    pub decisions: usize,
    pub frames_written: usize,
    pub divergence: Option<Divergence>,
    /// Why a stretch of the run was not replayed (a gap in the recording, a cut ring), when the
    /// replay found no snapshot of the engine after it to go on from.
    pub incomplete: Option<String>,
    /// Where the replay went on from a snapshot of the engine after a cut or a gap: the event's
    /// index, its instant, and why the stretch before it was not replayed.
    pub resumed: Vec<(usize, u64, String)>,
    /// Snapshots of the engine recorded, and those checked against the replayed engine.
    pub snapshots: usize,
    pub snapshots_checked: usize,
    /// The mux decisions read from the recording, not decided again (between a cut and the
    /// next snapshot): the story tells them as recorded.
    pub unreplayed_decisions: usize,
    /// The recorded run's start: monotonic and wall clock, ns.
    pub start_ns: u64,
    pub start_unix_ns: u64,
    #[serde(skip)]
    pub muxes: Vec<MuxStatus>,
    /// For each of `muxes`: decided again by the replay (else read from the recording).
    #[serde(skip)]
    pub replayed: Vec<bool>,
    /// When each item was written, ns.
    #[serde(skip)]
    pub writes: Vec<u64>,
}

/// The recorded run's events, handed to the engine as its [`PassIo`] would have.
struct Player<'a> {
    events: &'a [Event],
    next: usize,
    last_ns: u64,
    divergence: Option<Divergence>,
    opened: String,
    muxes: Vec<MuxStatus>,
    replayed: Vec<bool>,
    writes: Vec<u64>,
}

impl<'a> Player<'a> {
    fn diverge(&mut self, recorded: String, replayed: String) {
        if self.divergence.is_none() {
            self.divergence = Some(Divergence {
                event: self.next,
                at_ns: self.last_ns,
                recorded,
                replayed,
            });
        }
    }

    /// The next event when `want` takes it (it is then consumed); else a divergence.
    fn take<T>(&mut self, what: &str, want: impl FnOnce(&Event) -> Option<T>) -> Option<T> {
        if self.divergence.is_some() {
            return None;
        }
        let event = self.events.get(self.next);
        match event.and_then(want) {
            Some(value) => {
                if let Some(t) = event.and_then(Event::time) {
                    self.last_ns = t;
                }
                self.next += 1;
                Some(value)
            }
            None => {
                let recorded = event.map_or_else(|| "the end".into(), |e| format!("{e:?}"));
                self.diverge(recorded, format!("the engine asked for {what}"));
                None
            }
        }
    }

    /// The next event when it is `want`'s, else nothing (a read that found nothing is not
    /// recorded).
    fn take_if<T>(&mut self, want: impl Fn(&Event) -> Option<T>) -> Option<T> {
        if self.divergence.is_some() {
            return None;
        }
        let value = self.events.get(self.next).and_then(want)?;
        self.next += 1;
        Some(value)
    }
}

fn result_of(failed: &Option<String>) -> Result<(), String> {
    failed.clone().map_or(Ok(()), Err)
}

fn written(outcome: &Outcome) -> Result<Written, WriteError<String>> {
    match outcome {
        Outcome::Out(t) => Ok(Written::Out(Timestamp::from_nanos(*t))),
        Outcome::Held(t) => Ok(Written::Held(Timestamp::from_nanos(*t))),
        Outcome::Dropped(e) => Err(WriteError::Dropped(e.clone())),
        Outcome::Lost(e) => Err(WriteError::Lost(e.clone())),
    }
}

impl PassIo for Player<'_> {
    type Error = String;

    fn now(&mut self) -> Timestamp {
        let t = self.take("the clock", |e| match e {
            Event::Now { t } => Some(*t),
            _ => None,
        });
        Timestamp::from_nanos(t.unwrap_or(self.last_ns))
    }

    fn read_requests(&mut self, _: u32, mut take: impl FnMut(usize, &VelocityRequest)) {
        let read = self.take_if(|e| match e {
            Event::Requests { read } => Some(read.clone()),
            _ => None,
        });
        for (source, bytes) in read.unwrap_or_default() {
            match VelocityRequest::read_from_bytes(&bytes.0) {
                Ok(request) => take(source, &request),
                Err(_) => self.diverge("a request of the wrong size".into(), "a request".into()),
            }
        }
    }

    fn read_control(&mut self, mut take: impl FnMut(Ticket, &ControlRequest)) {
        let read = self.take_if(|e| match e {
            Event::Controls { read } => Some(read.clone()),
            _ => None,
        });
        for (ticket, bytes) in read.unwrap_or_default() {
            match ControlRequest::read_from_bytes(&bytes.0) {
                Ok(request) => take(ticket, &request),
                Err(_) => self.diverge(
                    "a control request of the wrong size".into(),
                    "a control request".into(),
                ),
            }
        }
    }

    fn serve_simulator(&mut self, _: Timestamp) {}

    fn acknowledge(&mut self, _: u32) {}

    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<String>> {
        let ours = wire_item(item);
        let recorded = self.take("a write", |e| match e {
            Event::Write { item, outcome } => Some((item.clone(), outcome.clone())),
            _ => None,
        });
        let Some((theirs, outcome)) = recorded else {
            return Err(WriteError::Lost("the replay diverged".into()));
        };
        if theirs != ours {
            self.next -= 1;
            self.diverge(format!("wrote {theirs:?}"), format!("wrote {ours:?}"));
        }
        if let Ok(Written::Out(t) | Written::Held(t)) = written(&outcome) {
            self.last_ns = t.as_nanos();
            self.writes.push(t.as_nanos());
        }
        written(&outcome)
    }

    fn flush(&mut self) -> Result<Timestamp, WriteError<String>> {
        let outcome = self.take("a flush", |e| match e {
            Event::Flush { outcome } => Some(outcome.clone()),
            _ => None,
        });
        match outcome.as_ref().map(written) {
            Some(Ok(Written::Out(t) | Written::Held(t))) => Ok(t),
            Some(Err(e)) => Err(e),
            None => Err(WriteError::Lost("the replay diverged".into())),
        }
    }

    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, String> {
        let read = self.take("a read of the bus", |e| match e {
            Event::BusRead { items, more, lost } => Some((
                items.clone(),
                lost.as_ref().map_or(Ok(*more), |e| Err(e.clone())),
            )),
            _ => None,
        });
        let Some((items, result)) = read else {
            return Err("the replay diverged".into());
        };
        for (t, item) in items {
            match to_bus(&item) {
                Some(item) => into.push((Timestamp::from_nanos(t), item)),
                None => self.diverge(format!("{item:?}"), "a frame a bus carries".into()),
            }
        }
        result
    }

    fn read_gps(&mut self, mut take: impl FnMut(&[u8])) -> Result<(), String> {
        let read = self.take("a read of the GPS receiver", |e| match e {
            Event::Gps { chunks, failed } => Some((chunks.clone(), result_of(failed))),
            _ => None,
        });
        let Some((chunks, result)) = read else {
            return Err("the replay diverged".into());
        };
        for chunk in &chunks {
            take(&chunk.0);
        }
        result
    }

    fn open(&mut self, _: Timestamp, _: Device) -> Result<&str, String> {
        let result = self.take("a device opened", |e| match e {
            Event::Open { result } => Some(result.clone()),
            _ => None,
        });
        self.opened = result.unwrap_or_else(|| Err("the replay diverged".into()))?;
        Ok(&self.opened)
    }

    fn close(&mut self, _: Device) {}

    fn keep_locks(&mut self, _: &[HeldLock]) -> Result<(), String> {
        self.take("the held locks kept", |e| match e {
            Event::Keep { failed } => Some(result_of(failed)),
            _ => None,
        })
        .unwrap_or(Ok(()))
    }

    fn publish(&mut self, publication: ToPublish) -> Result<(), String> {
        let ours = published(&publication);
        let recorded = self.take("a publication", |e| match e {
            Event::Publish { what, failed } => Some((what.clone(), result_of(failed))),
            _ => None,
        });
        let Some((theirs, result)) = recorded else {
            return Ok(());
        };
        if theirs != ours {
            self.next -= 1;
            let show = |p: &Published| match p {
                Published::Mux(bytes) => MuxStatus::read_from_bytes(&bytes.0)
                    .map_or_else(|_| format!("{p:?}"), |m| format!("mux status: {}", m.why())),
                other => format!("{other:?}"),
            };
            self.diverge(show(&theirs), show(&ours));
        }
        if let ToPublish::Mux(status) = publication {
            self.muxes.push(*status);
            self.replayed.push(true);
        }
        result
    }

    fn wake(&mut self, _: Readers) -> Result<(), String> {
        self.take("readers woken", |e| match e {
            Event::Woke { failed } => Some(result_of(failed)),
            _ => None,
        })
        .unwrap_or(Ok(()))
    }
}

/// The configuration a recording names (its start record's).
pub fn recorded_config(events: &[Event]) -> Result<&str, ReplayError> {
    match events.first() {
        Some(Event::Start { config, .. }) => Ok(config),
        _ => Err(ReplayError::NoStart),
    }
}

fn config_from(text: &str) -> Result<Config, ReplayError> {
    let raw: RawConfig = toml::from_str(text)?;
    Ok(raw.validate(Overrides::default())?)
}

/// Replays `events` on the recorded configuration, or on `config` (TOML) when given.
pub fn replay(events: &[Event], config: Option<&str>) -> Result<Replay, ReplayError> {
    let Some(Event::Start {
        version,
        config: recorded,
        now,
        unix_ns,
    }) = events.first()
    else {
        return Err(ReplayError::NoStart);
    };
    let text = config.unwrap_or(recorded);
    let config = config_from(text)?;
    let start = Timestamp::from_nanos(*now);
    let mut engine = Engine::new(
        EngineConfig::from_config(&config),
        driver_for_config(&config, start),
        Mux::new(&config.mux)?,
        start,
    );
    let mut player = Player {
        events,
        next: 1,
        last_ns: *now,
        divergence: None,
        opened: String::new(),
        muxes: Vec::new(),
        replayed: Vec::new(),
        writes: Vec::new(),
    };
    let config_differs = text != recorded;
    // Why the events read now are not replayed (after a cut or a gap, until a snapshot).
    let mut skipping: Option<String> = None;
    let (mut resumed, mut snapshots, mut snapshots_checked) = (Vec::new(), 0, 0);
    while player.divergence.is_none()
        && let Some(event) = events.get(player.next)
    {
        player.next += 1;
        if let Some(t) = event.time() {
            player.last_ns = t;
        }
        if let Some(why) = &skipping {
            if let Event::Snapshot { state } = event {
                snapshots += 1;
                if let Err(e) = engine.restore(&state.0) {
                    skipping = Some(format!("{why}; the snapshot after it: {e}"));
                    continue;
                }
                resumed.push((player.next - 1, player.last_ns, why.clone()));
                skipping = None;
            } else {
                read_on(std::slice::from_ref(event), &mut player);
            }
            continue;
        }
        let at = |now: &u64| Timestamp::from_nanos(*now);
        match event {
            Event::Restored { locks } => {
                let held: Vec<HeldLock> = locks
                    .iter()
                    .map(|l| HeldLock {
                        name: l.name.clone(),
                        holder: l.holder.clone(),
                        since: Timestamp::from_nanos(l.since),
                    })
                    .collect();
                engine.restore_locks(start, &held);
            }
            Event::RestoreFailed { reason } => engine.restore_failed(start, reason),
            Event::BusLost { now, reason } => engine.handle_bus_lost(at(now), reason),
            Event::Began { now } => engine.start(&mut player, at(now)),
            Event::Pass {
                bus,
                gps,
                sources,
                control,
                sim,
                polled,
            } => {
                let wake = Wake {
                    bus: *bus,
                    gps: *gps,
                    sources: *sources,
                    control: *control,
                    sim: *sim,
                    polled: *polled,
                };
                engine.run_pass(&mut player, wake);
            }
            Event::RxPaused { now } => {
                engine.is_rx_paused(at(now));
            }
            Event::Wakeups { now, fired } => {
                engine.spend_wakeups(at(now), *fired);
            }
            Event::ResetWakeups => engine.reset_wakeups(),
            Event::Stop { now } => engine.stop(&mut player, at(now)),
            Event::Snapshot { state } => {
                snapshots += 1;
                // Another configuration makes another state: only its decisions are compared.
                if !config_differs {
                    snapshots_checked += 1;
                    let ours = engine.snapshot().map_err(|e| e.to_string());
                    if ours.as_ref() != Ok(&state.0) {
                        player.next -= 1;
                        player.diverge(
                            format!("the engine's state ({} bytes)", state.0.len()),
                            match ours {
                                Ok(ours) => format!("another state ({} bytes)", ours.len()),
                                Err(e) => format!("no state: {e}"),
                            },
                        );
                    }
                }
            }
            Event::Gap { dropped } => {
                skipping = Some(format!(
                    "the recorder dropped the inputs of {dropped} passes (the disk was slow or \
                     full)"
                ));
            }
            Event::Cut => {
                skipping = Some("the ring had let go of the run's beginning".into());
            }
            other => {
                player.next -= 1;
                player.diverge(
                    format!("{other:?}"),
                    "the next pass or call of the shell".into(),
                );
            }
        }
    }
    let unreplayed_decisions = player.replayed.iter().filter(|&&r| !r).count();
    Ok(Replay {
        recorded_version: version.clone(),
        version_differs: version != env!("CARGO_PKG_VERSION"),
        config_differs,
        checked: player.divergence.as_ref().map_or(player.next, |d| d.event),
        events: events.len(),
        decisions: player.muxes.len() - unreplayed_decisions,
        unreplayed_decisions,
        frames_written: player.writes.len(),
        divergence: player.divergence,
        incomplete: skipping.map(|why| format!("{why}, and no snapshot of the engine follows")),
        resumed,
        snapshots,
        snapshots_checked,
        start_ns: *now,
        start_unix_ns: *unix_ns,
        muxes: player.muxes,
        replayed: player.replayed,
        writes: player.writes,
    })
}

/// The mux decisions and the writes of `events` as they were recorded, for a story that goes on
/// where the replay cannot (the engine's state after a gap or a cut is unknown until the next
/// snapshot).
fn read_on(events: &[Event], player: &mut Player<'_>) {
    for event in events {
        match event {
            Event::Publish {
                what: Published::Mux(bytes),
                ..
            } => {
                if let Ok(status) = MuxStatus::read_from_bytes(&bytes.0) {
                    player.muxes.push(status);
                    player.replayed.push(false);
                }
            }
            Event::Write {
                outcome: Outcome::Out(t) | Outcome::Held(t),
                ..
            } => player.writes.push(*t),
            _ => {}
        }
    }
}

/// One stretch of the run under one decision.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Chapter {
    /// Its first mux status, ns (`CLOCK_MONOTONIC`) and the wall clock.
    pub at_ns: u64,
    pub at: String,
    /// [`MuxStatus::why`].
    pub why: String,
    /// The source that drove, if one did.
    pub driver: Option<String>,
    /// A stop that was not asked for by the one who drove began here.
    pub stop: bool,
    /// From the decision to the first command written after it, ms.
    pub to_first_write_ms: Option<f64>,
    /// Decided again by the replay (else read from the recording).
    pub replayed: bool,
}

/// The wall-clock time of `ns` (`HH:MM:SS.mmm` UTC).
pub fn wall(replay: &Replay, ns: u64) -> String {
    let unix = replay.start_unix_ns + ns.saturating_sub(replay.start_ns);
    let ms = unix / 1_000_000;
    let (h, m, s) = (ms / 3_600_000 % 24, ms / 60_000 % 60, ms / 1000 % 60);
    format!("{h:02}:{m:02}:{s:02}.{:03}", ms % 1000)
}

/// The run in chapters: one each time the explanation of the decision changed.
pub fn story(replay: &Replay) -> Vec<Chapter> {
    let mut chapters: Vec<Chapter> = Vec::new();
    let mut before: Option<&MuxStatus> = None;
    for (index, status) in replay.muxes.iter().enumerate() {
        let why = status.why().to_string();
        let replayed = replay.replayed.get(index) == Some(&true);
        if chapters
            .last()
            .is_some_and(|c| c.why == why && c.replayed == replayed)
        {
            before = Some(status);
            continue;
        }
        let stop = before.is_some_and(|b| super::is_unasked_stop(b, status));
        let to_first_write_ms = stop
            .then(|| replay.writes.iter().find(|&&w| w >= status.stamp_ns))
            .flatten()
            .map(|w| (w - status.stamp_ns) as f64 / 1e6);
        chapters.push(Chapter {
            at_ns: status.stamp_ns,
            at: wall(replay, status.stamp_ns),
            why,
            driver: (status.zero_reason == ZeroReason::NONE)
                .then(|| status.active().map(|s| s.name().to_string()))
                .flatten(),
            stop,
            to_first_write_ms,
            replayed,
        });
        before = Some(status);
    }
    chapters
}

/// The decision in force at `ns`, in words: who won at what speed (or why nothing moves), the
/// required sources, the locks, and the last stop before it with how it ended.
pub fn at(replay: &Replay, ns: u64) -> Option<String> {
    let status = replay.muxes.iter().rev().find(|m| m.stamp_ns <= ns)?;
    let mut said = vec![format!(
        "at {} (decided {}): {} — output {:.2} m/s",
        wall(replay, ns),
        wall(replay, status.stamp_ns),
        status.why(),
        status.output.linear_x_mps
    )];
    for source in (status.sources().iter()).filter(|s| s.has(SourceFlags::REQUIRED)) {
        let fresh = source.has(SourceFlags::FRESH);
        said.push(format!(
            "{} {}",
            source.name(),
            if fresh { "fresh" } else { "silent" }
        ));
    }
    let held: Vec<String> = (status.locks().iter())
        .filter(|l| l.held != 0)
        .map(|l| format!("{} held since {}", l.name(), wall(replay, l.since_ns)))
        .collect();
    said.push(if held.is_empty() {
        "no lock held".into()
    } else {
        held.join(", ")
    });
    let chapters = story(replay);
    if let Some(stop) = chapters.iter().rev().find(|c| c.stop && c.at_ns <= ns) {
        let mut ended = format!("the last stop at {} ({})", stop.at, stop.why);
        let mut after = chapters
            .iter()
            .filter(|c| c.at_ns > stop.at_ns && c.at_ns <= ns);
        let waited = (after.clone()).find(|c| c.why.starts_with("stopped: waiting for a zero"));
        if let Some(waited) = waited {
            ended += &format!(
                ", then {} at {}",
                waited.why.trim_start_matches("stopped: "),
                waited.at
            );
        }
        if let Some((driver, again)) = (after.clone()).find_map(|c| Some((c.driver.as_ref()?, c))) {
            ended += &format!(
                ", {driver} drove again at {} (its zero ended the wait)",
                again.at
            );
        }
        // The stop in force is said already.
        if after.next().is_some() {
            said.push(ended);
        }
    }
    Some(said.join("; "))
}

/// `TIME` of `--at`: `HH:MM:SS[.mmm]` (UTC, on the recorded day) or `+SECONDS` since the start;
/// ns on the recorded run's clock.
pub fn parse_time(replay: &Replay, text: &str) -> Option<u64> {
    if let Some(seconds) = text.strip_prefix('+') {
        let seconds: f64 = seconds.parse().ok()?;
        return (seconds >= 0.0).then(|| replay.start_ns + (seconds * 1e9) as u64);
    }
    let mut parts = text.split(':');
    let (h, m, s): (u64, u64, f64) = (
        parts.next()?.parse().ok()?,
        parts.next()?.parse().ok()?,
        parts.next()?.parse().ok()?,
    );
    let of_day = ((h * 3600 + m * 60) as f64 + s) * 1e9;
    let day_start = replay.start_unix_ns / 86_400_000_000_000 * 86_400_000_000_000;
    let unix = day_start + of_day as u64;
    (replay.start_ns + unix).checked_sub(replay.start_unix_ns)
}

/// The verdict and the story in words.
pub fn render(replay: &Replay, chapters: &[Chapter]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let on = if replay.config_differs {
        "another configuration than the recorded one"
    } else {
        "the recorded configuration"
    };
    let _ = writeln!(
        out,
        "recorded by chassisd {}{}; replayed on {on}",
        replay.recorded_version,
        if replay.version_differs {
            format!(" (this is {})", env!("CARGO_PKG_VERSION"))
        } else {
            String::new()
        }
    );
    let _ = match &replay.divergence {
        None => writeln!(
            out,
            "replay: {} of {} events, {} mux decisions and {} items written: identical{}",
            replay.checked,
            replay.events,
            replay.decisions,
            replay.frames_written,
            if replay.incomplete.is_some() {
                " as far as the replay went"
            } else {
                ""
            }
        ),
        Some(d) => writeln!(
            out,
            "replay DIVERGED at event {} ({}), after {} identical mux decisions:\n  recorded: \
             {}\n  replayed: {}",
            d.event,
            wall(replay, d.at_ns),
            replay.decisions.saturating_sub(1),
            d.recorded,
            d.replayed
        ),
    };
    for (event, ns, why) in &replay.resumed {
        let _ = writeln!(
            out,
            "replay went on at event {event} ({}) from the engine's snapshot: {why} before it",
            wall(replay, *ns)
        );
    }
    let _ = writeln!(
        out,
        "engine state: {} of {} snapshots compared{}",
        replay.snapshots_checked,
        replay.snapshots,
        if replay.divergence.is_none() {
            ", identical"
        } else {
            ""
        }
    );
    if let Some(why) = &replay.incomplete {
        let _ = writeln!(out, "replay stopped: {why}");
    }
    let _ = writeln!(out, "story:");
    let mut resumed = replay.resumed.iter().peekable();
    let mut replaying = true;
    for c in chapters {
        while let Some((_, ns, why)) = resumed.next_if(|(_, ns, _)| *ns <= c.at_ns) {
            let at = wall(replay, *ns);
            let _ = writeln!(
                out,
                "  ({why}: replayed on from the engine's state at {at})"
            );
            replaying = true;
        }
        if c.replayed != replaying {
            replaying = c.replayed;
            let _ = writeln!(out, "  (from here on as recorded, not replayed)");
        }
        let mark = if c.stop { "STOP " } else { "" };
        let _ = write!(out, "  {}  {mark}{}", c.at, c.why);
        if let Some(ms) = c.to_first_write_ms {
            let _ = write!(
                out,
                " (first command written {ms:.3} ms after the decision)"
            );
        }
        out.push('\n');
    }
    out
}
