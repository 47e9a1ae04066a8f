//! The robot registry: one entry per robot, the one place that knows what each robot *is* — as
//! data. An entry names the robot's bus, its body's outline, the sensors with their mounting, the
//! joints the bridges publish, the odometry's stated variances and its profiles: the manuals'
//! profile of each protocol it may speak, its default first. Everything a protocol does (driver,
//! firmware, codec, the profile's part of the description) comes from the profile's family
//! ([`crate::family::Family`]); the registry knows no driver. [`describe`](crate::description::describe)
//! turns an entry and an effective profile into the `RobotDescription` chassisd publishes;
//! clients read that, never a table of their own.
//!
//! Adding a robot of an existing family: a variant of [`RobotKind`] (`kind.rs`; its number is
//! what `ChassisState::robot` carries, its name the `--robot` spelling), its entry here, and its
//! model in the family's profile where the family has models. The registry-wide tests
//! (`registry::tests`) and the family conformance suite walk every entry; the whole recipe, with
//! the tests that ask for a new robot by name, is `docs/ARCHITECTURE.md`'s "Adding a robot,
//! adding a family".

use chassis_interfaces::{
    BusKind, JointSource, Kinematics, OdometryVariance, RobotDescription, SensorKind, WireProtocol,
};

use crate::agilex_v1::{V1Model, V1Profile};
use crate::agilex_v2::{AutoDriver, V2Model, V2Profile};
use crate::driver::{BoxedDriver, DriverConfig};
use crate::family::Profile;
use crate::firmware::BoxedFirmware;
use crate::kind::RobotKind;
use crate::profile::{ProfileTableError, Protocol, ProtocolError};
use crate::time::Timestamp;
use crate::titan::TitanProfile;
use crate::xbot::XbotProfile;

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
    /// What people call it (`AgileX HUNTER SE`).
    pub display_name: &'static str,
    pub bus: Bus,
    /// `chassis_interfaces::Kinematics` of its plain model (a profile's `model` or `omni` may
    /// name a variant that differs).
    pub kinematics: u8,
    pub outline: Outline,
    pub sensors: &'static [Sensor],
    pub joints: &'static [Joint],
    pub odometry_variance: OdometryVariance,
    /// The manuals' profile of each protocol it may speak, its default one first (a robot that
    /// may speak AgileX V1 or V2 has both, and tells which by listening on a real CAN bus).
    pub profiles: &'static [fn() -> Profile],
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

/// The manuals' profiles of each protocol of each robot.
fn titan() -> Profile {
    TitanProfile::default().into()
}
fn xbot() -> Profile {
    XbotProfile::default().into()
}
fn v1(model: V1Model) -> Profile {
    V1Profile::for_model(model).into()
}
fn v2(model: V2Model) -> Profile {
    V2Profile::for_model(model).into()
}

static TITAN: RobotEntry = RobotEntry {
    kind: RobotKind::Titan,
    display_name: "AgileX TITAN",
    bus: AGILEX_CAN,
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
    profiles: &[titan],
};

static SCOUT_MINI: RobotEntry = RobotEntry {
    kind: RobotKind::ScoutMini,
    display_name: "AgileX SCOUT MINI",
    bus: AGILEX_CAN,
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
    profiles: &[|| v1(V1Model::ScoutMini), || v2(V2Model::ScoutMini)],
};

static XBOT: RobotEntry = RobotEntry {
    kind: RobotKind::Xbot,
    display_name: "XBot",
    bus: Bus::Rs232,
    kinematics: Kinematics::DIFFERENTIAL,
    outline: XBOT_OUTLINE,
    sensors: XBOT_SENSORS,
    joints: XBOT_WHEELS,
    odometry_variance: STATED_VARIANCE,
    profiles: &[xbot],
};

static SCOUT: RobotEntry = RobotEntry {
    kind: RobotKind::Scout,
    display_name: "AgileX SCOUT 2.0",
    bus: AGILEX_CAN,
    kinematics: Kinematics::SKID_STEER,
    outline: around_wheels(0.498, 0.583, 0.35),
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::Scout), || v1(V1Model::Scout)],
};

static HUNTER: RobotEntry = RobotEntry {
    kind: RobotKind::Hunter,
    display_name: "AgileX HUNTER 2.0",
    bus: AGILEX_CAN,
    kinematics: Kinematics::ACKERMANN,
    outline: around_wheels(0.650, 0.605, 0.38),
    sensors: &[],
    joints: FRONT_STEERING_JOINT,
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::Hunter)],
};

static HUNTER_SE: RobotEntry = RobotEntry {
    kind: RobotKind::HunterSe,
    display_name: "AgileX HUNTER SE",
    bus: AGILEX_CAN,
    kinematics: Kinematics::ACKERMANN,
    outline: around_wheels(0.657, 0.550, 0.33),
    sensors: &[],
    joints: FRONT_STEERING_JOINT,
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::HunterSe)],
};

static TRACER: RobotEntry = RobotEntry {
    kind: RobotKind::Tracer,
    display_name: "AgileX TRACER",
    bus: AGILEX_CAN,
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
    profiles: &[|| v2(V2Model::Tracer)],
};

static BUNKER: RobotEntry = RobotEntry {
    kind: RobotKind::Bunker,
    display_name: "AgileX BUNKER",
    bus: AGILEX_CAN,
    kinematics: Kinematics::TRACKED,
    outline: around_wheels(0.5, 0.5, 0.30),
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::Bunker), || v1(V1Model::Bunker)],
};

