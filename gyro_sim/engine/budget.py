"""The step budget of a run: a run whose plan exceeds :data:`~gyro_sim.scenes.step_control.STEP_BUDGET` is refused
before any work, in one line that says what to loosen (:class:`~gyro_sim.scenes.step_control.StepBudgetError`, a
:class:`~gyro_sim.scenes.scene.SceneError`: the CLI's one ``error:`` line, exit status 2). ``gyro-sim run --force``,
``run(scene, force=True)``, ``Runner(..., force=True)`` and the simulator node's ``force`` parameter run it anyway.

The work a plan predicts (:func:`planned_work`) is the steps of :meth:`Simulator.planned_steps` over the run's
duration plus its output samples and controller ticks (each is a stop of the stepper, and at least one step): it
is counted before anything is allocated, so a duration of 1e15 s is refused at once, not after minutes of building
its output grid.

A run of another duration than its scene's (``gyro-sim run --duration``, ``run(scene, duration=...)``) is held to
the scene's own limits first (:func:`check_run_size`: the output windows' samples and the memory of the result,
:func:`gyro_sim.scenes.scene.check_result_size`), before its step plan is made: a duration of 1e308 s is refused
there, in one line, not in the plan's arithmetic.
"""
from __future__ import annotations

import math
from typing import Optional

from gyro_sim.scenes.scene import SceneError, check_result_size
from gyro_sim.scenes.step_control import STEP_BUDGET, StepBudgetError
from gyro_sim.scenes.tolerance import DEFAULT_PHASE

__all__ = ["planned_work", "check_budget", "budget_message", "check_run_size"]

#: the looser tolerances the message tries, tightest first (it names the first that fits the budget)
_RTOLS = (1e-5, 1e-4, 1e-3, 1e-2, 1e-1)
_ATTITUDES = (1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)


def planned_work(sim, T: float, period: Optional[float]) -> tuple[float, float]:
    """(steps, stops) a run of ``T`` s of simulator ``sim`` (planned for its horizon) is predicted to take: the
    plan's steps (:meth:`Simulator.planned_steps`, over the horizon, scaled to T) and the output samples and
    controller ticks (``period`` s; None: none), counted without allocating them."""
    H = sim.horizon
    steps = sim.planned_steps() * (T / H if H > 0 else 1.0)
    stops = sim.scene.output.sample_count(T) + (T / period + 1.0 if period else 0.0)
    return steps, stops


def check_budget(sim, T: float, period: Optional[float], budget: Optional[float] = None) -> None:
    """Raise :class:`StepBudgetError` (one line: what the plan needs, what to loosen, ``--force``) where a run of
    ``T`` s of ``sim`` would take more than ``budget`` (default :data:`STEP_BUDGET`) steps and stops."""
    budget = STEP_BUDGET if budget is None else float(budget)
    steps, stops = planned_work(sim, T, period)
    total = steps + stops
    if total > budget or not math.isfinite(total):
        raise StepBudgetError(budget_message(sim, T, period, steps, stops, budget), planned=total, budget=budget)


def _fits(sim, T: float, rtol: float, attitude: Optional[float], stops: float, budget: float,
          **accuracy) -> Optional[float]:
    """The steps of the run at tolerances (rtol, attitude; ``accuracy``: other fields of the scene's accuracy) where
    they fit the budget (with the stops), else None."""
    steps = sim.planned_steps(sim.plan_for(rtol, attitude, **accuracy)) * (T / sim.horizon if sim.horizon > 0
                                                                             else 1.0)
    return steps if steps + stops <= budget else None


