"""Talking to a robot served by ``chassisd``: state, velocity sources, control, the frame tap.

Every port is opened the way the Rust client (``chassis-client``) opens it: a publish-subscribe
service and the event service of the same name, which the publisher notifies after sending; a
request-response service with the event of the same name (the client notifies the server) and
``<name>/reply`` (the server notifies its clients). The services belong to ``chassisd``: this
package only opens them, so a robot that is not served is reported, never created.

iceoryx2 ports are not thread-safe: keep a :class:`Robot` and its :class:`Source` on one thread.
"""

from __future__ import annotations

import ctypes
import math
import os
import re
import time
from collections.abc import Iterator
from typing import Any, TypeVar

import iceoryx2 as iox2

from ._contract import (
    PREFIX_ENV,
    REPLY_SUFFIX,
    SERVICES,
    BusFrame,
    ChassisState,
    ClampFlags,
    ControlKind,
    ControlMode,
    ControlRequest,
    ControlResponse,
    ControlStatus,
    DriveState,
    FaultClear,
    LightMode,
    LockStatus,
    MuxStatus,
    RequestFlags,
    RobotDescription,
    SimKind,
    SimRequest,
    Stop,
    Struct,
    ZeroReason,
)
from ._contract import VelocityRequest as _VelocityRequest

T = TypeVar("T", bound=Struct)

#: Most samples a state stream may buffer: the state service's ``subscriber_max_buffer_size``.
STATE_BUFFER: int = SERVICES["state"]["limits"]["subscriber_max_buffer_size"]
#: Largest buffer a frame tap may ask for.
FRAMES_BUFFER: int = SERVICES["frames"]["limits"]["subscriber_max_buffer_size"]

# State and mux samples a Robot's own latest-value subscribers keep: the newest and a few before.
_LATEST_BUFFER = 4
# Longest single wait for an answer before looking at the deadline again.
_ANSWER_POLL_S = 0.05
# How long an unknown source's error waits for the mux's list of the configured ones.
_MUX_CONNECT_S = 0.5
_NAME = re.compile(r"^[a-z0-9_-]{1,16}$")


class ChassisError(Exception):
    """Base of every error of this package."""


class NotServed(ChassisError):
    """No ``chassisd`` serves the robot (or the service asked for)."""

    def __init__(self, name: str) -> None:
        super().__init__(
            f"no service chassis/{name} — is chassisd running? (start it with `chassisd --robot …`)"
        )
        self.name = name


class UnknownSource(ChassisError):
    """The robot's ``chassisd`` has no velocity source of that name."""


class SourceTaken(ChassisError):
    """Another process already publishes as that source."""


class Timeout(ChassisError):
    """No answer to a control or sim request in time."""


class BadName(ChassisError, ValueError):
    """A robot or source name iceoryx2 or ``chassisd`` would refuse."""


class IpcError(ChassisError):
    """iceoryx2 failed in a way this package does not name."""


