"""Results for the scientific Python tools (issue 21): RunResult.to_dataframe() / to_xarray() with units and frames,
its short repr, the named state views of Simulator, stators by name, and gyro_sim.read_bag (a RunResult of a bag).

The bag checks hold read_bag to what the project guarantees (test_recording, test_ros): the arrays of a bag recorded
in-process are the run's, bit for bit, the sample times included.
"""
import copy
import dataclasses
import sys

import numpy as np
import pytest

import gyro_sim
from gyro_sim.io import results
from gyro_sim.physics.frames import euler_angles, quat_to_matrix
from gyro_sim.io.recording import BagData, record_result, record_run
from gyro_sim.engine.simulate import Runner, Simulator, drive

pd = pytest.importorskip("pandas", reason="the extra 'data' (pip install 'gyro_sim[data]') is not installed")
xr = pytest.importorskip("xarray", reason="the extra 'data' (pip install 'gyro_sim[data]') is not installed")

SCENE = "spinup_thin_shell"  # three stators z1, z2, z3; the spin-up law commands z3 at every tick
DURATION = 0.2
NAMES = ["z1", "z2", "z3"]
ARRAYS = ("t", "L", "q", "omega_b", "torque", "energy", "current", "field_rate", "field_phase", "euler")
J = 5.592e-6  # kg·m², the default shell's transverse moment (test_isotropic): an isotropic rotor, all three equal


