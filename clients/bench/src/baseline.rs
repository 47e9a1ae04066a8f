//! Raw-transport baselines: ping-pong between two processes with the payload of a
//! `ChassisState` (its size) over iceoryx2 (event-driven, busy-polling, poll-then-block), a Unix
//! datagram socket and UDP on loopback, one-way from `CLOCK_MONOTONIC` stamps (one clock for the
//! whole machine): both hops of every round trip back to back, or, paced like the service paths'
//! requests, the first hop after each pause only. A loaded receiver ([`Load`]) lives as
//! chassisd's loop does on a robot: another process wakes it at the chassis' feedback rate, a
//! tick of its own too; those wake-ups' own hops are measured, and so are the hops of a sample
//! it publishes after each of them to a reader that lives as a client does (the state's way).

use std::io::{BufRead, BufReader, ErrorKind};
use std::net::UdpSocket;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, anyhow, bail};
use chassis_client::{ChassisState, Ticker, now_ns, wait_listener};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::Builder;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use serde::{Deserialize, Serialize};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::paths::{HYBRID_SPIN, LoopMode};
use crate::placement::{Periods, nanos, pin_current_thread};
use crate::stats::Latencies;

/// The transports compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
pub enum Transport {
    /// iceoryx2 publish-subscribe, the receiver blocked on an event listener.
    IceoryxEvent,
    /// iceoryx2 publish-subscribe, the receiver polling continuously.
    IceoryxSpin,
    /// iceoryx2, the receiver polling for [`HYBRID_SPIN`] after each activity, then blocked on
    /// an event listener (chassisd's `--loop hybrid`).
    IceoryxHybrid,
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
            Transport::IceoryxHybrid => "iceoryx2 poll-then-block",
            Transport::Uds => "unix socket",
            Transport::Udp => "udp loopback",
        }
    }

    /// The transport that waits like a service loop in `mode`.
    pub fn like(mode: LoopMode) -> Self {
        match mode {
            LoopMode::Event => Transport::IceoryxEvent,
            LoopMode::Spin => Transport::IceoryxSpin,
            LoopMode::Hybrid => Transport::IceoryxHybrid,
        }
    }

    fn is_iceoryx(self) -> bool {
        !matches!(self, Transport::Uds | Transport::Udp)
    }
}

/// What the receiving side lives with besides the measured pings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Load {
    /// Wake-ups a second from a third process (the simulated chassis' feedback frames).
    pub feed_per_s: f64,
    /// The receiver's own periodic wake-up (the service's tick).
    pub tick: Duration,
    /// The receiver at SCHED_FIFO at this priority, its memory locked, as chassisd's loop.
    pub realtime: Option<u8>,
    /// The receiver publishes after each wake-up by the feed, to a reader where the ping side
    /// runs: the state rows' hop. Off for the hops into the loop, whose paths have no reader
    /// woken at that rate.
    pub published: bool,
}

impl Load {
    /// `, at SCHED_FIFO P as the service's loop`, or nothing at normal scheduling.
    pub fn fifo_text(&self) -> String {
        let fifo = |p| format!(", at SCHED_FIFO {p} as the service's loop");
        self.realtime.map_or(String::new(), fifo)
    }
}

/// How a baseline run's rounds go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rounds {
    /// Ping-pong back to back: both hops of every round count.
    BackToBack,
    /// One ping a period: only the ping's hop counts, the one after the pause.
    Paced(Duration),
    /// Back to back, each counted ping sent right after a lead ping that wakes the receiver
    /// (and is not answered): what a request meets when it follows another at once, as a
    /// safety stop follows a teleop request.
    AfterWakeUp,
    /// A controller's loop ([`Periods`]): one ping at the start of each period, the answers
    /// looked for without waiting; what counts is each period's start → its ping in the other
    /// process, and the periods the loop missed.
    Loop(Duration),
}

