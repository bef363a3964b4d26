"""Lane batching shared by the solvers and the transport layer: fixed-size blocks spread
over every local device, the slot-pool scheduler, work on compacted lanes, chunked vmap,
and scattering results back.

A "lane" is one receiver/light pair. jit compiles once per shape, so the solvers see
lanes only in blocks of a fixed size (`block_lanes` per device, `run_blocks`, the last
block padded with lanes that need no work) and meshes padded to power-of-two face and
vertex counts (`padded_mesh`): one compile per method, dtype and mesh size class,
whatever the lane count. A block is split over all local devices (`on_devices`,
`shard_map`, the mesh replicated); each device runs its own lanes.

Inside a block, a vmapped `while_loop` runs until its slowest lane ends. `run_pool`
avoids that waste: a fixed pool of slots (`pool_slots`, sized to the backend) steps the
lanes in flight, and a slot whose lane ended takes the next unfinished lane from a queue,
so every step advances `slots` live lanes until the queue is empty. Work that few lanes
need (`map_where`) runs on the compacted lanes that need it, in chunks, so its cost is
proportional to those lanes. `map_lanes` (fixed chunks, each until its slowest lane)
is the previous scheduler, kept for comparison (`Walk(scheduler="chunked")`).

Host work here is numpy index bookkeeping, done once per call, outside jit (DESIGN.md
"Skipping what a scene does not need").
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .compilation import jit, xla_options
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


# --------------------------------------------------------------------------- slot pool


def pool_slots(platform: str | None = None) -> int:
    """Lanes in flight per device in `run_pool` (env `CAUSTICS_JAX_POOL_SLOTS`).

    CPU: 256, the chunk width of `map_lanes`, so both schedulers run the same vmapped
    step and give the same results (the 4096 lanes of `tests/test_scheduling.py` bit-identical,
    also on an AVX-512 CPU; lanes that `map_where` compacts may round differently by a few
    eps, `testing.assert_same_lanes`; XLA CPU vectorises wider steps differently:
    1024 slots moved float32 points by up to 1.5e-4 of a barycentric unit, and ran
    slower). GPU: 512 lanes per streaming multiprocessor (`core_count`; 65536 when the
    backend does not report it), enough resident lanes to hide memory latency; TPU: 8192.
    """
    env = os.environ.get("CAUSTICS_JAX_POOL_SLOTS")
    if env:
        return int(env)
    device = jax.local_devices()[0] if platform is None else None
    platform = platform or device.platform
    if platform in ("gpu", "cuda", "rocm"):
        cores = getattr(device, "core_count", None) if device is not None else None
        return 512 * int(cores) if cores else 65536
    return 8192 if platform == "tpu" else 256


def block_lanes(platform: str | None = None) -> int:
    """Lanes per device in one call of a compiled solver (env `CAUSTICS_JAX_BLOCK_LANES`):
    128 pools' worth (32768 on CPU), so the pool drains (its slowest lanes finish with
    part of the slots idle) once per 128 pool-loads of lanes; padding lanes cost nothing
    but their share of the block's O(lanes) bookkeeping."""
    env = os.environ.get("CAUSTICS_JAX_BLOCK_LANES")
    if env:
        return int(env)
    return 128 * pool_slots(platform)


def _rows(tree, idx):
    """Rows `idx` of every leaf (`idx` clipped into range: callers mask the rest)."""
    n = jax.tree.leaves(tree)[0].shape[0]
    return jax.tree.map(lambda x: x[jnp.clip(idx, 0, n - 1)], tree)


def _select(mask, new, old):
    """Per lane `new` where `mask` else `old`, for pytrees with a leading lane axis."""
    return jax.tree.map(lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, old)


