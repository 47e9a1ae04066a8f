//! The simulated XBot board: the chassis side of the serial link, built on the XBot codec.
//!
//! Everything about its behaviour is documented on [`XbotSim`].

use std::time::Duration;

use chassis_interfaces::ControlMode;

use super::codec::{Frame, SensorReport, VelocityCommand, scale};
use super::stream::StreamParser;
use crate::DecodeError;
use crate::driver::{Rx, WireItem};
use crate::firmware::{
    Applied, BatteryModel, Firmware, InjectedCounts, Injection, MotorModel, SimBody, SimBodySpec,
    SimTruth, first_order_lag, past_timeout,
};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp, earliest};
use crate::xbot::XbotProfile;

/// The simulated XBot board: the chassis side of the RS232 link, built on the XBot codec.
///
/// [`XbotSim`] is sans-IO like the driver: bytes from the computer go in with their time
/// ([`Firmware::handle_rx`], any chunking; a [`StreamParser`] finds the frames), sensor reports
/// come out as [`WireItem::Bytes`] ([`Firmware::poll_transmit`]), and [`Firmware::poll_timeout`]
/// names the next deadline. It never reads a clock. Every frame in either direction goes through
/// the codec, so the profile's ⚠ choices (yaw-rate and lateral signs, BCD currents and ranges,
/// counts per wheel turn) are honoured on this side too.
///
/// # The manual's rules, as enforced
///
/// * **0x03 velocity** is the heartbeat: more than `command_timeout_ms` (500 ms) without one sets
///   the commanded speed to 0 (the board stays powered; the next 0x03 drives again). Speeds are
///   limited to the profile's `max_linear_mps` (1.5 m/s: the largest wheel target is scaled down,
///   keeping the turn's shape); a linear or lateral speed below `min_linear_mps` (0.01 m/s) is
///   executed as 0. The lateral speed moves only omni variants (`profile.omni`).
/// * **0x01 power**: disabled → the wheels stop (and their currents read 0); the stored command is
///   dropped, so after enabling, motion needs a fresh 0x03.
/// * **0x04 lift**: while enabled the platform moves toward the position (0 bottom, 100 top) at
///   [`XbotSim::LIFT_PCT_PER_S`]; disabled, it stops where it is. **0x05 servos** take the angles
///   at once (the board reports neither back).
/// * **Malformed input** (bad checksum, bad length or value, unknown id, a CAN frame) is counted
///   in [`SimTruth::bad_checksums_received`] / [`SimTruth::decode_errors`] and ignored, never a
///   panic; a sensor report sent *to* the board is ignored ([`SimTruth::frames_ignored`]).
///
/// # Sensor report (0x10)
///
/// Every [`XbotSim::REPORT_PERIOD`] (20 ms, 50 Hz — the manual promises "50 Hz or more" and names
/// no period) on a fixed grid anchored at construction or at the end of a boot; a late call skips
/// missed slots rather than bursting.
///
/// | field | simulated as |
/// | --- | --- |
/// | battery | 24 V-class pack, open-circuit 23.0 V (0 %) to 26.0 V (100 %), 0.05 Ω, 26 Ah (2 × 13 Ah, the spec sheet); draws 1.0 A idle + every motor current; BCD on the wire |
/// | IR rear ×3 | [`XbotSim::NOTHING_SEEN_IR_M`] (0.80 m) normally; [`Injection::ObstacleBehind`] `(Some(d))`: centre `d`, sides `d / cos 30°` |
/// | ultrasonic front ×3 | [`XbotSim::NOTHING_SEEN_ULTRASONIC_M`] (6.00 m, or 0.999 m when the profile reads them as BCD, whose 4 digits stop there); [`Injection::ObstacleAhead`] likewise |
/// | motor currents | per fitted wheel `|1.5 A/(m/s)·v + 3 A/(m/s²)·a| + 0.3 A` while powered, 0 A unpowered or for a lost driver, at most 15 A; lift 0.6 A moving, 0.1 A holding, 0 A disabled |
/// | encoders | wheel travel since boot ÷ `profile.metres_per_count()` (8000 counts per turn of the 0.2 m wheel), wrapping at 65536; the lift 100 counts per % since boot; the codec puts them on the wire as FL, FR, back-right, back-left |
/// | IMU | level, z up: accel (forward acceleration, centripetal v·ω, +1 g), gyro (0, 0, true yaw rate), mag (0.3 cos ψ, −0.3 sin ψ, −0.4) gauss, 31.5 °C, yaw = true heading (0.1°), pitch = roll = 0 |
/// | timestamp | µs since the end of the last boot, wrapping at 65536 |
///
/// The simulator does **not** stop for obstacles: the safety monitor does that.
///
/// # Choices where the manual is silent
///
/// * **Wheel separation**: `profile.wheel_separation_m`, or [`XbotSim::DEFAULT_WHEEL_SEPARATION_M`]
///   (0.45 m, the `bias` of the vendor's later ROS driver — not a measurement) when unset.
/// * **Drive**: each wheel follows a first-order lag toward its target with time constant
///   [`XbotSim::DEFAULT_SPEED_TIME_CONSTANT_S`] (0.2 s), and [`XbotSim::DEFAULT_STOP_TIME_CONSTANT_S`]
///   (0.1 s) toward zero while drive is blocked (power off, booting, a lost motor driver).
///   Two-wheel robots: differential kinematics, rear encoders and currents read 0. Omni variants:
///   four mecanum wheels in X configuration with the yaw term `ω·separation/2` (the wheelbase is not
///   modelled).
/// * **Power-up**: drive power **off** (the manual has a power-enable command and says nothing of
///   the state at power-up; the conservative reading), no command, lift disabled where it is,
///   servos at 90°/90° (the manual), encoders and the timestamp at 0. [`XbotSim::new`] starts
///   already booted.
/// * **Reboot** ([`Injection::Reboot`]): the board is silent and ignores every frame for
///   [`XbotSim::DEFAULT_BOOT_TIME`] (300 ms), then powers up as above. The true pose, the battery,
///   lost motor drivers and obstacles are physical and survive; the [`SimTruth`] counters keep
///   counting.
/// * **Injections**: `MotorDriverLoss { motor 1-4 }` stops drive while any driver is lost (rear
///   motors exist only on omni variants; otherwise `false`). `Battery` sets the state of charge.
///   `RcTakeover` and `Bumper` return `false`: the XBot's serial protocol has neither.
///   `Silence(d)` transmits nothing for `d` (commands are still obeyed). `Garbage(bytes)` puts the
///   bytes on the wire at once, as is, even while silent (line noise). `BadChecksums(n)` flips the
///   checksum of the next `n` reports (injections add up). [`SimTruth::injected`] counts the
///   garbage, corrupted and flood reports as they leave. `Flood { frames_per_s }` adds that many extra reports per
///   second (at most what the line carries at the profile's baud rate, 10 bits a byte; 0 stops it).
///   Silence, flood, pending corruptions and obstacles survive a reboot.
#[derive(Debug)]
pub struct XbotSim {
    profile: XbotProfile,
    // Options.
    wheel_separation_m: f64,
    tx_chunk_len: usize,

