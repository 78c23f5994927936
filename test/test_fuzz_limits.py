"""Issue 29, fuzzing: property-based tests (hypothesis) over the scene schema and the commands, run to their end.

* Scenes: built-in scenes with numbers replaced by extreme magnitudes (1e-300 … 1e308, huge integers, NaN, ±inf,
  scaled by 10^±20), the physical limits' keys set, names and descriptions in any unicode. Each example loads and
  runs (0.02 s at most) or is refused with the project's error (a SceneError; a StepBudgetError where its plan
  passes the fuzz budget): no other exception, no hang (every run within :data:`FUZZ_BUDGET` steps and stops of
  the plan), and no non-finite state without a ``failed`` status.
* Commands: a running scene commanded at its control ticks with random currents and rates (in-process through
  ``Runner.apply_commands`` / ``Simulator.set_stators``, and as ``gyro/stator_commands`` messages through the simulator
  node's check, :func:`gyro_sim.ros.common.parse_command`, then applied as its loop does): a command is taken or
  refused with one ValueError line (the node: a reason), and the run ends sound or failed.

The structural fuzzing of the scene text (mutated documents, random YAML, bytes; malformed messages) is
test_hostile.py. Default: :data:`SCENE_EXAMPLES` + :data:`COMMAND_EXAMPLES` examples, derandomized (the same in CI);
``pytest --fuzz-long`` runs :data:`LONG` times as many, randomized.
"""
from __future__ import annotations

import copy
import math
import warnings
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyro_sim.engine import budget as budget_mod
from gyro_sim.engine.runner import Runner
from gyro_sim.engine.simulate import run
from gyro_sim.scenes.scene import SceneError, builtin_scenes, load_scene, scene_from_dict
from gyro_sim.scenes.scene_text import parse_scene_text
from gyro_sim.scenes.step_control import StepBudgetError

#: steps + stops a fuzzed run's plan may take (the step budget of gyro_sim/engine/budget.py, lowered): no example
#: runs for long whatever its values
FUZZ_BUDGET = 2e4
#: simulated s a fuzzed scene runs at most
RUN_T = 0.02
SCENE_EXAMPLES = 150
COMMAND_EXAMPLES = 150
LONG = 20  # --fuzz-long: this many times the examples
MAX_MESSAGE = 4000  # characters of a SceneError (MAX_ERRORS lines of at most MAX_ERROR_LINE)

BASES = [parse_scene_text(builtin_scenes()[n].read_text()) for n in
         ("spinup_thin_shell", "spinup_solid_sphere", "nutation_oblate", "free_rotor", "three_stators")]

EXTREME = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 5e-324, 1e-300, 1e-15, 1e-6, 1e3, 1e6, 1e7, 1.0000001e7, 1e9, 1e15, 1e30, 1e300,
                     1.7976931348623157e308, -1e308, -1e6, 10 ** 400, -(10 ** 30), math.nan, math.inf, -math.inf]),
    st.floats(-1e4, 1e4),
    st.integers(-10 ** 6, 10 ** 6),
)
#: keys of the physical values (currents, rates, spins, moments, fields): half of the edits go to a number below one
PHYSICAL = {"current", "rate", "spin", "inertia", "coil_constant", "target_spin", "nu", "spin_rate", "frequency",
            "kinetic_moment", "control_current", "spin_current", "real"}
LIMIT_KEYS = (("stators", "max_current"), ("stators", "max_rate"), ("rotor", "max_inertia_ratio"))


def _numbers(x, prefix=()):
    """Paths (keys and indexes) of the numbers in a document."""
    if isinstance(x, bool):
        return []
    if isinstance(x, (int, float)):
        return [prefix]
    if isinstance(x, dict):
        return [p for k, v in x.items() for p in _numbers(v, prefix + (k,))]
    if isinstance(x, list):
        return [p for i, v in enumerate(x) for p in _numbers(v, prefix + (i,))]
    return []


def _set(doc, path, value):
    parent = doc
    for part in path[:-1]:
        parent = parent[part]
    parent[path[-1]] = value


def _get(doc, path):
    for part in path:
        doc = doc[part]
    return doc


@st.composite
def extreme_scenes(draw):
    """A built-in scene with 1-4 numbers replaced by extreme values or scaled by 10^±3 or 10^±20, maybe a physical
    limit set to an extreme value, maybe its name, description and a stator's name in random unicode."""
    doc = copy.deepcopy(draw(st.sampled_from(BASES)))
    doc["duration"] = draw(st.one_of(st.just(RUN_T), st.just(RUN_T), EXTREME))
    for _ in range(draw(st.integers(1, 4))):
        paths = _numbers(doc)
        physical = [p for p in paths if any(str(k) in PHYSICAL for k in p)]
        path = draw(st.sampled_from(physical if physical and draw(st.booleans()) else paths))
        if draw(st.booleans()):
            _set(doc, path, draw(EXTREME))
        else:
            v = _get(doc, path)  # (a huge integer drawn before stays as it is)
            if isinstance(v, float) or abs(v) < 1e300:
                _set(doc, path, v * 10.0 ** draw(st.one_of(st.integers(-3, 3), st.integers(-20, 20))))
    if draw(st.booleans()):
        section, key = draw(st.sampled_from(LIMIT_KEYS))
        if section == "rotor":
            doc["rotor"][key] = draw(EXTREME)
        elif doc.get("stators"):
            doc["stators"][draw(st.integers(0, len(doc["stators"]) - 1))][key] = draw(EXTREME)
    if draw(st.integers(0, 3)) == 0:
        doc["name"], doc["description"] = draw(st.text(max_size=30)), draw(st.text(max_size=60))
        if doc.get("stators") and draw(st.booleans()):
            doc["stators"][0]["name"] = draw(st.text(min_size=1, max_size=8))
    return doc


