//! The bridge's ROS 2 node and its two loops.
//!
//! * **Commands** ([`commands`], a thread of its own): `cmd_vel`, `e_stop` and `speed_limit`
//!   subscriptions and the three services, waited on with mio. A velocity goes into the mux as
//!   the source `ros2` the moment it is read, re-stamped with this computer's `CLOCK_MONOTONIC`
//!   (a ROS stamp is another clock), so chassisd's 500 ms timeout runs from its arrival. A
//!   Nav2 speed limit lowers the robot's standing limit as that source ([`speed_limit_request`]).
//!   Service calls and the e-stop wait for chassisd's control answer.
//! * **State** ([`state_loop`], the main thread): each state sample chassisd publishes becomes
//!   `odom` and `tf` at once; `joint_states`, `battery_state`, `imu/data`, `range/*` and `fix`
//!   follow the sample when the robot reports them; `diagnostics` goes out every second and on
//!   every change of a level or message. The robot's model, `robot_description` (its URDF) and
//!   `tf_static` (the URDF's fixed frames: `base_footprint`, the sensors, the tracks), goes out
//!   at start and again when a newer description changes it, transient local: a node that
//!   starts later (RViz, `robot_state_publisher`) is handed the last one.
//!
//! What the robot is comes from the description chassisd publishes (`chassis/<name>/robot`,
//! read once before the node is created, [`describe`]): a `range/<name>` topic per range sensor
//! it lists, the joints it lists in `joint_states`, the wheel geometry of the wheel joints and
//! the variances of `odom`. A newer description (protocol detection deciding) updates the
//! joints and variances; its range sensors are the node's topics, fixed at start.
//!
//! iceoryx2 ports stay on the thread that opened them (each loop has its own [`Robot`]); the DDS
//! entities are created once and moved into the loop that uses them.

use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{
    ChassisState, ClientError, ControlKind, ControlRequest, ControlResponse, ControlStatus,
    FaultClear, InvalidVelocity, MuxStatus, Robot, RobotDescription, SafetyStatus, Source,
    ValidRequest, VelocityRequest, termination_requested,
};
use mio::{Events, Interest, Poll, Token};
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile, Server,
    ServiceMapping, ServiceTypeName, Subscription,
    qos::{Durability, History, WhenFull},
    service::RmwRequestId,
};

use crate::convert::{self, Frames, ModelSent, RangeSensor, RosClock};
use crate::discovery::Reach;
use crate::msg::{
    BatteryState, Bool, DiagnosticArray, Imu, JointState, NavSatFix, Odometry, Range, SpeedLimit,
    StdString, TfMessage, TriggerRequest, TriggerResponse, Twist, TwistStamped, Typed,
};

/// The mux source the bridge publishes into (chassisd's default configuration has it).
pub const SOURCE: &str = "ros2";
/// How long a service call or the e-stop waits for chassisd's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(2);
/// The period of `diagnostics` when nothing changes.
const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);
/// The ROS 2 node's name.
pub const NODE_NAME: &str = "chassis_ros2";

/// What the bridge is told on its command line.
#[derive(Debug, Clone)]
pub struct Options {
    /// chassisd's robot name (`chassis/<name>/…`).
    pub name: String,
    /// ROS namespace of every topic and of the node, `/` or `/robot1`.
    pub namespace: String,
    pub domain_id: u16,
    /// `cmd_vel` is `geometry_msgs/TwistStamped` instead of `Twist`.
    pub stamped: bool,
    /// Publish odom → base_link on `tf`.
    pub tf: bool,
    /// Prefix of every frame id (`robot1/`).
    pub frame_prefix: String,
    pub service_mapping: ServiceMapping,
    /// Stamps are `CLOCK_MONOTONIC` itself, not ROS time.
    pub monotonic_stamps: bool,
    /// How far the participant reaches (ROS 2's discovery switches).
    pub reach: Reach,
}

/// The service mapping ROS 2's RMW layer uses: rmw_cyclonedds_cpp has its own; rmw_fastrtps and
/// rmw_connextdds use the "enhanced" mapping of the DDS-RPC specification.
pub fn mapping_for_rmw(rmw: Option<&str>) -> ServiceMapping {
    match rmw {
        Some(r) if r.contains("cyclonedds") => ServiceMapping::Cyclone,
        _ => ServiceMapping::Enhanced,
    }
}

/// QoS of the streams REP-2003 calls sensor data (`imu/data`, `range/*`, `fix`,
/// `battery_state`): best effort, the last 5 (rclcpp's `SensorDataQoS`).
pub fn sensor_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 5 })
}

/// QoS of `odom`, `joint_states`, `diagnostics`, `e_stop`, `speed_limit`: reliable, volatile,
/// the last 10 (rclcpp's default, what Nav2's speed filter offers: a limit is sent once per
/// zone, so none may be lost).
pub fn reliable_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Wait(Duration::from_millis(10)))
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// QoS of the bridge's `cmd_vel` reader: best effort, volatile, the last 1. A best-effort
/// reader is never sent a retransmission, so a reliable writer (Nav2's, `ros2 topic pub`'s —
/// reliable offers match a best-effort request) cannot replay twists it buffered through an
/// outage when the link comes back: what arrives was sent just now. A lost twist is replaced by
/// the next one (a controller publishes at 10-50 Hz); the mux's timeout covers a silence.
pub fn cmd_vel_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1 })
}

