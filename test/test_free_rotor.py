"""Free rigid body (physics.md §6 item 10): the geometric stepper against the exact Jacobi solution.

|L| and kinetic energy must stay at round-off over 10⁶ revolutions; the attitude is compared with
the closed form of :func:`gyro_sim.physics.closed_forms.free_rigid_body`.
"""
import math

import numpy as np
import pytest

from gyro_sim.physics.closed_forms import free_rigid_body
from gyro_sim.physics.frames import quat_to_matrix
from gyro_sim.scenes.scene import scene_from_dict
from gyro_sim.engine.simulate import run

SPIN = 100.0  # rad/s


def free_scene(J, revs, samples, **initial):
    T = revs * 2 * math.pi / SPIN
    ini = {"spin": SPIN, "theta": 0.3, "phi": 0.4, "psi": 0.2}
    ini.update(initial)
    return scene_from_dict({"rotor": {"inertia": J}, "torque_model": "none", "initial": ini, "duration": T,
                            "output": {"rate": samples / T}})


def attitude_error(r):
    """Largest rotation angle (rad) between the run's attitude and the exact solution."""
    R = quat_to_matrix(r.q)
    _, Rx = free_rigid_body(r.scene.inertia, R[0], r.L[0], r.t)
    # ‖R − Rx‖_F = 2√2 sin(angle/2): well conditioned for small angles (unlike arccos of the trace)
    d = np.linalg.norm(R - Rx, axis=(1, 2)) / (2 * math.sqrt(2))
    return float(np.max(2 * np.arcsin(np.clip(d, 0, 1))))


@pytest.mark.parametrize("J,kind", [([5.0e-6, 5.5e-6, 6.0e-6], "triaxial, round the major axis"),
                                    ([5.0e-6, 5.5e-6, 6.0e-6], "triaxial, round the minor axis"),
                                    ([5.5e-6, 5.5e-6, 6.0e-6], "axisymmetric")])
def test_conservation_over_a_million_revolutions(J, kind):
    ini = {"theta": 1.45, "phi": 1.47} if "minor" in kind else {}
    r = run(free_scene(J, 1e6, 50, **ini))
    Ln = np.linalg.norm(r.L, axis=1)
    dL = float(np.max(np.abs(Ln / Ln[0] - 1)))
    dE = float(np.max(np.abs(r.energy / r.energy[0] - 1)))
    print(f"\n{kind}: 10⁶ revolutions in {r.steps} steps, {r.wall_time:.2f} s: "
          f"|L| drift {dL:.1e}, energy drift {dE:.1e} (tolerance 1e-11 = round-off accumulated over the steps)")
    assert dL <= 1e-14
    assert dE <= 1e-11


@pytest.mark.parametrize("J,spt,tol", [([5.0e-6, 5.5e-6, 6.0e-6], 200, 1e-4), ([5.5e-6, 5.5e-6, 6.0e-6], 48, 1e-10)])
def test_attitude_against_jacobi_solution(J, spt, tol):
    """The 8th-order midpoint composition (triaxial) / exact split (axisymmetric) vs the elliptic solution."""
    s = free_scene(J, 1000, 400)
    s = s.model_copy(update={"integrator": s.integrator.model_copy(update={"steps_per_turn": spt})})
    r = run(s)
    err = attitude_error(r)
    print(f"\nJ = {J}: attitude error after 1000 revolutions {err:.2e} rad (tolerance {tol:.0e}), "
          f"{r.steps} steps ({spt} per turn of the body-frame motion)")
    assert err <= tol


def test_attitude_error_falls_at_eighth_order():
    """The free stepper of a triaxial body composes the midpoint step to order 8 (Kahan & Li s15odr8)."""
    J = [5.0e-6, 5.5e-6, 6.0e-6]
    errs = []
    for spt in (8, 16):
        s = free_scene(J, 100, 100)
        s = s.model_copy(update={"integrator": s.integrator.model_copy(update={"steps_per_turn": spt})})
        errs.append(attitude_error(run(s)))
    order = math.log2(errs[0] / errs[1])
    print(f"\nattitude errors {errs[0]:.2e} → {errs[1]:.2e} when the step halves: observed order {order:.2f}")
    assert 7.0 < order < 9.0


@pytest.mark.parametrize("J,ini,kind", [([5.0e-6, 5.5e-6, 6.0e-6], {}, "round the major axis"),
                                        ([5.0e-6, 5.5e-6, 6.0e-6], {"theta": 1.45, "phi": 1.47},
                                         "round the minor axis, large amplitude")])
def test_jacobi_over_1e5_revolutions_by_default(J, ini, kind):
    """Issue 19: a free triaxial rotor over 10⁵ revolutions, as a scene gives it (no integrator knobs), against the
    Jacobi solution within the scene's default attitude tolerance (1e-6 rad over the whole run). With the old
    default (48 steps per turn, 4th order) the attitude drifted 2.1e-5 rad a revolution: 2.1 rad over 10⁵."""
    s = free_scene(J, 1e5, 100, **ini)
    r = run(s)
    err = attitude_error(r)
    est = r.error_estimate
    print(f"\n{kind}: 10⁵ revolutions in {r.steps} steps, {r.wall_time:.2f} s: attitude error {err:.2e} rad "
          f"against the Jacobi solution (tolerance {s.accuracy.attitude:g} rad, the scene's default); estimated "
          f"{est.attitude:.2e} ({est.steps_method})")
    assert err <= s.accuracy.attitude
    assert est.attitude <= s.accuracy.attitude
