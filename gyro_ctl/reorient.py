"""Reorientation of the kinetic moment along axis-parallel paths in prescribed times ([K] §2).

Three stators with mutually orthogonal axes u_k (the case axes z_k in [K]) turn their fields at
rates ν_k. Averaged over the field phases and the rotor's fast motion, with the quasi-static torque
([K] (1.3)), the component L_k = u_k·L obeys ([K] (2.1) in SI, derivation in docs/reorientation.md)

    dL_k/dt = c_k ν_k − ½ (C + c_k) ω_k,   c_k = k_e (b_k I_k)²,  C = Σ c_k,  ω_k = γ L_k / J

with J = 2 J1 J2 / (J1 + J2), κ = J3/J − 1, γ = (1 + κ sin²θ)/(1 + κ) (ω = γ L/J is the rotor's
angular velocity averaged over precession and proper rotation). [K]'s non-dimensional m_k, μ, l_k
map to c_k, 1/(J Ω0), L_k/(J Ω0): μ m_k → c_k/(J Ω0), l_k → L_k/(J Ω0), τ → Ω0 t.

To move L_p from L_p1 to L_p2 in T_p holding L_q, L_r ([K] §2, (p, q, r) cyclic):

    Δ   = 4 (ν_q − ω_q)(ν_r − ω_r) − ω_q ω_r
    λ_p = γ [2 ω_q ω_r − 3 (ν_q ω_r + ν_r ω_q) + 4 ν_q ν_r] / Δ               (dimensionless)
    c_q = c_p ω_q (2 ν_r − ω_r)/Δ,   c_r = c_p ω_r (2 ν_q − ω_q)/Δ           (so dL_q/dt = dL_r/dt = 0)
    dL_p/dt = c_p (ν_p − λ_p L_p / J)   ⇒   c_p = J ln[(ν_p − λ_p L_p1/J)/(ν_p − λ_p L_p2/J)] / (λ_p T_p)
    I_k = √(c_k / k_e) / b_k

L_p approaches the asymptote L_p∞ = J ν_p/λ_p exponentially: the target must lie strictly between
L_p1 and L_p∞ (an intermediate point, never the asymptote), else the move is refused.

Field directions (the user gives only |ν_k|): the moving stator turns toward the target,
sign ν_p = sign(L_p2 − L_p1); a holding stator turns with the rotor, sign ν_q = sign(L_q) (+ if 0),
so that it makes up the braking of the other fields.

The law :func:`reorient` is a pure function of the state and the parameters: at each tick it finds
the active waypoint by time and re-plans it from the measured L (components along the stators'
axes) and θ over the remaining time (shrinking horizon: with the averaged model exact it gives the
same constant currents as the open-loop program; otherwise it corrects the O(μ) errors). Before
``start`` and after the last waypoint all currents are 0 (no torque: L stays put). The rotor and
coil constants it needs (J1, J2, J3, k_e, b_k) come with the parameters (:func:`scene_constants`
reads them from a scene). Refusals (ValueError naming the waypoint, the target and the limit) come
from :func:`plan`, which the law runs at every tick on the remaining waypoints with their full
durations; the currents actually commanded near a waypoint's end are scaled down to
``current_limit`` (all together, so the held components stay held) rather than refused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal, Optional, Sequence

import numpy as np
from pydantic import Field, model_validator

from .numbers import Finite, NonNegative, Positive
from .strict_model import StrictModel

__all__ = [
    "Waypoint",
    "ReorientParams",
    "Segment",
    "averaged_rate",
    "averaged_gamma",
    "segment_program",
    "plan",
    "reorient",
    "scene_constants",
]

_EPS_T = 1e-9  # s: time tolerance of the waypoint schedule (the control input is stamped in ns)


_Strict = StrictModel  # (unknown keys refused, immutable: gyro_ctl/strict_model.py)


class Waypoint(_Strict):
    """One axis-parallel move: the component of L along stator ``axis`` goes to ``target`` in ``duration``."""

    axis: str  # stator name (z1 | z2 | z3 in the built-in scenes); the component is L·u_axis
    """Name of the stator whose axis u carries the moved component L·u."""
    target: Finite  # N·m·s (kinetic moment component, case frame)
    """Target of the component L·u, N·m·s (case frame)."""
    duration: Positive  # s
    """Time of the move, s."""


class ReorientParams(_Strict):
    """Reorientation of L along axis-parallel paths ([K] §2). SI units throughout.

    - ``waypoints``: moves done one after the other from ``start`` (s).
    - ``rates``: |ν_k| (rad/s, > 0) of the three stators, by stator name; distinct magnitudes
      (non-resonant: cross terms of two fields average out only if their rates differ; the beats
      |ν_i| − |ν_j| should be ≫ 1/duration). The law chooses the signs.
    - ``coil_constants``: b_k (T/A), same stator names.
    - ``inertia``: J1, J2, J3 (kg·m²) of the rotor; ``k_e`` (N·m·s/T²) its quasi-static torque
      coefficient ([K] (1.2): thin shell (2π/3) σ r2⁴ h, solid sphere (2π/15) σ a⁵).
    - ``current_limit``: largest current amplitude (A) of any stator.
    """

    law: Literal["reorient"] = "reorient"
    """The law's name."""
    waypoints: Annotated[list[Waypoint], Field(min_length=1)]
    """The moves, done one after the other from start."""
    rates: dict[str, Positive]
    """|ν_k| of the three stators by name, rad/s (distinct magnitudes; the law chooses the signs)."""
    coil_constants: dict[str, Positive]
    """Coil constants b_k by stator name, T/A."""
    inertia: Annotated[list[Positive], Field(min_length=3, max_length=3)]
    """Principal moments J1, J2, J3 of the rotor, kg·m²."""
    k_e: Positive
    """Quasi-static torque coefficient of the rotor, N·m·s/T² ([K] (1.2))."""
    current_limit: Positive
    """Largest current amplitude of any stator, A."""
    start: NonNegative = 0.0
    """Time the first move starts, s."""

    @model_validator(mode="after")
    def _consistent(self) -> "ReorientParams":
        names = list(self.rates)
        if len(names) != 3:
            raise ValueError(f"rates = {self.rates}: give |ν| (rad/s) of exactly three stators with orthogonal axes")
        if set(self.coil_constants) != set(names):
            raise ValueError(f"coil_constants names {sorted(self.coil_constants)} must be the rates names {sorted(names)}")
        v = sorted(self.rates.values())
        if v[0] == v[1] or v[1] == v[2]:
            raise ValueError(f"rates = {self.rates}: the three |ν| must differ (non-resonant fields)")
        for i, w in enumerate(self.waypoints):
            if w.axis not in names:
                raise ValueError(f"waypoints.{i}.axis = {w.axis!r}: not a stator of rates; allowed: {names}")
        return self

    @property
    def stator_names(self) -> tuple:
        return tuple(self.rates)

    def stators_used(self) -> list[str]:
        return list(self.rates)

    def schedule(self) -> list[tuple[float, float]]:
        """(t_start, t_end) of each waypoint, s."""
        out, t = [], self.start
        for w in self.waypoints:
            out.append((t, t + w.duration))
            t += w.duration
        return out


