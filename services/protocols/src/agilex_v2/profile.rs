//! Profiles of the AgileX protocol-V2 robots: one struct for the whole family, one default per
//! model. Every doubtful point of the V2 reading (`docs/PROTOCOLS.md`, "AgileX protocol V2",
//! ⚠ D-1 … D-26) is a field here, with the reading's proposed default for that robot.

use chassis_interfaces::FaultFlags as F;
use serde::{Deserialize, Serialize};

use crate::kind::RobotKind;

/// Which V2 robot (and variant) a profile describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum V2Model {
    /// SCOUT 2.0 (V2 firmware): four-wheel skid steer.
    Scout,
    /// SCOUT MINI with V2 firmware, skid-steer wheels.
    ScoutMini,
    /// SCOUT MINI with V2 firmware, mecanum (omni) wheels.
    ScoutMiniOmni,
    /// HUNTER 2.0: front-wheel Ackermann with a parking brake.
    Hunter,
    /// HUNTER SE: front-wheel Ackermann, steering zero over 0x432/0x433.
    HunterSe,
    /// TRACER: two-wheel differential.
    Tracer,
    /// TRACER MINI: differential, (v, ω) in 0x111 like the TRACER (`PROTOCOLS-V2` §3.5, TMM).
    TracerMini,
    /// BUNKER / BUNKER MINI: tracked, differential.
    Bunker,
    /// RANGER MINI 2.0 / 3.0: four-wheel independent steering (dual Ackermann, crab, spin, park).
    RangerMini,
    /// RANGER MINI 1.0: "modified V2" — angles in 0.01° inverted, spin speed in b4-5.
    RangerMiniV1,
}

impl V2Model {
    /// Every V2 model (a new one last: the fuzz target's leading byte picks a model by its place
    /// here).
    pub const ALL: [V2Model; 10] = [
        V2Model::Scout,
        V2Model::ScoutMini,
        V2Model::ScoutMiniOmni,
        V2Model::Hunter,
        V2Model::HunterSe,
        V2Model::Tracer,
        V2Model::Bunker,
        V2Model::RangerMini,
        V2Model::RangerMiniV1,
        V2Model::TracerMini,
    ];

    /// The robot of this model (a variant is its robot's).
    pub fn robot(self) -> RobotKind {
        match self {
            V2Model::Scout => RobotKind::Scout,
            V2Model::ScoutMini | V2Model::ScoutMiniOmni => RobotKind::ScoutMini,
            V2Model::Hunter => RobotKind::Hunter,
            V2Model::HunterSe => RobotKind::HunterSe,
            V2Model::Tracer => RobotKind::Tracer,
            V2Model::TracerMini => RobotKind::TracerMini,
            V2Model::Bunker => RobotKind::Bunker,
            V2Model::RangerMini | V2Model::RangerMiniV1 => RobotKind::RangerMini,
        }
    }
}

/// How the twist maps onto 0x111 (`PROTOCOLS-V2` §3.8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kinematics {
    /// Differential, skid or tracked: (v, ω); v_y unachievable.
    Differential,
    /// Mecanum: (v, ω, v_y).
    Omni,
    /// Front-wheel Ackermann: (v, δ inner); no turn on the spot.
    Ackermann,
    /// Four-wheel steering with motion modes (dual Ackermann, crab, spin), set by 0x141.
    FourWheelSteer,
}

/// ⚠ D-1: which version request to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VersionQuery {
    /// 0x411 first, 0x4A1 only if nothing answers within a second.
    Both,
    /// 0x411 → 0x41A (manual).
    Manual,
    /// 0x4A1 → 0x4A1 text (SDK since 2023).
    Sdk,
    /// Never ask.
    Never,
}

/// ⚠ D-2: the values of 0x211 b1 (and what 0x421 accepts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModeCodes {
    /// Standby; `None` where the firmware has no standby (TRACER v1.2 calls 0x00 "RC").
    pub standby: Option<u8>,
    /// CAN command mode.
    pub can: u8,
    /// Serial (UART / APP) control.
    pub uart: Option<u8>,
    /// An RC transmitter holds authority.
    pub rc: u8,
}

