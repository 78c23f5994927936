"""An isotropic rotor whose attitude no one reads: ``output.attitude: false``
(gyro_sim.engine.simulate.integrates_attitude).

Without attitude L and the eddy modes are integrated in the case frame, τ(ė − Ω×e) + e = −τ(dB/dt − Ω×B)
(gyro_sim/compiled/kernels.py); these tests hold it to the body-frame model with the attitude.
"""
import math
import time

import numpy as np
import pytest

from gyro_sim import load_scene, run

from gyro_sim.compiled import frozen_flow
from gyro_sim.io.plotting import plot_run
from gyro_sim.io.recording import record_result
from gyro_sim.scenes.scene import SceneError
from gyro_sim.engine.simulate import _case_flag, Runner, Simulator

J = 5.592e-6  # kg·m², the default shell's transverse moment, all three equal here


def iso_scene(attitude: bool, duration: float = 2.0, **over):
    """The default thin-shell spin-up (2 s, no controller) with inertia [J, J, J]. The step knobs are given (the old
    defaults): a run plans its steps for its accuracy, and without the attitude it has no attitude tolerance to
    meet, so the two runs compared here would otherwise take other steps (gyro_sim/scenes/accuracy.py)."""
    ov = {"controller": None, "rotor.inertia": [J, J, J], "duration": duration, "output.attitude": attitude,
          "integrator": {"steps_per_turn": 12, "rate_change": 1e-4}, **over}
    return load_scene("spinup_thin_shell", overrides=ov)


def rel(a, b):
    """max over rows of |a − b| / max over rows of |b| (rows = samples of a 3-vector)."""
    return float(np.max(np.linalg.norm(a - b, axis=1)) / np.max(np.linalg.norm(b, axis=1)))


def spin_diff(ra, rb):
    wa, wb = np.linalg.norm(ra.omega_b, axis=1), np.linalg.norm(rb.omega_b, axis=1)
    return float(np.max(np.abs(wa - wb)) / np.max(wa))


def test_spinup_without_attitude_agrees_to_round_off():
    """The brief's scene with the stepper ``auto`` picks (frozen_flow): L, torque and |Ω| to round-off."""
    a, b = iso_scene(True), iso_scene(False)
    assert Simulator(b)._method() == "frozen_flow" and not Simulator(b).attitude and Simulator(a).attitude
    ra, rb = run(a), run(b)
    assert ra.attitude and not rb.attitude and ra.steps == rb.steps
    dL, dN, dW = rel(rb.L, ra.L), rel(rb.torque, ra.torque), spin_diff(ra, rb)
    tol = 1e-12
    print(f"\nattitude false vs true, 2 s iso spin-up, frozen_flow ({ra.steps} steps): max rel. diff L {dL:.1e}, "
          f"torque {dN:.1e}, |Ω| {dW:.1e} (tolerance {tol:g})")
    assert dL < tol and dN < tol and dW < tol
    # the spin itself moved: the comparison is not of two rotors at rest
    assert np.linalg.norm(rb.omega_b[-1]) > 10.0


@pytest.mark.parametrize("method", ["lawson8", "etdrk4"])
def test_turn_resolving_steppers_agree_within_their_error(method):
    """lawson8 and ETDRK4 integrate the case-frame equations with other stage values than the Lie-group steps:
    the two runs differ at the steppers' truncation level, within the sum of their estimated errors of L (measured:
    lawson8 3.8e-8, its runs' errors against lawson8 at 96 steps per turn 3.1e-8 and 6.8e-8, estimated 1.1e-7 and
    2.5e-7, since it may coarsen to 8 steps a turn; ETDRK4 5.4e-7, errors 9.7e-8 and 6.4e-7, estimated 9.1e-8 and
    5.8e-7), each run within the scene's rtol by its own estimate."""
    ov = {"integrator": {"method": method}}
    ra, rb = run(iso_scene(True, 1.0, **ov)), run(iso_scene(False, 1.0, **ov))
    dL, dN, dW = rel(rb.L, ra.L), rel(rb.torque, ra.torque), spin_diff(ra, rb)
    tol = ra.error_estimate.L + rb.error_estimate.L
    print(f"\n{method}: max rel. diff L {dL:.1e}, torque {dN:.1e}, |Ω| {dW:.1e} (tolerance {tol:.1e}: the two runs' "
          f"estimates)")
    assert max(ra.error_estimate.L, rb.error_estimate.L) <= ra.scene.accuracy.rtol
    assert dL < tol and dN < tol and dW < tol


