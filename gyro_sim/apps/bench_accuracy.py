"""The benchmark's accuracy part (issue 19): what each built-in scene achieves against the accuracy it states.

``gyro-sim bench --only accuracy`` (or as part of ``gyro-sim bench``) runs, for every built-in scene:

* a **converged reference** of the scene's model: the eddy modes of ``accuracy: {rtol: 1e-11, attitude: 1e-9}`` (the
  conductor's
  own truncation far below every tolerance swept), lawson8 at 64 steps per turn where no mode is stiff at that step
  (h ≤ τ_min/2: more steps per turn where a mode asks, up to 1024), else ETDRK4 at 2048 steps per turn; checked
  doubled until two agree to :data:`REF_TARGET` (at most :data:`REF_DOUBLINGS` times; their difference, the
  coarser's error, is ``ref_error``: the floor below which an achieved error means nothing);
* the scene **as shipped** (its own accuracy; default rtol 1e-6, attitude 1e-6 rad) at each fidelity level it
  accepts (``averaged`` refuses most), and at the **old defaults** (10 modes, 12/48 steps per turn, rate_change
  1e-4: :class:`gyro_sim.accuracy.legacy`);
* the **tolerance sweep**: ``accuracy: {rtol: tol, attitude: tol}`` for tol = 1e-3 … 1e-10 (full mode; 1e-3, 1e-6,
  1e-9 in quick mode), full fidelity.

Each run's achieved error is the largest over the output samples of |L − L_ref| / max |L_ref|, of the angle between
its symmetry axis and the reference's (the scene's ``attitude``; the whole rotation angle for a triaxial body) and
of its spin phase's (rad; :func:`gyro_sim.physics.frames.attitude_split`; not for runs that averaged the fast phases
out), beside the run's own
estimate (``RunResult.error_estimate``), their ratio and the run's CPU time. Quick mode runs each scene over
min(duration, 2 s) (the plan is made for that horizon).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

FULL_TOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
QUICK_TOLS = (1e-3, 1e-6, 1e-9)
QUICK_HORIZON = 2.0
REF_SPT_LAWSON = 64
REF_SPT_ETD = 2048
#: the reference's steps are doubled until two agree to this (L relative, attitude rad), at most REF_DOUBLINGS times
REF_TARGET = 1e-11
REF_DOUBLINGS = 3


@dataclass
class AccRow:
    scene: str
    horizon: float
    what: str  # "as shipped", "old defaults", "sweep"
    fidelity: str
    rtol: float
    attitude_tol: float
    L: float = math.nan  # achieved, relative
    q: float = math.nan  # achieved, rad (NaN: not a result)
    est_L: float = math.nan
    est_q: float = math.nan
    phase: float = math.nan  # achieved spin phase error, rad (NaN: no symmetry axis, or not a result)
    est_phase: float = math.nan
    phase_tol: float = math.nan  # rad, as the run reports it (accuracy.phase × the phase turned, or phase_atol)
    cpu: float = math.nan
    steps: int = 0
    note: str = ""
    ref_error: float = math.nan

    @property
    def met(self) -> bool:
        return bool(self.L <= self.rtol and not (self.q > self.attitude_tol) and not (self.phase > self.phase_tol))

    @property
    def verdict(self) -> str:
        """'yes' (met), 'no', 'no (warned)' (the run said it cannot hold the attitude tolerance: below 1e-12 of the
        spin phase, accuracy.PHASE_REL_MIN) or '–' where a tolerance is below the reference's own error."""
        if self.met:
            return "yes"
        tol = min(self.rtol, self.attitude_tol) if math.isfinite(self.attitude_tol) else self.rtol
        if tol <= self.ref_error:
            return "–"
        return "no (warned)" if "cannot be held" in self.note else "no"

    @property
    def ratio_L(self) -> float:
        return self.est_L / self.L if self.L > 0 else math.nan

    @property
    def ratio_q(self) -> float:
        return self.est_q / self.q if self.q > 0 else math.nan


@dataclass
class AccResults:
    rows: list = field(default_factory=list)
    refs: dict = field(default_factory=dict)  # scene → {method, steps_per_turn, modes, ref_error_L, ref_error_q, cpu}


