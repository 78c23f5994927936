"""Self-checks of gyro_sim.physics.closed_forms (each test prints the error it measured).

Run from the repo root: python -m pytest -q test/test_closed_forms.py -s
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid, solve_ivp
from scipy.optimize import brentq

from gyro_sim.physics.closed_forms import (
    averaged_nutation_rate,
    constant_field_transverse_decay_rate,
    euler_angles,
    free_rigid_body,
    g_thin_shell,
    l_frame,
    quasi_static_mean_torque,
    small_theta_nutation_rate,
    spinup_axial,
    thin_shell_nutation_window,
    thin_shell_small_theta_nutation_rate,
    torque_slip,
    torque_slip_thin_shell,
)
from gyro_sim.physics.constants import MU0


# ----------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------
def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rot(axis, a):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = skew(k)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def euler_rhs(t, y, J):
    Lb, R = y[:3], y[3:].reshape(3, 3)
    Om = Lb / J
    return np.concatenate([np.cross(Lb, Om), (R @ skew(Om)).ravel()])


# (J, body-frame L0): triaxial in several axis orders, both sides of the separatrix
# (round largest / smallest axis; x3 playing the roles a, b, c), negative components,
# near-permanent rotation, axisymmetric and isotropic bodies.
CASES = [
    ((1.0, 2.0, 3.0), (0.3, 0.2, 1.0)),  # round the largest axis (x3)
    ((1.0, 2.0, 3.0), (1.0, -0.2, 0.3)),  # round the smallest axis (x1)
    ((3.0, 1.0, 2.0), (0.3, 0.2, -1.0)),  # round x1 = largest, x3 intermediate
    ((2.0, 3.0, 1.0), (1.0, 0.5, 0.2)),  # round x2 = largest, x3 smallest
    ((2.0, 3.0, 1.0), (0.1, -0.2, 1.0)),  # round x3 = smallest
    ((1.2, 3.1, 2.0), (-0.9, 0.4, 0.6)),  # x3 intermediate
    ((1.0, 2.0, 3.0), (0.0, 1e-7, 1.0)),  # near-permanent rotation about x3
    ((1.0, 1.0, 2.0), (0.3, 0.2, 1.0)),  # oblate axisymmetric
    ((2.0, 1.0, 2.0), (0.3, 0.2, 1.0)),  # axisymmetric about x2
    ((1.0, 1.0, 1.0), (0.3, 0.2, 1.0)),  # isotropic
    ((1.0, 2.0, 3.0), (1.0, 0.4, 3**0.5 * (1 + 1e-4))),  # 1e-4 from the separatrix (m ≈ 1 − 4e-4)
]


# ----------------------------------------------------------------------------------
# free rigid body
# ----------------------------------------------------------------------------------
@pytest.mark.parametrize("J, Lb0", CASES)
def test_free_body_euler_residual(J, Lb0):
    """Finite-difference residual of dL_b/dt = L_b × Ω_b and dR/dt = R [Ω_b]×."""
    rng = np.random.default_rng(7)
    J = np.array(J)
    R0 = random_rotation(rng)
    L = R0 @ np.array(Lb0)
    h = 1e-3
    worst_L = worst_R = 0.0
    for t0 in (0.0, 0.77, 13.3, -5.1, 250.0):
        tt = t0 + h * np.array([-2, -1, 1, 2])
        Lb, R = free_rigid_body(J, R0, L, tt)
        dL = (Lb[0] - 8 * Lb[1] + 8 * Lb[2] - Lb[3]) / (12 * h)
        dR = (R[0] - 8 * R[1] + 8 * R[2] - R[3]) / (12 * h)
        Lc, Rc = free_rigid_body(J, R0, L, t0)
        Om = Lc[0] / J
        worst_L = max(worst_L, np.abs(dL - np.cross(Lc[0], Om)).max())
        worst_R = max(worst_R, np.abs(dR - Rc[0] @ skew(Om)).max())
        # consistency L_b = Rᵀ L and orthogonality
        assert np.abs(Rc[0].T @ L - Lc[0]).max() < 1e-13
        assert np.abs(Rc[0].T @ Rc[0] - np.eye(3)).max() < 1e-13
    print(f"\n  J={J} Lb0={Lb0}: FD residual |dL/dt − L×Ω| = {worst_L:.2e}, |dR/dt − R[Ω]×| = {worst_R:.2e}")
    assert worst_L < 1e-9 and worst_R < 1e-9


@pytest.mark.parametrize("J, Lb0", CASES)
def test_free_body_vs_dop853(J, Lb0):
    """Agreement with solve_ivp DOP853 (rtol = atol = 1e-13) over 4 periods of the fastest axis."""
    rng = np.random.default_rng(11)
    J = np.array(J)
    R0 = random_rotation(rng)
    L = R0 @ np.array(Lb0)
    T = 4 * 2 * np.pi / (np.linalg.norm(L) / J.min())
    t = np.linspace(0.0, T, 41)
    Lb, R = free_rigid_body(J, R0, L, t)
    sol = solve_ivp(
        euler_rhs, (0.0, T), np.concatenate([R0.T @ L, R0.ravel()]), method="DOP853",
        rtol=1e-13, atol=1e-13, t_eval=t, args=(J,),
    )
    eL = np.abs(sol.y[:3].T - Lb).max()
    eR = np.abs(sol.y[3:].T.reshape(-1, 3, 3) - R).max()
    print(f"\n  J={J} Lb0={Lb0}: max|ΔL_b| = {eL:.2e}, max|ΔR| = {eR:.2e} (DOP853, T = {T:.1f} s)")
    assert eL < 1e-10 and eR < 1e-10


def test_free_body_psi_vs_gauss_legendre():
    """ψ(t) from the elliptic-Π closed form vs Gauss–Legendre quadrature of
    ψ' = |L|(L1²/J1 + L2²/J2)/(L1² + L2²) along the exact L_b(t)."""
    rng = np.random.default_rng(3)
    xg, wg = np.polynomial.legendre.leggauss(30)
    worst = 0.0
    for J, Lb0 in CASES[:7]:
        J = np.array(J)
        R0 = random_rotation(rng)
        L = R0 @ np.array(Lb0)
        Lm = np.linalg.norm(L)
        T = 20 * 2 * np.pi / (Lm / J.min())
        edges = np.linspace(0.0, T, 401)
        a, b = edges[:-1], edges[1:]
        nodes = (0.5 * (b - a)[:, None] * xg[None, :] + 0.5 * (a + b)[:, None]).ravel()
        Lb, _ = free_rigid_body(J, R0, L, nodes)
        f = Lm * (Lb[:, 0] ** 2 / J[0] + Lb[:, 1] ** 2 / J[1]) / (Lb[:, 0] ** 2 + Lb[:, 1] ** 2)
        inc = (0.5 * (b - a) * (f.reshape(-1, 30) @ wg))
        psi_gl = np.concatenate([[0.0], np.cumsum(inc)])
        _, R, (psi, theta, phi) = free_rigid_body(J, R0, L, edges, return_angles=True)
        err = np.abs(psi - psi[0] - psi_gl).max() / abs(psi_gl[-1])
        worst = max(worst, err)
        # the angles returned are those of R (ψ read back from R is ill-conditioned ~ eps/θ)
        p2, t2, f2 = euler_angles(R, np.tile(L, (edges.size, 1)))
        e_back = max(np.abs(np.angle(np.exp(1j * (p2 - psi)))).max() * theta.min(), np.abs(t2 - theta).max())
        assert e_back < 1e-13, e_back
    print(f"\n  ψ closed form vs Gauss–Legendre: max relative error {worst:.2e}")
    assert worst < 1e-12


