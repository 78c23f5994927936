"""Fidelity levels: the averaged spin-up model and the hybrid ``auto`` against the full model."""
import math
import time

import numpy as np
import pytest

import gyro_sim
from gyro_sim.fidelity import spinup_model


def spinup(**over):
    return gyro_sim.load_scene("spinup_thin_shell", overrides=over)


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
