"""Magnetizable, anisotropic conducting body [BS] (effects.magnetizable) against closed forms.

m_b = (1/μ0)[M B_b + P1 dB_b/dt + P2 d²B_b/dt²] (physics.md §3; docs/magnetizable.md). Every test prints
the error it measured and asserts a stated tolerance:

1. P1, P2 of effects.default_p1_p2 = the first two Taylor terms of [M] (2.14) / (2.15) / corrected (2.13)
   (computed here independently by Cauchy integrals of the closed forms, mpmath) = [BS] §8 in SI; the
   Gaussian → SI conversion checked numerically in CGS units.
2. Constant field, sphere: the transverse spin decays at [BS] (8.3) in SI, k_e B²/J, in the full model;
   the magnetizable model agrees with the eddy-mode model to the first neglected order.
3. [BS] Theorem 2: the SI criterion ω²J + (B²/μ0)M against the eigenvalues of the linearisation, the
   linearisation against the printed (6.2), and the full model perturbed about each stationary rotation.
4. The nonlinear full model against [BS] (6.2) integrated independently; the kernel's d²B_b/dt²
   against finite differences of the recorded field.
5. The scene config/magnetizable_body.yaml.

Run: .venv/bin/python -m pytest -q -s test/test_magnetizable.py
"""
import math

import mpmath as mp
import numpy as np
import pytest
from scipy.constants import c as C_LIGHT, epsilon_0
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from gyro_sim.compiled import effects
from gyro_sim.physics import magnetizable as mg
from gyro_sim.physics.closed_forms import constant_field_transverse_decay_rate
from gyro_sim.physics.conductor import conductor_model
from gyro_sim.physics.constants import MU0
from gyro_sim.physics.frames import quat_to_matrix
from gyro_sim.scenes.scene import load_scene, scene_from_dict
from gyro_sim.engine.simulate import Simulator, run

A, SIGMA = 0.025, 2.5e7  # solid sphere: radius m, conductivity S/m
SPHERE = {"kind": "solid_sphere", "outer_radius": A, "conductivity": SIGMA}
T0 = MU0 * SIGMA * A * A  # μ0 σ a², s


def report(name, err, tol):
    print(f"\n{name}: measured {err:.3e}, tolerance {tol:.1e}")
    assert err <= tol, f"{name}: {err:.3e} > {tol:.1e}"


# ----------------------------------------------------------------------------------------
# 1. P1, P2 = the small-ω expansion of the transfer function


def _taylor_p(g, order=2, radius=1.0):
    """Coefficients G_1..G_order of g(p) = Σ G_k p^k, by Cauchy integrals on |p| = radius (mpmath, 30 digits)."""
    mp.mp.dps = 30
    return [float(x) for x in mp.taylor(g, 0, order, method="quad", radius=radius)[1:]]


def _g_sphere(s):
    """[M] (2.14): ĝ = −[1 − 3/x² + (3/x) cot x] as a function of s = x² = iω μ0σa²."""
    x = mp.sqrt(s)
    return -(1 - 3 / s + 3 * mp.cot(x) / x)


def _g_shell(rho):
    """Corrected [M] (2.13) (physics.md §3), ĝ = 2α/r2³ as a function of s = (k r2)² (r2 = 1 units)."""
    r1, h = mp.mpf(rho), 1 - mp.mpf(rho)

    def g(s):
        k = mp.sqrt(s)
        t = mp.tan(k * h)
        num = (s * s * r1 ** 2 - 3 * s * (r1 ** 2 + 1 - 3 * r1) + 9) * t - 3 * k * h * (s * r1 + 3)
        den = 2 * s * ((3 - s * r1 ** 2) * t + 3 * k * r1)
        return 2 * num / den

    return g


def _p_from_g(G1, G2, r2, t):
    """μ0 m = 2π r2³ [G1 t (iω) + G2 t² (iω)²] B and iω ↔ −d/dt: P1 = −2π r2³ G1 t, P2 = 2π r2³ G2 t²."""
    c = 2 * math.pi * r2 ** 3
    return -c * G1 * t, c * G2 * t * t


