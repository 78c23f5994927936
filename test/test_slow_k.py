"""[K]'s averaged model as a fidelity level (gyro_sim/averaging/slow_k.py) against the full model.

Three stators at constant rates ([K] (2.1)) and the ψ-switching law ([K] (3.1), (3.3)): ``fidelity: auto``
runs the averaged model where its region holds and the full model elsewhere (near θ = 0 under ψ-switching);
the error against the full model falls as O(ε) (ε = Σ c_k/(J Λ) + Σ|V_n|/Λ², the torque's change of L
per precession radian).
"""
import math

import numpy as np
import pytest

import gyro_sim
from gyro_sim.engine.simulate import Runner
from gyro_sim.scenes.scene import Accuracy
from gyro_sim.averaging.slow_k import slow_k_of, slow_state
from test_k_nutation import crossing, k21_scene, psi_scene


#: the averaged models enter where their ε ≤ accuracy.rtol / fidelity.AVERAGED_ERROR (and ≤ MU_MAX = 1e-3): these
#: tests of [K]'s model state an rtol that lets it in at MU_MAX (at the default rtol 1e-6 only where ε ≤ 2e-6)
LOOSE = Accuracy(rtol=2e-3)


def auto_of(scene):
    return scene.model_copy(update={"fidelity": "auto", "accuracy": LOOSE})


def eps_of(scene) -> float:
    """ε of the region test at the scene's start (after the first controller tick)."""
    r = Runner(scene)
    r.advance()
    if scene.controller is not None:
        from gyro_ctl.laws import make_law

        r.apply_commands(make_law(scene.controller)(r.control_input()))
    model, why = slow_k_of(r)
    assert model is not None, why
    return model.ratios(slow_state(r.sim))["eps"] * 1e-3


def test_three_stators_auto_error_falls_as_eps():
    """(2.1), three stators at 420, −1040, 200 rad/s, oblate rotor (κ = 0.2) from θ0 = 0.6 rad with L 0.5 rad
    off its equilibrium direction, 128 s and 256 s: `auto` is averaged throughout and its largest errors in L
    and θ against the full model halve with ε."""
    errs = []
    print()
    for scale in (1 / 32, 1 / 64):
        s, _, _ = k21_scene(0.2, 0.6, 4.0, turn=0.5, Is=1.6 * math.sqrt(scale), Ic=1.1 * math.sqrt(scale))
        s = s.model_copy(update={"duration": 4.0 / scale})
        full, hy = gyro_sim.run(s), gyro_sim.run(auto_of(s))
        eps = eps_of(s)
        eL = float(np.max(np.linalg.norm(full.L - hy.L, axis=1)) / np.linalg.norm(full.L[0]))
        eth = float(np.max(np.abs(full.theta - hy.theta)))
        errs.append((eps, eL, eth))
        print(f"  ε = {eps:.2e}: averaged {hy.averaged_segments}; max |ΔL|/|L| {eL:.2e}, max |Δθ| {eth:.2e} rad "
              f"(tolerance 3e-4, 6e-4); θ {full.theta[0]:.3f} → {full.theta[-1]:.4f} (full), {hy.theta[-1]:.4f} (auto); "
              f"wall {full.wall_time:.2f} s (full) vs {hy.wall_time:.3f} s (auto)")
        assert hy.averaged_segments == [(0.0, s.duration)]
        assert eL < 3e-4 and eth < 6e-4
        assert abs(full.theta[-1] - full.theta[0]) > 0.2  # θ did move (0.6 → 0.29 rad)
    (e1, L1, t1), (e2, L2, t2) = errs
    print(f"  error ratios for ε ratio {e1 / e2:.2f}: L {L1 / L2:.2f}, θ {t1 / t2:.2f} (O(ε): 2)")
    assert 1.6 < L1 / L2 < 2.5 and 1.6 < t1 / t2 < 2.5


