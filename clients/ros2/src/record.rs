//! `chassis-ros2 --record FILE.mcap`: the bridge's topics written as a ROS 2 bag, without DDS.
//!
//! The file is what `ros2 bag record -s mcap` writes (rosbag2's MCAP storage): profile `ros2`,
//! one schema per message type in the `ros2msg` encoding (the `.msg` definition with every type
//! it uses after it), channels named as the bridge's topics (`/odom`, `/tf`,
//! `/battery_state`, …, under `--namespace`) with the bridge's QoS in `offered_qos_profiles`,
//! and messages in CDR (little endian, the 4-byte encapsulation header first), serialised by the
//! `cdr-encoding` crate RustDDS itself uses, so the bytes are those the bridge puts on the wire.
//! The messages are the bridge's own ([`crate::bridge::messages`], [`convert::diagnostics`]),
//! stamped in ROS time, frames per REP 103/105 (`odom` → `base_link`). Log and publish times are
//! ROS time when the sample was written. The robot's description is the metadata record
//! `robot_description`; its model is on the topics `robot_description` (the URDF) and
//! `tf_static`, written at the start and again when a newer description changes it, with the
//! bridge's transient-local QoS (`ros2 bag play` offers them so to late joiners).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{
    BusKind, Kinematics, MuxStatus, RobotDescription, WireProtocol, deadline, now_ns,
    termination_requested,
};
use ros2_client::QosProfile;
use ros2_client::qos::{Durability, History, Reliability};
use serde::Serialize;

use crate::bridge::{self, Message};
use crate::convert::{self, Frames, ModelSent, RangeSensor, RosClock};

/// How often `diagnostics` is written when nothing changes (as the bridge publishes it).
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// The `.msg` definitions of every type the bridge writes and of the types they use, field
/// lines only (as ROS 2 Jazzy defines them).
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec"),
    ("std_msgs/String", "string data"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
    ),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms",
    ),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
         float64[] effort",
    ),
    (
        "sensor_msgs/BatteryState",
        "uint8 POWER_SUPPLY_STATUS_UNKNOWN = 0\nuint8 POWER_SUPPLY_STATUS_CHARGING = 1\n\
         uint8 POWER_SUPPLY_STATUS_DISCHARGING = 2\nuint8 POWER_SUPPLY_STATUS_NOT_CHARGING = 3\n\
         uint8 POWER_SUPPLY_STATUS_FULL = 4\nuint8 POWER_SUPPLY_HEALTH_UNKNOWN = 0\n\
         uint8 POWER_SUPPLY_HEALTH_GOOD = 1\nuint8 POWER_SUPPLY_HEALTH_OVERHEAT = 2\n\
         uint8 POWER_SUPPLY_TECHNOLOGY_UNKNOWN = 0\n\
         std_msgs/Header header\nfloat32 voltage\nfloat32 temperature\nfloat32 current\n\
         float32 charge\nfloat32 capacity\nfloat32 design_capacity\nfloat32 percentage\n\
         uint8 power_supply_status\nuint8 power_supply_health\nuint8 power_supply_technology\n\
         bool present\nfloat32[] cell_voltage\nfloat32[] cell_temperature\nstring location\n\
         string serial_number",
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n\
         float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n\
         float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n\
         float64[9] linear_acceleration_covariance",
    ),
    (
        "sensor_msgs/Range",
        "uint8 ULTRASOUND = 0\nuint8 INFRARED = 1\nstd_msgs/Header header\n\
         uint8 radiation_type\nfloat32 field_of_view\nfloat32 min_range\nfloat32 max_range\n\
         float32 range\nfloat32 variance",
    ),
    ("sensor_msgs/NavSatStatus", "int8 status\nuint16 service"),
    (
        "sensor_msgs/NavSatFix",
        "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\n\
         float64 longitude\nfloat64 altitude\nfloat64[9] position_covariance\n\
         uint8 position_covariance_type",
    ),
    ("diagnostic_msgs/KeyValue", "string key\nstring value"),
    (
        "diagnostic_msgs/DiagnosticStatus",
        "byte level\nstring name\nstring message\nstring hardware_id\n\
         diagnostic_msgs/KeyValue[] values",
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status",
    ),
];

fn fields_of(ty: &str) -> anyhow::Result<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(name, _)| *name == ty)
        .map(|(_, fields)| *fields)
        .with_context(|| format!("no .msg definition for {ty}"))
}

