//! `chassis record` and `chassis replay`.
//!
//! # `chassis record FILE` — MCAP
//!
//! Opens in Foxglove (or any MCAP tool). Three channels of JSON messages each described by a
//! JSON Schema (schema encoding `jsonschema`):
//!
//! | topic | schema | one message per |
//! | --- | --- | --- |
//! | `/chassis/<name>/frames` | `chassis.BusFrame` | frame on the bus, both directions: `stamp_ns`, `seq`, `direction` (`rx`/`tx`), `kind` (`can`/`serial`/`gps`), `can_id`, `extended`, `len`, `data` (the payload as hex) |
//! | `/chassis/<name>/state` | `chassis.ChassisState` | state sample published: every one, in order (`seq` numbers them; gaps are counted) |
//! | `/chassis/<name>/mux` | `chassis.MuxStatus` | mux decision seen (on change and at 10 Hz) |
//!
//! and beside them the well-known Foxglove schemas (protobuf), as the live view of
//! `chassis-foxglove` publishes them, so a recording replayed in Foxglove's 3D panel looks the
//! same:
//!
//! | topic | schema | what |
//! | --- | --- | --- |
//! | `/tf` | `foxglove.FrameTransforms` | odom → base_link from the odometry, base_link → the sensor frames; at most 50 per second |
//! | `/pose` | `foxglove.PoseInFrame` | the robot in odom, with `/tf` |
//! | `/gps` | `foxglove.LocationFix` | each new GPS fix |
//! | `/log` | `foxglove.Log` | faults appearing and clearing, link flags, changes of the mux's winner |
//!
//! Their timestamps are the samples' `stamp_ns`, on the same clock as every `log_time`.
//!
//! Every message's `log_time` and `publish_time` are the sample's own `stamp_ns`: the
//! **`CLOCK_MONOTONIC`** time of the machine that recorded (time since boot), not the wall clock.
//! The metadata record `chassis` holds what tools need to convert: `wall_minus_monotonic_ns`
//! (add it to a stamp for Unix-epoch ns), `start_wall_ns`, `start_monotonic_ns`, and the
//! `robot` (`titan`, `scout-mini`, `xbot`) and `name` recorded — `chassis replay` reads the robot
//! from it. The metadata record `chassis.summary`, written at the end, holds the counts: frames,
//! lost frames and sequence gaps, states, lost states and their gaps, mux decisions, duration.
//!
//! # `chassis record --candump FILE` — can-utils log
//!
//! `(SECS.MICROS) IFACE ID#HEX` lines as `candump -l` writes them: the time is the wall clock
//! (the frame's monotonic stamp plus the offset measured at start, so the spacing is exact), the
//! interface is `--iface` or the robot's name. `candump -l` has no direction, so only the frames
//! the chassis sent (RX) are written; with `--tx` both directions are, each line ending in ` R`
//! or ` T` (what `chassis replay` and `chassis decode` understand). The XBot's serial stream is
//! not CAN: record it as MCAP.
//!
//! # Losing nothing
//!
//! A thread of its own drains the frame tap (`Robot::frames`, 2048 frames of buffer) as soon as
//! the service's event says there is something, and hands batches to the writer; a full
//! 500 kbit/s CAN bus (≈ 4000 frames/s) leaves the buffer nearly empty. Every `BusFrame::seq`
//! gap is counted and reported at the end. The writer drains a state stream
//! (`Robot::state_stream`, `STATE_BUFFER` = 256 samples) whenever a batch of frames arrives, at
//! least every 50 ms: every state sample published is recorded (a saturated bus publishes one
//! per frame that changes the state, in bursts of ≈ 18 every 4 ms), and `ChassisState::seq`
//! gaps are counted too. Reading is from shared memory: the recorder never slows the service.
//! SIGINT / SIGTERM (or `--duration`) end the recording cleanly: the MCAP summary is written,
//! the summary printed on stderr.
//!
//! # `chassis replay FILE`
//!
//! Starts `chassisd --robot R --name N --bus replay:FILE@SPEED --no-safety-monitor` (the
//! `chassisd` next to this executable), which plays the recorded RX frames into the service
//! through the replay bus (see chassisd's `bus::replay`), at the recorded speed, `--speed X` or
//! `--max-speed`. It echoes the replayed state at most 10 times a second (`--quiet`: not at
//! all; `--json`: as JSON lines), and when the recording has played (the service reports its
//! bus down after frames arrived) it stops chassisd and prints the final state. Ctrl-C stops
//! both earlier. The robot comes from the MCAP metadata; a candump log needs `--robot`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, bail};
use chassis_client::Group;
use chassis_client::foxglove::{self as view, schema_of};
use chassis_client::layout::Layout;
use chassis_client::watch::{Severity, Watch};
use chassis_client::{
    BusFrame, ChassisState, FrameDirection, FrameKind, LinkFlags, MuxStatus, Robot, STATE_BUFFER,
    StateStream, install_signal_handlers, now_ns, termination_requested, valid_robot_name,
};
use chassis_protocols::{CanFrame, RobotKind};
use clap::Args;
use foxglove::Encode;
use foxglove::messages::{FrameTransforms, LocationFix, Log, PoseInFrame};
use serde::Serialize;
use serde_json::{Value, json};

use crate::live::{state_line, write_sample};

/// Frames the tap may hold between two drains.
const TAP_BUFFER: usize = 2048;
/// Name of the metadata record with the robot and the clocks.
const METADATA_NAME: &str = "chassis";
/// Name of the metadata record with the counts, written at the end.
const SUMMARY_NAME: &str = "chassis.summary";

