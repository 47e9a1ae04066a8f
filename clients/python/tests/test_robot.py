"""The package against real ``chassisd`` processes on the simulated robots."""

from __future__ import annotations

import signal
import textwrap
import time
from pathlib import Path

import pytest
from conftest import World, binary, wait_until

import chassis


def drive(
    robot: chassis.Robot,
    source: chassis.Source,
    request: chassis.VelocityRequest,
    until: object,
    timeout: float,
    world: World,
) -> chassis.ChassisState:
    """Sends ``request`` at ≈ 20 Hz until ``until(state)`` holds; fails after ``timeout`` s."""
    end = time.monotonic() + timeout
    while True:
        source.send(request)
        state = robot.wait_state(0.05)
        if state is not None and until(state):  # type: ignore[operator]
            return state
        if time.monotonic() > end:
            last = robot.latest_state()
            pytest.fail(
                f"not reached within {timeout} s; last state "
                f"{last.motion.to_dict() if last else None}\n{world.logs()}"
            )


def test_a_request_with_a_nan_or_an_infinity_is_refused_before_anything_is_sent() -> None:
    # No port is touched: the refusal comes first.
    source = chassis.Source("teleop", publisher=None, notifier=None)
    for bad in (float("nan"), float("inf"), float("-inf")):
        with pytest.raises(ValueError, match="linear_x_mps is not a finite number"):
            source.send(chassis.VelocityRequest.twist(bad))
        with pytest.raises(ValueError, match="limit_reverse_mps is not a finite number"):
            source.send(chassis.VelocityRequest.limit(0.0, bad, 0.0, 0.0))


def test_a_speed_limit_that_is_not_more_than_zero_is_refused_before_anything_is_sent() -> None:
    source = chassis.Source("planner", publisher=None, notifier=None)
    for bad in (0.0, -0.5):
        with pytest.raises(ValueError, match="a speed limit is more than 0"):
            source.limit_speed(bad)
    with pytest.raises(ValueError, match="speed_limit_mps is not a finite number"):
        source.limit_speed(float("nan"))


def test_a_source_lowers_the_speed_limit_and_only_the_operator_raises_it(world: World) -> None:
    robot = world.chassisd("titan")
    teleop = robot.source("teleop")
    planner = robot.source("planner")
    planner.limit_speed(0.3)
    fast = chassis.VelocityRequest.twist(0.8, 0.0)
    drive(robot, teleop, fast, lambda s: s.motion.linear_mps > 0.25, 15.0, world)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        teleop.send(fast)
        state = robot.wait_state(0.05)
        assert state is None or state.motion.linear_mps < 0.33, state.motion.to_dict()
    planner.limit_speed(1.0)
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.clamp_flags & chassis.ClampFlags.SPEED_LIMIT
    assert mux.why() == "driving from teleop · limited to 0.3 m/s by planner", mux.why()
    raised = robot.control("speed-limit", mps=0.6)
    assert raised.ok and "0.6 m/s" in raised.message, str(raised)
    drive(robot, teleop, fast, lambda s: s.motion.linear_mps > 0.5, 15.0, world)
    assert robot.control("speed-limit", mps=-1.0).status == chassis.ControlStatus.INVALID
    assert robot.control("speed-limit", mps=0.0).ok
    drive(robot, teleop, fast, lambda s: s.motion.linear_mps > 0.7, 15.0, world)


@pytest.mark.parametrize("kind", ["titan", "scout-mini", "xbot"])
def test_drives_and_reads_back_every_robot(world: World, kind: str) -> None:
    robot = world.chassisd(kind)
    start = robot.latest_state()
    assert start is not None
    described = robot.description
    assert described.kind_name == kind
    assert described.kind == start.robot
    teleop = robot.source("teleop")
    moving = drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.3, 0.0),
        lambda s: s.motion.linear_mps > 0.15 and s.odometry.x_m > start.odometry.x_m + 0.02,
        15.0,
        world,
    )
    assert moving.motion.linear_mps < 0.35
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.active_source_name() == "teleop"
    assert mux.output.linear_x_mps == pytest.approx(0.3, abs=0.01)
    drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.0, 0.0),
        lambda s: abs(s.motion.linear_mps) < 0.01,
        15.0,
        world,
    )
    assert robot.latest_state().to_dict()["motion"]["linear_mps"] == pytest.approx(0.0, abs=0.01)


