"""The gyro-sim command and the run plot, against a fake scene loader and simulator.

The fakes stand in for gyro_sim.scenes.scene and gyro_sim.engine.simulate (monkeypatched into
sys.modules and onto the gyro_sim package), so these tests say what the CLI does
with any implementation of that interface.
"""
from __future__ import annotations

import dataclasses
import importlib
import math
import re
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.apps import cli

from gyro_sim.io import plotting

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# --- fakes ------------------------------------------------------------------

class FakeSceneError(Exception):
    pass


@dataclasses.dataclass
class FakeScene:
    name: str
    description: str
    duration: float


@dataclasses.dataclass
class FakeRunResult:
    t: np.ndarray
    L: np.ndarray
    q: np.ndarray
    omega_b: np.ndarray
    euler: np.ndarray
    torque: np.ndarray
    energy: np.ndarray
    stator_names: list
    current: np.ndarray
    field_rate: np.ndarray
    field_phase: np.ndarray
    wall_time: float
    steps: int
    scene: FakeScene

    def summary(self) -> dict:
        spin = float(self.omega_b[-1, 2])
        return {
            "spin_rate": spin,
            "spin_rev_s": spin / (2 * math.pi),
            "theta_deg": math.degrees(self.euler[-1, 1]),
            "L_norm": float(np.linalg.norm(self.L[-1])),
            "energy": float(self.energy[-1]),
            "t_end": float(self.t[-1]),
            "wall_time": self.wall_time,
            "steps": self.steps,
            "realtime_factor": float(self.t[-1]) / self.wall_time,
        }

    def preview(self) -> "FakeRunResult":  # (RunResult.preview: itself when in memory)
        return self


def fake_result(scene: FakeScene, duration: float | None = None, n: int = 2001,
                stators=("x", "y", "z")) -> FakeRunResult:
    """A spin-up: Ω_b3 rises linearly to 100·2π rad/s, θ decays from 10°."""
    t_end = scene.duration if duration is None else duration
    t = np.linspace(0.0, t_end, n)
    omega3 = 2 * math.pi * 100.0 * t / t_end
    omega_b = np.column_stack([0.01 * np.ones(n), np.zeros(n), omega3])
    theta = np.radians(10.0) * np.exp(-t / t_end)
    euler = np.column_stack([np.zeros(n), theta, omega3 * t])
    inertia = 2e-5  # kg·m²
    L = inertia * omega_b
    k = len(stators)
    return FakeRunResult(
        t=t, L=L, q=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), omega_b=omega_b, euler=euler,
        torque=np.zeros((n, 3)), energy=0.5 * inertia * np.sum(omega_b**2, axis=1),
        stator_names=list(stators),
        current=np.column_stack([np.full(n, 1.0 + j) for j in range(k)]) if k else np.zeros((n, 0)),
        field_rate=np.zeros((n, k)), field_phase=np.zeros((n, k)),
        wall_time=0.5, steps=1234, scene=scene,
    )


SCENES = {
    "spinup_thin_shell": FakeScene("spinup_thin_shell", "Spin-up of a thin shell.\nMore text.", 2.0),
    "steer_solid": FakeScene("steer_solid", "Steering a solid sphere.", 4.0),
}


@pytest.fixture
def fakes(monkeypatch, tmp_path):
    """Install fake gyro_sim.scenes.scene / gyro_sim.engine.simulate; record the calls made."""
    calls = {"load": [], "run": []}
    scene_mod = types.ModuleType("gyro_sim.scenes.scene")  # (the homes the cli imports from; issue 22)
    sim_mod = types.ModuleType("gyro_sim.engine.simulate")

    def load_scene(name_or_path, overrides=None):
        calls["load"].append(name_or_path)
        calls.setdefault("overrides", []).append(overrides)
        key = Path(str(name_or_path)).stem
        if key not in SCENES:
            raise FakeSceneError(f"no scene named {name_or_path!r}")
        return SCENES[key]

    def builtin_scenes():
        return {name: tmp_path / f"{name}.yaml" for name in SCENES}

    def run(scene, duration=None, on_samples=None):
        calls["run"].append((scene, duration))
        return fake_result(scene, duration)

    scene_mod.SceneError = FakeSceneError
    scene_mod.load_scene = load_scene
    scene_mod.builtin_scenes = builtin_scenes
    sim_mod.run = run
    for mod in (scene_mod, sim_mod):
        monkeypatch.setitem(sys.modules, mod.__name__, mod)
        parent, _, child = mod.__name__.rpartition(".")
        monkeypatch.setattr(importlib.import_module(parent), child, mod, raising=False)
    # (the limits --duration meets read a real scene's output and model: not these fakes')
    monkeypatch.setattr(importlib.import_module("gyro_sim.engine.budget"), "check_run_size", lambda *a, **k: None)
    return calls


