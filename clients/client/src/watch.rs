//! What changed worth a log line between two samples: faults appearing and clearing, link flags
//! (bus down, RC authority, …) raised and lowered, and the mux's winner, reason for zero or held
//! locks changing. One wording for every view that logs a robot (the live Foxglove view,
//! `chassis record`'s `/log`).
//!
//! ```
//! use chassis_client::watch::{Severity, Watch};
//! use chassis_client::{ChassisState, FaultFlags};
//!
//! let mut watch = Watch::default();
//! let mut state = ChassisState::default();
//! assert!(watch.state(&state).is_empty());
//! state.system.fault_flags = FaultFlags::from_name("battery_over_voltage").unwrap_or(0);
//! assert_eq!(
//!     watch.state(&state),
//!     [(Severity::Error, "fault: battery_over_voltage".to_string())]
//! );
//! ```

use std::ops::{BitAnd, Not};

use chassis_interfaces::{ChassisState, FaultFlags, LinkFlags, MuxStatus};

/// How much a change matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Something cleared or a source took over.
    Info,
    /// A link flag raised, the mux commanding zero.
    Warning,
    /// A fault appeared.
    Error,
}

/// Remembers the last sample's faults, link flags and mux decision to log only changes.
#[derive(Debug, Default)]
pub struct Watch {
    faults: Option<u64>,
    link: Option<u32>,
    mux: Option<(u8, u8, u8, u8, u8)>,
}

impl Watch {
    /// Log lines for the changes `state` brings.
    pub fn state(&mut self, state: &ChassisState) -> Vec<(Severity, String)> {
        let (raised, cleared) = edges(&mut self.faults, state.system.fault_flags);
        let (up, down) = edges(&mut self.link, state.link_flags);
        let fault = FaultFlags::names;
        let link = LinkFlags::names;
        [
            named(raised, fault).map(|n| (Severity::Error, format!("fault: {n}"))),
            named(cleared, fault).map(|n| (Severity::Info, format!("fault cleared: {n}"))),
            named(up, link).map(|n| (Severity::Warning, format!("link: {n}"))),
            named(down, link).map(|n| (Severity::Info, format!("link: {n} no more"))),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// A log line when the mux's winner, its reason for zero or the number of held locks
    /// changes.
    pub fn mux(&mut self, mux: &MuxStatus) -> Option<(Severity, String)> {
        let locks = held_locks(mux);
        let key = (
            mux.active_source,
            mux.zero_reason,
            mux.stop,
            mux.awaiting_source,
            u8::try_from(locks.len()).unwrap_or(u8::MAX),
        );
        if self.mux.replace(key) == Some(key) {
            return None;
        }
        let text = format!("mux: {}", mux.why());
        let severity = if mux.active().is_some() {
            Severity::Info
        } else {
            Severity::Warning
        };
        Some((severity, text))
    }
}

/// The bits `now` raises and the bits it lowers against the value `last` holds (none yet: all
/// clear), which `now` then replaces.
fn edges<T>(last: &mut Option<T>, now: T) -> (T, T)
where
    T: Copy + Default + BitAnd<Output = T> + Not<Output = T>,
{
    let before = last.replace(now).unwrap_or_default();
    (now & !before, before & !now)
}

/// `names` of the bits set in `bits`, joined, if any is set.
fn named<T: Copy + Default + PartialEq>(
    bits: T,
    names: fn(T) -> Vec<&'static str>,
) -> Option<String> {
    (bits != T::default()).then(|| names(bits).join(", "))
}

/// Names of the locks held.
pub fn held_locks(mux: &MuxStatus) -> Vec<String> {
    mux.locks()
        .iter()
        .filter(|l| l.held != 0)
        .map(|l| l.name().to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_log_when_they_appear_and_when_they_clear() {
        let mut watch = Watch::default();
        let mut s = ChassisState::default();
        assert!(watch.state(&s).is_empty());
        s.system.fault_flags = FaultFlags::from_name("battery_over_voltage").unwrap();
        let lines = watch.state(&s);
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].0, Severity::Error);
        assert!(lines[0].1.contains("battery_over_voltage"), "{lines:?}");
        assert!(watch.state(&s).is_empty(), "unchanged: no line");
        s.system.fault_flags = 0;
        let lines = watch.state(&s);
        assert!(lines[0].1.starts_with("fault cleared"), "{lines:?}");
    }

    #[test]
    fn link_flags_log_when_they_rise_and_when_they_fall() {
        let mut watch = Watch::default();
        let mut s = ChassisState {
            link_flags: LinkFlags::BUS_DOWN,
            ..ChassisState::default()
        };
        assert_eq!(
            watch.state(&s),
            [(Severity::Warning, "link: bus_down".to_string())]
        );
        assert!(watch.state(&s).is_empty(), "unchanged: no line");
        s.link_flags = LinkFlags::CHASSIS_SILENT;
        assert_eq!(
            watch.state(&s),
            [
                (Severity::Warning, "link: chassis_silent".to_string()),
                (Severity::Info, "link: bus_down no more".to_string())
            ]
        );
    }

    #[test]
    fn the_mux_logs_once_per_change_of_its_decision() {
        let mut watch = Watch::default();
        let mux = MuxStatus::default();
        let (severity, text) = watch.mux(&mux).unwrap();
        assert_eq!(severity, Severity::Warning, "{text}");
        assert_eq!(text, "mux: stopped: none");
        assert_eq!(watch.mux(&mux), None, "unchanged: no line");
    }
}
