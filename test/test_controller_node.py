"""The controller node's ROS parameters over the parameter services (a real node process, a probe process).

Every law parameter shows the value in force (the scene's controller section merged with the parameters
set, with the defaults the law fills in); a parameter of a law not in force shows its unset value (NaN, ''
or ['']); a set naming a stator the scene does not have, or a parameter of another law, is refused with
the reason; a law switch works when the new law's parameters are complete.
"""
import json
import math

import pytest
import yaml

pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")

from test_ros import PROBE, PROBE_WINDOW, ROOT, Procs, finish  # noqa: E402

pytestmark = pytest.mark.ros

SPINUP = ["stator", "target_spin", "current", "ramp"]
PSI = ["control_stators", "spin_stator", "nu", "control_current", "spin_current", "spin_rate", "dead_band"]
ALL = ["law", *SPINUP, *PSI]
ALLOWED = "allowed: ['z1', 'z2', 'z3']"
SPINUP_REASON = "not a parameter of law 'spinup' (its parameters: stator, target_spin, current, ramp)"
PSI_REASON = ("not a parameter of law 'psi_switching' (its parameters: control_stators, spin_stator, nu, "
              "control_current, spin_current, spin_rate, dead_band)")


@pytest.fixture
def ros():
    p = Procs()
    yield p
    p.close()


def params_session(ros, tmp_path, requests, *ctl_args) -> list:
    """Start a controller with ``ctl_args`` (after --ros-args), run ``requests`` from a probe process; the
    answers (the controller must still be running at the end)."""
    ctl = ros.start("-m", "gyro_ctl.ros.controller_node", "--ros-args", *ctl_args)
    out = tmp_path / "params.json"
    code, text = finish(ros.start(PROBE, "params", str(out), str(PROBE_WINDOW), "gyro_controller",
                                  json.dumps(requests)), PROBE_WINDOW * 3)
    assert code == 0, text
    res = json.loads(out.read_text())
    assert ctl.poll() is None, "the controller ended"
    assert res["ready"], "the controller's parameter services did not come up"
    assert len(res["answers"]) == len(requests)
    return res["answers"]


def unset(v) -> bool:
    return v == "" or v == [""] or (isinstance(v, float) and math.isnan(v))


class Checks:
    """Every check of a session is made and the failing ones reported together (one node start covers many)."""

    def __init__(self, requests, answers):
        self.r, self.a, self.failed = requests, answers, []

    def fail(self, i, what):
        (op, arg), = self.r[i].items()
        self.failed.append(f"request {i} ({op}{'' if op in ('get', 'describe') else ' ' + json.dumps(arg)}): {what}")

    def same(self, i, want: dict) -> None:
        got = self.a[i]
        for n, v in want.items():
            if not (got.get(n) == v and type(got.get(n)) is type(v)):  # (a float is not shown as an int)
                self.fail(i, f"{n} = {got.get(n)!r}, expected {v!r}")

    def unset(self, i, names) -> None:
        bad = [n for n in names if not unset(self.a[i][n])]
        if bad:
            self.fail(i, f"{bad} should show their unset value")

    def refused(self, i, *fragments) -> None:
        r = self.a[i][0] if isinstance(self.a[i], list) else self.a[i]
        if r["successful"]:
            self.fail(i, "accepted, should be refused")
        elif not all(f in r["reason"] for f in fragments):
            self.fail(i, f"reason {r['reason']!r} lacks one of {fragments}")

    def ok(self, i) -> None:
        rs = self.a[i] if isinstance(self.a[i], list) else [self.a[i]]
        if not all(r["successful"] for r in rs):
            self.fail(i, f"refused, should be accepted: {[r['reason'] for r in rs]}")

    def done(self):
        assert not self.failed, "\n".join(self.failed)


