"""Objectives whose zeros are refracted paths `P -> M -> L` (seed 001 §3.4.1, math.md §4).

All take the triangle (`V`, `N`: vertex positions and normals, rows), the receiver `P`
(inside the medium), the light `L` (outside), the barycentric point `ab` and
`eta = eta_in / eta_out`, and broadcast over leading batch dimensions.
"""

from __future__ import annotations

import enum
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..runtime.kernel_contract import float_inputs
from .barycentric import barycentric_point, interpolated_normal
from .conic import conic_coefficients, conic_tangent, tangent_to_world
from .geometry import dot, norm, refract, safe_normalize


class ObjectiveStatus(enum.IntEnum):
    """Why an objective value is or is not meaningful at a point."""

    OK = 0
    TOTAL_INTERNAL_REFLECTION = 1  # refract(-w_P, -n_s, eta) is the zero vector
    DEGENERATE = 2  # M coincides with P or L, or the interpolated normal vanishes
    BACKWARD = 3  # the refracted ray points away from L (only `bracket_objective` reports it)


def path_vectors(V, N, P, L, ab):
    """`M`, shading normal `n_s`, `w_P`, `w_L` at `ab` (math.md §1), and a degeneracy flag:
    a zero vector among `n~`, `P - M`, `L - M`, or one whose length overflows the dtype (a
    scene beyond `arguments.scale_range`: float32 `P - M` of 3e19 m normalised to 0 and
    read as a root with status OK)."""
    M = barycentric_point(V, ab)
    n_tilde = interpolated_normal(N, ab)
    PM, LM = P - M, L - M
    lengths = [norm(x) for x in (n_tilde, PM, LM)]
    degenerate = ~functools.reduce(jnp.logical_and, [(d > 0) & jnp.isfinite(d) for d in lengths])
    return M, safe_normalize(n_tilde), safe_normalize(PM), safe_normalize(LM), degenerate


def refracted_direction(V, N, P, L, ab, eta):
    """`refract(-w_P, -n_s, eta)`: where the light arriving at `P` came from, seen at `M`.

    Seed 001 eq. 19 with the GLSL `refract` of math.md §1.
    """
    _, n_s, w_P, _, _ = path_vectors(V, N, P, L, ab)
    return refract(-w_P, -n_s, eta)


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
def signed_sine_and_status(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
    orientation: str = "tangent",
) -> tuple[Float[Array, "*batch"], Int[Array, "*batch"]]:
    """Signed sine `f` (seed 001 eq. 19-21) and an `ObjectiveStatus` per lane.

    `f = s |r x w_L|` with `r = refract(-w_P, -n_s, eta)`. `orientation` picks `s`:

    - `"tangent"` (the paper's eq. 20): `s = sign(t_world . (r x w_L))`, `t_world` the
      conic tangent (eq. 13-15) in world space. Ill-conditioned: `r`, `w_L` and the
      tangent all lie (nearly) in the plane through `P`, `L`, `M`, so `t . (r x w_L)` is
      proportional to how fast that plane turns along the curve; it is exactly 0 on a
      flat surface (constant normals: `tests/test_objectives.py::
      test_tangent_orientation_degenerates_with_constant_normals_while_plane_does_not`
      measures it at rounding level), so its sign is noise there (float32 and float64
      disagree on 49% of curve points; 0.13% at `normal_spread = 1e-3`, docs/conic.md),
      and it flips at `M0` where `M` crosses the line `PL` even though `|r x w_L|` does
      not vanish there (`test_tangent_orientation_flips_at_M0_while_plane_does_not`).
    - `"plane"`: `s = sign((r x w_L) . (PL x n_s))`. On the curve `n_s` lies in the plane
      through `P`, `L`, `M` (that is the coplanarity constraint), so `PL x n_s` is a
      normal of that plane, like `r x w_L`; unlike the conic tangent it is continuous
      along the whole curve (through `M0` too) and far from zero unless the normal is
      parallel to `PL`. `f` then changes sign at its zeros, and spuriously only where
      `n_s` is parallel to `PL` (possible on strongly curved triangles). The solvers
      refine with it.
    - `"line"`: `s = sign((r x w_L) . (PL x PM))`, also a normal of that plane; it
      flips spuriously only where `M` crosses the line `PL` (at `M0`). A true root
      flips both "plane" and "line"; the walk brackets only where both flip.

    Under total internal reflection `r = 0` and the formula gives `f = 0`, which is *not*
    a solution: the status says so, and solvers must read it.
    """
    if orientation not in ("tangent", "plane", "line"):
        raise ValueError(f"orientation must be 'tangent', 'plane' or 'line', got {orientation!r}")
    sine = _sine(V, N, P, L, ab, eta)
    return sine.signed(orientation, V, N, P, L, ab), sine.status


