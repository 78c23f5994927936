"""Fidelity levels: the averaged spin-up model and the hybrid ``auto`` against the full model."""
import math
import time

import numpy as np
import pytest

import gyro_sim
from gyro_sim.engine.fidelity import spinup_model


#: the averaged models enter where their ε ≤ accuracy.rtol / fidelity.AVERAGED_ERROR (and ≤ MU_MAX = 1e-3): these
#: tests of the models state an rtol that lets them in at MU_MAX (at the default rtol 1e-6 a run averages only
#: where ε ≤ 2e-6)
LOOSE = {"accuracy.rtol": 2e-3}


def spinup(**over):
    return gyro_sim.load_scene("spinup_thin_shell", overrides={**LOOSE, **over})


def rel(a, b):
    return abs(a / b - 1)


def test_auto_matches_full_default_scene():
    """Default scene, 60 s: spin rate and θ of `auto` within 1e-3 of the full model, for a fraction of the cost."""
    w = time.perf_counter()
    full = gyro_sim.run(spinup())
    w_full = time.perf_counter() - w
    w = time.perf_counter()
    hy = gyro_sim.run(spinup(fidelity="auto"))
    w_hy = time.perf_counter() - w
    e_spin, e_th = rel(hy.spin_rate[-1], full.spin_rate[-1]), rel(hy.theta[-1], full.theta[-1])
    print(f"\nauto: averaged over {hy.averaged_segments}; spin error {e_spin:.1e}, θ error {e_th:.1e}; "
          f"wall {w_hy:.3f} s vs full {w_full:.3f} s ({w_full / w_hy:.1f}x)")
    assert hy.averaged_segments and e_spin < 1e-3 and e_th < 1e-3


def test_averaged_error_falls_with_mu():
    """Averaged from t = 0 at 1500 rad/s, the error against the full model falls with μ (μ ∝ B0²) towards a
    floor (~1e-5 in spin) set by the switch-on transient of the eddy currents at t = 0, which the full
    model has (fields switched on at t = 0) and the averaged model does not (its order: c B0² τ/|L|)."""
    errs, mus = [], []
    for b in (8e-3, 4e-3, 2e-3):
        over = {"stators.2.coil_constant": b, "duration": 40.0 * (2e-3 / b) ** 2, "initial.spin": 1500.0,
                "controller": None}
        full = gyro_sim.run(spinup(**over))
        hy = gyro_sim.run(spinup(**over, fidelity="averaged"))
        mus.append(spinup_model(spinup(**over), 2).mu(float(np.linalg.norm(full.L[0]))))
        e = (rel(hy.spin_rate[-1], full.spin_rate[-1]), rel(hy.theta[-1], full.theta[-1]))
        errs.append(e)
        print(f"  B0 = {b * 1e3:g} mT: μ = {mus[-1]:.1e}, errors of the averaged model: spin {e[0]:.2e}, θ {e[1]:.2e}")
    assert max(max(e) for e in errs) < 1e-3
    assert errs[0][0] > errs[1][0] > errs[2][0] and errs[0][1] > errs[1][1] > errs[2][1]


def test_the_error_control_checks_after_an_averaged_stretch(monkeypatch):
    """constant_field under ``auto``: [M]'s averaged model to 6.87 s, then the full model to 60 s. The check instants
    inside the averaged stretch were never reached, and the error control waited for the first of them (0.0146 s)
    to the end: none of the full stretch's 14 checks was made, its step never controlled (10 627 steps) and its
    error measured at the end alone. Now the checks passed in the stretch are passed over, and the full stretch is
    checked (3 203 steps, the same errors against the full model: test_auto_runs_m_averaged_model_and_hands_back)."""
    from gyro_sim.scenes.step_control import ErrorControl

    made = []
    check = ErrorControl.check

    def spy(self, t, *args, **kw):
        made.append(t)
        return check(self, t, *args, **kw)

    monkeypatch.setattr(ErrorControl, "check", spy)
    hy = gyro_sim.run(gyro_sim.load_scene("constant_field", overrides={**LOOSE, "fidelity": "auto"}))
    (t0, t1), = hy.averaged_segments
    after = [t for t in made if t > t1]
    print(f"\n  averaged {t0:g}–{t1:.3f} s; {len(after)} checks after it, {hy.steps} steps; {hy.error_estimate.text()}")
    assert t1 < 10.0 and len(after) >= 13  # (the instants k T/16 past 6.87 s: 7.5 … 56.25 s)
    assert hy.error_estimate.met