/// Marks a lead ping ([`Rounds::AfterWakeUp`]), which the pong does not answer.
const LEAD: u64 = 1 << 62;
/// The ping that tells the pong to stop.
const LAST: u64 = u64::MAX;

const PADDING: usize = size_of::<ChassisState>() - 24;

/// What travels: the size of a `ChassisState`, with the sender's stamp and the latency the
/// receiver measured for the previous hop.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend, FromBytes, IntoBytes, Immutable, KnownLayout)]
#[type_name("chassis_bench::Ping.v1")]
pub struct Ping {
    pub stamp_ns: u64,
    pub seq: u64,
    pub measured_ns: u64,
    pub padding: [u8; PADDING],
}

fn ping(stamp_ns: u64, seq: u64, measured_ns: u64) -> Ping {
    let padding = [0; PADDING];
    Ping {
        stamp_ns,
        seq,
        measured_ns,
        padding,
    }
}

/// iceoryx2's (and Zenoh's) errors, named.
pub(crate) trait Named<T> {
    fn named(self, what: &str) -> anyhow::Result<T>;
}

impl<T, E: std::fmt::Debug> Named<T> for Result<T, E> {
    fn named(self, what: &str) -> anyhow::Result<T> {
        self.map_err(|e| anyhow!("{what}: {e:?}"))
    }
}

/// The endpoint of one side: send a ping, receive a ping.
trait Endpoint {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()>;
    /// Waits (at most `timeout`) for the next ping; stamps its arrival.
    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>>;

    /// Looks at what has arrived without waiting, as the command path's client looks at its
    /// subscriptions after each pause before it sends; an answer found there is one nobody
    /// waited for.
    fn look(&mut self) -> anyhow::Result<()> {
        Ok(())
    }
}

type Pub = Publisher<ipc::Service, Ping, ()>;
type Sub = Subscriber<ipc::Service, Ping, ()>;
type PubSub = publish_subscribe::PortFactory<ipc::Service, Ping, ()>;

/// iceoryx2 ports on `bench/<tag>/<what>` of one node.
struct Ports {
    node: Node<ipc::Service>,
    tag: String,
}

impl Ports {
    fn new(prefix: &str, tag: &str) -> anyhow::Result<Self> {
        let mut config = Config::default();
        config.global.prefix = FileName::new(prefix.as_bytes()).named("prefix")?;
        let node = NodeBuilder::new().config(&config).create::<ipc::Service>();
        let (node, tag) = (node.named("node")?, tag.to_string());
        Ok(Self { node, tag })
    }

    fn builder(&self, what: &str) -> anyhow::Result<Builder<ipc::Service>> {
        let name = format!("bench/{}/{what}", self.tag);
        let name: ServiceName = name.as_str().try_into().named(&name)?;
        Ok(self.node.service_builder(&name))
    }

    fn pubsub(&self, what: &str) -> anyhow::Result<PubSub> {
        (self.builder(what)?.publish_subscribe::<Ping>())
            .max_publishers(1)
            .max_subscribers(1)
            .history_size(0)
            .subscriber_max_buffer_size(16)
            .enable_safe_overflow(true)
            .open_or_create()
            .named(what)
    }

    fn event(&self, what: &str) -> anyhow::Result<event::PortFactory<ipc::Service>> {
        let event = self.builder(what)?.event().max_notifiers(4);
        event.open_or_create().named(what)
    }

    fn publisher(&self, what: &str) -> anyhow::Result<(Pub, Notifier<ipc::Service>)> {
        let publisher = self.pubsub(what)?.publisher_builder().create();
        let notifier = self.event(what)?.notifier_builder().create();
        Ok((publisher.named(what)?, notifier.named(what)?))
    }

    fn subscriber(&self, what: &str) -> anyhow::Result<(Sub, Listener<ipc::Service>)> {
        let subscriber = self.pubsub(what)?.subscriber_builder().create();
        let listener = self.event(what)?.listener_builder().create();
        Ok((subscriber.named(what)?, listener.named(what)?))
    }
}

