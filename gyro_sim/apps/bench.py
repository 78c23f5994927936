"""Work-precision benchmark: the project's integrator against the plain SciPy baseline.

``gyro-sim bench [--quick] [--out DIR] [--scenes NAME ...]`` (:func:`bench_main`) runs, in one
process and on the same scenes,

* the project's integrator (``gyro_sim.run``) at every fidelity level the scene format knows
  (``Scene.fidelity``), sweeping its accuracy knob ``integrator.steps_per_turn``;
* the baseline a user would write: :func:`scipy.integrate.solve_ivp` (DOP853 and LSODA) over a
  NumPy right-hand side of the same model (:func:`numpy_rhs`), sweeping rtol 1e-3 … 1e-10 with
  atol = rtol × the scale of each state component;
* the compiled baseline: classic fixed-step RK4 over a numba right-hand side of that model
  (:mod:`gyro_sim.bench_baseline`), sweeping the number of steps;
* the default scene's quasi-static variant (``torque_model: quasi_static``) beside it (``BenchConfig.variants``);

and measures CPU and wall time, steps, right-hand-side evaluations and the error of the final state
against a converged reference (our integrator at a high steps_per_turn, cross-checked against
DOP853 at rtol 1e-12). It also measures the cost of 50 against 1 solid-sphere modes, the
real-time factor of the default scene, the compiled kernels' cost per right-hand side and per
step, and (full mode only) a 20-minute spin-up. It writes ``DIR/bench.md`` (tables, date,
machine), ``DIR/bench.csv`` and ``DIR/work_precision.png``, and prints the headline ratios.

Timings: each run's CPU time of this process (``time.process_time``) and its wall time. The
headline ratios use CPU time, which other work on a shared machine disturbs far less than wall
time; the real-time factors are wall-clock. Compare ratios measured in one run, never absolute
times across runs. Errors are dimensionless:
``error = max(|L − L_ref| / |L_ref|, min(|q − q_ref|, |q + q_ref|))`` of the final state; for a run
of a reduced fidelity level that averaged out the spin phase (``RunResult.averaged_segments``) the
attitude is not a result, and its error is that of L alone (``|L − L_ref| / |L_ref|``, marked).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import sys
import time
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from gyro_sim.apps.bench_core import (  # noqa: F401  (re-exported: the old module path)
    AVERAGED_PART_RTOL, AVERAGED_SCENES, _baseline_once, BASELINES, below_target, BenchConfig, cost_at_error,
    DEFAULT_SCENES, drive_segments, _faster, fidelity_levels, final_error, full_config, is_baseline, knob_of,
    level_method, _line, _method_label, numpy_rhs, OURS, ours_levels, pareto_front, quick_config, RATE_CHANGES,
    REF_FLOOR_FACTOR, refined, Results, RK4_METHOD, Row, run_baseline, run_ours, _say, _scene_overrides, STAGES,
    state_scale, _table, TARGET_ERROR, _timed, _timed_warm, variant_label)
from gyro_sim.apps.bench_report import (  # noqa: F401  (re-exported: the old module path)
    both_ratios_lines, CSV_FIELDS, _fmt, headline_lines, machine, markdown, _ours, plot_work_precision,
    speedup_table, versions, write_outputs)

__all__ = [
    "numpy_rhs",
    "final_error",
    "Row",
    "BenchConfig",
    "quick_config",
    "full_config",
    "fidelity_levels",
    "run_ours",
    "run_baseline",
    "cost_at_error",
    "pareto_front",
    "run_bench",
    "write_outputs",
    "bench_main",
]

def work_precision(res: Results, scene: str, horizon: float, with_baselines: bool = True,
                   spt_ref: Optional[int] = None, extra: Optional[dict] = None) -> None:
    """Every method on one scene (with ``extra`` overrides: a variant, named by :func:`variant_label`) and horizon
    against one converged reference; fills res.rows. The baselines: solve_ivp (``cfg.baselines``) and, with
    ``cfg.compiled_baseline``, the compiled fixed-step RK4 (gyro_sim/apps/bench_baseline.py)."""
    cfg = res.config
    spt_ref = spt_ref or cfg.spt_ref
    label = variant_label(scene, extra)
    _say(f"[{label}, {horizon:g} s] reference: {OURS} full/lawson8, steps_per_turn={spt_ref}")
    ref = run_ours(scene, horizon, spt_ref, "full/lawson8", extra)
    ref.note = "reference"
    L_ref, q_ref = ref.L, ref.q
    L_scale = float(np.linalg.norm(L_ref)) or 1.0
    ref_info = {"scene": label, "horizon": horizon, "reference": f"{OURS} full/lawson8, steps_per_turn={spt_ref}",
                "check": "", "agreement": float("nan"), "ref_cpu": ref.cpu, "check_cpu": float("nan")}
    if with_baselines and cfg.rtol_ref:
        chk = run_baseline(scene, horizon, "DOP853", cfg.rtol_ref, L_scale, extra)
        ref_info.update(check=f"solve_ivp DOP853 rtol={cfg.rtol_ref:.0e}",
                        agreement=final_error(chk.L, chk.q, L_ref, q_ref), check_cpu=chk.cpu)
        _say(f"    cross-check DOP853 rtol={cfg.rtol_ref:.0e}: agreement {ref_info['agreement']:.2e}")
    res.refs.append(ref_info)
    rows: list[Row] = []
    for level in ours_levels():
        try:
            method = level_method(scene, level, extra)
        except Exception as exc:  # a level that does not apply to this scene
            res.notes.append(f"{label}: {_method_label(level)} skipped: {exc}".splitlines()[0])
            _say(f"    {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
            continue
        for value in (cfg.rate_changes if knob_of(method) == "rate_change" else cfg.steps_per_turn):
            try:
                r = run_ours(scene, horizon, value, level, extra, min_wall=cfg.min_wall, max_reps=cfg.max_reps)
            except Exception as exc:  # a level that does not apply to this scene
                res.notes.append(f"{label}: {_method_label(level)} skipped: {exc}".splitlines()[0])
                _say(f"    {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
                break
            r.score(L_ref, q_ref)
            rows.append(r)
            _say(_line(r))
    if with_baselines:
        floor = REF_FLOOR_FACTOR * ref_info["agreement"]
        for method in cfg.baselines:
            for rtol in cfg.rtols:
                r = run_baseline(scene, horizon, method, rtol, L_scale, extra, min_wall=cfg.min_wall,
                                 max_reps=cfg.max_reps)
                r.score(L_ref, q_ref)
                rows.append(r)
                _say(_line(r))
                if r.error <= floor and rtol != cfg.rtols[-1]:
                    # (tighter rtols would measure the reference, not the method: a stiff baseline whose stability
                    # bounds its step costs the same at every rtol)
                    res.notes.append(f"{label}: solve_ivp {method} at rtol < {rtol:.0e} not run: its error "
                                     f"{r.error:.1e} is at the reference's own agreement with DOP853 "
                                     f"{ref_info['agreement']:.1e}")
                    _say(f"    {method}: error at the reference's agreement; tighter rtols skipped")
                    break
        if cfg.compiled_baseline:
            from gyro_sim.apps.bench_baseline import RK4_STEPS, rk4_sweep

            rk4_rows, notes = rk4_sweep(scene, horizon, L_ref, q_ref, extra, cfg.rk4_steps or RK4_STEPS,
                                        cfg.min_wall, cfg.max_reps, label, say=lambda r: _say(_line(r)))
            rows.extend(rk4_rows)
            res.notes.extend(notes)
    for r in rows:
        r.scene = label
        if not with_baselines:
            r.note = "our integrator only (whole scene)" + ("; " + r.note if r.note else "")
        if r.method.startswith(OURS) and r.method != _method_label("full") and r.averaged == 0:
            r.note = (r.note + "; " if r.note else "") + "never averaged here (= full model)"
    res.rows.extend(rows)
    # headline: cost at the target error, speed-up of each method over the baselines
    by_method: dict[str, list[Row]] = {}
    for r in rows:
        by_method.setdefault(r.method, []).append(r)
    costs = {m: tuple(cost_at_error(rs, TARGET_ERROR, k) for k in ("cpu", "rhs", "wall"))
             for m, rs in by_method.items()}
    ours_full = costs.get(_method_label("full"), (float("nan"),) * 3)
    def ratio(a, b):
        return a / b if math.isfinite(a) and math.isfinite(b) and b > 0 else float("nan")

    for m, (cc, cr, cw) in costs.items():
        Lrows = [replace(r, error=r.error_L) for r in by_method[m]]
        res.headline.append({"scene": label, "horizon": horizon, "method": m, "cpu": cc, "wall": cw, "rhs": cr,
                             "flat": below_target(by_method[m]), "whole": not with_baselines,
                             "cpu_L": cost_at_error(Lrows, TARGET_ERROR, "cpu"),
                             "best": min((r.error for r in by_method[m]), default=float("nan")),
                             "speedup": ratio(cc, ours_full[0]), "speedup_wall": ratio(cw, ours_full[2]),
                             "rhs_ratio": ratio(cr, ours_full[1])})


def mode_cost(res: Results) -> None:
    """Our integrator on the solid sphere with 1 and 50 modes (ETDRK4 and frozen_flow at their default knobs);
    the baseline too."""
    cfg = res.config
    scene, T = cfg.mode_scene, cfg.mode_horizon
    # at fixed knobs (the old defaults: the plan's would follow each mode count's own accuracy)
    for level, knob in (("full/etdrk4", 48), ("full/frozen_flow", 1e-4)):
        for n in cfg.mode_counts:
            r = run_ours(scene, T, knob, level, {"modes": int(n)}, min_wall=cfg.min_wall, max_reps=cfg.max_reps)
            res.modes.append({"scene": scene, "modes": n, "method": r.method, "setting": r.setting, "horizon": T,
                              "cpu": r.cpu, "wall": r.wall, "steps": r.steps, "rhs": r.rhs, "rtf": r.rtf,
                              "ns_per_step": 1e9 * r.cpu / max(r.steps, 1)})
            _say(f"[modes] {scene} {r.method} modes={n}: cpu {r.cpu:.4f} s, wall {r.wall:.4f} s, steps {r.steps}, "
                 f"{r.rtf:.1f}x real time")
    if cfg.mode_baseline_horizon:
        Tb = cfg.mode_baseline_horizon
        for method in cfg.baselines:
            for n in cfg.mode_counts:
                ref = run_ours(scene, Tb, 48, "full/etdrk4", {"modes": int(n)})
                r = run_baseline(scene, Tb, method, 1e-6, float(np.linalg.norm(ref.L)) or 1.0, {"modes": int(n)})
                res.modes.append({"scene": scene, "modes": n, "method": r.method, "setting": r.setting,
                                  "horizon": Tb, "cpu": r.cpu, "wall": r.wall, "steps": r.steps, "rhs": r.rhs,
                                  "rtf": r.rtf, "ns_per_step": 1e9 * r.cpu / max(r.steps, 1)})
                _say(f"[modes] {scene} modes={n} {r.method} rtol=1e-6 over {Tb:g} s: cpu {r.cpu:.3f} s, "
                     f"steps {r.steps}, RHS {r.rhs}")


def _averaged_time(r) -> float:
    return float(sum(t1 - t0 for t0, t1 in (getattr(r, "averaged_segments", None) or [])))


def realtime_factor(res: Results) -> None:
    """The default scene as a user runs it (controller included), whole duration, at each fidelity level."""
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run

    cfg = res.config
    L_full = None
    for level in fidelity_levels():
        try:
            scene = load_scene(cfg.rtf_scene, overrides=None if level == "full" else {"fidelity": level})
            T = cfg.rtf_duration or scene.duration
            wall, cpu, r = _timed(partial(run, scene, duration=T), 0.0, 1)
        except Exception as exc:
            res.notes.append(f"real-time factor: {_method_label(level)} skipped: {exc}".splitlines()[0])
            _say(f"[real time] {_method_label(level)}: skipped ({str(exc).splitlines()[0]})")
            continue
        res.rtf.append({"scene": cfg.rtf_scene, "method": _method_label(level),
                        "what": "as shipped (controller on, output samples)", "duration": T, "wall": wall,
                        "cpu": cpu, "steps": int(r.steps), "rtf": T / wall, "rtf_cpu": T / cpu,
                        "averaged": _averaged_time(r),
                        "error_L": float("nan") if L_full is None else final_error(r.L[-1], None, L_full, None),
                        "spin_rev_s": float(r.spin_rate[-1] / (2 * math.pi)),
                        "theta_deg": float(np.degrees(r.theta[-1]))})
        if level == "full":
            L_full = r.L[-1].copy()
        _say(f"[real time] {cfg.rtf_scene} {T:g} s, {_method_label(level)}: wall {wall:.3f} s, cpu {cpu:.3f} s, "
             f"steps {r.steps}, real-time factor {T / wall:.1f} (per CPU second {T / cpu:.1f})")


#: the 20-minute spin-up's accuracies: (label, scene overrides). Its goal is L (the attitude of a rotor turned
#: through 2·10⁶ rad cannot be held to 1e-6 rad: the plan's floor is 1e-12 of the phase, docs/accuracy.md), so the
#: rows that time it hold L alone; the scene's own accuracy (attitude 1e-6 rad) is a row of its own
SPINUP_RUNS: tuple = (
    ("rtol 1e-6, attitude: null", {"accuracy": {"rtol": 1e-6, "attitude": None}}),
    ("rtol 1e-6, attitude: null, output 1 Hz", {"accuracy": {"rtol": 1e-6, "attitude": None}, "output.rate": 1.0}),
    ("as shipped: rtol 1e-6, attitude 1e-6 rad", {}),
)
#: its reference for L: the same run at this rtol
SPINUP_REF_RTOL = 1e-9


def long_spinup(res: Results) -> None:
    """20-minute spin-up of the default scene without its controller (fidelity full, ``method: auto``), at the
    accuracies of :data:`SPINUP_RUNS`, and at each other fidelity level (L to 1e-6).

    Each row's error of L is measured against a run at rtol :data:`SPINUP_REF_RTOL` (final state, relative); its
    attitude error is the run's own estimate (``RunResult.error_estimate``; no reference holds the phase of 2·10⁶
    rad better than the run at the floor)."""
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run

    cfg = res.config
    T = cfg.spinup_duration
    base = {"duration": T, "controller": None}
    target = next((s.rate for s in load_scene("spinup_thin_shell").stators if s.current > 0), float("nan"))
    ref = run(load_scene("spinup_thin_shell", overrides={**base, "accuracy": {"rtol": SPINUP_REF_RTOL,
                                                                                "attitude": None}}))

    def entry(method, setting, w, c, r):
        est = r.error_estimate
        return {"method": method, "setting": setting, "duration": T, "wall": w, "cpu": c, "steps": int(r.steps),
                "rtf": T / w, "rtf_cpu": T / c, "error": est.attitude if est is not None else float("nan"),
                "error_L": final_error(r.L[-1], None, ref.L[-1], None), "estimate_L": est.L if est is not None else float("nan"),
                "averaged": _averaged_time(r), "spin_rev_s": float(r.spin_rate[-1] / (2 * math.pi)),
                "spin_fraction": float(r.spin_rate[-1] / target), "theta_deg": float(np.degrees(r.theta[-1]))}

    runs = [(_method_label("full"), label, {**base, **ov}) for label, ov in SPINUP_RUNS]
    runs += [(_method_label(level), "rtol 1e-6, attitude: null", {**base, **SPINUP_RUNS[0][1], "fidelity": level})
             for level in fidelity_levels() if level != "full"]
    for method, setting, ov in runs:
        try:
            sc = load_scene("spinup_thin_shell", overrides=ov)
            run(sc, duration=1.0)  # (compiles or loads what it needs before the clock runs)
            w, c, r = _timed(partial(run, sc), 0.0, 1)
        except Exception as exc:  # a level that does not apply
            res.notes.append(f"spin-up: {method} skipped: {exc}".splitlines()[0])
            _say(f"[spin-up {T:g} s] {method}: skipped ({str(exc).splitlines()[0]})")
            continue
        e = entry(method, setting, w, c, r)
        res.spinup.append(e)
        _say(f"[spin-up {T:g} s] {method} {setting}: wall {w:.3f} s, cpu {c:.3f} s, steps {r.steps}, error of L "
             f"{e['error_L']:.1e} (estimate {e['estimate_L']:.1e}), attitude ≈ {_fmt(e['error'], '.1e')} rad, "
             f"spin {e['spin_rev_s']:.2f} rev/s")


def averaged_models(res: Results) -> None:
    """Each averaged model where it applies: ``fidelity: auto`` against ``full`` on scenes as shipped (whole
    duration, controllers on), wall time of each (least of the repeats), the time averaged and by which model,
    and the final errors of auto against full: L (relative, vector), spin (relative), θ (rad)."""
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run

    cfg = res.config
    for name in cfg.averaged_scenes:
        # at an rtol that lets the averaged models in at their MU_MAX (the default rtol 1e-6 averages only where
        # ε ≤ 2e-6: fidelity.mu_max); both runs at that accuracy
        sc = load_scene(name, overrides={"fidelity": "full", "accuracy.rtol": AVERAGED_PART_RTOL})
        sa = sc.model_copy(update={"fidelity": "auto"})
        for warm in (sc, sa):  # compile what this scene's types need before the clock runs
            run(warm, duration=min(sc.duration, 2.0 / sc.output.rate))
        wf, cf, f = _timed(partial(run, sc), cfg.min_wall, cfg.max_reps)
        wa, ca, a = _timed(partial(run, sa), cfg.min_wall, cfg.max_reps)
        e = {"scene": name, "duration": sc.duration, "models": ", ".join(sorted(set(a.averaged_models))) or "none",
             "averaged": _averaged_time(a), "wall_full": wf, "wall_auto": wa, "cpu_full": cf, "cpu_auto": ca,
             "speedup": cf / ca, "wall_speedup": wf / wa, "error_L": final_error(a.L[-1], None, f.L[-1], None),
             "error_spin": float(abs(a.spin_rate[-1] / f.spin_rate[-1] - 1)),
             "error_theta": float(abs(a.theta[-1] - f.theta[-1]))}
        res.averaged.append(e)
        _say(f"[averaged] {name} {sc.duration:g} s: {e['models']} over {e['averaged']:.3g} s; CPU full {cf:.3g} s, "
             f"auto {ca:.3g} s ({e['speedup']:.1f}x; wall {wf:.3g} s, {wa:.3g} s); L {e['error_L']:.1e}, spin {e['error_spin']:.1e}, "
             f"θ {e['error_theta']:.1e} rad")


SAVINGS: tuple = (
    # (what the scene skips, overrides of the scene that skips it, the overrides that make it do that work,
    #  what the comparison is)
    ("stators that are off", {}, {"stators.0.current": 1e-15, "stators.1.current": 1e-15},
     "z1, z2 at 1e-15 A (in the field sum: 3 phasors) against off"),
    ("effects that are off", {}, {"effects": {"gas_drag": {"transverse": [0.0], "axial": [0.0]}}},
     "gas drag with zero coefficients (effects on: frozen_flow does not apply) against none"),
    ("eddy-mode states (quasi-static torque)", {"torque_model": "quasi_static"}, {"torque_model": "lag"},
     "quasi_static (7 states, [K] (1.2)) against lag (10 states, [M] (2.15)): other physics, the same rotor; "
     "the quasi-static torque grows with the slip without bound, so frozen_flow's step is shorter"),
    ("output samples tied to the step", {}, {"output.rate": 1000.0},
     "1000 Hz output against 50 Hz: each sample costs a torque evaluation and is a stop, so a step longer "
     "than the sample spacing (frozen_flow's) is cut to it"),
    ("attitude of an isotropic rotor nobody reads", {"rotor.inertia": [5.592e-6] * 3, "output.attitude": False},
     {"output.attitude": True},
     "inertia [J, J, J]: output.attitude false (L and the eddy modes in the case frame, no q) against true "
     "(frozen_flow both; without attitude the accuracy plan is for L alone, so the step counts may differ)"),
)


def savings(res: Results) -> None:
    """What skipping each unneeded piece is worth: the default scene (no controller, the comparison horizon)
    with the saving and with the work it skips forced in, CPU time of each (least of the repeats), and the
    cost of the Euler angles a run computes only when they are read.

    Every path is run once before it is timed (:func:`_timed_warm`; the attitude-free frozen-flow step of the
    ``output.attitude: false`` row is compiled or loaded from numba's cache on its first call, which read as a
    0.00x saving when it was timed); each row keeps the seconds numba compiled during its timed runs
    (``compile``, ``compile_forced``: 0)."""
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import Simulator, run

    cfg = res.config
    T = cfg.horizon_of("spinup_thin_shell")
    for what, skipping, forced, how in SAVINGS:
        base = {"controller": None, **skipping}
        rows = []
        for ov in (base, {**base, **forced}):
            sc = load_scene("spinup_thin_shell", overrides=ov)
            w, c, r, comp = _timed_warm(partial(run, sc, duration=T), cfg.min_wall, cfg.max_reps)
            rows.append((c, int(r.steps), Simulator(sc)._method(), comp))
        (c0, n0, m0, k0), (c1, n1, m1, k1) = rows
        res.savings.append({"what": what, "how": how, "horizon": T, "cpu": c0, "cpu_forced": c1, "steps": n0,
                            "steps_forced": n1, "method": m0, "method_forced": m1, "ratio": c1 / c0,
                            "compile": k0, "compile_forced": k1})
        _say(f"[savings] {what}: {c0 * 1e3:.2f} ms ({m0}, {n0} steps) against {c1 * 1e3:.2f} ms ({m1}, {n1} steps) "
             f"= {c1 / c0:.2f}x ({how})")
    sc = load_scene("spinup_thin_shell", overrides={"controller": None, "duration": 60.0})
    _, c_run, r, k0 = _timed_warm(lambda: run(sc), cfg.min_wall, cfg.max_reps)
    _, c_eul, _, k1 = _timed_warm(lambda: replace(r, _euler=None).euler, cfg.min_wall, cfg.max_reps)
    res.savings.append({"what": "Euler angles nobody reads", "how": "RunResult.euler computed on first access "
                        f"(60 s, {r.t.size} samples) against the run itself", "horizon": 60.0, "cpu": c_run,
                        "cpu_forced": c_run + c_eul, "steps": int(r.steps), "steps_forced": int(r.steps),
                        "method": "", "method_forced": "", "ratio": (c_run + c_eul) / c_run,
                        "compile": k0, "compile_forced": k1})
    _say(f"[savings] Euler angles: {c_eul * 1e3:.2f} ms on first access against {c_run * 1e3:.2f} ms for the run")


def profile_kernels(res: Results) -> None:
    """Cost of the compiled pieces on the default scene (thin shell) and the solid sphere.

    ns per right-hand side (``kernels.nonlinear_part_at`` in a compiled loop), per field evaluation
    (``kernels.field_case``), per ETDRK4 step (``kernels.integrate_etd`` over one long span), the
    NumPy baseline's right-hand side, and the Python cost of one ``Simulator.advance`` call.
    """
    from gyro_sim.compiled import kernels
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import Simulator

    loop_rhs, loop_field = _profile_loops()
    cases = [("spinup_thin_shell", {}), (res.config.mode_scene or "spinup_solid_sphere", {"modes": 1}),
             (res.config.mode_scene or "spinup_solid_sphere", {"modes": 50})]
    for name, extra in cases:
        sim = Simulator(load_scene(name, overrides=_scene_overrides("full", extra)))
        Bre, Bim, om = sim.phasors()
        y = sim.y.copy()
        F = np.zeros(y.size)
        work = np.zeros(25)
        args = (y, Bre, Bim, om, sim.Jinv, sim.c_m, sim.w, sim.tail, sim.tau.size, F, work, sim.eff)
        label = name + (f" modes={extra['modes']}" if extra else "")
        loop_rhs(10, *args)
        loop_field(10, Bre, Bim, om, work[0:3], work[3:6])
        n = 500_000
        t_rhs = min(_once(partial(loop_rhs, n, *args)) for _ in range(3)) / n
        t_field = min(_once(partial(loop_field, n, Bre, Bim, om, work[0:3], work[3:6])) for _ in range(3)) / n
        h = sim._max_step(False, "etdrk4")
        k = 200_000
        stops, rec = np.array([k * h]), np.array([False])
        oy, oN = np.zeros((1, y.size)), np.zeros((1, 3))

        def integ(sim=sim, stops=stops, rec=rec, h=h, Bre=Bre, Bim=Bim, om=om, oy=oy, oN=oN):  # (bound now: B023)
            yy = sim.y.copy()
            return kernels.integrate_etd(yy, 0.0, 0.0, stops, rec, h, Bre, Bim, om, sim.Jinv, sim.c_m, sim.w,
                                         sim.tail, sim.lam, oy, oN, 0, sim.eff)

        integ()
        t_step = min(_once(integ) for _ in range(3)) / k
        t_ff = _frozen_flow_step_cost(sim, Bre, Bim, om)
        t_rk4 = _rk4_step_cost(sim)
        f = numpy_rhs(sim)
        m = 2000
        t_np = min(_once(lambda f=f, y=y, m=m: [f(1e-3, y) for _ in range(m)]) for _ in range(3)) / m
        for what, sec in (("RHS, compiled (nonlinear_part_at)", t_rhs), ("field B, dB/dt (field_case)", t_field),
                          ("ETDRK4 step (integrate_etd)", t_step), ("frozen_flow step (integrate_frozen)", t_ff),
                          ("RK4 step, compiled baseline (bench_baseline.rk4_span, 4 RHS)", t_rk4),
                          ("RHS, NumPy baseline", t_np)):
            if math.isfinite(sec):
                res.profile.append({"case": label, "what": what, "ns": sec * 1e9})
        res.profile.append({"case": label, "what": "ETDRK4 step / compiled RHS", "ns": t_step / t_rhs,
                            "unit": "ratio"})
        _say(f"[profile] {label}: RHS {t_rhs * 1e9:.0f} ns, field {t_field * 1e9:.0f} ns, "
             f"step {t_step * 1e9:.0f} ns ({t_step / t_rhs:.2f} RHS), frozen_flow step {t_ff * 1e9:.0f} ns, "
             f"compiled baseline's RK4 step {t_rk4 * 1e9:.0f} ns, "
             f"NumPy RHS {t_np * 1e9:.0f} ns")
    # Python cost of one call of Simulator.advance (tiny span: one step)
    sim = Simulator(load_scene("spinup_thin_shell", overrides={"controller": None}))
    h = sim._max_step(False, "etdrk4")
    m = 2000
    t_adv = _once(lambda: [sim.advance(sim.t + 0.5 * h) for _ in range(m)]) / m
    res.profile.append({"case": "spinup_thin_shell", "what": "Simulator.advance call of one step (Python + 1 step)",
                        "ns": t_adv * 1e9})
    _say(f"[profile] Simulator.advance of one step: {t_adv * 1e6:.1f} µs")


def _frozen_flow_step_cost(sim, Bre, Bim, om) -> float:
    """Seconds per frozen-flow step (``frozen_flow.integrate_frozen`` over 20 000 steps at the scene's
    rate_change, else the default), NaN where the stepper does not apply."""
    from gyro_sim.compiled import effects, frozen_flow

    ax = frozen_flow.supported(sim.J)
    if ax < 0 or sim.eff[effects.ON] != 0.0:
        return float("nan")
    h = sim._frozen_flow_step()
    if not math.isfinite(h):
        return float("nan")
    k = 20_000
    stops, rec = np.array([k * h]), np.array([False])
    oy, oN = np.zeros((1, sim.y.size)), np.zeros((1, 3))

    def integ():
        return frozen_flow.integrate_frozen(sim.y.copy(), 0.0, 0.0, stops, rec, h, Bre, Bim, om, sim.Jinv,
                                            sim.J[(ax + 1) % 3], sim.J[ax], ax, sim.c_m, sim.w, sim.tail,
                                            1.0 / sim.tau, oy, oN, 0, None)  # (None: as simulate passes it)

    integ()
    return min(_once(integ) for _ in range(3)) / k


def _rk4_step_cost(sim) -> float:
    """CPU seconds per step of the compiled baseline's RK4 (``bench_baseline.rk4_span``, 4 right-hand sides) over
    100 000 steps of 0.1 µs from the scene's initial state (NaN where it has effects the baseline lacks)."""
    from gyro_sim.compiled import effects
    from gyro_sim.apps.bench_baseline import model_args, rk4_span, warm

    if sim.eff[effects.ON] != 0.0:
        return float("nan")
    warm()
    args = model_args(sim)
    k = 100_000
    return min(_once(lambda: rk4_span(sim.y.copy(), 1e-7, k, *args)) for _ in range(3)) / k


