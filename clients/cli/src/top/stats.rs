//! The dashboard's arithmetic, pure: frames, states and mux decisions go in with the time they
//! were seen; rates, drops and latency percentiles come out. Tests feed hand-made samples.
//!
//! Every stamp is `CLOCK_MONOTONIC` ns, the clock of chassisd's stamps, so each latency below is
//! one subtraction of two readings of the same clock:
//!
//! * **frame→state**: a state sample that a frame changed carries that frame's read time
//!   (`ChassisState::stamp_ns`); its age when this process wakes up with it is bus read → decode
//!   → publish → shared memory → this subscriber awake. Only samples whose content differs
//!   from the previous one seen and whose stamp is newer count: chassisd publishes those the
//!   moment the frame is decoded. The others are its refreshes on the 20 ms tick (frames came
//!   but changed nothing), published up to a tick after their stamp. (A subscriber sees only
//!   the newest of a burst of samples — one per frame of a 50 Hz burst of ten — so consecutive
//!   `seq` cannot be required.)
//! * **state age**: the same age for every sample, refreshes included — how old the newest
//!   state is when a subscriber gets it.
//! * **decision→wire**: a mux decision that changed the output (`MuxStatus::stamp_ns`, its
//!   predecessor `seq - 1` had another output) → the first motion frame written to the bus at or
//!   after it (its `BusFrame::stamp_ns` on the tap). Both stamps are chassisd's.
//! * **request→decision**: for those decisions that took in a new request of the winner (its
//!   `last_seq` moved), that request's age (`active_age_ms`: the client's stamp, or its arrival
//!   if earlier, to the decision), whole milliseconds as the mux reports them. Smoothing steps
//!   between two requests are left out: their age is only the time since the last request.
//!   request→wire is the sum of the two.

use std::collections::{HashMap, VecDeque};

use chassis_client::{BusFrame, ChassisState, FrameDirection, FrameKind, MuxStatus};
use chassis_protocols::frame_json::{BoxedCodec, FrameJson};
use chassis_protocols::{CanFrame, Profile};

/// Frame rates are counted over this sliding window.
pub const WINDOW_NS: u64 = 1_000_000_000;
/// Latency percentiles are over this many latest samples.
pub const SAMPLES: usize = 1000;
/// TX stamps kept for matching decisions.
const TX_KEEP_NS: u64 = 2_000_000_000;
/// A decision with no motion frame this long after it is given up.
const MATCH_GIVE_UP_NS: u64 = 500_000_000;

/// What a rate is counted per.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum FrameKey {
    /// A CAN id (the standard and extended spaces apart).
    Can { id: u32, extended: bool },
    /// A frame the robot's codec found in the serial stream, by its command id.
    Serial { command: u32 },
    /// A chunk of a serial stream no codec reads (no description of the robot yet).
    Bytes,
    /// A chunk of the GPS receiver's NMEA stream.
    Gps,
}

impl FrameKey {
    /// `0x211`, `0x18FF0001`, `0x10`, `bytes`, `gps`.
    pub fn text(&self) -> String {
        match self {
            FrameKey::Can {
                id,
                extended: false,
            } => format!("0x{id:03X}"),
            FrameKey::Can { id, extended: true } => format!("0x{id:08X}"),
            FrameKey::Serial { command } => format!("0x{command:02X}"),
            FrameKey::Bytes => "bytes".into(),
            FrameKey::Gps => "gps".into(),
        }
    }
}

/// The counts of one key in one direction.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyStats {
    pub direction: u8,
    pub key: FrameKey,
    /// The frame's name in the robot's protocol, when it decodes.
    pub name: Option<String>,
    /// Frames in the window.
    pub in_window: u64,
    /// Frames since the dashboard started.
    pub total: u64,
}

impl KeyStats {
    /// Frames per second over the window.
    pub fn rate_hz(&self) -> f64 {
        self.in_window as f64 * 1e9 / WINDOW_NS as f64
    }
}

