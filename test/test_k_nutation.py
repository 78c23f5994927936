"""[K] (Komarov) averaged nutation models against the full model (gyro_sim.averaging.averaged; docs/averaged_k.md).

Every test runs the full model (gyro_sim.run on scenes from scene_from_dict, quasi-static torque
[K] (1.2)) and compares it with the averaged model in SI; each prints the error it measured.
``pytest -q -s test/test_k_nutation.py`` shows them. ε below is the averaging parameter: a stator
rate constant a = k_e B²/J over the precession rate |L|/J ([K]'s μ m_k).
"""
import math

import numpy as np
import pytest

import gyro_sim
from gyro_sim.compiled import effects
from gyro_sim.averaging.averaged import (K21Model, PsiSwitchingK, RotorK, StatorsK, k_e_of_scene, nutation_k22,
                               nutation_k22_rate, psi_switching_averaged, time_to_theta, transverse_decay_k32)

J = 5.592e-6  # kg·m², equatorial moment of the nutation_oblate rotor
B = 0.01  # coil constant, T/A
COND = dict(kind="thin_shell", outer_radius=0.025, thickness=0.001, conductivity=2.5e7)
K_E = 2 * math.pi / 3 * 2.5e7 * 0.025**4 * 0.001  # thin shell k_e = (2π/3) σ r2⁴ h, N·m·s/T²


def rotor(kappa):
    return dict(inertia=[J, J, J * (1 + kappa)], conductor=COND)


def stator(name, axis, current=0.0, rate=0.0, phase=0.0):
    return dict(name=name, axis=axis, coil_constant=B, current=current, rate=rate, phase=phase)


def current_for(a):
    """Current (A) that gives the rate constant a = k_e (b I)²/J (1/s)."""
    return math.sqrt(a * J / K_E) / B


def crossing(r, target, up=False):
    th = r.theta
    ok = th > target if up else th < target
    i = int(np.argmax(ok))
    return float(r.t[i]) if ok[i] else math.inf


def test_k_e_is_the_conductor_value():
    s = gyro_sim.scene_from_dict(dict(rotor=rotor(0.0), duration=1.0))
    assert k_e_of_scene(s) == pytest.approx(K_E, rel=1e-12)
    r = RotorK.of([1.0, 1.2, 1.5])
    assert r.J == pytest.approx(2 * 1.2 / 2.2) and r.delta == pytest.approx(0.2 / 2.2)
    assert r.kappa == pytest.approx(1.5 / r.J - 1)


# ------------------------------------------------------------------------------------------
# (2.2): no control
# ------------------------------------------------------------------------------------------
def k22_scene(kappa, current, theta0, duration):
    return gyro_sim.scene_from_dict(dict(
        name="k22", rotor=rotor(kappa), torque_model="quasi_static",
        stators=[stator("z3", [0, 0, 1], current, 200.0)], initial=dict(spin=200.0, theta=theta0),
        duration=duration, output=dict(rate=2000.0)))


