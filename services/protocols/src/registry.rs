//! The robot registry: one entry per robot, the one place that knows what each robot *is*.
//!
//! An entry names the robot (`--robot` spelling, display name), its bus, the wire protocols it
//! may speak and how the choice is made (listening on a real CAN bus when it may speak AgileX V1
//! or V2), how its profile's defaults are made, and the constructors of its driver, of its
//! simulated firmware and of its frame describer, with the facts no profile parameter holds:
//! the body's outline, the sensors with their mounting, the joints the bridges publish and the
//! odometry's stated variances. [`describe`](crate::description::describe) turns an entry and an
//! effective profile into the `RobotDescription` chassisd publishes; clients read that, never a
//! table of their own.
//!
//! Adding a robot: a variant of [`RobotKind`] (its number is what `ChassisState::robot`
//! carries), its [`RobotEntry`] in [`RobotKind::entry`], and its folder (codec, driver,
//! simulated firmware, profile) if it speaks a protocol of its own. The registry-wide tests
//! (`registry::tests`) walk every entry: a robot missing anywhere fails a test.

use std::time::Duration;

use chassis_interfaces::{
    BusKind, JointSource, Kinematics, OdometryVariance, SensorKind, WireProtocol,
};
use serde::{Deserialize, Serialize};

use crate::agilex_v2::{self, V2Model, V2Profile, detect::DetectSettings};
use crate::describe::RobotCodec;
use crate::driver::{BoxedDriver, DriverConfig};
use crate::firmware::BoxedFirmware;
use crate::profile::{
    Profile, Protocol, ProtocolError, TitanProfile, V1Model, V1Profile, XbotProfile,
};
use crate::{Timestamp, scout_mini, titan, xbot};

/// Which kind of robot. The number is the kind's id on the wire (`ChassisState::robot`,
/// `RobotDescription::kind`); 0 means none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[repr(u8)]
pub enum RobotKind {
    Titan = 1,
    ScoutMini = 2,
    Xbot = 3,
    /// SCOUT 2.0.
    Scout = 4,
    /// HUNTER 2.0.
    Hunter = 5,
    /// HUNTER SE.
    HunterSe = 6,
    /// TRACER.
    Tracer = 7,
    /// BUNKER / BUNKER MINI.
    Bunker = 8,
    /// RANGER MINI 2.0 / 3.0 (1.0 by its profile's `model`).
    RangerMini = 9,
}

/// A bus a robot is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bus {
    /// CAN at this bit rate, bit/s.
    Can { bitrate: u32 },
    /// An RS232 line; its baud rate is a profile parameter.
    Rs232,
}

impl Bus {
    /// `chassis_interfaces::BusKind`.
    pub fn kind(self) -> u8 {
        match self {
            Bus::Can { .. } => BusKind::CAN,
            Bus::Rs232 => BusKind::RS232,
        }
    }
}

/// The body's outline around `base_link`, m, and where the figures come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outline {
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    /// The manual's table the figures come from, or how they were made up.
    pub source: &'static str,
}

/// A sensor fitted to every robot of the kind, where it sits (`base_link`, REP-103 axes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Its name, also its frame id.
    pub name: &'static str,
    /// `chassis_interfaces::SensorKind`.
    pub kind: u8,
    /// Index of its reading in the state.
    pub index: u8,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub yaw_rad: f64,
    /// Cone of a range sensor, rad (NaN otherwise).
    pub field_of_view_rad: f64,
    pub min_range_m: f64,
    pub max_range_m: f64,
}

/// A joint the bridges publish: its name and which reading is its position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Joint {
    pub name: &'static str,
    /// `chassis_interfaces::JointSource`.
    pub source: u8,
    /// The wheel, for a wheel joint.
    pub index: u8,
}

