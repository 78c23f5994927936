"""Multi-process ROS 2 tests: real simulator/controller node processes talking over DDS.

Each test gets its own ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (DDS stays on this
machine); every process it starts is ended at teardown, also when the test fails.
"""
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

import gyro_sim  # noqa: E402
from gyro_sim.io.recording import bag_info, read_bag  # noqa: E402
from gyro_sim.io.rerun import rerun_bag  # noqa: E402
from gyro_sim.testing import release_domain, unique_domain  # noqa: E402  (a free ROS_DOMAIN_ID; the gyro_bench fixture uses it too)

pytestmark = pytest.mark.ros
PROBE = str(Path(__file__).with_name("ros_probe.py"))
ROOT = Path(__file__).resolve().parents[1]
PROBE_WINDOW = 150  # s: a probe listens at most this long (it ends as soon as it has what it waits for)
CONTROLLER = [sys.executable, "-m", "gyro_ctl.ros.controller_node", "--ros-args"]


class Procs:
    def __init__(self):
        self.domain = unique_domain()
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                        PYTHONUNBUFFERED="1")
        self.procs = []

    def start(self, *args, **kw):
        p = subprocess.Popen([sys.executable, *args], env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True, **kw)
        self.procs.append(p)
        return p

    def simulator(self, ns=None, **params):
        """The simulator node with these parameters (``ns``: its namespace, as ``-r __ns:=NS``)."""
        return self.start("-m", "gyro_sim.ros.simulator_node", "--ros-args", *_ns(ns), *_params(params))

    def controller(self, ns=None, **params):
        return self.start("-m", "gyro_ctl.ros.controller_node", "--ros-args", *_ns(ns), *_params(params))

    def close(self):
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in self.procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        release_domain(self.domain)  # (its nodes have ended: another session on the machine may take it)


def _ns(ns):
    return ["-r", f"__ns:={ns}"] if ns else []


def _params(d):
    out = []
    for k, v in d.items():
        out += ["-p", f"{k}:={float(v)!r}" if isinstance(v, float) else f"{k}:={v}"]
    return out


@pytest.fixture
def ros():
    p = Procs()
    yield p
    p.close()


def finish(p, timeout=180):
    out, _ = p.communicate(timeout=timeout)
    return p.returncode, out


def wait_ready(out: Path, timeout: float = 120.0) -> None:
    """Wait for a probe to have made its subscriptions (first imports may compile for a while)."""
    t0 = time.time()
    while not Path(str(out) + ".ready").exists():
        assert time.time() - t0 < timeout, "the probe did not start"
        time.sleep(0.1)
    time.sleep(0.5)


def closed_loop(bench, scene: str, duration: float, **kw):
    """The simulator and controller nodes over DDS in lockstep through the gyro_bench kit (gyro_sim.testing),
    recorded to a bag; (the BenchRun, the in-process run of the same scene)."""
    run = bench.run(scene, controller=CONTROLLER + ["-p", f"scene:={scene}"], duration=duration, **kw)
    return run, gyro_sim.run(gyro_sim.load_scene(scene), duration=duration)


def _commands(commands) -> list:
    """(t, {stator: (current, rate)}) of a command list (the order of the names aside)."""
    return [(t, {n: (c[i] if c else None, r[i] if r else None) for i, n in enumerate(nm)}) for t, nm, c, r in commands]


def test_lockstep_closed_loop_over_dds_equals_in_process(gyro_bench):
    """ψ-switching over DDS in lockstep damps the nutation and gives the in-process run's numbers, bit for bit:
    the kit's RunResult (from the bag) equals gyro_sim.run's, every array, the sample times included."""
    run, r = closed_loop(gyro_bench, "nutation_oblate", 1.0)
    k = run.result
    for name in ("t", "L", "q", "omega_b", "torque", "energy", "current", "field_rate", "field_phase", "euler"):
        a, c = getattr(r, name), getattr(k, name)
        assert a.shape == c.shape and np.array_equal(a, c), f"{name}: max |Δ| {np.max(np.abs(a - c))}"
    assert k.stator_names == r.stator_names
    assert _commands(k.commands) == _commands(r.commands)
    b = run.data
    assert np.all(np.diff(b.t_ns) > 0)
    th0, th1 = np.degrees(b.euler[0, 1]), np.degrees(b.euler[-1, 1])
    f = run.figures
    print(f"\n  lockstep over DDS: θ {th0:.2f}° → {th1:.3f}° in 1 s; {len(b.t)} samples identical to the in-process "
          f"run (max |Δ| = 0); {f['ticks_per_s']:.0f} closed-loop ticks/s; "
          f"command round trip median {f['latency_median_ms']:.2f} ms, p99 {f['latency_p99_ms']:.2f} ms")
    run.assert_theta_below(math.radians(0.5), after=1.0)
    run.assert_no_refusals()
    run.assert_watchdog_never_fired()
    rep = rerun_bag(run.bag)
    assert rep["identical"], rep


