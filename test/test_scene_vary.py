"""Varying a scene (issue 33): ``gyro-sim run --set KEY=VALUE``, :meth:`Scene.replace`, the frozen-field error that
points to it, and a run that refuses a scene made invalid by pydantic's ``model_copy(update=...)``."""
from __future__ import annotations

import pytest

import gyro_sim
from gyro_sim.apps import cli
from gyro_sim.scenes.scene import SceneError, builtin_scenes, load_scene


def test_frozen_field_error_points_to_replace():
    """Setting a field said only "Instance is frozen" (pydantic): now it names the field and the API."""
    sc = load_scene("three_stators")
    with pytest.raises(AttributeError) as err:
        sc.stators[2].current = 0.5
    msg = str(err.value)
    assert "Stator.current cannot be set" in msg and "scene.replace({'stators.2.current': 0.5})" in msg
    assert "\n" not in msg
    with pytest.raises(AttributeError, match=r"scene\.replace\(duration=\.\.\.\)"):
        sc.duration = 3.0
    with pytest.raises(AttributeError, match="cannot be set"):  # the controller's parameters too (gyro_ctl)
        load_scene("nutation_oblate").controller.params.dead_band = 0.0
    assert sc.stators[2].current == load_scene("three_stators").stators[2].current


def test_replace_validates_and_keeps_the_rest():
    sc = load_scene("three_stators")
    new = sc.replace({"stators.2.current": 0.5, "initial.theta": 0.1}, duration=0.5)
    assert (new.stators[2].current, new.initial.theta, new.duration) == (0.5, 0.1, 0.5)
    assert new.source == sc.source and new.stators[0] == sc.stators[0] and new.rotor == sc.rotor
    assert sc.stators[2].current != 0.5  # the original is unchanged
    with pytest.raises(SceneError, match=r"^invalid scene .*: stators\.2\.current = -1: .*greater than or equal to 0$"):
        sc.replace({"stators.2.current": -1})
    with pytest.raises(SceneError, match=r"^invalid scene .*: duration = -5: Input should be greater than 0$"):
        sc.replace(duration=-5)
    with pytest.raises(SceneError, match=r"stators\.9\.current.*not an index of stators \(3 items\)"):
        sc.replace({"stators.9.current": 1.0})
    with pytest.raises(SceneError, match="durations: unknown key"):
        sc.replace(durations=1.0)


@pytest.mark.parametrize("name", sorted(builtin_scenes()))
def test_replace_nothing_is_the_same_scene(name):
    sc = load_scene(name)
    assert sc.replace() == sc


def test_run_refuses_an_invalid_model_copy():
    """``model_copy(update=...)`` skips validation; the run then failed far inside ("duration = None", an
    IndexError): it now refuses the scene with the one-line field error before any work."""
    bad = load_scene("three_stators").model_copy(update={"duration": -5})
    with pytest.raises(SceneError, match=r"^invalid scene .*three_stators\.yaml: duration = -5: Input should be "
                                         r"greater than 0$"):
        gyro_sim.run(bad)
    with pytest.raises(SceneError, match=r"stators\.0\.current = -2"):
        gyro_sim.Simulator(load_scene("three_stators").model_copy(update={"stators": [
            {"name": "z1", "axis": [1, 0, 0], "coil_constant": 1.0, "current": -2.0}]}))


def test_check_valid_keeps_only_what_validated():
    """check_valid skips data that validated before, kept by value (the model_dump): an invalid copy of a scene that
    validated (model_copy skips validation) is refused, every time, and the scene itself still passes."""
    from gyro_sim.scenes.scene import check_valid

    sc = load_scene("three_stators")
    check_valid(sc)
    check_valid(sc)  # (kept: no second validation)
    for _ in range(2):  # (an invalid scene is never kept)
        with pytest.raises(SceneError, match="duration = -5"):
            check_valid(sc.model_copy(update={"duration": -5.0}))
        with pytest.raises(SceneError, match="duration = 0"):
            check_valid(sc.model_copy(update={"duration": 0}))
    check_valid(sc)
    check_valid(sc.model_copy(update={"duration": 2}))  # (2 and 2.0: both valid)


def test_cli_run_set(tmp_path, capsys):
    """``gyro-sim run SCENE --set KEY=VALUE`` (sweep's syntax) changes the scene; bad ones get one line, status 2."""
    code = cli.main(["run", "three_stators", "--quiet", "--out", str(tmp_path), "--set", "duration=0.05",
                     "--set", "stators.2.current=0.5", "--set", "controller=null"])
    out = capsys.readouterr().out
    assert code == 0 and "simulated time    0.05 s" in out, out
    for args, msg in ((["--set", "stators.2.current=-1"], "stators.2.current = -1: Input should be greater than"),
                      (["--set", "nokey"], "--set 'nokey': expected KEY=VALUE"),
                      (["--set", "=3"], "--set '=3': expected KEY=VALUE with a dotted key"),
                      (["--set", "durations=1"], "durations: unknown key")):
        assert cli.main(["run", "three_stators", "--quiet", "--out", str(tmp_path), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and msg in err[0], err


@pytest.mark.parametrize("name", sorted(builtin_scenes()))
def test_scene_written_for_ros_loads_back(name, tmp_path):
    """``run --ros --set``: the nodes load a file, so the changed scene is written and must load back the same."""
    from gyro_sim.apps.cli_run import _write_scene

    sc = load_scene(name).replace(duration=0.5)
    path = tmp_path / f"{name}_set.yaml"
    _write_scene(sc, path)
    again = load_scene(path)
    assert again.model_dump(exclude={"source", "name"}) == sc.model_dump(exclude={"source", "name"})
