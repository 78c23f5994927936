"""Averaged (slow) models of [K] (Komarov; docs/physics.md, Bibliography) for the quasi-static eddy torque, in SI.

Every public function takes and returns SI quantities (m, kg, s, T, rad, rad/s, N·m·s):
``L`` is the kinetic moment in the case frame (N·m·s), θ, φ the Euler angles of the body in
the L-frame exactly as the simulator outputs them (physics.md §1, ``gyro_sim.frames``:
R = Y Rz(ψ) Rx(θ) Rz(φ), L_b = |L| (sinθ sinφ, sinθ cosφ, cosθ)). The notes with the
derivations and the findings on the printed formulas are ``docs/averaged_k.md``.

Torque model: quasi-static, [K] (1.2) = physics.md §3, N = k_e B × (B × Ω + dB/dt),
k_e = ``conductor_model(...).k_e`` (N·m·s/T²). Stator k (axis u_k, field amplitude
B_k = b_k I_k in T, signed rate ν_k in rad/s) averaged over its field phase gives [K] (1.3):
⟨N_k⟩ = c_k [ν_k u_k − ½ (Ω + (Ω·u_k) u_k)], c_k = k_e B_k² (N·m·s).

SI translation of [K]'s symbols (choose any Ω0 > 0, rad/s, and torque scale M0, N·m):

* τ = Ω0 t;  l = |L|/(J Ω0);  J = 2 J1 J2/(J1 + J2) (harmonic mean, kg·m²);
  κ = J3/J − 1;  δ = (J2 − J1)/(J2 + J1) (this is [K]'s "μδ": [K] rescales δ → μδ in §2);
* [K]'s torque amplitude of stator k is m_k M0 = c_k Ω0 (αH²Ω0 of (1.2)), μ = M0/(J Ω0²), so
  **μ m_k = c_k/(J Ω0) = a_k/Ω0** with the SI rate constant **a_k = k_e B_k²/J** (1/s);
  [K]'s ν_k = ν_k(SI)/Ω0.  Only the products μ m_k appear, so no choice of M0 is needed.
* In the SI equations below μ never appears: μ m_k d/dτ → a_k d/dt.
  The averaging parameter of the full model is ε = a_k/(|L|/J) (torque rate over precession
  rate); the averaged models are first order in ε.

Conventions that differ from [K] (checked against the full model, see docs/averaged_k.md):
[K]'s φ is φ + π/2 (its θ′ carries −δ l sinθ sin2φ, ours +δ Λ sinθ sin2φ; cos2φ changes sign,
sin2φ changes sign), and [K]'s ψ is ψ − π/2 (its e⊥ = y1 cosψ + y2 sinψ).

Where the models hold: ε ≪ 1 (slow torque); quasi-static slips (|ν_k − Ω|τ_eff ≪ 1, else use the
lag model's torque-slip curve); torques that add ([K] §1 assumes it): the frequencies of the
torque, 2|ν_k| and |ν_j ± ν_k|, away from 0 (stator-stator resonance), from Λ = |L|/J (it drives the
nutation resonantly) and, for θ ≠ 0, π/2, from 2Λ; |δ| ≲ ε; the φ-averaged forms (2.2), (3.8)–(3.10)
also need θ away from π/2. Under ψ-switching the control fields swing back and forth instead of
turning, so also |ν_n| ≫ Λ and ||ν_1| − |ν_2|| ≫ Λ (docs/averaged_k.md §4).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from scipy.integrate import solve_ivp

__all__ = [
    "RotorK",
    "StatorsK",
    "k_e_of_scene",
    "gamma_k",
    "k21_rhs",
    "k21_torque",
    "K21Model",
    "K21Result",
    "nutation_k22",
    "nutation_k22_rate",
    "transverse_decay_k32",
    "PsiSwitchingK",
    "PsiResult",
    "Equilibrium",
    "LimitCycle",
    "psi_switching_averaged",
    "time_to_theta",
]

_Z = np.eye(3)


# ----------------------------------------------------------------------------------------
# rotor and stators
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RotorK:
    """Inertia of the rotor and [K]'s inertia symbols.

    J1, J2, J3 principal moments (kg·m²), x3 the polar axis. ``J`` = 2J1J2/(J1 + J2) (kg·m²),
    ``kappa`` = J3/J − 1 (> 0 oblate, < 0 prolate), ``delta`` = (J2 − J1)/(J2 + J1).
    """

    J1: float
    J2: float
    J3: float

    @classmethod
    def of(cls, inertia: Sequence[float]) -> "RotorK":
        J1, J2, J3 = (float(x) for x in inertia)
        return cls(J1, J2, J3)

    @property
    def J(self) -> float:
        return 2.0 * self.J1 * self.J2 / (self.J1 + self.J2)

    @property
    def kappa(self) -> float:
        return self.J3 / self.J - 1.0

    @property
    def delta(self) -> float:
        return (self.J2 - self.J1) / (self.J2 + self.J1)


@dataclass(frozen=True)
class StatorsK:
    """Stators as the averaged models see them (case frame, SI).

    axes (k,3) unit field axes u_k; B (k,) field amplitudes b_k I_k (T); rates (k,) signed
    field rates ν_k (rad/s).
    """

    axes: np.ndarray
    B: np.ndarray
    rates: np.ndarray

    @classmethod
    def make(cls, axes, B, rates) -> "StatorsK":
        ax = np.asarray(axes, dtype=float).reshape(-1, 3)
        ax = ax / np.linalg.norm(ax, axis=1, keepdims=True)
        B = np.asarray(B, dtype=float).reshape(-1)
        r = np.asarray(rates, dtype=float).reshape(-1)
        if not (ax.shape[0] == B.size == r.size):
            raise ValueError("axes, B and rates must describe the same number of stators")
        return cls(ax, B, r)

    @classmethod
    def of_scene(cls, scene) -> "StatorsK":
        """The stators of a scene at t = 0 (axis, b_k I_k, rate)."""
        st = scene.stators
        return cls.make([s.axis for s in st], [s.coil_constant * s.current for s in st], [s.rate for s in st])

    def rate_constants(self, k_e: float, J: float) -> np.ndarray:
        """a_k = k_e B_k²/J (1/s) = μ m_k Ω0 of [K]."""
        return k_e * self.B**2 / J


def k_e_of_scene(scene) -> float:
    """Quasi-static torque coefficient k_e = 2π r2³ τ_eff/μ0 (N·m·s/T²) of a scene's conductor."""
    from gyro_sim.physics.conductor import conductor_model

    c = scene.rotor.conductor
    return float(conductor_model(c.kind, c.outer_radius, c.conductivity, thickness=c.thickness).k_e)


