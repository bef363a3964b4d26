"""Cells over a projection plane listing the faces above them, and the first crossing of a
segment found by walking those cells (a 2D DDA, Amanatides & Woo 1987).

One structure serves two kinds of mesh:

- **regular heightfield grids** (`cells_from_layout`, from `GridInfo` or `detect_grid`):
  the cells are the grid's own, two faces each, exact (the faces tile the cell);
- **any other mesh** (`bin_faces`): a uniform grid over the plane of the two largest
  extents, each cell listing every face whose projected bounding box, padded by the
  traversal's rounding (below), overlaps it, in rows of `K` faces (-1 padding): `K` is
  the longest list but for the rare cells around a vertex of high valence, whose lists
  continue in extra rows (`FaceCells.more`), so that the few do not set every step's width.

Traversal (`first_hit_cells`): the segment `P + s d` is clipped to the box of the grid
and of the surface's height range (the slab), and its projection is walked cell by cell
in order of `s`; each cell's faces are tested with `crossing.triangle_crossing`. A
lane stops when its best crossing lies before the point where it leaves the current cell
(no later cell can hold an earlier crossing), when it leaves the slab or the grid.
Cost per segment O(k K), `k` the cells its projection crosses inside the slab: one for a
segment along the projection axis, `1 + |d_uv| (w_max - w_min) / (|d_w| cell)` for an
oblique one; independent of the triangle count for a given wave height and cell size.

Rounding. The grid lines are the vertices' own coordinates (`GridLayout`), so a crossing
on a cell wall is attributed to one of the two cells up to the rounding of the wall
crossing parameter, a few ulps of the coordinates; the faces of either cell accept it
because `triangle_crossing` accepts crossings within `C_ROUND` times the first-order
rounding bound outside an edge. `bin_faces` pads the boxes by `PAD_ULPS` ulps of the
coordinates so a face near a wall is listed on both sides.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..math.crossing import clip_to_box, face_frames, finite_segments, first_of, triangle_crossing
from ..runtime.lanes import LANE_CHUNK, map_lanes
from ..runtime.precision import check_mesh_dtype
from ..surface.grid import GridLayout
from ..surface.mesh import SurfaceMesh

#: Padding of a face's projected box when binning, in ulps of the coordinates' magnitude:
#: larger than the wall attribution error of the traversal (a few ulps), so a crossing
#: within rounding of a cell wall finds its face from either side.
PAD_ULPS = 256
#: Target number of faces per cell by `bin_faces` (measured best of 0.25, 0.5, 1, 2
#: on a jittered 32k-triangle mesh: docs/mesh.md).
FACES_PER_CELL = 0.5
#: Faces `bin_faces` processes at a time (its temporaries then stay in cache).
BIN_BLOCK = 8192
#: Longest cell list `bin_faces` accepts; a mesh that needs more (a fan of faces around one
#: point, a mesh folded many times over the plane) is left to the BVH.
MAX_CELL_FACES = 48


class FaceCells(eqx.Module):
    """Faces listed per cell of a rectilinear grid over a projection plane (module docstring).

    Attributes:
        u_lines: `(nu + 1,)` increasing grid line coordinates along world axis `axes[0]`.
        v_lines: `(nv + 1,)` increasing, along `axes[1]`.
        faces: `(rows, K)` int32 faces listed in cell `(i, j)` from row `j nu + i`, -1
            padding; rows past `nu nv` continue longer lists.
        more: `(rows,)` the row continuing each row's list, -1 where it ends.
        owner: `(rows,)` the cell `j nu + i` of each row.
        axes: static `(u, v, w)`: the projection is along world axis `w`.
        kind: static, `"grid"` (exact cells of a heightfield grid) or `"bins"`.
    """

    u_lines: Float[Array, " nu1"]
    v_lines: Float[Array, " nv1"]
    faces: Int[Array, "rows K"]
    more: Int[Array, " rows"]
    owner: Int[Array, " rows"]
    axes: tuple[int, int, int] = eqx.field(static=True)
    kind: str = eqx.field(static=True)

    @property
    def shape(self) -> tuple[int, int]:
        """`(nu, nv)` cells."""
        return self.u_lines.shape[0] - 1, self.v_lines.shape[0] - 1


def cells_from_layout(layout: GridLayout, dtype) -> FaceCells:
    """The exact cells of a regular heightfield grid (`grid.grid_layout` / `detect_grid`)."""
    nv, nu, _ = layout.cell_faces.shape
    return FaceCells(
        u_lines=jnp.asarray(layout.u_lines, dtype), v_lines=jnp.asarray(layout.v_lines, dtype),
        faces=jnp.asarray(layout.cell_faces.reshape(nu * nv, 2), jnp.int32),
        more=jnp.full(nu * nv, -1, jnp.int32), owner=jnp.arange(nu * nv, dtype=jnp.int32),
        axes=tuple(int(a) for a in layout.axes), kind="grid",
    )  # fmt: skip


def bin_faces(mesh: SurfaceMesh, *, faces_per_cell: float = FACES_PER_CELL,
              max_cell_faces: int = MAX_CELL_FACES) -> FaceCells | None:  # fmt: skip
    """Bin any mesh's faces into a uniform grid over the plane of its two largest extents.

    About `F / faces_per_cell` square cells; each lists the faces whose projected triangle,
    padded by `PAD_ULPS` ulps of the coordinates, meets it. Numpy, O(F log F).
    Returns None when some cell would list more than `max_cell_faces` faces.
    """
    check_mesh_dtype(mesh.dtype)
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces)
    dtype = np.dtype(mesh.dtype)
    extent = V.max(0) - V.min(0)
    w = int(np.argmin(extent))
    u, v = (k for k in range(3) if k != w)
    T = V[F][..., [u, v]]  # (F, 3, 2)
    lo, hi = T.min(axis=1), T.max(axis=1)
    origin, size = V[:, [u, v]].min(0), np.maximum(extent[[u, v]], 1e-300)
    cell = np.sqrt(size[0] * size[1] * faces_per_cell / len(F))
    n_cells = np.clip(np.ceil(size / cell).astype(np.int64), 1, None)
    # Lines as the traversal will see them (rounded to the mesh dtype), last one past the max.
    lines = [np.asarray((origin[k] + size[k] * np.arange(n_cells[k] + 1) / n_cells[k]).astype(dtype),
                        np.float64) for k in range(2)]  # fmt: skip
    pad = PAD_ULPS * float(np.finfo(dtype).eps) * float(np.max(np.abs(V)) + np.max(extent))
    first = [np.clip(np.searchsorted(lines[k], lo[:, k] - pad, side="right") - 1, 0, n_cells[k] - 1)
             for k in range(2)]  # fmt: skip
    last = [np.clip(np.searchsorted(lines[k], hi[:, k] + pad, side="right") - 1, 0, n_cells[k] - 1)
            for k in range(2)]  # fmt: skip
    # Per face and edge: the inward normal n (0 for a face that projects to a sliver: kept
    # wherever its box is), n . (edge start) and the padding in units of |n|.
    edge = np.roll(T, -1, axis=1) - T
    inward = np.stack([-edge[..., 1], edge[..., 0]], -1)
    inward *= np.sign(np.sum(inward * (np.roll(T, -2, axis=1) - T), -1))[..., None]
    offset = np.sum(inward * T, -1) - pad * np.hypot(inward[..., 0], inward[..., 1])
    faces, cell_ids = [], []
    for start in range(0, len(F), BIN_BLOCK):  # blocks of faces: temporaries stay in cache
        block = slice(start, start + BIN_BLOCK)
        face, ci, cj = _candidate_cells([f[block] for f in first], [x[block] for x in last], start)
        # Keep the (face, cell) pairs whose cell meets the projected triangle, not just its
        # box (2D separating axes: an edge with the whole cell beyond it, by more than the
        # padding, separates them; the cell's farthest point along -n is its centre plus
        # |n_u| h_u + |n_v| h_v, h the half sides).
        centre = np.stack([lines[0][ci] + lines[0][ci + 1], lines[1][cj] + lines[1][cj + 1]], -1) / 2
        half = np.stack([lines[0][ci + 1] - lines[0][ci], lines[1][cj + 1] - lines[1][cj]], -1) / 2
        n = inward[face]
        reach = np.einsum("mek,mk->me", n, centre) + np.einsum("mek,mk->me", np.abs(n), half)
        keep = np.all(reach >= offset[face], axis=1)
        faces.append(face[keep])
        cell_ids.append(cj[keep] * n_cells[0] + ci[keep])
    face, cell_id = np.concatenate(faces), np.concatenate(cell_ids)
    per_cell = np.bincount(cell_id, minlength=int(n_cells[0] * n_cells[1]))
    width = int(per_cell.max())
    if width > max_cell_faces:
        return None
    order = np.argsort(cell_id, kind="stable")
    slot = np.arange(len(order)) - np.repeat(np.cumsum(per_cell) - per_cell, per_cell)
    table, more, owner = _rows_of_lists(cell_id[order], slot, face[order], per_cell, row_width(per_cell))
    return FaceCells(u_lines=jnp.asarray(lines[0], dtype), v_lines=jnp.asarray(lines[1], dtype),
                     faces=jnp.asarray(table, jnp.int32), more=jnp.asarray(more, jnp.int32),
                     owner=jnp.asarray(owner, jnp.int32), axes=(u, v, w), kind="bins")  # fmt: skip


#: Fraction of cells whose lists may continue in extra rows (`row_width`).
LONG_CELLS = 1e-3


def row_width(per_cell: np.ndarray) -> int:
    """Faces per row of the cell table: the smallest width that holds the whole list of all
    but a fraction `LONG_CELLS` of the cells (those continue in extra rows). Every step of
    the traversal tests one row for every lane of a chunk, so a width set by the longest
    list makes all lanes pay for a few cells around a vertex of high valence: on the
    32k-triangle lagoon 48 of 64,170 cells list 9-11 faces, the others at most 8."""
    counts = np.bincount(per_cell)
    cells_longer = len(per_cell) - np.cumsum(counts)  # cells with more than w faces, per w
    return max(int(np.argmax(cells_longer <= LONG_CELLS * len(per_cell))), 1)


def _rows_of_lists(cell, slot, face, per_cell, width: int):
    """The cell table in rows of `width`: cell `c`'s first row is row `c`, its further rows
    are appended after the `len(per_cell)` cell rows and chained by `more`."""
    n_cells = len(per_cell)
    extra = np.maximum(-(-per_cell // width) - 1, 0)  # rows beyond the first, per cell
    base = n_cells + np.cumsum(extra) - extra  # each cell's first extra row
    rows = n_cells + int(extra.sum())
    table = np.full((rows, width), -1, np.int64)
    part = slot // width
    row = np.where(part == 0, cell, base[cell] + part - 1)
    table[row, slot % width] = face
    more = np.full(rows, -1, np.int64)
    owner = np.concatenate([np.arange(n_cells), np.repeat(np.arange(n_cells), extra)])
    long_cells = np.flatnonzero(extra)
    for c in long_cells:  # rare: a fraction LONG_CELLS of the cells at most
        chain = [c, *range(base[c], base[c] + extra[c])]
        more[chain[:-1]] = chain[1:]
    return table, more, owner


def _candidate_cells(first, last, offset: int):
    """`(face, i, j)` for every cell of every face's padded box (faces numbered from `offset`)."""
    span_i, span_j = last[0] - first[0] + 1, last[1] - first[1] + 1
    count = span_i * span_j
    local = np.repeat(np.arange(len(count)), count)
    k = np.arange(len(local)) - np.repeat(np.cumsum(count) - count, count)
    si = span_i[local]
    return local + offset, first[0][local] + k % si, first[1][local] + k // si


