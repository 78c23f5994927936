"""The edges of the gyro-sim command (issue 21): a missing optional dependency is one ``error:`` line naming its
extra, before any work; stdout closed early ends a command quietly; ``gyro-sim info`` is tidy."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from gyro_sim.apps import cli

from gyro_sim.common import extras
from gyro_sim.apps import sweep as sweep_mod

ROOT = Path(__file__).resolve().parents[1]


def hide(monkeypatch, *modules):
    """Make ``modules`` unimportable in this process (as if their extra were not installed)."""
    for m in modules:
        monkeypatch.setitem(sys.modules, m, None)


# --- missing extras ---------------------------------------------------------------------------------------

def test_require_names_the_extra(monkeypatch):
    hide(monkeypatch, "foxglove")
    with pytest.raises(extras.MissingExtra) as exc:
        extras.require("live", "gyro-sim run --live")
    assert str(exc.value) == "gyro-sim run --live needs the 'live' extra: pip install 'gyro_sim[live]' (missing: foxglove)"
    assert isinstance(exc.value, ImportError) and exc.value.extra == "live" and exc.value.modules == ("foxglove",)
    hide(monkeypatch, "pandas")
    with pytest.raises(extras.MissingExtra, match=r"^RunResult.to_dataframe\(\) needs the 'data' extra: pip install "
                                                  r"'gyro_sim\[data\]' \(missing: pandas\)$"):
        extras.require("data", "RunResult.to_dataframe()", ("pandas",))
    extras.require("data", "RunResult.to_xarray()", ("xarray",))  # (installed here: no error)


def test_every_extra_of_the_package_is_known():
    from test_packaging import pyproject

    declared = set(pyproject()["project"]["optional-dependencies"])
    assert declared - {"test"} == set(extras.EXTRAS)
    assert extras.extra_of("rcl_interfaces") == "ros" and extras.extra_of("numpy") is None


def one_error(capsys, status, extra):
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    assert len(err.splitlines()) == 1 and err.startswith("error: "), err
    assert f"pip install 'gyro_sim[{extra}]'" in err, err
    return err


@pytest.mark.parametrize("hidden,extra,tail", [
    (("pyarrow",), "sweep", ["--workers", "0"]),
    (("distributed",), "sweep", []),
    (("dask", "distributed", "pyarrow"), "sweep", []),
])
def test_sweep_without_its_extra_runs_nothing(monkeypatch, tmp_path, capsys, hidden, extra, tail):
    hide(monkeypatch, *hidden)
    ran = []
    monkeypatch.setattr(sweep_mod, "run_sweep", lambda *a, **k: ran.append(a))
    monkeypatch.setattr(sweep_mod, "load_sweep", lambda *a, **k: ran.append(a))
    monkeypatch.chdir(tmp_path)
    status = cli.main(["sweep", "spinup_thin_shell", "--vary", "stators.0.current=0.1:0.2:2",
                       "--out", str(tmp_path / "s.parquet"), *tail])
    err = one_error(capsys, status, extra)
    assert "gyro-sim sweep needs the 'sweep' extra" in err and hidden[0] in err
    assert ran == [] and list(tmp_path.iterdir()) == []  # nothing loaded, run or written


def test_run_sweep_checks_pyarrow_before_any_run(monkeypatch, tmp_path):
    """The API too: without pyarrow, run_sweep(out=...) used to run every variant, then fail writing Parquet."""
    hide(monkeypatch, "pyarrow")
    spec = SimpleNamespace(variants=lambda: pytest.fail("variants made before the check"))
    with pytest.raises(sweep_mod.SweepError, match=r"^run_sweep needs the 'sweep' extra: .*\(missing: pyarrow\)$"):
        sweep_mod.run_sweep(spec, out=tmp_path / "s.parquet", workers=0)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv,needs", [
    (["x.parquet"], {"pyarrow"}),
    (["s", "--dry-run"], set()),
    (["s", "--workers", "0"], {"pyarrow"}),
    (["s"], {"pyarrow", "dask", "distributed"}),
    (["s", "--workers", "0", "--scheduler", "tcp://h:1"], {"pyarrow", "dask", "distributed"}),
    (["s", "--measure", "--workers", "0"], {"dask", "distributed"}),
])
def test_what_each_sweep_command_needs(monkeypatch, argv, needs):
    args = sweep_mod.build_parser().parse_args(argv)
    for module in ("pyarrow", "dask", "distributed"):
        with monkeypatch.context() as m:
            hide(m, module)
            try:
                sweep_mod._check_command_extras(args)
                needed = False
            except extras.MissingExtra:
                needed = True
        assert needed == (module in needs), (argv, module)


def test_api_docs_without_pdoc(monkeypatch, tmp_path, capsys):
    hide(monkeypatch, "pdoc")
    err = one_error(capsys, cli.main(["api-docs", str(tmp_path / "api")]), "docs")
    assert err == "error: gyro-sim api-docs needs the 'docs' extra: pip install 'gyro_sim[docs]' (missing: pdoc)\n"
    assert list(tmp_path.iterdir()) == []


def test_run_ros_without_rclpy(monkeypatch, tmp_path, capsys):
    hide(monkeypatch, "rclpy")
    err = one_error(capsys, cli.main(["run", "free_rotor", "--ros", "--out", str(tmp_path / "o")]), "ros")
    assert err.startswith("error: gyro-sim run --ros needs the ROS 2 Python packages (rclpy)")
    assert list(tmp_path.iterdir()) == []


def test_a_command_raising_missing_extra_is_one_error_line(monkeypatch, capsys):
    """How a command of another part (e.g. run --live) reports its extra: raise MissingExtra, main says it."""
    hide(monkeypatch, "foxglove")

    def needs_live(args):
        extras.require("live", "gyro-sim run --live")
        pytest.fail("went on without its extra")

    monkeypatch.setattr(cli, "_cmd_scenes", needs_live)
    err = one_error(capsys, cli.main(["scenes"]), "live")
    assert err == ("error: gyro-sim run --live needs the 'live' extra: pip install 'gyro_sim[live]' "
                   "(missing: foxglove)\n")


# --- stdout closed early ----------------------------------------------------------------------------------

def closed_pipe_run(argv, unbuffered):
    """Run gyro-sim with stdout a pipe whose reader is gone before the command starts (so no output can slip
    into the pipe's buffer first; `gyro-sim scenes | head -1` where head has already exited), stdout buffered or
    not (PYTHONUNBUFFERED: the write or the final flush fails)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    env.update(PYTHONPATH=str(ROOT), **({"PYTHONUNBUFFERED": "1"} if unbuffered else {}))
    r, w = os.pipe()
    os.close(r)
    try:
        return subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", *argv], stdout=w, stderr=subprocess.PIPE,
                              text=True, timeout=300, cwd=ROOT, env=env)
    finally:
        os.close(w)


