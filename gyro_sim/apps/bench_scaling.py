"""The ``startup`` and ``sweep`` parts of ``gyro-sim bench`` (issue 23): what a new process and a sweep of short runs
cost, measured in one run.

* start-up: wall time of new processes (``subprocess``, the interpreter's own start included, numba's cache warm:
  each is run once untimed first): ``python -c pass``, ``import gyro_sim``,
  ``from gyro_sim.engine.simulate import run``,
  the first run of the default scene and ``gyro-sim --help``; for the first run also, inside the process, the
  import, the first run and a second one (first − second = what a first run pays besides its integration: numba's
  set-up and the kernels' cache). With ``baseline`` (a source tree of the code before, e.g. ``git archive`` of a
  commit) the same processes run that code (``PYTHONPATH``, from a folder of their own) interleaved with this
  one's, so before and after meet the same load.
* sweep: :mod:`gyro_sim.apps.bench_sweep` (issue 32): runs/s of a sweep of short runs in this process, on 1 and 2
  workers of a local cluster and of a cluster started as separate processes, the share of the CPU of every process
  outside the runs, the whole command, and the gain of batching 1,000 Monte Carlo variants per task; beside them
  :func:`gyro_sim.apps.bench_sweep.two_processes`, each running half of the runs at once without Dask (the most 2
  cores give).

Ratios within one run only: the machine is shared, its load (``/proc/loadavg``) is recorded before and after each
part.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

__all__ = ["STARTUP_CASES", "startup_times", "startup_part", "sweep_part",
           "headline", "markdown"]

#: the first run's process: says when its first run is done (the parent's clock stops there), then the import, first
#: run, second run (s) and numba's compile time (s) as one JSON line
_FIRST_RUN = """
import json, time
t0 = time.perf_counter()
from gyro_sim.scenes.scene import load_scene
from gyro_sim.engine.simulate import run
t1 = time.perf_counter()
sc = load_scene("spinup_thin_shell")
r = run(sc, duration={duration!r})
t2 = time.perf_counter()
print("first run done", flush=True)
run(sc, duration={duration!r})
t3 = time.perf_counter()
print(json.dumps({{"import": t1 - t0, "first": t2 - t1, "again": t3 - t2, "compile": r.compile_time}}))
"""

#: (label, python arguments) of each start-up case; {duration} is the first run's simulated time
STARTUP_CASES = (
    ("python alone", ["-c", "pass"]),
    ("import gyro_sim", ["-c", "import gyro_sim"]),
    ("from gyro_sim.engine.simulate import run", ["-c", "from gyro_sim.engine.simulate import run"]),
    ("first run of spinup_thin_shell", ["-c", _FIRST_RUN]),
    ("gyro-sim --help", ["-m", "gyro_sim.apps.cli", "--help"]),
)


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "–"


def _case_args(args: list, duration: float) -> list:
    return [a.format(duration=duration) if a is _FIRST_RUN else a for a in args]


def _process(args: list, env: dict, cwd: str) -> tuple[float, str]:
    """(wall s, stdout) of ``python ARGS`` as a new process: from its start to its end, or to its line
    ``first run done``."""
    with tempfile.TemporaryFile("w+") as err:  # (a file, not a pipe: stderr never blocks the process)
        w0 = time.perf_counter()
        p = subprocess.Popen([sys.executable, *args], env=env, cwd=cwd, stdout=subprocess.PIPE, stderr=err, text=True)
        wall, lines = None, []
        for line in p.stdout:
            if wall is None and line.startswith("first run done"):
                wall = time.perf_counter() - w0
            lines.append(line)
        rc = p.wait(timeout=900)
        wall = time.perf_counter() - w0 if wall is None else wall
        if rc != 0:
            err.seek(0)
            raise RuntimeError(f"python {' '.join(args)[:60]}... failed: {err.read().strip()[-500:]}")
    return wall, "".join(lines)


def startup_times(trees: dict, repeats: int = 5, duration: float = 60.0) -> list[dict]:
    """Start-up rows for each of ``trees`` (label → a source tree put first on PYTHONPATH, or None: the installed
    package), every case of :data:`STARTUP_CASES` run once untimed then ``repeats`` times, the trees interleaved.
    Each row: tree, case, min and median wall s, and for the first run the in-process import / first / again s."""
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="gyro_startup_") as cwd:  # (not a repo checkout: '' on sys.path)
        envs = {}
        for label, tree in trees.items():
            env = dict(os.environ)
            env.pop("PYTHONPATH", None)
            if tree is not None:
                env["PYTHONPATH"] = str(Path(tree).resolve())
            envs[label] = env
        for case, args in STARTUP_CASES:
            for label in trees:  # warm: numba's cache filled where it was not, the OS's file cache
                _process(_case_args(args, duration), envs[label], cwd)
            for _ in range(repeats):
                for label in trees:
                    wall, stdout = _process(_case_args(args, duration), envs[label], cwd)
                    row = out.setdefault((label, case), {"tree": label, "case": case, "walls": [], "inside": []})
                    row["walls"].append(wall)
                    if args[1] is _FIRST_RUN:
                        row["inside"].append(json.loads(stdout.strip().splitlines()[-1]))
    rows = []
    for row in out.values():
        w = row.pop("walls")
        row.update(min=min(w), median=statistics.median(w), repeats=len(w))
        inside = row.pop("inside")
        if inside:
            best = min(inside, key=lambda d: d["import"] + d["first"])
            row.update(import_s=best["import"], first_s=best["first"], again_s=best["again"],
                       compile_s=max(d["compile"] for d in inside), duration=duration)
        rows.append(row)
    return rows


def startup_part(res, quick: bool = False, baseline: Optional[str] = None, say=print) -> None:
    """Fill ``res.startup``: this code (and ``baseline``'s, if given) as new processes (:func:`startup_times`); the
    first run of the default scene over 2 s in quick mode, its whole 60 s otherwise."""
    trees = {"this code": None}
    if baseline:
        trees = {"before": baseline, "this code": None}
    load0 = _load()
    rows = startup_times(trees, repeats=3 if quick else 7, duration=2.0 if quick else 60.0)
    for r in rows:
        r["load"] = f"{load0} → {_load()}"
        extra = (f"; inside: import {r['import_s']:.3f} s, first run {r['first_s']:.3f} s, again {r['again_s']:.3f} s"
                 if "first_s" in r else "")
        say(f"[startup] {r['tree']}: {r['case']}: {r['min']:.3f} s (median {r['median']:.3f} s){extra}")
    res.startup.extend(rows)


# ------------------------------------------------------------------------------------------
# sweep scaling
# ------------------------------------------------------------------------------------------
def sweep_part(res, quick: bool = False, runs: Optional[int] = None, mc: Optional[int] = None, say=print) -> None:
    """Fill ``res.sweep``: :func:`gyro_sim.apps.bench_sweep.sweep_part` (issue 32's figures)."""
    from gyro_sim.apps import bench_sweep

    bench_sweep.sweep_part(res, quick, runs=runs, mc=mc, say=say)


# ------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------
def headline(res) -> list[str]:
    """The two parts' sentences for the headline."""
    from gyro_sim.apps import bench_sweep

    out = []
    by = {(r["tree"], r["case"]): r for r in res.startup}
    for case, _ in STARTUP_CASES[1:]:
        now, before = by.get(("this code", case)), by.get(("before", case))
        if now:
            out.append(f"start-up, `{case}` as a new process: {now['min']:.3f} s"
                       + (f" (before: {before['min']:.3f} s, {before['min'] / now['min']:.2f}x)" if before else ""))
    out += [bench_sweep.headline(row) for row in res.sweep]
    return out


def markdown(res) -> list[str]:
    """The two parts' sections of bench.md."""
    from gyro_sim.apps import bench_sweep

    L: list = []
    if res.startup:
        L += ["## Start-up of a process (new processes, numba's cache warm; s wall)", "",
              "| code | what | min | median | repeats | inside the process | load (1, 5, 15 min) |", "|---|---|---|---|---|---|---|"]
        for r in res.startup:
            inside = (f"import {r['import_s']:.3f}, first run ({r['duration']:g} s) {r['first_s']:.3f}, "
                      f"again {r['again_s']:.3f}; compile {r['compile_s']:.2f}" if "first_s" in r else "")
            L.append(f"| {r['tree']} | `{r['case']}` | {r['min']:.3f} | {r['median']:.3f} | {r['repeats']} | "
                     f"{inside} | {r['load']} |")
        L += ["", "Process wall time from the parent, from its start (the interpreter's included) to its end, or for "
              "the first run to the end of that run (the second run is timed inside only). first − again: what a "
              "first run pays besides its integration (numba's set-up, the kernels' cache).", ""]
    for row in res.sweep:
        L += bench_sweep.markdown(row)
    return L
