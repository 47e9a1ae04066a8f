//! `MuxStatus`: every decision of the priority mux, published on change and at 10 Hz.

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

use crate::text::{serialize_fixed_str, write_fixed_str};
use crate::{MAX_LOCKS, MAX_SOURCES, NAME_LEN};

ipc_type! {
    /// The velocity asked of the robot's body, in SI units (the same fields as a
    /// `VelocityRequest`): what the mux was asked and what it commands. Not a ROS `Twist`: it
    /// carries a steering angle and flags too.
    #[derive(Default, Serialize)]
    #[type_name("chassis::BodyVelocity.v1")]
    pub struct BodyVelocity {
        pub linear_x_mps: f32,
        pub linear_y_mps: f32,
        pub angular_z_radps: f32,
        pub steer_rad: f32,
        /// `RequestFlags::STEER` when `steer_rad` is the command instead of `angular_z_radps`.
        pub flags: u32,
    }
}

impl BodyVelocity {
    pub const ZERO: BodyVelocity = BodyVelocity {
        linear_x_mps: 0.0,
        linear_y_mps: 0.0,
        angular_z_radps: 0.0,
        steer_rad: 0.0,
        flags: 0,
    };

    /// True when the command asks for no motion at all.
    pub fn is_zero(&self) -> bool {
        self.linear_x_mps == 0.0
            && self.linear_y_mps == 0.0
            && self.angular_z_radps == 0.0
            && (self.flags & crate::RequestFlags::STEER == 0 || self.steer_rad == 0.0)
    }
}

named_constants! {
    /// Why a command was changed on its way to the wire (`MuxStatus::clamp_flags`,
    /// `CommandEcho::clamp_flags`).
    pub flags ClampFlags: u32 {
        /// Linear speed beyond the robot's limit.
        LINEAR_LIMIT = 1 << 0 => "linear_limit",
        /// Linear speed beyond the robot's limit while steering (TITAN: 1.5 m/s above 0.087 rad).
        LINEAR_LIMIT_STEERING = 1 << 1 => "linear_limit_steering",
        /// Steering angle beyond the robot's limit.
        STEER_LIMIT = 1 << 2 => "steer_limit",
        /// Yaw rate beyond the robot's limit.
        ANGULAR_LIMIT = 1 << 3 => "angular_limit",
        /// Lateral speed requested from a robot that cannot move sideways.
        LATERAL_UNSUPPORTED = 1 << 4 => "lateral_unsupported",
        /// A turn on the spot (ω with v = 0) requested from an Ackermann robot: unachievable.
        TURN_IN_PLACE_UNACHIEVABLE = 1 << 5 => "turn_in_place_unachievable",
        /// The yaw rate asked for needs a tighter turn than the robot can make.
        TURN_RADIUS_LIMIT = 1 << 6 => "turn_radius_limit",
        /// Speed change limited by the configured acceleration (smoothing).
        ACCELERATION_LIMIT = 1 << 7 => "acceleration_limit",
        /// Speed beyond the service's configured limit.
        CONFIG_SPEED_LIMIT = 1 << 8 => "config_speed_limit",
        /// The wire's resolution changed the value (SCOUT MINI percent steps).
        QUANTISED = 1 << 9 => "quantised",
        /// The chassis cannot move now (TITAN: the parking brake held; XBot: drive power off;
        /// SCOUT MINI V1: not in command mode): zero was sent.
        CHASSIS_NOT_READY = 1 << 10 => "chassis_not_ready",
        /// A limiting source (the safety monitor) clamped the winner's request.
        SAFETY_LIMIT = 1 << 11 => "safety_limit",
        /// The robot's standing speed limit ([`MuxStatus::speed_limit_mps`]) capped the speed.
        SPEED_LIMIT = 1 << 12 => "speed_limit",
    }
}

