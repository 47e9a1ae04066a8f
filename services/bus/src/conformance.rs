//! The conformance suite of [`CanBus`]: the contract the service relies on, checked the same way
//! on every backend (house style, rule 3).
//!
//! Each check takes the two ends of one link — `from` and `to`, or `a` and `b` — and returns a
//! [`Violation`] naming the check and what was seen instead. It never panics, so it is plain
//! library code: the backends' own tests run it on a socket pair and on slcan over a pty
//! (`cargo test -p chassis-bus conformance`), and `services/bus/tests/vcan.rs` runs it on two
//! SocketCAN sockets of `vcan0` inside a VM (`scripts/vm-tests`), where the kernel has CAN.
//!
//! | check | the contract |
//! | --- | --- |
//! | [`idle_recv_is_none_at_once`] | nothing pending: `recv` returns `Ok(None)` without blocking, the descriptor is not readable |
//! | [`frames_arrive_unchanged_and_in_order`] | standard and extended ids, 0 to 8 data bytes, the extreme ids: the same frames, in order, once; the sender does not hear itself |
//! | [`frames_cross_both_ways_at_once`] | both ends send before either reads: each gets the other's frame only |
//! | [`the_descriptor_turns_readable_when_a_frame_is_pending`] | the event loop may sleep on the descriptor: it turns readable when a frame is pending, not before, and not after the last one is read |
//! | [`a_burst_arrives_whole_and_in_order`] | a burst of one drain batch ([`MAX_RX_BATCH`]) arrives whole and in order; a full queue is reported as [`BusError::TxDropped`], never as a silent loss |
//! | [`a_lost_link_is_a_disconnect`] | a closed peer, a pty hung up, an interface down or removed: [`BusError::Disconnected`] from `recv` or `send`, never silence |
//!
//! [`check_link`] runs every check but the last (which ends the link) in both directions and
//! returns what it measured.
// The suite times real buses: it reads the clock as the loops do.
#![allow(clippy::disallowed_methods)]

use std::fmt;
use std::os::fd::{BorrowedFd, RawFd};
use std::time::Duration;

use chassis_protocols::{CanFrame, Timestamp};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use thiserror::Error;

use super::{BusError, CanBus, MAX_RX_BATCH};
use crate::clock;

/// How long a frame may take to cross a link before it counts as lost. Generous: the suite also
/// runs on an emulated CPU.
pub const DELIVERY_TIMEOUT: Duration = Duration::from_secs(3);
/// The longest a `recv` with nothing pending may take.
pub const NON_BLOCKING_LIMIT: Duration = Duration::from_millis(100);
/// Single frames timed by [`the_descriptor_turns_readable_when_a_frame_is_pending`].
const LATENCY_SAMPLES: usize = 25;

/// A broken promise of a bus backend.
#[derive(Debug, Error)]
#[error("{check}: {detail}")]
pub struct Violation {
    /// The check, as named in this module.
    pub check: &'static str,
    /// What was expected and what happened instead.
    pub detail: String,
}

fn violation(check: &'static str, detail: impl Into<String>) -> Violation {
    Violation {
        check,
        detail: detail.into(),
    }
}

/// What [`check_link`] measured, for the report.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Figures {
    /// One frame, send → its receiver's descriptor readable: median and worst of both directions.
    pub latency_median: Duration,
    pub latency_max: Duration,
    /// A burst of [`MAX_RX_BATCH`] frames, first send → last receive, in frames per second (the
    /// slower direction).
    pub burst_frames_per_s: f64,
    /// How often a burst's sender was told [`BusError::TxDropped`] and sent the frame again.
    pub burst_retries: u64,
}

impl fmt::Display for Figures {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "latency median {} µs, max {} µs; burst of {MAX_RX_BATCH} at {:.0} frames/s ({} sends retried)",
            self.latency_median.as_micros(),
            self.latency_max.as_micros(),
            self.burst_frames_per_s,
            self.burst_retries
        )
    }
}

/// Standard and extended ids, the extremes of each, and every length from 0 to 8 bytes.
pub fn sample_frames() -> Vec<CanFrame> {
    let mut frames = Vec::new();
    for len in 0..=8usize {
        let data: Vec<u8> = (0..len).map(|i| (0xA0 + len * 8 + i) as u8).collect();
        let standard = [0x000, 0x001, 0x123, CanFrame::MAX_STANDARD_ID][len % 4];
        let extended = [
            0x0000_0000,
            0x18FF_0001,
            0x0000_0800,
            CanFrame::MAX_EXTENDED_ID,
        ][len % 4];
        frames.extend(CanFrame::new(standard, &data).ok());
        frames.extend(CanFrame::new_extended(extended, &data).ok());
    }
    // Every byte value crosses: 0x00, 0xFF, CR and BEL (slcan's delimiters) among them.
    for chunk in [0x00u8, 0x0D, 0x07, 0x0A, 0x7F, 0x80, 0xFE, 0xFF].chunks(8) {
        frames.extend(CanFrame::new(0x211, chunk).ok());
    }
    frames
}

