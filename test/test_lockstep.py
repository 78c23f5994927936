"""Lockstep that holds under load (issue 30): a result that does not depend on the machine's load or on any
wall-clock timeout, a lost controller that fails the run, wrong stamps refused at once, a controller that ends
with the run. Real node processes over DDS, each test on its own ROS domain (see test_ros.py)."""
import json
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

from gyro_sim.io.recording import bag_info, read_bag  # noqa: E402
from test_ros import PROBE, PROBE_WINDOW, closed_loop, finish, ros  # noqa: E402,F401  (ros: the fixture)

pytestmark = pytest.mark.ros


@pytest.fixture
def hogs():
    """Two CPU-burning processes (one per core of the 2-core CI machine) for the test's duration."""
    from gyro_sim.apps.bench_ros import cpu_hogs

    with cpu_hogs(2) as procs:
        yield procs


@pytest.mark.parametrize("scene,duration", [("spinup_thin_shell", 2.0), ("nutation_oblate", 0.3)])
def test_lockstep_under_load_is_bit_identical(gyro_bench, hogs, scene, duration):
    """Two CPU hogs beside the nodes and a 1 ms watchdog_timeout (before: lockstep waited at most that long for
    each answer, then zeroed the currents: the result depended on the load): the bag equals the in-process run,
    every array, the commands included."""
    run, r = closed_loop(gyro_bench, scene, duration, watchdog_timeout=0.001)
    k = run.result
    for name in ("t", "L", "q", "omega_b", "current", "field_rate", "field_phase"):
        a, c = getattr(r, name), getattr(k, name)
        assert a.shape == c.shape and np.array_equal(a, c), f"{name}: differs from the in-process run"
    assert not [s for s in run.status if s.startswith(("watchdog", "controller lost"))], run.status
    f = run.figures
    print(f"\n  {scene} {duration:g} s in lockstep beside two CPU hogs: {len(k.t)} samples identical to the "
          f"in-process run; {f['ticks_per_s']:.0f} ticks/s, latency median {f['latency_median_ms']:.2f} ms")


def _children(pid: int) -> list:
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def test_a_killed_controller_fails_the_run(tmp_path):
    """SIGKILL to the controller of ``gyro-sim run --ros``: the run stops (on_controller_lost's default), the bag
    says ``failed: controller lost at t = ...`` and the launcher's status is non-zero (before: the simulator ran on
    with the currents zeroed, status 0, bag 'complete')."""
    from gyro_sim.testing import ros_env, unique_domain

    bag = tmp_path / "bag"
    env = dict(ros_env(unique_domain()), PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "gyro_sim.apps.cli", "run", "nutation_oblate", "--ros",
                          "--duration", "40", "--record", str(bag), "--out", str(tmp_path)], env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ctl, t0 = None, time.time()
        while time.time() - t0 < 120 and not (ctl and bag.exists()):  # the run has started
            ctl = next((c for c in _children(p.pid) if "gyro_ctl.ros.controller_node" in " ".join(c.cmdline())),
                       None)
            time.sleep(0.2)
        assert ctl is not None and bag.exists(), "the run did not start"
        time.sleep(1.0)
        ctl.kill()
        out, _ = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    info = bag_info(bag)
    lost = [s for s in read_bag(bag).status if s.startswith("controller lost")]
    print(f"\n  exit status {p.returncode}; bag end: {info['end_reason']}\n  {lost[0] if lost else out[-400:]}")
    assert p.returncode == 1, out
    assert info["end_reason"].startswith("failed: controller lost at t = "), info["end_reason"]
    assert lost and "its process ended" in lost[0] and "the run stops" in lost[0]
    assert info["end"] < 40.0


def test_a_controller_answering_stamp_zero_is_refused_at_once(ros, tmp_path):
    """A controller whose every answer is stamped 0: right at t = 0, refused from the first tick after it with a
    status line (before: dropped silently until the watchdog fired, the refusal came after)."""
    bag = tmp_path / "zero"
    sim = ros.simulator(scene="nutation_oblate", duration=0.2, record=bag, controller_timeout=3.0,
                        startup_timeout=120.0)
    ros.start(PROBE, "stamp_zero", "/", str(PROBE_WINDOW))
    code, out = finish(sim)
    b = read_bag(bag)
    warn = [(t, s) for t, s in zip(b.status_t, b.status, strict=True)
            if s.startswith(("refused", "controller lost", "watchdog"))]
    print("\n  " + "\n  ".join(f"t = {t:.3f} s: {s[:110]}" for t, s in warn[:3]))
    assert warn and warn[0][1].startswith("refused command: stamp = 0.000000000 s: lockstep waits for the command "
                                          "stamped 0.001000000 s"), warn
    assert warn[0][0] == pytest.approx(0.001)
    assert code == 1 and bag_info(bag)["end_reason"].startswith("failed: controller lost at t = 0.001 s"), out