/// What the bridge's reliable writers keep for a slow reader: the last 100 (a subscriber asks
/// for its own depth, rclcpp's 10 by default; depth is not part of matching). A writer whose
/// window of unacknowledged samples is full drops the sample (counted) instead of blocking the
/// state loop.
pub fn reliable_writer_qos() -> QosProfile {
    reliable_qos()
        .reliability_reliable(WhenFull::Fail)
        .history(History::KeepLast { depth: 100 })
}

/// QoS of `robot_description` and `tf_static`: reliable, transient local, the last 1 (what
/// `robot_state_publisher` and tf2's `StaticBroadcasterQoS` offer): the writer keeps the last
/// one for every reader that matches later.
pub fn latched_qos() -> QosProfile {
    reliable_qos()
        .durability(Durability::TransientLocal)
        .history(History::KeepLast { depth: 1 })
}

/// The node and every DDS entity, before they are handed to the loops.
pub struct Entities {
    pub node: Node,
    pub commands: Commands,
    pub outputs: Outputs,
}

/// What the commands loop reads.
pub struct Commands {
    cmd_vel: CmdVel,
    e_stop: Subscription<Bool>,
    speed_limit: Subscription<SpeedLimit>,
    /// The robot's forward limit, m/s: what a percentage speed limit is a percentage of.
    max_mps: f64,
    estop: Server<TriggerRequest, TriggerResponse>,
    estop_release: Server<TriggerRequest, TriggerResponse>,
    clear_faults: Server<TriggerRequest, TriggerResponse>,
}

enum CmdVel {
    Plain(Subscription<Twist>),
    Stamped(Subscription<TwistStamped>),
}

/// What the state loop publishes.
pub struct Outputs {
    odom: Publisher<Odometry>,
    tf: Option<Publisher<TfMessage>>,
    joint_states: Publisher<JointState>,
    battery: Publisher<BatteryState>,
    imu: Publisher<Imu>,
    /// One per range sensor of the description.
    ranges: Vec<(RangeSensor, Publisher<Range>)>,
    fix: Publisher<NavSatFix>,
    diagnostics: Publisher<DiagnosticArray>,
    /// The URDF, transient local.
    robot_description: Publisher<StdString>,
    /// The URDF's fixed frames, transient local.
    tf_static: Publisher<TfMessage>,
}

macro_rules! opaque_debug {
    ($($ty:ident),*) => {$(
        impl std::fmt::Debug for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.debug_struct(stringify!($ty)).finish_non_exhaustive()
            }
        }
    )*};
}
opaque_debug!(Entities, Commands, Outputs);

/// `path` under ROS namespace `namespace`, as a topic's name.
pub fn topic_name(namespace: &str, path: &str) -> anyhow::Result<Name> {
    let full = if namespace == "/" {
        format!("/{path}")
    } else {
        format!("{namespace}/{path}")
    };
    Name::parse(&full).map_err(|e| anyhow::anyhow!("bad ROS name {full}: {e:?}"))
}

impl Entities {
    /// Joins DDS domain `options.domain_id` and creates the node, its topics and services, a
    /// `range/<name>` topic for each range sensor `description` lists.
    pub fn create(options: &Options, description: &RobotDescription) -> anyhow::Result<Self> {
        let mut participant = rustdds::DomainParticipantBuilder::new(options.domain_id);
        if let Some(addresses) = options.reach.only_networks() {
            participant = participant.with_only_networks(addresses);
        }
        let participant = participant.build().context("joining the DDS domain")?;
        let context =
            Context::from_domain_participant(participant).context("joining the DDS domain")?;
        let node_name = NodeName::new(&options.namespace, NODE_NAME)
            .map_err(|e| anyhow::anyhow!("bad namespace {}: {e:?}", options.namespace))?;
        let mut node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(true))
            .context("creating the ROS 2 node")?;
        let ns = options.namespace.as_str();
        let private = if ns == "/" {
            format!("/{NODE_NAME}")
        } else {
            format!("{ns}/{NODE_NAME}")
        };

