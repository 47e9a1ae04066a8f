//! chassis doctor and chassisd on CAN controllers with a bit rate: two SJA1000s (QEMU's
//! emulated Kvaser PCI cards, the kernel's `kvaser_pci` driver) on one emulated bus, `can0`
//! and `can1`. What a vcan cannot show: a bit rate (right and wrong), `restart-ms`, the
//! controller's state and error counters read over netlink, a driver's name.
//!
//! Ignored on a normal host; `scripts/vm-tests` runs them in a VM started with the cards
//! (`CHASSIS_VM_QEMU`, `CHASSIS_VM_MODULES=kvaser_pci`) and iproute2's `ip` packed as
//! CHASSIS_IP (busybox's `ip` cannot set a bit rate). QEMU's SJA1000 acknowledges every frame
//! itself: it shows no bus errors and never goes bus-off, so those stay the error-frame tests'
//! (tests/tests/vcan.rs).
// Test code: helpers outside #[test] functions may unwrap, panic and read the wall clock.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::process::Command;
use std::time::Duration;

use chassis_tests::*;

const UP: Duration = Duration::from_secs(30);

fn ip(args: &[&str]) {
    let ip = std::env::var("CHASSIS_IP").unwrap_or_else(|_| "ip".into());
    let out = Command::new(&ip).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{ip} {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Sets `iface` down, to `bitrate` and `restart_ms`, and up again.
fn set(iface: &str, bitrate: u32, restart_ms: u32) {
    ip(&["link", "set", iface, "down"]);
    ip(&[
        "link",
        "set",
        iface,
        "type",
        "can",
        "bitrate",
        &bitrate.to_string(),
        "restart-ms",
        &restart_ms.to_string(),
    ]);
    ip(&["link", "set", iface, "up"]);
}

fn doctor(env: &Env, n: &str, bus: &str) -> (Option<i32>, String) {
    doctor_listening(env, "titan", n, bus)
}

#[test]
#[ignore = "needs QEMU's emulated SJA1000 cards: scripts/vm-tests runs it in a VM"]
fn the_doctor_reads_bit_rate_restart_ms_and_controller_state_of_a_real_driver() {
    let mut env = Env::new("sja1000");
    let n = format!("sj{}", std::process::id() % 100_000);

    // The wrong bit rate, no restart-ms, nobody else on the bus.
    set("can0", 250_000, 0);
    let (code, report) = doctor(&env, &n, "can:can0");
    assert_eq!(code, Some(1), "{report}");
    assert!(
        doctor_line(&report, "interface")
            .1
            .contains("driver kvaser_pci"),
        "{report}"
    );
    check_line(
        &report,
        "bitrate",
        "FAIL",
        "250000 bit/s; the AgileX TITAN speaks 500000",
    );
    assert!(
        report.contains("type can bitrate 500000 restart-ms 100"),
        "{report}"
    );
    assert_eq!(doctor_line(&report, "restart-ms").0, "warn", "{report}");
    check_line(
        &report,
        "controller",
        "ok",
        "error-active (error counters tx 0, rx 0)",
    );

    // Both controllers right; the simulated TITAN on can1.
    set("can0", 500_000, 100);
    set("can1", 500_000, 100);
    env.sim("sim", "titan", &[], &format!("{n}s"), "can:can1");
    let (ready, report) = until_passes(UP, || doctor(&env, &n, "can:can0"));
    assert!(ready.is_some(), "{report}\n{}", env.logs());
    assert!(
        doctor_line(&report, "bitrate")
            .1
            .contains("500000 bit/s, the AgileX TITAN's")
    );
    assert_eq!(doctor_line(&report, "restart-ms").0, "ok", "{report}");
    assert_eq!(doctor_line(&report, "robot").0, "ok", "{report}");
    // QEMU's controller reports no bus error; under load its receive FIFO overflows, which is
    // said as such, not as trouble on the bus.
    assert!(!report.contains("bus-errors"), "{report}");

    // chassisd on can0 reads the controller's state at open and drives the TITAN across.
    env.serve("titan", &n, &["--bus", "can:can0", "--no-safety-monitor"]);
    let mut robot = env.robot(&n, UP);
    let active = wait_for(UP, || {
        let s = state(&mut robot);
        s.link.can_state == ControllerState::ERROR_ACTIVE
            && s.system.control_mode == ControlMode::COMMAND
    });
    assert!(active.is_some(), "{:?}\n{}", state(&mut robot), env.logs());
    let status = env.chassis(&["status", "--name", &n]);
    let text = String::from_utf8_lossy(&status.stdout);
    println!("{text}");
    assert!(text.contains("can        error-active"), "{text}");
}
