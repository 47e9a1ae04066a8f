//! The fault matrix, on the bus: garbage frames and bad checksums injected by the simulated
//! chassis of the TITAN, a protocol-V2 robot (HUNTER), the SCOUT MINI and the XBot, at rising
//! rates while teleop drives. Each storm is held against the sender's truth: the simulated
//! chassis counts what it injected as each item leaves it (`chassis sim truth --injected`), the
//! row requires that it injected exactly what was asked (more than nothing), and the service's
//! counters and the frames on its tap must match that count. Figures are recorded with
//! [`Figures`] (`scripts/reliability`).
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::collections::HashMap;
use std::time::{Duration, Instant};

use chassis_protocols::{Protocol, RobotKind};
use chassis_tests::faults::*;
use chassis_tests::*;

const UP: Duration = Duration::from_secs(10);
const SUITE: &str = "faults_bus";

/// The storms' rows in the table.
const RANK: u32 = 300;

// ----- Garbage and bad-checksum storms -----

/// One storm: `kind` injected at `rate` per second for two seconds.
#[derive(Debug, Clone, Copy)]
struct Storm {
    kind: u8,
    /// Bad frames (garbage bytes, bad reports) a second.
    rate: u32,
    unit: &'static str,
}

/// The longest a storm's last injected items may take to leave the simulated chassis after the
/// storm ended: pending corruptions go out with the next feedback frames (7 SCOUT MINI frames
/// every 20 ms corrupt the last 25 in 80 ms; an XBot report every 20 ms), garbage at once. The
/// service's counters are compared with the sender's only after that, at a quiet moment (an
/// injected silence): no difference is allowed.
const SETTLE_BOUND: Duration = Duration::from_secs(1);

/// What one storm phase measured.
#[derive(Debug, Default, Clone, Copy)]
struct StormResult {
    /// Bad items (frames, bytes, reports) the test asked the simulator for.
    asked: u64,
    /// Bad items the simulated chassis sent, by its own count (the sender's truth).
    injected: u64,
    /// For CAN garbage: its bytes, by the sender's count (8 to a frame asked).
    injected_bytes: u64,
    /// From the end of the storm to the sender's count reaching what was asked (the last
    /// corruptions still pending), ms.
    settle_ms: f64,
    /// Bad items on the wire, from the service's frame tap.
    on_wire: u64,
    /// Bad items the service counted.
    counted: u64,
    tap_frames: u64,
    good_on_tap: u64,
    decoded: u64,
    /// Good frames the chassis sent that did not arrive (rolling counts; SCOUT MINI).
    count_gaps: u64,
    min_speed: f32,
}

impl StormResult {
    /// Good frames (reports) on the wire that the service did not decode, and gaps.
    fn lost(&self) -> u64 {
        self.good_on_tap.saturating_sub(self.decoded) + self.count_gaps
    }

    /// The storm happened (something was asked and injected) and went exactly as asked: the
    /// sender injected what was asked, the wire carried it, the service counted it and
    /// decoded every good frame.
    fn exact(&self) -> bool {
        self.asked > 0
            && self.injected == self.asked
            && self.settle_ms <= SETTLE_BOUND.as_secs_f64() * 1e3
            && self.on_wire == self.injected
            && self.counted == self.injected
            && self.decoded == self.good_on_tap
            && self.count_gaps == 0
    }
}

/// How a robot's bus carries a storm, by the family of its protocol (the registry's profile of
/// the robot): CAN frames where a bad one is an unknown id (TITAN, AgileX V2), CAN frames with a
/// checksum (AgileX V1, the SCOUT MINI), or a serial byte stream (XBot).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StormWire {
    UnknownIds,
    CheckedCan,
    Serial,
}

impl StormWire {
    fn of(robot: RobotKind) -> Self {
        // AgileX V1 checks a checksum in every frame; the other CAN protocols count an unknown
        // id; a serial robot's stream parser counts garbage.
        if !robot.is_can() {
            StormWire::Serial
        } else if robot.entry().defaults().protocol() == Some(Protocol::V1) {
            StormWire::CheckedCan
        } else {
            StormWire::UnknownIds
        }
    }

