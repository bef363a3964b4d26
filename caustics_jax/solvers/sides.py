"""A warning for lanes whose receiver and light sit on the wrong sides of the surface.

MATH.md §1: the normals point outward, toward the light; `P` is inside the medium (behind
the normals) and `L` outside. A path `P -> M -> L` then crosses the surface along its
normal: `(L - P) . n_g > 0` at the start point `M0`, `n_g` the crossed face's geometric
normal. When the mesh is wound the other way (normals down with the light above), or `P`
and `L` are swapped, the segment crosses against the normal, refraction from the wrong
side is total internal reflection or leads off the mesh, and every such lane ends
`TOTAL_INTERNAL_REFLECTION` or `LEFT_MESH` without an error. `warn_if_wrong_sides` says
so, with the fix.

It costs nothing when the solve went well: only when most lanes that cross the surface
failed does it look at why (start points of at most `SAMPLE` failed lanes).
"""

from __future__ import annotations

import numpy as np

from ..accel.prepared import PreparedSurface
from ..runtime.arguments import warn_user
from ._solution import Solution, Status

#: Failed lanes whose sides are checked (a sample: the diagnosis needs no more).
SAMPLE = 1024
#: Warn when more than this fraction of the lanes that cross the surface failed and more
#: than this fraction of the sampled failures cross against the normals.
FRACTION = 0.5


def wrong_side_fraction(prep: PreparedSurface, P, L, sol: Solution, sample: int = SAMPLE):
    """`(failed, wrong)`: the fraction of lanes with a start point that were not found, and
    the fraction of (at most `sample` of) those whose segment crosses the surface against
    its normal (`(L - P) . n_g < 0` at the start face). `(0, 0)` without such lanes."""
    status = np.asarray(sol.status)
    crossing = status != Status.NO_CROSSING
    failed_idx = np.flatnonzero(crossing & (status != Status.FOUND))
    if failed_idx.size == 0:
        return 0.0, 0.0
    failed = failed_idx.size / max(int(crossing.sum()), 1)
    pick = failed_idx[np.linspace(0, failed_idx.size - 1, min(sample, failed_idx.size)).astype(int)]
    P_s, L_s = np.asarray(P)[pick], np.asarray(L)[pick]
    face, _, found = (np.asarray(x) for x in prep.start_points(P_s, L_s))
    if not found.any():
        return failed, 0.0
    n_g = np.asarray(prep.mesh.face_normals, np.float64)[face[found]]
    along = np.sum((L_s[found] - P_s[found]).astype(np.float64) * n_g, axis=-1)
    return failed, float(np.mean(along < 0))


def warn_if_wrong_sides(prep: PreparedSurface, P, L, sol: Solution) -> None:
    """`UserWarning` when most lanes crossing the surface failed because `P` and `L` are on
    the wrong sides of it (module docstring); silent otherwise."""
    status = np.asarray(sol.status)
    crossing = int(np.sum(status != Status.NO_CROSSING))
    if crossing == 0 or np.sum(status == Status.FOUND) >= (1 - FRACTION) * crossing:
        return
    failed, wrong = wrong_side_fraction(prep, P, L, sol)
    if failed > FRACTION and wrong > FRACTION:
        warn_user(
            f"{100 * failed:.0f}% of the lanes crossing the surface failed, and {100 * wrong:.0f}% of those "
            "cross it against its normals: P must be inside the medium (behind the normals) and L outside "
            "(MATH.md §1). Swap P and L, or, if the mesh is wound clockwise (normals away from the light), "
            "reverse the face winding, e.g. SurfaceMesh.from_arrays(vertices, faces[:, ::-1])",
        )
