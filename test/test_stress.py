"""Numerical stress tests: extreme angles, spins, μ, skin depths, near-resonant stators, random scenes.

Fast versions run by default; ``pytest --stress`` runs the long ones too (marker ``slow``).
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gyro_sim
from gyro_sim.scenes.scene import Accuracy
from gyro_sim.physics.conductor import conductor_model, g_solid_sphere
from gyro_sim.scenes.scene import SceneError, scene_from_dict

SHELL = {"kind": "thin_shell", "outer_radius": 0.025, "thickness": 0.001, "conductivity": 2.5e7}
J = [5.592e-6, 5.592e-6, 5.704e-6]


def scene(**kw):
    d = {"rotor": {"inertia": J, "conductor": SHELL}, "duration": 0.1}
    d.update(kw)
    return scene_from_dict(d)


def finite(r):
    return all(np.all(np.isfinite(a)) for a in (r.L, r.q, r.omega_b, r.torque, r.energy, r.euler[:, 1]))


@pytest.mark.parametrize("theta", [1e-9, math.pi - 1e-9])
@pytest.mark.parametrize("fields", [False, True])
def test_theta_at_the_singular_values(theta, fields):
    """θ0 = 1e-9 and π − 1e-9: the quaternion state has no singularity; outputs stay finite and θ is kept."""
    kw = {"initial": {"spin": 500.0, "theta": theta}, "torque_model": "lag" if fields else "none",
          "stators": [{"name": "z3", "axis": [0, 0, 1], "coil_constant": 1e-3, "current": 1.0, "rate": 600.0}]
          if fields else []}
    if not fields:
        kw["rotor"] = {"inertia": J}
    r = gyro_sim.run(scene(**kw))
    dth = float(np.max(np.abs(r.theta - theta)))
    print(f"\nθ0 = {theta!r}, fields {fields}: max |θ − θ0| = {dth:.1e} rad over {r.steps} steps")
    assert finite(r) and dth < 1e-6


@pytest.mark.parametrize("spin", [1e3, 1e4, 1e5])
def test_high_spin_free_rotor_conserves(spin):
    """Triaxial free rotor up to 1e5 rad/s: |L| and energy at round-off."""
    r = gyro_sim.run(scene_from_dict({"rotor": {"inertia": [5.0e-6, 5.5e-6, 6.0e-6]}, "torque_model": "none",
                                      "initial": {"spin": spin, "theta": 0.4, "phi": 0.3},
                                      "duration": 2000 * 2 * math.pi / spin, "output": {"rate": 50 * spin / 2000}}))
    dE = float(np.max(np.abs(r.energy / r.energy[0] - 1)))
    dL = float(np.max(np.abs(np.linalg.norm(r.L, axis=1) / np.linalg.norm(r.L[0]) - 1)))
    print(f"\nspin {spin:g} rad/s, 2000 revolutions: |L| drift {dL:.1e}, energy drift {dE:.1e}")
    assert dL < 1e-14 and dE < 1e-12


def test_high_spin_with_field_stays_finite_and_brakes():
    """1e5 rad/s in a constant field: the transverse spin decays, L·B stays put, nothing overflows."""
    r = gyro_sim.run(scene(initial={"spin": 1e5, "L_direction": [0.6, 0, 0.8]}, duration=0.05,
                           field=[{"real": [0, 0, 0.01], "imag": [0, 0, 0], "frequency": 0.0}], output={"rate": 200.0}))
    dz = abs(r.L[-1, 2] / r.L[0, 2] - 1)
    print(f"\n1e5 rad/s, {r.steps} steps: L_z drift {dz:.1e}; |L_⊥| {np.hypot(*r.L[0, :2]):.4e} → {np.hypot(*r.L[-1, :2]):.4e}")
    assert finite(r) and dz < 1e-9 and np.hypot(*r.L[-1, :2]) < np.hypot(*r.L[0, :2])


@pytest.mark.parametrize("mu", [1e-6, 1e-4, 1e-2, 1e-1])
def test_mu_range_spinup(mu):
    """Spin-up with μ = k_e B² ν/(J ν²) from 1e-6 to 1e-1: finite, monotone approach to the field rate."""
    k_e = conductor_model("thin_shell", 0.025, 2.5e7, thickness=0.001).k_e
    nu = 500.0
    B = math.sqrt(mu * J[2] * nu / k_e)  # μ = k_e B²/(J3 ν)
    T = min(5.0, 3 * J[2] / (k_e * B**2))
    r = gyro_sim.run(scene(torque_model="quasi_static", duration=T, output={"rate": 200.0},
                           stators=[{"name": "z3", "axis": [0, 0, 1], "coil_constant": B, "current": 1.0, "rate": nu}]))
    print(f"\nμ = {mu:g}: B0 = {B:.3g} T, spin {r.spin_rate[0]:.1f} → {r.spin_rate[-1]:.2f} rad/s in {T:.3g} s")
    assert finite(r) and np.all(np.diff(r.spin_rate) >= -1e-9 * nu) and r.spin_rate[-1] <= nu * (1 + 1e-9)


@pytest.mark.parametrize("x", [1e2, 1e3])
def test_solid_sphere_deep_skin_effect(x):
    """ω μ0 σ a² up to 1e3 with 50 modes: the steady torque matches (2.14) (stiff modes, ETD steps)."""
    a, sigma = 0.025, 2.5e7
    w = x / (4e-7 * math.pi * sigma * a * a)
    m = conductor_model("solid_sphere", a, sigma, n_modes=50)
    tau1 = float(m.tau[0])
    r = gyro_sim.run(scene(rotor={"inertia": [1e3] * 3, "conductor": {"kind": "solid_sphere", "outer_radius": a,
                                                                      "conductivity": sigma}}, modes=50,
                           stators=[{"name": "z3", "axis": [0, 0, 1], "coil_constant": 1e-3, "current": 1.0, "rate": w}],
                           duration=20 * tau1, output={"rate": 1 / tau1}))
    expect = m.moment_scale * 1e-6 * float(np.imag(g_solid_sphere(w, a, sigma)))
    err = abs(r.torque[-1, 2] / expect - 1)
    print(f"\nω μ0 σ a² = {x:g}: torque error vs (2.14) {err:.1e} ({r.steps} steps, τ_50 = {m.tau[-1]:.1e} s)")
    assert finite(r) and err < 1e-4


def test_near_resonant_stators():
    """Two stators 0.1 % apart in rate: the cross terms beat slowly; the run stays finite and the averaged
    torque of the pair wanders around the non-resonant value instead of diverging."""
    r = gyro_sim.run(scene(torque_model="quasi_static", duration=2.0, output={"rate": 500.0},
                           initial={"spin": 100.0},
                           stators=[{"name": "a", "axis": [1, 0, 0], "coil_constant": 0.01, "current": 1.0, "rate": 1000.0},
                                    {"name": "b", "axis": [0, 1, 0], "coil_constant": 0.01, "current": 1.0, "rate": 1001.0}]))
    print(f"\nnear-resonant pair: {r.steps} steps; |L| {np.linalg.norm(r.L[0]):.3e} → {np.linalg.norm(r.L[-1]):.3e}")
    assert finite(r)


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(J1=st.floats(1e-7, 1e-3), r2=st.floats(0.1, 3.0), r3=st.floats(0.1, 3.0),
       spin=st.floats(-1e4, 1e4), theta=st.floats(0, math.pi), sigma=st.floats(-1e8, 1e8),
       B=st.floats(0, 0.05), nu=st.floats(-1e4, 1e4), model=st.sampled_from(["none", "quasi_static", "lag"]))
def test_random_scenes_run_or_are_refused(J1, r2, r3, spin, theta, sigma, B, nu, model):
    """A random scene either is refused at load with a message naming a key, or runs with no NaN,
    conserving |L| and energy where no torque acts."""
    d = {"rotor": {"inertia": [J1, J1 * r2, J1 * r3],
                   "conductor": {"kind": "thin_shell", "outer_radius": 0.02, "thickness": 0.001, "conductivity": sigma}},
         "torque_model": model, "initial": {"spin": spin, "theta": theta, "phi": 0.3}, "duration": 0.02,
         "stators": [{"name": "z3", "axis": [0, 0, 1], "coil_constant": max(B, 1e-9), "current": 1.0, "rate": nu}],
         "output": {"rate": 500.0}}
    try:
        s = scene_from_dict(d)
    except SceneError as e:
        msg = str(e)
        assert "invalid scene" in msg and any(k in msg for k in ("rotor.inertia", "conductivity")), msg
        return
    r = gyro_sim.run(s)
    assert finite(r)
    if model == "none":
        assert np.max(np.abs(r.energy - r.energy[0])) <= 1e-11 * max(r.energy[0], 1e-300)


@pytest.mark.slow
def test_twenty_minute_spinup_full_against_auto():
    """Long version: the 20-minute default spin-up (≈6·10⁵ revolutions), full model vs the hybrid."""
    import time

    s = gyro_sim.load_scene("spinup_thin_shell", overrides={"duration": 1200.0})
    w = time.perf_counter()
    full = gyro_sim.run(s)
    w_full = time.perf_counter() - w
    hy = gyro_sim.run(s.model_copy(update={"fidelity": "auto", "accuracy": Accuracy(rtol=2e-3)}))
    e = max(abs(hy.spin_rate[-1] / full.spin_rate[-1] - 1), abs(hy.theta[-1] / full.theta[-1] - 1))
    print(f"\n20-minute spin-up: full {w_full:.1f} s wall, {full.steps} steps; auto {hy.wall_time:.2f} s; "
          f"largest relative difference (spin, θ) {e:.1e}")
    assert e < 1e-3


#: where `auto` never averaged it ran the full model, but with its steps cut at its decision points (each test of
#: whether to average ends a step there): another step sequence of the same stepper, so the two runs differ by
#: the difference of their truncation errors, which depends on the stepper the scene takes. Measured over 550
#: random examples (444 never averaged; ``pytest --stress`` reports it again,
#: test_random_three_stator_scenes_auto_against_full_spread), largest relative |ΔL| and |Δθ| (rad) by the stepper
#: at t = 0: lawson8 (8th order) 7e-14, 7e-13; frozen_flow 1.5e-10, 4.8e-10; etdrk4 (4th order, stiff eddy
#: modes at spin 50 rad/s in near-static 3 mT fields) 2.5e-7, 1.4e-7, where the full model's own error is ~6e-4
#: (against a run at half its step). The former bounds 1e-9, 1e-7 failed on a random example (2.2e-9). The
#: bounds: 4× the largest measured, far below the full model's own error where that is reached, and 1e4 below
#: the averaged models' bound (1e-2), so a never-averaged run that leaves the full model still fails.
NEVER_AVERAGED_L = 1e-6
NEVER_AVERAGED_THETA = 1e-6

THREE_STATOR_SCENES = dict(
    r3=st.floats(0.6, 1.9), spin=st.floats(50.0, 3000.0), theta=st.floats(0.0, math.pi),
    turn=st.floats(0.0, math.pi), I=st.lists(st.floats(0.0, 0.3), min_size=3, max_size=3),
    nu=st.lists(st.floats(-3000.0, 3000.0), min_size=3, max_size=3),
    model=st.sampled_from(["quasi_static", "lag"]), psi=st.booleans())


def three_stator_auto_against_full(r3, spin, theta, turn, I, nu, model, psi) -> tuple:
    """(seconds averaged, relative |ΔL| and |Δθ| rad at the end, the scene) of `auto` against the full model, for
    a random axisymmetric rotor under three random stators (ψ-switching or not); asserts the bounds."""
    d = {"rotor": {"inertia": [5.592e-6, 5.592e-6, 5.592e-6 * r3],
                   "conductor": {"kind": "thin_shell", "outer_radius": 0.025, "thickness": 0.001, "conductivity": 2.5e7}},
         "torque_model": model, "duration": 2.0, "output": {"rate": 50.0},
         "initial": {"kinetic_moment": 5.592e-6 * r3 * spin, "L_direction": [math.sin(turn), 0.0, math.cos(turn)],
                     "theta": theta, "phi": 0.3},
         "stators": [{"name": n, "axis": a, "coil_constant": 1e-2, "current": c, "rate": v}
                     for n, a, c, v in zip(("z1", "z2", "z3"), ([1, 0, 0], [0, 1, 0], [0, 0, 1]), I, nu)]}
    if psi:
        d["controller"] = {"law": "psi_switching", "period": 2e-4, "params": {
            "control_stators": ["z1", "z2"], "spin_stator": "z3", "nu": [abs(nu[0]) + 3000.0, abs(nu[1]) + 9000.0],
            "control_current": I[0] * 0.2, "spin_current": I[2], "spin_rate": nu[2]}}
    s = scene_from_dict(d)
    full = gyro_sim.run(s)
    hy = gyro_sim.run(s.model_copy(update={"fidelity": "auto", "accuracy": Accuracy(rtol=2e-3)}))
    assert np.all(np.isfinite(hy.L)) and np.all(np.isfinite(hy.q))
    eL = float(np.linalg.norm(hy.L[-1] - full.L[-1]) / np.linalg.norm(full.L[-1]))
    eth = abs(float(hy.theta[-1] - full.theta[-1]))
    avg = sum(b - a for a, b in hy.averaged_segments)
    print(f"\n  {model} κ+1 = {r3:.2f} spin {spin:.0f} θ0 {theta:.2f} ψ-switching {psi}: averaged {avg:.2f} s by "
          f"{sorted(set(hy.averaged_models))}; L {eL:.1e}, θ {eth:.1e}")
    if avg > 0:
        assert eL < 1e-2 and eth < 1e-2
    else:  # never averaged: the full model, up to where its steps were cut (see NEVER_AVERAGED_L)
        assert eL < NEVER_AVERAGED_L and eth < NEVER_AVERAGED_THETA
    return avg, eL, eth, s


# derandomized: the same 20 examples every run (a random example may not decide the suite's fate)
@settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(**THREE_STATOR_SCENES)
def test_random_three_stator_scenes_auto_against_full(r3, spin, theta, turn, I, nu, model, psi):
    """Random axisymmetric rotors under three random stators (ψ-switching or not), ``fidelity: auto``: finite, and
    where `auto` averaged (any of its models) within 1e-2 of the full model in L and θ at the end; where it never
    averaged within NEVER_AVERAGED_L, NEVER_AVERAGED_THETA."""
    three_stator_auto_against_full(r3, spin, theta, turn, I, nu, model, psi)


@pytest.mark.slow
def test_random_three_stator_scenes_auto_against_full_spread():
    """Long version: 300 random examples (not derandomized; ~7 min); reports the spread of the never-averaged
    differences by the full model's stepper at t = 0 against NEVER_AVERAGED_L, NEVER_AVERAGED_THETA."""
    from gyro_sim.engine.simulate import Simulator

    never: dict = {}

    @settings(max_examples=300, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
    @given(**THREE_STATOR_SCENES)
    def check(r3, spin, theta, turn, I, nu, model, psi):
        avg, eL, eth, s = three_stator_auto_against_full(r3, spin, theta, turn, I, nu, model, psi)
        if avg == 0:
            never.setdefault(Simulator(s)._method(), []).append((eL, eth))

    check()
    for method, v in sorted(never.items()):
        eL, eth = np.array(v).T
        print(f"\n  never averaged, {method} at t = 0, {len(v)} examples: relative |ΔL| median {np.median(eL):.1e}, "
              f"largest {eL.max():.1e} (bound {NEVER_AVERAGED_L:.0e}); |Δθ| median {np.median(eth):.1e}, largest "
              f"{eth.max():.1e} rad (bound {NEVER_AVERAGED_THETA:.0e})")