def now_ns() -> int:
    """``CLOCK_MONOTONIC`` now, ns: the clock of every stamp in the system."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def service_name(robot: str, service: str, source: str | None = None) -> str:
    """The iceoryx2 name of ``service`` (``state``, ``cmd``, ``control``…) of ``robot``."""
    template: str = SERVICES[service]["name"]
    return template.format(robot=robot, source=source)


def reply_name(service: str) -> str:
    """The event on which the server of ``service`` tells its clients an answer is ready."""
    return service + REPLY_SUFFIX


def _copy(sample: Any, kind: type[T]) -> T:
    # One copy, straight out of the shared memory (not through an intermediate `bytes`).
    return kind.from_buffer_copy(kind.from_address(sample.payload_ptr))


def _error_name(error: BaseException) -> str:
    return str(error.args[0]) if error.args else ""


def _seconds(timeout: float) -> iox2.Duration:
    return iox2.Duration.from_secs_f64(max(0.0, timeout))


def _wait(listener: Any, timeout: float) -> None:
    """Waits at most ``timeout`` seconds for a notification on ``listener``. A signal that
    interrupts the wait ends it early as a wake-up with nothing, like a timeout: a SIGCONT after
    Ctrl-Z and ``fg`` or a debugger attaching is no reason to fail, and SIGINT is raised as
    ``KeyboardInterrupt`` by Python itself right after. Only a failure of the listener raises."""
    try:
        listener.timed_wait(_seconds(timeout))
    except iox2.ListenerWaitError as e:
        # The binding raises one exception type; its text names the variant.
        if "InterruptSignal" not in str(e):
            raise


class VelocityRequest(_VelocityRequest):
    """``chassis::VelocityRequest``: what a source asks the mux for, with its constructors."""

    @classmethod
    def twist(cls, linear_x_mps: float, angular_z_radps: float = 0.0) -> VelocityRequest:
        """A twist request (v, ω)."""
        return cls(linear_x_mps=linear_x_mps, angular_z_radps=angular_z_radps)

    @classmethod
    def steer(cls, linear_x_mps: float, steer_rad: float) -> VelocityRequest:
        """A speed with a steering angle (Ackermann robots)."""
        return cls(linear_x_mps=linear_x_mps, steer_rad=steer_rad, flags=RequestFlags.STEER)

    @classmethod
    def limit(
        cls,
        forward_mps: float,
        reverse_mps: float,
        lateral_mps: float,
        angular_radps: float,
    ) -> VelocityRequest:
        """A speed envelope imposed on every source of this source's priority or lower."""
        return cls(
            flags=RequestFlags.LIMIT,
            limit_forward_mps=forward_mps,
            limit_reverse_mps=reverse_mps,
            limit_lateral_mps=lateral_mps,
            limit_angular_radps=angular_radps,
        )

    @classmethod
    def speed_limit(cls, mps: float) -> VelocityRequest:
        """Lowers the robot's standing speed limit to ``mps`` (> 0) for every source."""
        return cls(flags=RequestFlags.SPEED_LIMIT, speed_limit_mps=mps)

    @classmethod
    def heartbeat(cls) -> VelocityRequest:
        """ "Alive, asking for nothing"."""
        return cls(flags=RequestFlags.HEARTBEAT)


class ControlAnswer(ControlResponse):
    """The answer to a control or sim request: ok, or refused with its reason."""

    @property
    def ok(self) -> bool:
        """True when the action was done."""
        return self.status == ControlStatus.OK

    @property
    def status_name(self) -> str:
        """``ok``, ``refused``, ``unsupported``, ``invalid`` or ``timeout``."""
        return ControlStatus.name(self.status)

    def __str__(self) -> str:
        return f"{self.status_name}: {self.message}"


def _source_names(mux: MuxStatus) -> list[str]:
    """The names of the configured sources, in the mux's order (``MuxStatus.source_names()``)."""
    count = min(mux.source_count, len(mux.sources))
    return [mux.sources[i].name for i in range(count)]


def _active_source(mux: MuxStatus) -> str | None:
    """The name of the source the mux follows, or None (``MuxStatus.active_source_name()``)."""
    if mux.active_source == MuxStatus.NO_SOURCE or mux.active_source >= len(mux.sources):
        return None
    return mux.sources[mux.active_source].name


# What ``MuxStatus.why()`` adds for the drive (``DriveState``) as the stops of category 0 and 1
# left it.
_DRIVE = {
    DriveState.BRAKING: " · braking, then the drive is cut",
    DriveState.CUT: " · drive cut",
    DriveState.CANNOT_CUT: " · this robot cannot cut its drive: zero is held instead",
}


