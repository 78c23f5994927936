"""The figures (issue 21): every plot function returns a matplotlib Figure, saves it when given a path, leaves the
backend alone; the run plot shows field rate, slip, command changes and switching instants; the phase portrait
and the bench plot say in their legends what they draw.

The run plot is checked on a synthetic run whose slip and events are known exactly (no simulation, no timing)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from gyro_sim.io import plotting
from gyro_sim.io.plotting import command_events, plot_run, slip

TWO_PI = 2.0 * math.pi
T_END = 2.0
N = 2001


def _state(t):
    """Currents (A) and signed rates (rad/s) of z1, z2, z3 at t: z1 on over [0.5, 1.5) and reversed at 1.0; z2 off
    throughout; z3 on, its current stepping 1 → 2 A at 1.2."""
    on1 = 0.5 <= t < 1.5
    cur = [0.3 if on1 else 0.0, 0.0, 2.0 if t >= 1.2 else 1.0]
    rate = [TWO_PI * (300.0 if t < 1.0 else -300.0), TWO_PI * 400.0, TWO_PI * 500.0]
    return cur, rate


def synthetic_run():
    """A spin-up about z3 (Ω₃/2π = 50 t rev/s, body = case frame) under three stators; commands every 0.1 s."""
    t = np.linspace(0.0, T_END, N)
    omega = np.column_stack([np.zeros(N), np.zeros(N), TWO_PI * 50.0 * t])
    states = [_state(x) for x in t]
    commands = []
    for k in range(20):
        tc = round(0.1 * k, 10)
        cur, rate = _state(tc)
        commands.append((tc, ["z1", "z2", "z3"], cur, rate))
    stators = [SimpleNamespace(name=n, axis=a, current=c, rate=r) for n, a, c, r in
               (("z1", [1, 0, 0], 0.0, TWO_PI * 300.0), ("z2", [0, 1, 0], 0.0, TWO_PI * 400.0),
                ("z3", [0, 0, 1], 1.0, TWO_PI * 500.0))]
    return SimpleNamespace(
        t=t, omega_b=omega, q=np.tile([1.0, 0.0, 0.0, 0.0], (N, 1)), L=1e-5 * omega,
        torque=np.column_stack([np.zeros(N), np.zeros(N), np.full(N, 2e-6)]),
        euler=np.column_stack([np.zeros(N), np.full(N, math.radians(5.0)), np.zeros(N)]),
        current=np.array([s[0] for s in states]), field_rate=np.array([s[1] for s in states]),
        stator_names=["z1", "z2", "z3"], commands=commands, attitude=True,
        scene=SimpleNamespace(name="synthetic", description="spin-up under three stators\nsecond line", stators=stators))


@pytest.fixture
def svg_backend():
    """A backend that is not Agg, as a notebook or GUI session would have; restored afterwards."""
    old = matplotlib.get_backend()
    matplotlib.use("svg")
    yield "svg"
    matplotlib.use(old)


def _axis(fig, ylabel_part):
    (ax,) = [a for a in fig.axes if ylabel_part in a.get_ylabel()]
    return ax


def _legend_texts(legend):
    return [t.get_text() for t in legend.get_texts()]


def _series_labels(ax):
    """The stators' series drawn on a panel: lines and envelopes (min–max per time bin, plotting._draw_series)."""
    labels = [h.get_label() for h in ax.get_lines() + [c for c in ax.collections if c.get_gid() == "envelope"]]
    return sorted(lab.replace(" (min–max per time bin)", "") for lab in labels if not lab.startswith("_"))


def _segments_x(ax, gid):
    (coll,) = [c for c in ax.collections if c.get_gid() == gid]
    return sorted(float(seg[0][0]) for seg in coll.get_segments())