class _Packing:
    """A pytree of per-lane arrays as one `(lanes, width)` matrix per dtype (bools as
    int32), so that moving lanes in and out of a pool's slots is a few gathers and
    scatters instead of one per leaf (the walk's lane state has about 50 leaves; each
    gather or scatter is its own kernel to compile and run). Exact: only data moves."""

    def __init__(self, tree):
        leaves, self.treedef = jax.tree.flatten(tree)
        self.kinds = [jnp.dtype(jnp.int32) if x.dtype == jnp.bool_ else x.dtype for x in leaves]
        self.groups = list(dict.fromkeys(self.kinds))
        self.layout, widths = [], dict.fromkeys(self.groups, 0)
        for x, kind in zip(leaves, self.kinds, strict=True):
            size = int(np.prod(x.shape[1:], dtype=np.int64))
            self.layout.append((kind, widths[kind], size, x.shape[1:], x.dtype))
            widths[kind] += size

    def pack(self, tree) -> tuple:
        leaves = jax.tree.leaves(tree)
        n = leaves[0].shape[0]
        parts: dict = {g: [] for g in self.groups}
        for x, kind in zip(leaves, self.kinds, strict=True):
            parts[kind].append(x.reshape(n, -1).astype(kind))
        return tuple(jnp.concatenate(parts[g], axis=1) for g in self.groups)

    def unpack(self, packed: tuple):
        mats = dict(zip(self.groups, packed, strict=True))
        leaves = [mats[kind][:, lo:lo + size].reshape(mats[kind].shape[:1] + shape).astype(dtype)
                  for kind, lo, size, shape, dtype in self.layout]
        return jax.tree.unflatten(self.treedef, leaves)


def run_pool(step, states, running, slots: int):
    """Step every running lane until it ends, `slots` lanes at a time (inside jit).

    `states`: a pytree of per-lane states with a leading lane axis `n`; `running` `(n,)`:
    the lanes that need steps (the others are returned unchanged). `step(state) ->
    (state, done)` advances one lane (vmapped over the slots). A slot whose lane is done
    writes it back and takes the next running lane from the queue; the loop ends when the
    queue is empty and every slot is idle. Each lane sees exactly the `step` calls it
    would see alone, so the results are those of a per-lane `while_loop`; the vmapped
    step runs on `slots` lanes in flight (idle slots only in the final drain), instead
    of a chunk waiting for its slowest lane.
    """
    n = running.shape[0]
    slots = min(slots, n)
    queue = jnp.nonzero(running, size=n, fill_value=n)[0].astype(jnp.int32)  # n: none left
    lane = queue[:slots]
    packing = _Packing(states)

    def body(carry):
        states, lane, slot, head = carry
        stepped, done = jax.vmap(step)(packing.unpack(slot))
        slot = packing.pack(stepped)
        finished = (lane < n) & done
        states = tuple(x.at[jnp.where(finished, lane, n)].set(s, mode="drop") for x, s in zip(states, slot,
                                                                                              strict=True))
        pos = head + jnp.cumsum(finished, dtype=jnp.int32) - 1  # queue position of each refill
        refill = jnp.where(pos < n, queue[jnp.clip(pos, 0, n - 1)], n)
        lane = jnp.where(finished, refill, lane)
        slot = _select(finished, _rows(states, lane), slot)
        return states, lane, slot, head + jnp.sum(finished, dtype=jnp.int32)

    packed = packing.pack(states)
    carry = (packed, lane, _rows(packed, lane), jnp.int32(slots))
    return packing.unpack(jax.lax.while_loop(lambda c: jnp.any(c[1] < n), body, carry)[0])


