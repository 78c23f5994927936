"""ROS 2 controller node: runs a law of :mod:`gyro_ctl.laws` on the simulator's published state.

Subscribes ``/gyro/imu`` (attitude, body rates) and, while its law reads it, ``/gyro/kinetic_moment`` (L, case
frame: ψ-switching and the Python laws; :func:`gyro_ctl.laws.reads_L`); for each stamp at which those have arrived
it evaluates the law and publishes ``/gyro/stator_commands`` with that stamp (lockstep simulators wait for exactly
that stamp). A law that does not read L leaves the topic unsubscribed, and the simulator then does not publish
it: one message fewer a tick (a switch to a law that reads it subscribes again; its first answer waits for the
simulator to see the subscription, at most about half a second in lockstep). The law and its parameters come from the
scene's ``controller`` section and can be overridden by ROS parameters (also at run time with
``ros2 param set``); a value that does not validate, a stator the scene does not have, or a parameter
of a law not in force is refused with the reason. The parameters always show what is in force.

The node ends after the simulator's final status (``done:`` on ``gyro/status``, once it has answered a state of
that run) with exit status 0, unless ``keep_alive`` is true; SIGINT or SIGTERM ends it cleanly (its last commands
flushed) with exit status 130 or 143 (:func:`gyro_sim.ros.common.node_main`); 2: a refused scene or parameter (one
``controller: error:`` line).
"""
from __future__ import annotations

import array
import math
import sys
import threading
from typing import Optional

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from pydantic import ValidationError

from gyro_sim.io.messages import (TOPIC_IMU, TOPIC_KINETIC_MOMENT, TOPIC_STATOR_COMMANDS, TOPIC_STATUS, TOPICS,
                                  node_topic)
from gyro_sim.ros.common import message_class, node_main, qos_profile, take
from gyro_sim.ros.wire import STAMP_PATHS, Template, Wire, state_templates, take_serialized
from gyro_sim.scenes.scene import SceneError, load_scene
from gyro_sim.engine.simulate import stator_triad

from ..config import LAW_NAMES, ControllerConfig, PsiSwitchingParams, SpinupParams, unknown_stators
from .. import law_kernels
from ..laws import ControlInput, make_law, reads_L

#: the laws whose parameters are ROS parameters (the others take theirs from the scene's controller section)
ROS_LAWS = {"spinup": SpinupParams, "psi_switching": PsiSwitchingParams}

#: law parameters exposed as ROS parameters: name → (law, kind, description)
LAW_PARAMS = {
    "stator": ("spinup", "str", "the stator driven, a stator of the scene"),
    "target_spin": ("spinup", "float", "target spin = field rate, rad/s"),
    "current": ("spinup", "float", "current amplitude, A"),
    "ramp": ("spinup", "float", "current ramp, A/s (0 = none: the full current at once)"),
    "control_stators": ("psi_switching", "str[]", "the control stators, stators of the scene"),
    "spin_stator": ("psi_switching", "str", "the spin stator, a stator of the scene"),
    "nu": ("psi_switching", "float|float[]", "control field rate(s) ν, rad/s: one value or one per control stator "
                                             "(> 0: θ → 0, < 0: θ → π)"),
    "control_current": ("psi_switching", "float", "control current, A"),
    "spin_current": ("psi_switching", "float", "spin stator current, A"),
    "spin_rate": ("psi_switching", "float", "spin stator field rate ν0, rad/s"),
    "dead_band": ("psi_switching", "float", "θ (and π − θ) below which the control currents are off, rad"),
}
_UNSET = {"str": "", "str[]": [""], "float": math.nan, "float|float[]": math.nan}
_EXPECTED = {"str": "a string", "str[]": "a list of strings", "float": "a number",
             "float|float[]": "a number or a list of numbers"}
for _law, _model in ROS_LAWS.items():  # one list of each law's parameters: the model's
    assert [n for n, v in LAW_PARAMS.items() if v[0] == _law] == [n for n in _model.model_fields if n != "law"]


