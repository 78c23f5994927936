"""A bag written by a process of its own: :class:`BagProcess`, :class:`gyro_sim.io.bag_writer.BagRecorder`'s writing
interface, whose writes are sent over a socket to a child process (``python -m gyro_sim.io.bag_process``, the node's
gyro_sim whatever the working directory holds) that runs the BagRecorder. The simulator node records so in lockstep
and freerun (in real time it writes the bag itself, in the pacing's idle time).

Why: the lockstep tick is a hand-over between two processes. Writing a state sample's seven messages costs ~90 µs
of Python (the CDR bytes and rosbags' MCAP records); in the node that is on the tick's critical path, and with both
nodes on one CPU (``--node-cpu auto``) it took turns with the controller. Here the node queues the sample rows'
numbers (~10 µs a tick, no Euler angles: the child computes those no one subscribed to) and sends the queue every
:data:`BATCH_WALL` s or :data:`BATCH_BYTES`; the child writes it on another CPU (``GYRO_SIM_WRITER_CPUS``).

The child writes what it is sent in order: the bag is the BagRecorder's, message for message. Its failures (a full
disk: :class:`RecordingError`) reach the node at its next send or at :meth:`BagProcess.close`. It ignores SIGINT,
SIGTERM and SIGHUP and runs in a session of its own: the node decides how the bag ends (``interrupted``, ``close``).
If the node ends without closing it (kill -9), the child sees the socket close and closes the bag with what it was
sent, ``gyro_sim.end`` = ``interrupted: the simulator process ended without closing the bag``: the writes queued
since the last send are lost (a send comes with a write, or the node's pump, once the oldest queued write is
:data:`BATCH_WALL` s old: normally the last 50 ms). A socket buffer's worth of writes (~200 kB) can wait for the
child; beyond, a send waits for it (memory stays flat).

``GYRO_SIM_WRITER_CPUS`` (comma-separated CPU numbers; :func:`gyro_sim.ros.launch.writer_cpus_env` sets it where the
launcher holds the nodes to one CPU): the CPUs the child may use.
"""
from __future__ import annotations

import os
import pickle
import signal
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection
from typing import Any, Literal, Mapping, Optional, Sequence, Union

import numpy as np

from gyro_sim.io.bag_writer import RecordingError
from gyro_sim.io.signals import interrupt_reason, signal_name

__all__ = ["BagProcess", "WRITER_CPUS_ENV"]

