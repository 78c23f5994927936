"""(θ, φ) phase portrait of a run over the averaged ψ-switching model of [K] §3 (a matplotlib Figure, Agg canvas).

``plot_phase(result_or_bag_data, path=None, scene=None) -> Figure`` (saved as PNG when given a path) draws

* left: the run's trajectory in the (φ, θ) plane (θ = ``euler[:, 1]``, φ = ``euler[:, 2]``, in degrees;
  φ wrapped to [0°, 180°): (3.4) depends on φ only through sin 2φ, cos 2φ), coloured by time, over the
  analytic portrait of :class:`gyro_sim.averaged.PsiSwitchingK` for the scene: streamlines of (3.4) on the
  ellipsoid (3.5) (|L| = J Λ0/(1 + κ sin²θ)), the equilibria at θ = π/2 of (3.6)–(3.7) marked by type
  (stable/unstable focus, saddle) and the limit cycles r⁺, r₋ of (3.9)–(3.10) (θ = const of the φ-averaged
  system (3.8); for δ ≠ 0 the cycles of (3.4) lie near these lines);
* right: θ against |L|/(J Λ0) (= [K]'s k/ω) with the ellipsoid (3.5), k/ω = 1/(1 + κ sin²θ), and the same
  equilibria and cycles.

``phi_convention="K"`` draws [K]'s φ_K = φ + 90° instead of the simulator's φ (docs/averaged_k.md §2).

For a scene the model does not describe (no ψ-switching controller, no eddy-current torque, no control
or spin field, an isotropic rotor…) the trajectory is drawn alone and the title says why
(:func:`portrait_model` gives the reason). The model is the quasi-static one; for a scene with the lag
torque model the curves are drawn but marked as indicative only.
"""
from __future__ import annotations

import math
import textwrap
from typing import Optional

import numpy as np

from gyro_sim.io.plotting import new_figure, save_png

__all__ = ["plot_phase", "portrait_model", "MAX_POINTS"]

MAX_POINTS = 20000  # trajectory points drawn (uniform stride beyond this)

_KIND_STYLE = {  # marker, face colour, edge colour, legend label (plain words; the type in parentheses)
    "stable focus": ("o", "tab:green", "darkgreen", "stable equilibrium (focus): the motion spirals in"),
    "unstable focus": ("o", "none", "tab:red", "unstable equilibrium (focus): spirals out"),
    "stable node": ("s", "tab:green", "darkgreen", "stable equilibrium (node)"),
    "unstable node": ("s", "none", "tab:red", "unstable equilibrium (node)"),
    "saddle": ("X", "tab:orange", "saddlebrown", "unstable equilibrium (saddle)"),
    "center": ("o", "none", "tab:blue", "neutral equilibrium (centre)"),
    "degenerate": ("o", "none", "gray", "equilibrium (degenerate)"),
}


def _scene_of(data, scene):
    """The scene: the argument, else ``data.scene`` (a RunResult), else the bag's embedded scene text."""
    if scene is not None:
        return scene
    sc = getattr(data, "scene", None)
    if sc is not None and hasattr(sc, "rotor"):
        return sc
    text = getattr(data, "scene_text", None)
    if text:
        try:
            from gyro_sim.scenes.scene import parse_scene_text, scene_from_dict

            return scene_from_dict(parse_scene_text(text, "(embedded scene)"), where="(embedded scene)")
        except Exception:  # noqa: BLE001 - a bag with an unreadable scene: trajectory only
            return None
    return None