def _why(mux: MuxStatus) -> str:
    """Why the robot moves or stands (``MuxStatus.why()``), as ``chassis status`` says it:
    ``driving from teleop``, ``stopped: waiting for a zero from teleop since lock_released``.

    Motion starts only from a zero: after a stop (``mux.stop``, a ``Stop`` name) the source
    that would win must ask for nothing before its motion is obeyed again.
    """
    names = _source_names(mux)
    active = _active_source(mux)
    if active is not None:
        text = f"driving from {active}"
    elif mux.zero_reason == ZeroReason.AWAITING_ZERO:
        waiting = names[mux.awaiting_source] if mux.awaiting_source < len(names) else "?"
        text = (
            f"stopped: waiting for a zero from {waiting} since {Stop.NAMES.get(mux.stop, mux.stop)}"
        )
    elif mux.zero_reason == ZeroReason.HELD:
        text = f"stopped: held by {Stop.NAMES.get(mux.stop, mux.stop)}"
    else:
        text = f"stopped: {ZeroReason.NAMES.get(mux.zero_reason, mux.zero_reason)}"
    held = [
        f"{lock.name} (category {lock.category})"
        for lock in mux.locks[: min(mux.lock_count, len(mux.locks))]
        if lock.held
    ]
    if held:
        text += f" · held: {', '.join(held)}"
    if active is not None and mux.clamp_flags & ClampFlags.CHASSIS_NOT_READY:
        text += " · the chassis cannot move now: zero sent"
    text += _DRIVE.get(mux.drive, "")
    if mux.speed_limit_mps > 0:
        holder = mux.speed_limit_holder
        by = "operator" if holder == LockStatus.HOLDER_OPERATOR else names[holder]
        text += f" · limited to {mux.speed_limit_mps:g} m/s by {by}"
    return text


MuxStatus.source_names = _source_names  # type: ignore[attr-defined]
MuxStatus.why = _why  # type: ignore[attr-defined]

# The sources this process has connected to before (prefix, robot, source): the first
# connection of each sends one heartbeat (see ``Robot.source``); a reconnection sends none.
_CONNECTED_SOURCES: set[tuple[str | None, str, str]] = set()


def _described(array: Any, count: int) -> list[Any]:
    return [array[i] for i in range(min(count, len(array)))]


def _description_summary(d: RobotDescription) -> dict[str, Any]:
    """The description as a dict with only the used list entries."""
    out = d.to_dict()
    out["sensors"] = [s.to_dict() for s in _described(d.sensors, d.sensor_count)]
    out["joints"] = [j.to_dict() for j in _described(d.joints, d.joint_count)]
    out["sources"] = [s.to_dict() for s in _described(d.sources, d.source_count)]
    for key in ("sensor_count", "joint_count", "source_count"):
        del out[key]
    return out


RobotDescription.summary = _description_summary  # type: ignore[attr-defined]
MuxStatus.active_source_name = _active_source  # type: ignore[attr-defined]


class _Reader:
    """A subscriber and the listener its publisher wakes."""

    def __init__(self, node: Any, name: str, payload: type[Struct], buffer: int) -> None:
        self.payload = payload
        service = _open_pubsub(node, name, payload)
        limit = service.static_config.subscriber_max_buffer_size
        self.buffer = max(1, min(buffer, max(1, limit)))
        self.subscriber = service.subscriber_builder().buffer_size(self.buffer).create()
        self.listener = _open_event(node, name).listener_builder().create()

    def _next(self) -> Any | None:
        """The oldest sample received and not yet read (a copy), or None."""
        sample = self.subscriber.receive()
        if sample is None:
            return None
        out = _copy(sample, self.payload)
        sample.delete()
        return out

    def drain(self) -> list[Any]:
        """Every sample received since the last call, oldest first (copies)."""
        return list(iter(self._next, None))

    def each(self, timeout: float) -> Iterator[Any]:
        """Every pending sample, or those that arrive within ``timeout`` seconds, each yielded
        as soon as it is copied out; the samples that arrive while the caller handles one are
        yielded too, until none is pending."""
        # Spend the notifications of the samples pending now: a wait is for later ones.
        self.listener.try_wait()
        sample = self._next()
        if sample is None:
            _wait(self.listener, timeout)
            sample = self._next()
        while sample is not None:
            yield sample
            sample = self._next()

    def wait(self, timeout: float) -> list[Any]:
        """Every pending sample, or those that arrive within ``timeout`` seconds."""
        return list(self.each(timeout))


def _open_pubsub(node: Any, name: str, payload: type[Struct]) -> Any:
    try:
        return node.service_builder(iox2.ServiceName.new(name)).publish_subscribe(payload).open()
    except iox2.PublishSubscribeOpenError as e:
        if _error_name(e) == "DoesNotExist":
            raise NotServed(name.removeprefix("chassis/")) from None
        raise IpcError(f"opening {name}: {_error_name(e)}") from None


