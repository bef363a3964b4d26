"""The distance correction factor D of a refracted path by ray differentials (seed 001 eq. 26-33).

`D` (seed 001 eq. 25: contribution `I_e F A rho / D`) is how much a pencil of rays leaving
the receiver `P` spreads by the time it reaches the light `L`: `D = |L'_perp x L'_par|`,
the area that a unit square of directions at `P` (spanned by `w_perp`, `w_par`) covers on
the plane through `L` orthogonal to `w_L`. `ray_differential_D` evaluates the paper's
closed form (math.md §6); `autodiff_D` is the exact reference, the Jacobian determinant of
a ray trace through the flat triangle with interpolated normals, by `jax.jacfwd`.

Both take the triangle (`V`, `N`: vertex positions and unit vertex normals, rows), the
receiver `P`, the light `L`, the barycentric refraction point `ab` and
`eta = eta_in / eta_out`, and broadcast over leading batch dimensions. `ab` should be a
solution (`refract(-w_P, -n_s, eta) = w_L`, e.g. from `solve`); off a solution both
functions still compute their formula, but they no longer describe the same map.

Signs, measured against `autodiff_D` (`tests/transport/test_differentials.py`,
`docs/transport.md`). With eq. 17's `w_P = (P - M)/|P - M|`:

- Eq. 28 as printed, `M' = d_P (w_P' - (w_P'.n_g)/(w_P.n_g) w_P)`, is **minus** the
  derivative of `M` when `w_P` turns by `w_P'`; it is the derivative when the ray
  direction `-w_P` (from `P` towards `M`) turns by `w_P'`.
- Eq. 29-30 differentiate `w_L = -eta w_P + mu n_s` (that is `refract(-w_P, -n_s, eta)`)
  with `w_P'` the turn of `w_P`; the same reading gives eq. 31 with `-eta w_P'`, where the
  extracted text has `+eta`.
- So the extracted eq. 28-31 mix two readings of `w_P'`; negating the `w_P'.n_s` of
  eq. 30 alone, or eq. 28 together with eq. 31's `eta` term, makes them consistent.
  These two readings agree with the exact Jacobian (to 1e-11 relative, float64): the true
  derivative with respect to `w_P`, used here and in math.md §6 (`M' = -d_P (...)`,
  eq. 30 as printed, eq. 31 with `-eta`, `n_s'` from the barycentrics of this `M'`), and
  its global negation (eq. 28 and eq. 31 as extracted, `-w_P'.n_s` in eq. 30), which
  flips `L'` and keeps `D`. Flipping `M'` alone (eq. 28 as printed with `-eta` in
  eq. 31) is wrong even on flat triangles (median relative error 0.7, up to 1e3; at
  `eta = 1` it gives `(d_P - d_L)^2`, as math.md §6 says); so are eq. 28-31 exactly as
  extracted, `+eta` with the true `M'`, a negated `mu'` (0.15 to 0.75).
- The paper leaves `n_s'` implicit: `n_s' = (I - n_s n_s^T) n~' / |n~|` with
  `n~' = (n1 - n0) a' + (n2 - n0) b'`, `(a', b')` the barycentric coordinates of `M'`
  (math.md §6). Dropping it is exact only on flat (constant-normal) triangles (median
  relative error 0.15 with `normal_spread = 0.3`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..math.barycentric import barycentric_coordinates, interpolated_normal
from ..math.geometry import dot, norm, refract, refraction_k, safe_div, safe_normalize
from ..math.objectives import orthonormal_frame, path_vectors
from ..runtime.kernel_contract import float_inputs


def validity_threshold(dtype):
    """Threshold for cosines and sines below which D is reported invalid.

    D's relative rounding error grows like `eps / cos` for each of these cosines (the
    divisions in eq. 28 and eq. 30, the Gram solve of a sliver triangle); below
    `sqrt(eps)` it would exceed `sqrt(eps)` (3e-4 in float32).
    """
    return jnp.sqrt(jnp.finfo(dtype).eps).astype(dtype)


def _direction_frame(w_P):
    """`(w_perp, w_par)`: orthonormal, both orthogonal to `w_P` (seed 001 §3.4.5).

    The paper does not say how to pick them; D is the area of a parallelogram spanned by
    the images of an orthonormal pair, so any rotation or reflection of the pair within
    the plane orthogonal to `w_P` gives the same D. The branchless frame of Duff et al.
    has no degenerate direction (the plane of incidence does, at normal incidence).
    """
    return orthonormal_frame(w_P)


def _triangle_ok(E1, E2, tiny):
    """False for slivers: `|E1 x E2| <= tiny |E1| |E2|` (sine of the angle at V0)."""
    return norm(jnp.cross(E1, E2)) > tiny * norm(E1) * norm(E2)


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
@functools.partial(jax.jit, static_argnames=("normalized",))
def ray_differential_D(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
    normalized: bool = False,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """Distance correction factor `D = |L'_perp x L'_par|` by ray differentials (seed 001 eq. 26-33).

    For each of `w_P' = w_perp, w_par` (unit, orthogonal to `w_P` and to each other):

    - eq. 26-27: `d_P = |P - M|`, `d_L = |L - M|`;
    - eq. 28 (sign corrected, module docstring):
      `M' = -d_P (w_P' - (w_P'.n_g)/(w_P.n_g) w_P)`, `n_g` the geometric normal;
    - `n_s' = (I - n_s n_s^T) ((n1 - n0) a' + (n2 - n0) b') / |n~|`, `(a', b')` the
      barycentric coordinates of `M'` (implicit in the paper; math.md §6);
    - eq. 29: `mu = w_L.n_s + eta w_P.n_s`;
    - eq. 30: `mu' = (eta^2 (w_P.n_s)/(w_L.n_s) + eta) (w_P'.n_s + w_P.n_s')`;
    - eq. 31 (minus sign restored): `w_L' = -eta w_P' + mu' n_s + mu n_s'`;
    - eq. 32: `L' = M' - (M'.w_L) w_L + d_L w_L'`;
    - eq. 33: `D = |L'_perp x L'_par|`.

    `normalized=True` returns `D / d_L^2 = |(L'_perp / d_L) x (L'_par / d_L)|` instead,
    formed from `L' / d_L = (M' - (M'.w_L) w_L) / d_L + w_L'`: dimensionless, and for a
    light at infinity its limit `|w_L'_perp x w_L'_par|` (math.md §9). It stays finite for a
    far light in float32 (a sun 1.5e11 m away: `D` itself, a product of two `d_L`, then
    squared in the norm, overflows); `path_irradiance` uses it.

    Returns `(D, valid)`. `valid` is False, and `D` is 0 (finite, with finite gradients),
    where `M` coincides with `P` or `L` or `n~ = 0`, the triangle is a sliver, `w_P` is
    (nearly) parallel to the triangle, `P` is not behind the shading normal
    (`w_P.n_s >= 0`), the refraction is total internal reflection, or `w_L` does not
    leave on the light side (`w_L.n_s <= sqrt(eps)`); "nearly" means a sine or cosine
    below `sqrt(eps)` of the dtype; also where `D` overflows (not finite, or 0 through an
    overflowed intermediate: a scene beyond `arguments.scale_range`). A concrete `eta <= 0`
    is refused (`ValueError`); a traced one gives invalid lanes.
    """
    M, n_s, w_P, w_L, degenerate = path_vectors(V, N, P, L, ab)
    dtype = M.dtype
    tiny = validity_threshold(dtype)
    eta = jnp.asarray(eta, dtype)
    E1 = V[..., 1, :] - V[..., 0, :]
    E2 = V[..., 2, :] - V[..., 0, :]
    d_P, d_L = norm(P - M), norm(L - M)
    n_g = safe_normalize(jnp.cross(E1, E2))
    n_len = norm(interpolated_normal(N, ab))
    cos_g, cos_P, cos_L = dot(w_P, n_g), dot(w_P, n_s), dot(w_L, n_s)
    k = refraction_k(cos_P, eta)  # negative under TIR
    ok_g, ok_L = jnp.abs(cos_g) > tiny, cos_L > tiny
    # refract(-w_P, -n_s, eta) needs P behind the shading normal (GLSL's dot(N, I) <= 0);
    # with the normal facing the other way GLSL's formula reflects instead (at eta = 1
    # exactly), so such a path is not the refraction that eq. 29-31 differentiate.
    # eta > 0: checked when concrete (float_inputs); a traced eta outside it is an invalid lane.
    valid = ~degenerate & _triangle_ok(E1, E2, tiny) & ok_g & ok_L & (cos_P < 0) & (k > 0) & (eta > 0)

    # Both differentials at once: axis -2 holds (w_perp, w_par); [..., None] broadcasts
    # per-path scalars over it, [..., None, :] per-path vectors.
    W = jnp.stack(_direction_frame(w_P), -2)
    s = lambda x: x[..., None, None]  # noqa: E731
    v = lambda x: x[..., None, :]  # noqa: E731
    M_d = -s(d_P) * (W - s(safe_div(1, cos_g, ok_g)) * dot(W, v(n_g))[..., None] * v(w_P))
    ab_d = barycentric_coordinates(v(E1), v(E2), M_d)
    n_tilde_d = ab_d[..., :1] * v(N[..., 1, :] - N[..., 0, :]) + ab_d[..., 1:] * v(N[..., 2, :] - N[..., 0, :])
    n_s_d = (n_tilde_d - dot(v(n_s), n_tilde_d)[..., None] * v(n_s)) * s(safe_div(1, n_len, n_len > 0))
    mu = cos_L + eta * cos_P
    mu_d = (eta**2 * cos_P * safe_div(1, cos_L, ok_L) + eta)[..., None] * (dot(W, v(n_s)) + dot(v(w_P), n_s_d))
    w_L_d = -eta[..., None, None] * W + mu_d[..., None] * v(n_s) + s(mu) * n_s_d
    if normalized:  # L' / d_L (eq. 32 divided by d_L; math.md §9)
        L_d = (M_d - dot(M_d, v(w_L))[..., None] * v(w_L)) * s(safe_div(1, d_L, d_L > 0)) + w_L_d
    else:
        L_d = M_d - dot(M_d, v(w_L))[..., None] * v(w_L) + s(d_L) * w_L_d
    D = norm(jnp.cross(L_d[..., 0, :], L_d[..., 1, :]))
    # A scene beyond the dtype's range (`arguments.scale_range`; float32 lengths near 1e9:
    # D grows as a product of four lengths) overflows to inf, or to 0 through an overflowed
    # barycentric solve: neither is a valid D (docs/input_contract.md "Scale").
    valid = valid & jnp.isfinite(D) & (D > 0)
    return jnp.where(valid, D, 0), valid


def _trace_to_light_plane(s, V, N, P, L, ab, eta):
    """Exact trace for one path: direction leaving `P` -> point on the plane at `L`, `w_L`-orthogonal.

    `s = (s_perp, s_par)` tilts the ray direction `-w_P` to `normalize(-w_P + s_perp w_perp
    + s_par w_par)`; the ray hits the triangle's plane (barycentrics extrapolated past the
    edges, so the map is smooth), takes the normalised interpolated normal there, refracts
    with GLSL `refract`, and runs to the plane through `L` orthogonal to the unperturbed
    `w_L`. Returns the hit's coordinates in an orthonormal basis of that plane.
    """
    _, _, w_P, w_L, _ = path_vectors(V, N, P, L, ab)
    w_perp, w_par = _direction_frame(w_P)
    d = safe_normalize(-w_P + s[0] * w_perp + s[1] * w_par)
    E1, E2 = V[1] - V[0], V[2] - V[0]
    n_g = jnp.cross(E1, E2)
    d_dot_n = dot(d, n_g)
    X = P + safe_div(dot(V[0] - P, n_g), d_dot_n, d_dot_n != 0) * d
    n_s = safe_normalize(interpolated_normal(N, barycentric_coordinates(E1, E2, X - V[0])))
    r = refract(d, -n_s, eta)
    r_dot_w = dot(r, w_L)
    Y = X + safe_div(dot(L - X, w_L), r_dot_w, r_dot_w != 0) * r
    e1, e2 = orthonormal_frame(w_L)
    return jnp.stack([dot(Y - L, e1), dot(Y - L, e2)])


def _autodiff_D_one(V, N, P, L, ab, eta):
    J = jax.jacfwd(_trace_to_light_plane)(jnp.zeros(2, P.dtype), V, N, P, L, ab, eta)
    return jnp.abs(J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0])


_autodiff_D_vectorized = jnp.vectorize(_autodiff_D_one, signature="(3,3),(3,3),(3),(3),(2),()->()")


@float_inputs("V", "N", "P", "L", "ab", params=("eta",), positive=("eta",))
@jax.jit
def autodiff_D(
    V: Float[Array, "*batch 3 3"],
    N: Float[Array, "*batch 3 3"],
    P: Float[Array, "*batch 3"],
    L: Float[Array, "*batch 3"],
    ab: Float[Array, "*batch 2"],
    eta,
) -> Float[Array, "*batch"]:
    """Exact `D` (the reference for seed 001 eq. 33): `|det|` of a Jacobian by `jax.jacfwd`.

    The map is `(s_perp, s_par) -> ` the point where the ray leaving `P` in direction
    `normalize(-w_P + s_perp w_perp + s_par w_par)`, refracted at the triangle's plane by
    the interpolated normal, meets the plane through `L` orthogonal to `w_L`, in an
    orthonormal basis of that plane; `w_perp, w_par` are those of `ray_differential_D`.
    At a solution `ab` this equals `ray_differential_D` (math.md §6 **verify**). Finite
    for finite input; meaningless where `ray_differential_D` reports `valid = False`.
    """
    eta = jnp.asarray(eta, jnp.asarray(P).dtype)
    return _autodiff_D_vectorized(V, N, P, L, ab, eta)