def bits(a) -> np.ndarray:
    """float64 bit patterns (bit-exact comparison: NaN = NaN, -0.0 ≠ 0.0)."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).view(np.int64)


def assert_bit_equal(a, b, what):
    assert np.shape(a) == np.shape(b), f"{what}: shape {np.shape(a)} != {np.shape(b)}"
    assert np.array_equal(bits(a), bits(b)), f"{what}: values differ"


@pytest.fixture(scope="module")
def res():
    return gyro_sim.run(gyro_sim.load_scene(SCENE), duration=DURATION)


@pytest.fixture(scope="module")
def no_attitude():
    """The default spin-up on an isotropic rotor with ``output.attitude: false``: run without attitude."""
    scene = gyro_sim.load_scene(SCENE, overrides={"controller": None, "rotor.inertia": [J, J, J],
                                                  "output.attitude": False})
    r = gyro_sim.run(scene, duration=DURATION)
    assert not r.attitude
    return r


def expected_columns():
    return (["L_x", "L_y", "L_z", "q_w", "q_x", "q_y", "q_z", "omega_b_x", "omega_b_y", "omega_b_z",
             "psi", "theta", "phi", "torque_x", "torque_y", "torque_z", "energy", "spin_rate"]
            + [f"{s}_{n}" for s in ("current", "field_rate", "field_phase") for n in NAMES])


# --- DataFrame -------------------------------------------------------------------------------------------

def test_dataframe_columns_values_units_frames(res):
    df = res.to_dataframe()
    n = len(res.t)
    assert n == 11 and df.shape == (n, 27)
    assert list(df.columns) == expected_columns()
    assert df.index.name == "t"
    assert_bit_equal(df.index.to_numpy(), res.t, "t")
    # every column is its array's values, bit for bit
    for name, comps in (("L", "xyz"), ("q", "wxyz"), ("omega_b", "xyz"), ("torque", "xyz")):
        for i, c in enumerate(comps):
            assert_bit_equal(df[f"{name}_{c}"], getattr(res, name)[:, i], f"{name}_{c}")
    for i, c in enumerate(("psi", "theta", "phi")):
        assert_bit_equal(df[c], res.euler[:, i], c)
    assert_bit_equal(df["energy"], res.energy, "energy")
    assert_bit_equal(df["spin_rate"], res.spin_rate, "spin_rate")
    for k, s in enumerate(NAMES):
        assert_bit_equal(df[f"current_{s}"], res.current[:, k], f"current_{s}")
        assert_bit_equal(df[f"field_rate_{s}"], res.field_rate[:, k], f"field_rate_{s}")
        assert_bit_equal(df[f"field_phase_{s}"], res.field_phase[:, k], f"field_phase_{s}")
    assert (df["current_z3"] == 1.0).all() and (df["current_z1"] == 0.0).all()  # the law drives z3 alone
    # units and frames: every column has one, and they say what the docstrings say
    units, frames = df.attrs["units"], df.attrs["frames"]
    assert set(units) == {"t", *df.columns} and set(frames) == set(df.columns)
    assert units["t"] == "s"
    assert [units[c] for c in ("L_x", "q_w", "omega_b_z", "psi", "torque_y", "energy", "spin_rate",
                               "current_z1", "field_rate_z2", "field_phase_z3")] == \
        ["N m s", "1", "rad/s", "rad", "N m", "J", "rad/s", "A", "rad/s", "rad"]
    assert [frames[c] for c in ("L_x", "q_w", "omega_b_z", "theta", "torque_y", "spin_rate", "current_z1")] == \
        ["case", "body to case", "body", "L-frame", "case", "body", ""]
    # the run's metadata
    est = res.error_estimate
    assert df.attrs["scene"] == SCENE and df.attrs["attitude"] == 1 and df.attrs["steps"] == res.steps
    assert df.attrs["t_end"] == DURATION
    assert df.attrs["error_L"] == est.L and df.attrs["error_attitude"] == est.attitude
    assert df.attrs["accuracy_met"] == int(est.met) and df.attrs["error_estimate"] == est.text()


def test_dataframe_of_a_run_without_attitude(no_attitude):
    df = no_attitude.to_dataframe()
    assert list(df.columns) == expected_columns()
    assert df[["q_w", "q_x", "q_y", "q_z", "psi", "theta", "phi"]].isna().all().all()
    assert_bit_equal(df["spin_rate"], np.linalg.norm(no_attitude.omega_b, axis=1), "spin_rate = |Ω|")
    frames = df.attrs["frames"]
    assert frames["omega_b_x"] == "case" and frames["spin_rate"] == "" and frames["L_x"] == "case"
    assert df.attrs["attitude"] == 0


# --- xarray ----------------------------------------------------------------------------------------------

def test_xarray_dims_values_units_frames(res):
    ds = res.to_xarray()
    n, n_modes = len(res.t), res.modes.shape[1] // 3
    assert n_modes >= 1
    assert dict(ds.sizes) == {"time": n, "component": 3, "quaternion": 4, "angle": 3, "stator": 3, "mode": n_modes}
    assert list(ds.component.values) == ["x", "y", "z"] and list(ds.quaternion.values) == ["w", "x", "y", "z"]
    assert list(ds.angle.values) == ["psi", "theta", "phi"] and list(ds.stator.values) == NAMES
    assert_bit_equal(ds.time.values, res.t, "time")
    assert ds.time.attrs["units"] == "s"
    for name in ("L", "q", "omega_b", "euler", "torque", "energy", "spin_rate", "current", "field_rate",
                 "field_phase"):
        assert_bit_equal(ds[name].values, getattr(res, name), name)
    assert_bit_equal(ds.modes.values, res.modes.reshape(n, n_modes, 3), "modes")
    assert ds.L.dims == ("time", "component") and ds.current.dims == ("time", "stator")
    assert ds.modes.dims == ("time", "mode", "component")
    # labelled access gives the same numbers as the array's columns
    assert_bit_equal(ds.L.sel(component="z").values, res.L[:, 2], "L_z")
    assert_bit_equal(ds.current.sel(stator="z3").values, res.current[:, 2], "current z3")
    assert_bit_equal(ds.euler.sel(angle="theta").values, res.theta, "θ")
    units = {v: ds[v].attrs["units"] for v in ds.data_vars}
    assert units == {"L": "N m s", "q": "1", "omega_b": "rad/s", "euler": "rad", "torque": "N m", "energy": "J",
                     "spin_rate": "rad/s", "current": "A", "field_rate": "rad/s", "field_phase": "rad",
                     "modes": "T"}
    frames = {v: ds[v].attrs.get("frame") for v in ds.data_vars}
    assert frames["L"] == "case" and frames["torque"] == "case" and frames["omega_b"] == "body"
    assert frames["q"] == "body to case" and frames["euler"] == "L-frame" and frames["modes"] == "body"
    assert frames["current"] is None and all(ds[v].attrs["long_name"] for v in ds.data_vars)
    est = res.error_estimate
    assert ds.attrs["scene"] == SCENE and ds.attrs["steps"] == res.steps and ds.attrs["attitude"] == 1
    assert ds.attrs["error_L"] == est.L and ds.attrs["error_estimate"] == est.text()


def test_xarray_stores_as_netcdf(res):
    """The attrs are of types netCDF takes (no bool, no None): the Dataset round-trips through a netCDF file."""
    ds = res.to_xarray()
    back = xr.open_dataset(ds.to_netcdf())
    assert_bit_equal(back.L.values, res.L, "L")
    assert back.L.attrs["units"] == "N m s" and back.L.attrs["frame"] == "case"
    assert back.attrs["scene"] == SCENE and back.attrs["accuracy_met"] == 1


def test_xarray_of_a_run_without_attitude(no_attitude):
    ds = no_attitude.to_xarray()
    assert ds.omega_b.attrs["frame"] == "case" and ds.modes.attrs["frame"] == "case"
    assert "frame" not in ds.spin_rate.attrs and ds.attrs["attitude"] == 0
    assert np.isnan(ds.q.values).all() and np.isnan(ds.euler.values).all()


# --- without the extra -----------------------------------------------------------------------------------

@pytest.mark.parametrize("method,module,work", [("to_dataframe", "pandas", "_columns"),
                                                ("to_xarray", "xarray", "_var")])
def test_missing_extra_says_which_before_any_work(res, monkeypatch, method, module, work):
    """Without pandas (xarray) one ImportError names the extra and its install line, before any column is made."""
    monkeypatch.setitem(sys.modules, module, None)  # `import pandas` now raises ImportError

    def no_work(*a, **k):
        raise AssertionError("work done before the missing extra was reported")

    from gyro_sim.engine import result  # (the views' home; gyro_sim.io.results re-exports them)

    monkeypatch.setattr(result, work, no_work)
    with pytest.raises(ImportError) as exc:
        getattr(res, method)()
    assert isinstance(exc.value, results.MissingExtraError)
    msg = str(exc.value)
    assert msg.startswith(f"RunResult.{method}() needs the 'data' extra: pip install 'gyro_sim[data]'")
    assert f"(missing: {module})" in msg and "\n" not in msg
    assert exc.value.__cause__ is None and exc.value.__context__ is None  # (raised before any import was tried)


# --- repr ------------------------------------------------------------------------------------------------

def test_repr_is_short_and_informative(res):
    text = repr(res)
    print("\n" + text)
    lines = text.splitlines()
    assert len(lines) <= 3 and len(text) <= 400 and all(len(x) <= 120 for x in lines)
    s = res.summary()
    assert lines[0] == f"<RunResult '{SCENE}': 0.2 s, 11 samples, {res.steps} steps, attitude yes"
    assert f"spin {s['spin_rate']:.6g} rad/s" in lines[1] and f"θ {s['theta_deg']:.4g}°" in lines[1]
    assert f"|L| {s['L_norm']:.6g} N·m·s" in lines[1]
    assert lines[2] == f" error estimate: {res.error_estimate.text()}, met>"
    assert str(res) == text


def test_repr_without_attitude_and_without_estimate(no_attitude):
    r = dataclasses.replace(no_attitude, error_estimate=None)
    text = repr(r)
    assert "attitude no" in text and "θ n/a (no attitude)" in text and "error estimate: none" in text
    assert f"spin {float(np.linalg.norm(r.omega_b[-1])):.6g} rad/s" in text


def test_repr_of_a_result_still_in_its_bag_reads_nothing(tmp_path):
    """A streamed run too long to keep (keep_bytes=0): the repr takes the preview's finals; the bag is not read."""
    r = record_run(gyro_sim.load_scene(SCENE), tmp_path / "bag", duration=DURATION, keep_bytes=0)
    assert r.__dict__.get("_load") is not None
    text = repr(r)
    assert r.__dict__.get("_load") is not None, "repr read the bag"
    assert "samples in its bag (read on first use)" in text
    assert f"spin {float(r.preview().spin_rate[-1]):.6g} rad/s" in text
    assert len(r.t) == 11 and "11 samples" in repr(r)  # once read, the count