/// The frame name (`motion_command`) and command id of a decoded frame.
fn name_and_id(json: &FrameJson) -> (Option<String>, Option<u32>) {
    let name = json
        .get("frame")
        .and_then(|v| v.as_str())
        .map(str::to_string);
    let id = json
        .get("id")
        .and_then(|v| v.as_str())
        .and_then(|text| u32::from_str_radix(text.trim_start_matches("0x"), 16).ok());
    (name, id)
}

/// Names frames by decoding them with the robot's codec (its family's, `Family::codec` of the
/// described robot's profile): one per direction, as a serial robot's stream parser keeps the
/// part of a frame that ends in the next read.
#[derive(Debug, Default)]
struct Namer {
    rx: Option<BoxedCodec>,
    tx: Option<BoxedCodec>,
    /// The robot is on a serial line (its codec reads a byte stream).
    serial: bool,
}

impl Namer {
    fn of(profile: Option<&Profile>) -> Self {
        let codec = || profile.map(|p| p.codec());
        Self {
            rx: codec(),
            tx: codec(),
            serial: profile.is_some_and(|p| !p.robot().is_can()),
        }
    }

    fn can(&self, frame: &BusFrame) -> Option<String> {
        let can = CanFrame::try_from(frame).ok()?;
        let json = self.rx.as_ref()?.decode_can(&can).ok()?;
        name_and_id(&json).0
    }

    /// The codec that finds frames in a serial stream read in `direction` (`None` for a robot
    /// on a CAN bus, or none described).
    fn serial_codec(&mut self, direction: u8) -> Option<&mut BoxedCodec> {
        if !self.serial {
            return None;
        }
        if direction == FrameDirection::TX {
            self.tx.as_mut()
        } else {
            self.rx.as_mut()
        }
    }
}

/// Frame rates per key and direction, tap drops, and the recent motion frames written.
#[derive(Debug)]
pub struct BusStats {
    namer: Namer,
    keys: Vec<KeyStats>,
    index: HashMap<(u8, FrameKey), usize>,
    /// (stamp, index into `keys`) of every counted frame in the window, oldest first.
    window: VecDeque<(u64, usize)>,
    last_seq: Option<u64>,
    /// Frames the tap lost between two reads (gaps in `BusFrame::seq`).
    pub dropped: u64,
    /// Frames read from the tap.
    pub frames: u64,
    /// Candidate serial frames the dashboard's own stream parsers rejected.
    pub serial_rejects: u64,
    /// Stamps of motion frames written (TX), oldest first.
    motion_tx: VecDeque<u64>,
}

impl BusStats {
    /// `profile` is the described robot's (`described::profile_of`): its codec names the
    /// frames and finds them in a serial stream. `None` counts CAN ids and serial chunks
    /// unnamed.
    pub fn new(profile: Option<&Profile>) -> Self {
        Self {
            namer: Namer::of(profile),
            keys: Vec::new(),
            index: HashMap::new(),
            window: VecDeque::new(),
            last_seq: None,
            dropped: 0,
            frames: 0,
            serial_rejects: 0,
            motion_tx: VecDeque::new(),
        }
    }

    /// Names frames from now on with another profile's codec (a newer description: protocol
    /// detection decided, another robot behind the name): names given so far are forgotten.
    pub fn set_profile(&mut self, profile: Option<&Profile>) {
        self.namer = Namer::of(profile);
        for key in &mut self.keys {
            key.name = None;
        }
    }