    // Control state.
    parser: StreamParser,
    powered: bool,
    /// The command being executed (ISO, limited); zero after a timeout or power-off.
    command: VelocityCommand,
    heartbeat_alive: bool,
    last_velocity_rx: Timestamp,
    /// Origin of the board's µs timestamp and of the encoder counts: the end of the last boot.
    booted_at: Timestamp,
    obstacle_ahead_m: Option<f64>,
    obstacle_behind_m: Option<f64>,
    lift_enabled: bool,
    lift_target_pct: f64,
    pan_rad: f64,
    tilt_rad: f64,

    // Physics.
    /// Wheel speeds FL, FR, RL, RR, m/s (two-wheel robots: only FL, FR).
    wheel_mps: [f64; 4],
    forward_accel_mps2: f64,
    /// Wheel travel since the last boot, m.
    wheel_travel_m: [f64; 4],
    lift_pct: f64,
    lift_pct_at_boot: f64,
    lift_moving: bool,
    motor_current_a: [f64; 4],
    lift_current_a: f64,

    // Output.
    reports: Grid,
    /// What every simulated chassis shares: the outbox, the boot, the battery, the pose, the
    /// injected faults and the counts of what it received.
    body: SimBody<Vec<u8>>,

    // Counters.
    reports_sent: u64,
    reports_corrupted: u64,
    heartbeat_timeouts: u64,
}