def _p_default(cond):
    P1, P2 = effects.default_p1_p2(cond)
    for P in (P1, P2):  # isotropic
        assert np.array_equal(P, P[0, 0] * np.eye(3))
    return P1[0, 0], P2[0, 0]


def test_p1_p2_sphere_and_thin_shell_are_the_expansion_of_the_transfer_function():
    G1, G2 = _taylor_p(_g_sphere, radius=2.0)  # poles at s = n²π²: radius 2 is inside
    print(f"\n  [M] (2.14) Taylor coefficients in x²: {G1!r}, {G2!r} (1/15 = {1 / 15!r}, 2/315 = {2 / 315!r})")
    report("sphere: G1, G2 vs 1/15, 2/315", max(abs(G1 * 15 - 1), abs(G2 * 315 / 2 - 1)), 1e-14)
    e1, e2 = _p_from_g(G1, G2, A, T0)
    b1, b2 = mg.sphere_p1_p2(A, SIGMA)  # [BS] §8 converted to SI
    report("sphere: [BS] P(1), P(2) in SI vs the expansion of (2.14)", max(abs(b1 / e1 - 1), abs(b2 / e2 - 1)), 1e-14)
    for n in (1, 10, 50):
        p1, p2 = _p_default(conductor_model("solid_sphere", A, SIGMA, n_modes=n))
        report(f"sphere, {n} modes: default_p1_p2 vs the expansion of (2.14) (P1, P2 relative)",
               max(abs(p1 / e1 - 1), abs(p2 / e2 - 1)), 1e-12)
    # thin shell [M] (2.15): ĝ = iωτ/(1 − iωτ)
    r2, h = 0.025, 0.001
    tau = MU0 * SIGMA * r2 * h / 3.0
    G1, G2 = _taylor_p(lambda p: p / (1 - p), radius=0.5)  # p = iωτ
    e1, e2 = _p_from_g(G1, G2, r2, tau)
    p1, p2 = _p_default(conductor_model("thin_shell", r2, SIGMA, thickness=h))
    t1, t2 = mg.thin_shell_p1_p2(r2, h, SIGMA)
    report("thin shell: default_p1_p2 and thin_shell_p1_p2 vs the expansion of (2.15)",
           max(abs(p1 / e1 - 1), abs(p2 / e2 - 1), abs(t1 / e1 - 1), abs(t2 / e2 - 1)), 1e-13)


@pytest.mark.parametrize("rho", [0.3, 0.6])
def test_p1_p2_thick_shell_with_the_tail_of_the_modes(rho):
    """A shell r1 = ρ r2: the 10 kept modes plus the tail term against the Taylor terms of corrected (2.13)."""
    r2 = 0.025
    G1, G2 = _taylor_p(_g_shell(rho), radius=1.0)
    e1, e2 = _p_from_g(G1, G2, r2, MU0 * SIGMA * r2 * r2)
    p1, p2 = _p_default(conductor_model("shell", r2, SIGMA, thickness=(1 - rho) * r2, n_modes=10))
    report(f"shell r1/r2 = {rho}, 10 modes: P1 vs (2.13)", abs(p1 / e1 - 1), 1e-12)
    report(f"shell r1/r2 = {rho}, 10 modes: P2 vs (2.13) (tail estimated by the sphere law)", abs(p2 / e2 - 1), 1e-7)