    /// Counts one frame of the tap.
    pub fn on_frame(&mut self, frame: &BusFrame) {
        self.frames += 1;
        if let Some(last) = self.last_seq
            && frame.seq > last + 1
        {
            self.dropped += frame.seq - last - 1;
        }
        if self.last_seq.is_none_or(|last| frame.seq > last) {
            self.last_seq = Some(frame.seq);
        }
        match frame.kind {
            FrameKind::CAN => {
                let key = FrameKey::Can {
                    id: frame.can_id,
                    extended: frame.flags & BusFrame::EXTENDED_ID != 0,
                };
                let slot = self.slot(frame.direction, key);
                if self.keys[slot].name.is_none() {
                    self.keys[slot].name = self.namer.can(frame);
                }
                self.count(slot, frame.stamp_ns, frame.direction);
            }
            FrameKind::GPS => {
                let slot = self.slot(frame.direction, FrameKey::Gps);
                self.keys[slot].name = Some("nmea".into());
                self.count(slot, frame.stamp_ns, frame.direction);
            }
            _ => {
                let Some(codec) = self.namer.serial_codec(frame.direction) else {
                    let slot = self.slot(frame.direction, FrameKey::Bytes);
                    self.count(slot, frame.stamp_ns, frame.direction);
                    return;
                };
                for item in codec.push_serial(frame.payload()) {
                    match item {
                        Ok(json) => {
                            let (name, id) = name_and_id(&json);
                            let Some(command) = id else {
                                continue;
                            };
                            let slot = self.slot(frame.direction, FrameKey::Serial { command });
                            self.keys[slot].name = name;
                            self.count(slot, frame.stamp_ns, frame.direction);
                        }
                        Err(_) => self.serial_rejects += 1,
                    }
                }
            }
        }
    }

    fn slot(&mut self, direction: u8, key: FrameKey) -> usize {
        if let Some(&i) = self.index.get(&(direction, key)) {
            return i;
        }
        self.keys.push(KeyStats {
            direction,
            key,
            name: None,
            in_window: 0,
            total: 0,
        });
        let i = self.keys.len() - 1;
        self.index.insert((direction, key), i);
        i
    }

    fn count(&mut self, slot: usize, stamp_ns: u64, direction: u8) {
        let stats = &mut self.keys[slot];
        stats.total += 1;
        stats.in_window += 1;
        let motion = matches!(stats.name.as_deref(), Some("motion_command" | "velocity"));
        self.window.push_back((stamp_ns, slot));
        if direction == FrameDirection::TX && motion {
            self.motion_tx.push_back(stamp_ns);
            while self
                .motion_tx
                .front()
                .is_some_and(|&t| t.saturating_add(TX_KEEP_NS) < stamp_ns)
            {
                self.motion_tx.pop_front();
            }
        }
    }

    /// Drops frames older than the window before `now_ns`.
    pub fn expire(&mut self, now_ns: u64) {
        let start = now_ns.saturating_sub(WINDOW_NS);
        while let Some(&(stamp, slot)) = self.window.front() {
            if stamp > start {
                break;
            }
            self.window.pop_front();
            if let Some(k) = self.keys.get_mut(slot) {
                k.in_window = k.in_window.saturating_sub(1);
            }
        }
    }

    /// Every key seen, RX first, then by key.
    pub fn keys(&self) -> Vec<KeyStats> {
        let mut keys = self.keys.clone();
        keys.sort_by_key(|k| (k.direction, k.key));
        keys
    }

    /// The first motion frame written at or after `stamp_ns`.
    fn first_motion_tx_after(&self, stamp_ns: u64) -> Option<u64> {
        self.motion_tx.iter().copied().find(|&t| t >= stamp_ns)
    }
}

/// Percentiles of one measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Summary {
    pub count: usize,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub max_ns: u64,
}

/// The latest [`SAMPLES`] values of one measurement, ns.
#[derive(Debug, Clone, Default)]
pub struct Samples {
    values: VecDeque<u64>,
    /// Samples since start (the window holds the latest).
    pub seen: u64,
}

impl Samples {
    pub fn push(&mut self, value_ns: u64) {
        if self.values.len() == SAMPLES {
            self.values.pop_front();
        }
        self.values.push_back(value_ns);
        self.seen += 1;
    }

    /// Nearest-rank p50 and p99 and the largest value; `None` before the first sample.
    pub fn summary(&self) -> Option<Summary> {
        if self.values.is_empty() {
            return None;
        }
        let mut sorted: Vec<u64> = self.values.iter().copied().collect();
        sorted.sort_unstable();
        let rank = |p: f64| {
            let n = sorted.len();
            // Nearest rank: ceil(p·n), 1-based.
            let r = ((p * n as f64).ceil() as usize).clamp(1, n);
            sorted[r - 1]
        };
        Some(Summary {
            count: sorted.len(),
            p50_ns: rank(0.50),
            p99_ns: rank(0.99),
            max_ns: sorted[sorted.len() - 1],
        })
    }
}

