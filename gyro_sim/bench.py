"""Work-precision benchmark: the project's integrator against the plain SciPy baseline.

``gyro-sim bench [--quick] [--out DIR] [--scenes NAME ...]`` (:func:`bench_main`) runs, in one
process and on the same scenes,

* the project's integrator (``gyro_sim.run``) at every fidelity level the scene format knows
  (``Scene.fidelity``), sweeping its accuracy knob ``integrator.steps_per_turn``;
* the baseline a user would write: :func:`scipy.integrate.solve_ivp` (DOP853 and LSODA) over a
  NumPy right-hand side of the same model (:func:`numpy_rhs`), sweeping rtol 1e-3 … 1e-10 with
  atol = rtol × the scale of each state component;
* the compiled baseline: classic fixed-step RK4 over a numba right-hand side of that model
  (:mod:`gyro_sim.bench_baseline`), sweeping the number of steps;
* the default scene's quasi-static variant (``torque_model: quasi_static``) beside it (``BenchConfig.variants``);

and measures CPU and wall time, steps, right-hand-side evaluations and the error of the final state
against a converged reference (our integrator at a high steps_per_turn, cross-checked against
DOP853 at rtol 1e-12). It also measures the cost of 50 against 1 solid-sphere modes, the
real-time factor of the default scene, the compiled kernels' cost per right-hand side and per
step, and (full mode only) a 20-minute spin-up. It writes ``DIR/bench.md`` (tables, date,
machine), ``DIR/bench.csv`` and ``DIR/work_precision.png``, and prints the headline ratios.

Timings: each run's CPU time of this process (``time.process_time``) and its wall time. The
headline ratios use CPU time, which other work on a shared machine disturbs far less than wall
time; the real-time factors are wall-clock. Compare ratios measured in one run, never absolute
times across runs. Errors are dimensionless:
``error = max(|L − L_ref| / |L_ref|, min(|q − q_ref|, |q + q_ref|))`` of the final state; for a run
of a reduced fidelity level that averaged out the spin phase (``RunResult.averaged_segments``) the
attitude is not a result, and its error is that of L alone (``|L − L_ref| / |L_ref|``, marked).
"""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import math
import os
import platform
import sys
import time
import typing
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

__all__ = [
    "numpy_rhs",
    "final_error",
    "Row",
    "BenchConfig",
    "quick_config",
    "full_config",
    "fidelity_levels",
    "run_ours",
    "run_baseline",
    "cost_at_error",
    "pareto_front",
    "run_bench",
    "write_outputs",
    "bench_main",
]

DEFAULT_SCENES = ("spinup_thin_shell", "spinup_solid_sphere")
# one scene (or two) for each averaged model: the spin-up model, [M]'s, [K]'s (three stators, ψ-switching)
AVERAGED_SCENES = ("spinup_thin_shell", "constant_field", "rotating_field", "three_stators", "nutation_slow")
TARGET_ERROR = 1e-6
#: accuracy.rtol of the averaged-models part: the averaged models enter at their MU_MAX (gyro_sim.fidelity.mu_max)
AVERAGED_PART_RTOL = 2e-3
OURS = "gyro_sim"  # method label prefix of the project's integrator
#: right-hand-side evaluations per step (frozen_flow, qs_flow: their two, three closed-form passes)
STAGES = {"lawson8": 12, "etdrk4": 4, "frozen_flow": 2, "qs_flow": 3}
#: the accuracy knob of each stepper (integrator.<knob>) and its sweep; steps_per_turn's from BenchConfig
RATE_CHANGES = (3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)


def knob_of(method: str) -> str:
    """The ``integrator`` field that sets the accuracy of a stepper."""
    return "rate_change" if method in ("frozen_flow", "qs_flow") else "steps_per_turn"


def refined(method: str, value: float) -> float:
    """The knob's value that halves the step."""
    return value / 2 if knob_of(method) == "rate_change" else 2 * value
BASELINES = ("DOP853", "LSODA")
#: the compiled baseline's method label (classic RK4, fixed step, numba right-hand side: gyro_sim/bench_baseline.py)
RK4_METHOD = "numba RK4"


#: a baseline's rtol sweep stops once its error is within this factor of the reference's agreement with DOP853 at
#: rtol_ref (below that the rows measure the reference)
REF_FLOOR_FACTOR = 2.0


def is_baseline(method: str) -> bool:
    """Whether a method label is one of the baselines (solve_ivp or the compiled RK4), not ours."""
    return method.startswith("solve_ivp") or method == RK4_METHOD


def _faster(ratio: float) -> str:
    """'2025x faster than' for a cost ratio (theirs / ours) ≥ 1, '3.2x slower than' below 1."""
    if not (isinstance(ratio, float) and math.isfinite(ratio) and ratio > 0):
        return "– against"
    if ratio >= 1:
        return f"{ratio:.0f}x faster than" if ratio >= 100 else f"{ratio:.3g}x faster than"
    return f"{1 / ratio:.3g}x slower than"


# ----------------------------------------------------------------------------------------
# the baseline's right-hand side: the model of docs/numerics.md in plain NumPy


def numpy_rhs(sim) -> Callable[[float, np.ndarray], np.ndarray]:
    """dy/dt of the full model as a NumPy function ``f(t, y)`` for ``solve_ivp``.

    ``sim`` is a :class:`gyro_sim.Simulator`; the field is its present segment (phasors
    referred to s = t − sim.t). State y = [L (case, N·m·s), q (w, x, y, z) body → case,
    e_n (body, T) 3 per mode]; the model (docs/numerics.md):

    * τ_n ė_n + e_n = −τ_n dB_b/dt,  dB_b/dt = Rᵀ dB/dt − Ω_b × B_b,  Ω_b = J⁻¹ Rᵀ L
    * m_b = c (Σ w_n e_n − T_tail dB_b/dt),  dL/dt = N = (R m_b) × B
    * dq/dt = ½ q ⊗ (0, Ω_b)

    Rotations use q/|q| (as the compiled kernel does, so stage values off the unit sphere are
    treated alike); the kinematics use q itself. Equal to ``kernels.nonlinear_part`` plus the
    linear decay −e_n/τ_n to round-off (test/test_bench.py). Written as a user would: NumPy
    arrays, explicit 3-vector cross products (``np.cross`` costs ~15 µs a call).
    """
    Bre, Bim, om = sim.phasors()
    Bre = np.asarray(Bre, float).reshape(-1, 3)
    Bim = np.asarray(Bim, float).reshape(-1, 3)
    om = np.asarray(om, float)
    omBre = om[:, None] * Bre
    omBim = om[:, None] * Bim
    Jinv = np.asarray(sim.Jinv, float)
    c_m = float(sim.c_m)
    w = np.asarray(sim.w, float)
    inv_tau = 1.0 / np.asarray(sim.tau, float) if np.size(sim.tau) else np.zeros(0)
    tail = float(sim.tail)
    t_seg = float(sim.t)
    n = 7 + 3 * inv_tau.size

    def cross(a, b):
        return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])

    def f(t, y):
        s = t - t_seg
        c = np.cos(om * s)
        sn = np.sin(om * s)
        B = c @ Bre + sn @ Bim  # case frame, T
        dB = c @ omBim - sn @ omBre  # T/s
        q = y[3:7]
        qw, qx, qy, qz = q / math.sqrt(q @ q)
        R = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
                      [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
                      [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)]])
        Om = Jinv * (y[0:3] @ R)  # Ω_b = J⁻¹ Rᵀ L
        out = np.empty(n)
        w0, x0, y0, z0 = q
        o0, o1, o2 = Om
        out[3] = -0.5 * (x0 * o0 + y0 * o1 + z0 * o2)
        out[4] = 0.5 * (w0 * o0 + y0 * o2 - z0 * o1)
        out[5] = 0.5 * (w0 * o1 + z0 * o0 - x0 * o2)
        out[6] = 0.5 * (w0 * o2 + x0 * o1 - y0 * o0)
        e = y[7:].reshape(-1, 3)
        if c_m == 0.0:
            out[0:3] = 0.0
            out[7:] = (-e * inv_tau[:, None]).ravel()
            return out
        Bb = B @ R
        dBb = dB @ R - cross(Om, Bb)
        mb = c_m * (w @ e - tail * dBb)
        out[0:3] = cross(R @ mb, B)
        out[7:] = (-e * inv_tau[:, None] - dBb).ravel()
        return out

    return f


def final_error(L: np.ndarray, q: Optional[np.ndarray], L_ref: np.ndarray, q_ref: np.ndarray) -> float:
    """max(|L − L_ref|/|L_ref|, min(|q − q_ref|, |q + q_ref|)) of final states (q normalised).

    ``q = None``: the error of L alone (a run whose attitude phase was averaged out).
    """
    L, L_ref = np.asarray(L, float), np.asarray(L_ref, float)
    eL = float(np.linalg.norm(L - L_ref) / max(np.linalg.norm(L_ref), 1e-300))
    if q is None:
        return eL
    q, q_ref = np.asarray(q, float), np.asarray(q_ref, float)
    q = q / np.linalg.norm(q)
    q_ref = q_ref / np.linalg.norm(q_ref)
    eq = float(min(np.linalg.norm(q - q_ref), np.linalg.norm(q + q_ref)))
    return max(eL, eq)


# ----------------------------------------------------------------------------------------
# measurements


