"""The walk's first triangle (seed 001 §3.4.2-3.4.4): from the start point `M0`, the
conic's two directions of travel, the exit of each, `f` there, and the walk or the
bracket each direction gives; an ellipse inside the triangle is sampled through the
pencil of lines at `M0`.

`first_triangle` decides (a `Start` record per lane); `start_states` builds the chosen
walk and the one the other way (the turn-back's); `ellipse_bracket` completes a lane whose
curve has no edge crossing. The scheduler stores each record before the next reads it
(`runtime.lane_solver.Stage`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..curve.arcs import (
    boundary_crossings,
    edge_roots,
    leaving_at_start,
    next_crossing,
    orientation,
    pencil_angle,
    pencil_point,
    project_to_conic,
    root_between,
)
from ..math.conic import conic_tangent
from ..math.objectives import ObjectiveStatus, bracket_objective, path_vectors
from ._solution import Status
from .walk_steps import BISECT, DONE, WALK, Replaced, Search, WalkState, face_frame

__all__ = ["Ellipse", "Start", "ellipse_bracket", "first_triangle", "start_states"]

def _cos_at_P(V, N, P, L, ab):
    """`-w_P . n_s` at points `ab` `(k, 2)`: the cosine of incidence on P's side."""
    _, n_s, w_P, _, _ = path_vectors(V, N, P, L, ab)
    return -jnp.sum(w_P * n_s, axis=-1)


class Ellipse(NamedTuple):
    """What the ellipse search (`ellipse_bracket`) needs from the first triangle."""

    coef: jax.Array
    tau: jax.Array
    perp: jax.Array
    near: jax.Array  # (2, 2): the near points of +t0 and -t0
    phi_near: jax.Array  # pencil angle of the +t0 near point
    f_near: jax.Array  # (2,)
    g_near: jax.Array  # (2,)
    st_near: jax.Array  # (2,)


class Decisions(NamedTuple):
    """The first triangle's decisions (`first_triangle`), per lane; `_p` / `_m`: of the
    `+t0` / `-t0` direction."""

    found: jax.Array  # the lane has a start point
    is_ellipse: jax.Array  # no edge crossing in either direction (§3.4.4)
    br_p: jax.Array  # f changes sign on the direction's arc
    br_m: jax.Array
    use_m_bracket: jax.Array  # both bracket: the -t0 one comes first
    walk_m: jax.Array  # no bracket: walk towards -t0
    tir_arc_p: jax.Array  # the arc runs into TIR (or BACKWARD) from a transmitting near point
    tir_arc_m: jax.Array
    degenerate_exit_p: jax.Array
    degenerate_exit_m: jax.Array
    at_m0: jax.Array  # M0 itself is a solution
    degenerate: jax.Array  # a singular conic or a degenerate f at M0
    okp: jax.Array  # the direction has an exit
    okm: jax.Array
    tir_out_p: jax.Array  # the arc runs out of TIR (or BACKWARD): M0 reflects, the exit transmits
    tir_out_m: jax.Array


class Start(NamedTuple):
    """What `first_triangle` found from `M0`, per lane; `start_states` builds the walks.

    The scheduler stores this record before building the states (`Stage`: each stage's
    result is stored before the next reads it), so each decision is computed once: XLA's
    CPU fusion copies a cheap producer into every kernel that reads it, and each of the
    two walks' ~25 state fields had recomputed the same chain of ~150 objective-status
    and sign tests. Pairs `(2, ...)` are the `+t0` and `-t0` directions."""

    decisions: Decisions
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
    ellipse: Ellipse


def first_triangle(mesh, P, L, face, ab0, found, eta, tol, lean: bool = False):
    """What the first triangle decides from `M0` (`Start`): the exits in both directions,
    `f` there, the bracket or the walk direction, terminal conditions; `start_states`
    builds the two walks from it, and an ellipse inside the triangle is left to
    `ellipse_bracket`.

    `lean`: the exits from the conic's two boundary crossings (`arcs.boundary_crossings`)
    ordered by their pencil angles from `M0`, instead of `next_crossing` over six edge
    roots; returns `(start, clear)`, and the lanes not `clear` (the signs undecided, `M0`
    on a crossing, a singular tangent) need the exact construction (`lean=False`)."""
    dtype = mesh.dtype
    V, N, coef = face_frame(mesh, face, P, L)
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

    # The frame of the pencil at M0, for an ellipse inside the triangle (`ellipse_bracket`).
    tau_e, perp_e = orientation(coef, ab0, t0)
    # f at M0, the two exits and the two near points (the ellipse samples apart, in
    # `ellipse_bracket`: one batch of 5 points here, rounded alike by both schedulers).
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
    decisions = Decisions(
        found=found, is_ellipse=~okp & ~okm, br_p=br_p, br_m=br_m, use_m_bracket=use_m_bracket, walk_m=walk_m,
        # The arc of each direction runs into TIR (or BACKWARD) from a transmitting near point.
        tir_arc_p=okp & (st_all[3] == OK) & lost(stp), tir_arc_m=okm & (st_all[4] == OK) & lost(stm),
        # ... or out of it: M0 totally reflecting (or BACKWARD), the exit transmitting, the
        # root between the onset and the exit (as `_walk_update`'s `Search.LO`).
        tir_out_p=okp & lost(st_all[3]) & (stp == OK), tir_out_m=okm & lost(st_all[4]) & (stm == OK),
        degenerate_exit_p=stp == DEG, degenerate_exit_m=stm == DEG, at_m0=at_m0,
        # A singular conic at a solution M0 does not matter (P, L and the normal aligned
        # on a flat surface make every point of the plane "coplanar"): M0 stays FOUND.
        degenerate=(singular & ~at_m0) | (st0 == DEG), okp=okp, okm=okm)
    ellipse = Ellipse(coef, tau_e, perp_e, jnp.stack([nearp, nearm]), phisp, jnp.stack([fsp, fsm]),
                       jnp.stack([gsp, gsm]), st_all[3:5])
    _, k, t, ab, phi, tau, perp, phi_s, near, _ = dirs
    start = Start(decisions, face.astype(jnp.int32), ab0, f0, k, t, ab, jnp.stack([fp, fm]),
                   jnp.stack([stp, stm]), jnp.stack([gp, gm]), phi, phi_s, jnp.stack([fsp, fsm]), near, tau, perp,
                   ellipse)
    return (start, clear) if lean else start


