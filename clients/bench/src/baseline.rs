//! Raw-transport baselines: ping-pong between two processes with the payload of
//! a `ChassisState` (its size) over iceoryx2 (event-driven and busy-polling), a Unix datagram
//! socket and UDP on loopback. One-way latency comes from `CLOCK_MONOTONIC` stamps (one clock for
//! the whole machine), in both directions of every round trip — or, paced like the service paths'
//! requests, the first hop after each pause only. A paced run can give the receiving side the
//! life chassisd's loop has on a robot ([`Load`]): another process waking it at the chassis'
//! feedback rate, and a periodic tick of its own; those wake-ups' own hops are measured too, and
//! so are the hops of a sample the receiver publishes after each of them to a reader that lives
//! as a client does (the state's way: from the loop to a client).

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::os::unix::net::UnixDatagram;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::{ChassisState, now_ns, wait_listener};
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
    /// iceoryx2 publish-subscribe, the receiver polling for [`HYBRID_SPIN`] after each
    /// activity, then blocked on an event listener (chassisd's `--loop hybrid`).
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
}

/// How long a hybrid receiver keeps polling after each activity: chassisd's `--spin-us` in the
/// benchmark's hybrid runs, and the poll-then-block baseline's window.
pub const HYBRID_SPIN: Duration = Duration::from_micros(200);

/// What the receiving side lives with besides the measured pings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    /// Wake-ups a second from a third process (the simulated chassis' feedback frames).
    pub feed_per_s: f64,
    /// The receiver's own periodic wake-up (the service's tick).
    pub tick: Duration,
    /// The receiver at SCHED_FIFO at this priority, its memory locked: as chassisd's loop in
    /// real-time mode.
    pub realtime: Option<u8>,
    /// The receiver publishes after each wake-up by the feed, to a reader where the ping side
    /// runs ([`Published`]): the state rows' hop. Off for the hops into the loop, whose paths
    /// have no reader woken at that rate.
    pub published: bool,
}

/// How a baseline run's rounds go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rounds {
    /// Ping-pong back to back: both hops of every round count.
    BackToBack,
    /// One ping a period: only the ping's hop counts, the one after the pause.
    Paced(Duration),
    /// Back to back, each counted ping sent right after a lead ping that wakes the receiver
    /// (and is not answered): only the counted ping's hop counts. What a request meets when it
    /// follows another at once, as a safety stop follows a teleop request.
    AfterWakeUp,
    /// A controller's loop ([`crate::periods::Periods`]): one ping at the start of each
    /// period, the answers looked for without waiting; what counts is each period's start →
    /// its ping in the other process, and the periods the loop missed.
    Loop(Duration),
}

/// Marks a lead ping ([`Rounds::AfterWakeUp`]), which the pong does not answer.
const LEAD: u64 = 1 << 62;

/// What the transport waits like.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Waiting {
    Block,
    Spin,
    /// Poll for this long after each activity, then block.
    Hybrid(Duration),
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
    /// The one-way latencies of a loaded receiver's feed so far, ns.
    fn feed_latencies(&self) -> &[u64] {
        &[]
    }

    /// Looks at what has arrived without waiting, as the command path's client looks at its
    /// subscriptions (the frame tap, the mux's status) after each pause before it sends; an
    /// answer found there is one nobody waited for.
    fn look(&mut self) -> anyhow::Result<()> {
        Ok(())
    }
}

struct IceoryxEndpoint {
    publisher: Publisher<ipc::Service, Ping, ()>,
    subscriber: Subscriber<ipc::Service, Ping, ()>,
    notifier: Notifier<ipc::Service>,
    /// The listener the pings' (and the feed's) notifications wake; taken out by a receiver
    /// that waits on a WaitSet ([`WaitSetEndpoint`]).
    listener: Option<Listener<ipc::Service>>,
    waiting: Waiting,
    /// The feed of a loaded receiver: its samples wake the same listener as the pings.
    feed: Option<Subscriber<ipc::Service, Ping, ()>>,
    /// The feed's one-way latencies, ns.
    feed_ns: Vec<u64>,
    /// The receiver's own tick and when it is next due.
    tick: Option<(Duration, u64)>,
    /// A loaded receiver's own publication, as chassisd's state.
    published: Option<Published>,
    last_activity: u64,
    _node: Node<ipc::Service>,
}

