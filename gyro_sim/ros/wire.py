"""The lockstep's per-tick messages on the wire as CDR bytes, past rclpy's Python message objects.

rclpy turns a message object into C and serializes it at each publish, and builds a Python message object (nested
objects, NumPy arrays, checked setters) at each take: about 60 µs of CPU a message here, most of a lockstep tick's
transport cost beside the DDS write itself. On the per-tick path the nodes instead publish the CDR bytes of a
builder's dict (:func:`gyro_sim.io.bag_format.cdr_message`: rosbags' serializer, the bytes a bag stores and the live
view sends) with rclpy's publish of serialized bytes, and take serialized messages, decoded by rosbags' CDR
deserializer into its dataclasses (the same field names as rclpy's messages). What goes on the wire is the message
rclpy would send (the same CDR bytes but for alignment padding, which Fast CDR leaves unwritten and rosbags zeroes):
:class:`Wire` checks each message type once, both ways, and keeps rclpy's own path for a type where the two differ
(another ROS distribution's definition) or that has no probe message (status, scene, diagnostics: not per tick).
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any, Optional

from gyro_sim.io.bag_format import _typestore, cdr_message
from gyro_sim.io.cdr_template import NUMBER_PATHS, STAMP_PATHS, Template
from gyro_sim.io.messages import (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATOR_COMMANDS, TOPICS,
                                  command_message, to_ros)

__all__ = ["Wire", "Template", "STAMP_PATHS", "CommandReader", "take_serialized", "command_view", "state_bytes"]


def take_serialized(sub) -> Optional[bytes]:
    """The next message of an rclpy subscription as its CDR bytes, or None (non-blocking, past the executor)."""
    r = sub.handle.take_message(sub.msg_type, True)
    return None if r is None else r[0]


def command_view(msg) -> SimpleNamespace:
    """A decoded sensor_msgs/JointState (rosbags) as :func:`gyro_sim.ros.common.parse_command` reads rclpy's: header,
    name, and effort/velocity as lists of Python floats (rclpy gives array.array('d'): the same values, and a refusal
    quotes them the same way)."""
    return SimpleNamespace(header=msg.header, name=list(msg.name), effort=msg.effort.tolist(),
                           velocity=msg.velocity.tolist())


def _probes() -> dict:
    """msgtype -> (topic, fields): a message of each per-sample and command type with a value in every field."""
    from gyro_sim.io.messages import state_messages

    msgs = state_messages(12.5, [1.0, -2.0, 3.5], [0.5, 0.5, -0.5, 0.5], [0.1, 0.2, -0.3], [0.4, 1.1, -2.0],
                          [1e-3, -2e-3, 3e-3], ["a", "bb"], [1.5, 2.0], [-0.25, 3.0], [0.75, 6.0])
    msgs[TOPIC_STATOR_COMMANDS] = command_message(12.5, ["a", "bb"], [1.5, 2.0], [-0.25, 3.0])
    return {TOPICS[topic]: (topic, fields) for topic, fields in msgs.items()}


def _alike(topic: str, fields: dict, cls: type, deserialize_message, serialize_message) -> bool:
    """Whether rclpy reads rosbags' bytes of ``fields`` as its own message of them, and rosbags reads rclpy's bytes
    as the same (re-serialized: the same bytes). (The bytes themselves may differ in their alignment padding, which
    Fast CDR leaves unwritten.)"""
    ours = bytes(cdr_message(topic, fields))
    msg = to_ros(cls, fields)
    if deserialize_message(ours, cls) != msg:
        return False
    ts, msgtype = _typestore(), TOPICS[topic]
    return bytes(ts.serialize_cdr(ts.deserialize_cdr(bytes(serialize_message(msg)), msgtype), msgtype)) == ours


class Wire:
    """CDR bytes for the messages of one node, where they are rclpy's bytes.

    ``classes``: topic → the rclpy message class of its publisher or subscription. :meth:`publish` sends a builder's
    dict; :meth:`serialized` says whether a topic's messages may be taken as bytes and read with :meth:`decode`."""

    def __init__(self, classes: dict):
        self.classes = dict(classes)
        self._ok: dict[str, bool] = {}  # msgtype -> rosbags' bytes are rclpy's

    def serialized(self, topic: str) -> bool:
        """Whether rosbags and rclpy serialize ``topic``'s type alike (checked once a type, on a message with a value
        in every field; a type without such a message is not taken as bytes)."""
        msgtype = TOPICS[topic]
        ok = self._ok.get(msgtype)
        if ok is None:
            from rclpy.serialization import deserialize_message, serialize_message

            probe = _probes().get(msgtype)
            try:
                ok = probe is not None and _alike(probe[0], probe[1], self.classes[topic], deserialize_message,
                                                  serialize_message)
            except Exception:  # noqa: BLE001 - a type rosbags does not know or builds otherwise: rclpy's path
                ok = False
            self._ok[msgtype] = ok
        return ok

    def encode(self, topic: str, fields: dict):
        """What to publish for a builder's dict of ``topic``: its CDR bytes, or an rclpy message where the two
        serializations differ (:meth:`serialized`)."""
        if self.serialized(topic):
            return bytes(cdr_message(topic, fields))
        return to_ros(self.classes[topic], fields)

    def publish(self, pub, topic: str, fields: dict) -> None:
        """Publish a builder's dict on ``pub`` (a publisher of ``topic``) as :meth:`encode` gives it."""
        pub.publish(self.encode(topic, fields))

    def decode(self, topic: str, raw: bytes) -> Any:
        """The message of ``topic``'s type in its CDR bytes (where :meth:`serialized`): rosbags', or rclpy's for
        bytes rosbags does not read (rclpy then decides, as it would have taking the message itself)."""
        try:
            return _typestore().deserialize_cdr(raw, TOPICS[topic])
        except Exception:  # noqa: BLE001 - rosbags' SerdeError, a bad string: rclpy's own reading
            from rclpy.serialization import deserialize_message

            return deserialize_message(raw, self.classes[topic])


