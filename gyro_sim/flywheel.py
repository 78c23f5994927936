"""Deprecated path of :mod:`gyro_sim.physics.flywheel` (gone in gyro_sim 0.2).

Importing it warns and gives that module (gyro_sim/_moved.py)."""
from gyro_sim._moved import alias

alias(__name__)