        let topic = |path: &str, ty: MessageTypeName, qos: &QosProfile| {
            let name = topic_name(ns, path)?;
            node.create_topic(&name, ty, qos)
                .with_context(|| format!("creating topic {path}"))
        };
        let cmd_vel_topic = if options.stamped {
            topic("cmd_vel", TwistStamped::type_name(), &reliable_qos())?
        } else {
            topic("cmd_vel", Twist::type_name(), &reliable_qos())?
        };
        let e_stop_topic = topic("e_stop", Bool::type_name(), &reliable_qos())?;
        let speed_limit_topic = topic("speed_limit", SpeedLimit::type_name(), &reliable_qos())?;
        let odom_topic = topic("odom", Odometry::type_name(), &reliable_qos())?;
        // Reliable, the last 100 (tf2_ros' `DynamicBroadcasterQoS`).
        let tf_qos = reliable_qos().history(History::KeepLast { depth: 100 });
        let tf_topic = topic("tf", TfMessage::type_name(), &tf_qos)?;
        let joints_topic = topic("joint_states", JointState::type_name(), &reliable_qos())?;
        let battery_topic = topic("battery_state", BatteryState::type_name(), &sensor_qos())?;
        let imu_topic = topic("imu/data", Imu::type_name(), &sensor_qos())?;
        let fix_topic = topic("fix", NavSatFix::type_name(), &sensor_qos())?;
        let diag_topic = topic("diagnostics", DiagnosticArray::type_name(), &reliable_qos())?;
        let model_topic = topic("robot_description", StdString::type_name(), &latched_qos())?;
        let tf_static_topic = topic("tf_static", TfMessage::type_name(), &latched_qos())?;
        let range_topics = convert::range_sensors(description)
            .into_iter()
            .map(|s| {
                let t = topic(
                    &format!("range/{}", s.name),
                    Range::type_name(),
                    &sensor_qos(),
                )?;
                Ok((s, t))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;

        let cmd_vel = if options.stamped {
            CmdVel::Stamped(node.create_subscription(&cmd_vel_topic, Some(cmd_vel_qos()))?)
        } else {
            CmdVel::Plain(node.create_subscription(&cmd_vel_topic, Some(cmd_vel_qos()))?)
        };
        let e_stop = node.create_subscription(&e_stop_topic, None)?;
        let speed_limit = node.create_subscription(&speed_limit_topic, None)?;
        let mut server = |base: &str| {
            let name = topic_name(&private, base)?;
            node.create_server(
                options.service_mapping,
                &name,
                &ServiceTypeName::new("std_srvs", "Trigger"),
                reliable_qos(),
                reliable_qos(),
            )
            .with_context(|| format!("creating service ~/{base}"))
        };
        let commands = Commands {
            cmd_vel,
            e_stop,
            speed_limit,
            max_mps: description.effective_limits().forward_mps,
            estop: server("estop")?,
            estop_release: server("estop_release")?,
            clear_faults: server("clear_faults")?,
        };
        let outputs = Outputs {
            odom: node.create_publisher(&odom_topic, Some(reliable_writer_qos()))?,
            tf: if options.tf {
                Some(node.create_publisher(&tf_topic, Some(reliable_writer_qos()))?)
            } else {
                None
            },
            joint_states: node.create_publisher(&joints_topic, Some(reliable_writer_qos()))?,
            battery: node.create_publisher(&battery_topic, None)?,
            imu: node.create_publisher(&imu_topic, None)?,
            ranges: range_topics
                .into_iter()
                .map(|(s, t)| node.create_publisher(&t, None).map(|p| (s, p)))
                .collect::<Result<Vec<_>, _>>()?,
            fix: node.create_publisher(&fix_topic, None)?,
            diagnostics: node.create_publisher(&diag_topic, Some(reliable_writer_qos()))?,
            robot_description: node.create_publisher(&model_topic, Some(latched_qos()))?,
            tf_static: node.create_publisher(&tf_static_topic, Some(latched_qos()))?,
        };
        Ok(Self {
            node,
            commands,
            outputs,
        })
    }
}

/// Connects to chassisd and reads the robot's description, waiting for both (the bridge may
/// start first). `None` when the process is asked to stop while waiting.
pub fn describe(name: &str) -> Option<(Robot, RobotDescription)> {
    let mut robot = chassis_client::wait_for_robot(name)?;
    let mut warned = false;
    while !termination_requested() {
        match robot.description(Duration::from_secs(1)) {
            Ok(d) => {
                tracing::info!(
                    robot = name,
                    model = d.model(),
                    sensors = d.sensors().len(),
                    joints = d.joints().len(),
                    "{}",
                    d.display_name()
                );
                return Some((robot, d));
            }
            Err(e) if !warned => {
                warned = true;
                tracing::warn!(error = %e, "waiting for the description of robot '{name}'");
            }
            Err(e) => tracing::debug!(error = %e, "no description yet"),
        }
    }
    None
}

/// Counts of what the commands loop refused, logged as they happen.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Drops {
    /// Velocities with a NaN or infinite component (or one beyond `f32`).
    pub non_finite: u64,
    /// Velocities chassisd's source did not take (source held by another process, IPC error).
    pub unsent: u64,
    /// Messages DDS could not deserialize.
    pub undecodable: u64,
    /// `TwistStamped`s older than the bound when they arrived (or unstamped).
    pub stale: u64,
    /// Speed limits that are not a number or are negative.
    pub bad_speed_limits: u64,
}

