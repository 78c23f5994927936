"""The live view (``gyro-sim run SCENE --live``, gyro_sim/io/live.py) and the Foxglove layout
(gyro_sim/io/foxglove_layout.py, config/foxglove_layout.json).

Two clients speak the Foxglove WebSocket protocol (https://github.com/foxglove/ws-protocol, docs/spec.md) to a
live run in a subprocess on 127.0.0.1:

* a Python one (``websockets``): serverInfo, advertise, subscribe, binary messageData (opcode 1: uint32
  subscription id, uint64 timestamp ns, payload), the payload CDR as in a bag (decoded by rosbags);
* the npm ``@foxglove/ws-protocol`` client with its default subprotocol (test/live_client: installed with npm
  into a temporary folder; skipped if node or npm is missing), decoding each message with the advertised ros2msg
  schema as a third-party tool does, and running the layout's user script over what it received.

The decoded samples equal the in-process run's. No assertion on timing: every receive has a generous timeout (a
bound for a hang, the numba kernels may compile first), the run waits for the client's subscriptions
(``--live-wait``) and keeps serving until it leaves (``--live-hold``).
"""
import json
import math
import os
import queue
import re
import shutil
import struct
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "config" / "foxglove_layout.json"
CLIENT = Path(__file__).resolve().parent / "live_client"
SCENE, DURATION = "spinup_thin_shell", 0.2  # s: 11 samples at the scene's 50 samples/s
RECV_TIMEOUT = 300.0  # s: bounds a hang (a first run compiles its kernels), never a timing check
NPM_TIMEOUT = 600.0  # s: bounds a hang of npm ci (a cold cache downloads ~30 MB), never a timing check
#: the two names of the protocol: the Foxglove app's / foxglove-sdk's, and the ws-protocol libraries'
SDK_V1, WS_V1 = "foxglove.sdk.v1", "foxglove.websocket.v1"
PER_SAMPLE = ["/gyro/imu", "/gyro/kinetic_moment", "/gyro/euler", "/gyro/torque", "/gyro/stators", "/tf"]


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


class _LiveRun:
    """``gyro-sim run SCENE --live`` in a subprocess (port 0, waiting for every channel's subscription, holding
    until the client leaves); :meth:`port` once it serves, :meth:`finish` its (exit status, stdout, stderr)."""

    def __init__(self, tmp_path, scene, duration, record=None):
        from gyro_sim.io.live import CHANNELS

        cmd = [sys.executable, "-m", "gyro_sim.apps.cli", "run", scene, "--duration", str(duration), "--out",
               tmp_path / "out", "--quiet", "--live", "--live-port", "0", "--live-wait", str(len(CHANNELS)),
               "--live-hold", "600", "--rate-factor", "10"] + (["--record", record] if record else [])
        self.proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=tmp_path, env=dict(os.environ, PYTHONPATH=os.pathsep.join(
                                         [str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p])))
        self.lines: queue.Queue = queue.Queue()
        self.seen: list = []
        threading.Thread(target=_lines, args=(self.proc.stderr, self.lines), daemon=True).start()

    def port(self) -> int:
        return _live_port(self.lines, self.seen)

    def finish(self) -> tuple:
        out, _ = self.proc.communicate(timeout=RECV_TIMEOUT)  # (the client left: the hold ends, the run exits)
        while True:
            line = self.lines.get(timeout=RECV_TIMEOUT)
            if line is None:
                break
            self.seen.append(line)
        return self.proc.returncode, out, "".join(self.seen)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def _receive(port: int, n_samples: int, subprotocols: list) -> tuple[str, dict, dict]:
    """Connect offering ``subprotocols``, subscribe to every channel, and collect the messages of each per-sample
    channel until each has ``n_samples``: (the subprotocol agreed, advertised channels by topic,
    topic → [(timestamp ns, CDR payload bytes)])."""
    from websockets.sync.client import connect

    with connect(f"ws://127.0.0.1:{port}", subprotocols=subprotocols, open_timeout=RECV_TIMEOUT,
                 proxy=None) as ws:
        info = json.loads(ws.recv(timeout=RECV_TIMEOUT))
        assert info["op"] == "serverInfo" and "time" in info["capabilities"], info
        channels: dict = {}
        while not set(PER_SAMPLE) <= set(channels):
            msg = json.loads(ws.recv(timeout=RECV_TIMEOUT))
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        subs = {i: c["topic"] for i, c in enumerate(channels.values())}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": channels[t]["id"]}
                                                                 for i, t in subs.items()]}))
        got: dict = {t: [] for t in channels}
        while any(len(got[t]) < n_samples for t in PER_SAMPLE):
            frame = ws.recv(timeout=RECV_TIMEOUT)
            if isinstance(frame, str) or frame[0] != 1:  # (status, time, advertise of a later channel)
                continue
            sub, ts = struct.unpack_from("<IQ", frame, 1)
            got[subs[sub]].append((ts, bytes(frame[13:])))
        return ws.subprotocol, channels, got


