//! Plausibility: the wheels follow the command.
//!
//! Three rules compare the linear speed on the wire (the mux's output after the driver's clamps,
//! `ChassisState::command`) with the linear speed measured (`ChassisState::motion`):
//!
//! * **runaway**: faster than any recent command allows, × `runaway_factor` + `still_mps` —
//!   moving while commanded still among them (latches by default);
//! * **direction**: against the command beyond `still_mps` (latches by default);
//! * **following**: commanded beyond `still_mps` and slower than `follow_fraction` of it for
//!   longer than the robot needs to get there (stops by default); the rule names what the
//!   chassis reports that explains it ([`Unfollowed`]), carried in `SafetyStatus::unfollowed`.
//!
//! A robot does not follow its command at once: it lags, and it brakes at its acceleration.
//! Each rule judges against the *reach* of recent commands — the fastest and the slowest speed
//! commanded, held for `lag_ms`, then closing in on the command at the robot's acceleration
//! (the description's effective limit, overridden by `[rules.plausibility] linear_accel_mps2`).
//! Without an acceleration none of the three judges, and the monitor says so once. Rules judge
//! only once the driver reports the command it put on the wire; a yaw rate is not judged
//! (steering robots put a steer angle on the wire, not a yaw rate).

use chassis_client::{
    ChassisState, ControlMode, FaultFlags, Group, LinkFlags, MotionLimits, SystemState, Unfollowed,
};
use serde::{Deserialize, Serialize};

use crate::config::{Action, ConfigError, Timing, bad, check_non_negative, check_timing, ms_to_ns};

/// `[rules.runaway]`, `[rules.direction]`, `[rules.following]`: when each acts.
macro_rules! plausibility_rule {
    ($name:ident, $doc:literal, $action:expr, $trigger:expr, $release:expr) => {
        #[doc = $doc]
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct $name {
            pub enabled: bool,
            pub action: Action,
            pub trigger_ms: u64,
            pub release_ms: u64,
        }

        impl Default for $name {
            fn default() -> Self {
                Self {
                    enabled: true,
                    action: $action,
                    trigger_ms: $trigger,
                    release_ms: $release,
                }
            }
        }

        impl $name {
            fn timing(&self, key: &str) -> Result<Option<Timing>, ConfigError> {
                check_timing(key, self.trigger_ms, self.release_ms)?;
                Ok(self
                    .enabled
                    .then(|| Timing::new(self.action, self.trigger_ms, self.release_ms)))
            }
        }
    };
}

plausibility_rule!(
    RunawayRule,
    "`[rules.runaway]`: faster than commanded, or moving while commanded still.",
    Action::Latch,
    200,
    500
);
plausibility_rule!(
    DirectionRule,
    "`[rules.direction]`: moving against the command.",
    Action::Latch,
    200,
    500
);
plausibility_rule!(
    FollowingRule,
    "`[rules.following]`: commanded, and not moving. It triggers after the time the robot needs \
     to start (see `[rules.plausibility]`), so its own `trigger_ms` adds to that.",
    Action::Stop,
    0,
    1000
);

/// `[rules.plausibility]`: the thresholds of the runaway, direction and following rules.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlausibilityThresholds {
    /// The robot's linear acceleration, m/s². Absent: the description's effective limit.
    #[serde(deserialize_with = "crate::config::plain_number")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub linear_accel_mps2: Option<f64>,
    /// A measured speed below this is still, m/s (measurement noise, creep).
    pub still_mps: f64,
    /// How long the robot may keep a command's speed after it changed, ms (its response lag).
    pub lag_ms: u64,
    /// A runaway: faster than the reach of recent commands × this (≥ 1) + `still_mps`.
    pub runaway_factor: f64,
    /// Not following: slower than this fraction of the command (0 to 1).
    pub follow_fraction: f64,
}