def law_fields(law: str) -> list:
    """The ROS parameters of ``law``, in the order of its model ([] for laws without ROS parameters)."""
    model = ROS_LAWS.get(law)
    return [n for n in model.model_fields if n != "law"] if model else []


def _is_unset(v) -> bool:
    """The value a parameter shows while its law is not in force (NaN, '', ['']; at start-up: not given)."""
    if isinstance(v, str):
        return v == ""
    if isinstance(v, float):
        return math.isnan(v)
    if isinstance(v, (list, tuple)):
        return list(v) == [""]
    return v is None


def _from_ros(name: str, v) -> tuple:
    """(value for the law model, '') or (None, reason) of a ROS parameter value (integers taken as numbers)."""
    kind = LAW_PARAMS[name][1]
    num = lambda x: isinstance(x, (int, float)) and not isinstance(x, bool)  # noqa: E731
    seq = isinstance(v, (list, tuple, array.array))
    if kind == "float" and num(v):
        return (None if name == "ramp" and v == 0 else float(v)), ""
    if kind == "float|float[]" and num(v):
        return float(v), ""
    if kind == "float|float[]" and seq and len(v) > 0 and all(num(x) for x in v):
        return [float(x) for x in v], ""
    if kind == "str" and isinstance(v, str):
        return v, ""
    if kind == "str[]" and seq and all(isinstance(x, str) for x in v):
        return list(v), ""
    return None, f"{name} = {v!r}: expected {_EXPECTED[kind]}"


def _to_ros(name: str, cfg: ControllerConfig) -> Parameter:
    """The ROS parameter showing ``name`` under ``cfg``: its value in force (ramp None: 0), or its unset value if
    its law is not in force."""
    kind = LAW_PARAMS[name][1]
    if name not in law_fields(cfg.law):
        v = _UNSET[kind]
    else:
        v = getattr(cfg.params, name)
        v = 0.0 if v is None else v  # (ramp: none)
    if kind == "str":
        return Parameter(name, Parameter.Type.STRING, str(v))
    if kind == "str[]":
        return Parameter(name, Parameter.Type.STRING_ARRAY, [str(x) for x in v])
    if isinstance(v, (list, tuple)):
        return Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(x) for x in v])
    return Parameter(name, Parameter.Type.DOUBLE, float(v))


def resolve(scene, current: ControllerConfig | None, law: str | None, given: dict) -> tuple:
    """(ControllerConfig, '') or (None, reason): the config in force after setting ``given`` (ROS parameter name →
    ROS value) and ``law`` (None: the one in force; '': the scene's).

    The law's parameters not given come from the config in force if the law is unchanged, else from the scene's
    controller section if it has that law, else from the law model's defaults. A parameter of another law is
    refused unless it is given its unset value (NaN, '', ['']: what it shows; nothing changes). Every stator
    named must be one of the scene's (:func:`gyro_ctl.config.unknown_stators`).
    """
    base_cfg = scene.controller
    if law is None:
        law = current.law
    if law == "":
        if base_cfg is None:
            return None, ("no control law: the scene has no controller section and parameter law is empty; "
                          "allowed: spinup, psi_switching, off, hold")
        law = base_cfg.law
    if law not in LAW_NAMES:
        return None, (f"law = {law!r}: allowed: spinup, psi_switching, off, hold, or the scene's law "
                      f"({base_cfg.law if base_cfg else 'none'}; manual, reorient: the scene's only)")
    fields = law_fields(law)
    params: dict = {}
    if current is not None and current.law == law:
        params = current.params.model_dump(exclude={"law"})
    elif base_cfg is not None and base_cfg.law == law:
        params = base_cfg.params.model_dump(exclude={"law"})
    elif law not in ROS_LAWS and law not in ("off", "hold"):
        return None, (f"law {law!r}: its parameters come from the scene's controller section only, and the scene's "
                      f"law is {base_cfg.law if base_cfg else 'none'!r}")
    for n, v in given.items():
        if n not in fields:
            if _is_unset(v):
                continue
            its = (f"its parameters: {', '.join(fields)}" if fields else
                   "it has none" if law in ("off", "hold") else "its parameters come from the scene only")
            return None, f"{n}: not a parameter of law {law!r} ({its})"
        value, err = _from_ros(n, v)
        if err:
            return None, f"law {law!r}: {err}"
        params[n] = value
    limits = {k: getattr(base_cfg, k) for k in ("current_limit", "rate_limit")} if base_cfg is not None else {}
    try:
        cfg = ControllerConfig(law=law, params=params, **limits)
    except ValidationError as e:
        missing = [str(er["loc"][-1]) for er in e.errors() if er["type"] == "missing"]
        errs = [": ".join(x for x in (".".join(str(k) for k in er["loc"][2:]), er["msg"].removeprefix("Value error, "))
                          if x) for er in e.errors() if er["type"] != "missing"]
        if missing:
            errs.append(f"{', '.join(missing)} not set (the scene's controller has "
                        f"{'law ' + repr(base_cfg.law) if base_cfg else 'no section'}: give "
                        f"{'them' if len(missing) > 1 else 'it'} together with law in one atomic set)")
        return None, f"law {law!r}: {'; '.join(errs)}"
    err = unknown_stators(cfg, [s.name for s in scene.stators])
    if err:
        return None, f"law {law!r}: {err}"
    return cfg, ""


