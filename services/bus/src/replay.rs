//! The replay bus (`--bus replay:FILE[@SPEED|@max]`): a recording played back at the far end of
//! a socket pair, so a field recording reproduces a bug at the desk.
//!
//! Like the embedded simulator, a thread sits at the chassis side of a socket pair
//! ([`bus_pair`]): datagrams for the CAN robots, a stream for the XBot — and the
//! service talks to it exactly as to a real bus. The thread writes the *received* frames of the
//! recording into the pair and reads and discards (counting them) whatever the service
//! transmits: the service's commands reach no chassis, and the recorded chassis goes on as it
//! did in the field.
//!
//! # Recordings
//!
//! * **MCAP** written by `chassis record` (recognised by its magic bytes): the messages of the
//!   channel whose topic ends in `/frames` (JSON, one `BusFrame` each: `direction` `"rx"`/`"tx"`,
//!   `kind` `"can"`/`"serial"`/`"gps"`, `can_id`, `extended`, `data` as hex), timed by their
//!   `log_time`. The `chassis` metadata record names the robot; a recording of another robot is
//!   refused at open.
//! * **candump -l logs**: `(SECS.MICROS) IFACE ID#HEX` lines (CAN robots only). A trailing
//!   direction flag (` R` / ` T`, as `chassis record --candump --tx` writes) is honoured: `T`
//!   lines were sent by a service and are not replayed.
//!
//! Recorded TX frames, GPS chunks and lines that do not parse are skipped and counted.
//!
//! # Timing
//!
//! At a speed factor (`@1`, the default, is the recorded timing; `@2` twice as fast, `@0.5` half)
//! each frame is due at the replay's start plus its offset from the first replayed frame, divided
//! by the factor ([`due_at`]). At `@max` frames are written as fast as the service drains the
//! socket: the thread waits only for room in it. This is the benchmark's "decode and publish as
//! fast as possible" load; the summary line gives the rate.
//!
//! The driver integrates its pose over the *arrival* time of the motion feedback, so only a
//! replay at the recorded speed reproduces the recorded pose; everything the chassis reports
//! itself (odometer, battery, faults, modes) replays exactly at any speed.
//!
//! # The end of the recording
//!
//! When the last frame has been read by the service, the thread logs a summary (frames, seconds,
//! frames/s, what it skipped and discarded) and closes its end: the service sees its bus end (an
//! error log, [`chassis_interfaces::LinkFlags::BUS_DOWN`] in the state) with the replayed state
//! kept as the last frames left it. A recording plays once per `chassisd` process: the service's
//! attempts to reopen the bus are refused, so the state stays `bus_down` instead of restarting
//! the recording. To play it again, restart `chassisd` (there is no loop option: a bug
//! reproduced once is reproduced; a benchmark wanting a longer run records a longer file).
// The player thread paces a recording by the clock: it is a loop that owns the clock.
#![allow(clippy::disallowed_methods)]

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::ops::ControlFlow;
use std::os::fd::{BorrowedFd, RawFd};
use std::str::FromStr;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use chassis_protocols::{CanFrame, CandumpLine, RobotKind, Timestamp, WireItem};
use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags};
use nix::sys::time::TimeSpec;
use serde::Deserialize;
use tracing::{debug, error, info, info_span, warn};

use super::datagram::bus_pair;
use super::{Bus, BusError};
use crate::clock;

/// How fast a recording plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ReplaySpeed {
    /// The recorded timing divided by `permille / 1000`: 1000 is the recorded speed, 2000 twice
    /// as fast, 500 half as fast.
    Factor { permille: u32 },
    /// As fast as the service takes the frames.
    Max,
}

impl ReplaySpeed {
    /// The recorded timing.
    pub const RECORDED: ReplaySpeed = ReplaySpeed::Factor { permille: 1000 };
    /// Fastest factor accepted.
    const MAX_FACTOR: f64 = 1000.0;
}

impl Default for ReplaySpeed {
    fn default() -> Self {
        Self::RECORDED
    }
}

/// A replay speed that is neither `max` nor a factor in (0, 1000].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{text}' is not a replay speed (a factor such as 1, 2 or 0.5, or max)")]
pub struct ReplaySpeedError {
    pub text: String,
}

/// Why the part of a `replay:` bus spec after the colon does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplaySpecError {
    #[error(transparent)]
    Speed(#[from] ReplaySpeedError),
    #[error("missing the recording's path")]
    MissingPath,
}

