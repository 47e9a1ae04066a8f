//! The robot loop: one thread owns the iceoryx2 ports (a `Robot`, its `foxglove` source and a
//! frame tap), reads the server's [`Inbox`], and logs to the Foxglove channels.
//!
//! Every 10 ms it drains the inbox (velocities, service calls), the frame tap and the newest
//! state and mux decision. It publishes
//!
//! * `/state`, `/tf`, `/pose` for the newest state sample at most every [`Config::state_period`]
//!   of the samples' own stamps (≤ 50 Hz: what a browser keeps up with), `/gps` with them when
//!   the receiver has a fix, `/scene` every 100 ms;
//! * `/mux` on every change of the decision and at 10 Hz;
//! * `/frames` every 100 ms: the frames since the last batch, decoded (at most
//!   [`MAX_FRAMES_PER_BATCH`]; the batch says how many it left out);
//! * `/log`: faults appearing and clearing, link flags, mux changes, service calls.
//!
//! Decoding and encoding are skipped for a channel nobody subscribes to.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::foxglove as fox;
use chassis_client::watch::{self, Severity, Watch};
use chassis_client::{
    BusFrame, ChassisState, ControlStatus, FrameDirection, FrameKind, MuxStatus, Robot, Source,
    Ticker, termination_requested,
};
use chassis_protocols::RobotKind;
use foxglove::messages::{FrameTransforms, LocationFix, Log, PoseInFrame, SceneUpdate};
use foxglove::{Channel, Context, PartialMetadata, RawChannel, Schema};
use serde_json::{Map, Value, json};

use crate::server::Inbox;
use crate::view::{self, Trail};
use chassis_client::foxglove::Body;
use chassis_foxglove_messages::{control_request, response_json};
use chassis_protocols::describe::RobotCodec;

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

/// What the loop needs to know.
#[derive(Debug, Clone)]
pub struct Config {
    pub name: String,
    /// Shortest time between two published state samples.
    pub state_period: Duration,
    /// Publish velocities from clients as the `foxglove` source.
    pub drive: bool,
}

/// The channels the bridge logs to.
#[derive(Debug)]
pub struct Channels {
    pub tf: Channel<FrameTransforms>,
    pub pose: Channel<PoseInFrame>,
    pub scene: Channel<SceneUpdate>,
    pub gps: Channel<LocationFix>,
    pub log: Channel<Log>,
    pub state: Arc<RawChannel>,
    pub mux: Arc<RawChannel>,
    pub frames: Arc<RawChannel>,
}

/// A JSON Schema describing a JSON value's shape: every field with its type.
pub fn schema_of(value: &Value) -> Value {
    match value {
        Value::Null => json!({}),
        Value::Bool(_) => json!({"type": "boolean"}),
        Value::Number(n) if n.is_f64() => json!({"type": "number"}),
        Value::Number(_) => json!({"type": "integer"}),
        Value::String(_) => json!({"type": "string"}),
        Value::Array(items) => json!({
            "type": "array",
            "items": items.first().map_or(json!({}), schema_of),
        }),
        Value::Object(map) => {
            let properties: Map<String, Value> =
                map.iter().map(|(k, v)| (k.clone(), schema_of(v))).collect();
            json!({"type": "object", "properties": properties})
        }
    }
}

fn frames_schema() -> Value {
    json!({
        "type": "object",
        "title": "chassis.Frames",
        "description": "Bus frames since the previous batch, each decoded as `chassis decode` prints it",
        "properties": {
            "count": {"type": "integer", "description": "frames in this batch"},
            "left_out": {"type": "integer", "description": "frames seen but not carried (batch full)"},
            "frames": {"type": "array", "items": {"type": "object", "properties": {
                "stamp_ns": {"type": "integer"},
                "seq": {"type": "integer"},
                "direction": {"type": "string"},
                "raw": {"type": "string"},
                "decoded": {"type": "object"},
                "error": {"type": "string"}
            }}}
        }
    })
}

