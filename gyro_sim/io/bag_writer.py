"""Writing a run as a rosbag2 bag (MCAP storage) without ROS: :class:`BagRecorder`, :func:`record_result` (a
finished RunResult) and the checks before a recording starts (:func:`check_write_target`). The bag's layout is
described in :mod:`gyro_sim.io.recording`."""
from __future__ import annotations

import math
import os
import shutil
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Mapping, Optional, Sequence, Union

import yaml

from gyro_sim import __version__
from gyro_sim.io.bag_format import (  # noqa: F401 (RESERVE_NAME: re-exported)
    _PREFIX, BAG_VERSION, CUSTOM_KEYS, EARLY_METADATA, RESERVE_NAME, _typestore, cdr_message, write_chunk_crcs,
)
from gyro_sim.io.messages import (
    QOS, TOPIC_DIAGNOSTICS, TOPIC_EFFECTS, TOPIC_SCENE, TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_STATUS,
    TOPIC_TF_STATIC, TOPICS,
    command_message, effects_message, scene_message, stamp_ns, state_messages, status_message, tf_static_message,
)
from gyro_sim.io.cdr_template import NUMBER_PATHS, STAMP_PATHS, Template
from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.io.signals import _held_signals, _signals_deferred, interrupt_reason

if TYPE_CHECKING:  # pragma: no cover
    from gyro_sim.engine.simulate import RunResult

__all__ = ["BagRecorder", "record_result", "stator_frames", "scene_text", "check_write_target", "RecordingError"]


def _qos(topic: str):
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    q = QOS[topic]
    zero = QosTime(0, 0)  # unspecified = the RMW default (infinite)
    return Qos(
        history=QosHistory[q["history"].upper()],
        depth=int(q["depth"]),
        reliability=QosReliability[q["reliability"].upper()],
        durability=QosDurability[q["durability"].upper()],
        deadline=zero,
        lifespan=zero,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=zero,
        avoid_ros_namespace_conventions=False,
    )


#: a chunk of the MCAP file is written out (and handed to the OS) once it spans this many simulated seconds or
#: has been open this many wall seconds, or holds 1 MiB (rosbags' own bound): kill -9 or a crash loses at most
#: the chunk that was open (`gyro-sim bag recover` rebuilds the rest); the first chunk (message definitions and
#: the scene) is written out with the first message
CHUNK_SPAN = 1.0
CHUNK_WALL = 1.0
#: bytes a recorder keeps allocated in its bag's file system while writing; freed to close the bag when the disk
#: fills (its summary and metadata.yaml need room); grows by RESERVE_PER_CHUNK per chunk written. The reserve is a
#: file without a name (O_TMPFILE, or unlinked as soon as it is made): its space goes back when its descriptor
#: closes, also when the process is killed (kill -9), so it never outlives its run
RESERVE_BYTES = 4 << 20
RESERVE_PER_CHUNK = 512
#: free space a recording wants before it starts (the reserve and the first chunks): checked up front
MIN_FREE_BYTES = 16 << 20


class RecordingError(OSError):
    """Recording failed (a target that is not writable, a full disk, a file size limit): one line that names the
    bag, the error and what the bag holds."""


def _nearest_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_write_target(path: Union[str, os.PathLike], what: str = "bag output") -> None:
    """Refuse, before any work, a bag path that cannot be recorded to: one that exists, under a file, in a
    directory that is not writable (read-only file system, permissions), or on a file system with less than
    :data:`MIN_FREE_BYTES` free. Raises :class:`RecordingError` (FileExistsError for an existing path)."""
    path = Path(path)
    if path.exists() or path.is_symlink():
        raise FileExistsError(f"{what} {str(path)!r} already exists; refusing to overwrite it "
                              "(choose a new path or remove the old bag)")
    base = _nearest_existing(path)
    if not base.is_dir():
        raise RecordingError(f"{what} {str(path)!r}: {str(base)!r} is not a directory")
    if not os.access(base, os.W_OK | os.X_OK):
        try:
            st = os.statvfs(base)
            ro = bool(st.f_flag & os.ST_RDONLY)
        except OSError:
            ro = False
        why = "is on a read-only file system" if ro else "is not writable"
        raise RecordingError(f"{what} {str(path)!r}: {str(base)!r} {why}")
    try:
        st = os.statvfs(base)
    except OSError:
        return
    free = st.f_bavail * st.f_frsize
    if free < MIN_FREE_BYTES:
        raise RecordingError(f"{what} {str(path)!r}: only {free / 2**20:.1f} MiB free on {str(base)!r}; a recording "
                             f"needs at least {MIN_FREE_BYTES / 2**20:.0f} MiB to start")