# --- parser and --help ------------------------------------------------------

@pytest.mark.parametrize("argv, expected", [
    (["--help"], ["run", "scenes"]),
    (["run", "--help"], ["SCENE", "--duration", "--out"]),
    (["scenes", "--help"], ["built-in scenes"]),
])
def test_help_exits_0_and_names_the_options(capsys, argv, expected):
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for word in expected:
        assert word in out, f"{word!r} missing from help of {argv}:\n{out}"


def test_no_command_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main([])
    assert exc.value.code == 2
    assert "COMMAND" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["0", "-1", "nan", "abc"])
def test_duration_must_be_positive_seconds(capsys, bad):
    with pytest.raises(SystemExit) as exc:
        cli.main(["run", "spinup_thin_shell", "--duration", bad])
    assert exc.value.code == 2
    assert "duration" in capsys.readouterr().err


@pytest.mark.parametrize("argv,fragment", [
    (["--rate", "0"], "--rate 0.0: must be a positive number"),
    (["--wait-for-subscribers", "-1"], "--wait-for-subscribers -1: must be an integer ≥ 0"),
])
def test_replay_refuses_bad_options_before_starting_ros(capsys, tmp_path, argv, fragment):
    assert cli.main(["replay", str(tmp_path), *argv]) == 2
    assert fragment in capsys.readouterr().err


def test_parser_defaults():
    args = cli.build_parser().parse_args(["run", "x.yaml"])
    assert args.scene == "x.yaml"
    assert args.duration is None
    assert args.out == Path("runs")


# --- run --------------------------------------------------------------------

def test_run_prints_summary_and_writes_png(fakes, tmp_path, capsys):
    out_dir = tmp_path / "out"
    assert cli.main(["run", "spinup_thin_shell", "--out", str(out_dir)]) == 0
    stdout = capsys.readouterr().out

    assert fakes["load"] == ["spinup_thin_shell"]
    assert fakes["run"] == [(SCENES["spinup_thin_shell"], None)]

    png = out_dir / "spinup_thin_shell.png"
    assert png.read_bytes()[:8] == PNG_MAGIC

    print(stdout)
    rows = dict(re.split(r"\s{2,}", line, maxsplit=1) for line in stdout.splitlines())
    assert rows["scene"] == "spinup_thin_shell"
    # Ω_b3 = 200π rad/s = 100 rev/s at the end of the fake run
    assert rows["final spin rate"] == f"{200 * math.pi:.6g} rad/s  (100 rev/s)"
    assert rows["final θ"] == f"{10 * math.exp(-1):.6g} deg"
    L_end = 2e-5 * math.hypot(0.01, 200 * math.pi)
    assert rows["|L|"] == f"{L_end:.6g} N·m·s"
    E_end = 0.5 * 2e-5 * (0.01**2 + (200 * math.pi) ** 2)
    assert rows["kinetic energy"] == f"{E_end:.6g} J"
    assert rows["simulated time"] == "2 s"
    assert rows["wall time"] == "0.500 s"
    assert rows["steps"] == "1234"
    assert rows["real-time factor"] == "4"
    assert rows["plot"] == str(png)


def test_run_passes_duration_and_defaults_out_to_runs(fakes, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "steer_solid", "--duration", "0.25"]) == 0
    assert fakes["run"] == [(SCENES["steer_solid"], 0.25)]
    assert (tmp_path / "runs" / "steer_solid.png").stat().st_size > 0
    assert "0.25 s" in capsys.readouterr().out


def test_run_names_the_png_after_the_scene_not_the_path(fakes, tmp_path, capsys):
    path = tmp_path / "somewhere" / "steer_solid.yaml"
    assert cli.main(["run", str(path), "--out", str(tmp_path)]) == 0
    assert fakes["load"] == [str(path)]
    assert (tmp_path / "steer_solid.png").exists()


