"""Replay a recorded bag over ROS 2: every topic with its original timing (× a rate factor), /clock included.

The messages are published as recorded (serialized CDR, no conversion), so a controller, a plotter
or ``ros2 topic echo`` sees exactly what the simulator published.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path
from typing import Callable

import rclpy
from rclpy.node import Node
from rosbags.rosbag2 import Reader

from gyro_sim.io.messages import QOS, TOPICS, node_topic
from gyro_sim.ros.common import (StopEvent, bound_teardown, exit_status, flush_publishers, message_class, qos_profile,
                                 stop_on_signals, wait_for_matches)
from gyro_sim.io.signals import signal_name


def replay(bag: str, rate: float = 1.0, stop: threading.Event | None = None, wait_for: int = 0,
           startup_timeout: float = 10.0, on_end: Callable[[int], None] | None = None) -> int:
    """Publish the bag's messages in log-time order, paced to the wall clock × ``rate``. Returns the count.

    Before the first message, discovery is given time to settle (:func:`~.common.wait_for_matches`, at most
    ``startup_timeout`` s), and at least ``wait_for`` subscriptions, summed over the bag's topics, must be
    matched (unless that time runs out: then a warning, and the replay starts). ``on_end(count)`` is called once
    the messages are published and flushed, before the node is destroyed (a process says its last line and
    bounds its teardown there: :func:`main`)."""
    stop = stop or threading.Event()
    node = Node("gyro_replay")
    try:
        with Reader(Path(bag)) as reader:
            pubs, skipped = {}, []
            for c in reader.connections:
                qos = qos_profile(c.topic) if c.topic in QOS else 10
                try:
                    cls = message_class(c.msgtype)
                except ImportError:  # e.g. tf2_msgs: no PyPI wheel; a ROS install has it
                    skipped.append(f"{c.topic} ({c.msgtype})")
                    continue
                # the bag's canonical names, relative to this node's namespace (-r __ns:=/unit2 replays one unit)
                pubs[c.id] = node.create_publisher(cls, node_topic(c.topic), qos)
            if skipped:
                node.get_logger().warning("not replayed, their message packages are not importable here: "
                                          + ", ".join(skipped))
            seen = wait_for_matches(node, pubs.values(), stop, startup_timeout, at_least=wait_for)
            if seen < wait_for:
                node.get_logger().warning(f"--wait-for-subscribers {wait_for}: {seen} matched after "
                                          f"{startup_timeout:g} s; replaying anyway")
            n = 0
            t0_log = None
            wall0 = time.perf_counter()
            for conn, t_log, raw in reader.messages(connections=[c for c in reader.connections if c.id in pubs]):
                if stop.is_set():
                    break
                if t0_log is None:
                    t0_log = t_log
                ahead = wall0 + (t_log - t0_log) * 1e-9 / rate - time.perf_counter()
                if ahead > 0:
                    stop.wait(ahead)
                pubs[conn.id].publish(bytes(raw))
                n += 1
            # reliable writers still hold the last samples until the readers acknowledge them: a node
            # destroyed now would drop them (as `ros2 bag play --wait-for-all-acked` does, wait, bounded)
            flush_publishers(node, 5.0)
            if on_end is not None:
                on_end(n)
            return n
    finally:
        node.destroy_node()


def parse_args(argv):
    """Arguments of ``python -m gyro_sim.ros.replay`` (argparse exits with status 2 and one line on bad input)."""
    import argparse

    def positive(text):
        v = float(text)
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{text}: must be a positive number")
        return v

    def count(text):
        v = int(text)
        if v < 0:
            raise argparse.ArgumentTypeError(f"{text}: must be an integer ≥ 0")
        return v

    ap = argparse.ArgumentParser(prog="python -m gyro_sim.ros.replay", description="publish a bag over ROS 2")
    ap.add_argument("bag", metavar="BAG")
    ap.add_argument("rate", metavar="RATE", nargs="?", type=positive, default=1.0,
                    help="playback speed factor (default 1)")
    ap.add_argument("--wait-for-subscribers", metavar="N", type=count, default=0,
                    help="wait until N subscriptions (summed over the topics) are matched before the first message")
    ap.add_argument("--startup-timeout", metavar="S", type=positive, default=10.0,
                    help="wall seconds to wait for discovery before the first message (default 10)")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    """``python -m gyro_sim.ros.replay BAG [RATE] [--wait-for-subscribers N] [--startup-timeout S]``."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop = StopEvent()
    restore = stop_on_signals(stop)
    status = 1

    def end(n: int) -> None:
        nonlocal status
        status = exit_status(stop)  # 130 / 143 when a signal ended it: scripts can tell it from a whole replay
        print(f"replay: published {n} messages from {args.bag}"
              + (f" (interrupted by {signal_name(status - 128)})" if status else ""), file=sys.stderr)
        if argv is None:  # a process: a DDS teardown that hangs still ends it, with this status
            bound_teardown("replay", status)

    try:
        replay(args.bag, args.rate, stop, args.wait_for_subscribers, args.startup_timeout, on_end=end)
        return status
    finally:
        restore()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["replay", "main", "TOPICS"]
