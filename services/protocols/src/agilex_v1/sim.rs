//! The simulated SCOUT MINI firmware: the chassis side of the wire, built on the SCOUT MINI codec.
//!
//! Everything about its behaviour is documented on [`V1Sim`].

use std::time::Duration;

use chassis_interfaces::ControlMode;

use super::codec::{
    Frame, Lights, MotionCommand, MotionFeedback, MotorFeedback, SystemStatus, body, clear_code,
    decode, fault, id, mode,
};
use super::driver::normalize_faults;
use super::kinematics::side_speeds;
use crate::DecodeError;
use crate::agilex_v1::V1Profile;
use crate::agilex_v2::vehicle_state_flags;
use crate::can::CanFrame;
use crate::driver::{Rx, WireItem};
use crate::firmware::{
    Applied, BatteryModel, Firmware, InjectedCounts, Injection, MotorModel, SimBody, SimBodySpec,
    SimTruth, clamp_i16, first_order_lag, non_negative, past_timeout, state_of_charge,
};
use crate::kind::RobotKind;
use crate::time::{Grid, Timestamp, earliest};

/// The last obeyed motion command.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Motion {
    linear_mps: f64,
    angular_radps: f64,
}

const MOTOR_COMM: [u16; 4] = [
    fault::MOTOR_1_COMM,
    fault::MOTOR_2_COMM,
    fault::MOTOR_3_COMM,
    fault::MOTOR_4_COMM,
];
/// Latched b5 bits that cut drive at once.
const POWER_FAULTS: u16 = fault::BATTERY_UNDER_VOLTAGE
    | fault::BATTERY_OVER_VOLTAGE
    | fault::MOTOR_1_COMM
    | fault::MOTOR_2_COMM
    | fault::MOTOR_3_COMM
    | fault::MOTOR_4_COMM;
/// Latched b5 bits that limit the drive output until cleared (the robot slowly stops).
const PROTECTIONS: u16 = fault::DRIVE_OVER_TEMP_PROTECTION | fault::MOTOR_OVER_CURRENT_PROTECTION;

/// Feedback ids in the order the chassis sends them; the index is the rolling counter's.
const FEEDBACK_IDS: [u16; 7] = [
    id::SYSTEM_STATUS,
    id::MOTION_FEEDBACK,
    id::MOTOR_1,
    id::MOTOR_1 + 1,
    id::MOTOR_1 + 2,
    id::MOTOR_1 + 3,
    id::LIGHT_STATE,
];