def test_spinup_over_dds_equals_in_process(gyro_bench):
    run, r = closed_loop(gyro_bench, "spinup_thin_shell", 4.0)
    b = run.data
    assert np.array_equal(b.L, r.L) and np.array_equal(b.q, r.q)
    run.assert_spin_reached(20 * max(b.omega_b[1, 2], 1.0), by=4.0)
    print(f"\n  spin-up over DDS: Ω3 {b.omega_b[0, 2]:.2f} → {b.omega_b[-1, 2]:.2f} rad/s, identical to in-process")


def test_replay_republishes_a_bag(ros, tmp_path):
    bag = tmp_path / "src"
    gyro_sim_run = gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=0.5)
    from gyro_sim.io.recording import record_result

    record_result(gyro_sim_run, bag)
    out = tmp_path / "seen.json"
    # the probe listens at most 100 s (less than finish's 180 s: a miss is a count below, not a timeout); the bag is
    # replayed at 1/10 of its pace: a reader on a loaded machine lagging by up to a second (100 samples, the QoS
    # depth of the state topics) loses none (at full pace, 1 kHz bursts overran a lagging reader's history)
    probe = ros.start(PROBE, "listen", str(out), "100", "501", "/gyro/kinetic_moment", "/clock", "/gyro/imu")
    wait_ready(out)
    rep = ros.start("-m", "gyro_sim.ros.replay", str(bag), "0.1", "--wait-for-subscribers", "3", "--startup-timeout",
                    "60")  # the probe's three subscriptions
    code, text = finish(rep)
    assert code == 0, text
    finish(probe)
    seen = json.loads(out.read_text())
    counts = bag_info(bag)["topics"]
    print(f"\n  replay: seen {seen['counts']} of {({k: counts[k]['count'] for k in seen['counts']})}")
    for topic, n in seen["counts"].items():
        assert n == counts[topic]["count"], (topic, n)
    assert seen["stamps"] == sorted(seen["stamps"])


def test_replay_stopped_by_a_signal_says_so_in_its_status(ros, tmp_path):
    """A replay ended by SIGTERM exited 0 like a whole one (scripts could not tell them apart): now 143, and its
    last line says it was interrupted."""
    bag = tmp_path / "src"
    from gyro_sim.io.recording import record_result

    record_result(gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=0.5), bag)
    out = tmp_path / "seen.json"
    probe = ros.start(PROBE, "listen", str(out), str(PROBE_WINDOW), "1", "/clock")  # ends at its first message
    wait_ready(out)
    # 500 s of wall time at this rate; the first message goes out once the probe is matched
    rep = ros.start("-m", "gyro_sim.ros.replay", str(bag), "0.001", "--wait-for-subscribers", "1",
                    "--startup-timeout", "120")
    finish(probe)  # the replay is publishing: its signal handlers are in place
    assert rep.poll() is None
    rep.send_signal(signal.SIGTERM)
    code, text = finish(rep, 120)
    assert code == 143 and "interrupted by SIGTERM" in text, text