@pytest.mark.parametrize("record,subprotocol", [(False, WS_V1), (True, SDK_V1)], ids=["in-process", "recorded"])
def test_live_run_is_received_and_decoded(tmp_path, record, subprotocol):
    """Either name of the protocol is accepted (foxglove-sdk alone answers foxglove.websocket.v1 with HTTP 400);
    channels carry the bag's schemas (ros2msg, the same text) and the bag's CDR bytes."""
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    pytest.importorskip("websockets", reason="the test client (pip install '.[test]')")
    import gyro_sim
    from gyro_sim.io.bag_format import _typestore, ros2msg_schema
    from gyro_sim.io.live import CHANNELS
    from gyro_sim.io.messages import TOPIC_IMU, TOPIC_STATORS, TOPIC_TF, TOPIC_TF_STATIC, TOPICS, stamp_ns

    scene = gyro_sim.load_scene(SCENE)
    # the same run in this process (with a sample callback, as the live run: the same breaks, the same bits)
    ref = gyro_sim.run(scene, duration=DURATION, on_samples=lambda s: None, attitude=True)
    n = len(ref.t)
    bag = tmp_path / "bag"
    run = _LiveRun(tmp_path, SCENE, DURATION, bag if record else None)
    try:
        agreed, channels, got = _receive(run.port(), n, [subprotocol])
        code, out, err = run.finish()
    finally:
        run.kill()
    assert code == 0, err + out
    assert "final spin rate" in out
    assert agreed == subprotocol

    assert set(CHANNELS) <= set(channels)
    for topic, c in channels.items():  # the bag's schema record: type name, ros2msg, the same text; CDR
        assert (c["schemaName"], c["schema"]) == ros2msg_schema(topic), topic
        assert (c["encoding"], c["schemaEncoding"]) == ("cdr", "ros2msg"), topic
    ts_ = _typestore()
    msgs = {t: [(ts, ts_.deserialize_cdr(data, TOPICS[t])) for ts, data in got[t]] for t in got}
    # every sample, in order, stamped with its simulation time (message timestamp = header stamp)
    for topic in PER_SAMPLE:
        assert [ts for ts, _ in got[topic]] == [stamp_ns(t) for t in ref.t], topic
    for (ts, imu), (_, km), (_, eu), (_, st), (_, tf), i in zip(*(msgs[t] for t in PER_SAMPLE[:3]),
                                                               msgs[TOPIC_STATORS], msgs[TOPIC_TF], range(n)):
        assert (imu.header.stamp.sec, imu.header.stamp.nanosec) == (ts // 10**9, ts % 10**9)
        # spin rate (body z) and the attitude body -> case, every bit (CDR keeps the float64s)
        assert imu.angular_velocity.z == ref.omega_b[i, 2]
        o = imu.orientation
        np.testing.assert_allclose([o.w, o.x, o.y, o.z], ref.q[i], rtol=0, atol=1e-15)
        v = km.vector
        np.testing.assert_array_equal([v.x, v.y, v.z], ref.L[i])
        assert eu.vector.y == ref.euler[i, 1]  # θ
        assert st.name == list(ref.stator_names)
        np.testing.assert_array_equal(st.effort, ref.current[i])
        np.testing.assert_array_equal(st.velocity, ref.field_rate[i])
        rotor = {tr.child_frame_id: tr for tr in tf.transforms}["gyro_rotor"]
        assert rotor.header.frame_id == "gyro_case"
        assert (rotor.header.stamp.sec, rotor.header.stamp.nanosec) == (ts // 10**9, ts % 10**9)
        r = rotor.transform.rotation
        np.testing.assert_allclose([r.w, r.x, r.y, r.z], ref.q[i], rtol=0, atol=1e-15)
    assert {tr.child_frame_id for tr in msgs[TOPIC_TF][0][1].transforms} == {"gyro_rotor", "gyro_l_frame"}
    static = {tr.child_frame_id for _, m in msgs[TOPIC_TF_STATIC] for tr in m.transforms}
    assert static == {f"gyro_stator_{name}" for name in ref.stator_names}
    if record:  # the same bytes as the bag's messages, under the same schema
        from rosbags.rosbag2 import Reader

        with Reader(bag) as reader:
            assert _layout_topics(json.loads(LAYOUT.read_text())) <= set(reader.topics)
            for c in reader.connections:
                if c.topic in channels:
                    assert (c.msgtype, c.msgdef.data) == ros2msg_schema(c.topic), c.topic
            for topic in PER_SAMPLE + [TOPIC_TF_STATIC]:
                conns = [c for c in reader.connections if c.topic == topic]
                raw = [bytes(data) for _, _, data in reader.messages(connections=conns)]
                assert raw[:1] == [got[topic][0][1]], topic  # (/tf_static: once in the bag)
                if topic != TOPIC_TF_STATIC:
                    assert raw == [data for _, data in got[topic]], topic
        assert msgs[TOPIC_IMU][-1][1].angular_velocity.z == ref.omega_b[-1, 2]


# --- the npm client ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def npm_client(tmp_path_factory) -> Path:
    """test/live_client installed with ``npm ci`` (its package-lock.json) in a temporary folder: client.js's
    path. Skips if node or npm is missing; fails if the install fails."""
    missing = [tool for tool in ("node", "npm") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not found: the npm @foxglove/ws-protocol client cannot run "
                    "(install Node.js >= 18 with npm)")
    folder = tmp_path_factory.mktemp("live_client")
    for name in ("package.json", "package-lock.json", "client.js"):
        shutil.copy(CLIENT / name, folder / name)
    r = subprocess.run(["npm", "ci", "--no-audit", "--no-fund", "--loglevel=error"], cwd=folder,
                       capture_output=True, text=True, timeout=NPM_TIMEOUT)
    assert r.returncode == 0, f"npm ci in {folder} failed:\n{r.stdout}{r.stderr}"
    return folder / "client.js"


def _three_stators_turned(tmp_path) -> Path:
    """config/three_stators.yaml with its stators renamed and their axes turned off the case axes (no stator
    along the spin axis): a scene whose slip ν − Ω·u differs from field rate − spin for every stator."""
    text = (ROOT / "config" / "three_stators.yaml").read_text(encoding="utf-8")
    turned = {"z1": ("coil_a", "[0.8, 0.6, 0.0]"), "z2": ("coil_b", "[-0.6, 0.8, 0.0]"),
              "z3": ("coil_c", "[0.0, 0.6, 0.8]")}
    for old, (name, axis) in turned.items():
        text, count = re.subn(rf"name: {old}, axis: \[[^\]]*\]", f"name: {name}, axis: {axis}", text)
        assert count == 1, old
    path = tmp_path / "three_stators_turned.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_npm_ws_protocol_client_decodes_the_live_view_and_runs_the_layout(tmp_path, npm_client):
    """The npm @foxglove/ws-protocol client (default subprotocol foxglove.websocket.v1) connects, subscribes,
    decodes every channel as CDR with the advertised ros2msg schema; the layouts' user script gives the slip
    ν − Ω·u of gyro_sim.io.plotting.slip, and the scene's layout names the series by the stators' names."""
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    import gyro_sim
    from gyro_sim.io.messages import stamp_ns
    from gyro_sim.io.plotting import slip

    scene_file = _three_stators_turned(tmp_path)
    duration = 0.5  # s: 11 samples at the scene's 20 samples/s
    scene = gyro_sim.load_scene(scene_file)
    names = [st.name for st in scene.stators]
    ref = gyro_sim.run(scene, duration=duration, on_samples=lambda s: None, attitude=True)
    n = len(ref.t)
    want = slip(ref)
    assert np.isfinite(want).all() and np.abs(want - (ref.field_rate - ref.omega_b[:, 2:3])).min() > 1.0

    run = _LiveRun(tmp_path, str(scene_file), duration)
    layout = tmp_path / "out" / f"{scene.name}_foxglove_layout.json"
    try:
        port = run.port()
        assert str(layout) in "".join(run.seen)  # (announced with the server)
        r = subprocess.run(["node", str(npm_client), f"ws://127.0.0.1:{port}", str(n), ",".join(PER_SAMPLE),
                            str(layout), str(LAYOUT)], capture_output=True, text=True, timeout=RECV_TIMEOUT)
        code, out, err = run.finish()
    finally:
        run.kill()
    assert r.returncode == 0, r.stderr + "".join(run.seen)
    assert code == 0, err + out
    got = json.loads(r.stdout)
    assert got["subprotocol"] == WS_V1
    assert {c["topic"] for c in got["channels"]} >= set(PER_SAMPLE) | {"/tf_static"}
    imu = [m for _, m in got["messages"]["/gyro/imu"][:n]]
    st = [m for _, m in got["messages"]["/gyro/stators"][:n]]
    assert [int(ts) for ts, _ in got["messages"]["/gyro/imu"][:n]] == [stamp_ns(t) for t in ref.t]
    np.testing.assert_array_equal([[m["angular_velocity"][c] for c in "xyz"] for m in imu], ref.omega_b)
    np.testing.assert_array_equal([m["velocity"] for m in st], ref.field_rate)
    assert all(m["name"] == names for m in st)
    assert [m["header"]["frame_id"] for m in imu[:1]] == ["gyro_rotor"]

    # the user script of the scene's layout (the scene's axes) and of the shipped one (other names and axes:
    # it takes them from /tf_static): slip ν − Ω·u per stator, in the order of /gyro/stators.name
    for path in (layout, LAYOUT):
        outs = got["scripts"][str(path)][:n]
        s = np.array([[math.nan if v is None else v for v in o["slip"]] for o in outs])
        np.testing.assert_allclose(s, want, rtol=1e-9, atol=1e-9, err_msg=str(path))
    mine = json.loads(layout.read_text(encoding="utf-8"))
    for panel in ("Plot!slip", "Plot!currents"):
        assert [p["label"] for p in mine["configById"][panel]["paths"]] == names, panel
    # the scripts type-check as strict TypeScript (the app reports a script's type errors instead of running it)
    sources = []
    for i, path in enumerate((layout, LAYOUT)):
        (node,) = json.loads(path.read_text(encoding="utf-8"))["userNodes"].values()
        sources.append(tmp_path / f"script{i}.ts")
        sources[-1].write_text(node["sourceCode"], encoding="utf-8")
    tsc = npm_client.parent / "node_modules" / "typescript" / "bin" / "tsc"
    r = subprocess.run(["node", str(tsc), "--strict", "--noEmit", "--noUnusedLocals", "--target", "ES2020", "--lib",
                        "ES2020"] + [str(p) for p in sources], capture_output=True, text=True, timeout=RECV_TIMEOUT)
    assert r.returncode == 0, r.stdout + r.stderr


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
    from gyro_sim.io.foxglove_layout import SCRIPT_OUTPUT, STANDARD_STATORS, layout, layout_text
    from gyro_sim.io.live import CHANNELS
    from gyro_sim.io.messages import FRAME_CASE, FRAME_L, FRAME_ROTOR, TOPICS, state_messages

    text = LAYOUT.read_text(encoding="utf-8")
    assert text == layout_text(layout(STANDARD_STATORS))  # the shipped file is the generator's, for z1, z2, z3
    layout = json.loads(text)
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
    assert re.search(r'export const output = "([^"]+)";', src).group(1) == SCRIPT_OUTPUT
    assert SCRIPT_OUTPUT.startswith("/studio_script/")
    for path in series:
        if path.startswith(SCRIPT_OUTPUT + "."):
            assert re.match(r"[A-Za-z_]+", path[len(SCRIPT_OUTPUT) + 1:]).group(0) in src, path


def test_layout_names_each_stator_series_by_the_stator():
    """Series per stator carry the stator's name (not "stator 1..3"), read the stator's index in /gyro/stators,
    and the slip panel plots the script's ν − Ω·u with the scene's axes as its starting values."""
    import gyro_sim
    from gyro_sim.io.foxglove_layout import SCRIPT_OUTPUT, layout, scene_layout

    shipped = json.loads(LAYOUT.read_text(encoding="utf-8"))["configById"]
    assert [p["label"] for p in shipped["Plot!slip"]["paths"]] == ["z1", "z2", "z3"]
    assert not any("stator " in p["label"] for cfg in shipped.values() for p in cfg.get("paths", []))
    mine = layout([("coil_a", (0.0, 3.0, 4.0)), ("coil_b", (1.0, 0.0, 0.0))])
    cfg = mine["configById"]
    assert [(p["value"], p["label"]) for p in cfg["Plot!slip"]["paths"]] == [
        (f"{SCRIPT_OUTPUT}.slip[0]", "coil_a"), (f"{SCRIPT_OUTPUT}.slip[1]", "coil_b")]
    assert [(p["value"], p["label"]) for p in cfg["Plot!currents"]["paths"]] == [
        ("/gyro/stators.effort[0]", "coil_a"), ("/gyro/stators.effort[1]", "coil_b")]
    assert [p["label"] for p in cfg["Plot!spin"]["paths"][1:]] == ["field rate ν, coil_a", "field rate ν, coil_b"]
    (node,) = mine["userNodes"].values()
    assert 'const axes: Record<string, Vec> = {"coil_a": [0.0, 0.6, 0.8], "coil_b": [1.0, 0.0, 0.0]};' in \
        node["sourceCode"]
    sc = gyro_sim.load_scene("spinup_solid_sphere")
    assert [p["label"] for p in scene_layout(sc)["configById"]["Plot!slip"]["paths"]] == [st.name for st in sc.stators]
    with pytest.raises(ValueError, match=r"stator 'x': axis \[0, 0, 0\] must be 3 finite numbers"):
        layout([("x", [0, 0, 0])])


def test_live_without_foxglove_is_one_line_before_any_work(tmp_path):
    # foxglove cannot be imported in the run's process (a sitecustomize on PYTHONPATH)
    (tmp_path / "site").mkdir()
    (tmp_path / "site/sitecustomize.py").write_text("import sys\nsys.modules['foxglove'] = None\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path / "site"), str(ROOT)]))
    r = subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", "run", SCENE, "--live", "--out",
                        str(tmp_path / "out"), "--record", str(tmp_path / "bag")], capture_output=True, text=True,
                       timeout=300, cwd=tmp_path, env=env)
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
    from gyro_sim.apps.cli import main

    assert main(["run", SCENE, "--live", "--out", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(message), err
    assert not (tmp_path / "out").exists()


def test_pacing_follows_the_rate_factor_on_a_fake_clock():
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    import gyro_sim
    from gyro_sim.io.live import LiveView

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


def test_relay_accepts_both_protocol_names_and_refuses_others():
    """The port a client reaches takes foxglove.sdk.v1 (preferred when both are offered) and
    foxglove.websocket.v1, and refuses another or none with HTTP 400, as foxglove-sdk's own server (behind it)
    refuses foxglove.websocket.v1."""
    pytest.importorskip("foxglove", reason="the extra 'live' (pip install '.[live]') is not installed")
    import gyro_sim
    from gyro_sim.io.live import LiveView
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    with LiveView(gyro_sim.load_scene(SCENE), port=0) as lv:
        url = f"ws://127.0.0.1:{lv.port}"
        for offer, agreed in (([WS_V1], WS_V1), ([SDK_V1], SDK_V1), ([WS_V1, SDK_V1], SDK_V1)):
            with connect(url, subprotocols=offer, proxy=None, open_timeout=RECV_TIMEOUT) as ws:
                assert ws.subprotocol == agreed
                assert json.loads(ws.recv(timeout=RECV_TIMEOUT))["op"] == "serverInfo"
        for offer in (None, ["foxglove.websocket.v2"]):
            with pytest.raises(InvalidStatus, match="HTTP 400"):
                connect(url, subprotocols=offer, proxy=None, open_timeout=RECV_TIMEOUT)
        assert lv.server.port != lv.port
        with pytest.raises(InvalidStatus, match="HTTP 400"):  # (the SDK's server: foxglove.sdk.v1 only)
            connect(f"ws://127.0.0.1:{lv.server.port}", subprotocols=[WS_V1], proxy=None, open_timeout=RECV_TIMEOUT)
