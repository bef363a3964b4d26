"""Solvers for refraction points: the curve walk (seed 001), optimistix Newton baselines,
and an exhaustive all-solutions reference."""

from ._solution import Solution, Status
from ._solve import solve

__all__ = ["Solution", "Status", "solve"]
