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
    let out = env.chassis(&[
        "doctor", "--robot", "titan", "--name", n, "--bus", bus, "--listen", "1",
    ]);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    (out.status.code(), text)
}

fn line<'a>(report: &'a str, key: &str) -> (&'a str, &'a str) {
    report
        .lines()
        .find_map(|l| {
            let mut w = l.split_whitespace();
            let v = w.next()?;
            (w.next()? == key).then_some((v, l))
        })
        .unwrap_or_else(|| panic!("no '{key}' line in\n{report}"))
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
        line(&report, "interface").1.contains("driver kvaser_pci"),
        "{report}"
    );
    let (verdict, bitrate) = line(&report, "bitrate");
    assert_eq!(verdict, "FAIL", "{report}");
    assert!(
        bitrate.contains("250000 bit/s; the AgileX TITAN speaks 500000"),
        "{report}"
    );
    assert!(
        report.contains("type can bitrate 500000 restart-ms 100"),
        "{report}"
    );
    assert_eq!(line(&report, "restart-ms").0, "warn", "{report}");
    let (verdict, controller) = line(&report, "controller");
    assert_eq!(verdict, "ok", "{report}");
    assert!(
        controller.contains("error-active (error counters tx 0, rx 0)"),
        "{report}"
    );

    // Both controllers right; the simulated TITAN on can1.
    set("can0", 500_000, 100);
    set("can1", 500_000, 100);
    env.sim("sim", "titan", &[], &format!("{n}s"), "can:can1");
    let mut report = String::new();
    let ready = wait_for(UP, || {
        let (code, text) = doctor(&env, &n, "can:can0");
        report = text;
        code == Some(0)
    });
    assert!(ready.is_some(), "{report}\n{}", env.logs());
    assert!(
        line(&report, "bitrate")
            .1
            .contains("500000 bit/s, the AgileX TITAN's")
    );
    assert_eq!(line(&report, "restart-ms").0, "ok", "{report}");
    assert_eq!(line(&report, "robot").0, "ok", "{report}");
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
