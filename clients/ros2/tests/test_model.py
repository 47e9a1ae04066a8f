"""The robot's model: the URDF ``chassis urdf`` prints and chassis-ros2 publishes on
``robot_description``, read by ``yourdfpy`` (an independent URDF parser, on lxml) and checked
against the description chassisd publishes; its fixed frames on ``tf_static``; both handed to a
Cyclone DDS peer that joins after the bridge has published them (transient local)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest
import yourdfpy
from cyclonedds.core import Policy, Qos
from cyclonedds.util import duration
from test_bridge import DISCOVERY_S, Peer, take_until

import chassis
import ros2_types as m
from conftest import Ros, wait_until

# Every robot of the registry, by its --robot name.
REGISTRY = [
    "titan",
    "scout-mini",
    "xbot",
    "scout",
    "hunter",
    "hunter-se",
    "tracer",
    "bunker",
    "ranger-mini",
    "tracer-mini",
]

# What robot_state_publisher offers and RViz's RobotModel asks for; tf2's static QoS.
LATCHED = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(1),
)


def parse(text: str, path: Path) -> yourdfpy.URDF:
    path.write_text(text)
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False, build_collision_scene_graph=False)
    assert urdf.validate(), urdf.errors
    return urdf


def known(value: float) -> bool:
    return math.isfinite(value) and value > 0.0


def translation(joint: Any) -> list[float]:
    return [float(v) for v in joint.origin[:3, 3]]


def yaw(joint: Any) -> float:
    return math.atan2(joint.origin[1, 0], joint.origin[0, 0])


def same_angle(a: float, b: float) -> bool:
    """Equal angles, to the URDF's nanoradian, whatever their turn (π is −π)."""
    return abs(math.atan2(math.sin(a - b), math.cos(a - b))) < 1e-8


def check_against_description(urdf: yourdfpy.URDF, d: dict[str, Any], prefix: str = "") -> None:
    """The URDF's dimensions are the description's: body, wheels, steering, tracks, sensors."""
    g = d["geometry"]
    base = f"{prefix}base_link"
    assert urdf.base_link == base
    radius = g["wheel_radius_m"] if known(g["wheel_radius_m"]) else 0.0
    footprint = urdf.joint_map["base_footprint_joint"]
    assert (footprint.parent, footprint.child) == (base, f"{prefix}base_footprint")
    assert translation(footprint) == pytest.approx([0.0, 0.0, -radius])

    size = [g["length_m"], g["width_m"], g["height_m"]]
    body = urdf.link_map[base].visuals
    if all(known(v) for v in size):
        assert list(body[0].geometry.box.size) == pytest.approx(size)
        # Standing on the ground: its centre half its height above base_footprint.
        assert body[0].origin[2, 3] + radius == pytest.approx(size[2] / 2.0)
    else:
        assert not body

    wheelbase, track = g["wheelbase_m"], g["track_m"]
    signs = {0: (1, 1), 1: (1, -1), 2: (-1, 1), 3: (-1, -1)}
    for j in d["joints"]:
        joint = urdf.joint_map[j["name"]]
        assert joint.parent == base
        x, y, z = translation(joint)
        if j["source"] == chassis.JointSource.WHEEL:
            assert joint.type == "continuous"
            assert list(joint.axis) == [0.0, 1.0, 0.0]
            sx, sy = signs[j["index"]]
            if known(wheelbase):
                assert x == pytest.approx(sx * wheelbase / 2.0)
            if known(track):
                assert y == pytest.approx(sy * track / 2.0)
            assert z == 0.0
            if radius:
                wheel = urdf.link_map[joint.child].visuals[0].geometry.cylinder
                assert wheel.radius == pytest.approx(radius)
        else:
            assert joint.type == "revolute"
            assert list(joint.axis) == [0.0, 0.0, 1.0]
            front = j["source"] == chassis.JointSource.FRONT_STEER
            if known(wheelbase):
                assert x == pytest.approx((1 if front else -1) * wheelbase / 2.0)
            steer = d["robot_limits"]["steer_rad"]
            if known(steer):
                assert (joint.limit.lower, joint.limit.upper) == pytest.approx((-steer, steer))

    if d["kinematics"] == chassis.Kinematics.TRACKED:
        for side, sign in (("left", 1), ("right", -1)):
            joint = urdf.joint_map[f"{side}_track_joint"]
            assert joint.type == "fixed" and joint.child == f"{prefix}{side}_track_link"
            if known(track):
                assert translation(joint)[1] == pytest.approx(sign * track / 2.0)
            band = urdf.link_map[joint.child].visuals[0].geometry.box.size
            if known(wheelbase):
                assert band[0] == pytest.approx(wheelbase)

    for s in d["sensors"]:
        joint = urdf.joint_map[f"{s['name']}_joint"]
        assert joint.type == "fixed" and joint.child == f"{prefix}{s['name']}_link"
        assert translation(joint) == pytest.approx([s["x_m"], s["y_m"], s["z_m"]])
        assert same_angle(yaw(joint), s["yaw_rad"]), s