def test_gaussian_to_si_conversion_numerically_in_cgs():
    """[BS] in CGS numbers (a in cm, λ in 1/s, H in Oe, m in erg/G, torque in erg) against the SI forms.

    Gaussian conductivity λ = σ/(4π ε0); ε = 4π/c². m_G = ε P(1) Ḣ + ε² P(2) Ḧ, m_SI = 1e-3 m_G for
    Ḣ = 1e4 Ḃ. (8.3): rate (1/16) ε λ I²/π for a sphere of unit density (1 g/cm³, J = 8πa⁵/15).
    The conventional factors 1 Oe ↔ 1e-4 T, 1 erg/G ↔ 1e-3 A·m² hold for μ0 = 4π·1e-7 H/m; SciPy's μ0
    (CODATA 2018) differs from it by 1.4e-10 relative, hence the tolerance 1e-9.
    """
    a_cm, lam = 100 * A, SIGMA / (4 * math.pi * epsilon_0)
    c_cgs = 100 * C_LIGHT
    eps = 4 * math.pi / c_cgs ** 2
    P1g, P2g = -a_cm ** 5 * lam / 30, a_cm ** 7 * lam ** 2 / 315  # [BS] §8
    dB, ddB = 0.7, -3.1  # T/s, T/s²
    m_cgs = eps * P1g * (1e4 * dB) + eps ** 2 * P2g * (1e4 * ddB)  # erg/G
    P1, P2 = mg.sphere_p1_p2(A, SIGMA)
    m_si = (P1 * dB + P2 * ddB) / MU0
    report("[BS] (6.1) moment, CGS numbers vs SI form", abs(1e-3 * m_cgs / m_si - 1), 1e-9)
    B = 0.01
    rate_cgs = eps * lam * (1e4 * B) ** 2 / (16 * math.pi)  # [BS] (8.3) exponent / t
    J_si = 1e3 * 8 * math.pi * A ** 5 / 15  # unit density, kg·m²
    report("[BS] (8.3) rate, CGS numbers vs (2π/15)σa⁵B²/J",
           abs(rate_cgs / mg.sphere_transverse_decay_rate(A, SIGMA, B, J_si) - 1), 1e-9)
    # Theorem 2: I² M_G (erg) = (B²/μ0) M_SI (J) with M_SI = 4π M_G (cm³ → m³)
    Mg = 3.0  # cm³
    report("[BS] Theorem 2 I²M: CGS (erg → J) vs (B²/μ0)·4πM_G", abs(1e-7 * (1e4 * B) ** 2 * Mg
                                                                   / (B * B / MU0 * 4 * math.pi * Mg * 1e-6) - 1), 1e-9)


# ----------------------------------------------------------------------------------------
# 2. constant field: transverse decay [BS] (8.3)


def _decay_run(magnetizable, spin, rho, B, J, duration, max_step):
    d = {"rotor": {"inertia": [J] * 3, "conductor": SPHERE}, "torque_model": "lag", "modes": 10,
         "field": [{"real": [0, 0, B], "frequency": 0.0}], "duration": duration,
         "initial": {"spin": spin, "L_direction": [math.sin(rho), 0, math.cos(rho)]}, "output": {"rate": 20.0},
         "integrator": {"steps_per_turn": 96, "max_step": max_step}}
    if magnetizable:
        d["effects"] = {"magnetizable": {}}  # M = 0, default P1, P2 (the conductor's)
    r = run(scene_from_dict(d))
    Lp = np.hypot(r.L[:, 0], r.L[:, 1])
    keep = r.t > 0.1 * duration  # past the eddy modes' switch-on transient (τ_1 = 2 ms)
    c = np.polyfit(r.t[keep], np.log(Lp[keep]), 1)
    resid = float(np.max(np.abs(np.polyval(c, r.t[keep]) - np.log(Lp[keep]))))
    drift = float(np.max(np.abs(r.L[:, 2] / r.L[0, 2] - 1)))
    return -c[0], resid, drift


