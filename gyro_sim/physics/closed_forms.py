"""Closed-form reference results used to check the simulator.

Everything here is SI (m, kg, s, T, rad, rad/s, kg·m²/s, N·m) and uses the frames of
``docs/physics.md`` §1:

* case frame Z (inertial), body frame X (principal axes, x3 = polar axis),
  attitude ``R`` maps body to case coordinates (``v_case = R @ v_body``);
* ``L`` (kinetic moment) in the case frame, ``L_b = Rᵀ L`` in the body frame,
  ``Ω_b = J⁻¹ L_b``;
* kinetic-moment frame ``Y = [y1 y2 y3]``, ``y3 = L/|L|``; Euler angles (z-x-z) of the
  body in Y: ``R = Y Rz(ψ) Rx(θ) Rz(φ)``, so ``L_b = |L| (sinθ sinφ, sinθ cosφ, cosθ)``.

Paper references (docs/physics.md, Bibliography): [M] Martynenko, [K] Komarov, [BS] Bogatyrev & Strygin;
[LL] Landau & Lifshitz, Mechanics §37.
See ``docs/closed_forms.md`` for the findings on [M] (3.18)–(3.20).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
from scipy.special import ellipj, ellipk, ellipkinc, elliprf, elliprj

from gyro_sim.physics.constants import MU0
from gyro_sim.physics.frames import euler_angles as _euler_stacked
from gyro_sim.physics.frames import l_frame

__all__ = [
    "free_rigid_body",
    "l_frame",
    "euler_angles",
    "quasi_static_mean_torque",
    "g_thin_shell",
    "torque_slip",
    "torque_slip_thin_shell",
    "spinup_axial",
    "NutationWindow",
    "thin_shell_nutation_window",
    "small_theta_nutation_rate",
    "thin_shell_small_theta_nutation_rate",
    "averaged_nutation_rate",
    "constant_field_transverse_decay_rate",
]


# ----------------------------------------------------------------------------------
# small rotation helpers
# ----------------------------------------------------------------------------------
def _skew(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def _rot_axis(k: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Rotations (n,3,3) about the fixed unit vector k by the angles a (n,) (Rodrigues)."""
    a = np.asarray(a, dtype=float)
    K = _skew(np.asarray(k, dtype=float))
    s, c = np.sin(a)[:, None, None], np.cos(a)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _rz(a: np.ndarray) -> np.ndarray:
    return _rot_axis(np.array([0.0, 0.0, 1.0]), a)


def _rx(a: np.ndarray) -> np.ndarray:
    return _rot_axis(np.array([1.0, 0.0, 0.0]), a)


# ----------------------------------------------------------------------------------
# frames and Euler angles
# ----------------------------------------------------------------------------------
def euler_angles(R: np.ndarray, L_case: np.ndarray):
    """Euler angles of the body in the L-frame as a tuple (ψ, θ, φ) (see :func:`gyro_sim.frames.euler_angles`)."""
    a = _euler_stacked(R, L_case)
    return a[..., 0], a[..., 1], a[..., 2]


# ----------------------------------------------------------------------------------
# exact torque-free motion (Euler–Poinsot) via Jacobi elliptic functions
# ----------------------------------------------------------------------------------
def _pi_incomplete(n: float, phi: np.ndarray, m: float) -> np.ndarray:
    """Π(n; φ|m) = ∫0^φ dθ / ((1 − n sin²θ) √(1 − m sin²θ)) for |φ| ≤ π/2 (Carlson, DLMF 19.25.14)."""
    s, c = np.sin(phi), np.cos(phi)
    s2 = s * s
    d2 = 1.0 - m * s2
    return s * elliprf(c * c, d2, 1.0) + (n / 3.0) * s * s2 * elliprj(c * c, d2, 1.0, 1.0 - n * s2)


def _pi_any(n: float, phi: np.ndarray, m: float, Pc: float) -> np.ndarray:
    """Π(n; φ|m) for any real φ via Π(φ + jπ) = Π(φ) + 2jΠ(n|m)."""
    j = np.round(np.asarray(phi) / np.pi)
    return _pi_incomplete(n, phi - j * np.pi, m) + 2.0 * j * Pc


