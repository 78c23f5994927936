"""Running a sweep (:mod:`gyro_sim.apps.sweep`): one task's chunk of variants (:func:`run_chunk`, what Dask
workers run), the Dask client, the driver (:func:`run_sweep`) and the timing of the execution (:func:`measure`).
dask.distributed and tqdm are imported only where used.
"""
from __future__ import annotations

import logging
import math
import os
import socket
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import numpy as np

from gyro_sim import __version__
from gyro_sim.apps.sweep_axes import SweepError
from gyro_sim.apps.sweep_io import (Journal, _flat_row, _journal_path, _read_journal, _row_from_flat, read_results,
                                  write_results)
from gyro_sim.apps.sweep_metrics import _quantity, parse_metric
from gyro_sim.apps.sweep_spec import SweepSpec, _scene_for
from gyro_sim.scenes.scene import SceneError


# ------------------------------------------------------------------------------------------
# one task: run a chunk of variants (in a Dask worker or in this process)
# ------------------------------------------------------------------------------------------
def _run_scene(scene):
    """The integrator (``gyro_sim.run``); one place so tests can stand in for it."""
    from gyro_sim.engine.simulate import run

    return run(scene)


def _worker_label() -> str:
    try:
        from distributed import get_worker

        return f"{get_worker().address}/pid{os.getpid()}"
    except Exception:  # not in a Dask worker (or no distributed)
        return f"{socket.gethostname()}/pid{os.getpid()}"


def _decimate(y: np.ndarray, n: int) -> list:
    if y.size <= n:
        return [float(v) for v in y]
    idx = np.unique(np.linspace(0, y.size - 1, n).round().astype(int))
    return [float(v) for v in y[idx]]


def run_chunk(payload: dict, items: Sequence[tuple]) -> list:
    """Run the variants ``items`` = [(run_id, values), ...] of a sweep ``payload`` (SweepSpec.payload)
    one after the other; returns one row per item: run_id, status ('ok' | 'invalid' | 'failed'),
    error, metrics {name: float}, series {quantity: [..]}, wall_time_run (s), cpu_time_run (s of this
    thread's CPU), sim_cpu (s of this thread's CPU in the run itself, ``gyro_sim.run``), worker. Never raises for a
    bad variant or a failed run: the reason goes in ``error``. Each variant's scene is built (and validated) once,
    here; the run is reduced to the requested metrics (and series) here: the row is all that leaves the worker."""
    return list(chunk_rows(payload, items))


def chunk_rows(payload: dict, items: Sequence[tuple]):
    """:func:`run_chunk`'s rows one at a time, as each run ends (the metrics parsed, the worker named once)."""
    metrics = [parse_metric(m) for m in payload["metrics"]]
    series = payload.get("series") or []
    npts = int(payload.get("series_points", 1000))
    label = _worker_label()
    for run_id, values in items:
        w0, c0 = time.perf_counter(), time.thread_time()
        row = {"run_id": run_id, "status": "ok", "error": None, "metrics": {}, "series": {}, "worker": label}
        try:
            scene = _scene_for(payload["scene"], payload.get("set") or {}, values, payload.get("where", ""),
                               payload.get("name", "scene"))
        except SceneError as e:
            row.update(status="invalid", error=str(e), wall_time_run=time.perf_counter() - w0,
                       cpu_time_run=time.thread_time() - c0, sim_cpu=0.0)
            yield row
            continue
        s0 = time.thread_time()
        try:
            res = _run_scene(scene) if any(m.needs_run for m in metrics) or series else None
            row["sim_cpu"] = time.thread_time() - s0
            if res is not None:
                # (q is NaN by design in a run without attitude: output.attitude false, isotropic rotor)
                finite = np.isfinite(res.L).all(axis=1) & (np.isfinite(res.q).all(axis=1) | (not res.attitude))
                if not finite.all():
                    i = int(np.argmin(finite))
                    raise FloatingPointError(f"non-finite state (L or attitude) at t = {res.t[i]:.6g} s")
            vals = {}
            for m in metrics:
                try:
                    vals[m.name] = m.evaluate(res, scene)
                except Exception as e:  # noqa: BLE001 - reported, never raised
                    raise RuntimeError(f"metric {m.name}: {type(e).__name__}: {e}") from None
            row["metrics"] = vals
            if series and res is not None:
                row["series"] = {"t": _decimate(res.t, npts), **{q: _decimate(_quantity(res, q), npts) for q in series}}
        except Exception as e:  # noqa: BLE001 - a failed run is a result
            msg = str(e) if isinstance(e, (FloatingPointError, RuntimeError)) and str(e) else f"{type(e).__name__}: {e}"
            row.update(status="failed", error=msg, metrics={}, series={}, sim_cpu=time.thread_time() - s0)
        row["wall_time_run"] = time.perf_counter() - w0
        row["cpu_time_run"] = time.thread_time() - c0  # (this thread's CPU s: measure() compares it, not stored)
        yield row