named_constants! {
    /// Why the mux outputs zero (`MuxStatus::zero_reason`).
    pub enum ZeroReason: u8 {
        /// A source is active; the output is its (limited) request.
        NONE = 0 => "none",
        /// No source has a fresh request.
        NO_ACTIVE_SOURCE = 1 => "no_active_source",
        /// A required source (the safety monitor) is stale: fail-safe zero.
        REQUIRED_SOURCE_STALE = 2 => "required_source_stale",
        /// A lock blocks every fresh source.
        LOCKED = 3 => "locked",
        /// The mux has not started yet.
        STARTING = 4 => "starting",
        /// A stop ended ([`MuxStatus::stop`] names which) while the source that would win asked
        /// for motion: motion starts only from a zero, so the mux waits until that source asks
        /// for zero; [`MuxStatus::awaiting_source`] names it.
        AWAITING_ZERO = 5 => "awaiting_zero",
        /// The bus or the chassis stops the robot ([`MuxStatus::stop`] names which): nothing is
        /// obeyed until it ends, and then only from a zero.
        HELD = 6 => "held",
    }
}

named_constants! {
    /// A stop the winning source did not ask for itself (`MuxStatus::stop`). When it ends, the
    /// robot moves again only once the source that would win has sent a zero since: silence, a
    /// timeout or another source's zero is not a zero (ISO 13850 and IEC 60204-1: a reset shall
    /// not start motion; ISO 3691-4: no automatic restart after a stop or a power interruption).
    pub enum Stop: u8 {
        /// No stop is in force or waited on.
        NONE = 0 => "none",
        /// chassisd started: a source that kept asking through a restart is not obeyed until it
        /// asks for zero (a client process that starts sends one zero as it connects).
        SERVICE_START = 1 => "service_start",
        /// A lock (the e-stop, a latch restored after a restart) was released.
        LOCK_RELEASED = 2 => "lock_released",
        /// The required source (the safety monitor) was silent and speaks again.
        REQUIRED_SOURCE = 3 => "required_source",
        /// The bus was lost (an adapter unplugged, an interface down) or the CAN controller
        /// went bus-off.
        BUS = 4 => "bus",
        /// The chassis reports its own E-stop switch.
        CHASSIS_ESTOP = 5 => "chassis_estop",
        /// A remote-control transmitter has the chassis.
        REMOTE_CONTROL = 6 => "remote_control",
        /// The chassis reports a fault that stops its drive (motor driver, over-current, …).
        CHASSIS_FAULT = 7 => "chassis_fault",
    }
}

named_constants! {
    /// Bits of [`SourceStatus::flags`].
    pub flags SourceFlags: u8 {
        /// The source must be fresh for anything to move.
        REQUIRED = 1 << 0 => "required",
        /// Its latest request is younger than its timeout.
        FRESH = 1 << 1 => "fresh",
        /// It is the mux's winner.
        ACTIVE = 1 << 2 => "active",
        /// Its latest request is a heartbeat (asks for nothing).
        HEARTBEAT = 1 << 3 => "heartbeat",
        /// A lock of higher priority blocks it.
        BLOCKED = 1 << 4 => "blocked",
        /// Its latest request is a speed envelope that currently limits the output.
        LIMITING = 1 << 5 => "limiting",
        /// Configured `remote`: a bridge (`chassis-zenoh`) may publish on it for another computer.
        REMOTE = 1 << 6 => "remote",
        /// A stop ended while its last word was motion: its motion is not obeyed until it asks
        /// for zero (silence is not a zero).
        AWAITING_ZERO = 1 << 7 => "awaiting_zero",
    }
}

ipc_type! {
    /// One configured velocity source, as the mux sees it.
    #[derive(Default, Serialize)]
    #[type_name("chassis::SourceStatus.v1")]
    pub struct SourceStatus {
        /// Source name (NUL-padded UTF-8), e.g. `teleop`.
        #[serde(serialize_with = "serialize_fixed_str")]
        pub name: [u8; NAME_LEN] as text,
        pub timeout_ms: u32,
        /// Age of its latest request, ms; `u32::MAX` when it has never sent one.
        pub age_ms: u32,
        /// Requests rejected (non-finite values).
        pub rejected: u32,
        pub priority: u8,
        /// [`SourceFlags`].
        pub flags: u8,
        #[serde(skip)]
        pub _reserved: [u8; 2],
        /// `seq` of its latest request.
        pub last_seq: u64,
    }
}