def free_rigid_body(J, R0, L_case, t, return_angles=False):
    """Exact torque-free motion of a rigid body about its centre of mass ([LL] §37).

    Parameters (SI)
    ----------
    J : (3,) principal moments of inertia (kg·m²) of body axes x1, x2, x3, any order,
        any two (or all) may be equal.
    R0 : (3,3) attitude at t = 0, body → case.
    L_case : (3,) kinetic moment in the case frame (kg·m²/s), constant.
    t : scalar or (n,) times (s), any sign, any order.
    return_angles : if True also return (psi, theta, phi), each (n,), the Euler angles of
        the body in the L-frame (rad). In the triaxial case and the axisymmetric case with
        x3 the symmetry axis, psi = ψ(R0) + the closed-form ∫ψ' dt (continuous, not
        wrapped; accurate also at small θ, where reading ψ back from R is not); otherwise
        psi is read back from R with ``euler_angles`` (wrapped to (−π, π]).

    Returns
    -------
    L_b : (n,3) body-frame kinetic moment, L_b(t) = R(t)ᵀ L.
    R : (n,3,3) attitude, body → case.

    Method
    ------
    Triaxial: in a right-handed permutation (a, b, c) of the body axes with I_b the
    intermediate moment and c the axis the motion goes round (the largest axis if
    |L|² > 2T I_b, the smallest if |L|² < 2T I_b):
    L_a = A_a cn u, L_b = A_b sn u, L_c = ±A_c dn u, u = λt + u0 (Jacobi, parameter m);
    all amplitudes are computed from sums of positive terms (no cancellation).
    Attitude: θ, φ from L_b(t); ψ from ψ' = |L|(L1²/J1 + L2²/J2)/(L1² + L2²)
    = |L|/J3 + |L|(2T − |L|²/J3)/(|L|² − L3²), integrated in closed form with the
    incomplete elliptic integral of the third kind Π(n; am u|m) (Carlson R_F, R_J), then
    R(t) = Rot(L̂, ψ − ψ0) R0 Rz(−φ0) Rx(θ − θ0) Rz(φ), which is R = Y Rz(ψ) Rx(θ) Rz(φ)
    written relative to R0 (exact at t = 0, robust at small θ).
    Axisymmetric (two equal moments, symmetry axis s): R(t) = Rot(L̂, |L|t/I_⊥) R0
    Rot_body(e_s, L_s (1/I_s − 1/I_⊥) t). Permanent rotation (L_b along a principal
    axis): R0 Rot_body(e_k, L_k t/J_k).
    Moments that agree to 1e-14 relative are treated as equal.

    Raises ValueError on (or within round-off of) the separatrix |L|² = 2T I_b.
    """
    J = np.asarray(J, dtype=float).reshape(3)
    if np.any(J <= 0):
        raise ValueError("moments of inertia must be positive")
    R0 = np.asarray(R0, dtype=float).reshape(3, 3)
    L = np.asarray(L_case, dtype=float).reshape(3)
    t = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
    n_t = t.size
    Lmag = float(np.linalg.norm(L))
    Lb0 = R0.T @ L
    if Lmag == 0.0:
        out = (np.zeros((n_t, 3)), np.broadcast_to(R0, (n_t, 3, 3)).copy())
        return out + (_angles_from(out[1], L, R0, None),) if return_angles else out
    Lhat = L / Lmag

    # ---- merge moments equal to round-off --------------------------------------
    Jm = J.copy()
    tol = 1e-14 * Jm.max()
    order = np.argsort(Jm)
    for i in range(2):
        p, q = order[i], order[i + 1]
        if Jm[q] - Jm[p] <= tol:
            Jm[p] = Jm[q] = 0.5 * (Jm[p] + Jm[q])

    # ---- permanent rotation about a principal axis ------------------------------
    nz = np.flatnonzero(Lb0 != 0.0)
    if nz.size == 1:
        k = int(nz[0])
        e = np.zeros(3)
        e[k] = 1.0
        R = R0 @ _rot_axis(e, Lb0[k] / Jm[k] * t)
        out = (np.tile(Lb0, (n_t, 1)), R)
        return out + (_angles_from(R, L, R0, None),) if return_angles else out

    # ---- isotropic / axisymmetric ------------------------------------------------
    if Jm[0] == Jm[1] or Jm[1] == Jm[2] or Jm[0] == Jm[2]:
        if Jm[0] == Jm[1]:
            s = 2
        elif Jm[1] == Jm[2]:
            s = 0
        else:
            s = 1
        Ip = Jm[(s + 1) % 3]
        Is = Jm[s]
        es = np.zeros(3)
        es[s] = 1.0
        nbody = Lb0[s] * (1.0 / Is - 1.0 / Ip)
        R = _rot_axis(Lhat, Lmag / Ip * t) @ R0 @ _rot_axis(es, nbody * t)
        Lb = np.einsum("nji,j->ni", _rot_axis(es, nbody * t), Lb0)  # Rot(e_s, −n t) L_b0
        if not return_angles:
            return Lb, R
        dpsi = Lmag / Ip * t if s == 2 else None  # ψ' = |L|/J⊥ exactly when x3 is the symmetry axis
        return Lb, R, _angles_from(R, L, R0, dpsi)

    # ---- triaxial: Jacobi elliptic solution -------------------------------------
    i_min, i_mid, i_max = (int(i) for i in np.argsort(Jm))
    kinv = 1.0 / Jm
    # sign of |L|² − 2T I_mid as a sum of two terms of fixed sign
    sep = Lb0[i_min] ** 2 * (Jm[i_min] - Jm[i_mid]) / Jm[i_min] + Lb0[i_max] ** 2 * (
        Jm[i_max] - Jm[i_mid]
    ) / Jm[i_max]
    sep_scale = (Lb0[i_min] ** 2 + Lb0[i_max] ** 2) * (Jm[i_max] - Jm[i_min]) / Jm[i_max]
    if abs(sep) <= 1e-12 * max(sep_scale, 1e-300) or sep_scale == 0.0:
        raise ValueError("free_rigid_body: initial state on (or within round-off of) the separatrix")
    if sep > 0:  # |L|² > 2T I_mid: motion round the largest axis
        ia, ib, ic = i_min, i_mid, i_max
    else:  # motion round the smallest axis
        ia, ib, ic = i_max, i_mid, i_min
    # right-handed (e_a, e_b, sgn e_c)
    perm = np.zeros((3, 3))
    perm[0, ia] = perm[1, ib] = perm[2, ic] = 1.0
    sgn = float(np.sign(np.linalg.det(perm)))
    La0, Lbb0, Lc0 = Lb0[ia], Lb0[ib], sgn * Lb0[ic]
    ka, kb, kc = kinv[ia], kinv[ib], kinv[ic]
    r = (kb - kc) / (ka - kc)  # in (0, 1)
    q = (kb - ka) / (kc - ka)  # = 1 − r, in (0, 1)
    Aa2 = La0 * La0 + r * Lbb0 * Lbb0
    Ab2 = La0 * La0 / r + Lbb0 * Lbb0
    Ac2 = Lc0 * Lc0 + q * Lbb0 * Lbb0
    Aa, Ab, Ac = np.sqrt(Aa2), np.sqrt(Ab2), np.sqrt(Ac2)
    m = q * Ab2 / Ac2
    if not (0.0 <= m < 1.0):
        raise ValueError("free_rigid_body: parameter m = %r not in [0, 1) (separatrix)" % m)
    csg = 1.0 if Lc0 > 0 else -1.0
    lam = csg * np.sign(kb - kc) * Ac * np.sqrt((kb - kc) * (ka - kc))
    K = float(ellipk(m))

    am0 = float(np.arctan2(Lbb0 * Aa, La0 * Ab))
    j0 = np.round(am0 / np.pi)
    u0 = float(ellipkinc(am0 - j0 * np.pi, m)) + 2.0 * j0 * K

    tt = np.concatenate([[0.0], t])
    u = u0 + lam * tt
    jj = np.round(u / (2.0 * K))
    rr = u - 2.0 * K * jj
    sn, cn, dn, ph = ellipj(rr, m)
    par = np.where(np.mod(jj, 2.0) == 0.0, 1.0, -1.0)
    La, Lbv, Lc = Aa * cn * par, Ab * sn * par, csg * Ac * dn
    Lb_all = np.empty((tt.size, 3))
    Lb_all[:, ia], Lb_all[:, ib], Lb_all[:, ic] = La, Lbv, sgn * Lc

    # ---- ψ: ψ' = |L|/J3 + C / (1 − n sn² u), closed form with Π(n; am u|m) ----------
    G = Lmag * Lmag
    two_T_minus = Lb0[0] ** 2 * (kinv[0] - kinv[2]) + Lb0[1] ** 2 * (kinv[1] - kinv[2])  # 2T − G/J3
    if ic == 2:  # L3² = A_c² dn² ⇒ G − L3² = A_a² + m A_c² sn²
        alpha, n_char = Aa2, -q * Ab2 / Aa2 if Aa2 > 0 else 0.0
    elif ia == 2:  # L3² = A_a² cn² ⇒ G − L3² = A_c² + A_a² sn²
        alpha, n_char = Ac2, -Aa2 / Ac2
    else:  # L3² = A_b² sn² ⇒ G − L3² = G − A_b² sn²
        alpha, n_char = G, Ab2 / G
    C = Lmag * two_T_minus / alpha
    Pc = float(elliprf(0.0, 1.0 - m, 1.0) + (n_char / 3.0) * elliprj(0.0, 1.0 - m, 1.0, 1.0 - n_char))
    Pi_u = _pi_incomplete(n_char, ph, m) + 2.0 * jj * Pc  # Π(n; am u|m), am u = ph + jπ
    Pi_0 = _pi_any(n_char, np.array(am0), m, Pc)
    dpsi = Lmag * kinv[2] * tt + (C / lam) * (Pi_u - Pi_0)

    theta = np.arctan2(np.hypot(Lb_all[:, 0], Lb_all[:, 1]), Lb_all[:, 2])
    phi = np.arctan2(Lb_all[:, 0], Lb_all[:, 1])
    th0, ph0 = theta[0], phi[0]
    B0 = R0 @ _rz(np.array([-ph0]))[0]
    R = _rot_axis(Lhat, dpsi[1:]) @ B0 @ _rx(theta[1:] - th0) @ _rz(phi[1:])
    if not return_angles:
        return Lb_all[1:], R
    psi0 = euler_angles(R0, L)[0]
    return Lb_all[1:], R, (psi0 + dpsi[1:], theta[1:], phi[1:])


