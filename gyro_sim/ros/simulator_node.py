"""ROS 2 simulator node: a thin adapter of :class:`gyro_sim.simulate.Runner` to topics, parameters and clocks.

Publishes the topic contract of :mod:`gyro_sim.messages` (``/gyro/...`` and ``/clock``, stamps in
simulation time) and subscribes to ``/gyro/stator_commands``. Timing modes:

* ``lockstep`` — at each controller tick the node publishes the state and waits for the command
  stamped with that tick; deterministic, as fast as the machine allows, identical to the in-process run.
* ``realtime`` — paced to the wall clock × ``rate_factor``; commands apply at the first tick after they
  arrive; the lateness (wall time from publishing a state to receiving its command) is measured.
* ``freerun`` — as fast as possible; commands apply at the first tick after they arrive.

Watchdog: if a controller is expected and no valid command arrives for ``watchdog_timeout`` wall
seconds, every stator current is set to zero and a status message says so; it re-arms when commands
come back. A malformed or out-of-range command is refused whole, with the reason on ``/gyro/status``.
"""
from __future__ import annotations

import math
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Optional

import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from ..messages import (TOPIC_CLOCK, TOPIC_EFFECTS, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT,
                        TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_STATUS, TOPIC_TORQUE, TOPICS, effects_message,
                        stamp_ns, state_messages, status_message, to_ros)
from ..scene import SceneError, load_scene
from ..simulate import Runner
from .common import message_class, node_main, parse_command, qos_profile, wait_for_matches

MODES = ("lockstep", "realtime", "freerun")
STATE_TOPICS = (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_CLOCK)


class SimulatorNode(Node):
    """Owns parameters, publishers and the command subscription; the loop is :meth:`run`."""

    def __init__(self):
        super().__init__("gyro_simulator")
        d = self._declare
        d("scene", "spinup_thin_shell", "scene file path or built-in scene name")
        d("mode", "lockstep", f"timing mode: {', '.join(MODES)}")
        d("rate_factor", 1.0, "realtime mode: simulated seconds per wall second", (1e-3, 1e4))
        d("duration", 0.0, "simulated duration in s (0 = the scene's)", (0.0, 1e9))
        d("record", "", "bag directory to record to (empty = no recording)")
        d("watchdog_timeout", 2.0, "wall seconds without a command before the currents go to zero (0 = off)",
          (0.0, 3600.0))
        d("startup_timeout", 30.0, "wall seconds to wait for the first command (lockstep) or for the "
          "subscribers of wait_for_subscribers (0 = no bound)", (0.0, 3600.0))
        d("wait_for_subscribers", 0, "before the first step, wait (at most startup_timeout) until this many "
          "subscriptions are matched to the node's topics, summed over the topics (0 = start at once)", (0, 10000))
        self.add_on_set_parameters_callback(self._on_set)
        err = self._check(self._params())
        if err:
            raise SceneError(err)
        self.commands: "queue.Queue" = queue.Queue()
        self.pubs = {t: self.create_publisher(message_class(TOPICS[t]), t, qos_profile(t)) for t in
                     STATE_TOPICS + (TOPIC_STATUS,)}
        if self.scene.effects.flywheel is not None or self.scene.effects.damper is not None:
            self.pubs[TOPIC_EFFECTS] = self.create_publisher(message_class(TOPICS[TOPIC_EFFECTS]), TOPIC_EFFECTS,
                                                             qos_profile(TOPIC_EFFECTS))
        self.create_subscription(message_class(TOPICS[TOPIC_STATOR_COMMANDS]), TOPIC_STATOR_COMMANDS,
                                 self._on_command, qos_profile(TOPIC_STATOR_COMMANDS))
        self.latencies: list[float] = []
        self.published_wall: dict[int, float] = {}

    # --- parameters --------------------------------------------------------------------------
    def _declare(self, name, default, description, rng=None):
        desc = ParameterDescriptor(description=description)
        if isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=rng[0], to_value=rng[1], step=1)]
        elif rng is not None:
            desc.floating_point_range = [FloatingPointRange(from_value=rng[0], to_value=rng[1], step=0.0)]
        self.declare_parameter(name, default, desc)

    def _params(self) -> dict:
        return {p: self.get_parameter(p).value for p in ("scene", "mode", "rate_factor", "duration", "record",
                                                         "watchdog_timeout", "startup_timeout",
                                                         "wait_for_subscribers")}

    def _check(self, p: dict) -> Optional[str]:
        if p["mode"] not in MODES:
            return f"parameter mode = {p['mode']!r}: allowed: {', '.join(MODES)}"
        try:
            self.scene = load_scene(p["scene"])
        except SceneError as e:
            return f"parameter scene = {p['scene']!r}: {e}"
        if p["record"] and Path(p["record"]).exists():
            return f"parameter record = {p['record']!r}: already exists; give a new directory"
        return None

    def _on_set(self, params) -> SetParametersResult:
        # values are fixed for a run: refuse changes with a reason (ranges are checked by rclpy)
        names = ", ".join(p.name for p in params)
        return SetParametersResult(successful=False, reason=f"{names}: set at start-up only (restart the node)")

    # --- topics ------------------------------------------------------------------------------
    def _on_command(self, msg) -> None:
        self.commands.put((msg, time.perf_counter()))

    def publish_status(self, text: str, warn: bool = False) -> None:
        if warn:  # rclpy ties one severity to each call site
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)
        self.pubs[TOPIC_STATUS].publish(to_ros(message_class(TOPICS[TOPIC_STATUS]), status_message(text)))

    def publish_samples(self, s: dict, names: list) -> None:
        now = time.perf_counter()
        for i in range(s["t"].size):
            msgs = state_messages(s["t"][i], s["L"][i], s["q"][i], s["omega_b"][i], s["euler"][i], s["torque"][i],
                                  names, s["current"][i], s["rate"][i], s["phase"][i])
            # the clock first, then the state; the stator state last (a tick's state is complete after it)
            eff = effects_message(s["t"][i], {k: v[i] for k, v in s["effects"].items()}) if s["effects"] else None
            if eff is not None:
                msgs[TOPIC_EFFECTS] = eff
            for topic in (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_EFFECTS,
                          TOPIC_STATORS):
                if topic in msgs:
                    self.pubs[topic].publish(to_ros(message_class(TOPICS[topic]), msgs[topic]))
            self.published_wall[stamp_ns(s["t"][i])] = now