def test_auto_does_not_count_the_averaged_stretch_as_the_steps_error():
    """The default scene under ``auto`` (rtol 2e-3): full model to 6.4 s, averaged to 60 s. At the hand-back the
    error control compared the run at 60 s with its shadow, left at 6.4 s: the spin-up in between counted as the
    steps' error, and the run reported L 0.88, "beyond the scene's accuracy" (its spin rate is within 8e-6 of the
    full model's: test_auto_matches_full_default_scene). Now the two are compared where the stretch starts, and the
    shadow takes up again from its end."""
    hy = gyro_sim.run(spinup(fidelity="auto"))
    est = hy.error_estimate
    print(f"\n  averaged {hy.averaged_segments}; {est.text()}; steps' part {est.steps_L:.2g}, averaged "
          f"{est.averaged_L:.2g}")
    assert hy.averaged_segments and est.met
    assert est.steps_L < 1e-8 and est.L == pytest.approx(est.steps_L + est.modes_L + est.averaged_L)


def test_averaged_refuses_a_scene_outside_its_region():
    with pytest.raises(gyro_sim.SceneError, match=r"fidelity = 'averaged'.*μ = .* > 0.001"):
        gyro_sim.run(spinup(fidelity="averaged", **{"initial.spin": 20.0}))
    with pytest.raises(gyro_sim.SceneError, match=r"fidelity = 'averaged'.*2 stators on"):
        gyro_sim.run(spinup(fidelity="averaged", **{"initial.spin": 2000.0, "stators.0.current": 1.0,
                                                    "stators.0.rate": 1000.0}))


def test_auto_hands_back_to_full_at_a_command():
    """A current step at 30 s: `auto` runs the full model there and returns to the averaged one."""
    over = {"commands": [{"time": 30.0, "stator": "z3", "current": 0.5}], "duration": 60.0}
    full = gyro_sim.run(spinup(**over))
    hy = gyro_sim.run(spinup(**over, fidelity="auto"))
    segs = hy.averaged_segments
    print(f"\naveraged stretches {[(round(a, 3), round(b, 3)) for a, b in segs]}; spin error "
          f"{rel(hy.spin_rate[-1], full.spin_rate[-1]):.1e}, θ error {rel(hy.theta[-1], full.theta[-1]):.1e}")
    assert len(segs) == 2 and segs[0][1] == pytest.approx(30.0) and segs[1][0] >= 30.0
    assert rel(hy.spin_rate[-1], full.spin_rate[-1]) < 1e-3 and rel(hy.theta[-1], full.theta[-1]) < 1e-3


def test_averaged_twenty_minute_spinup_costs_milliseconds():
    """The averaged model integrates 1200 s of spin-up (6·10⁵ revolutions) in milliseconds."""
    m = spinup_model(spinup(), 2)
    t = np.linspace(10.0, 1200.0, 200)
    m.solve(1e-3, 0.05, 10.0, t)
    w = time.perf_counter()
    L, th, nfev = m.solve(1e-3, 0.05, 10.0, t)
    w = time.perf_counter() - w
    revs = np.trapezoid(L / m.J3, t) / (2 * math.pi)
    print(f"\naveraged 1190 s, {revs:.2e} revolutions: {w * 1e3:.2f} ms, {nfev} RHS evaluations")
    assert nfev < 2000 and L[-1] / m.J3 > 0.9 * m.nu


def _slow_errors(full, hy):
    from gyro_sim.averaging.averaged_m import slow_variables

    sf, sh = slow_variables(full), slow_variables(hy)
    L0 = max(sf["L"][0], sf["L"][-1])
    return {"L": float(np.max(np.abs(sf["L"] - sh["L"])) / L0), "rho": float(np.max(np.abs(sf["rho"] - sh["rho"]))),
            "theta": float(np.max(np.abs(sf["theta"] - sh["theta"]))),
            "L_end": float(abs(sh["L"][-1] / sf["L"][-1] - 1)), "theta_end": float(abs(sh["theta"][-1] - sf["theta"][-1]))}


def test_auto_runs_m_averaged_model_and_hands_back():
    """[M]'s averaged model inside `auto`: the constant field from the start until the braked spin leaves its
    region (μ_eff > 1e-3), then the full model; the rotating field once spun up, to the end. Slow variables
    against the full model over the whole run (the O(μ) ripple of the full model counts as error)."""
    for name, tol in (("constant_field", {"L": 1e-4, "rho": 1e-4, "theta": 2e-3, "L_end": 1e-8}),
                      ("rotating_field", {"L": 1e-5, "rho": 1e-6, "theta": 1e-6, "L_end": 1e-5})):
        full = gyro_sim.run(gyro_sim.load_scene(name))
        hy = gyro_sim.run(gyro_sim.load_scene(name, overrides={**LOOSE, "fidelity": "auto"}))
        err = _slow_errors(full, hy)
        segs = hy.averaged_segments
        print(f"\n  {name}: averaged {[(round(a, 3), round(b, 3)) for a, b in segs]}; max errors "
              + ", ".join(f"{k} {v:.1e} (tol {tol[k]:.0e})" for k, v in err.items() if k in tol))
        assert len(segs) == 1 and segs[0][1] - segs[0][0] > 5.0
        for k, t in tol.items():
            assert err[k] < t, (name, k, err[k])
    # the rotating field's stretch runs to the end; the constant field's ends before the run (hand-back)
    assert segs[0][1] == pytest.approx(30.0)
    hy = gyro_sim.run(gyro_sim.load_scene("constant_field", overrides={**LOOSE, "fidelity": "auto"}))
    assert hy.averaged_segments[0][1] < 60.0 and np.isfinite(hy.euler[-1, 0])


