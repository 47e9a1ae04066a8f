//! `chassis-client`: talk to a robot served by `chassisd`.
//!
//! Every client process — teleop, planner, safety monitor, the CLI, third-party programs — uses
//! this crate and nothing else to reach a robot:
//!
//! * [`Robot::connect`] by name (`titan`, or whatever `chassisd --name` says);
//! * [`Robot::latest_state`] / [`Robot::wait_state`]: the [`ChassisState`], read zero-copy from
//!   shared memory, with a deadline. The state topic is a latest-value topic: the `Robot` keeps
//!   the newest sample, and a reader that wants every sample (a logger, a gap counter) opens a
//!   [`Robot::state_stream`];
//! * [`Robot::source`]: publish [`VelocityRequest`]s as one of the service's configured sources
//!   (`safety`, `teleop`, `planner` by default). The source's priority and timeout are the
//!   service's: a client cannot raise its own priority. One process per source. A request is
//!   parsed into a [`ValidRequest`] before it is sent: one with a NaN or an infinity never
//!   leaves the process;
//! * [`Robot::control`]: mode, brake, lights, lift, … answered with success or a reason;
//! * [`Robot::latest_mux`]: which source the mux chose and why.
//!
//! ```no_run
//! use std::time::Duration;
//! use chassis_client::{Robot, VelocityRequest};
//!
//! let mut robot = Robot::connect("titan")?;
//! let mut teleop = robot.source("teleop")?;
//! for _ in 0..50 {
//!     teleop.send(VelocityRequest::twist(0.3, 0.0))?;
//!     if let Some(state) = robot.wait_state(Duration::from_millis(100))? {
//!         println!("{:.2} m/s", state.motion.linear_mps);
//!     }
//! }
//! teleop.send(VelocityRequest::twist(0.0, 0.0))?;
//! # Ok::<(), chassis_client::ClientError>(())
//! ```
//!
//! iceoryx2 ports are not `Send`: keep a [`Robot`] and its [`Source`]s on one thread.
//!
//! Every message is a plain fixed-layout value (re-exported from `chassis-interfaces`), the
//! same bytes in every process and language, on services named after the robot:
//!
//! ```
//! use chassis_client::{ServiceKind, ValidRequest, VelocityRequest, service_name};
//!
//! let request = VelocityRequest::twist(0.3, 0.1); // m/s forward, rad/s left
//! assert!(ValidRequest::try_from(request).is_ok() && !request.is_heartbeat());
//! assert_eq!(std::mem::size_of::<VelocityRequest>(), 64);
//! assert_eq!(
//!     service_name("titan", ServiceKind::Cmd("teleop")),
//!     "chassis/titan/cmd/teleop"
//! );
//! ```

use std::time::Duration;

mod clock;
#[cfg(feature = "foxglove")]
pub mod foxglove;
mod owner;
mod rate;
pub mod urdf;
pub mod watch;

pub use clock::{PEER_CLOCK_SAMPLES, PeerClock, WallClock};
pub use rate::Decimator;

pub use chassis_interfaces::*;
use chassis_ipc::{
    CMD, CONTROL, ClientPorts, DESCRIPTION, FRAMES, IpcError, MUX, PUBLICATION, Reader,
    RequestResponse, SIM, STATE, Writer, publication,
};
pub use chassis_ipc::{
    IPC_PREFIX_ENV, STATE_BUFFER, ServiceKind, TEST_LOOP_STALL_ENV, service_name,
};
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use thiserror::Error;

/// What went wrong talking to a robot.
#[derive(Debug, Error)]
pub enum ClientError {
    #[error(
        "no service chassis/{name} — is chassisd running? (start it with `chassisd --robot …`)"
    )]
    NotRunning { name: String },
    #[error(
        "robot '{name}' has no source called '{source_name}' (configured: {configured}); \
         sources are set in chassisd's config"
    )]
    UnknownSource {
        name: String,
        source_name: String,
        configured: String,
    },
    #[error("source '{source_name}' of robot '{name}' is already held by another process")]
    SourceTaken { name: String, source_name: String },
    #[error("no answer from chassis/{name}/{what} within {timeout:?}")]
    Timeout {
        name: String,
        what: &'static str,
        timeout: Duration,
    },
    #[error(
        "chassis/{name}/robot has no description: is its chassisd older than the robot \
         description, or not serving yet?"
    )]
    NoDescription { name: String },
    #[error("'{0}' is not a valid robot or source name (1-16 of a-z 0-9 - _)")]
    BadName(String),
    /// A velocity request that is no [`ValidRequest`]: nothing was sent.
    #[error("request not sent: {0}")]
    InvalidRequest(#[from] InvalidVelocity),
    /// The robot's chassisd runs as another user, whose iceoryx2 files this process cannot
    /// share: every program of a robot runs as chassisd's user.
    #[error("chassisd for {name} runs as user {user}; run as that user: sudo -u {user} …")]
    OtherUser { name: String, user: String },
    #[error("iceoryx2: {0}")]
    Ipc(String),
}

fn ipc<E: std::fmt::Display>(what: &str) -> impl FnOnce(E) -> ClientError + '_ {
    move |e| ClientError::Ipc(format!("{what}: {e}"))
}

/// A [`ValidRequest`] is sent as it is: its parse cannot fail.
impl From<std::convert::Infallible> for ClientError {
    fn from(never: std::convert::Infallible) -> Self {
        match never {}
    }
}

impl From<IpcError> for ClientError {
    fn from(e: IpcError) -> Self {
        ClientError::Ipc(e.to_string())
    }
}

