//! The priority mux: configured sources × priorities × timeouts × locks × limits → one command.
//!
//! * Active source = the highest priority whose latest request is younger than its timeout;
//!   equal priority → the newer request. Nothing active → zero.
//! * A request's age counts from the earlier of its own stamp and its arrival, so a stale
//!   request is never fresh and a stamp from the future buys nothing.
//! * A lock held by a source blocks every source of lower priority than the lock until the same
//!   source (or the operator) releases it; it survives the holder's death.
//! * A required source (the safety monitor) must be fresh — a heartbeat is enough — or the output
//!   is zero.
//! * A source may send a speed envelope instead of a request (`RequestFlags::LIMIT`): it does not
//!   compete, but clamps the output of every source of its priority or lower, per direction —
//!   how the safety monitor slows the robot or blocks only the motion towards an obstacle.
//! * The robot's standing speed limit caps every source's linear speed: any source lowers it
//!   (`RequestFlags::SPEED_LIMIT`, a request that asks nothing else), only the operator raises or
//!   lifts it ([`Mux::set_speed_limit`]). `MuxStatus` says the cap and who set it.
//! * Configured speed limits, then acceleration smoothing; a stop from a safety-priority source,
//!   a stale required source, a lock and the timeout of the last active source are never
//!   smoothed: motion never outlives a dead source's timeout.
//! * **Motion starts only from a zero** (ISO 13850, IEC 60204-1: resetting a stop shall not
//!   initiate a restart; ISO 3691-4: no automatic restart after a stop or a power interruption).
//!   Every [`Stop`] the winning source did not ask for itself ends the same way: each source it
//!   stopped whose last word was motion is *awaiting zero*, and its motion is not obeyed until
//!   it asks for zero (a zero request, a heartbeat or an envelope). Silence, a timeout or
//!   another source's zero is not a zero. The stops: the service's start (every source awaits:
//!   a client process that starts sends one zero as it connects); a lock released — by its
//!   holder, the operator, any bridge, or after a latch restored at start (the sources below
//!   it); the required source stale and fresh again; and the holds the engine reports from the
//!   bus and the chassis ([`Mux::set_holds`]: bus lost or bus-off, the chassis' E-stop,
//!   remote-control takeover, a drive fault), while which the output is zero
//!   (`ZeroReason::HELD`). While the source that would win awaits, the output is zero and
//!   `MuxStatus` says so (`ZeroReason::AWAITING_ZERO`, `awaiting_source`, `stop`); it does not
//!   hand the robot to a lower source either.
//! * A held lock stops with a [`StopCategory`] (IEC 60204-1): its engage's, else its configured
//!   one. A stop of category 1 or 2 ramps the output down at `limits.braking_mps2` where one is
//!   configured (a controlled stop along the same path), one of category 0 does not.
//!   [`Mux::stop_category`] names the lowest in force once the output is zero; the engine
//!   carries it out on the drive (category 0 and 1 disable it). Every other stop is category 2.
//! * It takes only a [`ValidRequest`]: a request with a NaN or infinite number or a negative
//!   envelope is refused where the service parses it, and counted here ([`Mux::refuse`]). One
//!   asking for a speed no chassis could reach (over [`MAX_SANE_SPEED`] or
//!   [`MAX_SANE_YAW_RATE`], steering past ±90°) or naming a lock it does not have is rejected
//!   here. Either way it is counted against its source, and the source's previous request
//!   stands.
//!
//! Pure: time is a parameter. The service calls [`Mux::evaluate`] when a request arrives, on its
//! tick, and at [`Mux::next_deadline`].

use std::time::Duration;

use chassis_interfaces::{
    ClampFlags, Envelope, InvalidVelocity, LockStatus, MuxStatus, RequestFlags, SourceFlags,
    SourceStatus, Stop, StopCategory, ValidRequest, Velocity, ZeroReason,
};
use chassis_protocols::Timestamp;
use chassis_protocols::snapshot::{SnapshotError, raw};
use chassisd_config::mux::{LimitsConfig, LockConfig, MuxConfig, MuxConfigError, SourceConfig};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Fastest speed a request may ask for, m/s: far beyond any of these robots; a larger value is
/// a client bug, rejected rather than clamped.
pub const MAX_SANE_SPEED: f32 = 50.0;
/// Largest yaw rate a request may ask for, rad/s.
pub const MAX_SANE_YAW_RATE: f32 = 50.0;

/// A motion beyond [`MAX_SANE_SPEED`], [`MAX_SANE_YAW_RATE`] or ±π/2 steering. Envelope bounds
/// are not judged here: one beyond any speed limits nothing (`SafetyStatus::UNLIMITED` is
/// `f32::MAX`), and a negative one is no [`ValidRequest`].
fn is_absurd(v: &Velocity) -> bool {
    v.linear_x_mps().abs() > MAX_SANE_SPEED
        || v.linear_y_mps().abs() > MAX_SANE_SPEED
        || v.angular_z_radps().abs() > MAX_SANE_YAW_RATE
        || v.steer_rad().abs() > std::f32::consts::FRAC_PI_2
}

/// Why a request was not taken.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum Rejection {
    /// Refused where the service parsed it: no [`ValidRequest`].
    #[error("not a valid request: {0}")]
    Invalid(#[from] InvalidVelocity),
    #[error(
        "absurd value in the request (beyond {MAX_SANE_SPEED} m/s, {MAX_SANE_YAW_RATE} rad/s or ±π/2 steering)"
    )]
    Absurd,
    #[error("unknown lock bits 0x{0:X}")]
    UnknownLock(u32),
}

/// A lock name the configuration does not have.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("no lock called '{name}' (configured: {configured})")]
pub struct NoSuchLock {
    pub name: String,
    pub configured: String,
}

/// A source's latest request and the time its age counts from.
type Latest = Option<(Timestamp, ValidRequest)>;

#[derive(Debug, Clone)]
struct Source {
    config: SourceConfig,
    timeout: Duration,
    latest: Latest,
    rejected: u32,
    /// The [`Stop`] whose end its motion waits on: its last word was motion (or it has not
    /// spoken since the service started), and only a zero request of its own clears it.
    awaiting: u8,
}

impl Source {
    fn is_fresh(&self, now: Timestamp) -> bool {
        self.latest
            .is_some_and(|(t, _)| now.saturating_since(t) < self.timeout)
    }

    fn expiry(&self) -> Option<Timestamp> {
        self.latest.map(|(t, _)| t + self.timeout)
    }

    /// Whether its last word, fresh or not, was motion (not a heartbeat, not an envelope, not
    /// zero).
    fn last_word_was_motion(&self) -> bool {
        self.latest.is_some_and(|(_, r)| !asks_nothing(&r))
    }

    /// Awaits a zero since a stop and has spoken (a source that never spoke awaits its first
    /// zero since the start, which its library sends as it connects).
    fn is_awaiting(&self) -> bool {
        self.awaiting != Stop::NONE && self.latest.is_some()
    }
}

/// A request that asks for no motion: a zero, a heartbeat or an envelope. This, and only this,
/// ends a source's wait after a stop.
fn asks_nothing(request: &ValidRequest) -> bool {
    request.is_heartbeat() || request.is_limit() || request.velocity().is_zero()
}

#[derive(Debug, Clone)]
struct Lock {
    config: LockConfig,
    /// Holder (source index or [`LockStatus::HOLDER_OPERATOR`]) and since when.
    held: Option<(u8, Timestamp)>,
    /// The [`StopCategory`] of the hold: the one its engage asked for, else the configured one.
    category: u8,
}

impl Lock {
    fn configured_category(&self) -> u8 {
        self.config.category.unwrap_or(StopCategory::HOLD)
    }

    /// The [`StopCategory`] it stops with: its hold's while held, else its configured one.
    fn stop_category(&self) -> u8 {
        if self.held.is_some() {
            self.category
        } else {
            self.configured_category()
        }
    }