def test_a_killed_controller_with_currents_off_lets_the_run_go_on(ros, tmp_path):
    """The controller drives 100 lockstep ticks (gyro/step from a start paused), is killed, and the run resumes;
    with on_controller_lost currents_off the simulator counts it lost (controller_timeout 0.5 s here: DDS shows a
    killed process for ~20 s), zeroes every current, recorded like a command, and runs on to its end. The pause makes
    it independent of the machine's speed (before, a fast run could end before the kill)."""
    bag = tmp_path / "wd"
    sim = ros.simulator(scene="nutation_oblate", duration=0.5, record=bag, controller_timeout=0.5,
                        on_controller_lost="currents_off", start_paused=True, step_ticks=100, startup_timeout=120.0)
    ctl = ros.controller(scene="nutation_oblate")
    out = tmp_path / "phase1.json"
    p1 = ros.start(PROBE, "script", str(out), "/", str(PROBE_WINDOW), json.dumps(
        [{"wait_status": "paused at t = 0 s"}, {"call": "step"}, {"wait_status": "paused at t = 0.1 s"}]))
    code, text = finish(p1)
    assert code == 0 and "error" not in out.read_text(), (text, out.read_text())
    ctl.kill()
    ctl.wait()
    p2 = ros.start(PROBE, "script", str(tmp_path / "phase2.json"), "/", str(PROBE_WINDOW), json.dumps(
        [{"call": "resume"}, {"wait_status": "done:"}]))
    code, out_text = finish(sim)
    assert code == 0, out_text
    finish(p2)
    b = read_bag(bag)
    wd = [(t, s) for t, s in zip(b.status_t, b.status, strict=True) if s.startswith("controller lost")]
    assert wd and "currents_off" in wd[0][1], b.status
    t_fire = wd[0][0]
    after = b.t > t_fire + 1e-9
    print(f"\n  {wd[0][1]}\n  currents after it: max {np.max(b.current[after]):.1f} A over {after.sum()} samples")
    # at the first tick the killed controller did not answer: 0.101 (it answered the 0.1 state, published before the
    # pause, while paused), or 0.1 where the kill came before that answer (a loaded machine)
    assert min(abs(t_fire - 0.1), abs(t_fire - 0.101)) < 1e-9, t_fire
    assert after.sum() > 10 and np.all(b.current[after] == 0.0)
    assert bag_info(bag)["end_reason"] == "complete" and "currents_off" in b.custom["gyro_sim.controller_lost"]
    assert rerun_bag(bag)["identical"]  # the zeroing is recorded like a command


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_during_recording_leaves_a_readable_bag(ros, tmp_path, sig):
    bag = tmp_path / "sig"
    sim = ros.simulator(scene="spinup_thin_shell", mode="freerun", duration=3600.0, record=bag, watchdog_timeout=0.0)
    t0 = time.time()
    while not bag.exists() and time.time() - t0 < 60:
        time.sleep(0.1)
    time.sleep(2.0)
    sim.send_signal(sig)
    code, out = finish(sim, 30)
    assert code == 128 + sig, out  # 130 / 143: stopped by the signal, after a clean end (test_signals.py)
    b = read_bag(bag)
    info = bag_info(bag)
    print(f"\n  {sig.name}: bag holds {len(b.t)} samples up to t = {b.t[-1]:.2f} s; end: {info['end_reason']}")
    assert len(b.t) > 10 and np.all(np.diff(b.t_ns) > 0)
    assert info["end_reason"] == f"interrupted: signal {sig.name}"


def test_malformed_commands_are_refused_with_reasons(ros, tmp_path):
    """A sender flooding malformed commands (as fast as it can publish) gets every one refused with its
    reason, each reason on /gyro/status at most once a second, and does not hold the run up."""
    out = tmp_path / "status.json"
    probe = ros.start(PROBE, "listen", str(out), str(PROBE_WINDOW), "0", "/gyro/status")
    wait_ready(out)
    bad = ros.start(PROBE, "bad_commands", str(PROBE_WINDOW), "0")
    # the run starts once both probes subscribe to gyro/status (on a loaded machine the flooder could come up after
    # a 4 s run had ended, then wait for a 'done:' that was gone: the test timed out)
    sim = ros.simulator(scene="nutation_oblate", mode="realtime", duration=4.0, watchdog_timeout=0.0,
                        wait_for_subscribers=2, startup_timeout=120.0)
    code, text = finish(sim)
    assert code == 0, text
    finish(bad)
    finish(probe)
    status = json.loads(out.read_text())["status"]
    refusals = [s for s in status if s.startswith("refused command")]
    done = [s for s in status if s.startswith("done:")]
    assert done, status
    n_refused = int(re.search(r"(\d+) commands refused", done[-1]).group(1))
    wall = float(re.search(r"in ([\d.]+) s wall", done[-1]).group(1))
    print("\n  " + "\n  ".join(sorted(set(r.split(" (")[0] for r in refusals))))
    print(f"  {n_refused} commands refused in a 4 s real-time run ({wall:.2f} s wall), "
          f"{len(refusals)} refusal messages on /gyro/status")
    for fragment in ("effort[z1] = nan", "effort[z1] = -1.0", "unknown stator 'z9'", "one current (A) per name",
                     "velocity[z1] = inf"):
        assert any(fragment in s for s in refusals), fragment
    assert wall < 20.0  # not held up by the flood (before: the run never ended); 4 s when idle
    assert n_refused > len(refusals) and len(refusals) <= 5 * (math.ceil(wall) + 1)


@pytest.mark.parametrize("which,params,fragment", [
    ("simulator", {"mode": "bogus"}, "parameter mode = 'bogus': allowed: lockstep, realtime, freerun"),
    ("simulator", {"rate_factor": -5.0}, "rate_factor out of range"),
    ("simulator", {"scene": "no_such_scene"}, "no built-in scene of that name"),
    ("controller", {"scene": "nutation_oblate", "control_current": -1.0}, "control_current"),
    ("controller", {"scene": "free_rotor"}, "no control law"),
])
def test_bad_parameters_are_refused(ros, which, params, fragment):
    p = getattr(ros, which)(**params)
    code, out = finish(p, 60)
    print(f"\n  {which} {params}: exit {code}: {out.strip().splitlines()[-1]}")
    assert code == 2 and fragment in out


