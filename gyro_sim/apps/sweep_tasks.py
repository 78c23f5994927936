"""How a sweep's variants become Dask tasks: the workers' settings and the size of each task.

A task costs a fixed 1.5–7 ms of scheduling, (de)serialisation and hand-back (docs/sweeps.md), paid by the
client, the scheduler and the worker on the same cores as the runs. One run per task made short runs slower on
Dask than in one process (runs of 12 ms of the default scene: 82 runs/s in-process against 60 on one worker).
``batch="auto"`` (the default of :func:`gyro_sim.sweep.run_sweep` and ``gyro-sim sweep``) sizes each task as it
is sent (:class:`TaskSizer`): enough variants to last :data:`TASK_SECONDS` at the median run time seen so far,
never more than an even share of what is left over the worker threads, so that the workers finish together and
a hard stop loses at most :data:`TASKS_AHEAD` tasks per thread. Runs are independent: how they are grouped
changes no number (``test/test_sweep.py`` checks the results bit for bit).

Inside a worker a run cost a few per cent more CPU than in-process (12.9–14.0 against 12.3–12.7 ms a run of the
default scene over 2 s, on an idle machine): the worker's other threads take the GIL from the run's thread. Two
things remove it: the local cluster's workers run without Dask's statistical profiler (:data:`WORKER_CONFIG`),
which samples the running task's stack every 10 ms from a thread of its own (5–6 % of a core besides the runs,
against 3 % without it), and the compiled kernels a run calls from Python release the GIL (``nogil=True``:
``kernels.integrate``, ``integrate_free``, ``record_sample``, ``frozen_flow.integrate_frozen``), so the event
loop's thread takes it without interrupting the run. What is left of the gap on a busy machine is CPU contention:
the client, the scheduler and every other process share the same cores (docs/sweeps.md).
"""
from __future__ import annotations

import math
import statistics
import sys
from typing import Callable, Optional, Sequence

__all__ = ["TASK_SECONDS", "TASKS_AHEAD", "WORKER_THREADS_ENV", "START_METHOD", "WORKER_CONFIG", "TaskSizer",
           "worker_slots", "failed_rows", "run_fixed", "run_adaptive"]

#: s of runs a task aims at: long against the 1.5–7 ms each task costs, short enough for an even finish
TASK_SECONDS = 0.25
#: tasks kept in flight per worker thread (one running, one queued: no thread waits for the next task)
TASKS_AHEAD = 2
#: the thread pools of a worker process, one thread each: a worker runs one variant at a time on one core, and a
#: pool of threads per worker (numba's threading layer, OpenMP, BLAS) would have the workers fight over the cores
WORKER_THREADS_ENV = {"NUMBA_NUM_THREADS": 1, "OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}
#: how the local cluster starts its worker processes: ``fork`` on Linux, where a worker is then a copy of this
#: process with gyro_sim imported and the kernels the sweep uses loaded (:func:`gyro_sim.apps.sweep_exec.warm_up`):
#: 0.1 s of CPU and 0.4 s to start 2 workers, against 2.0 s of CPU and 4.4 s with ``spawn``, where each worker
#: imports distributed and gyro_sim and loads the kernels anew (0.75 s) — more than 128 runs of the default scene
#: cost. Elsewhere (macOS: fork is unsafe with its system libraries; Windows: no fork) Dask's default, ``spawn``.
START_METHOD = "fork" if sys.platform.startswith("linux") else "spawn"
#: the Dask settings of the local cluster's workers (dask.config keys; the environment is set before the worker
#: process starts, so numba and BLAS read it at import where the worker imports them)
#: (the system monitor, every 0.5 s, and the event loop's tick, every 20 ms, kept an idle cluster of 2 workers at
#: 5 % of a core; every 5 s and 0.5 s, at 2 %: they feed the dashboard, which the local cluster does not have)
WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.system-monitor.interval": "5s", "distributed.admin.tick.interval": "500ms",
                 "distributed.worker.multiprocessing-method": START_METHOD,
                 "distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": 65536, **WORKER_THREADS_ENV}}
#: run times (s) the sizer keeps (the median of the latest)
_KEEP = 256