impl Default for PlausibilityThresholds {
    fn default() -> Self {
        Self {
            linear_accel_mps2: None,
            still_mps: 0.05,
            lag_ms: 500,
            runaway_factor: 1.2,
            follow_fraction: 0.25,
        }
    }
}

/// The validated plausibility rules (a disabled rule is `None`).
#[derive(Debug, Clone, PartialEq)]
pub struct Plausibility {
    pub runaway: Option<Timing>,
    pub direction: Option<Timing>,
    pub following: Option<Timing>,
    /// The file's acceleration, m/s², overriding the description's.
    pub linear_accel_mps2: Option<f64>,
    pub still_mps: f64,
    pub lag_ns: u64,
    pub runaway_factor: f64,
    pub follow_fraction: f64,
}

impl Plausibility {
    pub(crate) fn validate(
        runaway: &RunawayRule,
        direction: &DirectionRule,
        following: &FollowingRule,
        t: &PlausibilityThresholds,
    ) -> Result<Self, ConfigError> {
        let key = "rules.plausibility";
        check_non_negative(key, &[("still_mps", t.still_mps)])?;
        if let Some(a) = t.linear_accel_mps2
            && !(a.is_finite() && a > 0.0)
        {
            return Err(bad(
                key,
                format!("linear_accel_mps2 must be above 0 (is {a})"),
            ));
        }
        if !(t.runaway_factor.is_finite() && (1.0..=3.0).contains(&t.runaway_factor)) {
            return Err(bad(key, "runaway_factor must be 1 to 3"));
        }
        if !(t.follow_fraction.is_finite() && (0.0..=1.0).contains(&t.follow_fraction)) {
            return Err(bad(key, "follow_fraction must be 0 to 1"));
        }
        if t.lag_ms > 10_000 {
            return Err(bad(key, "lag_ms must be at most 10000"));
        }
        Ok(Self {
            runaway: runaway.timing("rules.runaway")?,
            direction: direction.timing("rules.direction")?,
            following: following.timing("rules.following")?,
            linear_accel_mps2: t.linear_accel_mps2,
            still_mps: t.still_mps,
            lag_ns: ms_to_ns(t.lag_ms),
            runaway_factor: t.runaway_factor,
            follow_fraction: t.follow_fraction,
        })
    }
}

/// What the chassis reports that explains why it does not follow its command, most telling
/// first ([`Unfollowed`]).
pub fn unfollowed(state: &ChassisState) -> u8 {
    let faults = state.system.fault_flags;
    let system = state.is_valid(Group::System);
    let mode = state.system.control_mode;
    if state.link_flags & (LinkFlags::CHASSIS_SILENT | LinkFlags::BUS_DOWN | LinkFlags::CAN_BUS_OFF)
        != 0
    {
        Unfollowed::BUS_SILENT
    } else if faults & FaultFlags::EMERGENCY_STOP != 0
        || (system && state.system.body_status == SystemState::BODY_EMERGENCY_STOP)
    {
        Unfollowed::CHASSIS_ESTOP
    } else if state.has_link_flag(LinkFlags::RC_AUTHORITY) || mode == ControlMode::REMOTE {
        Unfollowed::REMOTE_CONTROL
    } else if mode == ControlMode::STANDBY {
        Unfollowed::STANDBY
    } else if mode == ControlMode::SERIAL {
        Unfollowed::SERIAL_MODE
    } else if faults & FaultFlags::STOPS_DRIVE != 0 {
        Unfollowed::DRIVER_FAULT
    } else if system && state.system.power_enabled == 0 {
        Unfollowed::DRIVERS_DISABLED
    } else if state.system.parking_brake_engaged != 0 {
        Unfollowed::PARKING_BRAKE
    } else {
        Unfollowed::UNREPORTED
    }
}

/// A rule's finding: the measured speed and the speed it is judged against, m/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finding {
    pub measured_mps: f64,
    pub against_mps: f64,
}

