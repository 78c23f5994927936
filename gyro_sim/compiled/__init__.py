"""Compiled kernels and steppers of the full model: plain numba functions on arrays, no Python objects (right-hand side,
lawson8 / ETDRK4 / free-rotor steppers, the frozen-flow and quasi-static-flow steps, the effects' compiled pieces),
and where numba compiles (``compile_watch``). May import ``gyro_sim.physics`` and ``gyro_sim.common``.
A new stepper is one file here.
"""
from gyro_sim.compiled.cache_stamp import install as _install_cache_stamp

_install_cache_stamp()  # (before any kernel module: their caches follow every kernel source, cache_stamp)