def test_k22_oblate_to_pole_prolate_to_equator_at_the_rate_of_2_2():
    """tan θ(t) = tan θ0 exp[−¼ κ/(1+κ) g² t], g² = 2 a (one stator, L ∥ z3), for κ = ±0.2 and two ε.

    Oblate (κ > 0): θ → 0 from θ0 < π/2 and → π from θ0 > π/2; prolate (κ < 0): θ → π/2. The rate is
    the slope of ln tan θ over the first 2 e-folds; the runs go on to 5 e-folds to see the end state.
    Expected error: O(ε) at most (second-order averaging); measured it falls faster (≈ ε^1.5–2).
    """
    print()
    for kappa, th0, goal in ((0.2, 0.6, 0.0), (0.2, math.pi - 0.6, math.pi), (-0.2, 0.3, math.pi / 2)):
        errs = []
        for current in (3.0, 6.0):
            probe = k22_scene(kappa, current, th0, 1.0)
            st = StatorsK.of_scene(probe)
            rate = float(nutation_k22_rate(probe.inertia, K_E, st, [0, 0, 1]))
            T = 5.0 / abs(rate)
            r = gyro_sim.run(k22_scene(kappa, current, th0, T))
            eps = st.rate_constants(K_E, J)[0] / (np.linalg.norm(r.L[0]) / J)
            w = r.t < 2.0 / abs(rate)
            slope = np.polyfit(r.t[w], np.log(np.abs(np.tan(r.theta[w]))), 1)[0]
            err = abs(slope / rate - 1)
            pred = nutation_k22(th0, r.t, probe.inertia, K_E, st)
            dth = np.degrees(np.max(np.abs(r.theta[w] - pred[w])))
            print(f"  κ = {kappa:+.1f}, θ0 = {math.degrees(th0):5.1f}°, ε = {eps:.4f}: d ln tanθ/dt = {slope:+.5f}/s "
                  f"vs (2.2) {rate:+.5f}/s, rel. error {err:.1e}; max |θ − θ(2.2)| = {dth:.3f}°; "
                  f"θ(5 e-folds) = {math.degrees(r.theta[-1]):.2f}° (→ {math.degrees(goal):.0f}°)")
            assert err < eps  # O(ε)
            assert abs(r.theta[-1] - goal) < abs(th0 - goal) * 0.03
            errs.append((eps, err))
        (e1, x1), (e2, x2) = errs
        print(f"    error ratio {x2 / x1:.1f} for ε ratio {e2 / e1:.1f} (exponent {math.log(x2 / x1) / math.log(e2 / e1):.1f})")
        assert x2 > x1  # the error is the averaging error: it grows with ε


def k21_scene(kappa, theta, duration, tilt=0.35, az=0.7, Is=1.6, Ic=1.1, rates=(420.0, -1040.0, 200.0), turn=0.0):
    """Three stators at constant rates; L = the (2.1) equilibrium L* plus a transverse offset (``tilt``,
    relative, at azimuth ``az``), or L* turned by ``turn`` rad towards z3 (same |L|).

    The rates keep every torque frequency (2|ν_k|, |ν_j ± ν_k|) ≥ 12 % away from |L*|/J, 2|L*|/J,
    3|L*|/J (no resonance with the precession) for both rotors used.
    """
    d = dict(name="k21", rotor=rotor(kappa), torque_model="quasi_static",
             stators=[stator("z1", [1, 0, 0], Ic, rates[0]), stator("z2", [0, 1, 0], Ic, rates[1]),
                      stator("z3", [0, 0, 1], Is, rates[2])],
             initial=dict(spin=1.0, theta=theta), duration=duration, output=dict(rate=200.0))
    m = K21Model.of_scene(gyro_sim.scene_from_dict(d))
    Ls = m.equilibrium_L(theta)
    if turn:
        k = np.cross(Ls, [0, 0, 1.0])
        k /= np.linalg.norm(k)
        L0 = Ls * math.cos(turn) + np.cross(k, Ls) * math.sin(turn)
    else:
        L0 = Ls + np.linalg.norm(Ls) * tilt * np.array([math.cos(az), math.sin(az), 0.0])
    d["initial"] = dict(theta=theta, kinetic_moment=float(np.linalg.norm(L0)), L_direction=list(L0))
    return gyro_sim.scene_from_dict(d), m, Ls


def test_k21_three_stators_kinetic_moment_and_nutation():
    """(2.1) for L (vector form) and θ, with g²(t) = Σ a_k (3 − a_3k²) varying as L turns back from 29° off
    its equilibrium direction: oblate rotor from θ0 = 0.6 (→ 0) and π − 0.6 (→ π); θ against (2.2) with the
    full model's own a_3k(t), and against (2.1) integrated."""
    print()
    for th0 in (0.6, math.pi - 0.6):
        s, m, _ = k21_scene(0.2, th0, 4.0, turn=0.5)
        r = gyro_sim.run(s)
        avg = m.integrate(r.L[0], th0, 0.0, r.t)
        eL = np.max(np.linalg.norm(r.L - avg.L, axis=1)) / np.linalg.norm(r.L[0])
        st = StatorsK.of_scene(s)
        pred = nutation_k22(th0, r.t, s.inertia, K_E, st, L=r.L)  # a_3k(t) of the full model
        g2 = np.sum(st.rate_constants(K_E, J) * (3 - (r.L / np.linalg.norm(r.L, axis=1)[:, None]) ** 2), axis=1)
        y, yp = (np.log(np.abs(np.tan(x))) for x in (r.theta, pred))
        e22 = abs(np.polyfit(r.t, y, 1)[0] / np.polyfit(r.t, yp, 1)[0] - 1)
        e21 = np.degrees(np.max(np.abs(r.theta - avg.theta)))
        print(f"  θ0 = {math.degrees(th0):5.1f}°: max |L − L(2.1)|/|L| = {eL:.1e}; g² from {g2[0]:.3f} to {g2[-1]:.3f}/s; "
              f"ln tanθ slope vs (2.2) rel. error {e22:.1e}; max |θ − θ(2.1)| = {e21:.2f}°; "
              f"θ: {math.degrees(th0):.1f}° → {math.degrees(r.theta[-1]):.1f}° ((2.1): {math.degrees(avg.theta[-1]):.1f}°)")
        assert eL < 0.01 and e22 < 0.01 and e21 < 1.0
        assert abs(g2[-1] / g2[0] - 1) > 0.03  # the a_3k did change


