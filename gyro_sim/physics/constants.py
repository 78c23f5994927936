"""Physical constants (SI).

``MU0`` is SciPy's ``scipy.constants.mu_0`` (CODATA 2022), written out so that importing the simulator does not
import ``scipy.constants`` (which parses the whole CODATA table: 40–65 ms of every process's start-up);
``test/test_startup.py`` checks the two are the same float.
"""
MU0 = 1.25663706127e-06  # vacuum permeability, H/m (CODATA 2022, = scipy.constants.mu_0)

__all__ = ["MU0"]
