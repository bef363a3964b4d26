"""Solvers for refraction points: the curve walk (seed 001), optimistix Newton baselines,
and an exhaustive all-solutions reference.

Each solver is an object of its options (`Walk`, `Newton`, `Exhaustive`), validated when
it is built; `solve(mesh, P, L, method="walk", **options)` is sugar for
`solve(mesh, P, L, method=Walk(**options))`.
"""

from ._solution import Solution, Status
from ._solve import METHODS, LocalSolve, check_lanes, returns_every_path, solve, solve_local
from .exhaustive import Exhaustive, ExhaustiveSolution
from .newton import Newton
from .options import SolverOptions, default_tol
from .trace import Trace
from .walk import Walk

__all__ = ["METHODS", "Exhaustive", "ExhaustiveSolution", "LocalSolve", "Newton", "Solution", "SolverOptions",
           "Status", "Trace", "Walk", "check_lanes", "default_tol", "returns_every_path", "solve", "solve_local"]
