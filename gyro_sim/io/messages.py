"""The ROS 2 topic contract of gyro_sim, and the content of its messages (no rclpy needed).

One content implementation, two adapters:

* the **builders** (:func:`state_messages`, :func:`command_message`, :func:`status_message`,
  :func:`scene_message`, :func:`clock_message`) return the fields of one message as plain
  nested dicts of Python ``float`` / ``int`` / ``str`` / ``list`` — exactly the types rclpy's
  generated setters accept;
* :func:`to_ros` fills an rclpy message object (given its class) from such a dict, and
  :func:`to_rosbags` builds the ``rosbags`` dataclass of the same message (for bags written
  without ROS, :mod:`gyro_sim.recording`).

Topics (namespace ``/gyro``, SI units, REP-103, ``header.stamp`` = simulation time):

=========================  ============================  ==============  =====================================
topic                      type                          frame_id        content
=========================  ============================  ==============  =====================================
``/gyro/imu``              sensor_msgs/msg/Imu           gyro_rotor      orientation = attitude body → case
                                                                         (x, y, z, w); angular_velocity = Ω_b
                                                                         (body, rad/s); covariances 0 (unknown);
                                                                         linear_acceleration 0 with
                                                                         covariance[0] = −1 (not provided)
``/gyro/kinetic_moment``   geometry_msgs/msg/Vector3Stamped  gyro_case   L, N·m·s
``/gyro/euler``            geometry_msgs/msg/Vector3Stamped  gyro_l_frame  x = ψ, y = θ, z = φ (rad)
``/gyro/torque``           geometry_msgs/msg/Vector3Stamped  gyro_case   electrodynamic torque, N·m
``/gyro/stators``          sensor_msgs/msg/JointState    (none)          name = stators, effort = current (A),
                                                                         velocity = signed field rate (rad/s),
                                                                         position = field phase (rad)
``/gyro/stator_commands``  sensor_msgs/msg/JointState    (none)          same meanings; position empty
``/gyro/effects``          sensor_msgs/msg/JointState    (none)          state of the scene's internal bodies (only
                                                                         when present): ``flywheel`` position =
                                                                         ∫Ω_f dt (rad), velocity = Ω_f (rad/s);
                                                                         ``damper_x|y|z`` position = u (m),
                                                                         velocity = u̇ (m/s), body frame
``/gyro/status``           std_msgs/msg/String           —               watchdog / refusals / info text (latched)
``/gyro/scene``            std_msgs/msg/String           —               scene file text (latched)
``/tf``                    tf2_msgs/msg/TFMessage        gyro_case       gyro_case → gyro_rotor (attitude) and
                                                                         gyro_case → gyro_l_frame, each sample
``/tf_static``             tf2_msgs/msg/TFMessage        gyro_case       gyro_case → gyro_stator_<name> (the
                                                                         stator triad e1, e2, axis), once
``/diagnostics``           diagnostic_msgs/msg/          —               run state, real-time factor, refusals,
                           DiagnosticArray                               watchdog (about 1 Hz wall)
``/clock``                 rosgraph_msgs/msg/Clock       —               simulation time
=========================  ============================  ==============  =====================================

QoS (:data:`QOS`): reliable, keep_last 100, volatile; ``/gyro/scene`` and ``/tf_static`` transient_local
depth 1 and ``/gyro/status`` transient_local depth 100 (a late subscriber gets the scene, the static frames and
the status lines so far).

The names above are the canonical ones (bags keep them). The nodes use them relative to their namespace
(:func:`node_topic`): ``gyro/imu``, ``tf``..., so ``-r __ns:=/unit2`` moves a gyroscope's topics to
``/unit2/gyro/...`` and ``/unit2/tf``; ``/clock`` and ``/diagnostics`` stay global (ROS convention).

Our arrays hold quaternions as (w, x, y, z); ROS messages as (x, y, z, w): the builders
convert.
"""
from __future__ import annotations

import math
from collections.abc import Mapping as _AbcMapping
from typing import Any, Mapping, Optional, Sequence

from gyro_sim.common.stamps import stamp_ns

