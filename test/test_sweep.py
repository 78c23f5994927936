"""Parameter sweeps (gyro_sim/apps/sweep.py, ``gyro-sim sweep``): spec parsing, variants, metrics, failed
and invalid runs, resume, the Parquet table, plots, the CLI, and execution on Dask — a local cluster
and a real scheduler with workers started here as separate processes on 127.0.0.1 (same numbers as
in-process). Runs are tiny (20 ms of nutation_oblate); ``-s`` prints the measured figures."""
import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import gyro_sim
from gyro_sim.apps import sweep as sw
from gyro_sim.apps import sweep_exec, sweep_tasks  # (run_chunk and run_sweep live there: patch their names there)
from gyro_sim.averaging.averaged import RotorK

TINY = {"duration": 0.02, "output.rate": 500.0}
METRICS = {"theta_end": "final(theta_deg)", "spin_end": "final_spin", "t_half": "time_below(theta_deg, 9.99)",
           "tmax": "max(torque_norm)", "L_drift": "drift(L_norm)", "sf": "k(sampling_factor)"}


def tiny(**over) -> sw.SweepSpec:
    d = {"scene": "nutation_oblate", "set": dict(TINY), "vary": {"controller.period": "0.001:0.004:4"},
         "metrics": dict(METRICS)}
    d.update(over)
    return sw.spec_from_dict(d, where="test")


def metric_table(res, names=None):
    names = names or [m.name for m in res.spec.metrics]
    return [(r["run_id"], r["status"], tuple(r[n] for n in names)) for r in res.rows]


# ------------------------------------------------------------------------------------------
# parsing
# ------------------------------------------------------------------------------------------
def test_grid_axes():
    a = sw.parse_axis("controller.period", "0.004:0.02:5")
    assert a.values == pytest.approx((0.004, 0.008, 0.012, 0.016, 0.02)) and a.values[-1] == 0.02
    assert sw.parse_axis("modes", "2:10:5").values == (2, 4, 6, 8, 10)
    assert sw.parse_axis("x", "1e-3:1e-1:3:log").values == pytest.approx((1e-3, 1e-2, 1e-1))
    assert sw.parse_axis("x", "0.1, 0.2,0.5").values == (0.1, 0.2, 0.5)
    assert sw.parse_axis("controller.params.nu", "[1000,2500]:[3000,7500]:3").values == (
        [1000.0, 2500.0], [2000.0, 5000.0], [3000.0, 7500.0])
    assert sw.parse_axis("x", {"start": 1, "stop": 3, "num": 3}).values == (1, 2, 3)
    assert sw.parse_axis("x", {"values": ["1e-3", 2]}).values == (0.001, 2)
    assert sw.parse_axis("x", [[1, 2], [3, 4]]).values == ([1, 2], [3, 4])
    assert sw.parse_axis("x", "1:2:1").values == (1,)
    for bad, msg in (("1:2:0", "must be ≥ 1"), ("1:2:x", "whole number"), ("0:1:3:log", "log spacing"),
                     ("a:b:3", "must be numbers"), ("1:2", "START:STOP:N"), ("[1,2]:[1]:3", "one length"),
                     ("1:2:3:cubic", "spacing")):
        with pytest.raises(sw.SweepError, match=msg):
            sw.parse_axis("x", bad)
    with pytest.raises(sw.SweepError, match="dotted scene key"):
        sw.parse_axis("controller..period", "1,2")


def test_random_draws_are_reproducible_and_independent_per_key():
    u = sw.parse_random("initial.theta", "uniform(0.1, 0.2)")
    n = sw.parse_random("initial.psi", "normal(1, 0.5)")
    lg = sw.parse_random("x", "loguniform(1e-3, 1e-1)")
    ri = sw.parse_random("modes", "randint(2, 4)")
    ch = sw.parse_random("torque_model", "choice(lag, quasi_static)")
    draws = {r.key: [r.draw(7, s) for s in range(200)] for r in (u, n, lg, ri, ch)}
    assert all(0.1 <= v <= 0.2 for v in draws["initial.theta"])
    assert abs(np.mean(draws["initial.psi"]) - 1) < 0.15 and 0.35 < np.std(draws["initial.psi"]) < 0.65
    assert all(1e-3 <= v <= 1e-1 for v in draws["x"]) and np.mean(np.log10(draws["x"])) == pytest.approx(-2, abs=0.2)
    assert set(draws["modes"]) == {2, 3, 4} and set(draws["torque_model"]) == {"lag", "quasi_static"}
    assert [u.draw(7, s) for s in range(5)] == draws["initial.theta"][:5]  # same seed, same draws
    assert u.draw(8, 0) != u.draw(7, 0)
    # a key's draws do not depend on the other keys of the sweep
    s1 = tiny(vary={}, random={"initial.theta": "uniform(0.1, 0.2)"}, samples=3)
    s2 = tiny(vary={}, random={"initial.theta": "uniform(0.1, 0.2)", "initial.psi": "uniform(0, 1)"}, samples=3)
    assert [v.values["initial.theta"] for v in s1.variants()] == [v.values["initial.theta"] for v in s2.variants()]
    for bad in ("uniform(1)", "uniform(2, 1)", "normal(0, -1)", "loguniform(0, 1)", "gauss(0, 1)", "choice()"):
        with pytest.raises(sw.SweepError):
            sw.parse_random("x", bad)


