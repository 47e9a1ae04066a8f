//! The XBot driver: a pure state machine over the XBot codec and stream parser.
//!
//! Everything about its behaviour is documented on [`XbotDriver`].

use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{ClampFlags, ControlMode, Group, LinkFlags, Velocity};

use super::codec::{Frame, LiftCommand, PowerCommand, SensorReport, ServoCommand, VelocityCommand};
use super::commands::{frames_for, twist_command};
use super::stream::StreamParser;
use crate::DecodeError;
use crate::command::{Command, Turn};
use crate::driver::{
    ControlOutcome, Driver, DriverConfig, DriverCore, Level, Rx, Unwrap16, WireItem, wrap_angle,
};
use crate::frame_json::frame_name;
use crate::kind::RobotKind;
use crate::time::{Timestamp, earliest};
use crate::xbot::XbotProfile;

/// The manual's bound on the 0x03 rate ("more than 5 Hz and less than 10 Hz"): at most this many
/// velocity frames in any one-second window, heartbeats and command changes together.
pub const MAX_VELOCITY_FRAMES_PER_S: usize = 10;
/// How late a heartbeat may go out and still count at its slot in the rate bound's window.
const HEARTBEAT_JITTER: Duration = Duration::from_millis(5);

/// Heartbeat rate used when the profile's `heartbeat_hz` is not a usable rate (positive, finite,
/// at most 1 kHz).
const FALLBACK_HEARTBEAT_HZ: f64 = 8.0;
const WINDOW: Duration = Duration::from_secs(1);
/// The board's 16-bit µs stamp wraps every 65.536 ms, s.
const STAMP_WRAP_S: f64 = 65_536e-6;
/// Wheel speeds are differences over at least this span of the board's time: closer reports
/// (a flood, a burst) would turn one count of quantisation into a large speed error.
const MIN_SPEED_SPAN: Duration = Duration::from_millis(15);
/// Encoder jump plausibility: a wheel cannot travel faster than this multiple of the top speed
/// (plus [`JUMP_MARGIN_MPS`]) ...
const JUMP_SPEED_FACTOR: f64 = 2.0;
const JUMP_MARGIN_MPS: f64 = 0.5;
/// ... over the receive gap plus this much (one sensor period of timing slack).
const JUMP_SLACK: Duration = Duration::from_millis(20);
/// Least time between two power-enable frames sent to recover a rebooted board.
const POWER_RETRY: Duration = Duration::from_millis(50);

/// Wheel encoders FL, FR, RL, RR and the lift encoder as running counts.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
struct Counters {
    unwrap: [Unwrap16; 5],
    offset: [i64; 5],
    position: [i64; 5],
    started: bool,
}

impl Counters {
    /// Takes the next raw readings. With `continuous` the deltas since the previous readings are
    /// returned; otherwise the readings become a new origin: the running counts carry on from
    /// where they were (a rebooted board restarts its counters at 0) and every delta is 0.
    fn update(&mut self, raw: [u16; 5], continuous: bool) -> [i64; 5] {
        let continuous = continuous && self.started;
        let mut delta = [0; 5];
        for i in 0..5 {
            if !continuous && self.started {
                self.offset[i] = self.position[i] - i64::from(raw[i]);
                self.unwrap[i] = Unwrap16::default();
            }
            let position = self.offset[i] + self.unwrap[i].update(raw[i]);
            if continuous {
                delta[i] = position - self.position[i];
            }
            self.position[i] = position;
        }
        self.started = true;
        delta
    }
}

/// The previous sensor report, for deltas.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Sample {
    at: Timestamp,
    wheels: [u16; 4],
}

/// The report wheel speeds are measured from.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct SpeedRef {
    at: Timestamp,
    stamp_us: u16,
    /// Running wheel counts FL, FR, RL, RR.
    position: [i64; 4],
}

