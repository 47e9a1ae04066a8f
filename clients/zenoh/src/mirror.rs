//! The operator side (`--mirror`): the robot's services recreated in this computer's iceoryx2,
//! with the contract's limits, so that the unchanged local tools — `chassis top`,
//! `chassis-teleop --source remote`, `chassis echo`, Python clients — work here.
//!
//! * the main thread creates `state`, `mux`, `robot` and `frames` and publishes what arrives
//!   from the robot (the Zenoh callbacks hand the samples over a channel: iceoryx2 ports stay on
//!   the thread that made them). The robot's description is asked for when the robot side
//!   becomes reachable (at start and after every outage) and taken whenever it changes, so a
//!   client here reads it as it would beside chassisd (`Robot::description`, Python's
//!   `Robot.wait_description`);
//! * a thread per remote source (learned from the robot's mux) creates `cmd/<source>` and puts
//!   every request on `chassis/<name>/cmd/<source>`;
//! * a thread serves `control`, asking the robot's queryable for each request. An `estop`
//!   LOCK_ENGAGE the robot does not answer stays asked: the thread delivers it again when the
//!   robot is heard again, until chassisd answers, and the mux published here shows it pending
//!   meanwhile ([`crate::estop`]);
//! * a queryable `chassis/<name>/clock` answers the robot side's clock queries with this
//!   computer's `CLOCK_MONOTONIC`: the robot side measures the offset and delay from them and
//!   judges each request's age by its stamp (made here by the client that sent it).
//!
//! Stamps are the robot's `CLOCK_MONOTONIC`: ages computed from them here are only meaningful
//! when both sides share a clock (two namespaces of one machine).

use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::Context as _;
use chassis_client::{
    BusFrame, ChassisState, ControlRequest, ControlResponse, ControlStatus, MuxStatus,
    RobotDescription, ServiceKind, VelocityRequest, now_ns, service_name, termination_requested,
    wait_listener,
};
use chassis_ipc::{CMD, CONTROL, DESCRIPTION, FRAMES, MUX, STATE, StampTrace, Writer};
use iceoryx2::port::update_connections::UpdateConnections as _;
use iceoryx2::prelude::*;
use zenoh::Wait as _;
use zenoh::handlers::FifoChannelHandler;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Reply;
use zenoh::sample::{Sample, SampleKind};
use zerocopy::IntoBytes as _;

use crate::convert::{Keys, Wire};
use crate::estop::{self, Asked, Keeper};
use crate::export::{remote_sources, spawn};
use crate::link_watch::{LOST_AFTER, LinkWatch, Lost};
use crate::net::{self, Net};

/// How long a control request waits for the robot's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(3);
/// How often blocked threads look at the stop flag.
const POLL: Duration = Duration::from_millis(100);
/// How often the control thread looks for news of its robot while an e-stop is pending.
const PENDING_POLL: Duration = Duration::from_millis(20);

/// What the operator side needs to know.
#[derive(Debug, Clone)]
pub struct Config {
    pub name: String,
    pub net: Net,
}

enum Incoming {
    /// A state, and when the subscriber's callback had it.
    State(Sample, u64),
    Mux(Sample),
    Frames(Sample),
    Description(Sample),
    Alive(bool),
    /// The control thread keeps an e-stop pending (`true`) or no longer (`false`).
    EstopPending(bool),
}

fn node(name: &str, role: &str) -> anyhow::Result<Node<ipc::Service>> {
    Ok(chassis_ipc::node(
        Some(&format!("chassis-zenoh/{name}/{role}")),
        &chassis_ipc::config(None)?,
        SignalHandlingMode::Disabled,
    )?)
}

fn zerr(what: &str) -> impl FnOnce(zenoh::Error) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e}")
}

/// Runs the operator side until SIGINT/SIGTERM or a thread's failure.
pub fn run(config: &Config) -> anyhow::Result<()> {
    let session = net::open(net::config(&config.net, &config.name, &[])?)?;
    eprintln!(
        "chassis-zenoh: mirroring robot '{}' from {}",
        config.name,
        config.net.endpoints.join(", ")
    );
    let stop = Arc::new(AtomicBool::new(false));
    let result = serve(&config.name, &session, &stop);
    let _ = session.close().wait();
    result
}

