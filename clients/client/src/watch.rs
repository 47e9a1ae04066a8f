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

use chassis_interfaces::{ChassisState, FaultFlags, LinkFlags, MuxStatus, ZeroReason};

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
    mux: Option<(u8, u8, u8)>,
}

impl Watch {
    /// Log lines for the changes `state` brings.
    pub fn state(&mut self, state: &ChassisState) -> Vec<(Severity, String)> {
        let mut out = Vec::new();
        let faults = state.system.fault_flags;
        let before = self.faults.replace(faults).unwrap_or(0);
        let raised = faults & !before;
        let cleared = before & !faults;
        if raised != 0 {
            out.push((
                Severity::Error,
                format!("fault: {}", FaultFlags::names(raised).join(", ")),
            ));
        }
        if cleared != 0 {
            out.push((
                Severity::Info,
                format!("fault cleared: {}", FaultFlags::names(cleared).join(", ")),
            ));
        }
        let link = state.link_flags;
        let before = self.link.replace(link).unwrap_or(0);
        let raised = link & !before;
        let lowered = before & !link;
        if raised != 0 {
            out.push((
                Severity::Warning,
                format!("link: {}", LinkFlags::names(raised).join(", ")),
            ));
        }
        if lowered != 0 {
            out.push((
                Severity::Info,
                format!("link: {} no more", LinkFlags::names(lowered).join(", ")),
            ));
        }
        out
    }

    /// A log line when the mux's winner, its reason for zero or the number of held locks
    /// changes.
    pub fn mux(&mut self, mux: &MuxStatus) -> Option<(Severity, String)> {
        let locks = held_locks(mux);
        let key = (
            mux.active_source,
            mux.zero_reason,
            u8::try_from(locks.len()).unwrap_or(u8::MAX),
        );
        if self.mux.replace(key) == Some(key) {
            return None;
        }
        let mut text = match mux.active() {
            Some(source) => format!(
                "mux: {} drives (priority {})",
                source.name(),
                mux.active_priority
            ),
            None => format!("mux: zero ({})", ZeroReason::name(mux.zero_reason)),
        };
        if !locks.is_empty() {
            text.push_str(&format!("; locks held: {}", locks.join(", ")));
        }
        let severity = if mux.active().is_some() {
            Severity::Info
        } else {
            Severity::Warning
        };
        Some((severity, text))
    }
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
    fn the_mux_logs_once_per_change_of_its_decision() {
        let mut watch = Watch::default();
        let mux = MuxStatus::default();
        let (severity, text) = watch.mux(&mux).unwrap();
        assert_eq!(severity, Severity::Warning, "{text}");
        assert!(text.starts_with("mux: zero"), "{text}");
        assert_eq!(watch.mux(&mux), None, "unchanged: no line");
    }
}
