"""Physical models as pure functions and small classes, SI units: constants, frames and quaternions, the eddy-current
response of the conductor, closed forms of the seed papers ([M], [K], [BS], [KLT], [S]) and the flywheel planner.
May import ``gyro_sim.common`` only (NumPy/SciPy/numba as libraries); knows nothing of scenes, runs or files.
"""
