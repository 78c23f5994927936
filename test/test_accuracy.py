"""Accuracy by default (issue 19): a scene states its tolerance; the run chooses modes and steps for it.

Part 1: the eddy modes. The torque of a rotating field on a solid sphere and on a shell (r1/r2 = 0.7) at
ωτ₁ = 1, 10, 100, 1000 against [M] (2.14) / the corrected (2.13), by default (no ``modes:`` in the scene). With
the old default of 10 modes the sphere's torque was 6 % too high at ωτ₁ = 100 and 8.6x at 1000.
"""
import math
import warnings

import numpy as np

from gyro_sim.physics.frames import attitude_split, symmetry_axis
import pytest

from gyro_sim.scenes.accuracy import AccuracyWarning, choose_modes, mode_plan, modal_error
from gyro_sim.physics.conductor import g_shell, g_solid_sphere, modal_shell
from gyro_sim.physics.constants import MU0
from gyro_sim.scenes.scene import SceneError, load_scene, scene_from_dict
from gyro_sim.engine.simulate import Simulator, run

A, SIG, B0 = 0.025, 2.5e7, 2e-3
RHO = 0.7  # r1/r2 of the thick shell


def tau1(kind: str) -> float:
    """Slowest eddy time constant (s): μ0σa²/π² for the sphere ([M] (2.14)'s first pole), the shell's first pole."""
    if kind == "shell":
        return float(modal_shell(RHO * A, A, SIG, 1).tau[0])
    return MU0 * SIG * A * A / math.pi ** 2


def field_scene(kind: str, x: float, **extra):
    """A rotor held (J = 1e6 kg m²: it does not spin up) in a 2 mT field turning at ν = x/τ₁ about z3, for 20 τ₁
    (the switch-on transient decays as e^(−t/τ₁): 2e-9 at the end)."""
    cond = {"kind": kind, "outer_radius": A, "conductivity": SIG}
    if kind == "shell":
        cond["thickness"] = (1 - RHO) * A
    t1 = tau1(kind)
    d = {"name": f"{kind}_wt{x:g}", "rotor": {"inertia": [1e6, 1e6, 1e6], "conductor": cond}, "torque_model": "lag",
         "stators": [{"name": "z3", "axis": [0, 0, 1], "coil_constant": B0, "current": 1.0, "rate": x / t1}],
         "duration": 20 * t1, "output": {"rate": 1 / t1}}
    d.update(extra)
    return scene_from_dict(d)


def exact_torque(kind: str, slip: float) -> float:
    """Axial torque (N m) of the rotating field at ``slip``: (2π a³/μ0) B0² Im ĝ, [M] (2.14) / (2.13) corrected."""
    g = g_solid_sphere(slip, A, SIG) if kind == "solid_sphere" else g_shell(slip, RHO * A, A, SIG)
    return 2 * math.pi * A ** 3 / MU0 * B0 ** 2 * float(np.imag(g))


@pytest.mark.parametrize("kind", ["solid_sphere", "shell"])
@pytest.mark.parametrize("x", [1, 10, 100, 1000])
def test_rotating_field_torque_by_default(kind, x):
    """[M] (2.14) (sphere) / (2.13) (shell, r1/r2 = 0.7) at ωτ₁ = x, within the scene's default rtol (1e-6)."""
    s = field_scene(kind, x)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)  # the default must not need a warning
        r = run(s)
    plan = Simulator(s).mode_plan
    slip = s.stators[0].rate - float(r.omega_b[-1, 2])
    err = abs(float(r.torque[-1, 2]) / exact_torque(kind, slip) - 1)
    tol = s.accuracy.rtol
    print(f"\n{kind}, ωτ₁ = {x}: {plan.n} modes (tail {plan.tail}), torque error {err:.2e} against [M] "
          f"{'(2.14)' if kind == 'solid_sphere' else '(2.13)'} (tolerance: the scene's rtol {tol:g})")
    assert err <= tol


