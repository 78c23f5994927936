"""Scene section ``effects``: the other torques and internal bodies of physics.md §4 and [BS].

Every effect is off unless its key is present; an absent effect costs nothing at run time
(the kernels skip it on one flag). Units SI, vectors and matrices in the body frame unless said::

    effects:
      unbalance:                     # restoring moment of the Lagrange top [KLT] (13)
        k: 1.0e-4                    # N·m: k(Θ) = k + k1 cosΘ + k2 cos²Θ, N_b = k(Θ) sinΘ (cosφ, −sinφ, 0)
        k1: 0.0
        k2: 0.0
        vertical: [0, 0, 1]          # case frame: the direction Θ is measured from (up, against g)
      gas_drag:                      # [KLT] (17): N_b = −(I1 Ω1, I1 Ω2, I3 Ω3), slowly varying
        transverse: [1.0e-9]         # I1(t) = Σ c_k t^k, N·m·s (coefficients in N·m·s / s^k)
        axial: [1.0e-9]              # I3(t), same form
      magnetizable:                  # [BS] (2.3), (6.1): m = (1/μ0)[M B_b + P1 dB_b/dt + P2 d²B_b/dt²]
        M: [[..], [..], [..]]        # m³, symmetric (0 for a non-magnetic body)
        P1: null                     # m³·s, symmetric; null = the conductor's −2π r2³ τ_eff (isotropic)
        P2: null                     # m³·s², symmetric; null = the conductor's 2π r2³ Σ w_n τ_n²
      flywheel:                      # [S]: gyrostat, L_b = J Ω_b + J_f Ω_f(t) a
        inertia: 1.0e-6              # J_f, kg·m² (axial moment of the wheel)
        axis: [1, 0, 0]              # a, body frame, normalised on load
        profile: {time: [0, 1, 2], speed: [0, 100, 0]}   # Ω_f(t) relative to the body, rad/s,
                                     # piecewise linear; held at the end values outside
      damper:                        # [KLT] §1: point mass on a spring with viscous friction
        mass: 1.0e-3                 # m, kg
        radius: 0.01                 # ρ: the attachment point O1 = ρ x3, m
        stiffness: 100.0             # c, N/m (isotropic spring)
        damping: 1.0e-3              # δ, N·s/m

When ``magnetizable`` is on it replaces the eddy-mode model of the conductor (its P1, P2 are the
first two terms of the same transfer function); ``torque_model`` then only selects none vs on.
"""
from __future__ import annotations

import math
from typing import Annotated, Optional

from pydantic import Field, field_validator, model_validator

from gyro_ctl.numbers import Finite, real
from gyro_ctl.strict_model import StrictModel

__all__ = ["Effects", "Unbalance", "GasDrag", "Magnetizable", "Profile", "Flywheel", "Damper", "unit_vector"]

Vec3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Mat3 = Annotated[list[Vec3], Field(min_length=3, max_length=3)]


_Strict = StrictModel  # (unknown keys refused, immutable: gyro_ctl/strict_model.py)


def unit_vector(a: list[float], key: str) -> list[float]:
    """``a`` normalised; ValueError naming ``key`` for a zero vector. math.hypot: no overflow for 1e200 and no
    underflow for 1e-200 (a sum of squares has both); a second division where the first left the length off 1
    (subnormal components lose digits)."""
    n = math.hypot(*a)
    if n == 0:
        raise ValueError(f"{key} = {a}: must be a non-zero vector")
    u = [x / n for x in a]
    n = math.hypot(*u)
    return u if abs(n - 1.0) < 1e-12 else [x / n for x in u]


def _symmetric(m: Optional[list[list[float]]], key: str) -> Optional[list[list[float]]]:
    if m is None:
        return m
    for i in range(3):
        for j in range(i + 1, 3):
            a, b = m[i][j], m[j][i]
            if abs(a - b) > 1e-12 * max(abs(a), abs(b), 1e-300):
                raise ValueError(f"{key} = {m}: must be symmetric (element [{i}][{j}] = {a} but [{j}][{i}] = {b})")
    return m


class Unbalance(_Strict):
    """Lagrange-top restoring moment [KLT] (13): N = k(Θ) (v × x3), Θ = angle(v, x3)."""

    k: Finite  # N·m (m g d for a centre of mass d above the pivot)
    """Restoring-moment coefficient, N·m (m g d for a centre of mass at distance d from the pivot along x3): k(Θ) = k +
    k1 cosΘ + k2 cos²Θ."""
    k1: Finite = 0.0
    """Coefficient of cosΘ in k(Θ), N·m."""
    k2: Finite = 0.0
    """Coefficient of cos²Θ in k(Θ), N·m."""
    vertical: Vec3 = [0.0, 0.0, 1.0]
    """The direction Θ is measured from (up, against gravity), case frame (dimensionless; normalised)."""

    @field_validator("vertical")
    @classmethod
    def _v(cls, a):
        return unit_vector(a, "vertical")


