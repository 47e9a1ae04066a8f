//! The robot side (`export`): chassisd's services exported onto Zenoh for an operator to mirror.
//!
//! * the main thread reads the state stream, the mux, the robot's description and the frame
//!   tap, and puts them on `chassis/<name>/state` (the newest sample of each read of the bus),
//!   `…/mux`, `…/robot` (when it changes; a queryable on the same key answers a mirror that
//!   connects later), `…/frames` (fixed-layout bytes) and decimated JSON twins
//!   (`…/state/json`, `…/mux/json`);
//! * a thread holds the remote sources' publishers and takes `chassis/<name>/cmd/<source>` from
//!   the network: only for sources chassisd's mux marks [`SourceFlags::REMOTE`] (never a
//!   required one); a request that is not one, or carries a NaN or an infinity, is dropped and
//!   counted ([`chassis_client::payload`]). A request is made on the operator's computer and
//!   stamped there with its `CLOCK_MONOTONIC`; this thread asks the mirror for its clock every
//!   [`CLOCK_PERIOD`] (`chassis/<name>/clock`) and keeps the offset of the fastest recent round
//!   trip ([`PeerClock`]). A request older than `max_age` when it arrives (buffered through an
//!   outage, or its clock not measured yet) is dropped and counted, never obeyed; one that is
//!   taken is re-stamped with the instant it was made, in this computer's clock, so chassisd's
//!   source timeout runs from then, not from its arrival;
//! * a thread answers the queryable `chassis/<name>/control` with chassisd's response.
//!
//! iceoryx2 ports are not `Send`: each thread connects to the robot itself.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, Decimator, MuxStatus, PeerClock,
    Robot, RobotDescription, STATE_BUFFER, Source, SourceFlags, Ticker, VelocityRequest, now_ns,
    termination_requested,
};
use chassis_ipc::StampTrace;
use zenoh::Wait as _;
use zenoh::qos::{CongestionControl, Priority};
use zerocopy::IntoBytes as _;

use crate::convert::{Keys, Wire};
use crate::net::{self, Net};

/// How long a control request waits for chassisd.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);
/// Frames are sent in batches this often.
const FRAMES_PERIOD_NS: u64 = 50_000_000;
/// Frames the tap holds between two batches.
const TAP_BUFFER: usize = 1024;
/// How often blocked threads look at the stop flag.
const POLL: Duration = Duration::from_millis(100);
/// How often the drive thread measures the operator side's clock.
pub const CLOCK_PERIOD: Duration = Duration::from_millis(500);

/// What the robot side needs to know.
#[derive(Debug, Clone)]
pub struct Config {
    pub name: String,
    pub net: Net,
    /// Most binary state samples per second on the network (0: the newest of every read of the
    /// bus).
    pub state_hz: f64,
    /// JSON twins per second.
    pub json_hz: f64,
    /// How long to wait for chassisd at start.
    pub wait: Duration,
    /// Oldest a velocity request may be when it arrives (its stamp against the operator's
    /// measured clock); older ones are dropped.
    pub max_age: Duration,
}

/// The remote sources of a mux decision: configured `remote`, never required.
pub fn remote_sources(mux: &MuxStatus) -> Vec<String> {
    mux.sources()
        .iter()
        .filter(|s| s.has(SourceFlags::REMOTE) && !s.has(SourceFlags::REQUIRED))
        .map(|s| s.name().to_string())
        .collect()
}

fn connect(name: &str, wait: Duration) -> anyhow::Result<Robot> {
    let deadline = chassis_client::deadline(wait);
    let mut retry = Ticker::new(Duration::from_millis(100));
    loop {
        match Robot::connect(name) {
            Ok(robot) => return Ok(robot),
            Err(e) if now_ns() >= deadline || termination_requested() => {
                return Err(e).context("connecting to chassisd");
            }
            Err(_) => retry.wait(),
        }
    }
}

fn first_mux(robot: &mut Robot, wait: Duration) -> anyhow::Result<MuxStatus> {
    let deadline = chassis_client::deadline(wait);
    loop {
        if let Some(mux) = robot.wait_mux(Duration::from_millis(100))? {
            return Ok(mux);
        }
        if now_ns() >= deadline || termination_requested() {
            anyhow::bail!("chassisd published no mux decision within {wait:?}");
        }
    }
}

