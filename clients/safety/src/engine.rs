//! The rule engine: the newest `ChassisState` and `MuxStatus` in, one [`Decision`] out.
//!
//! Pure: no I/O, no clock — `now_ns` is a parameter, so every rule is tested on simulated time.
//! The engine keeps what it needs to judge staleness on its own clock (when the state's `seq`
//! last changed), each rule's debounced level and each latch.
//!
//! It knows no robot: the speed and battery rules take their levels from the robot's
//! description ([`Engine::set_description`], resolved by [`Levels`]), or from the file where it
//! overrides them. Until a description is read only the file's levels are in force.
//!
//! # Levels, hysteresis and timing
//!
//! Every rule has a level: 0 (clear) or 1 (in force); the range rules have 1 = slow zone and
//! 2 = stop zone. Each evaluation a rule measures a *target* level, with hysteresis: a rule in
//! force is measured against its release threshold (threshold + margin), one that is clear against
//! its trigger threshold. The level follows the target once the target has been higher for
//! `trigger_ms` (or lower for `release_ms`), so one noisy sample neither triggers a debounced rule
//! nor releases one.
//!
//! # Latches
//!
//! A rule whose action is `latch` latches when it reaches its latch level (1; range rules: the
//! stop zone): the monitor sends a stop that engages the `estop` lock until the mux status shows
//! the lock held, then plain stops. Only the operator releases the lock
//! (`chassis control estop-release`); the engine sees it free in the mux status and unlatches. If
//! the condition is still present at that moment the rule is *acknowledged*: it does not latch
//! again, and does nothing (a range rule still blocks motion towards the obstacle) until the
//! condition clears for `release_ms` — then it is re-armed and latches on its next trigger. So
//! an operator who releases the e-stop with the bumper still pressed can drive the robot off the
//! obstacle; the next contact latches again. If the service restarts (the mux status `seq` goes
//! back), a lock the monitor had latched is engaged again. If the mux has no lock of that name, a
//! latching rule acts as a stop rule.

use chassis_client::{
    ChassisState, Envelope, EstopState, FaultFlags, Group, LinkFlags, LockStatus, MuxStatus,
    RULE_SLOTS, RequestFlags, RobotDescription, SafetyAction, SafetyEvent, SafetyRule,
    SafetyStatus, Unfollowed, VelocityRequest,
};

use crate::config::{Action, Config, RangeZones, SlowSpeeds, Timing};
use crate::levels::{BatteryBasis, Levels, number};
use crate::plausibility::{Finding, Verdict, Watch};

/// The envelope of the slow zone: every direction at its slow speed.
fn slow_envelope(slow: SlowSpeeds) -> Envelope {
    Envelope {
        forward_mps: slow.linear_mps,
        reverse_mps: slow.linear_mps,
        lateral_mps: slow.lateral_mps,
        angular_radps: slow.angular_radps,
    }
}

/// Near an obstacle in front (`front`) or behind: motion towards it slowed (level 1) or
/// blocked (level 2), away from it free; turning and strafing slowed (the corners sweep
/// towards it).
fn towards(front: bool, level: u8, slow: SlowSpeeds) -> Envelope {
    let toward = if level >= 2 { 0.0 } else { slow.linear_mps };
    let mut e = Envelope {
        lateral_mps: slow.lateral_mps,
        angular_radps: slow.angular_radps,
        ..Envelope::UNLIMITED
    };
    if front {
        e.forward_mps = toward;
    } else {
        e.reverse_mps = toward;
    }
    e
}

/// What the monitor publishes on its source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// All is well.
    Heartbeat,
    /// A speed envelope.
    Limit(Envelope),
    /// A zero request.
    Stop,
    /// A zero request that engages these lock bits, with a stop category (`None`: the lock's
    /// configured one).
    StopAndLock(u32, Option<u8>),
}

impl Command {
    /// The request to send.
    pub fn request(self) -> VelocityRequest {
        match self {
            Command::Heartbeat => VelocityRequest::heartbeat(),
            Command::Limit(e) => {
                VelocityRequest::limit(e.forward_mps, e.reverse_mps, e.lateral_mps, e.angular_radps)
            }
            Command::Stop => VelocityRequest::twist(0.0, 0.0),
            Command::StopAndLock(mask, category) => VelocityRequest {
                lock_engage: mask,
                flags: category.map_or(0, RequestFlags::of_category),
                ..VelocityRequest::twist(0.0, 0.0)
            },
        }
    }
}

