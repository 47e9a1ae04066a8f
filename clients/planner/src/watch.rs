//! Everything that stops the planner from getting there, judged from the state and the mux
//! status at a time given by the caller: faults, a silent service or chassis, a missing pose,
//! and being held — preempted by another source, blocked by a lock or a stale safety monitor,
//! the chassis not ready, an RC transmitter in charge — for longer than the preemption timeout.
//!
//! While held the planner keeps sending (so it resumes the moment it is handed back; the mux
//! decides who drives), and only gives up when the hold outlasts the timeout.

use chassis_client::{
    ChassisState, ClampFlags, FaultFlags, Group, LinkFlags, MuxStatus, SourceFlags, ZeroReason,
};
use thiserror::Error;

/// Why the robot does not obey the planner right now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Hold {
    /// Another source won the mux.
    PreemptedBy(String),
    /// A required source (the safety monitor) is stale: the mux outputs zero.
    RequiredSourceStale,
    /// A lock blocks the planner's source.
    Locked,
    /// The chassis cannot move (standby, brake, fault): the driver sends zero.
    ChassisNotReady,
    /// An RC transmitter has authority over the chassis.
    RcAuthority,
    /// The bus or the chassis stops the robot, or a stop ended and the mux waits for a zero
    /// (motion starts only from a zero): the mux's own explanation (`MuxStatus::why`).
    Stopped(String),
}

impl std::fmt::Display for Hold {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Hold::PreemptedBy(source) => write!(f, "preempted by {source}"),
            Hold::RequiredSourceStale => f.write_str(
                "held: a required source is stale (is the safety monitor running? \
                 chassisd --no-safety-monitor lifts the rule)",
            ),
            Hold::Locked => f.write_str("held: a lock blocks the planner (estop?)"),
            Hold::ChassisNotReady => {
                f.write_str("held: the chassis is not ready (standby, brake or fault)")
            }
            Hold::RcAuthority => f.write_str("held: an RC transmitter has authority"),
            Hold::Stopped(why) => write!(f, "held: {why}"),
        }
    }
}

/// Why the planner gives up.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Failure {
    #[error("chassis fault: {names}")]
    Fault { names: String },
    #[error("no new state from chassisd for {seconds:.1} s — is it still running?")]
    StaleState { seconds: f64 },
    #[error(
        "chassis/{name} publishes no pose (its pose group is not valid), so there is nothing to \
         follow a path with{hint}"
    )]
    NoPose { name: String, hint: String },
    #[error("the pose is {seconds:.1} s old{link}: the chassis stopped reporting")]
    StalePose { seconds: f64, link: String },
    #[error("{hold} for {seconds:.1} s, longer than the preemption timeout ({timeout_s} s)")]
    HeldTooLong {
        hold: Hold,
        seconds: f64,
        timeout_s: f64,
    },
}

impl Failure {
    /// The failure of a robot without a pose, with what to do about it (`hint`, from the
    /// robot's description: `run::pose_hint`).
    pub fn no_pose(name: &str, hint: &str) -> Self {
        Failure::NoPose {
            name: name.to_string(),
            hint: hint.to_string(),
        }
    }
}

/// The limits.
#[derive(Debug, Clone, PartialEq)]
pub struct WatchConfig {
    /// The robot's name (messages).
    pub name: String,
    /// What to do about a missing pose (appended to the failure).
    pub pose_hint: String,
    /// The planner's source.
    pub source: String,
    /// Longest hold, ns.
    pub preempt_timeout_ns: u64,
    /// Longest wait for a new state sample, ns.
    pub state_timeout_ns: u64,
    /// Oldest pose followed, ns.
    pub pose_timeout_ns: u64,
}

/// What the watch sees now.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// The planner drives.
    Clear,
    /// The planner is held since `since_ns`.
    Held { hold: Hold, since_ns: u64 },
}

/// The watch: state of the timers.
#[derive(Debug, Clone)]
pub struct Watch {
    config: WatchConfig,
    last_seq: Option<u64>,
    last_new_state_ns: u64,
    held_since_ns: Option<u64>,
}

const NS: f64 = 1e9;

impl Watch {
    pub fn new(config: WatchConfig, now_ns: u64) -> Self {
        Self {
            config,
            last_seq: None,
            last_new_state_ns: now_ns,
            held_since_ns: None,
        }
    }

