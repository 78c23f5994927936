"""The ``ros`` part of ``gyro-sim bench``: what a user of the nodes meets, measured in one run.

* first run: ``gyro-sim run SCENE`` (in-process) and ``gyro-sim run SCENE --ros`` as new processes with an empty
  numba cache (``NUMBA_CACHE_DIR`` in a temporary folder: what a fresh install pays) and again with it warm;
* lockstep: the simulator and controller nodes over DDS (separate processes, localhost), ticks/s, real-time
  factor and command latency p50/p99 against the same scene in-process, measured in the same run, on the machine
  as it is ("idle") and beside one CPU hog per core (``sh -c 'while :; do :; done'``), with the load average;
* real time: the 1 kHz ψ-switching scene at ×1, command latency median, p99 and max.

Every node runs as its own process (this process imports no rclpy), on a free ROS domain with localhost-only
discovery. Figures come from the nodes' own ``done:`` lines and the bags' metadata.
"""
from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

__all__ = ["ros_part"]

LOCKSTEP_SCENES = (("spinup_thin_shell", 60.0), ("nutation_oblate", 2.0))
REALTIME_SCENE = ("nutation_oblate", 2.0)  # 1 kHz control


#: where the ROS rows run the nodes (gyro_sim.ros.launch.node_cpus): as ``gyro-sim run --ros`` does by default
NODE_CPU = "auto"

#: a process that burns one CPU until killed (the lockstep rows "with one hog per core")
HOG = ("sh", "-c", "while :; do :; done")


@contextlib.contextmanager
def cpu_hogs(n: int):
    """``n`` CPU-burning processes while the block runs (killed at its end, also on an error)."""
    procs = [subprocess.Popen(HOG) for _ in range(n)]
    try:
        yield procs
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _env(cache: Optional[str] = None) -> dict:
    """The environment of one measurement's processes: a ROS domain of their own, DDS on this machine."""
    from gyro_sim.apps.testing import ros_env, unique_domain

    env = ros_env(unique_domain())
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def _cli(args: list, env: dict, timeout: float = 900.0) -> tuple[float, subprocess.CompletedProcess]:
    """(wall s, result) of ``python -m gyro_sim.cli ARGS`` as a new process."""
    w0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", *args], env=env, capture_output=True, text=True,
                       timeout=timeout)
    return time.perf_counter() - w0, r


def _figure(pattern: str, text: str, default=float("nan")) -> float:
    m = re.search(pattern, text)
    return float(m.group(1)) if m else default


def first_run(scene: str, tmp: Path, ros_too: bool = True) -> list[dict]:
    """Process wall time of the README's first commands, cold (empty numba cache) and warm: ``gyro-sim run`` and,
    with ``ros_too``, ``gyro-sim run --ros``."""
    rows = []
    for ros in (False, True) if ros_too else (False,):
        cache = str(tmp / f"numba_cache_{'ros' if ros else 'run'}")  # each starts empty
        for state in ("cold", "warm"):
            args = ["run", scene, "--quiet", "--out", str(tmp / f"out_{ros}_{state}")] + (["--ros"] if ros else [])
            wall, r = _cli(args, _env(cache))
            text = r.stdout + r.stderr
            compiled = _figure(r"\(\+ ([\d.]+) s compiling", text, 0.0)
            rows.append({"what": f"gyro-sim run {scene}" + (" --ros" if ros else ""), "cache": state,
                         "process_wall": wall, "compile": compiled, "ok": r.returncode == 0,
                         "rtf": _figure(r"real-time factor\s+([\d.]+)", text)})
    return rows