def gamma_k(theta, kappa):
    """[K]'s γ = (1 + κ sin²θ)/(1 + κ): ⟨Ω⟩ = γ L/J is the angular velocity averaged over ψ
    (axisymmetric rotor; dimensionless)."""
    s = np.sin(theta)
    return (1.0 + kappa * s * s) / (1.0 + kappa)


def _unit(L):
    n = float(np.linalg.norm(L))
    return np.array([0.0, 0.0, 1.0]) if n == 0.0 else np.asarray(L) / n


# ----------------------------------------------------------------------------------------
# [K] (2.1): three (any number of) stators at constant rates
# ----------------------------------------------------------------------------------------
def k21_torque(L, theta, J, kappa, axes, c, rates) -> np.ndarray:
    """The averaged torque of [K] (2.1), dL/dt = Σ_k c_k [ν_k u_k − ½ γΛ (y3 + a_3k u_k)] (N·m, case frame).

    L (3,) or (n, 3) case frame (N·m·s), θ scalar or (n,) rad; J, κ, axes (k, 3), c (k,) N·m·s and
    rates (k,) rad/s as in :func:`k21_rhs`. Vectorised over rows (the output samples of an averaged stretch).
    """
    L = np.asarray(L, dtype=float)
    Ln = np.linalg.norm(L, axis=-1, keepdims=True)
    y3 = np.divide(L, Ln, out=np.broadcast_to([0.0, 0.0, 1.0], L.shape).copy(), where=Ln > 0)
    g = np.asarray(gamma_k(theta, kappa))[..., None]
    a3 = y3 @ axes.T  # (…, k)
    return (c * rates) @ axes - 0.5 * g * (Ln / J) * (np.sum(c) * y3 + (c * a3) @ axes)  # [K] (2.1)


def k21_rhs(t, x, J, kappa, delta, axes, c, rates, control=None):
    """Right-hand side of [K] (2.1) in SI, vector form (any stator axes).

    State x = (L1, L2, L3, θ, φ): L case frame (N·m·s), θ, φ (rad, simulator convention).
    J (kg·m², harmonic mean of J1, J2), κ, δ as in :class:`RotorK`; axes (k,3) unit u_k;
    c (k,) = k_e B_k² (N·m·s); rates (k,) ν_k (rad/s). Returns dx/dt (N·m, rad/s, rad/s):

        dL/dt = Σ_k c_k [ν_k u_k − ½ (γ Λ y3 + γ Λ a_3k u_k)],    Λ = |L|/J, a_3k = y3·u_k
        dθ/dt = δ Λ sinθ sin2φ − ¼ κ/(1+κ) g² sinθ cosθ,            g² = Σ_k (c_k/J)(3 − a_3k²)
        dφ/dt = −Λ [κ/(1+κ) − δ cos2φ] cosθ

    which is [K] (2.1) with μ m_k → c_k/J, d/dτ → d/dt, l → Λ, [K]'s φ = φ + π/2 (hence the
    signs of the δ terms), and [K]'s l_k′ = μ[m_k ν_k − ½(M + m_k)γ l_k] written for any axes
    (for u_k = z_k the k-th component is exactly that). Averaged over the field phases σ_k and
    the precession angle ψ; holds for ε = c_k/(J Λ) ≪ 1, |δ| = O(ε) (the O(εδ) torque terms are
    dropped as in [K]), non-resonant rates, quasi-static slips.

    ``control`` (optional, (k,) rad/s²): the ψ-switching drive V_n = (2/π) ν_n c_n/J of each stator
    (0 for the others), adding −Σ_n V_n √(1 − a_3n²)/Λ to dθ/dt (used by :class:`PsiSwitchingK`,
    which also gives those stators rate 0 here: the ψ-average of ν sign(u_n·e⊥) u_n is zero).
    """
    L = np.asarray(x[0:3], dtype=float)
    th, ph = float(x[3]), float(x[4])
    Ln = float(np.linalg.norm(L))
    y3 = _unit(L)
    Lam = Ln / J
    a3 = axes @ y3
    dL = k21_torque(L, th, J, kappa, axes, c, rates)
    g2 = float(np.sum(c / J * (3.0 - a3 * a3)))
    s, co = math.sin(th), math.cos(th)
    k1 = kappa / (1.0 + kappa)
    dth = delta * Lam * s * math.sin(2 * ph) - 0.25 * k1 * g2 * s * co
    if control is not None and Lam > 0.0:
        dth -= float(np.sum(control * np.sqrt(np.clip(1.0 - a3 * a3, 0.0, 1.0)))) / Lam
    dph = -Lam * (k1 - delta * math.cos(2 * ph)) * co
    return np.array([dL[0], dL[1], dL[2], dth, dph])