__all__ = [
    "NAMESPACE", "FRAME_ROTOR", "FRAME_CASE", "FRAME_L",
    "TOPIC_IMU", "TOPIC_KINETIC_MOMENT", "TOPIC_EULER", "TOPIC_TORQUE", "TOPIC_STATORS",
    "TOPIC_STATOR_COMMANDS", "TOPIC_EFFECTS", "effects_message", "TOPIC_STATUS", "TOPIC_SCENE", "TOPIC_CLOCK",
    "TOPIC_TF", "TOPIC_TF_STATIC", "TOPIC_DIAGNOSTICS", "FRAME_STATOR_PREFIX",
    "TOPICS", "FRAME_IDS", "QOS", "STATE_TOPICS", "node_topic",
    "stamp", "stamp_ns", "state_messages", "command_message", "status_message", "scene_message",
    "clock_message", "tf_static_message", "diagnostics_message", "to_ros", "to_rosbags",
]

NAMESPACE = "/gyro"

# --- frames (REP-103: right-handed, SI) -----------------------------------------------------
FRAME_ROTOR = "gyro_rotor"  # body frame x1, x2, x3 (x3 = polar axis)
FRAME_CASE = "gyro_case"  # case frame z1, z2, z3 (stators fixed)
FRAME_L = "gyro_l_frame"  # the L-frame (its third axis along L)
FRAME_STATOR_PREFIX = "gyro_stator_"  # + stator name: the stator triad (e1, e2, axis u), fixed in the case

# --- topics ---------------------------------------------------------------------------------
TOPIC_IMU = NAMESPACE + "/imu"
TOPIC_KINETIC_MOMENT = NAMESPACE + "/kinetic_moment"
TOPIC_EULER = NAMESPACE + "/euler"
TOPIC_TORQUE = NAMESPACE + "/torque"
TOPIC_STATORS = NAMESPACE + "/stators"
TOPIC_STATOR_COMMANDS = NAMESPACE + "/stator_commands"
TOPIC_EFFECTS = NAMESPACE + "/effects"
TOPIC_STATUS = NAMESPACE + "/status"
TOPIC_SCENE = NAMESPACE + "/scene"
TOPIC_CLOCK = "/clock"
TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"
TOPIC_DIAGNOSTICS = "/diagnostics"

#: topic → ROS 2 message type (``pkg/msg/Name``)
TOPICS: dict[str, str] = {
    TOPIC_IMU: "sensor_msgs/msg/Imu",
    TOPIC_KINETIC_MOMENT: "geometry_msgs/msg/Vector3Stamped",
    TOPIC_EULER: "geometry_msgs/msg/Vector3Stamped",
    TOPIC_TORQUE: "geometry_msgs/msg/Vector3Stamped",
    TOPIC_STATORS: "sensor_msgs/msg/JointState",
    TOPIC_STATOR_COMMANDS: "sensor_msgs/msg/JointState",
    TOPIC_EFFECTS: "sensor_msgs/msg/JointState",
    TOPIC_STATUS: "std_msgs/msg/String",
    TOPIC_SCENE: "std_msgs/msg/String",
    TOPIC_CLOCK: "rosgraph_msgs/msg/Clock",
    TOPIC_TF: "tf2_msgs/msg/TFMessage",
    TOPIC_TF_STATIC: "tf2_msgs/msg/TFMessage",
    TOPIC_DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray",
}

#: topics that keep their absolute name in a namespaced node (ROS convention: one clock, one diagnostics bus)
GLOBAL_TOPICS = (TOPIC_CLOCK, TOPIC_DIAGNOSTICS)


def node_topic(topic: str) -> str:
    """The name a node uses for a canonical topic: relative to the node's namespace (``/gyro/imu`` →
    ``gyro/imu``, ``/tf`` → ``tf``), except :data:`GLOBAL_TOPICS`. In the root namespace both resolve alike."""
    return topic if topic in GLOBAL_TOPICS else topic.lstrip("/")

#: topic → header.frame_id ('' for JointState: joints carry no frame; absent = no header)
FRAME_IDS: dict[str, str] = {
    TOPIC_IMU: FRAME_ROTOR,
    TOPIC_KINETIC_MOMENT: FRAME_CASE,
    TOPIC_EULER: FRAME_L,
    TOPIC_TORQUE: FRAME_CASE,
    TOPIC_STATORS: "",
    TOPIC_STATOR_COMMANDS: "",
    TOPIC_EFFECTS: "",
}

