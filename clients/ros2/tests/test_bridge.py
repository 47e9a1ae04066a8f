"""chassis-ros2 against Cyclone DDS, an independent DDS implementation, standing in for a ROS 2
node: velocities in, the mux's decisions, the e-stop, the services, and every published topic
decoded with the ROS 2 types declared in ``ros2_types``."""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar

import pytest
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

import chassis
import ros2_types as m
from conftest import Ros, wait_until

T = TypeVar("T")

# What rclcpp asks for by default (reliable, volatile, the last 10) and its SensorDataQoS.
RELIABLE = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.Durability.Volatile,
    Policy.History.KeepLast(10),
)
SENSOR = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5))
DISCOVERY_S = 10.0


class Peer:
    """One DDS participant with the topics a ROS 2 node would open."""

    def __init__(self, domain: int) -> None:
        self.dp = DomainParticipant(domain)
        self.topics: dict[str, Topic] = {}

    def topic(self, name: str, kind: type[Any]) -> Topic:
        if name not in self.topics:
            self.topics[name] = Topic(self.dp, name, kind)
        return self.topics[name]

    def reader(self, name: str, kind: type[T], qos: Qos = RELIABLE) -> DataReader[T]:
        return DataReader(self.dp, self.topic(name, kind), qos=qos)

    def writer(self, name: str, kind: type[T], qos: Qos = RELIABLE) -> DataWriter[T]:
        return DataWriter(self.dp, self.topic(name, kind), qos=qos)


def wait_matched(writer: DataWriter[Any], ros: Ros) -> None:
    wait_until(
        "the bridge subscribed",
        lambda: writer.get_publication_matched_status().current_count > 0,
        DISCOVERY_S,
        ros,
    )


def take_until(
    reader: DataReader[T], ok: Callable[[T], bool], timeout: float, ros: Ros, what: str
) -> T:
    """Takes samples until one satisfies ``ok``; fails after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    last: T | None = None
    while time.monotonic() < end:
        for sample in reader.take(N=64):
            last = sample
            if ok(sample):
                return sample
        time.sleep(0.01)
    pytest.fail(f"{what}: not within {timeout} s (last sample: {last})\n{ros.logs()}")


def latest_mux(robot: chassis.Robot) -> chassis.MuxStatus | None:
    """The newest mux decision (the first call opens the subscriber and waits for one)."""
    return robot.latest_mux() or robot.wait_mux(1.0)


def active(robot: chassis.Robot) -> str | None:
    mux = latest_mux(robot)
    return None if mux is None else mux.active_source_name()  # type: ignore[attr-defined]


def estop_held(robot: chassis.Robot) -> bool:
    mux = latest_mux(robot)
    return mux is not None and any(
        lock.name == "estop" and lock.holder != chassis.LockStatus.HOLDER_NONE
        for lock in mux.locks[: mux.lock_count]
    )


def twist(vx: float, wz: float = 0.0, vy: float = 0.0) -> m.Twist:
    return m.Twist(linear=m.Vector3(x=vx, y=vy), angular=m.Vector3(z=wz))


class Publishing:
    """Publishes a message at 20 Hz in the background, as Nav2's controller does, while the
    test looks at the robot (``message`` may be a function making each one, to stamp it)."""

    def __init__(self, writer: DataWriter[Any], message: Any) -> None:
        self.writer = writer
        self.message = message
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self) -> None:
        while not self.stop.is_set():
            self.writer.write(self.message() if callable(self.message) else self.message)
            self.stop.wait(0.05)

    def __enter__(self) -> Publishing:
        self.thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop.set()
        self.thread.join()


def drive_until(
    cmd: DataWriter[Any], message: Any, condition: Callable[[], bool], timeout: float, ros: Ros
) -> None:
    """Publishes ``message`` at 20 Hz, as Nav2's controller does, until ``condition`` holds."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(f"not within {timeout} s\n{ros.logs()}")
        cmd.write(message)
        time.sleep(0.05)