    /// Judges the latest state and mux status at `now_ns`.
    pub fn observe(
        &mut self,
        now_ns: u64,
        state: Option<&ChassisState>,
        mux: Option<&MuxStatus>,
    ) -> Result<Status, Failure> {
        if let Some(s) = state
            && self.last_seq != Some(s.seq)
        {
            self.last_seq = Some(s.seq);
            self.last_new_state_ns = now_ns;
        }
        let silent = now_ns.saturating_sub(self.last_new_state_ns);
        if silent > self.config.state_timeout_ns {
            return Err(Failure::StaleState {
                seconds: silent as f64 / NS,
            });
        }
        let Some(state) = state else {
            return Ok(Status::Clear);
        };
        let faults = state.system.fault_flags & !FaultFlags::WARNINGS;
        if faults != 0 {
            return Err(Failure::Fault {
                names: FaultFlags::names(faults).join(", "),
            });
        }
        match state.age_ns(Group::Pose, now_ns) {
            None => return Err(Failure::no_pose(&self.config.name, &self.config.pose_hint)),
            Some(age) if age > self.config.pose_timeout_ns => {
                let flags = LinkFlags::names(state.link_flags);
                return Err(Failure::StalePose {
                    seconds: age as f64 / NS,
                    link: if flags.is_empty() {
                        String::new()
                    } else {
                        format!(" (link: {})", flags.join(", "))
                    },
                });
            }
            Some(_) => {}
        }
        let hold = self.hold(now_ns, state, mux);
        match hold {
            None => {
                self.held_since_ns = None;
                Ok(Status::Clear)
            }
            Some(hold) => {
                let since = *self.held_since_ns.get_or_insert(now_ns);
                let held = now_ns.saturating_sub(since);
                if held > self.config.preempt_timeout_ns {
                    return Err(Failure::HeldTooLong {
                        hold,
                        seconds: held as f64 / NS,
                        timeout_s: self.config.preempt_timeout_ns as f64 / NS,
                    });
                }
                Ok(Status::Held {
                    hold,
                    since_ns: since,
                })
            }
        }
    }