class TaskSizer:
    """The number of variants the next task gets.

    ``slots``: worker threads; ``task_seconds``: the wall time a task aims at. Until a run time is known every
    task gets one variant; then ``task_seconds`` / the median run time so far (the first runs of a fresh worker,
    which load the kernels, are outliers the median ignores), at most ⌈remaining / (TASKS_AHEAD × slots)⌉."""

    def __init__(self, slots: int, task_seconds: float = TASK_SECONDS, ahead: int = TASKS_AHEAD):
        self.slots = max(1, int(slots))
        self.task_seconds = float(task_seconds)
        self.ahead = max(1, int(ahead))
        self.times: list = []  # s, the latest run times
        self.sizes: list = []  # variants of every task sent (run_adaptive)

    def note(self, rows: Sequence[dict]) -> None:
        """Keep the run times (s, ``wall_time_run``) of a task's rows that ran (status ok)."""
        self.times.extend(float(r["wall_time_run"]) for r in rows
                          if r.get("status") == "ok" and r.get("wall_time_run"))
        del self.times[:-_KEEP]

    def run_seconds(self) -> Optional[float]:
        """The median run time seen so far (s), None before the first."""
        return statistics.median(self.times) if self.times else None

    def next_size(self, remaining: int) -> int:
        """Variants for the next task, out of ``remaining`` not sent yet (0 when none is left)."""
        if remaining <= 0:
            return 0
        share = max(1, math.ceil(remaining / (self.ahead * self.slots)))
        run = self.run_seconds()
        if run is None:
            return 1
        want = max(1, int(self.task_seconds / run)) if run > 0 else share
        return min(want, share, remaining)


def worker_slots(client, worker_addrs: Optional[Sequence[str]] = None) -> int:
    """Worker threads the tasks can run on: those of ``worker_addrs`` (all workers if None)."""
    workers = client.scheduler_info().get("workers", {})
    if worker_addrs:
        workers = {a: w for a, w in workers.items() if a in set(worker_addrs)}
    return max(1, sum(int(w.get("nthreads", 1) or 1) for w in workers.values()))


def failed_rows(chunk: Sequence[tuple], exc: BaseException) -> list:
    """The rows of a task that did not come back (e.g. its worker died: KilledWorker): every variant failed."""
    return [{"run_id": rid, "status": "failed", "error": f"task failed: {type(exc).__name__}: {exc}",
             "metrics": {}, "series": {}, "wall_time_run": 0.0, "worker": ""} for rid, _ in chunk]


def _placement(worker_addrs):
    return {"workers": list(worker_addrs), "allow_other_workers": False} if worker_addrs else {}


def run_fixed(client, fn: Callable, payload, items: list, batch: int, on_rows: Callable,
              worker_addrs: Optional[Sequence[str]] = None) -> None:
    """Run ``fn(payload, chunk)`` for chunks of ``batch`` of ``items``, all sent at once; ``on_rows(rows)`` as each
    task ends (in the order they end)."""
    from distributed import as_completed

    batch = max(1, int(batch))
    chunks = [items[i:i + batch] for i in range(0, len(items), batch)]
    futs = client.map(fn, [payload] * len(chunks), chunks, pure=False, **_placement(worker_addrs))
    index = {f.key: ch for f, ch in zip(futs, chunks)}
    try:
        for fut in as_completed(futs, loop=client.loop):  # (this client's loop: see run_adaptive)
            try:
                rows = fut.result()
            except Exception as e:  # noqa: BLE001 - e.g. a worker that died (KilledWorker)
                rows = failed_rows(index[fut.key], e)
            fut.release()
            on_rows(rows)
    finally:
        for f in futs:
            f.cancel()


def run_adaptive(client, fn: Callable, payload, items: list, on_rows: Callable,
                 worker_addrs: Optional[Sequence[str]] = None, task_seconds: float = TASK_SECONDS,
                 sizer: Optional[TaskSizer] = None) -> TaskSizer:
    """Run ``fn(payload, chunk)`` over ``items`` in tasks sized as they are sent (:class:`TaskSizer`), keeping
    :data:`TASKS_AHEAD` tasks per worker thread in flight; ``on_rows(rows)`` as each task ends. Returns the sizer
    (its run times; ``sizes``: the size of every task sent)."""
    from distributed import as_completed

    sizer = sizer or TaskSizer(worker_slots(client, worker_addrs), task_seconds)
    place = _placement(worker_addrs)
    pending: dict = {}
    # this client's event loop, not the default client's (the latest made in this process): on another client's
    # loop the futures' ends were seen late — 7 runs/s instead of 80 with a second client open
    done = as_completed(loop=client.loop)
    sent = 0

    def send() -> None:
        nonlocal sent
        k = sizer.next_size(len(items) - sent)
        chunk = items[sent:sent + k]
        sent += k
        fut = client.submit(fn, payload, chunk, pure=False, **place)
        pending[fut.key] = (fut, chunk)
        sizer.sizes.append(k)
        done.add(fut)

    try:
        while sent < len(items) and len(pending) < sizer.ahead * sizer.slots:
            send()
        for fut in done:
            _, chunk = pending.pop(fut.key)
            try:
                rows = fut.result()
            except Exception as e:  # noqa: BLE001 - e.g. a worker that died (KilledWorker)
                rows = failed_rows(chunk, e)
            fut.release()
            sizer.note(rows)
            on_rows(rows)
            while sent < len(items) and len(pending) < sizer.ahead * sizer.slots:
                send()
    finally:
        for f, _ in pending.values():
            f.cancel()
    return sizer
