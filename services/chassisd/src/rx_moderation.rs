//! Receive moderation: while the bus is saturated the loop reads it once per interval, everything
//! pending at once, instead of waking for every frame — the way a network driver switches from
//! interrupts to polling under load (Linux NAPI).
//!
//! A token bucket watches the rate of frames: each frame read takes a token (a byte stream
//! counts one per 8 bytes, a CAN payload's worth), tokens come back at [`SATURATION_FRAMES_PER_S`],
//! up to [`BURST`]. A chassis' ordinary feedback (TITAN: ten frames every 20 ms and a few slower
//! ones, about 540 frames/s) never empties it, so every frame is read the moment it arrives. A
//! saturated bus (500 kbit/s: 4,500 frames/s) empties it: the loop then stops watching the bus
//! descriptor and reads it once per interval; the frames wait in the
//! kernel's queue meanwhile (a few dozen at most; none is lost). When a poll finds less than the
//! saturation rate's worth of frames, the loop goes back to waking per frame. The price is at
//! most one interval of extra state latency, only while the bus is saturated.
//!
//! The loop watches the bus through an [`RxGate`], an epoll set of its own holding the bus
//! descriptor: closing and opening the gate is one system call, and the wait set itself never
//! changes.

use serde::{Deserialize, Serialize};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, RawFd};
use std::time::Duration;

use chassis_protocols::{Rx, Timestamp};
use nix::sys::epoll::{Epoll, EpollCreateFlags, EpollEvent, EpollFlags};

/// An epoll set that holds the bus descriptor while open and nothing while closed; the wait
/// set watches the gate's own descriptor, readable exactly when the gate is open and a frame
/// is pending.
#[derive(Debug)]
pub struct RxGate {
    epoll: Epoll,
    bus: Option<RawFd>,
    open: bool,
}

impl RxGate {
    pub fn new() -> nix::Result<Self> {
        Ok(Self {
            epoll: Epoll::new(EpollCreateFlags::EPOLL_CLOEXEC)?,
            bus: None,
            open: false,
        })
    }

    /// The descriptor to watch.
    pub fn raw_fd(&self) -> RawFd {
        self.epoll.0.as_raw_fd()
    }

    /// Watch `bus` (a new bus session) or nothing; the gate opens.
    pub fn watch(&mut self, bus: Option<RawFd>) -> nix::Result<()> {
        self.close();
        self.bus = bus;
        self.set_open(true)
    }

    pub fn is_open(&self) -> bool {
        self.open
    }

    /// Opens (`true`) or closes the gate.
    pub fn set_open(&mut self, open: bool) -> nix::Result<()> {
        if open == self.open {
            return Ok(());
        }
        self.open = open;
        let Some(raw) = self.bus else {
            return Ok(());
        };
        // SAFETY: the descriptor is only named to the kernel, never read or closed through
        // this borrow; a descriptor closed meanwhile makes the call fail, nothing worse.
        let fd = unsafe { BorrowedFd::borrow_raw(raw) };
        if open {
            self.epoll
                .add(fd, EpollEvent::new(EpollFlags::EPOLLIN, raw as u64))
        } else {
            self.epoll.delete(fd)
        }
    }

    fn close(&mut self) {
        // A bus already closed has left the set by itself.
        let _ = self.set_open(false);
    }
}

impl AsFd for RxGate {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.epoll.0.as_fd()
    }
}

/// Bytes of a byte stream that weigh one frame: a CAN payload's worth.
pub const BYTES_PER_FRAME: usize = 8;

/// What an item read from the bus weighs, in frames: a CAN frame one, a chunk of a byte stream
/// one per [`BYTES_PER_FRAME`] bytes begun. A serial robot's feedback is counted at the rate of
/// the CAN frames that would carry it, so one bucket serves both kinds of bus.
pub fn weight(rx: Rx<'_>) -> usize {
    match rx {
        Rx::Can(_) => 1,
        Rx::Bytes(bytes) => bytes.len().div_ceil(BYTES_PER_FRAME),
    }
}

/// Frames allowed back to back before moderation starts.
pub const BURST: f64 = 32.0;
/// Sustained frames per second above which the bus counts as saturated: above any chassis'
/// ordinary feedback, below a saturated bus.
pub const SATURATION_FRAMES_PER_S: f64 = 1500.0;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RxModeration {
    interval: Duration,
    tokens: f64,
    refilled_at: Timestamp,
    polling: bool,
    /// Frames read since `window_start` (the loop's tick may read during a pause).
    harvest: usize,
    window_start: Timestamp,
    paused_until: Option<Timestamp>,
}

