"""gyro_sim: simulator of an electrodynamically controlled gyroscope rotor.

The pure core (this package minus ``gyro_sim.ros``) never imports rclpy.
"""
__version__ = "0.1.0"
