//! Raw-transport baselines: ping-pong between two processes with the payload of a
//! `ChassisState` (840 bytes) over iceoryx2 (event-driven and busy-polling), a Unix datagram
//! socket and UDP on loopback. One-way latency comes from `CLOCK_MONOTONIC` stamps (one clock for
//! the whole machine), in both directions of every round trip — or, paced like the service paths'
//! requests, the first hop after each pause only.

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::os::unix::net::UnixDatagram;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{ChassisState, now_ns};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::placement::{Placement, pin_current_thread};
use crate::stats::Latencies;

/// The transports compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Transport {
    /// iceoryx2 publish-subscribe, the receiver blocked on an event listener.
    IceoryxEvent,
    /// iceoryx2 publish-subscribe, the receiver polling continuously.
    IceoryxSpin,
    /// A Unix datagram socket, blocking receive.
    Uds,
    /// UDP on 127.0.0.1, blocking receive.
    Udp,
}

impl Transport {
    pub fn label(self) -> &'static str {
        match self {
            Transport::IceoryxEvent => "iceoryx2 event",
            Transport::IceoryxSpin => "iceoryx2 busy-poll",
            Transport::Uds => "unix socket",
            Transport::Udp => "udp loopback",
        }
    }
}

/// What travels: the size of a `ChassisState`, with the sender's stamp and the latency the
/// receiver measured for the previous hop.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("chassis_bench::Ping.v1")]
pub struct Ping {
    pub stamp_ns: u64,
    pub seq: u64,
    pub measured_ns: u64,
    pub padding: [u8; size_of::<ChassisState>() - 24],
}

impl Default for Ping {
    fn default() -> Self {
        Self {
            stamp_ns: 0,
            seq: 0,
            measured_ns: 0,
            padding: [0; size_of::<ChassisState>() - 24],
        }
    }
}

impl Ping {
    fn to_bytes(self) -> Vec<u8> {
        let mut out = vec![0u8; size_of::<Ping>()];
        out[..8].copy_from_slice(&self.stamp_ns.to_le_bytes());
        out[8..16].copy_from_slice(&self.seq.to_le_bytes());
        out[16..24].copy_from_slice(&self.measured_ns.to_le_bytes());
        out
    }

    fn from_bytes(b: &[u8]) -> Option<Self> {
        let word = |i: usize| Some(u64::from_le_bytes(b.get(i..i + 8)?.try_into().ok()?));
        Some(Self {
            stamp_ns: word(0)?,
            seq: word(8)?,
            measured_ns: word(16)?,
            ..Self::default()
        })
    }
}

/// The endpoint of one side: send a ping, receive a ping.
trait Endpoint {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()>;
    /// Waits (at most `timeout`) for the next ping; stamps its arrival.
    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>>;
}

struct IceoryxEndpoint {
    publisher: Publisher<ipc::Service, Ping, ()>,
    subscriber: Subscriber<ipc::Service, Ping, ()>,
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    spin: bool,
    _node: Node<ipc::Service>,
}

fn service(name: &str) -> anyhow::Result<ServiceName> {
    name.try_into()
        .map_err(|e| anyhow::anyhow!("service name {name}: {e:?}"))
}

impl IceoryxEndpoint {
    fn open(prefix: &str, tag: &str, me: &str, peer: &str, spin: bool) -> anyhow::Result<Self> {
        let mut config = Config::default();
        config.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(|e| anyhow::anyhow!("prefix: {e:?}"))?;
        let node = NodeBuilder::new()
            .config(&config)
            .create::<ipc::Service>()
            .map_err(|e| anyhow::anyhow!("node: {e:?}"))?;
        let pubsub = |name: &str| {
            node.service_builder(&service(name)?)
                .publish_subscribe::<Ping>()
                .max_publishers(1)
                .max_subscribers(1)
                .history_size(0)
                .subscriber_max_buffer_size(4)
                .enable_safe_overflow(true)
                .open_or_create()
                .map_err(|e| anyhow::anyhow!("{name}: {e:?}"))
        };
        let event = |name: &str| {
            node.service_builder(&service(name)?)
                .event()
                .open_or_create()
                .map_err(|e| anyhow::anyhow!("{name} event: {e:?}"))
        };
        let mine = format!("bench/{tag}/{me}");
        let theirs = format!("bench/{tag}/{peer}");
        Ok(Self {
            publisher: pubsub(&mine)?
                .publisher_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("publisher: {e:?}"))?,
            subscriber: pubsub(&theirs)?
                .subscriber_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("subscriber: {e:?}"))?,
            notifier: event(&mine)?
                .notifier_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("notifier: {e:?}"))?,
            listener: event(&theirs)?
                .listener_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("listener: {e:?}"))?,
            spin,
            _node: node,
        })
    }
}

