"""Recording runs as rosbag2 bags (MCAP storage) without ROS, and reading them back.

Written with the ``rosbags`` library's rosbag2 :class:`~rosbags.rosbag2.Writer` (format
version 8, MCAP storage): a directory ``PATH/`` holding ``PATH.mcap`` (profile ``ros2``,
``ros2msg`` schemas, ``cdr`` messages, ``offered_qos_profiles`` on every channel, a summary
with statistics) and ``metadata.yaml`` — readable by ``ros2 bag info/play`` (Humble and
later), Foxglove and rosbags. Topics and message content are :mod:`gyro_sim.messages`
(the same contract the ROS nodes publish); the log time of every message is its stamp
(simulation time, ns).

The scene and the package version are stored twice:

* in the rosbag2 ``custom_data`` (``metadata.yaml``, and the same YAML inside the MCAP file's
  ``rosbag2`` metadata record that ``ros2 bag`` reads): keys ``gyro_sim.version``,
  ``gyro_sim.scene_name``, ``gyro_sim.scene`` (the scene file text), ``gyro_sim.end``
  (``complete`` or ``interrupted: <exception>``) and any ``extra`` keys;
* as one latched message on ``/gyro/scene`` (std_msgs/String, transient_local depth 1), so a
  player or Foxglove that ignores custom_data still gets the scene.

rosbags' MCAP writer has no API for MCAP metadata records of one's own (it writes exactly one,
``rosbag2``), hence this choice.

Use::

    with BagRecorder("runs/bag1", scene_text, "spinup") as rec:   # refuses an existing path
        rec.write_sample(t, L, q, omega_b, euler, torque, names, current, rate, phase)
    record_result(gyro_sim.run(scene), "runs/bag2")
    data = read_bag("runs/bag2"); data.t, data.L, data.scene_text
"""
from __future__ import annotations

import math
import os
import shutil
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Literal, Mapping, Optional, Sequence, Union

import numpy as np
import yaml

from gyro_sim import __version__
from gyro_sim.io.messages import (
    QOS, TOPIC_CLOCK, TOPIC_DIAGNOSTICS, TOPIC_EFFECTS, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_SCENE,
    TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_STATUS, TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TORQUE, TOPICS,
    command_message, effects_message, scene_message, stamp_ns, state_messages, status_message, tf_static_message,
    to_rosbags,
)

from gyro_sim.io.bag_format import _PREFIX, BAG_VERSION, CUSTOM_KEYS, EARLY_METADATA  # noqa: F401  (re-exported)

if TYPE_CHECKING:  # pragma: no cover
    from gyro_sim.engine.simulate import RunResult

__all__ = ["BagRecorder", "BagData", "record_result", "record_run", "stator_frames", "scene_text", "read_bag", "bag_info",
           "sigterm_as_interrupt", "check_write_target", "RecordingError", "RunInterrupted", "exit_status",
           "BagNotClosedError", "EARLY_METADATA",
           "BAG_VERSION", "CUSTOM_KEYS"]

_TYPESTORE = None


def _typestore():
    """The rosbags typestore (ROS 2 Humble definitions; identical hashes in Jazzy for our types)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
    return _TYPESTORE


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


# --- signals ----------------------------------------------------------------------------------

class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal (SIGTERM, SIGHUP; SIGINT raises a plain KeyboardInterrupt): ``signum``.
    ``exit_status`` is the shell's convention, 128 + signal number (143 for SIGTERM, 130 for SIGINT)."""

    def __init__(self, signum: int):
        super().__init__(f"signal {signal.Signals(signum).name}")
        self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def exit_status(exc: BaseException) -> int:
    """128 + the signal that ended a run (130 for Ctrl-C's plain KeyboardInterrupt, 143 for SIGTERM)."""
    return exc.exit_status if isinstance(exc, RunInterrupted) else 128 + int(signal.SIGINT)


#: [depth of the write sections open, the signal held meanwhile]: a signal that arrives while one sample's
#: messages are written is raised when they all are, so a bag never ends in half a sample
_HOLD: list = [0, None]