def test_equality_is_the_dataclass_one(res):
    """The repr is RunResult's own; equality stays the dataclass's (field by field)."""
    assert "__eq__" in vars(gyro_sim.RunResult) and gyro_sim.RunResult.__eq__.__qualname__ == "RunResult.__eq__"
    same = copy.copy(res)
    assert same == res
    same.steps += 1
    assert same != res


# --- Simulator: named views, stators by name --------------------------------------------------------------

def test_views_are_the_state_and_the_last_sample(res):
    """After a run, the Simulator's views equal the RunResult's last row (the same state, the same bits)."""
    r = Runner(gyro_sim.load_scene(SCENE), DURATION)
    drive(r)
    out, sim = r.result(), r.sim
    assert sim.t == out.t[-1]
    assert_bit_equal(sim.L, out.L[-1], "L")
    assert_bit_equal(sim.q, out.q[-1], "q")
    assert_bit_equal(sim.omega_b, out.omega_b[-1], "omega_b")
    assert_bit_equal(sim.modes, out.modes[-1], "modes")
    assert sim.modes.shape == (3 * sim.tau.size,) and sim.tau.size >= 1
    assert np.allclose(sim.euler, out.euler[-1], rtol=0, atol=1e-12)
    assert_bit_equal(sim.euler, euler_angles(quat_to_matrix(sim.y[3:7]), sim.y[0:3]), "euler")
    # copies: writing into a view leaves the state alone; the views cannot be assigned
    y = sim.y.copy()
    for name in ("L", "q", "omega_b", "euler", "modes"):
        getattr(sim, name)[:] = 7.0
        with pytest.raises(AttributeError):
            setattr(sim, name, np.zeros(3))
    assert_bit_equal(sim.y, y, "y")
    for name in ("L", "q", "omega_b", "euler", "modes"):
        doc = getattr(Simulator, name).__doc__
        assert any(u in doc for u in ("N·m·s", "rad/s", "rad", " T", "(w, x, y, z)")), name
        assert ("frame" in doc or "body → case" in doc), name


