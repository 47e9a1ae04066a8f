//! `SafetyStatus`: what the safety monitor (`chassis-safety`) decided and why, published on its
//! own service `chassis/<name>/safety` (publish-subscribe, history 1, + event) on every change
//! and at 10 Hz, so `chassis status` and dashboards can show every trigger and release.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

use crate::text::{serialize_fixed_str, write_fixed_str};

named_constants! {
    /// The monitor's rules: the index into the per-rule arrays of [`SafetyStatus`] and the bit in
    /// its rule masks.
    pub enum SafetyRule: u8 {
        /// Chassis fault flags that are not warnings.
        FAULT = 0 => "fault",
        /// Battery state of charge (or voltage where there is no BMS) below a threshold.
        BATTERY = 1 => "battery",
        /// No fresh state: the service or the chassis is silent, or the bus is down.
        STALE = 2 => "stale",
        /// The bumper (touch edge) is pressed.
        BUMPER = 3 => "bumper",
        /// Something in front, inside the ultrasonic slow or stop zone (XBot).
        ULTRASONIC = 4 => "ultrasonic",
        /// Something behind, inside the IR slow or stop zone (XBot).
        IR = 5 => "ir",
        /// Measured speed above the limit.
        SPEED = 6 => "speed",
        /// The operator's e-stop (SIGUSR1 to the monitor).
        OPERATOR = 7 => "operator",
        /// Moving while commanded still, or faster than commanded beyond a margin.
        RUNAWAY = 8 => "runaway",
        /// Moving against the command beyond a margin.
        DIRECTION = 9 => "direction",
        /// Commanded longer than the robot needs to start, measured still
        /// ([`SafetyStatus::unfollowed`] names the likely cause).
        FOLLOWING = 10 => "following",
        /// Safely limited speed: measured speed above the mux's standing speed limit
        /// (`MuxStatus::speed_limit_mps`) beyond a margin for longer than a bound.
        LIMIT = 11 => "limit",
    }
}

impl SafetyRule {
    /// Rules in use; the per-rule arrays have room for [`RULE_SLOTS`].
    pub const COUNT: usize = Self::NAMES.len();

    /// The rule's bit in the masks of [`SafetyStatus`].
    pub const fn bit(rule: u8) -> u32 {
        1 << rule
    }

    /// Names of the rules whose bits are set.
    pub fn names(bits: u32) -> Vec<&'static str> {
        Self::NAMES
            .iter()
            .filter(|(rule, _)| bits & Self::bit(*rule) != 0)
            .map(|(_, name)| *name)
            .collect()
    }
}

/// Slots reserved for rules (room to add rules without a layout change).
pub const RULE_SLOTS: usize = 12;
const _: () = assert!(SafetyRule::COUNT <= RULE_SLOTS);

named_constants! {
    /// What the monitor publishes on its velocity source (`SafetyStatus::action`), mildest first.
    pub enum SafetyAction: u8 {
        /// All is well: heartbeats.
        NONE = 0 => "none",
        /// A speed envelope (`VelocityRequest::limit`): slower, or no motion towards an obstacle.
        SLOW = 1 => "slow",
        /// An explicit zero request at the safety source's priority.
        STOP = 2 => "stop",
        /// A zero request that engages the `estop` lock, released only by the operator.
        LATCH = 3 => "latch",
    }
}

named_constants! {
    /// The `estop` lock as the monitor last saw it in the mux status (`SafetyStatus::estop`).
    pub enum EstopState: u8 {
        /// No mux status yet, or the mux has no lock called `estop`.
        UNKNOWN = 0 => "unknown",
        FREE = 1 => "free",
        /// Held by the monitor's own source.
        HELD_BY_MONITOR = 2 => "held by the monitor",
        /// Engaged by the operator (`chassis control estop`).
        HELD_BY_OPERATOR = 3 => "held by the operator",
        /// Held by another source.
        HELD_BY_OTHER = 4 => "held by another source",
    }
}

