"""ROS 2 controller node: runs a law of :mod:`gyro_ctl.laws` on the simulator's published state.

Subscribes ``/gyro/imu`` (attitude, body rates) and ``/gyro/kinetic_moment`` (L, case frame); for each
stamp at which both have arrived it evaluates the law and publishes ``/gyro/stator_commands`` with that
stamp (lockstep simulators wait for exactly that stamp). The law and its parameters come from the
scene's ``controller`` section and can be overridden by ROS parameters (also at run time with
``ros2 param set``); a value that does not validate is refused with the reason.
"""
from __future__ import annotations

import sys
import threading

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from pydantic import ValidationError

from gyro_sim.messages import (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATOR_COMMANDS, TOPICS, command_message,
                               node_topic, to_ros)
from gyro_sim.ros.common import message_class, msg_time, node_main, qos_profile
from gyro_sim.scene import SceneError, load_scene
from gyro_sim.simulate import stator_triad

from ..config import ControllerConfig
from ..laws import ControlInput, make_law

#: law parameters exposed as ROS parameters: name → (type default, description)
LAW_PARAMS = {
    "stator": ("", "spinup: the spin-up stator"),
    "target_spin": (float("nan"), "spinup: target spin = field rate, rad/s"),
    "current": (float("nan"), "spinup: current amplitude, A"),
    "ramp": (0.0, "spinup: current ramp, A/s (0 = none)"),
    "control_stators": ([""], "psi_switching: control stator names"),
    "spin_stator": ("", "psi_switching: the spin stator"),
    "nu": (float("nan"), "psi_switching: control field rate(s), rad/s: one value or one per control stator "
                         "(> 0: θ → 0, < 0: θ → π)"),
    "control_current": (float("nan"), "psi_switching: control current, A"),
    "spin_current": (float("nan"), "psi_switching: spin stator current, A"),
    "spin_rate": (float("nan"), "psi_switching: spin stator field rate ν0, rad/s"),
    "dead_band": (float("nan"), "psi_switching: θ below which the control currents are off, rad"),
}


def _unset(v) -> bool:
    return v is None or v == "" or v == [""] or (isinstance(v, float) and v != v)


