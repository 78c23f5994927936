"""Start the simulator and controller nodes as separate processes (no rclpy in this process).

DDS traffic stays on this machine by default: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` is set
unless the caller's environment already sets it. ``ROS_DOMAIN_ID`` is passed through.

Signals and lifetime (``gyro-sim run --ros``):

* SIGINT or SIGTERM to the launcher, alone or with its process group (a terminal's Ctrl-C), is forwarded to both
  nodes (a node that got the group's copy as well ignores the repeat). Each node ends its run, closes
  its bag (marked ``interrupted: signal SIGINT``/``SIGTERM``) and exits 130 / 143; the launcher waits for the
  simulator at most :data:`STOP_GRACE` s and for the controller :data:`CONTROLLER_GRACE` s, then, as a last
  resort, kills the node (SIGKILL) and says so on stderr (that bag may be unfinished).
* The nodes do not outlive the launcher, even a SIGKILLed one, two ways: on Linux each node is started with
  ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` (ctypes, in the child between fork and exec: :func:`node_preexec`): the
  kernel sends it SIGTERM as soon as the launcher's thread that started it ends; and everywhere,
  ``GYRO_SIM_PARENT_PID`` in the node's environment makes it watch its parent
  (:func:`gyro_sim.ros.common.watch_parent`: it looks every 0.5 s, then sends itself SIGTERM). Either way the node
  stops as on SIGTERM: its bag is closed, marked interrupted.
* A signal that comes while a node starts up ends it quietly (:data:`NODE_BOOT`), with 130 / 143.
* A controller that ends with an error (or is killed) while the simulator runs: the launcher says so and sends the
  simulator :data:`CONTROLLER_ENDED_SIGNAL`, whose ``on_controller_lost`` policy then applies (default ``stop``: the
  bag is marked ``failed: controller lost at t = …``, status 1).
* ``--node-cpu auto`` (the default) holds both lockstep nodes to one CPU (:func:`node_cpus`): they hand each tick
  to each other, so they never need two cores at once, and beside processes that take every core (a CPU hog per
  core) a hand-over on one core is prompt while one across cores waits for the other core's hog. The simulator's
  bag is written by a process of its own (:mod:`gyro_sim.io.bag_process`) on the other CPUs
  (:func:`writer_cpus_env`). Measured on this 2-core machine, default scene, 5 alternated runs each (medians,
  docs/benchmark.md): recorded, 1457 ticks/s idle and 967 beside one hog per core on one CPU, against 1336 / 640 left
  to the scheduler; not recorded, 1607 / 1460 against 1825 / 757. ``none`` leaves them to the scheduler.
* :func:`launch` returns the simulator's exit status: 0 the run reached its end, 130 / 143 it was stopped by
  SIGINT / SIGTERM (also when the node was ended by the signal before it could handle it: -2 / -15 are given as
  130 / 143), anything else a failure (1: the run failed, e.g. its controller was lost; 2: the node refused its scene
  or a parameter; negative: killed by that signal).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Optional

from gyro_sim.io.signals import signal_name

#: SIGINT/SIGTERM: what stops the nodes (and ``gyro-sim run --ros``) cleanly
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # (SIGHUP: the terminal closed; 129)
#: the signal the launcher sends the simulator when the controller's process ended with an error while the run goes on
#: (a SIGKILL, a crash): the simulator applies its ``on_controller_lost`` policy at once (the ROS graph shows a killed
#: process for ~20 s more: DDS's lease). Blocked in the nodes from the fork until the simulator's handler is set.
CONTROLLER_ENDED_SIGNAL = signal.SIGUSR1
#: the environment variable naming the process a node must not outlive (:func:`gyro_sim.ros.common.watch_parent`)
PARENT_PID_ENV = "GYRO_SIM_PARENT_PID"
STOP_GRACE = 30.0  # wall s the simulator has, after a forwarded signal, to close its bag before SIGKILL
CONTROLLER_GRACE = 10.0  # wall s the controller has to end after SIGINT/SIGTERM before SIGKILL
POLL = 0.05  # wall s between looks at the nodes while waiting
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def ros_env(domain_id: Optional[int] = None) -> dict:
    """Environment for the node processes: localhost-only discovery unless already set."""
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    return env


#: ``python -m MODULE ARGS`` for a node started by :func:`launch`, whose SIGINT/SIGTERM are blocked from the fork on
#: (:func:`node_preexec`): here they get a handler that ends the process quietly with 130 / 143 and are unblocked
#: (one that came meanwhile is delivered now); node_main (gyro_sim.ros.common) replaces that handler when it starts.
#: So a Ctrl-C while a node starts up or imports ends it without a KeyboardInterrupt traceback.
NODE_BOOT = ("import runpy, signal, sys\n"
             "for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):\n"
             "    signal.signal(s, lambda signum, frame: sys.exit(128 + signum))\n"
             "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM, signal.SIGHUP})\n"
             "del sys.argv[0]\n"
             "runpy.run_module(sys.argv[0], run_name='__main__', alter_sys=True)\n")


def node_command(module: str, params: dict) -> list[str]:
    """``python -c NODE_BOOT module --ros-args -p k:=v ...`` (as ``python -m module``, see :data:`NODE_BOOT`) with
    floats written as floats (ROS types them)."""
    cmd = [sys.executable, "-c", NODE_BOOT, module, "--ros-args"]
    for k, v in params.items():
        cmd += ["-p", f"{k}:={float(v)!r}" if isinstance(v, float) else f"{k}:={v}"]
    return cmd


def node_cpus(node_cpu="auto", mode: str = "lockstep") -> Optional[set]:
    """The CPUs the nodes are held to: ``"auto"`` in lockstep ``mode`` one CPU of this process's (the last: the first
    tends to take the machine's interrupts; None where this process has only one, or the platform has no affinity),
    in the other modes None (real time: the simulator paces, publishes and records while the controller works, and
    on one CPU they take turns: 1316–1352 of 2000 commands in time at 1 kHz against 1715–1741 left to the scheduler);
    an int that CPU in any mode (ValueError naming ``--node-cpu`` where this process may not use it); None or
    ``"none"``: left to the scheduler."""
    if node_cpu is None or node_cpu == "none" or not hasattr(os, "sched_getaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    if node_cpu == "auto":
        return {allowed[-1]} if len(allowed) > 1 and mode == "lockstep" else None
    try:
        cpu = int(node_cpu)
    except (TypeError, ValueError):
        cpu = -1
    if cpu not in allowed:
        raise ValueError(f"--node-cpu {node_cpu}: must be auto, none or a CPU this process may use ({allowed})")
    return {cpu}


def writer_cpus_env(cpus: Optional[set]) -> dict:
    """The nodes' environment entry that keeps the simulator's bag writer (:mod:`gyro_sim.io.bag_process`) off the
    CPU the nodes are held to (``cpus``, :func:`node_cpus`): on this process's other CPUs; {} where they are not
    held."""
    if not cpus:
        return {}
    from gyro_sim.io.bag_process import WRITER_CPUS_ENV

    others = sorted(set(os.sched_getaffinity(0)) - set(cpus))
    return {WRITER_CPUS_ENV: ",".join(str(c) for c in others)} if others else {}


def node_preexec(cpus: Optional[set] = None) -> Callable[[], None]:
    """The ``preexec_fn`` of a node (run in the child between fork and exec): SIGINT/SIGTERM blocked until
    :data:`NODE_BOOT` unblocks them, and, on Linux, ``prctl(PR_SET_PDEATHSIG, SIGTERM)``: the child gets SIGTERM when
    this process (the thread calling Popen) ends, also by SIGKILL (elsewhere, or without a usable libc, the nodes'
    parent watch, :func:`gyro_sim.ros.common.watch_parent`, does it). A child whose parent ended before the prctl
    exits at once (status 143). ``cpus``: the CPUs it is held to (:func:`node_cpus`), set before it starts a
    thread, so the middleware's threads are held there too."""
    prctl = None
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            prctl = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):
            prctl = None
    parent = os.getpid()
    stop = set(STOP_SIGNALS) | {CONTROLLER_ENDED_SIGNAL}

    def preexec() -> None:  # nothing here may need a lock another thread of the parent could hold
        signal.pthread_sigmask(signal.SIG_BLOCK, stop)
        if cpus:
            os.sched_setaffinity(0, cpus)
        if prctl is not None:
            prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))
            if os.getppid() != parent:
                os._exit(128 + int(signal.SIGTERM))

    return preexec


