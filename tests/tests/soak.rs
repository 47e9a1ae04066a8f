//! The soak (issue "Proof under faults", item 4): a simulated TITAN on a bus loaded to its full
//! 500 kbit/s for `CHASSIS_SOAK_MINUTES` (default 10), with every client attached — the safety
//! monitor (required), the planner driving figure-eights, `chassis record` to MCAP, a frame-tap
//! reader and a state reader in this test, and `chassis status` connecting and leaving every
//! sample period. Ignored by `cargo test`; `scripts/soak [--realtime PRIO] [MINUTES]` runs it in
//! release mode (with `CHASSIS_SOAK_REALTIME`, chassisd in real-time mode) and adds its figures
//! to docs/RELIABILITY.md.
//!
//! What "zero gaps" is measured on:
//! * frames: `BusFrame::seq` counts every frame the service read or wrote. A reader that drains
//!   the tap from its own thread (this test's, and `chassis record`'s, 2048 frames deep each)
//!   must see every number — a gap is a frame lost between the service and its readers;
//! * state: `ChassisState::seq` counts every sample the service published. This test's state
//!   reader drains a state stream (`Robot::state_stream`, `STATE_BUFFER` = 256 samples deep) from
//!   its own thread and hands every sample to a gap counter: it must see every number — a gap is
//!   a sample lost between the service and its reader. `chassis record` records every sample
//!   from a stream of its own and warns of any it lost: it must lose none either. The service's
//!   own failures to publish show in its log ("cannot publish state") and must not happen. A
//!   `Robot`'s own state reading is latest-value (it keeps the newest samples, and `chassis echo
//!   state` prints the newest per wake-up by design): no gap counter.
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use chassis_tests::faults::{HEARTBEAT_PERIOD, HeartbeatCheck, slot_lateness};
use chassis_tests::*;
use nix::sys::signal::Signal;

const UP: Duration = Duration::from_secs(10);

/// What the reader threads saw.
#[derive(Debug, Default)]
struct Seen {
    frames: u64,
    frame_gaps: u64,
    frames_lost: u64,
    /// TX 0x111 stamps, ns.
    heartbeats: Vec<u64>,
    states: u64,
    state_gaps: u64,
    states_lost: u64,
    /// Longest time without a state sample, ms.
    state_silence_ms: f64,
}

/// One resource sample of a process.
#[derive(Debug, Clone, Copy)]
struct Sample {
    at_s: f64,
    rss_kib: u64,
    fds: usize,
}

/// One row of the soak's table.
fn figure(
    test: &str,
    fault: &str,
    injection: &str,
    behaviour: &str,
    text: String,
    value: f64,
    pass: bool,
) -> Figure {
    Figure {
        rank: 900,
        fault: fault.into(),
        injection: injection.into(),
        behaviour: behaviour.into(),
        figure: text,
        value,
        pass,
        suite: "soak".into(),
        test: test.into(),
    }
}