@dataclass(frozen=True)
class Segment:
    """The program of one move (SI). Arrays are in the order of ``names``."""

    names: tuple  # stator names
    p: int  # index of the moving component
    L_start: np.ndarray  # (3,) N·m·s, components along the stators' axes
    target: float  # N·m·s
    duration: float  # s
    gamma: float
    c: np.ndarray  # (3,) k_e B_k², N·m·s
    currents: np.ndarray  # (3,) A
    rates: np.ndarray  # (3,) signed ν_k, rad/s
    """|ν_k| of the three stators by name, rad/s (distinct magnitudes; the law chooses the signs)."""
    lam: float  # λ_p (dimensionless)
    asymptote: Optional[float]  # J ν_p / λ_p (N·m·s) if λ_p > 0, else None

    def commands(self) -> dict:
        return {n: (float(i), float(r)) for n, i, r in zip(self.names, self.currents, self.rates)}


def averaged_gamma(inertia: Sequence[float], theta: float) -> tuple[float, float]:
    """(J, γ): J = 2 J1 J2/(J1 + J2) (kg·m²), γ = (1 + κ sin²θ)/(1 + κ), κ = J3/J − 1 ([K] §1, (2.1))."""
    J1, J2, J3 = (float(v) for v in inertia)
    J = 2 * J1 * J2 / (J1 + J2)
    kappa = J3 / J - 1.0
    return J, (1.0 + kappa * math.sin(theta) ** 2) / (1.0 + kappa)


