//! The simulated TITAN firmware: the chassis side of the wire, built on the TITAN codec.
//!
//! Everything about its behaviour is documented on [`TitanSim`].

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{DriverStatus, FaultFlags, RcState};

use super::codec::{
    AxleSpeed, BmsAlarm, BmsData, Frame, MotionFeedback, MotorFast, MotorSlow, Odometer,
    SteeringFeedback, SystemStatus, body, clear_code, decode, fault, id, mode,
};
use super::driver::normalize_faults;
use super::kinematics::{steer_command, yaw_rate};
use crate::can::CanFrame;
use crate::driver::{Rx, WireItem};
use crate::firmware::{
    Applied, BatteryModel, Firmware, InjectedCounts, Injection, Mode, MotorModel, SimBody,
    SimBodySpec, SimTruth, clamp_i16, first_order_lag, past_timeout, wrap_mm,
};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp, earliest};
use crate::titan::TitanProfile;

/// The last accepted motion command.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Motion {
    linear_mps: f64,
    steer_rad: f64,
}

/// 0x211 bits that stop drive: everything but the RC link (a warning).
const STOP_FAULTS: u32 = !fault::RC_LINK_LOST;
const MOTOR_COMM_LOST: [u32; 4] = [
    fault::MOTOR_1_COMM_LOST,
    fault::MOTOR_2_COMM_LOST,
    fault::MOTOR_3_COMM_LOST,
    fault::MOTOR_4_COMM_LOST,
];
/// BMS alarm / warning byte bit for under-voltage.
const BMS_UNDER_VOLTAGE: u8 = 1 << 2;

