//! The simulated protocol-V2 firmware: one chassis for the whole family, parametrised by the
//! robot's [`V2Profile`], built on the V2 codec and the shared simulator pieces.
//!
//! # Rules, as enforced (`PROTOCOLS-V2` §1, §5)
//!
//! * **Power-up**: standby (or CAN command mode where `starts_in_standby = false`), no RC
//!   transmitter, brake engaged where there is one, SOC 100 %. Standby obeys only 0x421 (and the
//!   queries 0x411 / 0x4A1 / 0x433); other commands are ignored and counted.
//! * **Authority**: CAN command mode obeys every command. While an RC transmitter holds authority
//!   (0x211 b1 = the profile's RC code) only 0x441 and the queries are obeyed. When the RC lets go
//!   the chassis drops to standby and needs 0x421 again (the BUNKER MINI's behaviour).
//! * **Heartbeat**: more than `command_timeout_ms` (500 ms) without 0x111 in CAN command mode
//!   stops the robot and sets the "host communication lost" fault bit (SDK table: b4 bit1); the
//!   next 0x111 clears it and is obeyed. The mode stays.
//! * **E-stop** ([`Injection::EStop`]): 0x211 b0 = 0x01 and, where the profile reads it so
//!   (⚠ D-20), fault word 0x0080; the robot stops and drops its command. 0x421 is still accepted.
//! * **Brake** (HUNTER 2.0): 0x131 with the profile's polarity, only in CAN command mode; speed
//!   commands move nothing while it is engaged; 0x211 b6 reports it.
//! * **RANGER**: 0x141 sets the motion mode (reported in 0x291); 0x111 is read in that mode.
//! * **Limits**: 0x111 beyond the profile's limits is clamped and counted.
//! * **Reboot** ([`Injection::Reboot`]): silent for the boot time, then as at power-up.
//!
//! # Feedback
//!
//! | period | frames |
//! | --- | --- |
//! | `status_period_ms` (20 or 100 ms) | 0x211 |
//! | 20 ms | 0x221, 0x241 (RC on), 0x251-0x25n, 0x311, and on four-wheel steering 0x271, 0x281, 0x291 |
//! | 100 ms | 0x261-0x26n |
//! | 500 ms | 0x361, 0x362 |
//!
//! 0x221 reports the applied command in the robot's own 0x111 form (a first-order lag of the
//! speeds, the steering at once), so a driver reading it with [`body_twist`] reproduces the true
//! body twist exactly.

use std::time::Duration;

use chassis_interfaces::{FaultFlags, RcState};

use super::codec::{
    Four, Frame, Lights, Motion, MotionMode, Odometer, SteeringZeroOffset, SystemStatus, Version,
    VersionText, decode, vehicle,
};
use super::commands::STOP;
use super::driver::normalize_faults;
use super::kinematics::{RangerMode, body_twist};
use super::profile::{Kinematics, SpinField, V2Profile};
use crate::can::CanFrame;
use crate::driver::{Rx, WireItem};
use crate::firmware::{
    Applied, BatteryModel, Firmware, InjectedCounts, Injection, Mode, SimBody, SimBodySpec,
    SimTruth, first_order_lag, wrap_mm,
};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp, earliest};
use crate::titan::{BmsAlarm, BmsData, MotorFast, MotorSlow};

/// The simulated protocol-V2 chassis.
#[derive(Debug)]
pub struct V2Sim {
    profile: V2Profile,
    robot: RobotKind,
    mode: Mode,
    applied: Motion,
    command: Motion,
    last_command: Option<Timestamp>,
    heartbeat_lost: bool,
    estop: bool,
    rc_on: bool,
    brake_engaged: bool,
    ranger_mode: RangerMode,
    lights: Lights,
    steering_offset: i16,
    odometer_m: [f64; 2],
    /// What every simulated chassis shares: the outbox, the boot, the battery, the pose, the
    /// injected faults and the counts of what it received.
    body: SimBody<CanFrame>,
    status: Grid,
    fast: Grid,
    slow: Grid,
    bms: Grid,
    count: u8,
    commands_clamped: u64,
}

