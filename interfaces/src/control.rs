//! The control request/response pair (iceoryx2 request-response service `control`).

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::layout::describe_layout;

use crate::NAME_LEN;
use crate::text::{read_fixed_str, serialize_fixed_str, write_fixed_str};

/// [`ControlRequest::kind`] and the meaning of its arguments.
#[derive(Debug, Clone, Copy)]
pub struct ControlKind;
impl ControlKind {
    /// `arg[0]`: `ControlMode::COMMAND` (take control) or `ControlMode::STANDBY` (let go).
    pub const MODE: u8 = 1;
    /// `arg[0]`: 1 engage the parking brake, 0 release it.
    pub const BRAKE: u8 = 2;
    /// `arg[0]`: a [`FaultClear`] code.
    pub const CLEAR_FAULTS: u8 = 3;
    /// `arg[0]`: [`LightMode`] of the front light, `arg[1]`: custom brightness %, `arg[2]`: 1 to
    /// enable light control, 0 to hand the lights back to the chassis.
    pub const LIGHTS: u8 = 4;
    /// `arg[0]`: 1 enter off-road mode, 0 leave it (refused while moving).
    pub const OFF_ROAD: u8 = 5;
    /// `arg[0]`: 1 enable the lift, 0 disable; `value[0]`: position, % of travel.
    pub const LIFT: u8 = 6;
    /// `value[0]`: pan, rad (0 ahead, left positive); `value[1]`: tilt, rad (0 ahead, up positive).
    pub const SERVOS: u8 = 7;
    /// `arg[0]`: 1 enable drive power, 0 disable.
    pub const POWER: u8 = 8;
    /// Set the current steering position as zero; answered when the chassis acknowledges.
    pub const STEERING_ZERO: u8 = 9;
    /// Release the lock named in `name` (default `estop`).
    pub const LOCK_RELEASE: u8 = 10;
    /// `arg[0]`: 1 enter CAN-upgrade silent mode, 0 leave it.
    pub const SILENT: u8 = 11;
    /// Engage the lock named in `name` on behalf of the operator.
    pub const LOCK_ENGAGE: u8 = 12;

    pub fn name(kind: u8) -> &'static str {
        match kind {
            Self::MODE => "mode",
            Self::BRAKE => "brake",
            Self::CLEAR_FAULTS => "clear-faults",
            Self::LIGHTS => "lights",
            Self::OFF_ROAD => "off-road",
            Self::LIFT => "lift",
            Self::SERVOS => "servos",
            Self::POWER => "power",
            Self::STEERING_ZERO => "steering-zero",
            Self::LOCK_RELEASE => "lock-release",
            Self::SILENT => "silent",
            Self::LOCK_ENGAGE => "lock-engage",
            _ => "unknown",
        }
    }
}

/// Normalized fault-clear codes (`ControlKind::CLEAR_FAULTS`); each driver maps them to its
/// robot's own code, or refuses one the robot has not.
#[derive(Debug, Clone, Copy)]
pub struct FaultClear;
impl FaultClear {
    /// Every clearable fault.
    pub const ALL: u8 = 0;
    pub const MOTOR_1_COMM: u8 = 1;
    pub const MOTOR_2_COMM: u8 = 2;
    pub const MOTOR_3_COMM: u8 = 3;
    pub const MOTOR_4_COMM: u8 = 4;
    pub const BATTERY_UNDER_VOLTAGE: u8 = 5;
    pub const BATTERY_OVER_VOLTAGE: u8 = 6;
    pub const RC_LINK: u8 = 7;
    pub const FRONT_STEERING_ENCODER: u8 = 8;
    pub const REAR_STEERING_ENCODER: u8 = 9;
    pub const OVER_CURRENT: u8 = 10;
    pub const OVER_TEMPERATURE: u8 = 11;