#: a harder case: L off the field's axis, fields about all three axes, a stretch without field (free stepper,
#: the case-frame modes turning with the body), current and rate steps
GENERAL = {"initial": {"spin": 1500.0, "L_direction": [0.3, 0.2, 1.0], "theta": 0.4, "psi": 0.3},
           "stators.0.current": 0.7, "stators.0.rate": -2000.0,
           "commands": [{"time": 0.2, "stator": "z3", "current": 0.0}, {"time": 0.2, "stator": "z1", "current": 0.0},
                        {"time": 0.35, "stator": "z3", "current": 1.0},
                        {"time": 0.45, "stator": "z2", "current": 0.5, "rate": 800.0}]}


def test_case_frame_model_converges_to_the_body_frame_model():
    """Resolved finely (lawson8, 64 steps per turn), the case-frame model and the body-frame model are one:
    measured 2.8e-14 in L over 1.5 s of the general scene; here 0.6 s."""
    ov = {**GENERAL, "integrator": {"method": "lawson8", "steps_per_turn": 64}}
    ra, rb = run(iso_scene(True, 0.6, **ov)), run(iso_scene(False, 0.6, **ov))
    dL, dN, dW = rel(rb.L, ra.L), rel(rb.torque, ra.torque), spin_diff(ra, rb)
    tol = 1e-12
    print(f"\ngeneral scene, lawson8 at 64 steps per turn: max rel. diff L {dL:.1e}, torque {dN:.1e}, |Ω| {dW:.1e} "
          f"(tolerance {tol:g})")
    assert dL < tol and dN < tol and dW < tol
    # the scene does work the modes: a frame error of the case-frame modes would show in the torque
    assert np.max(np.linalg.norm(ra.torque, axis=1)) > 1e-5


def test_case_frame_frozen_flow_is_as_accurate():
    """The frozen-flow step: with the attitude, its least-rotation correction moves the body (and the body-frame
    modes with it); without, the modes need none. On the general scene both are within the method's error of a
    fine reference, the case-frame one no worse (measured over 0.6 s: see the print)."""
    ref = run(iso_scene(True, 0.6, **GENERAL, integrator={"method": "lawson8", "steps_per_turn": 64}))
    ra = run(iso_scene(True, 0.6, **GENERAL, integrator={"method": "frozen_flow", "rate_change": 1e-4}))
    rb = run(iso_scene(False, 0.6, **GENERAL, integrator={"method": "frozen_flow", "rate_change": 1e-4}))
    ea, eb = rel(ra.L, ref.L), rel(rb.L, ref.L)
    print(f"\nfrozen_flow, general scene: error of L with attitude {ea:.1e}, without {eb:.1e}; "
          f"between them {rel(rb.L, ra.L):.1e}")
    assert eb < 1e-7 and eb < 2.0 * ea


def test_outputs_without_attitude(tmp_path):
    """q, Euler angles and θ are NaN; Ω is in the case frame (= L/J); the summary, the plot and a bag cope."""
    r = run(iso_scene(False, 0.2))
    assert np.isnan(r.q).all() and np.isnan(r.euler).all() and np.isnan(r.theta).all()
    assert np.allclose(r.omega_b, r.L / J, rtol=1e-15, atol=0.0)
    assert np.array_equal(r.spin_rate, np.linalg.norm(r.omega_b, axis=1))
    s = r.summary()
    assert s["attitude"] is False and math.isnan(s["theta_deg"]) and s["spin_rate"] > 0.0
    assert math.isclose(s["energy"], 0.5 * np.dot(r.L[-1], r.L[-1]) / J, rel_tol=1e-12)
    png = tmp_path / "iso.png"
    plot_run(r, png)
    assert png.stat().st_size > 1000
    with pytest.raises(ValueError, match="did not integrate the attitude"):
        record_result(r, tmp_path / "bag")
    # the same run with the attitude kept (as a recorded run does): the same L, finite q
    k = run(iso_scene(False, 0.2), attitude=True)
    assert k.attitude and np.isfinite(k.q).all() and rel(r.L, k.L) < 1e-12


def test_on_samples_chunks_without_attitude():
    """Runs with a samples callback (samples are then breaks) give NaN Euler angles in each chunk, the same L."""
    chunks = []
    r = run(iso_scene(False, 0.2), on_samples=chunks.append)
    assert all(np.isnan(c["euler"]).all() and np.isnan(c["q"]).all() for c in chunks)
    assert np.array_equal(np.vstack([c["L"] for c in chunks]), r.L)


@pytest.mark.parametrize("why,over", [
    ("axisymmetric rotor", {"rotor.inertia": [J, J, 1.02 * J]}),
    ("an effect on", {"effects": {"gas_drag": {"transverse": [0.0], "axial": [0.0]}}}),
    ("fidelity auto", {"fidelity": "auto"}),
    ("psi_switching reads θ", {"controller": {"law": "psi_switching", "period": 0.01,
                                              "params": {"nu": 300.0, "control_stators": ["z1", "z2"],
                                                         "spin_stator": "z3", "control_current": 0.1,
                                                         "spin_current": 1.0, "spin_rate": 3000.0}}}),
])
def test_attitude_kept_where_the_dynamics_need_it(why, over):
    """attitude: false is accepted and changes nothing where the rotor is not isotropic, an effect is on, the
    fidelity is averaged/auto or the controller reads the attitude: bit for bit the run with attitude: true."""
    ra, rb = run(iso_scene(True, 0.1, **over)), run(iso_scene(False, 0.1, **over))
    assert rb.attitude and np.isfinite(rb.q).all()
    for k in ("L", "q", "omega_b", "torque"):
        assert np.array_equal(getattr(ra, k), getattr(rb, k)), (why, k)


