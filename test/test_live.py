"""The live view (``gyro-sim run SCENE --live``, gyro_sim/io/live.py) and the Foxglove layout (config/
foxglove_layout.json).

A test client speaks the Foxglove WebSocket protocol (https://github.com/foxglove/ws-protocol) to a live run in a
subprocess on 127.0.0.1: serverInfo, advertise, subscribe, binary messageData (opcode 1: uint32 subscription id,
uint64 timestamp ns, JSON payload); the decoded samples equal the in-process run's. No assertion on timing: every
receive has a generous timeout (a bound for a hang, the numba kernels may compile first), the run waits for the
client's subscriptions (``--live-wait``) and keeps serving until it leaves (``--live-hold``).
"""
import json
import os
import queue
import re
import struct
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "config" / "foxglove_layout.json"
SCENE, DURATION = "spinup_thin_shell", 0.2  # s: 11 samples at the scene's 50 samples/s
RECV_TIMEOUT = 300.0  # s: bounds a hang (a first run compiles its kernels), never a timing check
#: the subprotocol of the Foxglove WebSocket protocol (foxglove-sdk >= 0.30 also offers its successor)
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]


def _lines(stream, out: queue.Queue) -> None:
    for line in stream:
        out.put(line)
    out.put(None)


def _live_port(lines: queue.Queue, seen: list) -> int:
    """The port of the ``live view: ws://127.0.0.1:PORT`` line of the run's stderr."""
    while True:
        line = lines.get(timeout=RECV_TIMEOUT)
        assert line is not None, "the run ended before serving: " + "".join(seen)
        seen.append(line)
        m = re.match(r"live view: ws://127\.0\.0\.1:(\d+) ", line)
        if m:
            return int(m.group(1))


def _receive(port: int, per_sample: list, n_samples: int) -> tuple[dict, dict]:
    """Connect, subscribe to every channel, and collect the JSON messages of each per-sample channel until each
    has ``n_samples``: (advertised channels by topic, topic → [(timestamp ns, message)])."""
    from websockets.sync.client import connect

    got: dict = {}
    with connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=RECV_TIMEOUT,
                 proxy=None) as ws:
        assert ws.subprotocol in SUBPROTOCOLS
        info = json.loads(ws.recv(timeout=RECV_TIMEOUT))
        assert info["op"] == "serverInfo" and "time" in info["capabilities"], info
        channels: dict = {}
        while not set(per_sample) <= set(channels):
            msg = json.loads(ws.recv(timeout=RECV_TIMEOUT))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        subs = {i: c["topic"] for i, c in enumerate(channels.values())}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": channels[t]["id"]}
                                                                 for i, t in subs.items()]}))
        got = {t: [] for t in channels}
        while any(len(got[t]) < n_samples for t in per_sample):
            frame = ws.recv(timeout=RECV_TIMEOUT)
            if isinstance(frame, str) or frame[0] != 1:  # (status, time, advertise of a later channel)
                continue
            sub, ts = struct.unpack_from("<IQ", frame, 1)
            got[subs[sub]].append((ts, json.loads(frame[13:])))
    return channels, got