# ------------------------------------------------------------------------------------------
# (3.2): transverse decay of L
# ------------------------------------------------------------------------------------------
def test_k32_transverse_part_decays_at_half_m_plus_3n_gamma():
    """Spin stator z3 on, control stators z1, z2 at constant non-resonant rates (equal currents): the
    transverse part z = L1 + i L2, measured from its (2.1) equilibrium z*, decays at ½(a_m + 3a_n)γ
    ([K] (3.2): −½ μ (m + 3n) γ) without turning. γ = 1/(1+κ) for the oblate rotor at θ = 0,
    γ = 1 for the prolate one at θ = π/2 (both stationary, so Ω has no precession harmonics).
    Under ψ-switching ⟨ν_n⟩ = 0, so z* = 0 and z itself decays (that is [K]'s statement)."""
    print()
    for kappa, th in ((0.2, 0.0), (-0.2, math.pi / 2)):
        s, m, Ls = k21_scene(kappa, th, 3.0)
        r = gyro_sim.run(s)
        z = (r.L[:, 0] - Ls[0]) + 1j * (r.L[:, 1] - Ls[1])
        w = np.abs(z) > 0.2 * abs(z[0])  # while the offset is well above the O(ε) ripple of L
        rate = -np.polyfit(r.t[w], np.log(np.abs(z[w])), 1)[0]
        pred = transverse_decay_k32(s.inertia, K_E, B * 1.6, B * 1.1, th)
        turn = np.degrees(np.max(np.abs(np.angle(z[w] / z[0]))))
        print(f"  κ = {kappa:+.1f}, θ = {math.degrees(th):.0f}°: decay rate {rate:.4f}/s vs ½(a_m + 3a_n)γ = {pred:.4f}/s "
              f"(rel. error {rate / pred - 1:+.1e}); azimuth of z − z* kept to {turn:.2f}° "
              f"(θ stayed within {np.degrees(np.max(np.abs(r.theta - th))):.2f}°)")
        assert abs(rate / pred - 1) < 0.02 and turn < 3.0


# ------------------------------------------------------------------------------------------
# ψ-switching (3.1), (3.3)–(3.4)
# ------------------------------------------------------------------------------------------
def psi_scene(kappa, theta0, eps_m=1e-2 / 35, q=0.1, r=(20.0, 50.0), sign=1.0, nu0=200.0, nper=50,
              phases=(0, 0, 0), L_direction=(0, 0, 1.0), L0=None):
    """ψ-switching scene and its averaged model: spin stator z3 at ν0 with a_m = ε_m Λ0 (Λ0 = |L|/J on the
    ellipsoid (3.5) at θ = 0), control stators z1, z2 with a_n = q a_m and rates ν_n = ±r_n Λ0 (far apart
    and fast: non-resonant); |L| on the ellipsoid at θ0 unless L0 is given; control sampled every
    T_prec/nper. The defaults give the control's own ε = a_n ν̄/Λ0² = 1e-3."""
    lam0 = nu0 * (1 + kappa) / (1 + q)  # = Lam0 of (3.5) for these stators
    a_n = q * eps_m * lam0
    d = dict(name="psi", rotor=rotor(kappa), torque_model="quasi_static",
             stators=[stator("z1", [1, 0, 0], phase=phases[0]), stator("z2", [0, 1, 0], phase=phases[1]),
                      stator("z3", [0, 0, 1], rate=nu0, phase=phases[2])],
             initial=dict(theta=theta0, L_direction=list(L_direction)), duration=1.0, output=dict(rate=100.0),
             controller=dict(law="psi_switching", period=1.0, params=dict(
                 control_stators=["z1", "z2"], spin_stator="z3", nu=[sign * x * lam0 for x in r],
                 control_current=current_for(a_n), spin_current=current_for(a_n / q), spin_rate=nu0, dead_band=1e-3)))
    m = PsiSwitchingK.of_scene(gyro_sim.scene_from_dict(d))
    L0 = float(m.ellipsoid_L(theta0)) if L0 is None else L0
    prec = 2 * math.pi * J / L0
    d["initial"]["kinetic_moment"] = L0
    d["controller"]["period"] = prec / nper
    return d, m, prec