    /// Held from `since` by `holder`, stopping with `category` (the configured one if `None`).
    fn hold(&mut self, holder: u8, since: Timestamp, category: Option<u8>) {
        self.held = Some((holder, since));
        self.category = category
            .filter(|&c| c <= StopCategory::HOLD)
            .unwrap_or_else(|| self.configured_category());
    }
}

/// The outcome of one evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// What to command.
    pub output: Velocity,
    /// The status changed in a way worth publishing at once (winner, reason, output, locks).
    pub changed: bool,
}

/// The mux.
#[derive(Debug, Clone, Default)]
pub struct Mux {
    sources: Vec<Source>,
    locks: Vec<Lock>,
    limits: LimitsConfig,
    output: Velocity,
    /// The configured speed limits, as bounds.
    speed_limits: Envelope,
    /// The standing speed limit, m/s, and who set it (a source index or
    /// [`LockStatus::HOLDER_OPERATOR`]).
    speed_limit: Option<(f32, u8)>,
    last_evaluation: Option<Timestamp>,
    status: MuxStatus,
    rejected: u64,
    /// The holds the engine reported (one bit per [`Stop`]) and the required sources' liveness
    /// at the last evaluation: their ends are stops.
    holds: u32,
    required: Liveness,
}

/// What the mux holds beyond its configuration, as a snapshot of the engine keeps it
/// ([`Mux::state`]): each source's latest request and wait, each lock's hold, the output and the
/// standing limit. A replay restores it on the configuration it runs on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MuxState {
    /// Per source: the latest request and its arrival, the rejections, the stop it awaits.
    sources: Vec<(Latest, u32, u8)>,
    /// Per lock: holder and since when, the category of the hold.
    locks: Vec<(Option<(u8, Timestamp)>, u8)>,
    output: Velocity,
    speed_limit: Option<(f32, u8)>,
    last_evaluation: Option<Timestamp>,
    #[serde(with = "raw")]
    status: MuxStatus,
    rejected: u64,
    holds: u32,
    required: Liveness,
}

/// The required sources, as the last evaluation found them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
enum Liveness {
    /// Not all fresh yet since the start (the safety monitor starting is not a restart).
    #[default]
    NeverFresh,
    Fresh,
    /// One went stale after all had been fresh: their return is a stop's end.
    Lost,
}

impl Mux {
    /// True for a source of safety priority: its stop is never smoothed, and never waits.
    pub fn is_safety_source(&self, index: usize) -> bool {
        self.sources
            .get(index)
            .is_some_and(|s| s.config.priority >= self.limits.safety_priority)
    }

    pub fn new(config: &MuxConfig) -> Result<Self, MuxConfigError> {
        config.validate()?;
        let sources: Vec<Source> = config
            .sources
            .iter()
            .map(|c| Source {
                timeout: Duration::from_millis(c.timeout_ms),
                config: c.clone(),
                latest: None,
                rejected: 0,
                // The service's start is a stop: a source that kept asking through a restart
                // must ask for zero first.
                awaiting: Stop::SERVICE_START,
            })
            .collect();
        let locks: Vec<Lock> = config
            .locks
            .iter()
            .map(|c| Lock {
                config: c.clone(),
                held: None,
                // Set by every hold.
                category: StopCategory::HOLD,
            })
            .collect();
        let mut status = MuxStatus {
            // Counts were validated against MAX_SOURCES / MAX_LOCKS (8 and 4).
            source_count: sources.len() as u8,
            lock_count: locks.len() as u8,
            active_source: MuxStatus::NO_SOURCE,
            zero_reason: ZeroReason::STARTING,
            active_age_ms: u32::MAX,
            ..MuxStatus::default()
        };
        for (slot, source) in status.sources.iter_mut().zip(&sources) {
            slot.set_name(&source.config.name);
            slot.priority = source.config.priority;
            slot.timeout_ms = u32::try_from(source.config.timeout_ms).unwrap_or(u32::MAX);
            slot.age_ms = u32::MAX;
            if source.config.required {
                slot.flags |= SourceFlags::REQUIRED;
            }
            if source.config.remote {
                slot.flags |= SourceFlags::REMOTE;
            }
        }
        for (slot, lock) in status.locks.iter_mut().zip(&locks) {
            slot.set_name(&lock.config.name);
            slot.priority = lock.config.priority;
            slot.holder = LockStatus::HOLDER_NONE;
        }
        Ok(Self {
            sources,
            locks,
            limits: config.limits.clone(),
            output: Velocity::ZERO,
            speed_limits: speed_limits(&config.limits),
            speed_limit: None,
            last_evaluation: None,
            status,
            rejected: 0,
            holds: 0,
            required: Liveness::NeverFresh,
        })
    }

    /// Its state beyond its configuration.
    pub fn state(&self) -> MuxState {
        MuxState {
            sources: (self.sources.iter())
                .map(|s| (s.latest, s.rejected, s.awaiting))
                .collect(),
            locks: self.locks.iter().map(|l| (l.held, l.category)).collect(),
            output: self.output,
            speed_limit: self.speed_limit,
            last_evaluation: self.last_evaluation,
            status: self.status,
            rejected: self.rejected,
            holds: self.holds,
            required: self.required,
        }
    }

    /// Goes on from `state`, taken of a mux of as many sources and locks.
    pub fn restore(&mut self, state: MuxState) -> Result<(), SnapshotError> {
        if state.sources.len() != self.sources.len() || state.locks.len() != self.locks.len() {
            return Err(SnapshotError::Mismatch(format!(
                "the mux had {} sources and {} locks, this configuration has {} and {}",
                state.sources.len(),
                state.locks.len(),
                self.sources.len(),
                self.locks.len()
            )));
        }
        for (source, (latest, rejected, awaiting)) in self.sources.iter_mut().zip(state.sources) {
            (source.latest, source.rejected, source.awaiting) = (latest, rejected, awaiting);
        }
        for (lock, (held, category)) in self.locks.iter_mut().zip(state.locks) {
            (lock.held, lock.category) = (held, category);
        }
        self.output = state.output;
        self.speed_limit = state.speed_limit;
        self.last_evaluation = state.last_evaluation;
        self.status = state.status;
        self.rejected = state.rejected;
        self.holds = state.holds;
        self.required = state.required;
        Ok(())
    }

    /// Takes a request from source `index` received at `now`. An absurd speed and unknown lock
    /// bits are rejected ([`Mux::refuse`]: counted; the source's previous request stands).
    pub fn on_request(
        &mut self,
        now: Timestamp,
        index: usize,
        request: &ValidRequest,
    ) -> Result<(), Rejection> {
        if index >= self.sources.len() {
            return Ok(());
        }
        let lock_count = self.locks.len();
        let known_locks = if lock_count >= 32 {
            u32::MAX
        } else {
            (1u32 << lock_count) - 1
        };
        let unknown_locks = (request.lock_engage | request.lock_release) & !known_locks;
        if is_absurd(&request.velocity()) {
            return Err(self.refuse(index, Rejection::Absurd));
        }
        if unknown_locks != 0 {
            return Err(self.refuse(index, Rejection::UnknownLock(unknown_locks)));
        }
        // Index < MAX_SOURCES (8) fits a u8.
        let holder = index as u8;
        if let Some(mps) = request.speed_limit() {
            if self.speed_limit.is_none_or(|(standing, _)| mps < standing) {
                self.speed_limit = Some((mps, holder));
            }
            return Ok(());
        }
        let source = &mut self.sources[index];
        let arrival = Timestamp::from_nanos(request.stamp_ns).min(now);
        source.latest = Some((arrival, *request));
        if asks_nothing(request) {
            source.awaiting = Stop::NONE;
        }
        let mut released = Vec::new();
        for (bit, lock) in self.locks.iter_mut().enumerate() {
            if request.lock_engage & (1 << bit) != 0 && lock.held.is_none() {
                lock.hold(holder, now, RequestFlags::category(request.flags));
            }
            if request.lock_release & (1 << bit) != 0 && lock.held.is_some_and(|(h, _)| h == holder)
            {
                lock.held = None;
                released.push(lock.config.priority);
            }
        }
        for priority in released {
            self.stop_ended(Stop::LOCK_RELEASED, Some(priority));
        }
        Ok(())
    }