/// The XBot driver: a pure state machine over the XBot codec (RS232 byte stream).
///
/// Sans-IO like every driver: serial bytes go in with their time ([`Driver::handle_rx`], any
/// chunking), frames come out as [`WireItem::Bytes`] ([`Driver::poll_transmit`]), and
/// [`Driver::poll_timeout`] names the next deadline. It never reads a clock.
///
/// # Link
///
/// * **Receive.** The bytes feed a [`StreamParser`]; every good frame is applied. A rejected
///   candidate counts in `state.link.rx_bad_checksum` (bad checksum) or
///   `state.link.rx_decode_errors` (anything else: zero or wrong length, unknown id, wrong marker,
///   undecodable value) and emits [`DriverEvent::RxDropped`](crate::driver::DriverEvent::RxDropped); `state.link.rx_bytes_discarded`
///   always equals the parser's discarded-byte count. A CAN frame counts as a decode error. A
///   command frame (0x01, 0x03, 0x04, 0x05) arriving from the chassis side is a loopback, not
///   feedback: it is dropped and counted in `rx_unknown_id`, and it does not keep the link alive.
/// * **Silence.** No sensor report for `config.silence_timeout_ms` sets
///   `LinkFlags::CHASSIS_SILENT` (with a notice). The real board's report period is not in the
///   manual (it promises "50 Hz or more"); [`super::XbotSim`] reports every 20 ms, so the default
///   100 ms timeout is five missed reports.
///
/// # Heartbeat and the 10 Hz bound
///
/// 0x03 goes out on a fixed grid at `profile.heartbeat_hz` (8 Hz = every 125 ms) through
/// [`CommandSchedule`](crate::driver::CommandSchedule), always, with explicit zeros when there
/// is no command. A changed command goes out at once, between heartbeats — but the manual
/// wants the 0x03 rate **below 10 Hz**, and a mux output changing every millisecond would
/// otherwise send hundreds of frames a second. So a change frame is sent only if every
/// one-second window that contains it still holds at most [`MAX_VELOCITY_FRAMES_PER_S`] (10)
/// velocity frames, counting the frames already sent and the heartbeats still due on the grid:
///
/// * a **stop** (all zero) may take the last slot: it goes out at once unless the window is
///   already full;
/// * any **other change** must leave one slot free for a stop (at 8 Hz: one change frame per
///   second), and keeps `config.min_command_interval_ms` after the previous frame;
/// * a change that may not go out yet rides the next heartbeat (at most 125 ms later), which always
///   carries the latest command, or goes out as soon as a slot frees, whichever is first.
///
/// A heartbeat counts at its slot on the grid even when the service's wake-up sent it a little
/// late (up to 5 ms): counted at its send time, it would share a one-second window with the
/// heartbeat eight slots on, and no change could ever go out between heartbeats.
///
/// So a steady command gives exactly one frame per 125 ms, a command flood gives at most
/// 10 frames in any second, and a stop after a flood of other changes still goes out at once.
/// Two exceptions: [`Driver::shutdown`]'s stop is never held back, and after a suspected board
/// reboot (below) the count starts afresh, since the board saw none of the earlier frames.
///
/// # Power
///
/// * With `config.take_control` the driver sends 0x01 power enable at start. The manual does not
///   say whether the board powers up with drive power on; the driver assumes off (as
///   [`super::XbotSim`] does), so enabling is part of taking control.
/// * [`Command::Power`] `{ enable: false }` disables drive power; from then on the driver sends
///   zero velocity (clamp flag `CHASSIS_NOT_READY`) and never re-enables by itself until
///   [`Command::Power`] `{ enable: true }`.
/// * **Board reboot.** The XBot reports no boot counter. The driver takes two things as evidence
///   of a reboot: (a) the sensor reports return after the link went silent (a reboot takes longer
///   than the silence timeout; a cut cable looks the same and the answer is harmless), and (b) a
///   wheel encoder jumping further than the wheel can travel since the previous report (more than
///   2 × the top speed + 0.5 m/s over the receive gap + 20 ms — a rebooted board restarts its
///   counters at 0). The board's µs stamp is *not* used: it wraps every 65.5 ms, three reports
///   at 50 Hz, so a restarted stamp cannot be told from jitter. On either evidence the driver
///   (while it wants power) re-sends power enable (at most every 50 ms), re-sends the current
///   velocity at once, and re-sends the last lift and servo commands; the encoder readings become
///   a new origin (nothing is bridged across the gap). A reboot shorter than the silence timeout
///   with the wheels within a few thousand counts of 0 goes unnoticed; the next silence or jump
///   catches it.
/// * `state.system.power_enabled` and `control_mode` are **as commanded** (the board reports
///   neither): `COMMAND` (and `LinkFlags::COMMAND_MODE`) while power is enabled, `STANDBY` while
///   it is disabled on request, `UNKNOWN` before any power frame.
///
/// # Sensor report (0x10) → state
///
/// | report | state | group |
/// | --- | --- | --- |
/// | battery voltage | `system.battery_voltage_v` | `System` |
/// | IR rear ×3, ultrasonic front ×3 | `ranges.ir_m`, `ranges.ultrasonic_m` | `Ranges` |
/// | currents FL, FR, RL, RR, lift | `motors[0..4].current_a`, `lift.current_a` | `MotorDrive`, `Lift` |
/// | encoders FL, FR, RL, RR, lift | `motors[0..4].position_counts`, `lift.encoder_counts` (running counts, unwrapped with [`Unwrap16`], continuous across reboots) | `MotorDrive`, `Lift` |
/// | IMU | `imu.*` (sensor axes, as sent), `imu.sensor_stamp_us` | `Imu` |
///
/// `motors[i].rpm` stays 0: the counts per turn are a ⚠ profile choice, so the driver reports
/// wheel speeds (below) rather than a shaft speed. Two-wheel robots report 0 for the rear wheels.
///
/// # Odometry
///
/// The front pair (FL, FR) are the drive wheels of the two-wheel robot; on omni variants, whose
/// roller geometry is not in the manual, the driver still uses the front pair (lateral motion is
/// not estimated from the encoders).
///
/// * Always: `odometry.left_distance_m` / `right_distance_m` (encoder deltas ×
///   `profile.metres_per_count()`, `Odometry`), `motion.wheel_mps` and the axle means
///   (`WheelSpeed`), and `motion.linear_mps` = the mean of the front wheel speeds (`Motion`).
///   Speeds are encoder differences over at least 15 ms of the board's time (so a flood or a burst
///   of reports does not turn one count of quantisation into noise), timed by the board's µs stamp.
///   The stamp wraps every 65.536 ms, so the receive times only choose how many wraps lie between
///   two reports (the count that brings the stamps' difference nearest the receive gap): a report
///   lost to a bad checksum and the next one read late by the host (two reports 40 ms apart on the
///   board, read 53 ms apart) still give the wheels' speed, not three quarters of it. The receive
///   gap may be off by up to half a wrap (32.8 ms) either way; a stamp that did not move between
///   two reports (a board that does not fill it) leaves the receive gap.
/// * With `profile.wheel_separation_m` set: `motion.angular_radps` = (v_right − v_left) / separation,
///   and the pose (`odometry.x_m`, `y_m`, `yaw_rad`, `Pose`) integrated from the encoder
///   displacements (arc midpoint rule; independent of serial timing jitter).
/// * Without it (the manual has no wheel separation): `motion.angular_radps` is the IMU's gyro z
///   (assumes the board is mounted level, z up, as in the simulator) and no pose is published
///   (`Pose` stays invalid).
///
/// # Commands
///
/// * Velocity: [`super::velocity_command`] applies the profile's limits; `state.command` echoes
///   what went on the wire with its clamp flags (`LINEAR_LIMIT`, `ANGULAR_LIMIT`,
///   `LATERAL_UNSUPPORTED`, `QUANTISED`). A steering request (`RequestFlags::STEER` with a non-zero
///   angle) cannot be driven by a robot without steering: zero is sent with `STEER_LIMIT`.
/// * [`Driver::control`]: `Power`, `Lift` (0x04; `state.lift.target_pct`/`enabled`, `Lift`) and
///   `Servos` (0x05; `state.pan_tilt` as the wire carries it, whole degrees, `PanTilt`); every
///   other action is `Unsupported`; `Velocity` and out-of-range arguments are `Invalid`; nothing is
///   accepted while the bus is down (`Refused`).
/// * [`Driver::set_bus_down`]: nothing is sent while down; when the bus returns the parser drops
///   its partial bytes, the heartbeat grid restarts, and the driver resynchronises as after a
///   reboot. [`Driver::shutdown`] sends zero velocity at once; drive power stays on (disabling it
///   would let the wheels free-wheel), and the board holds speed 0 by itself once the heartbeat
///   stops.
///
/// There is no GPS here: the service reads the receiver's NMEA stream separately.
#[derive(Debug, Serialize, Deserialize)]
pub struct XbotDriver {
    profile: XbotProfile,
    config: DriverConfig,
    core: DriverCore,
    parser: StreamParser,
    /// Frames to send: empty between passes, the only time a snapshot is taken.
    #[serde(skip)]
    queue: VecDeque<Frame>,