@pytest.mark.parametrize("unbuffered", [False, True])
@pytest.mark.parametrize("argv", [
    ["scenes"], ["sweep", "sweep_psi_rate", "--dry-run"],
    ["flywheel-plan", "--inertia", "1", "1", "1.5", "--wheel-inertia", "0.01", "--target-euler", "0", "0.3", "0"],
])
def test_stdout_closed_early_exits_quietly(argv, unbuffered):
    """Status 141 (128 + SIGPIPE, as a shell reports `yes | head -1`), nothing on stderr (no BrokenPipeError
    traceback, no 'Exception ignored')."""
    p = closed_pipe_run(argv, unbuffered)
    assert (p.returncode, p.stderr) == (cli.EXIT_BROKEN_PIPE, ""), p.stderr


@pytest.mark.parametrize("unbuffered", [False, True])
@pytest.mark.parametrize("argv", [["--help"], ["bench", "--help"], ["sweep", "--help"]])
def test_help_into_a_closed_pipe_is_quiet(argv, unbuffered):
    """argparse's own output: it ignores a failed write itself (its status, 0), or the flush after it fails (141)."""
    p = closed_pipe_run(argv, unbuffered)
    assert p.stderr == "" and p.returncode in (0, cli.EXIT_BROKEN_PIPE), (p.returncode, p.stderr)


