"""The coplanarity conic of seed 001 §3.3: coefficients, tangent, and edge intersections.

`M(a, b)` on a triangle with interpolated normal `n~(a, b)` satisfies the coplanarity
constraint `n~ . (PL x PM) = 0` (seed 001 eq. 9) on the conic
`A a^2 + B b^2 + C a b + D a + E b + F = 0` (eq. 12).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..runtime.kernel_contract import float_inputs
from .barycentric import edge_barycentric


def conic_matrix(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
) -> Float[Array, "*batch 3 3"]:
    """`K = N^T Q` of seed 001 eq. 10, so that the constraint reads `x^T K x = 0`, `x = (a, b, 1)`.

    Columns of `N`: `n1 - n0, n2 - n0, n0` (eq. 7); columns of `Q`:
    `PL x V0V1, PL x V0V2, PL x PV0` (eq. 10). `K` is not symmetric.
    """
    PL = L - P
    Ncols = jnp.stack([N[..., 1, :] - N[..., 0, :], N[..., 2, :] - N[..., 0, :], N[..., 0, :]], -2)
    edges = jnp.stack([V[..., 1, :] - V[..., 0, :], V[..., 2, :] - V[..., 0, :], V[..., 0, :] - P], -2)
    Qcols = jnp.cross(PL[..., None, :], edges)
    # K[i, j] = Ncol_i . Qcol_j
    return jnp.einsum("...ik,...jk->...ij", Ncols, Qcols)


@float_inputs("V", "N", "P", "L")
def conic_coefficients(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
) -> Float[Array, "*batch 6"]:
    """Conic coefficients `A, B, C, D, E, F` of the coplanarity constraint (seed 001 eq. 10-12).

    `V`, `N`: the triangle's vertex positions and vertex normals (rows); `P` receiver, `L`
    light. With `K = N^T Q`: `A = K11, B = K22, C = K12 + K21, D = K13 + K31,
    E = K23 + K32, F = K33` (math.md §2).
    """
    K = conic_matrix(V, N, P, L)
    return jnp.stack(
        [
            K[..., 0, 0],
            K[..., 1, 1],
            K[..., 0, 1] + K[..., 1, 0],
            K[..., 0, 2] + K[..., 2, 0],
            K[..., 1, 2] + K[..., 2, 1],
            K[..., 2, 2],
        ],
        axis=-1,
    )


@float_inputs("coef", "ab")
def conic_value(coef: Float[Array, "*batch 6"], ab: Float[Array, "*batch 2"]) -> Float[Array, "*batch"]:
    """`A a^2 + B b^2 + C a b + D a + E b + F` (seed 001 eq. 12)."""
    A, B, C, D, E, F = jnp.moveaxis(coef, -1, 0)
    a, b = ab[..., 0], ab[..., 1]
    return A * a * a + B * b * b + C * a * b + D * a + E * b + F


def symmetric_matrix(coef: Float[Array, "*batch 6"]) -> Float[Array, "*batch 3 3"]:
    """Symmetric part `S = (K + K^T) / 2` of the conic, rebuilt from `A..F` (seed 001 eq. 12;
    math.md §2: `S x` is half the gradient of `x^T K x`)."""
    A, B, C, D, E, F = jnp.moveaxis(coef, -1, 0)
    return jnp.stack(
        [
            jnp.stack([A, C / 2, D / 2], -1),
            jnp.stack([C / 2, B, E / 2], -1),
            jnp.stack([D / 2, E / 2, F], -1),
        ],
        -2,
    )


@float_inputs("coef", "ab")
def conic_tangent(coef: Float[Array, "*batch 6"], ab: Float[Array, "*batch 2"]) -> Float[Array, "*batch 2"]:
    """Tangent `(-v, u)` of the conic at `ab` in barycentric space (seed 001 eq. 13-15).

    `(u, v, w) = S (a, b, 1)` with the symmetric part `S`. The paper's eq. 14 multiplies by
    `K^T`, which is the gradient direction only for symmetric `K` (math.md §2;
    `tests/test_conic.py::test_paper_tangent_with_K_transpose_is_wrong_away_from_M0`
    shows the difference). Not normalised: its length is half the gradient's, zero at a
    singular point of the conic.
    """
    A, B, C, D, E, F = jnp.moveaxis(coef, -1, 0)
    a, b = ab[..., 0], ab[..., 1]
    u = A * a + C / 2 * b + D / 2
    v = C / 2 * a + B * b + E / 2
    return jnp.stack([-v, u], axis=-1)


def conic_centre(coef: Float[Array, "*batch 6"]):
    """Centre `(a_c, b_c)` of the conic `A a^2 + B b^2 + C ab + D a + E b + F` (seed 001
    eq. 11), where its gradient vanishes (`2A a + C b + D = 0`, `C a + 2B b + E = 0`), and
    whether it is an ellipse (`4AB - C^2 > 0`). Where it is not, the centre is finite and
    meaningless (the divisor is replaced by 1)."""
    A, B, C, D, E, _ = jnp.moveaxis(coef, -1, 0)
    det = 4 * A * B - C * C
    ellipse = det > 0
    safe = jnp.where(ellipse, det, 1)
    return (C * E - 2 * B * D) / safe, (C * D - 2 * A * E) / safe, ellipse


@float_inputs("V", "t")
def tangent_to_world(V: Float[Array, "*batch 3 3"], t: Float[Array, "*batch 2"]) -> Float[Array, "*batch 3"]:
    """`t_world = t_a (V1 - V0) + t_b (V2 - V0)` (math.md §2)."""
    return t[..., 0:1] * (V[..., 1, :] - V[..., 0, :]) + t[..., 1:2] * (V[..., 2, :] - V[..., 0, :])


def edge_quadratics(coef: Float[Array, "*batch 6"]) -> Float[Array, "*batch 3 3"]:
    """Quadratic `(q2, q1, q0)` in the edge parameter `t` for edges 0, 1, 2 (seed 001 eq. 22-24).

    Edge 0 (`b = 0`, `t = a`): `A t^2 + D t + F`; edge 1 (`(a, b) = (1 - t, t)`):
    `(A + B - C) t^2 + (C + E - 2A - D) t + (A + D + F)`; edge 2 (`a = 0`, `t = b`):
    `B t^2 + E t + F`. The paper's eq. 22 (`B b^2 + D b + F`) and eq. 23
    (`A a^2 + C a + F`) are misprints (math.md §3); eq. 24 is right.
    """
    A, B, C, D, E, F = jnp.moveaxis(coef, -1, 0)
    e0 = jnp.stack([A, D, F], -1)
    e1 = jnp.stack([A + B - C, C + E - 2 * A - D, A + D + F], -1)
    e2 = jnp.stack([B, E, F], -1)
    return jnp.stack([e0, e1, e2], -2)


def power_of_two_floor(x):
    """`2^floor(log2 x)` for positive normal `x`, from its exponent bits alone (0 for a
    subnormal): dividing by it is exact. Bit masks, where `jnp.frexp`/`ldexp` lower to
    ~50 and ~35 operations each: the walk solves ~20 quadratics, so the mask keeps its
    program smaller and its first compile shorter (docs/solvers.md, "Measurements behind
    the code"; docs/conic.md)."""
    x = jnp.asarray(x)
    info = jnp.finfo(x.dtype)
    uint = {4: jnp.uint32, 8: jnp.uint64}[x.dtype.itemsize]
    exponent_bits = ((1 << (info.bits - 1)) - 1) ^ ((1 << info.nmant) - 1)
    bits = jax.lax.bitcast_convert_type(x, uint)
    return jax.lax.bitcast_convert_type(bits & jnp.asarray(exponent_bits, uint), x.dtype)


@float_inputs("q2", "q1", "q0")
def solve_quadratic(
    q2: Float[Array, "*batch"], q1: Float[Array, "*batch"], q0: Float[Array, "*batch"]
) -> tuple[Float[Array, "*batch 2"], Bool[Array, "*batch 2"]]:
    """Real roots of `q2 t^2 + q1 t + q0 = 0`, ascending, without cancellation.

    `q = -(q1 + sign(q1) sqrt(disc)) / 2`, roots `q / q2` and `q0 / q` (Numerical Recipes
    §5.6). The coefficients are first scaled by their largest magnitude so nothing
    overflows (exactly: the scale is a power of two). Cases, each masked rather than poisoned:
    - `q2 = 0`: the single linear root `-q0 / q1`;
    - `|disc| <= 8 eps (q1^2 + |4 q2 q0|)` (zero within rounding): tangency, one double
      root `-q1 / 2 q2` reported once; two roots that close are not separable anyway;
    - all coefficients zero (the whole line lies on the conic): no isolated root;
    - a coefficient not finite: no root (an infinite one had given a NaN root marked valid).
    Returns `(roots, valid)`; invalid lanes hold 0.
    """
    dtype = jnp.result_type(q2, q1, q0)
    eps = jnp.finfo(dtype).eps
    scale = jnp.maximum(jnp.maximum(jnp.abs(q2), jnp.abs(q1)), jnp.abs(q0))
    nonzero = (scale > 0) & jnp.isfinite(scale)
    # Scale by a power of two (exact) so that the largest coefficient is in [1, 2).
    pow2 = power_of_two_floor(jnp.where(nonzero, scale, 1))
    pow2 = jnp.where(pow2 > 0, pow2, 1)  # (a subnormal scale: left unscaled)
    a, b, c = (x / pow2 for x in (q2, q1, q0))
    linear = a == 0
    a_safe = jnp.where(linear, 1, a)
    disc = b * b - 4 * a * c
    rounding = 8 * eps * (b * b + jnp.abs(4 * a * c))
    tangent = nonzero & ~linear & (jnp.abs(disc) <= rounding)
    two = nonzero & ~linear & (disc > rounding)
    one_linear = nonzero & linear & (b != 0)

    sign_b = jnp.where(b >= 0, 1, -1).astype(dtype)
    q = -(b + sign_b * jnp.sqrt(jnp.where(two, disc, 1))) / 2  # |q| > 0 wherever `two`
    q_safe = jnp.where(two, q, 1)
    r1, r2 = q / a_safe, c / q_safe
    root0 = jnp.where(
        two,
        jnp.minimum(r1, r2),
        jnp.where(tangent, -b / (2 * a_safe), jnp.where(one_linear, -c / jnp.where(b != 0, b, 1), 0)),
    )
    root1 = jnp.where(two, jnp.maximum(r1, r2), 0)
    roots = jnp.stack([root0, root1], -1)
    valid = jnp.stack([two | tangent | one_linear, two], -1)
    return jnp.where(valid, roots, 0), valid


#: Largest `tol` of `edge_intersections`: a slack for rounding, not a search radius.
EDGE_TOL_MAX = 1e-2


@float_inputs("coef", params=("tol",), bounds={"tol": (0, EDGE_TOL_MAX)})
def edge_intersections(coef: Float[Array, "*batch 6"], tol: float | None = None):
    """Intersections of the conic with the three edges (seed 001 eq. 22-24, corrected).

    Returns `(t, valid)`, both `(..., 3, 2)`: up to two roots per edge in the edge
    parameter of `barycentric.py` (edge 0: `t = a`; edge 1: `(a, b) = (1 - t, t)`; edge 2:
    `t = b`). A root is kept when it lies in `[-tol, 1 + tol]` and is then clamped to
    `[0, 1]`; `tol` defaults to `64 eps` of the dtype. A root at a vertex therefore appears
    on both edges that meet there; a tangency is one root; an edge lying entirely on the
    conic reports none (the walk treats such degenerate edges by its status codes).

    `tol` is a slack for the roots' rounding, in `[0, EDGE_TOL_MAX]` (1e-2): a clamped root
    lies up to `tol` of the edge off the conic, so `tol = 1e6` had made every root of the
    edges' lines a valid intersection, and `tol < 0` or NaN none. A concrete value outside
    is a `ValueError`; inside jit it is clipped into that range (NaN: the default).
    """
    quad = edge_quadratics(coef)
    default = 64 * jnp.finfo(coef.dtype).eps
    if tol is None:
        tol = default
    else:
        tol = jnp.where(jnp.isnan(tol), default, jnp.clip(tol, 0, EDGE_TOL_MAX))
    return edge_quadratic_roots(quad[..., 0], quad[..., 1], quad[..., 2], tol)


def edge_quadratic_roots(q2, q1, q0, tol=None):
    """`edge_intersections` for one edge's quadratic `(q2, q1, q0)` (`edge_quadratics`):
    its roots in `[-tol, 1 + tol]` clamped to `[0, 1]`, ascending, and which are valid
    (`tol` already checked; None: `64 eps`). The walk's sign-test exit
    (`arcs.sign_test_exit`) solves the exit edge alone with it."""
    t, valid = solve_quadratic(q2, q1, q0)
    tol = 64 * jnp.finfo(t.dtype).eps if tol is None else tol
    inside = (t >= -tol) & (t <= 1 + tol)
    valid = valid & inside
    return jnp.where(valid, jnp.clip(t, 0, 1), 0), valid


def edge_intersection_points(t: Float[Array, "*batch 3 2"]) -> Float[Array, "*batch 3 2 2"]:
    """Barycentric `(a, b)` of each edge root returned by `edge_intersections` (seed 001
    eq. 22-24 as corrected in math.md §3; edge table of `barycentric.py`)."""
    edge = jnp.arange(3)[:, None]
    return edge_barycentric(jnp.broadcast_to(edge, t.shape), t)


def conic_second_intersection(
    coef: Float[Array, "*batch 6"], ab0: Float[Array, "*batch 2"], d: Float[Array, "*batch 2"]
) -> tuple[Float[Array, "*batch 2"], Bool[Array, "*batch"]]:
    """Second point where the line `ab0 + s d` meets the conic, for `ab0` on the conic.

    Every line through a point of a conic meets it in exactly one other point, so the
    pencil of lines through `ab0` parametrises the whole curve by the line's angle; the
    walk bisects along the curve with it (seed 001 §3.4.3 "split the triangle so the new
    edge cuts the curve", here with the cutting line through a known curve point).
    `Q(ab0 + s d) = Q0 + s (grad . d) + s^2 (d^T S2 d)`; of its two roots the one of larger
    magnitude is the new point (the other is the anchor, `s ~ 0`). Invalid when the line
    is parallel to an asymptote (the point is at infinity).
    """
    A, B, C, D, E, F = jnp.moveaxis(coef, -1, 0)
    a, b = ab0[..., 0], ab0[..., 1]
    da, db = d[..., 0], d[..., 1]
    q2 = A * da * da + B * db * db + C * da * db
    grad_a = 2 * A * a + C * b + D
    grad_b = 2 * B * b + C * a + E
    q1 = grad_a * da + grad_b * db
    q0 = conic_value(coef, ab0)
    s, valid = solve_quadratic(q2, q1, q0)
    both = valid[..., 0] & valid[..., 1]
    far = jnp.where(both & (jnp.abs(s[..., 0]) > jnp.abs(s[..., 1])), s[..., 0], s[..., 1])
    ok = both  # a single (linear or tangent) root is the anchor itself
    return ab0 + jnp.where(ok, far, 0)[..., None] * d, ok
