"""ROS 2 simulator node: a thin adapter of :class:`gyro_sim.simulate.Runner` to topics, parameters, services and
clocks.

Publishes the topic contract of :mod:`gyro_sim.messages` (``gyro/...`` relative to the node's namespace,
``/clock`` and ``/diagnostics``; stamps in simulation time; ``tf``/``tf_static`` where tf2_msgs is importable)
and subscribes to ``gyro/stator_commands``. Commands are taken at control ticks: the scene controller's period,
or the ``control_period`` parameter (every scene accepts external commands). Timing modes:

* ``lockstep`` — where a controller is expected (``expect_controller``: by default, where the scene has a
  controller section), at each tick the node publishes the state and waits for the command stamped with that
  tick; deterministic, as fast as the machine allows, identical to the in-process run. A command stamped for
  another instant is refused and reported, and does not feed the watchdog.
* ``realtime`` — paced to the wall clock × ``rate_factor``; commands apply at the first tick after they
  arrive; the lateness (wall time from publishing a state to receiving its command) is measured.
* ``freerun`` — as fast as possible; commands apply at the first tick after they arrive.

Services (std_srvs/Trigger, relative to the namespace): ``gyro/pause`` (at the next tick), ``gyro/resume``,
``gyro/step`` (``step_ticks`` ticks while paused), ``gyro/reset`` (back to the scene's initial state; refused
while recording: a bag holds one run).

Watchdog: if a controller is expected and no valid command arrives for ``watchdog_timeout`` wall seconds
(paused time excluded), every stator current is set to zero and a status message says so; it re-arms when
commands come back. A malformed or out-of-range command is refused whole, with the reason on ``gyro/status``.

Signals and exit status (:func:`gyro_sim.ros.common.node_main`): SIGINT or SIGTERM ends the run at the loop's next
turn: the ``done:`` line says ``(interrupted)``, the bag is closed, readable, with custom data
``gyro_sim.end`` = ``interrupted: signal SIGINT`` (or ``SIGTERM``), and the node exits 130 (SIGINT) or 143
(SIGTERM); a second signal meanwhile changes nothing. 0: the run reached its duration. 1: the run failed (its
state broke: not finite, or |L| beyond what the fields can drive, :attr:`Runner.failure`): it stops there, and the
status topic, the ``done:`` line (no error estimate) and the bag's ``gyro_sim.end`` say ``failed: <what> at t = …``.
2: a refused scene or parameter (one ``simulator: error:`` line). A command beyond a stator's ``max_current`` /
``max_rate`` (gyro_sim/scenes/limits.py) is refused like any malformed one: state unchanged, a rate-limited
``refused command:`` status. In lockstep and freerun the bag is written by a process of its own
(:mod:`gyro_sim.io.bag_process`): a SIGKILL of the node leaves it closed with what was sent, marked interrupted; in
real time (written here) a SIGKILL leaves an unfinished bag (no index or metadata; ``gyro-sim bag recover``).
"""
from __future__ import annotations

import contextlib
import math
import re
import signal
from collections import deque
import sys
import threading
import time
from pathlib import Path
from typing import Optional

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node

from gyro_sim.io.messages import (DIAG_ERROR, DIAG_OK, DIAG_WARN, TOPIC_CLOCK, TOPIC_DIAGNOSTICS, TOPIC_EFFECTS, TOPIC_EULER, TOPIC_IMU,
                        TOPIC_KINETIC_MOMENT, TOPIC_SCENE, TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_STATUS,
                        TOPIC_TF, TOPIC_TF_STATIC, TOPIC_TORQUE, TOPICS, diagnostics_message, effects_message,
                        node_topic, scene_message, stamp_ns, state_messages, status_message)
from gyro_sim.compiled.compile_watch import announce_compiles, compile_seconds
from gyro_sim.engine.faults import FaultConfig, Faults
from gyro_sim.scenes.scene import SceneError, load_scene
from gyro_sim.io.recording import STREAM_BUFFER_ROWS, RecordingError
from gyro_sim.io.signals import interrupt_reason, signal_name
from gyro_sim.engine.simulate import Runner, controller_period
from gyro_sim.ros.common import (MessageWait, SignalFlag, exit_status, make_executor, message_class, node_main,
                                 parse_command, qos_profile, take, wait_for_matches)
from gyro_sim.ros.launch import CONTROLLER_ENDED_SIGNAL
from gyro_sim.ros.wire import CommandReader, Wire, state_bytes, state_templates, take_serialized

MODES = ("lockstep", "realtime", "freerun")
#: per-sample topics in publishing order: the clock first, the stator state last (a tick's state is complete after it)
SAMPLE_TOPICS = (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_TF, TOPIC_EFFECTS,
                 TOPIC_STATORS)