@dataclass
class K21Result:
    """Averaged time series: t (s), L (n,3) case frame (N·m·s), theta, phi (rad)."""

    t: np.ndarray
    L: np.ndarray
    theta: np.ndarray
    phi: np.ndarray


class K21Model:
    """[K] (2.1) for a rotor (inertia, k_e) and stators at constant currents and rates (SI).

    ``rotor``: RotorK or [J1, J2, J3] (kg·m²); ``k_e`` (N·m·s/T²); ``stators``: StatorsK.
    """

    def __init__(self, rotor, k_e: float, stators: StatorsK):
        self.rotor = rotor if isinstance(rotor, RotorK) else RotorK.of(rotor)
        self.k_e = float(k_e)
        self.stators = stators
        self.c = self.k_e * stators.B**2  # N·m·s

    @classmethod
    def of_scene(cls, scene) -> "K21Model":
        return cls(RotorK.of(scene.inertia), k_e_of_scene(scene), StatorsK.of_scene(scene))

    @property
    def rate_constants(self) -> np.ndarray:
        """a_k = k_e B_k²/J (1/s), [K]'s μ m_k Ω0."""
        return self.c / self.rotor.J

    def rhs(self, t, x):
        r = self.rotor
        return k21_rhs(t, x, r.J, r.kappa, r.delta, self.stators.axes, self.c, self.stators.rates)

    def equilibrium_L(self, theta: float) -> np.ndarray:
        """[K] (2.1) equilibrium of L at nutation θ (N·m·s, case frame), for mutually orthogonal stator axes:
        L_k* = 2 J c_k ν_k / (γ (C + c_k)),  C = Σ c_k ([K]: l_k* = 2 m_k ν_k/(γ(M + m_k)))."""
        g = gamma_k(theta, self.rotor.kappa)
        C = np.sum(self.c)
        Lk = 2.0 * self.rotor.J * self.c * self.stators.rates / (g * (C + self.c))
        return Lk @ self.stators.axes

    def integrate(self, L0, theta0: float, phi0: float, t, rtol=1e-10, atol=None) -> K21Result:
        """Integrate (2.1) from L0 (N·m·s), θ0, φ0 (rad) and return it at times t (s, increasing, t[0] = 0)."""
        t = np.asarray(t, dtype=float)
        L0 = np.asarray(L0, dtype=float)
        x0 = np.concatenate([L0, [theta0, phi0]])
        if atol is None:
            atol = np.concatenate([np.full(3, 1e-12 * max(np.linalg.norm(L0), 1e-30)), [1e-12, 1e-12]])
        sol = solve_ivp(self.rhs, (t[0], t[-1]), x0, t_eval=t, method="DOP853", rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(sol.message)
        return K21Result(sol.t, sol.y[0:3].T.copy(), sol.y[3].copy(), sol.y[4].copy())


# ----------------------------------------------------------------------------------------
# [K] (2.2): φ-averaged nutation without control
# ----------------------------------------------------------------------------------------
def nutation_k22(theta0, t, inertia, k_e, stators: StatorsK, L=None):
    """[K] (2.2) in SI: θ(t) of the uncontrolled rotor (quasi-static torque, non-resonant stators).

        tanθ(t) = tanθ(0) exp[−¼ κ/(1+κ) ∫0^t g²(t′) dt′],   g² = Σ_k k_e B_k² (3 − a_3k²)/J  (1/s)

    a_3k = y3·u_k (y3 = L/|L|). theta0 (rad, 0 < θ0 < π), t (n,) s increasing from 0,
    inertia [J1, J2, J3] (kg·m², J1 = J2: (2.2) is averaged over φ, so δ = 0 and θ away from π/2
    is where it holds; the δ term of (2.1) is dropped), k_e (N·m·s/T²), stators (StatorsK: the
    rates do not enter); L = direction of the kinetic moment, (3,) constant or (n,3) at the times
    t (e.g. from the full model or :class:`K21Model`); default z3.
    Returns θ(t) (rad) in (0, π): θ → 0 (θ0 < π/2) or π (θ0 > π/2) for κ > 0, → π/2 for κ < 0,
    at the rate ¼ |κ|/(1+κ) g² with 2 Σ a_k ≤ g² ≤ 3 Σ a_k ([K] (2.3)); ``nutation_k22_rate`` gives
    d ln tanθ/dt. The rates of the stators do not enter (they only move L, through a_3k).
    """
    t = np.asarray(t, dtype=float)
    rate = nutation_k22_rate(inertia, k_e, stators, L if L is not None else np.array([0.0, 0.0, 1.0]))
    rate = np.broadcast_to(rate, t.shape).astype(float)
    # trapezoidal ∫ of the rate (exact for constant rate)
    integ = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))]) if t.size > 1 else np.zeros(1)
    E = np.exp(integ)
    return np.arctan2(math.sin(theta0) * E, math.cos(theta0))


