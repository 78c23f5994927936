"""Physical constants (SI)."""
from scipy.constants import mu_0 as MU0  # vacuum permeability, H/m

__all__ = ["MU0"]
