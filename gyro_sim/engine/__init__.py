"""The simulator: the :class:`~gyro_sim.engine.simulator.Simulator` (assembles the model of a scene and advances it
with the compiled steppers), the :class:`~gyro_sim.engine.runner.Runner` (breaks, controller ticks, samples),
the :class:`~gyro_sim.engine.result.RunResult`, :func:`~gyro_sim.engine.simulate.run`, the compiled tick loop,
the fidelity driver (full / averaged / hybrid), fault injection and the warm-up of the numba cache. May import every
layer below (``averaging``, ``scenes``, ``compiled``, ``physics``, ``common``) and ``gyro_ctl``; never files, topics
or plots.
"""
