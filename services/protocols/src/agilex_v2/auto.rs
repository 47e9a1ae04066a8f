//! A SCOUT MINI, SCOUT 2.0 or BUNKER of either firmware: listen first, then drive it in the
//! protocol it speaks.
//!
//! [`AutoDriver`] transmits nothing until the [`Detector`] has decided (`PROTOCOLS-V2` §4.3); then
//! it builds the V1 driver ([`V1Driver`]) or the V2 one ([`V2Driver`]) at that instant and
//! hands everything to it, so not one frame of the wrong protocol is ever sent. Without a decision
//! by the deadline (or with both kinds of evidence) it sets [`LinkFlags::CHASSIS_SILENT`], logs
//! what it heard and listens again. After the link is lost for longer than the deadline the
//! decision stands (a firmware update needs a power cycle, which the service's restart covers).

use std::collections::VecDeque;
use std::time::Duration;

use chassis_interfaces::{ChassisState, LinkFlags, Velocity, WireProtocol};
use serde::{Deserialize, Serialize};

use super::detect::{DetectSettings, Detection, Detector};
use super::{V2Driver, V2Profile};
use crate::agilex_v1::V1Driver;
use crate::agilex_v1::V1Profile;
use crate::command::Command;
use crate::driver::{
    BoxedDriver, ControlOutcome, Driver, DriverConfig, DriverEvent, Level, Rx, WireItem,
};
use crate::family::Profile;
use crate::kind::RobotKind;
use crate::profile::Protocol;
use crate::time::Timestamp;

/// A driver for a robot that may speak V1 or V2 (SCOUT MINI, SCOUT 2.0, BUNKER) that detects
/// the protocol before sending anything.
#[derive(Serialize, Deserialize)]
pub struct AutoDriver {
    robot: RobotKind,
    v1: V1Profile,
    v2: V2Profile,
    detect: DetectSettings,
    config: DriverConfig,
    detector: Detector,
    #[serde(with = "detected")]
    inner: Option<(Protocol, Box<dyn Driver + Send>)>,
    #[serde(with = "crate::snapshot::raw")]
    state: ChassisState,
    events: VecDeque<DriverEvent>,
    command: Velocity,
    bus_down: bool,
}

impl std::fmt::Debug for AutoDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AutoDriver")
            .field("protocol", &self.protocol())
            .field("detector", &self.detector)
            .finish_non_exhaustive()
    }
}

impl AutoDriver {
    /// The listening driver of a robot whose profile in one protocol is `profile` (its
    /// detection settings apply) and in the other `other`: `None` unless one is V1, the other V2.
    pub(crate) fn boxed(
        profile: &Profile,
        other: &Profile,
        config: &DriverConfig,
        now: Timestamp,
    ) -> Option<BoxedDriver> {
        let (v1, v2, detect) = match (profile.get::<V1Profile>(), profile.get::<V2Profile>()) {
            (Some(v1), _) => (v1, other.get::<V2Profile>()?, DetectSettings::from(v1)),
            (_, Some(v2)) => (other.get::<V1Profile>()?, v2, DetectSettings::from(v2)),
            _ => return None,
        };
        let driver = Self::new(v1.clone(), v2.clone(), detect, config.clone(), now);
        Some(Box::new(driver))
    }

    /// Listening from `now` as `detect` says, for the robot of `v1` (its V1 `model`; `v2` is
    /// that robot's V2 profile).
    pub fn new(
        v1: V1Profile,
        v2: V2Profile,
        detect: DetectSettings,
        config: DriverConfig,
        now: Timestamp,
    ) -> Self {
        let detector = Self::detector(detect, now);
        let robot = v1.model.robot();
        Self {
            robot,
            v1,
            v2,
            detect,
            config,
            detector,
            inner: None,
            state: {
                let mut state = ChassisState {
                    robot: robot.id(),
                    ..ChassisState::default()
                };
                state.system.wire_protocol = WireProtocol::DETECTING;
                state
            },
            events: VecDeque::new(),
            command: Velocity::ZERO,
            bus_down: false,
        }
    }