class ControllerNode(Node):
    def __init__(self):
        super().__init__("gyro_controller")
        self.declare_parameter("scene", "spinup_thin_shell", ParameterDescriptor(
            description="scene file path or built-in name (stator axes, default law and parameters)"))
        self.declare_parameter("law", "", ParameterDescriptor(
            description="'' (the scene's), spinup, psi_switching, off, hold (manual: from the scene only)"))
        for name, (default, desc) in LAW_PARAMS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=desc,
                                                                      dynamic_typing=(name == "nu")))
        try:
            self.scene = load_scene(self.get_parameter("scene").value)
        except SceneError as e:
            raise SceneError(f"parameter scene: {e}") from None
        cfg, err = self._config({})
        if err:
            raise SceneError(err)
        self.cfg = cfg
        self.law = make_law(cfg)
        st = self.scene.stators
        self.names = tuple(s.name for s in st)
        self.axes = np.array([stator_triad(s.axis)[2] for s in st]).reshape(-1, 3)
        self.add_on_set_parameters_callback(self._on_set)
        self.pending: dict[int, dict] = {}
        self.pub = self.create_publisher(message_class(TOPICS[TOPIC_STATOR_COMMANDS]), node_topic(TOPIC_STATOR_COMMANDS),
                                         qos_profile(TOPIC_STATOR_COMMANDS))
        self.create_subscription(message_class(TOPICS[TOPIC_IMU]), node_topic(TOPIC_IMU), lambda m: self._on(m, "imu"),
                                 qos_profile(TOPIC_IMU))
        self.create_subscription(message_class(TOPICS[TOPIC_KINETIC_MOMENT]), node_topic(TOPIC_KINETIC_MOMENT),
                                 lambda m: self._on(m, "L"), qos_profile(TOPIC_KINETIC_MOMENT))
        self.get_logger().info(f"controller: law {cfg.law} with {cfg.params.model_dump(exclude={'law'})}"
                               + _expected_time_constant(self.scene, cfg))

    # --- parameters --------------------------------------------------------------------------
    def _config(self, changed: dict) -> tuple:
        """ControllerConfig from the scene's section overridden by set ROS parameters (+ ``changed``)."""
        value = lambda n: changed[n] if n in changed else self.get_parameter(n).value  # noqa: E731
        base = self.scene.controller
        law = value("law") or (base.law if base else "")
        if not law:
            return None, ("no control law: the scene has no controller section and parameter law is empty; "
                          "allowed: spinup, psi_switching, off, hold")
        params = base.params.model_dump(exclude={"law"}) if base is not None and base.law == law else {}
        for n in LAW_PARAMS:
            v = value(n)
            if not _unset(v) and n in _fields(law):
                if n == "ramp" and v == 0.0:
                    v = None
                elif n in ("control_stators", "nu") and not isinstance(v, (str, float, int)):
                    v = list(v)
                params[n] = v
        try:
            extra = {k: getattr(base, k) for k in ("current_limit", "rate_limit")} if base is not None else {}
            return ControllerConfig(law=law, params=params, **extra), ""
        except ValidationError as e:
            errs = "; ".join(f"{'.'.join(str(x) for x in er['loc'][1:]) or 'params'}: {er['msg']}"
                             for er in e.errors())
            return None, f"law {law!r}: {errs}"

    def _on_set(self, params) -> SetParametersResult:
        changed = {p.name: p.value for p in params}
        if "scene" in changed:
            return SetParametersResult(successful=False, reason="scene: set at start-up only")
        cfg, err = self._config(changed)
        if err:
            return SetParametersResult(successful=False, reason=err)
        self.cfg, self.law = cfg, make_law(cfg)
        self.get_logger().info(f"controller: now law {cfg.law} with {cfg.params.model_dump(exclude={'law'})}")
        return SetParametersResult(successful=True)

    # --- state in, command out ---------------------------------------------------------------
    def _on(self, msg, kind: str) -> None:
        key = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        entry = self.pending.setdefault(key, {})
        entry[kind] = msg
        if len(entry) < 2:
            if len(self.pending) > 1000:  # never grow without bound on a lost message
                for k in sorted(self.pending)[:500]:
                    del self.pending[k]
            return
        del self.pending[key]
        imu, Lm = entry["imu"], entry["L"]
        o, w = imu.orientation, imu.angular_velocity
        x = ControlInput(t=msg_time(imu.header), L=np.array([Lm.vector.x, Lm.vector.y, Lm.vector.z]),
                         q=np.array([o.w, o.x, o.y, o.z]), omega_b=np.array([w.x, w.y, w.z]),
                         stator_names=self.names, stator_axes=self.axes)
        cmds = self.law(x)
        names = list(cmds)  # empty (law 'hold'): an empty command, which changes nothing
        rates = [cmds[n][1] for n in names]
        fields = command_message(0.0, names, [float(cmds[n][0]) for n in names],
                                 None if all(r is None for r in rates) else [float(r) for r in rates])
        out = to_ros(message_class(TOPICS[TOPIC_STATOR_COMMANDS]), fields)
        out.header.stamp = imu.header.stamp
        self.pub.publish(out)


def _expected_time_constant(scene, cfg) -> str:
    """For spin-up: ', expected time constant T s' ([K] (2.1) at θ = 0: J3/(k_e B0²)), else ''."""
    if cfg.law != "spinup" or scene.rotor.conductor is None or scene.torque_model == "none":
        return ""
    from gyro_sim.conductor import conductor_model

    from ..laws import spinup_time_constant

    c = scene.rotor.conductor
    k_e = conductor_model(c.kind, c.outer_radius, c.conductivity, thickness=c.thickness, n_modes=scene.modes).k_e
    st = scene.stators[scene.stator_index(cfg.params.stator)]
    return f", expected time constant {spinup_time_constant(scene.inertia[2], k_e, st.coil_constant, cfg.params.current):.4g} s"


def _fields(law: str) -> set:
    from ..config import PsiSwitchingParams, SpinupParams

    model = {"spinup": SpinupParams, "psi_switching": PsiSwitchingParams}.get(law)  # others: from the scene only
    return set(model.model_fields) - {"law"} if model else set()


def _spin(node: ControllerNode, stop: threading.Event) -> int:
    while not stop.is_set() and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)
    return 0


def main(args=None) -> int:
    """Entry point (`ros2 run gyro_ctl controller`, console script `gyro-ctl-controller`)."""
    return node_main("controller", ControllerNode, _spin, args)


if __name__ == "__main__":
    sys.exit(main())
