"""The steppers behind one interface (diffrax's ``_solver``, scipy.integrate's ``OdeSolver.step``): the registry of
stepper names (the step plan's choice, :mod:`gyro_sim.engine.step_size`) → compiled integrator
(:mod:`gyro_sim.compiled`), how a command segment's arguments are built for it, and :func:`integrate`, which calls it
between stops in pieces a signal can interrupt.

Every stepper takes y in place from ``t0`` through sorted ``stops`` (recording the state and torque at those
``record`` marks, rows from ``k_out``), at steps of at most ``h_max``, under the field's phasors of the segment
(referred to ``t_seg``), and stops after at most ``budget`` steps where the next call resumes (``pos``): the same
steps, the same bits however the calls are cut (docs/accuracy.md, "Interruptible runs").

* ``lawson8`` / ``etdrk4``: :func:`gyro_sim.compiled.kernels.integrate` (the field steppers; their table
  :func:`gyro_sim.engine.model._tableau`);
* ``frozen_flow``: :func:`gyro_sim.compiled.frozen_flow.integrate_frozen`;
* ``qs_flow``: :func:`gyro_sim.compiled.qs_flow.integrate_qs`;
* ``free`` (no field, no effect): :func:`gyro_sim.compiled.kernels.integrate_free`.

The compiled tick loop (:mod:`gyro_sim.engine.ticks`) drives the same integrators with the argument tuples of
:func:`arguments`.
"""
from __future__ import annotations

import math
import time
from typing import Iterator

import numpy as np

from gyro_sim.compiled import frozen_flow, kernels, qs_flow
from gyro_sim.engine.model import _case_flag, _tableau

__all__ = ["STEPPERS", "COMPILED_STEPPERS", "CALL_WALL", "CALL_STEPS", "Segment", "arguments", "integrate",
           "tune_call"]

#: the steppers by name (the step plan's choice) → their compiled integrator
STEPPERS = {"lawson8": kernels.integrate, "etdrk4": kernels.integrate, "frozen_flow": frozen_flow.integrate_frozen,
            "qs_flow": qs_flow.integrate_qs, "free": kernels.integrate_free}
#: the steppers the compiled tick loop links (:func:`gyro_sim.engine.ticks.stepper`: all of them); a segment of
#: another would go break by break
COMPILED_STEPPERS = frozenset(STEPPERS)
#: the wall time (s) one stepper call of :func:`integrate` aims at: a long advance is made of calls of about this
#: length, and Python handles a signal (SIGINT, SIGTERM) between two of them
CALL_WALL = 0.1
#: steps of the first call of a long advance, and the bounds the calls' steps are tuned within (:func:`tune_call`);
#: where the calls are cut does not change a bit of the result
CALL_STEPS = (4096, 16, 1 << 24)

#: a command segment as the step plan leaves it (:meth:`gyro_sim.engine.simulator.Simulator._segment`):
#: (t_seg s, Bre T, Bim T, ω rad/s, free, stepper name, h_max s)
Segment = tuple


def arguments(terms, seg: Segment) -> tuple:
    """(Pf, Pz, Pa, Pq): the stepper's own arguments for segment ``seg`` of a model ``terms``
    (:class:`gyro_sim.engine.terms.Terms`) in its slot, lawson8/ETDRK4, frozen_flow, free or qs_flow, the others
    None (the compiled tick loop's form); the argument types are :func:`integrate`'s (numba compiles no new
    signature of the stepper)."""
    t_seg, Bre, Bim, om, free, method, h_max = seg
    case = None if terms.attitude else True
    if method in ("frozen_flow", "qs_flow"):
        ax = terms.sym_axis
        head = (Bre, Bim, om, terms.Jinv, terms.J[(ax + 1) % 3], terms.J[ax], ax, terms.c_m, terms.w, terms.tail)
        if method == "qs_flow":
            return None, None, None, (*head, case)  # (no effect runs in these flows: no eff)
        return None, (*head, terms.inv_tau, case), None, None
    if free:
        return None, None, (terms.Jinv, terms.inv_ref, terms.free_axis, terms.tau), None
    A, b, c = _tableau(method)  # (made on first use: a tick loop may be a process's first lawson8 run)
    P = (Bre, Bim, om, terms.Jinv, terms.c_m, terms.w, terms.tail, terms.lam, terms.eff, A, b, c, case)
    return P, None, None, None


