"""Scene loading: built-in scenes validate; a wrong scene is refused with one clear message."""
import math

import numpy as np
import pytest

from gyro_sim.scenes.scene import SceneError, builtin_scenes, load_scene, parse_scene_text, scene_from_dict

REQUIRED = {"spinup_thin_shell", "spinup_solid_sphere", "free_rotor", "constant_field",
            "pulsating_field", "rotating_field"}


def base():
    return parse_scene_text(builtin_scenes()["spinup_thin_shell"].read_text())


def test_builtin_scenes_load():
    scenes = builtin_scenes()
    assert REQUIRED <= set(scenes), f"missing built-in scenes: {REQUIRED - set(scenes)}"
    for name in scenes:
        s = load_scene(name)
        assert s.name == name
        assert s.duration > 0


def refuse(data, *fragments):
    with pytest.raises(SceneError) as ei:
        scene_from_dict(data, where="t.yaml")
    msg = str(ei.value)
    print(msg)
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


def mutate(path, value):
    d = base()
    cur = d
    parts = path.split(".")
    for p in parts[:-1]:
        cur = cur[int(p)] if isinstance(cur, list) else cur[p]
    last = parts[-1]
    if isinstance(cur, list):
        cur[int(last)] = value
    else:
        cur[last] = value
    return d


def test_unknown_key_lists_allowed_keys():
    d = base()
    d["rotor"]["colour"] = "red"
    refuse(d, "rotor.colour", "unknown key", "inertia", "conductor")


def test_wrong_type():
    refuse(mutate("duration", "long"), "duration", "'long'")


def test_negative_conductivity():
    refuse(mutate("rotor.conductor.conductivity", -1.0), "rotor.conductor.conductivity", "-1.0",
           "greater than or equal to 0.001")


def test_triangle_inequality():
    refuse(mutate("rotor.inertia", [1.0, 1.0, 3.0]), "rotor.inertia", "J3 = 3.0", "triangle inequality")


def test_missing_required_key():
    d = base()
    del d["duration"]
    refuse(d, "duration", "missing")


def test_missing_thickness_of_shell():
    d = base()
    del d["rotor"]["conductor"]["thickness"]
    refuse(d, "rotor.conductor", "thickness is missing")


def test_thickness_beyond_radius():
    refuse(mutate("rotor.conductor.thickness", 0.03), "thickness = 0.03", "outer_radius")


def test_out_of_range_theta():
    refuse(mutate("initial.theta", 4.0), "initial.theta", "4.0", "less than or equal to 3.14")


def test_nan_refused():
    refuse(mutate("stators.2.rate", float("nan")), "stators.2.rate", "finite")


def test_command_for_unknown_stator():
    d = base()
    d["commands"] = [{"time": 1.0, "stator": "z9", "current": 0.0}]
    refuse(d, "commands.0.stator", "'z9'", "z1")


def test_negative_current():
    refuse(mutate("stators.2.current", -2.0), "stators.2.current", "-2.0", "greater than or equal to 0")


def test_torque_model_needs_conductor():
    d = base()
    del d["rotor"]["conductor"]
    refuse(d, "torque_model", "rotor.conductor")


def test_unknown_scene_name_lists_builtins():
    with pytest.raises(SceneError) as ei:
        load_scene("no_such_scene")
    assert "spinup_thin_shell" in str(ei.value)


def test_bad_yaml(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("rotor: [unclosed\n")
    with pytest.raises(SceneError) as ei:
        load_scene(p)
    assert "not valid YAML" in str(ei.value)


def test_top_level_not_mapping(tmp_path):
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(SceneError, match="mapping"):
        load_scene(p)


def test_overrides_apply_before_validation():
    s = load_scene("spinup_thin_shell", overrides={"initial.theta": 0.2, "stators.2.current": 0.5})
    assert s.initial.theta == 0.2 and s.stators[2].current == 0.5
    with pytest.raises(SceneError, match="initial.theta"):
        load_scene("spinup_thin_shell", overrides={"initial.theta": -1})


def test_output_window_refused_when_empty_or_huge():
    refuse(mutate("output", {"rate": 50.0, "windows": [{"start": 2.0, "end": 1.0, "rate": 1000.0}]}),
           "output.windows.0", "end = 1.0", "greater than start = 2.0")
    refuse(mutate("output", {"rate": 50.0, "windows": [{"start": 0.0, "end": 50.0, "rate": 1e6}]}),
           "output.windows.0", "rate = 1000000.0", "5e+07 samples in [0.0, 50.0] s", "at most")
    # counted within the run: the same window in a 1 s run is fine
    d = mutate("output", {"rate": 50.0, "windows": [{"start": 0.0, "end": 100.0, "rate": 1e6}]})
    d["duration"] = 1.0
    assert scene_from_dict(d).output.sample_times(1.0).size == 1_000_001
    refuse(mutate("output", {"rate": 50.0, "windows": [{"start": 0.0, "end": 1.0}]}), "output.windows.0.rate", "missing")


def test_output_window_samples_join_the_regular_ones():
    s = scene_from_dict(mutate("output", {"rate": 10.0, "windows": [{"start": 0.25, "end": 0.3, "rate": 100.0}]}))
    t = s.output.sample_times(1.0)
    assert np.allclose(np.diff(t[t <= 0.2]), 0.1) and np.all(np.diff(t) > 0)
    inside = t[(t >= 0.25) & (t <= 0.3 + 1e-12)]
    assert inside.size == 6 and np.allclose(np.diff(inside), 0.01)
    assert s.output.window_at(0.27) is s.output.windows[0] and s.output.window_at(0.3) is None
    assert s.output.next_window_start(0.0) == 0.25 and s.output.next_window_start(0.25) == math.inf
