"""The lockstep's messages as CDR bytes (gyro_sim/ros/wire.py): what the nodes send is the message rclpy would
send, what they read is what rclpy would read. In one process, no DDS (rclpy's serialization alone)."""
import math

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from gyro_sim.common.stamps import stamp_ns  # noqa: E402
from gyro_sim.io.bag_format import cdr_message  # noqa: E402
from gyro_sim.io.messages import (TOPIC_CLOCK, TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT,  # noqa: E402
                                  TOPIC_STATOR_COMMANDS, TOPIC_STATORS, TOPIC_TORQUE, TOPICS, command_message,
                                  state_messages, to_ros)
from gyro_sim.ros.common import message_class  # noqa: E402
from gyro_sim.ros.wire import (STAMP_PATHS, CommandReader, Template, Wire, command_view, state_bytes,  # noqa: E402
                               state_templates)

HOT = (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_STATOR_COMMANDS)


@pytest.fixture(scope="module")
def wire():
    return Wire({t: message_class(TOPICS[t]) for t in HOT})


def random_states(n, seed=3):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        q = rng.standard_normal(4)
        yield (float(rng.uniform(0, 3e5)), rng.standard_normal(3) * 10.0 ** rng.uniform(-12, 12), q / np.linalg.norm(q),
               rng.standard_normal(3) * 1e3, rng.uniform(-3, 3, 3), rng.standard_normal(3), ["s1", "s2", "s3"],
               rng.uniform(0, 5, 3), rng.standard_normal(3) * 100, rng.uniform(0, 2 * math.pi, 3))


def test_per_tick_types_go_as_bytes_and_read_back_as_rclpy_messages(wire):
    """Every per-tick type is sent as bytes on this install, and rclpy reads those bytes as the message its own
    serialization of the same fields would give (states of random values, commands with and without rates)."""
    assert all(wire.serialized(t) for t in HOT)
    for state in random_states(50):
        msgs = state_messages(*state)
        msgs[TOPIC_STATOR_COMMANDS] = command_message(state[0], state[6], state[7], state[8])
        for topic, fields in msgs.items():
            if topic not in HOT:
                continue
            cls = message_class(TOPICS[topic])
            assert deserialize_message(wire.encode(topic, fields), cls) == to_ros(cls, fields), topic