def first_hit_cells(mesh: SurfaceMesh, cells: FaceCells, A: Float[Array, "n 3"], B: Float[Array, "n 3"],
                    exclude: Int[Array, " n"] | None = None, *, s_lo: float = 0.0, s_hi: float = 1.0,
                    widen: bool, chunk: int | None = None):  # fmt: skip
    """First crossing of `A + s (B - A)` with the surface for `s` in `[s_lo, s_hi]`, not on
    face `exclude` (per lane, -1: none), by the cell traversal of the module docstring.

    `widen=True` accepts crossings within the rounding bound outside the window (start
    points: a crossing at an end is kept); `widen=False` shrinks the window by it
    (occlusion: a crossing at an end, within rounding, is not a blocker). Lanes run in
    vmapped chunks of `chunk` (default on a CPU `cpu_chunk(K)`, at most 256 lanes: each
    chunk runs until its slowest lane; on an accelerator, all lanes in one vmap). Returns
    `(face, ab, s)`: face -1, `ab = 0`, `s = inf` where there is none. One jitted call
    (the window and `widen` are static).
    """
    check_mesh_dtype(mesh.dtype)
    if chunk is None:  # small chunks pay on a CPU; an accelerator wants every lane at once
        chunk = cpu_chunk(cells.faces.shape[1]) if jax.default_backend() == "cpu" else max(A.shape[0], 1)
    # The mesh's arrays, not the mesh: its static `grid` would key a compile per layout.
    window = _Window(float(s_lo), float(s_hi), bool(widen))
    return _first_hit_cells(mesh.vertices, mesh.faces, cells, A, B, exclude, window, chunk)


