//! SocketCAN on a kernel CAN interface: the bus conformance suite on two sockets of a vcan
//! interface, frames from can-utils, and interfaces taken down, brought back and removed.
//!
//! They need a kernel with CAN (`vcan`) and root for `ip link`, so they are ignored on a normal
//! host; `scripts/vm-tests` runs them with `--ignored` inside a VM whose kernel has CAN
//! (`scripts/vm/run-in-vm`). CHASSIS_VCAN names the shared interface (default vcan0); the tests
//! that take an interface down create their own and remove it afterwards.
// Test code: may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::process::Command;
use std::time::{Duration, Instant};

use chassis_bus::conformance::{self, check_link};
use chassis_bus::socketcan::SocketCan;
use chassis_bus::{BusError, CanBus};
use chassis_protocols::CanFrame;

fn iface() -> String {
    std::env::var("CHASSIS_VCAN").unwrap_or_else(|_| "vcan0".into())
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// A vcan interface of the test's own, removed when dropped.
struct ScratchVcan(String);

impl ScratchVcan {
    fn new(name: &str) -> Self {
        let _ = ip(&["link", "del", name]);
        ip(&["link", "add", "dev", name, "type", "vcan"]).unwrap();
        ip(&["link", "set", name, "up"]).unwrap();
        Self(name.to_string())
    }
}

impl Drop for ScratchVcan {
    fn drop(&mut self) {
        let _ = ip(&["link", "del", &self.0]);
    }
}

fn figure(text: impl AsRef<str>) {
    println!("figure: {}", text.as_ref());
}

fn ms(d: Duration) -> String {
    format!("{:.1} ms", d.as_secs_f64() * 1e3)
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn two_sockets_on_vcan_conform() {
    let iface = iface();
    let mut a = SocketCan::open(&iface).unwrap();
    let mut b = SocketCan::open(&iface).unwrap();
    let figures = check_link(&mut a, &mut b).unwrap();
    figure(format!("socketcan {iface} conformance: {figures}"));
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn frames_from_cansend_arrive_and_remote_frames_are_skipped() {
    let iface = iface();
    let mut bus = SocketCan::open(&iface).unwrap();
    conformance::idle_recv_is_none_at_once(&mut bus).unwrap();
    for frame in ["123#R", "211#000101E000000000", "18FF0001#0102", "7FF#"] {
        let status = Command::new("cansend").args([&iface, frame]).status();
        assert!(status.unwrap().success(), "cansend {iface} {frame}");
    }
    let mut got = Vec::new();
    let end = Instant::now() + conformance::DELIVERY_TIMEOUT;
    while got.len() < 3 && Instant::now() < end {
        match bus.recv().unwrap() {
            Some(frame) => got.push(frame.to_candump()),
            None => std::thread::sleep(Duration::from_millis(5)),
        }
    }
    assert_eq!(got, ["211#000101E000000000", "18FF0001#0102", "7FF#"]);
    conformance::idle_recv_is_none_at_once(&mut bus).unwrap();
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn an_interface_taken_down_is_a_disconnect_and_opens_again_once_up() {
    let vcan = ScratchVcan::new("vcandown0");
    let mut a = SocketCan::open(&vcan.0).unwrap();
    let mut b = SocketCan::open(&vcan.0).unwrap();
    let detect =
        conformance::a_lost_link_is_a_disconnect(&mut a, || ip(&["link", "set", &vcan.0, "down"]))
            .unwrap();
    conformance::a_lost_link_is_a_disconnect(&mut b, || Ok(())).unwrap();
    figure(format!(
        "socketcan: interface down seen as a disconnect in {}",
        ms(detect)
    ));

    // Down, it does not open (a socket bound to it would only report ENETDOWN again).
    match SocketCan::open(&vcan.0) {
        Err(BusError::Open { reason, .. }) => assert!(reason.contains("down"), "{reason}"),
        Err(other) => panic!("opening a down interface: {other}"),
        Ok(_) => panic!("a down interface opened as if it were up"),
    }

    ip(&["link", "set", &vcan.0, "up"]).unwrap();
    let mut a = SocketCan::open(&vcan.0).unwrap();
    let mut b = SocketCan::open(&vcan.0).unwrap();
    conformance::frames_arrive_unchanged_and_in_order(&mut a, &mut b).unwrap();
    conformance::frames_cross_both_ways_at_once(&mut a, &mut b).unwrap();
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn a_removed_interface_is_a_disconnect_and_cannot_be_opened() {
    let vcan = ScratchVcan::new("vcangone0");
    let mut bus = SocketCan::open(&vcan.0).unwrap();
    let detect =
        conformance::a_lost_link_is_a_disconnect(&mut bus, || ip(&["link", "del", &vcan.0]))
            .unwrap();
    figure(format!(
        "socketcan: interface removed seen as a disconnect in {}",
        ms(detect)
    ));
    assert!(matches!(
        SocketCan::open(&vcan.0),
        Err(BusError::Open { .. })
    ));
}

#[test]
#[ignore = "needs kernel CAN (vcan) and root: scripts/vm-tests runs it in a VM"]
fn a_frame_sent_while_the_interface_is_down_is_not_reported_sent() {
    let vcan = ScratchVcan::new("vcantx0");
    let mut bus = SocketCan::open(&vcan.0).unwrap();
    ip(&["link", "set", &vcan.0, "down"]).unwrap();
    let frame = CanFrame::new(0x111, &[0; 8]).unwrap();
    // The pending ENETDOWN may surface on either call; a send must never pass silently.
    let sent = bus.send(&frame);
    let received = bus.recv();
    assert!(
        sent.as_ref().is_err_and(BusError::is_disconnect)
            || received.as_ref().is_err_and(BusError::is_disconnect),
        "send: {sent:?}, recv: {received:?}"
    );
    assert!(
        bus.send(&frame).is_err_and(|e| e.is_disconnect()),
        "a send on a down interface passed"
    );
}
