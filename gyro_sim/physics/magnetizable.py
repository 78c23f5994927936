"""Magnetizable, anisotropic conducting body of [BS] in SI: closed forms and the Theorem-2 criterion.

[BS] = Bogatyrev & Strygin (docs/physics.md, Bibliography), Gaussian units. The full model
(:mod:`gyro_sim.compiled.kernels`, scene section ``effects.magnetizable``) uses the induced moment, body frame,

    m_b = (1/μ0) [M B_b + P1 dB_b/dt + P2 d²B_b/dt²]        (A·m²)          [BS] (2.3), (6.1)

with symmetric body matrices M (m³), P1 (m³·s), P2 (m³·s²). Conversion from [BS]:
[BS]'s torque is N = m_G × H with the Gaussian moment m_G = M_G H + ε P(1) Ḣ + ε² P(2) Ḧ
(ε = 4π/c², H in the body frame: [BS]'s "ΓH∞", written L in (6.2)). With H → B/μ0 and the
Gaussian polarizability α_G → 4π α_G (a superconducting sphere: m_G = −(a³/2) H, m = −(2π a³/μ0) B),

    M = 4π M_G,   P1 = 4π ε P(1),   P2 = 4π ε² P(2),   ελ → μ0 σ          (λ = conductivity)

and [BS]'s I²M (I = |H∞|) becomes (B²/μ0) M (both are torques: erg ↔ J). Functions here are pure
(numpy in, numpy/float out), SI, frames named in each docstring. physics.md §3, docs/magnetizable.md.
"""
from __future__ import annotations

import math

import numpy as np

from gyro_sim.physics.constants import MU0

__all__ = [
    "sphere_p1_p2",
    "thin_shell_p1_p2",
    "transverse_decay_rate",
    "sphere_transverse_decay_rate",
    "theorem2_quantity",
    "theorem2_stable_axis",
    "stationary_linearization",
    "near_sphere_eigenvalues",
    "bs62_rhs",
]


def sphere_p1_p2(a: float, sigma: float) -> tuple[float, float]:
    """P1 (m³·s), P2 (m³·s²) of a non-magnetic solid sphere (radius a m, conductivity σ S/m), isotropic.

    [BS] §8: P(1) = −a⁵λ/30, P(2) = a⁷λ²/315 (Gaussian); in SI
    P1 = 4π ε P(1) = −(2π/15) μ0 σ a⁵,  P2 = 4π ε² P(2) = (4π/315) μ0² σ² a⁷.
    Equal to the first two terms of [M] (2.14): ĝ = x²/15 + 2x⁴/315 + …, x² = iω μ0σa², iω ↔ −d/dt,
    μ0 m = 2πa³ ĝ B.
    """
    s = MU0 * sigma  # [BS] ελ = 4πλ/c² → μ0 σ
    p1 = 4.0 * math.pi * (-(a ** 5) * s / 30.0)  # [BS] §8 P(1), × 4π ε
    p2 = 4.0 * math.pi * (a ** 7) * s * s / 315.0  # [BS] §8 P(2), × 4π ε²
    return p1, p2


def thin_shell_p1_p2(r2: float, h: float, sigma: float) -> tuple[float, float]:
    """P1 (m³·s), P2 (m³·s²) of a thin shell (outer radius r2 m, wall h m, σ S/m), isotropic.

    [M] (2.15): ĝ = iωτ/(1 − iωτ) = iωτ + (iωτ)² + …, τ = μ0σ r2 h/3, so P1 = −2π r2³ τ, P2 = 2π r2³ τ².
    """
    tau = MU0 * sigma * r2 * h / 3.0  # [M] (2.15)
    return -2.0 * math.pi * r2 ** 3 * tau, 2.0 * math.pi * r2 ** 3 * tau * tau


