"""Recording runs as rosbag2 bags (MCAP storage) without ROS, and reading them back.

This module holds :func:`record_run` (a run streamed to its bag) and re-exports the rest, which lives beside it:
:mod:`gyro_sim.io.bag_writer` (:class:`BagRecorder`, :func:`record_result`), :mod:`gyro_sim.io.bag_reader`
(:func:`read_bag`, :func:`bag_info`) and :mod:`gyro_sim.io.signals` (:func:`sigterm_as_interrupt`).

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
  (``complete``, ``interrupted: <exception>`` or ``failed: <what> at t = … s``) and any ``extra`` keys;
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

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Optional, Sequence, Union

import numpy as np

# the names of before the split (issue 22), re-exported: `from gyro_sim.recording import X` keeps working
from gyro_sim.io.bag_format import _PREFIX, _TYPESTORE, BAG_VERSION, CUSTOM_KEYS, EARLY_METADATA, _typestore  # noqa: F401
from gyro_sim.io.bag_reader import (  # noqa: F401
    _THINNED, BagData, BagNotClosedError, bag_effects, _custom_data, _ns, _refuse_not_closed, bag_info, read_bag,
)
from gyro_sim.io.bag_writer import (  # noqa: F401
    CHUNK_SPAN, CHUNK_WALL, MIN_FREE_BYTES, RESERVE_BYTES, RESERVE_NAME, RESERVE_PER_CHUNK, BagRecorder, RecordingError,
    _command_values, _nearest_existing, _qos, check_write_target, record_result, scene_text, stator_frames,
)
from gyro_sim.io.signals import (  # noqa: F401
    _HOLD, RunInterrupted, _held_signals, _interrupt, _signals_deferred, exit_status, sigterm_as_interrupt,
)

if TYPE_CHECKING:  # pragma: no cover
    from gyro_sim.engine.simulate import RunResult

__all__ = ["BagRecorder", "BagData", "record_result", "record_run", "stator_frames", "scene_text", "read_bag", "bag_info",
           "sigterm_as_interrupt", "check_write_target", "RecordingError", "RunInterrupted", "exit_status",
           "BagNotClosedError", "EARLY_METADATA",
           "BAG_VERSION", "CUSTOM_KEYS"]


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
               extra: Optional[Mapping[str, Any]] = None, keep_bytes: int = KEEP_BYTES,
               force: bool = False) -> "RunResult":
    """Run a scene in-process and write its bag at ``path`` as it runs (the same bag :func:`record_result` writes
    of the same run, message for message). Memory stays flat: the simulator holds a buffer of
    :data:`STREAM_BUFFER_ROWS` output rows, the bag's open chunk is bounded (:data:`CHUNK_SPAN`,
    :data:`CHUNK_WALL`), and the returned RunResult keeps its rows in memory up to ``keep_bytes``; beyond, it
    reads them back from the bag when first used (without what bags do not hold in RunResult's form: ``modes``
    then has no columns; ``effects`` holds the /gyro/effects channels) and
    :meth:`RunResult.preview` gives a decimated copy.

    The write target is checked before the run (:func:`check_write_target`). Ctrl-C, SIGTERM or SIGHUP close
    the bag with everything up to the signal (``gyro_sim.end`` = ``interrupted: ...``) and re-raise
    (:class:`RunInterrupted` for SIGTERM / SIGHUP, KeyboardInterrupt for Ctrl-C). A full disk closes the bag
    with what fit and raises :class:`RecordingError`. ``on_samples(dict)`` is called with each chunk of rows.
    A scene with ``fidelity`` other than ``full`` is run in memory and recorded when it ends. ``force``: run a plan
    beyond the step budget (:func:`gyro_sim.engine.simulate.run`; refused before the bag is made without it)."""
    from gyro_sim.engine.simulate import Runner, drive, system_energy
    from gyro_sim.engine.simulate import RunResult as _RunResult

    path = Path(path)
    check_write_target(path)
    if scene.fidelity != "full":
        from gyro_sim.engine.simulate import run as _run

        result = _run(scene, duration, attitude=True, force=force)
        record_result(result, path, extra)
        return result
    r = Runner(scene, duration, sample_breaks=True, attitude=True, buffer_rows=STREAM_BUFFER_ROWS, force=force)
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
            order.finish(r.take_commands(), r.T if r.failure is None else r.sim.t)
        finally:
            if not rec.closed:
                rec.set_custom("gyro_sim.steps", int(r.sim.steps))
                rec.set_custom("gyro_sim.wall_time", float(r.wall_time))
                rec.set_custom("gyro_sim.compile_time", float(r.compile_time))
                if r.failure is not None:  # (no error estimate of a failed run: its end says what broke)
                    rec.run_failed(r.failure)
                else:
                    rec.set_custom("gyro_sim.error_estimate", r.error_estimate().to_json())
    known = dict(scene=scene, stator_names=names, wall_time=r.wall_time, compile_time=r.compile_time,
                 steps=r.sim.steps, attitude=True, failure=r.failure,
                 error_estimate=None if r.failure is not None else r.error_estimate())
    if kept.rows is not None:
        return _RunResult(**known, **kept.rows.series(), commands=kept.commands)
    preview = _RunResult(**known, **kept.preview.series(kept.last))
    def load() -> dict:
        b = read_bag(path)
        cmds = []
        for t, c, v in zip(b.command_t.tolist(), b.command_current, b.command_rate):
            ks = [k for k in range(len(b.stator_names)) if not (np.isnan(c[k]) and np.isnan(v[k]))]
            cmds.append((t, [b.stator_names[k] for k in ks], [None if np.isnan(c[k]) else float(c[k]) for k in ks],
                         [None if np.isnan(v[k]) else float(v[k]) for k in ks]))
        return {"t": b.t, "L": b.L, "q": b.q, "omega_b": b.omega_b, "torque": b.torque,
                "energy": system_energy(scene, b.omega_b, bag_effects(b)), "current": b.current, "field_rate": b.rate,
                "field_phase": b.phase, "modes": np.zeros((b.t.size, 0)),
                "effects": bag_effects(b), "commands": cmds, "_euler": b.euler}

    return _RunResult.lazy(load, preview, **known)
