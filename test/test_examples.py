"""The controllers of examples/ (plain rclpy, separate processes) against a real simulator node process, in lockstep
with recording, checked from the bag; and docs/protocol.md against the topic contract and the node's parameters.

Each example runs as its own process, as a user runs it (nothing of gyro_sim or gyro_ctl imported); every process
gets the test's own ROS_DOMAIN_ID and localhost-only discovery (:class:`test_ros.Procs`). Nothing here bounds a
time: the runs are lockstep, and the waits end on what they wait for.
"""
import ast
import re

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

import gyro_sim  # noqa: E402
from gyro_sim.io.messages import QOS, TOPICS, node_topic, stamp_ns  # noqa: E402
from gyro_sim.io.recording import read_bag  # noqa: E402
from gyro_sim.io.rerun import rerun_bag  # noqa: E402
from test_ros import ROOT, finish, ros  # noqa: E402,F401  (ros: the fixture)

pytestmark = pytest.mark.ros
EXAMPLES = ROOT / "examples"
SPINUP = EXAMPLES / "spinup_controller.py"
PSI = EXAMPLES / "psi_switching_controller.py"


def done_line(status: list) -> str:
    lines = [s for s in status if s.startswith("done:")]
    assert lines, status
    return lines[-1]


def tick_stamps(period: float, duration: float) -> list:
    """The stamps (ns) of the control ticks of a run: k · period for k = 0, 1, ... before the end (as the node)."""
    return [stamp_ns(t) for t in np.arange(int(np.ceil(duration / period - 1e-9))) * period]


def check_lockstep_run(b, period: float, duration: float) -> None:
    """Every tick answered once by a valid command, nothing refused, no watchdog, the run complete."""
    ticks = tick_stamps(period, duration)
    done = done_line(b.status)
    assert f" {len(ticks)} control ticks" in done and " 0 commands refused" in done, done
    assert "(interrupted)" not in done, done
    assert not [s for s in b.status if s.startswith(("refused command", "watchdog"))], b.status
    applied = np.round(b.command_t * 1e9).astype(np.int64).tolist()
    assert applied == ticks, "not every tick got one command"
    assert b.t[-1] == pytest.approx(duration)


# --- the examples' own requirements ------------------------------------------------------------------------------

def test_spinup_example_is_at_most_60_lines():
    n = len(SPINUP.read_text().splitlines())
    print(f"\n  {SPINUP.name}: {n} lines")
    assert n <= 60


@pytest.mark.parametrize("path", [SPINUP, PSI], ids=lambda p: p.name)
def test_examples_import_nothing_from_the_project(path):
    """A user's controller: rclpy, message packages and the standard library only."""
    mods = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            mods |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            mods.add((node.module or "").split(".")[0])
    assert mods <= {"rclpy", "geometry_msgs", "sensor_msgs", "std_msgs", "math"}, mods
    cpp = (EXAMPLES / "cpp" / "gyro_controller.cpp").read_text()
    assert "gyro_sim" not in re.findall(r'#include\s+[<"]([^>"]+)', cpp)


# --- against the simulator ---------------------------------------------------------------------------------------

def test_spinup_example_spins_the_rotor_up_in_lockstep(ros, tmp_path):
    """The spin-up example, with a target and current of its own (1500 rad/s, 2 A: not the scene's), drives the
    default scene for 4 s: every tick answered, nothing refused, its values applied from t = 0, the spin rising
    monotonically toward the target; the run equals the in-process run of the project's spin-up law with the same
    values, and its bag re-runs bit-identically."""
    target, current, duration, period = 1500.0, 2.0, 4.0, 0.02
    text = (ROOT / "config" / "spinup_thin_shell.yaml").read_text()
    law = "params: {stator: z3, target_spin: 3141.592653589793, current: 1.0}"
    assert law in text and f"period: {period}" in text
    scene = tmp_path / "spinup_thin_shell.yaml"  # (the project's law with the example's values: the reference)
    scene.write_text(text.replace(law, f"params: {{stator: z3, target_spin: {target}, current: {current}}}"))
    bag = tmp_path / "spinup"
    sim = ros.simulator(scene=str(scene), duration=duration, record=bag, startup_timeout=120.0)
    ctl = ros.start(str(SPINUP), "--ros-args", "-p", f"target_spin:={target!r}", "-p", f"current:={current!r}")
    code, out = finish(sim)
    assert code == 0, out
    code, ctl_out = finish(ctl, 60)
    assert code == 0, ctl_out  # it exits by itself at the simulator's done: line
    b = read_bag(bag)
    check_lockstep_run(b, period, duration)
    z3 = b.stator_names.index("z3")
    assert np.all(b.command_current[:, z3] == current) and np.all(b.command_rate[:, z3] == target)
    # the state at t shows the field that acted up to t: the scene's at t = 0, the example's from the first tick on
    assert b.current[0, z3] == 1.0 and np.all(b.current[1:, z3] == current) and np.all(b.rate[1:, z3] == target)
    spin = b.omega_b[:, 2]
    print(f"\n  spin-up example, lockstep: Ω3 {spin[0]:.1f} → {spin[-1]:.1f} rad/s in {duration} s (target {target}); "
          f"{done_line(b.status)[:100]}...")
    assert np.all(np.diff(spin) > 0) and spin[-1] < target
    assert spin[-1] > 0.1 * target  # (about 0.18 target: the lag model's slip torque at 2 A)
    r = gyro_sim.run(gyro_sim.load_scene(str(scene)), duration=duration)
    for k in ("L", "q", "omega_b", "current"):
        assert np.array_equal(getattr(b, k), getattr(r, k)), k
    rep = rerun_bag(bag)
    assert rep["identical"], rep