# --- the run plot -----------------------------------------------------------------------------------------
def test_command_events_find_switching_and_changes():
    ev = command_events(synthetic_run())
    assert ev.switching.tolist() == [0.5, 1.0, 1.5]  # z1 on, z1 reversed, z1 off
    assert ev.changes.tolist() == [1.2]  # z3 1 → 2 A
    # a small continuous adjustment is no command change; rates None = unchanged; a reversal of a field that is
    # off is no switching; without the scene's stators the first command sets the state
    r = synthetic_run()
    r.scene = SimpleNamespace(name="no stators")
    r.commands = [(0.0, ["z3"], [1.0], [100.0]), (0.1, ["z3"], [1.01], None), (0.2, ["z3"], [1.01], [-100.0]),
                  (0.3, ["z1"], [0.0], [-5.0]), (0.4, ["z3"], [1.01], [-200.0])]
    ev = command_events(r)
    assert ev.switching.tolist() == [0.2] and ev.changes.tolist() == [0.4]
    assert command_events(SimpleNamespace(stator_names=["z1"])).switching.size == 0  # no commands: no events


def test_slip_is_field_rate_minus_rotor_rate_about_the_stator_axis():
    r = synthetic_run()
    s = slip(r) / TWO_PI
    t = r.t
    assert np.allclose(s[:, 2], 500.0 - 50.0 * t, atol=1e-9)  # z3: field − spin
    on1 = (t >= 0.5) & (t < 1.5)
    assert np.all(np.isnan(s[~on1, 0])) and np.allclose(np.abs(s[on1, 0]), 300.0)  # z1: spin ⟂ its axis
    assert np.all(np.isnan(s[:, 1]))  # z2 carries no current: no slip
    # the body frame turned 90° about z3 (q = (cos45°, 0, 0, sin45°)): Ω in the case frame is the same here
    r.q = np.tile([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)], (N, 1))
    assert np.allclose(slip(r)[:, 2] / TWO_PI, 500.0 - 50.0 * t, atol=1e-9)
    r.scene = SimpleNamespace(name="no stators known")
    assert slip(r) is None


def test_plot_run_returns_a_figure_with_slip_field_rate_and_command_marks(tmp_path):
    r = synthetic_run()
    fig = plot_run(r)
    assert isinstance(fig, Figure)
    assert fig.get_suptitle() == "synthetic: spin-up under three stators"
    assert fig.axes[-1].get_xlabel() == "time (s)"
    for part in ("events", "rotor rate (rev/s)", "nutation θ (deg)", "|L| (", "direction of L", "torque on rotor",
                 "stator current", "field rate ν/2π (Hz)",
                 "slip (ν − Ω·u)/2π (Hz)"):
        _axis(fig, part)
    # the slip panel: z3 = 500 − 50 t Hz, z1 ±300 Hz while on, z2 (never on) not drawn
    ax = _axis(fig, "slip")
    lines = {ln.get_label(): ln for ln in ax.get_lines() if not ln.get_label().startswith("_")}
    assert set(lines) == {"z1", "z3"}
    x, y = lines["z3"].get_xdata(), lines["z3"].get_ydata()
    assert np.allclose(y, 500.0 - 50.0 * x, atol=1e-9)
    assert np.nanmax(np.abs(lines["z1"].get_ydata())) == pytest.approx(300.0)
    # the current panel: z1 and z2 (both at 0 A for a while) in different styles; z2 says it is off
    ax = _axis(fig, "stator current")
    cur = {ln.get_label(): ln for ln in ax.get_lines()}
    assert set(cur) == {"z1", "z2 (0 A throughout)", "z3"}
    styles = {(ln.get_linestyle(), ln.get_linewidth()) for ln in cur.values()}
    assert len(styles) == 3
    texts = _legend_texts(ax.get_legend())
    assert "switching (3×):\nfield reversed or on/off" in texts and "command change (1×):\nnew current or |ν|" in texts
    # the events strip: switching ticks and the command change; the change also across every data panel
    strip = _axis(fig, "events")
    assert _segments_x(strip, "switching") == [0.5, 1.0, 1.5]
    assert _segments_x(strip, "command_changes") == [1.2]
    for ax in fig.axes[1:]:
        assert _segments_x(ax, "command_changes") == [1.2]
    # saved when given a path, atomically
    png = tmp_path / "sub" / "run.png"
    assert isinstance(plot_run(r, png), Figure)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not png.with_name("run.png.tmp").exists()