/// The simulated TITAN chassis: the chassis side of the wire, built on the TITAN codec.
///
/// [`TitanSim`] is sans-IO like the driver: frames from the computer go in with their time
/// ([`Firmware::handle_rx`]), feedback comes out at the manual's periods
/// ([`Firmware::poll_transmit`]), and [`Firmware::poll_timeout`] names the next deadline. It never
/// reads a clock. Every frame in either direction goes through [`decode`] /
/// [`Frame::encode`], so the profile's ⚠ steering-sign choice is honoured on this side too.
///
/// # The manual's rules, as enforced
///
/// * **Power-up**: standby (0x211 mode 0x00), no RC transmitter, parking brake engaged, SOC as
///   configured (100 %). Standby obeys only 0x421; everything else is ignored (counted by
///   [`SimTruth::commands_ignored`]).
/// * **Authority by mode**: CAN command mode obeys every command. Standby obeys 0x421, and 0x111
///   only while it waits for the heartbeat to resume (below). While an RC transmitter holds
///   authority (mode 0x03) only 0x441 (clear faults) and 0x422 (silent mode, a bus function) are
///   obeyed; 0x111, 0x421, 0x131, 0x423 and 0x431 are ignored.
/// * **Motion** (0x111) moves the robot only in CAN command mode with the parking brake released,
///   no fault that stops drive, SOC ≥ the profile's cut-off (10 %) and the chassis booted.
///   Out-of-range commands (|v| > 3 m/s, |v| > 1.5 m/s while |steer| > 0.087 rad,
///   |steer| > 0.367 rad — the profile's limits) are clamped and counted
///   ([`TitanSim::commands_clamped`]). A 0x111 that arrives while drive is blocked still feeds
///   the heartbeat and sets the steering, but its speed is not stored: motion resumes only with a
///   fresh 0x111 after the block ends. The steering follows 0x111 in CAN command mode whenever
///   power is on, even with the brake engaged.
/// * **Heartbeat**: more than `command_timeout_ms` (500 ms) without 0x111 in CAN command mode sets
///   0x211 b6 bit1 and drops to standby; the next 0x111 clears the fault and CAN command mode
///   returns by itself. An explicit 0x421 = standby cancels that automatic return.
/// * **Parking brake**: 0x131 = 0x00 engages (the robot stops), 0x01 releases. Only 0x131 and a
///   reboot change it; mode changes and the simulated RC's levers do not.
/// * **Off-road** (0x423) switches only while |v| < [`TitanSim::STANDING_STILL_MPS`]; otherwise it
///   is ignored. It has no effect on the simulated physics.
/// * **Silent mode** (0x422 = 0x01): nothing is transmitted until 0x422 = 0x00 (commands are still
///   obeyed, the heartbeat still checked).
/// * **Steering zero** (0x431 = 0xAA): 0x43A = 0xEE follows after
///   [`TitanSim::DEFAULT_STEERING_ZERO_DELAY`]. The simulated steering encoders are ideal, so the
///   zero moves nothing.
/// * **Clearing faults** (0x441): `0x00` clears every latched non-severe fault whose cause is gone
///   (motor-driver communication of a driver that is back, RC link, steering encoders,
///   over-current, over-temperature, motor-driver error). Battery under-voltage counts as severe:
///   only `0x09` clears it, and only when SOC ≥ the cut-off (power is restored). `0x01`-`0x04`
///   clear one motor driver's communication fault if that driver answers again. The heartbeat
///   fault is not latched: it clears when 0x111 resumes or CAN command mode is entered.
/// * **Battery**: below the warning level (15 %) the BMS warning-1 under-voltage bit (bit2) is set
///   in every fitted group; below the cut-off (10 %) the BMS alarm-1 under-voltage bit is set, the
///   0x211 under-voltage fault (b7 bit0) latches, drive and steering power are cut and motion
///   commands are ignored. Raising the SOC again does not restore power by itself: send 0x441
///   code 0x09.
/// * **Malformed input** (undecodable frames, unknown ids, serial bytes on this CAN robot) is
///   counted in [`SimTruth::decode_errors`] and ignored. Valid frames that only the chassis sends
///   (feedback ids put on the bus by another node) are ignored and counted by
///   [`SimTruth::frames_ignored`].
///
/// # Feedback
///
/// One fixed grid per period, anchored at construction time (`start + k·period`): late calls never
/// shift it, and a call later than a whole period skips the missed slots instead of bursting.
///
/// | period | frames, in this order |
/// | --- | --- |
/// | 20 ms | 0x211, 0x221, 0x241 (only while an RC transmitter is on), 0x251-0x254, 0x271, 0x281, 0x311 |
/// | 100 ms | 0x261-0x264 |
/// | 500 ms | 0x361, 0x362, 0x363, 0x364, 0x365, 0x366 |
///
/// # Choices where the manual is silent
///
/// * **Steering convention.** The simulated truth is one front inner angle δ (ISO, left positive);
///   the rear axle steers opposite (dual Ackermann), so its wheels physically point the other way.
///   0x271 reports the front inner angle `δ` and the rear inner angle as the rear wheels' own
///   angle `-δ` (opposite signs, like the codec's fixture). The manual's 0x221 angle
///   `(α3+α4)/2` is read as the mean of the front angle α3 = δ and the rear angle mirrored into
///   the turn, α4 = δ, so 0x221 reports the inner angle δ — what 0x111 commands. Both go through
///   the codec, which negates them on the wire when `steering_feedback_left_positive = false`.
/// * **0x221 speed** is the body-centre speed `v` that [`super::kinematics::yaw_rate`] expects (so a
///   driver integrating 0x221 reproduces the true pose exactly). The four-wheel mean the manual
///   names equals it when driving straight and is up to ~4 % higher in the tightest turn; 0x281
///   reports the true mean of each axle's two wheels from the Ackermann geometry.
/// * **Odometers** (0x311) both advance by the signed body-centre distance ∫v dt, in mm, wrapping
///   as `s32`. They and the encoder positions stop counting while the chassis boots.
/// * **Motors** 1-4 are front-left, front-right, rear-left, rear-right. Wheel radius
///   [`TitanSim::WHEEL_RADIUS_M`] (0.165 m), gear ratio [`TitanSim::GEAR_RATIO`] (10:1), so 3 m/s
///   is ≈ 1736 motor rpm; 0x251 reports motor rpm and encoder positions at
///   [`TitanSim::ENCODER_PULSES_PER_REV`] (4096) pulses per motor revolution, wrapping as `s32`.
///   Motor current = 2.75 A per m/s of wheel speed + 1.5 A per m/s² of acceleration, signed like
///   the torque, limited to ±60 A.
///   0x261-0x264 report the pack voltage, driver 30 °C + 0.5 °C/A and motor 28 °C + 0.3 °C/A,
///   and the status bits "enabled" while drive is allowed and "supply under-voltage" while power
///   is cut.
/// * **Battery**: 48 V-class LiFePO4, open-circuit voltage linear from 44.0 V (0 %) to 52.0 V
///   (100 %), internal resistance 0.05 Ω. Pack current (BMS, positive = discharging) = 1.0 A for
///   the electronics + Σ|motor current|, so 1 m/s steady draws 12 A and drains one 24 Ah battery
///   in 2 h. SOC is reported rounded down (an SOC of 9.6 % reads 9 %), SOH 100 %, 25 °C.
/// * **BMS groups**: 0 = pack, 1 = battery 1, 2 = battery 2. With one battery (default) group 1
///   repeats the pack and group 2 reports all zeros (not fitted); with two
///   ([`TitanSim::with_batteries`]) the capacity doubles and groups 1 and 2 each carry half the
///   pack current.
/// * **RC**: [`Injection::RcTakeover`]`(true)` switches a transmitter on with SWB in the middle
///   (remote control, 0x211 mode 0x03), SWA up (2), SWC down (3), SWD up (2), sticks centred, so
///   the robot stops. 0x241 is sent every 20 ms with a rolling counter (reset by a reboot).
///   `RcTakeover(false)` switches it off: the chassis goes back to **standby** (as after power-up
///   without a transmitter) and a driver must send 0x421 again. Switching the transmitter off on
///   purpose is not an RC link loss, so no fault is set. A transmitter that is on at a reboot
///   holds authority again after it.
/// * **Body state and normalized faults**: 0x211 b0 is 0x02 (exception) whenever any fault bit is
///   set. [`SimTruth::fault_flags`] maps the 0x211 bits one to one onto `FaultFlags`, plus
///   `BODY_EXCEPTION` with the exception state, `BATTERY_LOW` below the warning level and
///   `BMS_ALARM` below the cut-off (the BMS alarm bit) — what a driver decoding the frames sees.
/// * **Bumper** sets 0x211 b5 bit5 and stops drive only while pressed (not latched).
/// * **Motor driver loss** latches b7 bit 3-6, stops drive and stops that motor's 0x25x/0x26x
///   frames while the driver is lost; the bit stays after the driver is back until 0x441 clears it.
/// * **Stopping**: the speed follows a first-order lag with time constant
///   [`TitanSim::DEFAULT_SPEED_TIME_CONSTANT_S`] (0.3 s) toward the command, and with the shorter
///   [`TitanSim::DEFAULT_STOP_TIME_CONSTANT_S`] (0.1 s) toward zero whenever drive is blocked
///   (brake, fault, bumper, standby, remote, power cut, boot). Steering slews at
///   [`TitanSim::DEFAULT_STEER_RATE_RADPS`] (1 rad/s) toward the command in CAN command mode,
///   toward zero in remote mode, and holds otherwise or without power.
/// * **Reboot**: everything returns to power-up at once — standby (or remote if a transmitter is
///   on), brake engaged, latched faults cleared (conditions that persist, such as a lost motor
///   driver, a pressed bumper or a flat battery, are raised again when the boot ends), odometers,
///   encoders and the RC counter at zero, silent and off-road modes left, pending replies dropped.
///   For [`TitanSim::DEFAULT_BOOT_TIME`] (300 ms) the chassis sends nothing and ignores every
///   frame. The true pose and the battery are physical and survive; the [`SimTruth`] counters are
///   the observer's and keep counting. [`TitanSim::new`] starts already booted (feedback at once).
/// * **Injections**: `Silence(d)` transmits nothing for `d`; `Flood { frames_per_s }` adds that
///   many extra feedback frames per second (copies of 0x221 and 0x251, alternating; at most
///   [`TitanSim::MAX_FLOOD_FRAMES_PER_S`]; 0 stops it) — both are test conditions and survive a
///   reboot. `Garbage(bytes)` puts frames with id 0x7F0 (unused by TITAN) carrying the bytes 8
///   at a time on the bus at once — another node's noise, so even during silence. `BadChecksums`, `ObstacleAhead` and `ObstacleBehind` return `false` (TITAN
///   has no checksum and no range sensors); so do a motor number outside 1-4 and a non-finite SOC.
#[derive(Debug, Clone)]
pub struct TitanSim {
    profile: TitanProfile,
    // Options.
    steer_rate_radps: f64,
    batteries: u8,

