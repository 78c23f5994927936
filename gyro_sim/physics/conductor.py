"""Eddy-current response of a conducting spherical rotor (physics.md section 3).

The rotor is a homogeneous, non-magnetic spherical shell (outer radius ``r2``,
inner radius ``r1``, conductivity ``sigma``; a solid sphere has ``r1 = 0``).
Seen from the body, it sits in a uniform field ``B_b(t)``; the induced magnetic
moment is the output of a linear, time-invariant filter.  With fields
proportional to ``exp(-i omega t)``

    m(omega) = (2 pi r2^3 / mu0) * g(omega) * B_b(omega)          [A m^2]

with the dimensionless transfer function ``g = 2 alpha / r2^3`` (alpha: Gaussian
polarizability of [M], m^3).  ``g(0) = 0`` and ``g -> -1`` for omega -> infinity
(perfect flux exclusion).

Closed forms (source [M] = Martynenko; docs/physics.md, Bibliography):

* thin shell, [M] (2.15):      g = i w tau / (1 - i w tau),  tau = mu0 sigma r2 h / 3
* solid sphere, [M] (2.14):    g = -[1 - 3/x^2 + (3/x) cot x],  x^2 = i w mu0 sigma a^2
* thick shell, [M] (2.13) as corrected in docs/physics.md §7 (the printed grouping of the
  denominator is dimensionally inconsistent).

The modal form used by the simulator (``ModalModel``) is the partial-fraction
expansion of these meromorphic functions of ``s = k^2 = i omega mu0 sigma``:

    g(omega) = sum_n w_n i w tau_n / (1 - i w tau_n)  +  i w tail_tau

i.e. a bank of first-order filters ``tau_n dm_n/dt + m_n = -(2 pi r2^3/mu0)
w_n tau_n dB_b/dt`` plus a static term for the truncated modes that keeps the
low-frequency (quasi-static) response exact.

All quantities are SI.  Angular frequencies are in rad/s and may be numpy arrays
(real or complex).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyro_sim.physics.constants import MU0

# scipy.optimize (brentq: a shell's poles) and scipy.special (zeta: the sphere's series and tail) are imported
# where they are used: a run of a thin shell needs neither, and importing them costs 0.1–0.2 s per process

__all__ = [
    "g_thin_shell",
    "g_solid_sphere",
    "alpha_shell",
    "g_shell",
    "shell_tau_eff",
    "ModalModel",
    "modal_thin_shell",
    "modal_solid_sphere",
    "modal_shell",
    "shell_pole_wavenumbers",
    "conductor_model",
    "DEFAULT_N_MODES",
]

#: default number of eddy-current modes kept by :func:`conductor_model`
DEFAULT_N_MODES = 10

# Small-|k| power series (in s = k^2 r2^2) are used for |s| < _SERIES_SWITCH,
# where the closed forms cancel badly.  The sphere's series of g converges like
# (|s| / pi^2)^n (ratio <= 0.2 here); the shell's numerator/denominator series are
# entire (sin/cos), with factorially decreasing terms.
_N_SERIES = 60
_SERIES_SWITCH = 2.0


# --------------------------------------------------------------------------- #
# helpers
# --------------------------------------------------------------------------- #
def _upper_root(z2):
    """sqrt(z2) on the branch with Im >= 0 (the functions used are even in it)."""
    z = np.sqrt(np.asarray(z2, dtype=complex))
    return np.where(z.imag < 0, -z, z)


def _tan_upper(z):
    """tan z for Im z >= 0 without overflow.

    Im z > 4: i (1 - q)/(1 + q), q = exp(2 i z) (|q| < 4e-4, no cancellation);
    otherwise numpy's tan (accurate there, and the q-form would lose
    ~eps/|z| for small |z|).
    """
    z = np.asarray(z, dtype=complex)
    q = np.exp(2j * np.where(z.imag > 4.0, z, 4j))
    return np.where(z.imag > 4.0, 1j * (1.0 - q) / (1.0 + q),
                    np.tan(np.where(z.imag > 4.0, 0.0, z)))


def _cot_upper(z):
    """cot z for Im z >= 0 without overflow: -i (1 + q)/(1 - q), q = exp(2 i z)."""
    q = np.exp(2j * z)
    return -1j * (1.0 + q) / (1.0 - q)


def _as_complex_array(omega):
    return np.asarray(omega, dtype=complex)


# --------------------------------------------------------------------------- #
# closed forms of [M]
# --------------------------------------------------------------------------- #
def g_thin_shell(omega, r2, h, sigma):
    """Transfer function of a thin shell, [M] (2.15).

    g = i w tau / (1 - i w tau),  tau = mu0 sigma r2 h / 3   (s).

    Parameters: omega [rad/s] (scalar or array, fields ~ exp(-i w t)),
    r2 outer radius [m], h wall thickness [m] (h << r2, h << skin depth),
    sigma conductivity [S/m].  Returns complex g (dimensionless).
    In [M] notation alpha' = -gamma xi w^2/(1 + xi^2 w^2), alpha'' = gamma w/(1 + xi^2 w^2),
    and g = 2 alpha / r2^3.
    """
    w = _as_complex_array(omega)
    tau = MU0 * sigma * r2 * h / 3.0  # [M] (2.15): xi = 4 pi lambda r2 h/(3 c^2)
    iwt = 1j * w * tau
    return iwt / (1.0 - iwt)


def g_solid_sphere(omega, a, sigma):
    """Transfer function of a solid sphere of radius a, [M] (2.14) (Landau-Lifshitz).

    g = -[1 - 3/x^2 + (3/x) cot x],   x^2 = i w mu0 sigma a^2.

    omega [rad/s] (scalar/array, real or complex), a [m], sigma [S/m]; returns
    complex g (dimensionless).  For |x|^2 < 2 the convergent series
    g = 6 sum_{n>=2} zeta(2n) x^(2n-2) / pi^(2n) = x^2/15 + 2 x^4/315 + ...
    is used (the closed form cancels to O(x^2)); otherwise cot is evaluated on the
    branch Im x >= 0 in the overflow-free form -i (1 + q)/(1 - q), q = exp(2ix).
    """
    w = _as_complex_array(omega)
    x2 = 1j * w * MU0 * sigma * a * a  # [M] (2.14): x^2 = i w mu0 sigma a^2
    x2f = x2.ravel()
    out = np.empty_like(x2f)
    small = np.abs(x2f) < _SERIES_SWITCH
    if np.any(small):
        from scipy.special import zeta

        n = np.arange(2, _N_SERIES + 2, dtype=float)
        coef = 6.0 * zeta(2 * n) / np.pi ** (2 * n)  # coefficient of x^(2n-2)
        out[small] = np.polynomial.polynomial.polyval(x2f[small], np.r_[0.0, coef])
    big = ~small
    if np.any(big):
        x = _upper_root(x2f[big])
        out[big] = -(1.0 - 3.0 / x2f[big] + 3.0 * _cot_upper(x) / x)  # [M] (2.14)
    return out.reshape(x2.shape)


def _shell_series(rho: float, n: int):
    """Power-series pieces of the corrected [M] (2.13) in units r2 = 1.

    Multiplying numerator and denominator of (2.13) by cos(kh) gives, with
    s = (k r2)^2, rho = r1/r2, eta = h/r2 = 1 - rho,

        alpha / r2^3 = eta * s * A(s) / (2 B(s)),

    where A(s) = [P(s) S(s eta^2) - 3 (s rho + 3) C(s eta^2)] / s^2 and
    B(s) = eta (3 - s rho^2) S(s eta^2) + 3 rho C(s eta^2) are entire in s
    (S(v) = sin(sqrt v)/sqrt v, C(v) = cos(sqrt v), P = s^2 rho^2 - 3s(rho^2+1-3rho) + 9).
    The s^0 and s^1 terms of the numerator cancel exactly (hence alpha(0) = 0);
    they are dropped analytically.  Returns the coefficient arrays (a, b), length n.
    (tan's own series would only converge for |s| eta^2 < pi^2/4.)
    """
    eta = 1.0 - rho
    e2 = eta * eta
    j = np.arange(n + 2)
    fact = np.cumprod(np.r_[1.0, np.arange(1.0, 2 * n + 5)])  # 0! .. (2n+4)!
    sig = (-1.0) ** j * e2 ** j / fact[2 * j + 1]  # S(s eta^2) coefficients of s^j
    gam = (-1.0) ** j * e2 ** j / fact[2 * j]  # C(s eta^2) coefficients of s^j
    p1 = -3.0 * (rho * rho + 1.0 - 3.0 * rho)  # coefficient of s in P(s)
    p2 = rho * rho  # coefficient of s^2 in P(s)
    m = np.arange(n)
    M = m + 2
    a = (9.0 * sig[M] + p1 * sig[M - 1] + p2 * sig[M - 2]
         - 9.0 * gam[M] - 3.0 * rho * gam[M - 1])
    b = 3.0 * eta * sig[m] + 3.0 * rho * gam[m]
    b[1:] -= eta * rho * rho * sig[m[1:] - 1]
    return a, b


def _alpha_shell_unit(s, rho: float):
    """alpha/r2^3 of the corrected [M] (2.13) as a function of s = (k r2)^2 (array)."""
    s = np.asarray(s, dtype=complex)
    sf = s.ravel()
    out = np.empty_like(sf)
    eta = 1.0 - rho
    small = np.abs(sf) < _SERIES_SWITCH
    if np.any(small):
        a, b = _shell_series(rho, _N_SERIES)
        pv = np.polynomial.polynomial.polyval
        ss = sf[small]
        out[small] = eta * ss * pv(ss, a) / (2.0 * pv(ss, b))
    big = ~small
    if np.any(big):
        s_b = sf[big]
        kap = _upper_root(s_b)  # k r2 with Im >= 0
        t = _tan_upper(kap * eta)  # tan(k h)
        # [M] (2.13), corrected grouping (physics.md section 3), r2 = 1 units
        num = ((s_b * s_b * rho * rho - 3.0 * s_b * (rho * rho + 1.0 - 3.0 * rho) + 9.0) * t
               - 3.0 * kap * eta * (s_b * rho + 3.0))
        den = 2.0 * s_b * ((3.0 - s_b * rho * rho) * t + 3.0 * kap * rho)
        out[big] = num / den
    return out.reshape(s.shape)


def _check_radii(r1, r2):
    if not (r2 > 0 and 0 <= r1 < r2):
        raise ValueError(f"need 0 <= r1 < r2, r2 > 0; got r1={r1!r}, r2={r2!r}")


def alpha_shell(omega, r1, r2, sigma):
    """Gaussian polarizability alpha(omega) of a spherical shell, [M] (2.13) corrected [m^3].

        alpha = r2 { [k^4 r1^2 r2^2 - 3k^2(r1^2 + r2^2 - 3 r1 r2) + 9] tan(kh)
                     - 3 k h (k^2 r1 r2 + 3) }
                / { 2 k^2 [ (3 - k^2 r1^2) tan(kh) + 3 k r1 ] },
        k^2 = i w mu0 sigma,  h = r2 - r1          (SI form of k^2 = 4 pi i lambda w / c^2)

    omega [rad/s] (scalar/array), radii [m] (0 <= r1 < r2), sigma [S/m].
    alpha is even in k; k is taken with Im k >= 0 and tan evaluated without
    overflow, so large |k h| is safe (alpha -> -r2^3/2).  The numerator vanishes
    like k^5 at k -> 0 (the closed form would lose ~(k r2)^-4 of precision), so for
    |k r2|^2 < 2 an exact power series in k^2 (numerator factor k^4
    cancelled analytically; sin, cos series) is used instead.
    """
    _check_radii(r1, r2)
    w = _as_complex_array(omega)
    s = 1j * w * MU0 * sigma * r2 * r2  # (k r2)^2
    return r2 ** 3 * _alpha_shell_unit(s, r1 / r2)


def g_shell(omega, r1, r2, sigma):
    """Transfer function g = 2 alpha / r2^3 of a shell of any thickness ([M] (2.13)).

    Dimensionless; omega [rad/s], radii [m], sigma [S/m].
    """
    _check_radii(r1, r2)
    w = _as_complex_array(omega)
    s = 1j * w * MU0 * sigma * r2 * r2
    return 2.0 * _alpha_shell_unit(s, r1 / r2)  # g = 2 alpha / r2^3


def _shell_g_coeffs(rho: float, n: int) -> np.ndarray:
    """Taylor coefficients G_j of g = sum_{j>=1} G_j s^j, s = (k r2)^2, from (2.13).

    Returned array has G_1..G_n (index 0 -> G_1).  Power-series division of
    eta s A(s) / B(s).
    """
    eta = 1.0 - rho
    a, b = _shell_series(rho, n)
    q = np.zeros(n)
    for j in range(n):  # q = A / B
        q[j] = (a[j] - np.dot(b[1:j + 1], q[j - 1::-1][:j])) / b[0]
    return eta * q  # g = 2 * alpha/r2^3 = eta s A/B


def shell_tau_eff(r1, r2, sigma):
    """Low-frequency time constant of a shell, tau_eff = mu0 sigma (r2^5 - r1^5)/(15 r2^3) [s].

    g = i w tau_eff + O(w^2).  Closed form from the k^2 term of the series of
    [M] (2.13) (equivalently: unscreened eddy currents E = (r x dB/dt)/2); it
    gives mu0 sigma a^2/15 for the sphere and mu0 sigma r2 h/3 for a thin shell.
    """
    _check_radii(r1, r2)
    return MU0 * sigma * (r2 ** 5 - r1 ** 5) / (15.0 * r2 ** 3)


# --------------------------------------------------------------------------- #
# modal model
# --------------------------------------------------------------------------- #
@dataclass(frozen=True, eq=False)
class ModalModel:
    """Partial-fraction (modal) eddy-current model of a spherical rotor.

    g(w) = sum_n w_n i w tau_n/(1 - i w tau_n) + i w tail_tau.

    Fields
    ------
    tau : mode time constants tau_n [s]
    weight : mode weights w_n [-] (sum -> 1 over all modes: g -> -1 at high w)
    tail_tau : sum over the neglected modes of w_n tau_n [s]; the static term
        m_tail = -(2 pi r2^3/mu0) tail_tau dB_b/dt keeps the low-frequency
        response exact (valid for w << 1/tau_{N+1}; it grows without bound above).
    radius : outer radius r2 [m]
    kind : "thin_shell", "solid_sphere" or "shell"
    """

    tau: np.ndarray
    weight: np.ndarray
    tail_tau: float
    radius: float
    kind: str

    def __post_init__(self):
        tau = np.array(self.tau, dtype=float).ravel()
        weight = np.array(self.weight, dtype=float).ravel()
        if tau.shape != weight.shape:
            raise ValueError("tau and weight must have the same length")
        tau.setflags(write=False)
        weight.setflags(write=False)
        object.__setattr__(self, "tau", tau)
        object.__setattr__(self, "weight", weight)
        object.__setattr__(self, "tail_tau", float(self.tail_tau))
        object.__setattr__(self, "radius", float(self.radius))

    @property
    def n_modes(self) -> int:
        return int(self.tau.size)

    def g(self, omega):
        """Modal transfer function g(omega) (dimensionless); omega [rad/s], array ok."""
        w = _as_complex_array(omega)
        iwt = 1j * w[..., None] * self.tau
        return (np.sum(self.weight * iwt / (1.0 - iwt), axis=-1)
                + 1j * w * self.tail_tau)

    @property
    def tau_eff(self) -> float:
        """Quasi-static time constant sum w_n tau_n + tail_tau [s]."""
        return float(np.sum(self.weight * self.tau) + self.tail_tau)

    @property
    def moment_scale(self) -> float:
        """2 pi r2^3 / mu0 [A m^2 / T]: m = moment_scale * g * B_b."""
        return 2.0 * np.pi * self.radius ** 3 / MU0

    @property
    def k_e(self) -> float:
        """Quasi-static torque coefficient k_e = 2 pi r2^3 tau_eff / mu0 [N m s / T^2].

        N = k_e B x (B x Omega + dB/dt), [K] (1.2).
        """
        return self.moment_scale * self.tau_eff


def modal_thin_shell(r2, h, sigma) -> ModalModel:
    """Single-mode model of a thin shell, [M] (2.15): w = 1, tau = mu0 sigma r2 h/3, no tail."""
    tau = MU0 * sigma * r2 * h / 3.0  # [M] (2.15)
    return ModalModel(tau=np.array([tau]), weight=np.array([1.0]), tail_tau=0.0,
                      radius=r2, kind="thin_shell")


def modal_solid_sphere(a, sigma, n_modes=DEFAULT_N_MODES) -> ModalModel:
    """Modal form of [M] (2.14) for a solid sphere of radius a [m].

    w_n = 6/(n^2 pi^2), tau_n = mu0 sigma a^2/(n^2 pi^2), n = 1..n_modes;
    tail_tau = sum_{n>N} w_n tau_n = (6 mu0 sigma a^2/pi^4) zeta(4, N+1)
    (sum over all n is mu0 sigma a^2/15).
    """
    from scipy.special import zeta

    n = np.arange(1, n_modes + 1, dtype=float)
    t0 = MU0 * sigma * a * a
    tau = t0 / (n * n * np.pi ** 2)  # poles of [M] (2.14): x = n pi
    weight = 6.0 / (n * n * np.pi ** 2)
    tail = 6.0 * t0 / np.pi ** 4 * float(zeta(4.0, n_modes + 1))
    return ModalModel(tau=tau, weight=weight, tail_tau=tail, radius=a,
                      kind="solid_sphere")


def _shell_phase(u):
    """phi(u) = arg(3 - u^2 + 3 i u), continuous and increasing from 0 (u=0) to pi."""
    r3 = np.sqrt(3.0)
    return np.arctan((2.0 * u - r3) / 3.0) + np.arctan((2.0 * u + r3) / 3.0)


def shell_pole_wavenumbers(r1, r2, n_modes) -> np.ndarray:
    """Real wavenumbers k_n [1/m] of the poles of (2.13), n = 1..n_modes, ascending.

    The poles are the roots of D(k) = (3 - k^2 r1^2) tan(kh) + 3 k r1 = 0.  Written
    without the tan poles, D cos(kh) = A(k) sin(k h + phi(k r1)) with
    A > 0 and phi(u) = arg(3 - u^2 + 3iu) strictly increasing from 0 to pi, so the
    n-th root is the unique solution of k h + phi(k r1) = n pi and lies in
    ((n-1) pi/h, n pi/h): every root found once, in order, none spurious.
    """
    from scipy.optimize import brentq

    _check_radii(r1, r2)
    h = r2 - r1
    ks = np.empty(n_modes)
    for n in range(1, n_modes + 1):
        f = lambda k, n=n: k * h + _shell_phase(k * r1) - n * np.pi  # noqa: E731
        lo, hi = (n - 1) * np.pi / h, n * np.pi / h
        # f(lo) = phi - pi < 0 and f(hi) = phi > 0 analytically; if rounding
        # (phi ~ 0 for r1 -> 0, phi ~ pi for thin shells) flips one of them, the root
        # is within round-off of that end.
        if f(hi) <= 0.0:
            ks[n - 1] = hi
        elif f(lo) >= 0.0:
            ks[n - 1] = lo
        else:
            ks[n - 1] = brentq(f, lo, hi, xtol=1e-15 * hi,
                               rtol=4 * np.finfo(float).eps, maxiter=200)
    return ks


def modal_shell(r1, r2, sigma, n_modes=DEFAULT_N_MODES) -> ModalModel:
    """Modal form of the corrected [M] (2.13) for a shell of any thickness.

    Poles s_n = k_n^2 of alpha(s) (s = k^2 = i w mu0 sigma) from
    :func:`shell_pole_wavenumbers`; with alpha = r2 N(k)/(2 k^2 F(k)),
    F = (3 - k^2 r1^2) sin(kh) + 3 k r1 cos(kh), N = P(k) sin(kh) - 3kh(k^2 r1 r2 + 3) cos(kh),
    the residue in s is R_n = r2 N(k_n)/(k_n F'(k_n)), and comparing with
    sum_n w_n s/(s_n - s):  w_n = -2 R_n/(r2^3 s_n),  tau_n = mu0 sigma / s_n.
    tail_tau = tau_eff (exact k^2 slope of (2.13), :func:`shell_tau_eff`) - sum kept w_n tau_n.
    r1 = 0 gives the sphere's modes; h << r2 one dominant mode with tau ~ mu0 sigma r2 h/3.
    """
    _check_radii(r1, r2)
    h = r2 - r1
    k = shell_pole_wavenumbers(r1, r2, n_modes)
    kh = k * h
    sn, cs = np.sin(kh), np.cos(kh)
    # numerator of (2.13) times cos(kh), divided by r2 (P(k) in brackets)
    P = k ** 4 * r1 ** 2 * r2 ** 2 - 3.0 * k ** 2 * (r1 ** 2 + r2 ** 2 - 3.0 * r1 * r2) + 9.0
    Nk = P * sn - 3.0 * kh * (k ** 2 * r1 * r2 + 3.0) * cs
    # F(k) = A(k) sin(kh + phi(k r1)) -> F'(k_n) = A (-1)^n (h + r1 phi'(k r1))
    u = k * r1
    amp = np.sqrt((3.0 - u * u) ** 2 + 9.0 * u * u)
    dphi = 3.0 * (3.0 + u * u) / ((3.0 - u * u) ** 2 + 9.0 * u * u)  # d phi/du
    sign = np.where(np.arange(1, n_modes + 1) % 2 == 0, 1.0, -1.0)
    dF = amp * sign * (h + r1 * dphi)
    s_n = k * k
    R = r2 * Nk / (k * dF)  # residue of alpha in s
    weight = -2.0 * R / (r2 ** 3 * s_n)
    tau = MU0 * sigma / s_n
    tail = shell_tau_eff(r1, r2, sigma) - float(np.sum(weight * tau))
    return ModalModel(tau=tau, weight=weight, tail_tau=tail, radius=r2, kind="shell")


def conductor_model(kind, outer_radius, conductivity, thickness=None,
                    n_modes=DEFAULT_N_MODES) -> ModalModel:
    """Build the modal eddy-current model of the rotor.

    kind : "thin_shell" ([M] (2.15), one mode; thickness required),
           "solid_sphere" ([M] (2.14); thickness ignored unless equal to the radius),
           "shell" (corrected [M] (2.13); thickness h = r2 - r1 required, 0 < h <= r2).
    outer_radius r2 [m], conductivity sigma [S/m], thickness [m], n_modes >= 1.
    """
    r2 = float(outer_radius)
    sigma = float(conductivity)
    if r2 <= 0 or sigma <= 0:
        raise ValueError("outer_radius and conductivity must be positive")
    if int(n_modes) < 1:
        raise ValueError("n_modes must be >= 1")
    if kind == "thin_shell":
        if thickness is None or not (0 < thickness <= r2):
            raise ValueError("thin_shell needs 0 < thickness <= outer_radius")
        return modal_thin_shell(r2, float(thickness), sigma)
    if kind == "solid_sphere":
        if thickness is not None and not np.isclose(thickness, r2):
            raise ValueError("solid_sphere: thickness must be None or equal the radius")
        return modal_solid_sphere(r2, sigma, int(n_modes))
    if kind == "shell":
        if thickness is None or not (0 < thickness <= r2):
            raise ValueError("shell needs 0 < thickness <= outer_radius")
        return modal_shell(r2 - float(thickness), r2, sigma, int(n_modes))
    raise ValueError(f"unknown conductor kind {kind!r}; "
                     "expected 'thin_shell', 'solid_sphere' or 'shell'")
