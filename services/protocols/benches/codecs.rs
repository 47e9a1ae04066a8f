//! Per-frame cost of the codecs and drivers: `cargo bench -p chassis-protocols`.
// Benchmark setup: a failed unwrap is a broken benchmark, reported by its panic.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use chassis_interfaces::GpsFix;
use chassis_protocols::agilex_v1::V1Profile;
use chassis_protocols::driver::{Driver, DriverConfig, Rx};
use chassis_protocols::titan::TitanProfile;
use chassis_protocols::xbot::XbotProfile;
use chassis_protocols::{CanFrame, Timestamp, agilex_v1, nmea, titan, xbot};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const XBOT_SENSOR: &str = "AA5547100162260302000100000005 0A0006000000000000060003000000000000050000000000000000E80301000000000000000000000000000000000000000000000000000000000002DC2F";

const NMEA_GGA: &str = "$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76";
const NMEA_RMC: &str = "$GNRMC,083559.00,A,3352.12800,S,15112.55800,E,0.004,77.52,091202,,,A*56";

fn hex(text: &str) -> Vec<u8> {
    let text: String = text.split_whitespace().collect();
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
        .collect()
}

fn codecs(c: &mut Criterion) {
    let titan_profile = TitanProfile::default();
    let status = CanFrame::from_candump("211#000101E000000200").unwrap();
    let motion = CanFrame::from_candump("221#01F4000000000064").unwrap();
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(1));
    g.bench_function("titan 0x211 system status", |b| {
        b.iter(|| titan::decode(black_box(&status), &titan_profile))
    });
    g.bench_function("titan 0x221 motion feedback", |b| {
        b.iter(|| titan::decode(black_box(&motion), &titan_profile))
    });
    let scout_profile = V1Profile::default();
    let scout = CanFrame::from_candump("130#01000A0000000044").unwrap();
    g.bench_function("scout-mini 0x130 with checksum", |b| {
        b.iter(|| agilex_v1::decode(black_box(&scout), &scout_profile))
    });
    let xbot_profile = XbotProfile::default();
    let sensor = hex(XBOT_SENSOR);
    g.bench_function("xbot 0x10 sensor frame through the stream parser", |b| {
        let mut parser = xbot::StreamParser::new();
        b.iter(|| {
            parser.push(black_box(&sensor));
            parser.next_frame(&xbot_profile)
        })
    });
    g.bench_function("nmea GGA sentence", |b| {
        b.iter(|| nmea::parse_sentence(black_box(NMEA_GGA)))
    });
    g.bench_function("nmea RMC sentence", |b| {
        b.iter(|| nmea::parse_sentence(black_box(NMEA_RMC)))
    });
    g.bench_function("nmea GGA line through the line reader into the fix", |b| {
        let mut reader = nmea::LineReader::new();
        let mut fix = GpsFix::default();
        let line = format!("{NMEA_GGA}\r\n");
        b.iter(|| {
            reader.push(black_box(line.as_bytes()));
            while let Some(line) = reader.next_line() {
                if let Ok(sentence) = nmea::parse_sentence(&line) {
                    nmea::apply(&sentence, &mut fix);
                }
            }
        })
    });
    // The same sentences through the `nmea` crate, for reference (see src/nmea/mod.rs).
    g.bench_function("nmea GGA sentence, nmea crate", |b| {
        b.iter(|| ::nmea::parse_str(black_box(NMEA_GGA)).is_ok())
    });
    g.bench_function("nmea RMC sentence, nmea crate", |b| {
        b.iter(|| ::nmea::parse_str(black_box(NMEA_RMC)).is_ok())
    });
    g.finish();

    let mut g = c.benchmark_group("encode");
    let command = titan::Frame::MotionCommand(titan::MotionCommand {
        linear_mps: 1.2,
        steer_rad: 0.1,
    });
    g.bench_function("titan 0x111", |b| {
        b.iter(|| black_box(&command).encode(&titan_profile))
    });
    let scout_command = agilex_v1::Frame::MotionCommand(agilex_v1::MotionCommand::drive(0.5, 0.1));
    g.bench_function("scout-mini 0x130", |b| {
        b.iter(|| black_box(&scout_command).encode(7, &scout_profile))
    });
    g.finish();

    let mut g = c.benchmark_group("driver");
    g.throughput(Throughput::Elements(1));
    let mut driver = titan::TitanDriver::new(
        titan_profile.clone(),
        DriverConfig::default(),
        Timestamp::ZERO,
    );
    let mut t = 0u64;
    g.bench_function("titan handle_rx (decode + state update)", |b| {
        b.iter(|| {
            t += 20_000;
            driver.handle_rx(Timestamp::from_nanos(t), Rx::Can(black_box(&motion)));
        })
    });
    g.finish();
}

criterion_group!(benches, codecs);
criterion_main!(benches);