def _open_event(node: Any, name: str) -> Any:
    try:
        return node.service_builder(iox2.ServiceName.new(name)).event().open()
    except iox2.EventOpenError as e:
        if _error_name(e) == "DoesNotExist":
            raise NotServed(name.removeprefix("chassis/")) from None
        raise IpcError(f"opening the event {name}: {_error_name(e)}") from None


class StateStream:
    """Every state sample the service publishes, in order (see :meth:`Robot.state_stream`)."""

    def __init__(self, reader: _Reader) -> None:
        self._reader = reader

    @property
    def buffer(self) -> int:
        """The samples that may queue between two reads (the buffer asked for, clamped)."""
        return self._reader.buffer

    def drain(self) -> list[ChassisState]:
        """Every sample received since the last call, oldest first, without waiting."""
        return self._reader.drain()

    def wait(self, timeout: float) -> list[ChassisState]:
        """Every pending sample, or else those that arrive within ``timeout`` seconds."""
        return self._reader.wait(timeout)

    def each(self, timeout: float) -> Iterator[ChassisState]:
        """Every pending sample, or else those that arrive within ``timeout`` seconds, each
        yielded as soon as it is read: a client acts on the first of a burst before the next
        is copied out (:meth:`wait` hands the burst over when all of it is). Samples that arrive
        while the loop body runs are yielded too, until none is pending::

            for state in stream.each(0.1):
                handle(state)
        """
        return self._reader.each(timeout)


class FrameTap:
    """Every frame on the bus, both directions (gaps show in ``BusFrame.seq``)."""

    def __init__(self, reader: _Reader) -> None:
        self._reader = reader

    def drain(self) -> list[BusFrame]:
        """Every frame received since the last call, oldest first."""
        return self._reader.drain()

    def wait(self, timeout: float) -> list[BusFrame]:
        """Every pending frame, or else those that arrive within ``timeout`` seconds."""
        return self._reader.wait(timeout)

    def each(self, timeout: float) -> Iterator[BusFrame]:
        """Every pending frame, or else those that arrive within ``timeout`` seconds, each
        yielded as soon as it is read (see :meth:`StateStream.each`)."""
        return self._reader.each(timeout)


class Source:
    """Publishes velocity requests as one configured source of the robot's mux."""

    def __init__(self, name: str, publisher: Any, notifier: Any) -> None:
        self.name = name
        self._publisher = publisher
        self._notifier = notifier
        self._seq = 0

    def send(self, request: _VelocityRequest) -> None:
        """Sends ``request`` now with the next sequence number and, unless it has one, the
        current ``CLOCK_MONOTONIC`` stamp, and wakes the service. A request with a NaN or an
        infinity in any of its numbers, or a speed limit that is not more than 0, is refused with
        ``ValueError`` and nothing is sent."""
        for name, kind in request._fields_:
            if kind is ctypes.c_float and not math.isfinite(getattr(request, name)):
                raise ValueError(f"request not sent: {name} is not a finite number")
        if request.flags & RequestFlags.SPEED_LIMIT and request.speed_limit_mps <= 0:
            raise ValueError("request not sent: a speed limit is more than 0 m/s")
        self._seq += 1
        sample = self._publisher.loan_uninit()
        payload = sample.payload().contents
        ctypes.memmove(ctypes.addressof(payload), ctypes.addressof(request), ctypes.sizeof(request))
        payload.seq = self._seq
        if payload.stamp_ns == 0:
            payload.stamp_ns = now_ns()
        sample.assume_init().send()
        self._notifier.notify()

    def twist(self, linear_x_mps: float, angular_z_radps: float = 0.0) -> None:
        """Asks for a forward speed and a yaw rate."""
        self.send(VelocityRequest.twist(linear_x_mps, angular_z_radps))

    def steer(self, linear_x_mps: float, steer_rad: float) -> None:
        """Asks for a forward speed and a steering angle (Ackermann robots)."""
        self.send(VelocityRequest.steer(linear_x_mps, steer_rad))

    def limit_speed(self, mps: float) -> None:
        """Lowers the robot's standing speed limit to ``mps`` m/s for every source. A limit
        above the standing one changes nothing: only the operator raises it
        (``Robot.control("speed-limit", mps=…)``). This source's latest request stands."""
        self.send(VelocityRequest.speed_limit(mps))

    def heartbeat(self) -> None:
        """ "Alive, asking for nothing" — a required source's heartbeat."""
        self.send(VelocityRequest.heartbeat())

    def stop(self) -> None:
        """An explicit stop (wins by this source's priority)."""
        self.send(VelocityRequest.twist(0.0, 0.0))

    def close(self) -> None:
        """Releases the source: another process may take it."""
        self._notifier.delete()
        self._publisher.delete()


