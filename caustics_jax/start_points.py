"""Start points of the walks: the first crossing of segment `P -> L` with the surface.

Seed 001 §3.4.2: `M0 = (PL) ∩ surface` satisfies the coplanarity constraint trivially
(`PM0 x LM0 = 0`), so every walk starts there. "First" means the crossing nearest to `P`
(smallest segment parameter `s` in `M = P + s (L - P)`): a wavy surface can be crossed
more than once.

Two paths, one segment-triangle kernel (`segment_triangle`, Möller-Trumbore):

- **grid** (`mesh.grid` set, chosen statically): a 2D DDA over the heightfield's cells
  along the xy projection of the segment, clipped to the slab `z_min <= z <= z_max` and
  to the grid's xy extent. Per segment it tests the two triangles of each cell it crosses
  inside the slab: O(k) with `k = 1 + |dxy| (z_max - z_min) / (|dz| cell)`, independent of
  the triangle count for vertical segments and set by the wave height and the segment's
  slope otherwise; no acceleration structure. The batch runs in lockstep, so a batch costs
  O(N max k).
- **general** (any mesh): a bounding-volume hierarchy built in numpy outside jit
  (`build_bvh`: faces sorted along a Morton curve of their centroids, grouped in leaves of
  `leaf_size`, a complete binary tree of boxes over the leaves; O(F log F) build, O(F)
  memory), traversed stacklessly inside jit (a complete tree's next node is a bit trick).
  Expected O(log F) boxes per segment for surfaces like water, O(F) worst case;
  closest-hit pruning keeps the first crossing exact.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .geometry import dot
from .mesh import SurfaceMesh


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


class FaceBVH(eqx.Module):
    """Complete binary tree of boxes over Morton-ordered leaves of faces (heap layout).

    Attributes:
        lo, hi: `(2 n_leaves, 3)` box corners of node `n` (1-based heap index: root 1,
            children `2n, 2n + 1`; leaves are `n_leaves .. 2 n_leaves - 1`; row 0 unused).
            Boxes are padded by a small multiple of the scene size so that rounding never
            culls a hit (flat faces have zero-thickness boxes).
        leaf_faces: `(n_leaves, leaf_size)` int32 face indices, -1 padding.
        n_leaves: static, a power of two.
    """

    lo: Float[Array, "nodes 3"]
    hi: Float[Array, "nodes 3"]
    leaf_faces: Int[Array, "leaves leaf_size"]
    n_leaves: int = eqx.field(static=True)


def build_bvh(mesh: SurfaceMesh, leaf_size: int = 4) -> FaceBVH:
    """Build the general path's BVH with numpy (outside jit); O(F log F) time, O(F) memory."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    T = V[np.asarray(mesh.faces)]  # (F, 3, 3)
    n_faces = len(T)
    lo_f, hi_f = T.min(axis=1), T.max(axis=1)
    scene_lo, scene_hi = lo_f.min(0), hi_f.max(0)
    # One scale for all axes (the bounding cube): per-axis scaling would give a thin water
    # layer's z the same weight as x and y, and scatter xy-neighbours across the tree.
    extent = max(float(np.max(scene_hi - scene_lo)), 1e-300)
    code = _morton3((T.mean(axis=1) - scene_lo) / extent)
    order = np.argsort(code, kind="stable")
    n_leaves = 1 << max(int(np.ceil(np.log2(max(-(-n_faces // leaf_size), 1)))), 0)
    slots = np.full(n_leaves * leaf_size, -1, dtype=np.int64)
    slots[:n_faces] = order
    leaf_faces = slots.reshape(n_leaves, leaf_size)
    pad_lo = np.where(leaf_faces[..., None] >= 0, lo_f[leaf_faces], np.inf)
    pad_hi = np.where(leaf_faces[..., None] >= 0, hi_f[leaf_faces], -np.inf)
    levels_lo, levels_hi = [pad_lo.min(axis=1)], [pad_hi.max(axis=1)]
    while len(levels_lo[-1]) > 1:
        levels_lo.append(levels_lo[-1].reshape(-1, 2, 3).min(axis=1))
        levels_hi.append(levels_hi[-1].reshape(-1, 2, 3).max(axis=1))
    # Heap rows: [unused, root, level 1, ..., leaves]. Empty boxes stay (+inf, -inf).
    lo = np.concatenate([np.full((1, 3), np.inf)] + levels_lo[::-1])
    hi = np.concatenate([np.full((1, 3), -np.inf)] + levels_hi[::-1])
    pad = 1e-5 * float(np.max(scene_hi - scene_lo) + np.max(np.abs(V)))
    lo, hi = lo - pad, hi + pad
    dtype = mesh.dtype
    return FaceBVH(lo=jnp.asarray(lo, dtype), hi=jnp.asarray(hi, dtype),
                   leaf_faces=jnp.asarray(leaf_faces, jnp.int32), n_leaves=n_leaves)  # fmt: skip


def start_points(mesh: SurfaceMesh, P, L, *, method: str = "auto",
                 bvh: FaceBVH | None = None) -> StartPoint:  # fmt: skip
    """First crossing `M0` of segment `P -> L` with the surface (seed 001 §3.4.2).

    `P`, `L`: `(*batch, 3)` (broadcast together), the mesh's float dtype. `method`:
    `"auto"` (the grid path when `mesh.grid` is set, else general), `"grid"` or
    `"general"` (see the module docstring for their complexity). `bvh` is the general
    path's acceleration structure; built here with `build_bvh` when not given (pass one
    to reuse it across calls, or when the mesh is traced). Inputs are validated here,
    outside jit; the work runs in a jitted core. `M0 = barycentric_point(V, barycentric)`.
    """
    P, L = _validate(mesh, P, L)
    if method == "auto":
        method = "grid" if mesh.grid is not None else "general"
    if method == "grid":
        if mesh.grid is None:
            raise ValueError("method='grid' needs a regular heightfield grid mesh (mesh.grid)")
        core = lambda P, L: _start_points_grid(mesh, P, L)  # noqa: E731
    elif method == "general":
        if bvh is None:
            bvh = build_bvh(mesh)
        core = lambda P, L: _start_points_bvh(mesh, bvh, P, L)  # noqa: E731
    else:
        raise ValueError(f"method must be 'auto', 'grid' or 'general', got {method!r}")
    batch = P.shape[:-1]
    face, ab, found = core(P.reshape(-1, 3), L.reshape(-1, 3))
    return StartPoint(face.reshape(batch), ab.reshape(*batch, 2), found.reshape(batch))


def first_crossing(mesh: SurfaceMesh, P, L, *, bvh: FaceBVH | None = None):
    """The jitted cores of `start_points` without its validation, for callers that already
    hold validated (or traced) `(n, 3)` arrays: the grid DDA when `mesh.grid` is set,
    else the BVH (built here when not given). Returns `(face, ab, found)`."""
    if mesh.grid is not None:
        return _start_points_grid(mesh, P, L)
    return _start_points_bvh(mesh, bvh if bvh is not None else build_bvh(mesh), P, L)


def segment_triangle(P: Float[Array, "*batch 3"], d: Float[Array, "*batch 3"],
                     V: Float[Array, "*batch 3 3"]):  # fmt: skip
    """Crossing of the segment `P + s d, s in [0, 1]` with triangle `V` (Möller-Trumbore).

    Returns `(s, ab, hit)`: segment parameter, barycentrics `(a, b)` of seed 001 eq. 3
    (projected into the closed triangle), and whether the segment crosses it. Hits within
    a few ulps outside an edge count, so a segment through a shared edge is never lost
    between two faces. Segments in the triangle's plane (`det = 0`) do not hit.
    """
    eps = jnp.finfo(P.dtype).eps
    e1, e2 = V[..., 1, :] - V[..., 0, :], V[..., 2, :] - V[..., 0, :]
    pvec = jnp.cross(d, e2)
    det = dot(e1, pvec)
    scale = jnp.sqrt(dot(d, d) * dot(e1, e1) * dot(e2, e2))
    ok = jnp.abs(det) > 16 * eps * scale
    inv = jnp.where(ok, 1 / jnp.where(ok, det, 1), 0)
    tvec = P - V[..., 0, :]
    qvec = jnp.cross(tvec, e1)
    a, b, s = dot(tvec, pvec) * inv, dot(d, qvec) * inv, dot(e2, qvec) * inv
    tol = 16 * eps
    hit = ok & (a >= -tol) & (b >= -tol) & (a + b <= 1 + tol) & (s >= -tol) & (s <= 1 + tol)
    a, b = jnp.maximum(a, 0), jnp.maximum(b, 0)
    over = a + b > 1
    total = jnp.where(over, a + b, 1)
    return jnp.clip(s, 0, 1), jnp.stack([a / total, b / total], axis=-1), hit


# --------------------------------------------------------------------------- grid path


@jax.jit
def _start_points_grid(mesh: SurfaceMesh, P, L):
    g = mesh.grid
    dtype = P.dtype
    d = L - P
    # Heights are traced (they may change between calls): one O(V) reduction per call.
    z = mesh.vertices[:, 2]
    z_min, z_max = jnp.min(z), jnp.max(z)
    # The slab only prunes cells; pad it so rounding never prunes a crossing.
    pad = 0.01 * (z_max - z_min) + 1e-5 * (1 + jnp.maximum(jnp.abs(z_min), jnp.abs(z_max)))
    box_lo = jnp.stack([jnp.asarray(g.x0, dtype), jnp.asarray(g.y0, dtype), z_min - pad])
    box_hi = jnp.stack(
        [
            jnp.asarray(g.x0 + g.nx * g.dx, dtype),
            jnp.asarray(g.y0 + g.ny * g.dy, dtype),
            z_max + pad,
        ]
    )
    s_in, s_out = _clip_to_box(P, d, box_lo, box_hi, jnp.ones(P.shape[:1], dtype))
    active = s_in <= s_out
    X = P + s_in[:, None] * d
    cell = jnp.asarray([g.dx, g.dy], dtype)
    origin = jnp.asarray([g.x0, g.y0], dtype)
    n_cells = jnp.asarray([g.nx, g.ny], jnp.int32)
    ij = jnp.clip(jnp.floor((X[:, :2] - origin) / cell).astype(jnp.int32), 0, n_cells - 1)
    step = jnp.sign(d[:, :2]).astype(jnp.int32)
    moving = step != 0
    d_safe = jnp.where(moving, d[:, :2], 1)
    inf = jnp.asarray(jnp.inf, dtype)
    boundary = origin + (ij + (step > 0)) * cell
    s_next = jnp.where(moving, (boundary - P[:, :2]) / d_safe, inf)
    s_delta = jnp.where(moving, cell / jnp.abs(d_safe), inf)

    def test_cell(ij):
        lower, upper = g.cell_faces(ij[:, 0], ij[:, 1])
        faces = jnp.stack([lower, upper], axis=-1)
        V, _ = mesh.triangle(faces)
        s, ab, hit = segment_triangle(P[:, None], d[:, None], V)
        s = jnp.where(hit, s, inf)
        first = jnp.argmin(s, axis=-1)
        pick = lambda x: jnp.take_along_axis(x, first[:, None], axis=1)[:, 0]  # noqa: E731
        return pick(faces), jnp.take_along_axis(ab, first[:, None, None], axis=1)[:, 0], hit.any(-1)

    def cond(state):
        k, _, _, done, *_ = state
        return (k < g.nx + g.ny + 1) & ~jnp.all(done)

    def body(state):
        k, ij, s_next, done, face, ab, found = state
        f, ab_c, hit = test_cell(ij)
        new = ~done & hit
        face = jnp.where(new, f, face)
        ab = jnp.where(new[:, None], ab_c, ab)
        found = found | new
        axis = jnp.argmin(s_next, axis=-1)  # the cell wall the segment leaves through
        s_leave = jnp.min(s_next, axis=-1)
        advance = jax.nn.one_hot(axis, 2, dtype=jnp.int32) * step
        ij = ij + advance
        s_next = s_next + jax.nn.one_hot(axis, 2, dtype=dtype) * s_delta
        left = jnp.any((ij < 0) | (ij >= n_cells), axis=-1) | (s_leave > s_out)
        return k + 1, jnp.clip(ij, 0, n_cells - 1), s_next, done | new | left, face, ab, found

    n = P.shape[0]
    init = (0, ij, s_next, ~active, jnp.full(n, -1, jnp.int32), jnp.zeros((n, 2), dtype),
            jnp.zeros(n, bool))  # fmt: skip
    *_, face, ab, found = jax.lax.while_loop(cond, body, init)
    return face, ab, found


def _clip_to_box(P, d, lo, hi, s_max):
    """Segment parameters `[s_in, s_out]` inside the box `[lo, hi]`, within `[0, s_max]`."""
    moving = d != 0
    inv = jnp.where(moving, 1 / jnp.where(moving, d, 1), 0)
    t0, t1 = (lo - P) * inv, (hi - P) * inv
    inside = (P >= lo) & (P <= hi)
    inf = jnp.asarray(jnp.inf, P.dtype)
    near = jnp.where(moving, jnp.minimum(t0, t1), jnp.where(inside, -inf, inf))
    far = jnp.where(moving, jnp.maximum(t0, t1), jnp.where(inside, inf, -inf))
    s_in = jnp.maximum(jnp.max(near, axis=-1), 0)
    s_out = jnp.minimum(jnp.min(far, axis=-1), s_max)
    return s_in, s_out


# --------------------------------------------------------------------------- general path


@jax.jit
def _start_points_bvh(mesh: SurfaceMesh, bvh: FaceBVH, P, L):
    dtype = P.dtype
    d = L - P
    n = P.shape[0]
    tol = 16 * jnp.finfo(dtype).eps
    n_leaves = bvh.n_leaves

    def body(state):
        node, best_s, face, ab = state
        live = node > 0
        idx = jnp.maximum(node, 1)
        s_in, s_out = _clip_to_box(P, d, bvh.lo[idx], bvh.hi[idx], best_s + tol)
        # Padding leaves have empty boxes (lo > hi), which a slab test alone would accept.
        nonempty = jnp.all(bvh.lo[idx] <= bvh.hi[idx], axis=-1)
        hit_box = live & nonempty & (s_in <= s_out)
        is_leaf = idx >= n_leaves
        # Leaf: test its faces (all lanes compute, masked; padding faces never hit).
        leaf = jnp.where(is_leaf, idx - n_leaves, 0)
        faces = bvh.leaf_faces[leaf]
        V, _ = mesh.triangle(faces)
        s, ab_c, hit = segment_triangle(P[:, None], d[:, None], V)
        hit = hit & (faces >= 0) & (hit_box & is_leaf)[:, None]
        s = jnp.where(hit, s, jnp.inf)
        first = jnp.argmin(s, axis=-1)
        s_first = jnp.min(s, axis=-1)
        better = s_first < best_s
        best_s = jnp.where(better, s_first, best_s)
        face = jnp.where(better, jnp.take_along_axis(faces, first[:, None], 1)[:, 0], face)
        ab = jnp.where(
            better[:, None], jnp.take_along_axis(ab_c, first[:, None, None], 1)[:, 0], ab
        )
        # Stackless next node in a complete heap: descend, or climb past right children
        # (strip the trailing one bits) and go to the sibling; 0 when the root is done.
        trailing_ones = jax.lax.population_count(idx ^ (idx + 1)) - 1
        up = jnp.right_shift(idx, trailing_ones)
        skip = jnp.where(up == 0, 0, up + 1)
        node = jnp.where(live, jnp.where(hit_box & ~is_leaf, 2 * idx, skip), 0)
        return node, best_s, face, ab

    # best_s starts just past the segment's end (segment_triangle's tolerance).
    init = (jnp.ones(n, jnp.int32), jnp.full(n, 1 + tol, dtype), jnp.full(n, -1, jnp.int32),
            jnp.zeros((n, 2), dtype))  # fmt: skip
    _, _, face, ab = jax.lax.while_loop(lambda st: jnp.any(st[0] > 0), body, init)
    return face, ab, face >= 0


# --------------------------------------------------------------------------- helpers


def _morton3(x: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of points in the unit cube (10 bits per axis, interleaved)."""
    q = np.clip((x * 1023).astype(np.int64), 0, 1023)

    def spread(v):
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        return (v | (v << 2)) & 0x09249249

    return (spread(q[:, 0]) << 2) | (spread(q[:, 1]) << 1) | spread(q[:, 2])


def _validate(mesh: SurfaceMesh, P, L):
    P, L = jnp.asarray(P), jnp.asarray(L)
    if P.shape[-1:] != (3,) or L.shape[-1:] != (3,):
        raise ValueError(f"P and L must have shape (..., 3), got {P.shape} and {L.shape}")
    try:
        shape = jnp.broadcast_shapes(P.shape, L.shape)
    except ValueError:
        raise ValueError(f"P {P.shape} and L {L.shape} do not broadcast together") from None
    for name, x in (("P", P), ("L", L)):
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