impl FromStr for ReplaySpeed {
    type Err = ReplaySpeedError;
    /// `max`, or a factor: `1`, `2`, `0.5`, `2x`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text == "max" {
            return Ok(ReplaySpeed::Max);
        }
        let number = text.strip_suffix('x').unwrap_or(text);
        let bad = || ReplaySpeedError { text: text.into() };
        let factor: f64 = number.parse().map_err(|_| bad())?;
        if !(factor.is_finite() && factor > 0.0 && factor <= Self::MAX_FACTOR) {
            return Err(bad());
        }
        let permille = (factor * 1000.0).round();
        if permille < 1.0 {
            return Err(bad());
        }
        // 1 <= permille <= 1_000_000 fits a u32.
        Ok(ReplaySpeed::Factor {
            permille: permille as u32,
        })
    }
}

impl fmt::Display for ReplaySpeed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReplaySpeed::Max => f.write_str("max"),
            ReplaySpeed::Factor { permille } => {
                let whole = permille / 1000;
                let fraction = permille % 1000;
                if fraction == 0 {
                    write!(f, "{whole}")
                } else {
                    let digits = format!("{fraction:03}");
                    write!(f, "{whole}.{}", digits.trim_end_matches('0'))
                }
            }
        }
    }
}

/// Splits the part of a `replay:` bus spec after the colon into the file and the speed
/// (`FILE`, `FILE@2`, `FILE@0.5`, `FILE@max`; the last `@` separates them).
pub fn parse_spec(rest: &str) -> Result<(String, ReplaySpeed), ReplaySpecError> {
    let (path, speed) = match rest.rsplit_once('@') {
        Some((path, speed)) => (path, speed.parse()?),
        None => (rest, ReplaySpeed::RECORDED),
    };
    if path.is_empty() {
        return Err(ReplaySpecError::MissingPath);
    }
    Ok((path.to_string(), speed))
}

/// When the frame recorded at `stamp_ns` is due: `start` plus its offset from the first replayed
/// frame (`first_ns`) divided by the speed factor; at once at [`ReplaySpeed::Max`]. A stamp
/// earlier than the first one is due at `start`.
pub fn due_at(start: Timestamp, first_ns: u64, stamp_ns: u64, speed: ReplaySpeed) -> Timestamp {
    match speed {
        ReplaySpeed::Max => start,
        ReplaySpeed::Factor { permille } => {
            let offset = u128::from(stamp_ns.saturating_sub(first_ns));
            let scaled = offset * 1000 / u128::from(permille.max(1));
            let scaled = u64::try_from(scaled).unwrap_or(u64::MAX);
            Timestamp::from_nanos(start.as_nanos().saturating_add(scaled))
        }
    }
}

/// The first bytes of every MCAP file.
const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
/// Name of the metadata record `chassis record` writes (robot, name, clocks).
pub const METADATA_NAME: &str = "chassis";

/// One frame to replay: when it was recorded and what to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    pub stamp_ns: u64,
    pub item: WireItem,
}

/// One record of a recording, as the replay sees it.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// A frame the chassis sent: replayed.
    Rx(Entry),
    /// A frame the recorded service sent: not replayed.
    Tx,
    /// Something else on the frames channel (a GPS chunk): not replayed.
    Other,
    /// A record that could not be read, and why.
    Bad(String),
}

/// A recording in one of the two formats.
#[derive(Debug)]
pub enum Recording {
    /// The bytes of an MCAP file, and the robot its metadata names.
    Mcap {
        bytes: Vec<u8>,
        robot: Option<RobotKind>,
    },
    /// A candump log (read line by line as it plays).
    Candump { path: String },
}

fn open_error(path: &str, reason: impl fmt::Display) -> BusError {
    BusError::Open {
        name: format!("replay:{path}"),
        reason: reason.to_string(),
    }
}

impl Recording {
    /// Reads the recording at `path`: MCAP when it starts with MCAP's magic, else a candump log.
    pub fn open(path: &str) -> Result<Self, BusError> {
        let mut head = [0u8; 8];
        let n = {
            use std::io::Read;
            let mut file = File::open(path).map_err(|e| open_error(path, e))?;
            file.read(&mut head).map_err(|e| open_error(path, e))?
        };
        if head[..n] == *MCAP_MAGIC {
            let bytes = std::fs::read(path).map_err(|e| open_error(path, e))?;
            let robot = mcap_metadata(&bytes)
                .and_then(|meta| meta.get("robot").map(|name| name.parse::<RobotKind>()))
                .transpose()
                .map_err(|e| open_error(path, e))?;
            Ok(Recording::Mcap { bytes, robot })
        } else {
            Ok(Recording::Candump {
                path: path.to_string(),
            })
        }
    }

