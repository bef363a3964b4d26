"""The set of every solution per lane, shared by the all-solutions solvers (the certified
exhaustive reference, `exhaustive.py`, and the curve tracer, `trace.py`): refine the roots
isolated on arc pieces (`arc_roots`), accept them (`|f| <= tol`, forward ray), add `M0`
where it is itself a solution, deduplicate per lane, pad, and pick the one nearest `M0`.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..curve.arc_roots import ArcPiece, arc_polynomial, isolate_roots, refine_root
from ..math.barycentric import barycentric_point
from ..math.conic import conic_coefficients
from ..math.objectives import ObjectiveStatus, bracket_objective
from ..runtime.lanes import padded_index
from ._solution import Solution, Status


class ExhaustiveSolution(NamedTuple):
    """All solutions per lane, plus the one nearest `M0` as a `Solution`.

    Attributes:
        solution: `Solution` with the solution nearest the start point `M0` per lane.
        all_points: `(N, max_count, 3)` every solution found (zero padded).
        all_triangles: `(N, max_count)` their faces (-1 padded).
        count: `(N,)` number of distinct solutions.
        all_barycentric: `(N, max_count, 2)` their barycentrics `(a, b)` (zero padded; last,
            so that the four-field construction of earlier versions still works).
    """

    solution: Solution
    all_points: np.ndarray
    all_triangles: np.ndarray
    count: np.ndarray
    all_barycentric: np.ndarray | None = None

    @classmethod
    def empty(cls, solution: Solution) -> ExhaustiveSolution:
        """No solution on any lane of `solution` (width 1, padded)."""
        n = solution.point.shape[0]
        return cls(solution, np.zeros((n, 1, 3)), np.full((n, 1), -1, np.int32), np.zeros(n, np.int32),
                   np.zeros((n, 1, 2)))


def translated(result: Solution | ExhaustiveSolution, offset: np.ndarray, has_start) -> Solution | ExhaustiveSolution:
    """`result` with its points moved by `offset` (`(3,)` float64; `solve` runs on
    `prepared.local` and moves back by its `origin`): each point added in float64 and
    rounded once to its dtype. Lanes without a point keep zeros: `point` where `triangle`
    is -1, `start_point` where `has_start` (`(N,)`) is False, `all_points` where
    `all_triangles` is -1. The same `result` where `offset` is zero."""
    if not np.any(offset):
        return result

    def moved(X, keep):
        X_np = np.asarray(X)
        out = np.where(np.asarray(keep)[..., None], X_np.astype(np.float64) + offset, X_np)
        return out.astype(X_np.dtype)

    def solution(sol: Solution) -> Solution:
        return dataclasses.replace(sol, point=jnp.asarray(moved(sol.point, np.asarray(sol.triangle) >= 0)),
                                   start_point=jnp.asarray(moved(sol.start_point, has_start)))

    if isinstance(result, ExhaustiveSolution):
        return result._replace(solution=solution(result.solution),
                               all_points=moved(result.all_points, np.asarray(result.all_triangles) >= 0))
    return solution(result)


@functools.partial(jax.jit, static_argnames=("iters",))
def _refine(mesh, P, L, faces, pieces, x0, x1, eta, iters):
    """Refine one interval per row of `pieces` (an `ArcPiece` of arrays); returns
    `(M, ab, f, status)` (status OK only for a forward ray)."""
    def one(p, l, f, pc, a, b):
        V, N = mesh.triangle(f)
        coef = conic_coefficients(V, N, p, l)
        ab = refine_root(V, N, p, l, coef, pc, eta, a, b, iters)
        # Into the closed face (a root at an arc's end sits on the edge up to rounding).
        ab = jnp.stack([jnp.clip(ab[0], 0, 1), jnp.clip(ab[1], 0, 1 - jnp.clip(ab[0], 0, 1))])
        fa, st, _ = bracket_objective(V, N, p, l, ab[None], eta)
        return barycentric_point(V, ab), ab, fa[0], st[0]

    return jax.vmap(one)(P, L, faces, pieces, x0, x1)


@jax.jit
def _f_status_points(mesh, faces, ab, P, L, eta):
    """`f` and status (OK = 0 only for a forward refracted ray) at `(face, ab)`."""
    V, N = mesh.triangle(faces)
    f, st, _ = jax.vmap(lambda v, n, p, l, a: bracket_objective(v, n, p, l, a[None], eta))(V, N, P, L, ab)
    return f[:, 0], st[:, 0]


@jax.jit
def piece_polynomials(mesh, P, L, faces, pieces, eta):
    """`(G, delta)` `(k, 13)` of arc pieces `pieces` (an `ArcPiece` of `(k, ...)` arrays) on
    faces `faces` for lanes `P`, `L` (`arc_roots.arc_polynomial`)."""
    def one(p, l, f, pc):
        V, N = mesh.triangle(f)
        G, delta, _ = arc_polynomial(V, N, p, l, conic_coefficients(V, N, p, l), pc, eta)
        return G, delta

    return jax.vmap(one)(P, L, faces, pieces)


def padded_call(fn, n: int, chunk: int):
    """Run `fn(sel)` over `range(n)` in chunks of `chunk` rows, each padded to 1024 rows or
    to `chunk` (two compiled sizes per kernel); numpy outputs cut to the real rows and
    concatenated per output (None for `n = 0`)."""
    outs = []
    for i in range(0, n, chunk):
        k = min(chunk, n - i)
        sel = padded_index(np.arange(i, i + k), min(chunk, 1024) if k <= 1024 else chunk)
        outs.append([np.asarray(x)[:k] for x in fn(sel)])
    return [np.concatenate(parts) for parts in zip(*outs, strict=True)] if outs else None


#: No candidate: `(row, M, ab, f, status)` of length 0.
NO_ROOTS = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int32))


def refine_intervals(mesh_b, P, L, eta, lanes, faces, pieces: ArcPiece, G, delta, options):
    """Isolate the roots of `G` `(k, 13)` on arc pieces `k` (lane `lanes[i]`, face
    `faces[i]`, piece `pieces[i]`) and refine them: `(row, M, ab, f, status)`, `row` the
    piece each candidate lies on. `options`: an object with `max_depth`, `iters`, `chunk`."""
    row, x0, x1, _ = isolate_roots(G, delta, options.max_depth)
    sub = ArcPiece(*(np.asarray(x)[row] for x in pieces))
    out = padded_call(
        lambda s: _refine(mesh_b, P[lanes[row[s]]], L[lanes[row[s]]], jnp.asarray(faces[row[s]]),
                          ArcPiece(*(jnp.asarray(x[s]) for x in sub)), jnp.asarray(x0[s]),
                          jnp.asarray(x1[s]), eta, options.iters),
        len(row), options.chunk)
    if out is None:
        return NO_ROOTS
    return (row, *out)


def dedupe_per_lane(owner, pts, resid, radius: float):
    """Indices of the candidates kept: per lane, a candidate closer than `radius` to an
    earlier one (ordered by `|f|`, best first) is dropped. Vectorised over lanes."""
    if len(owner) == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((np.abs(resid), owner))
    o, p = owner[order], pts[order]
    dup = np.zeros(len(o), bool)
    start = np.searchsorted(o, o, side="left")
    width = int(np.max(np.arange(len(o)) - start)) if len(o) else 0
    for k in range(1, width + 1):
        same = np.zeros(len(o), bool)
        same[k:] = o[k:] == o[:-k]
        close = np.zeros(len(o), bool)
        close[k:] = np.linalg.norm(p[k:] - p[:-k], axis=-1) <= radius
        dup |= same & close
    return order[~dup]


def gather_per_lane(n: int, owner, pts, tris, ab):
    """`(all_points, all_triangles, all_barycentric, count)` padded per lane."""
    count = np.bincount(owner, minlength=n).astype(np.int32)
    width = max(1, int(count.max()) if n else 1)
    order = np.argsort(owner, kind="stable")
    o = owner[order]
    rank = np.arange(len(o)) - np.searchsorted(o, o, side="left")
    all_points = np.zeros((n, width, 3))
    all_tris = np.full((n, width), -1, np.int32)
    all_ab = np.zeros((n, width, 2))
    all_points[o, rank] = pts[order]
    all_tris[o, rank] = tris[order]
    all_ab[o, rank] = ab[order]
    return all_points, all_tris, all_ab, count


def nearest_solution(mesh, P, L, eta, all_points, all_tris, all_ab, count, M0, found0) -> Solution:
    """The `Solution` holding each lane's solution nearest `M0` (nearest the line `PL` where
    the segment misses the surface)."""
    n, width = all_tris.shape
    Pn, Ln = np.asarray(P, np.float64), np.asarray(L, np.float64)
    u = (Ln - Pn) / np.linalg.norm(Ln - Pn, axis=-1, keepdims=True)
    rel = all_points - Pn[:, None]
    to_line = np.linalg.norm(rel - np.sum(rel * u[:, None], -1, keepdims=True) * u[:, None], axis=-1)
    to_m0 = np.linalg.norm(all_points - M0[:, None], axis=-1)
    dist = np.where(np.arange(width)[None] < count[:, None], np.where(found0[:, None], to_m0, to_line), np.inf)
    best = np.argmin(dist, axis=1)
    has = count > 0
    rows = np.arange(n)
    tri = np.where(has, all_tris[rows, best], -1)
    ab = np.where(has[:, None], all_ab[rows, best], 0)
    resid, _ = (np.asarray(x) for x in _f_status_points(mesh, jnp.asarray(np.maximum(tri, 0)), jnp.asarray(ab),
                                                        P, L, eta))
    status = np.where(has, Status.FOUND, np.where(found0, Status.NO_SOLUTION, Status.NO_CROSSING))
    dtype = mesh.dtype
    return Solution(
        point=jnp.asarray(np.where(has[:, None], all_points[rows, best], 0), dtype),
        triangle=jnp.asarray(tri.astype(np.int32)),
        barycentric=jnp.asarray(ab, dtype),
        found=jnp.asarray(has),
        status=jnp.asarray(status.astype(np.int32)),
        iterations=jnp.zeros(n, jnp.int32),
        residual=jnp.asarray(np.where(has, resid, 0), dtype),
        crossed=jnp.zeros(n, jnp.int32),
        start_point=jnp.asarray(np.where(found0[:, None], M0, 0), dtype),
    )


def start_point_roots(mesh, P, L, eta, start, tol: float):
    """`(lanes, M0, face, ab)` where `M0` itself is a solution: the conic may be singular
    there (P, L and the normal aligned, or a flat surface where the conic vanishes), with
    no arc through it; tested directly, as the walk does. Also returns every lane's `M0`."""
    face0, ab0, found0 = (np.asarray(x) for x in start)
    f0, st0 = (np.asarray(x) for x in _f_status_points(mesh, jnp.asarray(np.maximum(face0, 0)),
                                                        jnp.asarray(ab0), P, L, eta))
    at = np.nonzero(found0 & (np.abs(f0) <= tol) & (st0 == ObjectiveStatus.OK))[0]
    V0, _ = mesh.triangle(jnp.asarray(face0))
    M0 = np.asarray(barycentric_point(V0, jnp.asarray(ab0)))
    return at, M0, face0, ab0, found0


