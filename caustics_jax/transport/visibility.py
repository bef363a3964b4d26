"""Visibility of a refracted path through the surface itself (seed 001 §4, §6).

Seed 001 §4 traces one ray, from the refraction point `M` to the light `L`, to discard
paths in shadow; §6 notes that it misses a second crossing of the refractive surface
between `M` and `L` (light near the horizon, rough water). Testing `P -> M` as well is
this project's extension. Here the only occluder is the water surface: on steep waves,
or under grazing light, the segment `M -> L` can leave the water at `M` and cross a wave
crest before reaching the light, and `P -> M` can cross the surface from below before
`M`. Such a path satisfies Snell's law at `M` yet carries no light.

A path is visible when neither segment crosses the surface anywhere but at `M`: each is
tested with the start-point query (`start_points.first_crossing`, the first crossing of a
segment with the surface, on the prepared acceleration structure), the end at `M` pulled
back by a relative `eps` along the segment so that `M`'s own face (and its neighbours,
when `M` lies on an edge) is not reported (`eps = 1e-6` in float64, `1e-3` in float32:
far above the crossing test's rounding bound). A crest closer to `M` than `eps` times the
segment's length is not seen.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..accel.prepared import PreparedSurface, prepare
from ..accel.start_points import check_segments, first_crossing


def visibility_eps(dtype) -> float:
    """Relative pull-back of `M` along each segment (module docstring)."""
    return 1e-6 if jnp.dtype(dtype) == jnp.float64 else 1e-3


def path_visible(mesh, P, M, L) -> np.ndarray:
    """`(n,)` True where neither `P -> M` nor `M -> L` crosses the surface except at `M`.

    `M -> L` is seed 001 §4's shadow ray (against the surface, the §6 limitation); `P -> M`
    is this project's extension (module docstring).

    `P`, `M`, `L`: `(n, 3)` arrays (the mesh's dtype; a `ValueError` for another float
    dtype, a bad shape or a NaN, as `start_points` raises). One query of `2 n` segments.
    """
    prep: PreparedSurface = prepare(mesh)
    dtype = prep.dtype
    # Checked as start points are (shape, dtype, finite: one NaN row had looped forever).
    P, M = check_segments(prep.mesh, P, M, ("P", "M"))
    M, L = check_segments(prep.mesh, M, L, ("M", "L"))
    try:
        P, M, L = jnp.broadcast_arrays(P, M, L)
    except ValueError:
        raise ValueError(f"P {P.shape}, M {M.shape} and L {L.shape} do not broadcast together") from None
    # In the frame of `prep.local` (a far mesh moved near the origin, `frames.local_origin`):
    # float32 300 m away had judged 17 of 4000 segments otherwise than near the origin.
    P, M, L = (jnp.asarray(x, dtype).reshape(-1, 3) for x in (P, M, L))
    if np.any(prep.origin):
        shift = jnp.asarray(prep.origin, dtype)
        P, M, L = P - shift, M - shift, L - shift
    prep = prep.local
    n = P.shape[0]
    if n == 0:
        return np.zeros(0, bool)
    eps = visibility_eps(dtype)
    A = jnp.concatenate([P, M + eps * (L - M)])
    B = jnp.concatenate([M + eps * (P - M), L])
    _, _, hit = first_crossing(prep.mesh, A, B, bvh=prep.bvh)
    hit = np.asarray(hit)
    return ~(hit[:n] | hit[n:])
