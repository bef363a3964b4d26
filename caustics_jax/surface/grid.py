"""Regular heightfield grids recognised from a mesh's arrays, whatever their layout.

A surface `w = h(u, v)` sampled on a rectilinear grid of the `(u, v)` plane (`u, v, w` a
permutation of the world axes; `z` up for water) is what the start-point search can
traverse cell by cell in O(1) per cell (`face_cells.py`). `GridInfo` (mesh.py) describes
the project's own layout; a mesh loaded from arrays or a file (`SurfaceMesh.from_arrays`,
`from_trimesh`) has no `GridInfo` even when it is such a grid, and may order its vertices
x- or y-fastest, with either sign of the spacing, faces in any order and any diagonal per
cell. `detect_grid` recognises all of these from the arrays alone and returns the
`GridLayout` the traversal needs: the grid lines and a cell -> faces table.

Numpy, host side, O(V log V + F); called once per mesh by `prepare` (prepared.py).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .mesh import GridInfo


class GridLayout(NamedTuple):
    """A rectilinear grid over the `(u, v)` plane and the two faces of each cell.

    Attributes:
        axes: `(u, v, w)` world axis indices; the surface is a height along `w`.
        u_lines: `(nu + 1,)` float64 increasing `u` coordinates of the grid lines.
        v_lines: `(nv + 1,)` float64 increasing `v` coordinates.
        cell_faces: `(nv, nu, 2)` int64: the two faces covering cell `(i, j)` (between
            `u_lines[i], u_lines[i + 1]` and `v_lines[j], v_lines[j + 1]`) at `[j, i]`.
    """

    axes: tuple[int, int, int]
    u_lines: np.ndarray
    v_lines: np.ndarray
    cell_faces: np.ndarray


@functools.lru_cache(maxsize=16)
def grid_layout(grid: GridInfo) -> GridLayout:
    """The `GridLayout` of a `GridInfo` (either sign of `dx`, `dy`; cached per layout).

    Lines are computed as `GridInfo.vertex_xy` computes the vertices (`x0 + dx i`), so they
    are the vertices' own coordinates; a negative spacing reverses the cell order.
    """
    nx, ny = grid.nx, grid.ny
    x = grid.x0 + grid.dx * np.arange(nx + 1)
    y = grid.y0 + grid.dy * np.arange(ny + 1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    lower = 2 * (j * nx + i)  # GridInfo.cell_faces
    table = np.stack([lower, lower + 1], axis=-1)
    if grid.dx < 0:
        x, table = x[::-1], table[:, ::-1]
    if grid.dy < 0:
        y, table = y[::-1], table[::-1]
    return GridLayout((0, 1, 2), x, y, np.ascontiguousarray(table))


def detect_grid(vertices, faces, *, axis: int | None = None) -> GridLayout | None:
    """Recognise a regular (rectilinear) heightfield grid from vertex and face arrays.

    The projection along `axis` (default: the axis of least extent, `z` for water) must
    put every vertex on one of `nu + 1` lines in `u` and `nv + 1` lines in `v` (equal
    within 4 ulps of the input dtype at the coordinates' magnitude), every face on three
    distinct corners of one cell, and exactly two faces in each of the `nu nv` cells,
    covering it (the corners they omit are opposite: either diagonal, per cell). Vertex
    order, face order, winding and the sign of the spacing are free; duplicated vertices
    at a grid point are allowed. Returns None for anything else (the caller then uses a
    general acceleration structure).
    """
    V = np.asarray(vertices)
    F = np.asarray(faces, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) < 2:
        return None
    eps = float(np.finfo(V.dtype).eps) if np.issubdtype(V.dtype, np.floating) else 0.0
    V = V.astype(np.float64)
    extent = V.max(0) - V.min(0)
    w = int(np.argmin(extent)) if axis is None else int(axis)
    u, v = (k for k in range(3) if k != w)
    scale = float(np.max(np.abs(V[:, [u, v]])) + np.max(extent))
    lines_i = _lines(V[:, u], 4 * eps * scale)
    lines_j = _lines(V[:, v], 4 * eps * scale)
    if lines_i is None or lines_j is None:
        return None
    (u_lines, i), (v_lines, j) = lines_i, lines_j
    nu, nv = len(u_lines) - 1, len(v_lines) - 1
    if nu < 1 or nv < 1 or len(F) != 2 * nu * nv:
        return None
    fi, fj = i[F], j[F]
    ci, cj = fi.min(1), fj.min(1)
    if np.any(fi.max(1) - ci != 1) or np.any(fj.max(1) - cj != 1):
        return None
    corner = (fi - ci[:, None]) + 2 * (fj - cj[:, None])  # 0: (i, j), 1: (i+1, j), 2, 3
    if np.any(np.sort(corner, axis=1)[:, 1:] == np.sort(corner, axis=1)[:, :-1]):
        return None  # a repeated corner: the face is vertical in the projection
    missing = 6 - corner.sum(1)
    cell = cj * nu + ci
    if np.any(np.bincount(cell, minlength=nu * nv) != 2):
        return None
    order = np.argsort(cell, kind="stable")
    pair_missing = missing[order].reshape(-1, 2)
    if np.any(pair_missing.sum(1) != 3):  # omitted corners {0, 3} or {1, 2}: the cell is covered
        return None
    table = order.reshape(nv, nu, 2)
    return GridLayout((u, v, w), u_lines, v_lines, table)


def _lines(x: np.ndarray, tol: float):
    """Cluster coordinates into grid lines: `(lines, index of each x)`, or None when two
    clusters are not clearly apart (gaps within 1000 tolerances: not a grid, or one that
    rounding could not tell from another)."""
    order = np.argsort(x, kind="stable")
    xs = x[order]
    new = np.r_[True, np.diff(xs) > tol]
    if np.count_nonzero(new) > len(x) // 2 + 1:
        return None  # more lines than a grid with at least two points per line can have
    cluster = np.cumsum(new) - 1
    starts = xs[new]
    ends = np.r_[xs[np.flatnonzero(new)[1:] - 1], xs[-1]]
    if len(starts) > 1 and np.min(starts[1:] - ends[:-1]) <= 1000 * tol:
        return None
    index = np.empty(len(x), dtype=np.int64)
    index[order] = cluster
    return starts, index


__all__ = ["GridLayout", "detect_grid", "grid_layout"]
