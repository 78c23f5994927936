"""The ``sweep`` part of ``gyro-sim bench`` (issue 32): what a sweep of short runs costs, and how much of it is not
the runs themselves.

The sweep: 128 runs of the default scene (``spinup_thin_shell``) over 2 s as shipped, the spin-up law's current
0.5 … 1.5 A (:func:`sweep_spec`). Each configuration is timed over the same runs, warm (kernels loaded, workers
started), the configurations taking turns for ``repeats`` rounds, the fastest pass of each kept:

* in this process (``run_sweep(workers=0)`` with its journal and Parquet table: everything a sweep does but start);
* a local cluster (``LocalCluster``, 2 worker processes): 1 worker and 2 workers, tasks sized as they go (the
  default ``batch="auto"``);
* a cluster started as separate processes (``dask scheduler`` + ``dask worker --nworkers 2 --nthreads 1`` on
  127.0.0.1, with :data:`gyro_sim.apps.sweep_tasks.WORKER_THREADS_ENV`), reached by ``--scheduler`` as a user
  who outgrows one machine would: 1 and 2 workers;
* two plain processes without Dask, half of the runs each (what 2 cores give with no task overhead);
* the whole command ``gyro-sim sweep ... --workers 0`` and ``--workers 2`` as a new process (start, imports,
  kernel loads, cluster, table).

For each: runs/s, runs/s per core, the CPU of every process taking part (this one — the client, and a local
cluster's scheduler —, the workers, a separate scheduler: :func:`cpu_all`) and the share of it outside the runs
= 1 − Σ CPU inside ``gyro_sim.run`` (``sim_cpu`` of each row, the worker's thread) / that CPU. Then Monte Carlo:
1,000 variants (random current) on 2 workers, one run per task against tasks of many runs (``auto``): the gain of
batching variants per task.
Ratios within one run only: the machine is shared, its load (``/proc/loadavg``) is kept with each figure.
"""
from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

__all__ = ["this_code_env", "sweep_spec", "mc_spec", "cpu_all", "scheduler_processes", "two_processes",
           "sweep_figures", "headline", "markdown"]

#: the configurations timed in turn: label → (cluster: None | "local" | "processes", workers used)
CONFIGS = {"in_process": (None, 0), "local_1": ("local", 1), "local_2": ("local", 2),
           "processes_1": ("processes", 1), "processes_2": ("processes", 2)}
TITLES = {"in_process": "in this process (journal + Parquet)", "local_1": "local cluster, 1 worker",
          "local_2": "local cluster, 2 workers", "processes_1": "dask scheduler + dask worker, 1 worker",
          "processes_2": "dask scheduler + dask worker, 2 workers"}


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "–"


def this_code_env(**extra) -> dict:
    """The environment of a new process that imports this process's ``gyro_sim`` (its source tree first on
    PYTHONPATH: the processes measured run the code measured, whatever is installed)."""
    import gyro_sim

    tree = str(Path(gyro_sim.__file__).resolve().parents[1])
    path = os.environ.get("PYTHONPATH")
    return dict(os.environ, PYTHONPATH=tree + (os.pathsep + path if path else ""), **extra)


def sweep_spec(runs: int, duration: float = 2.0):
    """``runs`` variants of the default scene over ``duration`` s, the spin-up law's current 0.5 … 1.5 A."""
    from gyro_sim.apps.sweep import spec_from_dict

    return spec_from_dict({"scene": "spinup_thin_shell", "set": {"duration": duration},
                           "vary": {"controller.params.current": f"0.5:1.5:{runs}"},
                           "metrics": {"spin": "final(spin)"}}, where="bench")


def mc_spec(samples: int, duration: float = 2.0, seed: int = 0):
    """Monte Carlo: ``samples`` variants of the default scene, the spin-up current drawn uniform in 0.5 … 1.5 A."""
    from gyro_sim.apps.sweep import spec_from_dict

    return spec_from_dict({"scene": "spinup_thin_shell", "set": {"duration": duration},
                           "random": {"controller.params.current": "uniform(0.5, 1.5)"}, "samples": samples,
                           "seed": seed, "metrics": {"spin": "final(spin)"}}, where="bench")