def run_psi(d, duration, prec):
    d = dict(d, duration=duration, output=dict(rate=100.0 / prec))
    return gyro_sim.run(gyro_sim.scene_from_dict(d))


def test_psi_switching_reaches_pole_in_finite_time_as_averaged_model_says():
    """[K] §3: θ reaches 0.1° in finite time for an oblate and a prolate rotor (κ = ±0.02) with ν > 0,
    and θ → π (179.9°) with ν < 0; the time agrees with ``time_to_theta`` of (3.4) in SI.

    Control sampled at 1/50 of the precession period (gyro_ctl.laws.psi_switching), ε = 1e-3 (≈ 20
    precession periods), control rates 20 and 50 × |L|/J. Size of the error (measured ≲ 0.4 %): the
    sampled switch comes on average h/2 late, which weakens the drive by ⟨cos⟩ ≈ 1 − (Λh)²/6 = 0.26 %
    (time longer); the σ_n of a switched field swing back and forth instead of turning uniformly
    (residue O(Λ/ν)); the z1–z2 cross terms leave a residue O(Λ/|ν1 − ν2|); O(ε) from averaging.
    """
    print()
    cases = [("oblate", 0.02, math.radians(10), 1.0), ("prolate", -0.02, math.radians(10), 1.0),
             ("oblate, ν < 0", 0.02, math.radians(150), -1.0)]
    for label, kappa, th0, sign in cases:
        d, m, prec = psi_scene(kappa, th0, sign=sign)
        target = math.radians(0.1) if sign > 0 else math.pi - math.radians(0.1)
        tp = m.time_to_theta(th0, target)
        # the function form gives the same number
        assert time_to_theta(th0, target, d["rotor"]["inertia"], K_E, m.B_spin, m.nu0, m.B_c, m.nus) == pytest.approx(tp)
        r = run_psi(d, 1.25 * tp, prec)
        tm = crossing(r, target, up=sign < 0)
        h = d["controller"]["period"]
        bias = (2 * math.pi * h / prec) ** 2 / 6
        print(f"  {label:14s} κ = {kappa:+.2f}: θ {math.degrees(th0):.0f}° → {math.degrees(target):.1f}° in {tm:.4f} s "
              f"(full) vs {tp:.4f} s ((3.4)); rel. error {tm / tp - 1:+.2e} over {tp / prec:.0f} precession periods "
              f"(sampling alone: +{bias:.1e}); final θ {math.degrees(r.theta[-1]):.3f}°, "
              f"|L⊥|/|L| = {np.hypot(*r.L[-1, :2]) / np.linalg.norm(r.L[-1]):.1e}")
        assert math.isfinite(tm) and abs(tm / tp - 1) < 0.02
        assert (r.theta[-1] < target) if sign > 0 else (r.theta[-1] > target)