impl XbotSim {
    /// Period of the sensor report.
    pub const REPORT_PERIOD: Duration = Duration::from_millis(20);
    /// Wheel separation when the profile has none, m (not in the manual).
    pub const DEFAULT_WHEEL_SEPARATION_M: f64 = 0.45;
    /// Time constant of the wheel speed response, s.
    pub const DEFAULT_SPEED_TIME_CONSTANT_S: f64 = 0.2;
    /// Time constant of the wheel speed response while drive is blocked, s.
    pub const DEFAULT_STOP_TIME_CONSTANT_S: f64 = 0.1;
    /// Silence after a reboot.
    pub const DEFAULT_BOOT_TIME: Duration = Duration::from_millis(300);
    /// IR range with nothing in view, m.
    pub const NOTHING_SEEN_IR_M: f64 = 0.80;
    /// Ultrasonic range with nothing in view, m (binary ranges; see the type docs for BCD).
    pub const NOTHING_SEEN_ULTRASONIC_M: f64 = 6.00;
    /// Largest ultrasonic range four BCD digits of 0.1 cm carry, m.
    const NOTHING_SEEN_ULTRASONIC_BCD_M: f64 = 0.999;
    /// Side rangers look 30° off the centre line: a wall at `d` reads `d / cos 30°` on them.
    pub const SIDE_RANGE_FACTOR: f64 = 1.154_700_538_379_251_5;
    /// Lift speed, % of travel per second.
    pub const LIFT_PCT_PER_S: f64 = 10.0;
    /// Lift encoder counts per % of travel.
    pub const LIFT_COUNTS_PER_PCT: f64 = 100.0;
    /// The battery.
    pub const BATTERY: BatteryModel = BatteryModel {
        capacity_ah: 26.0,
        full_v: 26.0,
        empty_v: 23.0,
        resistance_ohm: 0.05,
    };
    /// Current of the electronics, A.
    pub const IDLE_CURRENT_A: f64 = 1.0;
    /// Motor current: 1.5 A per m/s of wheel speed, 3 A per m/s² of wheel acceleration, at most
    /// 15 A (the spec sheet's largest working current).
    pub const MOTOR: MotorModel = MotorModel {
        a_per_mps: 1.5,
        a_per_mps2: 3.0,
        limit_a: 15.0,
    };
    /// Motor current while powered and standing, A.
    pub const MOTOR_HOLD_A: f64 = 0.3;
    /// Lift motor current while moving, A (the manual's example report).
    pub const LIFT_MOVING_A: f64 = 0.6;
    /// Lift motor current while enabled and holding, A.
    pub const LIFT_HOLD_A: f64 = 0.1;
    /// IMU temperature, °C.
    pub const IMU_TEMPERATURE_C: f64 = 31.5;
    /// Horizontal and vertical components of the simulated Earth field, gauss.
    const MAG_HORIZONTAL_GAUSS: f64 = 0.3;
    const MAG_VERTICAL_GAUSS: f64 = -0.4;
    /// Bytes of one sensor report on the wire.
    const REPORT_LEN: u32 = 75;

