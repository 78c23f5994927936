"""The quasi-static flow step (gyro_sim/compiled/qs_flow.py, issue 23): its closed forms, its order, its agreement with
the turn-resolving steppers, the ``auto`` choice and the honesty of the run's error estimate with it.

No timing is asserted (the machine is shared): speed is the benchmark's (docs/benchmark.md)."""
import math
import warnings

import numpy as np
import pytest

from gyro_sim.compiled import frozen_flow

from gyro_sim.compiled import qs_flow
from gyro_sim.scenes.accuracy import legacy
from gyro_sim.physics.frames import quat_to_matrix
from gyro_sim.scenes.scene import load_scene
from gyro_sim.engine.simulate import Simulator, run
from gyro_sim.engine.terms import Terms

#: the default scene's quasi-static variant, as the benchmark runs it (no controller)
QS = {"torque_model": "quasi_static", "controller": None}


def _angle(q1, q2):
    """Rotation angle (rad) between unit quaternions, row by row (sign-blind; accurate for small angles)."""
    q1, q2 = np.atleast_2d(q1), np.atleast_2d(q2)
    d = np.minimum(np.linalg.norm(q1 - q2, axis=1), np.linalg.norm(q1 + q2, axis=1))
    return 4.0 * np.arcsin(np.minimum(1.0, 0.5 * d))


