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
``gyro_sim.recording``, ...) still import: each is the same module object as its new home (:data:`MOVED`).
"""
import importlib
import importlib.abc
import importlib.util
import sys
__version__ = "0.1.0"

#: public names → the module that holds them, imported on first use (PEP 562): `import gyro_sim` (and the pytest
#: plugin gyro_sim.testing, loaded in every pytest session) costs no numba/SciPy import until a run needs it
_LAZY = {"Scene": "scenes.scene", "SceneError": "scenes.scene", "builtin_scenes": "scenes.scene",
         "load_scene": "scenes.scene", "scene_from_dict": "scenes.scene", "RunResult": "engine.simulate",
         "Simulator": "engine.simulate", "run": "engine.simulate", "read_bag": "io.results"}

#: the module paths of before the layers (issue 22) → their home now, under gyro_sim
MOVED = {
    "extras": "common.extras",
    "constants": "physics.constants", "frames": "physics.frames", "conductor": "physics.conductor",
    "closed_forms": "physics.closed_forms", "magnetizable": "physics.magnetizable", "klt": "physics.klt",
    "flywheel": "physics.flywheel",
    "effects": "compiled.effects", "kernels": "compiled.kernels", "frozen_flow": "compiled.frozen_flow",
    "qs_flow": "compiled.qs_flow", "compile_watch": "compiled.compile_watch",
    "scene_text": "scenes.scene_text", "effect_config": "scenes.effect_config", "accuracy": "scenes.accuracy",
    "scene": "scenes.scene",
    "averaged": "averaging.averaged", "averaged_m": "averaging.averaged_m", "slow_k": "averaging.slow_k",
    "simulate": "engine.simulate", "ticks": "engine.ticks", "fidelity": "engine.fidelity",
    "warmup": "engine.warmup", "faults": "engine.faults",
    "messages": "io.messages", "recording": "io.recording", "bag_repair": "io.bag_repair",
    "results": "io.results", "rerun": "io.rerun", "live": "io.live", "plotting": "io.plotting",
    "cli": "apps.cli", "bench": "apps.bench", "bench_accuracy": "apps.bench_accuracy",
    "bench_baseline": "apps.bench_baseline", "bench_ros": "apps.bench_ros", "bench_scaling": "apps.bench_scaling",
    "bench_ticks": "apps.bench_ticks", "sweep": "apps.sweep", "sweep_tasks": "apps.sweep_tasks",
    "phase": "apps.phase", "api_docs": "apps.api_docs", "testing": "apps.testing",
}


class _OldPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports ``gyro_sim.<old>`` as the module object of its new home (both names, one module: an attribute set
    or monkeypatched through either is seen through the other; ``python -m gyro_sim.cli`` runs the new file)."""

    @staticmethod
    def _home(name: str):
        head, _, old = name.partition(".")
        return f"{head}.{MOVED[old]}" if head == __name__ and old in MOVED else None

    def find_spec(self, name, path=None, target=None):
        home = self._home(name)
        if home is None:
            return None
        return importlib.util.spec_from_loader(name, self)

    def __init__(self):
        self._specs: dict = {}  # alias name → its home's own spec, between create_module and exec_module

    def create_module(self, spec):
        module = importlib.import_module(self._home(spec.name))
        # the import machinery sets __spec__ to the alias's: put back in exec_module (kept per name: two threads
        # importing two old paths at once do not mix them up)
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        module.__spec__ = self._specs.pop(module.__spec__.name)  # (the home module ran when create_module imported it)

    def get_code(self, name):  # runpy: python -m gyro_sim.<old>
        home = self._home(name)
        return importlib.util.find_spec(home).loader.get_code(home)

    def is_package(self, name):
        return False


if not any(isinstance(f, _OldPaths) for f in sys.meta_path):
    sys.meta_path.insert(0, _OldPaths())  # (before an editable install's finder of the flat tree)


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in MOVED:  # gyro_sim.simulate without an import of it first (as before, once something had imported it)
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'gyro_sim' has no attribute {name!r}")


__all__ = ["Scene", "SceneError", "builtin_scenes", "load_scene", "scene_from_dict", "RunResult", "Simulator",
           "run", "read_bag", "__version__"]