    /// A board that has just finished booting at `now`: drive power off, SOC 100 %.
    pub fn new(profile: XbotProfile, now: Timestamp) -> Self {
        let wheel_separation_m = profile
            .wheel_separation_m
            .filter(|s| s.is_finite() && *s > 0.0)
            .unwrap_or(Self::DEFAULT_WHEEL_SEPARATION_M);
        let body = SimBody::new(
            SimBodySpec {
                motors: wheel_count(&profile),
                max_flood_per_s: line_reports_per_s(&profile),
                checksums: true,
                boot_time: Self::DEFAULT_BOOT_TIME,
                battery: Self::BATTERY,
                idle_current_a: Self::IDLE_CURRENT_A,
            },
            now,
        );
        Self {
            profile,
            wheel_separation_m,
            tx_chunk_len: 0,
            parser: StreamParser::new(),
            powered: false,
            command: VelocityCommand::default(),
            heartbeat_alive: false,
            last_velocity_rx: now,
            booted_at: now,
            obstacle_ahead_m: None,
            obstacle_behind_m: None,
            lift_enabled: false,
            lift_target_pct: 0.0,
            pan_rad: 0.0,
            tilt_rad: 0.0,
            wheel_mps: [0.0; 4],
            forward_accel_mps2: 0.0,
            wheel_travel_m: [0.0; 4],
            lift_pct: 0.0,
            lift_pct_at_boot: 0.0,
            lift_moving: false,
            motor_current_a: [0.0; 4],
            lift_current_a: 0.0,
            reports: Grid::new(Self::REPORT_PERIOD, now),
            body,
            reports_sent: 0,
            reports_corrupted: 0,
            heartbeat_timeouts: 0,
        }
    }

    /// Silence after a reboot (zero: the board answers at once).
    pub fn with_boot_time(mut self, boot_time: Duration) -> Self {
        self.body.set_boot_time(boot_time);
        self
    }

    /// Splits every frame into chunks of at most `len` bytes, as a UART read may return them
    /// (0: whole frames).
    pub fn with_tx_chunk_len(mut self, len: usize) -> Self {
        self.tx_chunk_len = len;
        self
    }

    pub fn profile(&self) -> &XbotProfile {
        &self.profile
    }

    /// The wheel separation the physics uses, m.
    pub fn wheel_separation_m(&self) -> f64 {
        self.wheel_separation_m
    }

    /// True while drive power is enabled.
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// True while the board boots after a reboot.
    pub fn is_booting(&self) -> bool {
        self.body.is_booting()
    }

    /// The lift's position and target, % of travel.
    pub fn lift_pct(&self) -> (f64, f64) {
        (self.lift_pct, self.lift_target_pct)
    }

    pub fn lift_enabled(&self) -> bool {
        self.lift_enabled
    }

    /// Pan and tilt, rad (ISO: pan left positive, tilt up positive, 0 ahead).
    pub fn servos_rad(&self) -> (f64, f64) {
        (self.pan_rad, self.tilt_rad)
    }

    /// Wheel speeds FL, FR, RL, RR, m/s.
    pub fn wheel_mps(&self) -> [f64; 4] {
        self.wheel_mps
    }

    /// Signed wheel travel FL, FR, RL, RR since the last boot, m (what the encoders count).
    pub fn wheel_travel_m(&self) -> [f64; 4] {
        self.wheel_travel_m
    }

    /// Motor currents FL, FR, RL, RR, A.
    pub fn motor_current_a(&self) -> [f64; 4] {
        self.motor_current_a
    }

    /// Sensor reports put on the wire (corrupted ones included).
    pub fn reports_sent(&self) -> u64 {
        self.reports_sent
    }

    /// Reports sent with a flipped checksum ([`Injection::BadChecksums`]).
    pub fn reports_corrupted(&self) -> u64 {
        self.reports_corrupted
    }

    /// Times the 500 ms heartbeat timeout set the speed to 0.
    pub fn heartbeat_timeouts(&self) -> u64 {
        self.heartbeat_timeouts
    }

    // -----------------------------------------------------------------------------------------
    // Rules.

