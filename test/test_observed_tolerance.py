"""Tolerances in terms of what is observed (issue 28): L, the directions of the rotor's axes, and the spin phase
relative to itself, measured apart (frames.attitude_split) and estimated apart by the run's error control.

Before the split the attitude tolerance (1e-6 rad absolute) included the spin phase: the default scene held its
phase to 1e-11 of itself and took 162,421 steps for 60 s."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from gyro_sim.engine.simulate import run
from gyro_sim.physics.frames import attitude_from_euler, attitude_split, symmetry_axis
from gyro_sim.scenes.scene import SceneError, load_scene
from test_frozen_flow import report


def _q(R: np.ndarray) -> np.ndarray:
    from gyro_sim.physics.frames import matrix_to_quat

    return matrix_to_quat(R)


def test_attitude_split_separates_the_axis_from_the_spin_phase():
    from gyro_sim.physics.frames import rot_x, rot_z

    q0 = attitude_from_euler(np.array([0.3, -0.2, 0.9]), 0.4, 0.7, 1.1)
    R0 = np.array(__import__("gyro_sim.physics.frames", fromlist=["quat_to_matrix"]).quat_to_matrix(q0))
    twist = _q(R0 @ rot_z(2e-3))  # about the body's x3: the spin phase alone
    swing = _q(R0 @ rot_x(3e-6))  # tilts x3: the direction alone
    d, p = attitude_split(q0, twist, 2)
    assert d < 1e-12 and abs(p - 2e-3) < 1e-12
    d, p = attitude_split(q0, swing, 2)
    assert abs(d - 3e-6) < 1e-12 and p < 1e-12
    d, p = attitude_split(q0, _q(R0 @ rot_x(3e-6) @ rot_z(2e-3)), 2)
    assert abs(d - 3e-6) < 1e-11 and abs(p - 2e-3) < 1e-11
    # the sign of a quaternion does not matter; a body without symmetry axis: the whole angle, no phase
    d, p = attitude_split(q0, -twist, 2)
    assert d < 1e-12 and abs(p - 2e-3) < 1e-12
    d, p = attitude_split(q0, twist, -1)
    assert abs(d - 2e-3) < 1e-12 and p == 0.0
    assert symmetry_axis([1.0, 1.0, 2.0]) == 2 and symmetry_axis([2.0, 1.0, 1.0]) == 0
    assert symmetry_axis([1.0, 2.0, 1.0]) == 1 and symmetry_axis([1.0, 2.0, 3.0]) == -1


def test_the_accuracy_section_takes_phase_and_phase_atol():
    s = load_scene("spinup_thin_shell")
    assert s.accuracy.phase == 1e-7 and s.accuracy.phase_atol is None
    s = load_scene("spinup_thin_shell", overrides={"accuracy": {"phase": 1e-9, "phase_atol": 1e-3}})
    assert s.accuracy.phase == 1e-9 and s.accuracy.phase_atol == 1e-3
    with pytest.raises(SceneError, match="phase"):
        load_scene("spinup_thin_shell", overrides={"accuracy": {"phase": -1.0}})


def _errors(r, ref):
    Lm = float(np.max(np.linalg.norm(ref.L, axis=1)))
    eL = float(np.max(np.linalg.norm(r.L - ref.L, axis=1))) / Lm
    d, p = attitude_split(r.q, ref.q, symmetry_axis(r.scene.rotor.inertia), r.L, ref.L)
    return eL, float(np.max(d)), float(np.max(p))


def _shipped_and_reference(T: float):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = run(load_scene("spinup_thin_shell", overrides={"duration": T}))
        ref = run(load_scene("spinup_thin_shell", overrides={
            "duration": T, "integrator": {"method": "frozen_flow", "rate_change": 2e-6}}))
    return r, ref


@pytest.mark.parametrize("T", [2.0, 60.0])
def test_default_scene_meets_its_tolerances_and_estimates_each_honestly(T):
    """The default scene as shipped against a converged frozen-flow reference (rate_change 2e-6, 500x below the
    run's): L, the symmetry axis' direction and the spin phase each within the scene's tolerance, and the run's
    estimate of each at least the error measured and at most ten times it. Measured (2 s / 60 s): estimate over
    true 3.5 / 5.3 (L), 3.9 / 1.3 (directions), 2.2 / 5.2 (phase)."""
    r, ref = _shipped_and_reference(T)
    est = r.error_estimate
    eL, ed, ep = _errors(r, ref)
    report(f"{T:g} s: L (relative)", eL, est.rtol)
    report(f"{T:g} s: directions (rad)", ed, est.atol)
    report(f"{T:g} s: spin phase (rad)", ep, est.phase_tol)
    print(f"  steps {r.steps}; estimate {est.text()}")
    assert est.met
    for true, e in ((eL, est.L), (ed, est.attitude), (ep, est.phase)):
        assert true <= e <= 10.0 * true, (true, e)
    if T == 60.0:
        # the spin phase held relative to itself (1e-7 of ~5e4 rad turned), the shadow free to step over the ticks
        # whose commands change nothing: issue 28's bound of 6,000 steps (3,203 measured; the absolute 1e-6 rad
        # took 162,421, the shadow stopped at every tick 6,006)
        assert r.steps <= 6000
        assert est.phase_tol > 1e-3


def test_an_absolute_phase_is_held_on_request():
    """``phase_atol`` asks for the spin phase in rad: the estimate reports against it, and the run meets it."""
    ov = {"duration": 2.0, "accuracy": {"phase_atol": 2e-8}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = run(load_scene("spinup_thin_shell", overrides=ov))
        ref = run(load_scene("spinup_thin_shell", overrides={
            **ov, "integrator": {"method": "frozen_flow", "rate_change": 2e-6}}))
    est = r.error_estimate
    _, _, ep = _errors(r, ref)
    report("2 s, phase_atol 2e-8: spin phase (rad)", ep, 2e-8)
    assert est.phase_tol == 2e-8 and est.met and ep <= 2e-8 <= est.phase_tol
    assert math.isfinite(est.phase) and est.phase >= ep


def test_the_error_controls_scalar_split_is_the_vector_one():
    """frames.attitude_split_one (the error control's, at each check) gives attitude_split's numbers: 3,000 random
    pairs of states from equal to far apart, every axis; agreement to round-off (measured: 8.9e-16 rad)."""
    from gyro_sim.physics.frames import attitude_split_one

    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(3000):
        q1 = rng.normal(size=4)
        q1 /= np.linalg.norm(q1)
        q2 = q1 + rng.normal(size=4) * 10 ** rng.uniform(-9, 0)
        q2 /= np.linalg.norm(q2)
        L1 = rng.normal(size=3)
        L2 = L1 + rng.normal(size=3) * 10 ** rng.uniform(-9, 0)
        ax = int(rng.integers(-1, 3))
        for a, b in zip(attitude_split(q1, q2, ax, L1, L2), attitude_split_one(q1, q2, ax, L1, L2), strict=True):
            worst = max(worst, abs(float(a) - b))
    report("scalar split against the vector one (rad)", worst, 1e-14)
    assert worst <= 1e-14