/// One robot of the registry.
#[derive(Debug)]
pub struct RobotEntry {
    pub kind: RobotKind,
    /// The `--robot` spelling, also the default robot name (`hunter-se`).
    pub name: &'static str,
    /// What people call it (`AgileX HUNTER SE`).
    pub display_name: &'static str,
    pub bus: Bus,
    /// The AgileX protocols it may speak (V1 and V2: listened for on a real CAN bus unless one
    /// is asked for); empty for a robot with a protocol of its own.
    pub protocols: &'static [Protocol],
    /// Its protocol when none is asked for and there is no listening (the simulator, a replay).
    pub default_protocol: Option<Protocol>,
    /// Its protocol-V1 model, where it may speak V1.
    pub v1_model: Option<V1Model>,
    /// Its protocol-V2 models, where it may speak V2: the first is its plain model, the others
    /// variants a profile's `model` may name (`scout-mini-omni`, `ranger-mini-v1`).
    pub v2_models: &'static [V2Model],
    /// `chassis_interfaces::Kinematics` of its plain model (a profile's `model` or `omni` may
    /// name a mecanum variant).
    pub kinematics: u8,
    pub outline: Outline,
    pub sensors: &'static [Sensor],
    pub joints: &'static [Joint],
    pub odometry_variance: OdometryVariance,
    /// Its profile in its default protocol, with the manuals' values ([`RobotEntry::defaults`]).
    pub profile: fn() -> Profile,
    /// Its driver for an effective profile.
    pub driver: fn(&Profile, &DriverConfig, Timestamp) -> BoxedDriver,
    /// Its simulated firmware for an effective profile, powered up at the given time.
    pub firmware: fn(&Profile, Timestamp) -> BoxedFirmware,
    /// Its frame describer (`chassis decode`, the Foxglove `/frames` topic).
    pub codec: fn(Profile) -> RobotCodec,
}

impl PartialEq for RobotEntry {
    fn eq(&self, other: &Self) -> bool {
        self.kind == other.kind
    }
}

/// The variances every robot states today: 1e-3 on position and speed, 1e-2 on yaw and yaw rate.
/// Stated, not measured; per robot here so a kind that slips more can say so.
const STATED_VARIANCE: OdometryVariance = OdometryVariance {
    position_m2: 1e-3,
    yaw_rad2: 1e-2,
    linear_m2ps2: 1e-3,
    angular_rad2ps2: 1e-2,
};

/// The AgileX robots' CAN bus.
const AGILEX_CAN: Bus = Bus::Can { bitrate: 500_000 };

const STEERING_JOINTS: &[Joint] = &[
    Joint {
        name: "front_steer_joint",
        source: JointSource::FRONT_STEER,
        index: 0,
    },
    Joint {
        name: "rear_steer_joint",
        source: JointSource::REAR_STEER,
        index: 0,
    },
];

const FRONT_STEERING_JOINT: &[Joint] = &[Joint {
    name: "front_steer_joint",
    source: JointSource::FRONT_STEER,
    index: 0,
}];

/// The XBot's drive wheels (its two-wheel base reports the front pair only; an omni variant adds
/// the rear pair, see [`crate::description::describe`]).
const XBOT_WHEELS: &[Joint] = &[
    Joint {
        name: "front_left_wheel_joint",
        source: JointSource::WHEEL,
        index: 0,
    },
    Joint {
        name: "front_right_wheel_joint",
        source: JointSource::WHEEL,
        index: 1,
    },
    Joint {
        name: "rear_left_wheel_joint",
        source: JointSource::WHEEL,
        index: 2,
    },
    Joint {
        name: "rear_right_wheel_joint",
        source: JointSource::WHEEL,
        index: 3,
    },
];

/// The XBot's body: 470 × 494 × 210 mm (its manual's specification table).
const XBOT_OUTLINE: Outline = Outline {
    length_m: 0.470,
    width_m: 0.494,
    height_m: 0.210,
    source: "XBot manual, specification table (470 × 494 × 210 mm)",
};