def test_metric_specs():
    assert sw.parse_metric("final_spin") == sw.Metric("final_spin", "final", ("spin",))
    assert sw.parse_metric("t=time_below(theta_deg, 0.1)") == sw.Metric("t", "time_below", ("theta_deg", 0.1))
    assert sw.parse_metric("max(torque_norm)").name == "max_torque_norm"
    assert sw.parse_metric("k(time_to_deg, 1)").args == ("time_to_deg", 1)
    for bad, msg in (("final(nope)", "unknown quantity"), ("time_below(theta_deg)", "takes 1 quantity and 1 number"),
                     ("frobnicate(theta)", "unknown function"), ("status=final(spin)", "reserved"),
                     ("k(zeta)", "k\\(NAME"), ("whatever", "unknown metric")):
        with pytest.raises(sw.SweepError, match=msg):
            sw.parse_metric(bad)


def test_spec_errors_name_the_problem():
    cases = [({"vary": {"initial.theta": "0:1:2"}, "random": {"initial.theta": "uniform(0,1)"}, "samples": 2},
              "varied twice"),
             ({"random": {"initial.theta": "uniform(0,1)"}}, "need a number of samples"),
             ({"samples": 3}, "no random key"),
             ({"set": {"controller.period": 0.001}}, "both fixed"),
             ({"metrics": {"a": "final(spin)", "controller.period": "final(spin)"}}, "metric"),
             ({"bogus": 1}, "unknown key"),
             ({"scene": "no_such_scene"}, "no such file and no built-in scene")]
    for over, msg in cases:
        with pytest.raises(sw.SweepError, match=msg):
            tiny(**over)


# ------------------------------------------------------------------------------------------
# variants and their runs (in this process)
# ------------------------------------------------------------------------------------------
def test_variants_grid_times_samples_with_stable_ids():
    s = tiny(vary={"controller.period": "0.001,0.002", "initial.theta": "0.1:0.3:3"},
             random={"initial.psi": "uniform(0, 6.28)"}, samples=2)
    vs = s.variants()
    assert len(vs) == 2 * 3 * 2
    assert [v.values["controller.period"] for v in vs[:6]] == [0.001] * 6  # last axis and samples vary fastest
    assert [v.sample for v in vs[:4]] == [0, 1, 0, 1]
    ids = [v.run_id for v in vs]
    assert len(set(ids)) == len(ids) and ids == [v.run_id for v in s.variants()]
    other = tiny(vary={"controller.period": "0.001,0.002", "initial.theta": "0.1:0.3:3"},
                 random={"initial.psi": "uniform(0, 6.28)"}, samples=2, set={"duration": 0.03})
    assert not set(ids) & {v.run_id for v in other.variants()}  # the fixed overrides are in the key


def test_serial_sweep_matches_direct_runs():
    res = sw.run_sweep(tiny(), workers=0, progress=False)
    assert res.n_total == res.n_run == 4 and res.n_failed == res.n_invalid == 0
    for row in res.rows:
        s = gyro_sim.load_scene("nutation_oblate", overrides={**TINY, "controller.period": row["controller.period"]})
        r = gyro_sim.run(s)
        assert row["theta_end"] == math.degrees(r.theta[-1])
        assert row["spin_end"] == r.spin_rate[-1]
        assert row["tmax"] == np.max(np.linalg.norm(r.torque, axis=1))
        L = np.linalg.norm(r.L, axis=1)
        assert row["L_drift"] == np.max(np.abs(L - L[0])) / L[0]
        t_half = r.t[np.argmax(np.degrees(r.theta) < 9.99)] if np.any(np.degrees(r.theta) < 9.99) else math.inf
        assert row["t_half"] == t_half
        lam_h = s.initial.spin * s.inertia[2] / RotorK.of(s.inertia).J * row["controller.period"]
        assert row["sf"] == pytest.approx(math.sin(lam_h) / lam_h, rel=1e-12)
        assert row["status"] == "ok" and row["gyro_sim_version"] == gyro_sim.__version__


