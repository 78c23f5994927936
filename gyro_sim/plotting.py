"""Plots of a simulation run (PNG, matplotlib's Agg canvas; never opens a window).

``plot_run(result, path)`` draws three stacked panels on one time axis:

1. spin rate Ω_b3 (body axis 3) in rev/s, with the magnitude |Ω| dashed;
2. nutation angle θ in degrees (a run without attitude, ``result.attitude`` False, has none: the panel
   says so and the spin panel shows |Ω| alone);
3. stator current amplitudes in A, one line per stator.

Long runs are thinned to at most ``MAX_POINTS`` points per line by keeping each
bucket's minimum and maximum, so peaks and envelopes survive the thinning.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

__all__ = ["plot_run", "decimate_minmax", "MAX_POINTS"]

MAX_POINTS = 5000


def decimate_minmax(t, y, max_points: int = MAX_POINTS):
    """Thin the series ``y(t)`` to at most ``max_points`` points.

    The samples are cut into ``(max_points - 2) // 2`` buckets of consecutive
    indices, and each bucket keeps the indices of its minimum and maximum; the
    first and last samples are always kept. A series that is short enough is
    returned unchanged.

    Args:
        t: sample times, shape (n,), any unit.
        y: values, shape (n,), any unit.
        max_points: the most points to return (>= 4).

    Returns:
        ``(t_kept, y_kept)``, in time order.
    """
    t = np.asarray(t)
    y = np.asarray(y)
    n = t.shape[0]
    if y.shape[0] != n:
        raise ValueError(f"t has {n} samples but y has {y.shape[0]}")
    if max_points < 4:
        raise ValueError("max_points must be at least 4")
    if n <= max_points:
        return t, y
    nb = (max_points - 2) // 2
    size = math.ceil(n / nb)
    nb = math.ceil(n / size)  # buckets actually needed
    padded = np.empty(nb * size, dtype=float)
    padded[:n] = y
    padded[n:] = y[-1]  # pad with the last value: its index clips to n - 1
    blocks = padded.reshape(nb, size)
    with np.errstate(invalid="ignore"):
        # NaN-tolerant: a block of NaNs keeps its first index
        finite = np.where(np.isnan(blocks), np.inf, blocks)
        i_min = np.argmin(finite, axis=1)
        finite = np.where(np.isnan(blocks), -np.inf, blocks)
        i_max = np.argmax(finite, axis=1)
    base = np.arange(nb) * size
    idx = np.concatenate(([0, n - 1], base + i_min, base + i_max))
    idx = np.unique(np.clip(idx, 0, n - 1))
    return t[idx], y[idx]


def _time_axis(t_end: float):
    """Seconds, minutes or hours, whichever keeps the tick labels short."""
    if t_end >= 3 * 3600.0:
        return 3600.0, "h"
    if t_end >= 3 * 60.0:
        return 60.0, "min"
    return 1.0, "s"


def save_png(fig, path) -> Path:
    """Write a figure as PNG atomically (a temporary file, then a rename): no half-written plot."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, format="png", dpi=100)
    os.replace(tmp, path)
    return path


def plot_run(result, path) -> Path:
    """Write a PNG summarising ``result`` (a ``gyro_sim.simulate.RunResult``).

    Uses ``result.t`` (s), ``result.omega_b`` (rad/s, body frame),
    ``result.euler[:, 1]`` (θ, rad), ``result.current`` (A, one column per
    stator), ``result.stator_names``, ``result.scene.name`` (the title) and, if
    present, ``result.L`` (N·m·s, case frame; a fourth panel).

    Args:
        result: the run to plot.
        path: where to write the PNG; missing parent folders are made.

    Returns:
        The path written, as a ``Path``.
    """
    # The object-oriented API with the Agg canvas: no pyplot state, no GUI backend.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    t = np.asarray(result.t, dtype=float)
    omega = np.asarray(result.omega_b, dtype=float).reshape(len(t), 3)
    theta_deg = np.degrees(np.asarray(result.euler, dtype=float).reshape(len(t), 3)[:, 1])
    current = np.asarray(result.current, dtype=float).reshape(len(t), -1)
    names = list(result.stator_names)
    scene = getattr(result, "scene", None)
    title = getattr(scene, "name", None) or "gyro_sim run"

    scale, unit = _time_axis(float(t[-1] - t[0]) if len(t) else 0.0)
    ts = t / scale

    L = getattr(result, "L", None)
    fig = Figure(figsize=(10.0, 10.0 if L is not None else 8.0), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(4 if L is not None else 3, 1, sharex=True)
    ax_spin, ax_theta, ax_cur = axes[0], axes[1], axes[-1]
    if L is not None:
        L = np.asarray(L, dtype=float).reshape(len(t), 3)
        for j in range(3):
            axes[2].plot(*decimate_minmax(ts, L[:, j]), color=f"C{j}", label=f"L{j + 1}")
        axes[2].set_ylabel("L, case frame (N·m·s)")
        axes[2].legend(loc="best")
    fig.suptitle(title)

    rev = 1.0 / (2.0 * math.pi)
    attitude = getattr(result, "attitude", True)
    if attitude:  # without attitude omega_b is in the case frame: its third component is no spin
        ax_spin.plot(*decimate_minmax(ts, omega[:, 2] * rev), color="C0", label="Ω_b3")
    ax_spin.plot(*decimate_minmax(ts, np.linalg.norm(omega, axis=1) * rev),
                 color="C1", linestyle="--", label="|Ω|")
    ax_spin.set_ylabel("spin rate (rev/s)")
    ax_spin.legend(loc="best")

    if attitude:
        ax_theta.plot(*decimate_minmax(ts, theta_deg), color="C2")
    else:
        ax_theta.text(0.5, 0.5, "attitude not integrated (output.attitude: false)", ha="center", va="center",
                      transform=ax_theta.transAxes)
    ax_theta.set_ylabel("nutation θ (deg)")

    for j in range(current.shape[1]):
        label = names[j] if j < len(names) else f"stator {j}"
        ax_cur.plot(*decimate_minmax(ts, current[:, j]), color=f"C{j}", label=label)
    if current.shape[1]:
        ax_cur.legend(loc="best")
    else:
        ax_cur.text(0.5, 0.5, "no stators", ha="center", va="center",
                    transform=ax_cur.transAxes)
    ax_cur.set_ylabel("stator current (A)")
    ax_cur.set_xlabel(f"time ({unit})")

    for ax in axes:
        ax.grid(True, alpha=0.3)

    return save_png(fig, path)