/// `CLOCK_MONOTONIC` now, ns: the clock of every stamp in the system.
pub fn now_ns() -> u64 {
    use nix::time::{ClockId, clock_gettime};
    clock_gettime(ClockId::CLOCK_MONOTONIC).map_or(0, |t| {
        let ns = i128::from(t.tv_sec()) * 1_000_000_000 + i128::from(t.tv_nsec());
        u64::try_from(ns).unwrap_or(0)
    })
}

/// `after` from now on `CLOCK_MONOTONIC`, ns (one too far to count is never).
pub fn deadline(after: Duration) -> u64 {
    now_ns().saturating_add(u64::try_from(after.as_nanos()).unwrap_or(u64::MAX))
}

/// A request-response client answered with `ControlResponse`, with its paired events.
type Counter<Req> = ClientPorts<Req>;

/// State samples a [`Robot`]'s own subscriber keeps: the newest, and a few before it for
/// [`Robot::wait_states`].
const LATEST_STATE_BUFFER: usize = 4;
/// Mux decisions a [`Robot`]'s own subscriber keeps (it wants the newest).
const LATEST_MUX_BUFFER: usize = 4;
/// Longest a reader waiting for the description sleeps between two looks.
const DESCRIPTION_POLL: Duration = Duration::from_millis(50);

/// A connection to one robot.
///
/// Its own state subscriber reads `chassis/<name>/state` as a latest-value topic: it keeps the
/// newest [`ChassisState`] (and the few before it), so a reader that is slower than the service
/// loses the oldest and never falls behind. A reader that needs every sample opens a
/// [`StateStream`] with [`Robot::state_stream`].
#[derive(Debug)]
pub struct Robot {
    name: String,
    node: Node<ipc::Service>,
    state: Subscriber<ipc::Service, ChassisState, ()>,
    state_events: Listener<ipc::Service>,
    mux: Option<Subscriber<ipc::Service, MuxStatus, ()>>,
    mux_events: Option<Listener<ipc::Service>>,
    latest_state: Option<ChassisState>,
    latest_mux: Option<MuxStatus>,
    description: Option<Subscriber<ipc::Service, RobotDescription, ()>>,
    latest_description: Option<RobotDescription>,
    safety: Option<Subscription<SafetyStatus>>,
    control: Option<Counter<ControlRequest>>,
    sim: Option<Counter<SimRequest>>,
    control_seq: u64,
    /// The iceoryx2 prefix it was opened with (its own or [`IPC_PREFIX_ENV`]'s).
    prefix: Option<String>,
}

/// The sources this process has connected to before, by prefix, robot and source: the first
/// connection of each sends one heartbeat (see [`Robot::source`]); a reconnection sends none.
static CONNECTED_SOURCES: std::sync::Mutex<Vec<(Option<String>, String, String)>> =
    std::sync::Mutex::new(Vec::new());

impl Robot {
    /// Connects to the robot served as `chassis/<name>/`: fails with
    /// [`ClientError::NotRunning`] when no `chassisd` serves it (yet), and with
    /// [`ClientError::BadName`] before touching shared memory for a name no robot can have.
    ///
    /// ```no_run
    /// use chassis_client::{ClientError, Robot};
    ///
    /// match Robot::connect("titan") {
    ///     Ok(robot) => println!("connected to {}", robot.name()),
    ///     Err(ClientError::NotRunning { .. }) => eprintln!("start it: chassisd --robot titan"),
    ///     Err(e) => return Err(e),
    /// }
    /// # Ok::<(), ClientError>(())
    /// ```
    ///
    /// ```
    /// use chassis_client::{ClientError, Robot};
    ///
    /// // Names are 1-16 of a-z 0-9 - _, checked before anything is opened.
    /// assert!(matches!(Robot::connect("Titan!"), Err(ClientError::BadName(_))));
    /// ```
    pub fn connect(name: &str) -> Result<Self, ClientError> {
        Self::connect_with_prefix(name, None)
    }

