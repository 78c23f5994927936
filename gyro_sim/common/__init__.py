"""Small helpers every layer may use: the optional dependencies of the pip extras and the one-line message for a
missing one (``extras``). Imports nothing of gyro_sim; the bottom layer.
"""
