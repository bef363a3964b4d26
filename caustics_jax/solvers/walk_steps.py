"""The walk's steps (seed 001 §3.4.3): a crossing into the next triangle along the
conic, and a refinement cut of a bracketed arc ("dichotomy").

A lane's `WalkState` is in one phase (`mode`): `WALK` crosses with the exit from the
conic's vertex signs (`arcs.sign_test_exit`), `EXACT` crosses with the exact pencil-order
construction (the lanes the signs leave undecided), `BISECT` cuts the bracketed arc,
`DONE` ends. `walk_step(..., phase)` computes that phase's step only (the pool
scheduler); `phase=None` computes the exact crossing and the cut and selects (one program
for every lane, the chunked scheduler). `f` is computed once per point of the walk: a
face's entry takes it from the previous exit, a cut is evaluated once.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..curve.arcs import (
    ArcStart,
    arc_from_point,
    inside,
    inward,
    opposite,
    orientation,
    pencil_angle,
    pencil_point,
    project_to_conic,
    root_between,
    sign_test_exit,
)
from ..math.conic import conic_coefficients, conic_tangent
from ..math.objectives import ObjectiveStatus, bracket_objective
from ..runtime.fusion import stored
from ..surface.mesh import cross_edge
from ._solution import Status

__all__ = ["BISECT", "DONE", "EXACT", "PHASES", "WALK", "Phase", "Replaced", "Search", "WalkState", "face_frame",
           "walk_step"]

class Phase(enum.IntEnum):
    """A lane's phase (`WalkState.mode`): a crossing decided by the vertex signs (`WALK`),
    a refinement cut (`BISECT`), a crossing by the exact construction (`EXACT`: the lanes
    the signs leave undecided, `arcs.sign_test_exit`), done. The pool scheduler steps each
    phase in its own pool (`run_pools`), so the exact construction runs on those lanes
    only; a phase's value is its pool's index."""

    WALK = 0
    BISECT = 1
    EXACT = 2
    DONE = 3


WALK, BISECT, EXACT, DONE = Phase.WALK, Phase.BISECT, Phase.EXACT, Phase.DONE


class Search(enum.IntEnum):
    """A bracket with one end totally reflecting or BACKWARD (`WalkState.tir_end`), where
    `f` has no sign to compare: the cuts close in on the onset there (`_bisect_update`).
    The member says which end is lost and what the lane does when the search ends
    without a root."""

    NONE = 0  # a plain bracket: f changes sign between its ends
    LO = -1  # the lo end (the arc's entry) is lost; no root: walk on from the arc's exit
    HI_TIR = 1  # the hi end (the exit) reflects totally; no root: the walk ends (TIR)
    HI = 2  # the hi end is lost (BACKWARD, or the first triangle's arc into TIR); no root: walk on


class Replaced(enum.IntEnum):
    """Illinois bookkeeping (`WalkState.side`): the bracket end the last cut replaced."""

    NONE = 0
    LO = -1
    HI = 1


#: The stepped phases' names, in index order (`runtime.lane_solver.LaneSolver.phases`).
PHASES = ("walk", "bisect", "exact")


class WalkState(NamedTuple):
    """A lane's walk: its phase and status, the face it is on and the exit it leaves by
    (with `f` there), the arc's pencil frame at `anchor`, the bracket (pencil angles, `f`
    and points of its ends), the best point so far, and its step and crossing counts."""

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
    side: jax.Array  # Illinois: which end the last cut replaced (`Replaced`)
    tir_end: jax.Array  # the onset search: which bracket end is lost, and what no root means (`Search`)
    best_ab: jax.Array
    best_f: jax.Array
    steps: jax.Array
    crossed: jax.Array


def face_frame(mesh, face, P, L):
    """Face `face`'s vertices, vertex normals and coplanarity conic (seed 001 eq. 10-12)."""
    V, N = mesh.triangle(face)
    return V, N, conic_coefficients(V, N, P, L)



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


