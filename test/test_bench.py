"""The work-precision benchmark (gyro_sim.apps.bench): its NumPy baseline is the compiled model, and it
writes its three files with sane contents."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from gyro_sim import load_scene

from gyro_sim.apps import bench_baseline

from gyro_sim.compiled import kernels
from gyro_sim.apps.bench import (RK4_METHOD, BenchConfig, Results, Row, bench_main, cost_at_error, final_error,
                            numpy_rhs, run_baseline, run_bench, run_ours, savings)
from gyro_sim.engine.simulate import Simulator, run

SCENES = [
    ("spinup_thin_shell", {}),
    ("spinup_solid_sphere", {"modes": 1}),
    ("spinup_solid_sphere", {"modes": 50}),
    ("spinup_thin_shell", {"torque_model": "quasi_static"}),
    ("spinup_thin_shell", {"torque_model": "none"}),
    ("free_rotor", {}),
    ("rotating_field", {}),
    # three stators with different rates, phases and a general field term on top
    ("spinup_thin_shell", {"stators.0.current": 0.7, "stators.0.rate": -1200.0, "stators.0.phase": 0.3,
                           "stators.1.current": 0.4, "stators.1.rate": 250.0,
                           "field": [{"real": [1e-4, -2e-4, 3e-4], "imag": [0.0, 5e-5, -1e-4], "frequency": 77.0}]}),
]


@pytest.mark.parametrize("name,overrides", SCENES)
def test_numpy_rhs_equals_compiled_kernel(name, overrides):
    """numpy_rhs = kernels.nonlinear_part + the linear decay −e_n/τ_n, to round-off, at random states
    (quaternions off the unit sphere, as at the stages of a step) and times."""
    scene = load_scene(name, overrides={"controller": None, **overrides})
    sim = Simulator(scene)
    sim.t = 0.37  # the segment starts later than 0: the RHS must use s = t − t_seg
    f = numpy_rhs(sim)
    Bre, Bim, om = sim.phasors()
    rng = np.random.default_rng(7)
    n = sim.y.size
    nm = sim.tau.size
    J3 = scene.inertia[2]
    for _ in range(20):
        y = np.empty(n)
        y[0:3] = rng.normal(size=3) * J3 * 3000.0
        y[3:7] = rng.normal(size=4) * rng.uniform(0.8, 1.2)
        y[7:] = rng.normal(size=n - 7) * 2e-3
        t = sim.t + rng.uniform(0.0, 0.05)
        F = np.zeros(n)
        kernels.nonlinear_part(t - sim.t, y, Bre, Bim, om, sim.Jinv, sim.c_m, sim.w, sim.tail, nm, F, np.zeros(25), sim.eff)
        F += sim.lam * y
        G = f(t, y)
        assert G.shape == F.shape
        for sl in (slice(0, 3), slice(3, 7), slice(7, n)):
            if sl.start >= n:
                continue
            scale = max(np.max(np.abs(F[sl])), 1e-300)
            assert np.max(np.abs(G[sl] - F[sl])) <= 1e-13 * scale, (sl, F[sl], G[sl])


@pytest.mark.parametrize("name,overrides", SCENES)
def test_compiled_baseline_rhs_equals_numpy_rhs(name, overrides):
    """The compiled RK4 baseline's right-hand side (bench_baseline.rhs, numba) = numpy_rhs to round-off, at random
    states (quaternions off the unit sphere) and times: the two baselines integrate one model."""
    sim = Simulator(load_scene(name, overrides={"controller": None, **overrides}))
    sim.t = 0.37
    f = numpy_rhs(sim)
    args = bench_baseline.model_args(sim)
    rng = np.random.default_rng(11)
    n = sim.y.size
    worst = 0.0
    for _ in range(20):
        y = np.empty(n)
        y[0:3] = rng.normal(size=3) * sim.J[2] * 3000.0
        y[3:7] = rng.normal(size=4) * rng.uniform(0.8, 1.2)
        y[7:] = rng.normal(size=n - 7) * 2e-3
        t = sim.t + rng.uniform(0.0, 0.05)
        F = np.zeros(n)
        bench_baseline.rhs(t - sim.t, y, *args, F)
        G = f(t, y)
        for sl in (slice(0, 3), slice(3, 7), slice(7, n)):
            if sl.start < n:
                scale = max(np.max(np.abs(G[sl])), 1e-300)
                worst = max(worst, float(np.max(np.abs(F[sl] - G[sl])) / scale))
    print(f"\n  {name} {overrides}: worst relative difference {worst:.1e} (tolerance 1e-13)")
    assert worst <= 1e-13


def test_rk4_baseline_converges_at_fourth_order():
    """The compiled RK4 on 0.02 s of spinup_thin_shell (10 turns of the field, lag model) against gyro_sim's
    lawson8 at 768 steps per turn (within 1.5e-14 of 3072): the error falls by 16 (within 5 %: order 4 ± 0.07)
    each time the step halves, from 2048 to 8192 steps."""
    ref = run_ours("spinup_thin_shell", 0.02, 768, "full/lawson8")
    errs = [bench_baseline.run_rk4("spinup_thin_shell", 0.02, n).score(ref.L, ref.q) for n in (2048, 4096, 8192)]
    ratios = [a / b for a, b in zip(errs, errs[1:])]
    print(f"\n  RK4 errors at 2048, 4096, 8192 steps: {', '.join(f'{e:.2e}' for e in errs)}; ratios "
          f"{', '.join(f'{r:.2f}' for r in ratios)} (16 within 5 %)")
    assert all(abs(r / 16.0 - 1.0) <= 0.05 for r in ratios)


@pytest.mark.parametrize("extra", [None, {"torque_model": "quasi_static"}])
def test_rk4_baseline_at_a_fine_step_agrees_with_gyro_sim_run(extra):
    """At 16384 steps over 0.02 s the compiled RK4 agrees with gyro_sim.run of the scene (controller removed)
    within the scene's stated accuracy (rtol 1e-6 on L, attitude 1e-6 rad: tolerance 1e-6 on the benchmark's
    error), and with lawson8 at 768 steps per turn within 1e-11; lag and quasi-static models."""
    scene = load_scene("spinup_thin_shell", overrides={"controller": None, **(extra or {})})
    r = bench_baseline.run_rk4("spinup_thin_shell", 0.02, 16384, extra)
    ours = run(scene, duration=0.02)
    tight = run_ours("spinup_thin_shell", 0.02, 768, "full/lawson8", extra)
    e_run = final_error(r.L, r.q, ours.L[-1], ours.q[-1])
    e_tight = final_error(r.L, r.q, tight.L, tight.q)
    tol = max(scene.accuracy.rtol, scene.accuracy.attitude)
    print(f"\n  {scene.torque_model}: RK4 (16384 steps) against gyro_sim.run {e_run:.1e} (tolerance {tol:g}), "
          f"against lawson8 768/turn {e_tight:.1e} (tolerance 1e-11)")
    assert r.steps == 16384 and r.rhs == 4 * 16384
    assert e_run <= tol and e_tight <= 1e-11


def test_savings_rows_are_timed_after_warm_up():
    """Every row of the savings part is measured after its path ran once (the attitude-free row read 0.00x when
    its first call, which compiles or loads its kernels, was timed): both CPU times > 0, no numba compile during
    the timed runs, the ratio finite and > 0. No timing is asserted."""
    cfg = BenchConfig(mode="smoke", scenes=("spinup_thin_shell",), default_horizon=0.05, min_wall=0.0, max_reps=1)
    res = Results(cfg)
    savings(res)
    assert len(res.savings) == 6
    for v in res.savings:
        print(f"\n  {v['what']}: {v['cpu'] * 1e3:.2f} -> {v['cpu_forced'] * 1e3:.2f} ms = {v['ratio']:.2f}x "
              f"(compiled during the timed runs: {v['compile']:g} s, {v['compile_forced']:g} s; tolerance 0)", end="")
        assert v["cpu"] > 0 and v["cpu_forced"] > 0
        assert math.isfinite(v["ratio"]) and v["ratio"] > 0
        assert v["compile"] == 0 and v["compile_forced"] == 0
    att = next(v for v in res.savings if v["what"].startswith("attitude"))
    assert att["method"] == att["method_forced"] == "frozen_flow"


def test_final_error_is_sign_invariant_in_q():
    L = np.array([0.0, 0.0, 2.0])
    q = np.array([0.6, 0.0, 0.8, 0.0])
    assert final_error(L, -q, L, q) == 0.0
    assert final_error(L * (1 + 1e-6), q, L, q) == pytest.approx(1e-6)


def test_cost_at_error_interpolates_log_log():
    rows = [Row("s", 1.0, "m", "rtol", v, wall, 1, 10 * i + 10, error=err)
            for i, (v, wall, err) in enumerate([(1e-3, 1.0, 1e-4), (1e-5, 10.0, 1e-8)])]
    assert cost_at_error(rows, 1e-6) == pytest.approx(math.sqrt(10.0))
    assert math.isnan(cost_at_error(rows[:1], 1e-6))  # never reaches the target
    flat = [Row("s", 1.0, "m", "rtol", v, wall, 1, 1, error=1e-11) for v, wall in [(1e-3, 2.0), (1e-6, 3.0)]]
    assert cost_at_error(flat, 1e-6) == 2.0  # every run below the target: the cheapest
    # a setting that costs more for less accuracy (LSODA's stiffness switching) is off the Pareto front
    bumpy = rows[:1] + [Row("s", 1.0, "m", "rtol", 1e-4, 50.0, 1, 1, error=2e-6)] + rows[1:]
    assert cost_at_error(bumpy, 1e-6) == pytest.approx(math.sqrt(10.0))


def test_baseline_and_ours_agree_on_a_short_horizon():
    """The two integrate the same model: tight settings agree far below the benchmark's errors."""
    ours = run_ours("spinup_thin_shell", 0.02, 768, "full/lawson8")
    L_scale = float(np.linalg.norm(ours.L))
    base = run_baseline("spinup_thin_shell", 0.02, "DOP853", 1e-11, L_scale)
    assert final_error(base.L, base.q, ours.L, ours.q) < 1e-9
    assert base.rhs > 0 and base.steps > 0 and ours.steps == 768 * 10
    # the scene's own stepper (frozen_flow) and its knob
    ff = run_ours("spinup_thin_shell", 0.02, 1e-6)
    err = final_error(base.L, base.q, ff.L, ff.q)
    print(f"\n  frozen_flow rate_change=1e-6 against DOP853 rtol=1e-11 over 0.02 s: {err:.1e} (tolerance 1e-8), "
          f"{ff.steps} steps")
    assert ff.knob == "rate_change" and ff.value == 1e-6 and err < 1e-8


