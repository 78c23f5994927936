"""The ROS conventions of the nodes, over DDS with real processes: namespaces, world control (pause / step /
reset), latched status and scene, /diagnostics, /tf in bags, lockstep for every scene, refusal of mis-stamped
commands, parameters shown in force and read-only where set at start-up.

Each test has its own ROS_DOMAIN_ID and localhost-only discovery (:class:`test_ros.Procs`). Nothing here bounds
a time: the waits end on what they wait for (status lines, counts), with generous limits for a loaded machine.
"""
import json
import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

import gyro_sim  # noqa: E402
from gyro_sim.io.recording import bag_info, read_bag  # noqa: E402
from gyro_sim.io.rerun import rerun_bag  # noqa: E402
from test_ros import PROBE, PROBE_WINDOW, finish, ros  # noqa: E402,F401  (ros: the fixture)

pytestmark = pytest.mark.ros


def run_script(ros, tmp_path, ns, steps, name="script"):
    """Start the script probe (see ros_probe.script); returns (process, path of its JSON)."""
    out = tmp_path / f"{name}.json"
    return ros.start(PROBE, "script", str(out), ns, str(PROBE_WINDOW), json.dumps(steps)), out


def script_result(p, out: Path) -> dict:
    code, text = finish(p)
    assert code == 0, text
    data = json.loads(out.read_text())
    errors = [r["error"] for r in data["results"] if "error" in r]
    assert not errors, (errors, data["status"])
    return data


def test_two_namespaced_pairs_share_a_domain(ros, tmp_path):
    """Two simulator/controller pairs in one domain, each under its own namespace (-r __ns:=...), run in lockstep
    without crosstalk: each bag equals its own scene's in-process run, bit for bit, with no refusal."""
    runs = {"/unit1": ("nutation_oblate", 0.3), "/unit2": ("spinup_thin_shell", 1.0)}
    sims = {}
    for ns, (scene, dur) in runs.items():
        sims[ns] = ros.simulator(scene=scene, duration=dur, record=tmp_path / ns.strip("/"), ns=ns)
        ros.controller(scene=scene, ns=ns)
    for ns, (scene, dur) in runs.items():
        code, out = finish(sims[ns])
        assert code == 0, out
        b = read_bag(tmp_path / ns.strip("/"))
        r = gyro_sim.run(gyro_sim.load_scene(scene), duration=dur)
        assert np.array_equal(b.L, r.L) and np.array_equal(b.q, r.q), ns
        done = [s for s in b.status if s.startswith("done:")][-1]
        print(f"\n  {ns}: {scene} {dur} s over DDS identical to in-process; {done[:80]}...")
        assert " 0 commands refused" in done, done


