"""`solve`: validate at the boundary, find start points, run the chosen solver jitted.

The solvers are objects of their options (`Walk`, `Newton`, `Exhaustive`, each validated
once in its constructor); `method="walk"` with keyword options is sugar for
`method=Walk(**options)`. Host analysis of the surface happens once per mesh
(`prepared.prepare`), never per call.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec

from ..accel.prepared import PreparedSurface, prepare
from ..accel.start_points import StartPoint, first_crossing
from ..runtime.arguments import check_eta, check_fits, check_points, check_scene_scale, check_tol_resolves
from ..runtime.blocks import lane_mesh, on_devices, run_blocks
from ..runtime.compilation import enable_compilation_cache
from ..surface.features import GENERAL, SceneFeatures
from ..surface.features import check as check_features
from ..surface.lights import Directional, light_points, scene_size
from ..surface.mesh import SurfaceMesh
from ._solution import Solution, Status
from .exhaustive import Exhaustive, ExhaustiveSolution
from .flat import flat_root, flat_solution
from .newton import Newton
from .options import SolverOptions
from .sides import warn_if_no_crossing, warn_if_wrong_sides
from .solution_set import translated
from .trace import Trace, with_solutions
from .walk import Walk

#: `method=` names and their solver classes.
METHODS: dict[str, type[SolverOptions]] = {"walk": Walk, "newton": Newton, "exhaustive": Exhaustive,
                                          "trace": Trace}


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
    return METHODS[method](**options)


def check_lanes(mesh: SurfaceMesh, P, L, origin=None):
    """`P`, `L` broadcast to `(N, 3)` in the mesh's dtype (see `check_points`), moved by
    `-origin` (float64, before the cast) when given: `PreparedSurface.local`'s frame."""
    dtype = mesh.dtype
    P_np = check_points("P", P, dtype)
    if not isinstance(L, Directional):
        L_np = check_points("L", L, dtype)
        try:
            P_np, _ = np.broadcast_arrays(P_np.reshape(-1, 3) if P_np.ndim == 1 else P_np,
                                          L_np.reshape(-1, 3) if L_np.ndim == 1 else L_np)
        except ValueError as exc:
            raise ValueError(f"P {P_np.shape} and L {L_np.shape} do not broadcast") from exc
        if P_np.ndim != 2:
            raise ValueError(f"P and L must broadcast to (N, 3), got {P_np.shape}")
    P_np = P_np.reshape(-1, 3) if P_np.ndim == 1 else P_np
    # A directional light, or a point light beyond the limit distance: the point on each
    # receiver's ray toward it (surface/lights.py, math.md §9).
    L_in = L if isinstance(L, Directional) else L_np  # (checked above)
    L_np = light_points(L_in, P_np, scene_size(np.asarray(mesh.vertices, np.float64), P_np), dtype,
                        checked=True).points
    check_scene_scale(np.asarray(mesh.vertices), (P_np,), dtype, (L_np,))
    if origin is not None and np.any(origin):
        P_np, L_np = P_np - origin, L_np - origin
    # (cast and copied on the host: jnp.asarray of a numpy array compiles once per shape)
    return jax.device_put(P_np.astype(dtype)), jax.device_put(L_np.astype(dtype))


def returns_every_path(method, options: dict) -> bool:
    """Whether `solve(..., method=method, **options)` returns every path per receiver (an
    `ExhaustiveSolution`: `Trace`, `Exhaustive(return_all=True)`, `solutions="all"`); a
    `ValueError` for a bad method or option, as `solve` would raise."""
    return solver_from(*with_solutions(method, options)).every_path()


