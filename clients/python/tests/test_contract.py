"""The generated module is the generator's output now, and every class matches the contract."""

from __future__ import annotations

import copy
import ctypes
import importlib.util
import json
import os
from pathlib import Path
from types import ModuleType

import pytest
from conftest import PYTHON_DIR, REPO

import chassis
from chassis import _contract

CONTRACT = json.loads((REPO / "interfaces" / "contract.json").read_text())


def generator() -> ModuleType:
    spec = importlib.util.spec_from_file_location("generate", PYTHON_DIR / "generate.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_committed_module_is_what_the_generator_writes_from_the_contract() -> None:
    committed = (PYTHON_DIR / "chassis" / "_contract.py").read_text()
    assert committed == generator().render(CONTRACT), (
        "chassis/_contract.py is stale: run python3 clients/python/generate.py"
    )
    # The package under test is that module, installed (scripts/python-tests says so).
    assert Path(_contract.__file__).read_text() == committed
    if os.environ.get("CHASSIS_PYTHON_INSTALLED"):
        assert "site-packages" in Path(chassis.__file__).parts, chassis.__file__


def test_a_changed_rust_field_changes_the_generated_module() -> None:
    changed = copy.deepcopy(CONTRACT)
    field = changed["types"]["ChassisState"]["fields"][1]
    field["type"] = {"kind": "primitive", "primitive": "i64"}
    assert generator().render(changed) != generator().render(CONTRACT)


def test_every_class_has_the_contracts_size_alignment_offsets_and_type_name() -> None:
    assert sorted(chassis.TYPES) == sorted(CONTRACT["types"])
    for name, described in CONTRACT["types"].items():
        cls = chassis.TYPES[name]
        assert cls.type_name() == described["type_name"], name
        assert ctypes.sizeof(cls) == described["size"], name
        assert ctypes.alignment(cls) == described["align"], name
        assert [f[0] for f in cls._fields_] == [f["name"] for f in described["fields"]], name
        for field in described["fields"]:
            member = getattr(cls, field["name"])
            assert (member.offset, member.size) == (field["offset"], field["size"]), (
                f"{name}.{field['name']}"
            )
    # The request class with constructors is the contract's VelocityRequest.
    assert ctypes.sizeof(chassis.VelocityRequest) == CONTRACT["types"]["VelocityRequest"]["size"]
    assert chassis.VelocityRequest.type_name() == CONTRACT["types"]["VelocityRequest"]["type_name"]


def test_every_constant_has_the_contracts_name_and_value() -> None:
    for group, described in CONTRACT["constants"].items():
        cls = chassis.CONSTANT_GROUPS[group]
        for value in described["values"]:
            assert getattr(cls, value["name"]) == value["value"], f"{group}::{value['name']}"
    both = chassis.FaultFlags.BUMPER | chassis.FaultFlags.OVER_CURRENT
    assert chassis.FaultFlags.names(both) == ["over-current", "bumper"]
    assert chassis.ControlStatus.name(chassis.ControlStatus.REFUSED) == "refused"


def test_names_and_limits_come_from_the_contract() -> None:
    services = {s["name"].split("/")[2]: s for s in CONTRACT["services"]}
    assert chassis.service_name("titan", "state") == services["state"]["name"].replace(
        "{robot}", "titan"
    )
    assert chassis.service_name("left", "cmd", "teleop") == services["cmd"]["name"].format(
        robot="left", source="teleop"
    )
    control = chassis.service_name("titan", "control")
    assert chassis.reply_name(control) == control + CONTRACT["reply_suffix"]
    assert [e["name"] for e in services["control"]["events"]] == [
        "chassis/{robot}/control",
        "chassis/{robot}/control" + CONTRACT["reply_suffix"],
    ]
    assert chassis.STATE_BUFFER == services["state"]["limits"]["subscriber_max_buffer_size"]
    assert chassis.FRAMES_BUFFER == services["frames"]["limits"]["subscriber_max_buffer_size"]
    assert _contract.PREFIX_ENV == CONTRACT["prefix_env"]


def test_every_text_field_reads_and_assigns_as_str_over_unchanged_bytes() -> None:
    marked = [
        (name, field)
        for name, described in CONTRACT["types"].items()
        for field in described["fields"]
        if field.get("text")
    ]
    assert ("RobotDescription", "kind_name") in [(name, f["name"]) for name, f in marked]
    for name, field in marked:
        what = f"{name}.{field['name']}"
        sample = chassis.TYPES[name]()
        assert getattr(sample, field["name"]) == "", what
        text = "é" + "x" * (field["size"] - 2)  # 'é' is two bytes: the field exactly full
        setattr(sample, field["name"], text)
        value = getattr(sample, field["name"])
        assert type(value) is str and value == text, what
        assert sample.to_dict()[field["name"]] == text, what
        start, end = field["offset"], field["offset"] + field["size"]
        assert bytes(sample)[start:end] == text.encode(), what
        # Bytes as a foreign writer may leave them: text ends at the first NUL, and invalid
        # UTF-8 is cut where it starts (as the Rust reader reads it).
        raw = bytearray(bytes(sample))
        raw[start:end] = b"ok\0ignored".ljust(field["size"], b"\0")
        assert getattr(type(sample).from_buffer_copy(raw), field["name"]) == "ok", what
        raw[start:end] = b"ok\xff!".ljust(field["size"], b"\0")
        assert getattr(type(sample).from_buffer_copy(raw), field["name"]) == "ok", what
        with pytest.raises(ValueError, match="longer than"):
            setattr(sample, field["name"], "x" * (field["size"] + 1))
        with pytest.raises(TypeError):
            setattr(sample, field["name"], b"ok")
    # A byte array that is not text stays bytes.
    assert isinstance(chassis.BusFrame().data, ctypes.Array)
    assert isinstance(chassis.ControlRequest().arg, ctypes.Array)
