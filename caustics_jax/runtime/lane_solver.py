"""One lane-solver protocol, one scheduler (docs/map.md "Layers", docs/solvers.md "One lane-solver protocol").

A solver is an equinox Module that says what a lane computes; this module says how the
lanes are scheduled, once for every solver (as optimistix's `AbstractIterativeSolver`
splits `init`, `step`, `terminate` and `postprocess` from the loop that runs them, and
pbrt-v4's wavefront renderer keeps one work queue per kind of work item):

- `stages`: the work before the first step, in order. A `Stage` runs on every lane, or,
  with `when`, only on the lanes that need it (a rare branch: compacted, so its cost is
  those lanes' alone, `pools.map_where`). Each stage's result is stored before the next
  stage reads it: XLA's CPU fusion copies a cheap producer into every kernel that reads
  it, and the copies were most of a first triangle's compile time (docs/solvers.md
  "Where the walk's compile time goes").
- `phases`: the kinds of step; `route(state)` names the phase a lane needs next (its
  index) or -1 once it is done; `step(state, phase)` runs that phase's step only (the
  pool scheduler), `step(state, None)` any phase (one program for every lane, the chunked
  scheduler).
- `passes`, `restart`: the stepping runs `passes` times; before each, `restart(record)`
  may send a lane back to work (the walk's turn-back from `M0`, a no-op for a lane that
  does not need it). `moving(record)` is the part the steps read and write and
  `settle(record, moving)` puts it back: the pools move only that. `pool_shares` sizes
  each phase's pool to its demand (`pool_widths`).
- `finish(record)`: the block's result from the final records (lane axis first).

Schedulers (`run_lanes`): `"pool"` steps each phase in its own slot pool refilled from a
queue of the lanes routed to it (`pools.run_pools`), so a step computes only its own
branch; `"chunked"` runs each lane's stages and its own `while_loop` (vmapped over chunks
of 256 lanes, each until its slowest lane). A lane sees the same sequence of steps under
both, so statuses and step counts agree and points agree up to the rounding of each
program's vector code (`tests/test_scheduling.py`).
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .lanes import map_lanes
from .pools import map_where, pool_slots, run_pools

__all__ = ["SCHEDULERS", "LaneSolver", "Stage", "pool_widths", "run_lanes", "stage_lane"]

SCHEDULERS = ("pool", "chunked")


class Stage(NamedTuple):
    """One step of a lane's set-up: `fn(record) -> record` on every lane, or with `when`
    (`when(record) -> bool`) only where it holds. There `keep=True`: `fn` returns the
    record's own structure and the other lanes keep theirs; `keep=False`: the other lanes
    get zeros of `fn`'s result. `chunked`: an every-lane stage runs in `lanes.map_lanes`'
    chunks under the pool scheduler too, so it rounds as the chunked scheduler does
    (XLA's vector code at another width rounds `f` differently: Newton's residuals 3.9e-7
    apart in float32, 9e-16 in float64); otherwise it is one vmap over the block."""

    fn: Callable
    when: Callable | None = None
    keep: bool = False
    chunked: bool = False


class LaneSolver(eqx.Module):
    """The protocol (module docstring). Subclasses set `phases` and implement `stages`,
    `route`, `step` and `finish` (abstract: a solver without one cannot be built);
    `passes`, `restart`, `moving` and `settle` default to one pass of the whole record."""

    phases: ClassVar[tuple[str, ...]] = ()
    passes: ClassVar[int] = 1
    #: Each phase's pool width as a share of the pool scheduler's slots (None: 1 each).
    pool_shares: ClassVar[tuple[float, ...] | None] = None

    @abc.abstractmethod
    def stages(self) -> tuple[Stage, ...]:
        """The lane's set-up, in order (module docstring)."""

    @abc.abstractmethod
    def route(self, state) -> jax.Array:
        """The phase `state` needs next (int32), or -1 once it is done."""

    @abc.abstractmethod
    def step(self, state, phase: int | None):
        """One step of `phase` (None: of the lane's own phase, every phase computed)."""

    @abc.abstractmethod
    def finish(self, record) -> Any:
        """The block's result from the final records (lane axis first)."""

    def restart(self, record):
        """Before each pass: the lanes sent back to work (default: none)."""
        return record

    def moving(self, record):
        """What the steps read and write (default: the whole record)."""
        return record

    def settle(self, record, moving):
        """`moving` put back into `record` after a pass."""
        del record
        return moving


