"""Issue 30: the simulator node's bag written by a process of its own (gyro_sim.io.bag_process), so recording is off
the lockstep tick's critical path and the nodes can share one CPU by default. The bag must be the BagRecorder's,
message for message; the writer's failures must reach the node; a signal meant for the node must not end the
writer; the node killed (kill -9) leaves a closed bag. Read back with rosbags' reader and gyro_sim's."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.engine.runner import Runner
from gyro_sim.io.bag_process import _LOST, WRITER_CPUS_ENV, BagProcess
from gyro_sim.io.bag_writer import BagRecorder, RecordingError
from gyro_sim.io.recording import bag_info, read_bag
from gyro_sim.scenes.scene import load_scene

NAMES = ["x", "y", "z"]


def _feed(rec, duration: float = 0.3, euler: bool = False) -> int:
    """The default scene's samples and commands, tick by tick as the node writes them (Euler angles left to the
    writer unless ``euler``); returns the samples written."""
    r = Runner(load_scene("spinup_thin_shell"), duration, attitude=True)
    n = 0
    while not r.done:
        rows = r.advance()
        if rows.stop > rows.start:
            s = r.samples(rows, euler=euler, energy=False)
            rec.write_samples(s, NAMES)
            rec.write_command(float(s["t"][-1]), NAMES, s["current"][-1], s["rate"][-1])
            n += s["t"].size
        r.release()
    rec.write_status(duration, "done")
    rec.set_custom("gyro_sim.figure", 1.5)
    return n


def _messages(bag: Path) -> list:
    from rosbags.rosbag2 import Reader

    with Reader(bag) as r:
        return [(c.topic, t, bytes(raw)) for c, t, raw in r.messages()]


@pytest.mark.parametrize("euler", [False, True])
def test_the_writer_process_writes_the_bag_the_recorder_writes(tmp_path, euler):
    """Message for message and byte for byte, with the Euler angles computed in the writer or sent by the node."""
    with BagRecorder(tmp_path / "a", "name: x\n", "x") as rec:
        n_rec = _feed(rec, euler=True)
    with BagProcess(tmp_path / "b", "name: x\n", "x") as bp:
        n_proc = _feed(bp, euler=euler)
    a, b = _messages(tmp_path / "a"), _messages(tmp_path / "b")
    assert n_rec == n_proc > 10 and len(a) == len(b) > 7 * n_rec
    assert a == b
    assert bag_info(tmp_path / "b")["custom"]["gyro_sim.figure"] == "1.5"


def test_a_refused_target_is_refused_in_the_node_and_leaves_no_process(tmp_path):
    (tmp_path / "bag").mkdir()
    with pytest.raises(FileExistsError, match="bag"):
        BagProcess(tmp_path / "bag", "name: x\n", "x")
    with pytest.raises(ValueError, match="scene_name"):
        BagProcess(tmp_path / "b2", "name: x\n", "")
    assert not (tmp_path / "b2").exists()


def test_a_failure_in_the_writer_reaches_the_node(tmp_path):
    """A write the BagRecorder refuses (here a reserved custom_data key) fails in the child: the node hears of it
    at its next send (RecordingError naming the bag), and the bag is closed, readable, marked interrupted."""
    bp = BagProcess(tmp_path / "bag", "name: x\n", "x")
    _feed(bp, duration=0.1)
    bp.set_custom("gyro_sim.end", "x")  # (reserved: refused by the recorder)
    with pytest.raises(RecordingError, match="writer error: ValueError"):
        bp.close()
    assert bp.failed and bp.closed
    info = bag_info(tmp_path / "bag")
    assert info["end_reason"] == "interrupted: writer error: ValueError", info["end_reason"]
    assert read_bag(tmp_path / "bag").t.size > 0


def test_a_signal_for_the_node_does_not_end_the_writer(tmp_path):
    """SIGINT / SIGTERM reach the writer too where they go to a process group (a terminal's Ctrl-C): it ignores
    them and runs in a group of its own; the node decides how the bag ends."""
    bp = BagProcess(tmp_path / "bag", "name: x\n", "x")
    assert os.getpgid(bp._proc.pid) != os.getpgid(0)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        os.kill(bp._proc.pid, sig)
    n = _feed(bp, duration=0.1)
    bp.close()
    assert bp._proc.returncode == 0
    assert bag_info(tmp_path / "bag")["end_reason"] == "complete"
    assert read_bag(tmp_path / "bag").t.size == n


def test_kill_9_of_the_node_leaves_a_closed_bag(tmp_path):
    """The node killed (kill -9) after its writes reached the writer: the writer sees the socket close and closes
    the bag with everything sent, marked interrupted (before the writer process: an unfinished bag, no index)."""
    script = textwrap.dedent(f"""
        import os, signal, sys, time
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_bag_process import _feed
        from gyro_sim.io.bag_process import BagProcess, BATCH_WALL
        bp = BagProcess({str(tmp_path / "bag")!r}, "name: x\\n", "x")
        n = _feed(bp, duration=0.2)
        time.sleep(BATCH_WALL)
        bp.flush_due()
        print(n, bp._proc.pid, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
        """)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert p.returncode == -signal.SIGKILL, p.stderr
    n, pid = (int(v) for v in p.stdout.split())
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (tmp_path / "bag" / "metadata.yaml").exists():
        time.sleep(0.05)
    while time.monotonic() < deadline and Path(f"/proc/{pid}").exists():
        time.sleep(0.05)
    info = bag_info(tmp_path / "bag")
    assert info["end_reason"] == f"interrupted: {_LOST}", info["end_reason"]
    data = read_bag(tmp_path / "bag")
    assert data.t.size == n and n > 5


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs CPU affinity and two CPUs")
def test_the_writer_runs_on_the_cpus_it_is_given(tmp_path, monkeypatch):
    """With the nodes held to one CPU (--node-cpu auto), the launcher gives the writer the others
    (gyro_sim.ros.launch.writer_cpus_env): it works beside the nodes, not in their CPU's turns."""
    from gyro_sim.ros.launch import node_cpus, writer_cpus_env

    cpus = node_cpus("auto", "lockstep")
    env = writer_cpus_env(cpus)
    want = set(os.sched_getaffinity(0)) - cpus
    assert env == {WRITER_CPUS_ENV: ",".join(str(c) for c in sorted(want))}
    assert writer_cpus_env(None) == {}
    monkeypatch.setenv(WRITER_CPUS_ENV, env[WRITER_CPUS_ENV])
    with BagProcess(tmp_path / "bag", "name: x\n", "x") as bp:
        assert os.sched_getaffinity(bp._proc.pid) == want
        bp.write_status(0.0, "x")


def test_samples_with_effects_or_other_dtypes_go_as_they_are(tmp_path):
    """Rows the float matrix cannot carry (effects' states) are sent whole: the same bag as the recorder's."""
    t = np.array([0.0, 0.01])
    s = {"t": t, "L": np.ones((2, 3)), "q": np.tile([1.0, 0, 0, 0], (2, 1)), "omega_b": np.zeros((2, 3)),
         "euler": None, "torque": np.zeros((2, 3)), "current": np.ones((2, 3)), "rate": np.zeros((2, 3)),
         "phase": np.zeros((2, 3)), "effects": {"flywheel_omega": np.array([1.0, 2.0])}}
    rec = BagRecorder(tmp_path / "a", "name: x\n", "x")
    rec.write_samples(s, NAMES)
    rec.close()
    with BagProcess(tmp_path / "b", "name: x\n", "x") as bp:
        bp.write_samples(s, NAMES)
    assert _messages(tmp_path / "a") == _messages(tmp_path / "b")


def test_the_node_gone_while_the_writer_opens_leaves_a_closed_bag(tmp_path):
    """The node ends (kill -9, an exception) after sending the open, before the writer's reply: the writer sees the
    socket closed where it replies and closes the bag as interrupted, quietly (before: a BrokenPipeError traceback and
    a bag left unclosed, to be recovered)."""
    import pickle
    import socket
    from multiprocessing.connection import Connection

    from gyro_sim.io.bag_process import _CALL

    ours, theirs = socket.socketpair()
    conn = Connection(ours.detach())
    conn.send_bytes(pickle.dumps([_CALL + pickle.dumps(
        ("open", (str(tmp_path / "bag"), "name: x\n", "x", None, None, None, None), {}))]))
    conn.close()  # (the node gone)
    p = subprocess.run([sys.executable, "-m", "gyro_sim.io.bag_process", str(theirs.fileno())],
                       pass_fds=(theirs.fileno(),), capture_output=True, text=True, timeout=120)
    theirs.close()
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr
    assert bag_info(tmp_path / "bag")["end_reason"] == f"interrupted: {_LOST}"


def test_the_writer_imports_the_nodes_gyro_sim_not_the_working_directorys(tmp_path, monkeypatch):
    """A node started from a directory holding another gyro_sim (a source checkout beside an installed package,
    ``ros2 run`` from the repository): its writer runs the node's code (before: ``python -m`` put the working
    directory first on sys.path; here the writer died on the other package's import, status 1)."""
    (tmp_path / "gyro_sim").mkdir()
    (tmp_path / "gyro_sim" / "__init__.py").write_text("raise ImportError('not the node\\'s gyro_sim')\n")
    monkeypatch.chdir(tmp_path)
    with BagProcess("bag", "name: x\n", "x") as bp:  # (relative: the node's working directory)
        bp.write_status(0.0, "x")
    assert bag_info(tmp_path / "bag")["end_reason"] == "complete"


def test_a_bag_that_cannot_be_closed_ends_the_node_with_one_error_line(tmp_path):
    """The simulator node's writer fails as it closes the bag (here metadata.yaml cannot be written; as a disk
    that fills in the last writes, which the node hears of at its close): the node says so in one ``error`` line and
    exits 1, as for a failure mid-run (before: the RecordingError left Loop.run from its ``finally``: a traceback)."""
    pytest.importorskip("rclpy")
    from gyro_sim.ros.launch import node_command
    from gyro_sim.testing import ros_env, unique_domain

    bag = tmp_path / "bag"
    cmd = node_command("gyro_sim.ros.simulator_node", {
        "scene": "spinup_thin_shell", "mode": "freerun", "duration": 100000.0, "expect_controller": "false",
        "progress": "false", "record": str(bag)})
    p = subprocess.Popen(cmd, env=ros_env(unique_domain()), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None and not (bag / "bag.mcap").exists():
            time.sleep(0.05)
        (bag / "metadata.yaml").mkdir()  # (rosbags writes it last, at the close)
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 1, err[-3000:]
    assert "cannot write metadata.yaml" in err and "Traceback" not in err, err[-3000:]


def test_an_exception_in_the_node_run_does_not_leave_a_complete_bag(tmp_path):
    """The simulator node's loop raises (a bug: here its sample publishing, once the run is under way): its bag is
    closed marked ``interrupted: <the exception>`` (before: ``complete``, a bag cut short that says it is whole)."""
    pytest.importorskip("rclpy")
    from gyro_sim.testing import ros_env, unique_domain

    bag = tmp_path / "bag"
    script = textwrap.dedent(f"""
        import sys
        from gyro_sim.ros import simulator_node as m
        publish = m.Loop.publish_samples
        def publish_samples(self, rows):
            if self.runner.sim.t > 0.2:
                raise RuntimeError("a bug")
            publish(self, rows)
        m.Loop.publish_samples = publish_samples
        sys.argv = ["simulator", "--ros-args", "-p", "scene:=spinup_thin_shell", "-p", "mode:=freerun",
                    "-p", "duration:=100000.0", "-p", "expect_controller:=false", "-p", "progress:=false",
                    "-p", "record:={bag}"]
        sys.exit(m.main())
        """)
    p = subprocess.run([sys.executable, "-c", script], env=ros_env(unique_domain()), capture_output=True, text=True,
                       timeout=180)
    assert p.returncode == 1 and "RuntimeError: a bug" in p.stderr, p.stderr[-3000:]
    info = bag_info(bag)
    assert info["end_reason"] == "interrupted: RuntimeError (a bug)", info["end_reason"]
    assert 0.2 <= read_bag(bag).t[-1] < 1.0


def test_no_rows_write_nothing_as_the_recorders_do(tmp_path):
    """write_samples of a run's arrays with no rows: nothing written, as the BagRecorder (before: ValueError, numpy's
    reshape of an empty array to (0, -1))."""
    s = {k: np.zeros((0, w)) for k, w in (("L", 3), ("q", 4), ("omega_b", 3), ("torque", 3), ("current", 3),
                                           ("rate", 3), ("phase", 3))}
    s.update(t=np.zeros(0), euler=None)
    with BagProcess(tmp_path / "b", "name: x\n", "x") as bp:
        bp.write_samples(s, NAMES)
        bp.write_status(0.0, "x")
    assert bag_info(tmp_path / "b")["end_reason"] == "complete"
    assert read_bag(tmp_path / "b").t.size == 0
