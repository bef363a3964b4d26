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
  A photon of flux `Phi = I_e cos_e du dv / r_e^2` lands on `|det J| du dv`, so the
  irradiance where it lands is `E = I_e T cos_e / (r_e^2 |det J|)` (times attenuation).
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

from .._precision import float_inputs
from ..barycentric import barycentric_coordinates, interpolated_normal
from ..geometry import dot, norm, reflect, refract, safe_div, safe_normalize
from ..mesh import SurfaceMesh
from ..objectives import orthonormal_frame
from .differentials import validity_threshold
from .photons import EmissionPlane, ReceiverGrid, refract_into_medium, surface_hits

MODES = ("refract", "reflect")


def triangle_area(x0, x1, x2) -> Float[Array, "*batch"]:
    """`|(x1 - x0) x (x2 - x0)| / 2` (Alg. 2's `TriArea`)."""
    return norm(jnp.cross(x1 - x0, x2 - x0)) / 2


def _scatter(l_dir, n, eta, mode):
    """Alg. 2 line 1-2: `normalize(reflect(LDir, n))`, or `normalize(refract(LDir, n, 1/eta))`."""
    if mode == "reflect":
        return safe_normalize(reflect(l_dir, n))
    return safe_normalize(refract(l_dir, n, 1 / jnp.asarray(eta, l_dir.dtype)))


def _check_mode(mode):
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")


@functools.partial(jax.jit, static_argnames=("mode",))
def _compression_ratio(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01, t_hit, eta, scale,
                       level, mode):
    w00 = _scatter(l_dir, n00, eta, mode)
    hit0 = x00 + t_hit[..., None] * w00
    hit1 = x10 + t_hit[..., None] * _scatter(l_dir10, n10, eta, mode)
    hit2 = x01 + t_hit[..., None] * _scatter(l_dir01, n01, eta, mode)
    A = triangle_area(x00, x10, x01)
    A_d = triangle_area(hit0, hit1, hit2)
    ok = A > 0
    sigma = jnp.sqrt(safe_div(A_d, A, ok)) * jnp.asarray(scale, A.dtype) ** level
    ok = ok & jnp.isfinite(sigma)  # areas overflow beyond arguments.scale_range (float32 1e10 m): invalid
    return jnp.where(ok, sigma, 0), ok


@float_inputs("x00", "x10", "x01", "n00", "n10", "n01", "l_dir", "t_hit", "l_dir10", "l_dir01",
               params=("eta", "scale", "level"))