/// A mux decision that changed the output, waiting for its motion frame.
#[derive(Debug, Clone, Copy)]
struct Decision {
    stamp_ns: u64,
    /// The winner's request age, when this decision took in a new request from it.
    request_age_ms: Option<u32>,
}

/// The latency measurements; see the module docs for what each one means.
#[derive(Debug, Default)]
pub struct Latency {
    pub frame_to_state: Samples,
    pub state_age: Samples,
    pub decision_to_wire: Samples,
    pub request_to_decision: Samples,
    /// Output changes for which no motion frame followed within 500 ms.
    pub unmatched: u64,
    last_state: Option<ChassisState>,
    last_mux: Option<MuxStatus>,
    pending: VecDeque<Decision>,
}

impl Latency {
    /// A state sample this process woke up with at `now_ns`. `measure` is false for samples
    /// found waiting while the dashboard was busy (their age would include its own delay).
    pub fn on_state(&mut self, now_ns: u64, state: &ChassisState, measure: bool) {
        if let Some(last) = &self.last_state
            && state.seq <= last.seq
        {
            return;
        }
        if measure && state.stamp_ns != 0 {
            let age = now_ns.saturating_sub(state.stamp_ns);
            self.state_age.push(age);
            let frame_made_it = self
                .last_state
                .as_ref()
                .is_some_and(|last| state.stamp_ns > last.stamp_ns && state.body() != last.body());
            if frame_made_it {
                self.frame_to_state.push(age);
            }
        }
        self.last_state = Some(*state);
    }

    /// A mux status, in the order published.
    pub fn on_mux(&mut self, mux: &MuxStatus) {
        if let Some(last) = &self.last_mux {
            if mux.seq <= last.seq {
                return;
            }
            if mux.seq == last.seq + 1 && mux.output != last.output {
                // A decision that took in a new request of the winner (not a smoothing step
                // between two of its requests, whose age is only the time since the last one).
                let new_request = mux.active().is_some_and(|winner| {
                    last.sources()
                        .get(usize::from(mux.active_source))
                        .is_none_or(|before| before.last_seq != winner.last_seq)
                });
                self.pending.push_back(Decision {
                    stamp_ns: mux.stamp_ns,
                    request_age_ms: (new_request && mux.active_age_ms != u32::MAX)
                        .then_some(mux.active_age_ms),
                });
            }
        }
        self.last_mux = Some(*mux);
    }