def test_twist_drives_the_robot_and_odom_tf_follow(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    odom = peer.reader("rt/odom", m.Odometry)
    tf = peer.reader("rt/tf", m.TFMessage, RELIABLE)
    wait_matched(cmd, ros)

    with Publishing(cmd, twist(0.4, 0.2)):
        wait_until("the mux follows ros2", lambda: active(robot) == "ros2", 10.0, ros)
        moving = take_until(
            odom, lambda o: o.twist.twist.linear.x > 0.3, 10.0, ros, "odom shows the motion"
        )
        later = take_until(
            odom,
            lambda o: o.pose.pose.position.x > moving.pose.pose.position.x + 0.1,
            10.0,
            ros,
            "odom's pose advances",
        )
        state = robot.latest_state()
        assert state is not None and state.motion.linear_mps > 0.3
    assert later.header.frame_id == "odom" and later.child_frame_id == "base_link"
    assert later.twist.twist.angular.z == pytest.approx(0.2, abs=0.05)
    # REP-103: a left turn at positive yaw rate makes the heading grow.
    q = later.pose.pose.orientation
    assert q.z > 0.0 and math.isclose(q.z**2 + q.w**2, 1.0, rel_tol=1e-9)
    # Covariances from the robot's description: x, y, yaw as it states them; z, roll, pitch
    # unmeasured.
    variance = robot.wait_description(5.0).odometry_variance
    cov = later.pose.covariance
    assert cov[0] == cov[7] == pytest.approx(variance.position_m2)
    assert cov[35] == pytest.approx(variance.yaw_rad2) and cov[14] == pytest.approx(1e6)
    assert later.twist.covariance[0] == pytest.approx(variance.linear_m2ps2)
    # ROS time: stamps are Unix time, within a few seconds of this computer's clock.
    stamp = later.header.stamp.sec + later.header.stamp.nanosec * 1e-9
    assert abs(stamp - time.time()) < 5.0

    frame = take_until(tf, lambda t: len(t.transforms) == 1, 5.0, ros, "tf")
    t = frame.transforms[0]
    assert (t.header.frame_id, t.child_frame_id) == ("odom", "base_link")
    assert t.transform.translation.x > 0.0


def test_teleop_preempts_the_ros2_source_and_hands_back(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    wait_matched(cmd, ros)
    drive_until(cmd, twist(0.3), lambda: active(robot) == "ros2", 10.0, ros)

    teleop = robot.source("teleop")
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        teleop.twist(-0.2)
        cmd.write(twist(0.3))
        time.sleep(0.05)
    assert active(robot) == "teleop"
    # Teleop goes quiet: after its 300 ms timeout the mux follows ros2 again.
    drive_until(cmd, twist(0.3), lambda: active(robot) == "ros2", 3.0, ros)


def test_a_killed_bridge_ends_the_motion_at_the_source_timeout(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    wait_matched(cmd, ros)
    drive_until(cmd, twist(0.3), lambda: active(robot) == "ros2", 10.0, ros)

    bridge = next(p for label, p, _ in ros.procs if label == "chassis-ros2")
    bridge.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    # The peer keeps publishing: nothing reaches the robot any more.
    while active(robot) == "ros2":
        cmd.write(twist(0.3))
        time.sleep(0.01)
        assert time.monotonic() - killed < 2.0, "ros2 still active 2 s after the bridge died"
    ended = time.monotonic() - killed
    mux = latest_mux(robot)
    assert mux is not None and mux.zero_reason == chassis.ZeroReason.NO_ACTIVE_SOURCE
    # The source's timeout is 500 ms from the last request the bridge forwarded.
    assert ended <= 0.5 + 0.25, f"motion outlived the source by {ended:.3f} s"
    wait_until(
        "the robot stops",
        lambda: (s := robot.latest_state()) is not None and abs(s.command.linear_mps) < 1e-6,
        2.0,
        ros,
    )


def test_e_stop_true_locks_and_release_stays_explicit(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    e_stop = peer.writer("rt/e_stop", m.Bool)
    wait_matched(e_stop, ros)
    wait_matched(cmd, ros)

    e_stop.write(m.Bool(data=True))
    wait_until("the e-stop engages", lambda: estop_held(robot), 5.0, ros)
    with Publishing(cmd, twist(0.3)):
        wait_until(
            "the mux holds zero for the lock",
            lambda: (
                (x := latest_mux(robot)) is not None and x.zero_reason == chassis.ZeroReason.LOCKED
            ),
            5.0,
            ros,
        )
        state = robot.latest_state()
        assert state is not None and state.command.linear_mps == 0.0
        # False on the topic does not release it.
        e_stop.write(m.Bool(data=False))
        time.sleep(0.3)
        assert estop_held(robot)
        state = robot.latest_state()
        assert state is not None and state.command.linear_mps == 0.0


class TriggerClient:
    """A ``std_srvs/Trigger`` client speaking rmw_cyclonedds_cpp's request/reply layout."""

    def __init__(self, peer: Peer, service: str) -> None:
        self.requests = peer.writer(f"rq{service}Request", m.TriggerRequest)
        self.replies = peer.reader(f"rr{service}Reply", m.TriggerReply)
        self.guid = list(os.urandom(8))
        self.seq = 0

    def call(self, ros: Ros, timeout: float = 5.0) -> m.TriggerReply:
        wait_matched(self.requests, ros)
        wait_until(
            "the reply writer matched",
            lambda: self.replies.get_subscription_matched_status().current_count > 0,
            DISCOVERY_S,
            ros,
        )
        self.seq += 1
        self.requests.write(
            m.TriggerRequest(client_guid=self.guid, sequence_high=0, sequence_low=self.seq)
        )
        return take_until(
            self.replies,
            lambda r: list(r.client_guid) == self.guid and r.sequence_low == self.seq,
            timeout,
            ros,
            "the service's reply",
        )


def test_each_service_answers_with_chassisd_s_response(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    estop = TriggerClient(peer, "/chassis_ros2/estop")
    release = TriggerClient(peer, "/chassis_ros2/estop_release")
    clear = TriggerClient(peer, "/chassis_ros2/clear_faults")

    answer = estop.call(ros)
    assert answer.success, answer.message
    wait_until("the mux shows the e-stop held", lambda: estop_held(robot), 2.0, ros)
    answer = release.call(ros)
    assert answer.success, answer.message
    wait_until("the mux shows the e-stop released", lambda: not estop_held(robot), 2.0, ros)
    answer = clear.call(ros)
    assert answer.success, answer.message
    # A refusal comes back with chassisd's reason: the XBot has no fault-clear command.
    ros.chassisd("xbot")
    ros.bridge("xbot", "--namespace", "/xbot", label="ros2-xbot")
    refused = TriggerClient(peer, "/xbot/chassis_ros2/clear_faults").call(ros)
    assert not refused.success, refused.message
    assert refused.message.startswith("unsupported:"), refused.message


def test_a_release_through_the_service_never_starts_motion(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    estop = TriggerClient(peer, "/chassis_ros2/estop")
    release = TriggerClient(peer, "/chassis_ros2/estop_release")
    wait_matched(cmd, ros)

    with Publishing(cmd, twist(0.3)):
        wait_until(
            "ros2 drives",
            lambda: (s := robot.latest_state()) is not None and s.motion.linear_mps > 0.2,
            10.0,
            ros,
        )
        assert estop.call(ros).success

        def standing(duration: float = 0.3) -> bool:
            end = time.monotonic() + duration
            while time.monotonic() < end:
                s = robot.wait_state(0.05)
                if s is not None and abs(s.motion.linear_mps) >= 0.001:
                    return False
            return True

        wait_until("the robot stands", standing, 5.0, ros)
        # Released while Nav2 (here: the publisher) still asks for 0.3 m/s: nothing moves.
        answer = release.call(ros)
        assert answer.success, answer.message
        peak = 0.0
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            s = robot.wait_state(0.05)
            if s is not None:
                peak = max(peak, abs(s.motion.linear_mps))
        assert peak < 0.01, f"the release started motion: {peak} m/s\n{ros.logs()}"
        assert "until ros2 asks for zero" in answer.message, answer.message
        mux = latest_mux(robot)
        assert mux is not None and mux.zero_reason == chassis.ZeroReason.AWAITING_ZERO
        awaited = mux.sources[mux.awaiting_source]
        assert awaited.name == "ros2"
    # A zero on cmd_vel, then motion is obeyed again.
    drive_until(
        cmd,
        twist(0.0),
        lambda: (
            (x := latest_mux(robot)) is not None
            and x.zero_reason != chassis.ZeroReason.AWAITING_ZERO
        ),
        5.0,
        ros,
    )
    drive_until(
        cmd,
        twist(0.3),
        lambda: (s := robot.latest_state()) is not None and s.motion.linear_mps > 0.2,
        10.0,
        ros,
    )


def test_stamped_cmd_vel_and_namespaces(ros: Ros) -> None:
    robot = ros.chassisd("scout-mini", "--name", "left")
    ros.bridge("left", "--stamped", "--namespace", "/left", "--frame-prefix", "left/")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/left/cmd_vel", m.TwistStamped)
    odom = peer.reader("rt/left/odom", m.Odometry)
    wait_matched(cmd, ros)

    def stamped(age_s: float) -> Callable[[], m.TwistStamped]:
        def make() -> m.TwistStamped:
            ns = time.time_ns() - int(age_s * 1e9)
            stamp = m.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            header = m.Header(stamp=stamp, frame_id="left/base_link")
            return m.TwistStamped(header=header, twist=twist(0.3))

        return make

    # Made 2 s ago (held through an outage) or unstamped: dropped, counted, never obeyed.
    for old in (stamped(2.0), lambda: m.TwistStamped(header=m.Header(), twist=twist(0.3))):
        with Publishing(cmd, old):
            time.sleep(1.0)
            assert active(robot) != "ros2", ros.logs()
            state = robot.latest_state()
            assert state is not None and state.command.linear_mps == 0.0
    assert "cmd_vel dropped as stale: made 2" in ros.logs(), ros.logs()
    assert "cmd_vel dropped as stale: unstamped" in ros.logs(), ros.logs()
    # Stamped now: obeyed.
    with Publishing(cmd, stamped(0.0)):
        wait_until("the mux follows ros2", lambda: active(robot) == "ros2", 10.0, ros)
        o = take_until(odom, lambda o: o.twist.twist.linear.x > 0.2, 10.0, ros, "odom")
    assert (o.header.frame_id, o.child_frame_id) == ("left/odom", "left/base_link")


def test_non_finite_velocities_are_dropped(ros: Ros) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    wait_matched(cmd, ros)
    for _ in range(10):
        cmd.write(twist(math.nan, 0.1))
        cmd.write(twist(0.2, math.inf))
        time.sleep(0.02)
    time.sleep(0.3)
    assert active(robot) is None
    mux = latest_mux(robot)
    assert mux is not None
    source = next(s for s in mux.sources[: mux.source_count] if s.name == "ros2")
    assert source.last_seq == 0, "a non-finite request reached the mux"
    # The bridge keeps working.
    drive_until(cmd, twist(0.2), lambda: active(robot) == "ros2", 5.0, ros)
    wait_until(
        "the drops are logged",
        lambda: "non-finite component dropped" in ros.logs(),
        2.0,
        ros,
    )


def test_a_nav2_speed_limit_caps_the_measured_speed_until_the_operator_raises_it(
    ros: Ros,
) -> None:
    robot = ros.chassisd("titan")
    ros.bridge("titan")
    peer = Peer(ros.domain)
    cmd = peer.writer("rt/cmd_vel", m.Twist)
    limits = peer.writer("rt/speed_limit", m.SpeedLimit)
    wait_matched(limits, ros)
    wait_matched(cmd, ros)

    def speed() -> float:
        state = robot.latest_state() or robot.wait_state(0.1)
        return -1.0 if state is None else state.motion.linear_mps

    def limit() -> float:
        mux = latest_mux(robot)
        return -1.0 if mux is None else mux.speed_limit_mps

    limits.write(m.SpeedLimit(percentage=False, speed_limit=0.4))
    wait_until("the limit stands", lambda: limit() == pytest.approx(0.4), 5.0, ros)
    with Publishing(cmd, twist(1.0)):
        wait_until("the robot runs at the limit", lambda: speed() > 0.35, 15.0, ros)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            assert speed() < 0.43, "the measured speed exceeds the limit"
            time.sleep(0.05)
        mux = latest_mux(robot)
        assert mux is not None and mux.clamp_flags & chassis.ClampFlags.SPEED_LIMIT
        assert mux.why() == "driving from ros2 · limited to 0.4 m/s by ros2", mux.why()
        # A percentage of the robot's maximum lowers it; neither 0 (no limit) nor a higher one
        # raise it, and a negative one is refused and logged.
        low = 0.1 * robot.description.robot_limits.forward_mps
        assert 0.05 < low < 0.35
        limits.write(m.SpeedLimit(percentage=True, speed_limit=10.0))
        wait_until("the percentage lowers it", lambda: limit() == pytest.approx(low), 5.0, ros)
        wait_until("the robot slows to it", lambda: speed() < low + 0.02, 15.0, ros)
        limits.write(m.SpeedLimit(percentage=False, speed_limit=0.0))
        limits.write(m.SpeedLimit(percentage=False, speed_limit=2.0))
        limits.write(m.SpeedLimit(percentage=False, speed_limit=-1.0))
        wait_until("the refusal is logged", lambda: "speed_limit refused" in ros.logs(), 5.0, ros)
        assert limit() == pytest.approx(low)
        assert speed() < low + 0.02
        raised = robot.control("speed-limit", mps=0.5)
        assert raised.ok, str(raised)
        wait_until("the operator raised it", lambda: speed() > 0.45, 15.0, ros)


def nmea(body: str) -> bytes:
    checksum = 0
    for c in body.encode():
        checksum ^= c
    return f"${body}*{checksum:02X}\r\n".encode()


def test_every_topic_decodes_on_each_robot(ros: Ros) -> None:
    # XBot: IMU, ranges, wheels and a GPS receiver on a pseudo-terminal.
    master, slave = os.openpty()
    gps = os.ttyname(slave)
    robots = {
        "titan": ros.chassisd("titan"),
        "scout-mini": ros.chassisd("scout-mini"),
        "xbot": ros.chassisd("xbot", "--gps", f"serial:{gps}"),
    }
    peer = Peer(ros.domain)
    readers: dict[str, dict[str, DataReader[Any]]] = {}
    for name in robots:
        ros.bridge(name, "--namespace", f"/{name.replace('-', '_')}", label=f"ros2-{name}")
        ns = f"rt/{name.replace('-', '_')}"
        readers[name] = {
            "odom": peer.reader(f"{ns}/odom", m.Odometry),
            "tf": peer.reader(f"{ns}/tf", m.TFMessage),
            "joint_states": peer.reader(f"{ns}/joint_states", m.JointState),
            "battery_state": peer.reader(f"{ns}/battery_state", m.BatteryState, SENSOR),
            "diagnostics": peer.reader(f"{ns}/diagnostics", m.DiagnosticArray),
            "imu": peer.reader(f"{ns}/imu/data", m.Imu, SENSOR),
            "range": peer.reader(f"{ns}/range/ultrasonic_front_centre", m.Range, SENSOR),
            "ir": peer.reader(f"{ns}/range/ir_rear_left", m.Range, SENSOR),
            "fix": peer.reader(f"{ns}/fix", m.NavSatFix, SENSOR),
        }

    for name, r in readers.items():
        odom = take_until(r["odom"], lambda o: True, DISCOVERY_S, ros, f"{name} odom")
        assert odom.header.frame_id == "odom"
        take_until(r["tf"], lambda t: len(t.transforms) == 1, 5.0, ros, f"{name} tf")
        battery = take_until(r["battery_state"], lambda b: True, 5.0, ros, f"{name} battery")
        assert 10.0 < battery.voltage < 80.0, battery
        assert battery.present
        diag = take_until(r["diagnostics"], lambda d: len(d.status) == 3, 5.0, ros, f"{name} diag")
        names = [s.name for s in diag.status]
        assert names == ["chassis: faults", "chassis: link", "chassis: mux"], names
        assert all(s.hardware_id == name for s in diag.status)
        link = dict((kv.key, kv.value) for kv in diag.status[1].values)
        assert link["robot"] == name and int(link["rx_frames"]) > 0

    # TITAN reports its steering angles; the XBot its wheels: the joints each description lists.
    def described_joints(robot: chassis.Robot) -> list[str]:
        return [j["name"] for j in robot.wait_description(5.0).summary()["joints"]]

    joints = take_until(readers["titan"]["joint_states"], lambda j: True, 5.0, ros, "titan joints")
    assert joints.name == ["front_steer_joint", "rear_steer_joint"]
    assert joints.name == described_joints(robots["titan"])
    joints = take_until(readers["xbot"]["joint_states"], lambda j: True, 5.0, ros, "xbot joints")
    assert joints.name == described_joints(robots["xbot"])
    assert joints.name[:2] == ["front_left_wheel_joint", "front_right_wheel_joint"]
    assert len(joints.position) == len(joints.velocity) == len(joints.name)

    imu = take_until(readers["xbot"]["imu"], lambda i: True, 5.0, ros, "xbot imu")
    q = imu.orientation
    assert imu.header.frame_id == "imu_link"
    assert math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-6)
    sonar = take_until(readers["xbot"]["range"], lambda x: True, 5.0, ros, "xbot ultrasonic")
    assert sonar.radiation_type == 0 and sonar.header.frame_id == "ultrasonic_front_centre_link"
    ir = take_until(readers["xbot"]["ir"], lambda x: True, 5.0, ros, "xbot ir")
    assert ir.radiation_type == 1 and ir.range >= 0.0

    # GPS: no fix first, then a fix.
    os.write(master, nmea("GPGGA,092751.000,,,,,0,0,,,M,,M,,"))
    no_fix = take_until(readers["xbot"]["fix"], lambda f: True, 5.0, ros, "no fix")
    assert no_fix.status.status == -1  # STATUS_NO_FIX
    fix = None
    end = time.monotonic() + 5.0
    while fix is None and time.monotonic() < end:
        os.write(master, nmea("GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,"))
        for f in readers["xbot"]["fix"].take(N=16):
            if f.status.status == 0:
                fix = f
        time.sleep(0.1)
    assert fix is not None, ros.logs()
    assert fix.latitude == pytest.approx(53.36134, abs=1e-4)
    assert fix.longitude == pytest.approx(-6.50562, abs=1e-4)
    assert fix.position_covariance_type == 1  # approximated from HDOP
    os.close(master)
    os.close(slave)

    # Robots without an IMU, ranges or GPS publish none.
    for name in ("titan", "scout-mini"):
        for topic in ("imu", "range", "fix"):
            assert readers[name][topic].take(N=1) == [], f"{name} published {topic}"