def transverse_decay_rate(P1: float, B: float, J: float) -> float:
    """Decay rate (1/s) of the spin ⟂ a constant field B (T) of a body with spherical inertia J (kg·m²)
    and isotropic P1 (m³·s, negative): −P1 B²/(μ0 J) = k_e B²/J.

    [BS] (8.3): L − (I/ω)Ω ∝ exp[−(1/16) ε λ I² t/π] for a sphere of unit density, J = (8/15)π a⁵,
    i.e. the exponent is ε|P(1)| I² t/J; in SI (this module's docstring) ε|P(1)| I² → |P1| B²/μ0.
    [BS]'s L there is the body-frame field, so L − (I/ω)Ω is (I/ω) × the part of Ω ⟂ the field.
    """
    return -P1 * B * B / (MU0 * J)  # [BS] (8.3)


def sphere_transverse_decay_rate(a: float, sigma: float, B: float, J: float) -> float:
    """[BS] (8.3) in SI for a solid sphere: (2π/15) σ a⁵ B²/J (1/s); a m, σ S/m, B T, J kg·m²."""
    return transverse_decay_rate(sphere_p1_p2(a, sigma)[0], B, J)


def theorem2_quantity(J, M, omega: float, B: float) -> np.ndarray:
    """ω² J_k + (B²/μ0) m_k (J) for k = 1, 2, 3: [BS] Theorem 2's "ω²J + I²M" in SI.

    J: principal moments (kg·m²), M: the diagonal of the magnetisation matrix in the same body axes
    (m³), ω spin rate (rad/s), B field magnitude (T). The stationary rotation Ω = ω e_k with the
    field along e_k is stable (P1 diagonal, negative) iff k maximises this quantity.

    Derivation (SI, docs/magnetizable.md): with P1 = 0 the body-frame equations
    J Ω̇ = JΩ × Ω + (1/μ0)(M b) × b, ḃ = b × Ω keep E = ½ Ω·JΩ − (1/2μ0) b·Mb and h = JΩ·b/|b|;
    the second variation of E − ω h at Ω = ω e_k, b = B e_k splits into 2×2 blocks
    [[J_i, −ωJ_i/B], [−ωJ_i/B, (ω²J_k − (B²/μ0)(m_i − m_k))/B²]] (i ≠ k), positive definite iff
    ω²J_k + (B²/μ0) m_k > ω²J_i + (B²/μ0) m_i. A negative P1 makes dE/dt = (1/μ0) ḃ·P1 ḃ ≤ 0: a
    minimum is asymptotically stable, a saddle unstable (dissipation removes gyroscopic stability).
    """
    J = np.asarray(J, float)
    M = np.asarray(M, float)
    if M.ndim == 2:
        M = np.diag(M)
    return omega * omega * J + (B * B / MU0) * M  # [BS] Theorem 2: ω²J + I²M, I²M → (B²/μ0) M


def theorem2_stable_axis(J, M, omega: float, B: float) -> int:
    """Index (0, 1, 2) of the body axis whose stationary rotation [BS] Theorem 2 calls stable."""
    return int(np.argmax(theorem2_quantity(J, M, omega, B)))


def stationary_linearization(J, M, P1, omega: float, B: float, axis: int) -> np.ndarray:
    """4×4 matrix A of the linearised [BS] (6.2) (first order, P2 = 0) at Ω = ω e_k, b = B e_k.

    k = ``axis``; (i, j, k) cyclic. State x = (Ω_i, Ω_j, b_i, b_j): transverse body rates (rad/s) and
    transverse body-frame field components (T); dx/dt = A x. J, M, P1: diagonals (kg·m², m³, m³·s)
    in the principal axes; ω rad/s; B T. From J Ω̇ = JΩ×Ω + (1/μ0)[(M b) × b + (P1 ḃ) × b], ḃ = b×Ω:

        J_i Ω̇_i = (J_j − J_k) ω Ω_j + (B/μ0)(m_j − m_k) b_j + (B/μ0) p_j (B Ω_i − ω b_i)
        J_j Ω̇_j = (J_k − J_i) ω Ω_i + (B/μ0)(m_k − m_i) b_i + (B/μ0) p_i (B Ω_j − ω b_j)
        ḃ_i = −B Ω_j + ω b_j,   ḃ_j = B Ω_i − ω b_i
    """
    J = np.asarray(J, float)
    M = np.asarray(M, float)
    P = np.asarray(P1, float)
    M = np.diag(M) if M.ndim == 2 else M
    P = np.diag(P) if P.ndim == 2 else P
    k = int(axis)
    i, j = (k + 1) % 3, (k + 2) % 3
    c = B / MU0
    return np.array([
        [c * P[j] * B / J[i], (J[j] - J[k]) * omega / J[i], -c * P[j] * omega / J[i], c * (M[j] - M[k]) / J[i]],
        [(J[k] - J[i]) * omega / J[j], c * P[i] * B / J[j], c * (M[k] - M[i]) / J[j], -c * P[i] * omega / J[j]],
        [0.0, -B, 0.0, omega],
        [B, 0.0, -omega, 0.0],
    ])


