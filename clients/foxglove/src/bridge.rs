//! The robot loops: one thread per robot owns its iceoryx2 ports (a `Robot`, its `foxglove`
//! source and a frame tap), reads the server's [`Inbox`] for that robot, and logs to the robot's
//! Foxglove channels (under `/<name>` and its frames under `<name>/` when the bridge serves
//! several robots: [`Naming`]).
//!
//! It draws the robot chassisd describes on `chassis/<name>/robot` — the body's outline, its
//! range sensors and the codec of its bus — and takes a newer description when one is published
//! (protocol detection deciding, a restarted chassisd). Every 10 ms it drains the inbox
//! (velocities, service calls), the frame tap and the newest state and mux decision. It
//! publishes
//!
//! * `/state`, `/tf`, `/pose` for the newest state sample at most every [`Config::state_period`]
//!   of the samples' own stamps (≤ 50 Hz: what a browser keeps up with), `/gps` with them when
//!   the receiver has a fix, `/scene` every 100 ms;
//! * `/mux` on every change of the decision and at 10 Hz;
//! * `/frames` every 100 ms: the frames since the last batch, decoded (at most
//!   [`MAX_FRAMES_PER_BATCH`]; the batch says how many it left out);
//! * `/log`: faults appearing and clearing, link flags, mux changes, service calls.
//!
//! Decoding and encoding are skipped for a channel nobody subscribes to. Service calls are
//! answered with chassisd's response as it is (`{"ok", "status", "message"}`).

use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::foxglove::{self as fox, Body};
use chassis_client::watch::{self, Severity, Watch};
use chassis_client::{
    BusFrame, ChassisState, ControlStatus, Decimator, MuxStatus, Robot, RobotDescription,
    SafetyStatus, Source, Ticker, WallClock, termination_requested,
};
use chassis_foxglove_messages::{control_request, response_json};
use chassis_protocols::frame_json::BoxedCodec;
use foxglove::PartialMetadata;
use serde_json::{Value, json};

use crate::convert::{self, Trail, frame_entries, mux_json, safety_json};
use crate::naming::Naming;
use crate::server::{self, Channels, Config, Inbox, Route};

/// Frames a `/frames` batch carries at most.
pub const MAX_FRAMES_PER_BATCH: usize = 1000;
/// Frames the tap may hold between two drains (10 ms: 40 on a saturated CAN bus).
const TAP_BUFFER: usize = 1024;
/// The loop's period.
const TICK: Duration = Duration::from_millis(10);
const SCENE_PERIOD_NS: u64 = 100_000_000;
const MUX_PERIOD_NS: u64 = 100_000_000;
const FRAMES_PERIOD_NS: u64 = 100_000_000;
/// How long a service call waits for chassisd's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);
/// How long a new connection waits for the robot's description before drawing without it.
const DESCRIPTION_WAIT: Duration = Duration::from_secs(2);

/// One robot's side of the bridge.
struct Served {
    naming: Naming,
    channels: Channels,
    inbox: Receiver<Inbox>,
}

/// Serves the robots on the WebSocket until SIGINT / SIGTERM, or until one robot's loop fails
/// (the others then stop too, and the failure is the bridge's).
pub fn run(config: &Config) -> anyhow::Result<()> {
    let ctx = foxglove::Context::new();
    let prefixed = config.names.len() > 1;
    let mut served = Vec::new();
    let mut routes = Vec::new();
    for name in &config.names {
        let naming = Naming::of(name, prefixed);
        let (tx, rx) = mpsc::channel();
        served.push(Served {
            channels: Channels::new(&ctx, &naming)?,
            naming: naming.clone(),
            inbox: rx,
        });
        routes.push(Route { naming, inbox: tx });
    }
    let handle = server::start(&ctx, config, &routes)?;
    drop(routes);
    let quoted: Vec<String> = config.names.iter().map(|n| format!("'{n}'")).collect();
    eprintln!(
        "chassis-foxglove: robot{} {}{} on ws://{}:{}{}",
        if prefixed { "s" } else { "" },
        quoted.join(", "),
        if prefixed {
            " (each under /<name>/…)"
        } else {
            ""
        },
        config.bind,
        handle.port(),
        if config.drive { "" } else { " (read-only)" }
    );
    let result = std::thread::scope(|scope| {
        let loops: Vec<_> = served
            .into_iter()
            .map(|robot| {
                scope.spawn(move || {
                    let name = robot.naming.robot.clone();
                    let result = robot_loop(config, &robot);
                    if result.is_err() {
                        chassis_client::request_termination();
                    }
                    result.with_context(|| format!("robot '{name}'"))
                })
            })
            .collect();
        loops
            .into_iter()
            .map(|handle| {
                handle
                    .join()
                    .unwrap_or_else(|_| Err(anyhow::anyhow!("a robot loop panicked")))
            })
            .collect::<anyhow::Result<Vec<()>>>()
    });
    handle.stop().wait_blocking();
    result.map(drop)
}

