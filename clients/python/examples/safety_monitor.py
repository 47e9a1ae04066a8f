#!/usr/bin/env python3
"""A minimal safety monitor: holds the robot's required ``safety`` source with heartbeats, and
latches the e-stop when the bumper is pressed or a range sensor reads closer than a threshold.

While it beats, the sources below it may drive; if it dies, ``chassisd`` stops the robot at the
source's timeout. Once latched, the robot stays stopped until an operator releases the e-stop
(``chassis control estop-release``).

    python3 safety_monitor.py xbot --stop-m 0.3
"""

from __future__ import annotations

import argparse
import math
import time

import chassis


def lock_mask(mux: chassis.MuxStatus | None, lock: str) -> int:
    """The bit of the lock called ``lock`` in the mux's locks (0 when there is none)."""
    if mux is None:
        return 0
    for i in range(min(mux.lock_count, len(mux.locks))):
        if mux.locks[i].name == lock:
            return 1 << i
    return 0


def danger(state: chassis.ChassisState, stop_m: float) -> str | None:
    """Why the robot must stop now, or None."""
    if state.system.fault_flags & chassis.FaultFlags.BUMPER:
        return "bumper pressed"
    if state.valid_mask & (1 << chassis.Group.RANGES):
        readings = [*state.ranges.ultrasonic_m, *state.ranges.ir_m]
        nearest = min((r if math.isfinite(r) and r >= 0 else 0.0) for r in readings)
        if nearest < stop_m:
            return f"obstacle at {nearest:.2f} m (< {stop_m:.2f} m)"
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", nargs="?", default="titan", help="the robot")
    parser.add_argument("--stop-m", type=float, default=0.3, help="latch below this range, m")
    parser.add_argument("--rate", type=float, default=20.0, help="heartbeats per second")
    parser.add_argument("--source", default="safety", help="the required source to hold")
    args = parser.parse_args()

    robot = chassis.Robot.connect(args.name)
    safety = robot.source(args.source)
    period = 1.0 / args.rate
    in_danger = False
    lock_pending = False
    print(f"holding '{args.source}' of {args.name}", flush=True)
    try:
        while True:
            beat = time.monotonic() + period
            state = robot.wait_state(period)
            reason = danger(state, args.stop_m) if state is not None else None
            if reason is None:
                in_danger = lock_pending = False
                safety.heartbeat()
            else:
                if not in_danger:
                    # Each danger engages the e-stop lock once; chassisd holds it until an
                    # operator releases it (`chassis control estop-release`).
                    in_danger = lock_pending = True
                    print(f"latching the e-stop: {reason}", flush=True)
                mask = lock_mask(robot.latest_mux(), "estop") if lock_pending else 0
                if mask:
                    safety.send(chassis.VelocityRequest(lock_engage=mask))
                    lock_pending = False
                else:
                    # A stop at the safety source's priority meanwhile.
                    safety.stop()
            time.sleep(max(0.0, beat - time.monotonic()))
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    raise SystemExit(main())
