"""The curve walk of seed 001 §3.4: follow the coplanarity conic from `M0` to a zero of `f`.

Per lane, from the start point `M0` (on the conic by construction, §3.4.2):

1. First triangle (`walk_start`): the conic's tangent at `M0` gives two directions of
   travel. For each, the next edge crossing along the curve comes from the conic's two
   boundary crossings ordered by their pencil angle from `M0`: every point of a conic is
   hit by exactly one line through a given curve point, and the line angle `phi`
   increases monotonically along the curve, so the first crossing in the direction of
   travel is the one of smallest `phi`. Where that does not decide (`M0` on a crossing, a
   singular tangent, the signs undecided), the exact construction over the six edge
   roots (`arcs.next_crossing`), which also settles the four-intersection re-entry case
   of Fig. 5c without a heuristic. If `f` changes sign between `M0` and a crossing,
   refine there; otherwise walk towards the crossing of smaller `|f|`. With no edge
   crossing at all the curve is an ellipse inside the triangle (§3.4.4): sample it through
   the pencil and bracket a sign change.
2. Walk (§3.4.3, `walk_steps`): cross the exit edge into the neighbour (adjacency
   buffer), orient the tangent inward, find the next crossing along the curve, evaluate
   `f`; cross again while `f` keeps its sign. The next crossing comes from the conic's
   signs at the three vertices and two edge quadratics (`arcs.sign_test_exit`); where the
   signs do not decide (a curve near a vertex, a re-entry, a pair of roots on one edge),
   from the pencil order of step 1, in the `EXACT` phase: the same exit wherever both
   decide.
3. Refine ("dichotomy"): the sign change lies on the arc between the entry point and the
   exit; cut the arc by lines through the entry point at angle `phi` (the paper splits
   the triangle so that the new edge cuts the curve; a line through a known curve point
   cuts it exactly once more) and bisect `phi`, or use Illinois false position on `phi`
   (`bracket="illinois"`, the default, same guarantees, fewer steps).
4. Turn back: when the first triangle holds no sign change the walk picks one direction
   (out of total internal reflection first, else towards the smaller `|f|`). If that walk
   fails (TIR, boundary, lost curve, stalled bracket) it restarts once from `M0` the other
   way, within the same `max_steps`. The paper walks one way only; on steep waves the
   first choice is wrong for some lanes (`test_walk_turns_back_when_the_first_direction_fails`).

A lane is `FOUND` exactly when `|f| <= tol` at the returned point (`f` = sine of the
angle between the refracted direction and `w_L`, so `tol` bounds the angle error).

`WalkSolver` states this as a lane solver (`runtime.lane_solver`): its stages (the first
triangle by the vertex signs, the exact construction where they do not decide, the two
walks from `M0`, the ellipse samples where the curve has no edge crossing), its phases
(`WALK`, `BISECT`, `EXACT`), two passes with the turn-back between them, and its finish.
The runtime schedules it (slot pools, compaction, chunks, devices) as it schedules the
Newton baselines.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from ..math.barycentric import barycentric_point
from ..math.objectives import signed_sine
from ..runtime.arguments import check_choice, check_int, check_tol
from ..runtime.blocks import on_devices
from ..runtime.lane_solver import LaneSolver, Stage, run_lanes
from ..surface.mesh import SurfaceMesh
from ._solution import Solution, Status, confirm_found
from .newton import Newton
from .options import SolverOptions, option, scheduler_option
from .walk_start import Ellipse, Start, ellipse_bracket, first_triangle, start_states
from .walk_steps import DONE, PHASES, WalkState, walk_step

__all__ = ["Walk", "WalkLane", "WalkSolver", "solve_walk"]

FALLBACKS = ("newton", "none")


class Walk(SolverOptions):
    """The curve walk of seed 001 §3.4 and its options (`solve(..., method=Walk(...))`).

    tol: accept a point when `|f| <= tol`, in `(0, 1)` (None: 1e-10 in float64, 1e-5 in
        float32, from the float32 audit's 1e-6 noise floor of `f`). Traced.
    max_steps: cap on crossings plus refinement steps per lane, in `[1, 2^31 - 1]`. Traced.
    bracket: "illinois" (false position with the Illinois fix) or "bisection" (the paper).
    ellipse_samples: pencil samples of an ellipse inside the first triangle (§3.4.4),
        in `[2, 4096]`.
    scheduler: "pool" (each phase in its own slot pool refilled from a queue, the rare
        branches only where needed) or "chunked" (chunks of 256 lanes, each until its
        slowest lane); same per-lane results (`runtime.lane_solver`).
    fallback: "newton" (default): a lane with a start point that the walk ends without a
        path is solved again by the one-step Newton from the same `M0`
        (`Newton(stepping="one_step")`, the same `tol`; then, where that fails too, from
        Cycles' gentle first step 0.1), on those lanes only; `"none"`:
        the walk alone (seed 001's method, what the GLSL walk runs). docs/solvers.md
        "Robustness on irregular meshes".
    """

    method: ClassVar[str] = "walk"
    traced: ClassVar[tuple[str, ...]] = ("tol", "max_steps")
    host: ClassVar[tuple[str, ...]] = ("fallback",)

    tol: float | None = option(None, lambda v: check_tol("tol", v))
    max_steps: int = option(512, lambda v: check_int("max_steps", v, 1))
    bracket: str = option("illinois", lambda v: check_choice("bracket", v, ("illinois", "bisection")))
    ellipse_samples: int = option(64, lambda v: check_int("ellipse_samples", v, 2, 4096))
    scheduler: str = scheduler_option()
    fallback: str = option("newton", lambda v: check_choice("fallback", v, FALLBACKS))

    flat_closed_form: ClassVar[bool] = True

    def solve_block(self, mesh: SurfaceMesh, P, L, eta, start, lane_id) -> Solution:
        del lane_id  # the walk draws nothing per lane
        return solve_walk(mesh, P, L, eta, start, self)

    def fallbacks(self, dtype) -> tuple[Newton, ...]:
        """`fallback="newton"`: the one-step Newton from the same `M0` and `tol`, then, on
        the lanes it misses too, the same from Cycles' gentle first step 0.1 (its MNEE step
        control: on the steep irregular stress mesh the one lane in 4,096 that both the
        walk and the full step lose)."""
        if self.fallback == "none":
            return ()
        tol = self.tolerance(dtype)
        return (Newton(stepping="one_step", tol=tol), Newton(stepping="one_step", initial_step=0.1, tol=tol))


class WalkLane(NamedTuple):
    """A lane's input: receiver `P`, light `L`, start point `M0` (`face`, barycentric
    `ab0`) and whether it has one (`found`)."""

    P: jax.Array
    L: jax.Array
    face: jax.Array
    ab0: jax.Array
    found: jax.Array


class FirstTriangle(NamedTuple):
    """A lane with its first triangle's record (`walk_start.first_triangle`); `clear`: the
    vertex signs decided both exits."""

    lane: WalkLane
    start: Start
    clear: jax.Array


class LaneState(NamedTuple):
    """A lane through the walk: `P`, `L`, its `WalkState`, and the turn-back: whether it
    turned already, whether it can, and the walk the other way from `M0`."""

    P: jax.Array
    L: jax.Array
    state: WalkState
    turned: jax.Array
    can_flip: jax.Array
    other: WalkState


class Moving(NamedTuple):
    """What a step reads and writes: `P`, `L` and the walk's state (`WalkSolver.moving`)."""

    P: jax.Array
    L: jax.Array
    state: WalkState


class WalkRecord(NamedTuple):
    """A lane between its stages and its finish: the `LaneState`, and what the ellipse
    search needs (`is_ellipse`: the curve has no edge crossing in the first triangle)."""

    lane: LaneState
    is_ellipse: jax.Array
    ellipse: Ellipse


class WalkSolver(LaneSolver):
    """The walk of seed 001 §3.4 as a lane solver (module docstring): `mesh` padded, `eta`,
    `tol` and `max_steps` (traced), `options` static."""

    phases: ClassVar[tuple[str, ...]] = PHASES
    passes: ClassVar[int] = 2  # the walk, then the turn-back's walk
    #: Pool widths by demand: a lane crosses about twice as often as it cuts (3.75 and
    #: 1.75 steps per lane on a 128^2 grid), and 0.1-2% of crossings take the exact
    #: construction. 512 / 256 / 64 slots on the CPU ran a block 1.25-1.4x faster than
    #: 256 each, with the same points (docs/solvers.md "One lane-solver protocol").
    pool_shares: ClassVar[tuple[float, ...]] = (2.0, 1.0, 0.25)

    mesh: SurfaceMesh
    eta: jax.Array
    tol: jax.Array
    max_steps: jax.Array
    options: Walk

    def _first(self, lane: WalkLane, lean: bool):
        return first_triangle(self.mesh, lane.P, lane.L, lane.face, lane.ab0, lane.found, self.eta, self.tol,
                              lean=lean)

    def stages(self) -> tuple[Stage, ...]:
        """The first triangle of every lane with a start point from the vertex signs, the
        exact construction on those the signs leave undecided, both walks from `M0` for
        every lane (a lane without a start point builds `NO_CROSSING`, no steps), and the
        ellipse samples where the curve has no edge crossing (`walk_start`)."""
        def lean(lane: WalkLane) -> FirstTriangle:
            start, clear = self._first(lane, lean=True)
            return FirstTriangle(lane, start, clear)

        def exact(rec: FirstTriangle) -> FirstTriangle:
            return rec._replace(start=self._first(rec.lane, lean=False))

        def walks(rec: FirstTriangle) -> WalkRecord:
            can_flip, state, other, is_ellipse, ellipse = start_states(rec.start)
            lane = LaneState(rec.lane.P, rec.lane.L, state, jnp.zeros_like(can_flip), can_flip, other)
            return WalkRecord(lane, is_ellipse, ellipse)

        def ellipse(rec: WalkRecord) -> WalkRecord:
            lane = rec.lane
            state = ellipse_bracket(self.mesh, lane.P, lane.L, self.eta, self.options.ellipse_samples, lane.state,
                                    rec.ellipse)
            return rec._replace(lane=lane._replace(state=state))

        return (Stage(lean, when=lambda lane: lane.found),
                Stage(exact, when=lambda rec: rec.lane.found & ~rec.clear, keep=True),
                Stage(walks),
                Stage(ellipse, when=lambda rec: rec.is_ellipse, keep=True))

    def route(self, lane: Moving) -> jax.Array:
        s = lane.state
        running = (s.mode != DONE) & (s.steps < self.max_steps)
        return jnp.where(running, s.mode, -1).astype(jnp.int32)

    def step(self, lane: Moving, phase: int | None) -> Moving:
        illinois = self.options.bracket == "illinois"
        return lane._replace(state=walk_step(self.mesh, lane.P, lane.L, self.eta, self.tol, illinois, lane.state,
                                             phase))

    def restart(self, rec: WalkRecord) -> WalkRecord:
        """The turn-back: a walk that failed (done, not FOUND) restarts once from `M0` the
        other way, keeping its step count. A lane that cannot turn, already turned, or is
        not done is returned unchanged."""
        lane = rec.lane
        s = lane.state
        failed = (s.mode == DONE) & (s.status != Status.FOUND) & lane.can_flip & ~lane.turned
        restart = lane.other._replace(steps=s.steps, crossed=s.crossed)
        state = jax.tree.map(lambda r, n: jnp.where(failed, r, n), restart, s)
        return rec._replace(lane=lane._replace(state=state, turned=lane.turned | failed))

    def moving(self, rec: WalkRecord) -> Moving:
        """What a step reads and writes: the turn-back's second state stays out of the
        pools (24 fields per lane move instead of 48)."""
        return Moving(rec.lane.P, rec.lane.L, rec.lane.state)

    def settle(self, rec: WalkRecord, moving: Moving) -> WalkRecord:
        return rec._replace(lane=rec.lane._replace(state=moving.state))

    def finish(self, rec: WalkRecord) -> WalkState:
        """The final states; lanes still running hit the cap `max_steps`."""
        s = rec.lane.state
        return s._replace(status=jnp.where(s.mode != DONE, Status.MAX_STEPS, s.status).astype(jnp.int32))


def _walk_block(mesh, eta, tol, max_steps, P, L, face, ab0, found, options: Walk) -> Solution:
    """One device's share of a block of lanes (`blocks.on_devices`)."""
    eta = jnp.asarray(eta, mesh.dtype)
    tol = jnp.asarray(tol, mesh.dtype)
    solver = WalkSolver(mesh, eta, tol, max_steps, options)
    states = run_lanes(solver, WalkLane(P, L, face, ab0, found), scheduler=options.scheduler)
    V, N = mesh.triangle(states.face)
    # A found lane reports the `f` its acceptance test read at the returned point (the
    # same point and formula: `bracket_objective`'s "plane" sine); evaluated again here at
    # the block's vector width it can round across `tol` (1 lane in 32,768 of the default
    # pool in float32 read 1.0015e-5 with tol 1e-5). Other lanes: `f` at their last point.
    residual = jnp.where(states.status == Status.FOUND, states.best_f,
                         signed_sine(V, N, P, L, states.best_ab, eta, orientation="plane"))
    status = confirm_found(states.status, residual, tol)
    V0, _ = mesh.triangle(face)
    return Solution(
        point=jnp.where(found[:, None], barycentric_point(V, states.best_ab), 0),
        triangle=jnp.where(found, states.face, -1),
        barycentric=jnp.where(found[:, None], states.best_ab, 0),
        found=status == Status.FOUND,
        status=status,
        iterations=states.steps,
        residual=jnp.where(found, residual, 0),
        crossed=states.crossed,
        start_point=jnp.where(found[:, None], barycentric_point(V0, ab0), 0),
    )


def solve_walk(mesh: SurfaceMesh, P, L, eta, start, options: Walk) -> Solution:
    """The walk on one block of lanes (`solve` runs every batch in blocks of one size, split
    over the local devices): `mesh` from `prepared.padded_mesh`, `start = (face, barycentric,
    found)`, `eta` a float."""
    face, ab0, found = start
    shared = (mesh, jnp.asarray(eta, mesh.dtype), jnp.asarray(options.tolerance(mesh.dtype), mesh.dtype),
              jnp.int32(options.max_steps))
    return on_devices(_walk_block, options.static(), shared, (P, L, face, ab0, found))
