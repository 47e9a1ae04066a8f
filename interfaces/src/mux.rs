//! `MuxStatus`: every decision of the priority mux, published on change and at 10 Hz.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::layout::describe_layout;

use crate::text::{read_fixed_str, serialize_fixed_str, write_fixed_str};
use crate::{MAX_LOCKS, MAX_SOURCES, NAME_LEN};

/// The velocity asked of the robot's body, in SI units (the same fields as a
/// `VelocityRequest`): what the mux was asked and what it commands. Not a ROS `Twist`: it
/// carries a steering angle and flags too.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    FromBytes,
    IntoBytes,
    Immutable,
    KnownLayout,
    ZeroCopySend,
    Serialize,
)]
#[type_name("chassis::BodyVelocity.v1")]
pub struct BodyVelocity {
    pub linear_x_mps: f32,
    pub linear_y_mps: f32,
    pub angular_z_radps: f32,
    pub steer_rad: f32,
    /// `RequestFlags::STEER` when `steer_rad` is the command instead of `angular_z_radps`.
    pub flags: u32,
}

describe_layout!(
    BodyVelocity,
    twist_description_covers_every_byte {
        linear_x_mps,
        linear_y_mps,
        angular_z_radps,
        steer_rad,
        flags,
    }
);

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

/// Why a command was changed on its way to the wire (`MuxStatus::clamp_flags`,
/// `CommandEcho::clamp_flags`).
#[derive(Debug, Clone, Copy)]
pub struct ClampFlags;
impl ClampFlags {
    /// Linear speed beyond the robot's limit.
    pub const LINEAR_LIMIT: u32 = 1 << 0;
    /// Linear speed beyond the robot's limit while steering (TITAN: 1.5 m/s above 0.087 rad).
    pub const LINEAR_LIMIT_STEERING: u32 = 1 << 1;
    /// Steering angle beyond the robot's limit.
    pub const STEER_LIMIT: u32 = 1 << 2;
    /// Yaw rate beyond the robot's limit.
    pub const ANGULAR_LIMIT: u32 = 1 << 3;
    /// Lateral speed requested from a robot that cannot move sideways.
    pub const LATERAL_UNSUPPORTED: u32 = 1 << 4;
    /// A turn on the spot (ω with v = 0) requested from an Ackermann robot: unachievable.
    pub const TURN_IN_PLACE_UNACHIEVABLE: u32 = 1 << 5;
    /// The yaw rate asked for needs a tighter turn than the robot can make.
    pub const TURN_RADIUS_LIMIT: u32 = 1 << 6;
    /// Speed change limited by the configured acceleration (smoothing).
    pub const ACCELERATION_LIMIT: u32 = 1 << 7;
    /// Speed beyond the service's configured limit.
    pub const CONFIG_SPEED_LIMIT: u32 = 1 << 8;
    /// The wire's resolution changed the value (SCOUT MINI percent steps).
    pub const QUANTISED: u32 = 1 << 9;
    /// The chassis cannot move now (standby, brake, RC authority, fault): zero was sent.
    pub const CHASSIS_NOT_READY: u32 = 1 << 10;
    /// A limiting source (the safety monitor) clamped the winner's request.
    pub const SAFETY_LIMIT: u32 = 1 << 11;

    pub const ALL: [(u32, &'static str); 12] = [
        (Self::LINEAR_LIMIT, "linear_limit"),
        (Self::LINEAR_LIMIT_STEERING, "linear_limit_steering"),
        (Self::STEER_LIMIT, "steer_limit"),
        (Self::ANGULAR_LIMIT, "angular_limit"),
        (Self::LATERAL_UNSUPPORTED, "lateral_unsupported"),
        (
            Self::TURN_IN_PLACE_UNACHIEVABLE,
            "turn_in_place_unachievable",
        ),
        (Self::TURN_RADIUS_LIMIT, "turn_radius_limit"),
        (Self::ACCELERATION_LIMIT, "acceleration_limit"),
        (Self::CONFIG_SPEED_LIMIT, "config_speed_limit"),
        (Self::QUANTISED, "quantised"),
        (Self::CHASSIS_NOT_READY, "chassis_not_ready"),
        (Self::SAFETY_LIMIT, "safety_limit"),
    ];

    pub fn names(bits: u32) -> Vec<&'static str> {
        Self::ALL
            .iter()
            .filter(|(bit, _)| bits & bit != 0)
            .map(|(_, name)| *name)
            .collect()
    }
}