def portrait_model(scene):
    """The averaged ψ-switching model of ``scene`` (``PsiSwitchingK.of_scene``) and a note, or None and why not.

    Returns ``(model, note)``: ``model`` is None when (3.4) does not describe the scene, and ``note`` then
    says why; otherwise ``note`` is '' or a caveat (lag torque model).
    """
    if scene is None or not hasattr(scene, "rotor"):
        return None, "no scene to build the averaged model from"
    ctl = getattr(scene, "controller", None)
    if ctl is None:
        return None, "no controller (the averaged model (3.4) is for the ψ-switching law)"
    if ctl.law != "psi_switching":
        return None, f"controller law {ctl.law!r}, not psi_switching"
    if scene.torque_model == "none" or scene.rotor.conductor is None:
        return None, "no eddy-current torque (torque_model none or no conductor)"
    p = ctl.params
    if not p.control_stators:
        return None, "no control stators"
    if p.control_current == 0.0 or all(p.rate(i) == 0.0 for i in range(len(p.control_stators))):
        return None, "control fields off (control current or ν = 0)"
    if p.spin_current == 0.0 or p.spin_rate == 0.0:
        return None, "spin stator off (no ellipsoid (3.5): |L| has no stationary value)"
    J = np.asarray(scene.rotor.inertia, dtype=float)
    if np.ptp(J) <= 1e-12 * np.max(J):
        return None, "isotropic rotor (κ = δ = 0): every axis is principal, θ and φ have no dynamics of their own"
    try:
        from gyro_sim.averaging.averaged import PsiSwitchingK

        m = PsiSwitchingK.of_scene(scene)
    except Exception as exc:  # noqa: BLE001 - any scene the model cannot take: say so in the title
        return None, f"averaged model not available ({exc})"
    if not (m.W0 > 0 and math.isfinite(m.Lam0) and m.Lam0 != 0.0):
        return None, "averaged model degenerate (W0 = 0)"
    note = "lag torque: curves of the quasi-static model, indicative only" if scene.torque_model == "lag" else ""
    return m, note


def _wrap_phi(phi_rad, convention: str):
    off = 0.5 * math.pi if convention == "K" else 0.0
    return np.degrees(np.mod(np.asarray(phi_rad, dtype=float) + off, math.pi))


def _colored_line(ax, x, y, t, cmap, norm, jump: Optional[float] = None, lw=1.2):
    """Draw y(x) coloured by t; segments jumping more than ``jump`` in x (a φ wrap) are dropped."""
    from matplotlib.collections import LineCollection

    pts = np.column_stack([x, y])
    seg = np.stack([pts[:-1], pts[1:]], axis=1)
    ok = np.all(np.isfinite(seg.reshape(len(seg), 4)), axis=1)
    if jump is not None:
        ok &= np.abs(np.diff(x)) < jump
    lc = LineCollection(seg[ok], cmap=cmap, norm=norm, linewidths=lw, zorder=3)
    lc.set_array(0.5 * (t[:-1] + t[1:])[ok])
    ax.add_collection(lc)
    return lc


