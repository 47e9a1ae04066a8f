#!/usr/bin/env python3
"""Prints a robot's state at 10 Hz: speed, odometry, battery, faults and the mux's choice.

python3 monitor.py titan            # until Ctrl-C
python3 monitor.py titan --count 20 # 20 lines (2 s), then exit
"""

from __future__ import annotations

import argparse
import time

import chassis


def line(state: chassis.ChassisState, mux: chassis.MuxStatus | None) -> str:
    """One line of the robot's state."""
    active = mux.active_source_name() if mux else None
    return (
        f"#{state.seq:<8} v {state.motion.linear_mps:+.3f} m/s  w {state.motion.angular_radps:+.3f}"
        f" rad/s  x {state.odometry.x_m:+8.3f} y {state.odometry.y_m:+8.3f}"
        f" yaw {state.odometry.yaw_rad:+.3f}  battery {state.system.battery_voltage_v:.1f} V"
        f"  faults {chassis.FaultFlags.name(state.system.fault_flags)}"
        f"  source {active or '-'}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("name", nargs="?", default="titan", help="the robot (chassisd --name)")
    parser.add_argument("--rate", type=float, default=10.0, help="lines per second")
    parser.add_argument("--count", type=int, default=0, help="lines to print (0: until Ctrl-C)")
    args = parser.parse_args()
    robot = chassis.Robot.connect(args.name)
    period = 1.0 / args.rate
    printed = 0
    next_line = time.monotonic()
    try:
        while args.count == 0 or printed < args.count:
            next_line += period
            robot.wait_state(max(0.0, next_line - time.monotonic()))
            time.sleep(max(0.0, next_line - time.monotonic()))
            state = robot.latest_state()
            if state is None:
                print("no state yet", flush=True)
            else:
                print(line(state, robot.latest_mux()), flush=True)
            printed += 1
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