def closed_loop(scene: str, sim_args: list) -> subprocess.CompletedProcess:
    """The scene's controller node and the simulator node (``sim_args``: more ``-p name:=value``) as processes on a
    free domain, on CPUs as ``gyro-sim run --ros`` runs them by default (:data:`NODE_CPU`); the simulator
    waits for two of the controller's subscriptions (gyro/imu and gyro/status, with gyro/kinetic_moment where its
    law reads L). Returns the simulator's result."""
    from gyro_sim.ros.launch import node_cpus, node_preexec, writer_cpus_env

    cpus = node_cpus(NODE_CPU, "realtime" if "mode:=realtime" in sim_args else "lockstep")
    env = {**_env(), **writer_cpus_env(cpus)}
    pin = node_preexec(cpus)  # (as the launcher starts them: held to its CPUs, ended with this process)
    ctl = subprocess.Popen([sys.executable, "-m", "gyro_ctl.ros.controller_node", "--ros-args", "-p",
                            f"scene:={scene}"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           preexec_fn=pin)
    try:
        return subprocess.run([sys.executable, "-m", "gyro_sim.ros.simulator_node", "--ros-args", "-p",
                               f"scene:={scene}", "-p", "wait_for_subscribers:=2", *sim_args],
                              env=env, capture_output=True, text=True, timeout=900, preexec_fn=pin)
    finally:
        ctl.send_signal(2)
        try:
            ctl.wait(timeout=10)
        except subprocess.TimeoutExpired:
            ctl.kill()


def lockstep(scene: str, duration: float, tmp: Path, hogs: int = 0) -> dict:
    """The two nodes over DDS in lockstep against the same scene in-process (warm caches), beside ``hogs`` CPU
    hogs (both runs)."""
    with cpu_hogs(hogs):
        load = os.getloadavg()[0]
        row = _lockstep(scene, duration)
    return {**row, "hogs": hogs, "load": load}


def _lockstep(scene: str, duration: float) -> dict:
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import controller_period, run

    sc = load_scene(scene)
    run(sc, duration=min(duration, 0.1))  # warm (kernels loaded)
    w0 = time.perf_counter()
    run(sc, duration=duration)
    wall_in = time.perf_counter() - w0
    sim = closed_loop(scene, ["-p", f"duration:={float(duration)!r}"])
    done = [line for line in (sim.stdout + sim.stderr).splitlines() if "done:" in line]
    line = done[-1] if done else ""
    period = controller_period(sc)
    ticks = int(round(duration / period)) if period else 0
    return {"scene": scene, "duration": duration, "ticks": ticks,
            "ticks_per_s": _figure(r"control ticks \(([\d.]+)/s\)", line),
            "rtf_dds": _figure(r"\(([\d.]+)x real time\)", line), "rtf_in_process": duration / wall_in,
            "in_process_ticks_per_s": ticks / wall_in,
            "latency_median_ms": _figure(r"median ([\d.]+) ms", line), "latency_p99_ms": _figure(r"p99 ([\d.]+) ms", line),
            "ok": sim.returncode == 0 and bool(line)}


def realtime(scene: str, duration: float, tmp: Path) -> dict:
    """Real time ×1 with the scene's controller: the command latency distribution the simulator measured."""
    from gyro_sim.io.recording import bag_info

    bag = tmp / "rt_bag"
    sim = closed_loop(scene, ["-p", "mode:=realtime", "-p", f"duration:={float(duration)!r}", "-p", f"record:={bag}",
                              "-p", "watchdog_timeout:=0.0"])
    custom = bag_info(bag)["custom"] if bag.exists() else {}
    from gyro_sim.io.recording import read_bag

    applied = len(read_bag(bag).command_t) if bag.exists() else 0
    c = lambda k: float(custom.get(f"gyro_sim.{k}", "nan")) * 1e3  # noqa: E731
    return {"scene": scene, "duration": duration, "median_ms": c("latency_median_s"), "p99_ms": c("latency_p99_s"),
            "max_ms": c("latency_max_s"), "applied": applied, "ok": sim.returncode == 0}


def ros_part(res, quick: bool = False) -> None:
    """Run the ros part into ``res.ros`` (dicts with a ``part`` key) and say each figure."""
    try:
        import importlib.util

        if importlib.util.find_spec("rclpy") is None:
            res.notes.append("ros part skipped: rclpy is not installed (pip install 'gyro_sim[ros]')")
            return
    except ValueError:
        return
    with tempfile.TemporaryDirectory(prefix="gyro_bench_ros_") as d:
        tmp = Path(d)
        for row in first_run("spinup_thin_shell", tmp):
            res.ros.append({"part": "first run", **row})
            print(f"[ros] {row['what']} ({row['cache']} numba cache): process {row['process_wall']:.2f} s wall, "
                  f"compile {row['compile']:.2f} s, real-time factor {row['rtf']:.4g}", flush=True)
        for scene, duration in LOCKSTEP_SCENES:
            for hogs in (0, os.cpu_count() or 1):
                row = lockstep(scene, duration if not quick else min(duration, 10.0), tmp, hogs)
                res.ros.append({"part": "lockstep", **row})
                print(f"[ros] lockstep {scene} {row['duration']:g} s, {_beside(row)}: {row['ticks_per_s']:.0f} ticks/s "
                      f"over DDS, real-time factor {row['rtf_dds']:.1f} over DDS vs {row['rtf_in_process']:.1f} "
                      f"in-process; command latency p50 {row['latency_median_ms']} ms, p99 {row['latency_p99_ms']} ms",
                      flush=True)
        row = realtime(*REALTIME_SCENE, tmp)
        res.ros.append({"part": "realtime", **row})
        print(f"[ros] real time ×1, {row['scene']} at 1 kHz: command latency median {row['median_ms']:.3f} ms, "
              f"p99 {row['p99_ms']:.3f} ms, max {row['max_ms']:.3f} ms; {row['applied']} commands applied on "
              f"{int(row['duration'] * 1000)} ticks", flush=True)


def _beside(row: dict) -> str:
    """'idle (load 0.6)' or 'one CPU hog per core (2 hogs, load 2.9)': what ran beside a lockstep row."""
    load = f"load {row.get('load', float('nan')):.1f}"
    return f"one CPU hog per core ({row['hogs']} hogs, {load})" if row.get("hogs") else f"idle ({load})"


def headline(res) -> list[str]:
    """The ros part's sentences for the headline."""
    out = []
    first = {(r["what"], r["cache"]): r for r in res.ros if r["part"] == "first run"}
    for what in dict.fromkeys(w for w, _ in first):
        cold, warm = first.get((what, "cold")), first.get((what, "warm"))
        if cold and warm:
            out.append(f"`{what}` as a new process: {cold['process_wall']:.2f} s wall with an empty numba cache "
                       f"({cold['compile']:.1f} s of it compiling, announced and left out of the real-time factor), "
                       f"{warm['process_wall']:.2f} s with the cache warm (what .ci/setup leaves)")
    for r in res.ros:
        if r["part"] == "lockstep":
            out.append(f"lockstep over DDS, {r['scene']} ({r['duration']:g} s, {r['ticks']} ticks), {_beside(r)}: "
                       f"{r['ticks_per_s']:.0f} closed-loop ticks/s, real-time factor {r['rtf_dds']:.1f} against "
                       f"{r['rtf_in_process']:.1f} in-process; command latency p50 {r['latency_median_ms']} ms, "
                       f"p99 {r['latency_p99_ms']} ms")
        elif r["part"] == "realtime":
            out.append(f"real time ×1, {r['scene']} at 1 kHz control: command latency median {r['median_ms']:.2f} ms, "
                       f"p99 {r['p99_ms']:.2f} ms, max {r['max_ms']:.2f} ms; commands applied on {r['applied']} of "
                       f"{int(r['duration'] * 1000)} ticks")
    return out


def markdown(res) -> list[str]:
    """The ros part's section of bench.md."""
    if not res.ros:
        return []
    L = ["## ROS path (nodes as processes over DDS, localhost)", "",
         "| part | what | figure |", "|---|---|---|"]
    for r in res.ros:
        if r["part"] == "first run":
            L.append(f"| first run | `{r['what']}`, {r['cache']} numba cache | process {r['process_wall']:.2f} s wall; "
                     f"compile {r['compile']:.2f} s; real-time factor {r['rtf']:.4g} |")
        elif r["part"] == "lockstep":
            L.append(f"| lockstep | {r['scene']} {r['duration']:g} s ({r['ticks']} ticks), {_beside(r)} | "
                     f"{r['ticks_per_s']:.0f} "
                     f"ticks/s; real-time factor {r['rtf_dds']:.1f} (in-process {r['rtf_in_process']:.1f}); "
                     f"command round trip median {r['latency_median_ms']} ms, p99 {r['latency_p99_ms']} ms |")
        else:
            L.append(f"| real time ×1 | {r['scene']} at 1 kHz, {r['duration']:g} s | latency median "
                     f"{r['median_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms, max {r['max_ms']:.3f} ms; "
                     f"{r['applied']} commands applied on {int(r['duration'] * 1000)} ticks |")
    return L + [""]