/// The XBot's range sensors: three ultrasonic at the front (20-600 cm, the manual's table),
/// three infrared at the rear (4-30 cm, fitted low against falls); the manual gives ranges, not
/// mounting, so positions are the body's corners and centre, the side sensors turned 30°, at the
/// heights a 210 mm body allows. Plus the IMU at `base_link`.
const XBOT_SENSORS: &[Sensor] = {
    const FRONT: f64 = XBOT_OUTLINE.length_m / 2.0;
    const REAR: f64 = -XBOT_OUTLINE.length_m / 2.0;
    const SIDE: f64 = XBOT_OUTLINE.width_m / 2.0 - 0.05;
    const TURN: f64 = std::f64::consts::FRAC_PI_6;
    const BACK: f64 = std::f64::consts::PI;
    const US_CONE: f64 = 30.0 * std::f64::consts::PI / 180.0;
    const IR_CONE: f64 = 10.0 * std::f64::consts::PI / 180.0;
    const fn range(
        name: &'static str,
        kind: u8,
        index: u8,
        x_m: f64,
        y_m: f64,
        yaw_rad: f64,
    ) -> Sensor {
        let ultrasonic = kind == SensorKind::ULTRASONIC;
        Sensor {
            name,
            kind,
            index,
            x_m,
            y_m,
            z_m: if ultrasonic { 0.15 } else { 0.03 },
            yaw_rad,
            field_of_view_rad: if ultrasonic { US_CONE } else { IR_CONE },
            min_range_m: if ultrasonic { 0.20 } else { 0.04 },
            max_range_m: if ultrasonic { 6.0 } else { 0.30 },
        }
    }
    const US: u8 = SensorKind::ULTRASONIC;
    const IR: u8 = SensorKind::INFRARED;
    &[
        range("ultrasonic_front_left", US, 0, FRONT, SIDE, TURN),
        range("ultrasonic_front_centre", US, 1, FRONT, 0.0, 0.0),
        range("ultrasonic_front_right", US, 2, FRONT, -SIDE, -TURN),
        range("ir_rear_left", IR, 0, REAR, SIDE, BACK),
        range("ir_rear_centre", IR, 1, REAR, 0.0, BACK),
        range("ir_rear_right", IR, 2, REAR, -SIDE, BACK),
        Sensor {
            name: "imu",
            kind: SensorKind::IMU,
            index: 0,
            x_m: 0.0,
            y_m: 0.0,
            z_m: 0.0,
            yaw_rad: 0.0,
            field_of_view_rad: f64::NAN,
            min_range_m: f64::NAN,
            max_range_m: f64::NAN,
        },
    ]
};

/// An outline drawn around the wheels (wheelbase + 0.2 m by track + 0.15 m): the manuals at hand
/// give no outside dimensions for these robots.
const fn around_wheels(wheelbase_m: f64, track_m: f64, height_m: f64) -> Outline {
    Outline {
        length_m: wheelbase_m + 0.2,
        width_m: track_m + 0.15,
        height_m,
        source: "drawn around the wheels (no outside dimensions in the manuals at hand)",
    }
}

/// The manuals' profiles of each robot's default protocol.
fn titan_defaults() -> Profile {
    Profile::Titan(TitanProfile::default())
}
fn scout_mini_defaults() -> Profile {
    Profile::ScoutMini(V1Profile::for_model(V1Model::ScoutMini))
}
fn xbot_defaults() -> Profile {
    Profile::Xbot(XbotProfile::default())
}
fn scout_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::Scout))
}
fn hunter_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::Hunter))
}
fn hunter_se_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::HunterSe))
}
fn tracer_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::Tracer))
}
fn bunker_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::Bunker))
}
fn ranger_mini_defaults() -> Profile {
    Profile::V2(V2Profile::for_model(V2Model::RangerMini))
}

/// The driver of a profile: each protocol family has one.
fn driver_of(profile: &Profile, config: &DriverConfig, now: Timestamp) -> BoxedDriver {
    match profile {
        Profile::Titan(p) => Box::new(titan::TitanDriver::new(p.clone(), config.clone(), now)),
        Profile::ScoutMini(p) => Box::new(scout_mini::ScoutMiniDriver::new(
            p.clone(),
            config.clone(),
            now,
        )),
        Profile::Xbot(p) => Box::new(xbot::XbotDriver::new(p.clone(), config.clone(), now)),
        Profile::V2(p) => Box::new(agilex_v2::V2Driver::new(p.clone(), config.clone(), now)),
    }
}

/// The simulated firmware of a profile.
fn firmware_of(profile: &Profile, now: Timestamp) -> BoxedFirmware {
    match profile {
        Profile::Titan(p) => Box::new(titan::TitanSim::new(p.clone(), now)),
        Profile::ScoutMini(p) => Box::new(scout_mini::ScoutMiniSim::new(p.clone(), now)),
        Profile::Xbot(p) => Box::new(xbot::XbotSim::new(p.clone(), now)),
        Profile::V2(p) => Box::new(agilex_v2::V2Sim::new(p.clone(), now)),
    }
}

