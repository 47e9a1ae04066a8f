//! Cost of one pass of the engine without I/O: `cargo bench -p chassisd --bench pass`.
// Benchmark setup: a failed unwrap is a broken benchmark, reported by its panic.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;
use std::time::Duration;

use chassis_interfaces::VelocityRequest;
use chassis_protocols::{DriverConfig, Profile, Robot, Timestamp, Transmit};
use chassisd::engine::{Engine, EngineConfig, Wake};
use chassisd::mux::{Mux, MuxConfig};
use chassisd::setup::driver_for;
use chassisd::sim::firmware_for;
use criterion::{Criterion, criterion_group, criterion_main};

const T0: Timestamp = Timestamp::from_millis(1_000);

/// Two seconds of a TITAN's feedback, as its simulated firmware sends it.
fn feedback(profile: &Profile) -> Vec<Transmit> {
    let mut firmware = firmware_for(profile, T0);
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

fn pass(c: &mut Criterion) {
    let profile = Profile::default_for(Robot::Titan);
    let frames = feedback(&profile);
    let config = EngineConfig {
        tick: Duration::from_millis(20),
        mux_status_period: Duration::from_millis(100),
        reconnect_initial: Duration::from_millis(100),
        reconnect_max: Duration::from_millis(2000),
        rx_moderation: Duration::from_micros(4000),
        gps: false,
    };
    let mut engine = Engine::new(
        config,
        driver_for(&profile, &DriverConfig::default(), T0),
        Mux::new(&MuxConfig::default()).unwrap(),
        T0,
    );
    let mut t = T0;
    let mut n = 0usize;
    c.bench_function(
        "engine pass: teleop request + one feedback frame (TITAN, 1 ms apart)",
        |b| {
            b.iter(|| {
                t += Duration::from_millis(1);
                n += 1;
                // The safety monitor every 50 ms, teleop every pass, a frame every pass.
                let safety = n.is_multiple_of(50);
                let wake = Wake {
                    bus: true,
                    sources: 0b10 | u32::from(safety),
                    ..Wake::default()
                };
                let frame = &frames[n % frames.len()];
                let reads = engine.begin_pass(t, wake);
                if reads.sources & 1 != 0 && safety {
                    let heartbeat = VelocityRequest {
                        stamp_ns: t.as_nanos(),
                        ..VelocityRequest::heartbeat()
                    };
                    engine.handle_request(t, 0, &heartbeat).ok();
                }
                if reads.sources & 0b10 != 0 {
                    let drive = VelocityRequest {
                        stamp_ns: t.as_nanos(),
                        ..VelocityRequest::twist(0.5, 0.1)
                    };
                    engine.handle_request(t, 1, black_box(&drive)).ok();
                }
                while let Some(item) = engine.poll_transmit(t) {
                    engine.handle_sent(t, &item);
                }
                if let Some(held) = engine.poll_held_locks() {
                    black_box(held);
                }
                if reads.bus {
                    engine.handle_rx(t, frame.as_rx());
                    while let Some(p) = engine.poll_publication() {
                        black_box(p);
                    }
                    engine.handle_bus_read(t, 1, false);
                }
                engine.handle_timeout(t);
                while let Some(item) = engine.poll_transmit(t) {
                    engine.handle_sent(t, &item);
                }
                engine.end_pass(t);
                while engine.poll_open(t).is_some() {}
                while let Some(p) = engine.poll_publication() {
                    black_box(p);
                }
                engine.spend_wakeups(t, wake.sources)
            })
        },
    );
}

criterion_group!(benches, pass);
criterion_main!(benches);