def run_pools(steps: tuple, route, states, slots: int, after=None):
    """`run_pool` with one pool per kind of step: a lane runs in the pool its state routes
    it to, so each step computes only its own branch (inside jit).

    `steps[k](state) -> state` is the step of pool `k`; `route(state)` is the pool a lane
    needs next (int32 in `[0, len(steps))`), or -1 once it is done. Each pool has `slots`
    slots and a ring-buffer queue of the lanes routed to it; after every trip the lanes
    whose route changed are written back and queued for their next pool (or leave when
    done), and every pool refills its free slots from its queue. A pool without a busy
    slot skips its step (`lax.cond`). A lane sees the same sequence of steps as in a
    per-lane loop that branches on its state, so the results are those of that loop; a
    branch that few lanes need costs only those lanes' slots.

    `after(state) -> state`, if given, runs on every slot after each pool's step, on the
    step's stored output (the branch's result): per lane the same as
    `after(steps[k](state))`, but what `after` reads from the step is computed once rather
    than copied by XLA's fusion into each output field's kernel. It must leave a state it
    does not apply to unchanged (idle slots pass through it too).
    """
    n = jax.tree.leaves(states)[0].shape[0]
    K = len(steps)
    slots = min(slots, n)
    first = jax.vmap(route)(states)
    packing = _Packing(states)
    states = packing.pack(states)
    bufs, tails, lanes_ = [], [], []
    for k in range(K):
        members = first == k
        bufs.append(jnp.nonzero(members, size=n, fill_value=n)[0].astype(jnp.int32))
        tails.append(jnp.sum(members, dtype=jnp.int32))
        lanes_.append(jnp.where(jnp.arange(slots) < tails[k], bufs[k][:slots], n))
    heads = [jnp.minimum(jnp.int32(slots), t) for t in tails]
    carry = (states, tuple(bufs), tuple(heads), tuple(tails), tuple(lanes_),
             tuple(_rows(states, lane) for lane in lanes_))

    def cond(c):
        _, _, heads, tails, lanes_, _ = c
        return jnp.any(jnp.stack([jnp.any(lane < n) for lane in lanes_]
                                 + [h < t for h, t in zip(heads, tails, strict=True)]))

    def body(c):
        states, (bufs, heads, tails, lanes_, slot_states) = c[0], (list(x) for x in c[1:])
        for k in range(K):
            busy = lanes_[k] < n
            stepped = jax.lax.cond(jnp.any(busy), lambda s, k=k: packing.pack(jax.vmap(steps[k])(packing.unpack(s))),
                                   lambda s: s, slot_states[k])
            if after is not None:
                stepped = packing.pack(jax.vmap(after)(packing.unpack(stepped)))
            to = jax.vmap(route)(packing.unpack(stepped))
            leave = busy & (to != k)
            target = jnp.where(leave, lanes_[k], n)  # n: dropped
            states = tuple(x.at[target].set(s, mode="drop") for x, s in zip(states, stepped, strict=True))
            for j in range(K):
                if j == k:
                    continue
                move = leave & (to == j)
                pos = (tails[j] + jnp.cumsum(move, dtype=jnp.int32) - 1) % n
                bufs[j] = bufs[j].at[jnp.where(move, pos, n)].set(lanes_[k], mode="drop")
                tails[j] = tails[j] + jnp.sum(move, dtype=jnp.int32)
            lanes_[k] = jnp.where(leave, n, lanes_[k])
            slot_states[k] = stepped
        for k in range(K):
            free = lanes_[k] >= n
            pos = heads[k] + jnp.cumsum(free, dtype=jnp.int32) - 1
            fill = free & (pos < tails[k])
            lanes_[k] = jnp.where(fill, bufs[k][pos % n], lanes_[k])
            heads[k] = heads[k] + jnp.minimum(jnp.sum(free, dtype=jnp.int32), tails[k] - heads[k])
            slot_states[k] = _select(fill, _rows(states, lanes_[k]), slot_states[k])
        return states, tuple(bufs), tuple(heads), tuple(tails), tuple(lanes_), tuple(slot_states)

    return packing.unpack(jax.lax.while_loop(cond, body, carry)[0])


