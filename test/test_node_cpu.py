"""Both nodes of ``gyro-sim run --ros`` on one CPU (gyro_sim/ros/launch.py, ``node_cpus``): every thread of both
node processes (the middleware's too) held to the same single CPU by default, the simulator's bag writer on the
others; ``--node-cpu none`` leaves them to the
scheduler; a CPU the launcher may not use is refused in one line. (Why: beside a CPU hog per core a lockstep
hand-over across cores waits for the other core's hog; docs/benchmark.md measures it. Not timed here.)"""
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from gyro_sim.ros.launch import launch, node_cpus
from gyro_sim.testing import unique_domain

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                                reason="needs CPU affinity and at least two CPUs")


def _children() -> dict:
    """{pid: 'simulator' | 'controller' | 'writer'} of this process's node children and the simulator's bag writer
    (from /proc)."""
    procs = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        procs[int(d.name)] = (int(stat.rsplit(")", 1)[1].split()[1]), cmd)
    out = {pid: who for pid, (ppid, cmd) in procs.items() if ppid == os.getpid()
           for who in ("simulator", "controller") if f"{who}_node" in cmd}
    sims = {pid for pid, who in out.items() if who == "simulator"}
    out.update({pid: "writer" for pid, (ppid, cmd) in procs.items() if ppid in sims and "bag_process" in cmd})
    return out


def _thread_cpus(pid: int) -> dict:
    """{thread id: its allowed CPUs} of process ``pid``."""
    cpus = {}
    for t in Path(f"/proc/{pid}/task").iterdir():
        try:
            cpus[int(t.name)] = frozenset(os.sched_getaffinity(int(t.name)))
        except OSError:
            pass
    return cpus


def _seen_while_running(node_cpu, tmp_path) -> dict:
    """Launch spinup_thin_shell with ``node_cpu``; once both nodes have their middleware threads, their threads'
    CPUs by node."""
    status = {}
    t = threading.Thread(target=lambda: status.setdefault("code", launch(
        "spinup_thin_shell", duration=200.0, record=str(tmp_path / "bag"), domain_id=unique_domain(),
        progress=False, node_cpu=node_cpu)))
    t.start()
    seen: dict = {}
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end and t.is_alive():
            kids = _children()
            got = {who: _thread_cpus(pid) for pid, who in kids.items()}
            # (both nodes up, each with the middleware's threads: more than a few; the bag's writer has opened the
            # bag, which it does once it has taken its CPUs)
            if (len(got) == 3 and all(len(v) >= 4 for k, v in got.items() if k != "writer")
                    and (tmp_path / "bag").exists()):
                seen = got
                break
            time.sleep(0.2)
    finally:
        for pid, who in _children().items():
            if who != "writer":
                os.kill(pid, 2)
        t.join(timeout=60)
    return seen


def test_both_nodes_and_all_their_threads_run_on_one_cpu(tmp_path):
    want = frozenset(node_cpus("auto"))
    seen = _seen_while_running("auto", tmp_path)
    print(f"\n  threads per node: { {k: len(v) for k, v in seen.items()} }, CPUs: "
          f"{ {k: sorted(set(v.values()), key=sorted) for k, v in seen.items()} } (want {sorted(want)})")
    assert set(seen) == {"simulator", "controller", "writer"}
    for who in ("simulator", "controller"):
        assert set(seen[who].values()) == {want}, (who, seen[who])
    # the bag's writer process works beside them, on the other CPUs (before: none; the bag was written in the
    # simulator's turns with the controller)
    assert set(seen["writer"].values()) == {frozenset(os.sched_getaffinity(0)) - want}, seen["writer"]


def test_auto_is_the_default():
    """Beside one CPU hog per core the default scene's lockstep keeps 66 % (recorded) and 91 % (not) of its idle
    ticks/s with both nodes on one CPU, 48 % / 41 % left to the scheduler (docs/benchmark.md)."""
    import inspect

    from gyro_sim.apps.cli import build_parser

    args = build_parser().parse_args(["run", "spinup_thin_shell", "--ros"])
    assert args.node_cpu == "auto"
    assert inspect.signature(launch).parameters["node_cpu"].default == "auto"


def test_node_cpu_none_leaves_them_to_the_scheduler(tmp_path):
    seen = _seen_while_running("none", tmp_path)
    every = frozenset(os.sched_getaffinity(0))
    assert set(seen) == {"simulator", "controller", "writer"}
    assert all(set(v.values()) == {every} for v in seen.values()), seen


def test_a_cpu_the_launcher_may_not_use_is_refused_in_one_line():
    bad = max(os.sched_getaffinity(0)) + 1
    for value in (str(bad), "fast"):
        r = subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", "run", "spinup_thin_shell", "--ros",
                            "--node-cpu", value, "--duration", "0.1"], capture_output=True, text=True, timeout=120)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert f"--node-cpu {value}: must be auto, none or a CPU" in lines[0], lines


def test_auto_holds_them_to_one_cpu_in_lockstep_only():
    """Real time: the simulator paces, publishes and records while the controller works; on one CPU they take
    turns (1316–1352 of 2000 commands in time at 1 kHz against 1715–1741 left to the scheduler): auto leaves them."""
    last = max(os.sched_getaffinity(0))
    assert node_cpus("auto", "lockstep") == {last}
    assert node_cpus("auto", "realtime") is None and node_cpus("auto", "freerun") is None
    assert node_cpus(str(last), "realtime") == {last} and node_cpus("none", "lockstep") is None