def cpu_all(client=None) -> float:
    """CPU s (user + system) so far of this process and, with a Dask ``client``, of every worker process and of the
    scheduler's process if it is another (each asked for its ``time.process_time``). A local cluster's scheduler
    runs in this process; the nannies, which only watch their workers, are not counted."""
    total = time.process_time()
    if client is not None:
        total += sum(client.run(time.process_time).values())
        if client.run_on_scheduler(os.getpid) != os.getpid():
            total += client.run_on_scheduler(time.process_time)
    return total


def _figures(n: int, wall: float, cpu: float, sim: float, cores: int, tasks: int, failed: int) -> dict:
    return {"runs": n, "wall": wall, "runs_per_s": n / wall, "per_core": n / wall / max(1, cores), "cpu": cpu,
            "sim_cpu": sim, "outside": 1.0 - sim / cpu if cpu > 0 else float("nan"), "tasks": tasks,
            "failed": failed, "load": _load()}


def _dask_pass(payload: dict, items: list, client, batch, addrs) -> dict:
    from gyro_sim.apps.sweep_exec import _timed_rows

    c0 = cpu_all(client)
    wall, rows, tasks = _timed_rows(payload, items, client, batch, worker_addrs=addrs)
    cpu = cpu_all(client) - c0
    return _figures(len(items), wall, cpu, sum(r.get("sim_cpu") or 0.0 for r in rows), len(addrs), tasks,
                    sum(r["status"] != "ok" for r in rows))


def _in_process_pass(spec, folder: str) -> dict:
    from gyro_sim.apps.sweep_exec import run_sweep

    c0, w0 = time.process_time(), time.perf_counter()
    res = run_sweep(spec, out=Path(folder) / "in_process.parquet", workers=0, resume=False, progress=False)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return _figures(res.n_run, wall, cpu, res.sim_cpu, 1, res.n_run, res.n_failed)


def command_pass(runs: int, folder: str, workers: int = 0) -> dict:
    """``gyro-sim sweep spinup_thin_shell --vary controller.params.current=0.5:1.5:RUNS --set duration=2 --workers N
    --quiet --no-plot`` as a new process: wall s, CPU s (the rusage of it and its children: a local cluster's
    processes), runs/s end to end."""
    args = [sys.executable, "-m", "gyro_sim.apps.cli", "sweep", "spinup_thin_shell", "--vary",
            f"controller.params.current=0.5:1.5:{runs}", "--set", "duration=2", "--metric", "spin=final(spin)",
            "--workers", str(workers), "--quiet", "--no-plot", "--no-resume",
            "--out", str(Path(folder) / f"command{workers}.parquet")]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    w0 = time.perf_counter()
    p = subprocess.run(args, capture_output=True, text=True, timeout=900, cwd=folder, env=this_code_env())
    wall = time.perf_counter() - w0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"gyro-sim sweep failed: {p.stderr.strip()[-500:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return {"runs": runs, "workers": workers, "wall": wall, "cpu": cpu, "runs_per_s": runs / wall, "load": _load()}