/// The `ros2msg` schema of `ty` (`nav_msgs/Odometry`): its fields, then each type it uses,
/// depth first, once, behind rosbag2's separator line and `MSG: package/Type`.
pub fn schema(ty: &str) -> anyhow::Result<String> {
    let mut text = fields_of(ty)?.to_string();
    let mut seen = vec![ty.to_string()];
    let mut pending = vec![ty.to_string()];
    while let Some(current) = pending.pop() {
        let mut uses = Vec::new();
        for line in fields_of(&current)?.lines() {
            let field_type = line.split_whitespace().next().unwrap_or("");
            let base = field_type.split('[').next().unwrap_or("");
            if base.contains('/') && !seen.iter().any(|s| s == base) {
                seen.push(base.to_string());
                uses.push(base.to_string());
            }
        }
        for used in &uses {
            text.push_str("\n================================================================================\nMSG: ");
            text.push_str(used);
            text.push('\n');
            text.push_str(fields_of(used)?);
        }
        // Depth first, in the order they were met.
        pending.extend(uses.into_iter().rev());
    }
    Ok(text)
}

/// rosbag2's `offered_qos_profiles` for one writer of `qos` (its YAML, the numeric form
/// rosbag2 reads: reliability 1 reliable / 2 best effort, durability 1 transient local /
/// 2 volatile, history 1 keep last; deadline, lifespan and lease infinite).
pub fn offered_qos(qos: &QosProfile) -> String {
    let reliability = match qos.reliability {
        Reliability::BestEffort => 2,
        Reliability::Reliable { .. } => 1,
    };
    let durability = match qos.durability {
        Durability::TransientLocal => 1,
        Durability::Volatile => 2,
    };
    let (history, depth) = match qos.history {
        History::KeepAll => (2, 0),
        History::KeepLast { depth } => (1, depth),
    };
    let infinite = "\n    sec: 9223372036\n    nsec: 854775807";
    format!(
        "- history: {history}\n  depth: {depth}\n  reliability: {reliability}\n  durability: \
         {durability}\n  deadline:{infinite}\n  lifespan:{infinite}\n  liveliness: 1\n  \
         liveliness_lease_duration:{infinite}\n  avoid_ros_namespace_conventions: false"
    )
}

/// A topic of the bag: its channel and how many messages it got.
#[derive(Debug)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// The bag being written.
pub struct Ros2Bag<W: Write + Seek> {
    writer: mcap::Writer<W>,
    channels: BTreeMap<String, Channel>,
    namespace: String,
    /// The robot's range sensors, one topic each (`range/<name>`), in the order of
    /// [`Message::Range`]'s index.
    ranges: Vec<RangeSensor>,
}

impl<W: Write + Seek> std::fmt::Debug for Ros2Bag<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Bag")
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

impl Ros2Bag<BufWriter<File>> {
    /// A new bag at `path`, with a topic for each of `ranges`.
    pub fn create(path: &Path, namespace: &str, ranges: Vec<RangeSensor>) -> anyhow::Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Self::new(BufWriter::new(file), namespace, ranges)
    }
}

impl<W: Write + Seek> Ros2Bag<W> {
    /// A bag written into `out`; topics under `namespace` (`/` or `/robot1`), a range topic for
    /// each of `ranges` (the robot's, [`convert::range_sensors`]).
    pub fn new(out: W, namespace: &str, ranges: Vec<RangeSensor>) -> anyhow::Result<Self> {
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(1)
            .create(out)
            .context("starting the MCAP file")?;
        let mut bag = Self {
            writer,
            channels: BTreeMap::new(),
            namespace: namespace.trim_end_matches('/').to_string(),
            ranges,
        };
        for (path, ty, qos) in topics(&bag.ranges) {
            bag.add_topic(&path, ty, &qos)?;
        }
        Ok(bag)
    }

    fn topic(&self, path: &str) -> String {
        format!("{}/{path}", self.namespace)
    }