/// What a loaded receiver publishes once per wake-up that took the feed's samples (one feed
/// sample, at the feed's pace), as chassisd's loop publishes its state after each feedback
/// frame that changed it: the hop a state reader meets, sent by a process that lives as the
/// loop does ([`read_published`] reads it).
struct Published {
    publisher: Publisher<ipc::Service, Ping, ()>,
    notifier: Notifier<ipc::Service>,
    seq: u64,
}

/// The service of a loaded receiver's publication.
fn published_service(tag: &str) -> String {
    format!("bench/{tag}/state")
}

fn service(name: &str) -> anyhow::Result<ServiceName> {
    name.try_into()
        .map_err(|e| anyhow::anyhow!("service name {name}: {e:?}"))
}

fn node(prefix: &str) -> anyhow::Result<Node<ipc::Service>> {
    let mut config = Config::default();
    config.global.prefix =
        FileName::new(prefix.as_bytes()).map_err(|e| anyhow::anyhow!("prefix: {e:?}"))?;
    NodeBuilder::new()
        .config(&config)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("node: {e:?}"))
}

fn pubsub(
    node: &Node<ipc::Service>,
    name: &str,
) -> anyhow::Result<
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, Ping, ()>,
> {
    node.service_builder(&service(name)?)
        .publish_subscribe::<Ping>()
        .max_publishers(1)
        .max_subscribers(1)
        .history_size(0)
        .subscriber_max_buffer_size(16)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| anyhow::anyhow!("{name}: {e:?}"))
}

fn event(
    node: &Node<ipc::Service>,
    name: &str,
) -> anyhow::Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>> {
    node.service_builder(&service(name)?)
        .event()
        .max_notifiers(4)
        .open_or_create()
        .map_err(|e| anyhow::anyhow!("{name} event: {e:?}"))
}

impl IceoryxEndpoint {
    fn open(
        prefix: &str,
        tag: &str,
        me: &str,
        peer: &str,
        waiting: Waiting,
        load: Option<Load>,
    ) -> anyhow::Result<Self> {
        let node = node(prefix)?;
        let mine = format!("bench/{tag}/{me}");
        let theirs = format!("bench/{tag}/{peer}");
        let feed = match load {
            Some(_) => Some(
                pubsub(&node, &format!("bench/{tag}/feed"))?
                    .subscriber_builder()
                    .create()
                    .map_err(|e| anyhow::anyhow!("feed subscriber: {e:?}"))?,
            ),
            None => None,
        };
        Ok(Self {
            publisher: pubsub(&node, &mine)?
                .publisher_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("publisher: {e:?}"))?,
            subscriber: pubsub(&node, &theirs)?
                .subscriber_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("subscriber: {e:?}"))?,
            notifier: event(&node, &mine)?
                .notifier_builder()
                .create()
                .map_err(|e| anyhow::anyhow!("notifier: {e:?}"))?,
            listener: Some(
                event(&node, &theirs)?
                    .listener_builder()
                    .create()
                    .map_err(|e| anyhow::anyhow!("listener: {e:?}"))?,
            ),
            waiting,
            feed,
            feed_ns: Vec::new(),
            tick: load.map(|l| (l.tick, now_ns() + nanos(l.tick))),
            published: match load {
                Some(Load {
                    published: true, ..
                }) => Some(Published {
                    publisher: pubsub(&node, &published_service(tag))?
                        .publisher_builder()
                        .create()
                        .map_err(|e| anyhow::anyhow!("state publisher: {e:?}"))?,
                    notifier: event(&node, &published_service(tag))?
                        .notifier_builder()
                        .create()
                        .map_err(|e| anyhow::anyhow!("state notifier: {e:?}"))?,
                    seq: 0,
                }),
                _ => None,
            },
            last_activity: now_ns(),
            _node: node,
        })
    }

    /// Takes the feed's samples; true if there were any.
    fn drain_feed(&mut self) -> anyhow::Result<bool> {
        let Some(feed) = &self.feed else {
            return Ok(false);
        };
        let mut any = false;
        while let Some(sample) = feed
            .receive()
            .map_err(|e| anyhow::anyhow!("feed receive: {e:?}"))?
        {
            self.feed_ns.push(now_ns().saturating_sub(sample.stamp_ns));
            any = true;
        }
        Ok(any)
    }

    /// Publishes one stamped sample of the receiver's own publication, if it has one.
    fn publish(&mut self) -> anyhow::Result<()> {
        let Some(published) = self.published.as_mut() else {
            return Ok(());
        };
        published.seq += 1;
        published
            .publisher
            .send_copy(Ping {
                stamp_ns: now_ns(),
                seq: published.seq,
                ..Ping::default()
            })
            .map_err(|e| anyhow::anyhow!("state send: {e:?}"))?;
        published
            .notifier
            .notify()
            .map_err(|e| anyhow::anyhow!("state notify: {e:?}"))?;
        Ok(())
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX / 2)
}