def test_free_body_group_property_long_time():
    """Flow property at long times: motion for t1 + t2 from R0 equals motion for t2 from R(t1)
    (t1 ≈ 10⁵ revolutions); |L| and energy conserved; R orthogonal."""
    rng = np.random.default_rng(5)
    worst = 0.0
    for J, Lb0 in CASES[:6] + CASES[7:9]:
        J = np.array(J)
        R0 = random_rotation(rng)
        L = R0 @ np.array(Lb0)
        t1 = 1e5 * 2 * np.pi / (np.linalg.norm(L) / J.min())
        t2 = np.linspace(0.0, 30.0, 7)
        Lb1, R1 = free_rigid_body(J, R0, L, t1)
        Lb_a, R_a = free_rigid_body(J, R1[0], L, t2)
        Lb_b, R_b = free_rigid_body(J, R0, L, t1 + t2)
        e = max(np.abs(R_a - R_b).max(), np.abs(Lb_a - Lb_b).max() / np.linalg.norm(L))
        E0 = np.sum(np.array(Lb0) ** 2 / J)
        eE = abs(np.sum(Lb_b**2 / J, axis=1) - E0).max() / E0
        eO = np.abs(np.swapaxes(R_b, 1, 2) @ R_b - np.eye(3)).max()
        worst = max(worst, e, eE, eO)
    print(f"\n  flow property at t ≈ 1e5 revolutions: max error {worst:.2e}")
    assert worst < 1e-9