def plot_phase(result_or_bag_data, path=None, scene=None, phi_convention: str = "sim"):
    """The (θ, φ) phase portrait of a run over the analytic curves of [K] §3, as a matplotlib Figure.

    Left: nutation θ (deg, polar axis x3 vs L) against the rotation angle φ about the polar axis (deg, mod
    180°); right: θ against |L| / L₀ (L₀ = J Λ0, N·m·s). The legend names every curve and marker in plain
    words ([K]'s equation numbers in the module docstring); the title gives the scene and the model's
    parameters (rotor shape, whether equilibria and limit cycles exist and why).

    Args:
        result_or_bag_data: a ``RunResult`` or ``BagData`` (or anything with ``t`` s, ``euler`` (n,3)
            ψ, θ, φ rad and ``L`` (n,3) N·m·s).
        path: if given, the figure is also written there as PNG (atomically; parent folders are made).
        scene: the run's :class:`~gyro_sim.scene.Scene`; default ``result.scene`` or the bag's embedded scene.
        phi_convention: ``"sim"`` (the simulator's φ, default) or ``"K"`` ([K]'s φ_K = φ + π/2).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state: restyle it, save it again).
    """
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    if phi_convention not in ("sim", "K"):
        raise ValueError(f"phi_convention = {phi_convention!r}: 'sim' or 'K'")
    data = result_or_bag_data
    t = np.asarray(data.t, dtype=float).ravel()
    n = t.size
    eul = np.asarray(data.euler, dtype=float).reshape(n, 3)
    Lv = getattr(data, "L", None)
    Lmag = np.linalg.norm(np.asarray(Lv, dtype=float).reshape(n, 3), axis=1) if Lv is not None else np.full(n, np.nan)
    if n > MAX_POINTS:
        idx = np.unique(np.concatenate([np.arange(0, n, int(math.ceil(n / MAX_POINTS))), [n - 1]]))
        t, eul, Lmag = t[idx], eul[idx], Lmag[idx]
    th = np.degrees(eul[:, 1])
    ph = _wrap_phi(eul[:, 2], phi_convention)

    sc = _scene_of(data, scene)
    name = getattr(sc, "name", None) or getattr(getattr(data, "scene", None), "name", None) \
        or getattr(data, "scene_name", None) or "gyro_sim run"
    model, note = portrait_model(sc)

    fig = new_figure((13.0, 8.5))
    ax, axL = fig.subplots(1, 2, sharey=True, width_ratios=[1.6, 1.0])
    cmap = colormaps["viridis"]
    norm = Normalize(vmin=float(t[0]) if n else 0.0, vmax=float(t[-1]) if n and t[-1] > t[0] else 1.0)

    # --- θ window: the trajectory, the equilibria and the cycles; all of [0°, 180°] if they span most of it
    fin = list(th[np.isfinite(th)])
    if model is not None:
        fin += [90.0] if model.equilibria() else []
        fin += [math.degrees(c.theta) for c in model.limit_cycles()]
    fin = np.asarray(fin, dtype=float)
    if fin.size and np.ptp(fin) < 120.0:
        pad = max(3.0, 0.1 * float(np.ptp(fin)))
        ylo, yhi = max(0.0, float(fin.min()) - pad), min(180.0, float(fin.max()) + pad)
    else:
        ylo, yhi = 0.0, 180.0

    legend = []
    Lscale, xlab = 1.0, "kinetic moment |L| (N·m·s)"
    if model is not None:
        J = model.rotor.J
        Lscale = J * model.Lam0
        xlab = (f"kinetic moment |L| / L₀\n(L₀ = J·Λ0 = {Lscale:.4g} N·m·s, the steady |L| at θ = 0; [K]'s k/ω)")
        # streamlines of (3.4) on the ellipsoid (3.5)
        gx = np.linspace(0.0, 180.0, 61)
        gy = np.linspace(max(ylo, 0.3), min(yhi, 179.7), 61)
        U = np.zeros((gy.size, gx.size))
        Vv = np.zeros_like(U)
        off = 0.5 * math.pi if phi_convention == "K" else 0.0
        for i, y in enumerate(np.radians(gy)):
            Le = float(model.ellipsoid_L(y))
            for j, x in enumerate(np.radians(gx)):
                d = model.rhs_reduced(0.0, [Le, y, x - off])
                U[i, j], Vv[i, j] = d[2], d[1]
        sp = np.hypot(U, Vv)
        with np.errstate(invalid="ignore", divide="ignore"):
            U, Vv = np.where(sp > 0, U / sp, 0.0), np.where(sp > 0, Vv / sp, 0.0)  # directions only
        ax.streamplot(gx, gy, U, Vv, density=1.1, color="0.78", linewidth=0.6, arrowsize=0.7, zorder=1)
        legend.append(Line2D([], [], color="0.7", lw=0.8, marker=">", markersize=4,
                             label="averaged motion at steady |L| (arrows: its direction)"))
        # ellipsoid (3.5) in the right panel
        tt = np.linspace(0.0, math.pi, 361)
        axL.plot(model.ellipsoid_L(tt) / Lscale, np.degrees(tt), color="0.35", lw=1.2, zorder=2,
                 label="steady |L| for each θ (spin drive = braking)")
        # equilibria (3.6)–(3.7)
        eqs = model.equilibria()
        seen = set()
        for e in eqs:
            x = float(_wrap_phi(e.phi, phi_convention))
            key = (round(x, 6), e.kind)
            if key in seen:
                continue
            seen.add(key)
            mk, fc, ec, lab = _KIND_STYLE.get(e.kind, ("o", "none", "k", e.kind))
            ax.plot([x], [90.0], linestyle="none", marker=mk, markersize=11, markerfacecolor=fc,
                    markeredgecolor=ec, markeredgewidth=2, zorder=5)
        if eqs:  # all equilibria share (k*, 90°) = (ω/(1+κ), 90°) in the right panel
            axL.plot([eqs[0].L / Lscale], [90.0], linestyle="none", marker="P", markersize=12, color="k",
                     markeredgecolor="w", zorder=5, label="the equilibria (at θ = 90°)")
        for e in eqs:
            mk, fc, ec, lab = _KIND_STYLE.get(e.kind, ("o", "none", "k", e.kind))
            if lab not in [h.get_label() for h in legend]:
                legend.append(Line2D([], [], linestyle="none", marker=mk, markersize=9, markerfacecolor=fc,
                                     markeredgecolor=ec, markeredgewidth=2, label=lab))
        # limit cycles (3.9)–(3.10)
        for c in model.limit_cycles():
            ls = "-" if c.stable else "--"
            col = "tab:purple" if c.name == "r+" else "tab:brown"
            lab = f"{'stable' if c.stable else 'unstable'} limit cycle {'r⁺' if c.name == 'r+' else 'r₋'}: " \
                  f"θ stays at {math.degrees(c.theta):.1f}° while φ turns"
            ax.axhline(math.degrees(c.theta), color=col, ls=ls, lw=1.8, zorder=4)
            axL.plot([c.L / Lscale], [math.degrees(c.theta)], marker="D", color=col, markersize=8,
                     markerfacecolor=col if c.stable else "none", linestyle="none", zorder=5,
                     label=f"limit cycle {'r⁺' if c.name == 'r+' else 'r₋'} ({'stable' if c.stable else 'unstable'})")
            legend.append(Line2D([], [], color=col, ls=ls, lw=1.6, label=lab))
        title = _title(name, getattr(sc, "description", None), model, bool(eqs), note)
        legend += [Line2D([], [], ls="none", label=text) for text in _symbols(model, bool(eqs), note)]
    else:
        title = _title(name, getattr(sc, "description", None), None, False, note)

    # --- the run
    if n:
        lc = _colored_line(ax, ph, th, t, cmap, norm, jump=90.0)
        _colored_line(axL, Lmag / Lscale, th, t, cmap, norm)
        for a, xs in ((ax, ph), (axL, Lmag / Lscale)):
            a.plot([xs[0]], [th[0]], marker="s", color=cmap(0.0), markeredgecolor="k", markersize=8,
                   linestyle="none", zorder=6)
            a.plot([xs[-1]], [th[-1]], marker="*", color=cmap(1.0), markeredgecolor="k", markersize=13,
                   linestyle="none", zorder=6)
        legend.append(Line2D([], [], marker="s", color=cmap(0.0), markeredgecolor="k", linestyle="none",
                             label=f"run start (t = {t[0]:.3g} s)"))
        legend.append(Line2D([], [], marker="*", color=cmap(1.0), markeredgecolor="k", markersize=11,
                             linestyle="none", label=f"run end (t = {t[-1]:.3g} s)"))
        cb = fig.colorbar(lc, ax=[ax, axL], shrink=0.9, pad=0.01)
        cb.set_label("time t (s): colour of the run's trajectory")
    else:
        ax.text(0.5, 0.5, "no samples", ha="center", va="center", transform=ax.transAxes)

    conv = "drawn as [K]'s φ_K = φ + 90°" if phi_convention == "K" else "the simulator's φ ([K]'s φ_K = φ + 90°)"
    ax.set_xlim(0.0, 180.0)
    ax.set_xticks(np.arange(0, 181, 30))
    ax.set_ylim(ylo, yhi)
    ax.set_xlabel(f"rotation angle φ of the rotor about its polar axis x3, mod 180° (deg)\n{conv}")
    ax.set_ylabel("nutation θ (deg): angle between the polar axis x3 and L")
    axL.set_xlabel(xlab)
    xs = Lmag[np.isfinite(Lmag)] / Lscale
    if model is not None:  # the ellipsoid over the θ window, the equilibria and cycles inside it
        tw = np.radians(np.linspace(ylo, yhi, 91))
        feats = [model.ellipsoid_L(tw) / Lscale]
        feats += [[c.L / Lscale] for c in model.limit_cycles() if ylo <= math.degrees(c.theta) <= yhi]
        ref = np.concatenate([xs] + [np.atleast_1d(np.asarray(f, dtype=float)) for f in feats])
    else:
        ref = xs
    if ref.size:
        lo, hi = float(ref.min()), float(ref.max())
        pad = 0.08 * (hi - lo) if hi > lo else 0.05 * max(abs(hi), 1e-30)
        axL.set_xlim(lo - pad, hi + pad)
    for a in (ax, axL):
        a.grid(True, alpha=0.3)
    handles = legend + [h for h in axL.get_legend_handles_labels()[0]]
    for h in handles:  # (two columns fit the figure's width)
        h.set_label("\n".join(textwrap.wrap(h.get_label().replace("\n", " "), 88)))
    if handles:  # one legend under both panels: it hides no trajectory
        fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)

    if path is not None:
        save_png(fig, path)
    return fig


