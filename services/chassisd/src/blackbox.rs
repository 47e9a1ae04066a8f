//! The black box: every input the engine is handed, recorded where the shell hands it over.
//!
//! The engine is sans-IO: everything it decides on comes through [`PassIo`] (the clock, the
//! requests, the control requests, how each write and read of the bus went) and through the few
//! calls the shell makes between passes (the pass itself with what woke it, receive moderation,
//! the wake budget, the restored locks). [`Taped`] wraps any [`PassIo`] and notes each of them as
//! an [`Event`], with what the engine wrote on the bus and published on the frame tap, the mux
//! and the control answers, so that feeding the same events to the same engine
//! (`blackbox::replay`) must write and publish the same bytes. The recording is one JSON object
//! per line: a new input of the engine is one more [`Event`] variant.
//!
//! The shell hands the events of each pass to a thread that keeps them in a bounded ring on disk
//! (`blackbox::ring`): a full channel drops the pass' events (counted, and marked in the
//! recording by a [`Event::Gap`]), never the pass.

pub mod replay;
pub mod ring;

use chassis_bus::can_controller::ControllerReport;
use chassis_interfaces::{ControlRequest, MuxStatus, VelocityRequest, ZeroReason};
use chassis_protocols::{CanFrame, Timestamp, WireItem};
use serde::{Deserialize, Serialize};
use zerocopy::IntoBytes;

use crate::engine::{
    BusItem, Device, HeldLock, PassIo, Readers, Ticket, ToPublish, Wake, WriteError, Written,
};

/// Bytes, as hex in the recording.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Bytes(#[serde(with = "hex::serde")] pub Vec<u8>);

impl Bytes {
    fn of(value: &(impl IntoBytes + zerocopy::Immutable + ?Sized)) -> Self {
        Self(value.as_bytes().to_vec())
    }
}

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

impl Item {
    fn of_wire(item: &WireItem) -> Self {
        match item {
            WireItem::Can(frame) => Item::Can {
                id: frame.id(),
                extended: frame.is_extended(),
                data: Bytes(frame.data().to_vec()),
            },
            WireItem::Bytes(bytes) => Item::Bytes(Bytes(bytes.clone())),
        }
    }

    fn of_bus(item: &BusItem) -> Self {
        match item {
            BusItem::Rx(item) => Self::of_wire(item),
            BusItem::Controller(r) => Item::Controller(Report {
                state: r.state,
                restarted: r.restarted,
                bus_error: r.bus_error,
                no_ack: r.no_ack,
                overflow: r.overflow,
                counters: r.counters,
                restart_ms: r.restart_ms,
                from_frame: r.from_frame,
            }),
        }
    }

    /// The item as the engine takes it; `None` for a CAN frame no bus carries.
    pub fn to_bus(&self) -> Option<BusItem> {
        Some(match self {
            Item::Can { id, extended, data } => BusItem::Rx(WireItem::Can(if *extended {
                CanFrame::new_extended(*id, &data.0).ok()?
            } else {
                CanFrame::new(*id, &data.0).ok()?
            })),
            Item::Bytes(bytes) => BusItem::Rx(WireItem::Bytes(bytes.0.clone())),
            Item::Controller(r) => BusItem::Controller(ControllerReport {
                state: r.state,
                restarted: r.restarted,
                bus_error: r.bus_error,
                no_ack: r.no_ack,
                overflow: r.overflow,
                counters: r.counters,
                restart_ms: r.restart_ms,
                from_frame: r.from_frame,
            }),
        })
    }
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
/// bus) as the FNV-1a digest of their bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Published {
    State(u64),
    Frame(u64),
    Mux(Bytes),
    Description(u64),
    Response { ticket: Ticket, answer: Bytes },
}