def map_where(fn, need, out, *args, chunk: int):
    """`out` with lanes `need` replaced by `vmap(fn)(*args)` at those lanes (inside jit).

    Computed on the compacted lanes that need it, `chunk` at a time, in a loop of
    `ceil(count / chunk)` trips: the cost is proportional to the lanes that need `fn`, not
    to the batch (a rare branch under a plain `vmap` is paid by every lane). `out` and
    `args` move as one matrix per dtype (`_Packing`): one scatter and one gather per
    dtype per trip, not one per leaf. `out=None`: zeros of `fn`'s output where `need` is
    False. `fn` is traced once either way (the loop body reuses the trace that gave the
    output's shape: a second trace of a large `fn` costs seconds of a first call).
    """
    n = need.shape[0]
    idx = jnp.nonzero(need, size=n, fill_value=n)[0].astype(jnp.int32)
    idx = jnp.concatenate([idx, jnp.full(chunk, n, jnp.int32)])
    trips = (jnp.sum(need, dtype=jnp.int32) + chunk - 1) // chunk

    arg_packing = _Packing(args)
    packed_args = arg_packing.pack(args)  # once, outside the loop
    batched = jax.jit(jax.vmap(fn))  # a nested jit caches its trace by argument shapes

    def apply(sel):
        return batched(*arg_packing.unpack(_rows(packed_args, sel)))

    if out is None:
        shapes = jax.eval_shape(apply, idx[:chunk])
        out = jax.tree.map(lambda x: jnp.zeros((n, *x.shape[1:]), x.dtype), shapes)
    packing = _Packing(out)

    def body(i, packed):
        res = apply(sel := jax.lax.dynamic_slice(idx, (i * chunk,), (chunk,)))
        res = jax.tree.map(lambda o, r: r.astype(o.dtype), out, res)
        return tuple(o.at[sel].set(r, mode="drop") for o, r in zip(packed, packing.pack(res), strict=True))

    return packing.unpack(jax.lax.fori_loop(0, trips, body, packing.pack(out)))


# --------------------------------------------------------------------------- devices and blocks


#: Most CPU devices `use_cpu_devices("all")` makes: a block holds `block_lanes()` lanes per
#: device (262,144 at 8), and optimistix Newton compiles its program once per device.
MAX_AUTO_CPU_DEVICES = 8


def max_cpu_devices() -> int:
    """The most CPU devices `use_cpu_devices` accepts: `max(64, os.cpu_count())`. More
    devices than cores only pad every batch further (a block of lanes per device) and
    compile optimistix Newton once more per device; 1000 had started a 100k-lane
    comparison padded to 32M lanes."""
    return max(64, os.cpu_count() or 1)


def use_cpu_devices(count: int | str) -> int:
    """Split the host CPU into `count` JAX devices (`"all"`: one per core, `os.cpu_count()`,
    at most `MAX_AUTO_CPU_DEVICES`),
    so that `on_devices` runs a share of every block on each core. Call it before JAX runs
    anything (it sets `jax_num_cpu_devices`, which JAX reads when its CPU backend starts);
    `caustics-jax compare --cpu-devices` and `make demo` do. Why: XLA runs one CPU device's
    program on one thread (an op is split over threads only when it is large), and the
    solvers' loops step a few hundred lanes at a time, so one device keeps one core busy.
    Measured on the 2-core CPU, 65,536 lanes of the default pool (float32): walk 93k -> 203k
    solves/s, one-step Newton 352k -> 690k with two devices; per-lane results are identical
    (`tests/test_devices.py`). Returns the device count; a `ValueError` when `count` is not
    a positive integer or `"all"`, or when the CPU backend already started with another
    count (a fresh process is needed)."""
    n = min(os.cpu_count() or 1, MAX_AUTO_CPU_DEVICES) if count == "all" else count
    limit = max_cpu_devices()
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= limit:
        raise ValueError(f"cpu devices must be a positive integer or 'all', at most {limit} (max(64, the CPU's "
                         f"{os.cpu_count()} cores): each device holds a block of lanes), got {count!r}")
    # The backend may have started already: then it is accepted below if the count matches.
    with contextlib.suppress(RuntimeError):
        jax.config.update("jax_num_cpu_devices", int(n))
    try:
        have = len(jax.devices("cpu"))
    except RuntimeError:
        raise ValueError("JAX has no CPU backend in this process (JAX_PLATFORMS excludes cpu)") from None
    if have != n:
        raise ValueError(f"JAX's CPU backend already started with {have} device(s); {n} CPU devices must be "
                         "requested before JAX runs anything (a fresh process)")
    return int(n)