    pub const NAMES: [(u8, &'static str); 12] = [
        (Self::ALL, "all"),
        (Self::MOTOR_1_COMM, "motor-1"),
        (Self::MOTOR_2_COMM, "motor-2"),
        (Self::MOTOR_3_COMM, "motor-3"),
        (Self::MOTOR_4_COMM, "motor-4"),
        (Self::BATTERY_UNDER_VOLTAGE, "battery-under-voltage"),
        (Self::BATTERY_OVER_VOLTAGE, "battery-over-voltage"),
        (Self::RC_LINK, "rc-link"),
        (Self::FRONT_STEERING_ENCODER, "front-steering-encoder"),
        (Self::REAR_STEERING_ENCODER, "rear-steering-encoder"),
        (Self::OVER_CURRENT, "over-current"),
        (Self::OVER_TEMPERATURE, "over-temperature"),
    ];

    pub fn name(code: u8) -> &'static str {
        Self::NAMES
            .iter()
            .find(|(c, _)| *c == code)
            .map_or("unknown", |(_, n)| n)
    }

    pub fn from_name(name: &str) -> Option<u8> {
        Self::NAMES
            .iter()
            .find(|(_, n)| *n == name)
            .map(|(c, _)| *c)
    }
}

/// Front light modes (SCOUT MINI 0x140 / 0x141).
#[derive(Debug, Clone, Copy)]
pub struct LightMode;
impl LightMode {
    /// Normally closed: off.
    pub const OFF: u8 = 0;
    /// Normally open: on.
    pub const ON: u8 = 1;
    pub const BREATHING: u8 = 2;
    /// Custom brightness.
    pub const CUSTOM: u8 = 3;

    pub fn name(mode: u8) -> &'static str {
        match mode {
            Self::OFF => "off",
            Self::ON => "on",
            Self::BREATHING => "breathing",
            Self::CUSTOM => "custom",
            _ => "unknown",
        }
    }
}

/// A control request.
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
#[type_name("chassis::ControlRequest.v1")]
pub struct ControlRequest {
    /// `CLOCK_MONOTONIC` time the request was created, ns.
    pub stamp_ns: u64,
    pub seq: u64,
    /// [`ControlKind`].
    pub kind: u8,
    /// Small arguments; meaning per [`ControlKind`].
    pub arg: [u8; 7],
    /// Numeric arguments; meaning per [`ControlKind`].
    pub value: [f32; 2],
    /// A lock name for the lock requests (NUL-padded UTF-8).
    #[serde(serialize_with = "serialize_fixed_str")]
    pub name: [u8; NAME_LEN],
}

describe_layout!(
    ControlRequest,
    control_request_description_covers_every_byte {
        stamp_ns,
        seq,
        kind,
        arg,
        value,
        name,
    }
);

impl ControlRequest {
    pub fn new(kind: u8) -> Self {
        Self {
            kind,
            ..Self::default()
        }
    }

    pub fn with_arg(mut self, index: usize, value: u8) -> Self {
        if let Some(slot) = self.arg.get_mut(index) {
            *slot = value;
        }
        self
    }

    pub fn with_value(mut self, index: usize, value: f32) -> Self {
        if let Some(slot) = self.value.get_mut(index) {
            *slot = value;
        }
        self
    }

    pub fn with_name(mut self, name: &str) -> Self {
        write_fixed_str(&mut self.name, name);
        self
    }

    pub fn name(&self) -> &str {
        read_fixed_str(&self.name)
    }
}

/// [`ControlResponse::status`].
#[derive(Debug, Clone, Copy)]
pub struct ControlStatus;
impl ControlStatus {
    pub const OK: u8 = 0;
    /// Understood but not done now (the message says why, e.g. "robot is moving").
    pub const REFUSED: u8 = 1;
    /// This robot has no such function.
    pub const UNSUPPORTED: u8 = 2;
    /// An argument is out of range.
    pub const INVALID: u8 = 3;
    /// The chassis did not acknowledge in time.
    pub const TIMEOUT: u8 = 4;

    pub fn name(status: u8) -> &'static str {
        match status {
            Self::OK => "ok",
            Self::REFUSED => "refused",
            Self::UNSUPPORTED => "unsupported",
            Self::INVALID => "invalid",
            Self::TIMEOUT => "timeout",
            _ => "unknown",
        }
    }
}

/// The answer to a control request.
#[repr(C)]
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    FromBytes,
    IntoBytes,
    Immutable,
    KnownLayout,
    ZeroCopySend,
    Serialize,
)]
#[type_name("chassis::ControlResponse.v1")]
pub struct ControlResponse {
    /// `CLOCK_MONOTONIC` time of the answer, ns.
    pub stamp_ns: u64,
    /// `seq` of the request this answers.
    pub request_seq: u64,
    /// [`ControlStatus`].
    pub status: u8,
    #[serde(skip)]
    pub _reserved: [u8; 7],
    /// A human-readable result or refusal reason (NUL-padded UTF-8).
    #[serde(serialize_with = "serialize_fixed_str")]
    pub message: [u8; ControlResponse::MESSAGE_LEN],
}