_LOOPS: list = []


def _profile_loops():
    """Compiled loops around ``kernels.nonlinear_part_at`` (with the phases computed each call, as a
    stepper's first stage does) and ``kernels.field_case`` (built once)."""
    if not _LOOPS:
        from numba import njit

        from gyro_sim.compiled import kernels

        nonlinear_part_at, phasor_trig, field_case = kernels.nonlinear_part_at, kernels.phasor_trig, kernels.field_case

        @njit(cache=False)
        def loop_rhs(n, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff):
            acc = 0.0
            cs = np.empty(om.shape[0])
            sn = np.empty(om.shape[0])
            for i in range(n):
                phasor_trig(1e-7 * i, om, cs, sn)
                nonlinear_part_at(cs, sn, 1e-7 * i, y, Bre, Bim, om, Jinv, c_m, w, tail, nm, F, work, eff)
                acc += F[0]
            return acc

        @njit(cache=False)
        def loop_field(n, Bre, Bim, om, B, dB):
            acc = 0.0
            for i in range(n):
                field_case(1e-7 * i, Bre, Bim, om, B, dB)
                acc += B[0]
            return acc

        _LOOPS.extend([loop_rhs, loop_field])
    return _LOOPS[0], _LOOPS[1]


def scaling_parts(res: Results, only: Optional[str] = None) -> None:
    """The startup and sweep parts (gyro_sim/apps/bench_scaling.py) where the config has them (``only``: that one)."""
    from gyro_sim.apps.bench_scaling import startup_part, sweep_part

    cfg, quick = res.config, res.config.mode == "quick"
    if only == "startup" or (only is None and cfg.startup):
        startup_part(res, quick, baseline=cfg.startup_baseline, say=_say)
    if only == "sweep" or (only is None and cfg.sweep):
        sweep_part(res, quick, say=_say)


