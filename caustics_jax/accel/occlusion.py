"""Occlusion by the surface itself: does a segment cross the water between its ends?

Seed 001 §4 traces a ray from `M` to `L` (and from `P` to `M`) to drop paths the surface
blocks (steep waves, grazing light). `segment_blocked` answers that for many segments
with the start points' acceleration structure (`prepare(mesh).accel`: grid cells, binned
faces or BVH) and the same rounding-aware segment-triangle test (`crossing.py`).

A segment that starts or ends on the surface (at a refraction point `M`) touches it there;
that touch is not a blocker. Crossings are ignored

- on `exclude_face` (per segment; the face `M` lies on, -1 for none);
- within `end_tolerance` of either end, as a fraction of the segment (`s < end_tolerance`
  or `s > 1 - end_tolerance`), and within the rounding bound of `s` of either end
  (`crossing.Crossing.s_tol`): a point on a shared edge or vertex is within rounding of
  every face around it, so its neighbours' crossings at `s = 0` are ignored as well.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool

from ..runtime.precision import check_mesh_dtype
from ..surface.mesh import SurfaceMesh
from .prepared import PreparedSurface, prepare
from .start_points import Accel, first_hit


def segment_blocked(surface: SurfaceMesh | PreparedSurface, A, B, *, exclude_face=None,
                    end_tolerance: float = 0.0, accel: Accel | None = None) -> Bool[Array, " n"]:  # fmt: skip
    """`(N,)` True where the open segment `A -> B` crosses the surface (module docstring).

    Args:
        surface: a `SurfaceMesh` or `PreparedSurface` (its cached acceleration structure is
            used, on `prepare(surface).local`: a far mesh is tested near the origin; `accel`
            overrides it, e.g. for a mesh traced inside jit, and then the segments are
            tested where they lie).
        A, B: `(N, 3)` (or broadcastable) segment ends, the surface's float dtype. Traced
            arrays are accepted (inside a user's `jit`; their values are then not checked).
        exclude_face: `None` or `(N,)` int face indices whose crossings never block (-1:
            none), e.g. the face of the refraction point `M` at one end.
        end_tolerance: fraction of the segment at each end where crossings are ignored,
            in `[0, 0.5)`, on top of the rounding bound.

    Returns a bool array: False for zero-length segments.
    Raises `ValueError` for shapes, dtypes, non-finite values, an out-of-range
    `end_tolerance` or `exclude_face`.
    """
    prep = surface if isinstance(surface, PreparedSurface) else None
    mesh = surface.mesh if prep is not None else surface
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"surface must be a SurfaceMesh or PreparedSurface, got {type(surface).__name__}")
    A, B = _check_points(mesh, A, B)
    n = A.shape[0]
    exclude = _check_exclude(exclude_face, n, mesh.faces.shape[0])
    if not (isinstance(end_tolerance, (int, float)) and 0 <= end_tolerance < 0.5):
        raise ValueError(f"end_tolerance must be a number in [0, 0.5), got {end_tolerance!r}")
    if accel is None:  # the prepared surface's own structure, in the frame of its `local`
        prep = (prep if prep is not None else prepare(mesh))
        if np.any(prep.origin):  # exact for points near the mesh
            shift = jnp.asarray(prep.origin, mesh.dtype)
            A, B = A - shift, B - shift
        prep = prep.local
        mesh, accel = prep.mesh, prep.accel
    if n == 0:
        return jnp.zeros(0, bool)
    face, _, _ = first_hit(mesh, accel, A, B, exclude, s_lo=end_tolerance, s_hi=1 - end_tolerance, widen=False)
    return face >= 0


def _check_points(mesh: SurfaceMesh, A, B):
    check_mesh_dtype(mesh.dtype, "surface")
    A, B = jnp.asarray(A), jnp.asarray(B)
    for name, x in (("A", A), ("B", B)):
        if x.shape[-1:] != (3,) or x.ndim > 2:
            raise ValueError(f"{name} must have shape (N, 3) or (3,), got {x.shape}")
        if not jnp.issubdtype(x.dtype, jnp.floating) or x.dtype != mesh.dtype:
            raise ValueError(f"{name} is {x.dtype} but the surface is {mesh.dtype}: pass {mesh.dtype} points")
        if not isinstance(x, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(x))):
            raise ValueError(f"{name} has NaN or Inf coordinates")
    try:
        shape = jnp.broadcast_shapes(A.shape, B.shape)
    except ValueError:
        raise ValueError(f"A {A.shape} and B {B.shape} do not broadcast together") from None
    shape = (1, 3) if len(shape) == 1 else shape
    return jnp.broadcast_to(A, shape), jnp.broadcast_to(B, shape)


def _check_exclude(exclude_face, n: int, n_faces: int):
    if exclude_face is None:
        return None
    e = jnp.asarray(exclude_face)
    if not jnp.issubdtype(e.dtype, jnp.integer) or e.shape not in ((), (n,)):
        raise ValueError(f"exclude_face must be None or ({n},) integer face indices, got {e.dtype} {e.shape}")
    if not isinstance(e, jax.core.Tracer) and np.any((np.asarray(e) < -1) | (np.asarray(e) >= n_faces)):
        raise ValueError(f"exclude_face must be in [-1, {n_faces}) (-1: none)")
    return jnp.broadcast_to(e.astype(jnp.int32), (n,))


__all__ = ["segment_blocked"]