def psi_run(eps_m, duration_to_theta, nper=200, fidelity="auto", theta0=30.0):
    """The ψ-switching scene of test_k_nutation (κ = 0.02, control rates 20 and 50 Λ0, a_n = 0.02 a_m), run
    to the time (3.4) gives for θ0 → ``duration_to_theta`` (deg) plus 10 %."""
    d, m, prec = psi_scene(0.02, math.radians(theta0), eps_m=eps_m, q=0.02, nper=nper)
    tp = m.time_to_theta(math.radians(theta0), math.radians(duration_to_theta))
    s = gyro_sim.scene_from_dict(dict(d, duration=1.1 * tp, output=dict(rate=20.0 / prec), fidelity=fidelity,
                                      accuracy=LOOSE.model_dump()))
    return s, tp


def test_psi_switching_auto_is_averaged_and_its_error_falls_as_eps():
    """ψ-switching from θ0 = 30° to about 15°: `auto` runs the averaged model ((3.3) vector form) throughout; its
    largest θ error against the full model halves with ε (control sampled at 1/200 of a precession period, whose
    delay alone biases the full model's drive by (Λh)²/6 = 1.6e-4)."""
    errs = []
    print()
    for eps_m in (4e-4, 2e-4):
        s, _ = psi_run(eps_m, 15.0)
        full, hy = gyro_sim.run(s.model_copy(update={"fidelity": "full"})), gyro_sim.run(s)
        eth = float(np.max(np.abs(full.theta - hy.theta)))
        eLn = float(np.max(np.abs(np.linalg.norm(full.L, axis=1) / np.linalg.norm(hy.L, axis=1) - 1)))
        eps = eps_of(s)
        errs.append(eth)
        print(f"  ε = {eps:.2e}: averaged {hy.averaged_segments}, θ 30° → {math.degrees(full.theta[-1]):.2f}° (full), "
              f"{math.degrees(hy.theta[-1]):.2f}° (auto); max |Δθ| {eth:.2e} rad (tolerance 1e-3), max |Δ|L||/|L| "
              f"{eLn:.1e} (tolerance 3e-3); the full model's L strays up to "
              f"{np.max(np.hypot(full.L[:, 0], full.L[:, 1]) / np.linalg.norm(full.L, axis=1)):.1e} rad off z3; "
              f"wall {full.wall_time:.2f} s (full) vs {hy.wall_time:.3f} s (auto)")
        assert hy.averaged_segments == [(0.0, s.duration)]
        assert eth < 1e-3 and eLn < 3e-3 and full.theta[-1] < math.radians(16.0)
    print(f"  θ error ratio {errs[0] / errs[1]:.2f} for an ε ratio of 2 (O(ε): 2, O(ε²): 4)")
    assert 1.6 < errs[0] / errs[1] < 3.2


def test_psi_switching_auto_reaches_the_pole_at_the_full_model_time():
    """Near the pole the switching is fast detail: `auto` hands back to the full model where θ changes by 5 % of
    sinθ in a precession period (θ ≈ 2.6° here) and the finite-time arrival at θ = 0.1° happens in the full model;
    it comes within 0.5 % of the full model's time (sampling at 1/50 of a precession period)."""
    s, tp = psi_run(4e-4, 0.1, nper=50)
    full, hy = gyro_sim.run(s.model_copy(update={"fidelity": "full"})), gyro_sim.run(s)
    target = math.radians(0.1)
    tf, ta = crossing(full, target), crossing(hy, target)
    print(f"\n  θ 30° → 0.1°: full {tf:.4f} s, auto {ta:.4f} s (rel. {ta / tf - 1:+.1e}, tolerance 5e-3), (3.4) {tp:.4f} s; "
          f"averaged {[(round(a, 3), round(b, 3)) for a, b in hy.averaged_segments]}; "
          f"wall {full.wall_time:.2f} s vs {hy.wall_time:.2f} s")
    assert math.isfinite(ta) and abs(ta / tf - 1) < 5e-3
    (t0, t1), = hy.averaged_segments
    th1 = float(np.interp(t1, hy.t, hy.theta))
    print(f"  handed back at θ = {math.degrees(th1):.2f}°")
    assert t0 == 0.0 and t1 < ta and math.radians(1.0) < th1 < math.radians(5.0)  # the arrival is not averaged
    assert hy.theta[-1] < target


