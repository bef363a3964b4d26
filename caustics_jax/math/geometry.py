"""Vector geometry shared by every layer: safe normalise, reflect, refract, exact Fresnel.

Conventions (math.md §1): `refract` has exactly GLSL semantics so the shader port can be
compared line by line; `eta` is the ratio incident/transmitted index.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..runtime.kernel_contract import float_inputs


def dot(u: Float[Array, "*batch 3"], v: Float[Array, "*batch 3"]) -> Float[Array, "*batch"]:
    """Dot product over the last axis."""
    return jnp.sum(u * v, axis=-1)


def norm(v: Float[Array, "*batch 3"]) -> Float[Array, "*batch"]:
    """Euclidean length over the last axis, with a finite gradient at zero."""
    sq = dot(v, v)
    safe = jnp.where(sq > 0, sq, 1)
    return jnp.where(sq > 0, jnp.sqrt(safe), 0)


@float_inputs("v")
def safe_normalize(v: Float[Array, "*batch 3"]) -> Float[Array, "*batch 3"]:
    """`v / |v|`, and the zero vector (not NaN) where `|v| = 0`.

    `|v|` is computed as `sqrt(v . v)`: where `v . v` leaves the dtype's range the result is
    the zero vector too (float32: `|v|` below about 1e-19, whose square the CPU flushes to
    0, or above 1.8e19, whose square is inf). Scenes inside `arguments.scale_range` form no
    such vector except for points closer than 1e-19 m; callers read a zero result as
    degenerate (`objectives.path_vectors`). There is no rescaling branch for those lengths:
    it would add seconds to the walk's compile (docs/solvers.md, "Measurements behind the
    code").
    """
    length = norm(v)
    inv = jnp.where(length > 0, 1 / jnp.where(length > 0, length, 1), 0)
    return v * inv[..., None]


def unit_vector(v: Float[Array, "*batch 3"]) -> tuple[Float[Array, "*batch 3"], Bool[Array, "*batch"]]:
    """`(v / |v|, ok)` for a direction of any finite length; `ok` False (and zeros) where `v`
    is zero or not finite.

    Where `v . v` would leave the dtype's range (largest component outside `[2^-60, 2^60]`)
    `v` is divided by its largest component first (`safe_normalize` squares it: a float32
    receiver normal of length 1e20 or 1e-20 had become the zero vector, and
    `path_irradiance` 0 marked valid); elsewhere the result, and its derivative, are
    exactly `safe_normalize(v)`'s.
    """
    m = jnp.max(jnp.abs(v), axis=-1)
    ok = jnp.isfinite(m) & (m > 0)
    rescale = ok & ((m < 2.0**-60) | (m > 2.0**60))
    v = jnp.where(ok[..., None], v, 0)
    return safe_normalize(v / jax.lax.stop_gradient(jnp.where(rescale, m, 1))[..., None]), ok


@float_inputs("I", "N")
def reflect(I: Float[Array, "*batch 3"], N: Float[Array, "*batch 3"]) -> Float[Array, "*batch 3"]:
    """GLSL `reflect`: `I - 2 dot(N, I) N` (seed 004 Alg. 2 uses it for the reflection variant)."""
    return I - 2 * dot(N, I)[..., None] * N


def refraction_k(cos_i: Float[Array, "*batch"], eta) -> Float[Array, "*batch"]:
    """Refract's `k = 1 - eta^2 (1 - cos_i^2)` (seed 002 eq. 3.1; math.md §1): `cos_t^2`.

    `cos_i = dot(N, I)` (either sign), `eta` = n_incident / n_transmitted. Negative under
    total internal reflection. `refract` and `fresnel_reflectance` both call it.
    """
    # GLSL's 1 - eta^2 (1 - cos^2), regrouped: 1 - cos^2 cancels near normal incidence and
    # 1 - eta^2 sin^2 near grazing; (1 - eta)(1 + eta) + (eta cos)^2 has neither problem.
    # For a large |eta| the two squares cancel: their rounding, eps eta^2, swamps k (float64
    # eta = 1e30 gave one lane in 107 of signed_sine's records a transmitted ray, status OK,
    # where every oblique ray is totally reflected), and from eta = 2^64 they overflow
    # float32 (-inf + inf: NaN eagerly, +inf under jit: all 107 OK, f = 0). From
    # `_K_LARGE_ETA` (above every physical index ratio, so physical ones are untouched)
    # k = 1 - eta (eta sin^2) with sin^2 = (1 - cos)(1 + cos): no cancellation away from the
    # TIR onset, overflow only toward -inf (TIR), 1 at normal incidence. The regrouped form
    # keeps its operands as they were (double-where'd operands had changed the walk's
    # rounding: one float32 lane of 512 lost on a steep pool). Derivatives are finite where
    # they fit the dtype (d k / d cos ~ eta^2: float32 up to eta ~ 1e19).
    ordinary = jnp.abs(eta) < _K_LARGE_ETA
    large = jnp.where(ordinary, 0, eta)
    k_large = 1 - large * (large * ((1 - cos_i) * (1 + cos_i)))  # no sqrt: d/dcos is exact at |cos| = 1
    return jnp.where(ordinary, (1 - eta) * (1 + eta) + (eta * cos_i) ** 2, k_large)


#: `refraction_k` takes `1 - (eta sin)^2` from this `|eta|` on (index ratios of real
#: materials lie below 5).
_K_LARGE_ETA = 16.0


@float_inputs("I", "N", params=("eta",), positive=("eta",))
def refract(
    I: Float[Array, "*batch 3"], N: Float[Array, "*batch 3"], eta
) -> Float[Array, "*batch 3"]:
    """GLSL `refract` (seed 002 eq. 3.1-3.2; math.md §1).

    `I` unit incident direction, `N` unit normal facing against it (`dot(N, I) <= 0`),
    `eta` = n_incident / n_transmitted. `k = 1 - eta^2 (1 - dot(N, I)^2)`; total internal
    reflection (`k < 0`) returns exactly the zero vector, otherwise
    `eta I - (eta dot(N, I) + sqrt(k)) N`.
    """
    eta = jnp.asarray(eta, dtype=I.dtype)[..., None]
    cos_i = dot(N, I)[..., None]
    k = refraction_k(cos_i, eta)
    transmits = k >= 0
    sqrt_k = safe_sqrt(k)
    out = eta * I - (eta * cos_i + sqrt_k) * N
    return jnp.where(transmits, out, jnp.zeros_like(out))


def newton_step_2x2(J: Float[Array, "2 2"], r: Float[Array, " 2"]):
    """The Newton step `dx = J^-1 r` of a 2x2 system by Cramer's rule, and whether `J` is
    solvable (finite, nonzero determinant, finite `r`); `dx = 0` where not (the one-step
    Newton's system, Hanika et al. 2015 §4.3)."""
    det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    solvable = jnp.isfinite(det) & (det != 0) & jnp.all(jnp.isfinite(r))
    inv = 1 / jnp.where(solvable, det, 1)
    dx = jnp.stack([J[1, 1] * r[0] - J[0, 1] * r[1], J[0, 0] * r[1] - J[1, 0] * r[0]]) * inv
    return jnp.where(solvable, dx, 0), solvable


def safe_div(x, y, ok):
    """`x / y` where `ok`, 0 elsewhere, with finite values and gradients (double where)."""
    return jnp.where(ok, x / jnp.where(ok, y, 1), 0)


def safe_sqrt(x):
    """sqrt of `max(x, 0)` whose gradient stays finite at and below zero (double where):
    the one copy, used by the kernels and the photon differentials too."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1)), 0)


@float_inputs("cos_i", params=("eta",), positive=("eta",))
def fresnel_reflectance(cos_i: Float[Array, "*batch"], eta) -> Float[Array, "*batch"]:
    """Exact unpolarised dielectric Fresnel reflectance (the `F` of seed 001 eq. 25).

    `cos_i = |cos|` of the incidence angle, `eta` = n_incident / n_transmitted (as in
    `refract`). `R = (r_s^2 + r_p^2) / 2` with
    `r_s = (eta cos_i - cos_t) / (eta cos_i + cos_t)`,
    `r_p = (cos_i - eta cos_t) / (cos_i + eta cos_t)`; `R = 1` under total internal
    reflection and at grazing incidence.
    """
    cos_i = jnp.clip(jnp.abs(cos_i), 0, 1)
    eta = jnp.asarray(eta, dtype=cos_i.dtype)
    cos_t2 = refraction_k(cos_i, eta)
    cos_t = safe_sqrt(cos_t2)
    den_s = eta * cos_i + cos_t
    den_p = cos_i + eta * cos_t
    ok = (cos_t2 > 0) & (den_s > 0) & (den_p > 0)
    r_s = (eta * cos_i - cos_t) / jnp.where(ok, den_s, 1)
    r_p = (cos_i - eta * cos_t) / jnp.where(ok, den_p, 1)
    return jnp.where(ok, (r_s**2 + r_p**2) / 2, 1)


@float_inputs("cos_i", params=("eta",), positive=("eta",))
def fresnel_transmittance(cos_i: Float[Array, "*batch"], eta) -> Float[Array, "*batch"]:
    """Exact unpolarised dielectric Fresnel transmittance `1 - R` (energy, not radiance)."""
    return 1 - fresnel_reflectance(cos_i, eta)


def beer_lambert(sigma_t, t: Float[Array, "*batch"]) -> Float[Array, "*batch"]:
    """`A = exp(-sigma_t t)`: Beer-Lambert attenuation over a path of length `t` in the
    medium (the `A` of seed 001 eq. 25; seed 003's throughput is `T A`). Negative `t` is
    clipped to 0 (so `A <= 1`), and `sigma_t <= 0` attenuates nothing, an infinite `t`
    included (`0 inf` would be NaN); callers check `sigma_t >= 0` at their boundary. The
    one transcription of the factor: `path_irradiance`, the photons, the photon
    differentials and `kernels.culling.throughput` use it."""
    t = jnp.asarray(t)
    optical_depth = jnp.where(sigma_t > 0, sigma_t * jnp.maximum(t, 0), 0)
    return jnp.exp(-optical_depth).astype(t.dtype)
