"""Model fidelity chosen per scene: ``full``, ``averaged`` or ``auto`` (hybrid).

The averaged model here is the spin-up of an axisymmetric rotor by one rotating field about its
axis u, at small nutation angle, for any conductor (the transfer function ĝ of
:mod:`gyro_sim.conductor`):

    d|L|/dt = (2π r2³/μ0) B0² Im ĝ(ν − |L|/J3)                    torque-slip curve (physics.md §5)
    dθ/dt   = θ · π r2³ B0²/(μ0 |L|) · [Im ĝ(|L|/J3 − ν) − Im ĝ(|L|/J1 − ν)]      [M] (3.18)

It averages over the field phase, the spin and the precession, so it costs milliseconds for any
number of revolutions. It holds where (checked by :func:`averaged_region`):

* one stator on (the others at 0 A), no general field, constant commands (no scheduled command
  inside the averaged stretch, no controller other than a constant ``spinup``);
* J1 = J2 (axisymmetric), L along the stator axis (ρ ≤ ``RHO_MAX``), θ ≤ ``THETA_MAX``;
* μ = |N| J1/|L|² ≤ ``MU_MAX``: the torque changes L little over a precession radian (the
  averaging parameter of [K]); below that spin the fast phases do not average out.

``auto`` runs the full model until the region is entered, hands the state over (|L|, θ) and runs
the averaged model to the next scheduled command or the end; at a command it hands back to the
full model (attitude rebuilt from θ with ψ = φ = 0, eddy modes from their quasi-steady response)
and so on. ``averaged`` refuses a scene that starts outside the region.

The second averaged model is [M]'s (:mod:`gyro_sim.averaged_m`: (3.6), (3.14), (3.17)) for the three
uniform fields of [M] §3 (constant along z3, pulsating along z3, rotating about z3; no command, no
controller, no effect). Its slow state is (|L|, ρ, σ, θ) and it holds where
:meth:`AveragedM.region` says so with μ_eff ≤ ``MU_MAX`` (small torque against the precession,
non-resonant torque harmonics, short eddy transient; any θ). ``auto`` hands over to it where the
[K] spin-up model does not apply and runs it to the end, or back to the full model at the instant
its solution leaves the region (:meth:`AveragedM.exit_events`) (L from (|L|, ρ, σ), attitude at ψ = φ = 0, eddy modes at
their steady response along the free motion: :func:`gyro_sim.frozen_flow.steady_modes`).

The third is [K]'s (:mod:`gyro_sim.slow_k`: (2.1) in vector form with the (3.3) drive of ψ-switching) for an
axisymmetric rotor under the quasi-static eddy torque, any stators at held commands or the ``psi_switching``
law, where :meth:`SlowK.check` holds (ε ≤ ``MU_MAX``, non-resonant torque harmonics, θ away from the pole under
ψ-switching). Inside an output window (``output.windows``) ``auto`` runs the full model.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.integrate import solve_ivp

from gyro_sim.engine import ticks
from gyro_sim.averaging.averaged_m import AveragedM, averaged_m_model
from gyro_sim.compiled.compile_watch import compile_seconds
from gyro_sim.averaging.slow_k import ENTER_MARGIN, MU_MAX, SlowK, slow_k_of
from gyro_sim.averaging.slow_k import slow_state as slow_k_state
from gyro_sim.physics.frames import attitude_from_euler, nutation_angle, quat_to_matrix
from gyro_sim.scenes.scene import Scene, SceneError
from gyro_sim.engine.model import AVERAGED_ERROR
from gyro_sim.engine.result import RunResult
from gyro_sim.engine.runner import Runner
from gyro_sim.engine.simulator import Simulator

THETA_MAX = 0.1  # rad


def mu_max(runner: Runner) -> float:
    """The averaging parameter's entry bound of a run: ``MU_MAX``, lowered to ``accuracy.rtol`` /
    :data:`AVERAGED_ERROR` so that an averaged stretch keeps the scene's accuracy (the averaged models' error is
    O(ε))."""
    return min(MU_MAX, runner.scene.accuracy.rtol / AVERAGED_ERROR)
RHO_MAX = 1e-3  # rad
RECHECK = 0.1  # the regions are tested again after this fraction of the slow time |L|/|N|


@dataclass(frozen=True)
class SpinupModel:
    """Averaged spin-up by one rotating field (SI): see the module docstring."""

    J1: float
    J3: float
    scale: float  # 2π r2³/μ0, A·m²/T
    tau: tuple  # mode time constants τ_n, s
    weight: tuple  # mode weights w_n
    tail: float  # static tail T (s): Im ĝ(ω) = Σ w_n ωτ_n/(1 + ω²τ_n²) + ω T
    B0: float  # T
    nu: float  # rad/s, signed along u

    def g_imag(self, w):
        """Im ĝ(ω) of the modal model (plain floats: this is the model's whole cost; arrays elementwise)."""
        acc = w * self.tail
        for wn, tn in zip(self.weight, self.tau):
            x = w * tn
            acc += wn * x / (1.0 + x * x)
        return acc

    def torque(self, L):
        """Axial torque (N·m) at |L| (N·m·s; a float or an array): torque-slip curve."""
        return self.scale * self.B0**2 * self.g_imag(self.nu - L / self.J3)

    def nutation_rate(self, L: float) -> float:
        """(1/θ) dθ/dt (1/s), [M] (3.18); its finite limit at L → 0 is used below |L| = 1e-9 J3 |ν|."""
        a, b = L / self.J3 - self.nu, L / self.J1 - self.nu
        k = 0.5 * self.scale * self.B0**2  # π r2³ B0²/μ0
        if abs(L) < 1e-9 * self.J3 * max(abs(self.nu), 1.0):
            h = 1e-6 * max(abs(self.nu), 1.0)
            dg = (self.g_imag(-self.nu + h) - self.g_imag(-self.nu - h)) / (2 * h)
            return k * dg * (1 / self.J3 - 1 / self.J1)
        return k / L * (self.g_imag(a) - self.g_imag(b))

    def mu(self, L: float) -> float:
        """Averaging parameter |N| J1/|L|² (∞ at L = 0)."""
        return abs(self.torque(L)) * self.J1 / L**2 if L > 0 else math.inf

    def solve(self, L0: float, theta0: float, t0: float, t_eval: np.ndarray):
        """|L|(t), θ(t) at t_eval (s) from |L|(t0) = L0, θ(t0) = theta0 (DOP853, rtol 1e-9)."""
        def rhs(t, y):
            return [self.torque(y[0]), self.nutation_rate(y[0]) * y[1]]

        t1 = float(t_eval[-1]) if len(t_eval) else t0
        if t1 <= t0:
            return np.full(len(t_eval), L0), np.full(len(t_eval), theta0), 0
        sol = solve_ivp(rhs, (t0, t1), [L0, theta0], method="DOP853", t_eval=t_eval, rtol=1e-9,
                        atol=[1e-12 * max(L0, 1e-12), 1e-13])
        return sol.y[0], sol.y[1], int(sol.nfev)


def spinup_model(scene: Scene, k: int) -> SpinupModel:
    """The averaged model of stator k of a scene (its present current and rate)."""
    sim = Simulator(scene)
    cond = sim.conductor
    if cond is None:
        raise SceneError("fidelity: the averaged model needs a conducting rotor with a torque model")
    J = scene.inertia
    if scene.torque_model == "quasi_static":  # [K] (1.2): ĝ ≈ iωτ_eff
        tau, weight, tail = (), (), float(cond.tau_eff)
    else:
        tau, weight, tail = tuple(map(float, cond.tau)), tuple(map(float, cond.weight)), float(cond.tail_tau)
    return SpinupModel(J1=float(J[0]), J3=float(J[2]), scale=float(cond.moment_scale), tau=tau, weight=weight,
                       tail=tail, B0=float(sim.b[k] * sim.current[k]), nu=float(sim.rate[k]))


def _model(runner: Runner, k: int) -> SpinupModel:
    """The spin-up model of stator k under its present command (cached on the runner)."""
    cache = runner.__dict__.setdefault("_spinup_models", {})
    key = (k, float(runner.sim.current[k]), float(runner.sim.rate[k]))
    if key not in cache:
        base = spinup_model(runner.scene, k)
        cache[key] = SpinupModel(J1=base.J1, J3=base.J3, scale=base.scale, tau=base.tau, weight=base.weight,
                                 tail=base.tail, B0=float(runner.sim.b[k] * key[1]), nu=key[2])
    return cache[key]


def averaged_region(runner: Runner) -> tuple[Optional[int], str]:
    """(stator index, '') if the averaged spin-up model holds for the runner's present state, else (None, why)."""
    scene, sim = runner.scene, runner.sim
    J = scene.inertia
    if J[0] != J[1]:
        return None, f"rotor.inertia = {list(J)}: the averaged model needs J1 = J2"
    if scene.field:
        return None, "a general field is present"
    if scene.effects.any:
        on = [k for k in type(scene.effects).model_fields if getattr(scene.effects, k) is not None]
        return None, f"effects {on} are on; the averaged model has none of them"
    lit = [k for k in range(len(sim.stator_names)) if sim.current[k] > 0]
    if len(lit) != 1:
        return None, f"{len(lit)} stators on; the averaged model takes exactly one"
    ctl = scene.controller
    if ctl is not None and not (ctl.law == "spinup" and ctl.params.ramp is None):
        return None, f"controller law {ctl.law!r} is not a constant command"
    k = lit[0]
    u = sim.axes[k]
    L = sim.y[0:3]
    Ln = math.sqrt(float(L @ L))
    if Ln == 0.0:
        return None, "|L| = 0"
    rho = math.acos(min(1.0, abs(float(L @ u)) / Ln))
    if rho > RHO_MAX:
        return None, f"L is {rho:.2e} rad off the stator axis (limit {RHO_MAX:g})"
    # μ before θ: a scalar formula, and the test that fails through a spin-up from rest
    mu = _model(runner, k).mu(Ln)
    if mu > mu_max(runner):
        return None, (f"μ = {mu:.2e} > {mu_max(runner):g} (spin too low for the averaging at accuracy.rtol "
                      f"{runner.scene.accuracy.rtol:g})")
    x = runner.control_input()
    if x.theta > THETA_MAX:
        return None, f"θ = {x.theta:.3g} rad > {THETA_MAX:g}"
    return k, ""


def _write_averaged_rows(r: Runner, rows: np.ndarray, L: np.ndarray, q: np.ndarray, N: np.ndarray) -> None:
    """Output rows of an averaged stretch: case-frame L (n, 3), attitude (n, 4), torque (n, 3); the eddy modes
    (averaged out) 0; the commands and field phases of the present, constant command."""
    sim = r.sim
    r.out_y[rows] = 0.0
    r.out_y[rows, 0:3] = L
    r.out_y[rows, 3:7] = q
    r.out_N[rows] = N
    r.cur[rows], r.rate[rows] = sim.current, sim.rate
    r.phase[rows] = np.mod(sim.phase + sim.rate * (r.t_out[rows, None] - sim.t), 2 * math.pi)


def _jump(r: Runner, n: int, t0: float, t1: float) -> None:
    """Move the runner past an averaged stretch [t0, t1] whose n output rows are written: the next break
    after t1, the field phases and the time at t1 (the state is the caller's to set)."""
    sim = r.sim
    r.row += n
    r._bi = int(np.searchsorted(r.breaks, t1 + 1e-12 * max(1.0, t1)))
    sim.phase = np.mod(sim.phase + sim.rate * (t1 - t0), 2 * math.pi)
    sim.t = t1


def _handover_to_full(runner: Runner, k: int, L: float, theta: float) -> None:
    """Rebuild the full state from (|L|, θ): L along u, attitude at ψ = φ = 0, eddy modes in their
    steady response to the present field (no switch-on transient): for a body-frame field
    B_b(t) = Re[(b_re + i b_im) e^{−i s t}], e_n = Re[ĝ_n(s)(b_re + i b_im)], b_im = (dB_b/dt)/s."""
    sim = runner.sim
    u = sim.axes[k]
    d = (1.0 if sim.rate[k] >= 0 else -1.0) * u
    sim.y[0:3] = L * d
    sim.y[3:7] = attitude_from_euler(d, 0.0, theta, 0.0)
    if not sim.tau.size:
        return
    Bre, Bim, om = sim.phasors()
    R = quat_to_matrix(sim.y[3:7])
    B, dB = Bre.sum(axis=0), (Bim * om[:, None]).sum(axis=0)
    Bb = R.T @ B
    Om_b = sim.Jinv * (R.T @ sim.y[0:3])
    dBb = R.T @ dB - np.cross(Om_b, Bb)
    slip = sim.rate[k] - float(Om_b @ (R.T @ d))  # field rate seen from the body
    b_im = dBb / slip if slip != 0.0 else np.zeros(3)
    for n, tau in enumerate(sim.tau):
        gn = 1j * slip * tau / (1 - 1j * slip * tau)
        sim.y[7 + 3 * n: 10 + 3 * n] = gn.real * Bb - gn.imag * b_im


def run_hybrid(scene: Scene, duration: Optional[float] = None, estimate: Optional[bool] = None,
               force: bool = False) -> RunResult:
    """``fidelity: auto`` (and ``averaged``): full model where needed, the averaged model elsewhere.

    The regions are tested where the commands change and otherwise every ``RECHECK`` of the slow time
    |L|/|N| (they move with the slow variables); between tests the full model runs its output samples
    inside one compiled call (or, with ``sampling: events``, switches the law at its exact instants). After
    a stretch that ended at its region's edge the full model runs that long before the next test; after
    one that ended at a command or an output window the next test is at once. A controller must be
    settled (its next command the one in force) before a stretch starts. ``force``: as :func:`gyro_sim.engine.
    simulate.run`'s (the step budget is the full model's plan).
    """
    from gyro_ctl.laws import make_law, make_switching

    r = Runner(scene, duration, sample_breaks=False, estimate=estimate, force=force)
    sim = r.sim
    ctl = scene.controller
    law = make_law(ctl) if ctl is not None else None
    switching = make_switching(ctl) if ctl is not None and ctl.sampling == "events" else None
    loop = ticks.tick_loop(r, law) if switching is None else None  # ticks in compiled code where they can be
    switched = set(ctl.params.control_stators) if ctl is not None and ctl.law == "psi_switching" else set()
    strict = scene.fidelity == "averaged"
    w0, c0 = time.perf_counter(), compile_seconds()
    cmd_times = sorted({c.time for c in scene.commands if c.time < r.T})
    segments: list = []  # (t0, t1) of averaged stretches
    models = []  # the averaged model of each stretch: "spin-up", "[M]", "[K]"
    nfev = 0
    next_test, tested_cmd = -math.inf, None
    while not r.done:
        if r.row > 0 and law is not None and r.is_control_tick:
            r.apply_commands(law(r.control_input()))
        until = None
        win = scene.output.window_at(sim.t) if r.row > 0 else None
        if win is not None:
            until = win.end
        elif r.row > 0:
            cmd = commands_key(sim)
            if sim.t >= next_test or cmd != tested_cmd:
                n, model, edge, why = _averaged_stretch_if_any(r, law, switched, cmd_times, segments)
                if model is not None:
                    nfev += n
                    models.append(model)
                    if edge and switched:  # the rebuilt attitude needs its switching signs at once
                        r.apply_commands(law(r.control_input()))
                    next_test = sim.t + _recheck(sim) if edge else -math.inf
                    tested_cmd = commands_key(sim)
                    continue
                if strict and not segments:
                    raise SceneError(f"fidelity = 'averaged': the averaged model does not hold at t = {sim.t:g} s: "
                                     f"{why}; use fidelity: auto or full")
                next_test, tested_cmd = sim.t + _recheck(sim), cmd
            until = min(next_test, scene.output.next_window_start(sim.t))
        if switching is not None and r.row > 0:
            r.advance_located(law, switching)  # to the next break (ticks, commands): the law's exact switches
            continue
        if until is not None and until <= sim.t + 1e-12 * max(1.0, sim.t):  # never an advance of zero
            until = float(r.t_out[r.row]) if r.row < r.t_out.size else None
        ticks.advance(r, loop, until)
    res = r.result()
    res.compile_time = compile_seconds() - c0
    res.wall_time = time.perf_counter() - w0 - res.compile_time
    res.averaged_segments = segments  # RunResult.euler: ψ, φ NaN there (averaged out)
    res.averaged_models = models
    res.averaged_rhs_evaluations = nfev
    return res


def _averaged_stretch_if_any(r: Runner, law, switched: set, cmd_times: list, segments: list):
    """Run the first averaged model whose region holds now (the spin-up model, [M]'s, [K]'s) over its stretch.

    Returns (RHS evaluations, the model's name or None, whether the stretch ended at its region's edge, why
    none applies: every model's reason)."""
    settled, why_law = law_settled(r, law, switched)
    if not settled:
        return 0, None, False, why_law
    k, why = averaged_region(r)
    if k is not None:
        r.estimator.averaged_eps.append(_model(r, k).mu(float(np.linalg.norm(r.sim.y[0:3]))))
        r.estimator.hold_shadow()  # (the shadow reaches the stretch's start, compared: it takes up again from its end)
        n = _averaged_stretch(r, k, cmd_times, segments)
        r.estimator.resync_shadow()
        return n, "spin-up", False, ""
    m, why_m = m_region(r)
    if m is not None:
        r.estimator.averaged_eps.append(mu_max(r))  # (the region's bound: [M]'s μ_eff at entry is below it)
        r.estimator.hold_shadow()
        n, edge = _m_stretch(r, m, cmd_times, segments)
        r.estimator.resync_shadow()
        return n, "[M]", edge, ""
    kk, why_k = k_region(r)
    if kk is not None:
        r.estimator.averaged_eps.append(kk.eps_ratio(slow_k_state(r.sim)) * kk.mu_max)
        r.estimator.hold_shadow()
        n, edge = _k_stretch(r, kk, cmd_times, segments)
        r.estimator.resync_shadow()
        return n, "[K]", edge, ""
    return 0, None, False, f"{why}; [M]'s averaged model: {why_m}; [K]'s averaged model: {why_k}"


def law_settled(r: Runner, law, switched: set = frozenset()) -> tuple[bool, str]:
    """(True, '') if the controller's next command is the one in force (so an averaged stretch may hold it),
    else (False, which stator it would change). ``switched``: stators whose field direction the law flips
    (ψ-switching, averaged by [K]'s model): compared in current and |rate|."""
    if law is None:
        return True, ""
    sim = r.sim
    for name, (cur, rate) in law(r.control_input()).items():
        k = sim.stator_names.index(name)
        if cur is not None and cur != sim.current[k]:
            return False, (f"the controller's next command sets {name}'s current to {cur:g} A "
                           f"(in force: {sim.current[k]:g} A)")
        if rate is not None and (abs(rate) != abs(sim.rate[k]) if name in switched else rate != sim.rate[k]):
            return False, f"the controller's next command sets {name}'s rate to {rate:g} rad/s (in force: {sim.rate[k]:g})"
    return True, ""


def commands_key(sim) -> tuple:
    """A hashable key of the stator commands in force (currents and rates)."""
    return sim.current.tobytes(), sim.rate.tobytes()


def _stretch_end(r: Runner, cmd_times: list) -> float:
    """Where an averaged stretch from now must end at the latest (s): the next scheduled command, the next
    output window or the end of the run."""
    t0 = r.sim.t
    return min(next((t for t in cmd_times if t > t0 + 1e-12), r.T), r.scene.output.next_window_start(t0))


def _integrate_slow(r: Runner, rhs, y0: np.ndarray, atol: np.ndarray, events: list, t_end: float, what: str):
    """Integrate a slow model (DOP853, rtol 1e-10, dense output) from now to ``t_end`` or its first terminal
    event. Returns (solution, the output rows it covers, t1, y(t1), whether an event ended it)."""
    t0 = r.sim.t
    rows = np.nonzero((r.t_out > t0 + 1e-12) & (r.t_out <= t_end))[0]
    sol = solve_ivp(rhs, (t0, t_end), y0, method="DOP853", t_eval=r.t_out[rows], rtol=1e-10, atol=atol,
                    dense_output=True, events=events)
    if sol.status < 0:
        raise RuntimeError(f"{what} averaged model: integration failed: {sol.message}")
    exits = [(float(te[0]), ye[0]) for te, ye in zip(sol.t_events, sol.y_events) if te.size]
    t1, y1 = min(exits, key=lambda e: e[0]) if exits else (t_end, sol.sol(t_end))
    n = int(np.count_nonzero(r.t_out[rows] <= t1 + 1e-12 * max(1.0, t1)))
    return sol, rows[:n], t1, y1, bool(exits)


def _recheck(sim) -> float:
    """Simulated time (s) until the regions are tested again: ``RECHECK`` × the slow time |L|/|N|; 0 (the next
    sample) at rest or without torque (e.g. at the switch-on, before the eddy currents build up)."""
    L, N = sim.y[0:3], sim.torque()
    n = math.sqrt(float(N @ N))
    return RECHECK * math.sqrt(float(L @ L)) / n if n > 0 else 0.0


def _averaged_stretch(r: Runner, k: int, cmd_times: list, segments: list) -> int:
    """Jump the runner over an averaged stretch to the next command (or the end). Returns RHS evaluations."""
    sim = r.sim
    t0 = sim.t
    t1 = _stretch_end(r, cmd_times)
    model = _model(r, k)
    L0 = float(np.linalg.norm(sim.y[0:3]))
    theta0 = r.control_input().theta
    rows = np.nonzero((r.t_out > t0 + 1e-12) & (r.t_out <= t1 + 1e-12))[0]
    t_eval = np.append(r.t_out[rows], t1) if (not rows.size or r.t_out[rows[-1]] < t1) else r.t_out[rows]
    L, th, nfev = model.solve(L0, theta0, t0, t_eval)
    n = rows.size
    u = sim.axes[k] * (1.0 if model.nu >= 0 else -1.0)
    if n:
        # attitude Y Rx(θ) (ψ = φ = 0: the fast phases are averaged out) as q_Y ⊗ (cos θ/2, sin θ/2, 0, 0)
        qY = attitude_from_euler(u, 0.0, 0.0, 0.0)
        c, s_ = np.cos(0.5 * th[:n]), np.sin(0.5 * th[:n])
        q = np.stack([qY[0] * c - qY[1] * s_, qY[0] * s_ + qY[1] * c, qY[2] * c + qY[3] * s_,
                      qY[3] * c - qY[2] * s_], axis=1)
        # elementwise torque: the model is plain arithmetic
        _write_averaged_rows(r, rows, L[:n, None] * u, q, model.torque(L[:n])[:, None] * u)
    # hand over: the state at t1, then the runner continues from there
    _jump(r, n, t0, t1)
    _handover_to_full(r, k, float(L[-1]), float(th[-1]))
    r.apply_scene_commands()
    segments.append((t0, t1))
    return nfev


# ------------------------------------------------------------------------------------------------
# [M]'s averaged model in the hybrid
# ------------------------------------------------------------------------------------------------
def _m_model(runner: Runner) -> tuple[Optional[AveragedM], str]:
    """[M]'s averaged model of the runner's scene (cached on the runner), or (None, why not)."""
    cache = runner.__dict__
    if "_m_model" not in cache:
        if runner.scene.effects.any:
            cache["_m_model"] = (None, "effects are on; [M]'s model has none of them")
        else:
            try:
                cache["_m_model"] = (averaged_m_model(runner.scene), "")
            except SceneError as exc:
                cache["_m_model"] = (None, str(exc).splitlines()[0])
    return cache["_m_model"]


def slow_state(sim) -> np.ndarray:
    """[M]'s slow variables (|L| N·m·s, ρ, σ, θ rad) of a simulator's present state (case-frame L; θ the
    angle between the body's x3 and L)."""
    L = sim.y[0:3]
    return np.array([math.sqrt(float(L @ L)), math.atan2(math.hypot(L[0], L[1]), L[2]), math.atan2(L[1], L[0]),
                     nutation_angle(sim.y[3:7], L)])


def m_region(runner: Runner) -> tuple[Optional[AveragedM], str]:
    """([M]'s model, '') if it holds at the runner's present state (μ_eff ≤ ``MU_MAX``), else (None, why)."""
    model, why = _m_model(runner)
    if model is None:
        return None, why
    y = slow_state(runner.sim)
    ok, why = model.region(L=y[0], rho=y[1], theta=y[3], mu_max=mu_max(runner))
    return (model, "") if ok else (None, why)


def _m_outputs(L, rho, sigma, theta) -> tuple[np.ndarray, np.ndarray]:
    """Case-frame L (n, 3) and the attitude (n, 4) at ψ = φ = 0 of [M]'s slow variables: the body is
    Rz(σ) Ry(ρ) Rx(θ) (the L-frame of l_frame turned by θ about y1), as q_z(σ) ⊗ q_y(ρ) ⊗ q_x(θ)."""
    sr, cr, ss, cs = np.sin(rho), np.cos(rho), np.sin(sigma), np.cos(sigma)
    Lc = L[:, None] * np.stack([sr * cs, sr * ss, cr], axis=1)
    a, b = np.cos(0.5 * sigma), np.sin(0.5 * sigma)  # q_z(σ) ⊗ q_y(ρ) = (a c, −b s, a s, b c)
    c, d = np.cos(0.5 * rho), np.sin(0.5 * rho)
    w0, w1, w2, w3 = a * c, -b * d, a * d, b * c
    e, f = np.cos(0.5 * theta), np.sin(0.5 * theta)  # ⊗ (e, f, 0, 0)
    q = np.stack([w0 * e - w1 * f, w0 * f + w1 * e, w2 * e + w3 * f, w3 * e - w2 * f], axis=1)
    return Lc, np.where(q[:, :1] < 0, -q, q)  # w ≥ 0, as frames.matrix_to_quat gives


def _m_stretch(r: Runner, model: AveragedM, cmd_times: list, segments: list) -> tuple[int, bool]:
    """Jump the runner over a stretch of [M]'s averaged model: to the end of the run (or the next output
    window), or to the instant its solution leaves the region (located by events between samples; there back
    to the full model). Returns (RHS evaluations, whether it ended at the region's edge)."""
    sim = r.sim
    t0 = sim.t
    y0 = slow_state(sim)
    atol = np.array([1e-12 * max(y0[0], 1e-300), 1e-12, 1e-12, 1e-12])
    sol, rows, t1, y1, edge = _integrate_slow(r, model.rhs, y0, atol, model.exit_events(mu_max(r)),
                                              _stretch_end(r, cmd_times), "[M]")
    n = rows.size
    if n:
        ts = r.t_out[rows]
        Lc, q = _m_outputs(*sol.sol(ts))
        # the averaged torque dL/dt (case frame): the dense output's central difference, δ small against
        # the steps (its truncation ~ δ², round-off ~ 1e-16 |L|/δ)
        d = 1e-6 * max(t1 - t0, 1e-300)
        tp, tm = np.minimum(ts + d, t1), np.maximum(ts - d, t0)
        N = (_m_outputs(*sol.sol(tp))[0] - _m_outputs(*sol.sol(tm))[0]) / (tp - tm)[:, None]
        _write_averaged_rows(r, rows, Lc, q, N)
    _jump(r, n, t0, t1)
    segments.append((t0, t1))
    _m_handover_to_full(sim, y1)
    return int(sol.nfev), edge


def _m_handover_to_full(sim, y_slow: np.ndarray) -> None:
    """The full state from [M]'s slow variables: L, the attitude at ψ = φ = 0, each eddy mode at its steady
    response to the field along the free motion (:func:`gyro_sim.frozen_flow.steady_modes`)."""
    Lc, q = _m_outputs(*(np.atleast_1d(v) for v in y_slow))
    sim.y[0:3], sim.y[3:7] = Lc[0], q[0]
    _steady_modes(sim)


def _steady_modes(sim) -> None:
    """Set each eddy mode of an axisymmetric rotor to its steady response to the present field along the
    free motion of the present (L, attitude) (:func:`gyro_sim.frozen_flow.steady_modes`); none for the
    quasi-static torque."""
    from gyro_sim.compiled import frozen_flow

    if sim.tau.size:
        ax = frozen_flow.supported(sim.J)
        ax = 2 if ax < 0 else ax  # the averaged regions take J1 = J2 to 1e-9: the polar axis x3
        Bre, Bim, om = sim.phasors()
        sim.y[7:7 + 3 * sim.tau.size] = frozen_flow.steady_modes(
            sim.y, Bre, Bim, om, sim.J[(ax + 1) % 3], sim.J[ax], ax, 1.0 / sim.tau, sim.w, sim.c_m, sim.tail).ravel()


# ------------------------------------------------------------------------------------------------
# [K]'s averaged model in the hybrid
# ------------------------------------------------------------------------------------------------
def k_region(runner: Runner) -> tuple[Optional[SlowK], str]:
    """([K]'s averaged model, '') if it holds at the runner's present state and commands, else (None, why)."""
    cache = runner.__dict__.setdefault("_slow_k", {})
    key = commands_key(runner.sim)
    if key not in cache:
        model, why = slow_k_of(runner)
        if model is not None:
            from dataclasses import replace

            model = replace(model, mu_max=mu_max(runner))
        cache[key] = (model, why)
    model, why = cache[key]
    if model is None:
        return None, why
    ok, why = model.check(slow_k_state(runner.sim), margin=ENTER_MARGIN)
    return (model, "") if ok else (None, why)


def _k_stretch(r: Runner, model: SlowK, cmd_times: list, segments: list) -> tuple[int, bool]:
    """Jump the runner over a stretch of [K]'s averaged model: to the next command, output window or the end,
    or to the instant its solution leaves the region (a solve_ivp event); there back to the full model
    (L, θ kept, ψ = φ = 0, eddy modes at their steady response). Returns (RHS evaluations, whether it ended
    at the region's edge)."""
    sim = r.sim
    t0 = sim.t
    x0 = slow_k_state(sim)
    atol = np.array([1e-12 * float(np.linalg.norm(x0[0:3]))] * 3 + [1e-12])
    sol, rows, t1, x1, edge = _integrate_slow(r, model.rhs, x0, atol, [model.exit_event()],
                                              _stretch_end(r, cmd_times), "[K]")
    n = rows.size
    if n:
        X = sol.sol(r.t_out[rows])
        L, th = X[0:3].T, X[3]
        _write_averaged_rows(r, rows, L, _k_attitude(L, th), model.torque(L, th))
    _jump(r, n, t0, t1)
    segments.append((t0, t1))
    sim.y[0:3], sim.y[3:7] = x1[0:3], _k_attitude(x1[None, 0:3], x1[3:4])[0]
    _steady_modes(sim)
    r.apply_scene_commands()
    return int(sol.nfev), edge


def _k_attitude(L: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Attitude (n, 4) at ψ = φ = 0 for case-frame L (n, 3) and θ (n,): the L-frame turned by θ about y1."""
    Ln = np.linalg.norm(L, axis=1)
    return _m_outputs(Ln, np.arctan2(np.hypot(L[:, 0], L[:, 1]), L[:, 2]), np.arctan2(L[:, 1], L[:, 0]), theta)[1]