def _errors(r, ref, split: bool = False):
    """(L relative, attitude rad) of run ``r`` against ``ref`` over their common samples; ``split``: (L, directions,
    spin phase) as the scene's tolerances count them (frames.attitude_split; NaN where not a result)."""
    from gyro_sim.physics.frames import attitude_split, symmetry_axis

    n = min(len(r.t), len(ref.t))
    if not np.allclose(r.t[:n], ref.t[:n], rtol=0, atol=1e-9):
        raise RuntimeError("bench_accuracy: the run's samples are not the reference's")
    Lmax = float(np.max(np.linalg.norm(ref.L[:n], axis=1)))
    eL = float(np.max(np.linalg.norm(r.L[:n] - ref.L[:n], axis=1)) / Lmax) if Lmax > 0 else 0.0
    eq = ep = math.nan
    if getattr(r, "attitude", True) and not getattr(r, "averaged_segments", None) and np.all(np.isfinite(r.q[:n])):
        ax = symmetry_axis(r.scene.rotor.inertia)
        if split:
            d, p = attitude_split(r.q[:n], ref.q[:n], ax, r.L[:n], ref.L[:n])
            eq, ep = float(np.max(d)), (float(np.max(p)) if ax >= 0 else math.nan)
        else:
            d = np.minimum(np.linalg.norm(r.q[:n] - ref.q[:n], axis=1), np.linalg.norm(r.q[:n] + ref.q[:n], axis=1))
            eq = float(np.max(4.0 * np.arcsin(np.clip(0.5 * d, 0.0, 1.0))))
    return (eL, eq, ep) if split else (eL, eq)


def _load(name: str, T: float, **over):
    from gyro_sim.scenes.scene import load_scene

    return load_scene(name, overrides={"duration": T, **over})


def reference_stepper(sim, T: float) -> tuple[str, int]:
    """(stepper, steps per turn) of a converged reference of simulator ``sim``'s scene over T s: lawson8 at
    :data:`REF_SPT_LAWSON` steps per turn, more where a mode asks (h ≤ τ_min/2), up to 1024; beyond that ETDRK4 at
    :data:`REF_SPT_ETD` (a stiff mode). The estimate part's references take it too (bench_estimate)."""
    om = sim.step_plan.turns * 2 * math.pi / T if T > 0 else 0.0
    spt = REF_SPT_LAWSON
    if om > 0 and math.isfinite(sim.tau_min):
        spt = max(spt, math.ceil(2 * math.pi / (om * 0.5 * sim.tau_min)))
    return ("lawson8", spt) if spt <= 1024 else ("etdrk4", REF_SPT_ETD)


