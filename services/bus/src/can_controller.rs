//! What a CAN controller says about itself, and what the service makes of it: the controller's
//! error state (ISO 11898-1: error-active, error-warning, error-passive, bus-off), its error
//! counters, and the counts `ChassisState::link` carries.
//!
//! Pure: the SocketCAN backend (`bus::socketcan`) turns the kernel's error frames into
//! [`ControllerReport`]s, the engine hands them to a [`Controller`] with the frames around them
//! in the order they were read, and publishes what the controller holds. Nothing here reads a
//! clock or a device.
//!
//! | report | state after it | counted in `LinkStats` |
//! | --- | --- | --- |
//! | bus-off (`CAN_ERR_BUSOFF`) | bus-off | `can_bus_off` (on entry) |
//! | restarted (`CAN_ERR_RESTARTED`) | error-active | `can_restarts` |
//! | controller problem: active (`CAN_ERR_CRTL_ACTIVE`) | error-active | |
//! | controller problem: rx/tx passive | error-passive | `can_error_passive` (on entry) |
//! | controller problem: rx/tx warning | error-warning | |
//! | error counters only (`CAN_ERR_CNT`) | from the counters (≥ 128 passive, ≥ 96 warning) | |
//! | protocol violation, bus error | unchanged | `can_bus_errors` |
//! | no ACK | unchanged | `can_no_ack` |
//! | controller problem: rx/tx overflow (frames lost in the controller) | unchanged | |
//!
//! Every error frame counts in `can_error_frames`. A data frame heard while the controller is
//! believed bus-off means it is on the bus again (a restart whose report was lost, or a driver
//! that sends none): the state becomes unknown until the next report. A bus reopened (the
//! interface taken down and up restarts the controller) starts from unknown too.

use chassis_interfaces::{ChassisState, ControllerState, LinkFlags};
use serde::{Deserialize, Serialize};

/// One report of the CAN controller: a SocketCAN error frame decoded, or the state the
/// interface had when the bus was opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ControllerReport {
    /// The state the report says the controller is in ([`ControllerState`]); `UNKNOWN` when it
    /// says none.
    pub state: u8,
    /// The controller was restarted after a bus-off.
    pub restarted: bool,
    /// A protocol violation or bus error was seen (bit, stuff, form, CRC…).
    pub bus_error: bool,
    /// A frame sent was not acknowledged by any node.
    pub no_ack: bool,
    /// The controller's receive (or transmit) buffer overflowed: frames were lost in it, not on
    /// the bus (the computer did not read fast enough).
    pub overflow: bool,
    /// The transmit and receive error counters, when the report carries them.
    pub counters: Option<(u8, u8)>,
    /// The interface's `restart-ms` when the report was made (asked on a bus-off), `None` when
    /// unknown; 0 means nothing restarts the controller.
    pub restart_ms: Option<u32>,
    /// An error frame; false for the state read from the interface when the bus was opened.
    pub from_frame: bool,
}

impl ControllerReport {
    /// The state the error counters stand for (ISO 11898-1 thresholds, as the kernel's
    /// `CAN_ERROR_WARNING_THRESHOLD` and `CAN_ERROR_PASSIVE_THRESHOLD`).
    pub fn state_of_counters(tx: u8, rx: u8) -> u8 {
        match tx.max(rx) {
            128.. => ControllerState::ERROR_PASSIVE,
            96.. => ControllerState::ERROR_WARNING,
            _ => ControllerState::ERROR_ACTIVE,
        }
    }

    /// The state after this report: what it says, else what its counters stand for.
    fn new_state(&self) -> Option<u8> {
        if self.state != ControllerState::UNKNOWN {
            return Some(self.state);
        }
        if self.restarted {
            return Some(ControllerState::ERROR_ACTIVE);
        }
        self.counters
            .map(|(tx, rx)| ControllerReport::state_of_counters(tx, rx))
    }
}

/// What one report (or one data frame) changed, for the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Change {
    /// The state it left and the state it entered, when it changed.
    pub state: Option<(u8, u8)>,
    pub restarted: bool,
    pub bus_error: bool,
    pub no_ack: bool,
    pub overflow: bool,
}

impl Change {
    pub fn is_empty(&self) -> bool {
        *self == Change::default()
    }
}

/// The controller as the service knows it: its state, counters and what it reported so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Controller {
    state: u8,
    counters: (u8, u8),
    error_frames: u64,
    error_passive: u64,
    bus_off: u64,
    restarts: u64,
    bus_errors: u64,
    no_ack: u64,
    restart_ms: Option<u32>,
}