@contextlib.contextmanager
def scheduler_processes(folder: str, nworkers: int = 2):
    """A ``dask scheduler`` and ``dask worker --nworkers N --nthreads 1`` started as separate processes on
    127.0.0.1 (one thread per pool, Dask's profiler off, its monitor and tick slower, as the local cluster's
    workers); yields the scheduler's
    address. Every process group started here is ended (TERM, then KILL) on the way out."""
    from gyro_sim.apps.sweep_tasks import WORKER_THREADS_ENV

    sched_file = Path(folder) / "scheduler.json"
    env = this_code_env(DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED="False",
                        DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL="5s",
                        DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL="500ms",
                        **{k: str(v) for k, v in WORKER_THREADS_ENV.items()})
    procs: list = []

    def start(args, name):
        with open(Path(folder) / f"{name}.log", "w") as log:
            procs.append(subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=log, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, start_new_session=True, cwd=folder, env=env))

    try:
        start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
               str(sched_file), "--idle-timeout", "600s"], "scheduler")
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            if procs[0].poll() is not None:
                raise RuntimeError((Path(folder) / "scheduler.log").read_text()[-500:])
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        start(["worker", address, "--host", "127.0.0.1", "--nworkers", str(nworkers), "--nthreads", "1",
               "--no-dashboard", "--local-directory", str(Path(folder) / "work"), "--death-timeout", "60"], "workers")
        yield address
    finally:
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=20)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def two_processes(spec, n: int = 2, repeats: int = 1) -> dict:
    """``n`` processes without Dask, each running 1/n of the variants in a loop at once (after its warm-up): wall s
    from the common start to the last end, runs/s (the fastest of ``repeats`` passes). What ``n`` cores give with no
    task overhead at all."""
    items = [(v.run_id, v.values) for v in spec.variants()]
    parts = [items[i::n] for i in range(n)]
    payload = spec.payload()
    code = ("import json, sys, time\nfrom gyro_sim.sweep import run_chunk\n"
            "payload, items = json.loads(sys.stdin.readline())\nitems = [tuple(x) for x in items]\n"
            "run_chunk(payload, items[:1])\nprint('ready', flush=True)\n"
            "while sys.stdin.readline():\n"
            "    t0 = time.time()\n    rows = run_chunk(payload, items)\n"
            "    print(json.dumps({'t0': t0, 't1': time.time(), 'ok': sum(r['status'] == 'ok' for r in rows)}), "
            "flush=True)\n")
    with tempfile.TemporaryDirectory(prefix="gyro_two_") as cwd:
        procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  text=True, cwd=cwd, env=this_code_env()) for _ in parts]
        pipes = [(p.stdin, p.stdout) for p in procs if p.stdin is not None and p.stdout is not None]
        try:
            for (stdin, _), part in zip(pipes, parts, strict=True):
                stdin.write(json.dumps([payload, part]) + "\n")
                stdin.flush()
            for _, stdout in pipes:
                assert stdout.readline().strip() == "ready"
            passes = []
            for _ in range(max(1, int(repeats))):
                for stdin, _ in pipes:  # go
                    stdin.write("\n")
                    stdin.flush()
                ends = [json.loads(stdout.readline()) for _, stdout in pipes]
                wall = max(e["t1"] for e in ends) - min(e["t0"] for e in ends)
                passes.append({"processes": n, "wall": wall, "runs_per_s": len(items) / wall,
                               "ok": sum(e["ok"] for e in ends)})
        finally:
            for p, (stdin, _) in zip(procs, pipes, strict=True):
                stdin.close()
                p.wait(timeout=60)
    return max(passes, key=lambda o: o["runs_per_s"])


def _connect(kind: str, folder: str, stack: contextlib.ExitStack, workers: int):
    """(client, worker addresses sorted) of a warm cluster of ``workers`` workers: local or separate processes."""
    from gyro_sim.apps.sweep_exec import _dask_client

    if kind == "local":
        client, cluster, _, _ = _dask_client(workers, None)
        if cluster is not None:
            stack.callback(cluster.close)
    else:
        address = stack.enter_context(scheduler_processes(folder, workers))
        client, _, _, _ = _dask_client(None, address)
        client.wait_for_workers(workers, timeout=120)
    stack.callback(client.close)
    return client, sorted(client.scheduler_info()["workers"])