impl Endpoint for IceoryxEndpoint {
    fn feed_latencies(&self) -> &[u64] {
        &self.feed_ns
    }

    fn look(&mut self) -> anyhow::Result<()> {
        match self
            .subscriber
            .receive()
            .map_err(|e| anyhow::anyhow!("receive: {e:?}"))?
        {
            Some(sample) => bail!("an answer nobody waited for: ping {}", sample.seq),
            None => Ok(()),
        }
    }

    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.publisher
            .send_copy(ping)
            .map_err(|e| anyhow::anyhow!("send: {e:?}"))?;
        if self.waiting != Waiting::Spin {
            self.notifier
                .notify()
                .map_err(|e| anyhow::anyhow!("notify: {e:?}"))?;
        }
        Ok(())
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        let listener = self
            .listener
            .take()
            .context("the listener is waited on by a WaitSet")?;
        // A signal that interrupts the wait is a wake-up with nothing, as in every client.
        let result = self.receive_with(timeout, &mut |wait| {
            wait_listener(&listener, wait).map_err(|e| anyhow::anyhow!("wait: {e:?}"))
        });
        self.listener = Some(listener);
        result
    }
}

impl IceoryxEndpoint {
    /// The next ping (at most `timeout` away), stamped on arrival; between looks, the feed and
    /// the tick are served and, when the receiver blocks, `wait` waits at most the time given
    /// for a notification and takes it.
    fn receive_with(
        &mut self,
        timeout: Duration,
        wait: &mut dyn FnMut(Duration) -> anyhow::Result<()>,
    ) -> anyhow::Result<Option<(Ping, u64)>> {
        let deadline = now_ns() + nanos(timeout);
        loop {
            if let Some(sample) = self
                .subscriber
                .receive()
                .map_err(|e| anyhow::anyhow!("receive: {e:?}"))?
            {
                let at = now_ns();
                self.last_activity = at;
                return Ok(Some((*sample, at)));
            }
            let mut now = now_ns();
            if self.drain_feed()? {
                self.last_activity = now;
                self.publish()?;
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
            let block = match self.waiting {
                Waiting::Spin => false,
                Waiting::Block => true,
                Waiting::Hybrid(window) => now.saturating_sub(self.last_activity) >= nanos(window),
            };
            if block {
                let until = self.tick.map_or(deadline, |(_, due)| due.min(deadline));
                wait(Duration::from_nanos(until.saturating_sub(now)))?;
            }
        }
    }
}

/// A receiver that waits as chassisd's loop does: on a WaitSet the listener is attached to,
/// taking the notifications of the listener that fired before reading the samples.
struct WaitSetEndpoint<'a> {
    inner: IceoryxEndpoint,
    waitset: &'a WaitSet<ipc::Service>,
    listener: &'a Listener<ipc::Service>,
}

impl Endpoint for WaitSetEndpoint<'_> {
    fn feed_latencies(&self) -> &[u64] {
        self.inner.feed_latencies()
    }

    fn send(&mut self, ping: Ping) -> anyhow::Result<()> {
        self.inner.send(ping)
    }

    fn receive(&mut self, timeout: Duration) -> anyhow::Result<Option<(Ping, u64)>> {
        let (waitset, listener) = (self.waitset, self.listener);
        self.inner.receive_with(timeout, &mut |wait| {
            waitset
                .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, wait)
                .map_err(|e| anyhow::anyhow!("wait set: {e:?}"))?;
            listener
                .try_wait(|_| {})
                .map(drop)
                .map_err(|e| anyhow::anyhow!("taking the notifications: {e:?}"))
        })
    }
}