def test_averaged_fidelity_takes_m_model_or_names_both_reasons():
    r = gyro_sim.run(gyro_sim.load_scene("rotating_field", overrides={**LOOSE, "fidelity": "averaged", "initial.spin": 3000.0}))
    assert r.averaged_segments and r.averaged_segments[0][0] <= 0.02
    with pytest.raises(gyro_sim.SceneError, match=r"fidelity = 'averaged'.*general field.*\[M\]'s averaged model: "
                                                  r"μ_eff = .* near resonance"):
        gyro_sim.run(gyro_sim.load_scene("pulsating_field", overrides={**LOOSE, "fidelity": "averaged"}))


def test_m_stretch_exit_between_samples_and_exact_torque():
    """The [M] stretch ends where its solution leaves the region, not at the next output sample (the same
    instant at 20 and at 0.2 samples per second), and its torque output is the averaged model's dL/dt."""
    from gyro_sim.averaging.averaged_m import averaged_m_model

    dense = gyro_sim.run(gyro_sim.load_scene("constant_field", overrides={**LOOSE, "fidelity": "auto"}))
    sparse = gyro_sim.run(gyro_sim.load_scene("constant_field", overrides={**LOOSE, "fidelity": "auto", "output.rate": 0.2}))
    t_dense, t_sparse = dense.averaged_segments[0][1], sparse.averaged_segments[0][1]
    model = averaged_m_model(dense.scene)
    worst = 0.0
    for i in np.nonzero((dense.t > 0) & (dense.t < t_dense))[0][::10]:
        L = dense.L[i]
        Ln, rho, sig = np.linalg.norm(L), math.atan2(math.hypot(L[0], L[1]), L[2]), math.atan2(L[1], L[0])
        dL, drho, dsig, _ = model.rates(Ln, rho, sig, dense.theta[i])
        sr, cr, ss, cs = math.sin(rho), math.cos(rho), math.sin(sig), math.cos(sig)
        N = (dL * np.array([sr * cs, sr * ss, cr]) + Ln * drho * np.array([cr * cs, cr * ss, -sr])
             + Ln * dsig * np.array([-sr * ss, sr * cs, 0.0]))
        worst = max(worst, float(np.linalg.norm(dense.torque[i] - N) / np.linalg.norm(N)))
    print(f"\n  hand-back at {t_dense:.6f} s (20 Hz output) and {t_sparse:.6f} s (0.2 Hz); torque vs the model's "
          f"rates: {worst:.1e} (tol 1e-6)")
    assert t_dense < 10.0 and t_sparse == pytest.approx(t_dense, rel=1e-9, abs=1e-9)
    assert worst < 1e-6


def test_output_window_runs_the_full_model_inside_auto():
    """A 5 kHz output window at 30–30.2 s of the default scene: `auto` leaves the averaged model at its start,
    runs the full model through it (every sample of the window within the full model's ripple of the full run)
    and goes back to the averaged model after it."""
    win = {"rate": 50.0, "windows": [{"start": 30.0, "end": 30.2, "rate": 5000.0}]}
    full = gyro_sim.run(spinup(output=win))
    hy = gyro_sim.run(spinup(output=win, fidelity="auto"))
    assert np.array_equal(full.t, hy.t)
    m = (hy.t >= 30.0) & (hy.t <= 30.2)
    eL = float(np.max(np.linalg.norm(full.L[m] - hy.L[m], axis=1)) / np.linalg.norm(full.L[m][0]))
    eth = float(np.max(np.abs(full.theta[m] - hy.theta[m])))
    segs = hy.averaged_segments
    print(f"\nwindow: {m.sum()} samples; averaged {[(round(a, 3), round(b, 3)) for a, b in segs]}; "
          f"in the window max |ΔL|/|L| {eL:.1e}, max |Δθ| {eth:.1e} rad (tolerance 1e-4, 1e-5)")
    assert m.sum() == 1001 and np.allclose(np.diff(hy.t[m]), 2e-4)
    assert any(b == pytest.approx(30.0) for _, b in segs) and any(a == pytest.approx(30.2) for a, _ in segs)
    assert not any(a < 30.2 - 1e-9 and b > 30.0 + 1e-9 for a, b in segs)  # no averaging inside
    # ψ, φ are known from the window's second sample on (its first, t = 30 s, ends the averaged stretch)
    assert np.all(np.isfinite(hy.euler[m & (hy.t > 30.0)])) and eL < 1e-4 and eth < 1e-5
