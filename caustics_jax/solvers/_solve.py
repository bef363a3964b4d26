"""`solve`: validate at the boundary, find start points, run the chosen solver jitted."""

from __future__ import annotations

import dataclasses
import functools
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..barycentric import barycentric_point
from ..features import GENERAL, SceneFeatures
from ..features import check as check_features
from ..features import resolve as resolve_features
from ..mesh import SurfaceMesh
from ..start_points import start_points
from ._solution import Solution, Status
from .newton import newton_options, solve_newton
from .walk import WalkOptions, default_tol, walk_lane

METHODS = ("walk", "newton", "exhaustive")


def _validate(mesh, P, L, eta, method):
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    dtype = mesh.dtype
    out = []
    for name, X in (("P", P), ("L", L)):
        X = np.asarray(X)
        if X.ndim == 0 or X.shape[-1] != 3:
            raise ValueError(f"{name} must have shape (N, 3) (or broadcast to it), got {X.shape}")
        if not np.issubdtype(X.dtype, np.number):
            raise ValueError(f"{name} must be numeric, got dtype {X.dtype}")
        bad = ~np.all(np.isfinite(X), axis=-1)
        if np.any(bad):
            rows = np.nonzero(bad.reshape(-1))[0][:10].tolist()
            raise ValueError(f"{name} has NaN or Inf coordinates at rows {rows}")
        out.append(X)
    try:
        P, L = np.broadcast_arrays(out[0].reshape(-1, 3) if out[0].ndim == 1 else out[0],
                                   out[1].reshape(-1, 3) if out[1].ndim == 1 else out[1])
    except ValueError as exc:
        raise ValueError(f"P {out[0].shape} and L {out[1].shape} do not broadcast") from exc
    if P.ndim != 2:
        raise ValueError(f"P and L must broadcast to (N, 3), got {P.shape}")
    eta_f = float(eta)
    if not np.isfinite(eta_f) or eta_f <= 0:
        raise ValueError(f"eta must be a finite positive index ratio, got {eta}")
    return jnp.asarray(P, dtype), jnp.asarray(L, dtype), eta_f


def _bucket(n: int, minimum: int = 256) -> int:
    return max(minimum, 1 << (max(n, 1) - 1).bit_length())


LANE_CHUNK = int(os.environ.get("CAUSTICS_JAX_LANE_CHUNK", 256))


def map_lanes(fn, *args, chunk: int | None = None):
    """`vmap(fn)` over lanes, `chunk` lanes at a time (`lax.map` with `batch_size`).

    A vmapped while loop runs until its slowest lane ends: over 100k lanes one lane that
    needs 90 iterations (median 5) would hold up all of them. In chunks, each chunk stops
    at its own slowest lane.
    """
    chunk = LANE_CHUNK if chunk is None else chunk
    if args[0].shape[0] <= chunk:
        return jax.vmap(fn)(*args)
    return jax.lax.map(lambda a: fn(*a), args, batch_size=chunk)