/// Mirrors the robot `name` over `session` into this computer's iceoryx2 until SIGINT/SIGTERM,
/// `stop`, or a thread's failure (which raises `stop`). The session stays open: a fleet's
/// mirrors share one.
pub fn serve(name: &str, session: &zenoh::Session, stop: &Arc<AtomicBool>) -> anyhow::Result<()> {
    let keys = Keys::new(name);
    let node = node(name, "mirror")?;
    let state_name = service_name(name, ServiceKind::State);
    let state = match STATE.create(&node, &state_name)?.publisher() {
        Ok(writer) => writer,
        Err(chassis_ipc::IpcError::Taken { .. }) => anyhow::bail!(
            "robot '{}' is already served on this computer (chassisd or another mirror holds {state_name}); \
             give the mirror its own CHASSIS_IPC_PREFIX or stop the other",
            name
        ),
        Err(e) => return Err(e.into()),
    };
    let mux = MUX
        .create(&node, &service_name(name, ServiceKind::Mux))?
        .publisher()?;
    let frames = FRAMES
        .create(&node, &service_name(name, ServiceKind::Frames))?
        .publisher()?;
    let description = DESCRIPTION
        .create(&node, &service_name(name, ServiceKind::Description))?
        .publisher()?;

    let (tx, rx) = mpsc::channel::<Incoming>();
    let subscribe = |key: &str, wrap: fn(Sample, u64) -> Incoming| {
        let tx = tx.clone();
        session
            .declare_subscriber(key.to_string())
            .callback(move |sample| {
                let _ = tx.send(wrap(sample, now_ns()));
            })
            .wait()
            .map_err(zerr(key))
    };
    let _state_sub = subscribe(&keys.state, Incoming::State)?;
    let _mux_sub = subscribe(&keys.mux, |s, _| Incoming::Mux(s))?;
    let _frames_sub = subscribe(&keys.frames, |s, _| Incoming::Frames(s))?;
    let _description_sub = subscribe(&keys.description, |s, _| Incoming::Description(s))?;
    // The bench's split of the state path (`CHASSIS_ZENOH_TRACE`; one robot a process), written
    // as the loop ends.
    let mut trace = StampTrace::<4>::from_env(chassis_ipc::Trace::ZenohMirror);
    let ask_tx = tx.clone();
    let ask_description = |session: &zenoh::Session| {
        let tx = ask_tx.clone();
        let asked = session
            .get(keys.description.clone())
            .callback(move |reply| {
                if let Ok(sample) = reply.into_result() {
                    let _ = tx.send(Incoming::Description(sample));
                }
            })
            .timeout(ANSWER_TIMEOUT)
            .wait();
        if let Err(e) = asked {
            tracing::warn!("asking the robot for its description: {e}");
        }
    };
    let alive_tx = tx.clone();
    let _clock = session
        .declare_queryable(keys.clock.clone())
        .callback(|query| {
            let now = now_ns();
            if let Err(e) = query
                .reply(query.key_expr().clone(), now.to_le_bytes().to_vec())
                .encoding(crate::convert::clock_encoding())
                .wait()
            {
                tracing::debug!("answering a clock query: {e}");
            }
        })
        .wait()
        .map_err(zerr(&keys.clock))?;
    let _alive_sub = session
        .liveliness()
        .declare_subscriber(&keys.alive)
        .history(true)
        .callback(move |sample| {
            let _ = alive_tx.send(Incoming::Alive(sample.kind() == SampleKind::Put));
        })
        .wait()
        .map_err(zerr(&keys.alive))?;
    // Counts each time the robot is heard again after a silence (its state after a loss, its
    // liveliness token back): the control thread delivers a pending e-stop then.
    let heard_again = Arc::new(AtomicU64::new(0));
    let mut threads = Vec::new();
    {
        let link = ControlLink {
            heard_again: heard_again.clone(),
            pending: tx.clone(),
        };
        let (name, session, keys) = (name.to_string(), session.clone(), keys.clone());
        threads.push(spawn("control".into(), stop, move |stop| {
            serve_control(&name, &session, &keys, &link, stop)
        })?);
    }
    drop(tx);

    let mut sources_started: HashSet<String> = HashSet::new();
    let states = Wire::<ChassisState>::new();
    let muxes = Wire::<MuxStatus>::new();
    let bus = Wire::<BusFrame>::new();
    let descriptions = Wire::<RobotDescription>::new();
    let mut described: Option<(u64, u64)> = None;
    let mut next_connections = now_ns();
    let mut dropped: u64 = 0;
    let mut drop_sample = |what: &str, e: &dyn std::fmt::Display| -> anyhow::Result<()> {
        dropped += 1;
        if dropped.is_power_of_two() {
            tracing::warn!(dropped, "dropped a {what} sample from the robot: {e}");
            eprintln!(
                "chassis-zenoh: dropped a {what} sample from the robot: {e} ({dropped} dropped)"
            );
        }
        Ok(())
    };
    let mut link = LinkWatch::new(LOST_AFTER);
    // The robot's newest mux as it sent it, and whether an e-stop is pending here: what the
    // mux published here is made of.
    let mut last_mux: Option<MuxStatus> = None;
    let mut estop_pending = false;
    let mut result = Ok(());
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        // The description is kept for late joiners: a reader that connects here gets it once
        // the publisher has seen it.
        if now_ns() >= next_connections {
            next_connections = now_ns() + 100_000_000;
            if let Err(e) = description.publisher.update_connections() {
                tracing::debug!("connecting late readers of the description: {e:?}");
            }
            // And of the robot's last decision, which a lost robot does not renew.
            if let Err(e) = mux.publisher.update_connections() {
                tracing::debug!("connecting late readers of the mux: {e:?}");
            }
        }
        let incoming = match rx.recv_timeout(POLL) {
            Ok(incoming) => incoming,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                // Silence: the last state again, marked lost, once the loss limit is passed.
                if let Some(lost) = link.poll(now_ns()) {
                    report_lost(name, &lost);
                    if let Err(e) = send(&state, lost.state) {
                        result = Err(e);
                        break;
                    }
                }
                continue;
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        };
        if let Some(lost) = link.poll(now_ns()) {
            report_lost(name, &lost);
            if let Err(e) = send(&state, lost.state) {
                result = Err(e);
                break;
            }
        }
        let sent = match incoming {
            Incoming::State(sample, received) => {
                let taken = trace.as_ref().map_or(0, |_| now_ns());
                match states.decode(sample.encoding(), &sample.payload().to_bytes()) {
                    Ok(s) => {
                        if link.heard(now_ns(), &s) {
                            eprintln!("chassis-zenoh: robot '{name}' heard again");
                            heard_again.fetch_add(1, Ordering::Relaxed);
                        }
                        if let Some(trace) = trace.as_mut() {
                            trace.push([s.stamp_ns, received, taken, now_ns()]);
                        }
                        send(&state, s)
                    }
                    Err(e) => drop_sample("state", &e),
                }
            }
            Incoming::Mux(sample) => {
                match muxes.decode(sample.encoding(), &sample.payload().to_bytes()) {
                    Ok(m) => {
                        for source in remote_sources(&m) {
                            if sources_started.insert(source.clone()) {
                                let (name, session, keys) =
                                    (name.to_string(), session.clone(), keys.clone());
                                threads.push(spawn(format!("cmd/{source}"), stop, move |stop| {
                                    forward(&name, &session, &keys, &source, stop)
                                })?);
                            }
                        }
                        last_mux = Some(m);
                        send(&mux, estop::marked(m, estop_pending))
                    }
                    Err(e) => drop_sample("mux", &e),
                }
            }
            Incoming::Frames(sample) => {
                match bus.decode_all(sample.encoding(), &sample.payload().to_bytes()) {
                    Ok(batch) => batch.into_iter().try_for_each(|f| send(&frames, f)),
                    Err(e) => drop_sample("frames", &e),
                }
            }
            Incoming::Description(sample) => {
                match descriptions.decode(sample.encoding(), &sample.payload().to_bytes()) {
                    Ok(d) if described != Some((d.seq, d.stamp_ns)) => {
                        described = Some((d.seq, d.stamp_ns));
                        eprintln!(
                            "chassis-zenoh: robot '{}' is {} ({}, {} sensors, {} joints)",
                            name,
                            d.display_name(),
                            d.model(),
                            d.sensors().len(),
                            d.joints().len()
                        );
                        send(&description, d)
                    }
                    Ok(_) => Ok(()),
                    Err(e) => drop_sample("robot", &e),
                }
            }
            Incoming::Alive(alive) => {
                if alive {
                    heard_again.fetch_add(1, Ordering::Relaxed);
                    ask_description(session);
                }
                eprintln!(
                    "chassis-zenoh: robot '{}' {}",
                    name,
                    if alive {
                        "reachable"
                    } else {
                        "lost (its remote sources time out on the robot)"
                    }
                );
                match link.alive(now_ns(), alive) {
                    Some(lost) => {
                        report_lost(name, &lost);
                        send(&state, lost.state)
                    }
                    None => Ok(()),
                }
            }
            // The robot's last mux again, as it is to be shown now: a lost robot sends none.
            Incoming::EstopPending(pending) => {
                estop_pending = pending;
                match last_mux {
                    Some(m) => send(&mux, estop::marked(m, pending)),
                    None => Ok(()),
                }
            }
        };
        if let Err(e) = sent {
            result = Err(e);
            break;
        }
    }
    crate::export::write_trace(trace.as_ref());
    crate::export::join(stop, threads, result)
}