struct IceoryxEndpoint {
    publisher: Pub,
    notifier: Notifier<ipc::Service>,
    subscriber: Sub,
    /// The listener the pings' (and the feed's) notifications wake (a pong's WaitSet holds it
    /// too).
    listener: Rc<Listener<ipc::Service>>,
    transport: Transport,
    /// The feed of a loaded receiver: its samples wake the same listener as the pings.
    feed: Option<Sub>,
    /// The feed's one-way latencies, ns.
    feed_ns: Vec<u64>,
    /// The receiver's own tick and when it is next due.
    tick: Option<(Duration, u64)>,
    /// A loaded receiver's own publication, once per wake-up that took the feed's samples, as
    /// chassisd's loop publishes its state after each feedback frame that changed it.
    published: Option<(Pub, Notifier<ipc::Service>)>,
    last_activity: u64,
    _ports: Ports,
}

impl IceoryxEndpoint {
    fn open(spec: &Spec, me: &str, peer: &str) -> anyhow::Result<Self> {
        let ports = Ports::new(&spec.prefix, &spec.tag)?;
        // Only the pong side lives with the load.
        let load = spec.load.filter(|_| me == "pong");
        let (publisher, notifier) = ports.publisher(me)?;
        let (subscriber, listener) = ports.subscriber(peer)?;
        let feed = load.map(|_| ports.pubsub("feed")).transpose()?;
        let feed = feed.map(|f| f.subscriber_builder().create().named("feed"));
        let publishes = load.is_some_and(|l| l.published);
        let published = publishes.then(|| ports.publisher("state"));
        Ok(Self {
            publisher,
            notifier,
            subscriber,
            listener: Rc::new(listener),
            transport: spec.transport,
            feed: feed.transpose()?,
            feed_ns: Vec::new(),
            tick: load.map(|l| (l.tick, now_ns() + nanos(l.tick))),
            published: published.transpose()?,
            last_activity: now_ns(),
            _ports: ports,
        })
    }

    /// Takes the feed's samples and, if there were any, publishes one sample of its own.
    fn drain_feed(&mut self) -> anyhow::Result<bool> {
        let Some(feed) = &self.feed else {
            return Ok(false);
        };
        let mut any = false;
        while let Some(sample) = feed.receive().named("feed receive")? {
            self.feed_ns.push(now_ns().saturating_sub(sample.stamp_ns));
            any = true;
        }
        if let Some((publisher, notifier)) = self.published.as_ref().filter(|_| any) {
            let state = ping(now_ns(), 0, 0);
            publisher.send_copy(state).named("state send")?;
            notifier.notify().named("state notify")?;
        }
        Ok(any)
    }

    /// The next ping (at most `timeout` away), stamped on arrival; between looks, the feed and
    /// the tick are served and, when the receiver blocks, `wait` waits at most the time given
    /// for a notification and takes it.
    fn receive_with(
        &mut self,
        timeout: Duration,
        wait: &mut dyn FnMut(&Listener<ipc::Service>, Duration) -> anyhow::Result<()>,
    ) -> anyhow::Result<Option<(Ping, u64)>> {
        let deadline = now_ns() + nanos(timeout);
        loop {
            if let Some(sample) = self.subscriber.receive().named("receive")? {
                self.last_activity = now_ns();
                return Ok(Some((*sample, self.last_activity)));
            }
            let mut now = now_ns();
            if self.drain_feed()? {
                self.last_activity = now;
            }
            if let Some((period, due)) = self.tick.as_mut()
                && now >= *due
            {
                // The tick's work is the wake-up itself.
                *due += nanos(*period);
                self.last_activity = now;
            }
            now = now_ns();
            if now >= deadline {
                return Ok(None);
            }
            let block = match self.transport {
                Transport::IceoryxSpin => false,
                Transport::IceoryxHybrid => {
                    now.saturating_sub(self.last_activity) >= nanos(HYBRID_SPIN)
                }
                _ => true,
            };
            if block {
                let until = self.tick.map_or(deadline, |(_, due)| due.min(deadline));
                wait(
                    &self.listener,
                    Duration::from_nanos(until.saturating_sub(now)),
                )?;
            }
        }
    }
}

