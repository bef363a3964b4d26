"""`solve`: validate at the boundary, find start points, run the chosen solver jitted.

The solvers are objects of their options (`Walk`, `Newton`, `Exhaustive`, each validated
once in its constructor); `method="walk"` with keyword options is sugar for
`method=Walk(**options)`. Host analysis of the surface happens once per mesh
(`prepared.prepare`), never per call.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..features import GENERAL, SceneFeatures
from ..features import check as check_features
from ..lanes import compact_index, lane_bucket, pad_lanes, scatter_lanes
from ..mesh import SurfaceMesh
from ..prepared import PreparedSurface, prepare
from ..start_points import StartPoint
from ._solution import Solution, Status
from .exhaustive import Exhaustive, ExhaustiveSolution, solve_exhaustive
from .flat import flat_root, flat_solution
from .newton import Newton, solve_newton
from .options import SolverOptions, check_eta
from .walk import Walk, solve_walk

#: `method=` names and their solver classes.
METHODS: dict[str, type[SolverOptions]] = {"walk": Walk, "newton": Newton, "exhaustive": Exhaustive}


def solver_from(method, options: dict) -> SolverOptions:
    """The solver object for `method` (a name of `METHODS` with keyword options, or an
    instance, then without options); raises `ValueError` naming what is wrong."""
    if isinstance(method, SolverOptions):
        if options:
            raise ValueError(f"options {sorted(options)} given next to a solver object {method!r}: "
                             "set them on the object")
        return method
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {tuple(METHODS)} or a solver object "
                         f"(caustics_jax.Walk, Newton, Exhaustive), got {method!r}")
    return METHODS[method].from_kwargs(**options)


def check_points(name: str, X, dtype) -> np.ndarray:
    """`X` as a float64 numpy array of shape `(..., 3)`: real numbers (integers are
    promoted), finite, and finite after the cast to the mesh's `dtype`."""
    X = np.asarray(X)
    if X.dtype == bool or not (np.issubdtype(X.dtype, np.integer) or np.issubdtype(X.dtype, np.floating)):
        raise ValueError(f"{name} must hold real numbers (integer or float), got dtype {X.dtype}")
    if X.ndim == 0 or X.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (or broadcast to it), got {X.shape}")
    X = X.astype(np.float64)
    with np.errstate(over="ignore"):
        bad = ~np.all(np.isfinite(X) & np.isfinite(X.astype(dtype)), axis=-1)
    if np.any(bad):
        rows = np.nonzero(bad.reshape(-1))[0][:10].tolist()
        raise ValueError(f"{name} has NaN or Inf coordinates, or coordinates that overflow "
                         f"{np.dtype(dtype).name}, at rows {rows}")
    return X


def check_lanes(mesh: SurfaceMesh, P, L):
    """`P`, `L` broadcast to `(N, 3)` in the mesh's dtype (see `check_points`)."""
    dtype = mesh.dtype
    P_np, L_np = (check_points(name, X, dtype) for name, X in (("P", P), ("L", L)))
    try:
        P_np, L_np = np.broadcast_arrays(P_np.reshape(-1, 3) if P_np.ndim == 1 else P_np,
                                         L_np.reshape(-1, 3) if L_np.ndim == 1 else L_np)
    except ValueError as exc:
        raise ValueError(f"P {P_np.shape} and L {L_np.shape} do not broadcast") from exc
    if P_np.ndim != 2:
        raise ValueError(f"P and L must broadcast to (N, 3), got {P_np.shape}")
    return jnp.asarray(P_np, dtype), jnp.asarray(L_np, dtype)