def state_templates(wire: "Wire") -> dict:
    """topic → :class:`Template` of the state messages a controller reads (/gyro/imu: stamp, orientation x y z w,
    angular velocity x y z; /gyro/kinetic_moment: stamp, L x y z) and /clock (stamp), as the simulator sends them
    without injected sensor noise (:func:`gyro_sim.io.messages.state_messages`), for the types ``wire`` may send as
    bytes."""
    from gyro_sim.io.messages import state_messages

    paths = {t: NUMBER_PATHS[t] for t in (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_CLOCK)}
    msgs = state_messages(0.0, [0.0] * 3, [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, [0.0] * 3, [], [], [], [],
                          only=list(paths))
    return {t: Template(t, msgs[t], p) for t, p in paths.items() if t in wire.classes and wire.serialized(t)}


def state_bytes(templates: dict, topics, ns: int, L, q, w) -> list:
    """The bytes of a state's messages on ``topics`` (each one of :func:`state_templates`: /clock, /gyro/imu,
    /gyro/kinetic_moment) straight from its numbers, without the builders' dicts: stamp ``ns`` (ns, within int32
    seconds), L (N m s), q (w, x, y, z), Ω_b (rad/s), each three or four Python floats. The same bytes as
    ``templates[topic].encode_fields`` of :func:`gyro_sim.io.messages.state_messages` of them (~5 µs a state
    instead of ~20)."""
    sec, nsec = divmod(ns, 1_000_000_000)
    values = {TOPIC_CLOCK: (sec, nsec), TOPIC_IMU: (sec, nsec, q[1], q[2], q[3], q[0], w[0], w[1], w[2]),
              TOPIC_KINETIC_MOMENT: (sec, nsec, L[0], L[1], L[2])}
    return [templates[t].encode(*values[t]) for t in topics]


class CommandReader:
    """The commands (sensor_msgs/JointState CDR bytes) a simulator takes, read as :func:`command_view` reads them:
    a message of the shape of one read before (the same names, frame id, positions, numbers of currents and rates,
    and alignment padding: every byte but the stamp's and the values') by a :class:`Template` of that shape, ~3 µs;
    any other by ``wire`` (:meth:`Wire.decode`, ~12 µs), whose shape is then learnt (at most :data:`SHAPES` shapes,
    and no more after :data:`SHAPES` messages whose bytes a template of their shape did not read back: e.g. padding
    that another serializer leaves unwritten). The view is the same either way: the stamp's integers, the names as
    texts, the values as Python floats."""

    #: shapes kept, and messages whose shape could not be learnt before learning stops
    SHAPES = 16

    def __init__(self, wire: Wire):
        self.wire = wire
        self._shapes: list = []  # (Template, header frame_id, names, currents, rates), the last read first
        self._misses = 0

    def read(self, raw: bytes) -> SimpleNamespace:
        """The view of a command's CDR bytes (:func:`command_view`)."""
        for i, shape in enumerate(self._shapes):
            numbers = shape[0].decode(raw)
            if numbers is not None:
                if i:
                    self._shapes.insert(0, self._shapes.pop(i))
                return _command_numbers(shape, numbers)
        msg = self.wire.decode(TOPIC_STATOR_COMMANDS, raw)
        view = command_view(msg)
        if len(self._shapes) < self.SHAPES and self._misses < self.SHAPES:
            self._learn(msg, view, raw)
        return view

    def _learn(self, msg, view: SimpleNamespace, raw: bytes) -> None:
        n_cur, n_rate = len(view.effort), len(view.velocity)
        try:
            if not all(isinstance(x, str) for x in view.name):
                raise ValueError("a name is no text")
            fields = {"header": {"stamp": {"sec": msg.header.stamp.sec, "nanosec": msg.header.stamp.nanosec},
                                 "frame_id": msg.header.frame_id},
                      "name": list(view.name), "position": msg.position.tolist(), "effort": list(view.effort),
                      "velocity": list(view.velocity)}
            tmpl = Template(TOPIC_STATOR_COMMANDS, fields, STAMP_PATHS + tuple(("effort", i) for i in range(n_cur))
                            + tuple(("velocity", i) for i in range(n_rate)))
            ok = tmpl.decode(raw) is not None  # (its bytes are these: the next of the shape is read by it)
        except Exception:  # noqa: BLE001 - a shape a template cannot hold (e.g. NaN values of a refused command)
            ok = False
        if not ok:
            self._misses += 1
            return
        self._shapes.insert(0, (tmpl, msg.header.frame_id, tuple(view.name), n_cur, n_rate))


def _command_numbers(shape: tuple, numbers: list) -> SimpleNamespace:
    """:func:`command_view` of a command read by a template: ``shape`` (Template, frame_id, names, number of currents,
    of rates), ``numbers`` (stamp sec, nanosec, the currents, the rates)."""
    _, frame_id, names, n_cur, n_rate = shape
    stamp = SimpleNamespace(sec=numbers[0], nanosec=numbers[1])
    return SimpleNamespace(header=SimpleNamespace(stamp=stamp, frame_id=frame_id), name=list(names),
                           effort=numbers[2:2 + n_cur], velocity=numbers[2 + n_cur:2 + n_cur + n_rate])