    /// Number of driven wheels: 2, or 4 on omni variants.
    fn wheels(&self) -> usize {
        wheel_count(&self.profile)
    }

    fn drive_blocked(&self) -> bool {
        !self.powered
            || self.body.is_booting()
            || self.body.motor_lost.iter().take(self.wheels()).any(|l| *l)
    }

    fn heartbeat_deadline(&self) -> Option<Timestamp> {
        self.heartbeat_alive
            .then(|| past_timeout(self.last_velocity_rx, self.profile.command_timeout_ms))
    }

    /// Physics and the deadlines that change what the board does (boot end, silence, heartbeat).
    fn expire(&mut self, now: Timestamp) {
        for dt in self.body.substeps(now) {
            self.step(dt);
        }
        if let Some(until) = self.body.expire(now) {
            self.booted_at = until;
            self.reports = Grid::new(Self::REPORT_PERIOD, until);
        }
        if self.heartbeat_deadline().is_some_and(|t| now >= t) {
            self.heartbeat_alive = false;
            self.command = VelocityCommand::default();
            self.heartbeat_timeouts += 1;
        }
    }

    /// The velocity the board executes for a received one: limits of the spec sheet, lateral
    /// speed only on omni variants.
    fn limit(&self, v: VelocityCommand) -> VelocityCommand {
        let min = self.profile.min_linear_mps;
        let floor = |speed: f64| if speed.abs() < min { 0.0 } else { speed };
        VelocityCommand {
            linear_x_mps: floor(v.linear_x_mps),
            linear_y_mps: if self.profile.omni {
                floor(v.linear_y_mps)
            } else {
                0.0
            },
            angular_z_radps: v.angular_z_radps,
        }
    }

    fn on_frame(&mut self, now: Timestamp, frame: Frame) {
        if self.body.is_booting() {
            self.body.received.ignored += 1;
            return;
        }
        match frame {
            Frame::Power(p) => {
                self.powered = p.enable;
                if !p.enable {
                    self.command = VelocityCommand::default();
                }
            }
            Frame::Velocity(v) => {
                self.last_velocity_rx = now;
                self.heartbeat_alive = true;
                self.command = if self.powered {
                    self.limit(v)
                } else {
                    VelocityCommand::default()
                };
            }
            Frame::Lift(l) => {
                self.lift_enabled = l.enable;
                if l.enable {
                    self.lift_target_pct = l.position_pct.clamp(0.0, 100.0);
                }
            }
            Frame::Servos(s) => {
                self.pan_rad = s.pan_rad;
                self.tilt_rad = s.tilt_rad;
            }
            Frame::Sensor(_) => {
                self.body.received.not_for_it += 1;
                return;
            }
        }
        self.body.received.commands += 1;
    }

    fn on_error(&mut self, error: &DecodeError) {
        match error {
            DecodeError::BadChecksum { .. } => self.body.received.bad_checksums += 1,
            _ => self.body.received.decode_errors += 1,
        }
    }

    fn reboot(&mut self, now: Timestamp) {
        self.powered = false;
        self.command = VelocityCommand::default();
        self.heartbeat_alive = false;
        self.lift_enabled = false;
        self.lift_target_pct = self.lift_pct;
        self.pan_rad = 0.0;
        self.tilt_rad = 0.0;
        self.parser.clear();
        if self.body.reboot(now) {
            self.booted_at = now;
            self.reports = Grid::new(Self::REPORT_PERIOD, now);
        }
        self.wheel_travel_m = [0.0; 4];
        self.lift_pct_at_boot = self.lift_pct;
    }

    // -----------------------------------------------------------------------------------------
    // Physics.

