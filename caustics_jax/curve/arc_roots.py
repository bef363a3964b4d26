"""Certified roots of the refraction condition on one arc of the coplanarity conic.

The exhaustive reference and the all-paths tracer both need every refraction point on an
arc of the conic inside one face (seed 001 §3.4.3, `arcs.face_arcs`). Sampling the signed
sine `f` on the arc and bracketing its sign changes misses roots: two roots in one sample
interval cancel, and so does a root next to an orientation flip of `f` (the "line"
orientation flips at `M0`; docs/solvers.md "The certified reference" counts the lanes a
sampled reference lost that way). This module replaces sampling by a polynomial whose roots contain every
solution on the arc, and isolates them with the Bernstein form (Descartes' rule of
signs), so the count of roots is certain, not a lower bound.

**The polynomial.** An arc is parametrised by the pencil of lines through its anchor `e`
(a curve point, `arcs.pencil_point`): the line with direction
`d(x) = (1 - x) d0 + x d1`, `x in [0, 1]` (`d0`, `d1` at the pencil angles bounding the
arc piece, less than pi/2 apart, so `d` never vanishes and its angle grows
monotonically), meets the conic again at `e - (g . d) d / (d^T S2 d)` (`g` the conic's
gradient at `e`, `S2` its quadratic part; `conic.conic_second_intersection`). So the
barycentrics are `(a, b) = (a_h, b_h) / q` with `a_h, b_h, q` polynomials of degree 2 in
`x`; on a straight conic (constant normals) the arc is the segment itself, `q = 1`.
Homogeneously, `q M`, `q n~`, `q (P - M)` and `q (L - M)` are polynomials of degree 2.

At a refraction point Snell's law in vector form holds (math.md §1, the half-vector
form of §4): `n~ x (w_L + eta w_P) = 0` (`w_P`, `w_L` unit vectors from `M` to `P` and
`L`). On the coplanarity curve `n~`, `w_P` and `w_L` lie in one plane through `P`, `L`
and `M`, so this cross product is parallel to the plane's normal `nu`, and with a fixed
vector `w` (the plane normal at the arc piece's middle) the scalar

    S = (n~ x w_L) . w + eta (n~ x w_P) . w

vanishes at every solution. Clearing the square roots of `|P - M|` and `|L - M|`:

    G(x) = X^2 |q (P - M)|^2 - eta^2 Y^2 |q (L - M)|^2,
    X = (q n~) . (q (L - M) x w),   Y = (q n~) . (q (P - M) x w),

a polynomial of degree 12 in `x` with `G = q^6 (...)`, `q != 0` on the arc (its points
are finite). Every solution on the arc is a root of `G`. Roots of `G` that are not
solutions (the other sign of the square roots, `n~ x (w_L - eta w_P) = 0`; points where
`nu` is orthogonal to `w`; backward rays) are harmless: each candidate is accepted only
where `|f| <= tol` with a forward refracted ray (`objectives.bracket_objective`).

**Isolation (Bernstein subdivision).** `G` is built directly in the Bernstein basis of
degree 12 on `[0, 1]` (products of Bernstein polynomials have Bernstein coefficients
`sum C(m,i) C(n,j) / C(m+n,k) f_i g_j`, all weights positive, so nothing cancels that
the absolute-value bound below does not see). By the variation-diminishing property
(Descartes' rule of signs in the Bernstein basis; Lane & Riesenfeld 1981), the number of
roots of `G` in `(0, 1)` is at most the number of sign variations of its coefficients and
has the same parity. Hence:

- all coefficients of one strict sign: no root in the interval (excluded);
- exactly one variation: exactly one simple root (isolated; `G` changes sign, so
  bisection on `S` converges to it when it is a solution);
- otherwise split the interval in two (de Casteljau at 1/2) and decide each half.

Rounding is accounted for: each coefficient carries a bound `delta = 4096 eps G_abs`
(2^-40 in float64), with `G_abs` the same products taken over the absolute values of
every factor: the standard a-priori bound `gamma_n G_abs` of a sum of products evaluated
in `n` roundings (Higham 2002, §3.1), here with `n` well below 4096. Against exact
rational arithmetic on the same float64 pieces the error measured at most `3.2 eps G_abs`
(`tests/test_arc_roots.py`), 1300 times below the bound. The bounds are carried through
the subdivisions (de Casteljau is a convex combination). A
coefficient within `delta` of zero has no certain sign: its interval is never excluded
or isolated, only split. An interval whose coefficients are all within their bounds
(`|G|` is at the rounding level on all of it: a double root, where two refraction points
merge at a caustic through `P`, or roots closer than rounding can separate) is one
candidate, its midpoint; so is an interval still undecided after `max_depth` halvings
(`2^-max_depth` of the arc piece). Without the first rule a double root would be split
down to `max_depth` over the whole region where `|G|` is below rounding (width
`sqrt(delta / G'')`), `2^max_depth` times that many intervals.

What is certified, and under which assumptions: every root of `G` on the arc pieces
given, for the curve defined by the float64 pieces `a_h, b_h, q` (the conic's rounding,
a perturbation of relative size eps of the input) -- none is missed, and each isolated
root is unique in its interval. The pieces must cover the curve inside the face
(`arcs.face_arcs` from every edge root, plus an ellipse inside the face, anchored here
on the line through its centre; an arc on one line of a conic that is a line pair, where
the pencil through its start sweeps only the other line, as the segment,
`chord_on_conic`); exact edge and vertex roots belong to both faces and are found at the
end of an arc piece (undecided up to `max_depth`, then a candidate).
"""

