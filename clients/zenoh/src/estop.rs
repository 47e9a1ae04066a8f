//! The operator's e-stop, kept asked by a mirror until the robot's chassisd has it.
//!
//! A mirror forwards each `control` request to its robot and hands back chassisd's answer. An
//! `estop` LOCK_ENGAGE is more than a request: the operator wants that robot stopped, also when
//! its link is down at that moment. So the mirror keeps it *pending* from the moment it forwards
//! it until chassisd answers (OK: the lock is held by chassisd, written to its lock file and
//! latched across its restarts), and while pending it delivers the request again as soon as the
//! robot is heard again (its state flows, its liveliness token is back) and at least every
//! [`RETRY_NS`]. An explicit release of the e-stop through the mirror ends the pending state, a
//! refusal by chassisd too (asking again would be refused again). No other request is kept.
//!
//! **How it shows.** The mirror publishes its robot's `MuxStatus` in this computer's iceoryx2;
//! while an e-stop is pending and the robot's `estop` lock is not held, the lock is published
//! with `held = 0` — the robot's truth — and `holder = LockStatus::HOLDER_OPERATOR` — the
//! operator's control request asked for it ([`marked`]). chassisd publishes a free lock with
//! `HOLDER_NONE`, so that combination is the mirror's alone: `chassis fleet` shows it as
//! `pending`, and `chassis control --all estop` names such a robot `NOT STOPPED … pending`.
//! Every view that asks whether a lock is held reads `held`, and still sees it free.
//!
//! Pure: time and the link's news are parameters.

use chassis_client::{ControlKind, ControlRequest, MuxStatus};

/// The lock the fleet e-stop engages (and a lock request without a name names).
pub const ESTOP: &str = "estop";
/// While pending, the e-stop is delivered again at least this often (when no delivery waits for
/// its answer), ns.
pub const RETRY_NS: u64 = 1_000_000_000;
/// Deliveries waiting for an answer at once, at most.
pub const MAX_IN_FLIGHT: usize = 4;

/// What a control request asks, as far as the kept e-stop is concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Asked {
    EstopEngage,
    EstopRelease,
    Other,
}

/// Sorts a control request (chassisd reads a lock request without a name as `estop`).
pub fn classify(request: &ControlRequest) -> Asked {
    let estop = matches!(request.name(), "" | ESTOP);
    match request.kind {
        ControlKind::LOCK_ENGAGE if estop => Asked::EstopEngage,
        ControlKind::LOCK_RELEASE if estop => Asked::EstopRelease,
        _ => Asked::Other,
    }
}

/// The robot's mux as the mirror publishes it: with an e-stop pending and the robot's `estop`
/// lock not held, the lock's holder is the operator while `held` stays 0.
pub fn marked(mut mux: MuxStatus, pending: bool) -> MuxStatus {
    if pending && let Some(lock) = mux.lock_index(ESTOP).and_then(|i| mux.locks.get_mut(i)) {
        lock.mark_pending();
    }
    mux
}

/// An e-stop the mirror keeps asked.
#[derive(Debug, Clone, Copy)]
pub struct Pending {
    pub request: ControlRequest,
    /// When the operator asked for it (this computer's clock), ns.
    pub since_ns: u64,
    /// When it was last sent to the robot, ns.
    pub tried_ns: u64,
    /// Deliveries sent, the first forward included.
    pub tries: u32,
    /// The robot failed to answer it at least once (it was reported kept pending).
    pub unanswered: bool,
}

/// The pending e-stop of one robot, if any.
#[derive(Debug, Clone, Default)]
pub struct Keeper {
    pending: Option<Pending>,
    /// The last count of "the robot is heard again" seen by [`Keeper::due`].
    heard: u64,
}

impl Keeper {
    /// `heard`: the count of "the robot is heard again" now.
    pub fn new(heard: u64) -> Self {
        Self {
            pending: None,
            heard,
        }
    }

    pub fn pending(&self) -> Option<&Pending> {
        self.pending.as_ref()
    }

    /// The operator asks for the e-stop at `now` (about to be forwarded): kept until chassisd
    /// answers. True when it was not pending before.
    pub fn asked(&mut self, request: ControlRequest, now_ns: u64) -> bool {
        match &mut self.pending {
            Some(p) => {
                p.request = request;
                p.tried_ns = now_ns;
                p.tries = p.tries.saturating_add(1);
                false
            }
            None => {
                self.pending = Some(Pending {
                    request,
                    since_ns: now_ns,
                    tried_ns: now_ns,
                    tries: 1,
                    unanswered: false,
                });
                true
            }
        }
    }

    /// The robot did not answer a delivery (no link, no reply in time, its robot side could not
    /// reach chassisd): still pending. True the first time for this e-stop (to be reported).
    pub fn unanswered(&mut self) -> bool {
        match &mut self.pending {
            Some(p) if !p.unanswered => {
                p.unanswered = true;
                true
            }
            _ => false,
        }
    }

    /// chassisd answered (OK or a refusal): no longer kept. The e-stop that was pending, if any.
    pub fn answered(&mut self) -> Option<Pending> {
        self.pending.take()
    }

    /// The operator released the e-stop: no longer kept. True if one was pending.
    pub fn released(&mut self) -> bool {
        self.pending.take().is_some()
    }

