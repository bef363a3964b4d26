"""Projected photon position (seed 002 eq. 3.3) and the exact ray-plane reference."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax import refract
from caustics_jax.kernels import projected_photon_position, ray_plane_intersection

DTYPES = [jnp.float32, jnp.float64]
EPS = {jnp.float32: np.finfo(np.float32).eps, jnp.float64: np.finfo(np.float64).eps}
seeds = st.integers(0, 2**32 - 1)


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_projection_is_the_orthogonal_foot_on_the_refracted_ray(dtype, seed):
    rng = np.random.default_rng(seed)
    W, T = rng.uniform(-10, 10, (2, 256, 3))
    D = _unit(rng, 256) * rng.uniform(0.1, 3, (256, 1))  # |D| need not be 1
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    P = np.asarray(projected_photon_position(c(W), c(T), c(D)))
    assert P.dtype == dtype
    scale = 32 * EPS[dtype] * 20 * np.linalg.norm(D, axis=-1)  # |T - W| <= 35, rounded ~4x
    assert np.all(np.abs(np.linalg.norm(np.cross(P - W, D), axis=-1)) <= scale * 3)
    assert np.all(np.abs(np.sum((T - P) * D, -1)) <= scale * 3)
    P2 = np.asarray(projected_photon_position(c(W), c(T), c(-2.5 * D)))
    np.testing.assert_allclose(P2, P, atol=64 * EPS[dtype] * 20)
    # zero direction (TIR from `refract`): stays at the water point, finite
    P0 = np.asarray(projected_photon_position(c(W), c(T), jnp.zeros((256, 3), dtype)))
    np.testing.assert_array_equal(P0, np.asarray(c(W)))


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_ray_plane_intersection_lies_on_both_and_flags_parallel_rays(dtype, seed):
    rng = np.random.default_rng(seed)
    o, q = rng.uniform(-5, 5, (2, 256, 3))
    d, n = _unit(rng, 256), _unit(rng, 256)
    d[:16] = np.cross(n[:16], _unit(rng, 16))  # parallel to the plane
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    X, t, hit = (np.asarray(a) for a in ray_plane_intersection(c(o), c(d), c(q), c(n)))
    assert X.dtype == dtype and np.all(np.isfinite(X)) and np.all(np.isfinite(t))
    assert not hit[:16].any()
    den = np.abs(np.sum(d * n, -1))
    ok = hit & (den > 0.05)  # well-conditioned lanes
    tol = 64 * EPS[dtype] * (10 + np.abs(t)) / np.maximum(den, 0.05)
    assert np.all(np.abs(np.sum((X - q) * n, -1))[ok] <= tol[ok])
    np.testing.assert_allclose(X[hit], (o + t[:, None] * d)[hit], atol=float(tol.max()))
    assert np.all(t[hit] >= 0)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_projection_is_exact_when_the_light_enters_along_the_water_normal(dtype, seed):
    """The thesis' best case: no bending, so the terrain point is already on the ray,
    whatever the terrain slope."""
    rng = np.random.default_rng(seed)
    W = np.c_[rng.uniform(-5, 5, (256, 2)), np.zeros(256)]
    l_dir = np.tile([0.0, 0, -1], (256, 1))
    slope = rng.uniform(0, np.radians(60), 256)
    az = rng.uniform(0, 2 * np.pi, 256)
    n_t = np.stack([np.sin(slope) * np.cos(az), np.sin(slope) * np.sin(az), np.cos(slope)], -1)
    q = W + [0, 0, -2.0]
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    T, _, _ = ray_plane_intersection(c(W), c(l_dir), c(q), c(n_t))
    D = refract(c(l_dir), c(np.tile([0.0, 0, 1], (256, 1))), 1 / 1.333)
    exact, _, hit = ray_plane_intersection(c(W), D, c(q), c(n_t))
    approx = np.asarray(projected_photon_position(c(W), T, D))
    assert np.all(np.asarray(hit))
    np.testing.assert_allclose(approx, np.asarray(exact), atol=64 * EPS[dtype] * 10)
    # and once the light is tilted, the approximation is off even on flat terrain
    tilted = np.tile([np.sin(0.6), 0, -np.cos(0.6)], (256, 1))
    flat = np.tile([0.0, 0, 1], (256, 1))
    T2, _, _ = ray_plane_intersection(c(W), c(tilted), c(q), c(flat))
    D2 = refract(c(tilted), c(flat), 1 / 1.333)
    exact2, _, _ = ray_plane_intersection(c(W), D2, c(q), c(flat))
    off = np.linalg.norm(
        np.asarray(projected_photon_position(c(W), T2, D2)) - np.asarray(exact2), axis=-1
    )
    assert np.all(off > 0.05)  # depth 2: several centimetres per metre of depth


def test_wrong_shapes_raise():
    with pytest.raises(ValueError, match="dir_refraction"):
        projected_photon_position(jnp.zeros(3), jnp.zeros(3), jnp.zeros(2))


@pytest.mark.parametrize("dtype", DTYPES)
def test_the_length_of_the_direction_and_normal_does_not_matter(dtype):
    """Eq. 3.3 and the plane hit depend on the directions of D and n only. As D.D and
    |d| |n| (before the fix), float32 |D| = 1e-20 underflowed (the photon stayed at
    PosWater), |D| = 1e20 overflowed (same), and |d| = |n| = 1e20 called every ray parallel."""
    lengths = {jnp.float32: [1e-30, 1e-20, 1.0, 1e20, 1e30], jnp.float64: [1e-300, 1e-160, 1.0, 1e160, 1e300]}
    s = np.asarray(lengths[dtype])[:, None]
    c = lambda a: jnp.asarray(a, dtype)  # noqa: E731
    W, T, D = np.zeros(3), np.array([1.0, 0, -2]), np.array([0.6, 0, -0.8])
    got = np.asarray(projected_photon_position(c(W), c(T), c(D * s)))
    want = np.asarray(projected_photon_position(c(W), c(T), c(D)))
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=4 * EPS[dtype], atol=0)
    n = np.array([0.0, 0.6, 0.8])
    point, t, hit = ray_plane_intersection(c(W), c(D * s), c([0.0, 0, -2]), c(n * s))
    assert bool(jnp.all(hit))
    p1, _, _ = ray_plane_intersection(c(W), c(D), c([0.0, 0, -2]), c(n))
    np.testing.assert_allclose(np.asarray(point), np.broadcast_to(np.asarray(p1), point.shape),
                               rtol=4 * EPS[dtype], atol=0)