def test_psi_switching_beats_the_passive_drift_of_a_prolate_rotor():
    """κ = −0.2, p = V/(κλ a_m ν0) = −0.8 (|p| > p* = ½(1+κ)^{-1/2}: no limit cycle, (3.10)): from θ0 = 60° the
    rotor crosses the passive barrier near 45° and reaches 0.1°; the time depends on [K]'s λ (+10 % on λ
    gives +20 % on the time), and the full model agrees with (3.4) to ~1 %."""
    d, m, prec = psi_scene(-0.2, math.radians(60), eps_m=0.02, q=0.003, r=(15.0, 37.5))
    m = PsiSwitchingK.of_scene(gyro_sim.scene_from_dict(dict(d, duration=1.0)))
    print(f"\n  p = {m.p:+.3f}, p*² = {m.p_star_sq:.3f}, cycles: {m.cycles_exist()}")
    assert not m.cycles_exist()
    target = math.radians(0.1)
    tp = m.time_to_theta(math.radians(60), target)
    r = run_psi(d, 1.2 * tp, prec)
    tm = crossing(r, target)
    free = m.V  # without the passive term the time would be θ/(V/Λ) with Λ ≈ Lam0
    t_nopassive = math.radians(60) * m.Lam0 / free
    print(f"  t(θ < 0.1°): full {tm:.3f} s, (3.4) {tp:.3f} s, rel. error {tm / tp - 1:+.2e} "
          f"({tp / prec:.0f} precession periods; without the κλ term (3.4) would say ≈ {t_nopassive:.2f} s)")
    assert abs(tm / tp - 1) < 0.03 and tp > 1.2 * t_nopassive


def test_prolate_rotor_is_caught_by_the_limit_cycle_r_minus():
    """(3.9)–(3.10): κ = −0.2, p = −0.3 (|p| < p*): cycles r⁺ (≈ 18°, unstable) and r₋ (≈ 75°, stable for
    κ < 0). From θ0 = 60° the full model follows (3.4) onto r₋ instead of reaching the pole."""
    d, m, prec = psi_scene(-0.2, math.radians(60), eps_m=0.02, q=0.001, r=(16.88, 42.2))
    m = PsiSwitchingK.of_scene(gyro_sim.scene_from_dict(dict(d, duration=1.0)))
    cyc = {c.name: c for c in m.limit_cycles()}
    print(f"\n  p = {m.p:+.3f}; cycles " + ", ".join(f"{c.name}: θ = {math.degrees(c.theta):.2f}°, "
                                                 f"{'stable' if c.stable else 'unstable'}" for c in cyc.values()))
    assert cyc["r-"].stable and not cyc["r+"].stable
    T = 30.0 / m.a_m
    r = run_psi(d, T, prec)
    avg = m.integrate(math.radians(60), r.t, L0=float(np.linalg.norm(r.L[0])))
    tail = r.t > T - 5.0 / m.a_m
    th_full, th_avg = np.degrees(np.mean(r.theta[tail])), np.degrees(np.mean(avg.theta[tail]))
    dev = np.degrees(np.max(np.abs(r.theta - avg.theta)))
    print(f"  mean θ over the last sixth of the run: full {th_full:.2f}°, (3.4) {th_avg:.2f}°, r₋ at "
          f"{math.degrees(cyc['r-'].theta):.2f}°; max |θ − θ(3.4)| = {dev:.2f}°; |L|: full "
          f"{np.linalg.norm(r.L[-1]) / cyc['r-'].L:.4f} × |L(r₋)|")
    assert abs(th_full - th_avg) < 1.0 and dev < 1.5
    assert abs(th_full - math.degrees(cyc["r-"].theta)) < 3.0 and np.min(r.theta) > math.radians(50)


