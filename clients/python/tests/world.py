"""Shared by the test suites that start real ``chassisd`` processes (this package's and the
ROS 2 bridge's): a test's world of processes, each world with its own iceoryx2 prefix."""

from __future__ import annotations

import gc
import glob
import itertools
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

import chassis

REPO = Path(__file__).resolve().parents[3]
BIN_DIR = Path(os.environ.get("CHASSIS_BIN_DIR", REPO / "target" / "debug"))
PYTHON_DIR = REPO / "clients" / "python"
UP_S = 20.0
_counter = itertools.count()


def binary(name: str) -> Path:
    path = BIN_DIR / name
    if not path.exists():
        pytest.fail(f"{path} is missing: run `cargo build --workspace --bins`")
    return path


def remove_ipc_files(prefix: str) -> None:
    """Removes the iceoryx2 files of ``prefix`` once its processes are gone."""
    for pattern in ("/dev/shm/{}*", "/tmp/iceoryx2/{}*", "/tmp/iceoryx2/*/{}*"):
        for path in glob.glob(pattern.format(prefix)):
            if os.path.isdir(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                try:
                    os.remove(path)
                except OSError:
                    pass


class World:
    """One test's processes, all sharing its iceoryx2 prefix."""

    def __init__(self, tmp: Path) -> None:
        self.prefix = f"cpy{os.getpid()}_{next(_counter)}_"
        self.tmp = tmp
        # Each world keeps chassisd's held locks (the e-stop) in a state directory of its own.
        self.env = dict(
            os.environ,
            CHASSIS_IPC_PREFIX=self.prefix,
            RUST_LOG="info",
            XDG_STATE_HOME=str(tmp / "state"),
        )
        self.procs: list[tuple[str, subprocess.Popen[bytes], Path]] = []
        self.robots: list[chassis.Robot] = []

    def spawn(self, label: str, argv: list[str]) -> subprocess.Popen[bytes]:
        log = self.tmp / f"{label}.log"
        with log.open("wb") as out:
            proc = subprocess.Popen(
                argv, env=self.env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
            )
        self.procs.append((label, proc, log))
        return proc

    def chassisd(self, robot: str, *args: str, safety: bool = False) -> chassis.Robot:
        """Starts ``chassisd --robot robot`` (without the safety rule unless ``safety``) and
        connects once its first state is out."""
        argv = [str(binary("chassisd")), "--robot", robot, *args]
        if not safety:
            argv.append("--no-safety-monitor")
        self.spawn(f"chassisd-{robot}", argv)
        name = args[args.index("--name") + 1] if "--name" in args else robot
        return self.connect(name)

    def connect(self, name: str) -> chassis.Robot:
        end = time.monotonic() + UP_S
        while True:
            try:
                robot = chassis.Robot.connect(name, prefix=self.prefix)
                if robot.wait_state(0.2) is not None:
                    self.robots.append(robot)
                    return robot
            except chassis.NotServed:
                pass
            if time.monotonic() > end:
                pytest.fail(f"chassis/{name} did not come up within {UP_S} s\n{self.logs()}")
            time.sleep(0.05)

    def chassis(self, *args: str) -> subprocess.CompletedProcess[str]:
        """Runs the ``chassis`` CLI to completion."""
        return subprocess.run(
            [str(binary("chassis")), *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=60,
        )

    def python(self, label: str, *args: str) -> subprocess.Popen[bytes]:
        """Starts ``python args…`` (the package is installed in this interpreter)."""
        return self.spawn(label, [sys.executable, *args])

    def logs(self) -> str:
        return "\n".join(
            f"----- {label} -----\n{log.read_text(errors='replace')}"
            for label, _, log in self.procs
        )

    def close(self) -> None:
        # The test's own iceoryx2 nodes go first, before the files they use.
        self.robots.clear()
        gc.collect()
        for _, proc, _ in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for _, proc, _ in self.procs:
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        remove_ipc_files(self.prefix)


def wait_until(
    what: str, condition: Callable[[], bool], timeout: float, world: World | None = None
) -> None:
    """Polls ``condition`` until it holds; fails the test after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(f"{what}: not within {timeout} s\n{world.logs() if world else ''}")
        time.sleep(0.02)
