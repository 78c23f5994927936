"""Simulation times as exact integer nanoseconds: the stamps of the samples, the messages and the bags.

One function every layer may use (the engine's output grid, the message contract, the bag readers):
:func:`stamp_ns` (re-exported by :mod:`gyro_sim.io.messages`, where it was before the layers).
"""
import math


def stamp_ns(t: float) -> int:
    """Simulation time ``t`` (s, finite, ≥ 0) as integer nanoseconds, rounded to nearest (ties up).

    Exact: computed from the binary value of ``t`` with integers, no floating-point product.
    """
    try:
        t = float(t)
    except (TypeError, ValueError):
        raise ValueError(f"time stamp t = {t!r}: must be a number of seconds") from None
    if not (math.isfinite(t) and t >= 0.0):
        raise ValueError(f"time stamp t = {t!r}: must be finite and ≥ 0 s")
    num, den = t.as_integer_ratio()
    return (2 * num * 1_000_000_000 + den) // (2 * den)
