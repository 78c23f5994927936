"""Reading a gyro_sim bag (rosbag2, MCAP) back: :func:`read_bag` (NumPy arrays per topic, :class:`BagData`) and
:func:`bag_info` (its metadata without its messages)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import numpy as np
import yaml

from gyro_sim.io.bag_format import CUSTOM_KEYS, _typestore
from gyro_sim.io.messages import (
    TOPIC_CLOCK, TOPIC_DIAGNOSTICS, TOPIC_EFFECTS, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_SCENE,
    TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_STATUS, TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TORQUE, TOPICS,
)

__all__ = ["BagData", "bag_effects", "read_bag", "bag_info", "BagNotClosedError", "BagDamagedError"]


@dataclass
class BagData:
    """A bag read back: NumPy arrays per topic (SI; rows = samples).

    Samples are aligned on the union of the state topics' header stamps (NaN where a topic
    has no message at a stamp; none in bags written by this module). ``q`` is (w, x, y, z).
    Command arrays have one column per stator (``stator_names`` order; NaN = not commanded).
    """

    t_ns: np.ndarray  # (n,) int64 header stamps, ns
    t: np.ndarray  # (n,) s
    L: np.ndarray  # (n,3) N·m·s, case frame
    q: np.ndarray  # (n,4) (w, x, y, z), body → case
    omega_b: np.ndarray  # (n,3) rad/s, body frame
    euler: np.ndarray  # (n,3) ψ, θ, φ rad
    torque: np.ndarray  # (n,3) N·m, case frame
    stator_names: list[str]
    current: np.ndarray  # (n,k) A
    rate: np.ndarray  # (n,k) rad/s
    phase: np.ndarray  # (n,k) rad
    command_t: np.ndarray  # (m,) s
    command_current: np.ndarray  # (m,k) A
    command_rate: np.ndarray  # (m,k) rad/s
    status_t: np.ndarray  # (s,) s (log time)
    status: list[str]
    clock_t: np.ndarray  # (c,) s
    scene_text: Optional[str]
    scene_name: Optional[str]
    version: Optional[str]
    custom: dict = field(default_factory=dict)
    effects: dict = field(default_factory=dict)  # /gyro/effects channel → (n, 2): position, velocity (SI)

    def __len__(self) -> int:
        return len(self.t)


def bag_effects(data: BagData) -> dict:
    """RunResult.effects of the /gyro/effects channels a bag holds (flywheel, damper)."""
    effects = {}
    if "flywheel" in data.effects:
        effects["flywheel_angle"] = data.effects["flywheel"][:, 0].copy()
        effects["flywheel_speed"] = data.effects["flywheel"][:, 1].copy()
    if all(f"damper_{a}" in data.effects for a in "xyz"):
        effects["damper_offset"] = np.stack([data.effects[f"damper_{a}"][:, 0] for a in "xyz"], axis=1)
        effects["damper_velocity"] = np.stack([data.effects[f"damper_{a}"][:, 1] for a in "xyz"], axis=1)
    return effects



def _custom_data(reader, path: Path) -> dict:
    """custom_data of a bag directory (metadata.yaml), or of a bare .mcap file (its rosbag2 record)."""
    meta = getattr(getattr(reader, "storage", None), "metadata", None)
    custom = getattr(meta, "custom", None)
    if custom:
        return dict(custom)
    if path.is_file():
        try:
            from mcap.reader import make_reader

            with open(path, "rb") as f:
                for m in make_reader(f).iter_metadata():
                    if m.name == "rosbag2" and "serialized_metadata" in m.metadata:
                        info = yaml.safe_load(m.metadata["serialized_metadata"]) or {}
                        return dict(info.get("custom_data") or {})
        except Exception:
            return {}
    return {}


class BagNotClosedError(ValueError):
    """A bag whose recording was cut (kill -9, crash, power loss): the message says to run `gyro-sim bag recover`."""


def _refuse_not_closed(path: Path) -> None:
    from gyro_sim.io.bag_repair import not_closed_message

    why = not_closed_message(path)
    if why:
        raise BagNotClosedError(why)


class BagDamagedError(ValueError):
    """A closed bag with chunks that do not match their CRCs: the message says which and to run `gyro-sim bag
    recover` (which keeps the sound chunks)."""


def _refuse_damaged(path: Path) -> None:
    from gyro_sim.io.bag_repair import damaged_message

    why = damaged_message(path)
    if why:
        raise BagDamagedError(why)


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


#: topics read_bag(max_samples=...) thins out (every k-th message and the last); status and the scene are kept
_THINNED = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_EFFECTS,
            TOPIC_STATOR_COMMANDS, TOPIC_CLOCK)


def read_bag(path: Union[str, os.PathLike], max_samples: Optional[int] = None) -> BagData:
    """Read a gyro_sim bag (a bag directory or its .mcap file) with rosbags into :class:`BagData`.

    ``max_samples``: read at most about that many samples of each state topic (and of the commands and /clock):
    every k-th message and the last one, k from the bag's message counts (memory bounded however long the run: a
    summary or a plot of an hour-long bag); None reads every message. A bag that was not closed, or whose chunks
    do not match their CRCs: :class:`BagNotClosedError` / :class:`BagDamagedError`, saying to run
    ``gyro-sim bag recover``."""
    from rosbags.rosbag2 import ReaderError

    path = Path(path)
    _refuse_not_closed(path)
    try:
        return _read_bag(path, max_samples)
    except ReaderError:  # (rosbags checks each chunk's CRC as it reads it)
        _refuse_damaged(path)
        raise


def _read_bag(path: Path, max_samples: Optional[int]) -> BagData:
    from rosbags.rosbag2 import Reader

    ts = _typestore()
    des = ts.deserialize_cdr
    acc: dict[str, tuple[list, list]] = {t: ([], []) for t in (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER,
                                                                 TOPIC_TORQUE, TOPIC_STATORS)}
    cmd: list = []
    status_t: list[int] = []
    status: list[str] = []
    clock: list[int] = []
    scene_text = None
    eff_msgs: list = []
    with Reader(path) as reader:
        custom = _custom_data(reader, path)
        conns = [c for c in reader.connections if c.topic in TOPICS and c.msgtype == TOPICS[c.topic]
                 and c.topic not in (TOPIC_TF, TOPIC_TF_STATIC, TOPIC_DIAGNOSTICS)]  # (not in BagData)
        stride = 1
        if max_samples is not None:
            most = max([c.msgcount for c in conns if c.topic in _THINNED] + [1])
            stride = max(1, -(-most // max(1, int(max_samples))))
        seen: dict[str, int] = {}
        last: dict[str, tuple] = {}  # a thinned topic's last message, when it was not kept

        def messages():
            for conn, log_ns, raw in reader.messages(connections=conns):
                if stride > 1 and conn.topic in _THINNED:
                    i = seen[conn.topic] = seen.get(conn.topic, -1) + 1
                    if i % stride:
                        last[conn.topic] = (conn, log_ns, raw)
                        continue
                    last.pop(conn.topic, None)
                yield conn, log_ns, raw
            yield from last.values()

        for conn, log_ns, raw in messages():
            topic = conn.topic
            m = des(raw, conn.msgtype)
            if topic == TOPIC_IMU:
                o, w = m.orientation, m.angular_velocity
                a = acc[topic]
                a[0].append(_ns(m.header.stamp))
                a[1].append((o.w, o.x, o.y, o.z, w.x, w.y, w.z))
            elif topic in (TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE):
                v = m.vector
                a = acc[topic]
                a[0].append(_ns(m.header.stamp))
                a[1].append((v.x, v.y, v.z))
            elif topic == TOPIC_STATORS:
                a = acc[topic]
                a[0].append(_ns(m.header.stamp))
                a[1].append((list(m.name), m.effort, m.velocity, m.position))
            elif topic == TOPIC_EFFECTS:
                eff_msgs.append((_ns(m.header.stamp), list(m.name), m.position, m.velocity))
            elif topic == TOPIC_STATOR_COMMANDS:
                cmd.append((_ns(m.header.stamp), list(m.name), m.effort, m.velocity))
            elif topic == TOPIC_STATUS:
                status_t.append(log_ns)
                status.append(m.data)
            elif topic == TOPIC_CLOCK:
                clock.append(_ns(m.clock))
            elif topic == TOPIC_SCENE:
                scene_text = m.data
    if scene_text is None:
        scene_text = custom.get(CUSTOM_KEYS["scene"])
    # --- align the state topics on the union of their stamps
    all_ns = [np.asarray(a[0], dtype=np.int64) for a in acc.values()]
    t_ns = np.unique(np.concatenate(all_ns)) if any(x.size for x in all_ns) else np.zeros(0, np.int64)
    n = t_ns.size

    def aligned(topic: str, width: int) -> np.ndarray:
        ns_list, vals = acc[topic]
        out = np.full((n, width), np.nan)
        if ns_list:
            out[np.searchsorted(t_ns, np.asarray(ns_list, dtype=np.int64))] = np.asarray(vals, dtype=float)
        return out

    imu = aligned(TOPIC_IMU, 7)
    names: list[str] = []  # stator columns: in order of first appearance (samples, then commands)
    seen_lists = dict.fromkeys([tuple(v[0]) for v in acc[TOPIC_STATORS][1]] + [tuple(c[1]) for c in cmd])
    for nm_list in seen_lists:
        for nm in nm_list:
            if nm not in names:
                names.append(nm)
    k = len(names)
    col = {nm: i for i, nm in enumerate(names)}
    st = np.full((3, n, k), np.nan)
    if acc[TOPIC_STATORS][0]:
        rows = np.searchsorted(t_ns, np.asarray(acc[TOPIC_STATORS][0], dtype=np.int64))
        for r, (nm, eff, vel, pos) in zip(rows.tolist(), acc[TOPIC_STATORS][1]):
            cols = [col[x] for x in nm]
            for j, arr in enumerate((eff, vel, pos)):
                if len(arr) == len(cols):
                    st[j, r, cols] = arr
    m = len(cmd)
    cc = np.full((2, m, k), np.nan)
    for i, (_, nm, eff, vel) in enumerate(cmd):
        cols = [col[x] for x in nm]
        for j, arr in enumerate((eff, vel)):
            if len(arr) == len(cols):
                cc[j, i, cols] = arr
    effects: dict[str, np.ndarray] = {}  # channel → (n, 2) position, velocity
    for ns, nm, pos, vel in eff_msgs:
        r = int(np.searchsorted(t_ns, ns))
        for j, name in enumerate(nm):
            effects.setdefault(name, np.full((n, 2), np.nan))[r] = (pos[j], vel[j])
    return BagData(
        t_ns=t_ns, t=t_ns / 1e9, L=aligned(TOPIC_KINETIC_MOMENT, 3), q=imu[:, 0:4], omega_b=imu[:, 4:7],
        euler=aligned(TOPIC_EULER, 3), torque=aligned(TOPIC_TORQUE, 3), stator_names=names,
        current=st[0], rate=st[1], phase=st[2],
        command_t=np.asarray([c[0] for c in cmd], dtype=np.int64) / 1e9, command_current=cc[0], command_rate=cc[1],
        status_t=np.asarray(status_t, dtype=np.int64) / 1e9, status=status,
        clock_t=np.asarray(clock, dtype=np.int64) / 1e9,
        scene_text=scene_text, scene_name=custom.get(CUSTOM_KEYS["scene_name"]),
        version=custom.get(CUSTOM_KEYS["version"]), custom=custom, effects=effects,
    )


def bag_info(path: Union[str, os.PathLike]) -> dict:
    """Summary of a bag without reading its messages: topics (type, count), times (s), scene, version. Its chunks
    are checked against their CRCs (:class:`BagDamagedError`)."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    _refuse_not_closed(path)
    _refuse_damaged(path)  # (reads the file once: a flipped byte in a chunk is found here, not by a later reader)
    bag_version, storage = None, path.suffix.lstrip(".")
    if path.is_dir() and (path / "metadata.yaml").is_file():
        info = (yaml.safe_load((path / "metadata.yaml").read_text()) or {}).get("rosbag2_bagfile_information") or {}
        bag_version, storage = info.get("version"), info.get("storage_identifier")
    with Reader(path) as reader:
        custom = _custom_data(reader, path)
        count = reader.message_count
        start = reader.start_time / 1e9 if count else math.nan
        end = (reader.end_time - 1) / 1e9 if count else math.nan
        topics = {name: {"type": ti.msgtype, "count": int(ti.msgcount)} for name, ti in sorted(reader.topics.items())}
    return {
        "path": str(path),
        "storage": storage,
        "bag_version": bag_version,
        "message_count": int(count),
        "start": start,
        "end": end,
        "duration": (end - start) if count else 0.0,
        "topics": topics,
        "scene_name": custom.get(CUSTOM_KEYS["scene_name"]),
        "version": custom.get(CUSTOM_KEYS["version"]),
        "end_reason": custom.get(CUSTOM_KEYS["end"]),
        "custom": {k: v for k, v in custom.items() if k != CUSTOM_KEYS["scene"]},
    }
