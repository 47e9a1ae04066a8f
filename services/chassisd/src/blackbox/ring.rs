//! The recording on disk: a bounded ring of segments in the state directory, written by a thread
//! of its own, and the windows kept as MCAP files (one JSON message per event on
//! `/chassisd/blackbox`, readable in Foxglove) that survive restarts.
//!
//! Each segment is a zstd frame of JSON lines (`ring-N.jsonl.zst`), flushed every
//! [`FLUSH_EVERY`] so that a crash loses no more; the ring is bounded by the bytes on disk and by
//! the age of its oldest segment, whichever comes first.
//!
//! The loop gathers the events of its passes and hands them over a bounded channel every
//! [`HAND_OVER`] or [`HAND_OVER_EVENTS`] ([`Tape::send`]): one wake-up of the writer for many passes, where one a pass
//! cost the loop a futex call and the writer a context switch each. When the writer falls behind
//! (a slow disk) the passes' events are dropped and counted, never a pass, and a pass the disk
//! refuses (full, failing) is counted by the writer ([`Tape::unrecorded`]).
//! The writer watches the mux decisions go by: a stop that was not asked for
//! ([`super::is_unasked_stop`]) keeps the window around it, [`KEEP_AFTER`] after it included,
//! as does [`Tape::keep`] (SIGUSR1). A previous run that ended without its orderly stop (a crash,
//! `kill -9`, a power cut) is kept when the service starts again.
// The writer owns its own clock: the window after a keep is wall time of the recorder's thread.
#![allow(clippy::disallowed_methods)]

use std::collections::VecDeque;
use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::time::{Duration, Instant};

use chassis_interfaces::MuxStatus;
use tracing::{info, warn};
use zerocopy::FromBytes;

use chassisd_blackbox::write_mcap;
pub use chassisd_blackbox::{ReadError, TOPIC, read};

use super::{Event, Published, is_unasked_stop};

/// How long after a keep its window goes on.
pub const KEEP_AFTER: Duration = Duration::from_secs(5);
/// The longest a window goes on after its first keep while more keeps join it.
const KEEP_LONGEST: Duration = Duration::from_secs(30);
/// Hand-overs the channel holds while the writer is busy: seconds of a slow disk.
const CHANNEL: usize = 64;
/// The longest the loop keeps the events of its passes before handing them to the writer, and
/// the most it gathers: a batch stays small enough to be allocated once, from the allocator's
/// pools (a full bus brings some 15,000 events a second, a replay at full speed a hundred times
/// more).
const HAND_OVER: Duration = Duration::from_millis(100);
const HAND_OVER_EVENTS: usize = 512;
/// Segments of the ring, each an eighth of its bound: the oldest is let go of when a ninth begins.
const SEGMENTS: u64 = 8;
/// The longest the end of the ring waits in the compressor before it is on disk.
const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// The compression level of the ring's segments: zstd's fastest. Its default, 3, took half of the
/// writer's time at a full bus and wrote no fewer bytes (0.8 % of a core and 4.9 MB a minute
/// against 0.5 % and 4.3 MB at a full 500 kbit/s simulated bus, release build).
const LEVEL: i32 = 1;

enum Msg {
    /// The events of this many passes.
    Events(Vec<Event>, u64),
    Keep(String),
}

/// The loop's end of the recorder.
#[derive(Debug)]
pub struct Tape {
    tx: SyncSender<Msg>,
    writer: std::thread::JoinHandle<()>,
    /// The events of the passes not handed over yet, the pass under way last.
    pub events: Vec<Event>,
    /// What the pass under way leaves to make into its events ([`super::Taped::finish`]).
    pub deferred: super::Deferred,
    /// The passes `events` holds, and since when it holds the first.
    passes: u64,
    since: Instant,
    /// Passes dropped since the last ones the writer took.
    dropped: u64,
    /// Passes dropped since start.
    dropped_total: u64,
    /// Passes the writer could not write (a full or failing disk), counted by it.
    unwritten: Arc<AtomicU64>,
    /// The writer began a segment: the engine's state is due ([`Tape::snapshot_due`]).
    snapshot_due: Arc<AtomicBool>,
}