static RANGER_MINI: RobotEntry = RobotEntry {
    kind: RobotKind::RangerMini,
    display_name: "AgileX RANGER MINI",
    bus: AGILEX_CAN,
    kinematics: Kinematics::FOUR_WHEEL_STEER,
    outline: around_wheels(0.494, 0.364, 0.34),
    sensors: &[],
    joints: STEERING_JOINTS,
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::RangerMini)],
};

/// The TRACER MINI, on the V2 family's bus (`PROTOCOLS-V2` §1: CAN 500 kbit/s). Its manual's CAN
/// pages (TMM, §3.5) give no outside dimensions and no wheel figures, so its outline is drawn
/// around the 0.5 × 0.5 m wheelbase and track its profile takes from the TRACER's (placeholders
/// no manual gives), at the TRACER's height (TRM §1.2, 163 mm): a stated guess until a TRACER
/// MINI specification table is at hand.
static TRACER_MINI: RobotEntry = RobotEntry {
    kind: RobotKind::TracerMini,
    display_name: "AgileX TRACER MINI",
    bus: AGILEX_CAN,
    kinematics: Kinematics::DIFFERENTIAL,
    outline: around_wheels(0.5, 0.5, 0.163),
    sensors: &[],
    joints: &[],
    odometry_variance: STATED_VARIANCE,
    profiles: &[|| v2(V2Model::TracerMini)],
};

impl RobotKind {
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
            RobotKind::TracerMini => &TRACER_MINI,
        }
    }

    /// True for the robots on a CAN bus.
    pub fn is_can(self) -> bool {
        matches!(self.entry().bus, Bus::Can { .. })
    }
}

/// The manuals' profile of the robot a description (as chassisd publishes it) describes, of
/// its model, in the protocol it says is in use: how a client that knows the robot only from its
/// description (the Foxglove view's `/frames`, `chassis top`) reads its bus. `None` for a kind
/// the registry does not know.
pub fn profile_for_description(description: &RobotDescription) -> Option<Profile> {
    let entry = RobotKind::from_id(description.kind)?.entry();
    Some(entry.profile_for_model(description.protocol, description.model()))
}

impl RobotEntry {
    /// The manuals' profile of each protocol it may speak, its default one first.
    pub fn profiles(&self) -> impl Iterator<Item = Profile> {
        self.profiles.iter().map(|profile| profile())
    }

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
        let other = self
            .profiles()
            .find(|p| p.protocol().is_some() && p.protocol() != profile.protocol());
        detect
            .then_some(other)
            .flatten()
            .and_then(|other| AutoDriver::boxed(profile, &other, config, now))
            .unwrap_or_else(|| profile.driver(config, now))
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
        crate::pair::Pair::new(driver, profile.firmware(start), start)
    }

    /// The manuals' profile of the protocol a state sample says the driver speaks
    /// (`SystemState::wire_protocol`) where the robot speaks it, its default profile otherwise
    /// (its own protocol, or still detecting): how a client reads its frames.
    pub fn profile_for_wire(&self, wire_protocol: u8) -> Profile {
        let protocol = match wire_protocol {
            WireProtocol::V1 => Some(Protocol::V1),
            WireProtocol::V2 => Some(Protocol::V2),
            _ => None,
        };
        protocol
            .and_then(|p| self.default_profile(Some(p)).ok())
            .unwrap_or_else(|| self.defaults())
    }

    /// The manuals' profile of its default protocol.
    pub fn defaults(&self) -> Profile {
        // Every entry has a profile (`registry::tests`); TITAN's stands in for an empty list.
        self.profiles().next().unwrap_or_else(titan)
    }

    /// The manuals' profile of one of its protocols (`None`: its default one).
    pub fn default_profile(&self, protocol: Option<Protocol>) -> Result<Profile, ProtocolError> {
        let Some(protocol) = protocol else {
            return Ok(self.defaults());
        };
        self.profiles()
            .find(|p| p.protocol() == Some(protocol))
            .ok_or(ProtocolError::NotSpoken {
                robot: self.kind,
                protocol: protocol.name(),
            })
    }

    /// Its profile in `protocol` (`None`: its default one) with the keys of `table` (the
    /// `[profile]` table of the service's config) set over the manuals' values. A table may
    /// name a variant with `model` (e.g. `scout-mini-omni`): its keys are then set over that
    /// variant's defaults; a model of another robot is refused.
    pub fn profile_from_table(
        &self,
        protocol: Option<Protocol>,
        table: &toml::Table,
    ) -> Result<Profile, ProfileTableError> {
        let profile = self.default_profile(protocol)?.with_table(table)?;
        if profile.robot() != self.kind {
            return Err(ProfileTableError::WrongModel {
                owner: profile.robot(),
                robot: self.kind,
            });
        }
        Ok(profile)
    }

    /// The manuals' profile of the model a description names, in the protocol it says is in
    /// use, where the model is this robot's; the profile for that protocol otherwise.
    pub fn profile_for_model(&self, wire_protocol: u8, model: &str) -> Profile {
        let base = self.profile_for_wire(wire_protocol);
        let mut table = toml::Table::new();
        table.insert("model".into(), model.into());
        match self.profile_from_table(base.protocol(), &table) {
            Ok(named) if named.protocol() == base.protocol() => named,
            _ => base,
        }
    }

    /// True when the robot may speak AgileX V1 or V2 and tells which by listening.
    pub fn detects_protocol(&self) -> bool {
        self.profiles.len() > 1
    }
}

#[cfg(test)]
mod tests;