/// The ping `recv` reads into a buffer, stamped on arrival; `None` when the socket's read timeout
/// passes first or the datagram is not a ping.
fn datagram(
    recv: impl FnOnce(&mut [u8]) -> std::io::Result<usize>,
) -> anyhow::Result<Option<(Ping, u64)>> {
    let mut buf = vec![0u8; 2048];
    match recv(&mut buf) {
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
        datagram(|buf| self.socket.recv(buf))
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
        datagram(|buf| self.socket.recv(buf))
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
    /// A loaded receiver: the feed's rate a second (another process wakes it).
    #[arg(long)]
    pub feed_per_s: Option<f64>,
    /// A loaded receiver: its own tick, µs.
    #[arg(long)]
    pub tick_us: Option<u64>,
    /// A loaded receiver: at SCHED_FIFO with this priority, its memory locked.
    #[arg(long)]
    pub realtime: Option<u8>,
    /// A loaded receiver: it publishes after each wake-up by the feed ([`Load::published`]).
    #[arg(long)]
    pub publish: bool,
}

impl PongArgs {
    fn load(&self) -> Option<Load> {
        Some(Load {
            feed_per_s: self.feed_per_s?,
            tick: Duration::from_micros(self.tick_us?),
            realtime: self.realtime,
            published: self.publish,
        })
    }

    fn feed_file(&self) -> std::path::PathBuf {
        self.dir.join(format!("{}-feed.txt", self.tag))
    }
}

/// Arguments of the feed process: another process waking a loaded receiver.
#[derive(Debug, Clone, clap::Args)]
pub struct FeedArgs {
    #[arg(long)]
    pub tag: String,
    #[arg(long)]
    pub prefix: String,
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Samples a second.
    #[arg(long)]
    pub rate: f64,
}

/// The feed role: a stamped sample and a wake-up of the receiver's listener `rate` times a
/// second, until killed.
pub fn feed(args: &FeedArgs) -> anyhow::Result<()> {
    if let Some(cpu) = args.cpu {
        pin_current_thread(cpu)?;
    }
    if !(args.rate.is_finite() && args.rate > 0.0) {
        bail!("feed rate {} is not a rate", args.rate);
    }
    let node = node(&args.prefix)?;
    let publisher = pubsub(&node, &format!("bench/{}/feed", args.tag))?
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("feed publisher: {e:?}"))?;
    // The pings' event: the receiver waits on one listener for both, like chassisd's loop.
    let notifier = event(&node, &format!("bench/{}/ping", args.tag))?
        .notifier_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("feed notifier: {e:?}"))?;
    let mut ticker = chassis_client::Ticker::new(Duration::from_secs_f64(1.0 / args.rate));
    println!("ready");
    loop {
        ticker.wait();
        publisher
            .send_copy(Ping {
                stamp_ns: now_ns(),
                ..Ping::default()
            })
            .map_err(|e| anyhow::anyhow!("feed send: {e:?}"))?;
        notifier
            .notify()
            .map_err(|e| anyhow::anyhow!("feed notify: {e:?}"))?;
    }
}

/// How an iceoryx2 transport's receiver waits; None for the socket transports.
fn iceoryx_waiting(transport: Transport) -> Option<Waiting> {
    match transport {
        Transport::IceoryxEvent => Some(Waiting::Block),
        Transport::IceoryxSpin => Some(Waiting::Spin),
        Transport::IceoryxHybrid => Some(Waiting::Hybrid(HYBRID_SPIN)),
        Transport::Uds | Transport::Udp => None,
    }
}

fn open_iceoryx(
    args: &PongArgs,
    me: &str,
    peer: &str,
    waiting: Waiting,
) -> anyhow::Result<IceoryxEndpoint> {
    // Only the pong side lives with the load.
    let load = if me == "pong" { args.load() } else { None };
    IceoryxEndpoint::open(&args.prefix, &args.tag, me, peer, waiting, load)
}

