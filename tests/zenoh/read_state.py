"""An independent Zenoh client (the ``eclipse-zenoh`` package) reads a robot's state from
``chassis-zenoh`` and checks every sample against the Python package's ``ChassisState``.

Started by tests/tests/system/zenoh.rs inside the operator's network namespace::

    python read_state.py --connect tcp/10.77.0.1:7447 --name titan --kind 1 --count 50 \
        [--put-source safety]
    python read_state.py --connect tls/10.77.0.1:7447 --certs DIR --name titan --kind 1 …

It checks the encoding (``application/octet-stream;<ChassisState's type name>``), the size,
that the robot kind is the one chassisd describes (``--kind``: the description's ``kind``, which
the test reads on the robot's side) and that ``seq`` rises; it matches JSON twins
(``…/state/json``) with the binary sample of the same ``seq``, field by field. With
``--put-source S`` it also publishes velocity requests on ``chassis/<name>/cmd/S`` (which the
robot side must refuse unless S is remote).
Prints a JSON summary on stdout; exits 1 with the reason on stderr when a check fails.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import math
import os
import queue
import subprocess
import sys
import time

import chassis
import zenoh


def fail(message: str) -> None:
    print(f"read_state.py: {message}", file=sys.stderr)
    sys.exit(1)


def session(endpoint: str, certs: str | None) -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    if certs:
        # The operator's certificate from `chassis-zenoh gen-certs`: mutual TLS.
        tls = "transport/link/tls"
        config.insert_json5(f"{tls}/root_ca_certificate", json.dumps(f"{certs}/ca.pem"))
        config.insert_json5(f"{tls}/connect_certificate", json.dumps(f"{certs}/operator.pem"))
        config.insert_json5(f"{tls}/connect_private_key", json.dumps(f"{certs}/operator-key.pem"))
        config.insert_json5(f"{tls}/enable_mtls", "true")
    return zenoh.open(config)


def close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-6)


def in_a_test_namespace() -> bool:
    """True inside a named network namespace (``ip netns exec``): the test's own, never the
    machine's, so that Zenoh never reaches a real interface."""
    out = subprocess.run(
        ["ip", "netns", "identify", str(os.getpid())], capture_output=True, text=True, check=False
    )
    return out.returncode == 0 and out.stdout.strip() != ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--connect", required=True)
    parser.add_argument("--name", required=True)
    parser.add_argument(
        "--kind", type=int, required=True, help="the robot kind its description gives (a number)"
    )
    parser.add_argument("--count", type=int, default=50)
    parser.add_argument("--timeout", type=float, default=20.0)
    parser.add_argument("--put-source")
    parser.add_argument("--certs", help="directory of chassis-zenoh gen-certs (tls/ endpoints)")
    args = parser.parse_args()
    if not in_a_test_namespace():
        fail("run me only inside the network namespace tests/tests/system/zenoh.rs builds")

    key = f"chassis/{args.name}/state"
    expected_encoding = f"application/octet-stream;{chassis.ChassisState.type_name()}"
    size = ctypes.sizeof(chassis.ChassisState)
    inbox: queue.Queue[tuple[str, str, bytes]] = queue.Queue()

    def take(sample: zenoh.Sample) -> None:
        inbox.put((str(sample.key_expr), str(sample.encoding), sample.payload.to_bytes()))

    z = session(args.connect, args.certs)
    subscribers = [
        z.declare_subscriber(key, take),
        z.declare_subscriber(f"{key}/json", take),
    ]
    states: dict[int, chassis.ChassisState] = {}
    twins: list[dict] = []
    last_seq = -1
    deadline = time.monotonic() + args.timeout
    while len(states) < args.count or not twins:
        left = deadline - time.monotonic()
        if left <= 0:
            fail(f"{len(states)} state samples and {len(twins)} JSON twins in {args.timeout} s")
        try:
            sample_key, encoding, payload = inbox.get(timeout=left)
        except queue.Empty:
            continue
        if sample_key == f"{key}/json":
            twins.append(json.loads(payload))
            continue
        if encoding != expected_encoding:
            fail(f"encoding {encoding!r}, expected {expected_encoding!r}")
        if len(payload) != size:
            fail(f"{len(payload)} bytes, ChassisState has {size}")
        state = chassis.ChassisState.from_buffer_copy(payload)
        if state.seq <= last_seq:
            fail(f"seq went from {last_seq} to {state.seq}")
        if state.robot != args.kind:
            fail(f"robot kind {state.robot}, the description gives {args.kind}")
        if state.stamp_ns == 0:
            fail("a state without its stamp")
        last_seq = state.seq
        states[state.seq] = state

    matched = 0
    for twin in twins:
        state = states.get(twin["seq"])
        if state is None:
            continue
        checks = {
            "stamp_ns": (twin["stamp_ns"], state.stamp_ns),
            "robot": (twin["robot"], state.robot),
            "motion.linear_mps": (twin["motion"]["linear_mps"], state.motion.linear_mps),
            "odometry.x_m": (twin["odometry"]["x_m"], state.odometry.x_m),
            "system.battery_voltage_v": (
                twin["system"]["battery_voltage_v"],
                state.system.battery_voltage_v,
            ),
        }
        for field, (from_json, from_bytes) in checks.items():
            if not close(float(from_json), float(from_bytes)):
                fail(f"seq {twin['seq']}: {field} is {from_json} in JSON, {from_bytes} in bytes")
        matched += 1

    if args.put_source:
        request = chassis.VelocityRequest.twist(0.5, 0.0)
        encoding = zenoh.Encoding(f"application/octet-stream;{chassis.VelocityRequest.type_name()}")
        for _ in range(10):
            z.put(
                f"chassis/{args.name}/cmd/{args.put_source}",
                bytes(request),
                encoding=encoding,
            )
            time.sleep(0.02)
        time.sleep(0.5)

    for subscriber in subscribers:
        subscriber.undeclare()
    z.close()
    print(
        json.dumps(
            {
                "samples": len(states),
                "json_twins": len(twins),
                "matched": matched,
                "encoding": expected_encoding,
                "size": size,
            }
        )
    )


if __name__ == "__main__":
    main()