/// What the three rules find in one state sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Verdict {
    /// Measured against the most the reach allows.
    pub runaway: Option<Finding>,
    /// Measured against the command.
    pub direction: Option<Finding>,
    /// Measured against the command, with the [`Unfollowed`] cause.
    pub following: Option<(Finding, u8)>,
}

/// The speeds recent commands allow, and since when the robot has not followed.
#[derive(Debug, Clone, Default)]
pub struct Watch {
    /// The description's effective linear acceleration, m/s² (NaN: none).
    described_accel_mps2: Option<f64>,
    /// Fastest and slowest speed recent commands allow, m/s, each with when it was last
    /// commanded.
    hi: (f64, u64),
    lo: (f64, u64),
    last_ns: Option<u64>,
    unfollowed_since: Option<u64>,
}

impl Watch {
    /// Takes the acceleration from the robot's description.
    pub fn set_limits(&mut self, limits: &MotionLimits) {
        let a = limits.linear_accel_mps2;
        self.described_accel_mps2 = (a.is_finite() && a > 0.0).then_some(a);
    }

    /// The acceleration the rules judge by: the file's, else the description's.
    pub fn accel_mps2(&self, p: &Plausibility) -> Option<f64> {
        p.linear_accel_mps2.or(self.described_accel_mps2)
    }

    /// Judges the newest state at `now`.
    pub fn judge(&mut self, now: u64, state: &ChassisState, p: &Plausibility) -> Verdict {
        let command = f64::from(state.command.linear_mps);
        let measured = f64::from(state.motion.linear_mps);
        let (Some(accel), true, true, true) = (
            self.accel_mps2(p),
            state.is_valid(Group::Command) && state.is_valid(Group::Motion),
            command.is_finite(),
            // A speed that is no number is the speed rule's.
            measured.is_finite(),
        ) else {
            *self = Self {
                described_accel_mps2: self.described_accel_mps2,
                ..Self::default()
            };
            return Verdict::default();
        };
        let dt = self
            .last_ns
            .map_or(0.0, |last| now.saturating_sub(last) as f64 / 1e9)
            .min(1.0);
        self.last_ns = Some(now);
        let closing = |at: u64| {
            if now.saturating_sub(at) >= p.lag_ns {
                accel * dt
            } else {
                0.0
            }
        };
        self.hi = if command >= self.hi.0 {
            (command, now)
        } else {
            ((self.hi.0 - closing(self.hi.1)).max(command), self.hi.1)
        };
        self.lo = if command <= self.lo.0 {
            (command, now)
        } else {
            ((self.lo.0 + closing(self.lo.1)).min(command), self.lo.1)
        };
        let (hi, lo, still) = (self.hi.0, self.lo.0, p.still_mps);
        let reach = hi.abs().max(lo.abs());
        let mut verdict = Verdict::default();
        let allowed = reach * p.runaway_factor + still;
        if measured.abs() > allowed {
            verdict.runaway = Some(Finding {
                measured_mps: measured,
                against_mps: allowed,
            });
        }
        let against = (command > still && measured < lo.min(0.0) - still)
            || (command < -still && measured > hi.max(0.0) + still);
        if against {
            verdict.direction = Some(Finding {
                measured_mps: measured,
                against_mps: command,
            });
        }
        let behind = command.abs() > still
            && measured * command.signum() < p.follow_fraction * command.abs();
        if !behind {
            self.unfollowed_since = None;
            return verdict;
        }
        let since = *self.unfollowed_since.get_or_insert(now);
        // Time to get from the slowest speed in reach to the command, and the lag.
        let need_s = (command.abs() + reach) / accel + p.lag_ns as f64 / 1e9;
        if now.saturating_sub(since) as f64 / 1e9 >= need_s {
            let finding = Finding {
                measured_mps: measured,
                against_mps: command,
            };
            verdict.following = Some((finding, unfollowed(state)));
        }
        verdict
    }
}