impl ModeCodes {
    /// Each mode's name with its code under these codes, in the order a shared code is named.
    pub(crate) fn names(&self) -> [(Option<u8>, &'static str); 4] {
        [
            (Some(self.can), "can"),
            (Some(self.rc), "rc"),
            (self.standby, "standby"),
            (self.uart, "uart"),
        ]
    }

    /// SDK ≥ v0.5.0, SCOUT v1.3.0, HUNTER SE, RANGER MINI, TRACER MINI.
    pub const SDK: ModeCodes = ModeCodes {
        standby: Some(0),
        can: 1,
        uart: Some(2),
        rc: 3,
    };
    /// HUNTER 2.0 (H2X v2.1).
    pub const HUNTER_2: ModeCodes = ModeCodes {
        standby: Some(0),
        can: 1,
        uart: None,
        rc: 2,
    };
    /// TRACER v1.2 and the older SDK.
    pub const TRACER_V12: ModeCodes = ModeCodes {
        standby: None,
        can: 1,
        uart: Some(2),
        rc: 0,
    };
}

/// ⚠ D-3: which fault-bit table 0x211 b4-5 follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultMap {
    /// SDK generic masks (SCOUT 2.0 / MINI later firmware, BUNKER, RANGER).
    Sdk,
    /// SCOUT v1.3.0 manual and TRACER v1.2 (b4 only).
    ScoutV13,
    /// TRACER MINI.
    TracerMini,
    /// HUNTER 2.0.
    Hunter2,
    /// HUNTER SE.
    HunterSe,
}

/// One bit of 0x211's fault word (b4 = high byte, b5 = low byte) under a ⚠ D-3 table: its name
/// as `PROTOCOLS-V2` §2.3.2 gives it for that robot, and the normalized flag it raises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultBit {
    /// The bit in the `u16be` word (b4 bit0 = 0x0100, b5 bit0 = 0x0001).
    pub mask: u16,
    /// The vendor's meaning, in snake case.
    pub name: &'static str,
    /// The `chassis_interfaces::FaultFlags` bit it sets.
    pub flag: u64,
}

/// b4 bit `n` of 0x211 (the high byte of the fault word).
const fn b4(n: u16, name: &'static str, flag: u64) -> FaultBit {
    b5(8 + n, name, flag)
}

/// b5 bit `n` of 0x211 (the low byte of the fault word; `n` 8-15 reach b4).
const fn b5(n: u16, name: &'static str, flag: u64) -> FaultBit {
    FaultBit {
        mask: 1 << n,
        name,
        flag,
    }
}

/// §2.3.2, SDK generic masks (`agilex_message.h`), SCOUT 2.0 / MINI later firmware; ROAS agrees
/// on b5 bits 0-6. b5 bit7 is ⚠ D-20's.
const SDK_FAULTS: &[FaultBit] = &[
    b4(0, "motor_driver_error", F::MOTOR_DRIVER_ERROR),
    b4(1, "host_communication_lost", F::HEARTBEAT_LOST),
    b5(0, "battery_failure", F::BATTERY_UNDER_VOLTAGE),
    b5(1, "battery_warning", F::BATTERY_UNDER_VOLTAGE_WARNING),
    b5(2, "rc_signal_lost", F::RC_LINK_LOST),
    b5(3, "motor_1_communication_lost", F::MOTOR_1_COMM_LOST),
    b5(4, "motor_2_communication_lost", F::MOTOR_2_COMM_LOST),
    b5(5, "motor_3_communication_lost", F::MOTOR_3_COMM_LOST),
    b5(6, "motor_4_communication_lost", F::MOTOR_4_COMM_LOST),
];

/// §2.3.2, SCOUT v1.3.0 (S2D table 3.2), TRACER v1.2 (TRM table 3.2): b4 only.
const SCOUT_V13_FAULTS: &[FaultBit] = &[
    b4(0, "battery_under_voltage_failure", F::BATTERY_UNDER_VOLTAGE),
    b4(
        1,
        "battery_under_voltage_warning",
        F::BATTERY_UNDER_VOLTAGE_WARNING,
    ),
    b4(2, "rc_link_lost", F::RC_LINK_LOST),
];