def test_the_description_is_read_late_and_carries_the_configured_override(
    world: World, tmp_path: Path
) -> None:
    config = tmp_path / "ranger.toml"
    config.write_text("[profile]\nmax_linear_mps = 0.6\n")
    world.chassisd("ranger-mini", "--config", str(config), safety=True)
    time.sleep(1.5)
    late = world.connect("ranger-mini")
    started = time.monotonic()
    d = late.description
    assert time.monotonic() - started < 0.5
    summary = d.summary()
    assert summary["kind_name"] == "ranger-mini"
    assert summary["display_name"] == "AgileX RANGER MINI"
    assert d.robot_limits.forward_mps == pytest.approx(0.6)
    assert d.kinematics == chassis.Kinematics.FOUR_WHEEL_STEER
    assert [j["name"] for j in summary["joints"]] == ["front_steer_joint", "rear_steer_joint"]
    safety = [s for s in summary["sources"] if s["name"] == "safety"]
    assert safety and safety[0]["flags"] & chassis.SourceFlags.REQUIRED


def test_a_robot_nobody_serves_is_reported_with_the_clis_advice(world: World) -> None:
    with pytest.raises(chassis.NotServed, match="is chassisd running"):
        chassis.Robot.connect("nobody", prefix=world.prefix)
    with pytest.raises(chassis.BadName):
        chassis.Robot.connect("Not A Name", prefix=world.prefix)


def test_a_python_source_is_preempted_by_a_rust_teleop_and_handed_back(world: World) -> None:
    robot = world.chassisd("titan")
    planner = robot.source("planner")
    slow = chassis.VelocityRequest.twist(0.2, 0.0)
    drive(robot, planner, slow, lambda s: s.motion.linear_mps > 0.15, 15.0, world)

    teleop = world.spawn(
        "teleop",
        [
            str(binary("chassis")),
            "pub",
            "velocity",
            "--source",
            "teleop",
            "--vx",
            "0.5",
            "--rate",
            "20",
            "--duration",
            "2",
            "--name",
            "titan",
        ],
    )
    seen: list[str | None] = []

    def active() -> str | None:
        planner.send(slow)
        mux = robot.wait_mux(0.05)
        name = mux.active_source_name() if mux else None
        if not seen or seen[-1] != name:
            seen.append(name)
        return name

    wait_until("the teleop takes over", lambda: active() == "teleop", 15.0, world)
    drive(robot, planner, slow, lambda s: s.motion.linear_mps > 0.3, 15.0, world)
    wait_until("the planner is handed back", lambda: active() == "planner", 15.0, world)
    assert teleop.wait(timeout=15) == 0
    drive(robot, planner, slow, lambda s: abs(s.motion.linear_mps - 0.2) < 0.03, 15.0, world)
    assert seen[-2:] == ["teleop", "planner"], seen


def test_a_source_held_by_another_process_is_taken(world: World) -> None:
    robot = world.chassisd("titan")
    holder = world.spawn(
        "holder",
        [
            str(binary("chassis")),
            "pub",
            "velocity",
            "--source",
            "teleop",
            "--heartbeat",
            "--name",
            "titan",
        ],
    )

    def beating() -> bool:
        # The CLI's heartbeats reach the mux: it holds the source.
        mux = robot.wait_mux(0.05)
        if mux is None:
            return False
        teleop = mux.sources[mux.source_names().index("teleop")]
        return bool(teleop.flags & chassis.SourceFlags.FRESH)

    wait_until("the CLI holds teleop", beating, 15.0, world)
    with pytest.raises(chassis.SourceTaken, match="already held"):
        robot.source("teleop")
    # Another source is free, an unknown one is named with the configured ones.
    robot.source("planner").heartbeat()
    with pytest.raises(chassis.UnknownSource, match="safety, teleop, planner"):
        robot.source("nosuch")
    holder.send_signal(signal.SIGTERM)
    assert holder.wait(timeout=15) == 0


KEEP_DRIVING = textwrap.dedent(
    """
    import sys, time, chassis
    robot = chassis.Robot.connect(sys.argv[1])
    planner = robot.source("planner")
    print("driving", flush=True)
    while True:
        planner.twist(0.3, 0.0)
        time.sleep(0.05)
    """
)
# KEEP_DRIVING's period: its last request is at most this old (and its own scheduling) when
# it is killed.
KEEP_DRIVING_PERIOD_MS = 50.0
# How late the test may see the mux drop a dead source, on top of its timeout: the service
# decides at the expiry, its loop waking up to a tick (20 ms) late on a loaded machine, and the
# test reads the newest status, which may be the next tick's (20 ms).
DECISION_ALLOWANCE_MS = 40.0
# How early, before the timeout counted from the kill: the age the last request already had
# (a period), and the driver's own scheduling (30 ms: a sleep that overran, a late send).
EARLY_ALLOWANCE_MS = KEEP_DRIVING_PERIOD_MS + 30.0


