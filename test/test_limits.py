"""Issue 29, nothing absurd gets through: the physical limits of a scene (gyro_sim/scenes/limits.py) refuse absurd
values in scene files, in-process commands, ROS command messages and the laws' parameters, in one line naming the
field, the value and the limit, the state unchanged; and a run whose state breaks anyway fails loudly
(Runner.failure: the summary, the bag's end, the CLI's exit status 1, no error estimate).

The property-based part (random scenes and commands run to their end) is test/test_fuzz_limits.py.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import gyro_sim
from gyro_sim.apps import cli
from gyro_sim.engine import runner as runner_mod
from gyro_sim.engine.runner import Runner
from gyro_sim.engine.simulate import drive, run
from gyro_sim.engine.simulator import Simulator
from gyro_sim.io.bag_reader import bag_info
from gyro_sim.io.recording import record_run
from gyro_sim.io.results import read_bag
from gyro_sim.scenes.limits import (FIELD_FLOOR, LIMIT_MARGIN, MAX_FIELD, MAX_INERTIA_RATIO, MAX_RATE, RATE_FLOOR,
                                    stator_limits)
from gyro_sim.scenes.scene import SceneError, load_scene


def one_line(exc) -> str:
    text = str(exc)
    assert "\n" not in text and len(text) < 400, text
    return text


# --- scene values ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("key,value,fragments", [
    # the scene that ran to |L| = 4.9e44 with exit status 0
    ("stators.2.current", 1e6, ["stators.2.current = 1e+06 A", "MAX_FIELD = 100 T"]),
    # the three that raised OverflowError in step_control._spt_for
    ("stators.2.rate", 1e300, ["stators.2.rate = 1e+300 rad/s", "MAX_RATE"]),
    ("initial.spin", 1e300, ["initial.spin = 1e+300", "MAX_RATE"]),
    ("controller.params.target_spin", -1e308, ["controller.params.target_spin = -1e+308 rad/s", "MAX_RATE"]),
    # the rotor that planned 1.5e13 steps (refused by the step budget since issue 28; now by its shape)
    ("rotor.inertia", [1e-15, 1e6, 1e6], ["rotor.inertia", "J_max/J_min = 1e+21", "rotor.max_inertia_ratio"]),
    ("stators.2.coil_constant", 1e300, ["stators.2.current = 1 A", "1e+300 T", "MAX_FIELD"]),
    ("field", [{"real": [0, 0, 1e3]}], ["field.0", "1000 T", "MAX_FIELD"]),
    ("stators.2.max_current", 1.0e9, ["stators.2.max_current = 1e+09 A", "MAX_FIELD"]),
    ("stators.2.max_current", 0.5, ["stators.2.current = 1 A: beyond 0.5 A", "(stators.2.max_current)"]),
    ("stators.2.max_rate", 100.0, ["stators.2.rate = 3141.59 rad/s: beyond 100 rad/s", "(stators.2.max_rate)"]),
    ("controller.params.current", 1e5, ["controller.params.current = 100000 A", "200 T", "MAX_FIELD"]),
])
def test_absurd_scene_values_are_refused_in_one_line(key, value, fragments):
    with pytest.raises(SceneError) as err:
        load_scene("spinup_thin_shell", overrides={key: value})
    text = one_line(err.value)
    for f in fragments:
        assert f in text, text


def test_explicit_limits_lift_the_defaults_up_to_the_absolute_ones():
    """The defaults derive from the scene (10x its largest field and rate, floors 0.1 T and 1e4 rad/s); a stator's
    max_current / max_rate and the rotor's max_inertia_ratio override them."""
    s = load_scene("spinup_thin_shell")
    cur, rate = stator_limits(s)
    # 2 mT at 1 A: 10 x 2 mT < the 0.1 T floor -> 0.1 T / 2e-3 T/A = 50 A; 10 x 3141.6 rad/s > the 1e4 floor
    assert np.allclose(cur, FIELD_FLOOR / 2e-3) and np.allclose(rate, LIMIT_MARGIN * 3141.592653589793)
    assert RATE_FLOOR < rate[0] < MAX_RATE
    s = load_scene("spinup_thin_shell", overrides={"stators.2.max_current": MAX_FIELD / 2e-3, "stators.2.max_rate": 1e6,
                                                   "rotor.max_inertia_ratio": 1e22})
    cur, rate = stator_limits(s)
    assert cur[2] == MAX_FIELD / 2e-3 and rate[2] == 1e6 and cur[0] == FIELD_FLOOR / 2e-3
    assert load_scene("spinup_thin_shell", overrides={"rotor.inertia": [1e-15, 1e6, 1e6],
                                                      "rotor.max_inertia_ratio": 1e22}).rotor.inertia[0] == 1e-15
    assert MAX_INERTIA_RATIO == 1e4


