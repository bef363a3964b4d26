"""Photon sprites (seed 004 eq. 16-20): the splat carries the ray intensity R."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from caustics_jax.kernels.sprites import (
    sprite_basis,
    sprite_corners,
    sprite_foreshortening,
    sprite_intensity,
    sprite_size,
)

DTYPES = [jnp.float32, jnp.float64]
EPS = {jnp.float32: np.finfo(np.float32).eps, jnp.float64: np.finfo(np.float64).eps}
seeds = st.integers(0, 2**32 - 1)


def _hits(seed, n):
    """Unit normals, and light directions hitting them from the front, up to 85 degrees."""
    rng = np.random.default_rng(seed)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    t = rng.normal(size=(n, 3))
    t -= np.sum(t * nrm, -1, keepdims=True) * nrm
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    theta = rng.uniform(0, np.radians(85), (n, 1))
    theta[:4] = 0  # normal incidence: the projected light direction vanishes
    l_dir = -np.cos(theta) * nrm + np.sin(theta) * t
    return rng, l_dir, nrm, theta[:, 0]


def _sprite(dtype, l_dir, nrm, x, q, R):
    c = lambda v: jnp.asarray(v, dtype)  # noqa: E731
    a = sprite_foreshortening(c(l_dir), c(nrm))
    F, Rv = sprite_basis(c(l_dir), c(nrm))
    corners = sprite_corners(c(x), c(q), a, F, Rv)
    return (np.asarray(v) for v in (a, F, Rv, corners, sprite_intensity(c(R), a, c(q))))


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_basis_is_orthonormal_tangent_and_follows_the_light(dtype, seed):
    _, l_dir, nrm, theta = _hits(seed, 256)
    F, Rv = (
        np.asarray(v) for v in sprite_basis(jnp.asarray(l_dir, dtype), jnp.asarray(nrm, dtype))
    )
    assert F.dtype == dtype
    tol = 32 * EPS[dtype]
    for u, v in ((F, F), (Rv, Rv)):
        np.testing.assert_allclose(np.sum(u * v, -1), 1, atol=tol)
    for u, v in ((F, Rv), (F, nrm), (Rv, nrm)):
        np.testing.assert_allclose(np.sum(u * v, -1), 0, atol=tol)
    tilted = theta > 1e-3
    assert np.all(np.sum(F * l_dir, -1)[tilted] > 0)
    np.testing.assert_allclose(np.sum(Rv * l_dir, -1), 0, atol=tol)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_sprite_area_times_intensity_is_the_ray_intensity(dtype, seed):
    rng, l_dir, nrm, theta = _hits(seed, 256)
    x = rng.uniform(-10, 10, (256, 3))
    q = rng.uniform(1e-2, 1, 256)
    R = rng.uniform(0, 5, 256)
    a, _, _, C, I = _sprite(dtype, l_dir, nrm, x, q, R)
    assert I.dtype == dtype and C.shape == (256, 4, 3)
    C = C.astype(np.float64) - x[:, None]
    # corners (-1,1), (1,1), (-1,-1), (1,-1): a rectangle with edges C1-C0 and C2-C0
    e1, e2 = C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]
    area = np.linalg.norm(np.cross(e1, e2), axis=-1)
    np.testing.assert_allclose(np.sum(e1 * e2, -1), 0, atol=1e-5 if dtype == jnp.float32 else 1e-12)
    rtol = 1e-5 if dtype == jnp.float32 else 1e-12  # corners rounded at |x| ~ 10
    assert np.all(np.abs(area * I - R) <= rtol * (1 + 10 / q) * R)
    # The patch intercepts the beam: projected across the light its area is q^2 cos/(cos+eps)
    l = l_dir / np.linalg.norm(l_dir, axis=-1, keepdims=True)
    p1 = e1 - np.sum(e1 * l, -1, keepdims=True) * l
    p2 = e2 - np.sum(e2 * l, -1, keepdims=True) * l
    beam = np.linalg.norm(np.cross(p1, p2), axis=-1)
    cos = np.cos(theta)
    want = q**2 * cos / (cos + 1e-3)
    assert np.all(np.abs(beam - want) <= rtol * (1 + 10 / q) * want)


@pytest.mark.parametrize("dtype", DTYPES)
def test_splatting_on_a_fine_grid_integrates_to_the_ray_intensity(dtype):
    """math.md §7 verify: rasterise sprites in the tangent plane, on a grid not aligned
    with the sprite, counting cells whose centre is inside the quad: sum I h^2 -> R."""
    _, l_dir, nrm, theta = _hits(3, 64)
    keep = np.flatnonzero(theta < np.radians(60))[:6]  # a <= 2: keeps the grid small
    l_dir, nrm = l_dir[keep], nrm[keep]
    x = np.zeros((6, 3))
    q, R = np.full(6, 0.5), np.linspace(0.5, 2, 6)
    a, _, _, C, I = _sprite(dtype, l_dir, nrm, x, q, R)
    h = 1e-3
    for k in range(6):
        # grid frame: an arbitrary tangent frame of the hit plane
        u = np.cross(nrm[k], [0.3, 0.5, 0.8])
        u /= np.linalg.norm(u)
        v = np.cross(nrm[k], u)
        poly = np.stack([C[k] @ u, C[k] @ v], -1)[[0, 1, 3, 2]]  # convex order
        half = np.abs(poly).max() + h
        g = np.arange(-half, half, h) + h / 2
        G = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
        d1, d2 = poly[1] - poly[0], poly[2] - poly[1]
        orient = np.sign(d1[0] * d2[1] - d1[1] * d2[0])
        inside = np.ones(len(G), bool)
        for i in range(4):
            p0, p1 = poly[i], poly[(i + 1) % 4]
            side = (p1[0] - p0[0]) * (G[:, 1] - p0[1]) - (p1[1] - p0[1]) * (G[:, 0] - p0[0])
            inside &= side * orient >= 0
        flux = inside.sum() * h * h * float(I[k])
        perimeter = 2 * q[k] * (1 + float(a[k]))
        # cells cut by the boundary: relative error <= perimeter * h / area
        assert abs(flux - R[k]) <= R[k] * perimeter * h / (float(a[k]) * q[k] ** 2)


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds, q0=st.floats(0.1, 4))
def test_size_scales_with_texel_spacing_q0_and_sigma(dtype, seed, q0):
    rng = np.random.default_rng(seed)
    sigma = rng.uniform(0, 4, 256)
    q = np.asarray(sprite_size(511.0, 255.0, 512, 256, q0, jnp.asarray(sigma, dtype)))
    assert q.dtype == dtype
    # one texel of a 512 x 256 map over a 511 x 255 range is 1 x 1
    np.testing.assert_allclose(q, q0 * sigma, rtol=4 * EPS[dtype])
    q2 = np.asarray(sprite_size(4 * 511.0, 255.0, 512, 256, q0, jnp.asarray(sigma, dtype)))
    np.testing.assert_allclose(q2, 2 * q, rtol=4 * EPS[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
@given(seed=seeds)
def test_foreshortening_is_bounded_and_one_over_cosine(dtype, seed):
    _, l_dir, nrm, theta = _hits(seed, 256)
    a = np.asarray(sprite_foreshortening(jnp.asarray(l_dir, dtype), jnp.asarray(nrm, dtype)))
    assert a.dtype == dtype
    want = 1 / (np.cos(theta) + 1e-3)
    # the cosine is rounded to ~eps absolute: relative error of a ~ eps / cos
    assert np.all(np.abs(a - want) <= 64 * EPS[dtype] / np.cos(theta) * want)
    back = np.asarray(sprite_foreshortening(jnp.asarray(-l_dir, dtype), jnp.asarray(nrm, dtype)))
    assert np.all((back > 0) & (back <= 1 / 1e-3 * (1 + 1e-6)))
    g = jax.grad(
        lambda l: sprite_intensity(1.0, sprite_foreshortening(l, jnp.asarray(nrm[0], dtype)), 0.0)
    )
    assert bool(jnp.all(jnp.isfinite(g(jnp.asarray(l_dir[0], dtype)))))


@pytest.mark.parametrize("dtype", DTYPES)
def test_a_subnormal_eps_is_refused_and_a_zero_one_stays_finite_inside_jit(dtype):
    """float32 eps = 1e-45 had given a = inf at grazing light (1 / eps, flushed to 0)."""
    l_dir, n = jnp.asarray([0.0, 0, -1], dtype), jnp.asarray([1.0, 0, 0], dtype)
    with pytest.raises(ValueError, match="eps"):
        sprite_foreshortening(l_dir, n, eps=float(np.finfo(dtype).tiny) / 4)
    a = jax.jit(lambda e: sprite_foreshortening(l_dir, n, e))(jnp.asarray(0.0, dtype))
    assert bool(jnp.isfinite(a))


def test_static_map_configuration_given_a_tracer_is_a_value_error_naming_it():
    with pytest.raises(ValueError, match="r_width.*static"):
        jax.jit(lambda w: sprite_size(w, 1.0, 256, 256, 1.0, jnp.ones(2)))(1.0)
    with pytest.raises(ValueError, match="ccm0_x.*static"):
        jax.jit(lambda c: sprite_size(1.0, 1.0, c, 256, 1.0, jnp.ones(2)))(256)