def _angles_from(R, L, R0, dpsi):
    """(ψ, θ, φ) of attitudes R; ψ = ψ(R0) + dpsi if given, else read back from R (wrapped)."""
    psi, theta, phi = euler_angles(R, np.broadcast_to(L, (R.shape[0], 3)))
    if dpsi is not None:
        return euler_angles(R0, L)[0] + dpsi, theta, phi
    return psi, theta, phi


# ----------------------------------------------------------------------------------
# quasi-static rotating-field torque, torque–slip, spin-up
# ----------------------------------------------------------------------------------
def quasi_static_mean_torque(k_e, B0, nu, u, e1, Omega):
    """Field-period average of the quasi-static eddy torque in one rotating field, [K] (1.3).

    ⟨N⟩ = k_e B0² [ν u − ½ (Ω + (Ω·u) u)]   (N·m, case frame)

    from N = k_e B × (B × Ω + dB/dt) ([K] (1.2), physics.md §3) with
    B(t) = B0 (e1 cos νt + e2 sin νt), e2 = u × e1. k_e (N·m·s/T²) = 2π r2³ τ_eff/μ0,
    B0 (T), ν (rad/s, sign = sense of rotation about u), u unit field axis (case frame),
    e1 unit vector ⟂ u (the average does not depend on it; it is only checked),
    Omega (3,) or (n,3) body angular velocity in the case frame (rad/s).
    Valid for slips ≪ 1/τ and non-resonant averaging (ν not commensurate with the rotor).
    """
    u = np.asarray(u, dtype=float)
    u = u / np.linalg.norm(u)
    if e1 is not None:
        e1 = np.asarray(e1, dtype=float)
        if abs(np.dot(e1, u)) > 1e-9 * np.linalg.norm(e1):
            raise ValueError("e1 must be perpendicular to u")
    Om = np.asarray(Omega, dtype=float)
    Ou = Om @ u
    return k_e * B0**2 * (nu * u - 0.5 * (Om + np.multiply.outer(Ou, u)))