/// §2.3.2, TRACER MINI (TMM p18).
const TRACER_MINI_FAULTS: &[FaultBit] = &[
    b4(1, "accessory_12v_over_current", F::OVER_CURRENT),
    b4(7, "anti_collision_strip", F::BUMPER),
    b5(0, "battery_under_voltage_failure", F::BATTERY_UNDER_VOLTAGE),
    b5(
        1,
        "battery_under_voltage_warning",
        F::BATTERY_UNDER_VOLTAGE_WARNING,
    ),
    b5(2, "rc_link_lost", F::RC_LINK_LOST),
];

/// §2.3.2, HUNTER 2.0 (H2X table 1).
const HUNTER_2_FAULTS: &[FaultBit] = &[
    b4(
        1,
        "front_steering_encoder_offline",
        F::FRONT_STEERING_ENCODER,
    ),
    b4(2, "rc_link_lost", F::RC_LINK_LOST),
    b4(4, "host_communication_lost", F::HEARTBEAT_LOST),
    b4(6, "driver_state_error", F::MOTOR_DRIVER_ERROR),
    b5(0, "battery_under_voltage", F::BATTERY_UNDER_VOLTAGE),
    b5(
        3,
        "steering_driver_communication_lost",
        F::MOTOR_1_COMM_LOST,
    ),
    b5(
        4,
        "rear_right_driver_communication_lost",
        F::MOTOR_2_COMM_LOST,
    ),
    b5(
        5,
        "rear_left_driver_communication_lost",
        F::MOTOR_3_COMM_LOST,
    ),
    b5(6, "driver_over_temperature", F::OVER_TEMPERATURE),
    b5(7, "motor_over_current", F::OVER_CURRENT),
];

/// §2.3.2, HUNTER SE (HSE table 3.1); b5 bit7 is ⚠ D-20's.
const HUNTER_SE_FAULTS: &[FaultBit] = &[
    b4(0, "motor_over_temperature", F::OVER_TEMPERATURE),
    b4(1, "driver_over_current", F::OVER_CURRENT),
    b4(2, "driver_status_error", F::MOTOR_DRIVER_ERROR),
    b5(0, "battery_under_voltage", F::BATTERY_UNDER_VOLTAGE),
    b5(1, "steering_zero_setting_error", F::FRONT_STEERING_ENCODER),
    b5(2, "rc_link_lost", F::RC_LINK_LOST),
    b5(
        3,
        "steering_driver_communication_lost",
        F::MOTOR_1_COMM_LOST,
    ),
    b5(
        4,
        "rear_right_driver_communication_lost",
        F::MOTOR_2_COMM_LOST,
    ),
    b5(
        5,
        "rear_left_driver_communication_lost",
        F::MOTOR_3_COMM_LOST,
    ),
];

impl FaultMap {
    /// The table's bits, as §2.3.2 names them. On the SDK and HUNTER SE tables b5 bit7
    /// (0x0080) is left to ⚠ D-20 ([`V2Profile::fault_bits`] adds it).
    pub fn bits(self) -> &'static [FaultBit] {
        match self {
            FaultMap::Sdk => SDK_FAULTS,
            FaultMap::ScoutV13 => SCOUT_V13_FAULTS,
            FaultMap::TracerMini => TRACER_MINI_FAULTS,
            FaultMap::Hunter2 => HUNTER_2_FAULTS,
            FaultMap::HunterSe => HUNTER_SE_FAULTS,
        }
    }
}

/// ⚠ D-6: layout of 0x362.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum BmsAlarmLayout {
    /// Alarm 1, alarm 2, warning 1, warning 2 (current SDK, HUNTER SE, TITAN).
    AlarmWarning,
    /// Protection codes 1-4, max / min cell temperature, count (older SDK).
    ProtectionCodes,
}

/// ⚠ D-10: how the steering zero is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SteeringZero {
    /// No steering zero over CAN.
    None,
    /// 0x431 with the profile's request value, acknowledged by 0x43A 0xEE (HUNTER 2.0).
    Request431,
    /// 0x432 set offset / 0x433 query / 0x43B answer (HUNTER SE).
    Offset432,
}

