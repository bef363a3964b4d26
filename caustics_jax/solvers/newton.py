"""Newton-type manifold solvers (Hanika et al. 2015 MNEE; Zeltner et al. 2020 SMS).

The unknown is the barycentric point `(a, b)` of the current triangle; the residual is a
2D constraint that vanishes on refracted paths (math.md §4): the half-vector constraint
(Walter et al. 2009, as in MNEE) or the angle-difference constraint (SMS). Same start
point `M0` and `Solution` as the walk; a lane is `FOUND` exactly when the signed sine at
the returned point is within `tol`, the criterion every solver is judged by. Two ways to
step across the mesh (`stepping`):

- `"converge"` (on optimistix): each patch runs `optimistix.root_find` for
  `inner_steps` steps in the triangle's own (extrapolated) coordinates; when the iterate
  leaves the triangle the solver crosses the edge where the step leaves it (the
  adjacency buffer, `cross_edge`) and restarts there. It converges inside every
  extended triangle before crossing, so it pays about 4 steps per triangle crossed.
- `"one_step"` (as the anchors do: Cycles' `mnee_newton_solver`, Mitsuba's SMS, Hanika
  et al. 2015 §4.3): one Newton step per iteration, `x - beta J^-1 C(x)` in the plane of
  the current triangle, then the tentative point is projected back onto the surface
  along the ray from `P` through it, and the step size `beta` adapts: halved when the
  projection fails (the ray leaves the mesh) or the projected path is not transmitting
  (`P` and `L` on the same side of the shading normal), doubled back towards 1 after
  an accepted step (starting from `initial_step`: 1 takes full Newton steps at once,
  Cycles starts at 0.1 "since target configurations far from the seed path can send the
  proposed solution further than the linearized local differential geometric quantities
  are meant for"). The projection walks the adjacency from the current face along the
  step (`_reproject`): the local equivalent of Cycles' scene ray cast, exact whenever
  the ray's hit is reached by crossing edges along the step, as on a heightfield. The
  2x2 Newton system is solved in closed form (Cramer's rule); `J` of the half-vector
  constraint is the closed form of `objectives.half_vector_residual_and_jacobian` (what
  `jax.jacfwd` computes, without its second pass through every intermediate), of the
  angle difference `jax.jacfwd`.

SMS-style multiple starts (`n_starts > 1`): extra starts drawn uniformly in the start
triangle, from a key folded with the lane's index (so a lane's starts do not depend on
how lanes are batched or spread over devices); the found solution nearest `M0` is
returned.

`NewtonSolver` is a lane solver (`runtime.lane_solver`): the runtime schedules its lanes
(`"pool"`, default: a slot pool refilled from a queue of unfinished lanes; `"chunked"`:
fixed chunks of 256 lanes, each until its slowest lane), as it schedules the walk; both
run the same per-lane iteration.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import optimistix as optx

from ..curve.arcs import inside as inside_triangle
from ..math.barycentric import barycentric_point, edge_barycentric, ray_plane_barycentric
from ..math.geometry import dot, newton_step_2x2
from ..math.objectives import (
    ObjectiveStatus,
    angle_difference_residual,
    bracket_objective,
    half_vector_residual,
    half_vector_residual_and_jacobian,
    path_vectors,
)
from ..runtime.arguments import MAX_INT32, check_choice, check_int, check_real, check_tol
from ..runtime.blocks import on_devices
from ..runtime.lane_solver import LaneSolver, Stage, run_lanes
from ..runtime.lanes import map_lanes
from ..surface.mesh import SurfaceMesh, cross_edge
from ._solution import Solution, Status, confirm_found
from .options import SolverOptions, option, scheduler_option

__all__ = ["Newton", "solve_newton"]

SOLVERS = ("newton", "chord", "dogleg", "levenberg_marquardt")
CONSTRAINTS = {"half_vector": half_vector_residual, "angle_difference": angle_difference_residual}
STEPPING = ("converge", "one_step")
#: `one_step`: edges the projection may cross in one step before it counts as failed (Cycles
#: gives its projection ray a bounded number of hits, MNEE_MAX_INTERSECTION_COUNT).
MAX_PROJECTION_CROSSINGS = 16
#: `one_step`: the step size `beta` below which the solve gives up (Cycles' MNEE_MINIMUM_STEP_SIZE).
MIN_BETA = 1e-4


class Newton(SolverOptions):
    """Newton-type manifold solvers (MNEE / SMS), and their options.

    solver: "newton", "chord", "dogleg" or "levenberg_marquardt" (optimistix solvers, for
        `stepping="converge"`; `"one_step"` takes plain Newton steps: solver "newton").
    constraint: "half_vector" (MNEE) or "angle_difference" (SMS).
    stepping: "converge" (optimistix to convergence in each triangle, then cross) or
        "one_step" (one Newton step, then project back onto the surface, as MNEE/SMS).
    scheduler: "pool" (slot pool) or "chunked" (chunks of 256 lanes), `runtime.lane_solver`.
    tol: acceptance `|f| <= tol` on the signed sine, in `(0, 1)` (None: as the walk). Traced.
    inner_steps: optimistix steps per triangle patch, in `[1, 1024]` ("converge" only).
    max_patches: cap per lane on patches (triangle changes and restarts; "one_step":
        on Newton steps), in `[1, 2^31 - 1]`. Traced.
    initial_step: "one_step": the first step size `beta`, in `(0, 1]` (1: full steps;
        Cycles' MNEE starts at 0.1, which costs steps on gentle waves and finds more
        paths on steep ones: docs/solvers.md). Traced.
    n_starts: 1 = start at `M0` only; more adds uniform starts in the start triangle
        (SMS-style), in `[1, 1024]`.
    seed: for the extra starts, in `[0, 2^31 - 1]`.
    """

    method: ClassVar[str] = "newton"
    traced: ClassVar[tuple[str, ...]] = ("tol", "max_patches", "initial_step")

    solver: str = option("newton", lambda v: check_choice("solver", v, SOLVERS))
    constraint: str = option("half_vector", lambda v: check_choice("constraint", v, tuple(CONSTRAINTS)))
    tol: float | None = option(None, lambda v: check_tol("tol", v))
    inner_steps: int = option(8, lambda v: check_int("inner_steps", v, 1, 1024))
    max_patches: int = option(64, lambda v: check_int("max_patches", v, 1, MAX_INT32))
    n_starts: int = option(1, lambda v: check_int("n_starts", v, 1, 1024))
    seed: int = option(0, lambda v: check_int("seed", v, 0))
    stepping: str = option("converge", lambda v: check_choice("stepping", v, STEPPING))
    scheduler: str = scheduler_option()
    initial_step: float = option(1.0, lambda v: check_real("initial_step", v, 0, 1, lo_open=True))

    def __check_init__(self):
        if self.stepping == "one_step" and self.solver != "newton":
            raise ValueError(f"stepping='one_step' takes plain Newton steps (MNEE/SMS): solver must be "
                             f"'newton', got {self.solver!r}")

    def solve_block(self, mesh, P, L, eta, start, lane_id) -> Solution:
        return solve_newton(mesh, P, L, eta, start, self, lane_id)

    def check_dtype(self, dtype) -> None:
        """optimistix 0.1.0's trust-region state is created in the default float dtype, so
        with x64 on it mixes float64 into a float32 solve and lineax rejects it."""
        if (self.solver in ("dogleg", "levenberg_marquardt") and jnp.dtype(dtype) == jnp.float32
                and jax.config.jax_enable_x64):
            raise ValueError(f"solver={self.solver!r} needs float64 or jax_enable_x64 off in float32")


def _make_solver(name: str, tol: float):
    # Step-size termination well below the acceptance tolerance; acceptance is decided on f.
    rtol = atol = tol / 10
    return {
        "newton": lambda: optx.Newton(rtol=rtol, atol=atol),
        "chord": lambda: optx.Chord(rtol=rtol, atol=atol),
        "dogleg": lambda: optx.Dogleg(rtol=rtol, atol=atol),
        "levenberg_marquardt": lambda: optx.LevenbergMarquardt(rtol=rtol, atol=atol),
    }[name]()


def _exit_edge(ab, ab_new):
    """First edge crossed by the segment `ab -> ab_new` (in barycentric space): `(k, t, lam)`."""
    d = ab_new - ab
    dtype = ab.dtype
    big = jnp.asarray(jnp.inf, dtype)
    # edge 0: b = 0; edge 1: a + b = 1; edge 2: a = 0 (distance to each, along d)
    lam0 = jnp.where(d[1] < 0, -ab[1] / jnp.where(d[1] < 0, d[1], 1), big)
    s = d[0] + d[1]
    lam1 = jnp.where(s > 0, (1 - ab[0] - ab[1]) / jnp.where(s > 0, s, 1), big)
    lam2 = jnp.where(d[0] < 0, -ab[0] / jnp.where(d[0] < 0, d[0], 1), big)
    lams = jnp.clip(jnp.stack([lam0, lam1, lam2]), 0, None)
    k = jnp.argmin(lams).astype(jnp.int32)
    lam = lams[k]
    q = ab + jnp.minimum(lam, 1) * d
    t = jnp.where(k == 0, q[0], q[1])  # edge 0: t = a; edges 1 and 2: t = b
    return k, jnp.clip(t, 0, 1), lam


class _State(NamedTuple):
    face: jax.Array
    ab: jax.Array
    status: jax.Array
    done: jax.Array
    patches: jax.Array
    steps: jax.Array
    crossed: jax.Array
    beta: jax.Array  # "one_step": the step size (1 for "converge")


def _f_at(mesh, P, L, face, ab, eta):
    """`f` ("plane") and status at one lane's `ab`, as every solver accepts a point
    (`bracket_objective`: BACKWARD where the refracted ray points away from `L` or `P`
    lies beyond the shading plane; Newton started on the mirror image of a solution had
    converged there, FOUND with `P` above the water)."""
    V, N = mesh.triangle(face)
    f, status, _ = bracket_objective(V, N, P, L, ab[None], eta)
    return f[0], status[0]


def newton_init(mesh, P, L, face, ab0, found, eta, tol, beta0) -> _State:
    """A lane's state before its first iteration (`M0` may already be a solution; `beta0`
    the first step size of "one_step")."""
    f0, st0 = _f_at(mesh, P, L, face, ab0, eta)
    at_m0 = (jnp.abs(f0) <= tol) & (st0 == ObjectiveStatus.OK)
    return _State(face=jnp.asarray(face, jnp.int32), ab=ab0,
                  status=jnp.where(found, jnp.where(at_m0, Status.FOUND, Status.MAX_STEPS),
                                   Status.NO_CROSSING).astype(jnp.int32),
                  done=~found | at_m0, patches=jnp.asarray(0, jnp.int32),
                  steps=jnp.asarray(0, jnp.int32), crossed=jnp.asarray(0, jnp.int32),
                  beta=jnp.asarray(beta0, ab0.dtype))


def _patch(mesh, P, L, eta, tol, options: Newton, s: _State) -> _State:
    """"converge": one patch, `inner_steps` optimistix steps in the current (extended)
    triangle, then accept, cross the exit edge, or stop at a boundary."""
    dtype = mesh.dtype
    solver = _make_solver(options.solver, tol)
    residual = CONSTRAINTS[options.constraint]
    slack = 64 * jnp.finfo(dtype).eps
    V, N = mesh.triangle(s.face)
    fn = lambda y, args: residual(V, N, P, L, y, eta)  # noqa: E731
    sol = optx.root_find(fn, solver, s.ab, max_steps=options.inner_steps, throw=False)
    ab_new = sol.value
    finite = jnp.all(jnp.isfinite(ab_new))
    ab_new = jnp.where(finite, ab_new, s.ab)
    inside = inside_triangle(ab_new, slack)
    k, t, _ = _exit_edge(s.ab, ab_new)
    g, _, _, ab_entry = cross_edge(mesh, s.face, k, t)
    left = ~inside & (g < 0)
    f_new, st_new = _f_at(mesh, P, L, s.face, jnp.where(inside, ab_new, s.ab), eta)
    converged = inside & (jnp.abs(f_new) <= tol) & (st_new == ObjectiveStatus.OK)
    face = jnp.where(inside | left, s.face, g)
    ab = jnp.where(inside, ab_new, jnp.where(left, edge_barycentric(k, t), ab_entry))
    status = jnp.where(converged, Status.FOUND, s.status)
    status = jnp.where(left, Status.LEFT_MESH, status)
    status = jnp.where(~finite, Status.NOT_CONVERGED, status)
    done = converged | left | ~finite
    return s._replace(face=face.astype(jnp.int32), ab=ab, status=status.astype(jnp.int32),
                      done=done, patches=s.patches + 1,
                      steps=s.steps + sol.stats["num_steps"].astype(jnp.int32),
                      crossed=s.crossed + jnp.where(inside | left, 0, 1))


def _reproject(mesh, P, face, ab, ab_t):
    """Project the tentative point `ab_t` (in `face`'s extended plane) back onto the surface
    along the ray from `P` through it, walking the adjacency from `face` along the step
    (Cycles' MNEE projects with a scene ray cast from the previous vertex; on a mesh the
    hit is found by crossing edges along the step). Returns `(face, ab, hit, left, crossings)`."""
    V, _ = mesh.triangle(face)
    T = barycentric_point(V, ab_t)
    slack = 64 * jnp.finfo(ab.dtype).eps

    def cond(c):
        face, x, y, ok, left, n = c
        return ok & ~inside_triangle(y, slack) & (n < MAX_PROJECTION_CROSSINGS)

    def body(c):
        face, x, y, ok, left, n = c
        k, t, _ = _exit_edge(x, y)
        g, _, _, e = cross_edge(mesh, face, k, t)
        Vg, _ = mesh.triangle(g)
        y_g, hit = ray_plane_barycentric(Vg, P, T)
        ok_g = (g >= 0) & hit
        return (jnp.where(ok_g, g, face), jnp.where(ok_g, e, x), jnp.where(ok_g, y_g, y), ok_g,
                left | (g < 0), n + 1)

    face, _, y, ok, left, n = jax.lax.while_loop(
        cond, body, (face, ab, ab_t, jnp.asarray(True), jnp.asarray(False), jnp.int32(0)))
    return face, y, ok & inside_triangle(y, slack), left, n


def _one_step(mesh, P, L, eta, tol, options: Newton, s: _State) -> _State:
    """"one_step": one Newton step with step size `beta`, projected back onto the surface
    (module docstring; Cycles' `mnee_newton_solver` loop body)."""
    residual = CONSTRAINTS[options.constraint]
    eps = jnp.finfo(mesh.dtype).eps
    V, N = mesh.triangle(s.face)
    if options.constraint == "half_vector":  # the closed-form Jacobian (math.md §4)
        r, J = half_vector_residual_and_jacobian(V, N, P, L, s.ab, eta)
    else:
        C = lambda ab: residual(V, N, P, L, ab, eta)  # noqa: E731
        r, J = C(s.ab), jax.jacfwd(C)(s.ab)
    dx, solvable = newton_step_2x2(J, r)
    face, ab, hit, left, crossings = _reproject(mesh, P, s.face, s.ab, s.ab - s.beta * dx)
    # The projected path must still refract: P and L on opposite sides of the shading
    # normal (Cycles rejects the tentative vertex otherwise).
    Vn, Nn = mesh.triangle(face)
    _, n_s, w_P, w_L, degenerate = path_vectors(Vn, Nn, P, L, ab)
    transmits = (dot(n_s, w_P) * dot(n_s, w_L) < 0) & ~degenerate
    accept = solvable & hit & transmits
    f, st = _f_at(mesh, P, L, face, ab, eta)
    found = accept & (jnp.abs(f) <= tol) & (st == ObjectiveStatus.OK)
    # A step that cannot move the point any more (Cycles: MNEE_MIN_PROGRESS_DISTANCE).
    stalled = accept & ~found & (jnp.linalg.norm(s.beta * dx) <= 4 * eps * jnp.maximum(jnp.linalg.norm(s.ab), 1))
    beta = jnp.where(accept, jnp.minimum(1, 2 * s.beta), s.beta / 2)
    gave_up = ~accept & (beta < MIN_BETA)
    status = jnp.where(found, Status.FOUND, s.status)
    status = jnp.where(stalled | (gave_up & ~left) | ~solvable, Status.NOT_CONVERGED, status)
    status = jnp.where(gave_up & left & solvable, Status.LEFT_MESH, status)
    return s._replace(
        face=jnp.where(accept, face, s.face).astype(jnp.int32), ab=jnp.where(accept, ab, s.ab),
        status=status.astype(jnp.int32), done=found | stalled | gave_up | ~solvable,
        patches=s.patches + 1, steps=s.steps + 1,
        crossed=s.crossed + jnp.where(accept, crossings, 0), beta=beta.astype(s.beta.dtype))


def newton_iteration(mesh, P, L, eta, tol, options: Newton, s: _State) -> _State:
    """One iteration of a lane: a patch ("converge") or a projected Newton step ("one_step")."""
    if options.stepping == "one_step":
        return _one_step(mesh, P, L, eta, tol, options, s)
    return _patch(mesh, P, L, eta, tol, options, s)


def _finish(mesh, P, L, eta, s: _State):
    """Lanes that ran out of patches at a totally reflecting point report TIR; `f` at the end."""
    f_end, st_end = _f_at(mesh, P, L, s.face, s.ab, eta)
    status = jnp.where((s.status == Status.MAX_STEPS) & (st_end == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION),
                       Status.TOTAL_INTERNAL_REFLECTION, s.status)
    return s._replace(status=status.astype(jnp.int32)), f_end


class NewtonLane(NamedTuple):
    """A lane's input: receiver, light, start face and barycentrics, whether it has one."""

    P: jax.Array
    L: jax.Array
    face: jax.Array
    ab: jax.Array
    found: jax.Array


class NewtonRecord(NamedTuple):
    P: jax.Array
    L: jax.Array
    state: _State


class NewtonSolver(LaneSolver):
    """The Newton baselines as a lane solver (`runtime.lane_solver`): one phase, an
    iteration (a patch or a projected step) until done or `max_patches`; `finish` reads
    `f` at the end point. `eta`, `tol`, `max_patches`, `beta0` traced."""

    phases: ClassVar[tuple[str, ...]] = ("iterate",)

    mesh: SurfaceMesh
    eta: jax.Array
    tol: jax.Array
    max_patches: jax.Array
    beta0: jax.Array
    options: Newton

    def stages(self) -> tuple[Stage, ...]:
        def init(x: NewtonLane) -> NewtonRecord:
            return NewtonRecord(x.P, x.L, newton_init(self.mesh, x.P, x.L, x.face, x.ab, x.found, self.eta, self.tol,
                                                      self.beta0))

        return (Stage(init, chunked=True),)

    def route(self, rec: NewtonRecord) -> jax.Array:
        s = rec.state
        return jnp.where(~s.done & (s.patches < self.max_patches), 0, -1).astype(jnp.int32)

    def step(self, rec: NewtonRecord, phase: int | None) -> NewtonRecord:
        del phase  # one phase
        s = rec.state
        nxt = newton_iteration(self.mesh, rec.P, rec.L, self.eta, self.tol, self.options, s)
        return rec._replace(state=jax.tree.map(lambda n, o: jnp.where(s.done, o, n), nxt, s))

    def finish(self, rec: NewtonRecord):
        """`(states, f_end)`: lanes that ran out of patches at a totally reflecting point
        report TIR; `f` at the end point (in chunks, as the chunked scheduler rounds it)."""
        return map_lanes(lambda p, l, s: _finish(self.mesh, p, l, self.eta, s), rec.P, rec.L, rec.state)


def _newton_block(mesh, eta, tol, max_patches, beta0, P, L, face, ab0, found, lane_id, options: Newton) -> Solution:
    """One device's share of a block of lanes (`blocks.on_devices`)."""
    eta = jnp.asarray(eta, mesh.dtype)
    tol = jnp.asarray(tol, mesh.dtype)
    n, S = P.shape[0], options.n_starts
    if S > 1:
        key = jax.random.PRNGKey(options.seed)
        w = jax.vmap(lambda i: jax.random.dirichlet(jax.random.fold_in(key, i), jnp.ones(3, mesh.dtype), (S - 1,)))(
            lane_id)
        starts = jnp.concatenate([ab0[:, None], w[..., 1:]], axis=1)  # (n, S, 2)
    else:
        starts = ab0[:, None]
    rep = lambda x: jnp.repeat(x, S, axis=0)  # noqa: E731  (lane-major: lane i's starts together)
    solver = NewtonSolver(mesh, eta, tol, max_patches, beta0, options)
    lanes = NewtonLane(rep(P), rep(L), rep(face), starts.reshape(n * S, 2), rep(found))
    states, f_end = run_lanes(solver, lanes, scheduler=options.scheduler)
    states, f_end = jax.tree.map(lambda x: x.reshape((n, S) + x.shape[1:]), (states, f_end))
    V, N = mesh.triangle(states.face)
    points = barycentric_point(V, states.ab)
    V0, _ = mesh.triangle(face)
    M0 = barycentric_point(V0, ab0)
    ok = states.status == Status.FOUND
    dist = jnp.where(ok, jnp.linalg.norm(points - M0[:, None], axis=-1), jnp.inf)
    best = jnp.where(jnp.any(ok, axis=1), jnp.argmin(dist, axis=1), 0)
    pick = lambda x: jnp.take_along_axis(x, best.reshape((n, 1) + (1,) * (x.ndim - 2)), axis=1)[:, 0]  # noqa: E731
    f_best = pick(f_end)
    status = confirm_found(pick(states.status), f_best, tol)
    return Solution(
        point=jnp.where(found[:, None], pick(points), 0),
        triangle=jnp.where(found, pick(states.face), -1),
        barycentric=jnp.where(found[:, None], pick(states.ab), 0),
        found=status == Status.FOUND,
        status=status,
        iterations=jnp.sum(states.steps, axis=1),
        residual=jnp.where(found, f_best, 0),
        crossed=pick(states.crossed),
        start_point=jnp.where(found[:, None], M0, 0),
    )


def solve_newton(mesh, P, L, eta, start, opts: Newton, lane_id=None) -> Solution:
    """The Newton baselines on one block of lanes (see `walk.solve_walk`); `lane_id` `(n,)`
    the lanes' indices in the whole batch (keys of the extra starts; default `arange(n)`)."""
    face, ab0, found = start
    lane_id = jnp.arange(P.shape[0], dtype=jnp.int32) if lane_id is None else lane_id
    shared = (mesh, jnp.asarray(eta, mesh.dtype), jnp.asarray(opts.tolerance(mesh.dtype), mesh.dtype),
              jnp.int32(opts.max_patches), jnp.asarray(opts.initial_step, mesh.dtype))
    return on_devices(_newton_block, opts.static(), shared, (P, L, face, ab0, found, lane_id),
                      spmd=opts.stepping != "converge")  # optimistix: see `blocks.on_devices`