def _check_outputs(out, scenes):
    md = (out / "bench.md").read_text()
    assert "machine:" in md and "date:" in md and "os.cpu_count()" in md
    assert "Headline" in md and "real-time factor" in md
    for s in scenes:
        assert s in md
    with open(out / "bench.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    methods = {r["method"] for r in rows}
    assert {"gyro_sim full", "gyro_sim full/etdrk4"} <= methods
    assert {"solve_ivp DOP853", "solve_ivp LSODA", RK4_METHOD} <= methods
    for r in rows:
        assert float(r["wall_s"]) > 0 and float(r["cpu_s"]) > 0 and int(r["steps"]) > 0
        assert math.isfinite(float(r["error"])) and float(r["error"]) >= 0
        assert float(r["realtime_factor"]) > 0
    # errors fall as our knob tightens (2nd, 4th or 8th order: by far more than 100x over a 16x (frozen_flow:
    # 100x) range of the step); coarsest (fewest steps) first
    for m in ("gyro_sim full", "gyro_sim full/etdrk4"):
        ours = [r for r in rows if r["method"] == m and r["scene"] == scenes[0]]
        errs = [float(r["error"]) for r in sorted(ours, key=lambda r: int(r["steps"]))]
        print(f"\n  {m}: errors {errs}")
        assert errs[-1] < errs[0] / 100 or errs[-1] < 1e-12
    png = (out / "work_precision.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_bench_smoke(tmp_path):
    """A tiny configuration of every part but the profile: files written, ratios finite."""
    cfg = BenchConfig(mode="smoke", scenes=("spinup_thin_shell",), default_horizon=0.01,
                      steps_per_turn=(12, 48, 192), rate_changes=(1e-3, 1e-5, 1e-7), spt_ref=768,
                      rtols=(1e-4, 1e-7), rtol_ref=1e-10,
                      mode_horizon=0.05, rtf_duration=0.1, profile=False, min_wall=0.0, max_reps=1,
                      averaged_scenes=("three_stators",), accuracy=False, ticks=False)
    res = run_bench(cfg, tmp_path, command="smoke")
    _check_outputs(tmp_path, ["spinup_thin_shell"])
    assert res.refs[0]["agreement"] < 1e-8
    # etdrk4 then frozen_flow, 1 and 50 modes each: ETDRK4 takes the same steps whatever the modes
    assert len(res.modes) == 4 and res.modes[0]["steps"] == res.modes[1]["steps"]
    assert res.rtf and res.rtf[0]["rtf"] > 0
    # [K]'s averaged model runs the three-stator scene throughout, within 1e-3 of the full model
    (a,) = res.averaged
    assert a["models"] == "[K]" and a["averaged"] == a["duration"] and a["error_L"] < 1e-3
    assert "Averaged models" in (tmp_path / "bench.md").read_text()


def test_ticks_part_times_both_loops_on_the_same_runs():
    """The per-tick part (quick): each case with the compiled ticks and the Python break loop (the same run: the
    same steps), the default scenes also without controller; ratios are CPU ratios of this run; bench.md's table."""
    from gyro_sim.apps.bench import markdown
    from gyro_sim.apps.bench_ticks import CASES, ticks_part

    res = Results(BenchConfig(mode="quick", min_wall=0.0, max_reps=1))
    ticks_part(res, quick=True)
    cases = [c[0] for c in CASES if c[4]]
    assert [v["case"] for v in res.ticks] == [c for c in cases for _ in range(3 if "default" in c else 2)]
    for case in cases:
        rows = {v["run"]: v for v in res.ticks if v["case"] == case}
        on, py = rows["controller on, compiled ticks"], rows["controller on, Python break loop"]
        assert on["steps"] == py["steps"] and py["ratio"] == py["cpu"] / on["cpu"] > 0
        if "controller off" in rows:
            assert on["ratio"] == on["cpu"] / rows["controller off"]["cpu"] > 0
    md = markdown(res)
    assert "## Control ticks in-process" in md and "with its controller what it costs without" in md
    assert "against the Python break loop the compiled ticks run `nutation_slow" in md


def test_output_rate_part_rows_against_the_50_hz_run(monkeypatch):
    """The output-rate rows (issue 23): each rate as shipped and with the accuracy of L alone, its CPU over the 50 Hz
    run's of the same accuracy, the samples the rate asks for, a sample a stop (never fewer steps than samples at
    10 kHz); bench.md's table. (Over 0.2 s here: the part's own 2 s / 10 s are the benchmark's.)"""
    from gyro_sim.apps import bench_ticks
    from gyro_sim.apps.bench import markdown

    monkeypatch.setitem(bench_ticks.OUTPUT_RATE_DURATION, "quick", 0.2)
    res = Results(BenchConfig(mode="quick", min_wall=0.0, max_reps=1))
    bench_ticks.output_rate_part(res, quick=True)
    rows = res.output_rates
    assert [v["rate"] for v in rows] == list(bench_ticks.OUTPUT_RATES) * 2
    for v in rows:
        ref = next(w for w in rows if w["accuracy"] == v["accuracy"] and w["rate"] == 50.0)
        assert v["ratio"] == v["cpu"] / ref["cpu"] > 0
        assert v["samples"] == int(round(0.2 * v["rate"])) + 1
        if v["rate"] == 10000.0:
            assert v["steps"] >= v["samples"] - 1
    print("\n  " + "\n  ".join(f"{v['accuracy']}, {v['rate']:g} Hz: {v['steps']} steps, {v['ratio']:.3g}x" for v in rows))
    md = markdown(res)
    assert "## Output rate" in md and "10000 Hz costs" in md


def test_bench_main_refuses_unknown_scene(tmp_path, capsys):
    assert bench_main(["--quick", "--out", str(tmp_path), "--scenes", "no_such_scene"]) == 2
    assert "error:" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_main_quick(tmp_path):
    """``bench --quick``: the three files, the headline printed (its run time is the benchmark's own figure, not
    a test's: a loaded machine must not fail it)."""
    assert bench_main(["--quick", "--out", str(tmp_path)]) == 0
    _check_outputs(tmp_path, ["spinup_thin_shell", "spinup_solid_sphere"])
    md = (tmp_path / "bench.md").read_text()
    assert "Where the time goes" in md and "ns" in md


def test_bench_ros_part_measures_the_node_path(tmp_path):
    """The ros part's pieces on short runs: a first run cold then warm (the warm process compiles nothing), lockstep
    over DDS with every tick answered and its figures parsed, real time with the latency distribution."""
    pytest.importorskip("rclpy", reason="the ROS 2 wheels (pip install '.[ros]') are not installed")
    from gyro_sim.apps import bench_ros

    # (the in-process command alone: the --ros pair's two more processes, one compiling every kernel afresh, were half
    # of this test's 91 s and nothing here read them)
    cold, warm = bench_ros.first_run("free_rotor", tmp_path, ros_too=False)
    print(f"\n  first run of free_rotor: cold {cold['process_wall']:.2f} s (compile {cold['compile']:.2f} s), "
          f"warm {warm['process_wall']:.2f} s")
    assert cold["ok"] and warm["ok"] and cold["compile"] > 0 and warm["compile"] == 0
    lk = bench_ros.lockstep("nutation_oblate", 0.2, tmp_path)
    print(f"  lockstep: {lk['ticks_per_s']:.0f} ticks/s, rtf {lk['rtf_dds']:.2f} vs {lk['rtf_in_process']:.2f}")
    assert lk["ok"] and lk["ticks"] == 200 and lk["ticks_per_s"] > 0 and lk["rtf_in_process"] > 0
    rt = bench_ros.realtime("nutation_oblate", 0.2, tmp_path)
    assert rt["ok"] and 0 <= rt["median_ms"] <= rt["p99_ms"] <= rt["max_ms"] and rt["applied"] > 0
    md = "\n".join(bench_ros.markdown(type("R", (), {"ros": [{"part": "lockstep", **lk}, {"part": "realtime", **rt}]})()))
    assert "ROS path" in md and "ticks/s" in md


def test_accuracy_part_smoke(tmp_path):
    """The accuracy part (gyro_sim/apps/bench_accuracy.py) on two short scenes: every row has an achieved error and an
    estimate, the shipped scene meets its accuracy, the tables and accuracy.csv are written."""
    from gyro_sim.apps.bench_accuracy import accuracy_part

    cfg = BenchConfig(mode="quick", only="accuracy", accuracy_scenes=("free_rotor", "nutation_oblate"))
    res = run_bench(cfg, tmp_path, command="smoke")
    rows = res.accuracy.rows
    shipped = [r for r in rows if r.what == "as shipped" and r.fidelity == "full"]
    # (nutation_oblate as shipped misses its spin phase over the quick 2 s since issue 28's split, and says so:
    # measured 1.9e-6 rad against 1e-6, estimated 9.7e-6; docs/benchmark.md)
    assert len(shipped) == 2 and all(r.met or r.scene == "nutation_oblate" for r in shipped)
    assert all(r.met or (r.est_phase > r.phase_tol and r.est_phase >= r.phase) for r in shipped)
    assert all(r.L == r.L for r in rows if not r.note.startswith("refused"))
    text = (tmp_path / "bench.md").read_text()
    assert "Accuracy by default" in text and (tmp_path / "accuracy.csv").is_file()
    for r in shipped:
        print(f"\n  {r.scene}: achieved L {r.L:.1e}, attitude {r.q:.1e} (stated {r.rtol:g}, {r.attitude_tol:g}); "
              f"estimate {r.est_L:.1e}, {r.est_q:.1e}")
    assert accuracy_part is not None


def test_baseline_sweep_stops_at_the_reference_floor(monkeypatch):
    """A baseline whose error is already at the reference's own agreement with DOP853 (a stiff solid sphere: DOP853
    took 37 754 steps at every rtol, 10 s each, error 6.1e-9 = the agreement) is not swept to tighter rtols: the
    rows would measure the reference. Here a stand-in baseline 1e-9 off the reference at every rtol: one row per
    method, and a note (before: all eight rtols each)."""
    from gyro_sim.apps import bench

    ref = bench.run_ours("spinup_thin_shell", 0.01, 3072, "full/lawson8")
    calls = []

    def stand_in(scene, horizon, method, rtol, L_scale, extra=None, min_wall=0.0, max_reps=1):
        calls.append((method, rtol))
        return bench.Row(scene, horizon, f"solve_ivp {method}", "rtol", rtol, 0.0, 1, 1, L=ref.L * (1 + 1e-9),
                         q=ref.q.copy(), cpu=1.0)

    monkeypatch.setattr(bench, "run_baseline", stand_in)
    cfg = bench.BenchConfig(mode="quick", scenes=("spinup_thin_shell",), default_horizon=0.01, spt_ref=3072,
                            compiled_baseline=False, steps_per_turn=(48,), rate_changes=(1e-4,), min_wall=0.0,
                            max_reps=1)
    res = bench.Results(cfg)
    bench.work_precision(res, "spinup_thin_shell", 0.01)
    swept = [c for c in calls if c[1] != cfg.rtol_ref]
    assert swept == [(m, cfg.rtols[0]) for m in cfg.baselines]
    assert any("tighter" in n or "not run" in n for n in res.notes)


def test_startup_and_sweep_parts(tmp_path):
    """The startup part times every case as new processes, this code and a baseline tree (here the repo itself, put
    on PYTHONPATH), with numba's cache warm (the untimed first process fills it); the sweep part measures runs/s in
    this process, on 1 and 2 workers and in two plain processes, with the same results; both parts' tables and
    headline sentences are written."""
    from pathlib import Path

    from gyro_sim.apps import bench_scaling

    repo = Path(__file__).resolve().parents[1]
    res = type("R", (), {"startup": [], "sweep": []})()
    res.startup = bench_scaling.startup_times({"before": str(repo), "this code": None}, repeats=1, duration=0.05)
    cases = [c for c, _ in bench_scaling.STARTUP_CASES]
    assert sorted((r["tree"], r["case"]) for r in res.startup) == sorted(
        (t, c) for t in ("before", "this code") for c in cases)
    for r in res.startup:
        assert 0 < r["min"] <= r["median"] and r["repeats"] == 1
        if r["case"].startswith("first run"):
            assert r["compile_s"] == 0 and r["first_s"] > 0 and r["again_s"] > 0 and r["import_s"] > 0
    for r in res.startup:
        r["load"] = "–"
    bench_scaling.sweep_part(res, quick=True, runs=8, mc=12, say=lambda s: None)
    (row,) = res.sweep
    for k in ("in_process", "local_1", "local_2", "processes_1", "processes_2", "mc_one", "mc_auto"):
        o = row[k]
        assert o["failed"] == 0 and o["runs_per_s"] > 0 and 0 < o["sim_cpu"] and o["outside"] < 1, (k, o)
    assert row["mc_one"]["tasks"] == 12 and row["mc_auto"]["tasks"] < 12 and row["mc_gain"] > 0
    assert row["ratio_local"] > 0 and row["ratio_processes"] > 0
    assert row["command"]["runs"] == row["command_2"]["runs"] == 8
    assert row["two_processes"]["ok"] == 8 and row["two_processes"]["runs_per_s"] > 0
    md = "\n".join(bench_scaling.markdown(res))
    assert "## Start-up of a process" in md and "## Sweep (8 runs" in md and "outside" in md
    assert any("start-up" in s for s in bench_scaling.headline(res))
    assert any("sweep of 8 runs" in s for s in bench_scaling.headline(res))
