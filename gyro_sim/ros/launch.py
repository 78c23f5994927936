"""Start the simulator and controller nodes as separate processes (no rclpy in this process).

DDS traffic stays on this machine by default: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` is set
unless the caller's environment already sets it. ``ROS_DOMAIN_ID`` is passed through.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Optional


def ros_env(domain_id: Optional[int] = None) -> dict:
    """Environment for the node processes: localhost-only discovery unless already set."""
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    return env


def node_command(module: str, params: dict) -> list[str]:
    """``python -m module --ros-args -p k:=v ...`` with floats written as floats (ROS types them)."""
    cmd = [sys.executable, "-m", module, "--ros-args"]
    for k, v in params.items():
        cmd += ["-p", f"{k}:={float(v)!r}" if isinstance(v, float) else f"{k}:={v}"]
    return cmd


def launch(scene: str, *, mode: str = "lockstep", record: Optional[str] = None, duration: Optional[float] = None,
           rate_factor: float = 1.0, watchdog_timeout: float = 2.0, with_controller: bool = True,
           domain_id: Optional[int] = None, progress: Optional[bool] = None) -> int:
    """Run the simulator (and, if ``with_controller``, the controller) until the simulator ends.

    ``scene`` is a path or a built-in name; returns the simulator's exit status. Ctrl-C is passed
    to both nodes, which end cleanly (the bag is closed). ``progress`` (default: stderr is a terminal): the
    simulator shows a progress line.
    """
    if progress is None:
        progress = sys.stderr.isatty()
    if Path(scene).is_file():
        scene = str(Path(scene).resolve())
    env = ros_env(domain_id)
    sim_params = {"scene": scene, "mode": mode, "rate_factor": float(rate_factor),
                  "watchdog_timeout": float(watchdog_timeout), "duration": float(duration or 0.0),
                  "progress": "true" if progress else "false"}
    if record:
        sim_params["record"] = str(Path(record).resolve())
    procs = []
    try:
        sim = subprocess.Popen(node_command("gyro_sim.ros.simulator_node", sim_params), env=env)
        procs.append(sim)
        if with_controller:
            procs.append(subprocess.Popen(node_command("gyro_ctl.ros.controller_node", {"scene": scene}), env=env))
        return sim.wait()
    except KeyboardInterrupt:
        for p in procs:
            p.send_signal(signal.SIGINT)
        return procs[0].wait() if procs else 130
    finally:
        for p in procs[1:]:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
