"""Averaged (slow) equations of [M] §3 (Martynenko; docs/physics.md, Bibliography) for any penetration depth, in SI.

An axisymmetric rotor (J1 = J2, polar axis x3) with a homogeneous spherical conductor of any
thickness in one of the three uniform fields of [M]:

* constant    B = B0 z3                        [M] (3.4)  -> averaged equations (3.6)
* pulsating   B = B0 sin(ωt) z3                [M] (3.13) -> (3.14) (+ the first integral (3.7))
* rotating    B = B0 (cos ωt, sin ωt, 0)       [M] (3.16) -> (3.17)   (ω signed: < 0 turns the other way)

Slow variables (physics.md §1, the simulator's conventions, which are [M]'s (2.2) exactly):
|L| (N·m·s), ρ = polar angle of L from z3, σ = azimuth of L, θ = nutation angle (cos θ = x3·L/|L|),
all in rad. Fast phases: the precession angle ψ (rate l = |L|/J1), the proper rotation φ
(rate −ν, ν = l κ cosθ/(1+κ), κ = (J3 − J1)/J1) and the field phase ωt.

SI translation of [M]'s symbols (docs/averaged_m.md §1 for the derivation):

* polarizability: α = r2³ ĝ/2 (ĝ of :mod:`gyro_sim.conductor`, fields ∝ e^{−iωt}); the Gaussian
  torque α H² becomes (4π/μ0) α B² = S ĝ B², S = 2π r2³/μ0 (``moment_scale``). Here
  **a(ω) = S ĝ(ω)** (A·m²/T), a′ = Re a, a″ = Im a (a′ even, a″ odd in ω);
* [M]'s ε1 H² α (ε1 = εH²/I1, time in units T_n = I1/L_*) becomes B0² a/J1 with time in s;
  l = |L|/J1 (rad/s), ω and ν in rad/s; so "l x′ = ε1 (...)" reads "|L| dx/dt = B0² (...)".

The printed right-hand sides, read this way, equal the average of the instantaneous torque of
the linear (steady-state) eddy response over the fast phases to round-off (checked by
:func:`torus_average_rates`, an independent numerical average, and against the full model;
test/test_averaged_m.py). The OCR damage is in the left-hand sides only ("l θ̈" for l′ in (3.14)
and (3.17), dots lost or doubled, one bracket of (3.17) mismatched); see docs/averaged_m.md.

Validity (``region``): μ ≪ 1 where μ = N* J1/|L|² is [M]'s ε = T_n/T_p (N* = S B0² max|ĝ| over the
combination frequencies, the size of the instantaneous torque; fidelity.py's μ = |N| J1/|L|² with
the averaged torque is the same order), the torque harmonics non-resonant (their slowest frequency
f_min, see :meth:`AveragedM.torque_frequencies`, enters as μ_eff = μ l/f_min), and the eddy-current
switch-on transient short against the slow time (μ l τ1 ≪ 1). No condition on θ: the case-frame
torque of an isotropic conductor on an axisymmetric body does not depend on φ (checked), so
the φ-average needs no non-resonance, unlike [K]'s averaged equations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from scipy.integrate import solve_ivp

from gyro_sim.physics.closed_forms import small_theta_nutation_rate, thin_shell_nutation_window
from gyro_sim.physics.conductor import conductor_model, g_shell, g_solid_sphere, g_thin_shell
from gyro_sim.physics.constants import MU0
from gyro_sim.scenes.scene import Scene, SceneError

__all__ = [
    "MU_MAX",
    "AveragedM",
    "ConstantFieldM",
    "PulsatingFieldM",
    "RotatingFieldM",
    "AveragedMResult",
    "averaged_m_model",
    "response_of_scene",
    "torus_average_rates",
    "slow_variables",
    "errors_against_full",
    "rates_constant",
    "rates_pulsating",
    "rates_rotating",
    "thin_shell_l_rate_polynomial",
    "thin_shell_l_star",
]

#: default bound on μ_eff accepted by :meth:`AveragedM.region` (errors measured against the full
#: model are 0.01–7.7 μ, docs/averaged_m.md §5; fidelity.py's hybrid uses the stricter 1e-3)
MU_MAX = 1e-2


# ------------------------------------------------------------------------------------------------
# the printed right-hand sides, SI (a1 = a', a2 = a'' callables of ω in rad/s, A·m²/T)
# ------------------------------------------------------------------------------------------------
def _nu(l, kappa, c):
    """[M] (2.3): ν = l κ cosθ/(1 + κ), the rate of −φ (rad/s)."""
    return l * kappa * c / (1.0 + kappa)


def rates_constant(a1: Callable, a2: Callable, B0, J1, J3, L, rho, theta) -> np.ndarray:
    """[M] (3.6) in SI: (d|L|/dt, dρ/dt, dσ/dt, dθ/dt) in a constant field B0 z3.

        d|L|/dt  = −¼ B0² sin²ρ X,   X = (1−c)² a″(l+ν) + (1+c)² a″(l−ν) + 2 s² a″(l)
        |L| ρ′   = −¼ B0² sinρ cosρ X
        |L| σ′   =  ¼ B0² cosρ {(1−c)² a′(l+ν) + (1+c)² a′(l−ν) + 2 s² [a′(l) − 2 a′(−ν)]}
        |L| θ′   = −¼ B0² s {sin²ρ [(1−c) a″(l+ν) − (1+c) a″(l−ν) + 2c a″(l)] + 4 cos²ρ a″(ν)}

    c = cosθ, s = sinθ, l = |L|/J1, ν = l κ c/(1+κ). B0 (T), J (kg·m²), L = |L| (N·m·s), angles rad.
    """
    l = L / J1
    kap = J3 / J1 - 1.0
    c, s = math.cos(theta), math.sin(theta)
    sr, cr = math.sin(rho), math.cos(rho)
    nu = _nu(l, kap, c)
    k = 0.25 * B0 * B0
    # [M] (3.6)
    X = (1 - c) ** 2 * a2(l + nu) + (1 + c) ** 2 * a2(l - nu) + 2 * s * s * a2(l)
    dL = -k * sr * sr * X
    drho = -k * sr * cr * X / L
    dsig = k * cr * ((1 - c) ** 2 * a1(l + nu) + (1 + c) ** 2 * a1(l - nu)
                     + 2 * s * s * (a1(l) - 2 * a1(-nu))) / L
    dth = -k * s * (sr * sr * ((1 - c) * a2(l + nu) - (1 + c) * a2(l - nu) + 2 * c * a2(l))
                    + 4 * cr * cr * a2(nu)) / L
    return np.array([dL, drho, dsig, dth])


def rates_pulsating(a1: Callable, a2: Callable, B0, omega, J1, J3, L, rho, theta) -> np.ndarray:
    """[M] (3.14) in SI (field B0 sin(ωt) z3); dρ/dt from the first integral (3.7), |L| cosρ = const.

        d|L|/dt = −(B0²/16) sin²ρ X,
            X = (1−c)² [a″(l+ν−ω) + a″(l+ν+ω)] + (1+c)² [a″(l−ν−ω) + a″(l−ν+ω)] + 2s² [a″(l−ω) + a″(l+ω)]
        |L| ρ′ = −(B0²/16) sinρ cosρ X                                            (from (3.7))
        |L| σ′ = (B0²/16) cosρ {−4s² [a′(−ν−ω) + a′(−ν+ω)] − 8c² a′(ω) + (1−c)² [a′(l+ν−ω) + a′(l+ν+ω)]
                               + (1+c)² [a′(l−ν−ω) + a′(l−ν+ω)] + 2s² [a′(l+ω) + a′(l−ω)]}
        |L| θ′ = (B0²/16) s {sin²ρ [−(1−c)(a″(l+ν−ω) + a″(l+ν+ω)) + (1+c)(a″(l−ν−ω) + a″(l−ν+ω))
                                   − 2c (a″(l−ω) + a″(l+ω))] + 4 cos²ρ [a″(−ν−ω) + a″(−ν+ω)]}

    (printed with "l θ̈" for l′ and 4 ctg²ρ inside the sin²ρ bracket; written here without the
    ctg so that ρ = 0 is regular). ω (rad/s) is the pulsation rate; the result is even in ω.
    """
    l = L / J1
    kap = J3 / J1 - 1.0
    c, s = math.cos(theta), math.sin(theta)
    sr, cr = math.sin(rho), math.cos(rho)
    nu = _nu(l, kap, c)
    w = omega
    k = B0 * B0 / 16.0
    # [M] (3.14)
    X = ((1 - c) ** 2 * (a2(l + nu - w) + a2(l + nu + w)) + (1 + c) ** 2 * (a2(l - nu - w) + a2(l - nu + w))
         + 2 * s * s * (a2(l - w) + a2(l + w)))
    dL = -k * sr * sr * X
    drho = -k * sr * cr * X / L  # [M] (3.7)
    dsig = k * cr * (-4 * s * s * (a1(-nu - w) + a1(-nu + w)) - 8 * c * c * a1(w)
                     + (1 - c) ** 2 * (a1(l + nu - w) + a1(l + nu + w))
                     + (1 + c) ** 2 * (a1(l - nu - w) + a1(l - nu + w))
                     + 2 * s * s * (a1(l + w) + a1(l - w))) / L
    dth = k * s * (sr * sr * (-(1 - c) * (a2(l + nu - w) + a2(l + nu + w))
                              + (1 + c) * (a2(l - nu - w) + a2(l - nu + w))
                              - 2 * c * (a2(l - w) + a2(l + w)))
                   + 4 * cr * cr * (a2(-nu - w) + a2(-nu + w))) / L
    return np.array([dL, drho, dsig, dth])


def rates_rotating(a1: Callable, a2: Callable, B0, omega, J1, J3, L, rho, theta) -> np.ndarray:
    """[M] (3.17) in SI (field B0 (cos ωt, sin ωt, 0), ω signed), with p = 1 + cosρ, m = 1 − cosρ:

        d|L|/dt = (B0²/16) {−(1−c)² [m² a″(l+ν+ω) + p² a″(l+ν−ω)] − (1+c)² [m² a″(l−ν+ω) + p² a″(l−ν−ω)]
                            − 2s² [p² a″(l−ω) + m² a″(l+ω)]}
        |L| ρ′ = (B0²/16) sinρ {(1−c)² [p a″(l+ν−ω) − m a″(l+ν+ω)] + (1+c)² [p a″(l−ν−ω) − m a″(l−ν+ω)]
                                + 2s² [p a″(l−ω) − m a″(l+ω) + 2a″(−ν−ω) − 2a″(−ν+ω)] − 8c² a″(ω)}
        |L| σ′ = (B0²/16) {(1−c)² [m a′(l+ν+ω) − p a′(l+ν−ω)] + (1+c)² [m a′(l−ν+ω) − p a′(l−ν−ω)]
                           + 2s² [2cosρ a′(−ν−ω) + 2cosρ a′(−ν+ω) − p a′(l−ω) + m a′(l+ω)] + 8 cosρ c² a′(ω)}
        |L| θ′ = (B0²/16) s {−(1−c) [p² a″(l+ν−ω) + m² a″(l+ν+ω)] + (1+c) [p² a″(l−ν−ω) + m² a″(l−ν+ω)]
                             + 4 sin²ρ [a″(−ν−ω) + a″(−ν+ω)] − 2c [p² a″(l−ω) + m² a″(l+ω)]}

    (printed with "l θ̈" for l′ and a "2 sin²ϑ (… ]" bracket mismatch in the σ line).
    """
    l = L / J1
    kap = J3 / J1 - 1.0
    c, s = math.cos(theta), math.sin(theta)
    sr, cr = math.sin(rho), math.cos(rho)
    nu = _nu(l, kap, c)
    w = omega
    p, m = 1.0 + cr, 1.0 - cr
    k = B0 * B0 / 16.0
    # [M] (3.17)
    dL = k * (-(1 - c) ** 2 * (m * m * a2(l + nu + w) + p * p * a2(l + nu - w))
              - (1 + c) ** 2 * (m * m * a2(l - nu + w) + p * p * a2(l - nu - w))
              - 2 * s * s * (p * p * a2(l - w) + m * m * a2(l + w)))
    drho = k * sr * ((1 - c) ** 2 * (p * a2(l + nu - w) - m * a2(l + nu + w))
                     + (1 + c) ** 2 * (p * a2(l - nu - w) - m * a2(l - nu + w))
                     + 2 * s * s * (p * a2(l - w) - m * a2(l + w) + 2 * a2(-nu - w) - 2 * a2(-nu + w))
                     - 8 * c * c * a2(w)) / L
    dsig = k * ((1 - c) ** 2 * (m * a1(l + nu + w) - p * a1(l + nu - w))
                + (1 + c) ** 2 * (m * a1(l - nu + w) - p * a1(l - nu - w))
                + 2 * s * s * (2 * cr * a1(-nu - w) + 2 * cr * a1(-nu + w) - p * a1(l - w) + m * a1(l + w))
                + 8 * cr * c * c * a1(w)) / L
    dth = k * s * (-(1 - c) * (p * p * a2(l + nu - w) + m * m * a2(l + nu + w))
                   + (1 + c) * (p * p * a2(l - nu - w) + m * m * a2(l - nu + w))
                   + 4 * sr * sr * (a2(-nu - w) + a2(-nu + w))
                   - 2 * c * (p * p * a2(l - w) + m * m * a2(l + w))) / L
    return np.array([dL, drho, dsig, dth])


# ------------------------------------------------------------------------------------------------
# conductor response of a scene
# ------------------------------------------------------------------------------------------------
def response_of_scene(scene: Scene, exact: bool = False):
    """(S, ĝ, τ1) of a scene's rotor: S = 2π r2³/μ0 (A·m²/T), ĝ callable (ω rad/s → complex),
    τ1 the slowest eddy time constant (s).

    By default ĝ is the one the full model integrates (``torque_model: lag`` → the modal model with
    the modes (and tail term) a run of the scene chooses, gyro_sim.accuracy.scene_conductor; ``quasi_static`` → iωτ_eff, [K] (1.2)); ``exact=True``
    takes the closed forms [M] (2.13)–(2.15) of :mod:`gyro_sim.conductor` instead.
    """
    c = scene.rotor.conductor
    if c is None or scene.torque_model == "none":
        raise SceneError("averaged_m: the [M] equations need a conducting rotor with torque_model lag or quasi_static")
    if scene.torque_model == "lag":  # the modes (and tail) a run of the scene integrates (gyro_sim.accuracy)
        from gyro_sim.scenes.accuracy import scene_conductor

        cond = scene_conductor(scene, quiet=True)
    else:
        cond = conductor_model(c.kind, c.outer_radius, c.conductivity, thickness=c.thickness)
    S = float(cond.moment_scale)
    tau1 = float(np.max(cond.tau)) if cond.tau.size else float(cond.tau_eff)
    if exact:
        r2, sg = c.outer_radius, c.conductivity
        if c.kind == "thin_shell":
            g = lambda w: g_thin_shell(w, r2, c.thickness, sg)  # noqa: E731  [M] (2.15)
        elif c.kind == "solid_sphere":
            g = lambda w: g_solid_sphere(w, r2, sg)  # noqa: E731  [M] (2.14)
        else:
            g = lambda w: g_shell(w, r2 - c.thickness, r2, sg)  # noqa: E731  [M] (2.13) corrected
    elif scene.torque_model == "quasi_static":
        te = float(cond.tau_eff)
        g = lambda w: 1j * np.asarray(w, dtype=float) * te  # noqa: E731  [K] (1.2)
        tau1 = 0.0
    else:
        g = cond.g
    return S, g, tau1


# ------------------------------------------------------------------------------------------------
# the models
# ------------------------------------------------------------------------------------------------
@dataclass
class AveragedMResult:
    """Averaged time series (SI): t (s), L = |L| (N·m·s), rho, sigma, theta (rad)."""

    t: np.ndarray
    L: np.ndarray
    rho: np.ndarray
    sigma: np.ndarray
    theta: np.ndarray
    nfev: int = 0
    model: Optional["AveragedM"] = None

    @property
    def l_cos_rho(self) -> np.ndarray:
        """|L| cos ρ = L·z3 (N·m·s): constant in constant and pulsating fields, [M] (3.7)."""
        return self.L * np.cos(self.rho)


@dataclass
class AveragedM:
    """Common part of the three [M] models. Use :func:`averaged_m_model` or ``<Kind>FieldM.from_scene``.

    J1, J2, J3 (kg·m²; the equations need J1 = J2, :meth:`region` says so otherwise), B0 field
    amplitude (T), omega field rate (rad/s; 0 for the constant field), S = 2π r2³/μ0 (A·m²/T),
    g = ĝ(ω) callable, tau1 slowest eddy time constant (s), y0 initial slow state (|L|, ρ, σ, θ).
    """

    J1: float
    J2: float
    J3: float
    B0: float
    omega: float
    S: float
    g: Callable
    tau1: float = 0.0
    y0: Optional[np.ndarray] = None
    scene: Optional[Scene] = field(default=None, repr=False)

    kind = "?"

    # --- response -------------------------------------------------------------------------------
    @property
    def kappa(self) -> float:
        """κ = (J3 − J1)/J1 ([M] (2.3))."""
        return self.J3 / self.J1 - 1.0

    @property
    def r2(self) -> float:
        """Outer radius (m) from S = 2π r2³/μ0."""
        return (self.S * MU0 / (2.0 * math.pi)) ** (1.0 / 3.0)

    def a(self, w):
        """a(ω) = S ĝ(ω) = (4π/μ0) α(ω) (A·m²/T), complex; ω rad/s (scalar or array)."""
        return self.S * np.asarray(self.g(np.asarray(w, dtype=float)), dtype=complex)

    def a1(self, w) -> float:
        """a′(ω) = S Re ĝ(ω) (A·m²/T), [M]'s α′ times 4π/μ0."""
        return float(np.real(self.a(w)))

    def a2(self, w) -> float:
        """a″(ω) = S Im ĝ(ω) (A·m²/T), [M]'s α″ times 4π/μ0."""
        return float(np.imag(self.a(w)))

    # --- equations ------------------------------------------------------------------------------
    def rates(self, L, rho, sigma, theta) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def rhs(self, t, y) -> np.ndarray:
        """d/dt of y = (|L|, ρ, σ, θ) (N·m, rad/s); the equations are autonomous."""
        return self.rates(y[0], y[1], y[2], y[3])

    def combination_frequencies(self, L, theta) -> np.ndarray:
        """The body-frame frequencies (rad/s) at which ĝ enters the equations."""
        raise NotImplementedError  # pragma: no cover

    def small_theta_rate(self, L, rho) -> float:
        """(1/θ) dθ/dt (1/s) at θ → 0, for |L| (N·m·s) and ρ (rad)."""
        raise NotImplementedError  # pragma: no cover

    def nutation_decays(self, L, rho=0.0) -> bool:
        """θ decays at small θ: the criterion [M] (3.11) (constant field), (3.15) (pulsating), (3.18) at
        ρ = 0 (rotating), each as the sign of :meth:`small_theta_rate`."""
        return self.small_theta_rate(L, rho) < 0.0

    def torque_frequencies(self, L) -> np.ndarray:
        """Frequencies (rad/s, > 0) of the fast harmonics of the case-frame torque projections.

        The torque is quadratic in the field: harmonics e^{i(jψ + nωt)}, |j| ≤ 2, n ∈ {0, ±2}
        (n = 0 only for the constant field), and none in φ (checked numerically,
        torus_average_rates(..., phi_spread=True)). Their frequencies |j l + n ω|, (j, n) ≠ 0.
        """
        l = L / self.J1
        ns = (0,) if self.omega == 0.0 else (0, 2, -2)
        f = [abs(j * l + n * self.omega) for j in (0, 1, 2) for n in ns if (j, n) != (0, 0)]
        return np.array(f)

    def mu(self, L, theta=None) -> float:
        """[M]'s ε = T_n/T_p = N* J1/|L|², N* = S B0² max|ĝ| over the combination frequencies (N·m)."""
        if L <= 0:
            return math.inf
        th = self.y0[3] if theta is None else theta
        gmax = float(np.max(np.abs(self.g(self.combination_frequencies(L, th)))))
        return self.S * self.B0**2 * gmax * self.J1 / L**2

    def mu_eff(self, L, theta=None) -> float:
        """μ l / f_min: μ scaled by the slowest torque harmonic (= μ when that is the precession)."""
        f = float(np.min(self.torque_frequencies(L)))
        l = L / self.J1
        return math.inf if f == 0.0 else self.mu(L, theta) * l / f

    def region(self, L=None, rho=None, theta=None, mu_max: float = MU_MAX) -> tuple[bool, str]:
        """(ok, reason): whether the averaged equations hold at the slow state (default: y0).

        Conditions: J1 = J2; |L| > 0; μ_eff = μ l/f_min ≤ mu_max (small torque, non-resonant fast
        phases: f_min is the slowest torque harmonic, e.g. 2|l − |ω|| near the resonance l = |ω|);
        eddy switch-on transient short: μ l τ1 ≤ mu_max. θ and ρ are free (the torque does not
        depend on φ; σ is regular at ρ = 0 in these equations).
        """
        y = self.y0 if self.y0 is not None else np.array([np.nan] * 4)
        L = float(y[0] if L is None else L)
        theta = float(y[3] if theta is None else theta)
        if abs(self.J2 - self.J1) > 1e-9 * self.J1:
            return False, f"J1 = {self.J1:g} ≠ J2 = {self.J2:g}: [M] §3 needs an axisymmetric body"
        if not (L > 0):
            return False, "|L| = 0: no fast precession to average over"
        mu = self.mu(L, theta)
        l = L / self.J1
        f = self.torque_frequencies(L)
        fmin = float(np.min(f))
        if fmin == 0.0:
            return False, f"exact resonance: a torque harmonic has zero frequency (l = {l:.6g}, ω = {self.omega:.6g} rad/s)"
        mue = mu * l / fmin
        if mue > mu_max:
            why = "torque too large for the precession rate" if fmin >= l * (1 - 1e-12) else \
                f"near resonance (slowest torque harmonic {fmin:.4g} rad/s vs l = {l:.4g} rad/s, ω = {self.omega:.4g})"
            return False, f"μ_eff = {mue:.3g} > {mu_max:g} (μ = {mu:.3g}): {why}"
        tr = mu * l * self.tau1
        if tr > mu_max:
            return False, f"eddy transient too slow: μ l τ1 = {tr:.3g} > {mu_max:g} (τ1 = {self.tau1:.3g} s)"
        return True, f"μ = {mu:.3g}, μ_eff = {mue:.3g}, μ l τ1 = {tr:.3g} (≤ {mu_max:g})"

    def exit_events(self, mu_max: float = MU_MAX) -> list:
        """solve_ivp events (terminal, falling) at which a solution leaves :meth:`region`: its two tests in
        continuous form, mu_max f_min − μ l (small, non-resonant torque) and mu_max − μ l τ1 (short eddy
        transient), each ≥ 0 inside."""
        def torque(t, y):
            L = y[0]
            if L <= 0:
                return -1.0
            return mu_max * float(np.min(self.torque_frequencies(L))) - self.mu(L, y[3]) * L / self.J1

        def transient(t, y):
            L = y[0]
            return mu_max - self.mu(L, y[3]) * L / self.J1 * self.tau1 if L > 0 else -1.0

        for e in (torque, transient):
            e.terminal, e.direction = True, -1
        return [torque, transient]

    def first_exit(self, res: "AveragedMResult", mu_max: float = MU_MAX) -> tuple[Optional[float], str]:
        """(first sample time at which :meth:`region` fails along an averaged solution, reason), or (None, '')."""
        for t, L, rho, th in zip(res.t, res.L, res.rho, res.theta):
            ok, why = self.region(L=L, rho=rho, theta=th, mu_max=mu_max)
            if not ok:
                return float(t), why
        return None, ""

    # --- integration ----------------------------------------------------------------------------
    def integrate(self, t, y0=None, rtol: float = 1e-10) -> AveragedMResult:
        """Integrate the slow equations (DOP853) and return the slow variables at the times t (s).

        y0 = (|L| N·m·s, ρ, σ, θ rad) at t[0]; default: the scene's initial state.
        """
        t = np.asarray(t, dtype=float)
        y0 = np.asarray(self.y0 if y0 is None else y0, dtype=float)
        if t.size < 1:
            raise ValueError("integrate: t needs at least one time")
        if t.size == 1 or t[-1] == t[0]:
            Y = np.repeat(y0[:, None], t.size, axis=1)
            return AveragedMResult(t, *Y, nfev=0, model=self)
        atol = np.array([1e-12 * max(y0[0], 1e-300), 1e-12, 1e-12, 1e-12])
        sol = solve_ivp(self.rhs, (t[0], t[-1]), y0, method="DOP853", t_eval=t, rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(f"averaged_m: integration failed: {sol.message}")
        return AveragedMResult(sol.t, sol.y[0], sol.y[1], sol.y[2], sol.y[3], nfev=int(sol.nfev), model=self)

    # --- construction ---------------------------------------------------------------------------
    @classmethod
    def from_scene(cls, scene: Scene, exact: bool = False) -> "AveragedM":
        """The model of a scene whose field is of this class's kind (SceneError otherwise)."""
        m = averaged_m_model(scene, exact=exact)
        if not isinstance(m, cls):
            raise SceneError(f"scene {scene.name!r} has a {m.kind} field, not a {cls.kind} one")
        return m


class ConstantFieldM(AveragedM):
    """[M] (3.6): constant field B0 z3 (omega = 0)."""

    kind = "constant"

    def rates(self, L, rho, sigma, theta):
        return rates_constant(self.a1, self.a2, self.B0, self.J1, self.J3, L, rho, theta)  # [M] (3.6)

    def combination_frequencies(self, L, theta):
        l = L / self.J1
        nu = _nu(l, self.kappa, math.cos(theta))
        return np.array([l + nu, l - nu, l, nu])

    def small_theta_rate(self, L, rho):
        """[M] (3.10): (1/θ) dθ/dt (1/s) at small θ,
        = −(B0²/|L|) {½ sin²ρ [a″(l) − a″(l/(1+κ))] + cos²ρ a″(κl/(1+κ))}; θ decays iff the brace > 0 (3.11)."""
        l, k = L / self.J1, self.kappa
        br = 0.5 * math.sin(rho) ** 2 * (self.a2(l) - self.a2(l / (1 + k))) + math.cos(rho) ** 2 * self.a2(k * l / (1 + k))
        return -self.B0**2 * br / L  # [M] (3.10)


class PulsatingFieldM(AveragedM):
    """[M] (3.14) with (3.7): field B0 sin(ωt) z3."""

    kind = "pulsating"

    def rates(self, L, rho, sigma, theta):
        return rates_pulsating(self.a1, self.a2, self.B0, self.omega, self.J1, self.J3, L, rho, theta)  # [M] (3.14)

    def combination_frequencies(self, L, theta):
        l, w = L / self.J1, self.omega
        nu = _nu(l, self.kappa, math.cos(theta))
        return np.array([l + nu - w, l + nu + w, l - nu - w, l - nu + w, l - w, l + w, nu + w, nu - w, w])

    def small_theta_rate(self, L, rho):
        """[M] (3.14) at θ → 0: (1/θ) dθ/dt = (B0²/(8|L|)) {sin²ρ [a″(l₁−ω) + a″(l₁+ω) − a″(l−ω) − a″(l+ω)]
        + 2cos²ρ [a″(−n−ω) + a″(−n+ω)]}, l₁ = l/(1+κ), n = κl/(1+κ); θ decays iff (3.15) holds."""
        l, k, w = L / self.J1, self.kappa, self.omega
        l1, n = l / (1 + k), k * l / (1 + k)
        a2 = self.a2
        br = (0.5 * math.sin(rho) ** 2 * (a2(l1 - w) + a2(l1 + w) - a2(l - w) - a2(l + w))
              + math.cos(rho) ** 2 * (a2(-n - w) + a2(-n + w)))  # left side of [M] (3.15)
        return self.B0**2 * br / (4.0 * L)


class RotatingFieldM(AveragedM):
    """[M] (3.17): field B0 (cos ωt, sin ωt, 0), ω signed."""

    kind = "rotating"

    def rates(self, L, rho, sigma, theta):
        return rates_rotating(self.a1, self.a2, self.B0, self.omega, self.J1, self.J3, L, rho, theta)  # [M] (3.17)

    # the same combinations l ± ν ± ω, l ± ω, ν ± ω, ω as the pulsating field's
    combination_frequencies = PulsatingFieldM.combination_frequencies

    def small_theta_rate(self, L, rho=0.0):
        """(1/θ) dθ/dt (1/s) of (3.17) at θ → 0 for any ρ:
        (B0²/(8|L|)) {(1+cosρ)² a″(l₁−ω) + (1−cosρ)² a″(l₁+ω) + 2 sin²ρ [a″(−n−ω) + a″(−n+ω)]
                      − (1+cosρ)² a″(l−ω) − (1−cosρ)² a″(l+ω)},  l₁ = l/(1+κ), n = κl/(1+κ).
        At ρ = 0 this is [M] (3.18), (B0²/(2|L|)) [a″(l₁−ω) − a″(l−ω)] (closed_forms.small_theta_nutation_rate)."""
        l, k, w = L / self.J1, self.kappa, self.omega
        l1, n = l / (1 + k), k * l / (1 + k)
        p, m = 1 + math.cos(rho), 1 - math.cos(rho)
        a2 = self.a2
        br = (p * p * a2(l1 - w) + m * m * a2(l1 + w) + 2 * math.sin(rho) ** 2 * (a2(-n - w) + a2(-n + w))
              - p * p * a2(l - w) - m * m * a2(l + w))
        return self.B0**2 * br / (8.0 * L)

    def small_theta_rate_318(self, L):
        """[M] (3.18) (ρ = 0) through closed_forms.small_theta_nutation_rate (same ĝ)."""
        return float(small_theta_nutation_rate(self.g, self.r2, self.B0, self.J1, self.J3, L, self.omega))


    def thin_shell_window(self, tau):
        """[M] (3.19)–(3.20) for a thin shell of time constant τ (s): closed_forms.thin_shell_nutation_window."""
        return thin_shell_nutation_window(self.J1, self.J3, tau, self.omega)


_KINDS = {"constant": ConstantFieldM, "pulsating": PulsatingFieldM, "rotating": RotatingFieldM}


def _field_of_scene(scene: Scene) -> tuple[str, float, float]:
    """(kind, B0 T, ω rad/s signed) of a scene's field; SceneError if it is none of [M]'s three."""
    terms = [(np.array(f.real) + 1j * np.array(f.imag), float(f.frequency)) for f in scene.field]
    for s in scene.stators:  # a stator is the field B I (e1 cos σ + e2 sin σ) = Re[B I (e1 + i e2) e^{−i(−ν)t} e^{-iσ0}]
        if s.current > 0:
            u = np.array(s.axis)
            if not np.allclose(u, [0, 0, 1], atol=1e-12):
                raise SceneError(f"averaged_m: stator {s.name!r} has axis {list(u)}; [M]'s rotating field turns about z3")
            B = s.coil_constant * s.current * np.exp(-1j * s.phase) * np.array([1.0, 1j, 0.0])
            terms.append((B, float(s.rate)) if s.rate >= 0 else (np.conj(B), -float(s.rate)))
    if len(terms) != 1:
        raise SceneError(f"averaged_m: [M]'s equations take exactly one field term; scene {scene.name!r} has {len(terms)}")
    Bp, w = terms[0]
    if scene.commands or scene.controller is not None:
        raise SceneError("averaged_m: commands and controllers are not modelled (constant field only)")
    z = np.array([0.0, 0.0, 1.0])
    perp = Bp - z * Bp[2]
    if w == 0.0:
        Br = np.real(Bp)
        if np.linalg.norm(Br[:2]) > 1e-12 * np.linalg.norm(Br) or Br[2] <= 0:
            raise SceneError("averaged_m: a constant field must point along +z3 ([M] (3.4))")
        return "constant", float(Br[2]), 0.0
    if np.linalg.norm(perp) <= 1e-12 * np.linalg.norm(Bp):
        return "pulsating", float(abs(Bp[2])), w  # B0 sin(ωt + δ) z3: the phase δ averages out
    if abs(Bp[2]) <= 1e-12 * np.linalg.norm(Bp):
        # rotating in z1z2: B_p = B0 e^{iδ} (1, ±i, 0)/... ; + : turns positively about z3
        if abs(Bp[1] - 1j * Bp[0]) <= 1e-9 * abs(Bp[0]) + 1e-300:
            return "rotating", float(abs(Bp[0])), w
        if abs(Bp[1] + 1j * Bp[0]) <= 1e-9 * abs(Bp[0]) + 1e-300:
            return "rotating", float(abs(Bp[0])), -w
    raise SceneError(f"averaged_m: field term {Bp} at {w} rad/s is neither pulsating along z3 nor rotating "
                     "(circularly) about z3")


def averaged_m_model(scene: Scene, exact: bool = False) -> AveragedM:
    """The [M] averaged model of a scene (constant, pulsating or rotating field along/about z3).

    The initial slow state is the scene's: |L| = J3·spin (or kinetic_moment), ρ, σ of
    ``initial.L_direction``, θ = ``initial.theta``. ``exact``: see :func:`response_of_scene`.
    """
    kind, B0, w = _field_of_scene(scene)
    S, g, tau1 = response_of_scene(scene, exact=exact)
    J = scene.inertia
    ini = scene.initial
    d = np.asarray(ini.L_direction, dtype=float)
    d /= np.linalg.norm(d)
    L0 = ini.kinetic_moment if ini.kinetic_moment is not None else J[2] * (ini.spin or 0.0)
    rho0 = math.atan2(math.hypot(d[0], d[1]), d[2])
    sig0 = math.atan2(d[1], d[0]) if math.hypot(d[0], d[1]) > 0 else 0.0
    y0 = np.array([float(L0), rho0, sig0, float(ini.theta)])
    return _KINDS[kind](J1=float(J[0]), J2=float(J[1]), J3=float(J[2]), B0=B0, omega=w, S=S, g=g, tau1=tau1,
                        y0=y0, scene=scene)


# ------------------------------------------------------------------------------------------------
# independent check: average of the instantaneous torque over the fast phases
# ------------------------------------------------------------------------------------------------
def torus_average_rates(model: AveragedM, L, rho, sigma, theta, n_grid: int = 8,
                        phi_spread: bool = False):
    """(d|L|/dt, dρ/dt, dσ/dt, dθ/dt) from averaging the instantaneous torque of the steady linear
    eddy response over the fast phases numerically (no use of [M]'s formulas).

    Along the unperturbed motion (ψ = l t, φ = −ν t, field phase χ = ωt) the body-frame field
    B_b = Rz(−φ) Rx(−θ) Rz(−ψ) Yᵀ B(χ) is a trigonometric polynomial on the torus (ψ, φ, χ); its
    harmonic e^{i(jψ + kφ + nχ)} has the body frequency W = −j l + k ν − n ω (fields ∝ e^{−iWt}) and
    gives the moment S ĝ(W) times it. N_b = m_b × B_b is projected on y1, y2, y3 (case-fixed) and
    on x3 and averaged over the grid (exact for n_grid ≥ 5: the products are of degree ≤ 2 per angle):
    |L|′ = ⟨N·y3⟩, |L| ρ′ = ⟨N·y1⟩, |L| sinρ σ′ = ⟨N·y2⟩, |L| sinθ θ′ = cosθ ⟨N·y3⟩ − ⟨N·x3⟩.
    ``phi_spread=True`` also returns the largest change of the four projected torques along the φ
    axis of the grid relative to their largest value: ≈ 1e-16 means they do not depend on φ.
    """
    l = L / model.J1
    c, s = math.cos(theta), math.sin(theta)
    nu = _nu(l, model.kappa, c)
    cr, sr, cs, ss = math.cos(rho), math.sin(rho), math.cos(sigma), math.sin(sigma)
    Y = np.array([[cr * cs, -ss, sr * cs], [cr * ss, cs, sr * ss], [-sr, 0.0, cr]])
    B0, w = model.B0, model.omega
    if model.kind == "constant":
        Bp, w = np.array([0.0, 0.0, B0], dtype=complex), 0.0
    elif model.kind == "pulsating":
        Bp = np.array([0.0, 0.0, 1j * B0])  # Re(i B0 e^{−iωt}) = B0 sin ωt
    else:
        Bp = B0 * np.array([1.0, 1j, 0.0])  # Re((1, i, 0) e^{−iωt}) = (cos ωt, sin ωt, 0)
    N = int(n_grid)
    ang = 2.0 * np.pi * np.arange(N) / N
    PSI, PHI, CHI = np.meshgrid(ang, ang, ang if w != 0.0 else np.zeros(1), indexing="ij")
    cp, sp, cf, sf = np.cos(PSI), np.sin(PSI), np.cos(PHI), np.sin(PHI)

    def to_body(v):  # Rz(−φ) Rx(−θ) Rz(−ψ) v, v (..., 3) in the L frame
        x = cp * v[..., 0] + sp * v[..., 1]
        y = -sp * v[..., 0] + cp * v[..., 1]
        y, z = c * y + s * v[..., 2], -s * y + c * v[..., 2]
        return np.stack([cf * x + sf * y, -sf * x + cf * y, z], axis=-1)

    Bcase = np.real(Bp * np.exp(-1j * CHI)[..., None])
    Bb = to_body(Bcase @ Y)
    axes = (0, 1, 2)
    C = np.fft.fftn(Bb, axes=axes)
    f = np.fft.fftfreq(N, 1.0 / N)
    fc = f if w != 0.0 else np.zeros(1)
    Fj, Fk, Fn = np.meshgrid(f, f, fc, indexing="ij")
    W = -Fj * l + Fk * nu - Fn * w
    zero = np.abs(W) <= 1e-12 * (abs(l) + abs(w))
    gW = np.where(zero, 0.0, model.g(np.where(zero, 1.0, W)))  # ĝ(0) = 0
    m = model.S * np.real(np.fft.ifftn(C * gW[..., None], axes=axes))
    Nb = np.cross(m, Bb)
    P = np.stack([np.sum(Nb * to_body(np.broadcast_to(np.eye(3)[i], Bb.shape)), axis=-1) for i in range(3)]
                 + [Nb[..., 2]])  # N·y1, N·y2, N·y3, N·x3 on the grid
    n1, n2, n3, nx3 = (float(np.mean(p)) for p in P)
    dth = (c * n3 - nx3) / (L * s) if s != 0.0 else 0.0
    dsig = n2 / (L * sr) if sr != 0.0 else math.nan
    out = np.array([n3, n1 / L, dsig, dth])
    if phi_spread:
        spread = float(np.max(np.abs(P - P.mean(axis=2, keepdims=True))) / max(np.max(np.abs(P)), 1e-300))
        return out, spread
    return out


# ------------------------------------------------------------------------------------------------
# the full model's slow variables, thin-shell closed forms
# ------------------------------------------------------------------------------------------------
def slow_variables(res) -> dict:
    """|L|, ρ, σ (unwrapped), θ (SI) of a full-model RunResult (case-frame L, θ = euler[:, 1])."""
    L = np.asarray(res.L)
    Ln = np.linalg.norm(L, axis=1)
    rho = np.arctan2(np.hypot(L[:, 0], L[:, 1]), L[:, 2])
    sig = np.unwrap(np.arctan2(L[:, 1], L[:, 0]))
    return {"t": np.asarray(res.t), "L": Ln, "rho": rho, "sigma": sig, "theta": np.asarray(res.euler[:, 1])}


def errors_against_full(model: AveragedM, res, y0=None) -> tuple[dict, AveragedMResult]:
    """Integrate ``model`` on the output times of a full-model RunResult ``res`` (from the full
    model's slow state at res.t[0], or y0) and return ({name: max error}, averaged result).

    Errors are max over the samples of |x_full − x_avg|: |L| relative to |L(0)|, ρ, θ in rad, σ as
    the arc sinρ |Δσ| (rad; σ unwrapped, undefined at ρ = 0). No smoothing: the O(μ) ripple of the
    full model counts as error.
    """
    sv = slow_variables(res)
    if y0 is None:
        y0 = [sv["L"][0], sv["rho"][0], sv["sigma"][0], sv["theta"][0]]
    a = model.integrate(sv["t"], y0=y0)
    L0 = sv["L"][0]
    err = {"L": float(np.max(np.abs(sv["L"] - a.L)) / L0),
           "rho": float(np.max(np.abs(sv["rho"] - a.rho))),
           "sigma": float(np.max(np.abs(sv["sigma"] - a.sigma) * np.sin(a.rho))),
           "theta": float(np.max(np.abs(sv["theta"] - a.theta)))}
    return err, a


def thin_shell_l_rate_polynomial(theta, kappa):
    """[M] (3.9): (a0, a1, a2) with d|L|/dt ∝ −(a2 u² + a1 u + a0), u = τ² l², for a thin shell in a
    constant field (α″ = γω/(1 + ξ²ω²), ξ = τ); b = κ/(1+κ):
    a0 = 2(1 − b c²), a1 = 4 + b² c² (1 − 3c² − 2b c²), a2 = (1 − b²c²)(2 + 2b c² − b² s² c²)."""
    b = kappa / (1.0 + kappa)
    c2 = math.cos(theta) ** 2
    s2 = 1.0 - c2
    a0 = 2.0 * (1.0 - b * c2)
    a1 = 4.0 + b * b * c2 * (1.0 - 3.0 * c2 - 2.0 * b * c2)
    a2 = (1.0 - b * b * c2) * (2.0 + 2.0 * b * c2 - b * b * s2 * c2)
    return a0, a1, a2


def thin_shell_l_star(tau, kappa) -> float:
    """[M] after (3.12): at ρ = π/2 a thin shell's small nutation decays ((3.11)) only for
    l < l* = √(1+κ)/τ (rad/s; l = |L|/J1), κ > 0."""
    return math.sqrt(1.0 + kappa) / tau