class GasDrag(_Strict):
    """[KLT] (17): N_b = −(I1 Ω_b1, I1 Ω_b2, I3 Ω_b3); I(t) polynomials in t (s)."""

    transverse: Annotated[list[Finite], Field(min_length=1, max_length=3)]  # N·m·s / s^k
    """Coefficients c_k of I1(t) = Σ c_k t^k (t in s), N·m·s / s^k: drag on the transverse body rates."""
    axial: Annotated[list[Finite], Field(min_length=1, max_length=3)]
    """Coefficients of I3(t), same form, N·m·s / s^k: drag on the axial body rate."""


class Magnetizable(_Strict):
    """[BS] (2.3), (6.1): induced moment m = (1/μ0)[M B_b + P1 Ḃ_b + P2 B̈_b] (body matrices)."""

    M: Mat3 = [[0.0] * 3, [0.0] * 3, [0.0] * 3]  # m³
    """Static magnetisation matrix (body frame, symmetric), m³; zero for a non-magnetic body."""
    P1: Optional[Mat3] = None  # m³·s
    """First-order (lag) matrix, body frame, symmetric, m³·s; None: the conductor's −2π r2³ τ_eff (isotropic)."""
    P2: Optional[Mat3] = None  # m³·s²
    """Second-order matrix, body frame, symmetric, m³·s²; None: the conductor's 2π r2³ Σ w_n τ_n²."""

    @field_validator("M", "P1", "P2")
    @classmethod
    def _sym(cls, m, info):
        return _symmetric(m, info.field_name)


class Profile(_Strict):
    """A speed table of the flywheel: Ω_f (rad/s, relative to the body) at the given times (s), piecewise linear."""

    time: Annotated[list[Finite], Field(min_length=1, max_length=64)]  # s, increasing
    """Times of the table, s (strictly increasing)."""
    speed: Annotated[list[Finite], Field(min_length=1, max_length=64)]  # rad/s
    """Flywheel speed Ω_f relative to the body at those times, rad/s (piecewise linear; held outside the table)."""

    @model_validator(mode="after")
    def _table(self) -> "Profile":
        if len(self.time) != len(self.speed):
            raise ValueError(f"profile: time has {len(self.time)} entries but speed has {len(self.speed)}; they pair up")
        for i in range(1, len(self.time)):
            if not self.time[i] > self.time[i - 1]:
                raise ValueError(f"profile.time = {self.time}: must be strictly increasing (s)")
        return self


class Flywheel(_Strict):
    """[S]: internal flywheel of axial inertia J_f on the body axis a, speed Ω_f(t) relative to the body."""

    inertia: real(gt=0)  # kg·m²
    """Axial moment of inertia J_f of the wheel, kg·m²."""
    axis: Vec3
    """The wheel's axis a in the body frame (dimensionless; normalised)."""
    profile: Profile = Profile(time=[0.0], speed=[0.0])
    """Speed table Ω_f(t) of the wheel relative to the body (s, rad/s)."""

    @field_validator("axis")
    @classmethod
    def _a(cls, a):
        return unit_vector(a, "axis")


class Damper(_Strict):
    """[KLT] §1: point mass m at O1 = ρ x3 on an isotropic spring c with viscous friction δ."""

    mass: real(gt=0)  # kg
    """The moving point mass m, kg."""
    radius: real(ge=0)  # m
    """Distance ρ of its attachment point O1 = ρ x3 from the centre of mass, m."""
    stiffness: real(gt=0)  # N/m
    """Spring stiffness c (isotropic), N/m."""
    damping: real(ge=0) = 0.0  # N·s/m
    """Viscous friction δ, N·s/m."""
    offset: Vec3 = [0.0, 0.0, 0.0]  # initial displacement of the mass from O1, body frame, m
    """Initial displacement of the mass from O1, body frame, m."""
    velocity: Vec3 = [0.0, 0.0, 0.0]  # initial velocity relative to the body, m/s
    """Initial velocity of the mass relative to the body, body frame, m/s."""


class Effects(_Strict):
    """The scene's ``effects`` section: each effect is off unless its key is present."""

    unbalance: Optional[Unbalance] = None
    """Restoring moment of the Lagrange top ([KLT] (13)); None: off."""
    gas_drag: Optional[GasDrag] = None
    """Gas drag with slowly varying coefficients ([KLT] (17)); None: off."""
    magnetizable: Optional[Magnetizable] = None
    """Magnetizable or non-spherical body ([BS] (2.3), (6.1)); replaces the eddy-mode model; None: off."""
    flywheel: Optional[Flywheel] = None
    """Internal flywheel ([S]); None: off."""
    damper: Optional[Damper] = None
    """Viscoelastic element: a point mass on a spring ([KLT] §1); None: off."""

    @property
    def any(self) -> bool:
        return any(getattr(self, k) is not None for k in type(self).model_fields)