/// Frame `i` of a burst: its number in the first four bytes, ids cycling, every fourth extended.
fn burst_frame(i: usize) -> Option<CanFrame> {
    let mut data = [0u8; 8];
    let n = u32::try_from(i).ok()?;
    data[..4].copy_from_slice(&n.to_be_bytes());
    data[4..].copy_from_slice(&(!n).to_le_bytes());
    let len = 4 + i % 5;
    if i % 4 == 3 {
        CanFrame::new_extended(0x1000_0000 | n, &data[..len]).ok()
    } else {
        CanFrame::new(0x100 + n % 0x600, &data[..len]).ok()
    }
}

fn elapsed(since: Timestamp) -> Duration {
    clock::now().saturating_since(since)
}

/// Waits until `fd` is readable (true) or `timeout` passes (false).
fn readable(fd: RawFd, timeout: Duration) -> Result<bool, Violation> {
    // SAFETY: `fd` belongs to a bus borrowed by the caller for the whole call.
    let fd = unsafe { BorrowedFd::borrow_raw(fd) };
    let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
    // Rounded up to the next millisecond, so a short wait still waits.
    let ms = timeout.as_micros().div_ceil(1000);
    let timeout = PollTimeout::try_from(ms).unwrap_or(PollTimeout::MAX);
    match poll(&mut fds, timeout) {
        Ok(n) => Ok(n > 0),
        Err(nix::errno::Errno::EINTR) => Ok(false),
        Err(e) => Err(violation(
            "poll",
            format!("poll on the bus descriptor: {e}"),
        )),
    }
}

fn recv_error(check: &'static str, bus: &dyn CanBus, err: BusError) -> Violation {
    violation(check, format!("recv on {} failed: {err}", bus.name()))
}

/// The next frame within `timeout`, waiting on the descriptor.
fn recv_within(
    check: &'static str,
    bus: &mut dyn CanBus,
    timeout: Duration,
) -> Result<Option<CanFrame>, Violation> {
    let start = clock::now();
    loop {
        match bus.recv() {
            Ok(Some(frame)) => return Ok(Some(frame)),
            Ok(None) => {}
            Err(err) => return Err(recv_error(check, bus, err)),
        }
        let spent = elapsed(start);
        if spent >= timeout {
            return Ok(None);
        }
        // Capped so a backend whose descriptor misses a wake-up still gets polled.
        readable(
            bus.raw_fd(),
            (timeout - spent).min(Duration::from_millis(50)),
        )?;
    }
}

/// Reads whatever is pending; any frame is a stray one.
fn settle(check: &'static str, bus: &mut dyn CanBus) -> Result<(), Violation> {
    if let Some(frame) = bus.recv().map_err(|e| recv_error(check, bus, e))? {
        return Err(violation(
            check,
            format!("{} received a frame nobody sent to it: {frame}", bus.name()),
        ));
    }
    Ok(())
}

/// Sends one frame and flushes it (a backend may buffer sends until `flush`).
fn send(check: &'static str, bus: &mut dyn CanBus, frame: &CanFrame) -> Result<(), Violation> {
    bus.send(frame)
        .and_then(|()| bus.flush())
        .map_err(|e| violation(check, format!("{} could not send {frame}: {e}", bus.name())))
}

/// Sends every frame of `frames` from `from`. A send refused with [`BusError::TxDropped`] (the
/// queue is full) is repeated after `to` has read what is pending, into `received`. Returns how
/// many sends were repeated.
fn send_all(
    check: &'static str,
    from: &mut dyn CanBus,
    to: &mut dyn CanBus,
    frames: &[CanFrame],
    received: &mut Vec<CanFrame>,
) -> Result<u64, Violation> {
    let mut retries = 0u64;
    for frame in frames {
        let mut refused_since = None;
        loop {
            match from.send(frame).and_then(|()| from.flush()) {
                Ok(()) => break,
                Err(BusError::TxDropped { .. }) => {
                    retries += 1;
                    let since = *refused_since.get_or_insert_with(clock::now);
                    if elapsed(since) > DELIVERY_TIMEOUT {
                        return Err(violation(
                            check,
                            format!("{} refused {frame} for {DELIVERY_TIMEOUT:?}", from.name()),
                        ));
                    }
                    while let Some(got) = to.recv().map_err(|e| recv_error(check, to, e))? {
                        received.push(got);
                    }
                    settle(check, from)?;
                    readable(to.raw_fd(), Duration::from_millis(1))?;
                }
                Err(err) => {
                    return Err(violation(
                        check,
                        format!("{} could not send {frame}: {err}", from.name()),
                    ));
                }
            }
        }
    }
    Ok(retries)
}

