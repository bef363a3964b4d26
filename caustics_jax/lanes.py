"""Lane batching shared by the solvers and the transport layer: padding to size classes,
chunked vmap, compaction of the lanes that need work, and scattering results back.

A "lane" is one receiver/light pair. jit compiles once per shape, so batches are padded
to a few size classes (`lane_bucket`) and meshes to power-of-two face and vertex counts
(`padded_mesh`). Host work here is numpy index bookkeeping, done once per call, outside
jit (DESIGN.md "Skipping what a scene does not need").
"""

from __future__ import annotations

import dataclasses
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .mesh import SurfaceMesh

#: Lanes per vmapped chunk of `map_lanes` (env `CAUSTICS_JAX_LANE_CHUNK`).
LANE_CHUNK = int(os.environ.get("CAUSTICS_JAX_LANE_CHUNK", 256))


def power_of_two_bucket(n: int, minimum: int = 256) -> int:
    """The smallest power of two `>= max(n, 1)`, at least `minimum`."""
    return max(minimum, 1 << (max(n, 1) - 1).bit_length())


def lane_bucket(n: int) -> int:
    """Lanes a batch is padded to: a power of two up to 4096 (at least 256), then a multiple
    of 4096 (at most 4% extra work above 100k lanes), so jit compiles once per size class."""
    return power_of_two_bucket(n, 256) if n <= 4096 else -(-n // 4096) * 4096


def map_lanes(fn, *args, chunk: int | None = None):
    """`vmap(fn)` over lanes, `chunk` lanes at a time (`lax.map` with `batch_size`).

    A vmapped while loop runs until its slowest lane ends: over 100k lanes one lane that
    needs 90 iterations (median 5) would hold up all of them. In chunks, each chunk stops
    at its own slowest lane.
    """
    chunk = LANE_CHUNK if chunk is None else chunk
    if args[0].shape[0] <= chunk:
        return jax.vmap(fn)(*args)
    return jax.lax.map(lambda a: fn(*a), args, batch_size=chunk)


def pad_lanes(P, L, start):
    """Pad lanes to `lane_bucket(N)` with copies of lane 0 marked `found = False` (a solver
    ends them at once). `start` is `(face, barycentric, found)`."""
    n = P.shape[0]
    extra = lane_bucket(n) - n
    if extra == 0:
        return P, L, start

    def pad(x, value=None):
        fill = jnp.broadcast_to(x[:1] if value is None else jnp.asarray(value, x.dtype),
                                (extra,) + x.shape[1:])
        return jnp.concatenate([x, fill])

    face, ab0, found = start
    return pad(P), pad(L), (pad(face), pad(ab0), pad(found, False))


def compact_index(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gather indices for the lanes `idx`, padded to `lane_bucket(len(idx))` with copies of
    `idx[0]` (one compile per size class), and the mask of the real ones."""
    k = idx.size
    g = np.concatenate([idx, np.full(lane_bucket(k) - k, idx[0], idx.dtype)])
    return g, np.arange(g.size) < k


def scatter_lanes(base, g: np.ndarray, keep: np.ndarray, sub):
    """`base` with lanes `g[keep]` replaced by the matching lanes of `sub` (pytrees)."""
    n = jax.tree.leaves(base)[0].shape[0]
    target = jnp.asarray(np.where(keep, g, n))  # n is out of bounds: dropped
    return jax.tree.map(lambda b, s: b.at[target].set(s.astype(b.dtype), mode="drop"), base, sub)


def padded_mesh(mesh: SurfaceMesh) -> SurfaceMesh:
    """The mesh padded to power-of-two face and vertex counts, so jit compiles once per bucket.

    The static `grid` layout is dropped (the solvers never read it; only start points do,
    and as a static field it would make every pool size its own compile). Padding faces
    are `(0, 0, 0)` with no neighbours and are never referenced by a real face's
    adjacency, so no walk can enter them; padding vertices are zeros.
    """
    F, V = mesh.faces.shape[0], mesh.vertices.shape[0]
    Fb, Vb = power_of_two_bucket(F), power_of_two_bucket(V)
    mesh = dataclasses.replace(mesh, grid=None)
    if (F, V) == (Fb, Vb):
        return mesh

    def pad(x, n, value):
        return jnp.concatenate([x, jnp.full((n - x.shape[0],) + x.shape[1:], value, x.dtype)])

    return eqx.tree_at(
        lambda m: (m.vertices, m.normals, m.faces, m.face_normals, m.neighbors, m.neighbor_edge),
        mesh,
        (pad(mesh.vertices, Vb, 0), pad(mesh.normals, Vb, 0), pad(mesh.faces, Fb, 0),
         pad(mesh.face_normals, Fb, 0), pad(mesh.neighbors, Fb, -1), pad(mesh.neighbor_edge, Fb, -1)),
    )


def padded_index(idx: np.ndarray, size: int) -> np.ndarray:
    """`idx` padded with its first entry (0 when empty) to `size` (one compile per size class)."""
    return np.concatenate([idx, np.full(size - len(idx), idx[0] if len(idx) else 0, idx.dtype)])
