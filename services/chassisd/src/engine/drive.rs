//! Stops of category 0 and 1 carried out on the drive (IEC 60204-1): a held lock's
//! [`StopCategory`] while the mux outputs zero ([`crate::mux::Mux::stop_category`]).
//!
//! * Category 0: the drive is disabled at once, with the robot's own command
//!   (`Family::drive_cut`: standby on AgileX, drive power off on the XBot).
//! * Category 1: zero is commanded (the chassis brakes under its own control); once the chassis
//!   reports standstill — or after [`CUT_AFTER`] at the latest — the drive is
//!   disabled.
//! * Category 2, and every stop that is not a lock: zero is commanded and held, the drive stays
//!   powered.
//!
//! A chassis that takes commands again while its drive is cut (a V2 or TITAN firmware returns
//! to command mode by itself on the first heartbeat after it dropped to standby for a lost one,
//! say after a bus outage) is cut again, at most every 500 ms.
//!
//! When no stop of category 0 or 1 is in force any more (its lock released, or a source above
//! the lock drives), the drive is enabled again. That starts no motion: the release is a stop
//! like any other, and the mux waits for a zero from the source that would win. A robot with no
//! way to disable its drive holds zero instead and says so ([`DriveState::CANNOT_CUT`]).

use serde::{Deserialize, Serialize};
use std::time::Duration;

use chassis_interfaces::{ChassisState, ControlMode, DriveState, LinkFlags, StopCategory};
use chassis_protocols::command::Command;
use chassis_protocols::{ControlOutcome, Driver, Timestamp};
use tracing::{info, warn};

/// The longest a category-1 stop waits for the standstill before it cuts the drive.
const CUT_AFTER: Duration = Duration::from_secs(3);

/// The shortest time between two cuts of a drive that is cut already.
const RECUT_AFTER: Duration = Duration::from_millis(500);

/// Below these the chassis stands still, m/s and rad/s.
const STILL_MPS: f32 = 0.02;
const STILL_RADPS: f32 = 0.05;

/// The drive as the stops left it, and how this robot disables and enables it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct Drive {
    /// The commands that disable and enable the drive again; `None`: the robot has none (or
    /// the service does not take control of it). The configuration's: not in a snapshot.
    #[serde(skip)]
    commands: Option<(Command, Command)>,
    state: u8,
    /// When the category-1 stop in force began braking.
    braking_since: Option<Timestamp>,
    /// When the drive was last cut (the command sent again while the chassis obeys anyway).
    cut_at: Timestamp,
}

impl Drive {
    pub(super) fn new(commands: Option<(Command, Command)>) -> Self {
        Self {
            commands,
            state: DriveState::ENABLED,
            braking_since: None,
            cut_at: Timestamp::ZERO,
        }
    }

    /// Restored from a snapshot: the commands are the configuration's.
    pub(super) fn set_commands(&mut self, commands: Option<(Command, Command)>) {
        self.commands = commands;
    }

    /// The [`DriveState`] (`MuxStatus::drive`).
    pub(super) fn state(&self) -> u8 {
        self.state
    }

    /// Carries out `category` (the mux's stop in force, if any) on `driver` at `now`. Returns
    /// whether the drive's state changed.
    pub(super) fn update(
        &mut self,
        now: Timestamp,
        category: Option<u8>,
        driver: &mut impl Driver,
    ) -> bool {
        let wanted = match category {
            Some(StopCategory::CUT) => DriveState::CUT,
            Some(StopCategory::BRAKE_THEN_CUT) if self.state == DriveState::CUT => DriveState::CUT,
            Some(StopCategory::BRAKE_THEN_CUT) => {
                let since = *self.braking_since.get_or_insert(now);
                if stands(driver.state()) || now.saturating_since(since) >= CUT_AFTER {
                    DriveState::CUT
                } else {
                    DriveState::BRAKING
                }
            }
            _ => DriveState::ENABLED,
        };
        if wanted != DriveState::BRAKING {
            self.braking_since = None;
        }
        let (wanted, command) = match (&self.commands, wanted) {
            (_, DriveState::ENABLED) => (wanted, None),
            (None, _) => (DriveState::CANNOT_CUT, None),
            (Some((cut, _)), DriveState::CUT) => (wanted, Some(cut)),
            (Some(_), braking) => (braking, None),
        };
        if wanted == self.state {
            // A chassis that takes commands again while its drive is cut (a heartbeat lost
            // while the bus was down, and the firmware's automatic return after it) is cut
            // again, at most every [`RECUT_AFTER`].
            if let Some(cut) = command
                && obeys(driver.state(), cut)
                && now.saturating_since(self.cut_at) >= RECUT_AFTER
            {
                self.cut_at = now;
                let outcome = driver.control(now, cut);
                warn!(
                    "the chassis takes commands again while its drive is cut: cut again ({})",
                    outcome.message()
                );
            }
            return false;
        }
        let was = std::mem::replace(&mut self.state, wanted);
        let category = category.map_or_else(|| "?".into(), StopCategory::text);
        match (was, wanted) {
            (_, DriveState::CUT) => {
                if let Some(cut) = command {
                    self.cut_at = now;
                    let outcome = driver.control(now, cut);
                    warn!(
                        "stop category {category}: drive cut ({})",
                        outcome.message()
                    );
                }
            }
            (DriveState::CUT, _) => {
                if let Some((_, enable)) = &self.commands {
                    let outcome = driver.control(now, enable);
                    if matches!(outcome, ControlOutcome::Done(_)) {
                        info!("drive enabled again ({})", outcome.message());
                    } else {
                        warn!("drive not enabled again: {}", outcome.message());
                    }
                }
            }
            (_, DriveState::CANNOT_CUT) => warn!(
                "a stop of category {category} is in force, but this robot cannot cut its \
                 drive: zero is held instead"
            ),
            _ => {}
        }
        true
    }
}

/// Whether the chassis reports it obeys what `cut` disables (command mode; drive power on).
fn obeys(state: &ChassisState, cut: &Command) -> bool {
    match cut {
        Command::Mode { .. } => state.system.control_mode == ControlMode::COMMAND,
        Command::Power { .. } => state.system.power_enabled != 0,
        _ => false,
    }
}

/// The chassis reports standstill: fresh feedback, its speed and yaw rate below
/// [`STILL_MPS`] and [`STILL_RADPS`].
fn stands(state: &ChassisState) -> bool {
    state.link_flags & LinkFlags::CHASSIS_SILENT == 0
        && state.motion.linear_mps.abs() < STILL_MPS
        && state.motion.angular_radps.abs() < STILL_RADPS
}