impl SourceStatus {
    pub fn set_name(&mut self, name: &str) {
        write_fixed_str(&mut self.name, name);
    }
    pub fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }
    /// The age of its latest request as read: `never` or `N ms`.
    pub fn age_text(&self) -> String {
        if self.age_ms == u32::MAX {
            "never".into()
        } else {
            format!("{} ms", self.age_ms)
        }
    }
}

ipc_type! {
    /// One configured lock.
    #[derive(Default, Serialize)]
    #[type_name("chassis::LockStatus.v1")]
    pub struct LockStatus {
        /// Lock name (NUL-padded UTF-8), e.g. `estop`.
        #[serde(serialize_with = "serialize_fixed_str")]
        pub name: [u8; NAME_LEN] as text,
        /// `CLOCK_MONOTONIC` time it was engaged, ns (0 when free).
        pub since_ns: u64,
        /// Sources below this priority are blocked while the lock is held.
        pub priority: u8,
        /// 1 while held.
        pub held: u8,
        /// Index of the holding source, [`LockStatus::HOLDER_OPERATOR`] for a control request, or
        /// [`LockStatus::HOLDER_NONE`].
        pub holder: u8,
        /// [`StopCategory`] of the stop while held (the one its engage asked for); while free,
        /// the lock's configured category.
        pub category: u8,
        #[serde(skip)]
        pub _reserved: [u8; 4],
    }
}

impl LockStatus {
    pub const HOLDER_NONE: u8 = 0xFF;
    pub const HOLDER_OPERATOR: u8 = 0xFE;

    pub fn set_name(&mut self, name: &str) {
        write_fixed_str(&mut self.name, name);
    }

    /// Asked for but not held: an operator's engage that the robot has not answered yet, kept
    /// asked by the fleet's mirror (`chassis-zenoh`) until it is delivered. Shown as the lock not
    /// held (`held` 0, the robot's truth) with the operator as its holder; chassisd itself
    /// publishes a free lock with [`LockStatus::HOLDER_NONE`], so only a mirror says this.
    pub fn is_pending(&self) -> bool {
        self.held == 0 && self.holder == Self::HOLDER_OPERATOR
    }

    /// Marks a lock that is not held as pending (see [`LockStatus::is_pending`]); a held lock
    /// stays as it is.
    pub fn mark_pending(&mut self) {
        if self.held == 0 {
            self.holder = Self::HOLDER_OPERATOR;
        }
    }
}

ipc_type! {
    /// The mux's decision.
    #[derive(Default, Serialize)]
    #[type_name("chassis::MuxStatus.v3")]
    pub struct MuxStatus {
        /// `CLOCK_MONOTONIC` time of the decision, ns.
        pub stamp_ns: u64,
        pub seq: u64,
        /// The winner's request as received (zero when nothing is active).
        pub requested: BodyVelocity,
        /// What the mux passed to the driver after limits and smoothing.
        pub output: BodyVelocity,
        /// [`ClampFlags`] the mux applied.
        pub clamp_flags: u32,
        /// Age of the winner's request, ms (`u32::MAX` when nothing is active).
        pub active_age_ms: u32,
        /// Requests rejected by the mux since start (non-finite values, unknown locks).
        pub rejected_requests: u64,
        /// Index into `sources` of the winner, or [`MuxStatus::NO_SOURCE`].
        pub active_source: u8,
        pub active_priority: u8,
        /// [`ZeroReason`].
        pub zero_reason: u8,
        pub source_count: u8,
        pub lock_count: u8,
        /// While `zero_reason` is [`ZeroReason::AWAITING_ZERO`]: index into `sources` of the source
        /// whose zero command the mux waits for (it would win).
        pub awaiting_source: u8,
        /// [`Stop`]: while `zero_reason` is [`ZeroReason::HELD`], the stop in force; while it is
        /// [`ZeroReason::AWAITING_ZERO`], the stop whose end waits for the zero.
        pub stop: u8,
        /// Who set the standing speed limit: an index into `sources` or
        /// [`LockStatus::HOLDER_OPERATOR`] ([`LockStatus::HOLDER_NONE`] while there is none).
        pub speed_limit_holder: u8,
        /// The standing speed limit every source is capped to, m/s; 0 while there is none. Any
        /// source may lower it; only the operator raises it.
        pub speed_limit_mps: f32,
        /// [`DriveState`]: the drive as the stops of categories 0 and 1 left it.
        pub drive: u8,
        #[serde(skip)]
        pub _reserved: [u8; 3],
        pub sources: [SourceStatus; MAX_SOURCES],
        pub locks: [LockStatus; MAX_LOCKS],
    }
}

