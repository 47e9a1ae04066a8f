//! Cost of one mux decision, with the parse of its requests: `cargo bench -p chassisd`.
// Benchmark setup: a failed unwrap is a broken benchmark, reported by its panic.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use chassis_interfaces::{ValidRequest, VelocityRequest};
use chassis_protocols::Timestamp;
use chassisd::mux::Mux;
use chassisd_config::mux::MuxConfig;
use criterion::{Criterion, criterion_group, criterion_main};

fn mux(c: &mut Criterion) {
    let mut mux = Mux::new(&MuxConfig::default()).unwrap();
    let mut t = 0u64;
    c.bench_function(
        "mux: request + evaluate (3 sources, 1 lock, smoothing)",
        |b| {
            b.iter(|| {
                t += 1_000_000;
                let now = Timestamp::from_nanos(t);
                // Each parsed as the engine parses what a source wrote.
                let heartbeat = ValidRequest::try_from(VelocityRequest {
                    stamp_ns: t,
                    ..VelocityRequest::heartbeat()
                })
                .unwrap();
                let drive = ValidRequest::try_from(black_box(VelocityRequest {
                    stamp_ns: t,
                    ..VelocityRequest::twist(0.5, 0.1)
                }))
                .unwrap();
                let _ = mux.on_request(now, 0, &heartbeat);
                let _ = mux.on_request(now, 1, black_box(&drive));
                mux.evaluate(now)
            })
        },
    );
}

criterion_group!(benches, mux);
criterion_main!(benches);
