"""A small ROS 2 peer for the multi-process tests (run as a separate process).

    python ros_probe.py listen OUT.json SECONDS UNTIL TOPIC [...]  count messages (keep status texts) for at
                                                                   most SECONDS, or until every topic has UNTIL
                                                                   (UNTIL 0 with /gyro/status: until the
                                                                   simulator's "done:" status)
    python ros_probe.py bad_commands SECONDS PERIOD                publish malformed stator commands every
                                                                   PERIOD s (0: as fast as it can) until the
                                                                   simulator is done (≤ SECONDS)
    python ros_probe.py script OUT NS SECONDS STEPS_JSON           in namespace NS, run the steps (service
                                                                   calls, parameter get/set, waits for status
                                                                   lines) while recording status, scene,
                                                                   /diagnostics and /clock; OUT.json
    python ros_probe.py answer NS SECONDS STATOR T_ON CURRENT      a minimal external controller: answer every
                                                                   kinetic_moment state with its stamp (empty
                                                                   command before T_ON, STATOR at CURRENT A from
                                                                   it) and send one malformed command first
    python ros_probe.py stamp_zero NS SECONDS                      answer every kinetic_moment state with an
                                                                   empty command stamped 0 (right at t = 0 only)
    python ros_probe.py stamped NS SECONDS PERIOD                  valid commands with wrong stamps (0 and the
                                                                   wall clock, alternately) every PERIOD s
    python ros_probe.py params OUT.json SECONDS NODE REQUESTS      wait (≤ SECONDS) for NODE's parameter
                                                                   services, run REQUESTS (a JSON list, in
                                                                   order) through its parameter services, write
                                                                   the answers as JSON

Topic and service names are relative to the probe's namespace (as the nodes use them); NS '/' is the root.

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

from gyro_sim.io.messages import (TOPIC_CLOCK, TOPIC_DIAGNOSTICS, TOPIC_KINETIC_MOMENT, TOPIC_SCENE,
                                  TOPIC_STATOR_COMMANDS, TOPIC_STATUS, TOPICS, node_topic)
from gyro_sim.ros.common import message_class, qos_profile


def listen(out: str, seconds: float, until: int, topics: list) -> None:
    node = Node("gyro_probe")
    counts = {t: 0 for t in topics}
    texts = []
    stamps = []
    imu: dict = {}

    def cb(topic):
        def f(msg):
            counts[topic] += 1
            if topic == TOPIC_STATUS:
                texts.append(msg.data)
            elif hasattr(msg, "header"):
                stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
            if hasattr(msg, "angular_velocity_covariance") and not imu:  # the first /gyro/imu's
                imu.update(orientation_covariance=list(msg.orientation_covariance),
                           angular_velocity_covariance=list(msg.angular_velocity_covariance),
                           angular_velocity=[msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z])
        return f

    for t in topics:
        node.create_subscription(message_class(TOPICS[t]), t, cb(t), _deep(t))
    open(out + ".ready", "w").close()  # subscriptions exist: the test may start publishers
    def complete():
        if until:
            return all(n >= until for n in counts.values())
        return any(t.startswith("done:") for t in texts)

    end = time.time() + seconds
    while time.time() < end and not complete():
        rclpy.spin_once(node, timeout_sec=0.05)
    with open(out, "w") as f:
        json.dump({"counts": counts, "status": texts, "stamps": stamps, "imu": imu}, f)
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
    seen = False  # the simulator's subscription to the commands was matched once
    while time.time() < end and not done:
        # the simulator gone (its subscription unmatched) ends the flood too: a "done:" it published as it exited
        # can be lost to a flooder starved of CPU (under load the flooder then ran to its 150 s and the test's
        # 180 s wait for it expired)
        n = pub.get_subscription_count()
        seen = seen or n > 0
        if seen and n == 0:
            break
        for names, eff, vel in bad:
            m = cls()
            m.name, m.effort, m.velocity = names, eff, vel
            pub.publish(m)
        burst = time.time() + period  # (spin_once returns at each status message: pace by the clock)
        rclpy.spin_once(node, timeout_sec=0.0)
        while time.time() < burst and not done:
            rclpy.spin_once(node, timeout_sec=max(burst - time.time(), 0.0))
    node.destroy_node()


# --- scripted checks of the simulator's services, parameters and latched topics ---------------------------

def _python_value(v):
    """A Python value of an rcl_interfaces ParameterValue."""
    from rclpy.parameter import parameter_value_to_python

    out = parameter_value_to_python(v)
    return list(out) if not isinstance(out, (bool, int, float, str, type(None))) else out


def _call(node, client, request, timeout=60.0):
    if not client.wait_for_service(timeout_sec=timeout):
        raise RuntimeError(f"service {client.srv_name} not available after {timeout} s")
    fut = client.call_async(request)
    rclpy.spin_until_future_complete(node, fut, timeout_sec=timeout)
    if not fut.done():
        raise RuntimeError(f"service {client.srv_name}: no answer after {timeout} s")
    return fut.result()


#: wall s a "mark" step spins before it reads the clock (two clean-clone suites side by side, four workers on two
#: cores: the last /clock of a step reached the probe after its "paused at" status line, 0.526 read against 0.528)
MARK_SETTLE = 1.0


def script(out: str, ns: str, seconds: float, steps: list) -> None:
    """Run ``steps`` against the simulator of namespace ``ns``; write what was seen and answered to ``out``.

    Steps: {"wait_status": TEXT, "count": K} (until K status lines containing TEXT were seen, latched ones
    included), {"call": "pause"|"resume"|"step"|"reset"}, {"get": [NAMES]}, {"set": {NAME: VALUE}},
    {"mark": LABEL} (the clock once it has settled: the probe spins MARK_SETTLE s first, so /clock messages published
    before a pause that reach it after the status line, as on a busy machine, are counted; a paused run publishes
    no more). Each step's result (with the last /clock seen) is in "results".
    """
    from rcl_interfaces.srv import GetParameters, SetParameters
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    node = Node("gyro_script_probe", namespace=ns)
    seen = {"status": [], "scene": [], "diagnostics": [], "clock": []}
    node.create_subscription(message_class(TOPICS[TOPIC_STATUS]), node_topic(TOPIC_STATUS),
                             lambda m: seen["status"].append(m.data), _deep(TOPIC_STATUS))
    node.create_subscription(message_class(TOPICS[TOPIC_SCENE]), node_topic(TOPIC_SCENE),
                             lambda m: seen["scene"].append(m.data), _deep(TOPIC_SCENE))
    node.create_subscription(message_class(TOPICS[TOPIC_CLOCK]), TOPIC_CLOCK,
                             lambda m: seen["clock"].append(m.clock.sec + m.clock.nanosec * 1e-9), _deep(TOPIC_CLOCK))
    node.create_subscription(message_class(TOPICS[TOPIC_DIAGNOSTICS]), TOPIC_DIAGNOSTICS,
                             lambda m: seen["diagnostics"].extend(
                                 [s.level[0] if isinstance(s.level, bytes) else int(s.level), s.name, s.message,
                                  s.hardware_id, {kv.key: kv.value for kv in s.values}] for s in m.status),
                             _deep(TOPIC_DIAGNOSTICS))
    sim = (ns.rstrip("/") + "/gyro_simulator") if ns != "/" else "/gyro_simulator"
    get_c = node.create_client(GetParameters, f"{sim}/get_parameters")
    set_c = node.create_client(SetParameters, f"{sim}/set_parameters")
    end = time.time() + seconds
    results = []

    def spin_until(cond):
        while not cond():
            if time.time() > end:
                raise TimeoutError("probe window over")
            rclpy.spin_once(node, timeout_sec=0.05)

    try:
        for step in steps:
            res = {"step": step}
            if "wait_status" in step:
                k = step.get("count", 1)
                spin_until(lambda step=step, k=k: sum(step["wait_status"] in x for x in seen["status"]) >= k)
            elif "call" in step:
                r = _call(node, node.create_client(Trigger, f"gyro/{step['call']}"), Trigger.Request())
                res.update(success=r.success, message=r.message)
            elif "get" in step:
                r = _call(node, get_c, GetParameters.Request(names=step["get"]))
                res["values"] = dict(zip(step["get"], (_python_value(v) for v in r.values)))
            elif "set" in step:
                req = SetParameters.Request(parameters=[Parameter(k, value=v).to_parameter_msg()
                                                        for k, v in step["set"].items()])
                r = _call(node, set_c, req)
                res["results"] = [[x.successful, x.reason] for x in r.results]
            elif "sleep" in step or "mark" in step:
                t1 = time.time() + step.get("sleep", MARK_SETTLE)
                spin_until(lambda t1=t1: time.time() > t1)
            rclpy.spin_once(node, timeout_sec=0.0)
            res["clock"] = seen["clock"][-1] if seen["clock"] else None
            results.append(res)
    except (TimeoutError, RuntimeError) as e:
        results.append({"error": str(e)})
    with open(out, "w") as f:
        json.dump({"results": results, **seen}, f)
    node.destroy_node()


def _deep(topic):
    """The contract's QoS with a deep reader queue: the probe measures what was published, so a Python callback
    falling behind a burst must not drop samples (reliable keep_last drops the oldest)."""
    qos = qos_profile(topic)
    qos.depth = max(qos.depth, 10000)
    return qos


def _done_watch(node, done: list) -> None:
    node.create_subscription(message_class(TOPICS[TOPIC_STATUS]), node_topic(TOPIC_STATUS),
                             lambda m: done.append(1) if m.data.startswith("done:") else None, _deep(TOPIC_STATUS))


def answer(ns: str, seconds: float, stator: str, t_on: float, current: float) -> None:
    """A minimal external controller (what a user writes): answer every state with its stamp."""
    node = Node("gyro_answer_probe", namespace=ns)
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    pub = node.create_publisher(cls, node_topic(TOPIC_STATOR_COMMANDS), qos_profile(TOPIC_STATOR_COMMANDS))
    done: list = []
    _done_watch(node, done)
    first = []

    def on_state(m):
        if not first:
            bad = cls()
            bad.header.stamp = m.header.stamp
            bad.name, bad.effort = [stator], [-1.0]  # malformed: refused with its reason
            pub.publish(bad)
            first.append(1)
        c = cls()
        c.header.stamp = m.header.stamp
        if m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 >= t_on:
            c.name, c.effort = [stator], [current]
        pub.publish(c)

    node.create_subscription(message_class(TOPICS[TOPIC_KINETIC_MOMENT]), node_topic(TOPIC_KINETIC_MOMENT), on_state,
                             _deep(TOPIC_KINETIC_MOMENT))
    end = time.time() + seconds
    while time.time() < end and not done:
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()


def stamp_zero(ns: str, seconds: float) -> None:
    """A controller that answers every state, always with stamp 0 (a bug a user's controller may have)."""
    node = Node("gyro_stamp_zero_probe", namespace=ns)
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    pub = node.create_publisher(cls, node_topic(TOPIC_STATOR_COMMANDS), qos_profile(TOPIC_STATOR_COMMANDS))
    done: list = []
    _done_watch(node, done)
    node.create_subscription(message_class(TOPICS[TOPIC_KINETIC_MOMENT]), node_topic(TOPIC_KINETIC_MOMENT),
                             lambda m: pub.publish(cls()), _deep(TOPIC_KINETIC_MOMENT))
    end = time.time() + seconds
    while time.time() < end and not done:
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()


def stamped(ns: str, seconds: float, period: float) -> None:
    """Valid commands with stamps of no pending tick (0 and the wall clock, alternately) until the run is done."""
    node = Node("gyro_stamp_probe", namespace=ns)
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    pub = node.create_publisher(cls, node_topic(TOPIC_STATOR_COMMANDS), qos_profile(TOPIC_STATOR_COMMANDS))
    done: list = []
    _done_watch(node, done)
    end = time.time() + seconds
    k = 0
    while time.time() < end and not done:
        c = cls()
        if k % 2:
            now = time.time()
            c.header.stamp.sec, c.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        c.name, c.effort = ["z1"], [0.1]
        pub.publish(c)
        k += 1
        t1 = time.time() + period
        while time.time() < t1 and not done:
            rclpy.spin_once(node, timeout_sec=max(t1 - time.time(), 0.0))
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
        cmd, a = sys.argv[1], sys.argv[2:]
        if cmd == "listen":
            listen(a[0], float(a[1]), int(a[2]), a[3:])
        elif cmd == "bad_commands":
            bad_commands(float(a[0]), float(a[1]))
        elif cmd == "script":
            script(a[0], a[1], float(a[2]), json.loads(a[3]))
        elif cmd == "answer":
            answer(a[0], float(a[1]), a[2], float(a[3]), float(a[4]))
        elif cmd == "stamp_zero":
            stamp_zero(a[0], float(a[1]))
        elif cmd == "stamped":
            stamped(a[0], float(a[1]), float(a[2]))
        elif cmd == "params":
            params(a[0], float(a[1]), a[2], json.loads(a[3]))
        else:
            raise SystemExit(f"ros_probe: unknown command {cmd!r}")
    finally:
        rclpy.shutdown()