/// Runs the robot side until SIGINT/SIGTERM or a thread's failure.
pub fn run(config: &Config) -> anyhow::Result<()> {
    let keys = Keys::new(&config.name);
    // The endpoints and certificates are checked before anything else.
    net::config(&config.net, &config.name, &[])?;
    let mut robot = connect(&config.name, config.wait)?;
    let mux = first_mux(&mut robot, config.wait)?;
    let remote = remote_sources(&mux);
    let session = net::open(net::config(&config.net, &config.name, &remote)?)?;
    eprintln!(
        "chassis-zenoh: robot '{}' on {} (remote sources: {})",
        config.name,
        config.net.endpoints.join(", "),
        if remote.is_empty() {
            "none".to_string()
        } else {
            remote.join(", ")
        }
    );
    let _alive = session
        .liveliness()
        .declare_token(&keys.alive)
        .wait()
        .map_err(|e| anyhow::anyhow!("declaring {}: {e}", keys.alive))?;

    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    if !remote.is_empty() {
        let (name, session, keys) = (config.name.clone(), session.clone(), keys.clone());
        let (remote, max_age) = (remote.clone(), config.max_age);
        threads.push(spawn("cmd".into(), &stop, move |stop| {
            drive(&name, &session, &keys, &remote, max_age, stop)
        })?);
    }
    {
        let (name, session, keys) = (config.name.clone(), session.clone(), keys.clone());
        threads.push(spawn("control".into(), &stop, move |stop| {
            control(&name, &session, &keys, stop)
        })?);
    }
    let result = publish(config, &session, &keys, &mut robot, mux, &stop);
    finish(&stop, threads, &session, result)
}

/// Ends a side: [`join`]s its threads, closes the session, and reports as `join` does.
pub fn finish(
    stop: &AtomicBool,
    threads: Vec<std::thread::JoinHandle<anyhow::Result<()>>>,
    session: &zenoh::Session,
    result: anyhow::Result<()>,
) -> anyhow::Result<()> {
    let joined = join(stop, threads, result);
    let _ = session.close().wait();
    joined
}

/// Raises the stop flag, joins `threads`, and reports the loop's own error (`result`) first,
/// then every thread's.
pub fn join(
    stop: &AtomicBool,
    threads: Vec<std::thread::JoinHandle<anyhow::Result<()>>>,
    result: anyhow::Result<()>,
) -> anyhow::Result<()> {
    stop.store(true, Ordering::Relaxed);
    let mut failures = Vec::new();
    for thread in threads {
        match thread.join() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => failures.push(format!("{e:#}")),
            Err(_) => failures.push("a thread panicked".into()),
        }
    }
    result?;
    if !failures.is_empty() {
        anyhow::bail!("{}", failures.join("; "));
    }
    Ok(())
}

/// Starts the thread `name` running `f`, which raises the stop flag when it ends (so that the
/// others end too).
pub fn spawn(
    name: String,
    stop: &Arc<AtomicBool>,
    f: impl FnOnce(&AtomicBool) -> anyhow::Result<()> + Send + 'static,
) -> std::io::Result<std::thread::JoinHandle<anyhow::Result<()>>> {
    let stop = stop.clone();
    std::thread::Builder::new().name(name).spawn(move || {
        let result = f(&stop);
        stop.store(true, Ordering::Relaxed);
        result
    })
}

fn zerr(what: &str) -> impl FnOnce(zenoh::Error) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e}")
}

