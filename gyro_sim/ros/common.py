"""Pieces shared by the simulator and controller nodes: message classes, QoS, command parsing, signals."""
from __future__ import annotations

import importlib
import itertools
import math
import numbers
import signal
import threading
import time
from collections import Counter
from typing import Callable, Iterable, Optional

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from gyro_sim.io.messages import QOS, stamp_ns
from gyro_sim.scenes.limits import real_value
from gyro_sim.scenes.scene_text import clip, preview
from gyro_sim.io.signals import signal_name
from gyro_sim.ros.launch import PARENT_PID_ENV, STOP_SIGNALS  # (launch.py: no rclpy)

_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE, "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}


def message_class(msgtype: str):
    """rclpy message class of 'pkg/msg/Name'."""
    pkg, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def qos_profile(topic: str) -> QoSProfile:
    """The QoS of a topic of the contract (:data:`gyro_sim.messages.QOS`)."""
    q = QOS[topic]
    return QoSProfile(depth=q["depth"], history=HistoryPolicy.KEEP_LAST, reliability=_RELIABILITY[q["reliability"]],
                      durability=_DURABILITY[q["durability"]])


def take(sub):
    """The next message of an rclpy subscription, or None: non-blocking, past the executor (the poll path)."""
    r = sub.handle.take_message(sub.msg_type, sub.raw)
    return None if r is None else r[0]


#: wall s between the wake-ups of a :class:`MessageWait` that no message ends (signals, liveness, services)
WAKE_PERIOD = 0.05


class MessageWait:
    """Block (in rcl's wait, no CPU) until one of ``subs`` (rclpy subscriptions) has a message: an rcl wait set over
    those subscriptions alone and a guard condition, made once and reused (the executor's ``spin_once`` builds one
    over every entity of the node at each call, ~75 µs here: more than a lockstep round trip's transport).

    The wait has no timeout: a timeout arms a kernel timer at each wait, ~17 µs of CPU on this KVM guest, against
    ~8 µs for a wait without one. Instead a daemon thread triggers the guard condition every ``period`` wall s, so
    a waiting caller wakes at least that often (to see a signal, the controller's liveness, services) and a caller
    that does not wait costs it nothing. The messages are then taken with :func:`take` (or
    :func:`gyro_sim.ros.wire.take_serialized`); services and parameters still go through the executor.
    :meth:`close` ends the thread."""

    def __init__(self, node, subs, period: float = WAKE_PERIOD):
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        self.subs = list(subs)
        self._guard = _rclpy.GuardCondition(node.context.handle)
        self._ws = _rclpy.WaitSet(len(self.subs), 1, 0, 0, 0, 0, node.context.handle)
        self._closed = threading.Event()
        self._ticker = threading.Thread(target=self._tick, args=(period,), name="gyro_sim-wake", daemon=True)
        self._ticker.start()

    def _tick(self, period: float) -> None:
        while not self._closed.wait(period):
            try:
                self._guard.trigger_guard_condition()
            except Exception:  # noqa: BLE001 - the context is being shut down: no one waits any more
                return

    def wait(self, only: Optional[list] = None) -> list:
        """Wait until a subscription has a message (of those whose indices ``only`` gives, default all), or at most
        about ``period`` s; which subscriptions have one (one bool each, in the order of ``subs``; False for those
        not waited on). A signal is seen when it returns."""
        ws = self._ws
        ws.clear_entities()
        subs = self.subs if only is None else [self.subs[i] for i in only]
        for s in subs:
            ws.add_subscription(s.handle)
        ws.add_guard_condition(self._guard)
        ws.wait(-1)
        ready = [ws.is_ready("subscription", i) for i in range(len(subs))]
        if only is None:
            return ready
        out = [False] * len(self.subs)
        for i, r in zip(only, ready, strict=True):
            out[i] = r
        return out

    def close(self) -> None:
        """End the wake-up thread and let go of the rcl wait set and guard condition (before the node is destroyed:
        the wait set points at its subscriptions); no wait follows."""
        self._closed.set()
        self._ticker.join(timeout=1.0)
        del self._ws, self._guard