def _shape_words(model) -> str:
    """The rotor's inertia in words: prolate/oblate (κ), transverse asymmetry (δ)."""
    k, d = model.kappa, model.rotor.delta
    shape = "oblate" if k > 0 else ("prolate" if k < 0 else "spherical inertia")
    asym = "axisymmetric (J1 = J2, δ = 0)" if d == 0 else f"δ = (J2 − J1)/(J2 + J1) = {d:+.3g}: transverse asymmetry"
    return f"rotor {shape}: polar / transverse inertia J3/J = {1 + k:.3g} (κ = J3/J − 1 = {k:+.3g}); {asym}"


def _equilibria_words(model, has_eq: bool) -> str:
    """Why the equilibria at θ = 90° exist or not: s = switching torque / asymmetry torque at θ = 90°."""
    s = model.s
    if not math.isfinite(s):
        return "no equilibria: an axisymmetric rotor (δ = 0) has no preferred φ"
    if has_eq:
        return (f"equilibria at θ = 90°: switching torque < asymmetry torque (|s| = {abs(s):.3g} ≤ 1; s = switching "
                "/ asymmetry torque)")
    return (f"no equilibria: switching torque > asymmetry torque (|s| = {abs(s):.3g} > 1; s = switching / asymmetry "
            "torque)")


