#!/usr/bin/env python3
"""Latency of the Python client's two paths through a running ``chassisd``.

* **state**: a frame read from the bus (``chassisd`` stamps it right after the read:
  ``ChassisState.stamp_ns``) → this Python process woke with the ``ChassisState`` it changed in
  hand (``CLOCK_MONOTONIC`` right after it was copied out: ``StateStream.each`` hands over
  each sample as it is read, as the Rust client's ``StateStream::wait`` calls its closure). The
  samples are read from a lossless ``StateStream``; by the rule ``chassis-bench`` applies to
  every client alike, a sample counts when its stamp is newer than every stamp received before
  it (a sample the service's tick merely refreshed carries an older frame's read time, and the
  first sample is the one published before the stream opened); gaps in ``seq`` are samples
  lost, counted as dropped. The robot drives throughout (teleop, 0.6 m/s, 0.3 rad/s) so that
  frames keep changing the state.
* **command**: a ``VelocityRequest`` stamped and sent here as the ``teleop`` source → the motion
  frame that ``chassisd`` wrote to the bus (the frame tap's TX stamp, ``BusFrame.stamp_ns``,
  taken right after the write). Requests alternate between two speeds, one every
  ``--interval-ms``; each is a change, so each writes a frame. The frames are recognised by
  their bytes as ``chassis encode --robot ROBOT velocity --vx V`` prints them, so this path needs
  a robot whose motion frame is the same for the same speed (TITAN; SCOUT MINI's frames carry a
  count and a checksum, the XBot's manual caps its rate).

Both figures are one-way, from ``CLOCK_MONOTONIC`` stamps taken in two processes.

Command line::

    python3 clients/python/bench.py [--name titan] [--robot titan] [--prefix P]
        [--state-samples 2000] [--commands 300] [--interval-ms 4]
        [--chassis target/release/chassis] [--paths state,command]

``chassisd`` must be running, a release build for meaningful figures, configured as
``chassis-bench`` configures it — no acceleration smoothing and no minimum spacing between
command frames, else the command path measures the ramp::

    [driver]
    min_command_interval_ms = 0
    brake_idle_engage_ms = 0

    [mux.limits]
    linear_accel_mps2 = 0.0
    angular_accel_radps2 = 0.0

    chassisd --robot titan --no-safety-monitor --config bench.toml

``--prefix`` (or ``CHASSIS_IPC_PREFIX``) is its iceoryx2 prefix. The ``teleop`` source must be
free. ``--chassis`` is the ``chassis`` CLI (default: ``target/release/chassis``, or
``CHASSIS_CLI``).

Output: one JSON object per line on stdout, one per path::

    {"client": "python", "path": "state", "robot": "titan", "samples": 2000, "missed": 0,
     "p50_us": 61.2, "p99_us": 190.4, "max_us": 812.0, "mean_us": 75.3}

``path`` is ``state`` or ``command``; ``samples`` the latencies recorded; ``missed`` the
requests whose frame did not appear within 500 ms (command path; 0 for state); times in µs.
Exit status 0, or 1 when a path recorded nothing.

``--latencies-dir DIR`` also writes every latency, one ns figure a line, to ``DIR/state.ns`` and
``DIR/command.ns`` (and the command path's missed count to ``DIR/command.missed``, the state
path's dropped samples to ``DIR/state.dropped``): ``chassis-bench`` summarises them as it does
the Rust client's. ``DIR/state.stamps`` holds, a line for each state latency, the stamps it
splits at: the frame read, the sample handed to iceoryx2 (``ChassisState.published_ns``), the
stream's wait returned (its wake-up over; when samples were pending already, the moment it
looked) and the sample in hand, ns.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import chassis

STATE_DRIVE = (0.6, 0.3)
SPEEDS = (0.25, 0.5)
FRAME_TIMEOUT_S = 0.5
KEEP_ALIVE_S = 0.05


def percentile(values: list[int], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``, nearest rank."""
    ordered = sorted(values)
    rank = max(0, min(len(ordered) - 1, round(q * len(ordered) + 0.5) - 1))
    return float(ordered[rank])


def row(path: str, robot: str, latencies: list[int], missed: int) -> dict[str, object]:
    """The JSON row of one path."""
    out: dict[str, object] = {
        "client": "python",
        "path": path,
        "robot": robot,
        "samples": len(latencies),
        "missed": missed,
    }
    if latencies:
        out |= {
            "p50_us": round(percentile(latencies, 0.50) / 1e3, 1),
            "p99_us": round(percentile(latencies, 0.99) / 1e3, 1),
            "max_us": round(max(latencies) / 1e3, 1),
            "mean_us": round(sum(latencies) / len(latencies) / 1e3, 1),
        }
    return out