@dataclass
class Row:
    """One measured run. ``knob``/``value``: steps_per_turn or rtol; ``error`` NaN if not known."""

    scene: str
    horizon: float  # simulated s
    method: str
    knob: str
    value: float
    wall: float  # s
    steps: int
    rhs: Optional[int]  # right-hand-side evaluations (None: not counted by that method)
    error: float = float("nan")
    note: str = ""
    L: Optional[np.ndarray] = field(default=None, repr=False)
    q: Optional[np.ndarray] = field(default=None, repr=False)
    averaged: float = 0.0  # simulated s spent in an averaged model (its attitude phase is not a result)
    error_L: float = float("nan")  # |L − L_ref| / |L_ref| alone (comparable across fidelity levels)
    cpu: float = float("nan")  # s, CPU time of this process for the run (time.process_time)

    def score(self, L_ref: np.ndarray, q_ref: np.ndarray) -> float:
        """Set and return ``error`` against a reference: of (L, q), or of L alone where averaged."""
        self.error_L = final_error(self.L, None, L_ref, q_ref)
        self.error = final_error(self.L, None if self.averaged > 0 else self.q, L_ref, q_ref)
        if self.averaged > 0 and "L only" not in self.note:
            self.note = (self.note + "; " if self.note else "") + \
                f"averaged {self.averaged:.3g} s of {self.horizon:g} s: error of L only"
        return self.error

    @property
    def rtf(self) -> float:
        """Real-time factor: simulated seconds per wall second."""
        return self.horizon / self.wall if self.wall > 0 else float("inf")

    @property
    def rtf_cpu(self) -> float:
        """Simulated seconds per CPU second."""
        return self.horizon / self.cpu if self.cpu > 0 else float("nan")

    @property
    def setting(self) -> str:
        if self.knob == "rtol":
            return f"rtol={self.value:.0e}"
        if self.knob == "steps":
            return f"steps={int(self.value)}"
        return f"{self.knob}={self.value:g}"


def fidelity_levels() -> list[str]:
    """The fidelity levels the scene format accepts (``Scene.fidelity``), 'full' first."""
    from .scene import Scene

    fld = Scene.model_fields.get("fidelity")
    levels = [a for a in typing.get_args(fld.annotation) if isinstance(a, str)] if fld is not None else []
    if not levels:
        levels = ["full"]
    return sorted(set(levels), key=lambda s: (s != "full", s))


def ours_levels() -> list[str]:
    """What the work-precision table runs of ours: every fidelity level, and the full model once more
    with each stepper forced (``full/lawson8``, ``full/etdrk4``; ``full`` itself picks by the scene:
    ``integrator.method: auto``)."""
    levels = fidelity_levels()
    return levels[:1] + ["full/lawson8", "full/etdrk4"] + levels[1:]


def _method_label(level: str) -> str:
    return f"{OURS} {level}"


def _timed(fn: Callable, min_wall: float = 0.0, max_reps: int = 1):
    """Run fn() until ``min_wall`` s in total or ``max_reps`` times.

    Returns (wall s, CPU s, result) of the repeat with the least CPU time (``time.process_time``:
    this process's CPU time, which other work on a shared machine disturbs far less than wall time).
    """
    best, total, reps, out = (math.inf, math.inf), 0.0, 0, None
    while True:
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        w, c = time.perf_counter() - w0, time.process_time() - c0
        if c < best[1]:
            best = (w, c)
        total, reps = total + w, reps + 1
        if reps >= max_reps or total >= min_wall:
            return best[0], best[1], out


def _timed_warm(fn: Callable, min_wall: float = 0.0, max_reps: int = 1):
    """fn() once untimed, then :func:`_timed`: a path's first call compiles its numba kernels or loads them from
    numba's cache (neither of which its cost should count; a cache load is not a compile event), and a first
    repeat longer than ``min_wall`` would be the only one.

    Returns (wall s, CPU s, result, s compiling during the timed repeats: 0 when the warm-up did its job).
    """
    from .compile_watch import compile_seconds

    compile_seconds()  # installs numba's compile listener before the warm-up
    fn()
    c0 = compile_seconds()
    wall, cpu, out = _timed(fn, min_wall, max_reps)
    return wall, cpu, out, compile_seconds() - c0


def _scene_overrides(level: str, extra: Optional[dict]) -> dict:
    ov: dict = {"controller": None}
    if level.startswith("full/"):
        ov["integrator.method"] = level.split("/", 1)[1]
    elif level != "full":
        ov["fidelity"] = level
    ov.update(extra or {})
    return ov


def level_method(scene_name: str, level: str = "full", extra: Optional[dict] = None) -> str:
    """The stepper a level starts the scene with (``Simulator._method``)."""
    from .scene import load_scene
    from .simulate import Simulator

    return Simulator(load_scene(scene_name, overrides=_scene_overrides(level, extra)))._method()


def run_ours(scene_name: str, horizon: float, value: Optional[float] = None, level: str = "full",
             extra: Optional[dict] = None, min_wall: float = 0.0, max_reps: int = 1) -> Row:
    """``gyro_sim.run`` of the scene (controller removed) over ``horizon`` s; wall includes setup.
    ``value``: the accuracy knob of the stepper the level starts with (:func:`knob_of`; None: the default).

    RHS evaluations of the full level: 12 per lawson8 step, 4 per ETDRK4 step, 2 per frozen-flow step
    (the stepper the run starts with) + 1 per output sample (the torque).
    """
    from .scene import load_scene
    from .simulate import Simulator, run

    method = level_method(scene_name, level, extra)
    knob = knob_of(method)
    ov = _scene_overrides(level, extra)
    if value is not None:
        ov[f"integrator.{knob}"] = int(value) if knob == "steps_per_turn" else float(value)
    scene = load_scene(scene_name, overrides=ov)
    # at a given knob the integrator alone (no error control's shadow run); the default run as a user gets it
    wall, cpu, res = _timed(lambda: run(scene, duration=horizon, estimate=None if value is None else False),
                            min_wall, max_reps)
    steps = int(res.steps)
    # per step + 1 per output sample; an averaged stretch adds its own (solve_ivp) count
    rhs = STAGES[method] * steps + int(res.t.size) + int(getattr(res, "averaged_rhs_evaluations", 0) or 0)
    segments = getattr(res, "averaged_segments", None) or []
    if value is None:  # the knob the run's plan starts with (gyro_sim/accuracy.py; its error control may change it)
        plan = Simulator(scene, horizon=horizon, quiet=True).step_plan
        value = plan.rate_change if knob == "rate_change" else plan.steps_per_turn[method]
    return Row(scene_name, horizon, _method_label(level), knob, float(value), wall, steps, int(rhs),
               L=res.L[-1].copy(), q=res.q[-1].copy(), averaged=float(sum(t1 - t0 for t0, t1 in segments)),
               cpu=cpu)


def state_scale(sim, L_scale: float) -> np.ndarray:
    """Per-component scale of the state for atol: |L| scale, 1 for q, the field amplitude for e_n."""
    Bre, Bim, _ = sim.phasors()
    B_amp = float(np.sum(np.sqrt(np.sum(np.asarray(Bre) ** 2 + np.asarray(Bim) ** 2, axis=-1)))) or 1.0
    return np.concatenate([np.full(3, L_scale), np.ones(4), np.full(sim.y.size - 7, B_amp)])


def run_baseline(scene_name: str, horizon: float, method: str, rtol: float, L_scale: float,
                 extra: Optional[dict] = None, min_wall: float = 0.0, max_reps: int = 1) -> Row:
    """``solve_ivp(method)`` over :func:`numpy_rhs`, segment by segment between the scene's commands.

    atol = rtol × :func:`state_scale`. The scene's controller is removed (as for our runs);
    its scheduled commands are applied at their instants (field steps as in the simulator).
    Repeated like :func:`run_ours` (``min_wall``, ``max_reps``; the least wall time is kept).
    """
    from .scene import load_scene

    scene = load_scene(scene_name, overrides=_scene_overrides("full", extra))
    wall, cpu, (sim, nfev, steps) = _timed(lambda: _baseline_once(scene, horizon, method, rtol, L_scale),
                                           min_wall, max_reps)
    return Row(scene_name, horizon, f"solve_ivp {method}", "rtol", rtol, wall, steps, nfev,
               L=sim.y[0:3].copy(), q=sim.y[3:7].copy(), cpu=cpu)


def _baseline_once(scene, horizon: float, method: str, rtol: float, L_scale: float):
    from scipy.integrate import solve_ivp

    atol: list = []  # of the state at t = 0, for every segment

    def advance(sim, t_next):
        if not atol:
            atol.append(rtol * state_scale(sim, L_scale))
        sol = solve_ivp(numpy_rhs(sim), (sim.t, t_next), sim.y.copy(), method=method, rtol=rtol, atol=atol[0])
        if sol.status != 0:
            raise RuntimeError(f"solve_ivp {method} rtol={rtol:g}: {sol.message}")
        return sol.y[:, -1].copy(), int(sol.nfev), int(sol.t.size - 1)

    return drive_segments(scene, horizon, advance)


def drive_segments(scene, horizon: float, advance: Callable):
    """A baseline's run of ``scene`` over ``horizon`` s, segment by segment between its scheduled commands.

    ``advance(sim, t_next) -> (y at t_next, RHS evaluations, steps)`` integrates the present segment (field of
    ``sim.phasors()``, referred to s = t − sim.t) from ``sim.t``; q is normalised at each command instant, the
    field phase carried on, and the commands applied there (field steps as in the simulator). Returns (the
    ``Simulator`` at ``horizon``, RHS evaluations, steps).
    """
    from .simulate import Simulator

    sim = Simulator(scene)
    cmds = sorted((c for c in scene.commands if c.time < horizon), key=lambda c: c.time)
    ci = 0

    def apply_due(t):
        nonlocal ci
        while ci < len(cmds) and cmds[ci].time <= t:
            c = cmds[ci]
            sim.set_stator(sim.stator_names.index(c.stator), current=c.current, rate=c.rate)
            ci += 1

    apply_due(0.0)
    stops = sorted({c.time for c in cmds if 0.0 < c.time < horizon} | {horizon})
    nfev = steps = 0
    for t_next in stops:
        y, f, n = advance(sim, t_next)
        y[3:7] /= np.linalg.norm(y[3:7])
        sim.y[:] = y
        sim.phase = np.mod(sim.phase + sim.rate * (t_next - sim.t), 2 * math.pi)
        sim.t = t_next
        nfev += f
        steps += n
        apply_due(t_next)
    return sim, nfev, steps


def pareto_front(rows: Sequence[Row], key: str = "wall") -> list[tuple[float, float]]:
    """(error, cost) of the runs no other run beats in both, by increasing cost (so decreasing error)."""
    pts = sorted((getattr(r, key), r.error) for r in rows
                 if r.error > 0 and math.isfinite(r.error) and getattr(r, key) not in (None, 0))
    front: list[tuple[float, float]] = []
    for c, e in pts:
        if not front or e < front[-1][0]:
            front.append((e, c))
    return front


