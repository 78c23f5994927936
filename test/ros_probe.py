"""A small ROS 2 peer for the multi-process tests (run as a separate process).

    python ros_probe.py listen OUT.json SECONDS UNTIL TOPIC [...]  count messages (keep status texts) for at
                                                                   most SECONDS, or until every topic has UNTIL
                                                                   (UNTIL 0 with /gyro/status: until the
                                                                   simulator's "done:" status)
    python ros_probe.py bad_commands SECONDS PERIOD                publish malformed stator commands every
                                                                   PERIOD s (0: as fast as it can) until the
                                                                   simulator is done (≤ SECONDS)
    python ros_probe.py params OUT.json SECONDS NODE REQUESTS      wait (≤ SECONDS) for NODE's parameter
                                                                   services, run REQUESTS (a JSON list, in
                                                                   order) through its parameter services, write
                                                                   the answers as JSON

A request of ``params`` is one of {"get": [names]} → {name: value}, {"describe": [names]} → {name:
{description, read_only, dynamic_typing, type}}, {"set": {name: value}} (service set_parameters: one result
per parameter, as ``ros2 param set``) → [{successful, reason}], {"set_atomically": {name: value}} (service
set_parameters_atomically: all or none) → {successful, reason}. Values as JSON (NaN allowed); a number
without a decimal point is sent as an integer parameter.
"""
import json
import sys
import time

import rclpy
from rclpy.node import Node

from gyro_sim.messages import TOPIC_STATOR_COMMANDS, TOPIC_STATUS, TOPICS
from gyro_sim.ros.common import message_class, qos_profile


def listen(out: str, seconds: float, until: int, topics: list) -> None:
    node = Node("gyro_probe")
    counts = {t: 0 for t in topics}
    texts = []
    stamps = []

    def cb(topic):
        def f(msg):
            counts[topic] += 1
            if topic == TOPIC_STATUS:
                texts.append(msg.data)
            elif hasattr(msg, "header"):
                stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
        return f

    for t in topics:
        # the contract's QoS with a deep reader queue: the probe measures what was published, so a Python
        # callback falling behind a burst must not drop samples (reliable keep_last drops the oldest)
        qos = qos_profile(t)
        qos.depth = max(qos.depth, 10000)
        node.create_subscription(message_class(TOPICS[t]), t, cb(t), qos)
    open(out + ".ready", "w").close()  # subscriptions exist: the test may start publishers
    def complete():
        if until:
            return all(n >= until for n in counts.values())
        return any(t.startswith("done:") for t in texts)

    end = time.time() + seconds
    while time.time() < end and not complete():
        rclpy.spin_once(node, timeout_sec=0.05)
    with open(out, "w") as f:
        json.dump({"counts": counts, "status": texts, "stamps": stamps}, f)
    node.destroy_node()


def bad_commands(seconds: float, period: float) -> None:
    """Publish malformed commands every ``period`` s (0: a flood) until the simulator's "done:" status, at
    most ``seconds``."""
    node = Node("gyro_bad_commander")
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    pub = node.create_publisher(cls, TOPIC_STATOR_COMMANDS, qos_profile(TOPIC_STATOR_COMMANDS))
    done = []
    node.create_subscription(message_class(TOPICS[TOPIC_STATUS]), TOPIC_STATUS,
                             lambda m: done.append(1) if m.data.startswith("done:") else None,
                             qos_profile(TOPIC_STATUS))
    bad = [
        (["z1"], [float("nan")], [0.0]),  # NaN current
        (["z1"], [-1.0], [0.0]),  # negative current
        (["z9"], [1.0], [0.0]),  # unknown stator
        (["z1", "z2"], [1.0], []),  # one current for two names
        (["z1"], [1.0], [float("inf")]),  # infinite rate
    ]
    end = time.time() + seconds
    while time.time() < end and not done:
        for names, eff, vel in bad:
            m = cls()
            m.name, m.effort, m.velocity = names, eff, vel
            pub.publish(m)
        burst = time.time() + period  # (spin_once returns at each status message: pace by the clock)
        rclpy.spin_once(node, timeout_sec=0.0)
        while time.time() < burst and not done:
            rclpy.spin_once(node, timeout_sec=max(burst - time.time(), 0.0))
    node.destroy_node()


def params(out: str, seconds: float, node_name: str, requests: list) -> None:
    from rclpy.parameter import Parameter, parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient

    node = Node("gyro_param_probe")
    client = AsyncParameterClient(node, node_name)
    ready = client.wait_for_services(timeout_sec=seconds)
    answers = []

    def call(future):
        rclpy.spin_until_future_complete(node, future, timeout_sec=seconds)
        if not future.done():
            raise TimeoutError(f"no answer from {node_name} within {seconds} s")
        return future.result()

    for req in requests if ready else []:
        (op, arg), = req.items()
        if op == "get":
            r = call(client.get_parameters(list(arg)))
            answers.append({n: parameter_value_to_python(v) for n, v in zip(arg, r.values)})
        elif op == "describe":
            r = call(client.describe_parameters(list(arg)))
            answers.append({d.name: {"description": d.description, "read_only": d.read_only,
                                     "dynamic_typing": d.dynamic_typing, "type": d.type} for d in r.descriptors})
        elif op in ("set", "set_atomically"):
            ps = [Parameter(n, value=v) for n, v in arg.items()]
            if op == "set":
                r = call(client.set_parameters(ps))
                answers.append([{"successful": x.successful, "reason": x.reason} for x in r.results])
            else:
                r = call(client.set_parameters_atomically(ps))
                answers.append({"successful": r.result.successful, "reason": r.result.reason})
        else:
            raise ValueError(f"unknown request {op!r}")
    with open(out, "w") as f:
        json.dump({"ready": ready, "answers": answers}, f)
    node.destroy_node()


if __name__ == "__main__":
    rclpy.init()
    try:
        if sys.argv[1] == "listen":
            listen(sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), sys.argv[5:])
        elif sys.argv[1] == "params":
            params(sys.argv[2], float(sys.argv[3]), sys.argv[4], json.loads(sys.argv[5]))
        else:
            bad_commands(float(sys.argv[2]), float(sys.argv[3]))
    finally:
        rclpy.shutdown()