impl V2Sim {
    pub const FAST_PERIOD: Duration = Duration::from_millis(20);
    pub const SLOW_PERIOD: Duration = Duration::from_millis(100);
    pub const BMS_PERIOD: Duration = Duration::from_millis(500);
    /// Silence after a reboot.
    pub const DEFAULT_BOOT_TIME: Duration = Duration::from_millis(300);
    /// Time constant of the speed response, s.
    pub const DEFAULT_SPEED_TIME_CONSTANT_S: f64 = 0.2;
    /// Wheel radius for the actuator rpm, m (not in any source).
    pub const WHEEL_RADIUS_M: f64 = 0.08;
    /// What the electronics draw, A; the motors add 4 A per m/s.
    pub const IDLE_CURRENT_A: f64 = 1.0;
    /// 24 V-class pack.
    pub const BATTERY: BatteryModel = BatteryModel {
        capacity_ah: 30.0,
        full_v: 27.0,
        empty_v: 22.0,
        resistance_ohm: 0.05,
    };
    /// The version text 0x4A1 answers with (10 frames of 8 characters, as the SDK expects).
    pub const VERSION_TEXT: &'static [u8; 80] =
        b"AgileX protocol V2 simulated firmware 1.0, built on simulated time, no hardware.";

    /// A chassis that has just finished booting at `now`.
    pub fn new(profile: V2Profile, now: Timestamp) -> Self {
        let robot = profile.model.robot();
        let status = Duration::from_millis(profile.status_period_ms.max(1));
        let mut sim = Self {
            robot,
            mode: Mode::Standby,
            applied: STOP,
            command: STOP,
            last_command: None,
            heartbeat_lost: false,
            estop: false,
            rc_on: false,
            brake_engaged: false,
            ranger_mode: RangerMode::DualAckermann,
            lights: Lights::default(),
            steering_offset: 22000,
            odometer_m: [0.0; 2],
            body: SimBody::new(
                SimBodySpec {
                    motors: 0,
                    max_flood_per_s: 0,
                    checksums: false,
                    boot_time: Self::DEFAULT_BOOT_TIME,
                    battery: Self::BATTERY,
                    idle_current_a: Self::IDLE_CURRENT_A,
                },
                now,
            ),
            status: Grid::new(status, now),
            fast: Grid::new(Self::FAST_PERIOD, now),
            slow: Grid::new(Self::SLOW_PERIOD, now),
            bms: Grid::new(Self::BMS_PERIOD, now),
            count: 0,
            commands_clamped: 0,
            profile,
        };
        // Power-up counts as the first boot.
        sim.body.boots = 1;
        sim.power_up();
        sim
    }

    pub fn profile(&self) -> &V2Profile {
        &self.profile
    }

    /// 0x111 frames beyond the profile's limits.
    pub fn commands_clamped(&self) -> u64 {
        self.commands_clamped
    }

    /// The RANGER motion mode in force.
    pub fn ranger_mode(&self) -> RangerMode {
        self.ranger_mode
    }

    /// The light state (0x231).
    pub fn lights(&self) -> Lights {
        self.lights
    }

    fn power_up(&mut self) {
        self.mode = if self.profile.starts_in_standby {
            Mode::Standby
        } else {
            Mode::Command
        };
        self.applied = STOP;
        self.command = STOP;
        self.last_command = None;
        self.heartbeat_lost = false;
        self.brake_engaged = self.profile.brake_lock_value.is_some();
        self.ranger_mode = RangerMode::DualAckermann;
        self.lights = Lights::default();
    }

    fn expire(&mut self, now: Timestamp) {
        self.body.expire(now);
        for dt in self.body.substeps(now) {
            self.step(dt);
        }
        if self.mode == Mode::Command
            && !self.heartbeat_lost
            && self.last_command.is_some_and(|t| {
                now.saturating_since(t) > Duration::from_millis(self.profile.command_timeout_ms)
            })
        {
            self.heartbeat_lost = true;
            self.command = STOP;
        }
    }

    fn drive_blocked(&self) -> bool {
        self.estop || self.mode != Mode::Command || self.heartbeat_lost || self.brake_engaged
    }

    fn step(&mut self, dt: f64) {
        let mut target = if self.drive_blocked() {
            Motion {
                steer_rad: self.applied.steer_rad,
                ..STOP
            }
        } else {
            self.command
        };
        target.linear_mps *= self.body.gain;
        target.angular_radps *= self.body.gain;
        if let Some(runaway) = self.body.runaway_mps {
            target.linear_mps = runaway;
        }
        let tau = Self::DEFAULT_SPEED_TIME_CONSTANT_S;
        self.applied = Motion {
            linear_mps: first_order_lag(self.applied.linear_mps, target.linear_mps, tau, dt),
            angular_radps: first_order_lag(
                self.applied.angular_radps,
                target.angular_radps,
                tau,
                dt,
            ),
            lateral_mps: first_order_lag(self.applied.lateral_mps, target.lateral_mps, tau, dt),
            steer_rad: target.steer_rad,
        };
        let (vx, vy, w) = self.body();
        self.body.pose.advance(vx, vy, w, dt);
        // Left and right wheel travel of a differential body; the centre on the others.
        let half_track = self.profile.track_m / 2.0;
        let (left, right) = match self.profile.kinematics {
            Kinematics::Differential | Kinematics::Omni => {
                (vx - w * half_track, vx + w * half_track)
            }
            _ => (vx, vx),
        };
        self.odometer_m[0] += left * dt;
        self.odometer_m[1] += right * dt;
        self.body.draw(Self::IDLE_CURRENT_A + 4.0 * vx.abs(), dt);
    }

