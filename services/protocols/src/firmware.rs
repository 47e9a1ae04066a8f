//! The simulated firmware contract: the chassis side of the wire, built on the same codecs.
//!
//! A firmware is sans-IO like a driver: commands go in with their time, feedback frames come out
//! at the manual's periods, and it enforces the manual's rules (standby after power-up, the
//! 500 ms command timeout, the parking brake, RC authority, checksums). Faults are injected by
//! value. `chassisd` runs one in-process as its default bus, and `chassisd sim` runs one as its
//! own process on a real bus.

use std::time::Duration;

use serde::Serialize;

use crate::driver::{Rx, Transmit};
use crate::profile::Robot;
use crate::time::Timestamp;

/// A fault or event to inject into a simulated chassis.
#[derive(Debug, Clone, PartialEq)]
pub enum Injection {
    /// Motor driver `motor` (1-4) stops answering (`lost`) or comes back.
    MotorDriverLoss { motor: u8, lost: bool },
    /// Set the battery's state of charge, % (TITAN cuts drive below 10 %).
    Battery { soc_pct: f64 },
    /// The bumper is pressed (`true`) or released.
    Bumper(bool),
    /// An RC transmitter takes over (`true`) or is switched off again.
    RcTakeover(bool),
    /// Power-cycle the chassis: it comes back as after power-up.
    Reboot,
    /// Stop transmitting for this long (commands are still obeyed).
    Silence(Duration),
    /// Put these raw bytes on the wire now (serial robots; CAN robots send them as frames with an
    /// unused id, 8 bytes each).
    Garbage(Vec<u8>),
    /// Corrupt the checksum of the next `n` frames sent (SCOUT MINI, XBot).
    BadChecksums(u32),
    /// An obstacle at this range in front (XBot ultrasonic front-centre), m; `None` clears it.
    ObstacleAhead(Option<f64>),
    /// An obstacle at this range behind (XBot IR rear-centre), m; `None` clears it.
    ObstacleBehind(Option<f64>),
    /// Send feedback as fast as the bus allows: `frames_per_s` extra frames (load tests).
    Flood { frames_per_s: u32 },
}

impl Injection {
    pub fn name(&self) -> &'static str {
        match self {
            Injection::MotorDriverLoss { .. } => "motor-driver-loss",
            Injection::Battery { .. } => "battery",
            Injection::Bumper(_) => "bumper",
            Injection::RcTakeover(_) => "rc-takeover",
            Injection::Reboot => "reboot",
            Injection::Silence(_) => "silence",
            Injection::Garbage(_) => "garbage",
            Injection::BadChecksums(_) => "bad-checksums",
            Injection::ObstacleAhead(_) => "obstacle-ahead",
            Injection::ObstacleBehind(_) => "obstacle-behind",
            Injection::Flood { .. } => "flood",
        }
    }
}

/// What a simulated chassis really does, for tests to compare with what the driver reports.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SimTruth {
    /// Body speeds the simulated chassis actually has.
    pub linear_mps: f64,
    pub lateral_mps: f64,
    pub angular_radps: f64,
    pub steer_rad: f64,
    /// Integrated true pose.
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
    /// `chassis_interfaces::ControlMode`.
    pub control_mode: u8,
    pub brake_engaged: bool,
    pub soc_pct: f64,
    /// Normalized `chassis_interfaces::FaultFlags` the chassis reports.
    pub fault_flags: u64,
    /// Command frames accepted.
    pub commands_received: u64,
    /// Frames dropped for a bad checksum.
    pub bad_checksums_received: u64,
    /// Frames that could not be decoded.
    pub decode_errors: u64,
    /// Times the chassis rebooted.
    pub boots: u32,
}

/// The contract every simulated firmware fulfils.
pub trait Firmware {
    fn robot(&self) -> Robot;

    /// Feeds what the computer sent at `now`.
    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>);

    /// Advances the physics and processes deadlines (feedback periods, command timeout).
    fn handle_timeout(&mut self, now: Timestamp);

    /// The next frame (or serial chunk) the chassis sends.
    fn poll_transmit(&mut self, now: Timestamp) -> Option<Transmit>;

    /// When [`Firmware::handle_timeout`] must be called next.
    fn poll_timeout(&self) -> Option<Timestamp>;

    /// Injects a fault or event. Returns `false` when this robot has no such thing.
    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool;

    /// What the chassis really does.
    fn truth(&self) -> SimTruth;
}