impl RxModeration {
    /// `interval`: how often a saturated bus is read; zero turns moderation off (every frame is
    /// read when it arrives).
    pub fn new(interval: Duration, now: Timestamp) -> Self {
        Self {
            interval,
            tokens: BURST,
            refilled_at: now,
            polling: false,
            harvest: 0,
            window_start: now,
            paused_until: None,
        }
    }

    /// The bus was read at `now` and gave `items` frames (a byte stream: 8 bytes a frame);
    /// `backlog`: the read stopped at its batch limit with more pending (a replay at full
    /// speed): no pause then, the next iteration reads on. Returns true when the loop should
    /// stop watching the bus until [`RxModeration::paused_until`].
    pub fn on_read(&mut self, now: Timestamp, items: usize, backlog: bool) -> bool {
        if self.interval.is_zero() || backlog {
            self.paused_until = None;
            return false;
        }
        if self.polling {
            // Judge the load once a whole interval has been harvested (by polls, and by the
            // loop's tick or a command reading the bus in between).
            self.harvest += items;
            let window = now.saturating_since(self.window_start);
            if window >= self.interval {
                let harvest = std::mem::take(&mut self.harvest);
                self.window_start = now;
                if (harvest as f64) < SATURATION_FRAMES_PER_S * window.as_secs_f64() {
                    self.polling = false;
                    self.tokens = BURST;
                    self.refilled_at = now;
                    self.paused_until = None;
                    return false;
                }
            }
            // Everything pending was just read: the next read is due one interval from now.
            // A read on the tick thus moves the poll with it, and the two share one wake-up.
            self.paused_until = Some(now + self.interval);
            return true;
        }
        self.refill(now);
        self.tokens -= items as f64;
        if self.tokens >= 0.0 {
            return false;
        }
        self.polling = true;
        self.harvest = 0;
        self.window_start = now;
        self.paused_until = Some(now + self.interval);
        true
    }

    /// True while the bus is read by polling.
    pub fn is_polling(&self) -> bool {
        self.polling
    }

    /// Until when the bus descriptor is not watched (`None`: watched).
    pub fn paused_until(&self) -> Option<Timestamp> {
        self.paused_until
    }

    /// True while the pause lasts; ends it once `now` has reached its end.
    pub fn is_paused(&mut self, now: Timestamp) -> bool {
        match self.paused_until {
            Some(t) if now < t => true,
            Some(_) => {
                self.paused_until = None;
                false
            }
            None => false,
        }
    }

    /// Forget the history (a new bus session).
    pub fn reset(&mut self, now: Timestamp) {
        self.tokens = BURST;
        self.refilled_at = now;
        self.polling = false;
        self.harvest = 0;
        self.window_start = now;
        self.paused_until = None;
    }

