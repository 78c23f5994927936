"""Replay a recorded bag over ROS 2: every topic with its original timing (× a rate factor), /clock included.

The messages are published as recorded (serialized CDR, no conversion), so a controller, a plotter
or ``ros2 topic echo`` sees exactly what the simulator published.
"""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.node import Node
from rosbags.rosbag2 import Reader

from ..messages import QOS, TOPICS
from .common import flush_publishers, message_class, qos_profile, stop_on_signals


def _wait_for_matches(node: Node, pubs, stop: threading.Event, timeout: float = 10.0, settle: float = 1.0) -> None:
    """Wait until discovery has settled: every subscriber in the graph matched to our publishers and the
    graph unchanged for ``settle`` s (2 × ``settle`` while no subscriber is seen; ≤ ``timeout``).

    Messages published before a reliable subscriber is matched are lost, so without this the first
    samples of a replay would be dropped for subscribers that are already running (the samples at the
    end are kept by :func:`flush_publishers`).
    """
    pubs = list(pubs)
    start = time.perf_counter()
    last, since = None, start
    while time.perf_counter() - start < timeout and not stop.is_set():
        seen = tuple(node.count_subscribers(p.topic_name) for p in pubs)
        matched = all(p.get_subscription_count() >= n for p, n in zip(pubs, seen))
        now = time.perf_counter()
        if seen != last:
            last, since = seen, now
        elif matched and now - since >= (settle if any(seen) else 2 * settle):
            # (no subscriber seen yet: give discovery longer, a busy machine can be slow to announce the
            # participants that are already running)
            break
        time.sleep(0.05)
    # our writers may know a reader before that reader knows them (its first samples would be dropped):
    # give the other side of discovery time too, as `ros2 bag play --delay` does
    stop.wait(settle)


def replay(bag: str, rate: float = 1.0, stop: threading.Event | None = None) -> int:
    """Publish the bag's messages in log-time order, paced to the wall clock × ``rate``. Returns the count."""
    stop = stop or threading.Event()
    node = Node("gyro_replay")
    try:
        with Reader(Path(bag)) as reader:
            pubs = {}
            for c in reader.connections:
                qos = qos_profile(c.topic) if c.topic in QOS else 10
                pubs[c.id] = node.create_publisher(message_class(c.msgtype), c.topic, qos)
            _wait_for_matches(node, pubs.values(), stop)
            n = 0
            t0_log = None
            wall0 = time.perf_counter()
            for conn, t_log, raw in reader.messages():
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
            return n
    finally:
        node.destroy_node()


def main(argv=None) -> int:
    """``python -m gyro_sim.ros.replay BAG [RATE]``."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print("usage: python -m gyro_sim.ros.replay BAG [RATE]", file=sys.stderr)
        return 2
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    try:
        n = replay(argv[0], float(argv[1]) if len(argv) > 1 else 1.0, stop)
        print(f"replay: published {n} messages from {argv[0]}", file=sys.stderr)
        return 0
    finally:
        restore()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["replay", "main", "TOPICS"]