impl Endpoint for IceoryxEndpoint {
    fn look(&mut self) -> anyhow::Result<()> {
        match self.subscriber.receive().named("receive")? {
            Some(sample) => bail!("an answer nobody waited for: ping {}", sample.seq),
            None => Ok(()),
        }
    }

    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.publisher.send_copy(ping).named("send")?;
        if self.transport != Transport::IceoryxSpin {
            self.notifier.notify().named("notify")?;
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        // A signal that interrupts the wait is a wake-up with nothing, as in every client.
        self.receive_with(timeout, &mut |listener, wait| {
            wait_listener(listener, wait).named("wait")
        })
    }
}

/// A datagram socket of the pair.
enum Socket {
    Uds(UnixDatagram, PathBuf),
    Udp(UdpSocket),
}

impl Socket {
    fn open(spec: &Spec, me: &str, peer: &str) -> anyhow::Result<Self> {
        if spec.transport == Transport::Uds {
            let path = |side| spec.dir.join(format!("{}-{side}.sock", spec.tag));
            let _ = std::fs::remove_file(path(me));
            return Ok(Socket::Uds(UnixDatagram::bind(path(me))?, path(peer)));
        }
        // Ports are derived from the tag so both sides know them without talking first.
        let base = 20_000 + (crate::placement::hash(&spec.tag) % 20_000) as u16;
        let (mine, theirs) = if me == "ping" {
            (base, base + 1)
        } else {
            (base + 1, base)
        };
        let socket = UdpSocket::bind(("127.0.0.1", mine))?;
        socket.connect(("127.0.0.1", theirs))?;
        Ok(Socket::Udp(socket))
    }
}

impl Endpoint for Socket {
    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        let bytes = ping.as_bytes().to_vec();
        match self {
            Socket::Uds(socket, peer) => socket.send_to(&bytes, peer)?,
            Socket::Udp(socket) => socket.send(&bytes)?,
        };
        Ok(())
    }

    /// `None` when the read timeout passes first or the datagram is not a ping.
    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        let (mut buf, timeout) = ([0u8; 2048], Some(timeout));
        let received = match self {
            Socket::Uds(s, _) => s.set_read_timeout(timeout).and_then(|()| s.recv(&mut buf)),
            Socket::Udp(s) => s.set_read_timeout(timeout).and_then(|()| s.recv(&mut buf)),
        };
        match received {
            Ok(n) => Ok(Ping::read_from_bytes(&buf[..n]).ok().map(|p| (p, now_ns()))),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => Ok(None),
            Err(e) => Err(e.into()),
        }
    }
}

/// Arguments of the pong and the feed processes (hidden roles of this binary): a [`Spec`].
#[derive(Debug, Clone, clap::Args)]
pub struct PongArgs {
    /// The [`Spec`], JSON.
    #[arg(long, value_parser = |s: &str| serde_json::from_str::<Spec>(s))]
    spec: Spec,
}

/// What a pong or a feed process is to do.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Spec {
    transport: Transport,
    /// Names the run's iceoryx2 services, sockets and files.
    tag: String,
    prefix: String,
    /// The CPU the process is pinned to.
    cpu: Option<usize>,
    /// Scratch directory for Unix socket paths and the feed's figures.
    dir: PathBuf,
    /// The receiver's load: the pong lives with it, the feed makes it.
    load: Option<Load>,
}

impl Spec {
    fn feed_file(&self) -> PathBuf {
        self.dir.join(format!("{}-feed.txt", self.tag))
    }