from __future__ import annotations

from math import comb
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..math.conic import conic_centre, conic_tangent, solve_quadratic
from ..math.objectives import path_vectors
from .arcs import arc_from_point, edge_roots, inward, on_tangent_line, orientation

#: Degree of `G` in the Bernstein basis.
DEGREE = 12
#: Rounding bound of each Bernstein coefficient of `G`, in units of the dtype's eps times
#: the coefficient of the absolute-value products (2^-40 in float64; module docstring).
ROUNDING_ULPS = 4096
#: Arc pieces per arc (each arc's pencil angle range is cut in `PIECES` equal parts, each
#: below pi/2).
PIECES = 2
#: A chord between two curve points lies on the conic when `|d^T S2 d|` is within this
#: many eps of `|A| d_a^2 + |B| d_b^2 + |C| |d_a d_b|` (`chord_on_conic`): the relative
#: tolerance of `arcs.next_crossing`'s "on the tangent line".
STRAIGHT_ULPS = 1000


def _product_weights(m: int, n: int) -> np.ndarray:
    """`W[i, j, k] = C(m, i) C(n, j) / C(m + n, k)` for `i + j = k`: the Bernstein product."""
    W = np.zeros((m + 1, n + 1, m + n + 1))
    for i in range(m + 1):
        for j in range(n + 1):
            W[i, j, i + j] = comb(m, i) * comb(n, j) / comb(m + n, i + j)
    return W


_WEIGHTS = {(m, n): _product_weights(m, n) for m, n in ((2, 2), (4, 4), (8, 4))}


def bernstein_product(f, g):
    """Bernstein coefficients of `f g` from those of `f` `(..., m+1)` and `g` `(..., n+1)`."""
    m, n = f.shape[-1] - 1, g.shape[-1] - 1
    W = jnp.asarray(_WEIGHTS[(m, n)], f.dtype)
    return jnp.einsum("...i,...j,ijk->...k", f, g, W)


def _split_matrices(n: int) -> tuple[np.ndarray, np.ndarray]:
    """de Casteljau at 1/2 as matrices: `left = Ml b`, `right = Mr b` (exact binary weights)."""
    Ml = np.zeros((n + 1, n + 1))
    for k in range(n + 1):
        for i in range(k + 1):
            Ml[k, i] = comb(k, i) / 2.0**k
    Mr = Ml[::-1, ::-1].copy()
    return Ml, Mr