/// The `CLOCK_MONOTONIC` instant a `TwistStamped` stamped `stamp` (ROS time, the sender's
/// system clock, as NTP keeps ROS computers) was made, if it arrived at `now_ns` at most
/// `max_age_ns` after that and not more than that before (a clock that far ahead is not
/// trusted either); never later than `now_ns`. An unstamped one (0) is refused.
pub fn stamp_age_check(
    stamp: crate::msg::Time,
    clock: RosClock,
    now_ns: u64,
    max_age_ns: u64,
) -> Result<u64, String> {
    if stamp.nanos() <= 0 {
        return Err("unstamped (header.stamp 0)".into());
    }
    let made = clock.monotonic_ns(stamp);
    let age = i128::from(now_ns) - i128::from(made);
    if age > i128::from(max_age_ns) {
        return Err(format!(
            "made {} ms before it arrived (at most {} ms)",
            age / 1_000_000,
            max_age_ns / 1_000_000
        ));
    }
    if -age > i128::from(max_age_ns) {
        return Err(format!(
            "stamped {} ms in the future (the sender's clock is not this one's)",
            -age / 1_000_000
        ));
    }
    Ok(made.min(now_ns))
}

/// A `cmd_vel` twist parsed into a velocity request: where a ROS 2 velocity enters. linear.x,
/// linear.y and angular.z are used, as `f32`: one that is not a finite number there (a NaN, an
/// infinity, or beyond `f32`) refuses the twist. The rest has no meaning for a ground robot and
/// is ignored.
pub fn twist_request(twist: &Twist) -> Result<ValidRequest, InvalidVelocity> {
    ValidRequest::try_from(VelocityRequest {
        linear_y_mps: twist.linear.y as f32,
        ..VelocityRequest::twist(twist.linear.x as f32, twist.angular.z as f32)
    })
}

/// A Nav2 speed limit parsed into the request that lowers the robot's standing limit: where a
/// ROS 2 speed limit enters. Absolute (m/s) or a percentage of `max_mps`, the robot's forward
/// limit. 0 (no limit) is `Ok(None)`: only the operator raises a limit (`chassis control
/// speed-limit`). A NaN, an infinity or a negative value is refused.
pub fn speed_limit_request(
    limit: &SpeedLimit,
    max_mps: f64,
) -> Result<Option<ValidRequest>, InvalidVelocity> {
    if limit.speed_limit == 0.0 {
        return Ok(None);
    }
    let mps = if limit.percentage {
        limit.speed_limit / 100.0 * max_mps
    } else {
        limit.speed_limit
    };
    ValidRequest::try_from(VelocityRequest::speed_limit(mps as f32)).map(Some)
}

/// The control request a service asks for.
pub fn service_request(service: ServiceKind) -> ControlRequest {
    match service {
        ServiceKind::Estop => ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop"),
        ServiceKind::EstopRelease => {
            ControlRequest::new(ControlKind::LOCK_RELEASE).with_name("estop")
        }
        ServiceKind::ClearFaults => {
            ControlRequest::new(ControlKind::CLEAR_FAULTS).with_arg(0, FaultClear::ALL)
        }
    }
}

/// The three `std_srvs/Trigger` services.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind {
    Estop,
    EstopRelease,
    ClearFaults,
}

/// chassisd's answer as a `Trigger` response: success when it did it, and its message (a
/// refusal's reason) either way.
pub fn trigger_response(answer: Result<ControlResponse, ClientError>) -> TriggerResponse {
    match answer {
        Ok(r) => TriggerResponse {
            success: r.status == ControlStatus::OK,
            message: if r.message().is_empty() {
                ControlStatus::name(r.status).to_string()
            } else {
                format!("{}: {}", ControlStatus::name(r.status), r.message())
            },
        },
        Err(e) => TriggerResponse {
            success: false,
            message: format!("chassisd did not answer: {e}"),
        },
    }
}

const CMD_VEL: Token = Token(0);
const E_STOP: Token = Token(1);
const ESTOP: Token = Token(2);
const ESTOP_RELEASE: Token = Token(3);
const CLEAR_FAULTS: Token = Token(4);
const SPEED_LIMIT: Token = Token(5);

/// The commands loop: runs until SIGINT / SIGTERM. A `TwistStamped` older than `max_age` when it
/// arrives is dropped and counted (`clock`: ROS time ↔ `CLOCK_MONOTONIC`).
pub fn commands(
    name: &str,
    mut c: Commands,
    clock: RosClock,
    max_age: Duration,
) -> anyhow::Result<Drops> {
    let max_age_ns = u64::try_from(max_age.as_nanos()).unwrap_or(u64::MAX);
    let Some(mut robot) = chassis_client::wait_for_robot(name) else {
        return Ok(Drops::default());
    };
    let mut poll = Poll::new().context("creating the poll")?;
    let registry = poll.registry();
    match &mut c.cmd_vel {
        CmdVel::Plain(s) => registry.register(s, CMD_VEL, Interest::READABLE)?,
        CmdVel::Stamped(s) => registry.register(s, CMD_VEL, Interest::READABLE)?,
    }
    registry.register(&mut c.e_stop, E_STOP, Interest::READABLE)?;
    registry.register(&mut c.speed_limit, SPEED_LIMIT, Interest::READABLE)?;
    registry.register(&mut c.estop, ESTOP, Interest::READABLE)?;
    registry.register(&mut c.estop_release, ESTOP_RELEASE, Interest::READABLE)?;
    registry.register(&mut c.clear_faults, CLEAR_FAULTS, Interest::READABLE)?;

    let mut source: Option<Source> = None;
    let mut drops = Drops::default();
    let mut events = Events::with_capacity(16);
    while !termination_requested() {
        if let Err(e) = poll.poll(&mut events, Some(Duration::from_millis(100))) {
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e).context("waiting for DDS");
        }
        // Every reader is drained on every wake: a readiness may have been merged with another.
        let age = (clock, max_age_ns);
        drain_cmd_vel(&c.cmd_vel, age, &mut robot, &mut source, &mut drops);
        drain_e_stop(&c.e_stop, &mut robot, &mut drops);
        drain_speed_limit(&c, &mut robot, &mut source, &mut drops);
        for (server, kind) in [
            (&c.estop, ServiceKind::Estop),
            (&c.estop_release, ServiceKind::EstopRelease),
            (&c.clear_faults, ServiceKind::ClearFaults),
        ] {
            serve(server, kind, &mut robot, &mut drops);
        }
    }
    Ok(drops)
}