def averaged_rate(L: np.ndarray, c: np.ndarray, nu: np.ndarray, J: float, gamma: float) -> np.ndarray:
    """[K] (2.1) in SI: dL_k/dt = c_k ν_k − ½ (C + c_k) γ L_k / J (N·m), stators along orthogonal axes."""
    L, c, nu = (np.asarray(a, dtype=float) for a in (L, c, nu))
    w = gamma * L / J
    return c * nu - 0.5 * (c.sum() + c) * w


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def segment_program(L: Sequence[float], p: int, target: float, duration: float, *, inertia: Sequence[float],
                    theta: float, k_e: float, coil_constants: Sequence[float], rates: Sequence[float],
                    names: Sequence[str] = ("z1", "z2", "z3"), current_limit: Optional[float] = None,
                    label: str = "") -> Segment:
    """Currents and field rates that move L_p from L[p] to ``target`` in ``duration`` holding the others ([K] §2).

    L: (3,) components of L along the three (orthogonal) stator axes, N·m·s; p: index of the moving
    one; inertia (kg·m²), θ (rad, for γ), k_e (N·m·s/T²), coil constants b_k (T/A), rates |ν_k|
    (rad/s). Raises ValueError (message starting with ``label``) if the target is not strictly
    between L_p and the asymptote J ν_p/λ_p, if the other components cannot be held with these
    rates, or if a current exceeds ``current_limit`` (A, None = no check).
    """
    L = np.asarray(L, dtype=float)
    b = np.asarray(coil_constants, dtype=float)
    nu_abs = np.abs(np.asarray(rates, dtype=float))
    names = tuple(names)
    q, r = (p + 1) % 3, (p + 2) % 3
    J, gamma = averaged_gamma(inertia, theta)
    w = gamma * L / J  # averaged angular velocity components, rad/s
    d = float(target) - float(L[p])
    nu = np.empty(3)
    nu[p] = nu_abs[p] * (1.0 if d >= 0 else -1.0)
    for k in (q, r):
        nu[k] = nu_abs[k] * (1.0 if L[k] >= 0 else -1.0)
    where = (f"{label}target L_{names[p]} = {_fmt(target)} N·m·s (from {_fmt(L[p])} in {_fmt(duration)} s, "
             f"holding L_{names[q]} = {_fmt(L[q])}, L_{names[r]} = {_fmt(L[r])})")
    if d == 0.0:
        return Segment(names, p, L.copy(), float(target), float(duration), gamma, np.zeros(3), np.zeros(3), nu, 1.0,
                       None)
    Delta = 4 * (nu[q] - w[q]) * (nu[r] - w[r]) - w[q] * w[r]
    if Delta == 0.0:
        raise ValueError(f"{where}: Δ = 0, the held components are singular for |ν| = {nu_abs.tolist()} rad/s")
    lam = gamma * (2 * w[q] * w[r] - 3 * (nu[q] * w[r] + nu[r] * w[q]) + 4 * nu[q] * nu[r]) / Delta
    asym = J * nu[p] / lam if lam > 0 else None
    a1 = nu[p] - lam * L[p] / J  # dL_p/dt / c_p at the start and at the target
    a2 = nu[p] - lam * float(target) / J
    s = 1.0 if d > 0 else -1.0
    if not (s * a1 > 0 and s * a2 > 0):
        if asym is not None:
            raise ValueError(
                f"{where}: beyond the reachable limit L_{names[p]}∞ = J ν/λ = {_fmt(asym)} N·m·s "
                f"(|ν_{names[p]}| = {_fmt(nu_abs[p])} rad/s, λ = {_fmt(lam)}); the target must lie strictly between "
                f"the start value and this asymptote: lower it or raise |ν_{names[p]}|")
        raise ValueError(f"{where}: unreachable, the averaged torque along {names[p]} does not point to the target "
                         f"(λ = {_fmt(lam)} ≤ 0 with |ν| = {nu_abs.tolist()} rad/s)")
    x = lam * d / (J * a2)  # ln(a1/a2) = log1p(x); x > −1 here
    c_p = d / (a2 * duration) * (math.log1p(x) / x if abs(x) > 1e-12 else 1.0 - 0.5 * x)
    c = np.empty(3)
    c[p] = c_p
    c[q] = c_p * w[q] * (2 * nu[r] - w[r]) / Delta
    c[r] = c_p * w[r] * (2 * nu[q] - w[q]) / Delta
    if c[q] < 0 or c[r] < 0:
        k = q if c[q] < 0 else r
        raise ValueError(f"{where}: L_{names[k]} cannot be held with |ν| = {nu_abs.tolist()} rad/s (needs k_e B² < 0); "
                         f"the holding fields must turn faster than the rotor, |ν_k| well above γ|L_k|/J = "
                         f"{_fmt(abs(w[k]))} rad/s")
    currents = np.sqrt(c / k_e) / b
    if current_limit is not None and currents.max() > current_limit:
        k = int(np.argmax(currents))
        t_min = duration * (currents.max() / current_limit) ** 2
        raise ValueError(f"{where}: needs {_fmt(currents[k])} A on {names[k]} (currents {np.round(currents, 6).tolist()} A) "
                         f"above current_limit = {_fmt(current_limit)} A; the shortest duration within the limit is "
                         f"{_fmt(t_min)} s")
    return Segment(names, p, L.copy(), float(target), float(duration), gamma, c, currents, nu, float(lam), asym)