impl MuxStatus {
    pub const NO_SOURCE: u8 = 0xFF;

    /// The configured sources.
    pub fn sources(&self) -> &[SourceStatus] {
        &self.sources[..usize::from(self.source_count).min(MAX_SOURCES)]
    }

    /// The configured locks.
    pub fn locks(&self) -> &[LockStatus] {
        &self.locks[..usize::from(self.lock_count).min(MAX_LOCKS)]
    }

    /// The winning source, if any.
    pub fn active(&self) -> Option<&SourceStatus> {
        self.sources().get(usize::from(self.active_source))
    }

    /// The source whose zero command the mux waits for after a stop, if it waits.
    pub fn awaiting(&self) -> Option<&SourceStatus> {
        if self.zero_reason != ZeroReason::AWAITING_ZERO {
            return None;
        }
        self.sources().get(usize::from(self.awaiting_source))
    }

    /// The standing speed limit, m/s, and the name of who set it (a source or `operator`).
    pub fn speed_limit(&self) -> Option<(f32, &str)> {
        if self.speed_limit_mps <= 0.0 {
            return None;
        }
        let holder = match self.speed_limit_holder {
            LockStatus::HOLDER_OPERATOR => "operator",
            index => self
                .sources()
                .get(usize::from(index))
                .map_or("?", SourceStatus::name),
        };
        Some((self.speed_limit_mps, holder))
    }

    /// Index of the lock called `name`.
    pub fn lock_index(&self, name: &str) -> Option<usize> {
        self.locks().iter().position(|l| l.name() == name)
    }

    /// Why the robot moves or stands, in words every view shows the same way: `driving from
    /// teleop`, `stopped: waiting for a zero from teleop since the bus came back · held: estop`.
    pub fn why(&self) -> Why<'_> {
        Why(self)
    }
}

/// The one explanation of a mux decision ([`MuxStatus::why`]), rendered by `Display`.
#[derive(Debug, Clone, Copy)]
pub struct Why<'a>(&'a MuxStatus);

named_constants! {
    /// The stop categories of IEC 60204-1, as a held lock stops the robot
    /// ([`LockStatus::category`]). Every other stop (a source's own zero, a stale required
    /// source, the bus and the chassis' holds) commands zero and leaves the drive powered.
    pub enum StopCategory: u8 {
        /// The drive disabled at once (AgileX: standby, and the parking brake where fitted;
        /// XBot: drive power off). A robot with no way to disable its drive stops as
        /// [`StopCategory::HOLD`] and says so ([`DriveState::CANNOT_CUT`]).
        CUT = 0 => "cut",
        /// Zero commanded (the chassis brakes under control), then the drive disabled once the
        /// chassis reports standstill, or after 3 s at the latest (chassisd's `engine/drive.rs`).
        BRAKE_THEN_CUT = 1 => "brake_then_cut",
        /// Zero commanded and held with the drive powered.
        HOLD = 2 => "hold",
    }
}

impl StopCategory {
    /// `0 (cut the drive at once)`, for views.
    pub fn text(category: u8) -> String {
        let what = match category {
            StopCategory::CUT => "cut the drive at once",
            StopCategory::BRAKE_THEN_CUT => "brake, then cut the drive",
            StopCategory::HOLD => "brake and hold",
            _ => "unknown",
        };
        format!("{category} ({what})")
    }
}