def test_vector_form_of_the_control_term_with_L_off_the_spin_axis():
    """(3.3) with L tilted 40° from z3: the ψ-average of the switched drive is (2/π) Σ_n ν_n a_n √(1 − a_3n²)
    (exact for the vector-form law), not the printed 2nν(1 + a_33²)/π: the full model follows the first
    (≲ 1 %) and misses the second by ≈ 12 %."""
    from scipy.integrate import solve_ivp

    rho, az, th0, target = math.radians(40), math.radians(30), math.radians(30), math.radians(5)
    Ld = np.array([math.sin(rho) * math.cos(az), math.sin(rho) * math.sin(az), math.cos(rho)])
    d, m, _ = psi_scene(0.02, th0)
    g = (1 + m.kappa * math.sin(th0) ** 2) / (1 + m.kappa)
    a33 = Ld[2]
    L0 = J * m.a_m * m.nu0 * a33 / (0.5 * g * (m.a_m + 3 * m.a_n + (m.a_m - m.a_n) * a33**2))  # |L| nullcline
    d, m, prec = psi_scene(0.02, th0, L_direction=Ld, L0=L0)
    tv = m.time_to_theta(th0, target, L0=L0, vector=True, L_direction=Ld)

    def printed(t, x):
        f = m.rhs_vector(t, x)
        a3 = m.axes @ (x[:3] / np.linalg.norm(x[:3]))
        lam = np.linalg.norm(x[:3]) / m.rotor.J
        f[3] += 2 / math.pi * (np.sum(m.nus * m.a_c * np.sqrt(1 - a3[:-1] ** 2))
                               - np.mean(m.nus * m.a_c) * (1 + a3[-1] ** 2)) / lam
        return f

    ev = lambda t, x: x[3] - target  # noqa: E731
    ev.terminal = True
    tpr = solve_ivp(printed, (0, 10 * tv), np.concatenate([L0 * Ld, [th0, 0.0]]), events=ev, rtol=1e-10,
                    method="DOP853").t_events[0][0]
    r = run_psi(d, 1.3 * tv, prec)
    tm = crossing(r, target)
    rho_end = math.degrees(math.acos(r.L[-1, 2] / np.linalg.norm(r.L[-1])))
    print(f"\n  θ 30° → 5° with L 40° off z3 (40° → {rho_end:.1f}°): full {tm:.4f} s; √-form {tv:.4f} s "
          f"(rel. error {tm / tv - 1:+.1e}); printed (1 + a_33²) form {tpr:.4f} s (rel. error {tm / tpr - 1:+.1e})")
    assert abs(tm / tv - 1) < 0.02 and abs(tm / tpr - 1) > 0.08


def test_equal_control_rates_resonate():
    """[K] assumes additive stator torques. Under ψ-switching with one |ν| for z1 and z2 the cross torque
    of the two control fields is resonant: it scales the θ-drive by
    f = 1 + [sin D + sin(D − x) + sin(S + x) + sin S]/4 ∈ [0, 2], x = πν/Λ, D = σ1 − σ2 + x, S = σ1 + σ2
    (field phases at t = 0, ψ0 = 0; docs/averaged_k.md §4). With fine sampling (exact-like switching) the
    full model shows f ≈ 2 or ≈ 0 for the field phase σ1 = π/2 or 3π/2 — the averaged model says 1."""
    print()
    for phi1 in (math.pi / 2, 3 * math.pi / 2):
        d, m, prec = psi_scene(0.02, math.radians(10), eps_m=1e-3, r=(10.0, 10.0), nper=1000, phases=(phi1, 0, 0))
        r = run_psi(d, 8 * prec, prec)
        lam = np.linalg.norm(r.L[0]) / J
        slope = np.polyfit(r.t, r.theta, 1)[0]
        passive = -m.kappa * m.lam * m.W0 * math.sin(math.radians(10)) * math.cos(math.radians(10))
        f = (slope - passive) / (-m.V / lam)
        x = math.pi * m.nus[0] / lam
        D, S = phi1 + x, phi1
        f_pred = 1 + (math.sin(D) + math.sin(D - x) + math.sin(S + x) + math.sin(S)) / 4
        print(f"  σ1(0) = {phi1:.3f} rad: θ-drive factor {f:.3f} (cross-term formula {f_pred:.3f}; [K] 1)")
        assert abs(f - f_pred) < 0.1