def test_constant_field_transverse_decay_BS83():
    """Sphere (J spherical, a = 25 mm, σ = 2.5e7 S/m) in 10 mT, spin 2.5 rad/s tilted 0.5 rad from B.

    [BS] (8.3) in SI: λ0 = k_e B²/J (first order). The kernel's model (P2 with Ω̇ from the P1 torque) gives
    exactly λ0 (1 + λ0 P2/|P1|): |L⊥| ∝ exp(−λt) with that λ (the P2 term (b×Ω)×Ω only turns L⊥ about B).
    The eddy-mode model (exact ĝ) agrees to the first neglected order, (G3/G1)(|Ω| μ0σa²)² = (|Ω|μ0σa²)²/105.
    """
    J, B, spin, rho = 4.42e-5, 0.01, 2.5, 0.5
    cond = conductor_model("solid_sphere", A, SIGMA)
    lam0 = constant_field_transverse_decay_rate(cond.k_e, B, J)
    lam_bs = mg.sphere_transverse_decay_rate(A, SIGMA, B, J)
    report("k_e B²/J (closed_forms) vs [BS] (8.3) in SI (magnetizable.py)", abs(lam0 / lam_bs - 1), 1e-14)
    P1, P2 = mg.sphere_p1_p2(A, SIGMA)
    second = lam0 * P2 / -P1  # the P2 correction of the rate, = λ0 μ0σa²/10.5
    T = 2.0 / lam0
    lam_m, resid_m, drift_m = _decay_run(True, spin, rho, B, J, T, 0.01)
    lam_e, resid_e, drift_e = _decay_run(False, spin, rho, B, J, T, 0.001)
    print(f"\n  λ0 = k_e B²/J = {lam0:.9f} 1/s; magnetizable {lam_m:.9f} (log-fit residual {resid_m:.1e}), "
          f"eddy modes {lam_e:.9f} (residual {resid_e:.1e}); P2 term λ0·P2/|P1| = {second:.3e}")
    report("magnetizable: L·B drift", drift_m, 1e-12)
    report("eddy modes: L·B drift", drift_e, 1e-12)
    report("magnetizable vs [BS] (8.3), relative (first order; bound 1.05 × the P2 term)",
           abs(lam_m / lam0 - 1), 1.05 * second)
    report("magnetizable vs λ0 (1 + λ0 P2/|P1|), relative", abs(lam_m / (lam0 * (1 + second)) - 1), 1e-9)
    bound = 2 * (spin * T0) ** 2 / 105
    report("magnetizable vs eddy-mode model, relative (bound 2(|Ω|μ0σa²)²/105)", abs(lam_m / lam_e - 1), bound)


# ----------------------------------------------------------------------------------------
# 3. [BS] Theorem 2

# a slightly prolate (along x1) magnetizable conducting body: J alone favours x3, M favours x1
J_T2 = np.array([4.0e-5, 4.2e-5, 4.4e-5])  # kg·m²
M_T2 = np.array([2.1e-4, 2.0e-4, 2.0e-4])  # m³ (isotropic 2e-4 gives no torque)
P1_T2 = -1.286e-7 * np.array([1.0, 0.8, 1.2])  # m³·s, diagonal, negative
OM_T2, B_T2 = 20.0, 0.03  # rad/s, T


def test_theorem2_criterion_equals_the_linearisation():
    """ω²J + (B²/μ0)M picks the one axis whose linearisation has all Re λ < 0 (random diagonal bodies);
    stationary_linearization equals the finite-difference Jacobian of the printed (6.2) in SI."""
    rng = np.random.default_rng(7)
    bad = 0
    for _ in range(400):
        J = rng.uniform(1.0, 2.0, 3) * 1e-5
        M = rng.uniform(0.0, 2e-5, 3)
        P1 = -rng.uniform(0.1, 3.0, 3) * 1e-7
        om, B = rng.uniform(1.0, 50.0), rng.uniform(0.005, 0.05)
        stable = [np.max(np.linalg.eigvals(mg.stationary_linearization(J, M, P1, om, B, k)).real) < 0
                  for k in range(3)]
        bad += stable != [k == mg.theorem2_stable_axis(J, M, om, B) for k in range(3)]
    report("random bodies where the criterion and the eigenvalues disagree (of 400)", bad, 0)
    # the linearisation against a central-difference Jacobian of [BS] (6.2) (P2 = 0)
    err = 0.0
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        A_lin = mg.stationary_linearization(J_T2, M_T2, P1_T2, OM_T2, B_T2, k)

        def f(x, i=i, j=j, k=k):
            Om = np.zeros(3)
            b = np.zeros(3)
            Om[[i, j]], b[[i, j]] = x[0:2], x[2:4]
            Om[k], b[k] = OM_T2, math.sqrt(B_T2 ** 2 - x[2] ** 2 - x[3] ** 2)
            dOm, db = mg.bs62_rhs(Om, b, J_T2, np.diag(M_T2), np.diag(P1_T2))
            return np.array([dOm[i], dOm[j], db[i], db[j]])

        sc = np.array([OM_T2, OM_T2, B_T2, B_T2]) * 1e-6
        Jac = np.column_stack([(f(sc[c] * np.eye(4)[c]) - f(-sc[c] * np.eye(4)[c])) / (2 * sc[c]) for c in range(4)])
        err = max(err, np.max(np.abs(Jac - A_lin) * sc[None, :] / sc[:, None]) / np.max(np.abs(A_lin)))
    report("stationary_linearization vs Jacobian of (6.2), scaled max", err, 1e-8)


