//! The control request/response pair (iceoryx2 request-response service `control`).

use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde::Serialize;

use crate::layout::ipc_type;
use crate::named::named_constants;

use crate::NAME_LEN;
use crate::text::{serialize_fixed_str, write_fixed_str};

named_constants! {
    /// [`ControlRequest::kind`] and the meaning of its arguments.
    pub enum ControlKind: u8 {
        /// `arg[0]`: `ControlMode::COMMAND` (take control) or `ControlMode::STANDBY` (let go).
        MODE = 1 => "mode",
        /// `arg[0]`: 1 engage the parking brake, 0 release it.
        BRAKE = 2 => "brake",
        /// `arg[0]`: a [`FaultClear`] code.
        CLEAR_FAULTS = 3 => "clear-faults",
        /// `arg[0]`: [`LightMode`] of the front light, `arg[1]`: custom brightness %, `arg[2]`: 1
        /// to enable light control, 0 to hand the lights back to the chassis.
        LIGHTS = 4 => "lights",
        /// `arg[0]`: 1 enter off-road mode, 0 leave it (refused while moving).
        OFF_ROAD = 5 => "off-road",
        /// `arg[0]`: 1 enable the lift, 0 disable; `value[0]`: position, % of travel.
        LIFT = 6 => "lift",
        /// `value[0]`: pan, rad (0 ahead, left positive); `value[1]`: tilt, rad (0 ahead, up
        /// positive).
        SERVOS = 7 => "servos",
        /// `arg[0]`: 1 enable drive power, 0 disable.
        POWER = 8 => "power",
        /// Set the current steering position as zero; answered when the chassis acknowledges.
        STEERING_ZERO = 9 => "steering-zero",
        /// Release the lock named in `name` (default `estop`).
        LOCK_RELEASE = 10 => "lock-release",
        /// `arg[0]`: 1 enter CAN-upgrade silent mode, 0 leave it.
        SILENT = 11 => "silent",
        /// Engage the lock named in `name` on behalf of the operator; `arg[0]`: 0 for the lock's
        /// configured stop category, 1 + a `StopCategory` for that one.
        LOCK_ENGAGE = 12 => "lock-engage",
        /// `value[0]`: the robot's standing speed limit, m/s, set by the operator — raised or
        /// lowered; 0 lifts it. A source can only lower it (`RequestFlags::SPEED_LIMIT`).
        SPEED_LIMIT = 13 => "speed-limit",
        /// Keep the black box's window around now as a file (`blackbox/kept/`), as a stop
        /// nobody asked for does; refused when the black box is off.
        KEEP = 14 => "keep",
    }
}

named_constants! {
    /// Normalized fault-clear codes (`ControlKind::CLEAR_FAULTS`); each driver maps them to its
    /// robot's own code, or refuses one the robot has not.
    pub enum FaultClear: u8 {
        /// Every clearable fault.
        ALL = 0 => "all",
        MOTOR_1_COMM = 1 => "motor-1",
        MOTOR_2_COMM = 2 => "motor-2",
        MOTOR_3_COMM = 3 => "motor-3",
        MOTOR_4_COMM = 4 => "motor-4",
        BATTERY_UNDER_VOLTAGE = 5 => "battery-under-voltage",
        BATTERY_OVER_VOLTAGE = 6 => "battery-over-voltage",
        RC_LINK = 7 => "rc-link",
        FRONT_STEERING_ENCODER = 8 => "front-steering-encoder",
        REAR_STEERING_ENCODER = 9 => "rear-steering-encoder",
        OVER_CURRENT = 10 => "over-current",
        OVER_TEMPERATURE = 11 => "over-temperature",
    }
}

named_constants! {
    /// Front light modes (SCOUT MINI 0x140 / 0x141).
    pub enum LightMode: u8 {
        /// Normally closed: off.
        OFF = 0 => "off",
        /// Normally open: on.
        ON = 1 => "on",
        BREATHING = 2 => "breathing",
        /// Custom brightness.
        CUSTOM = 3 => "custom",
    }
}

ipc_type! {
    /// A control request.
    #[derive(Default, Serialize)]
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
        pub name: [u8; NAME_LEN] as text,
    }
}

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
}