/// ⚠ D-11: order of the stick bytes in 0x241.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RcStickOrder {
    /// b1 right horizontal, b2 right vertical (SDK, TITAN).
    Sdk,
    /// b1 right vertical, b2 right horizontal (pyagxrobots).
    Pya,
}

/// ⚠ D-12: RANGER motion-mode numbers (0x141 / 0x291 b0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangerModeCodes {
    pub dual_ackermann: u8,
    pub crab: u8,
    pub spin: u8,
    pub park: Option<u8>,
    pub side_slip: Option<u8>,
}

impl RangerModeCodes {
    /// Each motion mode's name with its code under these codes, in the order a shared code is
    /// named.
    pub(crate) fn names(&self) -> [(Option<u8>, &'static str); 5] {
        [
            (Some(self.dual_ackermann), "dual_ackermann"),
            (Some(self.crab), "crab"),
            (Some(self.spin), "spin"),
            (self.park, "park"),
            (self.side_slip, "side_slip"),
        ]
    }

    /// RANGER MINI 2.0 / 3.0, RANGER (SDK ≥ 50b81529, RR1).
    pub const SDK: RangerModeCodes = RangerModeCodes {
        dual_ackermann: 0,
        crab: 1,
        spin: 2,
        park: Some(3),
        side_slip: Some(4),
    };
    /// RANGER MINI 1.0.
    pub const MINI_V1: RangerModeCodes = RangerModeCodes {
        dual_ackermann: 0,
        crab: 1,
        spin: 2,
        park: None,
        side_slip: Some(3),
    };
}

/// ⚠ D-13: where a spin (turn on the spot) speed goes in 0x111.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpinField {
    /// b2-3 yaw rate, 0.001 rad/s (SDK `RangerBase`).
    AngularB2,
    /// b4-5 wheel speed ω·r_spin, mm/s (RANGER MINI 1.0; an unmerged AgileX change for 2.0).
    WheelSpeedB4,
}

/// ⚠ D-14 / D-15: unit and sign of the steering fields (0x111 / 0x221 b6-7, 0x271).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SteerUnit {
    /// 0.001 rad, left positive.
    Milliradian,
    /// 0.01°, sign inverted (RANGER MINI 1.0).
    CentidegreeInverted,
}

impl SteerUnit {
    /// Wire units per radian, with the sign.
    pub fn scale(self) -> f64 {
        match self {
            SteerUnit::Milliradian => 1000.0,
            SteerUnit::CentidegreeInverted => -18000.0 / std::f64::consts::PI,
        }
    }
}