def _interrupt(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else RunInterrupted(signum)


@contextmanager
def _held_signals() -> Iterator[None]:
    """A section no signal handler of :func:`sigterm_as_interrupt` breaks: a signal that arrives within is
    raised at its end (cheap: a counter, no system call)."""
    _HOLD[0] += 1
    try:
        yield
    finally:
        _HOLD[0] -= 1
        if _HOLD[0] == 0 and _HOLD[1] is not None:
            signum, _HOLD[1] = _HOLD[1], None
            raise _interrupt(signum)


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`RunInterrupted` (a KeyboardInterrupt, as Ctrl-C
    raises) and Ctrl-C (while Python's default handler is in place) a KeyboardInterrupt, so ``finally`` /
    ``with BagRecorder`` close the bag. A signal that arrives while a sample is written to a bag is raised once
    the sample is whole. Main thread only (elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _raise(signum, frame):
        if _HOLD[0]:
            _HOLD[1] = _HOLD[1] or signum
            return
        raise _interrupt(signum)

    sigs = [signal.SIGTERM, signal.SIGHUP]
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        sigs.append(signal.SIGINT)
    old = {sig: signal.signal(sig, _raise) for sig in sigs}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM while the bag's index and metadata are written (a second Ctrl-C
    must not leave a half-closed file); delivered to the previous handlers afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    sigs = [signal.SIGINT, signal.SIGTERM]
    old = {}
    for s in sigs:
        # a handler installed outside Python (getsignal() is None, e.g. rclpy's) is left alone:
        # it could not be put back
        if signal.getsignal(s) is None:
            continue
        try:
            old[s] = signal.signal(s, lambda signum, frame: pending.append(signum))
        except (ValueError, OSError):  # pragma: no cover - not settable here
            pass
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for s in dict.fromkeys(pending):
            signal.raise_signal(s)


# --- writing ----------------------------------------------------------------------------------

#: a chunk of the MCAP file is written out (and handed to the OS) once it spans this many simulated seconds or
#: has been open this many wall seconds, or holds 1 MiB (rosbags' own bound): kill -9 or a crash loses at most
#: the chunk that was open (`gyro-sim bag recover` rebuilds the rest); the first chunk (message definitions and
#: the scene) is written out with the first message
CHUNK_SPAN = 1.0
CHUNK_WALL = 1.0
#: bytes a recorder keeps allocated next to its bag (``.gyro_sim_reserve``) while writing; freed to close the bag
#: when the disk fills (its summary and metadata.yaml need room); grows by RESERVE_PER_CHUNK per chunk written
RESERVE_BYTES = 4 << 20
RESERVE_PER_CHUNK = 512
RESERVE_NAME = ".gyro_sim_reserve"
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


class BagRecorder:
    """Writes one rosbag2 bag (MCAP) of a run: a context manager, closable from ``finally``.

    ``path`` is the bag directory to create; it must not exist (refused with FileExistsError
    before anything is written). ``scene_text`` is the scene file's text, ``scene_name`` its
    name, ``extra`` more custom_data entries (str → str/number), ``static_tf`` the ``/tf_static`` message
    (:func:`gyro_sim.messages.tf_static_message`, e.g. :func:`stator_frames`), written with the scene.

    Leaving the ``with`` block, normally or by an exception (KeyboardInterrupt included),
    closes the bag: everything written so far is in a complete, indexed file; custom_data
    ``gyro_sim.end`` says ``complete`` or ``interrupted: <exception>`` and ``gyro_sim.duration`` the time of the
    last state sample written (s). The scene message is logged at the time of the first message written (t = 0
    if none). Thread-safe.

    The bag is written as it goes: chunks of at most ``chunk_span`` simulated or ``chunk_wall`` wall seconds
    (:data:`CHUNK_SPAN`, :data:`CHUNK_WALL`), so memory stays flat and a crash loses at most one chunk. A write
    that fails (disk full, file size limit) drops the chunk it was writing, frees the space reserve, closes the
    bag with what was written whole and raises :class:`RecordingError`; every later write raises it too.
    """

    def __init__(self, path: Union[str, os.PathLike], scene_text: str, scene_name: str,
                 extra: Optional[Mapping[str, Any]] = None, static_tf: Optional[Mapping[str, Any]] = None,
                 chunk_span: float = CHUNK_SPAN, chunk_wall: float = CHUNK_WALL):
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
        self._ts = ts
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
        self._span_ns = int(round(float(chunk_span) * 1e9))
        self._chunk_wall = float(chunk_wall)
        self._failed: Optional[str] = None
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
            self._reserve_fd = os.open(self.path / RESERVE_NAME, os.O_CREAT | os.O_WRONLY | os.O_EXCL, 0o600)
        os.posix_fallocate(self._reserve_fd, 0, size)
        self._reserved = size

    def _free_reserve(self) -> None:
        fd, self._reserve_fd = self._reserve_fd, None
        if fd is not None:
            os.close(fd)
            try:
                os.unlink(self.path / RESERVE_NAME)
            except OSError:
                pass

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
        if isinstance(exc, RunInterrupted):  # (the words the simulator node uses too)
            self._end = f"interrupted: signal {signal.Signals(exc.signum).name}"
        elif isinstance(exc, KeyboardInterrupt):
            self._end = "interrupted: signal SIGINT"
        elif exc_type is not None:
            self._end = f"interrupted: {exc_type.__name__}" + (f" ({exc})" if str(exc) else "")
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
        msgtype = TOPICS[topic]
        return self._ts.serialize_cdr(to_rosbags(self._ts, msgtype, fields), msgtype)

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
        self._write(ns, [(topic, self._serialize(topic, f)) for topic, f in msgs.items()], float(t))

    def write_command(self, t: float, names: Sequence[str], current: Optional[Any], rate: Optional[Any]) -> None:
        """A stator command at time t: currents (A) and/or signed rates (rad/s) of the named stators."""
        data = self._serialize(TOPIC_STATOR_COMMANDS, command_message(t, names, current, rate))
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


# --- a run streamed to its bag -------------------------------------------------------------------

#: output rows a streamed run holds in memory at once (its buffer; released as they are written)
STREAM_BUFFER_ROWS = 4096
#: a streamed run keeps its rows in memory for the RunResult up to this many bytes; beyond, the result reads
#: its series back from the bag when first used (RunResult.lazy) and keeps a decimated preview
KEEP_BYTES = 64 << 20
#: rows of that preview (every k-th row, k doubling as the run goes on, and the last row)
PREVIEW_ROWS = 10_000


class _Rows:
    """Output rows appended chunk by chunk into arrays that grow by doubling (a run sampled one row at a time
    must not hold one small array per row)."""

    def __init__(self):
        self.n = 0
        self.a: Optional[dict] = None

    @staticmethod
    def _fields(s: dict, rows) -> dict:
        out = {k: np.asarray(s[k])[rows] for k in _Kept.KEYS}
        out.update({"effects." + k: np.asarray(v)[rows] for k, v in s["effects"].items()})
        return out

    def append(self, s: dict, rows) -> None:
        part = self._fields(s, rows)
        m = part["t"].shape[0]
        if self.a is None:
            self.a = {k: np.empty((max(1024, m),) + v.shape[1:], v.dtype) for k, v in part.items()}
        cap = self.a["t"].shape[0]
        if self.n + m > cap:
            cap = max(2 * cap, self.n + m)
            for k, v in self.a.items():
                grown = np.empty((cap,) + v.shape[1:], v.dtype)
                grown[: self.n] = v[: self.n]
                self.a[k] = grown
        for k, v in part.items():
            self.a[k][self.n: self.n + m] = v
        self.n += m

    @property
    def nbytes(self) -> int:
        return sum(v.nbytes for v in self.a.values()) if self.a else 0

    def halve(self) -> None:
        """Keep every other row (0, 2, 4, ...)."""
        keep = (self.n + 1) // 2
        for v in self.a.values():
            v[:keep] = v[: self.n: 2].copy()
        self.n = keep

    def series(self, last: Optional["_Rows"] = None) -> dict:
        """RunResult fields of the rows (and of ``last``'s rows after them if they are later)."""
        a = {k: v[: self.n] for k, v in self.a.items()}
        if last is not None and last.n and (not self.n or a["t"][-1] != last.a["t"][0]):
            a = {k: np.concatenate([v, last.a[k][:1]]) for k, v in a.items()}
        return {"t": a["t"], "L": a["L"], "q": a["q"], "omega_b": a["omega_b"], "torque": a["torque"],
                "energy": a["energy"], "current": a["current"], "field_rate": a["rate"], "field_phase": a["phase"],
                "modes": a["modes"], "effects": {k[8:]: v for k, v in a.items() if k.startswith("effects.")}}


class _Kept:
    """The output rows of a streamed run kept for its RunResult: all of them up to ``keep_bytes`` (then none), and
    always a decimated preview (every ``stride``-th row; the stride doubles when it reaches PREVIEW_ROWS) and the
    last row."""

    KEYS = ("t", "L", "q", "omega_b", "torque", "energy", "current", "rate", "phase", "modes")

    def __init__(self, keep_bytes: int):
        self.keep_bytes = keep_bytes
        self.rows: Optional[_Rows] = _Rows() if keep_bytes > 0 else None
        self.commands: Optional[list] = [] if keep_bytes > 0 else None
        self.preview, self.last = _Rows(), _Rows()
        self.stride, self.seen = 1, 0

    def add(self, s: dict, commands: list) -> None:
        n = s["t"].size
        if not n:
            return
        if self.rows is not None:
            self.rows.append(s, slice(None))
            self.commands.extend(commands)
            if self.rows.nbytes > self.keep_bytes:
                self.rows = self.commands = None  # from here on the bag holds them
        first = (-self.seen) % self.stride
        if first < n:
            self.preview.append(s, slice(first, None, self.stride))
        self.seen += n
        self.last.n = 0
        self.last.append(s, slice(n - 1, n))
        if self.preview.n >= PREVIEW_ROWS:
            self.preview.halve()
            self.stride *= 2


class _StreamOrder:
    """Writes a run's samples and applied commands to a :class:`BagRecorder` in the order :func:`record_result`
    writes them: a command before every sample later than it (a sample at a command's instant was taken before
    the command), commands at or after the run's end not at all."""

    def __init__(self, rec: BagRecorder, names: Sequence[str]):
        self.rec, self.names = rec, list(names)
        self.pending: list = []

    def _command(self, c) -> None:
        t, nm, cur, rate = c
        self.rec.write_command(float(t), list(nm), _command_values(cur), _command_values(rate))

    def write(self, s: dict, commands: list) -> None:
        self.pending.extend(commands)
        t = s["t"]
        eff = s["effects"]
        for i in range(t.size):
            ti = float(t[i])
            while self.pending and self.pending[0][0] < ti:
                self._command(self.pending.pop(0))
            self.rec.write_sample(ti, s["L"][i], s["q"][i], s["omega_b"][i], s["euler"][i], s["torque"][i],
                                  self.names, s["current"][i], s["rate"][i], s["phase"][i],
                                  {k: v[i] for k, v in eff.items()})

    def finish(self, commands: list, t_end: float) -> None:
        self.pending.extend(commands)
        for c in self.pending:
            if c[0] < t_end:
                self._command(c)
        self.pending = []


def record_run(scene, path: Union[str, os.PathLike], duration: Optional[float] = None, on_samples=None,
               extra: Optional[Mapping[str, Any]] = None, keep_bytes: int = KEEP_BYTES) -> "RunResult":
    """Run a scene in-process and write its bag at ``path`` as it runs (the same bag :func:`record_result` writes
    of the same run, message for message). Memory stays flat: the simulator holds a buffer of
    :data:`STREAM_BUFFER_ROWS` output rows, the bag's open chunk is bounded (:data:`CHUNK_SPAN`,
    :data:`CHUNK_WALL`), and the returned RunResult keeps its rows in memory up to ``keep_bytes``; beyond, it
    reads them back from the bag when first used (without what bags do not hold in RunResult's form: ``modes``
    then has no columns and ``effects`` is empty; read_bag gives the /gyro/effects channels) and
    :meth:`RunResult.preview` gives a decimated copy.

    The write target is checked before the run (:func:`check_write_target`). Ctrl-C, SIGTERM or SIGHUP close
    the bag with everything up to the signal (``gyro_sim.end`` = ``interrupted: ...``) and re-raise
    (:class:`RunInterrupted` for SIGTERM / SIGHUP, KeyboardInterrupt for Ctrl-C). A full disk closes the bag
    with what fit and raises :class:`RecordingError`. ``on_samples(dict)`` is called with each chunk of rows.
    A scene with ``fidelity`` other than ``full`` is run in memory and recorded when it ends."""
    from gyro_sim.engine.simulate import Runner, drive, kinetic_energy
    from gyro_sim.engine.simulate import RunResult as _RunResult

    path = Path(path)
    check_write_target(path)
    if scene.fidelity != "full":
        from gyro_sim.engine.simulate import run as _run

        result = _run(scene, duration, attitude=True)
        record_result(result, path, extra)
        return result
    r = Runner(scene, duration, sample_breaks=True, attitude=True, buffer_rows=STREAM_BUFFER_ROWS)
    kept = _Kept(keep_bytes)
    ext = {"gyro_sim.planned_duration": repr(float(r.T))}
    ext.update(extra or {})
    names = list(r.sim.stator_names)
    with sigterm_as_interrupt(), BagRecorder(path, scene_text(scene), scene.name, extra=ext,
                                             static_tf=stator_frames(scene)) as rec:
        order = _StreamOrder(rec, names)

        def take(s: dict) -> None:
            commands = r.take_commands()
            order.write(s, commands)
            kept.add(s, commands)
            if on_samples is not None:
                on_samples(s)

        try:
            drive(r, take, release=True)
            order.finish(r.take_commands(), r.T)
        finally:
            if not rec.closed:
                rec.set_custom("gyro_sim.steps", int(r.sim.steps))
                rec.set_custom("gyro_sim.wall_time", float(r.wall_time))
                rec.set_custom("gyro_sim.compile_time", float(r.compile_time))
                rec.set_custom("gyro_sim.error_estimate", r.error_estimate().to_json())
    known = dict(scene=scene, stator_names=names, wall_time=r.wall_time, compile_time=r.compile_time,
                 steps=r.sim.steps, attitude=True, error_estimate=r.error_estimate())
    if kept.rows is not None:
        return _RunResult(**known, **kept.rows.series(), commands=kept.commands)
    preview = _RunResult(**known, **kept.preview.series(kept.last))
    J = r.sim.J

    def load() -> dict:
        b = read_bag(path)
        cmds = []
        for t, c, v in zip(b.command_t.tolist(), b.command_current, b.command_rate):
            ks = [k for k in range(len(b.stator_names)) if not (np.isnan(c[k]) and np.isnan(v[k]))]
            cmds.append((t, [b.stator_names[k] for k in ks], [None if np.isnan(c[k]) else float(c[k]) for k in ks],
                         [None if np.isnan(v[k]) else float(v[k]) for k in ks]))
        return {"t": b.t, "L": b.L, "q": b.q, "omega_b": b.omega_b, "torque": b.torque,
                "energy": kinetic_energy(J, b.omega_b), "current": b.current, "field_rate": b.rate,
                "field_phase": b.phase, "modes": np.zeros((b.t.size, 0)),
                "effects": {}, "commands": cmds, "_euler": b.euler}

    return _RunResult.lazy(load, preview, **known)


# --- reading ----------------------------------------------------------------------------------

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


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


#: topics read_bag(max_samples=...) thins out (every k-th message and the last); status and the scene are kept
_THINNED = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_EFFECTS,
            TOPIC_STATOR_COMMANDS, TOPIC_CLOCK)


def read_bag(path: Union[str, os.PathLike], max_samples: Optional[int] = None) -> BagData:
    """Read a gyro_sim bag (a bag directory or its .mcap file) with rosbags into :class:`BagData`.

    ``max_samples``: read at most about that many samples of each state topic (and of the commands and /clock):
    every k-th message and the last one, k from the bag's message counts (memory bounded however long the run: a
    summary or a plot of an hour-long bag); None reads every message."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    _refuse_not_closed(path)
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
    """Summary of a bag without reading its messages: topics (type, count), times (s), scene, version."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    _refuse_not_closed(path)
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