    // Control state.
    mode: Mode,
    /// Dropped to standby by the heartbeat: the next 0x111 brings CAN command mode back.
    resume_on_heartbeat: bool,
    last_motion_rx: Timestamp,
    command: Motion,
    brake_engaged: bool,
    off_road: bool,
    silent_mode: bool,
    rc_on: bool,
    rc_counter: u8,
    bumper: bool,
    /// 0x211 fault word (latched bits and live conditions).
    faults: u32,

    // Physics.
    linear_mps: f64,
    accel_mps2: f64,
    front_steer_rad: f64,
    front_odometer_m: f64,
    rear_odometer_m: f64,
    wheel_mps: [f64; 4],
    motor_current_a: [f64; 4],
    /// Encoder positions, counts, kept in [0, 2³²).
    encoder_counts: [f64; 4],

    // Output.
    fast: Grid,
    slow: Grid,
    bms: Grid,
    zero_replies: VecDeque<Timestamp>,
    /// What every simulated chassis shares: the outbox, the boot, the battery, the pose, the
    /// injected faults and the counts of what it received.
    body: SimBody<CanFrame>,
    /// Motion frames clamped to the valid range.
    commands_clamped: u64,
}

impl TitanSim {
    /// Period of 0x211, 0x221, 0x241, 0x251-0x254, 0x271, 0x281, 0x311.
    pub const FAST_PERIOD: Duration = Duration::from_millis(20);
    /// Period of 0x261-0x264.
    pub const SLOW_PERIOD: Duration = Duration::from_millis(100);
    /// Period of 0x361-0x366.
    pub const BMS_PERIOD: Duration = Duration::from_millis(500);
    /// Wheel radius, m (not in the manual).
    pub const WHEEL_RADIUS_M: f64 = 0.165;
    /// Motor revolutions per wheel revolution (not in the manual).
    pub const GEAR_RATIO: f64 = 10.0;
    /// Encoder pulses per motor revolution, as 0x251-0x254 count them (not in the manual).
    pub const ENCODER_PULSES_PER_REV: f64 = 4096.0;
    /// Time constant of the speed response, s.
    pub const DEFAULT_SPEED_TIME_CONSTANT_S: f64 = 0.3;
    /// Time constant of the speed response while drive is blocked (a stop), s.
    pub const DEFAULT_STOP_TIME_CONSTANT_S: f64 = 0.1;
    /// Steering slew rate, rad/s.
    pub const DEFAULT_STEER_RATE_RADPS: f64 = 1.0;
    /// Silence after a reboot.
    pub const DEFAULT_BOOT_TIME: Duration = Duration::from_millis(300);
    /// Delay of the 0x43A acknowledgement after 0x431.
    pub const DEFAULT_STEERING_ZERO_DELAY: Duration = Duration::from_millis(50);
    /// Speed below which the robot stands still (off-road switching), m/s.
    pub const STANDING_STILL_MPS: f64 = 0.01;
    /// The pack (one battery; [`Self::with_batteries`] doubles the capacity).
    pub const BATTERY: BatteryModel = BatteryModel {
        capacity_ah: 24.0,
        full_v: 52.0,
        empty_v: 44.0,
        resistance_ohm: 0.05,
    };
    /// Current of the electronics, A.
    pub const IDLE_CURRENT_A: f64 = 1.0;
    /// Motor current: 2.75 A per m/s of wheel speed, 1.5 A per m/s² of acceleration, ±60 A.
    pub const MOTOR: MotorModel = MotorModel {
        a_per_mps: 2.75,
        a_per_mps2: 1.5,
        limit_a: 60.0,
    };
    /// Most extra frames per second [`Injection::Flood`] adds.
    pub const MAX_FLOOD_FRAMES_PER_S: u32 = 100_000;
    const AMBIENT_C: f64 = 25.0;