fn report_lost(name: &str, lost: &Lost) {
    if lost.first {
        tracing::warn!(robot = name, "link lost: {}", lost.why);
        eprintln!(
            "chassis-zenoh: robot '{name}' LOST: {} (shown here as remote_lost; its remote \
             sources time out on the robot)",
            lost.why
        );
    }
}

fn send<T: std::fmt::Debug + ZeroCopySend + Copy + 'static>(
    writer: &Writer<T>,
    value: T,
) -> anyhow::Result<()> {
    writer
        .publisher
        .send_copy(value)
        .map_err(|e| anyhow::anyhow!("publishing: {e}"))?;
    writer
        .notifier
        .notify()
        .map_err(|e| anyhow::anyhow!("waking the readers: {e}"))?;
    Ok(())
}

/// Creates the local `cmd/<source>` and puts each request on the network.
fn forward(
    name: &str,
    session: &zenoh::Session,
    keys: &Keys,
    source: &str,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let node = node(name, &format!("cmd-{source}"))?;
    let service = service_name(name, ServiceKind::Cmd(source));
    let reader = CMD
        .create(&node, &service)?
        .subscriber(CMD.limits.subscriber_max_buffer_size)?;
    let key = keys.cmd(source);
    let publisher = session
        .declare_publisher(key.clone())
        .encoding(Wire::<VelocityRequest>::new().encoding())
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::InteractiveHigh)
        .express(true)
        .wait()
        .map_err(zerr(&key))?;
    eprintln!("chassis-zenoh: source '{source}' of robot '{name}' ready here");
    let mut failed: u64 = 0;
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        wait_listener(&reader.listener, POLL)
            .map_err(|e| anyhow::anyhow!("waiting on {service}: {e}"))?;
        while let Some(sample) = reader
            .subscriber
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving on {service}: {e}"))?
        {
            if let Err(e) = publisher.put(sample.payload().as_bytes()).wait() {
                failed += 1;
                if failed.is_power_of_two() {
                    tracing::warn!(failed, "putting {key}: {e}");
                }
            }
        }
    }
    Ok(())
}

