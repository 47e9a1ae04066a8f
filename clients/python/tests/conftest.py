"""Fixtures starting real ``chassisd`` processes, each with its own iceoryx2 prefix."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from world import PYTHON_DIR, REPO, UP_S, World, binary, remove_ipc_files, wait_until

__all__ = ["PYTHON_DIR", "REPO", "UP_S", "World", "binary", "remove_ipc_files", "wait_until"]


@pytest.fixture
def world(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[World]:
    w = World(tmp_path)
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
