"""Exhaustive reference: every refraction point on the mesh, certified (math.md §5).

For each lane (P, L):

1. **Cull (conservative).** Descend a tree of face patches with bounding balls and
   normal cones (`cones.candidate_faces`, after Walter et al. 2009 §4): a patch where the
   interpolated normal can never be parallel to the half vector `w_L + eta w_P` holds no
   refraction point and is skipped with all its faces. `cull=False` keeps every face
   (the tests check both give the same solutions).
2. **Arcs.** Every arc of the coplanarity conic inside a surviving face
   (`arcs.face_arcs`: from each edge root, oriented inward, to the next crossing along
   the curve; plus an ellipse inside the face, anchored on the line through its centre),
   each cut into two pieces (`arc_roots.face_pieces`); an arc on one line of a conic that
   is a line pair is the segment (`arc_roots.chord_on_conic`).
3. **Certified isolation.** On each piece the refraction condition becomes a polynomial
   `G` of degree 12 in the Bernstein basis (`arc_roots.arc_polynomial`) whose roots
   contain every solution; Bernstein subdivision with rounding bounds isolates every
   root (`arc_roots.isolate_roots`): a piece or sub-interval is dropped only when the
   signs of its coefficients prove it has no root.
4. **Refine and accept.** Bisection on the sign of Snell's scalar in each interval that
   holds a root (`iters` steps; `arc_roots.refine_root`); a candidate is a solution when
   `|f| <= tol` and the refracted ray points towards `L` (`objectives.bracket_objective`
   status OK). Solutions are deduplicated per lane (a root on a shared edge is found
   from both faces).

What is guaranteed (docs/solvers.md "The certified reference"): every refraction point
of the piecewise-conic curve, up to the float64 rounding of the conic and of `G`'s
coefficients (bounded explicitly), is among the candidates; none is lost to sampling,
to orientation flips of `f` or to total internal reflection nearby (roots of `G` never lie
under TIR: there `|n x w_L| = eta |n x w_P|` cannot hold). Float64 only.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..accel.cones import candidate_faces
from ..accel.prepared import padded_mesh
from ..accel.start_points import start_points
from ..curve.arc_roots import PIECES, ArcPiece, face_pieces
from ..curve.arcs import N_ARCS, conic_touches_face
from ..math.conic import conic_coefficients
from ..math.objectives import ObjectiveStatus
from ..runtime.arguments import check_bool, check_int, check_real, check_tol
from .options import SolverOptions, option
from .solution_set import (
    NO_ROOTS,
    ExhaustiveSolution,
    assemble,
    padded_call,
    piece_polynomials,
    refine_intervals,
)

__all__ = ["Exhaustive", "ExhaustiveSolution", "candidate_pairs", "candidate_roots", "solve_exhaustive"]

#: Arc pieces per face (`arc_roots.face_pieces`).
N_PIECES = N_ARCS * PIECES


class Exhaustive(SolverOptions):
    """The certified all-solutions reference (float64) and its options.

    iters: bisection steps per isolated root, in `[1, 200]`.
    max_depth: Bernstein halvings before an undecided interval (roots closer than
        `2^-max_depth` of an arc piece) becomes one candidate, in `[8, 60]`.
    tol: acceptance `|f| <= tol`, in `(0, 1)`.
    chunk: (lane, face) pairs per jitted batch, in `[1, 2^20]`.
    dedupe: two roots closer than this (m) are one solution, `>= 0`.
    cull: skip patches of faces that provably hold no solution (`cones.py`).
    return_all: return an `ExhaustiveSolution` with every solution per lane.
    """

    method: ClassVar[str] = "exhaustive"

    iters: int = option(60, lambda v: check_int("iters", v, 1, 200))
    max_depth: int = option(48, lambda v: check_int("max_depth", v, 8, 60))
    tol: float = option(1e-9, lambda v: check_tol("tol", v, optional=False))
    chunk: int = option(4096, lambda v: check_int("chunk", v, 1, 2**20))
    dedupe: float = option(1e-7, lambda v: check_real("dedupe", v, 0.0))
    cull: bool = option(True, lambda v: check_bool("cull", v))
    return_all: bool = option(False, lambda v: check_bool("return_all", v))

    in_blocks: ClassVar[bool] = False

    def every_path(self) -> bool:
        return self.return_all

    def check_dtype(self, dtype) -> None:
        if jnp.dtype(dtype) != jnp.float64:
            raise ValueError("method='exhaustive' is the float64 reference: pass a float64 mesh")

    def solve_whole(self, prep, P, L, eta, start):
        return solve_exhaustive(prep.mesh, P, L, eta, start, self, padded=prep.padded)


# --------------------------------------------------------------------------- kernels


@jax.jit
def _cull(mesh, P, L):
    """`(n, F)` mask of faces whose conic meets them (`cull=False`: every face is scanned)."""
    V, N = mesh.vertices[mesh.faces], mesh.normals[mesh.faces]

    def lane(p, l):
        coef = conic_coefficients(V, N, p[None], l[None])
        return jax.vmap(conic_touches_face)(coef) & (mesh.neighbors[:, 0] >= -1)

    return jax.vmap(lane)(P, L)


@jax.jit
def _scan_pairs(mesh, P, L, faces):
    """The `N_PIECES` arc pieces of each (lane, face) pair (`arc_roots.face_pieces`)."""
    def one(p, l, f):
        V, N = mesh.triangle(f)
        return face_pieces(conic_coefficients(V, N, p, l))

    return jax.vmap(one)(P, L, faces)


# --------------------------------------------------------------------------- host driver


def candidate_pairs(mesh, mesh_b, P, L, eta, cull: bool, chunk: int):
    """`(lane, face)` pairs to scan: the cone culling's, or (`cull=False`) every face whose
    conic meets it (on the padded mesh, whose padding faces never do)."""
    if cull:
        return candidate_faces(mesh, P, L, eta)
    n, n_faces = P.shape[0], mesh_b.faces.shape[0]
    lanes, faces = [], []
    step = max(1, chunk * 64 // max(n_faces, 1))
    for i in range(0, n, step):
        li, fi = np.nonzero(np.asarray(_cull(mesh_b, P[i:i + step], L[i:i + step])))
        lanes.append(li + i)
        faces.append(fi)
    return np.concatenate(lanes).astype(np.int32), np.concatenate(faces).astype(np.int32)


def candidate_roots(mesh_b, P, L, eta, lanes, faces, options: Exhaustive):
    """Every refraction candidate on the arcs of faces `faces` for lanes `lanes` (pairs):
    `(pair, M, ab, f, status)` numpy arrays, `pair` indexing `lanes` (status OK only for a
    forward ray)."""
    if len(lanes) == 0:
        return NO_ROOTS
    fields = padded_call(lambda s: tuple(_scan_pairs(mesh_b, P[lanes[s]], L[lanes[s]], jnp.asarray(faces[s]))),
                         len(lanes), options.chunk)
    pieces = ArcPiece(*fields)
    pair, piece = np.nonzero(pieces.ok)
    pieces = ArcPiece(*(x[pair, piece] for x in pieces))
    G, delta = padded_call(lambda s: piece_polynomials(mesh_b, P[lanes[pair[s]]], L[lanes[pair[s]]],
                                                       jnp.asarray(faces[pair[s]]),
                                                       ArcPiece(*(jnp.asarray(x[s]) for x in pieces)), eta),
                           len(pair), options.chunk)
    row, M, ab, f, st = refine_intervals(mesh_b, P, L, eta, lanes[pair], faces[pair], pieces, G, delta, options)
    return pair[row], M, ab, f, st


def solve_exhaustive(mesh, P, L, eta, start, options: Exhaustive, padded=None):
    """`solve(..., method="exhaustive")`: every solution (float64); see the module docstring.

    Returns a `Solution` (the solution nearest `M0`, or nearest the line `PL` where the
    segment misses the surface), or with `return_all=True` an `ExhaustiveSolution` that
    also holds every solution per lane. Status: `FOUND` where a solution exists (even
    without a start point: the scan does not need one), else `NO_SOLUTION`, or
    `NO_CROSSING` where there is neither a solution nor a start point.
    """
    options.check_dtype(mesh.dtype)
    start = start if start is not None else start_points(mesh, P, L)
    mesh_b = padded if padded is not None else padded_mesh(mesh)
    lanes, faces = candidate_pairs(mesh, mesh_b, P, L, eta, options.cull, options.chunk)
    pair, M, ab, f, st = candidate_roots(mesh_b, P, L, eta, lanes, faces, options)
    ok = (np.abs(f) <= options.tol) & (st == ObjectiveStatus.OK)
    result = assemble(mesh, P, L, eta, start, options.tol, options.dedupe,
                      lanes[pair[ok]], M[ok], faces[pair[ok]], ab[ok], f[ok])
    return result if options.return_all else result.solution