def last_sample(s: dict) -> dict:
    """The last row of a samples dict (:meth:`Runner.samples`), as a one-row samples dict."""
    return {k: ({n: a[-1:] for n, a in v.items()} if isinstance(v, dict) else v[-1:]) for k, v in s.items()}


def run_node(node: SimulatorNode, stop: threading.Event) -> int:
    """The simulation loop (main thread); DDS callbacks run in an executor thread."""
    p = node._params()
    scene = node.scene
    # the node publishes /gyro/imu (orientation) and /gyro/euler: it always integrates the attitude, whatever
    # the scene's output.attitude says (simulate.integrates_attitude)
    runner = Runner(scene, p["duration"] or None, attitude=True)
    names = list(runner.sim.stator_names)
    expect_commands = scene.controller is not None
    recorder = None
    if p["record"]:
        from ..recording import BagRecorder, scene_text

        recorder = BagRecorder(p["record"], scene_text(scene), scene.name, extra={"gyro_sim.mode": p["mode"]})
    mode, factor = p["mode"], p["rate_factor"]
    wd = p["watchdog_timeout"]
    last_cmd_wall = time.perf_counter()
    have_cmd = False
    watchdog_fired = False
    latest = None  # latest valid command (names, current, rate, stamp_ns)
    refused = 0
    n_ticks = 0

    def status(text, warn=False):
        node.publish_status(text, warn)
        if recorder is not None:
            recorder.write_status(runner.sim.t, text)

    last_published: dict = {}
    refusals: dict = {}  # reason -> [wall time of its last report, refusals not reported since]

    def report_refusal(why: str, wall: float) -> None:
        """A refused command on /gyro/status: each reason at most once a second (wall), with the count of
        the same refusals not reported since (a sender repeating a bad command at 1 kHz must not flood the
        status topic, the log and this loop)."""
        last = refusals.setdefault(why, [-math.inf, 0])
        if wall - last[0] < 1.0:
            last[1] += 1
            return
        more = f" ({last[1]} more like it since the last report)" if last[1] else ""
        refusals[why] = [wall, 0]
        status(f"refused command: {why}{more}", warn=True)

    def drain(block_until_ns: Optional[int], timeout: float):
        """Take commands off the queue; with block_until_ns, wait (≤ timeout) for that stamp.

        While waiting, the last state is published again every 0.5 s, so a state lost before
        discovery completed does not stall the loop (the controller answers a repeat identically).
        """
        nonlocal latest, last_cmd_wall, have_cmd, watchdog_fired, refused
        deadline = time.perf_counter() + timeout
        resend = time.perf_counter() + 0.5
        queued = node.commands.qsize()  # without a wait, only what is queued now: a flood cannot stall the run
        while True:
            try:
                if block_until_ns is None:
                    if queued <= 0:
                        return False
                    queued -= 1
                    msg, wall = node.commands.get_nowait()
                else:
                    left = deadline - time.perf_counter()
                    if left <= 0 or stop.is_set():
                        return False
                    msg, wall = node.commands.get(timeout=min(left, 0.05))
            except queue.Empty:
                if block_until_ns is None:
                    return False
                if time.perf_counter() > resend and last_published:
                    node.publish_samples(last_published["s"], names)
                    resend = time.perf_counter() + 0.5
                continue
            cmd, why = parse_command(msg, names)
            if cmd is None:
                refused += 1
                report_refusal(why, wall)
                continue
            latest = cmd
            last_cmd_wall = wall
            have_cmd = True
            pub = node.published_wall.pop(cmd[3], None)
            if pub is not None:
                node.latencies.append(wall - pub)
            if watchdog_fired:
                watchdog_fired = False
                status("watchdog: commands are back; control resumed")
            if block_until_ns is not None and cmd[3] == block_until_ns:
                return True

    def apply(cmd):
        nm, cur, rate, stamp = cmd
        runner.apply_commands({n: (cur[i], rate[i] if rate is not None else None) for i, n in enumerate(nm)})
        if recorder is not None and nm:
            recorder.write_command(runner.sim.t, nm, cur, rate)

    try:
        want = p["wait_for_subscribers"]
        if want > 0:
            node.get_logger().info(f"waiting for {want} subscription(s) to the simulator's topics")
            seen = wait_for_matches(node, node.pubs.values(), stop, p["startup_timeout"] or math.inf, at_least=want)
            if seen < want:
                status(f"wait_for_subscribers = {want}: {seen} matched after {p['startup_timeout']:g} s "
                       f"(startup_timeout); starting anyway", warn=True)
        wall0 = last_cmd_wall = time.perf_counter()  # (the watchdog counts from the start of the run)
        status(f"simulator: scene {scene.name!r}, mode {mode}, duration {runner.T} s"
               + (f", recording to {p['record']}" if recorder else ""))
        while not runner.done and not stop.is_set():
            if runner.row > 0 and runner.is_control_tick:
                n_ticks += 1
                if mode == "lockstep" and expect_commands and not watchdog_fired:
                    timeout = wd if have_cmd else p["startup_timeout"]
                    if drain(stamp_ns(runner.sim.t), timeout if timeout > 0 else math.inf):
                        apply(latest)
                    latest = None  # applied, or stale (another tick's)
                else:
                    drain(None, 0.0)
                    if latest is not None:
                        apply(latest)
                        latest = None
                if expect_commands and wd > 0 and not watchdog_fired and time.perf_counter() - last_cmd_wall > wd:
                    watchdog_fired = True
                    apply((names, [0.0] * len(names), None, None))  # recorded like any command (re-run check)
                    status(f"watchdog: no command for {wd:g} s; all stator currents set to 0 A", warn=True)
            rows = runner.advance()
            if stop.is_set() and rows.stop == rows.start:
                break
            s = runner.samples(rows)
            node.publish_samples(s, names)
            if s["t"].size:
                last_published["s"] = last_sample(s)
            if recorder is not None:
                for i in range(s["t"].size):
                    recorder.write_sample(s["t"][i], s["L"][i], s["q"][i], s["omega_b"][i], s["euler"][i],
                                          s["torque"][i], names, s["current"][i], s["rate"][i], s["phase"][i],
                                          {k: v[i] for k, v in s["effects"].items()})
            if mode == "realtime":
                ahead = wall0 + runner.sim.t / factor - time.perf_counter()
                if ahead > 0:
                    stop.wait(ahead)
        wall = time.perf_counter() - wall0
        lat = np.array(node.latencies) if node.latencies else np.array([math.nan])
        if recorder is not None:
            for k, v in (("wall_time", wall), ("steps", runner.sim.steps), ("duration", runner.sim.t),
                         ("control_ticks_per_s", n_ticks / wall), ("latency_median_s", float(np.median(lat))),
                         ("latency_p99_s", float(np.percentile(lat, 99)))):
                recorder.set_custom(f"gyro_sim.{k}", v)
            if stop.is_set():
                recorder.interrupted("signal")
        status(f"done: t = {runner.sim.t:g} s in {wall:.3f} s wall ({runner.sim.t / wall:.1f}x real time), "
               f"{n_ticks} control ticks ({n_ticks / wall:.1f}/s), {runner.sim.steps} steps, "
               f"{refused} commands refused, command latency median {np.median(lat) * 1e3:.3f} ms "
               f"p99 {np.percentile(lat, 99) * 1e3:.3f} ms"
               + (" (interrupted)" if stop.is_set() else ""))
    finally:
        if recorder is not None:
            recorder.close()
    return 0


def _spin_and_run(node: SimulatorNode, stop: threading.Event) -> int:
    """DDS callbacks in an executor thread, the simulation loop in this one."""
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    try:
        return run_node(node, stop)
    finally:
        executor.shutdown(timeout_sec=1.0)
        spin.join(timeout=2.0)


def main(args=None) -> int:
    """Entry point (`ros2 run gyro_sim simulator`, console script `gyro-sim-simulator`)."""
    return node_main("simulator", SimulatorNode, _spin_and_run, args)


if __name__ == "__main__":
    sys.exit(main())
