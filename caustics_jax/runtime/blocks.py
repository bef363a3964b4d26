"""Blocks of lanes over devices: a compiled solver sees lanes only in blocks of a fixed
size (`block_lanes` per device, `run_blocks`, the last block padded with lanes that need
no work), and a block is split over all local devices (`on_devices`, `shard_map`, the
mesh replicated); each device runs its own lanes. One compile per method, dtype and mesh
size class, whatever the lane count.
"""

from __future__ import annotations

import contextlib
import functools
import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .compilation import jit, xla_options
from .pools import pool_slots


def block_lanes(platform: str | None = None) -> int:
    """Lanes per device in one call of a compiled solver (env `CAUSTICS_JAX_BLOCK_LANES`):
    128 pools' worth (32768 on CPU), so the pool drains (its slowest lanes finish with
    part of the slots idle) once per 128 pool-loads of lanes; padding lanes cost nothing
    but their share of the block's O(lanes) bookkeeping."""
    env = os.environ.get("CAUSTICS_JAX_BLOCK_LANES")
    if env:
        return int(env)
    return 128 * pool_slots(platform)


#: Most CPU devices `use_cpu_devices("all")` makes: a block holds `block_lanes()` lanes per
#: device (262,144 at 8), and optimistix Newton compiles its program once per device.
MAX_AUTO_CPU_DEVICES = 8


def max_cpu_devices() -> int:
    """The most CPU devices `use_cpu_devices` accepts: `max(64, os.cpu_count())`. More
    devices than cores only pad every batch further (a block of lanes per device) and
    compile optimistix Newton once more per device (1000 devices pad a 100k-lane
    comparison to 32M lanes)."""
    return max(64, os.cpu_count() or 1)


def use_cpu_devices(count: int | str) -> int:
    """Split the host CPU into `count` JAX devices (`"all"`: one per core, `os.cpu_count()`,
    at most `MAX_AUTO_CPU_DEVICES`),
    so that `on_devices` runs a share of every block on each core. Call it before JAX runs
    anything (it sets `jax_num_cpu_devices`, which JAX reads when its CPU backend starts);
    `caustics-jax compare --cpu-devices` and `make demo` do. Why: XLA runs one CPU device's
    program on one thread (an op is split over threads only when it is large), and the
    solvers' loops step a few hundred lanes at a time, so one device keeps one core busy
    and one device per core keeps them all busy (the gain: docs/solvers.md "Many devices
    and many hosts"); per-lane results are identical (`tests/test_devices.py`). Returns the
    device count; a `ValueError` when `count` is not a positive integer or `"all"`, or when
    the CPU backend already started with another count (a fresh process is needed)."""
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