class _Signals:
    """SIGINT/SIGTERM received by this process, recorded (not raised) while the nodes run; the main thread only
    (elsewhere Python delivers none: nothing is installed). A signal this process was started ignoring (e.g. SIGINT
    of a ``cmd &`` in a script) stays ignored."""

    def __init__(self):
        self.got: list[int] = []
        self.old: dict = {}

    def __enter__(self) -> "_Signals":
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:
                if signal.getsignal(s) is not signal.SIG_IGN:
                    self.old[s] = signal.signal(s, lambda signum, frame: self.got.append(signum))
        return self

    def __exit__(self, *exc) -> None:
        for s, h in self.old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


def _say(text: str) -> None:
    sys.stderr.write(f"gyro-sim: {text}\n")
    sys.stderr.flush()


def _wait(proc: subprocess.Popen, timeout: float) -> Optional[int]:
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        return None


def _kill(name: str, proc: subprocess.Popen, why: str) -> int:
    """The last resort: SIGKILL, said on stderr."""
    _say(f"the {name} node {why}: killed (SIGKILL)" + ("; its bag may be unfinished" if name == "simulator" else ""))
    proc.kill()
    return proc.wait()


def _stop(name: str, proc: subprocess.Popen, sig: int, grace: float) -> int:
    """End ``proc``: ``sig``, at most ``grace`` s, then SIGKILL."""
    if proc.poll() is None:
        proc.send_signal(sig)
    code = _wait(proc, grace)
    if code is None:
        code = _kill(name, proc, f"did not end within {grace:g} s of {signal_name(sig)}")
    return code


