#!/usr/bin/env python3
"""Latency of the ROS 2 bridge's two paths, beside the raw DDS hop it contains, in one run.

A Cyclone DDS participant (the Python binding) stands in for a ROS 2 node, as in the bridge's
tests. Against a running ``chassisd`` (configured as ``chassis-bench`` configures it) this
script starts ``chassis-ros2`` and measures, from ``CLOCK_MONOTONIC`` stamps taken in the
processes involved:

* **cmd_vel → frame**: a ``geometry_msgs/Twist`` written on ``cmd_vel`` → the motion frame
  ``chassisd`` wrote to the bus (the frame tap's TX stamp). Requests alternate between two
  speeds, one every ``--interval-ms``, so each writes a frame (as ``clients/python/bench.py``).
* **frame → odom**: a frame that moved the robot read by ``chassisd`` (``ChassisState.stamp_ns``)
  → the ``nav_msgs/Odometry`` it produced taken by this participant. The bridge runs with
  ``--monotonic-stamps``, so each odom's stamp is that read time itself. The odoms are stamped
  as they are taken off the reader, before this script deserializes them (``take_serialized``);
  so is the raw hop's. By the rule
  ``chassis-bench`` applies to every client alike, an odom counts when its stamp is newer than
  every stamp taken before it and its pose or twist differs from the odom before it: one that
  repeats an older frame's read time, or says what the one before it said (a tick's refresh), is
  left out. The odoms queued in this participant's reader while the other paths ran (its history,
  waiting for this script rather than for the bridge) are taken first and left out, as the
  Rust and Python readers leave out the sample published before they opened; the newest of them
  only sets the stamp.
* **raw hops**: the same two DDS implementations with nothing behind them, each carrying what
  its path carries with the same QoS. ``chassis-bench role dds-echo`` (the bridge's DDS stack)
  records each ``TwistStamped`` ping written here (Cyclone DDS → RustDDS, read as the bridge
  reads ``cmd_vel``) and answers it at once with an ``Odometry`` written as the bridge writes
  ``odom`` (RustDDS → Cyclone DDS, read here as ``odom`` is read), after a warm-up of
  ``WARMUP`` pings that are not counted, and as many counted as the path each hop divides:
  ``--commands`` for the cmd_vel hop, ``--state-samples`` for the odom hop. Each hop keeps the
  pace of its path, so that neither stack is woken more often than on it: the cmd_vel hop the
  command path's (``--interval-ms``), the odom hop the period of the odoms the state path
  counted, 1.7 % more (DIR/raw-out.period_ns).
* **the odom path's parts**: the bridge runs with ``CHASSIS_ROS2_TRACE`` naming DIR/odom.trace:
  for each odom it writes the frame's read time, when its state loop woke with the sample, when
  it handed the odom to RustDDS and when that write returned. DIR/state.pairs holds each counted
  odom's read time and the time it was taken here; ``chassis-bench`` joins the two.

DDS discovery multicasts: run it only in a network namespace whose only interface is the
loopback (``chassis-bench`` runs it under ``unshare --net``); it refuses to run elsewhere.

Command line::

    python3 clients/ros2/bench.py --name titan --prefix P --bridge target/release/chassis-ros2 \
        --echo target/release/chassis-bench --chassis target/release/chassis --latencies-dir DIR
        [--state-samples 2000] [--commands 300] [--interval-ms 4]

Writes DIR/command.ns, DIR/state.ns, DIR/raw-in.ns (Cyclone → RustDDS), DIR/raw-out.ns
(RustDDS → Cyclone), one latency in ns a line, DIR/command.missed, DIR/state.pairs,
DIR/raw-out.period_ns and DIR/odom.trace; prints one JSON line per path.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from cyclonedds._clayer import ddspy_take
from cyclonedds.core import (
    DDSException,
    InstanceState,
    Policy,
    Qos,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

import chassis

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "tests"))
sys.path.insert(0, str(HERE.parent / "python"))

import bench as client_bench  # noqa: E402  (clients/python/bench.py: frames, percentiles)
import ros2_types as m  # noqa: E402

DOMAIN = 77
DISCOVERY_S = 15.0
STATE_DRIVE = (0.6, 0.3)
# Pings before the counted ones: both stacks' first samples (discovery, allocation) left out, as
# chassis-bench's iceoryx2 baselines leave theirs out.
WARMUP = 200


def interfaces() -> list[str]:
    with open("/proc/net/dev") as f:
        return sorted(line.split(":")[0].strip() for line in f.readlines()[2:])


def reliable() -> Qos:
    return Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(10),
    )


def stamp(ns: int) -> m.Time:
    return m.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def nanos(t: m.Time) -> int:
    return t.sec * 1_000_000_000 + t.nanosec


def wait_matched(writer: DataWriter, what: str) -> None:
    end = time.monotonic() + DISCOVERY_S
    while writer.get_publication_matched_status().current_count == 0:
        if time.monotonic() > end:
            raise SystemExit(f"bench.py: {what} never matched")
        time.sleep(0.01)


def take_serialized(reader: DataReader, n: int) -> list[bytes]:
    """Up to ``n`` samples off ``reader``, still serialized (CDR), as ``DataReader.take`` takes
    them before it deserializes each.

    The odoms are stamped when they are taken, before they are deserialized: the binding
    deserializes an ``Odometry`` in Python, which is this stand-in's cost, not the bridge's, and
    not alike on both sides: here about 90 µs when the last was 4 ms before (the raw hop's pace
    once) and 180 µs when it was 20 ms before (the odom's). The raw hop's pong is stamped the
    same way. ``DataReader.take`` offers no other way: this calls the binding's C layer as it
    does.
    """
    mask = SampleState.Any | ViewState.Any | InstanceState.Any
    taken = ddspy_take(reader._ref, mask, n)  # noqa: SLF001
    if isinstance(taken, int):
        raise DDSException(taken, f"taking from {reader!r}")
    return [data for data, info in taken if info.valid_data]


def waiter(dp: DomainParticipant, reader: DataReader) -> WaitSet:
    ws = WaitSet(dp)
    ws.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    return ws


def command_path(
    robot: chassis.Robot,
    cmd: DataWriter,
    frames: dict[float, tuple[int, bytes]],
    count: int,
    interval_s: float,
) -> tuple[list[int], int]:
    def send(speed: float) -> int:
        sent = chassis.now_ns()
        cmd.write(m.Twist(linear=m.Vector3(x=speed)))
        return sent

    result = client_bench.paced_commands(robot, frames, count, interval_s, send, warmups=20)
    cmd.write(m.Twist())
    return result


def state_path(
    dp: DomainParticipant, cmd: DataWriter, odom: DataReader, samples: int
) -> list[tuple[int, int]]:
    """(frame read, odom taken) pairs, ns. The bridge runs with ``--monotonic-stamps``: each
    odom's stamp is the ``CLOCK_MONOTONIC`` read time of the frame that produced it."""
    ws = waiter(dp, odom)
    pairs: list[tuple[int, int]] = []
    drive = m.Twist(linear=m.Vector3(x=STATE_DRIVE[0]), angular=m.Vector3(z=STATE_DRIVE[1]))
    last_request = 0
    newest: int | None = None
    last_said: object = None
    # What queued in the reader's history before this path began waited for this script, not
    # for the bridge: taken and left out.
    while backlog := odom.take(N=64):
        for sample in backlog:
            read = nanos(sample.header.stamp)
            newest = read if newest is None else max(newest, read)
            last_said = (sample.pose, sample.twist)
    deadline = time.monotonic() + 120
    while len(pairs) < samples and time.monotonic() < deadline:
        if chassis.now_ns() - last_request > 50_000_000:
            cmd.write(drive)
            last_request = chassis.now_ns()
        ws.wait(duration(milliseconds=20))
        taken = take_serialized(odom, 64)
        woke = chassis.now_ns()
        for data in taken:
            sample = m.Odometry.deserialize(data)
            read = nanos(sample.header.stamp)
            said = (sample.pose, sample.twist)
            if newest is not None and read > newest and said != last_said:
                pairs.append((read, woke))
            newest = read if newest is None else max(newest, read)
            last_said = said
    cmd.write(m.Twist())
    return pairs


def odom_period(pairs: list[tuple[int, int]]) -> float:
    """The pace of the odom hop, s: the median period of the counted odoms, and 1.7 % more, as
    ``chassis-bench`` paces the command path (``paths::off_grid``), so that the pings sweep the
    phases of the simulated chassis' cycle instead of keeping one. 20 ms when too few odoms
    were counted to tell."""
    reads = sorted(read for read, _ in pairs)
    gaps = sorted(b - a for a, b in itertools.pairwise(reads) if b > a)
    period = gaps[len(gaps) // 2] / 1e9 if len(gaps) >= 10 else 0.02
    return period * 1.017


def raw_hops(
    dp: DomainParticipant, ping: DataWriter, pong: DataReader, count: int, interval_s: float
) -> list[int]:
    ws = waiter(dp, pong)
    out: list[int] = []
    next_send = time.monotonic()
    for _ in range(count):
        next_send += interval_s
        time.sleep(max(0.0, next_send - time.monotonic()))
        ping.write(m.TwistStamped(header=m.Header(stamp=stamp(chassis.now_ns()))))
        end = time.monotonic() + 0.5
        got = False
        while not got and time.monotonic() < end:
            ws.wait(duration(milliseconds=50))
            taken = take_serialized(pong, 8)
            woke = chassis.now_ns()
            for data in taken:
                out.append(woke - nanos(m.Odometry.deserialize(data).header.stamp))
                got = True
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", default="titan")
    parser.add_argument("--robot", default="titan")
    parser.add_argument("--prefix", default=os.environ.get("CHASSIS_IPC_PREFIX"))
    parser.add_argument("--bridge", required=True)
    parser.add_argument("--echo", required=True, help="chassis-bench, the raw hops' far end")
    parser.add_argument("--chassis", required=True)
    parser.add_argument("--latencies-dir", type=Path, required=True)
    parser.add_argument("--state-samples", type=int, default=2000)
    parser.add_argument("--commands", type=int, default=300)
    parser.add_argument("--interval-ms", type=float, default=4.0)
    args = parser.parse_args()
    if interfaces() != ["lo"]:
        raise SystemExit("bench.py: run it in a network namespace with only a loopback")
    out: Path = args.latencies_dir
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), RUST_LOG="warn")
    if args.prefix:
        env["CHASSIS_IPC_PREFIX"] = args.prefix
    interval = args.interval_ms / 1e3
    with (out / "bridge.log").open("wb") as log:
        bridge = subprocess.Popen(
            [args.bridge, "--name", args.name, "--monotonic-stamps"],
            env=dict(env, CHASSIS_ROS2_TRACE=str(out / "odom.trace")),
            stderr=log,
        )
        echo = subprocess.Popen(
            [args.echo, "role", "dds-echo", "--out", str(out / "raw-in.ns")], env=env, stderr=log
        )
    try:
        robot = chassis.Robot.connect(args.name, prefix=args.prefix)
        dp = DomainParticipant(DOMAIN)
        cmd = DataWriter(dp, Topic(dp, "rt/cmd_vel", m.Twist), qos=reliable())
        odom = DataReader(dp, Topic(dp, "rt/odom", m.Odometry), qos=reliable())
        ping = DataWriter(dp, Topic(dp, "rt/chassis_bench/ping", m.TwistStamped), qos=reliable())
        pong = DataReader(dp, Topic(dp, "rt/chassis_bench/pong", m.Odometry), qos=reliable())
        wait_matched(cmd, "cmd_vel")
        wait_matched(ping, "the echo's ping")
        frames = client_bench.motion_frames(args.chassis, args.robot)

        # Each hop at the pace of the path it divides, warm-up pings first (their hops left out
        # on both sides), as many counted as that path: the cmd_vel hop (the echo's record of
        # the pings) at the command path's, the odom hop (the pongs) at the odom's own period.
        raw_hops(dp, ping, pong, WARMUP + args.commands, interval)
        command, missed = command_path(robot, cmd, frames, args.commands, interval)
        time.sleep(0.6)  # the ros2 source expires: the state path starts from rest
        pairs = state_path(dp, cmd, odom, args.state_samples)
        state = [taken - read for read, taken in pairs]
        (out / "state.pairs").write_text("".join(f"{read} {taken}\n" for read, taken in pairs))
        period = odom_period(pairs)
        raw_out = raw_hops(dp, ping, pong, WARMUP + args.state_samples, period)[WARMUP:]
        (out / "raw-out.period_ns").write_text(f"{round(period * 1e9)}\n")
    finally:
        for proc in (echo, bridge):
            proc.send_signal(signal.SIGTERM)
        for proc in (echo, bridge):
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
    raw_in = [int(x) for x in (out / "raw-in.ns").read_text().split()][WARMUP:]
    raw_in = raw_in[: args.commands]  # the pings of the odom hop follow
    figures = {
        "command": (command, missed),
        "state": (state, 0),
        "raw-in": (raw_in, 0),
        "raw-out": (raw_out, 0),
    }
    for path, (latencies, lost) in figures.items():
        (out / f"{path}.ns").write_text("".join(f"{x}\n" for x in latencies))
        print(json.dumps(client_bench.row(path, args.robot, latencies, lost) | {"client": "ros2"}))
    (out / "command.missed").write_text(f"{missed}\n")
    return 0 if all(lat for lat, _ in figures.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