/// What the control thread shares with the mirror's loop.
struct ControlLink {
    /// Counts each time the robot is heard again after a silence.
    heard_again: Arc<AtomicU64>,
    /// Tells the loop when an e-stop becomes pending, or no longer is (the mux shows it).
    pending: mpsc::Sender<Incoming>,
}

impl ControlLink {
    fn heard(&self) -> u64 {
        self.heard_again.load(Ordering::Relaxed)
    }

    fn show(&self, pending: bool) {
        let _ = self.pending.send(Incoming::EstopPending(pending));
    }
}

/// Serves the local `control`, asking the robot for each request. An `estop` LOCK_ENGAGE is
/// kept pending from its forward until chassisd answers, and delivered again while pending
/// ([`crate::estop`]); a release of the e-stop ends that.
fn serve_control(
    name: &str,
    session: &zenoh::Session,
    keys: &Keys,
    link: &ControlLink,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let node = node(name, "control")?;
    let service = service_name(name, ServiceKind::Control);
    let ports = CONTROL
        .create(&node, &service)?
        .server()
        .with_context(|| format!("serving {service}"))?;
    let requests = Wire::<ControlRequest>::new();
    let responses = Wire::<ControlResponse>::new();
    let mut keeper = Keeper::new(link.heard());
    // Deliveries of the pending e-stop waiting for their answer.
    let mut deliveries: Vec<FifoChannelHandler<Reply>> = Vec::new();
    while !termination_requested() && !stop.load(Ordering::Relaxed) {
        let wait = if keeper.pending().is_some() {
            PENDING_POLL
        } else {
            POLL
        };
        wait_listener(&ports.requests, wait)
            .map_err(|e| anyhow::anyhow!("waiting on {service}: {e}"))?;
        while let Some(active) = ports
            .server
            .receive()
            .map_err(|e| anyhow::anyhow!("receiving on {service}: {e}"))?
        {
            let request = *active.payload();
            let asked = estop::classify(&request);
            match asked {
                Asked::EstopEngage => {
                    if keeper.asked(request, now_ns()) {
                        link.show(true);
                    }
                }
                Asked::EstopRelease => {
                    if keeper.released() {
                        deliveries.clear();
                        link.show(false);
                        tracing::info!(robot = name, "the pending e-stop was released here");
                        eprintln!(
                            "chassis-zenoh: robot '{name}': the e-stop it had not received yet \
                             was released by the operator; no longer kept"
                        );
                    }
                }
                Asked::Other => {}
            }
            let mut response = match ask(session, keys, &requests, &responses, &request) {
                Ok(response) => {
                    if asked == Asked::EstopEngage {
                        deliveries.clear();
                        settle(name, &mut keeper, &response, link);
                    }
                    response
                }
                Err(why) if asked == Asked::EstopEngage => {
                    if keeper.unanswered() {
                        report_kept(name, &why);
                    }
                    ControlResponse::new(
                        request.seq,
                        ControlStatus::TIMEOUT,
                        &format!("{why}; kept pending until the robot answers"),
                    )
                }
                Err(why) => ControlResponse::new(request.seq, ControlStatus::TIMEOUT, &why),
            };
            response.request_seq = request.seq;
            active
                .send_copy(response)
                .map_err(|e| anyhow::anyhow!("answering on {service}: {e}"))?;
            ports
                .replies
                .notify()
                .map_err(|e| anyhow::anyhow!("waking the clients of {service}: {e}"))?;
        }
        redeliver(
            name,
            session,
            keys,
            (&requests, &responses),
            link,
            &mut keeper,
            &mut deliveries,
        );
    }
    Ok(())
}

