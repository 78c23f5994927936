"""Compiled kernels of the full model: right-hand side and steppers (numba, no Python objects).

State vector ``y`` (all SI):

* ``y[0:3]``  L, kinetic moment in the case frame (N·m·s)
* ``y[3:7]``  q = (w, x, y, z), attitude quaternion body → case
* ``y[7+3n : 10+3n]``  e_n, the n-th eddy mode in the body frame (T): the induced moment is
  m_b = c (Σ_n w_n e_n − T_tail dB_b/dt),  c = 2π r2³/μ0 (physics.md §3).

Without attitude (``case``: an isotropic rotor without effects whose attitude no one reads) q is not
integrated (y[3:7] stays NaN) and the modes are carried in the case frame, e_n ← R e_n: with Ω = L/J
(case) and Ṙ = [Ω]× R the filter τ ė_n + e_n = −τ dB_b/dt becomes

    τ (ė_n − Ω × e_n) + e_n = −τ (dB/dt − Ω × B),   m = c (Σ_n w_n e_n − T_tail (dB/dt − Ω × B)),

whose linear decay −e_n/τ_n is the body frame's (the same integrating factors); a field step is
e_n −= ΔB. Nothing in it depends on the attitude (:func:`nonlinear_part_case`).

Each eddy mode is the first-order filter of [M] (2.15) written for its moment:
τ_n ė_n + e_n = −τ_n dB_b/dt, so that e_n = ĝ_n(ω) B_b with ĝ_n = iωτ_n/(1 − iωτ_n) and the sum
over n is the modal form of [M] (2.14) (or of the corrected (2.13)). The quasi-static torque
[K] (1.2) is the case with no modes and T_tail = τ_eff.

Field: B(t) = Σ_p [Bre_p cos(ω_p s) + Bim_p sin(ω_p s)], s = t − t_seg (case frame, T).

Steppers:

* :func:`integrate` — with fields: the 8th-order Lawson RK of :func:`lawson_lie_step` (lawson8), or
  (:func:`integrate_etd`) exponential RK4 (Cox & Matthews 2002, ETDRK4) for L and the eddy
  modes: the stiff linear parts −e_n/τ_n are integrated exactly (φ-functions), so short τ_n
  never force short steps; the attitude takes the same RK4 stages on the rotation group
  (RKMK4, :func:`etd_lie_step`), exact for a constant body rate.
* :func:`integrate_free` — the torque-free rotor, geometric: H = |L|²/(2J_ref) + H_r; the first
  flow is an exact rotation about the fixed L, the second an exact rotation about the body axis
  of symmetry (axisymmetric body: the step is exact) or, for a triaxial body, the Lie–Poisson
  implicit midpoint rule (Cayley update) composed to 4th order. Both sub-flows keep L (case)
  and the kinetic energy to round-off; the two flows commute.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gyro_sim.compiled.compile_watch import _install as _watch_compiles
from gyro_sim.compiled.effects import DMP, MAG, NE, ON, T0, body_rate, damper_derivs, magnetizable_moment, torque_body

_watch_compiles()  # (numba's compiles and cache loads watched from its import on: compile_watch)

# ----------------------------------------------------------------------------------------
# small vector/quaternion helpers


@njit(cache=True, inline="always")
def _rotate(w, x, y, z, v, out):
    """out = R v for the unit quaternion (w, x, y, z): t = 2 (q_v × v); v' = v + w t + q_v × t."""
    vx, vy, vz = v[0], v[1], v[2]
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    out[0] = vx + w * tx + (y * tz - z * ty)
    out[1] = vy + w * ty + (z * tx - x * tz)
    out[2] = vz + w * tz + (x * ty - y * tx)


@njit(cache=True, inline="always")
def _rot_body_to_case(q, v, out):
    """out = R(q) v."""
    _rotate(q[0], q[1], q[2], q[3], v, out)


@njit(cache=True, inline="always")
def _rot_case_to_body(q, v, out):
    """out = R(q)ᵀ v (rotation by the conjugate quaternion)."""
    _rotate(q[0], -q[1], -q[2], -q[3], v, out)


@njit(cache=True, inline="always")
def _qmul(a0, a1, a2, a3, b0, b1, b2, b3, out):
    out[0] = a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3
    out[1] = a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2
    out[2] = a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1
    out[3] = a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0