def _once(fn) -> float:
    """CPU seconds of one call (time.process_time)."""
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def _only_part(res: Results, only: str) -> None:
    """Run the part ``only`` (``gyro-sim bench --only``) into ``res``."""
    cfg = res.config
    quick = cfg.mode == "quick"
    if only in ("startup", "sweep"):
        scaling_parts(res, only)
    elif only == "accuracy":
        from gyro_sim.apps.bench_accuracy import accuracy_part

        accuracy_part(res, quick, list(cfg.accuracy_scenes) if cfg.accuracy_scenes else None, _say)
    elif only == "cost":
        from gyro_sim.apps.bench_cost import cost_part

        cost_part(res, quick, _say)
    elif only == "rk4":
        from gyro_sim.apps.bench_rk4 import rk4_part

        rk4_part(res, quick, _say)
    elif only == "estimate":
        from gyro_sim.apps.bench_estimate import estimate_part

        estimate_part(res, cfg)
    elif only == "ticks":
        from gyro_sim.apps.bench_ticks import output_rate_part, ticks_part

        ticks_part(res, quick=quick)
        output_rate_part(res, quick=quick)
    elif only == "ros":
        from gyro_sim.apps.bench_ros import ros_part

        ros_part(res, quick=quick)
    else:
        raise ValueError(f"--only {only!r}: no such part")


