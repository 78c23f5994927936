"""Issue 28, budgets and responsiveness: a run whose plan exceeds the step budget is refused before any work in one
line naming what to loosen (``--force`` / ``force=True`` runs it anyway), and SIGINT ends a run within about a second
wherever it is: the compiled steppers return to Python after a bounded number of steps (Simulator.advance calls them
in pieces), and where they are cut changes no bit of the result.

The time bounds are generous hang guards (the machine may be loaded); the issue's goal, 2 s on an idle machine, is
measured in the report of the change, not asserted here.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.engine import steppers
from gyro_sim.engine.budget import check_budget, planned_work
from gyro_sim.engine.runner import Runner
from gyro_sim.engine.simulate import run
from gyro_sim.engine.simulator import Simulator
from gyro_sim.io.bag_reader import bag_info, read_bag
from gyro_sim.scenes.scene import SceneError, load_scene
from gyro_sim.scenes.step_control import STEP_BUDGET, StepBudgetError

GYRO_SIM = [sys.executable, "-m", "gyro_sim.apps.cli"]
#: wall s from SIGINT to the end of the process, summary of the bag and its plot included: a hang guard on a loaded
#: machine (the defect it guards ignored SIGINT for minutes), not the goal, 2 s idle (measured 0.04-0.06 s to the
#: interrupt in-process, 2.2 s to the CLI's exit with its summary). 10 s failed once with two whole suites running
#: side by side on 2 cores (13.9 s, 2026-11-29: the summary and plot are CPU work shared four ways)
SIGINT_BOUND = 30.0

ABSURD = """\
name: absurd_inertia
rotor:
  inertia: [1.0e-15, 1.0e6, 1.0e6]
  max_inertia_ratio: 1.0e21  # (issue 29 refuses the ratio by default: lifted here to reach the step budget)
  conductor: {kind: thin_shell, outer_radius: 0.025, thickness: 0.001, conductivity: 2.5e7}
stators:
  - {name: z3, axis: [0, 0, 1], coil_constant: 2.0e-3, current: 1.0, rate: 3141.592653589793}