/// FNV-1a, 64 bits.
fn digest(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, &b| {
        (hash ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

impl Published {
    fn of(publication: &ToPublish) -> Self {
        match publication {
            ToPublish::State(state) => Published::State(digest(state.as_bytes())),
            ToPublish::Frame(frame) => Published::Frame(digest(frame.as_bytes())),
            ToPublish::Mux(status) => Published::Mux(Bytes::of(&**status)),
            ToPublish::Description(d) => Published::Description(digest(d.as_bytes())),
            ToPublish::Response { ticket, response } => Published::Response {
                ticket: *ticket,
                answer: Bytes::of(response),
            },
        }
    }
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
        read: Vec<(Ticket, Bytes)>,
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
    /// The recorder dropped this many passes' events here: the replay stops.
    Gap {
        dropped: u64,
    },
    /// The ring's oldest part is gone between the start and what follows: the replay stops.
    Cut,
}

impl Event {
    /// The pass of `wake`.
    pub fn pass(wake: Wake) -> Self {
        Event::Pass {
            bus: wake.bus,
            gps: wake.gps,
            sources: wake.sources,
            control: wake.control,
            sim: wake.sim,
            polled: wake.polled,
        }
    }

    pub fn restored(locks: &[HeldLock]) -> Self {
        Event::Restored {
            locks: locks
                .iter()
                .map(|l| Lock {
                    name: l.name.clone(),
                    holder: l.holder.clone(),
                    since: l.since.as_nanos(),
                })
                .collect(),
        }
    }

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

    pub fn from_line(line: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str(line)
    }
}

/// A stop that was not asked for by the one who drove, beginning at `now`: the required source
/// silent, a lock engaged (the operator's e-stop, a latch), or the robot held (the bus lost, a
/// chassis fault).
pub fn is_unasked_stop(before: &MuxStatus, now: &MuxStatus) -> bool {
    let stop = |m: &MuxStatus| {
        matches!(
            m.zero_reason,
            ZeroReason::REQUIRED_SOURCE_STALE | ZeroReason::LOCKED | ZeroReason::HELD
        )
        .then_some((m.zero_reason, m.stop))
    };
    // The service's start is not a stop: the required source has not spoken yet.
    before.zero_reason != ZeroReason::STARTING && stop(now).is_some() && stop(before) != stop(now)
}

/// A [`PassIo`] that notes everything the engine is handed into `events`.
#[derive(Debug)]
pub struct Taped<'a, I> {
    pub io: &'a mut I,
    pub events: &'a mut Vec<Event>,
    /// The name of the device last opened (the engine borrows it).
    opened: String,
}

impl<'a, I> Taped<'a, I> {
    pub fn new(io: &'a mut I, events: &'a mut Vec<Event>) -> Self {
        Self {
            io,
            events,
            opened: String::new(),
        }
    }
}

fn outcome<E: std::fmt::Display>(result: &Result<Written, WriteError<E>>) -> Outcome {
    match result {
        Ok(Written::Out(t)) => Outcome::Out(t.as_nanos()),
        Ok(Written::Held(t)) => Outcome::Held(t.as_nanos()),
        Err(WriteError::Dropped(e)) => Outcome::Dropped(e.to_string()),
        Err(WriteError::Lost(e)) => Outcome::Lost(e.to_string()),
    }
}

fn failed<E: std::fmt::Display>(result: &Result<(), E>) -> Option<String> {
    result.as_ref().err().map(ToString::to_string)
}

fn is_false(value: &bool) -> bool {
    !value
}

impl<I: PassIo> PassIo for Taped<'_, I> {
    type Error = I::Error;

    fn now(&mut self) -> Timestamp {
        let t = self.io.now();
        self.events.push(Event::Now { t: t.as_nanos() });
        t
    }

    fn read_requests(&mut self, sources: u32, mut take: impl FnMut(usize, &VelocityRequest)) {
        let mut read = Vec::new();
        self.io.read_requests(sources, |source, request| {
            read.push((source, Bytes::of(request)));
            take(source, request);
        });
        if !read.is_empty() {
            self.events.push(Event::Requests { read });
        }
    }

    fn read_control(&mut self, mut take: impl FnMut(Ticket, &ControlRequest)) {
        let mut read = Vec::new();
        self.io.read_control(|ticket, request| {
            read.push((ticket, Bytes::of(request)));
            take(ticket, request);
        });
        if !read.is_empty() {
            self.events.push(Event::Controls { read });
        }
    }

    fn serve_simulator(&mut self, now: Timestamp) {
        self.io.serve_simulator(now);
    }

    fn acknowledge(&mut self, sources: u32) {
        self.io.acknowledge(sources);
    }

    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<Self::Error>> {
        let result = self.io.write(item);
        self.events.push(Event::Write {
            item: Item::of_wire(item),
            outcome: outcome(&result),
        });
        result
    }

    fn flush(&mut self) -> Result<Timestamp, WriteError<Self::Error>> {
        let result = self.io.flush();
        let noted = match &result {
            Ok(t) => Outcome::Out(t.as_nanos()),
            Err(WriteError::Dropped(e)) => Outcome::Dropped(e.to_string()),
            Err(WriteError::Lost(e)) => Outcome::Lost(e.to_string()),
        };
        self.events.push(Event::Flush { outcome: noted });
        result
    }

    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, Self::Error> {
        let before = into.len();
        let result = self.io.read_bus(into);
        let items = into
            .get(before..)
            .unwrap_or_default()
            .iter()
            .map(|(t, item)| (t.as_nanos(), Item::of_bus(item)))
            .collect();
        self.events.push(Event::BusRead {
            items,
            more: result.as_ref().is_ok_and(|more| *more),
            lost: result.as_ref().err().map(ToString::to_string),
        });
        result
    }

    fn read_gps(&mut self, mut take: impl FnMut(&[u8])) -> Result<(), Self::Error> {
        let mut chunks = Vec::new();
        let result = self.io.read_gps(|bytes| {
            chunks.push(Bytes(bytes.to_vec()));
            take(bytes);
        });
        self.events.push(Event::Gps {
            chunks,
            failed: failed(&result),
        });
        result
    }

    fn open(&mut self, now: Timestamp, device: Device) -> Result<&str, Self::Error> {
        let result = self.io.open(now, device).map(str::to_string);
        self.events.push(Event::Open {
            result: match &result {
                Ok(name) => Ok(name.clone()),
                Err(e) => Err(e.to_string()),
            },
        });
        let name = result?;
        self.opened = name;
        Ok(&self.opened)
    }

    fn close(&mut self, device: Device) {
        self.io.close(device);
    }

    fn keep_locks(&mut self, held: &[HeldLock]) -> Result<(), Self::Error> {
        let result = self.io.keep_locks(held);
        self.events.push(Event::Keep {
            failed: failed(&result),
        });
        result
    }

    fn publish(&mut self, publication: ToPublish) -> Result<(), Self::Error> {
        let what = Published::of(&publication);
        let result = self.io.publish(publication);
        self.events.push(Event::Publish {
            what,
            failed: failed(&result),
        });
        result
    }

    fn wake(&mut self, readers: Readers) -> Result<(), Self::Error> {
        let result = self.io.wake(readers);
        self.events.push(Event::Woke {
            failed: failed(&result),
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(zero_reason: u8, stop: u8) -> MuxStatus {
        MuxStatus {
            zero_reason,
            stop,
            ..MuxStatus::default()
        }
    }

    #[test]
    fn every_event_reads_back_from_its_line() {
        let events = [
            Event::Start {
                version: "0.1.0".into(),
                config: "[service]\nrobot = \"titan\"\n".into(),
                now: 5,
                unix_ns: 7,
            },
            Event::pass(Wake {
                bus: true,
                sources: 0b101,
                ..Wake::default()
            }),
            Event::Requests {
                read: vec![(1, Bytes::of(&VelocityRequest::twist(0.3, 0.0)))],
            },
            Event::Write {
                item: Item::Can {
                    id: 0x111,
                    extended: false,
                    data: Bytes(vec![1, 2, 3]),
                },
                outcome: Outcome::Held(9),
            },
            Event::BusRead {
                items: vec![(3, Item::Bytes(Bytes(vec![0xA5])))],
                more: true,
                lost: None,
            },
            Event::Publish {
                what: Published::Frame(42),
                failed: Some("loan".into()),
            },
            Event::Gap { dropped: 2 },
        ];
        for event in events {
            let line = event.to_line().unwrap();
            assert!(!line.contains('\n'), "{line}");
            assert_eq!(Event::from_line(&line).unwrap(), event, "{line}");
        }
    }

    #[test]
    fn a_stop_is_one_nobody_asked_for_when_it_begins() {
        use chassis_interfaces::Stop;
        let driving = status(ZeroReason::NONE, Stop::NONE);
        let locked = status(ZeroReason::LOCKED, Stop::NONE);
        let bus = status(ZeroReason::HELD, Stop::BUS);
        let starting = status(ZeroReason::STARTING, Stop::NONE);
        let stale = status(ZeroReason::REQUIRED_SOURCE_STALE, Stop::NONE);
        assert!(is_unasked_stop(&driving, &locked));
        assert!(is_unasked_stop(&locked, &bus));
        assert!(!is_unasked_stop(&locked, &locked));
        assert!(!is_unasked_stop(&locked, &driving));
        assert!(!is_unasked_stop(&starting, &stale));
        let idle = status(ZeroReason::NO_ACTIVE_SOURCE, Stop::NONE);
        assert!(is_unasked_stop(&idle, &stale));
    }
}
