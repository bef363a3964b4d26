"""Newton-type manifold solvers (Hanika et al. 2015 MNEE; Zeltner et al. 2020 SMS) on optimistix.

The unknown is the barycentric point `(a, b)` of the current triangle; the residual is a
2D constraint that vanishes on refracted paths (MATH.md §4): the half-vector constraint
(Walter et al. 2009, as in MNEE) or the angle-difference constraint (SMS). Each patch
runs `optimistix.root_find` for a few steps in the triangle's own (extrapolated)
coordinates; when the iterate leaves the triangle the walk crosses the edge where the
step leaves it (the adjacency buffer, `cross_edge`) and restarts there. Same start point
`M0` and `Solution` as the walk; a lane is `FOUND` exactly when the signed sine at the
returned point is within `tol`, the criterion every solver is judged by.

SMS-style multiple starts (`n_starts > 1`): extra starts drawn uniformly in the start
triangle; the found solution nearest `M0` is returned.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import optimistix as optx

from ..arcs import inside as inside_triangle
from ..barycentric import barycentric_point, edge_barycentric
from ..lanes import map_lanes
from ..mesh import cross_edge
from ..objectives import (
    ObjectiveStatus,
    angle_difference_residual,
    half_vector_residual,
    signed_sine_and_status,
)
from ._solution import Solution, Status
from .options import SolverOptions, check_choice, check_int, check_tol

SOLVERS = ("newton", "chord", "dogleg", "levenberg_marquardt")
CONSTRAINTS = {"half_vector": half_vector_residual, "angle_difference": angle_difference_residual}


@dataclasses.dataclass(frozen=True)
class Newton(SolverOptions):
    """Newton-type manifold solvers (MNEE / SMS) on optimistix, and their options.

    solver: "newton", "chord", "dogleg" or "levenberg_marquardt" (optimistix solvers).
    constraint: "half_vector" (MNEE) or "angle_difference" (SMS).
    tol: acceptance `|f| <= tol` on the signed sine, in `(0, 1)` (None: as the walk). Traced.
    inner_steps: optimistix steps per triangle patch, in `[1, 1024]`.
    max_patches: cap on patches (triangle changes and restarts) per lane, in
        `[1, 2^31 - 1]`. Traced.
    n_starts: 1 = start at `M0` only; more adds uniform starts in the start triangle
        (SMS-style), in `[1, 1024]`.
    seed: for the extra starts, in `[0, 2^31 - 1]`.
    """

    method: ClassVar[str] = "newton"
    traced: ClassVar[tuple[str, ...]] = ("tol", "max_patches")

    solver: str = "newton"
    constraint: str = "half_vector"
    tol: float | None = None
    inner_steps: int = 8
    max_patches: int = 64
    n_starts: int = 1
    seed: int = 0

    def _validate(self):
        check_choice("solver", self.solver, SOLVERS)
        check_choice("constraint", self.constraint, tuple(CONSTRAINTS))
        object.__setattr__(self, "tol", check_tol("tol", self.tol))
        for name, hi in (("inner_steps", 1024), ("max_patches", 2**31 - 1), ("n_starts", 1024)):
            object.__setattr__(self, name, check_int(name, getattr(self, name), 1, hi))
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0))

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


def _newton_lane(mesh, P, L, face, ab0, found, eta, tol, max_patches, options: Newton):
    dtype = mesh.dtype
    solver = _make_solver(options.solver, tol)
    residual = CONSTRAINTS[options.constraint]
    slack = 64 * jnp.finfo(dtype).eps

    def f_at(face_, ab):
        V, N = mesh.triangle(face_)
        return signed_sine_and_status(V, N, P, L, ab, eta, orientation="plane")

    def body(s: _State) -> _State:
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
        f_new, st_new = f_at(s.face, jnp.where(inside, ab_new, s.ab))
        converged = inside & (jnp.abs(f_new) <= tol) & (st_new == ObjectiveStatus.OK)
        face = jnp.where(inside | left, s.face, g)
        ab = jnp.where(inside, ab_new, jnp.where(left, edge_barycentric(k, t), ab_entry))
        status = jnp.where(converged, Status.FOUND, s.status)
        status = jnp.where(left, Status.LEFT_MESH, status)
        status = jnp.where(~finite, Status.NOT_CONVERGED, status)
        done = converged | left | ~finite
        return _State(face=face.astype(jnp.int32), ab=ab, status=status.astype(jnp.int32),
                      done=done, patches=s.patches + 1,
                      steps=s.steps + sol.stats["num_steps"].astype(jnp.int32),
                      crossed=s.crossed + jnp.where(inside | left, 0, 1))

    def step(s):
        nxt = body(s)
        return jax.tree.map(lambda n, o: jnp.where(s.done, o, n), nxt, s)

    f0, st0 = f_at(face, ab0)
    at_m0 = (jnp.abs(f0) <= tol) & (st0 == ObjectiveStatus.OK)
    init = _State(face=jnp.asarray(face, jnp.int32), ab=ab0,
                  status=jnp.where(found, jnp.where(at_m0, Status.FOUND, Status.MAX_STEPS),
                                   Status.NO_CROSSING).astype(jnp.int32),
                  done=~found | at_m0, patches=jnp.asarray(0, jnp.int32),
                  steps=jnp.asarray(0, jnp.int32), crossed=jnp.asarray(0, jnp.int32))
    s = jax.lax.while_loop(lambda s: ~s.done & (s.patches < max_patches), step, init)
    f_end, st_end = f_at(s.face, s.ab)
    status = jnp.where((s.status == Status.MAX_STEPS) & (st_end == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION),
                       Status.TOTAL_INTERNAL_REFLECTION, s.status)
    return s._replace(status=status.astype(jnp.int32)), f_end


@functools.partial(jax.jit, static_argnames=("options",))
def _newton_batch(mesh, P, L, face, ab0, found, eta, tol, max_patches,
                  options: Newton) -> Solution:
    eta = jnp.asarray(eta, mesh.dtype)
    tol = jnp.asarray(tol, mesh.dtype)
    n = P.shape[0]
    if options.n_starts > 1:
        key = jax.random.PRNGKey(options.seed)
        w = jax.random.dirichlet(key, jnp.ones(3, mesh.dtype), (n, options.n_starts - 1))
        starts = jnp.concatenate([ab0[:, None], w[..., 1:]], axis=1)  # (n, S, 2)
    else:
        starts = ab0[:, None]
    lane = lambda p, l, f, a, ok: _newton_lane(mesh, p, l, f, a, ok, eta, tol, max_patches, options)  # noqa: E731
    per_start = jax.vmap(lambda a: map_lanes(lane, P, L, face, a, found), in_axes=1, out_axes=1)
    states, f_end = per_start(starts)  # leaves (n, S, ...)
    V, N = mesh.triangle(states.face)
    points = barycentric_point(V, states.ab)
    V0, _ = mesh.triangle(face)
    M0 = barycentric_point(V0, ab0)
    ok = states.status == Status.FOUND
    dist = jnp.where(ok, jnp.linalg.norm(points - M0[:, None], axis=-1), jnp.inf)
    best = jnp.where(jnp.any(ok, axis=1), jnp.argmin(dist, axis=1), 0)
    pick = lambda x: jnp.take_along_axis(x, best.reshape((n, 1) + (1,) * (x.ndim - 2)), axis=1)[:, 0]  # noqa: E731
    status = pick(states.status)
    return Solution(
        point=jnp.where(found[:, None], pick(points), 0),
        triangle=jnp.where(found, pick(states.face), -1),
        barycentric=jnp.where(found[:, None], pick(states.ab), 0),
        found=status == Status.FOUND,
        status=status,
        iterations=jnp.sum(states.steps, axis=1),
        residual=jnp.where(found, pick(f_end), 0),
        crossed=pick(states.crossed),
        start_point=jnp.where(found[:, None], M0, 0),
    )


def solve_newton(mesh, P, L, eta, start, opts: Newton) -> Solution:
    """The Newton baselines on a padded batch (see `walk.solve_walk` for the arguments)."""
    face, ab0, found = start
    return _newton_batch(mesh, P, L, face, ab0, found, eta, opts.tolerance(mesh.dtype),
                         jnp.int32(opts.max_patches), opts.static())
