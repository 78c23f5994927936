"""The per-tick part of the benchmark (``gyro-sim bench``): what control ticks cost an in-process run.

CPU time (``time.process_time``, least of the repeats after a warm-up run) of

* the default scene as shipped (50 Hz controller, 50 Hz output, accuracy rtol 1e-6 and 1e-6 rad) with its controller
  and without it, per simulated second, and their ratio;
* the same scene with ``accuracy.attitude: null`` (L alone: the steps are as long as the ticks, so the ticks'
  own cost shows);
* ``nutation_slow`` at ``fidelity: auto`` with ``accuracy.rtol`` 2e-3 (the averaged-models part's setting: [K]'s
  averaged model down to θ = 2.6°, then the full model with ψ-switching at 1.6 kHz) and, in full mode, as shipped
  (rtol 1e-6: no stretch averaged, 12 700 ticks);

each with the compiled tick loop (gyro_sim/engine/ticks.py) and with the break-by-break Python loop
(:func:`gyro_sim.ticks.python_ticks`) in the same process. Quick mode runs the default scene over 12 s (600 ticks)
and leaves out the as-shipped ``nutation_slow``.

Then what the output rate costs (:func:`output_rate_part`): the default scene without controller at output rates
of 10 Hz to 10 kHz, as shipped and with the accuracy of L alone, each run's CPU against the 50 Hz run's, with the
steps taken and the run's error estimate (a sample is a stop of the step: docs/benchmark.md says why there is no
dense output).
"""
from __future__ import annotations

from functools import partial
from typing import Optional

__all__ = ["ticks_part", "output_rate_part", "markdown_lines"]

#: (case, scene, overrides, duration s (None: the scene's), in quick mode too, the comparison without controller)
CASES: tuple = (
    ("default scene as shipped", "spinup_thin_shell", {}, None, True, True),
    ("default scene, accuracy of L alone", "spinup_thin_shell", {"accuracy": {"attitude": None}}, None, True, True),
    ("nutation_slow, fidelity auto, rtol 2e-3", "nutation_slow", {"fidelity": "auto", "accuracy.rtol": 2e-3}, None,
     True, False),
    ("nutation_slow, fidelity auto, as shipped", "nutation_slow", {"fidelity": "auto"}, None, False, False),
)
QUICK_DEFAULT_DURATION = 12.0  # s of the default scene in quick mode
OUTPUT_RATES = (10.0, 50.0, 1000.0, 10000.0)  # Hz: the output-rate rows (50 Hz is the scene's own, the reference)
OUTPUT_RATE_DURATION = {"quick": 2.0, "full": 10.0}  # s of the default scene in the output-rate rows


def ticks_part(res, quick: bool) -> None:
    """Fill ``res.ticks`` (dicts: case, run, duration, cpu, wall, steps, ratio, ratio_of)."""
    from gyro_sim.apps.bench_core import _say, _timed_warm
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run
    from gyro_sim.engine.ticks import python_ticks

    cfg = res.config
    for case, name, ov, T, in_quick, with_off in CASES:
        if quick and not in_quick:
            continue
        scene = load_scene(name, overrides=ov)
        T = T or (QUICK_DEFAULT_DURATION if quick and name == "spinup_thin_shell" else scene.duration)
        runs: dict = {}

        # (called within the iteration; case, T and runs bound as defaults all the same: B023)
        def timed(label: str, sc, python: bool = False, case=case, T=T, runs=runs) -> None:
            def go():
                if python:
                    with python_ticks():
                        return run(sc, duration=T)
                return run(sc, duration=T)

            wall, cpu, r, _ = _timed_warm(go, cfg.min_wall, cfg.max_reps)
            runs[label] = {"case": case, "run": label, "duration": T, "cpu": cpu, "wall": wall, "steps": int(r.steps),
                           "ratio": None, "ratio_of": ""}

        timed("controller on, compiled ticks", scene)
        timed("controller on, Python break loop", scene, python=True)
        runs["controller on, Python break loop"].update(
            ratio=runs["controller on, Python break loop"]["cpu"] / runs["controller on, compiled ticks"]["cpu"],
            ratio_of="compiled ticks")
        if with_off:
            timed("controller off", scene.model_copy(update={"controller": None}))
            on, off = runs["controller on, compiled ticks"], runs["controller off"]
            on.update(ratio=on["cpu"] / off["cpu"], ratio_of="controller off")
        for v in runs.values():
            res.ticks.append(v)
            _say(f"[ticks] {case} ({T:g} s), {v['run']}: CPU {v['cpu']:.4g} s ({v['cpu'] / T * 1e3:.3g} ms per "
                 f"simulated s), {v['steps']} steps" + (f"; {v['ratio']:.3g}x {v['ratio_of']}" if v["ratio"] else ""))


