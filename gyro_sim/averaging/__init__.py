"""Averaged (slow) models of [K] and [M] used as fidelity levels and as checks of the full model: pure functions
of the slow state and the scene. May import ``gyro_sim.scenes``, ``gyro_sim.compiled``, ``gyro_sim.physics`` and
``gyro_sim.common``.
"""