def run_bench(cfg: BenchConfig, out: Path, command: str = "") -> Results:
    """Run every part of ``cfg``, write DIR/bench.md, bench.csv, work_precision.png; return the results."""
    res = Results(cfg, started=_dt.datetime.now().astimezone().isoformat(timespec="seconds"), command=command)
    w0 = time.perf_counter()
    if cfg.only is not None:  # one part alone
        _only_part(res, cfg.only)
        res.wall_total = time.perf_counter() - w0
        write_outputs(res, Path(out))
        return res
    for scene in cfg.scenes:
        work_precision(res, scene, cfg.horizon_of(scene))
        for base, extra in cfg.variants:
            if base == scene:
                work_precision(res, scene, cfg.horizon_of(scene), extra=dict(extra))
    for scene in cfg.long_horizon_scenes:
        from gyro_sim.scenes.scene import load_scene

        T = load_scene(scene).duration
        work_precision(res, scene, T, with_baselines=False, spt_ref=cfg.long_spt_ref)
    if cfg.mode_scene:
        mode_cost(res)
    if cfg.rtf_scene:
        realtime_factor(res)
    if cfg.spinup_duration:
        long_spinup(res)
    if cfg.averaged_scenes:
        averaged_models(res)
    if cfg.profile:
        savings(res)
        profile_kernels(res)
    if cfg.ticks:
        from gyro_sim.apps.bench_ticks import output_rate_part, ticks_part

        ticks_part(res, quick=cfg.mode == "quick")
        output_rate_part(res, quick=cfg.mode == "quick")
    if cfg.ros:
        from gyro_sim.apps.bench_ros import ros_part

        ros_part(res, quick=cfg.mode == "quick")
    scaling_parts(res)
    if cfg.accuracy:
        from gyro_sim.apps.bench_accuracy import accuracy_part

        accuracy_part(res, cfg.mode == "quick", list(cfg.accuracy_scenes) if cfg.accuracy_scenes else None, _say)
    if cfg.estimate:
        from gyro_sim.apps.bench_estimate import estimate_part

        estimate_part(res, cfg)
    if cfg.cost:
        from gyro_sim.apps.bench_cost import cost_part

        cost_part(res, cfg.mode == "quick", _say)
    res.wall_total = time.perf_counter() - w0
    write_outputs(res, Path(out))
    return res