_DEFAULT_QOS = {"reliability": "reliable", "history": "keep_last", "depth": 100, "durability": "volatile"}
#: topic → QoS, as plain words (rclpy: ReliabilityPolicy.RELIABLE, HistoryPolicy.KEEP_LAST, ...)
QOS: dict[str, dict[str, Any]] = {topic: dict(_DEFAULT_QOS) for topic in TOPICS}
QOS[TOPIC_SCENE] = {"reliability": "reliable", "history": "keep_last", "depth": 1, "durability": "transient_local"}
QOS[TOPIC_TF_STATIC] = dict(QOS[TOPIC_SCENE])  # as tf2's static broadcaster
QOS[TOPIC_STATUS] = dict(QOS[TOPIC_SCENE], depth=100)  # latched: a late subscriber sees the start line

#: the topics published once per output sample, in the order :func:`state_messages` gives them
STATE_TOPICS: tuple[str, ...] = (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE,
                                 TOPIC_TF, TOPIC_STATORS)

_UNKNOWN_COV = [0.0] * 9  # all zeros: "covariance unknown" (sensor_msgs/Imu)
_NOT_PROVIDED_COV = [-1.0] + [0.0] * 8  # element 0 = −1: "no estimate of this quantity"


# --- time -------------------------------------------------------------------------------------

def stamp(t: float) -> tuple[int, int]:
    """(sec, nanosec) of ``builtin_interfaces/Time`` for simulation time ``t`` ≥ 0 (s).

    Rounded to the nearest ns (ties up); sec = floor, 0 ≤ nanosec < 10⁹.
    """
    return divmod(stamp_ns(t), 1_000_000_000)


def _time(t: float) -> dict:
    sec, nsec = stamp(t)
    if sec > 2**31 - 1:
        raise ValueError(f"time stamp t = {t!r}: beyond the int32 seconds of builtin_interfaces/Time")
    return {"sec": sec, "nanosec": nsec}


def _header(time: dict, frame_id: str) -> dict:
    return {"stamp": time, "frame_id": frame_id}


def _vec3(v: Any, what: str) -> list[float]:
    vals = _floats(v, what)
    if len(vals) != 3:
        raise ValueError(f"{what}: expected 3 components, got {len(vals)}")
    return vals


def _floats(v: Any, what: str) -> list[float]:
    try:
        out = v.tolist() if hasattr(v, "tolist") else list(v)
        out = [float(x) for x in out]
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a sequence of numbers, got {v!r}") from None
    return out


def _vector3_stamped(time: dict, frame_id: str, v: Any, what: str) -> dict:
    x, y, z = _vec3(v, what)
    return {"header": _header(time, frame_id), "vector": {"x": x, "y": y, "z": z}}


def _joint_state(time: dict, names: Sequence[str], what: str, position: Optional[Any] = None,
                 velocity: Optional[Any] = None, effort: Optional[Any] = None) -> dict:
    if isinstance(names, str):
        raise ValueError(f"{what}: names must be a list of stator names, got the string {names!r}")
    names = [str(n) for n in names]
    out = {"header": _header(time, ""), "name": names}
    for key, val in (("position", position), ("velocity", velocity), ("effort", effort)):
        vals = [] if val is None else _floats(val, f"{what}.{key}")
        if vals and len(vals) != len(names):
            raise ValueError(f"{what}.{key}: {len(vals)} values for {len(names)} stators {names}")
        out[key] = vals
    return out


# --- builders -------------------------------------------------------------------------------

def clock_message(t: float) -> dict:
    """``/clock``: rosgraph_msgs/Clock at simulation time t."""
    return {"clock": _time(t)}