    /// The true body twist (v, v_y, ω).
    fn body(&self) -> (f64, f64, f64) {
        body_twist(&self.applied, Some(self.ranger_mode), &self.profile)
    }

    /// The command within the profile's limits (counted when clamped).
    fn limited(&mut self, m: Motion) -> Motion {
        let p = &self.profile;
        let lim = |v: f64, max: f64| v.clamp(-max, max);
        let steer_max = match (p.kinematics, self.ranger_mode) {
            (Kinematics::FourWheelSteer, RangerMode::Crab) => p.max_crab_rad,
            _ => p.max_steer_rad,
        };
        let lateral_max = match (p.kinematics, p.spin_speed_field) {
            (Kinematics::FourWheelSteer, SpinField::WheelSpeedB4) => {
                p.max_angular_radps * p.spin_radius_m
            }
            _ => p.max_lateral_mps,
        };
        let out = Motion {
            linear_mps: lim(m.linear_mps, p.max_linear_mps),
            angular_radps: lim(m.angular_radps, p.max_angular_radps),
            lateral_mps: lim(m.lateral_mps, lateral_max),
            steer_rad: lim(m.steer_rad, steer_max),
        };
        // One wire unit of tolerance: a limit sent rounded to the nearest unit is not beyond it.
        let beyond = |a: f64, b: f64| (a - b).abs() > 0.001;
        if beyond(out.linear_mps, m.linear_mps)
            || beyond(out.angular_radps, m.angular_radps)
            || beyond(out.lateral_mps, m.lateral_mps)
            || beyond(out.steer_rad, m.steer_rad)
        {
            self.commands_clamped += 1;
        }
        out
    }

    fn on_command(&mut self, now: Timestamp, frame: Frame) {
        self.body.received.commands += 1;
        let command_mode = self.mode == Mode::Command;
        match frame {
            Frame::Mode(m) if self.mode != Mode::Remote => {
                self.mode = if m.can { Mode::Command } else { Mode::Standby };
                self.heartbeat_lost = false;
                self.command = STOP;
                self.last_command = m.can.then_some(now);
            }
            Frame::MotionCommand(m) if command_mode => {
                self.last_command = Some(now);
                self.heartbeat_lost = false;
                if self.estop || self.brake_engaged {
                    self.command = STOP;
                    self.body.received.ignored += 1;
                } else {
                    self.command = self.limited(m);
                }
            }
            Frame::ParkingBrake(b) if command_mode && self.profile.brake_lock_value.is_some() => {
                self.brake_engaged = b.engage;
                if b.engage {
                    self.command = STOP;
                }
            }
            Frame::MotionModeCommand(m)
                if command_mode && self.profile.kinematics == Kinematics::FourWheelSteer =>
            {
                match RangerMode::from_code(m.mode, &self.profile) {
                    Some(mode) => {
                        if mode != self.ranger_mode {
                            self.command = STOP;
                            self.applied = STOP;
                        }
                        self.ranger_mode = mode;
                    }
                    None => self.body.received.ignored += 1,
                }
            }
            Frame::LightCommand(l) if command_mode && self.profile.front_light => {
                self.lights = Lights { count: 0, ..l };
            }
            Frame::ClearFault(_) => self.heartbeat_lost = false,
            Frame::VersionRequest => self.send(
                now,
                Frame::Version(Version {
                    controller_hw: [1, 0],
                    driver_hw: [1, 0],
                    controller_sw: [2, 0],
                    driver_sw: [2, 0],
                }),
            ),
            Frame::SdkVersionRequest => {
                for chunk in Self::VERSION_TEXT.chunks_exact(8) {
                    let mut bytes = [0u8; 8];
                    bytes.copy_from_slice(chunk);
                    self.send(now, Frame::VersionText(VersionText { bytes }));
                }
            }
            Frame::SteeringZero if command_mode => {
                self.send(now, Frame::SteeringZeroAck { done: true });
            }
            Frame::SteeringZeroOffset(o) if command_mode => self.steering_offset = o.pulses,
            Frame::SteeringZeroQuery => {
                self.send(
                    now,
                    Frame::SteeringZeroOffsetReply(SteeringZeroOffset {
                        pulses: self.steering_offset,
                    }),
                );
            }
            _ => self.body.received.ignored += 1,
        }
    }