    // Velocity.
    /// The latest command from the mux.
    twist: Velocity,
    /// What the next 0x03 carries.
    desired: VelocityCommand,
    desired_flags: u32,
    /// What the last 0x03 carried (`None`: the board's command is unknown, e.g. after a reboot).
    on_wire: Option<VelocityCommand>,
    /// The schedule was told about the change (the rate bound allowed it).
    change_released: bool,
    /// When to check again whether a held-back change may go out.
    release_at: Option<Timestamp>,
    /// Send times of the 0x03 frames of the last second.
    sent_log: VecDeque<Timestamp>,
    /// The heartbeat slot the schedule serves next (mirrors its grid).
    next_heartbeat: Timestamp,

    // Power and the other actuators.
    want_power: bool,
    /// Drive power as last commanded since the board's last (detected) boot.
    power: Option<bool>,
    last_power_enable: Option<Timestamp>,
    last_lift: Option<LiftCommand>,
    last_servos: Option<ServoCommand>,

    // Feedback.
    counters: Counters,
    last_sample: Option<Sample>,
    speed_ref: Option<SpeedRef>,
    /// The next report is a new origin (after a silence or the bus returning).
    resync_pending: bool,
}

impl XbotDriver {
    /// A driver starting at `now`. With `config.take_control` it enables drive power at once.
    pub fn new(profile: XbotProfile, config: DriverConfig, now: Timestamp) -> Self {
        let (hz, period) = match Duration::try_from_secs_f64(1.0 / profile.heartbeat_hz) {
            Ok(period) if profile.heartbeat_hz > 0.0 && period >= Duration::from_millis(1) => {
                (profile.heartbeat_hz, period)
            }
            _ => (FALLBACK_HEARTBEAT_HZ, Duration::from_millis(125)),
        };
        let mut driver = Self {
            core: DriverCore::new(RobotKind::Xbot.id(), period, &config, now),
            parser: StreamParser::new(),
            queue: VecDeque::new(),
            twist: Velocity::ZERO,
            desired: VelocityCommand::default(),
            desired_flags: 0,
            on_wire: None,
            change_released: false,
            release_at: None,
            sent_log: VecDeque::new(),
            next_heartbeat: now,
            want_power: config.take_control,
            power: None,
            last_power_enable: None,
            last_lift: None,
            last_servos: None,
            counters: Counters::default(),
            last_sample: None,
            speed_ref: None,
            resync_pending: false,
            profile,
            config,
        };
        let asked = driver.profile.heartbeat_hz;
        if !(asked > 5.0 && asked < 10.0) {
            driver.core.notice(
                Level::Warn,
                format!(
                    "heartbeat_hz = {asked} is outside the manual's 5-10 Hz; sending at {hz} Hz"
                ),
            );
        }
        driver.update_power_state(now);
        if driver.want_power {
            driver.send_power(now, true);
        }
        driver.try_release(now);
        driver
    }