def make_executor():
    """The executor of a node's callbacks (run in the node's own loop thread). A SingleThreadedExecutor: its wait set
    holds no backlog. (rclpy's EventsExecutor queues an event per message, which messages taken by polling, see
    :func:`take`, never consume: services starve behind the backlog, and it grows without bound.)"""
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor()


def msg_time(header) -> float:
    """Simulation time (s) of a header stamp, as stamp_ns · 1e-9 (the value the in-process loop uses)."""
    return (header.stamp.sec * 1_000_000_000 + header.stamp.nanosec) * 1e-9


#: characters of a refused command's reason (it goes to /gyro/status: a hostile message may name 100k stators)
MAX_REASON = 240


def parse_command(msg, stators: list, limits: Optional[tuple] = None) -> tuple[Optional[tuple], str]:
    """Check a /gyro/stator_commands JointState; ((names, currents, rates|None, stamp_ns), '') or (None, reason).

    name: known stators (texts), no repeats; effort (current, A): one finite value ≥ 0 per name;
    velocity (field rate, rad/s): empty (rates unchanged) or one finite value per name. A message with
    no names and no values is a valid empty command (nothing changes). Numbers are real numbers (not
    booleans). The reason is one line of at most :data:`MAX_REASON` characters quoting values by
    :func:`gyro_sim.scene_text.preview`; a message with more names or values than there are stators is
    refused on its lengths alone (its cost is bounded by the number of stators, not by the message).
    ``limits``: (largest currents A, largest |rates| rad/s), one each per stator of ``stators`` (the scene's
    ``max_current`` / ``max_rate``, :mod:`gyro_sim.scenes.limits`): a value beyond is refused naming it and its limit.
    """
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    why = _command_problem(msg, list(stators), limits)
    if why:
        return None, clip(why, MAX_REASON)
    names = list(msg.name)
    if not names:
        return ([], [], None, stamp), ""  # an empty command: nothing changes (law 'hold')
    rate = [float(r) for r in msg.velocity]
    return (names, [float(c) for c in msg.effort], rate or None, stamp), ""


def _is_real(x) -> bool:
    """A real number, not a boolean (numpy's bool_ is no numbers.Real; Python's bool is). (A float first: the
    per-tick case, without the ABC's check.)"""
    return type(x) is float or (isinstance(x, numbers.Real) and not isinstance(x, bool))