def test_views_without_attitude():
    scene = gyro_sim.load_scene(SCENE, overrides={"controller": None, "rotor.inertia": [J, J, J],
                                                  "output.attitude": False})
    sim = Simulator(scene)
    sim.advance(0.01)
    assert not sim.attitude
    assert np.isnan(sim.q).all() and np.isnan(sim.euler).all()
    assert_bit_equal(sim.omega_b, sim.y[0:3] * sim.Jinv, "Ω = L/J")


def test_set_stator_by_name_or_index():
    scene = gyro_sim.load_scene(SCENE, overrides={"controller": None})
    a, b = Simulator(scene), Simulator(scene)
    a.set_stator("z1", current=0.5, rate=-3000.0)
    b.set_stator(0, current=0.5, rate=-3000.0)
    a.set_stators({"z2": (0.25, None), 2: (None, 100.0)})
    b.set_stators({1: (0.25, None), np.int64(2): (None, 100.0)})
    assert a.current.tolist() == b.current.tolist() == [0.5, 0.25, scene.stators[2].current]
    assert a.rate.tolist() == b.rate.tolist() == [-3000.0, scene.stators[1].rate, 100.0]
    a.advance(0.01)
    b.advance(0.01)
    assert_bit_equal(a.y, b.y, "y")


@pytest.mark.parametrize("bad,shown", [("z9", "'z9'"), (3, "3"), (-1, "-1"), (True, "True"), (1.0, "1.0"),
                                       (None, "None")])