#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Output file: MCAP (frames, state, mux decisions), or a can-utils log with --candump.
    pub file: PathBuf,
    /// The robot's name (chassisd --name).
    #[arg(long, default_value = "titan")]
    pub name: String,
    /// Write the CAN frames as a `candump -l` log instead of MCAP.
    #[arg(long)]
    pub candump: bool,
    /// With --candump: write the frames the service sent too, each line ending in R or T.
    #[arg(long, requires = "candump")]
    pub tx: bool,
    /// With --candump: the interface written on each line (default: the robot's name).
    #[arg(long, requires = "candump")]
    pub iface: Option<String>,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    pub duration: Option<f64>,
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// A recording: MCAP or a candump log.
    pub file: PathBuf,
    /// The robot (default: the one the MCAP recording names; required for a candump log).
    #[arg(long)]
    pub robot: Option<RobotKind>,
    /// The replayed robot's name (chassis/NAME/…); keep it apart from a live robot's.
    #[arg(long, default_value = "replay")]
    pub name: String,
    /// As fast as the service takes the frames.
    #[arg(long, conflicts_with = "speed")]
    pub max_speed: bool,
    /// Speed factor: 1 is the recorded timing, 2 twice as fast.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// chassisd's configuration file (profile parameters, limits).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print states as JSON lines.
    #[arg(long)]
    pub json: bool,
    /// Print only the final state.
    #[arg(long)]
    pub quiet: bool,
}

/// Counts `BusFrame::seq` gaps: frames the tap dropped between two drains.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct GapCounter {
    last: Option<u64>,
    /// Frames missing.
    pub lost: u64,
    /// Places where frames were missing.
    pub gaps: u64,
    /// Times the sequence started again (the service restarted).
    pub restarts: u64,
}

impl GapCounter {
    pub fn see(&mut self, seq: u64) {
        if let Some(last) = self.last {
            if seq > last + 1 {
                self.lost += seq - last - 1;
                self.gaps += 1;
            } else if seq <= last {
                self.restarts += 1;
            }
        }
        self.last = Some(seq);
    }
}

/// A frame as the MCAP frames channel has it.
#[derive(Debug, Serialize)]
pub struct FrameRecord {
    pub stamp_ns: u64,
    pub seq: u64,
    pub direction: &'static str,
    pub kind: &'static str,
    pub can_id: u32,
    pub extended: bool,
    pub len: u8,
    pub data: String,
}

impl FrameRecord {
    pub fn of(frame: &BusFrame) -> Self {
        Self {
            stamp_ns: frame.stamp_ns,
            seq: frame.seq,
            direction: FrameDirection::name(frame.direction),
            kind: FrameKind::name(frame.kind),
            can_id: frame.can_id,
            extended: frame.flags & BusFrame::EXTENDED_ID != 0,
            len: frame.len,
            data: hex::encode_upper(frame.payload()),
        }
    }
}

/// Adds the channel `topic` with the Foxglove schema of `T`.
fn foxglove_channel<T: Encode>(
    writer: &mut mcap::Writer<BufWriter<File>>,
    topic: &str,
) -> anyhow::Result<u16> {
    let schema = T::get_schema().with_context(|| format!("no schema for {topic}"))?;
    let schema_id = writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
    Ok(writer.add_channel(
        schema_id,
        topic,
        &T::get_message_encoding(),
        &BTreeMap::new(),
    )?)
}

/// The JSON Schema of the frames channel.
fn frame_schema() -> Value {
    json!({
        "title": "chassis.BusFrame",
        "description": "One CAN frame or serial chunk on the robot's bus, as chassisd's frame tap \
                        published it. stamp_ns: CLOCK_MONOTONIC ns when read or written.",
        "type": "object",
        "properties": {
            "stamp_ns": {"type": "integer", "description": "CLOCK_MONOTONIC ns"},
            "seq": {"type": "integer", "description": "tap sequence number; gaps are lost frames"},
            "direction": {"type": "string", "enum": ["rx", "tx"]},
            "kind": {"type": "string", "enum": ["can", "serial", "gps"]},
            "can_id": {"type": "integer"},
            "extended": {"type": "boolean"},
            "len": {"type": "integer"},
            "data": {"type": "string", "description": "payload, hex"}
        }
    })
}

fn titled(mut schema: Value, title: &str, description: &str) -> Value {
    if let Some(obj) = schema.as_object_mut() {
        obj.insert("title".into(), title.into());
        obj.insert("description".into(), description.into());
    }
    schema
}

/// The clocks and names at the start of a recording.
#[derive(Debug, Clone)]
pub struct Start {
    pub robot: &'static str,
    pub name: String,
    pub monotonic_ns: u64,
    pub wall_ns: i128,
}

impl Start {
    /// Add to a monotonic stamp for Unix-epoch ns.
    pub fn wall_offset_ns(&self) -> i128 {
        self.wall_ns - i128::from(self.monotonic_ns)
    }

    fn metadata(&self) -> BTreeMap<String, String> {
        [
            ("robot", self.robot.to_string()),
            ("name", self.name.clone()),
            ("clock", "CLOCK_MONOTONIC".to_string()),
            (
                "clock_note",
                "log_time and publish_time are CLOCK_MONOTONIC ns of the recording machine \
                 (time since boot), not wall clock; add wall_minus_monotonic_ns for Unix-epoch ns"
                    .to_string(),
            ),
            ("start_monotonic_ns", self.monotonic_ns.to_string()),
            ("start_wall_ns", self.wall_ns.to_string()),
            ("wall_minus_monotonic_ns", self.wall_offset_ns().to_string()),
            (
                "recorder",
                format!("chassis record {}", env!("CARGO_PKG_VERSION")),
            ),
            ("tap_buffer_frames", TAP_BUFFER.to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }
}

/// What a recording holds.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    /// Frames seen on the tap.
    pub frames: u64,
    /// Frames written (candump: the CAN frames of the chosen directions).
    pub written: u64,
    pub states: u64,
    pub mux: u64,
    pub gaps: GapCounter,
    /// `ChassisState::seq` gaps: state samples lost between two drains.
    pub state_gaps: GapCounter,
}

/// Where a recording goes.
trait Sink {
    fn frame(&mut self, frame: &BusFrame) -> anyhow::Result<bool>;
    fn state(&mut self, state: &ChassisState) -> anyhow::Result<()>;
    fn mux(&mut self, mux: &MuxStatus) -> anyhow::Result<()>;
    fn finish(self: Box<Self>, counts: &Counts, seconds: f64) -> anyhow::Result<()>;
}

/// Shortest time between two `/tf` + `/pose` messages, ns (50 Hz, as the live view).
const TF_PERIOD_NS: u64 = 20_000_000;
/// Name of the recorder in `/log`.
const LOG_NAME: &str = "chassis record";

/// The Foxglove channels of a recording and what they need to remember.
struct FoxgloveChannels {
    tf: u16,
    pose: u16,
    gps: u16,
    log: u16,
    body: Option<(u8, view::Body)>,
    watch: Watch,
    last_tf_ns: Option<u64>,
    last_gps_ns: u64,
}

/// An MCAP file with the chassis channels and the Foxglove ones.
pub struct McapSink {
    writer: mcap::Writer<BufWriter<File>>,
    frames: u16,
    state: u16,
    mux: u16,
    fox: FoxgloveChannels,
    sequence: [u32; 7],
    start: Start,
}

impl std::fmt::Debug for McapSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("name", &self.start.name)
            .finish()
    }
}

