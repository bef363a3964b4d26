"""Barycentric conventions of seed 001 eq. 3, and the edge parametrisation every layer shares.

`M = V0 + a (V1 - V0) + b (V2 - V0)`; inside the triangle when `a, b >= 0`, `a + b <= 1`.
Edge `k` joins vertices `k` and `k + 1 mod 3`, with the parameter `t` of
`edge_intersections`:

| edge | line      | (a, b) at parameter t | t = 0 at | t = 1 at |
|------|-----------|-----------------------|----------|----------|
| 0    | b = 0     | (t, 0)                | V0       | V1       |
| 1    | a + b = 1 | (1 - t, t)            | V1       | V2       |
| 2    | a = 0     | (0, t)                | V0       | V2       |

Edge 2 runs against the vertex order (from V0 to V2); `edge_param_from_vertex_order`
converts to "t = 0 at vertex k", which is what crossing into a neighbour needs.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..runtime.kernel_contract import float_inputs
from .geometry import dot


@float_inputs("t", ints=("edge",), bounds={"edge": (-1, 2)})
def edge_barycentric(edge: Int[Array, "*batch"], t: Float[Array, "*batch"]) -> Float[Array, "*batch 2"]:
    """Barycentric `(a, b)` of the point at parameter `t` on edge `edge` (seed 001 eq. 3;
    table above).

    `edge` is 0, 1 or 2, or -1 for no edge (what `mesh.cross_edge` returns on a boundary,
    so its outputs chain: the point of edge 2, finite and meaningless); a concrete other
    value is a `ValueError` (7 had silently given edge 2); inside jit (unchecked) any value
    but 0 and 1 gives edge 2's point. (No clip: the walk's program calls this with valid
    edges, and a clip would only add operations to it.)
    """
    t = jnp.asarray(t)
    edge = jnp.asarray(edge)
    a = jnp.where(edge == 0, t, jnp.where(edge == 1, 1 - t, 0))
    b = jnp.where(edge == 0, 0, jnp.where(edge == 1, t, t))
    return jnp.stack(jnp.broadcast_arrays(a.astype(t.dtype), b.astype(t.dtype)), axis=-1)


def edge_param_from_vertex_order(edge: Int[Array, "*batch"], t: Float[Array, "*batch"]):
    """Map the table's `t` to `s` with `s = 0` at vertex `edge`, `s = 1` at vertex `edge + 1`.

    The project's edge convention (table above; seed 001 fixes none). The map is an
    involution (applying it twice gives `t` back).
    """
    return jnp.where(jnp.asarray(edge) == 2, 1 - t, t)


@float_inputs("V", "ab")
def barycentric_point(V: Float[Array, "*batch 3 3"], ab: Float[Array, "*batch 2"]):
    """World point `V0 + a (V1 - V0) + b (V2 - V0)` (seed 001 eq. 3)."""
    a, b = ab[..., 0:1], ab[..., 1:2]
    return V[..., 0, :] + a * (V[..., 1, :] - V[..., 0, :]) + b * (V[..., 2, :] - V[..., 0, :])


def barycentric_coordinates(E1: Float[Array, "*batch 3"], E2: Float[Array, "*batch 3"],
                            x: Float[Array, "*batch 3"]) -> Float[Array, "*batch 2"]:
    """`(a, b)` with `x = a E1 + b E2` (seed 001 eq. 3 solved for `a, b`, `x = M - V0`),
    least squares (the 2x2 Gram system).

    For `x` in the triangle's plane this is exact; `det G = |E1 x E2|^2` (Lagrange's
    identity) is evaluated from the cross product, without the cancellation of
    `g11 g22 - g12^2` on thin triangles. Returns zeros where the triangle is degenerate.
    """
    g11, g12, g22 = dot(E1, E1), dot(E1, E2), dot(E2, E2)
    r1, r2 = dot(E1, x), dot(E2, x)
    det = dot(jnp.cross(E1, E2), jnp.cross(E1, E2))
    ok = det > 0
    inv = jnp.where(ok, 1 / jnp.where(ok, det, 1), 0)
    return jnp.stack([(g22 * r1 - g12 * r2) * inv, (g11 * r2 - g12 * r1) * inv], -1)


def ray_plane_barycentric(V: Float[Array, "3 3"], P: Float[Array, " 3"], T: Float[Array, " 3"]):
    """Barycentrics of the point where the ray from `P` through `T` meets the plane of
    triangle `V` (seed 001 eq. 3 solved for `a, b`), and whether it meets it ahead of `P`:
    one face of the one-step Newton's re-projection (`solvers.newton`)."""
    E1, E2 = V[1] - V[0], V[2] - V[0]
    n = jnp.cross(E1, E2)
    d = T - P
    denom = dot(n, d)
    ok = denom != 0
    s = jnp.where(ok, dot(n, V[0] - P) / jnp.where(ok, denom, 1), 0)
    return barycentric_coordinates(E1, E2, P + s * d - V[0]), ok & (s > 0)


@float_inputs("N", "ab")
def interpolated_normal(N: Float[Array, "*batch 3 3"], ab: Float[Array, "*batch 2"]):
    """Unnormalised interpolated normal `n~ = n0 + a (n1 - n0) + b (n2 - n0)` (seed 001 eq. 6-8)."""
    return barycentric_point(N, ab)