def g_thin_shell(omega, tau):
    """Thin-shell transfer function ĝ(ω) = iωτ/(1 − iωτ) (fields ∝ e^{−iωt}), [M] (2.15)."""
    w = np.asarray(omega, dtype=float)
    return 1j * w * tau / (1.0 - 1j * w * tau)


def torque_slip(g: Callable, r2, B0, slip):
    """Axial torque (N·m) of a field B0 rotating at slip s = ν − Ω_u relative to the rotor.

    N_u = (2π r2³/μ0) B0² Im ĝ(s)   (physics.md §5; exact for any ĝ, steady state,
    rotor spinning about the field axis u). ``g``: callable ĝ(ω) (ω in rad/s, fields
    ∝ e^{−iωt}), r2 outer radius (m), B0 (T), slip (rad/s, scalar or array).
    For a thin shell the pull-out (maximum) torque is (π r2³/μ0) B0² at s = 1/τ.
    """
    return 2.0 * np.pi * r2**3 / MU0 * B0**2 * np.imag(g(np.asarray(slip, dtype=float)))


def torque_slip_thin_shell(tau, r2, B0, slip):
    """Thin-shell torque–slip curve N_u = (2π r2³/μ0) B0² sτ/(1 + s²τ²) (N·m)."""
    return torque_slip(lambda w: g_thin_shell(w, tau), r2, B0, slip)