impl McapSink {
    pub fn create(path: &Path, start: Start) -> anyhow::Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(1);
        let mut writer = options
            .create(BufWriter::new(file))
            .context("starting the MCAP file")?;
        writer
            .write_metadata(&mcap::records::Metadata {
                name: METADATA_NAME.into(),
                metadata: start.metadata(),
            })
            .context("writing the MCAP metadata")?;
        let mut channel = |schema_name: &str,
                           schema: Value,
                           topic: &str,
                           type_name: &str|
         -> anyhow::Result<u16> {
            let schema_id =
                writer.add_schema(schema_name, "jsonschema", &serde_json::to_vec(&schema)?)?;
            let metadata = [("type_name".to_string(), type_name.to_string())].into();
            Ok(writer.add_channel(schema_id, topic, "json", &metadata)?)
        };
        let prefix = format!("/chassis/{}", start.name);
        let frames = channel(
            "chassis.BusFrame",
            frame_schema(),
            &format!("{prefix}/frames"),
            BusFrame::layout().type_name,
        )?;
        let state = channel(
            "chassis.ChassisState",
            titled(
                schema_of(&serde_json::to_value(ChassisState::default())?),
                "chassis.ChassisState",
                "Everything the chassis reports, in SI units (unit in every field name); \
                 *_stamp_ns are CLOCK_MONOTONIC ns",
            ),
            &format!("{prefix}/state"),
            ChassisState::layout().type_name,
        )?;
        let mux = channel(
            "chassis.MuxStatus",
            titled(
                schema_of(&serde_json::to_value(MuxStatus::default())?),
                "chassis.MuxStatus",
                "A decision of chassisd's velocity mux; stamp_ns is CLOCK_MONOTONIC ns",
            ),
            &format!("{prefix}/mux"),
            MuxStatus::layout().type_name,
        )?;
        let fox = FoxgloveChannels {
            tf: foxglove_channel::<FrameTransforms>(&mut writer, "/tf")?,
            pose: foxglove_channel::<PoseInFrame>(&mut writer, "/pose")?,
            gps: foxglove_channel::<LocationFix>(&mut writer, "/gps")?,
            log: foxglove_channel::<Log>(&mut writer, "/log")?,
            body: None,
            watch: Watch::default(),
            last_tf_ns: None,
            last_gps_ns: 0,
        };
        Ok(Self {
            writer,
            frames,
            state,
            mux,
            fox,
            sequence: [0; 7],
            start,
        })
    }

    fn write_encoded<T: Encode>(
        &mut self,
        which: usize,
        channel_id: u16,
        stamp_ns: u64,
        message: &T,
    ) -> anyhow::Result<()> {
        let mut data = Vec::new();
        message
            .encode(&mut data)
            .map_err(|e| anyhow::anyhow!("encoding a Foxglove message: {e}"))?;
        self.write(which, channel_id, stamp_ns, &data)
    }

    fn log(&mut self, level: Severity, text: String, stamp_ns: u64) -> anyhow::Result<()> {
        let message = view::log_message(LOG_NAME, level, text, stamp_ns);
        self.write_encoded(6, self.fox.log, stamp_ns, &message)
    }

    /// `/tf`, `/pose`, `/gps` and `/log` for a state sample.
    fn foxglove_state(&mut self, state: &ChassisState) -> anyhow::Result<()> {
        let t = state.stamp_ns;
        for (level, text) in self.fox.watch.state(state) {
            self.log(level, text, t)?;
        }
        if self
            .fox
            .body
            .as_ref()
            .is_none_or(|(kind, _)| *kind != state.robot)
            && let Some(body) = view::body_of(state.robot)
        {
            self.fox.body = Some((state.robot, body));
        }
        if self
            .fox
            .last_tf_ns
            .is_none_or(|last| t.saturating_sub(last) >= TF_PERIOD_NS)
            && let Some((_, body)) = &self.fox.body
        {
            let transforms = view::transforms(state, body, t);
            self.fox.last_tf_ns = Some(t);
            self.write_encoded(3, self.fox.tf, t, &transforms)?;
            self.write_encoded(4, self.fox.pose, t, &view::pose_in_frame(state, t))?;
        }
        let gps_ns = state.group_stamp_ns[Group::Gps.index()];
        if gps_ns != self.fox.last_gps_ns
            && let Some(fix) = view::location_fix(state, t)
        {
            self.fox.last_gps_ns = gps_ns;
            self.write_encoded(5, self.fox.gps, t, &fix)?;
        }
        Ok(())
    }

    fn write(
        &mut self,
        which: usize,
        channel_id: u16,
        stamp_ns: u64,
        data: &[u8],
    ) -> anyhow::Result<()> {
        self.sequence[which] = self.sequence[which].wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.sequence[which],
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        self.writer
            .write_to_known_channel(&header, data)
            .context("writing to the MCAP file")
    }
}

impl Sink for McapSink {
    fn frame(&mut self, frame: &BusFrame) -> anyhow::Result<bool> {
        let data = serde_json::to_vec(&FrameRecord::of(frame))?;
        self.write(0, self.frames, frame.stamp_ns, &data)?;
        Ok(true)
    }