def _walk_update(s: WalkState, g, e, geometry, fx, stx, gx, tol) -> WalkState:
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
    # root between); without a root there the walk goes on (`Search.HI`), as it always did
    # through BACKWARD stretches.
    tir_end = jnp.where(ok & e_ok & (stx == TIR), Search.HI_TIR, jnp.where(
        ok & e_ok & (stx == BACKWARD), Search.HI, jnp.where(
            ok & ((st_e == TIR) | (st_e == BACKWARD)) & x_ok, Search.LO, Search.NONE)))

    status, mode = s.status, jnp.where(bracket | (tir_end != Search.NONE), BISECT, WALK)
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
        side=jnp.full_like(s.side, Replaced.NONE), tir_end=tir_end.astype(jnp.int32),
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


def _bisect_geometry(coef, s: WalkState, illinois: bool):
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
        lam = jnp.where(s.tir_end != Search.NONE, 0.5, lam)  # f is 0 at a TIR end: no false position
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


def _bisect_update(s: WalkState, p, phi, ok, fm, stm, tol, illinois: bool, chord) -> WalkState:
    """Replace a bracket end by the cut `p` (pencil angle `phi`, from the chord cut where
    `chord`), or end the lane: FOUND, a stalled bracket, a TIR search without a root."""
    transmits = stm == ObjectiveStatus.OK
    searching = s.tir_end != Search.NONE
    hi_lost = (s.tir_end == Search.HI_TIR) | (s.tir_end == Search.HI)
    # In a search a BACKWARD cut sits on the far side of the onset, as a TIR one does.
    tir_mid = searching & ((stm == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION) | (stm == ObjectiveStatus.BACKWARD))
    ok = ok & (transmits | tir_mid)
    to_hi = opposite(fm, s.f_lo)  # the root lies between lo and p: p becomes the new hi
    # TIR search (`_walk_update`): p replaces the TIR end when it reflects too, or when f
    # changed sign against the transmitting end (then [that end, p] is a plain bracket);
    # otherwise p replaces the transmitting end, closing in on the onset of TIR.
    f_ok_end = jnp.where(hi_lost, s.f_lo, s.f_hi)
    flipped = transmits & opposite(fm, f_ok_end)
    replace_tir_end = tir_mid | flipped
    to_hi = jnp.where(searching, jnp.where(hi_lost, replace_tir_end, ~replace_tir_end), to_hi)
    # Every field below reads these decisions: stored once (`runtime.fusion`), not
    # copied into each field's kernel.
    to_hi, flipped, ok, transmits = stored((to_hi, flipped, ok, transmits))
    tir_end = jnp.where(flipped, Search.NONE, s.tir_end)
    phi_lo = jnp.where(to_hi, s.phi_lo, phi)
    phi_hi = jnp.where(to_hi, phi, s.phi_hi)
    ab_lo = jnp.where(to_hi, s.ab_lo, p)
    ab_hi = jnp.where(to_hi, p, s.ab_hi)
    f_lo = jnp.where(to_hi, s.f_lo, fm)
    f_hi = jnp.where(to_hi, fm, s.f_hi)
    if illinois:  # halve the stale end's value when the same end is kept twice
        side = jnp.where(searching, Replaced.NONE, jnp.where(to_hi, Replaced.HI, Replaced.LO))
        f_lo = jnp.where(to_hi & (s.side == Replaced.HI), f_lo / 2, f_lo)
        f_hi = jnp.where(~to_hi & (s.side == Replaced.LO), f_hi / 2, f_hi)
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
    better = ok & transmits & (jnp.abs(fm) < jnp.abs(s.best_f))
    found, stalled, better = stored((found, stalled, better))
    mode = jnp.where(found | stalled | ~ok, DONE, BISECT)
    status = jnp.where(found, Status.FOUND, jnp.where(stalled | ~ok, Status.NOT_CONVERGED, s.status))
    # A TIR search that closed in on the onset without a sign change found no root: a walk
    # into TIR ends there (`Search.HI_TIR`), a walk out of it (`LO`) or out of the first
    # triangle (`HI`) goes on from the arc's exit.
    no_root = stalled & ~found & (tir_end != Search.NONE)
    ends = tir_end == Search.HI_TIR
    mode = jnp.where(no_root, jnp.where(ends, DONE, WALK), mode)
    status = jnp.where(no_root, jnp.where(ends, Status.TOTAL_INTERNAL_REFLECTION, s.status), status)
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