#: Face tests per lockstep step of a CPU chunk (`cpu_chunk`).
CHUNK_FACE_TESTS = 1024


def cpu_chunk(cell_faces: int) -> int:
    """Lanes per vmapped chunk of the cell traversal on a CPU, for cells listing up to
    `cell_faces` faces: the largest power of two with `chunk * cell_faces <=
    CHUNK_FACE_TESTS`, at most `lanes.LANE_CHUNK` (256): a lockstep step that tests more
    faces runs several times slower per lane, and smaller chunks lose to the per-step
    overhead (docs/mesh.md, "Measurements behind the code")."""
    chunk = LANE_CHUNK
    while chunk > 16 and chunk * max(cell_faces, 1) > CHUNK_FACE_TESTS:
        chunk //= 2
    return chunk


class _Window(NamedTuple):
    """The segment window `[s_lo, s_hi]` and whether it is widened by rounding (static)."""

    s_lo: float
    s_hi: float
    widen: bool


class _Slab(NamedTuple):
    """What every lane of one call shares: the box of the grid (padded), each cell's height
    range, the faces' edge frames; computed once per call from the traced heights."""

    lo: jax.Array
    hi: jax.Array
    cell_lo: jax.Array
    cell_hi: jax.Array
    z_scale: jax.Array
    frames: tuple