def test_plot_run_of_a_view_without_field_rates_or_commands():
    """A bag view of an old recording (no field_rate, commands, scene stators): the panels it has, no slip."""
    r = synthetic_run()
    del r.field_rate, r.commands
    r.scene = SimpleNamespace(name="old bag")
    fig = plot_run(r)
    assert not [a for a in fig.axes if "slip" in a.get_ylabel()]
    assert "no switching, no command change" in [t.get_text() for t in _axis(fig, "events").texts]


def test_a_long_run_is_thinned():
    n = 400_001
    t = np.linspace(0.0, 100.0, n)
    r = synthetic_run()
    r.t, r.omega_b = t, np.column_stack([np.zeros(n), np.zeros(n), np.sin(t)])
    r.q, r.L, r.torque = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), 1e-5 * r.omega_b, np.ones((n, 3))
    r.euler, r.current = np.zeros((n, 3)), np.ones((n, 3))
    r.field_rate = np.ones((n, 3))
    fig = plot_run(r)
    assert max(len(ln.get_xdata()) for ax in fig.axes for ln in ax.get_lines()) <= plotting.MAX_POINTS


# --- every plot function: Figure, saved, backend untouched -------------------------------------------------
def _bench_results():
    from gyro_sim.apps.bench import BenchConfig, Results, Row

    res = Results(BenchConfig(mode="quick", min_wall=0.0, max_reps=1), started="test")
    for k, m in enumerate(["gyro_sim full", "solve_ivp DOP853"]):
        for j in range(4):
            res.rows.append(Row("spinup_thin_shell", 0.05, m, "rtol", 1e-3, wall=0.02 * (j + 1), steps=10, rhs=None,
                                error=10.0 ** (-3 - 2 * j + k), cpu=0.01 * (j + 1)))
    return res


def _phase_data():
    t = np.linspace(0.0, 1.0, 200)
    euler = np.column_stack([np.zeros_like(t), np.radians(80.0 + 5.0 * t), np.radians(15.0 + 30.0 * t)])
    L = np.column_stack([np.zeros_like(t), np.zeros_like(t), np.full_like(t, 1.1e-3)])
    return SimpleNamespace(t=t, euler=euler, L=L)


def _all_plots(tmp_path):
    from gyro_sim.apps.bench import plot_work_precision
    from gyro_sim.apps.phase import plot_phase
    from gyro_sim.apps.sweep import plot_sweep

    rows = [{"status": "ok", "k": float(i), "m": float(i * i)} for i in range(5)] + [{"status": "failed", "k": 5.0}]
    meta = {"name": "s", "grid": ["k"], "metrics": {"m": "k²"}}
    return {"run": lambda p: plot_run(synthetic_run(), p),
            "phase": lambda p: plot_phase(_phase_data(), p),
            "sweep": lambda p: plot_sweep(rows, meta, p),
            "bench": lambda p: plot_work_precision(_bench_results(), p)}


def test_every_plot_function_returns_a_figure_saves_it_and_leaves_the_backend(tmp_path, svg_backend):
    for name, plot in _all_plots(tmp_path).items():
        fig = plot(None)
        assert isinstance(fig, Figure) and fig.axes, name
        assert matplotlib.get_backend() == svg_backend, name
        png = tmp_path / name / f"{name}.png"
        assert isinstance(plot(png), Figure)
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert not png.with_name(png.name + ".tmp").exists()
        assert matplotlib.get_backend() == svg_backend, name
    assert matplotlib.rcParams["backend"] == svg_backend


