"""Control laws as pure functions of the rotor state (no ROS, no simulator objects).

A law takes a :class:`ControlInput` (what the simulator publishes: time, L in the case frame,
attitude, body angular velocity, the stators' names and axes) and its parameters, and returns
stator commands ``{name: (current A, signed field rate rad/s)}``. The same function runs inside
the core (``gyro_sim.run``) and in the controller node (``gyro_ctl.ros.controller``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

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
    zero-slip asymptote; time constant J3/(k_e b² I²) (see :func:`spinup_time_constant`).
    """
    current = p.current if p.ramp is None else min(p.current, p.ramp * x.t)
    return {p.stator: (current, p.target_spin)}


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
    """
    out: Commands = {p.spin_stator: (p.spin_current, p.spin_rate)}
    th = x.theta
    e = transverse_unit(x)
    if e is None or th < p.dead_band or math.pi - th < p.dead_band:
        for i, name in enumerate(p.control_stators):
            out[name] = (0.0, p.rate(i))
        return out
    for i, name in enumerate(p.control_stators):
        s = float(x.axis(name) @ e)
        out[name] = (p.control_current, p.rate(i) if s >= 0.0 else -p.rate(i))  # [K] (3.1)
    return out


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
    return {n: (0.0, None) for n in x.stator_names}


def hold(x: ControlInput, p: HoldParams) -> Commands:
    """Keep the last commands (send nothing)."""
    return {}


def manual(x: ControlInput, p: ManualParams) -> Commands:
    """The fixed commands of the parameters."""
    return {n: (c.current, c.rate) for n, c in p.commands.items()}


LAWS: Mapping[str, Callable] = {"spinup": spinup, "psi_switching": psi_switching, "off": off, "hold": hold,
                                "manual": manual, "reorient": reorient}
SWITCHING: Mapping[str, Callable] = {"psi_switching": psi_switching_functions}


def limited(commands: Commands, current_limit: float | None, rate_limit: float | None) -> Commands:
    """Commands clipped to 0 ≤ current ≤ current_limit (A) and |rate| ≤ rate_limit (rad/s)."""
    if current_limit is None and rate_limit is None:
        return commands
    out = {}
    for n, (c, r) in commands.items():
        if c is not None and current_limit is not None:
            c = min(max(c, 0.0), current_limit)
        if r is not None and rate_limit is not None:
            r = min(max(r, -rate_limit), rate_limit)
        out[n] = (c, r)
    return out


def make_law(cfg: ControllerConfig) -> Callable[[ControlInput], Commands]:
    """The law of a controller config (with its limits) as a one-argument function of the state."""
    fn = LAWS[cfg.law]
    params, cl, rl = cfg.params, cfg.current_limit, cfg.rate_limit
    return lambda x: limited(fn(x, params), cl, rl)


def make_switching(cfg: ControllerConfig) -> Callable[[ControlInput], np.ndarray] | None:
    """The law's switching functions (None for a law without switching)."""
    fn = SWITCHING.get(cfg.law)
    if fn is None:
        return None
    params = cfg.params
    return lambda x: fn(x, params)