    fn add_topic(&mut self, path: &str, ty: &str, qos: &QosProfile) -> anyhow::Result<()> {
        let (package, name) = ty.split_once('/').context("a type is package/Name")?;
        let schema_name = format!("{package}/msg/{name}");
        let schema_id = self
            .writer
            .add_schema(&schema_name, "ros2msg", schema(ty)?.as_bytes())?;
        let metadata = [("offered_qos_profiles".to_string(), offered_qos(qos))].into();
        let topic = self.topic(path);
        let id = self
            .writer
            .add_channel(schema_id, &topic, "cdr", &metadata)?;
        self.channels
            .insert(path.to_string(), Channel { id, sequence: 0 });
        Ok(())
    }

    /// Writes `message` on the topic `path` (as the bridge names it, `odom`), logged at ROS
    /// time `log_ns`.
    pub fn write<M: Serialize>(
        &mut self,
        path: &str,
        message: &M,
        log_ns: u64,
    ) -> anyhow::Result<()> {
        let channel = self
            .channels
            .get_mut(path)
            .with_context(|| format!("no topic {path}"))?;
        channel.sequence = channel.sequence.wrapping_add(1);
        // CDR_LE encapsulation, options 0; the payload aligns from the byte after it.
        let mut data = vec![0x00, 0x01, 0x00, 0x00];
        data.extend(
            cdr_encoding::to_vec::<M, byteorder::LittleEndian>(message)
                .with_context(|| format!("serialising a {path} message"))?,
        );
        let header = mcap::records::MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: log_ns,
            publish_time: log_ns,
        };
        self.writer
            .write_to_known_channel(&header, &data)
            .with_context(|| format!("writing a {path} message"))?;
        Ok(())
    }

    /// Writes one of the state loop's messages.
    pub fn write_message(&mut self, message: &Message, log_ns: u64) -> anyhow::Result<()> {
        match message {
            Message::Odom(m) => self.write("odom", m.as_ref(), log_ns),
            Message::Tf(m) => self.write("tf", m, log_ns),
            Message::Joints(m) => self.write("joint_states", m, log_ns),
            Message::Battery(m) => self.write("battery_state", m, log_ns),
            Message::Imu(m) => self.write("imu/data", m, log_ns),
            Message::Range(i, m) => {
                let sensor = self.ranges.get(*i).context("no such range sensor")?;
                self.write(&format!("range/{}", sensor.name), m, log_ns)
            }
            Message::Fix(m) => self.write("fix", m, log_ns),
        }
    }

    /// Writes a metadata record.
    pub fn metadata(&mut self, name: &str, values: BTreeMap<String, String>) -> anyhow::Result<()> {
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: name.to_string(),
                metadata: values,
            })
            .context("writing MCAP metadata")?;
        Ok(())
    }

    /// Messages written per topic (as the bridge names them).
    pub fn counts(&self) -> BTreeMap<String, u32> {
        self.channels
            .iter()
            .map(|(path, c)| (path.clone(), c.sequence))
            .collect()
    }

    /// Writes the summary and closes the file.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.writer.finish().context("finishing the MCAP file")?;
        Ok(())
    }
}

/// The bridge's state topics, their types and the QoS it offers them with.
fn topics(ranges: &[RangeSensor]) -> Vec<(String, &'static str, QosProfile)> {
    let mut topics = vec![
        (
            "odom".to_string(),
            "nav_msgs/Odometry",
            bridge::reliable_writer_qos(),
        ),
        (
            "tf".to_string(),
            "tf2_msgs/TFMessage",
            bridge::reliable_writer_qos(),
        ),
        (
            "joint_states".to_string(),
            "sensor_msgs/JointState",
            bridge::reliable_writer_qos(),
        ),
        (
            "battery_state".to_string(),
            "sensor_msgs/BatteryState",
            bridge::sensor_qos(),
        ),
        (
            "imu/data".to_string(),
            "sensor_msgs/Imu",
            bridge::sensor_qos(),
        ),
        (
            "fix".to_string(),
            "sensor_msgs/NavSatFix",
            bridge::sensor_qos(),
        ),
        (
            "diagnostics".to_string(),
            "diagnostic_msgs/DiagnosticArray",
            bridge::reliable_writer_qos(),
        ),
        (
            "robot_description".to_string(),
            "std_msgs/String",
            bridge::latched_qos(),
        ),
        (
            "tf_static".to_string(),
            "tf2_msgs/TFMessage",
            bridge::latched_qos(),
        ),
    ];
    for sensor in ranges {
        topics.push((
            format!("range/{}", sensor.name),
            "sensor_msgs/Range",
            bridge::sensor_qos(),
        ));
    }
    topics
}

