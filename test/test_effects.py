"""The effects plumbing (gyro_sim.compiled.effects): validation, off = no cost, the gyrostat kinematics, and bags.

The physics of each effect against its paper is tested in test_magnetizable, test_flywheel and test_klt.
"""
from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import gyro_sim
from gyro_sim.compiled import effects
from gyro_sim.io.recording import record_result
from gyro_sim.scenes.scene import SceneError, scene_from_dict

BASE = dict(rotor=dict(inertia=[1.0e-5, 1.2e-5, 1.5e-5]), torque_model="none", duration=0.4,
            output=dict(rate=50.0), initial=dict(spin=50.0, theta=0.1))


def scene(**effects_):
    return scene_from_dict(dict(BASE, effects=effects_))


@pytest.mark.parametrize("ef, fragment", [
    (dict(magnetizable=dict(M=[[1, 2, 0], [0, 1, 0], [0, 0, 1]])), "effects.magnetizable.M"),
    (dict(flywheel=dict(inertia=1e-6, axis=[0, 0, 0])), "axis = [0.0, 0.0, 0.0]: must be a non-zero vector"),
    (dict(flywheel=dict(inertia=1e-6, axis=[1, 0, 0], profile=dict(time=[0, 1], speed=[0]))), "they pair up"),
    (dict(flywheel=dict(inertia=1e-6, axis=[1, 0, 0], profile=dict(time=[0, 0], speed=[0, 1]))), "strictly increasing"),
    (dict(damper=dict(mass=-1.0, radius=0.01, stiffness=1.0)), "effects.damper.mass"),
    (dict(gas_drag=dict(transverse=[1, 2, 3, 4], axial=[0])), "effects.gas_drag.transverse"),
    (dict(wind=dict(k=1)), "allowed keys here: damper, flywheel, gas_drag, magnetizable, unbalance"),
])
def test_bad_effects_are_refused_with_one_clear_message(ef, fragment):
    with pytest.raises(SceneError) as e:
        scene(**ef)
    assert fragment in str(e.value), str(e.value)
    print(f"\n  {e.value}")


def test_effects_off_leave_the_model_untouched():
    """An absent effect packs to eff[ON] = 0 and the run is the plain rotor's, bit for bit; the free
    rotor keeps its exact geometric stepper."""
    s = scene_from_dict(dict(BASE, integrator=dict(steps_per_turn=480)))
    eff = effects.pack_effects(s)
    assert eff[effects.ON] == 0.0 and not eff.any()
    r = gyro_sim.run(s)
    # the same rotor with a drag of zero coefficients is on the effects path (RK4 steps): same physics
    # (both at 10× the default steps per turn, where both are converged to < 1e-8 rad)
    r2 = gyro_sim.run(scene_from_dict(dict(BASE, integrator=dict(steps_per_turn=480),
                                           effects=dict(gas_drag=dict(transverse=[0.0], axial=[0.0])))))
    assert r.steps < r2.steps  # the exact free stepper needs far fewer steps than the generic one
    err = np.max(np.abs(r.L - r2.L)) / np.linalg.norm(r.L[0])
    dq = np.max(np.minimum(np.linalg.norm(r.q - r2.q, axis=1), np.linalg.norm(r.q + r2.q, axis=1)))
    print(f"\n  free stepper {r.steps} steps vs effects path {r2.steps}: |ΔL|/|L| {err:.1e}, |Δq| {dq:.1e}")
    assert err < 1e-12 and dq < 1e-7


def test_flywheel_with_zero_total_moment_turns_the_body_at_lambda_times_the_wheel():
    """L = 0: Ω_b = −J_f Ω_f J⁻¹a ([S] (8)–(9)); the outputs carry Ω_f and its integral."""
    Jf, a = 1e-6, np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    s = scene_from_dict(dict(BASE, initial=dict(spin=0.0), effects=dict(
        flywheel=dict(inertia=Jf, axis=a.tolist(), profile=dict(time=[0.0, 0.2, 0.4], speed=[0.0, 400.0, 0.0])))))
    r = gyro_sim.run(s)
    wf = r.effects["flywheel_speed"]
    expect = -Jf * wf[:, None] * (a / np.array(BASE["rotor"]["inertia"]))[None, :]
    err = np.max(np.abs(r.omega_b - expect))
    print(f"\n  max |Ω_b + J_f Ω_f J⁻¹a| = {err:.1e} rad/s (peak |Ω_b| {np.max(np.abs(expect)):.2f})")
    assert err < 1e-12
    assert abs(r.effects["flywheel_angle"][-1] - 0.5 * 400.0 * 0.4) < 1e-12


def test_effect_states_are_recorded_and_read_back_independently(tmp_path):
    """/gyro/effects in the bag, decoded with mcap + mcap_ros2 (not our reader), equals the run."""
    s = scene(flywheel=dict(inertia=1e-6, axis=[0, 1, 0], profile=dict(time=[0.0, 0.4], speed=[0.0, 100.0])),
              damper=dict(mass=1e-3, radius=0.01, stiffness=50.0, damping=1e-3))
    r = gyro_sim.run(s)
    bag = record_result(r, tmp_path / "eff")
    (mcap_file,) = bag.glob("*.mcap")
    rows = []
    with open(mcap_file, "rb") as f:
        for _, _ch, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/gyro/effects"]):
            rows.append((list(msg.name), list(msg.position), list(msg.velocity)))
    assert len(rows) == len(r.t)
    assert rows[0][0] == ["flywheel", "damper_x", "damper_y", "damper_z"]
    pos = np.array([p for _, p, _ in rows])
    vel = np.array([v for _, _, v in rows])
    assert np.array_equal(pos[:, 0], r.effects["flywheel_angle"]) and np.array_equal(vel[:, 0], r.effects["flywheel_speed"])
    assert np.array_equal(pos[:, 1:], r.effects["damper_offset"]) and np.array_equal(vel[:, 1:], r.effects["damper_velocity"])