    /// Like [`Robot::connect`], with an explicit iceoryx2 file prefix instead of the one in
    /// [`IPC_PREFIX_ENV`] (tests isolating themselves from each other).
    pub fn connect_with_prefix(name: &str, prefix: Option<&str>) -> Result<Self, ClientError> {
        if !valid_robot_name(name) {
            return Err(ClientError::BadName(name.to_string()));
        }
        if let Some(user) = owner::other_users_chassisd(name) {
            return Err(ClientError::OtherUser {
                name: name.to_string(),
                user,
            });
        }
        let node = chassis_ipc::node(
            None,
            &chassis_ipc::config(prefix)?,
            SignalHandlingMode::Disabled,
        )?;
        let not_running = || ClientError::NotRunning {
            name: name.to_string(),
        };
        let topic = match STATE.open(&node, &service_name(name, ServiceKind::State)) {
            Ok(topic) => topic,
            Err(IpcError::NotFound { .. }) => return Err(not_running()),
            Err(e) => return Err(e.into()),
        };
        if topic.publishers() == 0 {
            return Err(not_running());
        }
        let Reader {
            subscriber: state,
            listener: state_events,
        } = topic.subscriber(LATEST_STATE_BUFFER)?;
        Ok(Self {
            name: name.to_string(),
            node,
            state,
            state_events,
            mux: None,
            mux_events: None,
            latest_state: None,
            latest_mux: None,
            description: None,
            latest_description: None,
            safety: None,
            control: None,
            sim: None,
            control_seq: 0,
            prefix: prefix
                .map(str::to_string)
                .or_else(|| std::env::var(IPC_PREFIX_ENV).ok()),
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// True while `chassisd` still publishes this robot's state.
    pub fn is_served(&self) -> bool {
        STATE
            .publishers(&self.node, &service_name(&self.name, ServiceKind::State))
            .is_ok_and(|n| n > 0)
    }

    /// Takes every pending state sample, oldest first, handing each to `each`.
    fn drain_state_each(
        &mut self,
        mut each: impl FnMut(&ChassisState),
    ) -> Result<usize, ClientError> {
        let latest = &mut self.latest_state;
        receive_all(&self.state, "receiving state", |s| {
            each(s);
            *latest = Some(*s);
        })
    }

    /// Waits at most `timeout` for new state samples and hands every one of them to `each`,
    /// oldest first (the service publishes one per frame that changes the state; a reader woken
    /// once may find several). Returns how many there were. The subscriber keeps the last 4
    /// samples: a reader woken after more were published loses the oldest (on a saturated bus
    /// the service publishes bursts of ≈ 18 at once). [`Robot::state_stream`] loses none.
    pub fn wait_states(
        &mut self,
        timeout: Duration,
        mut each: impl FnMut(&ChassisState),
    ) -> Result<usize, ClientError> {
        let (state, latest) = (&self.state, &mut self.latest_state);
        drain_or_wait(&self.state_events, timeout, "waiting for state", || {
            receive_all(state, "receiving state", |s| {
                each(s);
                *latest = Some(*s);
            })
        })
    }

    /// Hands every pending state sample to `each` without waiting (a busy-polling reader). Like
    /// [`Robot::wait_states`], it sees at most the last 4 samples published since its last call.
    pub fn poll_states(&mut self, each: impl FnMut(&ChassisState)) -> Result<usize, ClientError> {
        self.drain_state_each(each)
    }

    /// The newest state sample (a late joiner gets the last one published).
    ///
    /// ```no_run
    /// use chassis_client::{ControlMode, Group, Robot};
    ///
    /// let mut robot = Robot::connect("titan")?;
    /// if let Some(state) = robot.latest_state()? {
    ///     println!(
    ///         "{:.2} m/s, {:.2} rad/s, {}, at ({:.2}, {:.2}) m",
    ///         state.motion.linear_mps,
    ///         state.motion.angular_radps,
    ///         ControlMode::name(state.system.control_mode),
    ///         state.odometry.x_m,
    ///         state.odometry.y_m,
    ///     );
    ///     // A signal the robot never reported reads 0 with its group marked invalid.
    ///     if state.is_valid(Group::Gps) && state.gps.has_fix() {
    ///         println!("at {:.6}°, {:.6}°", state.gps.latitude_deg, state.gps.longitude_deg);
    ///     }
    /// }
    /// # Ok::<(), chassis_client::ClientError>(())
    /// ```
    pub fn latest_state(&mut self) -> Result<Option<ChassisState>, ClientError> {
        self.drain_state_each(|_| {})?;
        Ok(self.latest_state)
    }

    /// Waits at most `timeout` for a state sample newer than the ones seen so far.
    pub fn wait_state(&mut self, timeout: Duration) -> Result<Option<ChassisState>, ClientError> {
        let n = self.wait_states(timeout, |_| {})?;
        Ok(if n > 0 { self.latest_state } else { None })
    }

    fn open_mux(&mut self) -> Result<(), ClientError> {
        if self.mux.is_some() {
            return Ok(());
        }
        let reader = MUX
            .open(&self.node, &service_name(&self.name, ServiceKind::Mux))?
            .subscriber(LATEST_MUX_BUFFER)?;
        self.mux = Some(reader.subscriber);
        self.mux_events = Some(reader.listener);
        Ok(())
    }

    fn drain_mux(&mut self) -> Result<bool, ClientError> {
        Ok(self.poll_mux(|_| {})? > 0)
    }

    /// Hands every mux decision published since the last read to `each`, oldest first, without
    /// waiting (the subscriber keeps the last 4). Returns how many there were.
    pub fn poll_mux(&mut self, mut each: impl FnMut(&MuxStatus)) -> Result<usize, ClientError> {
        self.open_mux()?;
        let Some(mux) = &self.mux else {
            return Ok(0);
        };
        let latest = &mut self.latest_mux;
        receive_all(mux, "receiving mux status", |m| {
            each(m);
            *latest = Some(*m);
        })
    }

    /// The newest mux decision.
    pub fn latest_mux(&mut self) -> Result<Option<MuxStatus>, ClientError> {
        self.drain_mux()?;
        Ok(self.latest_mux)
    }

    /// Waits at most `timeout` for a newer mux decision.
    pub fn wait_mux(&mut self, timeout: Duration) -> Result<Option<MuxStatus>, ClientError> {
        if self.drain_mux()? {
            return Ok(self.latest_mux);
        }
        if let Some(events) = &self.mux_events {
            wait_listener(events, timeout).map_err(ipc("waiting for mux status"))?;
        }
        self.drain_mux()?;
        Ok(self.latest_mux)
    }

    /// Takes every pending description; true if there was one.
    fn drain_description(&mut self) -> Result<bool, ClientError> {
        if self.description.is_none() {
            let reader = DESCRIPTION
                .open(
                    &self.node,
                    &service_name(&self.name, ServiceKind::Description),
                )?
                .subscriber(DESCRIPTION.limits.subscriber_max_buffer_size)?;
            self.description = Some(reader.subscriber);
        }
        let Some(subscriber) = &self.description else {
            return Ok(false);
        };
        let latest = &mut self.latest_description;
        Ok(
            receive_all(subscriber, "receiving the robot description", |d| {
                *latest = Some(*d)
            })? > 0,
        )
    }

    /// What the robot is, as `chassisd` describes the robot it drives: kind, model, protocol
    /// in use, the effective limits, geometry, battery levels, sensors, joints and the mux's
    /// sources. Kept for late joiners: the first call waits at most `timeout` (the service hands
    /// it to a new reader within one tick of its loop). Later calls return at once, with any
    /// newer description (the protocol once detection decides).
    pub fn description(&mut self, timeout: Duration) -> Result<RobotDescription, ClientError> {
        let end = deadline(timeout);
        // A service that is starting (chassisd, or a mirror of another computer's robot) may
        // not have created the description's service yet: it counts as no description yet.
        let mut drained = self.drain_description();
        if let Some(description) = self.latest_description {
            return Ok(description);
        }
        loop {
            let left = end.saturating_sub(now_ns());
            if left == 0 {
                drained?;
                return Err(ClientError::NoDescription {
                    name: self.name.clone(),
                });
            }
            // The state is published at least every 100 ms: each sample is a chance to look.
            wait_listener(
                &self.state_events,
                Duration::from_nanos(left).min(DESCRIPTION_POLL),
            )
            .map_err(ipc("waiting for the robot description"))?;
            drained = self.drain_description();
            if matches!(drained, Ok(true)) {
                return self.latest_description.ok_or(ClientError::NoDescription {
                    name: self.name.clone(),
                });
            }
        }
    }

    /// The newest description received so far, without waiting.
    pub fn latest_description(&mut self) -> Result<Option<RobotDescription>, ClientError> {
        self.drain_description()?;
        Ok(self.latest_description)
    }

    /// The safety monitor's newest decision (`None` until it published one). The monitor may
    /// start after the client: its service is looked for at each call until it exists.
    pub fn latest_safety(&mut self) -> Result<Option<SafetyStatus>, ClientError> {
        if self.safety.is_none() {
            self.safety = self.subscriber::<SafetyStatus>(SafetyStatus::SERVICE)?;
        }
        match self.safety.as_mut() {
            Some(s) => s.latest(),
            None => Ok(None),
        }
    }

    /// Publishes velocity requests as the configured source `name`. Fails if the service has no
    /// such source, or if another process already holds it.
    ///
    /// The source's priority and timeout are the service's: a request counts until the
    /// source's timeout after it, so a client publishes at a steady rate, and its motion ends
    /// by itself when the client stops or dies.
    ///
    /// Motion starts only from a zero: after any stop it did not ask for (chassisd starting, a
    /// lock released, the safety monitor or the bus back, the chassis' E-stop released), the
    /// service obeys a source's motion only once that source has asked for nothing since.
    /// Starting a client process is a deliberate act, so the first connection of a source in
    /// this process sends one heartbeat (asks for nothing). A later connection of the same
    /// source by the same process (after chassisd restarted) sends none: a client that kept
    /// asking through a restart must send a zero ([`Source::stop`]) before it drives again, and
    /// `MuxStatus::why` says so while it waits.
    ///
    /// ```no_run
    /// use std::time::Duration;
    /// use chassis_client::{Robot, Ticker, VelocityRequest};
    ///
    /// let mut robot = Robot::connect("titan")?;
    /// let mut planner = robot.source("planner")?;
    /// let mut ticker = Ticker::new(Duration::from_millis(50));
    /// for _ in 0..40 {
    ///     planner.send(VelocityRequest::steer(0.5, 0.2))?; // 0.5 m/s, wheels 0.2 rad left
    ///     ticker.wait();
    /// }
    /// planner.stop()?;
    /// # Ok::<(), chassis_client::ClientError>(())
    /// ```
    pub fn source(&mut self, name: &str) -> Result<Source, ClientError> {
        if !valid_robot_name(name) {
            return Err(ClientError::BadName(name.to_string()));
        }
        let topic = match CMD.open(
            &self.node,
            &service_name(&self.name, ServiceKind::Cmd(name)),
        ) {
            Ok(topic) => topic,
            Err(IpcError::NotFound { .. }) => {
                let configured = self
                    .latest_mux()
                    .ok()
                    .flatten()
                    .map(|m| {
                        m.sources()
                            .iter()
                            .map(|s| s.name().to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    })
                    .unwrap_or_else(|| "unknown".into());
                return Err(ClientError::UnknownSource {
                    name: self.name.clone(),
                    source_name: name.to_string(),
                    configured,
                });
            }
            Err(e) => return Err(e.into()),
        };
        let Writer {
            publisher,
            notifier,
        } = topic.publisher().map_err(|e| match e {
            IpcError::Taken { .. } => ClientError::SourceTaken {
                name: self.name.clone(),
                source_name: name.to_string(),
            },
            other => other.into(),
        })?;
        let mut source = Source {
            name: name.to_string(),
            publisher,
            notifier,
            seq: 0,
        };
        let key = (self.prefix.clone(), self.name.clone(), name.to_string());
        let first = CONNECTED_SOURCES
            .lock()
            .map(|mut seen| {
                let first = !seen.contains(&key);
                if first {
                    seen.push(key);
                }
                first
            })
            .unwrap_or(false);
        if first {
            source.heartbeat()?;
        }
        Ok(source)
    }

    fn counter<Req: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
        &self,
        spec: &RequestResponse<Req>,
        kind: ServiceKind<'_>,
    ) -> Result<Counter<Req>, ClientError> {
        let name = service_name(&self.name, kind);
        match spec.open(&self.node, &name) {
            Ok(exchange) => Ok(exchange.client()?),
            Err(IpcError::NotFound { .. }) => Err(ClientError::NotRunning {
                name: format!("{}/{}", self.name, name.rsplit('/').next().unwrap_or("")),
            }),
            Err(e) => Err(e.into()),
        }
    }

    /// Asks for a control action and waits at most `timeout` for the answer: success, or a
    /// status and the reason it was refused.
    ///
    /// ```no_run
    /// use std::time::Duration;
    /// use chassis_client::{ControlKind, ControlRequest, ControlStatus, Robot};
    ///
    /// let mut robot = Robot::connect("titan")?;
    /// // The operator's e-stop: held (across restarts of chassisd) until released by name.
    /// let estop = ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name("estop");
    /// let answer = robot.control(estop, Duration::from_secs(1))?;
    /// if !answer.is_ok() {
    ///     eprintln!("refused: {} {}", ControlStatus::name(answer.status), answer.message());
    /// }
    /// # Ok::<(), chassis_client::ClientError>(())
    /// ```
    pub fn control(
        &mut self,
        request: ControlRequest,
        timeout: Duration,
    ) -> Result<ControlResponse, ClientError> {
        self.ask_service(
            |r| &mut r.control,
            &CONTROL,
            ServiceKind::Control,
            "control",
            request,
            timeout,
        )
    }

    /// Injects a fault into the robot's simulated chassis (only when its bus is the simulator).
    pub fn sim(
        &mut self,
        request: SimRequest,
        timeout: Duration,
    ) -> Result<ControlResponse, ClientError> {
        self.ask_service(
            |r| &mut r.sim,
            &SIM,
            ServiceKind::Sim,
            "sim",
            request,
            timeout,
        )
    }

    /// Opens the service `kind` on first use (kept in `slot`), numbers and stamps `request`
    /// and waits at most `timeout` for its answer. Control and sim requests share one count.
    fn ask_service<Req: Numbered + std::fmt::Debug + ZeroCopySend + Copy + 'static>(
        &mut self,
        slot: fn(&mut Self) -> &mut Option<Counter<Req>>,
        spec: &RequestResponse<Req>,
        kind: ServiceKind<'_>,
        what: &'static str,
        request: Req,
        timeout: Duration,
    ) -> Result<ControlResponse, ClientError> {
        if slot(self).is_none() {
            let counter = self.counter(spec, kind)?;
            *slot(self) = Some(counter);
        }
        self.control_seq += 1;
        let seq = self.control_seq;
        let request = request.numbered(seq, now_ns());
        let name = self.name.clone();
        let counter = slot(self)
            .as_ref()
            .ok_or_else(|| ClientError::Ipc(format!("no {what} client")))?;
        ask(&name, what, counter, request, seq, timeout)
    }

    /// A stream of every state sample the service publishes, with its own subscriber and its own
    /// listener: it does not disturb this `Robot`'s latest-value reading, and holds one of the
    /// state service's reader slots ([`chassis_ipc::MAX_READERS`]) while it lives.
    ///
    /// `buffer` samples may queue between two reads before the oldest are lost; it is clamped to
    /// 1..=the service's maximum ([`STATE_BUFFER`] with `chassisd`), and
    /// [`StateStream::buffer`] tells what it became. The service publishes one sample per frame
    /// that changes the state and wakes the readers once per read of the bus: ≈ 4300 samples a
    /// second on a saturated 500 kbit/s bus, in bursts of ≈ 18 every 4 ms, and after the service
    /// was held up, its backlog at once (up to 256). The full buffer holds such a backlog, and
    /// lets a reader of the moderated bus wake ≈ 55 ms late without losing a sample. Gaps show in
    /// `ChassisState::seq`, which numbers every sample published.
    ///
    /// The first sample is the newest one published before the stream opened (the topic keeps
    /// one); every sample after it follows in order.
    ///
    /// ```no_run
    /// use std::time::Duration;
    /// use chassis_client::{Robot, STATE_BUFFER};
    ///
    /// let robot = Robot::connect("titan")?;
    /// let states = robot.state_stream(STATE_BUFFER)?;
    /// let mut last = None;
    /// loop {
    ///     states.wait(Duration::from_millis(100), |s| {
    ///         if let Some(seq) = last.filter(|&seq| s.seq != seq + 1) {
    ///             eprintln!("lost {} samples after #{seq}", s.seq.saturating_sub(seq + 1));
    ///         }
    ///         last = Some(s.seq);
    ///     })?;
    /// }
    /// # Ok::<(), chassis_client::ClientError>(())
    /// ```
    pub fn state_stream(&self, buffer: usize) -> Result<StateStream, ClientError> {
        let topic = match STATE.open(&self.node, &service_name(&self.name, ServiceKind::State)) {
            Ok(topic) => topic,
            Err(IpcError::NotFound { .. }) => {
                return Err(ClientError::NotRunning {
                    name: self.name.clone(),
                });
            }
            Err(e) => return Err(e.into()),
        };
        // A service made with other limits (another version of chassisd) sets its own maximum.
        let buffer = buffer.clamp(1, topic.subscriber_max_buffer_size().max(1));
        let Reader {
            subscriber,
            listener: events,
        } = topic.subscriber(buffer)?;
        Ok(StateStream {
            subscriber,
            events,
            buffer,
        })
    }

    /// A tap of every frame on the bus, both directions. `buffer` frames may queue between two
    /// reads before the oldest are lost (gaps show in `BusFrame::seq`).
    pub fn frames(&self, buffer: usize) -> Result<FrameTap, ClientError> {
        let Reader {
            subscriber,
            listener: events,
        } = FRAMES
            .open(&self.node, &service_name(&self.name, ServiceKind::Frames))?
            .subscriber(buffer.max(1))?;
        Ok(FrameTap { subscriber, events })
    }
}

/// A request of a service that answers with a [`ControlResponse`]: the client numbers and
/// stamps it when it sends it.
trait Numbered {
    fn numbered(self, seq: u64, stamp_ns: u64) -> Self;
}

impl Numbered for ControlRequest {
    fn numbered(self, seq: u64, stamp_ns: u64) -> Self {
        Self {
            seq,
            stamp_ns,
            ..self
        }
    }
}

impl Numbered for SimRequest {
    fn numbered(self, seq: u64, stamp_ns: u64) -> Self {
        Self {
            seq,
            stamp_ns,
            ..self
        }
    }
}

fn ask<Req: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
    name: &str,
    what: &'static str,
    counter: &Counter<Req>,
    request: Req,
    seq: u64,
    timeout: Duration,
) -> Result<ControlResponse, ClientError> {
    let pending: PendingResponse<ipc::Service, Req, (), ControlResponse, ()> = counter
        .client
        .send_copy(request)
        .map_err(ipc("sending the request"))?;
    counter
        .requests
        .notify()
        .map_err(ipc("notifying the service"))?;
    let end = deadline(timeout);
    loop {
        while let Some(response) = pending.receive().map_err(ipc("receiving the answer"))? {
            if response.payload().request_seq == seq {
                return Ok(*response.payload());
            }
        }
        let left = end.saturating_sub(now_ns());
        if left == 0 {
            return Err(ClientError::Timeout {
                name: name.to_string(),
                what,
                timeout,
            });
        }
        wait_listener(
            &counter.replies,
            Duration::from_nanos(left).min(Duration::from_millis(50)),
        )
        .map_err(ipc("waiting for the answer"))?;
    }
}

/// Publishes velocity requests as one configured source.
#[derive(Debug)]
pub struct Source {
    name: String,
    publisher: Publisher<ipc::Service, VelocityRequest, ()>,
    notifier: Notifier<ipc::Service>,
    seq: u64,
}

impl Source {
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The sequence number of the last request sent (the mux reports it as
    /// `SourceStatus::last_seq`).
    pub fn last_seq(&self) -> u64 {
        self.seq
    }

    /// Sends a request now: parses a [`VelocityRequest`] into a [`ValidRequest`] (one that is not
    /// is refused with [`ClientError::InvalidRequest`] and nothing is sent; a bridge that parsed
    /// what it received hands over the `ValidRequest` itself), stamps it with the current
    /// `CLOCK_MONOTONIC` time (unless a stamp is set) and the next sequence number, and wakes
    /// the service.
    pub fn send<R>(&mut self, request: R) -> Result<(), ClientError>
    where
        R: TryInto<ValidRequest>,
        ClientError: From<R::Error>,
    {
        let mut request: VelocityRequest = *request.try_into()?;
        self.seq += 1;
        request.seq = self.seq;
        if request.stamp_ns == 0 {
            request.stamp_ns = now_ns();
        }
        self.publisher
            .send_copy(request)
            .map_err(ipc("sending the request"))?;
        self.notifier.notify().map_err(ipc("waking the service"))?;
        Ok(())
    }

    /// "Alive, asking for nothing" — the safety monitor's heartbeat.
    pub fn heartbeat(&mut self) -> Result<(), ClientError> {
        self.send(VelocityRequest::heartbeat())
    }

    /// An explicit stop (wins by this source's priority).
    pub fn stop(&mut self) -> Result<(), ClientError> {
        self.send(VelocityRequest::twist(0.0, 0.0))
    }

    /// Lowers the robot's standing speed limit to `mps` for every source; a limit this source
    /// asks above the standing one changes nothing (only the operator raises it:
    /// `ControlKind::SPEED_LIMIT`). Its latest request stands. A limit that is not a positive
    /// number is refused ([`ClientError::InvalidRequest`]).
    pub fn limit_speed(&mut self, mps: f32) -> Result<(), ClientError> {
        self.send(VelocityRequest::speed_limit(mps))
    }

    /// A stop that also engages the locks in `mask` (bit i = lock i of `MuxStatus::locks`).
    pub fn stop_and_lock(&mut self, mask: u32) -> Result<(), ClientError> {
        self.send(VelocityRequest {
            lock_engage: mask,
            ..VelocityRequest::twist(0.0, 0.0)
        })
    }
}

/// A tap of the bus frames.
#[derive(Debug)]
pub struct FrameTap {
    subscriber: Subscriber<ipc::Service, BusFrame, ()>,
    events: Listener<ipc::Service>,
}

impl FrameTap {
    /// Every frame received since the last call.
    pub fn drain(&self, each: impl FnMut(&BusFrame)) -> Result<usize, ClientError> {
        receive_all(&self.subscriber, "receiving frames", each)
    }

