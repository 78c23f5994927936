"""Tests of gyro_sim.physics.conductor against the closed forms of [M] (physics.md section 6, item 1).

Every test prints the error it measured and asserts it against a stated tolerance.
Units: sigma = 1/mu0 and r2 = 1 m, so omega (rad/s) equals the dimensionless
frequency omega mu0 sigma r2^2 used in physics.md.
"""
import numpy as np
import pytest
from scipy.special import spherical_jn, spherical_yn

from gyro_sim.physics.conductor import (
    ModalModel,
    alpha_shell,
    conductor_model,
    g_shell,
    g_solid_sphere,
    g_thin_shell,
    modal_shell,
    modal_solid_sphere,
    modal_thin_shell,
    shell_pole_wavenumbers,
    shell_tau_eff,
)
from gyro_sim.physics.constants import MU0

SIG = 1.0 / MU0  # mu0 sigma = 1 s/m^2
X = np.logspace(-2, 3, 501)  # omega mu0 sigma a^2 grid of physics.md


def relerr(a, b):
    return np.abs(a - b) / np.abs(b)


def max_upto(err, xmax):
    return float(err[X <= xmax * (1 + 1e-12)].max())


def untailed(m: ModalModel) -> ModalModel:
    return ModalModel(m.tau, m.weight, 0.0, m.radius, m.kind)


# --------------------------------------------------------------------------- #
# independent references
# --------------------------------------------------------------------------- #
def alpha_bvp(omega, r1, r2, sigma):
    """alpha from the boundary-value problem of [M] section 2, solved numerically.

    A = [B x n] f(r) e^{-i w t}: f0 = r/2 + alpha/r^2 (outside), f1 = C1 r (cavity),
    f2 = C2 j1(kr) + D2 y1(kr) (conductor); f and f' continuous at r1 and r2
    (B_r and B_tangential continuous, mu = 1).  Independent of the closed form (2.13).
    """
    k = np.sqrt(1j * omega * MU0 * sigma)

    def j(z, d=False):
        return spherical_jn(1, z, derivative=d)

    def y(z, d=False):
        return spherical_yn(1, z, derivative=d)

    M = np.array([
        [0, r1, -j(k * r1), -y(k * r1)],
        [0, 1, -k * j(k * r1, True), -k * y(k * r1, True)],
        [-1 / r2 ** 2, 0, j(k * r2), y(k * r2)],
        [2 / r2 ** 3, 0, k * j(k * r2, True), k * y(k * r2, True)],
    ], dtype=complex)
    return np.linalg.solve(M, np.array([0, 0, r2 / 2, 0.5], dtype=complex))[0]


def g_sphere_printed(omega, a, sigma):
    """[M] (2.14) exactly as printed (real form), y = sqrt(eta w), eta w = w mu0 sigma a^2/2."""
    y = np.sqrt(omega * MU0 * sigma * a * a / 2.0)
    d = np.cosh(2 * y) - np.cos(2 * y)
    re = -1.0 + 1.5 / y * (np.sinh(2 * y) - np.sin(2 * y)) / d  # 2 alpha'/r2^3
    im = 1.5 * (-1.0 / y ** 2 + (np.sinh(2 * y) + np.sin(2 * y)) / (y * d))  # 2 alpha''/r2^3
    return re + 1j * im


# --------------------------------------------------------------------------- #
# closed forms
# --------------------------------------------------------------------------- #
def test_sphere_cot_form_matches_printed_real_form():
    """(2.14) as cot of complex x agrees with [M]'s printed sh/ch form (and sign convention)."""
    x = np.logspace(-1, 3, 201)
    err = relerr(g_solid_sphere(x, 1.0, SIG), g_sphere_printed(x, 1.0, SIG)).max()
    print(f"\n(2.14) cot form vs printed real form: max rel err {err:.2e} (tol 1e-11)")
    assert err < 1e-11


def test_thin_shell_matches_printed_2_15():
    """g_thin_shell equals [M] (2.15) alpha', alpha'' (gamma = r2^3 xi/2, xi = tau)."""
    r2, h = 1.0, 1e-3
    tau = MU0 * SIG * r2 * h / 3
    w = np.logspace(-2, 3, 101) / tau
    gam = r2 ** 3 * tau / 2
    alpha = -gam * tau * w ** 2 / (1 + tau ** 2 * w ** 2) + 1j * gam * w / (1 + tau ** 2 * w ** 2)
    err = relerr(g_thin_shell(w, r2, h, SIG), 2 * alpha / r2 ** 3).max()
    print(f"\n(2.15) vs printed alpha', alpha'': max rel err {err:.2e} (tol 1e-14)")
    assert err < 1e-14


