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
//! The shell hands the events of its passes, every 100 ms, to a thread that keeps them in a
//! bounded ring on disk (`blackbox::ring`): a full channel drops the passes' events (counted, and
//! marked in the recording by a [`Event::Gap`]), never a pass. As each segment of the ring
//! begins, the shell adds the engine's whole state between two passes ([`Event::Snapshot`],
//! `Engine::snapshot`): the replay of a window whose beginning the ring let go of starts there.

pub mod replay;
pub mod ring;

use chassis_bus::can_controller::ControllerReport;
use chassis_interfaces::{ControlRequest, MuxStatus, VelocityRequest, ZeroReason};
use chassis_protocols::{CanFrame, Timestamp, WireItem};
pub use chassisd_blackbox::{Bytes, Event, Item, Lock, Outcome, Published, Report, digest};
use zerocopy::IntoBytes;

use crate::engine::{
    BusItem, Device, HeldLock, PassIo, Readers, Ticket, ToPublish, Wake, WriteError, Written,
};

fn bytes_of(value: &(impl IntoBytes + zerocopy::Immutable + ?Sized)) -> Bytes {
    Bytes(value.as_bytes().to_vec())
}

/// An item written, as recorded.
pub fn wire_item(item: &WireItem) -> Item {
    match item {
        WireItem::Can(frame) => Item::Can {
            id: frame.id(),
            extended: frame.is_extended(),
            data: Bytes(frame.data().to_vec()),
        },
        WireItem::Bytes(bytes) => Item::Bytes(Bytes(bytes.clone())),
    }
}

fn bus_item(item: &BusItem) -> Item {
    match item {
        BusItem::Rx(item) => wire_item(item),
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

/// A recorded item as the engine takes it; `None` for a CAN frame no bus carries.
pub fn to_bus(item: &Item) -> Option<BusItem> {
    Some(match item {
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

/// A publication, as recorded: the mux status and the control answers as their bytes, the
/// tap, the state and the description (hundreds of each a second on a busy bus) as the digest
/// of their bytes.
pub fn published(publication: &ToPublish) -> Published {
    match publication {
        ToPublish::State(state) => Published::State(digest(state.as_bytes())),
        ToPublish::Frame(frame) => Published::Frame(digest(frame.as_bytes())),
        ToPublish::Mux(status) => Published::Mux(bytes_of(&**status)),
        ToPublish::Description(d) => Published::Description(digest(d.as_bytes())),
        ToPublish::Response { ticket, response } => Published::Response {
            ticket: *ticket,
            answer: bytes_of(response),
        },
    }
}

/// The pass of `wake`.
pub fn pass(wake: Wake) -> Event {
    Event::Pass {
        bus: wake.bus,
        gps: wake.gps,
        sources: wake.sources,
        control: wake.control,
        sim: wake.sim,
        polled: wake.polled,
    }
}

/// The held locks read back at start.
pub fn restored(locks: &[HeldLock]) -> Event {
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

/// What a pass read from the bus, kept as the engine took it until the pass is over: the
/// recorded items (their bytes) are made then ([`Taped::finish`]). A burst of feedback frames
/// is read at once and each frame's state published in turn: made at once, they held every
/// state of the burst back by the microseconds they take. The buffers are kept from pass to
/// pass. (A publication's digest is made at once: a copy kept for later costs more, and on a
/// flooded bus the copies of a batch outgrow the cache.)
#[derive(Debug, Default)]
pub struct Deferred {
    /// The items read, as the engine took them.
    items: Vec<(Timestamp, BusItem)>,
    /// Each read's event: its index, and its items in [`Deferred::items`].
    reads: Vec<(usize, std::ops::Range<usize>)>,
}

/// A [`PassIo`] that notes everything the engine is handed into `events`.
#[derive(Debug)]
pub struct Taped<'a, I> {
    pub io: &'a mut I,
    pub events: &'a mut Vec<Event>,
    deferred: &'a mut Deferred,
    /// The name of the device last opened (the engine borrows it).
    opened: String,
}

impl<'a, I> Taped<'a, I> {
    pub fn new(io: &'a mut I, events: &'a mut Vec<Event>, deferred: &'a mut Deferred) -> Self {
        Self {
            io,
            events,
            deferred,
            opened: String::new(),
        }
    }

    /// Makes the events the pass left to make ([`Deferred`]): call it once the pass is over.
    pub fn finish(self) {
        let Deferred { items, reads } = self.deferred;
        for (index, read) in reads.drain(..) {
            if let Some(Event::BusRead { items: noted, .. }) = self.events.get_mut(index) {
                *noted = (items.get(read).unwrap_or_default().iter())
                    .map(|(t, item)| (t.as_nanos(), bus_item(item)))
                    .collect();
            }
        }
        items.clear();
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
            read.push((source, bytes_of(request)));
            take(source, request);
        });
        if !read.is_empty() {
            self.events.push(Event::Requests { read });
        }
    }

    fn read_control(&mut self, mut take: impl FnMut(Ticket, &ControlRequest)) {
        let mut read = Vec::new();
        self.io.read_control(|ticket, request| {
            read.push((ticket, bytes_of(request)));
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
            item: wire_item(item),
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
        let deferred = &mut *self.deferred;
        let from = deferred.items.len();
        deferred
            .items
            .extend_from_slice(into.get(before..).unwrap_or_default());
        let read = from..deferred.items.len();
        deferred.reads.push((self.events.len(), read));
        self.events.push(Event::BusRead {
            items: Vec::new(),
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
        let what = published(&publication);
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
            pass(Wake {
                bus: true,
                sources: 0b101,
                ..Wake::default()
            }),
            Event::Requests {
                read: vec![(1, bytes_of(&VelocityRequest::twist(0.3, 0.0)))],
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
