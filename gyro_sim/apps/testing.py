"""Test your controller against the simulator, in your own pytest suite.

A pytest plugin, opt-in (``pytest -p gyro_sim.testing``, or ``pytest_plugins = ["gyro_sim.testing"]`` in a
``conftest.py``; its public name is :mod:`gyro_sim.testing`): a test then gets the :func:`gyro_bench` fixture: a
:class:`GyroBench` working in the test's ``tmp_path``. A run starts the simulator node as a process (lockstep by
default, recording a bag), on a ROS domain of its own (a free ``ROS_DOMAIN_ID`` in 1–101,
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), starts your controller — any command line — with the same environment (:attr:`GyroBench.env`), waits for the end of the run and gives a
:class:`BenchRun`: the run as a :class:`gyro_sim.simulate.RunResult` (the type :func:`gyro_sim.run` returns),
the bag, the simulator's status lines and final figures::

    def test_my_controller(gyro_bench):
        run = gyro_bench.run("spinup_thin_shell", duration=3.0,
                             controller="python -m my_pkg.controller --ros-args -p gain:=2.0")
        run.assert_spin_reached(50.0, by=3.0)      # rad/s
        run.assert_no_refusals()

A controller that never answers, or answers with the wrong stamps, fails the test with
:class:`ControllerError` (an AssertionError) saying what the simulator saw and what the protocol wants. Every
process the bench starts is ended at teardown (SIGINT to its process group, then SIGKILL), also when the test
fails.

This module imports neither rclpy nor the recording code at import time (the nodes run as processes).
"""
from __future__ import annotations

import atexit
import itertools
import math
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence, Union

__all__ = ["GyroBench", "BenchRun", "BenchError", "ControllerError", "gyro_bench", "unique_domain",
           "result_from_bag", "parse_done_line", "assert_spin_reached", "assert_theta_below",
           "assert_no_refusals", "assert_watchdog_never_fired", "PROTOCOL"]

#: what a controller has to do, quoted in the errors
PROTOCOL = ("answer each state the simulator publishes on gyro/kinetic_moment / gyro/imu with a "
            "sensor_msgs/JointState on gyro/stator_commands carrying that state's header stamp (simulation "
            "time; an empty JointState = no change); see docs/protocol.md")
#: the kit's default wall s to wait for the controller (its subscriptions, then its first command): a bound, not a
#: timing (a Python ROS node's start and discovery took over 30 s, the node's own default, on this 2-core CI
#: machine under the load of two test suites: the examples' user suite failed there); a controller that never
#: answers still fails, after this long
STARTUP_TIMEOUT = 120.0
#: default wall s bound of a whole run (the simulator's own waits are bounded by startup_timeout / watchdog)
RUN_TIMEOUT = 600.0
STOP_GRACE = 10.0  # wall s between SIGINT and SIGKILL at teardown

# simulator parameter types (a value is sent as the type the node declared: an int for a double is refused)
_FLOAT = {"rate_factor", "duration", "control_period", "watchdog_timeout", "startup_timeout"}
_INT = {"wait_for_subscribers", "step_ticks"}
_BOOL = {"expect_controller", "start_paused", "progress"}
_LOG_LINE = re.compile(r"^\[(\w+)\] \[[^\]]*\] \[[^\]]*\]: (.*)$")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_LOG_FORMAT = "[{severity}] [{time}] [{name}]: {message}"


# --- ROS domains ------------------------------------------------------------------------------

_domains = itertools.count((os.getpid() * 7) % 101)
_used: set = set()
#: the machine-wide claims this process holds, by domain: an abstract Unix socket named for the domain, bound while
#: the domain is in use (released by :func:`release_domain` or when the process ends)
_claims: dict = {}