@pytest.mark.parametrize("r1", [0.1, 0.5, 0.9])
def test_corrected_2_13_vs_boundary_value_problem(r1):
    """The corrected (2.13) solves [M]'s boundary-value problem (independent derivation)."""
    w = np.logspace(-1, 2, 31)
    ref = np.array([alpha_bvp(x, r1, 1.0, SIG) for x in w])
    err = relerr(alpha_shell(w, r1, 1.0, SIG), ref).max()
    print(f"\nr1={r1}: corrected (2.13) vs BVP solve, w in [0.1, 100]: max rel err {err:.2e} "
          "(tol 1e-9)")
    assert err < 1e-9


def test_printed_grouping_of_2_13_is_wrong():
    """The printed denominator 2k^2(3 - k^2 r1^2) tan(kh) + 3k r1 misses the thin-shell limit."""
    r1, r2 = 0.99, 1.0
    h = r2 - r1
    w = np.logspace(-2, 2, 41) / (h / 3)
    k = np.sqrt(1j * w)
    t = np.tan(k * h)
    num = r2 * ((k ** 4 * r1 ** 2 * r2 ** 2 - 3 * k ** 2 * (r1 ** 2 + r2 ** 2 - 3 * r1 * r2) + 9) * t
                - 3 * k * h * (k ** 2 * r1 * r2 + 3))
    printed = num / (2 * k ** 2 * (3 - k ** 2 * r1 ** 2) * t + 3 * k * r1)
    ref = g_thin_shell(w, r2, h, SIG)
    err_printed = relerr(2 * printed / r2 ** 3, ref).max()
    err_corr = relerr(g_shell(w, r1, r2, SIG), ref).max()
    print(f"\nthin shell h=0.01: printed grouping err {err_printed:.2e}, corrected {err_corr:.2e}")
    assert err_corr < 0.03 < 0.5 < err_printed


def test_2_13_solid_sphere_limit():
    """(2.13) -> (2.14) as r1 -> 0; exact at r1 = 0, relative error (r1/r2)^5 otherwise."""
    ex = g_solid_sphere(X, 1.0, SIG)
    e0 = relerr(g_shell(X, 0.0, 1.0, SIG), ex).max()
    print(f"\nr1 = 0: (2.13) vs (2.14): max rel err {e0:.2e} (tol 1e-14)")
    assert e0 < 1e-14
    for rho in (0.2, 0.1, 0.05):
        e = relerr(g_shell(X, rho, 1.0, SIG), ex).max()
        print(f"r1/r2 = {rho}: max rel err {e:.3e}, err/(r1/r2)^5 = {e / rho ** 5:.4f} "
              "(expected 1: tau_eff ~ r2^5 - r1^5; tol [0.99, 1.01])")
        assert 0.99 < e / rho ** 5 < 1.01


def test_2_13_thin_shell_limit():
    """(2.13) -> (2.15) as h -> 0 at fixed w tau: relative error = 2 h/r2 + O(h^2).

    First order: the exact low-frequency slope is tau_eff = mu0 sigma (r2^5 - r1^5)/(15 r2^3)
    = (mu0 sigma r2 h/3)(1 - 2h/r2 + ...), while (2.15) uses mu0 sigma r2 h/3.
    """
    wt = np.logspace(-2, 3, 201)
    for h in (1e-2, 1e-3, 1e-4):
        w = wt / (h / 3)
        e = relerr(g_shell(w, 1.0 - h, 1.0, SIG), g_thin_shell(w, 1.0, h, SIG)).max()
        print(f"\nh/r2 = {h:.0e}: max rel err (2.13) vs (2.15) over w tau in [1e-2, 1e3]: {e:.3e}, "
              f"err/(h/r2) = {e / h:.4f} (expected 2, tol +-0.05)")
        assert abs(e / h - 2.0) < 0.05