def test_absurd_inertia_is_refused_in_one_line_before_any_work(tmp_path):
    """The issue's scene (inertia [1e-15, 1e6, 1e6], one stator, 1 s), run by the CLI: one ``error:`` line naming
    rotor.inertia and the ratio, exit status 2, nothing recorded (its budget and SIGINT: test_budget.py)."""
    path = tmp_path / "absurd.yaml"
    path.write_text("rotor:\n  inertia: [1.0e-15, 1.0e6, 1.0e6]\n  conductor: {kind: thin_shell, outer_radius: 0.025, "
                    "thickness: 0.001, conductivity: 2.5e7}\nstators:\n  - {name: z3, axis: [0, 0, 1], coil_constant: "
                    "2.0e-3, current: 1.0, rate: 3141.592653589793}\nduration: 1.0\n")
    code = cli.main(["run", str(path), "--record", str(tmp_path / "bag"), "--out", str(tmp_path / "runs"), "--quiet"])
    assert code == 2 and not (tmp_path / "bag").exists()


# --- commands ----------------------------------------------------------------------------------------------------

def test_huge_command_in_process_is_refused_and_the_state_is_unchanged():
    """The issue's case: set_stator('z3', current=1e5) at 0.5 s made L NaN. Now one ValueError naming the stator,
    the value and the limit; nothing changed, and the run goes on sound."""
    sim = gyro_sim.Simulator(gyro_sim.load_scene("spinup_thin_shell"))
    sim.advance(0.5)
    L, y, cur = sim.L, sim.y.copy(), sim.current.copy()
    with pytest.raises(ValueError) as err:
        sim.set_stator("z3", current=1e5)
    text = one_line(err.value)
    assert "'z3'" in text and "current = 100000 A" in text and "50 A" in text and "max_current" in text
    with pytest.raises(ValueError, match=r"rate = 1e\+09 rad/s: beyond its largest field rate 31415.9 rad/s"):
        sim.set_stators({"z1": (1.0, None), "z3": (None, 1e9)})  # (refused whole: z1 is not changed either)
    assert np.array_equal(sim.y, y) and np.array_equal(sim.current, cur)
    sim.set_stator("z3", current=50.0)  # at the limit: taken
    sim.advance(1.0)
    assert np.all(np.isfinite(sim.L)) and np.linalg.norm(sim.L) > np.linalg.norm(L)


def joint_state(names, effort, velocity=()):
    return SimpleNamespace(name=list(names), effort=list(effort), velocity=list(velocity),
                           header=SimpleNamespace(stamp=SimpleNamespace(sec=1, nanosec=0)))


def test_ros_command_beyond_a_limit_is_refused_with_field_value_and_limit():
    """``JointState(name=['z3'], effort=[1e5])`` was accepted by the simulator node and made L NaN for good: the
    node's check (gyro_sim.ros.common.parse_command with the simulator's limits, as Loop.take calls it) refuses it;
    the node reports it on gyro/status at most once a second per kind (Loop.report_refusal)."""
    pytest.importorskip("rclpy")
    from gyro_sim.ros.common import MAX_REASON, parse_command

    sim = Simulator(load_scene("spinup_thin_shell"))
    limits = (sim.max_current, sim.max_rate)
    names = sim.stator_names
    cmd, why = parse_command(joint_state(["z3"], [1e5]), names, limits)
    assert cmd is None and len(why) <= MAX_REASON
    assert "effort[z3] = 100000: beyond 50 A, the largest current of stator 'z3'" in why, why
    cmd, why = parse_command(joint_state(["z1", "z3"], [1.0, 1.0], [0.0, -1e6]), names, limits)
    assert cmd is None and "velocity[z3] = -1e+06" in why and "31415.9 rad/s" in why, why
    cmd, why = parse_command(joint_state(["z3"], [50.0], [-31415.0]), names, limits)
    assert why == "" and cmd[1] == [50.0]


def test_ros_node_refuses_the_huge_command_and_runs_on(monkeypatch):
    """The simulator node's loop (in-process, no DDS): the huge command is refused, reported once, the run applies
    nothing of it and ends complete and finite."""
    pytest.importorskip("rclpy")
    from gyro_sim.ros import simulator_node as sn

    scene = load_scene("spinup_thin_shell", overrides={"controller": None, "duration": 0.2})
    reports = []
    loop = SimpleNamespace(runner=Runner(scene, attitude=True, control_period=0.01), names=None, refused=0,
                           refusals={}, status=lambda text, warn=False: reports.append(text))
    loop.names = list(loop.runner.sim.stator_names)
    take = sn.Loop.take.__get__(loop)
    loop.report_refusal = sn.Loop.report_refusal.__get__(loop)
    for _ in range(3):
        assert take(joint_state(["z3"], [1e5]), 0.0, 0, False) is False
    assert loop.refused == 3 and len(reports) == 1 and "refused command: effort[z3] = 100000" in reports[0]
    drive(loop.runner)
    assert loop.runner.failure is None and np.all(np.isfinite(loop.runner.sim.y[0:7]))