describe_layout!(
    ControlResponse,
    control_response_description_covers_every_byte {
        stamp_ns,
        request_seq,
        status,
        _reserved,
        message,
    }
);

impl Default for ControlResponse {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            request_seq: 0,
            status: ControlStatus::OK,
            _reserved: [0; 7],
            message: [0; Self::MESSAGE_LEN],
        }
    }
}

impl ControlResponse {
    pub const MESSAGE_LEN: usize = 112;

    pub fn new(request_seq: u64, status: u8, message: &str) -> Self {
        let mut response = Self {
            request_seq,
            status,
            ..Self::default()
        };
        write_fixed_str(&mut response.message, message);
        response
    }

    pub fn message(&self) -> &str {
        read_fixed_str(&self.message)
    }

    pub fn is_ok(&self) -> bool {
        self.status == ControlStatus::OK
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn control_layouts_are_pinned() {
        assert_eq!(size_of::<ControlRequest>(), 48);
        assert_eq!(align_of::<ControlRequest>(), 8);
        assert_eq!(offset_of!(ControlRequest, kind), 16);
        assert_eq!(offset_of!(ControlRequest, arg), 17);
        assert_eq!(offset_of!(ControlRequest, value), 24);
        assert_eq!(offset_of!(ControlRequest, name), 32);
        assert_eq!(size_of::<ControlResponse>(), 136);
        assert_eq!(align_of::<ControlResponse>(), 8);
        assert_eq!(offset_of!(ControlResponse, status), 16);
        assert_eq!(offset_of!(ControlResponse, message), 24);
    }

    #[test]
    fn response_carries_its_reason() {
        let r = ControlResponse::new(7, ControlStatus::REFUSED, "robot is moving");
        assert_eq!(r.message(), "robot is moving");
        assert!(!r.is_ok());
        assert_eq!(r.request_seq, 7);
    }

    #[test]
    fn fault_clear_names_round_trip() {
        for (code, name) in FaultClear::NAMES {
            assert_eq!(FaultClear::from_name(name), Some(code));
            assert_eq!(FaultClear::name(code), name);
        }
    }

    #[test]
    fn builder_ignores_out_of_range_slots() {
        let r = ControlRequest::new(ControlKind::LIFT)
            .with_arg(0, 1)
            .with_arg(99, 5)
            .with_value(0, 42.0)
            .with_value(9, 1.0)
            .with_name("estop");
        assert_eq!(r.arg[0], 1);
        assert_eq!(r.value, [42.0, 0.0]);
        assert_eq!(r.name(), "estop");
    }
}

/// [`SimRequest::index`] of a [`SimKind::TRUTH`] request: the page of the truth to answer with
/// (one page fits a [`ControlResponse`]).
#[derive(Debug, Clone, Copy)]
pub struct SimTruthPage;
impl SimTruthPage {
    /// The true motion and the frames obeyed and rejected (see [`SimKind::TRUTH`]).
    pub const MOTION: u8 = 0;
    /// The faults the chassis injected, counted as each left it for the bus since power-up
    /// (queued ones, and those a silence or a reboot cleared, are not): `garbage_frames=…
    /// garbage_bytes=… bad_checksums=… flood_frames=…` — garbage CAN frames (serial: writes)
    /// and their bytes, frames (serial reports) sent with a corrupted checksum, and the extra
    /// frames of a flood. What a storm's sender really sent, for tests to hold the service's
    /// counters against.
    pub const INJECTED: u8 = 1;
}

/// [`SimRequest::kind`]: faults and events a simulated chassis can be given
/// (`chassis/<name>/sim`, offered only when the bus is the simulator).
#[derive(Debug, Clone, Copy)]
pub struct SimKind;
impl SimKind {
    /// Motor driver `index` (1-4) lost (`flag` 1) or back (0).
    pub const MOTOR_DRIVER_LOSS: u8 = 1;
    /// Battery state of charge = `value` %.
    pub const BATTERY: u8 = 2;
    /// Bumper pressed (`flag` 1) or released.
    pub const BUMPER: u8 = 3;
    /// RC transmitter takes over (`flag` 1) or is switched off.
    pub const RC_TAKEOVER: u8 = 4;
    /// Power-cycle the chassis.
    pub const REBOOT: u8 = 5;
    /// Stop transmitting for `value` seconds.
    pub const SILENCE: u8 = 6;
    /// `value` garbage bytes on the wire now.
    pub const GARBAGE: u8 = 7;
    /// Corrupt the checksum of the next `value` frames.
    pub const BAD_CHECKSUMS: u8 = 8;
    /// Obstacle ahead at `value` m (`flag` 0 clears it).
    pub const OBSTACLE_AHEAD: u8 = 9;
    /// Obstacle behind at `value` m (`flag` 0 clears it).
    pub const OBSTACLE_BEHIND: u8 = 10;
    /// `value` extra feedback frames per second (0 stops).
    pub const FLOOD: u8 = 11;
    /// Ask for what the simulated chassis really does (its true pose and speeds, not what it
    /// reports): the answer's message reads `x_m=… y_m=… yaw_rad=… linear_mps=… angular_radps=…
    /// commands=… rejected=…` (the frames it obeyed, and those it could not decode or dropped
    /// for a bad checksum, since power-up). `index` [`SimTruthPage::INJECTED`] asks for the
    /// faults it injected instead.
    pub const TRUTH: u8 = 12;
    /// The chassis' own emergency-stop switch pressed (`flag` 1) or released (AgileX protocol
    /// V2: 0x211 b0 reports it).
    pub const ESTOP_SWITCH: u8 = 13;
    /// The speed loop runs away (downhill, a failing speed controller, bad feedback): the
    /// chassis drives at `value` m/s forward (negative: reverse) whatever it is commanded, until
    /// `flag` 0 gives the control back.
    pub const RUNAWAY: u8 = 14;