def _slab(vertices, mesh_faces, cells: FaceCells, dtype) -> _Slab:
    u, v, w = cells.axes
    nu, nv = cells.shape
    # Heights are traced (animated water): one O(V) reduction per call for the slab.
    z = vertices[:, w]
    z_lo, z_hi = jnp.min(z), jnp.max(z)
    z_pad = 0.01 * (z_hi - z_lo) + 1e-5 * (1 + jnp.maximum(jnp.abs(z_lo), jnp.abs(z_hi)))
    us, vs = cells.u_lines, cells.v_lines
    uv_pad = 1e-5 * (jnp.maximum(us[-1] - us[0], vs[-1] - vs[0])
                     + jnp.max(jnp.abs(jnp.stack([us[0], us[-1], vs[0], vs[-1]]))))  # fmt: skip
    lo: list = [None] * 3
    hi: list = [None] * 3
    lo[u], lo[v], lo[w] = us[0] - uv_pad, vs[0] - uv_pad, z_lo - z_pad
    hi[u], hi[v], hi[w] = us[-1] + uv_pad, vs[-1] + uv_pad, z_hi + z_pad
    # Height range of each cell's faces (one gather of the cell table per call), for
    # skipping the cells a segment passes entirely above or below.
    face_z = z[mesh_faces]
    listed = cells.faces >= 0
    listed_face = jnp.maximum(cells.faces, 0)
    row_lo = jnp.min(jnp.where(listed, face_z.min(1)[listed_face], jnp.inf), axis=1)
    row_hi = jnp.max(jnp.where(listed, face_z.max(1)[listed_face], -jnp.inf), axis=1)
    cell_lo = jax.ops.segment_min(row_lo, cells.owner, num_segments=nu * nv, indices_are_sorted=False)
    cell_hi = jax.ops.segment_max(row_hi, cells.owner, num_segments=nu * nv, indices_are_sorted=False)
    # Edge vectors and lengths of every face, once per call (traced vertices), gathered
    # per test: cheaper than edges per test (docs/mesh.md "Measurements behind the code").
    frames = face_frames(vertices[mesh_faces])
    return _Slab(jnp.stack(lo).astype(dtype), jnp.stack(hi).astype(dtype), cell_lo, cell_hi,
                 jnp.maximum(jnp.abs(z_lo), jnp.abs(z_hi)), frames)


