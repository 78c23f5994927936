"""Signals and exit statuses of ``gyro-sim run --ros`` (gyro_sim/ros/launch.py) and of the nodes
(gyro_sim/ros/common.py node_main), with signals sent to real processes.

SIGINT/SIGTERM to the launcher reach both nodes, which close the bag (marked ``interrupted: signal ...``); the
launcher prints the summary of what was recorded and exits 130 / 143; the nodes die with the launcher even when it is
SIGKILLed; a node that ignores the signal is SIGKILLed after a bounded wait, said on stderr.

Each test has its own ROS_DOMAIN_ID (gyro_sim.testing); every process a test starts (the launcher's process group,
the nodes found by psutil) is ended at teardown, also when the test fails. No time is asserted: the waits end on
what they wait for, with generous bounds as hang guards only.
"""
import importlib.util
import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import psutil
import pytest

from gyro_sim.testing import ros_env, unique_domain
from test_packaging import launch_stubs  # noqa: F401 (a fixture: launch / launch_ros stubbed)

START_TIMEOUT = 180.0  # wall s for the nodes to start and the run to begin (imports, discovery; a loaded machine)
END_TIMEOUT = 120.0  # wall s for the processes to end after a signal (hang guard)
LONG = ["--duration", "600", "--mode", "lockstep"]  # a run the signal lands in the middle of


# --- helpers -------------------------------------------------------------------------------------

class Processes:
    """Processes a test started, ended at teardown: each one's process group (SIGKILL), then every psutil process
    registered (the nodes) still running."""

    def __init__(self):
        self.popen: list[subprocess.Popen] = []
        self.extra: list[psutil.Process] = []

    def start(self, argv, log: Path, **kw) -> subprocess.Popen:
        f = open(log, "w")
        try:
            p = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 start_new_session=True, **kw)
        finally:
            f.close()
        self.popen.append(p)
        return p

    def close(self):
        for p in self.popen:
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                p.wait()
        for q in self.extra:
            try:
                q.kill()
            except psutil.Error:
                pass


@pytest.fixture
def procs():
    p = Processes()
    yield p
    p.close()


