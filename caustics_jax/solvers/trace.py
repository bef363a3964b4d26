"""Every refraction point on the traced coplanarity curve: the walk of seed 001 §3.4.3,
continued past each root in both directions (`solve(..., method="walk", solutions="all")`).

The walk (`walk.py`) stops at the first root it brackets. Past the focal distance several
paths reach one receiver (docs/irradiance.md: the walk's single path carries a median 41%
of the all-path irradiance there), and they lie on the same coplanarity curve or on
other components of it. This solver follows the curve face by face, like the walk
(`arcs.next_crossing` for the exit of each arc, `mesh.cross_edge` into the neighbour),
but never stops at a root: on each arc it finds every root with the certified arc root
finder of the exhaustive reference (`arc_roots`: Bernstein isolation of Snell's
condition), and walks on until the curve leaves the mesh or closes.

**Which components are traced (`seeds`).** The curve set of a lane is the zero set of
the continuous function `n~(M) . (PL x PM)` on the mesh (seed 001 eq. 9; `n~` is
interpolated linearly along shared edges, so the conics of neighbouring faces meet on
their edge). Away from singular points it is a union of disjoint simple curves, each
either closed or ending on the mesh boundary (it cannot end inside: where it enters a
face through an edge it leaves through another edge, or it closes).

- `"start"`: the component through `M0` (the walk's), in both directions from `M0`
  until it meets the boundary twice or returns to `M0`.
- `"boundary"`: also every component that meets the boundary: the conic's
  roots on every boundary edge are seeds, and each is traced inward to its other end.
  Every open component has two ends on the boundary, so every open component is traced
  (twice: once from each end).

- `"faces"` (default): also the closed components. A closed component that does not
  pass through `M0` (a loop of the curve around a dimple of the surface, or an ellipse
  inside one face) has no boundary root and no start point on it. Its solutions lie on
  faces that the certified reference's cone test keeps (`accel.cones.candidate_faces`: a
  face whose normals and position cannot refract `P -> M -> L` holds no solution), so
  the arcs of every such face are scanned face by face with the reference's root finder
  (`exhaustive.candidate_roots`), and their roots join the traced ones (deduplicated).
  The cost is the reference's scan of those faces (docs/solvers.md measures it).

**Not guaranteed** (with `"start"` and `"boundary"`): the closed components above;
`method="exhaustive"` and `seeds="faces"` find them. Also not guaranteed
where a trace is cut short: more than `max_steps` faces (status `MAX_STEPS`), or more than
`max_arcs` arc pieces with a possible root on one trace (also `MAX_STEPS`), or the curve
lost at a tangency or a singular point (`LOST_CURVE`); the lane's status says so.

Status per lane: `FOUND` where a solution was found (the one nearest `M0` is
`solution`), else the first of `LOST_CURVE`, `MAX_STEPS` that cut a trace short, else
`NO_SOLUTION` (no solution on the traced components), or `NO_CROSSING` where the lane has
neither a start point nor a solution.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..accel.cones import candidate_faces, may_refract, patch_tree
from ..curve.arc_roots import (
    ArcPiece,
    arc_polynomial,
    classify,
    is_straight,
    pieces_of_arc,
)
from ..curve.arcs import arc_from_point, edge_roots, inward
from ..math.conic import conic_coefficients, conic_tangent, edge_intersections
from ..math.objectives import ObjectiveStatus
from ..runtime.arguments import check_choice, check_int, check_real, check_tol
from ..runtime.lane_solver import LaneSolver, Stage, run_lanes
from ..runtime.lanes import padded_index, power_of_two_bucket
from ..surface.mesh import SurfaceMesh, cross_edge
from ._solution import Status
from .exhaustive import Exhaustive, candidate_roots
from .options import SolverOptions, option
from .solution_set import ExhaustiveSolution, assemble, padded_call, piece_polynomials, refine_intervals

#: How a trace ended.
_OPEN, _BOUNDARY, _CLOSED, _LOST, _STEPS, _OVERFLOW = range(6)


class Trace(SolverOptions):
    """All solutions on the traced coplanarity curve (module docstring) and its options.

    tol: acceptance `|f| <= tol`, in `(0, 1)` (default 1e-10 float64, 1e-5 float32).
    seeds: `"faces"` (default: the components `"boundary"` traces, and the arcs of every
        face the cone test keeps, scanned by the certified reference's root finder, so
        closed components are found too), `"boundary"` (the component through `M0` and
        every component that meets the boundary) or `"start"` (only the component through
        `M0`).
    max_steps: faces per trace, in `[1, 2^20]`.
    max_arcs: arc pieces with a possible root recorded per trace, in `[1, 1024]`.
    iters: bisection steps per isolated root, in `[1, 200]`.
    max_depth: Bernstein halvings before an undecided interval becomes one candidate, in
        `[8, 60]` (at most 24 are useful in float32).
    dedupe: two roots closer than this (m) are one solution, `>= 0` (default relative to
        the mesh's largest coordinate `R`, as rounding is: `1e-7 max(1, R / 2)` m in
        float64, `1e-4 max(1, R / 2)` m in float32; the 4 m pools have `R` about 2. A fixed
        1e-4 m counted float32 duplicates 1.7e-4 m apart twice on the pool scaled by 1e3).
    chunk: rows per jitted batch of root refinement, in `[1, 2^20]`.
    """

    method: ClassVar[str] = "trace"

    tol: float | None = option(None, lambda v: check_tol("tol", v))
    seeds: str = option("faces", lambda v: check_choice("seeds", v, ("faces", "boundary", "start")))
    max_steps: int = option(4096, lambda v: check_int("max_steps", v, 1, 2**20))
    max_arcs: int = option(32, lambda v: check_int("max_arcs", v, 1, 1024))
    iters: int = option(60, lambda v: check_int("iters", v, 1, 200))
    max_depth: int = option(48, lambda v: check_int("max_depth", v, 8, 60))
    dedupe: float | None = option(None, lambda v: None if v is None else check_real("dedupe", v, 0.0))
    chunk: int = option(4096, lambda v: check_int("chunk", v, 1, 2**20))

    in_blocks: ClassVar[bool] = False

    def every_path(self) -> bool:
        return True

    def solve_whole(self, prep, P, L, eta, start):
        return solve_trace(prep.mesh, P, L, eta, start, self, prep.padded)

    def dedupe_radius(self, dtype, extent: float = 2.0) -> float:
        """`dedupe`, or its default for a mesh whose largest coordinate is `extent` (m)."""
        if self.dedupe is not None:
            return self.dedupe
        return (1e-7 if jnp.dtype(dtype) == jnp.float64 else 1e-4) * max(1.0, extent / 2)


# --------------------------------------------------------------------------- the trace


def _snap_to_root(coef, edge, t, ab):
    """The conic's root on `edge` nearest the entry parameter `t` (the pencil's anchor must
    lie on this face's conic; the neighbour's crossing agrees only to rounding)."""
    t_all, valid, ab_all = edge_roots(coef)
    e = jnp.clip(edge, 0, 2)
    gap = jnp.where(valid[e], jnp.abs(t_all[e] - t), jnp.inf)
    j = jnp.argmin(gap)
    ok = jnp.isfinite(gap[j]) & (gap[j] <= 1e3 * jnp.sqrt(jnp.finfo(coef.dtype).eps))
    snapped = jnp.where(edge >= 0, ok, True)
    return jnp.where((edge >= 0) & ok, t_all[e, j], t), jnp.where((edge >= 0) & ok, ab_all[e, j], ab), snapped


class TraceState(NamedTuple):
    """A trace between steps: the face it is on, its entry point, travel direction and entry
    edge, the step and arc counts, how it ended (`_OPEN` while running), and the faces and
    pieces of the arcs kept so far (`max_arcs` slots each)."""

    face: jax.Array
    ab: jax.Array
    direction: jax.Array
    entry_edge: jax.Array
    entry_t: jax.Array
    steps: jax.Array
    n_arcs: jax.Array
    end: jax.Array
    faces: jax.Array
    pieces: ArcPiece


class TraceRecord(NamedTuple):
    """A lane of `TraceSolver`: `P`, `L`, where its curve closes (`stop`: face, edge, edge
    parameter of the seed's crossing) and its `TraceState`."""

    P: jax.Array
    L: jax.Array
    stop: tuple
    state: TraceState


class TraceSolver(LaneSolver):
    """Following the curve from one seed as a lane solver (`runtime.lane_solver`): one
    phase, a triangle of the curve per step (its arc, the pieces that may hold a root, the
    crossing), until the curve closes, leaves the mesh, is lost, or a cap is reached.
    A lane is `(P, L, seed)`, `seed = (face, ab, direction, entry_edge, entry_t, stop_face,
    stop_edge, stop_t)`; its stage makes it a `TraceRecord`, each step advances its
    `TraceState`, and `finish` gives `(faces (max_arcs,), pieces ArcPiece (max_arcs,),
    n_arcs, end, steps)` per lane."""

    phases: ClassVar[tuple[str, ...]] = ("trace",)

    mesh: SurfaceMesh
    cones: tuple
    eta: jax.Array
    max_steps: int = eqx.field(static=True)
    max_arcs: int = eqx.field(static=True)

    def stages(self) -> tuple[Stage, ...]:
        def init(lane):
            P, L, (face, ab, direction, entry_edge, entry_t, stop_face, stop_edge, stop_t) = lane
            dtype = ab.dtype
            m = self.max_arcs
            empty = ArcPiece(jnp.zeros((m, 2), dtype), jnp.zeros((m, 2), dtype), jnp.zeros((m, 2), dtype),
                             jnp.zeros(m, dtype), jnp.zeros(m, dtype), jnp.zeros((m, 2), dtype), jnp.zeros(m, bool),
                             jnp.zeros(m, bool))
            state = TraceState(face, ab, direction, entry_edge, entry_t, jnp.int32(0), jnp.int32(0),
                               jnp.int32(_OPEN), jnp.full(m, -1, jnp.int32), empty)
            return TraceRecord(P, L, (stop_face, stop_edge, stop_t), state)

        return (Stage(init),)

    def route(self, rec) -> jax.Array:
        return jnp.where(rec.state.end == _OPEN, 0, -1).astype(jnp.int32)

    def step(self, rec, phase: int | None):
        del phase  # one phase
        P, L, (stop_face, stop_edge, stop_t), s = rec
        mesh, max_arcs = self.mesh, self.max_arcs
        face, ab, direction, entry_edge, entry_t, steps, n_arcs, _, faces_buf, buf = s
        dtype = ab.dtype
        centre, radius, axis, angle = self.cones
        tol_t = 1e3 * jnp.sqrt(jnp.finfo(dtype).eps)
        V, N = mesh.triangle(face)
        coef = conic_coefficients(V, N, P, L)
        entry_t, ab, snapped = _snap_to_root(coef, entry_edge, entry_t, ab)
        arc = arc_from_point(coef, ab, direction, entry_edge, entry_t)
        tau, perp, exit_edge, exit_t, exit_ab, phi = arc.tau, arc.perp, arc.edge, arc.t, arc.ab, arc.phi
        ok = arc.exists & snapped
        pcs = pieces_of_arc(ab, tau, perp, jnp.where(ok, phi, 0), exit_ab, is_straight(coef), ok)
        maybe = may_refract(centre[face], radius[face], axis[face], angle[face], P, L, self.eta)
        G, delta, _ = jax.vmap(lambda pc: arc_polynomial(V, N, P, L, coef, pc, self.eta))(pcs)
        live = ok & maybe & ~classify(G, delta).excluded
        slot = n_arcs + jnp.cumsum(live) - 1
        slot = jnp.where(live & (slot < max_arcs), slot, max_arcs)  # past the end: dropped
        buf = jax.tree.map(lambda b, x: b.at[slot].set(x, mode="drop"), buf, pcs)
        faces_buf = faces_buf.at[slot].set(face, mode="drop")
        n_arcs = n_arcs + jnp.sum(live).astype(jnp.int32)
        g, k_next, t_next, ab_next = cross_edge(mesh, face, exit_edge, exit_t)
        closed = (g == stop_face) & (k_next == stop_edge) & (jnp.abs(t_next - stop_t) <= tol_t)
        end = jnp.where(~ok, _LOST, jnp.where(n_arcs > max_arcs, _OVERFLOW, jnp.where(
            g < 0, _BOUNDARY, jnp.where(closed, _CLOSED, jnp.where(steps + 1 >= self.max_steps, _STEPS, _OPEN)))))
        s = TraceState(jnp.maximum(g, 0), ab_next, inward(k_next, dtype), k_next, t_next, steps + 1,
                       jnp.minimum(n_arcs, max_arcs + 1), end.astype(jnp.int32), faces_buf, buf)
        return rec._replace(state=s)

    def finish(self, rec):
        s = rec.state
        return s.faces, s.pieces, jnp.minimum(s.n_arcs, self.max_arcs), s.end, s.steps


@functools.partial(jax.jit, static_argnames=("max_steps", "max_arcs"))
def _trace(mesh, cones, P, L, eta, seeds, max_steps, max_arcs):
    """Every seed traced in its own loop (`TraceSolver`, chunks of 256 seeds)."""
    solver = TraceSolver(mesh, cones, eta, max_steps, max_arcs)
    return run_lanes(solver, (P, L, tuple(seeds)), scheduler="chunked")


@jax.jit
def _start_seeds(mesh, P, L, face, ab):
    """Both directions of travel from `M0`, each stopping where the other leaves the start
    face (a closed curve returns there). Returns the seed tuple for `2 n` traces."""
    V, N = mesh.triangle(face)
    coef = jax.vmap(conic_coefficients)(V, N, P, L)
    t = jax.vmap(conic_tangent)(coef, ab)

    def exits(c, a, d):
        arc = arc_from_point(c, a, d)
        return jnp.where(arc.exists, arc.edge, -1), arc.t

    e_plus, t_plus = jax.vmap(exits)(coef, ab, t)
    e_minus, t_minus = jax.vmap(exits)(coef, ab, -t)
    n = face.shape[0]
    minus_one = jnp.full(n, -1, jnp.int32)
    cat = lambda a, b: jnp.concatenate([a, b])  # noqa: E731
    return (cat(face, face), cat(ab, ab), cat(t, -t), cat(minus_one, minus_one),
            jnp.zeros(2 * n, ab.dtype), cat(face, face), cat(e_minus, e_plus), cat(t_minus, t_plus))


@jax.jit
def _boundary_roots(mesh, P, L, bface, bedge):
    """`(t, valid)` `(n, B, 2)`: the conic's roots on each boundary edge for lanes `(n, 3)`."""
    V, N = mesh.triangle(bface)

    def lane(p, l):
        coef = conic_coefficients(V, N, p[None], l[None])
        t, valid = edge_intersections(coef)
        rows = jnp.arange(bedge.shape[0])
        return t[rows, bedge], valid[rows, bedge]

    return jax.vmap(lane)(P, L)


def _boundary_seeds(mesh, P, L):
    """Seeds on every boundary edge root: `(lane, seed tuple)`."""
    nb = np.asarray(mesh.neighbors)
    bface, bedge = np.nonzero(nb == -1)
    n = P.shape[0]
    dtype = P.dtype
    if bface.size == 0 or n == 0:
        return np.zeros(0, np.int64), None
    lanes, faces, edges, ts = [], [], [], []
    step = max(1, (1 << 20) // bface.size)
    bf, be = jnp.asarray(bface, jnp.int32), jnp.asarray(bedge, jnp.int32)
    for i in range(0, n, step):
        k = min(step, n - i)
        sel = padded_index(np.arange(i, i + k), power_of_two_bucket(k, 16))
        t, valid = (np.asarray(x)[:k] for x in _boundary_roots(mesh, P[sel], L[sel], bf, be))
        li, bi, ri = np.nonzero(valid)
        lanes.append(li + i)
        faces.append(bface[bi])
        edges.append(bedge[bi])
        ts.append(t[li, bi, ri])
    lane = np.concatenate(lanes)
    face, edge, t = np.concatenate(faces), np.concatenate(edges), np.concatenate(ts)
    ab = np.stack([np.where(edge == 0, t, np.where(edge == 1, 1 - t, 0)),
                   np.where(edge == 0, 0, t)], -1)
    direction = np.asarray([[0.0, 1.0], [-1.0, -1.0], [1.0, 0.0]])[edge]
    m = len(lane)
    seeds = (jnp.asarray(face, jnp.int32), jnp.asarray(ab, dtype), jnp.asarray(direction, dtype),
             jnp.asarray(edge, jnp.int32), jnp.asarray(t, dtype), jnp.full(m, -1, jnp.int32),
             jnp.full(m, -1, jnp.int32), jnp.zeros(m, dtype))
    return lane, seeds


#: Seeds per jitted trace call (one compile for every seed count).
TRACE_BLOCK = 256


def _run_traces(mesh_b, cones, P, L, eta, lane, seeds, options: Trace):
    """Trace every seed, `TRACE_BLOCK` at a time; returns `(lane of each live piece, faces,
    ArcPiece, per-seed end, steps)`."""
    m = len(lane)
    outs = []
    for i in range(0, m, TRACE_BLOCK):
        k = min(TRACE_BLOCK, m - i)
        sel = padded_index(np.arange(i, i + k), TRACE_BLOCK)
        out = _trace(mesh_b, cones, P[lane[sel]], L[lane[sel]], eta, tuple(x[sel] for x in seeds),
                     options.max_steps, options.max_arcs)
        outs.append(jax.tree.map(lambda x, k=k: np.asarray(x)[:k], out))
    faces, pieces, n_arcs, end, steps = jax.tree.map(lambda *xs: np.concatenate(xs), *outs)
    used = np.arange(options.max_arcs)[None] < n_arcs[:, None]
    row, slot = np.nonzero(used)
    return (lane[row], faces[row, slot], ArcPiece(*(x[row, slot] for x in pieces)), end, steps)


def solve_trace(mesh, P, L, eta, start, options: Trace, padded) -> ExhaustiveSolution:
    """`solve(..., method="walk", solutions="all")`: see the module docstring."""
    n, dtype = P.shape[0], mesh.dtype
    tol = options.tolerance(dtype)
    tree = patch_tree(mesh)
    cones = tuple(jnp.asarray(x, dtype) for x in (tree.face_centre, tree.face_radius, tree.face_axis,
                                                 tree.face_angle))
    face0, ab0, found0 = (np.asarray(x) for x in start)
    m0_lanes = np.nonzero(found0)[0]
    seed_lanes, seed_parts = [], []
    if m0_lanes.size:
        g = jnp.asarray(m0_lanes)
        seeds = _start_seeds(padded, P[g], L[g], jnp.asarray(face0[m0_lanes], jnp.int32),
                             jnp.asarray(ab0[m0_lanes], dtype))
        seed_lanes.append(np.concatenate([m0_lanes, m0_lanes]))
        seed_parts.append(seeds)
    if options.seeds in ("boundary", "faces"):
        b_lane, b_seeds = _boundary_seeds(mesh, P, L)
        if b_lane.size:
            seed_lanes.append(b_lane)
            seed_parts.append(b_seeds)
    lanes_rows = np.zeros(0, np.int64)
    faces_rows = np.zeros(0, np.int32)
    pieces = None
    status = np.full(n, -1, np.int64)
    steps_lane = np.zeros(n, np.int64)
    crossed = np.zeros(n, np.int64)
    if seed_lanes:
        lane = np.concatenate(seed_lanes)
        seeds = tuple(jnp.concatenate(parts) for parts in zip(*seed_parts, strict=True))
        lanes_rows, faces_rows, pieces, end, steps = _run_traces(padded, cones, P, L, eta, lane, seeds, options)
        np.add.at(steps_lane, lane, steps)
        if m0_lanes.size:
            np.add.at(crossed, lane[:2 * m0_lanes.size], steps[:2 * m0_lanes.size])
        for code, st in ((_STEPS, Status.MAX_STEPS), (_OVERFLOW, Status.MAX_STEPS), (_LOST, Status.LOST_CURVE)):
            hit = np.zeros(n, bool)
            hit[lane[end == code]] = True
            status = np.where((status < 0) & hit, int(st), status)
    owner, pts, tris, abs_, res = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32),
                                   np.zeros((0, 2)), np.zeros(0))
    depth = options.max_depth if dtype == jnp.float64 else min(options.max_depth, 24)
    refine_opts = options.with_options(max_depth=depth)
    if pieces is not None and len(lanes_rows):
        G, delta = padded_call(
            lambda sl: piece_polynomials(padded, P[lanes_rows[sl]], L[lanes_rows[sl]], jnp.asarray(faces_rows[sl]),
                                          ArcPiece(*(jnp.asarray(x[sl]) for x in pieces)), eta),
            len(lanes_rows), options.chunk)
        row, M, ab, f, st = refine_intervals(padded, P, L, eta, lanes_rows, faces_rows, pieces, G, delta,
                                             refine_opts)
        ok = (np.abs(f) <= tol) & (st == ObjectiveStatus.OK)
        owner, pts, tris, abs_, res = lanes_rows[row[ok]], M[ok], faces_rows[row[ok]], ab[ok], f[ok]
    if options.seeds == "faces":
        # Closed components: the arcs of every face that may refract (the cone test of the
        # certified reference), scanned face by face by the reference's root finder
        # (`exhaustive.candidate_roots`). Every face, traced or not: a traced face may hold
        # another component's arc too.
        c_lane, c_face = (x.astype(np.int32) for x in candidate_faces(mesh, P, L, eta))
        scan = Exhaustive(tol=tol, iters=options.iters, max_depth=depth, chunk=options.chunk)
        pair, M, ab, f, st = candidate_roots(padded, P, L, eta, c_lane, c_face, scan)
        ok = (np.abs(f) <= tol) & (st == ObjectiveStatus.OK)
        owner = np.concatenate([owner, c_lane[pair[ok]]])
        pts, tris = np.concatenate([pts, M[ok]]), np.concatenate([tris, c_face[pair[ok]]])
        abs_, res = np.concatenate([abs_, ab[ok]]), np.concatenate([res, f[ok]])
    extent = float(np.max(np.abs(np.asarray(mesh.vertices)), initial=0.0))
    result = assemble(mesh, P, L, eta, start, tol, options.dedupe_radius(dtype, extent), owner, pts, tris, abs_,
                      res)
    has = result.count > 0
    final = np.where(has, Status.FOUND, np.where(status >= 0, status, np.asarray(result.solution.status)))
    sol = dataclasses.replace(result.solution, status=jnp.asarray(final.astype(np.int32)),
                              iterations=jnp.asarray(steps_lane.astype(np.int32)),
                              crossed=jnp.asarray(crossed.astype(np.int32)))
    return result._replace(solution=sol)