    /// Wheel speed targets FL, FR, RL, RR for a body velocity, scaled into the top speed.
    fn wheel_targets(&self, v: &VelocityCommand) -> [f64; 4] {
        let k = 0.5 * self.wheel_separation_m;
        let (vx, vy, w) = (v.linear_x_mps, v.linear_y_mps, v.angular_z_radps);
        let mut wheels = if self.profile.omni {
            [
                vx - vy - w * k,
                vx + vy + w * k,
                vx + vy - w * k,
                vx - vy + w * k,
            ]
        } else {
            [vx - w * k, vx + w * k, 0.0, 0.0]
        };
        let fastest = wheels.iter().fold(0.0f64, |m, s| m.max(s.abs()));
        let max = self.profile.max_linear_mps;
        if fastest > max && max > 0.0 {
            for wheel in &mut wheels {
                *wheel *= max / fastest;
            }
        }
        wheels
    }

    /// Body speeds (forward, lateral, yaw rate) of the wheel speeds.
    fn body(&self, w: &[f64; 4]) -> (f64, f64, f64) {
        let k = 0.5 * self.wheel_separation_m;
        if self.profile.omni {
            (
                0.25 * (w[0] + w[1] + w[2] + w[3]),
                0.25 * (-w[0] + w[1] + w[2] - w[3]),
                0.25 * (-w[0] + w[1] - w[2] + w[3]) / k,
            )
        } else {
            (0.5 * (w[0] + w[1]), 0.0, 0.5 * (w[1] - w[0]) / k)
        }
    }

    /// Integrates `dt` seconds (one sub-step of [`substeps`], never zero).
    fn step(&mut self, dt: f64) {
        let blocked = self.drive_blocked();
        let wheels = self.wheels();
        let (targets, tau) = match self.body.runaway_mps {
            // Every driven wheel at the runaway speed: straight ahead, past every limit.
            Some(runaway) => (
                std::array::from_fn(|i| if i < wheels { runaway } else { 0.0 }),
                Self::DEFAULT_SPEED_TIME_CONSTANT_S,
            ),
            None if blocked => ([0.0; 4], Self::DEFAULT_STOP_TIME_CONSTANT_S),
            None => (
                self.wheel_targets(&self.command)
                    .map(|w| w * self.body.gain),
                Self::DEFAULT_SPEED_TIME_CONSTANT_S,
            ),
        };
        let w0 = self.wheel_mps;
        let w1: [f64; 4] = std::array::from_fn(|i| first_order_lag(w0[i], targets[i], tau, dt));
        let mid = [0, 1, 2, 3].map(|i| 0.5 * (w0[i] + w1[i]));
        let (v, vy, w) = self.body(&mid);
        self.body.pose.advance(v, vy, w, dt);
        if !self.body.is_booting() {
            for (travel, speed) in self.wheel_travel_m.iter_mut().zip(mid) {
                *travel += speed * dt;
            }
        }
        let (v0, _, _) = self.body(&w0);
        let (v1, _, _) = self.body(&w1);
        self.forward_accel_mps2 = (v1 - v0) / dt;
        for i in 0..4 {
            let driving = i < wheels && self.powered && !self.body.motor_lost[i];
            let accel = (w1[i] - w0[i]) / dt;
            self.motor_current_a[i] = if driving {
                Self::MOTOR.magnitude_a(w1[i], accel, Self::MOTOR_HOLD_A)
            } else {
                0.0
            };
        }
        self.wheel_mps = w1;

        // Lift.
        let booted = !self.body.is_booting();
        let gap = self.lift_target_pct - self.lift_pct;
        self.lift_moving = booted && self.lift_enabled && gap != 0.0;
        if self.lift_moving {
            let travel = Self::LIFT_PCT_PER_S * dt;
            if gap.abs() <= travel {
                self.lift_pct = self.lift_target_pct;
            } else {
                self.lift_pct += travel.copysign(gap);
            }
        }
        self.lift_current_a = if self.lift_moving {
            Self::LIFT_MOVING_A
        } else if booted && self.lift_enabled {
            Self::LIFT_HOLD_A
        } else {
            0.0
        };

        // Battery.
        let motors_a = self.motor_current_a.iter().sum::<f64>();
        self.body
            .draw(Self::IDLE_CURRENT_A + motors_a + self.lift_current_a, dt);
    }