fn drain_cmd_vel(
    cmd_vel: &CmdVel,
    (clock, max_age_ns): (RosClock, u64),
    robot: &mut Robot,
    source: &mut Option<Source>,
    drops: &mut Drops,
) {
    loop {
        let taken = match cmd_vel {
            CmdVel::Plain(s) => s.take().map(|m| m.map(|(t, _)| (t, None))),
            CmdVel::Stamped(s) => s
                .take()
                .map(|m| m.map(|(t, _)| (t.twist, Some(t.header.stamp)))),
        };
        let (twist, stamp) = match taken {
            Ok(Some(taken)) => taken,
            Ok(None) => return,
            Err(e) => {
                drops.undecodable += 1;
                tracing::warn!(error = ?e, count = drops.undecodable, "cmd_vel: unreadable message dropped");
                continue;
            }
        };
        let mut request = match twist_request(&twist) {
            Ok(request) => request,
            Err(error) => {
                drops.non_finite += 1;
                tracing::warn!(
                    ?twist,
                    %error,
                    count = drops.non_finite,
                    "cmd_vel with a non-finite component dropped"
                );
                continue;
            }
        };
        if let Some(stamp) = stamp {
            match stamp_age_check(stamp, clock, chassis_client::now_ns(), max_age_ns) {
                // Its timeout runs from when it was made.
                Ok(made) => request = request.with_stamp_ns(made),
                Err(why) => {
                    drops.stale += 1;
                    tracing::warn!(count = drops.stale, "cmd_vel dropped as stale: {why}");
                    continue;
                }
            }
        }
        forward(request, robot, source, drops);
    }
}

/// Sends `request` as the `ros2` source, opening it when needed (chassisd may have restarted).
fn forward(
    request: ValidRequest,
    robot: &mut Robot,
    source: &mut Option<Source>,
    drops: &mut Drops,
) {
    if source.is_none() {
        match robot.source(SOURCE) {
            Ok(s) => *source = Some(s),
            Err(e) => {
                drops.unsent += 1;
                tracing::warn!(error = %e, count = drops.unsent, "cmd_vel dropped: cannot publish as source '{SOURCE}'");
                return;
            }
        }
    }
    if let Some(s) = source
        && let Err(e) = s.send(request)
    {
        drops.unsent += 1;
        tracing::warn!(error = %e, count = drops.unsent, "cmd_vel dropped");
        *source = None;
    }
}

fn drain_speed_limit(
    c: &Commands,
    robot: &mut Robot,
    source: &mut Option<Source>,
    drops: &mut Drops,
) {
    loop {
        let limit = match c.speed_limit.take() {
            Ok(Some((limit, _))) => limit,
            Ok(None) => return,
            Err(e) => {
                drops.undecodable += 1;
                tracing::warn!(error = ?e, count = drops.undecodable, "speed_limit: unreadable message dropped");
                continue;
            }
        };
        match speed_limit_request(&limit, c.max_mps) {
            Ok(Some(request)) => forward(request, robot, source, drops),
            Ok(None) => tracing::info!(
                "speed_limit: no limit asked; a standing limit stays until the operator raises \
                 it (chassis control speed-limit)"
            ),
            Err(error) => {
                drops.bad_speed_limits += 1;
                tracing::warn!(
                    ?limit,
                    %error,
                    count = drops.bad_speed_limits,
                    "speed_limit refused"
                );
            }
        }
    }
}

fn drain_e_stop(e_stop: &Subscription<Bool>, robot: &mut Robot, drops: &mut Drops) {
    loop {
        match e_stop.take() {
            Ok(Some((msg, _))) if msg.data => {
                let answer = robot.control(service_request(ServiceKind::Estop), ANSWER_TIMEOUT);
                let r = trigger_response(answer);
                tracing::info!(success = r.success, message = %r.message, "e_stop: engaged the operator e-stop");
            }
            // Releasing stays explicit (~/estop_release): a false on the topic does nothing.
            Ok(Some(_)) => {}
            Ok(None) => return,
            Err(e) => {
                drops.undecodable += 1;
                tracing::warn!(error = ?e, count = drops.undecodable, "e_stop: unreadable message dropped");
            }
        }
    }
}