def test_a_killed_python_source_ends_its_motion_at_its_timeout(world: World) -> None:
    robot = world.chassisd("titan")
    driver = world.python("driver", "-c", KEEP_DRIVING, "titan")

    def moving() -> bool:
        state = robot.wait_state(0.05)
        mux = robot.latest_mux()
        return (
            state is not None
            and state.motion.linear_mps > 0.15
            and mux is not None
            and mux.active_source_name() == "planner"
        )

    wait_until("the Python planner drives", moving, 20.0, world)
    killed_ns = chassis.now_ns()
    driver.send_signal(signal.SIGKILL)
    driver.wait(timeout=5)

    # The first status after the kill in which the mux dropped the planner: read as they come
    # (no sleep between reads), so that its stamp is the decision's, not the reader's.
    released: chassis.MuxStatus | None = None
    end = time.monotonic() + 10.0
    while released is None and time.monotonic() < end:
        mux = robot.wait_mux(0.02)
        if (
            mux is not None
            and mux.stamp_ns > killed_ns
            and mux.active_source == chassis.MuxStatus.NO_SOURCE
        ):
            released = mux
    assert released is not None, f"the mux never dropped the dead planner\n{world.logs()}"
    assert released.zero_reason == chassis.ZeroReason.NO_ACTIVE_SOURCE
    assert released.output.linear_x_mps == 0.0
    planner = released.sources[released.source_names().index("planner")]
    assert not planner.flags & chassis.SourceFlags.FRESH, planner.to_dict()
    # It was dropped for its age: the source's own timeout, not earlier…
    assert planner.age_ms >= planner.timeout_ms, planner.to_dict()
    # … and at it, by the test's clock: from the kill to the decision, the timeout less the
    # age its last request had at the kill, and no later than the timeout and the allowance.
    after_ms = (released.stamp_ns - killed_ns) / 1e6
    assert after_ms >= planner.timeout_ms - EARLY_ALLOWANCE_MS, (after_ms, planner.to_dict())
    assert after_ms <= planner.timeout_ms + DECISION_ALLOWANCE_MS, (
        after_ms,
        planner.to_dict(),
    )
    wait_until(
        "the robot stops",
        lambda: (s := robot.wait_state(0.05)) is not None and abs(s.motion.linear_mps) < 0.01,
        10.0,
        world,
    )


