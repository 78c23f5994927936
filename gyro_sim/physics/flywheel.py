"""Reorientation of a body by an internal flywheel ([S] Smolnikov; physics.md §4, §6 item 8).

Pure functions, SI units (kg·m², rad, rad/s, s). Frames (physics.md §1):

* case frame Z (inertial), body frame X = principal axes of the body, inertia J = diag(J1, J2, J3);
* attitude quaternion ``q = (w, x, y, z)``, body → case (``v_case = R(q) v_body``), as
  :attr:`gyro_sim.simulate.RunResult.q`;
* the wheel: axial moment J_f about the body-fixed unit axis a (body frame), speed Ω_f(t)
  *relative to the body* (rad/s), turn τ(t) = ∫₀ᵗ Ω_f dt (rad) ([S] (5)).

J is the inertia of the whole body **with the wheel locked** ([S]: "A, B, C are the principal moments
of the carrying body together with the flywheel"), so the gyrostat's kinetic moment is

    L_b = J Ω_b + J_f Ω_f a          (body frame)                                   [S] (1)

which is what the compiled model uses (:func:`gyro_sim.effects.body_rate`).

Forward problem ([S] (1), (8), (9), (29)). With L = 0 (body and wheel at rest at the start):
Ω_b = −J_f Ω_f J⁻¹a. Its direction, the *companion axis* e = J⁻¹a/|J⁻¹a|, is fixed in the body, hence
also in the case frame; the body turns about e by

    φ* − φ0* = −λ τ,     λ = J_f |J⁻¹a|,     |Ω_b| / |Ω_f| = λ = const                 [S] (8), (9), (29)

**Sign**: the body turns about +e by −λτ, i.e. opposite to the wheel (Ω_b·a = −J_f Ω_f a·J⁻¹a has the
sign of −Ω_f). The turn depends on τ only, not on how Ω_f varied ([S] (5)–(6)). e ≠ a unless J is
isotropic or a is a principal axis.

Inverse problem ([S] (21)–(24), closing remarks). For a wanted attitude q1 from q0: the relative turn
q0⁻¹ ⊗ q1 = (cos ½φ, sin ½φ e) (Euler's theorem) gives the companion axis e and the body's turn φ;
the wheel axis follows from inverting (24): J⁻¹a ∥ e ⇔ a ∥ J e, and the wheel turn is τ = φ/λ. We
choose a = −J e/|J e| so that τ > 0 (the wheel turns forward, the body backward about a's companion
axis −e, i.e. by +φ about e) and φ ∈ (0, π] (the short way). λ = J_f/|J e|; |J e| is the "reduced
moment of inertia" of [S] (30). [S] also gives closed forms in Euler angles: (21)–(22) for the angles
μ, ν of the wheel axis and (18) for τ; they are implemented here as an independent check
(:func:`smolnikov_wheel_angles`, :func:`smolnikov_wheel_turn`).

Angles of [S] (figure): a = (sin ν sin μ, sin ν cos μ, cos ν) in the principal axes x, y, z with
moments A = J1, B = J2, C = J3; the companion axis e = (sin ν* sin μ*, sin ν* cos μ*, cos ν*).

Cayley–Klein parameters and Euler angles of [S] (2)–(3): with R(q) = Rz(ψ) Rx(θ) Rz(φ) (z-x-z, in the
case frame; physics.md's Euler angles with Y = I),

    α = w + i z = cos ½θ e^{i(ψ+φ)/2},     β = −y + i x = i sin ½θ e^{i(ψ−φ)/2}          [S] (2)

and dq/dt = ½ q ⊗ (0, Ω_b) is exactly [S] (3) (checked term by term; test/test_flywheel.py).

OCR finding: [S] (23) as printed has the factor (1 ± ctg ν/(C R)); from (12) it must be
(ctg ν/(C R) ± 1) (the two agree for k1 but differ in sign for k2); (25) k2 = −tg ½ν* e^{−iμ*}
agrees with (12), not with (23) as printed. See docs/flywheel.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

__all__ = [
    "qmul", "qconj", "qnormalize", "rotation_quaternion", "attitude_error",
    "cayley_klein", "quat_from_cayley_klein", "euler_zxz", "quat_from_euler_zxz",
    "axis_angles", "axis_from_angles", "companion_axis", "turn_ratio", "reduced_inertia",
    "companion_angles", "wheel_angles_from_companion", "ck_coefficients", "ck_coefficients_23_printed",
    "gyrostat_body_rate", "wheel_energy", "forward_attitude", "turn_about_axis",
    "smolnikov_wheel_angles", "smolnikov_wheel_turn",
    "trapezoid_profile", "profile_angle", "FlywheelPlan", "plan_reorientation", "plan_scene",
]


# --- quaternions (w, x, y, z) ------------------------------------------------------------------

def qmul(p: Sequence[float], q: Sequence[float]) -> np.ndarray:
    """Hamilton product p ⊗ q of quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def qconj(q: Sequence[float]) -> np.ndarray:
    """Conjugate (inverse of a unit quaternion)."""
    return np.array([q[0], -q[1], -q[2], -q[3]], dtype=float)