def lane_bucket(n: int) -> int:
    """Lanes a batch is padded to: a power of two up to 4096 (at least 256), then a multiple
    of 4096 (at most 4% extra work above 100k lanes), so jit compiles once per size class."""
    return _bucket(n, 256) if n <= 4096 else -(-n // 4096) * 4096


def _pad_lanes(P, L, start):
    """Pad lanes with copies of lane 0 marked `found = False` (they end at once)."""
    n = P.shape[0]
    extra = lane_bucket(n) - n
    if extra == 0:
        return P, L, start

    def pad(x, value=None):
        fill = jnp.broadcast_to(x[:1] if value is None else jnp.asarray(value, x.dtype),
                                (extra,) + x.shape[1:])
        return jnp.concatenate([x, fill])

    face, ab0, found = start
    return pad(P), pad(L), (pad(face), pad(ab0), pad(found, False))


def bucketed(mesh: SurfaceMesh) -> SurfaceMesh:
    """The mesh padded to power-of-two face and vertex counts, so jit compiles once per bucket.

    The static `grid` layout is dropped. Padding faces are `(0, 0, 0)` with no neighbours
    and are never referenced by a real face's adjacency, so no walk can enter them;
    padding vertices are zeros.
    """
    F, V = mesh.faces.shape[0], mesh.vertices.shape[0]
    Fb, Vb = _bucket(F), _bucket(V)
    # The solvers never read the grid layout (only start points do); as a static field it
    # would make every pool size its own compile.
    mesh = dataclasses.replace(mesh, grid=None)
    if (F, V) == (Fb, Vb):
        return mesh

    def pad(x, n, value):
        return jnp.concatenate([x, jnp.full((n - x.shape[0],) + x.shape[1:], value, x.dtype)])

    return eqx.tree_at(
        lambda m: (m.vertices, m.normals, m.faces, m.face_normals, m.neighbors, m.neighbor_edge),
        mesh,
        (pad(mesh.vertices, Vb, 0), pad(mesh.normals, Vb, 0), pad(mesh.faces, Fb, 0),
         pad(mesh.face_normals, Fb, 0), pad(mesh.neighbors, Fb, -1), pad(mesh.neighbor_edge, Fb, -1)),
    )


@functools.partial(jax.jit, static_argnames=("options",))
def _walk_batch(mesh, P, L, face, ab0, found, eta, tol, max_steps,
                options: WalkOptions) -> Solution:
    eta = jnp.asarray(eta, mesh.dtype)
    tol = jnp.asarray(tol, mesh.dtype)
    states = map_lanes(
        lambda p, l, f, a, ok: walk_lane(mesh, p, l, f, a, ok, eta, options, tol, max_steps),
        P, L, face, ab0, found)
    V, N = mesh.triangle(states.face)
    from ..objectives import signed_sine

    residual = signed_sine(V, N, P, L, states.best_ab, eta, orientation="plane")
    status = states.status
    found_out = status == Status.FOUND
    V0, _ = mesh.triangle(face)
    return Solution(
        point=jnp.where(found[:, None], barycentric_point(V, states.best_ab), 0),
        triangle=jnp.where(found, states.face, -1),
        barycentric=jnp.where(found[:, None], states.best_ab, 0),
        found=found_out,
        status=status,
        iterations=states.steps,
        residual=jnp.where(found, residual, 0),
        crossed=states.crossed,
        start_point=jnp.where(found[:, None], barycentric_point(V0, ab0), 0),
    )


def _walk_options(**options) -> WalkOptions:
    try:
        opts = WalkOptions(**options)
    except TypeError as exc:
        raise ValueError(f"unknown walk option: {exc}") from exc
    if opts.bracket not in ("illinois", "bisection"):
        raise ValueError(f"bracket must be 'illinois' or 'bisection', got {opts.bracket!r}")
    if opts.max_steps < 1 or opts.ellipse_samples < 2:
        raise ValueError("max_steps must be >= 1 and ellipse_samples >= 2")
    return opts


def solve(mesh: SurfaceMesh, P, L, *, eta: float = 1.333, method: str = "walk", start=None,
          features="auto", **options) -> Solution:
    """Find refraction points `M` of paths `P -> M -> L` through the surface (seed 001 §3.4).

    Args:
        mesh: the refractive surface (`SurfaceMesh`), normals outward toward the light.
        P: `(N, 3)` receivers inside the medium (cast to the mesh's dtype).
        L: `(N, 3)` light positions (or one `(3,)` broadcast to all).
        eta: `eta_in / eta_out` (water 1.333).
        method: "walk" (seed 001 curve walk), "newton" (optimistix baselines) or
            "exhaustive" (all solutions, reference).
        start: optional precomputed `start_points(mesh, P, L)` result.
        features: `"auto"` (default: `caustics_jax.features(mesh)`), `None` (always the
            general path) or a `SceneFeatures` from `features(mesh)`. Walk and Newton
            (`n_starts=1`) skip what the scene does not need: lanes whose segment cannot
            reach the surface skip the start-point search, lanes without a start point
            skip the solver (`NO_CROSSING`), and on a flat surface the walk's points come
            in closed form (`solvers/flat.py`). Same statuses and points as `None`
            (docs/features.md); `iterations` and `crossed` of closed-form lanes count the
            root solve's halvings and no crossings. Ignored by "exhaustive".
        **options: per method; "walk": `tol`, `max_steps`, `bracket`, `ellipse_samples`
            (`WalkOptions`); "newton": `solver`, `constraint`, `tol`, `inner_steps`,
            `max_patches`, `n_starts`, `seed` (`NewtonOptions`); "exhaustive": `samples`,
            `iters`, `tol`, `chunk`, `dedupe`, `return_all`.

    Walk and Newton batches are padded to `lane_bucket(N)` lanes and meshes to
    power-of-two sizes, so jit compiles once per size class.

    Returns a `Solution`; `status` holds `Status` codes and `found` is True exactly where a
    point with `|residual| <= tol` was returned. Bad input raises `ValueError` here,
    before any jitted work.
    """
    P, L, eta = _validate(mesh, P, L, eta, method)
    check_features(features)
    if method == "exhaustive":
        from .exhaustive import OPTIONS, solve_exhaustive

        unknown = sorted(set(options) - set(OPTIONS))
        if unknown:
            raise ValueError(f"unknown exhaustive option(s) {unknown}; known: {OPTIONS}")
        return solve_exhaustive(mesh, P, L, eta, start=start, **options)
    opts = _walk_options(**options) if method == "walk" else newton_options(mesh.dtype, **options)
    feats = resolve_features(features, mesh)
    if feats is not None and feats != GENERAL and not (method == "newton" and opts.n_starts > 1):
        # (Newton's extra random starts are drawn per lane position: compaction would move them.)
        return _solve_specialised(mesh, P, L, eta, method, start, opts, feats)
    n = P.shape[0]
    start = start if start is not None else start_points(mesh, P, L)
    P, L, start = _pad_lanes(P, L, start)
    if method == "walk":
        face, ab0, found = start
        tol = opts.tol if opts.tol is not None else default_tol(mesh.dtype)
        static = opts._replace(tol=None, max_steps=0)  # traced: one compile for any value
        sol = _walk_batch(bucketed(mesh), P, L, face, ab0, found, eta, tol,
                          jnp.int32(opts.max_steps), static)
    else:
        sol = solve_newton(mesh, P, L, eta, start, opts)
    return jax.tree.map(lambda x: x[:n], sol)


# --------------------------------------------------------------------------- specialised path
# (`features`, DESIGN.md "Skipping what a scene does not need"; docs/features.md)


def compact_index(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gather indices for the lanes `idx`, padded to `lane_bucket(len(idx))` with copies of
    `idx[0]` (one compile per size class), and the mask of the real ones."""
    k = idx.size
    g = np.concatenate([idx, np.full(lane_bucket(k) - k, idx[0], idx.dtype)])
    return g, np.arange(g.size) < k


def scatter_lanes(base, g: np.ndarray, keep: np.ndarray, sub):
    """`base` with lanes `g[keep]` replaced by the matching lanes of `sub` (pytrees)."""
    n = jax.tree.leaves(base)[0].shape[0]
    target = jnp.asarray(np.where(keep, g, n))  # n is out of bounds: dropped
    return jax.tree.map(lambda b, s: b.at[target].set(s.astype(b.dtype), mode="drop"), base, sub)


def _no_crossing(n: int, dtype) -> Solution:
    """What every solver returns for a lane without a start point (walk `_first_triangle`,
    Newton `_newton_lane`): `NO_CROSSING`, zeros, triangle -1, no iterations."""
    return Solution(
        point=jnp.zeros((n, 3), dtype), triangle=jnp.full(n, -1, jnp.int32),
        barycentric=jnp.zeros((n, 2), dtype), found=jnp.zeros(n, bool),
        status=jnp.full(n, Status.NO_CROSSING, jnp.int32), iterations=jnp.zeros(n, jnp.int32),
        residual=jnp.zeros(n, dtype), crossed=jnp.zeros(n, jnp.int32),
        start_point=jnp.zeros((n, 3), dtype),
    )


def _compacted_start_points(mesh: SurfaceMesh, P, L):
    """`start_points` for the lanes whose segment's bounding box meets the mesh's; the rest
    (receiver and light both above the water, or both beside the pool) cannot cross."""
    n = P.shape[0]
    V = np.asarray(mesh.vertices, np.float64)
    lo, hi = V.min(0), V.max(0)
    pad = 1e-4 * float(np.max(hi - lo) + np.max(np.abs(V)) + 1)  # conservative: rounding never drops a crossing
    P_np, L_np = np.asarray(P, np.float64), np.asarray(L, np.float64)
    meets = np.all((np.maximum(P_np, L_np) >= lo - pad) & (np.minimum(P_np, L_np) <= hi + pad), -1)
    base = (jnp.full(n, -1, jnp.int32), jnp.zeros((n, 2), mesh.dtype), jnp.zeros(n, bool))
    idx = np.flatnonzero(meets)
    if idx.size == 0:
        return base
    if idx.size == n:  # nothing to skip: no gather, no scatter
        return tuple(start_points(mesh, P, L))
    g, real = compact_index(idx)
    sub = start_points(mesh, P[g], L[g])
    return scatter_lanes(base, g, real, (sub.face, sub.barycentric, sub.found))


def _solve_specialised(mesh, P, L, eta, method, start, opts, feats: SceneFeatures) -> Solution:
    """`solve` for `features`: closed form where the scene allows it, the solver on the
    compacted remaining lanes, results scattered back (docs/features.md)."""
    from .flat import flat_root, flat_solution

    n, dtype = P.shape[0], mesh.dtype
    if start is None:
        start = _compacted_start_points(mesh, P, L) if feats.compact_lanes else start_points(mesh, P, L)
    face, ab0, found = (jnp.asarray(x) for x in start)
    found_np = np.asarray(found)
    tol = opts.tol if opts.tol is not None else default_tol(dtype)
    sol = _no_crossing(n, dtype)
    need = found_np.copy() if feats.compact_lanes else np.ones(n, bool)
    if feats.flat and method == "walk" and found_np.any():
        g, real = compact_index(np.flatnonzero(found_np))
        P_g, L_g = P[g], L[g]
        _, below, above, usable = flat_root(mesh, P_g, L_g, eta)
        located = start_points(mesh, below, above)
        flat_sol, good = flat_solution(mesh, P_g, L_g, eta, tol, usable, tuple(located), face[g], ab0[g])
        keep = real & np.asarray(good)
        sol = scatter_lanes(sol, g, keep, flat_sol)
        need[g[keep]] = False
    if not need.any():
        return sol

    def run(P, L, face, ab0, found):
        if method == "walk":
            static = opts._replace(tol=None, max_steps=0)
            return _walk_batch(bucketed(mesh), P, L, face, ab0, found, eta, tol,
                               jnp.int32(opts.max_steps), static)
        return solve_newton(mesh, P, L, eta, (face, ab0, found), opts)

    if need.all():  # nothing to skip: the general batch as is
        P, L, start = _pad_lanes(P, L, (face, ab0, found))
        return jax.tree.map(lambda x: x[:n], run(P, L, *start))
    g, real = compact_index(np.flatnonzero(need))
    return scatter_lanes(sol, g, real, run(P[g], L[g], face[g], ab0[g], found[g] & jnp.asarray(real)))