    pub fn profile(&self) -> &XbotProfile {
        &self.profile
    }

    // -----------------------------------------------------------------------------------------
    // Power.

    fn send_power(&mut self, now: Timestamp, enable: bool) {
        self.queue.push_back(Frame::Power(PowerCommand { enable }));
        self.power = Some(enable);
        if enable {
            self.last_power_enable = Some(now);
        }
        self.update_power_state(now);
    }

    fn update_power_state(&mut self, now: Timestamp) {
        let mode = match self.power {
            Some(true) => ControlMode::COMMAND,
            Some(false) => ControlMode::STANDBY,
            None => ControlMode::UNKNOWN,
        };
        let sys = &mut self.core.state.system;
        sys.power_enabled = u8::from(self.power == Some(true));
        sys.control_mode = mode;
        self.core
            .set_flag(LinkFlags::COMMAND_MODE, mode == ControlMode::COMMAND);
        // The group also holds the battery voltage: it turns valid with the first report.
        if self.core.state.is_valid(Group::System) {
            self.core.state.touch(Group::System, now.as_nanos());
        }
    }

    /// The board may have rebooted: take it back as after power-up.
    fn resync(&mut self, now: Timestamp, why: &str) {
        if self.want_power
            && self
                .last_power_enable
                .is_none_or(|t| now.saturating_since(t) >= POWER_RETRY)
        {
            self.send_power(now, true);
        }
        let power = if self.want_power {
            "re-enabled"
        } else {
            "left as requested"
        };
        self.core.notice(
            Level::Warn,
            format!("{why}: the board may have rebooted; drive power {power}"),
        );
        self.queue.extend(self.last_lift.map(Frame::Lift));
        self.queue.extend(self.last_servos.map(Frame::Servos));
        // A rebooted board has no command: send ours again at once. It saw none of the frames
        // sent before it came back, so the one-second count starts afresh.
        self.sent_log.clear();
        self.on_wire = None;
        self.plan(now);
    }