@pytest.mark.parametrize("delta", [(0.0, 1e-3, 2e-3), (2e-3, 1e-3, 0.0), (0.0, 2e-3, 1e-3)])
def test_near_sphere_eigenvalues_BS81_83(delta):
    """[BS] (8.1)–(8.3) in SI for a near-sphere J = J0(E + diag δ), M = 0: the eigenvalues of the
    linearisation about spin ω e3 along B vs near_sphere_eigenvalues (first order in δ); e3 is stable iff
    δ3 > max(δ1, δ2) (x3 the largest inertia), i.e. Theorem 2 with M = 0."""
    J0, om, B = 4.42e-5, 20.0, 0.01
    P1 = mg.sphere_p1_p2(A, SIGMA)[0]
    rate = mg.transverse_decay_rate(P1, B, J0)
    J = J0 * (1 + np.array(delta))
    lam = np.linalg.eigvals(mg.stationary_linearization(J, np.zeros(3), np.full(3, P1), om, B, 2))
    pred = mg.near_sphere_eigenvalues(delta, om, rate)
    fast, slow = lam[np.abs(lam.imag) > om / 2], lam[np.abs(lam.imag) <= om / 2]
    e_fast = np.max(np.abs(np.sort_complex(fast) - np.sort_complex(pred[:2]))) / rate
    e_re = abs(np.max(slow.real) - np.max(pred[2:].real)) / abs(np.max(pred[2:].real))
    sp, sl = np.max(np.abs(pred[2:].imag)), np.max(np.abs(slow.imag))
    e_im = abs(sl - sp) / sp if sp > 0 else sl / (om * max(delta))
    print(f"\n  δ = {delta}: eigenvalues {np.round(np.sort_complex(lam), 6)}; [BS] {np.round(np.sort_complex(pred), 6)}")
    report(f"δ = {delta}: λ_1,2 = ±iω − k_e B²/J0 ((8.3)), error / rate", e_fast, 1e-2)
    report(f"δ = {delta}: max Re λ_3,4 ((8.1)/(8.2)), relative", e_re, 1e-2)
    report(f"δ = {delta}: |Im λ_3,4| ((8.1)), relative", e_im, 1e-2)
    assert (np.max(lam.real) < 0) == (delta[2] > max(delta[:2]))


def _magnetizable_sim(J, M, P1, P2, B_terms, duration, spt=48, max_step=None):
    d = {"rotor": {"inertia": list(map(float, J)), "conductor": SPHERE}, "field": B_terms, "duration": duration,
         "integrator": {"steps_per_turn": spt, "max_step": max_step},
         "effects": {"magnetizable": {"M": np.asarray(M, float).tolist(), "P1": np.asarray(P1, float).tolist(),
                                      "P2": np.asarray(P2, float).tolist()}}}
    return Simulator(scene_from_dict(d))


def _set_state(sim, J, Om_b, b):
    """Put the body at body rate Om_b (rad/s) with the constant field (along z3) seen as b (T) in the body."""
    B = np.linalg.norm(b)
    rot, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [b / B])  # R b̂ = z3
    qx = rot.as_quat()
    sim.y[3:7] = [qx[3], qx[0], qx[1], qx[2]]
    sim.y[0:3] = rot.as_matrix() @ (J * Om_b)


def _sample(sim, J, T, n, Bvec):
    ts = np.linspace(0.0, T, n + 1)[1:]
    out_y, out_N = np.zeros((n, sim.y.size)), np.zeros((n, 3))
    sim.advance(T, ts, out_y, out_N, 0)
    R = quat_to_matrix(out_y[:, 3:7])
    Om = np.einsum("nji,nj->ni", R, out_y[:, 0:3]) / J
    b = np.einsum("nji,j->ni", R, Bvec)
    return ts, Om, b, R, out_N