def _describe(name: str) -> ParameterDescriptor:
    law, kind, desc = LAW_PARAMS[name]
    unset = {"str": "''", "str[]": "['']"}.get(kind, "NaN")
    field = ROS_LAWS[law].model_fields[name]
    if not field.is_required() and field.default is not None:
        desc += f" (default {field.default})"
    return ParameterDescriptor(
        description=(f"{law}: {desc}. Shows the value in force while law is {law}; while the law in force is "
                     f"another (the parameter is not in force) it shows {unset}, and setting it is refused unless "
                     f"set together with law = {law} in one atomic set"),
        dynamic_typing=kind.startswith("float"))  # numbers: integers are taken too (shown as the floats in force)


class ControllerNode(Node):
    def __init__(self):
        super().__init__("gyro_controller")
        self.declare_parameter("scene", "spinup_thin_shell", ParameterDescriptor(
            description="scene file path or built-in name (stator axes, default law and parameters); start-up only",
            read_only=True))
        self.declare_parameter("law", "", ParameterDescriptor(
            description="the law in force: spinup, psi_switching, off, hold, or the scene's law (manual, reorient: "
                        "the scene's only, with the scene's parameters); at start-up '' = the scene's law. A switch "
                        "takes the new law's parameters from the same atomic set, else from the scene's controller "
                        "section if it has that law, else the law's defaults; refused if they are incomplete",
            additional_constraints="one of: spinup, psi_switching, off, hold, manual, reorient"))
        for name, (_, kind, _) in LAW_PARAMS.items():
            self.declare_parameter(name, _UNSET[kind], _describe(name))
        self.declare_parameter("keep_alive", False, ParameterDescriptor(
            description="stay running after the simulator's final status (done: on gyro/status); false: exit 0 "
                        "then, once this node has answered a state of that run", read_only=True))
        try:
            self.scene = load_scene(self.get_parameter("scene").value)
        except SceneError as e:
            raise SceneError(f"parameter scene: {e}") from None
        given = {n: self.get_parameter(n).value for n in LAW_PARAMS}
        cfg, err = resolve(self.scene, None, self.get_parameter("law").value,
                           {n: v for n, v in given.items() if not _is_unset(v)})
        if err:
            raise SceneError(err)
        self.cfg, self.law = cfg, make_law(cfg)
        law_kernels.warm()  # the compiled laws' kernel is loaded now, not at the first tick
        self._next = None  # the config an accepted set puts in force
        self._showing = False  # set while the parameters are being updated to the values in force
        self._show(cfg)
        st = self.scene.stators
        self.names = tuple(s.name for s in st)
        self.axes = np.array([stator_triad(s.axis)[2] for s in st]).reshape(-1, 3)
        self.pending: dict[int, dict] = {}  # stamp (ns) → {kind: numbers} of the states not yet answered
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._after_set)
        self._command_class = message_class(TOPICS[TOPIC_STATOR_COMMANDS])
        self.pub = self.create_publisher(message_class(TOPICS[TOPIC_STATOR_COMMANDS]), node_topic(TOPIC_STATOR_COMMANDS),
                                         qos_profile(TOPIC_STATOR_COMMANDS))
        self.subs: dict = {}  # kind ('imu', 'L') → subscription, of the kinds the law reads (:meth:`subscribe`)
        self.kinds: tuple = ()
        self.resubscribe = False  # set when a law switch changes the kinds read: the loop calls subscribe()
        self.subscribe()
        self.answered = 0  # commands published (a done: line before the first is an earlier run's: ignored)
        self.half = False  # the last state message taken waits for another of its stamp
        self.last_kind: Optional[str] = None  # the kind whose message completed the last stamp
        self.finished = False  # the simulator's run is done (and keep_alive is false): the loop ends
        self.status_sub = self.create_subscription(message_class(TOPICS[TOPIC_STATUS]), node_topic(TOPIC_STATUS),
                                                   self._on_status, qos_profile(TOPIC_STATUS))
        # states taken and commands published as CDR bytes where rosbags' and rclpy's serializations agree
        # (gyro_sim.ros.wire: rclpy's Python message objects cost more than the law)
        self.wire = Wire({t: message_class(TOPICS[t]) for t in (TOPIC_IMU, TOPIC_KINETIC_MOMENT)}
                         | {TOPIC_STATOR_COMMANDS: self._command_class})
        self.serialized = {kind: self.wire.serialized(t) for kind, t in _TOPIC.items()}
        self.wire.serialized(TOPIC_STATOR_COMMANDS)  # (checked now, not at the first command)
        # the simulator's state messages read at fixed places (gyro_sim.ros.wire.Template; others decoded whole)
        by_topic = state_templates(self.wire)
        self.templates = {k: by_topic[t] for k, t in _TOPIC.items() if t in by_topic}
        self._command_templates: dict = {}  # (names, with rates) -> Template of the command
        self._fixed: Optional[tuple] = None  # (law, names, currents, rates) of a law whose commands never change
        self.get_logger().info(f"controller: law {cfg.law} with {cfg.params.model_dump(exclude={'law'})}"
                               + _expected_time_constant(self.scene, cfg))

    # --- parameters --------------------------------------------------------------------------
    def _on_set(self, params) -> SetParametersResult:
        """Validate a set (all its parameters at once); the config it puts in force is kept for _after_set."""
        if self._showing:  # our own update to the values in force
            return SetParametersResult(successful=True)
        changed = {p.name: p.value for p in params}
        if "scene" in changed:  # (read-only: rclpy refuses it before this callback)
            return SetParametersResult(successful=False, reason="scene: set at start-up only")
        cfg, err = resolve(self.scene, self.cfg, changed.pop("law", None), changed)
        if err:
            return SetParametersResult(successful=False, reason=err)
        self._next = cfg
        return SetParametersResult(successful=True)

    def _after_set(self, params) -> None:
        """Put the accepted config in force and show it (our own update comes back here: ignored)."""
        if self._showing or self._next is None:
            return
        cfg, self._next = self._next, None
        if cfg != self.cfg:
            self.cfg, self.law = cfg, make_law(cfg)
            self.resubscribe = self.kinds != self.law_kinds()
            self.get_logger().info(f"controller: now law {cfg.law} with {cfg.params.model_dump(exclude={'law'})}")
        self._show(cfg)

    # --- the state subscriptions -------------------------------------------------------------
    def law_kinds(self) -> tuple:
        """The state messages the law in force needs at each stamp: ('imu', 'L') where it reads the kinetic moment
        (:func:`gyro_ctl.laws.reads_L`), else ('imu',) (the stamp, the attitude and the body rates)."""
        return ("imu", "L") if reads_L(self.law) else ("imu",)

    def subscribe(self) -> None:
        """Subscribe to the state topics the law in force needs and to no other (:meth:`law_kinds`): the simulator
        publishes a per-sample topic only to subscribers. Called at start-up and by the loop after a law switch
        that changes them (with no wait on the subscriptions in progress)."""
        self.resubscribe = False
        self.kinds = self.law_kinds()
        for kind, topic in _TOPIC.items():
            if kind in self.kinds and kind not in self.subs:
                self.subs[kind] = self.create_subscription(
                    message_class(TOPICS[topic]), node_topic(topic),
                    lambda m, kind=kind: self._on(state_numbers(m, kind), kind), qos_profile(topic))
            elif kind not in self.kinds and kind in self.subs:
                self.destroy_subscription(self.subs.pop(kind))
        self.half = False
        self.last_kind = None
        self.answer_pending()

    def answer_pending(self) -> None:
        """Answer the latest pending stamp that has every kind now needed (after a switch to a law that needs fewer:
        a lockstep simulator waits for it), dropping the older ones."""
        done = [k for k, e in self.pending.items() if all(kind in e for kind in self.kinds)]
        if done:
            key = max(done)
            entry = self.pending[key]
            for k in [k for k in self.pending if k <= key]:
                del self.pending[k]
            self._answer(key, entry)

    def _show(self, cfg: ControllerConfig) -> None:
        """Set law and the law parameters to what is in force (the other laws' parameters to their unset value)."""
        want = [Parameter("law", Parameter.Type.STRING, cfg.law)] + [_to_ros(n, cfg) for n in LAW_PARAMS]
        update = [p for p in want if not _same(self.get_parameter(p.name), p)]
        if not update:
            return
        self._showing = True
        try:
            r = self.set_parameters_atomically(update)
            if not r.successful:
                self.get_logger().error(f"controller: could not show the parameters in force: {r.reason}")
        finally:
            self._showing = False

    # --- state in, command out ---------------------------------------------------------------
    def _on_status(self, msg) -> None:
        """The simulator's final ``done:`` line ends this node (not with ``keep_alive``; not a line of a run it did
        not answer: gyro/status is latched, a late joiner gets the last lines of an earlier run)."""
        if msg.data.startswith("done:") and self.answered and not self.get_parameter("keep_alive").value:
            self.finished = True

    def take(self, kind: str):
        """The numbers (:func:`state_numbers`) of the next state message of subscription ``kind`` ('imu', 'L'), past
        the executor, or None: read from its CDR bytes where :attr:`wire` allows (at the places of
        :attr:`templates`, or decoded whole), else from rclpy's message."""
        sub = self.subs[kind]
        if not self.serialized[kind]:
            msg = take(sub)
            return None if msg is None else state_numbers(msg, kind)
        raw = take_serialized(sub)
        if raw is None:
            return None
        tmpl = self.templates.get(kind)
        numbers = tmpl.decode(raw) if tmpl is not None else None
        return numbers if numbers is not None else state_numbers(self.wire.decode(_TOPIC[kind], raw), kind)

    def _on(self, numbers: list, kind: str) -> None:
        """One state message's numbers (:func:`state_numbers`); with every kind the law needs of a stamp
        (:attr:`kinds`), the law's command for it."""
        key = numbers[0] * 1_000_000_000 + numbers[1]
        entry = self.pending.setdefault(key, {})
        entry[kind] = numbers
        self.half = not all(k in entry for k in self.kinds)
        if self.half:
            if len(self.pending) > 1000:  # never grow without bound on a lost message
                for k in sorted(self.pending)[:500]:
                    del self.pending[k]
            return
        del self.pending[key]
        self.last_kind = kind
        self._answer(key, entry)

    def _answer(self, key: int, entry: dict) -> None:
        """Publish the law's command for the state of stamp ``key`` (ns) from its messages' numbers ``entry``
        ({kind: :func:`state_numbers`}; without 'L' the law does not read it: zeros stand in)."""
        imu = entry["imu"]
        law, fixed = self.law, self._fixed
        if fixed is None or fixed[0] is not law:
            Lm = entry.get("L", _NO_L)
            x = ControlInput(t=key * 1e-9, L=np.array(Lm[2:5]), q=np.array([imu[5], imu[2], imu[3], imu[4]]),
                             omega_b=np.array(imu[6:9]), stator_names=self.names, stator_axes=self.axes)
            cmds = law(x)
            # the command (gyro_sim.io.messages.command_message's content, with the state's own stamp)
            names = list(cmds)  # empty (law 'hold'): an empty command, which changes nothing
            rates = [cmds[n][1] for n in names]
            effort = [float(cmds[n][0]) for n in names]
            velocity = [float(r) for r in rates] if any(r is not None for r in rates) else []
            # a law that reads neither the state nor the time gives these at every stamp (as the compiled tick loop
            # evaluates it once): kept for the next states until the law changes
            fixed = (law, names, effort, velocity) if getattr(law, "reads_state", True) is False else None
            self._fixed = fixed
        else:
            names, effort, velocity = fixed[1:]
        self.pub.publish(self._command(int(imu[0]), int(imu[1]), names, effort, velocity))
        self.answered += 1

    def _command(self, sec: int, nanosec: int, names: list, effort: list, velocity: list):
        """The command to publish (CDR bytes where :attr:`wire` allows, by a template per set of names)."""
        fields = {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""}, "name": names,
                  "position": [], "effort": effort, "velocity": velocity}
        key = (tuple(names), bool(velocity))
        tmpl = self._command_templates.get(key)
        if tmpl is None and len(self._command_templates) < 16 and self.wire.serialized(TOPIC_STATOR_COMMANDS):
            tmpl = self._command_templates[key] = Template(
                TOPIC_STATOR_COMMANDS, fields, STAMP_PATHS + tuple(("effort", i) for i in range(len(names)))
                + tuple(("velocity", i) for i in range(len(velocity))))
        if tmpl is not None:
            return tmpl.encode(sec, nanosec, *effort, *velocity)
        return self.wire.encode(TOPIC_STATOR_COMMANDS, fields)


