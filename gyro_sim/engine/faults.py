"""Fault injection for hardware-in-the-loop style tests of a controller (simulator node parameters).

What a bench would do to a controller, reproducibly from one seed and off by default (then nothing here runs):

* commands: a fraction dropped (``command_drop``: never applied, the previous command stays), a fraction
  corrupted (``command_corrupt``: each current of the command scaled by a factor uniform in [0, 2)), every
  command delayed by ``command_delay`` control ticks (applied that many ticks after the tick it answers), and
  the applied currents quantised to ``current_quantum`` A (a DAC's step);
* the published state (``gyro/imu``, ``gyro/kinetic_moment``): Gaussian noise on Ω_b (``noise_omega`` rad/s,
  each body component), on the attitude (``noise_attitude`` rad: a rotation about a uniformly random axis by an
  angle whose components are N(0, σ²) each) and on L (``noise_L`` N·m·s, each case component), and a constant
  bias on Ω_b (``bias_omega`` rad/s, body frame). ``gyro/imu``'s covariances then say so: orientation and
  angular velocity diag(σ²) (a bias is systematic: not in a covariance).

The simulation itself is not noisy: bags record the true state and the commands as applied (after drop,
corruption, delay, quantisation), so a bag re-runs bit for bit. Commands draw from a stream of the seed
(``fault_seed``), a fixed number of draws per tick; the sensor noise of a state is a function of (seed, stamp).
The same seed gives the same faults, whatever the subscribers or the machine's timing.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

__all__ = ["FaultConfig", "Faults"]


@dataclass(frozen=True)
class FaultConfig:
    """The fault-injection settings (SI); the defaults inject nothing."""

    seed: int = 0
    command_drop: float = 0.0  # fraction of commands dropped, 0–1
    command_corrupt: float = 0.0  # fraction of commands whose currents are scaled by U[0, 2), 0–1
    command_delay: int = 0  # control ticks between a command's tick and its application, ≥ 0
    current_quantum: float = 0.0  # A, applied currents rounded to multiples (0 = off)
    noise_omega: float = 0.0  # rad/s, std of the published Ω_b (body)
    noise_attitude: float = 0.0  # rad, std of each component of the published attitude's error rotation
    noise_L: float = 0.0  # N·m·s, std of each component of the published L (case)
    bias_omega: tuple = field(default=(0.0, 0.0, 0.0))  # rad/s, added to the published Ω_b (body)

    def __post_init__(self):
        for name in ("command_drop", "command_corrupt"):
            v = getattr(self, name)
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"{name} = {v!r}: a fraction in [0, 1]")
        for name in ("current_quantum", "noise_omega", "noise_attitude", "noise_L"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} = {v!r}: must be finite and ≥ 0")
        if int(self.command_delay) != self.command_delay or self.command_delay < 0:
            raise ValueError(f"command_delay = {self.command_delay!r}: a whole number of ticks ≥ 0")
        if len(self.bias_omega) != 3 or not all(math.isfinite(float(b)) for b in self.bias_omega):
            raise ValueError(f"bias_omega = {list(self.bias_omega)!r}: three finite rates (rad/s, body frame)")

    @property
    def commands_active(self) -> bool:
        return bool(self.command_drop or self.command_corrupt or self.command_delay or self.current_quantum)

    @property
    def sensors_active(self) -> bool:
        return bool(self.noise_omega or self.noise_attitude or self.noise_L or any(self.bias_omega))

    @property
    def active(self) -> bool:
        return self.commands_active or self.sensors_active

    def as_custom(self) -> dict:
        """custom_data entries of a bag (``gyro_sim.fault.<name>``), for the active settings only."""
        out = {}
        for name in ("seed", "command_drop", "command_corrupt", "command_delay", "current_quantum", "noise_omega",
                     "noise_attitude", "noise_L"):
            out[f"gyro_sim.fault.{name}"] = repr(getattr(self, name))
        out["gyro_sim.fault.bias_omega"] = repr([float(b) for b in self.bias_omega])
        return out


class Faults:
    """The faults of one run: commands through :meth:`command` at each tick, published states through
    :meth:`state`."""

    def __init__(self, cfg: FaultConfig, n_stators: int = 3):
        self.cfg = cfg
        self.n = max(int(n_stators), 1)
        self.rng_cmd = np.random.default_rng([int(cfg.seed), 1])  # one draw per tick (sensors: per stamp, state())
        self.fifo: deque = deque()
        self.dropped = self.corrupted = 0

    def command(self, cmd: Optional[tuple]) -> Optional[tuple]:
        """At a control tick: the command to apply now, from the one received for this tick (``cmd`` = (names,
        currents, rates | None, stamp) or None). Every tick draws the same numbers whether a command came or not,
        so the stream stays aligned with the ticks."""
        c = self.cfg
        drop, corrupt = self.rng_cmd.random(), self.rng_cmd.random()
        factors = dict(zip(range(self.n), self.rng_cmd.random(self.n) * 2.0))
        if cmd is not None and drop < c.command_drop:
            self.dropped += 1
            cmd = None
        if cmd is not None and corrupt < c.command_corrupt:
            self.corrupted += 1
            cmd = (cmd[0], [float(i) * factors.get(k, 1.0) for k, i in enumerate(cmd[1])], cmd[2], cmd[3])
        if cmd is not None and c.current_quantum:
            q = c.current_quantum
            cmd = (cmd[0], [round(float(i) / q) * q for i in cmd[1]], cmd[2], cmd[3])
        if c.command_delay:
            self.fifo.append(cmd)
            return self.fifo.popleft() if len(self.fifo) > c.command_delay else None
        return cmd

    def state(self, L: np.ndarray, q: np.ndarray, omega_b: np.ndarray, stamp: int) -> tuple:
        """Noisy copies (L case N·m·s, q = (w, x, y, z) body → case, Ω_b rad/s) of the state published with
        ``stamp`` (ns). The noise is a function of (seed, stamp): a state published again (while lockstep waits)
        carries the same noise, and who subscribes, or how often a state is repeated, changes nothing."""
        c = self.cfg
        r = np.random.default_rng([int(c.seed), 2, int(stamp)])
        nL, na, nw = r.standard_normal(3), r.standard_normal(3), r.standard_normal(3)
        L = np.asarray(L, float) + c.noise_L * nL
        omega_b = np.asarray(omega_b, float) + c.noise_omega * nw + np.asarray(c.bias_omega, float)
        q = np.asarray(q, float)
        if c.noise_attitude:
            v = c.noise_attitude * na  # error rotation vector (case frame), rad
            a = float(np.linalg.norm(v))
            if a > 0:
                s = math.sin(a / 2) / a
                e = np.array([math.cos(a / 2), v[0] * s, v[1] * s, v[2] * s])
                w0, x0, y0, z0 = e
                w1, x1, y1, z1 = q
                q = np.array([w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                              w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1, w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1])
        return L, q, omega_b

    def covariances(self) -> tuple[list, list]:
        """(orientation, angular velocity) covariances of gyro/imu (row-major 3x3, rad², (rad/s)²); zeros (=
        unknown, sensor_msgs/Imu) where no noise is injected."""
        a, w = self.cfg.noise_attitude ** 2, self.cfg.noise_omega ** 2
        return [a, 0.0, 0.0, 0.0, a, 0.0, 0.0, 0.0, a], [w, 0.0, 0.0, 0.0, w, 0.0, 0.0, 0.0, w]