class _Counter:
    """A request-response client, the notifier that wakes the server and the reply listener."""

    def __init__(self, node: Any, name: str, request: type[Struct]) -> None:
        self.name = name
        service_builder = node.service_builder(iox2.ServiceName.new(name))
        try:
            service = service_builder.request_response(request, ControlResponse).open()
        except iox2.RequestResponseOpenError as e:
            if _error_name(e) == "DoesNotExist":
                raise NotServed(name.removeprefix("chassis/")) from None
            raise IpcError(f"opening {name}: {_error_name(e)}") from None
        self.client = service.client_builder().create()
        self.requests = _open_event(node, name).notifier_builder().create()
        self.replies = _open_event(node, reply_name(name)).listener_builder().create()

    def ask(self, request: Any, timeout: float) -> ControlAnswer:
        pending = self.client.send_copy(request)
        self.requests.notify()
        deadline = time.monotonic() + timeout
        while True:
            while True:
                response = pending.receive()
                if response is None:
                    break
                answer = _copy(response, ControlAnswer)
                response.delete()
                if answer.request_seq == request.seq:
                    return answer
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"no answer from {self.name} within {timeout} s")
            _wait(self.replies, min(left, _ANSWER_POLL_S))


def _flag(value: Any, what: str) -> int:
    if isinstance(value, str):
        if value in ("on", "engage", "enable"):
            return 1
        if value in ("off", "release", "disable"):
            return 0
        raise ValueError(f"{what}: '{value}' is neither on nor off")
    return 1 if value else 0


def _u8(value: int, what: str) -> int:
    if not 0 <= int(value) <= 255:
        raise ValueError(f"{what} {value} is outside 0..255")
    return int(value)


def _fault_code(which: str) -> int:
    key = which.upper().replace("-", "_")
    for candidate in (key, key + "_COMM"):
        if hasattr(FaultClear, candidate):
            return int(getattr(FaultClear, candidate))
    names = ", ".join(FaultClear.NAMES.values())
    raise ValueError(f"unknown fault '{which}' (one of: {names})")