def budget_message(sim, T: float, period: Optional[float], steps: float, stops: float, budget: float) -> str:
    """The one line of a refused plan: the work it needs against the budget, then what would fit: a looser
    ``accuracy.attitude`` (the tightest decade that fits, or null where only L matters) or ``accuracy.rtol``, a lower
    ``output.rate`` / longer ``controller.period`` where the samples alone exceed it, a shorter ``duration``; where no
    tolerance fits, the fastest rotation the plan resolves (``rotor.inertia``, ``initial``, the stators' ``rate``);
    and ``--force``."""
    scene, acc = sim.scene, sim.scene.accuracy
    head = (f"scene {scene.name!r}: the run's plan needs about {steps + stops:.2g} steps over {T:g} s "
            f"({steps:.2g} steps of the stepper, {stops:.2g} output samples and controller ticks), beyond the "
            f"budget of {budget:.3g} (STEP_BUDGET)")
    ways = []
    if stops <= 0.5 * budget and sim.attitude and (acc.phase_atol is not None or (acc.phase or 1.0) < DEFAULT_PHASE):
        # an absolute (or very tight) spin phase: its error grows with the turns
        if _fits(sim, T, acc.rtol, acc.attitude, stops, budget, phase_atol=None, phase=DEFAULT_PHASE) is not None:
            now = (f"phase_atol {acc.phase_atol:g} rad" if acc.phase_atol is not None else f"phase {acc.phase:g}")
            ways.append(f"hold the spin phase relative to itself: leave out accuracy.phase_atol, accuracy.phase "
                        f"{DEFAULT_PHASE:g} (now {now})")
    if stops <= 0.5 * budget and not ways:
        att_on = sim.attitude and acc.attitude is not None
        null_fits = att_on and _fits(sim, T, acc.rtol, None, stops, budget) is not None
        if att_on:
            att = next((a for a in _ATTITUDES if a > acc.attitude and _fits(sim, T, acc.rtol, a, stops, budget)), None)
            if att is not None or null_fits:
                to = " or ".join(([f"{att:g} rad"] if att is not None else []) + (["null"] if null_fits else []))
                ways.append(f"loosen accuracy.attitude to {to} (now {acc.attitude:g} rad)")
        rt = next((r for r in _RTOLS if r > acc.rtol
                   and _fits(sim, T, r, acc.attitude if att_on else None, stops, budget)), None)
        if rt is not None:
            ways.append(f"loosen accuracy.rtol to {rt:g} (now {acc.rtol:g})")
        elif att_on and not null_fits:
            rt = next((r for r in _RTOLS if r > acc.rtol and _fits(sim, T, r, None, stops, budget)), None)
            if rt is not None:
                ways.append(f"loosen accuracy.rtol to {rt:g} with accuracy.attitude: null (now {acc.rtol:g}, "
                            f"{acc.attitude:g} rad)")
        if not ways:  # no tolerance fits: the rotation the plan resolves is the cost
            ways.append(f"no looser accuracy fits (the plan resolves {sim._auto_plan.turns:.3g} turns of a rotation "
                        f"at up to {sim._rates[0]:.3g} rad/s: see rotor.inertia, initial and the stators' rate)")
    else:
        ways.append(f"lower output.rate (now {scene.output.rate:g} /s)"
                    + (f" or raise controller.period (now {period:g} s)" if period and scene.controller else ""))
    # (the steps grow at least in proportion to the duration)
    ways.append(f"shorten the duration (about {T * budget / (steps + stops):.2g} s fits)")
    return f"{head}: {', or '.join(ways)}; --force (Python: force=True) runs it anyway"


def check_run_size(scene, T: float, name: str = "duration") -> None:
    """Raise :class:`~gyro_sim.scenes.scene.SceneError` (one line naming ``name``, e.g. ``--duration``, its value
    and what to lower) where a run of ``scene`` to ``T`` s is refused by the limits a scene file of that duration
    meets on loading: a finite duration > 0, at most ``MAX_WINDOW_SAMPLES`` samples a window and at most
    :func:`~gyro_sim.scenes.scene.max_result_bytes` of result in memory. Nothing is planned or allocated."""
    try:
        T = float(T)
    except (TypeError, ValueError):
        T = math.nan
    if not (math.isfinite(T) and T > 0):
        raise SceneError(f"{name} = {T}: must be a finite number of seconds > 0")
    try:
        scene.output.check_windows(T)
        check_result_size(scene, T, name)
    except ValueError as exc:
        raise SceneError(f"scene {scene.name!r}: {exc}") from None