def test_unknown_stator_is_one_clear_error(bad, shown):
    sim = Simulator(gyro_sim.load_scene(SCENE, overrides={"controller": None}))
    before = (sim.current.copy(), sim.rate.copy(), sim.y.copy())
    want = f"stator {shown}: no such stator; allowed: z1, z2, z3 (or an index 0–2)"
    with pytest.raises(ValueError) as exc:
        sim.set_stator(bad, current=0.5)
    assert str(exc.value) == want
    with pytest.raises(ValueError, match="no such stator"):  # nothing applied, not even the good one
        sim.set_stators({"z1": (0.7, 10.0), bad: (0.5, None)})
    for x, y in zip(before, (sim.current, sim.rate, sim.y)):
        assert_bit_equal(x, y, "state")


# --- read_bag ---------------------------------------------------------------------------------------------

def test_read_bag_is_the_run_result_reader():
    assert gyro_sim.read_bag is results.read_bag and "read_bag" in gyro_sim.__all__
    from gyro_sim import testing

    assert testing.result_from_bag.__module__ == "gyro_sim.apps.testing"  # (the kit's home; gyro_sim.testing kept)


@pytest.mark.parametrize("recorder", ["record_result", "record_run"])
def test_read_bag_equals_the_in_process_run(res, tmp_path, recorder):
    """A bag of the run (written after it, or as it runs: `gyro-sim run --record`) reads back as the same RunResult:
    every array bit for bit (sample times included), the commands, steps and error estimate; the same DataFrame."""
    bag = tmp_path / "bag"
    if recorder == "record_result":
        record_result(res, bag)
    else:
        record_run(gyro_sim.load_scene(SCENE), bag, duration=DURATION)
    back = gyro_sim.read_bag(bag)
    assert isinstance(back, gyro_sim.RunResult)
    for name in ARRAYS:
        assert_bit_equal(getattr(back, name), getattr(res, name), name)
    assert back.stator_names == NAMES and back.attitude and back.scene.name == SCENE
    assert back.commands == res.commands and len(back.commands) == 10
    assert back.steps == res.steps and back.error_estimate.to_json() == res.error_estimate.to_json()
    assert back.modes.shape == (len(res.t), 0)  # eddy modes are not recorded
    a, b = res.to_dataframe(), back.to_dataframe()
    pd.testing.assert_frame_equal(b, a, check_exact=True)
    assert b.attrs == a.attrs
    # the raw topics (BagData) and the .mcap file read the same
    data = gyro_sim.io.recording.read_bag(bag)
    assert isinstance(data, BagData)
    for src in (data, next(bag.glob("*.mcap"))):
        again = gyro_sim.read_bag(src)
        for name in ARRAYS:
            assert_bit_equal(getattr(again, name), getattr(res, name), f"{name} ({type(src).__name__})")
    from gyro_sim.testing import result_from_bag

    assert_bit_equal(result_from_bag(data).t, res.t, "t (the kit's result_from_bag)")


def test_read_bag_without_a_scene_asks_for_one(res, tmp_path):
    record_result(res, tmp_path / "bag")
    data = gyro_sim.io.recording.read_bag(tmp_path / "bag")
    data.scene_text = None
    with pytest.raises(ValueError, match=r"the bag holds no scene .*give scene="):
        gyro_sim.read_bag(data)
    back = gyro_sim.read_bag(data, scene=SCENE)  # the scene given: the same grid, the same bits
    assert_bit_equal(back.t, res.t, "t")
