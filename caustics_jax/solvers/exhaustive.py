"""Exhaustive reference: every refraction point on the mesh, by scanning every conic arc.

For each lane (P, L) and each face:

1. Cull (exactly): a face holds part of the coplanarity curve iff its conic crosses an
   edge, or is an ellipse whose centre lies inside the face with the opposite sign of
   `Q` at a vertex (seed 001 Fig. 5a).
2. Every arc inside a face starts at an edge root; from each root, oriented inward, the
   arc runs to the next crossing along the curve (`walk._next_crossing`). The arc is
   sampled at `samples` pencil angles through its start (`phi` in `(0, phi_exit)`,
   which covers exactly that arc); an ellipse inside the face is sampled over the whole
   pencil `(0, pi)` through a point of it.
3. Every interval where `f` changes sign in both orientations (a root, not an
   orientation flip; `walk._root_between`) is refined by bisection in `phi`.
4. Roots are deduplicated per lane (each arc is seen from both ends, and roots on shared
   edges from both faces).

Float64 only; cost `O(N F)` for the cull plus `O(N sqrt(F) samples)` for the scan on a
heightfield, so it is meant for meshes up to ~20k triangles. Exhaustive up to the
sampling: two roots closer than one sample interval of the same arc are missed (the
count is a lower bound; the tests check it against planted paths).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..barycentric import barycentric_point
from ..conic import conic_coefficients, conic_value, solve_quadratic
from ..start_points import start_points
from ._solution import Solution, Status
from .walk import (
    _INWARD,
    _edge_roots,
    _f,
    _next_crossing,
    _orientation,
    _pencil_point,
    _root_between,
)

ROOTS_PER_ARC = 2
N_ARCS = 7  # up to 6 edge roots as arc starts, plus one ellipse inside the face


class ExhaustiveSolution(NamedTuple):
    """All solutions per lane, plus the one nearest `M0` as a `Solution`.

    Attributes:
        solution: `Solution` with the solution nearest the start point `M0` per lane.
        all_points: `(N, max_count, 3)` every solution found (zero padded).
        all_triangles: `(N, max_count)` their faces (-1 padded).
        count: `(N,)` number of distinct solutions.
    """

    solution: Solution
    all_points: np.ndarray
    all_triangles: np.ndarray
    count: np.ndarray


def _touches(coef, V):
    """Does the conic pass through the face? Edge crossings, or an ellipse inside."""
    _, valid, _ = _edge_roots(coef)
    A, B, C, D, E, F = coef
    det = 4 * A * B - C * C
    ellipse = det > 0
    safe = jnp.where(ellipse, det, 1)
    a_c = (C * E - 2 * B * D) / safe
    b_c = (C * D - 2 * A * E) / safe
    inside = (a_c >= 0) & (b_c >= 0) & (a_c + b_c <= 1)
    centre = jnp.stack([a_c, b_c])
    opposite = conic_value(coef, centre) * F < 0  # F = Q at vertex V0
    return jnp.any(valid) | (ellipse & inside & opposite)


@jax.jit
def _cull(mesh, P, L):
    """`(n, F)` mask of faces whose conic meets them, for lanes `P, L` `(n, 3)`."""
    V, N = mesh.vertices[mesh.faces], mesh.normals[mesh.faces]

    def lane(p, l):
        coef = conic_coefficients(V, N, p[None], l[None])
        return jax.vmap(_touches)(coef, V) & (mesh.neighbors[:, 0] >= -1)

    return jax.vmap(lane)(P, L)


def _refine(coef, V, N, P, L, eta, anchor, tau, perp, lo, hi, f_lo, iters):
    def body(_, c):
        lo, hi, f_lo = c
        mid = (lo + hi) / 2
        p, _ = _pencil_point(coef, anchor, tau, perp, mid)
        fm = _f(V, N, P, L, p[None], eta)[0][0]
        left = jnp.sign(fm) * jnp.sign(f_lo) < 0
        return jnp.where(left, lo, mid), jnp.where(left, mid, hi), jnp.where(left, f_lo, fm)

    lo, hi, _ = jax.lax.fori_loop(0, iters, body, (lo, hi, f_lo))
    return _pencil_point(coef, anchor, tau, perp, (lo + hi) / 2)[0]


def _scan_face(mesh, P, L, face, eta, samples, iters):
    """Roots on every arc of one face: `(N_ARCS * ROOTS_PER_ARC, 2)` ab and validity."""
    V, N = mesh.triangle(face)
    coef = conic_coefficients(V, N, P, L)
    roots = _edge_roots(coef)
    t_all, valid_all, ab_all = roots
    starts, taus, perps, phi_ends, ok_arcs = [], [], [], [], []
    for k in range(3):
        for j in range(2):
            x = ab_all[k, j]
            t = jnp.stack([-(coef[2] / 2 * x[0] + coef[1] * x[1] + coef[4] / 2),
                           coef[0] * x[0] + coef[2] / 2 * x[1] + coef[3] / 2])
            inward = jnp.asarray(_INWARD[k], t.dtype)
            side = t @ inward
            tau, perp = _orientation(coef, x, jnp.where(side < 0, -t, t))
            ok, _, _, _, phi = _next_crossing(roots, x, tau, perp, k, t_all[k, j])
            starts.append(x)
            taus.append(tau)
            perps.append(perp)
            phi_ends.append(jnp.where(ok, phi, 0))
            ok_arcs.append(valid_all[k, j] & ok & (side != 0))
    # Ellipse inside the face (no edge root): anchor where the line b = 1/3 meets it.
    A, B, C, D, E, F = coef
    s, s_ok = solve_quadratic(A, C / 3 + D, B / 9 + E / 3 + F)
    anchor = jnp.stack([s[0], jnp.asarray(1 / 3, s.dtype)])
    t = jnp.stack([-(C / 2 * anchor[0] + B * anchor[1] + E / 2), A * anchor[0] + C / 2 * anchor[1] + D / 2])
    tau, perp = _orientation(coef, anchor, t)
    starts.append(anchor)
    taus.append(tau)
    perps.append(perp)
    phi_ends.append(jnp.asarray(jnp.pi, s.dtype) * (1 - 1e-9))
    ok_arcs.append(~jnp.any(valid_all) & s_ok[0])

    starts, taus, perps = jnp.stack(starts), jnp.stack(taus), jnp.stack(perps)
    phi_ends, ok_arcs = jnp.stack(phi_ends), jnp.stack(ok_arcs)
    frac = jnp.linspace(0, 1, samples + 1)[1:].astype(coef.dtype)
    phis = phi_ends[:, None] * frac[None]  # (arcs, samples)
    phis = phis.at[:, 0].set(phi_ends * 1e-9)  # just off the arc start

    def arc_points(x, tau, perp, ph):
        return jax.vmap(lambda p: _pencil_point(coef, x, tau, perp, p))(ph)

    pts, pts_ok = jax.vmap(arc_points)(starts, taus, perps, phis)  # (arcs, samples, 2)
    f, st, g = _f(V, N, P, L, pts.reshape(-1, 2), eta)
    f, st, g = (x.reshape(N_ARCS, samples) for x in (f, st, g))
    good = pts_ok & (st == 0)
    change = _root_between((f[:, :-1], g[:, :-1]), (f[:, 1:], g[:, 1:])) & good[:, :-1] & good[:, 1:]
    # the first ROOTS_PER_ARC sign changes of each arc
    order = jnp.argsort(~change, axis=1, stable=True)[:, :ROOTS_PER_ARC]
    has = jnp.take_along_axis(change, order, axis=1) & ok_arcs[:, None]

    def refine(arc, i):
        return _refine(coef, V, N, P, L, eta, starts[arc], taus[arc], perps[arc],
                       phis[arc, i], phis[arc, i + 1], f[arc, i], iters)

    arcs = jnp.repeat(jnp.arange(N_ARCS), ROOTS_PER_ARC)
    ab = jax.vmap(refine)(arcs, order.reshape(-1))
    return ab, has.reshape(-1)


@functools.partial(jax.jit, static_argnames=("samples", "iters"))
def _scan_pairs(mesh, P, L, faces, eta, samples, iters):
    ab, ok = jax.vmap(lambda p, l, f: _scan_face(mesh, p, l, f, eta, samples, iters))(P, L, faces)
    V, N = mesh.triangle(faces)
    fa, st, _ = jax.vmap(lambda v, n, p, l, a: _f(v, n, p, l, a, eta))(V, N, P, L, ab)
    M = barycentric_point(V[:, None], ab)
    return M, ab, ok, fa, st


def solve_exhaustive(mesh, P, L, eta, *, start=None, samples: int = 32, iters: int = 60,
                     tol: float = 1e-9, chunk: int = 4096, dedupe: float = 1e-7,
                     return_all: bool = False):
    """`solve(..., method="exhaustive")`: all solutions (float64); see the module docstring.

    Returns a `Solution` (the solution nearest `M0`), or with `return_all=True` an
    `ExhaustiveSolution` that also holds every solution per lane.
    """
    if mesh.dtype != jnp.float64:
        raise ValueError("method='exhaustive' is the float64 reference: pass a float64 mesh")
    if samples < 2 or iters < 1:
        raise ValueError("samples must be >= 2 and iters >= 1")
    from ._solve import _bucket, bucketed

    face0, ab0, found0 = start if start is not None else start_points(mesh, P, L)
    mesh_b = bucketed(mesh)
    n = P.shape[0]
    n_faces = mesh.faces.shape[0]
    lanes, faces = [], []
    step = max(1, chunk * 64 // max(n_faces, 1))
    for i in range(0, n, step):
        mask = np.asarray(_cull(mesh, P[i:i + step], L[i:i + step]))
        li, fi = np.nonzero(mask)
        lanes.append(li + i)
        faces.append(fi)
    lanes = np.concatenate(lanes).astype(np.int32)
    faces = np.concatenate(faces).astype(np.int32)
    pts, tris, res, abs_ = [], [], [], []
    for i in range(0, len(lanes), chunk):
        li, fi = lanes[i:i + chunk], faces[i:i + chunk]
        pad = _bucket(len(li), 64) - len(li)
        lp = np.concatenate([li, np.full(pad, li[0] if len(li) else 0, np.int32)])
        fp = np.concatenate([fi, np.full(pad, fi[0] if len(fi) else 0, np.int32)])
        M, ab, ok, fa, st = _scan_pairs(mesh_b, P[lp], L[lp], jnp.asarray(fp), eta, samples, iters)
        ok = np.asarray(ok)[:len(li)] & (np.abs(np.asarray(fa))[:len(li)] <= tol) & (np.asarray(st)[:len(li)] == 0)
        M = np.asarray(M)[:len(li)]
        pts.append(M[ok])
        abs_.append(np.asarray(ab)[:len(li)][ok])
        tris.append(np.repeat(fi[:, None], ok.shape[1], 1)[ok])
        res.append(np.repeat(li[:, None], ok.shape[1], 1)[ok])
    pts = np.concatenate(pts) if pts else np.zeros((0, 3))
    tris = np.concatenate(tris) if tris else np.zeros(0, np.int32)
    owner = np.concatenate(res) if res else np.zeros(0, np.int32)
    abs_ = np.concatenate(abs_) if abs_ else np.zeros((0, 2))

    # Deduplicate per lane (each arc from both ends; shared edges from both faces).
    per_lane_pts = [[] for _ in range(n)]
    per_lane_tri = [[] for _ in range(n)]
    per_lane_ab = [[] for _ in range(n)]
    order = np.lexsort((pts[:, 0], owner)) if len(pts) else np.zeros(0, int)
    for k in order:
        lane = owner[k]
        if all(np.linalg.norm(pts[k] - q) > dedupe for q in per_lane_pts[lane]):
            per_lane_pts[lane].append(pts[k])
            per_lane_tri[lane].append(tris[k])
            per_lane_ab[lane].append(abs_[k])
    count = np.array([len(x) for x in per_lane_pts], np.int32)
    width = max(1, int(count.max()) if n else 1)
    all_points = np.zeros((n, width, 3))
    all_tris = np.full((n, width), -1, np.int32)
    all_ab = np.zeros((n, width, 2))
    for i in range(n):
        if count[i]:
            all_points[i, :count[i]] = np.stack(per_lane_pts[i])
            all_tris[i, :count[i]] = per_lane_tri[i]
            all_ab[i, :count[i]] = np.stack(per_lane_ab[i])

    V0, _ = mesh.triangle(face0)
    M0 = np.asarray(barycentric_point(V0, ab0))
    found0 = np.asarray(found0)
    dist = np.where(np.arange(width)[None] < count[:, None],
                    np.linalg.norm(all_points - M0[:, None], axis=-1), np.inf)
    best = np.argmin(dist, axis=1)
    has = count > 0
    point = all_points[np.arange(n), best]
    tri = np.where(has, all_tris[np.arange(n), best], -1)
    ab = all_ab[np.arange(n), best]
    resid = np.asarray(_f_points(mesh, jnp.asarray(np.maximum(tri, 0)), jnp.asarray(ab), P, L, eta))
    status = np.where(~found0, Status.NO_CROSSING, np.where(has, Status.FOUND, Status.NOT_CONVERGED))
    sol = Solution(
        point=jnp.asarray(np.where(has[:, None], point, 0)),
        triangle=jnp.asarray(tri.astype(np.int32)),
        barycentric=jnp.asarray(np.where(has[:, None], ab, 0)),
        found=jnp.asarray(has),
        status=jnp.asarray(status.astype(np.int32)),
        iterations=jnp.zeros(n, jnp.int32),
        residual=jnp.asarray(np.where(has, resid, 0)),
        crossed=jnp.zeros(n, jnp.int32),
        start_point=jnp.asarray(np.where(found0[:, None], M0, 0)),
    )
    if return_all:
        return ExhaustiveSolution(sol, all_points, all_tris, count)
    return sol


@jax.jit
def _f_points(mesh, faces, ab, P, L, eta):
    V, N = mesh.triangle(faces)
    return jax.vmap(lambda v, n, p, l, a: _f(v, n, p, l, a[None], eta)[0][0])(V, N, P, L, ab)
