"""The curve walk of seed 001 §3.4: follow the coplanarity conic from `M0` to a zero of `f`.

Per lane, from the start point `M0` (on the conic by construction, §3.4.2):

1. First triangle: the conic's tangent at `M0` gives two directions of travel. For each,
   the next edge crossing along the curve is found exactly with the pencil of lines
   through the current curve point (`conic_second_intersection`): every point of a conic
   is hit by exactly one line through a given curve point, and the line angle `phi`
   increases monotonically along the curve, so the first crossing in the direction of
   travel is the edge root of smallest `phi`. This also settles the four-intersection
   re-entry case of Fig. 5c without a heuristic. If `f` changes sign between `M0` and a
   crossing, refine there; otherwise walk towards the crossing of smaller `|f|`. With no
   edge crossing at all the curve is an ellipse inside the triangle (§3.4.4): sample it
   through the pencil and bracket a sign change.
2. Walk (§3.4.3): cross the exit edge into the neighbour (adjacency buffer), orient the
   tangent inward, find the next crossing along the curve, evaluate `f`; cross again
   while `f` keeps its sign. The next crossing comes from the conic's signs at the three
   vertices and two edge quadratics (`arcs.sign_test_exit`); where the signs do not decide
   (a curve near a vertex, a re-entry, a pair of roots on one edge), from the pencil order
   of step 1, in the `EXACT` phase: the same exit wherever both decide.
3. Refine ("dichotomy"): the sign change lies on the arc between the entry point and the
   exit; cut the arc by lines through the entry point at angle `phi` (the paper splits
   the triangle so that the new edge cuts the curve; a line through a known curve point
   cuts it exactly once more) and bisect `phi`, or use Illinois false position on `phi`
   (`bracket="illinois"`, the default, same guarantees, fewer steps).

A lane is `FOUND` exactly when `|f| <= tol` at the returned point (`f` = sine of the
angle between the refracted direction and `w_L`, so `tol` bounds the angle error).

Scheduling (`Walk.scheduler`, docs/solvers.md "Throughput and the machine's limit"): under
`vmap` every lane pays for every branch, and a `while_loop` runs until its slowest lane.
`"pool"` (default) computes the first triangle without the ellipse samples for every lane
that has a start point, the 64-sample ellipse search (step 1's rare case) only for the
lanes whose curve has no edge crossing (`pools.map_where`), and steps the lanes in two
slot pools, one for walking lanes (crossings) and one for refining lanes (dichotomy and
TIR-onset search), each refilled from a queue of lanes in its mode (`pools.run_pools`),
so a step computes only the branch its lane needs (a third pool, `EXACT`, crosses the
lanes the vertex signs leave undecided; the first triangles likewise take the sign test
for every lane and the exact construction on the rest). `"chunked"` is the
previous scheduler (every lane computes the ellipse samples; fixed chunks of 256 lanes,
each until its slowest lane), kept for comparison. Both apply the same per-lane functions
(`_first_triangle` and `_start_states`, which `walk_init` composes; `walk_step` and
`walk_turn_back`, which `walk_advance` composes), so statuses and iteration counts
are the same and points equal up to the rounding of each program's vector code
(`tests/test_scheduling.py`, `testing.assert_same_lanes`). The pool runs each pair in two stages, with the
first stage's output stored in between: the first triangle's record (`_Start`), and the
turn-back between two passes of the pools (`_walk_pool`, whose pools then carry only `P`,
`L` and the walk's state). XLA's CPU fusion would otherwise recompute the first stage's
decisions in the kernel of every state field that depends on them, and the generated code
of those copies was most of the program's compile time (docs/solvers.md "Where the walk's
compile time goes").
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..curve.arcs import (
    ArcStart,
    arc_from_point,
    boundary_crossings,
    edge_roots,
    inside,
    inward,
    leaving_at_start,
    next_crossing,
    opposite,
    orientation,
    pencil_angle,
    pencil_point,
    project_to_conic,
    root_between,
    sign_test_exit,
)
from ..math.barycentric import barycentric_point
from ..math.conic import conic_coefficients, conic_tangent
from ..math.objectives import ObjectiveStatus, bracket_objective, path_vectors, signed_sine
from ..runtime.arguments import check_choice, check_int, check_tol
from ..runtime.blocks import on_devices
from ..runtime.lanes import map_lanes
from ..runtime.pools import map_where, pool_slots, run_pools
from ..surface.mesh import SurfaceMesh, cross_edge
from ._solution import Solution, Status, confirm_found
from .options import SolverOptions, option

__all__ = ["Walk", "solve_walk"]

#: Phases of a lane (`_State.mode`): a crossing decided by the vertex signs (`WALK`), a
#: refinement cut (`BISECT`), a crossing by the exact construction (`EXACT`: the lanes
#: the signs leave undecided, `arcs.sign_test_exit`), done. The pool scheduler steps each
#: phase in its own pool (`run_pools`), so the exact construction runs on those lanes only.
WALK, BISECT, EXACT, DONE = 0, 1, 2, 3
SCHEDULERS = ("pool", "chunked")
FALLBACKS = ("newton", "none")


class Walk(SolverOptions):
    """The curve walk of seed 001 §3.4 and its options (`solve(..., method=Walk(...))`).

    tol: accept a point when `|f| <= tol`, in `(0, 1)` (None: 1e-10 in float64, 1e-5 in
        float32, from the float32 audit's 1e-6 noise floor of `f`). Traced.
    max_steps: cap on crossings plus refinement steps per lane, in `[1, 2^31 - 1]`. Traced.
    bracket: "illinois" (false position with the Illinois fix) or "bisection" (the paper).
    ellipse_samples: pencil samples of an ellipse inside the first triangle (§3.4.4),
        in `[2, 4096]`.
    scheduler: "pool" (the rare branches only where needed, a slot pool refilled from a
        queue of unfinished lanes) or "chunked" (the previous scheduler: chunks of 256
        lanes, each until its slowest lane); same per-lane results (module docstring).
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
    scheduler: str = option("pool", lambda v: check_choice("scheduler", v, SCHEDULERS))
    fallback: str = option("newton", lambda v: check_choice("fallback", v, FALLBACKS))


class _State(NamedTuple):
    mode: jax.Array
    status: jax.Array
    face: jax.Array
    exit_k: jax.Array
    exit_t: jax.Array
    exit_ab: jax.Array
    f_exit: jax.Array  # f, its status and its "line" sign g at the exit: the next face's entry
    st_exit: jax.Array
    g_exit: jax.Array
    anchor: jax.Array
    tau: jax.Array
    perp: jax.Array  # tau rotated +90 deg, times the bend sense sigma
    phi_lo: jax.Array
    phi_hi: jax.Array
    f_lo: jax.Array
    f_hi: jax.Array
    ab_lo: jax.Array  # bracket ends as points (for the chord fallback)
    ab_hi: jax.Array
    side: jax.Array  # Illinois: which end was replaced last (-1 lo, +1 hi, 0 none)
    tir_end: jax.Array  # TIR search: which bracket end is totally reflecting (-1 lo, +1 or 2 hi, 0 none)
    best_ab: jax.Array
    best_f: jax.Array
    steps: jax.Array
    crossed: jax.Array


def _frame(mesh, face, P, L):
    V, N = mesh.triangle(face)
    return V, N, conic_coefficients(V, N, P, L)


def _cos_at_P(V, N, P, L, ab):
    """`-w_P . n_s` at points `ab` `(k, 2)`: the cosine of incidence on P's side."""
    _, n_s, w_P, _, _ = path_vectors(V, N, P, L, ab)
    return -jnp.sum(w_P * n_s, axis=-1)


class _Ellipse(NamedTuple):
    """What the ellipse search (`_ellipse_bracket`) needs from the first triangle."""

    coef: jax.Array
    tau: jax.Array
    perp: jax.Array
    near: jax.Array  # (2, 2): the near points of +t0 and -t0
    phi_near: jax.Array  # pencil angle of the +t0 near point
    f_near: jax.Array  # (2,)
    g_near: jax.Array  # (2,)
    st_near: jax.Array  # (2,)


class _Start(NamedTuple):
    """What `_first_triangle` found from `M0`, per lane; `_start_states` builds the walks.

    `flags` holds its booleans (`_FLAGS`) as the bits of one int32: the scheduler stores
    this record before building the states, and a stored value is computed once. XLA's
    CPU fusion copies a cheap producer into every kernel that reads it, so each of the
    two walks' ~25 state fields had recomputed the same chain of ~150 objective-status
    and sign tests. Pairs `(2, ...)` are the `+t0` and `-t0` directions."""

    flags: jax.Array
    face: jax.Array
    ab0: jax.Array
    f0: jax.Array
    k: jax.Array  # exit edges
    t: jax.Array  # exit edge parameters
    ab: jax.Array  # exits
    f: jax.Array  # f at the exits, their status and "line" sign (the next face's entry values)
    st: jax.Array
    g: jax.Array
    phi: jax.Array  # pencil angles of the exits
    phi_near: jax.Array  # pencil angles of the near points
    f_near: jax.Array
    near: jax.Array
    tau: jax.Array
    perp: jax.Array
    ellipse: _Ellipse


def _first_triangle(mesh, P, L, face, ab0, found, eta, tol, lean: bool = False):
    """What the first triangle decides from `M0` (`_Start`): the exits in both directions,
    `f` there, the bracket or the walk direction, terminal conditions; `_start_states`
    builds the two walks from it, and an ellipse inside the triangle is left to
    `_ellipse_bracket`.

    `lean`: the exits from the conic's two boundary crossings (`arcs.boundary_crossings`)
    ordered by their pencil angles from `M0`, instead of `next_crossing` over six edge
    roots; returns `(start, clear)`, and the lanes not `clear` (the signs undecided, `M0`
    on a crossing, a singular tangent) need the exact construction (`lean=False`)."""
    dtype = mesh.dtype
    V, N, coef = _frame(mesh, face, P, L)
    t0 = conic_tangent(coef, ab0)
    singular = jnp.linalg.norm(t0) == 0
    eps = float(np.finfo(dtype).eps)

    # The paper's sign of f flips at M0 (where M crosses the line PL); the "plane"
    # orientation does not, but each direction still starts its bracket a little off M0
    # so that the two brackets share no end point.
    delta0 = 1e4 * eps

    if lean:
        bc = boundary_crossings(coef)
        v_x = bc.ab - ab0
        dist_x = jnp.linalg.norm(v_x, axis=-1)
        scale_x = jnp.sum(jnp.abs(bc.ab), axis=-1) + jnp.sum(jnp.abs(ab0))
        # M0 away from both crossings: `leaving_at_start` changes nothing and
        # `next_crossing` drops no candidate, so the smaller pencil angle is its exit.
        clear = bc.clear & ~singular & jnp.all(dist_x > 8 * eps * scale_x)

        def crossing(tau, perp):
            phi = pencil_angle(v_x, tau, perp, dist_x, scale_x)
            i = jnp.argmin(phi)
            return jnp.asarray(True), bc.edge[i], bc.t[i], bc.ab[i], phi[i]
    else:
        roots = edge_roots(coef)

        def crossing(tau, perp):
            return leaving_at_start(roots, ab0, tau, next_crossing(roots, ab0, tau, perp))

    def direction(sign):
        tau, perp = orientation(coef, ab0, sign * t0)
        ok, k, t, ab, phi = crossing(tau, perp)
        room = jnp.linalg.norm(ab - ab0)
        delta = jnp.where(ok, jnp.minimum(delta0, 0.25 * room), delta0)
        near = project_to_conic(coef, ab0 + delta * tau)
        v = near - ab0
        phi_s = jnp.arctan2(v @ perp, v @ tau)
        phi_s = jnp.clip(phi_s, 0, jnp.where(ok, phi / 2, jnp.pi / 2))
        return ok, k, t, ab, phi, tau, perp, phi_s, near, room

    # Both directions in one vmap (+t0, -t0): one compiled copy of the crossing search.
    dirs = jax.vmap(direction)(jnp.asarray([1.0, -1.0], dtype))
    ok_pm, _, _, ab_pm, phi_pm, _, _, phis_pm, near_pm, room_pm = dirs
    (okp, okm), (abp, abm), (phip, phim) = ok_pm, ab_pm, phi_pm
    (nearp, nearm), (roomp, roomm), phisp = near_pm, room_pm, phis_pm[0]

    # The frame of the pencil at M0, for an ellipse inside the triangle (`_ellipse_bracket`).
    tau_e, perp_e = orientation(coef, ab0, t0)
    # f at M0, the two exits and the two near points (the ellipse samples apart, in
    # `_ellipse_bracket`: one batch of 5 points here, rounded alike by both schedulers).
    f_all, st_all, g_all = bracket_objective(V, N, P, L, jnp.stack([ab0, abp, abm, nearp, nearm]), eta)
    gp, gm, gsp, gsm = g_all[1], g_all[2], g_all[3], g_all[4]
    f0, fp, fm, fsp, fsm = f_all[:5]
    st0, stp, stm = st_all[0], st_all[1], st_all[2]
    # No room for a near point: f is continuous, so the exit's sign stands for the arc.
    fsp = jnp.where(okp & (roomp < 4 * delta0), fp, fsp)
    fsm = jnp.where(okm & (roomm < 4 * delta0), fm, fsm)
    gsp = jnp.where(okp & (roomp < 4 * delta0), gp, gsp)
    gsm = jnp.where(okm & (roomm < 4 * delta0), gm, gsm)

    OK = ObjectiveStatus.OK
    br_p = okp & root_between((fsp, gsp), (fp, gp)) & (stp == OK) & (st_all[3] == OK)
    br_m = okm & root_between((fsm, gsm), (fm, gm)) & (stm == OK) & (st_all[4] == OK)
    use_m_bracket = br_m & (~br_p | (phim < phip))
    # Walk direction without a bracket: out of total internal reflection first (towards
    # the larger cosine at P's side), else towards the smaller |f|.
    tirp, tirm = stp == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION, stm == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION
    cos_p, cos_m = _cos_at_P(V, N, P, L, jnp.stack([abp, abm]))
    prefer_m = jnp.where(tirp != tirm, tirp, jnp.where(tirp, cos_m > cos_p, jnp.abs(fm) < jnp.abs(fp)))

    walk_m = okm & (~okp | prefer_m)
    TIR, DEG = ObjectiveStatus.TOTAL_INTERNAL_REFLECTION, ObjectiveStatus.DEGENERATE
    at_m0 = (jnp.abs(f0) <= tol) & (st0 == OK)  # M0 itself is a solution
    # An exit whose refracted ray points away from L (BACKWARD, past 90 degrees from w_L)
    # ends an arc like TIR does: f is no bracket end there, but the root can lie between
    # the near point and the onset (a receiver 0.1 m under a flat surface: f 0.21 at the
    # near point, -0.99 BACKWARD at the exit, the solution 0.017 m from M0 on that arc).
    lost = lambda st: (st == TIR) | (st == ObjectiveStatus.BACKWARD)  # noqa: E731
    flags = dict(
        found=found, is_ellipse=~okp & ~okm, br_p=br_p, br_m=br_m, use_m_bracket=use_m_bracket, walk_m=walk_m,
        # The arc of each direction runs into TIR (or BACKWARD) from a transmitting near point.
        tir_arc_p=okp & (st_all[3] == OK) & lost(stp), tir_arc_m=okm & (st_all[4] == OK) & lost(stm),
        # ... or out of it: M0 totally reflecting (or BACKWARD), the exit transmitting, the
        # root between the onset and the exit (as `_walk_update`'s tir_end -1).
        tir_out_p=okp & lost(st_all[3]) & (stp == OK), tir_out_m=okm & lost(st_all[4]) & (stm == OK),
        degenerate_exit_p=stp == DEG, degenerate_exit_m=stm == DEG, at_m0=at_m0,
        # A singular conic at a solution M0 does not matter (P, L and the normal aligned
        # on a flat surface make every point of the plane "coplanar"): M0 stays FOUND.
        degenerate=(singular & ~at_m0) | (st0 == DEG), okp=okp, okm=okm)
    ellipse = _Ellipse(coef, tau_e, perp_e, jnp.stack([nearp, nearm]), phisp, jnp.stack([fsp, fsm]),
                       jnp.stack([gsp, gsm]), st_all[3:5])
    _, k, t, ab, phi, tau, perp, phi_s, near, _ = dirs
    start = _Start(_pack_flags(flags), face.astype(jnp.int32), ab0, f0, k, t, ab, jnp.stack([fp, fm]),
                   jnp.stack([stp, stm]), jnp.stack([gp, gm]), phi, phi_s, jnp.stack([fsp, fsm]), near, tau, perp,
                   ellipse)
    return (start, clear) if lean else start


#: The booleans of `_Start.flags`, bit i = name i.
_FLAGS = ("found", "is_ellipse", "br_p", "br_m", "use_m_bracket", "walk_m", "tir_arc_p", "tir_arc_m",
          "degenerate_exit_p", "degenerate_exit_m", "at_m0", "degenerate", "okp", "okm", "tir_out_p", "tir_out_m")


def _pack_flags(flags: dict) -> jax.Array:
    """`_FLAGS` as the bits of one int32 (`_Start`)."""
    return sum(flags[name].astype(jnp.int32) << i for i, name in enumerate(_FLAGS))


def _unpack_flags(bits) -> dict:
    return {name: (bits >> i) & 1 == 1 for i, name in enumerate(_FLAGS)}


def _start_states(start: _Start):
    """The initial state of both walks from `M0` (`_first_triangle`'s decisions), or a
    terminal status.

    Returns `(can_turn, state, other, is_ellipse, ellipse)`: `other` walks the other way
    from the one chosen; `can_turn` says whether that second way exists (a walk that
    started without a bracket, with an exit in both directions). Both share every
    evaluation of `f`. `is_ellipse`: the curve has no edge crossing (§3.4.4); there the
    state reads `UNRESOLVED_ELLIPSE` (unless `M0` is a solution, degenerate, or has no
    start point) until `_ellipse_bracket` has sampled the curve (`ellipse`: its inputs).
    """
    fl = _unpack_flags(start.flags)
    is_ellipse, br_p, br_m, found = fl["is_ellipse"], fl["br_p"], fl["br_m"], fl["found"]
    dtype = start.f0.dtype
    e = start.ellipse
    # Placeholders where the curve is an ellipse: `_ellipse_bracket` fills the bracket in.
    phis_all, fs_all, pts = jnp.zeros(2, dtype), jnp.zeros(2, dtype), jnp.zeros((2, 2), dtype)
    j, ellipse_bracket = 0, jnp.asarray(False)
    pm = lambda x, m: jnp.where(m, x[1], x[0])  # noqa: E731  (the -t0 or the +t0 direction)

    def build(walk_m):
        bracket = jnp.where(is_ellipse, ellipse_bracket, br_p | br_m)
        use_m = fl["use_m_bracket"] | (~(br_p | br_m) & walk_m)
        # No sign change, and the arc of the walk direction runs into TIR: search it
        # towards the onset first (`_bisect_update`; P within 1e-6 m of the surface puts
        # the root 1e-9 m from M0 and the rest of the triangle in TIR). Without a root
        # there the walk goes on as before (tir_end = 2).
        tir_arc = jnp.where(walk_m, fl["tir_arc_m"], fl["tir_arc_p"])
        tir_out = jnp.where(walk_m, fl["tir_out_m"], fl["tir_out_p"])
        search = ~is_ellipse & ~(br_p | br_m) & (tir_arc | tir_out)
        tau = jnp.where(is_ellipse, e.tau, pm(start.tau, use_m))
        perp = jnp.where(is_ellipse, e.perp, pm(start.perp, use_m))
        phi_lo = jnp.where(is_ellipse, phis_all[j], pm(start.phi_near, use_m))
        phi_hi = jnp.where(is_ellipse, phis_all[j + 1], pm(start.phi, use_m))
        f_lo = jnp.where(is_ellipse, fs_all[j], pm(start.f_near, use_m))
        f_hi = jnp.where(is_ellipse, fs_all[j + 1], pm(start.f, use_m))
        ab_lo = jnp.where(is_ellipse, pts[j], pm(start.near, use_m))
        ab_hi = jnp.where(is_ellipse, pts[j + 1], pm(start.ab, use_m))

        pick_m = walk_m
        degenerate_exit = jnp.where(pick_m, fl["degenerate_exit_m"], fl["degenerate_exit_p"])

        status = jnp.asarray(Status.FOUND, jnp.int32)
        mode = jnp.where(bracket | search, BISECT, WALK)
        # A walk may start inside total internal reflection (M0 beyond the critical angle):
        # it walks on until f is defined again, so only a degenerate exit stops it here.
        mode = jnp.where(~bracket & degenerate_exit, DONE, mode)
        status = jnp.where(~bracket & degenerate_exit, Status.DEGENERATE, status)
        mode = jnp.where(is_ellipse & ~ellipse_bracket, DONE, mode)
        status = jnp.where(is_ellipse & ~ellipse_bracket, Status.UNRESOLVED_ELLIPSE, status)
        mode = jnp.where(fl["at_m0"], DONE, mode)
        status = jnp.where(fl["at_m0"], Status.FOUND, status)
        # Terminal conditions that override everything else, most specific last.
        mode = jnp.where(fl["degenerate"], DONE, mode)
        status = jnp.where(fl["degenerate"], Status.DEGENERATE, status)
        mode = jnp.where(found, mode, DONE)
        status = jnp.where(found, status, Status.NO_CROSSING)

        searching = search & (mode == BISECT)
        can_flip = ((mode == WALK) | searching) & fl["okp"] & fl["okm"]
        return can_flip, _State(
            mode=mode.astype(jnp.int32), status=status.astype(jnp.int32), face=start.face,
            exit_k=pm(start.k, pick_m), exit_t=pm(start.t, pick_m), exit_ab=pm(start.ab, pick_m),
            f_exit=pm(start.f, pick_m), st_exit=pm(start.st, pick_m), g_exit=pm(start.g, pick_m),
            anchor=start.ab0, tau=tau, perp=perp, phi_lo=phi_lo, phi_hi=phi_hi, f_lo=f_lo, f_hi=f_hi,
            ab_lo=ab_lo, ab_hi=ab_hi, side=jnp.asarray(0, jnp.int32),
            tir_end=jnp.where(searching, jnp.where(tir_arc, 2, -1), 0).astype(jnp.int32),
            best_ab=start.ab0,
            best_f=start.f0, steps=jnp.asarray(0, jnp.int32), crossed=jnp.asarray(0, jnp.int32),
        )

    # The chosen way and the other way in one vmap: one compiled copy of `build`.
    walk_m = fl["walk_m"]
    flips, states = jax.vmap(build)(jnp.stack([walk_m, ~walk_m]))
    can_flip, state, other = flips[0], jax.tree.map(lambda x: x[0], states), jax.tree.map(lambda x: x[1], states)
    return can_flip, state, other, is_ellipse, e


def _ellipse_bracket(mesh, P, L, eta, n_ellipse, s: _State, e: _Ellipse) -> _State:
    """The curve is an ellipse inside the first triangle (seed 001 §3.4.4): sample it at
    `n_ellipse` pencil angles through `M0`, from just after `M0` (the near point of +t0)
    to just before it (the near point of -t0), so that no stretch is left out, and
    bracket the first sign change of `f`. A lane `_first_triangle` left unresolved starts
    refining there; without a sign change it stays `UNRESOLVED_ELLIPSE`."""
    dtype = s.anchor.dtype
    ab0 = s.anchor
    V, N = mesh.triangle(s.face)
    phis = jnp.pi * jnp.arange(1, n_ellipse, dtype=dtype) / n_ellipse
    pts, pts_ok = jax.vmap(lambda p: pencil_point(e.coef, ab0, e.tau, e.perp, p))(phis)
    f_e, st_e, g_e = bracket_objective(V, N, P, L, pts, eta)
    v = e.near[1] - ab0
    phi_nm = jnp.arctan2(v @ e.perp, v @ e.tau)
    phi_nm = jnp.where(phi_nm < 0, phi_nm + jnp.pi, phi_nm)
    phis_all = jnp.concatenate([e.phi_near[None], phis, phi_nm[None]])
    pts = jnp.concatenate([e.near[:1], pts, e.near[1:]])
    fs_all = jnp.concatenate([e.f_near[:1], f_e, e.f_near[1:]])
    gs = jnp.concatenate([e.g_near[:1], g_e, e.g_near[1:]])
    sts = jnp.concatenate([e.st_near[:1], st_e, e.st_near[1:]])
    ok_all = jnp.concatenate([jnp.ones(1, bool), pts_ok, jnp.ones(1, bool)]) & (sts == ObjectiveStatus.OK)
    change = root_between((fs_all[:-1], gs[:-1]), (fs_all[1:], gs[1:])) & ok_all[:-1] & ok_all[1:]
    j = jnp.argmax(change)
    opened = change[j] & (s.status == Status.UNRESOLVED_ELLIPSE)
    return s._replace(
        mode=jnp.where(opened, BISECT, s.mode).astype(jnp.int32),
        status=jnp.where(opened, Status.FOUND, s.status).astype(jnp.int32),
        phi_lo=jnp.where(opened, phis_all[j], s.phi_lo), phi_hi=jnp.where(opened, phis_all[j + 1], s.phi_hi),
        f_lo=jnp.where(opened, fs_all[j], s.f_lo), f_hi=jnp.where(opened, fs_all[j + 1], s.f_hi),
        ab_lo=jnp.where(opened, pts[j], s.ab_lo), ab_hi=jnp.where(opened, pts[j + 1], s.ab_hi))


def _walk_geometry(mesh, coef, g, k_in, t_in, e):
    """Enter face `g` at `e` (entry edge `k_in`): inward travel direction, next crossing."""
    return arc_from_point(coef, e, inward(k_in, coef.dtype), k_in, t_in)


def _lean_walk_geometry(coef, k_in, t_in, e):
    """`_walk_geometry` with the exit from the vertex signs (`arcs.sign_test_exit`):
    `(clear, ArcStart)`; where not clear the lane takes the exact construction."""
    clear, k, t, ab = sign_test_exit(coef, k_in, t_in)
    tangent = conic_tangent(coef, e)
    side = tangent @ inward(k_in, coef.dtype)
    tau, perp = orientation(coef, e, jnp.where(side < 0, -tangent, tangent))
    v = ab - e
    phi = pencil_angle(v, tau, perp, jnp.linalg.norm(v), jnp.sum(jnp.abs(ab)) + jnp.sum(jnp.abs(e)))
    return clear, ArcStart(side, tau, perp, jnp.asarray(True), k, t, ab, phi)


def _walk_update(s: _State, g, e, geometry, fx, stx, gx, tol) -> _State:
    """Cross into `g`; bracket if f changes sign on its arc, else schedule the next crossing.

    `fx, stx, gx`: `bracket_objective` at the new exit. At the entry `e` they are the
    previous exit's (`s.f_exit`, ...): the same point of the curve, where the interpolated
    normals of the two faces agree (a shared edge interpolates its two vertex normals), so
    `f` is computed once per point of the walk."""
    side, tau, perp, ok, k, tt, ab, phi = geometry
    left = g < 0
    f_e, st_e, g_e = s.f_exit, s.st_exit, s.g_exit
    e_ok, x_ok = st_e == ObjectiveStatus.OK, stx == ObjectiveStatus.OK
    found_e = e_ok & (jnp.abs(f_e) <= tol)
    found_x = ok & x_ok & (jnp.abs(fx) <= tol)
    # Entering the neighbour at `M0` itself (the first triangle left through the edge `M0`
    # lies on: `arcs.leaving_at_start`, exit angle 0): `g`'s "line" sign is undefined at a
    # point of the line PL, so there a sign change of `f` alone brackets (`f` is continuous
    # through `M0`, `signed_sine_and_status`).
    from_m0 = s.phi_hi == 0
    bracket = ok & e_ok & x_ok & (root_between((f_e, g_e), (fx, gx)) | (from_m0 & opposite(f_e, fx)))
    lost = ~ok | (side == 0)
    # An arc from a transmitting point to a totally reflecting one (or back) may hold a
    # root between the transmitting end and the onset of TIR, where neither end shows a
    # sign change (grazing light: the solution lies within 1e-5 m of the onset). Search
    # it towards the onset (`_bisect_update`) as the exhaustive reference does. Without a
    # root there, a walk into TIR ends (no root ahead on this branch); a walk out of it
    # goes on (inside TIR f is undefined).
    TIR, BACKWARD = ObjectiveStatus.TOTAL_INTERNAL_REFLECTION, ObjectiveStatus.BACKWARD
    # An arc into BACKWARD (the refracted ray turns away from L) is searched the same way
    # (a receiver 0.1 m under a wave: f 0.007 at the entry, -0.99 BACKWARD at the exit, the
    # root between); without a root there the walk goes on (2), as it always did through
    # BACKWARD stretches.
    tir_end = jnp.where(ok & e_ok & (stx == TIR), 1, jnp.where(ok & e_ok & (stx == BACKWARD), 2, jnp.where(
        ok & ((st_e == TIR) | (st_e == BACKWARD)) & x_ok, -1, 0)))

    status, mode = s.status, jnp.where(bracket | (tir_end != 0), BISECT, WALK)
    for cond, code in ((lost, Status.LOST_CURVE),
                       (found_x, Status.FOUND), (found_e, Status.FOUND), (left, Status.LEFT_MESH)):
        mode = jnp.where(cond, DONE, mode)
        status = jnp.where(cond, code, status)
    best_ab = jnp.where(found_x & ~found_e, ab, e)
    best_f = jnp.where(found_x & ~found_e, fx, f_e)
    face = jnp.where(left, s.face, g)
    best_ab = jnp.where(left, s.exit_ab, best_ab)
    best_f = jnp.where(left, s.f_exit, best_f)
    return s._replace(
        mode=mode.astype(jnp.int32), status=status.astype(jnp.int32), face=face,
        exit_k=k, exit_t=tt, exit_ab=ab, f_exit=fx, st_exit=stx.astype(jnp.int32), g_exit=gx, anchor=e,
        tau=tau, perp=perp,
        phi_lo=jnp.zeros_like(phi), phi_hi=phi, f_lo=f_e, f_hi=fx, ab_lo=e, ab_hi=ab,
        side=jnp.zeros_like(s.side), tir_end=tir_end.astype(jnp.int32),
        best_ab=best_ab, best_f=best_f, steps=s.steps + 1, crossed=s.crossed + jnp.where(left, 0, 1),
    )


def _chord_point(coef, ab_lo, ab_hi, lam):
    """Curve point cut by the normal line at `lam` along the chord (well-conditioned on short arcs)."""
    q = ab_lo + lam * (ab_hi - ab_lo)
    p = project_to_conic(coef, q)
    chord = ab_hi - ab_lo
    along = (p - ab_lo) @ chord
    ok = (along > 0) & (along < chord @ chord)
    return p, ok


def _bisect_geometry(coef, s: _State, illinois: bool):
    """The next cut of the bracketed arc ("dichotomy", seed 001 §3.4.3).

    The arc is cut by the conic's normal line through the chord point at `lam` (midpoint,
    or Illinois false position): well-conditioned on the nearly straight arcs of a fine
    mesh. Where that cut leaves the bracket (a strongly curved arc, e.g. an ellipse), the
    cut is the line through the anchor at the interpolated pencil angle `phi`, exact on
    any arc but ill-conditioned in float32 when the whole arc spans a tiny angle.
    """
    denom = s.f_hi - s.f_lo
    lam = 0.5
    if illinois:
        frac = -s.f_lo / jnp.where(denom != 0, denom, 1)  # false position, from the lo end
        lam = jnp.where(denom != 0, jnp.clip(frac, 1e-6, 1 - 1e-6), 0.5)
        lam = jnp.where(s.tir_end != 0, 0.5, lam)  # f is 0 at a TIR end: no false position
    phi_try = s.phi_lo + lam * (s.phi_hi - s.phi_lo)
    p_pencil, ok_pencil = pencil_point(coef, s.anchor, s.tau, s.perp, phi_try)
    p_chord, ok_chord = _chord_point(coef, s.ab_lo, s.ab_hi, lam)
    # The bracketed arc lies in the triangle; a cut landing outside it hit another piece
    # of the conic (possible for the chord cut near a tangency with an edge).
    ok_pencil = ok_pencil & inside(p_pencil)
    ok_chord = ok_chord & inside(p_chord)
    p = jnp.where(ok_chord, p_chord, p_pencil)
    v = p - s.anchor
    phi = jnp.where(ok_chord, jnp.arctan2(v @ s.perp, v @ s.tau), phi_try)
    return p, phi, ok_pencil | ok_chord, ok_chord


def _bisect_update(s: _State, p, phi, ok, fm, stm, tol, illinois: bool, chord) -> _State:
    """Replace a bracket end by the cut `p` (pencil angle `phi`, from the chord cut where
    `chord`), or end the lane: FOUND, a stalled bracket, a TIR search without a root."""
    transmits = stm == ObjectiveStatus.OK
    searching = s.tir_end != 0
    # In a search a BACKWARD cut sits on the far side of the onset, as a TIR one does.
    tir_mid = searching & ((stm == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION) | (stm == ObjectiveStatus.BACKWARD))
    ok = ok & (transmits | tir_mid)
    to_hi = opposite(fm, s.f_lo)  # the root lies between lo and p: p becomes the new hi
    # TIR search (`_walk_update`): p replaces the TIR end when it reflects too, or when f
    # changed sign against the transmitting end (then [that end, p] is a plain bracket);
    # otherwise p replaces the transmitting end, closing in on the onset of TIR.
    f_ok_end = jnp.where(s.tir_end > 0, s.f_lo, s.f_hi)
    flipped = transmits & opposite(fm, f_ok_end)
    replace_tir_end = tir_mid | flipped
    to_hi = jnp.where(searching, jnp.where(s.tir_end > 0, replace_tir_end, ~replace_tir_end), to_hi)
    tir_end = jnp.where(flipped, 0, s.tir_end)
    phi_lo = jnp.where(to_hi, s.phi_lo, phi)
    phi_hi = jnp.where(to_hi, phi, s.phi_hi)
    ab_lo = jnp.where(to_hi, s.ab_lo, p)
    ab_hi = jnp.where(to_hi, p, s.ab_hi)
    f_lo = jnp.where(to_hi, s.f_lo, fm)
    f_hi = jnp.where(to_hi, fm, s.f_hi)
    if illinois:  # halve the stale end's value when the same end is kept twice
        side = jnp.where(searching, 0, jnp.where(to_hi, 1, -1))
        f_lo = jnp.where(to_hi & (s.side == 1), f_lo / 2, f_lo)
        f_hi = jnp.where(~to_hi & (s.side == -1), f_hi / 2, f_hi)
    else:
        side = s.side
    found = ok & transmits & (jnp.abs(fm) <= tol)
    eps = jnp.finfo(p.dtype).eps
    # The pencil angle only measures a curved arc: on a straight one (a line conic along
    # the tangent, e.g. a flat surface) every chord cut has phi = 0 up to rounding, so
    # there the bracket is judged by its end points alone. After a chord cut `phi` is only
    # derived from the point (`atan2`), with an absolute rounding of about eps |ab| / |v|:
    # on a nearly straight arc (phi 0.002, chord 0.38) hundreds of times the threshold, so
    # a "stall" in phi there is a coin flip of rounding (float32 lanes of stress_grazing
    # had ended NOT_CONVERGED with the ends 1.5e-5 apart, the GLSL walk and the testbed
    # flipping differently). Only a pencil cut, which cuts at `phi` itself, stalls in phi.
    curved = jnp.maximum(jnp.abs(phi_lo), jnp.abs(phi_hi)) > jnp.sqrt(eps)
    stalled = (jnp.linalg.norm(ab_hi - ab_lo) <= 4 * eps * jnp.maximum(jnp.linalg.norm(ab_hi), 1)) | (
        curved & ~chord & (jnp.abs(phi_hi - phi_lo) <= 4 * eps * jnp.maximum(jnp.abs(phi_hi), 1e-30)))
    mode = jnp.where(found | stalled | ~ok, DONE, BISECT)
    status = jnp.where(found, Status.FOUND, jnp.where(stalled | ~ok, Status.NOT_CONVERGED, s.status))
    # A TIR search that closed in on the onset without a sign change found no root: a walk
    # into TIR ends there (tir_end 1), a walk out of it (-1) or out of the first triangle
    # (2) goes on from the arc's exit.
    no_root = stalled & ~found & (tir_end != 0)
    mode = jnp.where(no_root, jnp.where(tir_end == 1, DONE, WALK), mode)
    status = jnp.where(no_root, jnp.where(tir_end == 1, Status.TOTAL_INTERNAL_REFLECTION, s.status), status)
    better = ok & transmits & (jnp.abs(fm) < jnp.abs(s.best_f))
    keep = lambda new, old: jnp.where(ok, new, old)  # noqa: E731
    return s._replace(
        mode=mode.astype(jnp.int32), status=status.astype(jnp.int32),
        phi_lo=keep(phi_lo, s.phi_lo), phi_hi=keep(phi_hi, s.phi_hi),
        f_lo=keep(f_lo, s.f_lo), f_hi=keep(f_hi, s.f_hi),
        ab_lo=keep(ab_lo, s.ab_lo), ab_hi=keep(ab_hi, s.ab_hi),
        side=jnp.asarray(side, jnp.int32), tir_end=keep(tir_end, s.tir_end).astype(jnp.int32),
        best_ab=jnp.where(better | found, p, s.best_ab), best_f=jnp.where(better | found, fm, s.best_f),
        steps=s.steps + 1,
    )


def _step(mesh, P, L, eta, tol, illinois, s: _State) -> _State:
    """One iteration: a triangle crossing (WALK) or a refinement cut (BISECT).

    Under `vmap` both branches run for every lane, so they share one triangle gather,
    one conic and one evaluation of `f` (the new exit, or the cut) instead of two of each.
    """
    walking = s.mode == WALK
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = _frame(mesh, jnp.where(walking, g, s.face), P, L)
    walk_geo = _walk_geometry(mesh, coef, g, k_in, t_in, e)
    p, phi, ok, chord = _bisect_geometry(coef, s, illinois)
    f1, st1, g1 = bracket_objective(V, N, P, L, jnp.where(walking, walk_geo[6], p)[None], eta)
    walked = _walk_update(s, g, e, walk_geo, f1[0], st1[0], g1[0], tol)
    refined = _bisect_update(s, p, phi, ok, f1[0], st1[0], tol, illinois, chord)
    return jax.tree.map(lambda w, b: jnp.where(walking, w, b), walked, refined)


class LaneState(NamedTuple):
    """What one lane carries through the walk: its receiver and light, the walk state, and
    the turn-back (`walk_lane`): whether it turned already, whether it can, and the walk
    the other way from `M0`."""

    P: jax.Array
    L: jax.Array
    state: _State
    turned: jax.Array
    can_flip: jax.Array
    other: _State


def _walk_branch(mesh, P, L, eta, tol, s: _State) -> _State:
    """`_step` for a lane in WALK mode: only the crossing is computed."""
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = _frame(mesh, g, P, L)
    walk_geo = _walk_geometry(mesh, coef, g, k_in, t_in, e)
    f1, st1, g1 = bracket_objective(V, N, P, L, walk_geo[6][None], eta)
    return _walk_update(s, g, e, walk_geo, f1[0], st1[0], g1[0], tol)


def _lean_walk_branch(mesh, P, L, eta, tol, s: _State) -> _State:
    """`_walk_branch` with the sign-test exit (`_lean_walk_geometry`); a lane the signs
    leave undecided, or leaving the mesh, is returned unchanged in the `EXACT` phase."""
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = _frame(mesh, g, P, L)
    clear, geometry = _lean_walk_geometry(coef, k_in, t_in, e)
    f1, st1, g1 = bracket_objective(V, N, P, L, geometry.ab[None], eta)
    walked = _walk_update(s, g, e, geometry, f1[0], st1[0], g1[0], tol)
    decided = clear & (g >= 0)
    return jax.tree.map(lambda w, o: jnp.where(decided, w, o), walked, s._replace(mode=jnp.int32(EXACT)))


def _bisect_branch(mesh, P, L, eta, tol, illinois, s: _State) -> _State:
    """`_step` for a lane in BISECT mode: only the refinement cut is computed."""
    V, N, coef = _frame(mesh, s.face, P, L)
    p, phi, ok, chord = _bisect_geometry(coef, s, illinois)
    f1, st1, _ = bracket_objective(V, N, P, L, p[None], eta)
    return _bisect_update(s, p, phi, ok, f1[0], st1[0], tol, illinois, chord)


def walk_init(mesh: SurfaceMesh, P, L, face, ab0, found, eta, tol, options: Walk):
    """A lane's `LaneState` before its first step (the first triangle, §3.4.2-3.4.3),
    whether its curve is an ellipse inside that triangle (then `walk_ellipse` completes
    the state), and what the ellipse search needs."""
    can_flip, state, other, is_ellipse, ellipse = _start_states(_first_triangle(mesh, P, L, face, ab0, found, eta, tol))
    return LaneState(P, L, state, jnp.asarray(False), can_flip, other), is_ellipse, ellipse


def walk_ellipse(mesh: SurfaceMesh, eta, options: Walk, lane: LaneState, ellipse: _Ellipse) -> LaneState:
    """The first triangle of a lane whose curve is an ellipse inside it (§3.4.4): its
    `ellipse_samples` pencil samples and the bracket they give (`_ellipse_bracket`)."""
    return lane._replace(state=_ellipse_bracket(mesh, lane.P, lane.L, eta, options.ellipse_samples, lane.state,
                                                ellipse))


def walk_step(mesh: SurfaceMesh, eta, tol, options: Walk, lane: LaneState, mode: int | None = None) -> LaneState:
    """One iteration of a lane (`_step`: a crossing or a refinement cut), before the
    turn-back (`walk_turn_back`). A lane already done is returned unchanged. `mode` computes only
    that phase's branch, for a lane known to be in it (the pool scheduler): `WALK` the
    sign-test crossing (a lane it leaves undecided moves to `EXACT` without a step),
    `EXACT` the crossing by the exact construction, `BISECT` the refinement cut; None
    computes the exact crossing and the cut and selects (one vmapped program for all
    lanes, the chunked scheduler)."""
    s = lane.state
    illinois = options.bracket == "illinois"
    if mode == WALK:
        nxt = _lean_walk_branch(mesh, lane.P, lane.L, eta, tol, s)
    elif mode == EXACT:
        nxt = _walk_branch(mesh, lane.P, lane.L, eta, tol, s)
    elif mode == BISECT:
        nxt = _bisect_branch(mesh, lane.P, lane.L, eta, tol, illinois, s)
    else:
        nxt = _step(mesh, lane.P, lane.L, eta, tol, illinois, s)
    return lane._replace(state=jax.tree.map(lambda n, o: jnp.where(s.mode == DONE, o, n), nxt, s))


def walk_turn_back(lane: LaneState) -> LaneState:
    """The turn-back (`walk_lane`): a walk that failed (done, not FOUND) restarts once from
    `M0` the other way, keeping its step count. Idempotent: a lane that cannot turn, or
    already turned, or is not done, is returned unchanged."""
    s = lane.state
    failed = (s.mode == DONE) & (s.status != Status.FOUND) & lane.can_flip & ~lane.turned
    restart = lane.other._replace(steps=s.steps, crossed=s.crossed)
    return lane._replace(state=jax.tree.map(lambda r, n: jnp.where(failed, r, n), restart, s),
                         turned=lane.turned | failed)


def walk_advance(mesh: SurfaceMesh, eta, tol, options: Walk, lane: LaneState, mode: int | None = None) -> LaneState:
    """`walk_step` then `walk_turn_back`: one iteration of a lane, with the turn-back."""
    return walk_turn_back(walk_step(mesh, eta, tol, options, lane, mode))


def _running(s: _State, max_steps):
    return (s.mode != DONE) & (s.steps < max_steps)


def _capped(s: _State) -> _State:
    """Lanes still running at the end hit the cap `max_steps`."""
    return s._replace(status=jnp.where(s.mode != DONE, Status.MAX_STEPS, s.status).astype(jnp.int32))


def walk_lane(mesh: SurfaceMesh, P, L, face, ab0, found, eta, options: Walk,
              tol, max_steps):
    """Walk one lane in its own `while_loop` (vmapped by the "chunked" scheduler); returns
    the final `_State`.

    `tol` and `max_steps` are traced (a sweep over them compiles once); the rest of
    `options` is static.

    When the first triangle holds no sign change, the walk picks one direction along the
    curve (out of total internal reflection first, else towards the smaller `|f|`). If
    that walk fails (TIR, boundary, lost curve, stalled bracket), it restarts once from
    `M0` in the other direction, within the same `max_steps` budget. The paper walks one
    way only; on steep waves the first choice is wrong for some lanes (the exhaustive
    reference finds a solution behind `M0`), `test_walk_turns_back_when_the_first_direction_fails`.
    """
    lane, is_ellipse, ellipse = walk_init(mesh, P, L, face, ab0, found, eta, tol, options)
    lane = jax.tree.map(lambda a, b: jnp.where(is_ellipse, a, b), walk_ellipse(mesh, eta, options, lane, ellipse), lane)
    lane = jax.lax.while_loop(lambda c: _running(c.state, max_steps),
                              lambda c: walk_advance(mesh, eta, tol, options, c), lane)
    return _capped(lane.state)


def _walk_pool(mesh, P, L, face, ab0, found, eta, tol, max_steps, options: Walk) -> _State:
    """The "pool" scheduler (module docstring): first triangles of the lanes with a start
    point, the ellipse samples of the lanes that need them, then the slot pool."""
    slots = pool_slots()

    def first(p, l, f, a, ok):
        return _first_triangle(mesh, p, l, f, a, ok, eta, tol)

    # The first triangles' records (`_Start`), stored, then both walks built from them for
    # every lane. Lanes without a start point keep a zero record, which builds NO_CROSSING
    # with no steps (as `_first_triangle` ends them); they never step.
    def first_lean(p, l, f, a, ok):
        return _first_triangle(mesh, p, l, f, a, ok, eta, tol, lean=True)

    # Every lane's first triangle from the vertex signs, then the exact construction on
    # the lanes the signs leave undecided (compacted: their cost is theirs alone).
    starts, clear = map_where(first_lean, found, None, P, L, face, ab0, found, chunk=slots)
    starts = map_where(first, found & ~clear, starts, P, L, face, ab0, found, chunk=slots)
    can_flip, state, other, is_ellipse, ellipse = jax.vmap(_start_states)(starts)
    lanes = LaneState(P, L, state, jnp.zeros_like(can_flip), can_flip, other)
    lanes = map_where(lambda lane, e: walk_ellipse(mesh, eta, options, lane, e), is_ellipse, lanes, lanes, ellipse,
                      chunk=slots)

    # A walking lane, a refining one and one crossing by the exact construction compute
    # different branches of a step: each runs in its own pool (WALK = 0, BISECT = 1,
    # EXACT = 2), so no lane pays for another branch.
    def route(lane):
        return jnp.where(_running(lane.state, max_steps), lane.state.mode, -1).astype(jnp.int32)

    # The pools step only what a step reads and writes (`P`, `L`, the walk's state); the
    # turn-back's second state stays out of them. Two passes of one traced loop body: every
    # lane walks until done; the lanes that failed and can turn back restart from `M0` the
    # other way (`walk_turn_back`, a no-op on the first pass and on every other lane) and
    # walk again. Per lane the same steps as turning back right after the failing step
    # (the step count carries over, so `max_steps` caps both ways together); the pools
    # move 24 fields per lane (35 numbers) instead of 48 (66) and run no turn-back per trip
    # (docs/solvers.md, "Measurements behind the code"; `experiments/compile_options.py`'s
    # "scheduler alone" rows measure the pool as it is).
    steps = tuple(lambda lane, m=m: walk_step(mesh, eta, tol, options, lane, m) for m in (WALK, BISECT, EXACT))

    def walk_pass(_, lanes):
        lanes = jax.vmap(walk_turn_back)(lanes)
        moving = lanes._replace(turned=None, can_flip=None, other=None)
        return lanes._replace(state=run_pools(steps, route, moving, slots).state)

    lanes = jax.lax.fori_loop(0, 2, walk_pass, lanes)
    return _capped(lanes.state)


def _walk_block(mesh, eta, tol, max_steps, P, L, face, ab0, found, options: Walk) -> Solution:
    """One device's share of a block of lanes (`blocks.on_devices`)."""
    eta = jnp.asarray(eta, mesh.dtype)
    tol = jnp.asarray(tol, mesh.dtype)
    if options.scheduler == "pool":
        states = _walk_pool(mesh, P, L, face, ab0, found, eta, tol, max_steps, options)
    else:
        states = map_lanes(
            lambda p, l, f, a, ok: walk_lane(mesh, p, l, f, a, ok, eta, options, tol, max_steps),
            P, L, face, ab0, found)
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