static TITAN: RobotEntry = RobotEntry {
    kind: RobotKind::Titan,
    name: "titan",
    display_name: "AgileX TITAN",
    bus: AGILEX_CAN,
    protocols: &[],
    default_protocol: None,
    v1_model: None,
    v2_models: &[],
    kinematics: Kinematics::DUAL_ACKERMANN,
    outline: Outline {
        length_m: 1.640,
        width_m: 0.980,
        height_m: 1.440,
        source: "TITAN manual, specification table (1640 × 980 × 1440 mm)",
    },
    sensors: &[],
    joints: STEERING_JOINTS,
    odometry_variance: STATED_VARIANCE,
    profile: titan_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static SCOUT_MINI: RobotEntry = RobotEntry {
    kind: RobotKind::ScoutMini,
    name: "scout-mini",
    display_name: "AgileX SCOUT MINI",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V1, Protocol::V2],
    default_protocol: Some(Protocol::V1),
    v1_model: Some(V1Model::ScoutMini),
    v2_models: &[V2Model::ScoutMini, V2Model::ScoutMiniOmni],
    kinematics: Kinematics::SKID_STEER,
    outline: Outline {
        length_m: 0.627,
        width_m: 0.550,
        height_m: 0.252,
        source: "SCOUT MINI manual, specification table (627 × 550 × 252 mm)",
    },
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profile: scout_mini_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static XBOT: RobotEntry = RobotEntry {
    kind: RobotKind::Xbot,
    name: "xbot",
    display_name: "XBot",
    bus: Bus::Rs232,
    protocols: &[],
    default_protocol: None,
    v1_model: None,
    v2_models: &[],
    kinematics: Kinematics::DIFFERENTIAL,
    outline: XBOT_OUTLINE,
    sensors: XBOT_SENSORS,
    joints: XBOT_WHEELS,
    odometry_variance: STATED_VARIANCE,
    profile: xbot_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static SCOUT: RobotEntry = RobotEntry {
    kind: RobotKind::Scout,
    name: "scout",
    display_name: "AgileX SCOUT 2.0",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V1, Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: Some(V1Model::Scout),
    v2_models: &[V2Model::Scout],
    kinematics: Kinematics::SKID_STEER,
    outline: around_wheels(0.498, 0.583, 0.35),
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profile: scout_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static HUNTER: RobotEntry = RobotEntry {
    kind: RobotKind::Hunter,
    name: "hunter",
    display_name: "AgileX HUNTER 2.0",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: None,
    v2_models: &[V2Model::Hunter],
    kinematics: Kinematics::ACKERMANN,
    outline: around_wheels(0.650, 0.605, 0.38),
    sensors: &[],
    joints: FRONT_STEERING_JOINT,
    odometry_variance: STATED_VARIANCE,
    profile: hunter_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static HUNTER_SE: RobotEntry = RobotEntry {
    kind: RobotKind::HunterSe,
    name: "hunter-se",
    display_name: "AgileX HUNTER SE",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: None,
    v2_models: &[V2Model::HunterSe],
    kinematics: Kinematics::ACKERMANN,
    outline: around_wheels(0.657, 0.550, 0.33),
    sensors: &[],
    joints: FRONT_STEERING_JOINT,
    odometry_variance: STATED_VARIANCE,
    profile: hunter_se_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static TRACER: RobotEntry = RobotEntry {
    kind: RobotKind::Tracer,
    name: "tracer",
    display_name: "AgileX TRACER",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: None,
    v2_models: &[V2Model::Tracer],
    kinematics: Kinematics::DIFFERENTIAL,
    outline: Outline {
        length_m: 0.700,
        width_m: 0.500,
        height_m: 0.163,
        source: "TRACER manual §1.2 (700 × 500 × 163 mm), as spec/PROTOCOLS-V2.md cites it",
    },
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profile: tracer_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static BUNKER: RobotEntry = RobotEntry {
    kind: RobotKind::Bunker,
    name: "bunker",
    display_name: "AgileX BUNKER",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V1, Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: Some(V1Model::Bunker),
    v2_models: &[V2Model::Bunker],
    kinematics: Kinematics::TRACKED,
    outline: around_wheels(0.5, 0.5, 0.30),
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profile: bunker_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

static RANGER_MINI: RobotEntry = RobotEntry {
    kind: RobotKind::RangerMini,
    name: "ranger-mini",
    display_name: "AgileX RANGER MINI",
    bus: AGILEX_CAN,
    protocols: &[Protocol::V2],
    default_protocol: Some(Protocol::V2),
    v1_model: None,
    v2_models: &[V2Model::RangerMini, V2Model::RangerMiniV1],
    kinematics: Kinematics::FOUR_WHEEL_STEER,
    outline: around_wheels(0.494, 0.364, 0.34),
    sensors: &[],
    joints: STEERING_JOINTS,
    odometry_variance: STATED_VARIANCE,
    profile: ranger_mini_defaults,
    driver: driver_of,
    firmware: firmware_of,
    codec: RobotCodec::new,
};

impl RobotKind {
    /// Every robot of the registry.
    pub const ALL: [RobotKind; 9] = [
        RobotKind::Titan,
        RobotKind::ScoutMini,
        RobotKind::Xbot,
        RobotKind::Scout,
        RobotKind::Hunter,
        RobotKind::HunterSe,
        RobotKind::Tracer,
        RobotKind::Bunker,
        RobotKind::RangerMini,
    ];

    /// The robot's registry entry.
    pub fn entry(self) -> &'static RobotEntry {
        match self {
            RobotKind::Titan => &TITAN,
            RobotKind::ScoutMini => &SCOUT_MINI,
            RobotKind::Xbot => &XBOT,
            RobotKind::Scout => &SCOUT,
            RobotKind::Hunter => &HUNTER,
            RobotKind::HunterSe => &HUNTER_SE,
            RobotKind::Tracer => &TRACER,
            RobotKind::Bunker => &BUNKER,
            RobotKind::RangerMini => &RANGER_MINI,
        }
    }

    /// The kind's id on the wire (`ChassisState::robot`).
    pub fn id(self) -> u8 {
        self as u8
    }

    /// The kind of a `ChassisState::robot` id.
    pub fn from_id(id: u8) -> Option<RobotKind> {
        RobotKind::ALL.into_iter().find(|k| k.id() == id)
    }

    /// The command-line spelling (`titan`, `scout-mini`, `hunter`, …), also the default robot
    /// name.
    pub fn name(self) -> &'static str {
        self.entry().name
    }

    /// True for the robots on a CAN bus.
    pub fn is_can(self) -> bool {
        matches!(self.entry().bus, Bus::Can { .. })
    }

    /// The AgileX protocols the robot may speak (empty: a protocol of its own).
    pub fn protocols(self) -> &'static [Protocol] {
        self.entry().protocols
    }

    /// The protocol-V1 model of this robot, if it may speak V1.
    pub fn v1_model(self) -> Option<V1Model> {
        self.entry().v1_model
    }

    /// The plain protocol-V2 model of this robot, if it speaks V2.
    pub fn v2_model(self) -> Option<V2Model> {
        self.entry().v2_models.first().copied()
    }

    /// The robot a protocol-V1 model is.
    pub fn of_v1(model: V1Model) -> Option<RobotKind> {
        RobotKind::ALL
            .into_iter()
            .find(|k| k.v1_model() == Some(model))
    }

    /// The robot a protocol-V2 model (or variant) is.
    pub fn of_v2(model: V2Model) -> Option<RobotKind> {
        RobotKind::ALL
            .into_iter()
            .find(|k| k.entry().v2_models.contains(&model))
    }
}

impl RobotEntry {
    /// The driver for `profile`, this robot's effective profile. A robot that may speak V1 or
    /// V2, with `detect` (a real CAN bus and no protocol asked for), listens first and drives in
    /// the protocol it hears: `profile` stands for the protocol it is of, the other one gets its
    /// defaults, and the listening lasts as long as `profile` says.
    pub fn driver(
        &self,
        profile: &Profile,
        detect: bool,
        config: &DriverConfig,
        now: Timestamp,
    ) -> BoxedDriver {
        if detect {
            let pair = match (profile, self.v1_model, self.v2_models.first().copied()) {
                (Profile::ScoutMini(v1), _, Some(model)) => Some((
                    v1.clone(),
                    V2Profile::for_model(model),
                    DetectSettings::from(v1),
                )),
                (Profile::V2(v2), Some(model), _) => Some((
                    V1Profile::for_model(model),
                    v2.clone(),
                    DetectSettings::from(v2),
                )),
                _ => None,
            };
            if let Some((v1, v2, settings)) = pair {
                return Box::new(agilex_v2::AutoDriver::new(
                    v1,
                    v2,
                    settings,
                    config.clone(),
                    now,
                ));
            }
        }
        (self.driver)(profile, config, now)
    }

    /// Its driver for `profile` (default configuration, no detection) and its simulated firmware,
    /// wired back to back from `start` on simulated time: the registry-wide tests' and the
    /// clients' way to see a robot's exchange without a bus.
    pub fn simulated_pair(
        &self,
        profile: &Profile,
        start: Timestamp,
    ) -> crate::pair::Pair<BoxedDriver, BoxedFirmware> {
        let driver = self.driver(profile, false, &DriverConfig::default(), start);
        crate::pair::Pair::new(driver, (self.firmware)(profile, start), start)
    }

    /// Its frame describer for the protocol a state sample says the driver speaks
    /// (`SystemState::wire_protocol`): the manuals' profile of V1 or V2 where the robot speaks
    /// that one, its default profile otherwise (its own protocol, or still detecting).
    pub fn codec_for_wire(&self, wire_protocol: u8) -> RobotCodec {
        let protocol = match wire_protocol {
            WireProtocol::V1 => Some(Protocol::V1),
            WireProtocol::V2 => Some(Protocol::V2),
            _ => None,
        };
        let profile = protocol
            .and_then(|p| self.default_profile(Some(p)).ok())
            .unwrap_or_else(|| self.defaults());
        (self.codec)(profile)
    }

    /// The manuals' profile of its default protocol.
    pub fn defaults(&self) -> Profile {
        (self.profile)()
    }

    /// The manuals' profile of one of its protocols (`None`: its default one).
    pub fn default_profile(&self, protocol: Option<Protocol>) -> Result<Profile, ProtocolError> {
        let not_spoken = |p: Protocol| ProtocolError::NotSpoken {
            robot: self.kind,
            protocol: p.name(),
        };
        match protocol {
            None => Ok(self.defaults()),
            Some(p) if Some(p) == self.default_protocol => Ok(self.defaults()),
            Some(p) if !self.protocols.contains(&p) => Err(not_spoken(p)),
            Some(Protocol::V1) => self
                .v1_model
                .map(|m| Profile::ScoutMini(V1Profile::for_model(m)))
                .ok_or(not_spoken(Protocol::V1)),
            Some(Protocol::V2) => self
                .v2_models
                .first()
                .map(|&m| Profile::V2(V2Profile::for_model(m)))
                .ok_or(not_spoken(Protocol::V2)),
        }
    }

    /// True when the robot may speak AgileX V1 or V2 and tells which by listening.
    pub fn detects_protocol(&self) -> bool {
        self.protocols.len() > 1
    }
}

/// The robot spelled `name` (`--robot`).
pub fn find(name: &str) -> Option<&'static RobotEntry> {
    RobotKind::ALL
        .into_iter()
        .map(RobotKind::entry)
        .find(|e| e.name == name)
}

/// The `--robot` spellings, for messages and help.
pub fn names() -> Vec<&'static str> {
    RobotKind::ALL.into_iter().map(RobotKind::name).collect()
}

/// A robot name that is none of the registry's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown robot '{name}' (expected one of {})", names().join(", "))]
pub struct UnknownRobot {
    pub name: String,
}

impl std::str::FromStr for RobotKind {
    type Err = UnknownRobot;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        find(s)
            .map(|e| e.kind)
            .ok_or_else(|| UnknownRobot { name: s.into() })
    }
}

impl std::fmt::Display for RobotKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The heartbeat period a profile's driver keeps.
pub fn heartbeat_period(profile: &Profile) -> Duration {
    match profile {
        Profile::Titan(p) => Duration::from_millis(p.heartbeat_period_ms),
        Profile::ScoutMini(p) => Duration::from_millis(p.heartbeat_period_ms),
        Profile::Xbot(p) => Duration::from_secs_f64(1.0 / p.heartbeat_hz),
        Profile::V2(p) => Duration::from_millis(p.heartbeat_period_ms),
    }
}

#[cfg(test)]
mod tests;
