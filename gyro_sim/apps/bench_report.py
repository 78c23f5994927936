"""The benchmark's report: the headline, the tables (Markdown, CSV) and the work-precision plot of a
:class:`~gyro_sim.apps.bench_core.Results` (``gyro-sim bench`` writes them to ``--out``).
"""
from __future__ import annotations

import csv
import math
import os
import platform
from pathlib import Path

import numpy as np

from gyro_sim.apps.bench_core import (BASELINES, OURS, RK4_METHOD, TARGET_ERROR, Results, _faster, _method_label,
                                      _table, is_baseline)


def _fmt(x, spec: str = ".3g") -> str:
    if x is None:
        return "–"
    if isinstance(x, float) and not math.isfinite(x):
        return "–"
    return format(x, spec)


def headline_lines(res: Results) -> list[str]:
    """The headline ratios, one sentence each (printed and at the top of bench.md).

    Costs are CPU seconds of this process (``time.process_time``); the wall-clock ratio follows in
    brackets. Both come from the same runs.
    """
    lines = both_ratios_lines(res)
    full = _method_label("full")
    for h in res.headline:
        if is_baseline(h["method"]):
            flat = (f"; every {h['method']} setting is below {TARGET_ERROR:.0e}: its cheapest run"
                    + (", its step being set by stability" if h["method"].startswith("solve_ivp") else "")
                    ) if h.get("flat") else ""
            ours = _ours(res, h)
            lines.append(f"{h['scene']} ({h['horizon']:g} s): at error {TARGET_ERROR:.0e}, {full} is "
                         f"{_faster(h['speedup'])} {h['method']} (CPU {_fmt(ours.get('cpu'), '.3g')} s "
                         f"vs {_fmt(h['cpu'], '.3g')} s; wall-clock ratio {_fmt(h['speedup_wall'], '.3g')}x); "
                         f"{h['method']} makes {_fmt(h['rhs_ratio'], '.2f')}x our RHS evaluations{flat}")
        elif h.get("whole"):
            reach = (f"costs {_fmt(h['cpu'], '.3g')} CPU s, {_fmt(h['horizon'] / h['cpu'], '.3g')} simulated s "
                     f"per CPU s" if math.isfinite(h["cpu"]) else
                     f"is out of reach (best {_fmt(h['best'], '.1e')})")
            lines.append(f"{h['scene']} (whole {h['horizon']:g} s, no controller): {h['method']} at error "
                         f"{TARGET_ERROR:.0e} {reach}; at |ΔL|/|L| = {TARGET_ERROR:.0e} alone: "
                         f"{_fmt(h['cpu_L'], '.3g')} CPU s")
        elif h["method"] != full:
            lines.append(f"{h['scene']} ({h['horizon']:g} s): at error {TARGET_ERROR:.0e}, {h['method']} costs "
                         f"{_fmt(h['speedup'], '.3g')}x the CPU time of {full}")
    for meth in dict.fromkeys(m["method"] for m in res.modes if m["method"].startswith(OURS)):
        byn = {m["modes"]: m for m in res.modes if m["method"] == meth}
        ns = sorted(byn)
        if len(ns) >= 2:
            a, b = byn[ns[0]], byn[ns[-1]]
            lines.append(f"{res.config.mode_scene}: {ns[-1]} modes cost {b['cpu'] / a['cpu']:.2f}x {ns[0]} mode "
                         f"with {meth} (same {a['steps']} steps over {a['horizon']:g} s: {b['steps'] == a['steps']}; "
                         f"wall-clock ratio {b['wall'] / a['wall']:.2f}x)")
    for m in res.config.baselines:
        bb = {x["modes"]: x for x in res.modes if x["method"] == f"solve_ivp {m}"}
        if len(bb) >= 2:
            a, b = bb[min(bb)], bb[max(bb)]
            lines.append(f"{res.config.mode_scene}: solve_ivp {m} rtol=1e-6: {max(bb)} modes cost "
                         f"{b['cpu'] / a['cpu']:.0f}x {min(bb)} mode ({b['steps']} vs {a['steps']} steps "
                         f"over {a['horizon']:g} s)")
    for r in res.rtf:
        avg = (f", {r['averaged']:.3g} s averaged, |ΔL|/|L| = {r['error_L']:.1e} vs full"
               if r.get("averaged") else "")
        lines.append(f"{r['scene']} ({r['duration']:g} s, {r['what']}), {r['method']}: real-time factor "
                     f"{r['rtf']:.1f} (wall {r['wall']:.3g} s; {r['rtf_cpu']:.1f} per CPU second; "
                     f"{r['steps']} steps{avg})")
    for s in res.spinup:
        avg = f", {s['averaged']:.0f} s averaged" if s.get("averaged") else ""
        lines.append(f"spin-up {s['duration']:g} s, {s['method']} {s['setting']}: real-time factor {s['rtf']:.3g} "
                     f"(wall {s['wall']:.3g} s, CPU {s['cpu']:.3g} s{avg}), error of L {_fmt(s['error_L'], '.1e')}, attitude "
                     f"≈ {_fmt(s['error'], '.1e')} rad (estimate), spin {s['spin_rev_s']:.1f} rev/s "
                     f"({100 * s['spin_fraction']:.2f} % of the field rate)")
    from gyro_sim.apps.bench_ros import headline as ros_headline
    from gyro_sim.apps.bench_scaling import headline as scaling_headline

    return lines + ros_headline(res) + scaling_headline(res)