_SPLIT = _split_matrices(DEGREE)


def bernstein_split(b):
    """Coefficients `(..., DEGREE+1)` on the two halves of the interval (de Casteljau at 1/2)."""
    Ml, Mr = (jnp.asarray(M, b.dtype) for M in _SPLIT)
    return b @ Ml.T, b @ Mr.T


class ArcPiece(NamedTuple):
    """One arc piece of a face's conic, in the pencil through `anchor` (a curve point).

    Attributes:
        anchor: `(..., 2)` barycentrics of the pencil's centre (the arc's start).
        tau, perp: `(..., 2)` the pencil frame (`arcs.orientation`): angle `phi` from `tau`
            towards `perp`.
        phi_lo, phi_hi: the piece's pencil angles (`phi_hi - phi_lo < pi/2`); on a straight
            conic, the fractions of the segment `anchor -> end` instead.
        end: `(..., 2)` the arc's end (used by straight conics only).
        straight: the piece is a segment: the conic is a line (`is_straight`), or the arc
            lies on one line of a line pair (`chord_on_conic`, `pieces_of_arc`).
        ok: the piece exists.
    """

    anchor: jax.Array
    tau: jax.Array
    perp: jax.Array
    phi_lo: jax.Array
    phi_hi: jax.Array
    end: jax.Array
    straight: jax.Array
    ok: jax.Array


def pieces_of_arc(anchor, tau, perp, phi_end, end, straight, ok) -> ArcPiece:
    """The `PIECES` pieces `(PIECES, ...)` of one arc from `anchor` to pencil angle `phi_end`.

    An arc whose end lies ahead on the tangent line at `anchor` (`arcs.on_tangent_line`,
    where `next_crossing` puts it at pencil angle `eps |end - anchor|`) is the straight
    segment to `end`, whatever `straight` says: a line meeting a conic at a point of
    tangency and at one more point lies on the conic (it meets it three times, counted
    with multiplicity), so the conic is a line pair there, and the pencil through a
    point of one line sweeps the other line only (see `chord_on_conic`)."""
    v = end - anchor
    scale = jnp.sum(jnp.abs(end)) + jnp.sum(jnp.abs(anchor))
    straight = straight | (on_tangent_line(v @ perp, jnp.linalg.norm(v), scale) & (v @ tau > 0))
    k = jnp.arange(PIECES, dtype=anchor.dtype)
    span = jnp.where(straight, 1, phi_end)
    rep = lambda x: jnp.broadcast_to(x, (PIECES,) + jnp.shape(x))  # noqa: E731
    return ArcPiece(rep(anchor), rep(tau), rep(perp), k / PIECES * span, (k + 1) / PIECES * span,
                    rep(end), rep(straight), rep(ok))


def interior_ellipse(coef):
    """`(anchor, tau, perp, ok)` of an ellipse lying inside the face (no edge root): anchored
    where the line through its centre parallel to the `a` axis meets it (that line always
    does; `face_arcs` anchors on `b = 1/3`, which misses a small ellipse off that line)."""
    A, B, C, D, E, F = coef
    _, valid, _ = edge_roots(coef)
    a_c, b_c, ellipse = conic_centre(coef)
    s, s_ok = solve_quadratic(A, C * b_c + D, B * b_c * b_c + E * b_c + F)
    anchor = jnp.stack([s[0], b_c])
    tau, perp = orientation(coef, anchor, conic_tangent(coef, anchor))
    inside = (a_c >= 0) & (b_c >= 0) & (a_c + b_c <= 1)
    return anchor, tau, perp, ellipse & inside & s_ok[0] & ~jnp.any(valid)