    /// Starts this binary as `role` with this spec (on `cpu`) and waits until it is ready; the
    /// process and its stdout.
    fn start(
        &self,
        role: &str,
        cpu: Option<usize>,
    ) -> anyhow::Result<(Child, BufReader<ChildStdout>)> {
        let spec = serde_json::to_string(&Spec {
            cpu,
            ..self.clone()
        })?;
        let mut command = Command::new(std::env::current_exe()?);
        command.args(["role", role, "--spec", &spec]);
        let what = format!("the {role} process");
        let mut child = (command.stdout(Stdio::piped()).stderr(Stdio::inherit()))
            .spawn()
            .with_context(|| format!("starting {what}"))?;
        let mut reader = BufReader::new(child.stdout.take().context("no stdout")?);
        let mut line = String::new();
        reader.read_line(&mut line)?;
        if line.trim() != "ready" {
            bail!("{what} did not start: {line:?}");
        }
        Ok((child, reader))
    }
}

/// The feed role: a stamped sample and a wake-up of the receiver's listener `--feed-per-s`
/// times a second, until killed.
pub fn feed(PongArgs { spec }: &PongArgs) -> anyhow::Result<()> {
    if let Some(cpu) = spec.cpu {
        pin_current_thread(cpu)?;
    }
    let rate = spec.load.map_or(0.0, |l| l.feed_per_s);
    if !(rate.is_finite() && rate > 0.0) {
        bail!("feed rate {rate} is not a rate");
    }
    let ports = Ports::new(&spec.prefix, &spec.tag)?;
    let publisher = ports.pubsub("feed")?.publisher_builder().create();
    let publisher = publisher.named("feed publisher")?;
    // The pings' event: the receiver waits on one listener for both, like chassisd's loop.
    let notifier = ports.event("ping")?.notifier_builder().create();
    let notifier = notifier.named("feed notifier")?;
    let mut ticker = Ticker::new(Duration::from_secs_f64(1.0 / rate));
    println!("ready");
    loop {
        ticker.wait();
        publisher
            .send_copy(ping(now_ns(), 0, 0))
            .named("feed send")?;
        notifier.notify().named("feed notify")?;
    }
}

