"""Plots of a simulation run: a ``matplotlib.figure.Figure`` on its own Agg canvas (no pyplot state, the
backend left as it is, never a window); saved as PNG when given a path.

``plot_run(result, path=None) -> Figure`` draws stacked panels on one time axis:

0. events: switching instants (a field reverses or a stator turns on/off) and command changes (``result.commands``);
1. rotor rate in rev/s: spin Ω_b3 (about the polar axis x3) and the magnitude |Ω| dashed;
2. nutation angle θ in degrees (a run without attitude, ``result.attitude`` False, has none: the panel
   says so and the spin panel shows |Ω| alone);
3. kinetic moment L in N·m·s, case frame (when the result has ``L``);
4. stator current amplitudes in A, one step line per stator, each in its own style;
5. field rate ν/2π in Hz (signed: the direction of rotation) and 6. slip (ν − Ω·u)/2π in Hz (field rate minus
   the rotor's rate about the stator axis u) of each stator while it carries current (when the result has
   ``field_rate``).

Command changes are also dashed vertical lines across the panels.

Long runs are thinned to at most ``MAX_POINTS`` points per line by keeping each
bucket's minimum and maximum, so peaks and envelopes survive the thinning.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["plot_run", "decimate_minmax", "slip", "command_events", "CommandEvents", "save_png", "new_figure",
           "MAX_POINTS"]

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


def save_png(fig, path, dpi: int = 100) -> Path:
    """Write a figure as PNG atomically (a temporary file, then a rename): no half-written plot.

    Missing parent folders are made. Returns the path written, as a ``Path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, format="png", dpi=dpi)
    os.replace(tmp, path)
    return path


def new_figure(figsize, layout: str = "constrained"):
    """A ``matplotlib.figure.Figure`` on its own Agg canvas: no pyplot state, the backend left as it is.

    The caller can restyle it, show it in a notebook (``display(fig)``) or save it (:func:`save_png`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    return fig


# --- command events -----------------------------------------------------------------------------------
JUMP_FRACTION = 0.05  # a current or |field rate| step above this fraction of its run maximum is a command change


@dataclass(frozen=True)
class CommandEvents:
    """Instants (s) where the applied stator commands change, from ``result.commands``.

    ``switching``: a field reverses (the sign of its rate ν flips) or a stator turns on or off (current
    0 ↔ nonzero): the instants of the ψ-switching law. ``changes``: any other step of a current or of
    |ν| larger than ``JUMP_FRACTION`` of that stator's largest value in the run (smaller steps, e.g.
    a controller's continuous adjustments, are not marked: the current panel shows them)."""

    switching: np.ndarray
    changes: np.ndarray


def _initial_state(result, names):
    """name → [current A, rate rad/s] before the first command: the scene's stators, else unknown (None)."""
    state = {n: [None, None] for n in names}
    for st in getattr(getattr(result, "scene", None), "stators", None) or []:
        if getattr(st, "name", None) in state:
            state[st.name] = [float(st.current), float(st.rate)]
    return state


def _stator_scales(commands, names):
    """name → (largest |current| A, largest |rate| rad/s) over the commands (1 where none is nonzero)."""
    imax = {n: 0.0 for n in names}
    rmax = {n: 0.0 for n in names}
    for _, cnames, cur, rate in commands:
        for k, n in enumerate(cnames):
            if n not in imax:
                continue
            if cur is not None and cur[k] is not None and math.isfinite(cur[k]):
                imax[n] = max(imax[n], abs(float(cur[k])))
            if rate is not None and rate[k] is not None and math.isfinite(rate[k]):
                rmax[n] = max(rmax[n], abs(float(rate[k])))
    return {n: (imax[n] or 1.0, rmax[n] or 1.0) for n in names}


def _classify(old, new, scale):
    """'switch', 'change' or None for one stator going from ``old`` to ``new`` ([current A, rate rad/s])."""
    (i0, r0), (i1, r1) = old, new
    if i0 is None or r0 is None:
        return None
    if (i0 == 0.0) != (i1 == 0.0) or (r0 * r1 < 0.0 and i1 != 0.0):
        return "switch"
    if i1 == 0.0:  # off before and after: a new rate of a field that is not there
        return None
    if abs(i1 - i0) > JUMP_FRACTION * scale[0] or abs(abs(r1) - abs(r0)) > JUMP_FRACTION * scale[1]:
        return "change"
    return None