def test_psi_switching_example_damps_the_nutation_like_the_projects_law(ros, tmp_path):
    """The ψ-switching example on nutation_oblate, lockstep, 1 s: θ from 10° to below 0.5°, every tick answered,
    nothing refused; its commands are the project's own law's ([K] (3.1), gyro_ctl.laws.psi_switching, run
    in-process by gyro_sim.run) tick for tick, so the whole run is identical bit for bit; the bag re-runs
    bit-identically."""
    duration, period = 1.0, 0.001
    bag = tmp_path / "psi"
    sim = ros.simulator(scene="nutation_oblate", duration=duration, record=bag, startup_timeout=120.0)
    ctl = ros.start(str(PSI))
    code, out = finish(sim)
    assert code == 0, out
    code, ctl_out = finish(ctl, 60)
    assert code == 0, ctl_out
    b = read_bag(bag)
    check_lockstep_run(b, period, duration)
    th = np.degrees(b.euler[:, 1])
    print(f"\n  ψ-switching example, lockstep: θ {th[0]:.2f}° → {th[-1]:.4f}° in {duration} s; "
          f"{done_line(b.status)[:100]}...")
    assert th[0] == pytest.approx(10.0) and th[-1] < 0.5
    # the law switched: both field directions of both control stators, the control currents on and (dead band) off
    col = {n: b.stator_names.index(n) for n in ("z1", "z2", "z3")}
    assert set(b.command_rate[:, col["z1"]]) == {3000.0, -3000.0}
    assert set(b.command_rate[:, col["z2"]]) == {5000.0, -5000.0}
    assert set(b.command_current[:, col["z1"]]) <= {0.0, 0.316} and 0.316 in b.command_current[:, col["z1"]]
    assert np.all(b.command_current[:, col["z3"]] == 0.5) and np.all(b.command_rate[:, col["z3"]] == 200.0)
    # the project's law, in-process: the same commands at the same ticks, the same currents at every sample
    r = gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=duration)
    assert len(r.commands) == len(b.command_t)
    for i, (t, names, cur, rate) in enumerate(r.commands):
        assert stamp_ns(t) == round(b.command_t[i] * 1e9), i
        for n, c, v in zip(names, cur, rate):
            assert (b.command_current[i, col[n]], b.command_rate[i, col[n]]) == (c, v), (t, n)
    assert r.stator_names == b.stator_names
    for k in ("current", "L", "q", "omega_b", "torque"):
        assert np.array_equal(getattr(b, k), getattr(r, k)), k
    rep = rerun_bag(bag)
    assert rep["identical"], rep


# --- the documentation ---------------------------------------------------------------------------------------------

def test_protocol_doc_names_the_whole_contract():
    """docs/protocol.md names every topic (as the nodes use them) with its QoS, every simulator parameter but the
    terminal's progress line, and every service; the examples' README points at it."""
    from gyro_sim.ros.simulator_node import PARAMETERS

    doc = (ROOT / "docs" / "protocol.md").read_text()
    for topic in TOPICS:
        assert f"`{node_topic(topic)}`" in doc, topic
        if QOS[topic]["durability"] == "transient_local":
            row = next(line for line in doc.splitlines() if line.startswith(f"| `{node_topic(topic)}`"))
            assert "transient local" in row and f"keep last **{QOS[topic]['depth']}**" in row, row
    for name, *_ in PARAMETERS:
        if name != "progress":
            assert f"`{name}`" in doc, name
    for srv in ("pause", "resume", "step", "reset"):
        assert f"`gyro/{srv}`" in doc, srv
    assert "```mermaid\nsequenceDiagram" in doc
    assert "docs/protocol.md" in (EXAMPLES / "README.md").read_text()
