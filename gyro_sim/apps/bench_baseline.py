"""The compiled baseline of the benchmark: classic fixed-step RK4 on a numba right-hand side of the same model.

:func:`gyro_sim.bench.numpy_rhs` is the baseline a user writes for ``solve_ivp``; this is the one a user who
knows numba writes: the same right-hand side (:func:`rhs`, the model of docs/numerics.md: L in the case frame,
the attitude quaternion, the eddy modes, the field's rotating phasors), compiled, and the classic four-stage
Runge–Kutta method with a fixed step (:func:`rk4_span`), no error control. Its accuracy knob is the number of
steps over the horizon; :func:`rk4_sweep` sweeps it by factors of 2 to get its work-precision curve, scored
with the benchmark's error measure (``bench.final_error``) against the benchmark's reference.

It integrates both torque models of the work-precision scenes: ``lag`` (eddy modes, [M] (2.15) for a thin
shell, the modal form of [M] (2.14) for a sphere) and ``quasi_static`` ([K] (1.2): no modes,
T_tail = τ_eff). Scenes with effects (physics.md §4) are refused: ``numpy_rhs`` has none either.

Every compiled path is called once (:func:`warm`) before anything is timed, so no run pays numba's compile
or cache load.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np
from numba import njit

from gyro_sim.apps.bench_core import RK4_METHOD  # the method label of the tables, CSV and plot

__all__ = ["RK4_METHOD", "RK4_STEPS", "rhs", "rk4_span", "rk4_once", "run_rk4", "rk4_sweep", "warm"]

#: the sweep: steps over the horizon, by factors of 2 from one step (where the solution is smooth enough, as the
#: quasi-static model's L, a few steps reach 1e-6; the lag model's modes need the field's turns resolved)
RK4_STEPS = tuple(2 ** k for k in range(23))  # 1 … 4 194 304
#: the sweep stops below this error (round-off dominates there; far below the benchmark's 1e-6)
RK4_FLOOR = 1e-11
STAGES = 4  # right-hand-side evaluations per step
#: steps of the untimed first run (the scene's path compiled or loaded): enough to stay finite
STABLE_STEPS = 1 << 16


# ----------------------------------------------------------------------------------------
# the right-hand side (numba), written like bench.numpy_rhs


@njit(cache=True, inline="always")
def _field(s, Bre, Bim, om):
    """B and dB/dt (case frame; T, T/s) at s = t − t_seg: B = Σ_p Bre_p cos(ω_p s) + Bim_p sin(ω_p s)
    (physics.md §2, the segment's phasors)."""
    Bx = By = Bz = 0.0
    dx = dy = dz = 0.0
    for p in range(om.shape[0]):
        c = math.cos(om[p] * s)
        sn = math.sin(om[p] * s)
        Bx += Bre[p, 0] * c + Bim[p, 0] * sn
        By += Bre[p, 1] * c + Bim[p, 1] * sn
        Bz += Bre[p, 2] * c + Bim[p, 2] * sn
        dx += om[p] * (Bim[p, 0] * c - Bre[p, 0] * sn)
        dy += om[p] * (Bim[p, 1] * c - Bre[p, 1] * sn)
        dz += om[p] * (Bim[p, 2] * c - Bre[p, 2] * sn)
    return Bx, By, Bz, dx, dy, dz


@njit(cache=True, inline="always")
def _matrix(qw, qx, qy, qz):
    """R (body → case, row-major 9-tuple) of the unit quaternion (w, x, y, z)."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))


@njit(cache=True, inline="always")
def _mul(R, x, y, z):
    """R v: a body-frame vector in the case frame."""
    return (R[0] * x + R[1] * y + R[2] * z, R[3] * x + R[4] * y + R[5] * z, R[6] * x + R[7] * y + R[8] * z)


@njit(cache=True, inline="always")
def _mul_t(R, x, y, z):
    """Rᵀ v: a case-frame vector in the body frame."""
    return (R[0] * x + R[3] * y + R[6] * z, R[1] * x + R[4] * y + R[7] * z, R[2] * x + R[5] * y + R[8] * z)


@njit(cache=True)
def rhs(s, y, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail, F):
    """F = dy/dt of the full model at s = t − t_seg (s), the same function as ``bench.numpy_rhs``.

    y = [L (case, N·m·s), q = (w, x, y, z) body → case, e_n (body, T) 3 per mode]; ``Jinv`` 1/J (body, 1/(kg m²)),
    ``c_m`` = 2π r2³/μ0 (A m²/T), ``w`` the modes' weights, ``inv_tau`` 1/τ_n (1/s), ``tail`` T_tail (s; the
    quasi-static model: τ_eff and no modes). Rotations use q/|q|, the kinematics q itself (as numpy_rhs).
    """
    Bx, By, Bz, dBx, dBy, dBz = _field(s, Bre, Bim, om)
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    nq = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    R = _matrix(q0 / nq, q1 / nq, q2 / nq, q3 / nq)
    Lbx, Lby, Lbz = _mul_t(R, y[0], y[1], y[2])
    Ox, Oy, Oz = Jinv[0] * Lbx, Jinv[1] * Lby, Jinv[2] * Lbz  # Ω_b = J⁻¹ Rᵀ L   physics.md §1
    # dq/dt = ½ q ⊗ (0, Ω_b)   physics.md §1
    F[3] = -0.5 * (q1 * Ox + q2 * Oy + q3 * Oz)
    F[4] = 0.5 * (q0 * Ox + q2 * Oz - q3 * Oy)
    F[5] = 0.5 * (q0 * Oy + q3 * Ox - q1 * Oz)
    F[6] = 0.5 * (q0 * Oz + q1 * Oy - q2 * Ox)
    nm = inv_tau.shape[0]
    if c_m == 0.0:
        F[0] = F[1] = F[2] = 0.0
        for n in range(nm):
            for j in range(3):
                F[7 + 3 * n + j] = -y[7 + 3 * n + j] * inv_tau[n]
        return
    Bbx, Bby, Bbz = _mul_t(R, Bx, By, Bz)
    # dB_b/dt = Rᵀ dB/dt − Ω_b × B_b   docs/numerics.md
    ux, uy, uz = _mul_t(R, dBx, dBy, dBz)
    ux -= Oy * Bbz - Oz * Bby
    uy -= Oz * Bbx - Ox * Bbz
    uz -= Ox * Bby - Oy * Bbx
    # m_b = c (Σ w_n e_n − T_tail dB_b/dt)   [M] (2.15), modal (2.14); no modes, T_tail = τ_eff: [K] (1.2)
    mx, my, mz = -tail * ux, -tail * uy, -tail * uz
    for n in range(nm):
        k = 7 + 3 * n
        mx += w[n] * y[k]
        my += w[n] * y[k + 1]
        mz += w[n] * y[k + 2]
        # τ_n ė_n + e_n = −τ_n dB_b/dt   [M] (2.15)
        F[k] = -y[k] * inv_tau[n] - ux
        F[k + 1] = -y[k + 1] * inv_tau[n] - uy
        F[k + 2] = -y[k + 2] * inv_tau[n] - uz
    mcx, mcy, mcz = _mul(R, c_m * mx, c_m * my, c_m * mz)
    # N = m × B (case frame)   physics.md §3
    F[0] = mcy * Bz - mcz * By
    F[1] = mcz * Bx - mcx * Bz
    F[2] = mcx * By - mcy * Bx


@njit(cache=True)
def rk4_span(y, h, n, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail):
    """n classic RK4 steps of h (s) from s = 0, y advanced in place (units of :func:`rhs`); no error control:
    y ← y + h/6 (k1 + 2 k2 + 2 k3 + k4), k_i the right-hand sides at s, s + h/2, s + h/2, s + h."""
    m = y.shape[0]
    k1 = np.empty(m)
    k2 = np.empty(m)
    k3 = np.empty(m)
    k4 = np.empty(m)
    yt = np.empty(m)
    for i in range(n):
        s = i * h
        rhs(s, y, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail, k1)
        for j in range(m):
            yt[j] = y[j] + 0.5 * h * k1[j]
        rhs(s + 0.5 * h, yt, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail, k2)
        for j in range(m):
            yt[j] = y[j] + 0.5 * h * k2[j]
        rhs(s + 0.5 * h, yt, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail, k3)
        for j in range(m):
            yt[j] = y[j] + h * k3[j]
        rhs(s + h, yt, Bre, Bim, om, Jinv, c_m, w, inv_tau, tail, k4)
        for j in range(m):
            y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


# ----------------------------------------------------------------------------------------
# runs


def model_args(sim) -> tuple:
    """(Bre, Bim, ω, J⁻¹, c_m, w, 1/τ, T_tail) of a :class:`gyro_sim.Simulator`'s present segment, as the
    compiled functions take them (C-contiguous float64: one compiled signature for every scene)."""
    Bre, Bim, om = sim.phasors()
    tau = np.asarray(sim.tau, float)
    inv_tau = 1.0 / tau if tau.size else np.zeros(0)
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    return (f64(Bre).reshape(-1, 3), f64(Bim).reshape(-1, 3), f64(om).ravel(), f64(sim.Jinv), float(sim.c_m),
            f64(sim.w).ravel(), f64(inv_tau), float(sim.tail))


def rk4_once(scene, horizon: float, steps: int):
    """The scene (controller removed by the caller) over ``horizon`` s with ``steps`` RK4 steps in all, split
    between its command segments in proportion to their length (at least one each). Returns (the Simulator at
    the end, RHS evaluations, steps taken): ``bench.drive_segments``, which normalises q at each command instant
    and at the end."""
    from gyro_sim.apps.bench_core import drive_segments

    def advance(sim, t_next):
        n = max(1, int(round(steps * (t_next - sim.t) / horizon)))
        y = np.ascontiguousarray(sim.y, dtype=np.float64).copy()
        rk4_span(y, (t_next - sim.t) / n, n, *model_args(sim))
        return y, STAGES * n, n

    return drive_segments(scene, horizon, advance)


def _check_scene(scene) -> None:
    """Refuse what :func:`rhs` does not model: effects (physics.md §4)."""
    from gyro_sim.compiled import effects
    from gyro_sim.engine.simulate import Simulator

    if Simulator(scene).eff[effects.ON] != 0.0:
        raise ValueError(f"{scene.name}: the compiled RK4 baseline has no effects (physics.md §4)")


def run_rk4(scene_name: str, horizon: float, steps: int, extra: Optional[dict] = None, min_wall: float = 0.0,
            max_reps: int = 1, label: Optional[str] = None):
    """One timed run of the compiled RK4 baseline (``bench.Row``; knob ``steps`` over the horizon), after
    :func:`warm`; timed like the other methods (``bench._timed``: least CPU of the repeats)."""
    from gyro_sim.apps.bench_core import Row, _timed

    warm()
    scene = _load(scene_name, extra)
    wall, cpu, (sim, nfev, n) = _timed(lambda: rk4_once(scene, horizon, steps), min_wall, max_reps)
    return Row(label or scene_name, horizon, RK4_METHOD, "steps", float(n), wall, n, nfev,
               L=sim.y[0:3].copy(), q=sim.y[3:7].copy(), cpu=cpu)


def rk4_sweep(scene_name: str, horizon: float, L_ref: np.ndarray, q_ref: np.ndarray, extra: Optional[dict] = None,
              steps: Sequence[int] = RK4_STEPS, min_wall: float = 0.0, max_reps: int = 1,
              label: Optional[str] = None, say=None) -> tuple[list, list]:
    """The compiled RK4's work-precision curve: a run at each of ``steps`` (increasing), scored against the
    reference (``Row.score``: the benchmark's error measure), until the error is below :data:`RK4_FLOOR` or has
    fallen by less than 2 over the last two doublings (a 4th-order method gains 256 there: the floor is the
    reference's own error or round-off).

    Returns (rows, notes). A run whose error is above 1 or not finite (its step beyond RK4's stability: the state
    overflows) is left out of the rows and said in the notes. The scene's path (its ``Simulator``, the compiled
    functions) is run once before the first timed run.
    """
    scene = _load(scene_name, extra)
    _check_scene(scene)
    warm()
    with np.errstate(all="ignore"):
        rk4_once(scene, horizon, STABLE_STEPS)
    rows, unstable = [], []
    for n in sorted(set(int(k) for k in steps)):
        try:
            with np.errstate(all="ignore"):  # an unstable step overflows
                r = run_rk4(scene_name, horizon, n, extra, min_wall, max_reps, label)
                r.score(L_ref, q_ref)
        except ZeroDivisionError:  # (overflowed to q = 0 at a command instant's normalisation: numba raises)
            unstable.append(n)
            continue
        if not (r.error <= 1.0):  # overflowed (beyond RK4's stability) or 100 % off: no point of a curve
            unstable.append(n)
            continue
        rows.append(r)
        if say is not None:
            say(r)
        if r.error < RK4_FLOOR or (len(rows) >= 3 and rows[-3].steps * 4 == r.steps
                                   and max(x.error for x in rows[-3:]) < 1e-2 and rows[-3].error < 2.0 * r.error):
            break
    notes = [f"{label or scene_name} ({horizon:g} s): {RK4_METHOD} at {', '.join(map(str, unstable))} steps: error "
             "above 1 or not finite (beyond RK4's stability, or the motion not resolved); not listed"] if unstable else []
    return rows, notes


def _load(scene_name: str, extra: Optional[dict]):
    """The scene with ``extra`` overrides and no controller (as every work-precision method runs it)."""
    from gyro_sim.apps.bench_core import _scene_overrides
    from gyro_sim.scenes.scene import load_scene

    return load_scene(scene_name, overrides=_scene_overrides("full", extra))


_WARM: list = []


def warm() -> None:
    """Compile (or load from numba's cache) :func:`rk4_span` and :func:`rhs` for the one signature the runs use,
    once a process, before anything is timed."""
    if _WARM:
        return
    Bre = np.array([[1e-3, 0.0, 0.0]])
    Bim = np.array([[0.0, 1e-3, 0.0]])
    y = np.array([0.0, 0.0, 1e-3, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for nm in (1, 0):  # lag (one mode) and quasi-static (no mode): the same types
        rk4_span(y[:7 + 3 * nm].copy(), 1e-5, 2, Bre, Bim, np.array([100.0]), np.full(3, 1e5), 1e-2,
                 np.ones(nm), np.full(nm, 1e3), 1e-4)
    _WARM.append(True)