def _nameless_file(folder: Path) -> int:
    """A descriptor of a new file in ``folder``'s file system that has no name: O_TMPFILE where the file system
    has it, else a file made with a free name and unlinked at once. Its space is freed when it is closed,
    whoever closes it (the kernel, for a killed process)."""
    try:
        return os.open(folder, os.O_TMPFILE | os.O_WRONLY, 0o600)
    except (AttributeError, OSError):  # (no O_TMPFILE here, or a file system without it)
        pass
    import tempfile

    fd, name = tempfile.mkstemp(prefix=".gyro_sim_reserve-", dir=folder)
    os.unlink(name)
    return fd


_NO_TEMPLATE = object()


class BagRecorder:
    """Writes one rosbag2 bag (MCAP) of a run: a context manager, closable from ``finally``.

    ``path`` is the bag directory to create; it must not exist (refused with FileExistsError
    before anything is written). ``scene_text`` is the scene file's text, ``scene_name`` its
    name, ``extra`` more custom_data entries (str → str/number), ``static_tf`` the ``/tf_static`` message
    (:func:`gyro_sim.messages.tf_static_message`, e.g. :func:`stator_frames`), written with the scene.

    Leaving the ``with`` block, normally or by an exception (KeyboardInterrupt included),
    closes the bag: everything written so far is in a complete, indexed file; custom_data
    ``gyro_sim.end`` says ``complete``, ``interrupted: <exception>`` or ``failed: <what> at t = … s`` (the run's
    state broke: :meth:`run_failed`) and ``gyro_sim.duration`` the time of the
    last state sample written (s). The scene message is logged at the time of the first message written (t = 0
    if none). Thread-safe.

    The bag is written as it goes: chunks of at most ``chunk_span`` simulated or ``chunk_wall`` wall seconds
    (default :data:`CHUNK_SPAN`, :data:`CHUNK_WALL`), so memory stays flat and a crash loses at most one chunk. A write
    that fails (disk full, file size limit) drops the chunk it was writing, frees the space reserve, closes the
    bag with what was written whole and raises :class:`RecordingError`; every later write raises it too.
    """

    def __init__(self, path: Union[str, os.PathLike], scene_text: str, scene_name: str,
                 extra: Optional[Mapping[str, Any]] = None, static_tf: Optional[Mapping[str, Any]] = None,
                 chunk_span: Optional[float] = None, chunk_wall: Optional[float] = None):
        from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

        self._writer = None
        if not isinstance(scene_text, str):
            raise TypeError(f"BagRecorder: scene_text must be the scene file text (str), got {type(scene_text).__name__}")
        if not isinstance(scene_name, str) or not scene_name:
            raise ValueError(f"BagRecorder: scene_name must be a non-empty str, got {scene_name!r}")
        custom = {
            CUSTOM_KEYS["version"]: str(__version__),
            CUSTOM_KEYS["scene_name"]: scene_name,
            CUSTOM_KEYS["scene"]: scene_text,
        }
        for k, v in (extra or {}).items():
            if not isinstance(k, str) or not k:
                raise ValueError(f"BagRecorder: extra key {k!r}: must be a non-empty str")
            if k in custom or k == CUSTOM_KEYS["end"]:
                raise ValueError(f"BagRecorder: extra key {k!r} is reserved for the recorder")
            if isinstance(v, bool) or not isinstance(v, (str, int, float)):
                raise ValueError(f"BagRecorder: extra[{k!r}] = {v!r}: must be a str or a number")
            custom[k] = str(v)
        path = Path(path)
        check_write_target(path)
        self.path = path
        ts = _typestore()
        writer = Writer(path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        for k, v in custom.items():
            writer.set_custom_data(k, v)
        top = _nearest_existing(path)  # directories made from here on are removed if the bag cannot start
        try:
            writer.open()
        except WriterError as e:  # created by someone else since the check above
            raise FileExistsError(f"bag output {str(path)!r}: {e}") from None
        except OSError as e:
            raise RecordingError(f"bag output {str(path)!r}: cannot create it: {e.strerror or e}") from None
        self._lock = threading.Lock()
        self._scene_fields = scene_message(scene_text)
        self._static_tf = dict(static_tf) if static_tf is not None else None
        self._scene_written = False
        self._end = "complete"
        self.counts = {topic: 0 for topic in TOPICS}
        self.t_last = math.nan  # s, the last state sample written (in the open chunk or before)
        self.t_saved = math.nan  # s, the last state sample in a chunk written out whole
        # (None: the module's CHUNK_SPAN / CHUNK_WALL as they are when the bag is opened)
        self._span_ns = int(round(float(CHUNK_SPAN if chunk_span is None else chunk_span) * 1e9))
        self._chunk_wall = float(CHUNK_WALL if chunk_wall is None else chunk_wall)
        self._failed: Optional[str] = None
        self._templates: dict = {}  # shape -> Template (None: serialized whole), :meth:`_encode`
        self._reserve_fd: Optional[int] = None
        self._reserved = 0
        try:
            self._conns = {
                topic: writer.add_connection(topic, msgtype, typestore=ts, offered_qos_profiles=[_qos(topic)])
                for topic, msgtype in TOPICS.items()
            }
            self._writer = writer
            self._lock_file()
            self._write_early(custom)
            self._hook_chunks()
            self._reserve(RESERVE_BYTES)
        except BaseException as e:
            self._writer = None
            self._free_reserve()
            writer.abort()
            self._remove_new(path, top)
            if isinstance(e, OSError) and not isinstance(e, RecordingError):
                raise RecordingError(f"bag output {str(path)!r}: cannot start it: {e.strerror or e}") from None
            raise

    def _lock_file(self) -> None:
        """Hold an exclusive flock on the MCAP file while it is written (`gyro-sim bag recover` refuses a file a
        recorder still holds; a file system without flock: no lock)."""
        try:
            import fcntl

            fcntl.flock(self._writer.storage.bio.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except (ImportError, OSError):
            pass

    def _write_early(self, custom: Mapping[str, str]) -> None:
        """The custom_data known at the start as an MCAP metadata record (:data:`EARLY_METADATA`) right after the
        file header, written out at once: a recording cut short keeps them."""
        from mcap.data_stream import RecordBuilder
        from mcap.records import Metadata

        builder = RecordBuilder()
        Metadata(name=EARLY_METADATA, metadata=dict(custom)).write(builder)
        bio = self._writer.storage.bio
        bio.write(builder.end())
        bio.flush()

    @staticmethod
    def _remove_new(path: Path, top: Path) -> None:
        """Remove the bag directory and the parents made for it (up to ``top``, which existed)."""
        shutil.rmtree(path, ignore_errors=True)
        p = path.absolute().parent
        while p != top.absolute() and p != p.parent:
            try:
                p.rmdir()
            except OSError:
                break
            p = p.parent

    # --- chunks written as they fill; the state after the last one written whole ----------------
    def _hook_chunks(self) -> None:
        """Make the MCAP storage flush every chunk it closes and remember the state after it (see :meth:`_salvage`).
        (rosbags' McapWriter closes a chunk at 1 MiB by calling its own ``close_chunk``.)"""
        st = self._writer.storage
        write_chunk_crcs(st)  # (each chunk with its CRC: a damaged chunk is detected)
        close_chunk = st.close_chunk

        def close_and_flush() -> None:
            close_chunk()
            st.bio.flush()
            self._mark_saved()
            if len(st.chunks) % 1024 == 0:  # room for the index of the next 1024 chunks
                self._reserve(self._reserved + 1024 * RESERVE_PER_CHUNK)

        st.close_chunk = close_and_flush
        self._mark_saved()

    def _mark_saved(self) -> None:
        w = self._writer
        st = w.storage
        self._saved = (st.bio.tell(), len(st.chunks), dict(st.channel_stats), st.message_start_time,
                       st.message_end_time, dict(w.counts), w.min_timestamp, w.max_timestamp, dict(self.counts),
                       self.t_last)
        self.t_saved = self.t_last
        self._chunk_opened = time.monotonic()

    def _reserve(self, size: int) -> None:
        """Keep ``size`` bytes allocated in the reserve file (raises OSError when the disk has no room)."""
        if self._reserve_fd is None:
            self._reserve_fd = _nameless_file(self.path)
        os.posix_fallocate(self._reserve_fd, 0, size)
        self._reserved = size

    def _free_reserve(self) -> None:
        fd, self._reserve_fd = self._reserve_fd, None
        if fd is not None:
            os.close(fd)  # (a file without a name: its blocks are freed here)

    def _maybe_close_chunk(self, ns: int) -> None:
        """Write the open chunk out if it is the first (definitions and scene), spans ``chunk_span`` simulated
        seconds or has been open ``chunk_wall`` wall seconds."""
        st = self._writer.storage
        ch = st.chunk
        if ch.bio.tell() and (not st.chunks or ns - ch.message_start_time >= self._span_ns
                              or time.monotonic() - self._chunk_opened >= self._chunk_wall):
            st.close_chunk()

    def _salvage(self, exc: OSError) -> str:
        """After a failed write: cut the file back to the last chunk written whole, free the reserve and close the
        bag (``gyro_sim.end`` says why). Returns the one-line description of what happened."""
        from collections import defaultdict
        from io import BytesIO

        from rosbags.rosbag2.storage_mcap import PendingChunk

        w = self._writer
        st = w.storage
        why = exc.strerror or str(exc)
        pos, nchunks, stats, t0, t1, wcounts, mn, mx, counts, t_saved = self._saved
        try:
            st.bio.close()  # (its buffer may still hold bytes that do not fit: they are dropped below)
        except OSError:
            pass
        self._free_reserve()
        text = (f"recording to {str(self.path)!r} stopped: {why}; " if self._failed is None else "")
        try:
            os.truncate(st.path, pos)
            st.bio = open(st.path, "r+b")
            st.bio.seek(pos)
            self._lock_file()
            del st.chunks[nchunks:]
            st.channel_stats, st.message_start_time, st.message_end_time = dict(stats), t0, t1
            st.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
            w.counts, w.min_timestamp, w.max_timestamp = dict(wcounts), mn, mx
            self.counts, self.t_last = dict(counts), t_saved
            held = f"up to t = {t_saved:.6g} s" if math.isfinite(t_saved) else "no samples"
            w.set_custom_data(CUSTOM_KEYS["end"], f"interrupted: {why} (the bag holds {held})")
            w.set_custom_data(_PREFIX + "duration", repr(t_saved if math.isfinite(t_saved) else 0.0))
            w.close()
            return text + f"the bag is closed with what was written ({held})"
        except OSError as e2:
            try:
                w.abort()
            except OSError:
                pass
            return text + (f"the bag could not be closed ({e2.strerror or e2}): it holds the chunks written "
                           f"before; free some space and run: gyro-sim bag recover {self.path}")
        finally:
            self._writer = None

    # --- context manager
    def __enter__(self) -> "BagRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        if exc is not None:  # (the words the simulator node uses too)
            self._end = f"interrupted: {interrupt_reason(exc)}"
        self.close()
        return False

    def __del__(self):  # last resort: an unclosed recorder still leaves a readable bag
        try:
            if getattr(self, "_writer", None) is not None:
                self._end = "interrupted: not closed"
                self.close()
        except Exception:
            pass

    @property
    def closed(self) -> bool:
        return self._writer is None

    def set_custom(self, key: str, value: Any) -> None:
        """Add or replace a custom_data entry (str → str/number) before close, e.g. wall time at the end."""
        if not isinstance(key, str) or not key or key in CUSTOM_KEYS.values():
            raise ValueError(f"custom_data key {key!r}: must be a non-empty str not reserved by the recorder")
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise ValueError(f"custom_data[{key!r}] = {value!r}: must be a str or a number")
        with self._lock:
            if self._writer is None:
                raise RuntimeError(f"bag {str(self.path)!r} is closed")
            self._writer.set_custom_data(key, str(value))

    # --- writing
    def _serialize(self, topic: str, fields: dict) -> memoryview:
        return cdr_message(topic, fields)

    def _encode(self, topic: str, fields: dict):
        """The bytes of a per-sample or command message: by a :class:`gyro_sim.io.cdr_template.Template` of its shape
        (made at its first message: the same bytes as :meth:`_serialize`, ~2 µs instead of ~10-25), else
        :meth:`_serialize`. ``fields``: a builder's dict (:func:`gyro_sim.io.messages.state_messages`,
        :func:`gyro_sim.io.messages.command_message`), whose strings and constants are its topic's own; a JointState's
        names and lengths are part of its shape."""
        paths: Optional[tuple] = NUMBER_PATHS.get(topic)
        if paths is None:
            return self._serialize(topic, fields)
        key: tuple = (topic,)
        if topic in (TOPIC_STATORS, TOPIC_STATOR_COMMANDS):
            lengths = tuple(len(fields[k]) for k in ("position", "velocity", "effort"))
            key = (topic, tuple(fields["name"]), lengths)
            paths = STAMP_PATHS + tuple((k, i) for k, n in zip(("position", "velocity", "effort"), lengths, strict=True)
                                        for i in range(n))
        tmpl = self._templates.get(key, _NO_TEMPLATE)
        if tmpl is _NO_TEMPLATE:
            try:
                tmpl = Template(topic, fields, paths)
            except (ValueError, KeyError, TypeError):  # (no fixed place of a number: serialized whole)
                tmpl = None
            if len(self._templates) < 64:
                self._templates[key] = tmpl
        return self._serialize(topic, fields) if tmpl is None else tmpl.encode_fields(fields)

    def _write(self, ns: int, items: Sequence[tuple[str, Any]], t_sample: Optional[float] = None) -> None:
        """Write serialized (topic, data) pairs at log time ns (all or, on a bad argument, none); ``t_sample``:
        the time of the state sample they carry (s), if they do."""
        with self._lock:
            w = self._writer
            if w is None:
                if self._failed:
                    raise RecordingError(self._failed)
                raise RuntimeError(f"bag {str(self.path)!r} is closed")
            try:
                if not self._scene_written:
                    w.write(self._conns[TOPIC_SCENE], ns, self._serialize(TOPIC_SCENE, self._scene_fields))
                    self.counts[TOPIC_SCENE] += 1
                    if self._static_tf is not None:
                        w.write(self._conns[TOPIC_TF_STATIC], ns, self._serialize(TOPIC_TF_STATIC, self._static_tf))
                        self.counts[TOPIC_TF_STATIC] += 1
                    self._scene_written = True
                with _held_signals():  # (one sample: all its messages or none)
                    for topic, data in items:
                        w.write(self._conns[topic], ns, data)
                        self.counts[topic] += 1
                    if t_sample is not None:
                        self.t_last = t_sample
                self._maybe_close_chunk(ns)
            except OSError as exc:
                self._failed = self._salvage(exc)
                raise RecordingError(self._failed) from None

    def write_sample(self, t: float, L: Any, q: Any, omega_b: Any, euler: Any, torque: Any,
                     names: Sequence[str], current: Any, rate: Any, phase: Any,
                     effects: Optional[Mapping[str, Any]] = None) -> None:
        """One output sample at simulation time t (s): /clock, imu, kinetic_moment, euler, torque,
        stators (and /gyro/effects when ``effects`` has a state to publish). q is (w, x, y, z),
        body → case; see :func:`gyro_sim.messages.state_messages`."""
        msgs = state_messages(t, L, q, omega_b, euler, torque, names, current, rate, phase)
        eff = effects_message(t, effects) if effects else None
        if eff is not None:
            msgs[TOPIC_EFFECTS] = eff
        ns = stamp_ns(t)
        self._write(ns, [(topic, self._encode(topic, f)) for topic, f in msgs.items()], float(t))

    def write_samples(self, s: Mapping[str, Any], names: Sequence[str]) -> None:
        """Every row of a run's output arrays ``s`` (:meth:`gyro_sim.engine.runner.Runner.samples`) as
        :meth:`write_sample` writes one; Euler angles None: computed here from q and L, as the runner does
        (:func:`gyro_sim.engine.saving.sample_arrays`; the rows of a run with attitude)."""
        effects = s.get("effects") or {}
        eul = s.get("euler")
        if eul is None:
            eul = euler_angles(quat_to_matrix(s["q"]), s["L"])
        for i in range(s["t"].size):
            self.write_sample(s["t"][i], s["L"][i], s["q"][i], s["omega_b"][i], eul[i], s["torque"][i], names,
                              s["current"][i], s["rate"][i], s["phase"][i], {k: v[i] for k, v in effects.items()})

    def flush_due(self) -> None:
        """Nothing: every write is in the bag's open chunk at once (:class:`gyro_sim.io.bag_process.BagProcess`,
        whose interface this is, queues them)."""

    def write_command(self, t: float, names: Sequence[str], current: Optional[Any], rate: Optional[Any]) -> None:
        """A stator command at time t: currents (A) and/or signed rates (rad/s) of the named stators."""
        data = self._encode(TOPIC_STATOR_COMMANDS, command_message(t, names, current, rate))
        self._write(stamp_ns(t), [(TOPIC_STATOR_COMMANDS, data)])

    def write_diagnostics(self, t: float, fields: Mapping[str, Any]) -> None:
        """A ``/diagnostics`` message (:func:`gyro_sim.messages.diagnostics_message`) logged at time t."""
        self._write(stamp_ns(t), [(TOPIC_DIAGNOSTICS, self._serialize(TOPIC_DIAGNOSTICS, dict(fields)))])

    def write_status(self, t: float, text: str) -> None:
        """A status text (watchdog, refusal, info) logged at time t."""
        data = self._serialize(TOPIC_STATUS, status_message(text))
        self._write(stamp_ns(t), [(TOPIC_STATUS, data)])

    def interrupted(self, reason: str) -> None:
        """Mark the run as ended early (custom_data ``gyro_sim.end`` = ``interrupted: <reason>``)."""
        self._end = f"interrupted: {reason}"

    def run_failed(self, failure: str) -> None:
        """Mark the run as failed (custom_data ``gyro_sim.end`` = ``failure``, ``failed: <what> at t = … s``: its
        state broke (the Runner's failure; the bag holds the samples before it) or its controller was lost)."""
        self._end = failure

    @property
    def failed(self) -> Optional[str]:
        """The one-line description of a failed write (the bag was closed with what fit), else None."""
        return self._failed

    def close(self) -> None:
        """Finish the bag (index, summary, metadata.yaml; ``gyro_sim.duration`` = the last sample's time). Idempotent.
        A close that fails for lack of room drops the open chunk and closes with the rest (RecordingError)."""
        with self._lock:
            w = self._writer
            if w is None:
                return
            with _signals_deferred():
                try:
                    if not self._scene_written:
                        w.write(self._conns[TOPIC_SCENE], 0, self._serialize(TOPIC_SCENE, self._scene_fields))
                        self.counts[TOPIC_SCENE] += 1
                        self._scene_written = True
                    w.set_custom_data(CUSTOM_KEYS["end"], self._end)
                    w.set_custom_data(_PREFIX + "duration", repr(self.t_last if math.isfinite(self.t_last) else 0.0))
                    self._free_reserve()
                    w.close()
                except OSError as exc:
                    if w.storage is None:  # (metadata.yaml failed after the MCAP file was complete)
                        self._failed = f"bag {str(self.path)!r}: cannot write metadata.yaml: {exc.strerror or exc}"
                    else:
                        self._failed = self._salvage(exc)
                    raise RecordingError(self._failed) from None
                except BaseException:
                    w.abort()
                    raise
                finally:
                    self._free_reserve()
                    self._writer = None


def scene_text(scene) -> str:
    """The scene's file text if the file still says exactly this scene, else a YAML dump of it."""
    from gyro_sim.scenes.scene import SceneError, parse_scene_text, scene_from_dict

    src = getattr(scene, "source", None)
    if src:
        try:
            text = Path(src).read_text(encoding="utf-8")
            again = scene_from_dict(parse_scene_text(text, src), where=src, default_name=Path(src).stem)
            if again.model_dump(exclude={"source"}) == scene.model_dump(exclude={"source"}):
                return text
        except (OSError, UnicodeDecodeError, yaml.YAMLError, SceneError, AttributeError):
            pass
    from gyro_sim.scenes.scene_text import dump_scene_data

    return dump_scene_data(scene.model_dump(mode="json", exclude={"source"}))


def _command_values(values: Sequence[Optional[float]]) -> Optional[list]:
    """A command field: None (left empty) if no stator sets it, else floats with NaN = not set."""
    if all(v is None for v in values):
        return None
    return [math.nan if v is None else float(v) for v in values]


def stator_frames(scene) -> dict:
    """The ``/tf_static`` message of a scene: gyro_case → gyro_stator_<name>, axes = each stator's triad."""
    from gyro_sim.engine.simulate import stator_triad

    return tf_static_message([st.name for st in scene.stators], [stator_triad(st.axis) for st in scene.stators])


def record_result(result: "RunResult", path: Union[str, os.PathLike],
                  extra: Optional[Mapping[str, Any]] = None) -> Path:
    """Write a whole in-process :class:`~gyro_sim.simulate.RunResult` as a bag at ``path``.

    Every sample goes to the state topics; every command the run applied (the scene's schedule
    and the controller's, ``result.commands``) goes to ``/gyro/stator_commands`` at the time it
    was applied (a field no stator sets is left empty; NaN marks a stator that does not set it). The scene text is the scene file (when
    ``scene.source`` still holds exactly this scene; otherwise, e.g. after overrides, the
    validated scene dumped to YAML). Returns the bag directory. A run without attitude
    (``result.attitude`` False) is refused with ValueError: the state topics need it.
    """
    if not getattr(result, "attitude", True):
        raise ValueError("record_result: this run did not integrate the attitude (output.attitude: false on an "
                         "isotropic rotor): /gyro/imu and /gyro/euler need it; run it with "
                         "gyro_sim.run(scene, attitude=True) to record it")
    scene = result.scene
    text = scene_text(scene)
    names = list(result.stator_names)
    n = len(result.t)
    for t in result.t.tolist():  # validate every stamp before anything is written
        stamp_ns(t)
    t_end = float(result.t[-1]) if n else 0.0
    # every command the run applied (scene schedule and controller), at the time it applied it
    groups = [(float(t), list(nm), _command_values(cur), _command_values(rate))
              for t, nm, cur, rate in getattr(result, "commands", []) if t < t_end]
    ext = {"gyro_sim.steps": int(result.steps),
           "gyro_sim.wall_time": float(result.wall_time),
           # the duration the run's accuracy plan was made for (a run's last sample is at its end; gyro_sim.rerun)
           "gyro_sim.planned_duration": repr(t_end)}
    if getattr(result, "error_estimate", None) is not None:  # the run's estimated error (gyro_sim.accuracy)
        ext["gyro_sim.error_estimate"] = result.error_estimate.to_json()
    ext.update(extra or {})
    rows = (result.t.tolist(), result.L.tolist(), result.q.tolist(), result.omega_b.tolist(),
            result.euler.tolist(), result.torque.tolist(), result.current.tolist(),
            result.field_rate.tolist(), result.field_phase.tolist())
    effects = getattr(result, "effects", None) or {}
    with BagRecorder(path, text, scene.name, extra=ext, static_tf=stator_frames(scene)) as rec:
        gi = 0
        for i, (t, L, q, w, e, N, I, r, ph) in enumerate(zip(*rows)):
            # a sample at a command's time is taken before the command (simulate.run)
            while gi < len(groups) and groups[gi][0] < t:
                rec.write_command(*groups[gi])
                gi += 1
            rec.write_sample(t, L, q, w, e, N, names, I, r, ph, {k: v[i] for k, v in effects.items()})
        for g in groups[gi:]:
            rec.write_command(*g)
    return Path(path)
