"""The plots of a sweep's results (:mod:`gyro_sim.apps.sweep`): :func:`plot_sweep`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from gyro_sim.apps.sweep_axes import _is_number
from gyro_sim.apps.sweep_metrics import metric_unit

#: units of scene keys by their last part (a varied key's axis label); others are shown without one
KEY_UNITS = {"period": "s", "duration": "s", "time": "s", "start": "s", "end": "s", "max_step": "s",
             "current": "A", "control_current": "A", "spin_current": "A", "max_current": "A",
             "rate": "rad/s", "spin_rate": "rad/s", "nu": "rad/s", "max_rate": "rad/s", "spin": "rad/s",
             "theta": "rad", "phi": "rad", "psi": "rad", "dead_band": "rad", "phase": "rad",
             "kinetic_moment": "N·m·s", "inertia": "kg·m²", "conductivity": "S/m", "outer_radius": "m",
             "thickness": "m", "coil_constant": "T/A", "frequency": "rad/s", "mass": "kg", "radius": "m",
             "stiffness": "N/m", "damping": "N·s/m"}


def key_unit(key: str) -> str:
    """The unit of a dotted scene key (``controller.period`` → "s"), "" where unknown."""
    return KEY_UNITS.get(str(key).split(".")[-1], "")


def _with_unit(text: str, unit: str) -> str:
    return f"{text} ({unit})" if unit and unit != "1" else (f"{text} (ratio)" if unit == "1" else text)


def _draw_marks(ax, marks, name: str, xkey_unit: str) -> bool:
    """The theory's values (the sweep's ``marks``) on one 1-D panel: x marks as vertical lines, y marks of this
    metric as horizontal ones; True where one was drawn."""
    drawn = False
    for k, m in enumerate(marks or []):
        style = dict(color=f"C{3 + k}", ls="--", lw=1.2, gid="mark")
        if "x" in m:
            ax.axvline(m["x"], **style, label=f"{m['label']} ({m['x']:.3g}{' ' + xkey_unit if xkey_unit else ''})")
            drawn = True
        elif m.get("metric") == name:
            ax.axhline(m["y"], **style, label=f"{m['label']} ({m['y']:.3g})")
            drawn = True
    return drawn


# ------------------------------------------------------------------------------------------
# plots
# ------------------------------------------------------------------------------------------
def _xval(v):
    if isinstance(v, list):
        return float(v[0]) if v else math.nan
    return float(v) if _is_number(v) else math.nan


def plot_sweep(rows: list, meta: dict, path: str | Path | None = None, metrics: Optional[Sequence[str]] = None):
    """One figure, a panel per metric: a metric against the one grid key (runs as points, the median over
    Monte Carlo samples as a line), a 2-D map over the first two grid keys (mean over the rest), or
    histograms for a random-only sweep. Runs that never reached a level (inf) are ▲ at the top; failed
    or invalid variants are red × (1-D or 2-D cells). Axes carry the units of the keys (:data:`KEY_UNITS`) and
    metrics (:func:`gyro_sim.apps.sweep_metrics.metric_unit`); the sweep's ``marks`` (the theory's values, e.g.
    h* = π/Λ) are dashed lines on the 1-D panels.

    Args:
        rows: the result rows (:func:`read_results`); meta: the sweep's metadata (grid, random, metrics).
        path: if given, the figure is also written there as PNG (atomically; parent folders are made).
        metrics: the metric names to draw (default: every metric of ``meta``, at most 8).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state; the backend is left as it is)."""
    import matplotlib
    import matplotlib.transforms

    from gyro_sim.io.plotting import new_figure, save_png
    names = list(metrics or list(meta.get("metrics", {})))[:8]
    grid = list(meta.get("grid", []))
    rnd = list(meta.get("random", {}))
    n = max(1, len(names))
    ncol = 1 if n == 1 else 2
    nrow = math.ceil(n / ncol)
    fig = new_figure((6.4 * ncol, 4.0 * nrow), layout="tight")
    axes = fig.subplots(nrow, ncol, squeeze=False)
    title = f"sweep {meta.get('name', '')}: {len(rows)} runs"
    nf = sum(1 for r in rows if r["status"] != "ok")
    if nf:
        title += f", {nf} failed"
    fig.suptitle(title)
    ok = [r for r in rows if r["status"] == "ok"]
    bad = [r for r in rows if r["status"] != "ok"]
    for i, name in enumerate(names):
        ax = axes[i // ncol][i % ncol]
        expr = meta.get("metrics", {}).get(name, "")
        unit = metric_unit(expr) if expr else ""
        ax.set_title(f"{name} = {expr}" if expr else name, fontsize=9)
        if not grid:
            vals = np.array([r.get(name, math.nan) for r in ok], dtype=float)
            fin = vals[np.isfinite(vals)]
            if fin.size:
                ax.hist(fin, bins=max(5, min(40, int(math.sqrt(fin.size)) * 2)), color="C0", alpha=0.8)
            ninf = int(np.sum(np.isinf(vals)))
            ax.set_xlabel(_with_unit(name, unit) + (f"   ({ninf} never / inf)" if ninf else ""))
            ax.set_ylabel("runs")
            if rnd:
                ax.text(0.99, 0.97, f"{len(ok)} samples of {', '.join(rnd)}", transform=ax.transAxes, ha="right",
                        va="top", fontsize=8)
        elif len(grid) == 1:
            key = grid[0]
            xs = np.array([_xval(r.get(key)) for r in ok])
            ys = np.array([r.get(name, math.nan) for r in ok], dtype=float)
            fin = np.isfinite(ys)
            ax.plot(xs[fin], ys[fin], "o" if rnd else "o-", ms=4, alpha=0.6 if rnd else 1.0, color="C0", label="runs")
            if rnd and fin.any():
                ux = np.unique(xs[~np.isnan(ys)])
                med = np.array([np.median(ys[(xs == u) & ~np.isnan(ys)]) for u in ux])
                ax.plot(ux, np.where(np.isfinite(med), med, np.nan), "-", color="C1", label="median over samples")
            if np.any(np.isinf(ys)):
                tr = matplotlib.transforms.blended_transform_factory(ax.transData, ax.transAxes)
                ax.plot(xs[np.isinf(ys)], np.full(int(np.sum(np.isinf(ys))), 0.97), "^", color="C3", transform=tr,
                        label="never (inf)")
            if bad:
                tr = matplotlib.transforms.blended_transform_factory(ax.transData, ax.transAxes)
                bx = np.array([_xval(r.get(key)) for r in bad])
                ax.plot(bx, np.full(bx.size, 0.03), "x", color="red", transform=tr, label="failed / invalid")
            vec = any(isinstance(r.get(key), list) for r in rows)
            ax.set_xlabel(_with_unit(key + ("[0]" if vec else ""), key_unit(key)))
            ax.set_ylabel(_with_unit(name, unit))
            ax.grid(alpha=0.3)
            marked = _draw_marks(ax, meta.get("marks"), name, key_unit(key))
            if rnd or bad or marked or np.any(np.isinf(ys)):
                ax.legend(fontsize=7)
        else:
            kx, ky = grid[0], grid[1]
            xv = sorted({_xval(r.get(kx)) for r in rows})
            yv = sorted({_xval(r.get(ky)) for r in rows})
            Z = np.full((len(yv), len(xv)), math.nan)
            S = np.zeros_like(Z)
            C = np.zeros_like(Z)
            INF = np.zeros_like(Z)
            for r in ok:
                v = float(r.get(name, math.nan))
                a, b = yv.index(_xval(r.get(ky))), xv.index(_xval(r.get(kx)))
                if math.isfinite(v):
                    S[a, b] += v
                    C[a, b] += 1
                elif math.isinf(v):
                    INF[a, b] += 1
            with np.errstate(invalid="ignore", divide="ignore"):
                Z = np.where(C > 0, S / np.maximum(C, 1), math.nan)
            cmap = matplotlib.colormaps["viridis"]  # the registry: no pyplot
            cmap = cmap.with_extremes(bad="0.85") if hasattr(cmap, "with_extremes") else cmap
            im = ax.imshow(np.ma.masked_invalid(Z), origin="lower", aspect="auto", cmap=cmap, interpolation="nearest")
            fig.colorbar(im, ax=ax, label=_with_unit(name, unit))
            for a in range(len(yv)):
                for b in range(len(xv)):
                    if C[a, b] == 0 and INF[a, b] > 0:
                        ax.text(b, a, "∞", ha="center", va="center", fontsize=8, color="C3")
            for r in bad:
                ax.plot(xv.index(_xval(r.get(kx))), yv.index(_xval(r.get(ky))), "x", color="red")
            step_x, step_y = max(1, len(xv) // 8), max(1, len(yv) // 8)
            ax.set_xticks(range(0, len(xv), step_x), [f"{v:.3g}" for v in xv[::step_x]], fontsize=7)
            ax.set_yticks(range(0, len(yv), step_y), [f"{v:.3g}" for v in yv[::step_y]], fontsize=7)
            ax.set_xlabel(_with_unit(kx, key_unit(kx)))
            ax.set_ylabel(_with_unit(ky, key_unit(ky)))
    for j in range(len(names), nrow * ncol):
        axes[j // ncol][j % ncol].set_visible(False)
    if path is not None:
        save_png(fig, path, dpi=110)
    return fig