named_constants! {
    /// [`ControlResponse::status`].
    pub enum ControlStatus: u8 {
        OK = 0 => "ok",
        /// Understood but not done now (the message says why, e.g. "robot is moving").
        REFUSED = 1 => "refused",
        /// This robot has no such function.
        UNSUPPORTED = 2 => "unsupported",
        /// An argument is out of range.
        INVALID = 3 => "invalid",
        /// The chassis did not acknowledge in time.
        TIMEOUT = 4 => "timeout",
    }
}

ipc_type! {
    /// The answer to a control request.
    #[derive(Serialize)]
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
        pub message: [u8; ControlResponse::MESSAGE_LEN] as text,
    }
}

impl Default for ControlResponse {
    fn default() -> Self {
        Self {
            status: ControlStatus::OK,
            ..zerocopy::FromZeros::new_zeroed()
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

    pub fn is_ok(&self) -> bool {
        self.status == ControlStatus::OK
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

named_constants! {
    /// [`SimRequest::index`] of a [`SimKind::TRUTH`] request: the page of the truth to answer
    /// with (one page fits a [`ControlResponse`]).
    pub enum SimTruthPage: u8 {
        /// The true motion and the frames obeyed and rejected (see [`SimKind::TRUTH`]).
        MOTION = 0 => "motion",
        /// The faults the chassis injected, counted as each left it for the bus since power-up
        /// (queued ones, and those a silence or a reboot cleared, are not): `garbage_frames=…
        /// garbage_bytes=… bad_checksums=… flood_frames=…` — garbage CAN frames (serial:
        /// writes) and their bytes, frames (serial reports) sent with a corrupted checksum, and
        /// the extra frames of a flood. What a storm's sender really sent, for tests to hold the
        /// service's counters against.
        INJECTED = 1 => "injected",
    }
}

named_constants! {
    /// [`SimRequest::kind`]: faults and events a simulated chassis can be given
    /// (`chassis/<name>/sim`, offered only when the bus is the simulator).
    pub enum SimKind: u8 {
        /// Motor driver `index` (1-4) lost (`flag` 1) or back (0).
        MOTOR_DRIVER_LOSS = 1 => "motor-driver-loss",
        /// Battery state of charge = `value` %.
        BATTERY = 2 => "battery",
        /// Bumper pressed (`flag` 1) or released.
        BUMPER = 3 => "bumper",
        /// RC transmitter takes over (`flag` 1) or is switched off.
        RC_TAKEOVER = 4 => "rc-takeover",
        /// Power-cycle the chassis.
        REBOOT = 5 => "reboot",
        /// Stop transmitting for `value` seconds.
        SILENCE = 6 => "silence",
        /// `value` garbage bytes on the wire now.
        GARBAGE = 7 => "garbage",
        /// Corrupt the checksum of the next `value` frames.
        BAD_CHECKSUMS = 8 => "bad-checksums",
        /// Obstacle ahead at `value` m (`flag` 0 clears it).
        OBSTACLE_AHEAD = 9 => "obstacle-ahead",
        /// Obstacle behind at `value` m (`flag` 0 clears it).
        OBSTACLE_BEHIND = 10 => "obstacle-behind",
        /// `value` extra feedback frames per second (0 stops).
        FLOOD = 11 => "flood",
        /// Ask for what the simulated chassis really does (its true pose and speeds, not what it
        /// reports): the answer's message reads `x_m=… y_m=… yaw_rad=… linear_mps=…
        /// angular_radps=… commands=… rejected=…` (the frames it obeyed, and those it could not
        /// decode or dropped for a bad checksum, since power-up). `index`
        /// [`SimTruthPage::INJECTED`] asks for the faults it injected instead.
        TRUTH = 12 => "truth",
        /// The chassis' own emergency-stop switch pressed (`flag` 1) or released (AgileX
        /// protocol V2: 0x211 b0 reports it).
        ESTOP_SWITCH = 13 => "estop-switch",
        /// The speed loop runs away (downhill, a failing speed controller, bad feedback): the
        /// chassis drives at `value` m/s forward (negative: reverse) whatever it is commanded,
        /// until `flag` 0 gives the control back.
        RUNAWAY = 14 => "runaway",
        /// The wheels turn at `value` times the command (0: the chassis ignores it, 0 to 1: it
        /// slips, negative: it drives against it; at most 2 either way), until `flag` 0 makes it
        /// obey again.
        GAIN = 15 => "gain",
    }
}

ipc_type! {
    /// A fault to inject into a simulated chassis; answered with a [`ControlResponse`].
    #[derive(Default, Serialize)]
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
}