def test_templates_give_the_bytes_of_the_whole_serialization(wire):
    """The simulator's templates (imu, kinetic_moment, clock) patch a state's numbers into the bytes rosbags makes of
    the whole message, and read them back; a message of another shape (another frame id, rclpy's own bytes with
    their unwritten padding) is not read at the template's places (None: decoded whole)."""
    tmpl = state_templates(wire)
    assert set(tmpl) == {TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_CLOCK}
    for state in random_states(300):
        msgs = state_messages(*state)
        sec, nanosec = divmod(stamp_ns(state[0]), 1_000_000_000)
        (x, y, z), (w, qx, qy, qz), (wx, wy, wz) = state[1], state[2], state[3]
        numbers = {TOPIC_IMU: [sec, nanosec, qx, qy, qz, w, wx, wy, wz],
                   TOPIC_KINETIC_MOMENT: [sec, nanosec, x, y, z], TOPIC_CLOCK: [sec, nanosec]}
        for topic, t in tmpl.items():
            raw = t.encode_fields(msgs[topic])
            assert raw == bytes(cdr_message(topic, msgs[topic])), topic
            assert t.decode(raw) == numbers[topic]
    other = dict(msgs[TOPIC_KINETIC_MOMENT], header={"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "elsewhere"})
    assert tmpl[TOPIC_KINETIC_MOMENT].decode(bytes(cdr_message(TOPIC_KINETIC_MOMENT, other))) is None
    cls = message_class(TOPICS[TOPIC_IMU])
    rclpy_bytes = bytes(serialize_message(to_ros(cls, msgs[TOPIC_IMU])))
    assert tmpl[TOPIC_IMU].decode(rclpy_bytes) in (None, numbers[TOPIC_IMU])


def test_command_template_and_view(wire):
    """A controller's command by template (the controller node's path) is rclpy's message of the same content, and
    the simulator's view of it reads as rclpy's message does (names, currents, rates as Python floats)."""
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    names = ["s1", "s2", "s3"]
    for with_rates in (False, True):
        base = command_message(0.0, names, [0.0] * 3, [0.0] * 3 if with_rates else None)
        t = Template(TOPIC_STATOR_COMMANDS, base, STAMP_PATHS + tuple(("effort", i) for i in range(3))
                     + (tuple(("velocity", i) for i in range(3)) if with_rates else ()))
        for state in random_states(20, seed=5):
            cur, rate = [float(c) for c in state[7]], [float(r) for r in state[8]] if with_rates else None
            sec, nanosec = divmod(stamp_ns(state[0]), 1_000_000_000)
            raw = t.encode(sec, nanosec, *cur, *(rate or []))
            fields = command_message(state[0], names, cur, rate)
            ros_msg = deserialize_message(raw, cls)
            assert ros_msg == to_ros(cls, fields)
            view = command_view(wire.decode(TOPIC_STATOR_COMMANDS, raw))
            assert (view.name, view.effort, view.velocity) == (list(ros_msg.name), list(ros_msg.effort),
                                                               list(ros_msg.velocity))
            assert all(type(v) is float for v in view.effort + view.velocity)
            assert (view.header.stamp.sec, view.header.stamp.nanosec) == (sec, nanosec)


def test_undecodable_bytes_are_rclpys_to_judge(wire):
    """Bytes rosbags cannot read (a truncated command) go to rclpy's reading, which decides as it would have taking
    the message itself (here: it raises, as before the bytes path)."""
    raw = bytes(cdr_message(TOPIC_STATOR_COMMANDS, command_message(1.0, ["a"], [1.0], None)))
    with pytest.raises(Exception):  # noqa: B017 - rclpy's own error, whatever its type
        wire.decode(TOPIC_STATOR_COMMANDS, raw[:10])


def test_state_bytes_are_the_builders_bytes(wire):
    """The simulator node's per-tick state messages straight from the numbers (state_bytes) are the bytes the
    builders' dicts give through the same templates, and rosbags' whole serialization of them."""
    tmpl = state_templates(wire)
    topics = (TOPIC_CLOCK, TOPIC_IMU, TOPIC_KINETIC_MOMENT)
    for state in random_states(300, seed=11):
        msgs = state_messages(*state)
        L, q, w = (np.asarray(v, dtype=float).tolist() for v in (state[1], state[2], state[3]))
        got = state_bytes(tmpl, topics, stamp_ns(state[0]), L, q, w)
        assert got == [tmpl[t].encode_fields(msgs[t]) for t in topics]
        assert got == [bytes(cdr_message(t, msgs[t])) for t in topics]


def test_command_reader_reads_as_the_whole_decoding(wire):
    """The simulator's reading of commands (CommandReader: a shape seen before by its template) gives the view the
    whole decoding gives (command_view), for commands of several shapes interleaved (with and without rates, other
    names, an empty one, a frame id, NaN and huge values, rclpy's own bytes), and reads most of them by template."""
    cls = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
    reader = CommandReader(wire)
    rng = np.random.default_rng(7)
    shapes = [(["s1", "s2", "s3"], True), (["s1", "s2", "s3"], False), (["s2"], True), ([], False),
              (["s3", "s1"], False)]
    raws = []
    for k in range(400):
        names, with_rates = shapes[k % len(shapes)]
        cur = [float(c) for c in rng.uniform(0, 5, len(names))]
        rate = [float(r) for r in rng.standard_normal(len(names)) * 100] if with_rates else None
        if k % 37 == 5 and names:
            cur[0] = math.nan if k % 2 else 1e308
        fields = command_message(float(rng.uniform(0, 1e4)), names, cur, rate)
        if k % 50 == 7:
            fields["header"]["frame_id"] = "somewhere"
        raw = bytes(cdr_message(TOPIC_STATOR_COMMANDS, fields))
        raws.append(raw if k % 13 != 3 else bytes(serialize_message(to_ros(cls, fields))))
    taken = []
    reader_decode = wire.decode
    calls = []
    wire.decode = lambda topic, raw: (calls.append(1), reader_decode(topic, raw))[1]
    try:
        for raw in raws:
            taken.append(reader.read(raw))
    finally:
        del wire.decode
    for raw, view in zip(raws, taken, strict=True):
        whole = command_view(reader_decode(TOPIC_STATOR_COMMANDS, raw))
        assert (view.name, view.header.stamp.sec, view.header.stamp.nanosec, view.header.frame_id) == (
            whole.name, whole.header.stamp.sec, whole.header.stamp.nanosec, whole.header.frame_id)
        for a, b in ((view.effort, whole.effort), (view.velocity, whole.velocity)):
            assert len(a) == len(b) and all(type(x) is float for x in a)
            assert all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b, strict=True))
    assert len(calls) < len(raws) // 4, f"{len(calls)} of {len(raws)} commands decoded whole"