/// The main thread: state, mux and frames onto the network.
fn publish(
    config: &Config,
    session: &zenoh::Session,
    keys: &Keys,
    robot: &mut Robot,
    first: MuxStatus,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let declare = |key: &str, encoding: zenoh::bytes::Encoding, express: bool| {
        session
            .declare_publisher(key.to_string())
            .encoding(encoding)
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::DataHigh)
            .express(express)
            .wait()
            .map_err(zerr(key))
    };
    let state_pub = declare(&keys.state, Wire::<ChassisState>::new().encoding(), true)?;
    let mux_pub = declare(&keys.mux, Wire::<MuxStatus>::new().encoding(), true)?;
    let frames_pub = declare(&keys.frames, Wire::<BusFrame>::new().encoding(), false)?;
    let json = zenoh::bytes::Encoding::APPLICATION_JSON;
    let state_json_pub = declare(&keys.state_json, json.clone(), false)?;
    let mux_json_pub = declare(&keys.mux_json, json, false)?;

    let states = robot.state_stream(STATE_BUFFER)?;
    let tap = robot.frames(TAP_BUFFER)?;
    let description_pub = declare(
        &keys.description,
        Wire::<RobotDescription>::new().encoding(),
        false,
    )?;
    // The newest description, for the queryable that answers a mirror connecting later.
    let described: Arc<Mutex<Option<RobotDescription>>> = Arc::new(Mutex::new(None));
    let _description_queryable = {
        let described = described.clone();
        let encoding = Wire::<RobotDescription>::new().encoding();
        session
            .declare_queryable(keys.description.clone())
            .callback(move |query| {
                let latest = described.lock().ok().and_then(|d| *d);
                if let Some(d) = latest
                    && let Err(e) = query
                        .reply(query.key_expr().clone(), d.as_bytes())
                        .encoding(encoding.clone())
                        .wait()
                {
                    tracing::warn!("answering a query for the description: {e}");
                }
            })
            .wait()
            .map_err(zerr(&keys.description))?
    };
    let mut state_rate = Decimator::per_second(config.state_hz);
    let mut state_json_rate = Decimator::per_second(config.json_hz);
    let mut mux_json_rate = Decimator::per_second(config.json_hz);
    let mut last_description: Option<(u64, u64)> = None;
    let mut next_frames = now_ns();
    let mut next_check = now_ns();
    let mut batch: Vec<u8> = Vec::new();
    // The bench's split of the state path (`CHASSIS_ZENOH_TRACE`), written as the loop ends.
    let mut trace = StampTrace::<4>::from_env(chassis_ipc::Trace::ZenohExport);
    let mut failed: u64 = 0;
    let mut report = |what: &str, e: zenoh::Error| {
        failed += 1;
        if failed.is_power_of_two() {
            tracing::warn!(failed, "putting {what}: {e}");
        }
    };
    let mut put_mux = |m: &MuxStatus, report: &mut dyn FnMut(&str, zenoh::Error)| {
        if let Err(e) = mux_pub.put(m.as_bytes()).wait() {
            report("mux", e);
        }
        if mux_json_rate.pass(m.stamp_ns)
            && let Ok(text) = serde_json::to_vec(m)
            && let Err(e) = mux_json_pub.put(text).wait()
        {
            report("mux/json", e);
        }
    };
    put_mux(&first, &mut report);
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        // chassisd publishes a sample per frame and wakes its readers once per read of the bus;
        // a put costs tens of µs (the link's write): only the newest sample of each wake-up goes
        // out, so none waits behind the older ones of its read (the state is a latest-value
        // topic; `seq` numbers what was skipped).
        let mut newest = None;
        let mut woke = 0;
        let waited = states.wait(Duration::from_millis(20), |s| {
            if woke == 0 && trace.is_some() {
                woke = now_ns();
            }
            newest = Some(*s);
        });
        match waited {
            Ok(_) => {}
            // SIGTERM interrupts the wait: the end asked for, not a failure.
            Err(_) if termination_requested() => break,
            Err(e) => return Err(e.into()),
        }
        if let Some(s) = newest.as_ref() {
            if state_rate.pass(s.stamp_ns) {
                let begun = trace.as_ref().map_or(0, |_| now_ns());
                if let Err(e) = state_pub.put(s.as_bytes()).wait() {
                    report("state", e);
                }
                if let Some(trace) = trace.as_mut() {
                    trace.push([s.stamp_ns, woke, begun, now_ns()]);
                }
            }
            if state_json_rate.pass(s.stamp_ns)
                && let Ok(text) = serde_json::to_vec(s)
                && let Err(e) = state_json_pub.put(text).wait()
            {
                report("state/json", e);
            }
        }
        robot.poll_mux(|m| put_mux(m, &mut report))?;
        if let Some(d) = robot.latest_description()?
            && last_description != Some((d.seq, d.stamp_ns))
        {
            last_description = Some((d.seq, d.stamp_ns));
            if let Ok(mut latest) = described.lock() {
                *latest = Some(d);
            }
            if let Err(e) = description_pub.put(d.as_bytes()).wait() {
                report("robot", e);
            }
        }
        let now = now_ns();
        if now >= next_check {
            // Opening the service to count its publishers costs file operations: once a second.
            next_check = now + 1_000_000_000;
            if !robot.is_served() {
                anyhow::bail!("chassisd stopped serving '{}'", config.name);
            }
        }
        if now >= next_frames {
            next_frames = now + FRAMES_PERIOD_NS;
            batch.clear();
            tap.drain(|f| batch.extend_from_slice(f.as_bytes()))?;
            if !batch.is_empty()
                && let Err(e) = frames_pub.put(batch.clone()).wait()
            {
                report("frames", e);
            }
        }
    }
    write_trace(trace.as_ref());
    Ok(())
}