#: the state subscriptions' kinds and topics
_TOPIC = {"imu": TOPIC_IMU, "L": TOPIC_KINETIC_MOMENT}

#: the numbers of a kinetic moment a law that does not read it gets (:func:`state_numbers`' order: no stamp, L = 0)
_NO_L = [0, 0, 0.0, 0.0, 0.0]


def state_numbers(msg, kind: str) -> list:
    """The numbers the law reads from a state message (rclpy's or rosbags'), in the order of the simulator's
    templates (:func:`gyro_sim.ros.wire.state_templates`): stamp sec, nanosec, then for 'imu' the orientation
    x y z w and the angular velocity x y z, for 'L' the vector x y z."""
    st = msg.header.stamp
    if kind == "imu":
        o, w = msg.orientation, msg.angular_velocity
        return [st.sec, st.nanosec, o.x, o.y, o.z, o.w, w.x, w.y, w.z]
    v = msg.vector
    return [st.sec, st.nanosec, v.x, v.y, v.z]


def _expected_time_constant(scene, cfg) -> str:
    """For spin-up: ', expected time constant T s' ([K] (2.1) at θ = 0: J3/(k_e B0²)), else ''."""
    if cfg.law != "spinup" or scene.rotor.conductor is None or scene.torque_model == "none":
        return ""
    from gyro_sim.physics.conductor import conductor_model

    from ..laws import spinup_time_constant

    c = scene.rotor.conductor
    k_e = conductor_model(c.kind, c.outer_radius, c.conductivity, thickness=c.thickness).k_e  # (any N)
    st = scene.stators[scene.stator_index(cfg.params.stator)]
    return f", expected time constant {spinup_time_constant(scene.inertia[2], k_e, st.coil_constant, cfg.params.current):.4g} s"