@njit(cache=True)
def _normalize_q(y):
    n = math.sqrt(y[3] * y[3] + y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
    for i in range(3, 7):
        y[i] /= n


# ----------------------------------------------------------------------------------------
# fields and the right-hand side


@njit(cache=True)
def field_case(s, Bre, Bim, om, B, dB):
    """B(s) and dB/ds in the case frame (T, T/s) of a segment's phasors at s = t − t_seg."""
    B[0] = B[1] = B[2] = 0.0
    dB[0] = dB[1] = dB[2] = 0.0
    for p in range(om.shape[0]):
        c = math.cos(om[p] * s)
        sn = math.sin(om[p] * s)
        for j in range(3):
            B[j] += Bre[p, j] * c + Bim[p, j] * sn
            dB[j] += om[p] * (Bim[p, j] * c - Bre[p, j] * sn)


@njit(cache=True, inline="always")
def _rotl(w, x, y, z, vx, vy, vz):
    """R v for the unit quaternion (w, x, y, z), on scalars (no array traffic in the hot path)."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx))


@njit(cache=True, inline="always")
def phasor_trig(s, om, cs, sn):
    """cs[p], sn[p] = cos(ω_p s), sin(ω_p s): the phases of the field's phasors at s = t − t_seg."""
    for p in range(om.shape[0]):
        cs[p] = math.cos(om[p] * s)
        sn[p] = math.sin(om[p] * s)


@njit(cache=True)
def stage_trig_table(om, c, h, tab):
    """tab[i, 0, p], tab[i, 1, p] = cos, sin(ω_p c_i h): the phase advance of each phasor to stage i."""
    for i in range(c.shape[0]):
        for p in range(om.shape[0]):
            tab[i, 0, p] = math.cos(om[p] * c[i] * h)
            tab[i, 1, p] = math.sin(om[p] * c[i] * h)


@njit(cache=True, inline="always")
def _stage_trig(i, tab, tw):
    """tw[2:4] = the phases at stage i from those at the step's start tw[0:2] (angle addition)."""
    for p in range(tw.shape[1]):
        ci = tab[i, 0, p]
        si = tab[i, 1, p]
        tw[2, p] = tw[0, p] * ci - tw[1, p] * si
        tw[3, p] = tw[1, p] * ci + tw[0, p] * si


@njit(cache=True)
def nonlinear_part(s, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff):
    """:func:`nonlinear_part_at` with the phasor phases computed here, for any quaternion norm: the
    attitude is that of q/|q| and the kinematics F[3:7] = ½ q ⊗ (0, Ω_b) use q itself (a stage value
    off the unit sphere of a plain RK, or of the NumPy baseline, is treated alike)."""
    cs = np.empty(om.shape[0])
    sn = np.empty(om.shape[0])
    phasor_trig(s, om, cs, sn)
    nq = math.sqrt(y[3] * y[3] + y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
    yu = y.copy()
    for i in range(3, 7):
        yu[i] /= nq
    nonlinear_part_at(cs, sn, s, yu, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff)
    for i in range(3, 7):
        F[i] *= nq


@njit(cache=True, inline="always")
def _field_and_rates(cs, sn, Bre, Bim, om, mag):
    """The field B (T), its rate dB/dt (T/s) and, where ``mag``, its second derivative (T/s², else 0) in the case
    frame from the phasors at the phases cs, sn: 9 scalars (B, dB/dt, d²B/dt²)."""
    Bx = By = Bz = 0.0
    dBx = dBy = dBz = 0.0
    ddx = ddy = ddz = 0.0
    for p in range(om.shape[0]):
        c = cs[p]
        si = sn[p]
        bx = Bre[p, 0] * c + Bim[p, 0] * si
        by = Bre[p, 1] * c + Bim[p, 1] * si
        bz = Bre[p, 2] * c + Bim[p, 2] * si
        Bx += bx
        By += by
        Bz += bz
        dBx += om[p] * (Bim[p, 0] * c - Bre[p, 0] * si)
        dBy += om[p] * (Bim[p, 1] * c - Bre[p, 1] * si)
        dBz += om[p] * (Bim[p, 2] * c - Bre[p, 2] * si)
        if mag:
            o2 = om[p] * om[p]
            ddx -= o2 * bx
            ddy -= o2 * by
            ddz -= o2 * bz
    return Bx, By, Bz, dBx, dBy, dBz, ddx, ddy, ddz


@njit(cache=True, inline="always")
def _quaternion_rate(q0, q1, q2, q3, Ox, Oy, Oz, F):
    """F[3:7] = dq/dt = ½ q ⊗ (0, Ω_b): the kinematics of the stage quaternion itself (Ω_b in rad/s, body)."""
    F[3] = -0.5 * (q1 * Ox + q2 * Oy + q3 * Oz)
    F[4] = 0.5 * (q0 * Ox + q2 * Oz - q3 * Oy)
    F[5] = 0.5 * (q0 * Oy + q3 * Ox - q1 * Oz)
    F[6] = 0.5 * (q0 * Oz + q1 * Oy - q2 * Ox)


@njit(cache=True, inline="always")
def _eddy_moment(y, w, tail, nm, dbx, dby, dbz, F):
    """The eddy moment over c, Σ w_n e_n − T_tail dB_b/dt (body frame, T; times c_m it is A·m²), and each
    mode's forcing F[7+3n:10+3n] = −dB_b/dt (T/s; the decay −e_n/τ_n is the linear part)."""
    mx = -tail * dbx
    my = -tail * dby
    mz = -tail * dbz
    for n in range(nm):
        k = 7 + 3 * n
        mx += w[n] * y[k]
        my += w[n] * y[k + 1]
        mz += w[n] * y[k + 2]
        F[k] = -dbx
        F[k + 1] = -dby
        F[k + 2] = -dbz
    return mx, my, mz


@njit(cache=True, inline="always")
def nonlinear_part_at(cs, sn, s, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff):
    """F = right-hand side of the state without the linear mode decay −e_n/τ_n, for a unit quaternion y[3:7].

    ``cs``, ``sn``: cos(ω_p s), sin(ω_p s) of each phasor (the steppers get them by angle addition
    from one evaluation per step: see :func:`stage_trig`).

    F[0:3] = N (case, N·m) = (R m_b) × B  with m_b = c (Σ w_n e_n − T_tail dB_b/dt)   [physics.md §3]
    F[3:7] = ½ q ⊗ (0, Ω_b),  Ω_b = J⁻¹ Rᵀ L
    F[7+3n+j] = −(dB_b/dt)_j,  dB_b/dt = Rᵀ dB/dt − Ω_b × B_b
    ``eff`` (:mod:`gyro_sim.effects`): with eff[ON] ≠ 0 the effects change Ω_b, add torques, replace
    m_b by the magnetizable body's and give the damper's states F[7+3nm:]. ``work`` (length ≥ 25)
    receives Ω_b in work[12:15]. Written on scalars: array views in the hot path cost about 3×
    (measured by the benchmark).
    """
    has_eff = eff[ON] != 0.0
    mag = has_eff and eff[MAG] != 0.0
    # field and its rate (case frame)
    Bx, By, Bz, dBx, dBy, dBz, ddx, ddy, ddz = _field_and_rates(cs, sn, Bre, Bim, om, mag)
    # q is a unit quaternion (the steppers' stage attitudes are q_n ⊗ exp(u));
    # Rᵀ is the conjugate's rotation
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    w0, x0, y0, z0 = q0, q1, q2, q3
    Lbx, Lby, Lbz = _rotl(w0, -x0, -y0, -z0, y[0], y[1], y[2])
    k0 = 7 + 3 * nm
    t_abs = s
    if has_eff:
        t_abs = eff[T0] + s
        Ox, Oy, Oz = body_rate(t_abs, Lbx, Lby, Lbz, y, k0, Jinv, eff)
    else:
        Ox = Jinv[0] * Lbx
        Oy = Jinv[1] * Lby
        Oz = Jinv[2] * Lbz
    work[12] = Ox
    work[13] = Oy
    work[14] = Oz
    _quaternion_rate(q0, q1, q2, q3, Ox, Oy, Oz, F)
    for i in range(k0, F.shape[0]):  # extra states: the damper writes its own below
        F[i] = 0.0
    if c_m == 0.0 and not mag:
        F[0] = F[1] = F[2] = 0.0
        for i in range(7, k0):
            F[i] = 0.0
    else:
        Bbx, Bby, Bbz = _rotl(w0, -x0, -y0, -z0, Bx, By, Bz)
        dbx, dby, dbz = _rotl(w0, -x0, -y0, -z0, dBx, dBy, dBz)
        if mag:
            # B̈_b = Rᵀ B̈ − 2 Ω × (Rᵀ Ḃ) + Ω × (Ω × B_b) − Ω̇ × B_b, Ω̇ from the M and P1 torque ([BS]: to
            # the order of the expansion the P2 term's own torque is not needed in Ω̇)
            ax, ay, az = _rotl(w0, -x0, -y0, -z0, ddx, ddy, ddz)
            wbx, wby, wbz = Oy * Bbz - Oz * Bby, Oz * Bbx - Ox * Bbz, Ox * Bby - Oy * Bbx
            ax += -2.0 * (Oy * dbz - Oz * dby) + (Oy * wbz - Oz * wby)
            ay += -2.0 * (Oz * dbx - Ox * dbz) + (Oz * wbx - Ox * wbz)
            az += -2.0 * (Ox * dby - Oy * dbx) + (Ox * wby - Oy * wbx)
        # dB_b/dt = Rᵀ dB/dt − Ω_b × B_b
        dbx -= Oy * Bbz - Oz * Bby
        dby -= Oz * Bbx - Ox * Bbz
        dbz -= Ox * Bby - Oy * Bbx
        if mag:
            m1x, m1y, m1z = magnetizable_moment(eff, Bbx, Bby, Bbz, dbx, dby, dbz, 0.0, 0.0, 0.0)
            gx = (m1y * Bbz - m1z * Bby) - (Oy * Lbz - Oz * Lby)
            gy = (m1z * Bbx - m1x * Bbz) - (Oz * Lbx - Ox * Lbz)
            gz = (m1x * Bby - m1y * Bbx) - (Ox * Lby - Oy * Lbx)
            dOx, dOy, dOz = Jinv[0] * gx, Jinv[1] * gy, Jinv[2] * gz
            ax -= dOy * Bbz - dOz * Bby
            ay -= dOz * Bbx - dOx * Bbz
            az -= dOx * Bby - dOy * Bbx
            mx, my, mz = magnetizable_moment(eff, Bbx, Bby, Bbz, dbx, dby, dbz, ax, ay, az)
            mcx, mcy, mcz = _rotl(w0, x0, y0, z0, mx, my, mz)
        else:
            mx, my, mz = _eddy_moment(y, w, tail, nm, dbx, dby, dbz, F)
            mcx, mcy, mcz = _rotl(w0, x0, y0, z0, c_m * mx, c_m * my, c_m * mz)
        # N = m × B (case frame)
        F[0] = mcy * Bz - mcz * By
        F[1] = mcz * Bx - mcx * Bz
        F[2] = mcx * By - mcy * Bx
    if has_eff:
        x3x, x3y, x3z = _rotl(w0, x0, y0, z0, 0.0, 0.0, 1.0)
        nbx, nby, nbz, ncx, ncy, ncz = torque_body(t_abs, Ox, Oy, Oz, x3x, x3y, x3z, eff)
        tx, ty, tz = _rotl(w0, x0, y0, z0, nbx, nby, nbz)
        F[0] += tx + ncx
        F[1] += ty + ncy
        F[2] += tz + ncz
        if eff[DMP] != 0.0:
            Nbx, Nby, Nbz = _rotl(w0, -x0, -y0, -z0, F[0], F[1], F[2])
            damper_derivs(t_abs, y, k0, Jinv, eff, Lbx, Lby, Lbz, Ox, Oy, Oz, Nbx, Nby, Nbz, F)


@njit(cache=True, inline="always")
def nonlinear_part_plain(cs, sn, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work):
    """:func:`nonlinear_part_at` without the effects (``eff`` off), the same arithmetic (the same pieces:
    :func:`_field_and_rates`, :func:`_quaternion_rate`, :func:`_eddy_moment`): what a stepper that never runs with an
    effect on (frozen flow, quasi-static flow) records as its output torque. The effects' code compiled into the
    output kernel cost 1.7 s of the default scene's first compile (issue 31)."""
    Bx, By, Bz, dBx, dBy, dBz, _, _, _ = _field_and_rates(cs, sn, Bre, Bim, om, False)
    q0, q1, q2, q3 = y[3], y[4], y[5], y[6]
    Lbx, Lby, Lbz = _rotl(q0, -q1, -q2, -q3, y[0], y[1], y[2])
    k0 = 7 + 3 * nm
    Ox = Jinv[0] * Lbx
    Oy = Jinv[1] * Lby
    Oz = Jinv[2] * Lbz
    work[12] = Ox
    work[13] = Oy
    work[14] = Oz
    _quaternion_rate(q0, q1, q2, q3, Ox, Oy, Oz, F)
    for i in range(k0, F.shape[0]):
        F[i] = 0.0
    if c_m == 0.0:
        F[0] = F[1] = F[2] = 0.0
        for i in range(7, k0):
            F[i] = 0.0
        return
    Bbx, Bby, Bbz = _rotl(q0, -q1, -q2, -q3, Bx, By, Bz)
    dbx, dby, dbz = _rotl(q0, -q1, -q2, -q3, dBx, dBy, dBz)
    dbx -= Oy * Bbz - Oz * Bby  # dB_b/dt = Rᵀ dB/dt − Ω_b × B_b
    dby -= Oz * Bbx - Ox * Bbz
    dbz -= Ox * Bby - Oy * Bbx
    mx, my, mz = _eddy_moment(y, w, tail, nm, dbx, dby, dbz, F)
    mcx, mcy, mcz = _rotl(q0, q1, q2, q3, c_m * mx, c_m * my, c_m * mz)
    F[0] = mcy * Bz - mcz * By  # N = m × B (case frame)
    F[1] = mcz * Bx - mcx * Bz
    F[2] = mcx * By - mcy * Bx


@njit(cache=True, inline="always")
def nonlinear_part_case(cs, sn, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work):
    """Case-frame right-hand side without the linear mode decay, for an isotropic rotor without effects and
    without attitude (module docstring): y[0:3] = L (case, N·m·s), y[7+3n:10+3n] = e_n (case, T).

    Ω = L/J (rad/s, case; ``Jinv`` all equal), u = dB/dt − Ω × B (T/s, the field's rate seen from the body,
    in the case frame), m = c (Σ w_n e_n − T_tail u) (A·m²):
    F[0:3] = N = m × B (N·m), F[3:7] = 0, F[7+3n:10+3n] = Ω × e_n − u  (τ(ė − Ω×e) + e = −τ u).
    ``cs``, ``sn``: cos, sin(ω_p s) of each phasor; work[12:15] receives Ω.
    """
    Bx = By = Bz = 0.0
    dBx = dBy = dBz = 0.0
    for p in range(om.shape[0]):
        c = cs[p]
        si = sn[p]
        Bx += Bre[p, 0] * c + Bim[p, 0] * si
        By += Bre[p, 1] * c + Bim[p, 1] * si
        Bz += Bre[p, 2] * c + Bim[p, 2] * si
        dBx += om[p] * (Bim[p, 0] * c - Bre[p, 0] * si)
        dBy += om[p] * (Bim[p, 1] * c - Bre[p, 1] * si)
        dBz += om[p] * (Bim[p, 2] * c - Bre[p, 2] * si)
    Ox = Jinv[0] * y[0]
    Oy = Jinv[0] * y[1]
    Oz = Jinv[0] * y[2]
    work[12] = Ox
    work[13] = Oy
    work[14] = Oz
    for i in range(3, 7):
        F[i] = 0.0
    if c_m == 0.0:
        for i in range(F.shape[0]):
            F[i] = 0.0
        return
    ux = dBx - (Oy * Bz - Oz * By)
    uy = dBy - (Oz * Bx - Ox * Bz)
    uz = dBz - (Ox * By - Oy * Bx)
    mx = -tail * ux
    my = -tail * uy
    mz = -tail * uz
    for n in range(nm):
        k = 7 + 3 * n
        ex, ey, ez = y[k], y[k + 1], y[k + 2]
        mx += w[n] * ex
        my += w[n] * ey
        mz += w[n] * ez
        F[k] = (Oy * ez - Oz * ey) - ux
        F[k + 1] = (Oz * ex - Ox * ez) - uy
        F[k + 2] = (Ox * ey - Oy * ex) - uz
    mx *= c_m
    my *= c_m
    mz *= c_m
    F[0] = my * Bz - mz * By
    F[1] = mz * Bx - mx * Bz
    F[2] = mx * By - my * Bx


# ----------------------------------------------------------------------------------------
# exponential RK4


@njit(cache=True)
def _phi123(z):
    """φ1, φ2, φ3 of a real z (stable near 0): φ_k(z) = Σ_j z^j/(j+k)!."""
    if abs(z) < 0.5:
        p1 = 0.0
        p2 = 0.0
        p3 = 0.0
        term = 1.0  # z^j / j!
        for j in range(20):
            p1 += term / (j + 1)
            p2 += term / ((j + 1) * (j + 2))
            p3 += term / ((j + 1) * (j + 2) * (j + 3))
            term *= z / (j + 1)
        return p1, p2, p3
    if z < -1e3:  # e^z underflows: the exact asymptotic forms, without z² or z³ overflowing
        iz = 1.0 / z
        return -iz, -iz - iz * iz, -0.5 * iz - iz * iz - iz * iz * iz
    ez = math.exp(z)
    p1 = (ez - 1.0) / z
    p2 = (ez - 1.0 - z) / (z * z)
    p3 = (ez - 1.0 - z - 0.5 * z * z) / (z * z * z)
    return p1, p2, p3


@njit(cache=True)
def etd_coefficients(lam, h, E, E2, Q, A1, A2, A3):
    """ETDRK4 coefficients of Cox & Matthews (2002) for linear rates ``lam`` and step ``h``."""
    for i in range(lam.shape[0]):
        z = lam[i] * h
        E[i] = math.exp(z)
        E2[i] = math.exp(0.5 * z)
        p1h, _, _ = _phi123(0.5 * z)
        Q[i] = 0.5 * h * p1h
        p1, p2, p3 = _phi123(z)
        A1[i] = h * (p1 - 3.0 * p2 + 4.0 * p3)
        A2[i] = h * 2.0 * (p2 - 2.0 * p3)
        A3[i] = h * (-p2 + 4.0 * p3)


@njit(cache=True, inline="always")
def _q_exp(q, u0, u1, u2, out):
    """out = q ⊗ exp(u) for a body-frame rotation vector u (rad): the quaternion (cos ½|u|, sin ½|u| û)."""
    th = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    c = math.cos(0.5 * th)
    sc = 0.5 - th * th / 48.0 if th < 1e-4 else math.sin(0.5 * th) / th
    _qmul(q[0], q[1], q[2], q[3], c, sc * u0, sc * u1, sc * u2, out)


@njit(cache=True, inline="always")
def _q_exp_alpha(q, u0, u1, u2, out):
    """out = q ⊗ exp(u) (as :func:`_q_exp`); returns α of dexp⁻¹ at u (:func:`_dexpinv_alpha`) from the same
    cos and sin of |u|/2: α = (1 − (θ/2) cot(θ/2))/θ², θ = |u|."""
    th2 = u0 * u0 + u1 * u1 + u2 * u2
    th = math.sqrt(th2)
    c = math.cos(0.5 * th)
    if th < 1e-4:
        sc = 0.5 - th2 / 48.0
        a = 1.0 / 12.0 + th2 / 720.0
    else:
        sn = math.sin(0.5 * th)
        sc = sn / th
        a = (1.0 - 0.5 * th * c / sn) / th2
    _qmul(q[0], q[1], q[2], q[3], c, sc * u0, sc * u1, sc * u2, out)
    return a


@njit(cache=True, inline="always")
def _dexpinv_alpha(a, u0, u1, u2, v0, v1, v2, out):
    """out = dexp⁻¹_{−u}(v) on so(3), exact: v + ½ u×v + α u×(u×v), α from :func:`_q_exp_alpha`.

    For R = R_n exp(û) with body rates v (R' = R v̂): u' = dexp⁻¹_{−u}(v)."""
    c0 = u1 * v2 - u2 * v1
    c1 = u2 * v0 - u0 * v2
    c2 = u0 * v1 - u1 * v0
    out[0] = v0 + 0.5 * c0 + a * (u1 * c2 - u2 * c1)
    out[1] = v1 + 0.5 * c1 + a * (u2 * c0 - u0 * c2)
    out[2] = v2 + 0.5 * c2 + a * (u0 * c1 - u1 * c0)


@njit(cache=True)
def etd_lie_step(y, s, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, E, E2, Q, A1, A2, A3, buf, work, K, eff,
                 tab, tw):
    """One step of ETDRK4 with the attitude advanced on the rotation group (RKMK4, in place on y).

    L and the eddy modes take the Cox–Matthews ETDRK4 step; the quaternion is q_n ⊗ exp(u) with u
    from the classical RK4 tableau applied to u' = dexp⁻¹_u(Ω_b) (Munthe-Kaas). A constant Ω_b is
    integrated exactly, so the spin itself costs no accuracy: only the change of Ω_b and of the
    body-frame field (the slip) sets the error.
    """
    n = y.shape[0]
    Nu = buf[0]
    Na = buf[1]
    Nb = buf[2]
    Nc = buf[3]
    a = buf[4]
    b = buf[5]
    cc = buf[6]
    # K[0:12]: the stage increments K1..K4 (rad/s); K[12:16] scratch
    q0 = y[3:7]
    # tab: the phase advances to s + h/2 and s + h (stages 1, 2 of the table), tw[0:2] the phases at s
    phasor_trig(s, om, tw[0], tw[1])
    nonlinear_part_at(tw[0], tw[1], s, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nu, work, eff)
    _stage_trig(1, tab, tw)
    K[0] = work[12]
    K[1] = work[13]
    K[2] = work[14]
    for i in range(n):
        a[i] = E2[i] * y[i] + Q[i] * Nu[i]
    al = _q_exp_alpha(q0, 0.5 * h * K[0], 0.5 * h * K[1], 0.5 * h * K[2], a[3:7])
    nonlinear_part_at(tw[2], tw[3], s + 0.5 * h, a, Bre, Bim, om, Jinv, c_m, w, tail, nm, Na, work, eff)
    _dexpinv_alpha(al, 0.5 * h * K[0], 0.5 * h * K[1], 0.5 * h * K[2], work[12], work[13], work[14], K[3:6])
    for i in range(n):
        b[i] = E2[i] * y[i] + Q[i] * Na[i]
    al = _q_exp_alpha(q0, 0.5 * h * K[3], 0.5 * h * K[4], 0.5 * h * K[5], b[3:7])
    nonlinear_part_at(tw[2], tw[3], s + 0.5 * h, b, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nb, work, eff)
    _dexpinv_alpha(al, 0.5 * h * K[3], 0.5 * h * K[4], 0.5 * h * K[5], work[12], work[13], work[14], K[6:9])
    for i in range(n):
        cc[i] = E2[i] * a[i] + Q[i] * (2.0 * Nb[i] - Nu[i])
    al = _q_exp_alpha(q0, h * K[6], h * K[7], h * K[8], cc[3:7])
    _stage_trig(2, tab, tw)
    nonlinear_part_at(tw[2], tw[3], s + h, cc, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nc, work, eff)
    _dexpinv_alpha(al, h * K[6], h * K[7], h * K[8], work[12], work[13], work[14], K[9:12])
    u0 = h / 6.0 * (K[0] + 2.0 * K[3] + 2.0 * K[6] + K[9])
    u1 = h / 6.0 * (K[1] + 2.0 * K[4] + 2.0 * K[7] + K[10])
    u2 = h / 6.0 * (K[2] + 2.0 * K[5] + 2.0 * K[8] + K[11])
    for i in range(n):
        if i < 3 or i > 6:
            y[i] = E[i] * y[i] + A1[i] * Nu[i] + A2[i] * (Na[i] + Nb[i]) + A3[i] * Nc[i]
    _q_exp(q0, u0, u1, u2, K[12:16])
    for i in range(4):
        y[3 + i] = K[12 + i]
    _normalize_q(y)


@njit(cache=True)
def etd_case_step(y, s, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, E, E2, Q, A1, A2, A3, buf, work, tab, tw):
    """One ETDRK4 step (Cox & Matthews 2002) of the case-frame state without attitude (in place on y;
    :func:`nonlinear_part_case`): L and the modes only, y[3:7] untouched."""
    n = y.shape[0]
    Nu = buf[0]
    Na = buf[1]
    Nb = buf[2]
    Nc = buf[3]
    a = buf[4]
    b = buf[5]
    cc = buf[6]
    phasor_trig(s, om, tw[0], tw[1])
    nonlinear_part_case(tw[0], tw[1], y, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nu, work)
    _stage_trig(1, tab, tw)
    for i in range(n):
        a[i] = E2[i] * y[i] + Q[i] * Nu[i]
    nonlinear_part_case(tw[2], tw[3], a, Bre, Bim, om, Jinv, c_m, w, tail, nm, Na, work)
    for i in range(n):
        b[i] = E2[i] * y[i] + Q[i] * Na[i]
    nonlinear_part_case(tw[2], tw[3], b, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nb, work)
    for i in range(n):
        cc[i] = E2[i] * a[i] + Q[i] * (2.0 * Nb[i] - Nu[i])
    _stage_trig(2, tab, tw)
    nonlinear_part_case(tw[2], tw[3], cc, Bre, Bim, om, Jinv, c_m, w, tail, nm, Nc, work)
    for i in range(n):
        if i < 3 or i > 6:
            y[i] = E[i] * y[i] + A1[i] * Nu[i] + A2[i] * (Na[i] + Nb[i]) + A3[i] * Nc[i]


@njit(cache=True, inline="always")
def _equal_steps(span, h_max):
    """(k, h): the fewest equal steps h = span/k with h ≤ h_max (k ≥ 1)."""
    k = int(math.ceil(span / h_max * (1.0 - 1e-12)))
    if k < 1:
        k = 1
    return k, span / k


@njit(cache=True)
def _resume_at(pos):
    """(stop index, step of its span) a bounded stepper call starts at: ``pos[0]``, ``pos[1]`` (0, 0 without
    ``pos``). See :func:`integrate`."""
    if pos is None:
        return 0, 0
    return int(pos[0]), int(pos[1])


@njit(cache=True)
def _steps_now(pos, max_steps, steps, j0, k):
    """The step of a span of ``k`` steps this call ends before: k, or fewer where the call's ``max_steps`` (with
    ``steps`` taken) runs out (never fewer than j0 + 1 on a call's first span: each call makes progress)."""
    if pos is None:
        return k
    left = max_steps - steps
    if left < 1 and steps == 0:
        left = 1
    return k if k - j0 <= left else j0 + left


@njit(cache=True)
def _pause(pos, i, j, t):
    """Where the next call resumes: stop ``i`` (the number of stops: done), step ``j`` of its span, which started
    at ``t`` (the next call's t0)."""
    if pos is not None:
        pos[0] = i
        pos[1] = j
        pos[2] = t


@njit(cache=True)
def integrate_etd(y, t0, t_seg, t_stops, record, h_max, Bre, Bim, om, Jinv, c_m, w, tail, lam,
                  out_y, out_N, k_out, eff):
    """:func:`integrate` with the ETDRK4 step."""
    no = np.empty(0)
    return integrate(y, t0, t_seg, t_stops, record, h_max, Bre, Bim, om, Jinv, c_m, w, tail, lam,
                     out_y, out_N, k_out, eff, np.empty((0, 0)), no, no)


# ----------------------------------------------------------------------------------------
# geometric torque-free stepper


@njit(cache=True)
def _free_body_step(y, h, Jinv, inv_ref, axis, tmp):
    """Body flow of H_r = ½ Σ (1/J_i − 1/J_ref) L_i² over h (right multiplication of q)."""
    q = y[3:7]
    Lb = tmp[0:3]
    _rot_case_to_body(q, y[0:3], Lb)
    if axis >= 0:
        # only one body axis carries H_r: L_b[axis] is constant, the flow is an exact rotation
        beta = h * (Jinv[axis] - inv_ref) * Lb[axis]
        c = math.cos(0.5 * beta)
        sn = math.sin(0.5 * beta)
        r1 = sn if axis == 0 else 0.0
        r2 = sn if axis == 1 else 0.0
        r3 = sn if axis == 2 else 0.0
        _qmul(q[0], q[1], q[2], q[3], c, r1, r2, r3, tmp[3:7])
    else:
        # Lie–Poisson implicit midpoint: L_m = L_b + (h/2) L_m × Ω_r(L_m); q ← q ⊗ cay(h Ω_r(L_m))
        m0, m1, m2 = Lb[0], Lb[1], Lb[2]
        d0 = Jinv[0] - inv_ref
        d1 = Jinv[1] - inv_ref
        d2 = Jinv[2] - inv_ref
        scale = abs(m0) + abs(m1) + abs(m2) + 1e-300
        for _ in range(100):
            o0, o1, o2 = d0 * m0, d1 * m1, d2 * m2
            n0 = Lb[0] + 0.5 * h * (m1 * o2 - m2 * o1)
            n1 = Lb[1] + 0.5 * h * (m2 * o0 - m0 * o2)
            n2 = Lb[2] + 0.5 * h * (m0 * o1 - m1 * o0)
            diff = abs(n0 - m0) + abs(n1 - m1) + abs(n2 - m2)
            m0, m1, m2 = n0, n1, n2
            if diff <= 1e-16 * scale:
                break
        v0 = 0.5 * h * d0 * m0
        v1 = 0.5 * h * d1 * m1
        v2 = 0.5 * h * d2 * m2
        nrm = 1.0 / math.sqrt(1.0 + v0 * v0 + v1 * v1 + v2 * v2)
        _qmul(q[0], q[1], q[2], q[3], nrm, v0 * nrm, v1 * nrm, v2 * nrm, tmp[3:7])
    for i in range(4):
        y[3 + i] = tmp[3 + i]


@njit(cache=True)
def _free_case_rotation(y, h, inv_ref, tmp):
    """Flow of |L|²/(2 J_ref): rotation of the body about the fixed case-frame L at |L|/J_ref."""
    L0, L1, L2 = y[0], y[1], y[2]
    Ln = math.sqrt(L0 * L0 + L1 * L1 + L2 * L2)
    if Ln == 0.0:
        return
    ang = h * Ln * inv_ref
    c = math.cos(0.5 * ang)
    sn = math.sin(0.5 * ang) / Ln
    _qmul(c, sn * L0, sn * L1, sn * L2, y[3], y[4], y[5], y[6], tmp[3:7])
    for i in range(4):
        y[3 + i] = tmp[3 + i]


@njit(cache=True)
def _free_case_modes(y, h, inv_ref, tau):
    """Torque-free step without attitude (isotropic rotor, modes in the case frame): L is constant and each
    mode turns with the body about L by |L| h / J while it decays, e_n ← e^{−h/τ_n} Rot(L̂, |L| h/J) e_n
    (Rodrigues: e cos φ + (l̂ × e) sin φ + l̂ (l̂·e)(1 − cos φ))."""
    L0, L1, L2 = y[0], y[1], y[2]
    Ln = math.sqrt(L0 * L0 + L1 * L1 + L2 * L2)
    c, sn = 1.0, 0.0
    l0 = l1 = l2 = 0.0
    if Ln > 0.0:
        l0, l1, l2 = L0 / Ln, L1 / Ln, L2 / Ln
        c, sn = math.cos(h * Ln * inv_ref), math.sin(h * Ln * inv_ref)
    for n in range(tau.shape[0]):
        k = 7 + 3 * n
        f = math.exp(-h / tau[n])
        e0, e1, e2 = y[k], y[k + 1], y[k + 2]
        d = (l0 * e0 + l1 * e1 + l2 * e2) * (1.0 - c)
        y[k] = f * (e0 * c + (l1 * e2 - l2 * e1) * sn + l0 * d)
        y[k + 1] = f * (e1 * c + (l2 * e0 - l0 * e2) * sn + l1 * d)
        y[k + 2] = f * (e2 * c + (l0 * e1 - l1 * e0) * sn + l2 * d)


#: Kahan & Li (1997), "Composition constants for raising the orders of unconventional schemes for ordinary
#: differential equations", Math. Comp. 66, scheme s15odr8: 15 substeps γ1..γ7, γ8, γ7..γ1 of a symmetric
#: second-order step give order 8 (sum 1; checked: the observed order of the free stepper, test/test_free_rotor.py)
_KL8_HALF = (0.74167036435061295344822780, -0.40910082580003159399730010, 0.19075471029623837995387626,
             -0.57386247111608226665638773, 0.29906418130365592384446354, 0.33462491824529818378495798,
             0.31529309239676659663205666)
_KL8 = _KL8_HALF + (1.0 - 2.0 * sum(_KL8_HALF),) + _KL8_HALF[::-1]


@njit(cache=True)
def free_step(y, h, Jinv, inv_ref, axis, tau):
    """One geometric step of the torque-free rotor; eddy modes (no field) decay exactly. ``axis`` −3: no
    attitude (:func:`_free_case_modes`)."""
    if axis == -3:
        _free_case_modes(y, h, inv_ref, tau)
        return
    tmp = np.empty(8)
    _free_case_rotation(y, h, inv_ref, tmp)
    if axis >= 0 or axis == -2:
        if axis >= 0:
            _free_body_step(y, h, Jinv, inv_ref, axis, tmp)
    else:
        # symmetric composition of the symmetric (order 2) midpoint step: Kahan & Li (1997) s15odr8, order 8
        for g in _KL8:
            _free_body_step(y, g * h, Jinv, inv_ref, axis, tmp)
    _normalize_q(y)
    for n in range(tau.shape[0]):
        f = math.exp(-h / tau[n])
        for j in range(3):
            y[7 + 3 * n + j] *= f


@njit(cache=True, nogil=True)
def integrate_free(y, t0, t_stops, record, h_max, Jinv, inv_ref, axis, tau, out_y, out_N, k_out, pos=None,
                   max_steps=0):
    """Torque-free counterpart of :func:`integrate` (same stops/record/output contract, ``pos`` and
    ``max_steps`` as there).

    ``axis``: body axis index carrying H_r (axisymmetric body: exact steps), −2 for a
    spherical inertia (H_r = 0), −1 for a triaxial body (4th-order midpoint composition), −3 for a
    spherical inertia without attitude (modes in the case frame, :func:`_free_case_modes`).
    """
    steps = 0
    t = t0
    i0, j0 = _resume_at(pos)
    for i in range(i0, t_stops.shape[0]):
        span = t_stops[i] - t
        if span > 0.0:
            k, h = _equal_steps(span, h_max)
            j1 = _steps_now(pos, max_steps, steps, j0, k)
            for _ in range(j0, j1):
                free_step(y, h, Jinv, inv_ref, axis, tau)
            steps += j1 - j0
            if j1 < k:
                _pause(pos, i, j1, t)
                return k_out, steps
            j0 = 0
            t = t_stops[i]
        if record[i]:
            out_y[k_out, :] = y
            out_N[k_out, 0] = 0.0
            out_N[k_out, 1] = 0.0
            out_N[k_out, 2] = 0.0
            k_out += 1
    _pause(pos, t_stops.shape[0], 0, t)
    return k_out, steps


# ----------------------------------------------------------------------------------------
# Lawson (integrating-factor) explicit Runge–Kutta with the attitude on the rotation group


def dop853_tableau() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, b, c) of the 12-stage, 8th-order Dormand–Prince method (Hairer, Nørsett & Wanner; the coefficients of
    SciPy's DOP853, kept in :mod:`gyro_sim.compiled.dop853_coefficients`)."""
    from . import dop853_coefficients as d

    s = d.N_STAGES
    A = np.zeros((s, s))
    for i, row in enumerate(d.A_ROWS):
        A[i, :i] = row
    return A, np.array(d.B, dtype=float), np.array(d.C, dtype=float)


@njit(cache=True)
def nonzero_columns(A):
    """(cols, count): the columns j < i with A[i, j] ≠ 0 of each row i (DOP853's A is about half zeros)."""
    S = A.shape[0]
    cols = np.zeros((S, max(S, 1)), dtype=np.int64)
    count = np.zeros(S, dtype=np.int64)
    for i in range(S):
        for j in range(i):
            if A[i, j] != 0.0:
                cols[i, count[i]] = j
                count[i] += 1
    return cols, count


@njit(cache=True)
def lawson_coefficients(lam, h, A, b, c, E0, W, WB, Eh):
    """Weights of a Lawson step h with the integrating factors folded in (λ_k = 0 gives the plain tableau):
    E0[i,k] = e^{c_i h λ_k}, W[i,j,k] = h A[i,j] e^{(c_i − c_j) h λ_k}, WB[j,k] = h b_j e^{(1 − c_j) h λ_k},
    Eh[k] = e^{h λ_k}."""
    S = c.shape[0]
    for k in range(lam.shape[0]):
        Eh[k] = math.exp(lam[k] * h)
        for i in range(S):
            E0[i, k] = math.exp(c[i] * h * lam[k])
            WB[i, k] = h * b[i] * math.exp((1.0 - c[i]) * h * lam[k])
            for j in range(i):
                W[i, j, k] = h * A[i, j] * math.exp((c[i] - c[j]) * h * lam[k])


@njit(cache=True)
def lawson_lie_step(y, s, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, A, b, c, cols, count, E0, W, WB, Eh, Fs, Ys, Ks,
                    work, qn, eff, tab, tw):
    """One step of a Lawson RK (tableau A, b, c) for L and the eddy modes, RKMK on the attitude (in place).

    With v = e^{−λt} y the linear decay of the modes is exact and the tableau integrates the rest, so
    the method keeps the tableau's order where h/τ_n is moderate (the thin shell); the attitude is
    q_n ⊗ exp(u), u from the same tableau applied to u' = dexp⁻¹(Ω_b) (Munthe-Kaas). With the
    exponential map a constant Ω_b gives u' = Ω_b exactly, so the spin phase costs no error: the
    Cayley map (no trigonometric functions, tried first) made u = 2 tan(ωt/2), which the tableau only
    approximates: over a 20-minute spin-up (6·10⁵ turns, 12 steps a turn) that phase error reached
    6.8e-4 rad in q, against 1e-9-level with exp (measured in test_dynamics). One cos and sin of |u|/2
    per stage give both the stage attitude and dexp⁻¹. The field's phases: one cos and sin per
    phasor at the step's start, the stages' by angle addition (``tab`` from :func:`stage_trig_table`).
    Weights W, WB from :func:`lawson_coefficients`; only the nonzero A[i, j] (``cols``, ``count``) are
    visited. The quaternion slots of the sums are computed and overwritten (one loop over all k).
    """
    n = y.shape[0]
    S = c.shape[0]
    for k in range(4):
        qn[k] = y[3 + k]
    phasor_trig(s, om, tw[0], tw[1])
    for i in range(S):
        for k in range(n):
            Ys[k] = E0[i, k] * y[k]
        u0 = u1 = u2 = 0.0
        for jj in range(count[i]):
            j = cols[i, jj]
            for k in range(n):
                Ys[k] += W[i, j, k] * Fs[j, k]
            a = A[i, j]
            u0 += a * Ks[j, 0]
            u1 += a * Ks[j, 1]
            u2 += a * Ks[j, 2]
        u0 *= h
        u1 *= h
        u2 *= h
        alpha = _q_exp_alpha(qn, u0, u1, u2, Ys[3:7])
        _stage_trig(i, tab, tw)
        nonlinear_part_at(tw[2], tw[3], s + c[i] * h, Ys, Bre, Bim, om, Jinv, c_m, w, tail, nm, Fs[i], work, eff)
        _dexpinv_alpha(alpha, u0, u1, u2, work[12], work[13], work[14], Ks[i])
    for k in range(n):
        y[k] *= Eh[k]
    u0 = u1 = u2 = 0.0
    for j in range(S):
        if b[j] == 0.0:
            continue
        for k in range(n):
            y[k] += WB[j, k] * Fs[j, k]
        u0 += b[j] * Ks[j, 0]
        u1 += b[j] * Ks[j, 1]
        u2 += b[j] * Ks[j, 2]
    _q_exp(qn, h * u0, h * u1, h * u2, y[3:7])
    _normalize_q(y)


@njit(cache=True)
def lawson_case_step(y, s, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, b, c, cols, count, E0, W, WB, Eh, Fs, Ys, work,
                     tab, tw):
    """One Lawson RK step (weights from :func:`lawson_coefficients`) of the case-frame state without attitude
    (in place on y; :func:`nonlinear_part_case`): L and the modes only, y[3:7] untouched."""
    n = y.shape[0]
    S = c.shape[0]
    phasor_trig(s, om, tw[0], tw[1])
    for i in range(S):
        for k in range(n):
            Ys[k] = E0[i, k] * y[k]
        for jj in range(count[i]):
            j = cols[i, jj]
            for k in range(n):
                Ys[k] += W[i, j, k] * Fs[j, k]
        _stage_trig(i, tab, tw)
        nonlinear_part_case(tw[2], tw[3], Ys, Bre, Bim, om, Jinv, c_m, w, tail, nm, Fs[i], work)
    for k in range(n):
        if k < 3 or k > 6:
            y[k] *= Eh[k]
    for j in range(S):
        if b[j] == 0.0:
            continue
        for k in range(n):
            if k < 3 or k > 6:
                y[k] += WB[j, k] * Fs[j, k]


@njit(cache=True, nogil=True)
def integrate(y, t0, t_seg, t_stops, record, h_max, Bre, Bim, om, Jinv, c_m, w, tail, lam,
              out_y, out_N, k_out, eff, A, b, c, case=None, pos=None, max_steps=0):
    """Integrate y from t0 through each time in ``t_stops`` (increasing).

    The step is :func:`lawson_lie_step` with the tableau (A, b, c), or :func:`etd_lie_step` (ETDRK4)
    when the tableau is empty; with ``case`` (no attitude: isotropic rotor, no effects, modes in the
    case frame) :func:`lawson_case_step` or :func:`etd_case_step`. Each interval between stops is split
    into equal steps no longer than ``h_max``. Where ``record[i]`` the state and the torque (case, N·m)
    at ``t_stops[i]`` are written to ``out_y[k_out]``, ``out_N[k_out]`` and k_out advances. Returns
    (k_out, steps).

    A bounded call (``pos``, float (3,), given): it starts at stop ``pos[0]``, step ``pos[1]`` of that stop's
    span (t0 the span's start), takes at most ``max_steps`` steps and writes where the next call resumes to
    ``pos``: [stop, step of its span, the span's start (the next call's t0)]; ``pos[0]`` is the number of stops
    when all are reached. A span's steps are its equal steps (:func:`_equal_steps` of the span's own length, the
    same numbers in every call), and a step's numbers depend on y, the span's start, its index and h only: the
    states are the same bits as those of one call, however the calls are cut (the Python caller returns between
    them, so a signal is handled: :meth:`gyro_sim.engine.simulator.Simulator.advance`).
    """
    n = y.shape[0]
    nm = (n - 7 - int(eff[NE])) // 3
    eff[T0] = t_seg
    lawson = c.shape[0] > 0
    S = c.shape[0]
    # Lawson: integrating factors, stage derivatives and states
    E0 = np.empty((S, n))
    W = np.zeros((S, S, n))
    WB = np.empty((S, n))
    cols, count = nonzero_columns(A)
    Eh = np.empty(n)
    Fs = np.empty((max(S, 1), n))
    Ys = np.empty(n)
    Ks = np.empty((S, 3))
    qn = np.empty(4)
    # ETDRK4: coefficients and stage buffers
    buf = np.empty((7, n))
    K = np.empty(16)
    E = np.empty(n)
    E2 = np.empty(n)
    Q = np.empty(n)
    A1 = np.empty(n)
    A2 = np.empty(n)
    A3 = np.empty(n)
    work = np.empty(25)
    # the phase advance of each phasor to each stage (ETDRK4: s, s + h/2, s + h), and phases now
    c_trig = c if lawson else np.array([0.0, 0.5, 1.0])
    tab = np.empty((c_trig.shape[0], 2, om.shape[0]))
    tw = np.empty((4, om.shape[0]))
    h_last = -1.0
    steps = 0
    t = t0
    i0, j0 = _resume_at(pos)
    for i in range(i0, t_stops.shape[0]):
        span = t_stops[i] - t
        if span > 0.0:
            k, h = _equal_steps(span, h_max)
            if h != h_last:
                if lawson:
                    lawson_coefficients(lam, h, A, b, c, E0, W, WB, Eh)
                else:
                    etd_coefficients(lam, h, E, E2, Q, A1, A2, A3)
                stage_trig_table(om, c_trig, h, tab)
                h_last = h
            j1 = _steps_now(pos, max_steps, steps, j0, k)
            for j in range(j0, j1):
                if case is not None:
                    if lawson:
                        lawson_case_step(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, b, c, cols,
                                         count, E0, W, WB, Eh, Fs, Ys, work, tab, tw)
                    else:
                        etd_case_step(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jinv, c_m, w, tail, nm,
                                      E, E2, Q, A1, A2, A3, buf, work, tab, tw)
                elif lawson:
                    lawson_lie_step(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jinv, c_m, w, tail, nm, A, b, c,
                                    cols, count, E0, W, WB, Eh, Fs, Ys, Ks, work, qn, eff, tab, tw)
                else:
                    etd_lie_step(y, (t - t_seg) + j * h, h, Bre, Bim, om, Jinv, c_m, w, tail, nm,
                                 E, E2, Q, A1, A2, A3, buf, work, K, eff, tab, tw)
            steps += j1 - j0
            if j1 < k:
                _pause(pos, i, j1, t)
                return k_out, steps
            j0 = 0
            t = t_stops[i]
        if record[i]:
            record_sample(t - t_seg, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, eff, tw[0], tw[1], Fs[0], work, out_y,
                          out_N, k_out, case)
            k_out += 1
    _pause(pos, t_stops.shape[0], 0, t)
    return k_out, steps


@njit(cache=True, nogil=True)
def record_sample(s, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, eff, cs, sn, F, work, out_y, out_N, k, case=None):
    """Output sample k: the state y and the torque (case, N·m) at phase time s (scratch: cs, sn (P,), F (n,),
    work (25,)); ``case`` (None or True; None prunes the case-frame code): the state has no attitude
    (:func:`nonlinear_part_case`); ``eff`` None (a stepper that runs without effects): the effects' code is
    pruned (:func:`nonlinear_part_plain`)."""
    for i in range(y.shape[0]):  # (a loop: a slice assignment compiles numba's shape-error formatting, ~2 s)
        out_y[k, i] = y[i]
    phasor_trig(s, om, cs, sn)
    if case is not None:
        nonlinear_part_case(cs, sn, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work)
    elif eff is None:
        nonlinear_part_plain(cs, sn, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work)
    else:
        nonlinear_part_at(cs, sn, s, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff)
    out_N[k, 0] = F[0]
    out_N[k, 1] = F[1]
    out_N[k, 2] = F[2]