def test_free_body_separatrix_raises():
    J = np.array([1.0, 2.0, 3.0])
    # |L|² = 2T J2: L1² (1/J1 − 1/J2) = L3² (1/J2 − 1/J3) ⇒ L3 = L1 √3
    Lb0 = np.array([1.0, 0.4, np.sqrt(3.0)])
    with pytest.raises(ValueError):
        free_rigid_body(J, np.eye(3), Lb0, [0.0, 1.0])
    print("\n  separatrix raises ValueError: ok")


def test_euler_angles_round_trip():
    """euler_angles(Y Rz(ψ) Rx(θ) Rz(φ), L) returns (ψ, θ, φ); L_b = |L|(sθ sφ, sθ cφ, cθ)."""
    rng = np.random.default_rng(2)
    n = 2000
    L = rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, size=(n, 1))
    L[:5] = [[0, 0, 1], [0, 0, -1], [0.0, -0.0, -2.0], [1, 0, 0], [0, -3, 0]]
    psi = rng.uniform(-np.pi, np.pi, n)
    theta = rng.uniform(1e-3, np.pi - 1e-3, n)
    phi = rng.uniform(-np.pi, np.pi, n)
    Y = l_frame(L)
    R = np.array([Y[i] @ rot([0, 0, 1], psi[i]) @ rot([1, 0, 0], theta[i]) @ rot([0, 0, 1], phi[i]) for i in range(n)])
    p2, t2, f2 = euler_angles(R, L)
    err = max(
        np.abs(np.angle(np.exp(1j * (p2 - psi)))).max(),
        np.abs(t2 - theta).max(),
        np.abs(np.angle(np.exp(1j * (f2 - phi)))).max(),
    )
    Lm = np.linalg.norm(L, axis=1)
    Lb = np.einsum("nji,nj->ni", R, L)
    Lb_expect = Lm[:, None] * np.stack([np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)], 1)
    eLb = np.abs(Lb - Lb_expect).max() / Lm.max()
    eY = np.abs(np.swapaxes(Y, 1, 2) @ Y - np.eye(3)).max()
    ey3 = np.abs(Y[:, :, 2] - L / Lm[:, None]).max()
    print(f"\n  euler_angles round trip: angle error {err:.2e}, L_b error {eLb:.2e}, Y orthogonality {eY:.2e}")
    assert err < 1e-10 and eLb < 1e-13 and eY < 1e-14 and ey3 < 1e-14
    assert np.allclose(np.linalg.det(Y), 1.0)


