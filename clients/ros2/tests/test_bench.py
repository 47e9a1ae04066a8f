"""The ROS 2 benchmark script's own rules (``clients/ros2/bench.py``)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import bench  # noqa: E402


def test_the_odom_hop_keeps_the_counted_odoms_period_off_the_chassis_grid() -> None:
    # An odom every 20 ms, two of them not counted (a 40 ms gap each).
    reads = [i * 20_000_000 for i in range(30) if i not in (7, 19)]
    pairs = [(read, read + 500_000) for read in reversed(reads)]
    assert bench.odom_period(pairs) == pytest.approx(0.020 * 1.017)


def test_the_odom_hop_keeps_20_ms_when_too_few_odoms_were_counted() -> None:
    pairs = [(i * 7_000_000, 0) for i in range(5)]
    assert bench.odom_period(pairs) == pytest.approx(0.020 * 1.017)