/// Why the mux outputs zero (`MuxStatus::zero_reason`).
#[derive(Debug, Clone, Copy)]
pub struct ZeroReason;
impl ZeroReason {
    /// A source is active; the output is its (limited) request.
    pub const NONE: u8 = 0;
    /// No source has a fresh request.
    pub const NO_ACTIVE_SOURCE: u8 = 1;
    /// A required source (the safety monitor) is stale: fail-safe zero.
    pub const REQUIRED_SOURCE_STALE: u8 = 2;
    /// A lock blocks every fresh source.
    pub const LOCKED: u8 = 3;
    /// The mux has not started yet.
    pub const STARTING: u8 = 4;
    /// A lock was released while the source that would win asked for motion: a release never
    /// starts motion, so the mux waits until that source asks for zero (or stops asking);
    /// [`MuxStatus::awaiting_source`] names it.
    pub const AWAITING_ZERO: u8 = 5;

    pub fn name(reason: u8) -> &'static str {
        match reason {
            Self::NONE => "none",
            Self::NO_ACTIVE_SOURCE => "no_active_source",
            Self::REQUIRED_SOURCE_STALE => "required_source_stale",
            Self::LOCKED => "locked",
            Self::STARTING => "starting",
            Self::AWAITING_ZERO => "awaiting_zero",
            _ => "unknown",
        }
    }
}

/// Bits of [`SourceStatus::flags`].
#[derive(Debug, Clone, Copy)]
pub struct SourceFlags;
impl SourceFlags {
    /// The source must be fresh for anything to move.
    pub const REQUIRED: u8 = 1 << 0;
    /// Its latest request is younger than its timeout.
    pub const FRESH: u8 = 1 << 1;
    /// It is the mux's winner.
    pub const ACTIVE: u8 = 1 << 2;
    /// Its latest request is a heartbeat (asks for nothing).
    pub const HEARTBEAT: u8 = 1 << 3;
    /// A lock of higher priority blocks it.
    pub const BLOCKED: u8 = 1 << 4;
    /// Its latest request is a speed envelope that currently limits the output.
    pub const LIMITING: u8 = 1 << 5;
    /// Configured `remote`: a bridge (`chassis-zenoh`) may publish on it for another computer.
    pub const REMOTE: u8 = 1 << 6;
    /// It asked for motion when a lock blocking it was released: its motion is not obeyed until
    /// it asks for zero (or stops asking).
    pub const AWAITING_ZERO: u8 = 1 << 7;
}

/// One configured velocity source, as the mux sees it.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    FromBytes,
    IntoBytes,
    Immutable,
    KnownLayout,
    ZeroCopySend,
    Serialize,
)]
#[type_name("chassis::SourceStatus.v1")]
pub struct SourceStatus {
    /// Source name (NUL-padded UTF-8), e.g. `teleop`.
    #[serde(serialize_with = "serialize_fixed_str")]
    pub name: [u8; NAME_LEN],
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

describe_layout!(
    SourceStatus,
    source_status_description_covers_every_byte {
        name,
        timeout_ms,
        age_ms,
        rejected,
        priority,
        flags,
        _reserved,
        last_seq,
    }
);

impl SourceStatus {
    pub fn name(&self) -> &str {
        read_fixed_str(&self.name)
    }
    pub fn set_name(&mut self, name: &str) {
        write_fixed_str(&mut self.name, name);
    }
    pub fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }
}

/// One configured lock.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    FromBytes,
    IntoBytes,
    Immutable,
    KnownLayout,
    ZeroCopySend,
    Serialize,
)]
#[type_name("chassis::LockStatus.v1")]
pub struct LockStatus {
    /// Lock name (NUL-padded UTF-8), e.g. `estop`.
    #[serde(serialize_with = "serialize_fixed_str")]
    pub name: [u8; NAME_LEN],
    /// `CLOCK_MONOTONIC` time it was engaged, ns (0 when free).
    pub since_ns: u64,
    /// Sources below this priority are blocked while the lock is held.
    pub priority: u8,
    /// 1 while held.
    pub held: u8,
    /// Index of the holding source, [`LockStatus::HOLDER_OPERATOR`] for a control request, or
    /// [`LockStatus::HOLDER_NONE`].
    pub holder: u8,
    #[serde(skip)]
    pub _reserved: [u8; 5],
}