impl Endpoint for IceoryxEndpoint {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.publisher
            .send_copy(ping)
            .map_err(|e| anyhow::anyhow!("send: {e:?}"))?;
        if !self.spin {
            self.notifier
                .notify()
                .map_err(|e| anyhow::anyhow!("notify: {e:?}"))?;
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        let deadline = now_ns() + u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX / 2);
        loop {
            if let Some(sample) = self
                .subscriber
                .receive()
                .map_err(|e| anyhow::anyhow!("receive: {e:?}"))?
            {
                let at = now_ns();
                return Ok(Some((*sample, at)));
            }
            let now = now_ns();
            if now >= deadline {
                return Ok(None);
            }
            if !self.spin {
                self.listener
                    .timed_wait(|_| {}, Duration::from_nanos(deadline - now))
                    .map_err(|e| anyhow::anyhow!("wait: {e:?}"))?;
            }
        }
    }
}

struct UdsEndpoint {
    socket: UnixDatagram,
    peer: std::path::PathBuf,
}

impl Endpoint for UdsEndpoint {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.socket.send_to(&ping.to_bytes(), &self.peer)?;
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        self.socket.set_read_timeout(Some(timeout))?;
        let mut buf = vec![0u8; 2048];
        match self.socket.recv(&mut buf) {
            Ok(n) => Ok(Ping::from_bytes(&buf[..n]).map(|p| (p, now_ns()))),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e.into()),
        }
    }
}

struct UdpEndpoint {
    socket: UdpSocket,
}

impl Endpoint for UdpEndpoint {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.socket.send(&ping.to_bytes())?;
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        self.socket.set_read_timeout(Some(timeout))?;
        let mut buf = vec![0u8; 2048];
        match self.socket.recv(&mut buf) {
            Ok(n) => Ok(Ping::from_bytes(&buf[..n]).map(|p| (p, now_ns()))),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e.into()),
        }
    }
}

/// Arguments of the pong process (a hidden role of this binary).
#[derive(Debug, Clone, clap::Args)]
pub struct PongArgs {
    #[arg(long, value_enum)]
    pub transport: Transport,
    #[arg(long)]
    pub tag: String,
    #[arg(long)]
    pub prefix: String,
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Scratch directory for Unix socket paths.
    #[arg(long)]
    pub dir: std::path::PathBuf,
}

fn open_endpoint(args: &PongArgs, me: &str, peer: &str) -> anyhow::Result<Box<dyn Endpoint>> {
    Ok(match args.transport {
        Transport::IceoryxEvent | Transport::IceoryxSpin => Box::new(IceoryxEndpoint::open(
            &args.prefix,
            &args.tag,
            me,
            peer,
            args.transport == Transport::IceoryxSpin,
        )?),
        Transport::Uds => {
            let mine = args.dir.join(format!("{}-{me}.sock", args.tag));
            let _ = std::fs::remove_file(&mine);
            Box::new(UdsEndpoint {
                socket: UnixDatagram::bind(&mine)?,
                peer: args.dir.join(format!("{}-{peer}.sock", args.tag)),
            })
        }
        Transport::Udp => {
            // Ports are derived from the tag so both sides know them without talking first.
            let base = 20_000 + (crate::placement::hash(&args.tag) % 20_000) as u16;
            let (mine, theirs) = if me == "ping" {
                (base, base + 1)
            } else {
                (base + 1, base)
            };
            let socket = UdpSocket::bind(("127.0.0.1", mine))?;
            socket.connect(("127.0.0.1", theirs))?;
            Box::new(UdpEndpoint { socket })
        }
    })
}