def sweep_figures(runs: int = 128, mc: int = 1000, repeats: int = 3, processes: bool = True, say=print) -> dict:
    """Every figure of the part (module docstring): ``runs`` runs timed in each configuration of :data:`CONFIGS`
    (``processes``: with the separate-process cluster), ``repeats`` rounds taking turns, the fastest pass each; two
    plain processes; the whole command; ``mc`` Monte Carlo variants one run per task against ``auto`` on 2 workers
    (0: skipped)."""
    from gyro_sim.apps.sweep_exec import run_chunk

    spec = sweep_spec(runs)
    items = [(v.run_id, v.values) for v in spec.variants()]
    payload = spec.payload()
    out: dict = {"runs": runs, "duration": 2.0, "repeats": repeats, "cores": os.cpu_count(), "load_start": _load()}
    run_chunk(payload, items[:1])  # this process warm (kernels loaded)
    with tempfile.TemporaryDirectory(prefix="gyro_bench_sweep_") as folder:
        _in_process_pass(sweep_spec(2), folder)  # (and pyarrow imported: once per process, not per sweep)
    labels = [k for k, (kind, _) in CONFIGS.items() if kind != "processes" or processes]
    passes: dict = {k: [] for k in labels}
    with tempfile.TemporaryDirectory(prefix="gyro_bench_sweep_") as folder, contextlib.ExitStack() as stack:
        clusters = {}
        t0 = time.perf_counter()
        for kind in ("local", "processes") if processes else ("local",):
            clusters[kind] = _connect(kind, folder, stack, 2)
            clusters[kind][0].run(run_chunk, payload, items[:1])  # every worker warm
        out["cluster_start"] = time.perf_counter() - t0
        two: list = []
        for _ in range(max(1, repeats)):
            for label in labels:
                where, nw = CONFIGS[label]
                if where is None:
                    passes[label].append(_in_process_pass(spec, folder))
                else:
                    client, addrs = clusters[where]
                    passes[label].append(_dask_pass(payload, items, client, "auto", addrs[:nw]))
                say(f"[sweep] {TITLES[label]}: {passes[label][-1]['runs_per_s']:.1f} runs/s "
                    f"(load {passes[label][-1]['load']})")
            two.append(two_processes(spec, 2))
        for label in labels:
            out[label] = max(passes[label], key=lambda o: o["runs_per_s"])
        out["two_processes"] = dict(max(two, key=lambda o: o["runs_per_s"]), load=_load())
        if mc:
            mspec = mc_spec(mc)
            mitems = [(v.run_id, v.values) for v in mspec.variants()]
            client, addrs = clusters["local"]
            mpay = mspec.payload()
            out["mc_one"] = _dask_pass(mpay, mitems, client, 1, addrs)
            out["mc_auto"] = _dask_pass(mpay, mitems, client, "auto", addrs)
            out["mc_gain"] = out["mc_auto"]["runs_per_s"] / out["mc_one"]["runs_per_s"]
        out["command"] = command_pass(runs, folder)
        out["command_2"] = command_pass(runs, folder, workers=2)
    out["ratio_local"] = out["local_2"]["runs_per_s"] / out["local_1"]["runs_per_s"]
    if processes:
        out["ratio_processes"] = out["processes_2"]["runs_per_s"] / out["processes_1"]["runs_per_s"]
    out["load_end"] = _load()
    return out


def lines(out: dict) -> list[str]:
    """The part's printed report."""
    L = [f"{out['runs']} runs of spinup_thin_shell over {out['duration']:g} s on {out['cores']} cores; the fastest of "
         f"{out['repeats']} passes each (load {out['load_start']} → {out['load_end']}); cluster start + warm-up "
         f"{out['cluster_start']:.2f} s (not in the figures)"]
    for label, title in TITLES.items():
        if label in out:
            o = out[label]
            L.append(f"  {title:<42s}{o['runs_per_s']:8.1f} runs/s ({o['per_core']:.1f} per core)  "
                     f"CPU {o['cpu']:.2f} s, in the runs {o['sim_cpu']:.2f} s: outside {o['outside']:.0%}  "
                     f"{o['tasks']} tasks  load {o['load']}")
    L.append(f"  2 workers / 1 worker: local cluster x{out['ratio_local']:.2f}"
             + (f", separate processes x{out['ratio_processes']:.2f}" if "ratio_processes" in out else ""))
    t = out["two_processes"]
    L.append(f"  2 plain processes, half the runs each: {t['runs_per_s']:.1f} runs/s "
             f"(x{t['runs_per_s'] / out['in_process']['runs_per_s']:.2f} of in this process)")
    if "mc_gain" in out:
        a, b = out["mc_one"], out["mc_auto"]
        L.append(f"  Monte Carlo {a['runs']} variants on 2 workers: 1 run per task {a['runs_per_s']:.1f} runs/s "
                 f"(outside {a['outside']:.0%}), auto {b['runs_per_s']:.1f} runs/s in {b['tasks']} tasks "
                 f"(outside {b['outside']:.0%}): batch gain x{out['mc_gain']:.2f}")
    for c in (out["command"], out["command_2"]):
        L.append(f"  the whole command (new process, --workers {c['workers']}): {c['wall']:.2f} s, "
                 f"CPU {c['cpu']:.2f} s, "
                 f"{c['runs_per_s']:.1f} runs/s end to end (load {c['load']})")
    return L