def test_psi_switching_controller_from_the_params_file(ros, tmp_path):
    """config/controller.params.yaml (whatever its node key): the values in force, refusals, a valid set, switches
    psi_switching → spinup (its parameters in one atomic call; stator from the law's default) → off →
    psi_switching (completed from the scene: the scene's values)."""
    pfile = ROOT / "config" / "controller.params.yaml"
    (file_params,) = [v["ros__parameters"] for v in yaml.safe_load(pfile.read_text()).values()]
    reqs = [
        {"get": ALL},  # 0
        {"describe": ["scene", *ALL]},  # 1
        {"set": {"spin_stator": "z7"}},  # 2
        {"set": {"control_stators": ["z1", "z9"]}},  # 3
        {"set": {"target_spin": 100.0}},  # 4
        {"set": {"control_current": 0.2}},  # 5
        {"set": {"nu": [4000, 6000]}},  # 6 (integers: shown as the floats in force)
        {"set": {"scene": "spinup_thin_shell"}},  # 7
        {"get": ALL},  # 8
        {"set_atomically": {"law": "spinup", "target_spin": 500.0, "current": 0.3}},  # 9
        {"get": ALL},  # 10
        {"set": {"stator": "z9"}},  # 11
        {"set": {"nu": 3000.0}},  # 12
        {"set": {"law": "off"}},  # 13
        {"get": ALL},  # 14
        {"set": {"law": "psi_switching"}},  # 15
        {"get": ALL},  # 16
    ]
    a = params_session(ros, tmp_path, reqs, "--params-file", str(pfile))
    psi = {"law": "psi_switching", "control_stators": ["z1", "z2"], "spin_stator": "z3",
           **{n: file_params[n] for n in ("nu", "control_current", "spin_current", "spin_rate", "dead_band")}}
    assert file_params["law"] == "psi_switching"
    c = Checks(reqs, a)
    c.same(0, psi)
    c.unset(0, SPINUP)

    d = a[1]
    if not d["scene"]["read_only"] or any(d[n]["read_only"] for n in ALL):
        c.fail(1, "scene (only) should be read-only")
    units = {"target_spin": "rad/s", "current": " A", "ramp": "A/s", "nu": "rad/s", "control_current": " A",
             "spin_current": " A", "spin_rate": "rad/s", "dead_band": "rad"}
    for n in ALL:
        if units.get(n, "") not in d[n]["description"] or (n != "law" and "not in force" not in d[n]["description"]):
            c.fail(1, f"description of {n} lacks its unit or what it shows when not in force: {d[n]['description']!r}")

    c.refused(2, "spin_stator = 'z7'", "'z7' is not defined", ALLOWED)
    c.refused(3, "control_stators = ['z1', 'z9']", "'z9' is not defined", ALLOWED)
    c.refused(4, "target_spin: " + PSI_REASON)
    c.ok(5)
    c.ok(6)
    c.refused(7, "scene")
    c.same(8, {**psi, "control_current": 0.2, "nu": [4000.0, 6000.0]})

    c.ok(9)
    c.same(10, {"law": "spinup", "stator": "z3", "target_spin": 500.0, "current": 0.3, "ramp": 0.0})
    c.unset(10, PSI)
    c.refused(11, "stator = 'z9'", "'z9' is not defined", ALLOWED)
    c.refused(12, "nu: " + SPINUP_REASON)

    c.ok(13)
    c.same(14, {"law": "off"})
    c.unset(14, SPINUP + PSI)
    c.ok(15)
    c.same(16, psi)  # the scene's values (the same as the file's), not the ones set before the switches
    c.unset(16, SPINUP)
    c.done()


def test_spinup_controller_parameters_and_switch_to_psi_switching(ros, tmp_path):
    """Scene spinup_thin_shell: the scene's values in force, another law's parameter refused (alone and with law),
    a law switch refused while its parameters are incomplete, done in one atomic call (the law model's
    defaults shown), and back to spinup from the scene."""
    reqs = [
        {"get": ALL},  # 0
        {"set": {"nu": 3000.0}},  # 1
        {"set_atomically": {"law": "spinup", "nu": 3000.0}},  # 2
        {"set": {"law": "psi_switching"}},  # 3
        {"set": {"law": "bogus"}},  # 4
        {"set": {"current": 2, "ramp": 0.5}},  # 5
        {"get": ALL},  # 6
        {"set_atomically": {"law": "psi_switching", "nu": [3000.0, 5000.0], "control_current": 0.3,
                            "spin_current": 0.5, "spin_rate": 200.0, "spin_stator": "z9"}},  # 7
        {"set_atomically": {"law": "psi_switching", "nu": [3000.0, 5000.0], "control_current": 0.3,
                            "spin_current": 0.5, "spin_rate": 200.0}},  # 8
        {"get": ALL},  # 9
        {"set": {"law": "spinup"}},  # 10
        {"get": ALL},  # 11
    ]
    a = params_session(ros, tmp_path, reqs, "-p", "scene:=spinup_thin_shell")
    spinup = {"law": "spinup", "stator": "z3", "target_spin": 3141.592653589793, "current": 1.0, "ramp": 0.0}
    c = Checks(reqs, a)
    c.same(0, spinup)
    c.unset(0, PSI)
    c.refused(1, "nu: " + SPINUP_REASON)
    c.refused(2, "nu: " + SPINUP_REASON)
    c.refused(3, "law 'psi_switching'", "nu", "control_current", "spin_current", "spin_rate")
    c.refused(4, "law = 'bogus'", "spinup, psi_switching")
    c.ok(5)
    c.same(6, {**spinup, "current": 2.0, "ramp": 0.5})
    c.refused(7, "spin_stator = 'z9'", ALLOWED)
    c.ok(8)
    c.same(9, {"law": "psi_switching", "control_stators": ["z1", "z2"], "spin_stator": "z3", "nu": [3000.0, 5000.0],
               "control_current": 0.3, "spin_current": 0.5, "spin_rate": 200.0, "dead_band": 1e-3})
    c.unset(9, SPINUP)
    c.ok(10)
    c.same(11, spinup)  # the scene's values
    c.unset(11, PSI)
    c.done()