impl Tape {
    /// Starts the writer on `dir` with `bound` on the ring and at most `kept` kept files.
    pub fn start(dir: &Path, bound: Bound, kept: usize) -> io::Result<Self> {
        let mut ring = Ring::open(dir, bound, kept)?;
        let unwritten = Arc::clone(&ring.unwritten);
        let snapshot_due = Arc::clone(&ring.snapshot_due);
        let (tx, rx) = sync_channel(CHANNEL);
        let writer = std::thread::Builder::new()
            .name("blackbox".into())
            .spawn(move || ring.run(&rx))?;
        Ok(Self {
            tx,
            writer,
            events: Vec::with_capacity(HAND_OVER_EVENTS + HAND_OVER_EVENTS / 2),
            deferred: super::Deferred::default(),
            passes: 0,
            since: Instant::now(),
            dropped: 0,
            dropped_total: 0,
            unwritten,
            snapshot_due,
        })
    }

    /// True once after the writer began a segment: the engine's state belongs in it, so that a
    /// window whose beginning the ring let go of is replayed from there. A state that cannot be
    /// taken now is [`Tape::snapshot_later`].
    pub fn snapshot_due(&self) -> bool {
        self.snapshot_due.swap(false, Ordering::Relaxed)
    }

    pub fn snapshot_later(&self) {
        self.snapshot_due.store(true, Ordering::Relaxed);
    }

    /// Passes left unrecorded since start: dropped while the writer fell behind, or not written
    /// by it (the disk full or failing).
    pub fn unrecorded(&self) -> u64 {
        self.dropped_total + self.unwritten.load(Ordering::Relaxed)
    }

    /// A pass ended: its events join the ones to hand over, which go to the writer once they
    /// are [`HAND_OVER`] old or [`HAND_OVER_EVENTS`] many.
    pub fn send(&mut self) {
        if self.events.is_empty() {
            return;
        }
        if self.passes == 0 {
            self.since = Instant::now();
        }
        self.passes += 1;
        if self.events.len() >= HAND_OVER_EVENTS || self.since.elapsed() >= HAND_OVER {
            self.hand_over();
        }
    }

    /// Hands the events gathered to the writer, or drops them (counted).
    fn hand_over(&mut self) {
        if self.events.is_empty() {
            return;
        }
        let passes = std::mem::take(&mut self.passes).max(1);
        let room = Vec::with_capacity(HAND_OVER_EVENTS + HAND_OVER_EVENTS / 2);
        let mut batch = std::mem::replace(&mut self.events, room);
        if self.dropped > 0 {
            batch.insert(
                0,
                Event::Gap {
                    dropped: self.dropped,
                },
            );
        }
        match self.tx.try_send(Msg::Events(batch, passes)) {
            Ok(()) => self.dropped = 0,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                let before = self.dropped_total;
                self.dropped += passes;
                self.dropped_total += passes;
                if before.checked_ilog2() != self.dropped_total.checked_ilog2() {
                    warn!(
                        dropped = self.dropped_total,
                        "black box: the recorder falls behind; passes go unrecorded"
                    );
                }
            }
        }
    }

    /// Hands over what is left and waits for the writer: a keep asked for is written now.
    pub fn finish(mut self) {
        self.send();
        self.hand_over();
        drop(self.tx);
        if self.writer.join().is_err() {
            warn!("black box: the recorder's thread panicked");
        }
    }

    /// Keeps the window around now.
    pub fn keep(&mut self, reason: &str) {
        self.hand_over();
        if self.tx.try_send(Msg::Keep(reason.to_string())).is_err() {
            warn!("black box: cannot keep the window ({reason}): the recorder falls behind");
        }
    }
}

/// How much the ring holds: the bytes of its segments on disk, and how old the oldest may be.
#[derive(Debug, Clone, Copy)]
pub struct Bound {
    pub bytes: u64,
    pub age: Duration,
}

/// The segment being written: its file behind the compressor, and the bytes that reached it.
struct Segment {
    zstd: zstd::stream::write::Encoder<'static, Counted>,
    opened: Instant,
    flushed: Instant,
    /// Bytes and passes handed to the compressor since its last flush.
    pending: u64,
    passes: u64,
}