    fn state(&mut self, state: &ChassisState) -> anyhow::Result<()> {
        let data = serde_json::to_vec(state)?;
        self.write(1, self.state, state.stamp_ns, &data)?;
        self.foxglove_state(state)
    }

    fn mux(&mut self, mux: &MuxStatus) -> anyhow::Result<()> {
        let data = serde_json::to_vec(mux)?;
        self.write(2, self.mux, mux.stamp_ns, &data)?;
        if let Some((level, text)) = self.fox.watch.mux(mux) {
            self.log(level, text, mux.stamp_ns)?;
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>, counts: &Counts, seconds: f64) -> anyhow::Result<()> {
        let summary: BTreeMap<String, String> = [
            ("frames", counts.frames.to_string()),
            ("lost_frames", counts.gaps.lost.to_string()),
            ("sequence_gaps", counts.gaps.gaps.to_string()),
            ("sequence_restarts", counts.gaps.restarts.to_string()),
            ("states", counts.states.to_string()),
            ("lost_states", counts.state_gaps.lost.to_string()),
            ("state_gaps", counts.state_gaps.gaps.to_string()),
            ("mux", counts.mux.to_string()),
            ("duration_s", format!("{seconds:.3}")),
            ("end_monotonic_ns", now_ns().to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: SUMMARY_NAME.into(),
                metadata: summary,
            })
            .context("writing the MCAP summary metadata")?;
        self.writer.finish().context("finishing the MCAP file")?;
        Ok(())
    }
}

/// `(SECS.MICROS) IFACE ID#HEX[ FLAG]` for a CAN frame stamped `wall_ns` (Unix-epoch ns); `None`
/// for what is not a CAN frame.
pub fn candump_line(
    wall_ns: i128,
    iface: &str,
    frame: &BusFrame,
    flag: Option<char>,
) -> Option<String> {
    // Serial and GPS chunks and remote frames have no candump line.
    let can = CanFrame::try_from(frame).ok()?;
    let micros = wall_ns.max(0) / 1000;
    let mut line = format!(
        "({}.{:06}) {iface} {}",
        micros / 1_000_000,
        micros % 1_000_000,
        can.to_candump()
    );
    if let Some(flag) = flag {
        line.push(' ');
        line.push(flag);
    }
    Some(line)
}

/// A `candump -l` log.
#[derive(Debug)]
pub struct CandumpSink {
    out: BufWriter<File>,
    iface: String,
    tx: bool,
    wall_offset_ns: i128,
}

impl CandumpSink {
    pub fn create(path: &Path, iface: String, tx: bool, start: &Start) -> anyhow::Result<Self> {
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(Self {
            out: BufWriter::new(file),
            iface,
            tx,
            wall_offset_ns: start.wall_offset_ns(),
        })
    }
}

impl Sink for CandumpSink {
    fn frame(&mut self, frame: &BusFrame) -> anyhow::Result<bool> {
        let is_tx = frame.direction == FrameDirection::TX;
        if is_tx && !self.tx {
            return Ok(false);
        }
        let flag = self.tx.then_some(if is_tx { 'T' } else { 'R' });
        let wall = i128::from(frame.stamp_ns) + self.wall_offset_ns;
        match candump_line(wall, &self.iface, frame, flag) {
            Some(line) => {
                writeln!(self.out, "{line}").context("writing the candump log")?;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    fn state(&mut self, _: &ChassisState) -> anyhow::Result<()> {
        Ok(())
    }

    fn mux(&mut self, _: &MuxStatus) -> anyhow::Result<()> {
        Ok(())
    }

    fn finish(mut self: Box<Self>, _: &Counts, _: f64) -> anyhow::Result<()> {
        self.out.flush().context("writing the candump log")
    }
}

/// The tap thread: drains the frames as they come and hands them over in batches, until `stop`.
fn drain_tap(
    name: &str,
    stop: &AtomicBool,
    out: &mpsc::Sender<Vec<BusFrame>>,
    ready: &mpsc::Sender<Result<(), chassis_client::ClientError>>,
) {
    let tap =
        match Robot::connect(name).and_then(|robot| robot.frames(TAP_BUFFER).map(|t| (robot, t))) {
            Ok(tap) => tap,
            Err(err) => {
                // The receiver gives up after 5 s and reports that instead.
                ready.send(Err(err)).ok();
                return;
            }
        };
    let (_robot, tap) = tap;
    // The receiver gives up after 5 s and reports that instead.
    ready.send(Ok(())).ok();
    let mut batch = Vec::with_capacity(TAP_BUFFER);
    loop {
        let stopping = stop.load(Ordering::Relaxed);
        let result = if stopping {
            tap.drain(|f| batch.push(*f))
        } else {
            tap.wait(Duration::from_millis(20), |f| batch.push(*f))
        };
        if let Err(err) = result {
            eprintln!("chassis record: frame tap: {err}");
            return;
        }
        if !batch.is_empty() && out.send(std::mem::take(&mut batch)).is_err() {
            return;
        }
        if stopping {
            return;
        }
    }
}

/// The writing side of a recording.
struct Recorder {
    sink: Box<dyn Sink>,
    counts: Counts,
    last_mux: Option<u64>,
    quiet_since: u64,
    /// Every state sample, when state and mux samples are recorded too (MCAP).
    states: Option<StateStream>,
}

impl Recorder {
    fn frames(&mut self, batch: &[BusFrame]) -> anyhow::Result<()> {
        for frame in batch {
            self.counts.frames += 1;
            self.counts.gaps.see(frame.seq);
            if self.sink.frame(frame)? {
                self.counts.written += 1;
            }
        }
        Ok(())
    }

    /// Writes every state sample received since the last call (MCAP only).
    fn states(&mut self) -> anyhow::Result<()> {
        let Some(states) = &self.states else {
            return Ok(());
        };
        let mut written = Ok(());
        let mut newest = None;
        states.drain(|state| {
            self.counts.states += 1;
            self.counts.state_gaps.see(state.seq);
            newest = Some(state.stamp_ns);
            if written.is_ok() {
                written = self.sink.state(state);
            }
        })?;
        written?;
        if let Some(stamp) = newest {
            self.quiet_since = self.quiet_since.max(stamp);
        }
        Ok(())
    }

    /// Writes what arrived within 50 ms; false when the service is gone.
    fn step(
        &mut self,
        robot: &mut Robot,
        frames: &mpsc::Receiver<Vec<BusFrame>>,
    ) -> anyhow::Result<bool> {
        match frames.recv_timeout(Duration::from_millis(50)) {
            Ok(batch) => {
                self.frames(&batch)?;
                self.quiet_since = now_ns();
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the frame tap stopped"),
        }
        if self.states.is_some() {
            self.states()?;
            if let Some(mux) = robot.latest_mux()?
                && self.last_mux != Some(mux.seq)
            {
                self.last_mux = Some(mux.seq);
                self.sink.mux(&mux)?;
                self.counts.mux += 1;
            }
        }
        if now_ns().saturating_sub(self.quiet_since) > 2_000_000_000 {
            if !robot.is_served() {
                return Ok(false);
            }
            self.quiet_since = now_ns();
        }
        Ok(true)
    }
}

/// `chassis record`.
pub fn record(args: &RecordArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration must be a positive number of seconds");
    }
    let mut robot = Robot::connect(&args.name)?;
    let first = match robot.latest_state()? {
        Some(s) => s,
        None => robot
            .wait_state(Duration::from_secs(2))?
            .with_context(|| format!("chassis/{} published no state within 2 s", args.name))?,
    };
    let kind = first.robot;
    if args.candump
        && let Some(serial) = RobotKind::from_id(kind).filter(|k| !k.is_can())
    {
        bail!(
            "the {serial} speaks RS232: its serial stream is not CAN and cannot be a candump log; \
             record MCAP instead (chassis record FILE.mcap)"
        );
    }

    // The tap thread first, so nothing is missed from the first line of the file on.
    let stop = Arc::new(AtomicBool::new(false));
    let (frames_out, frames_in) = mpsc::channel::<Vec<BusFrame>>();
    let (ready_out, ready_in) = mpsc::channel();
    let tap_thread = {
        let stop = Arc::clone(&stop);
        let name = args.name.clone();
        std::thread::Builder::new()
            .name("frame-tap".into())
            .spawn(move || drain_tap(&name, &stop, &frames_out, &ready_out))
            .context("starting the frame tap thread")?
    };
    match ready_in.recv_timeout(Duration::from_secs(5)) {
        Ok(Ok(())) => {}
        Ok(Err(err)) => bail!("opening the frame tap of chassis/{}: {err}", args.name),
        Err(_) => bail!("the frame tap of chassis/{} did not open", args.name),
    }

    let start = Start {
        robot: RobotKind::from_id(kind).map_or("unknown", RobotKind::name),
        name: args.name.clone(),
        monotonic_ns: now_ns(),
        wall_ns: i128::from(chassis_bus::clock::unix_ns()),
    };
    let sink: Box<dyn Sink> = if args.candump {
        let iface = args.iface.clone().unwrap_or_else(|| args.name.clone());
        if iface.is_empty() || iface.chars().any(char::is_whitespace) {
            bail!("--iface must be one word");
        }
        Box::new(CandumpSink::create(&args.file, iface, args.tx, &start)?)
    } else {
        Box::new(McapSink::create(&args.file, start.clone())?)
    };
    eprintln!(
        "recording chassis/{} ({}) to {}{} — Ctrl-C to stop",
        args.name,
        start.robot,
        args.file.display(),
        if args.candump { " (candump)" } else { "" }
    );

    let states = (!args.candump)
        .then(|| robot.state_stream(STATE_BUFFER))
        .transpose()
        .with_context(|| format!("opening the state stream of chassis/{}", args.name))?;
    let mut recorder = Recorder {
        sink,
        counts: Counts::default(),
        last_mux: None,
        quiet_since: now_ns(),
        states,
    };
    let end = args
        .duration
        .map(|d| start.monotonic_ns.saturating_add((d * 1e9) as u64));
    let mut gone = false;
    let mut failure = None;
    while !termination_requested() && end.is_none_or(|e| now_ns() < e) {
        match recorder.step(&mut robot, &frames_in) {
            Ok(true) => {}
            Ok(false) => {
                gone = true;
                break;
            }
            Err(err) => {
                failure = Some(err);
                break;
            }
        }
    }

    // Stop the tap thread, then write what it still had.
    stop.store(true, Ordering::Relaxed);
    let _ = tap_thread.join();
    while let Ok(batch) = frames_in.try_recv() {
        if failure.is_none()
            && let Err(err) = recorder.frames(&batch)
        {
            failure = Some(err);
        }
    }
    if failure.is_none()
        && let Err(err) = recorder.states()
    {
        failure = Some(err);
    }
    let Recorder { sink, counts, .. } = recorder;
    let seconds = now_ns().saturating_sub(start.monotonic_ns) as f64 / 1e9;
    let finished = sink.finish(&counts, seconds);
    let rate = if seconds > 0.0 {
        counts.frames as f64 / seconds
    } else {
        0.0
    };
    eprintln!(
        "recorded {} frames ({rate:.0} frames/s{}), {} states, {} mux decisions in {seconds:.1} s to {}",
        counts.frames,
        if args.candump {
            format!(", {} written", counts.written)
        } else {
            String::new()
        },
        counts.states,
        counts.mux,
        args.file.display()
    );
    if counts.gaps.lost == 0 {
        eprintln!("no frame lost (0 sequence gaps)");
    } else {
        eprintln!(
            "WARNING: {} frames lost in {} sequence gaps (the recorder fell more than {TAP_BUFFER} frames behind)",
            counts.gaps.lost, counts.gaps.gaps
        );
    }
    if counts.state_gaps.lost > 0 {
        eprintln!(
            "WARNING: {} state samples lost in {} sequence gaps (the recorder fell more than \
             {STATE_BUFFER} samples behind)",
            counts.state_gaps.lost, counts.state_gaps.gaps
        );
    }
    if counts.gaps.restarts > 0 {
        eprintln!(
            "note: the frame sequence started again {} times (chassisd restarted)",
            counts.gaps.restarts
        );
    }
    finished?;
    if let Some(err) = failure {
        return Err(err);
    }
    if gone {
        bail!(
            "chassis/{} is gone (chassisd stopped); the recording is complete up to there",
            args.name
        );
    }
    Ok(())
}

/// The `chassis` metadata of an MCAP recording (`None` for a candump log). It sits at the start
/// of the file.
pub fn recording_metadata(path: &Path) -> anyhow::Result<Option<BTreeMap<String, String>>> {
    let mut head = Vec::new();
    File::open(path)
        .with_context(|| format!("opening {}", path.display()))?
        .take(1 << 20)
        .read_to_end(&mut head)
        .with_context(|| format!("reading {}", path.display()))?;
    if !head.starts_with(b"\x89MCAP0\r\n") {
        return Ok(None);
    }
    for record in mcap::read::LinearReader::new(&head)? {
        match record {
            Ok(mcap::records::Record::Metadata(meta)) if meta.name == METADATA_NAME => {
                return Ok(Some(meta.metadata));
            }
            Ok(_) => {}
            Err(_) => break,
        }
    }
    Ok(Some(BTreeMap::new()))
}

/// A started `chassisd`, stopped (SIGINT, then SIGKILL) when dropped.
#[derive(Debug)]
struct Service {
    child: Child,
}

impl Service {
    fn stop(&mut self) -> Option<std::process::ExitStatus> {
        use nix::sys::signal::{Signal, kill};
        use nix::unistd::Pid;
        if let Ok(Some(status)) = self.child.try_wait() {
            return Some(status);
        }
        if let Ok(pid) = i32::try_from(self.child.id()) {
            let _ = kill(Pid::from_raw(pid), Signal::SIGINT);
        }
        let deadline = now_ns() + 5_000_000_000;
        let mut ticker = chassis_client::Ticker::new(Duration::from_millis(20));
        while now_ns() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return Some(status);
            }
            ticker.wait();
        }
        let _ = self.child.kill();
        self.child.wait().ok()
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// `chassis replay`.
pub fn replay(args: &ReplayArgs) -> anyhow::Result<()> {
    install_signal_handlers();
    let path = std::fs::canonicalize(&args.file)
        .with_context(|| format!("opening {}", args.file.display()))?;
    let Some(path_text) = path.to_str() else {
        bail!("{} is not a UTF-8 path", path.display());
    };
    let recorded = recording_metadata(&path)?
        .and_then(|meta| meta.get("robot").map(|robot| robot.parse::<RobotKind>()))
        .transpose()
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("the robot {} names", path.display()))?;
    let robot = match (args.robot, recorded) {
        (Some(given), Some(rec)) if given != rec => {
            bail!(
                "{} is a recording of a {rec}, not a {given}",
                path.display()
            )
        }
        (Some(given), _) => given,
        (None, Some(rec)) => rec,
        (None, None) => bail!(
            "{} does not say which robot it is (a candump log): give --robot",
            path.display()
        ),
    };
    let speed = if args.max_speed {
        "max".to_string()
    } else if args.speed.is_finite() && args.speed > 0.0 && args.speed <= 1000.0 {
        format!("{}", args.speed)
    } else {
        bail!("--speed must be a factor above 0 and at most 1000");
    };
    if !valid_robot_name(&args.name) {
        bail!(
            "'{}' is not a valid robot name (1-16 of a-z 0-9 - _)",
            args.name
        );
    }
    let chassisd = crate::procs::sibling("chassisd")?;
    let mut command = Command::new(&chassisd);
    command
        .args(["--robot", robot.name(), "--name", &args.name])
        .arg("--bus")
        .arg(format!("replay:{path_text}@{speed}"))
        .arg("--no-safety-monitor")
        .stdin(Stdio::null());
    if let Some(config) = &args.config {
        command.arg("--config").arg(config);
    }
    // chassisd logs on stderr; keep our stdout for the states.
    if let Ok(fd) = std::os::fd::AsFd::as_fd(&std::io::stderr()).try_clone_to_owned() {
        command.stdout(Stdio::from(fd));
    }
    // chassisd must not outlive us.
    crate::procs::die_with_parent(&mut command);
    let mut service = Service {
        child: command
            .spawn()
            .with_context(|| format!("starting {}", chassisd.display()))?,
    };
    eprintln!(
        "replaying {} as chassis/{} ({robot}, speed {speed})",
        path.display(),
        args.name
    );

    // Connect once the service is up.
    let started = now_ns();
    let mut ticker = chassis_client::Ticker::new(Duration::from_millis(50));
    let mut connection = loop {
        if termination_requested() {
            return Ok(());
        }
        if let Ok(Some(status)) = service.child.try_wait() {
            bail!("chassisd exited at start ({status}); see its log above");
        }
        match Robot::connect(&args.name) {
            Ok(robot) => break robot,
            Err(err) if now_ns().saturating_sub(started) > 10_000_000_000 => {
                bail!("chassis/{} did not come up: {err}", args.name)
            }
            Err(_) => ticker.wait(),
        }
    };

    let mut last: Option<ChassisState> = None;
    let mut last_print = 0u64;
    let mut down_since: Option<u64> = None;
    let ended = loop {
        if termination_requested() {
            break false;
        }
        if let Ok(Some(status)) = service.child.try_wait() {
            bail!("chassisd exited during the replay ({status}); see its log above");
        }
        let Some(state) = connection.wait_state(Duration::from_millis(100))? else {
            continue;
        };
        last = Some(state);
        let now = now_ns();
        if !args.quiet && now.saturating_sub(last_print) >= 100_000_000 {
            last_print = now;
            write_sample(&mut std::io::stdout(), args.json, Some(&state), state_line)?;
        }
        if state.link_flags & LinkFlags::BUS_DOWN != 0 {
            if state.link.rx_frames > 0 {
                break true;
            }
            let since = *down_since.get_or_insert(now);
            if now.saturating_sub(since) > 5_000_000_000 {
                bail!("the replay bus did not open; see chassisd's log above");
            }
        } else {
            down_since = None;
        }
    };
    let status = service.stop();
    if let Some(state) = last {
        write_sample(&mut std::io::stdout(), args.json, Some(&state), state_line)?;
        eprintln!(
            "{}: {} frames replayed and decoded ({} decode errors, {} bad checksums, {} unknown ids)",
            if ended {
                "replay ended"
            } else {
                "replay stopped"
            },
            state.link.rx_frames,
            state.link.rx_decode_errors,
            state.link.rx_bad_checksum,
            state.link.rx_unknown_id
        );
    }
    if let Some(status) = status
        && !status.success()
    {
        bail!("chassisd ended with {status}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_protocols::CandumpLine;

    fn can_frame(seq: u64, stamp_ns: u64, id: u32, data: &[u8], direction: u8) -> BusFrame {
        let mut frame = BusFrame {
            stamp_ns,
            seq,
            can_id: id,
            direction,
            kind: FrameKind::CAN,
            ..BusFrame::default()
        };
        frame.set_payload(data);
        frame
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("chassis-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    fn start() -> Start {
        Start {
            robot: "titan",
            name: "rec".into(),
            monotonic_ns: 1_000_000_000,
            wall_ns: 1_700_000_000_000_000_000,
        }
    }

    #[test]
    fn sequence_gaps_count_the_lost_frames() {
        let mut gaps = GapCounter::default();
        for seq in [5, 6, 7, 10, 11, 15, 2, 3] {
            gaps.see(seq);
        }
        assert_eq!((gaps.lost, gaps.gaps, gaps.restarts), (5, 2, 1));
    }

    #[test]
    fn candump_lines_are_exact_to_the_microsecond_and_parse_back() {
        let frame = can_frame(1, 0, 0x211, &[1, 2, 3, 0xAB], FrameDirection::RX);
        let line = candump_line(1_700_000_000_123_456_789, "titan", &frame, None).unwrap();
        assert_eq!(line, "(1700000000.123456) titan 211#010203AB");
        let parsed = CandumpLine::parse(&line).unwrap();
        assert_eq!(parsed.interface, "titan");
        assert_eq!(parsed.frame.to_candump(), "211#010203AB");
        let mut ext = can_frame(2, 0, 0x18FF_0001, &[], FrameDirection::TX);
        ext.flags = BusFrame::EXTENDED_ID;
        assert_eq!(
            candump_line(5_000_001_000, "can0", &ext, Some('T')).unwrap(),
            "(5.000001) can0 18FF0001# T"
        );
        let serial = BusFrame {
            kind: FrameKind::SERIAL,
            ..BusFrame::default()
        };
        assert_eq!(candump_line(0, "x", &serial, None), None);
    }

    #[test]
    fn a_candump_recording_writes_rx_only_unless_asked_for_tx() {
        let path = scratch("rx.log");
        let frames = [
            can_frame(1, 1_000_000_000, 0x211, &[1], FrameDirection::RX),
            can_frame(2, 1_000_500_000, 0x111, &[2], FrameDirection::TX),
        ];
        for tx in [false, true] {
            let mut sink: Box<dyn Sink> =
                Box::new(CandumpSink::create(&path, "can0".into(), tx, &start()).unwrap());
            let written: Vec<bool> = frames.iter().map(|f| sink.frame(f).unwrap()).collect();
            sink.finish(&Counts::default(), 1.0).unwrap();
            let text = std::fs::read_to_string(&path).unwrap();
            if tx {
                assert_eq!(written, [true, true]);
                assert_eq!(
                    text,
                    "(1700000000.000000) can0 211#01 R\n(1700000000.000500) can0 111#02 T\n"
                );
            } else {
                assert_eq!(written, [true, false]);
                assert_eq!(text, "(1700000000.000000) can0 211#01\n");
            }
        }
    }

    #[test]
    fn schemas_describe_every_field_of_the_samples() {
        let value = serde_json::to_value(ChassisState::default()).unwrap();
        let schema = schema_of(&value);
        assert_eq!(schema["type"], "object");
        assert_eq!(
            schema["properties"]["motion"]["properties"]["linear_mps"]["type"],
            "number"
        );
        assert_eq!(schema["properties"]["seq"]["type"], "integer");
        let mux = schema_of(&serde_json::to_value(MuxStatus::default()).unwrap());
        assert_eq!(mux["properties"]["sources"]["type"], "array");
        assert_eq!(
            mux["properties"]["sources"]["items"]["properties"]["name"]["type"],
            "string"
        );
    }

    #[test]
    fn an_mcap_recording_reads_back_with_its_channels_metadata_and_messages() {
        let path = scratch("round-trip.mcap");
        let mut sink: Box<dyn Sink> = Box::new(McapSink::create(&path, start()).unwrap());
        let frames = [
            can_frame(
                7,
                1_000_000_100,
                0x211,
                &[0, 0x96, 0, 0, 0, 0, 0, 0],
                FrameDirection::RX,
            ),
            can_frame(8, 1_000_000_200, 0x111, &[1, 2], FrameDirection::TX),
        ];
        for f in &frames {
            assert!(sink.frame(f).unwrap());
        }
        let mut state = ChassisState {
            stamp_ns: 1_000_000_300,
            seq: 3,
            ..ChassisState::default()
        };
        state.motion.linear_mps = 0.5;
        state.odometry.x_m = 1.25;
        state.robot = RobotKind::Titan.id();
        sink.state(&state).unwrap();
        let mux = MuxStatus {
            stamp_ns: 1_000_000_400,
            seq: 9,
            ..MuxStatus::default()
        };
        sink.mux(&mux).unwrap();
        let counts = Counts {
            frames: 2,
            ..Counts::default()
        };
        sink.finish(&counts, 0.5).unwrap();

        let bytes = std::fs::read(&path).unwrap();
        let meta = recording_metadata(&path).unwrap().unwrap();
        assert_eq!(meta["robot"], "titan");
        assert_eq!(meta["name"], "rec");
        assert_eq!(meta["wall_minus_monotonic_ns"], "1699999999000000000");
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let topics: Vec<String> = summary.channels.values().map(|c| c.topic.clone()).collect();
        for topic in [
            "/chassis/rec/frames",
            "/chassis/rec/state",
            "/chassis/rec/mux",
        ] {
            assert!(topics.contains(&topic.to_string()), "{topics:?}");
        }
        for channel in summary.channels.values() {
            if channel.topic.starts_with("/chassis/") {
                assert_eq!(channel.message_encoding, "json");
                assert_eq!(channel.schema.as_ref().unwrap().encoding, "jsonschema");
            }
        }
        let all: Vec<mcap::Message> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let messages: Vec<&mcap::Message> = all
            .iter()
            .filter(|m| m.channel.topic.starts_with("/chassis/"))
            .collect();
        assert_eq!(messages.len(), 4);
        let frame: Value = serde_json::from_slice(&messages[0].data).unwrap();
        assert_eq!(messages[0].log_time, 1_000_000_100);
        assert_eq!(messages[0].publish_time, 1_000_000_100);
        assert_eq!(frame["direction"], "rx");
        assert_eq!(frame["kind"], "can");
        assert_eq!(frame["can_id"], 0x211);
        assert_eq!(frame["seq"], 7);
        assert_eq!(frame["data"], "0096000000000000");
        let tx: Value = serde_json::from_slice(&messages[1].data).unwrap();
        assert_eq!(tx["direction"], "tx");
        let state_back: Value = serde_json::from_slice(&messages[2].data).unwrap();
        assert_eq!(messages[2].channel.topic, "/chassis/rec/state");
        assert_eq!(state_back["odometry"]["x_m"], 1.25);
        assert_eq!(state_back["motion"]["linear_mps"], 0.5);
        assert_eq!(messages[3].log_time, 1_000_000_400);
        let mut summaries = summary
            .metadata_indexes
            .iter()
            .filter(|m| m.name == SUMMARY_NAME);
        let index = summaries.next().unwrap();
        let counts_back = mcap::read::metadata(&bytes, index).unwrap();
        assert_eq!(counts_back.metadata["frames"], "2");
        assert_eq!(counts_back.metadata["lost_frames"], "0");
    }

    #[test]
    fn an_mcap_recording_carries_the_foxglove_schemas_of_the_live_view() {
        use foxglove::Decode;
        let path = scratch("foxglove.mcap");
        let mut sink: Box<dyn Sink> = Box::new(McapSink::create(&path, start()).unwrap());
        let mut state = ChassisState {
            robot: RobotKind::Titan.id(),
            ..ChassisState::default()
        };
        // 1 s of samples every 5 ms, driving forward at 1 m/s; a fault appears half-way.
        for i in 0..200u64 {
            state.seq = i;
            state.stamp_ns = 1_000_000_000 + i * 5_000_000;
            state.odometry.x_m = i as f64 * 0.005;
            if i == 100 {
                state.system.fault_flags =
                    chassis_client::FaultFlags::from_name("heartbeat_lost").unwrap();
            }
            if i == 150 {
                state.touch(Group::Gps, state.stamp_ns);
                state.gps.fix_quality = 1;
                state.gps.latitude_deg = 48.5;
                state.gps.longitude_deg = 9.1;
            }
            sink.state(&state).unwrap();
        }
        sink.finish(&Counts::default(), 1.0).unwrap();

        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let schema_of_topic = |topic: &str| {
            let c = summary
                .channels
                .values()
                .find(|c| c.topic == topic)
                .unwrap();
            let s = c.schema.as_ref().unwrap();
            (
                s.name.clone(),
                s.encoding.clone(),
                c.message_encoding.clone(),
            )
        };
        for (topic, name) in [
            ("/tf", "foxglove.FrameTransforms"),
            ("/pose", "foxglove.PoseInFrame"),
            ("/gps", "foxglove.LocationFix"),
            ("/log", "foxglove.Log"),
        ] {
            let (schema, encoding, message_encoding) = schema_of_topic(topic);
            assert_eq!(schema, name);
            assert_eq!(
                (encoding.as_str(), message_encoding.as_str()),
                ("protobuf", "protobuf")
            );
        }
        let messages: Vec<mcap::Message> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let on = |topic: &str| -> Vec<&mcap::Message> {
            messages
                .iter()
                .filter(|m| m.channel.topic == topic)
                .collect()
        };
        // Every state sample as JSON, /tf and /pose at 50 Hz.
        assert_eq!(on("/chassis/rec/state").len(), 200);
        let tf = on("/tf");
        assert_eq!(tf.len(), 50);
        let last = FrameTransforms::decode(&tf[49].data[..]).unwrap();
        let base = &last.transforms[0];
        assert_eq!(base.child_frame_id, "base_link");
        assert!((base.translation.unwrap().x - 0.98).abs() < 1e-9);
        assert_eq!(tf[49].log_time, 1_000_000_000 + 196 * 5_000_000);
        let pose = PoseInFrame::decode(&on("/pose")[49].data[..]).unwrap();
        assert_eq!(pose.frame_id, "odom");
        assert!((pose.pose.unwrap().position.unwrap().x - 0.98).abs() < 1e-9);
        let gps = on("/gps");
        assert_eq!(gps.len(), 1);
        assert_eq!(
            LocationFix::decode(&gps[0].data[..]).unwrap().latitude,
            48.5
        );
        let logs: Vec<Log> = on("/log")
            .iter()
            .map(|m| Log::decode(&m.data[..]).unwrap())
            .collect();
        assert_eq!(logs.len(), 1, "{logs:?}");
        assert!(logs[0].message.contains("heartbeat_lost"), "{logs:?}");
        assert_eq!(logs[0].name, LOG_NAME);
    }

    #[test]
    fn a_candump_log_has_no_recording_metadata() {
        let path = scratch("plain.log");
        std::fs::write(&path, "(1.000000) can0 211#01\n").unwrap();
        assert_eq!(recording_metadata(&path).unwrap(), None);
    }
}