def test_every_registry_robot_s_urdf_parses_with_the_described_dimensions(ros: Ros) -> None:
    robots = {name: ros.chassisd(name) for name in REGISTRY}
    tracked = 0
    for name, robot in robots.items():
        d = robot.wait_description(5.0).summary()
        running = ros.chassis("urdf", "--name", name)
        assert running.returncode == 0, running.stderr
        urdf = parse(running.stdout, ros.tmp / f"{name}.urdf")
        # The registry's defaults without chassisd: the same links and joints (chassisd's own
        # configuration may move them: the simulated XBot states its wheel separation).
        registry = ros.chassis("urdf", "--robot", name)
        assert registry.returncode == 0, registry.stderr
        defaults = parse(registry.stdout, ros.tmp / f"{name}-defaults.urdf")
        assert set(defaults.link_map) == set(urdf.link_map), name
        assert set(defaults.joint_map) == set(urdf.joint_map), name
        check_against_description(urdf, d)
        assert urdf.robot.name == name
        # Every joint the bridge can publish is a moving joint of the URDF.
        movable = {j.name for j in urdf.robot.joints if j.type != "fixed"}
        assert {j["name"] for j in d["joints"]} == movable, name
        tracked += d["kinematics"] == chassis.Kinematics.TRACKED
    assert tracked >= 1, "a tracked robot is among them"

    # Under a frame prefix: every link is prefixed, the joints keep joint_states' names.
    prefixed = ros.chassis("urdf", "--name", "xbot", "--frame-prefix", "r1/")
    assert prefixed.returncode == 0, prefixed.stderr
    urdf = parse(prefixed.stdout, ros.tmp / "r1.urdf")
    assert all(link.name.startswith("r1/") for link in urdf.robot.links)
    check_against_description(urdf, robots["xbot"].wait_description(5.0).summary(), "r1/")
    wrong = ros.chassis("urdf", "--robot", "no-such-robot")
    assert wrong.returncode != 0 and "no-such-robot" in wrong.stderr


def test_a_late_joiner_gets_the_model_and_the_static_frames(ros: Ros) -> None:
    robot = ros.chassisd("xbot", "--name", "late")
    ros.bridge("late", "--namespace", "/late", "--frame-prefix", "late/")
    wait_until(
        "the bridge published its model",
        lambda: "robot_description and tf_static" in ros.logs(),
        DISCOVERY_S,
        ros,
    )
    # Well after the publication, a node starts (RViz, robot_state_publisher).
    time.sleep(1.0)
    peer = Peer(ros.domain)
    model = peer.reader("rt/late/robot_description", m.String, LATCHED)
    tf_static = peer.reader("rt/late/tf_static", m.TFMessage, LATCHED)
    text = take_until(model, lambda s: True, DISCOVERY_S, ros, "robot_description").data
    expected = ros.chassis("urdf", "--name", "late", "--frame-prefix", "late/")
    assert expected.returncode == 0, expected.stderr
    assert text == expected.stdout
    d = robot.wait_description(5.0).summary()
    check_against_description(parse(text, ros.tmp / "late.urdf"), d, "late/")

    frames = take_until(tf_static, lambda t: True, DISCOVERY_S, ros, "tf_static").transforms
    by_child = {t.child_frame_id: t for t in frames}
    assert {t.header.frame_id for t in frames} == {"late/base_link"}
    sensors = {f"late/{s['name']}_link" for s in d["sensors"]}
    assert set(by_child) == {"late/base_footprint"} | sensors
    for s in d["sensors"]:
        t = by_child[f"late/{s['name']}_link"].transform
        v, q = t.translation, t.rotation
        assert [v.x, v.y, v.z] == pytest.approx([s["x_m"], s["y_m"], s["z_m"]])
        assert same_angle(2.0 * math.atan2(q.z, q.w), s["yaw_rad"]), s
        assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-9)
    # The range topics' and the IMU's frames are links of the model.
    assert "late/ultrasonic_front_centre_link" in by_child and "late/imu_link" in by_child


def test_every_joint_state_names_a_joint_of_the_published_urdf(ros: Ros) -> None:
    peer = Peer(ros.domain)
    seen = {}
    for name in ("titan", "xbot", "ranger-mini"):
        ros.chassisd(name)
        ns = name.replace("-", "_")
        ros.bridge(name, "--namespace", f"/{ns}", label=f"ros2-{name}")
        seen[name] = (
            peer.reader(f"rt/{ns}/robot_description", m.String, LATCHED),
            peer.reader(f"rt/{ns}/joint_states", m.JointState),
        )
    for name, (model, joint_states) in seen.items():
        text = take_until(model, lambda s: True, DISCOVERY_S, ros, f"{name} model").data
        urdf = parse(text, ros.tmp / f"{name}.urdf")
        joints = take_until(joint_states, lambda j: True, 5.0, ros, f"{name} joints")
        assert joints.name, name
        for joint in joints.name:
            assert joint in urdf.joint_map, f"{name}: joint_states' {joint} is not in the URDF"
            assert urdf.joint_map[joint].type in ("continuous", "revolute"), joint