def alive(p: psutil.Process) -> bool:
    """Running (a zombie waiting for a parent to reap it has ended)."""
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def wait_gone(ps, timeout: float = END_TIMEOUT) -> list:
    """Wait until none of ``ps`` runs (≤ ``timeout``); the ones still running."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        left = [p for p in ps if alive(p)]
        if not left:
            return []
        time.sleep(0.1)
    return [p for p in ps if alive(p)]


def wait_for_text(log: Path, pattern: str, proc: subprocess.Popen, timeout: float = START_TIMEOUT) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if re.search(pattern, log.read_text(errors="replace"), re.M):
            return
        assert proc.poll() is None, f"ended (status {proc.returncode}) before {pattern!r}:\n{log.read_text()}"
        time.sleep(0.1)
    raise AssertionError(f"no {pattern!r} within {timeout:g} s:\n{log.read_text()}")


def ros_run(procs: Processes, tmp_path: Path, *extra, scene="spinup_thin_shell"):
    """``gyro-sim run SCENE --ros --record BAG`` in a process group of its own; (process, log, bag, out dir)."""
    bag, out, log = tmp_path / "bag", tmp_path / "out", tmp_path / "launcher.log"
    argv = [sys.executable, "-m", "gyro_sim.apps.cli", "run", scene, "--ros", "--quiet", "--out", str(out),
            "--record", str(bag), *extra]
    p = procs.start(argv, log, env=ros_env(unique_domain()), cwd=tmp_path)
    return p, log, bag, out


def started_run(procs: Processes, tmp_path: Path):
    """A long --ros run, once the simulator has begun recording; (process, log, bag, out, nodes by name)."""
    p, log, bag, out = ros_run(procs, tmp_path, *LONG)
    wait_for_text(log, r"\[gyro_simulator\]: simulator: scene", p)  # the bag is open, the run starts
    time.sleep(2.0)  # a part of the run recorded
    nodes = {}
    for c in psutil.Process(p.pid).children(recursive=True):
        cmd = " ".join(c.cmdline())
        for name in ("simulator_node", "controller_node"):
            if name in cmd:
                nodes[name] = c
    procs.extra += list(nodes.values())
    assert set(nodes) == {"simulator_node", "controller_node"}, nodes
    return p, log, bag, out, nodes


def read_interrupted_bag(bag: Path, sig: signal.Signals):
    from gyro_sim.io.recording import bag_info, read_bag

    info = bag_info(bag)
    b = read_bag(bag)
    assert info["end_reason"] == f"interrupted: signal {sig.name}", info["end_reason"]
    assert len(b.t) > 0 and b.status and b.status[-1].startswith("done:") and "(interrupted)" in b.status[-1]
    return b, info


def assert_summary(text: str, bag: Path, out: Path, sig: signal.Signals):
    assert "error:" not in text, text
    assert re.search(r"^scene +spinup_thin_shell$", text, re.M), text
    assert re.search(rf"^bag +{re.escape(str(bag))} \(\d+ messages\)$", text, re.M), text
    assert re.search(rf"^end +interrupted: signal {sig.name} \(exit status {128 + sig}\)$", text, re.M), text
    assert (out / "spinup_thin_shell.png").is_file()
    assert "killed (SIGKILL)" not in text, text


# --- gyro-sim run --ros --------------------------------------------------------------------------

HAVE_ROS = importlib.util.find_spec("rclpy") is not None


def needs_ros(test):
    """Marked ``ros``; skipped without the ROS 2 wheels."""
    skip = pytest.mark.skipif(not HAVE_ROS, reason="the ROS 2 wheels (pip install '.[ros]') are not installed")
    return pytest.mark.ros(skip(test))


@needs_ros
def test_sigterm_to_the_launcher_ends_both_nodes_with_a_complete_bag(procs, tmp_path):
    p, log, bag, out, nodes = started_run(procs, tmp_path)
    os.kill(p.pid, signal.SIGTERM)  # the launcher alone
    code = p.wait(timeout=END_TIMEOUT)
    left = wait_gone(nodes.values())
    text = log.read_text()
    assert not left, f"still running: {left}\n{text}"
    assert code == 143, text
    read_interrupted_bag(bag, signal.SIGTERM)
    assert_summary(text, bag, out, signal.SIGTERM)


@needs_ros
def test_ctrl_c_on_the_process_group_gives_the_summary_and_130(procs, tmp_path):
    p, log, bag, out, nodes = started_run(procs, tmp_path)
    os.killpg(p.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the launcher and both nodes
    code = p.wait(timeout=END_TIMEOUT)
    left = wait_gone(nodes.values())
    text = log.read_text()
    assert not left, f"still running: {left}\n{text}"
    assert code == 130, text
    b, info = read_interrupted_bag(bag, signal.SIGINT)
    assert_summary(text, bag, out, signal.SIGINT)
    print(f"\n  Ctrl-C: exit {code}, bag of {info['message_count']} messages up to t = {b.t[-1]:.3g} s")


@needs_ros
def test_ctrl_c_as_the_nodes_start_ends_quietly_with_130(procs, tmp_path):
    """Ctrl-C as soon as both node processes exist (they are still importing, usually): 130, no traceback; the bag,
    if the simulator had opened it by then, complete; else one line saying nothing was recorded."""
    from gyro_sim.io.recording import bag_info

    p, log, bag, out = ros_run(procs, tmp_path, *LONG)
    end = time.monotonic() + START_TIMEOUT
    nodes = []
    while len(nodes) < 2 and time.monotonic() < end and p.poll() is None:
        nodes = [c for c in psutil.Process(p.pid).children() if "_node" in " ".join(c.cmdline())]
        time.sleep(0.01)
    procs.extra += nodes
    assert len(nodes) == 2, log.read_text()
    os.killpg(p.pid, signal.SIGINT)
    code = p.wait(timeout=END_TIMEOUT)
    text = log.read_text()
    assert not wait_gone(nodes), text
    assert code == 130 and "Traceback" not in text and "error:" not in text, text
    if (bag / "metadata.yaml").exists():
        assert bag_info(bag)["end_reason"] == "interrupted: signal SIGINT"
        assert re.search(r"^end +interrupted: signal SIGINT \(exit status 130\)$", text, re.M), text
    else:
        assert text.strip().endswith("interrupted: SIGINT before the run started; nothing recorded"), text


@needs_ros
def test_sigkill_of_the_launcher_leaves_no_node_running(procs, tmp_path):
    p, log, bag, out, nodes = started_run(procs, tmp_path)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=END_TIMEOUT)
    left = wait_gone(nodes.values())
    assert not left, f"orphans still running: {[(q.pid, q.cmdline()) for q in left]}\n{log.read_text()}"
    # they were stopped by SIGTERM (PR_SET_PDEATHSIG, or their parent watch): the bag was closed
    read_interrupted_bag(bag, signal.SIGTERM)


@needs_ros
def test_a_complete_run_exits_0(procs, tmp_path):
    from gyro_sim.io.recording import bag_info

    p, log, bag, out = ros_run(procs, tmp_path, "--duration", "0.5")
    code = p.wait(timeout=START_TIMEOUT + END_TIMEOUT)
    text = log.read_text()
    assert code == 0, text
    assert "error:" not in text and "killed (SIGKILL)" not in text and not re.search(r"^end ", text, re.M), text
    assert bag_info(bag)["end_reason"] == "complete"
    assert (out / "spinup_thin_shell.png").is_file()


# --- the nodes alone -----------------------------------------------------------------------------

@needs_ros
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_the_nodes_exit_128_plus_the_signal_even_when_it_is_repeated(procs, tmp_path, sig):
    """The simulator and the controller, each signalled again and again until it has ended (a terminal's copy and a
    launcher's forwarded one, while the bag is closed and the process exits): 130 / 143, never -2 / -15, and the bag
    is closed, marked interrupted by that signal."""
    env = ros_env(unique_domain())
    bag = tmp_path / "bag"
    sim_log, ctl_log = tmp_path / "sim.log", tmp_path / "ctl.log"
    sim = procs.start([sys.executable, "-m", "gyro_sim.ros.simulator_node", "--ros-args", "-p",
                       "scene:=spinup_thin_shell", "-p", "duration:=600.0", "-p", f"record:={bag}"], sim_log, env=env)
    ctl = procs.start([sys.executable, "-m", "gyro_ctl.ros.controller_node", "--ros-args", "-p",
                       "scene:=spinup_thin_shell", "-p", "keep_alive:=true"], ctl_log, env=env)  # (not ended by done:)
    wait_for_text(sim_log, r"simulator: scene", sim)
    wait_for_text(ctl_log, r"controller: law", ctl)
    time.sleep(2.0)
    for p in (sim, ctl):
        end = time.monotonic() + END_TIMEOUT
        while p.poll() is None and time.monotonic() < end:
            p.send_signal(sig)
            time.sleep(0.05)
    assert sim.wait(timeout=END_TIMEOUT) == 128 + sig, sim_log.read_text()
    assert ctl.wait(timeout=END_TIMEOUT) == 128 + sig, ctl_log.read_text()
    read_interrupted_bag(bag, sig)
    for log in (sim_log, ctl_log):
        assert "Traceback" not in log.read_text(), log.read_text()


WATCHED = textwrap.dedent("""
    import sys
    from pathlib import Path
    from gyro_sim.ros.common import StopEvent, exit_status, stop_on_signals, watch_parent
    stop = StopEvent()
    stop_on_signals(stop)
    watch_parent(stop)
    print("ready", flush=True)
    stop.wait(300)
    Path(sys.argv[1]).write_text(str(exit_status(stop)))
""")
PARENT = textwrap.dedent("""
    import os, subprocess, sys, time
    from gyro_sim.ros.launch import PARENT_PID_ENV
    env = dict(os.environ, **{PARENT_PID_ENV: str(os.getpid())})
    c = subprocess.Popen([sys.executable, "-c", sys.argv[1], sys.argv[2]], env=env, stdout=subprocess.PIPE, text=True)
    c.stdout.readline()
    print(c.pid, flush=True)
    time.sleep(300)
""")


@needs_ros
def test_the_parent_watch_stops_a_node_whose_parent_is_killed(procs, tmp_path):
    """The portable fallback (without PR_SET_PDEATHSIG): GYRO_SIM_PARENT_PID makes the process stop as on SIGTERM
    once its parent is gone."""
    status = tmp_path / "status"
    parent = procs.start([sys.executable, "-c", PARENT, WATCHED, str(status)], tmp_path / "parent.log",
                         env=dict(os.environ, PYTHONUNBUFFERED="1"))
    end = time.monotonic() + START_TIMEOUT
    while not (tmp_path / "parent.log").read_text().strip() and time.monotonic() < end:
        assert parent.poll() is None, (tmp_path / "parent.log").read_text()
        time.sleep(0.1)
    child = psutil.Process(int((tmp_path / "parent.log").read_text().split()[0]))
    procs.extra.append(child)
    parent.kill()
    parent.wait()
    assert not wait_gone([child]), "the child outlived its parent"
    assert status.read_text() == str(128 + signal.SIGTERM)


# --- the launcher's bounded waits (no ROS: stand-in nodes) ---------------------------------------------

STAND_IN = textwrap.dedent("""
    # a node stand-in, started as launch() starts a node (gyro_sim.ros.launch.NODE_BOOT): ARGS --ros-args -p who:=NAME
    import os, signal, sys, time
    from pathlib import Path
    if os.environ["STAND_IN"] == "ignore":
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, signal.SIG_IGN)
    else:  # NODE_BOOT's handler: exit 128 + signal
        pass
    Path(os.environ["STAND_IN_DIR"], sys.argv[-1].split(":=")[1]).touch()
    time.sleep(600)