/// Nothing pending: `recv` answers `Ok(None)` at once and the descriptor is not readable.
pub fn idle_recv_is_none_at_once(bus: &mut dyn CanBus) -> Result<(), Violation> {
    const CHECK: &str = "idle_recv_is_none_at_once";
    // Replies of the link's own protocol (slcan's OKs) may be pending: they are no frames.
    settle(CHECK, bus)?;
    // A blocking recv would never return; a slow one once in three tries is the scheduler's.
    let mut fastest = Duration::MAX;
    for _ in 0..3 {
        let start = clock::now();
        let got = bus.recv().map_err(|e| recv_error(CHECK, bus, e))?;
        fastest = fastest.min(elapsed(start));
        if let Some(frame) = got {
            return Err(violation(CHECK, format!("an idle bus returned {frame}")));
        }
    }
    if fastest > NON_BLOCKING_LIMIT {
        return Err(violation(
            CHECK,
            format!("recv with nothing pending took at least {fastest:?}"),
        ));
    }
    if readable(bus.raw_fd(), Duration::ZERO)? {
        return Err(violation(
            CHECK,
            format!("the descriptor of idle {} is readable", bus.name()),
        ));
    }
    Ok(())
}

/// [`sample_frames`] sent by `from` arrive at `to` unchanged, in order and once; `from` hears
/// nothing of its own. (Sends refused as [`BusError::TxDropped`] are repeated, as in
/// [`a_burst_arrives_whole_and_in_order`].)
pub fn frames_arrive_unchanged_and_in_order(
    from: &mut dyn CanBus,
    to: &mut dyn CanBus,
) -> Result<(), Violation> {
    const CHECK: &str = "frames_arrive_unchanged_and_in_order";
    settle(CHECK, from)?;
    settle(CHECK, to)?;
    let frames = sample_frames();
    let mut received = Vec::with_capacity(frames.len());
    send_all(CHECK, from, to, &frames, &mut received)?;
    let mut early = received.into_iter();
    for (i, sent) in frames.iter().enumerate() {
        let got = match early.next() {
            Some(frame) => Some(frame),
            None => recv_within(CHECK, to, DELIVERY_TIMEOUT)?,
        };
        match got {
            Some(got) if got == *sent => {}
            Some(got) => {
                return Err(violation(
                    CHECK,
                    format!("frame {i}: sent {sent}, {} received {got}", to.name()),
                ));
            }
            None => {
                return Err(violation(
                    CHECK,
                    format!(
                        "frame {i} ({sent}) did not arrive within {DELIVERY_TIMEOUT:?} ({i} of {} did)",
                        frames.len()
                    ),
                ));
            }
        }
    }
    if let Some(extra) = recv_within(CHECK, to, Duration::from_millis(20))? {
        return Err(violation(
            CHECK,
            format!("{} received {extra} after the last frame", to.name()),
        ));
    }
    settle(CHECK, from).map_err(|v| violation(CHECK, format!("the sender heard itself: {v}")))
}

/// Both ends send before either reads; each receives exactly the other's frame.
pub fn frames_cross_both_ways_at_once(
    a: &mut dyn CanBus,
    b: &mut dyn CanBus,
) -> Result<(), Violation> {
    const CHECK: &str = "frames_cross_both_ways_at_once";
    settle(CHECK, a)?;
    settle(CHECK, b)?;
    let (fa, fb) = match (
        CanFrame::new(0x111, &[0xA1, 0xA2, 0xA3]),
        CanFrame::new_extended(0x0CFE_6CEE, &[0xB1]),
    ) {
        (Ok(fa), Ok(fb)) => (fa, fb),
        _ => return Err(violation(CHECK, "the test frames are invalid")),
    };
    send(CHECK, a, &fa)?;
    send(CHECK, b, &fb)?;
    expect_frame(CHECK, b, fa)?;
    expect_frame(CHECK, a, fb)?;
    settle(CHECK, a)?;
    settle(CHECK, b)
}