fn serve(
    server: &Server<TriggerRequest, TriggerResponse>,
    kind: ServiceKind,
    robot: &mut Robot,
    drops: &mut Drops,
) {
    loop {
        let id: RmwRequestId = match server.receive_request() {
            Ok(Some((id, _))) => id,
            Ok(None) => return,
            Err(e) => {
                drops.undecodable += 1;
                tracing::warn!(error = ?e, ?kind, "service request unreadable, dropped");
                continue;
            }
        };
        let response = trigger_response(robot.control(service_request(kind), ANSWER_TIMEOUT));
        tracing::info!(?kind, success = response.success, message = %response.message, "service call");
        if let Err(e) = server.send_response(id, response) {
            tracing::warn!(error = ?e, ?kind, "service response not sent");
        }
    }
}

/// One message of the state loop, for its topic.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// `odom` (boxed: three times the size of the others).
    Odom(Box<Odometry>),
    /// `tf` (odom → base_link).
    Tf(TfMessage),
    /// `joint_states`.
    Joints(JointState),
    /// `battery_state`.
    Battery(BatteryState),
    /// `imu/data`.
    Imu(Imu),
    /// `range/<sensor>`: the index of the sensor in the `ranges` [`messages`] was given.
    Range(usize, Range),
    /// `fix`.
    Fix(NavSatFix),
}

/// What `s` brings that the previous sample `latest` did not: odom and tf when the pose or the
/// body's motion was reported anew (a sample made by another frame repeats them), the joints
/// with their angles and speeds, each range sensor of `ranges` with its own reading. The
/// robot's `description` gives the odometry's variances and the joints. The bridge publishes
/// these; `chassis-ros2 --record` writes them.
pub fn messages(
    latest: Option<&ChassisState>,
    s: &ChassisState,
    description: &RobotDescription,
    ranges: &[RangeSensor],
    clock: RosClock,
    frames: &Frames,
) -> Vec<Message> {
    use chassis_client::Group;
    let fresh = |group: Group| {
        latest.is_none_or(|l| l.group_stamp_ns[group.index()] != s.group_stamp_ns[group.index()])
    };
    let mut out = Vec::new();
    if fresh(Group::Pose) || fresh(Group::Motion) {
        out.push(Message::Odom(Box::new(convert::odometry(
            s,
            &description.odometry_variance,
            clock,
            frames,
        ))));
        out.push(Message::Tf(convert::transform(s, clock, frames)));
    }
    if (fresh(Group::Steering) || fresh(Group::WheelSpeed))
        && let Some(j) = convert::joint_states(s, description, clock)
    {
        out.push(Message::Joints(j));
    }
    if (fresh(Group::BmsPack) || fresh(Group::System))
        && let Some(b) = convert::battery(s, clock, frames)
    {
        out.push(Message::Battery(b));
    }
    if fresh(Group::Imu)
        && let Some(i) = convert::imu(s, clock, frames)
    {
        out.push(Message::Imu(i));
    }
    if fresh(Group::Ranges) {
        for (index, sensor) in ranges.iter().enumerate() {
            if let Some(r) = convert::range(s, sensor, clock, frames) {
                out.push(Message::Range(index, r));
            }
        }
    }
    if fresh(Group::Gps)
        && let Some(fix) = convert::nav_sat_fix(s, clock, frames)
    {
        out.push(Message::Fix(fix));
    }
    out
}

/// The state loop's odom trace ([`chassis_ipc::ODOM_TRACE`], written when the loop ends;
/// `chassis-bench` splits its ROS 2 row with it).
type OdomTrace = chassis_ipc::StampTrace<4>;

/// What the state loop keeps between samples.
struct StateLoop<'a> {
    name: &'a str,
    out: &'a Outputs,
    clock: RosClock,
    frames: Frames,
    description: RobotDescription,
    /// The range sensors of `out.ranges`, in its order.
    sensors: Vec<RangeSensor>,
    latest: Option<ChassisState>,
    mux: Option<MuxStatus>,
    /// The safety monitor's decision, once it publishes one.
    safety: Option<SafetyStatus>,
    last_diagnostics: Option<(u64, Vec<(u8, String)>)>,
    /// The robot model last published.
    model: ModelSent,
    /// Publications DDS refused, counted and logged.
    failures: u64,
    /// When the loop woke with the samples it is publishing.
    woke_ns: u64,
    trace: Option<OdomTrace>,
}

