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
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.integrate import solve_ivp

from .frames import attitude_from_euler
from .scene import Scene, SceneError
from .simulate import RunResult, Runner

THETA_MAX = 0.1  # rad
RHO_MAX = 1e-3  # rad
MU_MAX = 1e-3


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

    def g_imag(self, w: float) -> float:
        """Im ĝ(ω) of the modal model (plain floats: this is the model's whole cost)."""
        acc = w * self.tail
        for wn, tn in zip(self.weight, self.tau):
            x = w * tn
            acc += wn * x / (1.0 + x * x)
        return acc

    def torque(self, L: float) -> float:
        """Axial torque (N·m) at |L| (N·m·s): torque-slip curve."""
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
    from .simulate import Simulator

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
    on = [k for k in range(len(sim.stator_names)) if sim.current[k] > 0]
    if len(on) != 1:
        return None, f"{len(on)} stators on; the averaged model takes exactly one"
    ctl = scene.controller
    if ctl is not None and not (ctl.law == "spinup" and ctl.params.ramp is None):
        return None, f"controller law {ctl.law!r} is not a constant command"
    k = on[0]
    u = np.cross(sim.e1[k], sim.e2[k])
    L = sim.y[0:3]
    Ln = float(np.linalg.norm(L))
    if Ln == 0.0:
        return None, "|L| = 0"
    rho = math.acos(min(1.0, abs(float(L @ u)) / Ln))
    if rho > RHO_MAX:
        return None, f"L is {rho:.2e} rad off the stator axis (limit {RHO_MAX:g})"
    x = runner.control_input()
    if x.theta > THETA_MAX:
        return None, f"θ = {x.theta:.3g} rad > {THETA_MAX:g}"
    m = _model(runner, k)
    mu = m.mu(Ln)
    if mu > MU_MAX:
        return None, f"μ = {mu:.2e} > {MU_MAX:g} (spin too low for the averaging)"
    return k, ""


def _handover_to_full(runner: Runner, k: int, L: float, theta: float) -> None:
    """Rebuild the full state from (|L|, θ): L along u, attitude at ψ = φ = 0, eddy modes in their
    steady response to the present field (no switch-on transient): for a body-frame field
    B_b(t) = Re[(b_re + i b_im) e^{−i s t}], e_n = Re[ĝ_n(s)(b_re + i b_im)], b_im = (dB_b/dt)/s."""
    from .frames import quat_to_matrix

    sim = runner.sim
    u = np.cross(sim.e1[k], sim.e2[k])
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


def run_hybrid(scene: Scene, duration: Optional[float] = None) -> RunResult:
    """``fidelity: auto`` (and ``averaged``): full model where needed, the averaged model elsewhere."""
    from gyro_ctl.laws import make_law

    r = Runner(scene, duration)
    law = make_law(scene.controller) if scene.controller is not None else None
    strict = scene.fidelity == "averaged"
    w0 = time.perf_counter()
    cmd_times = sorted({c.time for c in scene.commands if c.time < r.T})
    segments = []  # (t0, t1) of averaged stretches
    nfev = 0
    while not r.done:
        if r.row > 0 and law is not None and r.is_control_tick:
            r.apply_commands(law(r.control_input()))
        if r.row > 0:
            k, why = averaged_region(r)
            if strict and k is None and not segments:
                raise SceneError(f"fidelity = 'averaged': the averaged model does not hold at t = {r.sim.t:g} s: "
                                 f"{why}; use fidelity: auto or full")
            if k is not None:
                nfev += _averaged_stretch(r, k, cmd_times, segments)
                continue
        r.advance()
    res = r.result()
    res.wall_time = time.perf_counter() - w0
    for t0, t1 in segments:  # the fast phases ψ, φ are averaged out there
        inside = (res.t > t0 + 1e-12) & (res.t < t1 - 1e-12)
        res.euler[inside, 0] = np.nan
        res.euler[inside, 2] = np.nan
    res.averaged_segments = segments
    res.averaged_rhs_evaluations = nfev
    return res


def _averaged_stretch(r: Runner, k: int, cmd_times: list, segments: list) -> int:
    """Jump the runner over an averaged stretch to the next command (or the end). Returns RHS evaluations."""
    sim = r.sim
    t0 = sim.t
    t1 = next((t for t in cmd_times if t > t0 + 1e-12), r.T)
    model = _model(r, k)
    L0 = float(np.linalg.norm(sim.y[0:3]))
    theta0 = r.control_input().theta
    rows = np.nonzero((r.t_out > t0 + 1e-12) & (r.t_out <= t1 + 1e-12))[0]
    t_eval = np.append(r.t_out[rows], t1) if (not rows.size or r.t_out[rows[-1]] < t1) else r.t_out[rows]
    L, th, nfev = model.solve(L0, theta0, t0, t_eval)
    n = rows.size
    u = np.cross(sim.e1[k], sim.e2[k]) * (1.0 if model.nu >= 0 else -1.0)
    if n:
        # attitude Y Rx(θ) (ψ = φ = 0: the fast phases are averaged out) as q_Y ⊗ (cos θ/2, sin θ/2, 0, 0)
        qY = attitude_from_euler(u, 0.0, 0.0, 0.0)
        c, s_ = np.cos(0.5 * th[:n]), np.sin(0.5 * th[:n])
        q = np.stack([qY[0] * c - qY[1] * s_, qY[0] * s_ + qY[1] * c, qY[2] * c + qY[3] * s_,
                      qY[3] * c - qY[2] * s_], axis=1)
        r.out_y[rows] = 0.0
        r.out_y[rows, 0:3] = L[:n, None] * u
        r.out_y[rows, 3:7] = q
        r.out_N[rows] = np.array([model.torque(x) for x in L[:n]])[:, None] * u
        r.cur[rows], r.rate[rows] = sim.current, sim.rate
        r.phase[rows] = np.mod(sim.phase + sim.rate * (r.t_out[rows, None] - t0), 2 * math.pi)
    # hand over: the state at t1, then the runner continues from there
    r.row += n
    r._bi = int(np.searchsorted(r.breaks, t1 + 1e-12 * max(1.0, t1)))
    sim.phase = np.mod(sim.phase + sim.rate * (t1 - t0), 2 * math.pi)
    sim.t = t1
    _handover_to_full(r, k, float(L[-1]), float(th[-1]))
    r.apply_scene_commands()
    segments.append((t0, t1))
    return nfev