    /// A chassis that has just finished booting at `now`: standby, brake engaged, SOC 100 %.
    pub fn new(profile: TitanProfile, now: Timestamp) -> Self {
        Self {
            profile,
            steer_rate_radps: Self::DEFAULT_STEER_RATE_RADPS,
            batteries: 1,
            mode: Mode::Standby,
            resume_on_heartbeat: false,
            last_motion_rx: now,
            command: Motion::default(),
            brake_engaged: true,
            off_road: false,
            silent_mode: false,
            rc_on: false,
            rc_counter: 0,
            bumper: false,
            faults: 0,
            linear_mps: 0.0,
            accel_mps2: 0.0,
            front_steer_rad: 0.0,
            front_odometer_m: 0.0,
            rear_odometer_m: 0.0,
            wheel_mps: [0.0; 4],
            motor_current_a: [0.0; 4],
            encoder_counts: [0.0; 4],
            fast: Grid::new(Self::FAST_PERIOD, now),
            slow: Grid::new(Self::SLOW_PERIOD, now),
            bms: Grid::new(Self::BMS_PERIOD, now),
            zero_replies: VecDeque::new(),
            body: SimBody::new(
                SimBodySpec {
                    motors: 4,
                    max_flood_per_s: Self::MAX_FLOOD_FRAMES_PER_S,
                    checksums: false,
                    boot_time: Self::DEFAULT_BOOT_TIME,
                    battery: Self::BATTERY,
                    idle_current_a: Self::IDLE_CURRENT_A,
                },
                now,
            ),
            commands_clamped: 0,
        }
    }

    /// Steering slew rate, rad/s (0 or less = instantaneous).
    pub fn with_steer_rate_radps(mut self, rate: f64) -> Self {
        self.steer_rate_radps = if rate.is_finite() && rate > 0.0 {
            rate
        } else {
            f64::INFINITY
        };
        self
    }

    /// Batteries fitted, 1 or 2 (clamped).
    pub fn with_batteries(mut self, batteries: u8) -> Self {
        self.batteries = batteries.clamp(1, 2);
        self.body.set_packs(self.batteries);
        self
    }

    pub fn profile(&self) -> &TitanProfile {
        &self.profile
    }

    /// Motion frames clamped to the valid range.
    pub fn commands_clamped(&self) -> u64 {
        self.commands_clamped
    }

    pub fn off_road(&self) -> bool {
        self.off_road
    }

    pub fn silent_mode(&self) -> bool {
        self.silent_mode
    }

    /// Front and rear odometers, m (unwrapped).
    pub fn odometers_m(&self) -> (f64, f64) {
        (self.front_odometer_m, self.rear_odometer_m)
    }

    // -----------------------------------------------------------------------------------------
    // Rules.

    fn is_powered(&self) -> bool {
        !self.body.is_booting() && self.faults & fault::BATTERY_UNDER_VOLTAGE == 0
    }