def _said_ranges() -> list[tuple[int, int]]:
    """The byte ranges of a ``ChassisState`` that say something: all but its number, its stamps
    and the link's counters, which every publication changes."""
    kind = chassis.ChassisState
    changing = sorted(
        (field.offset, field.offset + field.size)
        for field in (
            getattr(kind, name)
            for name in ("seq", "stamp_ns", "published_ns", "group_stamp_ns", "link")
        )
    )
    said, at = [], 0
    for start, end in changing:
        if start > at:
            said.append((at, start))
        at = max(at, end)
    if at < ctypes.sizeof(kind):
        said.append((at, ctypes.sizeof(kind)))
    return said


SAID = _said_ranges()


def body(state: chassis.ChassisState) -> bytes:
    """What a sample says, without what every publication changes (:data:`SAID`). Cheap: it
    runs between two bursts, and a sample arriving meanwhile waits for it."""
    raw = bytes(state)
    return b"".join([raw[start:end] for start, end in SAID])


class StateRecorder:
    """The state-path rule every client of ``chassis-bench`` applies alike: a sample counts when
    its stamp is newer than every stamp received before it and it says something the sample
    before it did not (a tick's refresh of a frame that changed nothing is left out); the first
    sample only sets the stamp; gaps in ``seq`` are dropped samples."""

    def __init__(self) -> None:
        self.latencies: list[int] = []
        self.dropped = 0
        self.last_seq: int | None = None
        self.newest_stamp: int | None = None
        self.last_body: bytes | None = None

    def sample(self, state: chassis.ChassisState, received: int) -> bool:
        """Takes one received sample; whether it counted."""
        if self.last_seq is not None:
            if state.seq <= self.last_seq:
                return False
            self.dropped += state.seq - self.last_seq - 1
        self.last_seq = state.seq
        said = body(state)
        nothing_new = said == self.last_body
        self.last_body = said
        if self.newest_stamp is None:
            self.newest_stamp = state.stamp_ns
            return False
        if state.stamp_ns <= self.newest_stamp or nothing_new:
            self.newest_stamp = max(self.newest_stamp, state.stamp_ns)
            return False
        self.newest_stamp = state.stamp_ns
        self.latencies.append(received - state.stamp_ns)
        return True


class StampedListener:
    """A stream's listener that notes when its last wait returned: where the wake-up ends and
    the stream's reading of the samples begins, a boundary of ``chassis-bench``'s split."""

    def __init__(self, listener: Any) -> None:
        self._listener = listener
        self.returned_ns = 0

    def try_wait(self) -> Any:
        """The listener's ``try_wait``, stamped."""
        out = self._listener.try_wait()
        self.returned_ns = chassis.now_ns()
        return out

    def timed_wait(self, timeout: Any) -> Any:
        """The listener's ``timed_wait``, stamped."""
        out = self._listener.timed_wait(timeout)
        self.returned_ns = chassis.now_ns()
        return out


def state_path(
    robot: chassis.Robot, teleop: chassis.Source, samples: int
) -> tuple[StateRecorder, list[tuple[int, int, int, int]]]:
    """State-path latencies, ns, and the samples dropped; and for each latency its stamps
    ``(frame read, handed to iceoryx2, the stream's wait returned, the sample in hand)``."""
    stream = robot.state_stream()
    # The stream's own listener, stamped (the package has no hook for it: this is the bench's).
    listener = StampedListener(stream._reader.listener)  # noqa: SLF001
    stream._reader.listener = listener  # noqa: SLF001
    recorder = StateRecorder()
    stamps: list[tuple[int, int, int, int]] = []
    last_request = 0
    deadline = time.monotonic() + 120
    while len(recorder.latencies) < samples and time.monotonic() < deadline:
        if chassis.now_ns() - last_request > KEEP_ALIVE_S * 1e9:
            teleop.twist(*STATE_DRIVE)
            last_request = chassis.now_ns()
        # Each sample is stamped as it is read, as the Rust client's callback stamps it; the
        # rule runs once the burst is read, so that no sample of it waits on the rule's work.
        burst = [(state, listener.returned_ns, chassis.now_ns()) for state in stream.each(0.02)]
        for state, returned, received in burst:
            if recorder.sample(state, received):
                stamps.append((state.stamp_ns, state.published_ns, returned, received))
    teleop.stop()
    return recorder, stamps