def test_scene_error_exits_2_with_message_and_no_traceback(fakes, tmp_path, capsys):
    assert cli.main(["run", "no_such_scene", "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    assert captured.err == "error: no scene named 'no_such_scene'\n"
    assert captured.out == ""
    assert fakes["run"] == []
    assert list(tmp_path.iterdir()) == []


def test_scene_error_raised_by_the_simulator_also_exits_2(fakes, monkeypatch, tmp_path, capsys):
    def bad_run(scene, duration=None, on_samples=None):
        raise FakeSceneError("stator 'x' has no coils")
    monkeypatch.setattr(sys.modules["gyro_sim.engine.simulate"], "run", bad_run)
    assert cli.main(["run", "steer_solid", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "error: stator 'x' has no coils\n"


def test_format_summary_shows_missing_keys_as_dash():
    text = cli.format_summary("s", {"spin_rate": 1.0})
    assert "1 rad/s  (- rev/s)" in text
    assert "steps" in text and text.splitlines()[-1].split()[-1] == "-"


# --- scenes -----------------------------------------------------------------

def test_scenes_lists_names_with_first_line_of_description(fakes, capsys):
    assert cli.main(["scenes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "spinup_thin_shell  Spin-up of a thin shell.",
        "steer_solid        Steering a solid sphere.",
    ]


def test_scenes_reports_a_broken_scene_and_exits_2(fakes, monkeypatch, tmp_path, capsys):
    mod = sys.modules["gyro_sim.scenes.scene"]
    good = mod.builtin_scenes
    monkeypatch.setattr(mod, "builtin_scenes", lambda: {**good(), "broken": tmp_path / "broken.yaml"})
    assert cli.main(["scenes"]) == 2
    out = capsys.readouterr().out
    assert re.search(r"^broken +\[cannot load: no scene named .*broken\.yaml", out, re.M), out
    assert "steer_solid" in out


# --- the console script -----------------------------------------------------

def test_module_help_runs_in_a_fresh_interpreter():
    proc = subprocess.run([sys.executable, "-m", "gyro_sim.apps.cli", "--help"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "usage: gyro-sim" in proc.stdout


# --- plot_run ---------------------------------------------------------------

def test_plot_run_writes_a_png(tmp_path):
    result = fake_result(SCENES["spinup_thin_shell"])
    from matplotlib.figure import Figure

    path = tmp_path / "a" / "b.png"
    fig = plotting.plot_run(result, path)
    assert isinstance(fig, Figure)
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000, f"PNG only {len(data)} bytes"
    assert not (tmp_path / "a" / "b.png.tmp").exists()


def test_plot_run_handles_a_long_run_and_no_stators(tmp_path):
    result = fake_result(SCENES["steer_solid"], n=300_001, stators=())
    fig = plotting.plot_run(result, tmp_path / "long.png")
    assert (tmp_path / "long.png").read_bytes()[:8] == PNG_MAGIC
    # thinned: no line of the figure keeps more than MAX_POINTS of the 300,001 samples
    assert max(len(line.get_xdata()) for ax in fig.axes for line in ax.get_lines()) <= plotting.MAX_POINTS


def test_decimation_keeps_at_most_5000_points_and_the_extremes():
    n = 1_000_003
    t = np.linspace(0.0, 100.0, n)
    y = np.sin(2 * np.pi * 50.3 * t) * (1 + t / 100)  # 50 Hz carrier under an envelope
    y[123_457] = 7.0  # a lone spike
    td, yd = plotting.decimate_minmax(t, y)
    print(f"{n} -> {len(td)} points")
    assert len(td) <= plotting.MAX_POINTS
    assert np.all(np.diff(td) > 0)
    assert td[0] == t[0] and td[-1] == t[-1]
    assert yd.max() == 7.0
    assert yd.min() == y.min()
    # the upper envelope at the end (≈ 2) survives thinning
    assert yd[td > 99].max() == pytest.approx(y[t > 99].max())


def test_decimation_leaves_short_series_alone():
    t = np.arange(10.0)
    td, yd = plotting.decimate_minmax(t, t**2)
    assert np.array_equal(td, t) and np.array_equal(yd, t**2)


# --- the real modules, once they exist --------------------------------------

def test_real_scene_and_simulate_modules_offer_what_the_cli_uses():
    scene = pytest.importorskip("gyro_sim.scenes.scene")
    simulate = pytest.importorskip("gyro_sim.engine.simulate")
    assert issubclass(scene.SceneError, Exception)
    assert callable(scene.load_scene) and callable(scene.builtin_scenes)
    assert callable(simulate.run)


def test_run_with_fidelity_overrides_the_scene(fakes, tmp_path):
    assert cli.main(["run", "spinup_thin_shell", "--fidelity", "auto", "--out", str(tmp_path)]) == 0
    assert fakes["overrides"] == [{"fidelity": "auto"}]
    assert cli.main(["run", "spinup_thin_shell", "--out", str(tmp_path)]) == 0
    assert fakes["overrides"][-1] is None


def test_run_with_averaged_fidelity_refuses_ros(capsys):
    assert cli.main(["run", "spinup_thin_shell", "--ros", "--fidelity", "auto"]) == 2
    assert "--fidelity auto: the ROS simulator node runs the full model" in capsys.readouterr().err


def test_run_averaged_scene_in_auto_for_real(tmp_path, capsys):
    """``gyro-sim run three_stators --fidelity auto``: the real scene, averaged throughout ([K])."""
    assert cli.main(["run", "three_stators", "--fidelity", "auto", "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "three_stators" in out and (tmp_path / "three_stators.png").stat().st_size > 0