def start_states(start: Start):
    """The initial state of both walks from `M0` (`first_triangle`'s decisions), or a
    terminal status.

    Returns `(can_turn, state, other, is_ellipse, ellipse)`: `other` walks the other way
    from the one chosen; `can_turn` says whether that second way exists (a walk that
    started without a bracket, with an exit in both directions). Both share every
    evaluation of `f`. `is_ellipse`: the curve has no edge crossing (§3.4.4); there the
    state reads `UNRESOLVED_ELLIPSE` (unless `M0` is a solution, degenerate, or has no
    start point) until `ellipse_bracket` has sampled the curve (`ellipse`: its inputs).
    """
    fl = start.decisions._asdict()
    is_ellipse, br_p, br_m, found = fl["is_ellipse"], fl["br_p"], fl["br_m"], fl["found"]
    dtype = start.f0.dtype
    e = start.ellipse
    # Placeholders where the curve is an ellipse: `ellipse_bracket` fills the bracket in.
    phis_all, fs_all, pts = jnp.zeros(2, dtype), jnp.zeros(2, dtype), jnp.zeros((2, 2), dtype)
    j, ellipse_bracket = 0, jnp.asarray(False)
    pm = lambda x, m: jnp.where(m, x[1], x[0])  # noqa: E731  (the -t0 or the +t0 direction)

    def build(walk_m):
        bracket = jnp.where(is_ellipse, ellipse_bracket, br_p | br_m)
        use_m = fl["use_m_bracket"] | (~(br_p | br_m) & walk_m)
        # No sign change, and the arc of the walk direction runs into TIR: search it
        # towards the onset first (`_bisect_update`; P within 1e-6 m of the surface puts
        # the root 1e-9 m from M0 and the rest of the triangle in TIR). Without a root
        # there the walk goes on as before (`Search.HI`).
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
        return can_flip, WalkState(
            mode=mode.astype(jnp.int32), status=status.astype(jnp.int32), face=start.face,
            exit_k=pm(start.k, pick_m), exit_t=pm(start.t, pick_m), exit_ab=pm(start.ab, pick_m),
            f_exit=pm(start.f, pick_m), st_exit=pm(start.st, pick_m), g_exit=pm(start.g, pick_m),
            anchor=start.ab0, tau=tau, perp=perp, phi_lo=phi_lo, phi_hi=phi_hi, f_lo=f_lo, f_hi=f_hi,
            ab_lo=ab_lo, ab_hi=ab_hi, side=jnp.asarray(Replaced.NONE, jnp.int32),
            tir_end=jnp.where(searching, jnp.where(tir_arc, Search.HI, Search.LO), Search.NONE).astype(jnp.int32),
            best_ab=start.ab0,
            best_f=start.f0, steps=jnp.asarray(0, jnp.int32), crossed=jnp.asarray(0, jnp.int32),
        )

    # The chosen way and the other way in one vmap: one compiled copy of `build`.
    walk_m = fl["walk_m"]
    flips, states = jax.vmap(build)(jnp.stack([walk_m, ~walk_m]))
    can_flip, state, other = flips[0], jax.tree.map(lambda x: x[0], states), jax.tree.map(lambda x: x[1], states)
    return can_flip, state, other, is_ellipse, e



def ellipse_bracket(mesh, P, L, eta, n_ellipse, s: WalkState, e: Ellipse) -> WalkState:
    """The curve is an ellipse inside the first triangle (seed 001 §3.4.4): sample it at
    `n_ellipse` pencil angles through `M0`, from just after `M0` (the near point of +t0)
    to just before it (the near point of -t0), so that no stretch is left out, and
    bracket the first sign change of `f`. A lane `first_triangle` left unresolved starts
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