    // -----------------------------------------------------------------------------------------
    // Velocity.

    /// Recomputes the velocity to send from the latest command.
    fn plan(&mut self, now: Timestamp) {
        let c = self.twist;
        let twist = |angular: f64| {
            twist_command(
                c.linear_x_mps().into(),
                c.linear_y_mps().into(),
                angular,
                &self.profile,
            )
        };
        let (mut velocity, mut flags) = match Turn::of(&c) {
            Turn::Steer(steer) if steer != 0.0 => {
                (VelocityCommand::default(), ClampFlags::STEER_LIMIT)
            }
            Turn::Steer(_) => twist(0.0),
            Turn::YawRate(angular) => twist(angular),
        };
        if self.power == Some(false) && velocity != VelocityCommand::default() {
            velocity = VelocityCommand::default();
            flags |= ClampFlags::CHASSIS_NOT_READY;
        }
        self.desired = velocity;
        self.desired_flags = flags;
        self.try_release(now);
    }

    fn change_pending(&self) -> bool {
        self.on_wire != Some(self.desired)
    }

    fn prune(&mut self, now: Timestamp) {
        while self.sent_log.front().is_some_and(|&t| t + WINDOW <= now) {
            self.sent_log.pop_front();
        }
    }

    /// True when one more 0x03 at `now` (before the next heartbeat) keeps every one-second
    /// window containing it at or below `limit` frames, counting the frames sent and the
    /// heartbeats still due.
    fn extra_fits(&self, now: Timestamp, limit: usize) -> bool {
        let recent_after = |t: Timestamp| self.sent_log.iter().filter(|&&p| p + WINDOW > t).count();
        // The window starting just after `now - 1 s`.
        let mut worst = recent_after(now) + 1;
        // The windows ending just after each heartbeat still due within a second.
        let period = self.core.schedule.period();
        let mut heartbeat = self.next_heartbeat.max(now + Duration::from_nanos(1));
        let mut due = 0;
        while heartbeat < now + WINDOW {
            due += 1;
            worst = worst.max(recent_after(heartbeat) + 1 + due);
            heartbeat += period;
        }
        worst <= limit
    }

    /// Lets a pending change go out now if the rate bound allows, else notes when to look again.
    fn try_release(&mut self, now: Timestamp) {
        self.release_at = None;
        if self.core.bus_down || self.change_released || !self.change_pending() {
            return;
        }
        self.prune(now);
        let stop = self.desired == VelocityCommand::default();
        if !stop && let Some(&last) = self.sent_log.back() {
            let earliest_change = last + Duration::from_millis(self.config.min_command_interval_ms);
            if now < earliest_change {
                self.release_at = Some(earliest_change);
                return;
            }
        }
        let limit = if stop {
            MAX_VELOCITY_FRAMES_PER_S
        } else {
            MAX_VELOCITY_FRAMES_PER_S.saturating_sub(1)
        };
        if self.extra_fits(now, limit) {
            self.core.schedule.command_changed(stop);
            self.change_released = true;
        } else {
            // A slot frees when the oldest frame leaves the window; the heartbeat may come first.
            self.release_at = self.sent_log.front().map(|&t| t + WINDOW);
        }
    }