    // -----------------------------------------------------------------------------------------
    // Output.

    /// Queues a report in chunks; the injected faults it carries count when its last chunk
    /// leaves.
    fn enqueue(&mut self, bytes: Vec<u8>, injected: InjectedCounts) {
        let mut chunks: Vec<Vec<u8>> = if self.tx_chunk_len == 0 {
            vec![bytes]
        } else {
            bytes
                .chunks(self.tx_chunk_len)
                .map(<[u8]>::to_vec)
                .collect()
        };
        let last = chunks.pop();
        for chunk in chunks {
            self.body.outbox.push(chunk);
        }
        if let Some(chunk) = last {
            self.body.outbox.push_injected(chunk, injected);
        }
    }

    fn nothing_seen_ultrasonic_m(&self) -> f64 {
        if self.profile.bcd_currents_and_ranges {
            Self::NOTHING_SEEN_ULTRASONIC_BCD_M
        } else {
            Self::NOTHING_SEEN_ULTRASONIC_M
        }
    }

    /// Left, centre and right ranges for an obstacle at `centre_m` (or nothing).
    fn ranges(obstacle_m: Option<f64>, nothing_m: f64) -> [f64; 3] {
        match obstacle_m {
            Some(d) => {
                let side = (d * Self::SIDE_RANGE_FACTOR).min(nothing_m);
                [side, d.min(nothing_m), side]
            }
            None => [nothing_m; 3],
        }
    }

    fn report(&self, now: Timestamp) -> SensorReport {
        let metres = self.profile.metres_per_count();
        let wheels = self.wheels();
        let counts = |i: usize| -> u16 {
            if i >= wheels || metres.is_nan() || metres <= 0.0 {
                return 0;
            }
            wrap_u16(self.wheel_travel_m[i] / metres)
        };
        let lift_counts =
            wrap_u16((self.lift_pct - self.lift_pct_at_boot) * Self::LIFT_COUNTS_PER_PCT);
        let (v, _, w) = self.body(&self.wheel_mps);
        let g = scale::STANDARD_GRAVITY_MPS2;
        let accel_limit = 1.99 * g;
        let gyro_limit = (498.0f64).to_radians();
        let stamp_us = now.saturating_since(self.booted_at).as_micros() % 65_536;
        SensorReport {
            battery_voltage_v: self.body.battery_voltage_v().min(99.99),
            ir_m: Self::ranges(self.obstacle_behind_m, Self::NOTHING_SEEN_IR_M),
            ultrasonic_m: Self::ranges(self.obstacle_ahead_m, self.nothing_seen_ultrasonic_m()),
            motor_current_a: self.motor_current_a,
            lift_current_a: self.lift_current_a,
            encoder_counts: [counts(0), counts(1), counts(2), counts(3)],
            lift_encoder_counts: lift_counts,
            accel_mps2: [
                self.forward_accel_mps2.clamp(-accel_limit, accel_limit),
                (v * w).clamp(-accel_limit, accel_limit),
                g,
            ],
            gyro_radps: [0.0, 0.0, w.clamp(-gyro_limit, gyro_limit)],
            mag_gauss: [
                Self::MAG_HORIZONTAL_GAUSS * self.body.pose.yaw_rad.cos(),
                -Self::MAG_HORIZONTAL_GAUSS * self.body.pose.yaw_rad.sin(),
                Self::MAG_VERTICAL_GAUSS,
            ],
            temperature_c: Self::IMU_TEMPERATURE_C,
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: self.body.pose.yaw_rad,
            // Below 65536: the cast is exact.
            sensor_stamp_us: stamp_us as u16,
        }
    }