named_constants! {
    /// Why the chassis does not follow its command, as far as it reports
    /// (`SafetyStatus::unfollowed`, while [`SafetyRule::FOLLOWING`] is in force), most telling
    /// first.
    pub enum Unfollowed: u8 {
        /// The rule is not in force.
        NONE = 0 => "none",
        /// The chassis reports nothing that explains it: slipping, stalled, or a fault it does
        /// not report.
        UNREPORTED = 1 => "unreported",
        /// Nothing heard from the chassis, or the bus is down.
        BUS_SILENT = 2 => "bus-silent",
        /// The chassis' own E-stop is pressed.
        CHASSIS_ESTOP = 3 => "chassis-estop",
        /// An RC transmitter has the chassis.
        REMOTE_CONTROL = 4 => "remote-control",
        /// The chassis is in standby: it answers, it does not drive.
        STANDBY = 5 => "standby",
        /// The chassis takes its commands on another port (serial mode).
        SERIAL_MODE = 6 => "serial-mode",
        /// A motor driver is in error or unreachable.
        DRIVER_FAULT = 7 => "driver-fault",
        /// Drive power is off.
        DRIVERS_DISABLED = 8 => "drivers-disabled",
        /// The parking brake is engaged.
        PARKING_BRAKE = 9 => "parking-brake",
    }
}

impl Unfollowed {
    /// The cause in words, as every view shows it.
    pub fn text(cause: u8) -> &'static str {
        match cause {
            Self::UNREPORTED => {
                "the chassis reports no cause (slipping, stalled, or an unreported fault)"
            }
            Self::BUS_SILENT => "the chassis is silent or the bus is down",
            Self::CHASSIS_ESTOP => "the chassis' E-stop is pressed",
            Self::REMOTE_CONTROL => "a remote-control transmitter has the chassis",
            Self::STANDBY => "the chassis is in standby",
            Self::SERIAL_MODE => "the chassis takes commands on its serial port",
            Self::DRIVER_FAULT => "a motor driver is in error or unreachable",
            Self::DRIVERS_DISABLED => "drive power is off",
            Self::PARKING_BRAKE => "the parking brake is engaged",
            _ => "",
        }
    }
}

named_constants! {
    /// The kind of the monitor's last event (`SafetyStatus::last_event`).
    pub enum SafetyEvent: u8 {
        NONE = 0 => "none",
        /// A rule triggered, or went to a stricter level (slow zone → stop zone).
        TRIGGER = 1 => "trigger",
        /// A rule released, or went to a milder level.
        RELEASE = 2 => "release",
        /// The operator released the `estop` lock a rule had latched.
        UNLATCH = 3 => "unlatch",
    }
}

ipc_type! {
    /// The safety monitor's decision and its history.
    #[derive(Serialize)]
    #[type_name("chassis::SafetyStatus.v1")]
    pub struct SafetyStatus {
        /// `CLOCK_MONOTONIC` time of the decision, ns.
        pub stamp_ns: u64,
        /// Incremented for every published sample.
        pub seq: u64,
        /// `CLOCK_MONOTONIC` time the monitor started, ns.
        pub started_ns: u64,
        /// `seq` of the `ChassisState` the decision was made on (0: none yet).
        pub state_seq: u64,
        /// Age of that state sample (since its `stamp_ns`) at `stamp_ns`, ms, saturating.
        pub state_age_ms: u32,
        /// [`SafetyRule`] bits of the rules in force (triggered and not yet released).
        pub active_rules: u32,
        /// [`SafetyRule`] bits of latching rules whose latch the operator released while their
        /// condition was still present: they act again only once it clears and comes back.
        pub acknowledged_rules: u32,
        /// [`SafetyRule`] bits of the rules enabled in the monitor's configuration.
        pub enabled_rules: u32,
        /// The envelope in force, m/s and rad/s ([`SafetyStatus::UNLIMITED`]: no limit; all zero
        /// while stopping).
        pub limit_forward_mps: f32,
        pub limit_reverse_mps: f32,
        pub limit_lateral_mps: f32,
        pub limit_angular_radps: f32,
        /// [`SafetyAction`].
        pub action: u8,
        /// [`EstopState`].
        pub estop: u8,
        /// The [`SafetyRule`] of the last event (0xFF: none yet).
        pub last_rule: u8,
        /// [`SafetyEvent`] kind of the last event.
        pub last_event: u8,
        /// [`Unfollowed`]: why the chassis does not follow its command while
        /// [`SafetyRule::FOLLOWING`] is in force (was a reserved byte: readers that ignore it
        /// see 0).
        pub unfollowed: u8,
        #[serde(skip)]
        pub _reserved: [u8; 3],
        /// Times each rule triggered since the monitor started.
        pub trigger_counts: [u32; RULE_SLOTS],
        /// `CLOCK_MONOTONIC` time each rule last triggered, ns (0: never).
        pub last_trigger_ns: [u64; RULE_SLOTS],
        /// `CLOCK_MONOTONIC` time of the last event, ns (0: none yet).
        pub last_event_ns: u64,
        /// The last event in words (NUL-padded UTF-8), e.g.
        /// `ultrasonic: stop zone, 0.30 m < 0.35 m`.
        #[serde(serialize_with = "serialize_fixed_str")]
        pub last_text: [u8; SafetyStatus::TEXT_LEN] as text,
    }
}