@pytest.mark.parametrize("axis,T", [(0, 8.0), (1, 5.0), (2, 2.0)])
def test_theorem2_full_model_perturbed_stationary_rotations(axis, T):
    """Full model (M, P1 diagonal, P1 < 0, P2 = 0) started 1e-6 off Ω = ω e_k, B_b = B e_k: the perturbation
    follows exp(A t) of the linearisation; it decays only about the axis of the largest ω²J_k + (B²/μ0) m_k."""
    q = mg.theorem2_quantity(J_T2, M_T2, OM_T2, B_T2)
    k_stable = mg.theorem2_stable_axis(J_T2, M_T2, OM_T2, B_T2)
    assert k_stable == 0 and int(np.argmax(J_T2)) == 2  # the magnetic term changes the answer
    i, j = (axis + 1) % 3, (axis + 2) % 3
    sim = _magnetizable_sim(J_T2, np.diag(M_T2), np.diag(P1_T2), np.zeros((3, 3)),
                            [{"real": [0, 0, B_T2], "frequency": 0.0}], T)
    x0 = 1e-6 * np.array([0.6 * OM_T2, -0.3 * OM_T2, 0.5 * B_T2, 0.7 * B_T2])
    Om0, b0 = np.zeros(3), np.zeros(3)
    Om0[axis], Om0[[i, j]] = OM_T2, x0[0:2]
    b0[[i, j]] = x0[2:4]
    b0[axis] = math.sqrt(B_T2 ** 2 - x0[2] ** 2 - x0[3] ** 2)
    _set_state(sim, J_T2, Om0, b0)
    ts, Om, b, _, _ = _sample(sim, J_T2, T, 200, np.array([0.0, 0.0, B_T2]))
    X = np.column_stack([Om[:, i], Om[:, j], b[:, i], b[:, j]])
    A_lin = mg.stationary_linearization(J_T2, M_T2, P1_T2, OM_T2, B_T2, axis)
    Xl = np.array([expm(A_lin * t) @ x0 for t in ts])
    sc = np.array([OM_T2, OM_T2, B_T2, B_T2])
    nrm, nrm_l = np.linalg.norm(X / sc, axis=1), np.linalg.norm(Xl / sc, axis=1)
    err = np.max(np.linalg.norm((X - Xl) / sc, axis=1)) / np.max(nrm_l)
    late = ts > 0.5 * T
    rate = np.polyfit(ts[late], np.log(nrm[late]), 1)[0]
    rate_l = np.polyfit(ts[late], np.log(nrm_l[late]), 1)[0]
    re_max = float(np.max(np.linalg.eigvals(A_lin).real))
    growth = nrm[-1] / np.linalg.norm(x0 / sc)
    print(f"\n  axis x{axis + 1}: ω²J + B²M/μ0 = {q[axis]:.5f} J (largest {q[k_stable]:.5f} at x{k_stable + 1}); "
          f"max Re λ = {re_max:+.4f} 1/s; full model log-slope {rate:+.4f} (linear solution {rate_l:+.4f}); "
          f"|x(T)|/|x(0)| = {growth:.3g} after {T} s")
    report(f"x{axis + 1}: full model vs exp(A t), max relative", err, 1e-3)
    report(f"x{axis + 1}: log-slope full vs linear, relative to max Re λ", abs(rate - rate_l) / abs(re_max), 1e-3)
    report(f"x{axis + 1}: log-slope vs max Re λ, relative", abs(rate / re_max - 1), 0.05)
    if axis == k_stable:
        assert re_max < 0 and growth < 0.1
    else:
        assert re_max > 0 and growth > 10


