"""The benchmark's cost part (issue 28): what the default scene costs as shipped against its duration, beside the old
defaults (:class:`gyro_sim.scenes.tolerance.legacy`: 10 modes, 12/48 steps per turn, rate_change 1e-4, no error
control), in CPU seconds of this process (``time.process_time``; ratios from one run).

``gyro-sim bench --only cost`` runs ``spinup_thin_shell`` as shipped (its controller on) over 2, 20, 60, 200 s (and
1200 s, the 20-minute spin-up, and 2000 s in full mode): steps, CPU, CPU per simulated second, the real-time factor
in CPU, the run's own error estimate (L, the axis' directions, the spin phase against their tolerances), and the
same duration at the old defaults. Each row's CPU is the least of its repeats (:data:`REPEAT_CPU`,
:data:`REPEATS_MAX`). Cost linear in duration: CPU per simulated second within 2x across the durations.
Then every built-in scene over its own duration, as shipped and at the old defaults (``scene_rows``: steps, CPU,
the estimate against the scene's tolerances).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Optional

QUICK_DURATIONS = (2.0, 20.0, 60.0, 200.0)
FULL_DURATIONS = (2.0, 20.0, 60.0, 200.0, 1200.0, 2000.0)
SCENE = "spinup_thin_shell"
#: the scenes run over their own durations (None: every built-in scene)
SCENES: Optional[tuple] = None
#: a row is the least CPU of its repeats: runs are repeated until REPEAT_CPU s of CPU, at most REPEATS_MAX times (single
#: runs of 20–300 ms here now and then took 70–150 ms more: 0.109 against 0.033 s, 0.417 against 0.27 s)
REPEAT_CPU = 0.5
REPEATS_MAX = 3


@dataclass
class CostRow:
    duration: float
    what: str  # "as shipped", "old defaults"
    scene: str = SCENE
    steps: int = 0
    cpu: float = math.nan
    estimate: str = ""
    met: bool = False

    @property
    def cpu_per_s(self) -> float:
        """CPU s per simulated s."""
        return self.cpu / self.duration

    @property
    def realtime(self) -> float:
        """Simulated s per CPU s."""
        return self.duration / self.cpu if self.cpu > 0 else math.inf


@dataclass
class CostResults:
    rows: list = field(default_factory=list)
    scene_rows: list = field(default_factory=list)  # every built-in scene over its own duration


def _one(T: float, old: bool, name: str = SCENE) -> CostRow:
    from gyro_sim.engine.simulate import run
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.scenes.tolerance import legacy

    scene = load_scene(name, overrides={"duration": T})
    row = CostRow(T, "old defaults" if old else "as shipped", name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run(scene, duration=min(T, 0.05), force=True)  # (its kernels loaded: the row times the run)
        spent = 0.0
        cpus: list[float] = []
        while len(cpus) < REPEATS_MAX and (not cpus or spent < REPEAT_CPU):
            c0 = time.process_time()
            if old:
                with legacy():
                    r = run(scene, force=True)
            else:
                r = run(scene, force=True)
            cpus.append(time.process_time() - c0)
            spent += cpus[-1]
        row.cpu = min(cpus)
    row.steps = int(r.steps)
    est = r.error_estimate
    row.estimate, row.met = (est.text(), est.met) if est is not None else ("", False)
    return row


def cost_part(res, quick: bool, say=print) -> CostResults:
    """Run the part (module docstring); the rows go to ``res.cost``."""
    out = CostResults()
    res.cost = out
    _one(0.2, False)  # (the kernels loaded once: the rows time the runs)
    for T in (QUICK_DURATIONS if quick else FULL_DURATIONS):
        for old in (False, True):
            row = _one(T, old)
            out.rows.append(row)
            say(f"[cost] {SCENE} {T:g} s {row.what}: {row.steps} steps, {row.cpu:.3f} s CPU "
                f"({row.realtime:.0f}x real time), {row.estimate}")
    from gyro_sim.scenes.scene import builtin_scenes, load_scene

    for name in SCENES if SCENES is not None else builtin_scenes():
        T = load_scene(name).duration
        for old in (False, True):
            row = _one(T, old, name)
            out.scene_rows.append(row)
            say(f"[cost] {name} {T:g} s {row.what}: {row.steps} steps, {row.cpu:.3f} s CPU, {row.estimate}")
    return out


def scene_ratios(cost: CostResults) -> dict:
    """{scene: CPU as shipped over CPU at the old defaults} of the built-in scenes' rows."""
    by = {(r.scene, r.what): r for r in cost.scene_rows}
    return {n: by[(n, "as shipped")].cpu / by[(n, "old defaults")].cpu for n, w in by if w == "as shipped"
            and (n, "old defaults") in by and by[(n, "old defaults")].cpu > 0}