def assemble(mesh, P, L, eta, start, tol: float, dedupe: float, owner, pts, tris, ab, resid) -> ExhaustiveSolution:
    """The `ExhaustiveSolution` of accepted roots `(owner lane, point, face, ab, f)`: `M0`
    added where it is itself a solution, deduplicated within `dedupe` (m) per lane, padded,
    and the one nearest `M0` as `solution` (status `FOUND`, else `NO_SOLUTION`, or
    `NO_CROSSING` without a start point)."""
    n = P.shape[0]
    at, M0, face0, ab0, found0 = start_point_roots(mesh, P, L, eta, start, tol)
    owner = np.concatenate([owner, at]).astype(np.int64)
    pts = np.concatenate([pts, M0[at]])
    tris = np.concatenate([tris, face0[at]]).astype(np.int32)
    ab = np.concatenate([ab, ab0[at]])
    resid = np.concatenate([resid, np.zeros(len(at))])
    keep = dedupe_per_lane(owner, pts, resid, dedupe)
    all_points, all_tris, all_ab, count = gather_per_lane(n, owner[keep], pts[keep], tris[keep], ab[keep])
    sol = nearest_solution(mesh, P, L, eta, all_points, all_tris, all_ab, count, M0, found0)
    return ExhaustiveSolution(sol, all_points, all_tris, count, all_ab)