    pub const NAMES: [(u8, &'static str); 14] = [
        (Self::MOTOR_DRIVER_LOSS, "motor-driver-loss"),
        (Self::BATTERY, "battery"),
        (Self::BUMPER, "bumper"),
        (Self::RC_TAKEOVER, "rc-takeover"),
        (Self::REBOOT, "reboot"),
        (Self::SILENCE, "silence"),
        (Self::GARBAGE, "garbage"),
        (Self::BAD_CHECKSUMS, "bad-checksums"),
        (Self::OBSTACLE_AHEAD, "obstacle-ahead"),
        (Self::OBSTACLE_BEHIND, "obstacle-behind"),
        (Self::FLOOD, "flood"),
        (Self::TRUTH, "truth"),
        (Self::ESTOP_SWITCH, "estop-switch"),
        (Self::RUNAWAY, "runaway"),
    ];

    pub fn name(kind: u8) -> &'static str {
        Self::NAMES
            .iter()
            .find(|(k, _)| *k == kind)
            .map_or("unknown", |(_, n)| n)
    }
}

/// A fault to inject into a simulated chassis; answered with a [`ControlResponse`].
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
#[type_name("chassis::SimRequest.v1")]
pub struct SimRequest {
    pub stamp_ns: u64,
    pub seq: u64,
    /// [`SimKind`].
    pub kind: u8,
    /// On/off for the kinds that switch something.
    pub flag: u8,
    /// Motor number for [`SimKind::MOTOR_DRIVER_LOSS`]; the page of [`SimKind::TRUTH`]'s answer
    /// ([`SimTruthPage`]).
    pub index: u8,
    #[serde(skip)]
    pub _reserved: [u8; 5],
    /// Amount for the kinds that take one (%, s, m, bytes, frames, m/s).
    pub value: f64,
}

describe_layout!(
    SimRequest,
    sim_request_description_covers_every_byte {
        stamp_ns,
        seq,
        kind,
        flag,
        index,
        _reserved,
        value,
    }
);

#[cfg(test)]
mod sim_tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn sim_request_layout_is_pinned() {
        assert_eq!((size_of::<SimRequest>(), align_of::<SimRequest>()), (32, 8));
        assert_eq!(offset_of!(SimRequest, kind), 16);
        assert_eq!(offset_of!(SimRequest, index), 18);
        assert_eq!(offset_of!(SimRequest, value), 24);
    }
}