/// The simulated SCOUT MINI chassis: the chassis side of the wire, built on the SCOUT MINI codec.
///
/// [`V1Sim`] is sans-IO like the driver: frames from the computer go in with their time
/// ([`Firmware::handle_rx`]), feedback comes out every 20 ms ([`Firmware::poll_transmit`]), and
/// [`Firmware::poll_timeout`] names the next deadline. It never reads a clock. Every frame in
/// either direction goes through [`decode`] / [`Frame::encode`], so the profile's ⚠ full scales
/// are honoured on this side too: the simulated robot's *true* full scales are the profile it is
/// built with, which may differ from the driver's.
///
/// # The manual's rules, as enforced
///
/// * **Authority.** With the RC transmitter off (power-up) the chassis is in CAN command mode
///   (0x151 mode 0x01), but a 0x130 is obeyed only if it carries mode 0x01. A 0x130 with mode
///   0x00 or 0x02 is not obeyed: its speeds are ignored and it does not feed the command timeout
///   (so a chassis that only hears mode 0x00 stops at the latest 500 ms after the last obeyed
///   frame). An RC transmitter that is on ([`Injection::RcTakeover`]) has the highest authority:
///   0x151 reports mode 0x00, every 0x130 speed is ignored, the sticks are centred so the robot
///   stops. Switching it off hands back: command mode at once, and the next 0x130 with mode 0x01
///   is obeyed — no mode frame or handshake needed.
/// * **Command timeout**: more than `command_timeout_ms` (500 ms) after the last obeyed 0x130 the
///   command becomes zero and the robot stops. The manual names no fault bit for it, so none is
///   set; the next obeyed 0x130 drives again.
/// * **Checksums.** Every received frame's checksum is checked ([`decode`]). A frame with a wrong
///   one is dropped, counted ([`SimTruth::bad_checksums_received`]) and sets 0x151 b4 bit0 (CAN
///   command checksum error). The manual does not say when the bit clears: here it clears itself
///   [`V1Sim::DEFAULT_CHECKSUM_FAULT_HOLD`] (500 ms) after the last bad frame, like the
///   other b4 alarms, so a host sees it in at least 25 consecutive 0x151 frames even when only
///   one frame was corrupt; a steady stream of bad frames keeps it set.
/// * **Fault-clear codes** (0x130 b1) are honoured in every valid 0x130, whatever its mode byte
///   and even while an RC transmitter holds authority (clearing is not motion). A code clears
///   its latched bit; a fault whose cause persists (a lost motor driver, a flat battery, a driver
///   still above 65 °C, a current still above 20 A rms) latches again at once.
/// * **Lights** (0x140) are obeyed in every mode (the manual puts the light interface beside the
///   RC's, not under it): enable 0x01 takes over the front light with the frame's mode and
///   brightness; enable 0x00 hands the light back to the chassis (0x141 reports control off and
///   the chassis' own mode, normally closed, brightness 0). 0x141 reports the result.
/// * **Malformed input** (unknown or extended ids, wrong length, undefined values, serial bytes
///   on this CAN robot) is counted in [`SimTruth::decode_errors`] and ignored. Valid frames that
///   only the chassis sends (feedback ids from another node) are counted by
///   [`SimTruth::frames_ignored`].
///
/// # Faults (0x151 b4-b5)
///
/// | bit | set when | clears |
/// | --- | --- | --- |
/// | b4.0 checksum | a frame with a bad checksum arrived | by itself, 500 ms after the last one |
/// | b4.1 drive over-temp alarm | a motor driver is above 55 °C | by itself |
/// | b4.2 over-current alarm | a motor's current is above 15 A rms | by itself |
/// | b4.3 under-voltage alarm | the battery reads below `under_voltage_alarm_v` (22.5 V) | by itself |
/// | b4.4 RC disconnected | the RC transmitter is off | while the transmitter is on |
/// | b5.0 under-voltage failure | the battery reads below `under_voltage_failure_v` (22 V): drive cut | code 0x01, once the battery reads ≥ 22 V |
/// | b5.1 over-voltage failure | never (the simulated pack cannot exceed 29.2 V) | code 0x02 |
/// | b5.2-5 motor n communication | [`Injection::MotorDriverLoss`]: drive cut, that motor's 0x20n stops | code 0x03-0x06, once the driver answers again |
/// | b5.6 drive over-temp protection | a motor driver is above 65 °C: drive output limited | code 0x07 |
/// | b5.7 over-current protection | a motor's current is above 20 A rms: drive output limited | code 0x08 |
///
/// 0x151 b0 (body status) is 0x02 (exception) while any b5 bit is set, else 0x00; the simulated
/// chassis has no emergency-stop switch (the manual marks that state "not enabled").
///
/// # Feedback
///
/// Every 20 ms on one fixed grid anchored at construction time: 0x151, 0x131, 0x200-0x203 (a lost
/// motor driver's frame is missing), 0x141, in this order. Each id has its own rolling count
/// (from 0 at power-up and after a reboot, +1 per frame of that id sent, wrapping), and every
/// frame carries its correct checksum unless [`Injection::BadChecksums`] corrupts it.
///
/// # Choices where the manual is silent
///
/// * **Physics.** Linear and angular speed each follow a first-order lag toward the command with
///   time constant [`V1Sim::DEFAULT_SPEED_TIME_CONSTANT_S`] (0.3 s); the same lag brings
///   the robot to a stop after the command timeout, an RC takeover or a mode-0x00 release. A
///   power cut (under-voltage, a lost motor driver, a reboot) stops it with
///   [`V1Sim::DEFAULT_STOP_TIME_CONSTANT_S`] (0.1 s); a protection "limits the drive
///   output, the vehicle slowly stops" with [`V1Sim::PROTECTION_STOP_TIME_CONSTANT_S`]
///   (1 s). The true pose integrates the speeds by the midpoint rule in 5 ms sub-steps. 0x131
///   reports the true body speeds rounded to the wire's 1 mm/s and 1 mrad/s, so a driver
///   integrating 0x131 reproduces the true pose up to its 20 ms sampling and that rounding.
/// * **Motors** 1-4 are front-left, front-right, rear-left, rear-right (the manual's figure was
///   lost in the text extraction). Hub motors, so the shaft speed is the wheel's: rpm =
///   side speed / (2π · [`V1Sim::WHEEL_RADIUS_M`] (0.0875 m)) · 60, signed positive when the
///   wheel drives the robot forward; the side speeds come from
///   [`super::kinematics::side_speeds`]. Current (0x200 b0-1 is unsigned: the magnitude) =
///   |1.2 A per m/s of wheel speed + 1.0 A per m/s² of wheel acceleration| + any extra load
///   ([`V1Sim::set_extra_load_a`]), limited to 40 A, and zero while the drive output is
///   cut. The "rms" current the alarms use is the square root of a 1 s moving mean of its square.
///   The driver temperature follows 25 °C + 0.1 °C/A² · I_rms² with a 60 s time constant
///   ([`V1Sim::set_driver_temperature_c`] heats a driver at once); the motor temperature
///   reads 25 °C + 0.6 × the driver's rise.
/// * **Battery**: 24 V 15 Ah lithium pack (7 cells), open-circuit voltage linear from 21.0 V
///   (0 %) to 29.2 V (100 %, the manual's "fully recharged"), internal resistance 0.03 Ω. Pack
///   current = 0.8 A for the electronics + Σ motor currents, so 1 m/s steady draws 5.6 A and the
///   manual's 10 km range is about 1.9 h at 1.5 m/s. 0x151 reports the voltage under load; the
///   alarms and the failure compare that same voltage (22.5 V ≈ 18 %, 22 V ≈ 12 % at rest).
///   [`Injection::Battery`] sets the SOC.
/// * **Reboot**: for [`V1Sim::DEFAULT_BOOT_TIME`] (300 ms) the chassis sends nothing and
///   ignores every frame, and the drive output is cut. Then power-up state: command mode (or RC
///   with a transmitter on), no command, latched faults cleared (persisting causes latch again),
///   light control off, every rolling count back to 0. The true pose, the battery and the
///   temperatures are physical and survive; the [`SimTruth`] counters are the observer's and keep
///   counting. [`V1Sim::new`] starts already booted (feedback at once).
/// * **Injections**: `Silence(d)` transmits nothing for `d`; `Flood { frames_per_s }` adds that
///   many extra feedback frames per second (copies of 0x131 and 0x200, alternating, each with its
///   id's next count; at most [`V1Sim::MAX_FLOOD_FRAMES_PER_S`]; 0 stops it);
///   `BadChecksums(n)` corrupts the checksum byte (inverted) of the next `n` frames sent, flood
///   copies included (a second injection adds to what the first has not corrupted yet) — all
///   three survive a reboot. [`SimTruth::injected`] counts the corrupted, flood and garbage
///   frames as they leave. `Garbage(bytes)` puts frames with id 0x7F0 (unused by SCOUT MINI)
///   carrying the bytes 8 at a time on the bus at once — another node's noise, so even during
///   silence. `Bumper`, `ObstacleAhead`
///   and `ObstacleBehind` return `false` (the SCOUT MINI's anti-collision tube is no switch and
///   it has no range sensors); so do a motor number outside 1-4 and a non-finite SOC.
#[derive(Debug, Clone)]
pub struct V1Sim {
    profile: V1Profile,
    // Options.
    speed_time_constant_s: f64,
    checksum_fault_hold: Duration,