/// Profile of one AgileX protocol-V2 robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V2Profile {
    pub model: V2Model,
    pub kinematics: Kinematics,
    /// Wheelbase L, m.
    pub wheelbase_m: f64,
    /// Track W, m.
    pub track_m: f64,
    /// ⚠ D-19 / D-23: top speed the driver commands, m/s.
    pub max_linear_mps: f64,
    /// ⚠ D-19: largest yaw rate the driver commands (spin speed on four-wheel steering), rad/s.
    pub max_angular_radps: f64,
    /// ⚠ D-19: largest lateral speed (omni), m/s; 0 where there is none.
    pub max_lateral_mps: f64,
    /// Largest inner steering angle (Ackermann, dual Ackermann), rad.
    pub max_steer_rad: f64,
    /// Largest crab angle (four-wheel steering), rad.
    pub max_crab_rad: f64,
    /// Turn radius below which four-wheel steering spins instead, m.
    pub min_turn_radius_m: f64,
    /// Spin radius (half the wheel diagonal) for [`SpinField::WheelSpeedB4`], m.
    pub spin_radius_m: f64,
    /// Number of actuators (0x251-0x258 / 0x261-0x268).
    pub actuators: u8,
    /// ⚠ D-26: actuator names in 0x25x order (documented only for SCOUT MINI and HUNTER).
    pub actuator_names: Vec<String>,
    /// The chassis' command timeout, ms.
    pub command_timeout_ms: u64,
    /// Heartbeat (0x111) period, ms.
    pub heartbeat_period_ms: u64,
    /// ⚠ D-8: period of 0x211, ms (watchdogs allow for the slower 100 ms).
    pub status_period_ms: u64,
    /// ⚠ D-1.
    pub version_query: VersionQuery,
    /// ⚠ D-2.
    pub mode_codes: ModeCodes,
    /// ⚠ D-3.
    pub fault_map: FaultMap,
    /// ⚠ D-4: value of 0x131 b0 that locks the brake; `None`: the robot has no brake.
    pub brake_lock_value: Option<u8>,
    /// ⚠ D-5: unit of 0x361 b2-3, V.
    pub bms_voltage_lsb_v: f64,
    /// ⚠ D-6.
    pub bms_alarm_layout: BmsAlarmLayout,
    /// ⚠ D-7: 0x26x b5 bit6 = 1 means "enabled" (else "disabled").
    pub driver_bit6_means_enabled: bool,
    /// ⚠ D-9: DLC of one-byte commands (0x421, 0x441, 0x131, 0x141): 1 or 8.
    pub short_commands_dlc: u8,
    /// ⚠ D-10.
    pub steering_zero: SteeringZero,
    /// ⚠ D-10: 0x431 b0.
    pub steering_zero_request: u8,
    /// ⚠ D-11.
    pub rc_stick_order: RcStickOrder,
    /// ⚠ D-12.
    pub ranger_mode_codes: RangerModeCodes,
    /// ⚠ D-13.
    pub spin_speed_field: SpinField,
    /// ⚠ D-14 / D-15.
    pub steer_unit: SteerUnit,
    /// ⚠ D-16: listen this long for V1/V2 evidence before giving up, ms.
    pub detect_timeout_ms: u64,
    /// ⚠ D-16: consistent frames of one protocol needed to decide.
    pub detect_min_frames: u32,
    /// ⚠ D-17: 0x111 / 0x221 b4-5 positive = left.
    pub lateral_left_positive: bool,
    /// ⚠ D-18: resend 0x121 this often while overriding the lights, ms.
    pub light_refresh_ms: u64,
    /// Front light fitted (0x121 b1-2).
    pub front_light: bool,
    /// Rear light fitted (0x121 b3-4).
    pub rear_light: bool,
    /// ⚠ D-20: fault word bit 0x0080 means E-stop (else steering encoder).
    pub fault_0080_is_estop: bool,
    /// ⚠ D-21: 0x25x b4-7 carries encoder positions.
    pub motor_position_valid: bool,
    /// ⚠ D-22: the firmware starts in standby (else in command mode, TRACER v1.2 wording).
    pub starts_in_standby: bool,
    /// ⚠ D-24: unit of 0x311, m.
    pub odometer_lsb_m: f64,
    /// ⚠ D-25: the chassis reports its motion mode in 0x291.
    pub motion_mode_feedback: bool,
    /// 0x441 code clearing every non-severe fault (§2.3.4: HUNTER 2.0 0xFF, others 0x00).
    pub clear_all_code: u8,
    /// Battery under-voltage alarm level, V (0x211 b2-3).
    pub under_voltage_alarm_v: f64,
    /// Battery under-voltage failure level, V: the chassis cuts drive power below it (SCOUT 2.0
    /// §2.3.2 table: 22 V; HUNTER SE: 24 V; the others' manuals give none, so 22 V).
    pub under_voltage_failure_v: f64,
}

impl Default for V2Profile {
    fn default() -> Self {
        V2Profile::for_model(V2Model::Scout)
    }
}

fn names(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| (*s).to_string()).collect()
}

/// `b4_bitN` / `b5_bitN` for a fault-word bit no table names.
fn unnamed_fault_bit(mask: u16) -> String {
    let n = mask.trailing_zeros();
    if n >= 8 {
        format!("b4_bit{}", n - 8)
    } else {
        format!("b5_bit{n}")
    }
}