def control_request(action: str, /, **args: Any) -> ControlRequest:
    """The control request for ``action`` with the arguments ``chassis control`` takes.

    Actions: ``estop``, ``estop-release``, ``lock-engage`` / ``lock-release`` (``lock=``; an
    engage takes ``category=`` 0, 1 or 2, the stop category, else the lock's configured one),
    ``mode`` (``mode="command"|"standby"``), ``brake`` (``action="engage"|"release"``),
    ``clear-fault`` (``which="all"``, ``"motor-1"``…), ``lights`` (``mode="off"|"on"|
    "breathing"|"custom"|"auto"``, ``brightness=100``), ``off-road`` (``state=``), ``lift``
    (``position=`` %, ``disable=False``), ``servos`` (``pan=``, ``tilt=`` degrees), ``power``
    (``state=``), ``steering-zero``, ``silent`` (``state=``), ``speed-limit`` (``mps=``: the
    robot's speed limit, raised or lowered by the operator; 0 lifts it).
    """
    request = ControlRequest()

    def arg(index: int, value: int) -> None:
        request.arg[index] = value

    def take(name: str, default: Any = None) -> Any:
        if name in args:
            return args.pop(name)
        if default is None:
            raise TypeError(f"control '{action}' needs {name}=")
        return default

    if action in ("estop", "lock-engage"):
        request.kind = ControlKind.LOCK_ENGAGE
        _set_lock(request, "estop" if action == "estop" else take("lock"))
        category = args.pop("category", None)
        if category is not None:
            if category not in (0, 1, 2):
                raise ValueError(f"stop category {category}: 0, 1 or 2")
            arg(0, category + 1)
    elif action in ("estop-release", "lock-release"):
        request.kind = ControlKind.LOCK_RELEASE
        _set_lock(request, "estop" if action == "estop-release" else take("lock"))
    elif action == "mode":
        request.kind = ControlKind.MODE
        mode = take("mode")
        if mode not in ("command", "standby"):
            raise ValueError(f"mode '{mode}' is neither command nor standby")
        arg(0, ControlMode.COMMAND if mode == "command" else ControlMode.STANDBY)
    elif action == "brake":
        request.kind = ControlKind.BRAKE
        arg(0, _flag(take("action"), "brake"))
    elif action == "clear-fault":
        request.kind = ControlKind.CLEAR_FAULTS
        arg(0, _fault_code(take("which", "all")))
    elif action == "lights":
        request.kind = ControlKind.LIGHTS
        mode = take("mode")
        if mode == "auto":
            arg(0, LightMode.OFF)
            arg(2, 0)
        else:
            if not hasattr(LightMode, str(mode).upper()):
                raise ValueError(f"light mode '{mode}' unknown (off, on, breathing, custom, auto)")
            arg(0, getattr(LightMode, str(mode).upper()))
            arg(2, 1)
        arg(1, _u8(take("brightness", 100), "brightness"))
    elif action == "off-road":
        request.kind = ControlKind.OFF_ROAD
        arg(0, _flag(take("state"), "off-road"))
    elif action == "lift":
        request.kind = ControlKind.LIFT
        arg(0, 0 if take("disable", False) else 1)
        request.value[0] = float(take("position"))
    elif action == "servos":
        request.kind = ControlKind.SERVOS
        request.value[0] = math.radians(float(take("pan", 0.0)))
        request.value[1] = math.radians(float(take("tilt", 0.0)))
    elif action == "power":
        request.kind = ControlKind.POWER
        arg(0, _flag(take("state"), "power"))
    elif action == "steering-zero":
        request.kind = ControlKind.STEERING_ZERO
    elif action == "silent":
        request.kind = ControlKind.SILENT
        arg(0, _flag(take("state"), "silent"))
    elif action == "speed-limit":
        request.kind = ControlKind.SPEED_LIMIT
        request.value[0] = float(take("mps"))
    else:
        raise ValueError(f"unknown control action '{action}'")
    if args:
        raise TypeError(f"control '{action}' takes no {', '.join(sorted(args))}")
    return request


def _set_lock(request: ControlRequest, lock: str) -> None:
    try:
        request.name = lock
    except ValueError as e:
        raise BadName(str(e)) from None


def _valid_name(name: str) -> str:
    if not _NAME.match(name):
        raise BadName(f"'{name}' is not a valid robot or source name (1-16 of a-z 0-9 - _)")
    return name


def _config(prefix: str | None) -> Any:
    config = iox2.config.default()
    prefix = prefix if prefix is not None else os.environ.get(PREFIX_ENV)
    if prefix:
        config.global_cfg.prefix = iox2.FileName.new(prefix)
    return config