    /// Waits at most `timeout` for frames, then drains them.
    pub fn wait(
        &self,
        timeout: Duration,
        each: impl FnMut(&BusFrame),
    ) -> Result<usize, ClientError> {
        // Spend the notifications of the frames drained now, so that the wait is for later ones.
        self.events
            .try_wait(|_| {})
            .map_err(ipc("taking the frames' notifications"))?;
        let n = self.drain(each)?;
        if n > 0 {
            return Ok(n);
        }
        wait_listener(&self.events, timeout).map_err(ipc("waiting for frames"))?;
        Ok(0)
    }
}

/// Every state sample the service publishes, in order: see [`Robot::state_stream`].
///
/// Like every iceoryx2 port it is not `Send`: read it on the thread that opened it.
#[derive(Debug)]
pub struct StateStream {
    subscriber: Subscriber<ipc::Service, ChassisState, ()>,
    events: Listener<ipc::Service>,
    buffer: usize,
}

impl StateStream {
    /// The samples that may queue between two reads (the buffer asked for, clamped).
    pub fn buffer(&self) -> usize {
        self.buffer
    }

    /// Every sample received since the last call, oldest first, without waiting. Returns how
    /// many there were.
    pub fn drain(&self, each: impl FnMut(&ChassisState)) -> Result<usize, ClientError> {
        receive_all(&self.subscriber, "receiving state", each)
    }