# ----------------------------------------------------------------------------------
# quasi-static torque, torque–slip, spin-up
# ----------------------------------------------------------------------------------
def test_quasi_static_mean_torque_vs_period_average():
    """[K] (1.3) vs the field-period average of [K] (1.2) N = k_e B × (B × Ω + dB/dt)."""
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(20):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        e1 = np.cross(u, rng.normal(size=3))
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        k_e, B0, nu = rng.uniform(0.1, 2), rng.uniform(0.1, 2), rng.uniform(-50, 50)
        Om = rng.normal(size=3) * 30
        s = 2 * np.pi * np.arange(64) / 64  # σ = νt over one period
        B = B0 * (np.outer(np.cos(s), e1) + np.outer(np.sin(s), e2))
        dB = nu * B0 * (np.outer(-np.sin(s), e1) + np.outer(np.cos(s), e2))
        N = k_e * np.cross(B, np.cross(B, Om) + dB)
        ref = N.mean(axis=0)
        got = quasi_static_mean_torque(k_e, B0, nu, u, e1, Om)
        worst = max(worst, np.abs(got - ref).max() / np.abs(ref).max())
    print(f"\n  [K] (1.3) vs period average of (1.2): relative error {worst:.2e}")
    assert worst < 1e-13


def test_torque_slip_vs_time_domain_filter():
    """N_u = (2π r2³/μ0) B0² Im ĝ(s) vs the steady state of τ dm/dt + m = −(2π r2³/μ0) τ dB_b/dt
    for a rotor spinning about the field axis; pull-out torque at s = 1/τ."""
    r2, B0, tau = 0.02, 0.05, 3e-3
    K = 2 * np.pi * r2**3 / MU0
    worst = 0.0
    for s in (-900.0, -50.0, 10.0, 1 / tau, 2000.0):
        # body frame: field rotates at the slip s; w = m + K B_b obeys dw/dt = (K B_b − w)/τ
        def Bb(t, s=s):
            return B0 * np.array([np.cos(s * t), np.sin(s * t), 0.0])

        T = 40 * tau + 2 * np.pi / abs(s)
        sol = solve_ivp(lambda t, w: (K * Bb(t) - w) / tau, (0, T), np.zeros(3), method="DOP853", rtol=1e-12, atol=1e-16)
        w = sol.y[:, -1]
        N = np.cross(w - K * Bb(T), Bb(T))[2]
        ref = torque_slip_thin_shell(tau, r2, B0, s)
        worst = max(worst, abs(N - ref) / abs(ref))
    ss = np.linspace(1, 5 / tau, 200001)
    curve = torque_slip(lambda x: g_thin_shell(x, tau), r2, B0, ss)
    e_pull = abs(ss[np.argmax(curve)] * tau - 1.0)
    e_max = abs(curve.max() / (np.pi * r2**3 * B0**2 / MU0) - 1.0)
    # low slip: k_e B0² s with k_e = K τ
    e_low = abs(torque_slip_thin_shell(tau, r2, B0, 1e-3) / (K * tau * B0**2 * 1e-3) - 1.0)
    print(f"\n  torque–slip vs filter: {worst:.2e}; pull-out at sτ = 1 within {e_pull:.1e}, "
          f"peak (π r2³/μ0)B0² within {e_max:.1e}; low-slip k_e within {e_low:.1e}")
    assert worst < 1e-8 and e_pull < 1e-4 and e_max < 1e-9 and e_low < 1e-10