def qnormalize(q: Sequence[float]) -> np.ndarray:
    """q/|q|; raises ValueError for a zero or non-finite quaternion."""
    q = np.asarray(q, dtype=float)
    n = float(np.linalg.norm(q))
    if q.shape != (4,) or not math.isfinite(n) or n == 0.0:
        raise ValueError(f"quaternion {[float(x) for x in np.ravel(q)]}: needs 4 finite numbers (w, x, y, z), not all zero")
    return q / n


def rotation_quaternion(axis: Sequence[float], angle: float) -> np.ndarray:
    """Unit quaternion of a right-handed turn by ``angle`` (rad) about the unit ``axis``."""
    e = np.asarray(axis, dtype=float)
    e = e / np.linalg.norm(e)
    return np.concatenate([[math.cos(0.5 * angle)], math.sin(0.5 * angle) * e])


def attitude_error(q1: Sequence[float], q2: Sequence[float]) -> float:
    """Angle (rad, in [0, π]) of the rotation between attitudes q1 and q2 (sign of q ignored)."""
    d = qmul(qconj(qnormalize(q1)), qnormalize(q2))
    return 2.0 * math.atan2(float(np.linalg.norm(d[1:])), abs(float(d[0])))


# --- Cayley–Klein parameters and Euler angles [S] (2)–(3) ---------------------------------------

def cayley_klein(q: Sequence[float]) -> tuple[complex, complex]:
    """(α, β) of [S] (2) for the attitude q (body → case): α = w + i z, β = −y + i x.

    With these, dq/dt = ½ q ⊗ (0, Ω_b) is [S] (3): α' = ½ i ω_z α + ½(ω_y + i ω_x) β,
    β' = −½ i ω_z β − ½(ω_y − i ω_x) α (ω = Ω_b, body frame).
    """
    w, x, y, z = qnormalize(q)
    return complex(w, z), complex(-y, x)


def quat_from_cayley_klein(alpha: complex, beta: complex) -> np.ndarray:
    """Inverse of :func:`cayley_klein`: q = (Re α, Im β, −Re β, Im α)."""
    return qnormalize([alpha.real, beta.imag, -beta.real, alpha.imag])


def euler_zxz(q: Sequence[float]) -> tuple[float, float, float]:
    """(ψ, θ, φ) (rad) with R(q) = Rz(ψ) Rx(θ) Rz(φ), θ ∈ [0, π], from the Cayley–Klein form [S] (2).

    (ψ+φ)/2 = arg α, (ψ−φ)/2 = arg(−iβ) = atan2(y, x), θ = 2 atan2(|β|, |α|): well conditioned also
    near θ = 0, π (only the sum resp. the difference of ψ, φ is defined there).
    """
    alpha, beta = cayley_klein(q)
    s = 2.0 * math.atan2(alpha.imag, alpha.real)  # ψ + φ
    d = 2.0 * math.atan2(-beta.real, beta.imag)  # ψ − φ ; −iβ = x + i y
    theta = 2.0 * math.atan2(abs(beta), abs(alpha))
    return 0.5 * (s + d), theta, 0.5 * (s - d)


