"""Photon differentials: compression ratios, footprints and irradiance (seed 004 §3.2, seed 003).

A photon leaves the light `L` through a texel of the light-view parametrisation (the
emission plane of `photons.py`, the caustic map of seed 004 §3.1), refracts at the
surface and lands on a receiver. Three estimates of how much its beam is compressed:

- `compression_ratio` (seed 004 eq. 10-11, Alg. 2): the neighbours `x10, x01` of the
  surface point `x00` (adjacent texels) span a surface triangle of area `A`; the three
  refracted (or reflected) rays, each advanced by the **same** distance `t'` (the centre
  ray's hit distance), span a caustic triangle of area `A'`; `sigma = sqrt(A'/A) s^c`.
  Alg. 2 uses one light direction `LDir` for all three rays (exact for a directional
  light); `l_dir10`, `l_dir01` let a point light give each its own.
- `compression_ratio_exact`: the same three rays, each intersected with the receiver
  plane: `A'_rec / A`. Same-`t'` puts the caustic triangle roughly orthogonal to the
  beam instead of on the receiver; seed 004 puts that back with the foreshortening
  `a = 1/(-l_dir.n')` of eq. 19, so `sigma^2 a` estimates `A'_rec / A`.
- `texel_jacobian` / `photon_differential_irradiance`: the exact differential, the 2x2
  Jacobian by `jax.jacfwd` of "emission-plane point -> receiver-plane point" through the
  surface triangle (barycentrics extrapolated, interpolated normal, GLSL `refract`).
  A photon of flux `Phi = I_e |cos_e| du dv / r_e^2` lands on `|det J| du dv`, so the
  irradiance where it lands is `E = I_e T |cos_e| / (r_e^2 |det J|)` (times attenuation).
  Where one path reaches the receiver point this must equal the walk's
  `path_irradiance` (seed 001 eq. 25-33): the check that ties seeds 001 and 004 together.

`footprint_ellipse` gives the anisotropic elliptical footprint of seed 003 from the ray
differentials; `splat_footprints` accumulates photons as flux-conserving anisotropic
Gaussians on a `ReceiverGrid`. Sprite size and intensity (seed 004 eq. 16-20) are
`caustics_jax.kernels.sprite_size` and friends.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ..math.barycentric import barycentric_coordinates, interpolated_normal
from ..math.geometry import (
    beer_lambert,
    dot,
    norm,
    reflect,
    refract,
    refraction_k,
    safe_div,
    safe_normalize,
    safe_sqrt,
    unit_vector,
)
from ..math.objectives import orthonormal_frame
from ..runtime.arguments import check_int, check_points, check_real, real_array
from ..runtime.kernel_contract import float_inputs, in_domain
from ..surface.mesh import SurfaceMesh
from .differentials import validity_threshold
from .photons import EmissionPlane, ReceiverGrid, refract_into_medium, surface_hits

MODES = ("refract", "reflect")


@float_inputs("x0", "x1", "x2")
def triangle_area(x0: Float[Array, "*batch 3"], x1: Float[Array, "*batch 3"],
                  x2: Float[Array, "*batch 3"]) -> Float[Array, "*batch"]:
    """`|(x1 - x0) x (x2 - x0)| / 2` (Alg. 2's `TriArea`)."""
    return _edge_area(x1 - x0, x2 - x0)


def _edge_area(e1, e2):
    """Alg. 2's `TriArea` of the triangle spanned by the edges `e1, e2`."""
    return norm(jnp.cross(e1, e2)) / 2


# Alg. 2 takes unit normals and light directions: a unit vector rounded to float32 (also when
# cast to float64) has `|v.v - 1|` of about 3 eps32; a vector farther from unit length is not one.
_UNIT_SLACK = 16 * float(np.finfo(np.float32).eps)


def _unit_directions(*vectors):
    """Where every vector (Alg. 2's normals and light directions) is a unit vector to
    `_UNIT_SLACK`: finite, not zero and not of another length (zero normals had given
    `sigma = 1` valid). They are used as given, so values and derivatives are the formula's:
    normalising them here would move float32-rounded inputs by their own rounding, each
    independently of its neighbour, which on small texels swamps the neighbours'
    difference (docs/irradiance.md, "Measurements behind the code"), and would change the
    derivatives along the vectors."""
    ok = True
    for v in vectors:
        ok = ok & (jnp.abs(dot(v, v) - 1) <= _UNIT_SLACK)  # NaN and inf compare False
    return ok


def _scatter_pair(l0, n0, l1, n1, eta, mode):
    """`(w0, w1 - w0, ok)`: Alg. 2 lines 1-2 (`normalize(reflect(LDir, n))` or
    `normalize(refract(LDir, n, 1/eta))`) for a ray and its neighbour, the difference
    expanded in `l1 - l0` and `n1 - n0`.

    Neighbouring rays differ by about a texel over the distance it is seen from; taken as
    the difference of two unit vectors, `w1 - w0` keeps only `eps / |w1 - w0|` of its
    digits (float32, 0.1 mm texels: 1e-3, docs/irradiance.md). Expanded, every term is of
    the size of the difference. `ok` is False where either ray is totally internally
    reflected (GLSL `refract` returns 0), has no direction, does not arrive from the side
    its normal faces (`l.n >= 0`: a zero normal or an upward `l_dir` had given `sigma = 1`
    valid), or `eta` is not finite and `> 0`.
    """
    dl, dn = l1 - l0, n1 - n0
    c0, c1 = dot(n0, l0), dot(n1, l1)
    arrives = (c0 < 0) & (c1 < 0)
    dc = dot(dn, l1) + dot(n0, dl)  # c1 - c0
    if mode == "reflect":
        # GLSL reflect, r = I - 2 (N.I) N: r1 - r0 = dl - 2 (c1 dn + dc n0)
        r0, r1 = reflect(l0, n0), reflect(l1, n1)
        dr = dl - 2 * (c1[..., None] * dn + dc[..., None] * n0)
        ok = arrives
    else:
        # GLSL refract (math.md §1) with e = 1/eta: r = e I - (e c + s) N, s = sqrt(k),
        # k = refraction_k(c, e); so r1 - r0 = e dl - (e c1 + s1) dn - (e dc + ds) n0 with
        # ds = (k1 - k0) / (s1 + s0) and k1 - k0 = e^2 dc (c0 + c1).
        eta = jnp.asarray(eta, l0.dtype)
        ok_eta = in_domain(eta, lo=0, strict=True)
        e = safe_div(1, eta, ok_eta)
        r0, r1 = refract(l0, n0, e), refract(l1, n1, e)
        k0, k1 = refraction_k(c0, e), refraction_k(c1, e)
        ok = arrives & ok_eta & (k0 >= 0) & (k1 >= 0)  # k < 0: total internal reflection, no ray
        s0, s1 = safe_sqrt(k0), safe_sqrt(k1)
        ds = safe_div(e * e * dc * (c0 + c1), s0 + s1, s0 + s1 > 0)
        dr = e[..., None] * dl - (e * c1 + s1)[..., None] * dn - (e * dc + ds)[..., None] * n0
    # normalize: w1 - w0 = dr / m1 - r0 (m1 - m0) / (m0 m1), m1 - m0 = dr.(r0 + r1) / (m0 + m1)
    m0, m1 = norm(r0), norm(r1)
    ok = ok & (m0 > 0) & (m1 > 0)
    inv0, inv1 = safe_div(1, m0, m0 > 0), safe_div(1, m1, m1 > 0)
    dm = safe_div(dot(dr, r0 + r1), m0 + m1, ok)
    dw = dr * inv1[..., None] - r0 * (dm * inv0 * inv1)[..., None]
    return r0 * inv0[..., None], dw, ok


def _check_mode(mode):
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")


@functools.partial(jax.jit, static_argnames=("mode",))
def _compression_ratio(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01, t_hit, eta, scale,
                       level, mode):
    # Alg. 2 lines 3-6 on the caustic triangle's edges, hit_i - hit_00 = (x_i - x00) +
    # t' (w_i - w00), not on the hits x + t' w: float32 loses eps |x| / texel in the absolute
    # hits (8e-3 relative at 100 m from the origin with 1 mm texels; docs/irradiance.md).
    ok = _unit_directions(n00, n10, n01, l_dir, l_dir10, l_dir01)
    _, dw10, ok10 = _scatter_pair(l_dir, n00, l_dir10, n10, eta, mode)
    _, dw01, ok01 = _scatter_pair(l_dir, n00, l_dir01, n01, eta, mode)
    dx10, dx01 = x10 - x00, x01 - x00
    # t' <= 0: the receiver is behind the surface, which compression_ratio_exact rejects too;
    # t' = inf had given sigma 0 valid. Traced scale and level outside their domain: invalid.
    ok = ok & ok10 & ok01 & in_domain(t_hit, lo=0, strict=True)
    ok = ok & in_domain(scale, lo=1) & in_domain(level, lo=0, whole=True)
    t = t_hit[..., None]
    A = _edge_area(dx10, dx01)
    A_d = _edge_area(dx10 + t * dw10, dx01 + t * dw01)
    ok = ok & (A > 0)
    ratio = safe_div(A_d, A, ok)
    ok = ok & jnp.isfinite(ratio)  # areas overflow beyond arguments.scale_range (float32 1e10 m): invalid
    sigma = safe_sqrt(jnp.where(ok, ratio, 0)) * jnp.asarray(scale, A.dtype) ** level  # (invalid: masked below)
    ok = ok & jnp.isfinite(sigma)
    return jnp.where(ok, sigma, 0), ok


@float_inputs("x00", "x10", "x01", "n00", "n10", "n01", "l_dir", "t_hit", "l_dir10", "l_dir01",
               params=("eta", "scale", "level"), positive=("eta",), nonnegative=("level",), whole=("level",),
               bounds={"scale": (1, None)})
def compression_ratio(
    x00: Float[Array, "*batch 3"], x10: Float[Array, "*batch 3"], x01: Float[Array, "*batch 3"],
    n00: Float[Array, "*batch 3"], n10: Float[Array, "*batch 3"], n01: Float[Array, "*batch 3"],
    l_dir: Float[Array, "*batch 3"], t_hit: Float[Array, "*batch"], *, eta=1.333,
    scale=1.0, level=0, mode: str = "refract", l_dir10=None, l_dir01=None,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """Kernel scale `sigma = sqrt(A'/A) s^c` by the same-`t'` shortcut (seed 004 eq. 10-11, Alg. 2).

    `x00, x10, x01` surface points of adjacent texels (eq. 10), `n..` their unit normals
    (outward, toward the light), `l_dir` the unit light direction (from the light,
    `l_dir.n < 0`), used as given (unit to `16 eps` of float32, else the lane is invalid),
    `t_hit` the centre ray's hit distance `t'`, `scale`/`level` the cascade `s >= 1` and
    `c`, a whole number `>= 0` (seed 004 eq. 11; `cascade_intensity_scale`).
    `mode="refract"` (into the medium, index ratio `1/eta`) or `"reflect"` (Alg. 2 as
    printed). Returns `(sigma, valid)`, `valid` False (and `sigma = 0`) for a degenerate
    surface triangle, a normal or light direction that is not a unit vector (zero, not
    finite, or of another length), light arriving from
    behind a normal (`l_dir.n >= 0`), a ray totally internally reflected (as
    `compression_ratio_exact`), `t_hit` not finite and `> 0`, and (traced; concrete ones
    are a `ValueError`) `eta`, `scale` or `level` outside their domain.

    The caustic triangle is formed from differences (`x10 - x00`, and `w10 - w00` expanded
    in `n10 - n00`, `l_dir10 - l_dir`), so the float32 error scales with the texel, not
    with the distance from the origin (docs/irradiance.md, "float32").
    """
    _check_mode(mode)
    l_dir = jnp.asarray(l_dir)
    l_dir10 = l_dir if l_dir10 is None else jnp.asarray(l_dir10, l_dir.dtype)
    l_dir01 = l_dir if l_dir01 is None else jnp.asarray(l_dir01, l_dir.dtype)
    return _compression_ratio(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01,
                              jnp.asarray(t_hit, l_dir.dtype), eta, scale, level, mode)


def _plane_distance(x_rel, w, normal):
    """`(t, ok)`: the ray `x + t w` meets the plane `(point, normal)` at `t`, given
    `x_rel = x - point` (a difference, so that no absolute point enters); `ok` False where
    the ray is parallel to the plane (`t = 0` there)."""
    den = dot(w, normal)
    ok = jnp.abs(den) > 0
    return safe_div(-dot(x_rel, normal), den, ok), ok


@functools.partial(jax.jit, static_argnames=("mode",))
def _compression_ratio_exact(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01, point, normal,
                             eta, mode):
    # As _compression_ratio, on the receiver triangle's edges: with y_i = x_i + t_i w_i on
    # the plane, y_i - y00 = (x_i - x00) + t_i (w_i - w00) + (t_i - t00) w00 and
    # t_i - t00 = -((x_i - x00).n + t00 (w_i - w00).n) / (w_i.n).
    ok = _unit_directions(n00, n10, n01, l_dir, l_dir10, l_dir01)
    normal, ok_normal = unit_vector(normal)
    w00, dw10, ok10 = _scatter_pair(l_dir, n00, l_dir10, n10, eta, mode)
    _, dw01, ok01 = _scatter_pair(l_dir, n00, l_dir01, n01, eta, mode)
    t00, hit = _plane_distance(x00 - point, w00, normal)
    ok = ok & ok_normal & ok10 & ok01 & hit & (t00 > 0)
    edges = []
    for dx, dw in ((x10 - x00, dw10), (x01 - x00, dw01)):
        den = dot(w00 + dw, normal)
        hit = jnp.abs(den) > 0
        dt = safe_div(-(dot(dx, normal) + t00 * dot(dw, normal)), den, hit)
        ok = ok & hit & (t00 + dt > 0)  # each ray meets the plane in front of the surface
        edges.append(dx + (t00 + dt)[..., None] * dw + dt[..., None] * w00)
    A = triangle_area(x00, x10, x01)
    ok = ok & (A > 0)
    ratio = safe_div(_edge_area(*edges), A, ok)
    ok = ok & jnp.isfinite(ratio)  # as in _compression_ratio
    return jnp.where(ok, ratio, 0), ok


@float_inputs("x00", "x10", "x01", "n00", "n10", "n01", "l_dir", "receiver_point",
               "receiver_normal", "l_dir10", "l_dir01", params=("eta",), positive=("eta",))
def compression_ratio_exact(
    x00, x10, x01, n00, n10, n01, l_dir, receiver_point, receiver_normal, *, eta=1.333,
    mode: str = "refract", l_dir10=None, l_dir01=None,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """`A'_rec / A`: the three rays of Alg. 2 each intersected with the receiver plane.

    The reference for `compression_ratio`'s same-`t'` shortcut (math.md §7): no shared
    `t'`, the caustic triangle lies on the receiver. Arguments as `compression_ratio`,
    plus the receiver plane `(receiver_point, receiver_normal)` (normalised here, any
    finite length). Returns `(ratio, valid)`; `valid` False where a ray misses the plane
    (parallel or behind), is totally internally reflected, the surface triangle is
    degenerate, a normal or light direction is not a unit vector or the receiver normal is
    zero or not finite, light arrives from behind a normal, or (traced) `eta` is not finite
    and `> 0`. The receiver triangle is formed from differences, as in `compression_ratio`.
    """
    _check_mode(mode)
    l_dir = jnp.asarray(l_dir)
    l_dir10 = l_dir if l_dir10 is None else jnp.asarray(l_dir10, l_dir.dtype)
    l_dir01 = l_dir if l_dir01 is None else jnp.asarray(l_dir01, l_dir.dtype)
    point = jnp.asarray(receiver_point, l_dir.dtype)
    normal = jnp.asarray(receiver_normal, l_dir.dtype)
    return _compression_ratio_exact(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01,
                                    point, normal, eta, mode)


# --------------------------------------------------------------------------- exact differential


def _texel_trace(uv, V, N, L, X, eta, point, normal):
    """Emission-plane offset `uv` -> `(receiver coords (2,), T, cos_e, r_e, t, ok)` for one photon.

    The ray from `L` through `X + (u, v, 0)` meets the triangle's plane (barycentrics
    extrapolated past the edges, so the map is smooth), refracts there at the normalised
    interpolated normal, and runs to the receiver plane. Points are carried relative to
    `X`, `V0` and the receiver point, never as absolute coordinates (float32 would lose
    `eps |x|` of the barycentrics and the landing point far from the origin).
    """
    duv = jnp.concatenate([uv, jnp.zeros(1, uv.dtype)])
    d_raw = (X - L) + duv
    r_e = norm(d_raw)
    ok_e = r_e > 0  # X == L: the photon has no direction
    d = d_raw * safe_div(1, r_e, ok_e)
    E1, E2 = V[1] - V[0], V[2] - V[0]
    XV = (X - V[0]) + duv
    t_x, ok_s = _plane_distance(XV, d, jnp.cross(E1, E2))
    ok_s = ok_s & (t_x + r_e > 0)  # in front of L
    MV = XV + t_x * d  # M - V0
    n_s = safe_normalize(interpolated_normal(N, barycentric_coordinates(E1, E2, MV)))
    ok_eta = in_domain(eta, lo=0, strict=True)  # traced; concrete ones are refused
    r, T, ok_n = refract_into_medium(d, n_s, jnp.where(ok_eta, eta, 1))
    MP = MV + (V[0] - point)  # M - point
    t, ok_r = _plane_distance(MP, r, normal)
    YP = MP + t * r  # Y - point
    e1, e2 = orthonormal_frame(normal)
    coords = jnp.stack([dot(YP, e1), dot(YP, e2)])
    return coords, (point + YP, T, -d[2], r_e, t, ok_e & ok_s & ok_eta & ok_n & ok_r & (t > 0))


def _texel_one(V, N, L, X, eta, point, normal):
    J, aux = jax.jacfwd(_texel_trace, has_aux=True)(jnp.zeros(2, X.dtype), V, N, L, X, eta, point, normal)
    return (J, *aux)


_texel_vectorized = jnp.vectorize(
    _texel_one, signature="(3,3),(3,3),(3),(3),(),(3),(3)->(2,2),(3),(),(),(),(),()")


@float_inputs("V", "N", "L", "X", "receiver_point", "receiver_normal", params=("eta",), positive=("eta",))
@jax.jit
def texel_jacobian(
    V: Float[Array, "*batch 3 3"], N: Float[Array, "*batch 3 3"], L: Float[Array, "*batch 3"],
    X: Float[Array, "*batch 3"], eta, receiver_point: Float[Array, "*batch 3"],
    receiver_normal: Float[Array, "*batch 3"],
):
    """Exact photon differential: `J = d(receiver coords)/d(emission-plane xy)` by `jax.jacfwd`.

    The Jacobian of seed 003's footprint and the exact reference for seed 004 eq. 10-11
    (math.md §7).

    `V, N` the surface triangle the photon through emission point `X` hits (from the
    light `L`); the receiver plane `(receiver_point, receiver_normal)`, coordinates in
    `orthonormal_frame(receiver_normal)`. Returns `(J (2,2), Y (3,), T, cos_e, r_e, t,
    valid)`: the landing point, Fresnel transmittance, cosine of the photon direction
    with the emission-plane normal (+z), light-to-`X` distance, path length in the medium.
    `valid` is False (the other outputs finite, with finite gradients, but meaningless)
    where `X = L`, the ray misses the triangle's plane (parallel, or behind `L`), meets
    the shading normal from below, is totally internally reflected, misses the receiver
    (parallel or behind), `eta` is not finite and `> 0`, or `receiver_normal` (normalised
    here, any finite length) is zero or not finite.
    """
    dtype = jnp.asarray(X).dtype
    normal, ok_normal = unit_vector(jnp.asarray(receiver_normal, dtype))
    *out, ok = _texel_vectorized(V, N, L, X, jnp.asarray(eta, dtype), jnp.asarray(receiver_point, dtype),
                                 normal)
    return (*out, ok & ok_normal)


@float_inputs("V", "N", "L", "X", "receiver_point", "receiver_normal",
               params=("eta", "intensity", "sigma_t"), positive=("eta",),
               nonnegative=("intensity", "sigma_t"))
@jax.jit
def photon_differential_irradiance(V, N, L, X, eta, intensity, receiver_point, receiver_normal,
                                   sigma_t=0.0):
    """Irradiance where the photon through `X` lands: `I_e T A |cos_e| / (r_e^2 |det J|)`.

    math.md §7's flux bookkeeping, `Phi / A'`, with the exact landing area.

    Flux `I_e |cos_e| du dv / r_e^2` through the emission texel `du dv` (photons.py), times
    `T` and `A = exp(-sigma_t t)`, over its landing area `|det J| du dv` (`texel_jacobian`).
    Returns `(E, Y, valid)`: `E = 0` where `texel_jacobian` is invalid or `|det J|` is
    below `sqrt(eps)` of its scale (on a caustic, where the irradiance of a single photon
    tube is unbounded). `|cos_e|`: a photon crossing the emission plane upward (a light
    below it) carries positive flux too.
    """
    J, Y, T, cos_e, r_e, t, ok = texel_jacobian(V, N, L, X, eta, receiver_point, receiver_normal)
    det = jnp.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    scale = jnp.sum(J**2, axis=(-2, -1))
    dtype = det.dtype
    # intensity and sigma_t are checked when concrete (float_inputs); traced, a lane outside
    # their domain (negative, NaN or inf: intensity = inf had given E = inf valid) is invalid.
    intensity, sigma_t = jnp.asarray(intensity, dtype), jnp.asarray(sigma_t, dtype)
    ok = ok & (det > validity_threshold(dtype) * scale) & in_domain(intensity, lo=0) & in_domain(sigma_t, lo=0)
    E = (jnp.where(ok, intensity, 0) * T * beer_lambert(jnp.where(ok, sigma_t, 0), t) * jnp.abs(cos_e)
         * safe_div(1, r_e**2 * det, ok))
    return jnp.where(ok, E, 0), Y, ok


# --------------------------------------------------------------------------- footprints


@float_inputs("dY_du", "dY_dv")
def footprint_ellipse(dY_du: Float[Array, "*batch 2"], dY_dv: Float[Array, "*batch 2"]):
    """Elliptical footprint of a photon differential (seed 003): semi-axes, axis directions, area.

    The ray differentials `dY/du du`, `dY/dv dv` (receiver-plane vectors) are conjugate
    semi-diameters of the ellipse, the image of the unit circle of texel offsets under
    `J = [dY_du | dY_dv]`: its semi-axes are the singular values `s1 >= s2` of `J`, along
    the left singular vectors, and its area `pi s1 s2 = pi |det J|`. Returns
    `(axes (*batch, 2), directions (*batch, 2, 2) as rows, area)`.

    `s1` from the eigenvalues of `J J^T`, `s2 = |det J| / s1` (the difference
    `half_trace - root` would cancel: float32 lost the minor axis from aspect 1e4); the
    error is a few `eps s1`, the conditioning of a singular value (docs/irradiance.md).
    At a circle (`s1 = s2`) the semi-axes are not differentiable: both get the gradient of
    the mean of the one-sided derivatives (that of `sqrt((s1^2 + s2^2) / 2)`, `J/2` at
    `J = I`) and the directions, arbitrary there, are the x and y axes with zero gradient;
    at a singular `J` the gradient of `s2` is 0 (`d|det|` at 0). Values and gradients are
    finite for finite `J` (`J` is scaled by its largest entry first, so its squares do not
    overflow); the area overflows where `pi s1 s2` exceeds the dtype's range.
    """
    J = jnp.stack([dY_du, dY_dv], -1)
    # scale-free: m s(J / m) with m held constant has the gradient of s(J) (s is homogeneous)
    m = jax.lax.stop_gradient(jnp.max(jnp.abs(J), axis=(-2, -1)))
    Js = safe_div(J, m[..., None, None], (m > 0)[..., None, None])
    # Symmetric 2x2 eigenproblem of J J^T in closed form (no LAPACK call, works in float32).
    a, b, c = (Js[..., 0, 0] ** 2 + Js[..., 0, 1] ** 2,
               Js[..., 0, 0] * Js[..., 1, 0] + Js[..., 0, 1] * Js[..., 1, 1],
               Js[..., 1, 0] ** 2 + Js[..., 1, 1] ** 2)
    half_trace, diff = (a + c) / 2, (a - c) / 2
    q = diff**2 + b**2
    round_ = q > 0  # False at a circle: double eigenvalue, sqrt and arctan2 have no derivative
    root = safe_sqrt(q)
    s1 = safe_sqrt(half_trace + root)
    det = jnp.abs(Js[..., 0, 0] * Js[..., 1, 1] - Js[..., 0, 1] * Js[..., 1, 0])
    s2 = jnp.minimum(safe_div(det, s1, s1 > 0), s1)
    theta = 0.5 * jnp.where(round_, jnp.arctan2(jnp.where(round_, 2 * b, 0), jnp.where(round_, a - c, 1)), 0)
    u1 = jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    u2 = jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    axes = jnp.stack([s1, s2], -1) * m[..., None]
    return axes, jnp.stack([u1, u2], -2), jnp.pi * (s1 * m) * (s2 * m)


@functools.partial(jax.jit, static_argnames=("window", "nx", "ny"))
def _splat(xy, flux, cov, origin, cell, window, nx, ny):
    ij = jnp.floor((xy - origin) / cell).astype(jnp.int32)
    offs = jnp.arange(-window, window + 1)
    oi, oj = jnp.meshgrid(offs, offs, indexing="xy")
    ci = ij[:, None, 0] + oi.reshape(-1)[None]
    cj = ij[:, None, 1] + oj.reshape(-1)[None]
    centre = origin + (jnp.stack([ci, cj], -1) + 0.5) * cell
    r = centre - xy[:, None]
    inv = jnp.linalg.inv(cov)
    q = jnp.einsum("nki,nij,nkj->nk", r, inv, r)
    w = jnp.exp(-0.5 * q)
    inside = (ci >= 0) & (ci < nx) & (cj >= 0) & (cj < ny)
    # Normalised over the whole window (cells off the grid included): flux conserving.
    w = w / jnp.maximum(jnp.sum(w, -1, keepdims=True), jnp.finfo(w.dtype).tiny)
    idx = jnp.where(inside, cj * nx + ci, nx * ny)
    out = jnp.zeros(nx * ny + 1, flux.dtype).at[idx.reshape(-1)].add((w * flux[:, None]).reshape(-1))
    return out[:-1].reshape(ny, nx)


#: Largest `window` of `splat_footprints`: each photon touches `(2 window + 1)^2` cells.
MAX_SPLAT_WINDOW = 64
#: Largest `res` of `light_view_texels` (`res^2` photons: 2^28 at the bound).
MAX_TEXELS = 1 << 14


def splat_footprints(xy, flux, J, du: float, dv: float, receiver: ReceiverGrid, *,
                     kappa: float = 0.7, window: int = 6) -> np.ndarray:
    """Irradiance map from photons splatted as anisotropic Gaussians (seed 003 footprints).

    Photon `i` at `xy[i]` (receiver-plane x, y) with flux `flux[i]` and texel Jacobian
    `J[i]` spreads its flux as a Gaussian of covariance
    `kappa^2 (J D)(J D)^T + (cell^2/12) I`, `D = diag(du, dv)`, over a
    `(2 window + 1)^2` block of cells, normalised so that it deposits exactly its flux
    (flux leaving the grid is lost, as it should be). `kappa = 0.7` texel keeps the sum of
    kernels on a regular texel lattice flat to ~1e-4 (Poisson summation:
    `2 exp(-2 pi^2 kappa^2)`; docs/irradiance.md, "Measurements behind the code"); the
    cell term keeps a footprint smaller than a cell from aliasing. A
    footprint wider than about `window / 3` cells is truncated (still flux conserving,
    but blurred less than asked). The receiver plane must be horizontal (`J` in x, y).
    Returns `(ny, nx)` irradiance (W/m^2).
    """
    receiver = ReceiverGrid.check(receiver)
    kappa = check_real("kappa", kappa, 0, lo_open=True)
    window = check_int("window", window, 0, MAX_SPLAT_WINDOW)
    du, dv = check_real("du", du, 0, lo_open=True), check_real("dv", dv, 0, lo_open=True)
    xy_np, flux_np, J_np = real_array("xy", xy), real_array("flux", flux), real_array("J", J)
    n = xy_np.shape[0] if xy_np.ndim == 2 else -1
    if xy_np.shape != (n, 2) or flux_np.shape != (n,) or J_np.shape != (n, 2, 2):
        raise ValueError(f"xy, flux and J must have shapes (N, 2), (N,) and (N, 2, 2), got {xy_np.shape}, "
                         f"{flux_np.shape} and {J_np.shape}")
    for name, a in (("xy", xy_np), ("flux", flux_np), ("J", J_np)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite (pass the valid photons only)")
    if np.any(flux_np < 0):
        raise ValueError("flux must be >= 0")
    xy = jnp.asarray(xy)
    dtype = xy.dtype if jnp.issubdtype(xy.dtype, jnp.floating) else jnp.result_type(float)
    xy = xy.astype(dtype)
    JD = jnp.asarray(J, dtype) * jnp.asarray([du, dv], dtype)[None, None, :]
    cell = jnp.asarray([receiver.dx, receiver.dy], dtype)
    cov = kappa**2 * JD @ jnp.swapaxes(JD, -1, -2) + jnp.diag(cell**2 / 12)
    out = _splat(xy, jnp.asarray(flux, dtype), cov, jnp.asarray([receiver.x0, receiver.y0], dtype), cell,
                 window, receiver.nx, receiver.ny)
    return np.asarray(out, np.float64) / receiver.cell_area


class LightViewTexels(NamedTuple):
    """A regular `res x res` grid of photons through the emission plane (a caustic map, seed 004 §3.1).

    Attributes: `X (res, res, 3)` emission-plane points (texel centres, row `j` along y),
    `face (res, res)`, `ab (res, res, 2)`, `found (res, res)`: the surface hit of the ray
    from `L` through `X`; `du, dv` texel sizes; `plane` the `EmissionPlane`.
    """

    X: Array
    face: Array
    ab: Array
    found: Array
    du: float
    dv: float
    plane: EmissionPlane


def light_view_texels(mesh: SurfaceMesh, L, res: int) -> LightViewTexels:
    """Photons on a regular `res x res` texel grid over the emission plane covering `mesh`.

    The caustic-map texels of seed 004 §3.1 (Alg. 2 takes its neighbours `x10, x01` from
    adjacent texels), on a `photons.EmissionPlane`.
    """
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a SurfaceMesh, got {type(mesh).__name__}")
    res = check_int("res", res, 2, MAX_TEXELS)
    L_np = check_points("L", L, mesh.dtype)
    if L_np.shape != (3,):
        raise ValueError(f"L must be one point, shape (3,), got {L_np.shape}")
    plane = EmissionPlane.covering(mesh, L_np)
    du, dv = (plane.x1 - plane.x0) / res, (plane.y1 - plane.y0) / res
    x = plane.x0 + (np.arange(res) + 0.5) * du
    y = plane.y0 + (np.arange(res) + 0.5) * dv
    gx, gy = np.meshgrid(x, y, indexing="xy")
    X = jnp.asarray(np.stack([gx, gy, np.full_like(gx, plane.z)], -1), mesh.dtype)
    face, ab, found = surface_hits(mesh, jnp.asarray(L_np, mesh.dtype), X.reshape(-1, 3))
    return LightViewTexels(X, face.reshape(res, res), ab.reshape(res, res, 2), found.reshape(res, res),
                           du, dv, plane)