def test_ten_modes_were_wrong():
    """The issue's figures: 10 modes with the tail give 6 % at ωτ₁ = 100 and 8.6x at 1000 (Im ĝ); 50 modes 4.5e-3."""
    wt = MU0 * SIG * A * A / math.pi ** 2
    e100 = modal_error("solid_sphere", A, SIG, None, 10, True, 100 / wt)[1]
    e1000 = modal_error("solid_sphere", A, SIG, None, 10, True, 1000 / wt)[1]
    e50 = modal_error("solid_sphere", A, SIG, None, 50, True, 1000 / wt)[1]
    print(f"\nIm ĝ error up to ωτ₁ = 100 / 1000 with 10 modes: {e100:.3g} / {e1000:.3g}; 50 modes at 1000: {e50:.2g}")
    assert 0.05 < e100 < 0.08 and 7 < e1000 < 9 and 3e-3 < e50 < 6e-3


def test_explicit_modes_win_with_a_warning():
    s = field_scene("solid_sphere", 100, modes=10)
    with pytest.warns(AccuracyWarning, match="modes = 10 cannot meet accuracy"):
        sim = Simulator(s)
    assert sim.mode_plan.n == 10 and sim.tau.size == 10 and not sim.mode_plan.met
    # enough modes given: no warning
    s = field_scene("solid_sphere", 1, modes=40)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        assert Simulator(s).tau.size == 40


def test_looser_tolerance_fewer_modes_and_tail_choice():
    wt = MU0 * SIG * A * A / math.pi ** 2
    n6 = choose_modes("solid_sphere", A, SIG, None, 100 / wt, 2.5e-7, 2.5e-7)
    n3 = choose_modes("solid_sphere", A, SIG, None, 100 / wt, 2.5e-4, 2.5e-4)
    print(f"\nωτ₁ = 100: {n6[0]} modes for 2.5e-7, {n3[0]} for 2.5e-4 (tail {n6[1]}, {n3[1]})")
    assert n3[0] < n6[0] and n6[4] and n3[4]
    s = field_scene("shell", 10, accuracy={"rtol": 1e-3, "attitude": 1e-3})
    assert mode_plan(s).n < mode_plan(field_scene("shell", 10)).n