def test_closed_form_limits_zero_and_infinity():
    """g(0) = 0 exactly; g -> -1 with |g + 1| ~ 3/|x| at high frequency (skin effect)."""
    for name, f in [("sphere", lambda w: g_solid_sphere(w, 1.0, SIG)),
                    ("shell 0.5", lambda w: g_shell(w, 0.5, 1.0, SIG)),
                    ("shell 0.99", lambda w: g_shell(w, 0.99, 1.0, SIG))]:
        g0 = f(np.array([0.0]))[0]
        w = np.array([1e8, 1e10, 1e12, 1e14])
        gi = f(w)
        scaled = np.abs(gi + 1.0) * np.sqrt(w) / 3.0  # |x| = sqrt(w) here
        print(f"\n{name}: g(0) = {g0}, |g+1|*|x|/3 at w=1e8..1e14: {np.round(scaled, 4)}")
        assert g0 == 0
        assert np.all(np.isfinite(gi))
        assert np.all(scaled < 1.2)
        assert np.all(np.abs(gi + 1.0) < 1e-3)


def test_2_13_against_high_precision():
    """Double-precision (2.13) (series at small k, overflow-free tan at large k) vs mpmath."""
    import mpmath as mp
    mp.mp.dps = 50

    def alpha_mp(w, r1, r2):
        k = mp.sqrt(1j * mp.mpf(w))
        r1, r2 = mp.mpf(r1), mp.mpf(r2)
        h = r2 - r1
        t = mp.tan(k * h)
        num = r2 * ((k ** 4 * r1 ** 2 * r2 ** 2 - 3 * k ** 2 * (r1 ** 2 + r2 ** 2 - 3 * r1 * r2) + 9) * t
                    - 3 * k * h * (k ** 2 * r1 * r2 + 3))
        return complex(num / (2 * k ** 2 * ((3 - k ** 2 * r1 ** 2) * t + 3 * k * r1)))

    w = np.r_[np.logspace(-8, 10, 37), np.linspace(0.5, 4.0, 15)]
    worst = 0.0
    for r1 in (0.0, 0.3, 0.9, 0.999, 1 - 1e-7):
        ref = np.array([alpha_mp(x, r1, 1.0) for x in w])
        e = relerr(alpha_shell(w, r1, 1.0, SIG), ref).max()
        worst = max(worst, e)
        print(f"\nr1={r1}: alpha_shell vs 50-digit (2.13), w in [1e-8, 1e10]: max rel err {e:.2e}")
    assert worst < 1e-13


# --------------------------------------------------------------------------- #
# modal models
# --------------------------------------------------------------------------- #
def test_modal_sphere_vs_2_14():
    """Modal sphere with tail vs (2.14): the figures of physics.md section 3."""
    ex = g_solid_sphere(X, 1.0, SIG)
    cases = [  # (N, x, tolerance) ; physics.md: 2e-6, 1e-4, 5e-8, 4e-6
        (10, 10, 3e-6), (10, 100, 1.5e-4), (50, 100, 7e-8), (50, 1000, 5e-6)]
    for n, xm, tol in cases:
        m = modal_solid_sphere(1.0, SIG, n)
        e = max_upto(relerr(m.g(X), ex), xm)
        e0 = max_upto(relerr(untailed(m).g(X), ex), xm)
        print(f"\nN={n}, w mu0 sigma a^2 <= {xm}: max rel err {e:.2e} (tol {tol:.1e}); "
              f"without tail {e0:.2e} ({e0 / e:.0f}x larger)")
        assert e < tol
        assert e0 > 10 * e


@pytest.mark.parametrize("r1", [0.5, 0.2, 0.9])
def test_modal_shell_vs_2_13(r1):
    """Modal thick shell (poles and residues of (2.13)) vs (2.13) itself."""
    ex = g_shell(X, r1, 1.0, SIG)
    tol = {  # measured (r1 = 0.5): 1.0e-7, 6.0e-6, 5.1e-4 ; 2.8e-11, 1.6e-9, 1.4e-7
        10: {10: 2e-6, 100: 1e-4, 1000: 8e-3},
        50: {10: 5e-10, 100: 3e-8, 1000: 3e-6},
    }
    for n in (10, 50):
        m = modal_shell(r1, 1.0, SIG, n)
        g, g0 = m.g(X), untailed(m).g(X)
        for xm in (10, 100, 1000):
            e = max_upto(relerr(g, ex), xm)
            e0 = max_upto(relerr(g0, ex), xm)
            print(f"\nr1={r1} N={n} x<={xm}: max rel err {e:.2e} (tol {tol[n][xm]:.1e}), "
                  f"no tail {e0:.2e}")
            assert e < tol[n][xm]
            assert e0 > 2 * e