def integrate(terms, y: np.ndarray, t0: float, t_end: float, seg: Segment, stops: np.ndarray, record: np.ndarray,
              out_y: np.ndarray, out_N: np.ndarray, k_out: int, call_steps: int) -> Iterator[tuple[int, int, int]]:
    """Integrate ``y`` (in place) from ``t0`` to ``t_end`` (s; the last of ``stops``) with segment ``seg``'s stepper
    and step bound (the whole span where the plan has none), recording at ``stops[record]`` into rows of
    ``out_y`` / ``out_N`` from ``k_out``. The stepper is called for at most ``call_steps`` steps at a time and
    resumes where it stopped (the same steps, the same bits: gyro_sim.compiled.kernels.integrate): between calls
    Python runs, so SIGINT / SIGTERM are handled within about :data:`CALL_WALL` s however long the advance; the
    calls' steps are tuned on the way (:func:`tune_call`).

    Yields, after each call, (the next free row, the steps it took, the steps a call takes now); done when ``y``
    is at ``t_end``."""
    t_seg, Bre, Bim, om, free, method, h_max = seg
    if not math.isfinite(h_max):
        h_max = max(t_end - t0, 1e-300)
    pos = np.zeros(3)
    case = _case_flag(terms.attitude)
    ax = terms.sym_axis if method in ("frozen_flow", "qs_flow") else 0
    tab = None if method in ("frozen_flow", "qs_flow") or free else _tableau(method)
    J, Jinv = terms.J, terms.Jinv
    n = stops.size
    while True:
        budget = call_steps
        w0 = time.perf_counter()
        if method == "frozen_flow":
            k_out, steps = frozen_flow.integrate_frozen(
                y, t0, t_seg, stops, record, h_max, Bre, Bim, om, Jinv, J[(ax + 1) % 3], J[ax], ax, terms.c_m,
                terms.w, terms.tail, terms.inv_tau, out_y, out_N, k_out, *case, pos, budget)
        elif method == "qs_flow":
            k_out, steps = qs_flow.integrate_qs(
                y, t0, t_seg, stops, record, h_max, Bre, Bim, om, Jinv, J[(ax + 1) % 3], J[ax], ax, terms.c_m,
                terms.w, terms.tail, out_y, out_N, k_out, *case, pos, budget)
        elif free:
            k_out, steps = kernels.integrate_free(
                y, t0, stops, record, h_max, Jinv, terms.inv_ref, terms.free_axis, terms.tau, out_y, out_N, k_out,
                pos, budget)
        else:
            k_out, steps = kernels.integrate(
                y, t0, t_seg, stops, record, h_max, Bre, Bim, om, Jinv, terms.c_m, terms.w, terms.tail, terms.lam,
                out_y, out_N, k_out, terms.eff, *tab, *case, pos, budget)
        wall = time.perf_counter() - w0
        yield k_out, steps, call_steps
        if pos[0] >= n:
            return
        call_steps = tune_call(call_steps, wall, steps)
        t0 = float(pos[2])


def tune_call(call_steps: int, wall: float, steps: int) -> int:
    """The steps of the next stepper calls after a call of at most ``call_steps`` steps that took ``wall`` s and
    ``steps`` steps: where it was cut there, towards :data:`CALL_WALL` s a call (double where it took less than a
    quarter of it, in proportion where it took more; the first call of a process also compiles the stepper),
    within :data:`CALL_STEPS`."""
    if steps < call_steps:
        return call_steps
    if wall < 0.25 * CALL_WALL:
        n = 2 * call_steps
    elif wall > CALL_WALL:
        n = int(call_steps * 0.5 * CALL_WALL / wall)
    else:
        return call_steps
    return min(max(n, CALL_STEPS[1]), CALL_STEPS[2])