def chord_on_conic(coef, anchor, end):
    """The chord from curve point `anchor` to curve point `end` lies on the conic (to
    rounding): the conic is a line pair and the arc between them is the segment.

    On the line `anchor + u d`, `d = end - anchor`, the conic (seed 001 eq. 12) is the
    quadratic `kappa u^2 + (g . d) u + Q(anchor)` with `kappa = d^T S2 d` (`S2` its
    quadratic part, `g` its gradient at `anchor`); it vanishes at `u = 0` and `u = 1`, so
    it is `kappa u (u - 1)`, and the whole line lies on the conic exactly when
    `kappa = 0`. A conic containing a line is degenerate: a pair of lines, as on every face
    of a surface whose vertex normals lie in one plane together with `PL` (a single wave,
    a receiver under a point light, `tests/test_exhaustive.py`). The pencil through a
    point of one line meets the conic again only on the other line (every line through
    it but the line itself), so it cannot parametrise that arc: it is taken as the
    segment. Tolerance: `|kappa| <= STRAIGHT_ULPS eps (|A| d_a^2 + |B| d_b^2 + |C| |d_a d_b|)`,
    which a curved arc meets only within `~STRAIGHT_ULPS eps |d|` of its chord."""
    A, B, C = coef[0], coef[1], coef[2]
    d = end - anchor
    kappa = A * d[0] * d[0] + B * d[1] * d[1] + C * d[0] * d[1]
    size = jnp.abs(A) * d[0] * d[0] + jnp.abs(B) * d[1] * d[1] + jnp.abs(C * d[0] * d[1])
    eps = jnp.finfo(coef.dtype).eps
    return (jnp.abs(kappa) <= STRAIGHT_ULPS * eps * size) & jnp.any(d != 0)


def is_straight(coef):
    """The conic is a line (`A = B = C = 0` to rounding: constant normals), as `face_arcs`."""
    return jnp.max(jnp.abs(coef[:3])) <= 64 * jnp.finfo(coef.dtype).eps * jnp.max(jnp.abs(coef))


def face_pieces(coef) -> ArcPiece:
    """Every arc piece of a face's conic: `(7 PIECES,)` fields: the six arcs of
    `arcs.face_arcs` (from each edge root, oriented inward, to the next crossing), vmapped
    over the roots rather than unrolled (one compiled copy), and the interior ellipse of
    `interior_ellipse`.

    Each arc between two edge roots is listed from both ends; the copy from the root of
    larger index is marked not `ok` when the reverse arc exists and ends back at it
    (the end root's index is found by exact equality of its parameter: `next_crossing`
    returns one of the roots as computed). Where that is not certain both copies stay.
    An arc whose chord lies on the conic (`chord_on_conic`: a line pair) is the segment."""
    roots = edge_roots(coef)
    t_all, valid_all, ab_all = roots
    straight = is_straight(coef)

    def from_root(k, j):
        x = ab_all[k, j]
        arc = arc_from_point(coef, x, inward(k, coef.dtype), k, t_all[k, j], roots)
        tau, perp, ok, k_end, t_end, end, phi = arc.tau, arc.perp, arc.exists, arc.edge, arc.t, arc.ab, arc.phi
        same = valid_all[k_end] & (t_all[k_end] == t_end)
        end_index = jnp.where(jnp.any(same), 2 * k_end + jnp.argmax(same), -1)
        return x, tau, perp, jnp.where(ok, phi, 0), end, valid_all[k, j] & ok, end_index, chord_on_conic(coef, x, end)

    k, j = jnp.repeat(jnp.arange(3), 2), jnp.tile(jnp.arange(2), 3)
    anchor, tau, perp, phi_end, end, ok, end_index, chord = jax.vmap(from_root)(k, j)
    own = jnp.arange(6)
    e = jnp.maximum(end_index, 0)
    reverse_exists = (end_index >= 0) & ok[e] & (end_index[e] == own)
    ok = ok & ~(reverse_exists & (end_index < own))
    e_anchor, e_tau, e_perp, e_ok = interior_ellipse(coef)
    cat = lambda a, b: jnp.concatenate([a, b[None]])  # noqa: E731
    anchor, tau, perp, end = cat(anchor, e_anchor), cat(tau, e_tau), cat(perp, e_perp), cat(end, e_anchor)
    phi_end = cat(phi_end, jnp.asarray(jnp.pi, coef.dtype))
    ok = cat(ok, e_ok & ~straight)
    straight = straight | cat(chord, jnp.asarray(False))
    p = jax.vmap(pieces_of_arc)(anchor, tau, perp, phi_end, end, straight, ok)
    return jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), p)