/// A rule triggered, released or was unlatched.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// [`SafetyRule`].
    pub rule: u8,
    /// [`SafetyEvent`].
    pub kind: u8,
    /// The rule's level after the event.
    pub level: u8,
    /// The measurement and the threshold it crossed (NaN where there is none).
    pub value: f64,
    pub threshold: f64,
    pub text: String,
}

/// The outcome of one evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub command: Command,
    /// [`SafetyAction`].
    pub action: u8,
    /// The envelope in force (zero while stopping).
    pub envelope: Envelope,
    /// [`SafetyRule`] bits of the rules in force.
    pub active_rules: u32,
    /// [`SafetyRule`] bits of acknowledged latching rules.
    pub acknowledged_rules: u32,
    /// [`EstopState`].
    pub estop: u8,
    /// What happened in this evaluation.
    pub events: Vec<Event>,
    /// Problems with the setup, each reported once (WARN).
    pub notices: Vec<String>,
    /// What the engine decided about the setup, each said once (INFO): the reading the battery
    /// rule judges.
    pub infos: Vec<String>,
}

/// A rule's level, following its target after `trigger` (up) or `release` (down).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Debounce {
    level: u8,
    /// Since when the target has been above (true) or below (false) the level.
    pending: Option<(bool, u64)>,
}