class _GridStep(NamedTuple):
    """The 2D DDA of one segment over the cell grid: `P + s d`, stepping `step` per axis."""

    P: jax.Array
    d: jax.Array
    step: jax.Array
    us: jax.Array
    vs: jax.Array
    axes: tuple

    def wall(self, k, i, lines):
        """Parameter where the segment meets the next wall along grid axis `k` from cell `i`."""
        a = self.axes[k]
        moving = self.step[k] != 0
        x = lines[jnp.clip(i + (self.step[k] > 0), 0, lines.shape[0] - 1)]
        dk = jnp.where(moving, self.d[a], 1)
        return jnp.where(moving, (x - self.P[a]) / dk, jnp.inf)

    def next_cell(self, i, j, s_out, nu: int, nv: int):
        """`(s_leave, i_next, j_next, gone)`: where the segment leaves cell `(i, j)`, the cell
        it enters (clipped into the grid), and whether it leaves the grid or the window
        `s <= s_out` instead."""
        s_u, s_v = self.wall(0, i, self.us), self.wall(1, j, self.vs)
        s_leave = jnp.minimum(s_u, s_v)
        along_u = s_u <= s_v
        i_next = jnp.where(along_u, i + self.step[0], i)
        j_next = jnp.where(along_u, j, j + self.step[1])
        gone = (s_leave > s_out) | (i_next < 0) | (i_next >= nu) | (j_next < 0) | (j_next >= nv)
        return s_leave, jnp.clip(i_next, 0, nu - 1), jnp.clip(j_next, 0, nv - 1), gone