    /// Pairs waiting decisions with the motion frames written after them.
    pub fn resolve(&mut self, now_ns: u64, bus: &BusStats) {
        while let Some(decision) = self.pending.front().copied() {
            match bus.first_motion_tx_after(decision.stamp_ns) {
                Some(tx) => {
                    self.decision_to_wire.push(tx - decision.stamp_ns);
                    if let Some(age_ms) = decision.request_age_ms {
                        self.request_to_decision.push(u64::from(age_ms) * 1_000_000);
                    }
                }
                None if now_ns.saturating_sub(decision.stamp_ns) > MATCH_GIVE_UP_NS => {
                    self.unmatched += 1;
                }
                None => break,
            }
            self.pending.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use chassis_client::Velocity;
    use chassis_protocols::xbot::XbotProfile;
    use chassis_protocols::{Direction, RobotKind, Timestamp, WireItem, xbot};

    const MS: u64 = 1_000_000;

    fn defaults(kind: RobotKind) -> Profile {
        kind.entry().defaults()
    }

    fn titan() -> BusStats {
        BusStats::new(Some(&defaults(RobotKind::Titan)))
    }

    /// Every robot's driver against its simulated firmware, the wire seen as the tap shows it:
    /// every frame of the exchange, in both directions, gets its name from the robot's codec,
    /// and the motion frames are told apart (decision→wire needs them).
    #[test]
    fn every_robots_frames_get_names() {
        for kind in RobotKind::ALL {
            let entry = kind.entry();
            let profile = entry.defaults();
            let mut pair = entry.simulated_pair(&profile, Timestamp::from_millis(1_000));
            pair.record = true;
            pair.run_for(Duration::from_secs(2));
            pair.set_command(Velocity::twist(0.3, 0.0).unwrap());
            pair.run_for(Duration::from_secs(1));
            let mut stats = BusStats::new(Some(&profile));
            for (seq, record) in pair.log().iter().enumerate() {
                let mut frame = BusFrame {
                    seq: seq as u64 + 1,
                    stamp_ns: record.at.as_nanos(),
                    direction: match record.direction {
                        Direction::ToChassis => FrameDirection::TX,
                        Direction::FromChassis => FrameDirection::RX,
                    },
                    ..BusFrame::default()
                };
                match &record.item {
                    WireItem::Can(can) => {
                        frame.kind = FrameKind::CAN;
                        frame.can_id = can.id();
                        if can.is_extended() {
                            frame.flags |= BusFrame::EXTENDED_ID;
                        }
                        frame.set_payload(can.data());
                    }
                    WireItem::Bytes(bytes) => {
                        frame.kind = FrameKind::SERIAL;
                        frame.set_payload(bytes);
                    }
                }
                stats.on_frame(&frame);
            }
            let keys = stats.keys();
            assert!(keys.len() >= 3, "{kind}: {keys:?}");
            let unnamed: Vec<String> = keys
                .iter()
                .filter(|k| k.name.is_none())
                .map(|k| k.key.text())
                .collect();
            assert!(unnamed.is_empty(), "{kind}: unnamed {unnamed:?}");
            assert_eq!(stats.serial_rejects, 0, "{kind}");
            assert!(
                stats.first_motion_tx_after(0).is_some(),
                "{kind}: no motion frame among {keys:?}"
            );
        }
    }

    #[test]
    fn a_newer_profile_renames_the_frames_and_none_counts_them_unnamed() {
        let mut stats = BusStats::new(None);
        stats.on_frame(&can(1, 0, 0x111, FrameDirection::TX));
        let mut chunk = BusFrame {
            seq: 2,
            kind: FrameKind::SERIAL,
            ..BusFrame::default()
        };
        chunk.set_payload(&[0xAA, 0x55]);
        stats.on_frame(&chunk);
        let keys = stats.keys();
        assert!(keys.iter().all(|k| k.name.is_none()), "{keys:?}");
        assert!(keys.iter().any(|k| k.key == FrameKey::Bytes));
        stats.set_profile(Some(&defaults(RobotKind::Titan)));
        stats.on_frame(&can(3, 1, 0x111, FrameDirection::TX));
        let named = stats.keys().into_iter().find(|k| k.key.text() == "0x111");
        assert_eq!(
            named.and_then(|k| k.name).as_deref(),
            Some("motion_command")
        );
    }

    fn can(seq: u64, stamp_ms: u64, id: u32, direction: u8) -> BusFrame {
        let mut f = BusFrame {
            seq,
            stamp_ns: stamp_ms * MS,
            can_id: id,
            direction,
            kind: FrameKind::CAN,
            ..BusFrame::default()
        };
        f.set_payload(&[0; 8]);
        f
    }

    fn rate(stats: &BusStats, direction: u8, text: &str) -> f64 {
        stats
            .keys()
            .iter()
            .find(|k| k.direction == direction && k.key.text() == text)
            .map_or(0.0, KeyStats::rate_hz)
    }

    #[test]
    fn rates_per_id_and_direction_count_the_last_second() {
        let mut stats = titan();
        let mut seq = 0;
        // 0x211 at 50 Hz and 0x221 at 100 Hz received, 0x111 at 50 Hz sent, for 2 s.
        for ms in 0..2000u64 {
            if ms % 20 == 0 {
                seq += 1;
                stats.on_frame(&can(seq, ms, 0x211, FrameDirection::RX));
                seq += 1;
                stats.on_frame(&can(seq, ms, 0x111, FrameDirection::TX));
            }
            if ms % 10 == 0 {
                seq += 1;
                stats.on_frame(&can(seq, ms, 0x221, FrameDirection::RX));
            }
        }
        // The window is (now - 1 s, now].
        stats.expire(1990 * MS);
        assert_eq!(rate(&stats, FrameDirection::RX, "0x211"), 50.0);
        assert_eq!(rate(&stats, FrameDirection::RX, "0x221"), 100.0);
        assert_eq!(rate(&stats, FrameDirection::TX, "0x111"), 50.0);
        assert_eq!(rate(&stats, FrameDirection::RX, "0x111"), 0.0);
        let keys = stats.keys();
        assert_eq!(keys.len(), 3);
        assert_eq!(keys[0].direction, FrameDirection::RX, "RX first");
        assert_eq!(keys[0].total, 100);
        assert_eq!(stats.dropped, 0);
        // Half a second later with nothing new: half the window is left.
        stats.expire(2490 * MS);
        assert_eq!(rate(&stats, FrameDirection::RX, "0x211"), 25.0);
        stats.expire(3000 * MS);
        assert_eq!(rate(&stats, FrameDirection::RX, "0x221"), 0.0);
    }

    #[test]
    fn sequence_gaps_count_as_tap_drops() {
        let mut stats = titan();
        for seq in [5, 6, 7, 10, 11, 20] {
            stats.on_frame(&can(seq, seq, 0x211, FrameDirection::RX));
        }
        assert_eq!(stats.dropped, 2 + 8);
        assert_eq!(stats.frames, 6);
    }

    #[test]
    fn titan_frames_are_named_by_decoding_them() {
        let mut stats = titan();
        stats.on_frame(&can(1, 0, 0x111, FrameDirection::TX));
        stats.on_frame(&can(2, 0, 0x7AB, FrameDirection::RX));
        let keys = stats.keys();
        let name = |text: &str| {
            keys.iter()
                .find(|k| k.key.text() == text)
                .and_then(|k| k.name.clone())
        };
        assert_eq!(name("0x111").as_deref(), Some("motion_command"));
        assert_eq!(name("0x7AB"), None);
    }

    #[test]
    fn xbot_frames_are_found_across_serial_chunks() {
        let profile = XbotProfile::default();
        let frame = xbot::Frame::Velocity(xbot::VelocityCommand::default())
            .encode(&profile)
            .unwrap();
        let mut stats = BusStats::new(Some(&defaults(RobotKind::Xbot)));
        let mut bytes = frame.clone();
        bytes.extend_from_slice(&frame);
        let (a, b) = bytes.split_at(frame.len() + 2);
        for (seq, chunk) in [a, b].into_iter().enumerate() {
            let mut f = BusFrame {
                seq: seq as u64 + 1,
                stamp_ns: seq as u64 * MS,
                direction: FrameDirection::TX,
                kind: FrameKind::SERIAL,
                ..BusFrame::default()
            };
            f.set_payload(chunk);
            stats.on_frame(&f);
        }
        let keys = stats.keys();
        assert_eq!(keys.len(), 1);
        assert_eq!(keys[0].key, FrameKey::Serial { command: 0x03 });
        assert_eq!(keys[0].name.as_deref(), Some("velocity"));
        assert_eq!(keys[0].total, 2);
        assert_eq!(stats.first_motion_tx_after(0), Some(0));
        assert_eq!(stats.first_motion_tx_after(1), Some(MS));
    }

    #[test]
    fn percentiles_are_nearest_rank_over_the_latest_samples() {
        let mut s = Samples::default();
        assert_eq!(s.summary(), None);
        for v in 1..=100 {
            s.push(v);
        }
        assert_eq!(
            s.summary(),
            Some(Summary {
                count: 100,
                p50_ns: 50,
                p99_ns: 99,
                max_ns: 100
            })
        );
        s.push(7);
        assert_eq!(s.summary().map(|x| x.count), Some(101));
        for _ in 0..SAMPLES {
            s.push(3);
        }
        let full = s.summary().unwrap();
        assert_eq!((full.count, full.p99_ns, full.max_ns), (SAMPLES, 3, 3));
        assert_eq!(s.seen, 101 + SAMPLES as u64);
    }

    fn state(seq: u64, stamp_ms: u64, speed: f32) -> ChassisState {
        let mut s = ChassisState {
            seq,
            stamp_ns: stamp_ms * MS,
            ..ChassisState::default()
        };
        s.motion.linear_mps = speed;
        s
    }

    #[test]
    fn frame_to_state_counts_only_samples_a_new_frame_changed() {
        let mut l = Latency::default();
        l.on_state(100 * MS, &state(1, 99, 0.0), true);
        // Changed by a new frame: counted.
        l.on_state(201 * MS, &state(2, 200, 0.1), true);
        // A refresh (same content, same stamp, on the tick): state age only.
        l.on_state(218 * MS, &state(3, 200, 0.1), true);
        // A refresh after frames that changed nothing (same content, newer stamp).
        l.on_state(240 * MS, &state(4, 222, 0.1), true);
        // Changed by a new frame, after samples this subscriber never saw: counted.
        l.on_state(303 * MS, &state(9, 300, 0.2), true);
        // Found waiting while busy: nothing measured.
        l.on_state(450 * MS, &state(10, 400, 0.3), false);
        // Old or repeated samples are ignored.
        l.on_state(460 * MS, &state(10, 400, 0.3), true);
        let f = l.frame_to_state.summary().unwrap();
        assert_eq!((f.count, f.p50_ns, f.max_ns), (2, MS, 3 * MS));
        let a = l.state_age.summary().unwrap();
        assert_eq!((a.count, a.max_ns), (5, 18 * MS));
    }

    #[test]
    fn a_changed_decision_is_matched_with_the_next_motion_frame() {
        let mut bus = titan();
        let mut l = Latency::default();
        let mut mux = MuxStatus {
            seq: 1,
            stamp_ns: 100 * MS,
            ..MuxStatus::default()
        };
        mux.source_count = 1;
        mux.active_source = 0;
        mux.sources[0].last_seq = 1;
        l.on_mux(&mux);
        // Output changes at 120 ms with the winner's new request, 2 ms old.
        mux.seq = 2;
        mux.stamp_ns = 120 * MS;
        mux.output.linear_x_mps = 0.2;
        mux.active_age_ms = 2;
        mux.sources[0].last_seq = 2;
        l.on_mux(&mux);
        // A periodic status without a change.
        mux.seq = 3;
        mux.stamp_ns = 220 * MS;
        l.on_mux(&mux);
        // The tap shows motion frames at 100 ms (before) and at 120.4 ms (after).
        bus.on_frame(&can(1, 100, 0x111, FrameDirection::TX));
        l.resolve(121 * MS, &bus);
        assert_eq!(l.decision_to_wire.seen, 0, "waits for its frame");
        let mut f = can(2, 0, 0x111, FrameDirection::TX);
        f.stamp_ns = 120 * MS + 400_000;
        bus.on_frame(&f);
        // Sent, but not a motion frame: ignored.
        bus.on_frame(&can(3, 120, 0x421, FrameDirection::TX));
        l.resolve(125 * MS, &bus);
        let d = l.decision_to_wire.summary().unwrap();
        assert_eq!((d.count, d.max_ns), (1, 400_000));
        let r = l.request_to_decision.summary().unwrap();
        assert_eq!((r.count, r.max_ns), (1, 2 * MS));
        // A smoothing step with no new request: decision→wire only.
        mux.seq = 4;
        mux.stamp_ns = 240 * MS;
        mux.output.linear_x_mps = 0.3;
        mux.active_age_ms = 38;
        l.on_mux(&mux);
        let mut f = can(4, 0, 0x111, FrameDirection::TX);
        f.stamp_ns = 240 * MS + 200_000;
        bus.on_frame(&f);
        l.resolve(245 * MS, &bus);
        assert_eq!(l.decision_to_wire.seen, 2);
        assert_eq!(l.request_to_decision.seen, 1);
        // A change that no frame follows is given up.
        mux.seq = 5;
        mux.stamp_ns = 300 * MS;
        mux.output.linear_x_mps = 0.0;
        l.on_mux(&mux);
        l.resolve(900 * MS, &bus);
        assert_eq!(l.unmatched, 1);
        assert_eq!(l.decision_to_wire.seen, 2);
    }
}