    /// Counts `rejection` against source `index`, whose previous request stands, and returns it:
    /// how the service refuses a request it could not parse, and the mux one it will not take.
    pub fn refuse(&mut self, index: usize, rejection: Rejection) -> Rejection {
        if let Some(source) = self.sources.get_mut(index) {
            source.rejected = source.rejected.saturating_add(1);
            self.rejected += 1;
        }
        rejection
    }

    /// Releases the lock `name` whoever holds it (operator). Returns whether it was held. The
    /// sources it blocked whose last word was motion now await a zero request.
    pub fn release_lock(&mut self, name: &str) -> Result<bool, NoSuchLock> {
        let lock = self.lock_mut(name)?;
        let priority = lock.config.priority;
        let was_held = lock.held.take().is_some();
        if was_held {
            self.stop_ended(Stop::LOCK_RELEASED, Some(priority));
        }
        Ok(was_held)
    }

    /// The sources that have spoken and whose motion waits for a zero request since a stop.
    pub fn awaiting_zero(&self) -> Vec<&str> {
        self.sources
            .iter()
            .filter(|s| s.is_awaiting())
            .map(|s| s.config.name.as_str())
            .collect()
    }

    /// The holds in force, one bit per [`Stop`] ([`hold_bit`]), as the engine reads them from
    /// the bus and the chassis: while any is held the output is zero ([`ZeroReason::HELD`]);
    /// each that ends is a stop.
    pub fn set_holds(&mut self, holds: u32) {
        let ended = self.holds & !holds;
        self.holds = holds;
        for (stop, _) in Stop::NAMES {
            if ended & hold_bit(stop) != 0 {
                self.stop_ended(stop, None);
            }
        }
    }

    /// The holds in force (see [`Mux::set_holds`]).
    pub fn holds(&self) -> u32 {
        self.holds
    }

    /// `stop` ended: every source it stopped (those below `below`, or every one) whose last
    /// word was motion awaits a zero request before its motion is obeyed again. A source that
    /// has not spoken keeps the wait it has since the start.
    fn stop_ended(&mut self, stop: u8, below: Option<u8>) {
        for source in &mut self.sources {
            if below.is_none_or(|p| source.config.priority < p) && source.last_word_was_motion() {
                source.awaiting = stop;
            }
        }
    }

    /// Sets the standing speed limit on behalf of the operator, higher or lower than it was;
    /// `None` lifts it. The caller has checked that a limit is a positive number.
    pub fn set_speed_limit(&mut self, mps: Option<f32>) {
        self.speed_limit = mps.map(|mps| (mps, LockStatus::HOLDER_OPERATOR));
    }

    /// Engages the lock `name` on behalf of the operator, stopping with `category` (`None`: the
    /// lock's configured one). Returns whether it was free; a held lock keeps its category.
    pub fn engage_lock(
        &mut self,
        now: Timestamp,
        name: &str,
        category: Option<u8>,
    ) -> Result<bool, NoSuchLock> {
        let lock = self.lock_mut(name)?;
        if lock.held.is_some() {
            return Ok(false);
        }
        lock.hold(LockStatus::HOLDER_OPERATOR, now, category);
        Ok(true)
    }

    /// The [`StopCategory`] lock `name` stops with: its hold's while held, else its configured
    /// one.
    pub fn lock_category(&self, name: &str) -> Option<u8> {
        let lock = self.locks.iter().find(|l| l.config.name == name)?;
        Some(lock.stop_category())
    }

    /// The lowest [`StopCategory`] among the held locks, while the output is zero: the stop
    /// the engine carries out on the drive (`None`: no lock stops the robot). A stop of
    /// category 1 or 2 reaches zero at `limits.braking_mps2` where one is configured.
    pub fn stop_category(&self) -> Option<u8> {
        self.held_category().filter(|_| self.output.is_zero())
    }

    /// The lowest [`StopCategory`] among the held locks.
    fn held_category(&self) -> Option<u8> {
        self.locks
            .iter()
            .filter(|l| l.held.is_some())
            .map(|l| l.category)
            .min()
    }

    /// Holds the lock `name` for `holder` (a source index or [`LockStatus::HOLDER_OPERATOR`])
    /// since `since`, whatever held it before: how the service restores the locks it held before
    /// a restart.
    pub fn restore_lock(
        &mut self,
        name: &str,
        holder: u8,
        since: Timestamp,
    ) -> Result<(), NoSuchLock> {
        let lock = self.lock_mut(name)?;
        lock.hold(holder, since, None);
        Ok(())
    }

    /// Every configured lock in order: its name and, while held, its holder and since when.
    pub fn locks(&self) -> impl Iterator<Item = (&str, Option<(u8, Timestamp)>)> {
        self.locks.iter().map(|l| (l.config.name.as_str(), l.held))
    }

    fn lock_mut(&mut self, name: &str) -> Result<&mut Lock, NoSuchLock> {
        let configured: Vec<&str> = self.locks.iter().map(|l| l.config.name.as_str()).collect();
        let error = NoSuchLock {
            name: name.to_string(),
            configured: configured.join(", "),
        };
        self.locks
            .iter_mut()
            .find(|l| l.config.name == name)
            .ok_or(error)
    }