def _step(mesh, P, L, eta, tol, illinois, s: WalkState) -> WalkState:
    """One iteration: a triangle crossing (WALK) or a refinement cut (BISECT).

    Under `vmap` both branches run for every lane, so they share one triangle gather,
    one conic and one evaluation of `f` (the new exit, or the cut) instead of two of each.
    """
    walking = s.mode == WALK
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = face_frame(mesh, jnp.where(walking, g, s.face), P, L)
    walk_geo = _walk_geometry(mesh, coef, g, k_in, t_in, e)
    p, phi, ok, chord = _bisect_geometry(coef, s, illinois)
    f1, st1, g1 = bracket_objective(V, N, P, L, jnp.where(walking, walk_geo[6], p)[None], eta)
    walked = _walk_update(s, g, e, walk_geo, f1[0], st1[0], g1[0], tol)
    refined = _bisect_update(s, p, phi, ok, f1[0], st1[0], tol, illinois, chord)
    return jax.tree.map(lambda w, b: jnp.where(walking, w, b), walked, refined)



def _walk_branch(mesh, P, L, eta, tol, s: WalkState) -> WalkState:
    """`_step` for a lane in WALK mode: only the crossing is computed."""
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = face_frame(mesh, g, P, L)
    walk_geo = _walk_geometry(mesh, coef, g, k_in, t_in, e)
    f1, st1, g1 = bracket_objective(V, N, P, L, walk_geo[6][None], eta)
    return _walk_update(s, g, e, walk_geo, f1[0], st1[0], g1[0], tol)


def _lean_walk_branch(mesh, P, L, eta, tol, s: WalkState) -> WalkState:
    """`_walk_branch` with the sign-test exit (`_lean_walk_geometry`); a lane the signs
    leave undecided, or leaving the mesh, is returned unchanged in the `EXACT` phase."""
    g, k_in, t_in, e = cross_edge(mesh, s.face, s.exit_k, s.exit_t)
    V, N, coef = face_frame(mesh, g, P, L)
    clear, geometry = _lean_walk_geometry(coef, k_in, t_in, e)
    f1, st1, g1 = bracket_objective(V, N, P, L, geometry.ab[None], eta)
    walked = _walk_update(s, g, e, geometry, f1[0], st1[0], g1[0], tol)
    # Every field of both outcomes reads the crossing's decisions: stored once, not copied
    # into each field's kernel (`runtime.fusion`; docs/solvers.md "Stored decisions").
    walked, decided = stored((walked, clear & (g >= 0)))
    return jax.tree.map(lambda w, o: jnp.where(decided, w, o), walked, s._replace(mode=jnp.int32(EXACT)))


def _bisect_branch(mesh, P, L, eta, tol, illinois, s: WalkState) -> WalkState:
    """`_step` for a lane in BISECT mode: only the refinement cut is computed."""
    V, N, coef = face_frame(mesh, s.face, P, L)
    p, phi, ok, chord = _bisect_geometry(coef, s, illinois)
    f1, st1, _ = bracket_objective(V, N, P, L, p[None], eta)
    return _bisect_update(s, p, phi, ok, f1[0], st1[0], tol, illinois, chord)



def walk_step(mesh, P, L, eta, tol, illinois: bool, s: WalkState, phase: int | None = None) -> WalkState:
    """One step of a lane in `phase` (module docstring); a lane already `DONE` is returned
    unchanged. `WALK`: the sign-test crossing (a lane it leaves undecided moves to `EXACT`
    without a step); `EXACT`: the crossing by the exact construction; `BISECT`: the
    refinement cut; None: the exact crossing and the cut, selected by the lane's mode."""
    if phase == WALK:
        nxt = _lean_walk_branch(mesh, P, L, eta, tol, s)
    elif phase == EXACT:
        nxt = _walk_branch(mesh, P, L, eta, tol, s)
    elif phase == BISECT:
        nxt = _bisect_branch(mesh, P, L, eta, tol, illinois, s)
    else:
        nxt = _step(mesh, P, L, eta, tol, illinois, s)
    return jax.tree.map(lambda n, o: jnp.where(s.mode == DONE, o, n), nxt, s)