impl Default for SafetyStatus {
    fn default() -> Self {
        Self {
            limit_forward_mps: Self::UNLIMITED,
            limit_reverse_mps: Self::UNLIMITED,
            limit_lateral_mps: Self::UNLIMITED,
            limit_angular_radps: Self::UNLIMITED,
            action: SafetyAction::NONE,
            estop: EstopState::UNKNOWN,
            last_rule: Self::NO_RULE,
            last_event: SafetyEvent::NONE,
            ..zerocopy::FromZeros::new_zeroed()
        }
    }
}

impl SafetyStatus {
    /// The service suffix: the monitor publishes on `chassis/<name>/safety`.
    pub const SERVICE: &'static str = "safety";
    pub const TEXT_LEN: usize = 64;
    /// An envelope bound that limits nothing (finite, so it is a valid `VelocityRequest` limit).
    pub const UNLIMITED: f32 = f32::MAX;
    /// [`SafetyStatus::last_rule`] before the first event.
    pub const NO_RULE: u8 = 0xFF;

    pub fn set_last_text(&mut self, text: &str) {
        write_fixed_str(&mut self.last_text, text);
    }

    /// True while `rule` ([`SafetyRule`]) is in force.
    pub fn is_active(&self, rule: u8) -> bool {
        self.active_rules & SafetyRule::bit(rule) != 0
    }

    /// The decision in words, as every view shows it: `all clear`, `SLOW by ultrasonic`,
    /// `STOP by following: the chassis is in standby`.
    pub fn why(&self) -> String {
        if self.action == SafetyAction::NONE {
            return "all clear".into();
        }
        let mut text = format!(
            "{} by {}",
            SafetyAction::name(self.action).to_uppercase(),
            SafetyRule::names(self.active_rules).join(", ")
        );
        if self.unfollowed != Unfollowed::NONE {
            text.push_str(": ");
            text.push_str(Unfollowed::text(self.unfollowed));
        }
        text
    }

    /// How often `rule` triggered (0 for an unknown rule).
    pub fn trigger_count(&self, rule: u8) -> u32 {
        self.trigger_counts
            .get(usize::from(rule))
            .copied()
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rule_names_and_bits_agree() {
        assert_eq!(SafetyRule::name(SafetyRule::ULTRASONIC), "ultrasonic");
        assert_eq!(SafetyRule::name(200), "unknown");
        assert_eq!(
            SafetyRule::names(SafetyRule::bit(SafetyRule::FAULT) | SafetyRule::bit(SafetyRule::IR)),
            vec!["fault", "ir"]
        );
    }

    #[test]
    fn a_default_status_limits_nothing_and_serializes_its_text() {
        let mut s = SafetyStatus::default();
        assert_eq!(s.limit_forward_mps, SafetyStatus::UNLIMITED);
        assert!(!s.is_active(SafetyRule::STALE));
        s.set_last_text("battery: 12 % < 15 %");
        s.active_rules = SafetyRule::bit(SafetyRule::BATTERY);
        assert!(s.is_active(SafetyRule::BATTERY));
        let json = serde_json::to_value(s).unwrap();
        assert_eq!(json["last_text"], "battery: 12 % < 15 %");
        assert!(json.get("_reserved").is_none());
    }

    #[test]
    fn the_decision_in_words_names_the_rules_and_the_cause() {
        let mut s = SafetyStatus::default();
        assert_eq!(s.why(), "all clear");
        s.action = SafetyAction::STOP;
        s.active_rules = SafetyRule::bit(SafetyRule::FOLLOWING);
        s.unfollowed = Unfollowed::STANDBY;
        assert_eq!(s.why(), "STOP by following: the chassis is in standby");
        for (cause, _) in Unfollowed::NAMES.into_iter().skip(1) {
            assert!(!Unfollowed::text(cause).is_empty(), "{cause}");
        }
    }
}
