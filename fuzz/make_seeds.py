#!/usr/bin/env python3
"""Writes the fuzz seed corpus (fuzz/seeds/<target>/), one file per real example.

* CAN robots: every example frame quoted in the manuals (docs/PROTOCOLS.md, and the cited test
  vectors TV1-TV17 of the AgileX V2 reading), as id (u16 LE) + data, behind the target's own
  leading byte where it has one.
* slcan: lines as a CANable / USBtin sends and answers them.
* Zenoh: IPC samples packed from interfaces/contract.json, the layout chassis-zenoh puts on the
  wire (native byte order), as the bridge sends them.
* Foxglove: what @foxglove/ws-protocol clients send: the Teleop panel's Twist (JSON.stringify of
  its message) and service call requests.

Run it again after changing a seed: `python3 fuzz/make_seeds.py`.
"""

import json
import math
import pathlib
import struct
from typing import Any

HERE = pathlib.Path(__file__).parent
ROOT = HERE / "seeds"
CONTRACT = json.loads((HERE.parent / "interfaces" / "contract.json").read_text())


def can(id_: int, hex_: str) -> bytes:
    return id_.to_bytes(2, "little") + bytes.fromhex(hex_)


# ---------------------------------------------------------------------------------------------
# AgileX protocol V2: the leading byte picks the profile (low nibble: the model, in the order of
# fuzz_targets/agilex_v2_decode.rs; high bits: flipped doubtful choices).
V2_MODELS = [
    "scout",
    "scout-mini",
    "scout-mini-omni",
    "hunter",
    "hunter-se",
    "tracer",
    "bunker",
    "ranger-mini",
    "ranger-mini-v1",
    "tracer-mini",
]


def v2(model: str, id_: int, hex_: str, flips: int = 0) -> bytes:
    return bytes([V2_MODELS.index(model) | flips]) + can(id_, hex_)


# ---------------------------------------------------------------------------------------------
# IPC samples packed from the contract.
FORMATS = {
    "u8": "B",
    "u16": "H",
    "u32": "I",
    "u64": "Q",
    "i8": "b",
    "i16": "h",
    "i32": "i",
    "i64": "q",
    "f32": "f",
    "f64": "d",
}


def const(group: str, name: str) -> int:
    return next(v["value"] for v in CONTRACT["constants"][group]["values"] if v["name"] == name)


def locate(type_name: str, path: str) -> tuple[int, dict[str, Any]]:
    """Offset and field type of a dotted path (`motion.linear_mps`, `sources.0.name`)."""
    offset = 0
    ty: dict[str, Any] = {"kind": "struct", "struct": type_name}
    for part in path.split("."):
        if ty["kind"] == "struct":
            field = next(f for f in CONTRACT["types"][ty["struct"]]["fields"] if f["name"] == part)
            offset += field["offset"]
            ty = field["type"]
        else:
            index = int(part)
            assert ty["kind"] == "array" and index < ty["len"], path
            ty = ty["element"]
            offset += index * size_of(ty)
    return offset, ty


def size_of(ty: dict[str, Any]) -> int:
    if ty["kind"] == "primitive":
        return struct.calcsize(FORMATS[ty["primitive"]])
    if ty["kind"] == "array":
        return ty["len"] * size_of(ty["element"])
    return CONTRACT["types"][ty["struct"]]["size"]


def ipc(type_name: str, values: dict[str, Any]) -> bytes:
    """The bytes of one `type_name` sample: zeros, then `values` by dotted path."""
    buf = bytearray(CONTRACT["types"][type_name]["size"])
    for path, value in values.items():
        offset, ty = locate(type_name, path)
        if isinstance(value, (str, bytes)):
            text = value.encode() if isinstance(value, str) else value
            assert ty["kind"] == "array" and len(text) <= ty["len"], path
            buf[offset : offset + len(text)] = text
        else:
            struct.pack_into("=" + FORMATS[ty["primitive"]], buf, offset, value)
    return bytes(buf)


# The leading byte of zenoh_payload: the type, in the order of fuzz_targets/zenoh_payload.rs.
PAYLOAD_TYPES = [
    "VelocityRequest",
    "ControlRequest",
    "ChassisState",
    "MuxStatus",
    "BusFrame",
    "ControlResponse",
    "RobotDescription",
]
STAMP = 1_700_000_000_000_000_000