def state_messages(t: float, L: Any, q_wxyz: Any, omega_b: Any, euler: Any, torque: Any,
                   names: Sequence[str], current: Any, rate: Any, phase: Any,
                   imu_covariance: Optional[tuple] = None, only: Optional[Any] = None) -> dict[str, dict]:
    """The messages of one output sample at simulation time ``t`` (s): topic → fields.

    L, torque: case frame (N·m·s, N·m); q_wxyz: attitude body → case as (w, x, y, z);
    omega_b: body frame (rad/s); euler: (ψ, θ, φ) rad; names/current/rate/phase: per stator
    (A, rad/s signed, rad). Topics in :data:`STATE_TOPICS` order (``/clock`` first). ``imu_covariance``:
    (orientation, angular velocity) covariances of /gyro/imu, row-major 3x3 (rad², (rad/s)²), where the state
    carries injected noise (gyro_sim.faults); default zeros = unknown. ``only``: the topics to build (default all;
    a node builds those someone subscribes to, at each lockstep tick); the arguments of the others are not read.
    """
    only = STATE_TOPICS if only is None else only
    time = _time(t)
    q = _floats(q_wxyz, "q_wxyz")
    if len(q) != 4:
        raise ValueError(f"q_wxyz: expected 4 components (w, x, y, z), got {len(q)}")
    w, x, y, z = q
    wx, wy, wz = _vec3(omega_b, "omega_b")
    out: dict[str, dict] = {}
    if TOPIC_CLOCK in only:
        out[TOPIC_CLOCK] = {"clock": dict(time)}
    if TOPIC_IMU in only:
        out[TOPIC_IMU] = {
            "header": _header(dict(time), FRAME_ROTOR),
            "orientation": {"x": x, "y": y, "z": z, "w": w},
            "orientation_covariance": list(imu_covariance[0]) if imu_covariance else list(_UNKNOWN_COV),
            "angular_velocity": {"x": wx, "y": wy, "z": wz},
            "angular_velocity_covariance": list(imu_covariance[1]) if imu_covariance else list(_UNKNOWN_COV),
            "linear_acceleration": {"x": 0.0, "y": 0.0, "z": 0.0},
            "linear_acceleration_covariance": list(_NOT_PROVIDED_COV),
        }
    if TOPIC_KINETIC_MOMENT in only:
        out[TOPIC_KINETIC_MOMENT] = _vector3_stamped(dict(time), FRAME_CASE, L, "L")
    if TOPIC_EULER in only:
        out[TOPIC_EULER] = _vector3_stamped(dict(time), FRAME_L, euler, "euler")
    if TOPIC_TORQUE in only:
        out[TOPIC_TORQUE] = _vector3_stamped(dict(time), FRAME_CASE, torque, "torque")
    if TOPIC_TF in only:
        out[TOPIC_TF] = {"transforms": [_transform(time, FRAME_ROTOR, (w, x, y, z)),
                                        _transform(time, FRAME_L, _l_frame_quat(_vec3(L, "L")))]}
    if TOPIC_STATORS in only:
        out[TOPIC_STATORS] = _joint_state(dict(time), names, "stators", position=phase, velocity=rate, effort=current)
    return out


def _transform(time: dict, child: str, q_wxyz: Sequence[float]) -> dict:
    """geometry_msgs/TransformStamped gyro_case → ``child``: a pure rotation (the rotor turns about a fixed
    point, the case origin), q = (w, x, y, z) child → case."""
    w, x, y, z = q_wxyz
    return {"header": _header(dict(time), FRAME_CASE), "child_frame_id": child,
            "transform": {"translation": {"x": 0.0, "y": 0.0, "z": 0.0},
                          "rotation": {"x": x, "y": y, "z": z, "w": w}}}


def _l_frame_quat(L: Sequence[float]) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the L-frame Y = Rz(σ) Ry(ρ) (:func:`gyro_sim.frames.l_frame`: ρ the polar angle of L
    from z3, σ its azimuth; σ = 0 where L ∥ z3, Y = I where L = 0), scalar code."""
    Lx, Ly, Lz = L
    h = math.hypot(Lx, Ly)
    rho = math.atan2(h, Lz)
    sig = math.atan2(Ly, Lx) if h > 0.0 else 0.0
    cr, sr, cs, ss = math.cos(rho / 2), math.sin(rho / 2), math.cos(sig / 2), math.sin(sig / 2)
    return cs * cr, -ss * sr, cs * sr, ss * cr


def tf_static_message(names: Sequence[str], triads: Sequence[Sequence[Sequence[float]]]) -> dict:
    """``/tf_static``: gyro_case → ``gyro_stator_<name>`` for each stator, the frame whose x, y, z axes are the
    stator's triad (e1, e2, u) in case coordinates (``triads[k]`` = (e1, e2, u)), stamped 0."""
    import numpy as np

    from gyro_sim.physics.frames import matrix_to_quat

    out = []
    for name, (e1, e2, u) in zip(names, triads):
        R = [[float(e1[i]), float(e2[i]), float(u[i])] for i in range(3)]
        out.append(_transform(_time(0.0), FRAME_STATOR_PREFIX + str(name), matrix_to_quat(np.array(R)).tolist()))
    return {"transforms": out}