    /// Hands the pending samples to `each`, oldest first; with none pending, waits at most
    /// `timeout` for the service's next publication and hands those over. Returns how many there
    /// were (0: none within `timeout`).
    pub fn wait(
        &self,
        timeout: Duration,
        mut each: impl FnMut(&ChassisState),
    ) -> Result<usize, ClientError> {
        // The notifications pending now belong to the samples drained next: spend them, so that
        // the wait below is for later ones.
        self.events
            .try_wait(|_| {})
            .map_err(ipc("taking the state's notifications"))?;
        // A notification may belong to samples an earlier drain already took: the wait goes on.
        drain_or_wait(&self.events, timeout, "waiting for state", || {
            self.drain(&mut each)
        })
    }
}

/// Set by SIGINT or SIGTERM (through [`install_signal_handlers`]) or by [`request_termination`].
static STOP: std::sync::LazyLock<std::sync::Arc<std::sync::atomic::AtomicBool>> =
    std::sync::LazyLock::new(std::sync::Arc::default);

/// The request that makes a simulated chassis send `frames_per_s` extra feedback frames a
/// second on top of its own ([`SimKind::FLOOD`]; 0 stops): a loaded bus for benchmarks and
/// tests. Send it with [`Robot::sim`].
pub fn flood_request(frames_per_s: f64) -> SimRequest {
    SimRequest {
        kind: SimKind::FLOOD,
        flag: 1,
        value: frames_per_s,
        ..SimRequest::default()
    }
}

/// Installs handlers for SIGINT and SIGTERM (idempotent); [`termination_requested`] then tells
/// when one arrived. Call it once at start.
///
/// Each sets a flag of its own. iceoryx2's signal handler keeps only the last signal of any
/// kind, and systemd follows its SIGTERM with a SIGCONT: read from there, the SIGTERM of
/// `systemctl stop` was lost and the program ran on until systemd killed it. iceoryx2's handler
/// is installed first, so that it cannot replace these later; they hand every signal on to it.
pub fn install_signal_handlers() {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let _ = iceoryx2_bb_posix::signal::SignalHandler::last_signal();
        for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            if let Err(e) = signal_hook::flag::register(signal, std::sync::Arc::clone(&STOP)) {
                tracing::error!("installing the handler of signal {signal}: {e}");
            }
        }
    });
}