def cost_at_error(rows: Sequence[Row], target: float = TARGET_ERROR, key: str = "wall") -> float:
    """Cost (``cpu``, ``wall`` or ``rhs``) of one method at error ``target``, by log-log interpolation.

    The curve is the method's Pareto front (:func:`pareto_front`: the best a user gets by choosing
    the setting, so a setting that happens to cost more for less accuracy, as LSODA's stiffness
    switching sometimes does, does not count against the method). The two front points whose
    errors bracket the target are interpolated in log-log. If every run is already below the
    target (a method whose step is set by stability, not by its tolerance), the cheapest run's
    cost is returned (see :func:`below_target`); NaN if no run reaches the target.
    """
    front = pareto_front(rows, key)
    for (e0, c0), (e1, c1) in zip(front, front[1:]):
        if e1 <= target <= e0:
            a = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(c0) + a * (math.log(c1) - math.log(c0)))
    if front and front[0][0] <= target:
        return float(front[0][1])
    return float("nan")


def below_target(rows: Sequence[Row], target: float = TARGET_ERROR) -> bool:
    """Whether every run of a method has an error below ``target`` (its curve never crosses it)."""
    errs = [r.error for r in rows if math.isfinite(r.error)]
    return bool(errs) and all(e <= target for e in errs)


# ----------------------------------------------------------------------------------------
# configuration


@dataclass
class BenchConfig:
    """What to run. Horizons in simulated seconds; ``None`` for a part = skip it."""

    mode: str
    scenes: tuple = DEFAULT_SCENES
    horizon: dict = field(default_factory=dict)  # scene → horizon of the comparison (all methods)
    default_horizon: float = 0.2
    steps_per_turn: tuple = (6, 12, 24, 48, 96, 192, 384, 768)
    rate_changes: tuple = RATE_CHANGES
    spt_ref: int = 3072
    rtols: tuple = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
    rtol_ref: float = 1e-12
    baselines: tuple = BASELINES
    compiled_baseline: bool = True  # the compiled fixed-step RK4 (bench_baseline.py) beside the solve_ivp baselines
    rk4_steps: Optional[tuple] = None  # its sweep of step counts over the horizon (None: bench_baseline.RK4_STEPS)
    # work-precision variants of the scenes (run where the scene is in ``scenes``): (scene, overrides)
    variants: tuple = (("spinup_thin_shell", {"torque_model": "quasi_static"}),)
    long_horizon_scenes: tuple = ()  # our integrator only, over the scene's whole duration
    long_spt_ref: int = 1536
    mode_scene: Optional[str] = "spinup_solid_sphere"
    mode_counts: tuple = (1, 50)
    mode_horizon: float = 1.0
    mode_baseline_horizon: Optional[float] = None  # baseline cost of 1 vs 50 modes (rtol 1e-6)
    rtf_scene: Optional[str] = "spinup_thin_shell"
    rtf_duration: Optional[float] = None  # None: the scene's duration
    spinup_duration: Optional[float] = None  # the 20-minute spin-up (full mode): 1200 s
    averaged_scenes: tuple = AVERAGED_SCENES  # fidelity auto against full on the scenes of each averaged model
    profile: bool = True
    ros: bool = False  # the ros part (bench_ros): first runs, lockstep over DDS, real-time latency
    accuracy: bool = True  # the accuracy part (bench_accuracy): every built-in scene against its stated accuracy
    ticks: bool = True  # the per-tick part (bench_ticks): control ticks in-process, compiled against Python
    accuracy_scenes: Optional[tuple] = None  # its scenes (None: every built-in scene)
    startup: bool = False  # the startup part (bench_scaling): new processes' import and first-run times
    startup_baseline: Optional[str] = None  # a source tree of the code before, timed beside this one
    sweep: bool = False  # the sweep part (bench_scaling): runs/s in-process, on 1 and 2 Dask workers
    only: Optional[str] = None  # run this part alone ("accuracy", "ticks", "startup", "sweep")
    min_wall: float = 0.2  # repeat our (short) runs until this much wall time; keep the least
    max_reps: int = 5

    def horizon_of(self, scene: str) -> float:
        return float(self.horizon.get(scene, self.default_horizon))


def quick_config(scenes: Sequence[str] = DEFAULT_SCENES) -> BenchConfig:
    """0.2 s horizons (100 turns of the default scene's field), every tolerance (141 s wall with --no-ros
    --no-accuracy on 2026-11-25, docs/benchmark.md)."""
    return BenchConfig(mode="quick", scenes=tuple(scenes), default_horizon=0.2,
                       horizon={"spinup_thin_shell": 0.2, "spinup_solid_sphere": 0.2},
                       spt_ref=3072, mode_horizon=1.0, min_wall=0.1, max_reps=3, ros=True, startup=True, sweep=True)


def full_config(scenes: Sequence[str] = DEFAULT_SCENES) -> BenchConfig:
    """A few minutes: 2 s comparison horizons, whole-duration curves of our integrator, the
    baseline's cost with 1 and 50 modes and the 20-minute spin-up."""
    return BenchConfig(mode="full", scenes=tuple(scenes), default_horizon=2.0,
                       horizon={"spinup_thin_shell": 2.0, "spinup_solid_sphere": 2.0},
                       spt_ref=3072, long_horizon_scenes=("spinup_thin_shell",), long_spt_ref=1536,
                       mode_horizon=10.0, mode_baseline_horizon=0.1, spinup_duration=1200.0,
                       min_wall=0.3, max_reps=5, ros=True, startup=True, sweep=True)


# ----------------------------------------------------------------------------------------
# the parts of the benchmark


def _say(msg: str) -> None:
    print(msg, flush=True)


@dataclass
class Results:
    config: BenchConfig
    rows: list = field(default_factory=list)  # work-precision rows (all scenes, methods)
    refs: list = field(default_factory=list)  # dicts: scene, horizon, ref method, agreement
    headline: list = field(default_factory=list)  # dicts: scene, horizon, method, wall@1e-6, rhs@1e-6, speed-up
    modes: list = field(default_factory=list)  # dicts of the mode-cost part
    rtf: list = field(default_factory=list)  # dicts: scene, duration, wall, steps, rtf
    spinup: list = field(default_factory=list)
    profile: list = field(default_factory=list)  # dicts: what, ns
    savings: list = field(default_factory=list)  # dicts: what, how, cpu with the saving and without
    averaged: list = field(default_factory=list)  # dicts: scene, models, wall full/auto, final errors
    ros: list = field(default_factory=list)  # dicts of the ros part (bench_ros)
    ticks: list = field(default_factory=list)  # dicts of the per-tick part (bench_ticks)
    output_rates: list = field(default_factory=list)  # dicts of its output-rate rows (bench_ticks.output_rate_part)
    startup: list = field(default_factory=list)  # dicts of the startup part (bench_scaling)
    sweep: list = field(default_factory=list)  # dicts of the sweep part (bench_scaling)
    accuracy: Optional[object] = None  # the accuracy part (bench_accuracy.AccResults)
    notes: list = field(default_factory=list)
    started: str = ""
    command: str = ""
    wall_total: float = 0.0


def _line(r: Row) -> str:
    return (f"    {r.method:24s} {r.setting:20s} cpu {r.cpu:9.4f} s  wall {r.wall:9.4f} s  steps {r.steps:9d}  "
            f"error {r.error:.2e}")


def variant_label(scene: str, extra: Optional[dict] = None) -> str:
    """The name of a scene with overrides in the tables: ``spinup_thin_shell [torque_model: quasi_static]``."""
    return f"{scene} [{', '.join(f'{k}: {v}' for k, v in extra.items())}]" if extra else scene