def _fuzz_settings(request, n: int):
    if request.config.getoption("--fuzz-long"):
        return settings(max_examples=LONG * n, deadline=None, database=None,
                        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                               HealthCheck.filter_too_much])
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])


def _sound(res) -> str:
    """'ran' (every sample finite) or 'failed' (a run that stopped with its failure; the samples before it finite);
    a non-finite state without a failure fails the test."""
    att = res.attitude and not res.averaged_segments
    finite = np.all(np.isfinite(res.L)) and (not att or np.all(np.isfinite(res.q)))
    assert finite, f"non-finite state without a failed status (failure {res.failure!r})"
    if res.failure is not None:
        assert res.failure.startswith("failed: ") and " at t = " in res.failure and res.error_estimate is None
        return "failed"
    return "ran"


def _outcome(doc) -> str:
    try:
        scene = scene_from_dict(doc, where="fuzz.yaml")
    except SceneError as e:
        assert len(str(e)) <= MAX_MESSAGE, str(e)
        return "refused at load"
    try:
        res = run(scene, duration=min(scene.duration, RUN_T))
    except StepBudgetError as e:
        assert "\n" not in str(e)
        return "over the fuzz budget"
    except SceneError as e:  # (a run's own refusal, e.g. a duration whose samples pass the result's memory)
        assert len(str(e)) <= MAX_MESSAGE, str(e)
        return "refused at run"
    return _sound(res)


def test_fuzz_extreme_scenes(request, monkeypatch):
    """Scenes with extreme magnitudes, NaN/inf, huge integers and unicode: loaded and run (soundly or failed), or
    refused with the project's error; never another exception, never a plan beyond FUZZ_BUDGET."""
    monkeypatch.setattr(budget_mod, "STEP_BUDGET", FUZZ_BUDGET)
    tally: Counter = Counter()

    @_fuzz_settings(request, SCENE_EXAMPLES)
    @given(doc=extreme_scenes())
    def check(doc):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tally[_outcome(doc)] += 1

    check()
    print(f"\n  outcomes: {dict(sorted(tally.items()))}")
    assert tally["refused at load"] and tally["ran"]


# --- commands ------------------------------------------------------------------------------------------------------

SCENE = load_scene("spinup_thin_shell", overrides={"controller": None, "duration": 0.06})
NAMES = ["z1", "z2", "z3"]
VALUE = st.one_of(EXTREME, st.floats(0, 60), st.floats(-4e4, 4e4))


def joint_state(names, effort, velocity):
    return SimpleNamespace(name=names, effort=effort, velocity=velocity,
                           header=SimpleNamespace(stamp=SimpleNamespace(sec=0, nanosec=0)))


@st.composite
def command_lists(draw):
    """Commands for the ticks of a run: each a few stators (known or not) with a current and maybe a rate."""
    out = []
    for _ in range(draw(st.integers(1, 6))):
        names = draw(st.lists(st.sampled_from(NAMES + ["z9"]), min_size=0, max_size=3, unique=True))
        cur = [draw(VALUE) for _ in names]
        rate = [draw(VALUE) for _ in names] if draw(st.booleans()) else []
        out.append((names, cur, rate))
    return out


def _command_run(commands, over_ros: bool, tally: Counter) -> str:
    r = Runner(SCENE, control_period=0.01, estimate=False)
    if over_ros:
        from gyro_sim.ros.common import MAX_REASON, parse_command
    todo = list(commands)
    while not r.done:
        if r.row > 0 and r.is_control_tick and todo:
            names, cur, rate = todo.pop(0)
            before = (r.sim.y.copy(), r.sim.current.copy(), r.sim.rate.copy())
            if over_ros:  # the simulator node: its check, then Loop.apply
                cmd, why = parse_command(joint_state(names, cur, rate), NAMES, (r.sim.max_current, r.sim.max_rate))
                if cmd is None:
                    assert why and len(why) <= MAX_REASON and "\n" not in why
                    tally["refused (node)"] += 1
                else:
                    nm, c, v, _ = cmd
                    r.apply_commands({n: (c[i], v[i] if v is not None else None) for i, n in enumerate(nm)})
                    tally["taken (node)"] += 1
            else:
                try:
                    r.apply_commands({n: (cur[i], rate[i] if rate else None) for i, n in enumerate(names)})
                    tally["taken"] += 1
                except ValueError as e:
                    assert "\n" not in str(e) and len(str(e)) < 400
                    tally["refused"] += 1
                    after = (r.sim.y, r.sim.current, r.sim.rate)
                    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(before, after, strict=True))
        r.advance()
    return _sound(r.result())


def test_fuzz_commands_to_a_running_scene(request):
    """Random commands (extreme values, NaN/inf, unknown stators) to a running default scene, in-process and as the
    simulator node checks and applies its messages: taken or refused (one line, nothing changed); the run ends with
    a finite state or says it failed."""
    tally: Counter = Counter()

    @_fuzz_settings(request, COMMAND_EXAMPLES)
    @given(commands=command_lists(), over_ros=st.booleans())
    def check(commands, over_ros):
        if over_ros:
            pytest.importorskip("rclpy")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tally["run " + _command_run(commands, over_ros, tally)] += 1

    check()
    print(f"\n  outcomes: {dict(sorted(tally.items()))}")
    assert tally["refused"] and tally["taken"] and tally["run ran"]