def _first_hit_lane(cells: FaceCells, slab: _Slab, window: _Window, s_end, P, Q, exclude):
    """The cell traversal of one lane (module docstring): `(face, ab, s)`."""
    u, v, w = cells.axes
    nu, nv = cells.shape
    us, vs = cells.u_lines, cells.v_lines
    dtype = P.dtype
    eps = jnp.finfo(dtype).eps
    margin = 1 if window.widen else -1
    d = Q - P
    s_in, s_out = clip_to_box(P[None], d[None], slab.lo, slab.hi, s_end[None])
    s_in, s_out = s_in[0], s_out[0]
    X = P + s_in * d
    i = jnp.clip(jnp.searchsorted(us, X[u], side="right") - 1, 0, nu - 1)
    j = jnp.clip(jnp.searchsorted(vs, X[v], side="right") - 1, 0, nv - 1)
    grid = _GridStep(P, d, jnp.sign(jnp.stack([d[u], d[v]])).astype(jnp.int32), us, vs, (u, v))

    # Skip ahead (cheap steps, no face tests) to the first cell whose height range the
    # segment meets while inside it. Padded by 256 ulps of the magnitudes, far more than
    # the rounding of z at the walls: a cell holding a crossing is never skipped.
    meet_pad = 256 * eps * (jnp.max(jnp.abs(P)) + jnp.max(jnp.abs(d)) + slab.z_scale)

    def skip(state):
        i, j, s_enter, _, _ = state
        s_leave, i_next, j_next, gone = grid.next_cell(i, j, s_out, nu, nv)
        z0, z1 = P[w] + s_enter * d[w], P[w] + jnp.minimum(s_leave, s_out) * d[w]
        cell = j * nu + i
        meets = (jnp.maximum(z0, z1) + meet_pad >= slab.cell_lo[cell]) & (
            jnp.minimum(z0, z1) - meet_pad <= slab.cell_hi[cell])
        return (jnp.where(meets, i, i_next), jnp.where(meets, j, j_next), jnp.where(meets, s_enter, s_leave),
                meets | gone, ~meets & gone)

    empty = s_in > s_out
    i, j, _, _, missed = jax.lax.while_loop(lambda st: ~st[3], skip, (i, j, s_in, empty, empty))

    def body(state):  # tests one row of a cell's faces; a continued list stays in the cell
        i, j, row, _, best, face, ab, s_best = state
        faces = cells.faces[row]
        c = triangle_crossing(P[None], d[None], jax.tree.map(lambda x: x[jnp.maximum(faces, 0)], slab.frames))
        ok = (c.inside & (faces >= 0) & (faces != exclude)
              & (c.s >= window.s_lo - margin * c.s_tol) & (c.s <= window.s_hi + margin * c.s_tol))  # fmt: skip
        r_first, f_first, ab_first, s_first = first_of(c.rank()[None], ok[None], faces[None],
                                                       c.ab[None], c.s[None])  # fmt: skip
        better = r_first[0] < best
        best = jnp.where(better, r_first[0], best)
        face = jnp.where(better, f_first[0], face)
        ab = jnp.where(better, ab_first[0], ab)
        s_best = jnp.where(better, s_first[0], s_best)
        s_leave, i_next, j_next, gone = grid.next_cell(i, j, s_out, nu, nv)
        done = (best <= s_leave) | gone
        cont = cells.more[row]
        stay = cont >= 0
        return (jnp.where(stay, i, i_next), jnp.where(stay, j, j_next),
                jnp.where(stay, cont, j_next * nu + i_next), done & ~stay, best, face, ab, s_best)

    inf = jnp.asarray(jnp.inf, dtype)
    init = (i, j, j * nu + i, missed, inf, jnp.asarray(-1, jnp.int32), jnp.zeros(2, dtype), inf)
    *_, face, ab, s_best = jax.lax.while_loop(lambda state: ~state[3], body, init)
    return face, ab, s_best


@eqx.filter_jit
def _first_hit_cells(vertices, mesh_faces, cells: FaceCells, A, B, exclude, window: _Window, chunk: int):
    A, B = finite_segments(A, B)
    dtype = A.dtype
    slab = _slab(vertices, mesh_faces, cells, dtype)
    eps = jnp.finfo(dtype).eps
    # (Widened, the window reaches past s_hi by the rounding of s: keep the slab too.)
    s_hi = window.s_hi
    s_end = jnp.asarray(s_hi + 64 * float(eps) * (1 + abs(s_hi)) if window.widen else s_hi, dtype)
    exclude = jnp.full(A.shape[0], -1, jnp.int32) if exclude is None else exclude
    return map_lanes(lambda P, Q, x: _first_hit_lane(cells, slab, window, s_end, P, Q, x), A, B, exclude,
                     chunk=chunk)


__all__ = ["CHUNK_FACE_TESTS", "FaceCells", "bin_faces", "cells_from_layout", "cpu_chunk", "first_hit_cells"]