    // Control state.
    rc_on: bool,
    command: Motion,
    /// The command is dropped (timeout) at this time.
    command_until: Option<Timestamp>,
    checksum_fault_until: Option<Timestamp>,
    extra_load_a: f64,
    /// Latched 0x151 b5 bits.
    latched: u16,
    lights: Lights,

    // Physics.
    linear_mps: f64,
    angular_radps: f64,
    wheel_mps: [f64; 4],
    motor_current_a: [f64; 4],
    /// Moving mean of the squared motor currents, A².
    current_sq_a2: [f64; 4],
    driver_temp_c: [f64; 4],

    // Output.
    fast: Grid,
    counts: [u8; FEEDBACK_IDS.len()],
    /// What every simulated chassis shares: the outbox, the boot, the battery, the pose, the
    /// injected faults and the counts of what it received.
    body: SimBody<CanFrame>,
}

impl V1Sim {
    /// Period of every feedback frame.
    pub const FEEDBACK_PERIOD: Duration = Duration::from_millis(20);
    /// Wheel radius, m (not in the manual).
    pub const WHEEL_RADIUS_M: f64 = 0.0875;
    /// Time constant of the speed response, s.
    pub const DEFAULT_SPEED_TIME_CONSTANT_S: f64 = 0.3;
    /// Time constant of the stop when the drive power is cut, s.
    pub const DEFAULT_STOP_TIME_CONSTANT_S: f64 = 0.1;
    /// Time constant of the slow stop under a protection (limited drive output), s.
    pub const PROTECTION_STOP_TIME_CONSTANT_S: f64 = 1.0;
    /// Silence after a reboot.
    pub const DEFAULT_BOOT_TIME: Duration = Duration::from_millis(300);
    /// How long 0x151 b4 bit0 stays set after the last frame with a bad checksum.
    pub const DEFAULT_CHECKSUM_FAULT_HOLD: Duration = Duration::from_millis(500);
    /// The battery.
    pub const BATTERY: BatteryModel = BatteryModel {
        capacity_ah: 15.0,
        full_v: 29.2,
        empty_v: 21.0,
        resistance_ohm: 0.03,
    };
    /// Current of the electronics, A.
    pub const IDLE_CURRENT_A: f64 = 0.8;
    /// Motor current: 1.2 A per m/s of wheel speed, 1.0 A per m/s² of wheel acceleration, at
    /// most 40 A.
    pub const MOTOR: MotorModel = MotorModel {
        a_per_mps: 1.2,
        a_per_mps2: 1.0,
        limit_a: 40.0,
    };
    /// Time constant of the moving mean behind the rms current, s.
    pub const CURRENT_RMS_TIME_CONSTANT_S: f64 = 1.0;
    /// Motor over-current alarm (b4 bit2), A rms.
    pub const OVER_CURRENT_ALARM_A: f64 = 15.0;
    /// Motor over-current protection (b5 bit7), A rms.
    pub const OVER_CURRENT_PROTECTION_A: f64 = 20.0;
    /// Drive over-temperature alarm (b4 bit1), °C.
    pub const OVER_TEMPERATURE_ALARM_C: f64 = 55.0;
    /// Drive over-temperature protection (b5 bit6), °C.
    pub const OVER_TEMPERATURE_PROTECTION_C: f64 = 65.0;
    /// Ambient temperature, °C.
    pub const AMBIENT_C: f64 = 25.0;
    /// Driver temperature rise per A² of rms current, °C.
    pub const DRIVER_C_PER_A2: f64 = 0.1;
    /// Thermal time constant of a motor driver, s.
    pub const THERMAL_TIME_CONSTANT_S: f64 = 60.0;
    /// Most extra frames per second [`Injection::Flood`] adds.
    pub const MAX_FLOOD_FRAMES_PER_S: u32 = 100_000;

