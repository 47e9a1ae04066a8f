//! systemd's service notification protocol (`sd_notify(3)`), the few lines of it chassisd needs.
//!
//! Under a `Type=notify` unit systemd passes `$NOTIFY_SOCKET` (a datagram socket: a path, or an
//! abstract name written with a leading `@`) and, with `WatchdogSec=`, `$WATCHDOG_USEC` (and
//! `$WATCHDOG_PID`). chassisd sends, one datagram each:
//!
//! * `READY=1` once its services exist and the first state is out;
//! * `WATCHDOG=1` from the event loop, four times per `WATCHDOG_USEC`: a loop that hangs (not
//!   crashes) stops the pings and systemd restarts the service;
//! * `STATUS=…` with the mux's decision whenever it changes (`systemctl status` shows it);
//! * `STOPPING=1` when it begins its orderly stop.
//!
//! Without `$NOTIFY_SOCKET` nothing is sent. A send that fails is logged at DEBUG only: the
//! service never depends on its supervisor.

use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

use chassis_interfaces::MuxStatus;
use chassis_protocols::Timestamp;
use tracing::debug;

/// Where the notifications go and when the watchdog is due.
#[derive(Debug)]
pub struct Notifier {
    socket: UnixDatagram,
    to: SocketAddr,
    /// Time between two watchdog pings (a quarter of `WATCHDOG_USEC`), when it is enabled.
    ping_every: Option<Duration>,
    last_ping: Option<Timestamp>,
    status: String,
}

impl Notifier {
    /// The notifier systemd's environment asks for (`None` when not started by systemd with
    /// `Type=notify`, or when the socket cannot be used).
    pub fn from_env() -> Option<Self> {
        let path = std::env::var_os("NOTIFY_SOCKET")?;
        let to = address(&path.to_string_lossy())?;
        let socket = match UnixDatagram::unbound() {
            Ok(socket) => socket,
            Err(e) => {
                debug!("notify socket: {e}");
                return None;
            }
        };
        let for_us = std::env::var("WATCHDOG_PID")
            .ok()
            .and_then(|pid| pid.parse::<u32>().ok())
            .is_none_or(|pid| pid == std::process::id());
        let ping_every = std::env::var("WATCHDOG_USEC")
            .ok()
            .and_then(|usec| usec.parse::<u64>().ok())
            .filter(|&usec| usec > 0 && for_us)
            .map(|usec| Duration::from_micros(usec) / 4);
        Some(Self {
            socket,
            to,
            ping_every,
            last_ping: None,
            status: String::new(),
        })
    }

    /// The watchdog's ping period, when systemd watches the service.
    pub fn ping_every(&self) -> Option<Duration> {
        self.ping_every
    }

    /// `READY=1`, with the first status.
    pub fn ready(&mut self, status: &MuxStatus) {
        self.status = describe(status);
        self.send(&format!("READY=1\nSTATUS={}", self.status));
    }

    /// From the loop, after every pass: the watchdog ping when due, the status when the
    /// decision changed.
    pub fn pass(&mut self, now: Timestamp, status: &MuxStatus) {
        if let Some(every) = self.ping_every
            && self
                .last_ping
                .is_none_or(|last| now.saturating_since(last) >= every)
        {
            self.last_ping = Some(now);
            self.send("WATCHDOG=1");
        }
        let text = describe(status);
        if text != self.status {
            self.send(&format!("STATUS={text}"));
            self.status = text;
        }
    }

    /// When the loop must wake at the latest to ping in time.
    pub fn deadline(&self) -> Option<Timestamp> {
        Some(self.last_ping? + self.ping_every?)
    }

    /// `STOPPING=1`.
    pub fn stopping(&mut self) {
        self.send("STOPPING=1\nSTATUS=stopping: commanding zero");
    }

    fn send(&self, message: &str) {
        if let Err(e) = self.socket.send_to_addr(message.as_bytes(), &self.to) {
            debug!("notify: {e}");
        }
    }
}

/// `/run/systemd/notify` or `@abstract-name`.
fn address(text: &str) -> Option<SocketAddr> {
    let result = match text.strip_prefix('@') {
        Some(name) => {
            use std::os::linux::net::SocketAddrExt;
            SocketAddr::from_abstract_name(name.as_bytes())
        }
        None => SocketAddr::from_pathname(text),
    };
    result.map_err(|e| debug!("NOTIFY_SOCKET {text}: {e}")).ok()
}

/// The mux's decision in a few words: what drives the robot, or why nothing does.
pub fn describe(status: &MuxStatus) -> String {
    status.why().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mux::Mux;
    use chassisd_config::mux::MuxConfig;

    #[test]
    fn the_status_names_the_decision_and_the_held_locks() {
        let t = Timestamp::from_millis;
        let mut mux = Mux::new(&MuxConfig::default()).unwrap();
        mux.evaluate(t(1));
        assert_eq!(
            describe(mux.status()),
            "stopped: required source safety silent"
        );
        let mut mux = Mux::new(&MuxConfig::default().without_required_sources()).unwrap();
        let valid = |r| chassis_interfaces::ValidRequest::try_from(r).unwrap();
        let teleop = valid(chassis_interfaces::VelocityRequest {
            stamp_ns: t(1).as_nanos(),
            ..chassis_interfaces::VelocityRequest::twist(0.3, 0.0)
        });
        mux.on_request(t(1), 1, &teleop).unwrap();
        mux.evaluate(t(2));
        assert_eq!(
            describe(mux.status()),
            "stopped: waiting for a zero from teleop since chassisd started"
        );
        mux.on_request(
            t(2),
            1,
            &valid(chassis_interfaces::VelocityRequest::heartbeat()),
        )
        .unwrap();
        mux.on_request(t(2), 1, &teleop).unwrap();
        mux.evaluate(t(2));
        assert_eq!(describe(mux.status()), "driving from teleop");
        mux.engage_lock(t(3), "estop", None).unwrap();
        mux.evaluate(t(4));
        assert_eq!(
            describe(mux.status()),
            "stopped: locked · held: estop (category 2)"
        );
    }

    #[test]
    fn pings_come_four_times_per_watchdog_period_and_status_only_on_change() {
        let dir = std::env::temp_dir().join(format!("chassisd-notify-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let listener = UnixDatagram::bind(&path).unwrap();
        listener.set_nonblocking(true).unwrap();
        let mut notifier = Notifier {
            socket: UnixDatagram::unbound().unwrap(),
            to: address(&path.to_string_lossy()).unwrap(),
            ping_every: Some(Duration::from_millis(100)),
            last_ping: None,
            status: String::new(),
        };
        let mux = Mux::new(&MuxConfig::default()).unwrap();
        notifier.ready(mux.status());
        for ms in (0..=300).step_by(20) {
            notifier.pass(Timestamp::from_millis(1000 + ms), mux.status());
        }
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        while let Ok(n) = listener.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
        assert_eq!(got[0], "READY=1\nSTATUS=stopped: starting");
        assert_eq!(got[1..], ["WATCHDOG=1"; 4], "at 0, 100, 200, 300 ms");
        assert_eq!(
            notifier.deadline(),
            Some(Timestamp::from_millis(1400)),
            "the next ping"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