def speedup_table(res: Results) -> list[dict]:
    """Per compared scene and horizon: our cost at the target error and each baseline's ratio to it.

    Dicts: scene, horizon, ours (CPU s of ``gyro_sim full``), and per baseline method its CPU s (``cost``) and
    the ratio theirs / ours (``ratio``; > 1: ours is faster) under ``baselines``."""
    out = []
    for h in res.headline:
        if h["method"] != _method_label("full") or h.get("whole"):
            continue
        bl = {x["method"]: {"cost": x["cpu"], "ratio": x["speedup"], "flat": x.get("flat")}
              for x in res.headline if x["scene"] == h["scene"] and x["horizon"] == h["horizon"]
              and is_baseline(x["method"])}
        if bl:
            out.append({"scene": h["scene"], "horizon": h["horizon"], "ours": h["cpu"], "baselines": bl})
    return out


def both_ratios_lines(res: Results) -> list[str]:
    """One line per compared scene: our cost at the target error against SciPy's DOP853 and the compiled RK4."""
    lines = []
    for t in speedup_table(res):
        parts = [f"{_faster(v['ratio'])} {m} ({_fmt(v['cost'], '.3g')} s)" for m, v in t["baselines"].items()
                 if m in (f"solve_ivp {BASELINES[0]}", RK4_METHOD)]
        if parts:
            lines.append(f"{t['scene']} ({t['horizon']:g} s): at error {TARGET_ERROR:.0e} {_method_label('full')} "
                         f"costs {_fmt(t['ours'], '.3g')} CPU s: " + " and ".join(parts))
    return lines


def _ours(res: Results, h: dict) -> dict:
    for x in res.headline:
        if x["scene"] == h["scene"] and x["horizon"] == h["horizon"] and x["method"] == _method_label("full"):
            return x
    return {}


CSV_FIELDS = ["scene", "horizon_s", "method", "knob", "value", "cpu_s", "wall_s", "steps", "rhs_evals", "error",
              "error_L", "realtime_factor", "note"]