class _Sine(NamedTuple):
    """What every orientation of the signed sine shares (`_sine`), computed once."""

    M: jax.Array
    n_s: jax.Array
    w_L: jax.Array
    r: jax.Array
    c: jax.Array  # r x w_L
    degenerate: jax.Array
    status: jax.Array

    def signed(self, orientation, V, N, P, L, ab):
        """`f = s |r x w_L|` with the sign `s` of `orientation` (`signed_sine_and_status`)."""
        c = self.c
        if orientation == "tangent":
            ref = tangent_to_world(V, conic_tangent(conic_coefficients(V, N, P, L), ab))
            s = jnp.where(dot(ref, c) >= 0, 1, -1).astype(c.dtype)
        elif orientation == "plane":
            s = jnp.where(dot(c, jnp.cross(L - P, self.n_s)) >= 0, 1, -1).astype(c.dtype)
        else:  # "line"
            s = jnp.where(dot(c, jnp.cross(L - P, self.M - P)) >= 0, 1, -1).astype(c.dtype)
        return jnp.where(self.degenerate, 0, s * norm(c))


def _sine(V, N, P, L, ab, eta) -> _Sine:
    """The refracted direction `r`, `r x w_L` (seed 001 eq. 19-20) and the status at `ab`."""
    M, n_s, w_P, w_L, degenerate = path_vectors(V, N, P, L, ab)
    r = refract(-w_P, -n_s, eta)
    c = jnp.cross(r, w_L)
    tir = dot(r, r) == 0
    status = jnp.where(
        degenerate,
        ObjectiveStatus.DEGENERATE,
        jnp.where(tir, ObjectiveStatus.TOTAL_INTERNAL_REFLECTION, ObjectiveStatus.OK),
    ).astype(jnp.int32)
    return _Sine(M, n_s, w_L, r, c, degenerate, status)


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
def signed_sine(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
    orientation: str = "tangent",
) -> Float[Array, "*batch"]:
    """Signed sine `f` of seed 001 eq. 19-21 (see `signed_sine_and_status`).

    `f = 0` exactly on refracted paths, and also (spuriously) under total internal
    reflection; use `signed_sine_and_status` wherever that matters.
    """
    return signed_sine_and_status(V, N, P, L, ab, eta, orientation)[0]


def orthonormal_frame(n: Float[Array, "*batch 3"]):
    """Tangent vectors `(s, t)` with `(s, t, n)` right-handed and orthonormal.

    Branchless construction of Duff et al. 2017 ("Building an orthonormal basis,
    revisited"): continuous except across `n_z = 0`'s sign switch, exact for unit `n`.
    """
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = jnp.where(z >= 0, 1, -1).astype(n.dtype)
    a = -1 / (sign + z)
    b = x * y * a
    s = jnp.stack([1 + sign * x * x * a, sign * b, -sign * x], -1)
    t = jnp.stack([b, sign + y * y * a, -y], -1)
    return s, t


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
def half_vector_residual(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
) -> Float[Array, "*batch 2"]:
    """Tangential part of the generalised half vector in the frame of `n_s` (Walter et al. 2009).

    `h = -(eta_out w_L + eta_in w_P)` normalised (math.md §4, with `eta_out = 1`,
    `eta_in = eta`); a refracted path has `h` parallel to `n_s`, so both components
    vanish. `h` is the zero vector only for `eta = 1` on the straight line `P -> L`.
    """
    return _half_vector(V, N, P, L, ab, eta)[0]