def test_region_refuses_with_the_failing_test_named():
    """A ψ-switching scene with fast damping (ε ≈ 1.3e-3) is outside [K]'s region: `averaged` says which test
    fails and by how much; `auto` runs it in full."""
    d, m, prec = psi_scene(0.02, math.radians(10))
    s = gyro_sim.scene_from_dict(dict(d, duration=0.05, fidelity="averaged", accuracy=LOOSE.model_dump()))
    with pytest.raises(gyro_sim.SceneError, match=r"\[K\]'s averaged model: eps: 1\.\d+ × its limit"):
        gyro_sim.run(s)
    r = gyro_sim.run(auto_of(s))
    assert r.averaged_segments == [] and np.all(np.isfinite(r.L))


def test_reorient_law_is_not_averaged():
    s = gyro_sim.load_scene("reorient_L", overrides={"fidelity": "averaged", "duration": 0.1, "accuracy.rtol": 2e-3})
    with pytest.raises(gyro_sim.SceneError, match=r"\[K\]'s averaged model: controller law 'reorient'"):
        gyro_sim.run(s)


def _three_stators(**over):
    return gyro_sim.load_scene("three_stators", overrides=over)


def test_a_constant_law_overrides_a_scheduled_command_in_auto_as_in_full():
    """A `manual` law (period 1 s) re-sends z3 at 200 rad/s at its ticks; a scheduled command sets 300 rad/s at
    0.5 s. The full model runs 300 rad/s until the tick at 1 s; `auto` holds no averaged stretch across that
    tick (the law is not settled: its next command differs) and re-applies nothing between ticks."""
    from gyro_sim.scenes.scene import Command

    s = _three_stators(duration=6.0, controller={"law": "manual", "period": 1.0, "params": {"commands": {
        "z1": {"current": 0.19445, "rate": 420.0}, "z2": {"current": 0.19445, "rate": -1040.0},
        "z3": {"current": 0.28284, "rate": 200.0}}}})
    s = s.model_copy(update={"commands": [Command(time=0.5, stator="z3", rate=300.0)]})
    full, hy = gyro_sim.run(s), gyro_sim.run(auto_of(s))
    assert np.array_equal(full.field_rate, hy.field_rate)  # 300 rad/s on (0.5, 1], 200 after, in both
    assert not any(0.5 < c[0] < 1.0 for c in hy.commands)  # nothing re-applied between the ticks
    eL = float(np.max(np.linalg.norm(full.L - hy.L, axis=1)) / np.linalg.norm(full.L[0]))
    print(f"\n  averaged {[(round(a, 3), round(b, 3)) for a, b in hy.averaged_segments]}; max |ΔL|/|L| {eL:.1e} "
          "(tolerance 3e-4)")
    assert not any(a < 1.0 < b for a, b in hy.averaged_segments) and eL < 3e-4


def test_auto_tests_its_region_at_once_after_a_command():
    """A small rate change at 20 s of the 40 s `three_stators`: `auto` stops at the command and averages on from
    there (no full-model pause of a tenth of the slow time)."""
    s = _three_stators(duration=40.0, commands=[{"time": 20.0, "stator": "z3", "rate": 201.0}])
    hy = gyro_sim.run(auto_of(s))
    assert hy.averaged_segments == [(0.0, 20.0), (20.0, 40.0)]


def test_event_sampling_is_kept_in_the_full_stretches_of_auto():
    """`sampling: events` under `auto`: the full-model stretch near the pole switches at the law's exact
    instants (commands off the tick grid), as in `full`."""
    s = gyro_sim.load_scene("nutation_slow", overrides={"controller.sampling": "events", "duration": 7.5})
    hy = gyro_sim.run(auto_of(s))
    h = s.controller.period
    off_grid = [t for t, *_ in hy.commands if abs(t / h - round(t / h)) > 1e-6]
    print(f"\n  averaged {hy.averaged_segments}; {len(off_grid)} commands between ticks; θ end "
          f"{math.degrees(hy.theta[-1]):.3f}°")
    assert hy.averaged_segments and len(off_grid) > 10 and hy.theta[-1] < math.radians(0.1)