def test_modal_shell_weights_sum_to_one():
    """Sum of weights -> 1 (g -> -1): S_N = 1 - c/N + ..., Richardson 2 S_2N - S_N -> 1."""
    s1 = modal_shell(0.5, 1.0, SIG, 1000).weight.sum()
    m2 = modal_shell(0.5, 1.0, SIG, 2000)
    s2 = m2.weight.sum()
    rich = 2 * s2 - s1
    print(f"\nr1=0.5: S_1000 = {s1:.8f}, S_2000 = {s2:.8f}, Richardson {rich:.10f}, "
          f"|1 - R| = {abs(1 - rich):.1e} (tol 1e-6)")
    assert abs(1 - rich) < 1e-6
    assert s1 < s2 < 1
    assert np.all(m2.weight > 0) and np.all(np.diff(m2.tau) < 0)
    # high-frequency value of the modes alone is -sum w_n
    gi = untailed(m2).g(np.array([1e12]))[0]
    print(f"untailed modal g(1e12) = {gi:.6f}; g(0) = {m2.g(np.array([0.0]))[0]}")
    assert abs(gi + s2) < 1e-6 and m2.g(np.array([0.0]))[0] == 0


def test_shell_poles_complete_and_ordered():
    """Every root of (3 - k^2 r1^2) tan(kh) + 3 k r1 = 0 found once, in order, none spurious.

    Independent count: sign changes of F = (3 - k^2 r1^2) sin(kh) + 3 k r1 cos(kh) (no tan
    poles) on a fine grid; and D(k_n) ~ 0 in the tan form (poles of tan are not roots).
    """
    worst = 0.0
    for r1, r2 in [(0.5, 1.0), (0.05, 1.0), (0.99, 1.0), (0.7, 1.3)]:
        h = r2 - r1
        n = 40
        k = shell_pole_wavenumbers(r1, r2, n)
        kk = np.linspace(1e-9, k[-1] + 0.5 * np.pi / h, 400001)
        F = (3 - kk ** 2 * r1 ** 2) * np.sin(kk * h) + 3 * kk * r1 * np.cos(kk * h)
        changes = int(np.sum(np.sign(F[1:]) != np.sign(F[:-1])))
        D = (3 - k ** 2 * r1 ** 2) * np.tan(k * h) + 3 * k * r1
        scale = np.abs(3 - k ** 2 * r1 ** 2) * np.abs(1 / np.cos(k * h)) + 3 * k * r1
        res = float(np.max(np.abs(D) / scale))
        worst = max(worst, res)
        print(f"\nr1={r1}, r2={r2}: {n} roots, grid sign changes {changes}, "
              f"max |D(k_n)|/scale {res:.1e}")
        assert changes == n
        assert np.all(np.diff(k) > 0)
        idx = np.arange(1, n + 1)
        assert np.all(((idx - 1) * np.pi / h < k) & (k < idx * np.pi / h))
    assert worst < 1e-12


def test_modal_shell_limits():
    """r1 -> 0 gives the sphere's modes; a thin shell has one dominant mode, tau ~ mu0 sigma r2 h/3."""
    ms = modal_solid_sphere(1.0, SIG, 30)
    for r1, tol in [(0.0, 1e-12), (1e-6, 1e-9)]:
        m = modal_shell(r1, 1.0, SIG, 30)
        et = relerr(m.tau, ms.tau).max()
        ew = relerr(m.weight, ms.weight).max()
        etail = abs(m.tail_tau - ms.tail_tau) / ms.tail_tau
        print(f"\nr1={r1}: shell vs sphere modes: tau err {et:.1e}, weight err {ew:.1e}, "
              f"tail err {etail:.1e} (tol {tol:.0e}; tail, a difference: 1e-6)")
        assert et < tol and ew < tol and etail < 1e-6
    for h in (1e-2, 1e-3):
        m = modal_shell(1.0 - h, 1.0, SIG, 20)
        tau_t = h / 3
        print(f"h/r2={h:.0e}: w1 = {m.weight[0]:.6f} (1-w1 = {1 - m.weight[0]:.2e}), "
              f"tau1/(mu0 sigma r2 h/3) - 1 = {m.tau[0] / tau_t - 1:.2e}, w2 = {m.weight[1]:.2e}, "
              f"tau2/tau1 = {m.tau[1] / m.tau[0]:.1e} (tol: all O(h/r2), 1.1 h)")
        assert 1 - m.weight[0] < 1.1 * h
        assert abs(m.tau[0] / tau_t - 1) < 1.1 * h
        assert m.tau[1] / m.tau[0] < h