def test_the_controller_node_ends_after_the_run(ros, tmp_path):
    """The project's controller started by hand exits 0 after the simulator's final done: line (before: it ran
    until stopped)."""
    sim = ros.simulator(scene="nutation_oblate", duration=0.05, startup_timeout=120.0)
    ctl = ros.controller(scene="nutation_oblate")
    code, out = finish(sim)
    assert code == 0, out
    code, text = finish(ctl, 60)
    print(f"\n  controller: exit {code}; {text.strip().splitlines()[-1]}")
    assert code == 0 and "the simulator's run is done" in text


def test_done_line_without_commands_has_no_nan(ros, tmp_path):
    """No command accepted (a scene without controller, free run): the done line says so instead of 'nan ms', and
    the bag holds no latency figures."""
    bag = tmp_path / "free"
    sim = ros.simulator(scene="free_rotor", duration=0.05, record=bag)
    code, out = finish(sim)
    assert code == 0, out
    done = [s for s in read_bag(bag).status if s.startswith("done:")][-1]
    print(f"\n  {done[:160]}")
    assert "nan" not in done and "no command latency" in done
    assert not any(k.startswith("gyro_sim.latency") for k in bag_info(bag)["custom"])


def test_a_law_switch_mid_run_subscribes_and_goes_on(ros, tmp_path):
    """Spin-up reads no L (the controller subscribes to gyro/imu alone); a switch to ψ-switching mid-run subscribes
    to gyro/kinetic_moment, and the lockstep run goes on: the next tick waits until the simulator publishes L to the
    new subscription, every tick is answered (no controller lost), the ticks before the switch by spin-up (z3
    alone), those after it by ψ-switching (z1, z2 and z3). The switch happens while the run is paused at 0.4 s."""
    bag = tmp_path / "switch"
    sim = ros.simulator(scene="spinup_thin_shell", duration=1.0, record=bag, start_paused=True, step_ticks=20,
                        startup_timeout=120.0, controller_timeout=30.0)
    ros.controller(scene="spinup_thin_shell")
    p1 = ros.start(PROBE, "script", str(tmp_path / "p1.json"), "/", str(PROBE_WINDOW), json.dumps(
        [{"wait_status": "paused at t = 0 s"}, {"call": "step"}, {"wait_status": "paused at t = 0.4 s"}]))
    code, text = finish(p1)
    assert code == 0 and "error" not in (tmp_path / "p1.json").read_text(), text
    psi = {"law": "psi_switching", "control_stators": ["z1", "z2"], "spin_stator": "z3", "nu": [3000.0, 5000.0],
           "control_current": 0.3, "spin_current": 0.5, "spin_rate": 200.0}
    p2 = ros.start(PROBE, "params", str(tmp_path / "p2.json"), str(PROBE_WINDOW), "gyro_controller",
                   json.dumps([{"set_atomically": psi}]))
    code, text = finish(p2)
    answers = json.loads((tmp_path / "p2.json").read_text())["answers"]
    assert code == 0 and answers[0]["successful"], (text, answers)
    ros.start(PROBE, "script", str(tmp_path / "p3.json"), "/", str(PROBE_WINDOW), json.dumps(
        [{"call": "resume"}, {"wait_status": "done:"}]))
    code, out = finish(sim)
    assert code == 0, out
    b = read_bag(bag)
    lost = [s for s in b.status if s.startswith(("controller lost", "watchdog"))]
    assert not lost, lost
    commanded = ~np.isnan(b.command_current)  # (m, 3): z1 z2 z3
    before, after = b.command_t < 0.4 + 1e-9, b.command_t > 0.4 + 1e-9
    ticks = np.round(b.command_t / 0.02).astype(int)
    print(f"\n  {before.sum()} commands before the switch, {after.sum()} after; stators after: "
          f"{sorted(set(map(tuple, commanded[after].tolist())))}")
    assert commanded[before].tolist() == [[False, False, True]] * int(before.sum())
    assert after.any() and commanded[after][:, :2].all()
    assert sorted(set(ticks.tolist())) == list(range(0, 50)), ticks  # a command at every tick 0 … 0.98 s