def _noop(x):
    return x


# ------------------------------------------------------------------------------------------
# the driver
# ------------------------------------------------------------------------------------------
@dataclass
class SweepResult:
    spec: SweepSpec
    rows: list  # flat rows (table columns), by variant index
    n_total: int = 0
    n_run: int = 0  # run now
    sim_cpu: float = 0.0  # s of CPU in the runs themselves (gyro_sim.run, in whichever process ran them), run now
    n_skipped: int = 0  # already in the results file
    n_invalid: int = 0
    n_failed: int = 0  # failed runs (all, this time or before)
    wall: float = 0.0  # s, executing the runs (cluster start excluded)
    startup: float = 0.0  # s, starting / connecting to the cluster
    workers: int = 0
    tasks: int = 0  # tasks sent (runs in this process: one per run)
    mode: str = ""
    interrupted: bool = False
    out: Optional[Path] = None

    @property
    def runs_per_second(self) -> float:
        return self.n_run / self.wall if self.wall > 0 else math.nan


#: the progress bar's line (tqdm): runs done of all, failures, runs/s and the time left
PROGRESS_FORMAT = ("{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} runs{postfix} "
                   "[{elapsed}, {rate_fmt}, ETA {remaining}]")


class _Progress:
    """Runs done / failed, runs/s and the time left (tqdm on stderr, :data:`PROGRESS_FORMAT`); ``stream``: another
    file (tests)."""

    def __init__(self, total: int, initial: int, name: str, enabled: bool, stream=None):
        self.failed = 0
        self.bar = None
        if enabled and total > initial:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - the sweep extra brings it
                return
            stream = stream or sys.stderr
            tty = hasattr(stream, "isatty") and stream.isatty()
            self.bar = tqdm(total=total, initial=initial, desc=f"sweep {name}", unit=" runs", file=stream,
                            mininterval=0.2 if tty else 5.0, dynamic_ncols=True, leave=True,
                            bar_format=PROGRESS_FORMAT, postfix="")

    def update(self, rows: Sequence[dict]) -> None:
        """Count a batch of finished rows (one refresh for all of them)."""
        self.failed += sum(1 for r in rows if r["status"] != "ok")
        if self.bar is not None and rows:
            self.bar.set_postfix_str(f", {self.failed} failed" if self.failed else "", refresh=False)
            self.bar.update(len(rows))

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


#: s of simulated time of :func:`warm_up`'s run (0.02 s left a first full run of the default scene 3x slower: not
#: every kernel is called in its first steps)
WARM_SECONDS = 0.1


def warm_up(payload: dict, items: Sequence[tuple]) -> None:
    """Load in this process the compiled kernels the sweep's runs and metrics use: the first variant's row computed
    over :data:`WARM_SECONDS` of simulated time (or less, if it is shorter), then dropped. Before a local cluster
    starts its workers by ``fork`` (:data:`gyro_sim.apps.sweep_tasks.START_METHOD`) they all inherit them instead of
    loading them each. Never raises for a bad variant: one that does not validate or fails here fails where it runs,
    with its message."""
    if not items:
        return
    run_id, values = items[0]
    try:
        scene = _scene_for(payload["scene"], payload.get("set") or {}, values, payload.get("where", ""),
                           payload.get("name", "scene"))
        short = {**values, "duration": min(float(scene.duration), WARM_SECONDS)}
    except Exception:  # noqa: BLE001 - best effort: the workers then load the kernels themselves
        return
    run_chunk(payload, [(run_id, short)])


