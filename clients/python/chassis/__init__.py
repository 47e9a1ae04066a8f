"""``chassis``: Python clients of robots served by ``chassisd``, zero-copy over iceoryx2.

Five lines that drive a robot and print its odometry::

    import chassis
    robot = chassis.Robot.connect("titan")
    teleop = robot.source("teleop")
    for _ in range(50):
        teleop.twist(0.3, 0.0); state = robot.wait_state(0.1)
    print(state.odometry.x_m if state else "no state")

Every IPC type is a ctypes class with the Rust field names (``state.motion.linear_mps``), and
every flag and enum group a class of constants, generated from the contract
(``interfaces/contract.json``) by ``clients/python/generate.py``. A text field of the contract
reads and assigns as a ``str`` (``robot.description.kind_name == "titan"``).
"""

from ._contract import *  # noqa: F403
from ._contract import CONSTANT_GROUPS, SERVICES, TYPES
from .robot import (
    FRAMES_BUFFER,
    STATE_BUFFER,
    BadName,
    ChassisError,
    ControlAnswer,
    FrameTap,
    IpcError,
    NotServed,
    Robot,
    Source,
    SourceTaken,
    StateStream,
    Timeout,
    UnknownSource,
    VelocityRequest,
    control_request,
    now_ns,
    reply_name,
    service_name,
)

__all__ = [
    "CONSTANT_GROUPS",
    "FRAMES_BUFFER",
    "SERVICES",
    "STATE_BUFFER",
    "TYPES",
    "BadName",
    "ChassisError",
    "ControlAnswer",
    "FrameTap",
    "IpcError",
    "NotServed",
    "Robot",
    "Source",
    "SourceTaken",
    "StateStream",
    "Timeout",
    "UnknownSource",
    "VelocityRequest",
    "control_request",
    "now_ns",
    "reply_name",
    "service_name",
    *TYPES,
    *CONSTANT_GROUPS,
]
