"""gyro_sim: simulator of an electrodynamically controlled gyroscope rotor.

The pure core (this package minus ``gyro_sim.ros``) never imports rclpy. In a notebook::

    import gyro_sim
    scene = gyro_sim.load_scene("spinup_thin_shell")      # or a path to a YAML file
    result = gyro_sim.run(scene, duration=10.0)             # time series as NumPy arrays
    result.t, result.L, result.euler[:, 1], result.summary()
"""
__version__ = "0.1.0"

from .scene import Scene, SceneError, builtin_scenes, load_scene, scene_from_dict  # noqa: E402
from .simulate import RunResult, Simulator, run  # noqa: E402

__all__ = ["Scene", "SceneError", "builtin_scenes", "load_scene", "scene_from_dict", "RunResult", "Simulator",
           "run", "__version__"]