#: diagnostic_msgs/DiagnosticStatus levels
DIAG_OK, DIAG_WARN, DIAG_ERROR, DIAG_STALE = 0, 1, 2, 3


def diagnostics_message(t: float, name: str, hardware_id: str, level: int, message: str,
                        values: Mapping[str, Any]) -> dict:
    """``/diagnostics``: one DiagnosticStatus (``level`` 0 OK, 1 WARN, 2 ERROR, 3 STALE) with key/value pairs,
    stamped at simulation time t."""
    if level not in (DIAG_OK, DIAG_WARN, DIAG_ERROR, DIAG_STALE):
        raise ValueError(f"diagnostics level = {level!r}: allowed 0 (OK), 1 (WARN), 2 (ERROR), 3 (STALE)")
    return {"header": _header(_time(t), ""),
            "status": [{"level": level, "name": str(name), "message": str(message),
                        "hardware_id": str(hardware_id),
                        "values": [{"key": str(k), "value": str(v)} for k, v in values.items()]}]}


def effects_message(t: float, effects: Mapping[str, Any]) -> Optional[dict]:
    """``/gyro/effects`` at time t from one sample of :meth:`gyro_sim.simulate.Simulator.effect_outputs`
    (name → value), or None when no effect has a state to publish. Channels: ``flywheel`` (position =
    ∫Ω_f dt rad, velocity = Ω_f rad/s), ``damper_x``, ``damper_y``, ``damper_z`` (position = u m,
    velocity = u̇ m/s, body frame)."""
    names: list[str] = []
    pos: list[float] = []
    vel: list[float] = []
    if "flywheel_speed" in effects:
        names.append("flywheel")
        pos.append(float(effects["flywheel_angle"]))
        vel.append(float(effects["flywheel_speed"]))
    if "damper_offset" in effects:
        u, v = _vec3(effects["damper_offset"], "damper_offset"), _vec3(effects["damper_velocity"], "damper_velocity")
        names += ["damper_x", "damper_y", "damper_z"]
        pos += u
        vel += v
    if not names:
        return None
    return _joint_state(_time(t), names, "effects", position=pos, velocity=vel)


def command_message(t: float, names: Sequence[str], current: Optional[Any], rate: Optional[Any]) -> dict:
    """``/gyro/stator_commands`` at time t: effort = current (A), velocity = rate (rad/s).

    ``current`` or ``rate`` may be None (that field left empty: not commanded); position is empty.
    """
    return _joint_state(_time(t), names, "stator_commands", velocity=rate, effort=current)


def status_message(text: str) -> dict:
    """``/gyro/status``: std_msgs/String."""
    if not isinstance(text, str):
        raise ValueError(f"status text must be a str, got {type(text).__name__}")
    return {"data": text}


def scene_message(scene_text: str) -> dict:
    """``/gyro/scene``: std_msgs/String holding the scene file text."""
    if not isinstance(scene_text, str):
        raise ValueError(f"scene text must be a str, got {type(scene_text).__name__}")
    return {"data": scene_text}


# --- adapters -------------------------------------------------------------------------------

def to_ros(msg_class: type, fields: Mapping[str, Any]) -> Any:
    """An rclpy message of ``msg_class`` filled from a builder's dict (nested dicts = nested messages).

    Generic: nested messages are reached with getattr and filled in place; every other value
    is set with setattr (lists for sequences, as rclpy accepts). Sequences of nested messages
    are built from the element class rclpy's ``SLOT_TYPES`` names.
    """
    msg = msg_class()
    _fill_ros(msg, fields)
    return msg


_OCTETS: dict[type, frozenset] = {}  # message class → its octet fields (rclpy takes those as 1 byte)


def _octets(cls: type) -> frozenset:
    hit = _OCTETS.get(cls)
    if hit is None:
        types: dict = getattr(cls, "get_fields_and_field_types", dict)()
        hit = _OCTETS[cls] = frozenset(k for k, v in types.items() if v == "octet")
    return hit


def _is_mapping(value: Any) -> bool:
    return type(value) is dict or isinstance(value, _AbcMapping)  # (dict first: the per-sample path)


