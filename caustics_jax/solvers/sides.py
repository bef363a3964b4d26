"""Warnings for setup mistakes that leave every lane failing without an error: a receiver
and light on the wrong sides of the surface, or on the same side of it.

math.md §1: the normals point outward, toward the light; `P` is inside the medium (behind
the normals) and `L` outside. A path `P -> M -> L` then crosses the surface along its
normal: `(L - P) . n_g > 0` at the start point `M0`, `n_g` the crossed face's geometric
normal. When the mesh is wound the other way (normals down with the light above), or `P`
and `L` are swapped, the segment crosses against the normal, refraction from the wrong
side is total internal reflection or leads off the mesh, and every such lane ends
`TOTAL_INTERNAL_REFLECTION` or `LEFT_MESH` without an error. `warn_if_wrong_sides` says
so, with the fix.

When (nearly) every lane's segment `P-L` misses the surface, every lane ends
`NO_CROSSING`; `warn_if_no_crossing` names the likely cause when the lanes show one: the
light below the surface (on the receivers' side), or the receivers above it.

Both cost nothing when the solve went well: only when most lanes failed do they look at
why (start points of at most `SAMPLE` failed lanes; heights of the points).
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
#: `warn_if_no_crossing`: the fraction of NO_CROSSING lanes from which a cause is looked for.
NO_CROSSING_FRACTION = 0.99


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
            "(math.md §1). Swap P and L, or, if the mesh is wound clockwise (normals away from the light), "
            "reverse the face winding, e.g. SurfaceMesh.from_arrays(vertices, faces[:, ::-1])",
        )


def _heights(prep: PreparedSurface, X: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Heights of points `X` along the surface's mean normal (its "up": towards the light),
    and the surface's own height range along it."""
    mesh = prep.mesh
    up = np.sum(np.asarray(mesh.face_normals, np.float64), axis=0)
    up = up / max(float(np.linalg.norm(up)), 1e-300)
    h = np.asarray(mesh.vertices, np.float64) @ up
    return np.asarray(X, np.float64) @ up, float(h.min()), float(h.max())


def no_crossing_cause(prep: PreparedSurface, P, L, crosses) -> str | None:
    """Why (nearly) every lane misses the surface, when the lanes show it: most lights
    below the surface's lowest point, or most receivers above its highest point (heights
    along its mean normal); None when fewer than `NO_CROSSING_FRACTION` of the lanes miss
    it, or no such cause shows."""
    crosses = np.asarray(crosses, bool)
    n = crosses.size
    if n == 0 or np.mean(~crosses) < NO_CROSSING_FRACTION:
        return None
    miss = ~crosses
    hL, lo, hi = _heights(prep, np.broadcast_to(np.asarray(L), (n, 3))[miss])
    hP, _, _ = _heights(prep, np.broadcast_to(np.asarray(P), (n, 3))[miss])
    count = f"{int(miss.sum())} of the {n} lanes cross no surface (NO_CROSSING)"
    if np.mean(hL < lo) > FRACTION:
        return (f"{count}: the light is below the surface (L lies {np.median(lo - hL):.4g} below its lowest "
                "point, along its mean normal). L must lie outside the medium, on the side the normals point "
                "to, and the receivers P inside it (math.md §1); a Directional's direction is the way its "
                "rays travel (the sun overhead is (0, 0, -1))")
    if np.mean(hP > hi) > FRACTION:
        return (f"{count}: the receivers are above the surface (P lies {np.median(hP - hi):.4g} above its "
                "highest point, along its mean normal). The receivers P must lie inside the medium, behind the "
                "normals, and the light L outside it (math.md §1)")
    return None


def warn_if_no_crossing(prep: PreparedSurface, P, L, crosses) -> None:
    """`UserWarning` naming the likely cause when (nearly) every lane misses the surface
    (`no_crossing_cause`); silent otherwise. `crosses`: `(N,)` lanes whose segment meets it."""
    cause = no_crossing_cause(prep, P, L, crosses)
    if cause is not None:
        warn_user(cause)