def spinup_axial(J3, k_e, B0, nu, Omega0, t):
    """Quasi-static spin-up about the field axis (θ = 0): Ω(t) = ν + (Ω0 − ν) e^{−k_e B0² t/J3}.

    From [K] (1.3) with Ω = Ω_u u: J3 dΩ/dt = k_e B0² (ν − Ω) (= [K] (2.1) with θ = 0,
    one stator). J3 (kg·m²), k_e (N·m·s/T²), B0 (T), ν, Ω0 (rad/s), t (s). Valid while
    the slip |ν − Ω| ≪ 1/τ.
    """
    t = np.asarray(t, dtype=float)
    return nu + (Omega0 - nu) * np.exp(-k_e * B0**2 * t / J3)


# ----------------------------------------------------------------------------------
# [M] §3: rotating field, small nutation angle — (3.18)–(3.20)
#
# Findings (docs/closed_forms.md): [M]'s ξ is the thin-shell time constant τ = μ0σ r2 h/3
# ((2.15), Gaussian 4πλ r2 h/(3c²)); l = |L|/I1 (precession rate; [M] scales time by
# T_n = I1/L_*, which cancels in ξl, ξω); ω = field rate. (3.17) θ-equation at ρ = 0,
# θ → 0 gives (3.18) exactly; (3.18) + (2.15) give (3.19) exactly (α''(a) − α''(b) ∝
# (a − b)(1 − τ²ab), a = l/(1+κ) − ω, b = l − ω). Printed (3.19)/(3.20) are correct; OCR
# damage nearby: the first line of (3.17) reads "l θ̈" for l′, the label (3.20) is lost
# from the quadratic, and "угол Φ растёт" is ϑ. Checked against the torus-averaged exact
# linear response (averaged_nutation_rate), a time-domain filter average and a full
# (unaveraged) spin-up simulation — see test/test_closed_forms.py.
# ----------------------------------------------------------------------------------
class NutationWindow(NamedTuple):
    """Roots of [M] (3.20) in SI. θ (small) decreases iff κ·Q(l) > 0, with
    Q(l) = (1+κ)(1 − τ²ω²) + τ²(2+κ) ω l − τ² l²,  l = |L|/J1.

    For κ > 0 that is l_low < l < l_high; for κ < 0 outside it. l_low ≤ 0 (when ωτ ≤ 1)
    means the window starts at rest.
    """

    L_low: float  # |L| at the lower root (kg·m²/s)
    L_high: float  # |L| at the upper root (kg·m²/s)
    l_low: float  # [M]'s l = |L|/J1 (precession rate, rad/s), lower root
    l_high: float
    spin_low: float  # axial spin rate |L|/J3 (rad/s, at θ = 0), lower root
    spin_high: float
    kappa: float  # (J3 − J1)/J1


