"""Segment-triangle crossing (Möller-Trumbore) with a rounding-aware acceptance test, and
the slab clip of a segment against a box: the two kernels every surface query shares
(start points, occlusion, photon hits).

Why the tolerance is not a constant. Möller & Trumbore (1997) compute the barycentrics
`(a, b)` of the crossing (seed 001 eq. 3) as `a = tvec . pvec / det`,
`b = d . qvec / det`, `s = e2 . qvec / det` with `tvec = P - V0`, `pvec = d x e2`,
`qvec = tvec x e1`, `det = e1 . pvec`. The coordinates of `P` and `V0` are known only to
`u |x|` (`u` the unit roundoff of the dtype), so `tvec` carries an absolute error of about
`delta = u (max(|P|, |V0|) + |s| |d|)` (the last term: `d = L - P` was rounded too, to
`u |d|`, which moves the line by `u |s| |d|` at the crossing's `s`; `|s|` is capped at 1, the
segment's end. Before the cap on `s` the term was `u |d|` whatever `s`: with a light 1e8
times farther than the scene, as a directional light is placed (math.md §9), every
neighbour face then held the crossing "within rounding"). First-order propagation gives

    err(a) <= delta |pvec| / |det|,   err(b) <= delta |d| |e1| / |det|,
    err(s) <= delta |e1| |e2| / |det|

(`|pvec| / |det|` is `1 / (height of V1 over the edge V0 V2)` for a segment along the
normal, and grows as `1 / cos` for a grazing one). A constant tolerance such as
`16 eps` is orders of magnitude too small for small cells far from the origin: a segment
through a shared edge or vertex is then rejected by every face around it, and since
XLA's CPU rounding of the same lane differs with the batch shape, such a lane is found
alone and lost in a batch (docs/mesh.md, "Crossings on cell walls, edges and vertices").
Here each bound is `C_ROUND = 8` times the first-order estimate plus `16 eps`: a 32x
margin over the smallest factor at which planted edge and vertex crossings stop being
missed, far more than the rounding differences between batch shapes (docs/mesh.md,
"Measurements behind the code"). A hit that close outside a face is a hit of the face
within the rounding of its coordinates; its barycentrics are projected into the closed
triangle.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .geometry import dot

#: Safety factor on the first-order rounding estimate of the barycentrics (module docstring).
C_ROUND = 8


class Crossing(NamedTuple):
    """Crossing of a line with a triangle (`triangle_crossing`).

    Attributes:
        s: line parameter, unclipped (0 where the line is parallel to the plane).
        ab: barycentrics `(a, b)` of seed 001 eq. 3, projected into the closed triangle.
        inside: the crossing lies in the triangle within the rounding bound.
        exact: it lies in the closed triangle as computed (no tolerance needed).
        s_tol: the rounding bound of `s`.
    """

    s: Float[Array, "*batch"]
    ab: Float[Array, "*batch 2"]
    inside: Bool[Array, "*batch"]
    exact: Bool[Array, "*batch"]
    s_tol: Float[Array, "*batch"]

    def rank(self) -> Float[Array, "*batch"]:
        """Order of preference among hits: `s`, with a hit that needed the tolerance moved
        back by `s_tol`, so that where a segment crosses near a shared edge the face that
        holds the crossing as computed wins over its neighbour's extended plane (whose
        projected point is off by up to the tolerance), while a distinct earlier crossing
        still comes first."""
        return jnp.where(self.exact, self.s, self.s + self.s_tol)


class FaceFrame(NamedTuple):
    """What Möller-Trumbore needs of a triangle, independent of the line (`face_frames`):
    a table of these is computed once per call and gathered per face test."""

    V0: Float[Array, "*batch 3"]
    e1: Float[Array, "*batch 3"]  # V1 - V0
    e2: Float[Array, "*batch 3"]  # V2 - V0
    len_e1: Float[Array, "*batch"]
    len_e2: Float[Array, "*batch"]
    V0_max: Float[Array, "*batch"]  # max |V0| component, for the rounding bound


def finite_segments(A: Float[Array, "n 3"], B: Float[Array, "n 3"]):
    """`(A, B)` with every lane holding a NaN or Inf made a zero-length segment at the
    origin, which crosses nothing (the traversals' padding lanes): a NaN end had kept the
    cell and BVH traversals looping forever (`start_points.first_crossing`,
    `transport.path_visible`). Inside jit, where inputs are not checked."""
    finite = jnp.all(jnp.isfinite(A) & jnp.isfinite(B), axis=-1, keepdims=True)
    return jnp.where(finite, A, 0), jnp.where(finite, B, 0)


def face_frames(V: Float[Array, "*batch 3 3"]) -> FaceFrame:
    """The `FaceFrame` of triangles `V`."""
    V0 = V[..., 0, :]
    e1, e2 = V[..., 1, :] - V0, V[..., 2, :] - V0
    return FaceFrame(V0, e1, e2, jnp.sqrt(dot(e1, e1)), jnp.sqrt(dot(e2, e2)), jnp.max(jnp.abs(V0), -1))


def triangle_crossing(P: Float[Array, "*batch 3"], d: Float[Array, "*batch 3"],
                      V: Float[Array, "*batch 3 3"] | FaceFrame) -> Crossing:  # fmt: skip
    """Crossing of the line `P + s d` with triangle `V` (Möller-Trumbore; module docstring).

    `V`: the vertices, or their `face_frames` (a table computed once and gathered per
    test saves the edge vectors and lengths in every test). Returns a `Crossing`. Lines
    in the triangle's plane (`det` at the rounding level) do not cross it.
    """
    frame = V if isinstance(V, FaceFrame) else face_frames(V)
    eps = jnp.finfo(P.dtype).eps
    e1, e2, len_e1, len_e2 = frame.e1, frame.e2, frame.len_e1, frame.len_e2
    pvec = jnp.cross(d, e2)
    det = dot(e1, pvec)
    len_d = jnp.sqrt(dot(d, d))
    ok = jnp.abs(det) > 16 * eps * len_d * len_e1 * len_e2
    inv = jnp.where(ok, 1 / jnp.where(ok, det, 1), 0)
    tvec = P - frame.V0
    qvec = jnp.cross(tvec, e1)
    a, b, s = dot(tvec, pvec) * inv, dot(d, qvec) * inv, dot(e2, qvec) * inv
    # `d`'s rounding (relative `eps`) moves the line by `eps |d|` per unit of `s`: at the
    # crossing by `|s| eps |d|` (a far light's `d` is 1e8 times the scene, its crossing at
    # `s ~ 1e-8`), at most `eps |d|` on the segment.
    reach = jnp.minimum(jnp.abs(s), 1)
    delta = C_ROUND * eps * (jnp.maximum(jnp.max(jnp.abs(P), -1), frame.V0_max) + reach * jnp.max(jnp.abs(d), -1))
    abs_inv = jnp.abs(inv)
    tol_a = 16 * eps + delta * jnp.sqrt(dot(pvec, pvec)) * abs_inv
    tol_b = 16 * eps + delta * len_d * len_e1 * abs_inv
    s_tol = 16 * eps + delta * len_e1 * len_e2 * abs_inv
    inside = ok & (a >= -tol_a) & (b >= -tol_b) & (a + b <= 1 + tol_a + tol_b)
    exact = ok & (a >= 0) & (b >= 0) & (a + b <= 1)
    a, b = jnp.maximum(a, 0), jnp.maximum(b, 0)
    total = jnp.where(a + b > 1, a + b, 1)
    return Crossing(s, jnp.stack([a / total, b / total], axis=-1), inside, exact, s_tol)


def segment_triangle(P: Float[Array, "*batch 3"], d: Float[Array, "*batch 3"],
                     V: Float[Array, "*batch 3 3"]):  # fmt: skip
    """Crossing of the segment `P + s d, s in [0, 1]` with triangle `V` (Möller-Trumbore).

    Returns `(s, ab, hit)`: segment parameter clipped to `[0, 1]`, barycentrics `(a, b)`
    (seed 001 eq. 3, projected into the closed triangle), and whether the segment crosses
    it. Crossings within the rounding bound of the module docstring outside an edge or an
    end count, so a segment through a shared edge or vertex is never lost between faces.
    """
    c = triangle_crossing(P, d, V)
    hit = c.inside & (c.s >= -c.s_tol) & (c.s <= 1 + c.s_tol)
    return jnp.clip(c.s, 0, 1), c.ab, hit


def clip_to_box(P: Float[Array, "n 3"], d: Float[Array, "n 3"], lo, hi,
                s_max: Float[Array, " n"]) -> tuple[Float[Array, " n"], Float[Array, " n"]]:  # fmt: skip
    """Segment parameters `[s_in, s_out]` of `P + s d` inside the box `[lo, hi]`, within
    `[0, s_max]` (slab test; empty when `s_in > s_out`)."""
    moving = d != 0
    inv = jnp.where(moving, 1 / jnp.where(moving, d, 1), 0)
    t0, t1 = (lo - P) * inv, (hi - P) * inv
    inside = (P >= lo) & (P <= hi)
    inf = jnp.asarray(jnp.inf, P.dtype)
    near = jnp.where(moving, jnp.minimum(t0, t1), jnp.where(inside, -inf, inf))
    far = jnp.where(moving, jnp.maximum(t0, t1), jnp.where(inside, inf, -inf))
    s_in = jnp.maximum(jnp.max(near, axis=-1), 0)
    s_out = jnp.minimum(jnp.min(far, axis=-1), s_max)
    return s_in, s_out


def first_of(rank: Float[Array, "n k"], hit: Bool[Array, "n k"], *values):
    """Per row, the smallest `rank` among `hit` (inf where none) and `values` (each
    `(n, k, ...)`) taken at that column."""
    rank = jnp.where(hit, rank, jnp.inf)
    col = jnp.argmin(rank, axis=-1)
    picked = [jnp.take_along_axis(v, col.reshape(col.shape + (1,) * (v.ndim - 1)), axis=1)[:, 0]
              for v in values]  # fmt: skip
    return (jnp.min(rank, axis=-1), *picked)