    /// At `now`, with `heard` the count of "the robot is heard again" and `in_flight`
    /// deliveries waiting for their answer: the request to deliver again now, if it is time —
    /// at once when the robot was heard again since the last call, else once nothing waits and
    /// [`RETRY_NS`] passed since the last delivery.
    pub fn due(&mut self, now_ns: u64, heard: u64, in_flight: usize) -> Option<ControlRequest> {
        let heard_again = std::mem::replace(&mut self.heard, heard) != heard;
        let p = self.pending.as_mut()?;
        let retry = in_flight == 0 && now_ns.saturating_sub(p.tried_ns) >= RETRY_NS;
        if !(retry || heard_again && in_flight < MAX_IN_FLIGHT) {
            return None;
        }
        p.tried_ns = now_ns;
        p.tries = p.tries.saturating_add(1);
        Some(p.request)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chassis_client::LockStatus;

    const MS: u64 = 1_000_000;

    fn engage(name: &str) -> ControlRequest {
        ControlRequest::new(ControlKind::LOCK_ENGAGE).with_name(name)
    }

    #[test]
    fn only_the_estop_lock_requests_count() {
        assert_eq!(classify(&engage("estop")), Asked::EstopEngage);
        assert_eq!(classify(&engage("")), Asked::EstopEngage);
        assert_eq!(classify(&engage("dock")), Asked::Other);
        let release = ControlRequest::new(ControlKind::LOCK_RELEASE);
        assert_eq!(classify(&release), Asked::EstopRelease);
        assert_eq!(
            classify(&release.with_name("dock")),
            Asked::Other,
            "another lock"
        );
        let brake = ControlRequest::new(ControlKind::BRAKE).with_name("estop");
        assert_eq!(classify(&brake), Asked::Other);
        // Bytes that are no text, and kinds no one knows: nothing kept, nothing broken.
        let mut odd = ControlRequest::new(0xEE);
        odd.name = [0xFF; chassis_client::NAME_LEN];
        assert_eq!(classify(&odd), Asked::Other);
        odd.kind = ControlKind::LOCK_ENGAGE;
        assert_eq!(classify(&odd), Asked::EstopEngage, "no valid name: estop");
    }

    #[test]
    fn a_pending_estop_marks_a_free_estop_lock_only() {
        let mut mux = MuxStatus {
            lock_count: 2,
            ..MuxStatus::default()
        };
        mux.locks[0].set_name("dock");
        mux.locks[0].holder = LockStatus::HOLDER_NONE;
        mux.locks[1].set_name("estop");
        mux.locks[1].holder = LockStatus::HOLDER_NONE;
        assert_eq!(marked(mux, false).locks[1].holder, LockStatus::HOLDER_NONE);
        let shown = marked(mux, true);
        assert_eq!(shown.locks[1].holder, LockStatus::HOLDER_OPERATOR);
        assert_eq!(shown.locks[1].held, 0, "still free: the robot's truth");
        assert_eq!(shown.locks[0].holder, LockStatus::HOLDER_NONE);
        // Held by the robot: shown as the robot says.
        mux.locks[1].held = 1;
        mux.locks[1].holder = 0;
        assert_eq!(marked(mux, true).locks[1].holder, 0);
        // No estop lock, or a lock count past the table: left alone.
        let none = MuxStatus {
            lock_count: 200,
            ..MuxStatus::default()
        };
        assert_eq!(marked(none, true).locks, none.locks);
    }

    #[test]
    fn an_unanswered_estop_is_delivered_again_when_the_robot_is_heard_and_until_answered() {
        let mut k = Keeper::new(3);
        assert_eq!(k.due(0, 3, 0), None, "nothing pending");
        assert!(k.asked(engage("estop"), 100 * MS));
        assert!(!k.asked(engage("estop"), 110 * MS), "already pending");
        assert!(k.unanswered(), "reported once");
        assert!(!k.unanswered());
        // Not yet: nothing heard, the retry period not over.
        assert_eq!(k.due(500 * MS, 3, 0), None);
        // The robot is heard again: at once, even with a delivery still waiting.
        assert!(k.due(600 * MS, 4, 1).is_some());
        assert_eq!(k.due(610 * MS, 4, 1), None, "one per news");
        // Every retry period while nothing waits for an answer.
        assert_eq!(k.due(1_500 * MS, 4, 1), None, "one waits");
        assert_eq!(k.due(1_500 * MS, 4, 0), None, "not a period yet");
        assert!(k.due(1_600 * MS, 4, 0).is_some());
        // A flood of news does not pile up deliveries.
        assert_eq!(k.due(1_700 * MS, 5, MAX_IN_FLIGHT), None);
        let kept = k.answered().expect("it was pending");
        assert_eq!(kept.since_ns, 100 * MS);
        assert_eq!(kept.tries, 4);
        assert!(kept.unanswered);
        assert_eq!(k.due(5_000 * MS, 9, 0), None, "answered: kept no more");
    }

    #[test]
    fn a_release_ends_a_pending_estop() {
        let mut k = Keeper::new(0);
        assert!(!k.released(), "nothing to release");
        k.asked(engage(""), 0);
        assert!(k.released());
        assert!(k.pending().is_none());
        assert_eq!(k.due(10_000 * MS, 1, 0), None);
        assert!(!k.unanswered());
    }
}
