"""The flat module paths of before the layers (``gyro_sim.simulate``, ``gyro_sim.kernels``, ...): each is a shim
module (``gyro_sim/<old>.py``) that warns (DeprecationWarning) and hands back its new home's module object, so an
attribute set or monkeypatched through either name is seen through the other. They go in gyro_sim 0.2.

``gyro_sim.testing``, the pytest plugin's public path, is not among them (gyro_sim/testing.py).
"""
import importlib
import runpy
import sys
import warnings

__all__ = ["MOVED", "alias"]

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
    "phase": "apps.phase", "api_docs": "apps.api_docs",
}


def alias(name: str) -> None:
    """Make ``sys.modules[name]`` (``gyro_sim.<old>``, a shim) its new home's module, with a DeprecationWarning;
    run as ``python -m gyro_sim.<old>``, run the new home as the main module."""
    if name == "__main__":  # python -m gyro_sim.<old>: the shim's spec names it
        spec = sys.modules["__main__"].__spec__
        assert spec is not None  # (run with -m: a spec)
        name = spec.name
        home = f"gyro_sim.{MOVED[name.rpartition('.')[2]]}"
        warnings.warn(f"python -m {name} is deprecated: use python -m {home}", DeprecationWarning, stacklevel=2)
        runpy.run_module(home, run_name="__main__", alter_sys=True)
        return
    home = f"gyro_sim.{MOVED[name.rpartition('.')[2]]}"
    warnings.warn(f"{name} is deprecated (goes in gyro_sim 0.2): import {home}", DeprecationWarning, stacklevel=3)
    sys.modules[name] = importlib.import_module(home)