/// Writes a trace the bench asked for; a failure is logged (the bridge's work is done).
pub(crate) fn write_trace<const N: usize>(trace: Option<&StampTrace<N>>) {
    if let Some(trace) = trace
        && let Err(e) = trace.write()
    {
        tracing::warn!(error = %e, path = %trace.path().display(), "trace not written");
    }
}

/// Takes velocity requests from the network for the remote sources.
fn drive(
    name: &str,
    session: &zenoh::Session,
    keys: &Keys,
    remote: &[String],
    max_age: Duration,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let max_age_ns = u64::try_from(max_age.as_nanos()).unwrap_or(u64::MAX);
    let mut robot = Robot::connect(name)?;
    let mut sources: HashMap<String, Source> = HashMap::new();
    for source in remote {
        let publisher = robot
            .source(source)
            .with_context(|| format!("taking the remote source '{source}'"))?;
        sources.insert(source.clone(), publisher);
    }
    let subscriber = session
        .declare_subscriber(keys.cmd_any.clone())
        .wait()
        .map_err(zerr(&keys.cmd_any))?;
    let wire = Wire::<VelocityRequest>::new();
    let mut refused: u64 = 0;
    let mut bad: u64 = 0;
    let mut stale: u64 = 0;
    let mut peer = PeerClock::default();
    // Round trips (sent, the mirror's reading, received) from the query callbacks.
    let (clock_tx, clock_rx) = std::sync::mpsc::channel::<(u64, u64, u64)>();
    let mut next_clock = now_ns();
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        let now = now_ns();
        if now >= next_clock {
            next_clock = now + u64::try_from(CLOCK_PERIOD.as_nanos()).unwrap_or(u64::MAX);
            let tx = clock_tx.clone();
            let asked = session
                .get(keys.clock.clone())
                .callback(move |reply| {
                    let received = now_ns();
                    if let Ok(sample) = reply.result()
                        && let Some(peer_ns) = crate::convert::clock_reading(
                            sample.encoding(),
                            &sample.payload().to_bytes(),
                        )
                    {
                        let _ = tx.send((now, peer_ns, received));
                    }
                })
                .timeout(CLOCK_PERIOD)
                .wait();
            if let Err(e) = asked {
                tracing::debug!("asking the operator side's clock: {e}");
            }
        }
        while let Ok((sent, peer_ns, received)) = clock_rx.try_recv() {
            let first = peer.offset().is_none();
            peer.record(sent, peer_ns, received);
            if first && let Some((offset, uncertainty)) = peer.offset() {
                tracing::info!(
                    offset_ns = offset,
                    uncertainty_ns = uncertainty,
                    "measured the operator side's clock"
                );
            }
        }
        let sample = match subscriber.recv_timeout(Duration::from_millis(20)) {
            Ok(Some(sample)) => sample,
            Ok(None) => continue,
            Err(e) => anyhow::bail!("receiving velocity requests: {e}"),
        };
        let arrived = now_ns();
        let key = sample.key_expr().as_str();
        let Some(source) = keys.source_of(key).and_then(|s| sources.get_mut(s)) else {
            refused += 1;
            tracing::warn!(
                key,
                refused,
                "refused a velocity request: not a remote source of this robot"
            );
            eprintln!(
                "chassis-zenoh: refused a velocity request on {key}: not a remote source of robot '{name}' ({refused} refused)"
            );
            continue;
        };
        match wire.decode_request(sample.encoding(), &sample.payload().to_bytes()) {
            Ok(request) => match judge(&peer, request.stamp_ns, arrived, max_age_ns) {
                // Its timeout runs from when it was made, in this computer's clock.
                Ok(made) => source.send(request.with_stamp_ns(made))?,
                Err(why) => {
                    stale += 1;
                    tracing::warn!(key, stale, "dropped a velocity request: {why}");
                    if stale.is_power_of_two() {
                        eprintln!(
                            "chassis-zenoh: dropped a velocity request on {key}: {why} ({stale} dropped as stale)"
                        );
                    }
                }
            },
            // Not the type, cut, or carrying a NaN or an infinity: never passed on as motion.
            Err(e) => {
                bad += 1;
                if bad.is_power_of_two() {
                    tracing::warn!(key, bad, "dropped a velocity request: {e}");
                }
            }
        }
    }
    Ok(())
}