#: the scene's controller-less tick period (s): external commands are taken at 100 Hz unless control_period says
DEFAULT_CONTROL_PERIOD = 0.01
DIAGNOSTICS_PERIOD = 1.0  # wall s between /diagnostics messages
SUBSCRIBERS_REFRESH = 0.25  # wall s between looks at who subscribes to the per-sample topics
PUMP_PERIOD = 0.05  # wall s between executor turns (services, parameters) while the loop runs
MAX_COMMANDS_PER_TICK = 100  # commands taken at one tick (the subscription keeps the last 100)
LATENCY_WINDOW = 100_000  # command latencies kept (the last ones): the done line's median, p99, max
PUBLISHED_KEPT = 1000  # publish times of unanswered states kept (for the latency of a late answer)
RUNTIME_PARAMS = ("rate_factor", "watchdog_timeout", "startup_timeout", "step_ticks", "controller_timeout")
#: what lockstep does when its controller is lost (parameter on_controller_lost)
LOST_POLICIES = ("stop", "wait", "currents_off")
LIVENESS_PERIOD = 0.25  # wall s between looks at the controller's presence while lockstep waits for it
#: exit status of a run that failed (its controller lost, policy stop): the bag's end says ``failed: ...``
EXIT_FAILED = 1
#: the node's parameters: (name, default, description, range, read-only); defaults None come from the scene
PARAMETERS = (
    ("scene", "spinup_thin_shell", "scene file path or built-in scene name", None, True),
    ("mode", "lockstep", f"timing mode: {', '.join(MODES)}", None, True),
    ("rate_factor", 1.0, "realtime mode: simulated seconds per wall second", (1e-3, 1e4), False),
    ("duration", 0.0, "simulated duration in s (0 = the scene's)", (0.0, 1e9), True),
    ("record", "", "bag directory to record to (empty = no recording)", None, True),
    ("force", False, "run a scene whose plan exceeds the step budget (gyro_sim/engine/budget.py; without it such a "
     "run is refused at start, status 2, saying which tolerance or parameter to loosen)", None, True),
    ("control_period", None, "s between control ticks, where commands are taken (default: the scene controller's "
     f"period; {DEFAULT_CONTROL_PERIOD:g} s for a scene without a controller section)", (1e-6, 3600.0), True),
    ("expect_controller", None, "a controller is expected (default: the scene has a controller section): lockstep "
     "waits for its command at each tick, the watchdog watches it", None, True),
    ("watchdog_timeout", 2.0, "realtime and freerun: wall s without a valid command before the currents go to 0 A "
     "(0 = off; lockstep has no watchdog: see on_controller_lost)", (0.0, 3600.0), False),
    ("on_controller_lost", "stop", "lockstep: what to do when the controller is lost (its process ended, its "
     "publisher left the ROS graph, or it did not answer within controller_timeout / startup_timeout): stop (the "
     "run ends, bag 'failed: controller lost at t = ...', exit status 1), wait (for it to come back), currents_off "
     "(all currents 0 A, the run goes on without waiting; recorded)", None, True),
    ("controller_timeout", 60.0, "lockstep: wall s a controller present in the ROS graph may take to answer one "
     "state before it counts as lost (a hung one; 0 = no bound). Never a load-dependent result: a slow answer is "
     "waited for", (0.0, 86400.0), False),
    ("startup_timeout", 30.0, "wall s to wait for the first command (lockstep) or for the subscribers of "
     "wait_for_subscribers (0 = no bound)", (0.0, 3600.0), False),
    ("wait_for_subscribers", 0, "before the first step, wait (at most startup_timeout) until this many "
     "subscriptions are matched to the node's topics, summed over the topics (0 = start at once)", (0, 10000), True),
    ("start_paused", False, "start paused at t = 0 (after publishing the initial state): gyro/step, gyro/resume go "
     "on", None, True),
    ("step_ticks", 1, "control ticks one call of gyro/step runs", (1, 1_000_000_000), False),
    ("progress", False, "a progress line on stderr about once a wall second: simulated time, ticks/s, real-time "
     "factor (gyro-sim run --ros sets it on a terminal)", None, True),
    # fault injection (gyro_sim.faults): off by default, reproducible from fault_seed
    ("fault_seed", 0, "seed of the injected faults (commands: one stream of it; sensor noise: a function of it and "
     "the state's stamp)",
     (0, 2**31 - 1), True),
    ("command_drop", 0.0, "fraction of commands dropped (never applied: the previous command stays)", (0.0, 1.0), True),
    ("command_corrupt", 0.0, "fraction of commands whose currents are each scaled by a factor uniform in [0, 2)",
     (0.0, 1.0), True),
    ("command_delay", 0, "control ticks a command waits before it is applied", (0, 1_000_000), True),
    ("current_quantum", 0.0, "A: applied currents rounded to multiples of it (0 = off)", (0.0, 1e6), True),
    ("noise_omega", 0.0, "rad/s: std of the Gaussian noise on the published Ω_b (gyro/imu, each body component)",
     (0.0, 1e9), True),
    ("noise_attitude", 0.0, "rad: std of each component of a random error rotation of the published attitude",
     (0.0, 10.0), True),
    ("noise_L", 0.0, "N·m·s: std of the Gaussian noise on the published L (each case component)", (0.0, 1e9), True),
    ("bias_omega", [0.0, 0.0, 0.0], "rad/s: bias added to the published Ω_b (body frame x, y, z)", None, True),
)


def tf_available() -> bool:
    """Whether tf2_msgs is importable (a ROS install; the PyPI wheels have none): then tf/tf_static go live."""
    try:
        import tf2_msgs.msg  # noqa: F401
        return True
    except ImportError:
        return False


class RunControl:
    """Pause / resume / step / reset requests from the service callbacks to the loop (both run in the loop's
    thread: :meth:`Loop.pump`)."""

    def __init__(self, paused: bool):
        self.paused = paused
        self.steps_left = 0  # ticks still to run before pausing again
        self.reset = False

    def request(self, **kw) -> None:
        for k, v in kw.items():
            setattr(self, k, v)