struct Counted {
    file: BufWriter<File>,
    bytes: u64,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Segment {
    fn create(path: &Path) -> io::Result<Self> {
        let file = BufWriter::new(File::create(path)?);
        let now = Instant::now();
        Ok(Self {
            zstd: zstd::stream::write::Encoder::new(Counted { file, bytes: 0 }, LEVEL)?,
            opened: now,
            flushed: now,
            pending: 0,
            passes: 0,
        })
    }

    /// Everything written so far on disk, readable (the frame is left open).
    fn flush(&mut self) -> io::Result<()> {
        self.zstd.flush()?;
        self.flushed = Instant::now();
        self.pending = 0;
        self.passes = 0;
        Ok(())
    }

    /// The frame ended and on disk.
    fn finish(self) -> io::Result<()> {
        self.zstd.finish()?.flush()
    }
}

/// The writer's side: the ring's files.
struct Ring {
    dir: PathBuf,
    kept_dir: PathBuf,
    bound: Bound,
    kept: usize,
    /// The run's first events (the configuration, the restored locks, the first
    /// publications), kept whatever the ring lets go of.
    header: Vec<u8>,
    in_header: bool,
    /// The segments' files, oldest first; the last is `current`'s.
    segments: VecDeque<PathBuf>,
    current: Option<Segment>,
    next_segment: u64,
    /// The ring has let go of a segment.
    cut: bool,
    last_mux: Option<MuxStatus>,
    /// A keep waiting for its window's end, when it was first asked, and why.
    due: Option<(Instant, Instant, Vec<String>)>,
    /// Passes not written since start (shared with the [`Tape`]), and since the last written.
    unwritten: Arc<AtomicU64>,
    unwritten_since: u64,
    /// Set as a segment begins (shared with the [`Tape`]).
    snapshot_due: Arc<AtomicBool>,
}

impl Ring {
    fn open(dir: &Path, bound: Bound, kept: usize) -> io::Result<Self> {
        let dir = dir.join("blackbox");
        let kept_dir = dir.join("kept");
        fs::create_dir_all(&kept_dir)?;
        let mut ring = Self {
            dir,
            kept_dir,
            bound,
            kept,
            header: Vec::new(),
            in_header: true,
            segments: VecDeque::new(),
            current: None,
            next_segment: 0,
            cut: false,
            last_mux: None,
            due: None,
            unwritten: Arc::new(AtomicU64::new(0)),
            unwritten_since: 0,
            snapshot_due: Arc::new(AtomicBool::new(false)),
        };
        ring.take_over_previous()?;
        Ok(ring)
    }

    fn header_path(&self) -> PathBuf {
        self.dir.join("header.jsonl")
    }

    /// The previous run's ring: kept when it ended without its orderly stop, then cleared.
    fn take_over_previous(&mut self) -> io::Result<()> {
        let (text, segments) = ring_files(&self.dir)?;
        if let Some(text) = text {
            let last = text
                .split(|&b| b == b'\n')
                .rev()
                .find(|l| !l.is_empty())
                .unwrap_or_default();
            if !last.starts_with(br#"{"in":"stop""#) {
                let reason = "the previous run ended without its orderly stop";
                match self.write_kept(&text, reason) {
                    Ok(path) => warn!(file = %path.display(), "black box: {reason}: kept"),
                    Err(e) => warn!("black box: {reason}; not kept: {e}"),
                }
            }
        }
        for segment in segments {
            fs::remove_file(segment)?;
        }
        fs::write(self.header_path(), b"")
    }

    fn run(&mut self, rx: &Receiver<Msg>) {
        loop {
            let msg = match &self.due {
                Some((at, ..)) => rx.recv_timeout(at.saturating_duration_since(Instant::now())),
                None => rx.recv().map_err(|_| RecvTimeoutError::Disconnected),
            };
            match msg {
                Ok(Msg::Events(events, passes)) => self.record(events, passes),
                Ok(Msg::Keep(reason)) => self.schedule(reason),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    if let Some(current) = self.current.take()
                        && let Err(e) = current.finish()
                    {
                        warn!("black box: writing the ring: {e}");
                    }
                    if let Some((.., reasons)) = self.due.take() {
                        self.keep(&reasons);
                    }
                    return;
                }
            }
            if self
                .due
                .as_ref()
                .is_some_and(|(at, ..)| *at <= Instant::now())
                && let Some((.., reasons)) = self.due.take()
            {
                self.keep(&reasons);
            }
        }
    }