def write_outputs(res: Results, out: Path) -> None:
    """DIR/bench.csv (one line per work-precision run), DIR/bench.md, DIR/work_precision.png."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "bench.csv", "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(CSV_FIELDS)
        for r in res.rows:
            wr.writerow([r.scene, f"{r.horizon:g}", r.method, r.knob, f"{r.value:g}", f"{r.cpu:.6g}", f"{r.wall:.6g}",
                         r.steps, "" if r.rhs is None else r.rhs, f"{r.error:.6g}", f"{r.error_L:.6g}",
                         f"{r.rtf:.6g}", r.note])
    if res.accuracy is not None:
        from gyro_sim.apps.bench_accuracy import csv_rows

        rows = csv_rows(res.accuracy)
        with open(out / "accuracy.csv", "w", newline="") as fh:
            wr = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["scene"])
            wr.writeheader()
            wr.writerows(rows)
    from gyro_sim.apps.bench_estimate import write_csv as estimate_csv

    estimate_csv(res, out / "estimate.csv")
    (out / "bench.md").write_text(markdown(res))
    if res.rows:
        plot_work_precision(res, out / "work_precision.png")


def machine() -> str:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.platform()}, {cpu or platform.machine()}, os.cpu_count() = {os.cpu_count()}"


def versions() -> str:
    import numba
    import scipy

    return (f"Python {platform.python_version()}, NumPy {np.__version__}, SciPy {scipy.__version__}, "
            f"numba {numba.__version__}")


def markdown(res: Results) -> str:
    cfg = res.config
    load = ""
    if hasattr(os, "getloadavg"):
        load = f" (load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())})"
    L = [f"# gyro_sim work-precision benchmark ({cfg.mode})", "",
         f"- date: {res.started}",
         f"- machine: {machine()}{load}",
         f"- software: {versions()}",
         f"- command: `{res.command or 'gyro_sim.bench.run_bench'}`",
         f"- total wall time of the benchmark: {res.wall_total:.1f} s",
         "", "Compare the ratios of one run, not absolute times across runs. Costs are CPU seconds of the "
         "benchmark's process (`time.process_time`, which other work on a shared machine disturbs far less "
         "than wall time) with the wall-clock figures beside them. error = max(|L − L_ref|/|L_ref|, "
         "|q − q_ref|) of the final state (of L alone for a run that averaged the spin phase out); "
         "real-time factor = simulated s / wall s. Comparisons run each scene without its controller (the same "
         "problem for every method).", "", "## Headline", ""]
    L += [f"- {x}" for x in headline_lines(res)] or ["- (no comparison ran)"]
    sp = speedup_table(res)
    if sp:
        names = list(dict.fromkeys(m for t in sp for m in t["baselines"]))
        L += [""] + _table(
            f"## Speed-up at error {TARGET_ERROR:.0e} (CPU; the baseline's cost over ours, > 1: ours is faster)",
            f"scene | horizon s | {_method_label('full')} CPU s | " + " | ".join(f"vs {m}" for m in names),
            [f"{t['scene']} | {t['horizon']:g} | {_fmt(t['ours'])} | " + " | ".join(
                f"{_fmt(t['baselines'][m]['ratio'], '.3g')}x ({_fmt(t['baselines'][m]['cost'])} s"
                + (", cheapest run" if t['baselines'][m]['flat'] else "") + ")" if m in t["baselines"] else "–"
                for m in names) for t in sp],
            [f"{RK4_METHOD}: classic RK4 with a fixed step on a numba right-hand side of the same model "
             "(gyro_sim/apps/bench_baseline.py), swept over the number of steps; solve_ivp: SciPy over the NumPy "
             "right-hand side. Costs interpolated log-log on each method's Pareto front."])[:-1]
    L += ["", "## References", "",
          "| scene | horizon s | reference | CPU s | cross-check | CPU s | agreement |", "|---|---|---|---|---|---|---|"]
    for r in res.refs:
        L.append(f"| {r['scene']} | {r['horizon']:g} | {r['reference']} | {_fmt(r['ref_cpu'])} | {r['check'] or '–'} "
                 f"| {_fmt(r['check_cpu'])} | {_fmt(r['agreement'], '.1e')} |")
    L += ["", f"## Cost at error {TARGET_ERROR:.0e} (log-log interpolation along each method's Pareto front)", "",
          "| scene | horizon s | method | CPU s | wall s | RHS evaluations | CPU / ours | wall / ours | RHS / ours "
          "| CPU s at error of L alone | note |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for h in res.headline:
        note = "every setting below the target: cheapest run" if h.get("flat") else (
            f"no setting reached the target (best {h['best']:.1e})" if not math.isfinite(h["cpu"]) else "")
        L.append(f"| {h['scene']} | {h['horizon']:g} | {h['method']} | {_fmt(h['cpu'])} | {_fmt(h['wall'])} "
                 f"| {_fmt(h['rhs'], '.3g')} | {_fmt(h['speedup'], '.3g')} | {_fmt(h['speedup_wall'], '.3g')} "
                 f"| {_fmt(h['rhs_ratio'], '.3g')} | {_fmt(h['cpu_L'])} | {note} |")
    L += ["", "## Work-precision tables", ""]
    groups: dict = {}
    for r in res.rows:
        groups.setdefault((r.scene, r.horizon), []).append(r)
    for (scene, T), rows in groups.items():
        whole = any("whole scene" in r.note for r in rows)
        L += [f"### {scene}, horizon {T:g} s" + (" (our integrator only, the whole scene)" if whole else ""), "",
              "| method | setting | CPU s | wall s | steps | RHS evaluations | error | error of L | real-time factor "
              "| note |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            note = r.note.replace("our integrator only (whole scene)", "").strip("; ")
            L.append(f"| {r.method} | {r.setting} | {r.cpu:.4g} | {r.wall:.4g} | {r.steps} | {_fmt(r.rhs, 'd')} "
                     f"| {r.error:.2e} | {r.error_L:.2e} | {r.rtf:.3g} | {note} |")
        L.append("")
    if res.modes:
        L += _table("## Cost of eddy modes", "scene | modes | method | setting | horizon s | CPU s | wall s | steps "
                    "| RHS evaluations | CPU ns per step | real-time factor",
                    [f"{m['scene']} | {m['modes']} | {m['method']} | {m['setting']} | {m['horizon']:g} "
                     f"| {m['cpu']:.4g} | {m['wall']:.4g} | {m['steps']} | {_fmt(m['rhs'], 'd')} "
                     f"| {m['ns_per_step']:.4g} | {m['rtf']:.3g}" for m in res.modes])
    if res.rtf:
        L += _table("## Real-time factor of the default scene", "scene | method | run | duration s | wall s | CPU s "
                    "| steps | averaged s | real-time factor | per CPU s | final spin rev/s | final θ deg | L vs full",
                    [f"{r['scene']} | {r['method']} | {r['what']} | {r['duration']:g} | {r['wall']:.3g} "
                     f"| {r['cpu']:.3g} | {r['steps']} | {r['averaged']:.3g} | {r['rtf']:.3g} | {r['rtf_cpu']:.3g} "
                     f"| {r['spin_rev_s']:.2f} | {r['theta_deg']:.3g} | {_fmt(r['error_L'], '.1e')}" for r in res.rtf])
    if res.spinup:
        L += _table("## 20-minute spin-up (spinup_thin_shell, no controller)", "method | setting | duration s "
                    "| wall s | CPU s | steps | averaged s | real-time factor | attitude error rad (estimate) | error of L "
                    "| estimate of L | spin rev/s "
                    "| spin / field rate | θ deg",
                    [f"{s['method']} | {s['setting']} | {s['duration']:g} | {s['wall']:.4g} | {s['cpu']:.4g} "
                     f"| {s['steps']} | {s['averaged']:.4g} | {s['rtf']:.3g} | {_fmt(s['error'], '.1e')} "
                     f"| {_fmt(s['error_L'], '.1e')} | {_fmt(s.get('estimate_L', float('nan')), '.1e')} "
                     f"| {s['spin_rev_s']:.2f} | {s['spin_fraction']:.6f} "
                     f"| {s['theta_deg']:.3g}" for s in res.spinup],
                    ["Each row is `method: auto` at the accuracy named (the run picks its stepper, modes and steps). The "
                     "error of L is the final state's against a run at rtol 1e-9 (relative); the attitude's is the "
                     "run's own estimate (its `error_estimate`); averaged levels have none (they average the spin "
                     "phase out). The goal of issue 23 is the first row: L to 1e-6 in under 0.3 s."])
    if res.averaged:
        L += _table("## Averaged models: fidelity auto against full (scenes as shipped, whole duration)",
                    "scene | duration s | averaged by | averaged s | CPU s full | CPU s auto | speed-up (CPU) "
                    "| wall s full | wall s auto | error of L | error of spin | error of θ rad",
                    [f"{v['scene']} | {v['duration']:g} | {v['models']} | {v['averaged']:.4g} | {v['cpu_full']:.4g} "
                     f"| {v['cpu_auto']:.4g} | {v['speedup']:.3g} | {v['wall_full']:.4g} | {v['wall_auto']:.4g} "
                     f"| {v['error_L']:.1e} | {v['error_spin']:.1e} "
                     f"| {v['error_theta']:.1e}" for v in res.averaged],
                    ["Errors are final-state differences of auto from full; each contains the full model's fast ripple "
                     "(O(ε)), which the averaged model does not carry. The regions are in docs/averaged_k.md §7, "
                     "docs/averaged_m.md and gyro_sim/engine/fidelity.py."])
    if res.savings:
        L += _table("## What skipping is worth (spinup_thin_shell, no controller; CPU s)", "the scene skips | compared "
                    "| horizon s | CPU s (skipped) | stepper, steps | CPU s (done) | stepper, steps | ratio",
                    [f"{v['what']} | {v['how']} | {v['horizon']:g} | {v['cpu']:.4g} | {v['method']} {v['steps']} "
                     f"| {v['cpu_forced']:.4g} | {v['method_forced']} {v['steps_forced']} | {v['ratio']:.2f}"
                     for v in res.savings])
    if res.profile:
        L += _table("## Where the time goes (compiled kernels; CPU ns, least of 3)", "case | what | ns",
                    [f"{p['case']} | {p['what']} | "
                     + (f"{p['ns']:.2f} (ratio)" if p.get("unit") == "ratio" else f"{p['ns']:.4g}")
                     for p in res.profile])
    from gyro_sim.apps.bench_ros import markdown as ros_markdown
    from gyro_sim.apps.bench_ticks import markdown_lines as ticks_markdown
    from gyro_sim.apps.bench_ticks import output_rate_lines
    from gyro_sim.apps.bench_scaling import markdown as scaling_markdown

    L += ticks_markdown(res)
    L += output_rate_lines(res)
    L += ros_markdown(res)
    L += scaling_markdown(res)
    if res.accuracy is not None:
        from gyro_sim.apps.bench_accuracy import markdown_lines

        L += markdown_lines(res.accuracy)
    from gyro_sim.apps.bench_estimate import markdown_lines as estimate_markdown

    L += estimate_markdown(res)
    from gyro_sim.apps.bench_cost import markdown_lines as cost_markdown

    L += cost_markdown(res)
    from gyro_sim.apps.bench_rk4 import markdown_lines as rk4_markdown

    L += rk4_markdown(res)
    if res.notes:
        L += ["## Notes", ""] + [f"- {n}" for n in res.notes] + [""]
    return "\n".join(L) + "\n"


def plot_work_precision(res: Results, path=None):
    """Log-log CPU time of a run (s) against its error (final (L, q) vs the reference, dimensionless), one panel
    per scene/horizon, one line of markers per method; a dashed vertical line at the target error
    ``TARGET_ERROR`` where the headline compares the costs. Wall times are not drawn (they are in bench.csv).

    Args:
        res: the benchmark's results (``res.rows``: :class:`Row`).
        path: if given, the figure is also written there as PNG (atomically; parent folders are made).

    Returns:
        The ``matplotlib.figure.Figure`` (Agg canvas, no pyplot state).
    """
    from matplotlib.lines import Line2D

    from gyro_sim.io.plotting import new_figure, save_png

    groups: dict = {}
    for r in res.rows:
        groups.setdefault((r.scene, r.horizon), []).append(r)
    n = max(len(groups), 1)
    fig = new_figure((6.0 * n, 4.6))
    axes = fig.subplots(1, n, squeeze=False)[0]
    markers = ["o", "s", "^", "D", "v", "P", "X", "*", "h"]
    for ax, ((scene, T), rows) in zip(axes, groups.items()):
        methods: dict = {}
        for r in rows:
            methods.setdefault(r.method, []).append(r)
        for i, (m, rs) in enumerate(methods.items()):
            pts = [(r.error, r.cpu) for r in rs if r.error > 0 and math.isfinite(r.error)]
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker=markers[i % len(markers)], label=m)
        ax.axvline(TARGET_ERROR, color="0.6", ls="--", lw=1)
        ax.text(TARGET_ERROR, 0.98, f" target {TARGET_ERROR:.0e}", transform=ax.get_xaxis_transform(), rotation=90,
                va="top", ha="right", fontsize=7, color="0.4")
        ax.set_xlabel("error of the final (L, q) vs reference")
        ax.set_ylabel("CPU time of the run (s)")
        ax.set_title(f"{scene}, {T:g} s simulated", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        target = Line2D([], [], color="0.6", ls="--", lw=1,
                        label=f"target error {TARGET_ERROR:.0e} (costs compared here)")
        ax.legend(handles=ax.get_legend_handles_labels()[0] + [target], fontsize=8)
    if not groups:
        axes[0].text(0.5, 0.5, "no runs", ha="center")
    fig.suptitle(f"gyro_sim work-precision ({res.config.mode}, {res.started})", fontsize=10)
    if path is not None:
        save_png(fig, path, dpi=110)
    return fig


# ----------------------------------------------------------------------------------------
# command line