    /// The robot the recording is of, when it says.
    pub fn robot(&self) -> Option<RobotKind> {
        match self {
            Recording::Mcap { robot, .. } => *robot,
            Recording::Candump { .. } => None,
        }
    }

    /// Checks that `robot`'s service can play this recording.
    pub fn check(&self, path: &str, robot: RobotKind) -> Result<(), BusError> {
        match self {
            Recording::Mcap {
                robot: Some(recorded),
                ..
            } if *recorded != robot => Err(open_error(
                path,
                format!("a recording of a {recorded}: start chassisd with --robot {recorded}"),
            )),
            Recording::Candump { .. } if !robot.is_can() => Err(open_error(
                path,
                format!("a candump log holds CAN frames and the {robot} speaks RS232"),
            )),
            _ => Ok(()),
        }
    }

    /// Every record in order.
    pub fn steps(&self) -> Result<Box<dyn Iterator<Item = Step> + '_>, BusError> {
        match self {
            Recording::Mcap { bytes, .. } => Ok(Box::new(mcap_steps(bytes).into_iter())),
            Recording::Candump { path } => {
                let file = File::open(path).map_err(|e| open_error(path, e))?;
                let mut lines = BufReader::new(file).lines();
                let mut failed = false;
                Ok(Box::new(std::iter::from_fn(move || {
                    while !failed {
                        match lines.next()? {
                            Ok(line) => {
                                if let Some(step) = candump_step(&line) {
                                    return Some(step);
                                }
                            }
                            Err(err) => {
                                // A read error ends the log (it would repeat forever).
                                failed = true;
                                return Some(Step::Bad(format!("reading the log: {err}")));
                            }
                        }
                    }
                    None
                })))
            }
        }
    }
}

/// The key-value pairs of the `chassis` metadata record of an MCAP file (written at the start of
/// the recording, so even a file whose recorder was killed has it).
pub fn mcap_metadata(bytes: &[u8]) -> Option<std::collections::BTreeMap<String, String>> {
    use mcap::records::{Record, op};
    let mut found = None;
    let walked = crate::mcap_read::each_record(bytes, |opcode, data| {
        if opcode == op::METADATA
            && let Record::Metadata(meta) = mcap::parse_record(opcode, data)?
            && meta.name == METADATA_NAME
        {
            found = Some(meta.metadata);
            return Ok::<_, mcap::McapError>(ControlFlow::Break(()));
        }
        Ok(ControlFlow::Continue(()))
    });
    walked.ok().and(found)
}

/// A `BusFrame` as `chassis record` writes it on the frames channel (the fields the replay
/// needs; the rest are ignored).
#[derive(Debug, Deserialize)]
struct FrameRecord {
    direction: String,
    kind: String,
    #[serde(default)]
    can_id: u32,
    #[serde(default)]
    extended: bool,
    #[serde(default)]
    data: String,
}

/// The step of one frames-channel message.
pub fn frame_step(log_time: u64, data: &[u8]) -> Step {
    let record: FrameRecord = match serde_json::from_slice(data) {
        Ok(r) => r,
        Err(err) => return Step::Bad(format!("frame message: {err}")),
    };
    if record.direction != "rx" {
        return Step::Tx;
    }
    let Ok(bytes) = hex::decode(&record.data) else {
        return Step::Bad(format!("'{}' is not hex", record.data));
    };
    let item = match record.kind.as_str() {
        "can" => {
            let frame = if record.extended {
                CanFrame::new_extended(record.can_id, &bytes)
            } else {
                CanFrame::new(record.can_id, &bytes)
            };
            match frame {
                Ok(frame) => WireItem::Can(frame),
                Err(err) => return Step::Bad(err.to_string()),
            }
        }
        "serial" => WireItem::Bytes(bytes),
        _ => return Step::Other,
    };
    Step::Rx(Entry {
        stamp_ns: log_time,
        item,
    })
}

/// The step of one candump log line (`None` for blank lines and `#` comments).
pub fn candump_step(line: &str) -> Option<Step> {
    let text = line.trim();
    if text.is_empty() || text.starts_with('#') {
        return None;
    }
    let parsed = match CandumpLine::parse(text) {
        Ok(parsed) => parsed,
        Err(err) => return Some(Step::Bad(format!("'{text}': {err}"))),
    };
    // `(time) iface frame [R|T]`: the fourth field is the direction flag.
    if text.split_whitespace().nth(3) == Some("T") {
        return Some(Step::Tx);
    }
    let stamp_ns = text
        .strip_prefix('(')
        .and_then(|rest| rest.split_once(')'))
        .and_then(|(time, _)| decimal_ns(time.trim()))
        .unwrap_or_else(|| {
            if parsed.time_s.is_finite() && parsed.time_s > 0.0 {
                (parsed.time_s * 1e9) as u64
            } else {
                0
            }
        });
    Some(Step::Rx(Entry {
        stamp_ns,
        item: WireItem::Can(parsed.frame),
    }))
}