duration: 1.0
"""


def _absurd(tmp_path: Path) -> Path:
    """A scene whose rotor spins about an axis of 1e-15 kg m²: a 1 s run plans ~1.5e13 steps."""
    path = tmp_path / "absurd_inertia.yaml"
    path.write_text(ABSURD)
    return path


def _cli(*args, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run(GYRO_SIM + list(args), capture_output=True, text=True, timeout=timeout)


def _interrupt_mid_run(tmp_path: Path, scene: str, duration: str, settle: float = 3.0):
    """`gyro-sim run SCENE --duration D --force --record BAG`, SIGINT once its bag is written to and ``settle`` s
    more (the run computing), then wait for it to end. Returns (process, stdout, stderr, wall s from the signal to
    the end, bag)."""
    bag = tmp_path / "bag"
    proc = subprocess.Popen(GYRO_SIM + ["run", scene, "--duration", duration, "--force", "--record", str(bag),
                                        "--out", str(tmp_path / "runs"), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        mcap = bag / "bag.mcap"
        end = time.monotonic() + 120.0  # (imports; a first compile of the kernels where the cache is cold)
        while time.monotonic() < end and proc.poll() is None and not (mcap.is_file() and mcap.stat().st_size > 0):
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        time.sleep(settle)
        assert proc.poll() is None, proc.communicate()
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=60.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
            pytest.fail(f"the run ignored SIGINT for 60 s: {err[-2000:]}")
        return proc, out, err, time.monotonic() - t0, bag
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# --- responsiveness -------------------------------------------------------------------------------------------

def test_sigint_ends_a_30000_s_run_promptly_with_a_readable_bag(tmp_path):
    """A 30 000 s run of the default scene (1.7e9 planned steps, run with --force) ignored SIGINT for minutes: a
    compiled stepper ran a whole break's steps, and the field's breaks of a tick-less stretch are far apart. Now the
    run ends within seconds of the signal, exit status 130, its bag readable and marked interrupted."""
    proc, out, err, wall, bag = _interrupt_mid_run(tmp_path, "spinup_thin_shell", "30000")
    print(f"\n  SIGINT to exit: {wall:.2f} s wall (the bag's summary and plot included)")
    assert proc.returncode == 130, err
    assert wall < SIGINT_BOUND, (wall, err)
    info = bag_info(bag)
    assert info["end_reason"] == "interrupted: signal SIGINT"
    data = read_bag(bag)
    assert data.t.size > 1 and data.t[0] == 0.0 and 0.0 < data.t[-1] < 30000.0
    assert np.all(np.isfinite(data.L))
    assert "interrupted (SIGINT)" in err


def test_absurd_plan_is_refused_before_any_work_and_runs_interruptibly_when_forced(tmp_path):
    """inertia [1e-15, 1e6, 1e6], one stator, 1 s: the plan asks ~1.5e13 steps. Without --force: one ``error:``
    line naming the field (rotor.inertia) and --force, status 2, no bag, at once; with --force the run starts and
    SIGINT ends it within seconds."""
    scene = str(_absurd(tmp_path))
    bag = tmp_path / "refused"
    t0 = time.monotonic()
    p = _cli("run", scene, "--record", str(bag), "--out", str(tmp_path / "runs"), "--quiet")
    wall = time.monotonic() - t0
    lines = [x for x in p.stderr.splitlines() if x.strip()]
    print(f"\n  refused in {wall:.2f} s wall: {lines}")
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), p.stderr
    assert "rotor.inertia" in lines[0] and "--force" in lines[0] and "STEP_BUDGET" in lines[0]
    assert not bag.exists()
    proc, out, err, wall, bag = _interrupt_mid_run(tmp_path, scene, "1", settle=2.0)
    print(f"  forced, SIGINT to exit: {wall:.2f} s wall")
    assert proc.returncode == 130, err
    assert wall < SIGINT_BOUND, (wall, err)
    assert bag_info(bag)["end_reason"] == "interrupted: signal SIGINT"
    assert read_bag(bag).t[0] == 0.0


# --- the budget -----------------------------------------------------------------------------------------------

def test_budget_refusal_names_what_to_loosen():
    """The default scene over 30 000 s with its spin phase held absolutely (``phase_atol: 1e-6``: the attitude
    tolerance's meaning before issue 28) plans ~1.7e9 steps: refused (a SceneError: the CLI's one error line, status
    2) in one line that names the tolerance that would fit (the phase relative to itself), the duration that would,
    and force; force=True makes the Runner (the run itself is the test above). As shipped (phase relative) the same
    30 000 s fit the budget."""
    sc = load_scene("spinup_thin_shell", overrides={"accuracy": {"phase_atol": 1e-6}})
    with pytest.raises(StepBudgetError) as info:
        run(sc, duration=30000.0)
    msg = str(info.value)
    print(f"\n  {msg}")
    assert isinstance(info.value, SceneError) and "\n" not in msg
    assert "accuracy.phase_atol" in msg and "duration" in msg and "force" in msg
    assert info.value.planned > STEP_BUDGET == info.value.budget
    r = Runner(sc, 30000.0, force=True)
    assert r.sim.steps == 0 and r.T == 30000.0
    # the scene as shipped (what the message says) fits, and within the budget nothing is said
    Runner(load_scene("spinup_thin_shell"), 30000.0)
    # a tolerance the plan can loosen: the attitude of a triaxial body (no spin phase apart) at an absurd rtol
    tri = load_scene("free_rotor", overrides={"accuracy": {"rtol": 1e-13, "attitude": 1e-13},
                                              "output": {"rate": 1e-3}})
    with pytest.raises(StepBudgetError, match="accuracy.attitude"):
        Runner(tri, 1e6)
    steps, stops = planned_work(Simulator(sc, quiet=True), 60.0, 0.02)
    assert 1e4 < steps < 1e7 and stops == pytest.approx(60 * 50 + 2 + 60 / 0.02 + 1)


def test_budget_counts_output_samples_before_allocating_them():
    """A duration of 1e12 s asks for 5e13 output samples (an output grid of 400 TB): refused at once, naming
    output.rate, before any array is made (by the result's memory bound, checked before the step plan since issue
    29: scene.check_result_size)."""
    sc = load_scene("free_rotor")
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match="output.rate"):
        Runner(sc, 1e12)
    assert time.perf_counter() - t0 < 30.0


def test_budget_message_names_rtol_where_only_rtol_binds():
    """Where the attitude is not a result (output.attitude false on an isotropic rotor) the message names rtol."""
    sc = load_scene("spinup_thin_shell", overrides={"rotor.inertia": [5.6e-6] * 3, "output.attitude": False,
                                                    "controller": None, "accuracy": {"rtol": 1e-12}})
    sim = Simulator(sc, horizon=3e4, quiet=True)
    with pytest.raises(StepBudgetError) as info:
        check_budget(sim, 3e4, None, budget=min(STEP_BUDGET, 0.3 * sim.planned_steps()))
    msg = str(info.value)
    print(f"\n  {msg}")
    assert "accuracy.rtol" in msg and "accuracy.attitude" not in msg


# --- the same bits, however the stepper calls are cut -------------------------------------------------------

@pytest.mark.parametrize("name, overrides, duration", [
    ("spinup_thin_shell", None, 1.0),  # frozen_flow, the compiled tick loop
    ("spinup_thin_shell", {"torque_model": "quasi_static"}, 0.5),  # qs_flow
    ("three_stators", None, 0.3),  # lawson8
    ("constant_field", None, 0.3),  # etdrk4 / lawson8 held at tau
    ("free_rotor", None, 1.0),  # the free stepper
    ("spinup_thin_shell", {"rotor.inertia": [5.6e-6] * 3, "output.attitude": False, "controller": None}, 0.5),
])
def test_results_do_not_depend_on_where_the_stepper_calls_are_cut(monkeypatch, name, overrides, duration):
    """A run whose stepper calls are cut every 1 to 5 steps (resumed at the same stop, step and span start) gives
    the very bits of a run with calls of thousands of steps: the states, the torques, the step count and the
    error estimate."""
    def go():
        r = run(load_scene(name, overrides=overrides), duration=duration)
        return r, np.concatenate([r.L.ravel(), r.q.ravel(), r.torque.ravel(), r.modes.ravel()])

    ref, a = go()
    monkeypatch.setattr(steppers, "CALL_STEPS", (3, 1, 5))
    monkeypatch.setattr(steppers, "CALL_WALL", 1e-9)
    cut, b = go()
    assert cut.steps == ref.steps > 10
    assert a.tobytes() == b.tobytes()
    assert (cut.error_estimate.L, cut.error_estimate.attitude) == (ref.error_estimate.L, ref.error_estimate.attitude) \
        or np.isnan(ref.error_estimate.attitude) and cut.error_estimate.L == ref.error_estimate.L


def test_a_long_advance_returns_to_python_between_calls(monkeypatch):
    """One advance over many steps is made of several stepper calls (the signal handlers run between them), each of
    at most ``call_steps`` steps, and ends at the same state as one call."""
    sc = load_scene("free_rotor")
    calls = []
    from gyro_sim.compiled import kernels

    real = kernels.integrate_free

    def counted(*a):
        k_out, steps = real(*a)
        calls.append(steps)
        return k_out, steps

    one = Simulator(sc, quiet=True)
    one.call_steps = 1 << 40
    one.advance(2.0)
    many = Simulator(sc, quiet=True)
    many.call_steps = 7
    monkeypatch.setattr(steppers, "tune_call", lambda n, wall, steps: n)  # (7 steps a call)
    monkeypatch.setattr(kernels, "integrate_free", counted)
    many.advance(2.0)
    assert many.steps == one.steps == sum(calls) > 20 and max(calls) == 7 and len(calls) == -(-one.steps // 7)
    assert many.y.tobytes() == one.y.tobytes() and many.t == one.t
