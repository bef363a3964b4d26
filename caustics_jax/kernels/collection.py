"""Collection points of seed 000: radius, cylinder, reuse, resolve, temporal EMA (math.md §8).

A collection point `c` holds a position `p`, unit normal `n`, radius `r`, material id
`m`, camera throughput `tau` and accumulated radiant intensity `I`. Photons hitting the
cylinder of radius `r` and height `r/10` around `p` (axis `n`) add to `I`; the resolve
turns `I` into radiance; the temporal variant reuses the previous frame's points.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..math.geometry import dot, safe_normalize, safe_sqrt
from ..runtime.kernel_contract import float_inputs
from ._util import as_float, check_last_axis, float_dtype, ratio_scale, safe_div, tan_half

#: Search radius cap of seed 000 §3.2 (5 mm, scene units in metres).
RADIUS_CAP = 5e-3
#: Cylinder height as a fraction of its radius (seed 000 §3: "a tenth of c.r").
HEIGHT_FRACTION = 0.1
#: Gaussian width of the reuse kernel relative to the radius (seed 000 §3.1, sigma = 3/4 r).
SIGMA_FRACTION = 0.75
#: Normal agreement threshold of the reuse test (seed 000 eq. 4).
NORMAL_THRESHOLD = 0.9
#: Weight of the reused history in the temporal EMA (seed 000 §3.1).
EMA_ALPHA = 0.8
# Grazing views make the footprint unbounded; below this cosine the cap decides anyway.
_MIN_COS = 1e-6


@float_inputs("fov_y", params=("height_px",), positive=("fov_y", "height_px"), below={"fov_y": np.pi})
def pixel_spread_angle(fov_y: Float[Array, "*batch"], height_px) -> Float[Array, "*batch"]:
    """Spread angle of a primary ray cone (Akenine-Möller et al. 2021 §2, RTG1 ch. 20 eq. 30).

    `alpha = atan(2 tan(fov_y / 2) / H)`: the angle one pixel of a vertical field of view
    `fov_y` (radians) over `H` pixels subtends at the eye. `fov_y` lies in `(0, pi)`; inside
    jit (unchecked) a wider one is clipped below `pi`, where `alpha` tends to `pi / 2`.
    """
    fov_y = jnp.asarray(fov_y)
    dtype = float_dtype(fov_y)
    fov_y = fov_y.astype(dtype)
    return jnp.arctan(2 * tan_half(fov_y) / as_float(height_px, dtype))


@float_inputs("width", "spread", "t", params=("surface_spread", "roughness_spread"),
              bounds={"surface_spread": (None, None)}, nonnegative=("width", "spread", "t", "roughness_spread"),
              below={"spread": np.pi})
def ray_cone_propagate(
    width: Float[Array, "*batch"],
    spread: Float[Array, "*batch"],
    t: Float[Array, "*batch"],
    surface_spread=0.0,
    roughness_spread=0.0,
) -> tuple[Float[Array, "*batch"], Float[Array, "*batch"]]:
    """Ray cone after travelling `t` and scattering (Akenine-Möller et al. 2021 §2, §4).

    Width `W' = W + 2 t tan(gamma / 2)` (the exact cone; the paper's erratum puts the
    `/2` in) and spread `gamma' = gamma + beta_surface + beta_roughness`. The surface
    term comes from curvature; the roughness term widens the cone for glossy BSDFs
    (their §4). Both are angles supplied by the caller: the mapping from a BSDF
    roughness to an angle is the renderer's, not part of seed 000.

    `spread` is a full cone angle in `[0, pi)` (a cone of `pi` or more has no width; `tan`
    would turn negative); inside jit (unchecked) it is clipped below `pi`. `surface_spread`
    may be negative (a concave surface narrows the cone) but must be finite.
    """
    dtype = float_dtype(width, spread, t)
    width, spread, t = (jnp.asarray(a, dtype) for a in (width, spread, t))
    new_width = width + 2 * t * tan_half(spread)
    new_spread = spread + as_float(surface_spread, dtype) + as_float(roughness_spread, dtype)
    return new_width, new_spread


@float_inputs("width", params=("cap",), nonnegative=("width",), positive=("cap",))
def ray_cone_radius(width: Float[Array, "*batch"], cap=RADIUS_CAP) -> Float[Array, "*batch"]:
    """Collection radius at a secondary hit: half the ray-cone width, capped (seed 000 §3)."""
    width = jnp.asarray(width)
    dtype = float_dtype(width)
    return jnp.minimum(width.astype(dtype) / 2, as_float(cap, dtype))


@float_inputs("t", "spread", "cos_theta", params=("cap",), nonnegative=("t", "spread"), positive=("cap",),
              below={"spread": np.pi})
def pixel_footprint_radius(
    t: Float[Array, "*batch"],
    spread: Float[Array, "*batch"],
    cos_theta: Float[Array, "*batch"],
    cap=RADIUS_CAP,
) -> Float[Array, "*batch"]:
    """Radius of the disk enclosing a pixel's footprint at a primary hit, capped (seed 000 §3).

    A pixel of angular size `spread` seen at distance `t` covers a square of side
    `s = 2 t tan(spread / 2)` across the ray; on a surface whose normal makes angle
    `theta` with the ray it stretches to `s x s / |cos theta|`. The enclosing disk is its
    half-diagonal `(s / 2) sqrt(1 + 1 / cos^2 theta)`, then capped at `cap` (5 mm).
    `spread` lies in `[0, pi)`, clipped below `pi` inside jit (as `ray_cone_propagate`).
    """
    dtype = float_dtype(t, spread, cos_theta)
    t, spread, cos_theta = (jnp.asarray(a, dtype) for a in (t, spread, cos_theta))
    c = jnp.maximum(jnp.abs(cos_theta), as_float(_MIN_COS, dtype))
    half_side = t * tan_half(spread)
    r = half_side * jnp.sqrt(1 + c * c) / c
    return jnp.minimum(r, as_float(cap, dtype))


@float_inputs("center", "normal", "radius", nonnegative=("radius",))
def cylinder_aabb(
    center: Float[Array, "*batch 3"],
    normal: Float[Array, "*batch 3"],
    radius: Float[Array, "*batch"],
) -> tuple[Float[Array, "*batch 3"], Float[Array, "*batch 3"]]:
    """Tight AABB `(lo, hi)` of the collection cylinder (seed 000 §3; math.md §8).

    Cylinder of radius `r`, height `h = r / 10`, axis `n` (normalised here), centred on
    `center`. The disk of radius `r` spans `r sqrt(1 - n_i^2)` on axis `i` and the axis
    segment `(h / 2) |n_i|`, so the half-extent is their sum.
    """
    check_last_axis(center, "center", 3)
    check_last_axis(normal, "normal", 3)
    dtype = float_dtype(center, normal, radius)
    center = jnp.asarray(center, dtype)
    n = safe_normalize(jnp.asarray(normal, dtype))
    r = jnp.asarray(radius, dtype)[..., None]
    h = r * as_float(HEIGHT_FRACTION, dtype)
    half = r * safe_sqrt((1 - n) * (1 + n)) + (h / 2) * jnp.abs(n)
    return center - half, center + half


@float_inputs("point", "center", "normal", "radius", nonnegative=("radius",))
def in_cylinder(
    point: Float[Array, "*batch 3"],
    center: Float[Array, "*batch 3"],
    normal: Float[Array, "*batch 3"],
    radius: Float[Array, "*batch"],
) -> Bool[Array, "*batch"]:
    """Whether `point` lies in the collection cylinder (seed 000 §3, "located within").

    Offset and radius are compared divided by their largest magnitude (`ratio_scale`), so
    squares that leave the dtype (a float32 radius of 1e20) cannot decide the test.
    """
    check_last_axis(point, "point", 3)
    dtype = float_dtype(point, center, normal, radius)
    d = jnp.asarray(point, dtype) - jnp.asarray(center, dtype)
    n = safe_normalize(jnp.asarray(normal, dtype))
    r = jnp.asarray(radius, dtype)
    scale = ratio_scale(d, r)
    d, r = d / scale[..., None], r / scale
    axial = dot(d, n)
    radial2 = dot(d, d) - axial * axial
    return (jnp.abs(axial) <= r * as_float(HEIGHT_FRACTION / 2, dtype)) & (radial2 <= r * r)


@float_inputs("p_prev", "n_prev", "p", "n", "r", ints=("m_prev", "m"), nonnegative=("r",))
def reuse_accepted(
    p_prev: Float[Array, "*batch 3"],
    n_prev: Float[Array, "*batch 3"],
    m_prev: Int[Array, "*batch"],
    p: Float[Array, "*batch 3"],
    n: Float[Array, "*batch 3"],
    m: Int[Array, "*batch"],
    r: Float[Array, "*batch"],
) -> Bool[Array, "*batch"]:
    """Reuse acceptance test (seed 000 eq. 4).

    `|p_prev - p| <= r` (the current point's radius), `n_prev . n >= 0.9`, same material.
    The distance test compares squares of `d` and `r` divided by their largest magnitude,
    which stay in range where `d . d` or `r^2` alone would underflow or overflow.
    """
    check_last_axis(p, "p", 3)
    check_last_axis(p_prev, "p_prev", 3)
    dtype = float_dtype(p_prev, n_prev, p, n, r)
    d = jnp.asarray(p_prev, dtype) - jnp.asarray(p, dtype)
    r = jnp.asarray(r, dtype)
    scale = ratio_scale(d, r)
    d, r = d / scale[..., None], r / scale
    close = dot(d, d) <= r * r
    aligned = dot(jnp.asarray(n_prev, dtype), jnp.asarray(n, dtype)) >= as_float(
        NORMAL_THRESHOLD, dtype
    )
    return close & aligned & (jnp.asarray(m_prev) == jnp.asarray(m))


@float_inputs("p_prev", "p", "r", nonnegative=("r",))
def reuse_weight(
    p_prev: Float[Array, "*batch 3"], p: Float[Array, "*batch 3"], r: Float[Array, "*batch"]
) -> Float[Array, "*batch"]:
    """Gaussian reuse weight (seed 000 eq. 3) with `sigma = 0.75 r`.

    `w = exp(-|p - p_prev|^2 / (2 sigma^2))`. At `r = 0` the kernel degenerates to a
    delta: weight 1 at coincident points, else 0.

    `d` and `sigma` are divided by their largest magnitude before squaring (`d . d` or
    `sigma^2` alone under- or overflow: float32 `r = |d| = 1e20` gave inf/inf), and the
    exponent is cut where `exp` underflows anyway (beyond `-log(tiny)`: 87 in float32), so
    the division stays well conditioned and the gradient finite.
    """
    check_last_axis(p, "p", 3)
    dtype = float_dtype(p_prev, p, r)
    d = jnp.asarray(p_prev, dtype) - jnp.asarray(p, dtype)
    sigma = as_float(SIGMA_FRACTION, dtype) * jnp.asarray(r, dtype)
    scale = ratio_scale(d, sigma)
    d, sigma = d / scale[..., None], sigma / scale
    d2 = dot(d, d)
    two_sigma2 = 2 * sigma * sigma
    # max(sigma, |d_i|) = 1 after scaling, so unless both are 0 two_sigma2 >= d2 / x_max >= 1 / x_max
    x_max = as_float(-np.log(np.finfo(dtype).tiny), dtype)
    far = d2 > x_max * two_sigma2  # also r = 0 with d != 0: the delta kernel's 0
    ok = ~far & (two_sigma2 > 0)
    return jnp.where(far, 0, jnp.exp(-d2 / jnp.where(ok, two_sigma2, 1))).astype(dtype)


@float_inputs("tau", "intensity", "r", nonnegative=("r",))
def resolve(tau, intensity, r: Float[Array, "*batch"]):
    """Resolve accumulated intensity to radiance (seed 000 eq. 1): `L_o = tau I / (pi r^2)`.

    `tau` and `intensity` broadcast against `r` (add a trailing axis to `r` for RGB). A
    point with `r = 0` gathered nothing and resolves to 0.
    """
    dtype = float_dtype(tau, intensity, r)
    r = jnp.asarray(r, dtype)
    area = as_float(jnp.pi, dtype) * r * r
    return safe_div(jnp.asarray(tau, dtype) * jnp.asarray(intensity, dtype), area)


@float_inputs("L_hat", "L", params=("alpha",), bounds={"alpha": (0, 1)})
def temporal_ema(L_hat, L, alpha=EMA_ALPHA):
    """Temporal exponential moving average (seed 000 eq. 2): `alpha L_hat + (1 - alpha) L`.

    `L_hat` is the radiance gathered from the previous frame, `L` this frame's resolve;
    the paper uses `alpha = 0.8`.
    """
    dtype = float_dtype(L_hat, L)
    alpha = as_float(alpha, dtype)
    return alpha * jnp.asarray(L_hat, dtype) + (1 - alpha) * jnp.asarray(L, dtype)


@float_inputs("p", "n", "r", "p_prev", "n_prev", "r_prev", "L_prev", ints=("m", "m_prev"))
def gather_previous(
    p: Float[Array, "n 3"],
    n: Float[Array, "n 3"],
    m: Int[Array, " n"],
    r: Float[Array, " n"],
    p_prev: Float[Array, "k 3"],
    n_prev: Float[Array, "k 3"],
    m_prev: Int[Array, " k"],
    r_prev: Float[Array, " k"],
    L_prev: Float[Array, " k *channels"],
) -> tuple[Float[Array, " n *channels"], Float[Array, " n"]]:
    """Reference gather of last frame's radiance onto current points (seed 000 §3.1, eq. 3-4).

    Dense all-pairs version of the BVH query: a previous point contributes to the current
    point `c` when `c.p` lies in its cylinder (the "containing" query) and eq. 4 holds;
    its interpolated radiance `L_prev` enters with the weight of eq. 3. Returns
    `(L_hat, weight_sum)`. The paper says the weighted radiances are "accumulated"; we
    normalise by the weight sum, the reading under which a constant field stays constant
    (a raw sum would brighten wherever previous points overlap). `L_hat = 0` where
    nothing was accepted (`weight_sum = 0`).
    """
    for name, a, k in (("p", p, 3), ("n", n, 3), ("p_prev", p_prev, 3), ("n_prev", n_prev, 3)):
        check_last_axis(a, name, k)
    for rows, ref, others in (("p", p, dict(n=n, m=m, r=r)),
                              ("p_prev", p_prev, dict(n_prev=n_prev, m_prev=m_prev, r_prev=r_prev, L_prev=L_prev))):
        for name, a in others.items():
            if jnp.shape(a)[:1] != jnp.shape(ref)[:1]:
                raise ValueError(f"gather_previous: {name} must have one row per point of {rows} "
                                 f"({jnp.shape(ref)[0]}), got shape {jnp.shape(a)}")
    dtype = float_dtype(p, n, r, p_prev, n_prev, r_prev, L_prev)
    cur = lambda a: jnp.asarray(a)[:, None]  # noqa: E731  (current points along axis 0)
    prev = lambda a: jnp.asarray(a)[None, :]  # noqa: E731
    accepted = reuse_accepted(
        prev(p_prev), prev(n_prev), prev(m_prev), cur(p), cur(n), cur(m), cur(r)
    )
    contained = in_cylinder(cur(p), prev(p_prev), prev(n_prev), prev(r_prev))
    w = jnp.where(accepted & contained, reuse_weight(prev(p_prev), cur(p), cur(r)), 0).astype(dtype)
    L_prev = jnp.asarray(L_prev, dtype)
    weighted = jnp.tensordot(w, L_prev, axes=(1, 0))
    weight_sum = jnp.sum(w, axis=1)
    extra = (None,) * (L_prev.ndim - 1)
    return safe_div(weighted, weight_sum[(..., *extra)]), weight_sum