    /// Writes one pass' events. A pass that cannot be written is counted, with the passes the
    /// segment held since its last flush (lost with it); the segment is let go of, and the next
    /// pass written begins with a gap (a replay stops there).
    fn record(&mut self, mut events: Vec<Event>, passes: u64) {
        if self.unwritten_since > 0 {
            let dropped = self.unwritten_since;
            events.insert(0, Event::Gap { dropped });
        }
        match self.append(&events, passes) {
            Ok(()) => self.unwritten_since = 0,
            Err(e) => {
                let lost = (self.current.take()).map_or(passes, |s| s.passes.max(passes));
                self.unwritten_since += lost;
                let before = self.unwritten.fetch_add(lost, Ordering::Relaxed);
                if before.checked_ilog2() != (before + lost).checked_ilog2() {
                    warn!(
                        unwritten = before + lost,
                        "black box: writing the ring: {e}"
                    );
                }
            }
        }
    }

    /// A keep asked while another waits joins it, and its window goes on [`KEEP_AFTER`] after
    /// it too, up to [`KEEP_LONGEST`] after the first.
    fn schedule(&mut self, reason: String) {
        let now = Instant::now();
        match &mut self.due {
            Some((at, first, reasons)) => {
                *at = (now + KEEP_AFTER).min(*first + KEEP_LONGEST);
                reasons.push(reason);
            }
            None => self.due = Some((now + KEEP_AFTER, now, vec![reason])),
        }
    }

    /// Writes `events`, of `passes` passes: the run's first ones (up to its first pass) to the
    /// header, the others to the ring.
    fn append(&mut self, events: &[Event], passes: u64) -> io::Result<()> {
        let mut text = Vec::new();
        for event in events {
            if self.in_header && matches!(event, Event::Pass { .. }) {
                self.write_header(&std::mem::take(&mut text))?;
                self.in_header = false;
            }
            if let Event::Publish {
                what: Published::Mux(bytes),
                ..
            } = event
                && let Ok(status) = MuxStatus::read_from_bytes(&bytes.0)
            {
                if self
                    .last_mux
                    .as_ref()
                    .is_some_and(|before| is_unasked_stop(before, &status))
                {
                    self.schedule(format!("stop: {}", status.why()));
                }
                self.last_mux = Some(status);
            }
            event.write_line(&mut text)?;
        }
        if self.in_header {
            return self.write_header(&text);
        }
        self.write_segment(&text, passes)
    }

    fn write_header(&mut self, text: &[u8]) -> io::Result<()> {
        self.header.extend_from_slice(text);
        (fs::OpenOptions::new().append(true))
            .open(self.header_path())?
            .write_all(text)
    }

    fn write_segment(&mut self, text: &[u8], passes: u64) -> io::Result<()> {
        let per_segment = (self.bound.bytes / SEGMENTS).max(1);
        let per_age = self.bound.age / SEGMENTS as u32;
        let full = self.current.as_ref().is_none_or(|current| {
            current.zstd.get_ref().bytes >= per_segment || current.opened.elapsed() >= per_age
        });
        if full {
            // Flushed first: a failure then counts the passes the segment held.
            if let Some(current) = &mut self.current {
                current.flush()?;
            }
            if let Some(current) = self.current.take() {
                current.finish()?;
            }
            self.next_segment += 1;
            let path = self
                .dir
                .join(format!("ring-{:08}.jsonl.zst", self.next_segment));
            self.current = Some(Segment::create(&path)?);
            self.segments.push_back(path);
            self.snapshot_due.store(true, Ordering::Relaxed);
            while self.segments.len() as u64 > SEGMENTS {
                if let Some(old) = self.segments.pop_front() {
                    fs::remove_file(old)?;
                    self.cut = true;
                }
            }
        }
        if let Some(current) = &mut self.current {
            current.zstd.write_all(text)?;
            current.passes += passes;
            // What the compressor holds counts on disk only once flushed: flushed at least once
            // a segment's worth, so that the bound holds at any rate.
            current.pending += text.len() as u64;
            if current.flushed.elapsed() >= FLUSH_EVERY || current.pending >= per_segment {
                current.flush()?;
            }
        }
        Ok(())
    }

