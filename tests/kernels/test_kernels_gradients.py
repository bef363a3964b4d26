"""Values and gradients stay finite at the degenerate inputs the double-where guards."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from caustics_jax.kernels import (
    cylinder_aabb,
    fresnel_reflect_approx,
    intensity_attenuation,
    luminance,
    pixel_footprint_radius,
    projected_photon_position,
    ray_plane_intersection,
    resolve,
    reuse_weight,
)

DTYPES = [jnp.float32, jnp.float64]


def _finite_grad(f, *args):
    grad = jax.grad(lambda *a: jnp.sum(f(*a)), argnums=tuple(range(len(args))))
    grads = jax.jit(grad)(*args)  # one compile instead of many eager primitives
    return all(bool(jnp.all(jnp.isfinite(g))) for g in grads)


@pytest.mark.parametrize("dtype", DTYPES)
def test_gradients_are_finite_at_degenerate_inputs(dtype):
    z3 = jnp.zeros(3, dtype)
    axis = jnp.asarray([0.0, 0.0, 1.0], dtype)  # sqrt(1 - n_i^2) = 0 on z
    r0 = jnp.asarray(0.0, dtype)
    assert _finite_grad(
        lambda c, n, r: jnp.stack(cylinder_aabb(c, n, r)), z3, axis, jnp.asarray(1.0, dtype)
    )
    assert _finite_grad(reuse_weight, z3, z3, r0)  # r = 0 and coincident points
    assert _finite_grad(resolve, jnp.asarray(1.0, dtype), jnp.asarray(1.0, dtype), r0)
    assert _finite_grad(projected_photon_position, z3, axis, z3)  # D = 0 (TIR)
    assert _finite_grad(
        lambda o, d: ray_plane_intersection(o, d, axis, axis)[0],
        z3,
        jnp.asarray([1.0, 0, 0], dtype),
    )
    assert _finite_grad(
        pixel_footprint_radius, jnp.asarray(1.0, dtype), jnp.asarray(1e-3, dtype), r0
    )
    assert _finite_grad(lambda l: fresnel_reflect_approx(l, axis, 0.02), -axis)  # cos = 1
    assert _finite_grad(
        lambda t: intensity_attenuation(t, 1.0), jnp.asarray([0.0, 0.05, 1.0], dtype)
    )
    for out in (
        resolve(1.0, 1.0, r0),
        reuse_weight(z3, z3, r0),
        projected_photon_position(z3, axis, z3),
    ):
        assert bool(jnp.all(jnp.isfinite(out)))


@pytest.mark.parametrize("dtype", DTYPES)
def test_luminance_weights_sum_to_one_and_keep_the_dtype(dtype):
    rgb = np.random.default_rng(0).uniform(0, 5, (256, 3))
    lum = np.asarray(luminance(jnp.asarray(rgb, dtype)))
    assert lum.dtype == dtype
    grey = np.asarray(luminance(jnp.asarray(np.repeat(rgb[:, :1], 3, 1), dtype)))
    np.testing.assert_allclose(grey, rgb[:, 0], rtol=4 * np.finfo(dtype).eps)
    assert np.all((lum >= rgb.min(-1) * (1 - 1e-6)) & (lum <= rgb.max(-1) * (1 + 1e-6)))
