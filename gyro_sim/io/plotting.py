"""Plots of a simulation run: a ``matplotlib.figure.Figure`` on its own Agg canvas (no pyplot state, the
backend left as it is, never a window); saved as PNG when given a path.

``plot_run(result, path=None) -> Figure`` draws stacked panels on one time axis:

0. events: switching instants (a field reverses or a stator turns on/off) and command changes (``result.commands``);
1. rotor rate in rev/s: spin Ω_b3 (about the polar axis x3) and the magnitude |Ω| dashed;
2. nutation angle θ in degrees, on a log axis where it spans more than a factor 30 (the last 0.01° of a
   nutation damping stays visible) with the controller's dead band drawn (a run without attitude,
   ``result.attitude`` False, has none: the panel says so and the spin panel shows |Ω| alone);
3. kinetic moment (angular momentum) |L| and 4. its direction L/|L| (case frame components), when the
   result has ``L``;
5. the electrodynamic torque on the rotor, |N| and its case-frame components (when the result has ``torque``);
6. stator current amplitudes in A, one step line per stator, each in its own style;
7. field rate ν/2π in Hz (signed: the direction of rotation) and 8. slip (ν − Ω·u)/2π in Hz (field rate minus
   the rotor's rate about the stator axis u) of each stator while it carries current (when the result has
   ``field_rate``).

Command changes are also dashed vertical lines across the panels. L and N are shown in SI units with a
prefix (mN·m·s, µN·m) chosen from their size; no axis carries an offset or a ×10ⁿ label.

A series that reverses faster than the plot can resolve (a field rate, slip or torque under switching) is drawn as
its envelope: the minimum and maximum within each of ``ENVELOPE_BINS`` time bins, filled (not an aliased solid
band of line segments). Other long lines are thinned to at most ``MAX_POINTS`` points per line by keeping each
bucket's minimum and maximum, so peaks and envelopes survive the thinning.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["plot_run", "decimate_minmax", "slip", "command_events", "CommandEvents", "save_png", "new_figure",
           "si_scale", "plain_ticks", "MAX_POINTS", "ENVELOPE_BINS", "L_NAME"]

MAX_POINTS = 5000
#: time bins of an envelope (about the plot's width in pixels at 100 dpi)
ENVELOPE_BINS = 800
#: a series with more reversals than this is drawn as its envelope (:func:`_draw_series`)
ENVELOPE_REVERSALS = 20
#: the one name of L in plots, tables and documents
L_NAME = "kinetic moment (angular momentum)"
_PREFIXES = {-12: "p", -9: "n", -6: "µ", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}


def si_scale(values, unit: str) -> tuple[float, str]:
    """(factor, unit with an SI prefix) so that ``values * factor`` lies in [1, 1000) at its largest magnitude:
    ``si_scale([2e-6], "N·m") == (1e6, "µN·m")``. All-zero or non-finite values: (1, unit)."""
    v = np.asarray(values, dtype=float)
    v = np.abs(v[np.isfinite(v)])
    top = float(v.max()) if v.size else 0.0
    if top == 0.0:
        return 1.0, unit
    e = int(min(9, max(-12, 3 * math.floor(math.log10(top) / 3.0))))
    return 10.0 ** -e, _PREFIXES[e] + unit


def plain_ticks(ax) -> None:
    """No offset ("+2.864") and no ×10ⁿ label on the axes' linear scales: every tick label is its own value."""
    from matplotlib.ticker import ScalarFormatter

    for axis in (ax.xaxis, ax.yaxis):
        if isinstance(axis.get_major_formatter(), ScalarFormatter):
            fmt = ScalarFormatter(useOffset=False)
            fmt.set_powerlimits((-6, 9))  # (with units scaled by si_scale the values are 0.001 .. 1000)
            axis.set_major_formatter(fmt)


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