# ------------------------------------------------------------------------------------------
# the averaged model's own geometry ((3.5)–(3.11)) and the averages it rests on
# ------------------------------------------------------------------------------------------
def test_switched_drive_average_from_the_instantaneous_torque():
    """ψ-average of the quasi-static drive k_e B × dB/dt = c ν_n(ψ) u_n with ν_n = ν sign(u_n·e⊥), e⊥ turning
    about L: ⟨N·e⊥⟩ = (2/π) c ν √(1 − a_3n²) for any direction of L, ⟨N⟩ = 0 in the case frame (so L keeps
    its azimuth, (3.2)). Checked with the field of the simulator's stator triad (kernels.nonlinear_part)."""
    from gyro_sim.compiled import kernels
    from gyro_sim.engine.simulate import stator_triad

    rng = np.random.default_rng(3)
    c_m = 1.0
    for _ in range(3):
        y3 = rng.normal(size=3)
        y3 /= np.linalg.norm(y3)
        e1 = np.cross(y3, [0.3, 0.5, 0.8])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(y3, e1)
        for u in np.eye(3)[:2]:
            a, b, _ = stator_triad(u)
            psi = np.linspace(0, 2 * np.pi, 721)[:-1]
            proj, vec = [], []
            for p in psi:
                ep = math.cos(p) * e1 + math.sin(p) * e2
                nu = 50.0 * (1.0 if ep @ u >= 0 else -1.0)
                sig = 0.37
                Bre = (math.cos(sig) * a + math.sin(sig) * b)[None, :]
                Bim = (-math.sin(sig) * a + math.cos(sig) * b)[None, :]
                y = np.zeros(7)
                y[3] = 1.0  # body at rest (Ω = 0): only the drive
                F = np.zeros(7)
                kernels.nonlinear_part(0.0, y, Bre, Bim, np.array([nu]), np.ones(3), c_m, np.zeros(0), 1.0, 0, F,
                                       np.zeros(25), np.zeros(effects.TAB))
                proj.append(F[0:3] @ ep)
                vec.append(F[0:3].copy())
            c = c_m  # k_e with moment scale 1 and τ_eff 1, B = 1
            want = 2 / math.pi * c * 50.0 * math.sqrt(1 - (u @ y3) ** 2)
            assert np.mean(proj) == pytest.approx(want, rel=3e-3)
            assert np.linalg.norm(np.mean(vec, axis=0)) < 2e-3 * c * 50.0


def test_phase_portrait_of_3_4():
    """(3.5) ellipsoid = nullcline of |L|; (3.6)–(3.7) equilibria at θ = π/2 exist iff |s| ≤ 1, are zeros of
    (3.4), saddles iff δκ cos2φ_K < 0 else foci (stable iff κ < 0); (3.9)–(3.10) cycles are zeros of (3.8),
    exist iff p² ≤ 1/(4(1+κ)), r⁺ stable for κ > 0 and r₋ for κ < 0, agree with [K]'s small-p forms and merge
    into r* at p = p*; (3.11) Q is the energy integral of the free rotor (checked on the full model)."""
    ke = K_E
    for kappa in (0.02, -0.02):
        for delta in (0.01, -0.01):
            J1, J2 = J * (1 - delta), J * (1 + delta)
            Jh = 2 * J1 * J2 / (J1 + J2)
            m = PsiSwitchingK([J1, J2, Jh * (1 + kappa)], ke, 0.02, 200.0, 0.0005, 30.0)
            th = np.linspace(0.1, 3.0, 7)
            assert np.allclose([m.rhs_reduced(0, [L, t, 0.3])[0] for L, t in zip(m.ellipsoid_L(th), th)], 0,
                               atol=1e-12 * J * m.Lam0)
            eqs = m.equilibria()
            assert abs(m.s) <= 1 and len(eqs) == 4
            for e in eqs:
                assert np.max(np.abs(m.rhs_reduced(0, [e.L, e.theta, e.phi])[1:])) < 1e-10
                saddle = delta * kappa * math.cos(2 * (e.phi + math.pi / 2)) < 0
                assert e.kind == ("saddle" if saddle else ("stable focus" if kappa < 0 else "unstable focus"))
            # existence boundary (3.7): |δ| ≥ V/Λ*²
            Ls = m.Lam0 / (1 + kappa)
            for f, n in ((0.99, 4), (1.01, 0)):
                mm = PsiSwitchingK([J1, J2, Jh * (1 + kappa)], ke, 0.02, 200.0, 0.0005, 30.0 * abs(delta) * Ls**2 / m.V * f)
                assert len(mm.equilibria()) == n
    for kappa in (0.2, -0.2):
        base = PsiSwitchingK([J, J, J * (1 + kappa)], ke, 0.02, 200.0, 0.004, 1.0)
        pstar = math.sqrt(base.p_star_sq)
        for p in (0.05, 0.3, 0.999 * pstar, 1.001 * pstar):
            m = PsiSwitchingK([J, J, J * (1 + kappa)], ke, 0.02, 200.0, 0.004, p * math.copysign(1, kappa) / base.p)
            cyc = {c.name: c for c in m.limit_cycles()}
            if p > pstar:
                assert not m.cycles_exist() and not cyc
                continue
            for c in cyc.values():
                assert np.max(np.abs(m._rhs_phi_avg([c.L, c.theta]) / [J * m.a_m * m.nu0, 1.0])) < 1e-10
            assert cyc["r+"].stable == (kappa > 0) and cyc["r-"].stable == (kappa < 0)
            pp = m.p
            if p == 0.05:  # [K]'s small-p forms: cosθ⁺ ≈ −(1 − p²/2) sign p, k⁺ ≈ ω(1 − κp²), cosθ₋ ≈ −(1+κ)p, ...
                assert math.cos(cyc["r+"].theta) == pytest.approx(-(1 - pp**2 / 2) * np.sign(pp), abs=1e-4)
                assert cyc["r+"].L / (J * m.Lam0) == pytest.approx(1 - kappa * pp**2, abs=1e-4)
                assert math.cos(cyc["r-"].theta) == pytest.approx(-(1 + kappa) * pp, rel=1e-2)
                assert cyc["r-"].L / (J * m.Lam0) == pytest.approx((1 + kappa * (1 + kappa) * pp**2) / (1 + kappa), rel=1e-4)
            if p == 0.999 * pstar:  # r*: cosθ* = −√((1+κ)/(2+κ)) sign p, k* = ½ω(2+κ)/(1+κ)
                for c in cyc.values():
                    assert math.cos(c.theta) == pytest.approx(-math.sqrt((1 + kappa) / (2 + kappa)) * np.sign(pp), abs=0.03)
                    assert c.L / (J * m.Lam0) == pytest.approx(0.5 * (2 + kappa) / (1 + kappa), abs=0.01)
    # (3.11): free triaxial rotor of the full model
    s = gyro_sim.scene_from_dict(dict(rotor=dict(inertia=[0.99 * J, 1.01 * J, 1.05 * J]), duration=0.5,
                                      initial=dict(spin=200.0, theta=0.5, phi=0.3), output=dict(rate=2000.0)))
    r = gyro_sim.run(s)
    m = PsiSwitchingK(s.inertia, ke, 0.0, 0.0, 0.0, 0.0)
    Q = m.polhode_Q(r.theta, r.euler[:, 2])
    print(f"\n  (3.11): θ swings {np.degrees(np.ptp(r.theta)):.3f}°, Q constant to {np.ptp(Q) / Q[0]:.1e}")
    assert np.ptp(r.theta) > 1e-3 and np.ptp(Q) < 1e-10 * abs(Q[0])


