"""Exhaustive reference: every refraction point on the mesh, by scanning every conic arc.

For each lane (P, L) and each face:

1. Cull (exactly): a face holds part of the coplanarity curve iff its conic crosses an
   edge, or is an ellipse whose centre lies inside the face with the opposite sign of
   `Q` at a vertex (seed 001 Fig. 5a).
2. Every arc inside a face starts at an edge root; from each root, oriented inward, the
   arc runs to the next crossing along the curve (`arcs.face_arcs`). The arc is
   sampled at `samples` pencil angles through its start (`phi` in `(0, phi_exit)`,
   which covers exactly that arc); an ellipse inside the face is sampled over the whole
   pencil `(0, pi)` through a point of it.
3. Every interval where `f` changes sign in both orientations (a root, not an
   orientation flip; `arcs.root_between`) is refined by bisection in `phi`. An interval
   from a transmitting sample to a totally reflecting one is first cut at the onset of
   total internal reflection (bisection on the status), and a sign change between the
   sample and the onset is refined the same way: near-critical roots have no sample on
   their far side.
4. Roots are deduplicated per lane (each arc is seen from both ends, and roots on shared
   edges from both faces).

Float64 only; cost `O(N F)` for the cull plus `O(N sqrt(F) samples)` for the scan on a
heightfield, so it is meant for meshes up to ~20k triangles. Exhaustive up to the
sampling: two roots closer than one sample interval of the same arc are missed (the
count is a lower bound; the tests check it against planted paths).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..arcs import N_ARCS, conic_touches_face, face_arcs, root_between
from ..barycentric import barycentric_point
from ..conic import conic_coefficients
from ..lanes import padded_index, padded_mesh, power_of_two_bucket
from ..objectives import ObjectiveStatus, bracket_objective, path_vectors, refracted_direction
from ..start_points import start_points
from ._solution import Solution, Status
from .options import SolverOptions, check_bool, check_int, check_real, check_tol

ROOTS_PER_ARC = 2


@dataclasses.dataclass(frozen=True)
class Exhaustive(SolverOptions):
    """The exhaustive all-solutions reference (float64) and its options.

    samples: pencil samples per arc, in `[2, 4096]`.
    iters: bisection steps per bracket, in `[1, 200]`.
    tol: acceptance `|f| <= tol`, in `(0, 1)`.
    chunk: (lane, face) pairs per jitted batch, in `[1, 2^20]`.
    dedupe: two roots closer than this (m) are one solution, `>= 0`.
    return_all: return an `ExhaustiveSolution` with every solution per lane.
    """

    method: ClassVar[str] = "exhaustive"

    samples: int = 32
    iters: int = 60
    tol: float = 1e-9
    chunk: int = 4096
    dedupe: float = 1e-7
    return_all: bool = False

    def _validate(self):
        object.__setattr__(self, "samples", check_int("samples", self.samples, 2, 4096))
        object.__setattr__(self, "iters", check_int("iters", self.iters, 1, 200))
        object.__setattr__(self, "tol", check_tol("tol", self.tol, optional=False))
        object.__setattr__(self, "chunk", check_int("chunk", self.chunk, 1, 2**20))
        object.__setattr__(self, "dedupe", check_real("dedupe", self.dedupe, 0.0))
        object.__setattr__(self, "return_all", check_bool("return_all", self.return_all))


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


@jax.jit
def _cull(mesh, P, L):
    """`(n, F)` mask of faces whose conic meets them, for lanes `P, L` `(n, 3)`."""
    V, N = mesh.vertices[mesh.faces], mesh.normals[mesh.faces]

    def lane(p, l):
        coef = conic_coefficients(V, N, p[None], l[None])
        return jax.vmap(conic_touches_face)(coef) & (mesh.neighbors[:, 0] >= -1)

    return jax.vmap(lane)(P, L)


def _refine(point, V, N, P, L, eta, lo, hi, f_lo, iters):
    """Bisection in the arc parameter `u` of a bracket `[lo, hi]` (a sign change of `f`)."""
    def body(_, c):
        lo, hi, f_lo = c
        mid = (lo + hi) / 2
        fm = bracket_objective(V, N, P, L, point(mid)[None], eta)[0][0]
        left = jnp.sign(fm) * jnp.sign(f_lo) < 0
        return jnp.where(left, lo, mid), jnp.where(left, mid, hi), jnp.where(left, f_lo, fm)

    lo, hi, _ = jax.lax.fori_loop(0, iters, body, (lo, hi, f_lo))
    return point((lo + hi) / 2)


def _arcs(mesh, P, L, face):
    """`(V, N, FaceArcs)` of one face for one lane."""
    V, N = mesh.triangle(face)
    return V, N, face_arcs(conic_coefficients(V, N, P, L))


def _sample_u(samples, dtype):
    u = jnp.linspace(0, 1, samples + 1)[1:].astype(dtype)
    # Just off the arc start, and just past its end: a root exactly on an edge or at a
    # vertex (the arc's end) is then bracketed by a sign change; at u = 1 alone f is
    # rounding noise of either sign, and the next face's arc starts just past it.
    # Roots past the end are rejected in `_refine_brackets` (clamped to the face).
    return u.at[0].set(1e-9).at[-1].set(1 + 1e-6)


def _brackets(mesh, P, L, face, eta, samples):
    """Phase 1 for one (lane, face): sample every arc; up to ROOTS_PER_ARC sign changes of
    `f` per arc (kind 0) and ROOTS_PER_ARC transmit/TIR transitions (kind 1), as
    `(valid, arc, sample index)`, each `(2 N_ARCS ROOTS_PER_ARC,)`."""
    V, N, arcs = _arcs(mesh, P, L, face)
    u = _sample_u(samples, arcs.coef.dtype)
    ids = jnp.arange(N_ARCS)
    pts, pts_ok = jax.vmap(lambda a: jax.vmap(lambda x: arcs.point(a, x))(u))(ids)
    f, st, g = bracket_objective(V, N, P, L, pts.reshape(-1, 2), eta)
    f, st, g = (x.reshape(N_ARCS, samples) for x in (f, st, g))
    good = pts_ok & (st == ObjectiveStatus.OK)
    tir = pts_ok & (st == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION)
    change = root_between((f[:, :-1], g[:, :-1]), (f[:, 1:], g[:, 1:])) & good[:, :-1] & good[:, 1:]
    onset = (good[:, :-1] & tir[:, 1:]) | (tir[:, :-1] & good[:, 1:])
    out = []
    for mask in (change, onset):
        order = jnp.argsort(~mask, axis=1, stable=True)[:, :ROOTS_PER_ARC]
        has = jnp.take_along_axis(mask, order, axis=1) & arcs.ok[:, None]
        out.append((has.reshape(-1), jnp.repeat(ids, ROOTS_PER_ARC), order.reshape(-1)))
    return tuple(jnp.concatenate([a, b]) for a, b in zip(*out, strict=True))


def _refine_slot(mesh, P, L, face, eta, arc, i, kind, samples, iters):
    """Phase 2 for one bracket: the root on `[u_i, u_{i+1}]` of arc `arc`.

    Kind 1 (one end totally reflecting): a root between the last transmitting sample and
    the onset of total internal reflection has no sample on its far side, so find the
    onset first (bisection on the status), then look for a sign change up to it.
    """
    V, N, arcs = _arcs(mesh, P, L, face)
    u = _sample_u(samples, arcs.coef.dtype)
    u_lo, u_hi = u[i], u[i + 1]
    f2, st2, g2 = bracket_objective(V, N, P, L, jnp.stack([arcs.point(arc, u_lo)[0],
                                                      arcs.point(arc, u_hi)[0]]), eta)
    lo_ok = st2[0] == ObjectiveStatus.OK
    u_ok, u_far = jnp.where(lo_ok, u_lo, u_hi), jnp.where(lo_ok, u_hi, u_lo)
    f_ok, g_ok = jnp.where(lo_ok, f2[0], f2[1]), jnp.where(lo_ok, g2[0], g2[1])

    def body(_, c):
        a, b = c  # a transmits, b reflects totally
        m = (a + b) / 2
        stm = bracket_objective(V, N, P, L, arcs.point(arc, m)[0][None], eta)[1][0]
        is_tir = stm == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION
        return jnp.where(is_tir, a, m), jnp.where(is_tir, m, b)

    onset = kind == 1
    u_b, _ = jax.lax.fori_loop(0, jnp.where(onset, iters, 0), body, (u_ok, u_far))
    f_b, st_b, g_b = (x[0] for x in bracket_objective(V, N, P, L, arcs.point(arc, u_b)[0][None], eta))
    bracket = ~onset | (root_between((f_ok, g_ok), (f_b, g_b)) & (st_b == ObjectiveStatus.OK))
    ab = _refine(lambda x: arcs.point(arc, x)[0], V, N, P, L, eta, u_ok,
                 jnp.where(onset, u_b, u_far), f_ok, iters)
    return ab, bracket


@functools.partial(jax.jit, static_argnames=("samples",))
def _scan_brackets(mesh, P, L, faces, eta, samples):
    return jax.vmap(lambda p, l, f: _brackets(mesh, p, l, f, eta, samples))(P, L, faces)


@functools.partial(jax.jit, static_argnames=("samples", "iters"))
def _refine_brackets(mesh, P, L, faces, arc, i, kind, eta, samples, iters):
    ab, ok = jax.vmap(lambda p, l, f, a, j, k: _refine_slot(mesh, p, l, f, eta, a, j, k, samples, iters))(
        P, L, faces, arc, i, kind)
    # Into the closed face (a root refined just past an arc's end is judged where it
    # belongs: on the edge, or rejected below when f there exceeds tol).
    a = jnp.clip(ab[:, 0], 0, 1)
    ab = jnp.stack([a, jnp.clip(ab[:, 1], 0, 1 - a)], -1)
    V, N = mesh.triangle(faces)
    fa, st, _ = jax.vmap(lambda v, n, p, l, x: bracket_objective(v, n, p, l, x[None], eta))(V, N, P, L, ab)
    # f is a sine: it also vanishes where the refracted ray points straight away from L
    # (an angle error of pi). Only a forward ray is a solution.
    _, _, _, w_L, _ = path_vectors(V, N, P, L, ab)
    r = refracted_direction(V, N, P, L, ab, eta)
    forward = jnp.sum(r * w_L, axis=-1) > 0
    return barycentric_point(V, ab), ab, ok & forward, fa[:, 0], st[:, 0]


def solve_exhaustive(mesh, P, L, eta, start, options: Exhaustive, padded=None):
    """`solve(..., method="exhaustive")`: all solutions (float64); see the module docstring.

    Returns a `Solution` (the solution nearest `M0`, or nearest the line `PL` where the
    segment misses the surface), or with `return_all=True` an `ExhaustiveSolution` that
    also holds every solution per lane. Status: `FOUND` where a solution exists (even
    without a start point: the scan does not need one), else `NO_SOLUTION`, or
    `NO_CROSSING` where there is neither a solution nor a start point.
    """
    if mesh.dtype != jnp.float64:
        raise ValueError("method='exhaustive' is the float64 reference: pass a float64 mesh")
    samples, iters, tol, chunk = options.samples, options.iters, options.tol, options.chunk
    face0, ab0, found0 = start if start is not None else start_points(mesh, P, L)
    mesh_b = padded if padded is not None else padded_mesh(mesh)
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
    # Phase 1: brackets of every (lane, face) pair; phase 2: refine only the brackets.
    slot_pair, slot_arc, slot_i, slot_kind = [], [], [], []
    for i in range(0, len(lanes), chunk):
        li, fi = lanes[i:i + chunk], faces[i:i + chunk]
        sel = padded_index(np.arange(len(li)), power_of_two_bucket(len(li), 64))
        valid, arc, j = (np.asarray(x)[:len(li)] for x in _scan_brackets(
            mesh_b, P[li[sel]], L[li[sel]], jnp.asarray(fi[sel]), eta, samples))
        pair, slot = np.nonzero(valid)
        slot_pair.append(pair + i)
        slot_arc.append(arc[pair, slot])
        slot_i.append(j[pair, slot])
        slot_kind.append((slot >= N_ARCS * ROOTS_PER_ARC).astype(np.int32))
    slot_pair, slot_arc, slot_i, slot_kind = (
        np.concatenate(x).astype(np.int32) if x else np.zeros(0, np.int32)
        for x in (slot_pair, slot_arc, slot_i, slot_kind))
    pts, tris, res, abs_ = [], [], [], []
    for i in range(0, len(slot_pair), chunk):
        sl = np.arange(i, min(i + chunk, len(slot_pair)))
        sel = padded_index(sl, power_of_two_bucket(len(sl), 64))
        pair = slot_pair[sel]
        M, ab, ok, fa, st = (np.asarray(x)[:len(sl)] for x in _refine_brackets(
            mesh_b, P[lanes[pair]], L[lanes[pair]], jnp.asarray(faces[pair]),
            jnp.asarray(slot_arc[sel]), jnp.asarray(slot_i[sel]), jnp.asarray(slot_kind[sel]),
            eta, samples, iters))
        ok = ok & (np.abs(fa) <= tol) & (st == ObjectiveStatus.OK)
        pts.append(M[ok])
        abs_.append(ab[ok])
        tris.append(faces[pair[:len(sl)]][ok])
        res.append(lanes[pair[:len(sl)]][ok])
    pts = np.concatenate(pts) if pts else np.zeros((0, 3))
    tris = np.concatenate(tris) if tris else np.zeros(0, np.int32)
    owner = np.concatenate(res) if res else np.zeros(0, np.int32)
    abs_ = np.concatenate(abs_) if abs_ else np.zeros((0, 2))
    # M0 may be a solution where the conic is singular and has no arc through it (P, L
    # and the normal aligned at a vertex, or on a flat surface where the conic vanishes):
    # test it directly, as the walk does.
    f0, st0 = (np.asarray(x) for x in _f_status_points(mesh, jnp.asarray(np.maximum(np.asarray(face0), 0)),
                                                        jnp.asarray(ab0), P, L, eta))
    at_m0 = np.nonzero(np.asarray(found0) & (np.abs(f0) <= tol) & (st0 == ObjectiveStatus.OK))[0]
    V0, _ = mesh.triangle(face0)
    M0 = np.asarray(barycentric_point(V0, ab0))
    pts = np.concatenate([pts, M0[at_m0]])
    tris = np.concatenate([tris, np.asarray(face0)[at_m0]]).astype(np.int32)
    owner = np.concatenate([owner, at_m0]).astype(np.int32)
    abs_ = np.concatenate([abs_, np.asarray(ab0)[at_m0]])

    # Deduplicate per lane (each arc from both ends; shared edges from both faces).
    per_lane_pts = [[] for _ in range(n)]
    per_lane_tri = [[] for _ in range(n)]
    per_lane_ab = [[] for _ in range(n)]
    order = np.lexsort((pts[:, 0], owner)) if len(pts) else np.zeros(0, int)
    for k in order:
        lane = owner[k]
        if all(np.linalg.norm(pts[k] - q) > options.dedupe for q in per_lane_pts[lane]):
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

    found0 = np.asarray(found0)
    # The solution nearest M0; without M0 (segment P -> L misses the surface, yet a path
    # may exist), the one nearest the line PL.
    Pn, Ln = np.asarray(P, np.float64), np.asarray(L, np.float64)
    u = (Ln - Pn) / np.linalg.norm(Ln - Pn, axis=-1, keepdims=True)
    rel = all_points - Pn[:, None]
    to_line = np.linalg.norm(rel - np.sum(rel * u[:, None], -1, keepdims=True) * u[:, None], axis=-1)
    to_m0 = np.linalg.norm(all_points - M0[:, None], axis=-1)
    dist = np.where(np.arange(width)[None] < count[:, None],
                    np.where(found0[:, None], to_m0, to_line), np.inf)
    best = np.argmin(dist, axis=1)
    has = count > 0
    point = all_points[np.arange(n), best]
    tri = np.where(has, all_tris[np.arange(n), best], -1)
    ab = all_ab[np.arange(n), best]
    resid = np.asarray(_f_points(mesh, jnp.asarray(np.maximum(tri, 0)), jnp.asarray(ab), P, L, eta))
    status = np.where(has, Status.FOUND, np.where(found0, Status.NO_SOLUTION, Status.NO_CROSSING))
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
    if options.return_all:
        return ExhaustiveSolution(sol, all_points, all_tris, count)
    return sol


@jax.jit
def _f_status_points(mesh, faces, ab, P, L, eta):
    """`f` and the walk's status (OK = 0 only for a forward refracted ray) at `(face, ab)`."""
    V, N = mesh.triangle(faces)
    f, st, _ = jax.vmap(lambda v, n, p, l, a: bracket_objective(v, n, p, l, a[None], eta))(V, N, P, L, ab)
    return f[:, 0], st[:, 0]


@jax.jit
def _f_points(mesh, faces, ab, P, L, eta):
    V, N = mesh.triangle(faces)
    return jax.vmap(lambda v, n, p, l, a: bracket_objective(v, n, p, l, a[None], eta)[0][0])(V, N, P, L, ab)