def test_spinup_axial_vs_torque_slip_ode():
    """Ω(t) = ν + (Ω0 − ν) e^{−k_e B0² t/J3} vs J3 dΩ/dt = N_u(ν − Ω) with the thin-shell
    torque–slip curve at ντ = 0.01 (quasi-static error O((ντ)²))."""
    r2, B0, tau, J3, nu = 0.02, 0.05, 1e-4, 2e-6, 100.0
    k_e = 2 * np.pi * r2**3 * tau / MU0
    Tc = J3 / (k_e * B0**2)
    t = np.linspace(0, 5 * Tc, 101)
    sol = solve_ivp(lambda t, y: [torque_slip_thin_shell(tau, r2, B0, nu - y[0]) / J3], (0, t[-1]), [0.0],
                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=t)
    err = np.abs(sol.y[0] - spinup_axial(J3, k_e, B0, nu, 0.0, t)).max() / nu
    print(f"\n  spin-up closed form vs torque–slip ODE (ντ = {nu * tau}): {err:.2e} of ν")
    assert err < 2 * (nu * tau) ** 2


# ----------------------------------------------------------------------------------
# [M] (3.18)–(3.20): thin shell in a rotating field
# ----------------------------------------------------------------------------------
J1, J3, TAU, OMEGA = 1.0, 1.5, 1.0, 3.0  # κ = 0.5, ωτ = 3 > 1
R2 = 0.01
K_ = 2 * np.pi * R2**3 / MU0


def g_shell(x):
    return g_thin_shell(x, TAU)


def test_window_roots_vs_averaged_linear_response():
    """The sign changes of the averaged dθ/dt (torus average of the exact linear response at
    θ = 1e-4) are the roots J1 l_{1,2} of [M] (3.20); (3.18) matches the rate to O(θ²)."""
    win = thin_shell_nutation_window(J1, J3, TAU, OMEGA)

    def f(Lm):
        return averaged_nutation_rate(g_shell, R2, 1.0, J1, J3, Lm, OMEGA, 1e-4)

    r1 = brentq(f, 0.5, 4.4, xtol=1e-14)
    r2 = brentq(f, 4.6, 9.0, xtol=1e-14)
    e_roots = max(abs(r1 - win.L_low), abs(r2 - win.L_high)) / win.L_high
    worst = 0.0
    for Lm in (0.3, 1.0, 2.0, 3.0, 4.5, 6.0, 8.0, 12.0):
        for w in (OMEGA, 0.5, -2.0):
            got = averaged_nutation_rate(g_shell, R2, 1.0, J1, J3, Lm, w, 1e-4) / 1e-4
            ref = small_theta_nutation_rate(g_shell, R2, 1.0, J1, J3, Lm, w)
            ref2 = thin_shell_small_theta_nutation_rate(K_ * TAU, 1.0, J1, J3, TAU, Lm, w)
            assert abs(ref - ref2) <= 1e-12 * abs(ref)
            worst = max(worst, abs(got - ref) / abs(ref))
    # θ grows below the window, decays inside, grows above (κ > 0, ωτ > 1)
    signs = [int(np.sign(f(x))) for x in (0.5 * win.L_low, 0.5 * (win.L_low + win.L_high), 1.5 * win.L_high)]
    print(f"\n  window [M] (3.20): |L| ∈ ({win.L_low:.6f}, {win.L_high:.6f}) kg·m²/s; roots of the averaged "
          f"rate differ by {e_roots:.1e} (relative); (3.18) vs torus average: {worst:.1e}; signs {signs}")
    assert e_roots < 1e-7 and worst < 1e-6 and signs == [1, -1, 1]
    # synchronous state inside the window, and ωτ < 1 gives no lower root
    assert win.L_low < J3 * OMEGA < win.L_high
    assert thin_shell_nutation_window(J1, J3, TAU, 0.8 / TAU).l_low < 0