describe_layout!(
    LockStatus,
    lock_status_description_covers_every_byte {
        name,
        since_ns,
        priority,
        held,
        holder,
        _reserved,
    }
);

impl LockStatus {
    pub const HOLDER_NONE: u8 = 0xFF;
    pub const HOLDER_OPERATOR: u8 = 0xFE;

    pub fn name(&self) -> &str {
        read_fixed_str(&self.name)
    }
    pub fn set_name(&mut self, name: &str) {
        write_fixed_str(&mut self.name, name);
    }
}

/// The mux's decision.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Default,
    FromBytes,
    IntoBytes,
    Immutable,
    KnownLayout,
    ZeroCopySend,
    Serialize,
)]
#[type_name("chassis::MuxStatus.v1")]
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
    /// whose zero command the mux waits for (it would win). Was a reserved byte.
    pub awaiting_source: u8,
    #[serde(skip)]
    pub _reserved: [u8; 2],
    pub sources: [SourceStatus; MAX_SOURCES],
    pub locks: [LockStatus; MAX_LOCKS],
}

describe_layout!(
    MuxStatus,
    mux_status_description_covers_every_byte {
        stamp_ns,
        seq,
        requested,
        output,
        clamp_flags,
        active_age_ms,
        rejected_requests,
        active_source,
        active_priority,
        zero_reason,
        source_count,
        lock_count,
        awaiting_source,
        _reserved,
        sources,
        locks,
    }
);

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

    /// The source whose zero command the mux waits for after a release, if it waits.
    pub fn awaiting(&self) -> Option<&SourceStatus> {
        if self.zero_reason != ZeroReason::AWAITING_ZERO {
            return None;
        }
        self.sources().get(usize::from(self.awaiting_source))
    }

    /// Index of the lock called `name`.
    pub fn lock_index(&self, name: &str) -> Option<usize> {
        self.locks().iter().position(|l| l.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn mux_status_layout_is_pinned() {
        assert_eq!(
            (size_of::<BodyVelocity>(), align_of::<BodyVelocity>()),
            (20, 4)
        );
        assert_eq!(offset_of!(BodyVelocity, flags), 16);
        assert_eq!(
            (size_of::<SourceStatus>(), align_of::<SourceStatus>()),
            (40, 8)
        );
        assert_eq!(offset_of!(SourceStatus, timeout_ms), 16);
        assert_eq!(offset_of!(SourceStatus, priority), 28);
        assert_eq!(offset_of!(SourceStatus, last_seq), 32);
        assert_eq!((size_of::<LockStatus>(), align_of::<LockStatus>()), (32, 8));
        assert_eq!(offset_of!(LockStatus, since_ns), 16);
        assert_eq!(offset_of!(LockStatus, holder), 26);
        assert_eq!(size_of::<MuxStatus>(), 528);
        assert_eq!(align_of::<MuxStatus>(), 8);
        assert_eq!(offset_of!(MuxStatus, requested), 16);
        assert_eq!(offset_of!(MuxStatus, output), 36);
        assert_eq!(offset_of!(MuxStatus, clamp_flags), 56);
        assert_eq!(offset_of!(MuxStatus, active_age_ms), 60);
        assert_eq!(offset_of!(MuxStatus, rejected_requests), 64);
        assert_eq!(offset_of!(MuxStatus, active_source), 72);
        assert_eq!(offset_of!(MuxStatus, lock_count), 76);
        assert_eq!(offset_of!(MuxStatus, sources), 80);
        assert_eq!(offset_of!(MuxStatus, locks), 400);
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
    fn a_steer_command_with_zero_speed_but_an_angle_is_not_zero() {
        let mut t = BodyVelocity::ZERO;
        assert!(t.is_zero());
        t.steer_rad = 0.2;
        assert!(t.is_zero(), "steer ignored without the STEER flag");
        t.flags = crate::RequestFlags::STEER;
        assert!(!t.is_zero());
    }
}
