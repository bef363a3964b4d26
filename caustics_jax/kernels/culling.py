"""Energy culling of seed 003 ("Additional performance optimizations", Fig. 9 and Fig. 14).

The testbed refracts once, so what a photon or a path keeps of its emitted energy after the
water is two factors, the exact Fresnel transmittance `T` at the surface and Beer-Lambert
attenuation over its path `t` in the water (the `T` and `A` of seed 001 eq. 25):

    beta = T(cos_i, eta) exp(-sigma_t t)                                      (`throughput`)

Seed 003 discards energy below a threshold at three places. On what the testbed traces:

- mid-trace cull: a photon whose energy after the water is below `mid` is discarded before
  it is stored (`photon_cull`, status `CullStatus.MID`);
- final cull: a photon whose energy after interacting with the receiver, `albedo * energy`,
  is below `final` is not stored ("darker surfaces have less photons stored"; status
  `CullStatus.FINAL`);
- throughput cull: a receiver's refracted path is dropped when its throughput, *estimated*
  before the solve at the start point `M0` (where the segment `P -> L` crosses the
  surface), is below `min_throughput` (`throughput_cull`): the solve is skipped.

The seed states no unit for its thresholds; here they are in the unit of the energy passed
(`experiments/cull.py` passes `beta`, the fraction of the photon's emitted energy, so a
threshold does not change with the photon count). Culling is biased: what it removes is
never added back (docs/claims.md "Energy culling" measures how much, against the work it
saves). A NaN energy is culled, never stored.
"""

from __future__ import annotations

import enum

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..math.geometry import beer_lambert, fresnel_transmittance
from ..runtime.kernel_contract import float_inputs
from ._util import as_float, float_dtype


class CullStatus(enum.IntEnum):
    """What `photon_cull` did with a photon (a `uint` in the GLSL port)."""

    STORED = 0  # kept: stored on the receiver
    MID = 1  # discarded mid-trace: its energy after the water is below `mid`
    FINAL = 2  # not stored: `albedo * energy` is below `final`


@float_inputs("cos_i", "t", params=("eta", "sigma_t"), positive=("eta",), nonnegative=("sigma_t",))
def throughput(cos_i: Float[Array, "*batch"], t: Float[Array, "*batch"], eta, sigma_t) -> Float[Array, "*batch"]:
    """`beta = T(cos_i, eta) exp(-sigma_t t)`: the fraction of the energy left after the
    water (seed 001 eq. 25's `T A`; module docstring).

    `cos_i` the cosine of incidence on the light's side, `eta` = n_incident /
    n_transmitted as in `refract` (air to water: `1 / 1.333`), `T` the exact Fresnel
    transmittance (`math.geometry.fresnel_transmittance`), `t >= 0` the path length in the
    water (negative `t` is clipped to 0, so `beta <= T`; with `sigma_t = 0` nothing is
    attenuated, an infinite `t` included).
    """
    dtype = float_dtype(cos_i, t)
    T = fresnel_transmittance(jnp.asarray(cos_i, dtype), as_float(eta, dtype))
    return T * beer_lambert(as_float(sigma_t, dtype), jnp.asarray(t, dtype))


@float_inputs("energy", "threshold")
def energy_cull(energy: Float[Array, "*batch"], threshold: Float[Array, "*batch"]):
    """`(kept, keep)`: `keep = energy >= threshold` (seed 003's cull test), `kept` the
    energy where kept and 0 where culled. A NaN energy (or threshold) is culled."""
    dtype = float_dtype(energy, threshold)
    energy = jnp.asarray(energy, dtype)
    keep = energy >= jnp.asarray(threshold, dtype)
    return jnp.where(keep, energy, 0), keep


@float_inputs("energy", "albedo", "mid", "final", bounds={"albedo": (0, 1)})
def photon_cull(energy: Float[Array, "*batch"], albedo: Float[Array, "*batch"], mid: Float[Array, "*batch"],
                final: Float[Array, "*batch"]):
    """`(stored, status)`: seed 003's mid-trace and final cull of one photon (Fig. 9).

    `energy` is the photon's energy after the water (`throughput` times its emitted
    energy, or `beta` alone with thresholds as fractions), `albedo` the receiver's
    reflectance in `[0, 1]`. Mid-trace: `energy < mid` discards it (`CullStatus.MID`);
    final: `albedo * energy < final` leaves it unstored (`CullStatus.FINAL`). `stored` is
    the energy binned into the caustic map (irradiance; the albedo is applied when
    shading, not here), 0 for a culled photon; `status` is int32 `CullStatus`.
    """
    dtype = float_dtype(energy, albedo, mid, final)
    energy, albedo = jnp.asarray(energy, dtype), jnp.asarray(albedo, dtype)
    _, past_mid = energy_cull(energy, mid)
    _, past_final = energy_cull(albedo * energy, final)
    status = jnp.where(past_mid, jnp.where(past_final, int(CullStatus.STORED), int(CullStatus.FINAL)),
                       int(CullStatus.MID))
    return jnp.where(past_mid & past_final, energy, 0), status.astype(jnp.int32)


@float_inputs("cos_i", "d", "min_throughput", params=("eta", "sigma_t"), positive=("eta",),
              nonnegative=("sigma_t",))
def throughput_cull(cos_i: Float[Array, "*batch"], d: Float[Array, "*batch"], min_throughput: Float[Array, "*batch"],
                    eta, sigma_t):
    """`(beta_hat, keep)`: seed 003's throughput cull (Fig. 14) of a receiver's refracted path.

    The throughput is estimated before the solve at the start point `M0`: `cos_i` the
    cosine of incidence of the light's ray at `M0` on the shading normal there, `d =
    |P - M0|` (`beta_hat = throughput(cos_i, d, eta, sigma_t)`); the path is kept (solved)
    where `beta_hat >= min_throughput`. The estimate is not the solved path's throughput:
    a lane can be culled whose path would have passed (experiments/cull.py counts them).
    """
    beta_hat = throughput(cos_i, d, eta, sigma_t)
    _, keep = energy_cull(beta_hat, min_throughput)
    return beta_hat, keep