@functools.cache
def lane_mesh(devices: tuple | None = None) -> Mesh:
    """A one-axis device mesh (`"lanes"`) over `devices` (default: every local device)."""
    return Mesh(np.array(devices if devices is not None else jax.local_devices()), ("lanes",))


def lanes_per_block() -> int:
    """Lanes in one block: `block_lanes()` per local device."""
    return block_lanes() * len(jax.local_devices())


@functools.cache
def _compiled(fn, static, n_shared: int, n_lanes: int, devices: tuple, spmd: bool, options: tuple):
    # `options`: the XLA options in force (`compilation.xla_options()`), part of the key.
    def program(*args):
        return fn(*args, static)

    platform = devices[0].platform
    if len(devices) == 1 or not spmd:
        return jit(program, platform)
    specs = (PartitionSpec(),) * n_shared + (PartitionSpec("lanes"),) * n_lanes
    return jit(jax.shard_map(program, mesh=lane_mesh(devices), in_specs=specs,
                             out_specs=PartitionSpec("lanes"), check_vma=False), platform)


def on_devices(fn, static, shared: tuple, lanes: tuple, *, spmd: bool = True):
    """`fn(*shared, *lanes, static)` with the lane arrays split over every local device
    (`shared`, e.g. the mesh and traced options, replicated; `static` a hashable argument).

    One device: a plain jit. Several: one SPMD program (`shard_map` over `lane_mesh()`,
    compiled once) in which each device runs its contiguous share of the lanes with its
    own loops (no device waits for another's lanes before the block ends), so per-lane
    results do not depend on the device count. `spmd=False` is for programs `shard_map`
    cannot trace: optimistix 0.1.0's linear solves fail under `shard_map` in this JAX
    (lineax compares the shardings of its structures, "pytree does not match
    out_structure"); those run the same jitted program once per device on its share
    (`jax.sharding` places the shares; one compile per device). The lane count must be a
    multiple of the device count (`run_blocks` makes it so).
    """
    devices = tuple(jax.local_devices())
    program = _compiled(fn, static, len(shared), len(lanes), devices, spmd, tuple(sorted(xla_options().items())))
    if len(devices) == 1 or spmd:
        return program(*shared, *lanes)
    sharding = NamedSharding(lane_mesh(devices), PartitionSpec("lanes"))
    lanes = [jax.device_put(x, sharding) for x in lanes]
    shares = [{s.device: s.data for s in x.addressable_shards} for x in lanes]
    outs = [program(*jax.device_put(shared, d), *(share[d] for share in shares)) for d in devices]

    def assemble(*parts):
        shape = (sum(p.shape[0] for p in parts),) + parts[0].shape[1:]
        return jax.make_array_from_single_device_arrays(shape, sharding, list(parts))

    return jax.tree.map(assemble, *outs)


def run_blocks(fn, lanes: tuple, fill: tuple, size: int | None = None):
    """`fn(*block)` over consecutive blocks of `size` lanes (default `lanes_per_block()`),
    the last one padded with the rows `fill` (lanes that need no work); returns the
    outputs as numpy arrays of the original lane count.

    `lanes` are numpy arrays with a leading lane axis. `fn` sees only one shape, so a new
    lane count compiles nothing. Blocks are dispatched before any result is read back,
    so host work for one block overlaps the device work of the previous one.
    """
    size = lanes_per_block() if size is None else size
    n = lanes[0].shape[0]
    outs = []
    for lo in range(0, max(n, 1), size):
        block = []
        for x, f in zip(lanes, fill, strict=True):
            part = x[lo:lo + size]
            if part.shape[0] < size:
                pad = np.broadcast_to(np.asarray(f, x.dtype), (size - part.shape[0],) + x.shape[1:])
                part = np.concatenate([part, pad])
            block.append(part)
        outs.append(fn(*block))
    return jax.tree.map(lambda *xs: np.concatenate([np.asarray(x) for x in xs])[:n], *outs)