@pytest.mark.parametrize("record", [False, True], ids=["in-process", "recorded"])
def test_live_run_is_received_and_decoded(tmp_path, record):
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    pytest.importorskip("websockets", reason="the test client (pip install '.[test]')")
    import gyro_sim
    from gyro_sim.live import CHANNELS
    from gyro_sim.messages import (TOPIC_EULER, TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATORS, TOPIC_TF,
                                   TOPIC_TF_STATIC, TOPIC_TORQUE, stamp_ns)

    per_sample = [TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_EULER, TOPIC_TORQUE, TOPIC_STATORS, TOPIC_TF]
    scene = gyro_sim.load_scene(SCENE)
    # the same run in this process (with a sample callback, as the live run: the same breaks, the same bits)
    ref = gyro_sim.run(scene, duration=DURATION, on_samples=lambda s: None, attitude=True)
    n = len(ref.t)
    bag = tmp_path / "bag"
    cmd = [sys.executable, "-m", "gyro_sim.cli", "run", SCENE, "--duration", str(DURATION), "--out", tmp_path,
           "--quiet", "--live", "--live-port", "0", "--live-wait", str(len(CHANNELS)), "--live-hold", "600",
           "--rate-factor", "10"] + (["--record", bag] if record else [])
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True).start()
    seen: list = []
    try:
        channels, got = _receive(_live_port(lines, seen), per_sample, n)
        out, _ = proc.communicate(timeout=RECV_TIMEOUT)  # (the client left: the hold ends, the run exits)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, "".join(seen) + out
    assert "final spin rate" in out

    assert set(CHANNELS) <= set(channels)
    assert channels[TOPIC_TF]["schemaName"] == "foxglove.FrameTransforms"
    assert channels[TOPIC_IMU]["schemaName"] == "sensor_msgs/msg/Imu"
    assert all(c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema" for c in channels.values())
    # every sample, in order, stamped with its simulation time (message timestamp = header stamp)
    for topic in per_sample:
        assert [ts for ts, _ in got[topic]] == [stamp_ns(t) for t in ref.t], topic
    for (ts, imu), (_, km), (_, eu), (_, st), (_, tf), i in zip(*(got[t] for t in per_sample[:3]),
                                                               got[TOPIC_STATORS], got[TOPIC_TF], range(n)):
        assert imu["header"]["stamp"] == {"sec": ts // 10**9, "nanosec": ts % 10**9}
        # spin rate (body z) and the attitude body -> case, to round-off (JSON keeps every bit of a float)
        assert imu["angular_velocity"]["z"] == pytest.approx(ref.omega_b[i, 2], rel=1e-12, abs=1e-12)
        o = imu["orientation"]
        np.testing.assert_allclose([o["w"], o["x"], o["y"], o["z"]], ref.q[i], rtol=0, atol=1e-12)
        v = km["vector"]
        np.testing.assert_allclose([v["x"], v["y"], v["z"]], ref.L[i], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose([eu["vector"]["y"]], [ref.euler[i, 1]], rtol=1e-9, atol=1e-12)  # θ
        assert st["name"] == list(ref.stator_names)
        np.testing.assert_allclose(st["effort"], ref.current[i], rtol=1e-12, atol=0)
        np.testing.assert_allclose(st["velocity"], ref.field_rate[i], rtol=1e-12, atol=0)
        rotor = {tr["child_frame_id"]: tr for tr in tf["transforms"]}["gyro_rotor"]
        assert rotor["parent_frame_id"] == "gyro_case" and rotor["timestamp"] == {"sec": ts // 10**9,
                                                                                   "nsec": ts % 10**9}
        r = rotor["rotation"]
        np.testing.assert_allclose([r["w"], r["x"], r["y"], r["z"]], ref.q[i], rtol=0, atol=1e-12)
    assert {tr["child_frame_id"] for tr in got[TOPIC_TF][0][1]["transforms"]} == {"gyro_rotor", "gyro_l_frame"}
    static = {tr["child_frame_id"] for _, m in got[TOPIC_TF_STATIC] for tr in m["transforms"]}
    assert static == {f"gyro_stator_{name}" for name in ref.stator_names}
    if record:
        from gyro_sim.recording import bag_info, read_bag

        assert _layout_topics(json.loads(LAYOUT.read_text())) <= set(bag_info(bag)["topics"])
        b = read_bag(bag)
        np.testing.assert_array_equal(b.omega_b[:, 2], [m["angular_velocity"]["z"] for _, m in got[TOPIC_IMU]])


def _panels(node) -> list:
    """Panel ids of a layout's mosaic tree."""
    return [node] if isinstance(node, str) else _panels(node["first"]) + _panels(node["second"])


def _layout_topics(layout: dict) -> set:
    """The data-source topics a layout reads: plot series, 3D topics, user-script inputs (not script outputs)."""
    out = set()
    for cfg in layout["configById"].values():
        out |= {re.match(r"(/[^.\[]+)", p["value"]).group(1) for p in cfg.get("paths", [])}
        out |= set(cfg.get("topics", {}))
    for node in layout["userNodes"].values():
        out |= set(json.loads(re.search(r"export const inputs = (\[[^\]]*\]);", node["sourceCode"]).group(1)))
    return {t for t in out if not t.startswith("/studio_script/")}


def test_layout_follows_foxglove_format_and_reads_the_live_and_bag_topics():
    from gyro_sim.live import CHANNELS
    from gyro_sim.messages import FRAME_CASE, FRAME_L, FRAME_ROTOR, TOPICS, state_messages

    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    # the app's exported layout: configById (panel id "<type>!<suffix>" → config), a mosaic tree of the ids
    assert {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"} <= set(layout)
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"]) and len(set(panels)) == len(panels)
    kinds = [p.split("!")[0] for p in panels]
    assert kinds.count("3D") == 1 and kinds.count("Plot") == 5
    three_d = layout["configById"][panels[kinds.index("3D")]]
    assert three_d["followTf"] == FRAME_CASE
    assert {f"frame:{f}" for f in (FRAME_ROTOR, FRAME_L)} <= set(three_d["transforms"])
    # every topic it reads is advertised by a live run and written to every bag, under the same name
    topics = _layout_topics(layout)
    assert topics and topics <= set(CHANNELS) & set(TOPICS)
    # ... with the fields the paths name (the same message fields live and in bags)
    example = state_messages(0.0, [1.0, 2.0, 3.0], [1.0, 0, 0, 0], [0, 0, 4.0], [0.1, 0.2, 0.3], [0, 0, 0],
                             ["a", "b", "c"], [1.0, 2.0, 3.0], [5.0, 6.0, 7.0], [0, 0, 0])
    series = [p["value"] for cfg in layout["configById"].values() for p in cfg.get("paths", [])]
    for path in series:
        if path.startswith("/studio_script/"):
            continue
        topic, rest = re.match(r"(/[^.\[]+)\.(.*)", path).groups()
        value = example[topic]
        for key, index in re.findall(r"([A-Za-z_]+)(?:\[(\d+)\])?", rest):
            value = value[key] if index == "" else value[key][int(index)]
        assert isinstance(value, float), path
    # the user script: the output topic prefix user scripts need, the fields its plots read
    (node,) = layout["userNodes"].values()
    src = node["sourceCode"]
    out = re.search(r'export const output = "([^"]+)";', src).group(1)
    assert out.startswith("/studio_script/")
    for path in series:
        if path.startswith(out + "."):
            assert re.match(r"[A-Za-z_]+", path[len(out) + 1:]).group(0) in src, path
    for field in ("vector.x", "angular_velocity.z", "vector.y", "velocity"):
        assert f"m.{field}" in src


def test_live_without_foxglove_is_one_line_before_any_work(tmp_path):
    # foxglove cannot be imported in the run's process (a sitecustomize on PYTHONPATH)
    (tmp_path / "site").mkdir()
    (tmp_path / "site/sitecustomize.py").write_text("import sys\nsys.modules['foxglove'] = None\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path / "site"), str(ROOT)]))
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", SCENE, "--live", "--out", str(tmp_path / "out"),
                        "--record", str(tmp_path / "bag")], capture_output=True, text=True, timeout=300,
                       cwd=tmp_path, env=env)
    assert (r.returncode, r.stderr.splitlines()) == (
        2, ["error: gyro-sim run --live needs the 'live' extra: pip install 'gyro_sim[live]' (missing: foxglove)"]), r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site"]  # nothing was run or written


@pytest.mark.parametrize("extra,message", [
    (["--ros"], "error: --live serves an in-process run; with --ros, serve the nodes' topics with foxglove_bridge"),
    (["--rate-factor", "0"], "error: --rate-factor 0.0: must be a positive number"),
    (["--live-port", "70000"], "error: --live-port 70000: must be a TCP port"),
    (["--fidelity", "auto"], "error: --fidelity auto: --live streams the full model's samples"),
])
def test_live_bad_usage_is_one_line(tmp_path, capsys, extra, message):
    from gyro_sim.cli import main

    assert main(["run", SCENE, "--live", "--out", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(message), err
    assert not (tmp_path / "out").exists()


def test_pacing_follows_the_rate_factor_on_a_fake_clock():
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    import gyro_sim
    from gyro_sim.live import LiveView

    now = [100.0]
    slept = []

    def sleep(s):
        slept.append(s)
        now[0] += s

    with LiveView(gyro_sim.load_scene(SCENE), port=0, rate_factor=4.0, clock=lambda: now[0], sleep=sleep) as lv:
        q, z3 = [1.0, 0.0, 0.0, 0.0], [0.0] * 3
        for t in (0.0, 0.2, 0.4):
            lv.publish(t, [0, 0, 1.0], q, z3, z3, z3, z3, z3, z3)
        assert slept == pytest.approx([0.05, 0.05])  # 0.2 simulated s at 4x
        now[0] += 10.0  # far behind (e.g. a compile): the clock slips, no burst to catch up
        lv.publish(0.6, [0, 0, 1.0], q, z3, z3, z3, z3, z3, z3)
        lv.publish(0.8, [0, 0, 1.0], q, z3, z3, z3, z3, z3, z3)
        assert slept[2:] == pytest.approx([0.05])
        assert lv.samples_sent == 5 and lv.port > 0