def _command_problem(msg, stators: list, limits: Optional[tuple] = None) -> str:
    """'' if the command ``msg`` is valid for ``stators`` (see :func:`parse_command`), else the reason."""
    n, n_cur, n_rate = len(msg.name), len(msg.effort), len(msg.velocity)
    if n == 0:
        if n_cur or n_rate:
            return f"name is empty but effort/velocity are not; expected stator names from {preview(stators)}"
        return ""
    if n > len(stators):
        return (f"name has {n} entries: more than the {len(stators)} stators {preview(stators)} (a stator is "
                "named at most once)")
    names = list(msg.name)
    for i, name in enumerate(names):
        if not isinstance(name, str):
            return f"name[{i}] = {preview(name)}: a stator name is a text; allowed: {preview(stators)}"
    known = set(stators)
    unknown = [name for name in names if name not in known]
    if unknown:
        return f"name = {preview(names)}: unknown stator {preview(unknown[0])}; allowed: {preview(stators)}"
    if len(set(names)) != n:
        twice = [name for name, k in Counter(names).items() if k > 1]
        return f"name = {preview(names)}: stator {preview(twice[0])} is named twice"
    if n_cur != n:
        return f"effort = {preview(list(msg.effort[:8]))}: one current (A) per name expected ({n} names, {n_cur} values)"
    for name, c in zip(names, msg.effort):
        if not (_is_real(c) and math.isfinite(real_value(c)) and c >= 0):
            return f"effort[{name}] = {preview(c)}: current must be finite and ≥ 0 A"
    if n_rate and n_rate != n:
        return (f"velocity = {preview(list(msg.velocity[:8]))}: empty or one rate (rad/s) per name expected "
                f"({n} names, {n_rate} values)")
    for name, r in zip(names, msg.velocity):
        if not (_is_real(r) and math.isfinite(real_value(r))):
            return f"velocity[{name}] = {preview(r)}: field rate must be finite (rad/s)"
    if limits is not None:
        index = {n: k for k, n in enumerate(stators)}
        # (NumPy arrays as lists of floats in one call: iterating them makes NumPy scalars, ~2 µs a command)
        max_current, max_rate = (x.tolist() if hasattr(x, "tolist") else [float(v) for v in x] for x in limits)
        for name, c in zip(names, msg.effort, strict=True):
            lim = max_current[index[name]]
            if c > lim:
                return (f"effort[{name}] = {float(c):.6g}: beyond {lim:.6g} A, the largest current of stator "
                        f"{name!r} (its max_current in the scene)")
        for name, r in zip(names, msg.velocity if n_rate else [0.0] * n, strict=True):  # (empty: unchanged)
            lim = max_rate[index[name]]
            if abs(r) > lim:
                return (f"velocity[{name}] = {float(r):.6g}: beyond {lim:.6g} rad/s, the largest field rate of stator "
                        f"{name!r} (its max_rate in the scene)")
    return ""


def wants_help(argv) -> bool:
    """``-h`` or ``--help`` among the arguments before ``--ros-args`` (after it they are ROS's)."""
    return any(a in ("-h", "--help") for a in itertools.takewhile(lambda a: a != "--ros-args", argv))


def node_usage(command: str, params: Iterable = ()) -> str:
    """Usage text of a node: how to run ``command`` and its parameters, ``(name, default, description, ...)``
    tuples (extra items, e.g. a range, are ignored)."""
    rows = [(p[0], repr(p[1]), p[2]) for p in params]
    text = (f"usage: {command} [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r __ns:=/NS]]\n"
            "\nROS 2 node; -h/--help before --ros-args prints this text.\n")
    if rows:
        wn, wd = max(len(r[0]) for r in rows), max(len(r[1]) for r in rows)
        text += "\nparameters (name, default, description):\n" + "".join(
            f"  {n:<{wn}}  {d:<{wd}}  {desc}\n" for n, d, desc in rows)
    return text