fn expect_frame(
    check: &'static str,
    bus: &mut dyn CanBus,
    want: CanFrame,
) -> Result<(), Violation> {
    match recv_within(check, bus, DELIVERY_TIMEOUT)? {
        Some(got) if got == want => Ok(()),
        Some(got) => Err(violation(
            check,
            format!("{} received {got}, not {want}", bus.name()),
        )),
        None => Err(violation(
            check,
            format!("{want} did not reach {}", bus.name()),
        )),
    }
}

/// The descriptor of `to` is not readable while nothing is pending, turns readable when `from`
/// sends, and is quiet again once `recv` returned `Ok(None)`. Returns the send → readable
/// latency of each of `LATENCY_SAMPLES` (25) frames.
pub fn the_descriptor_turns_readable_when_a_frame_is_pending(
    from: &mut dyn CanBus,
    to: &mut dyn CanBus,
) -> Result<Vec<Duration>, Violation> {
    const CHECK: &str = "the_descriptor_turns_readable_when_a_frame_is_pending";
    settle(CHECK, from)?;
    settle(CHECK, to)?;
    let mut latencies = Vec::with_capacity(LATENCY_SAMPLES);
    for i in 0..LATENCY_SAMPLES {
        if readable(to.raw_fd(), Duration::ZERO)? {
            return Err(violation(
                CHECK,
                format!("round {i}: the descriptor is readable before anything was sent"),
            ));
        }
        let frame = CanFrame::new(0x7E0, &[u8::try_from(i).unwrap_or(0xFF); 8])
            .map_err(|e| violation(CHECK, e.to_string()))?;
        let sent = clock::now();
        send(CHECK, from, &frame)?;
        if !readable(to.raw_fd(), DELIVERY_TIMEOUT)? {
            return Err(violation(
                CHECK,
                format!("round {i}: not readable {DELIVERY_TIMEOUT:?} after a send"),
            ));
        }
        latencies.push(elapsed(sent));
        match recv_within(CHECK, to, DELIVERY_TIMEOUT)? {
            Some(got) if got == frame => {}
            other => {
                return Err(violation(
                    CHECK,
                    format!("round {i}: readable, but recv gave {other:?}, not {frame}"),
                ));
            }
        }
        if let Some(extra) = to.recv().map_err(|e| recv_error(CHECK, to, e))? {
            return Err(violation(
                CHECK,
                format!("round {i}: a second frame {extra}"),
            ));
        }
        if readable(to.raw_fd(), Duration::ZERO)? {
            return Err(violation(
                CHECK,
                format!("round {i}: still readable after recv returned None"),
            ));
        }
        // The sender may have protocol replies to read (slcan's transmit acks).
        settle(CHECK, from)?;
    }
    Ok(latencies)
}

/// What one burst took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Burst {
    pub frames: usize,
    pub took: Duration,
    /// Sends answered [`BusError::TxDropped`] and repeated after the receiver read.
    pub retries: u64,
}

/// `n` numbered frames sent back to back arrive whole and in order. A sender told
/// [`BusError::TxDropped`] (its queue is full) lets the receiver read, then sends the same frame
/// again: a full queue may refuse a frame, but it may not lose one it accepted.
pub fn a_burst_arrives_whole_and_in_order(
    from: &mut dyn CanBus,
    to: &mut dyn CanBus,
    n: usize,
) -> Result<Burst, Violation> {
    const CHECK: &str = "a_burst_arrives_whole_and_in_order";
    settle(CHECK, from)?;
    settle(CHECK, to)?;
    let sent: Vec<CanFrame> = (0..n).filter_map(burst_frame).collect();
    if sent.len() != n {
        return Err(violation(CHECK, format!("cannot number {n} frames")));
    }
    let mut received = Vec::with_capacity(n);
    let start = clock::now();
    let retries = send_all(CHECK, from, to, &sent, &mut received)?;
    while received.len() < n {
        match recv_within(CHECK, to, DELIVERY_TIMEOUT)? {
            Some(got) => received.push(got),
            None => break,
        }
    }
    let took = elapsed(start);
    if let Some(i) = (0..n.min(received.len())).find(|&i| received[i] != sent[i]) {
        let missing = sent.iter().filter(|f| !received.contains(f)).count();
        return Err(violation(
            CHECK,
            format!(
                "frame {i}: sent {}, received {} ({} of {n} arrived, {missing} lost)",
                sent[i],
                received[i],
                received.len()
            ),
        ));
    }
    if received.len() != n {
        return Err(violation(
            CHECK,
            format!(
                "{} of {n} frames arrived within {DELIVERY_TIMEOUT:?} after the last send",
                received.len()
            ),
        ));
    }
    settle(CHECK, to)?;
    settle(CHECK, from)?;
    Ok(Burst {
        frames: n,
        took,
        retries,
    })
}