def piece_homogeneous(coef, piece: ArcPiece):
    """Bernstein coefficients `(3, 2)` of `(a_h, b_h)` and `(3,)` of `q` on `x in [0, 1]`."""
    A, B, C, D, E, _ = coef
    S2 = jnp.stack([jnp.stack([A, C / 2]), jnp.stack([C / 2, B])])
    d0 = jnp.cos(piece.phi_lo) * piece.tau + jnp.sin(piece.phi_lo) * piece.perp
    d1 = jnp.cos(piece.phi_hi) * piece.tau + jnp.sin(piece.phi_hi) * piece.perp
    q = jnp.stack([d0 @ S2 @ d0, d0 @ S2 @ d1, d1 @ S2 @ d1])
    e = piece.anchor
    g = jnp.stack([2 * A * e[0] + C * e[1] + D, 2 * B * e[1] + C * e[0] + E])
    g0, g1 = g @ d0, g @ d1
    num = -jnp.stack([g0 * d0, (g0 * d1 + g1 * d0) / 2, g1 * d1])
    ab_curved = e[None] * q[:, None] + num
    p0 = e + piece.phi_lo * (piece.end - e)
    p1 = e + piece.phi_hi * (piece.end - e)
    ab_line = jnp.stack([p0, (p0 + p1) / 2, p1])
    ab_h = jnp.where(piece.straight, ab_line, ab_curved)
    q = jnp.where(piece.straight, jnp.ones_like(q), q)
    return ab_h, q


def piece_point(coef, piece: ArcPiece, x):
    """Barycentrics `(a, b)` of the arc piece at `x in [0, 1]` (the pencil point)."""
    ab_h, q = piece_homogeneous(coef, piece)
    w = jnp.stack([(1 - x) ** 2, 2 * x * (1 - x), x * x])
    qx = w @ q
    return (w @ ab_h) / jnp.where(qx == 0, 1, qx)


def _plane_normal(V, N, P, L, ab):
    """Unit normal of the plane through `P`, `L` and the curve point `ab` (`PL x n~`, or
    `PL x PM` where the normal is nearly parallel to `PL`)."""
    M, n_s, _, _, _ = path_vectors(V, N, P, L, ab)
    PL = L - P
    a = jnp.cross(PL, n_s)
    b = jnp.cross(PL, M - P)
    ua = a / jnp.maximum(jnp.linalg.norm(a), jnp.finfo(a.dtype).tiny)
    ub = b / jnp.maximum(jnp.linalg.norm(b), jnp.finfo(b.dtype).tiny)
    use_a = jnp.linalg.norm(a) >= 0.1 * jnp.linalg.norm(PL)
    return jnp.where(use_a, ua, ub)


def _cross_bern(X, w):
    """`X x w` for Bernstein coefficient rows `X` `(k, 3)` and a constant vector `w`."""
    return jnp.cross(X, w[None])


def _cross_bern_abs(X, w):
    aX, aw = jnp.abs(X), jnp.abs(w)
    return jnp.stack([aX[:, 1] * aw[2] + aX[:, 2] * aw[1],
                      aX[:, 2] * aw[0] + aX[:, 0] * aw[2],
                      aX[:, 0] * aw[1] + aX[:, 1] * aw[0]], -1)


def _dot_bern(X, Y):
    """`X . Y` for vector polynomials `(3 coefs, 3)`: degree 4 `(5,)`."""
    return jnp.sum(bernstein_product(X.T, Y.T), axis=0)