    fn send(&mut self, now: Timestamp, frame: Frame) {
        if self.body.is_quiet(now) {
            return;
        }
        // A value the wire cannot carry (a speed beyond ±32 m/s): nothing to send.
        let encoded = frame.encode(&self.profile);
        self.body
            .outbox
            .push_encoded(encoded, InjectedCounts::default());
    }

    fn next_count(&mut self) -> u8 {
        self.count = self.count.wrapping_add(1);
        self.count
    }

    fn wire_mode(&self) -> u8 {
        let codes = &self.profile.mode_codes;
        match self.mode {
            Mode::Command => codes.can,
            Mode::Remote => codes.rc,
            // ⚠ D-22: firmware without a standby code reports "RC" (0x00) when not commanded.
            Mode::Standby => codes.standby.unwrap_or(codes.rc),
        }
    }

    /// The fault word as the robot's ⚠ D-3 table spells it: "host communication lost" (SDK b4
    /// bit1, HUNTER 2.0 b4 bit4; the TRACER MINI and HUNTER SE tables have no such bit) and the
    /// E-stop bit where ⚠ D-20 reads b5 bit7 so.
    fn fault_word(&self) -> u16 {
        let bit = |set: bool, flag| set.then(|| self.profile.fault_bit_for(flag)).flatten();
        bit(self.heartbeat_lost, FaultFlags::HEARTBEAT_LOST).unwrap_or(0)
            | bit(self.estop, FaultFlags::EMERGENCY_STOP).unwrap_or(0)
    }

    /// The battery's voltage as the electronics alone would load it, V.
    fn battery_v(&self) -> f64 {
        Self::BATTERY.voltage_v(self.body.soc_pct, Self::IDLE_CURRENT_A)
    }

    fn send_status(&mut self, now: Timestamp) {
        let count = self.next_count();
        let frame = Frame::SystemStatus(SystemStatus {
            vehicle_state: if self.estop {
                vehicle::ESTOP
            } else {
                vehicle::NORMAL
            },
            vehicle: "",
            mode: self.wire_mode(),
            control: "",
            battery_voltage_v: (self.battery_v() * 10.0).round() / 10.0,
            fault_word: self.fault_word(),
            b6: u8::from(self.profile.reports_brake_in_b6() && self.brake_engaged),
            count,
        });
        self.send(now, frame);
    }

    fn send_fast(&mut self, now: Timestamp) {
        self.send(now, Frame::MotionFeedback(self.applied));
        if self.rc_on {
            let count = self.next_count();
            self.send(
                now,
                Frame::Rc(RcState {
                    switch_a: 2,
                    switch_b: 1,
                    switch_c: 2,
                    switch_d: 2,
                    counter: count,
                    ..RcState::default()
                }),
            );
        }
        let (vx, _, _) = self.body();
        let rpm = (vx / (2.0 * std::f64::consts::PI * Self::WHEEL_RADIUS_M) * 60.0).round();
        for motor in 1..=self.profile.actuators.min(8) {
            self.send(
                now,
                Frame::MotorFast(MotorFast {
                    motor,
                    rpm: rpm.clamp(-30000.0, 30000.0),
                    current_a: 0.0,
                    position_counts: 0,
                }),
            );
        }
        self.send(
            now,
            Frame::Odometer(Odometer {
                left_m: wrap_mm(self.odometer_m[0]),
                right_m: wrap_mm(self.odometer_m[1]),
            }),
        );
        if self.profile.kinematics == Kinematics::FourWheelSteer {
            let steer = self.applied.steer_rad;
            let angles = match self.ranger_mode {
                RangerMode::DualAckermann => [steer, steer, -steer, -steer],
                RangerMode::Crab => [steer; 4],
                RangerMode::Spin | RangerMode::Park => [0.0; 4],
            };
            self.send(now, Frame::SteeringAngles(Four { values: angles }));
            self.send(
                now,
                Frame::WheelSpeeds(Four {
                    values: [vx.clamp(-30.0, 30.0); 4],
                }),
            );
            if self.profile.motion_mode_feedback
                && let Some(code) = self.ranger_mode.code(&self.profile)
            {
                self.send(
                    now,
                    Frame::MotionModeState(MotionMode {
                        mode: code,
                        changing: false,
                    }),
                );
            }
        }
        if self.profile.front_light {
            let count = self.next_count();
            self.send(
                now,
                Frame::LightState(Lights {
                    count,
                    ..self.lights
                }),
            );
        }
    }

