"""The live view: a run served over the Foxglove WebSocket protocol while it runs (``gyro-sim run SCENE --live``).

The server is the ``foxglove-sdk`` package (the optional extra ``live``: ``pip install 'gyro_sim[live]'``); the
Foxglove app connects to ``ws://HOST:PORT`` ("Open connection" → "Foxglove WebSocket") and shows the run with
``config/foxglove_layout.json``.

Channels carry the bag's topic names and, but for ``/tf`` and ``/tf_static``, the bag's message fields (the
dicts of :func:`gyro_sim.messages.state_messages`, JSON-encoded, each with a JSON schema named after its ROS 2
type), so one layout, with the same message paths, serves a live run, a recorded bag and ``foxglove_bridge`` on
the ROS nodes:

====================== ================================ ======================================================
channel                schema (JSON)                    content (SI units; frames as in gyro_sim.messages)
====================== ================================ ======================================================
``/gyro/imu``          sensor_msgs/msg/Imu              orientation = attitude body → case (x, y, z, w);
                                                        angular_velocity = Ω_b (body, rad/s): ``.z`` = spin
``/gyro/kinetic_moment`` geometry_msgs/msg/Vector3Stamped L, frame gyro_case, N·m·s
``/gyro/euler``        geometry_msgs/msg/Vector3Stamped x = ψ, y = θ, z = φ of the body in the L-frame, rad
``/gyro/torque``       geometry_msgs/msg/Vector3Stamped electrodynamic torque, frame gyro_case, N·m
``/gyro/stators``      sensor_msgs/msg/JointState       effort = current A, velocity = signed field rate
                                                        rad/s, position = field phase rad
``/gyro/effects``      sensor_msgs/msg/JointState       internal bodies, only for scenes that have one
``/tf``                foxglove.FrameTransforms         gyro_case → gyro_rotor (the attitude, a pure rotation)
                                                        and gyro_case → gyro_l_frame, each sample
``/tf_static``         foxglove.FrameTransforms         gyro_case → gyro_stator_<name>, about once a wall s
====================== ================================ ======================================================

Message times (the protocol's ``timestamp``, the app's receive time) and the server time (``Time`` capability)
are the simulation time in ns, as the bags' log times. Pacing: sample t is sent at wall time
t0 + (t − t_first) / rate_factor (a run that cannot keep up is sent as fast as it goes, its clock slipped, not
caught up in a burst). :meth:`LiveView.wait_for_subscriptions` holds the run's start until that many channel
subscriptions (summed over clients) are made, so a client connected first misses no sample; :meth:`LiveView.hold`
keeps serving after the run until the clients unsubscribe (or a time limit), so none misses the last ones.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Optional

from gyro_sim.common.extras import MissingExtra, require
from gyro_sim.io.messages import (TOPIC_EFFECTS, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATORS,
                       TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TORQUE, TOPICS, effects_message, stamp_ns, state_messages)

__all__ = ["LIVE_WHAT", "LiveUnavailable", "require_foxglove", "LiveView", "CHANNELS", "json_schema",
           "frame_transforms"]

#: what needs the extra ``live``, in the one-line message of :func:`gyro_sim.extras.require`
LIVE_WHAT = "gyro-sim run --live"

#: the channels advertised at the start, in the order each sample logs them (``/gyro/effects`` comes on first use)
CHANNELS: tuple[str, ...] = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_TF,
                             TOPIC_TF_STATIC)
_SAME_AS_BAG = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS)
_RESEND_STATIC = 1.0  # wall s between /tf_static messages (a client that subscribes late gets the stator frames)
_SLIP = 0.25  # wall s behind the pacing clock after which the clock slips instead of the run catching up

#: foxglove.FrameTransforms as a JSON schema (https://docs.foxglove.dev/docs/sdk/schemas/frame-transforms)
_VEC = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
FRAME_TRANSFORMS_SCHEMA = {
    "title": "foxglove.FrameTransforms", "type": "object",
    "properties": {"transforms": {"type": "array", "items": {
        "title": "foxglove.FrameTransform", "type": "object",
        "properties": {"timestamp": _TIME, "parent_frame_id": {"type": "string"},
                       "child_frame_id": {"type": "string"}, "translation": _VEC, "rotation": _QUAT}}}}}


#: foxglove-sdk cannot be imported (the extra ``live`` is not installed): gyro_sim.extras' one-line error
LiveUnavailable = MissingExtra


def require_foxglove():
    """The ``foxglove`` module, or :class:`LiveUnavailable` naming the extra to install (one message format for
    every extra: :func:`gyro_sim.extras.require`)."""
    require("live", LIVE_WHAT)
    try:
        import foxglove
        from foxglove.websocket import Capability  # noqa: F401  (the server part: not in every build)
    except ImportError as e:  # found but unusable (a build without the server part)
        raise MissingExtra(f"{LIVE_WHAT} needs foxglove-sdk with its WebSocket server ({e}): "
                           "pip install --upgrade 'gyro_sim[live]'", "live", ("foxglove",)) from None
    return foxglove


def json_schema(example: Any, title: Optional[str] = None) -> dict:
    """A JSON schema (types only) describing ``example``, a message as plain dicts, lists, numbers, strings."""
    if isinstance(example, dict):
        out = {"type": "object", "properties": {k: json_schema(v) for k, v in example.items()}}
        return {"title": title, **out} if title else out
    if isinstance(example, (list, tuple)):
        return {"type": "array", "items": json_schema(example[0]) if example else {"type": "number"}}
    if isinstance(example, bool):
        return {"type": "boolean"}
    if isinstance(example, int):
        return {"type": "integer"}
    if isinstance(example, float):
        return {"type": "number"}
    return {"type": "string"}


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float as None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def frame_transforms(tf: dict) -> dict:
    """A ``tf2_msgs/TFMessage`` dict (:func:`gyro_sim.messages.state_messages`) as ``foxglove.FrameTransforms``:
    the same transforms (parent ← child, translation m, rotation x, y, z, w child → parent), stamps as sec/nsec."""
    out = []
    for tr in tf["transforms"]:
        st = tr["header"]["stamp"]
        out.append({"timestamp": {"sec": st["sec"], "nsec": st["nanosec"]},
                    "parent_frame_id": tr["header"]["frame_id"], "child_frame_id": tr["child_frame_id"],
                    "translation": dict(tr["transform"]["translation"]),
                    "rotation": dict(tr["transform"]["rotation"])})
    return {"transforms": out}


class _Subscriptions:
    """Counts the channel subscriptions of the server's clients (a foxglove ServerListener; called from its
    threads)."""

    def __init__(self):
        self.count = 0
        self.changed = threading.Condition()

    def on_subscribe(self, client, channel) -> None:
        with self.changed:
            self.count += 1
            self.changed.notify_all()

    def on_unsubscribe(self, client, channel) -> None:
        with self.changed:
            self.count -= 1
            self.changed.notify_all()


class LiveView:
    """A Foxglove WebSocket server for one in-process run; call it with each chunk of samples
    (:meth:`gyro_sim.simulate.Runner.samples`: t s, L N·m·s case, q (w, x, y, z) body → case, omega_b rad/s body,
    euler rad, torque N·m case, current A, rate rad/s, phase rad, per stator) as the run's ``on_samples``.

    ``rate_factor``: simulated s per wall s (pacing); ``host``/``port``: where to listen (port 0: a free one,
    see :attr:`port`). Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, scene, host: str = "127.0.0.1", port: int = 8765, rate_factor: float = 1.0,
                 clock=time.monotonic, sleep=time.sleep):
        if not (math.isfinite(rate_factor) and rate_factor > 0):
            raise ValueError(f"--rate-factor {rate_factor}: must be a positive number (simulated s per wall s)")
        fox = require_foxglove()
        from foxglove.websocket import Capability

        from gyro_sim.io.recording import stator_frames

        self._fox, self.rate_factor, self._clock, self._sleep = fox, float(rate_factor), clock, sleep
        self.names = [st.name for st in scene.stators]
        self.subs = _Subscriptions()
        self.server = fox.start_server(name=f"gyro_sim: {scene.name}", host=host, port=port,
                                       capabilities=[Capability.Time], server_listener=self.subs)
        self.channels: dict[str, Any] = {}
        n = len(self.names)
        example = state_messages(0.0, [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, [0.0] * 3,
                                 self.names, [0.0] * n, [0.0] * n, [0.0] * n)
        for topic in _SAME_AS_BAG:
            self._channel(topic, json_schema(example[topic], TOPICS[topic]))
        self._channel(TOPIC_TF, FRAME_TRANSFORMS_SCHEMA)
        self._channel(TOPIC_TF_STATIC, FRAME_TRANSFORMS_SCHEMA)
        self._static = frame_transforms(stator_frames(scene))
        self._static_sent: Optional[float] = None
        self._origin: Optional[tuple[float, float]] = None  # (wall s, simulated s) of the pacing clock
        self.samples_sent = 0

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return self.server.port

    def _channel(self, topic: str, schema: dict):
        self.channels[topic] = self._fox.Channel(topic, schema=schema, message_encoding="json")
        return self.channels[topic]

    def wait_for_subscriptions(self, n: int, poll: float = 0.2) -> None:
        """Block until at least ``n`` channel subscriptions are made (no timeout; Ctrl-C stops it)."""
        with self.subs.changed:
            while self.subs.count < n:
                self.subs.changed.wait(poll)  # (a timeout: signals are handled between waits)

    def _log(self, topic: str, msg: dict, ns: int) -> None:
        self.channels[topic].log(_finite(msg), log_time=ns)

    def _pace(self, t: float) -> None:
        """Sleep until simulated time ``t`` is due on the wall clock (× rate_factor)."""
        now = self._clock()
        if self._origin is None:
            self._origin = (now, t)
            return
        due = self._origin[0] + (t - self._origin[1]) / self.rate_factor
        if now < due:
            self._sleep(due - now)
        elif now - due > _SLIP:  # behind (a compile, a slow stretch): slip the clock
            self._origin = (now, t)

    def publish(self, t: float, L, q, omega_b, euler, torque, current, rate, phase,
                effects: Optional[dict] = None) -> None:
        """One output sample at simulation time ``t`` (s), paced; units and frames as in the class docstring."""
        self._pace(t)
        ns = stamp_ns(t)
        msgs = state_messages(t, L, q, omega_b, euler, torque, self.names, current, rate, phase)
        for topic in _SAME_AS_BAG:
            self._log(topic, msgs[topic], ns)
        self._log(TOPIC_TF, frame_transforms(msgs[TOPIC_TF]), ns)
        eff = effects_message(t, effects) if effects else None
        if eff is not None:
            if TOPIC_EFFECTS not in self.channels:
                self._channel(TOPIC_EFFECTS, json_schema(eff, TOPICS[TOPIC_EFFECTS]))
            self._log(TOPIC_EFFECTS, eff, ns)
        now = self._clock()
        if self._static_sent is None or now - self._static_sent >= _RESEND_STATIC:
            self._log(TOPIC_TF_STATIC, self._static, ns)
            self._static_sent = now
        self.server.broadcast_time(ns)
        self.samples_sent += 1

    def __call__(self, s: dict) -> None:
        """Publish a chunk of samples (the ``on_samples`` callback of :func:`gyro_sim.simulate.run`)."""
        eff = s.get("effects") or {}
        for i in range(len(s["t"])):
            self.publish(float(s["t"][i]), s["L"][i], s["q"][i], s["omega_b"][i], s["euler"][i], s["torque"][i],
                         s["current"][i], s["rate"][i], s["phase"][i],
                         {k: v[i] for k, v in eff.items()} if eff else None)

    def hold(self, seconds: float, poll: float = 0.2) -> None:
        """After the run: keep serving until every subscription is gone (the clients got what was sent and left)
        or ``seconds`` wall seconds have passed, so the last samples are not cut off by :meth:`close`."""
        end = self._clock() + seconds
        with self.subs.changed:
            while self.subs.count > 0 and self._clock() < end:
                self.subs.changed.wait(min(poll, max(end - self._clock(), 0.0)))

    def close(self) -> None:
        """Stop the server (clients are disconnected); idempotent."""
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