/// The pong role: echo every ping with the one-way latency measured on arrival, until the last
/// one; then a loaded receiver writes its feed's hops.
pub fn pong(PongArgs { spec }: &PongArgs) -> anyhow::Result<()> {
    if let Some(cpu) = spec.cpu {
        pin_current_thread(cpu)?;
    }
    if let Some(priority) = spec.load.and_then(|l| l.realtime) {
        crate::placement::enter_realtime(priority)?;
    }
    if !spec.transport.is_iceoryx() {
        let mut socket = Socket::open(spec, "pong", "ping")?;
        return answer(&mut socket, |s, timeout| s.receive(timeout));
    }
    // An iceoryx2 receiver waits on a WaitSet, as chassisd's loop does, taking the
    // notifications of the listener that fired before reading the samples.
    let mut endpoint = IceoryxEndpoint::open(spec, "pong", "ping")?;
    let waitset = WaitSetBuilder::new().create::<ipc::Service>();
    let waitset = waitset.named("wait set")?;
    let listener = endpoint.listener.clone();
    let guard = waitset.attach_notification(&*listener);
    let _guard = guard.named("attaching the listener")?;
    answer(&mut endpoint, |endpoint, timeout| {
        endpoint.receive_with(timeout, &mut |listener, wait| {
            let progression = |_| CallbackProgression::Continue;
            (waitset.wait_and_process_once_with_timeout(progression, wait)).named("wait set")?;
            let taken = listener.try_wait(|_| {});
            taken.map(drop).named("taking the notifications")
        })
    })?;
    if spec.load.is_some() {
        let text: String = endpoint
            .feed_ns
            .iter()
            .map(|ns| format!("{ns}\n"))
            .collect();
        let path = spec.feed_file();
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    println!("done");
    Ok(())
}

/// Answers pings, each taken by `receive`, until the last one.
fn answer<E: Endpoint>(
    endpoint: &mut E,
    mut receive: impl FnMut(&mut E, Duration) -> anyhow::Result<Option<(Ping, u64)>>,
) -> anyhow::Result<()> {
    println!("ready");
    loop {
        let Some((ping_in, arrived)) = receive(endpoint, Duration::from_secs(5))? else {
            bail!("no ping for 5 s");
        };
        if ping_in.seq == LAST {
            return Ok(());
        }
        if ping_in.seq & LEAD == 0 {
            let measured = arrived.saturating_sub(ping_in.stamp_ns);
            endpoint.send(ping(now_ns(), ping_in.seq, measured))?;
        }
    }
}

/// What a baseline run measured, every hop in ns, in order.
#[derive(Debug)]
pub struct Measured {
    /// The pings' counted hops.
    pub pings: Vec<u64>,
    /// [`Rounds::Loop`]: the periods whose ping went out after the period had ended.
    pub missed_periods: u64,
    /// A loaded receiver's feed hops.
    pub feed: Option<Vec<u64>>,
    /// A loaded iceoryx2 receiver's publication, as its reader took it.
    pub published: Option<Vec<u64>>,
}

impl Measured {
    /// Every ping hop as a distribution.
    pub fn all_pings(&self) -> Latencies {
        last_of(&self.pings, u64::MAX)
    }
}

/// The last `count` of `hops` (all of them when there are fewer): a baseline with as many
/// samples as the path it divides, taken once the receiver had run longest.
pub fn last_of(hops: &[u64], count: u64) -> Latencies {
    let keep = usize::try_from(count).unwrap_or(usize::MAX).min(hops.len());
    let mut latencies = Latencies::new();
    for &ns in &hops[hops.len() - keep..] {
        latencies.record(ns);
    }
    latencies
}

/// Runs `rounds` rounds of `shape` (after a warm-up) and returns the counted one-way latencies.
/// Paced, one ping per period and only the ping's hop: what a request meets when it comes after
/// a pause, as a controller's requests do (the receiver blocked, its CPU maybe idle). With
/// `load` (iceoryx2 only), the receiver also lives with a feed from a third process and a tick
/// of its own, and the feed's hops are measured.
pub fn run(
    transport: Transport,
    (ping_cpu, pong_cpu): (Option<usize>, Option<usize>),
    rounds: u64,
    shape: Rounds,
    load: Option<Load>,
    prefix: &str,
    dir: &Path,
) -> anyhow::Result<Measured> {
    let tag = format!("{}-{}", std::process::id(), crate::placement::unique());
    let (prefix, dir) = (prefix.to_string(), dir.to_path_buf());
    let spec = Spec {
        transport,
        tag,
        prefix,
        cpu: pong_cpu,
        dir,
        load,
    };
    let (mut pong, mut pong_out) = spec.start("pong", pong_cpu)?;
    // The loaded receiver's publication is read where the client reads, before the feed
    // starts it.
    let stop = Arc::new(AtomicBool::new(false));
    let published = (load.is_some_and(|l| l.published) && transport.is_iceoryx())
        .then(|| spawn_reader(&spec, ping_cpu, &stop))
        .transpose()?;
    let feed_at = |load| pong_cpu.map(|c| feed_cpu(c, transport, load));
    let mut feeder = load.map(|l| spec.start("feed", feed_at(l))).transpose()?;
    let result = crate::paths::pinned(ping_cpu, || {
        let mut endpoint: Box<dyn Endpoint> = match transport.is_iceoryx() {
            true => Box::new(IceoryxEndpoint::open(&spec, "ping", "pong")?),
            false => Box::new(Socket::open(&spec, "ping", "pong")?),
        };
        let result = match shape {
            Rounds::Loop(period) => loop_rounds(endpoint.as_mut(), rounds, period),
            _ => ping_rounds(endpoint.as_mut(), transport, rounds, shape).map(|p| (p, 0)),
        };
        // Tells the pong to stop (and to write its feed figures).
        let _ = endpoint.send(ping(0, LAST, 0));
        result
    })?;
    if let Some((feeder, _)) = feeder.as_mut() {
        let _ = feeder.kill();
        let _ = feeder.wait();
    }
    stop.store(true, Ordering::Relaxed);
    let panicked = |_| anyhow!("the state reader panicked");
    let published = published.map(|h| h.join().map_err(panicked)?).transpose()?;
    let (pings, missed_periods) = result?;
    // The pong writes its feed figures before it says "done".
    let _ = pong_out.read_line(&mut String::new());
    let _ = pong.wait();
    let feed = load.map(|_| -> anyhow::Result<Vec<u64>> {
        let path = spec.feed_file();
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        Ok(text.lines().filter_map(|l| l.parse().ok()).collect())
    });
    let feed = feed.transpose()?;
    Ok(Measured {
        pings,
        missed_periods,
        feed,
        published,
    })
}

/// Starts the reader of a loaded receiver's publication on `cpu`, at normal scheduling, and
/// returns once it is subscribed: it reads as the benchmark's state reader does, every hop
/// until `stop`, ns: the notifications pending are spent before each drain, and it waits (at
/// most 20 ms, to look at `stop`) only when a drain took nothing, as `StateStream::wait` does;
/// polling in a busy-poll run.
fn spawn_reader(
    spec: &Spec,
    cpu: Option<usize>,
    stop: &Arc<AtomicBool>,
) -> anyhow::Result<JoinHandle<anyhow::Result<Vec<u64>>>> {
    let (prefix, tag, stop) = (spec.prefix.clone(), spec.tag.clone(), stop.clone());
    let spin = spec.transport == Transport::IceoryxSpin;
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let open = move || -> anyhow::Result<_> {
        if let Some(cpu) = cpu {
            pin_current_thread(cpu)?;
        }
        let ports = Ports::new(&prefix, &tag)?;
        let (subscriber, listener) = ports.subscriber("state")?;
        Ok((ports, subscriber, listener))
    };
    let reader = move || {
        // iceoryx2's ports stay on the thread that opens them. An error opening them is the
        // spawner's to report; the thread then has read nothing.
        let (_ports, subscriber, listener) = match open() {
            Ok(opened) => opened,
            Err(e) => {
                let _ = ready_tx.send(Err(e));
                return Ok(Vec::new());
            }
        };
        let _ = ready_tx.send(Ok(()));
        let mut hops = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            if !spin {
                let taken = listener.try_wait(|_| {});
                taken.named("taking the state's notifications")?;
            }
            let before = hops.len();
            while let Some(sample) = subscriber.receive().named("state receive")? {
                hops.push(now_ns().saturating_sub(sample.stamp_ns));
            }
            if hops.len() == before && !spin {
                wait_listener(&listener, Duration::from_millis(20)).named("waiting for state")?;
            }
        }
        Ok(hops)
    };
    let thread = std::thread::Builder::new().name("state-reader".into());
    let handle = thread.spawn(reader).context("starting the state reader")?;
    let stopped = || anyhow!("the state reader stopped before it subscribed");
    ready_rx.recv().map_err(|_| stopped())??;
    Ok(handle)
}