def command_events(result) -> CommandEvents:
    """The switching instants and command changes of a run (s), from ``result.commands``.

    ``result.commands``: (t s, stator names, currents A or None, rates rad/s or None) as applied; a
    result without it (an old bag view) has no events. See :class:`CommandEvents` for what counts."""
    commands = list(getattr(result, "commands", None) or [])
    names = list(getattr(result, "stator_names", []))
    state = _initial_state(result, names)
    scales = _stator_scales(commands, names)
    switching, changes = [], []
    for t, cnames, cur, rate in commands:
        kinds = set()
        for k, n in enumerate(cnames):
            if n not in state:
                continue
            old = list(state[n])
            new = [float(cur[k]) if cur is not None and cur[k] is not None else old[0],
                   float(rate[k]) if rate is not None and rate[k] is not None else old[1]]
            kinds.add(_classify(old, new, scales[n]))
            state[n] = new
        if "switch" in kinds:
            switching.append(float(t))
        if "change" in kinds:
            changes.append(float(t))
    return CommandEvents(np.asarray(switching, dtype=float), np.asarray(changes, dtype=float))


# --- slip ----------------------------------------------------------------------------------------------
def _stator_axes(result, names):
    """(k, 3) unit axes u_k of the stators (case frame), from ``result.scene.stators``; None if unknown."""
    by_name = {getattr(s, "name", None): s for s in getattr(getattr(result, "scene", None), "stators", None) or []}
    if not names or any(n not in by_name for n in names):
        return None
    u = np.array([np.asarray(by_name[n].axis, dtype=float) for n in names])
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _omega_case(result, n):
    """(n, 3) rotor angular velocity Ω in the case frame, rad/s (R(q) Ω_b; Ω_b itself without attitude)."""
    from gyro_sim.physics.frames import quat_to_matrix

    omega = np.asarray(result.omega_b, dtype=float).reshape(n, 3)
    if not getattr(result, "attitude", True):
        return omega  # without attitude omega_b is already in the case frame
    q = np.asarray(result.q, dtype=float).reshape(n, 4)
    return np.einsum("nij,nj->ni", quat_to_matrix(q), omega)


def slip(result):
    """Slip of each stator's field over the rotor, rad/s: s_k = ν_k − Ω·u_k, shape (n, k).

    ν_k: the signed field rate (``result.field_rate``, rad/s); Ω·u_k: the rotor's angular velocity about
    the stator axis u_k (case frame). NaN while stator k carries no current (no field, no slip). For the
    spin stator of a rotor spinning about its axis this is field rate − spin rate; s → 0 is the
    induction motor's zero-torque asymptote. None when the field rates or stator axes are unknown."""
    rate = getattr(result, "field_rate", None)
    names = list(getattr(result, "stator_names", []))
    u = _stator_axes(result, names)
    if rate is None or u is None:
        return None
    n = len(np.asarray(result.t))
    rate = np.asarray(rate, dtype=float).reshape(n, -1)
    current = np.asarray(result.current, dtype=float).reshape(n, -1)
    s = rate - _omega_case(result, n) @ u.T
    return np.where(current != 0.0, s, np.nan)


# --- the run plot ---------------------------------------------------------------------------------------
# one style per stator, so coinciding traces (two stators off at 0 A) stay apart: wide and pale underneath,
# dashed and dotted on top
_STATOR_STYLES = [dict(ls="-", lw=3.2, alpha=0.45), dict(ls="--", lw=1.6), dict(ls=":", lw=2.2),
                  dict(ls="-.", lw=1.4)]
SWITCH_COLOR = "tab:red"
CHANGE_COLOR = "0.3"


def _stator_style(j):
    return dict(_STATOR_STYLES[j % len(_STATOR_STYLES)], color=f"C{j}")