def _as_status(code: int) -> int:
    """-2 / -15 (a node ended by SIGINT / SIGTERM before it handled it) as 130 / 143; other statuses as they are."""
    return 128 - code if -code in (int(s) for s in STOP_SIGNALS) else code


def launch(scene: str, *, mode: str = "lockstep", record: Optional[str] = None, duration: Optional[float] = None,
           rate_factor: float = 1.0, watchdog_timeout: float = 2.0, with_controller: bool = True,
           domain_id: Optional[int] = None, progress: Optional[bool] = None, force: bool = False,
           node_cpu: object = "auto") -> int:
    """Run the simulator (and, if ``with_controller``, the controller) until the simulator ends; then end the
    controller (SIGINT).

    ``scene`` is a path or a built-in name. Returns the simulator's exit status: 0 complete, 130 / 143 stopped by
    SIGINT / SIGTERM (the bag is closed, marked interrupted), other values a failure (see the module's docstring
    for the signals: forwarded to both nodes, bounded waits, the nodes die with this process). Call it from a
    thread that lives as long as the call (PR_SET_PDEATHSIG is tied to the thread that starts the nodes; it returns
    only once they have ended). ``progress`` (default: stderr is a terminal): the simulator shows a progress line.
    ``force``: the simulator runs a plan beyond the step budget (its ``force`` parameter, gyro_sim/engine/budget.py).
    ``node_cpu``: the CPU both nodes run on (:func:`node_cpus`: ``"auto"``, the default, one in lockstep; an int;
    None or ``"none"``: left to the scheduler).
    """
    cpus = node_cpus(node_cpu, mode)
    if progress is None:
        progress = sys.stderr.isatty()
    if Path(scene).is_file():
        scene = str(Path(scene).resolve())
    env = ros_env(domain_id)
    env[PARENT_PID_ENV] = str(os.getpid())
    env.update(writer_cpus_env(cpus))
    sim_params = {"scene": scene, "mode": mode, "rate_factor": float(rate_factor),
                  "watchdog_timeout": float(watchdog_timeout), "duration": float(duration or 0.0),
                  "progress": "true" if progress else "false"}
    if force:
        sim_params["force"] = "true"
    if record:
        sim_params["record"] = str(Path(record).resolve())
    preexec = node_preexec(cpus)
    procs: list[tuple[str, subprocess.Popen]] = []
    with _Signals() as sigs:
        try:
            sim = subprocess.Popen(node_command("gyro_sim.ros.simulator_node", sim_params), env=env,
                                   preexec_fn=preexec)
            procs.append(("simulator", sim))
            ctl = None
            if with_controller:
                ctl = subprocess.Popen(node_command("gyro_ctl.ros.controller_node", {"scene": scene}), env=env,
                                       preexec_fn=preexec)
                procs.append(("controller", ctl))
            code = _run(sim, ctl, sigs)
            if ctl is not None:  # SIGINT, or again the signal forwarded (a repeat changes nothing for a node)
                _stop("controller", ctl, sigs.got[0] if sigs.got else signal.SIGINT, CONTROLLER_GRACE)
            return _as_status(code)
        finally:  # (an error of this process: the nodes end with it)
            for name, p in procs:
                if p.poll() is None:
                    _stop(name, p, signal.SIGTERM, STOP_GRACE if name == "simulator" else CONTROLLER_GRACE)


def _run(sim: subprocess.Popen, ctl: Optional[subprocess.Popen], sigs: _Signals) -> int:
    """Wait for the simulator, forwarding the signals this process gets to both nodes; the simulator's status."""
    forwarded, deadline, ctl_seen = 0, None, ctl is None
    while True:
        code = _wait(sim, POLL)
        if code is not None:
            return code
        if len(sigs.got) > forwarded:
            for s in sigs.got[forwarded:]:
                for p in (sim, ctl):
                    if p is not None and p.poll() is None:
                        p.send_signal(s)
            if deadline is None:
                deadline = time.monotonic() + STOP_GRACE
            else:
                _say(f"waiting for the simulator node to close its bag (at most {deadline - time.monotonic():.0f} s "
                     "more, then SIGKILL)")
            forwarded = len(sigs.got)
        if deadline is not None and time.monotonic() > deadline:
            return _kill("simulator", sim, f"did not end within {STOP_GRACE:g} s of {signal_name(sigs.got[0])}")
        if not ctl_seen and ctl.poll() is not None:
            ctl_seen = True
            if not sigs.got and ctl.returncode != 0:
                _say(f"the controller node ended with status {ctl.returncode} while the simulator runs")
                if sim.poll() is None:
                    sim.send_signal(CONTROLLER_ENDED_SIGNAL)  # its on_controller_lost policy applies now