def quat_from_euler_zxz(psi: float, theta: float, phi: float) -> np.ndarray:
    """Quaternion of R = Rz(ψ) Rx(θ) Rz(φ) (rad), from [S] (2)."""
    alpha = math.cos(0.5 * theta) * complex(math.cos(0.5 * (psi + phi)), math.sin(0.5 * (psi + phi)))
    beta = 1j * math.sin(0.5 * theta) * complex(math.cos(0.5 * (psi - phi)), math.sin(0.5 * (psi - phi)))
    return quat_from_cayley_klein(alpha, beta)


# --- wheel axis, companion axis [S] (8), (24), (30) ---------------------------------------------

def _unit(v: Sequence[float], what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    if v.shape != (3,) or not math.isfinite(n) or n == 0.0:
        raise ValueError(f"{what} = {[float(x) for x in np.ravel(v)]}: needs a non-zero finite 3-vector")
    return v / n


def _inertia(J: Sequence[float]) -> np.ndarray:
    J = np.asarray(J, dtype=float)
    if J.shape != (3,) or not np.all(np.isfinite(J)) or np.any(J <= 0):
        raise ValueError(f"inertia = {[float(x) for x in np.ravel(J)]}: needs three positive principal moments J1, J2, J3 (kg·m²)")
    return J


def axis_angles(a: Sequence[float]) -> tuple[float, float]:
    """(μ, ν) (rad) of [S]'s figure: a = (sin ν sin μ, sin ν cos μ, cos ν), ν ∈ [0, π], μ ∈ (−π, π]."""
    a = _unit(a, "axis")
    return math.atan2(a[0], a[1]), math.acos(max(-1.0, min(1.0, a[2])))


def axis_from_angles(mu: float, nu: float) -> np.ndarray:
    """Unit vector (sin ν sin μ, sin ν cos μ, cos ν) (body frame)."""
    return np.array([math.sin(nu) * math.sin(mu), math.sin(nu) * math.cos(mu), math.cos(nu)])


def companion_axis(J: Sequence[float], a: Sequence[float]) -> np.ndarray:
    """Companion axis e = J⁻¹a/|J⁻¹a| (body frame, unit): the body's rotation axis [S] (24), (29)."""
    v = _unit(a, "axis") / _inertia(J)
    return v / np.linalg.norm(v)


def turn_ratio(J: Sequence[float], J_f: float, a: Sequence[float]) -> float:
    """λ = J_f |J⁻¹a| (dimensionless): |Ω_b| = λ |Ω_f|, body turn = λ τ  [S] (8), (9)."""
    return float(J_f) * float(np.linalg.norm(_unit(a, "axis") / _inertia(J)))


def reduced_inertia(J: Sequence[float], e: Sequence[float]) -> float:
    """|J e| (kg·m²): [S] (30)'s root (C² cos²ν* + B² sin²ν* cos²μ* + A² sin²ν* sin²μ*)^½, so that
    J_f τ + |J e| φ* = const and λ = J_f/|J e|. (Not the moment e·J e about the axis.)"""
    return float(np.linalg.norm(_inertia(J) * _unit(e, "companion axis")))


def companion_angles(J: Sequence[float], mu: float, nu: float) -> tuple[float, float]:
    """(μ*, ν*) of the companion axis from the wheel angles (μ, ν), [S] (24):
    tg μ* = (B/A) tg μ, cos ν* = ctg ν/(C R), sin ν* = (cos²μ/B² + sin²μ/A²)^½ / R (quadrants from e)."""
    return axis_angles(companion_axis(J, axis_from_angles(mu, nu)))


def wheel_angles_from_companion(J: Sequence[float], mu_s: float, nu_s: float) -> tuple[float, float]:
    """(μ, ν) of the wheel axis a ∥ J e that has the companion axis e(μ*, ν*): (24) inverted,
    tg μ = (A/B) tg μ*, tg ν = tg ν* (A² sin²μ* + B² cos²μ*)^½ / C."""
    return axis_angles(_inertia(J) * axis_from_angles(mu_s, nu_s))


def ck_coefficients(J: Sequence[float], mu: float, nu: float) -> tuple[complex, complex]:
    """k1, k2 of [S] (12): k_{1,2} = (ctg ν/C ± R)(cos μ/B + i sin μ/A)⁻¹,
    R = (ctg²ν/C² + cos²μ/B² + sin²μ/A²)^½; equal to (25) k1 = ctg ½ν* e^{−iμ*}, k2 = −tg ½ν* e^{−iμ*}.
    (The eigenvectors of (6): N = −i k M for γ = ±iλ/2.) Needs sin ν ≠ 0, (μ, ν) not on a pole of k."""
    A, B, C = _inertia(J)
    ctg = math.cos(nu) / math.sin(nu)
    R = math.sqrt(ctg ** 2 / C ** 2 + math.cos(mu) ** 2 / B ** 2 + math.sin(mu) ** 2 / A ** 2)
    P = complex(math.cos(mu) / B, math.sin(mu) / A)
    return (ctg / C + R) / P, (ctg / C - R) / P


def ck_coefficients_23_printed(J: Sequence[float], mu: float, nu: float) -> tuple[complex, complex]:
    """k1, k2 of [S] (23) *as printed*: (1 ± ctg ν/(C R)) (cos²μ/B² + sin²μ/A²)^−½ R e^{−i arctg((B/A) tg μ)}.
    Kept to document the OCR/print finding: k2 has the wrong sign (see module docstring)."""
    A, B, C = _inertia(J)
    ctg = math.cos(nu) / math.sin(nu)
    R = math.sqrt(ctg ** 2 / C ** 2 + math.cos(mu) ** 2 / B ** 2 + math.sin(mu) ** 2 / A ** 2)
    s = math.sqrt(math.cos(mu) ** 2 / B ** 2 + math.sin(mu) ** 2 / A ** 2)
    ph = np.exp(-1j * math.atan2(math.sin(mu) / A, math.cos(mu) / B))  # the branch of arg(cos μ/B + i sin μ/A)
    x = ctg / (C * R)
    return complex((1 + x) / s * R * ph), complex((1 - x) / s * R * ph)


# --- forward problem [S] (1), (9), (29) -------------------------------------------------------

def gyrostat_body_rate(J: Sequence[float], J_f: float, a: Sequence[float], wheel_speed: float,
                       L_b: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Ω_b = J⁻¹(L_b − J_f Ω_f a) (rad/s, body frame) of the gyrostat [S] (1) (L_b in N·m·s, body)."""
    return (np.asarray(L_b, dtype=float) - float(J_f) * float(wheel_speed) * _unit(a, "axis")) / _inertia(J)


def wheel_energy(omega_b: np.ndarray, J_f: float, a: Sequence[float], wheel_speed: np.ndarray) -> np.ndarray:
    """Kinetic energy (J) the turning wheel adds to the locked body's ½ Ω·J Ω: J_f Ω_f (a·Ω) + ½ J_f Ω_f².

    Ω = ``omega_b`` (rad/s, body frame, rows = samples), the wheel's axial moment J_f (kg·m²) on the body axis a
    turning at Ω_f = ``wheel_speed`` (rad/s, one per row) relative to the body. J (with the wheel locked) holds
    ½ J_f (a·Ω)²; the wheel's own spin about a is a·Ω + Ω_f. The motor driving the wheel does work, so the sum
    is not conserved; with L = 0 it is ½ J_f Ω_f² (1 − J_f a·J⁻¹a)."""
    w = np.atleast_2d(np.asarray(omega_b, dtype=float))
    ws = np.asarray(wheel_speed, dtype=float)
    return float(J_f) * ws * (w @ _unit(a, "axis")) + 0.5 * float(J_f) * ws * ws


def forward_attitude(q0: Sequence[float], J: Sequence[float], J_f: float, a: Sequence[float],
                     wheel_turn: float) -> np.ndarray:
    """Attitude after the wheel turned by τ = ``wheel_turn`` (rad) from rest with L = 0:
    q0 ⊗ (turn by −λτ about the companion axis e), [S] (29): φ* = φ0* − λτ."""
    e = companion_axis(J, a)
    return qmul(qnormalize(q0), rotation_quaternion(e, -turn_ratio(J, J_f, a) * float(wheel_turn)))


def turn_about_axis(q0: Sequence[float], q: np.ndarray, e: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Signed turn (rad, unwrapped along the rows of ``q``) about the body axis e, and the off-axis part.

    For each row: d = q0⁻¹ ⊗ q = (c, v); the turn is 2 atan2(v·e, c) (unwrapped), the off-axis part
    2|v − (v·e) e| (rad, small-angle measure of how far d is from a pure turn about e).
    """
    e = _unit(e, "axis")
    q = np.atleast_2d(np.asarray(q, dtype=float))
    d = np.array([qmul(qconj(qnormalize(q0)), qi / np.linalg.norm(qi)) for qi in q])
    ve = d[:, 1:] @ e
    turn = np.unwrap(2.0 * np.arctan2(ve, d[:, 0]))
    off = 2.0 * np.linalg.norm(d[:, 1:] - ve[:, None] * e, axis=1)
    return turn, off


# --- [S] closed forms of the inverse problem in Euler angles (21), (22), (18) ----------------

def smolnikov_wheel_angles(J: Sequence[float], euler0: Sequence[float], euler1: Sequence[float]) -> tuple[float, float]:
    """(μ, ν) (rad) of the wheel axis taking the body from Euler angles (ψ0, θ0, φ0) to (ψ1, θ1, φ1),
    [S] (21)–(22) as printed (verified against the vector solution, test/test_flywheel.py).

    Euler angles z-x-z in the case frame (:func:`euler_zxz`). (21) gives μ modulo π (atan2 of the
    printed numerator/denominator picks one branch), (22) then ν ∈ (0, π); the other branch is the
    opposite axis −a. Singular where both brackets of (21) vanish (e.g. θ0 = θ1 = 0).
    """
    A, B, C = _inertia(J)
    p0, t0, f0 = euler0
    p1, t1, f1 = euler1
    sd, cd = math.sin(p1 - p0), math.cos(p1 - p0)
    s, c = math.sin, math.cos
    # [S] (21): B tg μ = A · num/den
    num = (sd * (c(t1) * c(f1) * s(t0) - c(t0) * c(f0) * s(t1)) + cd * (s(f1) * s(t0) + s(f0) * s(t1))
           - s(t1) * s(f1) - s(t0) * s(f0))
    den = (sd * (-c(t1) * s(f1) * s(t0) + c(t0) * s(f0) * s(t1)) + cd * (c(f1) * s(t0) + c(f0) * s(t1))
           - s(t1) * c(f1) - s(t0) * c(f0))
    mu = math.atan(A * num / (B * den)) if den != 0.0 else math.copysign(0.5 * math.pi, num)  # μ modulo π
    # [S] (22): C tg ν = (cos θ0 − cos θ1) / [B⁻¹ cos μ (sin θ1 cos φ1 − sin θ0 cos φ0)
    #                                         + A⁻¹ sin μ (sin θ1 sin φ1 − sin θ0 sin φ0)]
    d22 = c(mu) / B * (s(t1) * c(f1) - s(t0) * c(f0)) + s(mu) / A * (s(t1) * s(f1) - s(t0) * s(f0))
    nu = math.atan2(c(t0) - c(t1), C * d22)  # ν ∈ (−π, π]: a negative ν is the same axis as (μ+π, −ν)
    if nu < 0.0:
        mu, nu = mu + math.pi, -nu
    mu = math.atan2(math.sin(mu), math.cos(mu))
    return mu, nu


def smolnikov_wheel_turn(J: Sequence[float], J_f: float, mu: float, nu: float,
                         euler0: Sequence[float], euler1: Sequence[float]) -> float:
    """Wheel turn τ (rad, λτ ∈ [0, 2π)) from the first integral [S] (17)/(18) with k1 of (12):
    (k1 α − iβ) e^{iλτ/2} = const ⇒ e^{iλτ/2} = (k1 α0 − iβ0)/(k1 α1 − iβ1).

    α, β of Euler angles are defined up to a common sign (ψ → ψ + 2π), so λτ is found modulo 2π.
    """
    lam = turn_ratio(J, J_f, axis_from_angles(mu, nu))
    k1, _ = ck_coefficients(J, mu, nu)
    a0, b0 = cayley_klein(quat_from_euler_zxz(*euler0))
    a1, b1 = cayley_klein(quat_from_euler_zxz(*euler1))
    ratio = (k1 * a0 - 1j * b0) / (k1 * a1 - 1j * b1)
    lam_tau = (2.0 * math.atan2(ratio.imag, ratio.real)) % (2.0 * math.pi)
    return lam_tau / lam


# --- speed profile ----------------------------------------------------------------------------

def trapezoid_profile(angle: float, peak_speed: Optional[float] = None, ramp: Optional[float] = None,
                      duration: Optional[float] = None, start: float = 0.0) -> tuple[list[float], list[float]]:
    """Piecewise-linear Ω_f(t) (times s, speeds rad/s) from rest to rest with ∫Ω_f dt = ``angle`` (rad).

    Give two of: ``peak_speed`` Ω_max (rad/s, > 0), ``ramp`` t_r (s, acceleration time), ``duration``
    T (s, start to stop); or ``duration`` alone (ramp = T/4). A negative ``angle`` gives a negative
    speed. Trapezoid: 0 → Ω over t_r, plateau, Ω → 0 over t_r; area Ω (T − t_r) = |angle|.
    With peak_speed and ramp, a turn too short for the plateau becomes a triangle at the same
    acceleration Ω_max/t_r (lower peak). Raises ValueError for inconsistent data.
    """
    sgn = 1.0 if angle >= 0 else -1.0
    ang = abs(float(angle))
    for name, v in (("peak_speed", peak_speed), ("ramp", ramp), ("duration", duration)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v}: must be a finite number > 0")
    if not (math.isfinite(ang) and ang > 0):
        raise ValueError(f"angle = {angle}: the wheel turn must be finite and non-zero (rad)")
    given = sum(v is not None for v in (peak_speed, ramp, duration))
    if given == 3:
        raise ValueError("give two of peak_speed, ramp, duration (the turn fixes the third)")
    if duration is not None and peak_speed is None:
        r = ramp if ramp is not None else 0.25 * duration
        if r > 0.5 * duration:
            raise ValueError(f"ramp = {r} s: must be at most half the duration {duration} s")
        peak, plateau = ang / (duration - r), duration - 2.0 * r
    elif duration is not None and peak_speed is not None:
        r = duration - ang / peak_speed
        if r <= 0.0:
            raise ValueError(f"peak_speed = {peak_speed} rad/s: too low to turn the wheel by {ang:.6g} rad in "
                             f"{duration} s (needs more than {ang / duration:.6g} rad/s)")
        if r > 0.5 * duration:
            raise ValueError(f"peak_speed = {peak_speed} rad/s: too high for a trapezoid of {duration} s turning "
                             f"the wheel by {ang:.6g} rad (at most {2.0 * ang / duration:.6g} rad/s)")
        peak, plateau = peak_speed, duration - 2.0 * r
    elif peak_speed is not None and ramp is not None:
        r, peak = ramp, peak_speed
        plateau = ang / peak - r
        if plateau < 0.0:  # triangle at the same acceleration
            acc = peak_speed / ramp
            peak = math.sqrt(ang * acc)
            r, plateau = peak / acc, 0.0
    else:
        raise ValueError("give two of peak_speed, ramp, duration (or duration alone)")
    t = [start, start + r]
    w = [0.0, sgn * peak]
    if plateau > 1e-12 * max(1.0, r):
        t.append(start + r + plateau)
        w.append(sgn * peak)
    t.append(start + 2.0 * r + plateau)
    w.append(0.0)
    return t, w


def profile_angle(time: Sequence[float], speed: Sequence[float]) -> float:
    """∫Ω_f dt (rad) of a piecewise-linear profile over its table (trapezoid rule, exact)."""
    t, w = np.asarray(time, float), np.asarray(speed, float)
    return float(np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(t)))


# --- inverse problem: the plan ------------------------------------------------------------------

@dataclass
class FlywheelPlan:
    """Result of :func:`plan_reorientation` (SI; vectors in the body frame)."""

    inertia: np.ndarray  # J1, J2, J3, kg·m² (body with the wheel locked)
    wheel_inertia: float  # J_f, kg·m²
    q_initial: np.ndarray  # (w, x, y, z) body → case
    q_target: np.ndarray  # (w, x, y, z) body → case
    axis: np.ndarray  # a, unit, the wheel axis
    companion: np.ndarray  # e_c = J⁻¹a/|J⁻¹a|, unit: the body's rotation axis (= −e)
    rotation_axis: np.ndarray  # e: the target is a turn by +body_turn about e (Euler's theorem)
    body_turn: float  # φ ∈ (0, π], rad
    lam: float  # λ = J_f |J⁻¹a|
    wheel_turn: float  # τ = φ/λ > 0, rad
    mu: float  # [S] angles of a, rad
    nu: float
    mu_star: float  # [S] angles of the companion axis e_c, rad
    nu_star: float
    time: list = field(default_factory=list)  # profile knots, s
    speed: list = field(default_factory=list)  # Ω_f at the knots, rad/s

    @property
    def end_time(self) -> float:
        return float(self.time[-1]) if self.time else 0.0

    def lines(self) -> list[str]:
        """Human-readable summary (SI)."""
        f = lambda v: "[" + ", ".join(f"{x:.9g}" for x in v) + "]"  # noqa: E731
        return [
            f"inertia J            {f(self.inertia)} kg·m² (body with the wheel locked)",
            f"wheel inertia J_f    {self.wheel_inertia:.6g} kg·m²",
            f"initial q            {f(self.q_initial)} (w, x, y, z; body → case)",
            f"target q             {f(self.q_target)}",
            f"body turn            {self.body_turn:.9g} rad ({math.degrees(self.body_turn):.6g} deg) about e = {f(self.rotation_axis)} (body)",
            f"wheel axis a         {f(self.axis)} (body)   mu = {self.mu:.9g} rad, nu = {self.nu:.9g} rad [S]",
            f"companion axis       {f(self.companion)} (body)   mu* = {self.mu_star:.9g} rad, nu* = {self.nu_star:.9g} rad [S] (24)",
            f"lambda = J_f|J⁻¹a|   {self.lam:.9g}   (|Ω_b| = lambda |Ω_f|) [S] (8)-(9)",
            f"wheel turn ∫Ω_f dt   {self.wheel_turn:.9g} rad ({self.wheel_turn / (2 * math.pi):.6g} rev) [S] (29)",
            f"profile time         {f(self.time)} s",
            f"profile speed        {f(self.speed)} rad/s",
        ]


def plan_reorientation(J: Sequence[float], J_f: float, q_target: Sequence[float],
                       q_initial: Sequence[float] = (1.0, 0.0, 0.0, 0.0), peak_speed: Optional[float] = None,
                       ramp: Optional[float] = None, duration: Optional[float] = None,
                       start: float = 0.0) -> FlywheelPlan:
    """Wheel axis, wheel turn and a trapezoid speed profile taking the body (at rest, L = 0) from
    ``q_initial`` to ``q_target`` (quaternions w, x, y, z, body → case; normalised here).

    [S] closing remarks with (24) inverted: q_initial⁻¹ ⊗ q_target = (cos ½φ, sin ½φ e) with φ ∈ (0, π]
    (Euler's theorem; e in the body frame); the companion axis must be ∓e, so a = −J e/|J e|
    (λ = J_f/|J e|) and the wheel turns forward by τ = φ/λ ([S] (29): the body turns by −λτ about
    J⁻¹a/|J⁻¹a| = −e, i.e. by +φ about e). Profile: :func:`trapezoid_profile` (two of peak_speed,
    ramp, duration), starting at ``start`` s. Raises ValueError if the target equals the start.
    """
    J = _inertia(J)
    if not (math.isfinite(J_f) and J_f > 0):
        raise ValueError(f"wheel inertia = {J_f}: must be a finite number > 0 (kg·m²)")
    q0, q1 = qnormalize(q_initial), qnormalize(q_target)
    d = qmul(qconj(q0), q1)
    if d[0] < 0:
        d = -d
    s = float(np.linalg.norm(d[1:]))
    phi = 2.0 * math.atan2(s, d[0])  # ∈ [0, π]
    if s < 1e-15:
        raise ValueError("the target attitude equals the initial one: there is nothing to turn")
    e = d[1:] / s
    a = -J * e
    a /= np.linalg.norm(a)
    lam = turn_ratio(J, J_f, a)
    tau = phi / lam
    t, w = trapezoid_profile(tau, peak_speed=peak_speed, ramp=ramp, duration=duration, start=start)
    mu, nu = axis_angles(a)
    ec = companion_axis(J, a)
    mu_s, nu_s = axis_angles(ec)
    return FlywheelPlan(inertia=J, wheel_inertia=float(J_f), q_initial=q0, q_target=q1, axis=a, companion=ec,
                        rotation_axis=e, body_turn=phi, lam=lam, wheel_turn=tau, mu=mu, nu=nu, mu_star=mu_s,
                        nu_star=nu_s, time=[float(x) for x in t], speed=[float(x) for x in w])


def plan_scene(plan: FlywheelPlan, name: str = "flywheel_plan", hold: float = 0.5,
               output_rate: float = 100.0, description: Optional[str] = None) -> dict:
    """A ready-to-run scene (dict, SI; dump with yaml) executing the plan: no fields, L = 0, the body
    at ``plan.q_initial`` (z-x-z Euler angles with L_direction z3, so the L-frame is the case frame),
    the flywheel effect with the plan's axis and profile; duration = end of the profile + ``hold`` s."""
    psi, theta, phi = euler_zxz(plan.q_initial)
    qt = ", ".join(f"{x:.12g}" for x in plan.q_target)
    desc = description or f"flywheel reorientation to the target attitude q = ({qt}) (w, x, y, z; body to case)"
    return {
        "name": name,
        "description": desc,
        "rotor": {"inertia": [float(x) for x in plan.inertia]},
        "torque_model": "none",
        "initial": {"kinetic_moment": 0.0, "L_direction": [0.0, 0.0, 1.0], "psi": float(psi), "theta": float(theta),
                    "phi": float(phi)},
        "duration": float(plan.end_time + hold),
        "output": {"rate": float(output_rate)},
        "effects": {"flywheel": {"inertia": float(plan.wheel_inertia), "axis": [float(x) for x in plan.axis],
                                 "profile": {"time": list(plan.time), "speed": list(plan.speed)}}},
    }