def motion_frames(chassis_cli: str, robot: str) -> dict[float, tuple[int, bytes]]:
    """The motion frame (CAN id, data) ``chassisd`` writes for each of :data:`SPEEDS`."""
    frames = {}
    for speed in SPEEDS:
        out = subprocess.run(
            [chassis_cli, "encode", "--robot", robot, "velocity", "--vx", str(speed)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
        if len(out) != 1 or "#" not in out[0]:
            raise SystemExit(f"bench.py: {robot}'s motion is not one CAN frame: {out}")
        can_id, data = out[0].split("#")
        frames[speed] = (int(can_id, 16), bytes.fromhex(data))
    return frames


def wait_for_frame(tap: chassis.FrameTap, frame: tuple[int, bytes], since: int) -> int | None:
    """The TX stamp of ``frame`` written at or after ``since``, or None after the timeout."""
    can_id, data = frame
    deadline = time.monotonic() + FRAME_TIMEOUT_S
    while time.monotonic() < deadline:
        for f in tap.wait(0.005):
            if (
                f.direction == chassis.FrameDirection.TX
                and f.can_id == can_id
                and f.stamp_ns >= since
                and bytes(f.data)[: f.len] == data
            ):
                return int(f.stamp_ns)
    return None


def paced_commands(
    robot: chassis.Robot,
    frames: dict[float, tuple[int, bytes]],
    count: int,
    interval_s: float,
    send: Callable[[float], int],
    warmups: int,
) -> tuple[list[int], int]:
    """Command-path latencies, ns, and the requests whose frame never appeared: one request
    every ``interval_s``, alternating between the two ``SPEEDS`` so that each writes a frame.
    ``send(speed)`` asks for ``speed`` and returns the stamp the request was made at; up to
    ``warmups`` first requests wait for the first frame (the TITAN's brake released, its
    command mode reached) and are not counted."""
    tap = robot.frames(chassis.FRAMES_BUFFER)
    start = chassis.now_ns()
    for _ in range(warmups):
        send(SPEEDS[0])
        if wait_for_frame(tap, frames[SPEEDS[0]], start) is not None:
            break
    latencies: list[int] = []
    missed = 0
    next_send = time.monotonic()
    for i in range(count):
        next_send += interval_s
        time.sleep(max(0.0, next_send - time.monotonic()))
        tap.drain()
        speed = SPEEDS[1] if i % 2 == 0 else SPEEDS[0]
        stamp = send(speed)
        written = wait_for_frame(tap, frames[speed], stamp)
        if written is None:
            missed += 1
        else:
            latencies.append(written - stamp)
    return latencies, missed


def command_path(
    robot: chassis.Robot,
    teleop: chassis.Source,
    frames: dict[float, tuple[int, bytes]],
    count: int,
    interval_s: float,
) -> tuple[list[int], int]:
    """Command-path latencies, ns, and the requests whose frame never appeared."""

    def send(speed: float) -> int:
        request = chassis.VelocityRequest.twist(speed, 0.0)
        request.stamp_ns = stamp = chassis.now_ns()
        teleop.send(request)
        return stamp

    result = paced_commands(robot, frames, count, interval_s, send, warmups=7)
    teleop.stop()
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", default="titan", help="the robot's name (chassisd --name)")
    parser.add_argument("--robot", default="titan", help="its kind, for `chassis encode`")
    parser.add_argument("--prefix", default=None, help="iceoryx2 prefix (CHASSIS_IPC_PREFIX)")
    parser.add_argument("--state-samples", type=int, default=2000)
    parser.add_argument("--commands", type=int, default=300)
    parser.add_argument("--interval-ms", type=float, default=4.0)
    parser.add_argument("--paths", default="state,command")
    default_cli = Path(__file__).resolve().parents[2] / "target" / "release" / "chassis"
    parser.add_argument("--chassis", default=os.environ.get("CHASSIS_CLI", str(default_cli)))
    parser.add_argument("--latencies-dir", default=None, help="write every latency here")
    args = parser.parse_args()
    paths = args.paths.split(",")

    robot = chassis.Robot.connect(args.name, prefix=args.prefix)
    teleop = robot.source("teleop")
    rows = []
    out = Path(args.latencies_dir) if args.latencies_dir else None
    if "state" in paths:
        recorder, stamps = state_path(robot, teleop, args.state_samples)
        latencies = recorder.latencies
        rows.append(row("state", args.robot, latencies, 0) | {"dropped": recorder.dropped})
        if out:
            (out / "state.ns").write_text("".join(f"{ns}\n" for ns in latencies))
            (out / "state.dropped").write_text(f"{recorder.dropped}\n")
            (out / "state.stamps").write_text("".join(" ".join(map(str, s)) + "\n" for s in stamps))
    if "command" in paths:
        frames = motion_frames(args.chassis, args.robot)
        latencies, missed = command_path(
            robot, teleop, frames, args.commands, args.interval_ms / 1e3
        )
        rows.append(row("command", args.robot, latencies, missed))
        if out:
            (out / "command.ns").write_text("".join(f"{ns}\n" for ns in latencies))
            (out / "command.missed").write_text(f"{missed}\n")
    for r in rows:
        print(json.dumps(r), flush=True)
    return 0 if all(r["samples"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