def test_averaged_integration_hits_the_pole_and_stays():
    m = PsiSwitchingK([J, J, 1.02 * J], K_E, 0.02, 200.0, 0.005, 2000.0)
    t = np.linspace(0, 3 * m.time_to_theta(0.2, 1e-9), 200)
    res = psi_switching_averaged(0.2, t, [J, J, 1.02 * J], K_E, 0.02, 200.0, 0.005, 2000.0)
    assert res.t_hit is not None and res.t_hit == pytest.approx(m.time_to_theta(0.2, 1e-9), rel=1e-3)
    assert np.all(res.theta[t > res.t_hit] == 0.0) and np.all(np.diff(res.theta[t < res.t_hit]) < 0)
    vec = m.integrate(0.2, t, vector=True)
    assert vec.t_hit == pytest.approx(res.t_hit, rel=1e-6)  # (3.2)–(3.3) = (3.4) for L ∥ z3


def test_nutation_prolate_scene():
    """config/nutation_prolate.yaml: ψ-switching damps the nutation of a prolate rotor below 0.1°."""
    s = gyro_sim.load_scene("nutation_prolate")
    assert s.rotor.inertia[2] < s.rotor.inertia[0]
    r = gyro_sim.run(s)
    tm = crossing(r, math.radians(0.1))
    print(f"\n  nutation_prolate (κ = {RotorK.of(s.inertia).kappa:+.4f}, {s.torque_model} torque): θ "
          f"{math.degrees(r.theta[0]):.1f}° → below 0.1° at {tm:.3f} s, {math.degrees(r.theta[-1]):.3f}° at {r.t[-1]:.1f} s")
    assert tm < 0.6 * s.duration and np.degrees(np.max(r.theta[r.t > tm + 0.1])) < 0.1