#: environment variable: the CPUs the writer process may use (comma-separated)
WRITER_CPUS_ENV = "GYRO_SIM_WRITER_CPUS"
#: the node's writes are sent together once they hold this many bytes or the oldest waited this long (wall s):
#: the writer wakes ~20 times a second, not at every tick (a wake-up per tick cost the node ~30 µs a send and
#: took CPU from its controller); a kill -9 of the node loses at most these writes
BATCH_BYTES = 64 << 10
BATCH_WALL = 0.05
#: wall s the writer process has to start and open the bag (a Python start and an import: ~0.3 s idle)
OPEN_TIMEOUT = 60.0
#: per-sample arrays sent as one float64 matrix, in this order (``t`` one column, each other as wide as it is;
#: ``euler`` only where the node computed it, else the writer does)
_SAMPLE_KEYS = ("t", "L", "q", "omega_b", "torque", "current", "rate", "phase")
_ROWS, _ROWS_EULER, _CALL = b"S" + bytes(7), b"E" + bytes(7), b"P"  # (8 bytes: the numbers start 8-aligned)
#: exceptions the child's open may raise that are raised again as themselves in the node
_OPEN_ERRORS = {e.__name__: e for e in (FileExistsError, RecordingError, ValueError, TypeError)}
_LOST = "the simulator process ended without closing the bag"
#: the writer process: ``python -m gyro_sim.io.bag_process FD`` with this gyro_sim's code (``-m`` would put the working
#: directory first on sys.path: a node started beside another gyro_sim, a source checkout, would run that one's writer)
_CHILD = "import sys; sys.path[0] = sys.argv.pop(1); from gyro_sim.io.bag_process import main; sys.exit(main())"
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class BagProcess:
    """A bag (MCAP, rosbag2) written by a child process: the arguments are :class:`BagRecorder`'s, and so are the
    writing methods; the constructor returns once the child has opened the bag (its refusal raised here, as the
    BagRecorder's would be: FileExistsError, RecordingError, ValueError)."""

    def __init__(self, path: Union[str, os.PathLike], scene_text: str, scene_name: str,
                 extra: Optional[Mapping[str, Any]] = None, static_tf: Optional[Mapping[str, Any]] = None,
                 chunk_span: Optional[float] = None, chunk_wall: Optional[float] = None):
        self.path = path
        self._failed: Optional[str] = None
        self._conn: Optional[Connection] = None
        self._names: Optional[tuple] = None
        self._batch: list = []
        self._batch_bytes = 0
        self._batch_wall = 0.0
        ours, theirs = socket.socketpair()
        try:
            self._proc = subprocess.Popen([sys.executable, "-c", _CHILD, _ROOT, str(theirs.fileno())],
                                          pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                          start_new_session=True)
        finally:
            theirs.close()
        self._conn = Connection(ours.detach())
        self._call("open", (os.fspath(path), scene_text, scene_name, extra, static_tf, chunk_span, chunk_wall))
        self._flush()
        if not self._conn.poll(OPEN_TIMEOUT):
            self._proc.kill()
            self._end_child()
            raise RecordingError(f"bag output {os.fspath(path)!r}: its writer process did not start within "
                                 f"{OPEN_TIMEOUT:g} s")
        reply = self._reply()
        if reply[0] == "error":
            self._end_child()
            raise _OPEN_ERRORS.get(reply[1], RecordingError)(reply[2])

    # --- the writing interface (BagRecorder's)
    def write_samples(self, s: Mapping[str, Any], names: Sequence[str]) -> None:
        """Every row of ``s`` (:meth:`BagRecorder.write_samples`; Euler angles None: the writer computes them): its
        numbers in one message."""
        n, eul = s["t"].size, s.get("euler")
        if not n:  # (nothing to write, as the BagRecorder's loop writes nothing)
            return
        arrays = [np.asarray(s[k]).reshape(n, -1) for k in _SAMPLE_KEYS]
        if eul is not None:
            arrays.append(np.asarray(eul).reshape(n, -1))
        if s.get("effects") or any(a.dtype != np.float64 for a in arrays):  # (rare: sent as they are)
            self._call("write_samples", (dict(s), list(names)))
            return
        if tuple(names) != self._names:
            self._names = tuple(names)
            self._call("names", (list(names),))
        self._add((_ROWS if eul is None else _ROWS_EULER) + np.hstack(arrays).tobytes())

    def write_sample(self, *args, **kwargs) -> None:
        self._call("write_sample", args, kwargs)

    def write_command(self, *args) -> None:
        self._call("write_command", args)

    def write_diagnostics(self, t: float, fields: Mapping[str, Any]) -> None:
        self._call("write_diagnostics", (t, dict(fields)))

    def write_status(self, *args) -> None:
        self._call("write_status", args)

    def set_custom(self, *args) -> None:
        self._call("set_custom", args)

    def interrupted(self, reason: str) -> None:
        self._call("interrupted", (reason,))

    def run_failed(self, failure: str) -> None:
        self._call("run_failed", (failure,))

    @property
    def failed(self) -> Optional[str]:
        """The child's failed write (the bag was closed with what fit), once it has been heard of, else None."""
        return self._failed

    @property
    def closed(self) -> bool:
        return self._conn is None

    def close(self) -> None:
        """Close the bag: returns when the child has written everything sent and closed it (RecordingError if that
        failed). Idempotent."""
        if self._conn is None:
            return
        try:
            self._call("close", ())
            self._flush()
            reply = self._reply()
        except RecordingError:
            reply = ("error", "RecordingError", self._failed)
        finally:
            self._end_child()
        if reply[0] == "error":
            self._failed = self._failed or reply[2]
            raise RecordingError(self._failed)

    def __enter__(self) -> "BagProcess":
        return self

    def __exit__(self, exc_type, exc, tb) -> Literal[False]:
        if exc is not None and self._conn is not None:
            self.interrupted(interrupt_reason(exc))
        self.close()
        return False

    def flush_due(self) -> None:
        """Send the queued writes if the oldest has waited :data:`BATCH_WALL` (call it while the node waits: a paused
        run's last writes reach the bag)."""
        if self._batch and time.monotonic() - self._batch_wall >= BATCH_WALL:
            self._flush()

    def __del__(self):  # (the child sees the socket close and closes the bag as interrupted)
        conn = getattr(self, "_conn", None)
        if conn is not None:
            try:
                self._flush()
            except Exception:
                pass
            conn.close()

    # --- the socket
    def _check(self) -> None:
        """Raise the child's failure, if it has sent one."""
        conn = self._conn
        if conn is not None and self._failed is None and conn.poll():
            reply = self._reply()
            if reply[0] == "error":
                self._failed = reply[2]
        if self._failed is not None:
            raise RecordingError(self._failed)

    def _call(self, op: str, args: tuple, kwargs: Optional[dict] = None) -> None:
        self._add(_CALL + pickle.dumps((op, args, kwargs or {}), protocol=pickle.HIGHEST_PROTOCOL))

    def _add(self, item: bytes) -> None:
        """Queue one write; the queue goes to the child once it is big or old enough (:data:`BATCH_BYTES`,
        :data:`BATCH_WALL`)."""
        if self._conn is None:
            raise RuntimeError(f"bag {str(self.path)!r} is closed")
        now = time.monotonic()
        if not self._batch:
            self._batch_wall = now
        self._batch.append(item)
        self._batch_bytes += len(item)
        if self._batch_bytes >= BATCH_BYTES or now - self._batch_wall >= BATCH_WALL:
            self._flush()

    def _flush(self) -> None:
        """Send the queued writes (RecordingError: the child failed, heard of here)."""
        batch, self._batch, self._batch_bytes = self._batch, [], 0
        if not batch:
            return
        self._check()
        assert self._conn is not None
        try:
            self._conn.send_bytes(pickle.dumps(batch, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError:
            self._failed = self._failed or f"bag {str(self.path)!r}: its writer process ended ({self._status()})"
            raise RecordingError(self._failed) from None

    def _reply(self) -> tuple:
        assert self._conn is not None
        try:
            return pickle.loads(self._conn.recv_bytes())
        except (EOFError, OSError):
            self._failed = self._failed or f"bag {str(self.path)!r}: its writer process ended ({self._status()})"
            raise RecordingError(self._failed) from None

    def _status(self) -> str:
        code = self._proc.wait()
        return f"status {code}" if code >= 0 else f"signal {signal_name(-code)}"

    def _end_child(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()
        self._proc.wait()


# --- the child ---------------------------------------------------------------------------------------------------
def _write_rows(rec, data: bytes, names: list) -> None:
    k, euler = len(names), data[:1] == _ROWS_EULER[:1]
    widths = (1, 3, 4, 3, 3, k, k, k) + ((3,) if euler else ())
    m = np.frombuffer(data, dtype=np.float64, offset=len(_ROWS)).reshape(-1, sum(widths))
    cols = np.cumsum((0,) + widths)
    keys = _SAMPLE_KEYS + (("euler",) if euler else ())
    s = dict(zip(keys, (m[:, a:b] for a, b in zip(cols[:-1], cols[1:], strict=True)), strict=True))
    s["t"] = m[:, 0]
    rec.write_samples(s, names)


def _serve(conn: Connection, rec) -> Optional[tuple]:
    """Write what comes until ``close`` (its reply) or the socket closes (the node is gone: None)."""
    state: dict = {"names": [], "failed": None}
    while True:
        try:
            batch = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            if state["failed"] is None:
                rec.interrupted(_LOST)
            return None
        for item in batch:
            if item[:1] == _CALL and pickle.loads(item[1:])[0] == "close":
                if state["failed"] is not None:
                    return ("error", "RecordingError", state["failed"])
                try:
                    rec.close()
                except RecordingError as exc:
                    return ("error", "RecordingError", str(exc))
                return ("closed",)
            if state["failed"] is None and _write(rec, item, state):
                try:
                    conn.send_bytes(pickle.dumps(("error", "RecordingError", state["failed"])))
                except OSError:  # (the node is gone: the next read sees the socket's end; the bag is closed)
                    pass


def _write(rec, item: bytes, state: dict) -> bool:
    """One queued write (``state``: the stators' names, the failure so far); True if it failed (the bag is then
    closed with what fit: writes after a failure are dropped, as the node hears of it)."""
    try:
        if item[:1] != _CALL:
            _write_rows(rec, item, state["names"])
            return False
        op, args, kwargs = pickle.loads(item[1:])
        if op == "names":
            state["names"] = args[0]
        else:
            getattr(rec, op)(*args, **kwargs)
        return False
    except RecordingError as exc:  # (the BagRecorder closed the bag with what fit)
        state["failed"] = str(exc)
    except Exception as exc:
        state["failed"] = f"bag {str(rec.path)!r}: writer error: {type(exc).__name__}: {exc}"
        rec.interrupted(f"writer error: {type(exc).__name__}")
        try:
            rec.close()
        except RecordingError:
            pass
    return True


def main(argv: Optional[Sequence[str]] = None) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    cpus = os.environ.get(WRITER_CPUS_ENV)
    if cpus and hasattr(os, "sched_setaffinity"):
        try:
            os.sched_setaffinity(0, {int(c) for c in cpus.split(",")})
        except (OSError, ValueError):
            pass
    conn = Connection(int((argv or sys.argv[1:])[0]))
    op, args, _ = pickle.loads(pickle.loads(conn.recv_bytes())[0][1:])
    from gyro_sim.io.bag_writer import BagRecorder

    try:
        rec = BagRecorder(*args)
    except Exception as exc:
        conn.send_bytes(pickle.dumps(("error", type(exc).__name__, str(exc))))
        return 2
    try:
        try:
            conn.send_bytes(pickle.dumps(("opened",)))
        except OSError:  # (the node ended before our reply: as at the socket's end, below)
            rec.interrupted(_LOST)
            return 0
        reply = _serve(conn, rec)
    finally:
        if not rec.closed:
            try:
                rec.close()
            except RecordingError:
                pass
    if reply is not None:
        try:
            conn.send_bytes(pickle.dumps(reply))
        except OSError:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