def arc_polynomial(V, N, P, L, coef, piece: ArcPiece, eta):
    """`(G, delta, w)`: Bernstein coefficients `(13,)` of `G` on the piece, their rounding
    bounds, and the plane normal `w` used (module docstring)."""
    ab_h, q = piece_homogeneous(coef, piece)
    E1, E2 = V[1] - V[0], V[2] - V[0]
    M_rel = ab_h[:, 0:1] * E1 + ab_h[:, 1:2] * E2  # q (M - V0)
    PM = q[:, None] * (P - V[0]) - M_rel  # q (P - M)
    LM = q[:, None] * (L - V[0]) - M_rel  # q (L - M)
    n_h = q[:, None] * N[0] + ab_h[:, 0:1] * (N[1] - N[0]) + ab_h[:, 1:2] * (N[2] - N[0])
    w = _plane_normal(V, N, P, L, piece_point(coef, piece, jnp.asarray(0.5, q.dtype)))
    X = _dot_bern(n_h, _cross_bern(LM, w))
    Y = _dot_bern(n_h, _cross_bern(PM, w))
    PM2, LM2 = _dot_bern(PM, PM), _dot_bern(LM, LM)
    eta2 = jnp.asarray(eta, q.dtype) ** 2
    G = bernstein_product(bernstein_product(X, X), PM2) - eta2 * bernstein_product(bernstein_product(Y, Y), LM2)
    aX = _dot_bern(jnp.abs(n_h), _cross_bern_abs(LM, w))
    aY = _dot_bern(jnp.abs(n_h), _cross_bern_abs(PM, w))
    aPM2, aLM2 = _dot_bern(jnp.abs(PM), jnp.abs(PM)), _dot_bern(jnp.abs(LM), jnp.abs(LM))
    G_abs = (bernstein_product(bernstein_product(aX, aX), aPM2)
             + eta2 * bernstein_product(bernstein_product(aY, aY), aLM2))
    fi = jnp.finfo(q.dtype)
    return G, ROUNDING_ULPS * fi.eps * G_abs + fi.tiny, w


def snell_scalar(V, N, P, L, ab, w, eta):
    """`S = (n~ x w_L) . w + eta (n~ x w_P) . w` at `ab`: zero at every refraction point on
    the curve (module docstring); its sign brackets the isolated roots."""
    _, n_s, w_P, w_L, _ = path_vectors(V, N, P, L, ab)
    return jnp.dot(jnp.cross(n_s, w_L + jnp.asarray(eta, w_P.dtype) * w_P), w)


class Verdict(NamedTuple):
    """`classify`'s answer per interval: excluded (no root), isolated (exactly one simple
    root), flat (`|G|` below its rounding bound on the whole interval: a numerical zero,
    one candidate), or none of these (split)."""

    excluded: jax.Array
    isolated: jax.Array
    flat: jax.Array


def classify(G, delta) -> Verdict:
    """Exclusion and isolation by the signs of the Bernstein coefficients (module docstring)."""
    pos, neg = G > delta, G < -delta
    certain = jnp.all(pos | neg, axis=-1)
    excluded = jnp.all(pos, axis=-1) | jnp.all(neg, axis=-1)
    variations = jnp.sum(pos[..., 1:] != pos[..., :-1], axis=-1)
    flat = ~jnp.any(pos | neg, axis=-1)
    return Verdict(excluded, certain & (variations == 1), flat)


@jax.jit
def _subdivide(G, delta):
    """One round: verdicts of the intervals and the coefficients of their two halves."""
    v = classify(G, delta)
    Gl, Gr = bernstein_split(G)
    dl, dr = bernstein_split(delta)
    return v.excluded, v.isolated, v.flat, Gl, Gr, dl, dr


