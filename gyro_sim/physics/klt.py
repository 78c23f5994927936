"""Averaged and closed-form models of [KLT] (Kushpil, Leshchenko, Timoshenko, 2000), in SI.

Two problems of [KLT] (docs/physics.md, Bibliography), each the check of
an effect of the full model (:mod:`gyro_sim.compiled.effects`, scene section ``effects``):

§1 **Near-spherical body with a viscoelastic element** (``effects.damper``): a point mass m on an
isotropic spring (stiffness c, N/m) with viscous friction (δ, N·s/m) attached at O1 = ρ e3 of a
rigid body. Ω² = c/m (rad²/s²), λ = δ/m (1/s). Under (1) Ω² ≫ λω ≫ ω² the mass follows its
quasi-static deflection and the body obeys the averaged equations (4) with the first integrals
(5), (8) and the slow evolution (7), solved in closed form at small Θ by (9)–(12).

§2 **Lagrange top** (``effects.unbalance``, ``effects.gas_drag``): an axisymmetric body (A
equatorial, C axial moment of inertia about the fixed point, kg·m²) under the restoring moment
k(Θ) sinΘ of (13) (k in N·m) and the slowly varying drag (17) N_b = −(I1 p, I1 q, I3 r)
(I in N·m·s). First approximation (18): the free-nutation amplitude decays as
exp(−A⁻¹∫I1 dt), the spin as r0(1 − C⁻¹∫I3 dt), the symmetry axis precesses about the vertical at
ψ' = k/(C r0) (the rate of the approximate gyroscope theory, refined by (19)).

SI conversion of the paper's scaled variables. §1: ε A', ε B', ε C' are inertias (kg·m²), and the
damper term printed ρ² m ω² carries the factor Ω⁻² that the paper counts as ε: in SI it is
m ρ² ω²/Ω² = m² ρ² ω²/c (kg·m²); τ = ω0 (J2* − J1*) t / J0. §2: p = εP, k = εK, M = ε²M*, τ = εt;
every formula below is written back in the unscaled quantities (D_ij = C^{-i} r0^{-j}: the printed
"D_ij = C^{-i} r0^{-1}" lost the exponent j, e.g. (19)'s D33 term A K² D33 cosΘ0 is the second-order
regular-precession rate A k² cosΘ/(C³ r0³)).

Frames: body frame e1, e2, e3 (principal axes of the body, e3 through O1 / the symmetry axis);
angular velocities in rad/s, angles in rad, times in s. Findings (where the printed formula needed a
correction or the full model disagrees) are in docs/klt.md and next to the functions.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.integrate import solve_ivp

__all__ = [
    # §1 viscoelastic element
    "inertia_with_mass_at_o1", "body_inertia_from_star", "quasi_static_offset", "damper_averaged_rhs",
    "mu_parameter", "slow_time_scale", "omega_angles", "omega_integral", "theta_phi_rhs", "first_integral",
    "integrate_theta_phi",
    "phi_at_pole", "theta_small", "damper_energy", "quasi_static_dissipation", "initial_state_for_omega",
    # §2 Lagrange top
    "k_of_theta", "dk_dtheta", "precession_rate", "regular_precession_rate", "top_initial", "poly_integral",
    "transverse_decay", "spin_first_order",
    "spin_exact", "nutation_phase_rate", "free_nutation", "theta_drift", "drift_rate", "spin_with_drag",
]

# ================================================================================================
# §1 Near-spherical body with a viscoelastic element
# ================================================================================================


def inertia_with_mass_at_o1(J: Sequence[float], m: float, rho: float) -> np.ndarray:
    """J0* (kg·m²): principal moments of the body with the mass held at O1 = ρ e3 ([KLT] (2), (3)).

    J: the rigid body alone (the simulator's ``rotor.inertia``); the mass adds m(ρ²I − ρ² e3 e3ᵀ),
    so J0* = (J1 + mρ², J2 + mρ², J3). In [KLT] O is the centre of inertia of the free system; the
    simulator's O is a fixed point, where the same holds with m in place of the reduced mass
    m M/(M + m) (they differ by m/M, nothing in the checks here).
    """
    J = np.asarray(J, float)
    return J + m * rho * rho * np.array([1.0, 1.0, 0.0])


def body_inertia_from_star(Jstar: Sequence[float], m: float, rho: float) -> np.ndarray:
    """Inverse of :func:`inertia_with_mass_at_o1`: the rigid body's J (kg·m²) for a wanted J0*."""
    Jstar = np.asarray(Jstar, float)
    return Jstar - m * rho * rho * np.array([1.0, 1.0, 0.0])


def quasi_static_offset(omega_b: Sequence[float], m: float, rho: float, c: float) -> np.ndarray:
    """Deflection u (m, body frame) of the mass from O1 in steady rotation at ω (rad/s, body frame).

    Relative equilibrium of the mass in the body rotating at constant ω: c u = m[ω² r − (ω·r) ω]
    with r = ρ e3 + u, i.e. [(c − mω²) I + m ω ωᵀ] u = m [ω² ρ e3 − (ω·ρ e3) ω]. Leading term
    u ≈ Ω⁻² ρ (ω² e3 − ω3 ω) (the centrifugal force over the stiffness), the first term of the
    expansion in Ω⁻² behind [KLT] (2). Exact for the relative equilibrium, so a mass started
    there has no free oscillation except the O(ε) one from the slow drift of ω in the body.
    """
    w = np.asarray(omega_b, float)
    w2 = float(w @ w)
    a = np.array([0.0, 0.0, rho])
    M = (c - m * w2) * np.eye(3) + m * np.outer(w, w)
    return np.linalg.solve(M, m * (w2 * a - float(w @ a) * w))


def damper_averaged_rhs(omega_b: np.ndarray, Jstar: Sequence[float], m: float, rho: float, c: float,
                        J0: float | None = None) -> np.ndarray:
    """dω/dt (rad/s², body frame) of [KLT] (4) in SI; ω (..., 3) rad/s.

    # [KLT] (4), SI: J0 ṗ =  q r [J2* − J3* + m ρ² ω²/Ω²]
    #                J0 q̇ = −p r [J1* − J3* + m ρ² ω²/Ω²]
    #                J0 ṙ = −p q [J2* − J1*]
    with Ω² = c/m and J0 the reference moment of (3) (default: the mean of J0*). Derivation (fixed
    point): the quasi-static deflection u0 = Ω⁻²ρ(ω² e3 − ω3 ω) changes the kinetic moment by
    m[2(a·u0)ω − (a·ω)u0 − (u0·ω)a] = mΩ⁻²ρ²[(2ω² − ω3²)ω − ω² ω3 e3]; only the last term survives
    ω × K, giving the torque m ρ² ω² ω3 Ω⁻² (ω × e3), i.e. the printed bracket with the Ω⁻² the
    paper absorbs in ε. No dissipative term to this order (see :func:`quasi_static_dissipation`).
    """
    w = np.asarray(omega_b, float)
    J1, J2, J3 = np.asarray(Jstar, float)
    J0 = float(np.mean(Jstar)) if J0 is None else float(J0)
    p, q, r = w[..., 0], w[..., 1], w[..., 2]
    d = m * m * rho * rho * (p * p + q * q + r * r) / c  # m ρ² ω² / Ω²
    return np.stack([q * r * (J2 - J3 + d), -p * r * (J1 - J3 + d), -p * q * (J2 - J1)], axis=-1) / J0


def mu_parameter(Jstar: Sequence[float], m: float, rho: float, c: float, omega0: float) -> float:
    """μ of [KLT] (7) in SI: μ = (A' − C' + ρ²mω0²Ω⁻²)/(A' − B') = (J1* − J3* + m²ρ²ω0²/c)/(J1* − J2*)."""
    J1, J2, J3 = np.asarray(Jstar, float)
    return (J1 - J3 + m * m * rho * rho * omega0 * omega0 / c) / (J1 - J2)  # [KLT] (7)


def slow_time_scale(Jstar: Sequence[float], omega0: float, J0: float | None = None) -> float:
    """dτ/dt (1/s) of [KLT]: τ = ε ω0 (B' − A')/J0 · t = ω0 (J2* − J1*)/J0 · t (signed)."""
    J1, J2, _ = np.asarray(Jstar, float)
    J0 = float(np.mean(Jstar)) if J0 is None else float(J0)
    return omega0 * (J2 - J1) / J0


def omega_angles(omega_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(|ω| rad/s, Θ, φ rad) of body-frame ω by [KLT] (6): p = ω cosφ sinΘ, q = ω sinφ sinΘ, r = ω cosΘ."""
    w = np.asarray(omega_b, float)
    n = np.linalg.norm(w, axis=-1)
    theta = np.arctan2(np.hypot(w[..., 0], w[..., 1]), w[..., 2])  # [KLT] (6)
    phi = np.arctan2(w[..., 1], w[..., 0])
    return n, theta, phi


def omega_integral(omega_b: np.ndarray, m: float, rho: float, c: float, J0: float) -> np.ndarray:
    """ω² [1 + 2 m ρ² (p² + q²)/(J0 Ω²)] (rad²/s²): the first integral (5) refined to O(ε²).

    (5) ω² = const holds to O(ε) only in the full model: |K| is conserved exactly and the energy to
    O(ε²) per slow-time unit, and with the quasi-static mass K = J0*ω + mΩ⁻²ρ²[(2ω² − ω3²)ω − ω²ω3 e3],
    2E = J0*ω·ω + 3mΩ⁻²ρ²ω²(ω² − ω3²) + …; eliminating the anisotropy ε(A', B', C') between
    4 E J0 − |K|² leaves J0² ω² + 2 J0 mρ²Ω⁻² ω² (p² + q²) = const + O(ε²). Finding of docs/klt.md
    (measured exponent 1.9–2.3 against 1.0 for ω² itself).
    """
    w = np.atleast_2d(np.asarray(omega_b, float))
    w2 = np.einsum("ni,ni->n", w, w)
    return w2 * (1.0 + 2.0 * m * m * rho * rho * (w[:, 0] ** 2 + w[:, 1] ** 2) / (c * J0))


def theta_phi_rhs(tau: float, y: Sequence[float], mu: float) -> list[float]:
    """[KLT] (7): Θ' = sinΘ sinφ cosφ, φ' = cosΘ (μ − sin²φ) (′ = d/dτ)."""
    th, ph = y
    s = math.sin(ph)
    return [math.sin(th) * s * math.cos(ph), math.cos(th) * (mu - s * s)]  # [KLT] (7)


def first_integral(theta, phi, mu: float):
    """c1 = sin²Θ (μ − sin²φ) of [KLT] (8) (constant along (7))."""
    return np.sin(theta) ** 2 * (mu - np.sin(phi) ** 2)  # [KLT] (8)


def integrate_theta_phi(tau: np.ndarray, theta0: float, phi0: float, mu: float, rtol: float = 1e-11) -> tuple:
    """Θ(τ), φ(τ) (rad) of [KLT] (7) at the slow times ``tau`` (increasing from 0), by DOP853."""
    tau = np.asarray(tau, float)
    sol = solve_ivp(theta_phi_rhs, (0.0, float(tau[-1])), [theta0, phi0], args=(mu,), method="DOP853",
                    t_eval=tau, rtol=rtol, atol=1e-13)
    return sol.y[0], sol.y[1]


def phi_at_pole(tau, phi0: float, mu: float) -> np.ndarray:
    """φ(τ) (rad, continuous) of φ' = μ − sin²φ, the limit Θ → 0 of (7): [KLT] (9), (10).

    μ > 1:  tanφ = l tan( r τ + arctan(l⁻¹ tanφ0)),  l = √(μ/(μ−1)), r = √(μ(μ−1))   # [KLT] (9)
    μ < 0:  tanφ = l tan(−r τ + arctan(l⁻¹ tanφ0))                                     # [KLT] (9)
    0<μ<1:  tanφ = j (a e^{Jτ} − w)/(a e^{Jτ} + w), j = √(μ/(1−μ)), J = 2√(μ(1−μ)),
            a = j⁻¹ tanφ0 + 1, w = 1 − j⁻¹ tanφ0                                      # [KLT] (10)
    (verified: d tanφ/dτ = μ + (μ − 1) tan²φ for each). The branch of arctan is followed so φ is
    continuous (for μ > 1 and μ < 0 φ turns without end; for 0 < μ < 1 it tends to arctan(±j)).
    """
    tau = np.asarray(tau, float)
    if mu > 1.0 or mu < 0.0:
        l = math.sqrt(mu / (mu - 1.0))
        r = math.sqrt(mu * (mu - 1.0))
        s = 1.0 if mu > 1.0 else -1.0
        # the phase x with tanφ = l tan x, continuous in τ; φ advances by π whenever x does
        k0 = math.floor((phi0 + math.pi / 2) / math.pi)  # φ0 = φ̂0 + k0 π with φ̂0 ∈ [−π/2, π/2)
        ph0 = phi0 - k0 * math.pi
        x0 = math.atan(math.tan(ph0) / l) if abs(math.cos(ph0)) > 1e-15 else math.copysign(math.pi / 2, ph0)
        x = s * r * tau + x0  # [KLT] (9)
        kx = np.floor((x + math.pi / 2) / math.pi)
        xh = x - kx * math.pi
        return np.arctan(l * np.tan(xh)) + (kx + k0) * math.pi
    if 0.0 < mu < 1.0:
        j = math.sqrt(mu / (1.0 - mu))
        J = 2.0 * math.sqrt(mu * (1.0 - mu))
        t0 = math.tan(phi0)
        a, w = t0 / j + 1.0, 1.0 - t0 / j  # [KLT] (10)
        E = np.exp(J * tau)
        k0 = round(phi0 / math.pi)
        return np.arctan(j * (a * E - w) / (a * E + w)) + k0 * math.pi  # [KLT] (10)
    raise ValueError(f"mu = {mu}: (9), (10) need mu > 1, mu < 0 or 0 < mu < 1")


def theta_small(tau, theta0: float, phi0: float, mu: float, printed: bool = False) -> np.ndarray:
    """Θ(τ) (rad) at small Θ: [KLT] (11) (μ > 1, μ < 0) and (12) (0 < μ < 1).

    At small Θ, (7) gives Θ²(μ − sin²φ) = const (the limit of (8)), so
    Θ² = Θ0² (μ − sin²φ0)/(μ − sin²φ(τ)) with φ(τ) of (9), (10). Written out:

    μ > 1 and μ < 0:  Θ² = Θ0² l⁻² (l² cos²φ0 + sin²φ0) [cos²x + l² sin²x],  x = ±rτ + arctan(l⁻¹ tanφ0)
    0 < μ < 1:        Θ² = Θ0² cos²φ0 (A e^{2Jτ} + B e^{Jτ} + C)/(4 e^{Jτ}),  A = (1 + j²)a²,
                      B = 2aw(1 − j²), C = (1 + j²)w²                                    # [KLT] (12)

    Finding: the printed (11) reads Θ² = Θ0² l^{±2} (l² cos²φ0 + sin²φ0)^{∓1} [cos²x + l² sin²x]^{∓1}
    with x = rτ + arctan(l⁻¹ tanφ0) and "upper signs for μ < 0, lower for μ > 1". The lower signs
    (exponents −2, +1, +1) are right for BOTH μ > 1 and μ < 0, with the x of (9) (−rτ for μ < 0):
    (μ − 1) l² = μ holds for either sign, so μ − sin²φ = μ/(cos²x + l² sin²x) in both cases. The
    upper-sign form agrees at τ = 0 only. ``printed=True`` returns the printed upper-sign form for
    μ < 0 (with the printed +rτ), to show the disagreement.
    """
    tau = np.asarray(tau, float)
    if mu > 1.0 or mu < 0.0:
        l = math.sqrt(mu / (mu - 1.0))
        r = math.sqrt(mu * (mu - 1.0))
        A0 = l * l * math.cos(phi0) ** 2 + math.sin(phi0) ** 2
        x0 = math.atan2(math.sin(phi0), l * math.cos(phi0))  # arctan(l⁻¹ tanφ0); only cos², sin² of x used
        if printed and mu < 0.0:
            x = r * tau + x0
            return theta0 * np.sqrt(l * l / A0 / (np.cos(x) ** 2 + l * l * np.sin(x) ** 2))  # printed (11), upper
        x = (r if mu > 1.0 else -r) * tau + x0
        return theta0 * np.sqrt(A0 * (np.cos(x) ** 2 + l * l * np.sin(x) ** 2)) / l  # [KLT] (11), corrected
    if 0.0 < mu < 1.0:
        j = math.sqrt(mu / (1.0 - mu))
        J = 2.0 * math.sqrt(mu * (1.0 - mu))
        t0 = math.tan(phi0)
        a, w = t0 / j + 1.0, 1.0 - t0 / j
        A, B, C = (1 + j * j) * a * a, 2 * a * w * (1 - j * j), (1 + j * j) * w * w
        E = np.exp(J * tau)
        return theta0 * abs(math.cos(phi0)) * np.sqrt((A * E * E + B * E + C) / (4.0 * E))  # [KLT] (12)
    raise ValueError(f"mu = {mu}: (11), (12) need mu > 1, mu < 0 or 0 < mu < 1")


def damper_energy(omega_b: np.ndarray, J: Sequence[float], m: float, rho: float, c: float,
                  u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Total mechanical energy (J) of body + mass: ½ωᵀJω + ½ m|v + ω × r|² + ½ c|u|², r = ρ e3 + u.

    ω (rad/s), u (m), v = u̇ relative to the body (m/s), all body frame, rows = samples. With no
    external torque dE/dt = −δ|v|² exactly (the friction's power).
    """
    w = np.atleast_2d(np.asarray(omega_b, float))
    u = np.atleast_2d(np.asarray(u, float))
    v = np.atleast_2d(np.asarray(v, float))
    r = u + np.array([0.0, 0.0, rho])
    vel = v + np.cross(w, r)
    return (0.5 * np.einsum("ni,i,ni->n", w, np.asarray(J, float), w) + 0.5 * m * np.einsum("ni,ni->n", vel, vel)
            + 0.5 * c * np.einsum("ni,ni->n", u, u))


def quasi_static_dissipation(omega_b: np.ndarray, Jstar: Sequence[float], m: float, rho: float, c: float,
                             delta: float, J0: float | None = None) -> np.ndarray:
    """Friction power δ|u̇0|² (W) of the quasi-static deflection, with ω̇ from (4): the dissipation.

    u0 = Ω⁻²ρ(ω² e3 − ω3 ω)/(1 − ω²/Ω²) ⇒ u̇0 = Ω⁻²ρ(2(ω·ω̇) e3 − ω̇3 ω − ω3 ω̇)/(1 − ω²/Ω²). For the
    near-spherical body ω̇ = O(ε ω²) (ω moves slowly in the body), so u̇0 = O(ε Ω⁻² ρ ω³) and the
    power is δ Ω⁻⁴ ρ² O(ε² ω⁶): the λΩ⁻⁴ term of Φ in (2) carries a factor ε here, it is second order
    and (4) rightly has no dissipative term. The full model's energy falls at the rate this returns,
    to O(ε) (measured: test/test_klt.py, docs/klt.md).
    """
    w = np.atleast_2d(np.asarray(omega_b, float))
    wd = damper_averaged_rhs(w, Jstar, m, rho, c, J0)
    W2 = c / m
    e3 = np.array([0.0, 0.0, 1.0])
    w2 = np.einsum("ni,ni->n", w, w)
    ud = (rho / W2) * (2.0 * np.einsum("ni,ni->n", w, wd)[:, None] * e3 - wd[:, 2:3] * w - w[:, 2:3] * wd)
    # the exact relative equilibrium is u0/(1 − ω²/Ω²) (u0 ⊥ ω), and ω² is constant by (5)
    return delta * np.einsum("ni,ni->n", ud, ud) / (1.0 - w2 / W2) ** 2


def initial_state_for_omega(omega_b: Sequence[float], J: Sequence[float], m: float, rho: float,
                            c: float) -> dict:
    """Scene keys that start the body at ω (rad/s, body frame) with the mass on its slow (forced)
    motion, so that no free oscillation of the mass is excited to the order used here.

    Returns ``{"initial": {kinetic_moment, L_direction, psi, theta, phi}, "offset": u, "velocity": v}``
    (L along z3, L_b = (J + m(|r|²I − r rᵀ)) ω + m r × v). u = the relative equilibrium of
    :func:`quasi_static_offset` plus the deflection by the Euler force, −Ω⁻² ω̇ × ρe3, and
    v = u̇0 = Ω⁻²ρ(2(ω·ω̇) e3 − ω̇3 ω − ω3 ω̇)/(1 − ω²/Ω²), with ω̇ from (4). Without these two
    terms the mass starts off its slow motion by O(ε Ω⁻² ρ ω²) and the free oscillation that
    follows dissipates ~ε³ of the energy at once (measured: 3 % of the whole loss over τ = 3 at
    ε = 0.005), which would hide the slow dissipation.
    """
    w = np.asarray(omega_b, float)
    Jstar = inertia_with_mass_at_o1(J, m, rho)
    wd = damper_averaged_rhs(w, Jstar, m, rho, c)
    W2 = c / m
    a = np.array([0.0, 0.0, rho])
    u0 = quasi_static_offset(w, m, rho, c) - np.cross(wd, a) / W2
    v0 = (rho / W2) * (2.0 * float(w @ wd) * np.array([0.0, 0.0, 1.0]) - wd[2] * w - w[2] * wd)
    v0 = v0 / (1.0 - float(w @ w) / W2)
    r = u0 + a
    A = np.diag(np.asarray(J, float)) + m * (float(r @ r) * np.eye(3) - np.outer(r, r))
    K = A @ w + m * np.cross(r, v0)
    n = float(np.linalg.norm(K))
    k = K / n
    # frames.py: L_b = |L| (sinθ sinφ, sinθ cosφ, cosθ)
    theta = math.acos(max(-1.0, min(1.0, float(k[2]))))
    phi = math.atan2(float(k[0]), float(k[1]))
    return {"initial": {"kinetic_moment": n, "L_direction": [0.0, 0.0, 1.0], "psi": 0.0, "theta": theta,
                        "phi": phi}, "offset": u0.tolist(), "velocity": v0.tolist()}


# ================================================================================================
# §2 Lagrange top: restoring moment k(Θ), slowly varying drag
# ================================================================================================


def k_of_theta(theta, k: float, k1: float = 0.0, k2: float = 0.0):
    """k(Θ) = k + k1 cosΘ + k2 cos²Θ (N·m), the scene's ``effects.unbalance``."""
    c = np.cos(theta)
    return k + k1 * c + k2 * c * c


def dk_dtheta(theta, k1: float = 0.0, k2: float = 0.0):
    """K' = dk/dΘ = −(k1 + 2 k2 cosΘ) sinΘ (N·m/rad)."""
    return -(k1 + 2.0 * k2 * np.cos(theta)) * np.sin(theta)


def precession_rate(k_theta: float, C: float, r0: float, A: float | None = None,
                    theta: float | None = None) -> float:
    """Mean precession rate ψ' (rad/s) of the symmetry axis about the vertical.

    First approximation ψ' = k/(C r0) ([KLT] (18) ψ(1) = εK D11 t; the approximate gyroscope
    theory). With A and Θ given, plus the second-order term of (19), A k² cosΘ/(C³ r0³)
    (ε²A K² D33 cosΘ0, D33 = C⁻³ r0⁻³): the slow root of the regular-precession condition
    k = ψ'(C r0 − A ψ' cosΘ) expanded to second order. k_theta = k(Θ0) (N·m), r0 spin (rad/s).
    """
    w1 = k_theta / (C * r0)  # [KLT] (18)
    if A is None or theta is None:
        return w1
    return w1 + A * k_theta ** 2 * math.cos(theta) / (C ** 3 * r0 ** 3)  # [KLT] (19), S(1)


def regular_precession_rate(k_theta: float, A: float, C: float, r0: float, theta: float) -> float:
    """Exact rate ψ' (rad/s) of the slow regular precession of the Lagrange top at the angle Θ.

    Θ' = 0 in (13) needs k(Θ) = ψ'(C r0 − A ψ' cosΘ) (r0 = the spin ω3); the slow root is
    ψ' = 2k/(C r0 + √(C² r0² − 4 A k cosΘ)), whose expansion is :func:`precession_rate`.
    """
    return 2.0 * k_theta / (C * r0 + math.sqrt(C * C * r0 * r0 - 4.0 * A * k_theta * math.cos(theta)))


def top_initial(A: float, C: float, r0: float, theta0: float, psidot: float = 0.0,
                nutation: Sequence[float] = (0.0, 0.0), vertical: Sequence[float] = (0.0, 0.0, 1.0)) -> dict:
    """Scene ``initial`` (kinetic_moment, L_direction, psi, theta, phi) of a Lagrange top.

    Symmetry axis x3 at Θ0 (rad) from the vertical v (tilted towards the case's z1 side of v), spin
    r0 = ω3 (rad/s), body rate ω_b = ψ' v_b + (free part (n1, n2, 0)) with the forced part ψ' v_b
    (ψ' in rad/s; pass :func:`regular_precession_rate` for a start without nutation) and the
    free-nutation part ``nutation`` = (a, −b) of (18) (rad/s, body frame). ω3 = r0 in all cases.
    """
    from gyro_sim.physics.frames import euler_angles  # R = Y Rz(ψ) Rx(θ) Rz(φ) (physics.md §1)

    v = np.asarray(vertical, float)
    v = v / np.linalg.norm(v)
    h = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    h = h - (h @ v) * v
    h /= np.linalg.norm(h)
    x3 = math.cos(theta0) * v + math.sin(theta0) * h
    x1 = math.cos(theta0) * h - math.sin(theta0) * v
    R = np.column_stack([x1, np.cross(x3, x1), x3])  # body → case
    vb = R.T @ v
    w = np.array([psidot * vb[0] + nutation[0], psidot * vb[1] + nutation[1], r0])
    L = R @ (np.array([A, A, C]) * w)
    psi, th, ph = (float(x) for x in euler_angles(R, L))
    n = float(np.linalg.norm(L))
    return {"kinetic_moment": n, "L_direction": (L / n).tolist(), "psi": psi, "theta": th, "phi": ph}


def poly_integral(coeffs: Sequence[float], t) -> np.ndarray:
    """∫₀ᵗ Σ c_k s^k ds of a gas-drag coefficient polynomial (N·m·s · s)."""
    t = np.asarray(t, float)
    return sum(ck * t ** (k + 1) / (k + 1) for k, ck in enumerate(coeffs))


def transverse_decay(t, A: float, transverse: Sequence[float]) -> np.ndarray:
    """exp(−A⁻¹ ∫₀ᵗ I1 dt): the factor of the free-nutation amplitude (a, b) in [KLT] (18)."""
    return np.exp(-poly_integral(transverse, t) / A)  # [KLT] (18)


def spin_first_order(t, r0: float, C: float, axial: Sequence[float]) -> np.ndarray:
    """r = r0 + εδ(1) = r0 (1 − C⁻¹ ∫₀ᵗ I3 dt) (rad/s): [KLT] (18)."""
    return r0 * (1.0 - poly_integral(axial, t) / C)  # [KLT] (18), δ(1) = −C⁻¹ r0 ∫ I3


def spin_exact(t, r0: float, C: float, axial: Sequence[float]) -> np.ndarray:
    """r0 exp(−C⁻¹ ∫₀ᵗ I3 dt): the exact solution of C ṙ = −I3(t) r ((13) with (17))."""
    return r0 * np.exp(-poly_integral(axial, t) / C)


def nutation_phase_rate(k_theta: float, dk: float, theta0: float, C: float, r0: float) -> float:
    """w (rad/s) of [KLT] (18): w = ½ ε D11 (2K cosΘ0 + K' sinΘ0) = (2k cosΘ0 + k' sinΘ0)/(2 C r0).

    The slow turn of (a, b) in the frame that turns at γ' = (C − A) r0/A relative to the body.
    """
    return (2.0 * k_theta * math.cos(theta0) + dk * math.sin(theta0)) / (2.0 * C * r0)  # [KLT] (18)


def free_nutation(omega_b: np.ndarray, vertical_b: np.ndarray, k_theta, C: float) -> np.ndarray:
    """(a, −b) of [KLT] (16), (18) in SI (rad/s): the free-nutation part of the transverse rate.

    (p, q) − ψ'_f (v1, v2) with ψ'_f = k(Θ)/(C r) the forced precession and v_b = (sinΘ sinφ,
    sinΘ cosφ, cosΘ) the vertical in the body frame: a = p − λ sinφ, b = −(q − λ cosφ),
    λ = k sinΘ/(C r) ([KLT] after (18), a0 = P0 − λ0 sinφ0, b0 = −Q0 + λ0 cosφ0). Rows = samples.
    """
    w = np.atleast_2d(np.asarray(omega_b, float))
    v = np.atleast_2d(np.asarray(vertical_b, float))
    f = np.asarray(k_theta, float) / (C * w[:, 2])
    return w[:, 0:2] - f[:, None] * v[:, 0:2]


def theta_drift(t, theta0: float, k_theta: float, C: float, r0: float, transverse: Sequence[float]) -> np.ndarray:
    """Mean nutation angle (rad) of (19): Θ0 + ε K0 D22 sinΘ0 ∫ I1 = Θ0 + k sinΘ0 ∫₀ᵗ I1 dt /(C² r0²).

    The drag on the forced precession makes the top fall (Θ grows from the vertical).
    """
    return theta0 + k_theta * math.sin(theta0) * poly_integral(transverse, t) / (C * C * r0 * r0)  # [KLT] (19)


def drift_rate(k_theta: float, L: float) -> float:
    """Azimuth drift rate (rad/s) of the kinetic moment about the vertical by the unbalance: k/|L|.

    For the fast top |L| ≈ C r0, the same as :func:`precession_rate`; the drift of a suspended
    gyroscope with a mass unbalance m g d (N·m) and kinetic moment |L| (N·m·s).
    """
    return k_theta / L


def spin_with_drag(t, k_eB2: float, nu: float, axial: Sequence[float], C: float, r0: float) -> np.ndarray:
    """Spin (rad/s) at times ``t`` (s, increasing from 0) of a rotor driven by one rotating field against
    the axial gas drag: C ṙ = k_eB0² (ν − r) − I3(t) r.

    k_eB0² (N·m·s): the quasi-static motor constant ([K] (1.3) at θ = 0, slip ≪ 1/τ); ν (rad/s) the
    field rate; ``axial``: the polynomial I3(t) of ``effects.gas_drag`` (N·m·s/s^k). At constant I3
    the spin settles at r* = k_eB0² ν/(k_eB0² + I3) (slip I3 ν/(k_eB0² + I3)) with the time constant
    C/(k_eB0² + I3): the drag's share of a spin-up controller's steady error.
    """
    t = np.asarray(t, float)

    def rhs(s, y):
        I3 = sum(ck * s ** k for k, ck in enumerate(axial))
        return [(k_eB2 * (nu - y[0]) - I3 * y[0]) / C]

    sol = solve_ivp(rhs, (0.0, float(t[-1])), [r0], t_eval=t, method="DOP853", rtol=1e-12, atol=1e-12 * abs(nu))
    return sol.y[0]