def test_a_pipe_read_to_its_end_is_status_0():
    p = subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", "scenes"], capture_output=True, text=True,
                       timeout=300, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert p.returncode == 0 and p.stderr == "" and "spinup_thin_shell" in p.stdout


# --- gyro-sim info ----------------------------------------------------------------------------------------

def bag_info(**custom):
    """What gyro_sim.io.recording.bag_info returns for a recorded in-process run (custom_data as the recorder
    writes)."""
    base = {"gyro_sim.scene_name": "free_rotor", "gyro_sim.version": "0.1.0", "gyro_sim.end": "complete",
            "gyro_sim.scene": "name: free_rotor\n", "gyro_sim.duration": "0.1", "gyro_sim.planned_duration": "0.1",
            "gyro_sim.wall_time": "0.40716126800009533", "gyro_sim.compile_time": "9.97845357899996",
            "gyro_sim.steps": "41",
            "gyro_sim.error_estimate": '{"L":0.0,"attitude":5.770445481674697e-15,"steps_L":0.0,'
                                       '"steps_attitude":5.770445481674697e-15,"modes_L":0.0,"modes_attitude":0.0,'
                                       '"averaged_L":0.0,"steps_method":"richardson","rtol":1e-06,"atol":1e-06,'
                                       '"met":true}'}
    base.update({f"gyro_sim.{k}": v for k, v in custom.items()})
    return {"path": "/b", "storage": "mcap", "bag_version": 8, "scene_name": "free_rotor", "version": "0.1.0",
            "start": 0.0, "end": 0.1, "duration": 0.1, "message_count": 149, "end_reason": "complete",
            "custom": base, "topics": {}}


def test_info_rows_are_tidy():
    rows = cli._info_rows(bag_info())
    labels = [a for a, _ in rows]
    assert labels.count("duration") == 1 and len(labels) == len(set(labels)), labels
    d = dict(rows)
    assert d["duration"] == "0.1 s (t = 0 to 0.1 s)"
    assert d["wall time"] == "0.407 s (+ 9.98 s compiling the kernels, first use)"
    assert d["steps"] == "41"
    assert d["estimated error"] == "L 0 (rtol 1e-06), attitude 5.8e-15 rad (1e-06)"
    assert "{" not in "".join(v for _, v in rows)  # no raw JSON
    assert max(len(a) for a in labels) <= 16  # the columns stay where they were ("messages          149")


def test_info_of_a_run_cut_short_and_of_other_keys():
    d = dict(cli._info_rows(bag_info(planned_duration="60", wall_time="1234.5678", compile_time="0",
                                     mode="lockstep", control_period="0.02", something_new="x")))
    assert d["duration"] == "0.1 s (t = 0 to 0.1 s; planned 60 s)"
    assert d["wall time"] == "1235 s" and d["mode"] == "lockstep" and d["control period"] == "0.02 s"
    assert d["something new"] == "x"


def test_info_prints_readable_numbers():
    """A ROS run's figures (issue 30: 'control ticks per s 72.60114958780215'): 4 significant digits, times below
    1 s in ms with their unit, integers and texts as they are."""
    d = dict(cli._info_rows(bag_info(control_ticks_per_s="72.60114958780215", latency_median_s="0.000412345",
                                     latency_max_s="1.5", controller_lost="t = 0.1 s: its process ended (stop)")))
    assert d["control ticks per s"] == "72.6"
    assert d["latency median"] == "0.412 ms" and d["latency max"] == "1.5 s"
    assert d["controller lost"] == "t = 0.1 s: its process ended (stop)"


def test_info_of_a_recorded_bag(tmp_path, capsys):
    import gyro_sim
    from gyro_sim.io.recording import record_run

    record_run(gyro_sim.load_scene("free_rotor"), tmp_path / "bag", duration=0.05)
    assert cli.main(["info", str(tmp_path / "bag")]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert [line.split("  ")[0] for line in lines].count("duration") == 1, out
    wall = next(line for line in lines if line.startswith("wall time"))
    assert wall.split()[2:4][1] == "s" and len(wall.split()[2].replace(".", "").lstrip("0")) <= 3, wall
    assert "messages          " in out and "estimated error   L " in out
