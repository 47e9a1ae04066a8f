//! The black box's recording: the inputs chassisd's engine was handed and what it wrote and
//! published, one [`Event`] a JSON line; a kept window is an MCAP file of those lines on
//! [`TOPIC`] (readable in Foxglove). chassisd records and replays them (`chassisd::blackbox`);
//! this crate is the format alone, so that its reader can be fuzzed without the service's
//! iceoryx2 stack.

use std::collections::BTreeMap;
use std::io::Write;
use std::ops::ControlFlow;

use chassis_bus::mcap_read::each_record;

use serde::{Deserialize, Serialize};

/// The topic of a kept window's events.
pub const TOPIC: &str = "/chassisd/blackbox";

/// Bytes, as hex in the recording.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Bytes(#[serde(with = "hex::serde")] pub Vec<u8>);

/// One item on the bus.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Item {
    Can {
        id: u32,
        extended: bool,
        data: Bytes,
    },
    Bytes(Bytes),
    /// A report of the CAN controller on itself.
    Controller(Report),
}

/// [`ControllerReport`], field for field.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Report {
    pub state: u8,
    pub restarted: bool,
    pub bus_error: bool,
    pub no_ack: bool,
    pub overflow: bool,
    pub counters: Option<(u8, u8)>,
    pub restart_ms: Option<u32>,
    pub from_frame: bool,
}

/// How a write or a flush of the bus went.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Out(u64),
    Held(u64),
    Dropped(String),
    Lost(String),
}

/// What the engine published, as the replay checks it: the mux status and the control answers
/// as their bytes, the tap, the state and the description (hundreds of each a second on a busy
/// bus) as the [`digest`] of their bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Published {
    State(u64),
    Frame(u64),
    Mux(Bytes),
    Description(u64),
    Response { ticket: u64, answer: Bytes },
}

/// The CRC-32 (IEEE) of `bytes`: a state of 904 bytes is a few dozen nanoseconds of the loop's
/// time with crc32fast's carry-less multiplication, where a byte-wise hash took a microsecond.
pub fn digest(bytes: &[u8]) -> u64 {
    u64::from(crc32fast::hash(bytes))
}

/// A held lock as restored at start.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Lock {
    pub name: String,
    pub holder: String,
    pub since: u64,
}

/// One input of the engine, or one thing it wrote or published (checked on replay).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "in", rename_all = "snake_case")]
pub enum Event {
    /// The run's first record: the version and the effective configuration (TOML).
    Start {
        version: String,
        config: String,
        now: u64,
        unix_ns: u64,
    },
    /// The held locks read back at start.
    Restored {
        locks: Vec<Lock>,
    },
    /// The held locks could not be read back.
    RestoreFailed {
        reason: String,
    },
    /// The bus could not be opened at start.
    BusLost {
        now: u64,
        reason: String,
    },
    /// The service's first publications.
    Began {
        now: u64,
    },
    /// One pass, and what woke it.
    Pass {
        bus: bool,
        gps: bool,
        sources: u32,
        control: bool,
        sim: bool,
        polled: bool,
    },
    /// The shell asked whether receive moderation pauses the bus.
    RxPaused {
        now: u64,
    },
    /// The shell spent the wake budget of the listeners that fired.
    Wakeups {
        now: u64,
        fired: u32,
    },
    /// The shell rebuilt its wait set.
    ResetWakeups,
    /// The orderly stop.
    Stop {
        now: u64,
    },
    /// The clock, read by the engine.
    Now {
        t: u64,
    },
    /// Requests read, each with its source's index.
    Requests {
        read: Vec<(usize, Bytes)>,
    },
    /// Control requests read, each with its ticket.
    Controls {
        read: Vec<(u64, Bytes)>,
    },
    /// An item written, and how the write went.
    Write {
        item: Item,
        outcome: Outcome,
    },
    Flush {
        outcome: Outcome,
    },
    /// One read of the bus: the items with their stamps, then whether more was pending (or the
    /// bus was lost).
    BusRead {
        items: Vec<(u64, Item)>,
        #[serde(default, skip_serializing_if = "is_false")]
        more: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lost: Option<String>,
    },
    /// Bytes of the GPS receiver (`failed`: it was lost).
    Gps {
        chunks: Vec<Bytes>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        failed: Option<String>,
    },
    /// A device opened (its name) or not.
    Open {
        result: Result<String, String>,
    },
    /// The held locks were kept, or the write failed.
    Keep {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        failed: Option<String>,
    },
    /// A publication, and whether it went out.
    Publish {
        what: Published,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        failed: Option<String>,
    },
    /// Readers woken, or not.
    Woke {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        failed: Option<String>,
    },
    /// The recorder dropped this many passes' events here: the replay goes on from the next
    /// [`Event::Snapshot`].
    Gap {
        dropped: u64,
    },
    /// The ring's oldest part is gone between the start and what follows: the replay goes on
    /// from the next [`Event::Snapshot`].
    Cut,
    /// The engine's state between two passes (`Engine::snapshot`), taken as each segment of the
    /// ring begins: a replay checks that it holds the same, or goes on from it after a cut or a
    /// gap.
    Snapshot {
        state: Bytes,
    },
}

impl Event {
    /// The instant this event carries, if it carries one.
    pub fn time(&self) -> Option<u64> {
        match self {
            Event::Start { now, .. }
            | Event::BusLost { now, .. }
            | Event::Began { now }
            | Event::RxPaused { now }
            | Event::Wakeups { now, .. }
            | Event::Stop { now } => Some(*now),
            Event::Now { t } => Some(*t),
            _ => None,
        }
    }