    /// Why the wheels may not turn right now, if they may not.
    fn drive_blocked(&self) -> bool {
        !self.is_powered()
            || self.mode != Mode::Command
            || self.brake_engaged
            || self.faults & STOP_FAULTS != 0
            || self.body.soc_pct < self.profile.low_battery_cutoff_soc_pct
    }

    /// Re-raises the faults whose cause persists (lost drivers, bumper, flat battery).
    fn refresh_conditions(&mut self) {
        if self.body.is_booting() {
            return;
        }
        for (lost, bit) in self.body.motor_lost.iter().zip(MOTOR_COMM_LOST) {
            if *lost {
                self.faults |= bit;
            }
        }
        if self.bumper {
            self.faults |= fault::BUMPER;
        } else {
            self.faults &= !fault::BUMPER;
        }
        if self.body.soc_pct < self.profile.low_battery_cutoff_soc_pct {
            self.faults |= fault::BATTERY_UNDER_VOLTAGE;
        }
        if self.drive_blocked() {
            self.command.linear_mps = 0.0;
        }
    }

    fn heartbeat_deadline(&self) -> Option<Timestamp> {
        (self.mode == Mode::Command && !self.body.is_booting())
            .then(|| past_timeout(self.last_motion_rx, self.profile.command_timeout_ms))
    }

    fn enter_command_mode(&mut self, now: Timestamp) {
        if self.mode != Mode::Command {
            self.mode = Mode::Command;
            self.command = Motion::default();
        }
        self.faults &= !fault::HEARTBEAT_LOST;
        self.resume_on_heartbeat = false;
        self.last_motion_rx = now;
    }

    fn enter_standby(&mut self) {
        self.mode = Mode::Standby;
        self.command = Motion::default();
    }

    /// Physics and the deadlines that change what the chassis obeys (boot end, heartbeat).
    fn expire(&mut self, now: Timestamp) {
        for dt in self.body.substeps(now) {
            self.step(dt);
        }
        if self.body.expire(now).is_some() {
            self.refresh_conditions();
        }
        if self.heartbeat_deadline().is_some_and(|t| now >= t) {
            self.faults |= fault::HEARTBEAT_LOST;
            self.enter_standby();
            self.resume_on_heartbeat = true;
        }
    }

    fn accepts(&self, frame_id: u16) -> bool {
        match self.mode {
            Mode::Command => true,
            Mode::Standby => {
                frame_id == id::MODE || (frame_id == id::MOTION_COMMAND && self.resume_on_heartbeat)
            }
            Mode::Remote => frame_id == id::CLEAR_FAULT || frame_id == id::SILENT_MODE,
        }
    }

    fn on_command(&mut self, now: Timestamp, frame: Frame) {
        if self.body.is_booting() || !self.accepts(frame.id()) {
            self.body.received.ignored += 1;
            return;
        }
        match frame {
            Frame::MotionCommand(c) => {
                if self.mode == Mode::Standby {
                    // The heartbeat resumed: the fault clears and CAN command mode returns.
                    self.enter_command_mode(now);
                }
                self.last_motion_rx = now;
                let limited = steer_command(c.linear_mps, c.steer_rad, &self.profile);
                if limited.clamp_flags != 0 {
                    self.commands_clamped += 1;
                }
                self.command = Motion {
                    linear_mps: if self.drive_blocked() {
                        0.0
                    } else {
                        limited.linear_mps
                    },
                    steer_rad: limited.steer_rad,
                };
            }
            Frame::Mode(m) => {
                if m.mode == mode::CAN_COMMAND {
                    self.enter_command_mode(now);
                } else {
                    self.enter_standby();
                    self.resume_on_heartbeat = false;
                }
            }
            Frame::ParkingBrake(b) => {
                self.brake_engaged = b.engage;
                if b.engage {
                    self.command.linear_mps = 0.0;
                }
            }
            Frame::SilentMode(s) => {
                self.silent_mode = s.enter;
                if s.enter {
                    self.body.outbox.clear();
                }
            }
            Frame::OffRoad(s) => {
                if self.linear_mps.abs() >= Self::STANDING_STILL_MPS {
                    self.body.received.ignored += 1;
                    return;
                }
                self.off_road = s.enter;
            }
            Frame::SteeringZero => self
                .zero_replies
                .push_back(now + Self::DEFAULT_STEERING_ZERO_DELAY),
            Frame::ClearFault(c) => self.clear_faults(c.code),
            // Not commands: `handle_rx` filters them out.
            _ => return,
        }
        self.body.received.commands += 1;
    }