def _domain_is_free(d: int) -> bool:
    """No DDS participant of domain ``d`` on this machine: participant 0's discovery port (Fast DDS and the
    RTPS default: 7400 + 250 d + 10) can be bound."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", 7410 + 250 * d))
            return True
        except OSError:
            return False


def _claim(d: int) -> Optional[socket.socket]:
    """Claim domain ``d`` on this machine (Linux's abstract socket namespace: the name goes with the process), or
    None where another process holds it. Without a claim, two test sessions on one machine could pick the same
    domain in the second or two before either's first node joined it, and each then saw the other's nodes (seen:
    two CI suites side by side, a probe reading another session's simulator)."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        s.bind(f"\0gyro_sim.ros_domain.{d}")
    except OSError:
        s.close()
        return None
    return s


def unique_domain() -> int:
    """A ROS_DOMAIN_ID for one test: 1–101 (ROS's advice on Linux: their ports stay below the ephemeral
    range 32768–60999, so no passing socket takes one), not used by this process, claimed by no other process of
    this package on the machine (until :func:`release_domain` or this process's end) and with no DDS participant
    in it (the start is spread by the process id, so parallel sessions pick apart)."""
    for _ in range(101):
        d = 1 + next(_domains) % 101
        if d in _used:
            continue
        claim = _claim(d)
        if claim is None:
            continue
        if not _domain_is_free(d):
            claim.close()
            continue
        _used.add(d)
        _claims[d] = claim
        return d
    raise RuntimeError("no free ROS domain id in 1-101")


def release_domain(d: int) -> None:
    """Give up this process's claim on domain ``d`` (its nodes have ended); this process does not use it again."""
    claim = _claims.pop(d, None)
    if claim is not None:
        claim.close()


def ros_env(domain: int, base: Optional[Mapping[str, str]] = None) -> dict:
    """``base`` (default os.environ) with ROS_DOMAIN_ID = ``domain``, DDS kept on this machine and unbuffered
    Python output."""
    return dict(os.environ if base is None else base, ROS_DOMAIN_ID=str(domain),
                ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")


# --- errors -----------------------------------------------------------------------------------

class BenchError(AssertionError):
    """A bench run failed: the simulator could not run the scene, or the run did not end in time."""


class ControllerError(BenchError):
    """The controller broke the protocol. ``kind``: ``no_answer`` (no command applied in the whole run, or nothing
    subscribed within startup_timeout), ``wrong_stamps`` (a command refused for its stamp) or ``exited`` (the
    controller process ended with an error while the simulator ran). ``status_line``: the simulator's line
    quoted; ``run``: the :class:`BenchRun` (bag, status) where the simulator left one."""

    def __init__(self, message: str, kind: str, status_line: Optional[str] = None, run: Optional["BenchRun"] = None):
        super().__init__(message)
        self.kind, self.status_line, self.run = kind, status_line, run


# --- processes --------------------------------------------------------------------------------

_live: list = []  # every process a bench started and has not ended: ended at exit as a last resort


def _end(proc: subprocess.Popen, grace: float = STOP_GRACE) -> None:
    """SIGINT to the process group, SIGKILL after ``grace`` s; then SIGKILL to what is left of the group (a
    wrapper's children)."""
    try:
        pgid = os.getpgid(proc.pid)
    except ProcessLookupError:
        pgid = None
    if proc.poll() is None:
        _signal_group(proc, pgid, signal.SIGINT)
        try:
            proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            _signal_group(proc, pgid, signal.SIGKILL)
            proc.wait()
    if pgid is not None and pgid == proc.pid:  # its own group (start_new_session): sweep the rest
        try:
            os.killpg(pgid, 0)
        except (ProcessLookupError, PermissionError):
            pass
        else:
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                try:
                    os.killpg(pgid, 0)
                except (ProcessLookupError, PermissionError):
                    break
                time.sleep(0.05)
            else:
                try:
                    os.killpg(pgid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
    if proc in _live:
        _live.remove(proc)


def _signal_group(proc: subprocess.Popen, pgid: Optional[int], sig: int) -> None:
    try:
        if pgid is not None and pgid == proc.pid:
            os.killpg(pgid, sig)
        else:
            proc.send_signal(sig)
    except (ProcessLookupError, PermissionError):
        pass


@atexit.register
def _end_all() -> None:
    for p in list(_live):
        _end(p, grace=2.0)


def command_argv(command: Union[str, Sequence[str]]) -> list:
    """A command line as an argv list (a string is split like a shell would); a leading ``python`` or ``python3``
    is this interpreter (``sys.executable``: the environment gyro_sim and the tests run in)."""
    argv = shlex.split(command) if isinstance(command, str) else [str(a) for a in command]
    if not argv:
        raise ValueError("empty command")
    if argv[0] in ("python", "python3"):
        argv[0] = sys.executable
    return argv


def _param_args(params: Mapping[str, Any]) -> list:
    out = []
    for k, v in params.items():
        if k in _BOOL or isinstance(v, bool):
            text = "true" if v else "false"
        elif k in _FLOAT:
            text = repr(float(v))
        elif k in _INT:
            text = str(int(v))
        elif isinstance(v, float):
            text = repr(v)
        elif isinstance(v, (list, tuple)):
            text = "[" + ", ".join(repr(x) if isinstance(x, (str, float)) else str(x) for x in v) + "]"
        else:
            text = str(v)
        out += ["-p", f"{k}:={text}"]
    return out


class _Simulator:
    """The simulator process of one run; a thread reads its output and watches the status lines."""

    def __init__(self, argv: list, env: dict, log: Path, watch):
        self.log = log
        self.lines: list = []  # its output, as printed
        self.status: list = []  # its log messages (gyro/status lines among them)
        self.watch = watch
        self.proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     errors="replace", start_new_session=True)
        _live.append(self.proc)
        self.thread = threading.Thread(target=self._read, name="gyro_bench-simulator-output", daemon=True)
        self.thread.start()

    def _read(self) -> None:
        with open(self.log, "w") as f:
            for raw in self.proc.stdout:
                line = _ANSI.sub("", raw.rstrip("\n"))
                f.write(line + "\n")
                f.flush()
                self.lines.append(line)
                m = _LOG_LINE.match(line)
                if m:
                    self.status.append(m.group(2))
                    self.watch(m.group(2))

    @property
    def output(self) -> str:
        return "\n".join(self.lines)


# --- results ----------------------------------------------------------------------------------

#: status lines of a silent controller: the watchdog (real time, free run) and a lost controller (lockstep)
SILENCE_LINES = ("watchdog: no command", "controller lost")

_DONE = {
    "t_end": r"done: t = (\S+) s",
    "wall_s": r" in (\S+) s wall",
    "real_time_factor": r"\((\S+)x real time\)",
    "control_ticks": r"(\d+) control ticks",
    "ticks_per_s": r"control ticks \((\S+)/s\)",
    "steps": r"(\d+) steps",
    "refused": r"(\d+) commands refused",
    "latency_median_ms": r"median (\S+) ms",
    "latency_p99_ms": r"p99 (\S+) ms",
    "latency_max_ms": r"max (\S+) ms",
    "compile_s": r"\(\+ (\S+) s compiling",
}


def parse_done_line(line: str) -> dict:
    """The figures of the simulator's final ``done: ...`` status line: t_end, wall_s, real_time_factor,
    control_ticks, ticks_per_s, steps, refused, latency_median_ms / _p99_ms / _max_ms (None: no command
    answered a published state), compile_s (0 when nothing compiled), interrupted, line. A figure the line does
    not hold is None."""
    out: dict = {"line": line, "interrupted": line.rstrip().endswith("(interrupted)")}
    for key, pattern in _DONE.items():
        m = re.search(pattern, line)
        if m is None:
            out[key] = 0.0 if key == "compile_s" else None
        elif key in ("control_ticks", "steps", "refused"):
            out[key] = int(m.group(1))
        else:
            out[key] = float(m.group(1))
    return out


def _start_figures(line: str) -> dict:
    """scene, mode, duration (s, exact), controller_expected of the ``simulator: ...`` start line."""
    out: dict = {"controller_expected": "controller expected" in line}
    m = re.search(r"mode (\w+)", line)
    out["mode"] = m.group(1) if m else None
    m = re.search(r"duration (\S+) s", line)
    out["duration"] = float(m.group(1)) if m else None
    return out


def result_from_bag(bag, scene=None, duration: Optional[float] = None, control_period: Optional[float] = None):
    """A :class:`gyro_sim.simulate.RunResult` of a bag the simulator node recorded (a path, or its
    :class:`~gyro_sim.recording.BagData`): :func:`gyro_sim.read_bag` (gyro_sim/io/results.py), imported on first use
    (this plugin loads in every pytest session)."""
    from gyro_sim.io.results import read_bag

    return read_bag(bag, scene, duration=duration, control_period=control_period)


@dataclass
class BenchRun:
    """One simulator run of a :class:`GyroBench`.

    ``result``: the run as a :class:`gyro_sim.simulate.RunResult` (from the bag: :func:`result_from_bag`);
    ``data``: the bag as read (:class:`gyro_sim.recording.BagData`); ``bag``: its path; ``status`` /
    ``status_t``: the simulator's gyro/status lines and their simulation times (s); ``figures``: the final
    ``done:`` line parsed (:func:`parse_done_line`; ticks_per_s, refused, latency_median_ms...), plus the start
    line's mode and controller_expected; ``stdout``: the simulator's output; ``controller_output``: that of the
    processes the bench started for this run (None if none); ``returncode``: the simulator's exit status.
    """

    scene: str
    bag: Path
    result: Any
    data: Any
    status: list
    status_t: Any
    figures: dict
    stdout: str
    controller_output: Optional[str] = None
    returncode: Optional[int] = None
    params: dict = field(default_factory=dict)

    @property
    def refusals(self) -> list:
        """The ``refused command: ...`` status lines."""
        return [s for s in self.status if s.startswith("refused command")]

    @property
    def watchdog_events(self) -> list:
        """(t s, line) of each time the watchdog fired or (lockstep) the controller was lost."""
        return [(float(t), s) for t, s in zip(self.status_t, self.status) if s.startswith(SILENCE_LINES)]

    def assert_spin_reached(self, rate: float, by: Optional[float] = None) -> None:
        assert_spin_reached(self, rate, by)

    def assert_theta_below(self, bound: float, after: float = 0.0) -> None:
        assert_theta_below(self, bound, after)

    def assert_no_refusals(self) -> None:
        assert_no_refusals(self)

    def assert_watchdog_never_fired(self) -> None:
        assert_watchdog_never_fired(self)


# --- assertion helpers ------------------------------------------------------------------------

def _result(run):
    return run.result if isinstance(run, BenchRun) else run


def assert_spin_reached(run, rate: float, by: Optional[float] = None) -> None:
    """The spin rate (Ω3, :attr:`RunResult.spin_rate`) reached ``rate`` rad/s at some sample at or before time
    ``by`` s (None: in the whole run). ``run``: a :class:`BenchRun` or a RunResult."""
    import numpy as np

    r = _result(run)
    t, spin = np.asarray(r.t), np.asarray(r.spin_rate)
    if not t.size:
        raise AssertionError(f"spin rate ≥ {rate:g} rad/s: the run has no samples")
    mask = np.ones(t.size, bool) if by is None else t <= by + 1e-9 * max(1.0, abs(by))
    when = "in the run" if by is None else f"by t = {by:g} s"
    if mask.any() and np.nanmax(np.where(mask, spin, -np.inf)) >= rate:
        return
    i = int(np.nanargmax(np.where(mask, spin, -np.inf))) if mask.any() else 0
    ended = f"; the run ended at t = {t[-1]:.6g} s" if by is not None and t[-1] < by else ""
    raise AssertionError(f"spin rate {rate:g} rad/s not reached {when}: at most {spin[i]:.6g} rad/s (at t = "
                         f"{t[i]:.6g} s); {spin[-1]:.6g} rad/s at the last sample, t = {t[-1]:.6g} s{ended}")


def assert_theta_below(run, bound: float, after: float = 0.0) -> None:
    """The nutation angle θ (rad, :attr:`RunResult.theta`) stays below ``bound`` rad at every sample from time
    ``after`` s on. ``run``: a :class:`BenchRun` or a RunResult."""
    import numpy as np

    r = _result(run)
    t, theta = np.asarray(r.t), np.asarray(r.theta)
    mask = t >= after - 1e-9 * max(1.0, abs(after))
    if not mask.any():
        raise AssertionError(f"θ below {bound:g} rad after t = {after:g} s: no sample after it (the run ended at "
                             f"t = {t[-1] if t.size else math.nan:.6g} s)")
    th = np.where(mask, theta, -np.inf)
    if np.isnan(th).any():
        i = int(np.flatnonzero(np.isnan(th))[0])
        raise AssertionError(f"θ below {bound:g} rad after t = {after:g} s: θ is NaN at t = {t[i]:.6g} s")
    i = int(np.argmax(th))
    if th[i] < bound:
        return
    raise AssertionError(f"θ = {th[i]:.6g} rad ({math.degrees(th[i]):.4g}°) at t = {t[i]:.6g} s, not below "
                         f"{bound:g} rad ({math.degrees(bound):.4g}°) after t = {after:g} s; θ at the last sample "
                         f"(t = {t[-1]:.6g} s): {theta[-1]:.6g} rad ({math.degrees(theta[-1]):.4g}°)")


def assert_no_refusals(run: BenchRun) -> None:
    """The simulator refused no command (the count of the final ``done:`` line; the refusal lines if the run
    has none)."""
    lines = run.refusals
    n = run.figures.get("refused")
    n = len(lines) if n is None else n
    if n == 0 and not lines:
        return
    shown = "; ".join(repr(s) for s in lines[:3]) + (f" (and {len(lines) - 3} more lines)" if len(lines) > 3 else "")
    raise AssertionError(f"the simulator refused {n} command(s): {shown}")


def assert_watchdog_never_fired(run: BenchRun) -> None:
    """The simulator's watchdog never fired and (lockstep) its controller was never lost (no ``watchdog: no command
    ...`` or ``controller lost ...`` status line)."""
    ev = run.watchdog_events
    if not ev:
        return
    what = ("the controller was lost" if ev[0][1].startswith("controller lost") else "the watchdog fired")
    raise AssertionError(f"{what} {len(ev)} time(s), first at t = {ev[0][0]:.9g} s: {ev[0][1]!r} "
                         "(no valid command for watchdog_timeout wall s, or lockstep's controller gone: see "
                         "on_controller_lost)")


# --- the bench --------------------------------------------------------------------------------

class GyroBench:
    """Runs the simulator node against a controller process, on a ROS domain of its own.

    ``workdir``: where bags and logs go (the fixture gives the test's ``tmp_path``; default: a new temporary
    directory). ``env``: the environment the nodes run with (``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE=
    LOCALHOST``): start a controller of your own with it (``subprocess.Popen(cmd, env=bench.env)``, or
    :meth:`spawn`, which also ends it) between :meth:`start` and :meth:`wait`; or give :meth:`run` its command.
    Runs are one after the other; :meth:`close` (the fixture's teardown) ends every process still running.
    """

    def __init__(self, workdir: Union[str, os.PathLike, None] = None, domain: Optional[int] = None):
        self.workdir = Path(workdir) if workdir is not None else Path(tempfile.mkdtemp(prefix="gyro_bench-"))
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.domain = domain if domain is not None else unique_domain()
        self.env = ros_env(self.domain)
        self.runs: list = []  # the BenchRuns so far
        self._n = 0
        self._sim: Optional[_Simulator] = None
        self._spawned: list = []  # (name, Popen, log path, argv) of the present run
        self._session: dict = {}
        self._running_at_end: set = set()
        self._output_at_end: dict = {}

    # --- one run ---------------------------------------------------------------------------
    def start(self, scene: Union[str, os.PathLike] = "spinup_thin_shell", *, duration: Optional[float] = None,
              mode: str = "lockstep", expect_controller: Optional[bool] = True,
              startup_timeout: float = STARTUP_TIMEOUT, watchdog_timeout: Optional[float] = None,
              wait_for_subscribers: int = 1, params: Optional[Mapping[str, Any]] = None,
              fail_fast: bool = True) -> "GyroBench":
        """Start the simulator node for ``scene`` (a built-in name or a YAML path), recording a bag in the work
        directory. ``duration``: simulated s (None: the scene's). ``expect_controller``: lockstep waits for a
        controller's command at each tick and the watchdog watches it (None: the scene's default: where it has a
        controller section). ``startup_timeout``: wall s to wait for ``wait_for_subscribers`` subscriptions to the
        simulator's topics (the controller's: its start-up is not part of the run), then for its first command.
        ``watchdog_timeout``: None = the node's default (2 s). ``params``: any other simulator parameter (as
        ``-p name:=value``). ``fail_fast``: end the run at once (:class:`ControllerError`) on a command refused
        for its stamp, when nothing subscribed within startup_timeout, or when a process :meth:`spawn` started
        exits with an error."""
        if self._sim is not None:
            raise RuntimeError("GyroBench.start: a run is under way; wait() for it first")
        params = dict(params or {})
        for k in ("scene", "record"):
            if k in params:
                raise ValueError(f"GyroBench.start: parameter {k!r} is the bench's (give scene=; the bench records)")
        self._n += 1
        tag = f"run{self._n}"
        bag = self.workdir / f"{tag}_bag"
        full = {"scene": str(scene), "mode": mode}
        if duration is not None:
            full["duration"] = duration
        if expect_controller is not None:
            full["expect_controller"] = bool(expect_controller)
        full["startup_timeout"] = startup_timeout
        if watchdog_timeout is not None:
            full["watchdog_timeout"] = watchdog_timeout
        if wait_for_subscribers:
            full["wait_for_subscribers"] = int(wait_for_subscribers)
        full.update(params)
        full["record"] = str(bag)
        self._session = {"scene": str(scene), "bag": bag, "params": full, "fail_fast": fail_fast, "fatal": None,
                         "tag": tag, "fatal_event": threading.Event()}
        argv = [sys.executable, "-m", "gyro_sim.ros.simulator_node", "--ros-args", *_param_args(full)]
        env = dict(self.env, RCUTILS_CONSOLE_OUTPUT_FORMAT=_LOG_FORMAT, RCUTILS_COLORIZED_OUTPUT="0")
        self._spawned = []
        self._sim = _Simulator(argv, env, self.workdir / f"{tag}_simulator.log", self._watch)
        return self

    def spawn(self, command: Union[str, Sequence[str]], *, name: str = "controller",
              cwd: Union[str, os.PathLike, None] = None, env: Optional[Mapping[str, str]] = None) -> subprocess.Popen:
        """Start ``command`` (a controller; a string is split like a shell's; a leading ``python`` is this
        interpreter) with :attr:`env` (plus ``env``), its output to ``<workdir>/<run>_<name>.log``, in a process
        group of its own; it is ended (SIGINT, then SIGKILL) when the run ends and at :meth:`close`."""
        argv = command_argv(command)
        tag = self._session.get("tag", f"run{self._n}")
        log = self.workdir / f"{tag}_{name}.log"
        with open(log, "w") as f:
            p = subprocess.Popen(argv, env=dict(self.env, **(env or {})), cwd=cwd, stdout=f,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        _live.append(p)
        self._spawned.append((name, p, log, argv))
        return p

    def wait(self, timeout: float = RUN_TIMEOUT) -> BenchRun:
        """Wait (≤ ``timeout`` wall s) for the simulator's run to end; end the processes :meth:`spawn` started;
        return the :class:`BenchRun`. Raises :class:`ControllerError` when the controller never answered, answered
        with the wrong stamps, or exited with an error meanwhile; :class:`BenchError` when the simulator failed or
        the run did not end within ``timeout``."""
        sim, s = self._sim, self._session
        if sim is None:
            raise RuntimeError("GyroBench.wait: no run started (call start() or run())")
        timed_out = False
        try:
            deadline = time.monotonic() + timeout
            while sim.proc.poll() is None:
                if s["fatal"] is None:
                    self._check_spawned()
                if s["fatal"] is not None or time.monotonic() > deadline:
                    timed_out = s["fatal"] is None
                    _end(sim.proc)  # SIGINT: the node closes the bag, marked interrupted
                    break
                s["fatal_event"].wait(0.05)
            sim.proc.wait()
            sim.thread.join(timeout=10.0)
        finally:
            # their output before the bench ends them (not the traceback of the SIGINT that ends them)
            self._output_at_end = {p.pid: _read_text(log) for _, p, log, _ in self._spawned}
            self._running_at_end = {p.pid for _, p, _, _ in self._spawned if p.poll() is None}
            for _, p, _, _ in self._spawned:
                _end(p)
            if sim.proc.poll() is None:
                _end(sim.proc)
            if sim.proc in _live:
                _live.remove(sim.proc)
            self._sim = None
        return self._conclude(sim, timed_out, timeout)

    def run(self, scene: Union[str, os.PathLike] = "spinup_thin_shell",
            controller: Union[str, Sequence[str], None] = None, *, timeout: float = RUN_TIMEOUT,
            cwd: Union[str, os.PathLike, None] = None, **start_kw) -> BenchRun:
        """:meth:`start` the simulator for ``scene`` (keywords: those of :meth:`start`), :meth:`spawn`
        ``controller`` (a command line; ``cwd``: its working directory), then :meth:`wait` (≤ ``timeout`` wall s).
        To run a controller you start yourself, use start(), your process with :attr:`env`, then wait()."""
        self.start(scene, **start_kw)
        try:
            if controller is not None:
                self.spawn(controller, cwd=cwd)
        except BaseException:
            self.close()
            raise
        return self.wait(timeout)

    def close(self) -> None:
        """End every process of the present run (SIGINT to its group, SIGKILL after a grace period)."""
        for _, p, _, _ in self._spawned:
            _end(p)
        if self._sim is not None:
            _end(self._sim.proc)
            self._sim.thread.join(timeout=10.0)
            self._sim = None

    def __enter__(self) -> "GyroBench":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- watching and concluding -----------------------------------------------------------------
    def _watch(self, line: str) -> None:
        """A status line of the running simulator (reader thread): the protocol failures that end a run early."""
        s = self._session
        if not s.get("fail_fast") or s.get("fatal") is not None:
            return
        if line.startswith("refused command: stamp = "):
            s["fatal"] = ("wrong_stamps", line)
        elif re.match(r"wait_for_subscribers = \d+: 0 matched", line):
            s["fatal"] = ("never_subscribed", line)
        if s.get("fatal") is not None:
            s["fatal_event"].set()

    def _check_spawned(self) -> None:
        """A spawned controller that exited with an error while the simulator runs: the run cannot go on well."""
        if not self._session.get("fail_fast"):
            return
        for name, p, _log, _argv in self._spawned:
            code = p.poll()
            if code not in (None, 0):
                self._session["fatal"] = ("exited", f"{name} exited with status {code}")
                return

    def _controllers(self) -> str:
        """What the bench knows of the controller processes, for the error messages."""
        if not self._spawned:
            return ("The bench did not start the controller: was it started with bench.env (ROS_DOMAIN_ID="
                    f"{self.domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)?")
        parts = []
        for name, p, log, argv in self._spawned:
            state = ("was still running when the run ended" if p.pid in self._running_at_end
                     else f"exited with status {p.returncode}")
            shown = shlex.join(a if len(a) <= 80 else a[:77].split("\n")[0] + "..." for a in argv)
            text = self._output_at_end.get(p.pid, _read_text(log))
            parts.append(f"The {name} ({shown}) {state}; its output ({log}) "
                         + (f"ends with:\n{_tail(text)}" if text.strip() else "is empty"))
        return "\n".join(parts)

    def _conclude(self, sim: _Simulator, timed_out: bool, timeout: float) -> BenchRun:
        s = self._session
        bag, params = s["bag"], s["params"]
        ctl_out = "\n".join(f"--- {name} ---\n{_read_text(log)}" for name, _, log, _ in self._spawned) or None
        run = None
        if (bag / "metadata.yaml").exists():
            run = self._bench_run(sim, bag, params, ctl_out)
        if timed_out:
            raise BenchError(f"the run of scene {s['scene']!r} did not end within {timeout:g} s wall (GyroBench.wait "
                             f"timeout); the simulator's output ends with:\n{_tail(sim.output)}")
        fatal = s["fatal"]
        if fatal is not None:
            kind, line = fatal
            if kind == "wrong_stamps":
                raise ControllerError(
                    f"the controller answers with wrong stamps: the simulator refused its command:\n  {line!r}\n"
                    f"A controller must {PROTOCOL}.\n{self._controllers()}", "wrong_stamps", line, run)
            if kind == "never_subscribed":
                raise ControllerError(
                    "the controller never answered: nothing subscribed to the simulator's topics within "
                    f"startup_timeout = {params.get('startup_timeout', STARTUP_TIMEOUT):g} s. The simulator said:\n"
                    f"  {line!r}\nA controller must {PROTOCOL}.\n{self._controllers()}", "no_answer", line, run)
            raise ControllerError(f"the controller process ended with an error while the simulator ran ({line}).\n"
                                  f"{self._controllers()}", "exited", line, run)
        start = _start_figures(next((x for x in run.status if x.startswith("simulator:")), "")) if run else {}
        if run is not None and start.get("controller_expected") and not _answered(run):
            line = (next((x for x in run.status if x.startswith("refused command: stamp")), None)
                    or next((x for x in run.status if x.startswith(SILENCE_LINES)), None))
            stamps = line is not None and line.startswith("refused command: stamp")
            what = ("the controller answered only with wrong stamps: no command was applied in the run"
                    if stamps else "the controller never answered: no command was applied in the whole run")
            said = (f" The simulator said:\n  {line!r}" if line else
                    f" The simulator's last line:\n  {run.status[-1]!r}" if run.status else "")
            raise ControllerError(f"{what} (scene {s['scene']!r}, mode {start['mode']}; startup_timeout = "
                                  f"{params.get('startup_timeout', STARTUP_TIMEOUT):g} s).{said}\n"
                                  f"A controller must {PROTOCOL}.\n{self._controllers()}",
                                  "wrong_stamps" if stamps else "no_answer", line, run)
        if sim.proc.returncode != 0 or run is None:
            raise BenchError(f"the simulator (scene {s['scene']!r}) exited with status {sim.proc.returncode}"
                             + ("" if run is not None else " and left no bag") + "; its output ends with:\n"
                             + _tail(sim.output))
        return run

    def _bench_run(self, sim: _Simulator, bag: Path, params: dict, ctl_out: Optional[str]) -> BenchRun:
        from gyro_sim.io.recording import read_bag

        data = read_bag(bag)
        done = next((x for x in reversed(data.status) if x.startswith("done:")), None)
        figures = parse_done_line(done) if done else {"line": None, "interrupted": True}
        start_line = next((x for x in data.status if x.startswith("simulator:")), "")
        start = _start_figures(start_line)
        figures.update(mode=start["mode"], controller_expected=start["controller_expected"])
        try:
            result = result_from_bag(data, self._session["scene"], duration=start["duration"])
        except Exception as e:  # noqa: BLE001 - a bag without samples (a run ended before its first)
            result = None
            figures["result_error"] = f"{type(e).__name__}: {e}"
        run = BenchRun(scene=self._session["scene"], bag=bag, result=result, data=data, status=list(data.status),
                       status_t=data.status_t, figures=figures, stdout=sim.output, controller_output=ctl_out,
                       returncode=sim.proc.returncode, params=dict(params))
        self.runs.append(run)
        return run


def _answered(run: BenchRun) -> bool:
    """Whether any controller command was applied: a command answered a published state (the latency figures
    are finite), or the bag holds a command other than the watchdog's zeroing."""
    med = run.figures.get("latency_median_ms")
    if med is not None and not math.isnan(med):
        return True
    fired = {round(t * 1e9) for t, _ in run.watchdog_events}
    return any(round(t * 1e9) not in fired for t in run.data.command_t.tolist())


def _read_text(path: Path) -> str:
    try:
        return Path(path).read_text(errors="replace")
    except OSError:
        return ""


def _tail(text: str, n: int = 15) -> str:
    lines = text.rstrip().splitlines()[-n:]
    return "\n".join("  | " + x for x in lines) if lines else "  | (no output)"


# --- the pytest plugin ------------------------------------------------------------------------

try:
    import pytest
except ImportError:  # pragma: no cover - used without pytest: GyroBench alone
    pytest = None

if pytest is not None:
    @pytest.fixture
    def gyro_bench(tmp_path):
        """A :class:`GyroBench` working in the test's ``tmp_path``; every process it started is ended at
        teardown, also when the test fails."""
        bench = GyroBench(tmp_path)
        try:
            yield bench
        finally:
            bench.close()
else:  # pragma: no cover
    gyro_bench = None