def _dask_client(workers: Optional[int], scheduler: Optional[str], warm: Optional[Callable] = None):
    """(client, cluster or None, n_workers, mode). ``warm()``: called in this process before a local cluster's workers
    start (with ``fork`` they inherit what it loaded; see :func:`warm_up`)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("running on Dask needs the sweep extra: pip install 'gyro_sim[sweep]' "
                         "(or --workers 0 to run in this process)") from None
    logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler:
        kw = {"scheduler_file": scheduler} if Path(scheduler).is_file() else {"address": scheduler}
        try:
            client = Client(timeout="20s", **kw)
        except Exception as e:  # noqa: BLE001
            raise SweepError(f"cannot connect to the Dask scheduler {scheduler}: {e}") from None
        n = len(client.scheduler_info().get("workers", {}))
        if n == 0:
            try:
                client.wait_for_workers(1, timeout=20)
            except Exception:  # noqa: BLE001
                client.close()
                raise SweepError(f"the Dask scheduler {scheduler} has no workers") from None
            n = len(client.scheduler_info().get("workers", {}))
        return client, None, n, f"scheduler {client.scheduler.address}"
    import dask

    from gyro_sim.apps.sweep_tasks import WORKER_CONFIG

    n = int(workers) if workers else (os.cpu_count() or 1)
    if warm is not None and WORKER_CONFIG["distributed.worker.multiprocessing-method"] == "fork":
        warm()
    with warnings.catch_warnings(), dask.config.set(WORKER_CONFIG):  # (the nannies pass it to their workers)
        # the scheduler's health endpoint moves off 8787 if that is taken
        warnings.filterwarnings("ignore", message=r"Port \d+ is already in use")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    return client, cluster, n, f"local cluster ({n} worker process{'es' if n != 1 else ''})"


def _batch_arg(text) -> Any:
    """``--batch``: ``"auto"`` or a whole number ≥ 1 (SweepError otherwise)."""
    if str(text).strip().lower() == "auto":
        return "auto"
    try:
        n = int(text)
    except (TypeError, ValueError):
        n = 0
    if n < 1:
        raise SweepError(f"--batch {text}: must be a whole number ≥ 1 or auto")
    return n


def _execute(payload: dict, items: list, client, batch, on_rows: Callable, worker_addrs=None):
    """Run ``items`` ([(run_id, values)]) on the client (in this process if None, one variant after the other):
    ``batch`` variants per task, or tasks sized as they are sent (``"auto"``, :func:`gyro_sim.sweep_tasks.
    run_adaptive`; returns its sizer)."""
    if client is None:
        for row in chunk_rows(payload, items):
            on_rows([row])
        return None
    from gyro_sim.apps.sweep_tasks import run_adaptive, run_fixed

    pl = client.scatter([payload], broadcast=True, hash=False)[0]  # once per worker, not once per task
    if batch == "auto":
        return run_adaptive(client, run_chunk, pl, items, on_rows, worker_addrs=worker_addrs)
    run_fixed(client, run_chunk, pl, items, int(batch), on_rows, worker_addrs=worker_addrs)
    return None


def run_sweep(spec: SweepSpec, out: Optional[str | Path] = None, workers: Optional[int] = None,
              scheduler: Optional[str] = None, batch="auto", resume: bool = True, retry_failed: bool = False,
              progress: bool = True) -> SweepResult:
    """Run every variant of ``spec`` as Dask tasks (``workers`` = 0: in this process), each validated where it runs
    (an invalid one is a row of status ``invalid``), skipping the runs ``out`` already holds. Writes ``out`` (Parquet)
    if given, its journal in batches as the runs end (:class:`gyro_sim.apps.sweep_io.Journal`). ``batch``: variants
    per task, or ``"auto"``: each task sized as it is sent (:mod:`gyro_sim.sweep_tasks`); the results do not
    depend on it. A local cluster's workers start from this process after :func:`warm_up` (``fork``, on Linux)."""
    t_start = time.perf_counter()
    from gyro_sim.common.extras import MissingExtra

    try:  # (before any run: without pyarrow the results could not be written after the last one)
        _require_extras(out is not None, workers == 0 and not scheduler, "run_sweep")
    except MissingExtra as e:
        raise SweepError(str(e)) from None
    variants = spec.variants()
    by_id = {v.run_id: v for v in variants}
    out = Path(out) if out is not None else None
    done: dict = {}
    if out is not None and resume:
        if out.is_file():
            old, _ = read_results(out)
            for flat in old:
                if flat.get("run_id") in by_id:
                    done[flat["run_id"]] = _row_from_flat(spec, flat)
        for r in _read_journal(_journal_path(out)):
            if r.get("run_id") in by_id:
                done[r["run_id"]] = r
        # (invalid variants are validated again: a changed scene loader may accept them)
        done = {k: r for k, r in done.items() if r["status"] == "ok" or (r["status"] == "failed" and not retry_failed)}
    elif out is not None:
        _journal_path(out).unlink(missing_ok=True)
    results: dict = dict(done)
    # each variant's scene is built (and validated) once, where it runs (run_chunk): an invalid one comes back as a
    # row of status "invalid" with the loader's message, before any integration of its own
    todo = [v for v in variants if v.run_id not in done]
    res = SweepResult(spec, [], n_total=len(variants), n_skipped=len(done), out=out)
    bar = _Progress(len(variants), len(variants) - len(todo), spec.name, progress)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
    journal = Journal(_journal_path(out)) if out is not None and todo else None

    def on_rows(rows):
        for r in rows:
            r["gyro_sim_version"] = __version__
            results[r["run_id"]] = r
        if journal is not None:
            journal.add(rows)
        res.n_run += sum(1 for r in rows if r["status"] != "invalid")
        res.sim_cpu += sum(r.get("sim_cpu") or 0.0 for r in rows)
        bar.update(rows)

    client = cluster = None
    try:
        if todo:
            payload = spec.payload()
            items = [(v.run_id, v.values) for v in todo]
            if workers == 0 and not scheduler:
                res.mode, res.workers = "in-process", 1
                res.startup = 0.0
            else:
                t0 = time.perf_counter()
                client, cluster, res.workers, res.mode = _dask_client(workers, scheduler,
                                                                      warm=lambda: warm_up(payload, items))
                res.startup = time.perf_counter() - t0
            t0 = time.perf_counter()
            sizer = _execute(payload, items, client, batch, on_rows)
            res.wall = time.perf_counter() - t0
            res.tasks = (len(sizer.sizes) if sizer is not None else
                         len(items) if client is None else math.ceil(len(items) / int(batch)))
    except KeyboardInterrupt:
        res.interrupted = True
        res.wall = time.perf_counter() - t_start
    finally:
        bar.close()
        if journal is not None:
            journal.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    res.rows = [_flat_row(spec, v, results[v.run_id]) for v in variants if v.run_id in results]
    res.n_failed = sum(1 for r in res.rows if r["status"] == "failed")
    res.n_invalid = sum(1 for r in res.rows if r["status"] == "invalid")
    if out is not None:
        meta = dict(spec.meta(), complete=not res.interrupted and len(res.rows) == len(variants),
                    created=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        write_results(out, res.rows, meta)
        _journal_path(out).unlink(missing_ok=True)
    return res


# ------------------------------------------------------------------------------------------
# measuring the execution (runs/s, scaling, overhead per task, batched path)
# ------------------------------------------------------------------------------------------
#: the Dask configurations :func:`measure` can time: label → (workers: "one" | "all", variants per task or "auto")
MEASURE_CONFIGS = {"one_worker": ("one", 1), "all_workers": ("all", 1), "batched": ("all", None),
                   "one_worker_auto": ("one", "auto"), "all_workers_auto": ("all", "auto")}


def _timed_rows(payload: dict, items: list, client, batch, worker_addrs=None) -> tuple:
    """(wall s, rows, tasks) of one pass over ``items``."""
    rows: list = []
    t0 = time.perf_counter()
    sizer = _execute(payload, items, client, batch, rows.extend, worker_addrs=worker_addrs)
    wall = time.perf_counter() - t0
    tasks = len(items) if client is None else (len(sizer.sizes) if sizer is not None
                                               else math.ceil(len(items) / int(batch)))
    return wall, rows, tasks


def _pass_figures(n: int, wall: float, rows: list, tasks: int, workers: int) -> dict:
    """runs/s, the mean cost of a run (wall and this thread's CPU, s) and the overhead per task of one pass."""
    run_sum = sum(r["wall_time_run"] for r in rows)
    o = {"wall": wall, "runs_per_s": n / wall, "tasks": tasks, "run_sum": run_sum,
         "cpu_sum": sum(r.get("cpu_time_run", 0.0) for r in rows), "failed": sum(1 for r in rows if r["status"] != "ok"),
         "workers": workers}
    o["run_wall"], o["run_cpu"] = o["run_sum"] / n, o["cpu_sum"] / n
    o["overhead_per_task"] = (workers * wall - run_sum) / tasks
    return o


def measure(spec: SweepSpec, workers: Optional[int] = None, batch: Optional[int] = None,
            noop_tasks: int = 400, scheduler: Optional[str] = None, stream=None,
            configs: Sequence[str] = tuple(MEASURE_CONFIGS), repeats: int = 1,
            each_round: Optional[Callable] = None) -> dict:
    """Time the sweep's runs in this process and on Dask, and the bare task overhead; returns (and prints) the
    figures.

    In this process one after the other (no Dask), before the cluster starts and again after it is closed
    (``serial``: their mean; a drifting load shows as their difference); then each of ``configs``
    (:data:`MEASURE_CONFIGS`): 1 worker or all workers, one task per run, ``batch`` runs per task (``batched``;
    default: an even split, 4 tasks per worker) or tasks sized as they are sent (``*_auto``, the default of
    ``run_sweep``). Workers are warmed first (simulator imported, kernels loaded); cluster start is reported
    apart. For each: runs/s, the speed-up over this process, the mean cost of a run inside the worker (wall and
    CPU of its thread, ``run_wall``, ``run_cpu``) against in-process, and the overhead per task = (workers × wall −
    Σ run time in the workers) / tasks; then the round trip of ``noop_tasks`` empty tasks (0: skipped). ``repeats``:
    passes of each, the configurations taking turns, the fastest kept (the one a busy machine disturbed least);
    ``each_round()``, if given, is called after each round's passes (the cluster idle) and its returns are kept in
    ``out["rounds"]`` (e.g. another measurement that should meet the same load)."""
    stream = stream or sys.stdout
    items = []
    for v in spec.variants():
        try:
            spec.scene_for(v.values)
            items.append((v.run_id, v.values))
        except SceneError:
            pass
    if not items:
        raise SweepError("no valid variant to measure")
    unknown = [c for c in configs if c not in MEASURE_CONFIGS]
    if unknown:
        raise SweepError(f"measure: unknown configuration(s) {unknown}; allowed: {', '.join(MEASURE_CONFIGS)}")
    n = len(items)
    payload = spec.payload()
    out: dict = {"runs": n, "repeats": max(1, int(repeats))}
    run_chunk(payload, items[:1])  # warm-up: imports, compiled kernels, first-call costs
    rounds = max(1, int(repeats))

    def one_pass(client, bb, ws=None, workers_=1):
        return _pass_figures(n, *_timed_rows(payload, items, client, bb, worker_addrs=ws), workers=workers_)

    def fastest(passes):
        return max(passes, key=lambda o: o["runs_per_s"])

    before = fastest([one_pass(None, 1) for _ in range(rounds)])
    t0 = time.perf_counter()
    client, cluster, nw, mode = _dask_client(workers, scheduler)
    out["mode"], out["workers"] = mode, nw
    b = batch or max(1, math.ceil(n / (4 * nw)))
    out["batch"] = b
    try:
        client.run(run_chunk, payload, items[:1])  # the same warm-up in every worker
        out["startup"] = time.perf_counter() - t0
        addrs = sorted(client.scheduler_info()["workers"])
        passes: dict = {label: [] for label in configs}
        out["rounds"] = []
        for _ in range(rounds):  # (the configurations in turn: a load that changes meets them all)
            for label in configs:
                which, bb = MEASURE_CONFIGS[label]
                ws = addrs[:1] if which == "one" else None
                passes[label].append(one_pass(client, bb or b, ws, 1 if ws else nw))
            if each_round is not None:
                out["rounds"].append(each_round())
        for label in configs:
            out[label] = fastest(passes[label])
        if noop_tasks:
            t0 = time.perf_counter()
            futs = client.map(_noop, range(noop_tasks), pure=False)
            client.gather(futs)
            out["noop_per_task"] = (time.perf_counter() - t0) / noop_tasks
            del futs
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    after = fastest([one_pass(None, 1) for _ in range(rounds)])
    out["serial_before"], out["serial_after"] = before, after
    out["serial"] = serial = {k: (before[k] + after[k]) / 2 for k in ("wall", "run_wall", "run_cpu")}
    serial["runs_per_s"] = n / serial["wall"]
    out["serial_wall"], out["serial_run_sum"] = serial["wall"], serial["run_wall"] * n
    out["serial_runs_per_s"] = serial["runs_per_s"]
    for label in configs:
        o = out[label]
        o["speedup"] = o["runs_per_s"] / serial["runs_per_s"]  # over this process
        o["run_wall_ratio"] = o["run_wall"] / serial["run_wall"]  # a run's cost in a worker / in-process
        o["run_cpu_ratio"] = o["run_cpu"] / serial["run_cpu"] if serial["run_cpu"] > 0 else math.nan
    if "one_worker" in out and "all_workers" in out:
        out["scaling_efficiency"] = out["all_workers"]["runs_per_s"] / (nw * out["one_worker"]["runs_per_s"])
    if "all_workers" in out and "batched" in out:
        out["batched_speedup"] = out["batched"]["runs_per_s"] / out["all_workers"]["runs_per_s"]
    stream.write("\n".join(measure_lines(out, spec.name)) + "\n")
    return out


def measure_lines(out: dict, name: str = "") -> list:
    """The printed report of :func:`measure`."""
    n, nw, serial = out["runs"], out["workers"], out["serial"]
    titles = {"one_worker": "Dask, 1 worker, 1 run per task", "all_workers": f"Dask, {nw} workers, 1 run per task",
              "batched": f"Dask, {nw} workers, {out['batch']} runs per task",
              "one_worker_auto": "Dask, 1 worker, auto batch", "all_workers_auto": f"Dask, {nw} workers, auto batch"}
    lines = [
        f"measured on {os.cpu_count()} cores, {out['mode']}: {n} runs of sweep {name} "
        f"(mean run {serial['run_wall'] * 1e3:.2f} ms in-process)"
        + (f"; the fastest of {out['repeats']} passes each" if out.get("repeats", 1) > 1 else ""),
        f"  cluster start + connect + warm-up {out['startup']:9.2f} s (not in the figures below)",
        f"  {'in-process, serial (no Dask)':<34s}{serial['runs_per_s']:9.2f} runs/s  {serial['wall']:7.2f} s  "
        f"(before the cluster {out['serial_before']['runs_per_s']:.2f}, after {out['serial_after']['runs_per_s']:.2f}); "
        f"a run {serial['run_wall'] * 1e3:.2f} ms wall, {serial['run_cpu'] * 1e3:.2f} ms CPU",
    ]
    for label, title in titles.items():
        if label not in out:
            continue
        o = out[label]
        extra = ""
        if label == "all_workers" and "scaling_efficiency" in out:
            extra = f"  efficiency {out['scaling_efficiency']:.2f}"
        if label == "batched" and "batched_speedup" in out:
            extra = f"  batched speed-up {out['batched_speedup']:.2f}x"
        lines.append(f"  {title:<34s}{o['runs_per_s']:9.2f} runs/s  {o['wall']:7.2f} s  {o['tasks']:5d} tasks  "
                     f"x{o['speedup']:.2f} of in-process  a run {o['run_wall'] * 1e3:.2f} ms wall "
                     f"({o['run_wall_ratio']:.2f}x), {o['run_cpu'] * 1e3:.2f} ms CPU ({o['run_cpu_ratio']:.2f}x)  "
                     f"overhead {o['overhead_per_task'] * 1e3:.2f} ms/task{extra}")
    if "noop_per_task" in out:
        lines.append(f"  empty task round trip             {out['noop_per_task'] * 1e3:9.2f} ms/task")
    lines.append("  (a run's cost: mean over the runs, inside the worker, against in-process; "
                 "overhead per task = (workers x wall - run time in the workers) / tasks)")
    return lines


def _require_extras(parquet: bool, in_process: bool, what: str = "gyro-sim sweep") -> None:
    """Raise :class:`gyro_sim.extras.MissingExtra` (one line naming the ``sweep`` extra) if what a sweep will
    use is not installed: pyarrow where results are read or written (``parquet``), Dask unless it runs
    ``in_process`` (``--workers 0``). Checked before any variant runs (a missing pyarrow would otherwise end
    the sweep after its last run); tqdm is optional (no progress bar without it)."""
    from gyro_sim.common.extras import missing, require

    modules = ("pyarrow",) * parquet + ("dask", "distributed") * (not in_process)
    gone = set(missing("sweep", modules))
    # --workers 0 is a way round a missing Dask only: it writes the same Parquet table (pyarrow)
    hint = "; or --workers 0 to run in this process" if not in_process and {"dask", "distributed"} & gone \
        and "pyarrow" not in gone else ""
    require("sweep", what, modules, hint=hint)