def work_precision(res: Results, scene: str, horizon: float, with_baselines: bool = True,
                   spt_ref: Optional[int] = None, extra: Optional[dict] = None) -> None:
    """Every method on one scene (with ``extra`` overrides: a variant, named by :func:`variant_label`) and horizon
    against one converged reference; fills res.rows. The baselines: solve_ivp (``cfg.baselines``) and, with
    ``cfg.compiled_baseline``, the compiled fixed-step RK4 (gyro_sim/bench_baseline.py)."""
    cfg = res.config
    spt_ref = spt_ref or cfg.spt_ref
    label = variant_label(scene, extra)
    _say(f"[{label}, {horizon:g} s] reference: {OURS} full/lawson8, steps_per_turn={spt_ref}")
    ref = run_ours(scene, horizon, spt_ref, "full/lawson8", extra)
    ref.note = "reference"
    L_ref, q_ref = ref.L, ref.q
    L_scale = float(np.linalg.norm(L_ref)) or 1.0
    ref_info = {"scene": label, "horizon": horizon, "reference": f"{OURS} full/lawson8, steps_per_turn={spt_ref}",
                "check": "", "agreement": float("nan"), "ref_cpu": ref.cpu, "check_cpu": float("nan")}
    if with_baselines and cfg.rtol_ref:
        chk = run_baseline(scene, horizon, "DOP853", cfg.rtol_ref, L_scale, extra)
        ref_info.update(check=f"solve_ivp DOP853 rtol={cfg.rtol_ref:.0e}",
                        agreement=final_error(chk.L, chk.q, L_ref, q_ref), check_cpu=chk.cpu)
        _say(f"    cross-check DOP853 rtol={cfg.rtol_ref:.0e}: agreement {ref_info['agreement']:.2e}")
    res.refs.append(ref_info)
    rows: list[Row] = []
    for level in ours_levels():
        try:
            method = level_method(scene, level, extra)
        except Exception as exc:  # a level that does not apply to this scene
            res.notes.append(f"{label}: {_method_label(level)} skipped: {exc}".splitlines()[0])
            _say(f"    {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
            continue
        for value in (cfg.rate_changes if knob_of(method) == "rate_change" else cfg.steps_per_turn):
            try:
                r = run_ours(scene, horizon, value, level, extra, min_wall=cfg.min_wall, max_reps=cfg.max_reps)
            except Exception as exc:  # a level that does not apply to this scene
                res.notes.append(f"{label}: {_method_label(level)} skipped: {exc}".splitlines()[0])
                _say(f"    {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
                break
            r.score(L_ref, q_ref)
            rows.append(r)
            _say(_line(r))
    if with_baselines:
        floor = REF_FLOOR_FACTOR * ref_info["agreement"]
        for method in cfg.baselines:
            for rtol in cfg.rtols:
                r = run_baseline(scene, horizon, method, rtol, L_scale, extra, min_wall=cfg.min_wall,
                                 max_reps=cfg.max_reps)
                r.score(L_ref, q_ref)
                rows.append(r)
                _say(_line(r))
                if r.error <= floor and rtol != cfg.rtols[-1]:
                    # (tighter rtols would measure the reference, not the method: a stiff baseline whose stability
                    # bounds its step costs the same at every rtol)
                    res.notes.append(f"{label}: solve_ivp {method} at rtol < {rtol:.0e} not run: its error "
                                     f"{r.error:.1e} is at the reference's own agreement with DOP853 "
                                     f"{ref_info['agreement']:.1e}")
                    _say(f"    {method}: error at the reference's agreement; tighter rtols skipped")
                    break
        if cfg.compiled_baseline:
            from .bench_baseline import RK4_STEPS, rk4_sweep

            rk4_rows, notes = rk4_sweep(scene, horizon, L_ref, q_ref, extra, cfg.rk4_steps or RK4_STEPS,
                                        cfg.min_wall, cfg.max_reps, label, say=lambda r: _say(_line(r)))
            rows.extend(rk4_rows)
            res.notes.extend(notes)
    for r in rows:
        r.scene = label
        if not with_baselines:
            r.note = "our integrator only (whole scene)" + ("; " + r.note if r.note else "")
        if r.method.startswith(OURS) and r.method != _method_label("full") and r.averaged == 0:
            r.note = (r.note + "; " if r.note else "") + "never averaged here (= full model)"
    res.rows.extend(rows)
    # headline: cost at the target error, speed-up of each method over the baselines
    by_method: dict[str, list[Row]] = {}
    for r in rows:
        by_method.setdefault(r.method, []).append(r)
    costs = {m: tuple(cost_at_error(rs, TARGET_ERROR, k) for k in ("cpu", "rhs", "wall"))
             for m, rs in by_method.items()}
    ours_full = costs.get(_method_label("full"), (float("nan"),) * 3)
    def ratio(a, b):
        return a / b if math.isfinite(a) and math.isfinite(b) and b > 0 else float("nan")

    for m, (cc, cr, cw) in costs.items():
        Lrows = [replace(r, error=r.error_L) for r in by_method[m]]
        res.headline.append({"scene": label, "horizon": horizon, "method": m, "cpu": cc, "wall": cw, "rhs": cr,
                             "flat": below_target(by_method[m]), "whole": not with_baselines,
                             "cpu_L": cost_at_error(Lrows, TARGET_ERROR, "cpu"),
                             "best": min((r.error for r in by_method[m]), default=float("nan")),
                             "speedup": ratio(cc, ours_full[0]), "speedup_wall": ratio(cw, ours_full[2]),
                             "rhs_ratio": ratio(cr, ours_full[1])})


def mode_cost(res: Results) -> None:
    """Our integrator on the solid sphere with 1 and 50 modes (ETDRK4 and frozen_flow at their default knobs);
    the baseline too."""
    cfg = res.config
    scene, T = cfg.mode_scene, cfg.mode_horizon
    # at fixed knobs (the old defaults: the plan's would follow each mode count's own accuracy)
    for level, knob in (("full/etdrk4", 48), ("full/frozen_flow", 1e-4)):
        for n in cfg.mode_counts:
            r = run_ours(scene, T, knob, level, {"modes": int(n)}, min_wall=cfg.min_wall, max_reps=cfg.max_reps)
            res.modes.append({"scene": scene, "modes": n, "method": r.method, "setting": r.setting, "horizon": T,
                              "cpu": r.cpu, "wall": r.wall, "steps": r.steps, "rhs": r.rhs, "rtf": r.rtf,
                              "ns_per_step": 1e9 * r.cpu / max(r.steps, 1)})
            _say(f"[modes] {scene} {r.method} modes={n}: cpu {r.cpu:.4f} s, wall {r.wall:.4f} s, steps {r.steps}, "
                 f"{r.rtf:.1f}x real time")
    if cfg.mode_baseline_horizon:
        Tb = cfg.mode_baseline_horizon
        for method in cfg.baselines:
            for n in cfg.mode_counts:
                ref = run_ours(scene, Tb, 48, "full/etdrk4", {"modes": int(n)})
                r = run_baseline(scene, Tb, method, 1e-6, float(np.linalg.norm(ref.L)) or 1.0, {"modes": int(n)})
                res.modes.append({"scene": scene, "modes": n, "method": r.method, "setting": r.setting,
                                  "horizon": Tb, "cpu": r.cpu, "wall": r.wall, "steps": r.steps, "rhs": r.rhs,
                                  "rtf": r.rtf, "ns_per_step": 1e9 * r.cpu / max(r.steps, 1)})
                _say(f"[modes] {scene} modes={n} {r.method} rtol=1e-6 over {Tb:g} s: cpu {r.cpu:.3f} s, "
                     f"steps {r.steps}, RHS {r.rhs}")


def _averaged_time(r) -> float:
    return float(sum(t1 - t0 for t0, t1 in (getattr(r, "averaged_segments", None) or [])))


def realtime_factor(res: Results) -> None:
    """The default scene as a user runs it (controller included), whole duration, at each fidelity level."""
    from .scene import load_scene
    from .simulate import run

    cfg = res.config
    L_full = None
    for level in fidelity_levels():
        try:
            scene = load_scene(cfg.rtf_scene, overrides=None if level == "full" else {"fidelity": level})
            T = cfg.rtf_duration or scene.duration
            wall, cpu, r = _timed(partial(run, scene, duration=T), 0.0, 1)
        except Exception as exc:
            res.notes.append(f"real-time factor: {_method_label(level)} skipped: {exc}".splitlines()[0])
            _say(f"[real time] {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
            continue
        res.rtf.append({"scene": cfg.rtf_scene, "method": _method_label(level),
                        "what": "as shipped (controller on, output samples)", "duration": T, "wall": wall,
                        "cpu": cpu, "steps": int(r.steps), "rtf": T / wall, "rtf_cpu": T / cpu,
                        "averaged": _averaged_time(r),
                        "error_L": float("nan") if L_full is None else final_error(r.L[-1], None, L_full, None),
                        "spin_rev_s": float(r.spin_rate[-1] / (2 * math.pi)),
                        "theta_deg": float(np.degrees(r.theta[-1]))})
        if level == "full":
            L_full = r.L[-1].copy()
        _say(f"[real time] {cfg.rtf_scene} {T:g} s, {_method_label(level)}: wall {wall:.3f} s, cpu {cpu:.3f} s, "
             f"steps {r.steps}, real-time factor {T / wall:.1f} (per CPU second {T / cpu:.1f})")


#: the 20-minute spin-up's accuracies: (label, scene overrides). Its goal is L (the attitude of a rotor turned
#: through 2·10⁶ rad cannot be held to 1e-6 rad: the plan's floor is 1e-12 of the phase, docs/accuracy.md), so the
#: rows that time it hold L alone; the scene's own accuracy (attitude 1e-6 rad) is a row of its own
SPINUP_RUNS: tuple = (
    ("rtol 1e-6, attitude: null", {"accuracy": {"rtol": 1e-6, "attitude": None}}),
    ("rtol 1e-6, attitude: null, output 1 Hz", {"accuracy": {"rtol": 1e-6, "attitude": None}, "output.rate": 1.0}),
    ("as shipped: rtol 1e-6, attitude 1e-6 rad", {}),
)
#: its reference for L: the same run at this rtol
SPINUP_REF_RTOL = 1e-9


def long_spinup(res: Results) -> None:
    """20-minute spin-up of the default scene without its controller (fidelity full, ``method: auto``), at the
    accuracies of :data:`SPINUP_RUNS`, and at each other fidelity level (L to 1e-6).

    Each row's error of L is measured against a run at rtol :data:`SPINUP_REF_RTOL` (final state, relative); its
    attitude error is the run's own estimate (``RunResult.error_estimate``; no reference holds the phase of 2·10⁶
    rad better than the run at the floor)."""
    from .scene import load_scene
    from .simulate import run

    cfg = res.config
    T = cfg.spinup_duration
    base = {"duration": T, "controller": None}
    target = next((s.rate for s in load_scene("spinup_thin_shell").stators if s.current > 0), float("nan"))
    ref = run(load_scene("spinup_thin_shell", overrides={**base, "accuracy": {"rtol": SPINUP_REF_RTOL,
                                                                                "attitude": None}}))

    def entry(method, setting, w, c, r):
        est = r.error_estimate
        return {"method": method, "setting": setting, "duration": T, "wall": w, "cpu": c, "steps": int(r.steps),
                "rtf": T / w, "rtf_cpu": T / c, "error": est.attitude if est is not None else float("nan"),
                "error_L": final_error(r.L[-1], None, ref.L[-1], None), "estimate_L": est.L if est is not None else float("nan"),
                "averaged": _averaged_time(r), "spin_rev_s": float(r.spin_rate[-1] / (2 * math.pi)),
                "spin_fraction": float(r.spin_rate[-1] / target), "theta_deg": float(np.degrees(r.theta[-1]))}

    runs = [(_method_label("full"), label, {**base, **ov}) for label, ov in SPINUP_RUNS]
    runs += [(_method_label(level), "rtol 1e-6, attitude: null", {**base, **SPINUP_RUNS[0][1], "fidelity": level})
             for level in fidelity_levels() if level != "full"]
    for method, setting, ov in runs:
        try:
            sc = load_scene("spinup_thin_shell", overrides=ov)
            run(sc, duration=1.0)  # (compiles or loads what it needs before the clock runs)
            w, c, r = _timed(partial(run, sc), 0.0, 1)
        except Exception as exc:  # a level that does not apply
            res.notes.append(f"spin-up: {method} skipped: {exc}".splitlines()[0])
            _say(f"[spin-up {T:g} s] {method}: skipped ({str(exc).splitlines()[0]})")
            continue
        e = entry(method, setting, w, c, r)
        res.spinup.append(e)
        _say(f"[spin-up {T:g} s] {method} {setting}: wall {w:.3f} s, cpu {c:.3f} s, steps {r.steps}, error of L "
             f"{e['error_L']:.1e} (estimate {e['estimate_L']:.1e}), attitude ≈ {_fmt(e['error'], '.1e')} rad, "
             f"spin {e['spin_rev_s']:.2f} rev/s")


def averaged_models(res: Results) -> None:
    """Each averaged model where it applies: ``fidelity: auto`` against ``full`` on scenes as shipped (whole
    duration, controllers on), wall time of each (least of the repeats), the time averaged and by which model,
    and the final errors of auto against full: L (relative, vector), spin (relative), θ (rad)."""
    from .scene import load_scene
    from .simulate import run

    cfg = res.config
    for name in cfg.averaged_scenes:
        # at an rtol that lets the averaged models in at their MU_MAX (the default rtol 1e-6 averages only where
        # ε ≤ 2e-6: fidelity.mu_max); both runs at that accuracy
        sc = load_scene(name, overrides={"fidelity": "full", "accuracy.rtol": AVERAGED_PART_RTOL})
        sa = sc.model_copy(update={"fidelity": "auto"})
        for warm in (sc, sa):  # compile what this scene's types need before the clock runs
            run(warm, duration=min(sc.duration, 2.0 / sc.output.rate))
        wf, cf, f = _timed(partial(run, sc), cfg.min_wall, cfg.max_reps)
        wa, ca, a = _timed(partial(run, sa), cfg.min_wall, cfg.max_reps)
        e = {"scene": name, "duration": sc.duration, "models": ", ".join(sorted(set(a.averaged_models))) or "none",
             "averaged": _averaged_time(a), "wall_full": wf, "wall_auto": wa, "cpu_full": cf, "cpu_auto": ca,
             "speedup": cf / ca, "wall_speedup": wf / wa, "error_L": final_error(a.L[-1], None, f.L[-1], None),
             "error_spin": float(abs(a.spin_rate[-1] / f.spin_rate[-1] - 1)),
             "error_theta": float(abs(a.theta[-1] - f.theta[-1]))}
        res.averaged.append(e)
        _say(f"[averaged] {name} {sc.duration:g} s: {e['models']} over {e['averaged']:.3g} s; CPU full {cf:.3g} s, "
             f"auto {ca:.3g} s ({e['speedup']:.1f}x; wall {wf:.3g} s, {wa:.3g} s); L {e['error_L']:.1e}, spin {e['error_spin']:.1e}, "
             f"θ {e['error_theta']:.1e} rad")


SAVINGS: tuple = (
    # (what the scene skips, overrides of the scene that skips it, the overrides that make it do that work,
    #  what the comparison is)
    ("stators that are off", {}, {"stators.0.current": 1e-15, "stators.1.current": 1e-15},
     "z1, z2 at 1e-15 A (in the field sum: 3 phasors) against off"),
    ("effects that are off", {}, {"effects": {"gas_drag": {"transverse": [0.0], "axial": [0.0]}}},
     "gas drag with zero coefficients (effects on: frozen_flow does not apply) against none"),
    ("eddy-mode states (quasi-static torque)", {"torque_model": "quasi_static"}, {"torque_model": "lag"},
     "quasi_static (7 states, [K] (1.2)) against lag (10 states, [M] (2.15)): other physics, the same rotor; "
     "the quasi-static torque grows with the slip without bound, so frozen_flow's step is shorter"),
    ("output samples tied to the step", {}, {"output.rate": 1000.0},
     "1000 Hz output against 50 Hz: each sample costs a torque evaluation and is a stop, so a step longer "
     "than the sample spacing (frozen_flow's) is cut to it"),
    ("attitude of an isotropic rotor nobody reads", {"rotor.inertia": [5.592e-6] * 3, "output.attitude": False},
     {"output.attitude": True},
     "inertia [J, J, J]: output.attitude false (L and the eddy modes in the case frame, no q) against true "
     "(frozen_flow both; without attitude the accuracy plan is for L alone, so the step counts may differ)"),
)


def savings(res: Results) -> None:
    """What skipping each unneeded piece is worth: the default scene (no controller, the comparison horizon)
    with the saving and with the work it skips forced in, CPU time of each (least of the repeats), and the
    cost of the Euler angles a run computes only when they are read.

    Every path is run once before it is timed (:func:`_timed_warm`; the attitude-free frozen-flow step of the
    ``output.attitude: false`` row is compiled or loaded from numba's cache on its first call, which read as a
    0.00x saving when it was timed); each row keeps the seconds numba compiled during its timed runs
    (``compile``, ``compile_forced``: 0)."""
    from .scene import load_scene
    from .simulate import Simulator, run

    cfg = res.config
    T = cfg.horizon_of("spinup_thin_shell")
    for what, skipping, forced, how in SAVINGS:
        base = {"controller": None, **skipping}
        rows = []
        for ov in (base, {**base, **forced}):
            sc = load_scene("spinup_thin_shell", overrides=ov)
            w, c, r, comp = _timed_warm(partial(run, sc, duration=T), cfg.min_wall, cfg.max_reps)
            rows.append((c, int(r.steps), Simulator(sc)._method(), comp))
        (c0, n0, m0, k0), (c1, n1, m1, k1) = rows
        res.savings.append({"what": what, "how": how, "horizon": T, "cpu": c0, "cpu_forced": c1, "steps": n0,
                            "steps_forced": n1, "method": m0, "method_forced": m1, "ratio": c1 / c0,
                            "compile": k0, "compile_forced": k1})
        _say(f"[savings] {what}: {c0 * 1e3:.2f} ms ({m0}, {n0} steps) against {c1 * 1e3:.2f} ms ({m1}, {n1} steps) "
             f"= {c1 / c0:.2f}x ({how})")
    sc = load_scene("spinup_thin_shell", overrides={"controller": None, "duration": 60.0})
    _, c_run, r, k0 = _timed_warm(lambda: run(sc), cfg.min_wall, cfg.max_reps)
    _, c_eul, _, k1 = _timed_warm(lambda: replace(r, _euler=None).euler, cfg.min_wall, cfg.max_reps)
    res.savings.append({"what": "Euler angles nobody reads", "how": "RunResult.euler computed on first access "
                        f"(60 s, {r.t.size} samples) against the run itself", "horizon": 60.0, "cpu": c_run,
                        "cpu_forced": c_run + c_eul, "steps": int(r.steps), "steps_forced": int(r.steps),
                        "method": "", "method_forced": "", "ratio": (c_run + c_eul) / c_run,
                        "compile": k0, "compile_forced": k1})
    _say(f"[savings] Euler angles: {c_eul * 1e3:.2f} ms on first access against {c_run * 1e3:.2f} ms for the run")


def profile_kernels(res: Results) -> None:
    """Cost of the compiled pieces on the default scene (thin shell) and the solid sphere.

    ns per right-hand side (``kernels.nonlinear_part_at`` in a compiled loop), per field evaluation
    (``kernels.field_case``), per ETDRK4 step (``kernels.integrate_etd`` over one long span), the
    NumPy baseline's right-hand side, and the Python cost of one ``Simulator.advance`` call.
    """
    from . import kernels
    from .scene import load_scene
    from .simulate import Simulator

    loop_rhs, loop_field = _profile_loops()
    cases = [("spinup_thin_shell", {}), (res.config.mode_scene or "spinup_solid_sphere", {"modes": 1}),
             (res.config.mode_scene or "spinup_solid_sphere", {"modes": 50})]
    for name, extra in cases:
        sim = Simulator(load_scene(name, overrides=_scene_overrides("full", extra)))
        Bre, Bim, om = sim.phasors()
        y = sim.y.copy()
        F = np.zeros(y.size)
        work = np.zeros(25)
        args = (y, Bre, Bim, om, sim.Jinv, sim.c_m, sim.w, sim.tail, sim.tau.size, F, work, sim.eff)
        label = name + (f" modes={extra['modes']}" if extra else "")
        loop_rhs(10, *args)
        loop_field(10, Bre, Bim, om, work[0:3], work[3:6])
        n = 500_000
        t_rhs = min(_once(partial(loop_rhs, n, *args)) for _ in range(3)) / n
        t_field = min(_once(partial(loop_field, n, Bre, Bim, om, work[0:3], work[3:6])) for _ in range(3)) / n
        h = sim._max_step(False, "etdrk4")
        k = 200_000
        stops, rec = np.array([k * h]), np.array([False])
        oy, oN = np.zeros((1, y.size)), np.zeros((1, 3))

        def integ(sim=sim, stops=stops, rec=rec, h=h, Bre=Bre, Bim=Bim, om=om, oy=oy, oN=oN):  # (bound now: B023)
            yy = sim.y.copy()
            return kernels.integrate_etd(yy, 0.0, 0.0, stops, rec, h, Bre, Bim, om, sim.Jinv, sim.c_m, sim.w,
                                         sim.tail, sim.lam, oy, oN, 0, sim.eff)

        integ()
        t_step = min(_once(integ) for _ in range(3)) / k
        t_ff = _frozen_flow_step_cost(sim, Bre, Bim, om)
        t_rk4 = _rk4_step_cost(sim)
        f = numpy_rhs(sim)
        m = 2000
        t_np = min(_once(lambda f=f, y=y, m=m: [f(1e-3, y) for _ in range(m)]) for _ in range(3)) / m
        for what, sec in (("RHS, compiled (nonlinear_part_at)", t_rhs), ("field B, dB/dt (field_case)", t_field),
                          ("ETDRK4 step (integrate_etd)", t_step), ("frozen_flow step (integrate_frozen)", t_ff),
                          ("RK4 step, compiled baseline (bench_baseline.rk4_span, 4 RHS)", t_rk4),
                          ("RHS, NumPy baseline", t_np)):
            if math.isfinite(sec):
                res.profile.append({"case": label, "what": what, "ns": sec * 1e9})
        res.profile.append({"case": label, "what": "ETDRK4 step / compiled RHS", "ns": t_step / t_rhs,
                            "unit": "ratio"})
        _say(f"[profile] {label}: RHS {t_rhs * 1e9:.0f} ns, field {t_field * 1e9:.0f} ns, "
             f"step {t_step * 1e9:.0f} ns ({t_step / t_rhs:.2f} RHS), frozen_flow step {t_ff * 1e9:.0f} ns, "
             f"compiled baseline's RK4 step {t_rk4 * 1e9:.0f} ns, "
             f"NumPy RHS {t_np * 1e9:.0f} ns")
    # Python cost of one call of Simulator.advance (tiny span: one step)
    sim = Simulator(load_scene("spinup_thin_shell", overrides={"controller": None}))
    h = sim._max_step(False, "etdrk4")
    m = 2000
    t_adv = _once(lambda: [sim.advance(sim.t + 0.5 * h) for _ in range(m)]) / m
    res.profile.append({"case": "spinup_thin_shell", "what": "Simulator.advance call of one step (Python + 1 step)",
                        "ns": t_adv * 1e9})
    _say(f"[profile] Simulator.advance of one step: {t_adv * 1e6:.1f} µs")


def _frozen_flow_step_cost(sim, Bre, Bim, om) -> float:
    """Seconds per frozen-flow step (``frozen_flow.integrate_frozen`` over 20 000 steps at the scene's
    rate_change, else the default), NaN where the stepper does not apply."""
    from . import effects, frozen_flow

    ax = frozen_flow.supported(sim.J)
    if ax < 0 or sim.eff[effects.ON] != 0.0:
        return float("nan")
    h = sim._frozen_flow_step()
    if not math.isfinite(h):
        return float("nan")
    k = 20_000
    stops, rec = np.array([k * h]), np.array([False])
    oy, oN = np.zeros((1, sim.y.size)), np.zeros((1, 3))

    def integ():
        return frozen_flow.integrate_frozen(sim.y.copy(), 0.0, 0.0, stops, rec, h, Bre, Bim, om, sim.Jinv,
                                            sim.J[(ax + 1) % 3], sim.J[ax], ax, sim.c_m, sim.w, sim.tail,
                                            1.0 / sim.tau, oy, oN, 0, sim.eff, None)  # (None: as simulate passes it)

    integ()
    return min(_once(integ) for _ in range(3)) / k


def _rk4_step_cost(sim) -> float:
    """CPU seconds per step of the compiled baseline's RK4 (``bench_baseline.rk4_span``, 4 right-hand sides) over
    100 000 steps of 0.1 µs from the scene's initial state (NaN where it has effects the baseline lacks)."""
    from . import effects
    from .bench_baseline import model_args, rk4_span, warm

    if sim.eff[effects.ON] != 0.0:
        return float("nan")
    warm()
    args = model_args(sim)
    k = 100_000
    return min(_once(lambda: rk4_span(sim.y.copy(), 1e-7, k, *args)) for _ in range(3)) / k


_LOOPS: list = []


def _profile_loops():
    """Compiled loops around ``kernels.nonlinear_part_at`` (with the phases computed each call, as a
    stepper's first stage does) and ``kernels.field_case`` (built once)."""
    if not _LOOPS:
        from numba import njit

        from . import kernels

        nonlinear_part_at, phasor_trig, field_case = kernels.nonlinear_part_at, kernels.phasor_trig, kernels.field_case

        @njit(cache=False)
        def loop_rhs(n, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff):
            acc = 0.0
            cs = np.empty(om.shape[0])
            sn = np.empty(om.shape[0])
            for i in range(n):
                phasor_trig(1e-7 * i, om, cs, sn)
                nonlinear_part_at(cs, sn, 1e-7 * i, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff)
                acc += F[0]
            return acc

        @njit(cache=False)
        def loop_field(n, Bre, Bim, om, B, dB):
            acc = 0.0
            for i in range(n):
                field_case(1e-7 * i, Bre, Bim, om, B, dB)
                acc += B[0]
            return acc

        _LOOPS.extend([loop_rhs, loop_field])
    return _LOOPS[0], _LOOPS[1]


def scaling_parts(res: Results, only: Optional[str] = None) -> None:
    """The startup and sweep parts (gyro_sim/bench_scaling.py) where the config has them (``only``: that one)."""
    from .bench_scaling import startup_part, sweep_part

    cfg, quick = res.config, res.config.mode == "quick"
    if only == "startup" or (only is None and cfg.startup):
        startup_part(res, quick, baseline=cfg.startup_baseline, say=_say)
    if only == "sweep" or (only is None and cfg.sweep):
        sweep_part(res, quick, say=_say)


def _once(fn) -> float:
    """CPU seconds of one call (time.process_time)."""
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def run_bench(cfg: BenchConfig, out: Path, command: str = "") -> Results:
    """Run every part of ``cfg``, write DIR/bench.md, bench.csv, work_precision.png; return the results."""
    res = Results(cfg, started=_dt.datetime.now().astimezone().isoformat(timespec="seconds"), command=command)
    w0 = time.perf_counter()
    if cfg.only in ("startup", "sweep"):
        scaling_parts(res, cfg.only)
        res.wall_total = time.perf_counter() - w0
        write_outputs(res, Path(out))
        return res
    if cfg.only == "accuracy":
        from .bench_accuracy import accuracy_part

        accuracy_part(res, cfg.mode == "quick", list(cfg.accuracy_scenes) if cfg.accuracy_scenes else None, _say)
        res.wall_total = time.perf_counter() - w0
        write_outputs(res, Path(out))
        return res
    if cfg.only == "ticks":
        from .bench_ticks import output_rate_part, ticks_part

        ticks_part(res, quick=cfg.mode == "quick")
        output_rate_part(res, quick=cfg.mode == "quick")
        res.wall_total = time.perf_counter() - w0
        write_outputs(res, Path(out))
        return res
    for scene in cfg.scenes:
        work_precision(res, scene, cfg.horizon_of(scene))
        for base, extra in cfg.variants:
            if base == scene:
                work_precision(res, scene, cfg.horizon_of(scene), extra=dict(extra))
    for scene in cfg.long_horizon_scenes:
        from .scene import load_scene

        T = load_scene(scene).duration
        work_precision(res, scene, T, with_baselines=False, spt_ref=cfg.long_spt_ref)
    if cfg.mode_scene:
        mode_cost(res)
    if cfg.rtf_scene:
        realtime_factor(res)
    if cfg.spinup_duration:
        long_spinup(res)
    if cfg.averaged_scenes:
        averaged_models(res)
    if cfg.profile:
        savings(res)
        profile_kernels(res)
    if cfg.ticks:
        from .bench_ticks import output_rate_part, ticks_part

        ticks_part(res, quick=cfg.mode == "quick")
        output_rate_part(res, quick=cfg.mode == "quick")
    if cfg.ros:
        from .bench_ros import ros_part

        ros_part(res, quick=cfg.mode == "quick")
    scaling_parts(res)
    if cfg.accuracy:
        from .bench_accuracy import accuracy_part

        accuracy_part(res, cfg.mode == "quick", list(cfg.accuracy_scenes) if cfg.accuracy_scenes else None, _say)
    res.wall_total = time.perf_counter() - w0
    write_outputs(res, Path(out))
    return res


# ----------------------------------------------------------------------------------------
# outputs


def _fmt(x, spec: str = ".3g") -> str:
    if x is None:
        return "–"
    if isinstance(x, float) and not math.isfinite(x):
        return "–"
    return format(x, spec)


def headline_lines(res: Results) -> list[str]:
    """The headline ratios, one sentence each (printed and at the top of bench.md).

    Costs are CPU seconds of this process (``time.process_time``); the wall-clock ratio follows in
    brackets. Both come from the same runs.
    """
    lines = both_ratios_lines(res)
    full = _method_label("full")
    for h in res.headline:
        if is_baseline(h["method"]):
            flat = (f"; every {h['method']} setting is below {TARGET_ERROR:.0e}: its cheapest run"
                    + (", its step being set by stability" if h["method"].startswith("solve_ivp") else "")
                    ) if h.get("flat") else ""
            ours = _ours(res, h)
            lines.append(f"{h['scene']} ({h['horizon']:g} s): at error {TARGET_ERROR:.0e}, {full} is "
                         f"{_faster(h['speedup'])} {h['method']} (CPU {_fmt(ours.get('cpu'), '.3g')} s "
                         f"vs {_fmt(h['cpu'], '.3g')} s; wall-clock ratio {_fmt(h['speedup_wall'], '.3g')}x); "
                         f"{h['method']} makes {_fmt(h['rhs_ratio'], '.2f')}x our RHS evaluations{flat}")
        elif h.get("whole"):
            reach = (f"costs {_fmt(h['cpu'], '.3g')} CPU s, {_fmt(h['horizon'] / h['cpu'], '.3g')} simulated s "
                     f"per CPU s" if math.isfinite(h["cpu"]) else
                     f"is out of reach (best {_fmt(h['best'], '.1e')})")
            lines.append(f"{h['scene']} (whole {h['horizon']:g} s, no controller): {h['method']} at error "
                         f"{TARGET_ERROR:.0e} {reach}; at |ΔL|/|L| = {TARGET_ERROR:.0e} alone: "
                         f"{_fmt(h['cpu_L'], '.3g')} CPU s")
        elif h["method"] != full:
            lines.append(f"{h['scene']} ({h['horizon']:g} s): at error {TARGET_ERROR:.0e}, {h['method']} costs "
                         f"{_fmt(h['speedup'], '.3g')}x the CPU time of {full}")
    for meth in dict.fromkeys(m["method"] for m in res.modes if m["method"].startswith(OURS)):
        byn = {m["modes"]: m for m in res.modes if m["method"] == meth}
        ns = sorted(byn)
        if len(ns) >= 2:
            a, b = byn[ns[0]], byn[ns[-1]]
            lines.append(f"{res.config.mode_scene}: {ns[-1]} modes cost {b['cpu'] / a['cpu']:.2f}x {ns[0]} mode "
                         f"with {meth} (same {a['steps']} steps over {a['horizon']:g} s: {b['steps'] == a['steps']}; "
                         f"wall-clock ratio {b['wall'] / a['wall']:.2f}x)")
    for m in res.config.baselines:
        bb = {x["modes"]: x for x in res.modes if x["method"] == f"solve_ivp {m}"}
        if len(bb) >= 2:
            a, b = bb[min(bb)], bb[max(bb)]
            lines.append(f"{res.config.mode_scene}: solve_ivp {m} rtol=1e-6: {max(bb)} modes cost "
                         f"{b['cpu'] / a['cpu']:.0f}x {min(bb)} mode ({b['steps']} vs {a['steps']} steps "
                         f"over {a['horizon']:g} s)")
    for r in res.rtf:
        avg = (f", {r['averaged']:.3g} s averaged, |ΔL|/|L| = {r['error_L']:.1e} vs full"
               if r.get("averaged") else "")
        lines.append(f"{r['scene']} ({r['duration']:g} s, {r['what']}), {r['method']}: real-time factor "
                     f"{r['rtf']:.1f} (wall {r['wall']:.3g} s; {r['rtf_cpu']:.1f} per CPU second; "
                     f"{r['steps']} steps{avg})")
    for s in res.spinup:
        avg = f", {s['averaged']:.0f} s averaged" if s.get("averaged") else ""
        lines.append(f"spin-up {s['duration']:g} s, {s['method']} {s['setting']}: real-time factor {s['rtf']:.3g} "
                     f"(wall {s['wall']:.3g} s, CPU {s['cpu']:.3g} s{avg}), error of L {_fmt(s['error_L'], '.1e')}, attitude "
                     f"≈ {_fmt(s['error'], '.1e')} rad (estimate), spin {s['spin_rev_s']:.1f} rev/s "
                     f"({100 * s['spin_fraction']:.2f} % of the field rate)")
    from .bench_ros import headline as ros_headline
    from .bench_scaling import headline as scaling_headline

    return lines + ros_headline(res) + scaling_headline(res)


def speedup_table(res: Results) -> list[dict]:
    """Per compared scene and horizon: our cost at the target error and each baseline's ratio to it.

    Dicts: scene, horizon, ours (CPU s of ``gyro_sim full``), and per baseline method its CPU s (``cost``) and
    the ratio theirs / ours (``ratio``; > 1: ours is faster) under ``baselines``."""
    out = []
    for h in res.headline:
        if h["method"] != _method_label("full") or h.get("whole"):
            continue
        bl = {x["method"]: {"cost": x["cpu"], "ratio": x["speedup"], "flat": x.get("flat")}
              for x in res.headline if x["scene"] == h["scene"] and x["horizon"] == h["horizon"]
              and is_baseline(x["method"])}
        if bl:
            out.append({"scene": h["scene"], "horizon": h["horizon"], "ours": h["cpu"], "baselines": bl})
    return out


def both_ratios_lines(res: Results) -> list[str]:
    """One line per compared scene: our cost at the target error against SciPy's DOP853 and the compiled RK4."""
    lines = []
    for t in speedup_table(res):
        parts = [f"{_faster(v['ratio'])} {m} ({_fmt(v['cost'], '.3g')} s)" for m, v in t["baselines"].items()
                 if m in (f"solve_ivp {BASELINES[0]}", RK4_METHOD)]
        if parts:
            lines.append(f"{t['scene']} ({t['horizon']:g} s): at error {TARGET_ERROR:.0e} {_method_label('full')} "
                         f"costs {_fmt(t['ours'], '.3g')} CPU s: " + " and ".join(parts))
    return lines


def _ours(res: Results, h: dict) -> dict:
    for x in res.headline:
        if x["scene"] == h["scene"] and x["horizon"] == h["horizon"] and x["method"] == _method_label("full"):
            return x
    return {}


CSV_FIELDS = ["scene", "horizon_s", "method", "knob", "value", "cpu_s", "wall_s", "steps", "rhs_evals", "error",
              "error_L", "realtime_factor", "note"]


def write_outputs(res: Results, out: Path) -> None:
    """DIR/bench.csv (one line per work-precision run), DIR/bench.md, DIR/work_precision.png."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "bench.csv", "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(CSV_FIELDS)
        for r in res.rows:
            wr.writerow([r.scene, f"{r.horizon:g}", r.method, r.knob, f"{r.value:g}", f"{r.cpu:.6g}", f"{r.wall:.6g}",
                         r.steps, "" if r.rhs is None else r.rhs, f"{r.error:.6g}", f"{r.error_L:.6g}",
                         f"{r.rtf:.6g}", r.note])
    if res.accuracy is not None:
        from .bench_accuracy import csv_rows

        rows = csv_rows(res.accuracy)
        with open(out / "accuracy.csv", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["scene"])
            wr.writeheader()
            wr.writerows(rows)
    (out / "bench.md").write_text(markdown(res))
    if res.rows:
        plot_work_precision(res, out / "work_precision.png")


def machine() -> str:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.platform()}, {cpu or platform.machine()}, os.cpu_count() = {os.cpu_count()}"


def versions() -> str:
    import numba
    import scipy

    return (f"Python {platform.python_version()}, NumPy {np.__version__}, SciPy {scipy.__version__}, "
            f"numba {numba.__version__}")


def _table(title: str, columns: str, rows: list, after: Sequence[str] = ()) -> list:
    """Markdown lines of a section: its title, a table with ``columns`` ("a | b | c") and ``rows`` (each
    "x | y | z"), then ``after`` and a blank line."""
    n = columns.count("|") + 1
    return ([title, "", f"| {columns} |", "|" + "---|" * n] + [f"| {r} |" for r in rows]
            + (["", *after] if after else []) + [""])


def markdown(res: Results) -> str:
    cfg = res.config
    load = ""
    if hasattr(os, "getloadavg"):
        load = f" (load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())})"
    L = [f"# gyro_sim work-precision benchmark ({cfg.mode})", "",
         f"- date: {res.started}",
         f"- machine: {machine()}{load}",
         f"- software: {versions()}",
         f"- command: `{res.command or 'gyro_sim.bench.run_bench'}`",
         f"- total wall time of the benchmark: {res.wall_total:.1f} s",
         "", "Compare the ratios of one run, not absolute times across runs. Costs are CPU seconds of the "
         "benchmark's process (`time.process_time`, which other work on a shared machine disturbs far less "
         "than wall time) with the wall-clock figures beside them. error = max(|L − L_ref|/|L_ref|, "
         "|q − q_ref|) of the final state (of L alone for a run that averaged the spin phase out); "
         "real-time factor = simulated s / wall s. Comparisons run each scene without its controller (the same "
         "problem for every method).", "", "## Headline", ""]
    L += [f"- {x}" for x in headline_lines(res)] or ["- (no comparison ran)"]
    sp = speedup_table(res)
    if sp:
        names = list(dict.fromkeys(m for t in sp for m in t["baselines"]))
        L += [""] + _table(
            f"## Speed-up at error {TARGET_ERROR:.0e} (CPU; the baseline's cost over ours, > 1: ours is faster)",
            f"scene | horizon s | {_method_label('full')} CPU s | " + " | ".join(f"vs {m}" for m in names),
            [f"{t['scene']} | {t['horizon']:g} | {_fmt(t['ours'])} | " + " | ".join(
                f"{_fmt(t['baselines'][m]['ratio'], '.3g')}x ({_fmt(t['baselines'][m]['cost'])} s"
                + (", cheapest run" if t['baselines'][m]['flat'] else "") + ")" if m in t["baselines"] else "–"
                for m in names) for t in sp],
            [f"{RK4_METHOD}: classic RK4 with a fixed step on a numba right-hand side of the same model "
             "(gyro_sim/bench_baseline.py), swept over the number of steps; solve_ivp: SciPy over the NumPy "
             "right-hand side. Costs interpolated log-log on each method's Pareto front."])[:-1]
    L += ["", "## References", "",
          "| scene | horizon s | reference | CPU s | cross-check | CPU s | agreement |", "|---|---|---|---|---|---|---|"]
    for r in res.refs:
        L.append(f"| {r['scene']} | {r['horizon']:g} | {r['reference']} | {_fmt(r['ref_cpu'])} | {r['check'] or '–'} "
                 f"| {_fmt(r['check_cpu'])} | {_fmt(r['agreement'], '.1e')} |")
    L += ["", f"## Cost at error {TARGET_ERROR:.0e} (log-log interpolation along each method's Pareto front)", "",
          "| scene | horizon s | method | CPU s | wall s | RHS evaluations | CPU / ours | wall / ours | RHS / ours "
          "| CPU s at error of L alone | note |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for h in res.headline:
        note = "every setting below the target: cheapest run" if h.get("flat") else (
            f"no setting reached the target (best {h['best']:.1e})" if not math.isfinite(h["cpu"]) else "")
        L.append(f"| {h['scene']} | {h['horizon']:g} | {h['method']} | {_fmt(h['cpu'])} | {_fmt(h['wall'])} "
                 f"| {_fmt(h['rhs'], '.3g')} | {_fmt(h['speedup'], '.3g')} | {_fmt(h['speedup_wall'], '.3g')} "
                 f"| {_fmt(h['rhs_ratio'], '.3g')} | {_fmt(h['cpu_L'])} | {note} |")
    L += ["", "## Work-precision tables", ""]
    groups: dict = {}
    for r in res.rows:
        groups.setdefault((r.scene, r.horizon), []).append(r)
    for (scene, T), rows in groups.items():
        whole = any("whole scene" in r.note for r in rows)
        L += [f"### {scene}, horizon {T:g} s" + (" (our integrator only, the whole scene)" if whole else ""), "",
              "| method | setting | CPU s | wall s | steps | RHS evaluations | error | error of L | real-time factor "
              "| note |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            note = r.note.replace("our integrator only (whole scene)", "").strip("; ")
            L.append(f"| {r.method} | {r.setting} | {r.cpu:.4g} | {r.wall:.4g} | {r.steps} | {_fmt(r.rhs, 'd')} "
                     f"| {r.error:.2e} | {r.error_L:.2e} | {r.rtf:.3g} | {note} |")
        L.append("")
    if res.modes:
        L += _table("## Cost of eddy modes", "scene | modes | method | setting | horizon s | CPU s | wall s | steps "
                    "| RHS evaluations | CPU ns per step | real-time factor",
                    [f"{m['scene']} | {m['modes']} | {m['method']} | {m['setting']} | {m['horizon']:g} "
                     f"| {m['cpu']:.4g} | {m['wall']:.4g} | {m['steps']} | {_fmt(m['rhs'], 'd')} "
                     f"| {m['ns_per_step']:.4g} | {m['rtf']:.3g}" for m in res.modes])
    if res.rtf:
        L += _table("## Real-time factor of the default scene", "scene | method | run | duration s | wall s | CPU s "
                    "| steps | averaged s | real-time factor | per CPU s | final spin rev/s | final θ deg | L vs full",
                    [f"{r['scene']} | {r['method']} | {r['what']} | {r['duration']:g} | {r['wall']:.3g} "
                     f"| {r['cpu']:.3g} | {r['steps']} | {r['averaged']:.3g} | {r['rtf']:.3g} | {r['rtf_cpu']:.3g} "
                     f"| {r['spin_rev_s']:.2f} | {r['theta_deg']:.3g} | {_fmt(r['error_L'], '.1e')}" for r in res.rtf])
    if res.spinup:
        L += _table("## 20-minute spin-up (spinup_thin_shell, no controller)", "method | setting | duration s "
                    "| wall s | CPU s | steps | averaged s | real-time factor | attitude error rad (estimate) | error of L "
                    "| estimate of L | spin rev/s "
                    "| spin / field rate | θ deg",
                    [f"{s['method']} | {s['setting']} | {s['duration']:g} | {s['wall']:.4g} | {s['cpu']:.4g} "
                     f"| {s['steps']} | {s['averaged']:.4g} | {s['rtf']:.3g} | {_fmt(s['error'], '.1e')} "
                     f"| {_fmt(s['error_L'], '.1e')} | {_fmt(s.get('estimate_L', float('nan')), '.1e')} "
                     f"| {s['spin_rev_s']:.2f} | {s['spin_fraction']:.6f} "
                     f"| {s['theta_deg']:.3g}" for s in res.spinup],
                    ["Each row is `method: auto` at the accuracy named (the run picks its stepper, modes and steps). The "
                     "error of L is the final state's against a run at rtol 1e-9 (relative); the attitude's is the "
                     "run's own estimate (its `error_estimate`); averaged levels have none (they average the spin "
                     "phase out). The goal of issue 23 is the first row: L to 1e-6 in under 0.3 s."])
    if res.averaged:
        L += _table("## Averaged models: fidelity auto against full (scenes as shipped, whole duration)",
                    "scene | duration s | averaged by | averaged s | CPU s full | CPU s auto | speed-up (CPU) "
                    "| wall s full | wall s auto | error of L | error of spin | error of θ rad",
                    [f"{v['scene']} | {v['duration']:g} | {v['models']} | {v['averaged']:.4g} | {v['cpu_full']:.4g} "
                     f"| {v['cpu_auto']:.4g} | {v['speedup']:.3g} | {v['wall_full']:.4g} | {v['wall_auto']:.4g} "
                     f"| {v['error_L']:.1e} | {v['error_spin']:.1e} "
                     f"| {v['error_theta']:.1e}" for v in res.averaged],
                    ["Errors are final-state differences of auto from full; each contains the full model's fast ripple "
                     "(O(ε)), which the averaged model does not carry. The regions are in docs/averaged_k.md §7, "
                     "docs/averaged_m.md and gyro_sim/fidelity.py."])
    if res.savings:
        L += _table("## What skipping is worth (spinup_thin_shell, no controller; CPU s)", "the scene skips | compared "
                    "| horizon s | CPU s (skipped) | stepper, steps | CPU s (done) | stepper, steps | ratio",
                    [f"{v['what']} | {v['how']} | {v['horizon']:g} | {v['cpu']:.4g} | {v['method']} {v['steps']} "
                     f"| {v['cpu_forced']:.4g} | {v['method_forced']} {v['steps_forced']} | {v['ratio']:.2f}"
                     for v in res.savings])
    if res.profile:
        L += _table("## Where the time goes (compiled kernels; CPU ns, least of 3)", "case | what | ns",
                    [f"{p['case']} | {p['what']} | "
                     + (f"{p['ns']:.2f} (ratio)" if p.get("unit") == "ratio" else f"{p['ns']:.4g}")
                     for p in res.profile])
    from .bench_ros import markdown as ros_markdown
    from .bench_ticks import markdown_lines as ticks_markdown
    from .bench_ticks import output_rate_lines
    from .bench_scaling import markdown as scaling_markdown

    L += ticks_markdown(res)
    L += output_rate_lines(res)
    L += ros_markdown(res)
    L += scaling_markdown(res)
    if res.accuracy is not None:
        from .bench_accuracy import markdown_lines

        L += markdown_lines(res.accuracy)
    if res.notes:
        L += ["## Notes", ""] + [f"- {n}" for n in res.notes] + [""]
    return "\n".join(L) + "\n"


def plot_work_precision(res: Results, path=None):
    """Log-log CPU time of a run (s) against its error (final (L, q) vs the reference, dimensionless), one panel
    per scene/horizon, one line of markers per method; a dashed vertical line at the target error
    ``TARGET_ERROR`` where the headline compares the costs. Wall times are not drawn (they are in bench.csv).

    Args:
        res: the benchmark's results (``res.rows``: :class:`Row`).
        path: if given, the figure is also written there as PNG (atomically; parent folders are made).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state).
    """
    from matplotlib.lines import Line2D

    from .plotting import new_figure, save_png

    groups: dict = {}
    for r in res.rows:
        groups.setdefault((r.scene, r.horizon), []).append(r)
    n = max(len(groups), 1)
    fig = new_figure((6.0 * n, 4.6))
    axes = fig.subplots(1, n, squeeze=False)[0]
    markers = ["o", "s", "^", "D", "v", "P", "X", "*", "h"]
    for ax, ((scene, T), rows) in zip(axes, groups.items()):
        methods: dict = {}
        for r in rows:
            methods.setdefault(r.method, []).append(r)
        for i, (m, rs) in enumerate(methods.items()):
            pts = [(r.error, r.cpu) for r in rs if r.error > 0 and math.isfinite(r.error)]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=markers[i % len(markers)], label=m)
        ax.axvline(TARGET_ERROR, color="0.6", ls="--", lw=1)
        ax.text(TARGET_ERROR, 0.98, f" target {TARGET_ERROR:.0e}", transform=ax.get_xaxis_transform(), rotation=90,
                va="top", ha="right", fontsize=7, color="0.4")
        ax.set_xlabel("error of the final (L, q) vs reference")
        ax.set_ylabel("CPU time of the run (s)")
        ax.set_title(f"{scene}, {T:g} s simulated", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        target = Line2D([], [], color="0.6", ls="--", lw=1,
                        label=f"target error {TARGET_ERROR:.0e} (costs compared here)")
        ax.legend(handles=ax.get_legend_handles_labels()[0] + [target], fontsize=8)
    if not groups:
        axes[0].text(0.5, 0.5, "no runs", ha="center")
    fig.suptitle(f"gyro_sim work-precision ({res.config.mode}, {res.started})", fontsize=10)
    if path is not None:
        save_png(fig, path, dpi=110)
    return fig


# ----------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gyro-sim bench",
        description="Work-precision benchmark: gyro_sim's integrator (every fidelity level) against "
                    "scipy solve_ivp (DOP853, LSODA) and a compiled fixed-step RK4 on the same scenes; writes "
                    "DIR/bench.md, bench.csv, "
                    "work_precision.png and prints the headline ratios.")
    p.add_argument("--quick", action="store_true",
                   help="short horizons (still minutes: 141 s wall with --no-ros --no-accuracy, docs/benchmark.md)")
    p.add_argument("--out", metavar="DIR", type=Path, default=Path("runs/bench"),
                   help="output folder (default: runs/bench)")
    p.add_argument("--scenes", metavar="SCENE", nargs="+", default=list(DEFAULT_SCENES),
                   help=f"scenes of the work-precision comparison (default: {' '.join(DEFAULT_SCENES)})")
    p.add_argument("--no-ros", action="store_true", help="skip the ros part (nodes over DDS, first runs)")
    p.add_argument("--no-accuracy", action="store_true",
                   help="skip the accuracy part (every built-in scene against the accuracy it states)")
    p.add_argument("--no-startup", action="store_true", help="skip the startup part (new processes' import times)")
    p.add_argument("--no-sweep", action="store_true", help="skip the sweep part (runs/s on 1 and 2 Dask workers)")
    p.add_argument("--startup-baseline", metavar="DIR",
                   help="a source tree of the code before (e.g. git archive of a commit): its start-up is timed beside "
                        "this code's, in the same run")
    p.add_argument("--only", choices=["accuracy", "ticks", "startup", "sweep"], help="run this part alone")
    p.add_argument("--accuracy-scenes", metavar="SCENE", nargs="+",
                   help="scenes of the accuracy part (default: every built-in scene)")
    return p


def bench_main(argv: Optional[Sequence[str]] = None) -> int:
    """``gyro-sim bench``: run the benchmark, write the files, print the headline. Returns 0 (2 on a bad scene)."""
    from .scene import SceneError, load_scene

    args = build_parser().parse_args(argv)
    try:  # every scene named, before anything runs
        for s in list(args.scenes) + list(args.accuracy_scenes or []):
            load_scene(s)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    cfg = (quick_config if args.quick else full_config)(args.scenes)
    cfg.ros = cfg.ros and not args.no_ros
    cfg.startup = cfg.startup and not args.no_startup
    cfg.sweep = cfg.sweep and not args.no_sweep
    cfg.startup_baseline = args.startup_baseline
    cfg.accuracy = not args.no_accuracy
    cfg.only = args.only
    if args.accuracy_scenes:
        cfg.accuracy_scenes = tuple(args.accuracy_scenes)
    command = "gyro-sim bench " + " ".join(sys.argv[1:] if argv is None else list(argv))
    res = run_bench(cfg, args.out, command=command.strip())
    print()
    print("Headline (ratios measured in this run):")
    for line in headline_lines(res):
        print("  " + line)
    if res.accuracy is not None:
        from .bench_accuracy import headline as acc_headline

        for line in acc_headline(res.accuracy):
            print("  " + line)
    print(f"wrote {args.out / 'bench.md'}, {args.out / 'bench.csv'}, {args.out / 'work_precision.png'} "
          f"({res.wall_total:.1f} s)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(bench_main())