/// The loop on one robot's side of the server, until SIGINT / SIGTERM or another robot's loop
/// failed.
fn robot_loop(config: &Config, served: &Served) -> anyhow::Result<()> {
    let Served {
        naming,
        channels,
        inbox,
    } = served;
    let Some(mut robot) = chassis_client::wait_for_robot(&naming.robot) else {
        return Ok(());
    };
    let tap = robot.frames(TAP_BUFFER).context("opening the frame tap")?;
    let mut source = Teleop {
        enabled: config.drive,
        source: None,
        warned: false,
    };
    let mut lp = Loop {
        channels,
        naming,
        clock: WallClock::measure(),
        described: None,
        body: None,
        codec: None,
        trail: Trail::default(),
        watch: Watch::default(),
        last_seq: None,
        decimator: Decimator::new(config.state_period),
        last_scene_ns: 0,
        last_gps_ns: 0,
        last_mux: None,
        last_mux_published_ns: 0,
        last_safety: None,
        last_safety_published_ns: 0,
        batch: Vec::new(),
        left_out: 0,
        last_batch_ns: 0,
    };
    lp.log(
        Severity::Info,
        format!("bridging robot '{}'", naming.robot),
        chassis_client::now_ns(),
    );
    match robot.description(DESCRIPTION_WAIT) {
        Ok(d) => lp.describe(&d),
        Err(e) => tracing::warn!(
            error = %e,
            "no description of robot '{}' yet: no body, sensors or decoded frames until one comes",
            naming.robot
        ),
    }
    let mut ticker = Ticker::new(TICK);
    while !termination_requested() {
        loop {
            match inbox.try_recv() {
                Ok(message) => lp.handle(message, &mut robot, &mut source),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return Ok(()),
            }
        }
        let now = chassis_client::now_ns();
        if let Some(d) = robot.latest_description()? {
            lp.describe(&d);
        }
        let want_frames = channels.frames.has_sinks();
        tap.drain(|frame| lp.frame(frame, want_frames))
            .context("reading the frame tap")?;
        if let Some(state) = robot.latest_state()? {
            lp.state(&state);
        }
        if let Some(mux) = robot.latest_mux()? {
            lp.mux(&mux, now);
        }
        if let Some(safety) = robot.latest_safety()? {
            lp.safety(&safety, now);
        }
        lp.flush_frames(now);
        ticker.wait();
    }
    if let Some(source) = source.source.as_mut()
        && let Err(e) = source.stop()
    {
        tracing::debug!(error = %e, "stopping the foxglove source");
    }
    Ok(())
}

/// The `foxglove` velocity source, opened when the first velocity arrives (chassisd may start
/// after the bridge) and again after a failure.
struct Teleop {
    enabled: bool,
    source: Option<Source>,
    warned: bool,
}

impl Teleop {
    fn get(&mut self, robot: &mut Robot) -> Option<&mut Source> {
        if !self.enabled {
            return None;
        }
        if self.source.is_none() {
            match robot.source("foxglove") {
                Ok(source) => {
                    self.source = Some(source);
                    self.warned = false;
                }
                Err(e) if !self.warned => {
                    self.warned = true;
                    tracing::warn!(error = %e, "no 'foxglove' source: the Teleop panel cannot drive");
                }
                Err(e) => tracing::debug!(error = %e, "opening the foxglove source"),
            }
        }
        self.source.as_mut()
    }
}