def test_invalid_and_failed_variants_are_recorded_and_the_sweep_goes_on(monkeypatch):
    real = sw._run_scene

    def flaky(scene):
        per = scene.controller.period
        if per == 0.002:
            raise RuntimeError("integrator blew up")
        r = real(scene)
        if per == 0.003:
            r.L[3:] = np.nan
        return r

    monkeypatch.setattr(sweep_exec, "_run_scene", flaky)
    spec = tiny(vary={"controller.period": "0.001:0.004:4", "initial.theta": "3.0,3.5"})
    res = sw.run_sweep(spec, workers=0, progress=False)
    by = {(r["controller.period"], r["initial.theta"]): r for r in res.rows}
    assert len(res.rows) == 8 and res.n_invalid == 4 and res.n_failed == 2
    for per in (0.001, 0.002, 0.003, 0.004):
        bad = by[(per, 3.5)]
        assert bad["status"] == "invalid" and "initial.theta" in bad["error"] and "3.5" in bad["error"]
        assert math.isnan(bad["theta_end"])
    assert by[(0.002, 3.0)]["status"] == "failed" and "integrator blew up" in by[(0.002, 3.0)]["error"]
    assert by[(0.003, 3.0)]["status"] == "failed" and "non-finite state" in by[(0.003, 3.0)]["error"]
    assert by[(0.001, 3.0)]["status"] == by[(0.004, 3.0)]["status"] == "ok"
    print("\n" + "\n".join(f"  {r['status']}: {r['error']}" for r in res.rows if r["error"]))


def test_resume_skips_what_is_done(tmp_path, monkeypatch):
    out = tmp_path / "res.parquet"
    spec = tiny(vary={"controller.period": "0.001:0.006:6"})
    calls = []
    real = sw._run_scene

    def stop_after_two(scene):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(scene.controller.period)
        return real(scene)

    monkeypatch.setattr(sweep_exec, "_run_scene", stop_after_two)
    first = sw.run_sweep(spec, out=out, workers=0, progress=False)
    assert first.interrupted and len(first.rows) == 2 and out.is_file()
    monkeypatch.setattr(sweep_exec, "_run_scene", real)
    second = sw.run_sweep(spec, out=out, workers=0, progress=False)
    assert second.n_skipped == 2 and second.n_run == 4 and not second.interrupted
    third = sw.run_sweep(spec, out=out, workers=0, progress=False)
    assert third.n_run == 0 and third.n_skipped == 6
    assert metric_table(third) == metric_table(sw.run_sweep(spec, workers=0, progress=False))
    # a hard stop before the table is written: the journal keeps the finished runs
    out2 = tmp_path / "hard.parquet"

    def no_disk(*a, **k):
        raise OSError("disk gone")

    monkeypatch.setattr(sweep_exec, "write_results", no_disk)
    with pytest.raises(OSError):
        sw.run_sweep(spec, out=out2, workers=0, progress=False)
    assert not out2.exists() and sw._journal_path(out2).is_file()
    monkeypatch.undo()
    again = sw.run_sweep(spec, out=out2, workers=0, progress=False)
    assert again.n_run == 0 and again.n_skipped == 6 and not sw._journal_path(out2).exists()
    # a changed metric list is another sweep: its rows run anew, the old ones are dropped
    spec2 = tiny(vary={"controller.period": "0.001:0.006:6"}, metrics={"theta_end": "final(theta_deg)"})
    assert sw.run_sweep(spec2, out=out, workers=0, progress=False).n_run == 6
    rows, _ = sw.read_results(out)
    assert len(rows) == 6 and "spin_end" not in rows[0]