/// Where the feed of a receiver pinned to `pong_cpu` runs: where chassisd places its simulated
/// chassis (`realtime::sim_cpus`). On the receiver's CPU when the receiver blocks at SCHED_FIFO
/// (the chassis runs only while the loop waits); otherwise on another CPU, the ping side's in a
/// cross-CPU run.
fn feed_cpu(pong_cpu: usize, transport: Transport, load: Load) -> usize {
    if load.realtime.is_some() && transport != Transport::IceoryxSpin {
        return pong_cpu;
    }
    (pong_cpu + 1) % crate::placement::cpu_count()
}

/// The counted hops, ns (a hop whose clocks disagree, the answer stamped before the ping, is
/// recorded as 0 ns: it stays counted and shows at the bottom of the distribution).
fn ping_rounds(
    endpoint: &mut dyn Endpoint,
    transport: Transport,
    rounds: u64,
    shape: Rounds,
) -> anyhow::Result<Vec<u64>> {
    let mut latencies = Vec::new();
    let (warmup, mut ticker) = match shape {
        Rounds::Paced(period) => (20, Some(Ticker::new(period))),
        Rounds::BackToBack | Rounds::AfterWakeUp | Rounds::Loop(_) => (200, None),
    };
    let label = transport.label();
    for seq in 0..warmup + rounds {
        if let Some(ticker) = ticker.as_mut() {
            ticker.wait();
            endpoint.look()?;
        }
        if shape == Rounds::AfterWakeUp {
            endpoint.send(ping(now_ns(), seq | LEAD, 0))?;
        }
        endpoint.send(ping(now_ns(), seq, 0))?;
        let Some((pong, arrived)) = endpoint.receive(Duration::from_secs(2))? else {
            bail!("{label}: no answer to ping {seq}");
        };
        if pong.seq != seq {
            bail!("{label}: ping {seq} answered as {}", pong.seq);
        }
        if seq >= warmup {
            latencies.push(pong.measured_ns);
            // Otherwise only the ping's hop counts: the answer finds both ends awake.
            if shape == Rounds::BackToBack {
                latencies.push(arrived.saturating_sub(pong.stamp_ns));
            }
        }
    }
    Ok(latencies)
}