    /// The error counter a storm of `kind` raises.
    fn counter(self, kind: u8, link: &LinkStats) -> u64 {
        match (self, kind) {
            (StormWire::UnknownIds, _) => link.rx_unknown_id,
            (StormWire::Serial, SimKind::GARBAGE) => link.rx_bytes_discarded,
            _ => link.rx_bad_checksum,
        }
    }

    /// The sender's count of what a storm of `kind` injects (`sim truth --injected`).
    fn injected_counter(self, kind: u8) -> &'static str {
        match (self, kind) {
            (StormWire::UnknownIds | StormWire::CheckedCan, SimKind::GARBAGE) => "garbage_frames",
            (StormWire::Serial, SimKind::GARBAGE) => "garbage_bytes",
            _ => "bad_checksums",
        }
    }

    /// CAN garbage comes as bytes, 8 to a frame.
    fn garbage_in_frames(self) -> bool {
        self == StormWire::UnknownIds
    }
}

fn scout_checksum_ok(f: &BusFrame) -> bool {
    let data = f.payload();
    let Some((&checksum, body)) = data.split_last() else {
        return false;
    };
    let sum = body.iter().fold(
        (f.can_id >> 8) as u8 + (f.can_id & 0xFF) as u8 + data.len() as u8,
        |s, b| s.wrapping_add(*b),
    );
    sum == checksum
}

