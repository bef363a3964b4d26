"""Projected photon position of seed 002 (eq. 3.3) and the exact ray-plane intersection.

Seed 002 places a photon by projecting the water-to-terrain vector (both read from the
same light-view texel) onto the refracted direction instead of tracing the refracted
ray. `ray_plane_intersection` is the exact answer against a locally planar terrain;
`experiments/kernel_approximations.py` maps the difference over slope and light angle.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..math.geometry import dot, safe_sqrt
from ..runtime.kernel_contract import float_inputs
from ._util import check_last_axis, float_dtype, ratio_scale, safe_div


@float_inputs("pos_water", "pos_terrain", "dir_refraction")
def projected_photon_position(
    pos_water: Float[Array, "*batch 3"],
    pos_terrain: Float[Array, "*batch 3"],
    dir_refraction: Float[Array, "*batch 3"],
) -> Float[Array, "*batch 3"]:
    """Photon position by projection (seed 002 eq. 3.3).

    `PosWater + ((PosTerrain - PosWater) . D) / |D|^2 D`: the orthogonal projection of
    the terrain point onto the refracted ray. `D = 0` (total internal reflection, which
    `refract` reports as the zero vector) returns `PosWater`; the thesis drops such photons.
    Only the direction of `D` matters: it is divided by its largest component first, so
    `D . D` cannot underflow (float32 `|D| = 1e-20` had left the photon at `PosWater`).
    """
    check_last_axis(pos_water, "pos_water", 3)
    check_last_axis(pos_terrain, "pos_terrain", 3)
    check_last_axis(dir_refraction, "dir_refraction", 3)
    dtype = float_dtype(pos_water, pos_terrain, dir_refraction)
    W, T, D = (jnp.asarray(a, dtype) for a in (pos_water, pos_terrain, dir_refraction))
    D = D / ratio_scale(D, 0)[..., None]
    s = safe_div(dot(T - W, D), dot(D, D))
    return W + s[..., None] * D


@float_inputs("origin", "direction", "plane_point", "plane_normal")
def ray_plane_intersection(
    origin: Float[Array, "*batch 3"],
    direction: Float[Array, "*batch 3"],
    plane_point: Float[Array, "*batch 3"],
    plane_normal: Float[Array, "*batch 3"],
) -> tuple[Float[Array, "*batch 3"], Float[Array, "*batch"], Bool[Array, "*batch"]]:
    """Exact intersection `(point, t, hit)` of `origin + t direction` with a plane (reference).

    What seed 002 eq. 3.3's projection approximates (module docstring); no paper formula.

    `t = ((plane_point - origin) . n) / (direction . n)`; `hit` is False for a ray
    parallel to the plane or a plane behind the origin (`t < 0`), where `point = origin`.
    "Parallel" means `|direction . n| <= 4 eps |direction| |n|`: below that the cosine is
    rounding noise and `t` would be meaningless. `direction` and `plane_normal` are divided
    by their largest components first, so that test and the intersection hold for any
    length of either (float32 `|d| = |n| = 1e20` had overflowed `|d| |n|`: no hit).
    """
    for name, a in (("origin", origin), ("direction", direction)):
        check_last_axis(a, name, 3)
    check_last_axis(plane_point, "plane_point", 3)
    check_last_axis(plane_normal, "plane_normal", 3)
    dtype = float_dtype(origin, direction, plane_point, plane_normal)
    o, d, q, n = (jnp.asarray(a, dtype) for a in (origin, direction, plane_point, plane_normal))
    length = ratio_scale(d, 0)
    d, n = d / length[..., None], n / ratio_scale(n, 0)[..., None]
    den = dot(d, n)
    noise = 4 * jnp.finfo(dtype).eps * safe_sqrt(dot(d, d) * dot(n, n))
    crosses = jnp.abs(den) > noise
    t = safe_div(dot(q - o, n), jnp.where(crosses, den, 0))  # in units of the scaled d
    hit = crosses & (t >= 0)
    t = jnp.where(hit, t, 0)
    return o + t[..., None] * d, t / length, hit