# --- a run that fails loudly --------------------------------------------------------------------------------------

def _poison_at(monkeypatch, t_bad: float) -> None:
    """Make the output samples after ``t_bad`` s hold a NaN in L, as a stepper that breaks writes them (the compiled
    tick loop and Runner.advance both hand their new samples to Runner._check_samples)."""
    check = Runner._check_samples

    def poisoned(self, sel, r):
        self.out_y[r][sel > t_bad, 0] = math.nan
        return check(self, sel, r)

    monkeypatch.setattr(Runner, "_check_samples", poisoned)


def test_a_run_whose_state_breaks_stops_and_says_so(monkeypatch):
    """A NaN state went on to the end: the result, the summary and the estimate looked valid. Now the run stops at the
    first broken sample: ``failure`` says what and when, the samples before it are all finite, no error estimate."""
    _poison_at(monkeypatch, 0.3)
    r = run(load_scene("spinup_thin_shell"), duration=1.0)
    assert r.failure is not None and r.failure.startswith("failed: the state is not finite (L")
    assert "at t = 0.32 s" in r.failure, r.failure  # (the first output sample after 0.3 s: 50 /s)
    assert r.t[-1] == pytest.approx(0.3) and np.all(np.isfinite(r.L)) and np.all(np.isfinite(r.q))
    assert r.error_estimate is None
    s = r.summary()
    assert s["failure"] == r.failure and math.isnan(s["error_L"])
    text = cli.format_summary("x", s)
    assert f"status            {r.failure}" in text and "estimated error" not in text


def test_energy_beyond_what_the_fields_can_drive_fails_the_run(monkeypatch):
    """|L| beyond L_limit (10 x J_max x twice the fastest rate the commands may set, J_max/J_min) fails the run: here
    the limit is lowered to 1e-4 N m s so the default scene's spin-up passes it within a second."""
    monkeypatch.setattr(runner_mod, "L_limit", lambda *a: 1e-4)
    r = run(load_scene("spinup_thin_shell"), duration=2.0)
    assert r.failure is not None and r.failure.startswith("failed: |L| = ") and "beyond the 0.0001 N m s" in r.failure
    assert np.linalg.norm(r.L[-1]) <= 1e-4 < float(r.failure.split("|L| = ")[1].split(" ")[0])


def test_huge_current_within_the_absolute_limit_runs_sound_or_fails_loudly():
    """20 T on the default rotor (1e4 A, explicit max_current): accepted (within MAX_FIELD), and its run either stays
    finite within L_limit or fails loudly; on main it ran to NaN with exit status 0 (or |L| = 4.9e44 at 1e6 A)."""
    s = load_scene("spinup_thin_shell", overrides={"controller": None, "duration": 2.0, "stators.2.current": 1e4,
                                                   "stators.2.max_current": 1e4})
    r = Runner(s)
    drive(r)
    res = r.result()
    assert np.all(np.isfinite(res.L))
    if res.failure is None:
        assert np.max(np.linalg.norm(res.L, axis=1)) <= r.L_sound and res.error_estimate is not None
    else:
        assert res.failure.startswith("failed: ") and " at t = " in res.failure and res.error_estimate is None
    print(f"\n  20 T on the default rotor: {res.failure or 'sound'}")


def test_cli_and_bag_say_failed_and_exit_1(monkeypatch, tmp_path, capsys):
    """``gyro-sim run --record``: exit status 1, the summary's status row and one ``error:`` line, the bag's end
    ``failed: …`` with no error estimate; read back, the RunResult carries the failure too."""
    _poison_at(monkeypatch, 0.3)
    bag = tmp_path / "bag"
    code = cli.main(["run", "spinup_thin_shell", "--duration", "1", "--record", str(bag), "--out",
                     str(tmp_path / "runs"), "--quiet"])
    out, err = capsys.readouterr()
    assert code == 1, (out, err)
    assert "status            failed: the state is not finite (L" in out
    assert [x for x in err.splitlines() if x.startswith("error:")] == [
        x for x in err.splitlines() if x.startswith("error: the run failed: the state is not finite")]
    info = bag_info(bag)
    assert info["end_reason"].startswith("failed: the state is not finite (L") and "at t = 0.32 s" in info["end_reason"]
    assert "gyro_sim.error_estimate" not in info["custom"]
    back = read_bag(bag)
    assert back.failure == info["end_reason"] and back.error_estimate is None and np.all(np.isfinite(back.L))
    r = record_run(load_scene("spinup_thin_shell"), tmp_path / "bag2", duration=1.0)  # (the Python API: the same)
    assert r.failure == info["end_reason"] and r.error_estimate is None