    fn detector(detect: DetectSettings, now: Timestamp) -> Detector {
        Detector::new(
            now,
            Duration::from_millis(detect.timeout_ms),
            detect.min_frames,
        )
    }

    /// The protocol in use, once detected.
    pub fn protocol(&self) -> Option<Protocol> {
        self.inner.as_ref().map(|(p, _)| *p)
    }

    /// The robot as the logs name it: `SCOUT MINI`, `SCOUT`, `BUNKER`.
    fn shown_name(&self) -> String {
        self.robot.name().replace('-', " ").to_uppercase()
    }

    fn notice(&mut self, level: Level, message: String) {
        self.events
            .push_back(DriverEvent::Notice { level, message });
    }

    fn check(&mut self, now: Timestamp) {
        if self.inner.is_some() {
            return;
        }
        match self.detector.poll(now) {
            Detection::Listening => {}
            Detection::Decided(protocol) => {
                let mut driver: Box<dyn Driver + Send> = match protocol {
                    Protocol::V1 => {
                        Box::new(V1Driver::new(self.v1.clone(), self.config.clone(), now))
                    }
                    Protocol::V2 => {
                        Box::new(V2Driver::new(self.v2.clone(), self.config.clone(), now))
                    }
                };
                driver.set_command(now, &self.command);
                if self.bus_down {
                    driver.set_bus_down(now, true);
                }
                self.notice(
                    Level::Info,
                    format!(
                        "{} speaks protocol {protocol}: driving it as such",
                        self.shown_name()
                    ),
                );
                self.inner = Some((protocol, driver));
            }
            outcome @ (Detection::Silent { .. } | Detection::Conflicting { .. }) => {
                self.state.link_flags |= LinkFlags::CHASSIS_SILENT;
                self.notice(
                    Level::Warn,
                    format!(
                        "{} protocol not detected within {} ms: {}; listening again",
                        self.shown_name(),
                        self.detect.timeout_ms,
                        outcome.describe()
                    ),
                );
                self.detector = Self::detector(self.detect, now);
            }
        }
    }
}

/// The driver of the protocol detected, in a snapshot: the protocol and the driver's own.
mod detected {
    use serde::de::Error as _;
    use serde::ser::Error as _;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::agilex_v1::V1Driver;
    use crate::agilex_v2::V2Driver;
    use crate::driver::Driver;
    use crate::profile::Protocol;
    use crate::snapshot::load;

    type Detected = Option<(Protocol, Box<dyn Driver + Send>)>;

    pub fn serialize<S: Serializer>(detected: &Detected, serializer: S) -> Result<S::Ok, S::Error> {
        let saved = match detected {
            Some((protocol, driver)) => {
                Some((*protocol, driver.snapshot().map_err(S::Error::custom)?))
            }
            None => None,
        };
        saved.serialize(serializer)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Detected, D::Error> {
        let Some((protocol, bytes)) = Option::<(Protocol, Vec<u8>)>::deserialize(deserializer)?
        else {
            return Ok(None);
        };
        let driver: Box<dyn Driver + Send> = match protocol {
            Protocol::V1 => Box::new(load::<V1Driver>(&bytes).map_err(D::Error::custom)?),
            Protocol::V2 => Box::new(load::<V2Driver>(&bytes).map_err(D::Error::custom)?),
        };
        Ok(Some((protocol, driver)))
    }
}

impl Driver for AutoDriver {
    crate::snapshot::whole_driver!();

    fn robot(&self) -> RobotKind {
        self.robot
    }

    fn handle_rx(&mut self, now: Timestamp, rx: Rx<'_>) {
        if let Some((_, driver)) = &mut self.inner {
            driver.handle_rx(now, rx);
            return;
        }
        if let Rx::Can(frame) = rx {
            self.state.link.rx_frames += 1;
            self.detector.handle_rx(frame);
        }
        self.check(now);
    }

    fn set_command(&mut self, now: Timestamp, command: &Velocity) {
        self.command = *command;
        if let Some((_, driver)) = &mut self.inner {
            driver.set_command(now, command);
        }
    }

