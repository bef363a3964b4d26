"""Lanes: one receiver/light pair each. Their shapes and bookkeeping, shared by every layer
above: size classes (`lane_bucket`: jit compiles once per class), padding, compaction
and scattering back, chunked vmap, and a pytree of per-lane arrays packed as one matrix
per dtype (`LanePacking`) so that moving lanes is a few gathers and scatters.

Host work here is numpy index bookkeeping, done once per call, outside jit (DESIGN.md
"Skipping what a scene does not need"). The schedulers are `pools` (slot pools) and
`blocks` (blocks over devices).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np

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


def padded_index(idx: np.ndarray, size: int) -> np.ndarray:
    """`idx` padded with its first entry (0 when empty) to `size` (one compile per size class)."""
    return np.concatenate([idx, np.full(size - len(idx), idx[0] if len(idx) else 0, idx.dtype)])


def take_rows(tree, idx):
    """Rows `idx` of every leaf (`idx` clipped into range: callers mask the rest)."""
    n = jax.tree.leaves(tree)[0].shape[0]
    return jax.tree.map(lambda x: x[jnp.clip(idx, 0, n - 1)], tree)


def select_lanes(mask, new, old):
    """Per lane `new` where `mask` else `old`, for pytrees with a leading lane axis."""
    return jax.tree.map(lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, old)


class LanePacking:
    """A pytree of per-lane arrays as one `(lanes, width)` matrix per dtype, so that moving
    lanes in and out of a pool's slots is a few gathers and scatters instead of one per
    leaf (the walk's lane state has about 50 leaves; each gather or scatter is its own
    kernel to compile and run). Booleans travel as the bits of int32 columns, 32 to a
    column: a solver keeps its decisions as named boolean fields, and they move, and are
    stored, as one word (XLA:CPU computes the word in one kernel, where it gave each
    boolean column a kernel of its own). Exact: only data moves."""

    _BITS = 32

    def __init__(self, tree):
        leaves, self.treedef = jax.tree.flatten(tree)
        self.kinds = [jnp.dtype(jnp.int32) if x.dtype == jnp.bool_ else x.dtype for x in leaves]
        self.groups = list(dict.fromkeys(self.kinds))
        self.layout, widths = [], dict.fromkeys(self.groups, 0)
        bit = 0  # booleans: bit `bit % 32` of the int32 columns after the int32 leaves'
        for x, kind in zip(leaves, self.kinds, strict=True):
            size = int(np.prod(x.shape[1:], dtype=np.int64))
            if x.dtype == jnp.bool_:
                self.layout.append((kind, bit, size, x.shape[1:], x.dtype))
                bit += size
            else:
                self.layout.append((kind, widths[kind], size, x.shape[1:], x.dtype))
                widths[kind] += size
        self.bits = bit
        self.bit_base = widths.get(jnp.dtype(jnp.int32), 0)  # the first bit column's index

    def pack(self, tree) -> tuple:
        leaves = jax.tree.leaves(tree)
        n = leaves[0].shape[0]
        parts: dict = {g: [] for g in self.groups}
        bools = []
        for x, kind in zip(leaves, self.kinds, strict=True):
            if x.dtype == jnp.bool_:
                bools.append(x.reshape(n, -1))
            else:
                parts[kind].append(x.reshape(n, -1).astype(kind))
        columns = [b[:, i].astype(jnp.int32) for b in bools for i in range(b.shape[1])]
        for lo in range(0, self.bits, self._BITS):
            word = columns[lo]
            for j in range(1, min(self._BITS, self.bits - lo)):  # element-wise: one fused kernel
                word = word | (columns[lo + j] << j)
            parts[jnp.dtype(jnp.int32)].append(word[:, None])
        return tuple(jnp.concatenate(parts[g], axis=1) if parts[g] else jnp.zeros((n, 0), g) for g in self.groups)

    def unpack(self, packed: tuple):
        mats = dict(zip(self.groups, packed, strict=True))
        leaves = []
        for kind, lo, size, shape, dtype in self.layout:
            mat = mats[kind]
            if dtype == jnp.bool_:
                idx = lo + np.arange(size)
                words = mat[:, self.bit_base + idx // self._BITS]
                bits = (words >> jnp.asarray(idx % self._BITS, jnp.int32)) & 1
                leaves.append((bits != 0).reshape(mat.shape[:1] + shape))
            else:
                leaves.append(mat[:, lo:lo + size].reshape(mat.shape[:1] + shape).astype(dtype))
        return jax.tree.unflatten(self.treedef, leaves)