/// Why a request is not obeyed: too old, or made on a clock not measured yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Stale {
    #[error("made {age_ms} ms before it arrived (at most {max_ms} ms)")]
    TooOld { age_ms: u64, max_ms: u64 },
    #[error("the operator side's clock is not measured yet")]
    NoClock,
}

/// The instant, in this computer's clock, a request stamped `stamp_ns` on the operator's was
/// made, if it arrived at `arrived_ns` at most `max_age_ns` after that (the clock's uncertainty
/// counted in its favour); never later than its arrival.
pub fn judge(
    peer: &PeerClock,
    stamp_ns: u64,
    arrived_ns: u64,
    max_age_ns: u64,
) -> Result<u64, Stale> {
    let (Some((made, _)), Some(age)) = (peer.local_ns(stamp_ns), peer.age_ns(stamp_ns, arrived_ns))
    else {
        return Err(Stale::NoClock);
    };
    if age > max_age_ns {
        return Err(Stale::TooOld {
            age_ms: age / 1_000_000,
            max_ms: max_age_ns / 1_000_000,
        });
    }
    Ok(made.min(arrived_ns))
}

/// Answers `chassis/<name>/control` with chassisd's responses.
fn control(
    name: &str,
    session: &zenoh::Session,
    keys: &Keys,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let mut robot = Robot::connect(name)?;
    let queryable = session
        .declare_queryable(keys.control.clone())
        .wait()
        .map_err(zerr(&keys.control))?;
    let requests = Wire::<ControlRequest>::new();
    let responses = Wire::<ControlResponse>::new();
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        let query = match queryable.recv_timeout(POLL) {
            Ok(Some(query)) => query,
            Ok(None) => continue,
            Err(e) => anyhow::bail!("receiving control requests: {e}"),
        };
        let request = match (query.payload(), query.encoding()) {
            (Some(payload), Some(encoding)) => requests
                .decode(encoding, &payload.to_bytes())
                .map_err(|e| e.to_string()),
            _ => Err("a control request carries a ControlRequest".to_string()),
        };
        let answer =
            request.and_then(|r| robot.control(r, ANSWER_TIMEOUT).map_err(|e| e.to_string()));
        let sent = match answer {
            Ok(response) => query
                .reply(query.key_expr().clone(), response.as_bytes())
                .encoding(responses.encoding())
                .wait(),
            Err(message) => {
                tracing::warn!("control request failed: {message}");
                query.reply_err(message).wait()
            }
        };
        if let Err(e) = sent {
            tracing::warn!("answering a control request: {e}");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_older_than_the_bound_or_on_an_unmeasured_clock_is_stale() {
        let ms = 1_000_000u64;
        let mut peer = PeerClock::default();
        assert_eq!(judge(&peer, 5, 10, 250 * ms), Err(Stale::NoClock));
        // The operator's clock is 100 s ahead; round trips of 4 ms.
        peer.record(1_000 * ms, 101_002 * ms, 1_004 * ms);
        // Made at 2.000 s here, arriving 50 ms later: taken, stamped when it was made.
        assert_eq!(
            judge(&peer, 102_000 * ms, 2_050 * ms, 250 * ms),
            Ok(2_000 * ms)
        );
        // Buffered through an outage: arriving 1.2 s later, dropped.
        assert_eq!(
            judge(&peer, 102_000 * ms, 3_200 * ms, 250 * ms),
            Err(Stale::TooOld {
                age_ms: 1_198,
                max_ms: 250
            })
        );
        // At the bound, counting the 2 ms of doubt in its favour: taken.
        assert!(judge(&peer, 102_000 * ms, 2_252 * ms, 250 * ms).is_ok());
        assert!(judge(&peer, 102_000 * ms, 2_253 * ms, 250 * ms).is_err());
        // Stamped in the future: taken, but never stamped later than its arrival.
        assert_eq!(
            judge(&peer, 103_000 * ms, 2_050 * ms, 250 * ms),
            Ok(2_050 * ms)
        );
    }

    #[test]
    fn only_remote_sources_that_are_not_required_are_taken() {
        let mut mux = MuxStatus {
            source_count: 3,
            ..MuxStatus::default()
        };
        mux.sources[0].set_name("safety");
        mux.sources[0].flags = SourceFlags::REQUIRED | SourceFlags::REMOTE;
        mux.sources[1].set_name("teleop");
        mux.sources[2].set_name("remote");
        mux.sources[2].flags = SourceFlags::REMOTE;
        assert_eq!(remote_sources(&mux), vec!["remote".to_string()]);
    }
}