    /// A chassis that has just finished booting at `now`: command mode (no RC transmitter),
    /// standing, SOC 100 %.
    pub fn new(profile: V1Profile, now: Timestamp) -> Self {
        Self {
            profile,
            speed_time_constant_s: Self::DEFAULT_SPEED_TIME_CONSTANT_S,
            checksum_fault_hold: Self::DEFAULT_CHECKSUM_FAULT_HOLD,
            rc_on: false,
            command: Motion::default(),
            command_until: None,
            checksum_fault_until: None,
            extra_load_a: 0.0,
            latched: 0,
            lights: Lights::default(),
            linear_mps: 0.0,
            angular_radps: 0.0,
            wheel_mps: [0.0; 4],
            motor_current_a: [0.0; 4],
            current_sq_a2: [0.0; 4],
            driver_temp_c: [Self::AMBIENT_C; 4],
            fast: Grid::new(Self::FEEDBACK_PERIOD, now),
            counts: [0; FEEDBACK_IDS.len()],
            body: SimBody::new(
                SimBodySpec {
                    motors: 4,
                    max_flood_per_s: Self::MAX_FLOOD_FRAMES_PER_S,
                    checksums: true,
                    boot_time: Self::DEFAULT_BOOT_TIME,
                    battery: Self::BATTERY,
                    idle_current_a: Self::IDLE_CURRENT_A,
                },
                now,
            ),
        }
    }