/// Storms of `phases` on `robot_kind`'s bus; `who` names it in the rows ("TITAN's").
fn storms(robot_kind: RobotKind, who: &str, test: &str, phases: &[Storm]) {
    let carrier = StormWire::of(robot_kind);
    let _machine = shared();
    let mut env = Env::new(&format!("storm-{robot_kind}"));
    let n = name(&format!("st{}", &robot_kind.name()[..2]));
    env.chassisd(
        "chassisd",
        &[
            "--robot",
            robot_kind.name(),
            "--name",
            &n,
            "--no-safety-monitor",
        ],
    );
    let mut robot = env.robot(&n, UP);
    let mut teleop = robot.source("teleop").unwrap();
    let go = VelocityRequest::twist(0.5, 0.0);
    let mut wire = Wire::new(&robot);
    let moving = wait_for(UP, || {
        teleop.send(go).unwrap();
        wire.pump();
        state(&mut robot).motion.linear_mps > 0.45
    });
    assert!(moving.is_some(), "no drive\n{}", env.logs());
    let mut results = Vec::new();
    for storm in phases {
        let counter = carrier.injected_counter(storm.kind);
        let before = quiet_moment(&mut robot, &mut teleop, go, || wire.pump());
        let sent_before = sim_injected(&mut robot);
        wire.frames.clear();
        // The quiet moment's silence has up to 100 ms still to run: the storm starts once the
        // chassis talks again (a frame decoded since that moment), so that the whole storm falls
        // on a talking chassis and the robot's speed is held over all of it.
        let talking = wait_for(Duration::from_secs(1), || {
            teleop.send(go).unwrap();
            wire.pump();
            state(&mut robot).link.rx_frames > before.link.rx_frames
        });
        assert!(
            talking.is_some(),
            "the chassis never talked again after the quiet moment\n{}",
            env.logs()
        );
        // Injections every 100 ms (or one bad frame every 1/rate s below 10 a second).
        let interval = Duration::from_secs_f64((1.0 / f64::from(storm.rate)).max(0.1));
        let per = (f64::from(storm.rate) * interval.as_secs_f64()).round() as u32;
        let phase = Duration::from_secs(2);
        let started = Instant::now();
        let mut next = started;
        let mut asked = 0u64;
        let mut min_speed = f32::MAX;
        while started.elapsed() < phase {
            if Instant::now() >= next {
                let answer = robot
                    .sim(
                        SimRequest {
                            kind: storm.kind,
                            // TITAN and V2 garbage comes as bytes, 8 to a frame.
                            value: f64::from(per * if carrier.garbage_in_frames() { 8 } else { 1 }),
                            ..SimRequest::default()
                        },
                        Duration::from_secs(3),
                    )
                    .unwrap();
                assert!(answer.is_ok(), "{}", answer.message());
                asked += u64::from(per);
                // Spaced from the last injection, not on a grid: a late loop never sends a
                // burst of them to catch up.
                next = Instant::now() + interval;
            }
            teleop.send(go).unwrap();
            wire.pump();
            if let Ok(Some(s)) = robot.wait_state(Duration::from_millis(20)) {
                min_speed = min_speed.min(s.motion.linear_mps);
            }
        }
        // The sender's count reaches what was asked once the last corruptions have gone out
        // with the next feedback frames; then the closing silence.
        let settled = wait_for(SETTLE_BOUND + Duration::from_millis(500), || {
            teleop.send(go).unwrap();
            wire.pump();
            let sent = sim_injected(&mut robot);
            sent.count(counter) - sent_before.count(counter) >= asked
        });
        let settle_ms = settled.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
        let after = quiet_moment(&mut robot, &mut teleop, go, || wire.pump());
        // Nothing more may leave after the count was reached (a corruption beyond what was
        // asked would show here).
        let sent = sim_injected(&mut robot);
        let rx: Vec<&BusFrame> = wire
            .frames
            .iter()
            .filter(|f| f.direction == FrameDirection::RX)
            .collect();
        let mut r = StormResult {
            asked,
            injected: sent.count(counter) - sent_before.count(counter),
            injected_bytes: sent.count("garbage_bytes") - sent_before.count("garbage_bytes"),
            settle_ms,
            counted: carrier.counter(storm.kind, &after.link)
                - carrier.counter(storm.kind, &before.link),
            tap_frames: rx.len() as u64,
            decoded: after.link.rx_frames - before.link.rx_frames,
            min_speed,
            ..StormResult::default()
        };
        match carrier {
            StormWire::UnknownIds => {
                r.good_on_tap = rx.iter().filter(|f| f.can_id != 0x7F0).count() as u64;
                r.on_wire = r.tap_frames - r.good_on_tap;
            }
            StormWire::CheckedCan => {
                r.good_on_tap = rx.iter().filter(|f| scout_checksum_ok(f)).count() as u64;
                r.on_wire = r.tap_frames - r.good_on_tap;
                let mut last: HashMap<u32, u8> = HashMap::new();
                for f in &rx {
                    let count = f.payload()[6];
                    if let Some(prev) = last.insert(f.can_id, count) {
                        r.count_gaps += u64::from(count.wrapping_sub(prev).wrapping_sub(1));
                    }
                }
            }
            StormWire::Serial => {
                // The bytes read: whole 75-byte reports that decoded, and the rest. Garbage:
                // the rest is the garbage. Bad checksums: the rest is whole reports.
                let bytes: u64 = rx.iter().map(|f| u64::from(f.len)).sum();
                r.tap_frames = bytes;
                r.good_on_tap = r.decoded;
                let rest = bytes.saturating_sub(75 * r.decoded);
                r.on_wire = if storm.kind == SimKind::GARBAGE {
                    rest
                } else if rest.is_multiple_of(75) {
                    rest / 75
                } else {
                    // Not whole reports: a report was cut, which no count can match.
                    u64::MAX
                };
            }
        }
        eprintln!("{robot_kind} {} {}/s: {r:?}", storm.unit, storm.rate);
        results.push((*storm, r));
    }
    let dropped_at_source = env.proc(0).log_text().contains("dropped a frame");
    let mut figures = Figures::faults();
    for (storm, r) in &results {
        let what = match (carrier, storm.kind) {
            (StormWire::UnknownIds, _) => {
                let v2 = robot_kind.entry().defaults().protocol() == Some(Protocol::V2);
                let protocol = if v2 { " (protocol V2)" } else { "" };
                format!("garbage CAN frames (id 0x7F0) on the {who} bus{protocol}")
            }
            (StormWire::CheckedCan, _) => format!("bad checksums on the {who} CAN frames"),
            (StormWire::Serial, SimKind::GARBAGE) => {
                format!("garbage bytes on the {who} serial line")
            }
            (StormWire::Serial, _) => format!("bad checksums on the {who} serial reports"),
        };
        let bytes_ok = !carrier.garbage_in_frames() || r.injected_bytes == 8 * r.asked;
        let pass =
            r.exact() && bytes_ok && !dropped_at_source && wire.lost == 0 && r.min_speed > 0.45;
        figures.add(fault_figure(
            SUITE,
            test,
            RANK,
            &format!("{what}, {} {}/s", storm.rate, storm.unit),
            &format!(
                "`chassis sim {}` every {} ms for 2 s while teleop drives at 0.5 m/s",
                if storm.kind == SimKind::GARBAGE {
                    "garbage BYTES"
                } else {
                    "bad-checksums FRAMES"
                },
                (1000.0 / f64::from(storm.rate)).max(100.0)
            ),
            "the simulated chassis injected exactly what was asked (its own count); every bad \
             item reached the service, which dropped and counted each one and decoded every \
             good one; the robot kept its speed",
            format!(
                "{} {unit} asked for, {} injected (the sender's count; the last out {:.0} ms \
                 after the storm), {} on the wire, {} counted; good frames lost {} ({} of {} \
                 decoded); lowest speed {:.2} m/s",
                r.asked,
                r.injected,
                r.settle_ms,
                r.on_wire,
                r.counted,
                r.lost(),
                r.decoded,
                r.good_on_tap,
                r.min_speed,
                unit = storm.unit,
            ),
            r.lost() as f64,
            pass,
        ));
    }
    assert!(
        !dropped_at_source,
        "the simulated chassis dropped frames\n{}",
        env.logs()
    );
    assert_eq!(wire.lost, 0, "the tap lost frames");
    for (storm, r) in &results {
        assert!(r.asked > 0, "{storm:?}: nothing asked: {r:?}");
        assert_eq!(r.injected, r.asked, "{storm:?}: the sender's count: {r:?}");
        if carrier.garbage_in_frames() {
            assert_eq!(r.injected_bytes, 8 * r.asked, "{storm:?}: {r:?}");
        }
        assert!(
            r.settle_ms <= SETTLE_BOUND.as_secs_f64() * 1e3,
            "{storm:?}: the last injections left {} ms after the storm: {r:?}",
            r.settle_ms
        );
        assert_eq!(r.on_wire, r.injected, "{storm:?}: on the wire: {r:?}");
        assert_eq!(r.counted, r.injected, "{storm:?}: counted: {r:?}");
        assert_eq!(r.decoded, r.good_on_tap, "{storm:?}: {r:?}");
        assert_eq!(r.count_gaps, 0, "{storm:?}: {r:?}");
        assert!(r.min_speed > 0.45, "{storm:?}: {r:?}");
    }
    figures.finish();
}