    fn send_slow(&mut self, now: Timestamp) {
        let voltage = (self.battery_v() * 10.0).round() / 10.0;
        let enabled = !self.drive_blocked();
        let bit6 = u8::from(enabled == self.profile.driver_bit6_means_enabled) << 6;
        for motor in 1..=self.profile.actuators.min(8) {
            self.send(
                now,
                Frame::MotorSlow(MotorSlow {
                    motor,
                    driver_voltage_v: voltage,
                    driver_temp_c: 30.0,
                    motor_temp_c: 28.0,
                    driver_status: bit6,
                }),
            );
        }
    }

    fn send_bms(&mut self, now: Timestamp) {
        let lsb = self.profile.bms_voltage_lsb_v;
        self.send(
            now,
            Frame::BmsData(BmsData {
                group: 0,
                soc_pct: self.body.soc_pct.round().clamp(0.0, 100.0),
                soh_pct: 100.0,
                voltage_v: (self.battery_v() / lsb).round() * lsb,
                current_a: 1.0,
                temperature_c: 25.0,
            }),
        );
        self.send(now, Frame::BmsAlarm(BmsAlarm::default()));
    }

    fn fault_flags(&self) -> u64 {
        let mut flags = normalize_faults(self.fault_word(), &self.profile);
        if self.estop {
            flags |= FaultFlags::EMERGENCY_STOP;
        }
        flags
    }
}

impl Firmware for V2Sim {
    fn robot(&self) -> RobotKind {
        self.robot
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        self.expire(now);
        // A booting chassis hears no CAN frame (serial bytes still count as decode errors).
        if self.body.is_booting() && matches!(rx, Rx::Can(_)) {
            return;
        }
        let profile = &self.profile;
        if let Some(command) = self
            .body
            .command(rx, |f| decode(f, profile), Frame::direction)
        {
            self.on_command(now, command);
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        self.expire(now);
        // Nothing is sent, and no rolling count moves, while booting or silenced.
        let quiet = self.body.is_quiet(now);
        if self.status.serve_due(now) && !quiet {
            self.send_status(now);
        }
        if self.fast.serve_due(now) && !quiet {
            self.send_fast(now);
        }
        if self.slow.serve_due(now) && !quiet {
            self.send_slow(now);
        }
        if self.bms.serve_due(now) && !quiet {
            self.send_bms(now);
        }
    }

    fn poll_transmit(&mut self, _now: Timestamp) -> Option<WireItem> {
        self.body.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let grids = self
            .status
            .next()
            .min(self.fast.next())
            .min(self.slow.next())
            .min(self.bms.next());
        let heartbeat = self
            .last_command
            .filter(|_| self.mode == Mode::Command && !self.heartbeat_lost)
            .map(|t| t + Duration::from_millis(self.profile.command_timeout_ms + 1));
        [heartbeat, self.body.poll_timeout()]
            .into_iter()
            .fold(Some(grids), earliest)
    }

    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.expire(now);
        match self.body.inject(now, injection) {
            Applied::Condition | Applied::Done => {}
            Applied::Refused => return false,
            Applied::Robot(Injection::EStop(pressed)) => {
                self.estop = pressed;
                if pressed {
                    self.command = STOP;
                }
            }
            Applied::Robot(Injection::RcTakeover(on)) => {
                self.rc_on = on;
                if on {
                    self.mode = Mode::Remote;
                    self.command = STOP;
                    self.heartbeat_lost = false;
                } else if self.mode == Mode::Remote {
                    self.mode = Mode::Standby;
                }
            }
            Applied::Robot(Injection::Reboot) => {
                self.power_up();
                self.body.reboot(now);
            }
            // No bumper, no range sensors.
            Applied::Robot(_) => return false,
        }
        true
    }

    fn truth(&self) -> SimTruth {
        let (vx, vy, w) = self.body();
        SimTruth {
            linear_mps: vx,
            lateral_mps: vy,
            angular_radps: w,
            steer_rad: self.applied.steer_rad,
            control_mode: self.mode.control_mode(),
            brake_engaged: self.brake_engaged,
            fault_flags: self.fault_flags(),
            ..self.body.truth()
        }
    }
}