class SimulatorNode(Node):
    """Owns parameters, publishers, services and the command subscription; the loop is :func:`run_node`."""

    def __init__(self):
        super().__init__("gyro_simulator")
        self._declare(*PARAMETERS[0])  # the scene first: two defaults come from it
        try:
            self.scene = load_scene(self.get_parameter("scene").value)
        except SceneError as e:
            raise SceneError(f"parameter scene = {self.get_parameter('scene').value!r}: {e}") from None
        ctl = self.scene.controller
        in_force = {"control_period": float(controller_period(self.scene) or DEFAULT_CONTROL_PERIOD),
                    "expect_controller": ctl is not None}
        for name, default, description, rng, read_only in PARAMETERS[1:]:
            self._declare(name, in_force.get(name, default), description, rng, read_only)
        self.add_on_set_parameters_callback(self._on_set)
        p = self.params()
        if p["mode"] not in MODES:
            raise SceneError(f"parameter mode = {p['mode']!r}: allowed: {', '.join(MODES)}")
        if p["on_controller_lost"] not in LOST_POLICIES:
            raise SceneError(f"parameter on_controller_lost = {p['on_controller_lost']!r}: allowed: "
                             f"{', '.join(LOST_POLICIES)}")
        if p["record"] and Path(p["record"]).exists():
            raise SceneError(f"parameter record = {p['record']!r}: already exists; give a new directory")
        self.live = {k: p[k] for k in RUNTIME_PARAMS}
        try:
            self.fault_config = FaultConfig(
                seed=p["fault_seed"], command_drop=p["command_drop"], command_corrupt=p["command_corrupt"],
                command_delay=p["command_delay"], current_quantum=p["current_quantum"], noise_omega=p["noise_omega"],
                noise_attitude=p["noise_attitude"], noise_L=p["noise_L"], bias_omega=tuple(p["bias_omega"]))
        except ValueError as e:
            raise SceneError(f"parameter {e}") from None
        self.faults: Optional[Faults] = None  # made per run (Loop.new_run): the same faults after a reset
        # (message, wall time received): filled by the executor in the loop's thread; bounded (a flood drops the
        # oldest, as the subscription's keep-last queue does)
        self.commands: deque = deque(maxlen=10 * MAX_COMMANDS_PER_TICK)
        self.tf = tf_available()
        topics = [t for t in SAMPLE_TOPICS if t != TOPIC_TF or self.tf]
        if self.scene.effects.flywheel is None and self.scene.effects.damper is None:
            topics.remove(TOPIC_EFFECTS)
        topics += [TOPIC_STATUS, TOPIC_SCENE, TOPIC_DIAGNOSTICS] + ([TOPIC_TF_STATIC] if self.tf else [])
        self.pubs = {t: self.create_publisher(message_class(TOPICS[t]), node_topic(t), qos_profile(t)) for t in topics}
        self.classes = {t: message_class(TOPICS[t]) for t in topics}
        self._subs, self._subs_next = (), 0.0
        self.command_sub = self.create_subscription(message_class(TOPICS[TOPIC_STATOR_COMMANDS]), node_topic(TOPIC_STATOR_COMMANDS),
                                 self._on_command, qos_profile(TOPIC_STATOR_COMMANDS))
        # the per-tick messages as CDR bytes (gyro_sim.ros.wire), each type checked now (not in the first tick)
        self.wire = Wire({**self.classes, TOPIC_STATOR_COMMANDS: self.command_sub.msg_type})
        self.commands_serialized = self.wire.serialized(TOPIC_STATOR_COMMANDS)
        self.command_reader = CommandReader(self.wire)  # (a command of a shape seen before: read by its template)
        for t in topics:
            self.wire.serialized(t)
        self.templates = state_templates(self.wire)  # (their numbers patched into bytes made once)
        self.control = RunControl(p["start_paused"])
        self.recording = bool(p["record"])
        from std_srvs.srv import Trigger

        for name, cb in (("pause", self._srv_pause), ("resume", self._srv_resume), ("step", self._srv_step),
                         ("reset", self._srv_reset)):
            self.create_service(Trigger, f"gyro/{name}", cb)
        self.t_now = 0.0  # simulation time, for the service replies (set by the loop)
        self.latencies: deque = deque(maxlen=LATENCY_WINDOW)  # s; the done line's figures are over these
        self.published_wall: dict[int, float] = {}
        #: stamp (ns) -> publications of that state to a subscriber, less the answers to it so far: lockstep drops an
        #: answer to a state since the previous tick quietly while this is > 0, refuses it after (a second answer
        #: to a state published once is a wrong stamp: e.g. a controller stamping every answer 0)
        self.published_n: dict[int, int] = {}

    # --- parameters --------------------------------------------------------------------------
    def _declare(self, name, default, description, rng=None, read_only=False):
        desc = ParameterDescriptor(description=description, read_only=read_only)
        if isinstance(default, int) and not isinstance(default, bool) and rng is not None:
            desc.integer_range = [IntegerRange(from_value=rng[0], to_value=rng[1], step=1)]
        elif rng is not None:
            desc.floating_point_range = [FloatingPointRange(from_value=rng[0], to_value=rng[1], step=0.0)]
        self.declare_parameter(name, default, desc)

    def params(self) -> dict:
        return {n[0]: self.get_parameter(n[0]).value for n in PARAMETERS}

    def _on_set(self, params) -> SetParametersResult:
        # read-only and range checks are rclpy's (with their reasons); the run-time ones take effect at once
        for prm in params:
            if prm.name not in RUNTIME_PARAMS:
                return SetParametersResult(successful=False, reason=f"{prm.name}: set at start-up only")
        for prm in params:
            self.live[prm.name] = prm.value
        return SetParametersResult(successful=True)

    # --- services ----------------------------------------------------------------------------
    def _srv_pause(self, request, response):
        c = self.control
        response.success = not c.paused
        response.message = (f"already paused at t = {self.t_now:.9g} s" if c.paused
                            else f"pausing at the next control tick (t = {self.t_now:.9g} s now)")
        c.request(paused=True, steps_left=0)
        return response

    def _srv_resume(self, request, response):
        c = self.control
        response.success = c.paused
        response.message = f"resumed at t = {self.t_now:.9g} s" if c.paused else "not paused"
        c.request(paused=False, steps_left=0)
        return response

    def _srv_step(self, request, response):
        c = self.control
        n = int(self.live["step_ticks"])
        if not c.paused:
            response.success, response.message = False, "step: the simulator is running; call gyro/pause first"
        else:
            c.request(steps_left=c.steps_left + n)
            response.success, response.message = True, f"stepping {n} control tick(s) from t = {self.t_now:.9g} s"
        return response

    def _srv_reset(self, request, response):
        if self.recording:
            response.success = False
            response.message = (f"reset: refused while recording to {self.get_parameter('record').value!r} "
                                "(a bag holds one run from t = 0)")
        else:
            self.control.request(reset=True)
            response.success, response.message = True, "resetting to the scene's initial state (t = 0)"
        return response

    # --- topics ------------------------------------------------------------------------------
    def _on_command(self, msg) -> None:
        self.commands.append((msg, time.perf_counter()))

    def publish(self, topic: str, fields: dict) -> None:
        self.wire.publish(self.pubs[topic], topic, fields)

    def take_command(self):
        """The next command message of the subscription (past the executor), or None: decoded from its CDR bytes
        where :attr:`wire` allows (:class:`gyro_sim.ros.wire.CommandReader`: a shape seen before by its template),
        else rclpy's message."""
        if not self.commands_serialized:
            return take(self.command_sub)
        raw = take_serialized(self.command_sub)
        return None if raw is None else self.command_reader.read(raw)

    def publish_status(self, text: str, warn: bool = False) -> None:
        if warn:  # rclpy ties one severity to each call site
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)
        self.publish(TOPIC_STATUS, status_message(text))

    def subscribed(self) -> tuple:
        """The per-sample topics someone subscribes to, in publishing order (counts refreshed every
        :data:`SUBSCRIBERS_REFRESH` wall s: publishing a topic no one reads is most of a lockstep tick's cost)."""
        now = time.perf_counter()
        if now >= self._subs_next:
            self._subs = tuple(t for t in SAMPLE_TOPICS if t in self.pubs and self.pubs[t].get_subscription_count())
            self._subs_next = now + SUBSCRIBERS_REFRESH
        return self._subs

    def publish_samples(self, s: dict, names: list) -> None:
        now = time.perf_counter()
        topics = self.subscribed()
        # the state a controller reads (/clock, gyro/imu, gyro/kinetic_moment) without injected sensor noise: its
        # numbers straight into the templates' bytes (the same bytes as the builders' dicts give, ~5 µs a state
        # instead of ~20)
        direct = (bool(topics) and all(t in self.templates for t in topics)
                  and not (self.faults is not None and self.fault_config.sensors_active))
        for i in range(s["t"].size):
            ns = stamp_ns(s["t"][i])
            if direct and ns < _INT32_NS:
                self._publish_direct(topics, ns, s["L"][i].tolist(), s["q"][i].tolist(), s["omega_b"][i].tolist())
            elif topics:
                L, q, w = s["L"][i], s["q"][i], s["omega_b"][i]
                cov = None
                if self.faults is not None and self.fault_config.sensors_active:
                    L, q, w = self.faults.state(L, q, w, ns)  # what a bench's sensors would read
                    cov = self.faults.covariances()
                eul = s["euler"]  # (None: not computed, no one subscribes to it)
                msgs = state_messages(s["t"][i], L, q, w, None if eul is None else eul[i], s["torque"][i], names,
                                      s["current"][i], s["rate"][i], s["phase"][i], imu_covariance=cov,
                                      only=topics if eul is not None else [t for t in topics if t != TOPIC_EULER])
                if s["effects"] and TOPIC_EFFECTS in topics:
                    msgs[TOPIC_EFFECTS] = effects_message(s["t"][i], {k: v[i] for k, v in s["effects"].items()})
                # encoded first (a template where the message has its shape: no sensor covariance injected), then
                # sent back to back: a controller woken by the first finds the second there
                tmpl = self.templates
                out = [(self.pubs[t], tmpl[t].encode_fields(msgs[t]) if t in tmpl and (cov is None or t != TOPIC_IMU)
                        else self.wire.encode(t, msgs[t])) for t in topics if msgs.get(t) is not None]
                for pub, m in out:
                    pub.publish(m)
            self.published_wall[ns] = now
            if topics:  # (published to no one: no answer to expect)
                self.published_n[ns] = self.published_n.get(ns, 0) + 1
        if len(self.published_n) > PUBLISHED_KEPT:  # states no one answered (no controller, or a dead one)
            for k in sorted(self.published_n)[:-PUBLISHED_KEPT // 10]:
                del self.published_n[k]
                self.published_wall.pop(k, None)


    def _publish_direct(self, topics: tuple, ns: int, L: list, q: list, w: list) -> None:
        """Publish a state to ``topics`` (each with a template: :func:`gyro_sim.ros.wire.state_templates`) from its
        numbers: stamp ``ns`` (ns, within int32 seconds), L (N m s), q (w, x, y, z), Ω_b (rad/s) as Python floats, in
        the order of the templates' paths (:func:`gyro_sim.io.messages.state_messages` puts the same numbers in its
        dicts)."""
        out = [(self.pubs[t], m) for t, m in zip(topics, state_bytes(self.templates, topics, ns, L, q, w),
                                                   strict=True)]  # (encoded first, then sent back to back)
        for pub, m in out:
            pub.publish(m)


#: stamps (ns) from here on are beyond builtin_interfaces/Time's int32 seconds (the builders refuse them, saying so)
_INT32_NS = (2**31) * 1_000_000_000


def last_sample(s: dict) -> dict:
    """The last row of a samples dict (:meth:`Runner.samples`), as a one-row samples dict (None stays None)."""
    return {k: ({n: a[-1:] for n, a in v.items()} if isinstance(v, dict) else None if v is None else v[-1:])
            for k, v in s.items()}


class Loop:
    """The simulation loop of one node; the node's callbacks (commands, services, parameters) run in the same thread
    (:meth:`pump`, :meth:`wait_for`, :meth:`wait_wall`, :meth:`hold`), and commands are polled (:func:`take`)."""

    def __init__(self, node: SimulatorNode, stop: threading.Event, spin_once):
        self.node, self.stop, self.spin_once = node, stop, spin_once
        self.p = p = node.params()
        self.mode = p["mode"]
        self.expect = bool(p["expect_controller"])
        self.lockstep_waits = self.mode == "lockstep" and self.expect  # lockstep waits for each tick's command
        self.recorder = None
        self.refused = 0
        self.next_pump = 0.0
        self.refusals: dict = {}  # reason key -> [wall time of its last report, refusals not reported since]
        self.waiter = MessageWait(node, [node.command_sub])
        #: set by CONTROLLER_ENDED_SIGNAL: the launcher saw the controller's process end (gyro_sim.ros.launch)
        self.controller_ended = SignalFlag()
        self.failed: Optional[str] = None  # the run failed: what (the bag's end is 'failed: <this>')
        self.lost_log: list = []  # (t, why, policy) of each time the controller was lost
        self.new_run()  # before the bag is opened: a run that cannot be made leaves no half-written bag
        if p["record"]:
            from gyro_sim.io.bag_process import BagProcess
            from gyro_sim.io.recording import BagRecorder, scene_text, stator_frames

            # lockstep and freerun: written by a process of its own (the tick only sends the numbers); real time:
            # here, in the pacing's idle time (nutation_oblate at 1 kHz, 3 runs each: 1774-1877 of 2000 commands
            # in time, against 1426-1491 with the writer's bursts competing with the nodes)
            recorder = BagRecorder if self.mode == "realtime" else BagProcess
            self.recorder = recorder(p["record"], scene_text(node.scene), node.scene.name,
                                     extra={"gyro_sim.mode": p["mode"],
                                            "gyro_sim.control_period": repr(p["control_period"]),
                                            # the run's accuracy plan is made for it (gyro_sim.rerun)
                                            "gyro_sim.planned_duration": repr(float(self.runner.T)),
                                            **(node.fault_config.as_custom() if node.fault_config.active else {})},
                                     static_tf=stator_frames(node.scene))

    def new_run(self) -> None:
        """A fresh run of the scene from t = 0 (start, and gyro/reset)."""
        node = self.node
        # a bounded buffer of output rows, released once published and recorded: memory stays flat however long
        # the run
        self.runner = Runner(node.scene, self.p["duration"] or None, attitude=True,
                             control_period=self.p["control_period"], buffer_rows=STREAM_BUFFER_ROWS,
                             force=bool(self.p["force"]))
        self.names = list(self.runner.sim.stator_names)
        node.faults = Faults(node.fault_config, len(self.names)) if node.fault_config.active else None
        self.latest = None  # latest valid command (names, current, rate, stamp_ns)
        self.have_cmd = False
        self.watchdog_fired = False  # currents zeroed for a silent controller (the watchdog, or a lost one)
        self.lost = False  # lockstep: the controller is lost (policy wait or currents_off: until it answers again)
        self.controller_seen = False  # a publisher of gyro/stator_commands was matched in this run
        self.fired_ns = 0
        self.n_ticks = 0
        self.last_published: dict = {}
        # lockstep: answers to the states published since the previous tick (a controller may answer every sample,
        # and a state published again while waiting gets a second answer) are dropped quietly; after a reset, so
        # are late answers to the previous run's states. Any other stamp is refused and reported.
        self.prev_run_ns = getattr(self, "tick_ns", -1)
        self.prev_tick_ns = self.tick_ns = -1
        self.waiting_since: Optional[float] = None
        node.published_wall.clear()
        node.published_n.clear()
        node.commands.clear()
        node.latencies.clear()
        self.wall0 = self.last_cmd_wall = self.last_diag = time.perf_counter()
        self.paused_wall = 0.0  # wall s spent paused (not real time, not watchdog time)
        self.c0 = self.c_seen = compile_seconds()  # numba compile time: left out of the same
        self._next_progress = self.wall0 + 1.0

    def run_wall(self) -> float:
        """Wall s of the run so far, less the time paused and the time numba spent compiling (a first use)."""
        return max(time.perf_counter() - self.wall0 - self.paused_wall - (compile_seconds() - self.c0), 1e-9)

    # --- reporting -------------------------------------------------------------------------------
    def status(self, text: str, warn: bool = False) -> None:
        self.node.publish_status(text, warn)
        if self.recorder is not None:
            self.recorder.write_status(self.runner.sim.t, text)

    def report_refusal(self, key: str, text: str, wall: float) -> None:
        """A refused command on gyro/status: each kind (``key``) at most once a wall second, with the count of the
        same refusals not reported since (a sender repeating a bad command at 1 kHz must not flood the status
        topic, the log and this loop)."""
        self.refused += 1
        last = self.refusals.setdefault(key, [-math.inf, 0])
        if wall - last[0] < 1.0:
            last[1] += 1
            return
        more = f" ({last[1]} more like it since the last report)" if last[1] else ""
        self.refusals[key] = [wall, 0]
        self.status(f"refused command: {text}{more}", warn=True)

    def run_state(self) -> tuple[int, str]:
        """(diagnostic level, message) of the run now."""
        t = self.runner.sim.t
        if self.lost or self.failed:
            return DIAG_WARN, f"controller lost (on_controller_lost {self.p['on_controller_lost']})"
        if self.watchdog_fired:
            return DIAG_WARN, f"watchdog fired: no valid command for {self.node.live['watchdog_timeout']:g} s"
        if self.waiting_since is not None and time.perf_counter() - self.waiting_since > 1.0:
            return DIAG_WARN, (f"waiting {time.perf_counter() - self.waiting_since:.1f} s for the command stamped "
                               f"{t:.9f} s")
        if self.runner.failure is not None:
            return DIAG_ERROR, self.runner.failure
        if self.runner.done:
            return DIAG_OK, f"done at t = {t:.9g} s"
        if self.node.control.paused and self.node.control.steps_left == 0:
            return DIAG_OK, f"paused at t = {t:.9g} s"
        return DIAG_OK, "running"

    def diagnostics(self, force: bool = False) -> None:
        """/diagnostics about once a wall second (and at changes): run state, real-time factor, refusals, watchdog."""
        now = time.perf_counter()
        if not force and now - self.last_diag < DIAGNOSTICS_PERIOD:
            return
        self.last_diag = now
        level, message = self.run_state()
        wall = self.run_wall()
        t = self.runner.sim.t
        wd = self.node.live["watchdog_timeout"]
        values = {"t": f"{t:.9g}", "duration": f"{self.runner.T:g}", "mode": self.mode,
                  "real_time_factor": f"{t / wall:.4g}", "control_ticks": self.n_ticks,
                  "ticks_per_s": f"{self.n_ticks / wall:.4g}", "commands_refused": self.refused,
                  "expect_controller": str(self.expect).lower(), "paused": str(self.node.control.paused).lower(),
                  "watchdog": "off" if not (self.expect and wd > 0 and not self.lockstep_waits) else (
                      "fired" if self.watchdog_fired else "armed")}
        if self.lockstep_waits:
            values["controller"] = "lost" if (self.lost or self.failed) else "present"
        fields = diagnostics_message(t, f"{self.node.get_fully_qualified_name()}: run",
                                     self.node.get_fully_qualified_name(), level, message, values)
        self.node.publish(TOPIC_DIAGNOSTICS, fields)
        if self.recorder is not None:
            self.recorder.write_diagnostics(t, fields)

    # --- commands ----------------------------------------------------------------------------
    def take(self, msg, wall: float, pending: int, strict: bool) -> bool:
        """Check one command message; keep it as the latest if valid. True when it is stamped ``pending`` (the
        present tick's stamp, ns).

        ``strict`` (lockstep with a controller expected): the stamp must be the pending tick's, or, after the
        watchdog fired, that of any state published since (a controller coming back); answers to the states
        published since the previous tick are dropped quietly (a controller may answer every sample, and a state
        published again gets a second answer); any other stamp is refused and reported, and feeds no watchdog.
        """
        sim = self.runner.sim
        cmd, why = parse_command(msg, self.names, (sim.max_current, sim.max_rate))
        if cmd is None:
            # one report a second per kind of refusal, whatever finite values are in it (a sender of changing bad
            # values must not flood the status topic either); NaN and inf stay kinds of their own
            self.report_refusal(re.sub(r"-?\b\d[\d.]*(?:e[-+]?\d+)?\b", "#", why), why, wall)
            return False
        ns = cmd[3]
        if strict and ns != pending and not (self.watchdog_fired and self.published(ns, self.fired_ns)):
            # quiet: an answer to a state published since the previous tick, no more answers than publications of
            # it (a state published again gets a second answer); or a late answer to the previous run's states
            if not ((self.published(ns, self.prev_tick_ns) and self.answerable(ns))
                    or self.published(ns, 0, self.prev_run_ns)):
                self.report_refusal("stamp", f"stamp = {ns * 1e-9:.9f} s: lockstep waits for the command stamped "
                                    f"{pending * 1e-9:.9f} s (answer each published state with its header stamp)",
                                    wall)
            return False
        if strict:
            self.answerable(ns)  # this answer uses up one publication of its state
        self.latest = cmd
        self.last_cmd_wall = max(self.last_cmd_wall, wall)  # (a command queued while paused: not later than resume)
        self.have_cmd = True
        published = self.node.published_wall
        pub = published.pop(ns, None)
        if pub is not None:
            self.node.latencies.append(wall - pub)
        if self.lost:
            self.lost = self.watchdog_fired = False
            self.status(f"controller back at t = {self.runner.sim.t:.9g} s: lockstep resumes")
        elif self.watchdog_fired:
            self.watchdog_fired = False
            self.status("watchdog: commands are back; control resumed")
        return ns == pending

    def answerable(self, ns: int) -> bool:
        """Whether the state stamped ``ns`` was published more often than answered so far; counts this answer."""
        n = self.node.published_n.get(ns, 0)
        if n <= 0:
            return False
        self.node.published_n[ns] = n - 1
        return True

    def published(self, ns: int, lo: int, hi: Optional[int] = None) -> bool:
        """Whether ``ns`` is the stamp of an output sample in [lo, hi] (hi: the present time), i.e. of a state
        this run published there."""
        if not (lo <= ns <= (stamp_ns(self.runner.sim.t) if hi is None else hi)):
            return False
        t_out = self.runner.t_out
        j = int(np.searchsorted(t_out, ns * 1e-9))
        return any(stamp_ns(t_out[i]) == ns for i in (j - 1, j, j + 1) if 0 <= i < t_out.size)

    def pump(self, timeout: float = 0.0) -> None:
        """Run the node's ready callbacks (service calls, parameters; commands that came that way) in this thread,
        waiting up to ``timeout`` s for the first; at most every :data:`PUMP_PERIOD` wall s unless it waits (an
        executor turn costs ~75 µs here: more than a lockstep exchange)."""
        now = time.perf_counter()
        if timeout <= 0 and now < self.next_pump:
            return
        self.next_pump = now + PUMP_PERIOD
        if self.recorder is not None:
            self.recorder.flush_due()  # (the bag's queued writes, also while paused)
        self.spin_once(timeout)

    def drain(self, pending: int, strict: bool) -> None:
        """Take the commands that came (at most :data:`MAX_COMMANDS_PER_TICK`: a flood cannot stall the run)."""
        self.pump()
        q = self.node.commands
        for _ in range(MAX_COMMANDS_PER_TICK):
            if q:
                msg, wall = q.popleft()
            else:
                msg, wall = self.node.take_command(), time.perf_counter()
                if msg is None:
                    return
            self.take(msg, wall, pending, strict)

    def wait_for(self, stamp: int) -> Optional[str]:
        """Lockstep: wait for the command stamped ``stamp``, however long a live controller takes (a wall-clock
        timeout must not change a lockstep result); None when it came (or the run is stopped), else why the
        controller counts as lost (:meth:`why_lost`). Between messages the loop blocks in a wait on the command
        subscription (:class:`MessageWait`: no busy poll). While waiting, the last state is published again every
        0.5 s, so a state lost before discovery completed does not stall the loop (the controller answers a repeat
        identically)."""
        q = self.node.commands
        now = time.perf_counter()
        start, resend, look = now, now + 0.5, now + LIVENESS_PERIOD
        self.waiting_since = now
        waited = False  # (the first look is the wait's: right after the state went out the answer is rarely in, and
        # a take that finds nothing costs ~10 µs a tick; the wait returns at once where it is)
        try:
            while not self.stop.is_set():
                while q:
                    msg, wall = q.popleft()
                    if self.take(msg, wall, stamp, True):
                        return None
                msg = self.node.take_command() if waited else None
                if msg is not None:
                    if self.take(msg, time.perf_counter(), stamp, True):
                        return None
                    continue
                self.pump()  # services and parameters meanwhile
                now = time.perf_counter()
                if now >= look:
                    look = now + LIVENESS_PERIOD
                    why = self.why_lost(now - start)
                    if why:
                        return why
                    self.diagnostics()
                if now >= resend:
                    if self.last_published:
                        self.node.publish_samples(last_sample(self.last_published["s"]), self.names)
                    resend = now + 0.5
                if not q:  # (a command the executor's turn took is not waited for)
                    self.waiter.wait()  # (woken at least every WAKE_PERIOD: signals, liveness, services)
                waited = True
            return None
        finally:
            self.waiting_since = None

    def why_lost(self, waited: float) -> str:
        """'' while the controller counts as present, else why it is lost: its process ended (the launcher's
        :data:`CONTROLLER_ENDED_SIGNAL`), its publisher of gyro/stator_commands left the ROS graph, or no command
        for startup_timeout (the first of a run) or controller_timeout (a hung one) wall s. (A policy ``wait``
        already lost it: only its coming back counts.)"""
        if self.lost:
            return ""
        live = self.node.live
        if self.controller_ended.is_set():
            self.controller_ended.clear()
            return "its process ended (gyro-sim run --ros)"
        present = self.node.command_sub.get_publisher_count() > 0
        if present:
            self.controller_seen = True
        elif self.controller_seen:
            return "its publisher of gyro/stator_commands left the ROS graph"
        if not self.have_cmd:
            bound = live["startup_timeout"]
            if bound > 0 and waited > bound:
                return f"no command since the start (startup_timeout {bound:g} s)"
        else:
            bound = live["controller_timeout"]
            if bound > 0 and waited > bound:
                return f"no answer for {bound:g} s (controller_timeout)"
        return ""

    def controller_lost(self, why: str, now_ns: int) -> None:
        """Apply the ``on_controller_lost`` policy (lockstep), once per loss: ``stop`` ends the run (failed),
        ``wait`` waits on for it, ``currents_off`` zeroes every current and runs on without waiting."""
        policy = self.p["on_controller_lost"]
        t = self.runner.sim.t
        self.lost_log.append((t, why, policy))
        if self.recorder is not None:
            self.recorder.set_custom("gyro_sim.controller_lost", "; ".join(
                f"t = {x:.9g} s: {w} ({pol})" for x, w, pol in self.lost_log))
        what = f"controller lost at t = {t:.9g} s: {why}"
        if policy == "stop":
            self.failed = f"controller lost at t = {t:.9g} s"
            self.status(f"{what}; the run stops (on_controller_lost stop)", warn=True)
        elif policy == "wait":
            self.lost = True
            self.status(f"{what}; waiting for it to come back (on_controller_lost wait)", warn=True)
        else:
            self.lost = self.watchdog_fired = True
            self.fired_ns = now_ns
            self.zero_currents()
            self.status(f"{what}; all stator currents set to 0 A, the run goes on (on_controller_lost currents_off)",
                        warn=True)
        self.diagnostics(force=True)

    def zero_currents(self) -> None:
        """Every stator current to 0 A (recorded like a command); a dead controller's delayed commands dropped."""
        faults = self.node.faults
        if faults is not None:
            faults.fifo.clear()  # a dead controller's delayed commands must not undo the zeroing
        self.apply((self.names, [0.0] * len(self.names), None, None))

    def apply(self, cmd) -> None:
        nm, cur, rate, _ = cmd
        try:
            self.runner.apply_commands({n: (cur[i], rate[i] if rate is not None else None) for i, n in enumerate(nm)})
        except ValueError as exc:  # (a command the fault injection scaled beyond a stator's limit: nothing changed)
            self.report_refusal("applied", str(exc), time.perf_counter())
            return
        if self.recorder is not None and nm:
            self.recorder.write_command(self.runner.sim.t, nm, cur, rate)

    def tick(self) -> None:
        """At a control tick: take (lockstep: wait for) the command, apply it, run the watchdog."""
        self.n_ticks += 1
        compiled = compile_seconds() - self.c_seen  # compiling (in the last advance) is no controller's silence:
        if compiled:  # counted before this tick's commands are taken
            self.c_seen += compiled
            self.last_cmd_wall += compiled
        now = stamp_ns(self.runner.sim.t)
        self.prev_tick_ns, self.tick_ns = self.tick_ns, now
        wd = self.node.live["watchdog_timeout"]
        strict = self.mode == "lockstep" and self.expect
        if strict and not self.watchdog_fired:
            why = self.wait_for(now)
            while why:  # lost: the policy says what next (wait: on waiting, for it to come back)
                self.latest = None
                self.controller_lost(why, now)
                why = self.wait_for(now) if self.lost and not self.watchdog_fired else ""
            if self.failed:
                return
        else:
            self.drain(now, strict)
        cmd, self.latest = self.latest, None  # (the next tick takes only what comes for it)
        faults = self.node.faults
        if faults is not None and faults.cfg.commands_active:
            cmd = faults.command(cmd)  # dropped, corrupted, delayed, quantised (gyro_sim.faults)
        if cmd is not None:
            self.apply(cmd)
        if (self.expect and not strict and wd > 0 and not self.watchdog_fired
                and time.perf_counter() - self.last_cmd_wall > wd):
            self.watchdog_fired, self.fired_ns = True, now
            self.zero_currents()  # recorded like any command
            waited = (f"no command for {wd:g} s" if self.have_cmd else
                      f"no command since the start (startup_timeout {self.node.live['startup_timeout']:g} s)")
            self.status(f"watchdog: {waited}; all stator currents set to 0 A", warn=True)
            self.diagnostics(force=True)

    # --- pause, step, reset --------------------------------------------------------------------
    def hold(self) -> None:
        """At a tick: stay here while paused (no step pending), serving reset; the paused time counts for neither
        the real-time pacing nor the watchdog."""
        c = self.node.control
        self.node.t_now = self.runner.sim.t
        announced = False
        w0 = time.perf_counter()
        while not self.stop.is_set():
            if c.reset or not c.paused or c.steps_left > 0:
                break
            if not announced:
                self.status(f"paused at t = {self.runner.sim.t:.9g} s")
                self.diagnostics(force=True)
                announced = True
            self.pump(0.2)
            self.diagnostics()
        held = time.perf_counter() - w0
        self.paused_wall += held
        self.last_cmd_wall = time.perf_counter()  # the watchdog counts from the resume

    def publish_samples(self, rows: slice) -> None:
        if rows.stop <= rows.start:  # a break that is no sample (a command's instant, an error-control check)
            return
        # (the Euler angles only where someone reads them: a third of the samples' cost)
        # (no energy: no topic carries it)
        # (the bag's writer computes them where no one subscribes)
        s = self.runner.samples(rows, euler=TOPIC_EULER in self.node.subscribed(), energy=False)
        self.node.publish_samples(s, self.names)
        if s["t"].size:
            # (its last row is taken where it is published again, while waiting for a command: the rows are still
            # in the runner's buffer then, as a slice of them would be)
            self.last_published["s"] = s
        if self.recorder is not None:
            self.recorder.write_samples(s, self.names)

    # --- the run -------------------------------------------------------------------------------------
    def run(self) -> int:
        node, p = self.node, self.p
        try:
            node.publish(TOPIC_SCENE, scene_message(_scene_text(node.scene)))
            if node.tf:
                from gyro_sim.io.recording import stator_frames

                node.publish(TOPIC_TF_STATIC, stator_frames(node.scene))
            want = p["wait_for_subscribers"]
            if want > 0:
                node.get_logger().info(f"waiting for {want} subscription(s) to the simulator's topics")
                seen = wait_for_matches(node, node.pubs.values(), self.stop, p["startup_timeout"] or math.inf,
                                        at_least=want)
                if seen < want:
                    self.status(f"wait_for_subscribers = {want}: {seen} matched after {p['startup_timeout']:g} s "
                                f"(startup_timeout); starting anyway", warn=True)
            self.wall0 = self.last_cmd_wall = time.perf_counter()  # (the watchdog counts from the start of the run)
            self.c0 = self.c_seen = compile_seconds()
            announce_compiles(say=lambda text: self.status(text))
            r = self.runner
            self.status(f"simulator: scene {node.scene.name!r}, mode {self.mode}, duration {r.T} s, control ticks "
                        f"every {r.period:g} s" + (", controller expected" if self.expect else "")
                        + (f", recording to {p['record']}" if self.recorder else ""))
            self.diagnostics(force=True)
            while not self.stop.is_set():
                node.t_now = self.runner.sim.t
                self.serve_controls()
                r = self.runner
                if r.done or self.stop.is_set():
                    break
                if r.row > 0 and r.is_control_tick:
                    self.tick()
                    if self.failed:
                        break
                    c = node.control
                    if c.steps_left > 0:
                        c.steps_left -= 1
                rows = r.advance()
                if self.stop.is_set() and rows.stop == rows.start:
                    break
                self.publish_samples(rows)
                r.release()
                self.diagnostics()
                self.pump()  # services and parameters every PUMP_PERIOD, also where no tick waits for a command
                if p["progress"]:
                    self.show_progress()
                if self.mode == "realtime":
                    self.wait_wall(r.sim.t / node.live["rate_factor"] - self.run_wall())
            status = self.finish()
            if self.recorder is not None:  # (here, not in the finally: a failed close is the except's, as one mid-run;
                self.recorder.close()  # a BagProcess hears here of a failure in the writes it sent last)
            return status
        except RecordingError as exc:  # a full disk: the bag is closed with what fit; the run stops
            self.recorder = None
            node.get_logger().error(str(exc))
            self.status(f"error: {exc}", warn=True)
            return 1
        except BaseException as exc:  # (a bug: the bag, cut short, must not say complete)
            if self.recorder is not None:
                self.recorder.interrupted(interrupt_reason(exc))
            raise
        finally:
            if self.recorder is not None:
                self.recorder.close()

    def wait_wall(self, seconds: float) -> None:
        """Real-time pacing: wait ``seconds`` wall in the executor, so commands arriving meanwhile are stamped
        with their arrival (the latency measured is the controller's, not the pacing's)."""
        end = time.perf_counter() + seconds
        while not self.stop.is_set():
            left = end - time.perf_counter()
            if left <= 0:
                return
            self.spin_once(left)

    def show_progress(self, end: bool = False) -> None:
        """``\r  t = … / T s  (… ticks/s, …x real time)`` on stderr, about once a wall second (``end``: the last)."""
        now = time.perf_counter()
        if not end and now < getattr(self, "_next_progress", 0.0):
            return
        self._next_progress = now + 1.0
        wall, t = self.run_wall(), self.runner.sim.t
        sys.stderr.write(f"\r  t = {t:.6g} / {self.runner.T:.6g} s  ({self.n_ticks / wall:.0f} ticks/s, "
                         f"{t / wall:.3g}x real time)   " + ("\n" if end else ""))
        sys.stderr.flush()

    def serve_controls(self) -> None:
        """Reset if asked; hold at a tick while paused."""
        c = self.node.control
        if c.reset:
            c.reset = False
            self.new_run()
            self.status("reset: back to the scene's initial state at t = 0")
        r = self.runner
        if r.row > 0 and r.is_control_tick and c.paused and c.steps_left == 0:
            self.hold()
            if c.reset:
                self.serve_controls()

    def finish(self) -> int:
        r, node = self.runner, self.node
        # decided once (the bag, the done line and the exit status agree); a run that reached its end is complete; one
        # whose state broke (Runner.failure) or whose controller was lost (self.failed) failed: status 1
        failure = r.failure if r.failure is not None else (f"failed: {self.failed}" if self.failed else None)
        status = EXIT_FAILED if failure is not None else 0 if r.done else exit_status(self.stop)
        wall = self.run_wall()
        compiled = compile_seconds() - self.c0
        lat = np.array(node.latencies)
        est = r.error_estimate()  # the run's estimated error so far (gyro_sim.accuracy)
        if self.recorder is not None:
            figures = [("wall_time", wall), ("compile_time", compiled), ("steps", r.sim.steps), ("duration", r.sim.t),
                       ("control_ticks_per_s", self.n_ticks / wall)]
            if lat.size:  # (no command answered a published state: no latency figures)
                figures += [("latency_median_s", float(np.median(lat))),
                            ("latency_p99_s", float(np.percentile(lat, 99))), ("latency_max_s", float(np.max(lat)))]
            for k, v in figures:
                self.recorder.set_custom(f"gyro_sim.{k}", v)
            if r.failure is None:  # (no error estimate of a run whose state broke: its end says what broke)
                self.recorder.set_custom("gyro_sim.error_estimate", est.to_json())
            if failure is not None:
                self.recorder.run_failed(failure)
            elif status:
                signum = getattr(self.stop, "signum", None)
                self.recorder.interrupted(f"signal {signal_name(signum)}" if signum else "stopped")
        if r.failure is not None:
            self.status(r.failure, warn=True)
        self.diagnostics(force=True)
        if self.p["progress"]:
            self.show_progress(end=True)
        latency = (f"command latency median {np.median(lat) * 1e3:.3f} ms p99 {np.percentile(lat, 99) * 1e3:.3f} ms "
                   f"max {np.max(lat) * 1e3:.3f} ms" if lat.size else "no command latency (no command answered a "
                   "published state)")
        self.status(f"done: t = {r.sim.t:g} s in {wall:.3f} s wall ({r.sim.t / wall:.1f}x real time), "
                    f"{self.n_ticks} control ticks ({self.n_ticks / wall:.1f}/s), {r.sim.steps} steps, "
                    f"{self.refused} commands refused, {latency}"
                    + (f" (+ {compiled:.1f} s compiling the kernels, first use)" if compiled else "")
                    + (f", {r.failure}" if r.failure is not None else f", estimated error {est.text()}")
                    + (f" ({failure})" if failure is not None and r.failure is None
                       else " (interrupted)" if status and failure is None else ""))
        return status  # 0 complete; 1 failed (state broke, controller lost); 130 / 143 SIGINT / SIGTERM (bag closed)


def _scene_text(scene) -> str:
    from gyro_sim.io.recording import scene_text

    return scene_text(scene)


def run_node(node: SimulatorNode, stop: threading.Event) -> int:
    """The simulation loop, with the node's callbacks run in the same thread (:meth:`Loop.pump`): a command
    reaches the loop without a thread hand-over (lockstep ticks/s). Returns the exit status: 0 the run reached its
    end, 128 + n it was stopped by signal n (``stop``, see :func:`gyro_sim.ros.common.exit_status`)."""
    executor = make_executor()
    executor.add_node(node)
    loop = None
    try:
        try:
            loop = Loop(node, stop, lambda timeout: executor.spin_once(timeout_sec=timeout))
        except (RecordingError, FileExistsError) as exc:  # the record target, checked before the run
            print(f"simulator: error: {exc}", file=sys.stderr)
            return 2
        with _controller_ended_signal(loop.controller_ended):
            return loop.run()
    finally:
        if loop is not None:
            loop.waiter.close()
        executor.shutdown()


@contextlib.contextmanager
def _controller_ended_signal(event: SignalFlag):
    """While the run goes on, :data:`CONTROLLER_ENDED_SIGNAL` (from ``gyro-sim run --ros``: the controller's process
    ended) sets ``event``; the launcher blocks it from the fork on, so one sent before now is delivered here."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(CONTROLLER_ENDED_SIGNAL, lambda signum, frame: event.set())
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {CONTROLLER_ENDED_SIGNAL})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_BLOCK, {CONTROLLER_ENDED_SIGNAL})
        signal.signal(CONTROLLER_ENDED_SIGNAL, old if old is not None else signal.SIG_DFL)


def _spin_and_run(node: SimulatorNode, stop: threading.Event) -> int:
    return run_node(node, stop)


def main(args=None) -> int:
    """Entry point (`ros2 run gyro_sim simulator`, console script `gyro-sim-simulator`)."""
    from gyro_sim.ros.common import node_usage

    usage = node_usage("ros2 run gyro_sim simulator", [(n, "(the scene's)" if d is None else d, t + (
        " (read-only)" if ro else "")) for n, d, t, _, ro in PARAMETERS])
    return node_main("simulator", SimulatorNode, _spin_and_run, args, usage=usage)


if __name__ == "__main__":
    sys.exit(main())