def thin_shell_nutation_window(J1, J3, tau, omega_field) -> NutationWindow:
    """[M] (3.19)–(3.20) in SI: |L| interval in which the nutation angle θ decreases.

    Axisymmetric thin-shell rotor (J1 = J2 equatorial, J3 polar, kg·m²; τ = μ0σ r2 h/3, s)
    with L along the axis u of a field rotating at ``omega_field`` (rad/s, positive = same
    sense as L), small θ and small ρ. [M]'s symbols: ξ = τ (its (2.15) ξ = 4πλ r2 h/(3c²)
    is the Gaussian form of τ), l = |L|/J1 (rad/s), ω = field rate (rad/s) — [M]'s
    non-dimensionalisation by T_n = I1/L_* cancels in ξl, ξω. The roots of
    −τ²l² + τ²ω(2+κ)l + (1+κ)(1 − τ²ω²) = 0 are

        l_{1,2} = ½ [ (2+κ) ω ∓ √(κ² ω² + 4(1+κ)/τ²) ],   κ = (J3 − J1)/J1,

    and |L|_{1,2} = J1 l_{1,2}. For ωτ > 1, κ > 0: 0 < l1 < l2 and θ grows while
    |L| < J1 l1 (early spin-up), as [M] states; the synchronous state |L| = J3 ω is
    always inside the window (Q = 1 + κ there). Checked independently against the
    averaged linear-response torque (``averaged_nutation_rate``) and a time-domain
    filter integration (test/test_closed_forms.py, docs/closed_forms.md).
    """
    kappa = (J3 - J1) / J1
    w = float(omega_field)
    disc = np.sqrt(kappa**2 * w**2 + 4.0 * (1.0 + kappa) / tau**2)
    l1 = 0.5 * ((2.0 + kappa) * w - disc)
    l2 = 0.5 * ((2.0 + kappa) * w + disc)
    return NutationWindow(J1 * l1, J1 * l2, l1, l2, J1 * l1 / J3, J1 * l2 / J3, kappa)


def small_theta_nutation_rate(g: Callable, r2, B0, J1, J3, L, omega_field):
    """(1/θ) dθ/dt (1/s), averaged, for small θ and ρ: [M] (3.18) in SI, any ĝ.

        dθ/dt = θ · π r2³ B0² / (μ0 |L|) · [Im ĝ(|L|/J3 − ω) − Im ĝ(|L|/J1 − ω)]

    ([M]: l θ' = ½ ε1 θ [α''(l/(1+κ) − ω) − α''(l − ω)], α = r2³ ĝ/2, ε1 H²-scaling →
    B0²·4π/μ0). |L|/J3 − ω is minus the slip of the spin, |L|/J1 − ω the precession
    rate relative to the field. ``g`` callable ĝ(ω); J1 = J2 equatorial, J3 polar;
    L = |L| (kg·m²/s); omega_field signed (positive = same sense as L).
    """
    L = np.asarray(L, dtype=float)
    a = L / J3 - omega_field
    b = L / J1 - omega_field
    return np.pi * r2**3 * B0**2 / (MU0 * L) * (np.imag(g(a)) - np.imag(g(b)))


def thin_shell_small_theta_nutation_rate(k_e, B0, J1, J3, tau, L, omega_field):
    """Thin-shell case of ``small_theta_nutation_rate`` with k_e = 2π r2³ τ/μ0 (SI):
    (1/θ) dθ/dt = k_e B0²/(2|L|) [a/(1 + a²τ²) − b/(1 + b²τ²)], a = |L|/J3 − ω, b = |L|/J1 − ω.
    Its sign is that of −κ·Q(|L|/J1) (see ``NutationWindow``)."""
    L = np.asarray(L, dtype=float)
    a = L / J3 - omega_field
    b = L / J1 - omega_field
    return k_e * B0**2 / (2.0 * L) * (a / (1.0 + (a * tau) ** 2) - b / (1.0 + (b * tau) ** 2))