impl Controller {
    /// Takes one report in: the new state, the counts. Returns what changed.
    pub fn apply(&mut self, report: &ControllerReport) -> Change {
        if report.from_frame {
            self.error_frames += 1;
        }
        if let Some(counters) = report.counters {
            self.counters = counters;
        }
        if report.restart_ms.is_some() {
            self.restart_ms = report.restart_ms;
        }
        let mut change = Change {
            restarted: report.restarted,
            bus_error: report.bus_error,
            no_ack: report.no_ack,
            overflow: report.overflow,
            state: None,
        };
        if report.restarted {
            self.restarts += 1;
        }
        if report.bus_error {
            self.bus_errors += 1;
        }
        if report.no_ack {
            self.no_ack += 1;
        }
        if let Some(state) = report.new_state() {
            change.state = self.enter(state);
        }
        change
    }

    /// A data frame was heard: a controller believed bus-off is on the bus again.
    pub fn heard_frame(&mut self) -> Change {
        Change {
            state: if self.state == ControllerState::BUS_OFF {
                self.enter(ControllerState::UNKNOWN)
            } else {
                None
            },
            ..Change::default()
        }
    }

    /// The bus was opened again (the interface went down and up, restarting the controller):
    /// its state is unknown until it reports.
    pub fn reopened(&mut self) -> Change {
        Change {
            state: self.enter(ControllerState::UNKNOWN),
            ..Change::default()
        }
    }

    fn enter(&mut self, state: u8) -> Option<(u8, u8)> {
        let from = self.state;
        if from == state {
            return None;
        }
        self.state = state;
        match state {
            ControllerState::BUS_OFF => self.bus_off += 1,
            ControllerState::ERROR_PASSIVE => self.error_passive += 1,
            _ => {}
        }
        Some((from, state))
    }

    /// [`ControllerState`] now.
    pub fn state(&self) -> u8 {
        self.state
    }

    /// The interface's `restart-ms` as last reported.
    pub fn restart_ms(&self) -> Option<u32> {
        self.restart_ms
    }

    /// Writes the state, the counts and the link flags into a state sample.
    pub fn write(&self, state: &mut ChassisState) {
        let link = &mut state.link;
        link.can_error_frames = self.error_frames;
        link.can_error_passive = self.error_passive;
        link.can_bus_off = self.bus_off;
        link.can_restarts = self.restarts;
        link.can_bus_errors = self.bus_errors;
        link.can_no_ack = self.no_ack;
        link.can_state = self.state;
        (link.can_tx_error_count, link.can_rx_error_count) = self.counters;
        state.link_flags &= !(LinkFlags::CAN_BUS_OFF | LinkFlags::CAN_ERROR_PASSIVE);
        state.link_flags |= match self.state {
            ControllerState::BUS_OFF => LinkFlags::CAN_BUS_OFF,
            ControllerState::ERROR_PASSIVE => LinkFlags::CAN_ERROR_PASSIVE,
            _ => 0,
        };
    }
}

/// What to do about a bus-off of interface `iface` whose `restart-ms` is `restart_ms`: the
/// log's second half.
pub fn bus_off_fix(iface: &str, restart_ms: Option<u32>) -> String {
    let now = format!(
        "restart it now with `sudo ip link set {iface} down && sudo ip link set {iface} up`"
    );
    let later = format!(
        "so that the kernel restarts it by itself next time, set restart-ms while the interface \
         is down (`sudo ip link set {iface} down && sudo ip link set {iface} type can \
         restart-ms 100 && sudo ip link set {iface} up`, or `RestartSec=100ms` in its \
         systemd-networkd .network file; docs/HARDWARE.md)"
    );
    match restart_ms {
        Some(ms) if ms > 0 => {
            format!("the kernel restarts the controller in {ms} ms (restart-ms); waiting")
        }
        Some(_) => format!("nothing restarts the controller (restart-ms is 0): {now}; {later}"),
        None => format!(
            "if the kernel does not restart the controller (restart-ms unset), {now}; {later}"
        ),
    }
}

/// Why a controller goes error-passive or bus-off, for the log.
pub const BUS_TROUBLE: &str = "too many errors on the bus: CAN H and L swapped or loose, \
     termination missing (120 Ω at each end: about 60 Ω between H and L with the power off), \
     another bit rate, or no other node powered to acknowledge";

#[cfg(test)]
mod tests {
    use super::*;

    fn state_of(c: &Controller) -> ChassisState {
        let mut s = ChassisState::default();
        c.write(&mut s);
        s
    }

    fn report(state: u8) -> ControllerReport {
        ControllerReport {
            state,
            from_frame: true,
            ..ControllerReport::default()
        }
    }