named_constants! {
    /// The drive as the stops of categories 0 and 1 leave it (`MuxStatus::drive`).
    pub enum DriveState: u8 {
        /// Powered and obeying the command: no stop of category 0 or 1 is in force.
        ENABLED = 0 => "enabled",
        /// A category-1 stop waits for the chassis' standstill before it disables the drive.
        BRAKING = 1 => "braking",
        /// Disabled by a stop of category 0 or 1; enabled again when that stop is released.
        CUT = 2 => "cut",
        /// A stop of category 0 or 1 is in force, but this robot has no way to disable its drive:
        /// zero is commanded and held (category 2).
        CANNOT_CUT = 3 => "cannot_cut",
    }
}

impl Stop {
    /// What holds the robot while `stop` is in force (`ZeroReason::HELD`).
    pub fn holding(stop: u8) -> &'static str {
        match stop {
            Stop::BUS => "the bus is lost or bus-off",
            Stop::CHASSIS_ESTOP => "the chassis' E-stop is pressed",
            Stop::REMOTE_CONTROL => "a remote-control transmitter has the chassis",
            Stop::CHASSIS_FAULT => "the chassis reports a drive fault",
            _ => "held",
        }
    }

    /// What ended when a source waits for its zero since `stop` (`ZeroReason::AWAITING_ZERO`).
    pub fn ended(stop: u8) -> &'static str {
        match stop {
            Stop::SERVICE_START => "chassisd started",
            Stop::LOCK_RELEASED => "a lock was released",
            Stop::REQUIRED_SOURCE => "the required source came back",
            Stop::BUS => "the bus came back",
            Stop::CHASSIS_ESTOP => "the chassis' E-stop was released",
            Stop::REMOTE_CONTROL => "remote control handed the chassis back",
            Stop::CHASSIS_FAULT => "the chassis' fault cleared",
            _ => "a stop",
        }
    }
}

