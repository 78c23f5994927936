"""The simulator, in parts shaped like a solver library's: :func:`~gyro_sim.engine.simulate.run` (the entry),
``terms`` (the model of a scene), ``step_size`` (the controller of the step), ``steppers`` (one interface to the
compiled steppers), ``saving`` (the output), ``shadow`` (the error estimate: the shadow run and the error control),
the :class:`~gyro_sim.engine.simulator.Simulator` (a run's state, composing them), the
:class:`~gyro_sim.engine.runner.Runner` (the run loop: breaks, controller ticks, samples), the
:class:`~gyro_sim.engine.result.RunResult`, the compiled tick loop,
the fidelity driver (full / averaged / hybrid), fault injection and the warm-up of the numba cache. May import every
layer below (``averaging``, ``scenes``, ``compiled``, ``physics``, ``common``) and ``gyro_ctl``; never files, topics
or plots.
"""