def node_main(who: str, build: Callable, loop: Callable, args=None, usage: Optional[str] = None) -> int:
    """Run a node process: rclpy without its signal handlers (SIGINT/SIGTERM set ``stop`` instead, see
    :func:`stop_on_signals`), ``build()`` the node (a SceneError or a refused parameter ends it with one
    ``who: error:`` line, status 2), then ``loop(node, stop)``, whose value is the exit status; always cleans up.

    Exit status: the loop's: 0 a complete run, ``128 + n`` (130 SIGINT, 143 SIGTERM) a node stopped by signal
    n (:func:`exit_status`), 2 a refused scene or parameter. The handlers stay installed until the node is torn
    down (a second signal while the bag is closed, or the node destroyed, changes nothing); run as a program
    (``args`` None), the process then ignores SIGINT/SIGTERM while it exits, so a late signal (e.g. the group's
    Ctrl-C and a launcher's forwarded copy) cannot turn its status into -2 or -15. Its teardown is bounded
    (:func:`bound_teardown`): one that hangs, even in C code holding the GIL, still ends the process with the loop's
    status, at most :data:`TEARDOWN_BUDGET` + :data:`TEARDOWN_LAST` + :data:`TEARDOWN_DUMP` s after the loop.

    With ``GYRO_SIM_PARENT_PID`` in the environment (``gyro-sim run --ros`` sets it), the node watches its parent
    (:func:`watch_parent`) and stops as on SIGTERM when it is gone.

    ``-h``/``--help`` before ``--ros-args`` (in ``args``, default ``sys.argv``) prints ``usage`` (default: a
    :func:`node_usage` without parameters) and returns 0 without initialising rclpy."""
    import sys

    if wants_help(sys.argv if args is None else args):
        print(usage or node_usage(who), end="")
        return 0

    stop = StopEvent()
    restore = stop_on_signals(stop)  # first: a signal from here on ends the node cleanly
    node = None
    status = None
    try:
        import rclpy
        from rclpy.exceptions import ParameterException

        from gyro_sim.scenes.scene import SceneError

        # rclpy's own handlers (SignalHandlerOptions.ALL) would shut the context down on SIGINT/SIGTERM, under the
        # loop, and chain to Python's SIGINT handler (KeyboardInterrupt): no clean end of the run, status -2
        rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
        watch_parent(stop)
        try:
            node = build()
        except (SceneError, ParameterException) as e:
            print(f"{who}: error: {e}", file=sys.stderr)
            status = 2
            return status
        status = loop(node, stop)
        return status
    finally:
        if args is None:  # a process: its teardown is bounded (the bag is closed by now)
            bound_teardown(who, status)
        try:
            if node is not None:
                flush_publishers(node)
                node.destroy_node()
            rclpy = sys.modules.get("rclpy")
            if rclpy is not None and rclpy.ok():
                rclpy.shutdown()
        finally:
            if args is None:  # a process about to exit: nothing more to do on a signal
                ignore_signals()
            else:
                restore()


#: wall s a node process may take to tear down (flush its publishers, destroy the node, shut rclpy down) once its
#: loop has ended and its bag is closed; beyond it the process exits with its status (bound_teardown). With the
#: GIL-free watchdog's TEARDOWN_LAST s after it, within the launcher's CONTROLLER_GRACE (10 s): a teardown that hangs
#: (seen in about 1 of 40 node exits under load in rclpy's Node.destroy_node, the GIL held) ends the process itself
#: instead of the launcher's SIGKILL (which it reports as a failure)
TEARDOWN_BUDGET = 6.0
TEARDOWN_LAST = 2.0
#: wall s between the GIL-free watchdog's tracebacks (faulthandler) and its exit with the status (:func:`exit_later`)
TEARDOWN_DUMP = 0.5


def bound_teardown(who: str, status: Optional[int], budget: Optional[float] = None) -> threading.Timer:
    """Start a daemon timer that ends the process with ``status`` (1 if the loop did not return one) after
    ``budget`` s (default :data:`TEARDOWN_BUDGET`) and says so on stderr: a DDS teardown that hangs (a node seen
    alive 120 s after its ``done:`` line, its launcher killed, on a loaded CI machine) must not leave an orphan.
    Everything the run owes (the bag, the done line) is written before the loop returns; stdout and stderr are
    flushed here.

    A teardown that hangs in C code holding the GIL (rclpy's Node.destroy_node, 1 node exit in 40 under load) keeps
    that timer from running: :data:`TEARDOWN_LAST` s after it a watchdog that needs no GIL prints every thread's
    traceback on stderr (faulthandler) and, :data:`TEARDOWN_DUMP` s later, ends the process with the same
    ``status`` (:func:`exit_later`; where it cannot be set up, faulthandler ends it, with status 1)."""
    import faulthandler
    import os
    import sys

    budget = TEARDOWN_BUDGET if budget is None else budget
    code = 1 if status is None else int(status)
    _flush_stdio()

    def _exit() -> None:
        try:
            sys.stderr.write(f"{who}: the ROS teardown took more than {budget:g} s; exiting with status {code}\n")
            sys.stderr.flush()
        finally:
            os._exit(code)

    timer = threading.Timer(budget, _exit)
    timer.daemon = True
    timer.start()
    hard = exit_later(budget + TEARDOWN_LAST + TEARDOWN_DUMP, code)
    faulthandler.dump_traceback_later(budget + TEARDOWN_LAST, exit=not hard)
    return timer