impl Channels {
    /// Creates the channels in `ctx`.
    pub fn new(ctx: &Arc<Context>) -> anyhow::Result<Self> {
        let json_channel = |topic: &str, schema_name: &str, schema: Value| {
            ctx.channel_builder(topic)
                .message_encoding("json")
                .schema(Schema::new(
                    schema_name,
                    "jsonschema",
                    schema.to_string().into_bytes(),
                ))
                .build_raw()
                .with_context(|| format!("creating {topic}"))
        };
        let state_value = serde_json::to_value(ChassisState::default())?;
        let mux_value = mux_json(&MuxStatus::default())?;
        Ok(Self {
            tf: ctx.channel_builder("/tf").build(),
            pose: ctx.channel_builder("/pose").build(),
            scene: ctx.channel_builder("/scene").build(),
            gps: ctx.channel_builder("/gps").build(),
            log: ctx.channel_builder("/log").build(),
            state: json_channel("/state", "chassis.ChassisState", schema_of(&state_value))?,
            mux: json_channel("/mux", "chassis.MuxStatus", schema_of(&mux_value))?,
            frames: json_channel("/frames", "chassis.Frames", frames_schema())?,
        })
    }
}

/// `/mux`: every field of the decision, with the names spelled out.
pub fn mux_json(mux: &MuxStatus) -> serde_json::Result<Value> {
    let mut value = serde_json::to_value(mux)?;
    if let Some(obj) = value.as_object_mut() {
        obj.insert(
            "active_name".into(),
            mux.active().map_or("", |s| s.name()).into(),
        );
        obj.insert(
            "zero_reason_name".into(),
            chassis_client::ZeroReason::name(mux.zero_reason).into(),
        );
        obj.insert("locks_held".into(), watch::held_locks(mux).into());
    }
    Ok(value)
}

/// Lets at most one sample per period through on average, judged on the samples' own stamps,
/// with a quarter period of slack for the loop's jitter (a sample 19.5 ms after the last one
/// of a 20 ms period passes; the next one is then due 40 ms after the first).
#[derive(Debug, Clone, Copy)]
pub struct Decimator {
    period_ns: u64,
    next_ns: Option<u64>,
}

impl Decimator {
    pub fn new(period: Duration) -> Self {
        Self {
            period_ns: u64::try_from(period.as_nanos()).unwrap_or(u64::MAX),
            next_ns: None,
        }
    }

    /// True when the sample stamped `stamp_ns` is to be published.
    pub fn pass(&mut self, stamp_ns: u64) -> bool {
        let slack = self.period_ns / 4;
        if let Some(next) = self.next_ns
            && stamp_ns.saturating_add(slack) < next
        {
            return false;
        }
        let after_stamp = stamp_ns.saturating_add(self.period_ns - slack);
        self.next_ns = Some(self.next_ns.map_or(after_stamp, |next| {
            next.saturating_add(self.period_ns).max(after_stamp)
        }));
        true
    }
}

/// `CLOCK_MONOTONIC` → Unix epoch, measured once.
#[derive(Debug, Clone, Copy)]
struct WallClock {
    offset_ns: i128,
}

impl WallClock {
    // The loop's one reading of the wall clock, at start, to stamp messages in Unix time.
    #[allow(clippy::disallowed_methods)]
    fn measure() -> Self {
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        Self {
            offset_ns: wall - i128::from(chassis_client::now_ns()),
        }
    }

    fn wall(self, monotonic_ns: u64) -> u64 {
        u64::try_from(i128::from(monotonic_ns) + self.offset_ns).unwrap_or(0)
    }
}

