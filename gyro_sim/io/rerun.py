"""Re-run check of a recorded bag: re-simulate its embedded scene with its recorded commands.

A bag holds the scene it was run from and every command the simulator applied (with the simulation
time it applied it at). Re-running the scene in-process, applying those commands at those times,
must give the recorded states bit for bit: the report says the largest difference found.
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from gyro_sim.io.messages import stamp_ns
from gyro_sim.io.recording import read_bag
from gyro_sim.scenes.scene import SceneError, parse_scene_text, scene_from_dict
from gyro_sim.engine.simulate import Runner


def rerun_bag(path) -> dict:
    """Re-simulate a bag; returns sample count, largest |Δ| of L, q, Ω_b, torque and whether all are 0 (a bag
    without a state sample, cut before its first one: nothing re-run, ``samples_recorded`` 0)."""
    b = read_bag(path)
    if not b.scene_text:
        raise SceneError(f"{path}: the bag holds no scene; it was not written by gyro_sim")
    where = f"{Path(path)} (embedded scene)"
    scene = scene_from_dict(parse_scene_text(b.scene_text, where), where=where)
    period = b.custom.get("gyro_sim.control_period")  # the node's ticks (set for scenes without a controller too)
    # the run's accuracy plan and error control were made for its planned duration (an interrupted bag ends before)
    planned = b.custom.get("gyro_sim.planned_duration")
    if not len(b.t):  # a recording stopped before its first sample: a valid empty bag, nothing to re-run
        return {"samples_recorded": 0, "samples_rerun": 0, "max_abs_diff": {k: 0.0 for k in ("L", "q", "omega_b",
                                                                                             "torque")},
                "identical": True, "unapplied_commands": len(b.command_t)}
    runner = Runner(scene, float(b.t[-1]), attitude=True,  # bags are recorded with the attitude
                    control_period=float(period) if period else None,
                    horizon=float(planned) if planned else None, force=True)  # (the run was made once)
    cmds: dict[int, list] = defaultdict(list)
    for i, t in enumerate(b.command_t):
        cmds[stamp_ns(t)].append(i)
    names = b.stator_names
    while not runner.done:
        if runner.row > 0:
            for i in cmds.pop(stamp_ns(runner.sim.t), []):
                cur, rate = b.command_current[i], b.command_rate[i]
                runner.apply_commands({n: (None if np.isnan(cur[k]) else float(cur[k]),
                                           None if np.isnan(rate[k]) else float(rate[k]))
                                       for k, n in enumerate(names) if not (np.isnan(cur[k]) and np.isnan(rate[k]))})
        runner.advance()
    r = runner.result()
    n = min(len(r.t), len(b.t))
    diff = {k: float(np.max(np.abs(getattr(r, a)[:n] - getattr(b, k)[:n]))) if n else 0.0
            for k, a in (("L", "L"), ("q", "q"), ("omega_b", "omega_b"), ("torque", "torque"))}
    return {"samples_recorded": len(b.t), "samples_rerun": len(r.t), "max_abs_diff": diff,
            "identical": len(r.t) == len(b.t) and all(v == 0.0 for v in diff.values()),
            "unapplied_commands": sum(len(v) for v in cmds.values())}