/// After `lose` (close the peer, hang up the line, take the interface down or remove it),
/// `survivor` reports [`BusError::Disconnected`] from `recv` or `send` within
/// [`DELIVERY_TIMEOUT`]. Frames still in flight may come first; dropped sends are allowed.
/// Returns how long the loss took to show.
pub fn a_lost_link_is_a_disconnect(
    survivor: &mut dyn CanBus,
    lose: impl FnOnce() -> Result<(), String>,
) -> Result<Duration, Violation> {
    const CHECK: &str = "a_lost_link_is_a_disconnect";
    let probe =
        CanFrame::new(0x7DF, &[0x02, 0x01, 0x00]).map_err(|e| violation(CHECK, e.to_string()))?;
    lose().map_err(|e| violation(CHECK, format!("cannot end the link: {e}")))?;
    let start = clock::now();
    let mut seen = Vec::new();
    while elapsed(start) < DELIVERY_TIMEOUT {
        match survivor.recv() {
            Err(err) if err.is_disconnect() => return Ok(elapsed(start)),
            Err(err) => {
                return Err(violation(
                    CHECK,
                    format!("recv reported {err}, not a disconnect"),
                ));
            }
            Ok(Some(frame)) => {
                seen.push(frame);
                continue;
            }
            Ok(None) => {}
        }
        match survivor.send(&probe).and_then(|()| survivor.flush()) {
            Err(err) if err.is_disconnect() => return Ok(elapsed(start)),
            Ok(()) | Err(BusError::TxDropped { .. }) => {}
            Err(err) => {
                return Err(violation(
                    CHECK,
                    format!("send reported {err}, not a disconnect"),
                ));
            }
        }
        readable(survivor.raw_fd(), Duration::from_millis(20))?;
    }
    Err(violation(
        CHECK,
        format!(
            "{} still looks healthy {DELIVERY_TIMEOUT:?} after the link was lost ({} frames read meanwhile)",
            survivor.name(),
            seen.len()
        ),
    ))
}

/// Every check but [`a_lost_link_is_a_disconnect`], in both directions.
pub fn check_link(a: &mut dyn CanBus, b: &mut dyn CanBus) -> Result<Figures, Violation> {
    idle_recv_is_none_at_once(a)?;
    idle_recv_is_none_at_once(b)?;
    frames_arrive_unchanged_and_in_order(a, b)?;
    frames_arrive_unchanged_and_in_order(b, a)?;
    frames_cross_both_ways_at_once(a, b)?;
    let mut latencies = the_descriptor_turns_readable_when_a_frame_is_pending(a, b)?;
    latencies.extend(the_descriptor_turns_readable_when_a_frame_is_pending(b, a)?);
    latencies.sort();
    let ab = a_burst_arrives_whole_and_in_order(a, b, MAX_RX_BATCH)?;
    let ba = a_burst_arrives_whole_and_in_order(b, a, MAX_RX_BATCH)?;
    let rate = |burst: &Burst| burst.frames as f64 / burst.took.as_secs_f64().max(1e-9);
    idle_recv_is_none_at_once(a)?;
    idle_recv_is_none_at_once(b)?;
    Ok(Figures {
        latency_median: latencies
            .get(latencies.len() / 2)
            .copied()
            .unwrap_or_default(),
        latency_max: latencies.last().copied().unwrap_or_default(),
        burst_frames_per_s: rate(&ab).min(rate(&ba)),
        burst_retries: ab.retries + ba.retries,
    })
}

#[cfg(test)]
mod tests {
    //! The suite on the backends that run anywhere: the socket pair of the embedded simulator and
    //! slcan (host side against the emulated adapter) over a pty.

    use super::*;
    use crate::datagram::PairCan;
    use crate::serial::{SerialBus, pty_pair};
    use crate::slcan::{SlcanAdapter, SlcanBus};

    fn socket_pair() -> (PairCan, PairCan) {
        PairCan::pair("sim").unwrap()
    }

