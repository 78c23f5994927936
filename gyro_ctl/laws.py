"""Control laws as pure functions of the rotor state (no ROS, no simulator objects).

A law takes a :class:`ControlInput` (what the simulator publishes: time, L in the case frame,
attitude, body angular velocity, the stators' names and axes) and its parameters, and returns
stator commands ``{name: (current A, signed field rate rad/s)}``. The same function runs inside
the core (``gyro_sim.run``) and in the controller node (``gyro_ctl.ros.controller``).

The built-in laws spinup, psi_switching, off, hold and manual, and the limits, are written once, compiled
(:mod:`gyro_ctl.law_kernels`): the functions here and :class:`CompiledLaw` call that code, and in-process runs call
it from their compiled tick loop (:mod:`gyro_sim.ticks`). Other laws (reorient, or a Python function put in
:data:`LAWS`) run as Python at each tick.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from . import law_kernels as lk
from .reorient import reorient
from .config import ControllerConfig, HoldParams, ManualParams, OffParams, PsiSwitchingParams, SpinupParams

Commands = dict  # {stator name: (current A, field rate rad/s)}


@dataclass(frozen=True)
class ControlInput:
    """State seen by a law. L (N·m·s) case frame; q = (w, x, y, z) body → case; omega_b rad/s body frame."""

    t: float
    L: np.ndarray
    q: np.ndarray
    omega_b: np.ndarray
    stator_names: tuple
    stator_axes: np.ndarray  # (k, 3) unit axes u_k in the case frame

    @property
    def polar_axis(self) -> np.ndarray:
        """x3, the body's polar axis, in the case frame."""
        w, x, y, z = self.q
        return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])

    @property
    def theta(self) -> float:
        """Nutation angle θ (rad) between x3 and L (0 where L = 0)."""
        n = float(np.linalg.norm(self.L))
        if n == 0.0:
            return 0.0
        x3 = self.polar_axis
        return math.atan2(float(np.linalg.norm(np.cross(x3, self.L))), float(x3 @ self.L))

    def axis(self, name: str) -> np.ndarray:
        return self.stator_axes[self.stator_names.index(name)]


def spinup(x: ControlInput, p: SpinupParams) -> Commands:
    """Spin-up ([K] §1): the spin stator's field turns at the target spin rate; current ramps to its limit.

    The quasi-static torque k_e B0²(ν − Ω) ([K] (1.3)) vanishes at Ω = ν, so the target spin is the
    zero-slip asymptote; time constant J3/(k_e b² I²) (see :func:`spinup_time_constant`). Compiled:
    :func:`gyro_ctl.law_kernels.law_values`.
    """
    return CompiledLaw(p)(x)


def spinup_time_constant(J3: float, k_e: float, coil_constant: float, current: float) -> float:
    """Time constant (s) of the exponential approach to the target spin, [K] (2.1) at θ = 0: J3/(k_e B0²)."""
    return J3 / (k_e * (coil_constant * current) ** 2)


def transverse_unit(x: ControlInput) -> np.ndarray | None:
    """e⊥ = (x3 − y3 cosθ)/sinθ: x3 projected on the plane normal to L (physics.md §5); None if undefined."""
    n = float(np.linalg.norm(x.L))
    if n == 0.0:
        return None
    y3 = x.L / n
    x3 = x.polar_axis
    v = x3 - y3 * float(x3 @ y3)
    s = float(np.linalg.norm(v))
    return None if s == 0.0 else v / s


def psi_switching(x: ControlInput, p: PsiSwitchingParams) -> Commands:
    """ψ-switching nutation control, [K] (3.1) in the vector form of physics.md §5.

    Control stators n: ν_n = ν sign(u_n · e⊥) (the field direction flips when the polar axis crosses
    the stator's plane); the spin stator stays on at ν0 to make up the braking torque. ν > 0 drives
    θ → 0, ν < 0 drives θ → π. Inside the dead band (θ < dead_band or π − θ < dead_band) the
    control currents are off, so the undefined e⊥ near θ = 0, π never drives noise-led switching.
    Compiled: :func:`gyro_ctl.law_kernels.law_values`.
    """
    return CompiledLaw(p)(x)


def psi_switching_functions(x: ControlInput, p: PsiSwitchingParams) -> np.ndarray:
    """Switching functions of [K] (3.1): u_n · e⊥ for the control stators (their sign sets ν_n).

    Zero inside the dead band (no switching there). A simulator locating the zeros of these between
    control ticks switches the fields at the exact instants.
    """
    th = x.theta
    e = transverse_unit(x)
    if e is None or th < p.dead_band or math.pi - th < p.dead_band:
        return np.zeros(len(p.control_stators))
    return np.array([float(x.axis(n) @ e) for n in p.control_stators])


def off(x: ControlInput, p: OffParams) -> Commands:
    """Every stator off (0 A), rates unchanged."""
    return CompiledLaw(p)(x)


def hold(x: ControlInput, p: HoldParams) -> Commands:
    """Keep the last commands (send nothing)."""
    return CompiledLaw(p)(x)


def manual(x: ControlInput, p: ManualParams) -> Commands:
    """The fixed commands of the parameters."""
    return CompiledLaw(p)(x)


#: the laws with a compiled form (gyro_ctl.law_kernels), by name
COMPILED: Mapping[str, Callable] = {"spinup": spinup, "psi_switching": psi_switching, "off": off, "hold": hold,
                                    "manual": manual}
LAWS: Mapping[str, Callable] = {**COMPILED, "reorient": reorient}
SWITCHING: Mapping[str, Callable] = {"psi_switching": psi_switching_functions}
_NO_AXES = np.zeros((0, 3))