    fn velocity_sent(&mut self, now: Timestamp) {
        self.prune(now);
        // A heartbeat counts at its slot on the grid: sent a little late (the service's
        // wake-up), it would otherwise share a one-second window with the heartbeat eight slots
        // on, and no change could ever go out between heartbeats.
        let logged = match self.core.schedule.heartbeat_slot(now) {
            Some(slot) if now.saturating_since(slot) <= HEARTBEAT_JITTER => slot,
            _ => now,
        };
        self.core.schedule.sent(now);
        // No change is pending in the schedule now, so its deadline is the next heartbeat.
        self.next_heartbeat = self.core.schedule.deadline();
        self.on_wire = Some(self.desired);
        self.change_released = false;
        self.release_at = None;
        self.sent_log.push_back(logged);
        let echo = &mut self.core.state.command;
        echo.linear_mps = self.desired.linear_x_mps as f32;
        echo.lateral_mps = self.desired.linear_y_mps as f32;
        echo.angular_radps = self.desired.angular_z_radps as f32;
        echo.steer_rad = 0.0;
        echo.clamp_flags = self.desired_flags;
        self.core.state.touch(Group::Command, now.as_nanos());
    }

    // -----------------------------------------------------------------------------------------
    // Feedback.

    fn on_frame(&mut self, now: Timestamp, frame: Frame) {
        let Frame::Sensor(report) = frame else {
            self.core.state.link.rx_unknown_id += 1;
            self.core.dropped(format!(
                "a {} command (0x{:02X}) from the chassis side: loopback?",
                frame_name(&frame),
                frame.command_id()
            ));
            return;
        };
        if self.core.feedback(now) {
            self.resync(now, "sensor reports are back after a silence");
        }
        self.apply_sensor(now, &report);
    }

    fn on_error(&mut self, error: &DecodeError, what: String) {
        match error {
            DecodeError::BadChecksum { .. } => self.core.state.link.rx_bad_checksum += 1,
            _ => self.core.state.link.rx_decode_errors += 1,
        }
        self.core.dropped(what);
    }

    /// True when a wheel moved further since the previous report than it physically can.
    fn implausible_jump(&self, now: Timestamp, previous: &Sample, wheels: &[u16; 4]) -> bool {
        let elapsed = now.saturating_since(previous.at) + JUMP_SLACK;
        let speed = JUMP_SPEED_FACTOR * self.profile.max_linear_mps + JUMP_MARGIN_MPS;
        let limit = speed * elapsed.as_secs_f64() / self.profile.metres_per_count();
        wheels
            .iter()
            .zip(previous.wheels)
            .any(|(&now_raw, before)| f64::from(now_raw.wrapping_sub(before) as i16).abs() > limit)
    }

    fn apply_sensor(&mut self, now: Timestamp, s: &SensorReport) {
        let t = now.as_nanos();
        self.core.state.system.battery_voltage_v = s.battery_voltage_v as f32;
        self.core.state.touch(Group::System, t);

        let ranges = &mut self.core.state.ranges;
        ranges.ir_m = s.ir_m.map(|r| r as f32);
        ranges.ultrasonic_m = s.ultrasonic_m.map(|r| r as f32);
        self.core.state.touch(Group::Ranges, t);

        let imu = &mut self.core.state.imu;
        imu.accel_mps2 = s.accel_mps2.map(|v| v as f32);
        imu.gyro_radps = s.gyro_radps.map(|v| v as f32);
        imu.mag_gauss = s.mag_gauss.map(|v| v as f32);
        imu.roll_rad = s.roll_rad as f32;
        imu.pitch_rad = s.pitch_rad as f32;
        imu.yaw_rad = s.yaw_rad as f32;
        imu.temperature_c = s.temperature_c as f32;
        imu.sensor_stamp_us = s.sensor_stamp_us.into();
        self.core.state.touch(Group::Imu, t);

        // Encoders: continuity, reboot evidence, running counts.
        let wheels = s.encoder_counts;
        let previous = self.last_sample.filter(|_| !self.resync_pending);
        let jumped = previous.is_some_and(|p| self.implausible_jump(now, &p, &wheels));
        if jumped {
            self.resync(
                now,
                "wheel encoders jumped further than the wheels can travel",
            );
        }
        let continuous = previous.is_some() && !jumped;
        self.resync_pending = false;
        let [fl, fr, rl, rr] = wheels;
        let delta = self
            .counters
            .update([fl, fr, rl, rr, s.lift_encoder_counts], continuous);
        for (i, motor) in self.core.state.motors.iter_mut().enumerate() {
            motor.position_counts = self.counters.position[i];
            motor.current_a = s.motor_current_a[i] as f32;
        }
        self.core.state.touch(Group::MotorDrive, t);
        let lift = &mut self.core.state.lift;
        lift.encoder_counts = self.counters.position[4];
        lift.current_a = s.lift_current_a as f32;
        self.core.state.touch(Group::Lift, t);

        let metres = self.profile.metres_per_count();
        let [left, right] = [0, 1].map(|i| delta[i] as f64 * metres);
        let odometry = &mut self.core.state.odometry;
        odometry.left_distance_m += left;
        odometry.right_distance_m += right;
        self.core.state.touch(Group::Odometry, t);

        let position = [0, 1, 2, 3].map(|i| self.counters.position[i]);
        let here = SpeedRef {
            at: now,
            stamp_us: s.sensor_stamp_us,
            position,
        };
        match self.speed_ref.filter(|_| continuous) {
            Some(from) => {
                let dt = sample_interval(now, from.at, from.stamp_us, s.sensor_stamp_us);
                if dt >= MIN_SPEED_SPAN.as_secs_f64() {
                    let speeds =
                        [0, 1, 2, 3].map(|i| (position[i] - from.position[i]) as f64 * metres / dt);
                    self.apply_speeds(now, speeds, s.gyro_radps[2]);
                    self.speed_ref = Some(here);
                }
            }
            None => self.speed_ref = Some(here),
        }
        if continuous && let Some(separation) = self.separation() {
            integrate_arc(left, right, separation, &mut self.core.state.odometry);
        }
        if self.separation().is_some() {
            self.core.state.touch(Group::Pose, t);
        }
        self.last_sample = Some(Sample { at: now, wheels });
    }