def test_pause_step_reset_and_latched_topics(ros, tmp_path):
    """World control like Gazebo's: gyro/pause stops a running lockstep run at a tick; gyro/step runs step_ticks
    ticks (the controller answers each) and pauses again; gyro/reset goes back to t = 0 (paused stays paused).
    The probe joins after the start line: status and scene are latched. Parameters show the values in force;
    start-up ones are read-only, run-time ones settable. (start_paused: the watchdog test in test_ros.)"""
    import signal

    ns = "/bench1"
    sim = ros.simulator(scene="nutation_oblate", duration=100.0, step_ticks=5, ns=ns)
    ros.controller(scene="nutation_oblate", ns=ns)
    steps = [
        {"wait_status": "simulator: scene 'nutation_oblate'"},
        {"get": ["control_period", "expect_controller", "mode", "step_ticks", "scene"]},
        {"set": {"mode": "freerun"}},
        {"set": {"control_period": 0.5}},
        {"set": {"rate_factor": 2.0}},
        {"set": {"watchdog_timeout": -1.0}},
        {"call": "step"},  # running: refused
        {"call": "pause"},
        {"wait_status": "paused at t = ", "count": 1},
        {"call": "step"},
        {"wait_status": "paused at t = ", "count": 2},
        {"mark": "after step"},
        {"call": "step"},
        {"wait_status": "paused at t = ", "count": 3},
        {"call": "reset"},
        {"wait_status": "reset: back to the scene's initial state"},
        {"wait_status": "paused at t = 0 s"},
        {"call": "pause"},  # already paused: refused
    ]
    p, out = run_script(ros, tmp_path, ns, steps)
    data = script_result(p, out)
    sim.send_signal(signal.SIGINT)
    code, text = finish(sim)
    assert code == 130, text  # stopped by SIGINT (test_signals.py)
    res = {json.dumps(r["step"]): r for r in data["results"]}
    get = res[json.dumps(steps[1])]["values"]
    print(f"\n  parameters in force: {get}")
    assert get == {"control_period": 0.001, "expect_controller": True, "mode": "lockstep", "step_ticks": 5,
                   "scene": "nutation_oblate"}
    (ok_mode, why_mode), = res[json.dumps(steps[2])]["results"]
    (ok_period, _), = res[json.dumps(steps[3])]["results"]
    (ok_rate, _), = res[json.dumps(steps[4])]["results"]
    (ok_wd, why_wd), = res[json.dumps(steps[5])]["results"]
    print(f"  set mode: {ok_mode} ({why_mode}); set watchdog_timeout = -1: {ok_wd} ({why_wd})")
    assert (ok_mode, ok_period, ok_rate, ok_wd) == (False, False, True, False)
    paused = [s for s in data["status"] if s.startswith("paused at t = ")]
    t_paused = [float(re.search(r"t = ([\d.e-]+) s", s).group(1)) for s in paused]
    print(f"  paused at: {t_paused}; service replies: "
          + "; ".join(f"{r['step']['call']}: {r['success']} ({r['message']})" for r in data["results"] if "call" in r["step"]))
    # paused at a tick; +5 ticks; +5 ticks; after the reset at 0
    assert len(t_paused) == 4 and t_paused[0] > 0 and t_paused[-1] == 0.0
    assert np.isclose(t_paused[1] - t_paused[0], 0.005, atol=1e-12)
    assert np.isclose(t_paused[2] - t_paused[1], 0.005, atol=1e-12)
    assert np.isclose(t_paused[0] / 0.001, round(t_paused[0] / 0.001), atol=1e-6)  # at a tick
    after = res[json.dumps(steps[11])]["clock"]
    assert np.isclose(after, t_paused[1], atol=1e-12)  # the clock stopped where the step ended
    calls = [(r["step"]["call"], r["success"]) for r in data["results"] if "call" in r["step"]]
    assert calls == [("step", False), ("pause", True), ("step", True), ("step", True), ("reset", True),
                     ("pause", False)]
    # latched: the probe joined late, yet has the start line and the scene
    assert data["scene"] and "name: nutation_oblate" in data["scene"][0]
    # /diagnostics: the run's state, with its figures
    diag = data["diagnostics"]
    assert diag and all(d[3] == f"{ns}/gyro_simulator" for d in diag)
    assert any("paused at t = " in d[2] for d in diag)
    assert {"t", "real_time_factor", "control_ticks", "commands_refused", "watchdog", "paused"} <= set(diag[-1][4])


def test_reset_is_refused_while_recording(ros, tmp_path):
    ns = "/rec1"
    sim = ros.simulator(scene="free_rotor", duration=0.2, start_paused=True, record=tmp_path / "bag", ns=ns)
    p, out = run_script(ros, tmp_path, ns, [{"wait_status": "paused at t = 0 s"}, {"call": "reset"},
                                            {"call": "resume"}, {"wait_status": "done:"}])
    data = script_result(p, out)
    assert finish(sim)[0] == 0
    reset = data["results"][1]
    print(f"\n  reset while recording: {reset['success']} ({reset['message']})")
    assert reset["success"] is False and "refused while recording" in reset["message"]
    assert bag_info(tmp_path / "bag")["end_reason"] == "complete"