def output_rate_part(res, quick: bool) -> None:
    """Fill ``res.output_rates`` (dicts: accuracy, rate, duration, cpu, wall, steps, samples, est_L, est_att, ratio):
    the default scene without controller at each of :data:`OUTPUT_RATES`, its CPU over the 50 Hz run's."""
    from gyro_sim.apps.bench_core import _say, _timed_warm
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run

    cfg = res.config
    T = OUTPUT_RATE_DURATION["quick" if quick else "full"]
    for acc, ov in (("as shipped (L 1e-6, attitude 1e-6 rad)", {}),
                    ("L alone (attitude: null)", {"accuracy": {"attitude": None}})):
        rows = []
        for rate in OUTPUT_RATES:
            scene = load_scene("spinup_thin_shell", overrides={"controller": None, "output.rate": rate, **ov})
            wall, cpu, r, _ = _timed_warm(partial(run, scene, duration=T), cfg.min_wall, cfg.max_reps)
            est = r.error_estimate
            rows.append({"accuracy": acc, "rate": rate, "duration": T, "cpu": cpu, "wall": wall, "steps": int(r.steps),
                         "samples": int(r.t.size), "est_L": est.L if est else None,
                         "est_att": est.attitude if est else None, "ratio": None})
        ref = next(v for v in rows if v["rate"] == 50.0)
        for v in rows:
            v["ratio"] = v["cpu"] / ref["cpu"]
            res.output_rates.append(v)
            _say(f"[output rate] {acc}, {v['rate']:g} Hz ({T:g} s): CPU {v['cpu']:.4g} s, {v['steps']} steps, "
                 f"{v['samples']} samples; {v['ratio']:.3g}x the 50 Hz run")


def _est(x) -> str:
    return "–" if x is None else f"{x:.2g}"


def output_rate_lines(res) -> list:
    """The output-rate table of bench.md ([] where the part did not run)."""
    if not getattr(res, "output_rates", None):
        return []
    from gyro_sim.apps.bench_core import _table

    top = [v for v in res.output_rates if v["rate"] == max(OUTPUT_RATES)]
    summary = "; ".join(f"{v['accuracy']}: {v['rate']:g} Hz costs {v['ratio']:.3g}x the 50 Hz run" for v in top)
    return _table("## Output rate (default scene without controller; CPU against the 50 Hz run)",
                  "accuracy | output Hz | duration s | CPU s | steps | samples | estimated error L, attitude rad | "
                  "x 50 Hz (CPU)",
                  [f"{v['accuracy']} | {v['rate']:g} | {v['duration']:g} | {v['cpu']:.4g} | {v['steps']} | "
                   f"{v['samples']} | {_est(v['est_L'])}, {_est(v['est_att'])} | {v['ratio']:.3g}x"
                   for v in res.output_rates],
                  [summary + ". A sample is a stop of the step (every stepper): past the planned step's rate each "
                   "sample costs a step, and the run is that much more accurate than its tolerance (docs/benchmark.md: "
                   "why there is no dense output)."])


def _row(v: dict) -> str:
    ratio = f"{v['ratio']:.3g}x {v['ratio_of']}" if v["ratio"] else "–"
    return (f"{v['case']} | {v['run']} | {v['duration']:g} | {v['cpu']:.4g} | {v['cpu'] / v['duration'] * 1e3:.3g} "
            f"| {v['wall']:.4g} | {v['steps']} | {ratio}")


def _ratio(res, case: str, run: str) -> Optional[float]:
    return next((v["ratio"] for v in res.ticks if v["case"] == case and v["run"] == run), None)


def markdown_lines(res) -> list:
    """The per-tick table of bench.md and its summary line ([] where the part did not run)."""
    if not res.ticks:
        return []
    from gyro_sim.apps.bench_core import _table

    on_off = _ratio(res, CASES[0][0], "controller on, compiled ticks")
    ns = [(v["case"], v["ratio"]) for v in res.ticks if v["case"].startswith("nutation_slow") and v["ratio"]]
    parts = [f"the default scene as shipped costs {on_off:.3g}x with its controller what it costs without"
             ] if on_off else []
    if ns:
        parts.append("against the Python break loop the compiled ticks run " + " and ".join(
            f"`{c}` {x:.3g}x faster" for c, x in ns))
    summary = "; ".join(parts)
    summary = summary[:1].upper() + summary[1:]
    return _table("## Control ticks in-process (CPU; compiled tick loop against the break-by-break Python loop)",
                  "case | run | duration s | CPU s | CPU ms per simulated s | wall s | steps | ratio (CPU)",
                  [_row(v) for v in res.ticks],
                  [summary + ".", "Both loops call the compiled law (gyro_ctl/law_kernels.py); the Python loop before "
                   "issue 23 also ran the laws in Python (scripts/tick_cost.py compares two versions of the code). "
                   "The shadow run of the error control stops at its checks and where a command changes what a stator "
                   "does, not at the ticks whose commands change nothing."])
