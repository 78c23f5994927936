"""Checks of gyro_sim.averaging.averaged_m: [M] (3.6), (3.14), (3.17) against an independent average of the
instantaneous torque, the small-θ closed forms (3.10)–(3.12), (3.15), (3.18)–(3.20), the first
integral (3.7), and the full (unaveraged) model, with the error measured as a function of μ.

Run from the repo root: .venv/bin/python -m pytest -q -s test/test_averaged_m.py
(every test prints what it measured and the tolerance it holds it to).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim import load_scene, run
from gyro_sim.averaging.averaged_m import (
    MU_MAX,
    ConstantFieldM,
    PulsatingFieldM,
    RotatingFieldM,
    averaged_m_model,
    errors_against_full,
    slow_variables,
    thin_shell_l_rate_polynomial,
    thin_shell_l_star,
    torus_average_rates,
)
from gyro_sim.physics.closed_forms import (
    constant_field_transverse_decay_rate,
    thin_shell_nutation_window,
    torque_slip,
)
from gyro_sim.scenes.scene import SceneError

J1 = 5.592e-6  # kg·m², the scenes' equatorial moment
J3 = 6.7e-6  # kg·m², oblate: κ = 0.198
TILT = [0.479425538604203, 0, 0.8775825618903728]  # L direction at ρ = 0.5 rad
THIN = {"kind": "thin_shell", "outer_radius": 0.025, "thickness": 0.001, "conductivity": 2.5e7}
SPHERE = {"kind": "solid_sphere", "outer_radius": 0.025, "conductivity": 2.5e7}
SHELL = {"kind": "shell", "outer_radius": 0.025, "thickness": 0.008, "conductivity": 2.5e7}
TAU_THIN = 4e-7 * math.pi * 2.5e7 * 0.025 * 0.001 / 3  # μ0 σ r2 h / 3 (s)


def model(name, **ov):
    return averaged_m_model(load_scene(name, overrides=ov))


def rotating_field(B0, w):
    return [{"real": [B0, 0, 0], "imag": [0, B0, 0], "frequency": w}]


def pulsating_field(B0, w):
    return [{"real": [0, 0, 0], "imag": [0, 0, B0], "frequency": w}]


def constant_field(B0):
    return [{"real": [0, 0, B0], "imag": [0, 0, 0], "frequency": 0.0}]


# ------------------------------------------------------------------------------------------------
# 1. the printed right-hand sides = the average of the instantaneous torque
# ------------------------------------------------------------------------------------------------
CONFIGS = [
    ("constant_field", {"rotor.inertia": [J1, J1, J3]}),
    ("constant_field", {"rotor.inertia": [J1, J1, 0.3 * J1], "rotor.conductor": SPHERE}),
    ("pulsating_field", {"rotor.conductor": SHELL, "rotor.inertia": [J1, J1, 1.8 * J1]}),
    ("pulsating_field", {"rotor.inertia": [J1, J1, 0.6 * J1]}),
    ("rotating_field", {"rotor.inertia": [J1, J1, J3]}),
    ("rotating_field", {"rotor.conductor": SPHERE, "field": [{"real": [2e-3, 0, 0], "imag": [0, -2e-3, 0],
                                                               "frequency": 900.0}]}),  # turning the other way
    ("rotating_field", {"rotor.conductor": SHELL, "rotor.inertia": [J1, J1, 0.4 * J1]}),
]


def test_printed_equations_equal_torus_average():
    """(3.6), (3.14), (3.17) as implemented vs torus_average_rates (FFT average of m × B of the steady
    linear response over ψ, φ, ωt; no [M] formula used) at random slow states, for the three
    conductors and oblate/prolate rotors, including θ ≈ π/2 (ν ≈ 0), ρ ≈ 0 and l ± ν ≈ 0.
    Also: the projected torques do not depend on φ, and the reading "l sinρ σ′" is rejected."""
    rng = np.random.default_rng(7)
    worst, spread_max, alt_min = 0.0, 0.0, math.inf
    for name, ov in CONFIGS:
        m = model(name, **ov)
        states = [(m.J1 * rng.uniform(200, 12000), rng.uniform(0.02, 3.12), rng.uniform(-3, 3), rng.uniform(0.02, 3.12))
                  for _ in range(12)]
        states += [(m.J1 * 3000, 0.7, 0.1, math.pi / 2), (m.J1 * 2500, 1e-3, 0.2, 1.1)]
        if m.kappa < -0.5:  # l + ν = 0 at cosθ = −(1+κ)/κ
            states.append((m.J1 * 2000, 0.9, 0.3, math.acos(-(1 + m.kappa) / m.kappa)))
        for L, rho, sig, th in states:
            a = m.rates(L, rho, sig, th)
            b, spread = torus_average_rates(m, L, rho, sig, th, phi_spread=True)
            w = np.array([1.0, L, L * math.sin(rho), L])  # → torque units: |L|′, |L|ρ′, |L| sinρ σ′, |L|θ′
            worst = max(worst, float(np.max(np.abs(a - b) * w) / np.max(np.abs(b) * w)))
            spread_max = max(spread_max, spread)
            if math.sin(rho) < 0.9 and abs(b[2]) * w[2] > 1e-3 * np.max(np.abs(b) * w):
                # the other reading of the printed left side, "l sinρ σ′ = ...": off by 1/sinρ
                alt_min = min(alt_min, abs(a[2] / math.sin(rho) - b[2]) / abs(b[2]))
    print(f"\n  printed (3.6)/(3.14)/(3.17) vs torus average: max rel. error {worst:.1e} (tol 1e-10); "
          f"φ-dependence of the torque {spread_max:.1e} (tol 1e-12); reading 'l sinρ σ′' off by ≥ {alt_min:.2f}")
    assert worst < 1e-10
    assert spread_max < 1e-12
    assert alt_min > 0.1


# ------------------------------------------------------------------------------------------------
# 2. closed forms and first integral
# ------------------------------------------------------------------------------------------------
def test_small_theta_closed_forms():
    """(3.10)/(3.11), the small-θ limit of (3.14) behind (3.15), and (3.18) vs (1/θ) dθ/dt of the full
    averaged equations at θ = 1e-5 (agreement O(θ²)); (3.18) equals closed_forms'
    small_theta_nutation_rate; a quasi-static oblate rotor always satisfies (3.11)."""
    th = 1e-5
    worst = 0.0
    for m in (model("constant_field", **{"rotor.inertia": [J1, J1, J3], "rotor.conductor": SPHERE}),
              model("constant_field", **{"rotor.inertia": [J1, J1, 0.5 * J1]}),
              model("pulsating_field", **{"rotor.inertia": [J1, J1, J3], "rotor.conductor": SHELL}),
              model("pulsating_field", **{"rotor.inertia": [J1, J1, 0.5 * J1]}),
              model("rotating_field", **{"rotor.inertia": [J1, J1, J3], "rotor.conductor": SPHERE}),
              model("rotating_field", **{"rotor.inertia": [J1, J1, 0.5 * J1]})):
        for L in m.J1 * np.array([300.0, 1500.0, 6000.0]):
            for rho in (0.0, 0.4, 1.3, 2.5):
                full = m.rates(L, rho, 0.0, th)[3] / th
                closed = m.small_theta_rate(L, rho)
                worst = max(worst, abs(full - closed) / max(abs(closed), 1e-300))
    rot = model("rotating_field", **{"rotor.inertia": [J1, J1, J3], "rotor.conductor": SHELL})
    e318 = max(abs(rot.small_theta_rate(L, 0.0) / rot.small_theta_rate_318(L) - 1) for L in J1 * np.array([200.0, 1e3, 5e3]))
    qs = model("constant_field", **{"rotor.inertia": [J1, J1, J3], "torque_model": "quasi_static"})
    always = all(qs.nutation_decays(J1 * l, rho) for l in (10.0, 1e3, 1e5) for rho in np.linspace(0, math.pi, 7))
    print(f"\n  small-θ closed forms (3.10), (3.15), (3.18) vs θ′/θ at θ = 1e-5: {worst:.1e} (tol 1e-8); "
          f"(3.18) vs closed_forms: {e318:.1e} (tol 1e-12); quasi-static κ > 0 satisfies (3.11) everywhere: {always}")
    assert worst < 1e-8 and e318 < 1e-12 and always


def test_thin_shell_closed_forms():
    """Thin shell: l* = √(1+κ)/τ where (3.11) changes sign at ρ = π/2 (after (3.12)); the roots of
    (3.20) where (3.18) changes sign; (3.9): d|L|/dt = −¼ B0² sin²ρ S τ l · 2P(u)/D with
    P = a2 u² + a1 u + a0, D = (1 + u)(1 + u(1+bc)²)(1 + u(1−bc)²), u = τ² l²."""
    m = model("constant_field", **{"rotor.inertia": [J1, J1, J3]})
    ls = thin_shell_l_star(TAU_THIN, m.kappa)
    sgn = [m.small_theta_rate(J1 * ls * f, math.pi / 2) for f in (1 - 1e-6, 1 + 1e-6)]
    rot = model("rotating_field", **{"rotor.inertia": [J1, J1, J3], "field": rotating_field(2e-3, 3.0 / TAU_THIN)})
    win = thin_shell_nutation_window(J1, J3, TAU_THIN, rot.omega)
    roots_ok = all(rot.small_theta_rate(Lr * (1 - 1e-6)) * rot.small_theta_rate(Lr * (1 + 1e-6)) < 0
                   for Lr in (win.L_low, win.L_high))
    worst39 = 0.0
    for kap in (0.2, -0.3, -0.75):
        mm = model("constant_field", **{"rotor.inertia": [J1, J1, (1 + kap) * J1]})
        for th in (0.3, 1.2, 2.0):
            for u in (0.01, 1.0, 50.0):
                l = math.sqrt(u) / TAU_THIN
                a0, a1, a2 = thin_shell_l_rate_polynomial(th, kap)
                b, c = kap / (1 + kap), math.cos(th)
                D = (1 + u) * (1 + u * (1 + b * c) ** 2) * (1 + u * (1 - b * c) ** 2)
                expect = -0.25 * mm.B0**2 * math.sin(0.7) ** 2 * mm.S * TAU_THIN * l * 2 * (a2 * u * u + a1 * u + a0) / D
                got = mm.rates(J1 * l, 0.7, 0.0, th)[0]
                worst39 = max(worst39, abs(got / expect - 1))
    print(f"\n  (3.11) sign change at l* = √(1+κ)/τ: rates {sgn[0]:.2e}, {sgn[1]:.2e}; (3.18) changes sign at the "
          f"(3.20) roots: {roots_ok}; (3.9) polynomial vs (3.6): {worst39:.1e} (tol 1e-8)")
    assert sgn[0] < 0 < sgn[1] and roots_ok and worst39 < 1e-8


def test_limits_against_closed_forms():
    """Rotating field at ρ = θ = 0: d|L|/dt = the torque–slip curve (closed_forms.torque_slip);
    constant field, sphere inertia, quasi-static: L sinρ decays at k_e B²/J
    (closed_forms.constant_field_transverse_decay_rate); oblate rotor in a constant field: |L|
    decreases and ρ → 0 ([M] after (3.7))."""
    rot = model("rotating_field", **{"rotor.conductor": SPHERE, "rotor.inertia": [J1, J1, J3]})
    e_slip = max(abs(rot.rates(L, 0.0, 0.0, 0.0)[0] / torque_slip(rot.g, rot.r2, rot.B0, rot.omega - L / J3) - 1)
                 for L in J3 * np.array([0.0 + 1.0, 300.0, 1100.0, 2000.0]))
    qs = model("constant_field", **{"rotor.inertia": [J1, J1, J1], "torque_model": "quasi_static"})
    L, rho = J1 * 50.0, 0.8
    dL, drho = qs.rates(L, rho, 0.0, 0.3)[:2]
    rate = -(dL * math.sin(rho) + L * math.cos(rho) * drho) / (L * math.sin(rho))
    k_e = qs.S * qs.g(1.0).imag
    e_dec = abs(rate / constant_field_transverse_decay_rate(k_e, qs.B0, J1) - 1)
    ob = model("constant_field", **{"rotor.inertia": [J1, J1, J3], "rotor.conductor": SHELL})
    signs = all(ob.rates(J1 * l, r, 0.0, t)[0] < 0 and ob.rates(J1 * l, r, 0.0, t)[1] < 0
                for l in (100.0, 3e3, 3e4) for r in (0.3, 1.0) for t in (0.2, 1.5, 2.8))
    # the modal ĝ (what the full model integrates, 10 modes) vs the closed forms (2.13)/(2.14)
    e_modal = 0.0
    for cond in (SPHERE, SHELL):
        sc = load_scene("rotating_field", overrides={"rotor.conductor": cond, "rotor.inertia": [J1, J1, J3]})
        mo, ex = averaged_m_model(sc), averaged_m_model(sc, exact=True)
        for st in ((J1 * 400, 0.5, 0.0, 0.3), (J1 * 3000, 1.2, 0.0, 1.0)):
            a, b = mo.rates(*st), ex.rates(*st)
            e_modal = max(e_modal, float(np.max(np.abs(a - b) * [1, st[0], st[0], st[0]])
                                         / np.max(np.abs(b) * [1, st[0], st[0], st[0]])))
    print(f"\n  torque-slip: {e_slip:.1e} (tol 1e-12); transverse decay k_e B²/J: {e_dec:.1e} (tol 1e-12); "
          f"oblate: |L| and ρ decrease: {signs}; modal (10 modes) vs exact ĝ: {e_modal:.1e} (tol 1e-3)")
    assert e_slip < 1e-12 and e_dec < 1e-12 and signs and e_modal < 1e-3


def test_first_integral_37():
    """[M] (3.7): |L| cosρ = L·z3 is constant in the constant and pulsating fields, in the averaged
    solution (to the integrator's tolerance) and in the full model (the torque m × B is ⟂ B ∥ z3);
    in the rotating field it is not (the test can tell)."""
    out = {}
    for name, ov in (("constant_field", {"initial.spin": 3000.0, "initial.theta": 0.5, "field": constant_field(0.05)}),
                     ("pulsating_field", {"initial.spin": 3000.0, "initial.theta": 0.5, "field": pulsating_field(0.05, 2300.0)}),
                     ("rotating_field", {"initial.spin": 400.0, "initial.theta": 0.3, "initial.L_direction": TILT,
                                         "field": rotating_field(0.014, 1256.6)})):
        sc = load_scene(name, overrides={**ov, "rotor.inertia": [J1, J1, J3], "duration": 0.3, "output": {"rate": 1000.0}})
        m = averaged_m_model(sc)
        res = run(sc)
        a = m.integrate(res.t)
        lc_avg = np.ptp(a.l_cos_rho) / a.L[0]
        lc_full = np.ptp(res.L[:, 2]) / np.linalg.norm(res.L[0])
        out[name] = (lc_avg, lc_full, abs(a.L[-1] / a.L[0] - 1))
    for k, v in out.items():
        print(f"\n  {k}: spread of |L| cosρ / |L0|: averaged {v[0]:.1e}, full {v[1]:.1e}; |L| changed by {v[2]:.2f}", end="")
    print()
    for k in ("constant_field", "pulsating_field"):
        assert out[k][0] < 1e-8 and out[k][1] < 1e-12 and out[k][2] > 0.01
    assert out["rotating_field"][0] > 1e-2 and out["rotating_field"][1] > 1e-2


# ------------------------------------------------------------------------------------------------
# 3. against the full model: error O(μ)
# ------------------------------------------------------------------------------------------------
MUS = (8e-3, 2e-3, 5e-4)
RATIO_BAND = (3.0, 6.5)  # error ratio per 4× in μ (O(μ): 4) of the errors that matter (≥ 10 % of the largest);
# pulsating/shell σ measured 6.06 with the three-pass frozen-flow full model
ERR_PER_MU = 10.0  # error / μ bound (measured ≤ 7.7, near the unstable θ = π/2 that amplifies the O(μ) start offset)

FULL_CASES = {
    # name: (scene, overrides, slow-time horizon C: T = C/(μ l0))
    "constant/thin": ("constant_field", {"initial.spin": 3000.0, "initial.theta": 0.5}, 4.0),
    # starts next to θ = π/2 (ν ≈ 0), an unstable equilibrium of (3.6) for this oblate rotor: θ runs to 0.7
    "constant/sphere θ0=1.52": ("constant_field", {"initial.spin": 3000.0, "initial.theta": 1.52,
                                                   "rotor.conductor": SPHERE}, 4.0),
    "pulsating/shell": ("pulsating_field", {"initial.spin": 3000.0, "initial.theta": 0.5, "rotor.conductor": SHELL,
                                            "field": pulsating_field(5e-3, 2300.0)}, 4.0),
    "rotating/thin": ("rotating_field", {"initial.spin": 400.0, "initial.theta": 0.3, "initial.L_direction": TILT}, 1.5),
    "rotating/sphere": ("rotating_field", {"initial.spin": 400.0, "initial.theta": 0.3, "initial.L_direction": TILT,
                                           "rotor.conductor": SPHERE}, 1.5),
}


def scaled_scene(name, ov, mu, C, n_out=400, spt=48):
    """The scene with the field scaled so that μ (at t = 0) = mu, run for C slow times 1/(μ l0)."""
    base = averaged_m_model(load_scene(name, overrides={**ov, "rotor.inertia": ov.get("rotor.inertia", [J1, J1, J3])}))
    L0 = base.y0[0]
    k = math.sqrt(mu / base.mu(L0))
    fld = []
    for f in load_scene(name, overrides=ov).field:
        fld.append({"real": [k * x for x in f.real], "imag": [k * x for x in f.imag], "frequency": f.frequency})
    T = C / (mu * L0 / base.J1)
    sc = load_scene(name, overrides={**ov, "rotor.inertia": ov.get("rotor.inertia", [J1, J1, J3]), "field": fld,
                                     "duration": T, "output": {"rate": n_out / T},
                                     "integrator": {"steps_per_turn": spt}})
    return sc


def error_table(name, ov, C, mus=MUS):
    rows = []
    for mu in mus:
        sc = scaled_scene(name, ov, mu, C)
        m = averaged_m_model(sc)
        res = run(sc)
        err, _ = errors_against_full(m, res)
        ok, why = m.region()
        rows.append((mu, err, ok, res.steps))
    return rows


def print_table(label, rows):
    print(f"\n  {label}: max error over {len(rows)} runs (|L| rel., ρ, sinρ·σ, θ in rad; error/μ in brackets)")
    for mu, e, ok, steps in rows:
        print(f"    μ = {mu:.1e} (region {'ok' if ok else 'no'}, {steps} steps): " +
              "  ".join(f"{k} {v:.2e} [{v / mu:.2f}]" for k, v in e.items()))


@pytest.mark.parametrize("case", list(FULL_CASES))
def test_full_model_error_is_O_mu(case):
    """Averaged (3.6)/(3.14)/(3.17) vs the full model over C slow times, for μ = 8e-3, 2e-3, 5e-4: every
    slow-variable error stays below 10 μ, and each error that matters (≥ 10 % of the largest one at
    the smaller μ) falls by 3–6× per 4× in μ (O(μ); a wrong term would leave an O(1) error)."""
    name, ov, C = FULL_CASES[case]
    rows = error_table(name, ov, C)
    print_table(case, rows)
    ratios = []
    for (mu1, e1, *_), (mu2, e2, *_) in zip(rows, rows[1:]):
        top = max(e2.values())
        for k in e1:
            assert e1[k] <= ERR_PER_MU * mu1 and e2[k] <= ERR_PER_MU * mu2, (k, e1[k], e2[k])
            if e2[k] >= 0.1 * top:
                ratios.append((k, e1[k] / e2[k]))
    print("    ratios per 4× μ: " + ", ".join(f"{k} {r:.2f}" for k, r in ratios) + f"  (band {RATIO_BAND})")
    assert all(RATIO_BAND[0] <= r <= RATIO_BAND[1] for _, r in ratios)


def test_resonance_is_outside_region():
    """Pulsating field at l = 2ω (torque harmonic ψ − 2ωt resonant): region() refuses it, and the
    full model shows why: the θ and σ errors fall only ~2× per 4× in μ (passage through a resonance,
    O(√μ)) and are ≥ 10× those of the non-resonant case ω = 0.75 l at the same μ."""
    l0 = 3000.0 * J3 / J1
    res_rows = error_table("pulsating_field", {"initial.spin": 3000.0, "initial.theta": 0.5,
                                               "field": pulsating_field(5e-3, 0.5 * l0)}, 4.0)
    ok_rows = error_table("pulsating_field", {"initial.spin": 3000.0, "initial.theta": 0.5,
                                              "field": pulsating_field(5e-3, 0.75 * l0)}, 4.0)
    print_table("pulsating, l = 2ω (resonant)", res_rows)
    print_table("pulsating, l = 4ω/3 (non-resonant)", ok_rows)
    m = model("pulsating_field", **{"initial.spin": 3000.0, "rotor.inertia": [J1, J1, J3],
                                    "field": pulsating_field(5e-3, 0.5 * l0)})
    ok, why = m.region()
    print(f"    region at l = 2ω: {ok}: {why}")
    r_th = res_rows[1][1]["theta"] / res_rows[2][1]["theta"]
    big = res_rows[2][1]["theta"] / ok_rows[2][1]["theta"]
    print(f"    resonant θ-error ratio per 4× μ: {r_th:.2f} (tol < 2.8); resonant/non-resonant at μ = {MUS[-1]:g}: {big:.1f} (tol > 10)")
    assert not ok and "resonance" in why
    assert r_th < 2.8 and big > 10


def test_prolate_thin_shell_L_grows_in_constant_field():
    """[M] after (3.9): for −(√(1+sin²θ) − cosθ)/(cosθ sin²θ) < κ/(1+κ) < −1/cosθ the u² coefficient
    a2 < 0 and |L| grows for u = τ²l² > u*. Thin shell, κ/(1+κ) = −3 (κ = −0.75), cosθ = 0.375,
    lτ = 40, ρ = π/2: (3.6) predicts |L| rising by ~1.4 % before θ leaves the window; the full
    model (μ = 2.5e-4) shows the same rise (peak within 10 % of the predicted one)."""
    kap = -0.75
    J3p = (1 + kap) * J1
    th0 = math.acos(0.375)
    a0, a1, a2 = thin_shell_l_rate_polynomial(th0, kap)
    l0 = 40.0 / TAU_THIN
    ov = {"initial.spin": l0 * J1 / J3p, "initial.theta": th0, "rotor.inertia": [J1, J1, J3p],
          "initial.L_direction": [1, 0, 0]}
    sc = scaled_scene("constant_field", ov, 2.5e-4, 1.5)
    m = averaged_m_model(sc)
    res = run(sc)
    err, a = errors_against_full(m, res)
    sv = slow_variables(res)
    rise_full = sv["L"].max() / sv["L"][0] - 1
    rise_avg = a.L.max() / a.L[0] - 1
    print(f"\n  (3.9) a2 = {a2:.3f} < 0; |L| rise: averaged {rise_avg:.4f}, full {rise_full:.4f} (tol 10 %); "
          f"errors {', '.join(f'{k} {v:.1e}' for k, v in err.items())}")
    assert a2 < 0 and m.rates(*m.y0)[0] > 0
    assert rise_avg > 0.01 and abs(rise_full / rise_avg - 1) < 0.1


# ------------------------------------------------------------------------------------------------
# 4. region and scene parsing
# ------------------------------------------------------------------------------------------------
def test_region_and_scenes():
    """region(): ok in the validated cases; refuses |L| = 0, large μ, J1 ≠ J2, a slow eddy transient,
    the resonances l = ω and l = 2ω; fields that are not [M]'s raise SceneError."""
    checks = []
    m = model("constant_field", **{"initial.spin": 3000.0, "rotor.inertia": [J1, J1, J3]})
    checks.append(("constant nominal", m.region(), True, "μ ="))
    strong = model("constant_field", **{"initial.spin": 3000.0, "rotor.inertia": [J1, J1, J3], "field": constant_field(0.5)})
    checks.append(("constant large μ", strong.region(), False, "μ_eff"))
    checks.append(("constant, μ_max", m.region(mu_max=m.mu(m.y0[0]) / 2), False, "μ_eff"))
    checks.append(("rotating from rest", model("rotating_field").region(), False, "|L| = 0"))
    checks.append(("J1 ≠ J2", model("constant_field", **{"rotor.inertia": [J1, 1.1 * J1, J3]}).region(), False, "axisymmetric"))
    slow = model("constant_field", **{"initial.spin": 3000.0, "rotor.inertia": [J1, J1, J3],
                                      "rotor.conductor": {**SPHERE, "conductivity": 1e9}, "field": constant_field(0.02)})
    checks.append(("slow eddy transient", slow.region(), False, "transient"))
    l0 = 3000.0 * J3 / J1
    for f, lab in ((1.0, "l = ω"), (0.5, "l = 2ω"), (0.999, "l ≈ ω")):
        mm = model("pulsating_field", **{"initial.spin": 3000.0, "rotor.inertia": [J1, J1, J3],
                                         "field": pulsating_field(5e-3, f * l0)})
        checks.append((lab, mm.region(), False, "resonance"))
    for lab, (ok, why), want, key in checks:
        print(f"\n  {lab}: {ok} — {why}", end="")
        assert ok == want and key in why, (lab, ok, why)
    print()
    assert isinstance(model("pulsating_field"), PulsatingFieldM) and isinstance(model("constant_field"), ConstantFieldM)
    assert isinstance(RotatingFieldM.from_scene(load_scene("rotating_field")), RotatingFieldM)
    with pytest.raises(SceneError):
        RotatingFieldM.from_scene(load_scene("constant_field"))
    # along a path: the default pulsating scene sits next to l = ω (l = 306, ω = 314 rad/s)
    pm = model("pulsating_field")
    t_exit, why = pm.first_exit(pm.integrate(np.linspace(0.0, 1.0, 11)))
    assert t_exit == 0.0 and "resonance" in why
    neg = model("rotating_field", field=[{"real": [1e-3, 0, 0], "imag": [0, -1e-3, 0], "frequency": 100.0}])
    assert isinstance(neg, RotatingFieldM) and neg.omega == -100.0 and neg.B0 == 1e-3
    st = model("rotating_field", field=[], stators=[{"name": "z3", "axis": [0, 0, 1], "coil_constant": 1e-3,
                                                      "current": 2.0, "rate": -50.0, "phase": 0.3}])
    assert st.omega == -50.0 and abs(st.B0 - 2e-3) < 1e-15
    for bad in ([{"real": [1e-3, 0, 0], "imag": [0, 0, 0], "frequency": 0.0}],  # constant, not along z3
                [{"real": [1e-3, 0, 1e-3], "imag": [0, 0, 0], "frequency": 10.0}],  # elliptic/tilted
                [{"real": [0, 0, 1e-3], "frequency": 0.0}, {"real": [0, 0, 1e-3], "frequency": 5.0}]):
        with pytest.raises(SceneError):
            model("constant_field", field=bad)
    assert MU_MAX == 1e-2