    /// Decides the command at `now`.
    pub fn evaluate(&mut self, now: Timestamp) -> Decision {
        let dt = self
            .last_evaluation
            .map_or(0.0, |t| now.secs_since(t).min(0.5));
        self.last_evaluation = Some(now);

        let blocking_priority = self
            .locks
            .iter()
            .filter(|l| l.held.is_some())
            .map(|l| l.config.priority)
            .max();
        let required_stale = self
            .sources
            .iter()
            .any(|s| s.config.required && !s.is_fresh(now));
        self.required = match (self.required, required_stale) {
            (Liveness::Lost, false) => {
                self.stop_ended(Stop::REQUIRED_SOURCE, None);
                Liveness::Fresh
            }
            (_, false) => Liveness::Fresh,
            (Liveness::NeverFresh, true) => Liveness::NeverFresh,
            (_, true) => Liveness::Lost,
        };
        let held = Stop::NAMES
            .into_iter()
            .map(|(stop, _)| stop)
            .find(|&stop| self.holds & hold_bit(stop) != 0);

        // The winner: fresh, asking for something, not blocked; highest priority, then newest.
        let mut winner: Option<usize> = None;
        let mut any_fresh_request = false;
        for (i, s) in self.sources.iter().enumerate() {
            let Some((arrival, request)) = s.latest else {
                continue;
            };
            if !s.is_fresh(now) || request.is_heartbeat() {
                continue;
            }
            any_fresh_request = true;
            if blocking_priority.is_some_and(|p| s.config.priority < p) {
                continue;
            }
            let better = match winner {
                None => true,
                Some(w) => {
                    let ws = &self.sources[w];
                    let w_arrival = ws.latest.map_or(Timestamp::ZERO, |(t, _)| t);
                    s.config.priority > ws.config.priority
                        || (s.config.priority == ws.config.priority && arrival > w_arrival)
                }
            };
            if better {
                winner = Some(i);
            }
        }

        let awaiting = winner.filter(|&w| self.sources[w].awaiting != Stop::NONE);
        let (requested, reason, winner) = if required_stale {
            (Velocity::ZERO, ZeroReason::REQUIRED_SOURCE_STALE, None)
        } else if held.is_some() {
            (Velocity::ZERO, ZeroReason::HELD, None)
        } else if awaiting.is_some() {
            (Velocity::ZERO, ZeroReason::AWAITING_ZERO, None)
        } else if let Some(w) = winner {
            let request = self.sources[w].latest.map(|(_, r)| r).unwrap_or_default();
            (request.velocity(), ZeroReason::NONE, Some(w))
        } else if any_fresh_request {
            (Velocity::ZERO, ZeroReason::LOCKED, None)
        } else {
            (Velocity::ZERO, ZeroReason::NO_ACTIVE_SOURCE, None)
        };

        let (limited, mut clamp_flags) = self.apply_speed_limits(requested);
        let (limited, limited_by) = match winner {
            Some(w) => self.apply_envelopes(now, self.sources[w].config.priority, limited),
            None => (limited, Vec::new()),
        };
        let safety_limited = limited_by
            .iter()
            .any(|&i| self.sources[i].config.priority >= self.limits.safety_priority);
        if !limited_by.is_empty() {
            clamp_flags |= ClampFlags::SAFETY_LIMIT;
        }
        let safety_stop = winner.is_some_and(|w| {
            self.sources[w].config.priority >= self.limits.safety_priority && limited.is_zero()
        });
        // A source that falls silent gets no grace period: its motion ends with its timeout.
        let unsmoothed = safety_stop
            || safety_limited
            || matches!(
                reason,
                ZeroReason::REQUIRED_SOURCE_STALE
                    | ZeroReason::HELD
                    | ZeroReason::LOCKED
                    | ZeroReason::NO_ACTIVE_SOURCE
                    | ZeroReason::AWAITING_ZERO
            );
        // A held lock's controlled stop (category 1 or 2) ramps down at the braking figure.
        let braking = reason == ZeroReason::LOCKED
            && self.limits.braking_mps2 > 0.0
            && self.held_category() != Some(StopCategory::CUT)
            && !self.output.is_zero();
        let output = if braking {
            clamp_flags |= ClampFlags::ACCELERATION_LIMIT;
            self.output.braked((self.limits.braking_mps2 * dt) as f32)
        } else if unsmoothed {
            limited
        } else {
            let (smoothed, smoothing_flags) = self.smooth(limited, dt);
            clamp_flags |= smoothing_flags;
            smoothed
        };
        self.output = output;

        let previous = self.status;
        self.fill_status(now, winner, reason, requested, output, clamp_flags);
        self.status.awaiting_source = awaiting
            .filter(|_| reason == ZeroReason::AWAITING_ZERO)
            .map_or(MuxStatus::NO_SOURCE, |w| w as u8);
        self.status.stop = match reason {
            ZeroReason::HELD => held.unwrap_or(Stop::NONE),
            ZeroReason::AWAITING_ZERO => awaiting.map_or(Stop::NONE, |w| self.sources[w].awaiting),
            _ => Stop::NONE,
        };
        for &i in &limited_by {
            if let Some(slot) = self.status.sources.get_mut(i) {
                slot.flags |= SourceFlags::LIMITING;
            }
        }
        let changed = previous.active_source != self.status.active_source
            || previous.zero_reason != self.status.zero_reason
            || previous.output != self.status.output
            || previous.clamp_flags != self.status.clamp_flags
            || previous.awaiting_source != self.status.awaiting_source
            || previous.stop != self.status.stop
            || previous.speed_limit_mps != self.status.speed_limit_mps
            || previous.speed_limit_holder != self.status.speed_limit_holder
            || previous.locks != self.status.locks;
        Decision { output, changed }
    }

    /// The configured limits, then the standing speed limit (linear speeds only).
    fn apply_speed_limits(&self, t: Velocity) -> (Velocity, u32) {
        let configured = t.bounded(&self.speed_limits);
        let mut flags = if configured != t {
            ClampFlags::CONFIG_SPEED_LIMIT
        } else {
            0
        };
        let Some((mps, _)) = self.speed_limit else {
            return (configured, flags);
        };
        let limited = configured.bounded(&Envelope {
            forward_mps: mps,
            reverse_mps: mps,
            lateral_mps: mps,
            angular_radps: f32::INFINITY,
        });
        if limited != configured {
            flags |= ClampFlags::SPEED_LIMIT;
        }
        (limited, flags)
    }

    /// Clamps `t` to the envelopes of the fresh limiting sources at or above `priority` (a
    /// steering angle is not a yaw rate: the envelope's yaw-rate bound leaves it alone);
    /// returns the sources whose envelope changed it.
    fn apply_envelopes(
        &self,
        now: Timestamp,
        priority: u8,
        mut t: Velocity,
    ) -> (Velocity, Vec<usize>) {
        let mut by = Vec::new();
        for (i, s) in self.sources.iter().enumerate() {
            let Some(envelope) = s.latest.and_then(|(_, r)| r.envelope()) else {
                continue;
            };
            if !s.is_fresh(now) || s.config.priority < priority {
                continue;
            }
            let envelope = if t.uses_steer() {
                Envelope {
                    angular_radps: f32::INFINITY,
                    ..envelope
                }
            } else {
                envelope
            };
            let before = t;
            t = t.bounded(&envelope);
            if t != before {
                by.push(i);
            }
        }
        (t, by)
    }

    fn smooth(&self, target: Velocity, dt: f64) -> (Velocity, u32) {
        // A rate of 0 (or less) is no smoothing: an infinite step.
        let step = |rate: f64| {
            if rate > 0.0 {
                (rate * dt) as f32
            } else {
                f32::INFINITY
            }
        };
        let out = self.output.towards(
            target,
            step(self.limits.linear_accel_mps2),
            step(self.limits.angular_accel_radps2),
        );
        let flags = if out != target {
            ClampFlags::ACCELERATION_LIMIT
        } else {
            0
        };
        (out, flags)
    }

    fn fill_status(
        &mut self,
        now: Timestamp,
        winner: Option<usize>,
        reason: u8,
        requested: Velocity,
        output: Velocity,
        clamp_flags: u32,
    ) {
        let status = &mut self.status;
        status.stamp_ns = now.as_nanos();
        status.requested = requested.into();
        status.output = output.into();
        status.clamp_flags = clamp_flags;
        status.zero_reason = reason;
        status.rejected_requests = self.rejected;
        (status.speed_limit_mps, status.speed_limit_holder) =
            self.speed_limit.unwrap_or((0.0, LockStatus::HOLDER_NONE));
        // Indices < MAX_SOURCES fit a u8.
        status.active_source = winner.map_or(MuxStatus::NO_SOURCE, |w| w as u8);
        status.active_priority = winner.map_or(0, |w| self.sources[w].config.priority);
        status.active_age_ms = winner
            .and_then(|w| self.sources[w].latest)
            .map_or(u32::MAX, |(t, _)| age_ms(now, t));
        let blocking_priority = self
            .locks
            .iter()
            .filter(|l| l.held.is_some())
            .map(|l| l.config.priority)
            .max();
        for (i, (slot, source)) in status.sources.iter_mut().zip(&self.sources).enumerate() {
            let mut flags = if source.config.required {
                SourceFlags::REQUIRED
            } else {
                0
            };
            if source.config.remote {
                flags |= SourceFlags::REMOTE;
            }
            if source.is_fresh(now) {
                flags |= SourceFlags::FRESH;
            }
            if Some(i) == winner {
                flags |= SourceFlags::ACTIVE;
            }
            if source.latest.is_some_and(|(_, r)| r.is_heartbeat()) {
                flags |= SourceFlags::HEARTBEAT;
            }
            if blocking_priority.is_some_and(|p| source.config.priority < p) {
                flags |= SourceFlags::BLOCKED;
            }
            if source.is_awaiting() {
                flags |= SourceFlags::AWAITING_ZERO;
            }
            slot.flags = flags;
            slot.age_ms = source.latest.map_or(u32::MAX, |(t, _)| age_ms(now, t));
            slot.rejected = source.rejected;
            slot.last_seq = source.latest.map_or(0, |(_, r)| r.seq);
        }
        for (slot, lock) in status.locks.iter_mut().zip(&self.locks) {
            match lock.held {
                Some((holder, since)) => {
                    slot.held = 1;
                    slot.holder = holder;
                    slot.since_ns = since.as_nanos();
                }
                None => {
                    slot.held = 0;
                    slot.holder = LockStatus::HOLDER_NONE;
                    slot.since_ns = 0;
                }
            }
            slot.category = lock.stop_category();
        }
    }

    /// The latest decision.
    pub fn status(&self) -> &MuxStatus {
        &self.status
    }

    /// The latest output.
    pub fn output(&self) -> Velocity {
        self.output
    }