def _run(name, overrides, T, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (explicit knobs warn where the error model says they miss the tolerance)
        return run(load_scene(name, overrides=overrides), duration=T, **kw)


def _final_errors(name, overrides, T, steps, ref_spt=96):
    """Errors (|ΔL|/|L|, attitude rad) of the final state of qs_flow runs with the given largest steps (s) against
    lawson8 at ``ref_spt`` steps per turn; one output sample, at the end."""
    base = {**overrides, "fidelity": "full", "output.rate": 1.0 / T}
    ref = _run(name, {**base, "integrator.method": "lawson8", "integrator.steps_per_turn": ref_spt}, T, estimate=False)
    out = []
    for h in steps:
        r = _run(name, {**base, "integrator.method": "qs_flow", "integrator.rate_change": 0.1,
                        "integrator.max_step": h}, T, estimate=False)
        out.append((float(np.linalg.norm(r.L[-1] - ref.L[-1]) / np.linalg.norm(ref.L[-1])),
                    float(_angle(r.q[-1], ref.q[-1])[0])))
    return out


@pytest.mark.parametrize("P", [1, 2, 3])
def test_pass_is_the_frozen_flow_pass_of_the_quasi_static_torque(P):
    """The step's closed forms over pairs of field phasors (qs_flow._qs_pass) give what the frozen-flow pass gives
    with the conductor's quasi-static response (no modes, T_tail = τ_eff): ∫N, ∫(h − σ)N, ∫N e^{−iΩ_p σ} and the
    mean axial moment, to round-off, for 1 to 3 phasors (one pair of equal rates: a ripple of frequency 0)."""
    rng = np.random.default_rng(10 + P)
    Bre, Bim = rng.normal(size=(P, 3)) * 1e-3, rng.normal(size=(P, 3)) * 1e-3
    om = rng.normal(size=P) * 300.0
    if P > 1:
        om[1] = om[0]
    Jt, Ja, ax = 5.6e-6, 6.2e-6, 2
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    L0 = rng.normal(size=3) * 5e-4
    y = np.concatenate([L0, q])
    c_m, tail, h = 2.0 * math.pi * 0.025 ** 3 / (4e-7 * math.pi), 2.6e-4, 0.013
    R = quat_to_matrix(q)
    Lbar = 1.01 * L0 + 1e-6
    La = 0.9 * float(Lbar @ R[:, ax])
    out_ff, K_ff = np.zeros(16), np.zeros((2, 3), complex)
    k = 9 * P
    frozen_flow._flow_pass(*Lbar, La, y, R, 0.0, h, Bre, Bim, om, Jt, Ja, ax, np.zeros(0), np.zeros(0), c_m, tail,
                           0, (Bre - 1j * Bim).astype(complex), np.empty((k, 3), complex), np.empty(k, complex),
                           np.empty(k, complex), np.exp(1j * om * h), np.zeros((1, 3), complex),
                           np.zeros((1, 3), complex), out_ff, K_ff)
    nt = P * P
    M0, g0 = np.empty(6), np.empty(3)
    MT, GT, FT = np.empty((nt, 6), complex), np.empty((nt, 3), complex), np.empty(nt)
    assert qs_flow.field_pairs(Bre, Bim, om, M0, g0, MT, GT, FT) == nt
    out, K = np.zeros(16), np.zeros((2, 3), complex)
    xa = R[:, ax]
    qs_flow._qs_pass(*Lbar, La, float(L0 @ xa), *xa, h, Jt, 1.0 / Ja - 1.0 / Jt, c_m * tail, M0, g0, MT, GT, FT,
                     np.exp(1j * FT * h), nt, True, True, out, K, np.zeros((nt, 5, 3), complex))
    for a, b in ((out[0:3], out_ff[0:3]), (out[3:6], out_ff[3:6]), (K, K_ff), (out[15], out_ff[15])):
        assert np.max(np.abs(a - b)) <= 1e-13 * np.max(np.abs(b))


def test_third_order_on_a_spin_up_second_on_a_turning_L():
    """Error ratios on halving the step. A spin-up (the quasi-static variant, 10x the field, 0.2 s from rest): the
    attitude's error falls 8x a halving (third order: the mean of L over the step is right to O(h³)); measured 7.97,
    7.84. three_stators (three fields, L turning back to its equilibrium, 1 s): about 4x (second order: the field's
    ripple acting on the turning L); measured 3.77 (L), 3.35 (attitude)."""
    e = _final_errors("spinup_thin_shell", {**QS, "stators.2.coil_constant": 2e-2}, 0.2, [0.01, 0.005, 0.0025])
    print(f"\n  spin-up: attitude errors {[f'{x[1]:.3g}' for x in e]}")
    assert e[0][1] / e[1][1] > 6.5 and e[1][1] / e[2][1] > 6.5
    e = _final_errors("three_stators", {"controller": None}, 1.0, [5e-4, 2.5e-4], ref_spt=192)
    print(f"  three_stators: L errors {[f'{x[0]:.3g}' for x in e]}, attitude {[f'{x[1]:.3g}' for x in e]}")
    assert e[0][0] / e[1][0] > 3.0 and e[0][1] / e[1][1] > 3.0


def test_drift_ripple_term_where_the_step_is_a_multiple_of_the_ripple_period():
    """A pass with L frozen misses k_e ∫(σ − h/2) M(σ) K(σ) D dσ (L drifting at D while the field's ripple and the
    axis's precession modulate the torque's slope); with steps a multiple of the ripple's period that adds up each
    step. Spin-up from rest at θ = 0.5, 500 Hz field, 1 ms steps (one ripple period): 9e-9 of |L| after 0.2 s
    without the term (the frozen-flow step has it), 3e-11 with it."""
    ov = {**QS, "initial.theta": 0.5}
    (eL, _), = _final_errors("spinup_thin_shell", ov, 0.2, [0.001])
    ff = _run("spinup_thin_shell", {**ov, "output.rate": 5.0, "integrator.method": "frozen_flow",
                                    "integrator.rate_change": 0.1, "integrator.max_step": 0.001}, 0.2, estimate=False)
    ref = _run("spinup_thin_shell", {**ov, "output.rate": 5.0, "integrator.method": "lawson8",
                                     "integrator.steps_per_turn": 96}, 0.2, estimate=False)
    e_ff = float(np.linalg.norm(ff.L[-1] - ref.L[-1]) / np.linalg.norm(ref.L[-1]))
    print(f"\n  |ΔL|/|L|: qs_flow {eL:.2g}, frozen_flow {e_ff:.2g}")
    assert eL < 1e-10 < e_ff


@pytest.mark.parametrize("T, tol", [(2.0, 1e-6), (2.0, 1e-4), (0.2, 1e-6)])
def test_default_run_within_tolerance_and_estimate_at_least_the_error(T, tol):
    """The quasi-static variant as a user runs it (auto: qs_flow, the error control's shadow run): its samples agree
    with lawson8 (96 steps per turn) within the accuracy asked, and the estimate it reports is at least the error
    measured, of L and of the attitude (order-1 Richardson: measured 2.0e-10 ≥ 1.7e-10 and 1.3e-9 ≥ 9.3e-10 rad over
    0.2 s)."""
    ov = {**QS, "accuracy.rtol": tol, "accuracy.attitude": tol}
    assert Simulator(load_scene("spinup_thin_shell", overrides=ov), horizon=T)._method() == "qs_flow"
    r = _run("spinup_thin_shell", ov, T)
    ref = _run("spinup_thin_shell", {**ov, "integrator.method": "lawson8", "integrator.steps_per_turn": 96}, T,
               estimate=False)
    eL = float(np.max(np.linalg.norm(r.L - ref.L, axis=1)) / np.max(np.linalg.norm(ref.L, axis=1)))
    eq = float(np.max(_angle(r.q, ref.q)))
    est = r.error_estimate
    print(f"\n  T = {T} s, tolerance {tol:g}: {r.steps} steps; measured L {eL:.2g}, attitude {eq:.2g} rad; "
          f"estimated {est.L:.2g}, {est.attitude:.2g} rad ({est.steps_method})")
    assert eL <= tol and eq <= tol and est.met
    assert est.L >= eL and est.attitude >= eq


def test_isotropic_rotor_without_attitude():
    """An isotropic rotor without attitude (L alone, Ω = L/J) takes the step's case-frame form: it agrees with
    lawson8 within the tolerance."""
    J = 5.592e-6
    ov = {**QS, "rotor.inertia": [J, J, J], "output.attitude": False}
    r = _run("spinup_thin_shell", {**ov, "integrator.method": "qs_flow"}, 1.0, estimate=False)
    ref = _run("spinup_thin_shell", {**ov, "integrator.method": "lawson8", "integrator.steps_per_turn": 48}, 1.0,
               estimate=False)
    assert not r.attitude
    err = float(np.max(np.linalg.norm(r.L - ref.L, axis=1)) / np.max(np.linalg.norm(ref.L, axis=1)))
    print(f"\n  |ΔL|/max|L| = {err:.2g}")
    assert err < 1e-8


def test_auto_takes_it_on_the_quasi_static_model_where_the_flow_step_pays():
    """``auto``: qs_flow on the quasi-static variant (where frozen_flow would be taken: the same step, a third of the
    cost), frozen_flow on the lag model, lawson8 where no flow step pays (three_stators: strong fields on a slow
    rotor), and the old defaults' runs (``legacy``) keep frozen_flow."""
    def method(name, ov):
        return Simulator(load_scene(name, overrides=ov))._method()

    assert method("spinup_thin_shell", QS) == "qs_flow"
    assert method("spinup_thin_shell", {"controller": None}) == "frozen_flow"
    assert method("three_stators", {"fidelity": "full"}) == "lawson8"
    with legacy():
        assert method("spinup_thin_shell", QS) == "frozen_flow"


def test_a_lag_scene_cannot_force_it():
    """``integrator.method: qs_flow`` integrates [K] (1.2): a scene with the lag model is refused, with the reason."""
    with pytest.raises(Exception, match="quasi-static torque"):
        load_scene("spinup_thin_shell", overrides={"integrator.method": "qs_flow"})


def test_the_field_and_torque_scale_are_computed_once_per_command_segment(monkeypatch):
    """A run asks for the field's phasors at its start, its first sample and its step plan, and the step plan asks
    for the torque's scale at several knobs: they are computed once while the commands are the same (before, the
    phasors were computed 7 times in a 0.2 s run of the quasi-static variant)."""
    calls = []
    real = Terms._phasors
    monkeypatch.setattr(Terms, "_phasors", lambda self, *a: calls.append(1) or real(self, *a))
    r = _run("spinup_thin_shell", QS, 0.2, estimate=False)
    assert r.steps > 0 and len(calls) == 1


def test_same_bits_whether_samples_are_breaks_or_not():
    """The ROS node makes every output sample a break, an in-process run records them inside one advance: with qs_flow
    (and its error control, and the spin-up law's ticks) both take the same steps and give the same bits (the step
    keeps e^{i f h} only within one call, and recomputes it alike)."""
    sc = load_scene("spinup_thin_shell", overrides={"torque_model": "quasi_static"})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = run(sc, duration=1.0)
        b = run(sc, duration=1.0, on_samples=lambda rows: None)
    assert a.steps == b.steps and np.array_equal(a.L, b.L) and np.array_equal(a.q, b.q)
    assert a.error_estimate.L == b.error_estimate.L
