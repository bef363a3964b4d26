"""Conservative culling of the faces that cannot hold a refraction point: bounding balls and
normal cones per patch of faces (the hierarchy of Walter et al. 2009, "Single scattering
in refractive media with triangle mesh boundaries", §4, applied to one receiver-light pair).

At a refraction point `M` Snell's law reads `n~ x H = 0` with the generalised half vector
`H = w_L + eta w_P` (math.md §1 and §4; `w_P`, `w_L` unit vectors from `M` to `P` and
`L`): `n~` is parallel to `H`. For a patch of faces inside a ball of centre `c` and radius
`r`, with `|P - c| = D_P > r`:

- `w_P` lies within the angle `asin(r / D_P)` of `c_P = (P - c) / D_P` (the cone of the
  ball seen from `P`), so `|w_P - c_P| <= 2 sin(asin(r / D_P) / 2)`; likewise `w_L`.
- Then `|H - H_c| <= delta = |w_L - c_L| + eta |w_P - c_P|` with `H_c = c_L + eta c_P`,
  and where `|H_c| > delta` the direction of `H` lies within `theta_H = asin(delta / |H_c|)`
  of `H_c`.
- `n~` at any point of a face is a convex combination of its unit vertex normals (seed
  001 eq. 6-8), so it lies in any convex cone that holds them: the patch's normal cone
  (axis `a`, half-angle `theta_n < pi / 2`).

So a patch with `angle(line H_c, line a) > theta_H + theta_n` holds no refraction point,
for any receiver and light position it is tested with: the test is exact geometry, not a
heuristic, and is made conservative for rounding by a margin (`_keep`). The hierarchy is
the start-point BVH's (`start_points.build_bvh`: Morton-ordered leaves, a complete binary
tree of boxes) with a normal cone per node; a lane descends only into children that pass.
The faces of the leaves that pass are tested once more with their own ball and cone.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..runtime.lanes import padded_index
from ..surface.mesh import SurfaceMesh
from .start_points import build_bvh

#: Faces per leaf of the patch tree.
LEAF_SIZE = 8
#: (lane, node) pairs per jitted test call (a power of 4).
CHUNK = 1 << 18


class PatchTree(NamedTuple):
    """Bounding balls and normal cones of a complete binary tree of face patches.

    Attributes:
        centre, radius: `(2 n_leaves, 3)`, `(2 n_leaves,)` ball of node `n` (heap index:
            root 1, children `2n, 2n + 1`, leaves `n_leaves ..`); radius `inf` for an empty
            node (it is always culled).
        axis, angle: `(2 n_leaves, 3)`, `(2 n_leaves,)` normal cone (unit axis, half-angle;
            `pi` where no cone below `pi / 2` holds the normals: never culled by it).
        leaf_faces: `(n_leaves, LEAF_SIZE)` face indices, -1 padding.
        face_centre, face_radius, face_axis, face_angle: the same per face.
        n_leaves: a power of two.
    """

    centre: np.ndarray
    radius: np.ndarray
    axis: np.ndarray
    angle: np.ndarray
    leaf_faces: np.ndarray
    face_centre: np.ndarray
    face_radius: np.ndarray
    face_axis: np.ndarray
    face_angle: np.ndarray
    n_leaves: int


def _cone(normals: np.ndarray, weights_mask: np.ndarray):
    """Axis and half-angle of the cone around the normalised mean of unit `normals`
    `(k, m, 3)` (masked by `weights_mask` `(k, m)`)."""
    s = np.sum(np.where(weights_mask[..., None], normals, 0), axis=1)
    length = np.linalg.norm(s, axis=-1, keepdims=True)
    axis = np.where(length > 0, s / np.where(length > 0, length, 1), [0.0, 0.0, 1.0])
    cos = np.clip(np.sum(normals * axis[:, None], -1), -1, 1)
    angle = np.max(np.where(weights_mask, np.arccos(cos), -np.inf), axis=1)
    angle = np.where(length[:, 0] > 0, angle, np.pi)
    return axis, angle


def _spread(c, a, live, axis):
    """Half-angle about `axis` of a cone `(c, a)` (-inf where not `live`)."""
    return np.where(live, np.arccos(np.clip(np.sum(c * axis, -1), -1, 1)) + a, -np.inf)


def build_patch_tree(mesh: SurfaceMesh) -> PatchTree:
    """The patch tree of `mesh` (numpy, outside jit; O(F log F))."""
    bvh = build_bvh(mesh, leaf_size=LEAF_SIZE)
    V = np.asarray(mesh.vertices, np.float64)
    Nv = np.asarray(mesh.normals, np.float64)
    Nv = Nv / np.linalg.norm(Nv, axis=-1, keepdims=True)
    F = np.asarray(mesh.faces)
    T, TN = V[F], Nv[F]
    face_centre = T.mean(1)
    face_radius = np.linalg.norm(T - face_centre[:, None], axis=-1).max(1)
    face_axis, face_angle = _cone(TN, np.ones(TN.shape[:2], bool))
    lo, hi = np.asarray(bvh.lo, np.float64), np.asarray(bvh.hi, np.float64)
    empty = ~np.all(lo <= hi, axis=-1)
    lo, hi = np.where(empty[:, None], 0.0, lo), np.where(empty[:, None], 0.0, hi)
    centre = (lo + hi) / 2
    radius = np.where(empty, np.inf, np.linalg.norm(hi - lo, axis=-1) / 2)
    n_leaves = bvh.n_leaves
    leaf_faces = np.asarray(bvh.leaf_faces)
    # Leaf cones from the vertex normals of their faces; inner cones enclose the children's.
    used = leaf_faces >= 0
    leaf_normals = TN[np.maximum(leaf_faces, 0)].reshape(n_leaves, -1, 3)
    leaf_axis, leaf_angle = _cone(leaf_normals, np.repeat(used, 3, axis=1))
    axis = np.zeros((2 * n_leaves, 3))
    angle = np.full(2 * n_leaves, np.pi)
    axis[n_leaves:], angle[n_leaves:] = leaf_axis, np.where(used.any(1), leaf_angle, -np.inf)
    for level_start in [n_leaves >> k for k in range(1, n_leaves.bit_length())]:
        nodes = np.arange(level_start, 2 * level_start)
        ca, cb = axis[2 * nodes], axis[2 * nodes + 1]
        aa, ab_ = angle[2 * nodes], angle[2 * nodes + 1]
        live_a, live_b = np.isfinite(aa) & (aa >= 0), np.isfinite(ab_) & (ab_ >= 0)
        s = np.where(live_a[:, None], ca, 0) + np.where(live_b[:, None], cb, 0)
        length = np.linalg.norm(s, axis=-1, keepdims=True)
        ax = np.where(length > 0, s / np.where(length > 0, length, 1), [0.0, 0.0, 1.0])
        ang = np.maximum(_spread(ca, aa, live_a, ax), _spread(cb, ab_, live_b, ax))
        axis[nodes] = ax
        angle[nodes] = np.where(length[:, 0] > 0, ang, np.pi)
    angle = np.where(np.isneginf(angle), np.pi, angle)  # empty nodes: culled by radius
    return PatchTree(centre, radius, axis, np.minimum(angle, np.pi), leaf_faces, face_centre,
                     face_radius, face_axis, face_angle, n_leaves)


_CACHE: dict[int, tuple[weakref.ref, PatchTree]] = {}


def patch_tree(mesh: SurfaceMesh) -> PatchTree:
    """`build_patch_tree(mesh)`, cached per mesh object (like `prepared.prepare`)."""
    key = id(mesh)
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is mesh:
        return hit[1]
    tree = build_patch_tree(mesh)

    def forget(_ref, key: int = key) -> None:
        _CACHE.pop(key, None)

    _CACHE[key] = (weakref.ref(mesh, forget), tree)
    return tree


def may_refract(centre, radius, axis, angle, P, L, eta):
    """False only where no point of the ball `(centre, radius)` with a normal in the cone
    `(axis, angle)` can refract `P -> M -> L` (module docstring). Broadcasts."""
    dtype = centre.dtype
    eps = jnp.finfo(dtype).eps
    eta = jnp.asarray(eta, dtype)

    def cone_of(X):
        v = X - centre
        D = jnp.linalg.norm(v, axis=-1)
        ok = D > radius * (1 + 64 * eps) + jnp.finfo(dtype).tiny
        c = v / jnp.where(ok, D, 1)[..., None]
        sin_t = jnp.where(ok, radius / jnp.where(ok, D, 1), 1)
        chord = 2 * jnp.sin(jnp.arcsin(jnp.clip(sin_t, 0, 1)) / 2)
        return c, chord, ok

    c_P, chord_P, ok_P = cone_of(P)
    c_L, chord_L, ok_L = cone_of(L)
    H = c_L + eta * c_P
    H_len = jnp.linalg.norm(H, axis=-1)
    delta = (chord_L + eta * chord_P) * (1 + 64 * eps) + 64 * eps * (1 + eta)
    bounded = ok_P & ok_L & (H_len > delta)
    theta_H = jnp.arcsin(jnp.clip(delta / jnp.where(bounded, H_len, 1), 0, 1))
    total = theta_H + angle + 1e3 * eps
    cos_alpha = jnp.abs(jnp.sum(H * axis, -1)) / jnp.where(bounded, H_len, 1)
    cull = bounded & (total < jnp.pi / 2) & (cos_alpha < jnp.cos(total) - 64 * eps)
    return ~cull & jnp.isfinite(radius)


@jax.jit
def _test_nodes(centre, radius, axis, angle, P, L, lane, node, eta):
    return may_refract(centre[node], radius[node], axis[node], angle[node], P[lane], L[lane], eta)


def _bucket(k: int) -> int:
    """Rows a test call is padded to: a power of 4 from 1024 (few compiled sizes)."""
    size = 1024
    while size < k:
        size *= 4
    return size


def _batched(fn, n: int, *args):
    """`fn(*args, index_chunk)` over `range(n)` in padded chunks; concatenated bool mask."""
    out = []
    for i in range(0, n, CHUNK):
        k = min(CHUNK, n - i)
        sel = padded_index(np.arange(i, i + k), _bucket(k))
        out.append(np.asarray(fn(sel))[:k])
    return np.concatenate(out) if out else np.zeros(0, bool)


def candidate_faces(mesh: SurfaceMesh, P, L, eta, lanes: np.ndarray | None = None):
    """`(lane, face)` pairs that may hold a refraction point, by descending the patch tree
    (host loop over levels, one jitted test per level). `P`, `L` `(N, 3)` device arrays;
    `lanes` optionally restricts the search to those lane indices."""
    tree = patch_tree(mesh)
    dtype = P.dtype
    dev = [jnp.asarray(x, dtype) for x in (tree.centre, tree.radius, tree.axis, tree.angle)]
    lane = np.arange(P.shape[0]) if lanes is None else np.asarray(lanes)
    node = np.ones(len(lane), np.int64)
    while True:
        keep = _batched(lambda s, lane=lane, node=node: _test_nodes(
            *dev, P, L, jnp.asarray(lane[s]), jnp.asarray(node[s]), eta), len(lane))
        lane, node = lane[keep], node[keep]
        if node.size == 0 or node[0] >= tree.n_leaves:
            break
        lane = np.repeat(lane, 2)
        node = 2 * np.repeat(node, 2) + np.tile([0, 1], node.size)
    faces = tree.leaf_faces[node - tree.n_leaves] if node.size else np.zeros((0, LEAF_SIZE), np.int64)
    lane = np.repeat(lane, LEAF_SIZE)
    faces = faces.reshape(-1)
    lane, faces = lane[faces >= 0], faces[faces >= 0]
    fdev = [jnp.asarray(x, dtype) for x in (tree.face_centre, tree.face_radius, tree.face_axis, tree.face_angle)]
    keep = _batched(lambda s: _test_nodes(*fdev, P, L, jnp.asarray(lane[s]), jnp.asarray(faces[s]), eta),
                    len(lane))
    return lane[keep].astype(np.int32), faces[keep].astype(np.int32)
