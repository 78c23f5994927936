"""The scene format: YAML text limits and guarded loading (``scene_text``), the ``effects`` and ``accuracy`` sections,
the validated :class:`~gyro_sim.scenes.scene.Scene` and the built-in scenes. May import ``gyro_sim.physics``,
``gyro_sim.compiled`` and ``gyro_sim.common``; nothing here runs a simulation.
"""