def check_start(start, n: int, dtype) -> StartPoint | None:
    """A user-given `start=` (a `StartPoint`, or `(face, barycentric, found)`) for `n` lanes."""
    if start is None:
        return None
    try:
        face, ab, found = start
    except (TypeError, ValueError):
        raise ValueError("start must be a StartPoint or a tuple (face (N,), barycentric (N, 2), "
                         "found (N,)) from caustics_jax.start_points") from None
    face, ab, found = np.asarray(face), np.asarray(ab), np.asarray(found)
    if face.shape != (n,) or ab.shape != (n, 2) or found.shape != (n,):
        raise ValueError(f"start must hold face ({n},), barycentric ({n}, 2) and found ({n},) for the "
                         f"{n} lanes of P and L, got {face.shape}, {ab.shape}, {found.shape}")
    if not np.issubdtype(face.dtype, np.integer) or not np.all(np.isfinite(ab)):
        raise ValueError("start: face must be integer and barycentric finite")
    return StartPoint(jnp.asarray(face, jnp.int32), jnp.asarray(ab, dtype), jnp.asarray(found, bool))


def empty_solution(n: int, dtype, status: Status = Status.NO_CROSSING) -> Solution:
    """What every solver returns for a lane without a start point: `NO_CROSSING`, zeros,
    triangle -1, no iterations (also the result of zero lanes, `n = 0`)."""
    return Solution(
        point=jnp.zeros((n, 3), dtype), triangle=jnp.full(n, -1, jnp.int32),
        barycentric=jnp.zeros((n, 2), dtype), found=jnp.zeros(n, bool),
        status=jnp.full(n, status, jnp.int32), iterations=jnp.zeros(n, jnp.int32),
        residual=jnp.zeros(n, dtype), crossed=jnp.zeros(n, jnp.int32),
        start_point=jnp.zeros((n, 3), dtype),
    )


def solve(mesh: SurfaceMesh | PreparedSurface, P, L, *, eta: float = 1.333, method="walk", start=None,
          features="auto", **options) -> Solution:
    """Find refraction points `M` of paths `P -> M -> L` through the surface (seed 001 §3.4).

    Args:
        mesh: the refractive surface (`SurfaceMesh`, normals outward toward the light), or
            a `PreparedSurface` from `caustics_jax.prepare(mesh)` (either way the host
            analysis runs once per mesh).
        P: `(N, 3)` receivers inside the medium (cast to the mesh's dtype).
        L: `(N, 3)` light positions (or one `(3,)` broadcast to all).
        eta: `eta_in / eta_out` (water 1.333), one finite positive number.
        method: "walk" (seed 001 curve walk), "newton" (optimistix baselines),
            "exhaustive" (all solutions, reference), or a solver object `Walk(...)`,
            `Newton(...)`, `Exhaustive(...)`.
        start: optional precomputed `start_points(mesh, P, L)` result.
        features: `"auto"` (default: the mesh's `SceneFeatures`), `None` (always the
            general path) or a `SceneFeatures` from `features(mesh)`. Walk and Newton
            (`n_starts=1`) skip what the scene does not need: lanes whose segment cannot
            reach the surface skip the start-point search, lanes without a start point
            skip the solver (`NO_CROSSING`), and on a flat surface the walk's points come
            in closed form (`solvers/flat.py`). Same statuses and points as `None`
            (docs/features.md); `iterations` and `crossed` of closed-form lanes count the
            root solve's halvings and no crossings. Ignored by "exhaustive".
        **options: the solver's options when `method` is a name (`Walk`, `Newton`,
            `Exhaustive` list them).

    Walk and Newton batches are padded to `lane_bucket(N)` lanes and meshes to
    power-of-two sizes, so jit compiles once per size class.

    Returns a `Solution` (an `ExhaustiveSolution` for `Exhaustive(return_all=True)`);
    `status` holds `Status` codes and `found` is True exactly where a point with
    `|residual| <= tol` was returned. Bad input raises `ValueError` here, before any
    jitted work; zero lanes give an empty result.
    """
    prep = prepare(mesh)
    solver = solver_from(method, options)
    P, L = check_lanes(prep.mesh, P, L)
    eta = check_eta(eta)
    check_features(features)
    n, dtype = P.shape[0], prep.dtype
    start = check_start(start, n, dtype)
    if isinstance(solver, Exhaustive):
        if n == 0:
            if dtype != jnp.float64:
                raise ValueError("method='exhaustive' is the float64 reference: pass a float64 mesh")
            sol = empty_solution(0, dtype, Status.NO_SOLUTION)
            return ExhaustiveSolution(sol, np.zeros((0, 1, 3)), np.zeros((0, 1), np.int32),
                                      np.zeros(0, np.int32)) if solver.return_all else sol
        start = start if start is not None else prep.start_points(P, L)
        return solve_exhaustive(prep.mesh, P, L, eta, tuple(start), solver, padded=prep.padded)
    if isinstance(solver, Newton):
        solver.check_dtype(dtype)
    if n == 0:
        return empty_solution(0, dtype)
    feats = prep.features if isinstance(features, str) else features
    if feats is not None and feats != GENERAL and not (isinstance(solver, Newton) and solver.n_starts > 1):
        # (Newton's extra random starts are drawn per lane position: compaction would move them.)
        return _solve_specialised(prep, P, L, eta, start, solver, feats)
    start = start if start is not None else prep.start_points(P, L)
    return _run_padded(prep, P, L, eta, tuple(start), solver)