def _half_vector(V, N, P, L, ab, eta):
    """The residual `(h . s, h . t)` of `half_vector_residual` and what its Jacobian reuses:
    `M`, `n_s`, `w_P`, `w_L`, `g = -(w_L + eta w_P)`, `h`, the frame `(s, t)` and `eta`."""
    M, n_s, w_P, w_L, _ = path_vectors(V, N, P, L, ab)
    eta = jnp.asarray(eta, dtype=w_P.dtype)[..., None]
    g = -(w_L + eta * w_P)
    h = safe_normalize(g)
    s, t = orthonormal_frame(n_s)
    return jnp.stack([dot(h, s), dot(h, t)], -1), (M, n_s, w_P, w_L, g, h, s, t, eta)


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
def half_vector_residual_and_jacobian(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
) -> tuple[Float[Array, "*batch 2"], Float[Array, "*batch 2 2"]]:
    """`half_vector_residual` and its Jacobian `d r / d (a, b)` in closed form (math.md §4).

    With `M = V0 + a e1 + b e2` and `n~ = n0 + a (n1 - n0) + b (n2 - n0)`, column `j` (`a`,
    `b`) follows `dM = e_j` and `dn~ = n_j - n0` through

        dw_P = -(I - w_P w_P^T) dM / d_P,   dw_L = -(I - w_L w_L^T) dM / d_L,
        dh   = -(I - h h^T) (dw_L + eta dw_P) / |w_L + eta w_P|,
        dn_s = (I - n_s n_s^T) dn~ / |n~|,

    and the derivative of Duff et al.'s frame (`orthonormal_frame`: with `c = -1 / (sign + z)`,
    `dc = c^2 dz`, `d(xy c) = c (y dx + x dy) + x y c^2 dz`): `dr = (dh . s + h . ds,
    dh . t + h . dt)`. What `jax.jacfwd` of the residual computes, without its second
    pass through every intermediate (the one-step Newton's Jacobian; its test checks it
    against `jacfwd`). Where a length vanishes (`M` on `P` or `L`, `n~ = 0`, `eta = 1` on
    the straight line) its column is 0, as the residual's `safe_normalize` is 0 there.
    """
    r, (M, n_s, w_P, w_L, g, h, s, t, eta) = _half_vector(V, N, P, L, ab, eta)
    dtype = w_P.dtype
    inv = lambda x: jnp.where(x > 0, 1 / jnp.where(x > 0, x, 1), 0)  # noqa: E731
    inv_g, inv_P, inv_L = inv(norm(g)), inv(norm(P - M)), inv(norm(L - M))
    inv_n = inv(norm(interpolated_normal(N, ab)))
    x, y, z = n_s[..., 0], n_s[..., 1], n_s[..., 2]
    sign = jnp.where(z >= 0, 1, -1).astype(dtype)
    c = -1 / (sign + z)
    tangent = lambda v, u: v - dot(u, v)[..., None] * u  # noqa: E731  ((I - u u^T) v)
    columns = []
    for dM, dn in ((V[..., 1, :] - V[..., 0, :], N[..., 1, :] - N[..., 0, :]),
                   (V[..., 2, :] - V[..., 0, :], N[..., 2, :] - N[..., 0, :])):
        dw_P = -tangent(dM, w_P) * inv_P[..., None]
        dw_L = -tangent(dM, w_L) * inv_L[..., None]
        dh = -tangent(dw_L + eta * dw_P, h) * inv_g[..., None]
        dns = tangent(dn, n_s) * inv_n[..., None]
        dx, dy, dz = dns[..., 0], dns[..., 1], dns[..., 2]
        dc = c * c * dz
        db = c * (y * dx + x * dy) + x * y * dc
        ds = jnp.stack([sign * (2 * x * c * dx + x * x * dc), sign * db, -sign * dx], -1)
        dt = jnp.stack([db, 2 * y * c * dy + y * y * dc, -dy], -1)
        columns.append(jnp.stack([dot(dh, s) + dot(h, ds), dot(dh, t) + dot(h, dt)], -1))
    return r, jnp.stack(columns, -1)