impl Debounce {
    fn update(&mut self, now: u64, target: u8, timing: &Timing) -> Option<(u8, u8)> {
        if target == self.level {
            self.pending = None;
            return None;
        }
        let up = target > self.level;
        let since = match self.pending {
            Some((dir, since)) if dir == up => since,
            _ => {
                self.pending = Some((up, now));
                now
            }
        };
        let wait = if up {
            timing.trigger_ns
        } else {
            timing.release_ns
        };
        if now.saturating_sub(since) >= wait {
            let from = self.level;
            self.level = target;
            self.pending = None;
            Some((from, target))
        } else {
            None
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
enum Latch {
    #[default]
    Idle,
    /// Latched; `seen_held` once the mux status showed the lock held.
    Latched { seen_held: bool },
    /// The operator released the lock while the condition was still present.
    Acknowledged,
}

#[derive(Debug, Clone, Default)]
struct RuleState {
    debounce: Debounce,
    latch: Latch,
    count: u32,
    last_trigger_ns: u64,
}

/// What caused a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Cause {
    None,
    Faults(u64),
    Soc,
    Voltage,
    ServiceSilent,
    ChassisSilent,
    NeverHeard,
    Link(u32),
    Bumper,
    Range,
    Blind,
    Speed {
        reverse: bool,
    },
    Operator,
    /// Over the mux's speed limit.
    Limit,
    /// A plausibility rule's finding (following: with its [`Unfollowed`] cause).
    Plausibility(Finding, u8),
}

/// One rule's measurement.
#[derive(Debug, Clone, Copy)]
struct Measure {
    target: u8,
    value: f64,
    /// The threshold in force (range rules: of the slow zone).
    threshold: f64,
    /// Range rules: the stop zone's edge in force.
    stop_edge: f64,
    cause: Cause,
}

impl Measure {
    fn clear() -> Self {
        Self {
            target: 0,
            value: f64::NAN,
            threshold: f64::NAN,
            stop_edge: f64::NAN,
            cause: Cause::None,
        }
    }

    fn flag(on: bool, cause: Cause) -> Self {
        Self {
            target: u8::from(on),
            cause,
            ..Self::clear()
        }
    }
}

/// The `estop` lock as the mux status shows it.
#[derive(Debug, Clone, Copy)]
struct LockView {
    /// The mux has such a lock (assumed until a mux status says otherwise).
    available: bool,
    index: Option<usize>,
    held: Option<bool>,
    estop: u8,
}

/// The last event, for the status.
#[derive(Debug, Clone, Default)]
struct LastEvent {
    rule: Option<u8>,
    kind: u8,
    stamp_ns: u64,
    text: String,
}

/// The rule engine.
#[derive(Debug, Clone)]
pub struct Engine {
    config: Config,
    source: String,
    /// The robot as messages name it (`chassis/h1`).
    label: String,
    /// The speed and battery levels in force.
    levels: Levels,
    /// The reading the battery rule judged last (`None`: not judged yet).
    battery_basis: Option<Option<BatteryBasis>>,
    rules: [RuleState; SafetyRule::COUNT],
    /// `seq` of the newest state sample and when it was first seen.
    state_seq: Option<u64>,
    state_arrival_ns: u64,
    last_mux_seq: Option<u64>,
    operator_pending: bool,
    warned_no_lock: bool,
    last_event: LastEvent,
    /// The reach of recent commands, for the plausibility rules.
    watch: Watch,
    /// What they found in the newest sample.
    verdict: Verdict,
    /// Said that the plausibility rules have no acceleration to judge by.
    warned_no_accel: bool,
    /// The [`Unfollowed`] cause the following rule last found.
    unfollowed: u8,
    /// The mux's standing speed limit, m/s (`None`: none, or no mux status yet).
    speed_limit: Option<f64>,
}

const RANGE_RULES: [u8; 2] = [SafetyRule::ULTRASONIC, SafetyRule::IR];

impl Engine {
    /// An engine for the monitor publishing as source `source` (to recognise its own lock) for
    /// the robot `label` (`chassis/h1`, in messages), with the file's levels only until
    /// [`Engine::set_description`].
    pub fn new(config: Config, source: &str, label: &str) -> Self {
        let levels = Levels::resolve(&config, None, label);
        Self {
            config,
            source: source.to_string(),
            label: label.to_string(),
            levels,
            battery_basis: None,
            rules: Default::default(),
            state_seq: None,
            state_arrival_ns: 0,
            last_mux_seq: None,
            operator_pending: false,
            warned_no_lock: false,
            last_event: LastEvent::default(),
            watch: Watch::default(),
            verdict: Verdict::default(),
            warned_no_accel: false,
            unfollowed: Unfollowed::NONE,
            speed_limit: None,
        }
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The speed and battery levels in force, and where each comes from.
    pub fn levels(&self) -> &Levels {
        &self.levels
    }

    /// Takes the speed and battery levels from the robot's description (a newer one replaces
    /// them: a protocol detected, a restarted chassisd with another configuration). Rules keep
    /// their state; the next evaluation judges with the new levels.
    pub fn set_description(&mut self, description: &RobotDescription) -> &Levels {
        self.levels = Levels::resolve(&self.config, Some(description), &self.label);
        self.battery_basis = None;
        self.watch
            .set_limits(&description.effective_limits(), description.kinematics);
        self.warned_no_accel = false;
        &self.levels
    }

    /// The operator's e-stop (SIGUSR1): latches at the next evaluation. Returns false when the
    /// operator rule is disabled.
    pub fn request_operator_estop(&mut self) -> bool {
        if self.config.operator {
            self.operator_pending = true;
        }
        self.config.operator
    }

    /// [`SafetyRule`] bits of the enabled rules.
    pub fn enabled_rules(&self) -> u32 {
        (0..SafetyRule::COUNT as u8)
            .filter(|&r| self.timing(r).is_some())
            .fold(0, |bits, r| bits | SafetyRule::bit(r))
    }

    fn timing(&self, rule: u8) -> Option<Timing> {
        self.config.timing(rule)
    }

    /// The level at which a latching rule latches.
    fn latch_level(rule: u8) -> u8 {
        if RANGE_RULES.contains(&rule) { 2 } else { 1 }
    }

    /// Decides at `now_ns` on the newest state and mux status (`None`: none seen yet).
    pub fn evaluate(
        &mut self,
        now_ns: u64,
        state: &ChassisState,
        mux: Option<&MuxStatus>,
    ) -> Decision {
        let mut events = Vec::new();
        let mut notices = Vec::new();
        let mut infos = Vec::new();
        if self.state_seq != Some(state.seq) {
            self.state_seq = Some(state.seq);
            self.state_arrival_ns = now_ns;
        }
        let lock = self.observe_lock(mux, &mut notices);
        self.speed_limit = mux
            .and_then(MuxStatus::speed_limit)
            .map(|(mps, _)| f64::from(mps));
        self.observe_battery_basis(state, &mut notices, &mut infos);
        self.verdict = self.watch.judge(now_ns, state, &self.config.plausibility);
        let p = &self.config.plausibility;
        let judging = p.runaway.or(p.direction).or(p.following).is_some();
        // Said once the driver reports a command the rules would judge.
        if judging
            && state.is_valid(Group::Command)
            && self.watch.accel_mps2(p).is_none()
            && !self.warned_no_accel
        {
            self.warned_no_accel = true;
            notices.push(format!(
                "runaway, direction and following rules: no linear acceleration is known for {}: \
                 they do not judge; set [rules.plausibility] linear_accel_mps2",
                self.label
            ));
        }

        for rule in 0..SafetyRule::COUNT as u8 {
            let Some(timing) = self.timing(rule) else {
                continue;
            };
            let index = usize::from(rule);
            let level = self.rules[index].debounce.level;
            let m = self.measure(rule, now_ns, state, level);
            let changed = self.rules[index].debounce.update(now_ns, m.target, &timing);
            if let Some((from, to)) = changed {
                let up = to > from;
                if up {
                    let st = &mut self.rules[index];
                    st.count = st.count.saturating_add(1);
                    st.last_trigger_ns = now_ns;
                }
                // The operator's e-stop is momentary: its fall is no news.
                if up || rule != SafetyRule::OPERATOR {
                    let threshold =
                        if RANGE_RULES.contains(&rule) && (to == 2 || (from == 2 && to == 1)) {
                            m.stop_edge
                        } else {
                            m.threshold
                        };
                    events.push(Event {
                        rule,
                        kind: if up {
                            SafetyEvent::TRIGGER
                        } else {
                            SafetyEvent::RELEASE
                        },
                        level: to,
                        value: m.value,
                        threshold,
                        text: describe(rule, from, to, &m, threshold),
                    });
                }
            }
            if timing.action == Action::Latch {
                self.update_latch(rule, &lock, &mut events);
            }
        }

        let mut decision = self.combine(&lock, events, notices);
        decision.infos = infos;
        if let Some(event) = decision.events.last() {
            self.last_event = LastEvent {
                rule: Some(event.rule),
                kind: event.kind,
                stamp_ns: now_ns,
                text: event.text.clone(),
            };
        }
        decision
    }

    /// Says once which reading the battery rule judges, and loudly when the robot reports a
    /// reading but no level is known for it.
    fn observe_battery_basis(
        &mut self,
        state: &ChassisState,
        notices: &mut Vec<String>,
        infos: &mut Vec<String>,
    ) {
        if self.config.battery.is_none() {
            return;
        }
        let soc = state.is_valid(Group::BmsPack);
        let voltage = state.is_valid(Group::System);
        if !(soc || voltage) {
            return;
        }
        let basis = self.levels.battery_basis(soc, voltage);
        if self.battery_basis == Some(basis) {
            return;
        }
        self.battery_basis = Some(basis);
        let label = &self.label;
        let level = |v: Option<f64>| v.map_or_else(|| "?".to_string(), number);
        match basis {
            Some(BatteryBasis::Soc) => infos.push(format!(
                "battery: judging {label} by its state of charge (below {} %, {})",
                level(self.levels.battery_soc_pct.value),
                self.levels.battery_soc_pct.origin
            )),
            Some(BatteryBasis::Voltage) => infos.push(format!(
                "battery: judging {label} by its voltage (below {} V, {}){}",
                level(self.levels.battery_voltage_v.value),
                self.levels.battery_voltage_v.origin,
                if soc {
                    "; it reports a state of charge, but no level is known for it"
                } else {
                    "; it reports no state of charge"
                }
            )),
            None => notices.push(format!(
                "battery rule: {label} reports its {} but no level is known for it ({}): no \
                 battery rule; set [rules.battery] min_voltage_v or min_soc_pct",
                if soc {
                    "state of charge and voltage"
                } else {
                    "voltage"
                },
                self.levels.battery_voltage_v.origin
            )),
        }
    }

    fn observe_lock(&mut self, mux: Option<&MuxStatus>, notices: &mut Vec<String>) -> LockView {
        let Some(m) = mux else {
            return LockView {
                available: true,
                index: None,
                held: None,
                estop: EstopState::UNKNOWN,
            };
        };
        // A new service instance starts its mux status at seq 1: every lock is free again.
        if self.last_mux_seq.is_some_and(|last| m.seq < last) {
            let mut relatched = false;
            for st in &mut self.rules {
                if st.latch == (Latch::Latched { seen_held: true }) {
                    st.latch = Latch::Latched { seen_held: false };
                    relatched = true;
                }
            }
            if relatched {
                notices.push(format!(
                    "the service restarted: engaging the '{}' lock again",
                    self.config.lock
                ));
            }
        }
        self.last_mux_seq = Some(m.seq);
        let Some(index) = m.lock_index(&self.config.lock) else {
            if !self.warned_no_lock {
                self.warned_no_lock = true;
                notices.push(format!(
                    "the mux has no lock called '{}': latching rules act as stop rules",
                    self.config.lock
                ));
            }
            return LockView {
                available: false,
                index: None,
                held: None,
                estop: EstopState::UNKNOWN,
            };
        };
        let lock = m.locks()[index];
        let held = lock.held != 0;
        let ours = m
            .sources()
            .iter()
            .position(|s| s.name() == self.source)
            .and_then(|i| u8::try_from(i).ok());
        let estop = if !held {
            EstopState::FREE
        } else if lock.holder == LockStatus::HOLDER_OPERATOR {
            EstopState::HELD_BY_OPERATOR
        } else if Some(lock.holder) == ours {
            EstopState::HELD_BY_MONITOR
        } else {
            EstopState::HELD_BY_OTHER
        };
        LockView {
            available: true,
            index: Some(index),
            held: Some(held),
            estop,
        }
    }

    fn update_latch(&mut self, rule: u8, lock: &LockView, events: &mut Vec<Event>) {
        let index = usize::from(rule);
        let latch_level = Self::latch_level(rule);
        let st = &mut self.rules[index];
        let present = st.debounce.level >= latch_level;
        if !lock.available {
            st.latch = Latch::Idle;
            return;
        }
        let name = SafetyRule::name(rule);
        match st.latch {
            Latch::Idle => {
                if present {
                    st.latch = Latch::Latched { seen_held: false };
                }
            }
            Latch::Latched { seen_held } => match lock.held {
                Some(true) => st.latch = Latch::Latched { seen_held: true },
                Some(false) if seen_held => {
                    let text = if present {
                        st.latch = Latch::Acknowledged;
                        format!(
                            "{name}: estop released by the operator; still present, \
                             re-latches only after it clears"
                        )
                    } else {
                        st.latch = Latch::Idle;
                        format!("{name}: estop released by the operator")
                    };
                    events.push(Event {
                        rule,
                        kind: SafetyEvent::UNLATCH,
                        level: st.debounce.level,
                        value: f64::NAN,
                        threshold: f64::NAN,
                        text,
                    });
                }
                _ => {}
            },
            Latch::Acknowledged => {
                if !present {
                    st.latch = Latch::Idle;
                    match events.iter_mut().rev().find(|e| e.rule == rule) {
                        Some(event) => event.text.push_str("; latch re-armed"),
                        None => events.push(Event {
                            rule,
                            kind: SafetyEvent::RELEASE,
                            level: st.debounce.level,
                            value: f64::NAN,
                            threshold: f64::NAN,
                            text: format!("{name}: cleared; latch re-armed"),
                        }),
                    }
                }
            }
        }
    }

    fn combine(&self, lock: &LockView, events: Vec<Event>, notices: Vec<String>) -> Decision {
        let slow = self.config.slow;
        let mut envelope = Envelope::UNLIMITED;
        let mut stop = false;
        let mut latched = false;
        let mut lock_bits = 0u32;
        let mut category: Option<u8> = None;
        let mut active_rules = 0u32;
        let mut acknowledged_rules = 0u32;
        for rule in 0..SafetyRule::COUNT as u8 {
            let Some(timing) = self.timing(rule) else {
                continue;
            };
            let st = &self.rules[usize::from(rule)];
            let level = st.debounce.level;
            if let Latch::Latched { seen_held } = st.latch {
                latched = true;
                active_rules |= SafetyRule::bit(rule);
                if !seen_held && let Some(i) = lock.index {
                    lock_bits |= 1 << i;
                    // The lowest category among the rules that engage it.
                    if let Some(c) = self.config.categories[usize::from(rule)] {
                        category = Some(category.map_or(c, |k| k.min(c)));
                    }
                }
                continue;
            }
            let acknowledged = st.latch == Latch::Acknowledged;
            if acknowledged {
                acknowledged_rules |= SafetyRule::bit(rule);
            }
            if level == 0 {
                continue;
            }
            active_rules |= SafetyRule::bit(rule);
            // What the rule's action does at its full level.
            let stops = match timing.action {
                Action::Slow => false,
                Action::Stop => true,
                // A latch that cannot be held (no such lock) is a stop; an acknowledged one
                // does nothing more.
                Action::Latch => !lock.available && !acknowledged,
            };
            if RANGE_RULES.contains(&rule) {
                envelope = envelope.min(towards(rule == SafetyRule::ULTRASONIC, level, slow));
                stop |= level >= 2 && stops;
            } else if timing.action == Action::Slow {
                envelope = envelope.min(slow_envelope(slow));
            } else {
                stop |= stops;
            }
        }
        let (command, action, envelope) = if latched {
            let command = if lock_bits != 0 {
                Command::StopAndLock(lock_bits, category)
            } else {
                Command::Stop
            };
            (command, SafetyAction::LATCH, Envelope::ZERO)
        } else if stop {
            (Command::Stop, SafetyAction::STOP, Envelope::ZERO)
        } else if envelope != Envelope::UNLIMITED {
            (Command::Limit(envelope), SafetyAction::SLOW, envelope)
        } else {
            (Command::Heartbeat, SafetyAction::NONE, Envelope::UNLIMITED)
        };
        Decision {
            command,
            action,
            envelope,
            active_rules,
            acknowledged_rules,
            estop: lock.estop,
            events,
            notices,
            infos: Vec::new(),
        }
    }

    fn measure(&mut self, rule: u8, now: u64, state: &ChassisState, level: u8) -> Measure {
        let c = &self.config;
        match rule {
            SafetyRule::FAULT => {
                let bits = c.fault.as_ref().map_or(0, |f| f.mask) & state.system.fault_flags;
                Measure::flag(bits != 0, Cause::Faults(bits))
            }
            SafetyRule::BUMPER => Measure::flag(
                state.system.fault_flags & FaultFlags::BUMPER != 0,
                Cause::Bumper,
            ),
            SafetyRule::OPERATOR => {
                let pending = std::mem::take(&mut self.operator_pending);
                Measure::flag(pending, Cause::Operator)
            }
            SafetyRule::BATTERY => {
                let Some(b) = &c.battery else {
                    return Measure::clear();
                };
                let levels = &self.levels;
                let basis = levels.battery_basis(
                    state.is_valid(Group::BmsPack),
                    state.is_valid(Group::System),
                );
                let (value, threshold, margin, cause) = match basis {
                    Some(BatteryBasis::Soc) => (
                        f64::from(state.system.battery_soc_pct),
                        levels.battery_soc_pct.value.unwrap_or(f64::NAN),
                        b.release_margin_pct,
                        Cause::Soc,
                    ),
                    Some(BatteryBasis::Voltage) => (
                        f64::from(state.system.battery_voltage_v),
                        levels.battery_voltage_v.value.unwrap_or(f64::NAN),
                        b.release_margin_v,
                        Cause::Voltage,
                    ),
                    // Never reported, or no level (said loudly): unknown is not low (the stale
                    // rule covers silence).
                    None => return Measure::clear(),
                };
                let threshold = if level > 0 {
                    threshold + margin
                } else {
                    threshold
                };
                Measure {
                    // A reading that is not a number counts as low.
                    target: u8::from(value.is_nan() || value < threshold),
                    value,
                    threshold,
                    stop_edge: f64::NAN,
                    cause,
                }
            }
            SafetyRule::STALE => {
                let Some(s) = &c.stale else {
                    return Measure::clear();
                };
                let service_age = now.saturating_sub(self.state_arrival_ns);
                let chassis_age = now.saturating_sub(state.stamp_ns);
                let link = state.link_flags & (LinkFlags::CHASSIS_SILENT | LinkFlags::BUS_DOWN);
                let ms = |ns: u64| ns as f64 / 1e6;
                if service_age > s.service_timeout_ns {
                    Measure {
                        target: 1,
                        value: ms(service_age),
                        threshold: ms(s.service_timeout_ns),
                        stop_edge: f64::NAN,
                        cause: Cause::ServiceSilent,
                    }
                } else if state.stamp_ns == 0 {
                    Measure::flag(true, Cause::NeverHeard)
                } else if chassis_age > s.chassis_timeout_ns {
                    Measure {
                        target: 1,
                        value: ms(chassis_age),
                        threshold: ms(s.chassis_timeout_ns),
                        stop_edge: f64::NAN,
                        cause: Cause::ChassisSilent,
                    }
                } else if link != 0 {
                    Measure::flag(true, Cause::Link(link))
                } else {
                    Measure {
                        value: ms(service_age.max(chassis_age)),
                        ..Measure::clear()
                    }
                }
            }
            SafetyRule::ULTRASONIC | SafetyRule::IR => {
                let (zones, ranges) = if rule == SafetyRule::ULTRASONIC {
                    (&c.ultrasonic, state.ranges.ultrasonic_m)
                } else {
                    (&c.ir, state.ranges.ir_m)
                };
                match zones {
                    Some(zones) => measure_range(zones, state, &ranges, now, level),
                    None => Measure::clear(),
                }
            }
            SafetyRule::SPEED => {
                let Some(s) = &c.speed else {
                    return Measure::clear();
                };
                if !state.is_valid(Group::Motion) {
                    return Measure::clear();
                }
                let linear = f64::from(state.motion.linear_mps);
                // No limit that way: said loudly when the description was read.
                let Some(max) = self.levels.speed_limit(linear) else {
                    return Measure::clear();
                };
                let value = linear.abs();
                // A speed that is not a number counts as too fast.
                let (target, threshold) = if level == 0 {
                    (value.is_nan() || value > max, max)
                } else {
                    let release = max - s.release_margin_mps.min(max / 2.0);
                    (value.is_nan() || value >= release, release)
                };
                Measure {
                    target: u8::from(target),
                    value,
                    threshold,
                    stop_edge: f64::NAN,
                    cause: Cause::Speed {
                        reverse: linear < 0.0,
                    },
                }
            }
            SafetyRule::LIMIT => {
                let (Some(l), Some(limit), true) =
                    (&c.limit, self.speed_limit, state.is_valid(Group::Motion))
                else {
                    return Measure::clear();
                };
                let value = f64::from(state.motion.linear_mps).abs();
                let threshold = limit + l.margin_mps;
                // A speed that is not a number counts as too fast.
                Measure {
                    target: u8::from(value.is_nan() || value > threshold),
                    value,
                    threshold,
                    stop_edge: f64::NAN,
                    cause: Cause::Limit,
                }
            }
            SafetyRule::RUNAWAY | SafetyRule::DIRECTION | SafetyRule::FOLLOWING => {
                let v = self.verdict;
                let found = match rule {
                    SafetyRule::RUNAWAY => v.runaway.map(|f| (f, Unfollowed::NONE)),
                    SafetyRule::DIRECTION => v.direction.map(|f| (f, Unfollowed::NONE)),
                    _ => v.following,
                };
                let Some((finding, cause)) = found else {
                    return Measure::clear();
                };
                if rule == SafetyRule::FOLLOWING {
                    self.unfollowed = cause;
                }
                Measure {
                    target: 1,
                    value: finding.measured,
                    threshold: finding.against,
                    stop_edge: f64::NAN,
                    cause: Cause::Plausibility(finding, cause),
                }
            }
            _ => Measure::clear(),
        }
    }

    /// Writes the decision and the rules' history into `status` (stamp, seq and start time are
    /// the caller's).
    pub fn fill_status(&self, decision: &Decision, status: &mut SafetyStatus) {
        status.state_seq = self.state_seq.unwrap_or(0);
        status.active_rules = decision.active_rules;
        status.acknowledged_rules = decision.acknowledged_rules;
        status.enabled_rules = self.enabled_rules();
        status.limit_forward_mps = decision.envelope.forward_mps;
        status.limit_reverse_mps = decision.envelope.reverse_mps;
        status.limit_lateral_mps = decision.envelope.lateral_mps;
        status.limit_angular_radps = decision.envelope.angular_radps;
        status.action = decision.action;
        status.estop = decision.estop;
        status.unfollowed = if self.rules[usize::from(SafetyRule::FOLLOWING)]
            .debounce
            .level
            > 0
        {
            self.unfollowed
        } else {
            Unfollowed::NONE
        };
        for (i, st) in self.rules.iter().enumerate().take(RULE_SLOTS) {
            status.trigger_counts[i] = st.count;
            status.last_trigger_ns[i] = st.last_trigger_ns;
        }
        if let Some(rule) = self.last_event.rule {
            status.last_rule = rule;
            status.last_event = self.last_event.kind;
            status.last_event_ns = self.last_event.stamp_ns;
            status.set_last_text(&self.last_event.text);
        }
    }
}

fn measure_range(
    zones: &RangeZones,
    state: &ChassisState,
    ranges: &[f32; 3],
    now: u64,
    level: u8,
) -> Measure {
    // Only robots that report ranges (the XBot) have these rules.
    let Some(age) = state.age_ns(Group::Ranges, now) else {
        return Measure::clear();
    };
    if age > zones.max_age_ns {
        // A blind sensor is an obstacle at 0 m.
        let max_age_ms = zones.max_age_ns as f64 / 1e6;
        return Measure {
            target: 2,
            value: age as f64 / 1e6,
            threshold: max_age_ms,
            stop_edge: max_age_ms,
            cause: Cause::Blind,
        };
    }
    // The nearest of the three; a reading that is not a distance is an obstacle.
    let distance = ranges
        .iter()
        .map(|&r| {
            if r.is_finite() && r >= 0.0 {
                f64::from(r)
            } else {
                0.0
            }
        })
        .fold(f64::INFINITY, f64::min);
    let stop_edge = zones.stop_m + if level >= 2 { zones.hysteresis_m } else { 0.0 };
    let slow_edge = zones.slow_m + if level >= 1 { zones.hysteresis_m } else { 0.0 };
    let target = if distance < stop_edge {
        2
    } else if distance < slow_edge {
        1
    } else {
        0
    };
    Measure {
        target,
        value: distance,
        threshold: slow_edge,
        stop_edge,
        cause: Cause::Range,
    }
}

/// An event in words, e.g. `ultrasonic: stop zone, 0.30 m < 0.35 m`.
fn describe(rule: u8, from: u8, to: u8, m: &Measure, threshold: f64) -> String {
    let name = SafetyRule::name(rule);
    let up = to > from;
    match (m.cause, up) {
        (Cause::Faults(bits), true) => format!("{name}: {}", FaultFlags::names(bits).join(", ")),
        (Cause::Faults(_), false) => format!("{name}: cleared"),
        (Cause::Soc, true) => format!("{name}: {:.0} % < {:.0} %", m.value, threshold),
        (Cause::Soc, false) => format!("{name}: {:.0} % ≥ {:.0} %, released", m.value, threshold),
        (Cause::Voltage, true) => format!("{name}: {:.2} V < {:.2} V", m.value, threshold),
        (Cause::Voltage, false) => {
            format!("{name}: {:.2} V ≥ {:.2} V, released", m.value, threshold)
        }
        (Cause::ServiceSilent, _) => format!(
            "{name}: no new state for {:.0} ms (> {:.0} ms)",
            m.value, threshold
        ),
        (Cause::ChassisSilent, _) => format!(
            "{name}: chassis silent for {:.0} ms (> {:.0} ms)",
            m.value, threshold
        ),
        (Cause::NeverHeard, _) => format!("{name}: no frame from the chassis yet"),
        (Cause::Link(flags), _) => format!("{name}: {}", LinkFlags::names(flags).join(", ")),
        (Cause::Bumper, true) => format!("{name}: pressed"),
        (Cause::Bumper, false) => format!("{name}: released"),
        (Cause::Operator, _) => format!("{name}: e-stop (SIGUSR1)"),
        (Cause::Blind, _) => format!(
            "{name}: blind, ranges {:.0} ms old (> {:.0} ms)",
            m.value, threshold
        ),
        (Cause::Range, true) => format!(
            "{name}: {} zone, {:.2} m < {:.2} m",
            if to >= 2 { "stop" } else { "slow" },
            m.value,
            threshold
        ),
        (Cause::Range, false) if to == 1 => format!(
            "{name}: back to the slow zone, {:.2} m ≥ {:.2} m",
            m.value, threshold
        ),
        (Cause::Range, false) => format!("{name}: clear, {:.2} m ≥ {:.2} m", m.value, threshold),
        (Cause::Speed { reverse }, true) => format!(
            "{name}: {:.2} m/s{} > {:.2} m/s",
            m.value,
            if reverse { " reverse" } else { "" },
            threshold
        ),
        (Cause::Speed { .. }, false) => format!(
            "{name}: {:.2} m/s < {:.2} m/s, released",
            m.value, threshold
        ),
        (Cause::Limit, true) => format!(
            "{name}: {:.2} m/s > the speed limit + margin, {:.2} m/s",
            m.value, threshold
        ),
        (Cause::Limit, false) => format!(
            "{name}: {:.2} m/s ≤ {:.2} m/s, released",
            m.value, threshold
        ),
        (Cause::Plausibility(f, _), _) if rule == SafetyRule::RUNAWAY => format!(
            "{name}: {:.2} {unit}, commands allow {:.2} {unit}",
            f.measured.abs(),
            f.against,
            unit = f.unit
        ),
        (Cause::Plausibility(f, _), _) if rule == SafetyRule::DIRECTION => format!(
            "{name}: {:.2} {unit} against a {:.2} {unit} command",
            f.measured,
            f.against,
            unit = f.unit
        ),
        (Cause::Plausibility(f, cause), _) => format!(
            "{name}: {:.2} of {:.2} {}, {}",
            f.measured,
            f.against,
            f.unit,
            Unfollowed::name(cause)
        ),
        (Cause::None, _) if rule == SafetyRule::STALE => format!("{name}: fresh state again"),
        (Cause::None, _) => format!("{name}: {}", if up { "triggered" } else { "released" }),
    }
}

#[cfg(test)]
#[path = "engine_tests.rs"]
mod tests;
