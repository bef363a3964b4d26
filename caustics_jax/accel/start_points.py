"""Start points of the walks: the first crossing of segment `P -> L` with the surface.

Seed 001 §3.4.2: `M0 = (PL) ∩ surface` satisfies the coplanarity constraint trivially
(`PM0 x LM0 = 0`), so every walk starts there. "First" means the crossing nearest to `P`
(smallest segment parameter `s` in `M = P + s (L - P)`): a wavy surface can be crossed
more than once.

One segment-triangle kernel (`crossing.triangle_crossing`, Möller-Trumbore with a
rounding-aware tolerance) and three acceleration structures (`build_accel` picks):

- **grid** (`face_cells.FaceCells`, kind "grid"): a regular heightfield grid, from
  `mesh.grid` (either sign of the spacing) or recognised from the arrays by
  `grid.detect_grid` (any vertex order, axis orientation, face order and diagonals); a 2D
  DDA over its cells, two faces per cell, O(cells crossed inside the wave slab).
- **cells** (`face_cells.bin_faces`, kind "bins"): any other mesh, its faces binned into
  a uniform grid over the plane of its two largest extents; the same DDA, `K` faces per
  cell (the longest list).
- **general** (`bvh.FaceBVH`): a bounding-volume hierarchy, for meshes whose bins would
  be too long (a fan around one point) and as the reference the others are tested against.

`docs/mesh.md` has the complexity, the rounding argument (why a crossing on a cell wall,
an edge or a vertex is found from either side, whatever the batch) and the measured speeds.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..math.crossing import segment_triangle
from ..runtime.lanes import lane_bucket
from ..runtime.precision import check_mesh_dtype, real_input_dtype
from ..surface.frames import on_exact_cells
from ..surface.grid import detect_grid, grid_layout
from ..surface.mesh import SurfaceMesh
from .bvh import FaceBVH, build_bvh, first_hit_bvh
from .face_cells import FaceCells, bin_faces, cells_from_layout, first_hit_cells

#: An acceleration structure of the surface queries (`build_accel`).
Accel = FaceCells | FaceBVH

METHODS = ("auto", "grid", "cells", "general")


class StartPoint(NamedTuple):
    """First crossing of `P -> L` with the surface (unpacks as `face, barycentric, found`).

    Attributes:
        face: `(*batch,)` int32 face index, -1 where not found.
        barycentric: `(*batch, 2)` `(a, b)` inside the face (0 where not found).
        found: `(*batch,)` bool, False where the segment does not cross the surface.
    """

    face: Int[Array, "*batch"]
    barycentric: Float[Array, "*batch 2"]
    found: Bool[Array, "*batch"]


def grid_cells(mesh: SurfaceMesh) -> FaceCells | None:
    """The exact cells of `mesh` when it is a regular heightfield grid: from `mesh.grid`
    (static, so this works on a traced mesh; on concrete arrays only where the vertices
    lie on its cells, `frames.on_exact_cells`), else recognised by `grid.detect_grid` from
    the concrete arrays; None otherwise."""
    check_mesh_dtype(mesh.dtype)
    if mesh.grid is not None and (isinstance(mesh.vertices, jax.core.Tracer) or on_exact_cells(mesh)):
        return cells_from_layout(grid_layout(mesh.grid), mesh.dtype)  # (a traced mesh's grid is trusted)
    _require_concrete(mesh, "recognising a grid")
    layout = detect_grid(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    return None if layout is None else cells_from_layout(layout, mesh.dtype)


def build_accel(mesh: SurfaceMesh) -> Accel:
    """The fastest start-point structure for `mesh` (numpy, outside jit; build it once per
    mesh: `prepare(mesh)` caches it): exact grid cells, else binned faces, else a BVH."""
    cells = grid_cells(mesh)
    if cells is None:
        cells = bin_faces(mesh)
    return cells if cells is not None else build_bvh(mesh)


def start_points(mesh: SurfaceMesh, P, L, *, method: str = "auto", bvh: FaceBVH | None = None,
                 accel: Accel | None = None) -> StartPoint:  # fmt: skip
    """First crossing `M0` of segment `P -> L` with the surface (seed 001 §3.4.2).

    `P`, `L`: `(*batch, 3)` (broadcast together), the mesh's float dtype. `method`:
    `"auto"` (`accel` when given, else the grid cells of a regular grid, else `bvh` when
    given, else `build_accel(mesh)`), `"grid"` (a regular heightfield grid's cells; a
    `ValueError` for other meshes), `"cells"` (faces binned over the plane, any mesh) or
    `"general"` (the BVH, `bvh` or built here). Pass `accel` (or `bvh`) to reuse a
    structure across calls, and when the mesh is traced. Inputs are validated here, outside
    jit; the work runs in a jitted core. `M0 = barycentric_point(V, barycentric)`.
    """
    P, L = check_segments(mesh, P, L)
    structure = _structure(mesh, method, bvh, accel)
    batch = P.shape[:-1]
    face, ab, found = first_crossing(mesh, P.reshape(-1, 3), L.reshape(-1, 3), accel=structure)
    return StartPoint(face.reshape(batch), ab.reshape(*batch, 2), found.reshape(batch))


def first_crossing(mesh: SurfaceMesh, P, L, *, bvh: FaceBVH | None = None, accel: Accel | None = None):
    """The jitted core of `start_points` without its validation, for callers that already
    hold validated (or traced) `(n, 3)` arrays. The structure is `accel`, else the grid
    cells of `mesh.grid`, else `bvh`, else `build_accel(mesh)`. Returns `(face, ab, found)`."""
    if accel is None:
        accel = _structure(mesh, "auto", bvh, None)
    face, ab, _ = first_hit(mesh, accel, P, L, widen=True)
    return face, ab, face >= 0


def first_hit(mesh: SurfaceMesh, accel: Accel, A, B, exclude=None, *, s_lo: float = 0.0, s_hi: float = 1.0,
              widen: bool):  # fmt: skip
    """First crossing of `A + s (B - A)` with the surface for `s` in `[s_lo, s_hi]`, not on
    face `exclude` (`(n,)`, -1: none; None: no exclusion), with the structure `accel`:
    `face_cells.first_hit_cells` or `bvh.first_hit_bvh` (same arguments; returns
    `(face, ab, s)`, face -1 and `ab = 0` where there is none). Lanes are padded to their
    size class (`lanes.lane_bucket`), so jit compiles once per class."""
    check_mesh_dtype(mesh.dtype)
    if isinstance(accel, FaceCells):
        core = first_hit_cells
    elif isinstance(accel, FaceBVH):
        core = first_hit_bvh
    else:
        raise ValueError(f"accel must be a FaceCells or FaceBVH (build_accel(mesh)), got {type(accel).__name__}")
    n = A.shape[0]
    if n == 0:
        return jnp.zeros(0, jnp.int32), jnp.zeros((0, 2), A.dtype), jnp.zeros(0, A.dtype)
    extra = lane_bucket(n) - n
    if extra:  # zero-length padding segments cross nothing
        A, B = (jnp.pad(x, ((0, extra), (0, 0))) for x in (A, B))
        exclude = None if exclude is None else jnp.pad(exclude, (0, extra), constant_values=-1)
    face, ab, s = core(mesh, accel, A, B, exclude, s_lo=s_lo, s_hi=s_hi, widen=widen)
    return (face[:n], ab[:n], s[:n]) if extra else (face, ab, s)


def _structure(mesh: SurfaceMesh, method: str, bvh: FaceBVH | None, accel: Accel | None) -> Accel:
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if method == "auto":
        if accel is not None:
            return accel
        cells = grid_cells(mesh) if mesh.grid is not None else None
        if cells is not None:
            return cells
        if bvh is not None:
            return bvh
        _require_concrete(mesh, "building an acceleration structure")
        return build_accel(mesh)
    if method == "grid":
        if isinstance(accel, FaceCells) and accel.kind == "grid":
            return accel
        cells = grid_cells(mesh)
        if cells is None:
            raise ValueError("method='grid' needs a regular heightfield grid mesh (mesh.grid, or "
                             "arrays that grid.detect_grid recognises)")
        return cells
    if method == "cells":
        if isinstance(accel, FaceCells) and accel.kind == "bins":
            return accel
        _require_concrete(mesh, "binning faces")
        cells = bin_faces(mesh)
        if cells is None:
            raise ValueError("method='cells': some cell would list more faces than "
                             "face_cells.MAX_CELL_FACES (use method='general')")
        return cells
    if isinstance(accel, FaceBVH):
        return accel
    if bvh is None:
        _require_concrete(mesh, "building the BVH")
        bvh = build_bvh(mesh)
    return bvh


def _require_concrete(mesh: SurfaceMesh, what: str) -> None:
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise ValueError(f"{what} needs a concrete mesh: inside jit, pass accel=build_accel(mesh) "
                         "(or bvh=) built outside")


def check_segments(mesh: SurfaceMesh, P, L, names: tuple[str, str] = ("P", "L")):
    """`P`, `L` for `start_points` on `mesh`: real arrays of shape `(..., 3)` broadcast
    together, floats only in the mesh's dtype and finite (concrete arrays), cast and
    broadcast; a `ValueError` naming the problem otherwise (docs/input_contract.md), with the
    arguments called `names` (another function's segment ends, e.g. `M`)."""
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh, got {type(mesh).__name__}")
    check_mesh_dtype(mesh.dtype)
    a, b = names
    for name, x in ((a, P), (b, L)):
        real_input_dtype(name, x)  # bool, complex, strings: ValueError (docs/input_contract.md)
        if np.ndim(x) == 0:
            raise ValueError(f"{a} and {b} must have shape (..., 3), got {name} = {x!r}")
    P, L = jnp.asarray(P), jnp.asarray(L)
    if P.shape[-1:] != (3,) or L.shape[-1:] != (3,):
        raise ValueError(f"{a} and {b} must have shape (..., 3), got {P.shape} and {L.shape}")
    try:
        shape = jnp.broadcast_shapes(P.shape, L.shape)
    except ValueError:
        raise ValueError(f"{a} {P.shape} and {b} {L.shape} do not broadcast together") from None
    for name, x in ((a, P), (b, L)):
        if not jnp.issubdtype(x.dtype, jnp.floating):
            continue
        if x.dtype != mesh.dtype:
            raise ValueError(
                f"{name} is {x.dtype} but the mesh is {mesh.dtype}: cast one "
                "(mesh.astype(dtype)); start_points never mixes precisions silently"
            )
        if not isinstance(x, jax.core.Tracer):
            bad = np.flatnonzero(~np.all(np.isfinite(np.asarray(x).reshape(-1, 3)), axis=-1))
            if bad.size:
                raise ValueError(f"{name} has NaN or Inf at (flattened) rows {bad[:10].tolist()}")
    P = jnp.broadcast_to(P.astype(mesh.dtype), shape)
    L = jnp.broadcast_to(L.astype(mesh.dtype), shape)
    return P, L


__all__ = ["Accel", "FaceBVH", "FaceCells", "StartPoint", "build_accel", "build_bvh", "check_segments",
           "first_crossing", "first_hit", "grid_cells", "segment_triangle", "start_points"]