def test_full_model_vs_BS62_nonlinear():
    """The flip x3 → x1 (large motion) of the Theorem-2 body: full model (P2 = 0) vs solve_ivp of (6.2) in SI."""
    T = 4.0
    sim = _magnetizable_sim(J_T2, np.diag(M_T2), np.diag(P1_T2), np.zeros((3, 3)),
                            [{"real": [0, 0, B_T2], "frequency": 0.0}], T, spt=200)
    Om0 = np.array([0.2, -0.1, OM_T2])
    b0 = B_T2 * np.array([0.05, 0.02, 1.0]) / np.linalg.norm([0.05, 0.02, 1.0])
    _set_state(sim, J_T2, Om0, b0)
    ts, Om, b, _, _ = _sample(sim, J_T2, T, 80, np.array([0.0, 0.0, B_T2]))

    def rhs(t, y):
        dOm, db = mg.bs62_rhs(y[:3], y[3:], J_T2, np.diag(M_T2), np.diag(P1_T2))
        return np.concatenate([dOm, db])

    sol = solve_ivp(rhs, (0, T), np.concatenate([Om0, b0]), method="DOP853", rtol=1e-12, atol=1e-14, t_eval=ts)
    e_Om = np.max(np.abs(Om - sol.y[:3].T)) / OM_T2
    e_b = np.max(np.abs(b - sol.y[3:].T)) / B_T2
    ang = np.degrees(np.arccos(np.clip(np.abs(b[:, 2]) / B_T2, 0, 1)))
    print(f"\n  angle x3–B: {ang[0]:.1f}° → max {ang.max():.1f}° over {T} s")
    assert ang.max() > 60.0
    report("full model vs (6.2): Ω_b (relative to ω)", e_Om, 1e-6)
    report("full model vs (6.2): B_b (relative to B)", e_b, 1e-6)


def test_kernel_second_derivative_of_the_body_field():
    """P2 term: the kernel's d²B_b/dt² (Rᵀ B̈ − 2Ω×RᵀḂ + Ω×(Ω×B_b) − Ω̇×B_b, Ω̇ from the M + P1 torque) vs a
    finite difference of the recorded B_b(t) = Rᵀ B(t), in a constant + rotating field with general
    symmetric M, P1, P2 and a triaxial body. The kernel leaves the P2 torque out of Ω̇ (in [BS] (6.1) only the
    M torque is in it; both orders are beyond the expansion): an error of relative size P2 B²/(μ0 J)
    (≈ 5e-5 here), below the tolerance; with that share put back into the finite difference
    (kernel B̈_b = true B̈_b + J⁻¹N_P2 × B_b) the two agree to the finite-difference error."""
    rng = np.random.default_rng(3)

    def sym(s):
        X = rng.normal(size=(3, 3))
        return s * (np.eye(3) + 0.3 * (X + X.T))

    M, P1, P2 = sym(1e-5), -sym(1e-7), sym(1e-12)  # symmetric; P1 negative definite
    assert np.all(np.linalg.eigvalsh(P1) < 0)
    om_f, B0, B1 = 30.0, 0.02, 0.015
    field = [{"real": [0, 0, B0], "frequency": 0.0}, {"real": [B1, 0, 0], "imag": [0, B1, 0], "frequency": om_f}]
    h = 2.5e-4
    T = 0.5
    sim = _magnetizable_sim(J_T2, M, P1, P2, field, T, max_step=h)
    _set_state(sim, J_T2, np.array([3.0, -5.0, 15.0]), np.array([0.3, 0.2, 1.0]))  # an arbitrary attitude
    n = int(round(T / h))
    ts = np.arange(1, n + 1) * h
    out_y, out_N = np.zeros((n, sim.y.size)), np.zeros((n, 3))
    sim.advance(T, ts, out_y, out_N, 0)
    R = quat_to_matrix(out_y[:, 3:7])
    Om = np.einsum("nji,nj->ni", R, out_y[:, 0:3]) / J_T2
    c, s = np.cos(om_f * ts), np.sin(om_f * ts)
    Bc = np.column_stack([B1 * c, B1 * s, np.full(n, B0)])
    dBc = np.column_stack([-om_f * B1 * s, om_f * B1 * c, np.zeros(n)])
    b = np.einsum("nji,nj->ni", R, Bc)
    db = np.einsum("nji,nj->ni", R, dBc) - np.cross(Om, b)
    # 4th-order central second difference
    ddb = (-b[4:] + 16 * b[3:-1] - 30 * b[2:-2] + 16 * b[1:-3] - b[:-4]) / (12 * h * h)
    sl = slice(2, n - 2)
    N_mp1 = np.einsum("nij,nj->ni", R[sl], np.cross(b[sl] @ M.T + db[sl] @ P1.T, b[sl]) / MU0)
    N_p2_kernel = out_N[sl] - N_mp1
    N_p2_fd = np.einsum("nij,nj->ni", R[sl], np.cross(ddb @ P2.T, b[sl]) / MU0)
    err = np.max(np.linalg.norm(N_p2_kernel - N_p2_fd, axis=1)) / np.max(np.linalg.norm(N_p2_fd, axis=1))
    # the share of the −Ω̇×B_b term: the error if it were left out
    dOm = np.gradient(Om, h, axis=0)[sl]
    N_wdot = np.einsum("nij,nj->ni", R[sl], np.cross(-np.cross(dOm, b[sl]) @ P2.T, b[sl]) / MU0)
    share = np.max(np.linalg.norm(N_wdot, axis=1)) / np.max(np.linalg.norm(N_p2_fd, axis=1))
    print(f"\n  P2 torque up to {np.max(np.linalg.norm(N_p2_fd, axis=1)):.3e} N·m (total up to "
          f"{np.max(np.linalg.norm(out_N, axis=1)):.3e}); the −Ω̇×B_b term alone is {share:.2f} of it; "
          f"P2 B²/(μ0 J) = {np.linalg.norm(P2, 2) * (B0 + B1) ** 2 / (MU0 * J_T2.min()):.1e}")
    assert share > 0.05
    report("kernel P2 torque vs finite difference of B_b, relative", err, 1e-4)
    Np2_b = np.einsum("nji,nj->ni", R[sl], N_p2_kernel)  # body frame
    ddb_k = ddb + np.cross(Np2_b / J_T2, b[sl])
    N_p2_k = np.einsum("nij,nj->ni", R[sl], np.cross(ddb_k @ P2.T, b[sl]) / MU0)
    err2 = np.max(np.linalg.norm(N_p2_kernel - N_p2_k, axis=1)) / np.max(np.linalg.norm(N_p2_fd, axis=1))
    report("... with the P2 torque's share of Ω̇ put into the finite difference", err2, 1e-7)


