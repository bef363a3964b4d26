"""Solvers for refraction points: the curve walk (seed 001), optimistix Newton baselines,
and an exhaustive all-solutions reference.

Each solver is an object of its options (`Walk`, `Newton`, `Exhaustive`), validated when
it is built; `solve(mesh, P, L, method="walk", **options)` is sugar for
`solve(mesh, P, L, method=Walk(**options))`.

The plumbing that the transport layer shares with `solve` (`check_lanes`, `solve_local`,
`returns_every_path`) lives in `solvers._solve` and is not part of this surface.
"""

from ._solution import Solution, Status
from ._solve import solve
from .exhaustive import Exhaustive, ExhaustiveSolution
from .newton import Newton
from .options import SolverOptions, default_tol
from .trace import Trace
from .walk import Walk

__all__ = ["Exhaustive", "ExhaustiveSolution", "Newton", "Solution", "SolverOptions", "Status", "Trace", "Walk",
           "default_tol", "solve"]