def _panel_theta(ax, ts, theta_deg, attitude, dead_band_deg=None):
    """θ (deg); a log axis where θ spans more than a factor 30 (θ → 0 under a nutation control), with the dead
    band of the controller (deg) as a dotted line."""
    if not attitude:
        ax.text(0.5, 0.5, "attitude not integrated (output.attitude: false)", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_ylabel("nutation θ (deg)\nx3 vs L", fontsize=9)
        return
    pos = theta_deg[np.isfinite(theta_deg) & (theta_deg > 0.0)]
    log = pos.size > 0 and float(pos.max()) > 30.0 * float(pos.min())
    if log:
        floor = max(float(pos.min()), float(pos.max()) * 1e-9)
        ax.set_yscale("log")
        ax.plot(*decimate_minmax(ts, np.maximum(theta_deg, floor)), color="C2", label="θ")
    else:
        ax.plot(*decimate_minmax(ts, theta_deg), color="C2", label="θ")
    if dead_band_deg is not None and dead_band_deg > 0.0 and (log or dead_band_deg >= 0.5 * float(
            np.nanmin(theta_deg) if np.isfinite(theta_deg).any() else 0.0)):
        ax.axhline(dead_band_deg, color="0.4", ls=":", lw=1.2, gid="dead_band",
                   label=f"dead band {dead_band_deg:.3g}°\n(control off below)")
        _legend(ax)
    ax.set_ylabel("nutation θ (deg)\nx3 vs L" + (", log" if log else ""), fontsize=9)


def _panel_L(ax, ts, L):
    """|L| in N·m·s with an SI prefix."""
    mag = np.linalg.norm(L, axis=1)
    f, unit = si_scale(mag, "N·m·s")
    ax.plot(*decimate_minmax(ts, mag * f), color="C0", label="|L|")
    ax.set_ylabel(f"{L_NAME.replace(' (', chr(10) + '(')}\n|L| ({unit})", fontsize=8)


def _panel_L_direction(ax, ts, L):
    """The direction of L: the case-frame components of L/|L| (NaN where L = 0)."""
    mag = np.linalg.norm(L, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(mag[:, None] > 0.0, L / mag[:, None], np.nan)
    for j in range(3):
        ax.plot(*decimate_minmax(ts, u[:, j]), **_stator_style(j), label=f"along z{j + 1}")  # zeros stay apart
    ax.set_ylim(-1.08, 1.08)
    ax.set_ylabel("direction of L\nL/|L|, case frame", fontsize=9)
    _legend(ax)


def _panel_torque(ax, ts, N):
    """The electrodynamic torque on the rotor: |N| and its case-frame components, SI prefix."""
    mag = np.linalg.norm(N, axis=1)
    f, unit = si_scale(mag, "N·m")
    for j in range(3):
        _draw_series(ax, ts, N[:, j] * f, steps=False, **_stator_style(j), label=f"N along z{j + 1}")
    _draw_series(ax, ts, mag * f, steps=False, color="k", lw=1.0, label="|N|")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_ylabel(f"torque on rotor\ncase frame ({unit})", fontsize=9)
    _legend(ax)


def _reversals(y) -> int:
    """How often the series turns (the sign of its change flips), NaN and flat stretches left out."""
    d = np.diff(np.asarray(y, dtype=float))
    d = d[np.isfinite(d) & (d != 0.0)]
    return int(np.count_nonzero(np.diff(np.sign(d)))) if d.size > 1 else 0


def _envelope(ts, y, bins: int = ENVELOPE_BINS):
    """(bin edges (bins + 1,), min (bins,), max (bins,)) of ``y`` over equal time bins (NaN where a bin is empty
    or all NaN)."""
    edges = np.linspace(float(ts[0]), float(ts[-1]), bins + 1)
    k = np.clip(np.searchsorted(edges, ts, side="right") - 1, 0, bins - 1)
    lo, hi = np.full(bins, np.inf), np.full(bins, -np.inf)
    ok = np.isfinite(y)
    np.minimum.at(lo, k[ok], y[ok])
    np.maximum.at(hi, k[ok], y[ok])
    lo[~np.isfinite(lo)], hi[~np.isfinite(hi)] = np.nan, np.nan
    return edges, lo, hi


def _draw_series(ax, ts, y, steps: bool = True, **style):
    """A line (a step line where ``steps``), or where it reverses more than ENVELOPE_REVERSALS times (switching
    faster than the plot resolves) its envelope: min..max per time bin, filled, with its edges (gid "envelope")."""
    if ts.size > 2 and _reversals(y) > ENVELOPE_REVERSALS:
        edges, lo, hi = _envelope(ts, y)
        color = style.get("color")
        label = style.get("label")
        x = np.repeat(edges, 2)[1:-1]
        ax.fill_between(x, np.repeat(lo, 2), np.repeat(hi, 2), color=color, alpha=0.25, lw=0, gid="envelope",
                        label=f"{label} (min–max per time bin)" if label else None)
        for edge in (lo, hi):
            ax.plot(x, np.repeat(edge, 2), color=color, lw=0.6, gid="envelope_edge")
        return
    ax.plot(*decimate_minmax(ts, y), **({"drawstyle": "steps-post"} if steps else {}), **style)


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
    """One step line per stator where ``values`` (n, k) is not all NaN (its envelope under fast switching:
    :func:`_draw_series`); ``empty`` said when none is."""
    drawn = 0
    for j in range(values.shape[1]):
        if np.all(np.isnan(values[:, j])):
            continue
        _draw_series(ax, ts, values[:, j], **_stator_style(j), label=_label(names, j))
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

    Panels on one time axis: rotor rate (rev/s: spin Ω₃ about the polar axis x3, |Ω|); nutation θ (deg; log
    scale where it spans more than a factor 30, with the controller's dead band); kinetic moment (angular
    momentum) |L| and the direction L/|L| (case frame; when ``result.L`` is given); the torque on the rotor
    (|N| and case-frame components; when ``result.torque`` is given); stator current amplitudes (A, one
    step line per stator, each in its own style so coinciding traces stay apart); field rate ν/2π (Hz,
    signed: the sign is the field's direction of rotation) and slip (ν − Ω·u)/2π (Hz, field rate minus the
    rotor's rate about the stator axis u, :func:`slip`) of each stator while it carries current. Command
    changes and switching instants (:func:`command_events`, from ``result.commands``) are marked on every
    panel. A series reversing faster than the plot resolves is drawn as its envelope (min..max per time bin);
    lines longer than ``MAX_POINTS`` are thinned with :func:`decimate_minmax`. No axis has an offset label.

    Args:
        result: the run: ``t`` (s), ``omega_b`` (rad/s, body frame), ``q``, ``euler`` (rad), ``current``
            (A), ``stator_names``, optionally ``L`` (N·m·s), ``torque`` (N·m), ``field_rate`` (rad/s),
            ``commands``, ``scene``.
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
    N = getattr(result, "torque", None)
    rate = getattr(result, "field_rate", None)
    s = slip(result)
    ev = command_events(result)

    kinds = ["events", "spin", "theta"] + (["L", "Ldir"] if L is not None else []) \
        + (["torque"] if N is not None else []) + ["current"] \
        + (["rate"] if rate is not None else []) + (["slip"] if rate is not None else [])
    fig = new_figure((12.5, 1.6 * (len(kinds) - 1) + 1.4))
    axes = fig.subplots(len(kinds), 1, sharex=True, height_ratios=[0.22] + [1.0] * (len(kinds) - 1))
    ax = dict(zip(kinds, axes))
    _panel_events(ax["events"], ev, scale)
    _panel_spin(ax["spin"], ts, omega, attitude)
    _panel_theta(ax["theta"], ts, theta_deg, attitude, _dead_band_deg(result))
    if L is not None:
        L = np.asarray(L, dtype=float).reshape(n, 3)
        _panel_L(ax["L"], ts, L)
        _panel_L_direction(ax["Ldir"], ts, L)
    if N is not None:
        _panel_torque(ax["torque"], ts, np.asarray(N, dtype=float).reshape(n, 3))
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
        plain_ticks(a)
    axes[0].grid(True, axis="x", alpha=0.3)
    fig.suptitle(_run_title(result))
    if path is not None:
        save_png(fig, path)
    return fig


def _dead_band_deg(result):
    """The ψ-switching controller's dead band (deg) of the result's scene, or None."""
    ctl = getattr(getattr(result, "scene", None), "controller", None)
    band = getattr(getattr(ctl, "params", None), "dead_band", None)
    return math.degrees(float(band)) if isinstance(band, (int, float)) else None


def _run_title(result) -> str:
    scene = getattr(result, "scene", None)
    title = getattr(scene, "name", None) or "gyro_sim run"
    desc = (getattr(scene, "description", None) or "").strip().split("\n")[0]
    return f"{title}: {desc}" if desc else title