    /// Time constant of the first-order speed response, s (0 = instantaneous).
    pub fn with_speed_time_constant_s(mut self, seconds: f64) -> Self {
        self.speed_time_constant_s = non_negative(seconds);
        self
    }

    /// How long 0x151 b4 bit0 stays set after the last frame with a bad checksum.
    pub fn with_checksum_fault_hold(mut self, hold: Duration) -> Self {
        self.checksum_fault_hold = hold;
        self
    }

    /// Starting state of charge, % (clamped to 0-100).
    pub fn with_soc_pct(mut self, soc_pct: f64) -> Self {
        if let Some(soc_pct) = state_of_charge(soc_pct) {
            self.body.soc_pct = soc_pct;
            self.refresh_conditions();
        }
        self
    }

    pub fn profile(&self) -> &V1Profile {
        &self.profile
    }

    /// The 0x151 fault word the chassis reports at its latest time.
    pub fn vendor_fault_word(&self) -> u16 {
        self.fault_word(self.body.last_update())
    }

    /// The light state 0x141 reports.
    pub fn lights(&self) -> Lights {
        self.lights
    }

    /// True while the chassis boots after a reboot.
    pub fn is_booting(&self) -> bool {
        self.body.is_booting()
    }

    /// Pack current, A (positive = discharging).
    pub fn battery_current_a(&self) -> f64 {
        self.body.pack_current_a
    }

    /// Motor driver temperatures, °C, motors 1-4.
    pub fn driver_temperatures_c(&self) -> [f64; 4] {
        self.driver_temp_c
    }

    /// The rms motor currents the alarms compare, A, motors 1-4.
    pub fn motor_currents_rms_a(&self) -> [f64; 4] {
        self.current_sq_a2.map(f64::sqrt)
    }

    /// Heats (or cools) every motor driver to `celsius` at `now` — a hot day, a long climb. The
    /// temperatures then relax toward what the current sustains.
    pub fn set_driver_temperature_c(&mut self, now: Timestamp, celsius: f64) {
        self.expire(now);
        if celsius.is_finite() {
            self.driver_temp_c = [celsius.clamp(-40.0, 120.0); 4];
            self.refresh_conditions();
        }
    }

    /// An extra current every motor draws while the drive output is on — a stalled wheel, a
    /// heavy load — A (0 removes it).
    pub fn set_extra_load_a(&mut self, now: Timestamp, amps: f64) {
        self.expire(now);
        self.extra_load_a = non_negative(amps);
    }

    // -----------------------------------------------------------------------------------------
    // Rules.

    fn mode(&self) -> u8 {
        if self.rc_on {
            mode::RC
        } else {
            mode::CAN_COMMAND
        }
    }

    /// The drive output is off (booting, power cut, protection).
    fn output_cut(&self) -> bool {
        self.body.is_booting() || self.latched != 0
    }

    /// The hottest motor driver, °C, and the largest rms motor current, A.
    fn peaks(&self) -> (f64, f64) {
        let max = |v: [f64; 4]| v.into_iter().fold(f64::NEG_INFINITY, f64::max);
        (max(self.driver_temp_c), max(self.motor_currents_rms_a()))
    }

    fn fault_word(&self, now: Timestamp) -> u16 {
        let (hottest_c, rms_a) = self.peaks();
        let mut word = self.latched;
        if self.checksum_fault_until.is_some_and(|t| now < t) {
            word |= fault::COMMAND_CHECKSUM;
        }
        if hottest_c > Self::OVER_TEMPERATURE_ALARM_C {
            word |= fault::DRIVE_OVER_TEMP_ALARM;
        }
        if rms_a > Self::OVER_CURRENT_ALARM_A {
            word |= fault::MOTOR_OVER_CURRENT_ALARM;
        }
        if self.body.battery_voltage_v() < self.profile.under_voltage_alarm_v {
            word |= fault::BATTERY_UNDER_VOLTAGE_ALARM;
        }
        if !self.rc_on {
            word |= fault::RC_DISCONNECTED;
        }
        word
    }