    /// The wheel separation when the profile has a usable one.
    fn separation(&self) -> Option<f64> {
        self.profile
            .wheel_separation_m
            .filter(|s| s.is_finite() && *s > 0.0)
    }

    fn apply_speeds(&mut self, now: Timestamp, wheel_mps: [f64; 4], gyro_z_radps: f64) {
        let t = now.as_nanos();
        let [fl, fr, rl, rr] = wheel_mps;
        let motion = &mut self.core.state.motion;
        motion.wheel_mps = wheel_mps.map(|v| v as f32);
        motion.front_axle_mps = (0.5 * (fl + fr)) as f32;
        motion.rear_axle_mps = (0.5 * (rl + rr)) as f32;
        self.core.state.touch(Group::WheelSpeed, t);
        let angular = match self.separation() {
            Some(separation) => (fr - fl) / separation,
            None => gyro_z_radps,
        };
        let motion = &mut self.core.state.motion;
        motion.linear_mps = (0.5 * (fl + fr)) as f32;
        motion.angular_radps = angular as f32;
        motion.lateral_mps = 0.0;
        motion.steer_rad = 0.0;
        self.core.state.touch(Group::Motion, t);
    }
}

/// Seconds between two reports on the board's clock: the difference of its µs stamps plus the
/// whole wraps that bring it nearest the receive gap; the receive gap if the stamp did not move.
fn sample_interval(now: Timestamp, before: Timestamp, stamp_before: u16, stamp_us: u16) -> f64 {
    let received = now.saturating_since(before).as_secs_f64();
    let ticks_us = stamp_us.wrapping_sub(stamp_before);
    if ticks_us == 0 {
        return received;
    }
    let stamped = f64::from(ticks_us) * 1e-6;
    let wraps = ((received - stamped) / STAMP_WRAP_S).round().max(0.0);
    stamped + wraps * STAMP_WRAP_S
}

/// Adds the arc driven by a differential drive whose left and right wheels travelled
/// `left_m` and `right_m` (midpoint heading).
fn integrate_arc(
    left_m: f64,
    right_m: f64,
    separation_m: f64,
    odometry: &mut chassis_interfaces::OdometryState,
) {
    let distance = 0.5 * (left_m + right_m);
    let turn = (right_m - left_m) / separation_m;
    let heading = odometry.yaw_rad + 0.5 * turn;
    let (sin, cos) = heading.sin_cos();
    odometry.x_m += distance * cos;
    odometry.y_m += distance * sin;
    odometry.yaw_rad = wrap_angle(odometry.yaw_rad + turn);
}

impl Driver for XbotDriver {
    crate::snapshot::whole_driver!(queue);

    fn robot(&self) -> RobotKind {
        RobotKind::Xbot
    }