def nutation_k22_rate(inertia, k_e, stators: StatorsK, L):
    """d ln tanθ/dt = −¼ κ/(1+κ) g² (1/s) of [K] (2.2) for kinetic-moment direction(s) L ((3,) or (n,3))."""
    r = RotorK.of(inertia)
    L = np.asarray(L, dtype=float)
    y3 = L / np.linalg.norm(L, axis=-1, keepdims=True)
    a3 = y3 @ stators.axes.T
    a = stators.rate_constants(k_e, r.J)
    g2 = np.sum(a * (3.0 - a3 * a3), axis=-1)
    return -0.25 * r.kappa / (1.0 + r.kappa) * g2


# ----------------------------------------------------------------------------------------
# [K] (3.2): transverse decay of L under ψ-switching
# ----------------------------------------------------------------------------------------
def transverse_decay_k32(inertia, k_e, B_spin, B_control, theta=0.0):
    """[K] (3.2) in SI: decay rate (1/s) of the transverse part z = L1 + i L2 of L (case frame),

        dz/dt = −½ (a_m + 3 a_n) γ z,   a_m = k_e B_spin²/J,  a_n = k_e B_control²/J,
        γ = (1 + κ sin²θ)/(1 + κ)

    ([K]: z′ = −½ μ (m + 3n) γ z with μ m = a_m/Ω0, μ n = a_n/Ω0). Spin stator on z3 (field
    B_spin, T), two control stators on z1, z2 with equal fields B_control (T); the control
    drive averages to zero over ψ (ψ-switching), so z decays without turning: the azimuth of L
    is kept. With the control stators at constant rates ν_1, ν_2 instead, the same rate applies to
    z − z* with z* = J(a_n ν_1 + i a_n ν_2)·2/(γ (a_m + 3 a_n)) (the (2.1) equilibrium).
    theta (rad) may be an array; inertia [J1, J2, J3] kg·m², k_e N·m·s/T².
    Holds for ε ≪ 1, non-resonant rates, quasi-static slips, θ slowly varying.
    """
    r = RotorK.of(inertia)
    a_m = k_e * B_spin**2 / r.J
    a_n = k_e * B_control**2 / r.J
    return 0.5 * (a_m + 3.0 * a_n) * gamma_k(np.asarray(theta, dtype=float), r.kappa)


# ----------------------------------------------------------------------------------------
# [K] §3: the ψ-switching law, averaged
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Equilibrium:
    """An equilibrium of (3.4) at θ = π/2 ((3.6)): φ (rad, simulator convention), |L| (N·m·s),
    eigenvalues (1/s) of the (θ, φ) linearisation, kind ('saddle', 'stable focus', ...)."""

    theta: float
    phi: float
    L: float
    eigenvalues: tuple
    kind: str


@dataclass(frozen=True)
class LimitCycle:
    """A cycle of the φ-averaged system (3.8) ((3.9)): θ (rad), |L| (N·m·s), stable?, name."""

    theta: float
    L: float
    stable: bool
    name: str  # 'r+' (nearer the pole) or 'r-' (nearer the equator)


@dataclass
class PsiResult:
    """ψ-switching averaged run: t (s), L (n,) |L| (N·m·s) or (n,3) case frame, theta, phi (rad)."""

    t: np.ndarray
    L: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    t_hit: Optional[float] = None  # time θ reached 0 (or π), s; None if not reached