# --------------------------------------------------------------------------- #
# low frequency
# --------------------------------------------------------------------------- #
def test_low_frequency_tau_eff():
    """g = i w tau_eff + O(w^2): sphere mu0 sigma a^2/15, thin shell mu0 sigma r2 h/3,
    shell mu0 sigma (r2^5 - r1^5)/(15 r2^3); modal models carry the same tau_eff."""
    w = 1e-7
    cases = [
        ("sphere (2.14)", g_solid_sphere(w, 1.0, SIG), 1.0 / 15),
        ("thin shell (2.15)", g_thin_shell(w, 1.0, 1e-3, SIG), 1e-3 / 3),
        ("shell 0.5 (2.13)", g_shell(w, 0.5, 1.0, SIG), (1 - 0.5 ** 5) / 15),
        ("shell 0.999 (2.13)", g_shell(w, 0.999, 1.0, SIG), (1 - 0.999 ** 5) / 15),
    ]
    for name, g, te in cases:
        e = abs(g / (1j * w * te) - 1)
        print(f"\n{name}: |g/(i w tau_eff) - 1| at w=1e-7: {e:.1e} (tol 1e-7)")
        assert e < 1e-7
    # the k^2 coefficient of the series of (2.13) equals the closed form (r2^5 - r1^5)/(15 r2^3)
    from gyro_sim.physics.conductor import _shell_g_coeffs
    eg = max(abs(_shell_g_coeffs(rho, 2)[0] / ((1 - rho ** 5) / 15) - 1)
             for rho in (0.0, 0.3, 0.5, 0.9, 0.999))
    print(f"series of (2.13): G1 vs (1 - rho^5)/15: max rel err {eg:.1e} (tol 1e-12)")
    assert eg < 1e-12
    for m, te in [(modal_solid_sphere(1.0, SIG, 5), 1 / 15),
                  (modal_thin_shell(1.0, 1e-3, SIG), 1e-3 / 3),
                  (modal_shell(0.5, 1.0, SIG, 5), shell_tau_eff(0.5, 1.0, SIG))]:
        e = abs(m.tau_eff / te - 1)
        print(f"{m.kind}: modal tau_eff rel err {e:.1e} (tol 1e-13)")
        assert e < 1e-13
    # k_e of [K] (1.2): sphere (2 pi/15) sigma a^5, thin shell (2 pi/3) sigma r2^4 h
    a, r2, h, sigma = 0.02, 0.025, 1e-4, 3.5e7
    e1 = abs(modal_solid_sphere(a, sigma, 10).k_e / (2 * np.pi / 15 * sigma * a ** 5) - 1)
    e2 = abs(modal_thin_shell(r2, h, sigma).k_e / (2 * np.pi / 3 * sigma * r2 ** 4 * h) - 1)
    print(f"k_e sphere rel err {e1:.1e}, thin shell {e2:.1e} (tol 1e-13)")
    assert e1 < 1e-13 and e2 < 1e-13