def payload(type_name: str, *samples: dict[str, Any]) -> bytes:
    return bytes([PAYLOAD_TYPES.index(type_name)]) + b"".join(ipc(type_name, s) for s in samples)


def media_type(type_name: str) -> str:
    return f"application/octet-stream;{CONTRACT['types'][type_name]['type_name']}"


def frame(seq: int, can_id: int, direction: str, hex_: str) -> dict[str, Any]:
    data = bytes.fromhex(hex_)
    return {
        "stamp_ns": STAMP + seq,
        "seq": seq,
        "can_id": can_id,
        "direction": const("FrameDirection", direction),
        "kind": const("FrameKind", "CAN"),
        "len": len(data),
        "data": data,
    }


TWIST = {"stamp_ns": STAMP, "seq": 7, "linear_x_mps": 0.5, "angular_z_radps": -0.25}

# ---------------------------------------------------------------------------------------------
# Foxglove: a Twist channel message has a leading byte < 0x80 (bits 0-1: the channel's schema,
# 0 geometry_msgs/Twist, 1 geometry_msgs/msg/Twist; bit 2: cdr instead of json); a service call
# 0x80 + the service's index in ServiceAction::ALL.
SERVICES = [
    "/estop",
    "/estop_release",
    "/clear_faults",
    "/mode",
    "/brake",
    "/lights",
    "/off_road",
    "/lift",
    "/servos",
    "/power",
    "/steering_zero",
    "/silent",
]


def teleop(field: str, value: float, schema: int = 0) -> bytes:
    message = {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}
    part, axis = field.split("-")
    message[part][axis] = value
    return bytes([schema]) + json.dumps(message, separators=(",", ":")).encode()


def service(name: str, request: str) -> bytes:
    return bytes([0x80 | SERVICES.index(name)]) + request.encode()