def _spherical_angles(d, n_s):
    """(theta, phi) of `d` in the frame of `n_s`, with finite values and gradients everywhere."""
    s, t = orthonormal_frame(n_s)
    x, y, z = dot(d, s), dot(d, t), dot(d, n_s)
    rho = norm(jnp.stack([x, y], -1))
    theta = jnp.arctan2(rho, z)
    pole = rho == 0
    phi = jnp.arctan2(jnp.where(pole, 0, y), jnp.where(pole, 1, x))
    return theta, phi


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
def angle_difference_residual(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
) -> Float[Array, "*batch 2"]:
    """Spherical-angle differences between `refract(-w_P, -n_s, eta)` and `w_L` (Zeltner et al. 2020).

    Angles are taken in the frame of `n_s`; the azimuth difference is wrapped to
    `(-pi, pi]` and weighted by `sin(theta_L)` so that it does not blow up (or jump) at
    the pole. Under total internal reflection the refracted vector is zero and the
    residual is meaningless: check `signed_sine_and_status`.
    """
    _, n_s, w_P, w_L, _ = path_vectors(V, N, P, L, ab)
    r = refract(-w_P, -n_s, eta)
    theta_r, phi_r = _spherical_angles(r, n_s)
    theta_l, phi_l = _spherical_angles(w_L, n_s)
    dphi = jnp.remainder(phi_r - phi_l + jnp.pi, 2 * jnp.pi) - jnp.pi
    return jnp.stack([theta_r - theta_l, jnp.sin(theta_l) * dphi], -1)


def bracket_objective(V, N, P, L, ab, eta):
    """`(f, status, g)` at points `ab` `(k, 2)` of one triangle: what the solvers bracket.

    - `f`: the signed sine (seed 001 eq. 19-21) in the "plane" orientation, continuous
      along the curve (the paper's tangent sign is rounding noise on gentle waves,
      `signed_sine_and_status`).
    - `status`: `ObjectiveStatus`; besides TIR and DEGENERATE it reports `BACKWARD` where
      the refracted ray points away from `L`. `f` is a sine: it also vanishes at an
      angle of pi and changes sign there in every orientation. Such points are no
      solution; a status other than OK keeps them out of every bracket and acceptance.
      Also `BACKWARD` where `P` lies on the outer side of the shading plane at `M`
      (`(P - M) . n_s >= 0`): the ray `M -> P` would leave through the surface, so
      `refract(-w_P, -n_s, eta)` is outside its domain (GLSL's `refract` needs
      `dot(N, I) < 0`) and its zero is no refraction. A receiver above the water had
      been given such a point FOUND by the exhaustive reference and the tracer.
    - `g`: `f` in the "line" orientation. A true root flips both `f` and `g`; an
      orientation flip of one of them flips only that one (`arcs.root_between`).

    Batched with one `vmap` over the points: one call site per solver step keeps the
    compiled program small (XLA compile time grows with every inlined copy).
    """
    def one(x):  # the path vectors and `r` once, both signs from them
        sine = _sine(V, N, P, L, x, eta)
        f, g = sine.signed("plane", V, N, P, L, x), sine.signed("line", V, N, P, L, x)
        outside = jnp.sum((P - sine.M) * sine.n_s) >= 0  # P beyond the tangent plane: no transmission
        backward = (sine.status == ObjectiveStatus.OK) & ((jnp.sum(sine.r * sine.w_L) <= 0) | outside)
        return f, jnp.where(backward, ObjectiveStatus.BACKWARD, sine.status), g

    return jax.vmap(one)(ab)