def headline(row: dict) -> str:
    o = row
    return (f"sweep of {o['runs']} runs of {o['duration']:g} s: {o['in_process']['runs_per_s']:.1f} runs/s in one "
            f"process "
            f"({o['in_process']['outside']:.0%} of its CPU outside the runs), {o['local_2']['runs_per_s']:.1f} on 2 "
            f"workers = x{o['ratio_local']:.2f} of 1 worker ({o['local_2']['outside']:.0%} outside)"
            + (f"; Monte Carlo batch gain x{o['mc_gain']:.2f}" if "mc_gain" in o else "")
            + f" (load {o['load_start']} → {o['load_end']})")


def markdown(row: dict) -> list[str]:
    L = [f"## Sweep ({row['runs']} runs of spinup_thin_shell over {row['duration']:g} s, as shipped; the fastest of "
         f"{row['repeats']} passes each)", "",
         "| how | runs/s | runs/s per core | CPU s (all processes) | in the runs | outside | tasks | load |",
         "|---|---|---|---|---|---|---|---|"]
    for label, title in TITLES.items():
        if label in row:
            o = row[label]
            L.append(f"| {title} | {o['runs_per_s']:.1f} | {o['per_core']:.1f} | {o['cpu']:.2f} | {o['sim_cpu']:.2f} | "
                     f"{o['outside']:.0%} | {o['tasks']} | {o['load']} |")
    t = row["two_processes"]
    L.append(f"| 2 plain processes, half each | {t['runs_per_s']:.1f} | {t['runs_per_s'] / 2:.1f} | | | | 2 | "
             f"{t['load']} |")
    if "mc_gain" in row:
        for k, title in (("mc_one", "Monte Carlo, 2 workers, 1 run per task"),
                         ("mc_auto", "Monte Carlo, 2 workers, auto")):
            o = row[k]
            L.append(f"| {title} ({o['runs']} variants) | {o['runs_per_s']:.1f} | {o['per_core']:.1f} | "
                     f"{o['cpu']:.2f} | "
                     f"{o['sim_cpu']:.2f} | {o['outside']:.0%} | {o['tasks']} | {o['load']} |")
    c, c2 = row["command"], row["command_2"]
    L += ["", f"2 workers / 1 worker: x{row['ratio_local']:.2f} (local cluster)"
          + (f", x{row['ratio_processes']:.2f} (dask scheduler + dask worker)" if "ratio_processes" in row else "")
          + (f"; Monte Carlo batch gain (auto over 1 run per task) x{row['mc_gain']:.2f}" if "mc_gain" in row else "")
          + f". The whole command as a new process: `--workers 0` {c['wall']:.2f} s, {c['cpu']:.2f} s CPU, "
          f"{c['runs_per_s']:.1f} runs/s end to end (load {c['load']}); `--workers 2` {c2['wall']:.2f} s, "
          f"{c2['cpu']:.2f} s CPU, {c2['runs_per_s']:.1f} runs/s (load {c2['load']}). Cluster start + warm-up "
          f"{row['cluster_start']:.2f} s, not in the table. Load {row['load_start']} → {row['load_end']}.", ""]
    return L


def sweep_part(res, quick: bool = False, runs: Optional[int] = None, mc: Optional[int] = None, say=print) -> None:
    """Fill ``res.sweep`` with one row of :func:`sweep_figures` (quick: 48 runs, one round, 200 Monte Carlo)."""
    out = sweep_figures(runs or (48 if quick else 128), mc=(200 if quick else 1000) if mc is None else mc,
                        repeats=1 if quick else 3, say=say)
    res.sweep.append(out)
    for line in lines(out):
        say(f"[sweep] {line}")