class Robot:
    """A connection to one robot served by ``chassisd``.

    Its own state subscriber reads ``chassis/<name>/state`` as a latest-value topic (it keeps
    the newest samples); a reader that needs every sample opens :meth:`state_stream`.
    """

    def __init__(self, name: str, node: Any, prefix: str | None = None) -> None:
        self.name = name
        self._node = node
        self._prefix = prefix if prefix is not None else os.environ.get(PREFIX_ENV)
        self._state = _Reader(node, service_name(name, "state"), ChassisState, _LATEST_BUFFER)
        self._mux: _Reader | None = None
        self._latest_state: ChassisState | None = None
        self._latest_mux: MuxStatus | None = None
        self._description: _Reader | None = None
        self._latest_description: RobotDescription | None = None
        self._control: _Counter | None = None
        self._sim: _Counter | None = None
        self._seq = 0

    @classmethod
    def connect(cls, name: str, prefix: str | None = None) -> Robot:
        """Connects to the robot served as ``chassis/<name>/``; ``prefix`` is the iceoryx2 file
        prefix (default: the environment's ``CHASSIS_IPC_PREFIX``, else iceoryx2's).

        Raises :class:`NotServed` when no ``chassisd`` serves ``name``.
        """
        _valid_name(name)
        node = (
            iox2.NodeBuilder.new()
            .config(_config(prefix))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )
        try:
            state = _open_pubsub(node, service_name(name, "state"), ChassisState)
        except NotServed:
            raise NotServed(name) from None
        if state.dynamic_config.number_of_publishers == 0:
            raise NotServed(name)
        return cls(name, node, prefix)

    def is_served(self) -> bool:
        """True while ``chassisd`` still publishes this robot's state."""
        try:
            state = _open_pubsub(self._node, service_name(self.name, "state"), ChassisState)
        except NotServed:
            return False
        return bool(state.dynamic_config.number_of_publishers > 0)

    def _take_states(self) -> int:
        samples = self._state.drain()
        if samples:
            self._latest_state = samples[-1]
        return len(samples)

    def latest_state(self) -> ChassisState | None:
        """The newest state sample (a late joiner gets the last one published)."""
        self._take_states()
        return self._latest_state

    def wait_state(self, timeout: float) -> ChassisState | None:
        """Waits at most ``timeout`` seconds for a state sample newer than those seen so far."""
        samples = self._state.wait(timeout)
        if not samples:
            return None
        self._latest_state = samples[-1]
        return self._latest_state

    def state_stream(self, buffer: int = STATE_BUFFER) -> StateStream:
        """A stream of every state sample, with its own subscriber and listener.

        ``buffer`` samples may queue between two reads before the oldest are lost; it is
        clamped to 1..the service's maximum (:data:`STATE_BUFFER`). Gaps show in
        ``ChassisState.seq``. The first sample is the newest one published before the stream
        opened.
        """
        return StateStream(
            _Reader(self._node, service_name(self.name, "state"), ChassisState, buffer)
        )

    def frames(self, buffer: int = FRAMES_BUFFER) -> FrameTap:
        """A tap of every frame on the bus, both directions."""
        return FrameTap(_Reader(self._node, service_name(self.name, "frames"), BusFrame, buffer))

    def _take_mux(self) -> int:
        if self._mux is None:
            self._mux = _Reader(
                self._node, service_name(self.name, "mux"), MuxStatus, _LATEST_BUFFER
            )
        samples = self._mux.drain()
        if samples:
            self._latest_mux = samples[-1]
        return len(samples)

    def latest_mux(self) -> MuxStatus | None:
        """The newest mux decision."""
        self._take_mux()
        return self._latest_mux

    def wait_mux(self, timeout: float) -> MuxStatus | None:
        """Waits at most ``timeout`` seconds for a newer mux decision; returns the newest."""
        if self._take_mux() == 0 and self._mux is not None:
            samples = self._mux.wait(timeout)
            if samples:
                self._latest_mux = samples[-1]
        return self._latest_mux

    def _take_description(self) -> int:
        if self._description is None:
            self._description = _Reader(
                self._node, service_name(self.name, "robot"), RobotDescription, 2
            )
        samples = self._description.drain()
        if samples:
            self._latest_description = samples[-1]
        return len(samples)

    def wait_description(self, timeout: float = 1.0) -> RobotDescription:
        """What the robot is, as ``chassisd`` describes the robot it drives: kind, model,
        protocol in use, its effective limits, geometry, battery levels, sensors, joints and
        the mux's sources (see ``RobotDescription.summary()`` for a readable dict).

        The service keeps it for late joiners and hands it to a new reader within one tick of
        its loop: the first call waits at most ``timeout`` seconds for it. Raises
        :class:`Timeout` when none arrives.
        """
        self._take_description()
        deadline = time.monotonic() + timeout
        while self._latest_description is None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise Timeout(f"no description on {service_name(self.name, 'robot')}")
            # The state is published at least every 100 ms: each sample is a chance to look.
            states = self._state.wait(min(left, _ANSWER_POLL_S))
            if states:
                self._latest_state = states[-1]
            self._take_description()
        return self._latest_description

    @property
    def description(self) -> RobotDescription:
        """The robot's description (:meth:`wait_description` with a one-second wait), updated
        when the service publishes a new one (the protocol once detection decides)."""
        return self.wait_description(1.0)

    def source(self, name: str) -> Source:
        """Publishes velocity requests as the configured source ``name`` (its priority and
        timeout are the service's). Raises :class:`UnknownSource` when the service has no such
        source and :class:`SourceTaken` when another process holds it.

        Motion starts only from a zero: after a stop it did not ask for (chassisd starting, a
        lock released, the safety monitor or the bus back), the service obeys a source's motion
        only once it has asked for nothing since. Starting a process is a deliberate act, so
        its first connection of a source sends one heartbeat; a reconnection of the same source
        by the same process sends none (send :meth:`Source.stop` before driving again).
        """
        _valid_name(name)
        topic = service_name(self.name, "cmd", name)
        try:
            data = _open_pubsub(self._node, topic, _VelocityRequest)
            events = _open_event(self._node, topic)
        except NotServed:
            # A new mux subscriber gets the latest decision once the publisher connects it.
            mux = self.wait_mux(_MUX_CONNECT_S)
            configured = ", ".join(_source_names(mux)) if mux else "unknown"
            raise UnknownSource(
                f"robot '{self.name}' has no source called '{name}' (configured: {configured}); "
                "sources are set in chassisd's config"
            ) from None
        taken = SourceTaken(
            f"source '{name}' of robot '{self.name}' is already held by another process"
        )
        try:
            publisher = data.publisher_builder().create()
        except iox2.PublisherCreateError as e:
            if _error_name(e) == "ExceedsMaxSupportedPublishers":
                raise taken from None
            raise IpcError(f"publisher of {topic}: {_error_name(e)}") from None
        try:
            notifier = events.notifier_builder().create()
        except iox2.NotifierCreateError as e:
            publisher.delete()
            if _error_name(e) == "ExceedsMaxSupportedNotifiers":
                raise taken from None
            raise IpcError(f"notifier of {topic}: {_error_name(e)}") from None
        source = Source(name, publisher, notifier)
        key = (self._prefix, self.name, name)
        if key not in _CONNECTED_SOURCES:
            _CONNECTED_SOURCES.add(key)
            source.heartbeat()
        return source

    def control(self, action: str, /, timeout: float = 3.0, **args: Any) -> ControlAnswer:
        """Asks for a control action (see :func:`control_request`) and waits at most
        ``timeout`` seconds for the answer: ok, or refused with its reason."""
        request = control_request(action, **args)
        if self._control is None:
            self._control = _Counter(self._node, service_name(self.name, "control"), ControlRequest)
        return self._ask(self._control, request, timeout)

    def sim(
        self,
        kind: str,
        flag: bool = True,
        index: int = 0,
        value: float = 0.0,
        timeout: float = 3.0,
    ) -> ControlAnswer:
        """Injects a fault into the robot's simulated chassis: ``kind`` is a ``SimKind`` name
        (``flood``, ``bumper``, ``obstacle-ahead``…) as ``chassis sim`` takes it."""
        code = getattr(SimKind, kind.upper().replace("-", "_"), None)
        if code is None:
            raise ValueError(
                f"unknown sim request '{kind}' (one of: {', '.join(SimKind.NAMES.values())})"
            )
        request = SimRequest(
            kind=code, flag=1 if flag else 0, index=_u8(index, "index"), value=value
        )
        if self._sim is None:
            self._sim = _Counter(self._node, service_name(self.name, "sim"), SimRequest)
        return self._ask(self._sim, request, timeout)

    def _ask(self, counter: _Counter, request: Any, timeout: float) -> ControlAnswer:
        self._seq += 1
        request.seq = self._seq
        request.stamp_ns = now_ns()
        return counter.ask(request, timeout)
