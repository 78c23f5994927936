"""The benchmark's cost part (issue 28): what the default scene costs as shipped against its duration, beside the old
defaults (:class:`gyro_sim.scenes.tolerance.legacy`: 10 modes, 12/48 steps per turn, rate_change 1e-4, no error
control), in CPU seconds of this process (``time.process_time``; ratios from one run).

``gyro-sim bench --only cost`` runs ``spinup_thin_shell`` as shipped (its controller on) over 2, 20, 60, 200 s (and
1200 s, the 20-minute spin-up, and 2000 s in full mode): steps, CPU, CPU per simulated second, the real-time factor
in CPU, the run's own error estimate (L, the axis' directions, the spin phase against their tolerances), and the
same duration at the old defaults. Cost linear in duration: CPU per simulated second within 2x across the durations.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

QUICK_DURATIONS = (2.0, 20.0, 60.0, 200.0)
FULL_DURATIONS = (2.0, 20.0, 60.0, 200.0, 1200.0, 2000.0)
SCENE = "spinup_thin_shell"


@dataclass
class CostRow:
    duration: float
    what: str  # "as shipped", "old defaults"
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


def _one(T: float, old: bool) -> CostRow:
    from gyro_sim.engine.simulate import run
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.scenes.tolerance import legacy

    scene = load_scene(SCENE, overrides={"duration": T})
    row = CostRow(T, "old defaults" if old else "as shipped")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c0 = time.process_time()
        if old:
            with legacy():
                r = run(scene, force=True)
        else:
            r = run(scene, force=True)
        row.cpu = time.process_time() - c0
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
    return out


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
    return out