    #[test]
    fn a_bus_off_then_a_restart_counts_once_each_and_raises_then_clears_the_flag() {
        let mut c = Controller::default();
        let change = c.apply(&report(ControllerState::BUS_OFF));
        assert_eq!(
            change.state,
            Some((ControllerState::UNKNOWN, ControllerState::BUS_OFF))
        );
        // The same state reported again is no new bus-off.
        assert!(c.apply(&report(ControllerState::BUS_OFF)).state.is_none());
        let s = state_of(&c);
        assert!(s.has_link_flag(LinkFlags::CAN_BUS_OFF));
        assert_eq!((s.link.can_bus_off, s.link.can_error_frames), (1, 2));
        assert_eq!(s.link.can_state, ControllerState::BUS_OFF);

        let restarted = ControllerReport {
            restarted: true,
            from_frame: true,
            ..ControllerReport::default()
        };
        let change = c.apply(&restarted);
        assert!(change.restarted);
        assert_eq!(
            change.state,
            Some((ControllerState::BUS_OFF, ControllerState::ERROR_ACTIVE))
        );
        let s = state_of(&c);
        assert_eq!(s.link_flags & LinkFlags::CAN_BUS_OFF, 0);
        assert_eq!((s.link.can_restarts, s.link.can_bus_off), (1, 1));
    }

    #[test]
    fn error_passive_is_counted_on_entry_and_the_flag_follows_the_state() {
        let mut c = Controller::default();
        c.apply(&report(ControllerState::ERROR_WARNING));
        c.apply(&report(ControllerState::ERROR_PASSIVE));
        c.apply(&report(ControllerState::ERROR_PASSIVE));
        assert!(state_of(&c).has_link_flag(LinkFlags::CAN_ERROR_PASSIVE));
        c.apply(&report(ControllerState::ERROR_WARNING));
        c.apply(&report(ControllerState::ERROR_PASSIVE));
        let s = state_of(&c);
        assert_eq!(s.link.can_error_passive, 2);
        c.apply(&report(ControllerState::ERROR_ACTIVE));
        let s = state_of(&c);
        assert_eq!(
            s.link_flags & (LinkFlags::CAN_ERROR_PASSIVE | LinkFlags::CAN_BUS_OFF),
            0
        );
    }

    #[test]
    fn counters_alone_give_the_state_by_the_iso_thresholds() {
        for ((tx, rx), want) in [
            ((0, 0), ControllerState::ERROR_ACTIVE),
            ((95, 0), ControllerState::ERROR_ACTIVE),
            ((96, 0), ControllerState::ERROR_WARNING),
            ((0, 127), ControllerState::ERROR_WARNING),
            ((128, 3), ControllerState::ERROR_PASSIVE),
            ((0, 255), ControllerState::ERROR_PASSIVE),
        ] {
            let mut c = Controller::default();
            c.apply(&ControllerReport {
                counters: Some((tx, rx)),
                from_frame: true,
                ..ControllerReport::default()
            });
            assert_eq!(c.state(), want, "tx {tx} rx {rx}");
            let s = state_of(&c);
            assert_eq!(
                (s.link.can_tx_error_count, s.link.can_rx_error_count),
                (tx, rx)
            );
        }
    }

    #[test]
    fn bus_errors_and_missing_acks_are_counted_without_changing_the_state() {
        let mut c = Controller::default();
        c.apply(&report(ControllerState::ERROR_ACTIVE));
        for _ in 0..3 {
            let change = c.apply(&ControllerReport {
                bus_error: true,
                no_ack: true,
                from_frame: true,
                ..ControllerReport::default()
            });
            assert!(change.state.is_none() && change.bus_error && change.no_ack);
        }
        let s = state_of(&c);
        assert_eq!((s.link.can_bus_errors, s.link.can_no_ack), (3, 3));
        assert_eq!(s.link.can_error_frames, 4);
        assert_eq!(c.state(), ControllerState::ERROR_ACTIVE);
    }

    #[test]
    fn a_frame_heard_while_bus_off_or_a_reopened_bus_makes_the_state_unknown() {
        let mut c = Controller::default();
        assert!(c.heard_frame().is_empty());
        c.apply(&report(ControllerState::BUS_OFF));
        assert_eq!(
            c.heard_frame().state,
            Some((ControllerState::BUS_OFF, ControllerState::UNKNOWN))
        );
        assert_eq!(state_of(&c).link_flags & LinkFlags::CAN_BUS_OFF, 0);
        c.apply(&report(ControllerState::ERROR_PASSIVE));
        c.reopened();
        assert_eq!(c.state(), ControllerState::UNKNOWN);
        // The state read at open is no error frame.
        c.apply(&ControllerReport {
            state: ControllerState::ERROR_ACTIVE,
            ..ControllerReport::default()
        });
        assert_eq!(state_of(&c).link.can_error_frames, 2);
    }

    #[test]
    fn the_fix_for_a_bus_off_depends_on_restart_ms() {
        let auto = bus_off_fix("can0", Some(100));
        assert!(auto.contains("in 100 ms"), "{auto}");
        assert!(!auto.contains("ip link"), "{auto}");
        let manual = bus_off_fix("can0", Some(0));
        assert!(
            manual.contains("sudo ip link set can0 down && sudo ip link set can0 up"),
            "{manual}"
        );
        assert!(manual.contains("restart-ms 100"), "{manual}");
        assert!(bus_off_fix("can0", None).contains("restart-ms unset"));
    }
}
