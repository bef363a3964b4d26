"""Photon sprites of seed 004 (eq. 16-20; math.md §7): size, stretch, corners, intensity.

Each photon hit is splatted as a rectangle in the tangent plane of the hit: side `q`
across the light and `a q` along the light's projection, `a` the foreshortening of
eq. 19. Eq. 20 divides the ray intensity by that area, so the splat carries `R`.
The compression ratio `sigma` of eq. 11 comes from the photon differentials (§7) and is
an input here.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..math.geometry import dot, safe_normalize
from ..runtime.kernel_contract import float_inputs
from ._util import as_float, check_last_axis, float_dtype, safe_div, static_int, static_real, tiny

#: Eq. 19's epsilon ("a small offset value"); the paper gives no number.
FORESHORTENING_EPS = 1e-3
#: Eq. 17's local unit patch, in the order of the paper.
PATCH = ((-1.0, 1.0), (1.0, 1.0), (-1.0, -1.0), (1.0, -1.0))


@float_inputs("sigma", params=("q0",), nonnegative=("sigma", "q0"))
def sprite_size(r_width, r_height, ccm0_x, ccm0_y, q0, sigma: Float[Array, "*batch"]):
    """Sprite side `q` (seed 004 eq. 16).

    `q = sqrt(r.width / (ccm0.x - 1) * r.height / (ccm0.y - 1)) q0 sigma`: the caustic-map
    texel spacing of the light's range, times the user scale `q0` and the compression
    ratio `sigma`. The light range `r_width`, `r_height` and the map size `ccm0_x`,
    `ccm0_y` are static configuration (Python numbers); `q0` and `sigma` may be traced.
    """
    r_width = static_real("sprite_size", "r_width", r_width, 0, lo_open=True)
    r_height = static_real("sprite_size", "r_height", r_height, 0, lo_open=True)
    ccm0_x = static_int("sprite_size", "ccm0_x", ccm0_x, 2, 2**16)
    ccm0_y = static_int("sprite_size", "ccm0_y", ccm0_y, 2, 2**16)
    sigma = jnp.asarray(sigma)
    dtype = float_dtype(sigma)
    spacing = (r_width / (ccm0_x - 1) * r_height / (ccm0_y - 1)) ** 0.5
    return as_float(spacing * q0, dtype) * sigma.astype(dtype)


@float_inputs("l_dir", "n_hit", params=("eps",), positive=("eps",))
def sprite_foreshortening(
    l_dir: Float[Array, "*batch 3"], n_hit: Float[Array, "*batch 3"], eps=FORESHORTENING_EPS
) -> Float[Array, "*batch"]:
    """Stretch `a = 1 / (-l_dir . n' + eps)` along the light (seed 004 eq. 19).

    The cosine is clamped at 0: Alg. 3 line 33 only splats front-facing hits, and a
    negative cosine would flip the patch. Inside jit (unchecked) `eps` is floored at the
    dtype's smallest normal number, so `a` stays finite.
    """
    check_last_axis(l_dir, "l_dir", 3)
    dtype = float_dtype(l_dir, n_hit)
    cos = jnp.maximum(-dot(jnp.asarray(l_dir, dtype), jnp.asarray(n_hit, dtype)), 0)
    return 1 / (cos + jnp.maximum(as_float(eps, dtype), tiny(dtype)))


@float_inputs("l_dir", "n_hit")
def sprite_basis(
    l_dir: Float[Array, "*batch 3"], n_hit: Float[Array, "*batch 3"]
) -> tuple[Float[Array, "*batch 3"], Float[Array, "*batch 3"]]:
    """Patch axes `(lp_F, lp_R)` (seed 004 Fig. 6): `l_dir` projected onto the tangent
    plane of `n'`, and `n' x lp_F`. At normal incidence the projection vanishes; any
    tangent then serves (the patch is square there), and we pick one deterministically.
    """
    check_last_axis(l_dir, "l_dir", 3)
    check_last_axis(n_hit, "n_hit", 3)
    dtype = float_dtype(l_dir, n_hit)
    n = safe_normalize(jnp.asarray(n_hit, dtype))
    l_dir = jnp.asarray(l_dir, dtype)
    tangential = l_dir - dot(l_dir, n)[..., None] * n
    # Near normal incidence the first projection cancels to a tiny vector whose normal
    # component is rounding noise of order eps |l|; projecting again removes it.
    tangential = tangential - dot(tangential, n)[..., None] * n
    helper = jnp.where(
        jnp.abs(n[..., :1]) < 0.9, jnp.asarray([1.0, 0, 0], dtype), jnp.asarray([0, 1.0, 0], dtype)
    )
    fallback = helper - dot(helper, n)[..., None] * n
    # below this the projected light direction is rounding noise
    tiny = dot(tangential, tangential) <= (16 * jnp.finfo(dtype).eps) ** 2
    lp_F = safe_normalize(jnp.where(tiny[..., None], fallback, tangential))
    return lp_F, jnp.cross(n, lp_F)


@float_inputs("x_hit", "q", "a", "lp_F", "lp_R")
def sprite_corners(
    x_hit: Float[Array, "*batch 3"],
    q: Float[Array, "*batch"],
    a: Float[Array, "*batch"],
    lp_F: Float[Array, "*batch 3"],
    lp_R: Float[Array, "*batch 3"],
) -> Float[Array, "*batch 4 3"]:
    """Sprite corners `x' + (q lp.x lp_F a + q lp.y lp_R) / 2` (seed 004 eq. 17-18)."""
    check_last_axis(x_hit, "x_hit", 3)
    dtype = float_dtype(x_hit, q, a, lp_F, lp_R)
    patch = jnp.asarray(PATCH, dtype)
    q = jnp.asarray(q, dtype)[..., None, None]
    a = jnp.asarray(a, dtype)[..., None, None]
    along = patch[:, :1] * jnp.asarray(lp_F, dtype)[..., None, :] * a
    across = patch[:, 1:] * jnp.asarray(lp_R, dtype)[..., None, :]
    return jnp.asarray(x_hit, dtype)[..., None, :] + q * (along + across) / 2


@float_inputs("R", "a", "q")
def sprite_intensity(R, a: Float[Array, "*batch"], q: Float[Array, "*batch"]):
    """Sprite intensity `I = R / (a q^2)` (seed 004 eq. 20); 0 for a zero-size sprite."""
    dtype = float_dtype(R, a, q)
    q = jnp.asarray(q, dtype)
    return safe_div(jnp.asarray(R, dtype), jnp.asarray(a, dtype) * q * q)