def near_sphere_eigenvalues(delta, omega: float, rate: float) -> np.ndarray:
    """[BS] (8.1)–(8.3) in SI: the 4 eigenvalues (1/s) of the linearisation about Ω = ω e3, B_b = B e3 of a
    non-magnetic near-sphere J = J0 (E + diag δ), |δ| ≪ 1, with isotropic P1 (M = 0, P2 left out).

    ``rate`` = −P1 B²/(μ0 J0) = k_e B²/J0 (1/s), ω rad/s. [BS] (Gaussian, J = (8/15)π a⁵ (E + ε diag α),
    so δ = εα, and (1/16) ελI²/π = ``rate``):

        λ_{1,2} = ±iω − rate                                            ((8.3): the field-relative spin)
        λ_{3,4} = ±iω √((δ1 − δ3)(δ2 − δ3)) + ½ rate (δ1 + δ2 − 2δ3)     ((8.1); real ±ω√(−…) is (8.2))

    The printed λ_{1,2} "±iω^{−1/16} ελI²π^{−1}" is OCR damage of ±iω − (1/16)ελI²/π; (8.1)'s bracket
    "[ε^{−1/2} ε² (α1 + α2)]" of a correction to the frequency, not kept here (relative O(δ)).
    """
    d1, d2, d3 = (float(x) for x in delta)
    root = omega * np.sqrt(complex((d1 - d3) * (d2 - d3)))  # [BS] (8.1) Λ1; imaginary → (8.2) Λ2
    re = 0.5 * rate * (d1 + d2 - 2.0 * d3)  # [BS] (8.1): (1/32) ε² λ I² π⁻¹ (α1 + α2 − 2α3)
    return np.array([1j * omega - rate, -1j * omega - rate, 1j * root + re, -1j * root + re])  # [BS] (8.3)


def bs62_rhs(Omega, b, J, M, P1, P2=None):
    """[BS] (6.2) in SI: (dΩ/dt, db/dt) of a body in a constant field, body frame.

    Ω rad/s, b = Rᵀ B (T) the body-frame field, J (3,) kg·m² principal moments, M, P1, P2 (3, 3)
    body matrices (m³, m³·s, m³·s²). As printed (the OCR's "Γ' = −Ω + Γ" is Γ̇ = −Ω̂Γ):

        J Ω̇ = JΩ × Ω + (1/μ0){ M b × b + P1 (b × Ω) × b
                               + P2 [(b × Ω) × Ω + b × J⁻¹(JΩ × Ω + (1/μ0) M b × b)] × b },
        ḃ = b × Ω.

    The P2 bracket is d²b/dt² with Ω̇ taken from the zeroth-order torque only ([BS]'s ordering);
    the compiled kernel also puts the P1 torque into that Ω̇ (a difference of order ε³).
    """
    Omega = np.asarray(Omega, float)
    b = np.asarray(b, float)
    J = np.asarray(J, float)
    M = np.asarray(M, float)
    P1 = np.asarray(P1, float)
    L = J * Omega
    gyro = np.cross(L, Omega)
    t0 = np.cross(M @ b, b) / MU0
    db = np.cross(b, Omega)  # [BS] (6.2): L' = L × Ω
    m = P1 @ db
    if P2 is not None:
        dOm0 = (gyro + t0) / J
        ddb = np.cross(db, Omega) + np.cross(b, dOm0)
        m = m + np.asarray(P2, float) @ ddb
    dOm = (gyro + t0 + np.cross(m, b) / MU0) / J
    return dOm, db
