"""The benchmark's RK4 part (issue 28): the default scene **as shipped** (its error control on) against the
compiled fixed-step RK4 (:mod:`gyro_sim.apps.bench_baseline`) at equal achieved error.

``gyro-sim bench --only rk4`` runs ``spinup_thin_shell`` with the lag and the quasi-static torque model, its
controller on and off, over 2 s and 60 s:

* **ours**: ``run(scene)`` as a user gets it (the accuracy plan, the error control's shadow run, the output samples;
  the controller's ticks in the compiled loop); after one untimed run of the whole duration (every kernel the run
  meets loaded), CPU of the least of :data:`REPEATS` repeats (:func:`time_ours`);
* a **reference**: the same scene by lawson8 at 64 steps per turn of the field (the benchmark's reference stepper,
  :func:`gyro_sim.apps.bench_accuracy.reference_stepper`), no error control;
* the **RK4's curve**: :func:`gyro_sim.apps.bench_baseline.rk4_sweep` over step counts by factors of 2, the
  commands replayed as scheduled commands where the controller is on (the commands our run applied at its ticks:
  the RK4 stops at every tick and takes them, without paying for the law); each point the least CPU of up to
  :data:`REPEATS` repeats within :data:`MIN_WALL` s (a long run once);
* every run scored by the benchmark's error measure at the end (:func:`gyro_sim.apps.bench_core.final_error`:
  max(|ΔL|/|L|, |Δq|), the spin phase included), and the RK4's CPU at our error by log-log interpolation of its
  Pareto front (:func:`gyro_sim.apps.bench_core.cost_at_error`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

SCENE = "spinup_thin_shell"
DURATIONS = (2.0, 60.0)
MODELS = ("lag", "quasi_static")
#: repeats of our run and of the RK4's cheaper runs (the least CPU kept; bench_core._timed): a run of a few ms timed
#: once is at the mercy of one scheduler hiccup on a shared machine
REPEATS = 3
#: the RK4's runs are repeated until this many wall s (at most REPEATS times)
MIN_WALL = 0.5
#: the RK4's step counts over the horizon: by factors of 2 up to 2^25 (the lag model over 60 s needs about 110 steps
#: a turn of the 500 Hz field at 1e-6, 6.6 million; the sweep stops where the error stops falling)
RK4_STEPS = tuple(2 ** k for k in range(26))


@dataclass
class Rk4Row:
    model: str
    controller: bool
    duration: float
    steps: int = 0
    cpu: float = math.nan
    error: float = math.nan
    rk4_cpu: float = math.nan  # the RK4's CPU at our error (NaN: its curve does not reach it)
    note: str = ""

    @property
    def speedup(self) -> float:
        return self.rk4_cpu / self.cpu if self.cpu > 0 else math.nan


@dataclass
class Rk4Results:
    rows: list = field(default_factory=list)


def _overrides(model: str, controller: bool, T: float) -> dict:
    ov: dict = {"duration": T, "torque_model": model}
    if not controller:
        ov["controller"] = None
    return ov


def _replayed(r) -> list:
    """Our run's applied commands (RunResult.commands) as a scene's scheduled ``commands``."""
    out = []
    for t, names, cur, rate in r.commands:
        for k, name in enumerate(names):
            c = {"time": float(t), "stator": name}
            if cur is not None and cur[k] is not None:
                c["current"] = float(cur[k])
            if rate is not None and rate[k] is not None:
                c["rate"] = float(rate[k])
            if len(c) > 2:
                out.append(c)
    return out


def time_ours(scene) -> tuple:
    """(CPU s, result) of ``run(scene)`` as shipped: one untimed run of the whole duration first (a kernel the run
    meets only late, e.g. once the spin-up passes a rate, is loaded from numba's cache there: not the run's cost),
    then the least CPU of :data:`REPEATS` repeats (bench_core._timed_warm)."""
    from gyro_sim.apps.bench_core import _timed_warm
    from gyro_sim.engine.simulate import run

    _, cpu, r, _ = _timed_warm(lambda: run(scene), math.inf, REPEATS)
    return cpu, r


def _one(model: str, controller: bool, T: float, say=print) -> Rk4Row:
    from gyro_sim.apps.bench_accuracy import reference_stepper
    from gyro_sim.apps.bench_baseline import rk4_sweep
    from gyro_sim.apps.bench_core import cost_at_error, final_error
    from gyro_sim.engine.simulate import Simulator, run
    from gyro_sim.scenes.scene import load_scene

    ov = _overrides(model, controller, T)
    scene = load_scene(SCENE, overrides=ov)
    row = Rk4Row(model, controller, T)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        row.cpu, r = time_ours(scene)
        method, spt = reference_stepper(Simulator(scene), T)
        ref = run(load_scene(SCENE, overrides={**ov, "integrator": {"method": method, "steps_per_turn": spt}}),
                  estimate=False)
    row.steps = int(r.steps)
    L_ref, q_ref = ref.L[-1], ref.q[-1]
    row.error = final_error(r.L[-1], r.q[-1], L_ref, q_ref)
    extra: dict = {"torque_model": model}
    if controller:
        extra["commands"] = _replayed(r)
    rows, notes = rk4_sweep(SCENE, T, L_ref, q_ref, extra=extra, steps=RK4_STEPS, min_wall=MIN_WALL,
                            max_reps=REPEATS)
    row.rk4_cpu = cost_at_error(rows, row.error, key="cpu")
    row.note = "; ".join(notes)
    say(f"[rk4] {SCENE} {model} controller {'on' if controller else 'off'} {T:g} s: ours {row.steps} steps "
        f"{row.cpu * 1e3:.1f} ms CPU, error {row.error:.2g}; RK4 at that error {row.rk4_cpu * 1e3:.1f} ms "
        f"({row.speedup:.1f}x)")
    return row


def rk4_part(res, quick: bool, say=print) -> Rk4Results:
    """Run the part (module docstring); the rows go to ``res.rk4``. (Quick and full mode run the same cases.)"""
    out = Rk4Results()
    res.rk4 = out
    for T in DURATIONS:
        for model in MODELS:
            for controller in (True, False):
                out.rows.append(_one(model, controller, T, say))
    return out


def markdown_lines(res) -> list[str]:
    rk = getattr(res, "rk4", None)
    if rk is None or not rk.rows:
        return []
    lines = ["## As shipped against the compiled RK4 (`--only rk4`)", "",
             f"`{SCENE}` as shipped (error control on) against the compiled fixed-step RK4 at the same error at the "
             "end (max(|ΔL|/|L|, |Δq|), spin phase included), CPU s of this process; the RK4's CPU interpolated "
             "log-log on its Pareto front.", "",
             "| model | controller | duration s | our steps | our CPU ms | our error | RK4 CPU ms at that error "
             "| ours faster |", "|---|---|---|---|---|---|---|---|"]
    for r in rk.rows:
        lines.append(f"| {r.model} | {'on' if r.controller else 'off'} | {r.duration:g} | {r.steps} | "
                     f"{r.cpu * 1e3:.2f} | {r.error:.2g} | {r.rk4_cpu * 1e3:.2f} | {r.speedup:.1f}x |")
    notes = [r.note for r in rk.rows if r.note]
    return lines + [""] + [f"- {n}" for n in notes] + ([""] if notes else [])


def headline(res) -> list[str]:
    rk = getattr(res, "rk4", None)
    if rk is None or not rk.rows:
        return []
    return [f"as shipped vs compiled RK4 ({r.model}, controller {'on' if r.controller else 'off'}, {r.duration:g} s): "
            f"{r.speedup:.1f}x" for r in rk.rows]