def check_start(start, n: int, dtype, n_faces: int | None = None) -> StartPoint | None:
    """A user-given `start=` (a `StartPoint`, or `(face, barycentric, found)`) for `n` lanes."""
    if start is None:
        return None
    try:
        face, ab, found = start
    except (TypeError, ValueError):
        raise ValueError("start must be a StartPoint or a tuple (face (N,), barycentric (N, 2), "
                         "found (N,)) from caustics_jax.accel.start_points") from None
    face, ab, found = np.asarray(face), np.asarray(ab), np.asarray(found)
    if face.shape != (n,) or ab.shape != (n, 2) or found.shape != (n,):
        raise ValueError(f"start must hold face ({n},), barycentric ({n}, 2) and found ({n},) for the "
                         f"{n} lanes of P and L, got {face.shape}, {ab.shape}, {found.shape}")
    if face.dtype == bool or not np.issubdtype(face.dtype, np.integer) or found.dtype != bool:
        raise ValueError(f"start: face must hold integers and found booleans, got {face.dtype} and {found.dtype}")
    if not (ab.dtype != bool and (np.issubdtype(ab.dtype, np.integer) or np.issubdtype(ab.dtype, np.floating))
            and np.all(np.isfinite(ab))):
        raise ValueError(f"start: barycentric must hold finite real numbers, got {ab.dtype}")
    bad = np.flatnonzero(found & ((face < 0) | (face >= (n_faces if n_faces is not None else np.inf))))
    if bad.size:
        raise ValueError(f"start: face must lie in [0, {n_faces}) where found, got {face[bad[:5]].tolist()} "
                         f"at lanes {bad[:5].tolist()}")
    # The walk and Newton start on the face: a point outside it is not on the face's conic
    # (5.0 gave FOUND 3 of 16 lanes and wrong TIR / LEFT_MESH statuses for the rest).
    a, b = ab[..., 0], ab[..., 1]
    slack = 1e-5  # rounding of a float32 start point computed elsewhere
    bad = np.flatnonzero(found & ((a < -slack) | (b < -slack) | (a + b > 1 + slack)))
    if bad.size:
        raise ValueError(f"start: barycentric must lie in the closed face (a, b >= 0, a + b <= 1, to {slack:g}) "
                         f"where found, got {ab[bad[:5]].tolist()} at lanes {bad[:5].tolist()}")
    return StartPoint(jnp.asarray(np.where(found, face, -1), jnp.int32), jnp.asarray(ab, dtype),
                      jnp.asarray(found, bool))


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


class LocalSolve(NamedTuple):
    """A solve in the frame of `prepare(mesh).local` (`solve_local`): what `irradiance`
    sums there, and `solve` moves back with `to_global`.

    Attributes:
        result: the `Solution` (or `ExhaustiveSolution`), points in the local frame.
        prep: the surface the solvers ran on (`prepare(mesh).local`).
        P, L: `(N, 3)` receivers and lights in that frame, the mesh's dtype.
        origin: `(3,)` float64 `prepare(mesh).origin` (zero near the origin).
        has_start: `(N,)` lanes with a start point `M0` (`start_point` is zero elsewhere).
    """

    result: Solution | ExhaustiveSolution
    prep: PreparedSurface
    P: jax.Array
    L: jax.Array
    origin: np.ndarray
    has_start: np.ndarray

    def to_global(self) -> Solution | ExhaustiveSolution:
        """`result` in the caller's frame (`solution_set.translated`)."""
        return translated(self.result, self.origin, self.has_start)


def solve(mesh: SurfaceMesh | PreparedSurface, P, L, *, eta: float = 1.333, method="walk", start=None,
          features="auto", **options) -> Solution:
    """Find refraction points `M` of paths `P -> M -> L` through the surface (seed 001 §3.4).

    Args:
        mesh: the refractive surface (`SurfaceMesh`, normals outward toward the light), or
            a `PreparedSurface` from `caustics_jax.prepare(mesh)` (either way the host
            analysis runs once per mesh).
        P: `(N, 3)` receivers inside the medium (cast to the mesh's dtype).
        L: `(N, 3)` light positions (or one `(3,)` broadcast to all), or a
            `Directional(direction)` (the sun: surface/lights.py, math.md §9).
        eta: `eta_in / eta_out` (water 1.333), one finite positive number.
        method: "walk" (the default: seed 001 curve walk), "newton" (optimistix
            baselines), "exhaustive" (all solutions, the float64 reference), "trace"
            (every solution on the walk's curve), or a solver object `Walk(...)`,
            `Newton(...)`, `Exhaustive(...)`, `Trace(...)`.
        start: optional precomputed `start_points(mesh, P, L)` result.
        features: `"auto"` (default: the mesh's `SceneFeatures`), `None` (always the
            general path) or a `SceneFeatures` from `features(mesh)`. Walk and Newton
            skip what the scene does not need: lanes whose segment cannot
            reach the surface skip the start-point search, lanes without a start point
            skip the solver (`NO_CROSSING`), and on a flat surface the walk's points come
            in closed form (`solvers/flat.py`). Same statuses and points as `None`,
            except on flat surfaces: points within 6.8e-6 m (float32), 6.2e-11 m
            (float64), and a few lanes the walk ends LOST_CURVE are FOUND
            (docs/features.md); `iterations` and `crossed` of closed-form lanes count the
            root solve's halvings and no crossings. Ignored by "exhaustive".
        **options: the solver's options when `method` is a name (`Walk`, `Newton`,
            `Exhaustive`, `Trace` list them); `solutions="all"` (walk or exhaustive)
            asks for every solution per lane.

    Walk and Newton run the lanes in fixed-size blocks spread over every local device
    (`blocks.run_blocks`, `blocks.on_devices`) on the mesh padded to power-of-two sizes:
    jit compiles once per method, dtype and mesh size class, whatever `N`, and JAX's
    persistent compilation cache keeps the programs between processes
    (`caustics_jax.runtime.compilation`; `CAUSTICS_JAX_COMPILATION_CACHE=0` turns it off).

    A mesh far from the coordinate origin is solved about its centre
    (`frames.local_origin`: `P`, `L` and the mesh moved by `-origin` in float64, exactly
    for the mesh) and the points come back moved by `+origin`, rounded once: float32 keeps
    the digits the triangles need (docs/input_contract.md "Scale").

    Returns a `Solution` (an `ExhaustiveSolution` for `Exhaustive(return_all=True)`,
    `Trace` and `solutions="all"`);
    `status` holds `Status` codes and `found` is True exactly where a point with
    `|residual| <= tol` was returned. Bad input raises `ValueError` here, before any
    jitted work; zero lanes give an empty result.
    """
    return solve_local(mesh, P, L, eta=eta, method=method, start=start, features=features, **options).to_global()