    /// Writes the window (the header, the ring) as a kept file.
    fn keep(&mut self, reasons: &[String]) {
        let reason = reasons.join("; ");
        let result = self
            .window()
            .and_then(|text| self.write_kept(&text, &reason));
        match result {
            Ok(path) => info!(file = %path.display(), "black box kept: {reason}"),
            Err(e) => warn!("black box: keeping the window ({reason}): {e}"),
        }
    }

    fn window(&mut self) -> io::Result<Vec<u8>> {
        if let Some(current) = &mut self.current {
            current.flush()?;
        }
        let mut text = self.header.clone();
        if self.cut {
            Event::Cut.write_line(&mut text)?;
        }
        for segment in &self.segments {
            text.extend(read_segment(segment)?);
        }
        Ok(text)
    }

    /// Writes `text` (events, one a line) as an MCAP file in the kept directory; the oldest
    /// kept files beyond the bound go.
    fn write_kept(&self, text: &[u8], reason: &str) -> io::Result<PathBuf> {
        let unix = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        let path = self.kept_dir.join(format!(
            "{}.{:03}.mcap",
            unix.as_secs(),
            unix.subsec_millis()
        ));
        let out = BufWriter::new(File::create(&path)?);
        write_mcap(out, text, reason).map_err(io::Error::other)?;
        let mut kept: Vec<PathBuf> = fs::read_dir(&self.kept_dir)?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect();
        kept.sort();
        let excess = kept.len().saturating_sub(self.kept.max(1));
        for old in kept.iter().take(excess) {
            fs::remove_file(old)?;
        }
        Ok(path)
    }
}

/// The ring in `dir` (`<state dir>/blackbox`) as one recording, if it holds one, and its
/// segments' files.
fn ring_files(dir: &Path) -> io::Result<(Option<Vec<u8>>, Vec<PathBuf>)> {
    let header = dir.join("header.jsonl");
    let mut segments: Vec<PathBuf> = fs::read_dir(dir)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "zst" || x == "jsonl") && p != &header)
        .collect();
    segments.sort();
    let Ok(mut text) = fs::read(&header) else {
        return Ok((None, segments));
    };
    for segment in &segments {
        text.extend(read_segment(segment)?);
    }
    Ok((Some(text), segments))
}

/// A segment's lines: what its compressed frame holds up to the last whole line (a segment
/// written until a crash ends where its last flush did), or a plain segment's.
fn read_segment(path: &Path) -> io::Result<Vec<u8>> {
    if path.extension().is_some_and(|x| x == "jsonl") {
        return fs::read(path);
    }
    let mut zstd = zstd::stream::read::Decoder::new(File::open(path)?)?;
    let mut text = Vec::new();
    let mut chunk = [0u8; 1 << 16];
    loop {
        match io::Read::read(&mut zstd, &mut chunk) {
            Ok(0) => break,
            Ok(n) => text.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            // The frame's end not written: the run ended before the segment did.
            Err(_) => break,
        }
    }
    let whole = text.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    text.truncate(whole);
    Ok(text)
}