    fn body_status(&self) -> u8 {
        if self.latched == 0 {
            body::NORMAL
        } else {
            body::EXCEPTION
        }
    }

    /// Latches the faults whose cause is present (lost drivers, flat battery, heat, current).
    fn refresh_conditions(&mut self) {
        if self.body.is_booting() {
            return;
        }
        for (lost, bit) in self.body.motor_lost.iter().zip(MOTOR_COMM) {
            if *lost {
                self.latched |= bit;
            }
        }
        if self.body.battery_voltage_v() < self.profile.under_voltage_failure_v {
            self.latched |= fault::BATTERY_UNDER_VOLTAGE;
        }
        let (hottest_c, rms_a) = self.peaks();
        if hottest_c > Self::OVER_TEMPERATURE_PROTECTION_C {
            self.latched |= fault::DRIVE_OVER_TEMP_PROTECTION;
        }
        if rms_a > Self::OVER_CURRENT_PROTECTION_A {
            self.latched |= fault::MOTOR_OVER_CURRENT_PROTECTION;
        }
    }

    /// Physics and the deadlines that change what the chassis does (boot end, command timeout).
    fn expire(&mut self, now: Timestamp) {
        for dt in self.body.substeps(now) {
            self.step(dt);
        }
        if self.body.expire(now).is_some() {
            self.refresh_conditions();
        }
        if self.command_until.is_some_and(|t| now >= t) {
            self.command_until = None;
            self.command = Motion::default();
        }
        if self.checksum_fault_until.is_some_and(|t| now >= t) {
            self.checksum_fault_until = None;
        }
    }

    fn on_motion(&mut self, now: Timestamp, c: MotionCommand) {
        let mut acted = false;
        if c.fault_clear != clear_code::NONE {
            self.clear_fault(c.fault_clear);
            acted = true;
        }
        if c.mode == mode::CAN_COMMAND && !self.rc_on {
            self.command = Motion {
                linear_mps: c.linear_mps,
                angular_radps: c.angular_radps,
            };
            self.command_until = Some(past_timeout(now, self.profile.command_timeout_ms));
            acted = true;
        }
        if acted {
            self.body.received.commands += 1;
        } else {
            self.body.received.ignored += 1;
        }
    }

    fn on_lights(&mut self, l: Lights) {
        self.lights = if l.control_enabled {
            l
        } else {
            Lights::default()
        };
        self.body.received.commands += 1;
    }

    fn clear_fault(&mut self, code: u8) {
        let clear = match code {
            clear_code::BATTERY_UNDER_VOLTAGE => fault::BATTERY_UNDER_VOLTAGE,
            clear_code::BATTERY_OVER_VOLTAGE => fault::BATTERY_OVER_VOLTAGE,
            clear_code::MOTOR_1_COMM..=clear_code::MOTOR_4_COMM => MOTOR_COMM
                .get(usize::from(code - clear_code::MOTOR_1_COMM))
                .copied()
                .unwrap_or(0),
            clear_code::DRIVE_OVER_TEMPERATURE => fault::DRIVE_OVER_TEMP_PROTECTION,
            clear_code::MOTOR_OVER_CURRENT => fault::MOTOR_OVER_CURRENT_PROTECTION,
            _ => 0,
        };
        self.latched &= !clear;
        // A cause that persists latches again at once.
        self.refresh_conditions();
    }

    fn reboot(&mut self, now: Timestamp) {
        self.command = Motion::default();
        self.command_until = None;
        self.checksum_fault_until = None;
        self.latched = 0;
        self.lights = Lights::default();
        self.counts = [0; FEEDBACK_IDS.len()];
        if self.body.reboot(now) {
            self.refresh_conditions();
        }
    }

    // -----------------------------------------------------------------------------------------
    // Physics.

    /// Target speeds and the time constant toward them.
    fn target(&self) -> (Motion, f64) {
        if self.body.is_booting() || self.latched & POWER_FAULTS != 0 {
            (Motion::default(), Self::DEFAULT_STOP_TIME_CONSTANT_S)
        } else if self.latched & PROTECTIONS != 0 {
            (Motion::default(), Self::PROTECTION_STOP_TIME_CONSTANT_S)
        } else if self.rc_on {
            // Sticks centred.
            (Motion::default(), self.speed_time_constant_s)
        } else {
            (self.command, self.speed_time_constant_s)
        }
    }