SEEDS = {
    "titan_decode": {
        "motion-150mm": can(0x111, "0096000000000000"),
        "mode-can": can(0x421, "01"),
        "brake-release": can(0x131, "01"),
        "status-heartbeat-lost": can(0x211, "000101E000000200"),
        "steering-zero-ack": can(0x43A, "EE"),
        "bms-alarm": can(0x362, "84010200"),
    },
    "agilex_v1_decode": {
        "forward-0.5": can(0x130, "01000A0000000044"),
        "rotate-10pct": can(0x130, "0100000A00000044"),
        "command-mode": can(0x130, "010000000000003A"),
        "bad-checksum": can(0x130, "01000A0000000045"),
    },
    "agilex_v2_decode": {
        "tv1-hunter-150mm": v2("hunter", 0x111, "0096000000000000"),
        "tv2-hunter-steer-200mrad": v2("hunter", 0x111, "00000000000000C8"),
        "tv3-scout-50mrad-s": v2("scout", 0x111, "0000003200000000"),
        "tv4-bunker-200mrad-s": v2("bunker", 0x111, "000000C800000000"),
        "tv5-bunker-250mm": v2("bunker", 0x111, "00FA000000000000"),
        "tv6-scout-can-mode": v2("scout", 0x421, "0100000000000000"),
        "tv7-scout-standby": v2("scout", 0x421, "0000000000000000"),
        "tv8-bunker-estop": v2("bunker", 0x211, "0100010000800000"),
        "tv9-bunker-motion-zero": v2("bunker", 0x221, "0000000000000000"),
        "tv10-bunker-rc": v2("bunker", 0x241, "AA00000000000061"),
        "tv11-bunker-odometer": v2("bunker", 0x311, "0000000000000000"),
        "tv12-bunker-estop-can": v2("bunker", 0x211, "010100FE00800000"),
        "tv13-tracer-light-off": v2("tracer", 0x121, "0100000000000000"),
        "tv14-sdk-version-request": v2("scout", 0x4A1, "01"),
        "tv15-version-request": v2("scout", 0x411, "01"),
        "tv16-hunter-steering-zero": v2("hunter", 0x431, "AA"),
        "tv16-hunter-steering-zero-ack": v2("hunter", 0x43A, "EE"),
        "tv17-hunter-se-zero-query": v2("hunter-se", 0x433, "AA"),
        "ranger-motion-mode": v2("ranger-mini", 0x141, "01"),
        "ranger-v1-steering-angles": v2("ranger-mini-v1", 0x271, "03E803E803E803E8"),
        "bms-protection-codes": v2("bunker", 0x362, "0100000023FB0007", flips=0x10),
        "sdk-version-text": v2("scout", 0x4A1, "4147582D56322E30"),
    },
    "xbot_stream": {
        "power-on": b"\x01" + bytes.fromhex("AA5502010102"),
        "forward-0.2": b"\x05" + bytes.fromhex("AA550D03CDCC4C3E00000000000000007D"),
        "lift-10": b"\x02" + bytes.fromhex("AA550304010A0C"),
        "servos": b"\x03" + bytes.fromhex("AA550305005A5C"),
        "sensor": b"\x10"
        + bytes.fromhex(
            "AA5547100162260302000100000005"
            "0A00060000000000060003000000000000050000000000000000"
            "E80301000000000000000000000000000000000000000000000000000000000002DC2F"
        ),
        "garbage-then-frame": b"\x04" + bytes.fromhex("00AA12AA55AA5502010102"),
    },
    "nmea_stream": {
        "gga": b"$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76\r\n",
        "rmc-no-fix": b"$GPRMC,235947.000,V,0000.0000,N,00000.0000,E,,,041299,,*1D\r\n",
    },
    "candump_text": {
        "frame": b"111#0096000000000000",
        "log-line": b"(1700000000.000000) can0 123#DEADBEEF",
    },
    # Leading byte: the chunk size the stream is fed in.
    "slcan_stream": {
        "frame-with-timestamp": b"\x05t1238112233445566778899AA\r",
        "titan-motion": b"\x40t11180096000000000000\r",
        "extended": b"\x03T18FF000120102\r",
        "open-and-acks": b"\x02C\rS6\rO\r\r\r\rz\rz\r",
        "bell-error": b"\x01\x07t43A1EE\r",
        "version-replies": b"\x04V1013\rNSIM1\rF00\r",
        "crlf-lines": b"\x07t43A1EE\r\nt2110\r\n",
        "overlong-then-frame": b"\x10" + b"t" * 40 + b"\rt43A1EE\r",
    },
    "zenoh_payload": {
        "velocity-twist": payload("VelocityRequest", TWIST),
        "velocity-steer": payload(
            "VelocityRequest",
            {
                "stamp_ns": STAMP,
                "seq": 8,
                "linear_x_mps": 0.3,
                "steer_rad": 0.2,
                "flags": const("RequestFlags", "STEER"),
            },
        ),
        "velocity-heartbeat": payload(
            "VelocityRequest",
            {"stamp_ns": STAMP, "seq": 9, "flags": const("RequestFlags", "HEARTBEAT")},
        ),
        "velocity-limit": payload(
            "VelocityRequest",
            {
                "stamp_ns": STAMP,
                "seq": 10,
                "flags": const("RequestFlags", "LIMIT"),
                "limit_forward_mps": 0.0,
                "limit_reverse_mps": 0.5,
                "limit_lateral_mps": 0.5,
                "limit_angular_radps": 1.0,
            },
        ),
        "velocity-nan": payload("VelocityRequest", {**TWIST, "linear_x_mps": math.nan}),
        "control-estop-release": payload(
            "ControlRequest",
            {
                "stamp_ns": STAMP,
                "seq": 1,
                "kind": const("ControlKind", "LOCK_RELEASE"),
                "name": "estop",
            },
        ),
        "control-lights": payload(
            "ControlRequest",
            {
                "stamp_ns": STAMP,
                "seq": 2,
                "kind": const("ControlKind", "LIGHTS"),
                "arg.0": const("LightMode", "CUSTOM"),
                "arg.1": 40,
                "arg.2": 1,
            },
        ),
        "control-lift": payload(
            "ControlRequest",
            {
                "stamp_ns": STAMP,
                "seq": 3,
                "kind": const("ControlKind", "LIFT"),
                "arg.0": 1,
                "value.0": 50.0,
            },
        ),
        "state-titan": payload(
            "ChassisState",
            {
                "seq": 1000,
                "stamp_ns": STAMP,
                # The TITAN's kind number (chassis_protocols::RobotKind::Titan.id()): the kind
                # is the registry's key, not a constant of the contract.
                "robot": 1,
                "motion.linear_mps": 0.5,
                "motion.angular_radps": 0.1,
                "odometry.x_m": 1.5,
                "system.battery_voltage_v": 25.6,
                "system.battery_soc_pct": 80.0,
            },
        ),
        "mux-three-sources": payload(
            "MuxStatus",
            {
                "stamp_ns": STAMP,
                "seq": 50,
                "source_count": 3,
                "lock_count": 1,
                "active_source": 1,
                "active_priority": 50,
                "sources.0.name": "safety",
                "sources.0.priority": 100,
                "sources.0.flags": const("SourceFlags", "REQUIRED") | const("SourceFlags", "FRESH"),
                "sources.1.name": "teleop",
                "sources.1.priority": 50,
                "sources.1.flags": const("SourceFlags", "ACTIVE") | const("SourceFlags", "FRESH"),
                "sources.2.name": "remote",
                "sources.2.priority": 40,
                "sources.2.flags": const("SourceFlags", "REMOTE"),
                "locks.0.name": "estop",
                "locks.0.priority": 255,
            },
        ),
        "frames-batch": payload(
            "BusFrame",
            frame(1, 0x211, "RX", "0001010000000000"),
            frame(2, 0x111, "TX", "0096000000000000"),
        ),
        "response-ok": payload(
            "ControlResponse",
            {
                "stamp_ns": STAMP,
                "request_seq": 1,
                "status": const("ControlStatus", "OK"),
                "message": "estop released",
            },
        ),
        # An XBot as chassisd describes it: one range sensor, one wheel joint, one source.
        "description-xbot": payload(
            "RobotDescription",
            {
                "seq": 1,
                "stamp_ns": STAMP,
                # The XBot's kind number (chassis_protocols::RobotKind::Xbot.id()).
                "kind": 3,
                "sensor_count": 1,
                "joint_count": 1,
                "source_count": 1,
                "name": "xbot",
                "kind_name": "xbot",
                "geometry.wheel_radius_m": 0.0625,
                "sensors.0.name": "ultrasonic_front_centre",
                "sensors.0.kind": const("SensorKind", "ULTRASONIC"),
                "sensors.0.max_range_m": 6.0,
                "joints.0.name": "front_left_wheel_joint",
                "joints.0.source": const("JointSource", "WHEEL"),
                "sources.0.name": "safety",
                "sources.0.priority": 255,
            },
        ),
        # A velocity request under a state's media type (bit 7: another type's).
        "velocity-as-state": bytes([0x80 | (2 << 3)]) + ipc("VelocityRequest", TWIST),
        # The media type spelled out (bit 6), then a NUL, then the bytes.
        "velocity-media-type-text": bytes([0x40])
        + media_type("VelocityRequest").encode()
        + b"\0"
        + ipc("VelocityRequest", TWIST),
    },
    "foxglove_client": {
        "teleop-up": teleop("linear-x", 1),
        "teleop-down": teleop("linear-x", -1),
        "teleop-left": teleop("angular-z", 1),
        "teleop-right": teleop("angular-z", -1, schema=1),
        "teleop-omni": teleop("linear-y", 0.5),
        "twist-partial": b"\x00" + b'{"linear":{"x":0.5},"angular":{"z":0}}',
        "twist-on-cdr": b"\x04" + b'{"linear":{"x":0.5}}',
        "twist-beyond-f32": b"\x00" + b'{"linear":{"x":1e39}}',
        "estop": service("/estop", "{}"),
        "estop-release-empty": service("/estop_release", ""),
        "clear-faults": service("/clear_faults", '{"which":"all"}'),
        "mode-standby": service("/mode", '{"take_control":false}'),
        "lights-custom": service("/lights", '{"mode":"custom","brightness_pct":40}'),
        "lift": service("/lift", '{"position_pct":50,"disable":false}'),
        "servos": service("/servos", '{"pan_deg":30,"tilt_deg":-10}'),
        "brake-unknown-field": service("/brake", '{"engage":true,"force":1}'),
    },
}

if __name__ == "__main__":
    for target, seeds in SEEDS.items():
        d = ROOT / target
        d.mkdir(parents=True, exist_ok=True)
        for name, data in seeds.items():
            (d / name).write_bytes(data)
    print("seeds written to", ROOT)