/// The live ring in `dir` (`<state dir>/blackbox`) as one recording.
pub fn read_ring(dir: &Path) -> io::Result<Vec<u8>> {
    ring_files(dir)?
        .0
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no black box ring here"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("chassisd-ring-{test}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    fn bound(bytes: u64) -> Bound {
        Bound {
            bytes,
            age: Duration::from_secs(600),
        }
    }

    fn start() -> Event {
        Event::Start {
            version: "0.1.0".into(),
            config: String::new(),
            now: 1,
            unix_ns: 1,
        }
    }

    fn pass(t: u64) -> Vec<Event> {
        vec![
            crate::blackbox::pass(crate::engine::Wake::default()),
            Event::Now { t },
            Event::Publish {
                what: Published::State(t),
                failed: None,
            },
        ]
    }

    fn kept(ring: &Ring) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = fs::read_dir(&ring.kept_dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        files
    }

    #[test]
    fn the_ring_lets_go_of_its_oldest_and_a_kept_window_says_so() {
        let dir = dir("bounded");
        let mut ring = Ring::open(&dir, bound(2_000), 2).unwrap();
        ring.append(&[start()], 1).unwrap();
        for t in 0..200 {
            ring.append(&pass(t), 1).unwrap();
        }
        assert!(ring.cut);
        assert_eq!(ring.segments.len() as u64, SEGMENTS);
        let on_disk: u64 = ring
            .segments
            .iter()
            .map(|p| fs::metadata(p).unwrap().len())
            .sum();
        assert!(on_disk < 2_000 + 2_000 / SEGMENTS + 200, "{on_disk} bytes");
        for _ in 0..3 {
            ring.keep(&["operator".into()]);
        }
        let files = kept(&ring);
        assert_eq!(files.len(), 2, "{files:?}");
        let events = read(&fs::read(&files[1]).unwrap()).unwrap();
        assert_eq!(events[0], start());
        assert_eq!(events[1], Event::Cut);
        assert_eq!(events.last(), pass(199).last());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn passes_a_full_disk_refuses_are_counted_and_the_next_written_begins_with_a_gap() {
        let dir = dir("full");
        // Segments of 1000 bytes: the compressor is flushed every few passes.
        let mut ring = Ring::open(&dir, bound(8_000), 4).unwrap();
        ring.record(vec![start()], 1);
        // The ring's first segment is /dev/full: its flush fails with ENOSPC, and every pass it
        // held since is lost with it.
        let first = ring.dir.join("ring-00000001.jsonl.zst");
        std::os::unix::fs::symlink("/dev/full", &first).unwrap();
        let mut t = 0;
        while ring.unwritten.load(Ordering::Relaxed) == 0 {
            assert!(t < 200, "no pass counted unwritten");
            ring.record(pass(t), 1);
            t += 1;
        }
        let unwritten = ring.unwritten.load(Ordering::Relaxed);
        assert_eq!(unwritten, t, "every pass the segment held is counted");
        assert!(unwritten > 1, "the segment held one pass only");
        assert_eq!(ring.unwritten_since, unwritten);
        // The next pass goes to a new segment, and begins with the gap.
        ring.record(pass(t), 1);
        assert_eq!(ring.unwritten_since, 0);
        ring.current.as_mut().unwrap().flush().unwrap();
        let text = read_segment(&ring.dir.join("ring-00000002.jsonl.zst")).unwrap();
        let events = read(&text).unwrap();
        assert_eq!(events[0], Event::Gap { dropped: unwritten });
        assert_eq!(events.last(), pass(t).last());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_run_that_ended_without_its_orderly_stop_is_kept_at_the_next_start() {
        let dir = dir("crash");
        let mut ring = Ring::open(&dir, bound(1 << 20), 4).unwrap();
        ring.append(&[start()], 1).unwrap();
        ring.append(&pass(5), 1).unwrap();
        // The flush of every second, then a pass still in the compressor when the run ends.
        ring.current.as_mut().unwrap().flush().unwrap();
        ring.append(&pass(6), 1).unwrap();
        drop(ring);
        let mut ring = Ring::open(&dir, bound(1 << 20), 4).unwrap();
        let files = kept(&ring);
        assert_eq!(files.len(), 1);
        let events = read(&fs::read(&files[0]).unwrap()).unwrap();
        assert_eq!(events.len(), 4, "{events:?}");
        assert_eq!(events.last(), pass(5).last());
        // An orderly stop leaves nothing to keep.
        ring.append(&[start()], 1).unwrap();
        ring.append(&[Event::Stop { now: 9 }], 1).unwrap();
        drop(ring);
        let ring = Ring::open(&dir, bound(1 << 20), 4).unwrap();
        assert_eq!(kept(&ring).len(), 1);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn what_is_not_a_recording_is_an_error() {
        assert!(read(b"").unwrap().is_empty());
        assert!(read(b"{\"in\":\"now\"}\n").is_err());
        assert!(read(b"not json").is_err());
        assert!(read(&[0xff, 0xfe]).is_err());
        let mut mcap = mcap::MAGIC.to_vec();
        mcap.extend_from_slice(b"truncated");
        assert!(read(&mcap).is_err());
    }
}