/// True once SIGINT or SIGTERM arrived (and from then on).
pub fn termination_requested() -> bool {
    install_signal_handlers();
    STOP.load(std::sync::atomic::Ordering::Relaxed)
}

/// Connects to the robot `name` once chassisd serves it — its state and its mux decision (the
/// service opens the state before the mux) — trying every 250 ms and saying once (a warning)
/// that the process waits. `None` when SIGINT or SIGTERM arrives first.
pub fn wait_for_robot(name: &str) -> Option<Robot> {
    let mut ticker = Ticker::new(Duration::from_millis(250));
    let mut first = true;
    while !termination_requested() {
        match Robot::connect(name).and_then(|mut robot| robot.latest_mux().map(|_| robot)) {
            Ok(robot) => return Some(robot),
            Err(e) if std::mem::take(&mut first) => {
                tracing::warn!(error = %e, "waiting for chassisd to serve robot '{name}'");
            }
            Err(e) => tracing::debug!(error = %e, "connecting"),
        }
        ticker.wait();
    }
    None
}

/// Makes [`termination_requested`] true from now on, as a signal would: a thread that ends on
/// its own error stops the process' other loops.
pub fn request_termination() {
    STOP.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// A periodic timer on `CLOCK_MONOTONIC` with absolute deadlines: periods never drift, and a
/// late wake-up skips the missed ones instead of bunching up. A signal ends the wait early.
#[derive(Debug)]
pub struct Ticker {
    period_ns: u64,
    next_ns: u64,
}

impl Ticker {
    /// The first tick is due now.
    pub fn new(period: Duration) -> Self {
        Self {
            period_ns: u64::try_from(period.as_nanos()).unwrap_or(u64::MAX).max(1),
            next_ns: now_ns(),
        }
    }

    /// Waits for the next tick.
    pub fn wait(&mut self) {
        use nix::sys::time::TimeSpec;
        use nix::time::{ClockId, ClockNanosleepFlags, clock_nanosleep};
        let deadline = TimeSpec::from_duration(Duration::from_nanos(self.next_ns));
        let _ = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &deadline,
        );
        let now = now_ns();
        self.next_ns = self.next_ns.saturating_add(self.period_ns);
        if self.next_ns <= now {
            let behind = now - self.next_ns;
            self.next_ns += (behind / self.period_ns + 1) * self.period_ns;
        }
    }
}