def solve_local(mesh: SurfaceMesh | PreparedSurface, P, L, *, eta: float = 1.333, method="walk", start=None,
                features="auto", **options) -> LocalSolve:
    """`solve` (same arguments and checks) without moving the result back: a `LocalSolve`
    in the frame of `prepare(mesh).local`, for callers that go on computing there
    (`irradiance`)."""
    glob = prepare(mesh)
    solver = solver_from(*with_solutions(method, options))
    P, L = check_lanes(glob.mesh, P, L, glob.origin)
    prep = glob.local

    def done(result, has_start):
        has_start = np.asarray(has_start, bool)
        warn_if_no_crossing(prep, P, L, has_start)  # the light below the surface, receivers above it
        return LocalSolve(result, prep, P, L, glob.origin, has_start)

    n, dtype = P.shape[0], prep.dtype
    eta = check_fits("eta", check_eta(eta), dtype, positive=True)
    solver.check_dtype(dtype)  # before the tolerance is judged (the exhaustive reference's is float64's)
    check_tol_resolves("tol", getattr(solver, "tol", None), dtype)
    check_features(features)
    start = check_start(start, n, dtype, prep.mesh.faces.shape[0])
    if not solver.in_blocks:  # the exhaustive reference, every path on the traced curve
        if n == 0:
            sol = empty_solution(0, dtype, Status.NO_SOLUTION)
            return done(ExhaustiveSolution.empty(sol) if solver.every_path() else sol, np.zeros(0, bool))
        start = start if start is not None else prep.start_points(P, L)
        return done(solver.solve_whole(prep, P, L, eta, tuple(start)), start[2])
    if n == 0:
        return done(empty_solution(0, dtype), np.zeros(0, bool))
    feats = prep.features if isinstance(features, str) else features
    sol = _solve_blocks(prep, P, L, eta, start, solver, None if feats == GENERAL else feats)
    warn_if_wrong_sides(prep, P, L, sol)  # mesh wound clockwise, or P and L swapped (solvers/sides.py)
    return done(sol, np.asarray(sol.status) != Status.NO_CROSSING)


# --------------------------------------------------------------------------- blocks of lanes
# Walk and Newton see lanes only in blocks of `blocks.lanes_per_block()` (the last one padded
# with lanes that need no work), split over every local device: one compile per method,
# dtype and mesh size class, whatever the lane count (docs/solvers.md "Batching").


def _solve_blocks(prep: PreparedSurface, P, L, eta, start, solver, feats: SceneFeatures | None) -> Solution:
    """Walk or Newton on every lane, block by block; with `feats` (docs/features.md) lanes
    whose segment cannot reach the surface never enter a block (`NO_CROSSING`), and on a
    flat surface the walk's points come in closed form."""
    enable_compilation_cache()
    n, dtype = P.shape[0], prep.dtype
    P_np, L_np = np.asarray(P), np.asarray(L)
    lanes = np.arange(n)
    if feats is not None and feats.compact_lanes and start is None:
        lanes = np.flatnonzero(prep.may_cross(P_np.astype(np.float64), L_np.astype(np.float64)))
    # Padding lanes: a zero-length segment beside the surface (no start point, no work).
    away = np.asarray(prep.hi + 2 * prep.pad + 1, dtype)
    fields = [P_np[lanes], L_np[lanes], lanes.astype(np.int32)]
    fill = [away, away, np.int32(0)]
    if start is not None:
        fields += [np.asarray(x)[lanes] for x in start]
        fill += [np.int32(-1), np.zeros(2, dtype), False]
    flat = feats is not None and feats.flat and solver.flat_closed_form
    out = run_blocks(lambda *block: _solve_block(prep, eta, solver, flat, *block), tuple(fields), tuple(fill))
    if solver.fallbacks(prep.dtype):
        out = _fallback(prep, eta, solver, fields, fill, out)
    sol = _empty_fields(n, dtype)
    for k, v in out.items():
        sol[k][lanes] = v
    return Solution(**jax.device_put(sol))