def isolate_roots(G: np.ndarray, delta: np.ndarray, max_depth: int):
    """Host loop of Bernstein subdivision over many arc pieces at once.

    `G`, `delta`: `(k, 13)` coefficients and bounds of `k` pieces on `[0, 1]`. Returns
    `(piece, x0, x1, isolated)`: every interval that holds roots, with `isolated` True where
    it holds exactly one simple root (else it is narrower than `2^-max_depth` and its
    roots are one candidate). Each round is one jitted call padded to a power of two.
    """
    from ..runtime.lanes import padded_index, power_of_two_bucket

    piece = np.arange(len(G))
    x0, x1 = np.zeros(len(G)), np.ones(len(G))
    out_piece, out_x0, out_x1, out_iso = [], [], [], []
    G, delta = np.asarray(G), np.asarray(delta)
    for depth in range(max_depth + 1):
        n = len(piece)
        if n == 0:
            break
        sel = padded_index(np.arange(n), power_of_two_bucket(n, 64))
        exc, iso, flat, Gl, Gr, dl, dr = (np.asarray(a)[:n] for a in _subdivide(G[sel], delta[sel]))
        keep_iso = iso & ~exc
        out_piece.append(piece[keep_iso])
        out_x0.append(x0[keep_iso])
        out_x1.append(x1[keep_iso])
        out_iso.append(np.ones(keep_iso.sum(), bool))
        out_piece.append(piece[flat])
        out_x0.append(x0[flat])
        out_x1.append(x1[flat])
        out_iso.append(np.zeros(flat.sum(), bool))
        split = ~exc & ~iso & ~flat
        if depth == max_depth:
            out_piece.append(piece[split])
            out_x0.append(x0[split])
            out_x1.append(x1[split])
            out_iso.append(np.zeros(split.sum(), bool))
            break
        mid = (x0[split] + x1[split]) / 2
        piece = np.concatenate([piece[split], piece[split]])
        x0, x1 = np.concatenate([x0[split], mid]), np.concatenate([mid, x1[split]])
        G = np.concatenate([Gl[split], Gr[split]])
        delta = np.concatenate([dl[split], dr[split]])
    cat = lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt)  # noqa: E731
    return cat(out_piece, np.int64), cat(out_x0, np.float64), cat(out_x1, np.float64), cat(out_iso, bool)


def refine_root(V, N, P, L, coef, piece: ArcPiece, eta, x0, x1, iters: int):
    """The root in `[x0, x1]` of the piece: bisection on the sign of `snell_scalar`.

    The interval is first scanned at 9 points for a sign change of `S` (an isolated root of
    `G` that is a solution always makes one; a flat or depth-limited interval may hold one
    too, wide in float32): bisection runs `iters` steps on the first sub-interval with a
    change, else the midpoint is returned (a double root, or a root of `G` that is no
    solution, which acceptance then rejects). Returns barycentrics `(2,)`. Isolated and
    depth-limited intervals are refined the same way."""
    _, _, w = arc_polynomial(V, N, P, L, coef, piece, eta)
    S = lambda x: snell_scalar(V, N, P, L, piece_point(coef, piece, x), w, eta)  # noqa: E731
    xs = x0 + (x1 - x0) * jnp.linspace(0, 1, 9).astype(jnp.result_type(x0))
    Ss = jax.vmap(S)(xs)
    change = jnp.sign(Ss[:-1]) * jnp.sign(Ss[1:]) <= 0
    j = jnp.argmax(change)
    has = jnp.any(change)
    lo, hi, s_lo = jnp.where(has, xs[j], x0), jnp.where(has, xs[j + 1], x1), Ss[j]

    def body(_, c):
        lo, hi, s_lo = c
        mid = (lo + hi) / 2
        s_mid = S(mid)
        left = jnp.sign(s_mid) * jnp.sign(s_lo) <= 0
        return jnp.where(left, lo, mid), jnp.where(left, mid, hi), jnp.where(left, s_lo, s_mid)

    lo, hi, _ = jax.lax.fori_loop(0, jnp.where(has, iters, 0), body, (lo, hi, s_lo))
    return piece_point(coef, piece, (lo + hi) / 2)