def _stage_lane(stage: Stage, x):
    """A stage on one lane (the chunked scheduler): the result where `when` holds."""
    y = stage.fn(x)
    if stage.when is None:
        return y
    other = x if stage.keep else jax.tree.map(jnp.zeros_like, y)
    need = stage.when(x)
    return jax.tree.map(lambda a, b: jnp.where(need, a, b), y, other)


def _stage_pool(stage: Stage, record, slots: int):
    """A stage on the lanes that need it, compacted (`pools.map_where`)."""
    if stage.when is None:
        return _map(stage.fn, record) if stage.chunked else jax.vmap(stage.fn)(record)
    need = jax.vmap(stage.when)(record)
    return map_where(stage.fn, need, record if stage.keep else None, record, chunk=slots)


def stage_lane(solver: LaneSolver, x):
    """Every stage of `solver` on one lane `x`, as the chunked scheduler runs them (the
    record its steps start from)."""
    for stage in solver.stages():
        x = _stage_lane(stage, x)
    return x


def _map(fn, tree, chunk: int | None = None):
    """`lanes.map_lanes` of `fn` over a pytree of lanes."""
    leaves, treedef = jax.tree.flatten(tree)
    return map_lanes(lambda *xs: fn(jax.tree.unflatten(treedef, xs)), *leaves, chunk=chunk)


def _lane_loop(solver: LaneSolver, record):
    """Every pass of one lane in its own `while_loop`s (the chunked scheduler)."""
    for _ in range(solver.passes):
        record = solver.restart(record)
        moving = jax.lax.while_loop(lambda m: solver.route(m) >= 0, lambda m: solver.step(m, None),
                                    solver.moving(record))
        record = solver.settle(record, moving)
    return record


def pool_widths(solver: LaneSolver | type[LaneSolver], slots: int | None = None) -> tuple[int, ...]:
    """The slots of each phase's pool: `pool_shares` of `slots` (default `pools.pool_slots()`),
    at least 8."""
    slots = pool_slots() if slots is None else slots
    shares = solver.pool_shares or (1.0,) * len(solver.phases)
    return tuple(max(8, int(round(share * slots))) for share in shares)


def run_lanes(solver: LaneSolver, lanes, *, scheduler: str = "pool", slots: int | None = None):
    """`solver.finish` of every lane of `lanes` (a pytree, lane axis first) after its stages
    and its steps, scheduled by `scheduler` (module docstring; inside jit)."""
    if scheduler not in SCHEDULERS:
        raise ValueError(f"scheduler must be one of {SCHEDULERS}, got {scheduler!r}")
    if scheduler == "chunked":
        return solver.finish(_map(lambda x: _lane_loop(solver, stage_lane(solver, x)), lanes))

    slots = pool_slots() if slots is None else slots
    record = lanes
    for stage in solver.stages():
        record = _stage_pool(stage, record, slots)
    steps = tuple(lambda m, k=k: solver.step(m, k) for k in range(len(solver.phases)))
    widths = pool_widths(solver, slots)

    def one_pass(_, record):
        record = jax.vmap(solver.restart)(record)
        moving = run_pools(steps, solver.route, jax.vmap(solver.moving)(record), widths)
        return jax.vmap(solver.settle)(record, moving)

    if solver.passes == 1:
        record = one_pass(0, record)
    else:
        record = jax.lax.fori_loop(0, solver.passes, one_pass, record)
    return solver.finish(record)