def _same(a: Parameter, b: Parameter) -> bool:
    """Same type and value (NaN equal to NaN)."""
    if a.type_ != b.type_:
        return False
    va, vb = a.value, b.value
    if isinstance(va, (list, tuple, array.array)):
        va, vb = list(va), list(vb)
        return len(va) == len(vb) and all(x == y or (x != x and y != y) for x, y in zip(va, vb))
    return va == vb or (va != va and vb != vb)


#: wall s between executor turns (parameters, services, gyro/status) while states come: an executor turn costs
#: ~1.5 ms of CPU here in a lockstep run (it builds a wait set over every entity of the node), ~25 µs a tick at
#: 0.05 s, ~8 at 0.2 s; a parameter set or the simulator's done: line is seen within this (and a signal)
PUMP_PERIOD = 0.2


def _spin(node: ControllerNode, stop: threading.Event) -> int:
    """The states are taken as they come, and between them the node blocks in a wait on its state
    subscriptions (:class:`gyro_sim.ros.common.MessageWait`: no busy poll, the core stays free for the simulator);
    parameters, services and gyro/status go through the executor every :data:`PUMP_PERIOD` s. Ends on a signal, or
    after the simulator's final ``done:`` status (unless ``keep_alive``)."""
    import time

    from gyro_sim.ros.common import MessageWait, exit_status, make_executor

    executor = make_executor()
    executor.add_node(node)
    kinds = list(node.subs)
    waiter = MessageWait(node, [node.subs[k] for k in kinds], period=PUMP_PERIOD)
    ready = [True] * len(kinds)  # the subscriptions to take from: at first all, then those the wait says have one
    next_pump = 0.0
    try:
        while not stop.is_set() and rclpy.ok() and not node.finished:
            if node.resubscribe:  # a law switch changed the state it reads (no wait on the subscriptions now)
                waiter.close()
                node.subscribe()
                kinds = list(node.subs)
                waiter = MessageWait(node, [node.subs[k] for k in kinds], period=PUMP_PERIOD)
                ready = [True] * len(kinds)
            # one message of each subscription (a second one queued behind it makes the next wait return at once),
            # none where the wait woke without a message (a take that finds none costs ~10 µs: one a tick before)
            for kind, r in zip(kinds, ready, strict=True):
                if r:
                    msg = node.take(kind)
                    if msg is not None:
                        node._on(msg, kind)
            now = time.perf_counter()
            if now >= next_pump:
                executor.spin_once(timeout_sec=0.0)
                next_pump = time.perf_counter() + PUMP_PERIOD
            # woken once a state: by the kind that completed the last one (the simulator publishes a state's two
            # messages back to back: the first is there when the last comes), by either while half of one is in
            # (woken at least every PUMP_PERIOD)
            woke = waiter.wait(None if node.half or node.last_kind is None else [kinds.index(node.last_kind)])
            # woken by the kind that completes a state: the state's other messages came before it (back to back)
            ready = [True] * len(kinds) if any(woke) else woke
    finally:
        waiter.close()
        executor.shutdown()
    if node.finished:
        node.get_logger().info("controller: the simulator's run is done; exiting (keep_alive:=true keeps it running)")
    return exit_status(stop)  # 0: done (or the context was shut down); 130 / 143: stopped by SIGINT / SIGTERM


def usage() -> str:
    """``--help`` text: the parameters with their unset defaults (the scene's controller section fills them)."""
    from gyro_sim.ros.common import node_usage

    base = (("scene", "spinup_thin_shell", "scene file path or built-in name (read-only)"),
            ("law", "", "'' (the scene's), " + ", ".join(sorted(ROS_LAWS)) + ", off, hold"),
            ("keep_alive", False, "stay running after the simulator's final done: status (read-only)"))
    return node_usage("ros2 run gyro_ctl controller",
                      base + tuple((n, _UNSET[k], f"{law}: {d}") for n, (law, k, d) in LAW_PARAMS.items()))


def main(args=None) -> int:
    """Entry point (`ros2 run gyro_ctl controller`, console script `gyro-ctl-controller`)."""
    return node_main("controller", ControllerNode, _spin, args, usage=usage())


if __name__ == "__main__":
    sys.exit(main())