""")


@pytest.mark.parametrize("behaviour", ["ignore", "exit"])
def test_the_launcher_forwards_the_signal_and_kills_a_node_that_does_not_end(monkeypatch, tmp_path, capfd,
                                                                             behaviour):
    """launch() in this process: a SIGINT it gets is forwarded to both nodes; stand-in nodes that ignore it are
    SIGKILLed after the bounded wait, and it says so; nodes that end on it give 130 and no such line."""
    from gyro_sim.ros import launch as launch_mod

    (tmp_path / "stand_in_node.py").write_text(STAND_IN)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("STAND_IN", behaviour)
    monkeypatch.setenv("STAND_IN_DIR", str(tmp_path))
    real = launch_mod.node_command
    monkeypatch.setattr(launch_mod, "node_command",
                        lambda module, params: real("stand_in_node", {"who": module.rsplit(".", 1)[1]}))
    monkeypatch.setattr(launch_mod, "STOP_GRACE", 2.0)
    monkeypatch.setattr(launch_mod, "CONTROLLER_GRACE", 1.0)
    ready = [tmp_path / "simulator_node", tmp_path / "controller_node"]
    pids = []

    def interrupt():  # once both stand-ins run: SIGINT to this process alone (the launcher)
        end = time.monotonic() + START_TIMEOUT
        while time.monotonic() < end and not all(r.exists() for r in ready):
            time.sleep(0.05)
        mine = [c for c in psutil.Process().children() if "stand_in_node" in " ".join(c.cmdline())]
        pids.extend(c.pid for c in mine)
        if all(r.exists() for r in ready):
            os.kill(os.getpid(), signal.SIGINT)
        else:  # (they did not start: end them, so that launch() returns and the test fails)
            for c in mine:
                c.kill()

    handler = signal.getsignal(signal.SIGINT)
    t = threading.Thread(target=interrupt, daemon=True)
    t.start()
    try:
        code = launch_mod.launch("spinup_thin_shell", record=None, progress=False)
    finally:
        t.join(timeout=START_TIMEOUT)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    err = capfd.readouterr().err
    assert len(pids) == 2 and not any(psutil.pid_exists(pid) and alive(psutil.Process(pid)) for pid in pids), err
    if behaviour == "ignore":
        assert code == -signal.SIGKILL, err
        assert "the simulator node did not end within 2 s of SIGINT: killed (SIGKILL); its bag may be unfinished" in err
        assert "the controller node did not end within 1 s of SIGINT: killed (SIGKILL)" in err
    else:
        assert code == 130 and "SIGKILL" not in err, err
    assert signal.getsignal(signal.SIGINT) is handler  # the launcher's handlers are put back


# --- the launch file (stub launch / launch_ros modules, as test_packaging.test_launch_file) ----------------

def test_the_launch_file_gives_the_simulator_time_to_close_its_bag(launch_stubs):
    from test_packaging import load_launch_file

    from gyro_sim.ros.launch import STOP_GRACE

    entities = list(load_launch_file().generate_launch_description().args[0])
    (sim,) = [e for e in entities if type(e) is launch_stubs.launch_ros_actions.Node]
    (group,) = [e for e in entities if type(e) is launch_stubs.launch_actions.GroupAction]
    # ros2 launch: SIGINT (a terminal's, or its own), SIGTERM after sigterm_timeout, SIGKILL sigkill_timeout later
    grace = float(sim.kwargs["sigterm_timeout"]) + float(sim.kwargs["sigkill_timeout"])
    assert grace >= STOP_GRACE  # as long as gyro-sim run --ros waits
    assert sim.kwargs["on_exit"] == launch_stubs.launch_actions.Shutdown(reason="the simulator node ended")
    for ctl in group.kwargs["actions"]:
        assert "on_exit" not in ctl.kwargs  # (the controller ending alone does not end the run)


# --- gyro-sim run --ros: what it says for each status of the simulator (launch() replaced) -------------------

@needs_ros  # (gyro-sim run --ros refuses to start without rclpy)
@pytest.mark.parametrize("case", ["no_bag", "no_samples", "killed", "refused", "disk_full"])
def test_the_cli_reports_each_end_of_the_simulator(monkeypatch, tmp_path, capsys, case):
    """Interrupted before the bag was opened or before the first sample: 130 and one line (no error, no traceback);
    a simulator that had to be killed or refused its scene: an ``error:`` line with its status, exit 2; a simulator
    whose disk filled (status 1, its bag closed with what fit): an ``error:`` line, the summary of the bag and 1, as
    the README's table says (issue 29: it was 2)."""
    from gyro_sim.apps import cli
    from gyro_sim.io.recording import BagRecorder
    from gyro_sim.ros import launch as launch_mod

    bag = tmp_path / "bag"

    def fake_launch(scene, **kw):
        assert kw["record"] == str(bag)
        if case == "no_samples":
            rec = BagRecorder(bag, "scene: text\n", "spinup_thin_shell")
            rec.interrupted("signal SIGINT")
            rec.close()
        if case == "disk_full":  # (what the node's recorder leaves: the samples before the disk filled)
            from gyro_sim.engine.simulate import run
            from gyro_sim.io.recording import record_result
            from gyro_sim.scenes.scene import load_scene

            record_result(run(load_scene("spinup_thin_shell"), duration=0.1), bag)
        return {"no_bag": 130, "no_samples": 130, "killed": -9, "refused": 2, "disk_full": 1}[case]

    monkeypatch.setattr(launch_mod, "launch", fake_launch)
    code = cli.main(["run", "spinup_thin_shell", "--ros", "--record", str(bag), "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    if case == "disk_full":
        assert code == 1 and err == f"error: the simulator node could not write the bag {bag} whole: complete\n"
        assert "final spin rate" in out and f"bag               {bag}" in out
        return
    assert out == ""
    if case == "no_bag":
        assert (code, err) == (130, "interrupted: SIGINT before the run started; nothing recorded\n")
    elif case == "no_samples":
        assert (code, err) == (130, f"interrupted: SIGINT before the first sample; the bag {bag} holds none\n")
    elif case == "killed":
        assert (code, err) == (2, "error: the simulator node ended with status -9 (SIGKILL)\n")
    else:
        assert (code, err) == (2, "error: the simulator node ended with status 2\n")


@needs_ros
def test_a_node_whose_ros_teardown_hangs_still_exits_with_its_status(procs, tmp_path):
    """CI failure: a simulator node was still running 120 s after its `done:` line (its launcher SIGKILLed, the
    machine loaded): nothing bounded the ROS teardown after the run. Now a node process whose teardown hangs
    (rclpy.shutdown made to sleep here) exits with its status after TEARDOWN_BUDGET s (set to 2 s), and says so."""
    bag = tmp_path / "bag"
    log = tmp_path / "sim.log"
    code = textwrap.dedent("""
        import sys, time
        import rclpy
        import gyro_sim.ros.common as common
        common.TEARDOWN_BUDGET = 2.0
        rclpy.shutdown = lambda *a, **k: time.sleep(1000)
        from gyro_sim.ros.simulator_node import main
        sys.argv = ["simulator"] + sys.argv[1:]
        sys.exit(main())
    """)
    p = procs.start([sys.executable, "-c", code, "--ros-args", "-p", "scene:=spinup_thin_shell", "-p",
                     "duration:=0.2", "-p", "mode:=freerun", "-p", f"record:={bag}"], log,
                    env=ros_env(unique_domain()))
    status = p.wait(timeout=START_TIMEOUT + END_TIMEOUT)
    text = log.read_text()
    print(f"\nstatus {status}; last lines: {text.strip().splitlines()[-2:]}")
    assert status == 0, text
    assert "the ROS teardown took more than 2 s; exiting with status 0" in text
    from gyro_sim.io.recording import bag_info

    assert bag_info(bag)["end_reason"] == "complete"



#: a simulator node whose Node.destroy_node blocks in C code holding the GIL (libc's sleep through ctypes.PyDLL,
#: which keeps the GIL): as the hang seen in 1 of 40 node exits under load, where no Python thread could run
GIL_HELD_TEARDOWN = textwrap.dedent("""
    import ctypes, sys, time
    import rclpy.node
    import gyro_sim.ros.common as common
    common.TEARDOWN_BUDGET, common.TEARDOWN_LAST = 2.0, 1.0
    def destroy_node(self):
        print(f"destroy_node hangs from {time.monotonic():.3f}", file=sys.stderr, flush=True)
        ctypes.PyDLL(None).sleep(1000)
    rclpy.node.Node.destroy_node = destroy_node
    from gyro_sim.ros.simulator_node import main
    sys.argv = ["simulator"] + sys.argv[1:]
    sys.exit(main())
""")


@needs_ros
def test_a_node_whose_teardown_hangs_holding_the_gil_exits_with_its_status(procs, tmp_path):
    """CI failure (test_lockstep_closed_loop_over_dds_equals_in_process): a simulator node finished its run, then
    hung in rclpy's Node.destroy_node holding the GIL; the teardown timer (a Python thread) never ran and
    faulthandler's watchdog ended the process with its own status 1, counted as a failed run. Now the GIL-free
    watchdog ends it with the run's status (0), after the threads' tracebacks, TEARDOWN_LAST + TEARDOWN_DUMP s after
    the budget (here 2 + 1 + 0.5 s)."""
    bag = tmp_path / "bag"
    log = tmp_path / "sim.log"
    p = procs.start([sys.executable, "-c", GIL_HELD_TEARDOWN, "--ros-args", "-p", "scene:=spinup_thin_shell", "-p",
                     "duration:=0.2", "-p", "mode:=freerun", "-p", f"record:={bag}"], log,
                    env=ros_env(unique_domain()))
    status = p.wait(timeout=START_TIMEOUT + END_TIMEOUT)
    ended = time.monotonic()
    text = log.read_text()
    m = re.search(r"destroy_node hangs from (\S+)", text)
    assert m, text
    print(f"\nstatus {status}, {ended - float(m.group(1)):.2f} s after destroy_node hung (the exit is due 3.5 s "
          "after the teardown began)")
    assert status == 0, text
    assert "Timeout (0:00:03)!" in text and "in destroy_node" in text  # (faulthandler's tracebacks, then the exit)
    assert "the ROS teardown took more than" not in text  # (the Python timer never ran: the GIL was held)
    from gyro_sim.io.recording import bag_info

    assert bag_info(bag)["end_reason"] == "complete"


#: the replay process (python -m gyro_sim.ros.replay) with the same destroy_node
GIL_HELD_REPLAY = GIL_HELD_TEARDOWN.replace("simulator_node import main", "replay import main").replace(
    '["simulator"]', '["replay"]')


@needs_ros
def test_a_replay_whose_teardown_hangs_holding_the_gil_exits_with_its_status(procs, tmp_path):
    """The replay's teardown was not bounded at all: a destroy_node that hangs (as the nodes' 1 in 40 under load) left
    the process running for good. Now it says its last line, then ends with its status (0) as a node does."""
    from gyro_sim.engine.simulate import run
    from gyro_sim.io.recording import record_result
    from gyro_sim.scenes.scene import load_scene

    bag = tmp_path / "bag"
    record_result(run(load_scene("spinup_thin_shell"), duration=0.05), bag)
    log = tmp_path / "replay.log"
    p = procs.start([sys.executable, "-c", GIL_HELD_REPLAY, str(bag), "100", "--startup-timeout", "1"], log,
                    env=ros_env(unique_domain()))
    try:
        status = p.wait(timeout=START_TIMEOUT)
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"the replay hung in its teardown: {log.read_text()}") from e
    text = log.read_text()
    print(f"\nstatus {status}; {[s for s in text.splitlines() if s.startswith('replay:')]}")
    assert status == 0, text
    assert re.search(r"^replay: published \d+ messages from ", text, re.M) and "in destroy_node" in text, text

#: a process that blocks in C code holding the GIL after exit_later(0.3, STATUS)
HELD_EXIT = textwrap.dedent("""
    import ctypes, sys
    from gyro_sim.ros.common import exit_later
    assert exit_later(0.3, int(sys.argv[1]))
    ctypes.PyDLL(None).sleep(1000)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="exit_later: a POSIX timer of Linux's libc")
@pytest.mark.parametrize("status", [0, 1, 130, 143])
def test_exit_later_ends_a_process_whose_gil_is_held_with_that_status(status):
    """The GIL-free exit of bound_teardown: the process ends with the status given, its only thread in C code
    holding the GIL (faulthandler's watchdog, which also needs no GIL, exits with 1 whatever the run's status)."""
    r = subprocess.run([sys.executable, "-c", HELD_EXIT, str(status)], capture_output=True, text=True,
                       timeout=END_TIMEOUT)
    assert r.returncode == status, r.stderr

# --- a signal handler takes no lock --------------------------------------------------------------

#: a child that raises the stop signal in its main thread while that thread holds the stop event's lock (as when
#: the group's Ctrl-C and the launcher's forwarded copy come µs apart: the second handler runs inside the first's
#: ``stop.set()``); another thread waits on the event meanwhile
HELD_STOP = textwrap.dedent("""
    import signal, sys, threading
    from gyro_sim.ros.common import StopEvent, exit_status, stop_on_signals
    stop = StopEvent()
    restore = stop_on_signals(stop)
    woke = []
    t = threading.Thread(target=lambda: woke.append(stop.wait(60)))
    t.start()
    with stop._cond:  # (inside stop.set() or stop.wait(): the event's lock is this thread's)
        signal.raise_signal(signal.SIGINT)  # (the handler runs here, in this thread)
        signal.raise_signal(signal.SIGTERM)
    t.join(60)
    print(stop.is_set(), stop.wait(0), woke, exit_status(stop), flush=True)
    restore()
""")


@needs_ros
def test_a_signal_that_comes_while_the_stop_event_is_held_stops_without_a_deadlock():
    """The simulator hung until SIGKILLed (1 run in 12 here, CI once) when the second of two SIGINTs came inside
    the first one's ``stop.set()``: the handler waited for the event's lock its own thread held. Bounded by a
    timeout: a deadlock fails the test instead of hanging the suite."""
    try:
        r = subprocess.run([sys.executable, "-c", HELD_STOP], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired as e:
        raise AssertionError("the signal handler waited for the lock its own thread held (deadlock)") from e
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "True", "[True]", "130"], r.stdout  # SIGINT came first: 130


@needs_ros
def test_the_controller_ended_flag_takes_no_lock():
    """CONTROLLER_ENDED_SIGNAL's handler sets a flag the loop reads and clears in the main thread; a lock there
    (a threading.Event) would deadlock a signal that comes inside clear()."""
    from gyro_sim.ros.common import SignalFlag
    from gyro_sim.ros.simulator_node import CONTROLLER_ENDED_SIGNAL, _controller_ended_signal
    flag = SignalFlag()
    assert not any(hasattr(v, "acquire") for v in vars(flag).values())
    with _controller_ended_signal(flag):
        signal.raise_signal(CONTROLLER_ENDED_SIGNAL)
        assert flag.is_set()
        flag.clear()
        assert not flag.is_set()
