"""Effects of physics.md §4 and [BS] in the compiled full model: parameter vector and kernels.

A scene's ``effects`` (:mod:`gyro_sim.effect_config`) are packed into one float64 vector ``eff``
(:func:`pack_effects`) that the kernels read at fixed offsets. ``eff[ON] == 0`` means no effect:
the kernels then skip everything here on that single test, so an effect that is off costs nothing.

What each effect does in the right-hand side (:func:`gyro_sim.kernels.nonlinear_part`):

* body rate Ω_b (:func:`body_rate`): the flywheel's relative kinetic moment h = J_f Ω_f(t) a and the
  damper mass's inertia m(|r|²I − r rᵀ) and relative momentum m r × v enter
  L_b = (J + m(|r|²I − r rᵀ)) Ω_b + m r × v + h  ([S] gyrostat; [KLT] §1). J is the rigid body alone.
* torques (case frame): Lagrange-top unbalance N = k(Θ) (v × x3), cosΘ = v·x3 ([KLT] (13));
  gas drag N_b = −(I1 Ω1, I1 Ω2, I3 Ω3) with I(t) polynomials ([KLT] (17)).
* the induced moment of a magnetizable body m = (1/μ0)[M B_b + P1 Ḃ_b + P2 B̈_b] ([BS] (2.3)).
* the damper's extra states (u, v): displacement of the mass from O1 and its velocity, body frame.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from gyro_sim.physics.constants import MU0

# --- layout of eff ---------------------------------------------------------------------------
T0 = 0  # absolute time (s) of s = 0 of the running segment
ON = 1  # 1.0 when any effect is on
NE = 2  # number of extra states appended after the eddy modes
UNB = 3  # on, k, k1, k2, v(3)                      3..9
DRAG = 10  # on, I1 coefficients (3), I3 coefficients (3)   10..16
MAG = 17  # on, M(9), P1(9), P2(9)                  17..44
FLY = 45  # on, J_f, a(3), n knots                  45..50
DMP = 51  # on, m, ρ, c, δ                          51..55
TAB = 56  # flywheel table: time(n), speed(n), angle at the knots(n)
N_DAMPER = 6  # extra states of the damper: u (m), v (m/s), body frame


def pack_effects(scene, conductor=None) -> np.ndarray:
    """The ``eff`` vector of a scene (SI). ``conductor``: its model, for the default P1, P2."""
    ef = scene.effects
    fly = ef.flywheel
    n = len(fly.profile.time) if fly is not None else 0
    eff = np.zeros(TAB + 3 * n)
    if not ef.any:
        return eff
    eff[ON] = 1.0
    if ef.unbalance is not None:
        u = ef.unbalance
        eff[UNB:UNB + 7] = [1.0, u.k, u.k1, u.k2, *u.vertical]
    if ef.gas_drag is not None:
        g = ef.gas_drag
        eff[DRAG] = 1.0
        eff[DRAG + 1:DRAG + 1 + len(g.transverse)] = g.transverse
        eff[DRAG + 4:DRAG + 4 + len(g.axial)] = g.axial
    if ef.magnetizable is not None:
        P1, P2 = default_p1_p2(conductor)
        m = ef.magnetizable
        eff[MAG] = 1.0
        eff[MAG + 1:MAG + 10] = np.asarray(m.M, float).ravel()
        eff[MAG + 10:MAG + 19] = (np.asarray(m.P1, float) if m.P1 is not None else P1).ravel()
        eff[MAG + 19:MAG + 28] = (np.asarray(m.P2, float) if m.P2 is not None else P2).ravel()
    if fly is not None:
        eff[FLY:FLY + 6] = [1.0, fly.inertia, *fly.axis, n]
        t = np.asarray(fly.profile.time, float)
        w = np.asarray(fly.profile.speed, float)
        eff[TAB:TAB + n] = t
        eff[TAB + n:TAB + 2 * n] = w
        eff[TAB + 2 * n:TAB + 3 * n] = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
    if ef.damper is not None:
        d = ef.damper
        eff[DMP:DMP + 5] = [1.0, d.mass, d.radius, d.stiffness, d.damping]
        eff[NE] = N_DAMPER
    return eff


def default_p1_p2(conductor) -> tuple[np.ndarray, np.ndarray]:
    """P1 (m³·s), P2 (m³·s²) of an isotropic conductor: the first two terms of ĝ's expansion.

    ĝ(ω) = Σ w_n iωτ_n/(1 − iωτ_n) = Σ w_n [iωτ_n + (iωτ_n)² + …] and iω ↔ −d/dt, so
    μ0 m = 2π r2³ [−(Σ w_n τ_n + T_tail) Ḃ_b + Σ w_n τ_n² B̈_b + …] (physics.md §3; for the solid
    sphere this is [BS]'s P(1) = −a⁵λ/30, P(2) = a⁷λ²/315 in SI).

    The modes n > N left out of the modal model also count in P2: their Σ w_n τ_n² (T_tail2) is
    added like T_tail is in P1. For the solid sphere w_n τ_n ∝ n⁻⁴ and τ_n ∝ n⁻², so exactly
    T_tail2 = T_tail τ_N N² ζ(6, N+1)/ζ(4, N+1); a shell's higher modes follow the same law
    asymptotically (P2 then within 1e-8 of the corrected [M] (2.13) at N = 10; measured in
    test/test_magnetizable.py); a thin shell has no tail. Without it P2 of a 10-mode sphere was
    1.5e-6 short, of a 1-mode sphere 1.7 % short.
    """
    if conductor is None:
        return np.zeros((3, 3)), np.zeros((3, 3))
    c = float(conductor.moment_scale) * MU0  # 2π r2³
    tau = np.asarray(conductor.tau, float)
    w = np.asarray(conductor.weight, float)
    p1 = -c * float(conductor.tau_eff)
    tail2 = getattr(conductor, "tail_tau2", None)
    if tail2 is None:
        tail2 = _tail_tau2(float(conductor.tail_tau), tau)
    p2 = c * float(np.sum(w * tau ** 2) + tail2)
    return p1 * np.eye(3), p2 * np.eye(3)


def _tail_tau2(tail_tau: float, tau: np.ndarray) -> float:
    """Σ_{n>N} w_n τ_n² (s²) of the truncated modes from T_tail = Σ_{n>N} w_n τ_n (s), sphere law τ_n ∝ n⁻²."""
    from scipy.special import zeta

    N = tau.size
    if N == 0 or tail_tau == 0.0:
        return 0.0
    return tail_tau * float(tau[-1]) * N * N * float(zeta(6.0, N + 1) / zeta(4.0, N + 1))


def flywheel_angle(t: np.ndarray, eff: np.ndarray) -> np.ndarray:
    """∫₀ᵗ Ω_f dt' (rad) of the piecewise-linear profile (held constant outside its table)."""
    t = np.asarray(t, float)
    n = int(eff[FLY + 5])
    if eff[FLY] == 0.0 or n == 0:
        return np.zeros_like(t)
    return np.vectorize(lambda x: _fly_angle(x, eff))(t) - _fly_angle(0.0, eff)


# --- compiled pieces ------------------------------------------------------------------------


@njit(cache=True)
def _fly_segment(t, eff):
    """(i, n): the table segment [t_i, t_{i+1}] holding t; i = −1 before, n − 1 after the table."""
    n = int(eff[FLY + 5])
    if t <= eff[TAB]:
        return -1, n
    if t >= eff[TAB + n - 1]:
        return n - 1, n
    i = 0
    while eff[TAB + i + 1] < t:
        i += 1
    return i, n


@njit(cache=True)
def flywheel_speed(t, eff):
    """Ω_f(t) (rad/s) and dΩ_f/dt (rad/s²) of the piecewise-linear profile."""
    i, n = _fly_segment(t, eff)
    if i < 0:
        return eff[TAB + n], 0.0
    if i >= n - 1:
        return eff[TAB + 2 * n - 1], 0.0
    t0, t1 = eff[TAB + i], eff[TAB + i + 1]
    w0, w1 = eff[TAB + n + i], eff[TAB + n + i + 1]
    slope = (w1 - w0) / (t1 - t0)
    return w0 + slope * (t - t0), slope


@njit(cache=True)
def flywheel_moment(t, eff, derivative):
    """The wheel's relative kinetic moment h = J_f Ω_f(t) a (N·m·s, body frame), or with
    ``derivative`` = 1 its rate ḣ = J_f dΩ_f/dt a (N·m)."""
    w, acc = flywheel_speed(t, eff)
    m = eff[FLY + 1] * (acc if derivative else w)
    return m * eff[FLY + 2], m * eff[FLY + 3], m * eff[FLY + 4]


@njit(cache=True)
def _fly_angle(t, eff):
    """∫ Ω_f from the first knot to t (rad), constant extension outside the table."""
    i, n = _fly_segment(t, eff)
    if i < 0:
        return eff[TAB + n] * (t - eff[TAB])
    if i >= n - 1:
        return eff[TAB + 3 * n - 1] + eff[TAB + 2 * n - 1] * (t - eff[TAB + n - 1])
    t0 = eff[TAB + i]
    w0 = eff[TAB + n + i]
    w, _ = flywheel_speed(t, eff)
    return eff[TAB + 2 * n + i] + 0.5 * (w0 + w) * (t - t0)


@njit(cache=True, inline="always")
def _poly(c0, c1, c2, t):
    return c0 + t * (c1 + t * c2)


@njit(cache=True)
def _solve_sym3(a00, a01, a02, a11, a12, a22, b0, b1, b2):
    """x = A⁻¹ b for a symmetric positive definite 3×3 A (cofactors)."""
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    return ((c00 * b0 + c01 * b1 + c02 * b2) / det,
            (c01 * b0 + c11 * b1 + c12 * b2) / det,
            (c02 * b0 + c12 * b1 + c22 * b2) / det)


@njit(cache=True)
def body_rate(t, Lbx, Lby, Lbz, y, k0, Jinv, eff):
    """Ω_b (rad/s, body) from the body-frame kinetic moment L_b (N·m·s) with the effects' terms.

    Flywheel: L_b − J_f Ω_f(t) a. Damper (state at y[k0:k0+6]): solve
    (J + m(|r|²I − r rᵀ)) Ω = L_b − h − m r × v, r = ρ e3 + u.
    """
    if eff[FLY] != 0.0:
        hx, hy, hz = flywheel_moment(t, eff, 0)
        Lbx -= hx
        Lby -= hy
        Lbz -= hz
    if eff[DMP] == 0.0:
        return Jinv[0] * Lbx, Jinv[1] * Lby, Jinv[2] * Lbz
    m = eff[DMP + 1]
    rx, ry, rz = y[k0], y[k0 + 1], eff[DMP + 2] + y[k0 + 2]
    vx, vy, vz = y[k0 + 3], y[k0 + 4], y[k0 + 5]
    r2 = rx * rx + ry * ry + rz * rz
    bx = Lbx - m * (ry * vz - rz * vy)
    by = Lby - m * (rz * vx - rx * vz)
    bz = Lbz - m * (rx * vy - ry * vx)
    return _solve_sym3(1.0 / Jinv[0] + m * (r2 - rx * rx), -m * rx * ry, -m * rx * rz,
                       1.0 / Jinv[1] + m * (r2 - ry * ry), -m * ry * rz, 1.0 / Jinv[2] + m * (r2 - rz * rz),
                       bx, by, bz)


@njit(cache=True)
def torque_body(t, Ox, Oy, Oz, x3x, x3y, x3z, eff):
    """Unbalance and gas drag, body frame (N·m); x3 = the body's polar axis in the case frame.

    The unbalance is computed in the case frame as k(Θ) v × x3 and returned there in the last three
    values (case frame) so the caller adds each where it is natural.
    """
    nbx = nby = nbz = 0.0
    ncx = ncy = ncz = 0.0
    if eff[DRAG] != 0.0:  # [KLT] (17)
        I1 = _poly(eff[DRAG + 1], eff[DRAG + 2], eff[DRAG + 3], t)
        I3 = _poly(eff[DRAG + 4], eff[DRAG + 5], eff[DRAG + 6], t)
        nbx, nby, nbz = -I1 * Ox, -I1 * Oy, -I3 * Oz
    if eff[UNB] != 0.0:  # [KLT] (13): N_b = k(Θ) sinΘ (cosφ, −sinφ, 0) = k(Θ) v × x3
        vx, vy, vz = eff[UNB + 4], eff[UNB + 5], eff[UNB + 6]
        c = vx * x3x + vy * x3y + vz * x3z
        k = _poly(eff[UNB + 1], eff[UNB + 2], eff[UNB + 3], c)
        ncx = k * (vy * x3z - vz * x3y)
        ncy = k * (vz * x3x - vx * x3z)
        ncz = k * (vx * x3y - vy * x3x)
    return nbx, nby, nbz, ncx, ncy, ncz


@njit(cache=True)
def magnetizable_moment(eff, Bx, By, Bz, dx, dy, dz, ddx, ddy, ddz):
    """m_b = (1/μ0)[M B_b + P1 Ḃ_b + P2 B̈_b] (A·m², body frame) from body-frame B_b, Ḃ_b, B̈_b."""
    mx = my = mz = 0.0
    o = MAG + 1
    for i in range(3):
        v = (eff[o + 3 * i] * Bx + eff[o + 3 * i + 1] * By + eff[o + 3 * i + 2] * Bz
             + eff[o + 9 + 3 * i] * dx + eff[o + 9 + 3 * i + 1] * dy + eff[o + 9 + 3 * i + 2] * dz
             + eff[o + 18 + 3 * i] * ddx + eff[o + 18 + 3 * i + 1] * ddy + eff[o + 18 + 3 * i + 2] * ddz)
        if i == 0:
            mx = v
        elif i == 1:
            my = v
        else:
            mz = v
    return mx / MU0, my / MU0, mz / MU0


@njit(cache=True)
def damper_derivs(t, y, k0, Jinv, eff, Lbx, Lby, Lbz, Ox, Oy, Oz, Nbx, Nby, Nbz, F):
    """F[k0:k0+6] = (u̇, v̇) of the damper mass (body frame), [KLT] §1 full model.

    With r = ρ e3 + u, A = J + m(|r|²I − r rᵀ), L_b = A Ω + m r × v + h:
    f = (−c u − δ v)/m − 2 Ω × v − Ω × (Ω × r)   (relative acceleration without the Ω̇ term)
    J Ω̇ = N_b − Ω × L_b − Ȧ Ω − m r × f − ḣ,   v̇ = f − Ω̇ × r.
    """
    m, rho, c, dl = eff[DMP + 1], eff[DMP + 2], eff[DMP + 3], eff[DMP + 4]
    ux, uy, uz = y[k0], y[k0 + 1], y[k0 + 2]
    vx, vy, vz = y[k0 + 3], y[k0 + 4], y[k0 + 5]
    rx, ry, rz = ux, uy, rho + uz
    # Ω × r, Ω × (Ω × r), Ω × v
    wrx, wry, wrz = Oy * rz - Oz * ry, Oz * rx - Ox * rz, Ox * ry - Oy * rx
    wwx, wwy, wwz = Oy * wrz - Oz * wry, Oz * wrx - Ox * wrz, Ox * wry - Oy * wrx
    wvx, wvy, wvz = Oy * vz - Oz * vy, Oz * vx - Ox * vz, Ox * vy - Oy * vx
    fx = (-c * ux - dl * vx) / m - 2.0 * wvx - wwx
    fy = (-c * uy - dl * vy) / m - 2.0 * wvy - wwy
    fz = (-c * uz - dl * vz) / m - 2.0 * wvz - wwz
    rv = rx * vx + ry * vy + rz * vz
    rO = rx * Ox + ry * Oy + rz * Oz
    vO = vx * Ox + vy * Oy + vz * Oz
    gx = Nbx - (Oy * Lbz - Oz * Lby) - m * (2.0 * rv * Ox - vx * rO - rx * vO) - m * (ry * fz - rz * fy)
    gy = Nby - (Oz * Lbx - Ox * Lbz) - m * (2.0 * rv * Oy - vy * rO - ry * vO) - m * (rz * fx - rx * fz)
    gz = Nbz - (Ox * Lby - Oy * Lbx) - m * (2.0 * rv * Oz - vz * rO - rz * vO) - m * (rx * fy - ry * fx)
    if eff[FLY] != 0.0:
        hx, hy, hz = flywheel_moment(t, eff, 1)
        gx -= hx
        gy -= hy
        gz -= hz
    dOx, dOy, dOz = Jinv[0] * gx, Jinv[1] * gy, Jinv[2] * gz
    F[k0] = vx
    F[k0 + 1] = vy
    F[k0 + 2] = vz
    F[k0 + 3] = fx - (dOy * rz - dOz * ry)
    F[k0 + 4] = fy - (dOz * rx - dOx * rz)
    F[k0 + 5] = fz - (dOx * ry - dOy * rx)
