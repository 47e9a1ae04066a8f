"""The README's example and the examples in ``clients/python/examples`` run against chassisd."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

from conftest import PYTHON_DIR, REPO, World, binary, wait_until

import chassis

EXAMPLES = PYTHON_DIR / "examples"


def run(world: World, *args: str, timeout: float = 90) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args],
        env=world.env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_the_readme_example_drives_titan_and_prints_its_odometry(world: World) -> None:
    readme = (REPO / "README.md").read_text()
    section = readme.split("\n## Python\n", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S)
    assert code is not None, "no python block in the README's Python section"
    assert len(code.group(1).strip().splitlines()) == 5
    world.chassisd("titan")
    done = run(world, "-c", code.group(1))
    assert done.returncode == 0, done.stderr
    odometry = eval(done.stdout)  # the dict the example prints
    assert odometry["x_m"] > 0.1, done.stdout


def test_the_monitor_prints_the_state(world: World) -> None:
    world.chassisd("xbot")
    done = run(world, str(EXAMPLES / "monitor.py"), "xbot", "--count", "5")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 5, done.stdout
    assert all(line.startswith("#") and " m/s" in line for line in lines), done.stdout


def test_drive_square_comes_back_to_its_start(world: World) -> None:
    world.chassisd("scout-mini")
    done = run(world, str(EXAMPLES / "drive_square.py"), "scout-mini", "--side", "0.25")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("corner") == 4, done.stdout
    error = float(re.search(r"within ([0-9.]+) m", done.stdout).group(1))  # type: ignore[union-attr]
    assert error < 0.1, done.stdout


def test_the_python_safety_monitor_holds_the_required_source(world: World) -> None:
    # The safety rule on: the required `safety` source must be alive for anything to move.
    robot = world.chassisd("xbot", safety=True)
    planner = robot.source("planner")

    def speed_after(seconds: float) -> float:
        end = time.monotonic() + seconds
        fastest = 0.0
        while time.monotonic() < end:
            planner.twist(0.3, 0.0)
            state = robot.wait_state(0.05)
            if state is not None:
                fastest = max(fastest, state.motion.linear_mps)
        return fastest

    assert speed_after(1.0) < 0.01, "moved without a safety monitor"
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.REQUIRED_SOURCE_STALE

    monitor = world.python("safety-monitor", str(EXAMPLES / "safety_monitor.py"), "xbot")

    def moving() -> bool:
        return speed_after(0.1) > 0.15

    wait_until("the robot moves while the monitor beats", moving, 20.0, world)

    # An obstacle closer than the threshold: the monitor latches the e-stop.
    assert robot.sim("obstacle-ahead", value=0.1).ok

    def latched() -> bool:
        planner.twist(0.3, 0.0)
        mux = robot.wait_mux(0.05)
        if mux is None:
            return False
        locks = {lock.name: lock for lock in mux.locks[: mux.lock_count]}
        return bool(locks["estop"].held)

    wait_until("the monitor latches the e-stop", latched, 10.0, world)
    wait_until("the robot stands", lambda: speed_after(0.1) < 0.01, 10.0, world)
    # The obstacle gone, the e-stop stays latched: the robot does not move.
    assert robot.sim("obstacle-ahead", flag=False).ok
    assert speed_after(1.0) < 0.01
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.LOCKED
    assert "latching the e-stop: obstacle at" in (world.tmp / "safety-monitor.log").read_text()

    # Released by the operator while the planner asks for motion: a release never starts
    # motion, so the robot waits for the planner's zero…
    planner.twist(0.3, 0.0)
    assert robot.control("estop-release").ok
    assert speed_after(0.5) < 0.01, "moved after the release by itself"
    # …and drives again, while the monitor beats, once the planner has asked for zero.
    planner.twist(0.0, 0.0)
    wait_until("the robot moves again", moving, 10.0, world)
    # …and stops when the monitor dies.
    monitor.send_signal(signal.SIGKILL)
    monitor.wait(timeout=5)
    wait_until("the robot stops without its monitor", lambda: speed_after(0.1) < 0.01, 10.0, world)
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.REQUIRED_SOURCE_STALE


def test_bench_prints_a_json_row_per_path(world: World) -> None:
    world.chassisd("titan")
    done = run(
        world,
        str(PYTHON_DIR / "bench.py"),
        "--state-samples",
        "50",
        "--commands",
        "5",
        "--chassis",
        str(binary("chassis")),
    )
    assert done.returncode == 0, done.stdout + done.stderr
    rows = [json.loads(line) for line in done.stdout.splitlines()]
    assert [r["path"] for r in rows] == ["state", "command"], rows
    assert rows[0]["samples"] >= 50 and rows[1]["samples"] + rows[1]["missed"] == 5, rows
    # The state path reads a lossless stream and says what it lost.
    assert rows[0]["dropped"] == 0, rows
    assert all(0 < r["p50_us"] <= r["p99_us"] <= r["max_us"] for r in rows), rows
