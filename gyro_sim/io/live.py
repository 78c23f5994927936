"""The live view: a run served over the Foxglove WebSocket protocol while it runs (``gyro-sim run SCENE --live``).

The server is the ``foxglove-sdk`` package (the optional extra ``live``: ``pip install 'gyro_sim[live]'``),
behind :class:`gyro_sim.io.live_relay.SubprotocolRelay`, so both names of the protocol are accepted:
``foxglove.sdk.v1`` (the Foxglove app) and ``foxglove.websocket.v1`` (the ws-protocol clients: the npm
``@foxglove/ws-protocol``, Lichtblick). The Foxglove app connects to ``ws://HOST:PORT`` ("Open connection" →
"Foxglove WebSocket") and shows the run with a layout of :mod:`gyro_sim.io.foxglove_layout`. docs/live.md is the
user's guide.

Channels carry the bag's topics in the bag's encoding: each message CDR-encoded by the same serializer
(:func:`gyro_sim.io.bag_format.cdr_message`, byte for byte as in a bag) under the same ``ros2msg`` schema (type
name and text as the bag's MCAP schema record), as ``foxglove_bridge`` serves the ROS nodes' topics; so one
layout, with the same message paths, serves a live run, a recorded bag and the bridge:

======================== ================================ ====================================================
channel                  schema (ros2msg)                 content (SI units; frames as in gyro_sim.io.messages)
======================== ================================ ====================================================
``/gyro/imu``            sensor_msgs/msg/Imu              orientation = attitude body → case (x, y, z, w);
                                                          angular_velocity = Ω_b (body, rad/s): ``.z`` = spin
``/gyro/kinetic_moment`` geometry_msgs/msg/Vector3Stamped L, frame gyro_case, N·m·s
``/gyro/euler``          geometry_msgs/msg/Vector3Stamped x = ψ, y = θ, z = φ of the body in the L-frame, rad
``/gyro/torque``         geometry_msgs/msg/Vector3Stamped electrodynamic torque, frame gyro_case, N·m
``/gyro/stators``        sensor_msgs/msg/JointState       effort = current A, velocity = signed field rate
                                                          rad/s, position = field phase rad
``/gyro/effects``        sensor_msgs/msg/JointState       internal bodies, only for scenes that have one
``/tf``                  tf2_msgs/msg/TFMessage           gyro_case → gyro_rotor (the attitude, a pure rotation)
                                                          and gyro_case → gyro_l_frame, each sample
``/tf_static``           tf2_msgs/msg/TFMessage           gyro_case → gyro_stator_<name> (the stator's triad
                                                          e1, e2, u), about once a wall s
======================== ================================ ====================================================

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
                                  TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TORQUE, effects_message, stamp_ns, state_messages)

__all__ = ["LIVE_WHAT", "LiveUnavailable", "require_foxglove", "LiveView", "CHANNELS", "MESSAGE_ENCODING",
           "SCHEMA_ENCODING"]

#: what needs the extra ``live``, in the one-line message of :func:`gyro_sim.extras.require`
LIVE_WHAT = "gyro-sim run --live"

#: the channels advertised at the start (``/gyro/effects`` comes on first use); a sample logs ``/tf_static`` first
#: (the first sample, then about once a wall second), then the others in this order
CHANNELS: tuple[str, ...] = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_TF,
                             TOPIC_TF_STATIC)
#: the channels' message encoding and schema encoding: a bag's (rosbag2 MCAP) and foxglove_bridge's on ROS 2
MESSAGE_ENCODING, SCHEMA_ENCODING = "cdr", "ros2msg"
_PER_SAMPLE = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_TF)
_RESEND_STATIC = 1.0  # wall s between /tf_static messages (a client that subscribes late gets the stator frames)
_SLIP = 0.25  # wall s behind the pacing clock after which the clock slips instead of the run catching up


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

        from gyro_sim.io.live_relay import SubprotocolRelay
        from gyro_sim.io.recording import stator_frames

        self._fox, self.rate_factor, self._clock, self._sleep = fox, float(rate_factor), clock, sleep
        self.names = [st.name for st in scene.stators]
        self.subs = _Subscriptions()
        # the SDK's server on this machine only; clients reach it through the relay, under either subprotocol
        self.server = fox.start_server(name=f"gyro_sim: {scene.name}", host="127.0.0.1", port=0,
                                       capabilities=[Capability.Time], server_listener=self.subs)
        try:
            self.relay: Optional[SubprotocolRelay] = SubprotocolRelay(host, port, self.server.port)
        except BaseException:
            self.server.stop()
            raise
        self._port = self.relay.port
        self.channels: dict[str, Any] = {}
        for topic in CHANNELS:
            self._channel(topic)
        self._static = stator_frames(scene)
        self._static_sent: Optional[float] = None
        self._origin: Optional[tuple[float, float]] = None  # (wall s, simulated s) of the pacing clock
        self.samples_sent = 0

    @property
    def port(self) -> int:
        """The TCP port clients connect to (the relay's)."""
        return self._port

    def _channel(self, topic: str):
        from gyro_sim.io.bag_format import ros2msg_schema

        name, text = ros2msg_schema(topic)
        schema = self._fox.Schema(name=name, encoding=SCHEMA_ENCODING, data=text.encode("utf-8"))
        self.channels[topic] = self._fox.Channel(topic, schema=schema, message_encoding=MESSAGE_ENCODING)
        return self.channels[topic]

    def wait_for_subscriptions(self, n: int, poll: float = 0.2) -> None:
        """Block until at least ``n`` channel subscriptions are made (no timeout; Ctrl-C stops it)."""
        with self.subs.changed:
            while self.subs.count < n:
                self.subs.changed.wait(poll)  # (a timeout: signals are handled between waits)

    def _log(self, topic: str, msg: dict, ns: int) -> None:
        from gyro_sim.io.bag_format import cdr_message

        self.channels[topic].log(bytes(cdr_message(topic, msg)), log_time=ns)

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
        now = self._clock()
        if self._static_sent is None or now - self._static_sent >= _RESEND_STATIC:  # (first, as in a bag)
            self._log(TOPIC_TF_STATIC, self._static, ns)
            self._static_sent = now
        for topic in _PER_SAMPLE:
            self._log(topic, msgs[topic], ns)
        eff = effects_message(t, effects) if effects else None
        if eff is not None:
            if TOPIC_EFFECTS not in self.channels:
                self._channel(TOPIC_EFFECTS)
            self._log(TOPIC_EFFECTS, eff, ns)
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
        if self.relay is not None:
            self.relay.close()
            self.relay = None
        if self.server is not None:
            self.server.stop()
            self.server = None

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