def test_averaged_rate_time_domain_and_quasi_static():
    """The torus average equals a Hann-windowed time average of the time-domain filter
    (τ dm/dt + m = −Kτ dB_b/dt) along the exact regular precession; at ωτ → 0 it equals the
    quasi-static [K] (2.1) θ' = −½ (k_e B0²/J1) κ/(1+κ) sinθ cosθ at finite θ."""

    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def td_rate(Lm, th, T=600.0, T0=30.0):
        l = Lm / J1
        nu = Lm * np.cos(th) * (1 / J1 - 1 / J3)
        c, s = np.cos(th), np.sin(th)
        RxT = np.array([[1, 0, 0], [0, c, s], [0, -s, c]], float)

        def Bb(t):  # R = Rz(l t) Rx(θ) Rz(−ν t); B_b = Rᵀ B
            t = np.atleast_1d(t)
            v = np.stack([np.cos((OMEGA - l) * t), np.sin((OMEGA - l) * t), 0 * t])
            v = RxT @ v
            cb, sb = np.cos(nu * t), np.sin(nu * t)  # Rz(−νt)ᵀ = Rz(νt)
            return np.stack([cb * v[0] - sb * v[1], sb * v[0] + cb * v[1], v[2]])

        ts = np.linspace(0, T0 + T, int((T0 + T) * 40) + 1)
        sol = solve_ivp(lambda t, y: (K_ * Bb(t)[:, 0] - y) / TAU, (0, T0 + T), np.zeros(3), method="DOP853",
                        rtol=1e-11, atol=1e-14, t_eval=ts)
        b = Bb(ts)
        m = sol.y - K_ * b
        N = np.cross(m.T, b.T)
        ph = -nu * ts
        y3 = np.stack([s * np.sin(ph), s * np.cos(ph), c + 0 * ts], 1)
        ep = (np.array([0, 0, 1.0]) - c * y3) / s
        v = -np.sum(N * ep, 1) / Lm
        sel = ts >= T0
        tt, v = ts[sel] - T0, v[sel]
        wgt = np.sin(np.pi * tt / T) ** 2
        return np.trapezoid(v * wgt, tt) / np.trapezoid(wgt, tt)

    worst = 0.0
    for Lm, th in ((1.0, 1e-3), (4.5, 1e-3), (8.0, 0.3)):
        a = td_rate(Lm, th)
        b = averaged_nutation_rate(g_shell, R2, 1.0, J1, J3, Lm, OMEGA, th)
        worst = max(worst, abs(a - b) / abs(b))
    kap = J3 / J1 - 1
    tq = 1e-5
    worst_qs = 0.0
    for th in (0.3, 1.0, 1.4, 2.5):
        got = averaged_nutation_rate(lambda x: g_thin_shell(x, tq), R2, 1.0, J1, J3, 2.0, OMEGA, th)
        ref = -0.5 * K_ * tq / J1 * kap / (1 + kap) * np.sin(th) * np.cos(th)
        worst_qs = max(worst_qs, abs(got - ref) / abs(ref))
    print(f"\n  torus vs time-domain filter average: {worst:.1e}; vs quasi-static [K] (2.1) at ωτ = {OMEGA * tq:.0e}: {worst_qs:.1e}")
    assert worst < 1e-7 and worst_qs < 1e-6