def _flush_stdio() -> None:
    """Flush sys.stdout and sys.stderr (before an exit that skips Python's own: os._exit, :func:`exit_later`)."""
    import sys

    for f in (sys.stdout, sys.stderr):
        try:
            f.flush()
        except (AttributeError, OSError, ValueError):  # (None, a closed or broken stream: nothing to save)
            pass


def exit_later(seconds: float, status: int) -> bool:
    """End the process with exit ``status`` in ``seconds`` s (wall, CLOCK_MONOTONIC), whatever its threads do then:
    a POSIX timer (timer_create, SIGEV_THREAD) whose own thread calls libc's ``_exit(status)``, no Python and no
    GIL in it (a thread hung in C code holding the GIL cannot hold it up, unlike a threading.Timer; faulthandler's
    watchdog also needs no GIL but always exits with status 1). Buffered stdio is not flushed. True if armed;
    False where it cannot be (not Linux, no timer_create): then nothing is armed."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    funcs = None
    for lib in (None, "librt.so.1"):  # (glibc < 2.34: the timer functions are librt's)
        try:
            so = ctypes.CDLL(lib)
            funcs = so.timer_create, so.timer_settime, so._exit
            break
        except (OSError, AttributeError):
            continue
    if funcs is None:
        return False
    create, settime, _exit = funcs

    class Timespec(ctypes.Structure):
        _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]

    class Itimerspec(ctypes.Structure):
        _fields_ = [("it_interval", Timespec), ("it_value", Timespec)]

    class Sigevent(ctypes.Structure):  # (Linux's struct sigevent, SIGEV_THREAD's members; 64 bytes and more)
        _fields_ = [("sigev_value", ctypes.c_void_p), ("sigev_signo", ctypes.c_int), ("sigev_notify", ctypes.c_int),
                    ("sigev_notify_function", ctypes.c_void_p), ("sigev_notify_attributes", ctypes.c_void_p),
                    ("_pad", ctypes.c_byte * 64)]

    sigev_thread, clock_monotonic = 2, 1
    # the thread calls _exit(sigev_value): the union sigval is passed as _exit's int argument (its low 32 bits,
    # the first integer register, as on x86-64 and arm64)
    ev = Sigevent(sigev_value=int(status) & 0xFF or None, sigev_notify=sigev_thread,
                  sigev_notify_function=ctypes.cast(_exit, ctypes.c_void_p).value)
    timer = ctypes.c_void_p()
    create.argtypes = [ctypes.c_int, ctypes.POINTER(Sigevent), ctypes.POINTER(ctypes.c_void_p)]
    settime.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.POINTER(Itimerspec), ctypes.c_void_p]
    if create(clock_monotonic, ctypes.byref(ev), ctypes.byref(timer)) != 0:
        return False
    whole = max(float(seconds), 1e-3)
    when = Itimerspec(it_value=Timespec(int(whole), int((whole % 1.0) * 1e9)))
    return settime(timer, 0, ctypes.byref(when), None) == 0


def wait_for_matches(node, pubs, stop: threading.Event, timeout: float = 10.0, settle: float = 1.0,
                     at_least: int = 0) -> int:
    """Wait until discovery has settled; returns the number of subscriptions matched to ``pubs`` (summed).

    Settled: at least ``at_least`` subscriptions matched (summed over ``pubs``), every subscriber the graph
    shows on their topics matched, and the graph unchanged for ``settle`` s (2 × ``settle`` while no
    subscriber is seen: a busy machine can be slow to announce participants already running); at most
    ``timeout`` s (wall) in all. Then ``settle`` s more: our writers may know a reader before that reader
    knows them, and samples sent before it does are dropped for it (as ``ros2 bag play --delay``).

    Messages published before a reliable subscriber is matched are lost to it: without this wait the first
    samples of a run or a replay would be dropped for subscribers that are already running (the samples at
    the end are kept by :func:`flush_publishers`).
    """
    pubs = list(pubs)
    start = time.perf_counter()
    last, since = None, start

    def matched_count():
        return sum(p.get_subscription_count() for p in pubs)

    while time.perf_counter() - start < timeout and not stop.is_set():
        seen = tuple(node.count_subscribers(p.topic_name) for p in pubs)
        matched = all(p.get_subscription_count() >= n for p, n in zip(pubs, seen)) and matched_count() >= at_least
        now = time.perf_counter()
        if seen != last:
            last, since = seen, now
        elif matched and now - since >= (settle if any(seen) else 2 * settle):
            break
        time.sleep(0.05)
    stop.wait(settle)
    return matched_count()


def flush_publishers(node, budget: float = 2.0) -> None:
    """Wait (at most ``budget`` s in all) until the readers have acknowledged every sample the node's reliable
    publishers sent: a node destroyed earlier drops its last samples (a replayed bag lost its last message
    1 run in 4 that way). A reader that died leaves its writer waiting: hence the bound."""
    import time

    from rclpy.duration import Duration

    end = time.monotonic() + budget
    try:
        for p in list(node.publishers):
            left = end - time.monotonic()
            if left <= 0 or not p.wait_for_all_acked(Duration(seconds=left)):
                return
    except Exception:  # noqa: BLE001 - a node being torn down: flushing is best effort, never the error shown
        return


PARENT_POLL = 0.5  # wall s between looks at the parent (watch_parent)


class SignalFlag:
    """A flag a signal handler sets: a plain attribute, no lock. (A threading.Event's ``set()`` takes its lock;
    Python runs the handler in the main thread between bytecodes, maybe inside that event's ``clear()`` there,
    holding the lock: the handler would wait for itself forever.)"""

    def __init__(self) -> None:
        self.value = False

    def set(self) -> None:
        self.value = True

    def is_set(self) -> bool:
        return self.value

    def clear(self) -> None:
        self.value = False


class StopEvent(threading.Event):
    """The event that ends a node's loop; ``signum``: the signal that set it (None: none, or not yet).

    A signal handler stops it with :meth:`request`, which takes no lock: Python runs a handler in the main thread
    between two bytecodes, which may be inside this event's own ``set()`` or ``wait()`` (holding its lock); a handler
    calling ``set()`` there waits for itself forever. (Seen: the group's Ctrl-C and the launcher's forwarded copy
    came ~µs apart, the second handler ran inside the first's ``set()``, and the simulator hung until SIGKILLed.)
    :meth:`request` marks the event stopped for :meth:`is_set` and :meth:`wait` at once and has a daemon thread
    (woken through a pipe) call ``set()`` for the other threads' waits."""

    signum: Optional[int] = None

    def __init__(self) -> None:
        super().__init__()
        self.requested = False  # (a plain attribute: written by a signal handler, read without a lock)
        self._pipe: Optional[tuple[int, int]] = None

    def arm(self) -> None:
        """Start the thread that sets the event when :meth:`request` wakes it (once; before a handler may call
        :meth:`request`)."""
        if self._pipe is not None:
            return
        import os

        r, w = os.pipe()
        os.set_blocking(w, False)
        self._pipe = (r, w)
        threading.Thread(target=self._set_on_request, args=(r,), name="gyro_sim-stop", daemon=True).start()

    def _set_on_request(self, r: int) -> None:
        import os

        try:
            while os.read(r, 1) == b"s":  # (b"q" from disarm, or b"" when the pipe's write end is closed, ends it)
                super().set()
        finally:
            os.close(r)

    def request(self, signum: Optional[int] = None) -> None:
        """Stop, from a signal handler (no lock taken): ``signum`` is kept if it is the first."""
        import os

        if self.signum is None and signum is not None:
            self.signum = signum
        self.requested = True
        if self._pipe is not None:
            try:
                os.write(self._pipe[1], b"s")
            except OSError:  # (a full pipe already holds a wake-up)
                pass

    def disarm(self) -> None:
        """End the thread and close the pipe (after the handlers that call :meth:`request` are gone)."""
        import os

        if self._pipe is None:
            return
        r, w = self._pipe
        self._pipe = None
        try:
            os.write(w, b"q")
        except OSError:
            pass
        os.close(w)  # (the thread then reads b"q", or the end of the file, closes its end and returns)

    def is_set(self) -> bool:
        return self.requested or super().is_set()

    def wait(self, timeout: Optional[float] = None) -> bool:
        return self.requested or super().wait(timeout)


def exit_status(stop: threading.Event) -> int:
    """A node's exit status: 0 if ``stop`` is not set; ``128 + n`` if signal n set it (130 SIGINT, 143 SIGTERM,
    as a shell reports a process killed by n, but after a clean end); 130 if it was set without a signal."""
    if not stop.is_set():
        return 0
    signum = getattr(stop, "signum", None)
    return 128 + int(signum) if signum else 128 + int(signal.SIGINT)


def stop_on_signals(stop: StopEvent) -> Callable[[], None]:
    """SIGINT/SIGTERM set ``stop`` (the loop ends cleanly and closes its bag) and, the first time, ``stop.signum``.
    Returns a restore function. (Python runs the handler in the main thread, between bytecodes: a loop blocked in
    the executor sees it when its wait times out.)"""
    old = {s: signal.getsignal(s) for s in STOP_SIGNALS}

    def handler(signum, frame):
        stop.request(signum)  # (no lock: see StopEvent)

    stop.arm()
    for s in old:
        signal.signal(s, handler)

    def restore():
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        stop.disarm()

    return restore


def ignore_signals() -> None:
    """Ignore SIGINT/SIGTERM from here on (a process that is exiting: at finalisation Python puts its handlers back
    to the default action, and a signal then would end it with status -2 / -15 after a clean run)."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)


def watch_parent(stop: threading.Event, environ=None) -> Optional[threading.Thread]:
    """If ``GYRO_SIM_PARENT_PID`` (in ``environ``, default ``os.environ``) names this process's parent: a daemon
    thread that sends this process SIGTERM (a clean stop, see :func:`stop_on_signals`) once the parent is gone (its
    parent pid changes: re-parented to init or a subreaper), looking every :data:`PARENT_POLL` s until ``stop`` is
    set. The portable half of "the nodes die with ``gyro-sim run --ros``": on Linux the launcher also sets
    PR_SET_PDEATHSIG (:mod:`gyro_sim.ros.launch`), which acts at once and also after a SIGKILL. Returns the thread
    (None: no such variable, or the parent is already gone: then the SIGTERM is sent at once)."""
    import os

    value = (os.environ if environ is None else environ).get(PARENT_PID_ENV, "")
    try:
        parent = int(value)
    except ValueError:
        return None
    if os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGTERM)
        return None

    def watch():
        while not stop.wait(PARENT_POLL):
            if os.getppid() != parent:
                os.kill(os.getpid(), signal.SIGTERM)
                return

    t = threading.Thread(target=watch, name="gyro_sim-parent-watch", daemon=True)
    t.start()
    return t


__all__ = ["message_class", "qos_profile", "msg_time", "take", "MessageWait", "make_executor", "parse_command", "stop_on_signals", "node_main",
           "StopEvent", "SignalFlag", "exit_status", "signal_name", "ignore_signals", "watch_parent", "STOP_SIGNALS", "PARENT_PID_ENV",
           "node_usage", "wants_help", "flush_publishers", "wait_for_matches", "stamp_ns"]
