"""Photon intensity of seed 004: attenuation and Schlick-like Fresnel (eq. 12-15).

Eq. 14 is Schlick's approximation with a free base fraction `F_frac` and exponent
`F_exp`; with `F_frac = ((eta - 1)/(eta + 1))^2` and `F_exp = 5` it is Schlick's own.
Its error against the exact Fresnel term (`caustics_jax.math.geometry.fresnel_reflectance`)
is measured in `experiments/kernel_approximations.py`.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..math.geometry import dot
from ..runtime.arguments import check_real
from ..runtime.kernel_contract import float_inputs
from ._util import as_float, check_last_axis, float_dtype, tiny

#: Focus bias of eq. 13 ("experimentally defined constant set to 0.95").
GAMMA = 0.95
#: Schlick's exponent; seed 004 leaves `F_exp` free.
SCHLICK_EXPONENT = 5.0


@float_inputs("t", params=("t_max", "gamma"), positive=("t_max", "gamma"), below={"gamma": 1})
def intensity_attenuation(t: Float[Array, "*batch"], t_max, gamma=GAMMA) -> Float[Array, "*batch"]:
    """Underwater intensity attenuation `I_att` (seed 004 eq. 13).

    With `x = 1 - t/t_max`: `1 - (x - gamma)/(1 - gamma)` if `x > gamma`, else
    `1 - (gamma - x)/gamma = x / gamma`. A tent in `t`: 0 at the surface, 1 at
    `t = (1 - gamma) t_max`, back to 0 at `t_max`. `t` is clipped to `[0, t_max]`.
    Inside jit (unchecked) `t_max` is floored at the dtype's smallest normal number and
    `gamma` clipped into `(0, 1)`, so a zero or invalid parameter gives a finite tent.
    """
    t = jnp.asarray(t)
    dtype = float_dtype(t)
    t_max = jnp.maximum(as_float(t_max, dtype), tiny(dtype))
    gamma = jnp.clip(as_float(gamma, dtype), tiny(dtype), jnp.nextafter(jnp.asarray(1, dtype), 0))
    x = 1 - jnp.clip(t.astype(dtype), 0, t_max) / t_max
    return jnp.where(x > gamma, 1 - (x - gamma) / (1 - gamma), 1 - (gamma - x) / gamma)


def schlick_f0(eta):
    """Normal-incidence reflectance `((eta - 1)/(eta + 1))^2`: Schlick's choice of `F_frac`.

    `F_frac` of seed 004 eq. 14, which leaves it free (module docstring).

    A Python float for a Python number (a static constant, e.g. for `f_frac`), else an
    array by the kernels' input contract (`kernel_contract.float_inputs`).
    """
    if isinstance(eta, int | float) and not isinstance(eta, bool):
        eta = check_real("eta", eta, 0, lo_open=True)
        return ((eta - 1) / (eta + 1)) ** 2
    return _schlick_f0_array(eta)


@float_inputs("eta", positive=("eta",))
def _schlick_f0_array(eta):
    return ((eta - 1) / (eta + 1)) ** 2


@float_inputs("l_dir", "n", params=("f_frac", "f_exp"), bounds={"f_frac": (0, 1)}, nonnegative=("f_exp",))
def fresnel_reflect_approx(
    l_dir: Float[Array, "*batch 3"],
    n: Float[Array, "*batch 3"],
    f_frac,
    f_exp=SCHLICK_EXPONENT,
) -> Float[Array, "*batch"]:
    """Schlick-like reflected Fresnel term (seed 004 eq. 14).

    `F_refl = F_frac + (1 - F_frac) (1 - (-l_dir . n))^F_exp` for light travelling along
    `l_dir` onto a surface with normal `n`. The cosine is clamped to `[0, 1]` so a
    back-facing or slightly non-unit input cannot raise a negative base to a power.
    At normal incidence the base `1 - cos` is 0 and `0^F_exp` is taken as its limit (0, or
    1 for `F_exp = 0`) without differentiating `pow` there, whose derivatives are infinite
    (`F_exp < 1`) or `0 log 0`.
    """
    check_last_axis(l_dir, "l_dir", 3)
    dtype = float_dtype(l_dir, n)
    cos = jnp.clip(-dot(jnp.asarray(l_dir, dtype), jnp.asarray(n, dtype)), 0, 1)
    f_frac, f_exp = as_float(f_frac, dtype), as_float(f_exp, dtype)
    base = 1 - cos
    lit = base > 0
    power = jnp.where(lit, jnp.where(lit, base, 1) ** f_exp, jnp.where(f_exp == 0, 1, 0).astype(dtype))
    return f_frac + (1 - f_frac) * power


@float_inputs("l_dir", "n", params=("f_frac", "f_exp"), bounds={"f_frac": (0, 1)}, nonnegative=("f_exp",))
def fresnel_refract_approx(
    l_dir: Float[Array, "*batch 3"], n: Float[Array, "*batch 3"], f_frac, f_exp=SCHLICK_EXPONENT
) -> Float[Array, "*batch"]:
    """Refracted Fresnel term, the complement of eq. 14 (seed 004 eq. 15)."""
    return 1 - fresnel_reflect_approx(l_dir, n, f_frac, f_exp)


@float_inputs("L", "i_att", "F")
def ray_intensity(L, i_att, F):
    """Photon ray intensity `R = L I_att F` (seed 004 eq. 12)."""
    dtype = float_dtype(L, i_att, F)
    return jnp.asarray(L, dtype) * jnp.asarray(i_att, dtype) * jnp.asarray(F, dtype)