def with_solutions(method, options: dict):
    """`solve`'s `solutions=` option: `"one"` (default: the method as given) or `"all"`
    (`method="walk"` becomes `Trace` with the remaining options; `Exhaustive` returns every
    solution with `return_all=True`; `Trace` always does). Returns `(method, options)`
    without `solutions`."""
    options = dict(options)
    solutions = options.pop("solutions", "one")
    if solutions not in ("one", "all"):
        raise ValueError(f"solutions must be 'one' or 'all', got {solutions!r}")
    if solutions == "one":
        return method, options
    if method == "walk":
        return "trace", options
    if method == "trace" or isinstance(method, Trace):
        return method, options
    if method == "exhaustive":
        return method, {**options, "return_all": True}
    if isinstance(method, Exhaustive):
        return method.with_options(return_all=True), options
    raise ValueError(f"solutions='all' needs method='walk' (the tracer), 'trace' or 'exhaustive', got {method!r}")


def closed_component(mesh, P, L, face, ab, *, eta: float = 1.333, max_steps: int = 4096) -> np.ndarray:
    """`(n,)` True where the curve through the point `(face, ab)` (on the lane's conic, e.g.
    a solution) closes on itself without meeting the boundary: its component has no
    boundary root, so `seeds="boundary"` reaches it only through `M0` (module docstring).
    Both directions are traced from the point, as from `M0`."""
    from ..accel.prepared import prepare

    prep = prepare(mesh)
    dtype = prep.dtype
    P, L = jnp.asarray(P, dtype).reshape(-1, 3), jnp.asarray(L, dtype).reshape(-1, 3)
    n = P.shape[0]
    tree = patch_tree(prep.mesh)
    cones = tuple(jnp.asarray(x, dtype) for x in (tree.face_centre, tree.face_radius, tree.face_axis,
                                                 tree.face_angle))
    seeds = _start_seeds(prep.padded, P, L, jnp.asarray(face, jnp.int32), jnp.asarray(ab, dtype))
    lane = np.concatenate([np.arange(n), np.arange(n)])
    options = Trace(max_steps=max_steps)
    _, _, _, end, _ = _run_traces(prep.padded, cones, P, L, jnp.asarray(eta, dtype), lane, seeds, options)
    return (end[:n] == _CLOSED) & (end[n:] == _CLOSED)