class PsiSwitchingK:
    """Averaged ψ-switching model of [K] §3 ((3.2)–(3.11)) in SI.

    Spin stator on ``spin_axis`` (default z3) with field B_spin = b I (T) at rate ν0 (rad/s);
    control stators on ``control_axes`` (default z1, z2; physics.md: axes in the z1z2 plane) with
    fields ``B_control`` (T; one value or one per control stator), switched by
    ν_n = ν_n sign(u_n·e⊥) (gyro_ctl.laws.psi_switching, [K] (3.1); ``nu`` rad/s, one value or one
    per control stator, all of one sign). inertia [J1, J2, J3] kg·m², k_e N·m·s/T².

    SI rates (1/s unless stated), a_m = k_e B_spin²/J, a_n = k_e B_control²/J; for [K]'s case (z1, z2,
    equal fields, equal |ν|) they are:

    * ``W0`` = (a_m + a_n)/(1+κ)          = μ ω0 Ω0   ([K] ω0 = (m+n)/(1+κ), time τ' = ω0 τ)
    * ``Lam0`` = a_m ν0 (1+κ)/(a_m + a_n) (rad/s)  — Λ = |L|/J at θ = 0 on the ellipsoid (3.5);
      [K]'s k = μΛ/W0 and ω = μ Lam0/W0 (k and ω carry the factor μ and τ' = W0 t/μ: μ drops out)
    * ``lam`` = ½ (a_m + 3a_n)/(a_m + a_n)  = [K] λ (dimensionless); ``q`` = a_n/a_m = [K] n/m
    * ``V`` = (4/π) a_n ν (rad/s²)          = [K] v W0²/μ  ([K] v = 4nν/(π ω0²))

    In general (any control axes ⟂ the spin axis, any fields and rates) W0 = ½ Σ_k a_k(1 + a_3k²)/(1+κ),
    λ = ¼ Σ_k a_k (3 − a_3k²)/((1+κ) W0), V = (2/π) Σ_n ν_n a_n √(1 − a_3n²), a_3k = u_k·u_spin.

    Reduced equations ((3.4), |z| ≪ 1, L along the spin axis; Λ = |L|/J):

        dΛ/dt = a_m ν0 − W0 (1 + κ sin²θ) Λ
        dθ/dt = δ Λ sinθ sin2φ − [V sign(sinθ) + κ λ W0 Λ sinθ cosθ]/Λ
        dφ/dt = −Λ [κ/(1+κ) − δ cos2φ] cosθ

    ([K] (3.4) divided by k: the printed "θ′ = −μ(δk² sinθ sin2φ + v sign sinθ + κλk sinθ cosθ)" is
    k θ′, as (3.3) is l θ′ and (3.8) prints "kθ′"; signs of δ for the simulator's φ = φ_K − π/2).

    Holds when the stator torques add ([K] §1 assumes it): the control fields must not be resonant
    with each other. At equal |ν_1| = |ν_2| the z1–z2 cross torque does not average out under
    ψ-switching (docs/averaged_k.md §4): give the control stators rates far apart
    (|ν_1| − |ν_2| ≫ |L|/J) and much faster than the precession (|ν_n| ≫ |L|/J).
    """

    def __init__(self, inertia, k_e, B_spin, nu0, B_control, nu, control_axes=((1.0, 0, 0), (0, 1.0, 0)),
                 spin_axis=(0, 0, 1.0)):
        self.rotor = inertia if isinstance(inertia, RotorK) else RotorK.of(inertia)
        self.k_e = float(k_e)
        self.B_spin, self.nu0 = float(B_spin), float(nu0)
        ca = np.asarray(control_axes, dtype=float).reshape(-1, 3)
        nc = ca.shape[0]
        self.B_c = np.broadcast_to(np.asarray(B_control, dtype=float), (nc,)).astype(float)
        self.nus = np.broadcast_to(np.asarray(nu, dtype=float), (nc,)).astype(float)
        if len({math.copysign(1.0, v) for v in self.nus if v != 0}) > 1:
            raise ValueError(f"nu = {list(self.nus)}: the control rates must share one sign")
        ax = np.vstack([ca, np.asarray(spin_axis, float)])
        self.axes = ax / np.linalg.norm(ax, axis=1, keepdims=True)
        J = self.rotor.J
        self.a_m = self.k_e * self.B_spin**2 / J
        self.a_c = self.k_e * self.B_c**2 / J  # per control stator, 1/s

    @property
    def a_n(self) -> float:
        """Mean control rate constant (1/s): [K]'s μ n Ω0 (n = m1 = m2)."""
        return float(np.mean(self.a_c))

    @property
    def nu(self) -> float:
        """Effective common control rate (rad/s): the ν of [K] giving the same V (mean of ν_n a_n / a_n)."""
        return float(np.sum(self.nus * self.a_c) / np.sum(self.a_c)) if np.sum(self.a_c) > 0 else float(np.mean(self.nus))

    @classmethod
    def of_scene(cls, scene) -> "PsiSwitchingK":
        """From a scene with a psi_switching controller (currents, rates and stators of its params)."""
        p = scene.controller.params
        st = {s.name: s for s in scene.stators}
        sp = st[p.spin_stator]
        cs = [st[n] for n in p.control_stators]
        nus = [p.nu[i] if isinstance(p.nu, list) else p.nu for i in range(len(cs))]
        return cls(scene.inertia, k_e_of_scene(scene), sp.coil_constant * p.spin_current, p.spin_rate,
                   [s.coil_constant * p.control_current for s in cs], nus,
                   control_axes=[s.axis for s in cs], spin_axis=sp.axis)

    # --- [K]'s rates and symbols ---------------------------------------------------------
    @property
    def kappa(self) -> float:
        return self.rotor.kappa

    @property
    def _a(self) -> np.ndarray:
        return np.concatenate([self.a_c, [self.a_m]])

    @property
    def _a3(self) -> np.ndarray:
        return self.axes @ self.axes[-1]

    @property
    def W0(self) -> float:
        """(1/s) ½ Σ_k a_k (1 + a_3k²)/(1+κ) at L ∥ spin axis; = (a_m + a_n)/(1+κ) = μ ω0 Ω0 of [K]."""
        return 0.5 * float(np.sum(self._a * (1 + self._a3**2))) / (1.0 + self.kappa)

    @property
    def Lam0(self) -> float:
        """Λ = |L|/J (rad/s) on the ellipsoid at θ = 0: a_m ν0/W0 ([K]: k = ω there)."""
        return self.a_m * self.nu0 / self.W0

    @property
    def lam(self) -> float:
        """[K] λ = ½(m + 3n)/(m + n): ¼ g²/((1+κ) W0), g² = Σ a_k (3 − a_3k²) (dimensionless)."""
        return 0.25 * float(np.sum(self._a * (3 - self._a3**2))) / ((1.0 + self.kappa) * self.W0)

    @property
    def q(self) -> float:
        return self.a_n / self.a_m

    @property
    def V(self) -> float:
        """(rad/s²) (2/π) Σ_n ν_n a_n √(1 − a_3n²); = 4 a_n ν/π for z1, z2 = [K]'s v W0²/μ."""
        a3 = self._a3[:-1]
        return 2.0 / math.pi * float(np.sum(self.nus * self.a_c * np.sqrt(np.clip(1 - a3**2, 0, 1))))

    def symbols(self, Omega0: Optional[float] = None, L: Optional[float] = None) -> dict:
        """[K]'s dimensionless symbols for a chosen Ω0 (rad/s, default |ν0|) and M0 = max(c_m, c_n) Ω0.

        Returns μ, m, n, q, κ, δ_K (= δ/μ), ω0, ω, λ, v, p, s and, if |L| (N·m·s) is given, l and k.
        """
        Om = abs(self.nu0) if Omega0 is None else float(Omega0)
        J = self.rotor.J
        cm, cn = self.a_m * J, self.a_n * J  # n: mean of the control stators
        M0 = max(cm, cn) * Om
        mu = M0 / (J * Om**2)
        m, n = cm * Om / M0, cn * Om / M0
        w0 = (m + n) / (1 + self.kappa)
        nu0, nu = self.nu0 / Om, self.nu / Om
        out = dict(mu=mu, m=m, n=n, q=n / m, kappa=self.kappa, delta_K=self.rotor.delta / mu, omega0=w0,
                   omega=m * nu0 / w0**2, lam=self.lam, v=4 * n * nu / (math.pi * w0**2),
                   p=self.p, s=self.s)
        if L is not None:
            out["l"] = L / (J * Om)
            out["k"] = out["l"] / w0
        return out

    # --- the averaged equations --------------------------------------------------------------
    def rhs_reduced(self, t, x):
        """(3.4) in SI, x = (|L| N·m·s, θ, φ); see the class docstring."""
        J, kap, dl = self.rotor.J, self.kappa, self.rotor.delta
        L, th, ph = x
        Lam = L / J
        s, c = math.sin(th), math.cos(th)
        sg = 1.0 if s > 0 else (-1.0 if s < 0 else 0.0)
        dL = J * (self.a_m * self.nu0 - self.W0 * (1.0 + kap * s * s) * Lam)
        dth = dl * Lam * s * math.sin(2 * ph) - (self.V * sg + kap * self.lam * self.W0 * Lam * s * c) / Lam
        dph = -Lam * (kap / (1 + kap) - dl * math.cos(2 * ph)) * c
        return np.array([dL, dth, dph])

    def rhs_vector(self, t, x):
        """(3.2)–(3.3) in SI for any direction of L, x = (L1, L2, L3 case N·m·s, θ, φ).

        dL/dt from (2.1) with the control stators' drive averaged out (⟨ν_n⟩ = 0 over ψ):
        dL/dt = c_m ν0 u_s − ½ γΛ Σ_k c_k (y3 + a_3k u_k); dθ/dt gains −(2/π) Σ_n ν_n a_n √(1 − a_3n²)/Λ,
        the exact ψ-average of −ν_n sign(u_n·e⊥) c_n (u_n·e⊥)/|L| (printed (3.3): 2nν(1 + a_33²)/π,
        see docs/averaged_k.md §3; both are 4nν/π at a_33 = 1, the case (3.4) uses).
        """
        r = self.rotor
        c = self.k_e * np.concatenate([self.B_c, [self.B_spin]]) ** 2  # N·m·s
        rates = np.concatenate([np.zeros(self.B_c.size), [self.nu0]])
        ctrl = np.concatenate([2.0 / math.pi * self.nus * c[:-1], [0.0]]) / r.J  # V_n, rad/s²
        return k21_rhs(t, x, r.J, r.kappa, r.delta, self.axes, c, rates, control=ctrl)

    # --- geometry of the phase portrait ------------------------------------------------------
    def ellipsoid_L(self, theta):
        """(3.5): the finite motion lies on |L| = J Lam0/(1 + κ sin²θ) (N·m·s), the nullcline of dΛ/dt
        ([K]: k = ω/(1 + κ sin²θ); in coordinates (√k, θ, φ) an ellipsoid of revolution with semi-axes
        √(ω/(1+κ)) (equator) and √ω (pole))."""
        s = np.sin(theta)
        return self.rotor.J * self.Lam0 / (1.0 + self.kappa * s * s)

    @property
    def s(self) -> float:
        """(3.6) [K]'s s = −v[(1+κ)/ω]²/δ = −V/(δ Λ*²), Λ* = Lam0/(1+κ) (θ = π/2); ±inf if δ = 0."""
        dl = self.rotor.delta
        Ls = self.Lam0 / (1.0 + self.kappa)
        if dl == 0.0:
            return math.copysign(math.inf, -self.V) if self.V != 0 else 0.0
        return -self.V / (dl * Ls * Ls)

    def equilibria(self) -> list:
        """(3.6)–(3.7): equilibria at θ = π/2, |L|* = J Lam0/(1+κ), sin2φ*_K = s; they exist iff |s| ≤ 1
        (⇔ |δ| ≥ (4/π) n|ν| [(m+n)/(m ν0)]²). Returned in the simulator's φ (φ = φ_K − π/2, so
        sin2φ* = −s), one per root in [0, π) × {0, π} (four for |s| < 1), with the eigenvalues of the
        (θ, φ) linearisation of :meth:`rhs_reduced` (|L| decouples at θ = π/2 and is stable).
        [K]: saddles where cos2φ_K* < 0, foci (stable iff κ < 0) where cos2φ_K* > 0 — true when
        δκ > 0; in general a saddle iff δ κ cos2φ_K* < 0."""
        s = self.s
        if not (abs(s) <= 1.0):
            return []
        Ls = self.rotor.J * self.Lam0 / (1.0 + self.kappa)
        base = 0.5 * math.asin(-s)  # simulator φ: sin2φ = −s
        roots = sorted({round(v % math.pi, 15) for v in (base, math.pi / 2 - base)})
        out = []
        for r0 in roots:
            for ph in (r0, r0 + math.pi):
                x = np.array([Ls, math.pi / 2, ph])
                A = np.zeros((2, 2))
                for j, h in ((1, 1e-7), (2, 1e-7)):
                    e = np.zeros(3)
                    e[j] = h
                    A[:, j - 1] = (self.rhs_reduced(0, x + e) - self.rhs_reduced(0, x - e))[1:] / (2 * h)
                ev = np.linalg.eigvals(A)
                out.append(Equilibrium(math.pi / 2, ph, Ls, tuple(ev), _kind(ev)))
        return out

    @property
    def p(self) -> float:
        """(3.10) p = v/(κλω) = V/(κ λ a_m ν0) (dimensionless; ±inf for κ = 0)."""
        d = self.kappa * self.lam * self.a_m * self.nu0
        if d == 0.0:
            return math.copysign(math.inf, self.V) if self.V != 0 else 0.0
        return self.V / d

    @property
    def p_star_sq(self) -> float:
        """(3.10) corrected: cycles exist iff p² ≤ p*² = 1/(4(1+κ)) (printed "1/(1+κ)^{-1}" is OCR damage)."""
        return 0.25 / (1.0 + self.kappa)

    def cycles_exist(self) -> bool:
        """(3.10): p² ≤ 1/(4(1+κ)) ⇔ 16 q(1+q)|ν/ν0| √(1+κ) ≤ π|κ|(1+3q)."""
        return self.p**2 <= self.p_star_sq

    def limit_cycles(self) -> list:
        """(3.9): cycles of the φ-averaged system (3.8) (θ ≠ π/2, stationary θ, |L|), with stability.

        cos²θ = [1 + 2κ(1+κ)p² ± D]/(2(1 + κ²p²)),  D = √(1 − 4(1+κ)p²),  cosθ has the sign of −p;
        |L| = J Lam0 (2 + κ ± κ D)/(2(1+κ)) — the printed k± lacks the factor κ before the root
        (it must give k⁺ ≈ ω, k₋ ≈ ω/(1+κ) as [K]'s own small-p forms do). Stability from the
        Jacobian of (3.8) in SI ([K]: r⁺ stable for κ > 0, r₋ for κ < 0)."""
        if not self.cycles_exist() or not math.isfinite(self.p):
            return []
        p, kap = self.p, self.kappa
        D = math.sqrt(max(0.0, 1.0 - 4.0 * (1 + kap) * p * p))
        out = []
        for sgn, name in ((1.0, "r+"), (-1.0, "r-")):
            x2 = (1.0 + 2 * kap * (1 + kap) * p * p + sgn * D) / (2.0 * (1.0 + kap * kap * p * p))
            c = -math.copysign(math.sqrt(min(max(x2, 0.0), 1.0)), p)
            th = math.acos(c)
            L = self.rotor.J * self.Lam0 * (2 + kap + sgn * kap * D) / (2 * (1 + kap))
            A = np.zeros((2, 2))
            x = np.array([L, th])
            for j, h in ((0, 1e-7 * L), (1, 1e-7)):
                e = np.zeros(2)
                e[j] = h
                A[:, j] = (self._rhs_phi_avg(x + e) - self._rhs_phi_avg(x - e)) / (2 * h)
            ev = np.linalg.eigvals(A)
            out.append(LimitCycle(th, L, bool(np.all(ev.real < 0)), name))
        return out

    def _rhs_phi_avg(self, x):
        """(3.8) in SI, x = (|L|, θ): the φ-average of (3.4) for 0 < θ < π."""
        J, kap = self.rotor.J, self.kappa
        L, th = x
        Lam = L / J
        s, c = math.sin(th), math.cos(th)
        return np.array([J * (self.a_m * self.nu0 - self.W0 * (1 + kap * s * s) * Lam),
                         -(self.V + kap * self.lam * self.W0 * Lam * s * c) / Lam])

    def polhode_Q(self, theta, phi):
        """(3.11): after the fields are switched off, Q = [κ/(1+κ) − δ cos2φ] sin²θ is constant
        (simulator φ; [K] writes +μδ cos2φ_K). Dimensionless."""
        return (self.kappa / (1 + self.kappa) - self.rotor.delta * np.cos(2 * np.asarray(phi))) * np.sin(theta) ** 2

    # --- integration ------------------------------------------------------------------------
    def integrate(self, theta0, t, L0=None, phi0=0.0, vector=False, L_direction=(0, 0, 1.0), rtol=1e-10):
        """Integrate from θ0 (rad), |L0| (N·m·s; default on the ellipsoid (3.5)), φ0 to the times t (s).

        ``vector=False``: (3.4) (L along the spin axis); ``vector=True``: (3.2)–(3.3) with L =
        |L0| L_direction. θ stops at 0 (π) when it gets there (the finite-time approach of [K]: the
        sign term makes θ = 0 an attracting sliding state); the time is ``t_hit``.
        """
        t = np.asarray(t, dtype=float)
        if L0 is None:
            L0 = float(self.ellipsoid_L(theta0))
        if vector:
            d = np.asarray(L_direction, dtype=float)
            x0 = np.concatenate([L0 * d / np.linalg.norm(d), [theta0, phi0]])
            f, ith = self.rhs_vector, 3
        else:
            x0 = np.array([L0, theta0, phi0])
            f, ith = self.rhs_reduced, 1

        def hit(tt, x):
            return math.sin(x[ith]) - 1e-12 if 0 < x[ith] < math.pi else -1.0

        hit.terminal = True
        hit.direction = -1
        sol = solve_ivp(f, (t[0], t[-1]), x0, method="DOP853", rtol=rtol, atol=1e-13 * np.maximum(np.abs(x0), 1e-3),
                        events=hit, dense_output=True)
        if not sol.success:
            raise RuntimeError(sol.message)
        t_hit = float(sol.t_events[0][0]) if sol.t_events[0].size else None
        X = np.empty((t.size, x0.size))
        inside = t <= sol.t[-1]
        X[inside] = sol.sol(t[inside]).T
        if not np.all(inside):  # after the hit: θ stays at 0 (π), |L| relaxes with θ fixed
            xe = sol.y[:, -1].copy()
            xe[ith] = 0.0 if xe[ith] < math.pi / 2 else math.pi

            def g(tt, x):
                y = np.concatenate([x, [xe[ith], xe[ith + 1]]]) if vector else np.array([x[0], xe[1], xe[2]])
                return f(tt, y)[: (3 if vector else 1)]

            n = 3 if vector else 1
            sol2 = solve_ivp(g, (sol.t[-1], t[-1]), xe[:n], method="DOP853", rtol=rtol, dense_output=True)
            X[~inside, :n] = sol2.sol(t[~inside]).T
            X[~inside, n:] = xe[n:]
        if vector:
            return PsiResult(t, X[:, 0:3], X[:, 3], X[:, 4], t_hit)
        return PsiResult(t, X[:, 0], X[:, 1], X[:, 2], t_hit)

    def time_to_theta(self, theta0, theta_target, L0=None, phi0=0.0, t_max=None, vector=False,
                      L_direction=(0, 0, 1.0)) -> float:
        """Time (s) for θ to go from θ0 to θ_target (rad; below θ0 for ν > 0, above for ν < 0) in the
        averaged model; inf if it is not reached within t_max (default 100/W0)."""
        if L0 is None:
            L0 = float(self.ellipsoid_L(theta0))
        t_max = 100.0 / self.W0 if t_max is None else float(t_max)
        down = theta_target < theta0
        ith = 3 if vector else 1
        if vector:
            d = np.asarray(L_direction, dtype=float)
            x0 = np.concatenate([L0 * d / np.linalg.norm(d), [theta0, phi0]])
            f = self.rhs_vector
        else:
            x0 = np.array([L0, theta0, phi0])
            f = self.rhs_reduced

        def ev(tt, x):
            return x[ith] - theta_target

        ev.terminal = True
        ev.direction = -1 if down else 1
        sol = solve_ivp(f, (0.0, t_max), x0, method="DOP853", rtol=1e-11, atol=1e-14 * np.maximum(np.abs(x0), 1e-3),
                        events=ev)
        return float(sol.t_events[0][0]) if sol.t_events[0].size else math.inf


