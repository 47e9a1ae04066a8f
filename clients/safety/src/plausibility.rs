//! Plausibility: the wheels follow the command.
//!
//! Three rules compare the speed on the wire (the mux's output after the driver's clamps,
//! `ChassisState::command`) with the speed measured (`ChassisState::motion`), on each axis a
//! robot commands: the linear speed, and the yaw rate where the robot puts one on the wire (it
//! does not steer its wheels: [`Kinematics::steers`]):
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
//! (the description's effective limit, overridden by `[rules.plausibility] linear_accel_mps2`
//! and `angular_accel_radps2`). Without an acceleration an axis is not judged, and the monitor
//! says so once for the linear one. Rules judge only once the driver reports the command it put
//! on the wire; a steering robot's yaw rate is not judged (it puts a steer angle on the wire).

use chassis_client::{
    ChassisState, ControlMode, FaultFlags, Group, Kinematics, LinkFlags, MotionLimits, SystemState,
    Unfollowed,
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
    /// The robot's yaw acceleration, rad/s². Absent: the description's effective limit.
    #[serde(deserialize_with = "crate::config::plain_number")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub angular_accel_radps2: Option<f64>,
    /// A measured speed below this is still, m/s (measurement noise, creep).
    pub still_mps: f64,
    /// A measured yaw rate below this is still, rad/s.
    pub still_radps: f64,
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
            angular_accel_radps2: None,
            still_mps: 0.05,
            still_radps: 0.1,
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
    /// The file's accelerations, m/s² and rad/s², overriding the description's.
    pub linear_accel_mps2: Option<f64>,
    pub angular_accel_radps2: Option<f64>,
    pub still_mps: f64,
    pub still_radps: f64,
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
        check_non_negative(
            key,
            &[("still_mps", t.still_mps), ("still_radps", t.still_radps)],
        )?;
        for (name, a) in [
            ("linear_accel_mps2", t.linear_accel_mps2),
            ("angular_accel_radps2", t.angular_accel_radps2),
        ] {
            if let Some(a) = a
                && !(a.is_finite() && a > 0.0)
            {
                return Err(bad(key, format!("{name} must be above 0 (is {a})")));
            }
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
            angular_accel_radps2: t.angular_accel_radps2,
            still_mps: t.still_mps,
            still_radps: t.still_radps,
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

/// A rule's finding: the measured speed and the speed it is judged against, in `unit` (`m/s`,
/// or `rad/s` for a yaw rate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Finding {
    pub measured: f64,
    pub against: f64,
    pub unit: &'static str,
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

/// One axis: the speeds recent commands allow, and since when the robot has not followed.
#[derive(Debug, Clone, Default)]
struct Reach {
    /// Fastest and slowest speed recent commands allow, each with when it was last commanded.
    hi: (f64, u64),
    lo: (f64, u64),
    unfollowed_since: Option<u64>,
}

/// What one axis is judged with: its acceleration, its still band and its unit.
#[derive(Debug, Clone, Copy)]
struct Axis {
    accel: f64,
    still: f64,
    unit: &'static str,
}

impl Reach {
    /// The three rules on one axis at `now`, `dt` s after the previous state: the runaway, the
    /// direction and the following findings.
    fn judge(
        &mut self,
        (now, dt): (u64, f64),
        (command, measured): (f64, f64),
        axis: Axis,
        p: &Plausibility,
    ) -> [Option<Finding>; 3] {
        let closing = |at: u64| {
            if now.saturating_sub(at) >= p.lag_ns {
                axis.accel * dt
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
        let (hi, lo, still) = (self.hi.0, self.lo.0, axis.still);
        let reach = hi.abs().max(lo.abs());
        let finding = |against| Finding {
            measured,
            against,
            unit: axis.unit,
        };
        let allowed = reach * p.runaway_factor + still;
        let runaway = (measured.abs() > allowed).then(|| finding(allowed));
        let against = (command > still && measured < lo.min(0.0) - still)
            || (command < -still && measured > hi.max(0.0) + still);
        let direction = against.then(|| finding(command));
        let behind = command.abs() > still
            && measured * command.signum() < p.follow_fraction * command.abs();
        if !behind {
            self.unfollowed_since = None;
            return [runaway, direction, None];
        }
        let since = *self.unfollowed_since.get_or_insert(now);
        // Time to get from the slowest speed in reach to the command, and the lag.
        let need_s = (command.abs() + reach) / axis.accel + p.lag_ns as f64 / 1e9;
        let following =
            (now.saturating_sub(since) as f64 / 1e9 >= need_s).then(|| finding(command));
        [runaway, direction, following]
    }
}

/// What the rules judge by, from the robot's description, and each axis' recent commands.
#[derive(Debug, Clone, Default)]
pub struct Watch {
    /// The description's effective accelerations, m/s² and rad/s² (none: not limited).
    described_accel_mps2: Option<f64>,
    described_accel_radps2: Option<f64>,
    /// The robot puts a yaw rate on the wire (it does not steer its wheels).
    yaw_on_the_wire: bool,
    linear: Reach,
    angular: Reach,
    last_ns: Option<u64>,
}

fn positive(a: f64) -> Option<f64> {
    (a.is_finite() && a > 0.0).then_some(a)
}

impl Watch {
    /// Takes the accelerations and the kinematics from the robot's description.
    pub fn set_limits(&mut self, limits: &MotionLimits, kinematics: u8) {
        self.described_accel_mps2 = positive(limits.linear_accel_mps2);
        self.described_accel_radps2 = positive(limits.angular_accel_radps2);
        self.yaw_on_the_wire = kinematics != 0 && !Kinematics::steers(kinematics);
    }

    /// The acceleration the rules judge by: the file's, else the description's.
    pub fn accel_mps2(&self, p: &Plausibility) -> Option<f64> {
        p.linear_accel_mps2.or(self.described_accel_mps2)
    }

    /// Judges the newest state at `now`.
    pub fn judge(&mut self, now: u64, state: &ChassisState, p: &Plausibility) -> Verdict {
        let linear = (
            f64::from(state.command.linear_mps),
            f64::from(state.motion.linear_mps),
        );
        let (Some(accel), true, true, true) = (
            self.accel_mps2(p),
            state.is_valid(Group::Command) && state.is_valid(Group::Motion),
            linear.0.is_finite(),
            // A speed that is no number is the speed rule's.
            linear.1.is_finite(),
        ) else {
            self.linear = Reach::default();
            self.angular = Reach::default();
            self.last_ns = None;
            return Verdict::default();
        };
        let dt = self
            .last_ns
            .map_or(0.0, |last| now.saturating_sub(last) as f64 / 1e9)
            .min(1.0);
        self.last_ns = Some(now);
        let axis = Axis {
            accel,
            still: p.still_mps,
            unit: "m/s",
        };
        let mut found = self.linear.judge((now, dt), linear, axis, p);
        let angular = (
            f64::from(state.command.angular_radps),
            f64::from(state.motion.angular_radps),
        );
        if let (true, Some(accel), true) = (
            self.yaw_on_the_wire,
            p.angular_accel_radps2.or(self.described_accel_radps2),
            angular.0.is_finite() && angular.1.is_finite(),
        ) {
            let axis = Axis {
                accel,
                still: p.still_radps,
                unit: "rad/s",
            };
            let yaw = self.angular.judge((now, dt), angular, axis, p);
            for (linear, yaw) in found.iter_mut().zip(yaw) {
                *linear = linear.or(yaw);
            }
        } else {
            self.angular = Reach::default();
        }
        let [runaway, direction, following] = found;
        Verdict {
            runaway,
            direction,
            following: following.map(|f| (f, unfollowed(state))),
        }
    }
}