def _nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _optional(values: np.ndarray) -> list:
    """Array values as a list of floats, NaN as None (a command field left unchanged)."""
    return [None if v != v else v for v in values.tolist()]


def law_form(p) -> tuple[int, np.ndarray, list | None, list]:
    """The compiled form of built-in law parameters ``p``: (kind, float parameters, the stator names it commands
    in order (None: every stator of the input, law ``off``), the control stators whose axes it reads), as
    :mod:`gyro_ctl.law_kernels` describes them."""
    if isinstance(p, SpinupParams):
        return lk.SPINUP, np.array([p.current, _nan(p.ramp), p.target_spin]), [p.stator], []
    if isinstance(p, PsiSwitchingParams):
        ctl = list(p.control_stators)
        fp = [p.spin_current, p.spin_rate, p.control_current, p.dead_band] + [p.rate(i) for i in range(len(ctl))]
        return lk.PSI_SWITCHING, np.array(fp, dtype=float), [p.spin_stator] + ctl, ctl
    if isinstance(p, OffParams):
        return lk.OFF, np.zeros(0), None, []
    if isinstance(p, HoldParams):
        return lk.HOLD, np.zeros(0), [], []
    if isinstance(p, ManualParams):
        return (lk.MANUAL, np.array([v for c in p.commands.values() for v in (c.current, c.rate)], dtype=float),
                list(p.commands), [])
    raise TypeError(f"law parameters {type(p).__name__}: no compiled form")


class CompiledLaw:
    """A built-in law with its limits as one call of :func:`gyro_ctl.law_kernels.law_commands`:
    ``law(x: ControlInput) -> Commands``, as the ROS controller node and Python callers use it. The attributes
    (``kind``, ``fp``, ``current_limit``, ``rate_limit``: NaN = none; ``needs_time``, ``reads_state``, ``reads_L``:
    whether the commands depend on the time, on the time or the state, on the kinetic moment) are what a compiled
    tick loop passes to the same kernel (gyro_sim.ticks) and what the controller node subscribes to."""

    def __init__(self, params, current_limit: float | None = None, rate_limit: float | None = None):
        self.kind, self.fp, self._names, self._control = law_form(params)
        self.current_limit, self.rate_limit = _nan(current_limit), _nan(rate_limit)
        # the law reads the time only while a spin-up current ramps; the state (L, q) only for ψ-switching: the
        # commands of the others are the same at every tick
        self.needs_time = self.kind == lk.SPINUP and self.fp[1] == self.fp[1]
        self.reads_state = self.needs_time or self.kind == lk.PSI_SWITCHING
        self.reads_L = self.kind == lk.PSI_SWITCHING  # (the kinetic moment: ψ-switching's alone)

    def command_names(self, stator_names) -> list:
        """The stators the law commands, in order (of ``stator_names``, the scene's, for law ``off``)."""
        return list(stator_names) if self._names is None else list(self._names)

    def control_axes(self, stator_names, stator_axes) -> np.ndarray:
        """(n, 3) unit axes (case frame) of the control stators the law reads (ValueError for an unknown name)."""
        if not self._control:
            return _NO_AXES
        names = list(stator_names)
        return np.array([stator_axes[names.index(n)] for n in self._control], dtype=float)

    def __call__(self, x: ControlInput) -> Commands:
        names = self.command_names(x.stator_names)
        cur, rate = np.empty(len(names)), np.empty(len(names))
        lk.law_commands(self.kind, float(x.t), np.ascontiguousarray(x.L, dtype=float),
                        np.ascontiguousarray(x.q, dtype=float), self.control_axes(x.stator_names, x.stator_axes),
                        self.fp, self.current_limit, self.rate_limit, cur, rate)
        return dict(zip(names, zip(_optional(cur), _optional(rate))))


def reads_L(law: Callable[[ControlInput], Commands]) -> bool:
    """Whether ``law`` (as :func:`make_law` gives it) reads the kinetic moment ``x.L``: of the compiled laws only
    ψ-switching does (the others read the time at most); a Python law may, so it counts as reading it. A caller
    that knows it does not may pass any L (e.g. zeros): the commands are the same."""
    return getattr(law, "reads_L", True)


def limited(commands: Commands, current_limit: float | None, rate_limit: float | None) -> Commands:
    """Commands clipped to 0 ≤ current ≤ current_limit (A) and |rate| ≤ rate_limit (rad/s)
    (:func:`gyro_ctl.law_kernels.limit_values`)."""
    if current_limit is None and rate_limit is None:
        return commands
    names = list(commands)
    cur = np.array([_nan(commands[n][0]) for n in names])
    rate = np.array([_nan(commands[n][1]) for n in names])
    lk.limit_values(cur, rate, _nan(current_limit), _nan(rate_limit))
    return dict(zip(names, zip(_optional(cur), _optional(rate))))


def make_law(cfg: ControllerConfig) -> Callable[[ControlInput], Commands]:
    """The law of a controller config (with its limits) as a one-argument function of the state: a
    :class:`CompiledLaw` for the built-in laws with a compiled form, else (reorient, or a law put in :data:`LAWS`
    in place of a built-in one) the Python function."""
    fn = LAWS[cfg.law]
    params, cl, rl = cfg.params, cfg.current_limit, cfg.rate_limit
    if COMPILED.get(cfg.law) is fn:
        return CompiledLaw(params, cl, rl)
    return lambda x: limited(fn(x, params), cl, rl)


def make_switching(cfg: ControllerConfig) -> Callable[[ControlInput], np.ndarray] | None:
    """The law's switching functions (None for a law without switching)."""
    fn = SWITCHING.get(cfg.law)
    if fn is None:
        return None
    params = cfg.params
    return lambda x: fn(x, params)
