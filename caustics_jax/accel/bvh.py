"""A bounding-volume hierarchy over any mesh's faces: the general (reference) path of the
surface queries, for meshes the cell traversal (`face_cells.py`) cannot serve well.

Built in numpy outside jit (`build_bvh`: faces sorted along a Morton curve of their
centroids, grouped in leaves of `leaf_size`, a complete binary tree of boxes over the
leaves; O(F log F) build, O(F) memory), traversed stacklessly inside jit (a complete
tree's next node is a bit trick). Expected O(log F) boxes per segment for surfaces like
water, O(F) worst case; closest-hit pruning keeps the first crossing exact.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..math.crossing import clip_to_box, finite_segments, first_of, triangle_crossing
from ..runtime.precision import check_mesh_dtype
from ..surface.mesh import SurfaceMesh


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
    check_mesh_dtype(mesh.dtype)
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


def first_hit_bvh(mesh: SurfaceMesh, bvh: FaceBVH, A: Float[Array, "n 3"], B: Float[Array, "n 3"],
                  exclude: Int[Array, " n"] | None = None, *, s_lo: float = 0.0, s_hi: float = 1.0,
                  widen: bool):  # fmt: skip
    """`face_cells.first_hit_cells` (same window, exclusion and returns) by BVH traversal."""
    check_mesh_dtype(mesh.dtype)
    return _first_hit_bvh(mesh.vertices, mesh.faces, bvh, A, B, exclude, float(s_lo), float(s_hi), widen)


@eqx.filter_jit
def _first_hit_bvh(vertices, mesh_faces, bvh, P, B, exclude, s_lo, s_hi, widen):
    P, B = finite_segments(P, B)
    d = B - P
    exclude = jnp.full(P.shape[0], -1, jnp.int32) if exclude is None else exclude
    dtype = P.dtype
    n = P.shape[0]
    eps = jnp.finfo(dtype).eps
    n_leaves = bvh.n_leaves
    margin = 1 if widen else -1
    # Boxes are pruned against the best crossing so far, plus the rounding of `s`.
    slack = 64 * eps * (1 + abs(s_hi))

    def body(state):
        node, best, s_best, face, ab = state
        live = node > 0
        idx = jnp.maximum(node, 1)
        s_in, s_out = clip_to_box(P, d, bvh.lo[idx], bvh.hi[idx], jnp.minimum(best, s_hi) + slack)
        # Padding leaves have empty boxes (lo > hi), which a slab test alone would accept.
        nonempty = jnp.all(bvh.lo[idx] <= bvh.hi[idx], axis=-1)
        hit_box = live & nonempty & (s_in <= s_out)
        is_leaf = idx >= n_leaves
        # Leaf: test its faces (all lanes compute, masked; padding faces never hit).
        leaf = jnp.where(is_leaf, idx - n_leaves, 0)
        faces = bvh.leaf_faces[leaf]
        V = vertices[mesh_faces[jnp.maximum(faces, 0)]]
        c = triangle_crossing(P[:, None], d[:, None], V)
        hit = (c.inside & (faces >= 0) & (faces != exclude[:, None]) & (hit_box & is_leaf)[:, None]
               & (c.s >= s_lo - margin * c.s_tol) & (c.s <= s_hi + margin * c.s_tol))  # fmt: skip
        r_first, f_first, ab_first, s_first = first_of(c.rank(), hit, faces, c.ab, c.s)
        better = r_first < best
        best = jnp.where(better, r_first, best)
        s_best = jnp.where(better, s_first, s_best)
        face = jnp.where(better, f_first, face)
        ab = jnp.where(better[:, None], ab_first, ab)
        # Stackless next node in a complete heap: descend, or climb past right children
        # (strip the trailing one bits) and go to the sibling; 0 when the root is done.
        trailing_ones = jax.lax.population_count(idx ^ (idx + 1)) - 1
        up = jnp.right_shift(idx, trailing_ones)
        skip = jnp.where(up == 0, 0, up + 1)
        node = jnp.where(live, jnp.where(hit_box & ~is_leaf, 2 * idx, skip), 0)
        return node, best, s_best, face, ab

    inf = jnp.full(n, jnp.inf, dtype)
    init = (jnp.ones(n, jnp.int32), inf, inf, jnp.full(n, -1, jnp.int32), jnp.zeros((n, 2), dtype))
    _, _, s_best, face, ab = jax.lax.while_loop(lambda st: jnp.any(st[0] > 0), body, init)
    return face, ab, s_best


def _morton3(x: np.ndarray) -> np.ndarray:
    """30-bit Morton codes of points in the unit cube (10 bits per axis, interleaved)."""
    q = np.clip((x * 1023).astype(np.int64), 0, 1023)

    def spread(v):
        v = (v | (v << 16)) & 0x030000FF
        v = (v | (v << 8)) & 0x0300F00F
        v = (v | (v << 4)) & 0x030C30C3
        return (v | (v << 2)) & 0x09249249

    return (spread(q[:, 0]) << 2) | (spread(q[:, 1]) << 1) | spread(q[:, 2])


__all__ = ["FaceBVH", "build_bvh", "first_hit_bvh"]