impl std::fmt::Display for Why<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = self.0;
        match (m.active(), m.zero_reason) {
            (Some(source), _) => write!(f, "driving from {}", source.name())?,
            (None, ZeroReason::AWAITING_ZERO) => write!(
                f,
                "stopped: waiting for a zero from {} since {}",
                m.awaiting().map_or("?", SourceStatus::name),
                Stop::ended(m.stop)
            )?,
            (None, ZeroReason::HELD) => write!(f, "stopped: {}", Stop::holding(m.stop))?,
            (None, ZeroReason::REQUIRED_SOURCE_STALE) => {
                let silent: Vec<&str> = m
                    .sources()
                    .iter()
                    .filter(|s| s.has(SourceFlags::REQUIRED) && !s.has(SourceFlags::FRESH))
                    .map(SourceStatus::name)
                    .collect();
                match silent.as_slice() {
                    [] => write!(f, "stopped: the required source is silent")?,
                    names => write!(f, "stopped: required source {} silent", names.join(", "))?,
                }
            }
            (None, reason) => write!(f, "stopped: {}", ZeroReason::name(reason).replace('_', " "))?,
        }
        let held: Vec<String> = m
            .locks()
            .iter()
            .filter(|l| l.held == 1)
            .map(|l| format!("{} (category {})", l.name(), l.category))
            .collect();
        if !held.is_empty() {
            write!(f, " · held: {}", held.join(", "))?;
        }
        if m.active().is_none() && !m.output.is_zero() {
            write!(f, " · braking to zero")?;
        }
        if m.active().is_some() && m.clamp_flags & ClampFlags::CHASSIS_NOT_READY != 0 {
            write!(f, " · the chassis cannot move now: zero sent")?;
        }
        match m.drive {
            DriveState::BRAKING => write!(f, " · braking, then the drive is cut")?,
            DriveState::CUT => write!(f, " · drive cut")?,
            DriveState::CANNOT_CUT => {
                write!(
                    f,
                    " · this robot cannot cut its drive: zero is held instead"
                )?;
            }
            _ => {}
        }
        if let Some((mps, holder)) = m.speed_limit() {
            write!(f, " · limited to {mps} m/s by {holder}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_never_heard_reads_never_and_a_heard_one_its_age() {
        let mut source = SourceStatus {
            age_ms: u32::MAX,
            ..SourceStatus::default()
        };
        assert_eq!(source.age_text(), "never");
        source.age_ms = 42;
        assert_eq!(source.age_text(), "42 ms");
    }

    #[test]
    fn mux_status_names_its_sources_and_locks() {
        let mut status = MuxStatus {
            source_count: 2,
            lock_count: 1,
            active_source: 1,
            ..MuxStatus::default()
        };
        status.sources[0].set_name("safety");
        status.sources[1].set_name("teleop");
        status.locks[0].set_name("estop");
        assert_eq!(status.active().map(SourceStatus::name), Some("teleop"));
        assert_eq!(status.lock_index("estop"), Some(0));
        assert_eq!(status.lock_index("other"), None);
        let json = serde_json::to_value(status).unwrap();
        assert_eq!(json["sources"][0]["name"], "safety");
        assert_eq!(json["locks"][0]["name"], "estop");
    }

    #[test]
    fn the_explanation_names_the_stop_and_the_source_it_waits_for() {
        let mut status = MuxStatus {
            source_count: 2,
            lock_count: 1,
            active_source: MuxStatus::NO_SOURCE,
            zero_reason: ZeroReason::AWAITING_ZERO,
            awaiting_source: 1,
            stop: Stop::BUS,
            ..MuxStatus::default()
        };
        status.sources[0].set_name("safety");
        status.sources[0].flags = SourceFlags::REQUIRED;
        status.sources[1].set_name("teleop");
        status.locks[0].set_name("estop");
        assert_eq!(
            status.why().to_string(),
            "stopped: waiting for a zero from teleop since the bus came back"
        );
        status.zero_reason = ZeroReason::HELD;
        status.stop = Stop::CHASSIS_ESTOP;
        status.locks[0].held = 1;
        status.locks[0].category = StopCategory::BRAKE_THEN_CUT;
        status.drive = DriveState::BRAKING;
        assert_eq!(
            status.why().to_string(),
            "stopped: the chassis' E-stop is pressed · held: estop (category 1) · braking, then \
             the drive is cut"
        );
        status.drive = DriveState::CUT;
        assert!(
            status
                .why()
                .to_string()
                .ends_with("(category 1) · drive cut")
        );
        status.drive = DriveState::ENABLED;
        status.zero_reason = ZeroReason::REQUIRED_SOURCE_STALE;
        assert_eq!(
            status.why().to_string(),
            "stopped: required source safety silent · held: estop (category 1)"
        );
        status.active_source = 1;
        assert_eq!(
            status.why().to_string(),
            "driving from teleop · held: estop (category 1)"
        );
        status.speed_limit_holder = 1;
        status.speed_limit_mps = 0.5;
        assert_eq!(
            status.why().to_string(),
            "driving from teleop · held: estop (category 1) · limited to 0.5 m/s by teleop"
        );
        status.speed_limit_holder = LockStatus::HOLDER_OPERATOR;
        assert_eq!(status.speed_limit(), Some((0.5, "operator")));
        status.active_source = MuxStatus::NO_SOURCE;
        status.zero_reason = ZeroReason::LOCKED;
        status.output.linear_x_mps = 0.4;
        assert!(
            status
                .why()
                .to_string()
                .contains("stopped: locked · held: estop (category 1) · braking to zero"),
            "{}",
            status.why()
        );
        status.output = BodyVelocity::ZERO;
        status.active_source = 1;
        status.clamp_flags = ClampFlags::CHASSIS_NOT_READY;
        assert!(
            status
                .why()
                .to_string()
                .contains("· the chassis cannot move now: zero sent"),
            "{}",
            status.why()
        );
    }

    #[test]
    fn a_steer_command_with_zero_speed_but_an_angle_is_not_zero() {
        let mut t = BodyVelocity::ZERO;
        assert!(t.is_zero());
        t.steer_rad = 0.2;
        assert!(t.is_zero(), "steer ignored without the STEER flag");
        t.flags = crate::RequestFlags::STEER;
        assert!(!t.is_zero());
    }
}