/// The pong role: echo every ping with the one-way latency measured on arrival.
pub fn pong(args: &PongArgs) -> anyhow::Result<()> {
    if let Some(cpu) = args.cpu {
        pin_current_thread(cpu)?;
    }
    let mut endpoint = open_endpoint(args, "pong", "ping")?;
    println!("ready");
    loop {
        match endpoint.receive(Duration::from_secs(5))? {
            Some((ping, arrived)) => {
                if ping.seq == u64::MAX {
                    return Ok(());
                }
                endpoint.send(Ping {
                    stamp_ns: now_ns(),
                    seq: ping.seq,
                    measured_ns: arrived.saturating_sub(ping.stamp_ns),
                    ..Ping::default()
                })?;
            }
            None => bail!("no ping for 5 s"),
        }
    }
}

fn wait_ready(child: &mut Child) -> anyhow::Result<BufReader<ChildStdout>> {
    let stdout = child.stdout.take().context("pong has no stdout")?;
    let mut reader = BufReader::new(stdout);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    if line.trim() != "ready" {
        bail!("pong did not start: {line:?}");
    }
    Ok(reader)
}

/// Runs `rounds` ping-pongs (after a warm-up) and returns the one-way latencies of both
/// directions — back to back, or, with `pace`, one ping per period and only the ping's hop: what
/// a request meets when it comes after a pause, as a controller's requests do (the receiver is
/// blocked and its CPU may be idle).
pub fn run(
    transport: Transport,
    placement: Placement,
    rounds: u64,
    pace: Option<Duration>,
    prefix: &str,
    dir: &std::path::Path,
) -> anyhow::Result<Latencies> {
    let tag = format!("{}-{}", std::process::id(), crate::placement::unique());
    let (ping_cpu, pong_cpu) = placement.cpus();
    let args = PongArgs {
        transport,
        tag: tag.clone(),
        prefix: prefix.to_string(),
        cpu: pong_cpu,
        dir: dir.to_path_buf(),
    };
    let exe = std::env::current_exe()?;
    let mut command = Command::new(exe);
    command
        .args(["role", "pong", "--transport"])
        .arg(
            clap::ValueEnum::to_possible_value(&transport)
                .map(|v| v.get_name().to_string())
                .unwrap_or_default(),
        )
        .args(["--tag", &tag, "--prefix", prefix, "--dir"])
        .arg(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    if let Some(cpu) = pong_cpu {
        command.args(["--cpu", &cpu.to_string()]);
    }
    let mut child = command.spawn().context("starting the pong process")?;
    let _reader = wait_ready(&mut child)?;
    if let Some(cpu) = ping_cpu {
        pin_current_thread(cpu)?;
    }
    let mut endpoint = open_endpoint(&args, "ping", "pong")?;
    let mut latencies = Latencies::new();
    let warmup = if pace.is_some() { 20 } else { 200 };
    let mut ticker = pace.map(chassis_client::Ticker::new);
    for seq in 0..warmup + rounds {
        if let Some(ticker) = ticker.as_mut() {
            ticker.wait();
        }
        let sent = now_ns();
        endpoint.send(Ping {
            stamp_ns: sent,
            seq,
            ..Ping::default()
        })?;
        let Some((pong, arrived)) = endpoint.receive(Duration::from_secs(2))? else {
            bail!("{}: no answer to ping {seq}", transport.label());
        };
        if seq >= warmup {
            latencies.record(pong.measured_ns);
            // Paced, only the hop after the pause counts: the answer finds both ends awake.
            if pace.is_none() {
                latencies.record_between(pong.stamp_ns, arrived);
            }
        }
    }
    let _ = endpoint.send(Ping {
        seq: u64::MAX,
        ..Ping::default()
    });
    crate::placement::unpin_current_thread();
    let _ = child.wait();
    Ok(latencies)
}