    /// When the decision may change without a new request: the next expiry of a fresh source.
    pub fn next_deadline(&self, now: Timestamp) -> Option<Timestamp> {
        self.sources
            .iter()
            .filter_map(Source::expiry)
            .filter(|&t| t > now)
            .min()
    }

    /// True while the output is still ramping towards the winner's request.
    pub fn is_ramping(&self) -> bool {
        self.status.clamp_flags & ClampFlags::ACCELERATION_LIMIT != 0
    }

    /// The status entry of source `index`.
    pub fn source_status(&self, index: usize) -> Option<&SourceStatus> {
        self.status.sources.get(index)
    }
}

/// The configured speed limits as bounds (0: only the robot's own limit).
fn speed_limits(limits: &LimitsConfig) -> Envelope {
    let bound = |max: f64| {
        if max > 0.0 { max as f32 } else { f32::INFINITY }
    };
    Envelope {
        forward_mps: bound(limits.max_linear_mps),
        reverse_mps: bound(limits.max_linear_mps),
        lateral_mps: bound(limits.max_lateral_mps),
        angular_radps: bound(limits.max_angular_radps),
    }
}

/// The bit of `stop` in [`Mux::set_holds`]'s set.
pub fn hold_bit(stop: u8) -> u32 {
    1u32.checked_shl(u32::from(stop)).unwrap_or(0)
}