/// Runs until SIGINT / SIGTERM.
pub fn run(config: &Config, channels: &Channels, inbox: &Receiver<Inbox>) -> anyhow::Result<()> {
    let Some(mut robot) = connect(&config.name) else {
        return Ok(());
    };
    let tap = robot.frames(TAP_BUFFER).context("opening the frame tap")?;
    let mut source = Teleop {
        enabled: config.drive,
        source: None,
        warned: false,
    };
    let clock = WallClock::measure();
    let mut lp = Loop {
        channels,
        clock,
        body: None,
        codec: None,
        wire_protocol: 0,
        trail: Trail::default(),
        watch: Watch::default(),
        last_seq: None,
        decimator: Decimator::new(config.state_period),
        last_scene_ns: 0,
        last_gps_ns: 0,
        last_mux: None,
        last_mux_published_ns: 0,
        batch: Vec::new(),
        left_out: 0,
        last_batch_ns: 0,
    };
    lp.log(
        Severity::Info,
        format!("bridging robot '{}'", config.name),
        chassis_client::now_ns(),
    );
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
        let want_frames = channels.frames.has_sinks();
        tap.drain(|frame| lp.frame(frame, want_frames))
            .context("reading the frame tap")?;
        if let Some(state) = robot.latest_state()? {
            lp.state(&state);
        }
        if let Some(mux) = robot.latest_mux()? {
            lp.mux(&mux, now);
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

/// Connects to the robot, waiting for chassisd to serve it; `None` when asked to stop first.
fn connect(name: &str) -> Option<Robot> {
    chassis_client::wait_for_robot(name, Duration::from_millis(250), |e, first| {
        if first {
            tracing::warn!(error = %e, "waiting for chassisd to serve robot '{name}'");
        } else {
            tracing::debug!(error = %e, "connecting");
        }
    })
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
    clock: WallClock,
    body: Option<(u8, Body)>,
    /// The describer of `/frames`, for (robot kind, wire protocol) of the last state sample.
    codec: Option<((u8, u8), RobotCodec)>,
    wire_protocol: u8,
    trail: Trail,
    watch: Watch,
    last_seq: Option<u64>,
    decimator: Decimator,
    last_scene_ns: u64,
    last_gps_ns: u64,
    last_mux: Option<MuxStatus>,
    last_mux_published_ns: u64,
    batch: Vec<Value>,
    left_out: u64,
    last_batch_ns: u64,
}

impl Loop<'_> {
    fn log(&self, level: Severity, message: String, monotonic_ns: u64) {
        let wall = self.clock.wall(monotonic_ns);
        self.channels.log.log_with_time(
            &fox::log_message(view::LOG_NAME, level, message, wall),
            wall,
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
        self.wire_protocol = state.system.wire_protocol;
        for (level, text) in self.watch.state(state) {
            self.log(level, text, state.stamp_ns);
        }
        self.trail.see(state);
        if !self.decimator.pass(state.stamp_ns) {
            return;
        }
        let wall = self.clock.wall(state.stamp_ns);
        if self
            .body
            .as_ref()
            .is_none_or(|(kind, _)| *kind != state.robot)
            && let Some(body) = fox::body_of(state.robot)
        {
            self.body = Some((state.robot, body));
        }
        let c = self.channels;
        if c.state.has_sinks() {
            match serde_json::to_vec(state) {
                Ok(bytes) => c
                    .state
                    .log_with_meta(&bytes, PartialMetadata::with_log_time(wall)),
                Err(e) => tracing::debug!(error = %e, "encoding a state sample"),
            }
        }
        c.pose.log_with_time(&fox::pose_in_frame(state, wall), wall);
        if let Some((_, body)) = &self.body {
            c.tf.log_with_time(&fox::transforms(state, body, wall), wall);
            if state.stamp_ns.saturating_sub(self.last_scene_ns) >= SCENE_PERIOD_NS {
                self.last_scene_ns = state.stamp_ns;
                if c.scene.has_sinks() {
                    c.scene
                        .log_with_time(&view::scene(state, body, &self.trail, wall), wall);
                }
            }
        }
        let gps_stamp = state.group_stamp_ns[chassis_client::Group::Gps.index()];
        if gps_stamp != self.last_gps_ns
            && let Some(fix) = fox::location_fix(state, wall)
        {
            self.last_gps_ns = gps_stamp;
            c.gps.log_with_time(&fix, wall);
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
                    PartialMetadata::with_log_time(self.clock.wall(mux.stamp_ns)),
                ),
                Err(e) => tracing::debug!(error = %e, "encoding a mux decision"),
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
        let kind = self.last_state_robot();
        let key = (kind, self.wire_protocol);
        if self.codec.as_ref().is_none_or(|(k, _)| *k != key)
            && let Some(robot) = RobotKind::from_id(kind)
        {
            // A robot with two protocols (SCOUT MINI, SCOUT 2.0, BUNKER) in the one it speaks.
            self.codec = Some((key, robot.entry().codec_for_wire(self.wire_protocol)));
        }
        let mut entry = Map::new();
        entry.insert("stamp_ns".into(), frame.stamp_ns.into());
        entry.insert("seq".into(), frame.seq.into());
        let direction = if frame.direction == FrameDirection::TX {
            "tx"
        } else {
            "rx"
        };
        entry.insert("direction".into(), direction.into());
        let hex: String = frame.payload().iter().map(|b| format!("{b:02X}")).collect();
        match frame.kind {
            FrameKind::CAN => {
                entry.insert("raw".into(), format!("{:03X}#{hex}", frame.can_id).into());
                let can = if frame.flags & BusFrame::EXTENDED_ID != 0 {
                    chassis_protocols::CanFrame::new_extended(frame.can_id, frame.payload())
                } else {
                    chassis_protocols::CanFrame::new(frame.can_id, frame.payload())
                };
                match (&self.codec, can) {
                    (Some((_, codec)), Ok(can)) => match codec.decode_can(&can) {
                        Ok(decoded) => {
                            entry.insert("decoded".into(), Value::Object(decoded));
                        }
                        Err(e) => {
                            entry.insert("error".into(), e.to_string().into());
                        }
                    },
                    (_, Err(e)) => {
                        entry.insert("error".into(), e.to_string().into());
                    }
                    (None, Ok(_)) => {
                        entry.insert("error".into(), "robot not known yet".into());
                    }
                }
                self.batch.push(Value::Object(entry));
            }
            FrameKind::GPS => {
                entry.insert(
                    "raw".into(),
                    String::from_utf8_lossy(frame.payload()).trim_end().into(),
                );
                self.batch.push(Value::Object(entry));
            }
            _ => {
                entry.insert("raw".into(), hex.into());
                let decoded = self
                    .codec
                    .as_mut()
                    .map(|(_, codec)| codec.push_serial(frame.payload()))
                    .unwrap_or_default();
                // A serial read may complete several frames, or none: one entry per frame.
                if decoded.is_empty() {
                    self.batch.push(Value::Object(entry));
                    return;
                }
                for item in decoded {
                    let mut e = entry.clone();
                    match item {
                        Ok(fields) => e.insert("decoded".into(), Value::Object(fields)),
                        Err(err) => e.insert("error".into(), err.to_string().into()),
                    };
                    self.batch.push(Value::Object(e));
                }
            }
        }
    }

    fn last_state_robot(&self) -> u8 {
        self.body.as_ref().map_or(0, |(kind, _)| *kind)
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
            Ok(bytes) => self
                .channels
                .frames
                .log_with_meta(&bytes, PartialMetadata::with_log_time(self.clock.wall(now))),
            Err(e) => tracing::debug!(error = %e, "encoding a frame batch"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn passed(period_ms: u64, samples: impl Iterator<Item = u64>) -> usize {
        let mut d = Decimator::new(Duration::from_millis(period_ms));
        samples.filter(|&t| d.pass(t)).count()
    }

    #[test]
    fn the_state_is_decimated_to_the_period_on_average() {
        // A sample every 4 ms for 10 s: 50 Hz out.
        let n = passed(20, (0..2500).map(|i| i * 4_000_000));
        assert!((499..=501).contains(&n), "{n}");
        // Samples every 10 ms, read with ±1 ms of jitter: still every other one.
        let jitter = |i: u64| if i.is_multiple_of(2) { 0 } else { 1_000_000 };
        let n = passed(20, (0..1000).map(|i| i * 10_000_000 + jitter(i)));
        assert!((499..=501).contains(&n), "{n}");
        // A 20 ms source a little early now and then loses nothing.
        let n = passed(
            20,
            (0..500u64).map(|i| i * 20_000_000 - if i.is_multiple_of(3) { 0 } else { 400_000 }),
        );
        assert_eq!(n, 500);
        // Slower samples all pass.
        assert_eq!(passed(20, (0..100).map(|i| i * 50_000_000)), 100);
    }

    #[test]
    fn the_state_schema_names_the_plotted_speed() {
        let schema = schema_of(&serde_json::to_value(ChassisState::default()).unwrap());
        assert_eq!(
            schema["properties"]["motion"]["properties"]["linear_mps"]["type"],
            "number"
        );
        let mux = schema_of(&mux_json(&MuxStatus::default()).unwrap());
        assert_eq!(mux["properties"]["active_name"]["type"], "string");
    }
}