def _fill_ros(obj: Any, fields: Mapping[str, Any]) -> None:
    for key, value in fields.items():
        if not hasattr(obj, key):
            raise ValueError(f"{type(obj).__name__} has no field {key!r}")
        if _is_mapping(value):
            _fill_ros(getattr(obj, key), value)
        elif type(value) is int and key in _octets(type(obj)):
            setattr(obj, key, bytes([value]))  # an int there would serialize wrongly
        elif type(value) in (list, tuple) and value and _is_mapping(value[0]):
            cls = _ros_element_class(obj, key)
            setattr(obj, key, [to_ros(cls, v) for v in value])
        else:
            setattr(obj, key, value)


def _ros_element_class(obj: Any, key: str) -> type:
    import importlib

    names = list(obj.get_fields_and_field_types())
    slot = type(obj).SLOT_TYPES[names.index(key)]
    vt = slot.value_type
    module = importlib.import_module(".".join(vt.namespaces))
    return getattr(module, vt.name)


_NP_DTYPES = {
    "bool": "bool", "byte": "uint8", "char": "uint8", "octet": "uint8", "uint8": "uint8", "int8": "int8",
    "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
    "uint64": "uint64", "float32": "float32", "float64": "float64",
}
_CONVERTERS: dict[tuple[int, str], tuple[Any, Any]] = {}


def to_rosbags(typestore: Any, msgtype: str, fields: Mapping[str, Any]) -> Any:
    """The ``rosbags`` message dataclass of ``msgtype`` built from a builder's dict.

    Nested messages from nested dicts; arrays/sequences of numbers as NumPy arrays of the
    field's dtype; ``string[]`` as lists; fields absent from the dict get their zero value.
    The per-type converter is compiled once per (typestore, msgtype).
    """
    key = (id(typestore), msgtype)
    hit = _CONVERTERS.get(key)
    if hit is None or hit[0] is not typestore:
        hit = (typestore, _compile(typestore, msgtype))
        _CONVERTERS[key] = hit
    return hit[1](fields)


def _compile(typestore: Any, msgtype: str):
    import numpy as np
    from rosbags.interfaces import Nodetype

    if msgtype not in typestore.fielddefs:
        raise ValueError(f"message type {msgtype!r} is not in the typestore")
    cls = typestore.types[msgtype]
    _, fielddefs = typestore.fielddefs[msgtype]
    plan = []  # (name, convert(value), default())
    for name, (nodetype, detail) in fielddefs:
        if nodetype == Nodetype.NAME:
            sub = _compile(typestore, detail)
            plan.append((name, sub, lambda sub=sub: sub({})))
        elif nodetype == Nodetype.BASE:
            base = detail[0]
            if base == "string":
                plan.append((name, str, str))
            elif base == "bool":
                plan.append((name, bool, bool))
            elif base.startswith("float"):
                plan.append((name, float, float))
            else:
                plan.append((name, int, int))
        elif nodetype in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (elem_type, elem_detail), length = detail
            fixed = length if nodetype == Nodetype.ARRAY else 0
            if elem_type == Nodetype.BASE and elem_detail[0] in _NP_DTYPES:
                dt = np.dtype(_NP_DTYPES[elem_detail[0]])
                plan.append((name, lambda v, dt=dt: np.asarray(v, dtype=dt),
                             lambda dt=dt, n=fixed: np.zeros(n, dtype=dt)))
            elif elem_type == Nodetype.BASE:  # string[]
                plan.append((name, lambda v: [str(s) for s in v],
                             lambda n=fixed: [""] * n))
            else:
                sub = _compile(typestore, elem_detail)
                plan.append((name, lambda v, sub=sub: [sub(x) for x in v],
                             lambda sub=sub, n=fixed: [sub({}) for _ in range(n)]))
        else:  # pragma: no cover - rosbags has no other node types in fielddefs
            raise ValueError(f"{msgtype}.{name}: unsupported field kind {nodetype}")
    known = {p[0] for p in plan}

    def convert(fields: Mapping[str, Any]):
        if type(fields) is not dict and not isinstance(fields, Mapping):
            raise ValueError(f"{msgtype}: expected a dict of fields, got {type(fields).__name__}")
        if not known.issuperset(fields):
            raise ValueError(f"{msgtype} has no field {sorted(set(fields) - known)[0]!r}")
        return cls(*[conv(fields[n]) if n in fields else default() for n, conv, default in plan])

    return convert