impl StateLoop<'_> {
    fn publish<M: serde::Serialize + std::fmt::Debug>(
        failures: &mut u64,
        topic: &str,
        p: &Publisher<M>,
        m: M,
    ) {
        if let Err(e) = p.publish(m) {
            *failures += 1;
            if failures.is_power_of_two() {
                tracing::warn!(error = ?e, topic, count = *failures, "publication failed");
            }
        }
    }

    /// Publishes what `s` brings that the previous sample did not ([`messages`]).
    fn on_state(&mut self, s: &ChassisState) {
        let out = self.out;
        let f = &mut self.failures;
        let messages = messages(
            self.latest.as_ref(),
            s,
            &self.description,
            &self.sensors,
            self.clock,
            &self.frames,
        );
        for m in messages {
            match m {
                Message::Odom(m) => {
                    let begun = self.trace.is_some().then(chassis_client::now_ns);
                    Self::publish(f, "odom", &out.odom, *m);
                    if let (Some(trace), Some(begun)) = (&mut self.trace, begun) {
                        let written = chassis_client::now_ns();
                        trace.push([s.stamp_ns, self.woke_ns, begun, written]);
                    }
                }
                Message::Tf(m) => {
                    if let Some(tf) = &out.tf {
                        Self::publish(f, "tf", tf, m);
                    }
                }
                Message::Joints(m) => Self::publish(f, "joint_states", &out.joint_states, m),
                Message::Battery(m) => Self::publish(f, "battery_state", &out.battery, m),
                Message::Imu(m) => Self::publish(f, "imu/data", &out.imu, m),
                Message::Range(i, m) => {
                    if let Some((_, p)) = out.ranges.get(i) {
                        Self::publish(f, "range", p, m);
                    }
                }
                Message::Fix(m) => Self::publish(f, "fix", &out.fix, m),
            }
        }
        self.latest = Some(*s);
    }

    /// Publishes `robot_description` and `tf_static` when the description's model is not the
    /// one published last.
    fn publish_model(&mut self) {
        let stamp = self.clock.ros_time(chassis_client::now_ns());
        if let Some((urdf, tf)) = self.model.update(&self.description, &self.frames, stamp) {
            tracing::info!(
                bytes = urdf.data.len(),
                frames = tf.transforms.len(),
                "robot_description and tf_static"
            );
            let f = &mut self.failures;
            Self::publish(f, "robot_description", &self.out.robot_description, urdf);
            Self::publish(f, "tf_static", &self.out.tf_static, tf);
        }
    }

    /// Takes a newer description: its joints, wheel geometry and variances, its model.
    fn describe(&mut self, d: RobotDescription) {
        if (d.seq, d.stamp_ns) == (self.description.seq, self.description.stamp_ns) {
            return;
        }
        let ranges = |d: &RobotDescription| convert::range_sensors(d);
        if ranges(&d) != ranges(&self.description) {
            tracing::warn!(
                "the robot's range sensors changed: range topics stay those of the start (restart chassis-ros2)"
            );
        }
        tracing::info!(model = d.model(), seq = d.seq, "a newer robot description");
        self.description = d;
        self.publish_model();
    }

    fn diagnostics(&mut self, now_ns: u64) {
        let stamp = self.clock.ros_time(now_ns);
        let array = convert::diagnostics(
            self.name,
            self.latest.as_ref(),
            self.mux.as_ref(),
            self.safety.as_ref(),
            stamp,
        );
        let key = convert::diagnostics_key(&array);
        let due = self.last_diagnostics.as_ref().is_none_or(|(at, last)| {
            u128::from(now_ns.saturating_sub(*at)) >= DIAGNOSTICS_PERIOD.as_nanos() || *last != key
        });
        if due {
            Self::publish(
                &mut self.failures,
                "diagnostics",
                &self.out.diagnostics,
                array,
            );
            self.last_diagnostics = Some((now_ns, key));
        }
    }
}