def test_mis_stamped_commands_are_refused_and_the_controller_counts_as_lost(ros, tmp_path):
    """Lockstep with commands stamped for no pending tick (0 and the wall clock, as `ros2 topic pub` sends): each
    kind refused with a status line naming the stamp lockstep waits for (the one stamped 0 answers t = 0); they do
    not count as answers: the sender is lost after controller_timeout, and with on_controller_lost currents_off the
    run goes on to its end (before: it stalled, '0 commands refused')."""
    bag = tmp_path / "stamp"
    sim = ros.simulator(scene="nutation_oblate", duration=0.2, record=bag, on_controller_lost="currents_off",
                        controller_timeout=1.0, startup_timeout=120.0)
    ros.start(PROBE, "stamped", "/", str(PROBE_WINDOW), "0.02")
    code, out = finish(sim)
    assert code == 0, out
    b = read_bag(bag)
    refusals = [s for s in b.status if s.startswith("refused command: stamp = ")]
    done = [s for s in b.status if s.startswith("done:")][-1]
    print("\n  " + (refusals[0] if refusals else "no refusal") + f"\n  {done[:120]}")
    assert refusals and "lockstep waits for the command stamped" in refusals[0]
    assert any(s.startswith("controller lost at t = 0.001 s: no answer for 1 s (controller_timeout)")
               for s in b.status)
    n_refused = int(re.search(r"(\d+) commands refused", done).group(1))
    assert n_refused >= 1 and "(interrupted)" not in done
    assert b.t[-1] == pytest.approx(0.2)