    /// One line of the recording.
    pub fn to_line(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string(self)
    }

    /// Appends the event's line, its newline included, to `out` (the recorder's encoding,
    /// compiled with this crate: optimised in every profile, see the workspace's Cargo.toml).
    pub fn write_line(&self, out: &mut Vec<u8>) -> Result<(), serde_json::Error> {
        serde_json::to_writer(&mut *out, self)?;
        out.push(b'\n');
        Ok(())
    }

    pub fn from_line(line: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str(line)
    }
}

fn is_false(value: &bool) -> bool {
    !value
}

/// Why bytes are not a recording.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("not a black box MCAP file: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("a recording is UTF-8 text")]
    Utf8,
    #[error("line {line}: {source}")]
    Line {
        line: usize,
        source: serde_json::Error,
    },
}

/// Reads a recording's text: one event a line.
pub fn parse(text: &str) -> Result<Vec<Event>, ReadError> {
    text.lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(n, line)| {
            Event::from_line(line).map_err(|source| ReadError::Line {
                line: n + 1,
                source,
            })
        })
        .collect()
}

/// The events of a kept window (MCAP), or of the ring's text (one JSON event a line).
pub fn read(bytes: &[u8]) -> Result<Vec<Event>, ReadError> {
    use mcap::records::{Record, op};
    if !bytes.starts_with(mcap::MAGIC) {
        return parse(std::str::from_utf8(bytes).map_err(|_| ReadError::Utf8)?);
    }
    // Only the two kinds of record the events are in are parsed (mcap 0.26 panics on some
    // corrupt records of other kinds, an attachment's among them); the rest are skipped.
    let (mut channel, mut text) = (None, String::new());
    each_record(bytes, |opcode, data| {
        match (opcode, channel) {
            (op::CHANNEL, _) | (op::MESSAGE, Some(_)) => {}
            _ => return Ok::<_, ReadError>(ControlFlow::Continue(())),
        }
        match mcap::parse_record(opcode, data)? {
            Record::Channel(found) if found.topic == TOPIC => channel = Some(found.id),
            Record::Message { header, data } if Some(header.channel_id) == channel => {
                text.push_str(std::str::from_utf8(&data).map_err(|_| ReadError::Utf8)?);
                text.push('\n');
            }
            _ => {}
        }
        Ok(ControlFlow::Continue(()))
    })?;
    parse(&text)
}

/// Writes `text` (events, one a line) as an MCAP window into `out`, `reason` in its metadata.
pub fn write_mcap<W: Write + std::io::Seek>(
    out: W,
    text: &[u8],
    reason: &str,
) -> Result<(), mcap::McapError> {
    let mut writer = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(1)
        .create(out)?;
    writer.write_metadata(&mcap::records::Metadata {
        name: "chassisd.blackbox".into(),
        metadata: BTreeMap::from([("reason".to_string(), reason.to_string())]),
    })?;
    let channel = writer.add_channel(0, TOPIC, "json", &BTreeMap::new())?;
    let mut time = 0;
    for (sequence, line) in text
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .enumerate()
    {
        if let Some(t) = std::str::from_utf8(line)
            .ok()
            .and_then(|l| Event::from_line(l).ok())
            .and_then(|e| e.time())
        {
            time = t;
        }
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: sequence as u32,
            log_time: time,
            publish_time: time,
        };
        writer.write_to_known_channel(&header, line)?;
    }
    writer.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A zstd chunk whose one record says it is ~3.7e18 bytes long (what the fuzzer found):
    /// mcap 0.26's `MessageStream` reserved that much and aborted; the reader refuses it.
    #[test]
    fn a_chunk_record_longer_than_its_chunk_is_an_error_not_a_panic() {
        // Found by the fuzz target: an uncompressed chunk whose record claims more bytes than
        // the chunk's records hold; mcap 0.26 alone panics on it.
        let bytes = include_bytes!("../../../fuzz/seeds/blackbox_reader/chunk-overrun.mcap");
        assert!(matches!(
            read(bytes),
            Err(ReadError::Mcap(mcap::McapError::UnexpectedEoc))
        ));
        // And one whose length runs past the end of a u64 before the file's end.
        let bytes = include_bytes!("../../../fuzz/seeds/blackbox_reader/top-level-overflow.mcap");
        assert!(read(bytes).is_err());
    }

    #[test]
    fn records_of_other_kinds_are_not_parsed() {
        // Found by the fuzz target: an attachment shorter than its own CRC, on which mcap 0.26's
        // record parser panics; a recording's events are never in one, so it is skipped (and the
        // file, cut short after it, is refused).
        let bytes = include_bytes!("../../../fuzz/seeds/blackbox_reader/attachment-overrun.mcap");
        assert!(read(bytes).is_err());
    }

    #[test]
    fn a_record_longer_than_the_ceiling_is_an_error() {
        let window = include_bytes!("../../../fuzz/seeds/blackbox_reader/window.mcap");
        assert!(!read(window).expect("a kept window reads").is_empty());
        let corrupt = include_bytes!("../testdata/record-of-3.7e18-bytes.mcap");
        let error = read(corrupt).expect_err("a record beyond the ceiling");
        assert!(
            matches!(
                error,
                ReadError::Mcap(mcap::McapError::RecordTooLarge { .. })
            ),
            "{error}"
        );
    }
}