/// `SECS[.FRACTION]` to ns, exactly (an `f64` loses the microseconds of an epoch time).
pub fn decimal_ns(text: &str) -> Option<u64> {
    let (secs, fraction) = text.split_once('.').unwrap_or((text, ""));
    let digits = |text: &str| text.bytes().all(|b| b.is_ascii_digit());
    if secs.is_empty() || !digits(secs) || !digits(fraction) {
        return None;
    }
    let mut nanos = 0u64;
    for (i, digit) in fraction.bytes().take(9).enumerate() {
        nanos += u64::from(digit - b'0') * 10u64.pow(8 - i as u32);
    }
    secs.parse::<u64>()
        .ok()?
        .checked_mul(1_000_000_000)?
        .checked_add(nanos)
}

/// The steps of an MCAP file's frames channels: a frame each message, then why the file ended
/// early when it did (a recorder killed mid-write leaves a truncated file: what is there plays).
fn mcap_steps(bytes: &[u8]) -> Vec<Step> {
    use mcap::records::{Record, op};
    // Channel id → whether it is a frames channel.
    let mut frames_channels: HashMap<u16, bool> = HashMap::new();
    let mut steps = Vec::new();
    let walked = crate::mcap_read::each_record(bytes, |opcode, data| {
        if matches!(opcode, op::CHANNEL | op::MESSAGE) {
            match mcap::parse_record(opcode, data)? {
                Record::Channel(c) => {
                    let frames = c.topic.ends_with("/frames") && c.message_encoding == "json";
                    frames_channels.insert(c.id, frames);
                }
                Record::Message { header, data }
                    if frames_channels.get(&header.channel_id) == Some(&true) =>
                {
                    steps.push(frame_step(header.log_time, &data));
                }
                _ => {}
            }
        }
        Ok::<_, mcap::McapError>(ControlFlow::Continue(()))
    });
    if let Err(err) = walked {
        steps.push(Step::Bad(format!("the recording ends early: {err}")));
    }
    steps
}

/// Recordings this process has played: a replay plays once (see the module docs).
static PLAYED: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Opens `path` for `robot`'s service and starts playing it at `speed` in its own thread.
pub fn open(path: &str, speed: ReplaySpeed, robot: RobotKind) -> Result<Bus, BusError> {
    {
        let played = PLAYED.lock().unwrap_or_else(PoisonError::into_inner);
        if played.iter().any(|p| p == path) {
            return Err(open_error(
                path,
                "the replay has ended (a recording plays once; restart chassisd to play it again)",
            ));
        }
    }
    let recording = Recording::open(path)?;
    recording.check(path, robot)?;
    let io = |e: std::io::Error| open_error(path, e);
    let (ours, theirs) = bus_pair(&format!("replay:{path}"), robot.is_can()).map_err(io)?;
    let file = path.to_string();
    std::thread::Builder::new()
        .name("replay".into())
        .spawn(move || {
            let span = info_span!("replay", file = file.as_str(), speed = %speed);
            let _guard = span.enter();
            leave_the_loops_cpu();
            match recording.steps() {
                Ok(steps) => play(steps, theirs, speed, &file),
                Err(err) => error!("{err}"),
            }
        })
        .map_err(io)?;
    PLAYED
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(path.to_string());
    info!(robot = robot.name(), %speed, "replaying {path}");
    Ok(ours)
}

/// A service loop pinned to a CPU (`chassisd --cpu`) hands its pinning down to the threads it
/// starts: the replay moves to the other CPUs, so it never competes with the loop it feeds.
fn leave_the_loops_cpu() {
    use nix::libc::{CPU_ISSET, CPU_SET, CPU_SETSIZE, cpu_set_t, sched_getaffinity};
    let size = std::mem::size_of::<cpu_set_t>();
    // SAFETY: `cpu_set_t` is plain data (all zeroes is the empty set); the calls read and write
    // only the sets passed to them, of the size given.
    unsafe {
        let mut inherited: cpu_set_t = std::mem::zeroed();
        if sched_getaffinity(0, size, &mut inherited) != 0 {
            return;
        }
        let online = nix::libc::sysconf(nix::libc::_SC_NPROCESSORS_ONLN);
        let online = usize::try_from(online)
            .unwrap_or(0)
            .min(usize::try_from(CPU_SETSIZE).unwrap_or(0));
        let mut others: cpu_set_t = std::mem::zeroed();
        let mut count = 0;
        for cpu in 0..online {
            if !CPU_ISSET(cpu, &inherited) {
                CPU_SET(cpu, &mut others);
                count += 1;
            }
        }
        if count > 0 && nix::libc::sched_setaffinity(0, size, &others) == 0 {
            debug!(cpus = count, "replay runs beside the pinned loop");
        }
    }
}