/// The pending e-stop's deliveries: their answers taken, and the next one sent when it is time
/// (never blocking: a dead link holds up no request asked meanwhile).
fn redeliver(
    name: &str,
    session: &zenoh::Session,
    keys: &Keys,
    (requests, responses): (&Wire<ControlRequest>, &Wire<ControlResponse>),
    link: &ControlLink,
    keeper: &mut Keeper,
    deliveries: &mut Vec<FifoChannelHandler<Reply>>,
) {
    let mut answered = None;
    let mut i = 0;
    while i < deliveries.len() {
        match deliveries[i].try_recv() {
            Ok(None) => i += 1,
            Ok(Some(reply)) => match judge(responses, &reply) {
                Ok(response) => {
                    answered = Some(response);
                    break;
                }
                Err(why) => {
                    tracing::debug!(robot = name, "a delivery of the pending e-stop: {why}");
                    deliveries.swap_remove(i);
                }
            },
            // Over without an answer: no route to the robot, or no reply in time.
            Err(_) => {
                deliveries.swap_remove(i);
            }
        }
    }
    if let Some(response) = answered {
        deliveries.clear();
        settle(name, keeper, &response, link);
    }
    if let Some(request) = keeper.due(now_ns(), link.heard(), deliveries.len()) {
        match query(session, keys, requests, &request) {
            Ok(replies) => deliveries.push(replies),
            Err(why) => tracing::debug!(robot = name, "delivering the pending e-stop: {why}"),
        }
    }
}

