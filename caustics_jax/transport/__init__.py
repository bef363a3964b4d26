"""Light transport along a solved refracted path: the D factor of seed 001 eq. 25-33."""

from .differentials import autodiff_D, ray_differential_D

__all__ = ["autodiff_D", "ray_differential_D"]