def _cycles_words(model) -> str:
    """Why the limit cycles exist or not: p = switching torque / the polar-inertia (κ) torque."""
    p = model.p
    if not math.isfinite(p):
        return "no limit cycles: no polar-inertia torque (κ = 0)"
    if model.cycles_exist():
        return (f"limit cycles: polar-inertia torque balances the switching (p² = {p * p:.3g} ≤ p*² = "
                f"{model.p_star_sq:.3g}; p = switching / polar-inertia torque)")
    return (f"no limit cycles: switching torque > polar-inertia torque (p² = {p * p:.3g} > p*² = "
            f"{model.p_star_sq:.3g}; p = switching / polar-inertia torque)")


def _symbols(model, has_eq: bool, note: str) -> list:
    """Legend lines defining [K]'s symbols for this rotor and what they predict, in plain words."""
    lines = ["How to read: x3 is the rotor's symmetry (polar) axis, L its kinetic moment (angular momentum); "
             "θ = 0 means\nx3 along L (no nutation). Grey arrows: where the averaged motion goes; the run is the "
             "coloured line.",
             f"Λ0 = {model.Lam0:.4g} rad/s: the precession rate |L|/J the spin drive holds at θ = 0 (J: transverse "
             "inertia)",
             _shape_words(model)]
    lines.append(_equilibria_words(model, has_eq))
    lines.append(_cycles_words(model))
    if note:
        lines.append(f"({note})")
    return lines


def _title(name, description, model, has_eq: bool, note: str) -> str:
    """Two lines: the scene, then what the figure is (the symbols and predictions are in the legend)."""
    head = f"{name}: {description}" if description else name
    if model is None:
        return f"{head}\ntrajectory only: {note}"
    return (f"{head}\nphase portrait: nutation θ against the rotation angle φ and |L| under ψ-switching, over the "
            "averaged model of [K] §3 (symbols in the legend)")