/// What a replay did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct ReplayStats {
    /// Frames (CAN) or chunks (serial) written to the service.
    pub replayed: u64,
    /// Recorded TX frames (not replayed).
    pub recorded_tx: u64,
    /// GPS chunks and other records (not replayed).
    pub other: u64,
    /// Records that could not be read.
    pub bad: u64,
    /// Frames (CAN) or bytes (serial) the service sent during the replay, discarded.
    pub discarded: u64,
}

/// The result of offering one entry to the socket.
enum Push {
    Done,
    /// The socket is full; `offset` bytes of a serial chunk went already.
    Full,
}

/// Writes `entry` (from byte `offset` for a serial chunk) into the pair.
fn push(bus: &mut Bus, entry: &Entry, offset: &mut usize) -> Result<Push, BusError> {
    match (&entry.item, &mut *bus) {
        (WireItem::Bytes(bytes), Bus::Bytes(byte_bus)) => {
            // A chunk must go whole, so write it directly and keep what did not fit.
            // SAFETY: the descriptor belongs to `byte_bus`, borrowed for this call.
            let fd = unsafe { BorrowedFd::borrow_raw(byte_bus.raw_fd()) };
            while *offset < bytes.len() {
                match nix::unistd::write(fd, &bytes[*offset..]) {
                    Ok(n) => *offset += n,
                    Err(Errno::EAGAIN) => return Ok(Push::Full),
                    Err(Errno::EINTR) => {}
                    Err(err) => {
                        return Err(BusError::Disconnected {
                            name: byte_bus.name().to_string(),
                            source: err.into(),
                        });
                    }
                }
            }
            Ok(Push::Done)
        }
        (item, bus) => match bus.transmit(item) {
            Ok(()) => Ok(Push::Done),
            // The service has not read the socket empty yet.
            Err(BusError::TxDropped { .. }) => Ok(Push::Full),
            Err(err) => Err(err),
        },
    }
}

/// Bytes written into the socket that its peer has not read yet.
fn unread(fd: RawFd) -> Option<i32> {
    let mut pending: nix::libc::c_int = 0;
    // SAFETY: TIOCOUTQ (SIOCOUTQ) on a Unix socket stores one int at the pointer we pass; `fd`
    // is open for the whole call.
    let rc = unsafe { nix::libc::ioctl(fd, nix::libc::TIOCOUTQ, &mut pending) };
    (rc == 0).then_some(pending)
}

/// Waits until `fd` is readable (or, when `writable`, has room), or `timeout` passes.
fn wait(fd: RawFd, writable: bool, timeout: Option<Duration>) {
    // SAFETY: the caller owns the descriptor for the whole call.
    let bus_fd = unsafe { BorrowedFd::borrow_raw(fd) };
    let mut flags = PollFlags::POLLIN;
    if writable {
        flags |= PollFlags::POLLOUT;
    }
    let mut fds = [PollFd::new(bus_fd, flags)];
    if let Err(err) = nix::poll::ppoll(&mut fds, timeout.map(TimeSpec::from_duration), None)
        && err != Errno::EINTR
    {
        warn!("replay wait failed: {err}");
    }
}

/// Reads and drops what the service sent: frames (CAN) or bytes (serial).
fn discard(bus: &mut Bus) -> Result<u64, BusError> {
    let mut n = 0u64;
    match bus {
        Bus::Can(can) => {
            while can.recv()?.is_some() {
                n += 1;
            }
        }
        Bus::Bytes(bytes) => {
            let mut buf = [0u8; 4096];
            while let k @ 1.. = bytes.read(&mut buf)? {
                n += k as u64;
            }
        }
    }
    Ok(n)
}

/// Most frames written between two reads of what the service sends.
const BATCH: usize = 256;
/// Longest wait for the service to read the last frames.
const DRAIN_LIMIT: Duration = Duration::from_secs(2);