def test_scene_without_controller_is_commanded_from_outside_in_lockstep(ros, tmp_path):
    """A scene with no controller section ticks at control_period and takes external commands; with
    expect_controller, lockstep waits for them: a minimal external controller (answer each state with its stamp)
    switches z3 off at t = 0.1 s. The bag re-runs bit for bit; its malformed command is refused; /tf, /tf_static
    and /diagnostics are in the bag (read by the independent mcap reader)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag = tmp_path / "ext"
    sim = ros.simulator(scene="spinup_solid_sphere", duration=0.2, record=bag, expect_controller=True,
                        control_period=0.02, startup_timeout=120.0)
    ros.start(PROBE, "answer", "/", str(PROBE_WINDOW), "z3", "0.1", "0.0")
    code, out = finish(sim)
    assert code == 0, out
    b = read_bag(bag)
    assert b.custom["gyro_sim.control_period"] == "0.02"
    on, off = b.t < 0.1 - 1e-9, b.t > 0.1 + 1e-9
    print(f"\n  external commands on a controller-less scene: z3 current {b.current[on, 0].max()} A before "
          f"t = 0.1 s, {b.current[off, 0].max()} A after; {len(b.command_t)} commands applied")
    assert np.all(b.current[on, 0] == 1.0) and np.all(b.current[off, 0] == 0.0)
    assert any("effort[z3] = -1.0" in s for s in b.status)  # malformed: refused, not ignored
    rep = rerun_bag(bag)
    assert rep["identical"], rep
    counts = {}
    diag = []
    with open(next(bag.glob("*.mcap")), "rb") as f:
        for _, ch, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[ch.topic] = counts.get(ch.topic, 0) + 1
            if ch.topic == "/diagnostics":
                diag.append(m.status[0])
            if ch.topic == "/tf_static":
                assert [x.child_frame_id for x in m.transforms] == ["gyro_stator_z3"]
    print(f"  bag: /tf {counts.get('/tf')}, /tf_static {counts.get('/tf_static')}, /diagnostics "
          f"{counts.get('/diagnostics')} messages; last diagnostic: {diag[-1].message if diag else None}")
    assert counts["/tf"] == len(b.t) and counts["/tf_static"] == 1 and counts["/diagnostics"] >= 2
    assert {kv.key for kv in diag[-1].values} >= {"real_time_factor", "commands_refused", "watchdog"}


FAULTS = dict(fault_seed=11, command_drop=0.2, command_corrupt=0.1, command_delay=2, current_quantum=0.05,
              noise_omega=0.5, noise_attitude=0.002, noise_L=1e-6, bias_omega="[0.0, 0.0, 0.3]")


def test_fault_injection_is_reproducible_and_reaches_the_controller(ros, tmp_path):
    """Faults on (drop, corrupt, delay, quantise; noise and bias on the published state): two lockstep runs with
    the same seed give the same bag bit for bit; the controller sees the noise (its commands differ from a clean
    run's) and gyro/imu's covariances say how much; the bag holds the commands as applied, so it re-runs
    identically; the settings are in its metadata."""
    out = tmp_path / "imu.json"
    probe = ros.start(PROBE, "listen", str(out), str(PROBE_WINDOW), "1", "/gyro/imu")
    from test_ros import wait_ready

    wait_ready(out)
    bags = []
    for k in range(2):
        bag = tmp_path / f"faulty{k}"
        # the first run starts once the controller (imu, kinetic_moment) and the probe (imu) subscribe: a loaded
        # machine discovered the probe after the 0.3 s run had ended (it saw no gyro/imu); the probe ends at its first
        sim = ros.simulator(scene="nutation_oblate", duration=0.3, record=bag, wait_for_subscribers=3 - k,
                            startup_timeout=120.0, **FAULTS)
        ros.controller(scene="nutation_oblate")
        code, text = finish(sim)
        assert code == 0, text
        bags.append(read_bag(bag))
    finish(probe)
    a, b = bags
    for k in ("L", "q", "current", "command_current"):
        assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k
    clean = gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=0.3)
    assert not np.array_equal(a.current, clean.current)
    assert np.allclose(a.command_current[~np.isnan(a.command_current)] / 0.05,
                       np.round(a.command_current[~np.isnan(a.command_current)] / 0.05))  # quantised
    assert rerun_bag(tmp_path / "faulty0")["identical"]
    assert a.custom["gyro_sim.fault.command_drop"] == "0.2" and a.custom["gyro_sim.fault.seed"] == "11"
    imu = json.loads(out.read_text())["imu"]
    print(f"\n  faults: {len(a.command_t)} commands applied on 300 ticks (drop 0.2, delay 2); imu covariance "
          f"orientation {imu['orientation_covariance'][0]:.1e} rad², angular velocity "
          f"{imu['angular_velocity_covariance'][0]:.2f} (rad/s)²")
    assert imu["orientation_covariance"][0] == pytest.approx(0.002 ** 2)
    assert imu["angular_velocity_covariance"][4] == pytest.approx(0.25)


def test_bad_fault_settings_are_refused(ros):
    p = ros.simulator(scene="nutation_oblate", bias_omega="[0.0, 1.0]")
    code, out = finish(p, 60)
    assert code == 2 and "bias_omega" in out, out


def test_a_pause_longer_than_the_watchdog_does_not_fire_it(ros, tmp_path):
    """Paused for three watchdog timeouts with a healthy controller (its answer to the paused tick's state queued
    meanwhile): on resume no watchdog fires (before: it did, and zeroed the currents for a tick)."""
    bag = tmp_path / "paused"
    sim = ros.simulator(scene="nutation_oblate", duration=0.05, start_paused=True, watchdog_timeout=0.5, record=bag,
                        startup_timeout=120.0)
    ros.controller(scene="nutation_oblate")
    p, out = run_script(ros, tmp_path, "/", [{"wait_status": "paused at t = 0 s"}, {"sleep": 1.5},
                                             {"call": "resume"}, {"wait_status": "done:"}])
    script_result(p, out)
    code, text = finish(sim)
    assert code == 0, text
    b = read_bag(bag)
    wd = [s for s in b.status if s.startswith("watchdog")]
    print(f"\n  paused 1.5 s with watchdog_timeout 0.5 s: watchdog lines {wd}")
    assert not wd and np.array_equal(b.L, gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=0.05).L)