/// chassisd answered an e-stop: no longer kept, whatever the answer.
fn settle(name: &str, keeper: &mut Keeper, response: &ControlResponse, link: &ControlLink) {
    let Some(kept) = keeper.answered() else {
        return;
    };
    link.show(false);
    let pending_ms = now_ns().saturating_sub(kept.since_ns) / 1_000_000;
    if response.is_ok() {
        if kept.unanswered {
            tracing::info!(
                robot = name,
                pending_ms,
                deliveries = kept.tries,
                "the pending e-stop reached chassisd: {}",
                response.message()
            );
            eprintln!(
                "chassis-zenoh: robot '{name}' has the e-stop now: {} (pending {pending_ms} ms, \
                 {} deliveries)",
                response.message(),
                kept.tries
            );
        }
    } else {
        tracing::warn!(
            robot = name,
            status = ControlStatus::name(response.status),
            "chassisd refused the e-stop: {}; no longer kept",
            response.message()
        );
        eprintln!(
            "chassis-zenoh: robot '{name}': chassisd refused the e-stop ({}: {}); no longer kept",
            ControlStatus::name(response.status),
            response.message()
        );
    }
}

fn report_kept(name: &str, why: &str) {
    tracing::warn!(
        robot = name,
        "e-stop kept pending: {why}; delivered when the robot answers again"
    );
    eprintln!(
        "chassis-zenoh: robot '{name}' did not take the e-stop ({why}): kept pending, delivered \
         when its link returns"
    );
}

/// Sends `request` to the robot's control queryable; its replies arrive on the handler.
fn query(
    session: &zenoh::Session,
    keys: &Keys,
    requests: &Wire<ControlRequest>,
    request: &ControlRequest,
) -> Result<FifoChannelHandler<Reply>, String> {
    session
        .get(keys.control.clone())
        .payload(request.as_bytes())
        .encoding(requests.encoding())
        .timeout(ANSWER_TIMEOUT)
        .wait()
        .map_err(|e| format!("asking the robot: {e}"))
}

/// chassisd's answer in a reply, or why it is none.
fn judge(responses: &Wire<ControlResponse>, reply: &Reply) -> Result<ControlResponse, String> {
    match reply.result() {
        Ok(sample) => responses
            .decode(sample.encoding(), &sample.payload().to_bytes())
            .map_err(|e| format!("the robot's answer: {e}")),
        Err(err) => Err(format!(
            "the robot refused: {}",
            err.payload()
                .try_to_string()
                .map_or_else(|_| "?".into(), |s| s.into_owned())
        )),
    }
}

/// The robot's answer to `request`, or why there is none.
fn ask(
    session: &zenoh::Session,
    keys: &Keys,
    requests: &Wire<ControlRequest>,
    responses: &Wire<ControlResponse>,
    request: &ControlRequest,
) -> Result<ControlResponse, String> {
    match query(session, keys, requests, request)?.recv() {
        Ok(reply) => judge(responses, &reply),
        Err(_) => Err(format!(
            "no answer from the robot over Zenoh (waited at most {ANSWER_TIMEOUT:?})"
        )),
    }
}