/// A client's own publish-subscribe service beside the robot's, `chassis/<name>/<suffix>` (the
/// safety monitor's `SafetyStatus` on `chassis/<name>/safety`), made by [`Robot::publisher`]:
/// history 1 (a late reader gets the latest sample), one publisher, safe overflow, and a paired
/// event service that wakes the readers.
#[derive(Debug)]
pub struct Publication<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> {
    publisher: Publisher<ipc::Service, T, ()>,
    notifier: Notifier<ipc::Service>,
}

impl<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> Publication<T> {
    /// Publishes `sample` and wakes the readers.
    pub fn send(&self, sample: T) -> Result<(), ClientError> {
        self.publisher
            .send_copy(sample)
            .map_err(ipc("publishing"))?;
        self.notifier.notify().map_err(ipc("waking the readers"))?;
        Ok(())
    }
}

/// A reader of a service made with [`Robot::publisher`], opened by [`Robot::subscriber`].
#[derive(Debug)]
pub struct Subscription<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> {
    subscriber: Subscriber<ipc::Service, T, ()>,
    events: Listener<ipc::Service>,
    latest: Option<T>,
}

impl<T: std::fmt::Debug + ZeroCopySend + Copy + 'static> Subscription<T> {
    fn drain(&mut self) -> Result<bool, ClientError> {
        let latest = &mut self.latest;
        Ok(receive_all(&self.subscriber, "receiving", |s| *latest = Some(*s))? > 0)
    }

    /// The newest sample received so far.
    pub fn latest(&mut self) -> Result<Option<T>, ClientError> {
        self.drain()?;
        Ok(self.latest)
    }

    /// Waits at most `timeout` for a sample newer than the ones seen so far. A new reader gets
    /// the publisher's latest sample with its next publication.
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<T>, ClientError> {
        let (subscriber, latest) = (&self.subscriber, &mut self.latest);
        let n = drain_or_wait(&self.events, timeout, "waiting for a sample", || {
            receive_all(subscriber, "receiving", |s| *latest = Some(*s))
        })?;
        Ok(if n > 0 { self.latest } else { None })
    }
}

