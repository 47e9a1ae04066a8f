//! Fixed-layout types shared by `chassisd` and every client process.
//!
//! Every type here crosses a process boundary through iceoryx2 shared memory, so each one is
//! `#[repr(C)]`, holds no pointer and no heap memory, uses fixed-width integers and floats only
//! (enumerations are a `u8` plus named constants), and names its unit in every field name
//! (`linear_mps`, `steer_rad`, `voltage_v`, `stamp_ns`). The iceoryx2 type name carries a layout
//! version (`"chassis::ChassisState.v4"`): iceoryx2 itself compares only name, size and alignment,
//! so any layout change must bump the version. The committed contract (`interfaces/contract.json`)
//! pins every type's size, alignment and field offsets, and a test compares the code with it, so
//! such a change is always deliberate.
//!
//! Each type also describes itself field by field ([`layout::Layout`]): the machine-readable
//! contract (`chassis interfaces --json`) that programs in other languages mirror.
//!
//! Beside them, and never in shared memory: [`ValidRequest`] and [`Velocity`], a velocity request
//! parsed where it enters a process into types that cannot hold a NaN or an infinity, which the
//! mux and the drivers take.
//!
//! Axes follow ISO 8855 / REP 103 for every robot: x forward, y left, z up, counter-clockwise
//! (left turn) positive. Timestamps are `CLOCK_MONOTONIC` nanoseconds, system-wide, so a reader in
//! another process can compute one-way latencies without clock synchronisation.

mod control;
mod description;
mod frame;
pub mod layout;
mod mux;
mod named;
mod names;
pub mod payload;
mod request;
mod safety;
mod state;
mod text;
mod velocity;

pub use control::{
    ControlKind, ControlRequest, ControlResponse, ControlStatus, FaultClear, LightMode, SimKind,
    SimRequest, SimTruthPage,
};
pub use description::{
    BatteryLevels, BusKind, DescriptionFlags, DescriptionFull, Geometry, JointDescription,
    JointSource, Kinematics, LABEL_LEN, MAX_JOINTS, MAX_SENSORS, MotionLimits, OdometryVariance,
    RobotDescription, SensorDescription, SensorKind, SourceDescription,
};
pub use frame::{BusFrame, FrameDirection, FrameKind};
pub use mux::{
    BodyVelocity, ClampFlags, DriveState, LockStatus, MuxStatus, SourceFlags, SourceStatus, Stop,
    StopCategory, ZeroReason,
};
pub use names::valid_robot_name;
pub use request::{RequestFlags, VelocityRequest};
pub use safety::{
    EstopState, RULE_SLOTS, SafetyAction, SafetyEvent, SafetyRule, SafetyStatus, Unfollowed,
};
pub use state::{
    BmsState, ChassisState, CommandEcho, ControlMode, ControllerState, DriverStatus, FaultFlags,
    GROUP_SLOTS, GpsFix, Group, ImuState, LiftState, LightsState, LinkFlags, LinkStats,
    MotionState, MotorState, OdometryState, PanTiltState, RangesState, RcState, SystemState,
    WireProtocol, wrap_angle,
};
pub use text::{read_fixed_str, write_fixed_str};
pub use velocity::{Envelope, InvalidVelocity, ValidRequest, Velocity};

/// Size of a fixed-length, NUL-padded UTF-8 name (source and lock names).
pub const NAME_LEN: usize = 16;
/// Most velocity sources a mux can be configured with.
pub const MAX_SOURCES: usize = 8;
/// Most locks a mux can be configured with.
pub const MAX_LOCKS: usize = 4;