    /// Integrates `dt` seconds (one sub-step of [`substeps`], never zero).
    fn step(&mut self, dt: f64) {
        self.refresh_conditions();
        let (mut target, mut tau) = self.target();
        target.linear_mps *= self.body.gain;
        target.angular_radps *= self.body.gain;
        if let Some(runaway) = self.body.runaway_mps {
            target.linear_mps = runaway;
            tau = self.speed_time_constant_s;
        }
        let lag = |from: f64, to: f64| first_order_lag(from, to, tau, dt);
        let (v0, w0) = (self.linear_mps, self.angular_radps);
        let v1 = lag(v0, target.linear_mps);
        let w1 = lag(w0, target.angular_radps);

        // Midpoint rule for the pose.
        let v_mid = 0.5 * (v0 + v1);
        let w_mid = 0.5 * (w0 + w1);
        self.body.pose.advance(v_mid, 0.0, w_mid, dt);
        self.linear_mps = v1;
        self.angular_radps = w1;

        let (left, right) = side_speeds(v1, w1, &self.profile);
        let (left_acc, right_acc) = side_speeds((v1 - v0) / dt, (w1 - w0) / dt, &self.profile);
        self.wheel_mps = [left, right, left, right];
        let accel = [left_acc, right_acc, left_acc, right_acc];
        let output_on = !self.output_cut();
        let rms_keep = (-dt / Self::CURRENT_RMS_TIME_CONSTANT_S).exp();
        let heat_keep = (-dt / Self::THERMAL_TIME_CONSTANT_S).exp();
        let currents: [f64; 4] = std::array::from_fn(|motor| {
            if output_on && !self.body.motor_lost[motor] {
                Self::MOTOR.magnitude_a(self.wheel_mps[motor], accel[motor], self.extra_load_a)
            } else {
                0.0
            }
        });
        self.motor_current_a = currents;
        for ((sq, temp), current) in self
            .current_sq_a2
            .iter_mut()
            .zip(self.driver_temp_c.iter_mut())
            .zip(currents)
        {
            *sq = current * current + (*sq - current * current) * rms_keep;
            let steady = Self::AMBIENT_C + Self::DRIVER_C_PER_A2 * *sq;
            *temp = steady + (*temp - steady) * heat_keep;
        }
        let motors_a = self.motor_current_a.iter().sum::<f64>();
        self.body.draw(Self::IDLE_CURRENT_A + motors_a, dt);
    }

    // -----------------------------------------------------------------------------------------
    // Output.

    fn send(&mut self, now: Timestamp, frame: Frame) {
        self.send_injected(now, frame, InjectedCounts::default());
    }

    /// Like [`V1Sim::send`], for a frame that carries an injected fault (a flood's); a
    /// pending [`Injection::BadChecksums`] corrupts it as it would any frame.
    fn send_injected(&mut self, now: Timestamp, frame: Frame, mut injected: InjectedCounts) {
        if self.body.is_quiet(now) {
            return;
        }
        let Some(index) = FEEDBACK_IDS.iter().position(|i| *i == frame.id()) else {
            // Only feedback ids are sent by the chassis.
            return;
        };
        let count = self.counts[index];
        // Every value is kept inside its wire range; a frame that still does not fit is not sent.
        let Ok(mut can) = frame.encode(count, &self.profile) else {
            return;
        };
        self.counts[index] = count.wrapping_add(1);
        if self.body.take_corruption() {
            can = corrupt_checksum(&can);
            injected = injected + InjectedCounts::BAD_CHECKSUM;
        }
        self.body.outbox.push_injected(can, injected);
    }

    fn motion_feedback(&self) -> Frame {
        Frame::MotionFeedback(MotionFeedback {
            linear_mps: clamp_i16(self.linear_mps, 1000.0),
            angular_radps: clamp_i16(self.angular_radps, 1000.0),
        })
    }