    fn clear_faults(&mut self, code: u8) {
        let motor_bit = |m: usize| {
            if self.body.motor_lost[m] {
                0
            } else {
                MOTOR_COMM_LOST[m]
            }
        };
        let clear = match code {
            clear_code::ALL_NON_SEVERE => {
                (0..4).fold(0, |acc, m| acc | motor_bit(m))
                    | fault::RC_LINK_LOST
                    | fault::FRONT_STEERING_ENCODER
                    | fault::REAR_STEERING_ENCODER
                    | fault::OVER_CURRENT
                    | fault::OVER_TEMPERATURE
                    | fault::MOTOR_DRIVER_ERROR
            }
            clear_code::MOTOR_1_COMM..=clear_code::MOTOR_4_COMM => {
                motor_bit(usize::from(code - clear_code::MOTOR_1_COMM))
            }
            // Power is restored only from a battery above the cut-off.
            clear_code::BATTERY_UNDER_VOLTAGE
                if self.body.soc_pct >= self.profile.low_battery_cutoff_soc_pct =>
            {
                fault::BATTERY_UNDER_VOLTAGE
            }
            clear_code::RC_LINK_LOST => fault::RC_LINK_LOST,
            clear_code::FRONT_STEERING_ENCODER => fault::FRONT_STEERING_ENCODER,
            clear_code::REAR_STEERING_ENCODER => fault::REAR_STEERING_ENCODER,
            clear_code::OVER_CURRENT => fault::OVER_CURRENT,
            clear_code::OVER_TEMPERATURE => fault::OVER_TEMPERATURE,
            _ => 0,
        };
        self.faults &= !clear;
    }

    fn reboot(&mut self, now: Timestamp) {
        self.mode = if self.rc_on {
            Mode::Remote
        } else {
            Mode::Standby
        };
        self.resume_on_heartbeat = false;
        self.command = Motion::default();
        self.brake_engaged = true;
        self.off_road = false;
        self.silent_mode = false;
        self.faults = 0;
        self.front_odometer_m = 0.0;
        self.rear_odometer_m = 0.0;
        self.encoder_counts = [0.0; 4];
        self.rc_counter = 0;
        self.zero_replies.clear();
        self.last_motion_rx = now;
        if self.body.reboot(now) {
            self.refresh_conditions();
        }
    }

    // -----------------------------------------------------------------------------------------
    // Physics.

    /// Integrates `dt` seconds (one sub-step of [`substeps`], never zero).
    fn step(&mut self, dt: f64) {
        self.refresh_conditions();
        let blocked = self.drive_blocked();
        let (target, tau) = match self.body.runaway_mps {
            Some(runaway) => (runaway, Self::DEFAULT_SPEED_TIME_CONSTANT_S),
            None if blocked => (0.0, Self::DEFAULT_STOP_TIME_CONSTANT_S),
            None => (
                self.command.linear_mps * self.body.gain,
                Self::DEFAULT_SPEED_TIME_CONSTANT_S,
            ),
        };
        let v0 = self.linear_mps;
        let v1 = first_order_lag(v0, target, tau, dt);
        let steer_target = match self.mode {
            _ if !self.is_powered() => self.front_steer_rad,
            Mode::Command => self.command.steer_rad,
            Mode::Remote => 0.0,
            Mode::Standby => self.front_steer_rad,
        };
        let s0 = self.front_steer_rad;
        let max_move = self.steer_rate_radps * dt;
        let s1 = s0 + (steer_target - s0).clamp(-max_move, max_move);

        // Midpoint rule for the pose and the distances.
        let v_mid = 0.5 * (v0 + v1);
        let s_mid = 0.5 * (s0 + s1);
        let w_mid = yaw_rate(v_mid, s_mid, &self.profile);
        self.body.pose.advance(v_mid, 0.0, w_mid, dt);
        if !self.body.is_booting() {
            self.front_odometer_m += v_mid * dt;
            self.rear_odometer_m += v_mid * dt;
            let counts_per_m = Self::GEAR_RATIO * Self::ENCODER_PULSES_PER_REV
                / (std::f64::consts::TAU * Self::WHEEL_RADIUS_M);
            let wheels = self.wheel_speeds(v_mid, s_mid);
            for (counts, wheel) in self.encoder_counts.iter_mut().zip(wheels) {
                *counts = (*counts + wheel * dt * counts_per_m).rem_euclid(4_294_967_296.0);
            }
        }

        self.linear_mps = v1;
        self.front_steer_rad = s1;
        self.accel_mps2 = (v1 - v0) / dt;
        self.wheel_mps = self.wheel_speeds(v1, s1);
        for (current, wheel) in self.motor_current_a.iter_mut().zip(self.wheel_mps) {
            *current = Self::MOTOR.signed_a(wheel, self.accel_mps2);
        }
        let motors_a = self.motor_current_a.iter().map(|c| c.abs()).sum::<f64>();
        self.body.draw(Self::IDLE_CURRENT_A + motors_a, dt);
    }

    /// Wheel speeds front-left, front-right, rear-left, rear-right, m/s, for body-centre speed `v`
    /// and front inner angle `steer` (dual Ackermann: the centre of rotation lies on the lateral
    /// line through the body centre).
    fn wheel_speeds(&self, v: f64, steer: f64) -> [f64; 4] {
        if steer == 0.0 || !steer.is_finite() {
            return [v; 4];
        }
        let a = self.profile.wheelbase_m / 2.0;
        let b = self.profile.track_m / 2.0;
        let radius = a / steer.abs().tan() + b;
        let inner = v * a.hypot(radius - b) / radius;
        let outer = v * a.hypot(radius + b) / radius;
        let (left, right) = if steer > 0.0 {
            (inner, outer)
        } else {
            (outer, inner)
        };
        [left, right, left, right]
    }

