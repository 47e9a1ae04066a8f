#!/usr/bin/env python3
"""Drives a square closed on odometry: a leg until the odometry has covered the side, a turn in
place until the yaw has changed by 90°, four times. For robots that turn in place (SCOUT MINI,
XBot); an Ackermann TITAN cannot.

    python3 drive_square.py scout-mini --side 1.0
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import chassis


def wrap(angle: float) -> float:
    """``angle`` in -π..π."""
    return math.atan2(math.sin(angle), math.cos(angle))


def steer_until(
    robot: chassis.Robot,
    source: chassis.Source,
    command: Callable[[chassis.ChassisState], chassis.VelocityRequest | None],
    timeout: float,
) -> chassis.ChassisState:
    """Sends ``command(state)`` for each new state until it returns None, then stops and waits
    for the robot to stand still; raises TimeoutError after ``timeout`` s."""
    end = time.monotonic() + timeout
    state = robot.latest_state()
    while True:
        request = command(state) if state is not None else chassis.VelocityRequest.twist(0, 0)
        if request is None:
            break
        source.send(request)
        state = robot.wait_state(0.05) or state
        if time.monotonic() > end:
            raise TimeoutError("the robot did not get there: is it in command mode?")
    while True:
        source.stop()
        state = robot.wait_state(0.05) or state
        moving = abs(state.motion.linear_mps) > 0.005 or abs(state.motion.angular_radps) > 0.005
        if not moving:
            return state
        if time.monotonic() > end:
            raise TimeoutError("the robot does not stop")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", nargs="?", default="scout-mini", help="the robot")
    parser.add_argument("--side", type=float, default=1.0, help="side of the square, m")
    parser.add_argument("--speed", type=float, default=0.4, help="forward speed, m/s")
    parser.add_argument("--turn-rate", type=float, default=0.8, help="yaw rate, rad/s")
    parser.add_argument("--source", default="teleop", help="the configured source to drive as")
    parser.add_argument("--timeout", type=float, default=30.0, help="per leg or turn, s")
    args = parser.parse_args()

    robot = chassis.Robot.connect(args.name)
    source = robot.source(args.source)
    state = robot.wait_state(1.0) or robot.latest_state()
    if state is None:
        raise SystemExit(f"{args.name} publishes no state")
    start = state.odometry
    print(f"start x {start.x_m:+.3f} y {start.y_m:+.3f} yaw {start.yaw_rad:+.3f}", flush=True)
    try:
        for corner in range(1, 5):
            # Targets from the start pose, so that errors do not add up from corner to corner.
            heading = start.yaw_rad + (corner - 1) * math.pi / 2
            x0, y0 = state.odometry.x_m, state.odometry.y_m

            def forward(
                s: chassis.ChassisState, x0: float = x0, y0: float = y0
            ) -> chassis.VelocityRequest | None:
                left = args.side - math.hypot(s.odometry.x_m - x0, s.odometry.y_m - y0)
                if left < 0.01:
                    return None
                return chassis.VelocityRequest.twist(min(args.speed, max(0.05, 1.5 * left)), 0.0)

            def turn(
                s: chassis.ChassisState, target: float = heading + math.pi / 2
            ) -> chassis.VelocityRequest | None:
                error = wrap(target - s.odometry.yaw_rad)
                if abs(error) < 0.02:
                    return None
                rate = min(args.turn_rate, max(0.1, 2.0 * abs(error)))
                return chassis.VelocityRequest.twist(0.0, math.copysign(rate, error))

            state = steer_until(robot, source, forward, args.timeout)
            state = steer_until(robot, source, turn, args.timeout)
            odo = state.odometry
            print(f"corner {corner}: x {odo.x_m:+.3f} y {odo.y_m:+.3f} yaw {odo.yaw_rad:+.3f}")
    finally:
        source.stop()
    error = math.hypot(state.odometry.x_m - start.x_m, state.odometry.y_m - start.y_m)
    print(f"back at the start within {error:.3f} m", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