#[test]
fn garbage_frame_storms_on_the_titan_bus_are_counted_and_lose_no_good_frame() {
    let frames = |rate| Storm {
        kind: SimKind::GARBAGE,
        // 8 bytes to a frame.
        rate,
        unit: "frames",
    };
    storms(
        RobotKind::Titan,
        "TITAN's",
        "garbage_frame_storms_on_the_titan_bus_are_counted_and_lose_no_good_frame",
        &[frames(10), frames(100), frames(1000)],
    );
}

#[test]
fn garbage_frame_storms_on_a_protocol_v2_bus_are_counted_and_lose_no_good_frame() {
    let frames = |rate| Storm {
        kind: SimKind::GARBAGE,
        rate,
        unit: "frames",
    };
    storms(
        RobotKind::Hunter,
        "HUNTER's",
        "garbage_frame_storms_on_a_protocol_v2_bus_are_counted_and_lose_no_good_frame",
        &[frames(10), frames(100), frames(1000)],
    );
}

#[test]
fn bad_checksum_storms_on_the_scout_mini_bus_are_counted_and_lose_no_good_frame() {
    let bad = |rate| Storm {
        kind: SimKind::BAD_CHECKSUMS,
        rate,
        unit: "frames",
    };
    storms(
        RobotKind::ScoutMini,
        "SCOUT MINI's",
        "bad_checksum_storms_on_the_scout_mini_bus_are_counted_and_lose_no_good_frame",
        &[bad(10), bad(100), bad(250)],
    );
}

#[test]
fn garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report() {
    let garbage = |rate| Storm {
        kind: SimKind::GARBAGE,
        rate,
        unit: "bytes",
    };
    let bad = |rate| Storm {
        kind: SimKind::BAD_CHECKSUMS,
        rate,
        unit: "reports",
    };
    storms(
        RobotKind::Xbot,
        "XBot's",
        "garbage_and_bad_checksum_storms_on_the_xbot_line_are_counted_and_lose_no_good_report",
        &[
            garbage(100),
            garbage(1000),
            garbage(10_000),
            bad(5),
            bad(20),
        ],
    );
}