def _legend(ax, **kw):
    """A legend outside the panel, on its right: it never hides a trace."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, **kw)


def _panel_spin(ax, ts, omega, attitude):
    rev = 1.0 / (2.0 * math.pi)
    if attitude:  # without attitude omega_b is in the case frame: its third component is no spin
        ax.plot(*decimate_minmax(ts, omega[:, 2] * rev), color="C0", label="spin Ω₃/2π\n(about polar axis x3)")
    ax.plot(*decimate_minmax(ts, np.linalg.norm(omega, axis=1) * rev), color="C1", ls="--",
            label="|Ω|/2π (total)")
    ax.set_ylabel("rotor rate (rev/s)")
    _legend(ax)


def _panel_theta(ax, ts, theta_deg, attitude):
    if attitude:
        ax.plot(*decimate_minmax(ts, theta_deg), color="C2")
    else:
        ax.text(0.5, 0.5, "attitude not integrated (output.attitude: false)", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_ylabel("nutation θ (deg)\npolar axis x3 vs L")


def _panel_L(ax, ts, L):
    for j in range(3):
        ax.plot(*decimate_minmax(ts, L[:, j]), **_stator_style(j), label=f"L along z{j + 1}")  # zeros stay apart
    ax.set_ylabel("kinetic moment L\ncase frame (N·m·s)")
    _legend(ax)


def _label(names, j):
    return names[j] if j < len(names) else f"stator {j}"


def _panel_current(ax, ts, current, names):
    for j in range(current.shape[1]):
        off = not np.any(current[:, j] != 0.0)
        ax.plot(*decimate_minmax(ts, current[:, j]), drawstyle="steps-post", **_stator_style(j),
                label=_label(names, j) + (" (0 A throughout)" if off else ""))
    if not current.shape[1]:
        ax.text(0.5, 0.5, "no stators", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel("stator current\namplitude (A)")


def _panel_per_stator(ax, ts, values, names, ylabel, empty):
    """One step line per stator where ``values`` (n, k) is not all NaN; ``empty`` said when none is."""
    drawn = 0
    for j in range(values.shape[1]):
        if np.all(np.isnan(values[:, j])):
            continue
        ax.plot(*decimate_minmax(ts, values[:, j]), drawstyle="steps-post", **_stator_style(j),
                label=_label(names, j))
        drawn += 1
    if drawn:
        ax.axhline(0.0, color="0.5", lw=0.6)
        _legend(ax)
    else:
        ax.text(0.5, 0.5, empty, ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel(ylabel)


def _panel_events(ax, ev: CommandEvents, scale):
    """The strip above the panels: switching instants (upper row) and command changes (lower row) as ticks."""
    if ev.switching.size:
        ax.vlines(ev.switching / scale, 0.55, 0.95, colors=SWITCH_COLOR, lw=0.8, gid="switching")
    if ev.changes.size:
        ax.vlines(ev.changes / scale, 0.05, 0.45, colors=CHANGE_COLOR, lw=1.2, gid="command_changes")
    if not (ev.switching.size or ev.changes.size):
        ax.text(0.5, 0.5, "no switching, no command change", ha="center", va="center", fontsize=8,
                color="0.4", transform=ax.transAxes)
    ax.set_ylim(0.0, 1.0)
    ax.set_yticks([0.75, 0.25], ["switching", "command"], fontsize=7)
    ax.tick_params(axis="y", length=0)
    ax.set_ylabel("events", fontsize=8)


def _mark_changes(axes, ev: CommandEvents, scale):
    """Command changes as thin dashed lines across the data panels (switching instants are too many: strip only)."""
    from matplotlib.transforms import blended_transform_factory

    if not ev.changes.size:
        return
    for ax in axes:
        ax.vlines(ev.changes / scale, 0.0, 1.0, transform=blended_transform_factory(ax.transData, ax.transAxes),
                  colors=CHANGE_COLOR, lw=0.7, linestyles=(0, (4, 3)), zorder=1.5, gid="command_changes")


def _event_handles(ev: CommandEvents):
    from matplotlib.lines import Line2D

    h = []
    if ev.switching.size:
        h.append(Line2D([], [], color=SWITCH_COLOR, marker="|", ls="none", markersize=9, markeredgewidth=1.2,
                        label=f"switching ({ev.switching.size}×):\nfield reversed or on/off"))
    if ev.changes.size:
        h.append(Line2D([], [], color=CHANGE_COLOR, lw=0.8, ls=(0, (4, 3)),
                        label=f"command change ({ev.changes.size}×):\nnew current or |ν|"))
    return h


def plot_run(result, path=None):
    """A figure summarising ``result`` (a ``gyro_sim.simulate.RunResult`` or a bag's view of one).

    Panels on one time axis: rotor rate (rev/s: spin Ω₃ about the polar axis x3, |Ω|); nutation θ (deg);
    kinetic moment L (N·m·s, case frame; when ``result.L`` is given); stator current amplitudes (A, one
    step line per stator, each in its own style so coinciding traces stay apart); field rate ν/2π (Hz,
    signed: the sign is the field's direction of rotation) and slip (ν − Ω·u)/2π (Hz, field rate minus the
    rotor's rate about the stator axis u, :func:`slip`) of each stator while it carries current. Command
    changes and switching instants (:func:`command_events`, from ``result.commands``) are marked on every
    panel. Lines longer than ``MAX_POINTS`` are thinned with :func:`decimate_minmax`.

    Args:
        result: the run: ``t`` (s), ``omega_b`` (rad/s, body frame), ``q``, ``euler`` (rad), ``current``
            (A), ``stator_names``, optionally ``L``, ``field_rate`` (rad/s), ``commands``, ``scene``.
        path: if given, the figure is also written there as PNG (atomically; parent folders made).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state: restyle it, save it again).
    """
    t = np.asarray(result.t, dtype=float)
    n = len(t)
    omega = np.asarray(result.omega_b, dtype=float).reshape(n, 3)
    theta_deg = np.degrees(np.asarray(result.euler, dtype=float).reshape(n, 3)[:, 1])
    current = np.asarray(result.current, dtype=float).reshape(n, -1)
    names = list(result.stator_names)
    attitude = getattr(result, "attitude", True)
    scale, unit = _time_axis(float(t[-1] - t[0]) if n else 0.0)
    ts = t / scale
    L = getattr(result, "L", None)
    rate = getattr(result, "field_rate", None)
    s = slip(result)
    ev = command_events(result)

    kinds = ["events", "spin", "theta"] + (["L"] if L is not None else []) + ["current"] \
        + (["rate"] if rate is not None else []) + (["slip"] if rate is not None else [])
    fig = new_figure((12.5, 1.85 * (len(kinds) - 1) + 1.4))
    axes = fig.subplots(len(kinds), 1, sharex=True, height_ratios=[0.22] + [1.0] * (len(kinds) - 1))
    ax = dict(zip(kinds, axes))
    _panel_events(ax["events"], ev, scale)
    _panel_spin(ax["spin"], ts, omega, attitude)
    _panel_theta(ax["theta"], ts, theta_deg, attitude)
    if L is not None:
        _panel_L(ax["L"], ts, np.asarray(L, dtype=float).reshape(n, 3))
    _panel_current(ax["current"], ts, current, names)
    if rate is not None:
        nu = np.asarray(rate, dtype=float).reshape(n, -1) / (2.0 * math.pi)
        _panel_per_stator(ax["rate"], ts, np.where(current != 0.0, nu, np.nan), names,
                          "field rate ν/2π (Hz)\n± = direction", "no stator carries current")
        _panel_per_stator(ax["slip"], ts, s / (2.0 * math.pi) if s is not None else np.full_like(nu, np.nan),
                          names, "slip (ν − Ω·u)/2π (Hz)\nfield − rotor about u",
                          "no stator carries current" if s is not None else "stator axes unknown: no slip")
    _mark_changes(axes[1:], ev, scale)
    ax["current"].legend(handles=ax["current"].get_legend_handles_labels()[0] + _event_handles(ev),
                         loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    axes[-1].set_xlabel(f"time ({unit})")
    for a in axes[1:]:
        a.grid(True, alpha=0.3)
    axes[0].grid(True, axis="x", alpha=0.3)
    fig.suptitle(_run_title(result))
    if path is not None:
        save_png(fig, path)
    return fig


def _run_title(result) -> str:
    scene = getattr(result, "scene", None)
    title = getattr(scene, "name", None) or "gyro_sim run"
    desc = (getattr(scene, "description", None) or "").strip().split("\n")[0]
    return f"{title}: {desc}" if desc else title