def reference(name: str, T: float) -> tuple[object, dict]:
    """The converged reference run of scene ``name`` over T s (see the module docstring) and its description."""
    from gyro_sim.scenes.accuracy import mode_plan
    from gyro_sim.engine.simulate import Simulator, run

    s = _load(name, T)
    over = {"controller": s.controller.model_dump() if s.controller else None}
    fine = _load(name, T, accuracy={"rtol": 1e-11, "attitude": 1e-9})
    n_ref = None
    if s.rotor.conductor is not None and s.torque_model == "lag" and s.rotor.conductor.kind != "thin_shell" \
            and s.effects.magnetizable is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            n_ref = max(mode_plan(fine, T, quiet=True).n, mode_plan(s, T, quiet=True).n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = Simulator(_load(name, T, **({"modes": n_ref} if n_ref else {})), attitude=True, quiet=True)
    method, spt = reference_stepper(sim, T)

    def go(k):
        integ = {"method": method, "steps_per_turn": int(k)}
        sc = _load(name, T, integrator=integ, **({"modes": n_ref} if n_ref else {}))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c0 = time.process_time()
            r = run(sc, attitude=True)
            return r, time.process_time() - c0

    # doubled until two agree to REF_TARGET (at most REF_DOUBLINGS times): the finer is the reference, their
    # difference (the coarser's error) bounds its own
    coarse, cpu = go(spt)
    for _ in range(REF_DOUBLINGS):
        spt *= 2
        ref, c = go(spt)
        cpu += c
        eL, eq = _errors(coarse, ref)
        if max(eL, 0.0 if math.isnan(eq) else eq) <= REF_TARGET:
            break
        coarse = ref
    del over
    return ref, {"method": method, "steps_per_turn": spt, "modes": n_ref, "ref_error_L": eL, "ref_error_q": eq,
                 "cpu": cpu}


def _one(name: str, T: float, what: str, fidelity: str, ref, over: dict, legacy_run: bool = False) -> "AccRow":
    from gyro_sim.scenes.accuracy import legacy
    from gyro_sim.scenes.scene import SceneError
    from gyro_sim.engine.simulate import run

    s = _load(name, T, **over)
    if fidelity != "full":
        s = s.model_copy(update={"fidelity": fidelity})
    acc = s.accuracy
    row = AccRow(scene=name, horizon=T, what=what, fidelity=fidelity, rtol=acc.rtol,
                 attitude_tol=math.nan if acc.attitude is None else acc.attitude)
    try:
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            c0 = time.process_time()
            if legacy_run:
                with legacy():
                    r = run(s, attitude=True)
            else:
                r = run(s, attitude=True)
            row.cpu = time.process_time() - c0
        if w:
            row.note = "; ".join(sorted({str(x.message).split(":")[1].strip()[:60] for x in w}))
    except SceneError as exc:
        row.note = f"refused: {str(exc)[:80]}"
        return row
    row.L, row.q, row.phase = _errors(r, ref, split=True)
    row.steps = int(r.steps)
    e = r.error_estimate
    if e is not None:
        row.est_L, row.est_q, row.est_phase, row.phase_tol = e.L, e.attitude, e.phase, e.phase_tol
        if e.steps_method != "richardson":
            row.note = (row.note + "; " if row.note else "") + f"estimate: {e.steps_method}"
    if getattr(r, "averaged_segments", None):
        row.note = (row.note + "; " if row.note else "") + \
            f"averaged {sum(b - a for a, b in r.averaged_segments):.3g} s (attitude not a result)"
    return row


def accuracy_part(res, quick: bool, scenes: Optional[list] = None, say=print) -> AccResults:
    """Run the part (module docstring); the rows go to ``res.accuracy`` (an :class:`AccResults`)."""
    from gyro_sim.apps.bench_core import fidelity_levels
    from gyro_sim.scenes.scene import builtin_scenes, load_scene

    out = AccResults()
    res.accuracy = out
    names = scenes or list(builtin_scenes())
    tols = QUICK_TOLS if quick else FULL_TOLS
    for name in names:
        s0 = load_scene(name)
        T = min(s0.duration, QUICK_HORIZON) if quick else s0.duration
        t0 = time.perf_counter()
        ref, info = reference(name, T)
        info["ref_error"] = max(info["ref_error_L"], 0.0 if math.isnan(info["ref_error_q"]) else info["ref_error_q"])
        out.refs[name] = info
        say(f"[accuracy] {name} ({T:g} s): reference {info['method']} {info['steps_per_turn']} steps per turn"
            f"{', ' + str(info['modes']) + ' modes' if info['modes'] else ''}: its own error {info['ref_error']:.1e}")
        for level in fidelity_levels():
            out.rows.append(_one(name, T, "as shipped", level, ref, {}))
        out.rows.append(_one(name, T, "old defaults", "full", ref, {}, legacy_run=True))
        for tol in tols:
            out.rows.append(_one(name, T, "sweep", "full", ref, {"accuracy": {"rtol": tol, "attitude": tol}}))
        for r in out.rows:
            if r.scene == name:
                r.ref_error = info["ref_error"]
        say(f"[accuracy] {name}: {time.perf_counter() - t0:.1f} s")
    return out


def _f(x, spec=".2g") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def markdown_lines(acc: AccResults) -> list[str]:
    """The part's tables for bench.md."""
    lines = ["## Accuracy by default (issue 19)", "",
             "Achieved error (max over the output samples; L relative to max |L|, attitude in rad) against a "
             "converged reference, the run's own estimate, and CPU time. `ref` bounds the reference's own error "
             "(its difference from the same at half the steps): achieved errors near it are the reference's, and "
             "a tolerance below it is not measured (met: `–`).", ""]
    lines += ["### Scenes as shipped", "",
              "| scene | T s | fidelity | stated rtol / attitude / phase rad | achieved L | achieved attitude | "
              "achieved phase | estimate L | estimate attitude | estimate phase | met | CPU s | steps | ref | note |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in acc.rows:
        if r.what in ("as shipped", "old defaults"):
            label = r.fidelity if r.what == "as shipped" else "full, old defaults"
            lines.append(f"| {r.scene} | {r.horizon:g} | {label} | {_f(r.rtol, 'g')} / {_f(r.attitude_tol, 'g')} / "
                         f"{_f(r.phase_tol)} | {_f(r.L)} | {_f(r.q)} | {_f(r.phase)} | {_f(r.est_L)} | {_f(r.est_q)} | "
                         f"{_f(r.est_phase)} | "
                         f"{'–' if r.note.startswith('refused') else r.verdict} | {_f(r.cpu, '.3g')} | "
                         f"{r.steps} | {_f(r.ref_error, '.1e')} | {r.note} |")
    lines += ["", "### Tolerance sweep (full fidelity; rtol = attitude = tol)", "",
              "| scene | tol | achieved L | achieved attitude | estimate / achieved (L, attitude) | met | CPU s | steps |",
              "|---|---|---|---|---|---|---|---|"]
    for r in acc.rows:
        if r.what == "sweep":
            lines.append(f"| {r.scene} | {r.rtol:.0e} | {_f(r.L)} | {_f(r.q)} | {_f(r.ratio_L, '.2g')}, "
                         f"{_f(r.ratio_q, '.2g')} | {r.verdict} | {_f(r.cpu, '.3g')} | {r.steps} |")
    return lines + [""]


def csv_rows(acc: AccResults) -> list[dict]:
    return [{"scene": r.scene, "horizon_s": r.horizon, "what": r.what, "fidelity": r.fidelity, "rtol": r.rtol,
             "attitude_tol": r.attitude_tol, "error_L": r.L, "error_attitude": r.q, "estimate_L": r.est_L,
             "estimate_attitude": r.est_q, "error_phase": r.phase, "estimate_phase": r.est_phase,
             "phase_tol": r.phase_tol, "met": r.verdict, "cpu_s": r.cpu, "steps": r.steps,
             "ref_error": r.ref_error, "note": r.note} for r in acc.rows]


def headline(acc: AccResults) -> list[str]:
    """One line per scene as shipped (full fidelity): achieved against stated, and the cost against the old defaults."""
    lines = []
    by: dict = {}
    for r in acc.rows:
        by.setdefault(r.scene, {})[(r.what, r.fidelity)] = r
    for name, d in by.items():
        a, o = d.get(("as shipped", "full")), d.get(("old defaults", "full"))
        if a is None:
            continue
        cost = f", {a.cpu / o.cpu:.2g}x the CPU of the old defaults (which reached L {_f(o.L)}, attitude {_f(o.q)})" \
            if o is not None and o.cpu > 0 else ""
        lines.append(f"accuracy: {name} as shipped: L {_f(a.L)}, attitude {_f(a.q)} rad against rtol {_f(a.rtol, 'g')}, "
                     f"attitude {_f(a.attitude_tol, 'g')} ({'met' if a.met else 'NOT met'}; estimate {_f(a.est_L)}, "
                     f"{_f(a.est_q)}){cost}")
    sweep = [r for r in acc.rows if r.what == "sweep"]
    bad = [r for r in sweep if r.verdict == "no"]
    warned = [r for r in sweep if r.verdict == "no (warned)"]
    unmeasured = sum(1 for r in sweep if r.verdict == "–")
    lines.append(f"accuracy sweep: {len(sweep)} runs, {len(bad)} beyond their tolerance unannounced"
                 + (": " + ", ".join(f"{r.scene}@{r.rtol:.0e}" for r in bad[:10]) if bad else "")
                 + (f"; {len(warned)} beyond it as the run warned (attitude below 1e-12 of the spin phase): "
                    + ", ".join(f"{r.scene}@{r.rtol:.0e}" for r in warned[:10]) if warned else "")
                 + (f" ({unmeasured} below the reference's own error, not measured)" if unmeasured else ""))
    return lines