/// The robot's description as the metadata record `robot_description`: its names, kind,
/// protocol, kinematics and bus as text, and each part (limits, geometry, battery levels,
/// odometry variance, sensors, joints, sources) as JSON.
pub fn description_metadata(d: &RobotDescription) -> BTreeMap<String, String> {
    let json = |v: serde_json::Result<String>| v.unwrap_or_default();
    [
        ("name", d.name().to_string()),
        ("robot", d.kind_name().to_string()),
        ("model", d.model().to_string()),
        ("display_name", d.display_name().to_string()),
        ("protocol", WireProtocol::name(d.protocol).to_string()),
        ("kinematics", Kinematics::name(d.kinematics).to_string()),
        ("bus", BusKind::name(d.bus).to_string()),
        ("robot_limits", json(serde_json::to_string(&d.robot_limits))),
        (
            "configured_limits",
            json(serde_json::to_string(&d.configured_limits)),
        ),
        ("geometry", json(serde_json::to_string(&d.geometry))),
        ("battery", json(serde_json::to_string(&d.battery))),
        (
            "odometry_variance",
            json(serde_json::to_string(&d.odometry_variance)),
        ),
        ("command_timeout_ms", d.command_timeout_ms.to_string()),
        ("heartbeat_period_ms", d.heartbeat_period_ms.to_string()),
        ("sensors", json(serde_json::to_string(d.sensors()))),
        ("joints", json(serde_json::to_string(d.joints()))),
        ("sources", json(serde_json::to_string(d.sources()))),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// What `chassis-ros2 --record` is told.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    pub name: String,
    pub namespace: String,
    pub frame_prefix: String,
    /// Write `tf` (odom → base_link).
    pub tf: bool,
    pub monotonic_stamps: bool,
    /// Stop after this long; `None`: at SIGINT or SIGTERM.
    pub duration: Option<Duration>,
}

/// Records the robot `options.name` into `path` until the duration passes or the process is
/// asked to stop; returns the messages written per topic.
pub fn record(path: &Path, options: &RecordOptions) -> anyhow::Result<BTreeMap<String, u32>> {
    // The description gives the range topics, the odometry's variances and the joints.
    let Some((mut robot, description)) = bridge::describe(&options.name) else {
        return Ok(BTreeMap::new());
    };
    let mut bag = Ros2Bag::create(
        path,
        &options.namespace,
        convert::range_sensors(&description),
    )?;
    bag.metadata("robot_description", description_metadata(&description))?;
    let frames = Frames::new(&options.frame_prefix);
    let clock = RosClock::new(options.monotonic_stamps);
    let log_time = || u64::try_from(clock.ros_time(now_ns()).nanos()).unwrap_or(0);
    let end = options.duration.map(deadline);
    let mut latest = None;
    let mut mux: Option<MuxStatus> = None;
    let mut safety = None;
    let mut last_diagnostics: Option<(u64, Vec<(u8, String)>)> = None;
    let mut model = ModelSent::default();
    let mut description = description;
    let mut write_model = |bag: &mut Ros2Bag<_>, d: &RobotDescription| -> anyhow::Result<()> {
        if let Some((urdf, tf)) = model.update(d, &frames, clock.ros_time(now_ns())) {
            bag.write("robot_description", &urdf, log_time())?;
            bag.write("tf_static", &tf, log_time())?;
        }
        Ok(())
    };
    write_model(&mut bag, &description)?;
    tracing::info!(robot = %options.name, path = %path.display(), "recording");
    while !termination_requested() && end.is_none_or(|end| now_ns() < end) {
        let mut samples = Vec::with_capacity(4);
        if let Err(e) = robot.wait_states(Duration::from_millis(50), |s| samples.push(*s)) {
            if termination_requested() {
                break;
            }
            return Err(e).context("reading state");
        }
        for s in &samples {
            let messages = bridge::messages(
                latest.as_ref(),
                s,
                &description,
                &bag.ranges,
                clock,
                &frames,
            );
            for m in messages {
                if matches!(m, Message::Tf(_)) && !options.tf {
                    continue;
                }
                bag.write_message(&m, log_time())?;
            }
            latest = Some(*s);
        }
        if let Some(m) = robot.latest_mux().context("reading the mux decision")? {
            mux = Some(m);
        }
        if let Some(s) = robot
            .latest_safety()
            .context("reading the safety monitor")?
        {
            safety = Some(s);
        }
        if let Some(d) = robot
            .latest_description()
            .context("reading the robot description")?
            && (d.seq, d.stamp_ns) != (description.seq, description.stamp_ns)
        {
            write_model(&mut bag, &d)?;
            description = d;
        }
        let now = now_ns();
        let array = convert::diagnostics(
            &options.name,
            latest.as_ref(),
            mux.as_ref(),
            safety.as_ref(),
            clock.ros_time(now),
        );
        let key = convert::diagnostics_key(&array);
        let due = last_diagnostics.as_ref().is_none_or(|(at, last)| {
            u128::from(now.saturating_sub(*at)) >= DIAGNOSTICS_PERIOD.as_nanos() || *last != key
        });
        if due {
            bag.write("diagnostics", &array, log_time())?;
            last_diagnostics = Some((now, key));
        }
    }
    let counts = bag.counts();
    Ros2Bag::finish(bag)?;
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, Odometry, Time};

    #[test]
    fn the_odometry_schema_carries_every_type_it_uses_once() {
        let text = schema("nav_msgs/Odometry").unwrap();
        assert!(text.starts_with("std_msgs/Header header\n"), "{text}");
        for used in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "geometry_msgs/PoseWithCovariance",
            "geometry_msgs/Pose",
            "geometry_msgs/Point",
            "geometry_msgs/Quaternion",
            "geometry_msgs/TwistWithCovariance",
            "geometry_msgs/Twist",
            "geometry_msgs/Vector3",
        ] {
            assert_eq!(
                text.matches(&format!("\nMSG: {used}\n")).count(),
                1,
                "{used} in\n{text}"
            );
        }
        for ty in DEFINITIONS.iter().map(|(t, _)| *t) {
            schema(ty).unwrap();
        }
    }

    #[test]
    fn the_model_topics_are_offered_transient_local() {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut bag = Ros2Bag::new(&mut out, "/r1", Vec::new()).unwrap();
        let text = crate::msg::StdString {
            data: "<robot name=\"r\"/>".into(),
        };
        bag.write("robot_description", &text, 1).unwrap();
        bag.finish().unwrap();
        let bytes = out.into_inner();
        let messages: Vec<mcap::Message> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let m = &messages[0];
        assert_eq!(m.channel.topic, "/r1/robot_description");
        let qos = &m.channel.metadata["offered_qos_profiles"];
        assert!(
            qos.contains("durability: 1") && qos.contains("depth: 1"),
            "{qos}"
        );
        assert_eq!(
            m.channel.schema.as_ref().unwrap().name,
            "std_msgs/msg/String"
        );
        assert_eq!(&m.data[4..8], &18u32.to_le_bytes());
        assert_eq!(&m.data[8..26], b"<robot name=\"r\"/>\0");
    }

    #[test]
    fn a_message_is_cdr_behind_the_little_endian_encapsulation() {
        let mut out = std::io::Cursor::new(Vec::new());
        let mut bag = Ros2Bag::new(&mut out, "/", Vec::new()).unwrap();
        let frames = Frames::new("");
        let mut odom: Odometry = convert::odometry(
            &chassis_client::ChassisState::default(),
            &chassis_client::OdometryVariance::default(),
            RosClock::with_offset(0),
            &frames,
        );
        odom.header = Header::new(Time { sec: 7, nanosec: 9 }, "odom");
        bag.write("odom", &odom, 1).unwrap();
        bag.finish().unwrap();
        let bytes = out.into_inner();
        let messages: Vec<mcap::Message> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(messages.len(), 1);
        let m = &messages[0];
        assert_eq!(m.channel.topic, "/odom");
        assert_eq!(m.channel.message_encoding, "cdr");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("nav_msgs/msg/Odometry", "ros2msg")
        );
        assert!(m.channel.metadata["offered_qos_profiles"].contains("reliability: 1"));
        // Encapsulation, then sec 7, nanosec 9, the frame id "odom" with its terminator.
        assert_eq!(&m.data[..4], &[0, 1, 0, 0]);
        assert_eq!(&m.data[4..12], &[7, 0, 0, 0, 9, 0, 0, 0]);
        assert_eq!(&m.data[12..16], &5u32.to_le_bytes());
        assert_eq!(&m.data[16..21], b"odom\0");
    }
}
