"""Control ticks in compiled code (issue 23): the built-in laws written once in compiled form give the commands of
the Python laws they replaced, and in-process runs through the compiled tick loop (gyro_sim/engine/ticks.py) give the
break-by-break Python loop's numbers bit for bit (every array, the commands, the steps, the error estimate), with
the Python loop entered a few times per run instead of at every tick. A law put in ``LAWS`` in Python still runs,
at every tick."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gyro_sim
from gyro_ctl import laws
from gyro_ctl.config import ControllerConfig
from gyro_sim.engine import simulate
from gyro_sim.engine.ticks import python_ticks

NAMES = ("z1", "z2", "z3")
AXES = np.eye(3)


# --- the Python laws before issue 23 (gyro_ctl/laws.py of commit 5e6310d), the oracle of the compiled ones --------
def _ref_theta(x):
    n = float(np.linalg.norm(x.L))
    if n == 0.0:
        return 0.0
    x3 = x.polar_axis
    return math.atan2(float(np.linalg.norm(np.cross(x3, x.L))), float(x3 @ x.L))


def _ref_transverse_unit(x):
    n = float(np.linalg.norm(x.L))
    if n == 0.0:
        return None
    y3 = x.L / n
    x3 = x.polar_axis
    v = x3 - y3 * float(x3 @ y3)
    s = float(np.linalg.norm(v))
    return None if s == 0.0 else v / s


def _ref_spinup(x, p):
    current = p.current if p.ramp is None else min(p.current, p.ramp * x.t)
    return {p.stator: (current, p.target_spin)}


def _ref_psi_switching(x, p):
    out = {p.spin_stator: (p.spin_current, p.spin_rate)}
    th = _ref_theta(x)
    e = _ref_transverse_unit(x)
    if e is None or th < p.dead_band or math.pi - th < p.dead_band:
        for i, name in enumerate(p.control_stators):
            out[name] = (0.0, p.rate(i))
        return out
    for i, name in enumerate(p.control_stators):
        s = float(x.axis(name) @ e)
        out[name] = (p.control_current, p.rate(i) if s >= 0.0 else -p.rate(i))
    return out


def _ref_limited(commands, current_limit, rate_limit):
    if current_limit is None and rate_limit is None:
        return commands
    out = {}
    for n, (c, r) in commands.items():
        if c is not None and current_limit is not None:
            c = min(max(c, 0.0), current_limit)
        if r is not None and rate_limit is not None:
            r = min(max(r, -rate_limit), rate_limit)
        out[n] = (c, r)
    return out


_REF = {"spinup": _ref_spinup, "psi_switching": _ref_psi_switching,
        "off": lambda x, p: {n: (0.0, None) for n in x.stator_names}, "hold": lambda x, p: {},
        "manual": lambda x, p: {n: (c.current, c.rate) for n, c in p.commands.items()}}

CONFIGS = [
    ControllerConfig(law="psi_switching", params=dict(nu=[4000.0, 10000.0], control_current=0.066,
                                                      spin_current=0.47, spin_rate=200.0)),
    ControllerConfig(law="psi_switching", current_limit=0.05, rate_limit=5000.0,
                     params=dict(control_stators=["z2", "z3"], spin_stator="z1", nu=-3000.0, control_current=0.3,
                                 spin_current=0.5, spin_rate=-7000.0, dead_band=0.2)),
    ControllerConfig(law="spinup", params=dict(target_spin=100.0, current=2.0, ramp=0.7), current_limit=1.5),
    ControllerConfig(law="spinup", params=dict(stator="z1", target_spin=-300.0, current=1.0), rate_limit=200.0),
    ControllerConfig(law="off", params={}, current_limit=0.3),
    ControllerConfig(law="hold", params={}),
    ControllerConfig(law="manual", current_limit=2.0, rate_limit=5.0,
                     params={"commands": {"z2": {"current": 1.0, "rate": -3.0}, "z1": {"current": 3.0, "rate": 9.0}}}),
]


def _unit(v):
    return v / np.linalg.norm(v)


_vec = st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=3, max_size=3).map(np.array)
_quat = st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4).map(np.array).filter(
    lambda q: np.linalg.norm(q) > 1e-3).map(_unit)


@st.composite
def states(draw):
    """(t s, L N·m·s, q): L of any size (0 included), along the polar axis or a hair off it (the dead band and an
    undefined e⊥), or anywhere."""
    q = draw(_quat)
    kind = draw(st.sampled_from(["any", "pole", "near pole", "zero"]))
    scale = 10.0 ** draw(st.floats(-8, 2))
    x3 = laws.ControlInput(t=0.0, L=np.zeros(3), q=q, omega_b=np.zeros(3), stator_names=NAMES,
                           stator_axes=AXES).polar_axis
    if kind == "zero":
        L = np.zeros(3)
    elif kind == "pole":
        L = scale * x3 * draw(st.sampled_from([1.0, -1.0]))
    elif kind == "near pole":
        L = scale * (x3 * draw(st.sampled_from([1.0, -1.0])) + 10.0 ** draw(st.floats(-12, -1)) * draw(_vec))
    else:
        L = scale * draw(_vec)
    return draw(st.floats(0.0, 100.0)), L, q


@pytest.mark.parametrize("cfg", CONFIGS, ids=[f"{c.law}{i}" for i, c in enumerate(CONFIGS)])
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(state=states())
def test_compiled_law_gives_the_python_laws_commands(cfg, state):
    """The compiled law (make_law, and the law function of LAWS) equals the Python law it replaced on random states:
    the same stators in the same order, the same currents and rates (None where unchanged)."""
    t, L, q = state
    x = laws.ControlInput(t=t, L=L, q=q, omega_b=np.zeros(3), stator_names=NAMES, stator_axes=AXES)
    want = _ref_limited(_REF[cfg.law](x, cfg.params), cfg.current_limit, cfg.rate_limit)
    law = laws.make_law(cfg)
    assert isinstance(law, laws.CompiledLaw)
    got = law(x)
    assert list(got) == list(want) and got == want
    assert laws.LAWS[cfg.law](x, cfg.params) == _REF[cfg.law](x, cfg.params)


def test_limited_clips_like_before():
    """limited() (now the compiled clip) keeps None fields and clips like min(max(c, 0), limit)."""
    cmds = {"a": (-1.0, 5000.0), "b": (None, -9000.0), "c": (3.0, None), "d": (0.5, 10.0)}
    for cl, rl in ((None, None), (2.0, None), (None, 4000.0), (2.0, 4000.0), (0.0, 0.0)):
        assert laws.limited(cmds, cl, rl) == _ref_limited(cmds, cl, rl)


# --- runs: the compiled tick loop against the break-by-break Python loop -----------------------------------------
def _same(a, b) -> list:
    """What differs between two RunResults (every array to the bit, the commands, steps, estimate)."""
    bad = []
    for n in ("t", "L", "q", "omega_b", "torque", "energy", "current", "field_rate", "field_phase", "modes", "euler"):
        x, y = getattr(a, n), getattr(b, n)
        if not (x.shape == y.shape and np.array_equal(x, y, equal_nan=True)):
            bad.append(n)
    for n in ("commands", "steps", "error_estimate", "averaged_segments"):
        if getattr(a, n) != getattr(b, n):
            bad.append(n)
    return bad


def _counted_advances(monkeypatch) -> list:
    """Calls of Runner.advance (the Python loop's step) from now on: one item each."""
    calls = []
    orig = simulate.Runner.advance

    def counted(self, until=None):
        calls.append(1)
        return orig(self, until=until)

    monkeypatch.setattr(simulate.Runner, "advance", counted)
    return calls


OFF_LAW = {"controller": {"law": "off", "period": 0.02, "params": {}}}
MANUAL_WITH_COMMANDS = {"controller": {"law": "manual", "period": 0.01, "rate_limit": 2000.0,
                                      "params": {"commands": {"z3": {"current": 1.0, "rate": 3000.0}}}},
                        "commands": [{"time": 0.5, "stator": "z3", "current": 0.5},
                                     {"time": 0.75, "stator": "z1", "current": 0.2, "rate": 100.0}]}
RUNS = [
    # (scene, overrides, duration s, run() keywords)
    ("spinup_thin_shell", {}, 6.0, {}),  # spin-up, frozen_flow steps shorter than the ticks, shadow
    ("spinup_thin_shell", {"accuracy": {"attitude": None}}, 60.0, {}),  # steps as long as the ticks
    ("spinup_thin_shell", {"controller.params.ramp": 0.5, "controller.current_limit": 0.8}, 3.0, {}),  # reads t
    ("spinup_thin_shell", OFF_LAW, 4.0, {}),  # rates left unchanged (None)
    ("spinup_thin_shell", MANUAL_WITH_COMMANDS, 1.0, {}),  # scene commands between ticks, law undoing them
    ("spinup_thin_shell", {}, 1.0, {"estimate": False}),  # no shadow
    ("nutation_oblate", {}, 0.5, {}),  # ψ-switching every 1 ms
    ("nutation_oblate", {"controller.period": 0.004, "output.rate": 1000.0}, 0.5, {}),  # samples between ticks
    # [K] averaged, then the full model (lawson8)
    ("nutation_slow", {"fidelity": "auto", "accuracy.rtol": 2e-3, "integrator.method": "lawson8"}, None, {}),
    # the quasi-static flow step (qs_flow) under ψ-switching and under the spin-up law: its ticks compiled since
    # issue 28 (the Python loop ran them: 3.2x the CPU on nutation_slow)
    ("nutation_slow", {}, 2.0, {}),
    ("spinup_thin_shell", {"torque_model": "quasi_static"}, 2.0, {}),
]


@pytest.mark.parametrize("name,overrides,duration,kw", RUNS, ids=[f"{r[0]}-{i}" for i, r in enumerate(RUNS)])
def test_compiled_ticks_give_the_python_loops_run_bit_for_bit(monkeypatch, name, overrides, duration, kw):
    """A run through the compiled tick loop equals the break-by-break Python loop's, every array to the bit, its
    commands (one per tick), steps and error estimate; the Python loop's Runner.advance runs a few times (the
    scene commands, the error control's checks, the end, the chunks' limits), not at every tick."""
    scene = gyro_sim.load_scene(name, overrides=overrides)
    with python_ticks():
        ref = gyro_sim.run(scene, duration=duration, **kw)
    calls = _counted_advances(monkeypatch)
    new = gyro_sim.run(scene, duration=duration, **kw)
    n_ticks = len(ref.commands)
    print(f"\n  {name}: {n_ticks} ticks, {len(calls)} Python advances, {new.steps} steps: identical")
    assert not _same(ref, new), _same(ref, new)
    assert n_ticks > 40 and len(calls) < n_ticks / 2


def test_checks_and_end_in_the_compiled_loop(monkeypatch):
    """The error control's checks and the end end a call of the compiled loop, the shadow following there (they
    went through Runner.advance one at a time: 25 Python advances on the default scene over 2 s, with the law
    evaluated in Python before each): now only the first sample takes Runner.advance, with or without a law."""
    for ov in ({}, {"controller": None}, {"torque_model": "quasi_static"}):
        scene = gyro_sim.load_scene("spinup_thin_shell", overrides=ov)
        calls = _counted_advances(monkeypatch)
        r = gyro_sim.run(scene, duration=2.0)
        assert r.error_estimate is not None and len(calls) == 1, (ov, len(calls))


@given(st.lists(st.sampled_from([0.0, -0.0, 0.1, 0.25, 1.0, 1e-300, 3.5, 7.0]), max_size=12),
       st.lists(st.sampled_from([0.0, 0.1, 0.3, 1.0, 2.0, 7.0]), max_size=6))
def test_sorted_union_and_holds_are_unique_and_isin(a, b):
    """The run's break sets (scenes.scene.sorted_union, engine.model.holds): np.unique's and np.isin's bits."""
    from gyro_sim.engine.model import holds
    from gyro_sim.scenes.scene import sorted_union

    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    u = sorted_union(a, b)
    ref = np.unique(np.concatenate([a, b]))
    assert u.tobytes() == ref.tobytes()
    assert np.array_equal(holds(a, u), np.isin(a, u)) and np.array_equal(holds(a, np.unique(b)), np.isin(a, b))


def test_on_samples_get_the_same_rows(monkeypatch):
    """With ``on_samples`` (the CLI's progress line: samples are breaks) the rows come in chunks; together they are
    the Python loop's rows, and the run is the same."""
    scene = gyro_sim.load_scene("nutation_oblate")
    got = {True: [], False: []}
    for compiled in (False, True):
        def take(s, out=got[compiled]):
            out.append(s)

        if compiled:
            new = gyro_sim.run(scene, duration=0.3, on_samples=take)
        else:
            with python_ticks():
                ref = gyro_sim.run(scene, duration=0.3, on_samples=take)
    assert not _same(ref, new)
    for key in ("t", "L", "q", "omega_b", "euler", "torque", "energy", "current", "rate", "phase"):
        a = np.concatenate([s[key] for s in got[False]])
        b = np.concatenate([s[key] for s in got[True]])
        assert np.array_equal(a, b), key
    assert len(got[True]) < len(got[False]) / 3


def test_streamed_run_in_a_small_buffer():
    """A streamed run (drive with release) whose output buffer holds 7 rows: every chunk fits it, and the rows and
    commands handed over are the Python loop's."""
    from gyro_sim.engine.simulate import Runner, drive

    scene = gyro_sim.load_scene("nutation_oblate")
    out = {}
    for compiled in (False, True):
        r = Runner(scene, 0.2, sample_breaks=True, attitude=True, buffer_rows=7)
        rows, cmds = [], []

        def take(s, r=r, rows=rows, cmds=cmds):
            assert s["t"].size <= 7
            rows.append({k: np.copy(v) for k, v in s.items() if k != "effects"})  # (views of the buffer)
            cmds.extend(r.take_commands())

        if compiled:
            drive(r, take, release=True)
        else:
            with python_ticks():
                drive(r, take, release=True)
        out[compiled] = (np.concatenate([s["L"] for s in rows]), np.concatenate([s["q"] for s in rows]),
                         np.concatenate([s["phase"] for s in rows]), cmds + r.take_commands(), r.sim.steps,
                         r.error_estimate())
    a, b = out[False], out[True]
    assert all(np.array_equal(x, y) for x, y in zip(a[:3], b[:3]))
    assert a[3:] == b[3:]


def test_recorded_bag_is_the_python_loops(tmp_path):
    """record_run (streamed, samples as breaks) writes the bag the Python loop writes: the same samples and commands."""
    from gyro_sim.io.recording import read_bag, record_run

    scene = gyro_sim.load_scene("nutation_oblate")
    with python_ticks():
        record_run(scene, tmp_path / "python", duration=0.3)
    record_run(scene, tmp_path / "compiled", duration=0.3)
    a, b = read_bag(tmp_path / "python"), read_bag(tmp_path / "compiled")
    for key in ("t", "L", "q", "omega_b", "euler", "torque", "current", "rate", "phase", "command_t",
                "command_current", "command_rate"):
        assert np.array_equal(getattr(a, key), getattr(b, key), equal_nan=True), key


def test_a_python_law_in_LAWS_runs_at_every_tick(monkeypatch):
    """A law replaced in gyro_ctl.laws.LAWS by a Python function (one that cannot compile) keeps the Python path: it
    is called at every tick with a ControlInput, and its commands drive the run (here the built-in spin-up's, so
    the run equals the compiled one bit for bit)."""
    scene = gyro_sim.load_scene("spinup_thin_shell")
    compiled = gyro_sim.run(scene, duration=2.0)
    seen = []

    def my_spinup(x, p):
        seen.append(x.t)
        return laws.spinup(x, p)

    monkeypatch.setitem(laws.LAWS, "spinup", my_spinup)
    assert not isinstance(laws.make_law(scene.controller), laws.CompiledLaw)
    mine = gyro_sim.run(scene, duration=2.0)
    assert len(seen) == len(compiled.commands) == 100 and seen == sorted(seen)
    assert not _same(compiled, mine)


def test_a_first_lawson8_segment_in_the_tick_loop(monkeypatch):
    """lawson8's table is made on first use (engine.model._tableau, re-exported by gyro_sim.engine.simulate): a
    process whose first lawson8 segment is taken by the compiled tick loop (nutation_slow at fidelity auto: its full-model stretch after the averaged one) ran into
    a KeyError there (`gyro-sim bench --only ticks` in a new process); it must build the table and give the Python
    loop's numbers."""
    from gyro_sim.engine import model  # (the table's home: a name re-exported by simulate is a copy of the reference)

    monkeypatch.setattr(model, "_TABLEAU", {})
    scene = gyro_sim.load_scene("nutation_slow", overrides={"fidelity": "auto", "accuracy.rtol": 2e-3,
                                                           "integrator.method": "lawson8"})
    a = gyro_sim.run(scene, duration=8.0)
    assert "lawson8" in model._TABLEAU
    monkeypatch.setattr(model, "_TABLEAU", {})
    with python_ticks():
        b = gyro_sim.run(scene, duration=8.0)
    print(f"\n  nutation_slow auto (rtol 2e-3), 8 s: {a.steps} steps, θ end {np.degrees(a.theta[-1]):.4f}°")
    assert a.steps == b.steps and np.array_equal(a.L, b.L) and np.array_equal(a.q, b.q)
