"""The CDR bytes of messages of one shape that differ only in some numbers (:class:`Template`): the bytes rosbags'
serializer makes of the whole message (:func:`gyro_sim.io.bag_format.cdr_message`), with those numbers patched in
place. The simulator node and the controller node send and read their per-tick messages so
(:mod:`gyro_sim.ros.wire`), and the recorder writes a run's per-sample messages so (:mod:`gyro_sim.io.bag_writer`).
"""
from __future__ import annotations

import struct
from typing import Any, Optional

from gyro_sim.io.bag_format import _typestore, cdr_message
from gyro_sim.io.messages import (TOPIC_CLOCK, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATOR_COMMANDS,
                                  TOPIC_STATORS, TOPIC_TF, TOPIC_TORQUE, TOPICS)

__all__ = ["Template", "STAMP_PATHS", "NUMBER_PATHS"]

#: a header's stamp, as a :class:`Template` path
STAMP_PATHS = (("header", "stamp", "sec"), ("header", "stamp", "nanosec"))
_VECTOR = STAMP_PATHS + tuple(("vector", k) for k in "xyz")
#: topic -> where the numbers of its per-sample message are (the builders' dicts: gyro_sim.io.messages), in the order
#: a :class:`Template` of them takes them; the stators' and the commands' (a JointState's stamp, position, velocity,
#: effort) follow from their lengths (gyro_sim.io.bag_writer.BagRecorder._encode)
NUMBER_PATHS: dict[str, tuple] = {
    TOPIC_CLOCK: (("clock", "sec"), ("clock", "nanosec")),
    TOPIC_IMU: STAMP_PATHS + tuple(("orientation", k) for k in "xyzw") + tuple(("angular_velocity", k) for k in "xyz"),
    TOPIC_KINETIC_MOMENT: _VECTOR, TOPIC_EULER: _VECTOR, TOPIC_TORQUE: _VECTOR,
    TOPIC_TF: tuple(("transforms", j) + p for j in range(2) for p in STAMP_PATHS + tuple(
        ("transform", "rotation", k) for k in "xyzw")),
    TOPIC_STATORS: (), TOPIC_STATOR_COMMANDS: (),
}

_STRUCT = {"int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i", "uint32": "I", "int64": "q",
           "uint64": "Q", "float32": "f", "float64": "d"}


def _leaf_base(msgtype: str, path: tuple) -> str:
    """The base type ('float64', 'int32', ...) of the number at ``path`` (field names, and an index into an array
    or sequence) of ``msgtype``, from the typestore's definitions."""
    from rosbags.interfaces import Nodetype

    fields = dict(_typestore().fielddefs[msgtype][1])
    node = fields[path[0]]
    for key in path[1:]:
        if node[0] == Nodetype.NAME:
            node = dict(_typestore().fielddefs[node[1]][1])[key]
        else:  # (an array or sequence: key is an index)
            node = node[1][0]
    if node[0] == Nodetype.NAME:
        raise ValueError(f"{msgtype}: {'.'.join(map(str, path))} is a message, not a number")
    if node[0] != Nodetype.BASE or node[1][0] not in _STRUCT:
        raise ValueError(f"{msgtype}: {'.'.join(map(str, path))} is no number")
    return node[1][0]


def _with(fields: Any, path: tuple, value) -> Any:
    """A copy of the nested ``fields`` (dicts and lists) with the leaf at ``path`` set to ``value``."""
    if not path:
        return value
    out = dict(fields) if isinstance(fields, dict) else list(fields)
    out[path[0]] = _with(fields[path[0]], path[1:], value)
    return out


def _get(fields: Any, path: tuple):
    for key in path:
        fields = fields[key]
    return fields


class Template:
    """The CDR bytes of messages of one shape that differ only in some numbers (a header stamp, a vector, ...):
    one message serialized by rosbags (:func:`gyro_sim.io.bag_format.cdr_message`) with those numbers patched in
    place, ~0.5 µs against ~10 µs for the whole serialization (and ~30 µs for rclpy's).

    ``fields``: a builder's dict of ``topic``, whose strings, sequence lengths and other numbers every message of
    the template shares; ``paths``: where the varying numbers are (tuples of field names and indices), in the order
    :meth:`encode` takes them and :meth:`decode` gives them. Each number's place in the bytes is found by
    serializing ``fields`` with it set to two values that differ in every byte (so nothing about CDR's layout is
    written here); :meth:`encode` of the numbers of ``fields`` gives rosbags' bytes of ``fields`` (checked)."""

    def __init__(self, topic: str, fields: dict, paths):
        self.topic, self.paths = topic, tuple(tuple(p) for p in paths)
        msgtype = TOPICS[topic]
        self.base = bytes(cdr_message(topic, fields))
        self._ops = []  # (struct format, offset) per path
        for path in self.paths:
            fmt = "<" + _STRUCT[_leaf_base(msgtype, path)]
            size = struct.calcsize(fmt)
            a, b = (struct.unpack(fmt, bytes([m]) * size)[0] for m in (0x11, 0x22))
            ra = bytes(cdr_message(topic, _with(fields, path, a)))
            rb = bytes(cdr_message(topic, _with(fields, path, b)))
            diff = [i for i in range(len(ra)) if ra[i] != rb[i]]
            if len(ra) != len(self.base) or len(diff) != size or diff[-1] - diff[0] != size - 1:
                raise ValueError(f"{topic}: {'.'.join(map(str, path))} has no fixed place in the message bytes")
            self._ops.append((fmt, diff[0]))
        spans = sorted((off, off + struct.calcsize(fmt)) for fmt, off in self._ops)
        # the bytes a message must share with the template for decode to read its numbers (all but the numbers)
        cuts = [0] + [x for span in spans for x in span] + [len(self.base)]
        self._same = [(cuts[i], cuts[i + 1]) for i in range(0, len(cuts), 2) if cuts[i] < cuts[i + 1]]
        if self.encode(*(_get(fields, p) for p in self.paths)) != self.base:
            raise ValueError(f"{topic}: the template does not reproduce its message")

    def encode(self, *values) -> bytes:
        """The message's bytes with the numbers ``values`` (one per path)."""
        out = bytearray(self.base)
        for (fmt, off), v in zip(self._ops, values, strict=True):
            struct.pack_into(fmt, out, off, v)
        return bytes(out)

    def decode(self, raw: bytes) -> Optional[list]:
        """The numbers (one per path) of a message of this shape, or None for a message of another shape (another
        frame id, sequence length, constant, or alignment padding that is not zero: decode it whole instead)."""
        if len(raw) != len(self.base):
            return None
        base = self.base
        for a, b in self._same:
            if raw[a:b] != base[a:b]:
                return None
        return [struct.unpack_from(fmt, raw, off)[0] for fmt, off in self._ops]

    def encode_fields(self, fields: dict) -> bytes:
        """:meth:`encode` of the numbers of a builder's dict of the template's shape (its other fields are not
        read: the caller knows they are the template's)."""
        return self.encode(*(_get(fields, p) for p in self.paths))