#: Lanes per block of the walk's Newton fallback (`_newton_fallback`), per device: the few
#: lanes the walk ends without a path, in blocks of their own size (one compile per mesh
#: size class, whatever the batch).
FALLBACK_BLOCK_LANES = 1024


def _fallback(prep: PreparedSurface, eta, solver, fields: list, fill: list, out: dict) -> dict:
    """The lanes with a start point that `solver` ended without a path, solved again by
    each of `solver.fallbacks` in turn from the same start point, on those lanes only
    (`Walk(fallback="newton")`: the one-step Newton, then the same from Cycles' gentle
    first step 0.1; docs/solvers.md "Robustness on irregular meshes"); where one finds a
    path, its point, triangle, barycentrics, status and residual replace the lane's, and
    its iterations and crossings are added to the lane's. Other lanes are untouched."""
    size = FALLBACK_BLOCK_LANES * len(jax.local_devices())
    for retry_solver in solver.fallbacks(prep.dtype):
        failed = np.flatnonzero((out["status"] != Status.FOUND) & (out["status"] != Status.NO_CROSSING))
        if failed.size == 0:
            break
        retry = run_blocks(lambda *block, r=retry_solver: _solve_block(prep, eta, r, False, *block),
                           tuple(x[failed] for x in fields), tuple(fill), size=size)
        rescued = retry["found"]
        lanes = failed[rescued]
        for k in ("point", "triangle", "barycentric", "found", "status", "residual"):
            out[k][lanes] = retry[k][rescued]
        for k in ("iterations", "crossed"):
            out[k][lanes] += retry[k][rescued]
    return out


def _empty_fields(n: int, dtype) -> dict:
    """`empty_solution` as numpy arrays (built on the host: no compile per lane count)."""
    dtype = np.dtype(dtype)
    return {"point": np.zeros((n, 3), dtype), "triangle": np.full(n, -1, np.int32),
            "barycentric": np.zeros((n, 2), dtype), "found": np.zeros(n, bool),
            "status": np.full(n, Status.NO_CROSSING, np.int32), "iterations": np.zeros(n, np.int32),
            "residual": np.zeros(n, dtype), "crossed": np.zeros(n, np.int32),
            "start_point": np.zeros((n, 3), dtype)}


def _solve_block(prep: PreparedSurface, eta, solver, flat: bool, P, L, lane_id, *start) -> dict:
    """One block: start points (unless given), the flat closed form where it settles a lane,
    the solver on the rest. Every call sees the same shapes."""
    sharding = NamedSharding(lane_mesh(), PartitionSpec("lanes"))
    P, L, lane_id = (jax.device_put(x, sharding) for x in (P, L, lane_id))
    if start:
        face, ab0, found = (jax.device_put(x, sharding) for x in start)
    else:
        face, ab0, found = _block_start_points(prep, P, L)
    run = lambda need: solver.solve_block(prep.padded, P, L, eta, (face, ab0, need), lane_id)  # noqa: E731
    if not flat:
        return _fields(run(found))
    mesh = prep.mesh
    _, below, above, usable = flat_root(mesh, P, L, eta)
    located = _block_start_points(prep, below, above)
    flat_sol, good = flat_solution(mesh, P, L, eta, solver.tolerance(prep.dtype), usable, tuple(located),
                                   face, ab0)
    good = good & found
    return _select_fields(good, _fields(flat_sol), _fields(run(found & ~good)))


def _block_start_points(prep: PreparedSurface, P, L) -> StartPoint:
    """`prep.start_points(P, L)` for one block (validated lanes of the block's shape, in
    `prep`'s frame) as a block program (`blocks.on_devices`): compiled once per mesh size
    class and accel shape with the project's XLA options, its lanes split over the devices."""
    mesh = prep.padded  # no static grid: the accel carries the layout as arrays
    face, ab, found = on_devices(_start_points_program, None, (mesh, prep.accel), (P, L))
    return StartPoint(face, ab, found)


def _start_points_program(mesh, accel, P, L, static):
    del static
    return first_crossing(mesh, P, L, accel=accel)


def _fields(sol: Solution) -> dict:
    return {f.name: getattr(sol, f.name) for f in dataclasses.fields(Solution)}


@jax.jit
def _select_fields(mask, a: dict, b: dict) -> dict:
    return {k: jnp.where(mask.reshape(mask.shape + (1,) * (a[k].ndim - 1)), a[k], b[k]) for k in a}


__all__ = ["METHODS", "LocalSolve", "check_lanes", "empty_solution", "returns_every_path", "solve", "solve_local",
           "solver_from"]