def _kind(ev) -> str:
    ev = np.asarray(ev)
    re, im = ev.real, ev.imag
    if np.all(np.abs(ev) == 0):
        return "degenerate"
    if re[0] * re[1] < 0 and np.all(im == 0):
        return "saddle"
    stab = "stable" if np.all(re < 0) else ("unstable" if np.all(re > 0) else "center")
    if stab == "center":
        return "center"
    return f"{stab} {'focus' if np.any(im != 0) else 'node'}"


# ----------------------------------------------------------------------------------------
# the brief's function-style API
# ----------------------------------------------------------------------------------------
def psi_switching_averaged(theta0, t, inertia, k_e, B_spin, nu0, B_control, nu, L0=None, phi0=0.0,
                           vector=False, **kw) -> PsiResult:
    """Averaged ψ-switching model (3.4) (or (3.2)–(3.3) with ``vector=True``) integrated over t (s).

    inertia [J1, J2, J3] kg·m²; k_e N·m·s/T²; B_spin, B_control field amplitudes b·I (T) of the
    spin stator (z3, rate ν0 rad/s) and of each control stator (z1, z2, switched ±ν rad/s);
    θ0, φ0 rad; L0 = |L| N·m·s (default on the ellipsoid (3.5)). Returns :class:`PsiResult`.
    See :class:`PsiSwitchingK` for the equations and their SI form.
    """
    m = PsiSwitchingK(inertia, k_e, B_spin, nu0, B_control, nu, **kw)
    return m.integrate(theta0, t, L0=L0, phi0=phi0, vector=vector)


def time_to_theta(theta0, theta_target, inertia, k_e, B_spin, nu0, B_control, nu, L0=None, phi0=0.0,
                  vector=False, **kw) -> float:
    """Predicted time (s) for θ to fall from θ0 to θ_target (or rise, for ν < 0) under ψ-switching,
    from the averaged model (3.4) in SI (see :class:`PsiSwitchingK`)."""
    m = PsiSwitchingK(inertia, k_e, B_spin, nu0, B_control, nu, **kw)
    return m.time_to_theta(theta0, theta_target, L0=L0, phi0=phi0, vector=vector)