def test_full_model_nutation_grows_early_in_spinup():
    """Full model (rigid body + thin-shell eddy filter, no averaging): a thin-shell rotor spun up
    from |L| = 0.6 by a field with ωτ = 3: θ grows while |L| < J1 l1, then decays, and follows
    ln θ = ln θ0 + ∫ (3.18) dt along the simulated |L|(t) within 2 % (O(μ) ripple, μ ≈ 1e-3)."""
    J = np.array([J1, J1, J3])
    c = 0.01  # K B0² (N·m): μ = torque / (J ω²) ≈ 1e-3
    B0 = np.sqrt(c / K_)

    def rhs(t, y):
        L, R, w = y[:3], y[3:12].reshape(3, 3), y[12:]
        B = B0 * np.array([np.cos(OMEGA * t), np.sin(OMEGA * t), 0.0])
        Bb = R.T @ B
        Om = (R.T @ L) / J
        N = R @ np.cross(w - K_ * Bb, Bb)
        return np.concatenate([N, (R @ skew(Om)).ravel(), (K_ * Bb - w) / TAU])

    th0 = 0.02
    R0 = rot([1, 0, 0], th0)
    y0 = np.concatenate([[0.0, 0.0, 0.6], R0.ravel(), np.zeros(3)])
    ts = np.linspace(0, 800.0, 8001)
    sol = solve_ivp(rhs, (0, ts[-1]), y0, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=ts)
    L = sol.y[:3].T
    R = sol.y[3:12].T.reshape(-1, 3, 3)
    Lm = np.linalg.norm(L, axis=1)
    th = np.arccos(np.clip(np.einsum("ni,ni->n", R[:, :, 2], L) / Lm, -1, 1))
    rate = thin_shell_small_theta_nutation_rate(K_ * TAU, B0, J1, J3, TAU, Lm, OMEGA)
    pred = th0 * np.exp(cumulative_trapezoid(rate, ts, initial=0.0))
    e_traj = np.abs(th / pred - 1).max()
    win = thin_shell_nutation_window(J1, J3, TAU, OMEGA)
    # |L| at the maximum of θ (θ smoothed over ~ 10 s)
    k = 101
    ths = np.convolve(th, np.ones(k) / k, mode="same")
    i = np.argmax(ths[k:-k]) + k
    e_peak = abs(Lm[i] / win.L_low - 1)
    print(f"\n  full model: θ max {th.max() / th0:.3f} θ0 at |L| = {Lm[i]:.3f} (window L_low = {win.L_low:.3f}, "
          f"{e_peak:.1e} off); θ(t) vs ∫(3.18): {e_traj:.1e}; θ(800 s)/θ0 = {th[-1] / th0:.3f}")
    assert th.max() > 1.05 * th0 and th[-1] < th.max() * 0.9
    assert e_traj < 2e-2 and e_peak < 2e-2


# ----------------------------------------------------------------------------------
# constant field
# ----------------------------------------------------------------------------------
def test_constant_field_transverse_decay_full_model():
    """Sphere-inertia thin shell in a constant field, full filter model with |Ω|τ = 3e-3:
    Ω ⟂ B decays at k_e B²/J, L·B conserved ([M] (3.7), [BS] (8.3))."""
    J, tau, r2 = 1e-3, 1e-2, 0.01
    K = 2 * np.pi * r2**3 / MU0
    k_e = K * tau
    rate = 0.2
    Bmag = np.sqrt(rate * J / k_e)
    Bv = np.array([0.0, 0.0, Bmag])

    def rhs(t, y):
        L, R, w = y[:3], y[3:12].reshape(3, 3), y[12:]
        Bb = R.T @ Bv
        Om = (R.T @ L) / J
        N = R @ np.cross(w - K * Bb, Bb)
        return np.concatenate([N, (R @ skew(Om)).ravel(), (K * Bb - w) / tau])

    L0 = J * np.array([0.2, -0.1, 0.2])
    R0 = rot([1, 2, 3], 0.4)
    w0 = K * (R0.T @ Bv) - K * tau * np.cross(R0.T @ L0 / J, R0.T @ Bv)  # quasi-steady start
    T = 10.0
    sol = solve_ivp(rhs, (0, T), np.concatenate([L0, R0.ravel(), w0]), method="DOP853", rtol=1e-11, atol=1e-16,
                    t_eval=[0, T])
    L = sol.y[:3, -1]
    measured = -np.log(np.hypot(L[0], L[1]) / np.hypot(L0[0], L0[1])) / T
    expect = constant_field_transverse_decay_rate(k_e, Bmag, J)
    e_rate = abs(measured / expect - 1)
    e_axial = abs(L[2] / L0[2] - 1)
    print(f"\n  constant field: measured decay {measured:.6f} 1/s vs k_e B²/J = {expect:.6f} ({e_rate:.1e}); "
          f"L·B drift {e_axial:.1e}")
    assert e_rate < 1e-4 and e_axial < 1e-6