/// [`Rounds::Loop`]: `rounds` periods (after 200 of warm-up) of a loop that sends a ping at the
/// start of each and looks for the answers without waiting. Each counted hop: the period's
/// start → its ping in the pong process; and the counted periods missed.
fn loop_rounds(
    endpoint: &mut dyn Endpoint,
    rounds: u64,
    period: Duration,
) -> anyhow::Result<(Vec<u64>, u64)> {
    const WARMUP: u64 = 200;
    let mut periods = Periods::new(period);
    // Each ping's period start and send stamp.
    let mut started: Vec<(u64, u64)> = Vec::new();
    let mut hops = Vec::new();
    // Takes one answer, if there is one within `timeout`: its hop, counted past the warm-up.
    let take =
        |endpoint: &mut dyn Endpoint, timeout, started: &[(u64, u64)], hops: &mut Vec<u64>| {
            let answer = endpoint.receive(timeout)?;
            if let Some((pong, _)) = answer
                && pong.seq >= WARMUP
                && let Some(&(start, sent)) =
                    usize::try_from(pong.seq).ok().and_then(|i| started.get(i))
            {
                hops.push((sent + pong.measured_ns).saturating_sub(start));
            }
            anyhow::Ok(answer.is_some())
        };
    for seq in 0..WARMUP + rounds {
        let start = periods.next();
        while take(endpoint, Duration::ZERO, &started, &mut hops)? {}
        let sent = now_ns();
        started.push((start, sent));
        endpoint.send(ping(sent, seq, 0))?;
        periods.end(start, seq >= WARMUP);
    }
    // An answer 2 s late is lost: a receiver descheduled longer than its buffer of pings lasts.
    while (hops.len() as u64) < rounds
        && take(endpoint, Duration::from_secs(2), &started, &mut hops)?
    {}
    Ok((hops, periods.misses))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The feed sits where chassisd puts its simulated chassis: beside a receiver that blocks at
    /// SCHED_FIFO, on the other CPU beside any other.
    #[test]
    fn the_feed_runs_where_the_simulated_chassis_would() {
        let load = |realtime| Load {
            feed_per_s: 500.0,
            tick: Duration::from_millis(20),
            realtime,
            published: false,
        };
        let other = if crate::placement::cpu_count() > 1 {
            1
        } else {
            0
        };
        for transport in [Transport::IceoryxEvent, Transport::IceoryxHybrid] {
            assert_eq!(feed_cpu(0, transport, load(Some(80))), 0);
            assert_eq!(feed_cpu(0, transport, load(None)), other);
        }
        assert_eq!(feed_cpu(0, Transport::IceoryxSpin, load(None)), other);
    }
}