/// The replay's event loop: plays `steps` into `bus` at `speed`, discarding what the service
/// sends, until the recording ends or the service closes its end.
fn play(
    mut steps: Box<dyn Iterator<Item = Step> + '_>,
    mut bus: Bus,
    speed: ReplaySpeed,
    file: &str,
) {
    let mut stats = ReplayStats::default();
    let is_can = bus.is_can();
    let start = clock::now();
    let mut first: Option<(u64, Timestamp)> = None;
    let mut pending: Option<(Entry, usize)> = None;
    let mut finished = false;
    loop {
        match discard(&mut bus) {
            Ok(n) => stats.discarded += n,
            Err(err) => {
                info!(?stats, "the service closed the replay bus: {err}");
                return;
            }
        }

        let now = clock::now();
        let mut full = false;
        let mut next_due = None;
        for _ in 0..BATCH {
            if pending.is_none() {
                pending = loop {
                    match steps.next() {
                        Some(Step::Rx(entry)) => {
                            if is_can != matches!(entry.item, WireItem::Can(_)) {
                                stats.bad += 1;
                                continue;
                            }
                            break Some((entry, 0));
                        }
                        Some(Step::Tx) => stats.recorded_tx += 1,
                        Some(Step::Other) => stats.other += 1,
                        Some(Step::Bad(reason)) => {
                            stats.bad += 1;
                            if stats.bad.is_power_of_two() {
                                warn!(bad = stats.bad, "skipped a record: {reason}");
                            }
                        }
                        None => break None,
                    }
                };
            }
            let Some((entry, offset)) = pending.as_mut() else {
                finished = true;
                break;
            };
            let (first_ns, first_at) = *first.get_or_insert((entry.stamp_ns, now));
            let due = due_at(first_at, first_ns, entry.stamp_ns, speed);
            if due > now {
                next_due = Some(due);
                break;
            }
            match push(&mut bus, entry, offset) {
                Ok(Push::Done) => {
                    stats.replayed += 1;
                    pending = None;
                }
                Ok(Push::Full) => {
                    full = true;
                    break;
                }
                Err(err) => {
                    info!(?stats, "the service closed the replay bus: {err}");
                    return;
                }
            }
        }
        if let Err(err) = bus.flush()
            && err.is_disconnect()
        {
            info!(?stats, "the service closed the replay bus: {err}");
            return;
        }
        if finished {
            break;
        }
        let timeout = match next_due {
            Some(due) => Some(due.saturating_since(clock::now())),
            // Full: wait for room. Neither: the batch ended, go round at once.
            None if full => Some(Duration::from_secs(1)),
            None => Some(Duration::ZERO),
        };
        wait(bus.raw_fd(), full, timeout);
    }

    // Let the service read the tail: what is buffered here or unread in the socket is lost when
    // the pair closes.
    let drain_start = clock::now();
    while (bus.unflushed() > 0 || unread(bus.raw_fd()).is_some_and(|n| n > 0))
        && clock::now().saturating_since(drain_start) < DRAIN_LIMIT
    {
        if let Err(err) = bus.flush()
            && err.is_disconnect()
        {
            debug!("the service closed the replay bus before the tail was read: {err}");
            break;
        }
        wait(bus.raw_fd(), false, Some(Duration::from_millis(1)));
        stats.discarded += discard(&mut bus).unwrap_or(0);
    }
    let end = clock::now();
    let began = first.map_or(start, |(_, at)| at);
    let seconds = end.secs_since(began);
    let rate = if seconds > 0.0 {
        stats.replayed as f64 / seconds
    } else {
        0.0
    };
    debug!(?stats, "replay finished");
    info!(
        frames = stats.replayed,
        seconds = format!("{seconds:.3}"),
        frames_per_s = format!("{rate:.0}"),
        recorded_tx_skipped = stats.recorded_tx,
        other_skipped = stats.other,
        bad = stats.bad,
        service_tx_discarded = stats.discarded,
        "replay of {file} ended: {} {} in {seconds:.3} s ({rate:.0}/s); the bus ends here",
        stats.replayed,
        if is_can { "frames" } else { "chunks" },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replay_speeds_parse_and_print_back() {
        for (text, speed) in [
            ("max", ReplaySpeed::Max),
            ("1", ReplaySpeed::RECORDED),
            ("2", ReplaySpeed::Factor { permille: 2000 }),
            ("0.5", ReplaySpeed::Factor { permille: 500 }),
            ("1.25", ReplaySpeed::Factor { permille: 1250 }),
            ("0.001", ReplaySpeed::Factor { permille: 1 }),
        ] {
            assert_eq!(text.parse::<ReplaySpeed>().unwrap(), speed);
            assert_eq!(speed.to_string(), text);
        }
        assert_eq!("10x".parse::<ReplaySpeed>().unwrap().to_string(), "10");
        for bad in ["", "fast", "0", "-1", "NaN", "inf", "0.0001", "1e9"] {
            assert!(bad.parse::<ReplaySpeed>().is_err(), "{bad}");
        }
    }

    #[test]
    fn replay_spec_splits_at_the_last_at_sign() {
        assert_eq!(
            parse_spec("/tmp/a@b.mcap@max").unwrap(),
            ("/tmp/a@b.mcap".to_string(), ReplaySpeed::Max)
        );
        assert_eq!(
            parse_spec("run.log").unwrap(),
            ("run.log".to_string(), ReplaySpeed::RECORDED)
        );
        assert!(parse_spec("").is_err());
        assert!(parse_spec("@2").is_err());
        assert!(
            parse_spec("/tmp/a@b.mcap")
                .unwrap_err()
                .to_string()
                .contains("b.mcap")
        );
    }

    #[test]
    fn frames_are_due_at_their_recorded_offset_divided_by_the_speed() {
        let start = Timestamp::from_nanos(1_000);
        let at = |stamp, speed| due_at(start, 5_000, stamp, speed).as_nanos();
        assert_eq!(at(5_000, ReplaySpeed::RECORDED), 1_000);
        assert_eq!(at(6_000, ReplaySpeed::RECORDED), 2_000);
        assert_eq!(at(6_000, ReplaySpeed::Factor { permille: 2000 }), 1_500);
        assert_eq!(at(6_000, ReplaySpeed::Factor { permille: 500 }), 3_000);
        assert_eq!(
            at(4_000, ReplaySpeed::RECORDED),
            1_000,
            "a stamp going back"
        );
        assert_eq!(at(9_999_999, ReplaySpeed::Max), 1_000);
        // A day at a thousandth of the speed does not overflow.
        let day = 86_400_000_000_000u64;
        assert_eq!(
            due_at(start, 0, day, ReplaySpeed::Factor { permille: 1 }).as_nanos(),
            1_000 + day * 1000
        );
    }

    #[test]
    fn candump_lines_become_steps_and_tx_lines_are_not_replayed() {
        let Some(Step::Rx(entry)) = candump_step("(1700000000.250000) titan 211#0102030405060708")
        else {
            panic!("not an rx step");
        };
        assert_eq!(entry.stamp_ns, 1_700_000_000_250_000_000);
        assert_eq!(
            entry.item,
            WireItem::Can(CanFrame::from_candump("211#0102030405060708").unwrap())
        );
        assert!(matches!(
            candump_step("(1.000000) can0 211#01 R"),
            Some(Step::Rx(_))
        ));
        assert_eq!(candump_step("(1.000000) can0 111#01 T"), Some(Step::Tx));
        assert_eq!(candump_step("   "), None);
        assert_eq!(candump_step("# comment"), None);
        assert!(matches!(candump_step("(1.0) can0 zz#"), Some(Step::Bad(_))));
        assert_eq!(decimal_ns("12.5"), Some(12_500_000_000));
        assert_eq!(decimal_ns("3"), Some(3_000_000_000));
        assert_eq!(decimal_ns("0.0000000019"), Some(1));
        assert_eq!(decimal_ns("-1.0"), None);
        assert_eq!(decimal_ns("1e3"), None);
    }

    #[test]
    fn frame_messages_become_steps() {
        let rx = br#"{"stamp_ns":5,"seq":1,"direction":"rx","kind":"can","can_id":529,"extended":false,"len":2,"data":"0A0B"}"#;
        assert_eq!(
            frame_step(7, rx),
            Step::Rx(Entry {
                stamp_ns: 7,
                item: WireItem::Can(CanFrame::new(0x211, &[0x0A, 0x0B]).unwrap()),
            })
        );
        let serial = br#"{"direction":"rx","kind":"serial","data":"AA55"}"#;
        assert_eq!(
            frame_step(1, serial),
            Step::Rx(Entry {
                stamp_ns: 1,
                item: WireItem::Bytes(vec![0xAA, 0x55]),
            })
        );
        let tx = br#"{"direction":"tx","kind":"can","can_id":273,"data":""}"#;
        assert_eq!(frame_step(1, tx), Step::Tx);
        let gps = br#"{"direction":"rx","kind":"gps","data":"24"}"#;
        assert_eq!(frame_step(1, gps), Step::Other);
        assert!(matches!(frame_step(1, b"{"), Step::Bad(_)));
        assert!(matches!(
            frame_step(
                1,
                br#"{"direction":"rx","kind":"can","can_id":4096,"data":""}"#
            ),
            Step::Bad(_)
        ));
    }

    /// Writes a small MCAP recording the way `chassis record` does (frames channel, metadata).
    fn write_mcap(path: &std::path::Path, robot: &str, frames: &[(u64, &str)]) {
        let file = std::io::BufWriter::new(File::create(path).unwrap());
        let mut writer = mcap::Writer::new(file).unwrap();
        let meta = mcap::records::Metadata {
            name: METADATA_NAME.into(),
            metadata: [("robot".to_string(), robot.to_string())].into(),
        };
        writer.write_metadata(&meta).unwrap();
        let schema = writer
            .add_schema("chassis.BusFrame", "jsonschema", b"{}")
            .unwrap();
        let frames_channel = writer
            .add_channel(schema, "/chassis/x/frames", "json", &Default::default())
            .unwrap();
        let state_channel = writer
            .add_channel(schema, "/chassis/x/state", "json", &Default::default())
            .unwrap();
        for (i, (t, json)) in frames.iter().enumerate() {
            let header = mcap::records::MessageHeader {
                channel_id: frames_channel,
                sequence: i as u32,
                log_time: *t,
                publish_time: *t,
            };
            writer
                .write_to_known_channel(&header, json.as_bytes())
                .unwrap();
            let header = mcap::records::MessageHeader {
                channel_id: state_channel,
                ..header
            };
            writer.write_to_known_channel(&header, b"{}").unwrap();
        }
        writer.finish().unwrap();
    }

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("chassisd-replay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    #[test]
    fn an_mcap_recording_yields_its_frames_and_names_its_robot() {
        let path = scratch("steps.mcap");
        write_mcap(
            &path,
            "titan",
            &[
                (
                    100,
                    r#"{"direction":"rx","kind":"can","can_id":529,"data":"01"}"#,
                ),
                (
                    200,
                    r#"{"direction":"tx","kind":"can","can_id":273,"data":"02"}"#,
                ),
                (
                    300,
                    r#"{"direction":"rx","kind":"can","can_id":785,"data":"03"}"#,
                ),
            ],
        );
        let text = path.to_str().unwrap();
        let recording = Recording::open(text).unwrap();
        assert_eq!(recording.robot(), Some(RobotKind::Titan));
        recording.check(text, RobotKind::Titan).unwrap();
        let err = recording.check(text, RobotKind::ScoutMini).unwrap_err();
        assert!(err.to_string().contains("--robot titan"), "{err}");
        let steps: Vec<Step> = recording.steps().unwrap().collect();
        assert_eq!(steps.len(), 3, "{steps:?}");
        assert!(matches!(&steps[0], Step::Rx(e) if e.stamp_ns == 100));
        assert_eq!(steps[1], Step::Tx);
        assert!(matches!(&steps[2], Step::Rx(e) if e.stamp_ns == 300));
        let _ = std::fs::remove_file(path);
    }

    #[test]
    fn a_candump_log_is_refused_for_the_xbot() {
        let path = scratch("xbot.log");
        std::fs::write(&path, "(1.000000) can0 211#01\n").unwrap();
        let text = path.to_str().unwrap();
        let recording = Recording::open(text).unwrap();
        assert_eq!(recording.robot(), None);
        assert!(recording.check(text, RobotKind::Xbot).is_err());
        recording.check(text, RobotKind::Titan).unwrap();
        let _ = std::fs::remove_file(path);
    }

    #[test]
    fn a_replay_plays_every_rx_frame_into_the_pair_then_ends_the_bus() {
        let path = scratch("play.log");
        std::fs::write(
            &path,
            "(10.000000) can0 211#01\n(10.000100) can0 111#02 T\nbad line\n(10.000200) can0 311#03 R\n",
        )
        .unwrap();
        let text = path.to_str().unwrap();
        let mut bus = open(text, ReplaySpeed::Max, RobotKind::Titan).unwrap();
        let mut got = Vec::new();
        let mut gone = false;
        for _ in 0..500 {
            wait(bus.raw_fd(), false, Some(Duration::from_millis(10)));
            match bus.receive(|rx| {
                if let chassis_protocols::Rx::Can(frame) = rx {
                    got.push(frame.id());
                }
            }) {
                Ok(_) => {}
                Err(err) => {
                    assert!(err.is_disconnect());
                    gone = true;
                    break;
                }
            }
            // A datagram peer that left shows only when we send.
            if got.len() == 2 {
                let frame = CanFrame::new(0x111, &[0]).unwrap();
                if let Err(err) = bus.transmit(&WireItem::Can(frame)) {
                    assert!(err.is_disconnect(), "{err}");
                    gone = true;
                    break;
                }
            }
        }
        assert_eq!(got, vec![0x211, 0x311]);
        assert!(gone, "the replay bus did not end");
        let again = open(text, ReplaySpeed::Max, RobotKind::Titan).unwrap_err();
        assert!(again.to_string().contains("plays once"), "{again}");
        let _ = std::fs::remove_file(path);
    }
}
