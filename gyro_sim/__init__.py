"""gyro_sim: simulator of an electrodynamically controlled gyroscope rotor.

The pure core (this package minus ``gyro_sim.ros``) never imports rclpy. In a notebook::

    import gyro_sim
    scene = gyro_sim.load_scene("spinup_thin_shell")      # or a path to a YAML file
    result = gyro_sim.run(scene, duration=10.0)             # time series as NumPy arrays
    result.t, result.L, result.euler[:, 1], result.summary()
    result.to_dataframe(), result.to_xarray()                # with the extra 'data' (pandas, xarray)
    again = gyro_sim.read_bag("runs/bag1")                  # a RunResult of a recorded bag

``gyro_sim.read_bag`` returns a RunResult (:func:`gyro_sim.io.results.read_bag`); the raw topics of a bag as arrays
are :func:`gyro_sim.io.recording.read_bag` (BagData).

The package is layered (docs/architecture.md): ``common`` < ``physics`` < ``compiled`` < ``scenes`` < ``averaging``
< ``engine`` < ``io`` < ``ros`` < ``apps``; a module imports only its own layer and those below
(test/test_layers.py). The flat module paths of before the layers (``gyro_sim.simulate``, ``gyro_sim.kernels``,
``gyro_sim.recording``, ...) are shim modules that warn (DeprecationWarning) and give their new home's module
object (gyro_sim/_moved.py); they go in 0.2.
"""
import importlib

__version__ = "0.1.0"

#: public names → the module that holds them, imported on first use (PEP 562): `import gyro_sim` costs no
#: numba/SciPy import until a run needs it
_LAZY = {"Scene": "scenes.scene", "SceneError": "scenes.scene", "builtin_scenes": "scenes.scene",
         "load_scene": "scenes.scene", "scene_from_dict": "scenes.scene", "RunResult": "engine.simulate",
         "Simulator": "engine.simulate", "run": "engine.simulate", "read_bag": "io.results"}

def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    moved = importlib.import_module(f"{__name__}._moved").MOVED  # the deprecated flat paths: a shim module each
    if name == "MOVED":
        return moved
    if name in moved or name == "testing":  # gyro_sim.simulate without an import of it first: its shim (warns)
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'gyro_sim' has no attribute {name!r}")


__all__ = ["Scene", "SceneError", "builtin_scenes", "load_scene", "scene_from_dict", "RunResult", "Simulator",
           "run", "read_bag", "__version__"]