def _run_padded(prep: PreparedSurface, P, L, eta, start, solver) -> Solution:
    """The solver on the lanes padded to their size class, cut back to `N` lanes."""
    n = P.shape[0]
    P, L, start = pad_lanes(P, L, start)
    run = solve_walk if isinstance(solver, Walk) else solve_newton
    sol = run(prep.padded, P, L, eta, start, solver)
    return jax.tree.map(lambda x: x[:n], sol)


# --------------------------------------------------------------------------- specialised path
# (`features`, DESIGN.md "Skipping what a scene does not need"; docs/features.md)


def _compacted_start_points(prep: PreparedSurface, P, L):
    """`start_points` for the lanes whose segment's bounding box meets the mesh's; the rest
    (receiver and light both above the water, or both beside the pool) cannot cross."""
    n = P.shape[0]
    meets = prep.may_cross(np.asarray(P, np.float64), np.asarray(L, np.float64))
    base = (jnp.full(n, -1, jnp.int32), jnp.zeros((n, 2), prep.dtype), jnp.zeros(n, bool))
    idx = np.flatnonzero(meets)
    if idx.size == 0:
        return base
    if idx.size == n:  # nothing to skip: no gather, no scatter
        return tuple(prep.start_points(P, L))
    g, real = compact_index(idx)
    sub = prep.start_points(P[g], L[g])
    return scatter_lanes(base, g, real, (sub.face, sub.barycentric, sub.found))


def _solve_specialised(prep: PreparedSurface, P, L, eta, start, solver, feats: SceneFeatures) -> Solution:
    """`solve` for `features`: closed form where the scene allows it, the solver on the
    compacted remaining lanes, results scattered back (docs/features.md)."""
    n, dtype, mesh = P.shape[0], prep.dtype, prep.mesh
    if start is None:
        start = _compacted_start_points(prep, P, L) if feats.compact_lanes else tuple(prep.start_points(P, L))
    face, ab0, found = (jnp.asarray(x) for x in start)
    found_np = np.asarray(found)
    sol = empty_solution(n, dtype)
    need = found_np.copy() if feats.compact_lanes else np.ones(n, bool)
    if feats.flat and isinstance(solver, Walk) and found_np.any():
        g, real = compact_index(np.flatnonzero(found_np))
        P_g, L_g = P[g], L[g]
        _, below, above, usable = flat_root(mesh, P_g, L_g, eta)
        located = prep.start_points(below, above)
        flat_sol, good = flat_solution(mesh, P_g, L_g, eta, solver.tolerance(dtype), usable, tuple(located),
                                       face[g], ab0[g])
        keep = real & np.asarray(good)
        sol = scatter_lanes(sol, g, keep, flat_sol)
        need[g[keep]] = False
    if not need.any():
        return sol
    if need.all():  # nothing to skip: the general batch as is
        return _run_padded(prep, P, L, eta, (face, ab0, found), solver)
    g, real = compact_index(np.flatnonzero(need))
    run = solve_walk if isinstance(solver, Walk) else solve_newton
    sub = run(prep.padded, P[g], L[g], eta, (face[g], ab0[g], found[g] & jnp.asarray(real)), solver)
    return scatter_lanes(sol, g, real, sub)


__all__ = ["METHODS", "empty_solution", "lane_bucket", "solve", "solver_from"]
