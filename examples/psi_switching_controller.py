#!/usr/bin/env python3
"""ψ-switching nutation control for gyro_sim, written from [K] (3.1) (plain rclpy; see docs/protocol.md).

The rotor's polar axis x3 precesses about the kinetic moment L; θ is the angle between them (nutation).
Let e⊥ = (x3 − y3 cosθ)/sinθ, y3 = L/|L|, be the unit vector of x3 projected on the plane normal to L
(docs/physics.md §5). Each control stator n (axis u_n in the case frame) turns its field at

    ν_n = ν · sign(u_n · e⊥)                                   # [K] (3.1)

so its direction flips twice per precession period, when x3 crosses the stator's plane; ν > 0 drives
θ → 0 (in finite time), ν < 0 drives θ → π. The spin stator stays on at spin_rate to make up the braking
torque. Inside the dead band (θ < dead_band or π − θ < dead_band, where e⊥ is ill-defined) the control
currents are off.

State in: gyro/imu (orientation = attitude body → case, quaternion x, y, z, w) and gyro/kinetic_moment
(L, case frame, N·m·s), published once per state with the same header stamp: they are paired by stamp.
Command out: gyro/stator_commands, stamped with the state's stamp (lockstep waits for it); effort =
current (A), velocity = signed field rate (rad/s).

Parameters (defaults: the controller section of the nutation_oblate scene; numbers with a decimal point):
control_stators ['z1', 'z2'], control_axes [1.0, 0.0, 0.0, 0.0, 1.0, 0.0] (the control stators' unit axes
u_n in the case frame, 3 numbers each: the scene's stators[].axis), nu [3000.0, 5000.0] (rad/s, one value
or one per control stator), control_current 0.316 (A), spin_stator 'z3', spin_current 0.5 (A), spin_rate
200.0 (rad/s), dead_band 0.001 (rad). Exits when the simulator reports "done:" on gyro/status.

    python3 examples/psi_switching_controller.py --ros-args -p nu:="[3000.0, 5000.0]"
"""
import math

import rclpy
from geometry_msgs.msg import Vector3Stamped
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import String

QOS = 100  # the contract's QoS: reliable, keep last 100, volatile (rclpy's default profile with depth 100)


def polar_axis(q):
    """x3 (the body's third axis) in the case frame, from the attitude quaternion (x, y, z, w) body → case."""
    x, y, z, w = q
    return (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def norm(a):
    return math.sqrt(dot(a, a))


def psi_switching(q, L, p):
    """{stator: (current A, field rate rad/s)} of [K] (3.1) for attitude q (x, y, z, w) and L (case frame)."""
    out = {p["spin_stator"]: (p["spin_current"], p["spin_rate"])}
    x3 = polar_axis(q)
    n = norm(L)
    theta = math.atan2(norm(cross(x3, L)), dot(x3, L)) if n > 0 else 0.0  # nutation angle
    e_perp = None
    if n > 0:
        y3 = tuple(c / n for c in L)
        c = dot(x3, y3)
        v = tuple(a - b * c for a, b in zip(x3, y3))  # x3 projected on the plane normal to L
        s = norm(v)
        e_perp = tuple(a / s for a in v) if s > 0 else None
    in_band = e_perp is None or theta < p["dead_band"] or math.pi - theta < p["dead_band"]
    for name, u, nu in zip(p["control_stators"], p["axes"], p["nu"]):
        if in_band:
            out[name] = (0.0, nu)  # control currents off near θ = 0, π
        else:
            out[name] = (p["control_current"], nu if dot(u, e_perp) >= 0.0 else -nu)  # [K] (3.1)
    return out


class PsiSwitchingController(Node):
    def __init__(self):
        super().__init__("psi_switching_controller")
        declare = lambda name, default: self.declare_parameter(name, default).value  # noqa: E731
        p = {"control_stators": list(declare("control_stators", ["z1", "z2"])),
             "spin_stator": declare("spin_stator", "z3"),
             "control_current": declare("control_current", 0.316),
             "spin_current": declare("spin_current", 0.5),
             "spin_rate": declare("spin_rate", 200.0),
             "dead_band": declare("dead_band", 0.001)}
        nu = list(declare("nu", [3000.0, 5000.0]))
        axes = list(declare("control_axes", [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]))
        k = len(p["control_stators"])
        if len(nu) not in (1, k) or len(axes) != 3 * k:
            raise SystemExit(f"psi_switching_controller: {k} control stators need 1 or {k} values of nu and "
                             f"{3 * k} numbers in control_axes (got {len(nu)} and {len(axes)})")
        p["nu"] = nu * k if len(nu) == 1 else nu
        p["axes"] = [tuple(axes[3 * i:3 * i + 3]) for i in range(k)]
        self.p = p
        self.pending = {}  # stamp (ns) → {'imu': Imu, 'L': Vector3Stamped}: the two halves of one state
        self.done = False
        self.pub = self.create_publisher(JointState, "gyro/stator_commands", QOS)
        self.create_subscription(Imu, "gyro/imu", lambda m: self.on_state("imu", m), QOS)
        self.create_subscription(Vector3Stamped, "gyro/kinetic_moment", lambda m: self.on_state("L", m), QOS)
        latched = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(String, "gyro/status", self.on_status, latched)

    def on_state(self, kind, msg):
        stamp = msg.header.stamp
        key = stamp.sec * 1_000_000_000 + stamp.nanosec
        entry = self.pending.setdefault(key, {})
        entry[kind] = msg
        if len(entry) < 2:
            if len(self.pending) > 1000:  # a half that never came: never grow without bound
                for old in sorted(self.pending)[:500]:
                    del self.pending[old]
            return
        del self.pending[key]
        o, v = entry["imu"].orientation, entry["L"].vector
        commands = psi_switching((o.x, o.y, o.z, o.w), (v.x, v.y, v.z), self.p)
        cmd = JointState()
        cmd.header.stamp = stamp  # the stamp of the state answered: lockstep waits for it
        cmd.name = list(commands)
        cmd.effort = [float(c) for c, _ in commands.values()]
        cmd.velocity = [float(r) for _, r in commands.values()]
        self.pub.publish(cmd)

    def on_status(self, msg):
        self.done = self.done or msg.data.startswith("done:")


def main():
    rclpy.init()
    node = PsiSwitchingController()
    try:
        while rclpy.ok() and not node.done:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # nothing to do at shutdown: the simulator's watchdog takes over
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