def plan(p: ReorientParams, L: Sequence[float], theta: float = 0.0, first: int = 0) -> list[Segment]:
    """The open-loop program of waypoints ``first``… from components L (N·m·s, along p.stator_names).

    Each move starts where the previous one ended (its target substituted). Raises ValueError naming
    the waypoint (1-based), its target and the violated limit.
    """
    names = p.stator_names
    rates = [p.rates[n] for n in names]
    b = [p.coil_constants[n] for n in names]
    Lc = np.asarray(L, dtype=float).copy()
    out = []
    for i in range(first, len(p.waypoints)):
        w = p.waypoints[i]
        k = names.index(w.axis)
        seg = segment_program(Lc, k, w.target, w.duration, inertia=p.inertia, theta=theta, k_e=p.k_e,
                              coil_constants=b, rates=rates, names=names, current_limit=p.current_limit,
                              label=f"reorient: waypoint {i + 1} (axis {w.axis}): ")
        out.append(seg)
        Lc[k] = w.target
    return out


def _components(x, names) -> np.ndarray:
    U = np.array([x.axis(n) for n in names], dtype=float)
    if np.max(np.abs(U @ U.T - np.eye(3))) > 1e-6:
        raise ValueError(f"reorient: the axes of stators {list(names)} must be orthonormal ([K] §2: u_k = z_k)")
    return U @ np.asarray(x.L, dtype=float)


def reorient(x, p: ReorientParams) -> dict:
    """The law: {stator: (current A, signed field rate rad/s)} for the state ``x`` (gyro_ctl.laws.ControlInput).

    Piecewise by waypoint time; within a waypoint the move is re-planned from the measured L and θ over
    the remaining time, currents scaled down together to ``current_limit`` if needed. Raises ValueError
    if the remaining program (from the present state, full durations) is infeasible.
    """
    names = p.stator_names
    off = {n: (0.0, float(p.rates[n])) for n in names}
    sched = p.schedule()
    t = float(x.t)
    if t >= sched[-1][1] - _EPS_T:
        return off
    Lc = _components(x, names)
    theta = float(x.theta)
    i = next(j for j, (t0, t1) in enumerate(sched) if t < t1 - _EPS_T)
    plan(p, Lc, theta, first=i)  # refusal of an infeasible remaining program
    t0, t1 = sched[i]
    if t < t0 - _EPS_T:
        return off
    w = p.waypoints[i]
    seg = segment_program(Lc, names.index(w.axis), w.target, t1 - t, inertia=p.inertia, theta=theta, k_e=p.k_e,
                          coil_constants=[p.coil_constants[n] for n in names], rates=[p.rates[n] for n in names],
                          names=names)
    cur = seg.currents
    m = float(cur.max())
    if m > p.current_limit:
        cur = cur * (p.current_limit / m)  # all c_k scaled by one factor: the held components stay held
    return {n: (float(I), float(nu)) for n, I, nu in zip(names, cur, seg.rates)}


def scene_constants(scene, stators: Sequence[str] = ("z1", "z2", "z3")) -> dict:
    """``inertia``, ``k_e`` and ``coil_constants`` of a scene (gyro_sim.scenes.scene.Scene), for ReorientParams.

    k_e = 2π r2³ τ_eff/μ0 of the rotor's conductor (the quasi-static coefficient of [K] (1.2)).
    """
    from gyro_sim.physics.conductor import conductor_model

    cond = scene.rotor.conductor
    model = conductor_model(cond.kind, cond.outer_radius, cond.conductivity, thickness=cond.thickness)  # (k_e: any N)
    b = {s.name: float(s.coil_constant) for s in scene.stators}
    return {"inertia": [float(v) for v in scene.rotor.inertia], "k_e": float(model.k_e),
            "coil_constants": {n: b[n] for n in stators}}