# ----------------------------------------------------------------------------------------
# 4. the scene


def test_scene_magnetizable_body():
    """config/magnetizable_body.yaml: spin about x3 (largest J) along the field, 0.02 rad off. With the scene's
    anisotropic M the body leaves x3 and ends spinning about x1 along ±B at h/J1 (h = L·B̂ conserved);
    with M made isotropic (no magnetic torque) it stays at x3."""
    s = load_scene("magnetizable_body")
    J = s.inertia
    M = np.array(s.effects.magnetizable.M)
    B = float(np.linalg.norm(s.field[0].real))
    om = s.initial.spin
    q = mg.theorem2_quantity(J, M, om, B)
    print(f"\n  ω²J + B²M/μ0 = {q} J: stable axis x{np.argmax(q) + 1}; J alone: x{np.argmax(J) + 1}")
    assert np.argmax(q) == 0 and np.argmax(J) == 2
    T = 16.0
    r = run(s, duration=T)
    R = quat_to_matrix(r.q)
    x1z, x3z = R[:, 2, 0], R[:, 2, 2]  # z3 components of the body axes x1, x3
    h = r.L[0, 2]
    h_drift = np.max(np.abs(r.L[:, 2] / h - 1))
    e_x1 = 1 - abs(x1z[-1])
    e_spin = abs(abs(r.omega_b[-1, 0]) / (h / J[0]) - 1)
    print(f"  wall {r.wall_time:.2f} s; x3 leaves B: min |x3·z3| = {np.min(np.abs(x3z)):.3f}; at {T} s "
          f"|x1·z3| = {abs(x1z[-1]):.5f}, Ω_b = {np.round(r.omega_b[-1], 3)} rad/s (h/J1 = {h / J[0]:.3f})")
    report("scene: L·B drift", h_drift, 1e-12)
    report("scene: 1 − |x1·B̂| at the end", e_x1, 2e-3)
    report("scene: |Ω_b1| vs h/J1 at the end, relative", e_spin, 2e-3)
    # the same start with M isotropic: x3 (largest J) is the stable axis, the nutation decays
    iso = np.eye(3) * float(M[1, 1])
    s2 = load_scene("magnetizable_body", overrides={"effects.magnetizable.M": iso.tolist()})
    r2 = run(s2, duration=4.0)
    th = r2.theta
    print(f"  M isotropic: θ {np.degrees(th[0]):.3f}° → {np.degrees(th[-1]):.4f}° in 4 s")
    assert th[-1] < 0.5 * th[0] and np.max(th) < 1.2 * th[0]