/// Hands every pending sample of `subscriber` to `each`, oldest first; returns how many.
fn receive_all<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
    subscriber: &Subscriber<ipc::Service, T, ()>,
    what: &'static str,
    mut each: impl FnMut(&T),
) -> Result<usize, ClientError> {
    let mut n = 0;
    while let Some(sample) = subscriber.receive().map_err(ipc(what))? {
        each(&sample);
        n += 1;
    }
    Ok(n)
}

/// Waits at most `timeout` for a notification on `listener`. A signal that interrupts the wait
/// ends it early as a wake-up with nothing, like a timeout: SIGTERM and SIGINT are the caller's
/// to see (its termination flag), and a SIGCONT after a stop (Ctrl-Z, `fg`) or a debugger
/// attaching is no reason for a client to fail. Only a failure of the listener is an error.
pub fn wait_listener(
    listener: &Listener<ipc::Service>,
    timeout: Duration,
) -> Result<(), ListenerWaitError> {
    match listener.timed_wait(|_| {}, timeout) {
        Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(()),
        Err(e) => Err(e),
    }
}

/// Runs `drain` (it returns how many samples it took); while it takes none, waits on `events`
/// until `timeout` has passed and drains again after every wake-up. Returns the count of the
/// drain that took something (0: nothing within `timeout`).
fn drain_or_wait(
    events: &Listener<ipc::Service>,
    timeout: Duration,
    what: &'static str,
    mut drain: impl FnMut() -> Result<usize, ClientError>,
) -> Result<usize, ClientError> {
    let n = drain()?;
    if n > 0 {
        return Ok(n);
    }
    let end = deadline(timeout);
    loop {
        let left = end.saturating_sub(now_ns());
        if left == 0 {
            return Ok(0);
        }
        wait_listener(events, Duration::from_nanos(left)).map_err(ipc(what))?;
        let n = drain()?;
        if n > 0 {
            return Ok(n);
        }
    }
}

impl Robot {
    fn publication_name(&self, suffix: &str) -> Result<String, ClientError> {
        if !valid_robot_name(suffix) {
            return Err(ClientError::BadName(suffix.to_string()));
        }
        Ok(service_name(&self.name, ServiceKind::Publication(suffix)))
    }

    /// Creates (or opens) the service `chassis/<name>/<suffix>` and becomes its one publisher.
    /// `suffix` is 1-16 of a-z 0-9 - _ and must not be one of the robot's own services.
    pub fn publisher<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
        &self,
        suffix: &str,
    ) -> Result<Publication<T>, ClientError> {
        let Writer {
            publisher,
            notifier,
        } = publication::<T>()
            .create(&self.node, &self.publication_name(suffix)?)?
            .publisher()?;
        Ok(Publication {
            publisher,
            notifier,
        })
    }

    /// Opens the service `chassis/<name>/<suffix>` made by [`Robot::publisher`]; `None` when
    /// nobody has made it.
    pub fn subscriber<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
        &self,
        suffix: &str,
    ) -> Result<Option<Subscription<T>>, ClientError> {
        let topic = match publication::<T>().open(&self.node, &self.publication_name(suffix)?) {
            Ok(topic) => topic,
            Err(IpcError::NotFound { .. }) => return Ok(None),
            Err(e) => return Err(e.into()),
        };
        let Reader {
            subscriber,
            listener: events,
        } = topic.subscriber(PUBLICATION.subscriber_max_buffer_size)?;
        Ok(Some(Subscription {
            subscriber,
            events,
            latest: None,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_request_switches_the_simulators_flood_on_at_its_rate() {
        let r = flood_request(2000.0);
        assert_eq!(
            (r.kind, r.flag, r.index, r.value),
            (SimKind::FLOOD, 1, 0, 2000.0)
        );
        assert_eq!(flood_request(0.0).value, 0.0, "0 stops it");
    }
}