def compression_ratio(
    x00: Float[Array, "*batch 3"], x10: Float[Array, "*batch 3"], x01: Float[Array, "*batch 3"],
    n00: Float[Array, "*batch 3"], n10: Float[Array, "*batch 3"], n01: Float[Array, "*batch 3"],
    l_dir: Float[Array, "*batch 3"], t_hit: Float[Array, "*batch"], *, eta=1.333,
    scale=1.0, level=0, mode: str = "refract", l_dir10=None, l_dir01=None,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """Kernel scale `sigma = sqrt(A'/A) s^c` by the same-`t'` shortcut (seed 004 eq. 10-11, Alg. 2).

    `x00, x10, x01` surface points of adjacent texels (eq. 10), `n..` their unit normals
    (outward, toward the light), `l_dir` the unit light direction (from the light,
    `l_dir.n < 0`), `t_hit` the centre ray's hit distance `t'`, `scale`/`level` the
    cascade `s` and `c`. `mode="refract"` (into the medium, index ratio `1/eta`) or
    `"reflect"` (Alg. 2 as printed). Returns `(sigma, valid)`, `valid` False (and
    `sigma = 0`) for a degenerate surface triangle.
    """
    _check_mode(mode)
    l_dir = jnp.asarray(l_dir)
    l_dir10 = l_dir if l_dir10 is None else jnp.asarray(l_dir10, l_dir.dtype)
    l_dir01 = l_dir if l_dir01 is None else jnp.asarray(l_dir01, l_dir.dtype)
    return _compression_ratio(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01,
                              jnp.asarray(t_hit, l_dir.dtype), eta, scale, level, mode)


def _to_plane(x, w, point, normal):
    """Ray `x + t w` on the plane `(point, normal)`: `(hit, t, ok)`; `ok` needs `t > 0`."""
    den = dot(w, normal)
    ok_den = jnp.abs(den) > 0
    t = safe_div(dot(point - x, normal), den, ok_den)
    return x + t[..., None] * w, t, ok_den & (t > 0)


@functools.partial(jax.jit, static_argnames=("mode",))
def _compression_ratio_exact(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01, point, normal,
                             eta, mode):
    hits, ok = [], True
    for x, n, d in ((x00, n00, l_dir), (x10, n10, l_dir10), (x01, n01, l_dir01)):
        y, _, hit = _to_plane(x, _scatter(d, n, eta, mode), point, normal)
        hits.append(y)
        ok = ok & hit
    A = triangle_area(x00, x10, x01)
    ok = ok & (A > 0)
    ratio = safe_div(triangle_area(*hits), A, ok)
    ok = ok & jnp.isfinite(ratio)  # as in _compression_ratio
    return jnp.where(ok, ratio, 0), ok


@float_inputs("x00", "x10", "x01", "n00", "n10", "n01", "l_dir", "receiver_point",
               "receiver_normal", "l_dir10", "l_dir01", params=("eta",))
def compression_ratio_exact(
    x00, x10, x01, n00, n10, n01, l_dir, receiver_point, receiver_normal, *, eta=1.333,
    mode: str = "refract", l_dir10=None, l_dir01=None,
) -> tuple[Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """`A'_rec / A`: the three rays of Alg. 2 each intersected with the receiver plane.

    The reference for `compression_ratio`'s same-`t'` shortcut (MATH.md §7): no shared
    `t'`, the caustic triangle lies on the receiver. Arguments as `compression_ratio`,
    plus the receiver plane `(receiver_point, receiver_normal)`. Returns
    `(ratio, valid)`; `valid` False where a ray misses the plane (parallel or behind) or
    the surface triangle is degenerate.
    """
    _check_mode(mode)
    l_dir = jnp.asarray(l_dir)
    l_dir10 = l_dir if l_dir10 is None else jnp.asarray(l_dir10, l_dir.dtype)
    l_dir01 = l_dir if l_dir01 is None else jnp.asarray(l_dir01, l_dir.dtype)
    point = jnp.asarray(receiver_point, l_dir.dtype)
    normal = safe_normalize(jnp.asarray(receiver_normal, l_dir.dtype))
    return _compression_ratio_exact(x00, x10, x01, n00, n10, n01, l_dir, l_dir10, l_dir01,
                                    point, normal, eta, mode)


# --------------------------------------------------------------------------- exact differential


def _texel_trace(uv, V, N, L, X, eta, point, normal):
    """Emission-plane offset `uv` -> `(receiver coords (2,), T, cos_e, r_e, t, ok)` for one photon.

    The ray from `L` through `X + (u, v, 0)` meets the triangle's plane (barycentrics
    extrapolated past the edges, so the map is smooth), refracts there at the normalised
    interpolated normal, and runs to the receiver plane.
    """
    Xu = X + jnp.concatenate([uv, jnp.zeros(1, uv.dtype)])
    d_raw = Xu - L
    r_e = norm(d_raw)
    d = d_raw / r_e
    E1, E2 = V[1] - V[0], V[2] - V[0]
    M, _, ok_s = _to_plane(L, d, V[0], jnp.cross(E1, E2))
    n_s = safe_normalize(interpolated_normal(N, barycentric_coordinates(E1, E2, M - V[0])))
    r, T, ok_n = refract_into_medium(d, n_s, eta)
    Y, t, ok_r = _to_plane(M, r, point, normal)
    e1, e2 = orthonormal_frame(normal)
    coords = jnp.stack([dot(Y - point, e1), dot(Y - point, e2)])
    return coords, (Y, T, -d[2], r_e, t, ok_s & ok_n & ok_r)


def _texel_one(V, N, L, X, eta, point, normal):
    J, aux = jax.jacfwd(_texel_trace, has_aux=True)(jnp.zeros(2, X.dtype), V, N, L, X, eta, point, normal)
    return (J, *aux)


_texel_vectorized = jnp.vectorize(
    _texel_one, signature="(3,3),(3,3),(3),(3),(),(3),(3)->(2,2),(3),(),(),(),(),()")


@float_inputs("V", "N", "L", "X", "receiver_point", "receiver_normal", params=("eta",))
@jax.jit
def texel_jacobian(
    V: Float[Array, "*batch 3 3"], N: Float[Array, "*batch 3 3"], L: Float[Array, "*batch 3"],
    X: Float[Array, "*batch 3"], eta, receiver_point: Float[Array, "*batch 3"],
    receiver_normal: Float[Array, "*batch 3"],
):
    """Exact photon differential: `J = d(receiver coords)/d(emission-plane xy)` by `jax.jacfwd`.

    The Jacobian of seed 003's footprint and the exact reference for seed 004 eq. 10-11
    (MATH.md §7).

    `V, N` the surface triangle the photon through emission point `X` hits (from the
    light `L`); the receiver plane `(receiver_point, receiver_normal)`, coordinates in
    `orthonormal_frame(receiver_normal)`. Returns `(J (2,2), Y (3,), T, cos_e, r_e, t,
    valid)`: the landing point, Fresnel transmittance, cosine of the photon direction
    with the emission-plane normal (+z), light-to-`X` distance, path length in the medium.
    """
    dtype = jnp.asarray(X).dtype
    normal = safe_normalize(jnp.asarray(receiver_normal, dtype))
    return _texel_vectorized(V, N, L, X, jnp.asarray(eta, dtype), jnp.asarray(receiver_point, dtype),
                             normal)


@float_inputs("V", "N", "L", "X", "receiver_point", "receiver_normal",
               params=("eta", "intensity", "sigma_t"))
@jax.jit
def photon_differential_irradiance(V, N, L, X, eta, intensity, receiver_point, receiver_normal,
                                   sigma_t=0.0):
    """Irradiance where the photon through `X` lands: `I_e T A cos_e / (r_e^2 |det J|)`.

    MATH.md §7's flux bookkeeping, `Phi / A'`, with the exact landing area.

    Flux `I_e cos_e du dv / r_e^2` through the emission texel `du dv` (photons.py), times
    `T` and `A = exp(-sigma_t t)`, over its landing area `|det J| du dv` (`texel_jacobian`).
    Returns `(E, Y, valid)`: `E = 0` where invalid or `|det J|` is below `sqrt(eps)` of
    its scale (on a caustic, where the irradiance of a single photon tube is unbounded).
    """
    J, Y, T, cos_e, r_e, t, ok = texel_jacobian(V, N, L, X, eta, receiver_point, receiver_normal)
    det = jnp.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    scale = jnp.sum(J**2, axis=(-2, -1))
    ok = ok & (det > validity_threshold(det.dtype) * scale)
    dtype = det.dtype
    E = (jnp.asarray(intensity, dtype) * T * jnp.exp(-jnp.asarray(sigma_t, dtype) * t) * cos_e
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
    """
    J = jnp.stack([dY_du, dY_dv], -1)
    # Symmetric 2x2 eigenproblem of J J^T in closed form (no LAPACK call, works in float32).
    a, b, c = (J[..., 0, 0] ** 2 + J[..., 0, 1] ** 2, J[..., 0, 0] * J[..., 1, 0] + J[..., 0, 1] * J[..., 1, 1],
               J[..., 1, 0] ** 2 + J[..., 1, 1] ** 2)
    half_trace, diff = (a + c) / 2, (a - c) / 2
    root = jnp.sqrt(diff**2 + b**2)
    lam1, lam2 = half_trace + root, jnp.maximum(half_trace - root, 0)
    theta = 0.5 * jnp.arctan2(2 * b, a - c)
    u1 = jnp.stack([jnp.cos(theta), jnp.sin(theta)], -1)
    u2 = jnp.stack([-jnp.sin(theta), jnp.cos(theta)], -1)
    det = jnp.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    return jnp.stack([jnp.sqrt(lam1), jnp.sqrt(lam2)], -1), jnp.stack([u1, u2], -2), jnp.pi * det


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


def splat_footprints(xy, flux, J, du: float, dv: float, receiver: ReceiverGrid, *,
                     kappa: float = 0.7, window: int = 6) -> np.ndarray:
    """Irradiance map from photons splatted as anisotropic Gaussians (seed 003 footprints).

    Photon `i` at `xy[i]` (receiver-plane x, y) with flux `flux[i]` and texel Jacobian
    `J[i]` spreads its flux as a Gaussian of covariance
    `kappa^2 (J D)(J D)^T + (cell^2/12) I`, `D = diag(du, dv)`, over a
    `(2 window + 1)^2` block of cells, normalised so that it deposits exactly its flux
    (flux leaving the grid is lost, as it should be). `kappa = 0.7` texel keeps the sum of
    kernels on a regular texel lattice flat to ~1e-4 (Poisson summation:
    `2 exp(-2 pi^2 kappa^2)`; measured 1.2e-4 on a lattice of 1.46 cells, 0.32 with
    `kappa = 0.3`); the cell term keeps a footprint smaller than a cell from aliasing. A
    footprint wider than about `window / 3` cells is truncated (still flux conserving,
    but blurred less than asked). The receiver plane must be horizontal (`J` in x, y).
    Returns `(ny, nx)` irradiance (W/m^2).
    """
    receiver = ReceiverGrid(*receiver)
    receiver.validate()
    xy = jnp.asarray(xy)
    dtype = xy.dtype
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
    if res < 2:
        raise ValueError(f"res must be >= 2, got {res}")
    L_np = np.asarray(L, np.float64).reshape(3)
    plane = EmissionPlane.covering(mesh, L_np)
    du, dv = (plane.x1 - plane.x0) / res, (plane.y1 - plane.y0) / res
    x = plane.x0 + (np.arange(res) + 0.5) * du
    y = plane.y0 + (np.arange(res) + 0.5) * dv
    gx, gy = np.meshgrid(x, y, indexing="xy")
    X = jnp.asarray(np.stack([gx, gy, np.full_like(gx, plane.z)], -1), mesh.dtype)
    face, ab, found = surface_hits(mesh, jnp.asarray(L_np, mesh.dtype), X.reshape(-1, 3))
    return LightViewTexels(X, face.reshape(res, res), ab.reshape(res, res, 2), found.reshape(res, res),
                           du, dv, plane)