def linearity(cost: CostResults) -> float:
    """Largest over smallest CPU per simulated second as shipped, over the durations from 20 s on (the 2 s run is
    the spin-up's costliest stretch alone, and its few milliseconds are dominated by the run's set-up)."""
    v = [r.cpu_per_s for r in cost.rows if r.what == "as shipped" and r.duration >= 20.0]
    return max(v) / min(v) if v else math.nan


def markdown_lines(res) -> list[str]:
    cost = getattr(res, "cost", None)
    if cost is None or not cost.rows:
        return []
    lines = ["## Cost against duration (issue 28)", "",
             f"`{SCENE}` (controller on) as shipped and at the old defaults; CPU s of one process, ratios from one "
             "run. The estimate is the run's own (L, the symmetry axis' directions, the spin phase, each against "
             "its tolerance).", "",
             "| duration s | what | steps | CPU s | CPU ms per simulated s | real time (CPU) | estimate |",
             "|---|---|---|---|---|---|---|"]
    for r in cost.rows:
        lines.append(f"| {r.duration:g} | {r.what} | {r.steps} | {r.cpu:.3f} | {1e3 * r.cpu_per_s:.2f} | "
                     f"{r.realtime:.0f}x | {r.estimate} |")
    lines += ["", f"CPU per simulated second, as shipped, from 20 s on: largest / smallest = {linearity(cost):.2f}.",
              ""]
    if cost.scene_rows:
        ratios = scene_ratios(cost)
        by = {(r.scene, r.what): r for r in cost.scene_rows}
        lines += ["### Every built-in scene over its own duration", "",
                  "| scene | duration s | as shipped: steps, CPU s | its estimate | old defaults: steps, CPU s | "
                  "their estimate | CPU ratio |", "|---|---|---|---|---|---|---|"]
        for n, ratio in ratios.items():
            a, o = by[(n, "as shipped")], by[(n, "old defaults")]
            lines.append(f"| {n} | {a.duration:g} | {a.steps}, {a.cpu:.3f} | {a.estimate} | {o.steps}, {o.cpu:.3f} | "
                         f"{o.estimate} | {ratio:.2f}x |")
        lines.append("")
    return lines


def headline(res) -> list[str]:
    cost = getattr(res, "cost", None)
    if cost is None:
        return []
    shipped = {r.duration: r for r in cost.rows if r.what == "as shipped"}
    old = {r.duration: r for r in cost.rows if r.what == "old defaults"}
    out = []
    for T, r in shipped.items():
        o = old.get(T)
        ratio = f", {r.cpu / o.cpu:.2f}x the CPU of the old defaults" if o is not None and o.cpu > 0 else ""
        out.append(f"cost: {SCENE} {T:g} s as shipped: {r.steps} steps, {r.cpu:.3f} s CPU, {r.realtime:.0f}x real "
                   f"time{ratio}; {'met' if r.met else 'NOT met'}")
    out.append(f"cost: CPU per simulated second from 20 s on within {linearity(cost):.2f}x")
    ratios = scene_ratios(cost)
    if ratios:
        worst = max(ratios, key=lambda n: ratios[n])
        met = sum(1 for r in cost.scene_rows if r.what == "as shipped" and r.met)
        out.append(f"cost: built-in scenes as shipped against the old defaults: {ratios[worst]:.2f}x at most "
                   f"({worst}); {met} of {len(ratios)} meet their accuracy by their own estimate")
    return out