    // -----------------------------------------------------------------------------------------
    // Output.

    fn send(&mut self, now: Timestamp, frame: Frame) {
        self.send_injected(now, frame, InjectedCounts::default());
    }

    /// Like [`TitanSim::send`], for a frame that carries an injected fault.
    fn send_injected(&mut self, now: Timestamp, frame: Frame, injected: InjectedCounts) {
        if self.body.is_quiet(now) || self.silent_mode {
            return;
        }
        // Every value is kept inside its wire range; a frame that still does not fit is not sent.
        let encoded = frame.encode(&self.profile);
        self.body.outbox.push_encoded(encoded, injected);
    }

    fn wire_mode(&self) -> u8 {
        match self.mode {
            Mode::Standby => mode::STANDBY,
            Mode::Command => mode::CAN_COMMAND,
            Mode::Remote => mode::REMOTE,
        }
    }

    fn motion_feedback(&self) -> Frame {
        Frame::MotionFeedback(MotionFeedback {
            linear_mps: clamp_i16(self.linear_mps, 1000.0),
            // (α3 + α4) / 2 with α3 the front angle and α4 the rear angle mirrored into the turn.
            steer_rad: clamp_i16(self.front_steer_rad, 1000.0),
        })
    }

    fn motor_fast(&self, motor: usize) -> Frame {
        Frame::MotorFast(MotorFast {
            motor: motor_number(motor),
            rpm: clamp_i16(self.motor_rpm(motor), 1.0).round(),
            current_a: clamp_i16(self.motor_current_a[motor], 10.0),
            // The count is kept in [0, 2³²): reinterpreting it as s32 wraps like the hardware.
            position_counts: self.encoder_counts[motor] as u32 as i32,
        })
    }

    fn motor_rpm(&self, motor: usize) -> f64 {
        self.wheel_mps[motor] / (std::f64::consts::TAU * Self::WHEEL_RADIUS_M)
            * 60.0
            * Self::GEAR_RATIO
    }

    fn send_fast(&mut self, now: Timestamp) {
        let body_status = if self.faults == 0 {
            body::NORMAL
        } else {
            body::EXCEPTION
        };
        self.send(
            now,
            Frame::SystemStatus(SystemStatus {
                body_status,
                mode: self.wire_mode(),
                battery_voltage_v: self.body.battery_voltage_v().min(6553.5),
                vendor_fault_word: self.faults,
            }),
        );
        self.send(now, self.motion_feedback());
        if self.rc_on {
            let counter = self.rc_counter;
            self.rc_counter = self.rc_counter.wrapping_add(1);
            self.send(
                now,
                Frame::Rc(RcState {
                    switch_a: 2,
                    switch_b: 1,
                    switch_c: 3,
                    switch_d: 2,
                    counter,
                    ..RcState::default()
                }),
            );
        }
        for motor in 0..4 {
            if !self.body.motor_lost[motor] {
                self.send(now, self.motor_fast(motor));
            }
        }
        let steer = clamp_i16(self.front_steer_rad, 1000.0);
        self.send(
            now,
            Frame::SteeringFeedback(SteeringFeedback {
                front_steer_rad: steer,
                rear_steer_rad: -steer,
            }),
        );
        let w = self.wheel_mps;
        self.send(
            now,
            Frame::AxleSpeed(AxleSpeed {
                front_axle_mps: clamp_i16(0.5 * (w[0] + w[1]), 1000.0),
                rear_axle_mps: clamp_i16(0.5 * (w[2] + w[3]), 1000.0),
            }),
        );
        self.send(
            now,
            Frame::Odometer(Odometer {
                front_distance_m: wrap_mm(self.front_odometer_m),
                rear_distance_m: wrap_mm(self.rear_odometer_m),
            }),
        );
    }

    fn send_slow(&mut self, now: Timestamp) {
        let voltage = self.body.battery_voltage_v().min(6553.5);
        let mut status = 0;
        if !self.drive_blocked() {
            status |= DriverStatus::ENABLED;
        }
        if self.faults & fault::BATTERY_UNDER_VOLTAGE != 0 {
            status |= DriverStatus::SUPPLY_UNDER_VOLTAGE;
        }
        for motor in 0..4 {
            if self.body.motor_lost[motor] {
                continue;
            }
            let current = self.motor_current_a[motor].abs();
            self.send(
                now,
                Frame::MotorSlow(MotorSlow {
                    motor: motor_number(motor),
                    driver_voltage_v: voltage,
                    driver_temp_c: (Self::AMBIENT_C + 5.0 + 0.5 * current).round(),
                    motor_temp_c: (Self::AMBIENT_C + 3.0 + 0.3 * current).round().min(127.0),
                    driver_status: status,
                }),
            );
        }
    }