    fn control(&mut self, now: Timestamp, command: &Command) -> ControlOutcome {
        match &mut self.inner {
            Some((_, driver)) => driver.control(now, command),
            None => ControlOutcome::Refused(format!(
                "the {}'s protocol (V1 or V2) is not detected yet: nothing is sent",
                self.shown_name()
            )),
        }
    }

    fn handle_timeout(&mut self, now: Timestamp) {
        match &mut self.inner {
            Some((_, driver)) => driver.handle_timeout(now),
            None => self.check(now),
        }
    }

    fn poll_transmit(&mut self, now: Timestamp) -> Option<WireItem> {
        self.inner
            .as_mut()
            .and_then(|(_, driver)| driver.poll_transmit(now))
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        match &self.inner {
            Some((_, driver)) => driver.poll_timeout(),
            None => Some(self.detector.deadline()),
        }
    }

    fn poll_event(&mut self) -> Option<DriverEvent> {
        if let Some(event) = self.events.pop_front() {
            return Some(event);
        }
        self.inner
            .as_mut()
            .and_then(|(_, driver)| driver.poll_event())
    }

    fn state(&self) -> &ChassisState {
        match &self.inner {
            Some((_, driver)) => driver.state(),
            None => &self.state,
        }
    }

    fn set_bus_down(&mut self, now: Timestamp, down: bool) {
        self.bus_down = down;
        match &mut self.inner {
            Some((_, driver)) => driver.set_bus_down(now, down),
            None => {
                if down {
                    self.state.link_flags |= LinkFlags::BUS_DOWN;
                } else {
                    self.state.link_flags &= !LinkFlags::BUS_DOWN;
                    self.detector = Self::detector(self.detect, now);
                }
            }
        }
    }

