//! The far end of the ROS 2 bridge's raw DDS hops (`clients/ros2/bench.py` starts it as
//! `chassis-bench role dds-echo`): the bridge's DDS stack, its messages and QoS, with nothing
//! behind it, so that a hop carries what the bridge's path carries.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{ChassisState, RobotDescription, termination_requested};
use chassis_ros2::bridge::{cmd_vel_qos, reliable_qos, reliable_writer_qos, topic_name};
use chassis_ros2::convert::{self, Frames, RosClock};
use chassis_ros2::msg::{Odometry, TwistStamped, Typed};
use mio::{Events, Interest, Poll, Token};
use ros2_client::{Context, ContextOptions, NodeName, NodeOptions, Publisher, Subscription};

const PING: Token = Token(0);

#[derive(Debug, clap::Args)]
pub struct EchoArgs {
    /// Where to write the pings' one-way latencies, ns, one a line.
    #[arg(long)]
    out: PathBuf,
    /// DDS domain (default: `ROS_DOMAIN_ID`, else 0).
    #[arg(long, env = "ROS_DOMAIN_ID", default_value_t = 0)]
    domain_id: u16,
}

/// Each `TwistStamped` on `chassis_bench/ping` (its stamp: the sender's `CLOCK_MONOTONIC` at the
/// write), read as `cmd_vel` is read, is recorded as a one-way latency and answered at once on
/// `chassis_bench/pong` by an `Odometry` written as `odom` is written (the same message, the
/// same writer QoS), stamped with this process' `CLOCK_MONOTONIC` at that write. Runs until
/// SIGINT / SIGTERM, then writes the latencies, ns, one a line, to `--out`.
pub fn run(args: &EchoArgs) -> anyhow::Result<()> {
    let (domain_id, out) = (args.domain_id, &args.out);
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id))
        .context("joining the DDS domain")?;
    let mut node = context
        .new_node(
            NodeName::new("/", "chassis_bench_echo")
                .map_err(|e| anyhow::anyhow!("node name: {e:?}"))?,
            NodeOptions::new(),
        )
        .context("creating the node")?;
    let ping_topic = node.create_topic(
        &topic_name("/", "chassis_bench/ping")?,
        TwistStamped::type_name(),
        &reliable_qos(),
    )?;
    let pong_topic = node.create_topic(
        &topic_name("/", "chassis_bench/pong")?,
        Odometry::type_name(),
        &reliable_qos(),
    )?;
    let mut ping: Subscription<TwistStamped> =
        node.create_subscription(&ping_topic, Some(cmd_vel_qos()))?;
    let pong: Publisher<Odometry> =
        node.create_publisher(&pong_topic, Some(reliable_writer_qos()))?;
    // An odom as the bridge writes it for a robot at rest: the same size on the wire.
    let description = RobotDescription::default();
    let odom = convert::odometry(
        &ChassisState::default(),
        &description.odometry_variance,
        RosClock::with_offset(0),
        &Frames::new(""),
    );
    let mut poll = Poll::new()?;
    poll.registry()
        .register(&mut ping, PING, Interest::READABLE)?;
    let mut events = Events::with_capacity(4);
    let mut latencies = Vec::new();
    while !termination_requested() {
        if let Err(e) = poll.poll(&mut events, Some(Duration::from_millis(100))) {
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e).context("waiting for DDS");
        }
        while let Ok(Some((m, _))) = ping.take() {
            let now = chassis_client::now_ns();
            let sent = u64::try_from(m.header.stamp.nanos()).unwrap_or(0);
            latencies.push(now.saturating_sub(sent));
            let mut answer = odom.clone();
            answer.header.stamp = chassis_ros2::msg::Time::from_nanos(
                i64::try_from(chassis_client::now_ns()).unwrap_or(0),
            );
            if let Err(e) = pong.publish(answer) {
                eprintln!("chassis-bench dds-echo: pong not sent: {e:?}");
            }
        }
    }
    let text: String = latencies.iter().map(|l| format!("{l}\n")).collect();
    std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
    drop(pong);
    drop(ping);
    Ok(())
}
