"""The slot-pool scheduler: lanes stepped in fixed pools of slots refilled from queues
(`run_pools`), and work on the compacted lanes that need it (`map_where`); the lane-solver
protocol (`lane_solver.run_lanes`) schedules every solver with them.

Inside a block, a vmapped `while_loop` runs until its slowest lane ends. `run_pools`
avoids that waste: a fixed pool of slots (`pool_slots`, sized to the backend) per kind of
step steps the lanes in flight, and a slot whose lane ended or moved on takes the next
lane from its queue, so every step advances live lanes until the queues are empty. Work that few lanes
need (`map_where`) runs on the compacted lanes that need it, in chunks, so its cost is
proportional to those lanes.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp

from .lanes import LanePacking, select_lanes, take_rows


def pool_slots(platform: str | None = None) -> int:
    """Lanes in flight per device and pool in `run_pools` (env `CAUSTICS_JAX_POOL_SLOTS`;
    a lane solver's `pool_shares` scale it per phase).

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


def run_pools(steps: tuple, route, states, slots: int | tuple[int, ...]):
    """Step every lane until it is done, in one slot pool per kind of step: a lane runs in
    the pool its state routes it to, so each step computes only its own branch (inside jit).

    `steps[k](state) -> state` is the step of pool `k`; `route(state)` is the pool a lane
    needs next (int32 in `[0, len(steps))`), or -1 once it is done. Each pool has `slots`
    slots (or `slots[k]`: pools sized to their demand) and a ring-buffer queue of the
    lanes routed to it; after every trip the lanes whose route changed are written back
    and queued for their next pool (or leave when done), and every pool refills its free
    slots from its queue. A pool without a busy
    slot skips its step, and one with no slot to refill skips its refill's gather (`lax.cond`:
    a pool drains with one or two lanes for tens of trips). A lane sees the same sequence of steps as in a
    per-lane loop that branches on its state, so the results are those of that loop; a
    branch that few lanes need costs only those lanes' slots.

    """
    n = jax.tree.leaves(states)[0].shape[0]
    K = len(steps)
    widths = [min(w, n) for w in (slots if isinstance(slots, tuple) else (slots,) * K)]
    first = jax.vmap(route)(states)
    packing = LanePacking(states)
    states = packing.pack(states)
    bufs, tails, lanes_ = [], [], []
    for k in range(K):
        members = first == k
        bufs.append(jnp.nonzero(members, size=n, fill_value=n)[0].astype(jnp.int32))
        tails.append(jnp.sum(members, dtype=jnp.int32))
        lanes_.append(jnp.where(jnp.arange(widths[k]) < tails[k], bufs[k][:widths[k]], n))
    heads = [jnp.minimum(jnp.int32(widths[k]), t) for k, t in enumerate(tails)]
    carry = (states, tuple(bufs), tuple(heads), tuple(tails), tuple(lanes_),
             tuple(take_rows(states, lane) for lane in lanes_))

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
            slot_states[k] = jax.lax.cond(
                jnp.any(fill), lambda s, f=fill, lane=lanes_[k]: select_lanes(f, take_rows(states, lane), s),
                lambda s: s, slot_states[k])
        return states, tuple(bufs), tuple(heads), tuple(tails), tuple(lanes_), tuple(slot_states)

    return packing.unpack(jax.lax.while_loop(cond, body, carry)[0])


def map_where(fn, need, out, *args, chunk: int):
    """`out` with lanes `need` replaced by `vmap(fn)(*args)` at those lanes (inside jit).

    Computed on the compacted lanes that need it, `chunk` at a time, in a loop of
    `ceil(count / chunk)` trips: the cost is proportional to the lanes that need `fn`, not
    to the batch (a rare branch under a plain `vmap` is paid by every lane). `out` and
    `args` move as one matrix per dtype (`LanePacking`): one scatter and one gather per
    dtype per trip, not one per leaf. `out=None`: zeros of `fn`'s output where `need` is
    False. `fn` is traced once either way (the loop body reuses the trace that gave the
    output's shape: a second trace of a large `fn` costs seconds of a first call).

    Where no lane needs `fn` nothing is packed or moved (`lax.cond`): packing a block's
    records had cost 5.3 ms of a 32,768-lane walk block whose curves held no ellipse. With
    `args == (out,)` (a stage that updates its own record) the lanes are read from the
    packed `out` itself: one packing of the record, not two (each lane is read before the
    trip that writes it, and only once).
    """
    n = need.shape[0]
    idx = jnp.nonzero(need, size=n, fill_value=n)[0].astype(jnp.int32)
    idx = jnp.concatenate([idx, jnp.full(chunk, n, jnp.int32)])
    count = jnp.sum(need, dtype=jnp.int32)
    trips = (count + chunk - 1) // chunk
    in_place = out is not None and len(args) == 1 and args[0] is out
    arg_packing = LanePacking(args)
    batched = jax.jit(jax.vmap(fn))  # a nested jit caches its trace by argument shapes

    def apply(packed_args, sel):
        return batched(*arg_packing.unpack(take_rows(packed_args, sel)))

    if out is None:
        shapes = jax.eval_shape(lambda a, s: apply(arg_packing.pack(a), s), args, idx[:chunk])
        out = jax.tree.map(lambda x: jnp.zeros((n, *x.shape[1:]), x.dtype), shapes)
    packing = LanePacking(out)

    def run(out, args):
        packed_out = packing.pack(out)
        packed_args = None if in_place else arg_packing.pack(args)  # once, outside the loop

        def body(i, packed):
            sel = jax.lax.dynamic_slice(idx, (i * chunk,), (chunk,))
            res = apply(packed if in_place else packed_args, sel)
            res = jax.tree.map(lambda o, r: r.astype(o.dtype), out, res)
            return tuple(o.at[sel].set(r, mode="drop") for o, r in zip(packed, packing.pack(res), strict=True))

        return packing.unpack(jax.lax.fori_loop(0, trips, body, packed_out))

    return jax.lax.cond(count > 0, run, lambda out, args: out, out, args)