def test_realtime_mode_paces_and_measures_latency(gyro_bench, tmp_path):
    """Real time ×1 at a 200 Hz control rate: paced to the wall clock, the controller's commands applied at
    ticks only, at most one a tick, with the law's values, and their latency measured.

    Only what holds on a loaded machine is asserted. How many ticks get a command in time is the machine's
    load (the simulator, the controller and DDS share 2 cores; under the real-time contract only the latest of
    a bunch of late commands is applied): it is printed, not bounded. The simulator waits for the controller's
    two subscriptions before it starts, so the controller's start-up is not part of the run.
    """
    period = 0.005
    scene = tmp_path / "nutation_oblate_200hz.yaml"
    text = (ROOT / "config" / "nutation_oblate.yaml").read_text()
    assert "period: 0.001" in text
    scene.write_text(text.replace("period: 0.001", f"period: {period}"))
    # the kit raises ControllerError if no controller command was applied at all
    run = gyro_bench.run(str(scene), controller=CONTROLLER + ["-p", f"scene:={scene}"], mode="realtime",
                         duration=2.0, wait_for_subscribers=2, startup_timeout=120.0,
                         watchdog_timeout=0.0)  # (the watchdog's zeroing: its own test)
    b, f = run.data, run.figures
    run_wall = float(bag_info(run.bag)["custom"]["gyro_sim.wall_time"])
    ticks = int(round(2.0 / period))
    assert len(b.command_t) > 0, "no controller command was applied"
    print(f"\n  real time ×1, 200 Hz control: 2 s simulated in {run_wall:.2f} s wall; command latency median "
          f"{f['latency_median_ms']:.3f} ms, p99 {f['latency_p99_ms']:.3f} ms; {len(b.command_t)} commands applied "
          f"on {ticks} ticks (first at t = {b.command_t[0]:.3f} s); θ end {np.degrees(b.euler[-1, 1]):.3f}°")
    assert run_wall >= 2.0  # paced: never ahead of the wall clock
    assert np.isfinite(f["latency_median_ms"]) and f["latency_median_ms"] >= 0 and f["latency_p99_ms"] >= 0
    k = b.command_t / period
    assert np.allclose(k, np.round(k), atol=1e-6), "a command was applied between ticks"
    assert np.all(np.diff(b.command_t) > 0), "two commands were applied at one tick"
    # the law's values only: control currents on or off, the spin stator at its current
    assert set(np.unique(b.command_current[:, :2])) <= {0.0, 0.316}
    assert np.all(b.command_current[:, 2] == 0.5)


EFFECTS_SCENE = """name: effects_node
description: flywheel and damper state published by the simulator node
rotor: {inertia: [1.0e-5, 1.2e-5, 1.5e-5]}
torque_model: none
initial: {spin: 50.0, theta: 0.1}
duration: 0.5
output: {rate: 100.0}
effects:
  flywheel: {inertia: 1.0e-6, axis: [1, 1, 0], profile: {time: [0.0, 0.25, 0.5], speed: [0.0, 300.0, 0.0]}}
  damper: {mass: 1.0e-3, radius: 0.01, stiffness: 50.0, damping: 1.0e-3}
"""


def test_simulator_node_publishes_effect_states(ros, tmp_path):
    """/gyro/effects (flywheel angle/speed, damper deflection) over DDS and in the bag, equal to the in-process run."""
    scene = tmp_path / "effects_node.yaml"
    scene.write_text(EFFECTS_SCENE)
    out = tmp_path / "seen.json"
    probe = ros.start(PROBE, "listen", str(out), str(PROBE_WINDOW), "51", "/gyro/effects")
    wait_ready(out)
    bag = tmp_path / "eff"
    sim = ros.simulator(scene=str(scene), record=bag, wait_for_subscribers=1)  # (no controller: no lockstep wait)
    code, text = finish(sim)
    assert code == 0, text
    finish(probe)
    seen = json.loads(out.read_text())
    b = read_bag(bag)
    r = gyro_sim.run(gyro_sim.load_scene(str(scene)))
    assert set(b.effects) == {"flywheel", "damper_x", "damper_y", "damper_z"}
    assert np.array_equal(b.effects["flywheel"][:, 0], r.effects["flywheel_angle"])
    assert np.array_equal(b.effects["flywheel"][:, 1], r.effects["flywheel_speed"])
    for j, ax in enumerate("xyz"):
        assert np.array_equal(b.effects[f"damper_{ax}"][:, 0], r.effects["damper_offset"][:, j])
    print(f"\n  /gyro/effects: {seen['counts']['/gyro/effects']} messages seen over DDS, {len(b.t)} in the bag; "
          f"flywheel turn {r.effects['flywheel_angle'][-1]:.2f} rad, identical to in-process")
    assert seen["counts"]["/gyro/effects"] == len(b.t) == 51
