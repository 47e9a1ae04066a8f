//! `chassis-bench --attach NAME` against a chassisd it did not start, under the robot's own name
//! and IPC prefix: the state rows and the control loop's rows measured by reading only, the rows
//! that send velocity listed as withheld; with `--wheels-off-ground`, those measured too.
#![allow(clippy::unwrap_used, clippy::panic, clippy::disallowed_methods)]

use std::time::Duration;

use chassis_client::{Source, VelocityRequest};
use chassis_tests::*;
use serde_json::Value;

const UP: Duration = Duration::from_secs(10);

/// The rows (`path`, `leg`, samples) of run `run` and the withheld rows' reasons, from the
/// samples of `chassis-bench --smoke --attach NAME extra…`, run while `drive` (when given) keeps
/// the robot moving as its own software would.
fn attached_bench(
    env: &mut Env,
    name: &str,
    extra: &[&str],
    mut drive: Option<&mut Source>,
) -> (Vec<(String, String, u64)>, Vec<String>) {
    let samples = env.dir.join(format!("bench{}.jsonl", extra.len()));
    let samples_arg = samples.display().to_string();
    let mut args = vec!["--smoke", "--allow-dirty", "--attach", name];
    args.extend(["--samples", &samples_arg]);
    args.extend_from_slice(extra);
    let bench = env.spawn_program("bench", &bin("chassis-bench"), &args, &[]);
    let mut code = None;
    for _ in 0..1200 {
        if let Some(source) = drive.as_deref_mut() {
            source.send(VelocityRequest::twist(0.4, 0.2)).unwrap();
        }
        code = env.proc(bench).wait_exit(Duration::from_millis(50));
        if code.is_some() {
            break;
        }
    }
    assert_eq!(code, Some(0), "chassis-bench failed\n{}", env.logs());
    let text = std::fs::read_to_string(&samples).unwrap();
    let lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let withheld = lines[0]["run"]["withheld"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let withheld = withheld.iter().map(|w| w[1].as_str().unwrap().to_string());
    let rows = lines.iter().filter_map(|l| l.get("row")).map(|row| {
        let text = |field: &str| row[field].as_str().unwrap().to_string();
        assert!(text("run").starts_with("titan attached as "), "{row}");
        let count = row["summary"]["count"].as_u64().unwrap();
        (text("path"), text("leg"), count)
    });
    (rows.collect(), withheld.collect())
}

fn measured(rows: &[(String, String, u64)], path: &str, leg: &str) -> u64 {
    let found = rows.iter().find(|(p, l, _)| p == path && l == leg);
    found
        .unwrap_or_else(|| panic!("no {path} {leg} row in {rows:?}"))
        .2
}

#[test]
fn the_bench_attached_to_a_running_robot_reads_it_and_drives_it_only_with_its_wheels_off_the_ground()
 {
    // The bench's loops keep a CPU busy: never beside a test that measures a flooded bus.
    let _machine = chassis_tests::faults::exclusive();
    // A robot configured for a 1 kHz controller: every command goes out at once, unramped.
    let mut env = Env::new("bench-attach");
    let config = env.write(
        "chassisd.toml",
        "[driver]\nmin_command_interval_ms = 0\n\n\
         [mux.limits]\nlinear_accel_mps2 = 0.0\nangular_accel_radps2 = 0.0\n",
    );
    let n = name("bat");
    env.serve("titan", &n, &["--no-safety-monitor", "--config", &config]);
    let mut robot = env.robot(&n, UP);
    // The robot's own software drives it (a lower priority than the bench's teleop): its
    // feedback keeps changing the state the bench reads.
    let mut planner = source(&mut robot, "planner");
    planner.send(VelocityRequest::twist(0.0, 0.0)).unwrap();
    let (rows, withheld) = attached_bench(&mut env, &n, &[], Some(&mut planner));
    planner.stop().unwrap();
    for (path, leg) in [
        ("state", "state"),
        ("in-service", "state"),
        ("loop", "state-age"),
    ] {
        assert!(measured(&rows, path, leg) > 0, "{path} {leg}: {rows:?}");
    }
    let sending = |(path, leg): &(&str, &str)| *path == "command" || *leg == "period-to-frame";
    let sent = |rows: &[(String, String, u64)]| {
        (rows.iter()).any(|(p, l, _)| sending(&(p.as_str(), l.as_str())))
    };
    assert!(
        !sent(&rows),
        "a row that sends velocity, without the flag: {rows:?}"
    );
    // The command row, its in-service row and the 1 kHz loop's period → frame.
    assert_eq!(withheld, ["wheels-on-ground"; 3]);

    let (rows, withheld) = attached_bench(&mut env, &n, &["--wheels-off-ground"], None);
    assert!(withheld.is_empty(), "{withheld:?}");
    for (path, leg) in [
        ("command", "first-frame-toward"),
        ("loop", "period-to-frame"),
    ] {
        assert!(measured(&rows, path, leg) > 0, "{path} {leg}: {rows:?}");
    }
    assert!(measured(&rows, "state", "state") > 0, "{rows:?}");
}