def averaged_nutation_rate(g: Callable, r2, B0, J1, J3, L, omega_field, theta, n_grid=16):
    """Independent check of [M] (3.18): averaged dθ/dt (rad/s) at ANY θ from the exact
    linear response, for an axisymmetric rotor (J1 = J2) with L = |L| z3 (ρ = 0) in the
    field B = B0 (cos ωt, sin ωt, 0).

    Along the unperturbed regular precession (ψ' = |L|/J1, φ' = −ν, ν = |L| cosθ (1/J1 −
    1/J3)) the body-frame field B_b = B0 Rz(−φ) Rx(−θ) Rz(ωt − ψ) e1 is a trigonometric
    polynomial on the 2-torus (a, b) = (ωt − ψ, φ); its harmonic e^{i(ja + kb)} has the
    body frequency ω_jk = j(|L|/J1 − ω) + kν (convention e^{−iωt}) and gives the moment
    (2π r2³/μ0) ĝ(ω_jk) times it. The torque N_b = m × B_b gives
    dθ/dt = −N_b·e⊥/|L|, e⊥ = (x3 − y3 cosθ)/sinθ; this is averaged over the torus
    (= the time average when ω − |L|/J1 and ν are incommensurate). 0 < θ < π.
    """
    th = float(theta)
    nu = L * np.cos(th) * (1.0 / J1 - 1.0 / J3)
    N = int(n_grid)
    ang = 2.0 * np.pi * np.arange(N) / N
    A, Bg = np.meshgrid(ang, ang, indexing="ij")  # A = a, Bg = b
    v = np.stack([np.cos(A), np.sin(A), np.zeros_like(A)], axis=-1)
    # Rx(−θ)
    c, s = np.cos(th), np.sin(th)
    v = np.stack([v[..., 0], c * v[..., 1] + s * v[..., 2], -s * v[..., 1] + c * v[..., 2]], axis=-1)
    # Rz(−b)
    cb, sb = np.cos(Bg), np.sin(Bg)
    Bb = B0 * np.stack([cb * v[..., 0] + sb * v[..., 1], -sb * v[..., 0] + cb * v[..., 1], v[..., 2]], axis=-1)
    Cf = np.fft.fft2(Bb, axes=(0, 1))
    jf = np.fft.fftfreq(N, 1.0 / N)
    Jg, Kg = np.meshgrid(jf, jf, indexing="ij")
    wjk = Jg * (L / J1 - omega_field) + Kg * nu
    gj = np.where(wjk == 0.0, 0.0, g(np.where(wjk == 0.0, 1.0, wjk)))
    m = np.real(np.fft.ifft2(Cf * (2.0 * np.pi * r2**3 / MU0) * gj[..., None], axes=(0, 1)))
    Nb = np.cross(m, Bb)
    y3 = np.stack([s * np.sin(Bg), s * np.cos(Bg), c * np.ones_like(Bg)], axis=-1)
    eperp = (np.array([0.0, 0.0, 1.0]) - c * y3) / s
    return -np.mean(np.sum(Nb * eperp, axis=-1)) / L


# ----------------------------------------------------------------------------------
# constant field
# ----------------------------------------------------------------------------------
def constant_field_transverse_decay_rate(k_e, B, J):
    """Decay rate (1/s) of the angular velocity ⟂ B of a spherical rotor (J1 = J2 = J3 = J)
    in a constant field: k_e B²/J.

    Quasi-static torque N = k_e B × (B × Ω) = −k_e B² Ω⊥ ([K] (1.2) with dB/dt = 0), so
    Ω⊥ ∝ e^{−k_e B² t/J} while L·B is conserved ([M] (3.7): l cosρ = const). [BS] (8.3):
    exponent (1/16) ε λ I² t/π with ε = 4π/c², J = (8/15)π a⁵, P(1) = −a⁵λ/30 (Gaussian),
    i.e. ε|P(1)| I²/J = k_e B²/J in SI (k_e = (2π/15) σ a⁵ for a solid sphere); [BS]'s
    "L" in (6.2)/(8.3) is the body-frame field ΓH∞, not the kinetic moment, and its
    L − (I/ω)Ω is the part of Ω not along the field. Valid for |Ω|τ_eff ≪ 1. Beyond it
    (thin shell, Ω ⟂ B) the body sees the field rotating at |Ω| (torque–slip curve) and the
    rate is k_e B²/(J (1 + Ω²τ²)), so the decay is no longer exponential.
    k_e (N·m·s/T²), B (T), J (kg·m²).
    """
    return k_e * B**2 / J