fn age_ms(now: Timestamp, since: Timestamp) -> u32 {
    u32::try_from(now.saturating_since(since).as_millis()).unwrap_or(u32::MAX - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_interfaces::VelocityRequest;

    fn ms(v: u64) -> Timestamp {
        Timestamp::from_millis(v)
    }

    /// A request as the service parses it.
    fn valid(request: VelocityRequest) -> ValidRequest {
        ValidRequest::try_from(request).unwrap()
    }

    fn request(now: Timestamp, vx: f32) -> ValidRequest {
        valid(VelocityRequest {
            stamp_ns: now.as_nanos(),
            ..VelocityRequest::twist(vx, 0.0)
        })
    }

    fn heartbeat(now: Timestamp) -> ValidRequest {
        valid(VelocityRequest {
            stamp_ns: now.as_nanos(),
            ..VelocityRequest::heartbeat()
        })
    }

    /// A mux whose sources have connected as client processes do: each one's library sends one
    /// heartbeat as it connects (the required sources' heartbeats are the tests' own).
    fn connected(config: &MuxConfig) -> Mux {
        let mut m = Mux::new(config).unwrap();
        for (index, source) in config.sources.iter().enumerate() {
            if !source.required {
                m.on_request(ms(0), index, &heartbeat(ms(0))).unwrap();
            }
        }
        m
    }

    /// Default sources, connected, no smoothing, so outputs equal requests.
    fn mux() -> Mux {
        let mut config = MuxConfig::default();
        config.limits.linear_accel_mps2 = 0.0;
        config.limits.angular_accel_radps2 = 0.0;
        connected(&config)
    }

    /// Like [`mux`] but without the required safety monitor.
    fn mux_unrequired() -> Mux {
        let mut config = MuxConfig::default().without_required_sources();
        config.limits.linear_accel_mps2 = 0.0;
        config.limits.angular_accel_radps2 = 0.0;
        connected(&config)
    }

    const SAFETY: usize = 0;
    const TELEOP: usize = 1;
    const PLANNER: usize = 2;

    #[test]
    fn mux_outputs_zero_and_says_why_when_the_required_safety_monitor_is_silent() {
        let mut m = mux();
        m.on_request(ms(0), PLANNER, &request(ms(0), 0.5)).unwrap();
        let d = m.evaluate(ms(1));
        assert_eq!(d.output, Velocity::ZERO);
        assert_eq!(m.status().zero_reason, ZeroReason::REQUIRED_SOURCE_STALE);
    }

    #[test]
    fn a_safety_heartbeat_lets_the_planner_drive_without_winning_itself() {
        let mut m = mux();
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), PLANNER, &request(ms(0), 0.5)).unwrap();
        let d = m.evaluate(ms(1));
        assert_eq!(d.output.linear_x_mps(), 0.5);
        assert_eq!(m.status().active_source, PLANNER as u8);
        assert_ne!(m.status().sources[SAFETY].flags & SourceFlags::HEARTBEAT, 0);
    }

    #[test]
    fn teleop_preempts_the_planner_and_hands_back_when_it_times_out() {
        let mut m = mux();
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), PLANNER, &request(ms(0), 0.5)).unwrap();
        m.on_request(ms(10), TELEOP, &request(ms(10), -0.2))
            .unwrap();
        assert_eq!(m.evaluate(ms(10)).output.linear_x_mps(), -0.2);
        assert_eq!(m.status().active_source, TELEOP as u8);
        // Keep the planner and safety fresh; teleop stops sending.
        for t in (100..=400).step_by(100) {
            m.on_request(ms(t), SAFETY, &heartbeat(ms(t))).unwrap();
            m.on_request(ms(t), PLANNER, &request(ms(t), 0.5)).unwrap();
        }
        // Teleop's 300 ms timeout has passed at 310 ms.
        assert_eq!(m.evaluate(ms(400)).output.linear_x_mps(), 0.5);
        assert_eq!(m.status().active_source, PLANNER as u8);
    }

    #[test]
    fn mux_falls_back_to_zero_when_teleop_times_out() {
        let mut m = mux_unrequired();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.0)).unwrap();
        m.evaluate(ms(0));
        let d = m.evaluate(ms(301));
        assert_eq!(d.output, Velocity::ZERO);
        assert_eq!(m.status().zero_reason, ZeroReason::NO_ACTIVE_SOURCE);
        // The planner's heartbeat as it connected expires last, at its 500 ms.
        assert_eq!(m.next_deadline(ms(301)), Some(ms(500)));
        assert_eq!(m.next_deadline(ms(500)), None);
    }

    #[test]
    fn the_next_deadline_is_the_earliest_source_expiry() {
        let mut m = Mux::new(&MuxConfig::default()).unwrap();
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(50), TELEOP, &request(ms(50), 0.1)).unwrap();
        assert_eq!(m.next_deadline(ms(60)), Some(ms(200)));
        assert_eq!(m.next_deadline(ms(200)), Some(ms(350)));
    }

    #[test]
    fn equal_priorities_are_won_by_the_newer_request() {
        let config = MuxConfig {
            sources: vec![
                SourceConfig {
                    name: "a".into(),
                    priority: 50,
                    timeout_ms: 500,
                    required: false,
                    remote: false,
                },
                SourceConfig {
                    name: "b".into(),
                    priority: 50,
                    timeout_ms: 500,
                    required: false,
                    remote: false,
                },
            ],
            locks: vec![],
            limits: LimitsConfig {
                linear_accel_mps2: 0.0,
                ..LimitsConfig::default()
            },
        };
        let mut m = connected(&config);
        m.on_request(ms(0), 0, &request(ms(0), 0.1)).unwrap();
        m.on_request(ms(5), 1, &request(ms(5), 0.2)).unwrap();
        assert_eq!(m.evaluate(ms(6)).output.linear_x_mps(), 0.2);
        m.on_request(ms(7), 0, &request(ms(7), 0.3)).unwrap();
        assert_eq!(m.evaluate(ms(8)).output.linear_x_mps(), 0.3);
    }

    #[test]
    fn a_stale_stamp_is_never_fresh_and_a_future_stamp_buys_nothing() {
        let mut m = mux_unrequired();
        // Created 400 ms ago: older than teleop's 300 ms timeout on arrival.
        m.on_request(ms(1000), TELEOP, &request(ms(600), 0.4))
            .unwrap();
        assert_eq!(m.evaluate(ms(1000)).output, Velocity::ZERO);
        // Stamped an hour ahead: counts from its arrival.
        m.on_request(ms(2000), TELEOP, &request(ms(3_602_000), 0.4))
            .unwrap();
        assert_eq!(m.evaluate(ms(2100)).output.linear_x_mps(), 0.4);
        assert_eq!(m.evaluate(ms(2301)).output, Velocity::ZERO);
    }

    #[test]
    fn absurd_requests_are_rejected_counted_and_the_previous_one_stands() {
        let mut m = mux_unrequired();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.3)).unwrap();
        for bad in [
            VelocityRequest::twist(1e30, 0.0),
            VelocityRequest::twist(0.0, -1e6),
            VelocityRequest::steer(1.0, 3.0),
            VelocityRequest {
                linear_y_mps: 80.0,
                ..VelocityRequest::twist(0.0, 0.0)
            },
        ] {
            let bad = valid(VelocityRequest {
                stamp_ns: ms(1).as_nanos(),
                ..bad
            });
            assert_eq!(m.on_request(ms(1), TELEOP, &bad), Err(Rejection::Absurd));
        }
        assert_eq!(m.evaluate(ms(2)).output.linear_x_mps(), 0.3);
        assert_eq!(m.status().rejected_requests, 4);
        // Fast but possible is not absurd: the robot's limits clamp it.
        assert!(m.on_request(ms(3), TELEOP, &request(ms(3), 9.0)).is_ok());
    }

    #[test]
    fn an_unlimited_envelope_bound_is_taken_and_limits_nothing() {
        // The safety monitor blocks forward motion only: reverse, lateral and yaw unlimited.
        let mut m = mux();
        let unlimited = f32::MAX;
        let envelope = valid(VelocityRequest {
            stamp_ns: ms(0).as_nanos(),
            ..VelocityRequest::limit(0.0, unlimited, unlimited, unlimited)
        });
        assert_eq!(m.on_request(ms(0), SAFETY, &envelope), Ok(()));
        m.on_request(ms(0), TELEOP, &request(ms(0), -0.4)).unwrap();
        assert_eq!(m.evaluate(ms(1)).output.linear_x_mps(), -0.4);
        m.on_request(ms(2), TELEOP, &request(ms(2), 0.4)).unwrap();
        assert_eq!(m.evaluate(ms(3)).output.linear_x_mps(), 0.0);
        assert_eq!(m.status().rejected_requests, 0);
    }

    #[test]
    fn a_lock_blocks_lower_priorities_until_its_holder_releases_it() {
        let mut m = mux();
        let estop = valid(VelocityRequest {
            lock_engage: 1,
            ..*request(ms(0), 0.0)
        });
        m.on_request(ms(0), SAFETY, &estop).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.4)).unwrap();
        // Safety's own zero request wins first; then it sends heartbeats only.
        m.on_request(ms(10), SAFETY, &heartbeat(ms(10))).unwrap();
        m.on_request(ms(10), TELEOP, &request(ms(10), 0.4)).unwrap();
        assert_eq!(m.evaluate(ms(10)).output, Velocity::ZERO);
        assert_eq!(m.status().zero_reason, ZeroReason::LOCKED);
        assert_eq!(m.status().locks[0].held, 1);
        assert_eq!(m.status().locks[0].holder, SAFETY as u8);
        assert_ne!(m.status().sources[TELEOP].flags & SourceFlags::BLOCKED, 0);
        // Teleop cannot release a lock it does not hold.
        let sneaky = valid(VelocityRequest {
            lock_release: 1,
            ..*request(ms(20), 0.4)
        });
        m.on_request(ms(20), TELEOP, &sneaky).unwrap();
        m.on_request(ms(20), SAFETY, &heartbeat(ms(20))).unwrap();
        assert_eq!(m.evaluate(ms(20)).output, Velocity::ZERO);
        let release = valid(VelocityRequest {
            lock_release: 1,
            ..*heartbeat(ms(30))
        });
        m.on_request(ms(30), SAFETY, &release).unwrap();
        m.on_request(ms(30), TELEOP, &request(ms(30), 0.4)).unwrap();
        // Teleop asked for motion when the lock went: a release never starts motion.
        assert_eq!(m.evaluate(ms(30)).output, Velocity::ZERO);
        assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
        m.on_request(ms(40), TELEOP, &request(ms(40), 0.0)).unwrap();
        m.on_request(ms(50), TELEOP, &request(ms(50), 0.4)).unwrap();
        assert_eq!(m.evaluate(ms(50)).output.linear_x_mps(), 0.4);
    }

    #[test]
    fn a_lock_survives_its_holder_and_only_the_operator_can_release_it() {
        let mut m = mux_unrequired();
        let latch = valid(VelocityRequest {
            lock_engage: 1,
            ..*request(ms(0), 0.0)
        });
        m.on_request(ms(0), TELEOP, &latch).unwrap();
        // Teleop dies: it never sends again. The planner is below the lock's priority.
        for t in (1000..=5000).step_by(500) {
            m.on_request(ms(t), PLANNER, &request(ms(t), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(t)).output, Velocity::ZERO, "at {t} ms");
        }
        assert_eq!(m.release_lock("estop"), Ok(true));
        assert_eq!(m.evaluate(ms(5001)).output, Velocity::ZERO, "awaiting zero");
        m.on_request(ms(5020), PLANNER, &request(ms(5020), 0.0))
            .unwrap();
        m.on_request(ms(5040), PLANNER, &request(ms(5040), 0.3))
            .unwrap();
        assert_eq!(m.evaluate(ms(5040)).output.linear_x_mps(), 0.3);
        assert!(m.release_lock("nope").is_err());
    }

    /// ISO 13850 / IEC 60204-1: resetting a stop shall not initiate a restart. Teleop keeps
    /// asking for 0.3 m/s through an e-stop: the release leaves the robot still, names teleop as
    /// the source it waits for, and neither hands the robot to a lower source nor needs anything
    /// from a source that was not asking for motion.
    #[test]
    fn a_release_never_starts_motion_until_the_winner_asks_for_zero() {
        let mut m = mux_unrequired();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.3)).unwrap();
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 0.3);
        assert_eq!(m.engage_lock(ms(10), "estop", None), Ok(true));
        m.on_request(ms(20), TELEOP, &request(ms(20), 0.3)).unwrap();
        m.on_request(ms(20), PLANNER, &request(ms(20), 0.2))
            .unwrap();
        assert_eq!(m.evaluate(ms(20)).output, Velocity::ZERO);
        assert_eq!(m.release_lock("estop"), Ok(true));
        assert_eq!(m.awaiting_zero(), ["teleop", "planner"]);
        assert_eq!(m.evaluate(ms(30)).output, Velocity::ZERO);
        assert_eq!(m.status().stop, Stop::LOCK_RELEASED);
        for t in (30..300).step_by(20) {
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.3)).unwrap();
            m.on_request(ms(t), PLANNER, &request(ms(t), 0.2)).unwrap();
            let d = m.evaluate(ms(t));
            assert_eq!(d.output, Velocity::ZERO, "at {t} ms");
            assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
            assert_eq!(m.status().awaiting().map(|s| s.name()), Some("teleop"));
            assert_ne!(
                m.status().sources[TELEOP].flags & SourceFlags::AWAITING_ZERO,
                0
            );
        }
        // Teleop lets go (a zero request): teleop drives at once when it asks again.
        m.on_request(ms(300), TELEOP, &request(ms(300), 0.0))
            .unwrap();
        m.on_request(ms(300), PLANNER, &request(ms(300), 0.2))
            .unwrap();
        assert_eq!(
            m.evaluate(ms(300)).output,
            Velocity::ZERO,
            "teleop's zero wins"
        );
        m.on_request(ms(320), TELEOP, &request(ms(320), 0.3))
            .unwrap();
        assert_eq!(m.evaluate(ms(320)).output.linear_x_mps(), 0.3);
        assert_eq!(m.awaiting_zero(), ["planner"]);
        // The planner still awaits its own zero: teleop falling silent does not hand it the
        // robot.
        let after_timeout = ms(320) + Duration::from_millis(400);
        m.on_request(after_timeout, PLANNER, &request(after_timeout, 0.2))
            .unwrap();
        assert_eq!(m.evaluate(after_timeout).output, Velocity::ZERO);
        assert_eq!(m.status().awaiting().map(|s| s.name()), Some("planner"));
    }

    /// Silence is not a zero: a source that falls silent after a release (a lossy link) and
    /// asks for motion again still awaits its zero. A source whose last word was zero is free.
    #[test]
    fn a_source_that_fell_silent_after_a_release_still_awaits_its_zero() {
        let mut m = mux_unrequired();
        assert_eq!(m.engage_lock(ms(0), "estop", None), Ok(true));
        m.on_request(ms(10), TELEOP, &request(ms(10), 0.3)).unwrap();
        assert_eq!(m.release_lock("estop"), Ok(true));
        assert_eq!(m.evaluate(ms(20)).output, Velocity::ZERO);
        let later = ms(10) + Duration::from_secs(1);
        assert_eq!(m.evaluate(later).output, Velocity::ZERO);
        assert_eq!(m.awaiting_zero(), ["teleop"]);
        m.on_request(later, TELEOP, &request(later, 0.3)).unwrap();
        assert_eq!(m.evaluate(later).output, Velocity::ZERO);
        assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
        m.on_request(later, TELEOP, &request(later, 0.0)).unwrap();
        m.on_request(later, TELEOP, &request(later, 0.3)).unwrap();
        assert_eq!(m.evaluate(later).output.linear_x_mps(), 0.3);
        // A release while the last word of every source was zero leaves every source free.
        m.on_request(later, TELEOP, &request(later, 0.0)).unwrap();
        assert_eq!(m.engage_lock(later, "estop", None), Ok(true));
        assert_eq!(m.release_lock("estop"), Ok(true));
        assert!(m.awaiting_zero().is_empty());
        let quiet = later + Duration::from_secs(1);
        m.on_request(quiet, TELEOP, &request(quiet, 0.3)).unwrap();
        assert_eq!(m.evaluate(quiet).output.linear_x_mps(), 0.3);
    }

    /// chassisd (re)starting is a stop: a client that kept asking through the restart (it never
    /// connected anew, so its library sent no heartbeat) is not obeyed until it asks for zero.
    #[test]
    fn a_source_that_kept_asking_through_a_restart_awaits_its_zero() {
        let mut config = MuxConfig::default().without_required_sources();
        config.limits.linear_accel_mps2 = 0.0;
        let mut m = Mux::new(&config).unwrap();
        for t in (0..200).step_by(20) {
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(t)).output, Velocity::ZERO, "at {t} ms");
            assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
            assert_eq!(m.status().stop, Stop::SERVICE_START);
            assert_eq!(m.status().awaiting().map(|s| s.name()), Some("teleop"));
        }
        m.on_request(ms(200), TELEOP, &heartbeat(ms(200))).unwrap();
        m.on_request(ms(220), TELEOP, &request(ms(220), 0.3))
            .unwrap();
        assert_eq!(m.evaluate(ms(220)).output.linear_x_mps(), 0.3);
        assert_eq!(m.status().stop, Stop::NONE);
    }

    /// A safety monitor that dies and is started again ends a stop: the source that kept asking
    /// waits for its own zero, whatever the safety monitor sends. Its first start is no restart.
    #[test]
    fn a_restarted_safety_monitor_does_not_restart_the_robot() {
        let mut m = mux();
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.3)).unwrap();
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 0.3);
        for t in (50..1000).step_by(50) {
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.3)).unwrap();
            m.evaluate(ms(t));
        }
        assert_eq!(m.status().zero_reason, ZeroReason::REQUIRED_SOURCE_STALE);
        for t in (1000..1500).step_by(50) {
            m.on_request(ms(t), SAFETY, &heartbeat(ms(t))).unwrap();
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(t)).output, Velocity::ZERO, "at {t} ms");
            assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
            assert_eq!(m.status().stop, Stop::REQUIRED_SOURCE);
        }
        m.on_request(ms(1500), SAFETY, &request(ms(1500), 0.0))
            .unwrap();
        m.on_request(ms(1510), TELEOP, &request(ms(1510), 0.3))
            .unwrap();
        assert_eq!(
            m.evaluate(ms(1510)).output,
            Velocity::ZERO,
            "another source's zero is not teleop's"
        );
        m.on_request(ms(1520), TELEOP, &request(ms(1520), 0.0))
            .unwrap();
        m.on_request(ms(1540), SAFETY, &heartbeat(ms(1540)))
            .unwrap();
        m.on_request(ms(1540), TELEOP, &request(ms(1540), 0.3))
            .unwrap();
        assert_eq!(m.evaluate(ms(1540)).output.linear_x_mps(), 0.3);
    }

    /// A hold (the bus lost, the chassis' E-stop, remote control, a drive fault) zeroes the
    /// output while it lasts and names itself; its end waits for the winner's zero.
    #[test]
    fn a_hold_stops_the_robot_and_its_end_waits_for_a_zero() {
        let mut m = mux_unrequired();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.3)).unwrap();
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 0.3);
        for stop in [
            Stop::BUS,
            Stop::CHASSIS_ESTOP,
            Stop::REMOTE_CONTROL,
            Stop::CHASSIS_FAULT,
        ] {
            m.set_holds(hold_bit(stop) | hold_bit(Stop::CHASSIS_FAULT));
            m.on_request(ms(10), TELEOP, &request(ms(10), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(10)).output, Velocity::ZERO);
            assert_eq!(m.status().zero_reason, ZeroReason::HELD);
            assert_eq!(m.status().stop, stop.min(Stop::CHASSIS_FAULT));
            m.set_holds(0);
            m.on_request(ms(20), TELEOP, &request(ms(20), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(20)).output, Velocity::ZERO);
            assert_eq!(m.status().zero_reason, ZeroReason::AWAITING_ZERO);
            assert_eq!(m.status().stop, Stop::CHASSIS_FAULT, "the last stop to end");
            m.on_request(ms(30), TELEOP, &request(ms(30), 0.0)).unwrap();
            m.on_request(ms(40), TELEOP, &request(ms(40), 0.3)).unwrap();
            assert_eq!(m.evaluate(ms(40)).output.linear_x_mps(), 0.3, "{stop}");
        }
    }

    /// Any source lowers the standing speed limit, which caps every source's linear speed (not
    /// its yaw rate); a higher one from a source changes nothing; the operator raises and lifts
    /// it. The status names the cap and who set it.
    #[test]
    fn any_source_lowers_the_speed_limit_and_only_the_operator_raises_it() {
        let mut m = mux_unrequired();
        let limit = |mps| valid(VelocityRequest::speed_limit(mps));
        let fast = valid(VelocityRequest::twist(1.2, 0.8));
        m.on_request(ms(0), TELEOP, &fast).unwrap();
        m.on_request(ms(0), PLANNER, &limit(0.5)).unwrap();
        let d = m.evaluate(ms(0));
        assert_eq!(
            (d.output.linear_x_mps(), d.output.angular_z_radps()),
            (0.5, 0.8)
        );
        assert_ne!(m.status().clamp_flags & ClampFlags::SPEED_LIMIT, 0);
        assert_eq!(m.status().speed_limit(), Some((0.5, "planner")));
        assert_eq!(m.status().active().map(SourceStatus::name), Some("teleop"));
        m.on_request(ms(0), SAFETY, &limit(0.3)).unwrap();
        m.on_request(ms(0), TELEOP, &limit(0.9)).unwrap();
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 0.3);
        assert_eq!(m.status().speed_limit(), Some((0.3, "safety")));
        m.set_speed_limit(Some(1.0));
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 1.0);
        assert_eq!(m.status().speed_limit(), Some((1.0, "operator")));
        m.set_speed_limit(None);
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 1.2);
        assert_eq!(m.status().speed_limit(), None);
        assert_eq!(m.status().clamp_flags & ClampFlags::SPEED_LIMIT, 0);
    }

    #[test]
    fn the_operator_can_engage_a_lock() {
        let mut m = mux_unrequired();
        assert_eq!(m.engage_lock(ms(0), "estop", None), Ok(true));
        assert_eq!(m.engage_lock(ms(1), "estop", None), Ok(false));
        m.on_request(ms(2), TELEOP, &request(ms(2), 0.3)).unwrap();
        assert_eq!(m.evaluate(ms(2)).output, Velocity::ZERO);
        assert_eq!(m.status().locks[0].holder, LockStatus::HOLDER_OPERATOR);
    }

    #[test]
    fn unknown_lock_bits_are_rejected() {
        let mut m = mux();
        let bad = valid(VelocityRequest {
            lock_engage: 0b100,
            ..*request(ms(0), 0.0)
        });
        assert_eq!(
            m.on_request(ms(0), TELEOP, &bad),
            Err(Rejection::UnknownLock(0b100))
        );
    }

    #[test]
    fn acceleration_is_smoothed_but_a_safety_stop_is_not() {
        let mut config = MuxConfig::default();
        config.limits.linear_accel_mps2 = 1.0;
        let mut m = connected(&config);
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 1.0)).unwrap();
        m.evaluate(ms(0));
        let d = m.evaluate(ms(100));
        assert!(
            (d.output.linear_x_mps() - 0.1).abs() < 1e-6,
            "{:?}",
            d.output
        );
        assert!(m.is_ramping());
        for t in (120..=1200).step_by(20) {
            m.on_request(ms(t), SAFETY, &heartbeat(ms(t))).unwrap();
            m.on_request(ms(t), TELEOP, &request(ms(t), 1.0)).unwrap();
            m.evaluate(ms(t));
        }
        assert_eq!(m.output().linear_x_mps(), 1.0);
        // Safety asks for a stop: zero at once.
        m.on_request(ms(1210), SAFETY, &request(ms(1210), 0.0))
            .unwrap();
        assert_eq!(m.evaluate(ms(1210)).output, Velocity::ZERO);
        assert_eq!(m.status().active_source, SAFETY as u8);
    }

    #[test]
    fn motion_ends_with_the_timeout_of_a_silent_source_without_a_ramp() {
        let mut config = MuxConfig::default().without_required_sources();
        config.limits.linear_accel_mps2 = 0.5;
        let mut m = connected(&config);
        m.evaluate(ms(0));
        for t in (0..=2000).step_by(20) {
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.5)).unwrap();
            m.evaluate(ms(t));
        }
        assert_eq!(m.output().linear_x_mps(), 0.5);
        // Teleop's last request was at 2000 ms: still moving at 2299 ms, zero at 2300 ms.
        assert_eq!(m.evaluate(ms(2299)).output.linear_x_mps(), 0.5);
        assert_eq!(m.evaluate(ms(2300)).output, Velocity::ZERO);
    }

    #[test]
    fn a_stale_safety_monitor_stops_at_once_without_smoothing() {
        let mut config = MuxConfig::default();
        config.limits.linear_accel_mps2 = 0.5;
        let mut m = connected(&config);
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.0)).unwrap();
        m.evaluate(ms(0));
        // Ramp up to 0.5 m/s over a second, with safety fresh.
        for t in (20..=1000).step_by(20) {
            m.on_request(ms(t), SAFETY, &heartbeat(ms(t))).unwrap();
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.5)).unwrap();
            m.evaluate(ms(t));
        }
        assert!(m.output().linear_x_mps() > 0.4);
        m.on_request(ms(1100), TELEOP, &request(ms(1100), 0.5))
            .unwrap();
        // Safety's last heartbeat was at 1000 ms; its timeout is 200 ms.
        assert_eq!(m.evaluate(ms(1201)).output, Velocity::ZERO);
    }

    #[test]
    fn a_safety_envelope_blocks_only_the_direction_towards_the_obstacle_at_once() {
        let mut config = MuxConfig::default();
        config.limits.linear_accel_mps2 = 0.5;
        let mut m = connected(&config);
        let ahead_blocked = |t: u64| {
            valid(VelocityRequest {
                stamp_ns: ms(t).as_nanos(),
                ..VelocityRequest::limit(0.0, 1.0, 1.0, 2.0)
            })
        };
        m.on_request(ms(0), SAFETY, &heartbeat(ms(0))).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.0)).unwrap();
        m.evaluate(ms(0));
        for t in (20..=2000).step_by(20) {
            m.on_request(ms(t), SAFETY, &heartbeat(ms(t))).unwrap();
            m.on_request(ms(t), TELEOP, &request(ms(t), 0.6)).unwrap();
            m.evaluate(ms(t));
        }
        assert_eq!(m.output().linear_x_mps(), 0.6);
        // An obstacle ahead: forward blocked at once, no ramp.
        m.on_request(ms(2010), SAFETY, &ahead_blocked(2010))
            .unwrap();
        let d = m.evaluate(ms(2010));
        assert_eq!(d.output.linear_x_mps(), 0.0);
        assert_eq!(
            m.status().active_source,
            TELEOP as u8,
            "teleop still wins; it is limited"
        );
        assert_ne!(m.status().clamp_flags & ClampFlags::SAFETY_LIMIT, 0);
        assert_ne!(m.status().sources[SAFETY].flags & SourceFlags::LIMITING, 0);
        // Reversing away is allowed (ramped as usual).
        for t in (2030..=3000).step_by(20) {
            m.on_request(ms(t), SAFETY, &ahead_blocked(t)).unwrap();
            m.on_request(ms(t), TELEOP, &request(ms(t), -0.3)).unwrap();
            m.evaluate(ms(t));
        }
        assert_eq!(m.output().linear_x_mps(), -0.3);
        // The limit keeps the safety monitor alive for the required rule.
        assert_ne!(m.status().zero_reason, ZeroReason::REQUIRED_SOURCE_STALE);
    }

    #[test]
    fn a_limit_from_a_lower_priority_source_does_not_bind_a_higher_one() {
        let mut m = mux_unrequired();
        let slow = valid(VelocityRequest {
            stamp_ns: 0,
            ..VelocityRequest::limit(0.1, 0.1, 0.1, 0.1)
        });
        m.on_request(ms(0), PLANNER, &slow).unwrap();
        m.on_request(ms(0), TELEOP, &request(ms(0), 0.5)).unwrap();
        assert_eq!(m.evaluate(ms(0)).output.linear_x_mps(), 0.5);
    }

    #[test]
    fn configured_speed_limits_clamp_and_say_so() {
        let mut config = MuxConfig::default().without_required_sources();
        config.limits = LimitsConfig {
            max_linear_mps: 0.5,
            max_angular_radps: 0.3,
            linear_accel_mps2: 0.0,
            angular_accel_radps2: 0.0,
            ..LimitsConfig::default()
        };
        let mut m = connected(&config);
        let fast = valid(VelocityRequest {
            stamp_ns: 0,
            ..VelocityRequest::twist(-2.0, 1.0)
        });
        m.on_request(ms(0), TELEOP, &fast).unwrap();
        let d = m.evaluate(ms(0));
        assert_eq!(
            (d.output.linear_x_mps(), d.output.angular_z_radps()),
            (-0.5, 0.3)
        );
        assert_ne!(m.status().clamp_flags & ClampFlags::CONFIG_SPEED_LIMIT, 0);
        assert_eq!(m.status().requested.linear_x_mps, -2.0);
    }

    #[test]
    fn the_status_names_sources_locks_and_changes() {
        let mut m = mux();
        let first = m.evaluate(ms(0));
        assert!(first.changed, "starting → required stale is a change");
        assert!(!m.evaluate(ms(1)).changed);
        let s = m.status();
        assert_eq!(s.sources()[0].name(), "safety");
        assert_eq!(s.sources()[2].name(), "planner");
        assert_eq!(s.locks()[0].name(), "estop");
        assert_eq!(s.sources()[0].timeout_ms, 200);
        let remote = s.sources().iter().find(|s| s.name() == "remote").unwrap();
        assert!(remote.has(SourceFlags::REMOTE));
        assert!(!s.sources()[0].has(SourceFlags::REMOTE));
        m.evaluate(ms(2));
        let remote = m
            .status()
            .sources()
            .iter()
            .find(|s| s.name() == "remote")
            .copied()
            .unwrap();
        assert!(remote.has(SourceFlags::REMOTE), "kept after a decision");
    }
}