    fn motor_feedback(&self, motor: usize) -> Frame {
        let index = motor.min(3);
        let rpm = self.wheel_mps[index] / (std::f64::consts::TAU * Self::WHEEL_RADIUS_M) * 60.0;
        let driver_temp = self.driver_temp_c[index];
        let motor_temp = Self::AMBIENT_C + 0.6 * (driver_temp - Self::AMBIENT_C);
        Frame::Motor(MotorFeedback {
            // index < 4.
            motor: index as u8 + 1,
            current_a: self.motor_current_a[index].clamp(0.0, 6553.5),
            rpm: clamp_i16(rpm.round(), 1.0),
            driver_temp_c: driver_temp.round().clamp(-128.0, 127.0),
            motor_temp_c: motor_temp.round().clamp(-128.0, 127.0),
        })
    }

    fn send_feedback(&mut self, now: Timestamp) {
        self.send(
            now,
            Frame::SystemStatus(SystemStatus {
                body_status: self.body_status(),
                mode: self.mode(),
                battery_voltage_v: self.body.battery_voltage_v().min(6553.5),
                vendor_fault_word: self.fault_word(now),
            }),
        );
        self.send(now, self.motion_feedback());
        for motor in 0..4 {
            if !self.body.motor_lost[motor] {
                self.send(now, self.motor_feedback(motor));
            }
        }
        self.send(now, Frame::LightState(self.lights));
    }
}

impl Firmware for V1Sim {
    fn robot(&self) -> RobotKind {
        self.profile.model.robot()
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        self.expire(now);
        if self.body.is_booting() {
            self.body.received.ignored += 1;
            return;
        }
        let Rx::Can(frame) = rx else {
            self.body.received.decode_errors += 1;
            return;
        };
        match decode(frame, &self.profile) {
            Ok(decoded) => match decoded.frame {
                Frame::MotionCommand(c) => self.on_motion(now, c),
                Frame::LightCommand(l) => self.on_lights(l),
                Frame::SystemStatus(_)
                | Frame::MotionFeedback(_)
                | Frame::Motor(_)
                | Frame::LightState(_) => self.body.received.not_for_it += 1,
            },
            Err(DecodeError::BadChecksum { .. }) => {
                self.body.received.bad_checksums += 1;
                self.checksum_fault_until = Some(now + self.checksum_fault_hold);
            }
            Err(_) => self.body.received.decode_errors += 1,
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        self.expire(now);
        if self.fast.serve_due(now) {
            self.send_feedback(now);
        }
        if let Some(motor) = self.body.flood_due(now) {
            let copy = if motor {
                self.motor_feedback(0)
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
        [self.command_until, self.body.poll_timeout()]
            .into_iter()
            .fold(Some(self.fast.next()), earliest)
    }

    fn inject(&mut self, now: Timestamp, injection: Injection) -> bool {
        self.expire(now);
        match self.body.inject(now, injection) {
            Applied::Condition => self.refresh_conditions(),
            Applied::Done => {}
            Applied::Refused => return false,
            Applied::Robot(Injection::RcTakeover(on)) => {
                self.rc_on = on;
                if on {
                    self.command = Motion::default();
                    self.command_until = None;
                }
            }
            Applied::Robot(Injection::Reboot) => self.reboot(now),
            // The anti-collision tube is no switch; no range sensors, no E-stop switch.
            Applied::Robot(_) => return false,
        }
        true
    }

    fn truth(&self) -> SimTruth {
        SimTruth {
            linear_mps: self.linear_mps,
            angular_radps: self.angular_radps,
            control_mode: if self.rc_on {
                ControlMode::REMOTE
            } else {
                ControlMode::COMMAND
            },
            fault_flags: normalize_faults(self.fault_word(self.body.last_update()))
                | vehicle_state_flags(self.body_status()),
            ..self.body.truth()
        }
    }
}

/// The same frame with its checksum byte (b7) inverted.
fn corrupt_checksum(frame: &CanFrame) -> CanFrame {
    let mut data = [0u8; 8];
    let len = frame.len().min(8);
    data[..len].copy_from_slice(frame.data());
    if let Some(last) = data[..len].last_mut() {
        *last = !*last;
    }
    CanFrame::new(frame.id(), &data[..len]).unwrap_or(*frame)
}

#[cfg(test)]
#[path = "sim_tests.rs"]
mod sim_tests;