# --- the phase portrait and the bench plot say what they draw ----------------------------------------------
def test_phase_portrait_legend_and_title_in_words():
    from gyro_sim import load_scene
    from gyro_sim.apps.phase import plot_phase

    fig = plot_phase(_phase_data(), scene=load_scene("phase_portrait"))
    ax = fig.axes[0]
    assert ax.get_ylabel() == "nutation θ (deg): angle between the polar axis x3 and L"
    assert ax.get_xlabel().startswith("rotation angle φ of the rotor about its polar axis x3, mod 180° (deg)")
    assert fig.axes[1].get_xlabel().startswith("kinetic moment |L| / L₀\n(L₀ = J·Λ0 = ")
    texts = _legend_texts(fig.legends[0])
    for want in ("averaged motion at steady |L| (arrows: its direction)",
                 "stable equilibrium (focus): the motion spirals in", "unstable equilibrium (saddle)",
                 "run start (t = 0 s)", "run end (t = 1 s)", "steady |L| for each θ (spin drive = braking)",
                 "the equilibria (at θ = 90°)"):
        assert want in texts
    # the title says what the figure is in two lines; [K]'s symbols and predictions are defined in the legend
    title = fig.get_suptitle()
    assert title.count("\n") == 1 and "symbols in the legend" in title and "κ" not in title
    legend = " ".join(t.replace("\n", " ") for t in texts)
    for want in ("How to read: x3 is the rotor's symmetry (polar) axis, L its kinetic moment (angular momentum)",
                 "Λ0 = ", "rotor prolate: polar / transverse inertia J3/J = 0.8 (κ = J3/J − 1 = -0.2)",
                 "δ = (J2 − J1)/(J2 + J1) = +0.01: transverse asymmetry",
                 "equilibria at θ = 90°: switching torque < asymmetry torque (|s| = 0.5 ≤ 1; s = switching / "
                 "asymmetry torque)", "no limit cycles: switching torque > polar-inertia torque",
                 "p = switching / polar-inertia torque"):
        assert want in legend, want
    # an axisymmetric rotor ([K]'s s = −∞): said in words, no infinity
    fig = plot_phase(_phase_data(), scene=load_scene("nutation_oblate"))
    legend = " ".join(t.get_text().replace("\n", " ") for t in fig.legends[0].get_texts())
    assert "axisymmetric (J1 = J2, δ = 0)" in legend and "no equilibria: an axisymmetric rotor" in legend
    assert "∞" not in legend + fig.get_suptitle() and "s = " not in legend


def test_bench_plot_legend_matches_the_lines_drawn():
    from gyro_sim.apps.bench import TARGET_ERROR, plot_work_precision

    fig = plot_work_precision(_bench_results())
    (ax,) = fig.axes
    texts = _legend_texts(ax.get_legend())
    assert texts == ["gyro_sim full", "solve_ivp DOP853", "target error 1e-06 (costs compared here)"]
    lines = ax.get_lines()
    assert [ln.get_label() for ln in lines[:2]] == texts[:2] and len(lines) == 3  # two methods + the target line
    assert list(lines[2].get_xdata()) == [TARGET_ERROR, TARGET_ERROR] and lines[2].get_linestyle() == "--"
    assert "dotted" not in ax.get_ylabel() and ax.get_ylabel() == "CPU time of the run (s)"
    assert any(t.get_text().strip() == "target 1e-06" for t in ax.texts)


