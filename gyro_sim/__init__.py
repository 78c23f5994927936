"""gyro_sim: simulator of an electrodynamically controlled gyroscope rotor.

The pure core (this package minus ``gyro_sim.ros``) never imports rclpy. In a notebook::

    import gyro_sim
    scene = gyro_sim.load_scene("spinup_thin_shell")      # or a path to a YAML file
    result = gyro_sim.run(scene, duration=10.0)             # time series as NumPy arrays
    result.t, result.L, result.euler[:, 1], result.summary()
    result.to_dataframe(), result.to_xarray()                # with the extra 'data' (pandas, xarray)
    again = gyro_sim.read_bag("runs/bag1")                  # a RunResult of a recorded bag

``gyro_sim.read_bag`` returns a RunResult (:func:`gyro_sim.results.read_bag`); the raw topics of a bag as arrays
are :func:`gyro_sim.recording.read_bag` (BagData).
"""
__version__ = "0.1.0"

#: public names → the module that holds them, imported on first use (PEP 562): `import gyro_sim` (and the pytest
#: plugin gyro_sim.testing, loaded in every pytest session) costs no numba/SciPy import until a run needs it
_LAZY = {"Scene": "scene", "SceneError": "scene", "builtin_scenes": "scene", "load_scene": "scene",
         "scene_from_dict": "scene", "RunResult": "simulate", "Simulator": "simulate", "run": "simulate",
         "read_bag": "results"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'gyro_sim' has no attribute {name!r}")


__all__ = ["Scene", "SceneError", "builtin_scenes", "load_scene", "scene_from_dict", "RunResult", "Simulator",
           "run", "read_bag", "__version__"]