# ----------------------------------------------------------------------------------------
# outputs


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gyro-sim bench",
        description="Work-precision benchmark: gyro_sim's integrator (every fidelity level) against "
                    "scipy solve_ivp (DOP853, LSODA) and a compiled fixed-step RK4 on the same scenes; writes "
                    "DIR/bench.md, bench.csv, "
                    "work_precision.png and prints the headline ratios.")
    p.add_argument("--quick", action="store_true",
                   help="short horizons (still minutes: 141 s wall with --no-ros --no-accuracy, docs/benchmark.md)")
    p.add_argument("--out", metavar="DIR", type=Path, default=Path("runs/bench"),
                   help="output folder (default: runs/bench)")
    p.add_argument("--scenes", metavar="SCENE", nargs="+", default=list(DEFAULT_SCENES),
                   help=f"scenes of the work-precision comparison (default: {' '.join(DEFAULT_SCENES)})")
    p.add_argument("--no-ros", action="store_true", help="skip the ros part (nodes over DDS, first runs)")
    p.add_argument("--no-accuracy", action="store_true",
                   help="skip the accuracy part (every built-in scene against the accuracy it states)")
    p.add_argument("--no-estimate", action="store_true",
                   help="skip the estimate part (each case's error estimate against its true error)")
    p.add_argument("--no-startup", action="store_true", help="skip the startup part (new processes' import times)")
    p.add_argument("--no-sweep", action="store_true", help="skip the sweep part (runs/s on 1 and 2 Dask workers)")
    p.add_argument("--startup-baseline", metavar="DIR",
                   help="a source tree of the code before (e.g. git archive of a commit): its start-up is timed beside "
                        "this code's, in the same run")
    p.add_argument("--only", choices=["accuracy", "cost", "estimate", "rk4", "ticks", "startup", "sweep", "ros"],
                   help="run this part alone")
    p.add_argument("--accuracy-scenes", metavar="SCENE", nargs="+",
                   help="scenes of the accuracy part (default: every built-in scene)")
    return p


