"""gyro_sim.testing, the kit a user's own test suite uses to test a controller against the simulator (the
``gyro_bench`` pytest fixture: an opt-in plugin, ``-p gyro_sim.testing`` or ``pytest_plugins``; test/conftest.py
asks for it).

The ROS tests here start real simulator / controller processes on a ROS domain of their own. Only outcomes are
asserted, never timings (the machine is shared); every wait is bounded by the kit's startup_timeout / watchdog.
The kit's bit-for-bit equality with an in-process run is test_ros.test_lockstep_closed_loop_over_dds_equals_in_process.
"""
import importlib.metadata
import importlib.util
import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import gyro_sim
from gyro_sim.testing import (PROTOCOL, BenchError, BenchRun, ControllerError, GyroBench, assert_no_refusals,
                              assert_spin_reached, assert_theta_below, assert_watchdog_never_fired, command_argv,
                              parse_done_line, unique_domain)

ROOT = Path(__file__).resolve().parents[1]
needs_ros = pytest.mark.skipif(importlib.util.find_spec("rclpy") is None,
                               reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

DONE = ("done: t = 0.5 s in 0.747 s wall (0.7x real time), 500 control ticks (669.8/s), 4316 steps, 3 commands "
        "refused, command latency median 0.382 ms p99 5.657 ms max 8.299 ms")


# --- without ROS --------------------------------------------------------------------------------

def test_importing_the_plugin_is_cheap_and_rclpy_free():
    """Importing gyro_sim.testing (a session that asks for the plugin does) adds neither rclpy nor the recording /
    bag-reading code to what ``import gyro_sim`` loads."""
    code = ("import sys, gyro_sim; before = set(sys.modules); import gyro_sim.testing; "
            "print(' '.join(sorted(set(sys.modules) - before)))")
    new = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    pytest_own = ("_pytest", "pytest", "pluggy", "py", "iniconfig", "pygments")  # loaded in any pytest session
    print(f"\n  import gyro_sim.testing adds (beyond pytest's): "
          f"{' '.join(m for m in new if m.split('.')[0] not in pytest_own)}")
    assert "gyro_sim.apps.testing" in new
    heavy = [m for m in new if m.split(".")[0] in ("rclpy", "rosbags", "mcap", "yaml", "matplotlib", "numba")
             or m in ("gyro_sim.ros", "gyro_sim.io.recording", "gyro_sim.io.messages")]
    assert not heavy, heavy


def test_the_plugin_is_opt_in():
    """No pytest11 entry point: a pytest session on a machine with gyro_sim installed that does not ask for the plugin
    imports nothing of gyro_sim (no numba, no import hook); one that asks (-p gyro_sim.testing) gets gyro_bench."""
    assert not [e for e in importlib.metadata.entry_points(group="pytest11") if e.value.startswith("gyro_sim")]


@pytest.mark.parametrize("ask", [False, True])
def test_a_plain_pytest_session_imports_no_gyro_sim(tmp_path, ask):
    (tmp_path / "test_plain.py").write_text(textwrap.dedent("""
        import sys

        def test_modules(request):
            loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("gyro_sim", "numba", "gyro_ctl"))
            hooks = [type(f).__module__ for f in sys.meta_path if type(f).__module__.startswith("gyro_sim")]
            print("LOADED", loaded, "HOOKS", hooks, "FIXTURE", "gyro_bench" in request.fixturenames
                  or request.config.pluginmanager.hasplugin("gyro_sim.testing"))
        """))
    argv = [sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", str(tmp_path / "test_plain.py")]
    if ask:
        argv[3:3] = ["-p", "gyro_sim.testing"]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTEST_ADDOPTS", "PYTEST_PLUGINS")}
    r = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    line = next(x for x in r.stdout.splitlines() if "LOADED" in x)
    if ask:
        assert "gyro_sim.apps.testing" in line and line.endswith("FIXTURE True"), line
        assert "'numba'" not in line, line  # (even the plugin imports no numba until a run)
    else:
        assert line == "LOADED [] HOOKS [] FIXTURE False", line


def test_parse_done_line():
    f = parse_done_line(DONE)
    assert f["t_end"] == 0.5 and f["wall_s"] == 0.747 and f["real_time_factor"] == 0.7
    assert f["control_ticks"] == 500 and f["ticks_per_s"] == 669.8 and f["steps"] == 4316 and f["refused"] == 3
    assert (f["latency_median_ms"], f["latency_p99_ms"], f["latency_max_ms"]) == (0.382, 5.657, 8.299)
    assert f["compile_s"] == 0.0 and not f["interrupted"]
    g = parse_done_line(DONE.replace("0.382 ms p99 5.657 ms max 8.299 ms", "nan ms p99 nan ms max nan ms")
                        + " (+ 2.0 s compiling the kernels, first use) (interrupted)")
    assert math.isnan(g["latency_median_ms"]) and g["compile_s"] == 2.0 and g["interrupted"]


def test_command_line_and_domain(tmp_path):
    assert command_argv("python -m my.ctl --ros-args -p 'gain:=2.0'") == [
        sys.executable, "-m", "my.ctl", "--ros-args", "-p", "gain:=2.0"]
    assert command_argv(["./ctl", "x"]) == ["./ctl", "x"]
    d = unique_domain()
    assert 1 <= d <= 101 and d != unique_domain()
    b = GyroBench(tmp_path)  # no run: a work directory and an environment only
    assert b.env["ROS_DOMAIN_ID"] == str(b.domain) and b.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    b.close()


def test_assertion_helpers_give_the_measured_values():
    r = gyro_sim.run(gyro_sim.load_scene("spinup_thin_shell"), duration=1.0)
    assert_spin_reached(r, 20.0, by=1.0)  # 26.8 rad/s at 1 s
    with pytest.raises(AssertionError, match=r"spin rate 100 rad/s not reached by t = 0.5 s: at most 13.4\d* rad/s "
                                             r"\(at t = 0.5 s\)"):
        assert_spin_reached(r, 100.0, by=0.5)
    with pytest.raises(AssertionError, match="the run ended at t = 1 s"):
        assert_spin_reached(r, 100.0, by=5.0)
    assert_theta_below(r, 0.06)  # θ0 = 0.05 rad
    with pytest.raises(AssertionError, match=r"θ = 0.05\d* rad \(2.86\d*°\) at t = 0.\d+ s, not below 0.01 rad"):
        assert_theta_below(r, 0.01, after=0.2)
    run = BenchRun(scene="s", bag=Path("b"), result=r, data=None, status=[
        "simulator: ...", "refused command: stamp = 1.5 s: lockstep waits for the command stamped 0.02 s (...)",
        "watchdog: no command for 2 s; all stator currents set to 0 A", DONE],
        status_t=np.array([0.0, 0.02, 0.04, 0.5]), figures=parse_done_line(DONE), stdout="")
    with pytest.raises(AssertionError, match=r"refused 3 command\(s\): 'refused command: stamp = 1.5 s"):
        run.assert_no_refusals()
    with pytest.raises(AssertionError, match=r"watchdog fired 1 time\(s\), first at t = 0.04 s: 'watchdog: no"):
        run.assert_watchdog_never_fired()
    ok = BenchRun(scene="s", bag=Path("b"), result=r, data=None, status=["simulator: ...", "done: ..."],
                  status_t=np.array([0.0, 1.0]), figures={"refused": 0}, stdout="")
    assert_no_refusals(ok)
    assert_watchdog_never_fired(ok)
    ok.assert_spin_reached(20.0)


# --- a user's test suite --------------------------------------------------------------------------

#: the README's "Test your controller" example: a user's test file, using only the installed package's fixture
USER_TEST = '''\
"""Tests of my controller against the gyro_sim simulator (pip install 'gyro_sim[ros]' gives the fixture)."""
import math

CONTROLLER = "python -m gyro_ctl.ros.controller_node --ros-args -p scene:=spinup_thin_shell"


def test_controller_spins_the_rotor_up(gyro_bench):
    run = gyro_bench.run("spinup_thin_shell", controller=CONTROLLER, duration=3.0)
    run.assert_spin_reached(50.0, by=3.0)          # rad/s
    run.assert_theta_below(math.radians(5.0))      # stays upright
    run.assert_no_refusals()
    run.assert_watchdog_never_fired()
    print(run.figures["ticks_per_s"], "ticks/s;", run.bag)
'''


def run_user_suite(directory: Path, files: dict, timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Write ``files`` ({name: source}) into ``directory`` (outside the repo) and run pytest there in a fresh
    process, as a user would (cwd = that directory, no cache), with the conftest.py that asks for the plugin (it is
    opt-in). For example controllers too: a test file whose controller command runs the example."""
    directory.mkdir(parents=True, exist_ok=True)
    files = {"conftest.py": 'pytest_plugins = ["gyro_sim.testing"]\n', **files}
    for name, text in files.items():
        (directory / name).write_text(text)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-s", "."], cwd=directory,
                          env=env, capture_output=True, text=True, timeout=timeout)


@needs_ros
def test_a_user_test_suite_runs_the_controller_with_the_installed_fixture(tmp_path):
    suite = tmp_path / "my_controller_tests"
    assert ROOT not in suite.resolve().parents
    assert len(USER_TEST.splitlines()) <= 16
    p = run_user_suite(suite, {"test_my_controller.py": USER_TEST})
    print("\n  " + "\n  ".join(p.stdout.strip().splitlines()[-3:]))
    assert p.returncode == 0 and "1 passed" in p.stdout, p.stdout + p.stderr
    assert not (suite / ".pytest_cache").exists()


EXAMPLES_TEST = '''\
"""The example controllers, tested through the installed fixture as a user's own suite would."""
import math
import sys

EXAMPLES = {examples!r}


def test_spinup_example(gyro_bench):
    ctl = [sys.executable, EXAMPLES + "/spinup_controller.py", "--ros-args", "-p", "target_spin:=1500.0"]
    run = gyro_bench.run("spinup_thin_shell", controller=ctl, duration=2.0)
    run.assert_spin_reached(20.0, by=2.0)
    run.assert_no_refusals()
    run.assert_watchdog_never_fired()


def test_psi_switching_example(gyro_bench):
    run = gyro_bench.run("nutation_oblate", controller=[sys.executable, EXAMPLES + "/psi_switching_controller.py"],
                         duration=1.0)
    run.assert_theta_below(math.radians(0.5), after=0.9)
    run.assert_no_refusals()
'''


def test_the_examples_through_the_kit_in_a_user_suite(tmp_path_factory):
    """Each example controller (examples/, plain rclpy) tested the way a user tests theirs: a suite outside the repo
    that imports nothing but the installed fixture."""
    suite = tmp_path_factory.mktemp("user_examples_suite")
    p = run_user_suite(suite, {"test_examples_kit.py": EXAMPLES_TEST.format(examples=str(ROOT / "examples"))})
    print("\n  " + "\n  ".join(p.stdout.strip().splitlines()[-2:]))
    assert p.returncode == 0 and "2 passed" in p.stdout, p.stdout + p.stderr


# --- the kit's errors -------------------------------------------------------------------------------

#: a controller that starts and never subscribes
SLEEPER = [sys.executable, "-c", "import time; time.sleep(600)"]
#: a node that subscribes to the state and never answers
MUTE = [sys.executable, "-c", textwrap.dedent("""\
    import rclpy
    from geometry_msgs.msg import Vector3Stamped
    rclpy.init()
    node = rclpy.create_node("mute_controller")
    node.create_subscription(Vector3Stamped, "gyro/kinetic_moment", lambda msg: None, 100)
    rclpy.spin(node)
    """)]
#: a controller that answers every state with a command stamped with the wall clock
WALL_CLOCK_STAMPS = [sys.executable, "-c", textwrap.dedent("""\
    import rclpy
    from geometry_msgs.msg import Vector3Stamped
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node("wall_clock_controller")
    pub = node.create_publisher(JointState, "gyro/stator_commands", 100)
    def answer(state):
        cmd = JointState(name=["z3"], effort=[1.0])
        cmd.header.stamp = node.get_clock().now().to_msg()  # the wall clock, not state.header.stamp
        pub.publish(cmd)
    node.create_subscription(Vector3Stamped, "gyro/kinetic_moment", answer, 100)
    rclpy.spin(node)
    """)]
#: short, bounded waits: ≤ 3 s for the controller's subscriptions, then for its first command
QUICK = dict(duration=0.5, startup_timeout=3.0, watchdog_timeout=1.0)


def _says_the_protocol(e: ControllerError) -> None:
    text = str(e)
    assert PROTOCOL in text and "gyro/stator_commands" in text and "header stamp" in text
    assert e.status_line and repr(e.status_line) in text  # the simulator's own line, quoted


@needs_ros
def test_a_controller_that_never_subscribes(gyro_bench):
    with pytest.raises(ControllerError) as ei:
        gyro_bench.run("spinup_thin_shell", controller=SLEEPER, **QUICK)
    e = ei.value
    print(f"\n  {e}".replace("\n", "\n  "))
    assert isinstance(e, AssertionError) and e.kind == "no_answer"
    assert "never answered" in str(e) and "startup_timeout = 3 s" in str(e)
    assert e.status_line.startswith("wait_for_subscribers = 1: 0 matched")
    assert "was still running when the run ended" in str(e)
    _says_the_protocol(e)


@needs_ros
def test_a_controller_that_subscribes_and_never_answers(gyro_bench):
    """No command at all: the simulator waits startup_timeout for the first, then counts the controller as lost and
    stops the run (on_controller_lost stop); the kit raises quoting that line. The bag is there to look at."""
    with pytest.raises(ControllerError) as ei:
        gyro_bench.run("spinup_thin_shell", controller=MUTE, **QUICK)
    e = ei.value
    print(f"\n  {e}".replace("\n", "\n  "))
    assert e.kind == "no_answer" and "no command was applied in the whole run" in str(e)
    assert e.status_line.startswith("controller lost at t = 0 s: no command since the start (startup_timeout 3 s)")
    _says_the_protocol(e)
    assert e.run is not None and (e.run.bag / "metadata.yaml").exists() and not e.run.figures["interrupted"]


@needs_ros
@pytest.mark.parametrize("fail_fast", [True, False])
def test_a_controller_that_answers_with_wall_clock_stamps(gyro_bench, fail_fast):
    """fail_fast (the default): the first refusal ends the run; without it the run goes on (the controller counts
    as lost after startup_timeout: the run stops) and the kit raises at its end, no command having been applied."""
    with pytest.raises(ControllerError) as ei:
        gyro_bench.run("spinup_thin_shell", controller=WALL_CLOCK_STAMPS, fail_fast=fail_fast, **QUICK)
    e = ei.value
    print(f"\n  {e}".replace("\n", "\n  "))
    assert e.kind == "wrong_stamps" and "wrong stamps" in str(e)
    assert e.status_line.startswith("refused command: stamp = ")
    assert "lockstep waits for the command stamped 0.000000000 s" in e.status_line
    _says_the_protocol(e)
    assert e.run is not None and e.run.figures["interrupted"] == fail_fast


@needs_ros
def test_a_controller_that_exits_with_an_error(gyro_bench):
    crash = [sys.executable, "-c", "import sys; print('my_controller: error: gain must be > 0'); sys.exit(3)"]
    with pytest.raises(ControllerError) as ei:
        gyro_bench.run("spinup_thin_shell", controller=crash, **QUICK)
    e = ei.value
    print(f"\n  {e}".replace("\n", "\n  "))
    assert e.kind == "exited" and "exited with status 3" in str(e) and "gain must be > 0" in str(e)


@needs_ros
def test_a_scene_the_simulator_refuses(gyro_bench):
    with pytest.raises(BenchError) as ei:
        gyro_bench.run("no_such_scene", controller=SLEEPER, **QUICK)
    print(f"\n  {ei.value}".replace("\n", "\n  "))
    assert not isinstance(ei.value, ControllerError)
    assert "exited with status 2" in str(ei.value) and "no built-in scene of that name" in str(ei.value)


def _gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    # a zombie is gone for our purpose (its parent has not reaped it yet)
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] == "Z"
    except OSError:
        return True


@needs_ros
def test_teardown_when_the_test_body_raises_leaves_no_process(tmp_path):
    """A test failing mid-run: the simulator, the controller and a child of a wrapper script all end."""
    child_pid = tmp_path / "child.pid"
    wrapper = ["sh", "-c", f"sleep 600 & echo $! > {child_pid}; wait"]
    pids = []
    with pytest.raises(RuntimeError, match="the test body failed"):
        with GyroBench(tmp_path / "bench") as bench:
            bench.start("spinup_thin_shell", duration=0.5, startup_timeout=60.0)
            pids += [bench._sim.proc.pid, bench.spawn(wrapper, name="wrapper").pid]
            t0 = time.monotonic()
            while not child_pid.exists() or not child_pid.read_text().strip():
                assert time.monotonic() - t0 < 60, "the wrapper did not start its child"
                time.sleep(0.05)
            pids.append(int(child_pid.read_text()))
            raise RuntimeError("the test body failed")
    left = [p for p in pids if not _gone(p)]
    assert not left, left


def test_a_domain_claimed_by_another_process_is_not_picked(monkeypatch):
    """Two CI suites side by side picked the same ROS_DOMAIN_ID in the second before either's first node joined it
    (the check was for a DDS participant in it), and a probe of one read the other's simulator. Now a domain is
    claimed machine-wide while in use: a process that holds domain d makes this one pass over it, even with no node
    in it; released, it is free again for others."""
    import itertools
    import subprocess
    import sys

    from gyro_sim.apps import testing as kit

    child = subprocess.Popen([sys.executable, "-c", "import sys; from gyro_sim.testing import unique_domain; "
                              "print(unique_domain(), flush=True); sys.stdin.read()"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        held = int(child.stdout.readline())
        monkeypatch.setattr(kit, "_domains", itertools.count(held - 1))  # (this process would try `held` first)
        d = kit.unique_domain()
        assert d != held and 1 <= d <= 101
        kit.release_domain(d)
        again = kit._claim(d)  # (released: free for another process)
        assert again is not None
        again.close()
    finally:
        child.stdin.close()
        child.wait(timeout=30)
    after = kit._claim(held)  # (the child ended: its claim went with it)
    assert after is not None
    after.close()