/// The state loop, on `robot` as [`describe`] connected it: runs until SIGINT / SIGTERM.
pub fn state_loop(
    name: &str,
    (mut robot, description): (Robot, RobotDescription),
    frames: Frames,
    clock: RosClock,
    out: &Outputs,
) -> anyhow::Result<()> {
    let mut lp = StateLoop {
        name,
        out,
        clock,
        frames,
        description,
        sensors: out
            .ranges
            .iter()
            .map(|(sensor, _)| sensor.clone())
            .collect(),
        latest: None,
        mux: None,
        safety: None,
        last_diagnostics: None,
        model: ModelSent::default(),
        failures: 0,
        woke_ns: 0,
        trace: OdomTrace::from_env(chassis_ipc::Trace::Odom),
    };
    lp.publish_model();
    tracing::info!(robot = name, "bridging");
    while !termination_requested() {
        // Every sample the subscriber holds, oldest first: odom keeps the robot's own rate.
        let mut samples = Vec::with_capacity(4);
        if let Err(e) = robot.wait_states(Duration::from_millis(50), |s| samples.push(*s)) {
            if termination_requested() {
                break;
            }
            return Err(e).context("reading state");
        }
        lp.woke_ns = chassis_client::now_ns();
        for s in &samples {
            lp.on_state(s);
        }
        if let Some(m) = robot.latest_mux().context("reading the mux decision")? {
            lp.mux = Some(m);
        }
        if let Some(status) = robot
            .latest_safety()
            .context("reading the safety monitor")?
        {
            lp.safety = Some(status);
        }
        if let Some(d) = robot
            .latest_description()
            .context("reading the robot description")?
        {
            lp.describe(d);
        }
        lp.diagnostics(chassis_client::now_ns());
    }
    if let Some(trace) = &lp.trace
        && let Err(e) = trace.write()
    {
        tracing::warn!(error = %e, path = %trace.path().display(), "odom trace not written");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::Vector3;

    #[test]
    fn a_twist_becomes_a_request_and_a_non_finite_one_does_not() {
        let t = Twist {
            linear: Vector3 {
                x: 0.5,
                y: 0.1,
                z: 9.0,
            },
            angular: Vector3 {
                x: 9.0,
                y: 9.0,
                z: -0.2,
            },
        };
        let r = twist_request(&t).expect("finite");
        assert_eq!(
            (r.linear_x_mps, r.linear_y_mps, r.angular_z_radps),
            (0.5, 0.1, -0.2)
        );
        assert_eq!(
            r.stamp_ns, 0,
            "stamped on arrival by the source, not by the sender"
        );
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
            let mut t = t;
            t.angular.z = bad;
            assert!(twist_request(&t).is_err());
            let mut t2 = t;
            t2.angular.z = 0.0;
            t2.linear.x = bad;
            assert!(twist_request(&t2).is_err());
        }
        // What a ground robot ignores may be anything.
        let mut t3 = t;
        t3.linear.z = f64::NAN;
        assert!(twist_request(&t3).is_ok());
    }

    #[test]
    fn a_nav2_speed_limit_is_absolute_or_a_percentage_and_zero_lifts_nothing() {
        let limit = |percentage, speed_limit| {
            speed_limit_request(
                &SpeedLimit {
                    percentage,
                    speed_limit,
                    ..SpeedLimit::default()
                },
                2.0,
            )
            .map(|r| r.and_then(|r| r.speed_limit()))
        };
        assert_eq!(limit(false, 0.5), Ok(Some(0.5)));
        assert_eq!(limit(true, 25.0), Ok(Some(0.5)));
        assert_eq!(limit(true, 0.0), Ok(None));
        assert_eq!(
            limit(false, -0.5),
            Err(InvalidVelocity::NonPositiveSpeedLimit)
        );
        assert!(limit(true, f64::NAN).is_err());
    }

    #[test]
    fn a_stamped_twist_older_than_the_bound_is_stale() {
        use crate::msg::Time;
        let ms = 1_000_000u64;
        // ROS time is monotonic time + 1000 s here.
        let clock = RosClock::with_offset(1_000_000_000_000);
        let stamp = |mono_ms: u64| Time::from_nanos((1_000_000 + mono_ms) as i64 * ms as i64);
        let max = 250 * ms;
        assert_eq!(
            stamp_age_check(stamp(5_000), clock, 5_100 * ms, max),
            Ok(5_000 * ms)
        );
        assert!(stamp_age_check(stamp(5_000), clock, 5_251 * ms, max).is_err());
        let old = stamp_age_check(stamp(5_000), clock, 6_200 * ms, max).unwrap_err();
        assert!(old.contains("1200 ms"), "{old}");
        // A little ahead (clocks a few ms apart): taken, stamped at its arrival.
        assert_eq!(
            stamp_age_check(stamp(5_010), clock, 5_000 * ms, max),
            Ok(5_000 * ms)
        );
        assert!(stamp_age_check(stamp(9_000), clock, 5_000 * ms, max).is_err());
        assert!(stamp_age_check(Time::default(), clock, 5_000 * ms, max).is_err());
    }

    #[test]
    fn services_ask_chassisd_for_the_operator_e_stop_and_a_fault_clear() {
        let r = service_request(ServiceKind::Estop);
        assert_eq!((r.kind, r.name()), (ControlKind::LOCK_ENGAGE, "estop"));
        let r = service_request(ServiceKind::EstopRelease);
        assert_eq!((r.kind, r.name()), (ControlKind::LOCK_RELEASE, "estop"));
        let r = service_request(ServiceKind::ClearFaults);
        assert_eq!(
            (r.kind, r.arg[0]),
            (ControlKind::CLEAR_FAULTS, FaultClear::ALL)
        );
    }

    #[test]
    fn a_refusal_is_no_success_with_its_reason() {
        let ok = trigger_response(Ok(ControlResponse::new(1, ControlStatus::OK, "done")));
        assert!(ok.success);
        assert_eq!(ok.message, "ok: done");
        let no = trigger_response(Ok(ControlResponse::new(
            1,
            ControlStatus::REFUSED,
            "moving",
        )));
        assert!(!no.success);
        assert_eq!(no.message, "refused: moving");
        let gone = trigger_response(Err(ClientError::Ipc("gone".into())));
        assert!(!gone.success && gone.message.starts_with("chassisd did not answer"));
    }

    #[test]
    fn the_rmw_picks_the_service_mapping() {
        assert!(matches!(
            mapping_for_rmw(Some("rmw_cyclonedds_cpp")),
            ServiceMapping::Cyclone
        ));
        assert!(matches!(
            mapping_for_rmw(Some("rmw_fastrtps_cpp")),
            ServiceMapping::Enhanced
        ));
        assert!(matches!(mapping_for_rmw(None), ServiceMapping::Enhanced));
    }
}