    /// The service's slcan host on the slave side of a pty (as on a USB adapter's tty), the
    /// emulated adapter on the master side, its channel opened.
    fn slcan() -> (SlcanBus<SerialBus>, SlcanAdapter<SerialBus>) {
        let (master, slave) = pty_pair().unwrap();
        let host = SlcanBus::open(slave, 500_000).unwrap();
        let mut adapter = SlcanAdapter::new(master);
        let start = clock::now();
        while !adapter.is_open() {
            assert_eq!(adapter.recv().unwrap(), None);
            assert!(
                elapsed(start) < DELIVERY_TIMEOUT,
                "the channel never opened"
            );
            readable(adapter.raw_fd(), Duration::from_millis(10)).unwrap();
        }
        (host, adapter)
    }

    #[test]
    fn sample_frames_cover_every_length_and_both_id_kinds() {
        let frames = sample_frames();
        for len in 0..=8 {
            assert!(frames.iter().any(|f| f.len() == len && f.is_extended()));
            assert!(frames.iter().any(|f| f.len() == len && !f.is_extended()));
        }
        assert!(frames.iter().any(|f| f.id() == CanFrame::MAX_EXTENDED_ID));
        assert!(
            frames
                .iter()
                .any(|f| f.id() == CanFrame::MAX_STANDARD_ID && !f.is_extended())
        );
        assert!((0..MAX_RX_BATCH).all(|i| burst_frame(i).is_some()));
    }

    #[test]
    fn socket_pair_conforms() {
        let (mut a, mut b) = socket_pair();
        let figures = check_link(&mut a, &mut b).unwrap();
        eprintln!("socket pair: {figures}");
    }

    #[test]
    fn socket_pair_reports_a_closed_peer_as_a_disconnect() {
        let (mut a, b) = socket_pair();
        a_lost_link_is_a_disconnect(&mut a, || {
            drop(b);
            Ok(())
        })
        .unwrap();
    }

    #[test]
    fn slcan_over_a_pty_conforms() {
        let (mut host, mut adapter) = slcan();
        let figures = check_link(&mut host, &mut adapter).unwrap();
        eprintln!("slcan over a pty: {figures}");
    }

    #[test]
    fn slcan_host_reports_the_adapter_unplugged_as_a_disconnect() {
        let (mut host, adapter) = slcan();
        a_lost_link_is_a_disconnect(&mut host, || {
            drop(adapter);
            Ok(())
        })
        .unwrap();
    }

    #[test]
    fn slcan_adapter_reports_the_host_gone_as_a_disconnect() {
        let (host, mut adapter) = slcan();
        a_lost_link_is_a_disconnect(&mut adapter, || {
            drop(host);
            Ok(())
        })
        .unwrap();
    }

    /// A backend that swallows frames must fail the suite: the suite itself is tested.
    #[derive(Debug)]
    struct Lossy {
        inner: PairCan,
        sent: usize,
    }

    impl CanBus for Lossy {
        fn recv(&mut self) -> Result<Option<CanFrame>, BusError> {
            self.inner.recv()
        }
        fn send(&mut self, frame: &CanFrame) -> Result<(), BusError> {
            self.sent += 1;
            if self.sent.is_multiple_of(7) {
                return Ok(());
            }
            self.inner.send(frame)
        }
        fn flush(&mut self) -> Result<(), BusError> {
            self.inner.flush()
        }
        fn raw_fd(&self) -> RawFd {
            self.inner.raw_fd()
        }
        fn name(&self) -> &str {
            "lossy"
        }
    }

    #[test]
    fn a_backend_that_loses_frames_fails_the_suite() {
        let (a, mut b) = socket_pair();
        let mut lossy = Lossy { inner: a, sent: 0 };
        let err = frames_arrive_unchanged_and_in_order(&mut lossy, &mut b).unwrap_err();
        assert_eq!(err.check, "frames_arrive_unchanged_and_in_order");
        let (a, mut b) = socket_pair();
        let mut lossy = Lossy { inner: a, sent: 0 };
        let err = a_burst_arrives_whole_and_in_order(&mut lossy, &mut b, 64).unwrap_err();
        assert!(err.detail.contains("lost"), "{err}");
    }

    #[test]
    fn a_link_that_never_breaks_fails_the_disconnect_check() {
        let (mut a, _b) = socket_pair();
        let start = clock::now();
        let err = a_lost_link_is_a_disconnect(&mut a, || Ok(())).unwrap_err();
        assert!(elapsed(start) >= DELIVERY_TIMEOUT);
        assert!(err.detail.contains("still looks healthy"), "{err}");
    }
}
