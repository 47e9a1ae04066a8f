"""A Cyclone DDS participant standing in for a ROS 2 node on another computer: publishes
``geometry_msgs/Twist`` on ``cmd_vel`` (reliable, as rclcpp's default) at 20 Hz for a while, then
prints how many readers it matched, as JSON. Run by tests/tests/system/ros2_reach.rs inside a
network namespace of its own; the ROS 2 types are clients/ros2/tests/ros2_types.py's."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "clients" / "ros2" / "tests"))

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

import ros2_types as m


def refuse_the_hosts_network() -> None:
    """Exits unless this process runs in a named network namespace (`ip netns exec NAME …`, as
    the test starts it): DDS discovery must never reach a real interface."""
    try:
        name = subprocess.run(
            ["ip", "netns", "identify", str(os.getpid())],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError) as e:
        sys.exit(f"drive_peer.py: cannot tell which network namespace this is ({e}); refusing")
    if not name:
        sys.exit(
            "drive_peer.py: runs only inside a test's network namespace (ip netns exec …), "
            "never on the host's network"
        )


def main() -> None:
    refuse_the_hosts_network()
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--vx", type=float, default=0.3)
    args = parser.parse_args()
    dp = DomainParticipant(args.domain)
    qos = Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.Volatile,
        Policy.History.KeepLast(10),
    )
    writer = DataWriter(dp, Topic(dp, "rt/cmd_vel", m.Twist), qos=qos)
    twist = m.Twist(linear=m.Vector3(x=args.vx), angular=m.Vector3())
    end = time.monotonic() + args.seconds
    matched = 0
    while time.monotonic() < end:
        writer.write(twist)
        matched = max(matched, writer.get_publication_matched_status().current_count)
        time.sleep(0.05)
    print(json.dumps({"matched": matched}))


if __name__ == "__main__":
    main()