def test_second_coefficient_sphere():
    """Second coefficient of the sphere: g = i w tau_eff + c2 (i w)^2 + ...

    From (2.14): x cot x = 1 - x^2/3 - x^4/45 - 2x^6/945 - ..., so
    g = -1 + 3/x^2 - (3/x) cot x = x^2/15 + 2 x^4/315 + ...,  x^2 = i w mu0 sigma a^2:
    c2 = +(2/315)(mu0 sigma)^2 a^4 (the coefficient of w^2 is -2/315 (mu0 sigma a^2)^2).
    Modal form: g = sum w_n [i w tau_n + (i w tau_n)^2 + ...] -> c2 = sum w_n tau_n^2
    = 6 zeta(6)/pi^6 (mu0 sigma a^2)^2 = 2/315 (mu0 sigma a^2)^2.
    [BS]: m = P1 dB/dt + P2 d^2B/dt^2 with P(1) = -a^5 lambda/30, P(2) = a^7 lambda^2/315
    (epsilon = 4 pi/c^2 absorbed): P2/P1 = -(2/21) a^2 lambda eps.  Here (i w -> -d/dt,
    lambda eps -> mu0 sigma) P2/P1 = -c2/tau_eff = -(2/21) mu0 sigma a^2.
    """
    a, sigma = 0.03, 5.8e7
    t0 = MU0 * sigma * a * a
    c2 = 2.0 / 315 * t0 ** 2
    tau_eff = t0 / 15
    # implementation of (2.14) at small w
    w = 1e-5 / t0
    g = g_solid_sphere(w, a, sigma)
    # (g - i w tau_eff)/(i w)^2 = c2 + c3 (i w) + c4 (i w)^2 ...: the O(w) remainder is
    # imaginary (next term 6 zeta(8)/pi^8 x^6 = x^6/1575, i.e. x^2/10 = 1e-6 relative),
    # so the real part gives c2 to O(w^2).
    c2_num = ((g - 1j * w * tau_eff) / (1j * w) ** 2).real
    e_impl = abs(c2_num / c2 - 1)
    print(f"\n(2.14) at w mu0 sigma a^2 = 1e-5: c2 rel err {e_impl:.1e} (tol 1e-9)")
    assert e_impl < 1e-9
    # modal sum with many modes (tail of sum w_n tau_n^2 ~ N^-5)
    m = modal_solid_sphere(a, sigma, 200)
    e_modal = abs(np.sum(m.weight * m.tau ** 2) / c2 - 1)
    # truncation: sum_{n>200} 6/(n^6 pi^6) / (2/315) ~ 6e-13
    print(f"modal sum w_n tau_n^2 (N=200) vs 2/315 (mu0 sigma a^2)^2: rel err {e_modal:.1e} "
          "(tol 2e-12)")
    assert e_modal < 2e-12
    # [BS] ratio P2/P1
    ratio = -c2_num / tau_eff
    e_bs = abs(ratio / (-(2.0 / 21) * t0) - 1)
    print(f"[BS] P2/P1 = -(2/21) mu0 sigma a^2: rel err {e_bs:.1e} (tol 1e-9)")
    assert e_bs < 1e-9
    # the shell's modal model has the same property: sum w tau^2 = c2 of (2.13)
    ms = modal_shell(0.5, 1.0, SIG, 300)
    w = 1e-5
    g = g_shell(w, 0.5, 1.0, SIG)
    c2_shell = ((g - 1j * w * shell_tau_eff(0.5, 1.0, SIG)) / (1j * w) ** 2).real
    e_sh = abs(np.sum(ms.weight * ms.tau ** 2) / c2_shell - 1)
    print(f"shell r1=0.5: modal sum w tau^2 vs second coefficient of (2.13): rel err {e_sh:.1e} "
          "(tol 1e-9)")
    assert e_sh < 1e-9


# --------------------------------------------------------------------------- #
# API
# --------------------------------------------------------------------------- #
def test_conductor_model_dispatch():
    r2, sigma = 0.025, 3.5e7
    m1 = conductor_model("thin_shell", r2, sigma, thickness=1e-4)
    m2 = conductor_model("solid_sphere", r2, sigma, n_modes=7)
    m3 = conductor_model("shell", r2, sigma, thickness=0.01, n_modes=7)
    e3 = abs(m3.tau_eff / shell_tau_eff(r2 - 0.01, r2, sigma) - 1)
    print(f"\nkinds {m1.kind}, {m2.kind}, {m3.kind}; modes {m1.n_modes}, {m2.n_modes}, "
          f"{m3.n_modes}; shell tau_eff rel err {e3:.1e} (tol 1e-12)")
    assert (m1.kind, m2.kind, m3.kind) == ("thin_shell", "solid_sphere", "shell")
    assert (m1.n_modes, m2.n_modes, m3.n_modes) == (1, 7, 7)
    assert e3 < 1e-12
    assert m1.moment_scale == pytest.approx(2 * np.pi * r2 ** 3 / MU0, rel=1e-15)
    with pytest.raises(ValueError):
        conductor_model("cube", r2, sigma)
    with pytest.raises(ValueError):
        conductor_model("shell", r2, sigma)
    with pytest.raises(ValueError):
        conductor_model("thin_shell", r2, sigma, thickness=2 * r2)
    # full-thickness shell is the sphere
    m4 = conductor_model("shell", r2, sigma, thickness=r2, n_modes=7)
    e4 = relerr(m4.tau, m2.tau).max()
    print(f"shell with h = r2 vs sphere: tau rel err {e4:.1e} (tol 1e-12)")
    assert e4 < 1e-12
