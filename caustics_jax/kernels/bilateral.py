"""Adaptive-radius cross-bilateral denoiser of seed 004 (eq. 21-28, Alg. 4; math.md §8).

Two misreadings are settled here (docs/kernels.md):

- `eps` of eq. 22 is "a small value" in the text but `1.0` in Alg. 4 line 22. We default
  to Alg. 4's 1.0: only then does the centre pixel's fixed weight 1 (Alg. 4 line 6)
  equal `w(p, p)`, so skipping the centre and seeding the sum with 1 is the same filter
  as eq. 24 over the whole footprint.
- `C_scene = 0.114 lum(L_min)` in eq. 25, `0.144` in Alg. 4 line 7. The constant is a
  parameter; the default is eq. 25's 0.114 (the equation is the definition, the
  algorithm cites it, and 0.114 -> 0.144 is a one-digit slip).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..math.geometry import dot
from ..runtime.kernel_contract import float_inputs
from ._util import as_float, check_last_axis, float_dtype, ratio_scale, static_int, tiny

#: Eq. 25's constant (default). Alg. 4 line 7 prints 0.144 instead.
C_SCENE_FACTOR = 0.114
C_SCENE_FACTOR_ALG4 = 0.144
#: Alg. 4 line 22 uses 1.0 for eq. 22's epsilon.
EPS_ALG4 = 1.0
#: Rec. 709 relative luminance weights; seed 004 does not name its `lum`.
REC709 = (0.2126, 0.7152, 0.0722)
_MAX_RADIUS = 15


@float_inputs("z_p", "z_q", "pos_p", "pos_q", "delta", params=("eps",), positive=("delta", "eps"))
def bilateral_weight(
    z_p: Float[Array, "*batch"],
    z_q: Float[Array, "*batch"],
    pos_p: Float[Array, "*batch 3"],
    pos_q: Float[Array, "*batch 3"],
    delta: Float[Array, "*batch"],
    eps=EPS_ALG4,
) -> Float[Array, "*batch"]:
    """Cross-bilateral weight `w = w_z w_pos` (seed 004 eq. 21-23).

    `w_z = 1 / (|z_p - z_q| + eps)` (eq. 22), `w_pos = 1 / (1 + 10 d.d / delta^2)` with
    `d = pos_p - pos_q` (eq. 23). With the default `eps = 1` (Alg. 4 line 22), `w <= 1`
    and `w(p, p) = 1`, the centre weight of Alg. 4.

    Eq. 23 is evaluated as `delta'^2 / (delta'^2 + 10 d'.d')` with `d`, `delta` divided
    by their largest magnitude: `delta^2` alone underflows (float32 `delta = 1e-23` and
    `p = q` gave 0/0) or overflows (`delta = |d| = 1e30`: inf/inf), the ratio does not.
    Inside jit (unchecked) `delta = 0` gives the limit, 1 at `p = q` and 0 elsewhere, and
    `eps` is floored at the dtype's smallest normal number.
    """
    check_last_axis(pos_p, "pos_p", 3)
    dtype = float_dtype(z_p, z_q, pos_p, pos_q, delta)
    z_p, z_q, delta = (jnp.asarray(a, dtype) for a in (z_p, z_q, delta))
    d = jnp.asarray(pos_p, dtype) - jnp.asarray(pos_q, dtype)
    w_z = 1 / (jnp.abs(z_p - z_q) + jnp.maximum(as_float(eps, dtype), tiny(dtype)))
    scale = ratio_scale(d, delta)
    d, delta = d / scale[..., None], delta / scale
    delta2 = delta * delta
    den = delta2 + 10 * dot(d, d)  # in [1, 11] unless delta = d = 0 (then 0)
    w_pos = jnp.where(den > 0, delta2 / jnp.where(den > 0, den, 1), 1)
    return w_z * w_pos


@float_inputs("rgb", params=("weights",), nonnegative=("weights",))
def luminance(rgb: Float[Array, "*batch 3"], weights=REC709) -> Float[Array, "*batch"]:
    """Luminance `lum(.)` of seed 004 eq. 25-28 as a weighted channel sum (Rec. 709 default)."""
    check_last_axis(rgb, "rgb", 3)
    rgb = jnp.asarray(rgb)
    dtype = float_dtype(rgb)
    return jnp.sum(rgb.astype(dtype) * jnp.asarray(weights, dtype), axis=-1)


@float_inputs("lum_c", params=("lum_l_min", "c_scene_factor"), nonnegative=("lum_l_min",),
              positive=("c_scene_factor",))
def adaptive_kernel_params(
    lum_c: Float[Array, "*batch"], lum_l_min, c_scene_factor=C_SCENE_FACTOR
) -> tuple[Int[Array, "*batch"], Int[Array, "*batch"], Float[Array, "*batch"]]:
    """Radius, step and distance scale `(rho, lambda, delta)` (seed 004 eq. 25-28).

    `C_scene = c_scene_factor lum(L_min)` (eq. 25; 0.114 by default, 0.144 in Alg. 4);
    `lum(C(p)) < 0.1 C_scene` gives `(15, 5, 15)`, `< 0.5 C_scene` gives `(10, 1, 2)`,
    otherwise `(5, 1, 1)`.
    """
    lum_c = jnp.asarray(lum_c)
    dtype = float_dtype(lum_c)
    c_scene = as_float(c_scene_factor, dtype) * as_float(lum_l_min, dtype)
    dark = lum_c < as_float(0.1, dtype) * c_scene
    dim = lum_c < as_float(0.5, dtype) * c_scene

    def pick(a, b, c, kind):
        return jnp.where(dark, a, jnp.where(dim, b, c)).astype(kind)

    return pick(15, 10, 5, jnp.int32), pick(5, 1, 1, jnp.int32), pick(15, 2, 1, dtype)


def _neighbours(a, offsets, axis: int):
    """`a` shifted by each offset along `axis` (entry `x` holds `a[x + i]`), and validity."""
    size = a.shape[axis]
    idx = jnp.arange(size)[None, :] + offsets[:, None]
    valid = (idx >= 0) & (idx < size)
    shifted = jnp.take(a, jnp.clip(idx, 0, size - 1), axis=axis)  # offsets land at `axis`
    return jnp.moveaxis(shifted, axis, 0), valid


@float_inputs("C", "depth", "pos", params=("lum_l_min", "c_scene_factor", "eps"), nonnegative=("lum_l_min",),
              positive=("c_scene_factor", "eps"))
def denoise_subpass(
    C: Float[Array, "H W 3"],
    depth: Float[Array, "H W"],
    pos: Float[Array, "H W 3"],
    lum_l_min,
    axis: int = 1,
    c_scene_factor=C_SCENE_FACTOR,
    eps=EPS_ALG4,
) -> Float[Array, "H W 3"]:
    """One 1-D sub-pass of the adaptive cross-bilateral denoiser (seed 004 eq. 24, Alg. 4).

    For each pixel `p`, `(rho, lambda, delta)` come from `lum(C(p))` (eq. 25-28); the
    neighbours `q = p + i e_axis` for `i = -rho, -rho + lambda, ..., rho`, `i != 0`,
    contribute `w(p, q) C(q)` (eq. 21-23) and the centre enters with weight 1 (Alg. 4
    lines 6, 17). Alg. 4 steps along x (`axis=1`); the separable pass repeats along y.
    Neighbours outside the image are skipped (Alg. 4 leaves the border to the sampler).
    `pos` holds the world- or view-space position of each pixel (Alg. 4's
    `ViewSpaceFromZ`).
    """
    C, depth, pos = jnp.asarray(C), jnp.asarray(depth), jnp.asarray(pos)
    if C.ndim != 3 or C.shape[-1] != 3 or depth.shape != C.shape[:2] or pos.shape != C.shape:
        raise ValueError(
            "expected C (H,W,3), depth (H,W), pos (H,W,3); "
            f"got {C.shape}, {depth.shape}, {pos.shape}"
        )
    axis = static_int("denoise_subpass", "axis", axis, 0, 1)
    dtype = float_dtype(C, depth, pos)
    C, depth, pos = C.astype(dtype), depth.astype(dtype), pos.astype(dtype)
    if C.size == 0:  # no pixels (H or W = 0): nothing to gather along either axis
        return C
    rho, lam, delta = adaptive_kernel_params(luminance(C), lum_l_min, c_scene_factor)
    # One gather over all 30 offsets keeps the traced graph small; offsets a pixel's own
    # (rho, lambda) excludes get weight 0.
    offsets = jnp.asarray([i for i in range(-_MAX_RADIUS, _MAX_RADIUS + 1) if i != 0])
    C_q, valid = _neighbours(C, offsets, axis)
    z_q, _ = _neighbours(depth, offsets, axis)
    pos_q, _ = _neighbours(pos, offsets, axis)
    i = offsets[:, None, None]
    valid = jnp.expand_dims(valid, 2 - axis)  # (offsets, H, 1) or (offsets, 1, W)
    active = valid & (jnp.abs(i) <= rho) & (i % lam == 0)
    w = jnp.where(active, bilateral_weight(depth, z_q, pos, pos_q, delta, eps), 0)
    # Weights reach 1 / eps: for a tiny eps, 31 of them overflow the sums (inf / inf). The
    # filter is a ratio, so dividing every weight (the centre's 1 too) by the largest
    # changes nothing else; with eps >= 1 (Alg. 4) that divisor is 1: Alg. 4's weights exactly.
    m = jax.lax.stop_gradient(jnp.maximum(1, jnp.max(w, axis=0)))
    w = w / m
    total = C / m[..., None] + jnp.sum(w[..., None] * C_q, axis=0)
    weight = 1 / m + jnp.sum(w, axis=0)
    return total / weight[..., None]


@float_inputs("C", "depth", "pos", params=("lum_l_min", "c_scene_factor", "eps"), nonnegative=("lum_l_min",),
              positive=("c_scene_factor", "eps"))
def bilateral_denoise(
    C: Float[Array, "H W 3"],
    depth: Float[Array, "H W"],
    pos: Float[Array, "H W 3"],
    lum_l_min,
    passes: int = 1,
    c_scene_factor=C_SCENE_FACTOR,
    eps=EPS_ALG4,
) -> Float[Array, "H W 3"]:
    """Separable adaptive cross-bilateral denoiser (seed 004 §3.3): x then y sub-pass, repeated."""
    passes = static_int("bilateral_denoise", "passes", passes, 0, 64)
    for _ in range(passes):
        C = denoise_subpass(C, depth, pos, lum_l_min, 1, c_scene_factor, eps)
        C = denoise_subpass(C, depth, pos, lum_l_min, 0, c_scene_factor, eps)
    return C