    fn hold(&self, now_ns: u64, state: &ChassisState, mux: Option<&MuxStatus>) -> Option<Hold> {
        if state.has_link_flag(LinkFlags::RC_AUTHORITY) {
            return Some(Hold::RcAuthority);
        }
        // A mux status older than the state timeout says nothing about now.
        let mux =
            mux.filter(|m| now_ns.saturating_sub(m.stamp_ns) <= self.config.state_timeout_ns)?;
        let ours = mux
            .sources()
            .iter()
            .find(|s| s.name() == self.config.source);
        if ours.is_some_and(|s| s.has(SourceFlags::BLOCKED)) {
            return Some(Hold::Locked);
        }
        match mux.active() {
            Some(active) if active.name() != self.config.source => {
                Some(Hold::PreemptedBy(active.name().to_string()))
            }
            Some(_) if mux.clamp_flags & ClampFlags::CHASSIS_NOT_READY != 0 => {
                Some(Hold::ChassisNotReady)
            }
            Some(_) => None,
            None => match mux.zero_reason {
                ZeroReason::REQUIRED_SOURCE_STALE => Some(Hold::RequiredSourceStale),
                ZeroReason::LOCKED => Some(Hold::Locked),
                ZeroReason::HELD | ZeroReason::AWAITING_ZERO => {
                    Some(Hold::Stopped(mux.why().to_string()))
                }
                _ => None,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::Stop;

    const S: u64 = 1_000_000_000;

    fn config() -> WatchConfig {
        WatchConfig {
            name: "bot".into(),
            pose_hint: ": set its track".into(),
            source: "planner".into(),
            preempt_timeout_ns: 2 * S,
            state_timeout_ns: S,
            pose_timeout_ns: S,
        }
    }

    fn state(seq: u64, now: u64) -> ChassisState {
        let mut s = ChassisState {
            seq,
            ..ChassisState::default()
        };
        s.touch(Group::Pose, now);
        s
    }

    fn mux(active: Option<&str>, now: u64) -> MuxStatus {
        let mut m = MuxStatus {
            stamp_ns: now,
            source_count: 3,
            active_source: MuxStatus::NO_SOURCE,
            ..MuxStatus::default()
        };
        for (i, name) in ["safety", "teleop", "planner"].iter().enumerate() {
            m.sources[i].set_name(name);
            if Some(*name) == active {
                m.active_source = u8::try_from(i).unwrap();
            }
        }
        if active.is_none() {
            m.zero_reason = ZeroReason::NO_ACTIVE_SOURCE;
        }
        m
    }

    #[test]
    fn the_planner_is_clear_while_it_wins_the_mux() {
        let mut w = Watch::new(config(), 10 * S);
        let now = 10 * S;
        assert_eq!(
            w.observe(now, Some(&state(1, now)), Some(&mux(Some("planner"), now))),
            Ok(Status::Clear)
        );
        // Before its first request wins nothing is active: not a hold.
        assert_eq!(
            w.observe(now, Some(&state(2, now)), Some(&mux(None, now))),
            Ok(Status::Clear)
        );
    }

    #[test]
    fn teleop_preempts_and_a_preemption_longer_than_the_timeout_fails() {
        let mut w = Watch::new(config(), 0);
        let mut seq = 0;
        let mut at = |w: &mut Watch, t: u64, active: &str| {
            seq += 1;
            w.observe(t, Some(&state(seq, t)), Some(&mux(Some(active), t)))
        };
        assert_eq!(
            at(&mut w, S, "teleop"),
            Ok(Status::Held {
                hold: Hold::PreemptedBy("teleop".into()),
                since_ns: S
            })
        );
        assert!(matches!(
            at(&mut w, 2 * S, "teleop"),
            Ok(Status::Held { .. })
        ));
        // Handed back: the timer starts again.
        assert_eq!(at(&mut w, 2 * S + 1, "planner"), Ok(Status::Clear));
        assert!(matches!(
            at(&mut w, 3 * S, "teleop"),
            Ok(Status::Held { .. })
        ));
        let err = at(&mut w, 5 * S + 1, "teleop").unwrap_err();
        assert!(matches!(err, Failure::HeldTooLong { .. }), "{err}");
        assert!(
            err.to_string().starts_with("preempted by teleop for 2.0 s"),
            "{err}"
        );
    }

    /// A stop after which the mux waits for the planner's zero is a hold: the planner, which
    /// kept asking, gives up after its timeout (its exit sends the zero) rather than driving on
    /// by itself — motion starts only from a zero.
    #[test]
    fn a_wait_for_the_planners_zero_is_a_hold_that_ends_the_run() {
        let mut w = Watch::new(config(), 0);
        let mut m = mux(None, S);
        m.zero_reason = ZeroReason::AWAITING_ZERO;
        m.awaiting_source = 2;
        m.stop = Stop::REQUIRED_SOURCE;
        let held = w.observe(S, Some(&state(1, S)), Some(&m)).unwrap();
        let Status::Held { hold, .. } = held else {
            panic!("{held:?}");
        };
        assert_eq!(
            hold.to_string(),
            "held: stopped: waiting for a zero from planner since the required source came back"
        );
        let late = 3 * S + 1;
        m.stamp_ns = late;
        let err = w
            .observe(late, Some(&state(2, late)), Some(&m))
            .unwrap_err();
        assert!(matches!(err, Failure::HeldTooLong { .. }), "{err}");
    }

    #[test]
    fn a_stale_safety_monitor_and_a_lock_are_holds_too() {
        let mut w = Watch::new(config(), 0);
        let mut m = mux(None, S);
        m.zero_reason = ZeroReason::REQUIRED_SOURCE_STALE;
        let held = w.observe(S, Some(&state(1, S)), Some(&m)).unwrap();
        assert!(matches!(
            held,
            Status::Held {
                hold: Hold::RequiredSourceStale,
                ..
            }
        ));
        let mut m = mux(Some("planner"), S);
        m.sources[2].flags = SourceFlags::BLOCKED;
        let held = w.observe(S, Some(&state(2, S)), Some(&m)).unwrap();
        assert!(matches!(
            held,
            Status::Held {
                hold: Hold::Locked,
                ..
            }
        ));
        let mut s = state(3, S);
        s.link_flags = LinkFlags::RC_AUTHORITY;
        let held = w
            .observe(S, Some(&s), Some(&mux(Some("planner"), S)))
            .unwrap();
        assert!(matches!(
            held,
            Status::Held {
                hold: Hold::RcAuthority,
                ..
            }
        ));
    }

    #[test]
    fn faults_fail_but_warnings_do_not() {
        let mut w = Watch::new(config(), 0);
        let mut s = state(1, S);
        s.system.fault_flags = FaultFlags::BATTERY_LOW | FaultFlags::OVER_TEMPERATURE_WARNING;
        assert!(w.observe(S, Some(&s), None).is_ok());
        s.system.fault_flags |= FaultFlags::MOTOR_DRIVER_ERROR;
        s.seq = 2;
        let err = w.observe(S, Some(&s), None).unwrap_err();
        assert_eq!(err.to_string(), "chassis fault: motor_driver_error");
    }

    #[test]
    fn a_silent_service_a_missing_pose_and_a_stale_pose_fail() {
        let mut w = Watch::new(config(), 0);
        assert!(w.observe(S / 2, Some(&state(1, 0)), None).is_ok());
        // The same sample again and again: the service stopped publishing.
        let err = w.observe(2 * S, Some(&state(1, 0)), None).unwrap_err();
        assert!(matches!(err, Failure::StaleState { .. }), "{err}");

        let mut w = Watch::new(config(), 0);
        let no_pose = ChassisState {
            seq: 1,
            ..ChassisState::default()
        };
        let err = w.observe(0, Some(&no_pose), None).unwrap_err();
        assert!(
            err.to_string().ends_with("path with: set its track"),
            "{err}"
        );

        let mut w = Watch::new(config(), 0);
        let mut old = state(1, S);
        old.link_flags = LinkFlags::CHASSIS_SILENT;
        let err = w.observe(3 * S, Some(&old), None).unwrap_err();
        assert!(err.to_string().contains("chassis_silent"), "{err}");
    }
}