    crate::driver::core_accessors!();

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        let Rx::Bytes(bytes) = rx else {
            self.core
                .wrong_medium("a CAN frame on the XBot's serial link");
            return;
        };
        // Collected first: applying a frame needs the whole driver, the parser included.
        let items: Vec<_> = self.parser.feed(bytes, &self.profile).collect();
        for item in items {
            match item {
                Ok(frame) => self.on_frame(now, frame),
                Err(err) => self.on_error(&err.error, err.to_string()),
            }
        }
        self.core.state.link.rx_bytes_discarded = self.parser.bytes_discarded();
    }

    fn set_command(&mut self, now: Timestamp, command: &Velocity) {
        self.twist = *command;
        self.plan(now);
    }

    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        let planned = crate::driver::admit!(self.core, command, |c| frames_for(c, &self.profile));
        let t = now.as_nanos();
        let mut outcome = ControlOutcome::Done(format!("{} sent", command.name()));
        for frame in planned.frames {
            match frame {
                Frame::Power(p) => {
                    self.want_power = p.enable;
                    self.send_power(now, p.enable);
                    // Re-plan: disabling sends zero; enabling sends the command again at once (a
                    // disabled board forgot it).
                    self.on_wire = None;
                    self.plan(now);
                    outcome = ControlOutcome::Done(if p.enable {
                        "drive power enabled".into()
                    } else {
                        "drive power disabled; zero velocity is sent until it is enabled again"
                            .into()
                    });
                }
                Frame::Lift(l) => {
                    self.last_lift = Some(l);
                    let lift = &mut self.core.state.lift;
                    lift.enabled = u8::from(l.enable);
                    lift.target_pct = l.position_pct as f32;
                    self.core.state.touch(Group::Lift, t);
                    self.queue.push_back(frame);
                    outcome = ControlOutcome::Done(format!(
                        "lift {} to {:.0} %",
                        if l.enable { "enabled" } else { "disabled" },
                        l.position_pct
                    ));
                }
                Frame::Servos(s) => {
                    // As the wire carries it: whole degrees.
                    let pan = (90.0 - (90.0 - s.pan_rad.to_degrees()).round()).to_radians();
                    let tilt = ((90.0 + s.tilt_rad.to_degrees()).round() - 90.0).to_radians();
                    self.last_servos = Some(s);
                    self.core.state.pan_tilt.pan_rad = pan as f32;
                    self.core.state.pan_tilt.tilt_rad = tilt as f32;
                    self.core.state.touch(Group::PanTilt, t);
                    self.queue.push_back(frame);
                    outcome = ControlOutcome::Done(format!(
                        "pan {:.0}°, tilt {:.0}°",
                        pan.to_degrees(),
                        tilt.to_degrees()
                    ));
                }
                // `frames_for` plans these only for motion, refused above.
                Frame::Velocity(_) | Frame::Sensor(_) => {}
            }
        }
        outcome
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        if self.core.check_silence(now, "sensor report") {
            self.resync_pending = true;
        }
        if self.release_at.is_some_and(|t| now >= t) {
            self.try_release(now);
        }
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        if self.core.bus_down {
            self.queue.clear();
            return None;
        }
        let frame = if let Some(frame) = self.queue.pop_front() {
            frame
        } else if self.core.schedule.is_due(now) {
            self.velocity_sent(now);
            Frame::Velocity(self.desired)
        } else {
            return None;
        };
        self.core
            .transmit(&frame, frame.encode(&self.profile), WireItem::Bytes)
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        earliest(Some(self.core.poll_timeout()?), self.release_at)
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        if !self.core.set_bus_down(now, down) {
            return;
        }
        self.queue.clear();
        if down {
            self.release_at = None;
            self.change_released = false;
        } else {
            self.parser.clear();
            self.core.state.link.rx_bytes_discarded = self.parser.bytes_discarded();
            self.next_heartbeat = now;
            self.resync_pending = true;
            self.last_power_enable = None;
            self.resync(now, "the bus is back");
        }
    }

    fn shutdown(&mut self, now: Timestamp) {
        self.twist = Velocity::ZERO;
        self.plan(now);
        self.queue.clear();
        // The one frame exempt from the rate bound: a final stop is never held back.
        self.core.schedule.command_changed(true);
        self.change_released = true;
        self.release_at = None;
    }
}

#[cfg(test)]
#[path = "driver_tests.rs"]
mod driver_tests;
