//! Cost of one pass of the engine without I/O (`Engine::run_pass` on a `PassIo` that takes and
//! gives at once): `cargo bench -p chassisd --bench pass`.
// Benchmark setup: a failed unwrap is a broken benchmark, reported by its panic.
#![allow(clippy::unwrap_used)]

use std::convert::Infallible;
use std::hint::black_box;
use std::time::Duration;

use chassis_interfaces::{ControlRequest, VelocityRequest};
use chassis_protocols::{DriverConfig, Profile, RobotKind, Timestamp, WireItem};
use chassisd::engine::{
    BusItem, Device, Engine, EngineConfig, HeldLock, PassIo, Readers, Ticket, ToPublish, Wake,
    WriteError, Written,
};
use chassisd::mux::Mux;
use chassisd_config::mux::MuxConfig;
use criterion::{Criterion, criterion_group, criterion_main};

const T0: Timestamp = Timestamp::from_millis(1_000);

/// Two seconds of a TITAN's feedback, as its simulated firmware sends it.
fn feedback(profile: &Profile) -> Vec<WireItem> {
    let mut firmware = profile.firmware(T0);
    let mut frames = Vec::new();
    let mut t = T0;
    while t < T0 + Duration::from_secs(2) {
        firmware.handle_timeout(t);
        while let Some(item) = firmware.poll_transmit(t) {
            frames.push(item);
        }
        t = firmware
            .poll_timeout()
            .unwrap()
            .max(t + Duration::from_micros(1));
    }
    frames
}

/// The world of the benchmark: a request of teleop every pass (and of the safety monitor every
/// 50th), one feedback frame per pass, a bus that writes at once, ports that take everything.
struct BenchIo {
    now: Timestamp,
    /// Sources with a request not yet read (one bit each), and the frame not yet read.
    requests: u32,
    frame: Option<WireItem>,
}

impl PassIo for BenchIo {
    type Error = Infallible;

    fn now(&mut self) -> Timestamp {
        self.now
    }

    fn read_requests(&mut self, sources: u32, mut take: impl FnMut(usize, &VelocityRequest)) {
        let due = self.requests & sources;
        self.requests &= !sources;
        if due & 1 != 0 {
            take(0, &heartbeat(self.now));
        }
        if due & 0b10 != 0 {
            take(1, black_box(&drive(self.now)));
        }
    }

    fn read_control(&mut self, _take: impl FnMut(Ticket, &ControlRequest)) {}

    fn serve_simulator(&mut self, _now: Timestamp) {}

    fn acknowledge(&mut self, _sources: u32) {}

    fn write(&mut self, item: &WireItem) -> Result<Written, WriteError<Infallible>> {
        black_box(item);
        Ok(Written::Out(self.now))
    }

    fn flush(&mut self) -> Result<Timestamp, WriteError<Infallible>> {
        Ok(self.now)
    }

    fn read_bus(&mut self, into: &mut Vec<(Timestamp, BusItem)>) -> Result<bool, Infallible> {
        into.extend(
            self.frame
                .take()
                .map(|frame| (self.now, BusItem::Rx(frame))),
        );
        Ok(false)
    }

    fn read_gps(&mut self, _take: impl FnMut(&[u8])) -> Result<(), Infallible> {
        Ok(())
    }

    fn open(&mut self, _now: Timestamp, _device: Device) -> Result<&str, Infallible> {
        Ok("bench")
    }

    fn close(&mut self, _device: Device) {}

    fn keep_locks(&mut self, held: &[HeldLock]) -> Result<(), Infallible> {
        black_box(held);
        Ok(())
    }

    fn publish(&mut self, publication: ToPublish) -> Result<(), Infallible> {
        black_box(publication);
        Ok(())
    }

    fn wake(&mut self, readers: Readers) -> Result<(), Infallible> {
        black_box(readers);
        Ok(())
    }
}

fn heartbeat(t: Timestamp) -> VelocityRequest {
    VelocityRequest {
        stamp_ns: t.as_nanos(),
        ..VelocityRequest::heartbeat()
    }
}

fn drive(t: Timestamp) -> VelocityRequest {
    VelocityRequest {
        stamp_ns: t.as_nanos(),
        ..VelocityRequest::twist(0.5, 0.1)
    }
}

fn engine(profile: &Profile) -> Engine {
    let config = EngineConfig {
        tick: Duration::from_millis(20),
        mux_status_period: Duration::from_millis(100),
        reconnect_initial: Duration::from_millis(100),
        reconnect_max: Duration::from_millis(2000),
        rx_moderation: Duration::from_micros(4000),
        gps: false,
        bus: "can:bench0".into(),
        descriptions: Vec::new(),
        recording: false,
        drive_cut: None,
    };
    Engine::new(
        config,
        profile.driver(&DriverConfig::default(), T0),
        Mux::new(&MuxConfig::default()).unwrap(),
        T0,
    )
}

/// What wakes pass `n`: the bus and teleop, the safety monitor every 50th.
fn wake(n: usize) -> Wake {
    Wake {
        bus: true,
        sources: 0b10 | u32::from(n.is_multiple_of(50)),
        ..Wake::default()
    }
}

fn pass(c: &mut Criterion) {
    let profile = RobotKind::Titan.entry().defaults();
    let frames = feedback(&profile);

    let mut engine_a = engine(&profile);
    let mut io = BenchIo {
        now: T0,
        requests: 0,
        frame: None,
    };
    let mut n = 0usize;
    c.bench_function(
        "engine pass: teleop request + one feedback frame (TITAN, 1 ms apart)",
        |b| {
            b.iter(|| {
                n += 1;
                io.now += Duration::from_millis(1);
                let wake = wake(n);
                io.requests = wake.sources;
                io.frame = Some(frames[n % frames.len()].clone());
                engine_a.run_pass(&mut io, wake);
                engine_a.spend_wakeups(io.now, wake.sources)
            })
        },
    );

    // The same pass stepped by hand, in the order the shell ran before the engine owned it: what
    // the one sequence costs over calling the steps directly.
    let mut engine_b = engine(&profile);
    let mut t = T0;
    let mut n = 0usize;
    c.bench_function("engine pass stepped by hand (the same work)", |b| {
        b.iter(|| {
            t += Duration::from_millis(1);
            n += 1;
            let wake = wake(n);
            let frame = frames[n % frames.len()].clone();
            let reads = engine_b.begin_pass(t, wake);
            if reads.sources & wake.sources & 1 != 0 {
                engine_b.handle_request(t, 0, &heartbeat(t)).ok();
            }
            if reads.sources & 0b10 != 0 {
                engine_b.handle_request(t, 1, black_box(&drive(t))).ok();
            }
            while let Some(item) = engine_b.poll_transmit(t) {
                black_box(&item);
                engine_b.handle_sent(t, &item);
            }
            if let Some(held) = engine_b.poll_held_locks() {
                black_box(held);
            }
            if reads.bus {
                engine_b.handle_rx(t, frame.as_rx());
                while let Some(p) = engine_b.poll_publication() {
                    black_box(p);
                }
                engine_b.handle_bus_read(t, 1, false);
            }
            engine_b.handle_timeout(t);
            while let Some(item) = engine_b.poll_transmit(t) {
                black_box(&item);
                engine_b.handle_sent(t, &item);
            }
            engine_b.end_pass(t);
            while engine_b.poll_open(t).is_some() {}
            while let Some(p) = engine_b.poll_publication() {
                black_box(p);
            }
            engine_b.spend_wakeups(t, wake.sources)
        })
    });
}

criterion_group!(benches, pass);
criterion_main!(benches);