def bench_main(argv: Optional[Sequence[str]] = None) -> int:
    """``gyro-sim bench``: run the benchmark, write the files, print the headline. Returns 0 (2 on a bad scene)."""
    from gyro_sim.scenes.scene import SceneError, load_scene

    args = build_parser().parse_args(argv)
    try:  # every scene named, before anything runs
        for s in list(args.scenes) + list(args.accuracy_scenes or []):
            load_scene(s)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    cfg = (quick_config if args.quick else full_config)(args.scenes)
    cfg.ros = cfg.ros and not args.no_ros
    cfg.startup = cfg.startup and not args.no_startup
    cfg.sweep = cfg.sweep and not args.no_sweep
    cfg.startup_baseline = args.startup_baseline
    cfg.accuracy = not args.no_accuracy
    cfg.estimate = cfg.estimate and not args.no_estimate
    cfg.only = args.only
    if args.accuracy_scenes:
        cfg.accuracy_scenes = tuple(args.accuracy_scenes)
    command = "gyro-sim bench " + " ".join(sys.argv[1:] if argv is None else list(argv))
    res = run_bench(cfg, args.out, command=command.strip())
    print()
    print("Headline (ratios measured in this run):")
    for line in headline_lines(res):
        print("  " + line)
    if res.accuracy is not None:
        from gyro_sim.apps.bench_accuracy import headline as acc_headline

        for line in acc_headline(res.accuracy):
            print("  " + line)
    if res.estimate is not None:
        from gyro_sim.apps.bench_estimate import headline as est_headline

        for line in est_headline(res.estimate):
            print("  " + line)
    from gyro_sim.apps.bench_cost import headline as cost_headline

    for line in cost_headline(res):
        print("  " + line)
    from gyro_sim.apps.bench_rk4 import headline as rk4_headline

    for line in rk4_headline(res):
        print("  " + line)
    print(f"wrote {args.out / 'bench.md'}, {args.out / 'bench.csv'}, {args.out / 'work_precision.png'} "
          f"({res.wall_total:.1f} s)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(bench_main())