def test_parquet_table_holds_parameters_metrics_series_and_version(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = tmp_path / "t.parquet"
    spec = tiny(vary={"controller.params.nu": "[3000,5000]:[4000,6000]:2"},
                random={"initial.theta": "uniform(0.1,0.2)"}, samples=2, series=["theta_deg", "spin"],
                series_points=20)
    res = sw.run_sweep(spec, out=out, workers=0, progress=False)
    t = pq.read_table(out)
    cols = set(t.column_names)
    assert {"run_id", "index", "sample", "status", "error", "gyro_sim_version", "controller.params.nu",
            "initial.theta", "series.t", "series.theta_deg", "series.spin"} <= cols
    assert set(METRICS) <= cols
    typ = t.schema.field("controller.params.nu").type
    assert pa.types.is_list(typ) and pa.types.is_float64(typ.value_type)
    rows, meta = sw.read_results(out)
    assert meta["grid"] == ["controller.params.nu"] and list(meta["random"]) == ["initial.theta"]
    assert meta["metrics"]["t_half"] == "time_below(theta_deg,9.99)" and meta["gyro_sim_version"] == gyro_sim.__version__
    assert meta["complete"] is True and meta["scene"]["name"] == "nutation_oblate"
    assert [r["controller.params.nu"] for r in rows] == [[3000.0, 5000.0]] * 2 + [[4000.0, 6000.0]] * 2
    assert all(len(r["series.t"]) <= 20 and len(r["series.theta_deg"]) == len(r["series.t"]) for r in rows)
    assert rows[0]["series.theta_deg"][-1] == pytest.approx(rows[0]["theta_end"])
    assert rows == [{k: r[k] for k in rows[0]} for r in res.rows]


def test_a_variants_scene_is_built_once(monkeypatch):
    """Each variant's scene is built and validated once per sweep, where it runs (it was built twice: validated by
    the driver, then built again for the run); an invalid variant is still recorded with the loader's message."""
    from gyro_sim.apps import sweep_spec

    calls = []
    real = sweep_spec._scene_for

    def counting(*a, **k):
        calls.append(a[2])
        return real(*a, **k)

    monkeypatch.setattr(sweep_spec, "_scene_for", counting)
    monkeypatch.setattr(sweep_exec, "_scene_for", counting)
    spec = tiny(vary={"controller.period": "0.001,0.002", "initial.theta": "0.2,3.5"},
                random={"initial.psi": "uniform(0, 6.28)"}, samples=2)
    res = sw.run_sweep(spec, workers=0, progress=False)
    assert len(res.rows) == 8 and res.n_invalid == 4 and res.n_run == 4
    assert sorted(map(str, calls)) == sorted(str(v.values) for v in spec.variants())  # one build per variant
    assert all("initial.theta" in r["error"] for r in res.rows if r["status"] == "invalid")


def test_journal_is_written_in_batches(tmp_path, monkeypatch):
    """The journal takes a sweep's finished rows in batches (one write and flush per JOURNAL_SECONDS, and at the
    end), not a line and a flush per run; a hard stop before the table is written still finds every finished run."""
    from gyro_sim.apps import sweep_io

    monkeypatch.setattr(sweep_io, "JOURNAL_SECONDS", 3600.0)
    out = tmp_path / "j.parquet"
    sizes = []
    real = sw._run_scene

    def watch(scene):
        path = sw._journal_path(out)
        sizes.append(path.stat().st_size if path.exists() else 0)
        return real(scene)

    def no_disk(*a, **k):
        raise OSError("disk gone")

    monkeypatch.setattr(sweep_exec, "_run_scene", watch)
    monkeypatch.setattr(sweep_exec, "write_results", no_disk)
    spec = tiny(vary={"controller.period": "0.001:0.006:6"})
    with pytest.raises(OSError):
        sw.run_sweep(spec, out=out, workers=0, progress=False)
    assert sizes == [0] * 6  # nothing written while the runs went on
    assert len(sw._read_journal(sw._journal_path(out))) == 6  # all of them at the end, in one write
    j = sweep_io.Journal(tmp_path / "x.jsonl", seconds=0.0)
    j.add([{"a": 1}, {"a": 2}])
    j.add([{"a": 3}])
    j.close()
    assert j.writes == 2 and len(sw._read_journal(tmp_path / "x.jsonl")) == 3  # seconds=0: a write per batch


def test_seeds_are_recorded_per_run(tmp_path):
    """Each row holds the seed of its random draws (with its sample number they give its values again); a row
    that draws nothing has none."""
    out = tmp_path / "s.parquet"
    spec = tiny(vary={"controller.period": "0.001,0.002"}, random={"initial.psi": "uniform(0, 6.28)"}, samples=2,
                seed=41)
    sw.run_sweep(spec, out=out, workers=0, progress=False)
    rows, _ = sw.read_results(out)
    assert [r["seed"] for r in rows] == [41] * 4 and [r["sample"] for r in rows] == [0, 1, 0, 1]
    (rv,) = spec.random
    assert all(r["initial.psi"] == rv.draw(r["seed"], r["sample"]) for r in rows)
    grid = sw.run_sweep(tiny(), out=tmp_path / "g.parquet", workers=0, progress=False)
    assert {r["seed"] for r in grid.rows} == {None}
    with pytest.raises(sw.SweepError, match="reserved"):
        sw.parse_metric("seed=final(spin)")


def test_progress_bar_shows_runs_per_second_and_time_left():
    import io

    text = io.StringIO()
    bar = sweep_exec._Progress(10, 2, "demo", True, stream=text)
    bar.update([{"status": "ok"}, {"status": "failed"}])
    bar.close()
    line = text.getvalue().strip().splitlines()[-1]
    assert "4/10 runs" in line and "1 failed" in line and "runs/s" in line and "ETA" in line, line


def test_plots(tmp_path):
    one = sw.run_sweep(tiny(), workers=0, progress=False)
    two = sw.run_sweep(tiny(vary={"controller.period": "0.001,0.002,0.003", "initial.theta": "0.1,0.2,4.0"}),
                       workers=0, progress=False)
    mc = sw.run_sweep(tiny(vary={}, random={"initial.theta": "uniform(0.1,0.3)"}, samples=12), workers=0,
                      progress=False)
    for name, r in (("one", one), ("two", two), ("mc", mc)):
        png = tmp_path / f"{name}.png"
        fig = sw.plot_sweep(r.rows, r.spec.meta(), png)
        assert fig.axes and png.stat().st_size > 20_000 and not png.with_name(png.name + ".tmp").exists()
        with open(png, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------------------
# command line and built-in sweep files
# ------------------------------------------------------------------------------------------
def test_builtin_sweep_files_load_and_every_variant_validates():
    names = sw.builtin_sweeps()
    assert {"sweep_psi_rate", "sweep_k310_cycles", "sweep_k37_equilibria"} <= set(names)
    assert not set(names) & set(gyro_sim.builtin_scenes())  # sweep files are not scenes
    for name in names:
        spec = sw.load_sweep(name)
        vs = spec.variants()
        for v in vs:
            spec.scene_for(v.values)
        print(f"  {name}: {len(vs)} variants of {spec.scene_ref}, metrics {[m.name for m in spec.metrics]}")
    k310 = sw.load_sweep("sweep_k310_cycles")
    p = [sw._k_metric(k310.scene_for(v.values), "p", []) for v in k310.variants()]
    pstar = sw._k_metric(k310.scene_for(k310.variants()[0].values), "p_star", [])
    assert min(map(abs, p)) < pstar < max(map(abs, p))  # the grid crosses the (3.10) boundary
    k37 = sw.load_sweep("sweep_k37_equilibria")
    s = [sw._k_metric(k37.scene_for(v.values), "s", []) for v in k37.variants()]
    assert min(map(abs, s)) < 1 < max(map(abs, s))  # and the (3.7) boundary


def test_cli(tmp_path, capsys):
    assert sw.sweep_main(["sweep_psi_rate", "--dry-run"]) == 0
    assert "sweep psi_rate: 76 variants, 0 invalid" in capsys.readouterr().out
    for argv, msg in ((["nutation_oblate", "--vary", "controller.period=1:2"], "START:STOP:N"),
                      (["nutation_oblate", "--metric", "final(nope)"], "unknown quantity"),
                      (["nutation_oblate", "--random", "initial.theta=uniform(0,1)"], "samples"),
                      (["no_such_scene"], "no such file"),
                      (["nutation_oblate", "--batch", "0"], "--batch"),
                      (["nutation_oblate", "--batch", "some"], "--batch")):
        assert sw.sweep_main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and msg in err and err.count("\n") == 1, err
    out = tmp_path / "cli.parquet"
    argv = ["nutation_oblate", "--vary", "controller.period=0.001,0.002", "--vary", "initial.theta=0.1,4",
            "--set", "duration=0.02", "--metric", "th=final(theta_deg)", "--workers", "0", "--out", str(out), "--quiet"]
    assert sw.sweep_main(argv) == 0
    text = capsys.readouterr().out
    assert "4 variants (2 run now, 0 from" in text and "2 invalid" in text and out.is_file()
    assert out.with_suffix(".png").is_file()
    assert sw.sweep_main(argv) == 0
    assert "(0 run now, 2 from" in capsys.readouterr().out
    assert sw.sweep_main([str(out), "--no-plot"]) == 0
    shown = capsys.readouterr().out
    assert "initial.theta" in shown and "invalid" in shown
    bad = ["nutation_oblate", "--vary", "initial.theta=3.5,4", "--set", "duration=0.02", "--workers", "0", "--out",
           str(tmp_path / "bad.parquet"), "--quiet", "--no-plot"]
    assert sw.sweep_main(bad) == 1  # every variant invalid: recorded, status 1


def test_core_needs_no_dask(tmp_path):
    """The spec, variants, metrics and in-process runs import neither dask, distributed, tqdm nor pyarrow."""
    code = f"""
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('dask', 'distributed', 'tqdm', 'pyarrow'):
            raise ImportError('blocked ' + name)
sys.meta_path.insert(0, Block())
from gyro_sim.apps import sweep as sw
spec = sw.spec_from_dict({{'scene': 'nutation_oblate', 'set': {TINY!r}, 'vary': {{'controller.period': '0.001,0.002'}}}})
res = sw.run_sweep(spec, workers=0, progress=True)
assert [r['status'] for r in res.rows] == ['ok', 'ok'], res.rows
try:
    sw.run_sweep(spec, workers=1)
except sw.SweepError as e:
    print('refused:', e)
print('no dask:', not any(m.split('.')[0] in ('dask', 'distributed') for m in sys.modules))
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "refused: run_sweep needs the 'sweep' extra: pip install 'gyro_sim[sweep]' (missing: dask, distributed); " \
           "or --workers 0" in p.stdout and "no dask: True" in p.stdout


# ------------------------------------------------------------------------------------------
# Dask: a local cluster, and a scheduler + workers as separate processes
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def reference():
    """The tiny sweep in this process (no Dask) and on a local cluster of 2 worker processes."""
    spec = tiny(vary={"controller.period": "0.001:0.006:6"}, random={"initial.psi": "uniform(0, 6.28)"}, samples=2)
    serial = sw.run_sweep(spec, workers=0, progress=False)
    t0 = time.perf_counter()
    local = sw.run_sweep(spec, workers=2, progress=False)
    print(f"\n  local cluster: start {local.startup:.2f} s, {local.n_run} runs in {local.wall:.2f} s "
          f"(total {time.perf_counter() - t0:.2f} s), {local.mode}")
    return spec, serial, local


def test_local_cluster_gives_the_in_process_numbers(reference):
    spec, serial, local = reference
    assert local.mode.startswith("local cluster (2 worker") and local.n_failed == 0
    assert metric_table(local) == metric_table(serial)
    workers = {r["worker"] for r in local.rows}
    assert all(w.startswith("tcp://127.0.0.1:") for w in workers) and len(workers) == 2


def test_batched_path_gives_the_same_numbers(reference):
    spec, serial, _ = reference
    batched = sw.run_sweep(spec, workers=2, batch=5, progress=False)
    assert metric_table(batched) == metric_table(serial)
    assert batched.tasks == 3  # (12 variants, 5 per task)


def test_tasks_are_batched_by_default():
    """``run_sweep``'s default (batch="auto") sends several variants per task once run times are known, and gives
    the numbers of one task per run and of this process bit for bit. (40 variants: the first task of each worker
    thread has one, and a fresh worker's first run, which loads the kernels, is slow; once five run times are known
    their median is a run's, ≤ 0.125 s, and a task gets at least two of the ≥ 31 variants left.)"""
    spec = tiny(vary={"controller.period": "0.001:0.006:40"}, metrics={"th": "final(theta_deg)", "sf": "final_spin"})
    serial = sw.run_sweep(spec, workers=0, progress=False)
    auto = sw.run_sweep(spec, workers=2, progress=False)
    one_each = sw.run_sweep(spec, workers=2, batch=1, progress=False)
    print(f"\n  40 variants: {auto.tasks} tasks by default, {one_each.tasks} one per run")
    assert serial.tasks == 40 and one_each.tasks == 40 and 1 < auto.tasks < 40
    assert metric_table(auto) == metric_table(one_each) == metric_table(serial)
    assert all(r["status"] == "ok" for r in serial.rows)


def test_task_sizer():
    """Variants per task: 1 until a run time is known; then TASK_SECONDS / the median run time, at most an even
    share of what is left over TASKS_AHEAD tasks per worker thread, never more than is left."""
    from gyro_sim.apps.sweep_tasks import TASKS_AHEAD, TaskSizer

    t = TaskSizer(slots=2, task_seconds=0.25)
    assert t.next_size(128) == 1 and t.next_size(0) == 0
    t.note([{"status": "ok", "wall_time_run": x} for x in (0.01, 0.012, 0.3)]  # a first run: the median ignores it
           + [{"status": "failed", "wall_time_run": 5.0}, {"status": "ok", "wall_time_run": 0.0}])
    assert t.run_seconds() == 0.012
    assert t.next_size(1000) == int(0.25 / 0.012) == 20
    assert t.next_size(40) == 40 // (TASKS_AHEAD * 2) == 10  # the tail shrinks: the workers finish together
    assert t.next_size(1) == 1
    slow = TaskSizer(slots=2)
    slow.note([{"status": "ok", "wall_time_run": 2.0}])
    assert slow.next_size(100) == 1  # runs longer than a task: one each
    t.note([{"status": "ok", "wall_time_run": 0.001}] * 300)  # the latest run times rule
    assert t.run_seconds() == 0.001 and t.next_size(10_000) == 250


def test_kernels_called_from_python_release_the_gil():
    """The compiled kernels a run calls from Python release the GIL (``nogil=True``): in a Dask worker the event
    loop's thread then takes it without making the run's thread give it up (a run cost 2–5 % more CPU in a worker
    than in-process with them holding it, the same without)."""
    from gyro_sim.compiled import frozen_flow
    from gyro_sim.compiled import kernels

    for k in (kernels.integrate, kernels.integrate_free, kernels.record_sample, frozen_flow.integrate_frozen):
        assert k.targetoptions.get("nogil") is True, k.py_func.__name__


def test_local_cluster_workers_run_without_the_profiler():
    """Dask's statistical profiler samples the running task's stack every 10 ms from a thread of the worker (5–6 %
    of a core besides the runs): the local cluster's workers have it off."""
    import dask

    client, cluster, n, _ = sw._dask_client(1, None)
    try:
        on = client.run(lambda: dask.config.get("distributed.worker.profile.enabled"))
        assert n == 1 and list(on.values()) == [False]
        # one thread per pool (numba, OpenMP, BLAS): the workers do not fight over the cores
        env = client.run(lambda: {k: os.environ.get(k) for k in sweep_tasks.WORKER_THREADS_ENV})
        assert list(env.values()) == [{k: "1" for k in sweep_tasks.WORKER_THREADS_ENV}]
    finally:
        client.close()
        cluster.close()
    assert dask.config.get("distributed.worker.profile.enabled") is True  # (this process's setting untouched)


def _loaded_kernels() -> int:
    """Compiled kernel versions loaded in this process (numba dispatchers of gyro_sim's and gyro_ctl's modules)."""
    from numba.core.registry import CPUDispatcher

    mods = [m for name, m in list(sys.modules.items())
            if m is not None and name.split(".")[0] in ("gyro_sim", "gyro_ctl")]
    return sum(len(v.overloads) for m in mods for v in list(vars(m).values()) if isinstance(v, CPUDispatcher))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the local cluster forks its workers on Linux only")
def test_local_cluster_workers_start_warm():
    """On Linux the local cluster's workers are forked from this process after its warm-up run: they start with
    gyro_sim imported and the sweep's kernels loaded (with spawn each imported and loaded them anew: 2 s of CPU for 2
    workers, more than 128 runs of the default scene), and give the same numbers (test_local_cluster_gives_...)."""
    spec = tiny()
    payload, items = spec.payload(), [(v.run_id, v.values) for v in spec.variants()]
    sweep_exec.warm_up({**payload, "set": {**payload["set"], "initial.theta": 9.0}}, items)  # invalid: no raise
    client, cluster, n, _ = sw._dask_client(2, None, warm=lambda: sweep_exec.warm_up(payload, items))
    try:
        here = _loaded_kernels()
        there = client.run(_loaded_kernels)  # (before any task)
        assert here > 0 and list(there.values()) == [here, here]
    finally:
        client.close()
        cluster.close()


def test_tasks_are_awaited_on_their_clients_loop(monkeypatch):
    """The driver waits for its tasks on its own client's event loop, also when another client was made after it in
    this process (Dask's default client): on that one's loop the ends of the tasks were seen late (7 runs/s instead of
    80 in the benchmark, which holds a local cluster and a scheduler's client at once)."""
    import distributed

    from gyro_sim.apps.sweep_tasks import run_adaptive, run_fixed

    loops = []
    real = distributed.as_completed

    def spy(*a, **k):
        loops.append(k.get("loop"))
        return real(*a, **k)

    monkeypatch.setattr(distributed, "as_completed", spy)
    spec = tiny(vary={"controller.period": "0.001:0.003:3"}, metrics={"th": "final(theta_deg)"})
    payload, items = spec.payload(), [(v.run_id, v.values) for v in spec.variants()]
    client, cluster, _, _ = sw._dask_client(1, None)
    other = distributed.Client(cluster.scheduler_address)  # made last: the default client
    try:
        assert distributed.default_client() is other
        rows: list = []
        run_adaptive(client, sweep_exec.run_chunk, payload, items, rows.extend)
        run_fixed(client, sweep_exec.run_chunk, payload, items, 2, rows.extend)
        assert sorted(r["run_id"] for r in rows) == sorted(2 * [i[0] for i in items])
        assert all(r["status"] == "ok" for r in rows) and loops == [client.loop, client.loop]
    finally:
        other.close()
        client.close()
        cluster.close()


@pytest.fixture
def dask_processes(tmp_path):
    """A ``dask scheduler`` and ``dask worker --nworkers 2`` as separate processes, on 127.0.0.1 only
    (:func:`gyro_sim.apps.bench_sweep.scheduler_processes`: every process group is ended, TERM then KILL, whatever
    the test does); yields the scheduler file."""
    from gyro_sim.apps.bench_sweep import scheduler_processes

    with scheduler_processes(str(tmp_path), 2):
        yield tmp_path / "scheduler.json"


def test_scheduler_processes_give_the_local_numbers(reference, dask_processes):
    spec, serial, local = reference
    sched_file = dask_processes
    address = json.loads(sched_file.read_text())["address"]
    assert address.startswith("tcp://127.0.0.1:")
    t0 = time.perf_counter()
    remote = sw.run_sweep(spec, scheduler=address, progress=False)
    print(f"\n  {remote.mode}: {remote.workers} workers, {remote.n_run} runs in {remote.wall:.2f} s "
          f"(connect {remote.startup:.2f} s, total {time.perf_counter() - t0:.2f} s)")
    assert remote.mode == f"scheduler {address}" and remote.n_failed == 0
    assert metric_table(remote) == metric_table(local) == metric_table(serial)
    workers = {r["worker"].rsplit("/pid", 1)[0] for r in remote.rows}
    assert workers and all(w.startswith("tcp://127.0.0.1:") for w in workers)
    assert not workers & {r["worker"].rsplit("/pid", 1)[0] for r in local.rows}  # not the local cluster's
    pids = {int(r["worker"].rsplit("/pid", 1)[1]) for r in remote.rows}
    assert os.getpid() not in pids
    # the scheduler file works as the address too
    again = sw.run_sweep(spec, scheduler=str(sched_file), progress=False)
    assert metric_table(again) == metric_table(local)


def test_measure_reports_the_figures(capsys):
    spec = tiny(vary={"controller.period": "0.001:0.002:24"}, metrics={"th": "final(theta_deg)"})
    out = sw.measure(spec, workers=2, noop_tasks=100)
    text = capsys.readouterr().out
    with capsys.disabled():
        print("\n" + text)
    assert out["workers"] == 2 and out["runs"] == 24 and out["batch"] == 3
    for k in sw.MEASURE_CONFIGS:
        o = out[k]
        assert o["runs_per_s"] > 0 and o["failed"] == 0 and o["speedup"] > 0
        assert o["run_wall"] > 0 and o["run_cpu"] > 0 and o["run_wall_ratio"] > 0 and o["run_cpu_ratio"] > 0
    assert out["one_worker"]["tasks"] == out["all_workers"]["tasks"] == 24 and out["batched"]["tasks"] == 8
    assert 1 < out["all_workers_auto"]["tasks"] < 24
    assert out["serial"]["run_cpu"] > 0 and out["serial_before"]["runs_per_s"] > 0 and out["serial_after"]["runs_per_s"] > 0
    assert 0 < out["scaling_efficiency"] < 1.5 and out["batched_speedup"] > 0 and out["noop_per_task"] > 0
    assert "efficiency" in text and "batched speed-up" in text and "auto batch" in text and "ms CPU" in text
    part = sw.measure(spec, workers=1, noop_tasks=0, configs=("one_worker_auto",), repeats=2, each_round=lambda: 7)
    assert set(sw.MEASURE_CONFIGS) & set(part) == {"one_worker_auto"} and "noop_per_task" not in part
    assert part["repeats"] == 2 and part["rounds"] == [7, 7] and "fastest of 2 passes" in capsys.readouterr().out
    with pytest.raises(sw.SweepError, match="unknown configuration"):
        sw.measure(spec, workers=1, configs=("three_workers",))


@pytest.mark.parametrize("hidden", [("pyarrow",), ("pyarrow", "dask", "distributed")])
def test_missing_pyarrow_hint_says_what_to_install(hidden, monkeypatch, tmp_path, capsys):
    """Without pyarrow and Dask the hint said "or --workers 0", which fails the same way (the results table is
    Parquet either way): the line says what to install, with or without --workers 0."""
    for name in hidden:
        monkeypatch.setitem(sys.modules, name, None)
    lines = []
    for workers in ([], ["--workers", "0"]):
        code = sw.sweep_main(["nutation_oblate", "--vary", "controller.period=0.001,0.002", "--out",
                              str(tmp_path / "r.parquet"), "--quiet", "--no-plot", *workers])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, (code, err)
        lines.append(err[0])
    for line in lines:
        assert "pip install 'gyro_sim[sweep]' (missing: pyarrow" in line and "--workers 0" not in line, line
    assert all(line.startswith("error: gyro-sim sweep needs") for line in lines)
    assert not (tmp_path / "r.parquet").exists()