struct Loop<'a> {
    channels: &'a Channels,
    naming: &'a Naming,
    clock: WallClock,
    /// The description drawn (`seq`, `stamp_ns`: a restarted chassisd counts again).
    described: Option<(u64, u64)>,
    body: Option<Body>,
    /// The describer of `/frames`, for the robot and protocol of the description.
    codec: Option<BoxedCodec>,
    trail: Trail,
    watch: Watch,
    last_seq: Option<u64>,
    decimator: Decimator,
    last_scene_ns: u64,
    last_gps_ns: u64,
    last_mux: Option<MuxStatus>,
    last_mux_published_ns: u64,
    last_safety: Option<SafetyStatus>,
    last_safety_published_ns: u64,
    batch: Vec<Value>,
    left_out: u64,
    last_batch_ns: u64,
}

impl Loop<'_> {
    fn log(&self, level: Severity, message: String, monotonic_ns: u64) {
        let wall = self.clock.wall_ns(monotonic_ns);
        self.channels.log.log_with_time(
            &fox::log_message(convert::LOG_NAME, level, message, wall),
            wall,
        );
    }

    /// Takes the robot's body, sensors and codec from a description not drawn yet.
    fn describe(&mut self, d: &RobotDescription) {
        if self.described == Some((d.seq, d.stamp_ns)) {
            return;
        }
        self.described = Some((d.seq, d.stamp_ns));
        self.body = Some(Body::of(d));
        self.codec = chassis_protocols::registry::profile_for_description(d).map(|p| p.codec());
        if self.codec.is_none() {
            tracing::warn!(
                kind = d.kind,
                "a robot kind this view does not know: frames not decoded"
            );
        }
        self.log(
            Severity::Info,
            format!(
                "robot: {} ({}), {} range sensors",
                d.display_name(),
                d.model(),
                self.body.as_ref().map_or(0, |b| b.sensors.len())
            ),
            d.stamp_ns,
        );
    }

    fn handle(&mut self, message: Inbox, robot: &mut Robot, teleop: &mut Teleop) {
        match message {
            Inbox::Twist(request) => match teleop.get(robot) {
                Some(source) => {
                    if let Err(e) = source.send(request) {
                        tracing::warn!(error = %e, "publishing a Teleop velocity");
                    }
                }
                None => tracing::debug!("velocity ignored: no foxglove source"),
            },
            Inbox::TwistEnded => {
                if let Some(source) = teleop.source.as_mut()
                    && let Err(e) = source.stop()
                {
                    tracing::warn!(error = %e, "stopping the foxglove source");
                }
            }
            Inbox::Call {
                action,
                payload,
                responder,
            } => {
                let answer = control_request(action, &payload)
                    .map_err(|e| e.to_string())
                    .and_then(|request| {
                        robot
                            .control(request, ANSWER_TIMEOUT)
                            .map_err(|e| format!("asking chassisd: {e}"))
                    });
                let now = chassis_client::now_ns();
                match answer {
                    Ok(response) => {
                        let level = if response.is_ok() {
                            Severity::Info
                        } else {
                            Severity::Warning
                        };
                        self.log(
                            level,
                            format!(
                                "{}: {} {}",
                                action.name(),
                                ControlStatus::name(response.status),
                                response.message()
                            ),
                            now,
                        );
                        responder.respond_ok(response_json(&response).to_string());
                    }
                    Err(e) => {
                        self.log(Severity::Error, format!("{}: {e}", action.name()), now);
                        responder.respond_err(e);
                    }
                }
            }
        }
    }

    fn state(&mut self, state: &ChassisState) {
        if self.last_seq == Some(state.seq) {
            return;
        }
        self.last_seq = Some(state.seq);
        for (level, text) in self.watch.state(state) {
            self.log(level, text, state.stamp_ns);
        }
        self.trail.see(state);
        if !self.decimator.pass(state.stamp_ns) {
            return;
        }
        let wall = self.clock.wall_ns(state.stamp_ns);
        let c = self.channels;
        if c.state.has_sinks() {
            match serde_json::to_vec(state) {
                Ok(bytes) => c
                    .state
                    .log_with_meta(&bytes, PartialMetadata::with_log_time(wall)),
                Err(e) => tracing::debug!(error = %e, "encoding a state sample"),
            }
        }
        let n = self.naming;
        c.pose
            .log_with_time(&n.pose(fox::pose_in_frame(state, wall)), wall);
        if let Some(body) = &self.body {
            c.tf.log_with_time(&n.transforms(fox::transforms(state, body, wall)), wall);
            if state.stamp_ns.saturating_sub(self.last_scene_ns) >= SCENE_PERIOD_NS {
                self.last_scene_ns = state.stamp_ns;
                if c.scene.has_sinks() {
                    c.scene.log_with_time(
                        &n.scene(convert::scene(state, body, &self.trail, wall)),
                        wall,
                    );
                }
            }
        }
        let gps_stamp = state.group_stamp_ns[chassis_client::Group::Gps.index()];
        if gps_stamp != self.last_gps_ns
            && let Some(fix) = fox::location_fix(state, wall)
        {
            self.last_gps_ns = gps_stamp;
            c.gps.log_with_time(&n.fix(fix), wall);
        }
    }

    fn mux(&mut self, mux: &MuxStatus, now: u64) {
        let changed = self.last_mux.is_none_or(|last| {
            (last.active_source, last.zero_reason, last.clamp_flags)
                != (mux.active_source, mux.zero_reason, mux.clamp_flags)
                || watch::held_locks(&last) != watch::held_locks(mux)
        });
        if let Some((level, text)) = self.watch.mux(mux) {
            self.log(level, text, mux.stamp_ns);
        }
        if self.last_mux.is_some_and(|last| last.seq == mux.seq) && !changed {
            return;
        }
        if !changed && now.saturating_sub(self.last_mux_published_ns) < MUX_PERIOD_NS {
            return;
        }
        self.last_mux = Some(*mux);
        self.last_mux_published_ns = now;
        if self.channels.mux.has_sinks() {
            match mux_json(mux).and_then(|v| serde_json::to_vec(&v)) {
                Ok(bytes) => self.channels.mux.log_with_meta(
                    &bytes,
                    PartialMetadata::with_log_time(self.clock.wall_ns(mux.stamp_ns)),
                ),
                Err(e) => tracing::debug!(error = %e, "encoding a mux decision"),
            }
        }
    }

    /// `/safety` on every change of the decision, else at the mux's period.
    fn safety(&mut self, status: &SafetyStatus, now: u64) {
        let decision = |s: &SafetyStatus| (s.action, s.active_rules, s.unfollowed, s.estop);
        let changed = self
            .last_safety
            .is_none_or(|last| decision(&last) != decision(status));
        if self.last_safety.is_some_and(|last| last.seq == status.seq) && !changed {
            return;
        }
        if !changed && now.saturating_sub(self.last_safety_published_ns) < MUX_PERIOD_NS {
            return;
        }
        self.last_safety = Some(*status);
        self.last_safety_published_ns = now;
        if self.channels.safety.has_sinks() {
            match safety_json(status).and_then(|v| serde_json::to_vec(&v)) {
                Ok(bytes) => self.channels.safety.log_with_meta(
                    &bytes,
                    PartialMetadata::with_log_time(self.clock.wall_ns(status.stamp_ns)),
                ),
                Err(e) => tracing::debug!(error = %e, "encoding a safety decision"),
            }
        }
    }

    fn frame(&mut self, frame: &BusFrame, wanted: bool) {
        if !wanted {
            return;
        }
        if self.batch.len() >= MAX_FRAMES_PER_BATCH {
            self.left_out += 1;
            return;
        }
        self.batch.extend(frame_entries(frame, self.codec.as_mut()));
    }

    fn flush_frames(&mut self, now: u64) {
        if now.saturating_sub(self.last_batch_ns) < FRAMES_PERIOD_NS {
            return;
        }
        self.last_batch_ns = now;
        if self.batch.is_empty() && self.left_out == 0 {
            return;
        }
        let batch = json!({
            "count": self.batch.len(),
            "left_out": self.left_out,
            "frames": std::mem::take(&mut self.batch),
        });
        self.left_out = 0;
        match serde_json::to_vec(&batch) {
            Ok(bytes) => self.channels.frames.log_with_meta(
                &bytes,
                PartialMetadata::with_log_time(self.clock.wall_ns(now)),
            ),
            Err(e) => tracing::debug!(error = %e, "encoding a frame batch"),
        }
    }
}