#[test]
#[ignore = "a 10-minute soak: scripts/soak [MINUTES] runs it"]
fn a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth() {
    let test = "a_titan_on_a_full_bus_with_every_client_runs_for_minutes_without_gaps_or_growth";
    let minutes: f64 = std::env::var("CHASSIS_SOAK_MINUTES")
        .ok()
        .and_then(|m| m.parse().ok())
        .unwrap_or(10.0);
    let duration = Duration::from_secs_f64(minutes * 60.0);
    // Resources are compared from the end of the warm-up (a tenth of the run, at most a minute).
    let warm_up = (duration / 10).min(Duration::from_secs(60));
    let period = Duration::from_secs(10).min(duration / 6);
    let mut env = Env::new("soak");
    let n = format!("soak{}", std::process::id() % 100_000);
    // `scripts/soak --realtime PRIO`: chassisd's loop at SCHED_FIFO PRIO.
    let realtime = std::env::var("CHASSIS_SOAK_REALTIME")
        .ok()
        .filter(|p| !p.is_empty());
    let mut args = vec!["--robot", "titan", "--name", &n];
    if let Some(priority) = &realtime {
        args.extend(["--realtime", priority.as_str()]);
    }
    let service = env.chassisd("chassisd", &args);
    let mut robot = env.robot(&n, UP);
    let safety = env.spawn("safety", "chassis-safety", &["--name", &n]);
    let driving = wait_for(UP, || {
        mux(&mut robot)
            .sources()
            .iter()
            .any(|s| s.name() == "safety" && s.has(SourceFlags::FRESH))
    });
    assert!(driving.is_some(), "no safety monitor\n{}", env.logs());

    // Load the bus to its capacity: 500 kbit/s of 8-byte standard frames (111 bits each), less
    // the feedback the chassis sends anyway.
    let before = state(&mut robot);
    let t0 = now_ns();
    pause(Duration::from_secs(1));
    let after = state(&mut robot);
    let normal =
        (after.link.rx_frames - before.link.rx_frames) as f64 / ((now_ns() - t0) as f64 / 1e9);
    let capacity = 500_000.0 / 111.0;
    let flood = (capacity - normal).max(0.0).round();
    let answer = robot
        .sim(chassis_client::flood_request(flood), Duration::from_secs(3))
        .unwrap();
    assert!(answer.is_ok(), "{}", answer.message());
    let planner = env.spawn(
        "planner",
        "chassis-planner",
        &["--name", &n, "--shape", "figure-eight", "--repeat"],
    );
    let mcap = env.dir.join("soak.mcap");
    let recorder = env.spawn(
        "record",
        "chassis",
        &["record", mcap.to_str().unwrap(), "--name", &n],
    );

    // The readers, each on its own thread with its own connection.
    let stop = Arc::new(AtomicBool::new(false));
    let seen = Arc::new(Mutex::new(Seen::default()));
    let tap_reader = {
        let (stop, seen, prefix, n) = (stop.clone(), seen.clone(), env.prefix.clone(), n.clone());
        std::thread::spawn(move || {
            let robot = Robot::connect_with_prefix(&n, Some(&prefix)).unwrap();
            let tap = robot.frames(2048).unwrap();
            let mut last = 0u64;
            while !stop.load(Ordering::Relaxed) {
                let mut batch = Seen::default();
                tap.wait(Duration::from_millis(100), |f| {
                    batch.frames += 1;
                    if last != 0 && f.seq != last + 1 {
                        batch.frame_gaps += 1;
                        batch.frames_lost += f.seq.saturating_sub(last + 1);
                    }
                    last = f.seq;
                    if f.direction == FrameDirection::TX && f.can_id == 0x111 {
                        batch.heartbeats.push(f.stamp_ns);
                    }
                })
                .unwrap();
                let mut shared = seen.lock().unwrap();
                shared.frames += batch.frames;
                shared.frame_gaps += batch.frame_gaps;
                shared.frames_lost += batch.frames_lost;
                shared.heartbeats.extend(batch.heartbeats);
            }
        })
    };
    let (ready_out, ready) = std::sync::mpsc::channel();
    let state_reader = {
        let (stop, seen, prefix, n) = (stop.clone(), seen.clone(), env.prefix.clone(), n.clone());
        std::thread::spawn(move || {
            let robot = Robot::connect_with_prefix(&n, Some(&prefix)).unwrap();
            let stream = robot.state_stream(STATE_BUFFER).unwrap();
            assert_eq!(stream.buffer(), STATE_BUFFER);
            ready_out.send(()).unwrap();
            let mut last: Option<(u64, u64)> = None;
            while !stop.load(Ordering::Relaxed) {
                let mut batch = Seen::default();
                stream
                    .wait(Duration::from_millis(100), |s| {
                        batch.states += 1;
                        if let Some((seq, stamp)) = last {
                            if s.seq != seq + 1 {
                                batch.state_gaps += 1;
                                batch.states_lost += s.seq.saturating_sub(seq + 1);
                            }
                            let silence = s.stamp_ns.saturating_sub(stamp) as f64 / 1e6;
                            batch.state_silence_ms = batch.state_silence_ms.max(silence);
                        }
                        last = Some((s.seq, s.stamp_ns));
                    })
                    .unwrap();
                let mut shared = seen.lock().unwrap();
                shared.states += batch.states;
                shared.state_gaps += batch.state_gaps;
                shared.states_lost += batch.states_lost;
                shared.state_silence_ms = shared.state_silence_ms.max(batch.state_silence_ms);
            }
        })
    };

    // The state reader receives every sample from here on: it must count all those published.
    ready.recv_timeout(UP).unwrap();

    // The run: resources sampled every period, a short-lived client each time.
    let pid = env.proc(service).pid().as_raw().unsigned_abs();
    let started = Instant::now();
    // The heartbeat is held against this window: one 0x111 a period from here to the end.
    let run_start_ns = now_ns();
    let first_state = state(&mut robot);
    let mut samples: Vec<Sample> = Vec::new();
    let mut not_driving = 0u32;
    let mut mux_samples = 0u32;
    let mut status_failures = 0u32;
    while started.elapsed() < duration {
        let next = Instant::now() + period;
        samples.push(Sample {
            at_s: started.elapsed().as_secs_f64(),
            rss_kib: rss_kib(pid).unwrap_or(0),
            fds: open_fds(pid).unwrap_or(0),
        });
        if !env.chassis(&["status", "--name", &n]).status.success() {
            status_failures += 1;
        }
        while Instant::now() < next && started.elapsed() < duration {
            if let Ok(Some(m)) = robot.wait_mux(Duration::from_millis(200)) {
                mux_samples += 1;
                if m.zero_reason != ZeroReason::NONE {
                    not_driving += 1;
                }
            }
        }
        let s = samples.last().unwrap();
        eprintln!(
            "{:>6.0} s: chassisd {} KiB, {} fds",
            s.at_s, s.rss_kib, s.fds
        );
    }
    let elapsed = started.elapsed().as_secs_f64();
    let run_end_ns = now_ns();
    let last_state = state(&mut robot);
    samples.push(Sample {
        at_s: elapsed,
        rss_kib: rss_kib(pid).unwrap_or(0),
        fds: open_fds(pid).unwrap_or(0),
    });

    // The end: the recorder's own account, then the readers.
    env.proc(recorder).signal(Signal::SIGINT);
    let recorder_code = env.proc(recorder).wait_exit(Duration::from_secs(30));
    let recorder_log = env.proc(recorder).log_text();
    let recorder_clean =
        recorder_code == Some(0) && recorder_log.contains("no frame lost (0 sequence gaps)");
    // It records every state sample too, and warns of any it lost.
    let recorder_states_clean =
        recorder_code == Some(0) && !recorder_log.contains("state samples lost");
    let recorded = recorder_log
        .lines()
        .find(|l| l.starts_with("recorded"))
        .unwrap_or("")
        .to_string();
    let mcap_mib = std::fs::metadata(&mcap).map_or(0.0, |m| m.len() as f64 / (1024.0 * 1024.0));
    stop.store(true, Ordering::Relaxed);
    tap_reader.join().unwrap();
    state_reader.join().unwrap();
    let seen = std::mem::take(&mut *seen.lock().unwrap());
    let monitor = robot
        .subscriber::<SafetyStatus>(SafetyStatus::SERVICE)
        .unwrap()
        .and_then(|mut sub| sub.wait(Duration::from_secs(1)).unwrap());
    let stale_triggers = monitor.map_or(u32::MAX, |m| m.trigger_count(SafetyRule::STALE));
    let log = env.proc(service).log_text();
    let publish_failures = log.matches("cannot publish").count();
    let sim_drops = log.matches("dropped a frame").count();
    assert!(
        env.proc(planner).is_running(),
        "the planner died\n{}",
        env.logs()
    );
    assert!(
        env.proc(safety).is_running(),
        "the monitor died\n{}",
        env.logs()
    );

    // The figures.
    let bus_rate = (last_state.link.rx_frames - first_state.link.rx_frames) as f64
        / ((last_state.stamp_ns - first_state.stamp_ns) as f64 / 1e9);
    let load = bus_rate / capacity * 100.0;
    let base = samples
        .iter()
        .find(|s| s.at_s >= warm_up.as_secs_f64())
        .copied()
        .unwrap_or(samples[0]);
    let end = *samples.last().unwrap();
    let rss_growth = end.rss_kib as i64 - base.rss_kib as i64;
    let rss_max = samples.iter().map(|s| s.rss_kib).max().unwrap_or(0);
    let fd_growth = end.fds as i64 - base.fds as i64;
    let fd_max = samples.iter().map(|s| s.fds).max().unwrap_or(0);
    let mut heartbeats = seen.heartbeats.clone();
    heartbeats.sort_unstable();
    let late = slot_lateness(&heartbeats, run_start_ns, run_end_ns, HEARTBEAT_PERIOD);
    let lateness = Spread::of(&late);
    let gaps = Spread::of_gaps(&heartbeats);
    let beat = HeartbeatCheck::of(&heartbeats, run_start_ns, run_end_ns, HEARTBEAT_PERIOD);
    let within =
        late.iter().filter(|l| **l <= 2.0).count() as f64 / late.len().max(1) as f64 * 100.0;
    let minutes_text = format!("{:.1} min", elapsed / 60.0);
    let injection = format!(
        "{minutes_text} on the simulated TITAN, the bus flooded to {load:.0} % of 500 kbit/s \
         ({bus_rate:.0} frames/s received), chassis-safety, chassis-planner (figure-eights), \
         chassis record, a tap reader, a state reader, `chassis status` every {} s",
        period.as_secs()
    );
    eprintln!(
        "soak: {elapsed:.0} s, bus {bus_rate:.0} frames/s ({load:.0} %), {seen:?} (heartbeats \
         omitted), recorder: {recorded}, {mcap_mib:.1} MiB; rss {base:?} → {end:?} (max \
         {rss_max}); lateness {lateness:?}; gaps {gaps:?}; stale triggers {stale_triggers}; \
         not driving {not_driving}/{mux_samples}; status failures {status_failures}",
        seen = (
            seen.frames,
            seen.frame_gaps,
            seen.frames_lost,
            seen.states,
            seen.state_gaps,
            seen.states_lost,
            seen.state_silence_ms
        )
    );

    let mut figures = Figures::soak();
    let frames_ok = seen.frames_lost == 0 && recorder_clean && sim_drops == 0;
    figures.add(figure(
        test,
        "frames: sequence gaps",
        &injection,
        "every frame read or written reached both tap readers in sequence",
        format!(
            "{} frames read by the test's tap reader, {} lost; chassis record: {}; {mcap_mib:.0} \
             MiB of MCAP",
            seen.frames, seen.frames_lost, recorded
        ),
        seen.frames_lost as f64,
        frames_ok,
    ));
    // The service numbers every sample it publishes; a failed publication is logged.
    let published = last_state.seq - first_state.seq;
    let states_ok = publish_failures == 0
        && recorder_states_clean
        && seen.state_gaps == 0
        && seen.states_lost == 0
        && seen.states >= published
        && seen.state_silence_ms < 100.0;
    figures.add(figure(
        test,
        "state: sequence gaps",
        &injection,
        &format!(
            "every state sample numbered was published (a sample per frame that changes the \
             state) and reached both state readers in sequence: their streams buffer \
             {STATE_BUFFER} samples, the bursts of the moderated bus included"
        ),
        format!(
            "{published} samples published ({:.0}/s), {publish_failures} failed publications; \
             the state reader thread received {}, gaps {} ({} lost); chassis record: {}; \
             longest wait for a sample {:.1} ms",
            published as f64 / elapsed,
            seen.states,
            seen.state_gaps,
            seen.states_lost,
            if recorder_states_clean {
                "every state recorded, 0 lost"
            } else {
                "state samples lost (see its log)"
            },
            seen.state_silence_ms
        ),
        seen.state_gaps as f64,
        states_ok,
    ));
    let memory_ok = rss_growth <= 1024;
    figures.add(figure(
        test,
        "resident memory of chassisd",
        &injection,
        "flat after the warm-up",
        format!(
            "{} KiB at {:.0} s, {} KiB at the end ({rss_growth:+} KiB); peak {rss_max} KiB",
            base.rss_kib, base.at_s, end.rss_kib
        ),
        rss_growth as f64,
        memory_ok,
    ));
    let fds_ok = fd_growth <= 0;
    figures.add(figure(
        test,
        "open file descriptors of chassisd",
        &injection,
        &format!(
            "constant, with a client connecting and leaving every {} s",
            period.as_secs()
        ),
        format!(
            "{} at {:.0} s, {} at the end ({fd_growth:+}); most {fd_max}",
            base.fds, base.at_s, end.fds
        ),
        fd_growth as f64,
        fds_ok,
    ));
    figures.add(figure(
        test,
        "heartbeat (0x111) jitter",
        &injection,
        &format!(
            "the 20 ms grid held under the full bus to the end of the run, command changes from \
             the planner in between: every slot served (at most {} per mille a period late), \
             no gap of two periods, the last heartbeat within two periods of the end",
            HeartbeatCheck::TOLERANCE_PER_MILLE
        ),
        format!(
            "{} of {} slots served ({} 0x111 frames); lateness behind the grid p50 {:.2} ms, \
             p99 {:.2} ms, worst {:.2} ms ({within:.2} % within 2 ms); longest gap {:.2} ms, \
             the last heartbeat {:.2} ms before the end (bound {:.0} ms); 0x111 intervals \
             {:.2}-{:.2} ms",
            beat.served,
            beat.expected,
            beat.frames,
            lateness.p50_ms,
            lateness.p99_ms,
            lateness.max_ms,
            beat.longest_gap_ms,
            beat.gap_to_end_ms,
            beat.gap_bound_ms,
            gaps.min_ms,
            gaps.max_ms
        ),
        lateness.max_ms,
        beat.pass(),
    ));
    let guarded = stale_triggers == 0 && not_driving == 0;
    figures.add(figure(
        test,
        "safety and drive",
        &injection,
        "the monitor never saw a stale state and the planner drove the whole time",
        format!(
            "stale-state triggers {stale_triggers}; mux samples without a winner \
             {not_driving}/{mux_samples}; `chassis status` failures {status_failures}"
        ),
        f64::from(stale_triggers),
        guarded && status_failures == 0,
    ));
    assert!(
        frames_ok,
        "frames lost: {} / recorder: {recorded}",
        seen.frames_lost
    );
    assert!(
        states_ok,
        "publish failures {publish_failures}; the state reader received {} of {published}, lost \
         {} in {} gaps; longest wait for a state {:.1} ms; recorder: {recorded}",
        seen.states, seen.states_lost, seen.state_gaps, seen.state_silence_ms
    );
    assert!(memory_ok, "resident memory grew by {rss_growth} KiB");
    assert!(fds_ok, "open file descriptors grew by {fd_growth}");
    assert!(beat.pass(), "the heartbeat: {beat:?}; gaps {gaps:?}");
    assert!(
        guarded,
        "stale triggers {stale_triggers}, not driving {not_driving}"
    );
    assert_eq!(status_failures, 0);
    figures.finish();
}