def test_command_beyond_the_plan_warns_once():
    """A command faster than anything in the scene (here: through Simulator.set_stator, as the ROS node does)
    passes the slip the modes were chosen for: one warning, and slip_met records it. (The stator's ``max_rate`` lets
    the command through: by default a rate 10 times the scene's is refused, issue 29.)"""
    t1 = tau1("solid_sphere")
    s = field_scene("solid_sphere", 1, stators=[{"name": "z3", "axis": [0, 0, 1], "coil_constant": B0, "current": 1.0,
                                                 "rate": 1 / t1, "max_rate": 2000 / t1}])
    sim = Simulator(s)
    n = sim.mode_plan.n
    sim.advance(1e-3)
    with pytest.warns(AccuracyWarning, match="beyond the"):
        sim.set_stator(0, rate=1000 / tau1("solid_sphere"))
        sim.advance(2e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        sim.set_stator(0, rate=2000 / tau1("solid_sphere"))
        sim.advance(3e-3)
    assert sim.slip_met > 1999 / tau1("solid_sphere") and sim.tau.size == n


def test_law_rates_count_in_the_plan():
    """A law's rate parameters are part of the slip bound (the spin-up law of the default scene)."""
    s = load_scene("spinup_thin_shell")
    assert mode_plan(s).slip >= 3141.59
    s = load_scene("spinup_solid_sphere", overrides={"stators": [{"name": "z3", "axis": [0, 0, 1],
                                                                  "coil_constant": 2e-3, "rate": 0.0}],
                                                     "controller": {"law": "spinup", "period": 0.02, "params": {
                                                         "stator": "z3", "target_spin": 628.3, "current": 1.0}}})
    assert mode_plan(s).slip >= 628.3


@pytest.mark.parametrize("acc,msg", [({"rtol": 0.0}, "rtol"), ({"rtol": 0.5}, "rtol"), ({"attitude": -1}, "attitude"),
                                     ({"tolerance": 1e-3}, "unknown key")])
def test_accuracy_section_is_validated(acc, msg):
    with pytest.raises(SceneError, match=msg):
        scene_from_dict({"rotor": {"inertia": [1, 1, 1]}, "duration": 1.0, "accuracy": acc})


# --- part 2 and 3: steps chosen for the tolerance, the error control, the estimate ---------------------------
def test_error_control_decides_alike_whatever_the_breaks():
    """The error control checks at fixed instants that are breaks of every run: an in-process run and one whose
    samples are breaks (as the ROS node runs) change their step alike and give the same bits and estimate."""
    from gyro_sim.engine.simulate import Runner, drive

    s = load_scene("spinup_thin_shell", overrides={"duration": 4.0})
    runs = []
    for breaks in (False, True):
        r = Runner(s, sample_breaks=breaks, attitude=True)
        drive(r)
        runs.append(r)
    a, b = (x.result() for x in runs)
    divs = [h[3] for h in runs[0].estimator.control.history]
    print(f"\nstep divisor at the checks: {', '.join(f'{d:.3g}' for d in divs)}; final {runs[0].sim.step_div:.3g}")
    assert len(set(divs)) > 1  # the control did change the step
    assert np.array_equal(a.L, b.L) and np.array_equal(a.q, b.q) and a.steps == b.steps
    assert a.error_estimate == b.error_estimate


def test_estimate_is_reported_everywhere(tmp_path):
    from gyro_sim.apps.cli import format_summary
    from gyro_sim.io.recording import bag_info, record_run

    s = load_scene("nutation_oblate", overrides={"duration": 0.2})
    r = record_run(s, tmp_path / "bag")
    est = r.error_estimate
    assert est is not None and est.steps_method == "richardson" and est.met
    summ = r.summary()
    assert summ["error_L"] == est.L and summ["error_attitude"] == est.attitude and summ["accuracy_met"] is True
    assert "estimated error" in format_summary("x", summ)
    custom = bag_info(tmp_path / "bag")["custom"]
    from gyro_sim.scenes.accuracy import ErrorEstimate

    assert ErrorEstimate.from_json(str(custom["gyro_sim.error_estimate"])) == est
    print(f"\nestimate: {est.text()}")


def test_steps_follow_the_tolerance_and_explicit_knobs_win_with_a_warning():
    # (at the default 1e-6 the plan of rotating_field is at lawson8's floor of 8 steps per turn, as at 1e-3)
    s6 = load_scene("rotating_field", overrides={"duration": 2.0, "accuracy": {"rtol": 1e-9, "attitude": 1e-9}})
    s3 = load_scene("rotating_field", overrides={"duration": 2.0, "accuracy": {"rtol": 1e-3, "attitude": 1e-3}})
    p6, p3 = Simulator(s6).step_plan, Simulator(s3).step_plan
    assert p6.steps_per_turn["lawson8"] > p3.steps_per_turn["lawson8"] and p6.rate_change <= p3.rate_change
    s = load_scene("rotating_field", overrides={"duration": 2.0, "integrator": {"method": "lawson8",
                                                                              "steps_per_turn": 8},
                                                "accuracy": {"rtol": 1e-9, "attitude": 1e-9}})
    with pytest.warns(AccuracyWarning, match="steps_per_turn = 8 cannot meet accuracy"):
        r = run(s)
    assert r.error_estimate is not None


@pytest.mark.parametrize("name,T", [("rotating_field", 2.0), ("pulsating_field", 2.0), ("constant_field", 4.0),
                                    ("spinup_thin_shell", 4.0)])
def test_estimate_within_a_factor_ten_of_the_error(name, T):
    """The run's estimate against its error from a converged reference (lawson8 with steps well under τ and the
    turn), on scenes whose error is far above the reference's own."""
    ov = {"duration": T}
    r = run(load_scene(name, overrides=ov), attitude=True)
    ref = run(load_scene(name, overrides={**ov, "integrator": {"method": "lawson8", "steps_per_turn": 512}}),
              attitude=True, estimate=False)
    n = len(ref.t)
    eL, eq, ep = _errors_against(r, ref, split=True)
    est = r.error_estimate
    print(f"\n{name} {T:g} s: error L {eL:.2e}, directions {eq:.2e}, phase {ep:.2e}; estimate {est.L:.2e}, "
          f"{est.attitude:.2e}, {est.phase:.2e} (ratios {est.L / eL:.2g}, {est.attitude / eq:.2g}, "
          f"{est.phase / ep:.2g}; within a factor 10 asked); {n} samples")
    assert eq <= s_tol(r) and eL <= r.scene.accuracy.rtol and ep <= est.phase_tol
    # (constant_field's stiff ETDRK4 stretches are estimated at order 1, an upper bound: 16x its phase measured with
    # the absolute phase; 26x with the phase relative to itself, its steps 716 instead of 1,721)
    assert 0.5 <= est.phase / ep <= (30 if name == "constant_field" else 10)  # (rotating_field: 0.8)
    # the directions (the axis' cone about L) the steps hold far closer than the phases: where they are at the
    # reference's own level the ratio says nothing; else within the factor
    assert eq < 1e-11 or 0.1 <= est.attitude / eq <= 10


def s_tol(r):
    return r.scene.accuracy.attitude


def _errors_against(r, ref, split: bool = False):
    """(max relative error of L, max attitude error rad) of run r against ref on the same samples; ``split``: the
    attitude's as (directions, phases) (frames.attitude_split with L: the axis' cone about L, and the spin phase or the
    axis' place on its cone), the tolerances' terms."""
    d = np.minimum(np.linalg.norm(r.q - ref.q, axis=1), np.linalg.norm(r.q + ref.q, axis=1))
    eL = float(np.max(np.linalg.norm(r.L - ref.L, axis=1)) / np.max(np.linalg.norm(ref.L, axis=1)))
    if split:
        di, ph = attitude_split(r.q, ref.q, symmetry_axis(r.scene.rotor.inertia), r.L, ref.L)
        return eL, float(np.max(di)), float(np.max(ph))
    return eL, float(np.max(4 * np.arcsin(d / 2)))


@pytest.fixture(scope="module")
def constant_field_reference():
    """constant_field over 2 s by lawson8 at 1924 steps per turn (h = τ/8; agrees with 962 to 4e-12 rad)."""
    s = load_scene("constant_field", overrides={"duration": 2.0,
                                                "integrator": {"method": "lawson8", "steps_per_turn": 1924}})
    return run(s, attitude=True, estimate=False)


def test_a_loose_tolerance_with_stiff_etdrk4_steps_is_met_and_not_underestimated(constant_field_reference):
    """Bench defect: at accuracy 1e-3 constant_field ran ETDRK4 at 8 τ per step, where its error falls as h^1.4 to
    h^2, not h^4: the Richardson estimate at order 4 was 1/6 to 1/10 of the error, and the run missed its
    attitude tolerance (1.5e-3 rad against 1e-3). Stiff stretches are now estimated at order 1."""
    s = load_scene("constant_field", overrides={"duration": 2.0, "accuracy": {"rtol": 1e-3, "attitude": 1e-3}})
    r = run(s, attitude=True)
    eL, eq = _errors_against(r, constant_field_reference)
    est = r.error_estimate
    print(f"\nconstant_field at 1e-3: error L {eL:.2e}, attitude {eq:.2e} rad; estimate {est.L:.2e}, "
          f"{est.attitude:.2e}")
    assert eL <= 1e-3 and eq <= 1e-3
    assert est.L >= eL and est.attitude >= eq


def test_a_tight_tolerance_holds_lawson8_at_tau_instead_of_etdrk4(constant_field_reference):
    """Bench defect: at accuracy 1e-9 constant_field (τ = 0.26 ms, 100 rad/s) ran ETDRK4 for 3.6 million steps
    (lawson8's planned step was beyond 2 τ); lawson8 held at τ costs 3 % of that and meets the tolerance."""
    s = load_scene("constant_field", overrides={"duration": 2.0, "accuracy": {"rtol": 1e-9, "attitude": 1e-9}})
    r = run(s, attitude=True)
    eL, eq, ep = _errors_against(r, constant_field_reference, split=True)
    print(f"\nconstant_field at 1e-9: {r.steps} steps, error L {eL:.2e}, directions {eq:.2e} rad, phase {ep:.2e} rad "
          f"(tolerance {r.error_estimate.phase_tol:.2e})")
    est = r.error_estimate
    assert r.steps < 200_000
    assert eL <= 1e-9 and ep <= est.phase_tol
    # the axis' cone at 1e-9 rad: measured 2.4e-9 whatever the step (140,962 or 2.5 million steps: not the steps'
    # error); the run says so (its estimate above what it reaches, the summary 'not met')
    assert eq <= 1e-9 or (est.attitude >= eq and not est.met)