def test_plot_of_a_recorded_bag_shows_slip_and_switching(tmp_path):
    """`gyro-sim plot BAG` (cli._bag_result → plot_run): the bag's field rates, commands and embedded scene give
    the slip panel and the switching instants of a ψ-switching run, as the in-process run's plot has them."""
    import gyro_sim
    from gyro_sim.apps import cli
    from gyro_sim.io.recording import record_result

    r = gyro_sim.run(gyro_sim.load_scene("nutation_oblate"), duration=0.1)
    record_result(r, tmp_path / "bag")
    res = cli._bag_result(tmp_path / "bag")[0]
    ev_run, ev_bag = command_events(r), command_events(res)
    assert ev_run.switching.size > 3 and np.allclose(ev_bag.switching, ev_run.switching)
    fig = plot_run(res)
    assert _series_labels(_axis(fig, "slip")) == ["z1", "z2", "z3"]
    assert _segments_x(_axis(fig, "events"), "switching") == pytest.approx(sorted(ev_run.switching))
    png = tmp_path / "p.png"
    assert cli.main(["plot", str(tmp_path / "bag"), "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --- plots an engineer reads without the papers (issue 33) -------------------------------------------------
def _switching_run(n=4001, flips=400):
    """The synthetic run with z1's field reversing ``flips`` times and θ damped from 10° to 1e-3° (a dead band of
    0.01°), torques of a few µN·m: what ψ-switching does."""
    r = synthetic_run()
    t = np.linspace(0.0, T_END, n)
    r.t = t
    r.omega_b = np.column_stack([np.zeros(n), np.zeros(n), TWO_PI * 50.0 * t])
    r.q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    r.L = np.column_stack([1e-4 * np.ones(n), np.zeros(n), 1e-3 + 1e-6 * t])
    r.euler = np.column_stack([np.zeros(n), np.radians(10.0 * 10.0 ** (-2.0 * t)), np.zeros(n)])
    sign = np.where(np.floor(t / T_END * flips) % 2 == 0, 1.0, -1.0)
    r.current = np.column_stack([0.3 * np.ones(n), np.zeros(n), np.ones(n)])
    r.field_rate = np.column_stack([TWO_PI * 300.0 * sign, np.zeros(n), TWO_PI * 500.0 * np.ones(n)])
    r.torque = np.column_stack([3e-6 * sign, 1e-6 * np.ones(n), 2e-6 * np.ones(n)])
    r.scene.controller = SimpleNamespace(law="psi_switching", params=SimpleNamespace(dead_band=math.radians(0.01)))
    return r


def _offset_texts(fig):
    fig.canvas.draw()
    return [(a.get_ylabel(), a.yaxis.get_offset_text().get_text()) for a in fig.axes
            if a.yaxis.get_offset_text().get_text()]


def test_theta_near_zero_on_a_log_axis_with_the_dead_band():
    """θ on a linear axis hid the last 0.01° and the dead band: it is log scale where it spans > 30×."""
    fig = plot_run(_switching_run())
    ax = _axis(fig, "nutation θ")
    assert ax.get_yscale() == "log" and ax.get_ylim()[0] < 1e-2
    (band,) = [ln for ln in ax.get_lines() if ln.get_gid() == "dead_band"]
    assert band.get_ydata()[0] == pytest.approx(0.01) and "dead band 0.01°" in band.get_label()
    assert _axis(plot_run(synthetic_run()), "nutation θ").get_yscale() == "linear"  # 5° throughout


def test_no_offset_labels_on_any_axis():
    """The spin-up's θ axis showed "+2.864", L "1e-5"-type multipliers: every axis labels its own values."""
    r = synthetic_run()
    r.euler[:, 1] = np.radians(2.864 - 1e-5 * r.t)  # nearly constant, as a spin-up's θ
    r.torque = np.column_stack([np.zeros(N), np.zeros(N), 1.5e-4 - 1e-9 * r.t])
    for fig in (plot_run(r), plot_run(_switching_run())):
        assert _offset_texts(fig) == []
    ax = _axis(plot_run(r), "torque on rotor")
    assert "(µN·m)" in ax.get_ylabel()


def test_torque_panel_and_L_as_magnitude_and_direction():
    fig = plot_run(_switching_run())
    ax = _axis(fig, "torque on rotor")
    assert "case frame (µN·m)" in ax.get_ylabel()
    assert {"|N|", "N along z1"} <= {lab.replace(" (min–max per time bin)", "") for lab in
                                      _legend_texts(ax.get_legend())}
    ax = _axis(fig, "|L| (")
    assert ax.get_ylabel() == "kinetic moment\n(angular momentum)\n|L| (mN·m·s)"
    (mag,) = ax.get_lines()
    assert np.allclose(mag.get_ydata(), 1e3 * np.hypot(1e-4, 1e-3 + 1e-6 * np.asarray(mag.get_xdata())), rtol=1e-9)
    ax = _axis(fig, "direction of L")
    assert ax.get_ylim() == pytest.approx((-1.08, 1.08))
    z = [ln for ln in ax.get_lines() if ln.get_label() == "along z3"][0]
    assert 0.99 < min(z.get_ydata()) <= max(z.get_ydata()) < 1.0


def test_switching_series_are_envelopes():
    """Field rate, slip and torque under switching: min..max per time bin, filled (not aliased line bands)."""
    fig = plot_run(_switching_run())
    for part in ("field rate", "slip", "torque on rotor"):
        ax = _axis(fig, part)
        env = [c for c in ax.collections if c.get_gid() == "envelope"]
        assert env, part
        edges = [ln for ln in ax.get_lines() if ln.get_gid() == "envelope_edge"]
        assert edges and all(len(ln.get_xdata()) == 2 * plotting.ENVELOPE_BINS for ln in edges), part
    rate = _axis(fig, "field rate")
    assert _series_labels(rate) == ["z1", "z3"]  # z1 as an envelope, z3 (constant) as a line
    (z3,) = [ln for ln in rate.get_lines() if ln.get_label() == "z3"]
    assert np.allclose(z3.get_ydata(), 500.0)


def test_one_name_for_L():
    from gyro_sim.engine.result import SERIES

    assert plotting.L_NAME == "kinetic moment (angular momentum)"
    assert SERIES["L"][2].startswith(plotting.L_NAME)


def test_sweep_plot_units_and_the_theory_s_marks():
    """Sweep plots had no units and no theory: axis labels carry units, the spec's marks are drawn (h* = π/Λ)."""
    from gyro_sim.apps.sweep_plot import plot_sweep
    from gyro_sim.apps.sweep_spec import load_sweep
    from gyro_sim.scenes.scene import config_dir

    spec = load_sweep(config_dir() / "sweep_psi_rate.yaml")
    meta = spec.meta()
    (mark,) = meta["marks"]
    assert mark["x"] == pytest.approx(0.0154, abs=5e-5)  # h* = π/Λ, Λ = |L0|/J = 204 rad/s (the spec's header)
    rows = [{"status": "ok", "controller.period": h, "theta_end": 10.0 * h, "t_below": 0.5, "t_settle": 1.0,
             "sf": math.sin(204 * h) / (204 * h)} for h in (0.002, 0.01, 0.02)]
    fig = plot_sweep(rows, meta)
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        assert ax.get_xlabel() == "controller.period (s)"
        (line,) = [ln for ln in ax.get_lines() if ln.get_gid() == "mark"]
        assert line.get_xdata()[0] == pytest.approx(mark["x"])
        assert "h* = π/Λ" in " ".join(_legend_texts(ax.get_legend()))
    labels = {ax.get_ylabel() for ax in fig.axes if ax.get_visible()}
    assert labels == {"theta_end (deg)", "t_below (s)", "t_settle (s)", "sf (ratio)"}
    # a y mark on its metric's panel: [K] (3.10)'s p = −p* in the k310 sweep
    meta = load_sweep(config_dir() / "sweep_k310_cycles.yaml").meta()
    (mark,) = meta["marks"]
    assert mark["metric"] == "p" and mark["y"] == pytest.approx(-0.559, abs=1e-3)