    /// Sends a status report; `injected` says whether a flood asked for it.
    fn send_report(&mut self, now: Timestamp, mut injected: InjectedCounts) {
        if self.body.is_quiet(now) {
            return;
        }
        let Ok(mut bytes) = Frame::Sensor(self.report(now)).encode(&self.profile) else {
            // Every value is kept inside its wire range; this is a bug guard.
            return;
        };
        if self.body.take_corruption() {
            self.reports_corrupted += 1;
            if let Some(checksum) = bytes.last_mut() {
                *checksum ^= 0xFF;
            }
            injected = injected + InjectedCounts::BAD_CHECKSUM;
        }
        self.reports_sent += 1;
        self.enqueue(bytes, injected);
    }
}

impl Firmware for XbotSim {
    fn robot(&self) -> RobotKind {
        RobotKind::Xbot
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        self.expire(now);
        let Rx::Bytes(bytes) = rx else {
            self.body.received.decode_errors += 1;
            return;
        };
        // A booting board obeys nothing: `on_frame` counts what it ignores.
        // Collected first: obeying a frame needs the whole board, the parser included.
        let items: Vec<_> = self.parser.feed(bytes, &self.profile).collect();
        for item in items {
            match item {
                Ok(frame) => self.on_frame(now, frame),
                Err(err) => self.on_error(&err.error),
            }
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        self.expire(now);
        if !self.body.is_booting() && self.reports.serve_due(now) {
            self.send_report(now, InjectedCounts::default());
        }
        if self.body.flood_due(now).is_some() && !self.body.is_booting() {
            self.send_report(now, InjectedCounts::FLOOD);
        }
    }

    fn poll_transmit(&mut self, _now: Timestamp) -> Option<WireItem> {
        self.body.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let reports = (!self.body.is_booting()).then_some(self.reports.next());
        [self.heartbeat_deadline(), self.body.poll_timeout()]
            .into_iter()
            .fold(reports, earliest)
    }

    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.expire(now);
        match self.body.inject(now, injection) {
            Applied::Condition | Applied::Done => {}
            Applied::Refused => return false,
            Applied::Robot(Injection::Reboot) => self.reboot(now),
            Applied::Robot(Injection::ObstacleAhead(range)) if valid_range(range) => {
                self.obstacle_ahead_m = range;
            }
            Applied::Robot(Injection::ObstacleBehind(range)) if valid_range(range) => {
                self.obstacle_behind_m = range;
            }
            // An obstacle at no finite distance; the serial protocol has no RC, no bumper and no
            // E-stop switch.
            Applied::Robot(_) => return false,
        }
        true
    }

    fn truth(&self) -> SimTruth {
        let (linear, lateral, angular) = self.body(&self.wheel_mps);
        SimTruth {
            linear_mps: linear,
            lateral_mps: lateral,
            angular_radps: angular,
            control_mode: if self.powered && !self.body.is_booting() {
                ControlMode::COMMAND
            } else {
                ControlMode::STANDBY
            },
            ..self.body.truth()
        }
    }
}

/// An injected obstacle range: `None` (nothing in view) or a finite distance ≥ 0, m.
fn valid_range(range: Option<f64>) -> bool {
    range.is_none_or(|d| d.is_finite() && d >= 0.0)
}

/// Number of driven wheels: 2, or 4 on omni variants.
fn wheel_count(profile: &XbotProfile) -> usize {
    if profile.omni { 4 } else { 2 }
}

/// Most reports per second the line carries at the profile's baud rate (10 bits a byte).
fn line_reports_per_s(profile: &XbotProfile) -> u32 {
    (profile.baud / 10 / XbotSim::REPORT_LEN).max(1)
}

/// A signed count as the 16-bit wrapping counter reports it.
fn wrap_u16(counts: f64) -> u16 {
    if !counts.is_finite() {
        return 0;
    }
    // rem_euclid keeps it in [0, 65536): the cast is exact after rounding (65536 wraps to 0).
    (counts.round().rem_euclid(65_536.0) as u32 % 65_536) as u16
}

#[cfg(test)]
#[path = "sim_tests.rs"]
mod sim_tests;
