"""The benchmark's building blocks, shared by every part (``gyro_sim.apps.bench*``): method labels and knobs, a
table row (:class:`Row`), timing, runs of the project's integrator and of the SciPy baselines, the error
measures, the configuration and the results, and the Markdown table helper.
"""
from __future__ import annotations

import math
import time
import typing
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np


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
#: the compiled baseline's method label (classic RK4, fixed step, numba right-hand side:
#: gyro_sim/apps/bench_baseline.py)
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
    from gyro_sim.scenes.scene import Scene

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
    from gyro_sim.compiled.compile_watch import compile_seconds

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
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import Simulator

    return Simulator(load_scene(scene_name, overrides=_scene_overrides(level, extra)))._method()


def run_ours(scene_name: str, horizon: float, value: Optional[float] = None, level: str = "full",
             extra: Optional[dict] = None, min_wall: float = 0.0, max_reps: int = 1) -> Row:
    """``gyro_sim.run`` of the scene (controller removed) over ``horizon`` s; wall includes setup.
    ``value``: the accuracy knob of the stepper the level starts with (:func:`knob_of`; None: the default).

    RHS evaluations of the full level: 12 per lawson8 step, 4 per ETDRK4 step, 2 per frozen-flow step
    (the stepper the run starts with) + 1 per output sample (the torque).
    """
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import Simulator, run

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
    # (the knob the run's plan starts with: gyro_sim/scenes/accuracy.py; its error control may change it)
    if value is None:
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
    from gyro_sim.scenes.scene import load_scene

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
    from gyro_sim.engine.simulate import Simulator

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
    estimate: bool = False  # the estimate part (bench_estimate): each case's error estimate against its true error
    cost: bool = False  # the cost part (bench_cost): the default scene's cost against its duration, old defaults beside
    accuracy_scenes: Optional[tuple] = None  # its scenes (None: every built-in scene)
    startup: bool = False  # the startup part (bench_scaling): new processes' import and first-run times
    startup_baseline: Optional[str] = None  # a source tree of the code before, timed beside this one
    sweep: bool = False  # the sweep part (bench_scaling): runs/s in-process, on 1 and 2 Dask workers
    only: Optional[str] = None  # run this part alone (bench --only's choices)
    min_wall: float = 0.2  # repeat our (short) runs until this much wall time; keep the least
    max_reps: int = 5

    def horizon_of(self, scene: str) -> float:
        return float(self.horizon.get(scene, self.default_horizon))


def quick_config(scenes: Sequence[str] = DEFAULT_SCENES) -> BenchConfig:
    """0.2 s horizons (100 turns of the default scene's field), every tolerance (141 s wall with --no-ros
    --no-accuracy on 2026-11-25, docs/benchmark.md)."""
    return BenchConfig(mode="quick", scenes=tuple(scenes), default_horizon=0.2,
                       horizon={"spinup_thin_shell": 0.2, "spinup_solid_sphere": 0.2},
                       spt_ref=3072, mode_horizon=1.0, min_wall=0.1, max_reps=3, ros=True, startup=True, sweep=True,
                       estimate=True, cost=True)


def full_config(scenes: Sequence[str] = DEFAULT_SCENES) -> BenchConfig:
    """A few minutes: 2 s comparison horizons, whole-duration curves of our integrator, the
    baseline's cost with 1 and 50 modes and the 20-minute spin-up."""
    return BenchConfig(mode="full", scenes=tuple(scenes), default_horizon=2.0,
                       horizon={"spinup_thin_shell": 2.0, "spinup_solid_sphere": 2.0},
                       spt_ref=3072, long_horizon_scenes=("spinup_thin_shell",), long_spt_ref=1536,
                       mode_horizon=10.0, mode_baseline_horizon=0.1, spinup_duration=1200.0,
                       min_wall=0.3, max_reps=5, ros=True, startup=True, sweep=True, estimate=True, cost=True)


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
    estimate: Optional[object] = None  # the estimate part (bench_estimate.EstResults)
    cost: Optional[object] = None  # the cost part (bench_cost.CostResults)
    rk4: Optional[object] = None  # the RK4 part (bench_rk4.Rk4Results)
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



def _table(title: str, columns: str, rows: list, after: Sequence[str] = ()) -> list:
    """Markdown lines of a section: its title, a table with ``columns`` ("a | b | c") and ``rows`` (each
    "x | y | z"), then ``after`` and a blank line."""
    n = columns.count("|") + 1
    return ([title, "", f"| {columns} |", "|" + "---|" * n] + [f"| {r} |" for r in rows]
            + (["", *after] if after else []) + [""])


