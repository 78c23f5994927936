"""Compile the numba kernels of the built-in scenes ahead of their first run (``gyro-sim warmup``).

A kernel compiles on its first use with an install (then it is loaded from numba's on-disk cache, see
:mod:`gyro_sim.compile_watch`). ``.ci/setup`` runs this once after installing, so the README's first commands
start at once; any other install (a plain ``pip install .``, colcon, a Dask worker with its own cache) pays the
same compile once, announced by one line, and can run ``gyro-sim warmup`` too.
"""
from __future__ import annotations

import time
from typing import Callable, Iterable, Optional

from gyro_sim.compiled.compile_watch import compile_seconds

__all__ = ["warm", "currents_off"]

#: simulated seconds each scene runs: long enough to pass its first control tick and output sample
WARM_DURATION = 0.05


def warm(names: Optional[Iterable[str]] = None, say: Callable[[str], None] = print) -> float:
    """Run each scene (default: every built-in one) for :data:`WARM_DURATION` s, as scenes run in-process, as
    `gyro-sim run` runs them (a caller taking each sample: its progress line) and as the ROS node and recordings run
    them (with the attitude), so every kernel they use is compiled and cached. Returns the
    compile seconds spent (0 where the cache was warm)."""
    from gyro_sim.scenes.scene import builtin_scenes, load_scene
    from gyro_sim.engine.simulate import run

    c_start = compile_seconds()
    for name in names or list(builtin_scenes()):
        c0, w0 = compile_seconds(), time.perf_counter()
        scene = load_scene(name)
        d = min(scene.duration, WARM_DURATION)
        run(scene, duration=d)
        run(scene, duration=d, on_samples=_ignore)  # (as `gyro-sim run` does: each sample a break, for its progress)
        if scene.fidelity != "full" or not scene.output.attitude:
            run(load_scene(name, overrides={"fidelity": "full"}), duration=d, attitude=True)
        currents_off(load_scene(name, overrides={"fidelity": "full"}), d)
        c = compile_seconds() - c0
        if c > 0:
            say(f"warmup: {name}: compiled in {c:.1f} s ({time.perf_counter() - w0:.1f} s)")
    return compile_seconds() - c_start


def _ignore(samples: dict) -> None:
    """An ``on_samples`` that takes the rows and does nothing with them."""


def currents_off(scene, duration: float) -> None:
    """Run ``scene`` as the ROS simulator node does (gyro_sim/ros/simulator_node.py: a streamed
    :class:`~gyro_sim.simulate.Runner` with the attitude) with every stator current set to 0 A at its first control
    tick after t = 0: the path of a lost controller (``on_controller_lost currents_off``) and of the watchdog, where
    the torque-free integrator takes over (its kernel compiled mid-run before ``warmup`` ran this)."""
    from gyro_sim.engine.simulate import Runner, controller_period

    if not scene.stators:
        return
    # (the node streams its rows through a small buffer: the same kernels, whatever the buffer's size)
    r = Runner(scene, duration, attitude=True, control_period=controller_period(scene) or 0.01,  # (the node's default)
               buffer_rows=64)
    zero = {n: (0.0, None) for n in r.sim.stator_names}
    while not r.done:
        if r.row > 0 and r.is_control_tick:
            r.apply_commands(zero)
        r.advance()
        r.release()