def test_spinup_controller_runs_without_attitude():
    """The spin-up law reads neither q nor θ: with it the attitude is still dropped, and L is the same."""
    over = {"controller": {"law": "spinup", "period": 0.02,
                           "params": {"stator": "z3", "target_spin": 3141.592653589793, "current": 1.0}}}
    ra, rb = run(iso_scene(True, 0.5, **over)), run(iso_scene(False, 0.5, **over))
    assert not rb.attitude and rel(rb.L, ra.L) < 1e-12


def test_ros_node_runner_keeps_the_attitude():
    """The simulator node and the bag re-run make their Runner with attitude=True: it is integrated anyway."""
    sc = iso_scene(False, 0.1)
    assert not Runner(sc).sim.attitude
    assert Runner(sc, attitude=True).sim.attitude
    import inspect

    from pathlib import Path

    from gyro_sim.io import rerun
    assert "attitude=True" in inspect.getsource(rerun.rerun_bag)
    import gyro_sim

    node = (Path(gyro_sim.__file__).parent / "ros" / "simulator_node.py").read_text()
    assert "Runner(node.scene, self.p[\"duration\"] or None, attitude=True," in node


def test_bad_attitude_value_is_refused():
    with pytest.raises(SceneError, match=r"output\.attitude = 3"):
        iso_scene(3)
    with pytest.raises(SceneError, match=r"output\.attitude"):
        iso_scene("no")


def test_no_attitude_work_makes_the_step_cheaper():
    """The case-frame frozen-flow step does no attitude work (no projection onto the body, no nutation integrals,
    one moment term per phasor): measured 3.3x cheaper runs; asserted > 1.5x on the compiled loop (least of 5)."""
    costs = []
    for att in (True, False):
        sim = Simulator(iso_scene(att))
        t_seg, Bre, Bim, om, _, method, h = sim._segment()
        assert method == "frozen_flow"
        stops, rec = np.array([2.0]), np.array([False])
        oy, oN = np.zeros((1, sim.y.size)), np.zeros((1, 3))

        def go(sim=sim, t_seg=t_seg, stops=stops, rec=rec, h=h, Bre=Bre, Bim=Bim, om=om, oy=oy, oN=oN):
            y = sim.y.copy()
            return frozen_flow.integrate_frozen(y, 0.0, t_seg, stops, rec, h, Bre, Bim, om, sim.Jinv, J, J, 2,
                                                sim.c_m, sim.w, sim.tail, 1.0 / sim.tau, oy, oN, 0,
                                                *_case_flag(sim.attitude))

        go()
        best = math.inf
        for _ in range(5):
            c = time.process_time()
            go()
            best = min(best, time.process_time() - c)
        costs.append(best)
    print(f"\nfrozen-flow loop, 2 s: {costs[0] * 1e3:.2f} ms with attitude, {costs[1] * 1e3:.2f} ms without "
          f"({costs[0] / costs[1]:.1f}x)")
    assert costs[0] > 1.5 * costs[1]


def test_cli_run_without_attitude_and_recorded(tmp_path, capsys):
    """`gyro-sim run` on a scene with attitude: false: the summary says θ was not integrated; with --record the
    run keeps the attitude (the bag's /gyro/imu and /gyro/euler need it) and the bag holds a finite q."""
    import yaml

    from gyro_sim.apps import cli
    from gyro_sim.io.recording import read_bag
    from gyro_sim.scenes.scene import config_dir, parse_scene_text

    data = parse_scene_text((config_dir() / "spinup_thin_shell.yaml").read_text())
    data.update(duration=0.2, controller=None, output={"rate": 50.0, "attitude": False})
    data["rotor"]["inertia"] = [J, J, J]
    path = tmp_path / "iso.yaml"
    path.write_text(yaml.safe_dump(data))
    assert cli.main(["run", str(path), "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    with capsys.disabled():
        print("\n" + out)
    assert "not integrated (output.attitude: false)" in out and "(|Ω|)" in out
    bag = tmp_path / "bag"
    assert cli.main(["run", str(path), "--out", str(tmp_path), "--quiet", "--record", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "not integrated" not in out
    b = read_bag(bag)
    assert np.isfinite(b.q).all() and np.isfinite(b.euler).all() and len(b.t) == 11
