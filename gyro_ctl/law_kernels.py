"""The built-in control laws in compiled form (numba): one implementation that Python and compiled code call.

:func:`law_commands` evaluates a law on plain numbers (t s, L N·m·s in the case frame, q = (w, x, y, z) body →
case) and writes its commands into two arrays, current (A) and signed field rate (rad/s), one entry per stator the
law commands; NaN stands for ``None`` (that field of the command left unchanged). The limits of the controller
section clip the values in the same call. :class:`gyro_ctl.laws.CompiledLaw` wraps it in the ``ControlInput ->
Commands`` API for the ROS controller node and the Python callers; :mod:`gyro_sim.ticks` calls it inside the
compiled in-process tick loop, so both evaluate the same machine code on the same numbers.

A law is described by its kind (the constants below) and ``fp``, its float parameters:

* ``SPINUP``: (current A, ramp A/s or NaN, target_spin rad/s); one command.
* ``PSI_SWITCHING``: (spin_current A, spin_rate rad/s, control_current A, dead_band rad, ν_0 … ν_{n−1} rad/s);
  commands: the spin stator, then the n control stators, whose unit axes (case frame) are the rows of ``axes``.
* ``OFF``: (); one command (0 A, rate unchanged) per stator of the scene.
* ``HOLD``: (); no command.
* ``MANUAL``: (current_0, rate_0, current_1, rate_1, …); one command per named stator.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["SPINUP", "PSI_SWITCHING", "OFF", "HOLD", "MANUAL", "law_commands", "law_values", "limit_values", "warm"]

SPINUP, PSI_SWITCHING, OFF, HOLD, MANUAL = 0, 1, 2, 3, 4


@njit(cache=True)
def law_values(kind, t, L, q, axes, fp, cur, rate):
    """The commands of law ``kind`` (module docstring) at time ``t`` (s) for L (3,) and q (4,), unclipped: written
    to ``cur`` (A) and ``rate`` (rad/s), NaN = unchanged. ``axes`` (n, 3): the control stators' unit axes
    (ψ-switching; any (0, 3) array otherwise)."""
    if kind == SPINUP:
        # spin-up ([K] §1): the field turns at the target spin; the current ramps to its value (min(I, ramp·t))
        c = fp[0]
        if fp[1] == fp[1]:
            ramped = fp[1] * t
            if ramped < c:
                c = ramped
        cur[0] = c
        rate[0] = fp[2]
    elif kind == PSI_SWITCHING:
        _psi_switching(L, q, axes, fp, cur, rate)
    elif kind == OFF:
        for j in range(cur.shape[0]):
            cur[j] = 0.0
            rate[j] = math.nan
    elif kind == MANUAL:
        for j in range(cur.shape[0]):
            cur[j] = fp[2 * j]
            rate[j] = fp[2 * j + 1]
    # HOLD: no command


@njit(cache=True, inline="always")
def _psi_switching(L, q, axes, fp, cur, rate):
    """ψ-switching, [K] (3.1) in the vector form of physics.md §5: control stator n turns its field at
    ν_n sign(u_n · e⊥), e⊥ = (x3 − y3 cosθ)/sinθ the polar axis projected on the plane normal to L (y3 = L/|L|);
    the spin stator stays on. Inside the dead band (θ or π − θ below it, or e⊥ undefined) the control currents are
    off, their rates +ν_n."""
    cur[0] = fp[0]
    rate[0] = fp[1]
    w, x, y, z = q[0], q[1], q[2], q[3]
    a0 = 2 * (x * z + w * y)  # x3, the polar axis, in the case frame
    a1 = 2 * (y * z - w * x)
    a2 = 1 - 2 * (x * x + y * y)
    L0, L1, L2 = L[0], L[1], L[2]
    n = math.sqrt(L0 * L0 + L1 * L1 + L2 * L2)
    inside = True  # in the dead band, or e⊥ undefined
    e0 = e1 = e2 = 0.0
    if n != 0.0:
        c0, c1, c2 = a1 * L2 - a2 * L1, a2 * L0 - a0 * L2, a0 * L1 - a1 * L0
        th = math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), a0 * L0 + a1 * L1 + a2 * L2)  # θ between x3 and L
        y0, y1, y2 = L0 / n, L1 / n, L2 / n
        ct = a0 * y0 + a1 * y1 + a2 * y2
        v0, v1, v2 = a0 - y0 * ct, a1 - y1 * ct, a2 - y2 * ct
        s = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if s != 0.0 and not (th < fp[3] or math.pi - th < fp[3]):
            inside = False
            e0, e1, e2 = v0 / s, v1 / s, v2 / s
    for i in range(axes.shape[0]):
        nu = fp[4 + i]
        if inside:
            cur[1 + i] = 0.0
            rate[1 + i] = nu
        else:
            u = axes[i]
            cur[1 + i] = fp[2]
            rate[1 + i] = nu if u[0] * e0 + u[1] * e1 + u[2] * e2 >= 0.0 else -nu  # [K] (3.1)


@njit(cache=True)
def limit_values(cur, rate, current_limit, rate_limit):
    """Clip commands in place to 0 ≤ current ≤ ``current_limit`` (A) and |rate| ≤ ``rate_limit`` (rad/s); a NaN
    limit is no limit, a NaN value (unchanged) stays. Python's min/max order: max(c, 0) keeps c unless 0 > c."""
    for j in range(cur.shape[0]):
        c = cur[j]
        if c == c and current_limit == current_limit:
            if 0.0 > c:
                c = 0.0
            if current_limit < c:
                c = current_limit
            cur[j] = c
        r = rate[j]
        if r == r and rate_limit == rate_limit:
            if -rate_limit > r:
                r = -rate_limit
            if rate_limit < r:
                r = rate_limit
            rate[j] = r


@njit(cache=True)
def law_commands(kind, t, L, q, axes, fp, current_limit, rate_limit, cur, rate):
    """:func:`law_values` then :func:`limit_values`: the commands a controller sends (NaN limits: none)."""
    law_values(kind, t, L, q, axes, fp, cur, rate)
    limit_values(cur, rate, current_limit, rate_limit)


def warm() -> None:
    """Call :func:`law_commands` once with the argument types every caller uses: numba loads it from its cache (or
    compiles it) now rather than at a controller's first tick."""
    law_commands(HOLD, 0.0, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros((0, 3)), np.zeros(0), math.nan,
                 math.nan, np.zeros(0), np.zeros(0))
