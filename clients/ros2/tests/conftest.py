"""Fixtures for the ROS 2 bridge's tests: real ``chassisd`` and ``chassis-ros2`` processes, and a
Cyclone DDS participant standing in for a ROS 2 node.

DDS discovery multicasts. These tests refuse to run anywhere but in a network namespace of
their own whose only interface is the loopback (``scripts/ros2-tests`` makes one with
``unshare --net``), so that no discovery packet ever leaves the machine.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "python" / "tests"))

from world import World, binary, wait_until  # noqa: E402

__all__ = ["Ros", "World", "binary", "wait_until"]

_domains = itertools.count(10)


def interfaces() -> list[str]:
    """This network namespace's interfaces (``/proc/net/dev`` is per namespace; ``/sys`` may
    still show the machine's)."""
    with open("/proc/net/dev") as f:
        return sorted(line.split(":")[0].strip() for line in f.readlines()[2:])


def pytest_configure(config: pytest.Config) -> None:
    if interfaces() != ["lo"]:
        raise pytest.UsageError(
            "the ROS 2 bridge tests run DDS discovery: run them through scripts/ros2-tests, "
            "in a network namespace with only a loopback "
            f"(this one has {', '.join(interfaces())})"
        )


class Ros(World):
    """A world with a DDS domain of its own, shared by the bridge and the test's participant."""

    def __init__(self, tmp: Path) -> None:
        super().__init__(tmp)
        self.domain = next(_domains)
        self.env["ROS_DOMAIN_ID"] = str(self.domain)
        self.env["RMW_IMPLEMENTATION"] = "rmw_cyclonedds_cpp"
        self.env["RUST_LOG"] = "info,rustdds=error,ros2_client=warn"

    def bridge(self, name: str, *args: str, label: str = "chassis-ros2") -> None:
        """Starts ``chassis-ros2 --name name args…``."""
        self.spawn(label, [str(binary("chassis-ros2")), "--name", name, *args])


@pytest.fixture
def ros(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Ros]:
    w = Ros(tmp_path)
    yield w
    w.close()
    report = getattr(request.node, "rep_call", None)
    if report is not None and report.failed:
        print(w.logs())


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    report = yield
    if report.when == "call":
        item.rep_call = report  # type: ignore[attr-defined]
    return report
