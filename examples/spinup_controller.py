#!/usr/bin/env python3
"""A minimal spin-up controller for gyro_sim (plain rclpy; see docs/protocol.md).

Answers every state the simulator publishes on gyro/kinetic_moment with a command stamped like
that state (lockstep): stator `stator` at `current` A, its field turning at `target_spin` rad/s,
the zero-slip asymptote of the spin-up of [K] §1 (torque ∝ ν − Ω, so Ω → ν). Parameters (give
numbers with a decimal point): stator (default z3), target_spin (rad/s), current (A). Exits when
the simulator reports "done:" on gyro/status.

    python3 examples/spinup_controller.py --ros-args -p target_spin:=1500.0 -p current:=2.0
"""
import rclpy
from geometry_msgs.msg import Vector3Stamped
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String


class SpinupController(Node):
    def __init__(self):
        super().__init__("spinup_controller")
        self.stator = self.declare_parameter("stator", "z3").value
        self.target_spin = self.declare_parameter("target_spin", 3141.592653589793).value
        self.current = self.declare_parameter("current", 1.0).value
        self.done = False
        # QoS of the contract: reliable, keep last 100, volatile (rclpy's default with depth 100)
        self.pub = self.create_publisher(JointState, "gyro/stator_commands", 100)
        self.create_subscription(Vector3Stamped, "gyro/kinetic_moment", self.on_state, 100)
        latched = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(String, "gyro/status", self.on_status, latched)

    def on_state(self, msg):
        cmd = JointState()
        cmd.header.stamp = msg.header.stamp  # the stamp of the state answered: lockstep waits for it
        cmd.name, cmd.effort, cmd.velocity = [self.stator], [self.current], [self.target_spin]
        self.pub.publish(cmd)

    def on_status(self, msg):
        self.done = self.done or msg.data.startswith("done:")


def main():
    rclpy.init()
    node = SpinupController()
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