impl V2Profile {
    /// The reading's defaults for `model`.
    // 0.5235 and 2.5235 are the SDK's full scales as printed, not approximations of π/6.
    #[allow(clippy::approx_constant)]
    pub fn for_model(model: V2Model) -> Self {
        let skid4 = names(&["front-right", "front-left", "rear-left", "rear-right"]);
        let base = V2Profile {
            model,
            kinematics: Kinematics::Differential,
            wheelbase_m: 0.498,
            track_m: 0.583,
            max_linear_mps: 1.5,
            max_angular_radps: 0.5235,
            max_lateral_mps: 0.0,
            max_steer_rad: 0.0,
            max_crab_rad: 0.0,
            min_turn_radius_m: 0.0,
            spin_radius_m: 0.0,
            actuators: 4,
            actuator_names: skid4.clone(),
            command_timeout_ms: 500,
            heartbeat_period_ms: 20,
            status_period_ms: 100,
            version_query: VersionQuery::Both,
            mode_codes: ModeCodes::SDK,
            fault_map: FaultMap::Sdk,
            brake_lock_value: None,
            bms_voltage_lsb_v: 0.1,
            bms_alarm_layout: BmsAlarmLayout::AlarmWarning,
            driver_bit6_means_enabled: true,
            short_commands_dlc: 8,
            steering_zero: SteeringZero::None,
            steering_zero_request: 0xAA,
            rc_stick_order: RcStickOrder::Sdk,
            ranger_mode_codes: RangerModeCodes::SDK,
            spin_speed_field: SpinField::AngularB2,
            steer_unit: SteerUnit::Milliradian,
            detect_timeout_ms: 5000,
            detect_min_frames: 3,
            lateral_left_positive: true,
            light_refresh_ms: 200,
            front_light: true,
            rear_light: true,
            fault_0080_is_estop: true,
            motor_position_valid: true,
            starts_in_standby: true,
            odometer_lsb_m: 0.001,
            motion_mode_feedback: false,
            clear_all_code: 0x00,
            under_voltage_alarm_v: 23.5,
            under_voltage_failure_v: 22.0,
        };
        match model {
            V2Model::Scout => base,
            V2Model::ScoutMini => V2Profile {
                wheelbase_m: 0.452,
                track_m: 0.490,
                max_linear_mps: 3.0,
                max_angular_radps: 2.5235,
                under_voltage_alarm_v: 22.5,
                ..base
            },
            V2Model::ScoutMiniOmni => V2Profile {
                model,
                kinematics: Kinematics::Omni,
                max_lateral_mps: 2.0,
                ..V2Profile::for_model(V2Model::ScoutMini)
            },
            V2Model::Hunter => V2Profile {
                kinematics: Kinematics::Ackermann,
                wheelbase_m: 0.650,
                track_m: 0.605,
                max_linear_mps: 1.5,
                max_angular_radps: 0.0,
                max_steer_rad: 0.576,
                actuators: 3,
                actuator_names: names(&["steering", "rear-right", "rear-left"]),
                mode_codes: ModeCodes::HUNTER_2,
                fault_map: FaultMap::Hunter2,
                brake_lock_value: Some(0x01),
                bms_voltage_lsb_v: 0.01,
                driver_bit6_means_enabled: false,
                steering_zero: SteeringZero::Request431,
                fault_0080_is_estop: false,
                front_light: false,
                rear_light: false,
                clear_all_code: 0xFF,
                under_voltage_alarm_v: 24.5,
                ..base
            },
            V2Model::HunterSe => V2Profile {
                kinematics: Kinematics::Ackermann,
                wheelbase_m: 0.657,
                track_m: 0.550,
                max_linear_mps: 1.5,
                max_angular_radps: 0.0,
                max_steer_rad: 0.400,
                actuators: 3,
                actuator_names: names(&["steering", "rear-right", "rear-left"]),
                fault_map: FaultMap::HunterSe,
                bms_voltage_lsb_v: 0.01,
                steering_zero: SteeringZero::Offset432,
                motor_position_valid: false,
                rear_light: false,
                under_voltage_alarm_v: 24.5,
                // "cut-off < 24 V (SOC < 10 %)" (HSE §1.2).
                under_voltage_failure_v: 24.0,
                ..base
            },
            V2Model::Tracer => V2Profile {
                wheelbase_m: 0.5,
                track_m: 0.5,
                max_linear_mps: 1.8,
                max_angular_radps: 1.0,
                actuators: 2,
                actuator_names: names(&["right", "left"]),
                status_period_ms: 20,
                fault_map: FaultMap::TracerMini,
                motor_position_valid: false,
                rear_light: false,
                under_voltage_alarm_v: 22.5,
                ..base
            },
            // TRACER MINI. From TMM (the manual's CAN pages 17-22, as `PROTOCOLS-V2` §3.5 reads
            // them): 0x111 valid ±1800 mm/s and ±1000 × 0.001 rad/s; 0x211 b1 0 standby /
            // 1 command / 2 APP / 3 RC (⚠ D-2, `ModeCodes::SDK`); its own fault table (§2.3.2,
            // TMM p18, ⚠ D-3); standby at power-up (§1, TMM p22, ⚠ D-22); 0x211 every 20 ms
            // (⚠ D-8). Those pages give no dimensions, drives, lights or battery levels, so the
            // TRACER's values stand for them: two drives, the front light only, no motor
            // position (⚠ D-21), the 22.5 V alarm (TRM table 3.2), the family's 22 V failure
            // level, and the 0.5 × 0.5 m wheelbase and track, a placeholder no manual gives.
            V2Model::TracerMini => V2Profile {
                model,
                kinematics: Kinematics::Differential,
                max_linear_mps: 1.8,
                max_angular_radps: 1.0,
                status_period_ms: 20,
                mode_codes: ModeCodes::SDK,
                fault_map: FaultMap::TracerMini,
                starts_in_standby: true,
                ..V2Profile::for_model(V2Model::Tracer)
            },
            V2Model::Bunker => V2Profile {
                wheelbase_m: 0.5,
                track_m: 0.5,
                max_linear_mps: 1.5,
                max_angular_radps: 0.7853,
                actuators: 2,
                actuator_names: names(&["right", "left"]),
                front_light: false,
                rear_light: false,
                ..base
            },
            V2Model::RangerMini => V2Profile {
                kinematics: Kinematics::FourWheelSteer,
                wheelbase_m: 0.494,
                track_m: 0.364,
                max_linear_mps: 1.5,
                max_angular_radps: 4.8,
                max_steer_rad: 0.6981,
                max_crab_rad: 1.570,
                min_turn_radius_m: 0.4764,
                spin_radius_m: 0.3068,
                actuators: 8,
                actuator_names: names(&[
                    "drive-1", "drive-2", "drive-3", "drive-4", "steer-1", "steer-2", "steer-3",
                    "steer-4",
                ]),
                status_period_ms: 20,
                bms_voltage_lsb_v: 0.01,
                motion_mode_feedback: true,
                ..base
            },
            V2Model::RangerMiniV1 => V2Profile {
                model,
                wheelbase_m: 0.36,
                track_m: 0.36,
                max_angular_radps: 0.3,
                max_crab_rad: 0.6981,
                min_turn_radius_m: 0.4,
                spin_radius_m: 0.254558,
                ranger_mode_codes: RangerModeCodes::MINI_V1,
                spin_speed_field: SpinField::WheelSpeedB4,
                steer_unit: SteerUnit::CentidegreeInverted,
                lateral_left_positive: false,
                ..V2Profile::for_model(V2Model::RangerMini)
            },
        }
    }

