//! The simulated loopback chassis, built on the shared simulator pieces ([`SimBody`]): it obeys
//! 0x010 (within the profile's limits) until its command timeout, answers with 0x020 every
//! 20 ms, and takes the injections
//! every chassis shares (silence, garbage, reboot, battery, runaway); it has no motor drivers
//! to lose, no checksum, no flood, RC, bumper, E-stop or range sensors.

use std::time::Duration;

use chassis_interfaces::ControlMode;

use super::codec::{Feedback, Frame, Twist, decode};
use super::profile::LoopbackProfile;
use crate::can::CanFrame;
use crate::driver::{Rx, WireItem};
use crate::firmware::{
    Applied, BatteryModel, Firmware, InjectedCounts, Injection, SimBody, SimBodySpec, SimTruth,
    clamp_i16, first_order_lag, past_timeout,
};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp, earliest};

/// The simulated loopback chassis.
#[derive(Debug)]
pub struct LoopbackSim {
    profile: LoopbackProfile,
    /// The command obeyed, until `command_until`.
    command: Twist,
    command_until: Option<Timestamp>,
    linear_mps: f64,
    angular_radps: f64,
    feedback: Grid,
    body: SimBody<CanFrame>,
}

impl LoopbackSim {
    /// Period of 0x020.
    pub const FEEDBACK_PERIOD: Duration = Duration::from_millis(20);
    /// Time constant of the speed response, s.
    pub const SPEED_TIME_CONSTANT_S: f64 = 0.2;
    /// No motor drivers to lose, no flood, no checksum; a 300 ms boot; a 24 V pack; 0.5 A for
    /// the electronics (the motors add 2 A per m/s).
    pub(crate) const BODY: SimBodySpec = SimBodySpec {
        motors: 0,
        max_flood_per_s: 0,
        checksums: false,
        boot_time: Duration::from_millis(300),
        battery: BatteryModel {
            capacity_ah: 20.0,
            full_v: 25.2,
            empty_v: 21.0,
            resistance_ohm: 0.05,
        },
        idle_current_a: 0.5,
    };

    /// A chassis that has just finished booting at `now`, standing, waiting for a command.
    pub fn new(profile: LoopbackProfile, now: Timestamp) -> Self {
        Self {
            profile,
            command: Twist::default(),
            command_until: None,
            linear_mps: 0.0,
            angular_radps: 0.0,
            feedback: Grid::new(Self::FEEDBACK_PERIOD, now),
            body: SimBody::new(Self::BODY, now),
        }
    }

    /// Physics and the deadlines that change what the chassis does (boot end, command timeout).
    fn expire(&mut self, now: Timestamp) {
        for dt in self.body.substeps(now) {
            self.step(dt);
        }
        self.body.expire(now);
        if self.command_until.is_some_and(|t| now >= t) {
            self.command_until = None;
            self.command = Twist::default();
        }
    }

    /// Integrates `dt` seconds.
    fn step(&mut self, dt: f64) {
        let mut target = self.command;
        target.linear_mps *= self.body.gain;
        target.angular_radps *= self.body.gain;
        if let Some(runaway) = self.body.runaway_mps {
            target.linear_mps = runaway;
        }
        let lag = |from, to| first_order_lag(from, to, Self::SPEED_TIME_CONSTANT_S, dt);
        let (v0, w0) = (self.linear_mps, self.angular_radps);
        self.linear_mps = lag(v0, target.linear_mps);
        self.angular_radps = lag(w0, target.angular_radps);
        let v_mid = 0.5 * (v0 + self.linear_mps);
        let w_mid = 0.5 * (w0 + self.angular_radps);
        self.body.pose.advance(v_mid, 0.0, w_mid, dt);
        let current = Self::BODY.idle_current_a + 2.0 * self.linear_mps.abs();
        self.body.draw(current, dt);
    }

    fn obeying(&self) -> bool {
        self.command_until.is_some()
    }

    fn reboot(&mut self, now: Timestamp) {
        self.command = Twist::default();
        self.command_until = None;
        self.body.reboot(now);
    }
}

impl Firmware for LoopbackSim {
    fn robot(&self) -> RobotKind {
        self.profile.robot
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        self.expire(now);
        let Some(Frame::Command(command)) = self.body.command(rx, decode, Frame::direction) else {
            return;
        };
        if self.body.is_booting() {
            self.body.received.ignored += 1;
            return;
        }
        // Beyond the profile's limits a command is clamped to them.
        let (linear, angular) = (self.profile.max_linear_mps, self.profile.max_angular_radps);
        self.command = Twist {
            linear_mps: command.linear_mps.clamp(-linear, linear),
            angular_radps: command.angular_radps.clamp(-angular, angular),
        };
        self.command_until = Some(past_timeout(now, self.profile.command_timeout_ms));
        self.body.received.commands += 1;
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        self.expire(now);
        if self.feedback.serve_due(now) && !self.body.is_quiet(now) {
            let feedback = Frame::Feedback(Feedback {
                linear_mps: clamp_i16(self.linear_mps, 1000.0),
                angular_radps: clamp_i16(self.angular_radps, 1000.0),
                battery_voltage_v: self.body.battery_voltage_v().min(655.35),
                obeying: self.obeying(),
            });
            let encoded = feedback.encode();
            self.body
                .outbox
                .push_encoded(encoded, InjectedCounts::default());
        }
    }

    fn poll_transmit(&mut self, _now: Timestamp) -> Option<WireItem> {
        self.body.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        [self.command_until, self.body.poll_timeout()]
            .into_iter()
            .fold(Some(self.feedback.next()), earliest)
    }

    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.expire(now);
        match self.body.inject(now, injection) {
            Applied::Condition | Applied::Done => true,
            Applied::Robot(Injection::Reboot) => {
                self.reboot(now);
                true
            }
            Applied::Refused | Applied::Robot(_) => false,
        }
    }

    fn truth(&self) -> SimTruth {
        SimTruth {
            linear_mps: self.linear_mps,
            angular_radps: self.angular_radps,
            control_mode: if self.obeying() {
                ControlMode::COMMAND
            } else {
                ControlMode::STANDBY
            },
            ..self.body.truth()
        }
    }
}
