"""Where a mesh is solved: the local origin of a mesh far from the coordinate origin, and
whether its regular grid (`SurfaceMesh.grid`) still describes its vertices.

float32 keeps about 7 digits of a coordinate: a mesh solved where it lies, hundreds of
metres from the origin, loses the digits its triangles need, and most of its lanes end in
TIR, LEFT_MESH or NOT_CONVERGED from noise in `f`, not physics (docs/input_contract.md,
"Scale" and "Measurements behind the code"). `prepare(mesh)` therefore runs the solvers on
`local_mesh(mesh, local_origin(...))` and moves the points back (`prepared.py`).

The start points trust a grid's exact cells (`start_points.grid_cells`): a crossing near a
cell wall is found only if the vertices lie on the cells to rounding. `grid_state` says
how well they do; a grid that does not fit is not used (the faces are binned instead).
"""

from __future__ import annotations

import numpy as np

from .mesh import SurfaceMesh

#: A grid whose vertices lie farther than this fraction of its smaller spacing from their
#: grid positions, and farther than `STALE_ULPS` float32 spacings of the largest
#: coordinate, is "stale": the mesh's xy changed after the grid was built. Only the
#: warning depends on it (a grid off its vertices is never used): rounding kept from a
#: far position reaches 1.5-2.3% of a spacing (a float32 grid built at 1e4 m with 0.02 m
#: cells, moved to the origin), well below a quarter.
STALE_GRID = 0.25
#: Rounding a vertex's xy may carry from float32, the coarsest dtype it may have passed
#: through (a float32 grid 1e5 m away is 4e-3 m off its exact cells, 1.5% of a 0.26 m
#: spacing), in spacings of float32 at the largest coordinate.
STALE_ULPS = 8


def on_exact_cells(mesh: SurfaceMesh) -> bool:
    """Whether `mesh`'s vertices lie on its grid's exact cells (True without a grid), to
    the tolerance `grid.detect_grid` recognises a grid with: 4 ulps, in the mesh's dtype,
    of the largest xy coordinate plus the extent."""
    g = mesh.grid
    if g is None:
        return True
    xy = g.vertex_xy()
    scale = float(np.max(np.abs(xy)) + np.max(np.ptp(xy, axis=0)))
    return mesh.grid_deviation() <= 4 * float(np.finfo(mesh.dtype).eps) * scale


def grid_state(mesh: SurfaceMesh) -> str:
    """How well `mesh.grid` describes the vertices (concrete arrays):

    - `"none"`: no grid;
    - `"exact"`: on the exact cells (`on_exact_cells`); the start points use them;
    - `"rounded"`: off by the rounding of an earlier dtype or position (within
      `STALE_GRID` of a spacing or `STALE_ULPS` float32 spacings): a float32 grid cast with
      `astype("float64")`, or a float32 grid 300 m away moved near the origin (1.5e-5 m off
      the cells there); the exact cells lose a crossing within that of a cell wall
      (docs/input_contract.md, "Measurements behind the code"), so the start points bin
      the faces;
    - `"stale"`: farther: the xy changed after the grid was built (`eqx.tree_at` on
      `vertices`; on the grid's cells a moved pool finds no start point, silently
      NO_CROSSING). The faces are binned too, and `prepare` warns.
    """
    g = mesh.grid
    if g is None:
        return "none"
    if on_exact_cells(mesh):
        return "exact"
    rounding = STALE_ULPS * float(np.spacing(np.float32(np.max(np.abs(g.vertex_xy())))))
    return "rounded" if mesh.grid_deviation() <= max(STALE_GRID * min(abs(g.dx), abs(g.dy)), rounding) else "stale"


def local_origin(vertices, dtype) -> np.ndarray:
    """`(3,)` float64: where the solvers put the origin for a mesh with these vertices.

    Each axis whose bounding-box centre lies farther from zero than the box's largest side
    is moved to that centre; the others stay (zero for a mesh around the origin, so its
    solves are bit for bit what they were). The centre is snapped to a multiple of the
    axis's largest vertex coordinate's spacing in `dtype`, so `V - origin` is exact: the
    solvers see the same triangles, only nearer (module docstring).
    """
    V = np.asarray(vertices, np.float64)
    if V.size == 0:
        return np.zeros(3)
    lo, hi = V.min(0), V.max(0)
    centre, extent = (lo + hi) / 2, float(np.max(hi - lo))
    step = np.spacing(np.max(np.abs(V), 0).astype(dtype)).astype(np.float64)
    return np.where(np.abs(centre) > extent, np.round(centre / step) * step, 0.0)


def local_mesh(mesh: SurfaceMesh, origin: np.ndarray) -> SurfaceMesh:
    """`mesh` moved by `-origin` (`SurfaceMesh.translated`), without its grid where the
    moved vertices are not on the moved grid's exact cells (`on_exact_cells`: a far float32
    grid keeps its rounding, which is many ulps near the origin)."""
    local = mesh.translated(-origin) if np.any(origin) else mesh
    return local if on_exact_cells(local) else local.without_grid()
