//! The bare Zenoh hop (`chassis-bench role zenoh-pub` and `zenoh-sub`): a put → a subscriber's
//! callback, with the same session configuration as the bridge, payloads the size
//! of a `ChassisState`, stamped with `CLOCK_MONOTONIC` (both ends on one machine, in two
//! network namespaces).

use std::io::Write as _;
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{ChassisState, Ticker, now_ns, termination_requested};
use clap::Args;
use zenoh::Wait as _;
use zenoh::qos::{CongestionControl, Priority};

use chassis_zenoh::net::{self, Net, Role};

/// The key the baseline runs on.
const KEY: &str = "chassis-bench/raw";

#[derive(Debug, Args)]
pub struct RawArgs {
    /// Serve on this endpoint (the publisher's side, like the robot side).
    #[arg(long)]
    listen: Vec<String>,
    /// Connect to this endpoint (the subscriber's side, like the mirror).
    #[arg(long)]
    connect: Vec<String>,
    /// Allow plain TCP beyond loopback.
    #[arg(long)]
    insecure: bool,
    /// Samples to send (publisher) or to receive (subscriber).
    #[arg(long, default_value_t = 1000)]
    count: u64,
    /// Publisher: time between two samples, µs (the pace of the path the hop divides).
    #[arg(long, default_value_t = 4000)]
    interval_us: u64,
    /// Subscriber: where to write the latencies, one ns figure a line.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Give up after this long, s.
    #[arg(long, default_value_t = 60)]
    timeout: u64,
}

fn session(args: &RawArgs) -> anyhow::Result<zenoh::Session> {
    let (role, endpoints) = if args.listen.is_empty() {
        (Role::Operator, args.connect.clone())
    } else {
        (Role::Robot, args.listen.clone())
    };
    let net = Net {
        role,
        endpoints,
        certs: None,
        insecure: args.insecure,
        lease_ms: 3000,
    };
    net::open(net::config(&net, "bench", &[])?)
}

/// Publishes `count` stamped samples once a subscriber is there.
pub fn publish(args: &RawArgs) -> anyhow::Result<()> {
    let session = session(args)?;
    let publisher = session
        .declare_publisher(KEY)
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::DataHigh)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let deadline = now_ns() + args.timeout * 1_000_000_000;
    let mut ticker = Ticker::new(Duration::from_micros(args.interval_us.max(1)));
    while !publisher
        .matching_status()
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .matching()
    {
        if now_ns() > deadline || termination_requested() {
            anyhow::bail!("no subscriber within {} s", args.timeout);
        }
        ticker.wait();
    }
    let mut payload = vec![0u8; size_of::<ChassisState>()];
    // Sends until the subscriber has had its count (it leaves) or the time is up: a few
    // samples may be lost to the link.
    while now_ns() < deadline && !termination_requested() {
        ticker.wait();
        payload[..8].copy_from_slice(&now_ns().to_ne_bytes());
        publisher
            .put(payload.clone())
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        if !publisher
            .matching_status()
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .matching()
        {
            break;
        }
    }
    let _ = session.close().wait();
    Ok(())
}

/// Receives `count` samples and writes their put → callback latencies.
pub fn subscribe(args: &RawArgs) -> anyhow::Result<()> {
    let session = session(args)?;
    let (tx, rx) = mpsc::channel::<u64>();
    let subscriber = session
        .declare_subscriber(KEY)
        .callback(move |sample| {
            let received = now_ns();
            let bytes = sample.payload().to_bytes();
            if let Some(stamp) = bytes
                .get(..8)
                .and_then(|b| <[u8; 8]>::try_from(b).ok())
                .map(u64::from_ne_bytes)
            {
                let _ = tx.send(received.saturating_sub(stamp));
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut latencies = Vec::new();
    let timeout = Duration::from_secs(args.timeout);
    while (latencies.len() as u64) < args.count {
        match rx.recv_timeout(timeout) {
            Ok(ns) => latencies.push(ns),
            Err(_) => anyhow::bail!(
                "{} of {} samples within {timeout:?}",
                latencies.len(),
                args.count
            ),
        }
    }
    drop(subscriber);
    let _ = session.close().wait();
    let path = args.out.clone().context("--out FILE is needed")?;
    let mut file =
        std::fs::File::create(&path).with_context(|| format!("writing {}", path.display()))?;
    for ns in latencies {
        writeln!(file, "{ns}")?;
    }
    Ok(())
}