    fn send_bms(&mut self, now: Timestamp) {
        let soc = self.body.soc_pct.floor().clamp(0.0, 100.0);
        let voltage = self.body.battery_voltage_v().min(655.35);
        let current = clamp_i16(self.body.pack_current_a, 10.0);
        let mut alarm = BmsAlarm::default();
        if self.body.soc_pct < self.profile.low_battery_warning_soc_pct {
            alarm.warning_1 |= BMS_UNDER_VOLTAGE;
        }
        if self.body.soc_pct < self.profile.low_battery_cutoff_soc_pct {
            alarm.alarm_1 |= BMS_UNDER_VOLTAGE;
        }
        let data = BmsData {
            group: 0,
            soc_pct: soc,
            soh_pct: 100.0,
            voltage_v: voltage,
            current_a: current,
            temperature_c: Self::AMBIENT_C,
        };
        let battery = BmsData {
            current_a: current / f64::from(self.batteries),
            ..data
        };
        let groups = [
            (data, alarm),
            (battery, alarm),
            if self.batteries >= 2 {
                (battery, alarm)
            } else {
                (BmsData::default(), BmsAlarm::default())
            },
        ];
        for (group, (data, alarm)) in (0u8..).zip(groups) {
            self.send(now, Frame::BmsData(BmsData { group, ..data }));
            self.send(now, Frame::BmsAlarm(BmsAlarm { group, ..alarm }));
        }
    }

    /// The normalized flags of what the chassis reports (0x211 word, body state, BMS).
    fn fault_flags(&self) -> u64 {
        let mut flags = normalize_faults(self.faults);
        if self.faults != 0 {
            flags |= FaultFlags::BODY_EXCEPTION;
        }
        if self.body.soc_pct < self.profile.low_battery_warning_soc_pct {
            flags |= FaultFlags::BATTERY_LOW;
        }
        if self.body.soc_pct < self.profile.low_battery_cutoff_soc_pct {
            flags |= FaultFlags::BMS_ALARM;
        }
        flags
    }
}

impl Firmware for TitanSim {
    fn robot(&self) -> RobotKind {
        RobotKind::Titan
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        self.expire(now);
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
        while self.zero_replies.front().is_some_and(|t| *t <= now) {
            self.zero_replies.pop_front();
            self.send(now, Frame::SteeringZeroAck);
        }
        if self.fast.serve_due(now) {
            self.send_fast(now);
        }
        if self.slow.serve_due(now) {
            self.send_slow(now);
        }
        if self.bms.serve_due(now) {
            self.send_bms(now);
        }
        if let Some(motor) = self.body.flood_due(now) {
            let copy = if motor {
                self.motor_fast(0)
            } else {
                self.motion_feedback()
            };
            self.send_injected(now, copy, InjectedCounts::FLOOD);
        }
    }

    fn poll_transmit(&mut self, _now: Timestamp) -> Option<WireItem> {
        self.body.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        let grids = self.fast.next().min(self.slow.next()).min(self.bms.next());
        [
            self.heartbeat_deadline(),
            self.zero_replies.front().copied(),
            self.body.poll_timeout(),
        ]
        .into_iter()
        .fold(Some(grids), earliest)
    }

    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.expire(now);
        match self.body.inject(now, injection) {
            Applied::Condition => self.refresh_conditions(),
            Applied::Done => {}
            Applied::Refused => return false,
            Applied::Robot(Injection::Bumper(pressed)) => {
                self.bumper = pressed;
                self.refresh_conditions();
            }
            Applied::Robot(Injection::RcTakeover(on)) => {
                self.rc_on = on;
                if on {
                    self.mode = Mode::Remote;
                    self.command = Motion::default();
                    self.resume_on_heartbeat = false;
                    self.faults &= !fault::HEARTBEAT_LOST;
                } else if self.mode == Mode::Remote {
                    self.enter_standby();
                }
            }
            Applied::Robot(Injection::Reboot) => self.reboot(now),
            // No checksum, no range sensors, no E-stop switch.
            Applied::Robot(_) => return false,
        }
        true
    }

    fn truth(&self) -> SimTruth {
        SimTruth {
            linear_mps: self.linear_mps,
            angular_radps: yaw_rate(self.linear_mps, self.front_steer_rad, &self.profile),
            steer_rad: self.front_steer_rad,
            control_mode: self.mode.control_mode(),
            brake_engaged: self.brake_engaged,
            fault_flags: self.fault_flags(),
            ..self.body.truth()
        }
    }
}

/// 1-4 from an index 0-3.
fn motor_number(index: usize) -> u8 {
    // index < 4.
    (index.min(3) + 1) as u8
}

#[cfg(test)]
#[path = "sim_tests.rs"]
mod sim_tests;