@pytest.mark.parametrize("params,reason", [
    ({"scene": "nutation_oblate", "control_stators": "[z1, z9]"},
     "control_stators = ['z1', 'z9']: stator 'z9' is not defined; " + ALLOWED),
    ({"scene": "spinup_thin_shell", "nu": 3.0}, "nu: " + SPINUP_REASON),
])
def test_bad_parameters_at_start_up_are_refused(ros, params, reason):
    code, out = finish(ros.controller(**params), 60)
    print(f"\n  controller {params}: exit {code}: {out.strip().splitlines()[-1] if out.strip() else ''}")
    assert code == 2
    errors = [ln for ln in out.splitlines() if "controller: error:" in ln]
    assert len(errors) == 1 and reason in errors[0], out


SUBS_SCRIPT = r"""
import json, sys
import rclpy
from gyro_ctl.ros.controller_node import ControllerNode
from gyro_sim.io.messages import TOPIC_KINETIC_MOMENT, node_topic
from rclpy.parameter import Parameter

rclpy.init(args=["ctl", "--ros-args", "-p", "scene:=" + sys.argv[1]])
node = ControllerNode()
sent = []
node.pub.publish = lambda m: sent.append(m)  # (the commands the node publishes, seen here)
L_topic = node.get_namespace().rstrip("/") + "/" + node_topic(TOPIC_KINETIC_MOMENT)


def seen():
    return {"kinds": list(node.kinds), "subs": sorted(node.subs), "L_subscribers": node.count_subscribers(L_topic)}


out = {"start": seen()}
psi = {"law": "psi_switching", "control_stators": ["z1", "z2"], "spin_stator": "z3", "nu": [3000.0, 5000.0],
       "control_current": 0.3, "spin_current": 0.5, "spin_rate": 200.0}
r = node.set_parameters_atomically([Parameter(k, value=v) for k, v in psi.items()])
out["switch_ok"], out["resubscribe"] = r.successful, node.resubscribe
node.subscribe()
out["psi"] = seen()
imu = [0, 20_000_000, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 3000.0]  # stamp 0.02 s, q = 1, Ω_b along x3
node._on(imu, "imu")  # half of a state: ψ-switching waits for its L
out["answered_half"], out["half"] = len(sent), node.half
r = node.set_parameters_atomically([Parameter("law", value="spinup")])
node.subscribe()  # the switch back: the waiting state is answered at once (a lockstep simulator waits for it)
out["spinup"], out["answered_after"], out["pending"] = seen(), len(sent), len(node.pending)
print(json.dumps(out))
node.destroy_node()
rclpy.shutdown()
"""


def test_the_controller_subscribes_to_L_only_where_its_law_reads_it(ros):
    """Spin-up reads no kinetic moment: the controller subscribes to gyro/imu alone, so the simulator publishes one
    state message a tick instead of two (before: gyro/kinetic_moment too, whatever the law). A switch to
    ψ-switching subscribes to it; a state half in at a switch back is answered at once."""
    code, text = finish(ros.start("-c", SUBS_SCRIPT, "spinup_thin_shell"), 120)
    assert code == 0, text
    out = json.loads(text.strip().splitlines()[-1])
    assert out["start"] == {"kinds": ["imu"], "subs": ["imu"], "L_subscribers": 0}, out["start"]
    assert out["switch_ok"] and out["resubscribe"]
    assert out["psi"] == {"kinds": ["imu", "L"], "subs": ["L", "imu"], "L_subscribers": 1}, out["psi"]
    assert out["answered_half"] == 0 and out["half"]
    assert out["spinup"]["subs"] == ["imu"] and out["spinup"]["L_subscribers"] == 0, out["spinup"]
    assert out["answered_after"] == 1 and out["pending"] == 0


def test_psi_switching_scene_subscribes_to_both(ros):
    """ψ-switching reads L and the attitude: both state topics from the start."""
    code, text = finish(ros.start("-c", SUBS_SCRIPT, "nutation_oblate"), 120)
    assert code == 0, text
    out = json.loads(text.strip().splitlines()[-1])
    assert out["start"] == {"kinds": ["imu", "L"], "subs": ["L", "imu"], "L_subscribers": 1}, out["start"]
