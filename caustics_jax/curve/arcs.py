"""Arcs of the coplanarity conic inside one triangle: the geometry the walk, the exhaustive
reference and the curve tracer share (seed 001 §3.4.3-3.4.4, math.md §2-3).

Inside a face the conic `A a^2 + B b^2 + C a b + D a + E b + F = 0` (seed 001 eq. 12) is
cut by the edges (eq. 22-24, corrected) into arcs. An arc is parametrised through the
pencil of lines through one of its points (`conic.conic_second_intersection`: every line
through a curve point meets the conic in exactly one other point), by the line's angle
`phi` measured from the travel direction `tau` towards `perp`; `orientation` picks the
sense of `perp` so that the curve ahead has `phi` in `(0, pi)` and `phi` increases
monotonically along it. Then the first edge crossing met when travelling along the curve
is the edge root of smallest `phi` (`next_crossing`), which also settles the
four-intersection re-entry case of seed 001 Fig. 5c without a heuristic.

`face_arcs` lists every arc of a face (from each edge root, oriented inward, to the next
crossing, plus an ellipse lying inside the face), and `FaceArcs.point` maps `u in [0, 1]`
to a point of an arc; `trace_arcs` samples them for a whole batch of faces (the curve
figure). The per-step tests of the walk and the exhaustive scan (`root_between`) live
here too, so both judge a sign change the same way.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..math.barycentric import barycentric_point, edge_barycentric
from ..math.conic import (
    conic_centre,
    conic_coefficients,
    conic_second_intersection,
    conic_tangent,
    conic_value,
    edge_intersection_points,
    edge_intersections,
    edge_quadratic_roots,
    edge_quadratics,
    solve_quadratic,
)

#: Inward normal of each edge in barycentric space (edge 0: b = 0 -> +b; edge 1:
#: a + b = 1 -> -(a + b); edge 2: a = 0 -> +a), in the edge numbering of `barycentric.py`.
INWARD = ((0.0, 1.0), (-1.0, -1.0), (1.0, 0.0))
#: Arcs per face listed by `face_arcs`: up to 6 edge roots as arc starts, plus one
#: ellipse inside the face.
N_ARCS = 7


def orientation(coef, e, tau):
    """Unit travel direction and the `sigma`-signed normal `perp` at curve point `e`, so
    that the curve ahead (direction `tau`) has pencil angles `phi` in `(0, pi)`.

    The pencil frame of the module docstring (this project's parametrisation of the walk
    of seed 001 §3.4.3), bent towards the tangent of seed 001 eq. 13-15 (math.md §2)."""
    tau = tau / jnp.maximum(jnp.linalg.norm(tau), jnp.finfo(tau.dtype).tiny)
    A, B, C = coef[0], coef[1], coef[2]
    t = conic_tangent(coef, e)
    grad = jnp.stack([t[1], -t[0]])  # half the gradient (u, v)
    c2 = A * tau[0] ** 2 + B * tau[1] ** 2 + C * tau[0] * tau[1]
    bend = -jnp.sign(c2) * grad
    cross = tau[0] * bend[1] - tau[1] * bend[0]
    sigma = jnp.where(cross < 0, -1, 1).astype(tau.dtype)
    perp = sigma * jnp.stack([-tau[1], tau[0]])
    return tau, perp


def edge_roots(coef):
    """`(t, valid, ab)`: the conic's edge roots (`conic.edge_intersections`, `(3, 2)` each)
    and their barycentrics `(3, 2, 2)` (seed 001 eq. 22-24, corrected in math.md §3)."""
    t, valid = edge_intersections(coef)
    return t, valid, edge_intersection_points(t)


def next_crossing(roots, e, tau, perp, entry_edge=-1, entry_t=0.0):
    """The first edge root met when travelling along the conic from `e` in direction `tau`.

    Seed 001 §3.4.3's exit edge, including the re-entry case of Fig. 5c (module docstring).

    Returns `(ok, edge, t, ab, phi)`. Never a candidate: on the entry edge, the root
    nearest the entry parameter when it is within `8 sqrt(eps)` of it (the entry point
    itself, recomputed in this triangle's conic). Candidates only when no other root is
    left: roots within `8 eps` (relative to the barycentrics' magnitude) of `e`: the same
    point (a vertex root reported on two edges: edge roots are clamped into `[0, 1]`, so
    such duplicates coincide to rounding), where "ahead" is undefined. A root farther
    than that is a different point of the curve, however close: in float32 a curve that
    clips a corner within 1e-5 of a vertex, or a start point 5e-6 from an edge, has its
    exit there, and a `64 eps` exclusion lost the curve or sent the walk backwards.
    """
    t, valid, ab = roots
    eps = float(np.finfo(t.dtype).eps)
    v = ab - e
    dist = jnp.linalg.norm(v, axis=-1)
    scale = jnp.sum(jnp.abs(ab), axis=-1) + jnp.sum(jnp.abs(e))
    on_entry = jnp.arange(3)[:, None] == entry_edge
    gap = jnp.where(on_entry & valid, jnp.abs(t - entry_t), jnp.inf)
    nearest = gap == jnp.min(gap)
    allowed = valid & ~(nearest & (gap < 8 * np.sqrt(eps)))
    cand = allowed & (dist > 8 * eps * scale)
    cand = jnp.where(jnp.any(cand), cand, allowed)
    phi = pencil_angle(v, tau, perp, dist, scale)
    phi = jnp.where(cand, phi, jnp.inf).reshape(-1)
    i = jnp.argmin(phi)
    return jnp.isfinite(phi[i]), (i // 2).astype(jnp.int32), t.reshape(-1)[i], ab.reshape(-1, 2)[i], phi[i]


def pencil_angle(v, tau, perp, dist, scale):
    """The pencil angle in `[0, pi)` of a curve point `e + v` seen from the curve point `e`
    in the frame `(tau, perp)` of `orientation` (`next_crossing`'s order along the curve);
    `dist = |v|`, `scale` the magnitude of both points' barycentrics.

    On the tangent line itself (a straight curve: constant normals, a flat surface) the
    line angle is 0 or pi only up to rounding; there, ahead comes first (nearest first)
    and behind comes last. The same holds for a root close to `e` on a gentle curve:
    its true `across` (curvature x dist^2 / 2) is below the absolute rounding of the
    barycentrics (`e` and the root are each off the conic by ~eps |ab|), so the sign of
    `across` is noise while the sign of `along` is not. Without the absolute bound a
    float32 root 1e-4 behind `e` read as "ahead at angle 1e-3" (arctan2(-0, -1) wraps
    to 0), and the walk went the wrong way in both directions.
    """
    eps = float(np.finfo(v.dtype).eps)
    along, across = v @ tau, v @ perp
    phi = jnp.arctan2(across, along)
    phi = jnp.where(phi < 0, phi + jnp.pi, phi)  # the cutting line's angle, in [0, pi)
    on_tangent = on_tangent_line(across, dist, scale)
    return jnp.where(on_tangent, jnp.where(along > 0, eps * dist, jnp.pi), phi)


#: Vertex values of the conic within this many eps of its largest coefficient read as
#: zero in `sign_test_exit` (the curve passes near that vertex): the lane takes the exact
#: construction. Edge quadratics' coefficients are sums of up to five conic coefficients,
#: so a root within `edge_intersections`' 64 eps slack of a vertex gives a vertex value
#: below 5 x 64 eps of the largest one; 1024 leaves room for their rounding.
VERTEX_ZERO = 1024


class BoundaryCrossings(NamedTuple):
    """`boundary_crossings`' answer: `clear` (the signs decide: the conic meets the face's
    boundary exactly twice), the two crossings' `edge` `(2,)`, edge roots `t` `(2,)` and
    points `ab` `(2, 2)`."""

    clear: jax.Array
    edge: jax.Array
    t: jax.Array
    ab: jax.Array


def boundary_crossings(coef) -> BoundaryCrossings:
    """The two points where the conic crosses the face's boundary, from the signs of the
    conic at the three vertices and two edge quadratics (the lean exit of the walk, seed
    001 §3.4.3, without `next_crossing`'s pencil order over six roots).

    The conic's values at `V0, V1, V2` are `F`, `A + D + F`, `B + E + F` (eq. 12 at
    `(a, b) = (0, 0), (1, 0), (0, 1)`). With all three clearly non-zero and not all of one
    sign, exactly two edges have end points of different signs, and each holds exactly
    one root of its quadratic (eq. 22-24, corrected); the third edge's ends agree and it
    holds none or two. When it holds none (its quadratic's extremum lies off the edge, or
    on the end points' side of zero), the conic meets the boundary exactly twice and the
    curve inside the face is one arc between those two roots. `clear` is False otherwise:
    a vertex value within `VERTEX_ZERO` eps of the largest coefficient (the curve near a
    vertex), all vertices of one sign (no crossing, an ellipse inside, or pairs of roots:
    the re-entry of Fig. 5c), a pair of roots on the third edge, a root count other than
    one on a crossing edge. The roots are `edge_quadratic_roots` of those edges: where
    clear, bit for bit `edge_roots`' own.
    """
    dtype = coef.dtype
    eps = float(np.finfo(dtype).eps)
    # Reductions, argmin and indexing over the 3 vertices, 3 edges and 6 coefficients are
    # written as element-wise maxima and selects (the same values, bit for bit): under
    # `vmap` a reduction or gather over such a minor axis of 3 or 6 costs XLA:CPU about
    # 40 ns per lane, far more than its arithmetic (the argmin and the `any`/`all` were 13%
    # of a crossing step's kernel time at 512 lanes; docs/solvers.md "Where the walk's time
    # goes on XLA:CPU"). The vertex values are `conic_value` at V0, V1, V2 written out
    # (called per vertex, the step traced 253 us of kernel time against 244, one trace each).
    A, B, C, D, E, F = (coef[..., i] for i in range(6))
    biggest = jnp.maximum(jnp.maximum(jnp.maximum(jnp.abs(A), jnp.abs(B)), jnp.maximum(jnp.abs(C), jnp.abs(D))),
                          jnp.maximum(jnp.abs(E), jnp.abs(F)))
    zero = VERTEX_ZERO * eps * biggest
    v0, v1, v2 = F, A + D + F, B + E + F  # eq. 12 at (0, 0), (1, 0), (0, 1), as in the docstring
    nonzero = (jnp.abs(v0) > zero) & (jnp.abs(v1) > zero) & (jnp.abs(v2) > zero)
    p0, p1, p2 = v0 > 0, v1 > 0, v2 > 0
    d0, d1, d2 = p0 != p1, p1 != p2, p0 != p2  # edges 0, 1, 2: ends of different signs
    # the edge whose ends agree (the only one, where clear): the first with `~d`
    third = jnp.where(~d0, 0, jnp.where(~d1, 1, jnp.where(~d2, 2, 0))).astype(jnp.int32)
    quad = edge_quadratics(coef)

    def edge_quad(k):
        return tuple(jnp.where(k == 0, quad[..., 0, i], jnp.where(k == 1, quad[..., 1, i], quad[..., 2, i]))
                     for i in range(3))

    q2, q1, q0 = edge_quad(third)
    # The third edge's quadratic at its extremum `t* = -q1 / 2 q2`: a pair of roots on the
    # edge needs `t*` on it and `q(t*)` of the other sign than its end points' (or zero).
    t_star = -q1 / jnp.where(q2 != 0, 2 * q2, 1)
    extremum = q0 + q1 * t_star / 2
    pair = (q2 != 0) & (t_star > 0) & (t_star < 1) & (extremum * jnp.sign(q0) <= zero)
    edges = jnp.stack([(third + 1) % 3, (third + 2) % 3]).astype(jnp.int32)
    ea, eb = edge_quad(edges[0]), edge_quad(edges[1])
    roots, valid = edge_quadratic_roots(*(jnp.stack([a, b]) for a, b in zip(ea, eb, strict=True)))
    one = valid[:, 0] != valid[:, 1]
    t = jnp.where(valid[:, 0], roots[:, 0], roots[:, 1])
    clear = nonzero & (d0 | d1 | d2) & ~pair & one[0] & one[1]
    return BoundaryCrossings(clear, edges, t, edge_barycentric(edges, t))


def sign_test_exit(coef, entry_edge, entry_t):
    """The exit of the arc that entered the face through `entry_edge` at `entry_t`:
    `(clear, edge, t, ab)` (`boundary_crossings`: of the two crossings, the one that is
    not the entry). `clear` also needs the entry edge to be one of the two and its root
    within `next_crossing`'s `8 sqrt(eps)` of `entry_t` (the entry point, recomputed in
    this face's conic), so that where clear `next_crossing` returns the same exit."""
    bc = boundary_crossings(coef)
    eps = float(np.finfo(coef.dtype).eps)
    a = bc.edge[0] == entry_edge  # the entry is crossing 0, else crossing 1 (selects, not gathers)
    pick = lambda first, second: jnp.where(a, first, second)  # noqa: E731
    is_entry = (pick(bc.edge[0], bc.edge[1]) == entry_edge) & (
        jnp.abs(pick(bc.t[0], bc.t[1]) - entry_t) < 8 * np.sqrt(eps))
    return bc.clear & is_entry, pick(bc.edge[1], bc.edge[0]), pick(bc.t[1], bc.t[0]), pick(bc.ab[1], bc.ab[0])


def inward(edge, dtype):
    """Inward normal of edge `edge` in barycentric space (`INWARD`)."""
    return jnp.asarray(INWARD, dtype)[jnp.clip(edge, 0, 2)]


class ArcStart(NamedTuple):
    """The arc from a curve point whose tangent is oriented along a direction, to the next
    edge crossing (`arc_from_point`).

    Attributes:
        side: the tangent's component along the direction; 0 where the curve runs along
            it (no arc starts there).
        tau, perp: the pencil frame of the arc (`orientation`).
        ok: the next crossing exists (`next_crossing`).
        edge, t, ab, phi: that crossing's edge, edge parameter, point and pencil angle.
    """

    side: jax.Array
    tau: jax.Array
    perp: jax.Array
    ok: jax.Array
    edge: jax.Array
    t: jax.Array
    ab: jax.Array
    phi: jax.Array

    @property
    def exists(self):
        """An arc starts here and reaches an edge: `ok` and `side != 0`."""
        return self.ok & (self.side != 0)


def arc_from_point(coef, e, direction, entry_edge=-1, entry_t=0.0, roots=None) -> ArcStart:
    """The arc from curve point `e`, its tangent oriented along `direction` (a barycentric
    vector: the inward normal of the entry edge when entering a face), to the next edge
    crossing (`next_crossing` in the frame of `orientation`); `roots`: the conic's
    `edge_roots` when the caller has them."""
    t = conic_tangent(coef, e)
    side = t @ direction
    tau, perp = orientation(coef, e, jnp.where(side < 0, -t, t))
    roots = edge_roots(coef) if roots is None else roots
    ok, edge, t_next, ab, phi = next_crossing(roots, e, tau, perp, entry_edge, entry_t)
    return ArcStart(side, tau, perp, ok, edge, t_next, ab, phi)


def leaving_at_start(roots, e, tau, crossing):
    """`next_crossing`'s `crossing` from a start point `e` that lies on an edge, corrected
    for a direction `tau` that leaves the triangle through that edge at once.

    A curve through a point of an edge runs on one side into the triangle and on the other
    into the neighbour. `next_crossing` drops a root within `8 eps` of `e` (the same
    point) while another is left, so travelling outward it returned the next root in pencil
    order: where the curve *re-enters* the triangle, with the arc between them outside it
    (a segment `P -> L` through an edge midpoint of `wavy_pool(2048)`: 253 of 400 lanes
    found, 400 once moved by 1e-9 m). Here, when a root on edge `k` coincides with `e`
    (`8 eps`, as in `next_crossing`) and `tau` points out of the triangle across that edge
    (`tau . INWARD[k] < 0`), the exit is that root (`phi = 0`): the walk crosses into the
    neighbour at `e`. At a vertex the first such edge is taken."""
    t, valid, ab = roots
    eps = float(np.finfo(t.dtype).eps)
    dist = jnp.linalg.norm(ab - e, axis=-1)
    scale = jnp.sum(jnp.abs(ab), axis=-1) + jnp.sum(jnp.abs(e))
    outward = jnp.asarray(INWARD, tau.dtype) @ tau < 0
    hit = (valid & (dist <= 8 * eps * scale) & outward[:, None]).reshape(-1)
    leaves = jnp.any(hit)
    i = jnp.argmax(hit)
    ok, k, tt, ab_x, phi = crossing
    return (ok | leaves, jnp.where(leaves, (i // 2).astype(jnp.int32), k), jnp.where(leaves, t.reshape(-1)[i], tt),
            jnp.where(leaves, ab.reshape(-1, 2)[i], ab_x), jnp.where(leaves, jnp.zeros_like(phi), phi))


def on_tangent_line(across, dist, scale):
    """A root at distance `dist` from the curve point `e`, `across` from the tangent line at
    `e` (`(root - e) . perp`), lies on that tangent line to rounding (`next_crossing`):
    `|across| <= 1e3 eps dist`, or `<= 64 eps scale` with `scale` the magnitude of the
    barycentrics of both points (their absolute rounding). A rounding bound of this
    project (math.md §1: tolerances scaled to eps), no paper formula."""
    eps = float(np.finfo(across.dtype).eps)
    return (jnp.abs(across) <= 1e3 * eps * dist) | (jnp.abs(across) <= 64 * eps * scale)


def project_to_conic(coef, q):
    """The conic point nearest `q` along the gradient direction at `q` (one exact line cut).

    The gradient is `S (a, b, 1)` (math.md §2, seed 001 eq. 13-15 with `S` for `K^T`); the
    cut is the quadratic `Q(q + h n)` in `h`."""
    t = conic_tangent(coef, q)
    n = jnp.stack([t[1], -t[0]])
    n = n / jnp.maximum(jnp.linalg.norm(n), jnp.finfo(n.dtype).tiny)
    A, B, C, D, E, F = coef
    q2 = A * n[0] ** 2 + B * n[1] ** 2 + C * n[0] * n[1]
    q1 = (2 * A * q[0] + C * q[1] + D) * n[0] + (2 * B * q[1] + C * q[0] + E) * n[1]
    h, ok = solve_quadratic(q2, q1, conic_value(coef, q))
    h = jnp.where(ok, h, jnp.inf)
    h_min = jnp.where(jnp.abs(h[0]) < jnp.abs(h[1]), h[0], h[1])
    return q + jnp.where(jnp.isfinite(h_min), h_min, 0) * n


def pencil_point(coef, anchor, tau, perp, phi):
    """The curve point cut by the line through `anchor` at pencil angle `phi`, and whether
    the cut exists (`conic.conic_second_intersection`; seed 001 §3.4.3's "new edge cuts
    the curve", here a line through a curve point)."""
    d = jnp.cos(phi) * tau + jnp.sin(phi) * perp
    return conic_second_intersection(coef, anchor, d)


def opposite(f1, f2):
    """Strictly opposite signs."""
    return jnp.sign(f1) * jnp.sign(f2) < 0


def root_between(fg1, fg2):
    """A sign change of `f` in both orientations (`objectives.bracket_objective`'s `f` and
    `g`) between two curve points: a root, not an orientation flip (seed 001 §3.4.3's
    "if f changes sign"; eq. 20-21, math.md §4)."""
    return opposite(fg1[0], fg2[0]) & opposite(fg1[1], fg2[1])


def inside(ab, slack=None):
    """`ab` in the closed triangle up to `slack` (default `64 eps`): seed 001 eq. 3's
    `(a, b, a + b)` in `[0, 1]^3`."""
    slack = 64 * jnp.finfo(ab.dtype).eps if slack is None else slack
    return (ab[0] >= -slack) & (ab[1] >= -slack) & (ab[0] + ab[1] <= 1 + slack)


class FaceArcs(NamedTuple):
    """The arcs of one face's conic, each parametrised by `u` in `[0, 1]` (`point`).

    Attributes:
        coef: `(6,)` conic coefficients.
        straight: the conic is a line (`A = B = C = 0` to rounding: constant normals).
        starts, ends: `(N_ARCS, 2)` barycentrics where each arc starts and ends.
        taus, perps: `(N_ARCS, 2)` the pencil frame at each start (`orientation`).
        phi_ends: `(N_ARCS,)` pencil angle of each arc's end (pi for the ellipse).
        ok: `(N_ARCS,)` which arcs exist.
    """

    coef: jax.Array
    straight: jax.Array
    starts: jax.Array
    ends: jax.Array
    taus: jax.Array
    perps: jax.Array
    phi_ends: jax.Array
    ok: jax.Array

    def point(self, arc, u):
        """The pencil angle `phi = u phi_end` through the arc's start for a curved conic; the
        straight segment to the next crossing when the conic is a line (every other line
        through a point of a line conic meets it only there, so the pencil cannot
        parametrise it). Returns `(ab, ok)`."""
        curved, curved_ok = pencil_point(self.coef, self.starts[arc], self.taus[arc],
                                         self.perps[arc], u * self.phi_ends[arc])
        line = self.starts[arc] + u * (self.ends[arc] - self.starts[arc])
        return jnp.where(self.straight, line, curved), self.straight | curved_ok


def face_arcs(coef) -> FaceArcs:
    """Every arc of the conic `coef` inside its face: from each edge root, oriented inward,
    to the next crossing along the curve, plus an ellipse inside the face (no edge root),
    anchored where the line `b = 1/3` meets it: the cases of seed 001 Fig. 5a-c."""
    A, B, C, D, E, F = coef
    scale = jnp.max(jnp.abs(coef))
    straight = jnp.max(jnp.abs(coef[:3])) <= 64 * jnp.finfo(coef.dtype).eps * scale
    roots = edge_roots(coef)
    t_all, valid_all, ab_all = roots
    starts, ends, taus, perps, phi_ends, ok_arcs = [], [], [], [], [], []
    for k in range(3):
        for j in range(2):
            x = ab_all[k, j]
            arc = arc_from_point(coef, x, jnp.asarray(INWARD[k], coef.dtype), k, t_all[k, j], roots)
            starts.append(x)
            ends.append(arc.ab)
            taus.append(arc.tau)
            perps.append(arc.perp)
            phi_ends.append(jnp.where(arc.ok, arc.phi, 0))
            ok_arcs.append(valid_all[k, j] & arc.exists)
    s, s_ok = solve_quadratic(A, C / 3 + D, B / 9 + E / 3 + F)
    anchor = jnp.stack([s[0], jnp.asarray(1 / 3, s.dtype)])
    tau, perp = orientation(coef, anchor, conic_tangent(coef, anchor))
    starts.append(anchor)
    ends.append(anchor)
    taus.append(tau)
    perps.append(perp)
    phi_ends.append(jnp.asarray(jnp.pi, s.dtype) * (1 - 1e-9))
    ok_arcs.append(~jnp.any(valid_all) & s_ok[0] & ~straight)
    return FaceArcs(coef, straight, jnp.stack(starts), jnp.stack(ends), jnp.stack(taus),
                    jnp.stack(perps), jnp.stack(phi_ends), jnp.stack(ok_arcs))


def conic_touches_face(coef):
    """Does the conic pass through the face? Edge crossings, or an ellipse whose centre lies
    inside the face with the opposite sign of the conic at vertex V0 (seed 001 Fig. 5a)."""
    _, valid, _ = edge_roots(coef)
    a_c, b_c, ellipse = conic_centre(coef)
    F = coef[5]
    centre_inside = (a_c >= 0) & (b_c >= 0) & (a_c + b_c <= 1)
    centre = jnp.stack([a_c, b_c])
    opposite_sign = conic_value(coef, centre) * F < 0  # F = the conic at vertex V0
    return jnp.any(valid) | (ellipse & centre_inside & opposite_sign)


def trace_arcs(V, N, P, L, samples: int, return_arcs: bool = False):
    """Sample every arc of the coplanarity conic (seed 001 Fig. 3, eq. 10-12) on faces
    `(V, N)` `(F, 3, 3)` for one receiver `P` and light `L`: `(ab, xyz, ok)` of shapes
    `(F, N_ARCS, samples, 2 | 3)`
    and `(F, N_ARCS, samples)`, `u` uniform in `[0, 1]` along each arc's pencil angle (the
    same parametrisation the walk refines on and the exhaustive reference scans).

    With `return_arcs`, also the `FaceArcs` of every face (fields batched over `F`): the
    exact start and end roots, which arcs exist, which conics are straight. A tracer needs
    them to chain arcs across edges: at `u = 0` a curved arc's pencil line is the tangent,
    whose second intersection is a double root that rounding either merges (`ok` False,
    `ab` the start) or splits (`ab` off the start along the curve), and on a gentle arc
    (small `phi_end`) the samples at both ends move along the curve by up to 2e-7 in
    float64 and 5e-3 in float32 (barycentric, measured on a wavy pool; they stay on the
    curve); and an ellipse anchor (arc `N_ARCS - 1`) is listed whether or not it lies
    inside the face.
    """
    u = jnp.linspace(0, 1, samples).astype(V.dtype)

    def one(v, n):
        arcs = face_arcs(conic_coefficients(v, n, P, L))
        ab, ok = jax.vmap(lambda a: jax.vmap(lambda x: arcs.point(a, x))(u))(jnp.arange(N_ARCS))
        out = (ab, barycentric_point(v, ab), ok & arcs.ok[:, None])
        return (*out, arcs) if return_arcs else out

    return jax.vmap(one)(V, N)