READ_STATES = """
import signal
import sys
import chassis
# Ctrl-C as in a terminal: a runner in the background hands its children SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)
robot = chassis.Robot.connect(sys.argv[1])
stream = robot.state_stream()
read = 0
try:
    while True:
        for _ in stream.each(0.5):
            read += 1
        robot.wait_state(0.05)
        print(read, flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


def test_a_reader_stopped_and_continued_goes_on_and_ctrl_c_reaches_it(world: World) -> None:
    """A signal that interrupts a wait (a SIGCONT after Ctrl-Z and ``fg``) is no failure of the
    reader; SIGINT still ends it as ``KeyboardInterrupt``."""
    world.chassisd("titan")
    reader = world.python("reader", "-c", READ_STATES, "titan")
    log = world.tmp / "reader.log"

    def lines() -> list[str]:
        return log.read_text(errors="replace").splitlines()

    wait_until("the reader reads", lambda: len(lines()) > 2, 20.0, world)
    for _ in range(3):
        reader.send_signal(signal.SIGSTOP)
        time.sleep(0.1)
        reader.send_signal(signal.SIGCONT)
        time.sleep(0.05)
    read = len(lines())
    wait_until("the reader goes on", lambda: len(lines()) > read + 2, 5.0, world)
    assert reader.poll() is None, world.logs()
    reader.send_signal(signal.SIGINT)
    assert reader.wait(timeout=5) == 0, world.logs()
    assert lines()[-1] == "interrupted", world.logs()


@pytest.mark.parametrize("read", ["wait", "each"])
def test_a_state_stream_loses_nothing_on_a_flooded_bus(world: World, read: str) -> None:
    robot = world.chassisd("titan")
    assert robot.state_stream(0).buffer == 1
    stream = robot.state_stream(10**6)
    assert stream.buffer == chassis.STATE_BUFFER
    teleop = robot.source("teleop")
    drive_request = chassis.VelocityRequest.twist(0.3, 0.0)
    answer = robot.sim("flood", value=2000.0)
    assert answer.ok, str(answer)
    drive(robot, teleop, drive_request, lambda s: s.motion.linear_mps > 0.1, 15.0, world)
    stream.drain()

    received = gaps = lost = largest = 0
    last: int | None = None
    started = time.monotonic()
    while time.monotonic() - started < 2.0:
        teleop.send(drive_request)
        time.sleep(0.006)
        batch = stream.wait(0.1) if read == "wait" else list(stream.each(0.1))
        largest = max(largest, len(batch))
        for state in batch:
            received += 1
            if last is not None and state.seq != last + 1:
                gaps += 1
                lost += max(0, state.seq - last - 1)
            last = state.seq
    if read == "each":
        # A sample is handed over as soon as it is read: the rest of the burst still waits.
        teleop.send(drive_request)
        time.sleep(0.006)
        first = next(stream.each(0.1))
        rest = stream.drain()
        assert rest and rest[0].seq == first.seq + 1, (first.seq, [s.seq for s in rest])
    print(f"stream: {received} samples, {gaps} gaps ({lost} lost), up to {largest} per read")
    assert (gaps, lost) == (0, 0), f"lost {lost} samples in {gaps} gaps\n{world.logs()}"
    assert received >= 1000, f"only {received} samples in 2 s"
    assert largest > 4, f"at most {largest} samples per read: the bus was not flooded"


def test_control_actions_are_answered_with_success_or_a_reason(world: World) -> None:
    robot = world.chassisd("titan")
    teleop = robot.source("teleop")
    drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.3, 0.0),
        lambda s: s.motion.linear_mps > 0.15,
        15.0,
        world,
    )
    refused = robot.control("off-road", state="on")
    assert refused.status == chassis.ControlStatus.REFUSED and "moving" in refused.message, str(
        refused
    )
    refused = robot.control("brake", action="engage")
    assert not refused.ok and refused.status_name == "refused", str(refused)
    unsupported = robot.control("lights", mode="on")
    assert unsupported.status == chassis.ControlStatus.UNSUPPORTED, str(unsupported)

    # The operator's e-stop holds the robot whatever the teleop asks; stop category 0 cuts the
    # drive at once.
    engaged = robot.control("estop", category=0)
    assert engaged.ok and "stop category 0 (cut the drive at once)" in engaged.message, str(engaged)
    stopped = drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.3, 0.0),
        lambda s: abs(s.motion.linear_mps) < 0.01,
        15.0,
        world,
    )
    assert stopped.motion.linear_mps == pytest.approx(0.0, abs=0.01)
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.LOCKED
    assert mux.locks[0].category == chassis.StopCategory.CUT
    assert mux.drive == chassis.DriveState.CUT, mux.why()
    # A release never starts motion: the teleop still asks for 0.3 m/s, so nothing moves
    # until it has asked for zero.
    teleop.send(chassis.VelocityRequest.twist(0.3, 0.0))
    released = robot.control("estop-release")
    assert released.ok and "nothing moves until teleop asks for zero" in released.message, str(
        released
    )
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        teleop.send(chassis.VelocityRequest.twist(0.3, 0.0))
        state = robot.wait_state(0.05)
        assert state is None or abs(state.motion.linear_mps) < 0.01, "moved after the release"
    mux = robot.wait_mux(1.0)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.AWAITING_ZERO
    assert mux.sources[mux.awaiting_source].name == "teleop"
    assert mux.stop == chassis.Stop.LOCK_RELEASED
    assert mux.why() == "stopped: waiting for a zero from teleop since lock-released", mux.why()
    teleop.send(chassis.VelocityRequest.twist(0.0, 0.0))
    drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.3, 0.0),
        lambda s: s.motion.linear_mps > 0.15,
        15.0,
        world,
    )

    drive(
        robot,
        teleop,
        chassis.VelocityRequest.twist(0.0, 0.0),
        lambda s: abs(s.motion.linear_mps) < 0.005,
        15.0,
        world,
    )
    teleop.stop()
    engaged = robot.control("brake", action="engage")
    assert engaged.ok, str(engaged)
    assert robot.control("clear-fault", which="all").ok
    assert robot.control("brake", action="release").ok

    with pytest.raises(ValueError, match="unknown control action"):
        robot.control("warp")
    with pytest.raises(TypeError, match="needs"):
        robot.control("brake")
    with pytest.raises(ValueError, match="unknown fault"):
        robot.control("clear-fault", which="everything")


def test_xbot_lift_and_servos_are_controlled_and_a_range_is_refused(world: World) -> None:
    robot = world.chassisd("xbot")
    assert robot.control("power", state="on").ok
    lift = robot.control("lift", position=50.0)
    assert lift.ok, str(lift)
    servos = robot.control("servos", pan=20.0, tilt=-10.0)
    assert servos.ok, str(servos)
    invalid = robot.control("lift", position=150.0)
    assert invalid.status == chassis.ControlStatus.INVALID, str(invalid)
    assert robot.control("steering-zero").status == chassis.ControlStatus.UNSUPPORTED


def test_the_frame_tap_shows_both_directions(world: World) -> None:
    robot = world.chassisd("scout-mini")
    tap = robot.frames(chassis.FRAMES_BUFFER)
    teleop = robot.source("teleop")
    directions: set[int] = set()
    end = time.monotonic() + 10
    while directions != {chassis.FrameDirection.RX, chassis.FrameDirection.TX}:
        teleop.twist(0.2, 0.0)
        directions |= {frame.direction for frame in tap.wait(0.05)}
        assert time.monotonic() < end, f"directions seen: {directions}"