    /// Every named bit of 0x211's fault word on this robot: the ⚠ D-3 table, with b5 bit7 as
    /// ⚠ D-20 reads it where the table leaves it open (SDK "steering encoder", HUNTER SE and the
    /// BUNKER MINI capture "E-stop").
    pub fn fault_bits(&self) -> impl Iterator<Item = FaultBit> + '_ {
        let d20 = matches!(self.fault_map, FaultMap::Sdk | FaultMap::HunterSe).then(|| {
            if self.fault_0080_is_estop {
                b5(7, "estop", F::EMERGENCY_STOP)
            } else {
                b5(7, "steering_encoder", F::FRONT_STEERING_ENCODER)
            }
        });
        self.fault_map.bits().iter().copied().chain(d20)
    }

    /// The names of the bits set in a 0x211 fault word, in the order of §2.3.2's table (b4 bit0
    /// … bit7, then b5 bit0 … bit7); a set bit the robot's table does not name reads `b4_bit3`,
    /// `b5_bit6`, ….
    pub fn fault_names(&self, word: u16) -> Vec<String> {
        (8..16u16)
            .chain(0..8)
            .map(|n| 1u16 << n)
            .filter(|mask| word & mask != 0)
            .map(|mask| {
                self.fault_bits()
                    .find(|b| b.mask == mask)
                    .map_or_else(|| unnamed_fault_bit(mask), |b| b.name.to_string())
            })
            .collect()
    }

    /// The fault-word bit that raises `flag` on this robot, if its table has one.
    pub fn fault_bit_for(&self, flag: u64) -> Option<u16> {
        self.fault_bits().find(|b| b.flag == flag).map(|b| b.mask)
    }

    /// 0x211 b6 is the parking-brake state (HUNTER 2.0, H2X row 18); reserved elsewhere.
    pub fn reports_brake_in_b6(&self) -> bool {
        self.brake_lock_value.is_some() && self.fault_map == FaultMap::Hunter2
    }

    /// This profile with the keys of `overrides` (the `[profile]` table of the service's
    /// config) set over it. Unknown keys and wrong types are errors.
    pub fn with_overrides(&self, overrides: &toml::Table) -> Result<Self, toml::de::Error> {
        crate::profile::with_overrides(self, overrides)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::family::Family;

    #[test]
    fn every_model_validates_and_names_itself() {
        for model in V2Model::ALL {
            let p = V2Profile::for_model(model);
            assert_eq!(p.validate(), Ok(()), "{model:?}");
            assert_eq!(p.model, model);
            assert_eq!(
                usize::from(p.actuators),
                p.actuator_names.len(),
                "{model:?}"
            );
        }
    }

    #[test]
    fn the_readings_defaults_per_robot() {
        let h = V2Profile::for_model(V2Model::Hunter);
        assert_eq!(h.mode_codes, ModeCodes::HUNTER_2);
        assert_eq!(h.brake_lock_value, Some(0x01));
        assert!(!h.driver_bit6_means_enabled);
        assert_eq!(h.clear_all_code, 0xFF);
        let se = V2Profile::for_model(V2Model::HunterSe);
        assert_eq!(se.max_linear_mps, 1.5);
        assert_eq!(se.steering_zero, SteeringZero::Offset432);
        assert!(!se.motor_position_valid);
        let omni = V2Profile::for_model(V2Model::ScoutMiniOmni);
        assert_eq!(omni.kinematics, Kinematics::Omni);
        assert!(omni.lateral_left_positive);
        let v1 = V2Profile::for_model(V2Model::RangerMiniV1);
        assert_eq!(v1.steer_unit, SteerUnit::CentidegreeInverted);
        assert_eq!(v1.ranger_mode_codes.side_slip, Some(3));
        assert_eq!(V2Profile::default().short_commands_dlc, 8);
    }

    #[test]
    fn overrides_set_keys_over_the_models_defaults() {
        let table: toml::Table =
            toml::from_str("short_commands_dlc = 1\nmax_linear_mps = 1.2").unwrap();
        let p = V2Profile::for_model(V2Model::Hunter)
            .with_overrides(&table)
            .unwrap();
        assert_eq!((p.short_commands_dlc, p.max_linear_mps), (1, 1.2));
        assert_eq!(p.brake_lock_value, Some(0x01));
        assert_eq!(p.wheelbase_m, 0.650);
        let bad: toml::Table = toml::from_str("max_speed = 4").unwrap();
        let err = V2Profile::default().with_overrides(&bad).unwrap_err();
        assert!(err.to_string().contains("unknown field"), "{err}");
        let nested: toml::Table = toml::from_str("mode_codes = { can = 1, rc = 0 }").unwrap();
        let p = V2Profile::default().with_overrides(&nested).unwrap();
        assert_eq!(p.mode_codes.standby, None);
    }

    #[test]
    fn nonsense_does_not_validate() {
        let p = V2Profile {
            short_commands_dlc: 3,
            ..V2Profile::default()
        };
        assert!(p.validate().is_err());
        let p = V2Profile {
            max_steer_rad: 0.0,
            ..V2Profile::for_model(V2Model::Hunter)
        };
        assert!(p.validate().is_err());
    }
}