    fn shutdown(&mut self, now: Timestamp) {
        if let Some((_, driver)) = &mut self.inner {
            driver.shutdown(now);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Direction;
    use crate::agilex_v1::V1Model;
    use crate::agilex_v1::V1Sim;
    use crate::agilex_v2::{V2Model, V2Sim};
    use crate::firmware::Firmware;
    use crate::pair::Pair;
    use chassis_interfaces::ControlMode;

    const T0: Timestamp = Timestamp::from_millis(1000);

    fn auto() -> AutoDriver {
        let v1 = V1Profile::default();
        let detect = DetectSettings::from(&v1);
        AutoDriver::new(
            v1,
            V2Profile::for_model(V2Model::ScoutMini),
            detect,
            DriverConfig::default(),
            T0,
        )
    }

    fn forward() -> Velocity {
        Velocity::twist(0.5, 0.0).unwrap()
    }

    /// Drives `pair` forward and returns the ids the driver sent, and when it first sent.
    fn drive<F: Firmware>(pair: &mut Pair<AutoDriver, F>) -> (Vec<u32>, Timestamp) {
        pair.record = true;
        pair.set_command(forward());
        pair.run_for(Duration::from_millis(3000));
        let sent: Vec<_> = pair
            .log()
            .iter()
            .filter(|r| r.direction == Direction::ToChassis)
            .filter_map(|r| r.item.as_can().map(|f| (r.at, f.id())))
            .collect();
        let first = sent.first().map(|(t, _)| *t).unwrap_or(T0);
        (sent.into_iter().map(|(_, id)| id).collect(), first)
    }

    /// The robots with V1 and V2 firmware, each with its V1 and V2 profile.
    fn robots() -> [(V1Profile, V2Profile); 3] {
        [
            (
                V1Profile::default(),
                V2Profile::for_model(V2Model::ScoutMini),
            ),
            (
                V1Profile::for_model(V1Model::Scout),
                V2Profile::for_model(V2Model::Scout),
            ),
            (
                V1Profile::for_model(V1Model::Bunker),
                V2Profile::for_model(V2Model::Bunker),
            ),
        ]
    }

    #[test]
    fn a_v1_chassis_is_driven_in_v1_and_never_sees_a_v2_frame() {
        for (v1, v2) in robots() {
            let robot = v1.model.robot();
            let detect = DetectSettings::from(&v2);
            let driver = AutoDriver::new(v1.clone(), v2, detect, DriverConfig::default(), T0);
            assert_eq!(driver.robot(), robot);
            assert_eq!(driver.state().robot, robot.id());
            let mut pair = Pair::new(driver, V1Sim::new(v1, T0), T0);
            let (ids, first) = drive(&mut pair);
            assert_eq!(pair.driver.protocol(), Some(Protocol::V1), "{robot}");
            assert_eq!(pair.driver.state().system.wire_protocol, WireProtocol::V1);
            assert_eq!(pair.driver.state().robot, robot.id(), "{robot}");
            assert!(ids.iter().all(|id| matches!(id, 0x130 | 0x140)), "{ids:x?}");
            assert!(first > T0, "{robot}: sent before listening");
            assert!(
                (pair.firmware.truth().linear_mps - 0.5).abs() < 0.06,
                "{robot}: {:?}",
                pair.firmware.truth()
            );
            assert_eq!(pair.firmware.truth().decode_errors, 0, "{robot}");
            let events = pair.take_events();
            let notices = crate::pair::notices(&events);
            let shown = robot.name().replace('-', " ").to_uppercase();
            assert!(
                notices
                    .iter()
                    .any(|(_, m)| *m == format!("{shown} speaks protocol v1: driving it as such")),
                "{notices:?}"
            );
        }
    }

    #[test]
    fn a_v2_chassis_is_driven_in_v2_and_never_sees_a_v1_frame() {
        for (v1, v2) in robots() {
            let robot = v1.model.robot();
            let detect = DetectSettings::from(&v2);
            let driver = AutoDriver::new(v1, v2.clone(), detect, DriverConfig::default(), T0);
            let mut pair = Pair::new(driver, V2Sim::new(v2, T0), T0);
            let (ids, first) = drive(&mut pair);
            assert_eq!(pair.driver.protocol(), Some(Protocol::V2), "{robot}");
            assert_eq!(pair.driver.state().system.wire_protocol, WireProtocol::V2);
            assert_eq!(pair.driver.state().robot, robot.id(), "{robot}");
            assert!(
                ids.iter()
                    .all(|id| matches!(id, 0x111 | 0x421 | 0x411 | 0x4A1)),
                "{ids:x?}"
            );
            // Three V2 frames arrive within the first 20 ms feedback slot (100 ms where 0x211
            // comes every 100 ms: 0x221 is the evidence); nothing went out before.
            assert!(
                first > T0 && first <= T0 + Duration::from_millis(60),
                "{robot}: {first:?}"
            );
            assert_eq!(pair.firmware.truth().control_mode, ControlMode::COMMAND);
            assert!((pair.firmware.truth().linear_mps - 0.5).abs() < 1e-3);
            assert_eq!(pair.firmware.truth().decode_errors, 0, "{robot}");
        }
    }

    #[test]
    fn a_silent_bus_is_reported_and_retried_and_nothing_is_sent() {
        let mut d = auto();
        assert_eq!(d.state().system.wire_protocol, WireProtocol::DETECTING);
        let deadline = d.poll_timeout().unwrap();
        assert_eq!(deadline, T0 + Duration::from_millis(5000));
        d.handle_timeout(deadline);
        assert_ne!(d.state().link_flags & LinkFlags::CHASSIS_SILENT, 0);
        let Some(DriverEvent::Notice { level, message }) = d.poll_event() else {
            panic!("no notice");
        };
        assert_eq!(level, Level::Warn);
        assert!(message.contains("nothing heard"), "{message}");
        assert_eq!(d.poll_transmit(deadline), None);
        assert_eq!(
            d.poll_timeout(),
            Some(deadline + Duration::from_millis(5000))
        );
        assert!(matches!(
            d.control(deadline, &Command::Mode { take_control: true }),
            ControlOutcome::Refused(_)
        ));
    }
}