    fn refill(&mut self, now: Timestamp) {
        let elapsed = now.saturating_since(self.refilled_at);
        self.refilled_at = now;
        self.tokens = (self.tokens + elapsed.as_secs_f64() * SATURATION_FRAMES_PER_S).min(BURST);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn us(v: u64) -> Timestamp {
        Timestamp::ZERO + Duration::from_micros(v)
    }

    /// Simulates the loop: frames arrive at `times` (µs); the loop reads when a frame arrives
    /// and the gate is open, and at the end of each pause. Returns (reads, worst wait of a
    /// frame in the kernel, µs).
    fn run(m: &mut RxModeration, times: &[u64]) -> (usize, u64) {
        run_ticked(m, times, None)
    }

    /// [`run`], with the loop's tick every `tick` µs reading the bus too. Every read is a
    /// wake-up of the loop: the count returned is also the wake-ups'.
    fn run_ticked(m: &mut RxModeration, times: &[u64], tick: Option<u64>) -> (usize, u64) {
        let mut reads = 0;
        let mut pending: Vec<u64> = Vec::new();
        let mut worst = 0;
        let mut i = 0;
        let end = times.last().copied().unwrap_or(0) + 100_000;
        let mut read = |m: &mut RxModeration, t: u64, pending: &mut Vec<u64>| {
            for &arrived in pending.iter() {
                worst = worst.max(t - arrived);
            }
            let items = pending.len();
            pending.clear();
            reads += 1;
            m.on_read(us(t), items, false);
        };
        // Step through time in 10 µs increments.
        let mut t = 0;
        while t <= end {
            while i < times.len() && times[i] <= t {
                pending.push(times[i]);
                i += 1;
            }
            let on_tick = tick.is_some_and(|tick| t % tick == 0);
            if on_tick || m.paused_until().is_some_and(|p| us(t) >= p) {
                m.is_paused(us(t));
                read(m, t, &mut pending);
            } else if !pending.is_empty() && !m.is_paused(us(t)) {
                read(m, t, &mut pending);
            }
            t += 10;
        }
        (reads, worst)
    }

    /// TITAN's ordinary feedback on a 500 kbit/s bus for `seconds`: ten 20 ms frames back to
    /// back (222 µs apart), four 100 ms frames, six 500 ms frames.
    fn titan_feedback(seconds: u64) -> Vec<u64> {
        let mut times = Vec::new();
        for cycle in 0..seconds * 50 {
            let start = cycle * 20_000;
            let mut n = 10;
            if cycle % 5 == 0 {
                n += 4;
            }
            if cycle % 25 == 0 {
                n += 6;
            }
            times.extend((0..n).map(|k| start + k * 222));
        }
        times
    }

    #[test]
    fn a_can_frame_weighs_one_and_a_byte_chunk_one_per_eight_bytes_begun() {
        let frame = chassis_protocols::CanFrame::new(0x211, &[0; 8]).unwrap();
        assert_eq!(weight(Rx::Can(&frame)), 1);
        let empty = chassis_protocols::CanFrame::new(0x211, &[]).unwrap();
        assert_eq!(
            weight(Rx::Can(&empty)),
            1,
            "a frame weighs one whatever its payload"
        );
        let weights: Vec<usize> = [0, 1, 8, 9, 16, 17, 4096]
            .iter()
            .map(|&n| weight(Rx::Bytes(&vec![0u8; n])))
            .collect();
        assert_eq!(weights, [0, 1, 1, 2, 2, 3, 512]);
    }

    #[test]
    fn a_serial_flood_pauses_like_a_can_flood_of_the_same_bytes() {
        // 4,500 CAN frames a second, or the same payload bytes as 36-byte chunks a millisecond
        // (4.5 per read): both saturate the bucket.
        let weigh = |chunk: usize| weight(Rx::Bytes(&vec![0u8; chunk]));
        let mut can = RxModeration::new(Duration::from_millis(4), us(0));
        let mut serial = RxModeration::new(Duration::from_millis(4), us(0));
        let (mut can_paused, mut serial_paused) = (false, false);
        for ms in 0..100 {
            can_paused |= can.on_read(us(ms * 1000), 4, false);
            serial_paused |= serial.on_read(us(ms * 1000), weigh(36), false);
        }
        assert!(can_paused && serial_paused);
        // Counted per read instead, the serial flood would never pause.
        let mut per_read = RxModeration::new(Duration::from_millis(4), us(0));
        assert!((0..100).all(|ms| !per_read.on_read(us(ms * 1000), 1, false)));
    }

    #[test]
    fn off_never_pauses() {
        let mut m = RxModeration::new(Duration::ZERO, us(0));
        assert!((0..1000).all(|i| !m.on_read(us(i), 1, false)));
        assert_eq!(m.paused_until(), None);
    }

    #[test]
    fn ordinary_feedback_is_read_the_moment_it_arrives() {
        let mut m = RxModeration::new(Duration::from_millis(4), us(0));
        let times = titan_feedback(10);
        let (reads, worst) = run(&mut m, &times);
        assert_eq!(reads, times.len());
        assert!(worst <= 10, "a frame waited {worst} µs");
        assert!(!m.is_polling());
    }

    #[test]
    fn a_saturated_bus_is_read_once_per_interval_and_nothing_waits_longer() {
        // 500 kbit/s, 8-byte frames: one every 222 µs, for two seconds.
        let interval = Duration::from_millis(4);
        let mut m = RxModeration::new(interval, us(0));
        let times: Vec<u64> = (0..9000).map(|k| k * 222).collect();
        let (reads, worst) = run(&mut m, &times);
        // The burst, then one read per interval: about 500 in two seconds, not 9000.
        assert!(reads < 600, "{reads} reads");
        assert!(reads > 400, "{reads} reads");
        assert!(worst <= 4_000 + 20, "a frame waited {worst} µs");
    }

    #[test]
    fn the_tick_and_the_poll_share_a_wake_up() {
        // The saturated bus of the test above, with the loop's 20 ms tick reading it too: the
        // tick's read moves the next poll, so a tick costs no wake-up of its own. Two seconds:
        // 100 ticks and 400 polls between them, plus ≈ 50 reads before the bucket runs dry and
        // the ticks after the flood — about 550; 650 if ticks and polls ran apart.
        let mut m = RxModeration::new(Duration::from_millis(4), us(0));
        // The flood begins between two ticks: polling starts out of step with them.
        let times: Vec<u64> = (0..9000).map(|k| 1_230 + k * 222).collect();
        let (wakes, worst) = run_ticked(&mut m, &times, Some(20_000));
        assert!(wakes <= 570, "{wakes} wake-ups");
        assert!(wakes > 400, "{wakes} wake-ups");
        assert!(worst <= 4_000 + 20, "a frame waited {worst} µs");
        assert!(!m.is_polling(), "polling ended with the flood");
    }

    #[test]
    fn a_saturated_bus_delivered_in_bursts_is_polled_too() {
        // The same load arriving as five frames per write, one write per millisecond.
        let interval = Duration::from_millis(4);
        let mut m = RxModeration::new(interval, us(0));
        let times: Vec<u64> = (0..10_000).map(|k| (k / 5) * 1000).collect();
        let (reads, worst) = run(&mut m, &times);
        assert!(reads < 600, "{reads} reads");
        assert!(worst <= 4_000 + 20, "a frame waited {worst} µs");
    }

    #[test]
    fn polling_ends_when_the_load_does() {
        let mut m = RxModeration::new(Duration::from_millis(4), us(0));
        let mut times: Vec<u64> = (0..4500).map(|k| k * 222).collect();
        let quiet_from = times.last().copied().unwrap_or(0) + 1000;
        times.extend(titan_feedback(2).iter().map(|t| t + quiet_from));
        let _ = run(&mut m, &times);
        assert!(!m.is_polling());
        // And the ordinary feedback after it is read at once again.
        let (reads, worst) = run(&mut m, &titan_feedback(2));
        assert_eq!(reads, titan_feedback(2).len());
        assert!(worst <= 10);
    }

    #[test]
    fn a_backlog_is_read_on_without_pause() {
        let mut m = RxModeration::new(Duration::from_millis(2), us(0));
        for i in 0..10_000 {
            assert!(!m.on_read(us(i), 256, true));
            assert!(!m.is_paused(us(i)));
        }
    }

    fn readable(fd: RawFd) -> bool {
        use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
        // SAFETY: test-local descriptor, alive for the call.
        let fd = unsafe { BorrowedFd::borrow_raw(fd) };
        let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
        poll(&mut fds, PollTimeout::ZERO).unwrap() == 1
    }

    #[test]
    fn the_gate_is_readable_only_while_open_and_a_frame_is_pending() {
        use std::io::{Read, Write};
        let (mut bus, mut chassis) = std::os::unix::net::UnixStream::pair().unwrap();
        bus.set_nonblocking(true).unwrap();
        let mut gate = RxGate::new().unwrap();
        gate.watch(Some(bus.as_raw_fd())).unwrap();
        assert!(gate.is_open());
        assert!(!readable(gate.raw_fd()));
        chassis.write_all(b"frame").unwrap();
        assert!(readable(gate.raw_fd()));
        gate.set_open(false).unwrap();
        assert!(!readable(gate.raw_fd()));
        // Frames queue meanwhile, nothing is lost.
        chassis.write_all(b"frame").unwrap();
        gate.set_open(true).unwrap();
        assert!(readable(gate.raw_fd()));
        let mut buf = [0u8; 16];
        assert_eq!(bus.read(&mut buf).unwrap(), 10);
        assert!(!readable(gate.raw_fd()));
        // A new session: the old descriptor leaves the set, the new one joins.
        let (bus2, mut chassis2) = std::os::unix::net::UnixStream::pair().unwrap();
        gate.watch(Some(bus2.as_raw_fd())).unwrap();
        chassis.write_all(b"old").unwrap();
        assert!(!readable(gate.raw_fd()));
        chassis2.write_all(b"new").unwrap();
        assert!(readable(gate.raw_fd()));
    }
}