fn open_endpoint(args: &PongArgs, me: &str, peer: &str) -> anyhow::Result<Box<dyn Endpoint>> {
    Ok(match args.transport {
        Transport::IceoryxEvent | Transport::IceoryxSpin | Transport::IceoryxHybrid => {
            let waiting = iceoryx_waiting(args.transport).unwrap_or(Waiting::Block);
            Box::new(open_iceoryx(args, me, peer, waiting)?)
        }
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
    if let Some(priority) = args.realtime {
        crate::placement::enter_realtime(priority)?;
    }
    // An iceoryx2 receiver waits on a WaitSet, as chassisd's loop does.
    if let Some(waiting) = iceoryx_waiting(args.transport) {
        let mut inner = open_iceoryx(args, "pong", "ping", waiting)?;
        let listener = inner.listener.take().context("the pong's listener")?;
        let waitset = WaitSetBuilder::new()
            .create::<ipc::Service>()
            .map_err(|e| anyhow::anyhow!("wait set: {e:?}"))?;
        let _guard = waitset
            .attach_notification(&listener)
            .map_err(|e| anyhow::anyhow!("attaching the listener: {e:?}"))?;
        let mut endpoint = WaitSetEndpoint {
            inner,
            waitset: &waitset,
            listener: &listener,
        };
        return answer(args, &mut endpoint);
    }
    let mut endpoint = open_endpoint(args, "pong", "ping")?;
    answer(args, endpoint.as_mut())
}

/// Answers pings until the last one (`u64::MAX`), writing a loaded receiver's feed figures.
fn answer(args: &PongArgs, endpoint: &mut dyn Endpoint) -> anyhow::Result<()> {
    println!("ready");
    loop {
        match endpoint.receive(Duration::from_secs(5))? {
            Some((ping, arrived)) => {
                if ping.seq == u64::MAX {
                    if args.load().is_some() {
                        let text: String = endpoint
                            .feed_latencies()
                            .iter()
                            .map(|ns| format!("{ns}\n"))
                            .collect();
                        std::fs::write(args.feed_file(), text)
                            .with_context(|| format!("writing {}", args.feed_file().display()))?;
                    }
                    println!("done");
                    return Ok(());
                }
                if ping.seq & LEAD != 0 {
                    continue;
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

/// What a baseline run measured: the pings' hops, and a loaded receiver's feed hops (every
/// one, ns, in order).
pub struct Measured {
    /// Every counted hop of the pings, ns, in order.
    pub pings: Vec<u64>,
    /// [`Rounds::Loop`]: the periods whose ping went out after the period had ended.
    pub missed_periods: u64,
    pub feed: Option<Vec<u64>>,
    /// A loaded iceoryx2 receiver's publication, as its reader took it ([`Published`]): every
    /// hop, ns, in order.
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

/// Runs `rounds` ping-pongs (after a warm-up) and returns the counted one-way latencies
/// ([`Rounds`]): back to back, both directions; paced, one ping per period and only the ping's
/// hop: what a request meets when it comes after a pause, as a controller's requests do (the
/// receiver is blocked and its CPU may be idle); after a wake-up, the hop of a ping that follows
/// another at once. With `load` (iceoryx2 only), the receiver also lives with a feed from a third
/// process and a tick of its own, and the feed's hops are measured.
#[allow(clippy::too_many_arguments)]
pub fn run(
    transport: Transport,
    placement: Placement,
    rounds: u64,
    shape: Rounds,
    load: Option<Load>,
    prefix: &str,
    dir: &std::path::Path,
) -> anyhow::Result<Measured> {
    let tag = format!("{}-{}", std::process::id(), crate::placement::unique());
    let (ping_cpu, pong_cpu) = placement.cpus();
    let args = PongArgs {
        transport,
        tag: tag.clone(),
        prefix: prefix.to_string(),
        cpu: pong_cpu,
        dir: dir.to_path_buf(),
        feed_per_s: load.map(|l| l.feed_per_s),
        tick_us: load.map(|l| u64::try_from(l.tick.as_micros()).unwrap_or(u64::MAX)),
        realtime: load.and_then(|l| l.realtime),
        publish: load.is_some_and(|l| l.published),
    };
    let exe = std::env::current_exe()?;
    let mut command = Command::new(&exe);
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
    if let Some(load) = load {
        command
            .arg("--feed-per-s")
            .arg(load.feed_per_s.to_string())
            .arg("--tick-us")
            .arg(load.tick.as_micros().to_string());
        if let Some(priority) = load.realtime {
            command.args(["--realtime", &priority.to_string()]);
        }
        if load.published {
            command.arg("--publish");
        }
    }
    let mut child = command.spawn().context("starting the pong process")?;
    let mut reader = wait_ready(&mut child)?;
    // The loaded receiver's publication is read where the client reads, before the feed
    // starts it.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let published = match (load, iceoryx_waiting(transport)) {
        (
            Some(Load {
                published: true, ..
            }),
            Some(waiting),
        ) => Some(spawn_reader(
            prefix,
            &tag,
            ping_cpu,
            waiting == Waiting::Spin,
            &stop,
        )?),
        _ => None,
    };
    let feed_cpu = pong_cpu.map(|cpu| feed_cpu(cpu, transport, load));
    let mut feeder = match load {
        Some(load) => {
            let mut feed = Command::new(&exe);
            feed.args(["role", "feed", "--tag", &tag, "--prefix", prefix, "--rate"])
                .arg(load.feed_per_s.to_string())
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit());
            if let Some(cpu) = feed_cpu {
                feed.args(["--cpu", &cpu.to_string()]);
            }
            let mut feeder = feed.spawn().context("starting the feed process")?;
            wait_ready(&mut feeder)?;
            Some(feeder)
        }
        None => None,
    };
    if let Some(cpu) = ping_cpu {
        pin_current_thread(cpu)?;
    }
    let result = open_endpoint(&args, "ping", "pong").and_then(|mut endpoint| {
        let result = match shape {
            Rounds::Loop(period) => loop_rounds(endpoint.as_mut(), transport, rounds, period),
            _ => ping_rounds(endpoint.as_mut(), transport, rounds, shape).map(|p| (p, 0)),
        };
        // Tells the pong to stop (and to write its feed figures).
        let _ = endpoint.send(Ping {
            seq: u64::MAX,
            ..Ping::default()
        });
        result
    });
    crate::placement::unpin_current_thread();
    if let Some(feeder) = feeder.as_mut() {
        let _ = feeder.kill();
        let _ = feeder.wait();
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let published = match published {
        Some(handle) => Some(
            handle
                .join()
                .map_err(|_| anyhow::anyhow!("the state reader panicked"))??,
        ),
        None => None,
    };
    let (pings, missed_periods) = result?;
    // The pong writes its feed figures before it says "done".
    let mut line = String::new();
    let _ = reader.read_line(&mut line);
    let _ = child.wait();
    let feed = match load {
        Some(_) => {
            let path = args.feed_file();
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            Some(text.lines().filter_map(|l| l.parse::<u64>().ok()).collect())
        }
        None => None,
    };
    Ok(Measured {
        pings,
        missed_periods,
        feed,
        published,
    })
}

/// Starts the reader of a loaded receiver's publication ([`Published`]) on `cpu`, at normal
/// scheduling, and returns once it is subscribed: it reads as the benchmark's state reader
/// does, blocked on its listener between drains (polling in a busy-poll run), until `stop`.
fn spawn_reader(
    prefix: &str,
    tag: &str,
    cpu: Option<usize>,
    spin: bool,
    stop: &std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> anyhow::Result<std::thread::JoinHandle<anyhow::Result<Vec<u64>>>> {
    let (prefix, tag, stop) = (prefix.to_string(), tag.to_string(), stop.clone());
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let handle = std::thread::Builder::new()
        .name("state-reader".into())
        .spawn(move || {
            // iceoryx2's ports stay on the thread that opens them. An error opening them is the
            // spawner's to report; the thread then has read nothing.
            let opened = (|| -> anyhow::Result<_> {
                if let Some(cpu) = cpu {
                    pin_current_thread(cpu)?;
                }
                let node = node(&prefix)?;
                let subscriber = pubsub(&node, &published_service(&tag))?
                    .subscriber_builder()
                    .create()
                    .map_err(|e| anyhow::anyhow!("state subscriber: {e:?}"))?;
                let listener = event(&node, &published_service(&tag))?
                    .listener_builder()
                    .create()
                    .map_err(|e| anyhow::anyhow!("state listener: {e:?}"))?;
                Ok((node, subscriber, listener))
            })();
            match opened {
                Ok((_node, subscriber, listener)) => {
                    let _ = ready_tx.send(Ok(()));
                    read_published(&subscriber, &listener, spin, &stop)
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    Ok(Vec::new())
                }
            }
        })
        .context("starting the state reader")?;
    ready_rx
        .recv()
        .map_err(|_| anyhow::anyhow!("the state reader stopped before it subscribed"))??;
    Ok(handle)
}

/// Every hop of the publication until `stop`, ns: the notifications pending are spent before
/// each drain, and the reader waits (at most 20 ms, to look at `stop`) only when a drain took
/// nothing, as `StateStream::wait` does.
fn read_published(
    subscriber: &Subscriber<ipc::Service, Ping, ()>,
    listener: &Listener<ipc::Service>,
    spin: bool,
    stop: &std::sync::atomic::AtomicBool,
) -> anyhow::Result<Vec<u64>> {
    let mut hops = Vec::new();
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        if !spin {
            listener
                .try_wait(|_| {})
                .map_err(|e| anyhow::anyhow!("taking the state's notifications: {e:?}"))?;
        }
        let mut took = false;
        while let Some(sample) = subscriber
            .receive()
            .map_err(|e| anyhow::anyhow!("state receive: {e:?}"))?
        {
            hops.push(now_ns().saturating_sub(sample.stamp_ns));
            took = true;
        }
        if !took && !spin {
            wait_listener(listener, Duration::from_millis(20))
                .map_err(|e| anyhow::anyhow!("waiting for state: {e:?}"))?;
        }
    }
    Ok(hops)
}

/// Where the feed of a receiver pinned to `pong_cpu` runs: where chassisd places its simulated
/// chassis (`realtime::sim_cpus`). On the receiver's CPU when the receiver blocks at SCHED_FIFO (the
/// chassis runs only while the loop waits); otherwise on another CPU, the ping side's in a
/// cross-CPU run.
fn feed_cpu(pong_cpu: usize, transport: Transport, load: Option<Load>) -> usize {
    let fifo = load.is_some_and(|l| l.realtime.is_some());
    if fifo && transport != Transport::IceoryxSpin {
        return pong_cpu;
    }
    let cpus = crate::placement::cpu_count();
    if cpus > 1 {
        (pong_cpu + 1) % cpus
    } else {
        pong_cpu
    }
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
        Rounds::Paced(period) => (20, Some(chassis_client::Ticker::new(period))),
        Rounds::BackToBack | Rounds::AfterWakeUp | Rounds::Loop(_) => (200, None),
    };
    for seq in 0..warmup + rounds {
        if let Some(ticker) = ticker.as_mut() {
            ticker.wait();
            endpoint.look()?;
        }
        if shape == Rounds::AfterWakeUp {
            endpoint.send(Ping {
                stamp_ns: now_ns(),
                seq: seq | LEAD,
                ..Ping::default()
            })?;
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
        if pong.seq != seq {
            bail!("{}: ping {seq} answered as {}", transport.label(), pong.seq);
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
    transport: Transport,
    rounds: u64,
    period: Duration,
) -> anyhow::Result<(Vec<u64>, u64)> {
    const WARMUP: u64 = 200;
    let mut periods = crate::periods::Periods::new(period);
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
        endpoint.send(Ping {
            stamp_ns: sent,
            seq,
            ..Ping::default()
        })?;
        periods.end(start, seq >= WARMUP);
    }
    while (hops.len() as u64) < rounds {
        if !take(endpoint, Duration::from_secs(2), &started, &mut hops)? {
            bail!(
                "{}: {} of {rounds} loop pings unanswered",
                transport.label(),
                rounds - hops.len() as u64
            );
        }
    }
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
            assert_eq!(feed_cpu(0, transport, Some(load(Some(80)))), 0);
            assert_eq!(feed_cpu(0, transport, Some(load(None))), other);
        }
        assert_eq!(feed_cpu(0, Transport::IceoryxSpin, Some(load(None))), other);
        assert_eq!(feed_cpu(0, Transport::IceoryxEvent, None), other);
    }
}
