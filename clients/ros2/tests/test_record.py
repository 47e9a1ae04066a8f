"""``chassis-ros2 --record``: a drive of the simulated TITAN written as a ROS 2 bag, read back
with the ``mcap-ros2-support`` package (the decoder Foxglove's and ros2's Python tools use),
independently of the bridge's own code."""

from __future__ import annotations

import math
import subprocess
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import Ros, binary


def read_bag(path: Path) -> tuple[dict[str, list[Any]], dict[str, Any], dict[str, dict[str, str]]]:
    """Every message decoded by topic, each channel by topic, and the metadata records."""
    messages: dict[str, list[Any]] = {}
    channels: dict[str, Any] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2"
        for _schema, channel, _message, decoded in reader.iter_decoded_messages():
            messages.setdefault(channel.topic, []).append(decoded)
            channels[channel.topic] = channel
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return messages, channels, metadata


def test_a_recorded_drive_decodes_as_odometry_tf_and_battery_state(ros: Ros) -> None:
    robot = ros.chassisd("titan", "--name", "rec")
    bag = ros.tmp / "drive.mcap"
    recorder = ros.spawn(
        "record",
        [str(binary("chassis-ros2")), "--name", "rec", "--record", str(bag), "--duration", "5"],
    )
    # 0.4 m/s with a 0.2 rad/s left turn for 2 s, then stopped.
    drive = ros.chassis(
        "pub", "velocity", "--name", "rec", "--source", "teleop",
        "--vx", "0.4", "--wz", "0.2", "--duration", "2",
    )  # fmt: skip
    assert drive.returncode == 0, drive.stderr
    try:
        recorder.wait(timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the recorder did not stop after --duration\n{ros.logs()}")
    assert recorder.returncode == 0, ros.logs()
    state = robot.wait_state(1.0)
    assert state is not None

    messages, channels, metadata = read_bag(bag)
    odom, tf, battery = messages["/odom"], messages["/tf"], messages["/battery_state"]
    assert len(odom) > 50 and len(tf) == len(odom) and battery

    # The channels as rosbag2 writes them: ROS 2 types, CDR, the bridge's QoS.
    assert channels["/odom"].message_encoding == "cdr"
    assert "reliability: 1" in channels["/odom"].metadata["offered_qos_profiles"]
    assert "reliability: 2" in channels["/battery_state"].metadata["offered_qos_profiles"]

    # Odometry: REP-105 frames, the commanded speed and yaw rate reached, a left turn (REP-103:
    # positive yaw), and the last pose is the one chassisd ends with.
    assert {(o.header.frame_id, o.child_frame_id) for o in odom} == {("odom", "base_link")}
    fastest = max(odom, key=lambda o: o.twist.twist.linear.x)
    assert fastest.twist.twist.linear.x == pytest.approx(0.4, abs=0.03)
    assert fastest.twist.twist.angular.z == pytest.approx(0.2, abs=0.03)
    last = odom[-1]
    assert last.twist.twist.linear.x == pytest.approx(0.0, abs=0.01)
    p = last.pose.pose.position
    assert p.x == pytest.approx(state.odometry.x_m, abs=1e-3)
    assert p.y == pytest.approx(state.odometry.y_m, abs=1e-3)
    assert p.x > 0.5 and p.y > 0.0
    q = last.pose.pose.orientation
    assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-9)
    assert 2.0 * math.atan2(q.z, q.w) == pytest.approx(state.odometry.yaw_rad, abs=1e-3)
    assert last.pose.covariance[0] == pytest.approx(1e-3)

    # TFMessage: odom → base_link, the same pose as odom at the same stamp.
    t = tf[-1].transforms
    assert len(t) == 1
    assert (t[0].header.frame_id, t[0].child_frame_id) == ("odom", "base_link")
    assert (t[0].header.stamp.sec, t[0].header.stamp.nanosec) == (
        last.header.stamp.sec,
        last.header.stamp.nanosec,
    )
    assert t[0].transform.translation.x == pytest.approx(p.x, abs=1e-9)
    assert t[0].transform.rotation.z == pytest.approx(q.z, abs=1e-9)

    # BatteryState: the pack chassisd reports.
    b = battery[-1]
    assert b.header.frame_id == "base_link"
    assert b.present
    pack = state.bms[0]
    assert b.voltage == pytest.approx(pack.voltage_v, abs=0.1)
    assert b.percentage == pytest.approx(pack.soc_pct / 100.0, abs=0.01)

    # The robot's description.
    description = metadata["robot_description"]
    assert description["robot"] == "titan" and description["name"] == "rec"
    assert description["kinematics"] == "dual_ackermann"  # the TITAN steers both axles
    assert "TITAN" in description["display_name"]

    # Its model, as the bridge publishes it: the URDF `chassis urdf` prints, and its fixed
    # frames, both offered transient local.
    urdf = ros.chassis("urdf", "--name", "rec")
    assert urdf.returncode == 0, urdf.stderr
    assert [s.data for s in messages["/robot_description"]] == [urdf.stdout]
    (static,) = messages["/tf_static"]
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ("base_link", "base_footprint")
    ]
    for topic in ("/robot_description", "/tf_static"):
        qos = channels[topic].metadata["offered_qos_profiles"]
        assert "durability: 1" in qos and "depth: 1" in qos, qos
